//! The world-space Gaussian kernel of paper 001 eq. 23 and its weighted tap sums
//! (eqs. 21-22, 24-26): a fast `exp` and a branch-free, auto-vectorized accumulation over
//! contiguous taps that computes each weight once for the two layers (E_R and E_RV) that
//! share it.

/// SIMD width the tap loop is written for (four f32 lanes: SSE2 on baseline x86-64).
pub const LANES: usize = 4;

/// Arguments at or above this give a weight of exactly 0 (e^-87 ~ 1.6e-38 is at the
/// bottom of the normal f32 range).
pub const EXP_CUTOFF: f32 = 87.0;

// Taylor coefficients of 2^f = e^(f ln 2), f in [-0.5, 0.5]: ln2^n / n!.
const C1: f32 = std::f32::consts::LN_2;
const C2: f32 = 0.240_226_5;
const C3: f32 = 0.055_504_11;
const C4: f32 = 0.009_618_129;
const C5: f32 = 0.001_333_355_8;
const C6: f32 = 0.000_154_035_3;

/// e^-a for a >= 0, branch-free, for the Gaussian weights of eq. 23.
///
/// 2^y with y = -a log2(e) is split into 2^k (exponent bits) times 2^f, f in
/// [-0.5, 0.5], by a degree-6 Taylor polynomial (truncation error <= 1.2e-7 relative).
/// Measured max relative error against f64 `exp` (test `fast_exp_accuracy`): 3e-7 for
/// a <= 1, growing as ~6e-8 a from the rounding of y (<= 5e-6 at a = 80). exp(0) is
/// exactly 1; a >= [`EXP_CUTOFF`] or NaN gives exactly 0.
#[inline(always)]
pub fn exp_neg(a: f32) -> f32 {
    let y = (a * -std::f32::consts::LOG2_E).max(-126.0);
    // Round to nearest for y <= 0 by truncating y - 0.5 (a truncating cast, no libm
    // floor on SSE2); y is in [-126, 0], so the cast is in range.
    let k = (y - 0.5) as i32;
    let f = y - k as f32;
    let p = 1.0 + f * (C1 + f * (C2 + f * (C3 + f * (C4 + f * (C5 + f * C6)))));
    let scale = f32::from_bits(((k + 127) as u32) << 23);
    let r = p * scale;
    if a < EXP_CUTOFF { r } else { 0.0 }
}

/// Number of value planes per filtered kind: E_R rgb, E_RV rgb, valid_R, valid_RV.
pub const VALUE_PLANES: usize = 8;

/// The pixel a tap sum is for: its world position and squared bandwidth B^2.
#[derive(Clone, Copy, Debug)]
pub struct Target {
    pub position: [f32; 3],
    pub b2: f32,
}

/// Contiguous source taps (all slices of the same length, a multiple of [`LANES`]):
/// world positions, squared bandwidths, the tap mask (1 inside the radius, 0 for the
/// padding taps that round the count up to a multiple of [`LANES`]) and the value planes
/// (non-finite values stored as 0 with valid = 0; missing positions stored far away).
pub struct Taps<'a> {
    pub px: &'a [f32],
    pub py: &'a [f32],
    pub pz: &'a [f32],
    pub b2: &'a [f32],
    pub mask: &'a [f32],
    pub values: [&'a [f32]; VALUE_PLANES],
}

/// Lane-wise running sums of w * value for each value plane (so for the valid planes,
/// the sums of weights). Reduced over lanes in a fixed order by [`Sums::total`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Sums(pub [[f32; LANES]; VALUE_PLANES]);

impl Sums {
    /// The sum of plane `q` over the lanes, always in the same order.
    #[inline]
    pub fn total(&self, q: usize) -> f32 {
        let s = &self.0[q];
        (s[0] + s[1]) + (s[2] + s[3])
    }
}

/// Adds w * value over `taps` to `sums`, w = exp(-2 Bbar^2 |p - p_i|^2) with
/// Bbar^2 = (B^2(target) + B^2(source)) / 2 (paper 001 eq. 23), times the tap mask.
#[inline(always)]
pub fn accumulate(target: Target, taps: &Taps, sums: &mut Sums) {
    let n = taps.px.len() / LANES;
    fn lanes(s: &[f32], n: usize) -> &[[f32; LANES]] {
        bytemuck::cast_slice(&s[..n * LANES])
    }
    let chunks = |s| lanes(s, n);
    let (px, py, pz) = (chunks(taps.px), chunks(taps.py), chunks(taps.pz));
    let (b2, mask) = (chunks(taps.b2), chunks(taps.mask));
    let v = taps.values.map(|s| lanes(s, n));
    let [tx, ty, tz] = target.position;
    let acc = &mut sums.0;
    for c in 0..n {
        let mut w = [0.0f32; LANES];
        for l in 0..LANES {
            let (dx, dy, dz) = (px[c][l] - tx, py[c][l] - ty, pz[c][l] - tz);
            let d2 = dx * dx + dy * dy + dz * dz;
            w[l] = exp_neg((target.b2 + b2[c][l]) * d2) * mask[c][l];
        }
        for q in 0..VALUE_PLANES {
            for l in 0..LANES {
                acc[q][l] += w[l] * v[q][c][l];
            }
        }
    }
}
