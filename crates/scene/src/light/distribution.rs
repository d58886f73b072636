//! Importance sampling of a lat-long environment map (paper 001 Sec. 5.2): a 2D
//! piecewise-constant distribution over the map's texels, weighted by luminance times
//! sin(theta) so that it is proportional to the radiant power each texel sends towards
//! the centre, sampled by inversion of a marginal CDF over rows and a conditional CDF per
//! row (Pharr, Jakob and Humphreys, PBRT Sec. 13.6.7).
//!
//! The map's primary sample space is (u, v) in [0, 1)^2, u = x / W along columns (phi =
//! 2 pi u) and v = y / H along rows (theta = pi v). The distribution is piecewise constant
//! in (u, v) with density p_uv(texel) = W H P(texel), and the change of variables to
//! solid angle has Jacobian dω = 2 pi^2 sin(theta) du dv, so the density per steradian is
//! exactly p_uv / (2 pi^2 sin theta) at the direction's own theta: it varies as
//! 1 / sin(theta) inside a texel. [`Distribution2D::pdf`] evaluates it there, not at the
//! texel centre.

use super::EnvMap;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// Smallest fractional offset inside a texel a sample may take: keeps sampled directions
/// off the poles (where sin theta = 0 and the pdf per steradian is infinite). It moves
/// samples by at most 1e-9 of a texel.
const MIN_FRACTION: f64 = 1e-9;

/// Rec. 709 luminance of linear RGB, with negative and non-finite values counted as 0
/// (they carry no power to sample).
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    let y = 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
    if y.is_finite() && y > 0.0 { y } else { 0.0 }
}

/// A 2D piecewise-constant distribution over the texels of a W x H lat-long map
/// (paper 001 Sec. 5.2), or the uniform distribution over the sphere when the map
/// carries no power at all (all black), so sampling never produces NaNs.
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution2D {
    width: u32,
    height: u32,
    /// Normalized marginal CDF over rows: H + 1 entries from 0 to exactly 1.
    row_cdf: Vec<f64>,
    /// Normalized conditional CDF of each row: H blocks of W + 1 entries from 0 to 1
    /// (rows without weight keep a uniform CDF; they are never chosen).
    column_cdf: Vec<f64>,
    /// Density in (u, v) of each texel, W H P(texel), row-major.
    texel_pdf_uv: Vec<f32>,
    /// No texel carries power: uniform sphere sampling.
    uniform: bool,
}

/// One draw of [`Distribution2D::sample_texel`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DistributionSample {
    /// Unit world direction.
    pub direction: Vec3,
    /// Density of `direction` per steradian.
    pub pdf: f32,
    /// Row-major index of the texel the direction lies in.
    pub texel: usize,
}

impl Distribution2D {
    /// The distribution of `env` weighted by luminance x sin(theta).
    pub fn from_env(env: &EnvMap) -> Distribution2D {
        let weights: Vec<f32> = env.radiance.par_iter().map(|&c| luminance(c)).collect();
        Self::from_weights(env.width, env.height, &weights)
    }

