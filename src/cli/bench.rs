//! `relume bench`: per-stage medians and the end-to-end rate over repeated runs.

use super::progress;
use super::replay::{Pacing, RunArgs, load, some_frame_replayed, stop_on_interrupt};
use clap::Args;
use relume::graph::timing::parts_of;
use relume::graph::{RunReport, Stats};
use std::sync::atomic::Ordering;

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(flatten)]
    run: RunArgs,
    /// Measured runs (after one warm-up run).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    repeat: u32,
    /// Run one frame at a time, so that each stage's time is its own work, and its
    /// allocation high-water mark its own (the most bytes it held allocated at once
    /// while processing a frame, its threads included: the "peak alloc MB" column). By
    /// default the stages run at once on different frames, as in `replay`: the
    /// end-to-end rate is the real one, but a stage's time also holds the time it
    /// waited for cores that other stages (sample.path's threads, say) were using.
    #[arg(long)]
    isolated: bool,
    /// Print JSON: stages.<name>.{median_ms, p95_ms, max_ms, alloc_peak_mb (with
    /// --isolated), parts (a stage that splits its time: sample.path's material,
    /// object, differential and setup, paper 000 Table 2's rows, each with its
    /// median_ms, p95_ms, max_ms)}, fps, peak_resident_mb (the process's, over the load
    /// and every run), isolated, repeat (the runs measured), interrupted.
    #[arg(long)]
    json: bool,
}

