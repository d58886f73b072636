//! Per-frame cost of `filter.axis_aligned` at 640x480 on synthetic inputs: a sphere in
//! front of a plane (world positions and normals from a pinhole camera), four noisy
//! irradiance layers, finite occluder / reflector distances on part of the image, R = 15.
//!
//! - `filter.axis_aligned/temporal`: the whole filter, temporal on, with the previous
//!   frame's state in place. E_RV == E_R off the sphere (as `sample.path` makes them:
//!   equal bits away from the virtual objects), independent noise on it. The previous
//!   frame is seen from the same pose, so every group reads its temporal taps at offset
//!   0, the cheapest way: a lower bound. The issue-5 budget (median <= 25 ms on 2
//!   cores) is measured on replayed frames, whose previous pixels lie at offsets that
//!   step lane by lane: `cargo bench --bench mixed_reality -- stage/filter`.
//! - `filter.axis_aligned/temporal_rv_differs`: the same with E_RV != E_R everywhere
//!   (as on real frames, where the objects change E_RV a little almost everywhere; the
//!   filter's cost does not depend on it).
//! - `filter.axis_aligned/temporal_moving`: temporal on, the camera moving between
//!   frames (2 cm sideways, 0.5 degrees of turn; the world positions are kept, so only
//!   the reprojection changes): pixels find their previous pixels at other offsets.
//!   Still smoother than real frames: counted once, 70 % of its groups read their taps
//!   at one offset that is a multiple of 8 and 4 % at several offsets, against 5 % and
//!   42 % on replayed frames of the synthetic recording.
//! - `filter.axis_aligned/spatial`: temporal off (E_RV == E_R off the sphere).
//! - `pass/prepare_x`, `pass/y_spatial`, `pass/y_temporal`: the passes the stage runs,
//!   alone (where the time goes), with the kernel the CPU runs (AVX2 + FMA where it has
//!   them): the preparation fused with the X pass row by row, then the Y pass;
//!   `pass/prepare` and `pass/x`: the preparation and the X pass each over the whole
//!   image (the reference form of the fused pass);
//!   `pass/x_portable`: the X pass with the portable kernel (CPUs without them). The
//!   temporal pass's previous frame is the same frame, so every pixel finds itself and
//!   the temporal taps are read contiguously.
//! - `environment_bandwidth/512x256`: B_e of a map (once per map in the stage).

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{Affine3A, Vec3};
use relume::light::EnvMap;
use relume::pinhole::Pinhole;
use relume::raster::{Image, ScalarImage, Vec3Image};
use relume::recording::{Intrinsics, Pose};
use relume::rng::{hash, unit_f32};
use relume::simd::Kernel;
use relume::stages::filter::lane_planes::{LaneLayout, LanePlanes};
use relume::stages::filter::layout::{BandwidthSettings, INPUT_PLANES, PrepareInputs, X_PLANES};
use relume::stages::filter::passes::{self, Previous, XSet};
use relume::stages::filter::planes;
use relume::stages::filter::temporal::PreviousView;
use relume::stages::filter::{
    AxisAlignedFilter, FilterInputs, FilterOutputs, FilterParams, environment_bandwidth,
};
use std::hint::black_box;

const W: u32 = 640;
const H: u32 = 480;
const RADIUS: usize = 15;

struct Inputs {
    /// Independent noise in all four layers.
    layers: Vec<[Vec3Image; 4]>,
    /// E_RV == E_R off the sphere.
    layers_rv_equal: Vec<[Vec3Image; 4]>,
    position: Vec3Image,
    normal: Vec3Image,
    zd: ScalarImage,
    zi: ScalarImage,
    exponent: ScalarImage,
}

