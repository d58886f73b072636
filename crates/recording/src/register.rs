//! Depth registered to the color camera, for recordings whose depth comes from a camera of
//! its own (RealSense and Azure Kinect recordings: other intrinsics, another size, an
//! extrinsic between the two). Every stage of relume assumes depth in the color view, so
//! importers register once, here, and the recording stores registered depth.
//!
//! The depth map is taken as a surface: each depth pixel is back-projected with the depth
//! intrinsics and moved by the extrinsic into the color camera; each pair of triangles
//! between four neighbouring depth pixels is projected into the color image and
//! rasterized there, keeping the nearest surface at each color pixel (a z-buffer). Depth is
//! interpolated as 1/z, affine in image coordinates over a planar triangle, so a planar
//! surface registers exactly, at any ratio of the two resolutions and with no cracks
//! between triangles. A triangle whose corners step in depth more than a surface seen at
//! [`Registration::max_obliquity_deg`] would is an edge between two surfaces: it is
//! dropped, so depth is never smeared across edges. Inside such an edge triangle lies the
//! near surface's silhouette, unsampled: the near surface may reach anywhere across it.
//! Seen from the color camera's other viewpoint, that reach may hide the far surface
//! behind it, so the triangle is also drawn as an occluder at the depths the near surface
//! can have there, and a farther surface it covers is left a hole. Holes stay holes, and a color pixel the
//! depth camera did not see gets no depth.
//!
//! librealsense's `rs2::align` and the Azure Kinect SDK's
//! `k4a_transformation_depth_image_to_color_camera` do the same job by splatting each depth
//! pixel's footprint with its own depth, which is exact only on surfaces facing the
//! camera; the triangles here are exact on every plane.

use crate::lens::Distortion;
use glam::{DMat3, DQuat, DVec3};
use relume_base::pinhole::Intrinsics;

/// The rigid transform from the depth camera's frame to the color camera's (both in
/// optical convention: x right, y down, z forward): `X_color = rotation * X_depth +
/// translation`, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extrinsic {
    /// The rotation from depth camera axes to color camera axes.
    pub rotation: DQuat,
    /// The depth camera's origin in the color camera's frame, metres.
    pub translation: DVec3,
}

impl Extrinsic {
    /// The two cameras coincide.
    pub const IDENTITY: Extrinsic = Extrinsic {
        rotation: DQuat::IDENTITY,
        translation: DVec3::ZERO,
    };

    /// Whether points stay where they are (within a micrometre and a microradian).
    pub fn is_identity(&self) -> bool {
        self.translation.length() < 1e-6 && self.rotation.angle_between(DQuat::IDENTITY) < 1e-6
    }

    /// The transform that undoes this one.
    pub fn inverse(&self) -> Extrinsic {
        let rotation = self.rotation.inverse();
        Extrinsic {
            rotation,
            translation: -(rotation * self.translation),
        }
    }

    /// This transform after `first`: `self * first`.
    pub fn after(&self, first: &Extrinsic) -> Extrinsic {
        Extrinsic {
            rotation: self.rotation * first.rotation,
            translation: self.rotation * first.translation + self.translation,
        }
    }
}

/// How one recording's depth camera relates to its color camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Registration {
    /// The depth camera, at the depth images' size.
    pub depth: Intrinsics,
    /// The color camera, at the color images' size: the registered depth's.
    pub color: Intrinsics,
    /// The depth camera's lens distortion (`None`: a pinhole camera).
    pub depth_lens: Option<Distortion>,
    /// The color camera's lens distortion: registered depth lands on the color image's
    /// own (distorted) pixels.
    pub color_lens: Option<Distortion>,
    pub depth_to_color: Extrinsic,
    /// Surfaces seen more obliquely than this (degrees between the surface normal and the
    /// depth camera's ray) count as edges: 80, as a structured-light or time-of-flight
    /// camera measures little beyond it. Taken within 0 to 89 degrees.
    pub max_obliquity_deg: f64,
}

/// Why a registration cannot run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RegisterError {
    /// The depth image does not have the depth camera's size.
    #[error("the depth image is {got}, the depth camera's intrinsics say {want}")]
    DepthSize { got: String, want: String },
}

