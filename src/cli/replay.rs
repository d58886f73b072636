//! `relume replay` and `relume bench`.

use super::output::{self, default_recording_path};
use super::prepare;
use super::{produce, progress};
use anyhow::{Context, bail};
use clap::{Args, Parser};
use relume::graph::{Frame, Pipeline, Registry, RunFailure, RunOptions, RunReport, run};
use relume::light::EnvCloud;
use relume::recording::writer::write_file_atomic;
use relume::recording::{Replay, ReplayOptions};
use relume::stages::kind;
use relume::stages::write::ply::ply_bytes;
use relume::stages::write::{write_exr, write_png, write_record};
use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// What replay and bench share: which recording, which pipeline, which frames.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// The recording (.relume). Default: the built-in synthetic recording, generated into
    /// recordings/default.relume on first use.
    pub(super) recording: Option<PathBuf>,
    /// Pipeline file (TOML). Default: the built-in pipelines/default.toml.
    #[arg(short, long)]
    pub(super) pipeline: Option<PathBuf>,
    /// Frames to replay: A..B (B excluded), A.., ..B or a single index N. Default: every
    /// frame.
    #[arg(long, value_parser = parse_frames)]
    pub(super) frames: Option<Range<usize>>,
    /// Skip (and count) frames with corrupt records, or with images that do not decode
    /// (as inspect --verify finds them), instead of stopping with an error.
    #[arg(long)]
    pub(super) skip_corrupt: bool,
    /// Seed for stages that draw random numbers.
    #[arg(long, default_value_t = 1)]
    pub(super) seed: u64,
    /// Change a stage's parameter for this run, as if the pipeline file said so:
    /// STAGE.PARAM=VALUE, STAGE being the stage's name (its kind when it has none).
    /// Repeatable. E.g. --set sample.path.query=vct --set sample.path.direct=8
    #[arg(long = "set", value_name = "STAGE.PARAM=VALUE")]
    pub(super) overrides: Vec<relume::graph::ParamOverride>,
    /// The largest gap between two pose samples that a frame's pose is interpolated
    /// across, in milliseconds (default: five times the pose stream's median interval,
    /// at least 50 ms). Frames in longer gaps have no pose: a stage that needs one stops
    /// there, and the run says how many there are.
    #[arg(long, value_name = "MS", value_parser = parse_gap_ms)]
    pub(super) max_pose_gap: Option<i64>,
}

/// `--max-pose-gap`: milliseconds, positive and finite, as nanoseconds.
pub(super) fn parse_gap_ms(text: &str) -> Result<i64, String> {
    match text.trim().parse::<f64>() {
        Ok(ms) if (1e-6..1e12).contains(&ms) => Ok((ms * 1e6).round() as i64),
        _ => Err(format!(
            "invalid gap {text:?}: expected milliseconds, a positive number"
        )),
    }
}

#[derive(Parser, Debug)]
pub struct ReplayArgs {
    #[command(flatten)]
    run: RunArgs,
    /// Directory that `write` stages save into.
    #[arg(short, long, default_value = "out")]
    out: PathBuf,
    /// Remove the frames an earlier run left in the folders this run writes (else a
    /// warning names those outside this run's frames, which it does not replace).
    #[arg(long)]
    clean_out: bool,
    /// Write per-frame timings of every stage (FILE.csv or FILE.json: the extension picks
    /// the format).
    #[arg(long, value_name = "FILE")]
    timings: Option<PathBuf>,
    /// Write a Chrome trace (open it in Perfetto or chrome://tracing).
    #[arg(long, value_name = "FILE.json")]
    trace: Option<PathBuf>,
    /// Print one line per frame with a digest of every product (the timing table then
    /// goes to stderr), to compare runs frame by frame.
    #[arg(long)]
    hash: bool,
    /// Save these products of every frame into OUT/<product>/ (comma-separated names, or
    /// `all` for every image, compensation, cloud and pose in the frame), without editing
    /// the pipeline. A pose is saved as one line of a TUM trajectory file: `cat
    /// OUT/pose/*.txt` is the run's trajectory. `relume stages` says what each stage
    /// produces.
    #[arg(long, value_delimiter = ',', value_name = "PRODUCTS")]
    save: Vec<String>,
    /// File formats for --save: png, exr (f32 values), or both (png,exr). PNGs of
    /// colors, normals and radiance are 8-bit for viewing; depth PNGs hold 16-bit
    /// millimetres (exact, but a viewer shows them near-black: 1 m is 1000 of 65535).
    #[arg(long, value_delimiter = ',', default_value = "png", value_parser = ["png", "exr"])]
    save_format: Vec<String>,
    /// After the run, save the last frame's environment-sample cloud as a binary PLY
    /// (opens in MeshLab or CloudCompare).
    #[arg(long, value_name = "FILE.ply")]
    export_cloud: Option<PathBuf>,
}

