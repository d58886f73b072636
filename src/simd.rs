//! Eight f32 lanes, one pixel per lane, for the per-pixel loops that the compiler does
//! not vectorize well by itself (the filter's tap loops, `sample.val`'s shading and
//! shadow maps): AVX2
//! with FMA where the CPU has them (detected at run time, [`Kernel::detect`]), plain
//! arrays with `f32::mul_add` elsewhere. Both compute the same operations with the same
//! roundings (a fused multiply-add rounds once in either), so outputs do not depend on
//! the kernel. (Exception: [`Lanes::trunc_to_i32`] of NaN or out-of-range values, which
//! callers do not use.)
//!
//! Use: a generic `#[inline(always)]` function over [`Lanes`], called through a
//! `#[target_feature(enable = "avx2,fma")]` wrapper with [`Avx2`] when [`Kernel::detect`]
//! says so, else with [`Portable`]. Never call lane operations from closures inside
//! such functions: closures do not inherit `#[target_feature]`, and the intrinsics in
//! them would stay function calls (10-30x slower).

/// Number of lanes (target pixels per vector).
pub const LANES: usize = 8;

/// Which eight-lane code runs: the filter's passes and sample.val's shading and shadow
/// maps (through
/// [`Lanes`]), and the screen-space tracer's batches (`ssrt::TraceBatch`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// AVX2 + FMA (x86-64 only, checked at run time).
    Avx2Fma,
    /// Arrays of eight floats: any CPU, the same bits, several times slower.
    Portable,
}

impl Kernel {
    /// `self`, or [`Kernel::Portable`] where the CPU lacks what `self` needs: a caller
    /// may ask for any kernel, the code only runs what the CPU has.
    pub fn available(self) -> Kernel {
        match self {
            Kernel::Avx2Fma if Kernel::detect() != Kernel::Avx2Fma => Kernel::Portable,
            kernel => kernel,
        }
    }

    /// The fastest kernel this CPU runs.
    pub fn detect() -> Kernel {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            return Kernel::Avx2Fma;
        }
        Kernel::Portable
    }
}

/// Eight f32 lanes. Loads and gathers take raw pointers: callers check that every lane
/// they read lies inside their buffers.
pub trait Lanes: Copy {
    fn splat(v: f32) -> Self;
    fn from_array(a: [f32; LANES]) -> Self;
    fn to_array(self) -> [f32; LANES];
    /// # Safety
    /// `p..p + LANES` must be readable.
    unsafe fn load(p: *const f32) -> Self;
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
}

/// The portable lanes.
#[derive(Clone, Copy, Debug)]
pub struct Portable([f32; LANES]);

