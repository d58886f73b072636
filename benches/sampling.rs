//! Per-frame cost of the light and sampling stages of
//! `pipelines/mixed-reality-sampling.toml` at 640x480 on the synthetic recording, with
//! the state (fused depth, cloud, lights) built up over the preceding frames.
//!
//! - `stage/<name>`: every stage's `process` on a copy of the frame as it arrives there.
//!   Stages that reuse their output while their input map is unchanged (light.importance,
//!   light.split, light.val) measure that reuse here; their update cost is measured
//!   directly below.
//! - `sample.path/plain` and `sample.path/object_aware`: the sampling math alone, with
//!   the stage's defaults (16 direct + 16 indirect samples per pixel), the object-aware
//!   scheme off and on. The pipeline's objects cover about 5 % of the frame.
//! - `sample.path/tenth`: the same as `plain` with the objects scaled up to cover about
//!   a tenth of the frame (the budget case; the bench prints the share).
//! - `sample.path/tenth_fast`: the same at `pipelines/mixed-reality-fast.toml`'s sample
//!   counts, 4 direct + 4 indirect samples per pixel.
//! - `sample.path/table3/<query>_<N>[_novis]`: paper 000 Table 3's grid on the
//!   `tenth` case: each radiance query (`ssrt`, `em`, `dit` with 6 iterations,
//!   `vct`) at N = 16, 32 and 64 samples per pixel and layer (4 primaries x 4, 8, 16
//!   direct and as many indirect), with the objects' self-occlusion test and without
//!   (`_novis`).
//!   `RELUME_BENCH_TABLE3=16` limits it to one N.
//! - `sample.path/reuse/<query>`: every query on the same case at the default chain's
//!   counts (1 + 1 fresh samples a pixel, 2 + 2 near the objects, with visibility), as
//!   `pipelines/mixed-reality.toml` runs `ssrt` and its twins
//!   `mixed-reality-{dit,vct-reuse}.toml` run `dit` and `vct`, with temporal reuse.
//! - `sample.path/reuse/em_no_objects`: `reuse/em` with no virtual object: what the
//!   estimator costs before any object is traced (em's own query is one impostor
//!   lookup by direction), the floor under every `reuse/<query>`.
//! - `sample.path/no_objects`: `plain` with no virtual object: the real scene's
//!   estimates alone, the floor under `plain`, `object_aware` and `tenth`.
//! - `objects/nearest`: the BVH alone, on one thread: the frame's object queries of
//!   `sample.path/tenth`, as its primary, real and virtual surfaces ask them.
//! - `ssrt/one_by_one`, `ssrt/batch_Portable`, `ssrt/batch_Avx2Fma`: the screen-space
//!   tracer alone on one thread, 16 cosine rays from every 16th pixel, traced ray by ray
//!   and as one batch with each kernel the CPU has.
//! - `light.val/update_warm` and `light.val/update_cold`: one update at 16 lights,
//!   warm-started on an unchanged map and from a cold start (the stage's work whenever
//!   the environment changes lies between the two).
//! - `light.impostor/build`: the cube map splatted from the frame's cloud.
//! - `light.importance/build`: the 4096-sample table of the frame's environment.
//!
//! `RELUME_BENCH_PIPELINE=FILE cargo bench --bench sampling` measures another pipeline.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Affine3A;
use relume::light::{ImpostorBuilder, ImpostorParams, LightTable, ValBuilder, ValParams};
use relume::objects::{Triangle, VirtualScene};
use relume::pinhole::Pinhole;
use relume::stages::kind::FrameProducts;
use relume::stages::sample::path::sampling::{Basis, cosine_hemisphere};
use relume::stages::sample::path::{IrradianceLayers, PathInputs, PathParams, sample_path};
use relume::stages::world::PipelineObjects;

/// Frames replayed before the measured one.
const WARM_FRAMES: usize = 12;

