//! [`Mesh::triangle`] for eight quads at a time (one per lane): between neighbouring
//! frames a quad stays about a pixel wide, so each triangle's bounding box holds at
//! most 2 x 2 pixel centres, and the lanes test those four candidates without a
//! branch. Each lane computes what the scalar code computes, operation for operation
//! (no fused multiply-adds), so the keys have its bits; a lane whose triangle is wider,
//! or has a NaN coordinate (where the scalar `f32::min` differs from a lane minimum),
//! is handed to the scalar code. Only the z-tests of covered centres leave the lanes.

use super::mesh::{EDGE_TOLERANCE, MAX_TRIANGLE_SPAN_PX, Mesh, QuadRow, Vertex, VertexRows};
use relume_base::simd::{Kernel, LANES, Lanes, Portable};

/// Rasterizes the quads of `row` in groups of eight from the left; returns how many
/// it did (the caller does the rest one at a time).
pub(super) fn rasterize_quads(
    kernel: Kernel,
    mesh: &Mesh,
    vertices: &VertexRows,
    row: &QuadRow,
) -> usize {
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::available` says the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { rasterize_quads_avx2(mesh, vertices, row) },
        _ => rasterize_quads_with::<Portable>(mesh, vertices, row),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn rasterize_quads_avx2(mesh: &Mesh, vertices: &VertexRows, row: &QuadRow) -> usize {
    rasterize_quads_with::<relume_base::simd::Avx2>(mesh, vertices, row)
}

/// Eight vertices, one per lane.
#[derive(Clone, Copy)]
struct VertexLanes<V> {
    x: V,
    y: V,
    inv_z: V,
    weight: V,
}

impl<V: Lanes> VertexLanes<V> {
    #[inline(always)]
    fn load(vertices: &VertexRows, i: usize) -> Self {
        VertexLanes {
            x: V::load_slice(&vertices.x, i),
            y: V::load_slice(&vertices.y, i),
            inv_z: V::load_slice(&vertices.inv_z, i),
            weight: V::load_slice(&vertices.weight, i),
        }
    }

    /// `a` where `mask`, else `b`, field by field.
    #[inline(always)]
    fn select(mask: V, a: Self, b: Self) -> Self {
        VertexLanes {
            x: V::select(mask, a.x, b.x),
            y: V::select(mask, a.y, b.y),
            inv_z: V::select(mask, a.inv_z, b.inv_z),
            weight: V::select(mask, a.weight, b.weight),
        }
    }

    /// Lane `l`'s vertex.
    #[inline(always)]
    fn lane(&self, l: usize) -> Vertex {
        Vertex {
            x: self.x.to_array()[l],
            y: self.y.to_array()[l],
            inv_z: self.inv_z.to_array()[l],
            weight: self.weight.to_array()[l],
        }
    }
}

#[inline(always)]
fn rasterize_quads_with<V: Lanes>(mesh: &Mesh, vertices: &VertexRows, row: &QuadRow) -> usize {
    // Quads x..x + 8 read vertices x..x + 9: full groups end at the last vertex.
    let groups = (mesh.width.saturating_sub(1)) / LANES;
    for g in 0..groups {
        let x = g * LANES;
        let a = VertexLanes::<V>::load(vertices, row.top + x);
        let b = VertexLanes::<V>::load(vertices, row.top + x + 1);
        let c = VertexLanes::<V>::load(vertices, row.bottom + x);
        let d = VertexLanes::<V>::load(vertices, row.bottom + x + 1);
        let (za, zb) = (V::load_slice(row.z_top, x), V::load_slice(row.z_top, x + 1));
        let (zc, zd) = (
            V::load_slice(row.z_bottom, x),
            V::load_slice(row.z_bottom, x + 1),
        );
        // |za - zd| <= |zb - zc| (false for NaN, as in the scalar quad): split along
        // a-d, else along b-c.
        let along_ad = abs(zb.sub(zc)).ge(abs(za.sub(zd)));
        triangle_lanes(
            mesh,
            [a, b, VertexLanes::select(along_ad, d, c)],
            [za, zb, V::select(along_ad, zd, zc)],
        );
        triangle_lanes(
            mesh,
            [VertexLanes::select(along_ad, a, b), d, c],
            [V::select(along_ad, za, zb), zd, zc],
        );
    }
    groups * LANES
}

#[inline(always)]
fn abs<V: Lanes>(v: V) -> V {
    v.and_not(V::splat(-0.0))
}

/// A mask of the lanes that are not NaN.
#[inline(always)]
fn not_nan<V: Lanes>(v: V) -> V {
    v.ge(v)
}

/// Whether lane `l` of a mask is set.
#[inline(always)]
fn set(mask: &[f32; LANES], l: usize) -> bool {
    mask[l].to_bits() >> 31 == 1
}

/// The first and last pixel centre in `[lo, hi]` per lane and whether there is one, as
/// the scalar `centre_range` finds them.
#[inline(always)]
fn centre_range<V: Lanes>(lo: V, hi: V, last: V) -> (V, V, V) {
    let (zero, one) = (V::splat(0.0), V::splat(1.0));
    let some = hi.ge(zero).and(last.ge(lo));
    let t = lo.trunc();
    let first = V::select(lo.gt(zero), t.add(one.and(t.lt(lo))), zero);
    let end = hi.trunc().min(last);
    (first, end, some.and(end.ge(first)))
}

/// `v` clamped to `[lo, hi]` as `f32::clamp` does it.
#[inline(always)]
fn clamp<V: Lanes>(v: V, lo: V, hi: V) -> V {
    let v = V::select(v.lt(lo), lo, v);
    V::select(v.gt(hi), hi, v)
}

/// [`Mesh::triangle`] for eight triangles (`v`, with `z_prev` their vertex depths in the
/// previous map).
#[inline(always)]
fn triangle_lanes<V: Lanes>(mesh: &Mesh, v: [VertexLanes<V>; 3], z_prev: [V; 3]) {
    let [v0, v1, v2] = v;
    let (zero, one) = (V::splat(0.0), V::splat(1.0));
    let valid = v0
        .inv_z
        .gt(zero)
        .and(v1.inv_z.gt(zero))
        .and(v2.inv_z.gt(zero));
    if !valid.any() {
        return;
    }
    // Depths of valid vertices are finite and positive: no NaN in these minima.
    let z_near = z_prev[0].min(z_prev[1]).min(z_prev[2]);
    let z_far = z_prev[0].max(z_prev[1]).max(z_prev[2]);
    let stretched = z_far.sub(z_near).gt(V::splat(mesh.max_stretch).mul(z_near));
    let (x_min, x_max) = (v0.x.min(v1.x).min(v2.x), v0.x.max(v1.x).max(v2.x));
    let (y_min, y_max) = (v0.y.min(v1.y).min(v2.y), v0.y.max(v1.y).max(v2.y));
    let (x_lo, x_hi, x_some) = centre_range(x_min, x_max, V::splat(mesh.x_last));
    let (y_lo, y_hi, y_some) = centre_range(y_min, y_max, V::splat(mesh.y_last));
    let span = V::splat(MAX_TRIANGLE_SPAN_PX);
    let too_big = x_max.sub(x_min).gt(span).or(y_max.sub(y_min).gt(span));
    let (e1x, e1y) = (v1.x.sub(v0.x), v1.y.sub(v0.y));
    let (e2x, e2y) = (v2.x.sub(v0.x), v2.y.sub(v0.y));
    let area = e1x.mul(e2y).sub(e2x.mul(e1y));
    let area_abs = abs(area);
    let degenerate = V::splat(1e-12).ge(area_abs);
    let accepted = valid
        .and(x_some)
        .and(y_some)
        .and_not(stretched.or(too_big).or(degenerate));
    // A NaN coordinate: the scalar minima skip it, the lanes' do not, so such a
    // triangle is the scalar code's whatever the lanes made of it.
    let numbers = not_nan(v0.x).and(not_nan(v0.y)).and(not_nan(v1.x));
    let numbers = numbers
        .and(not_nan(v1.y))
        .and(not_nan(v2.x))
        .and(not_nan(v2.y));
    let wide = x_hi.sub(x_lo).gt(one).or(y_hi.sub(y_lo).gt(one));
    let scalar = valid.and_not(numbers).or(accepted.and(wide));
    let lanes = accepted.and(numbers).and_not(wide);
    if scalar.any() {
        let scalar = scalar.to_array();
        let z = [
            z_prev[0].to_array(),
            z_prev[1].to_array(),
            z_prev[2].to_array(),
        ];
        for l in (0..LANES).filter(|&l| set(&scalar, l)) {
            let vertices = [v0.lane(l), v1.lane(l), v2.lane(l)];
            mesh.triangle(vertices, [z[0][l], z[1][l], z[2][l]]);
        }
    }
    if !lanes.any() {
        return;
    }
    let sign = V::select(area.lt(zero), V::splat(-1.0), one);
    let tolerance = V::splat(-EDGE_TOLERANCE).mul(area_abs);
    let signed_area = area.mul(sign);
    let inv_area = one.div(signed_area);
    let (inv_z_min, inv_z_max) = (
        v0.inv_z.min(v1.inv_z).min(v2.inv_z),
        v0.inv_z.max(v1.inv_z).max(v2.inv_z),
    );
    let (weight_min, weight_max) = (
        v0.weight.min(v1.weight).min(v2.weight),
        v0.weight.max(v1.weight).max(v2.weight),
    );
    let (wz0, wz1, wz2) = (
        v0.weight.mul(v0.inv_z),
        v1.weight.mul(v1.inv_z),
        v2.weight.mul(v2.inv_z),
    );
    for (i, j) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
        let (px, py) = (x_lo.add(V::splat(i)), y_lo.add(V::splat(j)));
        let candidate = lanes.and(x_hi.ge(px)).and(y_hi.ge(py));
        if !candidate.any() {
            continue;
        }
        let (dx, dy) = (px.sub(v0.x), py.sub(v0.y));
        let a1 = dx.mul(e2y).sub(e2x.mul(dy)).mul(sign);
        let a2 = e1x.mul(dy).sub(dx.mul(e1y)).mul(sign);
        let a0 = signed_area.sub(a1).sub(a2);
        let outside = a0.lt(tolerance).or(a1.lt(tolerance)).or(a2.lt(tolerance));
        let inside = candidate.and_not(outside);
        if !inside.any() {
            continue;
        }
        let (b1, b2) = (a1.mul(inv_area), a2.mul(inv_area));
        let b0 = one.sub(b1).sub(b2);
        let inv_z = b0.mul(v0.inv_z).add(b1.mul(v1.inv_z)).add(b2.mul(v2.inv_z));
        let z = one.div(clamp(inv_z, inv_z_min, inv_z_max));
        let weight = b0.mul(wz0).add(b1.mul(wz1)).add(b2.mul(wz2)).mul(z);
        let weight = clamp(weight, weight_min, weight_max);
        let (inside, z, weight) = (inside.to_array(), z.to_array(), weight.to_array());
        let (px, py) = (px.to_array(), py.to_array());
        for l in (0..LANES).filter(|&l| set(&inside, l)) {
            let key = ((z[l].to_bits() as u64) << 32) | weight[l].to_bits() as u64;
            mesh.z_test(py[l] as usize * mesh.width + px[l] as usize, key);
        }
    }
}
