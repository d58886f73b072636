//! The per-pixel gather and fit of [`super::gather`], eight pixels at a time: the pixels
//! of one phase (x mod step) at eight consecutive grid columns share their table of
//! covering offsets, so for each offset their eight samples lie side by side in the
//! grid's planes, one load per coordinate. Each lane follows the scalar gather step for
//! step (first valid sample as the reference, list of at most k, rejection by depth gap,
//! the same sums in the same order), then the scalar fit (`Scatter::fit`, the case
//! picked by selects) and `plane_along`, operation for operation: the same bits.

use super::fit::Scatter;
use super::gather::{RowFit, RowOut, fit_pixel, plane_along};
use super::params::NormalCode;
use glam::{Vec3, Vec3A};
use relume_base::simd::{Kernel, LANES, Lanes, Portable, dot3};

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
    fit_row_with::<relume_base::simd::Avx2>(fit, y, out)
}

#[inline(always)]
fn fit_row_with<V: Lanes>(fit: &RowFit, y: usize, out: &mut RowOut) {
    let w = out.normals.len();
    let (row_tables, row_base) = (fit.row_tables(y), fit.row_base(y));
    let ray_y = fit.ray(0, y).y;
    for (phase, table) in row_tables.iter().enumerate().take(w) {
        // Pixel phase + j step has its window centred at grid column j.
        let pixels = (w - phase).div_ceil(fit.step);
        let full = pixels - pixels % LANES;
        for first in (0..full).step_by(LANES) {
            let sums = gather_lanes::<V>(fit, row_base + first, table);
            let xs: [usize; LANES] = std::array::from_fn(|l| phase + (first + l) * fit.step);
            let ray_x = V::from_array(xs.map(|x| fit.ray_x[x]));
            let fits = fit_lanes(fit, &sums, [ray_x, V::splat(ray_y)]);
            for (x, (count, result)) in xs.into_iter().zip(fits) {
                out.set(x, count, result);
            }
        }
        for j in full..pixels {
            let x = phase + j * fit.step;
            let (count, result) = fit_pixel(fit, row_base + j, table, fit.ray(x, y));
            out.set(x, count, result);
        }
    }
}

/// A pixel's unit normal and refined depth, or why it has none.
type PixelFit = Result<(Vec3, f32), NormalCode>;

/// Eight pixels' scatter sums (as [`Scatter`] keeps them), one pixel per lane.
struct LaneSums<V> {
    /// Mask: the pixel has a valid sample (its reference).
    found: V,
    count: V,
    origin: [V; 3],
    sum: [V; 3],
    squares: [V; 3],
    cross: [V; 3],
}

/// [`LaneSums`] as arrays, lane by lane.
struct SumArrays {
    count: [f32; LANES],
    origin: [[f32; LANES]; 3],
    sum: [[f32; LANES]; 3],
    squares: [[f32; LANES]; 3],
    cross: [[f32; LANES]; 3],
}

impl SumArrays {
    #[inline(always)]
    fn of<V: Lanes>(sums: &LaneSums<V>) -> SumArrays {
        SumArrays {
            count: sums.count.to_array(),
            origin: planes(&sums.origin),
            sum: planes(&sums.sum),
            squares: planes(&sums.squares),
            cross: planes(&sums.cross),
        }
    }

    /// Lane `l`'s scatter.
    fn scatter(&self, l: usize) -> Scatter {
        let lane = |v: &[[f32; LANES]; 3]| Vec3A::new(v[0][l], v[1][l], v[2][l]);
        Scatter::from_sums(
            lane(&self.origin),
            self.count[l] as u32,
            lane(&self.sum),
            lane(&self.squares),
            lane(&self.cross),
        )
    }
}

/// The scatter sums of the eight pixels whose windows are centred at grid indices
/// `base..base + 8`, over `offsets` (nearest first): lane by lane what `fit_pixel` sums.
#[inline(always)]
fn gather_lanes<V: Lanes>(fit: &RowFit, base: usize, offsets: &[isize]) -> LaneSums<V> {
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
    LaneSums {
        found,
        count,
        origin,
        sum,
        squares,
        cross,
    }
}

