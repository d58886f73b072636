//! Three planes of lanes for eight points or vectors (x, y, z), and what the lane code
//! of several stages does with them: loads from and stores to `[Vec3]` images, finite
//! tests, splats and differences.

use super::{LANES, Lanes};
use glam::Vec3;

/// Three coordinate planes of eight points, one point per lane.
pub type Xyz<V> = [V; 3];

/// Pixels `i..i + LANES` of `data` as three planes: three vector loads and
/// [`Lanes::deinterleave3`] (three gathers per call took a quarter of the filter's
/// pass). Panics past the end of `data`.
#[inline(always)]
pub fn load_xyz<V: Lanes>(data: &[Vec3], i: usize) -> Xyz<V> {
    let pixels = &data[i..i + LANES];
    let floats = pixels.as_ptr().cast::<f32>();
    // SAFETY: the LANES pixels are 3 LANES floats (Vec3 is #[repr(C)], three f32).
    let triples = unsafe {
        [
            V::load(floats),
            V::load(floats.add(LANES)),
            V::load(floats.add(2 * LANES)),
        ]
    };
    V::deinterleave3(triples)
}

/// Writes three planes to pixels `i..i + LANES` of `data` (the inverse of
/// [`load_xyz`]). Panics past the end of `data`.
#[inline(always)]
pub fn store_xyz<V: Lanes>(v: Xyz<V>, data: &mut [Vec3], i: usize) {
    let pixels = &mut data[i..i + LANES];
    let floats = pixels.as_mut_ptr().cast::<f32>();
    let [a, b, c] = V::interleave3(v);
    // SAFETY: the LANES pixels are 3 LANES writable floats.
    unsafe {
        a.store(floats);
        b.store(floats.add(LANES));
        c.store(floats.add(2 * LANES));
    }
}

/// Mask of the lanes where `v` is finite (v - v is 0 there, NaN elsewhere).
#[inline(always)]
pub fn finite<V: Lanes>(v: V) -> V {
    v.sub(v).ge(V::splat(0.0))
}

/// Mask of the lanes where all three coordinates are finite (`Vec3::is_finite`).
#[inline(always)]
pub fn finite_xyz<V: Lanes>(v: &Xyz<V>) -> V {
    finite(v[0]).and(finite(v[1])).and(finite(v[2]))
}

/// `v` in every lane.
#[inline(always)]
pub fn splat_xyz<V: Lanes>(v: Vec3) -> Xyz<V> {
    [V::splat(v.x), V::splat(v.y), V::splat(v.z)]
}

/// `a - b` per coordinate.
#[inline(always)]
pub fn sub_xyz<V: Lanes>(a: &Xyz<V>, b: &Xyz<V>) -> Xyz<V> {
    [a[0].sub(b[0]), a[1].sub(b[1]), a[2].sub(b[2])]
}