impl Registration {
    /// See [`Registration::max_obliquity_deg`].
    pub const DEFAULT_MAX_OBLIQUITY_DEG: f64 = 80.0;

    /// A registration with the default obliquity limit.
    pub fn new(depth: Intrinsics, color: Intrinsics, depth_to_color: Extrinsic) -> Self {
        Registration {
            depth,
            color,
            depth_lens: None,
            color_lens: None,
            depth_to_color,
            max_obliquity_deg: Self::DEFAULT_MAX_OBLIQUITY_DEG,
        }
    }

    /// Whether the depth is already in the color view: the same intrinsics, lens and
    /// size, and no extrinsic. Registering it would copy it.
    pub fn is_identity(&self) -> bool {
        self.depth == self.color
            && self.depth_lens == self.color_lens
            && self.depth_to_color.is_identity()
    }
}

/// Per-depth-pixel and per-color-pixel buffers, kept between frames.
#[derive(Default)]
pub struct Scratch {
    /// Each depth pixel in the color image: x, y, and 1/z in the color camera (0: none).
    projected: Vec<[f32; 3]>,
    /// Each depth pixel's own depth in metres (0: none).
    depth_m: Vec<f32>,
    /// The largest 1/z so far at each color pixel (the nearest surface).
    nearest: Vec<f32>,
    /// The largest 1/z of the edge triangles' corners covering each color pixel.
    edge_nearest: Vec<f32>,
    /// Each depth pixel's ray on the z = 1 plane (NaN: outside the lens's field), and the
    /// camera it was computed for.
    rays: Vec<[f32; 2]>,
    rays_for: Option<(Intrinsics, Option<Distortion>)>,
}

/// Registers `depth` (units of `unit_m`, 0 = no measurement, the depth camera's size)
/// into `out` (the color camera's size), in the same units; 0 where the depth camera saw
/// nothing.
pub fn register_depth(
    depth: &[u16],
    unit_m: f64,
    registration: &Registration,
    out: &mut Vec<u16>,
    scratch: &mut Scratch,
) -> Result<(), RegisterError> {
    let (dk, ck) = (&registration.depth, &registration.color);
    let (dw, dh) = (dk.width as usize, dk.height as usize);
    if depth.len() != dw * dh {
        return Err(RegisterError::DepthSize {
            got: format!("{} pixels", depth.len()),
            want: format!("{}x{}", dk.width, dk.height),
        });
    }
    let (cw, ch) = (ck.width as usize, ck.height as usize);
    out.clear();
    if registration.is_identity() {
        out.extend_from_slice(depth);
        return Ok(());
    }
    project(depth, unit_m, registration, scratch);
    for buffer in [&mut scratch.nearest, &mut scratch.edge_nearest] {
        buffer.clear();
        buffer.resize(cw * ch, 0.0);
    }
    // Corners of one depth step: a surface at the obliquity limit changes depth by
    // z * tan(limit) / f per pixel; a triangle's corners are at most 1.5 pixels apart.
    let obliquity = registration.max_obliquity_deg.clamp(0.0, 89.0);
    let step = (obliquity.to_radians().tan() * 1.5 / dk.fx.min(dk.fy)) as f32;
    // A triangle of neighbouring depth pixels covers about (color f / depth f)^2 color
    // pixels; one far larger lies at the color camera's own centre (a damaged extrinsic)
    // and is not drawn, so that no input makes registration quadratic.
    let scale = (ck.fx / dk.fx).max(ck.fy / dk.fy).max(1.0);
    let max_pixels = (64.0 * scale * scale) as i64 + 64;
    let Scratch {
        projected,
        depth_m,
        nearest,
        edge_nearest,
        rays,
        ..
    } = scratch;
    let camera = Projector::new(registration, rays);
    for y in 0..dh.saturating_sub(1) {
        for x in 0..dw.saturating_sub(1) {
            let i = y * dw + x;
            let quad = [i, i + 1, i + dw, i + dw + 1];
            for tri in [[quad[0], quad[1], quad[2]], [quad[1], quad[3], quad[2]]] {
                let z = tri.map(|i| depth_m[i]);
                let (lo, hi) = (z[0].min(z[1]).min(z[2]), z[0].max(z[1]).max(z[2]));
                let p = tri.map(|i| projected[i]);
                if lo <= 0.0 || p.iter().any(|p| p[2] <= 0.0) {
                    continue;
                }
                if hi - lo <= lo * step {
                    rasterize(p, (cw, ch), max_pixels, nearest);
                    continue;
                }
                // An edge: the near surface may reach across the whole triangle, at any
                // depth it can have there (its nearest corner's, up to a surface step
                // beyond). Swept in three slices, each flat at its nearest 1/z.
                for z in [lo, lo * (1.0 + step / 2.0), lo * (1.0 + step)] {
                    let reach = tri.map(|i| camera.project(i, z));
                    if reach.iter().all(|p| p[2] > 0.0) {
                        let w = reach[0][2].max(reach[1][2]).max(reach[2][2]);
                        rasterize(
                            reach.map(|[x, y, _]| [x, y, w]),
                            (cw, ch),
                            max_pixels,
                            edge_nearest,
                        );
                    }
                }
            }
        }
    }
    // Behind an edge's nearest corner by more than a surface's own step: hidden.
    let hidden = 1.0 / (1.0 + step);
    let unit = unit_m as f32;
    out.extend(nearest.iter().zip(edge_nearest.iter()).map(|(&w, &edge)| {
        // Units rounded to nearest (no libm call); f32 keeps 65535 units to 0.004 of one.
        let units = 1.0 / (w * unit) + 0.5;
        if w > 0.0 && w >= edge * hidden && (1.0..65536.0).contains(&units) {
            units as u16
        } else {
            0
        }
    }));
    Ok(())
}

