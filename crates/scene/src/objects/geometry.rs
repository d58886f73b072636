//! The geometry every object file shares: the [`Triangle`] and its [`Material`], the
//! axis-aligned box [`Aabb`], a triangle's normal, and the ray-triangle test that the
//! brute-force queries and the BVH both run.

use glam::Vec3;

/// The surface of a virtual object: diffuse when `exponent` is 0, Phong otherwise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Diffuse albedo k_V in [0, 1] per channel.
    pub albedo: Vec3,
    /// Phong exponent (0 = diffuse).
    pub exponent: f32,
}

impl Material {
    pub const DIFFUSE_GRAY: Material = Material {
        albedo: Vec3::splat(0.7),
        exponent: 0.0,
    };

    pub fn is_glossy(&self) -> bool {
        self.exponent > 0.0
    }
}

/// One world-space triangle with per-vertex normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    pub vertices: [Vec3; 3],
    /// Unit vertex normals (the geometric normal when the mesh has none).
    pub normals: [Vec3; 3],
    /// Index into [`VirtualScene::materials`](super::VirtualScene::materials).
    pub material: u32,
}

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

/// The empty box.
impl Default for Aabb {
    fn default() -> Self {
        Aabb::EMPTY
    }
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// The ray parameters where the ray enters and leaves the box, clipped to
    /// [t_min, t_max]; `None` when it misses.
    #[inline]
    pub fn ray_span(
        &self,
        origin: Vec3,
        inv_dir: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32)> {
        let t0 = (self.min - origin) * inv_dir;
        let t1 = (self.max - origin) * inv_dir;
        let near = t0.min(t1).max_element().max(t_min);
        let far = t0.max(t1).min_element().min(t_max);
        (near <= far).then_some((near, far))
    }
}

/// The unit geometric normal of a triangle (counter-clockwise front).
pub fn tri_normal(v: &[Vec3; 3]) -> Vec3 {
    (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero()
}

/// Moller-Trumbore: (t, u, v) of the hit with t in (t_min, t_max), both sides.
#[inline]
pub fn ray_triangle(
    origin: Vec3,
    dir: Vec3,
    v: &[Vec3; 3],
    t_min: f32,
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    let (t, u, w) = ray_triangle_edges(origin, dir, v[0], v[1] - v[0], v[2] - v[0])?;
    (t > t_min && t < t_max).then_some((t, u, w))
}

/// Moller-Trumbore on a triangle given as v0 and its edges e1 = v1 - v0, e2 = v2 - v0:
/// (t, u, v) of the hit at any t. [`ray_triangle`] and the [`Bvh`](super::Bvh) (which
/// stores the edges) both call it, so they give bit-identical t, u and v.
#[inline]
pub fn ray_triangle_edges(
    origin: Vec3,
    dir: Vec3,
    v0: Vec3,
    e1: Vec3,
    e2: Vec3,
) -> Option<(f32, f32, f32)> {
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - v0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let w = dir.dot(q) * inv;
    if w < 0.0 || u + w > 1.0 {
        return None;
    }
    Some((e2.dot(q) * inv, u, w))
}
