//! The crate's stage runs inside a relume pipeline, built from a pipeline file by the
//! library's registry, and gives exactly what its op gives on the decoded depth.

use relume::graph::{Pipeline, RunOptions, run};
use relume::raster::LabelImage;
use relume::recording::synth::{SynthConfig, generate};
use relume::recording::{Replay, ReplayOptions};
use relume_stage_example::{depth_edges, registry};

#[test]
fn the_stage_runs_in_a_pipeline_and_gives_what_its_op_gives() {
    let dir = tempfile::tempdir().unwrap();
    let recording = dir.path().join("room.relume");
    let synth = SynthConfig {
        frames: 2,
        width: 64,
        height: 48,
        ..Default::default()
    };
    generate(&synth, &recording).unwrap();
    let registry = registry();
    let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("depth-edges.toml");
    let pipeline = Pipeline::load(&file, &registry).unwrap();
    let replay = Replay::open(&recording, ReplayOptions::default()).unwrap();
    let stages = pipeline
        .build(&registry, replay.recording.header(), dir.path(), 1)
        .unwrap_or_else(|(s, e)| panic!("{s}: {e}"));
    let mut frames = 0;
    run(
        &pipeline,
        stages,
        &replay,
        &RunOptions::default(),
        &mut |frame| {
            let depth = frame.depth("depth").unwrap();
            let mut want = LabelImage::zeroed(depth.width, depth.height);
            depth_edges(depth, 0.25, &mut want).unwrap();
            let got = frame.labels("edges").unwrap();
            assert_eq!(got.data, want.data, "frame {}", frame.index);
            // The room has walls, a floor and objects: some edges, far from all pixels.
            let edges = got.data.iter().filter(|&&l| l == 255).count();
            assert!(edges > 0 && edges < got.data.len() / 4, "{edges} edges");
            frames += 1;
        },
    )
    .unwrap();
    assert_eq!(frames, 2);
}

#[test]
fn a_pipeline_with_a_wrong_parameter_is_refused_at_its_line() {
    let src = relume::graph::config::SourceFile {
        name: "bad.toml".into(),
        text: "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"example.depth_edges\"\n\
               params = { threshold = -1.0 }\n"
            .into(),
    };
    let err = Pipeline::parse(&src, &registry()).unwrap_err().to_string();
    assert!(err.contains("bad.toml:5:"), "{err}");
    assert!(
        err.contains("parameter `threshold` = -1 is out of range"),
        "{err}"
    );
}

#[test]
fn the_demo_binary_runs() {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_relume-stage-example"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(out.lines().count(), 3, "{out}");
    assert!(out.lines().all(|l| l.contains(" edges=")), "{out}");
}