/// `--frames`: shared with batch manifests' `frames` setting.
pub(super) use relume::recording::replay::parse_frames;

/// A recording and pipeline loaded and checked, ready to run.
pub(super) struct Loaded {
    pub(super) replay: Replay,
    pub(super) pipeline: Pipeline,
    registry: Registry,
    pub(super) frames: Range<usize>,
}

pub(super) fn load(args: &RunArgs) -> anyhow::Result<Loaded> {
    let registry = relume::stages::registry();
    let pipeline = match &args.pipeline {
        Some(p) => Pipeline::load_with(p, &registry, &args.overrides)?,
        None => Pipeline::builtin_default_with(&registry, &args.overrides)?,
    };
    let (replay, frames) = open_recording(args)?;
    let mut pipeline = pipeline;
    prepare::announce_programs(&pipeline);
    prepare::place_objects(&mut pipeline, &replay, frames.start, "")?;
    Ok(Loaded {
        replay,
        pipeline,
        registry,
        frames,
    })
}

/// The recording `args` names (the built-in one, generated on first use, when none)
/// and the frames of it to replay: an error when it has none, or when `--frames`
/// starts past its end.
pub(super) fn open_recording(args: &RunArgs) -> anyhow::Result<(Replay, Range<usize>)> {
    let path = match &args.recording {
        Some(p) => p.clone(),
        None => {
            let p = default_recording_path();
            produce::ensure_default_recording(&p)?;
            p
        }
    };
    let replay = Replay::open(
        &path,
        ReplayOptions {
            skip_corrupt: args.skip_corrupt,
            max_pose_gap_ns: args.max_pose_gap,
            ..Default::default()
        },
    )?;
    let stats = &replay.stats;
    if stats.frames_in_pose_gaps > 0 {
        eprintln!(
            "warning: {}: {} of {} frames lie in gaps of the pose stream longer than {:.0} ms \
             and have no pose: poses are not interpolated across such gaps (--max-pose-gap \
             sets the limit)",
            path.display(),
            stats.frames_in_pose_gaps,
            stats.frames,
            stats.max_pose_gap_ns.unwrap_or(0) as f64 * 1e-6
        );
    }
    if let Some(stamp) = stats.first_duplicate_stamp_ns {
        eprintln!(
            "warning: {}: {} color record(s) share their stamp with the one before (the \
             first at {stamp} ns): each is replayed as a frame of its own, with the same \
             depth and pose",
            path.display(),
            stats.duplicate_color_stamps,
        );
    }
    if let Some(damage) = replay.recording.damage() {
        eprintln!(
            "warning: {damage}; replaying the {} complete frames it holds",
            replay.len()
        );
    }
    if replay.is_empty() {
        bail!(
            "{}: no frames to replay ({} color records, {} skipped without depth)",
            path.display(),
            replay.stats.color_records,
            replay.stats.skipped_no_depth
        );
    }
    let frames = args.frames.clone().unwrap_or(0..usize::MAX);
    if frames.start >= replay.len() {
        bail!(
            "--frames starts at {} but {} has {} frames",
            frames.start,
            path.display(),
            replay.len()
        );
    }
    // An open end (`A..`) means the last frame; an explicit one past it is worth a word.
    if frames.end != usize::MAX && frames.end > replay.len() {
        eprintln!(
            "warning: --frames ends at {} but {} has {} frames: replaying {}..{}",
            frames.end,
            path.display(),
            replay.len(),
            frames.start,
            replay.len()
        );
    }
    let frames = frames.start..frames.end.min(replay.len());
    Ok((replay, frames))
}

