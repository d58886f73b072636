//! Splatting the environment-sample cloud into a view with a depth test (paper 000
//! Sec. 3, "G-Buffer as AR basis"): every sample covers a disk of world radius r (a
//! screen ellipse of radii f r / z pixels, clamped), each covered pixel takes the depth of
//! the sample's tangent plane along its view ray, and the nearest sample wins.
//!
//! The depth test runs in parallel over samples with one `AtomicU64` per pixel holding
//! (depth bits << 32 | sample index): `fetch_min` keeps the nearest sample and breaks
//! ties by the lower index, whatever the order the threads arrive in.

use super::{COVERAGE_NONE, COVERAGE_SPLAT, GBuffer};
use crate::graph::{EnvCloud, StageError};
use crate::pinhole::Pinhole;
use crate::recording::Pose;
use glam::{Mat3, Mat4, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Samples nearer to the camera than this (metres) are not splatted.
pub const NEAR_M: f32 = 0.01;
/// The smallest screen radius in pixels: a little more than sqrt(1/2), so that the disk
/// always contains the nearest pixel centre and every sample in view covers a pixel.
pub const MIN_RADIUS_PX: f32 = 0.75;
/// Below this cosine between the normal and the view direction a splat is drawn at the
/// sample's own depth instead of along its tangent plane.
pub const GRAZING_COS: f32 = 0.25;
/// Tangent-plane depths are clamped to the sample depth +- this many splat radii.
pub const PLANE_DEPTH_SPAN: f32 = 3.0;

const EMPTY_KEY: u64 = u64::MAX;
const SAMPLES_PER_TASK: usize = 4096;

/// Parameters of [`splat`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplatParams {
    /// World-space radius of a sample's disk, metres.
    pub radius: f32,
    /// Upper bound of the screen radius, pixels (bounds the cost of very near samples).
    pub max_radius_px: f32,
}

impl Default for SplatParams {
    fn default() -> Self {
        SplatParams {
            radius: 0.035,
            max_radius_px: 64.0,
        }
    }
}

/// The per-pixel depth-test keys, kept across frames to avoid reallocation.
#[derive(Debug, Default)]
pub struct SplatBuffer {
    keys: Vec<AtomicU64>,
}

/// Splats `cloud` (world space) into the view of `camera` at `pose` (camera-to-world),
/// overwriting every pixel of `out`: the nearest sample's color, its tangent-plane depth
/// and its normal turned into camera space and towards the camera, coverage
/// [`COVERAGE_SPLAT`]; pixels no sample covers get NaN color, depth 0, a zero normal and
/// coverage [`COVERAGE_NONE`]. Samples with a non-finite position or color are skipped.
pub fn splat(
    cloud: &EnvCloud,
    pose: &Pose,
    camera: &Pinhole,
    params: &SplatParams,
    buffer: &mut SplatBuffer,
    out: &mut GBuffer,
) -> Result<(), StageError> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    if (out.width(), out.height()) != (camera.width, camera.height) || !out.is_consistent() {
        return Err(StageError::Failed(format!(
            "G-buffer is {}x{}, camera is {w}x{h}",
            out.width(),
            out.height()
        )));
    }
    let n = cloud.len();
    if cloud.colors.len() != n || cloud.normals.len() != n {
        return Err(StageError::Failed(format!(
            "cloud has {n} positions, {} colors and {} normals",
            cloud.colors.len(),
            cloud.normals.len()
        )));
    }
    if n > u32::MAX as usize {
        return Err(StageError::Failed(format!(
            "cloud of {n} samples is too large to splat"
        )));
    }
    if !(params.radius.is_finite() && params.radius >= 0.0 && params.max_radius_px.is_finite()) {
        return Err(StageError::Failed(
            "splat radius must be finite and >= 0".into(),
        ));
    }
    let keys = &mut buffer.keys;
    if keys.len() != w * h {
        *keys = (0..w * h).map(|_| AtomicU64::new(EMPTY_KEY)).collect();
    } else {
        keys.par_iter_mut()
            .with_min_len(1 << 14)
            .for_each(|k| *k.get_mut() = EMPTY_KEY);
    }
    let world_to_camera = pose.matrix().inverse().as_mat4();
    let rotation = Mat3::from_mat4(world_to_camera);
    if w > 0 && h > 0 {
        let raster = Raster {
            camera,
            keys,
            world_to_camera,
            rotation,
            radius: params.radius,
            max_radius_px: params.max_radius_px.max(MIN_RADIUS_PX),
        };
        cloud
            .positions
            .par_chunks(SAMPLES_PER_TASK)
            .zip(cloud.normals.par_chunks(SAMPLES_PER_TASK))
            .zip(cloud.colors.par_chunks(SAMPLES_PER_TASK))
            .enumerate()
            .for_each(|(task, ((positions, normals), colors))| {
                let first = task * SAMPLES_PER_TASK;
                for (j, ((p, nrm), c)) in positions.iter().zip(normals).zip(colors).enumerate() {
                    if c.is_finite() {
                        raster.splat_one(*p, *nrm, (first + j) as u32);
                    }
                }
            });
    }
    resolve(cloud, camera, &rotation, keys, out);
    Ok(())
}

