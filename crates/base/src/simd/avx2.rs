//! The AVX2 + FMA lanes ([`Avx2`]).

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
    fn rotate_up(self, r: usize) -> Self {
        // Lane l takes lane (l + 8 - r) mod 8, the index computed in a register (the
        // Y pass rotates some 25 vectors per group that straddles two blocks).
        Avx2(unsafe {
            let iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let shifted = _mm256_add_epi32(iota, _mm256_set1_epi32((LANES - r) as i32));
            let index = _mm256_and_si256(shifted, _mm256_set1_epi32(LANES as i32 - 1));
            _mm256_permutevar8x32_ps(self.0, index)
        })
    }
    #[inline(always)]
    fn permute(self, index: Self) -> Self {
        // vpermps reads the low three bits of each index.
        Avx2(unsafe { _mm256_permutevar8x32_ps(self.0, _mm256_castps_si256(index.0)) })
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
    #[inline(always)]
    fn interleave3(planes: [Self; 3]) -> [Self; 3] {
        let [x, y, z] = planes;
        unsafe {
            // One permutation per plane puts each of its lanes where one of the three
            // results wants it (x_i at position 3 i mod 8, y_i at 3 i + 1, z_i at
            // 3 i + 2), then blends pick per result.
            let x = _mm256_permutevar8x32_ps(x.0, _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5));
            let y = _mm256_permutevar8x32_ps(y.0, _mm256_setr_epi32(5, 0, 3, 6, 1, 4, 7, 2));
            let z = _mm256_permutevar8x32_ps(z.0, _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7));
            // Blend bit j set: position j from the second operand.
            // Result 0: x at 0, 3, 6; y at 1, 4, 7; z at 2, 5.
            let r0 = _mm256_blend_ps::<0b0010_0100>(_mm256_blend_ps::<0b1001_0010>(x, y), z);
            // Result 1: z at 0, 3, 6; x at 1, 4, 7; y at 2, 5.
            let r1 = _mm256_blend_ps::<0b0010_0100>(_mm256_blend_ps::<0b0100_1001>(x, z), y);
            // Result 2: y at 0, 3, 6; z at 1, 4, 7; x at 2, 5.
            let r2 = _mm256_blend_ps::<0b1001_0010>(_mm256_blend_ps::<0b0100_1001>(x, y), z);
            [Avx2(r0), Avx2(r1), Avx2(r2)]
        }
    }
    #[inline(always)]
    fn deinterleave3(triples: [Self; 3]) -> [Self; 3] {
        let [Avx2(r0), Avx2(r1), Avx2(r2)] = triples;
        unsafe {
            // The blends of interleave3 pick each plane's lanes out of the three
            // vectors (x_i sits at position 3 i mod 8 of vector 3 i / 8, and so on);
            // one permutation per plane puts them in order.
            // x: from r0 at 0, 3, 6; r1 at 1, 4, 7; r2 at 2, 5.
            let x = _mm256_blend_ps::<0b0010_0100>(_mm256_blend_ps::<0b1001_0010>(r0, r1), r2);
            // y: from r0 at 1, 4, 7; r1 at 2, 5; r2 at 0, 3, 6.
            let y = _mm256_blend_ps::<0b0100_1001>(_mm256_blend_ps::<0b0010_0100>(r0, r1), r2);
            // z: from r0 at 2, 5; r1 at 0, 3, 6; r2 at 1, 4, 7.
            let z = _mm256_blend_ps::<0b1001_0010>(_mm256_blend_ps::<0b0100_1001>(r0, r1), r2);
            [
                Avx2(_mm256_permutevar8x32_ps(
                    x,
                    _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5),
                )),
                Avx2(_mm256_permutevar8x32_ps(
                    y,
                    _mm256_setr_epi32(1, 4, 7, 2, 5, 0, 3, 6),
                )),
                Avx2(_mm256_permutevar8x32_ps(
                    z,
                    _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7),
                )),
            ]
        }
    }
}