/// A sphere (radius 0.4 m, 2 m ahead) in front of a plane at 3 m; `frames` sets of
/// layers with independent noise; occluders / reflectors at 0.3-0.8 m on the lower half
/// (as under an object), none above; Phong exponent 64 on the sphere.
fn inputs(frames: usize) -> Inputs {
    let cam = Pinhole::new(&Intrinsics::PRIMESENSE, W, H);
    let center = Vec3::new(0.1, 0.1, 2.0);
    let radius = 0.4;
    let n = (W * H) as usize;
    let (mut position, mut normal) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut on_sphere = Vec::with_capacity(n);
    for v in 0..H {
        for u in 0..W {
            let ray = cam.ray(u as f32, v as f32);
            let d = ray.normalize();
            let b = d.dot(center);
            let disc = b * b - (center.length_squared() - radius * radius);
            if disc >= 0.0 {
                let p = d * (b - disc.sqrt());
                position.push(p);
                normal.push((p - center) / radius);
                on_sphere.push(true);
            } else {
                position.push(ray * 3.0);
                normal.push(Vec3::NEG_Z);
                on_sphere.push(false);
            }
        }
    }
    let noise = |seed: u64, i: usize| unit_f32(hash(&[seed, i as u64]));
    let layers = (0..frames as u64)
        .map(|f| {
            std::array::from_fn(|k| {
                let data = (0..n)
                    .map(|i| {
                        let s = 10 * f + k as u64;
                        Vec3::new(noise(s, i), noise(s + 100, i), noise(s + 200, i)) * 2.0
                    })
                    .collect();
                Image::from_vec(W, H, data).unwrap()
            })
        })
        .collect::<Vec<[Vec3Image; 4]>>();
    let layers_rv_equal = layers
        .iter()
        .map(|l| {
            std::array::from_fn(|k| {
                if k < 2 {
                    return l[k].clone();
                }
                let data = (0..n)
                    .map(|i| {
                        if on_sphere[i] {
                            l[k].data[i]
                        } else {
                            l[k - 2].data[i]
                        }
                    })
                    .collect();
                Image::from_vec(W, H, data).unwrap()
            })
        })
        .collect();
    let distance = |seed: u64| {
        let data = (0..n)
            .map(|i| {
                if i / W as usize > H as usize / 2 {
                    0.3 + 0.5 * noise(seed, i)
                } else {
                    f32::INFINITY
                }
            })
            .collect();
        Image::from_vec(W, H, data).unwrap()
    };
    let exponent = on_sphere
        .iter()
        .map(|&s| if s { 64.0 } else { 0.0 })
        .collect();
    Inputs {
        layers,
        layers_rv_equal,
        position: Image::from_vec(W, H, position).unwrap(),
        normal: Image::from_vec(W, H, normal).unwrap(),
        zd: distance(1000),
        zi: distance(1001),
        exponent: Image::from_vec(W, H, exponent).unwrap(),
    }
}

impl Inputs {
    fn frame(&self, f: usize, rv_equal: bool, moving: bool) -> FilterInputs<'_> {
        let layers = if rv_equal {
            &self.layers_rv_equal
        } else {
            &self.layers
        };
        let l = &layers[f % layers.len()];
        // Alternating between two poses.
        let pose = if moving && f % 2 == 1 {
            Pose::from_parts(
                glam::DVec3::new(0.02, 0.0, 0.0),
                glam::DQuat::from_rotation_y(0.5f64.to_radians()),
            )
        } else {
            Pose::IDENTITY
        };
        FilterInputs {
            layers: [&l[0], &l[1], &l[2], &l[3]],
            world_position: &self.position,
            world_normal: &self.normal,
            direct_min_distance: &self.zd,
            indirect_min_distance: &self.zi,
            exponent: &self.exponent,
            environment: None,
            view: Some((pose, Pinhole::new(&Intrinsics::PRIMESENSE, W, H))),
        }
    }
}