    /// The distribution over a W x H lat-long grid whose texel weights are `weights`
    /// (e.g. luminance) times sin(theta) of the texel centre's row; sin(theta_c) is
    /// proportional to the texel's solid angle, 2 sin(theta_c) sin(pi / 2H) 2 pi / W.
    /// Negative and non-finite weights count as 0; a grid with no positive weight (or a
    /// `weights` slice of the wrong length, or an empty grid) gives the uniform sphere.
    pub fn from_weights(width: u32, height: u32, weights: &[f32]) -> Distribution2D {
        let (w, h) = (width as usize, height as usize);
        let mut dist = Distribution2D {
            width,
            height,
            row_cdf: Vec::new(),
            column_cdf: vec![0.0; h * (w + 1)],
            texel_pdf_uv: vec![0.0; w * h],
            uniform: true,
        };
        if w == 0 || h == 0 || weights.len() != w * h {
            return dist;
        }
        // Per row: the unnormalized conditional prefix sums (f64), then the row's total.
        let row_weights: Vec<f64> = dist
            .column_cdf
            .par_chunks_mut(w + 1)
            .zip(weights.par_chunks(w))
            .enumerate()
            .map(|(row, (cdf, texels))| {
                let sin_theta = ((row as f64 + 0.5) / h as f64 * PI).sin();
                let mut sum = 0.0f64;
                cdf[0] = 0.0;
                for (c, &t) in cdf[1..].iter_mut().zip(texels) {
                    let t = if t.is_finite() && t > 0.0 {
                        t as f64
                    } else {
                        0.0
                    };
                    sum += t * sin_theta;
                    *c = sum;
                }
                if sum > 0.0 {
                    let inv = 1.0 / sum;
                    cdf[1..].iter_mut().for_each(|c| *c *= inv);
                    cdf[w] = 1.0;
                } else {
                    cdf.iter_mut()
                        .enumerate()
                        .for_each(|(i, c)| *c = i as f64 / w as f64);
                }
                sum
            })
            .collect();
        let mut row_cdf = Vec::with_capacity(h + 1);
        row_cdf.push(0.0);
        let mut total = 0.0f64;
        for &rw in &row_weights {
            total += rw;
            row_cdf.push(total);
        }
        if !(total > 0.0 && total.is_finite()) {
            return dist;
        }
        let inv_total = 1.0 / total;
        row_cdf.iter_mut().for_each(|c| *c *= inv_total);
        // Trailing rows without weight share the end point exactly.
        for c in row_cdf.iter_mut().rev() {
            if *c >= 1.0 - 1e-15 {
                *c = 1.0;
            } else {
                break;
            }
        }
        row_cdf[h] = 1.0;
        // Texel densities in (u, v) straight from the weights (not from CDF differences,
        // which lose relative precision for tiny texels).
        let scale = (w * h) as f64 * inv_total;
        dist.texel_pdf_uv
            .par_chunks_mut(w)
            .zip(weights.par_chunks(w))
            .enumerate()
            .for_each(|(row, (out, texels))| {
                let sin_theta = ((row as f64 + 0.5) / h as f64 * PI).sin();
                for (o, &t) in out.iter_mut().zip(texels) {
                    let t = if t.is_finite() && t > 0.0 {
                        t as f64
                    } else {
                        0.0
                    };
                    *o = (t * sin_theta * scale) as f32;
                }
            });
        dist.row_cdf = row_cdf;
        dist.uniform = false;
        dist
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// True when the map carried no power and the distribution is the uniform sphere.
    pub fn is_uniform(&self) -> bool {
        self.uniform
    }

    /// The probability of drawing a direction inside texel `index` (row-major); for the
    /// uniform fallback, the texel's solid angle / 4 pi. 0 for an index out of range.
    pub fn texel_probability(&self, index: usize) -> f64 {
        let (w, h) = (self.width as usize, self.height as usize);
        if index >= w * h {
            return 0.0;
        }
        if self.uniform {
            let row = index / w;
            let (t0, t1) = (row as f64 / h as f64 * PI, (row + 1) as f64 / h as f64 * PI);
            return (t0.cos() - t1.cos()) / (2.0 * w as f64);
        }
        self.texel_pdf_uv[index] as f64 / (w * h) as f64
    }

    /// A direction drawn from the distribution by inverting the CDFs at primary sample
    /// (u1 along rows, u2 along columns, both in [0, 1)), and its pdf per steradian.
    #[inline]
    pub fn sample(&self, u1: f64, u2: f64) -> (Vec3, f32) {
        let s = self.sample_texel(u1, u2);
        (s.direction, s.pdf)
    }

    /// [`Distribution2D::sample`] with the index of the texel drawn. The position inside
    /// the texel is continuous (the CDF inverted linearly inside its step), so the
    /// direction is exactly distributed with density p_uv / (2 pi^2 sin theta).
    pub fn sample_texel(&self, u1: f64, u2: f64) -> DistributionSample {
        let u1 = u1.clamp(0.0, 1.0 - f64::EPSILON);
        let u2 = u2.clamp(0.0, 1.0 - f64::EPSILON);
        let (w, h) = (self.width as usize, self.height as usize);
        if self.uniform {
            let cos_theta = 1.0 - 2.0 * u1;
            let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
            let (sp, cp) = (2.0 * PI * u2).sin_cos();
            let direction = DVec3::new(sin_theta * cp, cos_theta, sin_theta * sp).as_vec3();
            let texel = if w == 0 || h == 0 {
                0
            } else {
                let row = ((cos_theta.clamp(-1.0, 1.0).acos() / PI * h as f64) as usize).min(h - 1);
                let column = ((u2 * w as f64) as usize).min(w - 1);
                row * w + column
            };
            return DistributionSample {
                direction,
                pdf: (0.25 / PI) as f32,
                texel,
            };
        }
        let (row, fy) = invert(&self.row_cdf, u1);
        let (column, fx) = invert(&self.column_cdf[row * (w + 1)..(row + 1) * (w + 1)], u2);
        let theta = (row as f64 + fy) / h as f64 * PI;
        let phi = (column as f64 + fx) / w as f64 * 2.0 * PI;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        let texel = row * w + column;
        DistributionSample {
            direction: DVec3::new(st * cp, ct, st * sp).as_vec3(),
            pdf: (self.texel_pdf_uv[texel] as f64 / (2.0 * PI * PI * st)) as f32,
            texel,
        }
    }

    /// The density per steradian of drawing unit direction `d`: p_uv of the texel
    /// holding `d` over 2 pi^2 sin(theta) at `d`'s own theta (exact, not the texel
    /// centre's); 1 / 4 pi for the uniform fallback.
    pub fn pdf(&self, d: Vec3) -> f32 {
        if self.uniform {
            return (0.25 / PI) as f32;
        }
        let d = d.as_dvec3();
        let len = d.length();
        if !(len > 0.0 && len.is_finite()) {
            return 0.0;
        }
        let sin_theta = (d.x * d.x + d.z * d.z).sqrt() / len;
        let texel = self.texel_of(d / len);
        let p = self.texel_pdf_uv[texel] as f64;
        if p == 0.0 {
            return 0.0;
        }
        (p / (2.0 * PI * PI * sin_theta.max(1e-300))) as f32
    }

    /// The texel holding unit direction `d` (the map convention of [`EnvMap::coords_of`],
    /// in f64).
    #[inline]
    fn texel_of(&self, d: DVec3) -> usize {
        let (w, h) = (self.width as usize, self.height as usize);
        let theta = d.y.clamp(-1.0, 1.0).acos();
        let mut phi = d.z.atan2(d.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let row = ((theta / PI * h as f64) as usize).min(h - 1);
        let column = ((phi / (2.0 * PI) * w as f64) as usize).min(w - 1);
        row * w + column
    }
}

/// The step of normalized CDF `cdf` (n + 1 entries, 0 ..= 1) that holds `u` in [0, 1),
/// and `u`'s fractional position inside it, kept off the step's ends by
/// [`MIN_FRACTION`]. Steps of zero width are never returned.
#[inline]
fn invert(cdf: &[f64], u: f64) -> (usize, f64) {
    let n = cdf.len() - 1;
    // The last entry <= u: its step [cdf[i], cdf[i + 1]) holds u and has positive width.
    let i = (cdf.partition_point(|&c| c <= u) - 1).min(n - 1);
    let width = cdf[i + 1] - cdf[i];
    let f = if width > 0.0 {
        (u - cdf[i]) / width
    } else {
        0.5
    };
    (i, f.clamp(MIN_FRACTION, 1.0 - MIN_FRACTION))
}

/// The integral of `dist`'s pdf over the sphere by sub-texel quadrature (each texel
/// split into 4 rows x 2 columns of sub-cells, the pdf evaluated by
/// [`Distribution2D::pdf`] at each sub-cell's centre times its exact solid angle). A
/// correct pdf integrates to 1; the quadrature's own relative error is about
/// -(pi / 4H)^2 / 24 (the midpoint rule on 1 / sin(theta) over a sub-row): 1e-4 at
/// H = 16, 2.5e-5 at H = 32. Used by `relume eval` (`pdf_integral`) and the tests.
pub fn pdf_integral(dist: &Distribution2D) -> f64 {
    const SUB_ROWS: usize = 4;
    const SUB_COLUMNS: usize = 2;
    let (w, h) = (dist.width as usize, dist.height as usize);
    if w == 0 || h == 0 {
        return 0.0;
    }
    let (rows, columns) = (h * SUB_ROWS, w * SUB_COLUMNS);
    let d_phi = 2.0 * PI / columns as f64;
    let per_row: Vec<f64> = (0..rows)
        .into_par_iter()
        .map(|r| {
            let (t0, t1) = (
                r as f64 / rows as f64 * PI,
                (r + 1) as f64 / rows as f64 * PI,
            );
            let d_omega = d_phi * (t0.cos() - t1.cos());
            let (st, ct) = (0.5 * (t0 + t1)).sin_cos();
            let mut sum = 0.0f64;
            for c in 0..columns {
                let (sp, cp) = ((c as f64 + 0.5) * d_phi).sin_cos();
                let d = DVec3::new(st * cp, ct, st * sp).as_vec3();
                sum += dist.pdf(d) as f64;
            }
            sum * d_omega
        })
        .collect();
    per_row.iter().sum()
}

/// Pearson's chi-square test of `observed` counts against `expected` counts (same
/// order), neighbouring bins merged until each expects at least 5: (statistic, degrees of
/// freedom, p-value by the Wilson-Hilferty normal approximation, accurate for the
/// hundreds of degrees of freedom the tests use).
#[cfg(test)]
pub(crate) fn chi_square(observed: &[f64], expected: &[f64]) -> (f64, usize, f64) {
    let (mut statistic, mut bins) = (0.0, 0usize);
    let (mut o, mut e) = (0.0, 0.0);
    for (&oi, &ei) in observed.iter().zip(expected) {
        o += oi;
        e += ei;
        if e >= 5.0 {
            statistic += (o - e) * (o - e) / e;
            bins += 1;
            (o, e) = (0.0, 0.0);
        }
    }
    if e > 0.0 {
        statistic += (o - e) * (o - e) / e;
        bins += 1;
    }
    let k = (bins.max(2) - 1) as f64;
    let z = ((statistic / k).cbrt() - (1.0 - 2.0 / (9.0 * k))) / (2.0 / (9.0 * k)).sqrt();
    (
        statistic,
        bins - 1,
        0.5 * erfc(z / std::f64::consts::SQRT_2),
    )
}

/// The complementary error function (Numerical Recipes' Chebyshev fit, relative error
/// below 1.2e-7).
#[cfg(test)]
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use relume_base::rng;

    /// A 64 x 32 map with a small, very bright sun, a dim sky, a black band and a
    /// ground, so the pdf spans many orders of magnitude and has zero regions.
    pub(crate) fn peaky_map() -> EnvMap {
        let sun = Vec3::new(0.4, 0.8, 0.3).normalize();
        EnvMap::from_fn(64, 32, |d| {
            if d.dot(sun) > 0.995 {
                Vec3::new(20000.0, 18000.0, 15000.0)
            } else if d.y > 0.0 {
                Vec3::new(0.3, 0.5, 1.0) * (0.2 + d.y)
            } else if d.y > -0.2 {
                Vec3::ZERO
            } else {
                Vec3::new(0.2, 0.15, 0.1)
            }
        })
    }

    #[test]
    fn pdf_integrates_to_one_on_a_peaky_map_and_on_the_uniform_fallback() {
        let dist = Distribution2D::from_env(&peaky_map());
        assert!(!dist.is_uniform());
        let integral = pdf_integral(&dist);
        eprintln!("peaky map: pdf integral {integral:.8}");
        assert!((integral - 1.0).abs() < 1e-3, "{integral}");
        // Quadrature error (pi / 128)^2 / 24 = 2.5e-5 at H = 32: the pdf is exact.
        assert!((integral - 1.0).abs() < 5e-5, "{integral}");
        let probabilities: f64 = (0..64 * 32).map(|i| dist.texel_probability(i)).sum();
        assert!((probabilities - 1.0).abs() < 1e-6, "{probabilities}");

        let black = Distribution2D::from_env(&EnvMap::constant(64, 32, Vec3::ZERO));
        assert!(black.is_uniform());
        assert!((pdf_integral(&black) - 1.0).abs() < 1e-6);
        let probabilities: f64 = (0..64 * 32).map(|i| black.texel_probability(i)).sum();
        assert!((probabilities - 1.0).abs() < 1e-9, "{probabilities}");
    }

    #[test]
    fn pdf_is_exact_per_steradian_inside_a_texel() {
        // On a constant map p_uv = W H sin(theta_c) / (W sum_r sin(theta_r)): the pdf per
        // steradian at any theta inside row r is p_uv / (2 pi^2 sin theta).
        let (w, h) = (16u32, 8u32);
        let dist = Distribution2D::from_env(&EnvMap::constant(w, h, Vec3::ONE));
        let sum_sin: f64 = (0..h)
            .map(|r| ((r as f64 + 0.5) / h as f64 * PI).sin())
            .sum();
        for (row, frac) in [(0u32, 0.05f64), (0, 0.95), (3, 0.5), (7, 0.9)] {
            let theta = (row as f64 + frac) / h as f64 * PI;
            let d = Vec3::new(
                theta.sin() as f32 * 0.6,
                theta.cos() as f32,
                theta.sin() as f32 * 0.8,
            );
            let sin_c = ((row as f64 + 0.5) / h as f64 * PI).sin();
            let p_uv = (w * h) as f64 * sin_c / (w as f64 * sum_sin);
            let expected = p_uv / (2.0 * PI * PI * theta.sin());
            let pdf = dist.pdf(d) as f64;
            assert!(
                (pdf / expected - 1.0).abs() < 1e-5,
                "row {row} frac {frac}: {pdf} vs {expected}"
            );
        }
        // The pdf of each sample equals pdf(direction), and sampled directions are unit.
        for i in 0..2000u64 {
            let (u1, u2) = (
                rng::unit_f64(rng::hash(&[1, i, 0])),
                rng::unit_f64(rng::hash(&[1, i, 1])),
            );
            let (d, pdf) = dist.sample(u1, u2);
            assert!((d.length() - 1.0).abs() < 1e-6);
            assert!(
                (pdf / dist.pdf(d) - 1.0).abs() < 1e-4,
                "{pdf} vs {}",
                dist.pdf(d)
            );
        }
    }

    /// Draws `n` texels from `dist` with independent hashed uniforms.
    fn histogram(dist: &Distribution2D, n: u64) -> Vec<f64> {
        let mut counts = vec![0.0; (dist.width() * dist.height()) as usize];
        for i in 0..n {
            let (u1, u2) = (
                rng::unit_f64(rng::hash(&[7, i, 0])),
                rng::unit_f64(rng::hash(&[7, i, 1])),
            );
            counts[dist.sample_texel(u1, u2).texel] += 1.0;
        }
        counts
    }

    #[test]
    fn independent_samples_pass_a_chi_square_test_that_a_wrong_model_fails() {
        let map = peaky_map();
        let dist = Distribution2D::from_env(&map);
        let n = 200_000u64;
        let observed = histogram(&dist, n);
        let expected: Vec<f64> = (0..observed.len())
            .map(|i| n as f64 * dist.texel_probability(i))
            .collect();
        let (chi2, dof, p) = chi_square(&observed, &expected);
        eprintln!("chi-square {chi2:.1} on {dof} dof, p = {p:.3}");
        assert!(p > 1e-3, "chi-square {chi2} on {dof} dof, p = {p}");
        // The same histogram against luminance without the sin(theta) weight.
        let lum: Vec<f64> = map.radiance.iter().map(|&c| luminance(c) as f64).collect();
        let total: f64 = lum.iter().sum();
        let wrong: Vec<f64> = lum.iter().map(|l| n as f64 * l / total).collect();
        let (chi2, dof, p) = chi_square(&observed, &wrong);
        assert!(
            p < 1e-12,
            "the unweighted model should fail: {chi2} on {dof} dof, p = {p}"
        );
    }

    #[test]
    fn black_empty_and_bad_maps_fall_back_to_uniform_sphere_sampling() {
        let mut nan_map = EnvMap::constant(8, 4, Vec3::new(-1.0, 0.0, 0.0));
        nan_map.radiance[3] = Vec3::NAN;
        for dist in [
            Distribution2D::from_env(&EnvMap::constant(8, 4, Vec3::ZERO)),
            Distribution2D::from_env(&EnvMap::distant(0, 0, Vec::new())),
            Distribution2D::from_env(&nan_map),
            Distribution2D::from_weights(8, 4, &[1.0; 5]),
        ] {
            assert!(dist.is_uniform());
            let mut mean = DVec3::ZERO;
            for i in 0..4096u64 {
                let (d, pdf) =
                    dist.sample((i as f64 + 0.5) / 4096.0, rng::unit_f64(rng::hash(&[i])));
                assert!((d.length() - 1.0).abs() < 1e-6 && d.is_finite(), "{d}");
                assert_eq!(pdf, (0.25 / PI) as f32);
                mean += d.as_dvec3();
            }
            assert!((mean / 4096.0).length() < 0.03, "{mean}");
            assert_eq!(dist.pdf(Vec3::X), (0.25 / PI) as f32);
        }
    }

    #[test]
    fn building_is_identical_with_one_and_three_threads() {
        let map = peaky_map();
        let a = relume_base::threads::with_threads(1, || Distribution2D::from_env(&map));
        let b = relume_base::threads::with_threads(3, || Distribution2D::from_env(&map));
        let bits = |d: &Distribution2D| -> Vec<u64> {
            d.row_cdf
                .iter()
                .chain(&d.column_cdf)
                .map(|v| v.to_bits())
                .chain(d.texel_pdf_uv.iter().map(|v| v.to_bits() as u64))
                .collect()
        };
        assert_eq!(bits(&a), bits(&b));
    }
}