fn bench_sampling(c: &mut Criterion) {
    // The allocation policy the relume binary runs with (crates/graph/src/memory.rs).
    relume::graph::memory::keep_freed_memory();
    let common::WarmedUp {
        pipeline,
        header,
        mut stages,
        arriving,
        done,
        _dir,
        ..
    } = common::warm_up("mixed-reality-sampling.toml", WARM_FRAMES + 1);

    let mut group = c.benchmark_group("sampling_640x480");
    group.sample_size(10);
    common::bench_each_stage(&mut group, &pipeline, &mut stages, &arriving, &[]);

    // The sampling math alone, both schemes.
    if let Some(spec) = pipeline.stages.iter().find(|s| s.kind == "sample.path") {
        let depth = done.depth(&spec.inputs["depth"]).unwrap();
        let mask = done.scalar(&spec.outputs["mask"]).unwrap();
        eprintln!(
            "sample.path: the objects cover {:.1} % of the image",
            coverage(mask) * 100.0
        );
        let inputs = PathInputs {
            depth,
            normals: done.normals(&spec.inputs["normals"]).unwrap(),
            radiance: done.radiance(&spec.inputs["radiance"]).unwrap(),
            camera: Pinhole::new(&header.depth_intrinsics, depth.width, depth.height),
            camera_to_world: Affine3A::from_mat4(
                done.pose(&spec.inputs["pose"]).unwrap().matrix().as_mat4(),
            ),
            table: done.light_table(&spec.inputs["light_table"]).unwrap(),
            // light.impostor's map, for the em and dit queries.
            environment: Some(done.environment("environment").unwrap().as_ref()),
            // light.voxels' volume, for the vct query.
            voxels: Some(done.voxels("voxels").unwrap().as_ref()),
            objects: pipeline.objects(),
            object_voxels: None,
            frame: WARM_FRAMES as u64,
            spots: &[],
        };
        bench_tracer(
            &mut group,
            &inputs,
            &PathParams::from_params(&spec.params, 1),
        );
        for object_aware in [false, true] {
            let params = PathParams {
                object_aware,
                seed: 1,
                ..PathParams::from_params(&spec.params, 1)
            };
            let name = if object_aware {
                "object_aware"
            } else {
                "plain"
            };
            let mut out = IrradianceLayers::new(depth.width, depth.height);
            group.bench_function(format!("sample.path/{name}"), |b| {
                b.iter(|| sample_path(&inputs, &params, &mut out).unwrap())
            });
        }
        // The budget case: objects covering about a tenth of the image. The
        // pipeline's objects scaled about the world origin: in the default pipeline the
        // floor point under the torus, so that they still stand on the floor.
        let scaled = scaled_objects(pipeline.objects(), TENTH_SCALE);
        let inputs = PathInputs {
            objects: &scaled,
            ..inputs
        };
        let params = PathParams {
            object_aware: false,
            seed: 1,
            ..PathParams::from_params(&spec.params, 1)
        };
        let mut out = IrradianceLayers::new(depth.width, depth.height);
        sample_path(&inputs, &params, &mut out).unwrap();
        eprintln!(
            "sample.path/tenth: the objects, scaled by {TENTH_SCALE}, cover {:.1} % of the image",
            coverage(&out.mask) * 100.0
        );
        group.bench_function("sample.path/tenth", |b| {
            b.iter(|| sample_path(&inputs, &params, &mut out).unwrap())
        });
        // The same at pipelines/mixed-reality-fast.toml's counts: 4 + 4 samples per pixel.
        // Its own outputs, so that `out` keeps tenth's for the object queries below.
        let fast = PathParams {
            primary: 2,
            direct: 2,
            indirect: 2,
            ..params
        };
        let mut fast_out = IrradianceLayers::new(depth.width, depth.height);
        group.bench_function("sample.path/tenth_fast", |b| {
            b.iter(|| sample_path(&inputs, &fast, &mut fast_out).unwrap())
        });
        bench_queries(&mut group, &inputs, &params);
        bench_object_queries(&mut group, &scaled, &inputs, &out);
        let no_objects = VirtualScene::default();
        let inputs = PathInputs {
            objects: &no_objects,
            ..inputs
        };
        group.bench_function("sample.path/no_objects", |b| {
            b.iter(|| sample_path(&inputs, &params, &mut out).unwrap())
        });
    }

    // light.val's update and light.importance's table on the frame's maps.
    if let Some(spec) = pipeline.stages.iter().find(|s| s.kind == "light.val") {
        let direct = done
            .environment(&spec.inputs["direct_light"])
            .unwrap()
            .clone();
        let indirect = done
            .environment(&spec.inputs["indirect_light"])
            .unwrap()
            .clone();
        let mut builder = ValBuilder::new(ValParams::default());
        builder.update(&direct, &indirect);
        // Warm-started on the same map (static light: k-means is already at its fixed
        // point) and from a cold start (k-means++ seeding, up to 100 iterations): the
        // per-frame cost under changing light lies between the two.
        group.bench_function("light.val/update_warm", |b| {
            b.iter(|| builder.update(&direct, &indirect))
        });
        group.bench_function("light.val/update_cold", |b| {
            b.iter(|| ValBuilder::new(ValParams::default()).update(&direct, &indirect))
        });
    }
    if let Some(spec) = pipeline.stages.iter().find(|s| s.kind == "light.impostor") {
        let cloud = done.cloud(&spec.inputs["cloud"]).unwrap().clone();
        let center = pipeline.objects().bounds().center();
        let mut builder = ImpostorBuilder::new(ImpostorParams::default()).unwrap();
        eprintln!("light.impostor: a cloud of {} samples", cloud.len());
        group.bench_function("light.impostor/build", |b| {
            b.iter(|| builder.build(&cloud, center).unwrap())
        });
    }
    if let Some(spec) = pipeline
        .stages
        .iter()
        .find(|s| s.kind == "light.importance")
    {
        let env = done
            .environment(&spec.inputs["environment"])
            .unwrap()
            .clone();
        group.bench_function("light.importance/build", |b| {
            b.iter(|| LightTable::build(&env, 4096, 1))
        });
    }
    group.finish();
}

