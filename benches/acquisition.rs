//! Per-frame cost of each stage of `pipelines/acquisition.toml` at 640x480, on the
//! synthetic recording (generated into a temporary directory), with the stages' state
//! (fused depth, c_{t-1}, the cloud) built up over the preceding frames; plus
//! `gbuffer.splat` over a cloud of one million samples.
//!
//! `RELUME_BENCH_PIPELINE=FILE cargo bench --bench acquisition` measures another pipeline.
//!
//! Each stage is measured on a copy of the frame as it arrives at that stage, so the
//! figures are the stage's own cost, free of the pipeline's thread contention.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use relume::graph::{Frame, Product};
use relume::light::EnvCloud;
use relume::pinhole::Pinhole;
use relume::rng;
use relume::stages::kind;
use std::sync::Arc;

/// Frames replayed before the measured one.
const WARM_FRAMES: usize = 12;

fn bench_acquisition(c: &mut Criterion) {
    // The allocation policy the relume binary runs with (crates/graph/src/memory.rs).
    relume::graph::memory::keep_freed_memory();
    let common::WarmedUp {
        pipeline,
        header,
        mut stages,
        arriving,
        _dir,
        ..
    } = common::warm_up("acquisition.toml", WARM_FRAMES + 1);

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
        input.insert(&cloud_input, Product::new(kind::CLOUD, Arc::new(cloud)));
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
