//! Per-frame cost of `composite.differential`'s math at 640x480 on synthetic inputs:
//! four irradiance layers with E_RV well below E_R inside a disc (a tenth of the image,
//! as under and around a virtual object) and slightly below it on most other pixels (as
//! in real frames, where the objects block some light everywhere), the mask 0 on a
//! smaller disc (the object), a smooth camera image, a channel-mixing inverse
//! compensation.
//!
//! - `composite/640x480`: [`composite`] into fresh output images, as the stage runs it
//!   once per frame (the issue-5 budget: median <= 3 ms on 2 cores).

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{Mat3, Vec3};
use relume::raster::{Image, ScalarImage, Vec3Image};
use relume::rng::{hash, unit_f32};
use relume::stages::composite::{
    CompositeInputs, CompositeOutputs, CompositeParams, GammaEncoder, composite,
};
use std::hint::black_box;

const W: u32 = 640;
const H: u32 = 480;

struct Layers {
    e: [Vec3Image; 4],
    mask: ScalarImage,
    k_v: Vec3Image,
    radiance: Vec3Image,
}

fn layers() -> Layers {
    let noise = |salt: u64, i: usize| {
        Vec3::new(
            unit_f32(hash(&[salt, i as u64, 0])),
            unit_f32(hash(&[salt, i as u64, 1])),
            unit_f32(hash(&[salt, i as u64, 2])),
        )
    };
    let image = |f: &dyn Fn(usize, f32) -> Vec3| Image {
        width: W,
        height: H,
        data: (0..(W * H) as usize)
            .map(|i| {
                let (x, y) = ((i % W as usize) as f32, (i / W as usize) as f32);
                let r2 = (x - 320.0).powi(2) + (y - 300.0).powi(2);
                f(i, r2)
            })
            .collect(),
    };
    // A disc of radius 98 px is a tenth of the image; the object is the inner 60 px.
    let (region, object) = (98.0f32 * 98.0, 60.0f32 * 60.0);
    let e_r_dir = image(&|i, _| 0.5 + 0.5 * noise(1, i));
    let e_r_ind = image(&|i, _| 0.1 + 0.1 * noise(2, i));
    // Objects block some of the room's light everywhere: E_RV is a little below E_R on
    // 94 % of the pixels of a real frame (frames 10-13 of the built-in recording).
    let e_rv_dir = image(&|i, r2| {
        if r2 < region {
            0.2 + 0.5 * noise(3, i)
        } else if hash(&[5, i as u64]) % 100 < 94 {
            0.97 * e_r_dir.data[i]
        } else {
            e_r_dir.data[i]
        }
    });
    let e_rv_ind = image(&|i, _| e_r_ind.data[i]);
    Layers {
        mask: Image {
            width: W,
            height: H,
            data: image(&|_, r2| Vec3::splat((r2 >= object) as u8 as f32))
                .data
                .iter()
                .map(|v| v.x)
                .collect(),
        },
        k_v: image(&|_, _| Vec3::new(0.7, 0.5, 0.3)),
        // A smooth camera image with a little noise, bright enough to clip in a corner.
        radiance: image(&|i, _| {
            let (x, y) = (
                (i % W as usize) as f32 / W as f32,
                (i / W as usize) as f32 / H as f32,
            );
            Vec3::new(0.05 + x, 0.05 + 0.8 * y, 0.3 + 0.4 * x * y) + 0.02 * noise(4, i)
        }),
        e: [e_r_dir, e_r_ind, e_rv_dir, e_rv_ind],
    }
}

fn bench_composite(c: &mut Criterion) {
    // The allocation policy the relume binary runs with (crates/graph/src/memory.rs).
    relume::graph::memory::keep_freed_memory();
    let layers = layers();
    let inputs = CompositeInputs {
        e_r_dir: &layers.e[0],
        e_r_ind: &layers.e[1],
        e_rv_dir: &layers.e[2],
        e_rv_ind: &layers.e[3],
        mask: &layers.mask,
        k_v: &layers.k_v,
        radiance: &layers.radiance,
        inverse_compensation: Mat3::from_cols_array(&[
            1.1, 0.05, 0.0, 0.02, 0.95, 0.03, 0.0, 0.04, 1.02,
        ]),
    };
    let params = CompositeParams::default();
    let encoder = GammaEncoder::new(params.gamma);
    let mut group = c.benchmark_group("composite");
    group.bench_function("640x480", |b| {
        b.iter(|| {
            let mut out = CompositeOutputs::new(W, H);
            composite(black_box(&inputs), &params, &encoder, &mut out).unwrap();
            out
        })
    });
    group.finish();
}

criterion_group!(benches, bench_composite);
criterion_main!(benches);
