//! The preparation pass ([`super::planes::prepare`]) for eight pixels of a row at once,
//! one per lane: curvature (eq. 20), bandwidths (eqs. 17, 18) and the cleaned planes,
//! with the same operations in the same order as the scalar functions of
//! [`super::bandwidth`] (glam's `normalize`, `length` and `dot` use no fused
//! multiply-adds, and neither does this), so the same bits.
//!
//! As everywhere in lane code: no lane operations inside closures (they do not inherit
//! `#[target_feature]`).

use super::bandwidth::{MAX_BANDWIDTH, MIN_NEIGHBOUR_DISTANCE, MIN_OCCLUDER_DISTANCE};
use super::layout::{
    B2_IND, B2X_DIR, B2Y_DIR, BandwidthSettings, DIR, IND, MISSING_POSITION, PX, PY, PZ,
    PrepareInputs, RowLayout,
};
use relume_base::simd::xyz::{Xyz, finite, finite_xyz, load_xyz, sub_xyz as sub};
use relume_base::simd::{LANES, Lanes, dot3};

/// Mask of the lanes where `v` is +0 or -0.
#[inline(always)]
fn is_zero<V: Lanes>(v: V) -> V {
    let zero = V::splat(0.0);
    v.ge(zero).and(zero.ge(v))
}

/// `v.normalize()` as glam computes it: v * (1 / sqrt(v . v)).
#[inline(always)]
fn normalize<V: Lanes>(v: &Xyz<V>) -> Xyz<V> {
    let recip = V::splat(1.0).div(dot3(*v, *v).sqrt());
    [v[0].mul(recip), v[1].mul(recip), v[2].mul(recip)]
}

/// `bandwidth::usable` per lane: finite position and normal, normal not zero.
#[inline(always)]
fn usable<V: Lanes>(p: &Xyz<V>, n: &Xyz<V>) -> V {
    let n_zero = is_zero(n[0]).and(is_zero(n[1])).and(is_zero(n[2]));
    finite_xyz(p).and(finite_xyz(n)).and_not(n_zero)
}

/// `bandwidth::curvature_to` per lane from the targets (positions `p`, normalized
/// normals `n_unit`) to the neighbours (`q`, `m`): the curvature, and the mask of the
/// lanes where it exists (neighbour usable and not too close).
#[inline(always)]
fn curvature_to<V: Lanes>(p: &Xyz<V>, n_unit: &Xyz<V>, q: &Xyz<V>, m: &Xyz<V>) -> (V, V) {
    let offset = sub(p, q);
    let d = dot3(offset, offset).sqrt();
    let exists = usable(q, m).and(d.ge(V::splat(MIN_NEIGHBOUR_DISTANCE)));
    // angle_between: c (1 + c^2 (1/24 + c^2 3/640)), c = |a/|a| - b/|b||.
    let chord = sub(n_unit, &normalize(m));
    let c = dot3(chord, chord).sqrt();
    let c2 = c.mul(c);
    let series = c2
        .mul(V::splat(3.0 / 640.0))
        .add(V::splat(1.0 / 24.0))
        .mul(c2)
        .add(V::splat(1.0));
    (c.mul(series).div(d), exists)
}

/// The curvature along one image axis: towards the forward neighbour where it exists
/// (`forward`: whether it is inside the image), else the backward one, else 0.
#[inline(always)]
fn curvature_along<V: Lanes>(
    target: (&Xyz<V>, &Xyz<V>),
    forward: Option<(Xyz<V>, Xyz<V>)>,
    backward: Option<(Xyz<V>, Xyz<V>)>,
) -> V {
    let (p, n_unit) = target;
    let zero = V::splat(0.0);
    let (back, back_exists) = match backward {
        Some((q, m)) => curvature_to(p, n_unit, &q, &m),
        None => (zero, zero),
    };
    let (fwd, fwd_exists) = match forward {
        Some((q, m)) => curvature_to(p, n_unit, &q, &m),
        None => (zero, zero),
    };
    V::select(fwd_exists, fwd, V::select(back_exists, back, zero))
}

/// `bandwidth::inverse_distance` per lane.
#[inline(always)]
fn inverse_distance<V: Lanes>(z: V) -> V {
    let inverse = V::splat(1.0).div(z.max(V::splat(MIN_OCCLUDER_DISTANCE)));
    V::select(finite(z), inverse, V::splat(0.0))
}

/// `bandwidth::clamp_bandwidth` per lane (as `f32::clamp` for finite values: -0 stays
/// -0; +inf gives the maximum, -inf and NaN 0).
#[inline(always)]
fn clamp_bandwidth<V: Lanes>(b: V) -> V {
    let zero = V::splat(0.0);
    let max = V::splat(MAX_BANDWIDTH);
    let low = V::select(b.lt(zero), zero, b);
    V::select(low.gt(max), max, low).zero_if_nan()
}

