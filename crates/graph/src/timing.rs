//! Per-frame timings of every stage, their summary (median, p95, max), the end-of-run
//! table, per-frame CSV/JSON rows and a Chrome trace that Perfetto opens.

use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// What one stage spent on one frame, in nanoseconds since the run started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FrameTiming {
    pub frame: usize,
    /// When processing began.
    pub start_ns: u64,
    /// Waiting for the frame (and its feedback inputs) before processing.
    pub wait_in_ns: u64,
    pub process_ns: u64,
    /// Waiting for room in the output channel after processing.
    pub wait_out_ns: u64,
    /// The part of `process_ns` a program outside relume says it computed (an external
    /// stage's reply); the rest of it is transport. `None` for relume's own stages.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub program_ns: Option<u64>,
    /// The most bytes the stage held allocated at once while processing the frame,
    /// beyond what was allocated before (lockstep runs with the counting allocator
    /// only: see [`super::memory::CountingAllocator`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alloc_peak_bytes: Option<u64>,
    /// `process_ns` split into the parts the stage names (see
    /// [`Stage::parts`](crate::Stage::parts)); `None` for stages that do not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parts: Option<Parts>,
}

/// Most parts a stage splits a frame's time into.
pub const MAX_PARTS: usize = 4;

/// A stage's processing time of one frame split into named parts, as the stage
/// measured them: `sample.path`'s material estimation, virtual object and
/// differential background (paper 000 Table 2's rows), say. Serialized as a map from
/// name to nanoseconds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Parts {
    /// The parts' names, at most [`MAX_PARTS`].
    pub names: &'static [&'static str],
    /// Nanoseconds per part, in `names`' order (the rest are 0).
    pub ns: [u64; MAX_PARTS],
}

impl Parts {
    /// Each part's name and nanoseconds.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        self.names.iter().copied().zip(self.ns.iter().copied())
    }
}

impl Serialize for Parts {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(self.iter())
    }
}

/// All frames of one stage.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StageTimings {
    pub name: String,
    pub kind: String,
    pub frames: Vec<FrameTiming>,
}

impl StageTimings {
    pub fn new(name: &str, kind: &str) -> StageTimings {
        StageTimings {
            name: name.into(),
            kind: kind.into(),
            frames: Vec::new(),
        }
    }

    /// Summary of processing times.
    pub fn process(&self) -> Stats {
        Stats::of(self.frames.iter().map(|f| f.process_ns))
    }

    /// Summary of waiting times (input plus output).
    /// The program's own time and the rest of processing (transport), for a stage
    /// whose frames report it ([`FrameTiming::program_ns`]).
    pub fn program_and_transport(&self) -> Option<(Stats, Stats)> {
        let split: Vec<(u64, u64)> = self
            .frames
            .iter()
            .filter_map(|f| Some((f.program_ns?, f.process_ns.saturating_sub(f.program_ns?))))
            .collect();
        if split.is_empty() {
            return None;
        }
        Some((
            Stats::of(split.iter().map(|s| s.0)),
            Stats::of(split.iter().map(|s| s.1)),
        ))
    }

    /// Summary of each named part's time, for a stage whose frames report parts
    /// ([`FrameTiming::parts`]), in the order the stage names them.
    pub fn parts(&self) -> Vec<(&'static str, Stats)> {
        parts_of(self.frames.iter())
    }

    pub fn wait(&self) -> Stats {
        Stats::of(self.frames.iter().map(|f| f.wait_in_ns + f.wait_out_ns))
    }
}

/// Summary of each named part's time over `frames` (those that report parts), in the
/// order of the first frame that does.
pub fn parts_of<'a>(frames: impl Iterator<Item = &'a FrameTiming>) -> Vec<(&'static str, Stats)> {
    let mut names: Vec<&'static str> = Vec::new();
    let mut samples: Vec<Vec<u64>> = Vec::new();
    for parts in frames.filter_map(|f| f.parts) {
        for (name, ns) in parts.iter() {
            let i = match names.iter().position(|n| *n == name) {
                Some(i) => i,
                None => {
                    names.push(name);
                    samples.push(Vec::new());
                    names.len() - 1
                }
            };
            samples[i].push(ns);
        }
    }
    names
        .into_iter()
        .zip(samples)
        .map(|(name, ns)| (name, Stats::of(ns)))
        .collect()
}

/// Median, 95th percentile and maximum, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Stats {
    pub median_ms: f64,
    pub p95_ms: f64,
    pub max_ms: f64,
    /// The mean: a stage with `every = k` costs this per frame, amortized.
    pub mean_ms: f64,
}

