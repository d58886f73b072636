//! The preparation in lanes against the scalar one, and the fused preparation and X
//! pass against the two apart, bit for bit.

use super::lane_planes::{LaneLayout, LanePlanes, fill_line};
use super::layout::{BandwidthSettings, INPUT_PLANES, PrepareInputs, X_PLANES};
use super::passes::{XSet, prepare_x_pass, x_pass};
use super::planes::{prepare, prepare_pixel, row_scratch};
use super::prepare_lanes::*;
use glam::Vec3;
use relume_base::raster::{Image, ScalarImage, Vec3Image};
use relume_base::rng::{hash, unit_f32};
use relume_base::simd::Kernel;
use relume_base::simd::Portable;

fn noise(seed: u64, i: usize) -> f32 {
    unit_f32(hash(&[seed, i as u64]))
}

/// Picks one of `specials` for about one pixel in five, else `regular`.
fn sometimes(seed: u64, i: usize, specials: &[f32], regular: f32) -> f32 {
    let k = (noise(seed, i) * 5.0 * specials.len() as f32) as usize;
    specials.get(k).copied().unwrap_or(regular)
}

struct Images {
    layers: [Vec3Image; 4],
    position: Vec3Image,
    normal: Vec3Image,
    zd: ScalarImage,
    zi: ScalarImage,
    exponent: ScalarImage,
}

/// A bumpy surface with what the bandwidths must survive: missing positions and
/// normals (NaN, infinite), zero normals, neighbours at the same position, missing
/// and non-positive distances and exponents, missing values.
fn images(w: usize, h: usize) -> Images {
    let vec3 = |f: &dyn Fn(usize) -> Vec3| -> Vec3Image {
        Image::from_vec(w as u32, h as u32, (0..w * h).map(f).collect()).unwrap()
    };
    let scalar = |f: &dyn Fn(usize) -> f32| -> ScalarImage {
        Image::from_vec(w as u32, h as u32, (0..w * h).map(f).collect()).unwrap()
    };
    let position = vec3(&|i| {
        let (x, y) = ((i % w) as f32, (i / w) as f32);
        let z = 2.0 + 0.05 * noise(1, i);
        let p = Vec3::new(0.01 * x, 0.01 * y, z);
        match (noise(2, i) * 20.0) as u32 {
            0 => Vec3::NAN,
            1 => Vec3::new(f32::INFINITY, 0.0, 1.0),
            // The same position as the left neighbour (distance below the minimum).
            2 if i % w > 0 => Vec3::new(0.01 * (x - 1.0), 0.01 * y, z),
            _ => p,
        }
    });
    let normal = vec3(&|i| match (noise(3, i) * 20.0) as u32 {
        0 => Vec3::ZERO,
        1 => Vec3::new(0.0, f32::NAN, 1.0),
        2 => Vec3::new(-0.0, 0.0, -0.0),
        _ => Vec3::new(noise(4, i) - 0.5, noise(5, i) - 0.5, -1.0) * 3.0,
    });
    let distances = [f32::INFINITY, f32::NAN, 0.0, -1.0, 1e-5];
    let layer = |seed: u64| {
        vec3(&|i| {
            let v = Vec3::new(noise(seed, i), noise(seed + 1, i), noise(seed + 2, i));
            if noise(seed + 3, i) < 0.1 {
                Vec3::new(v.x, f32::NAN, v.z)
            } else {
                v
            }
        })
    };
    Images {
        layers: [layer(10), layer(20), layer(30), layer(40)],
        position,
        normal,
        zd: scalar(&|i| sometimes(6, i, &distances, 0.1 + noise(7, i))),
        zi: scalar(&|i| sometimes(8, i, &distances, 0.2 + noise(9, i))),
        exponent: scalar(&|i| {
            sometimes(
                11,
                i,
                &[f32::NAN, -3.0, 0.0, -0.0, f32::INFINITY],
                64.0 * noise(12, i),
            )
        }),
    }
}

impl Images {
    fn inputs(&self) -> PrepareInputs<'_> {
        PrepareInputs {
            layers: [
                &self.layers[0],
                &self.layers[1],
                &self.layers[2],
                &self.layers[3],
            ],
            world_position: &self.position,
            world_normal: &self.normal,
            direct_min_distance: &self.zd,
            indirect_min_distance: &self.zi,
            exponent: &self.exponent,
        }
    }
}

const SETTINGS: BandwidthSettings = BandwidthSettings { b_f: 1.0, b_e: 3.0 };

