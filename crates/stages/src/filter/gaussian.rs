//! The world-space Gaussian kernel of paper 001 eq. 23 and its weighted tap sums
//! (eqs. 21-22, 24-26): a fast `exp` and the tap loops, eight target pixels at a time
//! (one per lane, [`Lanes`]). A window's weights come first ([`tap_weights`]: the
//! squared distance once per tap for both kinds, a weight per kind, shared by its two
//! layers E_R and E_RV), then the weighted sums per kind ([`accumulate`]).
//!
//! The loops read their taps from lane-interleaved planes (see [`super::lane_planes`])
//! through a [`Window`]: per tap, one vector per plane, read by a [`Fetch`]: one load
//! ([`Contiguous`]: the X and Y passes, and the temporal taps when the eight targets
//! found their previous pixels at one offset that is a multiple of 8), two blended
//! loads ([`Straddling`]: any other common offset), two permuted loads per line
//! ([`Permuted`]: different offsets, within two blocks and three lines) or gathered per
//! lane ([`Gathered`]: the rest).

use relume_base::simd::{LANES, Lanes};

/// Largest filter radius accepted (taps per pass: 2 R + 1).
pub const MAX_RADIUS: usize = 64;

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
pub const ROUNDING_MAGIC: f32 = 12_582_912.0;

/// e^-a for a >= 0, branch-free and without float-to-int conversion, for the Gaussian
/// weights of eq. 23.
///
/// 2^y, y = -a log2(e), is split into 2^k (exponent bits) times 2^f, f = y - k in
/// [-0.5, 0.5], by a degree-4 minimax polynomial (2.8e-6 relative, Horner steps as fused
/// multiply-adds); k = round(y) comes from the mantissa of y + 1.5 * 2^23. Measured max
/// relative error against f64 `exp` (test `fast_exp_accuracy`): under 4e-6 on [0, 1]
/// and 8e-6 over [0, 40) (the rounding of y adds up to ~6e-8 a). exp(0) is exactly 1;
/// a >= [`EXP_CUTOFF`] or NaN gives exactly 0. [`exp_neg_lanes`] computes the same bits.
#[inline]
pub fn exp_neg(a: f32) -> f32 {
    let y = a * -std::f32::consts::LOG2_E;
    let t = y + ROUNDING_MAGIC;
    let f = y - (t - ROUNDING_MAGIC);
    let mut p = C4;
    for c in [C3, C2, C1, 1.0] {
        p = p.mul_add(f, c);
    }
    // t's low bits hold k (two's complement); shifted into the exponent field, plus the
    // bias 127, they make 2^k. Only used for k >= -58 (a < 40).
    let scale = f32::from_bits((t.to_bits() << 23).wrapping_add(127 << 23));
    let r = p * scale;
    if a < EXP_CUTOFF { r } else { 0.0 }
}

/// [`exp_neg`] per lane, with the cutoff per lane: lanes with `a >= limit` give 0 (a
/// limit below 0 masks a lane out for any a >= 0).
#[inline(always)]
pub fn exp_neg_lanes<V: Lanes>(a: V, limit: V) -> V {
    let y = a.mul(V::splat(-std::f32::consts::LOG2_E));
    let t = y.add(V::splat(ROUNDING_MAGIC));
    let f = y.sub(t.sub(V::splat(ROUNDING_MAGIC)));
    let mut p = V::splat(C4);
    for c in [C3, C2, C1, 1.0] {
        p = p.mul_add(f, V::splat(c));
    }
    p.mul(t.exponent_from_low_bits(127))
        .zero_unless_below(a, limit)
}

/// Number of value planes per filtered kind: E_R rgb, E_RV rgb, valid_R, valid_RV.
pub const VALUE_PLANES: usize = 8;

/// How a tap's vector is read from a plane.
pub trait Fetch<V: Lanes> {
    /// The tap's eight lanes of a plane: from `p` on ([`Contiguous`]), or gathered with
    /// `p` as the base.
    ///
    /// # Safety
    /// The lanes' addresses must be readable.
    unsafe fn fetch(&self, p: *const f32) -> V;
}

/// The eight targets' taps are consecutive floats.
pub struct Contiguous;

impl<V: Lanes> Fetch<V> for Contiguous {
    #[inline(always)]
    unsafe fn fetch(&self, p: *const f32) -> V {
        // SAFETY: forwarded from the caller.
        unsafe { V::load(p) }
    }
}

/// Lane l's tap is at `p + offset[l]` (the temporal taps of targets that found their
/// previous pixels at different offsets).
pub struct Gathered(pub [i32; LANES]);

impl<V: Lanes> Fetch<V> for Gathered {
    #[inline(always)]
    unsafe fn fetch(&self, p: *const f32) -> V {
        // SAFETY: forwarded from the caller.
        unsafe { V::gather(p, &self.0) }
    }
}

/// Lane l's tap is at `p + second` where `mask` selects it, at `p` elsewhere (windows
/// that straddle two blocks of a blocks set, see `passes`): two vector loads,
/// blended.
#[derive(Clone, Copy)]
pub struct Straddling<V> {
    pub second: isize,
    pub mask: V,
}

