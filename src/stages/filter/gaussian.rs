//! The world-space Gaussian kernel of paper 001 eq. 23 and its weighted tap sums
//! (eqs. 21-22, 24-26): a fast `exp` and a branch-free, auto-vectorized accumulation over
//! contiguous chunks of taps that computes each weight once for the two layers (E_R and
//! E_RV) that share it.
//!
//! Taps are stored as an array of structures of arrays: a line (an image row or column)
//! is a sequence of [`Chunk`]s, each holding [`LANES`] consecutive pixels of every plane
//! (see [`super::planes`]), so one pointer and constant offsets reach every plane of a
//! chunk and the four lanes load as one SSE2 vector.

use super::simd::F4;

/// SIMD width the tap loop is written for (four f32 lanes: SSE2 on baseline x86-64).
pub const LANES: usize = 4;

/// Arguments at or above this give a weight of exactly 0: e^-40 ~ 4e-18, far below the
/// f32 resolution of a sum that holds the target's own weight 1 (and the products stay
/// clear of subnormal floats, which are slow).
pub const EXP_CUTOFF: f32 = 40.0;

// 2^f ~ 1 + C1 f + C2 f^2 + C3 f^3 + C4 f^4 on f in [-0.5, 0.5]: relative-error minimax
// coefficients (iteratively reweighted least squares, constant term pinned to 1 so that
// exp(0) = 1 exactly); max relative error 2.8e-6 in exact arithmetic.
const C1: f32 = 0.693_124_2;
const C2: f32 = 0.240_241;
const C3: f32 = 0.055_906_43;
const C4: f32 = 0.009_582_807;

/// 1.5 * 2^23: adding it rounds a float of magnitude < 2^22 to an integer, which then
/// sits in the low mantissa bits.
const ROUNDING_MAGIC: f32 = 12_582_912.0;

/// e^-a for a >= 0, branch-free and without float-to-int conversion, for the Gaussian
/// weights of eq. 23.
///
/// 2^y, y = -a log2(e), is split into 2^k (exponent bits) times 2^f, f = y - k in
/// [-0.5, 0.5], by a degree-4 minimax polynomial (2.8e-6 relative); k = round(y) comes
/// from the mantissa of y + 1.5 * 2^23. Measured max relative error against f64 `exp`
/// (test `fast_exp_accuracy`): 2.9e-6 on [0, 1], 4.7e-6 over [0, 40) (the rounding of
/// y adds up to ~6e-8 a). exp(0) is exactly 1;
/// a >= [`EXP_CUTOFF`] or NaN gives exactly 0.
#[inline(always)]
pub fn exp_neg(a: f32) -> f32 {
    let y = a * -std::f32::consts::LOG2_E;
    let t = y + ROUNDING_MAGIC;
    let f = y - (t - ROUNDING_MAGIC);
    let p = 1.0 + f * (C1 + f * (C2 + f * (C3 + f * C4)));
    // t's low bits hold k (two's complement); shifted into the exponent field, plus the
    // bias 127, they make 2^k. Only used for k >= -58 (a < 40).
    let scale = f32::from_bits((t.to_bits() << 23).wrapping_add(127 << 23));
    let r = p * scale;
    if a < EXP_CUTOFF { r } else { 0.0 }
}

/// [`exp_neg`] on four lanes (the same operations, so the same bits per lane).
#[inline(always)]
pub fn exp_neg4(a: F4) -> F4 {
    exp_neg4_below(a, F4::splat(EXP_CUTOFF))
}

/// [`exp_neg4`] with the cutoff per lane: lanes with `a >= limit` give 0 (a limit below
/// 0 masks a lane out for any a >= 0).
#[inline(always)]
pub fn exp_neg4_below(a: F4, limit: F4) -> F4 {
    let y = a.mul(F4::splat(-std::f32::consts::LOG2_E));
    let t = y.add(F4::splat(ROUNDING_MAGIC));
    let f = y.sub(t.sub(F4::splat(ROUNDING_MAGIC)));
    let mut p = F4::splat(C4);
    for c in [C3, C2, C1, 1.0] {
        p = p.mul(f).add(F4::splat(c));
    }
    p.mul(t.exponent_from_low_bits(127))
        .zero_unless_below(a, limit)
}

/// Number of value planes per filtered kind: E_R rgb, E_RV rgb, valid_R, valid_RV.
pub const VALUE_PLANES: usize = 8;

/// Planes per chunk: world position (3), squared bandwidths (3), two kinds of values.
pub const NPLANES: usize = 6 + 2 * VALUE_PLANES;