impl Loaded {
    /// Builds the stages (with `run_args`' seed) and runs them once over the frames, fed
    /// as `pacing` says.
    pub(super) fn run_once(
        &self,
        out_dir: &Path,
        run_args: &RunArgs,
        pacing: Pacing,
        stop: &Arc<AtomicBool>,
        sink: &mut dyn FnMut(Frame),
    ) -> Result<RunReport, Box<RunFailure>> {
        let stages = match self.pipeline.build(
            &self.registry,
            self.replay.recording.header(),
            out_dir,
            run_args.seed,
        ) {
            Ok(s) => s,
            Err((stage, source)) => {
                let line = self.pipeline.stages.iter().find(|s| s.name == stage);
                let at = match line {
                    Some(s) => format!("{}:{}", self.pipeline.file, s.line),
                    None => self.pipeline.file.clone(),
                };
                return Err(Box::new(RunFailure {
                    error: relume::graph::PipelineError::Build { at, stage, source },
                    report: RunReport::default(),
                }));
            }
        };
        let options = RunOptions {
            frames: self.frames.clone(),
            skip_corrupt: run_args.skip_corrupt,
            stop: stop.clone(),
            lockstep: pacing == Pacing::Lockstep,
        };
        run(&self.pipeline, stages, &self.replay, &options, sink)
    }
}

/// How [`Loaded::run_once`] feeds frames to the pipeline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Pacing {
    /// The stages work on different frames at once, as a replay does.
    Pipelined,
    /// One frame in the pipeline at a time ([`RunOptions::lockstep`]).
    Lockstep,
}

/// A flag that the first Ctrl-C (or SIGTERM) sets; a second one exits (see
/// [`super::interrupt`]).
pub(super) fn stop_on_interrupt() -> Arc<AtomicBool> {
    super::interrupt::stop_flag()
}

/// An error before the run when --save names a product no stage of `pipeline` makes.
pub(super) fn check_saved_products(pipeline: &Pipeline, names: &[String]) -> anyhow::Result<()> {
    let made: Vec<&str> = pipeline
        .stages
        .iter()
        .flat_map(|s| s.outputs.values().map(String::as_str))
        .collect();
    for name in names.iter().filter(|n| *n != "all") {
        if !made.contains(&name.as_str()) {
            bail!(
                "--save: pipeline `{}` makes no product `{name}`; it makes: {}",
                pipeline.name,
                made.join(", ")
            );
        }
    }
    Ok(())
}

/// An error when a comma-separated option names an entry twice (two writers would race
/// for one file).
fn check_no_repeats(option: &str, names: &[String]) -> anyhow::Result<()> {
    for (i, name) in names.iter().enumerate() {
        if names[..i].contains(name) {
            bail!("{option} names {name:?} twice");
        }
    }
    Ok(())
}

