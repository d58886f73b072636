//! Screen-space ray tracing against real geometry (paper 001 Sec. 5): rays are
//! intersected with the current frame's depth map, which stands for the real scene.

use crate::pinhole::Pinhole;
use crate::raster::{DepthImage, depth_is_valid};
use glam::{Affine3A, Vec3};

/// Where a world ray met the real surface of the depth map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RealHit {
    /// Ray parameter (metres along a unit direction).
    pub t: f32,
    /// The pixel whose surface was hit.
    pub pixel: (u32, u32),
}

/// Settings of the screen-space tracer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceParams {
    /// A ray is behind the surface (a hit) when it is deeper than the depth map by at
    /// most this much, in metres: surfaces are this thick.
    pub thickness: f32,
    /// Pixels skipped at the start of the march, so a ray does not hit its own surface.
    pub skip_pixels: f32,
}

impl Default for TraceParams {
    fn default() -> Self {
        TraceParams {
            thickness: 0.1,
            skip_pixels: 1.5,
        }
    }
}

/// Traces world-space rays against one depth map seen from one camera.
pub struct ScreenTracer<'a> {
    depth: &'a DepthImage,
    camera: Pinhole,
    world_to_camera: Affine3A,
    params: TraceParams,
}

impl<'a> ScreenTracer<'a> {
    /// A tracer over `depth` (metres, 0 = missing) seen by `camera` placed by
    /// `camera_to_world`.
    pub fn new(
        depth: &'a DepthImage,
        camera: Pinhole,
        camera_to_world: Affine3A,
        params: TraceParams,
    ) -> Self {
        ScreenTracer {
            depth,
            camera,
            world_to_camera: camera_to_world.inverse(),
            params,
        }
    }

    /// The first real surface along `origin + t dir` (world, `dir` unit) with t < t_max,
    /// or `None` when the ray leaves the image or the depth map has no surface there.
    pub fn trace(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<RealHit> {
        let o = self.world_to_camera.transform_point3(origin);
        let d = self.world_to_camera.transform_vector3(dir);
        let near = 1e-3;
        // Clip the segment to z >= near.
        let mut t_end = t_max;
        if d.z < 0.0 {
            t_end = t_end.min((near - o.z) / d.z);
        }
        if o.z < near || t_end <= 0.0 || !t_end.is_finite() {
            return None;
        }
        let start = self.camera.project(o)?;
        let end_point = o + d * t_end;
        let end = self.camera.project(end_point)?;
        let span = (end - start).abs().max_element();
        let steps = span.ceil().max(1.0) as u32;
        let inv_z0 = 1.0 / o.z;
        let inv_z1 = 1.0 / end_point.z;
        let first = (self.params.skip_pixels.ceil() as u32).min(steps);
        for i in first..=steps {
            let f = i as f32 / steps as f32;
            let p = start + (end - start) * f;
            let (u, v) = ((p.x + 0.5) as i32, (p.y + 0.5) as i32);
            if p.x < -0.5
                || p.y < -0.5
                || u >= self.camera.width as i32
                || v >= self.camera.height as i32
            {
                return None;
            }
            let ray_z = 1.0 / (inv_z0 + (inv_z1 - inv_z0) * f);
            let surface = *self.depth.at(u as u32, v as u32);
            if depth_is_valid(surface)
                && ray_z >= surface
                && ray_z - surface <= self.params.thickness
            {
                // Recover t from the camera-space depth along the ray.
                let t = if d.z.abs() > 1e-6 {
                    (ray_z - o.z) / d.z
                } else {
                    t_end * f
                };
                return Some(RealHit {
                    t: t.max(0.0),
                    pixel: (u as u32, v as u32),
                });
            }
        }
        None
    }
}
