//! Nine-coefficient spherical harmonics for low-frequency (indirect) light (paper 004
//! Sec. 4.4, eqs. 9-10), with the irradiance convolution of Ramamoorthi and Hanrahan,
//! "An efficient representation for irradiance environment maps" (SIGGRAPH 2001).
//!
//! Basis and sign convention: the real SH of bands 0-2 exactly as R&H write them
//! (their eq. 3), evaluated on the **world** coordinates (x, y, z) of a unit direction,
//! in this order:
//!
//! | k | Y | formula |
//! |---|---|---|
//! | 0 | Y00 | 0.282095 |
//! | 1 | Y1-1 | 0.488603 y |
//! | 2 | Y10 | 0.488603 z |
//! | 3 | Y11 | 0.488603 x |
//! | 4 | Y2-2 | 1.092548 x y |
//! | 5 | Y2-1 | 1.092548 y z |
//! | 6 | Y20 | 0.315392 (3 z^2 - 1) |
//! | 7 | Y21 | 1.092548 x z |
//! | 8 | Y22 | 0.546274 (x^2 - y^2) |
//!
//! So the formulas' polar ("up") axis is world **z**, which in relume's rooms is
//! horizontal; world up is +y. Nothing depends on which axis is polar: each band is
//! closed under rotation and the clamped-cosine convolution scales whole bands, so the
//! irradiance is the same for any choice. Consumers must only use [`sh9_basis`] for both
//! projection and evaluation.

use super::EnvMap;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// Clamped-cosine convolution factors per band (R&H eq. 8): A0 = pi, A1 = 2 pi / 3,
/// A2 = pi / 4, repeated per coefficient.
pub const SH9_COSINE_LOBE: [f64; 9] = [
    PI,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
];

/// The nine basis functions at unit direction (x, y, z) (table in the module docs).
#[inline]
pub fn sh9_basis(d: DVec3) -> [f64; 9] {
    let (x, y, z) = (d.x, d.y, d.z);
    [
        0.282095,
        0.488603 * y,
        0.488603 * z,
        0.488603 * x,
        1.092548 * x * y,
        1.092548 * y * z,
        0.315392 * (3.0 * z * z - 1.0),
        1.092548 * x * z,
        0.546274 * (x * x - y * y),
    ]
}

/// Radiance SH coefficients C_k = sum over texels of L Y_k(d) dOmega (eq. 10), with the
/// exact solid angle of each texel and its centre direction, accumulated in f64 per row
/// and then over rows in order (deterministic for any thread count). Non-finite texels
/// count as black. Assumes `map.radiance.len() == width * height`.
pub fn project_sh9(map: &EnvMap) -> [Vec3; 9] {
    let width = map.width as usize;
    if width == 0 || map.height == 0 {
        return [Vec3::ZERO; 9];
    }
    // Per column (cos phi, sin phi) of the texel centres.
    let phis: Vec<(f64, f64)> = (0..width)
        .map(|c| {
            let phi = (c as f64 + 0.5) / width as f64 * 2.0 * PI;
            (phi.cos(), phi.sin())
        })
        .collect();
    let rows: Vec<[DVec3; 9]> = map
        .radiance
        .par_chunks(width)
        .enumerate()
        .map(|(row, texels)| {
            let theta = (row as f64 + 0.5) / map.height as f64 * PI;
            let (st, ct) = theta.sin_cos();
            let d_omega = map.texel_solid_angle(row as u32) as f64;
            let mut sum = [DVec3::ZERO; 9];
            for (l, &(cp, sp)) in texels.iter().zip(&phis) {
                if !l.is_finite() {
                    continue;
                }
                let y = sh9_basis(DVec3::new(st * cp, ct, st * sp));
                let l = l.as_dvec3() * d_omega;
                for (s, yk) in sum.iter_mut().zip(y) {
                    *s += l * yk;
                }
            }
            sum
        })
        .collect();
    let mut total = [DVec3::ZERO; 9];
    for row in &rows {
        for (t, r) in total.iter_mut().zip(row) {
            *t += *r;
        }
    }
    total.map(|c| c.as_vec3())
}

/// Irradiance at a surface with unit normal `normal` from radiance SH coefficients:
/// E(n) = sum_k A_l C_k Y_k(n) (R&H eq. 7), i.e. eq. 9 without the rho / pi of the BRDF
/// and without occlusion. A constant radiance L gives pi L.
#[inline]
pub fn sh9_irradiance(coeffs: &[Vec3; 9], normal: Vec3) -> Vec3 {
    let y = sh9_basis(normal.as_dvec3());
    let mut e = Vec3::ZERO;
    for k in 0..9 {
        e += coeffs[k] * (SH9_COSINE_LOBE[k] * y[k]) as f32;
    }
    e
}

