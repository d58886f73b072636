//! What `relume compare` saves: three pipelines (the default, the fast one and
//! sample.dir) over one synthetic recording, run as one graph whose acquisition and
//! light stages are shared (`shared`), against the three run one after another
//! (`one_after_another`). Also `acquisition_once`: `pipelines/acquisition.toml` plus the
//! light stages alone, the part `shared` runs once. Expect
//! shared <= acquisition_once + the three branches < one_after_another.
//!
//! 8 frames at 320x240, so that a sample takes seconds, not minutes.

use criterion::{Criterion, criterion_group, criterion_main};
use relume::graph::{Pipeline, Registry, RunOptions, StageGraph, run, run_graph};
use relume::recording::synth::{SynthConfig, generate};
use relume::recording::{Replay, ReplayOptions};
use std::path::{Path, PathBuf};

const VARIANTS: [&str; 3] = [
    "default.toml",
    "mixed-reality-fast.toml",
    "mixed-reality-dir.toml",
];

fn load(name: &str, registry: &Registry) -> Pipeline {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("pipelines")
        .join(name);
    Pipeline::load(&path, registry).unwrap()
}

fn bench_compare(c: &mut Criterion) {
    relume::graph::memory::keep_freed_memory();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("synth.relume");
    let config = SynthConfig {
        frames: 8,
        width: 320,
        height: 240,
        ..SynthConfig::default()
    };
    generate(&config, &path).unwrap();
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let header = replay.recording.header().clone();
    let registry = relume::stages::registry();
    let mut pipelines: Vec<Pipeline> = VARIANTS.iter().map(|v| load(v, &registry)).collect();
    let world = pipelines[0].world.clone();
    for p in &mut pipelines {
        p.world = world.clone();
    }
    let labels = ["default", "fast", "dir"];
    let branches: Vec<(String, &Pipeline)> = labels
        .iter()
        .map(|l| l.to_string())
        .zip(&pipelines)
        .collect();
    let graph = StageGraph::shared(&branches);
    let out_dirs: Vec<PathBuf> = labels.iter().map(|l| dir.path().join(l)).collect();
    // The shared part alone: the default pipeline cut after its last shared stage.
    let mut trunk = pipelines[0].clone();
    let shared = graph.branch_nodes[0]
        .iter()
        .take_while(|&&n| graph.nodes[n].branches.len() == 3)
        .count();
    trunk.stages.truncate(shared);
    trunk
        .feedback
        .retain(|f| f.producer < shared && f.consumer < shared);

    let mut group = c.benchmark_group("compare_320x240_8frames");
    group.sample_size(10);
    let options = RunOptions::default();
    group.bench_function("shared", |b| {
        b.iter(|| {
            let stages = graph.build(&registry, &header, &out_dirs, 1).unwrap();
            run_graph(&graph, stages, &replay, &options, &mut |_| {}).unwrap()
        })
    });
    group.bench_function("one_after_another", |b| {
        b.iter(|| {
            for (p, out) in pipelines.iter().zip(&out_dirs) {
                let stages = p.build(&registry, &header, out, 1).unwrap();
                run(p, stages, &replay, &options, &mut |_| {}).unwrap();
            }
        })
    });
    group.bench_function("acquisition_once", |b| {
        b.iter(|| {
            let stages = trunk.build(&registry, &header, dir.path(), 1).unwrap();
            run(&trunk, stages, &replay, &options, &mut |_| {}).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench_compare);
criterion_main!(benches);
