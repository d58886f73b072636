//! Selection of sample pairs and their weighted moments (paper 000 Sec. 4.1, eq. (1)),
//! fused into one pass over the pixels.
//!
//! A pixel's pair is (u, r): u = the camera's linearized color, r = the reference
//! radiance. It is rejected by the first test it fails, in this order:
//! 1. **no reference**: coverage below `min_coverage`, or r not finite;
//! 2. **saturated**: any camera channel `<= dark_level` or `>= bright_level`;
//! 3. **gradient**: in either image, the relative gradient of the luminance
//!    `L = R + G + B` over the four direct neighbours (clamped at the border),
//!    `g = (|L(x+1) - L(x-1)| + |L(y+1) - L(y-1)|) / (L(x+1) + L(x-1) + L(y+1) + L(y-1))`,
//!    exceeds `max_gradient`. `g` is scale-invariant (the same at any exposure and in
//!    either color space), lies in [0, 1] for non-negative values and is about half the
//!    L1 norm of the log-luminance gradient per pixel where the image is smooth: 0.05
//!    means roughly 10 % change per pixel. A neighbour without data (non-finite) counts as
//!    a strong gradient: the border of the reference's data is not trusted;
//! 4. **hue-saturation** (coarse): `||hsv(u)_hs - hsv(r)_hs|| > max_hs_distance`;
//! 5. **HSV** (strict, after `c_{t-1}`): `sqrt(d_hs^2 + dv^2) > max_hsv_distance` between
//!    `c_{t-1}(u)` and r, with the relative brightness difference `dv` (see [`super::hsv`]).
//!
//! Kept pairs add, with `d = ||hsv(u)_hs - hsv(r)_hs||` and the weights of eq. (1)
//! `w_a = (1 - min(1, d))^beta_gain`, `w_c = (1 - min(1, d))^beta_linear`:
//! `w_a u` and `w_a r` (for A_t), `w_c u u^T` and `w_c u r^T` (for C_t, eq. (2)).

use super::compensation::PairCounts;
use super::hsv::{Linearize, hs_point, pair_weight, value_distance};
use crate::OpError;
use glam::{DMat3, DVec3, Mat3, Vec3};
use rayon::prelude::*;
use relume_base::raster::{LabelImage, Rgb8Image, Vec3Image};

/// Rows per reduction band: partial sums are taken over fixed bands of rows and combined
/// in band order, so the result does not depend on the number of threads.
const ROWS_PER_BAND: usize = 4;

/// Thresholds of the pair filters and exponents of eq. (1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairParams {
    /// Lowest `reference_coverage` label that counts as data (1 = push-pull filled,
    /// 2 = a splatted sample).
    pub min_coverage: u8,
    /// Camera levels at or below this, in any channel, are under-saturated.
    pub dark_level: u8,
    /// Camera levels at or above this, in any channel, are over-saturated.
    pub bright_level: u8,
    /// Largest relative luminance gradient (see the module doc) in either image.
    pub max_gradient: f32,
    /// Coarse filter: largest hue-saturation distance between u and r.
    pub max_hs_distance: f32,
    /// Strict filter: largest HSV distance between c_{t-1}(u) and r.
    pub max_hsv_distance: f32,
    /// Exponent beta of eq. (1) for the weights of A_t (2 in paper 000).
    pub beta_gain: u32,
    /// Exponent beta of eq. (1) for the weights of C_t (8 in paper 000).
    pub beta_linear: u32,
}

impl Default for PairParams {
    fn default() -> Self {
        PairParams {
            min_coverage: 1,
            dark_level: 5,
            bright_level: 250,
            max_gradient: 0.1,
            max_hs_distance: 0.4,
            max_hsv_distance: 0.25,
            beta_gain: 2,
            beta_linear: 8,
        }
    }
}

