//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod open3d;
pub mod sample;
pub mod venv;

use std::path::PathBuf;
use std::process::{Command, Output};

/// The shared test data folder: `$RELUME_DATA`, else `../shared/data` beside the checkout.
/// Panics with a message saying where it looked when it is missing.
pub fn data_dir() -> PathBuf {
    let dir = match std::env::var_os("RELUME_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
    };
    assert!(
        dir.join("README.md").is_file(),
        "test data is missing: expected the shared data folder at {} (set RELUME_DATA to its path)",
        dir.display()
    );
    dir
}

/// The names of the entries of `dir`, sorted.
pub fn file_names(dir: &std::path::Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The `relume` binary built for these tests.
pub fn relume() -> Command {
    Command::new(env!("CARGO_BIN_EXE_relume"))
}

/// Sends `signal` (as `kill` takes it: "-INT", "-TERM") to `child` and waits for its
/// output.
pub fn signal_and_wait(child: std::process::Child, signal: &str) -> Output {
    let status = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .expect("run kill");
    assert!(status.success(), "kill {signal} failed");
    child.wait_with_output().expect("wait for relume")
}

/// Runs `relume` with `args` in `cwd`; returns its output.
pub fn run_in(cwd: &std::path::Path, args: &[&str]) -> Output {
    relume()
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run relume")
}

/// `relume replay REC -p PIPELINE --hash` in `cwd` on a rayon pool of `threads`
/// threads: one digest line per frame and product.
pub fn replay_hashes(
    cwd: &std::path::Path,
    recording: &str,
    pipeline: &str,
    threads: &str,
) -> String {
    let mut cmd = relume();
    cmd.args(["replay", recording, "-p", pipeline, "--hash", "--out", "o"])
        .current_dir(cwd)
        .env("RAYON_NUM_THREADS", threads);
    stdout(&ok(cmd.output().expect("run relume")))
}

/// Imports the shared livingroom1 (Redwood layout) into `dir/lr.relume`.
pub fn import_livingroom1(dir: &std::path::Path) {
    let data = data_dir().join("livingroom1");
    ok(run_in(
        dir,
        &[
            "import",
            "redwood",
            data.to_str().unwrap(),
            "-o",
            "lr.relume",
        ],
    ));
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The `composite.differential` scores of `relume eval RECORDING --stage
/// composite.differential --json` with `options`, run in `dir`.
pub fn composite_scores(
    dir: &std::path::Path,
    recording: &str,
    options: &[&str],
) -> serde_json::Value {
    let mut args = vec![
        "eval",
        recording,
        "--stage",
        "composite.differential",
        "--json",
    ];
    args.extend(options);
    let doc: serde_json::Value = serde_json::from_str(&stdout(&ok(run_in(dir, &args)))).unwrap();
    doc["stages"]["composite.differential"].clone()
}

/// Asserts that relume succeeded, printing both streams otherwise.
pub fn ok(o: Output) -> Output {
    succeeded("relume", o)
}

/// Asserts that `program` succeeded, printing both streams otherwise.
pub fn succeeded(program: &str, o: Output) -> Output {
    assert!(
        o.status.success(),
        "{program} failed ({:?})\nstdout:\n{}\nstderr:\n{}",
        o.status,
        stdout(&o),
        stderr(&o)
    );
    o
}

/// The path of a shipped pipeline file, `pipelines/<name>`.
pub fn pipeline(name: &str) -> String {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("pipelines")
        .join(name)
        .display()
        .to_string()
}

/// A small synthetic recording in `dir`.
pub fn small_recording(dir: &std::path::Path, frames: usize) -> PathBuf {
    let path = dir.join("small.relume");
    ok(run_in(
        dir,
        &[
            "synth",
            "-o",
            "small.relume",
            "--frames",
            &frames.to_string(),
            "--size",
            "64x48",
            "--seed",
            "3",
        ],
    ));
    path
}
