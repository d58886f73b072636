//! A light that changes, from the command line: `relume synth --panel-off-at` switches
//! the ceiling panel off at a frame, and `relume eval --score-frames` over the switch
//! reports how far the composite's differential follows the truth, frame by frame, and
//! its lag.

mod common;

use common::{ok, run_in, stderr};
use serde_json::Value;

/// The composite's scores of `relume eval` on `recording` over frames 3..20.
fn composite_scores(dir: &std::path::Path, recording: &str) -> Value {
    common::composite_scores(
        dir,
        recording,
        &["--score-frames", "3..20", "--reference-stride", "4"],
    )
}

#[test]
fn the_panel_switched_off_is_followed_and_its_lag_measured() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let synth = |name: &str, extra: &[&str]| {
        let mut args = vec![
            "synth", "-o", name, "--frames", "20", "--size", "160x120", "--seed", "3",
        ];
        args.extend(extra);
        ok(run_in(d, &args));
    };
    synth("lit.relume", &[]);
    synth("switched.relume", &["--panel-off-at", "6"]);

    let lit = composite_scores(d, "lit.relume");
    let switched = composite_scores(d, "switched.relume");
    let ratios = |scores: &Value| -> Vec<f64> {
        scores["differential_ratio_by_frame"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let (lit_ratios, switched_ratios) = (ratios(&lit), ratios(&switched));
    assert_eq!(lit_ratios.len(), 17, "{lit}");
    // Up to the switch the recordings, and so the runs, are the same; from it on the
    // truth and the camera frames differ.
    assert_eq!(lit_ratios[..3], switched_ratios[..3]);
    assert!(
        (3..17).all(|i| lit_ratios[i] != switched_ratios[i]),
        "{lit_ratios:?} {switched_ratios:?}"
    );
    // The composite shows a share of the true shadows between none and all of them.
    assert!(
        switched_ratios.iter().all(|r| (0.0..1.5).contains(r)),
        "{switched_ratios:?}"
    );
    // The switch is found in the recording and its lag measured: 0 to the 14 frames
    // scored from it on.
    assert_eq!(switched["change_frame"], 6, "{switched}");
    let lag = switched["change_lag_frames"].as_u64().unwrap();
    assert!(lag <= 14, "{switched}");
    assert!(switched["change_final_ratio"].as_f64().unwrap() > 0.0);
    // Before the switch: the median of the shares of frames 3, 4 and 5.
    let mut before = switched_ratios[..3].to_vec();
    before.sort_by(f64::total_cmp);
    assert_eq!(switched["change_ratio_before"].as_f64().unwrap(), before[1]);
    assert!(lit.get("change_frame").is_none(), "{lit}");

    // Too few scored frames after the switch: said instead of a lag.
    let short = common::composite_scores(
        d,
        "switched.relume",
        &["--score-frames", "3..12", "--reference-stride", "4"],
    );
    assert_eq!(
        short["change_unmeasured"],
        "the change at frame 6 needs 10 scored frames from it on, 6 were scored (give --score-frames a range that runs further past it)"
    );

    // A switch after the last frame is refused.
    let o = run_in(
        d,
        &[
            "synth",
            "-o",
            "late.relume",
            "--frames",
            "5",
            "--size",
            "160x120",
            "--panel-off-at",
            "5",
        ],
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o)
            .contains("the panel cannot switch off at frame 5: the recording's frames are 0 to 4"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("late.relume").exists());
}