impl Stats {
    /// Summarizes nanosecond samples (all zero when there are none).
    pub fn of(samples: impl IntoIterator<Item = u64>) -> Stats {
        let mut v: Vec<u64> = samples.into_iter().collect();
        if v.is_empty() {
            return Stats::default();
        }
        v.sort_unstable();
        let ms = |ns: f64| ns * 1e-6;
        Stats {
            median_ms: ms(percentile(&v, 0.5)),
            p95_ms: ms(percentile(&v, 0.95)),
            max_ms: ms(*v.last().expect("non-empty") as f64),
            mean_ms: ms(v.iter().map(|&ns| ns as f64).sum::<f64>() / v.len() as f64),
        }
    }
}

/// "material median 1.000 ms, object 2.000 ms, ..." for a stage's parts.
pub fn parts_line(parts: &[(&str, Stats)]) -> String {
    let each: Vec<String> = parts
        .iter()
        .enumerate()
        .map(|(i, (name, stats))| match i {
            0 => format!("{name} median {:.3} ms", stats.median_ms),
            _ => format!("{name} {:.3} ms", stats.median_ms),
        })
        .collect();
    each.join(", ")
}

/// Linear-interpolated percentile of sorted samples.
fn percentile(sorted: &[u64], p: f64) -> f64 {
    let pos = p * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    let w = pos - lo as f64;
    sorted[lo] as f64 * (1.0 - w) + sorted[hi] as f64 * w
}

/// What a run measured.
#[derive(Clone, Debug, Default)]
pub struct RunReport {
    /// The source first, then every stage in pipeline order.
    pub stages: Vec<StageTimings>,
    /// End-to-end latency of each frame that left the pipeline.
    pub latencies_ns: Vec<u64>,
    pub frames_out: usize,
    pub wall_ns: u64,
    /// Frames skipped as corrupt (with `--skip-corrupt`): index and cause.
    pub skipped_corrupt: Vec<(usize, String)>,
    /// Stopped early by a stop request (Ctrl-C).
    pub interrupted: bool,
}

impl RunReport {
    /// Frames per second over the whole run.
    pub fn fps(&self) -> f64 {
        if self.wall_ns == 0 {
            0.0
        } else {
            self.frames_out as f64 / (self.wall_ns as f64 * 1e-9)
        }
    }

    pub fn latency(&self) -> Stats {
        Stats::of(self.latencies_ns.iter().copied())
    }