impl<V: Lanes> Fetch<V> for Straddling<V> {
    #[inline(always)]
    unsafe fn fetch(&self, p: *const f32) -> V {
        // SAFETY (both loads): forwarded from the caller.
        unsafe {
            let first = V::load(p);
            let second = V::load(p.wrapping_offset(self.second));
            V::select(self.mask, second, first)
        }
    }
}

/// Most lines a [`Permuted`] fetch reads per tap.
pub const PERMUTED_LINES: usize = 3;

/// Lanes whose taps lie in two consecutive blocks of a blocks set (see `passes`), on
/// `K` different lines (the temporal taps of targets whose previous pixels are at
/// different offsets): per line, the two blocks' vectors are loaded and each lane's
/// float picked out by a permutation; the lines' picks are merged by lane. A handful
/// of register operations where a gather costs some ten cycles on the CPUs measured.
#[derive(Clone, Copy)]
pub struct Permuted<V, const K: usize> {
    /// Per lane, its float's lane within its block ([`Lanes::lane_indices`]).
    pub index: V,
    /// The lanes that read the second block.
    pub second: V,
    /// Floats from a block to the next.
    pub block_step: isize,
    /// Per line: floats from the window's base to the line, and its lanes (line 0's
    /// mask is unused: the lanes of no other line read it).
    pub lines: [(isize, V); K],
}

impl<V: Lanes, const K: usize> Permuted<V, K> {
    /// The lanes' floats of the line at `p`.
    ///
    /// # Safety
    /// `p..p + 8` and the same in the next block must be readable.
    #[inline(always)]
    unsafe fn pick(&self, p: *const f32) -> V {
        // SAFETY (both loads): forwarded from the caller.
        unsafe {
            let first = V::load(p).permute(self.index);
            let second = V::load(p.wrapping_offset(self.block_step)).permute(self.index);
            V::select(self.second, second, first)
        }
    }
}

impl<V: Lanes, const K: usize> Fetch<V> for Permuted<V, K> {
    #[inline(always)]
    unsafe fn fetch(&self, p: *const f32) -> V {
        // SAFETY (every pick): forwarded from the caller, for each line.
        unsafe {
            let mut v = self.pick(p.wrapping_offset(self.lines[0].0));
            for &(offset, lanes) in &self.lines[1..] {
                v = V::select(lanes, self.pick(p.wrapping_offset(offset)), v);
            }
            v
        }
    }
}

/// The taps of one window in a set of planes: lane 0's first tap of plane 0 (for
/// [`Gathered`] taps: the planes' start), and the distances in floats between planes
/// and between consecutive taps. Pointers are advanced with wrapping arithmetic, since
/// with gathered taps they are only bases.
#[derive(Clone, Copy, Debug)]
pub struct Window {
    pub planes: *const f32,
    pub plane_stride: usize,
    pub tap_step: usize,
    pub taps: usize,
}

/// Most taps in a window: 2 R + 1 for the largest radius accepted.
pub const MAX_TAPS: usize = 2 * MAX_RADIUS + 1;

/// Per kind (direct, indirect), one weight vector per tap of a window:
/// [`tap_weights`] fills it, [`accumulate`] reads it.
pub type TapWeights<V> = [[V; MAX_TAPS]; 2];

/// Where one filtered kind's weights come from: the plane of the taps' squared
/// bandwidths B^2, and the eight targets' B^2.
#[derive(Clone, Copy, Debug)]
pub struct Bandwidths<V> {
    pub plane: usize,
    pub target: V,
}

/// The Gaussian weight of eq. 23 of each tap of `window` for the eight targets at
/// `target` (world positions), for each kind that is `Some`: `weights[k][i]` =
/// exp(-2 Bbar^2 |p - p_i|^2), Bbar^2 = (B^2(target) + B^2(source)) / 2, the taps'
/// positions read from the three planes from `position` on. The squared distance is
/// computed once for both kinds. Lanes whose `limit` is below 0 get weight 0.
///
/// Weights first, sums after ([`accumulate`]): a loop that did both per tap carried a
/// chain of some 60 cycles per tap (loads, distance, `exp`, sums), more than the CPU
/// could overlap across taps.
///
/// # Safety
/// Every tap of `window` that `fetch` reads must lie inside its planes.
#[inline(always)]
pub unsafe fn tap_weights<V: Lanes, F: Fetch<V>>(
    fetch: &F,
    window: &Window,
    position: usize,
    target: [V; 3],
    kinds: [Option<Bandwidths<V>>; 2],
    limit: V,
    weights: [&mut [V]; 2],
) {
    let [direct, indirect] = weights;
    let taps = TapsAt {
        fetch,
        window,
        position,
        target,
        limit,
    };
    // SAFETY (all arms): forwarded from the caller.
    unsafe {
        match kinds {
            [Some(d), Some(i)] => taps.weigh([d, i], [direct, indirect]),
            [Some(d), None] => taps.weigh([d], [direct]),
            [None, Some(i)] => taps.weigh([i], [indirect]),
            [None, None] => {}
        }
    }
}

