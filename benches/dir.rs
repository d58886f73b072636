//! Per-frame cost of `sample.dir` (Differential Instant Radiosity, paper 002) at
//! 640x480 on the synthetic recording, with `pipelines/mixed-reality-dir.toml`'s
//! defaults (256 VPLs, 1024 points per map, 128 x 128 maps, 4 x 4 interleaving) and
//! its state built up over the preceding frames:
//!
//! - `sample.dir/frame`: the whole render (what the stage does per frame);
//! - `sample.dir/lights`: the VPLs and their imperfect shadow maps (the environment's
//!   VPLs and maps, the bounce candidates, resampling, the bounce VPLs' maps);
//! - `sample.dir/shade`: the interleaved gather and the geometry-aware blur.
//!
//! `RELUME_BENCH_PIPELINE=FILE cargo bench --bench dir` measures another pipeline's
//! sample.dir stage.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Affine3A;
use relume::pinhole::Pinhole;
use relume::stages::kind::FrameProducts;
use relume::stages::sample::instant_radiosity::{DirInputs, DirParams, DirRenderer, MeshPoints};
use relume::stages::sample::layers::IrradianceLayers;
use relume::stages::world::PipelineObjects;

/// Frames replayed before the measured one.
const WARM_FRAMES: usize = 12;

fn bench_dir(c: &mut Criterion) {
    relume::graph::memory::keep_freed_memory();
    let common::WarmedUp {
        pipeline,
        header,
        done,
        _dir,
        ..
    } = common::warm_up("mixed-reality-dir.toml", WARM_FRAMES + 1);
    let spec = pipeline
        .stages
        .iter()
        .find(|s| s.kind == "sample.dir")
        .expect("the pipeline has a sample.dir stage");
    let depth = done.depth(&spec.inputs["depth"]).unwrap();
    let inputs = DirInputs {
        depth,
        normals: done.normals(&spec.inputs["normals"]).unwrap(),
        radiance: done.radiance(&spec.inputs["radiance"]).unwrap(),
        camera: Pinhole::new(&header.depth_intrinsics, depth.width, depth.height),
        camera_to_world: Affine3A::from_mat4(
            done.pose(&spec.inputs["pose"]).unwrap().matrix().as_mat4(),
        ),
        table: done.light_table(&spec.inputs["light_table"]).unwrap(),
        objects: pipeline.objects(),
        spots: &[],
        frame: WARM_FRAMES as u64,
    };
    let params = DirParams::from_params(&spec.params, 1);
    let mesh = MeshPoints::new(pipeline.objects(), params.mesh_points as usize, params.seed);
    let mut renderer = DirRenderer::default();
    let mut out = IrradianceLayers::new(depth.width, depth.height);
    let mut group = c.benchmark_group("dir_640x480");
    group.sample_size(20);
    group.bench_function("sample.dir/frame", |b| {
        b.iter(|| renderer.render(&inputs, &params, &mesh, &mut out).unwrap())
    });
    group.bench_function("sample.dir/lights", |b| {
        b.iter(|| renderer.lights(&inputs, &params, &mesh).unwrap())
    });
    // The shading reads the lights of the last `lights` (made here too when the
    // filter skips the benches above).
    renderer.lights(&inputs, &params, &mesh).unwrap();
    group.bench_function("sample.dir/shade", |b| {
        b.iter(|| renderer.shade(&inputs, &params, &mut out).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench_dir);
criterion_main!(benches);
