//! Tracking from the command line: `pipelines/tracking.toml` on a synthetic recording,
//! scored by `relume eval` against the recording's true poses.

mod common;

use common::{ok, pipeline, run_in, stderr, stdout};
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

/// A recording without poses (livingroom1's first frames, its trajectory left out):
/// the acquisition pipeline is refused before it runs, with the tracker named; its
/// tracked twin runs, and since livingroom1's world is its first camera's (where the
/// tracker starts without poses), its products are bit for bit the ones it gives with
/// the trajectory in the folder.
#[test]
fn a_recording_without_poses_runs_acquisition_with_the_tracker() {
    const FRAMES: usize = 6;
    let tmp = tempfile::tempdir().unwrap();
    for (name, with_poses) in [("bare", false), ("posed", true)] {
        livingroom1_folder(&tmp.path().join(name), FRAMES, with_poses);
        ok(run_in(
            tmp.path(),
            &["import", "redwood", name, "-o", &format!("{name}.relume")],
        ));
    }

    let untracked = run_in(
        tmp.path(),
        &[
            "replay",
            "bare.relume",
            "-p",
            &pipeline("acquisition.toml"),
            "--out",
            "o",
        ],
    );
    assert!(!untracked.status.success());
    let err = stderr(&untracked);
    assert!(
        err.contains("bare.relume: the recording has no camera poses, and stage `gbuffer.splat`")
            && err.contains("its input `pose` reads `pose`")
            && err.contains("pose.track")
            && err.contains("pipelines/acquisition-tracked.toml"),
        "{err}"
    );

    let tracked = pipeline("acquisition-tracked.toml");
    let hashes = |rec: &str| {
        let o = ok(run_in(
            tmp.path(),
            &["replay", rec, "-p", &tracked, "--hash", "--out", "o"],
        ));
        assert!(!stderr(&o).contains("lost"), "{}", stderr(&o));
        // The recording's own poses (and the record that holds them) are what the
        // two runs differ in. And the sign of zero: livingroom1's first pose is the
        // identity written with `-0.00000000`s, so frame 0's pose and the cloud (world
        // positions, some of them 0 + -0) differ in those bits, and nothing else.
        stdout(&o)
            .lines()
            .map(|l| {
                let frame0 = l.starts_with("000000 ");
                l.split(' ')
                    .filter(|t| {
                        let dropped = ["record=", "recorded_pose=", "cloud="];
                        let differs = dropped.iter().any(|d| t.starts_with(d))
                            || (frame0 && t.starts_with("pose="));
                        !differs
                    })
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect::<Vec<_>>()
    };
    let bare = hashes("bare.relume");
    assert_eq!(
        bare.iter().filter(|l| l.contains(" pose=")).count(),
        FRAMES - 1,
        "{bare:?}"
    );
    assert_eq!(bare, hashes("posed.relume"));
}

/// Links livingroom1's first `frames` frames into `dir` (a Redwood folder), with the
/// trajectory's first records when `with_poses`.
fn livingroom1_folder(dir: &Path, frames: usize, with_poses: bool) {
    let data = common::data_dir().join("livingroom1");
    for (sub, ext) in [("color", "jpg"), ("depth", "png")] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        for i in 0..frames {
            let file = format!("{i:05}.{ext}");
            std::os::unix::fs::symlink(data.join(sub).join(&file), dir.join(sub).join(&file))
                .unwrap();
        }
    }
    if with_poses {
        let log = std::fs::read_to_string(data.join("trajectory.log")).unwrap();
        let head: Vec<&str> = log.lines().take(5 * frames).collect();
        std::fs::write(dir.join("trajectory.log"), head.join("\n") + "\n").unwrap();
    }
}

/// Objects anchored to the floor on a recording without poses: the tracked world is the
/// first frame's camera, and the floor found there is livingroom1's (the same anchor as
/// with the recorded poses, whose first is the identity); a run that starts elsewhere
/// is refused at the anchor, and the run from frame 0 finishes its frames.
#[test]
fn anchors_on_a_recording_without_poses_are_found_in_the_tracked_world() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, with_poses) in [("bare", false), ("posed", true)] {
        livingroom1_folder(&tmp.path().join(name), 4, with_poses);
        ok(run_in(
            tmp.path(),
            &["import", "redwood", name, "-o", &format!("{name}.relume")],
        ));
    }
    let text = std::fs::read_to_string(pipeline("mixed-reality-tracked.toml"))
        .unwrap()
        .replacen(
            "translation = [0.0, 0.09, 0.0]",
            "anchor = \"floor\"\nat_pixel = [320, 440]\ntranslation = [0.0, 0.09, 0.0]",
            1,
        )
        .replacen(
            "translation = [0.3, 0.12, -0.42]",
            "anchor = \"floor\"\nat_pixel = [320, 440]\ntranslation = [0.3, 0.12, -0.42]",
            1,
        );
    std::fs::write(tmp.path().join("p.toml"), text).unwrap();
    // The torus's line: "... its frame's origin is [x, y, z] m, its up [x, y, z]; ...".
    let anchor = |rec: &str| {
        let o = ok(run_in(
            tmp.path(),
            &["validate", "p.toml", "--recording", rec],
        ));
        let out = stdout(&o) + &stderr(&o);
        let line = out
            .lines()
            .find(|l| l.starts_with("object `torus`: anchored on the floor"))
            .unwrap_or_else(|| panic!("{out}"))
            .to_string();
        let numbers = |after: &str| -> Vec<f32> {
            let rest = &line[line.find(after).unwrap() + after.len()..];
            rest[..rest.find(']').unwrap()]
                .split(", ")
                .map(|v| v.parse().unwrap())
                .collect()
        };
        (numbers("origin is ["), numbers("its up ["), line.clone())
    };
    let (origin, up, line) = anchor("bare.relume");
    assert!(line.contains("depth samples of frames 0..1"), "{line}");
    let (posed_origin, posed_up, _) = anchor("posed.relume");
    // livingroom1's floor, in its first camera's frame: y = 0.405 m below the camera
    // (y down), seen 1.1 m ahead at that pixel.
    assert!((origin[1] - 0.41).abs() < 0.015, "{line}");
    for k in 0..3 {
        assert!(
            (origin[k] - posed_origin[k]).abs() < 0.005,
            "{origin:?} {posed_origin:?}"
        );
        assert!((up[k] - posed_up[k]).abs() < 0.02, "{up:?} {posed_up:?}");
    }

    let late = run_in(
        tmp.path(),
        &[
            "replay",
            "bare.relume",
            "-p",
            "p.toml",
            "--frames",
            "2..4",
            "--out",
            "o",
        ],
    );
    assert!(!late.status.success());
    let err = stderr(&late);
    assert!(
        err.contains(
            "object `torus`: `bare.relume` has no camera poses, and the tracked world is the \
             camera of frame 2, where the run starts: anchors are found on that frame alone, \
             not on frame 0"
        ) && err.contains("anchor it on frame 2 (`frame = 2`), or start the run at frame 0"),
        "{err}"
    );
    ok(run_in(
        tmp.path(),
        &["replay", "bare.relume", "-p", "p.toml", "--out", "o"],
    ));
    assert_eq!(common::file_names(&tmp.path().join("o/final")).len(), 4);
}
