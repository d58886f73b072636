//! The per-pixel gather of [`super::gather`], eight pixels at a time: the pixels of one
//! phase (x mod step) at eight consecutive grid columns share their table of covering
//! offsets, so for each offset their eight samples lie side by side in the grid's
//! planes, one load per coordinate. Each lane follows the scalar gather step for step
//! (first valid sample as the reference, list of at most k, rejection by depth gap,
//! the same sums in the same order), so the sums, and the fits made from them one pixel
//! at a time, have the scalar bits.

use super::fit::Scatter;
use super::gather::{RowFit, RowOut, fit_pixel, plane_along};
use crate::simd::{Kernel, LANES, Lanes, Portable};
use glam::Vec3A;

/// Fits row `y` with `kernel`'s lanes (pixels left over after the last full group of
/// a phase one at a time).
pub(super) fn fit_row_lanes(kernel: Kernel, fit: &RowFit, y: usize, out: &mut RowOut) {
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::available` says the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { fit_row_avx2(fit, y, out) },
        _ => fit_row_with::<Portable>(fit, y, out),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn fit_row_avx2(fit: &RowFit, y: usize, out: &mut RowOut) {
    fit_row_with::<crate::simd::Avx2>(fit, y, out)
}

#[inline(always)]
fn fit_row_with<V: Lanes>(fit: &RowFit, y: usize, out: &mut RowOut) {
    let w = out.normals.len();
    let (row_tables, row_base) = (fit.row_tables(y), fit.row_base(y));
    for (phase, table) in row_tables.iter().enumerate().take(w) {
        // Pixel phase + j step has its window centred at grid column j.
        let pixels = (w - phase).div_ceil(fit.step);
        let full = pixels - pixels % LANES;
        for first in (0..full).step_by(LANES) {
            let scatters = gather_lanes::<V>(fit, row_base + first, table);
            for (l, scatter) in scatters.iter().enumerate() {
                let x = phase + (first + l) * fit.step;
                match scatter {
                    Some(s) => out.set(x, s.count(), plane_along(s, fit, fit.ray(x, y))),
                    None => out.set(x, 0, Err(super::NormalCode::NoSample)),
                }
            }
        }
        for j in full..pixels {
            let x = phase + j * fit.step;
            let (count, result) = fit_pixel(fit, row_base + j, table, fit.ray(x, y));
            out.set(x, count, result);
        }
    }
}

/// The scatters of the eight pixels whose windows are centred at grid indices `base..
/// base + 8`, over `offsets` (nearest first): lane by lane what `fit_pixel` sums, `None`
/// where no sample is valid.
#[inline(always)]
fn gather_lanes<V: Lanes>(
    fit: &RowFit,
    base: usize,
    offsets: &[isize],
) -> [Option<Scatter>; LANES] {
    let [xs, ys, zs] = &fit.grid.planes;
    let (zero, one) = (V::splat(0.0), V::splat(1.0));
    let (k, gap) = (V::splat(fit.k as f32), V::splat(fit.gap));
    // Masks: the lanes that have their reference sample.
    let mut found = zero;
    let mut origin = [V::splat(f32::NAN); 3];
    // Samples listed (valid ones, the reference included) and samples added.
    let (mut listed, mut count) = (zero, zero);
    let mut sum = [zero; 3];
    let mut squares = [zero; 3];
    let mut cross = [zero; 3];
    for &offset in offsets {
        let i = base.wrapping_add_signed(offset);
        let (px, py, pz) = (
            V::load_slice(xs, i),
            V::load_slice(ys, i),
            V::load_slice(zs, i),
        );
        let valid = pz.gt(zero);
        // Lanes past their reference whose list is not full yet (the scalar loop's
        // `break` once k are listed).
        let open = found.and(listed.lt(k));
        listed = listed.add(one.and(open.and(valid)));
        // |p.z - origin.z| <= gap, false for holes (NaN): a - b is exactly -(b - a).
        let near = gap.ge(pz.sub(origin[2])).and(gap.ge(origin[2].sub(pz)));
        let keep = open.and(near);
        // Zero offsets where not kept, as `Scatter::add_if`.
        let (dx, dy, dz) = (
            px.sub(origin[0]).and(keep),
            py.sub(origin[1]).and(keep),
            pz.sub(origin[2]).and(keep),
        );
        count = count.add(one.and(keep));
        sum = [sum[0].add(dx), sum[1].add(dy), sum[2].add(dz)];
        squares = [
            squares[0].add(dx.mul(dx)),
            squares[1].add(dy.mul(dy)),
            squares[2].add(dz.mul(dz)),
        ];
        cross = [
            cross[0].add(dx.mul(dy)),
            cross[1].add(dy.mul(dz)),
            cross[2].add(dz.mul(dx)),
        ];
        // The first valid sample becomes the reference: listed and added once, at a
        // zero offset from itself.
        let first = valid.and_not(found);
        origin = [
            V::select(first, px, origin[0]),
            V::select(first, py, origin[1]),
            V::select(first, pz, origin[2]),
        ];
        listed = V::select(first, one, listed);
        count = V::select(first, one, count);
        found = found.or(valid);
    }
    let found = found.to_array();
    let count = count.to_array();
    let [ox, oy, oz] = [
        origin[0].to_array(),
        origin[1].to_array(),
        origin[2].to_array(),
    ];
    let [sx, sy, sz] = [sum[0].to_array(), sum[1].to_array(), sum[2].to_array()];
    let [qx, qy, qz] = [
        squares[0].to_array(),
        squares[1].to_array(),
        squares[2].to_array(),
    ];
    let [cx, cy, cz] = [
        cross[0].to_array(),
        cross[1].to_array(),
        cross[2].to_array(),
    ];
    std::array::from_fn(|l| {
        (found[l].to_bits() >> 31 == 1).then(|| {
            Scatter::from_sums(
                Vec3A::new(ox[l], oy[l], oz[l]),
                count[l] as u32,
                Vec3A::new(sx[l], sy[l], sz[l]),
                Vec3A::new(qx[l], qy[l], qz[l]),
                Vec3A::new(cx[l], cy[l], cz[l]),
            )
        })
    })
}