/// `bandwidth::direct_bandwidth` per lane, from `angular` = B_f + 2 B_rho.
#[inline(always)]
fn direct_bandwidth<V: Lanes>(curvature: V, inverse_distance: V, angular: V, b_e: V) -> V {
    clamp_bandwidth(
        curvature
            .mul(angular)
            .add(inverse_distance.mul(angular.add(b_e))),
    )
}

/// Where a group writes: the row's planes and filter widths.
pub(super) struct RowOut<'a> {
    pub row: &'a mut [f32],
    pub width_dir: &'a mut [f32],
    pub width_ind: &'a mut [f32],
}

/// Prepares pixels (x0 + l, y) of row `y` (see [`super::planes::prepare`]). Pixels
/// x0 - 1 and x0 + LANES must be inside the row (the X neighbours are read in lanes).
#[inline(always)]
pub(super) fn prepare_group<V: Lanes>(
    images: &PrepareInputs,
    settings: BandwidthSettings,
    layout: &RowLayout,
    y: usize,
    x0: usize,
    out: &mut RowOut,
) {
    let (w, h) = (layout.width, layout.height);
    assert!(x0 >= 1 && x0 + LANES < w && y < h);
    let i = y * w + x0;
    let (p, n) = neighbours::<V>(images, i);
    let zero = V::splat(0.0);
    // Curvature (eq. 20), 0 where the target itself is not usable.
    let target_usable = usable(&p, &n);
    let n_unit = normalize(&n);
    let target = (&p, &n_unit);
    let (right, left) = (neighbours(images, i + 1), neighbours(images, i - 1));
    let below = if y + 1 < h {
        Some(neighbours(images, i + w))
    } else {
        None
    };
    let above = if y > 0 {
        Some(neighbours(images, i - w))
    } else {
        None
    };
    let kx = curvature_along(target, Some(right), Some(left)).and(target_usable);
    let ky = curvature_along(target, below, above).and(target_usable);
    // Bandwidths (eqs. 17, 18).
    let m = V::load_slice(&images.exponent.data, i);
    let m = V::select(finite(m), m.max(zero), zero);
    let glossy = m.gt(zero);
    let b_rho = V::select(glossy, V::splat(1.25).mul(m.sqrt()), zero);
    let angular = V::splat(settings.b_f).add(V::splat(2.0).mul(b_rho));
    let b_e = V::splat(settings.b_e);
    let inverse_zd = inverse_distance(V::load_slice(&images.direct_min_distance.data, i));
    let inverse_zi = inverse_distance(V::load_slice(&images.indirect_min_distance.data, i));
    let bx = direct_bandwidth(kx, inverse_zd, angular, b_e);
    let by = direct_bandwidth(ky, inverse_zd, angular, b_e);
    let indirect_brdf = V::select(
        glossy,
        V::splat(4.27).add(V::splat(0.15).mul(m)),
        V::splat(2.8),
    );
    let bi = clamp_bandwidth(indirect_brdf.mul(inverse_zi));
    // The planes.
    let has_position = finite_xyz(&p);
    let missing = V::splat(MISSING_POSITION);
    let row = &mut *out.row;
    for (q, c) in [(PX, 0), (PY, 1), (PZ, 2)] {
        V::select(has_position, p[c], missing).store_slice(row, layout.in_row(q, x0));
    }
    for (q, b) in [(B2X_DIR, bx), (B2Y_DIR, by), (B2_IND, bi)] {
        b.mul(b)
            .and(has_position)
            .store_slice(row, layout.in_row(q, x0));
    }
    for (kind, r, rv) in [(DIR, 0, 2), (IND, 1, 3)] {
        for (slot, layer) in [(0, r), (3, rv)] {
            let v = load_xyz::<V>(&images.layers[layer].data, i);
            let ok = has_position.and(finite_xyz(&v));
            for (c, value) in v.into_iter().enumerate() {
                value
                    .and(ok)
                    .store_slice(row, layout.in_row(kind + slot + c, x0));
            }
            let valid = V::splat(1.0).and(ok);
            valid.store_slice(row, layout.in_row(kind + 6 + slot / 3, x0));
        }
    }
    // Filter sizes 1 / B (paper 001 Fig. 7).
    let one = V::splat(1.0);
    let nan = V::splat(f32::NAN);
    let size_dir = V::splat(0.5).mul(one.div(bx).add(one.div(by)));
    V::select(has_position, size_dir, nan).store_slice(out.width_dir, x0);
    V::select(has_position, one.div(bi), nan).store_slice(out.width_ind, x0);
}

/// Positions and normals of pixels `j..j + LANES`.
#[inline(always)]
fn neighbours<V: Lanes>(images: &PrepareInputs, j: usize) -> (Xyz<V>, Xyz<V>) {
    (
        load_xyz(&images.world_position.data, j),
        load_xyz(&images.world_normal.data, j),
    )
}
