//! Per-frame cost of each stage of `pipelines/acquisition.toml` at 640x480, on the
//! synthetic recording (generated into a temporary directory), with the stages' state
//! (fused depth, c_{t-1}, the cloud) built up over the preceding frames; plus
//! `gbuffer.splat` over a cloud of one million samples.
//!
//! `RELUME_BENCH_PIPELINE=FILE cargo bench --bench acquisition` measures another pipeline.
//!
//! Each stage is measured on a copy of the frame as it arrives at that stage, so the
//! figures are the stage's own cost, free of the pipeline's thread contention.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use relume::graph::{EnvCloud, Frame, FrameSource, Pipeline, Product, Registry};
use relume::pinhole::Pinhole;
use relume::recording::synth::{SynthConfig, generate};
use relume::recording::{Replay, ReplayOptions};
use relume::rng;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Frames replayed before the measured one.
const WARM_FRAMES: usize = 12;

fn bench_acquisition(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("synth.relume");
    let config = SynthConfig {
        frames: WARM_FRAMES + 1,
        ..SynthConfig::default()
    };
    generate(&config, &path).unwrap();
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let registry = Registry::builtin();
    // RELUME_BENCH_PIPELINE measures another pipeline the same way.
    let pipeline_path = std::env::var_os("RELUME_BENCH_PIPELINE")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines/acquisition.toml")
        });
    let pipeline = Pipeline::load(&pipeline_path, &registry).unwrap();
    let header = replay.recording.header().clone();
    let mut stages = pipeline
        .build(&registry, &header, dir.path(), 1)
        .map_err(|(s, e)| format!("{s}: {e}"))
        .unwrap();

    // Replays frames in this thread, stage after stage, feeding `product@prev` inputs
    // from the previous frame; keeps the last frame as each stage received it.
    let mut previous: BTreeMap<String, Arc<Product>> = BTreeMap::new();
    let mut arriving = Vec::new();
    for n in 0..=WARM_FRAMES {
        let mut frame = replay.read(n).unwrap();
        for (name, product) in &previous {
            frame.insert_shared(&format!("{name}@prev"), product.clone());
        }
        arriving.clear();
        for stage in stages.iter_mut() {
            arriving.push(frame.clone());
            stage.process(&mut frame).unwrap();
        }
        previous = pipeline
            .feedback
            .iter()
            .filter_map(|f| Some((f.product.clone(), frame.get_shared(&f.product)?.clone())))
            .collect();
    }

    let mut group = c.benchmark_group("acquisition_640x480");
    group.sample_size(20);
    for (i, stage) in stages.iter_mut().enumerate() {
        let spec = &pipeline.stages[i];
        group.bench_function(&spec.name, |b| {
            b.iter(|| {
                let mut frame: Frame = arriving[i].clone();
                stage.process(&mut frame).unwrap();
                frame
            })
        });
    }

    // gbuffer.splat over a cloud of 1M samples spread over the frame's surfaces.
    if let Some(i) = pipeline
        .stages
        .iter()
        .position(|s| s.kind == "gbuffer.splat")
    {
        let frame = &arriving[i];
        let cloud = million_samples(frame, &header);
        let mut input = frame.clone();
        let cloud_input = pipeline.stages[i].inputs["cloud"].clone();
        input.insert(&cloud_input, Product::Cloud(Arc::new(cloud)));
        group.bench_function("gbuffer.splat/1M_samples", |b| {
            b.iter(|| {
                let mut frame = input.clone();
                stages[i].process(&mut frame).unwrap();
                frame
            })
        });
    }
    group.finish();
}

/// One million samples on the surfaces the frame's depth sees (each pixel's point,
/// jittered within 2 cm), with world positions, gray colors and normals towards the
/// camera.
fn million_samples(frame: &Frame, header: &relume::recording::Header) -> EnvCloud {
    let records = frame.record("record").unwrap();
    let depth = relume::recording::codec::decode_depth(
        &records.depth.as_ref().unwrap().image,
        header.depth_unit_m,
    )
    .unwrap();
    let pose = records.pose.unwrap().matrix().as_mat4();
    let camera = Pinhole::new(&header.depth_intrinsics, depth.width, depth.height);
    let valid: Vec<usize> = (0..depth.data.len())
        .filter(|&i| depth.data[i] > 0.0)
        .collect();
    let mut cloud = EnvCloud::default();
    for k in 0..1_000_000u64 {
        let i = valid[(rng::hash(&[7, k]) % valid.len() as u64) as usize];
        let (u, v) = (
            (i % depth.width as usize) as f32,
            (i / depth.width as usize) as f32,
        );
        let jitter = Vec3::new(
            rng::unit_f32(rng::hash(&[8, k])) - 0.5,
            rng::unit_f32(rng::hash(&[9, k])) - 0.5,
            rng::unit_f32(rng::hash(&[10, k])) - 0.5,
        ) * 0.02;
        let p = camera.back_project(u, v, depth.data[i]);
        cloud.positions.push(pose.transform_point3(p + jitter));
        cloud.colors.push(Vec3::splat(0.3));
        cloud.normals.push(pose.transform_vector3(-p.normalize()));
    }
    cloud
}

criterion_group!(benches, bench_acquisition);
criterion_main!(benches);