impl Lanes for Portable {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        Portable([v; LANES])
    }
    #[inline(always)]
    fn from_array(a: [f32; LANES]) -> Self {
        Portable(a)
    }
    #[inline(always)]
    fn to_array(self) -> [f32; LANES] {
        self.0
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller guarantees p..p + LANES is readable.
        Portable(unsafe { p.cast::<[f32; LANES]>().read_unaligned() })
    }
    #[inline(always)]
    unsafe fn gather(p: *const f32, index: &[i32; LANES]) -> Self {
        // SAFETY: the caller guarantees every p + index[l] is readable.
        Portable(index.map(|i| unsafe { *p.offset(i as isize) }))
    }
    #[inline(always)]
    unsafe fn gather_at(p: *const f32, index: Self) -> Self {
        // SAFETY: the caller's contract.
        Portable(index.0.map(|i| unsafe { *p.add(i as usize) }))
    }
    #[inline(always)]
    unsafe fn store(self, p: *mut f32) {
        // SAFETY: the caller guarantees p..p + LANES is writable.
        unsafe { p.cast::<[f32; LANES]>().write_unaligned(self.0) }
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| self.0[l] + o.0[l]))
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| self.0[l] - o.0[l]))
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| self.0[l] * o.0[l]))
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| self.0[l] / o.0[l]))
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        Portable(std::array::from_fn(|l| self.0[l].mul_add(b.0[l], c.0[l])))
    }
    #[inline(always)]
    fn zero_unless_below(self, a: Self, limit: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            if a.0[l] < limit.0[l] { self.0[l] } else { 0.0 }
        }))
    }
    #[inline(always)]
    fn zero_unless_positive(self, cond: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            if cond.0[l] > 0.0 { self.0[l] } else { 0.0 }
        }))
    }
    #[inline(always)]
    fn zero_if_nan(self) -> Self {
        Portable(self.0.map(|v| if v.is_nan() { 0.0 } else { v }))
    }
    #[inline(always)]
    fn exponent_from_low_bits(self, bias: i32) -> Self {
        Portable(
            self.0
                .map(|v| f32::from_bits((v.to_bits() << 23).wrapping_add((bias as u32) << 23))),
        )
    }
    #[inline(always)]
    fn all_zero(self) -> bool {
        self.0.iter().all(|&v| v == 0.0)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Portable(self.0.map(f32::sqrt))
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            if self.0[l] > o.0[l] {
                self.0[l]
            } else {
                o.0[l]
            }
        }))
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            if self.0[l] < o.0[l] {
                self.0[l]
            } else {
                o.0[l]
            }
        }))
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| mask(self.0[l] < o.0[l])))
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| mask(self.0[l] > o.0[l])))
    }
    #[inline(always)]
    fn ge(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| mask(self.0[l] >= o.0[l])))
    }
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            f32::from_bits(self.0[l].to_bits() & o.0[l].to_bits())
        }))
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            f32::from_bits(self.0[l].to_bits() | o.0[l].to_bits())
        }))
    }
    #[inline(always)]
    fn and_not(self, o: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            f32::from_bits(self.0[l].to_bits() & !o.0[l].to_bits())
        }))
    }
    #[inline(always)]
    fn select(mask: Self, a: Self, b: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            if mask.0[l].to_bits() >> 31 == 1 {
                a.0[l]
            } else {
                b.0[l]
            }
        }))
    }
    #[inline(always)]
    fn any(self) -> bool {
        self.0.iter().any(|v| v.to_bits() >> 31 == 1)
    }
    #[inline(always)]
    fn trunc_to_i32(self) -> [i32; LANES] {
        self.0.map(|v| v as i32)
    }
    #[inline(always)]
    fn trunc(self) -> Self {
        Portable(self.0.map(f32::trunc))
    }
    #[inline(always)]
    fn transpose(rows: [Self; LANES]) -> [Self; LANES] {
        std::array::from_fn(|l| Portable(std::array::from_fn(|r| rows[r].0[l])))
    }
}

/// A mask lane: all bits set for true.
#[inline(always)]
fn mask(b: bool) -> f32 {
    f32::from_bits(if b { u32::MAX } else { 0 })
}

// Crate-private: its safe methods run AVX2 instructions, so only code that checked the
// CPU (through `Kernel`) may make one.
#[cfg(target_arch = "x86_64")]
pub(crate) use avx2::Avx2;

#[cfg(target_arch = "x86_64")]
mod avx2 {
    // SAFETY (every intrinsic below): `Avx2` is crate-private and only used inside
    // functions compiled with `#[target_feature(enable = "avx2,fma")]`, which are called
    // only with `Kernel::Avx2Fma` from `Kernel::available` (the CPU has both features);
    // these methods are inlined into them.
    use super::{LANES, Lanes};
    use std::arch::x86_64::*;

    /// Eight lanes in an AVX register.
    #[derive(Clone, Copy, Debug)]
    #[repr(transparent)]
    pub struct Avx2(__m256);