/// [`LANES`] consecutive pixels of every plane.
pub type Chunk = [[f32; LANES]; NPLANES];

/// The pixel a tap sum is for: its world position and squared bandwidth B^2.
#[derive(Clone, Copy, Debug)]
pub struct Target {
    pub position: [f32; 3],
    pub b2: f32,
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

/// The pixel a two-kind tap sum is for: its world position and the squared bandwidths
/// B^2 of the direct and the indirect kind.
#[derive(Clone, Copy, Debug)]
pub struct BothTarget {
    pub position: [f32; 3],
    pub b2: [f32; 2],
}

/// The value planes of the E_R layer of a kind (rgb, valid) that [`accumulate_r`] sums.
pub const R_PLANES: [usize; 4] = [0, 1, 2, 6];

/// [`accumulate`] of the E_R planes ([`R_PLANES`]) of both kinds at once, where the
/// caller knows E_RV == E_R over the window (then E_RV's sums are E_R's): one squared
/// distance per tap for the two kinds (the weights differ only by B^2), 8 multiply-adds
/// instead of 16. Each weight and each E_R sum is the same operations, in the same
/// order, as [`accumulate`] performs, so the results have the same bits. `B2D` is the
/// direct kind's B^2 plane, `B2I` the indirect kind's; `DIR` and `IND` the first value
/// planes of the kinds.
#[inline(always)]
pub fn accumulate_r<const B2D: usize, const B2I: usize, const DIR: usize, const IND: usize>(
    target: BothTarget,
    chunks: &[Chunk],
    limits: &[[f32; LANES]],
    sums: &mut [Sums; 2],
) {
    let [tx, ty, tz] = target.position.map(F4::splat);
    let [tbd, tbi] = target.b2.map(F4::splat);
    let mut acc_dir = R_PLANES.map(|q| F4::from_array(sums[0].0[q]));
    let mut acc_ind = R_PLANES.map(|q| F4::from_array(sums[1].0[q]));
    for (chunk, limit) in chunks.iter().zip(limits) {
        let load = |q: usize| F4::from_array(chunk[q]);
        let (dx, dy, dz) = (load(0).sub(tx), load(1).sub(ty), load(2).sub(tz));
        let d2 = dx.mul(dx).add(dy.mul(dy)).add(dz.mul(dz));
        let limit = F4::from_array(*limit);
        let w_dir = exp_neg4_below(tbd.add(load(B2D)).mul(d2), limit);
        let w_ind = exp_neg4_below(tbi.add(load(B2I)).mul(d2), limit);
        for (k, &q) in R_PLANES.iter().enumerate() {
            acc_dir[k] = acc_dir[k].add(w_dir.mul(load(DIR + q)));
            acc_ind[k] = acc_ind[k].add(w_ind.mul(load(IND + q)));
        }
    }
    for (k, &q) in R_PLANES.iter().enumerate() {
        sums[0].0[q] = acc_dir[k].to_array();
        sums[1].0[q] = acc_ind[k].to_array();
    }
}

/// Adds w * value over the taps in `chunks` to `sums`, with
/// w = exp(-2 Bbar^2 |p - p_i|^2), Bbar^2 = (B^2(target) + B^2(source)) / 2 (paper 001
/// eq. 23), for the taps inside the radius; `limits` holds per tap the exp cutoff
/// ([`EXP_CUTOFF`] inside the radius, -1 for the other taps that share their chunks, so
/// their weight is 0 at no extra cost). Squared bandwidths are read from plane `B2`, values from the
/// [`VALUE_PLANES`] planes from `VALUES` on. Positions are plane 0..3.
#[inline(always)]
pub fn accumulate<const B2: usize, const VALUES: usize>(
    target: Target,
    chunks: &[Chunk],
    limits: &[[f32; LANES]],
    sums: &mut Sums,
) {
    let [tx, ty, tz] = target.position.map(F4::splat);
    let tb = F4::splat(target.b2);
    let mut acc = sums.0.map(F4::from_array);
    for (chunk, limit) in chunks.iter().zip(limits) {
        let load = |q: usize| F4::from_array(chunk[q]);
        let (dx, dy, dz) = (load(0).sub(tx), load(1).sub(ty), load(2).sub(tz));
        let d2 = dx.mul(dx).add(dy.mul(dy)).add(dz.mul(dz));
        let w = exp_neg4_below(tb.add(load(B2)).mul(d2), F4::from_array(*limit));
        for (q, acc) in acc.iter_mut().enumerate() {
            *acc = acc.add(w.mul(load(VALUES + q)));
        }
    }
    sums.0 = acc.map(F4::to_array);
}
