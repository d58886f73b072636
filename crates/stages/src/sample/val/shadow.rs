//! Shadow maps of the virtual area lights (paper 004 Sec. 5, Fig. 9): per light, one
//! depth map of the virtual objects and one of the real scene over the same frustum,
//! which is fitted to the virtual objects' bounding sphere ("we construct each shadow
//! frustum to closely fit all visible virtual objects and use this frustum for both
//! virtual and reconstructed shadow maps").
//!
//! Depth is light-space z along the frustum axis. The virtual map rasterizes the
//! triangles ([`super::virtual_maps`]); the real map splats the depth map's world points
//! (nearest texel, nearest depth), then closes single-texel holes with the farther of
//! two opposite neighbours, so that a surface sampled more sparsely than the map does
//! not leak light and no occluder grows at silhouettes ([`super::real_splat`]). Real
//! points between the light and the near plane count as occluders (the paper projects
//! them onto the near plane), but only from `real_occluder_reach` metres in front of
//! the objects' near side: the emitter's own surface (a VAL sits on the wall or lamp it
//! came from, or 100 m out for a distant map, behind the room's walls) must not shadow
//! the scene it lights.

use glam::{Vec2, Vec3, Vec3A};
use relume_base::simd::{LANES, Lanes, dot3};
use relume_scene::objects::Aabb;

/// The largest shadow map, in texels per side: texel indices stay below 2^24, whole
/// numbers that f32 holds exactly (the shading computes them in float lanes).
pub(crate) const MAX_SHADOW_MAP_SIZE: usize = 4096;

/// The light-space frame and projection of one light's shadow maps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ShadowFrustum {
    pub origin: Vec3A,
    pub right: Vec3A,
    pub up: Vec3A,
    pub axis: Vec3A,
    /// tan of the half-angle of the square frustum.
    pub tan_half: f32,
    /// Texels per unit of x/z: size / (2 tan_half).
    pub scale: f32,
    /// Texels per side.
    pub size: usize,
    /// Real points nearer than this (light-space z) are not splatted.
    pub real_from: f32,
}

impl ShadowFrustum {
    /// The frustum from `light` (a Lambertian emitter facing `normal`) that just holds
    /// the bounding sphere of `bounds`, or `None` when no map is needed or possible: no
    /// objects, the light inside (or within 5 % of) the sphere, or the sphere wholly
    /// behind the light's emitting side (nothing it shadows is lit by it).
    pub fn fit(light: Vec3, normal: Vec3, bounds: &Aabb, size: usize, reach: f32) -> Option<Self> {
        if !(bounds.min.cmple(bounds.max).all()) || size == 0 {
            return None;
        }
        let centre = bounds.center();
        let radius = 0.5 * (bounds.max - bounds.min).length() * 1.01 + 1e-4;
        let v = centre - light;
        let distance = v.length();
        if distance.is_nan() || distance <= radius * 1.05 || normal.dot(v) <= -radius {
            return None;
        }
        let tan_half = radius / (distance * distance - radius * radius).sqrt();
        let real_from = (distance - radius - reach).max(0.0);
        Some(Self::along(light, v / distance, tan_half, size, real_from))
    }

    /// The square frustum from `light` along unit `axis` (any right and up about it).
    fn along(light: Vec3, axis: Vec3, tan_half: f32, size: usize, real_from: f32) -> Self {
        let helper = if axis.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
        let right = helper.cross(axis).normalize();
        let up = axis.cross(right);
        ShadowFrustum {
            origin: light.into(),
            right: right.into(),
            up: up.into(),
            axis: axis.into(),
            tan_half,
            scale: size as f32 / (2.0 * tan_half),
            size,
            real_from,
        }
    }

    /// The square frustum from `light` along unit `axis` whose half-angle has tangent
    /// `tan_half` (a spot's cone), splatting real points from the light on.
    pub fn cone(light: Vec3, axis: Vec3, tan_half: f32, size: usize) -> Option<Self> {
        let axis = axis.normalize_or_zero();
        if axis == Vec3::ZERO || !(tan_half > 0.0 && tan_half.is_finite()) || size == 0 {
            return None;
        }
        Some(Self::along(light, axis, tan_half, size, 0.0))
    }

    /// World point to light space (x, y, z along the axis).
    #[inline]
    pub fn light_space(&self, p: Vec3A) -> Vec3A {
        let d = p - self.origin;
        Vec3A::new(d.dot(self.right), d.dot(self.up), d.dot(self.axis))
    }

    /// The texel holding light-space point `l`, or `None` outside the frustum. (The
    /// scalar path of the spot lights and the reference: the area lights' lanes compute
    /// the same texels.)
    pub fn texel(&self, l: Vec3A) -> Option<usize> {
        if l.z.is_nan() || l.z <= 0.0 {
            return None;
        }
        let k = self.scale / l.z;
        let half = self.size as f32 * 0.5;
        self.texel_at(l.x * k + half, l.y * k + half)
    }