/// The planes and filter widths of `prepare` with `kernel`, or pixel by pixel.
fn prepared(images: &Images, kernel: Option<Kernel>) -> Vec<u32> {
    let (w, h) = (images.position.width, images.position.height);
    let inputs = images.inputs();
    let settings = SETTINGS;
    let lanes = LaneLayout::segments(INPUT_PLANES, w as usize, h as usize, 15);
    let mut planes = LanePlanes::new(lanes);
    let mut width_dir = Image::filled(w, h, 0.0);
    let mut width_ind = Image::filled(w, h, 0.0);
    let (w, h) = (w as usize, h as usize);
    match kernel {
        Some(kernel) => prepare(
            kernel,
            &inputs,
            settings,
            &mut planes,
            &mut width_dir,
            &mut width_ind,
        ),
        None => {
            let layout = row_scratch(&lanes);
            let mut scratch = vec![0.0; layout.row_step()];
            let step = lanes.line_step();
            for y in 0..h {
                let mut out = RowOut {
                    row: &mut scratch,
                    width_dir: &mut width_dir.data[y * w..(y + 1) * w],
                    width_ind: &mut width_ind.data[y * w..(y + 1) * w],
                };
                for x in 0..w {
                    prepare_pixel(&inputs, settings, &layout, y, x, &mut out);
                }
                let line = &mut planes.data_mut()[y * step..(y + 1) * step];
                fill_line::<Portable>(&lanes, &scratch, |q| layout.in_row(q, 0), line);
            }
        }
    }
    let floats = planes
        .data()
        .iter()
        .chain(&width_dir.data)
        .chain(&width_ind.data);
    floats.map(|v| v.to_bits()).collect()
}

/// Widths around the group boundaries (a group needs a pixel on each side), and
/// single rows.
#[test]
fn groups_of_eight_give_the_bits_of_single_pixels() {
    for (w, h) in [
        (37, 6),
        (1, 1),
        (2, 3),
        (9, 2),
        (10, 1),
        (11, 2),
        (17, 3),
        (18, 1),
    ] {
        let images = images(w, h);
        let expected = prepared(&images, None);
        for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
            assert!(
                prepared(&images, Some(kernel)) == expected,
                "{kernel:?} differs from pixel by pixel at {w}x{h}"
            );
        }
    }
}

/// The bits of the X set and the filter widths from `prepare` then `x_pass`
/// (`fused` false) or from `prepare_x_pass`.
fn x_set_bits(images: &Images, kernel: Kernel, radius: usize, fused: bool) -> Vec<u32> {
    let (w, h) = (images.position.width, images.position.height);
    let (wu, hu) = (w as usize, h as usize);
    let inputs = images.inputs();
    let mut x_set = XSet::new(LaneLayout::blocks(X_PLANES, wu, hu, radius));
    let mut width_dir = Image::filled(w, h, 0.0);
    let mut width_ind = Image::filled(w, h, 0.0);
    if fused {
        let widths = [&mut width_dir, &mut width_ind];
        prepare_x_pass(kernel, &inputs, SETTINGS, radius, &mut x_set, widths);
    } else {
        let mut input = LanePlanes::new(LaneLayout::segments(INPUT_PLANES, wu, hu, radius));
        let (dir, ind) = (&mut width_dir, &mut width_ind);
        prepare(kernel, &inputs, SETTINGS, &mut input, dir, ind);
        x_pass(kernel, &input, radius, &mut x_set);
    }
    let floats = x_set
        .planes()
        .data()
        .iter()
        .chain(&width_dir.data)
        .chain(&width_ind.data);
    floats.map(|v| v.to_bits()).collect()
}

/// The fused pass (one row prepared at a time into a one-line set) gives the X set
/// and filter widths of the two passes, bit for bit: heights that are and are not
/// whole bands of rows (16), widths around the groups of eight, both kernels (on a
/// CPU without AVX2 + FMA, `Avx2Fma` runs the portable kernel), two radii.
#[test]
fn prepare_x_pass_gives_the_bits_of_prepare_then_x_pass() {
    for (w, h) in [
        (37, 6),
        (1, 1),
        (5, 17),
        (9, 2),
        (18, 1),
        (40, 33),
        (64, 16),
    ] {
        let images = images(w, h);
        for radius in [2, 15] {
            for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
                assert!(
                    x_set_bits(&images, kernel, radius, true)
                        == x_set_bits(&images, kernel, radius, false),
                    "{kernel:?}, radius {radius}: the fused pass differs at {w}x{h}"
                );
            }
        }
    }
}
