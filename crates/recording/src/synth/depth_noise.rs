//! Kinect-like depth from clean ground truth: axial noise growing with z^2, disparity
//! quantization, holes at grazing angles and behind depth discontinuities, out-of-range
//! holes, and random dropouts in small blobs. Stored in integer depth units (0 = missing).
//!
//! Every random decision is keyed by (seed, frame, purpose, pixel or blob cell), so the
//! result does not depend on the number of threads.

use super::render::{pixel_direction, purpose};
use crate::types::Intrinsics;
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::depth_is_valid;
use relume_base::rng::Counter;

/// Nearest measurable depth (m); closer surfaces are holes.
pub const MIN_RANGE_M: f64 = 0.4;
/// Farthest measurable depth (m).
pub const MAX_RANGE_M: f64 = 8.0;
/// Axial noise: sigma(z) = `NOISE_BASE_M + NOISE_QUADRATIC * (z - 0.4)^2` metres.
pub const NOISE_BASE_M: f64 = 0.0012;
/// See [`NOISE_BASE_M`].
pub const NOISE_QUADRATIC: f64 = 0.0019;
/// Inverse-depth quantization step (1/m): Kinect v1 resolves 1/8 pixel of disparity
/// with a 7.5 cm baseline and a 580 px focal length, so depth steps are about
/// 0.0029 * z^2 m (3 mm at 1 m, 2.6 cm at 3 m).
pub const DISPARITY_STEP: f64 = 0.125 / (580.0 * 0.075);
/// A pixel whose |cos| between normal and view ray is below
/// `GRAZING_COS + GRAZING_JITTER * uniform` is a hole.
pub const GRAZING_COS: f32 = 0.15;
/// See [`GRAZING_COS`].
pub const GRAZING_JITTER: f32 = 0.05;
/// Probability of a hole on the far side of a depth jump (the projector's shadow).
pub const FAR_SIDE_HOLE: f32 = 0.85;
/// Probability of a hole on the near side of a depth jump.
pub const NEAR_SIDE_HOLE: f32 = 0.3;
/// Side of the square cells that may each hold one dropout blob (pixels).
pub const DROPOUT_CELL: u32 = 8;
/// Probability that a cell holds a blob; with radii uniform in 1..3 px this drops about
/// 1 percent of the pixels.
pub const DROPOUT_PROBABILITY: f32 = 0.05;

/// The smallest jump between neighbouring pixels counted as a discontinuity: a few
/// centimetres, or more where one pixel spans more than that on a steep but continuous
/// surface (`8 z / fx`, which bounds the step of surfaces not already grazing holes).
fn jump_threshold(z: f32, fx: f64) -> f32 {
    0.03f32.max(8.0 * z / fx as f32)
}

/// Clean depth in units of `unit_m` (0 = missing), rounded, clamped to the u16 range.
pub fn clean_depth_units(depth: &[f32], unit_m: f64) -> Vec<u16> {
    depth
        .iter()
        .map(|&z| metres_to_units(z as f64, unit_m))
        .collect()
}

fn metres_to_units(z: f64, unit_m: f64) -> u16 {
    if z.is_finite() && z > 0.0 {
        (z / unit_m).round().clamp(1.0, u16::MAX as f64) as u16
    } else {
        0
    }
}

/// Kinect-like depth units from clean camera-space depth `depth` (m) and camera-space
/// `normals` of the view with intrinsics `k`.
pub fn noisy_depth_units(
    depth: &[f32],
    normals: &[Vec3],
    k: &Intrinsics,
    seed: u64,
    frame: u64,
    unit_m: f64,
) -> Vec<u16> {
    let (w, h) = (k.width as usize, k.height as usize);
    let mut out = vec![0u16; depth.len()];
    if depth.len() != w * h || normals.len() != depth.len() {
        return out;
    }
    let dropouts = dropout_mask(seed, frame, k.width, k.height);
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, unit) in row.iter_mut().enumerate() {
                *unit = if dropouts[y * w + x] {
                    0
                } else {
                    noisy_pixel(depth, normals, k, seed, frame, unit_m, x, y)
                };
            }
        });
    out
}

#[allow(clippy::too_many_arguments)]
fn noisy_pixel(
    depth: &[f32],
    normals: &[Vec3],
    k: &Intrinsics,
    seed: u64,
    frame: u64,
    unit_m: f64,
    x: usize,
    y: usize,
) -> u16 {
    let (w, h) = (k.width as usize, k.height as usize);
    let i = y * w + x;
    let z = depth[i];
    if !depth_is_valid(z) || (z as f64) < MIN_RANGE_M || (z as f64) > MAX_RANGE_M {
        return 0;
    }
    let pixel = i as u64;
    let mut holes = Counter::new(&[seed, frame, purpose::DEPTH_HOLES, pixel]);
    let ray = pixel_direction(k, x as u32, y as u32);
    let cos = normals[i].dot(ray).abs() / ray.length();
    if cos < GRAZING_COS + GRAZING_JITTER * holes.next_f32() {
        return 0;
    }
    let threshold = jump_threshold(z, k.fx);
    let (mut far_side, mut near_side) = (false, false);
    for ny in y.saturating_sub(1)..(y + 2).min(h) {
        for nx in x.saturating_sub(1)..(x + 2).min(w) {
            let zn = depth[ny * w + nx];
            if !depth_is_valid(zn) || z - zn > threshold {
                far_side = true;
            } else if zn - z > threshold {
                near_side = true;
            }
        }
    }
    let r = holes.next_f32();
    if (far_side && r < FAR_SIDE_HOLE) || (near_side && r < NEAR_SIDE_HOLE) {
        return 0;
    }
    let z = z as f64;
    let mut noise = Counter::new(&[seed, frame, purpose::DEPTH_NOISE, pixel]);
    let sigma = NOISE_BASE_M + NOISE_QUADRATIC * (z - MIN_RANGE_M).powi(2);
    let noisy = (z + sigma * noise.next_gaussian()).max(MIN_RANGE_M);
    let steps = (1.0 / noisy / DISPARITY_STEP).round().max(1.0);
    metres_to_units(1.0 / (steps * DISPARITY_STEP), unit_m)
}