fn bench_filter(c: &mut Criterion) {
    // The allocation policy the relume binary runs with (crates/graph/src/memory.rs).
    relume::graph::memory::keep_freed_memory();
    let input = inputs(2);
    let mut group = c.benchmark_group("filter_640x480");
    group.sample_size(30);
    for (name, temporal, rv_equal, moving) in [
        ("temporal", true, true, false),
        ("temporal_rv_differs", true, false, false),
        ("temporal_moving", true, true, true),
        ("spatial", false, true, false),
    ] {
        let params = FilterParams {
            radius: RADIUS,
            environment_bandwidth: 4.0,
            temporal,
            ..Default::default()
        };
        let mut filter = AxisAlignedFilter::new(params);
        let mut out = FilterOutputs::new(W, H);
        filter
            .filter(&input.frame(0, rv_equal, moving), &mut out)
            .unwrap();
        let mut f = 1;
        group.bench_function(format!("filter.axis_aligned/{name}"), |b| {
            b.iter(|| {
                let mut out = FilterOutputs::new(W, H);
                filter
                    .filter(&input.frame(f, rv_equal, moving), &mut out)
                    .unwrap();
                f += 1;
                black_box(out)
            })
        });
    }

    // The passes alone.
    let (w, h) = (W as usize, H as usize);
    let l = &input.layers_rv_equal[0];
    let prep = PrepareInputs {
        layers: [&l[0], &l[1], &l[2], &l[3]],
        world_position: &input.position,
        world_normal: &input.normal,
        direct_min_distance: &input.zd,
        indirect_min_distance: &input.zi,
        exponent: &input.exponent,
    };
    let settings = BandwidthSettings { b_f: 1.0, b_e: 4.0 };
    let kernel = Kernel::detect();
    let mut input = LanePlanes::new(LaneLayout::segments(INPUT_PLANES, w, h, RADIUS));
    let mut width_dir = Image::filled(W, H, 0.0);
    let mut width_ind = Image::filled(W, H, 0.0);
    let mut prepare = || {
        planes::prepare(
            kernel,
            &prep,
            settings,
            &mut input,
            &mut width_dir,
            &mut width_ind,
        )
    };
    // Run once here too, so that the passes below have their inputs when the prepare
    // bench is filtered out.
    prepare();
    group.bench_function("pass/prepare", |b| b.iter(&mut prepare));
    let mut x_set = XSet::new(LaneLayout::blocks(X_PLANES, w, h, RADIUS));
    group.bench_function("pass/x", |b| {
        b.iter(|| passes::x_pass(kernel, &input, RADIUS, &mut x_set))
    });
    group.bench_function("pass/x_portable", |b| {
        b.iter(|| passes::x_pass(Kernel::Portable, &input, RADIUS, &mut x_set))
    });
    group.bench_function("pass/prepare_x", |b| {
        b.iter(|| {
            passes::prepare_x_pass(
                kernel,
                &prep,
                settings,
                RADIUS,
                &mut x_set,
                [&mut width_dir, &mut width_ind],
            )
        })
    });
    passes::x_pass(kernel, &input, RADIUS, &mut x_set);
    let mut out: [Vec3Image; 4] = std::array::from_fn(|_| Image::filled(W, H, Vec3::ZERO));
    // Run once here too, for the full windows of the temporal pass below.
    passes::y_pass(kernel, &mut x_set, None, RADIUS, &mut out);
    group.bench_function("pass/y_spatial", |b| {
        b.iter(|| passes::y_pass(kernel, &mut x_set, None, RADIUS, &mut out))
    });
    let view = PreviousView {
        world_to_camera: Affine3A::IDENTITY,
        camera: Pinhole::new(&Intrinsics::PRIMESENSE, W, H),
    };
    // The same set as the previous frame's, with the full windows its Y pass found.
    let previous_x_set = x_set.clone();
    let previous = Previous {
        x_set: &previous_x_set,
        view: &view,
    };
    group.bench_function("pass/y_temporal", |b| {
        b.iter(|| passes::y_pass(kernel, &mut x_set, Some(previous), RADIUS, &mut out))
    });
    let map = EnvMap::from_fn(512, 256, |d| {
        Vec3::splat(1.0 + (4.0 * d.x).sin().abs() + 10.0 * d.y.max(0.0).powi(8))
    });
    group.bench_function("environment_bandwidth/512x256", |b| {
        b.iter(|| environment_bandwidth(black_box(&map)))
    });
    group.finish();
}

criterion_group!(benches, bench_filter);
criterion_main!(benches);