    /// The texel at map coordinates (`fx`, `fy`) (texel edges at integers), or `None`
    /// off the map. (The scalar path, as `texel`.)
    pub fn texel_at(&self, fx: f32, fy: f32) -> Option<usize> {
        let s = self.size as f32;
        (fx >= 0.0 && fx < s && fy >= 0.0 && fy < s).then(|| {
            (fy as usize).min(self.size - 1) * self.size + (fx as usize).min(self.size - 1)
        })
    }

    /// Raster coordinates (texel centres at integers) of light-space point `l`.
    #[inline]
    pub fn project(&self, l: Vec3) -> Vec2 {
        let half = self.size as f32 * 0.5 - 0.5;
        Vec2::new(l.x / l.z * self.scale + half, l.y / l.z * self.scale + half)
    }

    /// World size of one texel at light-space depth `z`.
    pub fn footprint(&self, z: f32) -> f32 {
        z / self.scale
    }

    /// False when no point of the sphere (`centre`, `radius`) can be in the frustum at
    /// light-space depth `from` or more: outside the cone around the square frustum, or
    /// wholly nearer than `from`.
    #[inline]
    pub fn may_hold(&self, centre: Vec3A, radius: f32, from: f32) -> bool {
        let l = self.light_space(centre);
        if l.z + radius < from.max(0.0) {
            return false;
        }
        // The circumscribed cone: tan beta = sqrt(2) tan_half.
        let tan_beta = std::f32::consts::SQRT_2 * self.tan_half;
        let cos_beta = 1.0 / (1.0 + tan_beta * tan_beta).sqrt();
        let sin_beta = tan_beta * cos_beta;
        let lateral = (l.x * l.x + l.y * l.y).sqrt();
        lateral * cos_beta - l.z * sin_beta <= radius
    }
}

/// The frames of up to [`LANES`] lights' frusta, one light per lane. Lanes without a
/// light hold a frame that no point passes (`real_from` infinite, `size` 0).
pub(crate) struct FrustumLanes<V> {
    origin: [V; 3],
    right: [V; 3],
    up: [V; 3],
    axis: [V; 3],
    pub real_from: V,
    pub scale: V,
    /// Half the texels per side: map coordinates of the axis.
    pub half: V,
    /// Texels per side.
    pub size: V,
}

impl<V: Lanes> FrustumLanes<V> {
    #[inline(always)]
    pub fn new<'f>(frusta: impl Iterator<Item = &'f ShadowFrustum> + Clone) -> Self {
        // No lane operations in closures (see `relume_base::simd`): they only build arrays.
        let lanes = |none: f32, f: &dyn Fn(&ShadowFrustum) -> f32| {
            let mut a = [none; LANES];
            for (l, frustum) in frusta.clone().take(LANES).enumerate() {
                a[l] = f(frustum);
            }
            a
        };
        let vector = |f: &dyn Fn(&ShadowFrustum) -> Vec3A| {
            [
                lanes(0.0, &|t| f(t).x),
                lanes(0.0, &|t| f(t).y),
                lanes(0.0, &|t| f(t).z),
            ]
        };
        FrustumLanes {
            origin: lanes3(vector(&|f| f.origin)),
            right: lanes3(vector(&|f| f.right)),
            up: lanes3(vector(&|f| f.up)),
            axis: lanes3(vector(&|f| f.axis)),
            real_from: V::from_array(lanes(f32::INFINITY, &|f| f.real_from)),
            scale: V::from_array(lanes(1.0, &|f| f.scale)),
            half: V::from_array(lanes(0.0, &|f| f.size as f32 * 0.5)),
            size: V::from_array(lanes(0.0, &|f| f.size as f32)),
        }
    }

    /// `p - origin` per lane: [`ShadowFrustum::light_space`] is this offset's dot
    /// products with `right`, `up` and `axis` ([`Self::x`], [`Self::y`], [`Self::z`]).
    #[inline(always)]
    pub fn offset(&self, p: Vec3A) -> [V; 3] {
        [
            V::splat(p.x).sub(self.origin[0]),
            V::splat(p.y).sub(self.origin[1]),
            V::splat(p.z).sub(self.origin[2]),
        ]
    }

    #[inline(always)]
    pub fn x(&self, d: [V; 3]) -> V {
        dot3(d, self.right)
    }

    #[inline(always)]
    pub fn y(&self, d: [V; 3]) -> V {
        dot3(d, self.up)
    }

    #[inline(always)]
    pub fn z(&self, d: [V; 3]) -> V {
        dot3(d, self.axis)
    }
}

#[inline(always)]
fn lanes3<V: Lanes>(a: [[f32; LANES]; 3]) -> [V; 3] {
    [
        V::from_array(a[0]),
        V::from_array(a[1]),
        V::from_array(a[2]),
    ]
}