pub fn bench(a: BenchArgs) -> anyhow::Result<i32> {
    let loaded = load(&a.run)?;
    let stop = stop_on_interrupt();
    let scratch = std::env::temp_dir().join(format!("relume-bench-{}", std::process::id()));
    let pacing = if a.isolated {
        Pacing::Lockstep
    } else {
        Pacing::Pipelined
    };
    let result = (|| -> anyhow::Result<Vec<RunReport>> {
        let mut reports = Vec::new();
        let bar = progress::bar(a.repeat as u64 + 1, "bench", "runs");
        for i in 0..=a.repeat {
            let report = loaded
                .run_once(&scratch, &a.run, pacing, &stop, &mut |_| {})
                .map_err(|f| anyhow::Error::new(f.error))?;
            // Run 0 warms caches and page-ins. A run cut short by an interrupt timed
            // fewer frames than the others, so it is left out too.
            if i > 0 && !report.interrupted {
                reports.push(report);
            }
            bar.inc(1);
            if stop.load(Ordering::Relaxed) {
                break;
            }
        }
        bar.finish_and_clear();
        Ok(reports)
    })();
    let _ = std::fs::remove_dir_all(&scratch);
    let reports = result?;
    // As replay and eval: a bench stopped before its last run was complete exits 130,
    // with what it measured (an interrupt after the last frame was sent changes nothing).
    let interrupted = reports.len() < a.repeat as usize;
    if reports.is_empty() {
        // --repeat is at least 1, and only an interrupted run is left out.
        eprintln!("error: interrupted before a measured run was complete");
        return Ok(130);
    }
    let status = if interrupted {
        eprintln!(
            "interrupted: the timings cover the {} of {} measured runs complete",
            reports.len(),
            a.repeat
        );
        130
    } else {
        0
    };
    some_frame_replayed(&loaded, &reports[0])?;
    let names: Vec<(String, String)> = reports[0]
        .stages
        .iter()
        .map(|s| (s.name.clone(), s.kind.clone()))
        .collect();
    let per_stage: Vec<Stats> = (0..names.len())
        .map(|i| {
            Stats::of(
                reports
                    .iter()
                    .flat_map(|r| r.stages[i].frames.iter().map(|f| f.process_ns)),
            )
        })
        .collect();
    // Each stage's allocation high-water mark over every measured frame (lockstep
    // runs only), MB.
    let alloc_peak_mb: Vec<Option<f64>> = (0..names.len())
        .map(|i| {
            reports
                .iter()
                .flat_map(|r| r.stages[i].frames.iter().filter_map(|f| f.alloc_peak_bytes))
                .max()
                .map(|b| b as f64 / 1e6)
        })
        .collect();
    // Each stage's parts, for a stage that times them (sample.path: paper 000 Table
    // 2's rows), over every measured frame.
    let parts: Vec<Vec<(&str, Stats)>> = (0..names.len())
        .map(|i| parts_of(reports.iter().flat_map(|r| r.stages[i].frames.iter())))
        .collect();
    let peak_resident_mb = relume::graph::memory::peak_resident_bytes().map(|b| b as f64 / 1e6);
    let mut fps: Vec<f64> = reports.iter().map(|r| r.fps()).collect();
    fps.sort_by(f64::total_cmp);
    let median_fps = fps[fps.len() / 2];
    let frames = reports[0].frames_out;
    // A stage that runs on every k-th frame: its mean over all frames is its cost.
    let every_of = |name: &str| {
        let stage = loaded.pipeline.stages.iter().find(|s| s.name == name);
        stage.map_or(1, |s| s.every)
    };
    // A stage that runs behind on its own thread: its time is its wait for that thread.
    let lag_of = |name: &str| {
        let stage = loaded.pipeline.stages.iter().find(|s| s.name == name);
        stage.map_or(0, |s| s.lag)
    };
    if a.json {
        let stages: serde_json::Map<String, serde_json::Value> = names
            .iter()
            .zip(per_stage.iter().zip(&alloc_peak_mb))
            .zip(&parts)
            .map(|(((n, k), (s, alloc)), parts)| {
                let mut timing = serde_json::json!({
                    "kind": k,
                    "median_ms": s.median_ms,
                    "p95_ms": s.p95_ms,
                    "max_ms": s.max_ms,
                    "mean_ms": s.mean_ms,
                    "every": every_of(n),
                    "lag": lag_of(n),
                    "alloc_peak_mb": alloc,
                });
                if !parts.is_empty() {
                    let parts: serde_json::Map<String, serde_json::Value> = parts
                        .iter()
                        .map(|(name, stats)| (name.to_string(), serde_json::json!(stats)))
                        .collect();
                    timing["parts"] = parts.into();
                }
                (n.clone(), timing)
            })
            .collect();
        let doc = serde_json::json!({
            "pipeline": loaded.pipeline.name,
            "recording": loaded.replay.recording.path().display().to_string(),
            "frames": frames,
            "repeat": reports.len(),
            "isolated": a.isolated,
            "interrupted": interrupted,
            "stages": stages,
            "fps": median_fps,
            "peak_resident_mb": peak_resident_mb,
        });
        outln!("{}", serde_json::to_string_pretty(&doc)?)?;
        return Ok(status);
    }
    let width = names
        .iter()
        .map(|(n, k)| n.len().max(k.len()))
        .max()
        .unwrap_or(5)
        .max(5);
    outln!(
        "{} on {}: {} frames x {} runs (after 1 warm-up){}",
        loaded.pipeline.name,
        loaded.replay.recording.path().display(),
        frames,
        reports.len(),
        if a.isolated {
            ", one frame at a time"
        } else {
            ""
        }
    )?;
    let alloc_column = match a.isolated {
        true => format!("  {:>14}", "peak alloc MB"),
        false => String::new(),
    };
    outln!(
        "{:<width$}  {:<width$}  {:>9}  {:>9}  {:>9}  {:>10}{alloc_column}",
        "stage",
        "kind",
        "median ms",
        "p95 ms",
        "max ms",
        "frames/s"
    )?;
    let (mut amortized, mut behind) = (Vec::new(), Vec::new());
    let stage_rows = names
        .iter()
        .zip(per_stage.iter().zip(&alloc_peak_mb))
        .zip(&parts);
    for (((n, k), (s, alloc)), parts) in stage_rows {
        let lag = lag_of(n);
        if lag > 0 {
            behind.push(format!("`{n}` (lag {lag})"));
        }
        let every = every_of(n);
        let typical = if every > 1 {
            amortized.push(format!("`{n}` (every {every})"));
            s.mean_ms
        } else {
            s.median_ms
        };
        let rate = if typical > 0.0 {
            1e3 / typical
        } else {
            f64::INFINITY
        };
        let alloc = match (a.isolated, alloc) {
            (true, Some(mb)) => format!("  {mb:>14.1}"),
            (true, None) => format!("  {:>14}", "-"),
            (false, _) => String::new(),
        };
        outln!(
            "{n:<width$}  {k:<width$}  {:>9.3}  {:>9.3}  {:>9.3}  {:>10.1}{alloc}",
            typical,
            s.p95_ms,
            s.max_ms,
            rate
        )?;
        for (part, p) in parts {
            let label = format!("  {part}");
            outln!(
                "{label:<width$}  {:<width$}  {:>9.3}  {:>9.3}  {:>9.3}",
                "(part)",
                p.median_ms,
                p.p95_ms,
                p.max_ms
            )?;
        }
    }
    if parts.iter().any(|p| !p.is_empty()) {
        outln!(
            "(part): a stage's own split of its time, each part's median over the frames (the \
             medians need not add up to the stage's)"
        )?;
    }
    if !amortized.is_empty() {
        outln!(
            "{}: the mean over all frames, its cost per frame amortized, in place of the median",
            amortized.join(", ")
        )?;
    }
    if !behind.is_empty() {
        outln!(
            "{}: the frame's wait for its own thread's result, not the time that thread computes (it overlaps the other stages, even with --isolated)",
            behind.join(", ")
        )?;
    }
    if let Some(mb) = peak_resident_mb {
        outln!("peak resident memory: {mb:.0} MB (the process, over loading and every run)")?;
    }
    if a.isolated {
        outln!(
            "end to end: {median_fps:.1} frames/s one frame at a time (median of {} runs); \
             without --isolated the stages overlap",
            reports.len()
        )?;
    } else {
        outln!(
            "end to end: {median_fps:.1} frames/s (median of {} runs); stage times include \
             waiting for cores that other stages hold: --isolated times each stage alone",
            reports.len()
        )?;
    }
    Ok(status)
}
