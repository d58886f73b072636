//! Virtual objects: triangle meshes with materials, placed in world space, and ray
//! queries against them through a BVH (the design guide's "Virtual objects"; paper 001
//! Sec. 3 for the diffuse albedo k_V and Phong exponent of the differential composite).
//!
//! # `[[object]]` in pipeline configs
//!
//! A pipeline file lists its virtual objects as top-level `[[object]]` tables; they are
//! built into one [`VirtualScene`] when the pipeline loads (`Pipeline.objects`, handed
//! to every stage as `BuildContext.objects`). A pipeline without objects has an empty
//! scene. World coordinates are those of the recording's poses, in metres; in the
//! synthetic room y is up, the floor is y = 0 and (0, 0.3, 0) is free.
//!
//! ```toml
//! [[object]]
//! name = "torus"                 # optional, names it in messages; default: the shape
//! shape = "torus"                # sphere | box | torus | quad | mesh
//! major_radius = 0.25            # shape keys, see below
//! minor_radius = 0.08
//! translation = [0.0, 0.08, 0.0] # world position of the shape's origin; default 0
//! rotation_deg = [0.0, 0.0, 0.0] # about world x, then y, then z: R = Rz Ry Rx
//! scale = 1.0                    # uniform
//! albedo = [0.8, 0.3, 0.2]       # diffuse k_V in [0, 1]; default 0.7 gray
//! exponent = 0                   # Phong exponent; 0 = diffuse (default)
//! ```
//!
//! A point p of the shape lands at `translation + R (scale p)`, in world coordinates,
//! or in an anchor's frame on a real surface of the recording ([`anchor`]):
//!
//! ```toml
//! anchor = "floor"               # on the floor found in frames `frame`..`frame`+5
//! at_pixel = [410, 300]          # where this color pixel of frame `frame` sees it
//! frame = 0                      # (at_pixel alone: the surface seen at that pixel)
//! ```
//!
//! Shapes are centred on their origin with y up (meshes keep the file's origin):
//!
//! | shape | keys (defaults) | triangles |
//! |---|---|---|
//! | `sphere` | `radius` (0.25), `segments` (48; half as many rings) | 2 s (s/2 - 1): 2208 |
//! | `box` | `size` = [x, y, z] ([0.3, 0.3, 0.3]), flat normals | 12 |
//! | `torus` | `major_radius` (0.25), `minor_radius` (0.08), `segments` (64), `minor_segments` (32); ring in the xz plane, shadows itself | 2 s m: 4096 |
//! | `quad` | `size` = [x, z] ([1, 1]); in the xz plane facing +y | 2 |
//! | `mesh` | `path` to a Wavefront OBJ file, relative to the pipeline file's directory; file normals when every corner has one, else area-weighted smooth normals; MTL files are ignored | as in the file |
//!
//! Every key is checked when the pipeline loads: unknown keys (with the closest
//! spelling), unknown shapes, wrong types, values out of range, a torus whose tube is
//! wider than its ring, duplicate names, and mesh files that cannot be read or hold no
//! valid triangles are errors with the file, line and column of the offending value.
//! Anchored objects are placed when a run opens its recording
//! (`relume_stages::world::place_objects`); a pixel outside the images, a frame
//! past the end, no floor, or no surface at the pixel is an error at the key that asked.
//! `relume objects` lists every key. The same objects can be built in code with
//! [`ObjectSpec`] and [`VirtualScene::from_specs`].

pub mod anchor;
pub mod bvh;
pub mod mesh;
mod obj_lines;
pub mod shapes;
pub mod spec;
pub mod voxelize;

pub use bvh::Bvh;
pub use mesh::{load_obj, parse_obj};
pub use spec::{MAX_TRANSLATION, MAX_WORLD_COORDINATE, ObjectError, ObjectSpec, Shape};

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
/// (t, u, v) of the hit at any t. [`ray_triangle`] and the [`Bvh`] (which stores the
/// edges) both call it, so they give bit-identical t, u and v.
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
