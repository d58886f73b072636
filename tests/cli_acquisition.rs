//! The acquisition pipeline from the command line: eval, saving products, exporting the
//! cloud, determinism, and a real recording without ground truth.

mod common;

use common::{ok, run_in, stderr, stdout};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn acquisition() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("pipelines/acquisition.toml")
        .display()
        .to_string()
}

/// A small synthetic recording in `dir`.
fn small_recording(dir: &Path, frames: usize) -> PathBuf {
    let frames = frames.to_string();
    ok(run_in(
        dir,
        &[
            "synth", "-o", "s.relume", "--frames", &frames, "--size", "160x120",
        ],
    ));
    dir.join("s.relume")
}

#[test]
fn eval_reports_every_acquisition_score_as_json() {
    let tmp = tempfile::tempdir().unwrap();
    small_recording(tmp.path(), 4);
    let p = acquisition();
    let o = ok(run_in(
        tmp.path(),
        &["eval", "s.relume", "-p", &p, "--json"],
    ));
    let report: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(report["frames"], 4);
    assert_eq!(report["ground_truth"], true);
    assert_eq!(report["pipeline"], "acquisition");
    let stages = &report["stages"];
    for (stage, keys) in [
        (
            "depth.fuse",
            &["rmse_raw_m", "rmse_fused_m", "holes_raw", "holes_fused"][..],
        ),
        (
            "normals.plane_fit",
            &["mean_angle_deg", "median_angle_deg", "valid_fraction"][..],
        ),
        (
            "color.compensate",
            &["transform_rel_error_median", "approximate_frames"][..],
        ),
        ("gbuffer.splat", &["reference_psnr_db"][..]),
    ] {
        for key in keys {
            assert!(
                stages[stage][key].is_number(),
                "{stage}.{key} missing in {report}"
            );
        }
    }
    // The text form names each stage and says nothing about missing ground truth.
    let text = stdout(&ok(run_in(tmp.path(), &["eval", "s.relume", "-p", &p])));
    assert!(
        text.contains("normals.plane_fit (normals.plane_fit)"),
        "{text}"
    );
    assert!(!text.contains("no ground truth"), "{text}");
    // --stage scores only the named stages, and names the choices when one is wrong.
    let o = ok(run_in(
        tmp.path(),
        &[
            "eval",
            "s.relume",
            "-p",
            &p,
            "--json",
            "--stage",
            "depth.fuse",
        ],
    ));
    let only: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let names: Vec<&String> = only["stages"].as_object().unwrap().keys().collect();
    assert_eq!(names, ["depth.fuse"]);
    assert_eq!(
        only["stages"]["depth.fuse"]["rmse_fused_m"],
        stages["depth.fuse"]["rmse_fused_m"]
    );
    for (name, what) in [
        ("fuse", "is not in the pipeline"),
        ("decode", "cannot be scored"),
    ] {
        let o = run_in(tmp.path(), &["eval", "s.relume", "-p", &p, "--stage", name]);
        assert!(!o.status.success());
        assert!(
            stderr(&o).contains(&format!(
                "stage `{name}` {what}; the stages eval can score here: gbuffer.splat, \
                 color.compensate, depth.fuse, normals.plane_fit"
            )),
            "{}",
            stderr(&o)
        );
    }
}