/// Depth pixels to the color image: back-projection along each depth pixel's ray, the
/// extrinsic, projection with the color intrinsics (and the color lens's distortion).
struct Projector<'a> {
    rays: &'a [[f32; 2]],
    color: [f32; 4],
    color_lens: Option<Distortion>,
    rotation: glam::Mat3,
    translation: glam::Vec3,
}

impl<'a> Projector<'a> {
    fn new(registration: &Registration, rays: &'a [[f32; 2]]) -> Self {
        let k = &registration.color;
        Projector {
            rays,
            color: [k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32],
            color_lens: registration.color_lens.filter(|lens| !lens.is_none()),
            rotation: DMat3::from_quat(registration.depth_to_color.rotation).as_mat3(),
            translation: registration.depth_to_color.translation.as_vec3(),
        }
    }

    /// Depth pixel `i` at depth `z` metres in the color image: x, y and 1/z there (all 0
    /// when it lies behind the color camera or outside either lens's field).
    fn project(&self, i: usize, z: f32) -> [f32; 3] {
        let [rx, ry] = self.rays[i];
        let [cfx, cfy, ccx, ccy] = self.color;
        let point = glam::Vec3::new(rx * z, ry * z, z);
        let c = self.rotation * point + self.translation;
        // Also rejects NaN, which fails every comparison.
        if c.z.is_nan() || c.z <= 0.0 {
            return [0.0; 3];
        }
        let w = 1.0 / c.z;
        let (mut x, mut y) = (c.x * w, c.y * w);
        if let Some(lens) = &self.color_lens {
            match lens.distort(x as f64, y as f64) {
                Some((dx, dy)) => (x, y) = (dx as f32, dy as f32),
                None => return [0.0; 3],
            }
        }
        [x * cfx + ccx, y * cfy + ccy, w]
    }
}

/// Each depth pixel's ray on the z = 1 plane: `((x - cx) / fx, (y - cy) / fy)` through a
/// pinhole, undistorted through a lens (NaN where it cannot be: outside its field).
/// Kept in `scratch` while the depth camera stays the same.
fn depth_rays(registration: &Registration, scratch: &mut Scratch) {
    let key = (registration.depth, registration.depth_lens);
    if scratch.rays_for == Some(key) {
        return;
    }
    let k = &registration.depth;
    let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
    let lens = registration.depth_lens.filter(|lens| !lens.is_none());
    scratch.rays.clear();
    for y in 0..k.height {
        for x in 0..k.width {
            scratch.rays.push(match &lens {
                None => [(x as f32 - cx) / fx, (y as f32 - cy) / fy],
                Some(lens) => {
                    let xd = (x as f64 - k.cx) / k.fx;
                    let yd = (y as f64 - k.cy) / k.fy;
                    match lens.undistort(xd, yd) {
                        Some((ux, uy)) => [ux as f32, uy as f32],
                        None => [f32::NAN; 2],
                    }
                }
            });
        }
    }
    scratch.rays_for = Some(key);
}