/// `Scatter::fit` and `plane_along` for the eight pixels of `sums`, whose view rays
/// have x and y `ray` (z 1): lane by lane the same operations, the case chosen by
/// selects, so the same bits. A lane with a NaN determinant (overflowing sums) goes
/// through the scalar code, whose `f32::max` skips NaN where a lane maximum does not.
#[inline(always)]
fn fit_lanes<V: Lanes>(fit: &RowFit, sums: &LaneSums<V>, ray: [V; 2]) -> [(u32, PixelFit); LANES] {
    let (zero, one) = (V::splat(0.0), V::splat(1.0));
    let LaneSums { count, sum: s, .. } = *sums;
    // Centre: S = sum(d d^T) - sum(d) mean^T (see `Scatter::fit`).
    let mean = [s[0].div(count), s[1].div(count), s[2].div(count)];
    let (xx, yy, zz) = (
        sums.squares[0].sub(s[0].mul(mean[0])),
        sums.squares[1].sub(s[1].mul(mean[1])),
        sums.squares[2].sub(s[2].mul(mean[2])),
    );
    let (xy, yz, xz) = (
        sums.cross[0].sub(s[0].mul(mean[1])),
        sums.cross[1].sub(s[1].mul(mean[2])),
        sums.cross[2].sub(s[2].mul(mean[0])),
    );
    let det_x = yy.mul(zz).sub(yz.mul(yz));
    let det_y = xx.mul(zz).sub(xz.mul(xz));
    let det_z = xx.mul(yy).sub(xy.mul(xy));
    let trace = xx.add(yy).add(zz);
    let det_max = det_x.max(det_y).max(det_z);
    let well = det_max.gt(V::splat(fit.min_determinant).mul(trace).mul(trace));
    let numbers = not_nan(det_x).and(not_nan(det_y)).and(not_nan(det_z));
    let (case_z, case_y) = (equal(det_max, det_z), equal(det_max, det_y));
    let by_y = [
        xz.mul(yz).sub(xy.mul(zz)),
        det_y,
        xy.mul(xz).sub(yz.mul(xx)),
    ];
    let by_x = [
        det_x,
        xz.mul(yz).sub(xy.mul(zz)),
        xy.mul(yz).sub(xz.mul(yy)),
    ];
    let by_z = [
        xy.mul(yz).sub(xz.mul(yy)),
        xy.mul(xz).sub(yz.mul(xx)),
        det_z,
    ];
    let direction = [
        V::select(case_z, by_z[0], V::select(case_y, by_y[0], by_x[0])),
        V::select(case_z, by_z[1], V::select(case_y, by_y[1], by_x[1])),
        V::select(case_z, by_z[2], V::select(case_y, by_y[2], by_x[2])),
    ];
    let centroid = [
        sums.origin[0].add(mean[0]),
        sums.origin[1].add(mean[1]),
        sums.origin[2].add(mean[2]),
    ];
    let length = dot3(direction, direction).sqrt();
    let unit = [
        direction[0].div(length),
        direction[1].div(length),
        direction[2].div(length),
    ];
    let finite = finite(unit[0]).and(finite(unit[1])).and(finite(unit[2]));
    let towards = dot3(unit, centroid).gt(zero);
    let flip = V::select(towards, V::splat(-1.0), one);
    let normal = [unit[0].mul(flip), unit[1].mul(flip), unit[2].mul(flip)];
    let z = dot3(normal, centroid).div(dot3(normal, [ray[0], ray[1], one]));
    let off = z.sub(centroid[2]);
    let gap = V::splat(fit.gap);
    let meets = gap.ge(off).and(gap.ge(zero.sub(off))).and(z.gt(zero));
    // Lanes as arrays: the outcome of each.
    let (found, numbers, well) = (sums.found.to_array(), numbers.to_array(), well.to_array());
    let (finite, meets) = (finite.to_array(), meets.to_array());
    let (z, rays) = (z.to_array(), [ray[0].to_array(), ray[1].to_array()]);
    let normal = [
        normal[0].to_array(),
        normal[1].to_array(),
        normal[2].to_array(),
    ];
    let count = sums.count.to_array();
    // The sums lane by lane, for the scalar fit, only when a lane needs it.
    let fallback = match numbers.iter().all(|m| m.to_bits() >> 31 == 1) {
        true => None,
        false => Some(SumArrays::of(sums)),
    };
    std::array::from_fn(|l| {
        let set = |mask: &[f32; LANES]| mask[l].to_bits() >> 31 == 1;
        let n = count[l] as u32;
        let result = if !set(&found) {
            return (0, Err(NormalCode::NoSample));
        } else if n < 3 {
            Err(NormalCode::TooFewSamples)
        } else if !set(&numbers)
            && let Some(arrays) = &fallback
        {
            let ray = Vec3::new(rays[0][l], rays[1][l], 1.0);
            plane_along(&arrays.scatter(l), fit, ray)
        } else if !set(&well) || !set(&finite) {
            Err(NormalCode::Degenerate)
        } else if !set(&meets) {
            Err(NormalCode::RayMissesPlane)
        } else {
            Ok((Vec3::new(normal[0][l], normal[1][l], normal[2][l]), z[l]))
        };
        (n, result)
    })
}

/// Three vectors as arrays.
#[inline(always)]
fn planes<V: Lanes>(v: &[V; 3]) -> [[f32; LANES]; 3] {
    [v[0].to_array(), v[1].to_array(), v[2].to_array()]
}

/// A mask of the lanes that are not NaN.
#[inline(always)]
fn not_nan<V: Lanes>(v: V) -> V {
    v.ge(v)
}

/// A mask of the lanes that are finite (x - x is 0 only for them).
#[inline(always)]
fn finite<V: Lanes>(v: V) -> V {
    let zero = V::splat(0.0);
    let d = v.sub(v);
    d.ge(zero).and(zero.ge(d))
}

/// A mask of the lanes where `a == b`.
#[inline(always)]
fn equal<V: Lanes>(a: V, b: V) -> V {
    a.ge(b).and(b.ge(a))
}