    impl Lanes for Avx2 {
        #[inline(always)]
        fn splat(v: f32) -> Self {
            Avx2(unsafe { _mm256_set1_ps(v) })
        }
        #[inline(always)]
        fn from_array(a: [f32; LANES]) -> Self {
            Avx2(unsafe { _mm256_loadu_ps(a.as_ptr()) })
        }
        #[inline(always)]
        fn to_array(self) -> [f32; LANES] {
            let mut a = [0.0; LANES];
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), self.0) };
            a
        }
        #[inline(always)]
        unsafe fn load(p: *const f32) -> Self {
            Avx2(unsafe { _mm256_loadu_ps(p) })
        }
        #[inline(always)]
        unsafe fn gather(p: *const f32, index: &[i32; LANES]) -> Self {
            Avx2(unsafe {
                let index = _mm256_loadu_si256(index.as_ptr().cast());
                _mm256_i32gather_ps::<4>(p, index)
            })
        }
        #[inline(always)]
        unsafe fn gather_at(p: *const f32, index: Self) -> Self {
            Avx2(unsafe { _mm256_i32gather_ps::<4>(p, _mm256_cvttps_epi32(index.0)) })
        }
        #[inline(always)]
        unsafe fn store(self, p: *mut f32) {
            unsafe { _mm256_storeu_ps(p, self.0) }
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_add_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_sub_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_mul_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_div_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn mul_add(self, b: Self, c: Self) -> Self {
            Avx2(unsafe { _mm256_fmadd_ps(self.0, b.0, c.0) })
        }
        #[inline(always)]
        fn zero_unless_below(self, a: Self, limit: Self) -> Self {
            Avx2(unsafe { _mm256_and_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(a.0, limit.0), self.0) })
        }
        #[inline(always)]
        fn zero_unless_positive(self, cond: Self) -> Self {
            Avx2(unsafe {
                let positive = _mm256_cmp_ps::<_CMP_GT_OQ>(cond.0, _mm256_setzero_ps());
                _mm256_and_ps(positive, self.0)
            })
        }
        #[inline(always)]
        fn zero_if_nan(self) -> Self {
            Avx2(unsafe { _mm256_and_ps(_mm256_cmp_ps::<_CMP_ORD_Q>(self.0, self.0), self.0) })
        }
        #[inline(always)]
        fn exponent_from_low_bits(self, bias: i32) -> Self {
            Avx2(unsafe {
                let i = _mm256_slli_epi32::<23>(_mm256_castps_si256(self.0));
                _mm256_castsi256_ps(_mm256_add_epi32(i, _mm256_set1_epi32(bias << 23)))
            })
        }
        #[inline(always)]
        fn all_zero(self) -> bool {
            unsafe {
                let zero = _mm256_cmp_ps::<_CMP_EQ_OQ>(self.0, _mm256_setzero_ps());
                _mm256_movemask_ps(zero) == 0xff
            }
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            Avx2(unsafe { _mm256_sqrt_ps(self.0) })
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            // maxps returns its second operand unless the first is greater.
            Avx2(unsafe { _mm256_max_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_min_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn lt(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn gt(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn ge(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_cmp_ps::<_CMP_GE_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn and(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_and_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn or(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_or_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn and_not(self, o: Self) -> Self {
            Avx2(unsafe { _mm256_andnot_ps(o.0, self.0) })
        }
        #[inline(always)]
        fn select(mask: Self, a: Self, b: Self) -> Self {
            Avx2(unsafe { _mm256_blendv_ps(b.0, a.0, mask.0) })
        }
        #[inline(always)]
        fn any(self) -> bool {
            unsafe { _mm256_movemask_ps(self.0) != 0 }
        }
        #[inline(always)]
        fn trunc_to_i32(self) -> [i32; LANES] {
            let mut a = [0; LANES];
            unsafe { _mm256_storeu_si256(a.as_mut_ptr().cast(), _mm256_cvttps_epi32(self.0)) };
            a
        }
        #[inline(always)]
        fn trunc(self) -> Self {
            Avx2(unsafe { _mm256_round_ps::<{ _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC }>(self.0) })
        }
        #[inline(always)]
        fn transpose(rows: [Self; LANES]) -> [Self; LANES] {
            let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;
            unsafe {
                // Pairs of rows interleaved, then quads, then the 128-bit halves swapped.
                let t0 = _mm256_unpacklo_ps(r0.0, r1.0);
                let t1 = _mm256_unpackhi_ps(r0.0, r1.0);
                let t2 = _mm256_unpacklo_ps(r2.0, r3.0);
                let t3 = _mm256_unpackhi_ps(r2.0, r3.0);
                let t4 = _mm256_unpacklo_ps(r4.0, r5.0);
                let t5 = _mm256_unpackhi_ps(r4.0, r5.0);
                let t6 = _mm256_unpacklo_ps(r6.0, r7.0);
                let t7 = _mm256_unpackhi_ps(r6.0, r7.0);
                let q0 = _mm256_shuffle_ps::<0x44>(t0, t2);
                let q1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
                let q2 = _mm256_shuffle_ps::<0x44>(t1, t3);
                let q3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
                let q4 = _mm256_shuffle_ps::<0x44>(t4, t6);
                let q5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
                let q6 = _mm256_shuffle_ps::<0x44>(t5, t7);
                let q7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
                [
                    Avx2(_mm256_permute2f128_ps::<0x20>(q0, q4)),
                    Avx2(_mm256_permute2f128_ps::<0x20>(q1, q5)),
                    Avx2(_mm256_permute2f128_ps::<0x20>(q2, q6)),
                    Avx2(_mm256_permute2f128_ps::<0x20>(q3, q7)),
                    Avx2(_mm256_permute2f128_ps::<0x31>(q0, q4)),
                    Avx2(_mm256_permute2f128_ps::<0x31>(q1, q5)),
                    Avx2(_mm256_permute2f128_ps::<0x31>(q2, q6)),
                    Avx2(_mm256_permute2f128_ps::<0x31>(q3, q7)),
                ]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows<V: Lanes>() -> [V; LANES] {
        std::array::from_fn(|r| V::from_array(std::array::from_fn(|l| (10 * r + l) as f32)))
    }

    fn check_transpose<V: Lanes>(name: &str) {
        let columns = V::transpose(rows::<V>());
        for (l, column) in columns.iter().enumerate() {
            let expected: [f32; LANES] = std::array::from_fn(|r| (10 * r + l) as f32);
            assert_eq!(column.to_array(), expected, "{name}, column {l}");
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn check_transpose_avx2() {
        check_transpose::<Avx2>("Avx2");
    }

    #[test]
    fn transpose_moves_lane_l_of_row_r_to_lane_r_of_row_l() {
        check_transpose::<Portable>("Portable");
        #[cfg(target_arch = "x86_64")]
        if Kernel::detect() == Kernel::Avx2Fma {
            // SAFETY: the CPU has AVX2 and FMA.
            unsafe { check_transpose_avx2() };
        }
    }

    /// `trunc` as `f32::trunc` (negative, halves, just below whole numbers, large,
    /// infinite, NaN), and `gather_at` reading at whole-number float indices up to
    /// just below 2^24.
    fn check_trunc_and_gather_at<V: Lanes>(name: &str) {
        let values = [
            [-2.5, -0.7, -0.0, 0.0, 0.49, 0.99999994, 1.0, 127.99999],
            [
                4095.5,
                8_388_607.5,
                16_777_215.0,
                1e10,
                -1e10,
                f32::INFINITY,
                f32::NEG_INFINITY,
                3.5,
            ],
        ];
        for v in values {
            let got = V::from_array(v).trunc().to_array();
            for (g, x) in got.iter().zip(v) {
                assert_eq!(g.to_bits(), x.trunc().to_bits(), "{name}: trunc({x})");
            }
        }
        assert!(V::splat(f32::NAN).trunc().to_array()[0].is_nan(), "{name}");
        let data: Vec<f32> = (0..1 << 16).map(|i| i as f32 * 0.5).collect();
        let index = [0.0, 1.0, 65535.0, 17.0, 17.0, 4096.0, 3.0, 60000.0];
        // SAFETY: every index is inside `data`.
        let got = unsafe { V::gather_at(data.as_ptr(), V::from_array(index)) }.to_array();
        assert_eq!(got, index.map(|i| data[i as usize]), "{name}");
        // The largest index the contract allows.
        let mut far = vec![1.0f32; 1 << 24];
        far[(1 << 24) - 1] = 7.0;
        let at = [16_777_215.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        // SAFETY: every index is inside `far`.
        let got = unsafe { V::gather_at(far.as_ptr(), V::from_array(at)) }.to_array();
        assert_eq!(got[0], 7.0, "{name}");
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn check_trunc_and_gather_at_avx2() {
        check_trunc_and_gather_at::<Avx2>("Avx2");
    }

    #[test]
    fn trunc_rounds_toward_zero_and_gather_at_reads_at_float_indices() {
        check_trunc_and_gather_at::<Portable>("Portable");
        #[cfg(target_arch = "x86_64")]
        if Kernel::detect() == Kernel::Avx2Fma {
            // SAFETY: the CPU has AVX2 and FMA.
            unsafe { check_trunc_and_gather_at_avx2() };
        }
    }
}