pub fn replay(a: ReplayArgs) -> anyhow::Result<i32> {
    // The options first: loading may render the built-in recording.
    check_no_repeats("--save", &a.save)?;
    check_no_repeats("--save-format", &a.save_format)?;
    let outputs = [
        ("--timings", &a.timings, &["csv", "json"][..]),
        ("--trace", &a.trace, &["json"][..]),
        ("--export-cloud", &a.export_cloud, &["ply"][..]),
    ];
    for (i, (option, path, extensions)) in outputs.iter().enumerate() {
        let Some(path) = path else { continue };
        output::check_output_file(option, path)?;
        let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if !extensions.iter().any(|e| e.eq_ignore_ascii_case(extension)) {
            bail!(
                "{option} {}: the file name must end in .{}",
                path.display(),
                extensions.join(" or .")
            );
        }
        if let Some((other, _, _)) = outputs[..i]
            .iter()
            .find(|(_, p, _)| p.as_ref() == Some(path))
        {
            bail!("{other} and {option} name the same file {}", path.display());
        }
    }
    let loaded = load(&a.run)?;
    check_saved_products(&loaded.pipeline, &a.save)?;
    if a.export_cloud.is_some()
        && !loaded
            .pipeline
            .stages
            .iter()
            .any(|s| s.kind == "cloud.samples")
    {
        bail!(
            "--export-cloud: pipeline `{}` produces no environment-sample cloud (add a \
             cloud.samples stage)",
            loaded.pipeline.name
        );
    }
    let folders = super::out_dir::frame_folders(&loaded.pipeline, &a.out, &a.save);
    // A run that writes into --out holds it: another one there would mix the two.
    let _lock = match folders.is_empty() && a.export_cloud.is_none() {
        true => None,
        false => Some(super::lock::lock_output(&a.out, "--out")?),
    };
    super::out_dir::remove_stale_partials(&a.out, 3);
    super::out_dir::earlier_frames(&folders, &loaded.frames, a.clean_out)?;
    let stop = stop_on_interrupt();
    let bar = progress::bar(loaded.frames.len() as u64, "replaying", "frames");
    let stdout = std::io::stdout();
    let mut hash_error = None;
    let mut save_error: Option<anyhow::Error> = None;
    let mut last_cloud = None;
    let mut sink = |frame: Frame| {
        bar.inc(1);
        if a.export_cloud.is_some()
            && let Some(cloud) = frame
                .products()
                .find_map(|(_, p)| p.get::<Arc<EnvCloud>>(kind::CLOUD))
        {
            last_cloud = Some(cloud.clone());
        }
        if !a.save.is_empty()
            && save_error.is_none()
            && let Err(e) = save_products(&frame, &a.save, &a.save_format, &a.out)
        {
            // The run ends after the frames in flight: the error is reported then.
            save_error = Some(e);
            stop.store(true, Ordering::SeqCst);
        }
        if a.hash {
            let mut line = format!("{:06} {}", frame.index, frame.stamp_ns);
            for (name, product) in frame.products() {
                line.push_str(&format!(" {name}={:016x}", product.digest()));
            }
            if hash_error.is_none()
                && let Err(e) = writeln!(stdout.lock(), "{line}")
            {
                // Nobody reads the lines any more, or they cannot be written: stop.
                hash_error = Some(e);
                stop.store(true, Ordering::SeqCst);
            }
        }
    };
    let result = loaded.run_once(&a.out, &a.run, Pacing::Pipelined, &stop, &mut sink);
    bar.finish_and_clear();
    let (report, failure) = match result {
        Ok(r) => (r, None),
        Err(f) => (f.report, Some(f.error)),
    };
    let table = format!(
        "{} on {} ({}):\n{}",
        loaded.pipeline.name,
        loaded.replay.recording.path().display(),
        loaded.pipeline.file,
        report.table()
    );
    // A run that failed before any stage timed a frame (a stage that could not be set
    // up) has no table to show: only its error.
    let nothing_timed = report.stages.iter().all(|s| s.frames.is_empty());
    // A stdout error is reported last: the files asked for and a failed run come first.
    let table_written = if failure.is_some() && nothing_timed {
        Ok(())
    } else if a.hash {
        eprint!("{table}");
        Ok(())
    } else {
        out!("{table}")
    };
    for (frame, cause) in &report.skipped_corrupt {
        eprintln!("skipped corrupt frame {frame}: {cause}");
    }
    if !report.skipped_corrupt.is_empty() {
        eprintln!("{}", skipped_summary(&report.skipped_corrupt));
    }
    if let Some(path) = &a.timings {
        report
            .write_timings(path)
            .with_context(|| format!("cannot write timings to {}", path.display()))?;
    }
    if let Some(path) = &a.trace {
        report
            .write_trace(path)
            .with_context(|| format!("cannot write the trace to {}", path.display()))?;
    }
    if let Some(e) = save_error {
        return Err(e.context("--save stopped"));
    }
    if let Some(path) = &a.export_cloud {
        let Some(cloud) = last_cloud else {
            bail!(
                "--export-cloud: pipeline `{}` produces no environment-sample cloud (add a \
                 cloud.samples stage)",
                loaded.pipeline.name
            );
        };
        write_file_atomic(path, &ply_bytes(&cloud))
            .with_context(|| format!("cannot write the cloud to {}", path.display()))?;
        eprintln!(
            "saved {} environment samples to {}",
            cloud.len(),
            path.display()
        );
    }
    if let Some(e) = hash_error {
        return Err(anyhow::Error::new(e).context("cannot write hash lines"));
    }
    if let Some(error) = failure {
        return Err(anyhow::Error::new(error).context(format!(
            "replay of {} stopped",
            loaded.replay.recording.path().display()
        )));
    }
    table_written?;
    if report.interrupted {
        eprintln!("interrupted: {} frames complete", report.frames_out);
        return Ok(130);
    }
    some_frame_replayed(&loaded, &report)?;
    Ok(0)
}