/// The mean relative error of SH9 irradiance against [`EnvMap::irradiance_brute_force`]
/// over `normals` (unit), for `relume eval` (`sh_irradiance_rel_error`): per normal
/// |E_sh - E_brute|_1 / |E_brute|_1 (sums over the three channels); normals where the
/// brute-force irradiance is 0 count 0 when SH gives 0 too and 1 otherwise. 0 for no
/// normals.
pub fn sh_irradiance_rel_error(map: &EnvMap, normals: &[Vec3]) -> f64 {
    if normals.is_empty() {
        return 0.0;
    }
    let coeffs = project_sh9(map);
    let errors: Vec<f64> = normals
        .par_iter()
        .map(|&n| {
            let reference = map.irradiance_brute_force(n).as_dvec3();
            let sh = sh9_irradiance(&coeffs, n).as_dvec3();
            let denominator = reference.abs().element_sum();
            let difference = (sh - reference).abs().element_sum();
            if denominator > 0.0 {
                difference / denominator
            } else if difference == 0.0 {
                0.0
            } else {
                1.0
            }
        })
        .collect();
    errors.iter().sum::<f64>() / normals.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit normals spread over the sphere (a Fibonacci lattice).
    fn normals(count: usize) -> Vec<Vec3> {
        let golden = PI * (3.0 - 5f64.sqrt());
        (0..count)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / count as f64;
                let r = (1.0 - y * y).sqrt();
                let phi = golden * i as f64;
                Vec3::new((r * phi.cos()) as f32, y as f32, (r * phi.sin()) as f32)
            })
            .collect()
    }

    #[test]
    fn basis_is_orthonormal_under_the_texel_quadrature() {
        let map = EnvMap::constant(256, 128, Vec3::ONE);
        let mut gram = [[0.0f64; 9]; 9];
        for i in 0..map.radiance.len() {
            let y = sh9_basis(map.texel_direction(i).as_dvec3());
            let w = map.texel_solid_angle((i / 256) as u32) as f64;
            for a in 0..9 {
                for b in 0..9 {
                    gram[a][b] += y[a] * y[b] * w;
                }
            }
        }
        for (a, row) in gram.iter().enumerate() {
            for (b, &g) in row.iter().enumerate() {
                let expected = if a == b { 1.0 } else { 0.0 };
                assert!((g - expected).abs() < 2e-3, "<Y{a}, Y{b}> = {g}");
            }
        }
    }

    #[test]
    fn constant_map_gives_pi_l_for_every_normal() {
        let l = Vec3::new(1.0, 2.0, 0.5);
        let coeffs = project_sh9(&EnvMap::constant(128, 64, l));
        for n in normals(50) {
            let e = sh9_irradiance(&coeffs, n);
            let expected = l * std::f32::consts::PI;
            assert!(
                (e - expected).abs().max_element() < 1e-3 * 2.0 * PI as f32,
                "{n} {e}"
            );
        }
        assert!(
            (coeffs[0] - l * (4.0 * PI as f32 * 0.282095))
                .abs()
                .max_element()
                < 1e-3
        );
        for (k, c) in coeffs.iter().enumerate().skip(1) {
            // Only the quadrature's error: 128 x 64 texel centres.
            assert!(c.abs().max_element() < 2e-3, "C{k} = {c}");
        }
    }

    #[test]
    fn smooth_map_is_within_one_percent_of_brute_force() {
        let map = EnvMap::from_fn(128, 64, |d| {
            Vec3::new(
                1.0 + 0.5 * d.y + 0.3 * d.x * d.x,
                0.8 + 0.2 * d.z - 0.3 * d.y * d.x,
                0.6 + 0.4 * d.y * d.y,
            )
        });
        let error = sh_irradiance_rel_error(&map, &normals(200));
        eprintln!("smooth map: SH9 mean relative irradiance error {error}");
        assert!(error < 0.01, "mean relative error {error}");
        // A degree-2 polynomial map is band-limited: the error is the quadrature's only.
        assert!(error < 1e-4, "mean relative error {error}");
    }

    #[test]
    fn a_sky_with_sun_is_close_but_not_exact() {
        // Not band-limited: the SH9 error of R&H for real maps is a few percent at most.
        let map = EnvMap::from_fn(128, 64, |d| {
            Vec3::splat(0.5 + 0.5 * d.y.max(0.0))
                + Vec3::splat(5.0) * d.dot(Vec3::Y).max(0.0).powi(8)
        });
        let error = sh_irradiance_rel_error(&map, &normals(100));
        eprintln!("sky with sun: SH9 mean relative irradiance error {error}");
        assert!(error > 1e-3 && error < 0.06, "mean relative error {error}");
    }

    #[test]
    fn projection_is_deterministic_across_thread_counts() {
        let map = EnvMap::from_fn(97, 41, |d| Vec3::new(d.x.abs() * 3.0, d.y + 1.5, d.z * d.z));
        let one = relume_base::threads::with_threads(1, || project_sh9(&map));
        let three = relume_base::threads::with_threads(3, || project_sh9(&map));
        let bits = |c: [Vec3; 9]| c.map(|v| v.to_array().map(f32::to_bits));
        assert_eq!(bits(one), bits(three));
    }
}
