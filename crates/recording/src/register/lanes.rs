//! [`Quads::draw`] for eight quads at a time, one per lane, for the common case: a quad
//! on one surface, all four corners seen, whose bounding box holds at most 2 x 2 color
//! pixel centres inside the image (depth and color cameras of similar resolution, as
//! RealSense recordings have). The lanes test those four candidates against both
//! triangles without a branch, since which pixels a one-pixel quad covers is a coin
//! toss for the branch predictor. Each lane computes what the scalar code computes,
//! operation for operation (no fused multiply-adds), so the registered depth has its
//! bits; a lane whose quad is anything else (an edge, a hole, a NaN, a wider quad, the
//! image's border) is handed to the scalar code.

use super::quads::{EDGE_TOLERANCE, Projected, Quads};
use relume_base::simd::{Kernel, LANES, Lanes, Portable};

/// Draws the quads of the depth row starting at pixel `row` (of a `width`-pixel depth
/// image) in groups of eight from the left; returns how many it did (the caller does the
/// rest one at a time).
pub(super) fn surface_quads(kernel: Kernel, quads: &mut Quads, row: usize, width: usize) -> usize {
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::available` says the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { surface_quads_avx2(quads, row, width) },
        _ => surface_quads_with::<Portable>(quads, row, width),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn surface_quads_avx2(quads: &mut Quads, row: usize, width: usize) -> usize {
    surface_quads_with::<relume_base::simd::Avx2>(quads, row, width)
}

/// Eight projected depth pixels: color-image x, y and 1/z.
#[derive(Clone, Copy)]
struct Corner<V> {
    x: V,
    y: V,
    w: V,
}

impl<V: Lanes> Corner<V> {
    #[inline(always)]
    fn load(p: &Projected, i: usize) -> Self {
        Corner {
            x: V::load_slice(&p.x, i),
            y: V::load_slice(&p.y, i),
            w: V::load_slice(&p.w, i),
        }
    }
}

/// A mask of the lanes that are not NaN.
#[inline(always)]
fn not_nan<V: Lanes>(v: V) -> V {
    v.ge(v)
}

/// The smallest whole number at or above `x`, as the scalar `ceil` for |x| < 2^31.
#[inline(always)]
fn ceil<V: Lanes>(x: V) -> V {
    let t = x.trunc();
    t.add(V::splat(1.0).and(t.lt(x)))
}

/// The largest whole number at or below `x`, as the scalar `floor` for |x| < 2^31.
#[inline(always)]
fn floor<V: Lanes>(x: V) -> V {
    let t = x.trunc();
    t.sub(V::splat(1.0).and(t.gt(x)))
}

/// The edge function of the edge from a to b at (qx, qy), over the triangle's signed
/// area: the barycentric weight of the corner opposite the edge (`Triangle::weight_at`).
#[inline(always)]
fn edge<V: Lanes>(a: Corner<V>, b: Corner<V>, qx: V, qy: V, inv_area: V) -> V {
    (b.x.sub(a.x))
        .mul(qy.sub(a.y))
        .sub((qx.sub(a.x)).mul(b.y.sub(a.y)))
        .mul(inv_area)
}

/// Whether lane `l` of a mask is set.
#[inline(always)]
fn set(mask: &[f32; LANES], l: usize) -> bool {
    mask[l].to_bits() >> 31 == 1
}

#[inline(always)]
fn surface_quads_with<V: Lanes>(quads: &mut Quads, row: usize, width: usize) -> usize {
    // Quads x..x + 8 read depth pixels x..x + 9: full groups end at the row's last pixel.
    let groups = width.saturating_sub(1) / LANES;
    let (cw, ch) = quads.size;
    let (zero, one) = (V::splat(0.0), V::splat(1.0));
    let (x_last, y_last) = (V::splat(cw as f32 - 1.0), V::splat(ch as f32 - 1.0));
    let step = V::splat(quads.step);
    for g in 0..groups {
        let i = row + g * LANES;
        // No closures here: they would not inherit the AVX2 target feature.
        let (d, pr) = (quads.depth_m, quads.projected);
        let z = [
            V::load_slice(d, i),
            V::load_slice(d, i + 1),
            V::load_slice(d, i + width),
            V::load_slice(d, i + width + 1),
        ];
        let p = [
            Corner::<V>::load(pr, i),
            Corner::load(pr, i + 1),
            Corner::load(pr, i + width),
            Corner::load(pr, i + width + 1),
        ];
        // One surface, all corners seen, as `Quads::draw` decides (depths are finite).
        let lo = z[0].min(z[1]).min(z[2]).min(z[3]);
        let hi = z[0].max(z[1]).max(z[2]).max(z[3]);
        let seen = p[0]
            .w
            .gt(zero)
            .and(p[1].w.gt(zero))
            .and(p[2].w.gt(zero))
            .and(p[3].w.gt(zero));
        let surface = lo.gt(zero).and(seen).and(lo.mul(step).ge(hi.sub(lo)));
        // No NaN or infinity anywhere (the scalar minima skip a NaN, the lanes' do not).
        let finite = V::splat(f32::MAX);
        let mut numbers = surface;
        for c in &p {
            for v in [c.x, c.y, c.w] {
                numbers = numbers.and(finite.ge(v.max(zero.sub(v))));
            }
        }
        let min_x = p[0].x.min(p[1].x).min(p[2].x).min(p[3].x);
        let max_x = p[0].x.max(p[1].x).max(p[2].x).max(p[3].x);
        let min_y = p[0].y.min(p[1].y).min(p[2].y).min(p[3].y);
        let max_y = p[0].y.max(p[1].y).max(p[2].y).max(p[3].y);
        let (x0, x1) = (ceil(min_x), floor(max_x));
        let (y0, y1) = (ceil(min_y), floor(max_y));
        // The 2 x 2 block from (x0, y0) holds every centre and lies in the image.
        let block = x0
            .ge(zero)
            .and(y0.ge(zero))
            .and(x0.add(one).ge(x1))
            .and(y0.add(one).ge(y1))
            .and(x_last.ge(x0.add(one)))
            .and(y_last.ge(y0.add(one)));
        // No centre in the box, or the box outside the image (the depth camera's wider
        // field): nothing to draw.
        let empty = x1
            .lt(x0)
            .or(y1.lt(y0))
            .or(x1.lt(zero))
            .or(y1.lt(zero))
            .or(x_last.lt(x0))
            .or(y_last.lt(y0));
        let lanes = numbers.and(block);
        let (lanes_set, done) = (lanes.to_array(), lanes.or(numbers.and(empty)).to_array());
        for l in (0..LANES).filter(|&l| !set(&done, l)) {
            quads.draw(i + l);
        }
        if !lanes.any() {
            continue;
        }
        // Per candidate centre (x0 + dx, y0 + dy): the nearest 1/z of the two triangles
        // covering it (0: none).
        let candidates = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)];
        let mut best = [zero; 4];
        for t in [[p[0], p[1], p[2]], [p[1], p[3], p[2]]] {
            let t_min_x = t[0].x.min(t[1].x).min(t[2].x);
            let t_max_x = t[0].x.max(t[1].x).max(t[2].x);
            let t_min_y = t[0].y.min(t[1].y).min(t[2].y);
            let t_max_y = t[0].y.max(t[1].y).max(t[2].y);
            let area = (t[1].x.sub(t[0].x))
                .mul(t[2].y.sub(t[0].y))
                .sub((t[2].x.sub(t[0].x)).mul(t[1].y.sub(t[0].y)));
            let drawn = lanes.and(area.max(zero.sub(area)).ge(V::splat(1e-12)));
            let inv_area = one.div(area);
            for (k, &(dx, dy)) in candidates.iter().enumerate() {
                let (qx, qy) = (x0.add(V::splat(dx)), y0.add(V::splat(dy)));
                // In the quad's box and the triangle's (x >= ceil(min) is x >= min for
                // a whole x).
                let boxed = drawn
                    .and(x1.ge(qx))
                    .and(y1.ge(qy))
                    .and(qx.ge(t_min_x))
                    .and(t_max_x.ge(qx))
                    .and(qy.ge(t_min_y))
                    .and(t_max_y.ge(qy));
                let l0 = edge(t[1], t[2], qx, qy, inv_area);
                let l1 = edge(t[2], t[0], qx, qy, inv_area);
                let l2 = one.sub(l0).sub(l1);
                let tolerance = V::splat(EDGE_TOLERANCE);
                let outside = l0.lt(tolerance).or(l1.lt(tolerance)).or(l2.lt(tolerance));
                let w = l0.mul(t[0].w).add(l1.mul(t[1].w)).add(l2.mul(t[2].w));
                // A NaN weight is never kept, as `w > slot` never holds for it.
                let inside = boxed.and_not(outside).and(not_nan(w));
                best[k] = V::select(inside.and(w.gt(best[k])), w, best[k]);
            }
        }
        let (x0, y0) = (x0.trunc_to_i32(), y0.trunc_to_i32());
        for (k, &(dx, dy)) in candidates.iter().enumerate() {
            let best = best[k].to_array();
            for l in (0..LANES).filter(|&l| set(&lanes_set, l)) {
                let pixel = (y0[l] as usize + dy as usize) * cw + x0[l] as usize + dx as usize;
                let slot = &mut quads.nearest[pixel];
                if best[l] > *slot {
                    *slot = best[l];
                }
            }
        }
    }
    groups * LANES
}
