//! The blur of `blur.rs`, eight neighbouring pixels at a time (one per lane), where all
//! their taps lie inside the image. Each lane follows the scalar [`super::blur`] pixel
//! operation for operation (the same taps in the same order, the same sums, means and
//! minima), so a pixel gets the same bits either way; the tests check that.
//!
//! `same_surface` is tested in its reduced form: `n . m >= 0.9` already fails where
//! either normal is zero (n . m is +-0, or NaN against an infinite coordinate), and
//! `|(q - p) . n| <= tolerance` where `q` is not finite, so the explicit checks of the
//! scalar code change no answer.

use super::blur_pass::{PLANE_TOLERANCE, PassInputs, Taps};
use crate::sample::layers::LayerRow;
use relume_base::simd::xyz::{Xyz, finite_xyz, load_xyz, store_xyz, sub_xyz};
use relume_base::simd::{Kernel, LANES, Lanes, Portable, dot3};
use std::ops::Range;

/// Blurs the pixels `xs` of a row (every tap of each inside the image) in groups of
/// eight with `kernel`'s lanes; returns the first pixel it left (the rest of `xs`, fewer
/// than eight).
pub(super) fn blur_span(
    kernel: Kernel,
    pass: &PassInputs,
    taps: Taps,
    xs: Range<usize>,
    row: &mut LayerRow<'_>,
) -> usize {
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::available` says the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { blur_span_avx2(pass, taps, xs, row) },
        _ => blur_span_with::<Portable>(pass, taps, xs, row),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn blur_span_avx2(
    pass: &PassInputs,
    taps: Taps,
    xs: Range<usize>,
    row: &mut LayerRow<'_>,
) -> usize {
    blur_span_with::<relume_base::simd::Avx2>(pass, taps, xs, row)
}

#[inline(always)]
fn blur_span_with<V: Lanes>(
    pass: &PassInputs,
    taps: Taps,
    xs: Range<usize>,
    row: &mut LayerRow<'_>,
) -> usize {
    let mut x = xs.start;
    while x + LANES <= xs.end {
        blur_group::<V>(pass, taps, x, row);
        x += LANES;
    }
    x
}

/// The sums over the taps that pass a test: their two light layers, how many, and
/// the least of their two minimum distances.
struct Sums<V> {
    direct: Xyz<V>,
    indirect: Xyz<V>,
    count: V,
    direct_min: V,
    indirect_min: V,
}

impl<V: Lanes> Sums<V> {
    #[inline(always)]
    fn new() -> Self {
        let (zero, infinity) = (V::splat(0.0), V::splat(f32::INFINITY));
        Sums {
            direct: [zero; 3],
            indirect: [zero; 3],
            count: zero,
            direct_min: infinity,
            indirect_min: infinity,
        }
    }

    /// Adds tap `j` of `pass.input` (its two layers `direct`, `indirect`) where `ok`.
    #[inline(always)]
    fn add(&mut self, ok: V, direct: Xyz<V>, indirect: Xyz<V>, pass: &PassInputs, j: usize) {
        for c in 0..3 {
            self.direct[c] = V::select(ok, self.direct[c].add(direct[c]), self.direct[c]);
            self.indirect[c] = V::select(ok, self.indirect[c].add(indirect[c]), self.indirect[c]);
        }
        self.count = V::select(ok, self.count.add(V::splat(1.0)), self.count);
        // f32::min keeps the running minimum against NaN: take a tap's value only
        // where it is smaller.
        let direct_min = V::load_slice(&pass.input.direct_min_distance.data, j);
        let indirect_min = V::load_slice(&pass.input.indirect_min_distance.data, j);
        self.direct_min = V::select(
            ok.and(direct_min.lt(self.direct_min)),
            direct_min,
            self.direct_min,
        );
        self.indirect_min = V::select(
            ok.and(indirect_min.lt(self.indirect_min)),
            indirect_min,
            self.indirect_min,
        );
    }

    /// The means, or `own` where `own` is not finite (`keep_nan` of the scalar blur).
    #[inline(always)]
    fn means(&self, own_direct: Xyz<V>, own_indirect: Xyz<V>) -> (Xyz<V>, Xyz<V>) {
        (
            mean_or_own(&self.direct, self.count, &own_direct),
            mean_or_own(&self.indirect, self.count, &own_indirect),
        )
    }
}

/// `sum / count` (NaN where `count` is 0) where `own` is finite, else `own`.
#[inline(always)]
fn mean_or_own<V: Lanes>(sum: &Xyz<V>, count: V, own: &Xyz<V>) -> Xyz<V> {
    let (some, nan) = (count.gt(V::splat(0.0)), V::splat(f32::NAN));
    let keep = finite_xyz(own);
    let mut out = *own;
    for c in 0..3 {
        out[c] = V::select(keep, V::select(some, sum[c].div(count), nan), own[c]);
    }
    out
}

/// `a` in the lanes of `mask`, else `b`.
#[inline(always)]
fn select_xyz<V: Lanes>(mask: V, a: Xyz<V>, b: Xyz<V>) -> Xyz<V> {
    [
        V::select(mask, a[0], b[0]),
        V::select(mask, a[1], b[1]),
        V::select(mask, a[2], b[2]),
    ]
}

/// Whether neighbour `q`, `m` shows the same surface as `p`, `n` (`same_surface`, in
/// the reduced form of the module docs).
#[inline(always)]
fn same_surface<V: Lanes>(p: &Xyz<V>, n: &Xyz<V>, q: &Xyz<V>, m: &Xyz<V>) -> V {
    let along = dot3(sub_xyz(q, p), *n);
    let tolerance = V::splat(PLANE_TOLERANCE);
    dot3(*n, *m)
        .ge(V::splat(0.9))
        .and(tolerance.ge(along))
        .and(along.ge(V::splat(-PLANE_TOLERANCE)))
}

/// Blurs pixels `x..x + LANES` of the row.
#[inline(always)]
fn blur_group<V: Lanes>(pass: &PassInputs, taps: Taps, x: usize, row: &mut LayerRow<'_>) {
    let (input, geometry, real) = (pass.input, pass.geometry, pass.real);
    let one = V::splat(1.0);
    let i = taps.start + x;
    let first = i - taps.lo * taps.stride;
    let tap_indices = (0..=taps.lo + taps.hi).map(|t| first + t * taps.stride);

    // E_R over the real surface (and whether any tap is virtual or touched).
    let (rp, rn) = (
        load_xyz::<V>(&real.position, i),
        load_xyz::<V>(&real.normal, i),
    );
    let mut real_sums = Sums::<V>::new();
    let mut touched = false;
    for j in tap_indices.clone() {
        let direct = load_xyz::<V>(&input.e_r_dir.data, j);
        let indirect = load_xyz::<V>(&input.e_r_ind.data, j);
        let (q, m) = (
            load_xyz::<V>(&real.position, j),
            load_xyz::<V>(&real.normal, j),
        );
        let ok = finite_xyz(&direct)
            .and(finite_xyz(&indirect))
            .and(same_surface(&rp, &rn, &q, &m));
        real_sums.add(ok, direct, indirect, pass, j);
        let flags = &input.touched.data[j..j + LANES];
        touched |= u64::from_ne_bytes(flags.try_into().expect("eight flags")) != 0
            || V::load_slice(&geometry.mask.data, j).lt(one).any();
    }
    let own_direct = load_xyz::<V>(&input.e_r_dir.data, i);
    let own_indirect = load_xyz::<V>(&input.e_r_ind.data, i);
    let (e_r_dir, e_r_ind) = real_sums.means(own_direct, own_indirect);
    store_xyz(e_r_dir, row.e_r_dir, x);
    store_xyz(e_r_ind, row.e_r_ind, x);
    if !touched {
        // Every tap real and untouched: E_RV is E_R, tap for tap.
        store_xyz(e_r_dir, row.e_rv_dir, x);
        store_xyz(e_r_ind, row.e_rv_ind, x);
        real_sums.direct_min.store_slice(row.direct_min_distance, x);
        real_sums
            .indirect_min
            .store_slice(row.indirect_min_distance, x);
        row.touched[x..x + LANES].fill(0);
        return;
    }

    // Some lane's window holds a virtual or touched pixel: E_RV over the visible
    // surface, of the same kind (real or virtual) as the pixel.
    let lanes_touched: [bool; LANES] = std::array::from_fn(|l| {
        tap_indices
            .clone()
            .any(|j| input.touched.data[j + l] != 0 || geometry.mask.data[j + l] < 1.0)
    });
    let virtual_here = V::load_slice(&geometry.mask.data, i).lt(one);
    let vp = load_xyz::<V>(&geometry.world_position.data, i);
    let vn = load_xyz::<V>(&geometry.world_normal.data, i);
    let mut visible_sums = Sums::<V>::new();
    for j in tap_indices {
        let direct = load_xyz::<V>(&input.e_rv_dir.data, j);
        let indirect = load_xyz::<V>(&input.e_rv_ind.data, j);
        let q = load_xyz::<V>(&geometry.world_position.data, j);
        let m = load_xyz::<V>(&geometry.world_normal.data, j);
        let virtual_there = V::load_slice(&geometry.mask.data, j).lt(one);
        let same_kind = virtual_there
            .and(virtual_here)
            .or(V::splat(f32::from_bits(!0)).and_not(virtual_there.or(virtual_here)));
        let ok = same_kind
            .and(finite_xyz(&direct))
            .and(finite_xyz(&indirect))
            .and(same_surface(&vp, &vn, &q, &m));
        visible_sums.add(ok, direct, indirect, pass, j);
    }
    let own_direct = load_xyz::<V>(&input.e_rv_dir.data, i);
    let own_indirect = load_xyz::<V>(&input.e_rv_ind.data, i);
    let (e_rv_dir, e_rv_ind) = visible_sums.means(own_direct, own_indirect);
    let touched_mask = V::from_mask(lanes_touched);
    store_xyz(select_xyz(touched_mask, e_rv_dir, e_r_dir), row.e_rv_dir, x);
    store_xyz(select_xyz(touched_mask, e_rv_ind, e_r_ind), row.e_rv_ind, x);
    V::select(touched_mask, visible_sums.direct_min, real_sums.direct_min)
        .store_slice(row.direct_min_distance, x);
    V::select(
        touched_mask,
        visible_sums.indirect_min,
        real_sums.indirect_min,
    )
    .store_slice(row.indirect_min_distance, x);
    for (flag, touched) in row.touched[x..x + LANES].iter_mut().zip(lanes_touched) {
        *flag = touched as u8;
    }
}
