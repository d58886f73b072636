//! Stages that do the same job are interchangeable: in every shipped pipeline, each
//! such stage swapped for the other (its parameters back to their defaults) still
//! checks and runs.

use relume::graph::{Params, Pipeline, Registry, RunOptions, SourceFile, run};
use relume::recording::synth::{SynthConfig, generate};
use relume::recording::{Replay, ReplayOptions};

/// Kinds that do the same job, each swapped for the other.
const SWAPS: [(&str, &str); 4] = [
    ("normals.plane_fit", "normals.cross"),
    ("normals.cross", "normals.plane_fit"),
    ("sample.path", "sample.dir"),
    ("sample.dir", "sample.path"),
];

/// `text` with its `stage`-th stage made `kind`: without its parameters, and without
/// the bindings of roles `kind` does not have (as a user swapping the kind would do).
fn swapped(text: &str, stage: usize, kind: &str, registry: &Registry) -> String {
    let info = registry.get(kind).unwrap();
    let ports = (info.ports)(&Params::defaults(info.params));
    let mut doc: toml::Table = toml::from_str(text).unwrap();
    let stages = doc["stage"].as_array_mut().unwrap();
    let s = stages[stage].as_table_mut().unwrap();
    s.insert("kind".into(), toml::Value::String(kind.into()));
    s.remove("params");
    for (key, roles) in [("inputs", &ports.inputs), ("outputs", &ports.outputs)] {
        if let Some(toml::Value::Table(bound)) = s.get_mut(key) {
            bound.retain(|role, _| roles.iter().any(|p| p.role == *role));
        }
    }
    toml::to_string(&doc).unwrap()
}

/// Every shipped pipeline runs on the first two frames of a small synthetic recording;
/// the tracked ones on a larger one, whose camera steps (a 6-frame path) are fine enough
/// to track: at 64 x 48 over two frames the tracker loses the second, and a lost frame
/// stops them.
#[test]
fn every_interchangeable_stage_swaps_in_every_shipped_pipeline() {
    let tmp = tempfile::tempdir().unwrap();
    let open = |name: &str, config: SynthConfig| {
        let recording = tmp.path().join(name);
        generate(&config, &recording).unwrap();
        Replay::open(&recording, ReplayOptions::default()).unwrap()
    };
    let small = open(
        "s.relume",
        SynthConfig {
            frames: 2,
            width: 64,
            height: 48,
            ..SynthConfig::default()
        },
    );
    let trackable = open(
        "t.relume",
        SynthConfig {
            frames: 6,
            width: 160,
            height: 120,
            seed: 3,
            ..SynthConfig::default()
        },
    );
    let registry = relume::stages::registry();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    let mut swaps = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let original = Pipeline::load(file, &registry).unwrap();
        let tracked = original.stages.iter().any(|s| s.kind == "pose.track");
        let replay = if tracked { &trackable } else { &small };
        let options = RunOptions {
            frames: 0..2,
            ..RunOptions::default()
        };
        for (i, stage) in original.stages.iter().enumerate() {
            for (from, to) in SWAPS.iter().filter(|(from, _)| *from == stage.kind) {
                let what = format!("{}: stage {} {from} -> {to}", file.display(), stage.name);
                let src = SourceFile {
                    name: file.display().to_string(),
                    text: swapped(&text, i, to, &registry),
                };
                let p = Pipeline::parse(&src, &registry).unwrap_or_else(|e| panic!("{what}: {e}"));
                let stages = p
                    .build(&registry, replay.recording.header(), tmp.path(), 1)
                    .unwrap_or_else(|(s, e)| panic!("{what}: {s}: {e}"));
                let mut frames = 0;
                run(&p, stages, replay, &options, &mut |_| frames += 1)
                    .unwrap_or_else(|e| panic!("{what}: {e}"));
                assert_eq!(frames, 2, "{what}");
                swaps += 1;
            }
        }
    }
    assert!(swaps >= 20, "{swaps} swaps tried");
}
