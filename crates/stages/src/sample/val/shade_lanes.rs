//! The scalar `shade::shade_point` for eight points at once, one per lane ([`Lanes`]):
//! the same operations in the same order per lane, so each lane's result has the bits
//! the scalar function gives (tested). A row's real pixels are shaded eight at a time,
//! then its virtual hits eight at a time.
//!
//! Per light the branches of the scalar code become masks: a lane whose light is behind
//! it or that lies outside the light's shadow frustum adds nothing or skips the map
//! lookups; the two shadow-map texels are gathered; the slope-scaled bias test runs
//! only when some lane's texels may occlude it.

use super::shade::{Biases, Maps, PreparedLight, Shaded};
use super::shadow::MAX_SHADOW_MAP_SIZE;
use glam::Vec3;
use relume_base::simd::xyz::splat_xyz;
use relume_base::simd::{LANES, Lanes, dot3};

/// Eight shading points: world positions and unit normals (x, y, z lanes), the world
/// size of each point's real-map splat (see [`Biases::slope`]), and a mask of the lanes
/// to shade.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Points<V> {
    pub position: [V; 3],
    pub normal: [V; 3],
    pub patch: V,
    pub active: V,
}

/// `b` broadcast minus `a` per component.
#[inline(always)]
fn sub_from<V: Lanes>(b: Vec3, a: [V; 3]) -> [V; 3] {
    [
        V::splat(b.x).sub(a[0]),
        V::splat(b.y).sub(a[1]),
        V::splat(b.z).sub(a[2]),
    ]
}

/// `a` minus `b` broadcast per component.
#[inline(always)]
fn sub_splat<V: Lanes>(a: [V; 3], b: Vec3) -> [V; 3] {
    [
        a[0].sub(V::splat(b.x)),
        a[1].sub(V::splat(b.y)),
        a[2].sub(V::splat(b.z)),
    ]
}

/// The [`Shaded`] values of eight points, one per lane, as arrays: a pixel reads its
/// lane with [`ShadedLanes::lane`]. (Building eight `Shaded` here and copying one out
/// later reads whole vectors of fields just written one by one, which stalls the CPU's
/// store forwarding.)
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShadedLanes {
    e_r: [[f32; LANES]; 3],
    e_rv: [[f32; LANES]; 3],
    min_occluder: [f32; LANES],
}

impl ShadedLanes {
    /// Lane `l`'s values.
    #[inline(always)]
    pub fn lane(&self, l: usize) -> Shaded {
        Shaded {
            e_r: Vec3::new(self.e_r[0][l], self.e_r[1][l], self.e_r[2][l]),
            e_rv: Vec3::new(self.e_rv[0][l], self.e_rv[1][l], self.e_rv[2][l]),
            min_occluder: self.min_occluder[l],
        }
    }
}

