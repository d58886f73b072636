//! Shadow maps of the virtual area lights (paper 004 Sec. 5, Fig. 9): per light, one
//! depth map of the virtual objects and one of the real scene over the same frustum,
//! which is fitted to the virtual objects' bounding sphere ("we construct each shadow
//! frustum to closely fit all visible virtual objects and use this frustum for both
//! virtual and reconstructed shadow maps").
//!
//! Depth is light-space z along the frustum axis. The virtual map rasterizes the
//! triangles; the real map splats the depth map's world points (nearest texel, nearest
//! depth), then closes single-texel holes with the farther of two opposite neighbours
//! (so a surface sampled more sparsely than the map does not leak light, and no
//! occluder grows at silhouettes). Real points between the light and the near plane
//! count as occluders (the paper projects them onto the near plane), but only from
//! `real_occluder_reach` metres in front of the objects' near side: the emitter's own
//! surface (a VAL sits on the wall or lamp it came from, or 100 m out for a distant
//! map, behind the room's walls) must not shadow the scene it lights.

use super::raster::{DepthTarget, raster_view_triangle};
use crate::objects::{Aabb, VirtualScene};
use glam::{Vec2, Vec3, Vec3A};

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
        let axis = v / distance;
        let helper = if axis.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
        let right = helper.cross(axis).normalize();
        let up = axis.cross(right);
        let tan_half = radius / (distance * distance - radius * radius).sqrt();
        Some(ShadowFrustum {
            origin: light.into(),
            right: right.into(),
            up: up.into(),
            axis: axis.into(),
            tan_half,
            scale: size as f32 / (2.0 * tan_half),
            size,
            real_from: (distance - radius - reach).max(0.0),
        })
    }

    /// World point to light space (x, y, z along the axis).
    #[inline]
    pub fn light_space(&self, p: Vec3A) -> Vec3A {
        let d = p - self.origin;
        Vec3A::new(d.dot(self.right), d.dot(self.up), d.dot(self.axis))
    }

    /// The texel holding light-space point `l`, or `None` outside the frustum.
    #[inline]
    pub fn texel(&self, l: Vec3A) -> Option<usize> {
        if l.z.is_nan() || l.z <= 0.0 {
            return None;
        }
        let k = self.scale / l.z;
        let half = self.size as f32 * 0.5;
        self.texel_at(l.x * k + half, l.y * k + half)
    }

    /// The texel at map coordinates (`fx`, `fy`) (texel edges at integers), or `None`
    /// off the map.
    #[inline]
    pub fn texel_at(&self, fx: f32, fy: f32) -> Option<usize> {
        let s = self.size as f32;
        (fx >= 0.0 && fx < s && fy >= 0.0 && fy < s).then(|| {
            (fy as usize).min(self.size - 1) * self.size + (fx as usize).min(self.size - 1)
        })
    }

    /// Raster coordinates (texel centres at integers) of light-space point `l`.
    #[inline]
    fn project(&self, l: Vec3) -> Vec2 {
        let half = self.size as f32 * 0.5 - 0.5;
        Vec2::new(l.x / l.z * self.scale + half, l.y / l.z * self.scale + half)
    }

    /// World size of one texel at light-space depth `z`.
    #[inline]
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

