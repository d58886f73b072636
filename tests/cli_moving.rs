//! Objects that move, from the command line: a torus sliding along keyframes is rendered
//! where its path puts it in every frame (the same products as the torus standing still
//! there), the same bits at any thread count, and `relume eval --score-frames` scores
//! each frame of the slide and the ghost it leaves.

mod common;

use common::{ok, pipeline, run_in, stdout};
use std::path::Path;

/// `pipelines/mixed-reality-moving.toml` with its torus sliding from x = -0.5 at frame 2
/// to x = 0.5 at frame 12 (or standing at `still_x`), written into `dir` as `name`.
fn moving_pipeline(dir: &Path, name: &str, still_x: Option<f32>) -> String {
    let text = std::fs::read_to_string(pipeline("mixed-reality-moving.toml")).unwrap();
    let path_keys =
        "keyframes = [10, 40]\nkeyframe_translation = [[-0.5, 0.09, 0.1], [0.5, 0.09, 0.1]]\n";
    assert!(text.contains(path_keys), "the shipped torus's path changed");
    let placement = match still_x {
        Some(x) => format!("translation = [{x}, 0.09, 0.1]\n"),
        None => path_keys.replace("[10, 40]", "[2, 12]"),
    };
    std::fs::write(dir.join(name), text.replace(path_keys, &placement)).unwrap();
    name.to_string()
}

/// Frame by frame, the digest of each of `products` in a `--hash` replay.
fn digests(dir: &Path, pipeline: &str, products: &[&str]) -> Vec<Vec<String>> {
    let out = stdout(&ok(run_in(
        dir,
        &["replay", "s.relume", "-p", pipeline, "--hash", "--out", "o"],
    )));
    out.lines()
        .map(|line| {
            products
                .iter()
                .map(|p| {
                    line.split(' ')
                        .find(|kv| kv.starts_with(&format!("{p}=")))
                        .unwrap_or_else(|| panic!("no {p} in {line}"))
                        .to_string()
                })
                .collect()
        })
        .collect()
}

#[test]
fn a_sliding_torus_is_rendered_where_its_path_puts_it_and_scored_frame_by_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    ok(run_in(
        d,
        &[
            "synth", "-o", "s.relume", "--frames", "16", "--size", "160x120", "--seed", "3",
        ],
    ));
    // The renderer's fresh products depend on the objects of their frame alone (the
    // light's centre follows them too): before the path, halfway along it (frame 7,
    // x = 0) and after it, they are those of the torus standing still there.
    let products = ["mask", "fresh_e_rv_dir", "fresh_e_rv_ind", "environment"];
    let moving = digests(d, &moving_pipeline(d, "moving.toml", None), &products);
    assert_eq!(moving.len(), 16);
    for (x, frames) in [(-0.5, 0..3), (0.0, 7..8), (0.5, 12..16)] {
        let still = digests(
            d,
            &moving_pipeline(d, &format!("still{x}.toml"), Some(x)),
            &products,
        );
        for f in frames {
            assert_eq!(moving[f], still[f], "frame {f}: the torus at x = {x}");
        }
    }
    // Between, the torus is elsewhere than at either end.
    let start = digests(d, "still-0.5.toml", &products);
    assert_ne!(moving[5][0], start[5][0]);
    // Every product of every frame, the carried histories included, whatever the
    // thread count.
    let one = common::replay_hashes(d, "s.relume", "moving.toml", "1");
    assert_eq!(one.lines().count(), 16);
    assert_eq!(
        common::replay_hashes(d, "s.relume", "moving.toml", "3"),
        one
    );

    // Scores over time: every frame of 3..12, the truth and the references following
    // the torus.
    let scores = |pipeline: &str| {
        common::composite_scores(
            d,
            "s.relume",
            &[
                "-p",
                pipeline,
                "--score-frames",
                "3..12",
                "--reference-stride",
                "2",
            ],
        )
    };
    let composite = &scores("moving.toml");
    assert_eq!(
        composite["scored_frames"],
        serde_json::json!([3, 4, 5, 6, 7, 8, 9, 10, 11])
    );
    for key in ["psnr_db_by_frame", "psnr_db_truth_by_frame"] {
        let values = composite[key].as_array().unwrap();
        assert_eq!(values.len(), 9, "{key}: {composite}");
        assert!(
            values.iter().all(|v| v.as_f64().unwrap().is_finite()),
            "{key}: {composite}"
        );
    }
    // The ghost: the torus slides 10 cm a frame here (three times the shipped path's
    // speed); what its shadows and light left behind fades from the composite frame by
    // frame, and is gone (within 5 % of the truth's loss) within the 5 frames measured.
    let shares: Vec<f64> = composite["ghost_share_by_age"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_f64().unwrap())
        .collect();
    assert_eq!(shares.len(), 5, "{composite}");
    assert!(shares.windows(2).all(|w| w[1] < w[0]), "{shares:?}");
    let gone = composite["ghost_gone_after_frames"].as_u64().unwrap();
    assert!(gone <= 5, "{composite}");
    assert!(composite["ghost_pixels_by_age"][0].as_u64().unwrap() > 100);
    // A torus held still between two keyframes leaves nothing: the region is empty,
    // and eval says why there is no score.
    let held = std::fs::read_to_string(d.join("moving.toml"))
        .unwrap()
        .replace(
            "[[-0.5, 0.09, 0.1], [0.5, 0.09, 0.1]]",
            "[[0.0, 0.09, 0.1], [0.0, 0.09, 0.1]]",
        );
    std::fs::write(d.join("held.toml"), held).unwrap();
    let held = &scores("held.toml");
    assert_eq!(
        held["ghost_pixels_by_age"],
        serde_json::json!([0, 0, 0, 0, 0])
    );
    assert!(
        held["ghost_unmeasured"]
            .as_str()
            .unwrap()
            .starts_with("no scored frame shows a point the objects' shadows or light left"),
        "{held}"
    );
    // A range the replay does not reach is refused, saying so.
    let o = run_in(
        d,
        &[
            "eval",
            "s.relume",
            "-p",
            "moving.toml",
            "--score-frames",
            "20..30",
        ],
    );
    assert!(!o.status.success());
    assert!(
        common::stderr(&o).contains("--score-frames 20..30 has no frame of the replay (0..16)"),
        "{}",
        common::stderr(&o)
    );
}
