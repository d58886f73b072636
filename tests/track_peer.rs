//! `scripts/track_peer.py`: relume's tracker (`pose.track`) beside Open3D's RGB-D
//! odometry (PyPI's `open3d` 0.19, hybrid and color Jacobian terms, chained frame to
//! frame) on the same frames, each scored against the recording's poses.
//!
//! On a small synthetic recording: the script's ATE and RPE of relume's trajectory equal
//! `relume eval`'s, Open3D's rows cover every frame and track the camera (their ATEs
//! far below the recorded path's spread, the ATE of a camera that never moved).
//!
//! The Python side runs in a virtual environment made once under the target folder by
//! `pip install open3d==0.19.0 numpy` (about 2.5 minutes and 1.8 GB here); after that
//! the comparison takes 10-30 s on two cores.

mod common;

use common::open3d::python;
use common::{ok, run_in, stderr, stdout, succeeded};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Instant;

/// Frames and size of the synthetic recording: the camera moves 25 cm over 10 frames.
const FRAMES: usize = 10;
const SIZE: &str = "320x240";
/// Open3D's hybrid odometry's largest ATE here. Measured over seeds 1 to 3: 1.2 to
/// 1.4 mm, against 80 mm for a camera that never moved.
const OPEN3D_HYBRID_ATE_M: f64 = 0.005;
/// Open3D's color (intensity only) odometry's largest ATE here: measured 11 to 12 mm
/// (the synthetic camera's exposure changes from frame to frame, which the photometric
/// term alone takes for motion).
const OPEN3D_COLOR_ATE_M: f64 = 0.03;
/// The agreement the script promises between its ATE of relume's trajectory and relume
/// eval's: the TUM files it reads give metres to 9 decimals.
const ATE_AGREEMENT_M: f64 = 1e-8;

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/track_peer.py")
}

/// Runs the script with `python` in `dir` on `args` (after the relume binary's path).
fn track_peer(python: &Path, dir: &Path, args: &[&str]) -> Output {
    Command::new(python)
        .arg(script())
        .args(["--relume", env!("CARGO_BIN_EXE_relume")])
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run python")
}

/// `key` of `row` as a number, or a panic naming both.
fn number(row: &Value, key: &str) -> f64 {
    row[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} is not a number in {row}"))
}

#[test]
fn open3d_odometry_runs_beside_pose_track_on_the_same_frames_and_scores() {
    let python = python();
    let dir = tempfile::tempdir().unwrap();
    let frames = FRAMES.to_string();
    ok(run_in(
        dir.path(),
        &[
            "synth", "-o", "s.relume", "--frames", &frames, "--size", SIZE, "--seed", "3",
        ],
    ));
    let started = Instant::now();
    let out = track_peer(
        python,
        dir.path(),
        &["s.relume", "--work", "work", "--json"],
    );
    let seconds = started.elapsed().as_secs_f64();
    let out = succeeded("track_peer.py", out);
    let report: Value = serde_json::from_str(&stdout(&out)).unwrap_or_else(|e| {
        panic!(
            "track_peer.py --json printed no JSON ({e}):\n{}",
            stdout(&out)
        )
    });
    eprintln!("track_peer.py took {seconds:.1} s");

    // relume's own scores, from a run of its own.
    let eval = ok(run_in(
        dir.path(),
        &[
            "eval",
            "s.relume",
            "-p",
            &common::pipeline("tracking.toml"),
            "--json",
        ],
    ));
    let eval: Value = serde_json::from_str(&stdout(&eval)).unwrap();
    let eval = &eval["stages"]["pose.track"];

    let methods = &report["methods"];
    let still = number(&report["recorded_path"], "ate_rmse_if_still_m");
    for (name, row) in methods.as_object().expect("methods is an object") {
        eprintln!(
            "  {name:<14} frames {} lost {} ATE {:.3} mm RPE {:.3} mm/frame {:.4} deg/frame, \
             {:.1} ms/frame",
            row["frames"],
            row["lost_frames"],
            1e3 * number(row, "ate_rmse_m"),
            1e3 * number(row, "rpe_translation_m_per_frame"),
            number(row, "rpe_rotation_deg_per_frame"),
            number(row, "median_ms_per_frame"),
        );
    }
    eprintln!("  a camera that never moved: ATE {:.1} mm", 1e3 * still);
    assert_eq!(report["frames"], serde_json::json!([0, FRAMES]));
    assert!(
        (0.05..0.2).contains(&still),
        "the recorded path's spread is {still} m"
    );

    // The script scores relume's trajectory as relume eval does.
    let relume = &methods["relume"];
    assert_eq!(relume["frames"].as_u64(), Some(FRAMES as u64));
    assert_eq!(relume["lost_frames"], eval["lost_frames"]);
    for key in [
        "ate_rmse_m",
        "rpe_translation_m_per_frame",
        "rpe_rotation_deg_per_frame",
    ] {
        let (mine, theirs) = (number(relume, key), number(eval, key));
        let tolerance = if key.ends_with("_deg_per_frame") {
            1e-5
        } else {
            ATE_AGREEMENT_M
        };
        assert!(
            (mine - theirs).abs() <= tolerance,
            "{key}: the script says {mine}, relume eval {theirs}"
        );
    }
    assert_eq!(report["ate_check"]["agrees"], Value::Bool(true));
    assert!(number(relume, "median_ms_per_frame") > 0.0);

    // Open3D's rows: every frame, finite scores, and tracking that follows the camera.
    for (name, bound) in [
        ("open3d_hybrid", OPEN3D_HYBRID_ATE_M),
        ("open3d_color", OPEN3D_COLOR_ATE_M),
    ] {
        let row = &methods[name];
        assert!(row.is_object(), "no {name} row in {methods}");
        assert_eq!(row["frames"].as_u64(), Some(FRAMES as u64), "{name}");
        assert_eq!(row["frames_scored"].as_u64(), Some(FRAMES as u64), "{name}");
        let ate = number(row, "ate_rmse_m");
        assert!(
            ate.is_finite() && ate < bound,
            "{name}: ATE {ate} m, expected under {bound} m"
        );
        assert!(number(row, "rpe_translation_m_per_frame").is_finite());
        assert!(number(row, "rpe_rotation_deg_per_frame").is_finite());
        assert!(number(row, "median_ms_per_frame") > 0.0);
    }
    assert_eq!(methods["open3d_hybrid"]["lost_frames"].as_u64(), Some(0));

    // --work keeps relume's frames and poses.
    for product in ["color", "depth", "pose", "recorded_pose"] {
        let saved = common::file_names(&dir.path().join("work").join(product));
        assert_eq!(saved.len(), FRAMES, "work/{product}: {saved:?}");
    }
}

#[test]
fn without_open3d_the_script_says_how_to_install_it() {
    // `python3 -S` imports no site packages: neither numpy nor open3d.
    let dir = tempfile::tempdir().unwrap();
    let mut python = Command::new("python3");
    python.arg("-S");
    let out = python
        .arg(script())
        .args(["missing.relume", "--relume", env!("CARGO_BIN_EXE_relume")])
        .current_dir(dir.path())
        .output()
        .expect("the script needs python3 on PATH");
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let said = stderr(&out);
    assert!(
        said.contains("pip install open3d==0.19.0 numpy") && !said.contains("Traceback"),
        "{said}"
    );

    // A malformed frame range is refused before anything runs.
    let out = Command::new("python3")
        .arg("-S")
        .arg(script())
        .args(["r.relume", "--frames", "3-5"])
        .output()
        .expect("run python3");
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--frames"), "{}", stderr(&out));
}
