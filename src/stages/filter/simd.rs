//! Four f32 lanes for the filter's tap loop: SSE2 on x86-64 (part of the baseline, so no
//! runtime detection), plain arrays elsewhere. Written out by hand because LLVM's
//! vectorizer grouped the tap loop's lanes badly (shuffles per tap) from array code.

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
mod imp {
    // SAFETY (every `unsafe` below): the intrinsics only need SSE2, which this module is
    // compiled with (the cfg above); they touch no memory.
    use std::arch::x86_64::*;

    /// Four f32 lanes.
    #[derive(Clone, Copy, Debug)]
    #[repr(transparent)]
    pub struct F4(__m128);

    impl F4 {
        #[inline(always)]
        pub fn from_array(a: [f32; 4]) -> F4 {
            F4(bytemuck::cast(a))
        }
        #[inline(always)]
        pub fn to_array(self) -> [f32; 4] {
            bytemuck::cast(self.0)
        }
        #[inline(always)]
        pub fn splat(v: f32) -> F4 {
            F4(unsafe { _mm_set1_ps(v) })
        }
        #[inline(always)]
        pub fn add(self, o: F4) -> F4 {
            F4(unsafe { _mm_add_ps(self.0, o.0) })
        }
        #[inline(always)]
        pub fn sub(self, o: F4) -> F4 {
            F4(unsafe { _mm_sub_ps(self.0, o.0) })
        }
        #[inline(always)]
        pub fn mul(self, o: F4) -> F4 {
            F4(unsafe { _mm_mul_ps(self.0, o.0) })
        }
        /// `self` where `a < limit` (false for NaN), else 0.
        #[inline(always)]
        pub fn zero_unless_below(self, a: F4, limit: F4) -> F4 {
            F4(unsafe { _mm_and_ps(_mm_cmplt_ps(a.0, limit.0), self.0) })
        }
        /// The float with bits ((bits(self) << 23) + (bias << 23)) per lane.
        #[inline(always)]
        pub fn exponent_from_low_bits(self, bias: i32) -> F4 {
            F4(unsafe {
                let i = _mm_slli_epi32::<23>(_mm_castps_si128(self.0));
                _mm_castsi128_ps(_mm_add_epi32(i, _mm_set1_epi32(bias << 23)))
            })
        }
    }
}

#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
mod imp {
    /// Four f32 lanes.
    #[derive(Clone, Copy, Debug)]
    pub struct F4([f32; 4]);

    impl F4 {
        #[inline(always)]
        pub fn from_array(a: [f32; 4]) -> F4 {
            F4(a)
        }
        #[inline(always)]
        pub fn to_array(self) -> [f32; 4] {
            self.0
        }
        #[inline(always)]
        pub fn splat(v: f32) -> F4 {
            F4([v; 4])
        }
        #[inline(always)]
        pub fn add(self, o: F4) -> F4 {
            F4(std::array::from_fn(|l| self.0[l] + o.0[l]))
        }
        #[inline(always)]
        pub fn sub(self, o: F4) -> F4 {
            F4(std::array::from_fn(|l| self.0[l] - o.0[l]))
        }
        #[inline(always)]
        pub fn mul(self, o: F4) -> F4 {
            F4(std::array::from_fn(|l| self.0[l] * o.0[l]))
        }
        #[inline(always)]
        pub fn zero_unless_below(self, a: F4, limit: F4) -> F4 {
            F4(std::array::from_fn(|l| {
                if a.0[l] < limit.0[l] { self.0[l] } else { 0.0 }
            }))
        }
        #[inline(always)]
        pub fn exponent_from_low_bits(self, bias: i32) -> F4 {
            F4(self
                .0
                .map(|v| f32::from_bits((v.to_bits() << 23).wrapping_add((bias as u32) << 23))))
        }
    }
}

pub use imp::F4;
