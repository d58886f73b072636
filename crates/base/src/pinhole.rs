//! The pinhole camera model in f32, for per-pixel work: projection of camera-space points
//! to pixel coordinates and back. Pixel (u, v) has its centre at integer coordinates, as
//! in TUM RGB-D and Open3D (u = fx X / Z + cx).

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics of one sensor, in pixels, for an image of `width` x `height`.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    /// The PrimeSense / Kinect default (fx = fy = 525, centre 319.5, 239.5) at 640x480.
    pub const PRIMESENSE: Intrinsics = Intrinsics {
        width: 640,
        height: 480,
        fx: 525.0,
        fy: 525.0,
        cx: 319.5,
        cy: 239.5,
    };

    /// The same camera at another resolution: focal lengths and centre scale with the size.
    pub fn scaled_to(&self, width: u32, height: u32) -> Intrinsics {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        Intrinsics {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
        }
    }
}

/// The largest image side a recording may declare (pixels).
pub const MAX_IMAGE_SIDE: u32 = 16384;
/// The most pixels a recording's images may declare (64 Mpx: 768 MiB of f32 RGB).
pub const MAX_IMAGE_PIXELS: u64 = 64 << 20;
/// The shortest and longest focal lengths a camera may declare, in multiples of its
/// image's larger side: a field of view across that side of 168.6 degrees down to
/// 0.57 degrees. A focal length outside them is a unit mistake (metres for pixels, a
/// value for another image size), not a lens.
pub const FOCAL_RANGE_IN_SIDES: (f64, f64) = (0.05, 100.0);

impl Intrinsics {
    /// Why these intrinsics cannot describe a camera, if they cannot: sizes of 0 or
    /// over [`MAX_IMAGE_SIDE`] / [`MAX_IMAGE_PIXELS`], focal lengths that are not finite
    /// and positive or lie outside [`FOCAL_RANGE_IN_SIDES`], a principal point that is
    /// not finite or lies further outside the image than its own width or height.
    pub fn check(&self) -> Result<(), String> {
        let (w, h) = (self.width, self.height);
        if w == 0 || h == 0 || w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE {
            return Err(format!(
                "image size {w}x{h} is not between 1 and {MAX_IMAGE_SIDE} on each side"
            ));
        }
        if w as u64 * h as u64 > MAX_IMAGE_PIXELS {
            return Err(format!(
                "image size {w}x{h} is over {MAX_IMAGE_PIXELS} pixels"
            ));
        }
        let side = w.max(h) as f64;
        let (shortest, longest) = FOCAL_RANGE_IN_SIDES;
        for (name, f) in [("fx", self.fx), ("fy", self.fy)] {
            if !(f.is_finite() && f > 0.0) {
                return Err(format!(
                    "{name} = {f} is not a finite positive focal length"
                ));
            }
            if !(shortest * side..=longest * side).contains(&f) {
                return Err(format!(
                    "{name} = {} px is not a focal length for a {w}x{h} image: it must lie \
                     between {shortest} and {longest} times the image's larger side \
                     ({} to {} px)",
                    readable(f),
                    shortest * side,
                    longest * side
                ));
            }
        }
        for (name, c, size) in [("cx", self.cx, w as f64), ("cy", self.cy, h as f64)] {
            if !c.is_finite() {
                return Err(format!("{name} = {c} is not finite"));
            }
            if !(-size..=2.0 * size).contains(&c) {
                return Err(format!(
                    "{name} = {} px lies further outside the {w}x{h} image than its own size \
                     (it must lie between {} and {} px)",
                    readable(c),
                    -size,
                    2.0 * size
                ));
            }
        }
        Ok(())
    }
}

/// `x` for a message: plain where that is short (`525`, `0.001`), in scientific
/// notation where it is not (`1e300`, `1e-30`), so an absurd value does not print as
/// three hundred digits.
pub fn readable(x: f64) -> String {
    let magnitude = x.abs();
    if x.is_finite() && x != 0.0 && !(1e-4..1e7).contains(&magnitude) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// Pinhole intrinsics for an image of `width` x `height` pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Pinhole {
    /// `intrinsics` rescaled to an image of `width` x `height`.
    pub fn new(intrinsics: &Intrinsics, width: u32, height: u32) -> Pinhole {
        let k = intrinsics.scaled_to(width, height);
        Pinhole {
            width,
            height,
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
        }
    }

    /// The pixel coordinates of camera-space point `p`, or `None` behind the camera.
    #[inline]
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        (p.z > 0.0).then(|| Vec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    /// The pixel index of camera-space point `p` (nearest pixel centre), or `None` when
    /// it is behind the camera or outside the image.
    #[inline]
    pub fn pixel_of(&self, p: Vec3) -> Option<(u32, u32)> {
        let uv = self.project(p)?;
        let (u, v) = ((uv.x + 0.5).floor(), (uv.y + 0.5).floor());
        (u >= 0.0 && v >= 0.0 && u < self.width as f32 && v < self.height as f32)
            .then_some((u as u32, v as u32))
    }

    /// The view ray through pixel coordinates (u, v), scaled so that its z is 1: the
    /// camera-space point at depth z is `ray(u, v) * z`.
    #[inline]
    pub fn ray(&self, u: f32, v: f32) -> Vec3 {
        Vec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    /// The camera-space point at pixel (u, v) and depth `z`.
    #[inline]
    pub fn back_project(&self, u: f32, v: f32, z: f32) -> Vec3 {
        self.ray(u, v) * z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_and_back_projection_are_inverse() {
        let cam = Pinhole::new(&Intrinsics::PRIMESENSE, 320, 240);
        assert_eq!(
            (cam.fx, cam.cx),
            (262.5, 159.5),
            "pixel centres scale about the corner"
        );
        let p = cam.back_project(10.0, 200.0, 2.5);
        let uv = cam.project(p).unwrap();
        assert!((uv - Vec2::new(10.0, 200.0)).length() < 1e-4);
        assert_eq!(cam.pixel_of(p), Some((10, 200)));
        assert_eq!(cam.project(Vec3::new(0.0, 0.0, -1.0)), None);
        assert_eq!(cam.pixel_of(cam.back_project(-0.6, 5.0, 1.0)), None);
        assert_eq!(
            cam.pixel_of(cam.back_project(319.4, 5.0, 1.0)),
            Some((319, 5))
        );
    }
}
