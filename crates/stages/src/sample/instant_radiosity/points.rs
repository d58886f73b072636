//! The two point sets Differential Instant Radiosity stands on (paper 002 Secs. 3.3,
//! 3.7): the real surface seen by the camera (one point per depth pixel, in world space)
//! and points spread over the virtual meshes. Both feed the imperfect shadow maps
//! (each map splats its own sparse subset) and the VPL candidates.

use glam::{Affine3A, Vec3};
use rayon::prelude::*;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Vec3Image, depth_is_valid};
use relume_base::rng;
use relume_scene::objects::{Material, VirtualScene};

/// The real surface per pixel: world position (NaN: none), unit normal (zero: none)
/// and the area the pixel sees, and the list of pixels that have all three.
#[derive(Default)]
pub struct RealSurface {
    pub position: Vec<Vec3>,
    pub normal: Vec<Vec3>,
    /// Square metres of surface the pixel sees (facing the camera; z^2 / (fx fy)).
    pub area: Vec<f32>,
    /// Indices of the pixels with a position and a normal, in raster order.
    pub valid: Vec<u32>,
    /// Per valid pixel (as `valid`), its position and area side by side: the shadow
    /// maps' subsets read one cache line a point.
    valid_points: Vec<(Vec3, f32)>,
}

impl RealSurface {
    /// Fills the surface from a depth map (metres; 0 or non-finite: none) and its
    /// camera-space normals (zero: none).
    pub fn update(
        &mut self,
        depth: &DepthImage,
        normals: &Vec3Image,
        camera: Pinhole,
        camera_to_world: Affine3A,
    ) {
        let w = depth.width as usize;
        self.position.resize(depth.len(), Vec3::NAN);
        self.normal.resize(depth.len(), Vec3::ZERO);
        self.area.resize(depth.len(), 0.0);
        let pixel_area = 1.0 / (camera.fx * camera.fy);
        self.position
            .par_chunks_mut(w.max(1))
            .zip(self.normal.par_chunks_mut(w.max(1)))
            .zip(self.area.par_chunks_mut(w.max(1)))
            .enumerate()
            .for_each(|(y, ((positions, normals_out), areas))| {
                for x in 0..positions.len() {
                    let i = y * w + x;
                    let (z, n) = (depth.data[i], normals.data[i]);
                    let ok = depth_is_valid(z) && n != Vec3::ZERO && n.is_finite();
                    positions[x] = if ok {
                        camera_to_world.transform_point3(camera.back_project(x as f32, y as f32, z))
                    } else {
                        Vec3::NAN
                    };
                    areas[x] = if ok { z * z * pixel_area } else { 0.0 };
                    normals_out[x] = if ok {
                        camera_to_world.transform_vector3(n).normalize_or_zero()
                    } else {
                        Vec3::ZERO
                    };
                }
            });
        self.valid.clear();
        self.valid
            .extend((0..self.position.len() as u32).filter(|&i| {
                self.normal[i as usize] != Vec3::ZERO && self.position[i as usize].is_finite()
            }));
        self.valid_points.clear();
        self.valid_points.extend(
            self.valid
                .iter()
                .map(|&i| (self.position[i as usize], self.area[i as usize])),
        );
    }

    /// The `count` points of subset `key` of the valid pixels: every `n / count`-th
    /// one from an offset hashed from `key`, so different keys splat different points;
    /// each with the radius of the disc of surface it stands for (its pixel's area
    /// times the stride).
    pub fn subset(&self, count: usize, key: u64) -> impl Iterator<Item = (Vec3, f32)> + '_ {
        let n = self.valid.len();
        let share = n as f32 / count.min(n).max(1) as f32 / std::f32::consts::PI;
        strided(n, count, key).map(move |i| {
            let (position, area) = self.valid_points[i];
            (position, (area * share).sqrt())
        })
    }
}

/// Indices of a stratified subset of `count` of `0..n`: stride `n / count` (at least 1)
/// from an offset hashed from `key` (wrapping around).
pub fn strided(n: usize, count: usize, key: u64) -> impl Iterator<Item = usize> {
    let take = count.min(n);
    let stride = n.checked_div(take).unwrap_or(1);
    let offset = if n == 0 {
        0
    } else {
        (rng::mix64(key) % n as u64) as usize
    };
    // offset < n and k stride < n: one wrap at most.
    (0..take).map(move |k| {
        let i = offset + k * stride;
        if i >= n { i - n } else { i }
    })
}

/// Points spread uniformly by area over the virtual meshes (stratified over the
/// triangles' cumulative area), each with its normal and material; built once per stage
/// since the objects do not move.
#[derive(Clone, Debug, Default)]
pub struct MeshPoints {
    pub position: Vec<Vec3>,
    pub normal: Vec<Vec3>,
    pub material: Vec<Material>,
    /// Surface area each point stands for (square metres).
    pub area: f32,
}

impl MeshPoints {
    /// `count` points over `objects` (none when the scene is empty).
    pub fn new(objects: &VirtualScene, count: usize, seed: u64) -> MeshPoints {
        let areas: Vec<f64> = objects
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.vertices;
                0.5 * (b - a).cross(c - a).length() as f64
            })
            .collect();
        let total: f64 = areas.iter().sum();
        let mut out = MeshPoints::default();
        if total <= 0.0 || count == 0 || !total.is_finite() {
            return out;
        }
        out.area = (total / count as f64) as f32;
        let (mut tri, mut below) = (0usize, 0.0f64);
        for k in 0..count {
            let h = rng::hash(&[seed, 0xD1B0, k as u64]);
            let target = (k as f64 + rng::unit_f64(h)) / count as f64 * total;
            while tri + 1 < areas.len() && below + areas[tri] <= target {
                below += areas[tri];
                tri += 1;
            }
            let t = &objects.triangles[tri];
            let (mut u, mut v) = (
                rng::unit_f32(rng::mix64(h)),
                rng::unit_f32(rng::mix64(h ^ 0x5EED)),
            );
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let [a, b, c] = t.vertices;
            let w = 1.0 - u - v;
            out.position.push(a * w + b * u + c * v);
            let n = (t.normals[0] * w + t.normals[1] * u + t.normals[2] * v)
                .normalize_or(relume_scene::objects::tri_normal(&t.vertices));
            out.normal.push(n);
            out.material.push(
                objects
                    .materials
                    .get(t.material as usize)
                    .copied()
                    .unwrap_or(Material::DIFFUSE_GRAY),
            );
        }
        out
    }

    pub fn len(&self) -> usize {
        self.position.len()
    }

    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// The `count` points of subset `key` (see [`strided`]), each with the radius of
    /// the disc of surface it stands for.
    pub fn subset(&self, count: usize, key: u64) -> impl Iterator<Item = (Vec3, f32)> + '_ {
        let n = self.len();
        let radius =
            (self.area * n as f32 / count.min(n).max(1) as f32 / std::f32::consts::PI).sqrt();
        strided(n, count, key).map(move |i| (self.position[i], radius))
    }

    /// The centre and radius of a sphere around every point.
    pub fn bounding_sphere(&self) -> Option<(Vec3, f32)> {
        let first = *self.position.first()?;
        let (lo, hi) = self
            .position
            .iter()
            .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        let center = (lo + hi) * 0.5;
        let radius = self
            .position
            .iter()
            .map(|p| p.distance(center))
            .fold(0.0f32, f32::max);
        Some((center, radius))
    }
}