/// What one sample's rasterization needs.
struct Raster<'a> {
    camera: &'a Pinhole,
    keys: &'a [AtomicU64],
    world_to_camera: Mat4,
    rotation: Mat3,
    radius: f32,
    max_radius_px: f32,
}

impl Raster<'_> {
    /// Depth-tests sample `index` at world position `world` with world normal `normal`
    /// into every pixel centre inside its screen ellipse.
    #[inline]
    fn splat_one(&self, world: Vec3, normal: Vec3, index: u32) {
        let cam = self.camera;
        let p = self.world_to_camera.transform_point3(world);
        if !p.is_finite() || p.z <= NEAR_M {
            return;
        }
        let inv_z = 1.0 / p.z;
        let (u, v) = (cam.fx * p.x * inv_z + cam.cx, cam.fy * p.y * inv_z + cam.cy);
        let rx = (cam.fx * self.radius * inv_z).clamp(MIN_RADIUS_PX, self.max_radius_px);
        let ry = (cam.fy * self.radius * inv_z).clamp(MIN_RADIUS_PX, self.max_radius_px);
        let (w, h) = (cam.width as f32, cam.height as f32);
        let (top, bottom) = ((v - ry).ceil().max(0.0), (v + ry).floor().min(h - 1.0));
        // All finite here: p is finite and the radii are clamped.
        if top > bottom || u + rx < 0.0 || u - rx > w - 1.0 {
            return;
        }
        // Depth along pixel (x, y)'s ray on the tangent plane n . X = n . p:
        // z = (n . p) / (n . ray(x, y)), and n . ray(x, y) = a x + b y + c.
        let n = self.rotation * normal;
        let n_len = n.length();
        let n_dot_p = n.dot(p);
        let tangent = n_len > 0.0 && n_dot_p.abs() >= GRAZING_COS * n_len * p.length();
        let (a, b, c) = (
            n.x / cam.fx,
            n.y / cam.fy,
            n.z - n.x * cam.cx / cam.fx - n.y * cam.cy / cam.fy,
        );
        let span = PLANE_DEPTH_SPAN * self.radius;
        let (near, far) = ((p.z - span).max(NEAR_M), p.z + span);
        let low_index = index as u64;
        let flat_key = ((p.z.to_bits() as u64) << 32) | low_index;
        let width = cam.width as usize;
        let inv_ry2 = 1.0 / (ry * ry);
        for y in top as usize..=bottom as usize {
            let dy = y as f32 - v;
            let half = rx * (1.0 - dy * dy * inv_ry2).max(0.0).sqrt();
            let (left, right) = ((u - half).ceil().max(0.0), (u + half).floor().min(w - 1.0));
            if left > right {
                continue;
            }
            let (left, right) = (left as usize, right as usize);
            let row = &self.keys[y * width + left..=y * width + right];
            let row_term = b * y as f32 + c;
            for (k, slot) in row.iter().enumerate() {
                let key = if tangent {
                    let z = n_dot_p / (a * (left + k) as f32 + row_term);
                    // NaN and negative depths (ray past the plane's horizon) fall to `near`.
                    let z = if z <= far { z.max(near) } else { far };
                    ((z.to_bits() as u64) << 32) | low_index
                } else {
                    flat_key
                };
                if key < slot.load(Relaxed) {
                    slot.fetch_min(key, Relaxed);
                }
            }
        }
    }
}

