//! `relume batch MANIFEST [--shard I/N|auto]` and `relume batch --summary DIR`: every
//! recording of a manifest through every pipeline, one item after another, each into
//! `OUT/<item id>/` with a `DONE` marker last (see `relume::batch`).

/// A line on stderr that a closed pipe (`relume batch ... 2>&1 | head`) cannot turn
/// into a panic: the batch goes on, its markers and exit status say how it went.
macro_rules! note {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

use super::output;
use super::replay::{
    Pacing, RunArgs, check_saved_products, load, save_products, some_frame_replayed,
};
use anyhow::{Context, bail};
use clap::Parser;
use relume::batch::marker::{self, Marker, MarkerState, config_digest};
use relume::batch::shard::{self, resolve_auto};
use relume::batch::summary::{self, ItemStatus};
use relume::batch::{Item, Manifest, Settings, Shard, ShardSpec};
use relume::graph::Frame;
use relume::recording::writer::write_file_atomic;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

const MANIFEST: &str = "\
Manifest (TOML; paths relative to its folder):
  out = \"runs\"                         optional; default <manifest stem>-out beside it
  recordings = [\"a.relume\", \"data/b.relume\"]
  pipelines = [\"../pipelines/acquisition.toml\"]
  [settings]                           optional, for every run, as replay takes them:
  frames = \"0..50\"                     save = [\"normals\"]    save_format = [\"png\"]
  seed = 1    skip_corrupt = false     set = [\"STAGE.PARAM=VALUE\"]    max_pose_gap_ms = 100
  run_programs = false                 true lets pipelines with external stages start programs

Items: every recording through every pipeline, id <recording stem>__<pipeline stem>__<hash>
(hash: 8 hex digits of xxh3 of the two paths as written, ./ and // removed). Each writes
OUT/<id>/: the saved products, report.json (frames, per-frame product digests),
timings.json, then DONE.
A rerun skips items with a valid DONE and redoes the others from scratch.

Shards: an item belongs to shard xxh3(id) mod N, whatever its place in the manifest.
--shard auto reads SLURM_ARRAY_TASK_ID with SLURM_ARRAY_TASK_COUNT (or _MIN/_MAX), else
JOB_COMPLETION_INDEX with the count from --shards N or RELUME_SHARDS (Kubernetes sets no
count variable). deploy/slurm.sbatch and deploy/k8s-indexed-job.yaml are examples.

Exit status: 0 when every item of the shard is done, 1 when one failed, 75 when none
failed but another relume run still holds some (a resubmitted job still running them:
wait for it, or run again later), 130 when interrupted. --summary: 0 when every item is
done, 1 otherwise.";

#[derive(Parser, Debug)]
#[command(after_help = MANIFEST)]
pub struct BatchArgs {
    /// The manifest (TOML): recordings, pipelines, settings, output folder.
    manifest: Option<PathBuf>,
    /// Run only shard I of N (0-based: I/N), or `auto` to take it from a Slurm job array
    /// or a Kubernetes Indexed Job. Default: every item.
    #[arg(long, value_name = "I/N|auto")]
    shard: Option<String>,
    /// The shard count for --shard auto where the scheduler gives none (a Kubernetes
    /// Indexed Job: its completions); the variable RELUME_SHARDS does the same.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    shards: Option<u64>,
    /// The output folder, instead of the manifest's `out`.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print the state of every item (done, failed, missing) of an output folder
    /// (default: the manifest's) instead of running anything.
    #[arg(long, value_name = "DIR", num_args = 0..=1)]
    summary: Option<Option<PathBuf>>,
    /// With --summary: JSON instead of a table.
    #[arg(long, requires = "summary")]
    json: bool,
}

pub fn batch(a: BatchArgs) -> anyhow::Result<i32> {
    if let Some(dir) = &a.summary {
        let dir = match (dir, &a.out, &a.manifest) {
            (Some(d), _, _) | (None, Some(d), _) => d.clone(),
            (None, None, Some(m)) => Manifest::load(m)?.out,
            (None, None, None) => bail!("--summary needs a folder (or a manifest to take it from)"),
        };
        return summarize(&dir, a.json);
    }
    let Some(manifest_path) = &a.manifest else {
        bail!("relume batch needs a manifest (or --summary DIR); see relume batch --help");
    };
    // The shard spec first: a wrong one is an error before anything is read.
    let spec = a.shard.as_deref().map(ShardSpec::parse).transpose()?;
    let manifest = Manifest::load(manifest_path)?;
    let (shard, from) = match spec {
        None if a.shards.is_some() => {
            bail!(
                "--shards gives the shard count for --shard auto: give --shard auto (or --shard I/N)"
            )
        }
        None => (Shard::ALL, "every item".to_string()),
        Some(ShardSpec::Fixed(s)) => {
            if let Some(n) = a.shards.filter(|&n| n != s.count) {
                bail!("--shards {n} disagrees with --shard {s}");
            }
            (s, format!("--shard {s}"))
        }
        Some(ShardSpec::Auto) => {
            let (s, from) = resolve_auto(&|name| std::env::var(name).ok(), a.shards)?;
            (s, format!("--shard auto: {from}"))
        }
    };
    let out = a.out.clone().unwrap_or_else(|| manifest.out.clone());
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    summary::write_items(&out, &manifest.items)?;
    let mine = shard::select(&manifest.items, |i| &i.id, shard);
    note!(
        "shard {shard} ({from}): {} of the manifest's {} items, into {}",
        mine.len(),
        manifest.items.len(),
        out.display()
    );
    if shard.count > manifest.items.len() as u64 {
        note!(
            "warning: {} shards for {} items: at least {} shards have nothing to run{}; a \
             job array as large as the item count is enough",
            shard.count,
            manifest.items.len(),
            shard.count - manifest.items.len() as u64,
            if mine.is_empty() {
                ", this one among them"
            } else {
                ""
            }
        );
    }
    let stop = super::replay::stop_on_interrupt();
    let (mut ran, mut skipped, mut failed, mut busy) = (0, 0, 0, 0);
    for (k, item) in mine.iter().enumerate() {
        if stop.load(Ordering::SeqCst) {
            break;
        }
        let prefix = format!("[{}/{}] {}", k + 1, mine.len(), item.id);
        match run_or_skip(item, &manifest.settings, &out, &stop, &prefix) {
            Ok(Outcome::Skipped) => skipped += 1,
            Ok(Outcome::Ran) => ran += 1,
            Ok(Outcome::Busy) => busy += 1,
            Ok(Outcome::Interrupted) => break,
            Err(e) => {
                failed += 1;
                note!("{prefix}: FAILED: {}", output::report(&e));
            }
        }
    }
    let mut line = format!(
        "shard {shard}: {} item(s): ran {ran}, skipped {skipped} (done earlier), failed {failed}",
        mine.len()
    );
    if busy > 0 {
        line.push_str(&format!(
            ", {busy} left to another run that holds them (see their DONE or FAILED there)"
        ));
    }
    if stop.load(Ordering::SeqCst) {
        note!("{line}; interrupted: the others were not run");
        return Ok(130);
    }
    note!("{line}");
    Ok(exit_status(failed, busy))
}

/// EX_TEMPFAIL (sysexits.h): the items left to another run are not done yet, so a
/// scheduler's "after this job succeeded" must not fire on this run.
const ITEMS_HELD_ELSEWHERE: i32 = 75;

fn exit_status(failed: usize, busy: usize) -> i32 {
    match (failed, busy) {
        (0, 0) => 0,
        (0, _) => ITEMS_HELD_ELSEWHERE,
        _ => 1,
    }
}

enum Outcome {
    Skipped,
    Ran,
    /// Another process holds the item's lock.
    Busy,
    Interrupted,
}

/// Runs `item` unless its marker says it is done; a failure leaves `FAILED` and no
/// marker.
fn run_or_skip(
    item: &Item,
    settings: &Settings,
    out: &Path,
    stop: &Arc<AtomicBool>,
    prefix: &str,
) -> anyhow::Result<Outcome> {
    let dir = out.join(&item.id);
    // Before the marker is read: another run of this item (a resubmitted job array, two
    // shards that overlap) would clear the folder under this one, or this one under it.
    let _lock = match super::lock::lock_item(out, &item.id)? {
        Ok(lock) => lock,
        Err(holder) => {
            note!("{prefix}: being run by another relume process ({holder}): left to it");
            return Ok(Outcome::Busy);
        }
    };
    let pipeline_text = relume::files::read_regular_to_string(&item.pipeline_path)
        .with_context(|| format!("cannot read {}", item.pipeline_path.display()))?;
    let recording = marker::recording_digest(&item.recording_path)
        .with_context(|| format!("cannot read {}", item.recording_path.display()))?;
    let config = config_digest(
        &format!("{}\nrecording {recording:016x}", settings.canonical()),
        &pipeline_text,
    );
    match Marker::check(&dir, &item.id, Some(config)) {
        MarkerState::Valid(_) => {
            note!("{prefix}: done earlier, skipped");
            return Ok(Outcome::Skipped);
        }
        MarkerState::Invalid(why) => note!("{prefix}: {why}: running it again"),
        MarkerState::Absent if dir.exists() => {
            note!(
                "{prefix}: its folder has no DONE marker (a failed or interrupted run): running it again"
            )
        }
        MarkerState::Absent => {}
    }
    marker::clear(&dir)?;
    note!("{prefix}: {} through {}", item.recording, item.pipeline);
    let started = Instant::now();
    match run_item(item, settings, &dir, stop, started) {
        Ok(true) => {
            Marker::of(&dir, &item.id, config)?.write(&dir)?;
            note!("{prefix}: done in {:.1} s", started.elapsed().as_secs_f64());
            Ok(Outcome::Ran)
        }
        Ok(false) => {
            note!("{prefix}: interrupted; it has no DONE marker and runs again next time");
            Ok(Outcome::Interrupted)
        }
        Err(e) => {
            marker::write_failed(&dir, &output::report(&e))?;
            Err(e)
        }
    }
}

/// Replays `item` as `relume replay` does, into `dir`; `false` when interrupted.
fn run_item(
    item: &Item,
    settings: &Settings,
    dir: &Path,
    stop: &Arc<AtomicBool>,
    started: Instant,
) -> anyhow::Result<bool> {
    let run_args = RunArgs {
        recording: Some(item.recording_path.clone()),
        pipeline: Some(item.pipeline_path.clone()),
        frames: settings.frames.clone(),
        skip_corrupt: settings.skip_corrupt,
        seed: settings.seed,
        overrides: settings.set.clone(),
        max_pose_gap: settings.max_pose_gap_ns,
    };
    let loaded = load(&run_args)?;
    let programs = relume::stages::external::programs(&loaded.pipeline.stages);
    if let Some((stage, command)) = programs.first().filter(|_| !settings.run_programs) {
        anyhow::bail!(
            "{}: stage `{stage}` would start `{command}`: a batch starts programs only when \
             its manifest's [settings] say run_programs = true",
            item.pipeline
        );
    }
    check_saved_products(&loaded.pipeline, &settings.save)?;
    let bar = super::progress::bar(loaded.frames.len() as u64, "replaying", "frames");
    let mut hashes = Vec::new();
    let mut save_error: Option<anyhow::Error> = None;
    let mut sink = |frame: Frame| {
        bar.inc(1);
        if !settings.save.is_empty()
            && save_error.is_none()
            && let Err(e) = save_products(&frame, &settings.save, &settings.save_format, dir)
        {
            save_error = Some(e);
            stop.store(true, Ordering::SeqCst);
        }
        let products: serde_json::Map<String, serde_json::Value> = frame
            .products()
            .map(|(name, p)| (name.to_string(), format!("{:016x}", p.digest()).into()))
            .collect();
        hashes.push(serde_json::json!({
            "frame": frame.index, "stamp_ns": frame.stamp_ns, "products": products
        }));
    };
    let result = loaded.run_once(dir, &run_args, Pacing::Pipelined, stop, &mut sink);
    bar.finish_and_clear();
    if let Some(e) = save_error {
        // The flag stopped this item's replay, not the batch: the next items still run
        // (a signal in the same instant is lost; a second one stops the batch).
        stop.store(false, Ordering::SeqCst);
        return Err(e.context("saving products"));
    }
    let report = match result {
        Ok(r) => r,
        Err(f) => return Err(anyhow::Error::new(f.error).context("the replay stopped")),
    };
    if report.interrupted {
        return Ok(false);
    }
    some_frame_replayed(&loaded, &report)?;
    let skipped: Vec<serde_json::Value> = report
        .skipped_corrupt
        .iter()
        .map(|(frame, cause)| serde_json::json!({ "frame": frame, "cause": cause }))
        .collect();
    // Deterministic content only: no times, no absolute paths.
    let content = serde_json::json!({
        "id": item.id,
        "recording": item.recording,
        "pipeline": item.pipeline,
        "pipeline_name": loaded.pipeline.name,
        "frames": { "start": loaded.frames.start, "end": loaded.frames.end },
        "frames_out": report.frames_out,
        "skipped_corrupt": skipped,
        "saved": settings.save,
        "hashes": hashes,
    });
    write_json(&dir.join(marker::REPORT), &content)?;
    let timings = serde_json::json!({
        "wall_s": started.elapsed().as_secs_f64(),
        "run": report.summary_json(),
    });
    write_json(&dir.join(marker::TIMINGS), &timings)?;
    Ok(true)
}

fn write_json(path: &Path, value: &serde_json::Value) -> anyhow::Result<()> {
    let mut bytes = serde_json::to_vec_pretty(value)?;
    bytes.push(b'\n');
    write_file_atomic(path, &bytes).with_context(|| format!("cannot write {}", path.display()))
}

/// `--summary`: a table (or JSON) of every item of `dir`.
fn summarize(dir: &Path, json: bool) -> anyhow::Result<i32> {
    if !dir.is_dir() {
        bail!("--summary {}: no such folder", dir.display());
    }
    if summary::read_items(dir)?.is_none() {
        note!(
            "warning: {} has no {}: only items with a folder are listed, not those no shard \
             has started",
            dir.display(),
            summary::ITEMS
        );
    }
    let items = summary::summarize(dir)?;
    let count = |s: ItemStatus| items.iter().filter(|i| i.status == s).count();
    let (done, failed, missing) = (
        count(ItemStatus::Done),
        count(ItemStatus::Failed),
        count(ItemStatus::Missing),
    );
    if json {
        let value = serde_json::json!({
            "out": dir.display().to_string(),
            "counts": { "done": done, "failed": failed, "missing": missing },
            "items": items,
        });
        outln!("{}", serde_json::to_string_pretty(&value)?)?;
    } else {
        let width = items.iter().map(|i| i.id.len()).max().unwrap_or(4).max(4);
        outln!(
            "{:width$}  {:7}  {:>6}  {:>5}  {:>10}  {:>7}  {:>6}  note",
            "item",
            "status",
            "frames",
            "files",
            "bytes",
            "wall_s",
            "fps"
        )?;
        let opt = |v: Option<String>| v.unwrap_or_else(|| "-".into());
        for i in &items {
            let line = format!(
                "{:width$}  {:7}  {:>6}  {:>5}  {:>10}  {:>7}  {:>6}  {}",
                i.id,
                i.status.name(),
                opt(i.frames.map(|v| v.to_string())),
                opt(i.files.map(|v| v.to_string())),
                opt(i.bytes.map(|v| v.to_string())),
                opt(i.wall_s.map(|v| format!("{v:.2}"))),
                opt(i.fps.map(|v| format!("{v:.1}"))),
                i.note.as_deref().unwrap_or("")
            );
            outln!("{}", line.trim_end())?;
        }
        outln!(
            "{} item(s): {done} done, {failed} failed, {missing} missing",
            items.len()
        )?;
    }
    Ok(if done == items.len() { 0 } else { 1 })
}
