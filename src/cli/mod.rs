//! Command-line definitions and dispatch. Errors are `anyhow` here, at the edge; the
//! library's typed errors carry the file, line, frame or stage they concern.

/// `println!` that returns an error instead of panicking when standard output fails
/// (a closed pipe, a full disk); see [`stdout_write`].
macro_rules! outln {
    () => {
        $crate::cli::stdout_write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::cli::stdout_write(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` that returns an error instead of panicking (see [`outln!`]).
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::stdout_write(format_args!($($arg)*))
    };
}

mod batch;
mod bench;
mod catalog;
mod compare;
mod diff;
mod eval;
mod export;
mod inspect;
mod interrupt;
mod out_dir;
mod produce;
mod progress;
mod replay;

use clap::{Parser, Subcommand};
use relume::stages::world::PipelineObjects;
use std::path::{Path, PathBuf};

/// relume replays recorded RGB-D sensor logs (color, depth, camera pose) through
/// configurable pipelines of stages, times every stage per frame, and compares runs
/// frame by frame.
///
/// Start with `relume` (or `relume replay`): it generates a built-in synthetic recording on first use
/// (into recordings/default.relume), runs the default pipeline over it (mixed reality:
/// virtual objects in the footage, lit by the room), writes the finished frames to
/// out/final/ and prints a timing table per stage.
#[derive(Parser, Debug)]
#[command(name = "relume", version, long_about, max_term_width = 100, after_help = EXAMPLES)]
struct Cli {
    /// With no command, `relume` runs `relume replay` with its defaults.
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a synthetic recording of an analytic room with ground truth.
    Synth(produce::SynthArgs),
    /// Import a recording from a dataset layout (TUM RGB-D, Redwood / Open3D), a ScanNet
    /// .sens file or a ROS 2 / Foxglove MCAP log.
    #[command(subcommand)]
    Import(produce::ImportCommand),
    /// Export a recording, and the products a replay saved, as MCAP for Foxglove.
    #[command(subcommand)]
    Export(export::ExportCommand),
    /// Describe a recording: header, streams, rates and association.
    Inspect(inspect::InspectArgs),
    /// Replay a recording through a pipeline (with no arguments: the built-in default).
    Replay(replay::ReplayArgs),
    /// Run a pipeline and score its stages against the recording's ground truth.
    Eval(eval::EvalArgs),
    /// Replay several pipelines together (shared stages run once), score each as eval
    /// does, and write a report: report.json, report.md and index.html.
    Compare(compare::CompareArgs),
    /// Compare two runs' saved products frame by frame; exit status 1 when they differ.
    Diff(diff::DiffArgs),
    /// Benchmark each stage of a pipeline: medians over repeated runs after a warm-up.
    ///
    /// The pipeline's `write` stages write into a temporary folder, removed afterwards
    /// (also after a first Ctrl-C; a second one aborts at once and leaves it): a bench
    /// times the writing but leaves no files behind.
    Bench(bench::BenchArgs),
    /// Run a manifest's recordings through its pipelines, one item per pair, all of
    /// them or one shard (--shard I/N or auto, for Slurm job arrays and Kubernetes
    /// Indexed Jobs); a rerun skips finished items. --summary DIR: what is done.
    Batch(batch::BatchArgs),
    /// List every stage kind with its inputs, outputs and parameters.
    Stages(catalog::StagesArgs),
    /// Check a pipeline file without running it.
    Validate(catalog::ValidateArgs),
    /// List every key of a pipeline's `[[object]]` tables: shapes, placement (in the
    /// world, or on the recording's floor or a surface seen at a pixel), material.
    Objects(catalog::ObjectsArgs),
}

const EXAMPLES: &str = "\
Examples:
  relume replay                                    the built-in recording and pipeline
  relume import redwood DATA/livingroom1 -o lr.relume
  relume inspect lr.relume --json
  relume replay lr.relume -p pipelines/mixed-reality-livingroom1.toml --frames 0..50 --out out/lr
  relume replay lr.relume -p pipelines/geometry.toml --frames 0..50 --trace t.json
  relume replay lr.relume -p pipelines/acquisition.toml --hash > run1.txt
                                                   one digest line per frame, to diff runs
  relume eval recordings/default.relume --json      scores of the default pipeline's stages
  relume bench lr.relume -p pipelines/mixed-reality-livingroom1.toml --frames 0..20
  relume stages                                    what a pipeline can use
  relume objects                                   the keys of [[object]] tables
  relume validate my.toml";

/// An error before any work (a replay, a synth, an import), rather than after it, when
/// the file an option names cannot be written: something other than a regular file
/// stands there (a folder, a device), or its folder does not exist.
/// The line that import and export end with: what `out` holds, its size, the time.
pub(crate) fn print_wrote(
    out: &Path,
    (color, depth, poses): (usize, usize, usize),
    extra: &str,
    start: std::time::Instant,
) -> anyhow::Result<()> {
    let bytes = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    outln!(
        "wrote {} ({color} color, {depth} depth, {poses} poses{extra}, {:.1} MB) in {:.2} s",
        out.display(),
        bytes as f64 / 1e6,
        start.elapsed().as_secs_f64()
    )
}

/// An error when the output `out` is the input file `input` (written over before it is
/// read to its end).
pub(crate) fn check_not_input(out: &Path, input: &Path) -> anyhow::Result<()> {
    if let (Ok(a), Ok(b)) = (out.canonicalize(), input.canonicalize())
        && a == b
    {
        anyhow::bail!(
            "-o {} is the input file: give the output another name",
            out.display()
        );
    }
    Ok(())
}

pub(crate) fn check_output_file(option: &str, path: &Path) -> anyhow::Result<()> {
    // Where the file will be written: through a symbolic link, to what it leads to.
    let target = relume::recording::writer::output_target(path)
        .map_err(|e| anyhow::anyhow!("{option} {}: {e}", path.display()))?;
    if let Some(folder) = target.parent()
        && !folder.as_os_str().is_empty()
        && !folder.is_dir()
    {
        anyhow::bail!(
            "{option} {}: the folder {} does not exist",
            path.display(),
            folder.display()
        );
    }
    Ok(())
}

/// Writes to standard output: an error naming it when that fails, where `print!`
/// would panic. A reader that went away ([`is_broken_pipe`]) ends the command quietly.
pub fn stdout_write(text: std::fmt::Arguments) -> anyhow::Result<()> {
    use std::io::Write;
    std::io::stdout()
        .lock()
        .write_fmt(text)
        .map_err(|e| anyhow::Error::new(e).context("cannot write to standard output"))
}

/// Whether `error` comes from writing into a pipe whose reader has closed it (as in
/// `relume stages | head`): the output is no longer wanted, so the command ends with
/// status 0 and no message, as ripgrep does.
pub fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// The message for an error that ended a command: its causes from the outermost in,
/// joined by ": ", each said once. The library's errors name their cause in their own
/// message (so that `{}` alone is complete) and also hand it on as their `source`, so
/// the plain chain would repeat it (`a: b: b`); a cause whose text already ends the
/// message is left out.
pub fn report(error: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in error.chain() {
        let text = cause.to_string();
        // The cause ends the message as its own part (after ": "), not by chance.
        if message == text || message.ends_with(&format!(": {text}")) {
            continue;
        }
        if !message.is_empty() {
            message.push_str(": ");
        }
        message.push_str(&text);
    }
    message
}

/// The most worker threads `RAYON_NUM_THREADS` may ask for. Far more than any machine
/// has cores; tens of thousands exhaust memory while the threads start.
const MAX_THREADS: usize = 1024;

/// An error when `RAYON_NUM_THREADS` asks for more than [`MAX_THREADS`] threads (rayon
/// ignores values that are not a number, and 0 means one per core).
fn check_thread_count() -> anyhow::Result<()> {
    let requested = std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.trim().parse::<u64>().ok());
    if let Some(n) = requested.filter(|&n| n > MAX_THREADS as u64) {
        anyhow::bail!(
            "RAYON_NUM_THREADS={n} asks for more than {MAX_THREADS} worker threads; leave it \
             unset for one per core"
        );
    }
    Ok(())
}

/// Runs the command line; returns the exit code.
pub fn main() -> anyhow::Result<i32> {
    let cli = Cli::parse();
    check_thread_count()?;
    interrupt::install();
    let command = cli
        .command
        .unwrap_or_else(|| Command::Replay(replay::ReplayArgs::parse_from(["replay"])));
    match command {
        Command::Synth(a) => produce::synth(a),
        Command::Import(c) => produce::import(c),
        Command::Export(c) => export::export(c),
        Command::Inspect(a) => inspect::inspect(a),
        Command::Replay(a) => replay::replay(a),
        Command::Eval(a) => eval::eval(a),
        Command::Compare(a) => compare::compare(a),
        Command::Diff(a) => diff::diff(a),
        Command::Bench(a) => bench::bench(a),
        Command::Batch(a) => batch::batch(a),
        Command::Stages(a) => catalog::stages(a),
        Command::Validate(a) => catalog::validate(a),
        Command::Objects(a) => catalog::objects(a),
    }
}

/// Places `pipeline`'s objects anchored to the scene on `replay`, saying where (each
/// line after `prefix`, which names the pipeline where several run).
pub(crate) fn place_objects(
    pipeline: &mut relume::graph::Pipeline,
    replay: &relume::recording::Replay,
    prefix: &str,
) -> anyhow::Result<()> {
    for placed in pipeline.place_objects(replay)? {
        eprintln!("{prefix}{placed}");
    }
    Ok(())
}

/// A warning before scores of a pipeline with stages at their own rate (`every = k`,
/// `lag = n`): on the frames between their runs, or always when they run behind, they
/// and the stages after them hand on products of an earlier frame, which eval compares
/// with the current frame's truth and references.
pub(crate) fn warn_every(pipeline: &relume::graph::Pipeline) {
    let slow: Vec<String> = pipeline
        .stages
        .iter()
        .filter(|s| s.every > 1 || s.lag > 0)
        .map(|s| match (s.every, s.lag) {
            (1, lag) => format!("`{}` (lag {lag})", s.name),
            (every, 0) => format!("`{}` (every {every})", s.name),
            (every, lag) => format!("`{}` (every {every}, lag {lag})", s.name),
        })
        .collect();
    if !slow.is_empty() {
        let one = slow.len() == 1;
        eprintln!(
            "warning: {} of `{}` {} at {} own rate (every k: on every k-th frame; lag n: n frames behind): on the frames between, or behind, {} and the stages after {} are scored with products of an earlier frame against the current frame's truth and references",
            slow.join(", "),
            pipeline.file,
            if one { "runs" } else { "run" },
            if one { "its" } else { "their" },
            if one { "it" } else { "they" },
            if one { "it" } else { "them" },
        );
    }
}

/// Where the built-in default recording is kept.
pub(crate) fn default_recording_path() -> PathBuf {
    PathBuf::from("recordings").join("default.relume")
}

#[cfg(test)]
mod tests {
    use super::report;

    #[derive(Debug, thiserror::Error)]
    #[error("{path}: {source}")]
    struct Named {
        path: &'static str,
        #[source]
        source: std::io::Error,
    }

    #[derive(Debug, thiserror::Error)]
    #[error("stage `write` could not be set up: {source}")]
    struct Setup {
        #[source]
        source: Named,
    }

    fn not_a_directory() -> std::io::Error {
        std::io::Error::other("Not a directory")
    }

    #[test]
    fn each_cause_is_said_once() {
        let error = anyhow::Error::new(Setup {
            source: Named {
                path: "/dev/null/x/final",
                source: not_a_directory(),
            },
        })
        .context("replay of r.relume stopped");
        assert_eq!(
            report(&error),
            "replay of r.relume stopped: stage `write` could not be set up: \
             /dev/null/x/final: Not a directory"
        );
    }

    #[test]
    fn causes_not_in_the_message_are_kept() {
        // A context over an error that does not repeat it, and an error whose message
        // does not name its source: every part is said.
        let error = anyhow::Error::new(not_a_directory())
            .context("cannot write out/final/000001.png")
            .context("frame 1");
        assert_eq!(
            report(&error),
            "frame 1: cannot write out/final/000001.png: Not a directory"
        );
    }
}