/// The dropout blobs of a `width` x `height` frame (true = dropped). Each
/// `DROPOUT_CELL`-square cell holds a blob with probability `DROPOUT_PROBABILITY`,
/// centred anywhere in the cell, with a radius of 1 to 3 pixels.
pub fn dropout_mask(seed: u64, frame: u64, width: u32, height: u32) -> Vec<bool> {
    let (w, h) = (width as usize, height as usize);
    let mut mask = vec![false; w * h];
    let size = DROPOUT_CELL as f32;
    for cell_y in 0..height.div_ceil(DROPOUT_CELL) as u64 {
        for cell_x in 0..width.div_ceil(DROPOUT_CELL) as u64 {
            let mut r = Counter::new(&[seed, frame, purpose::DEPTH_DROPOUT, cell_x, cell_y]);
            if r.next_f32() >= DROPOUT_PROBABILITY {
                continue;
            }
            let centre_x = (cell_x as f32 + r.next_f32()) * size;
            let centre_y = (cell_y as f32 + r.next_f32()) * size;
            let radius = 1.0 + 2.0 * r.next_f32();
            let x0 = (centre_x - radius).floor().max(0.0) as usize;
            let y0 = (centre_y - radius).floor().max(0.0) as usize;
            let x1 = ((centre_x + radius).ceil() as usize).min(w);
            let y1 = ((centre_y + radius).ceil() as usize).min(h);
            for y in y0..y1 {
                for x in x0..x1 {
                    let (dx, dy) = (x as f32 + 0.5 - centre_x, y as f32 + 0.5 - centre_y);
                    if dx * dx + dy * dy <= radius * radius {
                        mask[y * w + x] = true;
                    }
                }
            }
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(width: u32, height: u32, z: f32) -> (Intrinsics, Vec<f32>, Vec<Vec3>) {
        let k = Intrinsics::PRIMESENSE.scaled_to(width, height);
        let n = (width * height) as usize;
        (k, vec![z; n], vec![Vec3::NEG_Z; n])
    }

    #[test]
    fn clean_units_round_and_keep_missing() {
        assert_eq!(
            clean_depth_units(&[0.0, 1.0, 0.00031, f32::NAN, 20.0], 0.0002),
            vec![0, 5000, 2, 0, 65535]
        );
    }

    #[test]
    fn noise_grows_with_depth_and_dropouts_are_about_one_percent() {
        let mut errors = Vec::new();
        for z in [1.0f32, 3.0] {
            let (k, depth, normals) = plane(160, 120, z);
            let units = noisy_depth_units(&depth, &normals, &k, 7, 0, 0.0002);
            let valid: Vec<f64> = units
                .iter()
                .filter(|&&u| u > 0)
                .map(|&u| u as f64 * 0.0002)
                .collect();
            let holes = 1.0 - valid.len() as f64 / units.len() as f64;
            assert!((0.003..0.03).contains(&holes), "hole fraction {holes}");
            let rms = (valid.iter().map(|v| (v - z as f64).powi(2)).sum::<f64>()
                / valid.len() as f64)
                .sqrt();
            errors.push(rms);
        }
        assert!(
            errors[0] < 0.006 && errors[1] > 2.0 * errors[0],
            "{errors:?}"
        );
    }

    #[test]
    fn grazing_surfaces_and_far_sides_of_jumps_are_holes() {
        let (k, mut depth, mut normals) = plane(64, 48, 2.0);
        // Left half at 2 m, right half at 3 m.
        for y in 0..48 {
            for x in 32..64 {
                depth[y * 64 + x] = 3.0;
            }
        }
        let units = noisy_depth_units(&depth, &normals, &k, 1, 0, 0.0002);
        let far_edge_holes = (0..48).filter(|&y| units[y * 64 + 32] == 0).count();
        assert!(far_edge_holes > 30, "{far_edge_holes}");
        // A surface seen almost edge-on is all holes.
        for (i, n) in normals.iter_mut().enumerate() {
            let ray = pixel_direction(&k, (i % 64) as u32, (i / 64) as u32);
            *n = ray.cross(Vec3::X).normalize();
        }
        depth.iter_mut().for_each(|z| *z = 2.0);
        let units = noisy_depth_units(&depth, &normals, &k, 1, 0, 0.0002);
        assert!(units.iter().all(|&u| u == 0));
    }
}