    /// The end-of-run table: per stage median, p95 and max of processing time, median
    /// wait, then throughput and latency.
    pub fn table(&self) -> String {
        let width = self
            .stages
            .iter()
            .map(|s| s.name.len().max(s.kind.len()))
            .max()
            .unwrap_or(5)
            .max(5);
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{:<width$}  {:<width$}  {:>6}  {:>9}  {:>9}  {:>9}  {:>9}",
            "stage", "kind", "frames", "median ms", "p95 ms", "max ms", "wait ms"
        );
        for s in &self.stages {
            let p = s.process();
            let _ = writeln!(
                out,
                "{:<width$}  {:<width$}  {:>6}  {:>9.3}  {:>9.3}  {:>9.3}  {:>9.3}",
                s.name,
                s.kind,
                s.frames.len(),
                p.median_ms,
                p.p95_ms,
                p.max_ms,
                s.wait().median_ms
            );
        }
        for s in &self.stages {
            let parts = s.parts();
            if !parts.is_empty() {
                let _ = writeln!(out, "{}: {}", s.name, parts_line(&parts));
            }
        }
        for s in &self.stages {
            if let Some((program, transport)) = s.program_and_transport() {
                let _ = writeln!(
                    out,
                    "{}: the program's own time median {:.3} ms, transport median {:.3} ms",
                    s.name, program.median_ms, transport.median_ms
                );
            }
        }
        let l = self.latency();
        let _ = writeln!(
            out,
            "{} frames in {:.3} s: {:.1} frames/s; latency median {:.3} ms, p95 {:.3} ms, max {:.3} ms",
            self.frames_out,
            self.wall_ns as f64 * 1e-9,
            self.fps(),
            l.median_ms,
            l.p95_ms,
            l.max_ms
        );
        out
    }

    /// Writes per-frame rows as CSV (`.csv`) or JSON (anything else).
    pub fn write_timings(&self, path: &Path) -> std::io::Result<()> {
        let csv = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        let bytes = if csv {
            let mut out = String::from(
                "stage,kind,frame,start_ms,wait_in_ms,process_ms,wait_out_ms,program_ms\n",
            );
            for s in &self.stages {
                for f in &s.frames {
                    let _ = writeln!(
                        out,
                        "{},{},{},{:.6},{:.6},{:.6},{:.6},{}",
                        s.name,
                        s.kind,
                        f.frame,
                        f.start_ns as f64 * 1e-6,
                        f.wait_in_ns as f64 * 1e-6,
                        f.process_ns as f64 * 1e-6,
                        f.wait_out_ns as f64 * 1e-6,
                        f.program_ns
                            .map(|ns| format!("{:.6}", ns as f64 * 1e-6))
                            .unwrap_or_default()
                    );
                }
            }
            out.into_bytes()
        } else {
            #[derive(Serialize)]
            struct Row<'a> {
                stage: &'a str,
                kind: &'a str,
                #[serde(flatten)]
                timing: &'a FrameTiming,
            }
            let rows: Vec<Row> = self
                .stages
                .iter()
                .flat_map(|s| {
                    s.frames.iter().map(move |f| Row {
                        stage: &s.name,
                        kind: &s.kind,
                        timing: f,
                    })
                })
                .collect();
            serde_json::to_vec_pretty(
                &serde_json::json!({ "frames": rows, "summary": self.summary_json() }),
            )
            .map_err(std::io::Error::other)?
        };
        relume_recording::writer::write_file_atomic(path, &bytes)
    }

    /// Per-stage summary as JSON: `stages.<name>.{median_ms, p95_ms, max_ms, wait_median_ms}`,
    /// `fps`, `frames`, `latency`.
    pub fn summary_json(&self) -> serde_json::Value {
        let stages: serde_json::Map<String, serde_json::Value> = self
            .stages
            .iter()
            .map(|s| {
                let p = s.process();
                let mut stage = serde_json::json!({ "kind": s.kind, "frames": s.frames.len(), "median_ms": p.median_ms, "p95_ms": p.p95_ms, "max_ms": p.max_ms, "wait_median_ms": s.wait().median_ms });
                let parts = s.parts();
                if !parts.is_empty() {
                    stage["parts_median_ms"] = parts
                        .iter()
                        .map(|(name, stats)| (name.to_string(), stats.median_ms.into()))
                        .collect::<serde_json::Map<_, _>>()
                        .into();
                }
                if let Some((program, transport)) = s.program_and_transport() {
                    stage["program_median_ms"] = program.median_ms.into();
                    stage["transport_median_ms"] = transport.median_ms.into();
                }
                (s.name.clone(), stage)
            })
            .collect();
        serde_json::json!({ "stages": stages, "fps": self.fps(), "frames": self.frames_out, "latency": self.latency() })
    }

    /// Writes a Chrome trace (JSON array format): one track per stage, with processing
    /// and waiting as spans; chrome://tracing and Perfetto open it.
    pub fn write_trace(&self, path: &Path) -> std::io::Result<()> {
        let mut events = Vec::new();
        for (tid, s) in self.stages.iter().enumerate() {
            events.push(serde_json::json!({ "ph": "M", "name": "thread_name", "pid": 1, "tid": tid, "args": { "name": format!("{} ({})", s.name, s.kind) } }));
            events.push(serde_json::json!({ "ph": "M", "name": "thread_sort_index", "pid": 1, "tid": tid, "args": { "sort_index": tid } }));
            for f in &s.frames {
                let us = |ns: u64| ns as f64 * 1e-3;
                let span = |name: String, cat: &str, start: u64, dur: u64| serde_json::json!({ "ph": "X", "name": name, "cat": cat, "pid": 1, "tid": tid, "ts": us(start), "dur": us(dur), "args": { "frame": f.frame } });
                if f.wait_in_ns > 0 {
                    events.push(span(
                        "wait input".into(),
                        "wait",
                        f.start_ns - f.wait_in_ns,
                        f.wait_in_ns,
                    ));
                }
                events.push(span(
                    format!("{} #{}", s.name, f.frame),
                    "process",
                    f.start_ns,
                    f.process_ns,
                ));
                if f.wait_out_ns > 0 {
                    events.push(span(
                        "wait output".into(),
                        "wait",
                        f.start_ns + f.process_ns,
                        f.wait_out_ns,
                    ));
                }
            }
        }
        let bytes = serde_json::to_vec(
            &serde_json::json!({ "traceEvents": events, "displayTimeUnit": "ms" }),
        )
        .map_err(std::io::Error::other)?;
        relume_recording::writer::write_file_atomic(path, &bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_interpolate() {
        let s = Stats::of([1_000_000, 2_000_000, 3_000_000, 4_000_000, 100_000_000]);
        assert_eq!(s.median_ms, 3.0);
        assert_eq!(s.max_ms, 100.0);
        assert!((s.p95_ms - 80.8).abs() < 1e-9, "{}", s.p95_ms);
        assert_eq!(Stats::of([]), Stats::default());
    }
}
