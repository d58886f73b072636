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

/// Number of lanes (target pixels per vector).
pub const LANES: usize = 8;

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

/// A mask lane: all bits set for true.
#[inline(always)]
fn mask(b: bool) -> f32 {
    f32::from_bits(if b { u32::MAX } else { 0 })
}

// Crate-private: its safe methods run AVX2 instructions, so only code that checked the
// CPU (through `Kernel`) may make one.
#[cfg(target_arch = "x86_64")]
pub use avx2::Avx2;

#[cfg(target_arch = "x86_64")]
mod avx2;
pub mod xyz;

#[cfg(test)]
mod tests;