/// Rasterizes the virtual triangles into `map` (size^2 texels, reset here).
pub(crate) fn virtual_shadow_map(frustum: &ShadowFrustum, scene: &VirtualScene, map: &mut [f32]) {
    map.fill(f32::INFINITY);
    let mut target = DepthTarget {
        width: frustum.size,
        height: frustum.size,
        first_row: 0,
        depth: map,
        ids: None,
    };
    for (i, tri) in scene.triangles.iter().enumerate() {
        let view = tri
            .vertices
            .map(|v| Vec3::from(frustum.light_space(v.into())));
        raster_view_triangle(&mut target, &view, 1e-6, |l| frustum.project(l), i as u32);
    }
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

/// Largest splat half-width in texels (bounds the cost of very close, coarse points).
const MAX_SPLAT_RADIUS: f32 = 16.0;

/// Splats the real world points (`width` per row, non-finite = none) of the tiles that
/// may reach the frustum into `map` (nearest depth per texel), each over a square of
/// texels as wide as the patch it stands for (`patches`, per point: see
/// [`PointSampling::footprint`]; so a surface the camera sampled more coarsely than the
/// map's texels still covers the map), then closes single-texel holes into `map` using
/// `scratch` (both size^2).
pub(crate) fn real_shadow_map(
    frustum: &ShadowFrustum,
    points: &[Vec3A],
    patches: &[f32],
    width: usize,
    tiles: &[Option<Tile>],
    map: &mut [f32],
    scratch: &mut [f32],
) {
    map.fill(f32::INFINITY);
    let size = frustum.size;
    let half = size as f32 * 0.5;
    for tile in tiles.iter().flatten() {
        if !frustum.may_hold(tile.centre, tile.radius, frustum.real_from) {
            continue;
        }
        for y in tile.y0..tile.y1 {
            let row = y * width + tile.x0..y * width + tile.x1;
            for (p, &patch) in points[row.clone()].iter().zip(&patches[row]) {
                let l = frustum.light_space(*p);
                // NaN points fail this test too.
                if !(l.z >= frustum.real_from && l.z > 0.0) {
                    continue;
                }
                let k = frustum.scale / l.z;
                let (fx, fy) = (l.x * k + half, l.y * k + half);
                // Half the patch's diagonal, in texels.
                let radius = (0.71 * patch * k).min(MAX_SPLAT_RADIUS);
                if radius < 0.5 {
                    if let Some(t) = frustum.texel_at(fx, fy)
                        && l.z < map[t]
                    {
                        map[t] = l.z;
                    }
                    continue;
                }
                let s = size as f32;
                let (x0, x1) = ((fx - radius).max(0.0), (fx + radius).min(s - 1e-3));
                let (y0, y1) = ((fy - radius).max(0.0), (fy + radius).min(s - 1e-3));
                if !(x0 <= x1 && y0 <= y1) {
                    continue;
                }
                for ty in y0 as usize..=y1 as usize {
                    for t in &mut map[ty * size + x0 as usize..=ty * size + x1 as usize] {
                        if l.z < *t {
                            *t = l.z;
                        }
                    }
                }
            }
        }
    }
    close_holes(map, scratch, size);
}

/// Fills each empty texel whose left and right, or upper and lower, neighbours are both
/// filled, with the farthest of those filled pairs' depths (reads a copy: the result does
/// not depend on the scan order).
fn close_holes(map: &mut [f32], scratch: &mut [f32], size: usize) {
    scratch.copy_from_slice(map);
    for y in 0..size {
        for x in 0..size {
            let i = y * size + x;
            if scratch[i].is_finite() {
                continue;
            }
            let mut fill = f32::NEG_INFINITY;
            if x > 0 && x + 1 < size && scratch[i - 1].is_finite() && scratch[i + 1].is_finite() {
                fill = fill.max(scratch[i - 1]).max(scratch[i + 1]);
            }
            if y > 0
                && y + 1 < size
                && scratch[i - size].is_finite()
                && scratch[i + size].is_finite()
            {
                fill = fill.max(scratch[i - size]).max(scratch[i + size]);
            }
            if fill.is_finite() {
                map[i] = fill;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::{Material, Triangle};

    fn unit_box() -> Aabb {
        Aabb {
            min: Vec3::new(-0.5, 0.0, -0.5),
            max: Vec3::new(0.5, 1.0, 0.5),
        }
    }

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

    #[test]
    fn virtual_map_holds_the_depth_of_a_square_seen_from_above() {
        let b = unit_box();
        let f = ShadowFrustum::fit(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, &b, 64, 1.0).unwrap();
        let (y, h) = (1.0, 0.25);
        let v = [
            Vec3::new(-h, y, -h),
            Vec3::new(h, y, -h),
            Vec3::new(h, y, h),
            Vec3::new(-h, y, h),
        ];
        let tri = |a, b, c| Triangle {
            vertices: [a, b, c],
            normals: [Vec3::Y; 3],
            material: 0,
        };
        let scene = VirtualScene::new(
            vec![tri(v[0], v[1], v[2]), tri(v[0], v[2], v[3])],
            vec![Material::DIFFUSE_GRAY],
        );
        let mut map = vec![0.0; 64 * 64];
        virtual_shadow_map(&f, &scene, &mut map);
        let centre = f.texel(f.light_space(Vec3A::new(0.0, 0.0, 0.0))).unwrap();
        assert!((map[centre] - 4.0).abs() < 1e-4, "{}", map[centre]);
        let outside = f.texel(f.light_space(Vec3A::new(0.45, 0.0, 0.0))).unwrap();
        assert_eq!(map[outside], f32::INFINITY);
        // Covered texels: the square's share of the map, (0.5 / 4) / (2 tan) squared.
        let covered = map.iter().filter(|z| z.is_finite()).count() as f32;
        let expected = (0.5 / 4.0 / (2.0 * f.tan_half) * 64.0).powi(2);
        assert!(
            (covered - expected).abs() < 0.1 * expected,
            "{covered} vs {expected}"
        );
    }

    #[test]
    fn real_map_keeps_the_nearest_point_and_closes_single_holes() {
        let b = unit_box();
        let f = ShadowFrustum::fit(Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, &b, 32, 1.0).unwrap();
        // A floor sampled at every texel except one column, a nearer point above it, a
        // point of the light's own ceiling (nearer than real_from) and a NaN.
        let mut points = Vec::new();
        let texel_width = f.footprint(5.0);
        for k in 0..32 {
            for i in 0..32 {
                if i == 10 {
                    points.push(Vec3A::NAN);
                    continue;
                }
                let x = (i as f32 - 15.5) * texel_width;
                let z = (k as f32 - 15.5) * texel_width;
                points.push(Vec3A::new(x, 0.0, z));
            }
        }
        points.push(Vec3A::new(0.01, 0.5, 0.01));
        points.push(Vec3A::new(0.0, 4.9, 0.0));
        let width = points.len();
        let tiles = [tile_of(&points, width, 0, width, 0, 1)];
        let (mut map, mut scratch) = (vec![0.0; 32 * 32], vec![0.0; 32 * 32]);
        // Points of negligible footprint: one texel each.
        let sampling = PointSampling {
            origin: Vec3A::new(0.0, 5.0, 0.0),
            pixel_angle: 1e-4,
        };
        let patches = |points: &[Vec3A], sampling: PointSampling| -> Vec<f32> {
            points.iter().map(|p| sampling.footprint(*p)).collect()
        };
        let fine = patches(&points, sampling);
        real_shadow_map(&f, &points, &fine, width, &tiles, &mut map, &mut scratch);
        let at = |p: Vec3A| map[f.texel(f.light_space(p)).unwrap()];
        assert!(
            (at(Vec3A::new(0.01, 0.0, 0.01)) - 4.5).abs() < 1e-5,
            "the point above wins"
        );
        assert!((at(Vec3A::new(0.3, 0.0, 0.3)) - 5.0).abs() < 1e-5);
        let hole = Vec3A::new((10.0 - 15.5) * texel_width, 0.0, 0.0);
        assert!(
            (at(hole) - 5.0).abs() < 1e-5,
            "the missing column is closed"
        );
        assert!(
            map.iter().all(|&z| z >= 4.5),
            "the ceiling point is not an occluder"
        );
        // Coarse points cover the texels around them: every fourth point of each row
        // still closes the map.
        let sparse: Vec<Vec3A> = points[..32 * 32].iter().step_by(4).copied().collect();
        let tiles = [tile_of(&sparse, sparse.len(), 0, sparse.len(), 0, 1)];
        let coarse = PointSampling {
            pixel_angle: 4.0 * texel_width / 5.0,
            ..sampling
        };
        real_shadow_map(
            &f,
            &sparse,
            &patches(&sparse, coarse),
            sparse.len(),
            &tiles,
            &mut map,
            &mut scratch,
        );
        let inner = (4..28).flat_map(|y| (4..28).map(move |x| y * 32 + x));
        assert!(
            inner.clone().all(|t| (map[t] - 5.0).abs() < 1e-5),
            "no holes"
        );
    }
}
