//! Virtual objects: triangle meshes with materials, placed in world space, and ray
//! queries against them.

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
    /// Index into [`VirtualScene::materials`].
    pub material: u32,
}

/// Where a ray met a virtual object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VirtualHit {
    /// Ray parameter (metres for a unit direction).
    pub t: f32,
    pub position: Vec3,
    /// Unit shading normal, flipped to face the ray's origin.
    pub normal: Vec3,
    pub material: Material,
    /// Index of the triangle hit.
    pub triangle: u32,
}

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
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

/// The virtual objects of a pipeline, in world space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VirtualScene {
    pub triangles: Vec<Triangle>,
    pub materials: Vec<Material>,
}

impl VirtualScene {
    /// True when there is nothing to hit.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The bounding box of every triangle ([`Aabb::EMPTY`] when empty).
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for t in &self.triangles {
            for v in t.vertices {
                b.grow(v);
            }
        }
        b
    }

    /// The nearest hit along `origin + t dir` with t in (t_min, t_max).
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<VirtualHit> {
        self.intersect_brute_force(origin, dir, t_min, t_max)
    }

    /// True when anything is hit with t in (t_min, t_max).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        self.intersect(origin, dir, t_min, t_max).is_some()
    }

    /// [`VirtualScene::intersect`] by testing every triangle (the reference for tests).
    pub fn intersect_brute_force(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<VirtualHit> {
        let mut best: Option<(f32, u32, f32, f32)> = None;
        let mut limit = t_max;
        for (i, tri) in self.triangles.iter().enumerate() {
            if let Some((t, u, v)) = ray_triangle(origin, dir, &tri.vertices, t_min, limit) {
                limit = t;
                best = Some((t, i as u32, u, v));
            }
        }
        best.map(|(t, i, u, v)| self.hit_record(origin, dir, t, i, u, v))
    }

    /// The hit record of triangle `index` at barycentrics (u, v).
    pub fn hit_record(
        &self,
        origin: Vec3,
        dir: Vec3,
        t: f32,
        index: u32,
        u: f32,
        v: f32,
    ) -> VirtualHit {
        let tri = &self.triangles[index as usize];
        let n = (tri.normals[0] * (1.0 - u - v) + tri.normals[1] * u + tri.normals[2] * v)
            .normalize_or(tri_normal(&tri.vertices));
        let normal = if n.dot(dir) > 0.0 { -n } else { n };
        VirtualHit {
            t,
            position: origin + dir * t,
            normal,
            material: self.materials[tri.material as usize],
            triangle: index,
        }
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
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - v[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let w = dir.dot(q) * inv;
    if w < 0.0 || u + w > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t > t_min && t < t_max).then_some((t, u, w))
}
