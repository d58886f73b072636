//! Eight f32 lanes, one pixel per lane, for the per-pixel loops that the compiler does
//! not vectorize well by itself (the filter's tap loops, `sample.val`'s shading and
//! shadow maps, `normals.plane_fit`'s gather, `depth.fuse`'s triangles, `sample.dir`'s
//! gather, blur and splats): AVX2
//! with FMA where the CPU has them (detected at run time, [`Kernel::detect`]), plain
//! arrays with `f32::mul_add` elsewhere. Both compute the same operations with the same
//! roundings (a fused multiply-add rounds once in either), so outputs do not depend on
//! the kernel. (Exception: [`Lanes::trunc_to_i32`] of NaN or out-of-range values, which
//! callers do not use.)
//!
//! Use: a generic `#[inline(always)]` function over [`Lanes`], called through a
//! `#[target_feature(enable = "avx2,fma")]` wrapper with `Avx2` when [`Kernel::detect`]
//! says so, else with [`Portable`]. Never call lane operations from closures inside
//! such functions: closures do not inherit `#[target_feature]`, and the intrinsics in
//! them would stay function calls (10-30x slower).

use lanes::mask;
pub use lanes::{LANES, Lanes};

/// Which eight-lane code runs: the filter's passes, sample.val's shading and shadow
/// maps, plane_fit's gather, depth.fuse's triangles and sample.dir's gather, blur and
/// splats (through [`Lanes`]), and the
/// screen-space tracer's batches (`ssrt::TraceBatch`).
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

/// a . b per lane in glam's order (`Vec3::dot`, and `Vec3A::dot` on x86-64):
/// (x x' + y y') + z z', no fused multiply-add, so each lane has glam's bits.
#[inline(always)]
pub fn dot3<V: Lanes>(a: [V; 3], b: [V; 3]) -> V {
    a[0].mul(b[0]).add(a[1].mul(b[1])).add(a[2].mul(b[2]))
}

/// The portable lanes.
#[repr(transparent)]
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
    #[inline(always)]
    fn rotate_up(self, r: usize) -> Self {
        Portable(std::array::from_fn(|l| self.0[(l + LANES - r) % LANES]))
    }
    #[inline(always)]
    fn permute(self, index: Self) -> Self {
        Portable(std::array::from_fn(|l| {
            self.0[index.0[l].to_bits() as usize % LANES]
        }))
    }
    #[inline(always)]
    fn interleave3(planes: [Self; 3]) -> [Self; 3] {
        std::array::from_fn(|r| {
            Portable(std::array::from_fn(|j| {
                let i = LANES * r + j;
                planes[i % 3].0[i / 3]
            }))
        })
    }
    #[inline(always)]
    fn deinterleave3(triples: [Self; 3]) -> [Self; 3] {
        std::array::from_fn(|c| {
            Portable(std::array::from_fn(|j| {
                let i = 3 * j + c;
                triples[i / LANES].0[i % LANES]
            }))
        })
    }
}

// Crate-private: its safe methods run AVX2 instructions, so only code that checked the
// CPU (through `Kernel`) may make one.
#[cfg(target_arch = "x86_64")]
pub use avx2::Avx2;

#[cfg(target_arch = "x86_64")]
mod avx2;
mod lanes;
pub mod xyz;

#[cfg(test)]
mod tests;
