//! The eight-lane interface that both kernels implement ([`Portable`] in the parent
//! module, `Avx2` in its own) and the lane code of every stage is written against: the
//! lane count [`LANES`] and the [`Lanes`] trait.
//!
//! [`Portable`]: super::Portable

/// Number of lanes (target pixels per vector).
pub const LANES: usize = 8;

/// Eight f32 lanes. Loads and gathers take raw pointers: callers check that every lane
/// they read lies inside their buffers.
pub trait Lanes: Copy {
    fn splat(v: f32) -> Self;
    fn from_array(a: [f32; LANES]) -> Self;
    fn to_array(self) -> [f32; LANES];
    /// # Safety
    /// `p..p + LANES` must be readable.
    unsafe fn load(p: *const f32) -> Self;
    /// Lanes of `data[i..i + LANES]` (panics past the end of `data`).
    #[inline(always)]
    fn load_slice(data: &[f32], i: usize) -> Self {
        let lanes = &data[i..i + LANES];
        // SAFETY: `lanes` holds LANES floats.
        unsafe { Self::load(lanes.as_ptr()) }
    }
    /// Stores the lanes at `out[i..i + LANES]` (panics past the end of `out`).
    #[inline(always)]
    fn store_slice(self, out: &mut [f32], i: usize) {
        let lanes = &mut out[i..i + LANES];
        // SAFETY: `lanes` holds LANES floats.
        unsafe { self.store(lanes.as_mut_ptr()) }
    }
    /// Lane l reads `p + index[l]`.
    /// # Safety
    /// Every `p + index[l]` must be readable.
    unsafe fn gather(p: *const f32, index: &[i32; LANES]) -> Self;
    /// Lane l reads `p + index[l]`, for an index computed in lanes (no trip through
    /// memory).
    /// # Safety
    /// Every `index[l]` must be a whole number in [0, 2^24) (exact in f32; others
    /// convert to offsets that differ between kernels, or negative ones), and every
    /// `p + index[l]` readable.
    unsafe fn gather_at(p: *const f32, index: Self) -> Self;
    /// # Safety
    /// `p..p + LANES` must be writable.
    unsafe fn store(self, p: *mut f32);
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    /// self * b + c, rounded once.
    fn mul_add(self, b: Self, c: Self) -> Self;
    /// `self` where `a < limit` (false for NaN), else 0.
    fn zero_unless_below(self, a: Self, limit: Self) -> Self;
    /// `self` where `cond > 0`, else 0.
    fn zero_unless_positive(self, cond: Self) -> Self;
    /// `self` with NaN lanes replaced by 0.
    fn zero_if_nan(self) -> Self;
    /// The float with bits ((bits(self) << 23) + (bias << 23)) per lane.
    fn exponent_from_low_bits(self, bias: i32) -> Self;
    /// Whether every lane is +0 or -0.
    fn all_zero(self) -> bool;

    /// The square root per lane (correctly rounded, as `f32::sqrt`).
    fn sqrt(self) -> Self;
    /// `self` where `self > o`, else `o` (so `o` where either is NaN; `f32::max` for
    /// finite values of different magnitude or sign).
    fn max(self, o: Self) -> Self;
    /// `self` where `self < o`, else `o`.
    fn min(self, o: Self) -> Self;
    /// Masks (all bits set where true): `self < o`, `self > o`, `self >= o`, false
    /// for NaN as in Rust.
    fn lt(self, o: Self) -> Self;
    fn gt(self, o: Self) -> Self;
    fn ge(self, o: Self) -> Self;
    /// Bitwise and, or, and `self & !o` (of masks, or of a value and a mask).
    fn and(self, o: Self) -> Self;
    fn or(self, o: Self) -> Self;
    fn and_not(self, o: Self) -> Self;
    /// `a` where `mask`, else `b`.
    fn select(mask: Self, a: Self, b: Self) -> Self;
    /// Whether any lane of a mask is set.
    fn any(self) -> bool;
    /// Truncation toward zero to i32 per lane (for values that fit).
    fn trunc_to_i32(self) -> [i32; LANES];
    /// Rounding toward zero per lane, as `f32::trunc`.
    fn trunc(self) -> Self;
    /// The 8 x 8 transpose: lane r of result l is lane l of `rows[r]`.
    fn transpose(rows: [Self; LANES]) -> [Self; LANES];
    /// The lanes rotated up by `r` (0 <= r < 8): lane (l + r) mod 8 of the result is
    /// lane l of `self`.
    fn rotate_up(self, r: usize) -> Self;
    /// Lane l of the result is lane `i & 7` of `self`, where i is lane l of `index` read
    /// as the bits of an integer ([`Lanes::lane_indices`] makes them).
    fn permute(self, index: Self) -> Self;
    /// A mask for [`Lanes::select`]: all bits set in the lanes that are `on`.
    #[inline(always)]
    fn from_mask(on: [bool; LANES]) -> Self {
        Self::from_array(on.map(mask))
    }
    /// Eight lane indices for [`Lanes::permute`], each in its lane's bits.
    #[inline(always)]
    fn lane_indices(index: [u32; LANES]) -> Self {
        Self::from_array(index.map(f32::from_bits))
    }
    /// Three planes interleaved: lane j of result r is lane (8 r + j) / 3 of plane
    /// (8 r + j) % 3, so that the three results are eight (x, y, z) triples in a row.
    fn interleave3(planes: [Self; 3]) -> [Self; 3];
    /// The inverse of [`Lanes::interleave3`]: eight (x, y, z) triples in a row, three
    /// vectors, into their three planes.
    fn deinterleave3(triples: [Self; 3]) -> [Self; 3];
}

/// A mask lane: all bits set for true.
#[inline(always)]
pub(super) fn mask(b: bool) -> f32 {
    f32::from_bits(if b { u32::MAX } else { 0 })
}