#[test]
fn eval_needs_a_scorable_stage() {
    let tmp = tempfile::tempdir().unwrap();
    small_recording(tmp.path(), 2);
    std::fs::write(tmp.path().join("d.toml"), "[[stage]]\nkind = \"decode\"\n").unwrap();
    let o = run_in(tmp.path(), &["eval", "s.relume", "-p", "d.toml"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("has no stage that eval can score"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn eval_refuses_a_reference_stride_that_leaves_one_row() {
    let tmp = tempfile::tempdir().unwrap();
    small_recording(tmp.path(), 2);
    let p = acquisition();
    let o = run_in(
        tmp.path(),
        &["eval", "s.relume", "-p", &p, "--reference-stride", "120"],
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains(
            "--reference-stride 120 leaves 2x1 pixels of the recording's 160x120 images \
             for the references: the scores would stand on a single row or column; use a \
             stride below 120"
        ),
        "{}",
        stderr(&o)
    );
}

#[test]
fn replay_saves_products_and_exports_the_cloud_as_ply() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 3);
    let p = acquisition();
    ok(run_in(
        d,
        &[
            "replay",
            "s.relume",
            "-p",
            &p,
            "--out",
            "out",
            "--save",
            "reference,compensated,normals,compensation",
            "--save-format",
            "png,exr",
            "--export-cloud",
            "cloud.ply",
        ],
    ));
    for n in 0..3 {
        for file in [
            "reference/{n}.png",
            "reference/{n}.exr",
            "compensated/{n}.png",
            "normals/{n}.exr",
            "compensation/{n}.json",
        ] {
            let path = d.join("out").join(file.replace("{n}", &format!("{n:06}")));
            assert!(path.is_file(), "{} missing", path.display());
        }
    }
    let first: Value =
        serde_json::from_slice(&std::fs::read(d.join("out/compensation/000000.json")).unwrap())
            .unwrap();
    assert_eq!(first["initial"], true);
    assert_eq!(first["matrix"][0], serde_json::json!([1.0, 0.0, 0.0]));

    let ply = std::fs::read(d.join("cloud.ply")).unwrap();
    let text = String::from_utf8_lossy(&ply);
    let end = text.find("end_header\n").expect("a PLY header") + "end_header\n".len();
    let count: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    assert!(count > 100, "{count} samples");
    assert_eq!(ply.len(), end + count * 39, "39 bytes per vertex");

    let o = run_in(d, &["replay", "s.relume", "-p", &p, "--save", "nope"]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("no product `nope`") && err.contains("fused_depth"),
        "{err}"
    );
}

#[test]
fn acquisition_products_are_identical_across_thread_counts() {
    let tmp = tempfile::tempdir().unwrap();
    small_recording(tmp.path(), 5);
    let p = acquisition();
    let hashes = |threads: &str| common::replay_hashes(tmp.path(), "s.relume", &p, threads);
    let one = hashes("1");
    assert_eq!(one.lines().count(), 5);
    for product in [
        "cloud=",
        "compensated=",
        "fused_depth=",
        "reference=",
        "normals=",
    ] {
        assert!(one.contains(product), "{one}");
    }
    assert_eq!(hashes("3"), one);
    assert_eq!(hashes("2"), one);
}

#[test]
fn livingroom1_runs_through_acquisition_and_eval_reports_self_consistency() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    common::import_livingroom1(d);
    let p = acquisition();
    let o = ok(run_in(
        d,
        &["eval", "lr.relume", "-p", &p, "--frames", "0..12"],
    ));
    let text = stdout(&o);
    assert!(text.contains("has no ground truth"), "{text}");
    // Normals, scored against the truth alone, are refused before the run.
    let o = run_in(
        d,
        &[
            "eval",
            "lr.relume",
            "-p",
            &p,
            "--stage",
            "normals.plane_fit",
        ],
    );
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o),
        format!(
            "error: {p}: stage `normals.plane_fit` (normals.plane_fit) is scored against the \
             true normals, and the recording has no ground truth; the stages eval can score \
             on it: gbuffer.splat, color.compensate, depth.fuse\n"
        )
    );
    // As is a pipeline whose only scores are its normals'.
    let geometry = concat!(env!("CARGO_MANIFEST_DIR"), "/pipelines/geometry.toml");
    let o = run_in(d, &["eval", "lr.relume", "-p", geometry]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o),
        format!(
            "error: {geometry}: the pipeline's only stages to score, `normals.cross`, are \
             scored against the true normals, and the recording has no ground truth\n"
        )
    );
    let o = ok(run_in(
        d,
        &["eval", "lr.relume", "-p", &p, "--frames", "0..12", "--json"],
    ));
    let report: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(report["ground_truth"], false);
    let fuse = &report["stages"]["depth.fuse"];
    assert!(fuse.get("rmse_raw_m").is_none(), "{fuse}");
    let (raw, fused) = (
        fuse["warp_rmse_raw_m"].as_f64().unwrap(),
        fuse["warp_rmse_fused_m"].as_f64().unwrap(),
    );
    assert!(raw > 0.0 && fused > 0.0, "{fuse}");
    let compensate = &report["stages"]["color.compensate"];
    assert!(
        compensate["approximate_frames"].as_u64().unwrap() < 12,
        "{compensate}"
    );
    assert!(
        report["stages"]["gbuffer.splat"]["reference_psnr_db"]
            .as_f64()
            .unwrap()
            > 10.0
    );
}