/// Bounding spheres of tiles of the real points, to skip whole tiles per light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Tile {
    pub centre: Vec3A,
    pub radius: f32,
    /// Pixel rectangle [x0, x1) x [y0, y1).
    pub x0: usize,
    pub x1: usize,
    pub y0: usize,
    pub y1: usize,
}

/// Tile edge in pixels.
pub(crate) const TILE: usize = 16;

/// The bounding sphere of the finite points of one tile (`None` when it has none).
pub(crate) fn tile_of(
    points: &[Vec3A],
    width: usize,
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
) -> Option<Tile> {
    let mut lo = Vec3A::splat(f32::INFINITY);
    let mut hi = Vec3A::splat(f32::NEG_INFINITY);
    for y in y0..y1 {
        for p in &points[y * width + x0..y * width + x1] {
            if p.is_finite() {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
    }
    lo.cmple(hi).all().then(|| Tile {
        centre: (lo + hi) * 0.5,
        radius: (hi - lo).length() * 0.5,
        x0,
        x1,
        y0,
        y1,
    })
}

/// How the camera sampled the real points: each stands for a patch of about
/// `pixel_angle` * (distance to `origin`) metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PointSampling {
    pub origin: Vec3A,
    /// Radians per pixel (1 / focal length in pixels, the larger of x and y).
    pub pixel_angle: f32,
}

impl PointSampling {
    /// The world size of the patch a real point at `p` stands for.
    #[inline]
    pub fn footprint(&self, p: Vec3A) -> f32 {
        (p - self.origin).length() * self.pixel_angle
    }
}

/// What the map tests of this module and of `real_splat` and `virtual_maps` share.
#[cfg(test)]
pub(super) mod test_support {
    use super::*;
    use relume_base::simd::Kernel;

    /// The objects' box the test frusta are fitted to.
    pub fn unit_box() -> Aabb {
        Aabb {
            min: Vec3::new(-0.5, 0.0, -0.5),
            max: Vec3::new(0.5, 1.0, 0.5),
        }
    }

    /// Eight lights on a rising spiral around the unit box, facing the origin, with
    /// maps of `size` texels per side.
    pub fn eight_lights(size: usize) -> Vec<ShadowFrustum> {
        (0..8)
            .map(|j| {
                let angle = j as f32 * 0.8;
                let light = Vec3::new(3.0 * angle.cos(), 1.5 + 0.5 * j as f32, 3.0 * angle.sin());
                ShadowFrustum::fit(light, -light, &unit_box(), size, 1.0).unwrap()
            })
            .collect()
    }

    /// Asserts that `build(kernel, group)` gives `reference` (one map per light of
    /// `lights`) bit for bit, with both kernels and groups of 1, 3 and 8 lights.
    pub fn assert_groups_match(
        lights: &[ShadowFrustum],
        reference: &[Vec<f32>],
        build: impl Fn(Kernel, &[ShadowFrustum]) -> Vec<Vec<f32>>,
    ) {
        for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
            for group in [1, 3, 8] {
                for (k, frusta) in lights.chunks(group).enumerate() {
                    for (j, map) in build(kernel, frusta).iter().enumerate() {
                        let light = k * group + j;
                        let differ = map
                            .iter()
                            .zip(&reference[light])
                            .filter(|(a, b)| a.to_bits() != b.to_bits())
                            .count();
                        assert_eq!(differ, 0, "{kernel:?}, groups of {group}: light {light}");
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::unit_box;
    use super::*;

    #[test]
    fn frustum_holds_the_bounding_sphere_and_rejects_lights_inside_or_behind() {
        let b = unit_box();
        let f = ShadowFrustum::fit(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, &b, 64, 1.0).unwrap();
        for corner in [
            b.min,
            b.max,
            Vec3::new(0.5, 0.0, -0.5),
            Vec3::new(-0.5, 1.0, 0.5),
        ] {
            assert!(f.texel(f.light_space(corner.into())).is_some(), "{corner}");
        }
        assert!(f.texel(f.light_space(Vec3A::new(3.0, 0.5, 0.0))).is_none());
        assert_eq!(
            f.texel(f.light_space(Vec3A::new(0.0, 0.5, 0.0))),
            Some(32 * 64 + 32)
        );
        let radius = 0.5 * 3f32.sqrt() * 1.01 + 1e-4;
        assert!((f.real_from - (4.5 - radius - 1.0)).abs() < 1e-5);
        assert!(ShadowFrustum::fit(Vec3::new(0.0, 0.5, 0.0), Vec3::Y, &b, 64, 1.0).is_none());
        assert!(ShadowFrustum::fit(Vec3::new(0.0, 5.0, 0.0), Vec3::Y, &b, 64, 1.0).is_none());
        assert!(
            ShadowFrustum::fit(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, &Aabb::EMPTY, 64, 1.0).is_none()
        );
    }
}
