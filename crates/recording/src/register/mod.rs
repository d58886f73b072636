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

mod lanes;
mod quads;

use crate::lens::Distortion;
use glam::{DQuat, DVec3};
use quads::{Projected, Projector, Quads};
use relume_base::pinhole::Intrinsics;
use relume_base::simd::Kernel;

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
    /// Each depth pixel in the color image: x, y, and 1/z in the color camera (all 0:
    /// none), as three planes.
    projected: Projected,
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
    register_with(
        Some(Kernel::detect()),
        depth,
        unit_m,
        registration,
        out,
        scratch,
    )
}

/// [`register_depth`] with eight quads at a time on `kernel`'s lanes where they can be,
/// or (`None`) every quad one at a time: the same output either way.
fn register_with(
    kernel: Option<Kernel>,
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
    let mut quads = Quads {
        depth_m,
        projected,
        camera: projector(registration, rays),
        size: (cw, ch),
        step,
        max_pixels,
        nearest,
        edge_nearest,
    };
    for y in 0..dh.saturating_sub(1) {
        let row = y * dw;
        let done = match kernel {
            Some(kernel) => lanes::surface_quads(kernel, &mut quads, row, dw),
            None => 0,
        };
        for x in done..dw.saturating_sub(1) {
            quads.draw(row + x);
        }
    }
    // Behind an edge's nearest corner by more than a surface's own step: hidden.
    let hidden = 1.0 / (1.0 + step);
    let unit = unit_m as f32;
    out.resize(cw * ch, 0);
    for ((out, &w), &edge) in out.iter_mut().zip(nearest.iter()).zip(edge_nearest.iter()) {
        // Units rounded to nearest (no libm call); f32 keeps 65535 units to 0.004 of one.
        let units = 1.0 / (w * unit) + 0.5;
        let kept = w > 0.0 && w >= edge * hidden && (1.0..65536.0).contains(&units);
        *out = if kept { units as u16 } else { 0 };
    }
    Ok(())
}

/// The depth pixels' projector into the color view of `registration`.
fn projector<'a>(registration: &Registration, rays: &'a [[f32; 2]]) -> Projector<'a> {
    let e = &registration.depth_to_color;
    Projector::new(
        &registration.color,
        registration.color_lens,
        (e.rotation, e.translation),
        registration.depth.width as usize,
        rays,
    )
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
    let camera = projector(registration, &scratch.rays);
    let unit = unit_m as f32;
    let n = depth.len();
    let Projected { x, y, w } = &mut scratch.projected;
    for plane in [&mut *x, &mut *y, &mut *w, &mut scratch.depth_m] {
        plane.clear();
        plane.resize(n, 0.0);
    }
    let depth_m = &mut scratch.depth_m[..n];
    let (x, y, w) = (&mut x[..n], &mut y[..n], &mut w[..n]);
    if camera.color_lens.is_some() {
        for (i, &d) in depth.iter().enumerate() {
            let z = d as f32 * unit;
            depth_m[i] = z;
            let p = match d {
                0 => [0.0; 3],
                _ => camera.project(i, z),
            };
            [x[i], y[i], w[i]] = p;
        }
        return;
    }
    // A pinhole color camera: `Projector::project`'s operations without its branches,
    // so that the loop runs in vector registers.
    let rays = &camera.rays[..n];
    let [cfx, cfy, ccx, ccy] = camera.color;
    for i in 0..n {
        let z = depth[i] as f32 * unit;
        depth_m[i] = z;
        let [rx, ry] = rays[i];
        let c = camera.rotation * glam::Vec3::new(rx * z, ry * z, z) + camera.translation;
        // False for NaN, as in `Projector::project`.
        let seen = depth[i] != 0 && c.z > 0.0;
        let inv_z = 1.0 / c.z;
        let (px, py) = ((c.x * inv_z) * cfx + ccx, (c.y * inv_z) * cfy + ccy);
        x[i] = if seen { px } else { 0.0 };
        y[i] = if seen { py } else { 0.0 };
        w[i] = if seen { inv_z } else { 0.0 };
    }
}

#[cfg(test)]
mod tests {
    use super::quads::{ceil, floor};
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
    fn eight_quads_at_a_time_give_the_bits_of_one_at_a_time() {
        // A room-like depth map: a tilted floor, a box with steps at its sides, holes,
        // and depth pixels beyond the color view (the depth camera's field is wider), seen
        // from 1.5 cm to the side through slightly longer color optics.
        let dk = k(97, 61, 80.0);
        let mut ck = k(100, 64, 86.0);
        ck.cx += 0.3;
        let depth: Vec<u16> = (0..97 * 61)
            .map(|i| {
                let (x, y) = (i % 97, i / 97);
                let floor = 1500 + 9 * y as u16 + 3 * x as u16;
                match (x, y) {
                    _ if (x * 7 + y * 13) % 29 == 0 => 0,
                    (30..=60, 10..=40) => 900 + 2 * x as u16,
                    _ => floor,
                }
            })
            .collect();
        let beside = Extrinsic {
            rotation: DQuat::from_rotation_y(0.01),
            translation: DVec3::new(0.015, 0.002, 0.0),
        };
        let r = Registration::new(dk, ck, beside);
        let run = |kernel| {
            let mut out = Vec::new();
            register_with(kernel, &depth, 0.001, &r, &mut out, &mut Scratch::default()).unwrap();
            out
        };
        let one_at_a_time = run(None);
        assert!(one_at_a_time.iter().filter(|&&d| d > 0).count() > 4000);
        assert_eq!(run(Some(Kernel::Portable)), one_at_a_time);
        assert_eq!(run(Some(Kernel::Avx2Fma)), one_at_a_time);
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