/// What one pass over the pairs gathers: counts per rejection reason and the weighted
/// sums of Sec. 4.2 and 4.3 (f64).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairMoments {
    pub counts: PairCounts,
    /// Sum of `w_a u` (denominator of the scale s of Sec. 4.2).
    pub weighted_u: DVec3,
    /// Sum of `w_a r` (numerator of s).
    pub weighted_r: DVec3,
    /// `U W^2 U^T` of eq. (2): sum of `w_c u u^T`.
    pub uu: DMat3,
    /// `U W^2 R^T` of eq. (2): sum of `w_c u r^T`.
    pub ur: DMat3,
}

impl Default for PairMoments {
    fn default() -> Self {
        PairMoments {
            counts: PairCounts::default(),
            weighted_u: DVec3::ZERO,
            weighted_r: DVec3::ZERO,
            uu: DMat3::ZERO,
            ur: DMat3::ZERO,
        }
    }
}

impl PairMoments {
    /// The moments of an image of `pixels` pixels with no reference at all.
    pub fn without_reference(pixels: usize) -> PairMoments {
        let n = u32::try_from(pixels).unwrap_or(u32::MAX);
        PairMoments {
            counts: PairCounts {
                candidates: n,
                no_reference: n,
                ..PairCounts::default()
            },
            ..PairMoments::default()
        }
    }

    /// Adds one kept pair with weights `w_gain` (for A_t) and `w_linear` (for C_t).
    #[inline]
    pub fn add(&mut self, u: Vec3, r: Vec3, w_gain: f32, w_linear: f32) {
        let (u, r) = (u.as_dvec3(), r.as_dvec3());
        let (wa, wc) = (w_gain as f64, w_linear as f64);
        self.weighted_u += wa * u;
        self.weighted_r += wa * r;
        let wu = wc * u;
        // Column j of u u^T is u * u_j; of u r^T it is u * r_j.
        self.uu.x_axis += wu * u.x;
        self.uu.y_axis += wu * u.y;
        self.uu.z_axis += wu * u.z;
        self.ur.x_axis += wu * r.x;
        self.ur.y_axis += wu * r.y;
        self.ur.z_axis += wu * r.z;
        self.counts.kept += 1;
    }

    /// Adds the counts and sums of `other` (taken over other pixels).
    pub fn merge(&mut self, other: &PairMoments) {
        let (a, b) = (&mut self.counts, &other.counts);
        a.candidates += b.candidates;
        a.no_reference += b.no_reference;
        a.saturated += b.saturated;
        a.gradient += b.gradient;
        a.hue_saturation += b.hue_saturation;
        a.hsv += b.hsv;
        a.kept += b.kept;
        self.weighted_u += other.weighted_u;
        self.weighted_r += other.weighted_r;
        self.uu += other.uu;
        self.ur += other.ur;
    }
}

/// The relative gradient of the module doc from the luminances of the left, right,
/// upper and lower neighbours; infinite when a neighbour is not finite or negative sums.
#[inline]
fn relative_gradient(left: f32, right: f32, up: f32, down: f32) -> f32 {
    let sum = left + right + up + down;
    let difference = (right - left).abs() + (down - up).abs();
    if sum > 0.0 {
        difference / sum
    } else if sum == 0.0 {
        0.0
    } else {
        f32::INFINITY
    }
}

/// `value <= limit`; false for NaN, so a pair with an undefined measure is rejected.
#[inline]
fn within(value: f32, limit: f32) -> bool {
    value <= limit
}