/// The scale of `sample.path/tenth`'s objects: the default pipeline's cover about 5 %
/// of the bench frame, these about 10 % (the bench prints the measured share).
const TENTH_SCALE: f32 = 1.45;

/// The share of the image whose primaries see an object: the mean of 1 - M.
fn coverage(mask: &relume::raster::ScalarImage) -> f64 {
    mask.data.iter().map(|&m| 1.0 - m as f64).sum::<f64>() / mask.data.len() as f64
}

/// `objects` scaled by `factor` about the world origin (normals unchanged), with the
/// BVH rebuilt.
fn scaled_objects(objects: &VirtualScene, factor: f32) -> VirtualScene {
    let triangles = objects
        .triangles
        .iter()
        .map(|t| Triangle {
            vertices: t.vertices.map(|v| v * factor),
            ..*t
        })
        .collect();
    VirtualScene::new(triangles, objects.materials.clone())
}

/// `objects/nearest`: the nearest-hit queries of sample.path/tenth's frame on one
/// thread, rebuilt from its outputs: from every 3rd pixel of every 3rd row, 8
/// cosine-distributed rays about the pixel's normal, leaving the virtual surface where
/// a primary saw an object and the real one elsewhere, plus the pixel's view ray. As in
/// sample.path, only the rays that meet the objects' bounding box query the BVH.
fn bench_object_queries(
    group: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>,
    objects: &VirtualScene,
    inputs: &PathInputs,
    out: &IrradianceLayers,
) {
    let camera_position = glam::Vec3::from(inputs.camera_to_world.translation);
    let bounds = objects.bounds();
    let mut rays = Vec::new();
    let mut rng = relume::rng::Counter::new(&[7, 0x0b1]);
    let (w, h) = (out.mask.width as usize, out.mask.height as usize);
    for y in (0..h).step_by(3) {
        for x in (0..w).step_by(3) {
            let i = y * w + x;
            let (p, n) = (out.world_position.data[i], out.world_normal.data[i]);
            if !p.is_finite() || n == glam::Vec3::ZERO {
                continue;
            }
            rays.push((camera_position, (p - camera_position).normalize()));
            let origin = p + n * 1e-4;
            let basis = Basis::new(n.normalize());
            for _ in 0..8 {
                let local = cosine_hemisphere(rng.next_f32(), rng.next_f32());
                rays.push((origin, basis.to_world(local)));
            }
        }
    }
    rays.retain(|(o, d)| bounds.ray_span(*o, d.recip(), 0.0, f32::INFINITY).is_some());
    let hits = rays
        .iter()
        .filter(|(o, d)| objects.intersect(*o, *d, 0.0, f32::INFINITY).is_some())
        .count();
    eprintln!(
        "objects/nearest: {} rays meet the box, {hits} hit an object",
        rays.len()
    );
    group.bench_function("objects/nearest", |b| {
        b.iter(|| {
            rays.iter()
                .filter_map(|(o, d)| objects.intersect(*o, *d, 0.0, f32::INFINITY))
                .map(|hit| hit.t)
                .sum::<f32>()
        })
    });
}