/// "3 corrupt frame(s) skipped: 2 with a corrupt color record, 1 with a corrupt pose
/// record", from the causes a run recorded (the kind of record each names).
pub(super) fn skipped_summary(skipped: &[(usize, String)]) -> String {
    let mut by_cause: Vec<(String, usize)> = Vec::new();
    for (_, cause) in skipped {
        // Record errors name the record as "record N (kind)".
        let kind = cause
            .split_once(") at byte")
            .and_then(|(head, _)| head.rsplit_once('('))
            .map(|(_, kind)| kind);
        let what = match kind {
            Some(k) => format!("a corrupt {k} record"),
            None => "another cause".to_string(),
        };
        match by_cause.iter_mut().find(|(w, _)| *w == what) {
            Some(entry) => entry.1 += 1,
            None => by_cause.push((what, 1)),
        }
    }
    let parts: Vec<String> = by_cause
        .iter()
        .map(|(w, n)| format!("{n} with {w}"))
        .collect();
    format!(
        "{} corrupt frame(s) skipped: {}",
        skipped.len(),
        parts.join(", ")
    )
}

/// An error when a run went through but replayed no frame: every frame in the range was
/// corrupt and skipped (`--skip-corrupt`), so there is nothing to show for it.
pub(super) fn some_frame_replayed(loaded: &Loaded, report: &RunReport) -> anyhow::Result<()> {
    // An interrupted run may not have reached its good frames.
    if report.frames_out == 0 && !report.skipped_corrupt.is_empty() && !report.interrupted {
        bail!(
            "{}: all {} frames in the range are corrupt and were skipped: nothing was replayed",
            loaded.replay.recording.path().display(),
            report.skipped_corrupt.len()
        );
    }
    Ok(())
}

/// Saves the products named in `names` (or all writable ones for `all`) of `frame` into
/// `out/<product>/<frame>.<ext>`.
pub(super) fn save_products(
    frame: &Frame,
    names: &[String],
    formats: &[String],
    out: &Path,
) -> anyhow::Result<()> {
    use rayon::prelude::*;
    let all = names.iter().any(|n| n == "all");
    let mut jobs = Vec::new();
    for (name, product) in frame.products() {
        if !(all || names.iter().any(|n| n == name)) || !kind::is_writable(product.kind()) {
            continue;
        }
        let dir = out.join(name);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let stem = dir.join(format!("{:06}", frame.index));
        if !kind::is_image(product.kind()) {
            jobs.push((product, stem, None));
            continue;
        }
        for f in formats {
            jobs.push((product, stem.with_extension(f), Some(f.as_str())));
        }
    }
    if !all {
        for n in names {
            match frame.get(n) {
                None => bail!(
                    "frame {} has no product `{n}`; it has: {}",
                    frame.index,
                    frame
                        .products()
                        .map(|(k, _)| k)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                Some(p) if !kind::is_writable(p.kind()) => {
                    bail!("`{n}` is a {} and cannot be saved", p.kind().name())
                }
                Some(_) => {}
            }
        }
    }
    jobs.par_iter()
        .map(|(product, path, format)| match format {
            None => write_record(product, path, frame.stamp_ns),
            Some("exr") => write_exr(product, path),
            Some(_) => write_png(product, path),
        })
        .collect::<Result<(), _>>()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::parse_frames;

    #[test]
    fn frame_ranges_parse_or_say_what_is_expected() {
        assert_eq!(parse_frames("3..7"), Ok(3..7));
        assert_eq!(parse_frames("3.."), Ok(3..usize::MAX));
        assert_eq!(parse_frames("..7"), Ok(0..7));
        assert_eq!(parse_frames(".."), Ok(0..usize::MAX));
        assert_eq!(parse_frames("5"), Ok(5..6));
        let expected = |text: &str| {
            Err(format!(
                "invalid frame range {text:?}: expected A..B, A.., ..B or N"
            ))
        };
        for text in ["", "x", "1..x", "-1", "1...3"] {
            assert_eq!(parse_frames(text), expected(text), "{text:?}");
        }
        assert_eq!(
            parse_frames("5..5"),
            Err("frame range \"5..5\" is empty".into())
        );
        let max = usize::MAX.to_string();
        assert_eq!(
            parse_frames(&max),
            Err(format!("frame range {max:?} is empty"))
        );
    }
}
