//! Differential Instant Radiosity (`sample.dir`) from the command line: scored by
//! `relume eval` against the same references as `sample.path`, and run on livingroom1.

mod common;

use common::{ok, pipeline, run_in, stdout};
use serde_json::Value;

/// Frame 14 of the built-in room, references on every 4th pixel. Measured when written:
/// ratio_rmse 0.062 (sample.path's own at its defaults: 0.100), composite psnr_db 34.6
/// (the 16 + 16 reference chain: 37.4).
#[test]
fn eval_scores_sample_dir_against_the_path_references() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    ok(run_in(d, &["synth", "-o", "s.relume"]));
    let dir = pipeline("mixed-reality-dir.toml");
    let o = ok(run_in(
        d,
        &[
            "eval",
            "s.relume",
            "-p",
            &dir,
            "--frames",
            "0..15",
            "--stage",
            "sample.dir,composite.differential",
            "--reference-stride",
            "4",
            "--json",
        ],
    ));
    let doc: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let sampler = &doc["stages"]["sample.dir"];
    let composite = &doc["stages"]["composite.differential"];
    let key = |stage: &Value, k: &str| {
        stage[k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k} missing in {stage}"))
    };
    assert_eq!(sampler["scored_frames"], serde_json::json!([14]));
    assert_eq!(composite["scored_frames"], serde_json::json!([14]));
    assert!(key(sampler, "region_pixels") > 1000.0, "{sampler}");
    let (near, all) = (key(sampler, "ratio_rmse"), key(sampler, "ratio_rmse_all"));
    assert!(near < 0.1, "ratio_rmse {near}");
    assert!(all < 0.1, "ratio_rmse_all {all}");
    let psnr = key(composite, "psnr_db");
    assert!(psnr > 32.0, "psnr_db {psnr}");
}

#[test]
fn livingroom1_runs_through_differential_instant_radiosity() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    common::import_livingroom1(d);
    let lr = pipeline("mixed-reality-dir-livingroom1.toml");
    ok(run_in(
        d,
        &[
            "replay",
            "lr.relume",
            "-p",
            &lr,
            "--frames",
            "0..2",
            "--out",
            "o",
        ],
    ));
    for f in ["000000.png", "000001.png"] {
        let image = image::open(d.join("o/final").join(f)).unwrap().to_rgb8();
        assert_eq!(image.dimensions(), (640, 480));
    }
}
