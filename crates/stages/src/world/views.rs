//! What the anchors need of a recorded frame: its depth in metres, the camera models of
//! its color and depth images, and its pose; and the surface samples of a frame in
//! world space for the floor.

use super::floor::SurfacePoint;
use glam::{Mat3, Vec2, Vec3};
use relume_base::pinhole::Pinhole;
use relume_base::raster::DepthImage;
use relume_recording::{Replay, codec};

/// One recorded frame as the anchors see it.
#[derive(Clone, Debug)]
pub struct CameraView {
    pub frame: usize,
    /// Metres; 0 where the sensor saw nothing.
    pub depth: DepthImage,
    pub depth_camera: Pinhole,
    pub color_camera: Pinhole,
    /// Camera-to-world rotation (camera x right, y down, z forward).
    pub rotation: Mat3,
    /// The camera's centre in the world.
    pub position: Vec3,
}

impl CameraView {
    /// Frame `n` of `replay`; an error saying why when it has no depth image or no
    /// pose (a missing pose is the identity where `identity_if_missing`: the first
    /// camera of a tracked world), or its records cannot be read.
    pub fn read(
        replay: &Replay,
        n: usize,
        identity_if_missing: bool,
    ) -> Result<CameraView, String> {
        let records = replay.read_frame(n).map_err(|e| e.to_string())?;
        let header = replay.recording.header();
        let Some(depth) = records.depth else {
            return Err(format!("frame {n} has no depth image"));
        };
        let pose = match records.pose {
            Some(pose) => pose,
            None if identity_if_missing => relume_recording::Pose::IDENTITY,
            None => {
                return Err(format!(
                    "frame {n} has no camera pose (it lies in a gap of the pose stream)"
                ));
            }
        };
        let depth = codec::decode_depth(&depth.image, header.depth_unit_m)
            .map_err(|e| format!("frame {n}'s depth image does not decode: {e}"))?;
        let (dk, ck) = (&header.depth_intrinsics, &header.color_intrinsics);
        Ok(CameraView {
            frame: n,
            depth_camera: Pinhole::new(dk, depth.width, depth.height),
            color_camera: Pinhole::new(ck, ck.width, ck.height),
            depth,
            rotation: glam::DMat3::from_quat(pose.rotation()).as_mat3(),
            position: pose.translation().as_vec3(),
        })
    }

    /// The camera-space view ray (z = 1) through color pixel `pixel`; depth and color
    /// are taken to share the camera's centre (registered, as every importer gives).
    pub fn color_ray(&self, pixel: Vec2) -> Vec3 {
        self.color_camera.ray(pixel.x, pixel.y)
    }

    /// The median of the valid depths (metres) in the 5 x 5 depth pixels around camera-
    /// space `ray`'s pixel, or `None` when it has none or falls outside the image.
    pub fn depth_near(&self, ray: Vec3) -> Option<f32> {
        let (u, v) = self.depth_camera.pixel_of(ray)?;
        let (w, h) = (self.depth.width, self.depth.height);
        let mut depths: Vec<f32> = (v.saturating_sub(2)..(v + 3).min(h))
            .flat_map(|y| (u.saturating_sub(2)..(u + 3).min(w)).map(move |x| (x, y)))
            .map(|(x, y)| self.depth.data[(y * w + x) as usize])
            .filter(|z| *z > 0.0 && z.is_finite())
            .collect();
        depths.sort_by(f32::total_cmp);
        depths.get(depths.len() / 2).copied()
    }

    /// The image's up direction in the world (camera y points down the image).
    pub fn up(&self) -> Vec3 {
        -self.rotation.y_axis
    }

    /// A camera-space point in the world.
    pub fn to_world(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.position
    }

    /// The depth samples on a grid of about 160 columns, in world space, with normals
    /// from the neighbouring samples a grid step away (central differences, crossed),
    /// turned towards the camera. Samples without all four neighbours, or across a
    /// depth step of more than 5 % plus 2 cm, are left out.
    pub fn surface_points(&self) -> Vec<SurfacePoint> {
        let (w, h) = (self.depth.width, self.depth.height);
        let step = (w / 160).max(1);
        let at = |u: u32, v: u32| {
            let z = self.depth.data[(v * w + u) as usize];
            (z > 0.0 && z.is_finite())
                .then(|| self.depth_camera.back_project(u as f32, v as f32, z))
        };
        let mut points = Vec::new();
        for v in (step..h.saturating_sub(step)).step_by(step as usize) {
            for u in (step..w.saturating_sub(step)).step_by(step as usize) {
                let (Some(p), Some(l), Some(r), Some(t), Some(b)) = (
                    at(u, v),
                    at(u - step, v),
                    at(u + step, v),
                    at(u, v - step),
                    at(u, v + step),
                ) else {
                    continue;
                };
                let tolerance = 0.02 + 0.05 * p.z;
                if [l, r, t, b].iter().any(|q| (q.z - p.z).abs() > tolerance) {
                    continue;
                }
                let mut n = (r - l).cross(b - t).normalize_or_zero();
                if n == Vec3::ZERO {
                    continue;
                }
                if n.dot(p) > 0.0 {
                    n = -n;
                }
                points.push(SurfacePoint {
                    position: self.to_world(p),
                    normal: self.rotation * n,
                });
            }
        }
        points
    }
}
