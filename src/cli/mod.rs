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
mod lock;
mod out_dir;
mod output;
mod prepare;
mod produce;
mod progress;
mod replay;

use clap::{Parser, Subcommand};
pub use output::{is_broken_pipe, report, stdout_write};

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
    /// .sens file, a ROS 2 / Foxglove MCAP log, a ROS 1 bag (RealSense recordings too), a
    /// Record3D .r3d export (iPhone / iPad LiDAR) or an Azure Kinect .mkv recording.
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

/// The most worker threads `RAYON_NUM_THREADS` may ask for. Far more than any machine
/// has cores; tens of thousands exhaust memory while the threads start.
const MAX_THREADS: usize = 1024;

/// An error when `RAYON_NUM_THREADS` asks for more than [`MAX_THREADS`] threads (rayon
/// ignores values that are not a number, and 0 means one per core), or when the worker
/// threads cannot start.
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
    // Started before any stage: a system that refuses them (a thread or address-space
    // limit) then ends the run with this error, where a stage's first parallel loop would
    // panic starting them.
    rayon::ThreadPoolBuilder::new().build_global().map_err(|e| {
        anyhow::anyhow!(
            "cannot start the worker threads (a higher thread or memory limit, or RAYON_NUM_THREADS=1, lets them start): {e}"
        )
    })
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