/// The eight points' [`Shaded`] values; lanes outside `points.active` are meaningless.
/// `lookup` is the lights' frustum mask of the scalar `shade_point`, the same for the
/// eight points (real points of one tile; `u64::MAX` for virtual hits, which lie in
/// every frustum).
#[inline(always)]
pub(crate) fn shade_points<V: Lanes>(
    points: &Points<V>,
    lookup: u64,
    lights: &[PreparedLight],
    maps: Maps,
    biases: Biases,
) -> ShadedLanes {
    let (x, n) = (points.position, points.normal);
    let zero = V::splat(0.0);
    let infinity = V::splat(f32::INFINITY);
    let mut e_r = [zero; 3];
    let mut e_rv = [zero; 3];
    let mut min_occluder = infinity;
    for (j, light) in lights.iter().enumerate() {
        // Eq. 6 as in `light_irradiance`.
        let v = sub_from(light.position.into(), x);
        let cos_receiver = dot3(n, v);
        // -(n_j . v): negating the normal first gives the same bits.
        let cos_light = dot3(splat_xyz(-Vec3::from(light.normal)), v);
        let lit = cos_receiver
            .gt(zero)
            .and(cos_light.gt(zero))
            .and(points.active);
        if !lit.any() {
            continue;
        }
        let r2 = dot3(v, v);
        let scale = cos_receiver
            .mul(cos_light)
            .div(r2.mul(r2.max(V::splat(light.min_r2))));
        let intensity = Vec3::from(light.intensity);
        let e = [
            V::splat(intensity.x).mul(scale),
            V::splat(intensity.y).mul(scale),
            V::splat(intensity.z).mul(scale),
        ];
        let (mut real_visible, mut virtual_visible) = (lit, lit);
        let frustum = light.frustum_to_look_up(j, lookup);
        if let Some(f) = frustum {
            let d = sub_splat(x, f.origin.into());
            let lx = dot3(d, splat_xyz(f.right.into()));
            let ly = dot3(d, splat_xyz(f.up.into()));
            let lz = dot3(d, splat_xyz(f.axis.into()));
            // `ShadowFrustum::texel`.
            let k = V::splat(f.scale).div(lz);
            let half = V::splat(f.size as f32 * 0.5);
            let (fx, fy) = (lx.mul(k).add(half), ly.mul(k).add(half));
            let s = V::splat(f.size as f32);
            let inside = lit
                .and(lz.gt(zero))
                .and(fx.ge(zero))
                .and(fx.lt(s))
                .and(fy.ge(zero))
                .and(fy.lt(s));
            if inside.any() {
                // `ShadowFrustum::texel_at`: inside the map the coordinates truncate to
                // texels below `size`, and the index is a whole number below
                // MAX_SHADOW_MAP_SIZE^2 = 2^24, exact in f32. Lanes outside read texel 0
                // and are masked out below.
                let texel = V::select(inside, fy.trunc().mul(s).add(fx.trunc()), zero);
                let (virtual_map, real_map) = (j * maps.stride, j * maps.stride + maps.texels);
                assert!(
                    f.size <= MAX_SHADOW_MAP_SIZE
                        && f.size * f.size <= maps.texels
                        && real_map + maps.texels <= maps.data.len()
                );
                // SAFETY: every index is a texel of light j's two maps (checked above).
                let (z_virtual, z_real) = unsafe {
                    (
                        V::gather_at(maps.data.as_ptr().add(virtual_map), texel),
                        V::gather_at(maps.data.as_ptr().add(real_map), texel),
                    )
                };
                let vb = V::splat(biases.virtual_bias);
                let rb = V::splat(biases.real_bias);
                let may_occlude = z_virtual
                    .lt(lz.sub(vb))
                    .or(z_real.lt(lz.sub(rb)))
                    .and(inside);
                // The slope test gives the fast path's answer where the fast path
                // applies (see `shade_point`), so it runs for all lanes or none.
                if biases.slope < 0.0 || may_occlude.any() {
                    let r = r2.sqrt();
                    let one = V::splat(1.0);
                    // f32::clamp(0.1, 1.0), NaN kept.
                    let cos = cos_receiver.div(r);
                    let (low, high) = (V::splat(0.1), one);
                    let cos = V::select(cos.lt(low), low, V::select(cos.gt(high), high, cos));
                    let tan = one.sub(cos.mul(cos)).sqrt().div(cos);
                    let footprint = lz.div(V::splat(f.scale));
                    let slope = V::splat(biases.slope).mul(tan);
                    let virtual_occludes = z_virtual
                        .lt(lz.sub(vb.add(slope.mul(footprint))))
                        .and(inside);
                    let real_occludes = z_real
                        // As f32::max(footprint, patch) for a NaN patch.
                        .lt(lz.sub(rb.add(slope.mul(points.patch.max(footprint)))))
                        .and(inside);
                    virtual_visible = virtual_visible.and_not(virtual_occludes);
                    real_visible = real_visible.and_not(real_occludes);
                    let occluder = V::select(virtual_occludes, z_virtual, infinity);
                    // `a.min(b)` as f32::min(b, a) for a NaN a.
                    let occluder = V::select(real_occludes, z_real.min(occluder), occluder);
                    // f32::is_finite.
                    let blocked = occluder
                        .lt(infinity)
                        .and(occluder.gt(V::splat(f32::NEG_INFINITY)));
                    if blocked.any() {
                        let d = r.mul(one.sub(occluder.div(lz)));
                        let cos_at_receiver = cos_receiver.div(r);
                        let candidate = d.max(zero).div(cos_at_receiver);
                        let nearer = candidate.min(min_occluder);
                        min_occluder = V::select(blocked, nearer, min_occluder);
                    }
                }
            }
        }
        let both = real_visible.and(virtual_visible);
        for c in 0..3 {
            e_r[c] = e_r[c].add(e[c].and(real_visible));
            e_rv[c] = e_rv[c].add(e[c].and(both));
        }
    }
    // No closures on lanes here (see `relume_base::simd`).
    ShadedLanes {
        e_r: [e_r[0].to_array(), e_r[1].to_array(), e_r[2].to_array()],
        e_rv: [e_rv[0].to_array(), e_rv[1].to_array(), e_rv[2].to_array()],
        min_occluder: min_occluder.to_array(),
    }
}
