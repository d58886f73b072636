//! Stages at their own rate: `every = k` (paper 004 Sec. 3.2's light model at a lower
//! rate than the frames) and `lag = n` (computed behind the frames, on its own thread),
//! through `relume replay --hash`.

use std::path::Path;
use std::process::{Command, Output};

/// `relume ARGS` in `dir`, whatever its exit status.
fn run(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_relume"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

fn relume(dir: &Path, args: &[&str], threads: &str) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_relume"))
        .args(args)
        .current_dir(dir)
        .env("RAYON_NUM_THREADS", threads)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout).unwrap()
}

/// `--hash` lines of `pipeline` (written to `dir/p.toml`) over `frames` of a small
/// synthetic recording: per frame, product name -> digest.
fn digests(dir: &Path, pipeline: &str, frames: &str, threads: &str) -> Vec<Vec<(String, String)>> {
    std::fs::write(dir.join("p.toml"), pipeline).unwrap();
    let args = [
        "replay", "s.relume", "-p", "p.toml", "--hash", "--frames", frames, "--out", "o",
    ];
    relume(dir, &args, threads)
        .lines()
        .map(|line| {
            line.split_whitespace()
                .skip(2)
                .map(|kv| {
                    let (k, v) = kv.split_once('=').unwrap();
                    (k.to_string(), v.to_string())
                })
                .collect()
        })
        .collect()
}

fn digest(frame: &[(String, String)], product: &str) -> String {
    frame.iter().find(|(k, _)| k == product).unwrap().1.clone()
}

fn recording() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "synth", "-o", "s.relume", "--frames", "8", "--size", "32x24",
    ];
    relume(dir.path(), &args, "2");
    dir
}

const PROBE: &str = "[[stage]]\nkind = \"decode\"\n\n[[stage]]\nkind = \"light.envmap\"\n\n[[stage]]\nkind = \"light.importance\"\n";

#[test]
fn every_k_on_unchanging_inputs_gives_the_products_of_every_frame() {
    let dir = recording();
    let d = dir.path();
    let each = digests(d, PROBE, "0..8", "2");
    let fourth = digests(d, &format!("{PROBE}every = 4\n"), "0..8", "2");
    assert_eq!(each.len(), 8);
    assert_eq!(each, fourth);
}

#[test]
fn frames_between_runs_carry_the_last_runs_products_whatever_the_threads() {
    let dir = recording();
    let d = dir.path();
    let every3 = "[[stage]]\nkind = \"decode\"\nevery = 3\n";
    let each = digests(d, "[[stage]]\nkind = \"decode\"\n", "0..8", "2");
    let runs = digests(d, every3, "0..8", "2");
    // Runs on frames 0, 3, 6; the frames between show the last run's color.
    for (frame, ran) in [
        (0, 0),
        (1, 0),
        (2, 0),
        (3, 3),
        (4, 3),
        (5, 3),
        (6, 6),
        (7, 6),
    ] {
        assert_eq!(
            digest(&runs[frame], "color"),
            digest(&each[ran], "color"),
            "frame {frame}"
        );
        // The source's own record is the frame's.
        assert_eq!(
            digest(&runs[frame], "record"),
            digest(&each[frame], "record")
        );
    }
    // A run that starts between multiples runs the stage on its first frame.
    let late = digests(d, every3, "1..5", "2");
    let shown: Vec<String> = late.iter().map(|f| digest(f, "color")).collect();
    let expected: Vec<String> = [1, 1, 3, 3]
        .iter()
        .map(|&i| digest(&each[i], "color"))
        .collect();
    assert_eq!(shown, expected);
    // Which frames run depends on the frame indices alone.
    assert_eq!(digests(d, every3, "0..8", "1"), runs);
}

#[test]
fn every_and_lag_must_be_integers_in_range() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases = [
        ("every", "0", "1 to 100000"),
        ("every", "1.5", "1 to 100000"),
        ("every", "\"4\"", "1 to 100000"),
        ("lag", "-1", "0 to 64"),
        ("lag", "65", "0 to 64"),
        ("lag", "true", "0 to 64"),
    ];
    for (key, bad, range) in cases {
        std::fs::write(
            d.join("p.toml"),
            format!("[[stage]]\nkind = \"decode\"\n{key} = {bad}\n"),
        )
        .unwrap();
        let o = run(d, &["validate", "p.toml"]);
        assert_eq!(o.status.code(), Some(1), "{key} = {bad}");
        let err = String::from_utf8_lossy(&o.stderr);
        let column = key.len() + 4;
        let expected =
            format!("p.toml:3:{column}: `{key}` of stage `decode` must be an integer from {range}");
        assert!(err.contains(&expected), "{err}");
    }
}

