//! Tracking from the command line: `pipelines/tracking.toml` on a synthetic recording,
//! scored by `relume eval` against the recording's true poses.

mod common;

use common::{ok, run_in, stdout};
use serde_json::Value;
use std::path::Path;

#[test]
fn eval_scores_the_tracked_trajectory_against_the_true_one() {
    let tmp = tempfile::tempdir().unwrap();
    ok(run_in(
        tmp.path(),
        &[
            "synth", "-o", "s.relume", "--frames", "12", "--size", "320x240",
        ],
    ));
    let pipeline = Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines/tracking.toml");
    let o = ok(run_in(
        tmp.path(),
        &[
            "eval",
            "s.relume",
            "-p",
            pipeline.to_str().unwrap(),
            "--json",
        ],
    ));
    let report: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let track = &report["stages"]["pose.track"];
    assert_eq!(track["frames"], 12, "{track}");
    assert_eq!(track["lost_frames"], 0, "{track}");
    assert_eq!(track["frames_scored"], 12, "{track}");
    // Kinect-like depth noise, 320x240: a few millimetres at most over 12 frames (the
    // camera moves about 3 cm a frame).
    let ate = track["ate_rmse_m"].as_f64().unwrap();
    assert!(ate < 0.003, "{track}");
    let rpe = track["rpe_translation_m_per_frame"].as_f64().unwrap();
    assert!(rpe > 0.0 && rpe < 0.003, "{track}");
    assert!(
        track["rpe_rotation_deg_per_frame"].as_f64().unwrap() < 0.1,
        "{track}"
    );
}
