//! Per-pixel filter bandwidths of paper 001 Secs. 6-7: screen-space curvature (eq. 20),
//! the direct-light bandwidth (eq. 17, with eq. 13 as its diffuse case) and the indirect
//! bandwidth (eq. 18). Bandwidths are angular frequencies per metre of world space; the
//! filter's size is 1 / B (paper 001 Sec. 6.4 and Fig. 7's convention: eq. 23's Gaussian
//! exp(-2 Bbar^2 d^2) has standard deviation 1 / (2 Bbar)).

use crate::OpError;
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::{ScalarImage, Vec3Image};

/// World distances below this (metres) between neighbouring positions are too small to
/// give a curvature (the positions coincide up to float noise).
pub const MIN_NEIGHBOUR_DISTANCE: f32 = 1e-6;

/// Occluder / reflector distances are clamped up to this many metres, so a zero or
/// negative recorded distance gives a large but finite bandwidth.
pub const MIN_OCCLUDER_DISTANCE: f32 = 1e-3;

/// Bandwidths are clamped to this (per metre: a filter size 1 / B of 0.1 mm), so squares
/// stay finite.
pub const MAX_BANDWIDTH: f32 = 1e4;

/// Angular bandwidth B_rho of a Phong lobe cos^m about the mirror direction, per radian;
/// 0 for a diffuse surface (m = 0).
///
/// An approximation (paper 001 gives no formula): cos^m(a) ~ exp(-m a^2 / 2) is a
/// Gaussian of angular sigma 1/sqrt(m), whose spectrum is a Gaussian of width sqrt(m);
/// the factor 1.25 makes m = 64 give the paper's B_rho = 10 (Sec. 8, FURNITURE).
#[inline]
pub fn brdf_bandwidth(exponent: f32) -> f32 {
    if exponent > 0.0 {
        1.25 * exponent.sqrt()
    } else {
        0.0
    }
}

/// The bandwidth B_h of the BRDF for indirect light (paper 001 Sec. 6.5, from MWRD13):
/// 2.8 for diffuse surfaces (m = 0), 4.27 + 0.15 m for a Phong exponent m.
#[inline]
pub fn indirect_brdf_bandwidth(exponent: f32) -> f32 {
    if exponent > 0.0 {
        4.27 + 0.15 * exponent
    } else {
        2.8
    }
}

/// The visibility factor cos^2(theta_occ) / z of eqs. 13 and 17 from the occluder distance
/// the samplers record, t / cos(theta) of the nearest blocked sample: with the occluder's
/// depth z = t cos(theta) (paper 001 Fig. 3c), cos^2(theta_occ) / z = 1 / (t / cos(theta)).
/// 0 where there is no occluder (non-finite), 1 / max(value, [`MIN_OCCLUDER_DISTANCE`])
/// otherwise.
#[inline]
fn inverse_distance(z: f32) -> f32 {
    if z.is_finite() {
        1.0 / z.max(MIN_OCCLUDER_DISTANCE)
    } else {
        0.0
    }
}

/// Direct-light bandwidth along one image axis, paper 001 eq. 17:
/// B = kappa (B_f + 2 B_rho) + (cos^2(theta_occ) / z) (B_f + 2 B_rho + B_e), with
/// cos^2(theta_occ) / z = 1 / `occluder_distance` (the samplers record t / cos(theta) of
/// the nearest blocked sample, and z = t cos(theta)), and no visibility term where
/// `occluder_distance` is infinite.
/// With B_rho = 0 this is eq. 13. Clamped to [0, [`MAX_BANDWIDTH`]].
#[inline]
pub fn direct_bandwidth(
    curvature: f32,
    occluder_distance: f32,
    b_f: f32,
    b_rho: f32,
    b_e: f32,
) -> f32 {
    let angular = b_f + 2.0 * b_rho;
    let b = curvature * angular + inverse_distance(occluder_distance) * (angular + b_e);
    clamp_bandwidth(b)
}

/// Indirect bandwidth, paper 001 eq. 18: B = B_h / z_min (the same along X and Y); 0 where
/// no reflector was hit (`reflector_distance` infinite): the kernel is flat.
#[inline]
pub fn indirect_bandwidth(reflector_distance: f32, exponent: f32) -> f32 {
    clamp_bandwidth(indirect_brdf_bandwidth(exponent) * inverse_distance(reflector_distance))
}

