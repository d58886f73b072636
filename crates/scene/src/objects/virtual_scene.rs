//! The virtual objects of a pipeline as one scene in world space ([`VirtualScene`]): its
//! triangles and materials, the [`Bvh`] over them, and the ray queries that return a
//! [`VirtualHit`].

use super::bvh::Bvh;
use super::error::ObjectError;
use super::geometry::{Aabb, Material, Triangle, ray_triangle, tri_normal};
use super::spec::ObjectSpec;
use glam::Vec3;

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

/// The virtual objects of a pipeline, in world space.
///
/// Build it with [`VirtualScene::new`] (or [`VirtualScene::from_specs`]), which builds the
/// [`Bvh`] that [`VirtualScene::intersect`] and [`VirtualScene::occluded`] traverse. A
/// scene written as a struct literal with `bvh: Bvh::default()` (or `..Default::default()`)
/// still answers every query, by testing each triangle; so does one whose `triangles`
/// changed length after the build. After editing triangles in place, call
/// [`VirtualScene::rebuild`].
#[derive(Clone, Debug, Default)]
pub struct VirtualScene {
    pub triangles: Vec<Triangle>,
    pub materials: Vec<Material>,
    /// The hierarchy over `triangles` (empty when not built).
    pub bvh: Bvh,
}

/// Scenes are equal when their triangles and materials are: the BVH is derived data.
impl PartialEq for VirtualScene {
    fn eq(&self, other: &Self) -> bool {
        self.triangles == other.triangles && self.materials == other.materials
    }
}

impl VirtualScene {
    /// A scene of `triangles` (world space) whose `material` fields index `materials`,
    /// with its BVH built (deterministically: the same triangles give the same tree).
    pub fn new(triangles: Vec<Triangle>, materials: Vec<Material>) -> VirtualScene {
        let bvh = Bvh::build(&triangles);
        VirtualScene {
            triangles,
            materials,
            bvh,
        }
    }

    /// The scene of `specs` in world space: object k uses material k; BVH built.
    pub fn from_specs(specs: &[ObjectSpec]) -> Result<VirtualScene, ObjectError> {
        let mut triangles = Vec::new();
        let mut materials = Vec::with_capacity(specs.len());
        for (k, spec) in specs.iter().enumerate() {
            triangles.extend(spec.world_triangles(k as u32)?);
            materials.push(spec.material);
        }
        Ok(VirtualScene::new(triangles, materials))
    }

    /// Rebuilds the BVH after `triangles` were edited.
    pub fn rebuild(&mut self) {
        self.bvh = Bvh::build(&self.triangles);
    }

    /// The BVH when it was built for the current triangles.
    fn hierarchy(&self) -> Option<&Bvh> {
        self.bvh
            .is_built_for(self.triangles.len())
            .then_some(&self.bvh)
    }

    /// True when there is nothing to hit.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The bounding box of every triangle ([`Aabb::EMPTY`] when empty); kept by the BVH,
    /// so it costs nothing per call once built.
    pub fn bounds(&self) -> Aabb {
        if let Some(bvh) = self.hierarchy() {
            return bvh.bounds();
        }
        let mut b = Aabb::EMPTY;
        for t in &self.triangles {
            for v in t.vertices {
                b.grow(v);
            }
        }
        b
    }

    /// The nearest hit along `origin + t dir` with t in (t_min, t_max), through the BVH.
    /// Of hits at exactly the same t, the triangle with the smaller index wins, as in
    /// [`VirtualScene::intersect_brute_force`], so both give identical records.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<VirtualHit> {
        match self.hierarchy() {
            Some(bvh) => bvh
                .nearest(origin, dir, t_min, t_max)
                .map(|(t, i, u, v)| self.hit_record(origin, dir, t, i, u, v)),
            None => self.intersect_brute_force(origin, dir, t_min, t_max),
        }
    }

    /// True when anything is hit with t in (t_min, t_max) (any-hit traversal: stops at
    /// the first triangle found).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        match self.hierarchy() {
            Some(bvh) => bvh.any_hit(origin, dir, t_min, t_max),
            None => self.occluded_brute_force(origin, dir, t_min, t_max),
        }
    }

    /// [`VirtualScene::occluded`] by testing every triangle (the reference for tests).
    pub fn occluded_brute_force(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        self.triangles
            .iter()
            .any(|tri| ray_triangle(origin, dir, &tri.vertices, t_min, t_max).is_some())
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
            material: self
                .materials
                .get(tri.material as usize)
                .copied()
                .unwrap_or(Material::DIFFUSE_GRAY),
            triangle: index,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::spec::Shape;

    #[test]
    fn materials_follow_the_objects() {
        let mut a = ObjectSpec::new("a", Shape::DEFAULT_BOX);
        a.material.albedo = Vec3::new(0.8, 0.3, 0.2);
        let mut b = ObjectSpec::new("b", Shape::DEFAULT_SPHERE);
        b.translation = Vec3::new(0.0, 2.0, 0.0);
        b.material.exponent = 20.0;
        let scene = VirtualScene::from_specs(&[a, b]).unwrap();
        assert_eq!(scene.triangles.len(), 12 + 2208);
        assert_eq!(scene.materials.len(), 2);
        let down = Vec3::NEG_Y;
        let hit = scene
            .intersect(Vec3::new(0.01, 5.0, 0.02), down, 0.0, 10.0)
            .unwrap();
        assert_eq!(hit.material.exponent, 20.0);
        let surface = (0.25f32 * 0.25 - 0.01 * 0.01 - 0.02 * 0.02).sqrt();
        assert!((hit.t - (3.0 - surface)).abs() < 1e-3, "{}", hit.t);
        let hit = scene
            .intersect(Vec3::new(0.05, 1.0, 0.02), down, 0.0, 10.0)
            .unwrap();
        assert_eq!(hit.material.albedo, Vec3::new(0.8, 0.3, 0.2));
        assert!((hit.t - 0.85).abs() < 1e-6);
    }

    #[test]
    fn no_specs_make_an_empty_scene_and_a_bad_spec_fails_it() {
        assert!(VirtualScene::from_specs(&[]).unwrap().is_empty());
        let mut bad = ObjectSpec::new("s", Shape::DEFAULT_SPHERE);
        bad.scale = 0.0;
        let e =
            VirtualScene::from_specs(&[ObjectSpec::new("b", Shape::DEFAULT_BOX), bad]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "object `s`: scale must be positive and finite, got 0"
        );
    }
}