/// A decode stage `lag` frames behind, the points made from its depth, and the
/// channels' capacity.
fn lagged(lag: u32, capacity: u32) -> String {
    format!(
        "[pipeline]\nchannel_capacity = {capacity}\n\n[[stage]]\nkind = \"decode\"\nlag = {lag}\n\n[[stage]]\nkind = \"depth.to_points\"\ninputs = {{ depth = \"depth\" }}\n"
    )
}

#[test]
fn a_lagged_stage_hands_on_its_products_of_frame_t_minus_n_whatever_threads_and_capacity() {
    let dir = recording();
    let d = dir.path();
    let each = digests(d, &lagged(0, 2), "0..8", "2");
    let behind = digests(d, &lagged(2, 2), "0..8", "2");
    assert_eq!(behind.len(), 8);
    for (frame, made_from) in [0, 0, 0, 1, 2, 3, 4, 5].into_iter().enumerate() {
        for product in ["color", "depth", "points"] {
            assert_eq!(
                digest(&behind[frame], product),
                digest(&each[made_from], product),
                "frame {frame}: {product}"
            );
        }
        assert_eq!(
            digest(&behind[frame], "record"),
            digest(&each[frame], "record")
        );
    }
    for (threads, capacity) in [("1", 1), ("3", 1), ("3", 8)] {
        assert_eq!(
            digests(d, &lagged(2, capacity), "0..8", threads),
            behind,
            "{threads} threads, capacity {capacity}"
        );
    }
    // Positions in the run, not frame indices: a run from frame 3 starts with frame 3's.
    let late = digests(d, &lagged(2, 2), "3..6", "2");
    let shown: Vec<String> = late.iter().map(|f| digest(f, "color")).collect();
    let expected: Vec<String> = [3, 3, 3]
        .iter()
        .map(|&i| digest(&each[i], "color"))
        .collect();
    assert_eq!(shown, expected);
}

#[test]
fn eval_warns_that_a_stage_at_its_own_rate_is_scored_with_earlier_products() {
    let dir = recording();
    let d = dir.path();
    let pipeline = "[[stage]]\nkind = \"decode\"\nevery = 2\n\n[[stage]]\nkind = \"depth.to_points\"\ninputs = { depth = \"depth\" }\n\n[[stage]]\nkind = \"normals.cross\"\n";
    std::fs::write(d.join("p.toml"), pipeline).unwrap();
    let o = run(d, &["eval", "s.relume", "-p", "p.toml"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("warning: `decode` (every 2) of `p.toml` runs at its own rate (every k: on every k-th frame; lag n: n frames behind): on the frames between, or behind, it and the stages after it are scored with products of an earlier frame"),
        "{err}"
    );
}

#[test]
fn a_stage_at_its_own_rate_and_behind_hands_on_its_last_run_before_the_frame() {
    let dir = recording();
    let d = dir.path();
    let each = digests(d, &lagged(0, 2), "0..8", "2");
    let paced = lagged(1, 2).replace("lag = 1\n", "every = 3\nlag = 1\n");
    let shown = digests(d, &paced, "0..8", "2");
    // Runs on frames 0, 3, 6 (every 3), read one frame later (lag 1): frame t shows
    // the last run at or before t - 1 (frame 0 its own).
    for (frame, ran) in [0, 0, 0, 0, 3, 3, 3, 6].into_iter().enumerate() {
        assert_eq!(
            digest(&shown[frame], "color"),
            digest(&each[ran], "color"),
            "frame {frame}"
        );
    }
    assert_eq!(digests(d, &paced, "0..8", "1"), shown);
}

#[test]
fn lag_and_every_given_as_parameters_say_where_they_belong() {
    let dir = recording();
    let d = dir.path();
    std::fs::write(d.join("p.toml"), "[[stage]]\nkind = \"decode\"\n").unwrap();
    let args = [
        "replay",
        "s.relume",
        "-p",
        "p.toml",
        "--out",
        "o",
        "--set",
        "decode.lag=1",
    ];
    let o = run(d, &args);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("unknown parameter `lag` for stage `decode` (decode)")
            && err.contains("hint: `lag` is a key of the [[stage]] table, not a parameter: write `lag = ...` beside `kind` in the pipeline file (--set changes parameters only)"),
        "{err}"
    );
}