/// Turns the winning keys into the G-buffer.
fn resolve(
    cloud: &EnvCloud,
    camera: &Pinhole,
    rotation: &Mat3,
    keys: &[AtomicU64],
    out: &mut GBuffer,
) {
    let w = camera.width.max(1) as usize;
    out.color
        .data
        .par_chunks_mut(w)
        .zip(out.depth.data.par_chunks_mut(w))
        .zip(out.normals.data.par_chunks_mut(w))
        .zip(out.coverage.data.par_chunks_mut(w))
        .zip(keys.par_chunks(w))
        .enumerate()
        .for_each(|(y, ((((color, depth), normals), coverage), keys))| {
            for (x, key) in keys.iter().enumerate() {
                let key = key.load(Relaxed);
                if key == EMPTY_KEY {
                    color[x] = Vec3::NAN;
                    depth[x] = 0.0;
                    normals[x] = Vec3::ZERO;
                    coverage[x] = COVERAGE_NONE;
                    continue;
                }
                let i = (key & 0xffff_ffff) as usize;
                let n = (*rotation * cloud.normals[i]).normalize_or_zero();
                let ray = camera.ray(x as f32, y as f32);
                color[x] = cloud.colors[i];
                depth[x] = f32::from_bits((key >> 32) as u32);
                normals[x] = if n.dot(ray) > 0.0 { -n } else { n };
                coverage[x] = COVERAGE_SPLAT;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::Intrinsics;
    use glam::{DQuat, DVec3};

    fn camera() -> Pinhole {
        Pinhole::new(&Intrinsics::PRIMESENSE, 160, 120)
    }

    /// Samples on a 5 cm grid over the plane n . X = n . X0 around X0 (camera space of
    /// `pose`), returned in world space.
    fn plane_cloud(pose: &Pose, centre: Vec3, normal: Vec3, half_extent: f32) -> EnvCloud {
        let m = pose.matrix().as_mat4();
        let tangent = normal.any_orthonormal_vector();
        let bitangent = normal.cross(tangent);
        let steps = (half_extent / 0.05) as i32;
        let mut cloud = EnvCloud::default();
        for i in -steps..=steps {
            for j in -steps..=steps {
                let p = centre + tangent * (i as f32 * 0.05) + bitangent * (j as f32 * 0.05);
                cloud.positions.push(m.transform_point3(p));
                cloud.colors.push(Vec3::new(0.25, 0.5, (i + j) as f32));
                cloud.normals.push(m.transform_vector3(-normal));
            }
        }
        cloud
    }

    fn splat_all(cloud: &EnvCloud, pose: &Pose, params: &SplatParams) -> GBuffer {
        let cam = camera();
        let mut out = GBuffer::new(cam.width, cam.height);
        splat(
            cloud,
            pose,
            &cam,
            params,
            &mut SplatBuffer::default(),
            &mut out,
        )
        .unwrap();
        out
    }

    #[test]
    fn a_tilted_plane_splats_to_its_exact_depth_and_normal() {
        let pose = Pose::from_parts(DVec3::new(1.0, 2.0, -0.5), DQuat::from_rotation_y(0.4));
        // The plane z = 2 + 0.4 x (camera space): normal (0.4, 0, -1) facing the camera.
        let normal = Vec3::new(-0.4, 0.0, 1.0).normalize();
        let cloud = plane_cloud(&pose, Vec3::new(0.0, 0.0, 2.0), normal, 2.0);
        let out = splat_all(&cloud, &pose, &SplatParams::default());
        let cam = camera();
        let facing = -normal;
        let mut hits = 0;
        for y in 30..90 {
            for x in 40..120 {
                let i = y * 160 + x;
                if out.coverage.data[i] != COVERAGE_SPLAT {
                    continue;
                }
                hits += 1;
                let ray = cam.ray(x as f32, y as f32);
                let expected = 2.0 / (1.0 - 0.4 * ray.x);
                assert!((out.depth.data[i] - expected).abs() < 1e-4, "({x}, {y})");
                assert!((out.normals.data[i] - facing).length() < 1e-5);
                assert_eq!(out.color.data[i].x, 0.25);
            }
        }
        assert!(hits > 60 * 80 * 9 / 10, "most pixels are hit: {hits}");
    }

    #[test]
    fn the_nearest_sample_wins_and_covers_its_footprint() {
        let pose = Pose::IDENTITY;
        let mut cloud = EnvCloud::default();
        // Far sample first, near sample second, both on the optical axis; a third one
        // exactly as near as the second (tie: the lower index wins).
        for (z, tag) in [(3.0, 0.0), (1.0, 1.0), (1.0, 2.0)] {
            cloud.positions.push(Vec3::new(0.0, 0.0, z));
            cloud.colors.push(Vec3::splat(tag));
            cloud.normals.push(Vec3::Z);
        }
        let params = SplatParams {
            radius: 0.01,
            max_radius_px: 64.0,
        };
        let out = splat_all(&cloud, &pose, &params);
        // Both project to (79.5, 59.5). Near: radius 0.01 * 131.25 / 1 = 1.3 px; far:
        // 0.44 px, raised to 0.75. The 4 nearest centres lie at 0.71 px, the next 8 at
        // 1.58 px: both cover the same 4 pixels and the near one wins them all.
        for (x, y) in [(79, 59), (80, 59), (79, 60), (80, 60)] {
            let i = y * 160 + x;
            assert_eq!(out.depth.data[i], 1.0);
            assert_eq!(out.color.data[i], Vec3::splat(1.0), "tie: lower index");
            assert_eq!(
                out.normals.data[i],
                Vec3::NEG_Z,
                "turned towards the camera"
            );
        }
        let covered = out
            .coverage
            .data
            .iter()
            .filter(|&&c| c == COVERAGE_SPLAT)
            .count();
        assert_eq!(covered, 4);
        assert!(out.color.data[0].is_nan() && out.depth.data[0] == 0.0);
        assert_eq!(out.normals.data[0], Vec3::ZERO);
    }

    #[test]
    fn deterministic_for_any_thread_count() {
        let pose = Pose::from_parts(DVec3::new(0.1, 0.0, 0.0), DQuat::from_rotation_x(0.1));
        let mut cloud = plane_cloud(&pose, Vec3::new(0.0, 0.0, 2.0), Vec3::NEG_Z, 1.5);
        // A second, interpenetrating plane makes many exact and near ties.
        let other = plane_cloud(
            &pose,
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(0.3, 0.1, -1.0).normalize(),
            1.5,
        );
        cloud.positions.extend(&other.positions);
        cloud.colors.extend(&other.colors);
        cloud.normals.extend(&other.normals);
        let run = || splat_all(&cloud, &pose, &SplatParams::default());
        let a = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(run);
        let b = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap()
            .install(run);
        assert_eq!(a.bits(), b.bits());
    }

    #[test]
    fn empty_cloud_and_samples_behind_the_camera_leave_no_data() {
        let pose = Pose::IDENTITY;
        let mut cloud = EnvCloud::default();
        let out = splat_all(&cloud, &pose, &SplatParams::default());
        assert!(out.coverage.data.iter().all(|&c| c == COVERAGE_NONE));
        cloud.positions.push(Vec3::new(0.0, 0.0, -1.0));
        cloud.colors.push(Vec3::ONE);
        cloud.normals.push(Vec3::Z);
        cloud.positions.push(Vec3::new(0.0, 0.0, 1.0));
        cloud.colors.push(Vec3::NAN);
        cloud.normals.push(Vec3::Z);
        let out = splat_all(&cloud, &pose, &SplatParams::default());
        assert!(out.coverage.data.iter().all(|&c| c == COVERAGE_NONE));
        assert!(out.depth.data.iter().all(|&d| d == 0.0));
    }
}
