//! Reprojection into the previous frame for the temporal filter (paper 001 eqs. 24-26):
//! the pixel (x', y') of the previous frame whose world position is nearest the current
//! pixel's.

use super::planes::{C_PX, C_PY, C_PZ, Planes};
use crate::pinhole::Pinhole;
use glam::{Affine3A, Vec3};

/// Half size of the search window around the projected pixel (1: 3 x 3).
pub const SEARCH_RADIUS: i32 = 1;

/// The previous frame as the temporal filter sees it.
#[derive(Clone, Copy, Debug)]
pub struct PreviousView {
    /// World to previous camera.
    pub world_to_camera: Affine3A,
    /// The previous camera (same intrinsics, same image size).
    pub camera: Pinhole,
}

/// The previous pixel (x', y') matching world position `p`: `p` is projected into the
/// previous camera and rounded to a pixel, then the [`SEARCH_RADIUS`] window around it is
/// searched for the previous pixel with the nearest world position (ties: the first in
/// row order). `previous` is the previous frame's column set (position y of line x
/// is pixel (x, y)).
/// `None` when `p` is behind the previous camera or projects off-screen, or
/// when no pixel of the window has a position.
#[inline]
pub fn find_previous(p: Vec3, view: &PreviousView, previous: &Planes) -> Option<(usize, usize)> {
    let c = view.world_to_camera.transform_point3(p);
    if c.z.is_nan() || c.z <= 0.0 {
        return None;
    }
    let cam = &view.camera;
    let u = cam.fx * c.x / c.z + cam.cx + 0.5;
    let v = cam.fy * c.y / c.z + cam.cy + 0.5;
    // The search stays inside both the camera and the previous planes (the column set
    // is the transposed image: its lines are image columns).
    let width = previous.height.min(cam.width as usize) as i32;
    let height = previous.width.min(cam.height as usize) as i32;
    let (w, h) = (width as f32, height as f32);
    if !(u >= 0.0 && v >= 0.0 && u < w && v < h) {
        return None;
    }
    // u, v >= 0: truncation is the floor.
    let (u, v) = (u as i32, v as i32);
    let mut best: Option<(usize, usize)> = None;
    let mut best_d2 = Planes::MISSING_DISTANCE2;
    for dy in -SEARCH_RADIUS..=SEARCH_RADIUS {
        for dx in -SEARCH_RADIUS..=SEARCH_RADIUS {
            let (x, y) = (u + dx, v + dy);
            if x < 0 || y < 0 || x >= width || y >= height {
                continue;
            }
            let (x, y) = (x as usize, y as usize);
            let q = Vec3::new(
                previous.at(C_PX, y, x),
                previous.at(C_PY, y, x),
                previous.at(C_PZ, y, x),
            );
            let d2 = (q - p).length_squared();
            if d2 < best_d2 {
                best_d2 = d2;
                best = Some((x, y));
            }
        }
    }
    best
}
