//! The per-pixel pass of `sample.val`: which surface the pixel shows (real point from
//! the depth map, or the virtual hit at the pixel centre) and its shading.

use super::ValInputs;
use super::raster::NO_ID;
use super::shade::{Biases, Maps, PreparedLight, Sh9Irradiance, shade_point};
use super::shadow::{PointSampling, TILE};
use crate::objects::ray_triangle;
use crate::raster::depth_is_valid;
use glam::{Vec3, Vec3A};

/// How the camera sampled the real points.
pub(super) fn sampling_of(inputs: &ValInputs) -> PointSampling {
    PointSampling {
        origin: inputs.camera_to_world.translation,
        pixel_angle: 1.0 / inputs.camera.fx.abs().min(inputs.camera.fy.abs()),
    }
}

/// Everything the per-pixel pass reads.
pub(super) struct PixelContext<'a> {
    pub(super) inputs: &'a ValInputs<'a>,
    pub(super) real_points: &'a [Vec3A],
    pub(super) real_normals: &'a [Vec3A],
    pub(super) lookup: &'a [u64],
    pub(super) tiles_per_row: usize,
    pub(super) ids: &'a [u32],
    pub(super) lights: &'a [PreparedLight],
    pub(super) maps: Maps<'a>,
    pub(super) biases: Biases,
    pub(super) sh: Sh9Irradiance,
    pub(super) sampling: PointSampling,
}

/// One pixel's outputs.
pub(super) struct PixelOut {
    pub(super) e_r_dir: Vec3,
    pub(super) e_r_ind: Vec3,
    pub(super) e_rv_dir: Vec3,
    pub(super) e_rv_ind: Vec3,
    pub(super) mask: f32,
    pub(super) k_v: Vec3,
    pub(super) position: Vec3,
    pub(super) normal: Vec3,
    pub(super) direct_min_distance: f32,
}

impl PixelContext<'_> {
    #[inline]
    pub(super) fn pixel(&self, x: usize, y: usize) -> PixelOut {
        let w = self.inputs.depth.width as usize;
        let i = y * w + x;
        let real = self.real_points[i];
        let real_normal = self.real_normals[i];
        let real_ok = real.is_finite() && real_normal != Vec3A::ZERO;
        let real_shaded = real_ok.then(|| {
            let patch = self.sampling.footprint(real);
            let lookup = self.lookup[(y / TILE) * self.tiles_per_row + x / TILE];
            shade_point(
                real,
                real_normal,
                patch,
                lookup,
                self.lights,
                self.maps,
                self.biases,
            )
        });
        let mut out = PixelOut {
            e_r_dir: Vec3::NAN,
            e_r_ind: Vec3::NAN,
            e_rv_dir: Vec3::NAN,
            e_rv_ind: Vec3::NAN,
            mask: 1.0,
            k_v: Vec3::ZERO,
            position: real.into(),
            normal: real_normal.into(),
            direct_min_distance: f32::INFINITY,
        };
        if let Some(s) = real_shaded {
            let e_ind = self.sh.at(real_normal);
            out.e_r_dir = s.e_r;
            out.e_r_ind = e_ind;
            out.e_rv_dir = s.e_rv;
            out.e_rv_ind = e_ind;
            out.direct_min_distance = s.min_occluder;
        }
        let id = self.ids[i];
        if id == NO_ID {
            return out;
        }
        // The virtual surface at the pixel centre, if nearer than the real one.
        let c = self.inputs.camera;
        let ray = c.ray(x as f32, y as f32);
        let dir = self
            .inputs
            .camera_to_world
            .transform_vector3(ray)
            .normalize();
        let origin = Vec3::from(self.sampling.origin);
        let scene = self.inputs.objects;
        let tri = &scene.triangles[id as usize];
        let hit = match ray_triangle(origin, dir, &tri.vertices, 0.0, f32::INFINITY) {
            Some((t, u, v)) => Some(scene.hit_record(origin, dir, t, id, u, v)),
            // The raster and the ray test disagree at the very edge: ask the scene.
            None => scene.intersect(origin, dir, 0.0, f32::INFINITY),
        };
        let Some(hit) = hit else { return out };
        let z = self.inputs.depth.data[i];
        if depth_is_valid(z) && hit.t >= z * ray.length() {
            return out;
        }
        let n = Vec3A::from(hit.normal);
        let x = Vec3A::from(hit.position);
        let patch = self.sampling.footprint(x);
        // The objects lie inside every frustum: always look up.
        let s = shade_point(x, n, patch, u64::MAX, self.lights, self.maps, self.biases);
        out.e_rv_dir = s.e_rv;
        out.e_rv_ind = self.sh.at(n);
        out.mask = 0.0;
        out.k_v = hit.material.albedo;
        out.position = hit.position;
        out.normal = hit.normal;
        out.direct_min_distance = s.min_occluder;
        out
    }
}
