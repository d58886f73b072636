//! [`gather`] for eight receivers at a time: the pixels of one interleaving class in a
//! row share their VPLs (as do the first bounce's candidates: further bounces relight
//! them one at a time), so each VPL's terms (its transfer, the projection into its two
//! shadow maps, the lookups and the depth tests) run for eight receivers at once, one
//! per lane. Each lane follows the scalar [`gather`] operation for operation
//! (the same products, sums and comparisons in the same order, no fused multiply-add),
//! so a pixel gets the same bits either way; the tests check that.

use super::ism::{MAX_SLOPE, MapView, Projection};
use super::params::Flags;
use super::shade::{Gathered, LightSet, Receiver, gather};
use super::vpl::Emitter;
use glam::Vec3;
use relume_base::simd::xyz::{splat_xyz, sub_xyz};
use relume_base::simd::{Kernel, LANES, Lanes, Portable, dot3};
use std::f32::consts::FRAC_1_PI;

/// [`gather`] at eight points (`positions`, unit `normals`) of one kind of `receiver`
/// with `kernel`'s lanes. The results of lanes whose point is not finite (the NaN
/// stand-ins [`gather_each`] gives items without a point) are garbage to drop.
pub(super) fn gather_lanes(
    kernel: Kernel,
    lights: &LightSet,
    members: &[u32],
    receiver: Receiver,
    positions: &[Vec3; LANES],
    normals: &[Vec3; LANES],
) -> [Gathered; LANES] {
    let points = (positions, normals);
    match kernel.available() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::available` says the CPU has AVX2 and FMA.
        Kernel::Avx2Fma => unsafe { gather_avx2(lights, members, receiver, points) },
        _ => gather_with::<Portable>(lights, members, receiver, points),
    }
}

/// Gathers `members` at the point and normal `point_of` gives each item (none: no
/// gather), in order, eight at a time with `kernel`'s lanes, else one at a time;
/// `put` takes each result.
pub(super) fn gather_each<T>(
    kernel: Option<Kernel>,
    lights: &LightSet,
    members: &[u32],
    receiver: Receiver,
    items: &[T],
    point_of: impl Fn(&T) -> Option<(Vec3, Vec3)>,
    mut put: impl FnMut(Option<Gathered>),
) {
    // The lanes follow the paper's flags only.
    let kernel = kernel.filter(|_| lights.flags == Flags::Reciprocal);
    for group in items.chunks(LANES) {
        if let (Some(kernel), Ok(group)) = (kernel, <&[T; LANES]>::try_from(group)) {
            let points = group.each_ref().map(&point_of);
            // The lanes of items without a point gather garbage, dropped here.
            let (p, n) = (Vec3::NAN, Vec3::ZERO);
            let gathered = gather_lanes(
                kernel,
                lights,
                members,
                receiver,
                &points.map(|point| point.map_or(p, |(p, _)| p)),
                &points.map(|point| point.map_or(n, |(_, n)| n)),
            );
            for (g, point) in gathered.into_iter().zip(points) {
                put(point.map(|_| g));
            }
        } else {
            for item in group {
                put(point_of(item).map(|(p, n)| gather(lights, members, p, n, receiver)));
            }
        }
    }
}

/// Eight receivers' positions and normals.
type Points<'a> = (&'a [Vec3; LANES], &'a [Vec3; LANES]);

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn gather_avx2(
    lights: &LightSet,
    members: &[u32],
    receiver: Receiver,
    points: Points,
) -> [Gathered; LANES] {
    gather_with::<relume_base::simd::Avx2>(lights, members, receiver, points)
}

/// Eight points as three planes of lanes.
#[inline(always)]
fn planes<V: Lanes>(points: &[Vec3; LANES]) -> [V; 3] {
    [
        V::from_array(points.map(|p| p.x)),
        V::from_array(points.map(|p| p.y)),
        V::from_array(points.map(|p| p.z)),
    ]
}

/// `sum + light * factor` where `active`, else `sum` (the scalar `+=` of a Vec3).
#[inline(always)]
fn add_where<V: Lanes>(sum: &mut [V; 3], active: V, light: [V; 3], factor: V) {
    for c in 0..3 {
        sum[c] = V::select(active, sum[c].add(light[c].mul(factor)), sum[c]);
    }
}

/// Eight points projected into a map ([`Projection::project`] per lane): the mask of
/// those that fall in it, their texels' columns and rows (as floats), their depths.
pub(super) struct Projected<V> {
    pub inside: V,
    pub x: V,
    pub y: V,
    pub depth: V,
}

#[inline(always)]
pub(super) fn project<V: Lanes>(projection: &Projection, p: [V; 3], size: usize) -> Projected<V> {
    let zero = V::splat(0.0);
    let (inside, u, v, depth) = match *projection {
        Projection::Paraboloid { origin, frame } => {
            let d = sub_xyz(&p, &splat_xyz(origin));
            let r = dot3(d, d).sqrt();
            let z = dot3(d, splat_xyz(frame[2]));
            // r NaN, r <= 0 or z <= 0: outside.
            let inside = r.gt(zero).and(z.gt(zero));
            let k = V::splat(1.0).div(r.add(z));
            let u = dot3(d, splat_xyz(frame[0])).mul(k);
            let v = dot3(d, splat_xyz(frame[1])).mul(k);
            (inside, u, v, r)
        }
        Projection::Orthographic {
            center,
            radius,
            frame,
        } => {
            let d = sub_xyz(&p, &splat_xyz(center));
            let depth = V::splat(radius).sub(dot3(d, splat_xyz(frame[2])));
            // depth NaN or < 0: outside.
            let inside = depth.ge(zero);
            let k = V::splat(1.0 / radius);
            let u = dot3(d, splat_xyz(frame[0])).mul(k);
            let v = dot3(d, splat_xyz(frame[1])).mul(k);
            (inside, u, v, depth)
        }
    };
    let (half, s) = (V::splat(0.5), V::splat(size as f32));
    let u = u.mul(half).add(half).mul(s);
    let v = v.mul(half).add(half).mul(s);
    let inside = inside
        .and(u.ge(zero))
        .and(v.ge(zero))
        .and(u.lt(s))
        .and(v.lt(s));
    Projected {
        inside,
        x: u.trunc(),
        y: v.trunc(),
        depth,
    }
}

/// The tangent of the slope bias for the cosine `cos` of the light's angle to the
/// receiver's normal, as [`MapView::test`] takes it; made by the first of a VPL's
/// two tests that needs it (`slope`: `None` before).
#[inline(always)]
fn slope_tangent<V: Lanes>(cos: V, slope: &mut Option<V>) -> V {
    // (No lane operations in closures: see `relume_base::simd`.)
    if let Some(tan) = *slope {
        return tan;
    }
    let one = V::splat(1.0);
    let cos = cos.max(V::splat(1e-3)).min(one);
    let tan = one
        .sub(cos.mul(cos))
        .sqrt()
        .div(cos)
        .min(V::splat(MAX_SLOPE));
    *slope = Some(tan);
    tan
}

/// [`MapView::test`] per lane, of the lanes in `active`: visibility (1 or 0) and the
/// occluder's depth difference (INFINITY where visible). `tan` holds the slope bias's
/// tangent of `cos` once a test of the same VPL made it ([`slope_tangent`]).
#[inline(always)]
fn test<V: Lanes>(
    map: &MapView,
    at: &Projected<V>,
    cos: V,
    tan: &mut Option<V>,
    active: V,
) -> (V, V) {
    let (one, infinity) = (V::splat(1.0), V::splat(f32::INFINITY));
    // (No lane operations in closures: see `relume_base::simd`.)
    let [x0, y0, x1, y1] = map.rect;
    let (x0, y0) = (V::splat(f32::from(x0)), V::splat(f32::from(y0)));
    let (x1, y1) = (V::splat(f32::from(x1)), V::splat(f32::from(y1)));
    let hit = active
        .and(at.inside)
        .and(at.x.ge(x0))
        .and(at.x.lt(x1))
        .and(at.y.ge(y0))
        .and(at.y.lt(y1));
    if !hit.any() {
        return (one, infinity);
    }
    let size = map.size as f32;
    let index = V::select(hit, at.y.mul(V::splat(size)).add(at.x), V::splat(0.0));
    // SAFETY: a hit lane's texel lies in the map (0 <= x, y < size, exact in f32 up to
    // 2^12 texels a side); the others read texel 0.
    debug_assert!(map.size <= 4096 && map.depth.len() >= map.size * map.size);
    let stored = unsafe { V::gather_at(map.depth.as_ptr(), index) };
    let tan = slope_tangent(cos, tan);
    let texel = match *map.projection {
        Projection::Paraboloid { .. } => at.depth.mul(V::splat(4.0)).div(V::splat(size)),
        Projection::Orthographic { radius, .. } => V::splat(2.0 * radius / size),
    };
    let bias = V::splat(map.bias).add(V::splat(map.slope).mul(tan).mul(texel));
    let hidden = hit.and(at.depth.gt(stored.add(bias)));
    (
        V::select(hidden, V::splat(0.0), one),
        V::select(hidden, at.depth.sub(stored), infinity),
    )
}

#[inline(always)]
fn gather_with<V: Lanes>(
    lights: &LightSet,
    members: &[u32],
    receiver: Receiver,
    (positions, normals): Points,
) -> [Gathered; LANES] {
    let (zero, infinity) = (V::splat(0.0), V::splat(f32::INFINITY));
    let p = planes::<V>(positions);
    let n = planes::<V>(normals);
    let reach_squared = V::splat(lights.reach * lights.reach);
    let mut r_dir = [zero; 3];
    let mut r_ind = [zero; 3];
    let mut rv_dir = [zero; 3];
    let mut rv_ind = [zero; 3];
    let mut touched = zero;
    let mut direct_min = infinity;
    let mut indirect_min = infinity;
    for &i in members {
        let vpl = &lights.vpls[i as usize];
        let slot = vpl.slot as usize;
        let real = receiver == Receiver::Real;
        let for_real = real && vpl.counts_for_real();
        let for_combined = vpl.counts_for_combined() && (real || !vpl.real_only);
        if !for_real && !for_combined {
            continue;
        }
        let (transfer, distance, direct, cos, reached) = match vpl.emitter {
            Emitter::Direction(d) => {
                let cos = dot3(n, splat_xyz(d)).max(zero);
                (cos, zero, true, cos, V::splat(f32::from_bits(!0)))
            }
            Emitter::Surface {
                position: origin,
                normal: n_vpl,
            } => {
                let to = sub_xyz(&p, &splat_xyz(origin));
                let d2 = dot3(to, to);
                // 0 < d2 <= reach^2 (not NaN): most VPLs reach none of the eight.
                let within = d2.gt(zero).and_not(d2.gt(reach_squared));
                if !within.any() {
                    continue;
                }
                let d = d2.sqrt();
                let cos_vpl = dot3(splat_xyz(n_vpl), to).div(d);
                let cos_p = V::splat(-1.0).mul(dot3(n, to)).div(d);
                let floor = lights.clamp_squared.max(vpl.patch * FRAC_1_PI);
                let transfer = cos_vpl.mul(cos_p).div(d2.max(V::splat(floor)));
                // Within reach, both cosines positive.
                let reached = within.and(cos_vpl.gt(zero)).and(cos_p.gt(zero));
                (transfer, d, false, cos_p, reached)
            }
        };
        // A NaN or non-positive transfer adds nothing.
        let active = reached.and(transfer.gt(zero));
        if !active.any() {
            continue;
        }
        let (real_map, virtual_map) = (lights.map(slot, 0), lights.map(slot, 1));
        let projected = project(real_map.projection, p, lights.size);
        let mut tan = None;
        let (st_r, behind_r) = test(&real_map, &projected, cos, &mut tan, active);
        let (st_v, behind_v) = if !for_combined || virtual_map.is_empty() {
            (V::splat(1.0), infinity)
        } else if virtual_map.projection == real_map.projection {
            // A surface VPL's two maps share their paraboloid.
            test(&virtual_map, &projected, cos, &mut tan, active)
        } else {
            let projected = project(virtual_map.projection, p, lights.size);
            test(&virtual_map, &projected, cos, &mut tan, active)
        };
        let light = [
            V::splat(vpl.power.x).mul(transfer),
            V::splat(vpl.power.y).mul(transfer),
            V::splat(vpl.power.z).mul(transfer),
        ];
        let st_rv = st_r.min(st_v);
        touched = if for_real != for_combined {
            touched.or(active)
        } else {
            touched.or(active.and(st_v.lt(st_r)))
        };
        let (r, rv) = if direct {
            (&mut r_dir, &mut rv_dir)
        } else {
            (&mut r_ind, &mut rv_ind)
        };
        if for_real {
            add_where(r, active, light, st_r);
        }
        if for_combined {
            add_where(rv, active, light, st_rv);
        }
        if direct {
            let behind = behind_r.min(behind_v);
            let counts = active.and(behind.lt(infinity));
            let nearest = direct_min.min(behind.div(transfer.max(V::splat(1e-3))));
            direct_min = V::select(counts, nearest, direct_min);
        } else {
            let counts = active.and(st_rv.gt(zero).or(st_r.gt(zero)));
            indirect_min = V::select(counts, indirect_min.min(distance), indirect_min);
        }
    }
    // Lane results as arrays (no lane operations in closures: see `relume_base::simd`).
    let mut sums = [[[0.0; LANES]; 3]; 4];
    for (sum, lanes) in sums.iter_mut().zip([r_dir, r_ind, rv_dir, rv_ind]) {
        for c in 0..3 {
            sum[c] = lanes[c].to_array();
        }
    }
    let [r_dir, r_ind, rv_dir, rv_ind] = sums;
    let vec3 = |v: &[[f32; LANES]; 3], l: usize| Vec3::new(v[0][l], v[1][l], v[2][l]);
    let (touched, direct_min, indirect_min) = (
        touched.to_array(),
        direct_min.to_array(),
        indirect_min.to_array(),
    );
    std::array::from_fn(|l| Gathered {
        r_dir: vec3(&r_dir, l),
        r_ind: vec3(&r_ind, l),
        rv_dir: vec3(&rv_dir, l),
        rv_ind: vec3(&rv_ind, l),
        touched: touched[l].to_bits() != 0,
        direct_min_distance: direct_min[l],
        indirect_min_distance: indirect_min[l],
    })
}