/// The arguments of [`tap_weights`] that do not depend on the kinds.
struct TapsAt<'a, V, F> {
    fetch: &'a F,
    window: &'a Window,
    position: usize,
    target: [V; 3],
    limit: V,
}

impl<V: Lanes, F: Fetch<V>> TapsAt<'_, V, F> {
    /// [`tap_weights`] for `K` kinds.
    ///
    /// # Safety
    /// As for [`tap_weights`].
    #[inline(always)]
    unsafe fn weigh<const K: usize>(&self, kinds: [Bandwidths<V>; K], mut weights: [&mut [V]; K]) {
        let (fetch, window) = (self.fetch, self.window);
        let [tx, ty, tz] = self.target;
        for weights in &weights {
            assert!(weights.len() >= window.taps);
        }
        let stride = window.plane_stride;
        let plane = |tap: *const f32, q: usize| tap.wrapping_add(q * stride);
        // SAFETY (every fetch): the caller guarantees the window's taps are inside the
        // planes.
        unsafe {
            let mut tap = window.planes;
            for i in 0..window.taps {
                let dx = fetch.fetch(plane(tap, self.position)).sub(tx);
                let dy = fetch.fetch(plane(tap, self.position + 1)).sub(ty);
                let dz = fetch.fetch(plane(tap, self.position + 2)).sub(tz);
                let d2 = dz.mul_add(dz, dy.mul_add(dy, dx.mul(dx)));
                for (kind, weights) in kinds.iter().zip(weights.iter_mut()) {
                    let b2 = kind.target.add(fetch.fetch(plane(tap, kind.plane)));
                    weights[i] = exp_neg_lanes(b2.mul(d2), self.limit);
                }
                // Wrapping: after the last tap the pointer may leave the planes unread.
                tap = tap.wrapping_add(window.tap_step);
            }
        }
    }
}

/// Adds w_i * value_i over the taps i of `window` to `sums`, for each of the
/// [`VALUE_PLANES`] value planes from plane `values` on (so for the valid planes, the
/// sums of weights), with the weights from [`tap_weights`]. Taps in order, so each
/// lane's sums are the same bits whatever its neighbours are.
///
/// # Safety
/// Every tap of `window` that `fetch` reads must lie inside its planes.
#[inline(always)]
pub unsafe fn accumulate<V: Lanes, F: Fetch<V>>(
    fetch: &F,
    window: &Window,
    values: usize,
    weights: &[V],
    sums: &mut [V; VALUE_PLANES],
) {
    // SAFETY: forwarded from the caller.
    unsafe { sum_taps::<V, F, false>(fetch, window, values, weights, sums) }
}

/// [`accumulate`] for a window whose every tap has both layers' values of the kind
/// (its two valid planes all 1, see `passes::FullWindows`): each weight is added to
/// the two valid sums as it is, and the valid planes are not read. The same bits, since
/// w * 1 + s rounded once is w + s rounded; two loads and two multiply-adds fewer per
/// tap.
///
/// # Safety
/// Every tap of `window` that `fetch` reads must lie inside its planes.
#[inline(always)]
pub unsafe fn accumulate_full<V: Lanes, F: Fetch<V>>(
    fetch: &F,
    window: &Window,
    values: usize,
    weights: &[V],
    sums: &mut [V; VALUE_PLANES],
) {
    // SAFETY: forwarded from the caller.
    unsafe { sum_taps::<V, F, true>(fetch, window, values, weights, sums) }
}

/// [`accumulate`] (`FULL` false) or [`accumulate_full`] (`FULL` true).
///
/// # Safety
/// Every tap of `window` that `fetch` reads must lie inside its planes.
#[inline(always)]
unsafe fn sum_taps<V: Lanes, F: Fetch<V>, const FULL: bool>(
    fetch: &F,
    window: &Window,
    values: usize,
    weights: &[V],
    sums: &mut [V; VALUE_PLANES],
) {
    assert!(weights.len() >= window.taps);
    // The planes read: all, or the six rgb planes (the valid planes follow them).
    let read = if FULL { 6 } else { VALUE_PLANES };
    // A local copy, so the sums stay in registers (stores through `sums` could alias the
    // raw-pointer loads as far as the compiler knows).
    let mut acc = *sums;
    let stride = window.plane_stride;
    let plane = |tap: *const f32, q: usize| tap.wrapping_add(q * stride);
    // SAFETY (every fetch): the caller guarantees the window's taps are inside the planes.
    unsafe {
        let mut tap = window.planes;
        for &w in &weights[..window.taps] {
            for (q, sum) in acc[..read].iter_mut().enumerate() {
                *sum = w.mul_add(fetch.fetch(plane(tap, values + q)), *sum);
            }
            if FULL {
                acc[6] = acc[6].add(w);
                acc[7] = acc[7].add(w);
            }
            // Wrapping: after the last tap the pointer may leave the planes unread.
            tap = tap.wrapping_add(window.tap_step);
        }
    }
    *sums = acc;
}
