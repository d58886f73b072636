//! Bounding volumes of the virtual objects for `sample.path`'s pretests: the cone of
//! directions from a point that may meet the objects' bounding sphere, the bounding
//! box, and the pixels where a primary ray may meet them.

use super::inputs::PathInputs;
use glam::Vec3;
use relume_scene::objects::{Aabb, VirtualHit, VirtualScene};

/// Directions from a point that may meet the objects' bounding sphere: those within
/// the cone of half-angle asin(r / distance) about the direction to its centre.
#[derive(Clone, Copy, Debug)]
pub(super) struct Cone {
    pub axis: Vec3,
    pub cos_half: f32,
}

impl Cone {
    /// Every direction (the point is inside the sphere).
    pub const ALL: Cone = Cone {
        axis: Vec3::Z,
        cos_half: -2.0,
    };

    #[inline(always)]
    pub fn admits(&self, dir: Vec3) -> bool {
        self.axis.dot(dir) >= self.cos_half
    }
}

/// The virtual objects with their bounding volumes, for the pretests.
pub(super) struct Objects<'a> {
    pub scene: &'a VirtualScene,
    pub aabb: Aabb,
    pub center: Vec3,
    /// Squared radius of a sphere holding the box, inflated for rounding.
    pub radius2: f32,
}

impl Objects<'_> {
    /// The cone of directions from `p` that may meet the bounding sphere.
    #[inline]
    pub fn cone(&self, p: Vec3) -> Cone {
        let oc = self.center - p;
        let dist2 = oc.length_squared();
        if dist2.is_nan() || dist2 <= self.radius2 {
            return Cone::ALL;
        }
        let dist = dist2.sqrt();
        Cone {
            axis: oc / dist,
            // A margin of 1e-5 keeps the test conservative under rounding.
            cos_half: (1.0 - self.radius2 / dist2).sqrt() - 1e-5,
        }
    }

    /// The nearest object hit along `o + t d` with t < t_max, after the bounding-box
    /// pretest.
    #[inline]
    pub fn hit(&self, o: Vec3, d: Vec3, t_max: f32) -> Option<VirtualHit> {
        if !self.box_admits(o, d, t_max) {
            return None;
        }
        self.scene.intersect(o, d, 0.0, t_max)
    }

    /// The bounding-box pretest of [`Objects::hit`]: whether `o + t d` meets the box
    /// with t < t_max.
    #[inline]
    pub fn box_admits(&self, o: Vec3, d: Vec3, t_max: f32) -> bool {
        self.aabb.ray_span(o, d.recip(), 0.0, t_max).is_some()
    }
}

/// Pixels (inclusive bounds) whose footprint may show the box: the projected corners'
/// bounding rectangle grown by a pixel; the whole image when a corner is not in front
/// of the camera.
pub(super) fn object_pixel_bounds(inputs: &PathInputs, aabb: &Aabb) -> [i64; 4] {
    let (w, h) = (inputs.depth.width as i64, inputs.depth.height as i64);
    let all = [0, 0, w - 1, h - 1];
    let to_camera = inputs.camera_to_world.inverse();
    let (mut lo, mut hi) = (
        glam::Vec2::splat(f32::INFINITY),
        glam::Vec2::splat(f32::NEG_INFINITY),
    );
    for i in 0..8 {
        let corner = Vec3::new(
            if i & 1 == 0 { aabb.min.x } else { aabb.max.x },
            if i & 2 == 0 { aabb.min.y } else { aabb.max.y },
            if i & 4 == 0 { aabb.min.z } else { aabb.max.z },
        );
        let c = to_camera.transform_point3(corner);
        if c.z.is_nan() || c.z <= 1e-3 {
            return all;
        }
        let Some(uv) = inputs.camera.project(c) else {
            return all;
        };
        lo = lo.min(uv);
        hi = hi.max(uv);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return all;
    }
    let clamp = |v: f32, max: i64| (v as i64).clamp(-1, max + 1);
    [
        clamp(lo.x - 2.0, w),
        clamp(lo.y - 2.0, h),
        clamp(hi.x + 2.0, w),
        clamp(hi.y + 2.0, h),
    ]
}