/// Selects the sample pairs of paper 000 Sec. 4.1 between the camera image `color` and
/// the `reference` radiance with its `coverage` labels, and accumulates their weighted
/// moments (eq. (1), the sums of Sec. 4.2 and eq. (2)) in one pass. `previous` is
/// c_{t-1}, applied to u for the strict HSV filter. All three images must have the same
/// size. Deterministic for any number of threads.
pub fn select_pairs(
    color: &Rgb8Image,
    reference: &Vec3Image,
    coverage: &LabelImage,
    linearize: &Linearize,
    previous: &Mat3,
    params: &PairParams,
) -> Result<PairMoments, OpError> {
    for (what, w, h) in [
        ("reference", reference.width, reference.height),
        ("reference coverage", coverage.width, coverage.height),
    ] {
        if (w, h) != (color.width, color.height) {
            return Err(OpError::SizeMismatch(format!(
                "{what} is {w}x{h}, the camera image is {}x{}",
                color.width, color.height
            )));
        }
    }
    let (w, h) = (color.width as usize, color.height as usize);
    if w == 0 || h == 0 {
        return Ok(PairMoments::default());
    }
    let lin = linearize.table();
    // c_{t-1}(u) = sum over channels of column c times lin[level]: the products per
    // level are tabulated once (768 entries) instead of 9 multiplications per pixel;
    // the sum is taken in the same order as `Mat3 * Vec3`.
    let cols = [previous.x_axis, previous.y_axis, previous.z_axis];
    let mapped: [[Vec3; 3]; 256] = std::array::from_fn(|level| cols.map(|c| c * lin[level]));
    let camera_luminance =
        |c: [u8; 3]| lin[c[0] as usize] + lin[c[1] as usize] + lin[c[2] as usize];
    let bands: Vec<PairMoments> = (0..h.div_ceil(ROWS_PER_BAND))
        .into_par_iter()
        .map(|band| {
            let mut m = PairMoments::default();
            let rows = band * ROWS_PER_BAND..((band + 1) * ROWS_PER_BAND).min(h);
            for y in rows {
                let row = y * w;
                let (up, down) = (y.saturating_sub(1) * w, (y + 1).min(h - 1) * w);
                let color_row = &color.data[row..row + w];
                let reference_row = &reference.data[row..row + w];
                let coverage_row = &coverage.data[row..row + w];
                m.counts.candidates += w as u32;
                for x in 0..w {
                    let r = reference_row[x];
                    if coverage_row[x] < params.min_coverage || !r.is_finite() {
                        m.counts.no_reference += 1;
                        continue;
                    }
                    let c = color_row[x];
                    let darkest = c[0].min(c[1]).min(c[2]);
                    let brightest = c[0].max(c[1]).max(c[2]);
                    if darkest <= params.dark_level || brightest >= params.bright_level {
                        m.counts.saturated += 1;
                        continue;
                    }
                    let (left, right) = (row + x.saturating_sub(1), row + (x + 1).min(w - 1));
                    let (above, below) = (up + x, down + x);
                    let camera_gradient = relative_gradient(
                        camera_luminance(color.data[left]),
                        camera_luminance(color.data[right]),
                        camera_luminance(color.data[above]),
                        camera_luminance(color.data[below]),
                    );
                    let reference_gradient = relative_gradient(
                        reference.data[left].element_sum(),
                        reference.data[right].element_sum(),
                        reference.data[above].element_sum(),
                        reference.data[below].element_sum(),
                    );
                    if !(within(camera_gradient, params.max_gradient)
                        && within(reference_gradient, params.max_gradient))
                    {
                        m.counts.gradient += 1;
                        continue;
                    }
                    let u = linearize.rgb(c);
                    let (u_hs, _) = hs_point(u);
                    let (r_hs, r_v) = hs_point(r);
                    let hs_distance = u_hs.distance(r_hs);
                    if !within(hs_distance, params.max_hs_distance) {
                        m.counts.hue_saturation += 1;
                        continue;
                    }
                    let [m0, m1, m2] = [
                        mapped[c[0] as usize][0],
                        mapped[c[1] as usize][1],
                        mapped[c[2] as usize][2],
                    ];
                    let (p_hs, p_v) = hs_point(m0 + m1 + m2);
                    let dv = value_distance(p_v, r_v);
                    let hsv_distance = (p_hs.distance_squared(r_hs) + dv * dv).sqrt();
                    if !within(hsv_distance, params.max_hsv_distance) {
                        m.counts.hsv += 1;
                        continue;
                    }
                    m.add(
                        u,
                        r,
                        pair_weight(hs_distance, params.beta_gain),
                        pair_weight(hs_distance, params.beta_linear),
                    );
                }
            }
            m
        })
        .collect();
    let mut total = PairMoments::default();
    for band in &bands {
        total.merge(band);
    }
    Ok(total)
}