/// The screen-space tracer alone, on one thread: from every 4th pixel of every 4th row
/// of the frame, 16 cosine-distributed rays about its normal, up to `max_distance` (as
/// sample.path's indirect rays), traced one by one and as one batch with each kernel.
fn bench_tracer(
    group: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>,
    inputs: &PathInputs,
    params: &PathParams,
) {
    use relume::simd::Kernel;
    use relume::stages::sample::path::sampling::{Basis, cosine_hemisphere};
    use relume::stages::sample::ssrt::ScreenTracer;
    use relume::stages::sample::ssrt::batch::TraceBatch;
    let tracer = ScreenTracer::new(
        inputs.depth,
        inputs.camera,
        inputs.camera_to_world,
        params.trace,
    );
    let mut rays = Vec::new();
    let mut u = relume::rng::Counter::new(&[3]);
    for y in (0..inputs.depth.height).step_by(4) {
        for x in (0..inputs.depth.width).step_by(4) {
            let (z, n) = (*inputs.depth.at(x, y), *inputs.normals.at(x, y));
            if !(z > 0.0 && z.is_finite() && n.is_finite() && n != glam::Vec3::ZERO) {
                continue;
            }
            let n = n.normalize();
            let p = inputs.camera.back_project(x as f32, y as f32, z) + n * (z / 500.0);
            let basis = Basis::new(n);
            for _ in 0..16 {
                let d = basis.to_world(cosine_hemisphere(u.next_f32(), u.next_f32()));
                rays.push((p, d));
            }
        }
    }
    eprintln!("ssrt: {} rays", rays.len());
    let t_max = params.max_distance;
    group.bench_function("ssrt/one_by_one", |b| {
        b.iter(|| {
            rays.iter()
                .filter(|&&(o, d)| tracer.trace_camera(o, d, t_max).is_some())
                .count()
        })
    });
    let mut batch = TraceBatch::new(&tracer, rays.len());
    for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
        if kernel.available() != kernel {
            continue; // the CPU lacks it
        }
        group.bench_function(format!("ssrt/batch_{kernel:?}"), |b| {
            b.iter(|| {
                batch.clear();
                for &(o, d) in &rays {
                    batch.push(tracer.origin(o).as_ref(), d, t_max);
                }
                batch.trace(kernel);
                batch.hits().iter().filter(|h| h.is_some()).count()
            })
        });
    }
}

/// Paper 000 Table 3's grid: every query at N = 16, 32, 64 samples per pixel, with
/// and without the visibility test, on `inputs` (the `tenth` case).
fn bench_queries(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    inputs: &PathInputs,
    params: &PathParams,
) {
    use relume::stages::sample::query::QueryKind;
    let counts: Vec<u32> = match std::env::var("RELUME_BENCH_TABLE3") {
        Ok(n) => vec![n.parse().expect("RELUME_BENCH_TABLE3 is 16, 32 or 64")],
        Err(_) => vec![16, 32, 64],
    };
    let size = (inputs.depth.width, inputs.depth.height);
    let mut out = IrradianceLayers::new(size.0, size.1);
    // The stage builds the objects' solid volume once, not per frame.
    let vct = PathParams {
        query: QueryKind::Vct,
        ..*params
    };
    let object_volume = vct.object_volume(inputs.objects);
    let inputs = &PathInputs {
        object_voxels: object_volume.as_ref(),
        ..*inputs
    };
    for query in [
        QueryKind::Ssrt,
        QueryKind::Em,
        QueryKind::Dit,
        QueryKind::Vct,
    ] {
        for &n in &counts {
            for visibility in [true, false] {
                let per_primary = n / params.primary.max(1);
                let p = PathParams {
                    query,
                    visibility,
                    direct: per_primary,
                    indirect: per_primary,
                    ..*params
                };
                let name = format!(
                    "sample.path/table3/{}_{n}{}",
                    query.name(),
                    if visibility { "" } else { "_novis" }
                );
                group.bench_function(name, |b| {
                    b.iter(|| sample_path(inputs, &p, &mut out).unwrap())
                });
            }
        }
    }
    // The same queries at the default chain's counts (pipelines/mixed-reality.toml and
    // its dit / vct twins): 1 + 1 fresh samples a pixel, 2 + 2 near the objects, with
    // visibility; temporal.accumulate (not timed here) reuses earlier frames' samples.
    for query in [
        QueryKind::Ssrt,
        QueryKind::Em,
        QueryKind::Dit,
        QueryKind::Vct,
    ] {
        let p = PathParams {
            query,
            visibility: true,
            primary: 1,
            direct: 1,
            indirect: 1,
            near_primary: 2,
            near_distance: 0.1,
            ..*params
        };
        group.bench_function(format!("sample.path/reuse/{}", query.name()), |b| {
            b.iter(|| sample_path(inputs, &p, &mut out).unwrap())
        });
        if query == QueryKind::Em {
            // The estimator's floor at these counts: no objects, so no primaries,
            // shadows or reflections to trace; em's query is one impostor lookup by
            // direction.
            let no_objects = VirtualScene::default();
            let bare = PathInputs {
                objects: &no_objects,
                ..*inputs
            };
            group.bench_function("sample.path/reuse/em_no_objects", |b| {
                b.iter(|| sample_path(&bare, &p, &mut out).unwrap())
            });
        }
    }
}

criterion_group!(benches, bench_sampling);
criterion_main!(benches);