/// Each depth pixel's depth in metres and its place in the color image.
fn project(depth: &[u16], unit_m: f64, registration: &Registration, scratch: &mut Scratch) {
    depth_rays(registration, scratch);
    let camera = Projector::new(registration, &scratch.rays);
    let unit = unit_m as f32;
    scratch.projected.clear();
    scratch.depth_m.clear();
    for (i, &d) in depth.iter().enumerate() {
        let z = d as f32 * unit;
        scratch.depth_m.push(z);
        scratch.projected.push(match d {
            0 => [0.0; 3],
            _ => camera.project(i, z),
        });
    }
}

/// The smallest integer at or above `x` (saturating; NaN gives 0), without the libm call
/// `f32::ceil` is on a baseline x86-64 target.
fn ceil(x: f32) -> i32 {
    let i = x as i32;
    i + ((i as f32) < x) as i32
}

/// The largest integer at or below `x` (saturating; NaN gives 0).
fn floor(x: f32) -> i32 {
    let i = x as i32;
    i - ((i as f32) > x) as i32
}

/// Draws one triangle (color-image x, y and 1/z at each corner) into `nearest`, keeping
/// the larger 1/z at each pixel whose centre (integer coordinates) lies inside or on it.
/// A triangle whose bounding box holds more than `max_pixels` pixels is not drawn.
fn rasterize(
    p: [[f32; 3]; 3],
    (width, height): (usize, usize),
    max_pixels: i64,
    nearest: &mut [f32],
) {
    let min_x = ceil(p[0][0].min(p[1][0]).min(p[2][0])).max(0);
    let max_x = floor(p[0][0].max(p[1][0]).max(p[2][0])).min(width as i32 - 1);
    let min_y = ceil(p[0][1].min(p[1][1]).min(p[2][1])).max(0);
    let max_y = floor(p[0][1].max(p[1][1]).max(p[2][1])).min(height as i32 - 1);
    if min_x > max_x
        || min_y > max_y
        || (max_x - min_x + 1) as i64 * (max_y - min_y + 1) as i64 > max_pixels
    {
        return;
    }
    let area =
        (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
    if area.abs() < 1e-12 {
        return;
    }
    let inv_area = 1.0 / area;
    // Edge function of the edge from a to b at q, over the triangle's signed area: the
    // barycentric weight of the corner opposite the edge.
    let edge = |a: [f32; 3], b: [f32; 3], qx: f32, qy: f32| {
        ((b[0] - a[0]) * (qy - a[1]) - (qx - a[0]) * (b[1] - a[1])) * inv_area
    };
    for y in min_y as usize..=max_y as usize {
        let qy = y as f32;
        for x in min_x as usize..=max_x as usize {
            let qx = x as f32;
            let l0 = edge(p[1], p[2], qx, qy);
            let l1 = edge(p[2], p[0], qx, qy);
            let l2 = 1.0 - l0 - l1;
            // A hair of tolerance keeps pixels on a shared edge from falling between
            // its two triangles by rounding.
            const EPS: f32 = -1e-5;
            if l0 < EPS || l1 < EPS || l2 < EPS {
                continue;
            }
            let w = l0 * p[0][2] + l1 * p[1][2] + l2 * p[2][2];
            let slot = &mut nearest[y * width + x];
            if w > *slot {
                *slot = w;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k(width: u32, height: u32, f: f64) -> Intrinsics {
        Intrinsics {
            width,
            height,
            fx: f,
            fy: f,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
        }
    }

    #[test]
    fn depth_already_in_the_color_view_is_copied() {
        let kk = k(4, 3, 5.0);
        let depth: Vec<u16> = (0..12).collect();
        let mut out = Vec::new();
        let r = Registration::new(kk, kk, Extrinsic::IDENTITY);
        register_depth(&depth, 0.001, &r, &mut out, &mut Scratch::default()).unwrap();
        assert_eq!(out, depth);
    }

    #[test]
    fn a_wall_facing_the_cameras_registers_to_its_depth_and_nothing_beyond_its_view() {
        // A wall at 2 m seen by a narrow depth camera 4 cm to the color camera's right:
        // every color pixel the depth camera sees gets 2000 mm, the others none.
        let (dk, ck) = (k(40, 30, 30.0), k(64, 48, 40.0));
        let depth = vec![2000u16; 40 * 30];
        let shift = Extrinsic {
            rotation: DQuat::IDENTITY,
            translation: DVec3::new(0.04, 0.0, 0.0),
        };
        let r = Registration::new(dk, ck, shift);
        let mut out = Vec::new();
        register_depth(&depth, 0.001, &r, &mut out, &mut Scratch::default()).unwrap();
        for y in 0..48 {
            for x in 0..64 {
                // The color pixel's point on the wall, in the depth camera.
                let (cx, cy) = (
                    (x as f64 - ck.cx) / ck.fx * 2.0,
                    (y as f64 - ck.cy) / ck.fy * 2.0,
                );
                let (u, v) = ((cx - 0.04) / 2.0 * dk.fx + dk.cx, cy / 2.0 * dk.fy + dk.cy);
                let inside = (0.0..=39.0).contains(&u) && (0.0..=29.0).contains(&v);
                let got = out[y * 64 + x];
                assert_eq!(got, if inside { 2000 } else { 0 }, "pixel {x},{y}");
            }
        }
    }

    #[test]
    fn a_step_between_two_surfaces_is_not_smeared() {
        // Left half at 1 m, right half at 3 m, same camera: no depth between them.
        let kk = k(20, 10, 20.0);
        let depth: Vec<u16> = (0..200)
            .map(|i| if i % 20 < 10 { 1000 } else { 3000 })
            .collect();
        let mut shifted = kk;
        shifted.cx += 0.25;
        let r = Registration::new(kk, shifted, Extrinsic::IDENTITY);
        let mut out = Vec::new();
        register_depth(&depth, 0.001, &r, &mut out, &mut Scratch::default()).unwrap();
        for (i, &d) in out.iter().enumerate() {
            assert!(d == 0 || d == 1000 || d == 3000, "pixel {i}: {d}");
        }
        assert!(out.contains(&1000) && out.contains(&3000));
    }

    #[test]
    fn integer_bounds_round_towards_the_pixels_inside() {
        let cases = [
            (1.5f32, 2, 1),
            (-1.5, -1, -2),
            (3.0, 3, 3),
            (-0.0, 0, 0),
            (-0.25, 0, -1),
        ];
        for (x, c, f) in cases {
            assert_eq!((ceil(x), floor(x)), (c, f), "{x}");
        }
    }

    #[test]
    fn a_surface_at_the_color_cameras_centre_is_not_drawn_across_the_image() {
        // A damaged extrinsic puts the wall 1 mm in front of the color camera: each
        // triangle would cover the whole image (quadratic work); none is drawn.
        let kk = k(64, 48, 50.0);
        let depth = vec![1000u16; 64 * 48];
        let near = Extrinsic {
            rotation: DQuat::IDENTITY,
            translation: DVec3::new(0.0, 0.0, -0.999),
        };
        let r = Registration::new(kk, kk, near);
        let mut out = Vec::new();
        register_depth(&depth, 0.001, &r, &mut out, &mut Scratch::default()).unwrap();
        let drawn = out.iter().filter(|&&d| d != 0).count();
        assert!(drawn < 64 * 48 / 4, "{drawn} pixels");
    }

    #[test]
    fn a_wrong_depth_size_is_refused() {
        let kk = k(4, 3, 5.0);
        let r = Registration::new(kk, kk, Extrinsic::IDENTITY);
        let e = register_depth(&[0; 5], 0.001, &r, &mut Vec::new(), &mut Scratch::default());
        assert_eq!(
            e.unwrap_err().to_string(),
            "the depth image is 5 pixels, the depth camera's intrinsics say 4x3"
        );
    }

    #[test]
    fn extrinsics_compose_and_invert() {
        let a = Extrinsic {
            rotation: DQuat::from_rotation_y(0.3),
            translation: DVec3::new(0.1, -0.2, 0.05),
        };
        let round = a.inverse().after(&a);
        assert!(round.is_identity(), "{round:?}");
    }
}