#[inline]
fn clamp_bandwidth(b: f32) -> f32 {
    if b.is_finite() {
        b.clamp(0.0, MAX_BANDWIDTH)
    } else if b > 0.0 {
        MAX_BANDWIDTH
    } else {
        0.0
    }
}

/// The unsigned angle (radians) between two non-zero vectors, from the chord c between
/// their directions: 2 asin(c / 2) = c + c^3 / 24 + 3 c^5 / 640 + ... (three terms; no
/// libm call). Relative error: < 2e-4 up to 30 degrees, 0.8 % at 90 degrees; it
/// underestimates only beyond that, where neighbouring normals are no longer a smooth
/// surface anyway.
#[inline]
fn angle_between(a: Vec3, b: Vec3) -> f32 {
    let c = (a.normalize() - b.normalize()).length();
    let c2 = c * c;
    c * (1.0 + c2 * (1.0 / 24.0 + c2 * (3.0 / 640.0)))
}

#[inline]
fn usable(p: Vec3, n: Vec3) -> bool {
    p.is_finite() && n.is_finite() && n != Vec3::ZERO
}

/// Curvature between a pixel and one neighbour: angle of the normals over the distance of
/// the positions (eq. 20), or `None` when the neighbour is unusable or too close.
#[inline]
fn curvature_to(p: Vec3, n: Vec3, q: Vec3, m: Vec3) -> Option<f32> {
    if !usable(q, m) {
        return None;
    }
    let d = (p - q).length();
    (d >= MIN_NEIGHBOUR_DISTANCE).then(|| angle_between(n, m) / d)
}

/// Screen-space curvatures kappa_X, kappa_Y (paper 001 eq. 20): the angle between the
/// normals of neighbouring pixels over the distance between their world positions, with
/// the forward neighbour (x + 1 or y + 1), falling back to the backward one where the
/// forward one is invalid or closer than [`MIN_NEIGHBOUR_DISTANCE`]; 0 where neither is
/// usable or the pixel itself has no position or normal. Units: radians per metre.
pub fn screen_curvature(
    positions: &Vec3Image,
    normals: &Vec3Image,
    kappa_x: &mut ScalarImage,
    kappa_y: &mut ScalarImage,
) -> Result<(), OpError> {
    if !positions.same_size(normals)
        || !positions.same_size(kappa_x)
        || !positions.same_size(kappa_y)
    {
        return Err(OpError::SizeMismatch(format!(
            "filter curvature: positions {}x{}, normals {}x{}, outputs {}x{} / {}x{} differ",
            positions.width,
            positions.height,
            normals.width,
            normals.height,
            kappa_x.width,
            kappa_x.height,
            kappa_y.width,
            kappa_y.height
        )));
    }
    let w = positions.width as usize;
    if w == 0 {
        return Ok(());
    }
    kappa_x
        .data
        .par_chunks_mut(w)
        .zip(kappa_y.data.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (kx_row, ky_row))| {
            curvature_row(positions, normals, y, kx_row, ky_row);
        });
    Ok(())
}

/// kappa_X and kappa_Y of row `y` (see [`screen_curvature`]).
fn curvature_row(
    positions: &Vec3Image,
    normals: &Vec3Image,
    y: usize,
    kx_row: &mut [f32],
    ky_row: &mut [f32],
) {
    for (x, (kx, ky)) in kx_row.iter_mut().zip(ky_row.iter_mut()).enumerate() {
        (*kx, *ky) = curvature_at(positions, normals, x, y);
    }
}

/// kappa_X and kappa_Y of pixel (x, y) (see [`screen_curvature`]).
pub(super) fn curvature_at(
    positions: &Vec3Image,
    normals: &Vec3Image,
    x: usize,
    y: usize,
) -> (f32, f32) {
    let (w, h) = (positions.width as usize, positions.height as usize);
    let p = &positions.data;
    let n = &normals.data;
    let i = y * w + x;
    let (pc, nc) = (p[i], n[i]);
    if !usable(pc, nc) {
        return (0.0, 0.0);
    }
    let along = |fwd: Option<usize>, bwd: Option<usize>| {
        fwd.and_then(|j| curvature_to(pc, nc, p[j], n[j]))
            .or_else(|| bwd.and_then(|j| curvature_to(pc, nc, p[j], n[j])))
            .unwrap_or(0.0)
    };
    (
        along((x + 1 < w).then_some(i + 1), (x > 0).then(|| i - 1)),
        along((y + 1 < h).then_some(i + w), (y > 0).then(|| i - w)),
    )
}
