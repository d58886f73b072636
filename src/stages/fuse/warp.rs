//! Forward warping of the previous fused depth and weight map into the current view
//! (paper 002 Sec. 4.2, eqs. 11-14): the previous map becomes a triangle mesh with one
//! vertex per pixel, each vertex is back-projected (eq. 11), moved into the current
//! camera (eqs. 12, 13) and projected (eq. 14), and the triangles are rasterized with a
//! z-test, carrying the weights. Triangles with a missing vertex or stretched across a
//! depth discontinuity are dropped, as the paper drops invalid and degenerate elements.
//!
//! Pose convention: the paper's T_warp = T_prev^-1 T_current acts on view matrices
//! (world-to-camera). relume's poses are camera-to-world, so a point p in the previous
//! camera's space lands in the current camera's space at `T_cur^-1 * T_prev * p`
//! ([`previous_to_current`]).

use crate::graph::StageError;
use crate::pinhole::Pinhole;
use crate::raster::{DepthImage, Image, ScalarImage, depth_is_valid};
use crate::recording::Pose;
use glam::{DMat4, Mat3, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// Parameters of [`warp_depth`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WarpParams {
    /// A triangle is dropped when its vertex depths (in the previous map) differ by more
    /// than this fraction of the nearest one: it spans a depth discontinuity, and
    /// rasterizing it would draw a "skin" between foreground and background.
    pub max_stretch: f32,
}

impl Default for WarpParams {
    fn default() -> Self {
        WarpParams { max_stretch: 0.05 }
    }
}

/// Warped vertices nearer to the current camera than this (metres) are dropped.
const NEAR_M: f32 = 1e-3;
/// Triangles whose bounding box in the current view is wider or taller than this many
/// pixels are dropped. Between neighbouring frames a 2x2-pixel quad stays about a pixel
/// wide; a huge one comes from a vertex almost in the camera plane (degenerate).
pub const MAX_TRIANGLE_SPAN_PX: f32 = 16.0;
/// Barycentric tolerance: pixel centres on a shared edge belong to both triangles, so
/// rounding never opens a crack between them (the z-test picks one value).
const EDGE_TOLERANCE: f32 = 1e-5;
/// Quad rows per parallel task (the vertices of a band stay in cache).
const BAND_ROWS: usize = 8;
/// An empty z-buffer entry.
const EMPTY: u64 = u64::MAX;

/// The rigid transform that takes a point from the previous camera's space into the
/// current camera's space: `T_cur^-1 * T_prev` for camera-to-world poses (the paper's
/// `T_warp = T_prev^-1 T_current` of eq. 12 in its view-matrix convention).
pub fn previous_to_current(prev_pose: &Pose, cur_pose: &Pose) -> DMat4 {
    cur_pose.matrix().inverse() * prev_pose.matrix()
}

/// The render target of the warping step: warped depth (metres, 0 = nothing landed
/// there) and weight (0 there), with the z-buffer that resolves overlaps. Reuse one
/// across frames to avoid reallocating.
#[derive(Debug)]
pub struct WarpedDepth {
    pub depth: DepthImage,
    pub weight: ScalarImage,
    /// Per pixel `(depth bits << 32) | weight bits`, [`EMPTY`] when nothing landed.
    /// Positive finite f32 bit patterns order like their values, so `fetch_min` keeps
    /// the nearest surface (ties: the lower weight) whatever the thread order. All
    /// entries are [`EMPTY`] between calls.
    keys: Vec<AtomicU64>,
}

impl WarpedDepth {
    /// An empty target of `width` x `height` pixels (all depths and weights 0).
    pub fn new(width: u32, height: u32) -> WarpedDepth {
        let n = width as usize * height as usize;
        WarpedDepth {
            depth: Image::filled(width, height, 0.0),
            weight: Image::filled(width, height, 0.0),
            keys: (0..n).map(|_| AtomicU64::new(EMPTY)).collect(),
        }
    }
}

/// One warped vertex: current-view pixel coordinates, 1 / current depth (0 = invalid)
/// and weight.
#[derive(Clone, Copy, Default)]
struct Vertex {
    x: f32,
    y: f32,
    inv_z: f32,
    weight: f32,
}

/// Warps the previous fused map (`prev_depth`, `prev_weight`, seen from `prev_pose`)
/// into the view of `cur_pose` (paper 002 eqs. 11-14). Both views use `camera`, whose
/// size must be that of the maps. Each 2x2 pixel quad becomes two triangles (split along
/// the diagonal whose end depths differ less); a triangle is dropped when a vertex has
/// no depth, no positive weight or ends behind the camera, when its depths differ by
/// more than `max_stretch` relative to the nearest, or when it is degenerate in the new
/// view. Pixel centres inside a triangle get the perspective-correct depth (1/z
/// interpolated linearly on screen) and weight; the nearest surface wins.
pub fn warp_depth(
    prev_depth: &DepthImage,
    prev_weight: &ScalarImage,
    prev_pose: &Pose,
    cur_pose: &Pose,
    camera: &Pinhole,
    params: &WarpParams,
    warped: &mut WarpedDepth,
) -> Result<(), StageError> {
    if !prev_depth.same_size(prev_weight) || !prev_depth.same_size(&warped.depth) {
        return Err(StageError::Failed(format!(
            "depth warp: previous depth is {}x{}, its weight {}x{}, the target {}x{}",
            prev_depth.width,
            prev_depth.height,
            prev_weight.width,
            prev_weight.height,
            warped.depth.width,
            warped.depth.height
        )));
    }
    if (camera.width, camera.height) != (prev_depth.width, prev_depth.height) {
        return Err(StageError::Failed(format!(
            "depth warp: camera is for {}x{}, depth is {}x{}",
            camera.width, camera.height, prev_depth.width, prev_depth.height
        )));
    }
    let (w, h) = (prev_depth.width as usize, prev_depth.height as usize);
    let m = previous_to_current(prev_pose, cur_pose).as_mat4();
    let rotation = Mat3::from_mat4(m);
    let mesh = Mesh {
        depth: &prev_depth.data,
        weight: &prev_weight.data,
        width: w,
        rotation,
        translation: m.w_axis.truncate(),
        camera: *camera,
        // The ray of pixel (u, v) is (rx(u), ry(v), 1); rotated, its rx(u) part.
        columns: (0..w)
            .map(|u| rotation.x_axis * ((u as f32 - camera.cx) / camera.fx))
            .collect(),
        max_stretch: params.max_stretch,
        x_last: w as f32 - 1.0,
        y_last: h as f32 - 1.0,
        keys: &warped.keys,
    };
    let quad_rows = h.saturating_sub(1);
    if w >= 2 {
        (0..quad_rows.div_ceil(BAND_ROWS))
            .into_par_iter()
            .for_each_init(Vec::new, |vertices, band| {
                let first = band * BAND_ROWS;
                mesh.rasterize_band(first, (first + BAND_ROWS).min(quad_rows), vertices);
            });
    }
    // Read the z-buffer out and leave it empty for the next call.
    let keys = &mut warped.keys;
    let row = w.max(1);
    warped
        .depth
        .data
        .par_chunks_mut(row)
        .zip(warped.weight.data.par_chunks_mut(row))
        .zip(keys.par_chunks_mut(row))
        .for_each(|((depth, weight), keys)| {
            for ((d, wt), key) in depth.iter_mut().zip(weight).zip(keys) {
                let k = std::mem::replace(key.get_mut(), EMPTY);
                (*d, *wt) = if k == EMPTY {
                    (0.0, 0.0)
                } else {
                    (f32::from_bits((k >> 32) as u32), f32::from_bits(k as u32))
                };
            }
        });
    Ok(())
}

/// The pixel indices `ceil(lo).max(0)..=floor(hi).min(last)` of the centres in
/// `[lo, hi]`, or `None` when there are none (or a bound is NaN). Truncating casts
/// instead of `floor`/`ceil`, which are library calls without SSE4.1.
#[inline]
fn centre_range(lo: f32, hi: f32, last: f32) -> Option<(usize, usize)> {
    if !(hi >= 0.0 && lo <= last) {
        return None;
    }
    // lo <= last and hi >= 0, so both casts are in range (hi saturates when huge).
    let first = if lo > 0.0 {
        let t = lo as usize;
        t + ((t as f32) < lo) as usize
    } else {
        0
    };
    let end = (hi as usize).min(last as usize);
    (first <= end).then_some((first, end))
}

/// The previous map as a mesh, with the transform into the current view.
struct Mesh<'a> {
    depth: &'a [f32],
    weight: &'a [f32],
    width: usize,
    rotation: Mat3,
    translation: Vec3,
    camera: Pinhole,
    columns: Vec<Vec3>,
    max_stretch: f32,
    /// The last pixel column and row, as floats.
    x_last: f32,
    y_last: f32,
    keys: &'a [AtomicU64],
}

impl Mesh<'_> {
    /// Warps the vertices of pixel row `y` into `out` (appended).
    fn warp_row(&self, y: usize, out: &mut Vec<Vertex>) {
        let c = &self.camera;
        let row_ray = self.rotation.y_axis * ((y as f32 - c.cy) / c.fy) + self.rotation.z_axis;
        let start = y * self.width;
        let depths = &self.depth[start..start + self.width];
        let weights = &self.weight[start..start + self.width];
        for ((&z, &weight), column) in depths.iter().zip(weights).zip(&self.columns) {
            let mut v = Vertex::default();
            if depth_is_valid(z) && weight.is_finite() && weight > 0.0 {
                // eqs. 11, 13: p = ray * z in the previous camera, then R p + t.
                let p = (*column + row_ray) * z + self.translation;
                if p.z > NEAR_M {
                    let inv_z = 1.0 / p.z;
                    v = Vertex {
                        x: c.fx * p.x * inv_z + c.cx,
                        y: c.fy * p.y * inv_z + c.cy,
                        inv_z,
                        weight,
                    };
                }
            }
            out.push(v);
        }
    }

    /// Rasterizes the quads of rows `first..end` (vertex rows `first..=end`).
    fn rasterize_band(&self, first: usize, end: usize, vertices: &mut Vec<Vertex>) {
        let w = self.width;
        vertices.clear();
        for y in first..=end {
            self.warp_row(y, vertices);
        }
        for y in first..end {
            let top = &vertices[(y - first) * w..(y - first + 1) * w];
            let bottom = &vertices[(y - first + 1) * w..(y - first + 2) * w];
            let z_top = &self.depth[y * w..(y + 1) * w];
            let z_bottom = &self.depth[(y + 1) * w..(y + 2) * w];
            for x in 0..w - 1 {
                // a b
                // c d
                let (a, b, c, d) = (top[x], top[x + 1], bottom[x], bottom[x + 1]);
                let (za, zb, zc, zd) = (z_top[x], z_top[x + 1], z_bottom[x], z_bottom[x + 1]);
                if (za - zd).abs() <= (zb - zc).abs() {
                    self.triangle([a, b, d], [za, zb, zd]);
                    self.triangle([a, d, c], [za, zd, zc]);
                } else {
                    self.triangle([a, b, c], [za, zb, zc]);
                    self.triangle([b, d, c], [zb, zd, zc]);
                }
            }
        }
    }

    /// Z-tests the pixel centres inside one triangle; `z_prev` are its vertex depths in
    /// the previous map.
    #[inline]
    fn triangle(&self, v: [Vertex; 3], z_prev: [f32; 3]) {
        let [v0, v1, v2] = v;
        if v0.inv_z <= 0.0 || v1.inv_z <= 0.0 || v2.inv_z <= 0.0 {
            return;
        }
        let z_near = z_prev[0].min(z_prev[1]).min(z_prev[2]);
        let z_far = z_prev[0].max(z_prev[1]).max(z_prev[2]);
        if z_far - z_near > self.max_stretch * z_near {
            return;
        }
        let (x_min, x_max) = (v0.x.min(v1.x).min(v2.x), v0.x.max(v1.x).max(v2.x));
        let (y_min, y_max) = (v0.y.min(v1.y).min(v2.y), v0.y.max(v1.y).max(v2.y));
        // Most triangles of a 1-pixel quad hold no pixel centre. Also false for NaN.
        let (Some((x_lo, x_hi)), Some((y_lo, y_hi))) = (
            centre_range(x_min, x_max, self.x_last),
            centre_range(y_min, y_max, self.y_last),
        ) else {
            return;
        };
        if x_max - x_min > MAX_TRIANGLE_SPAN_PX || y_max - y_min > MAX_TRIANGLE_SPAN_PX {
            return;
        }
        let (e1x, e1y) = (v1.x - v0.x, v1.y - v0.y);
        let (e2x, e2y) = (v2.x - v0.x, v2.y - v0.y);
        // Twice the signed area; the edge functions below are barycentrics times it.
        let area = e1x * e2y - e2x * e1y;
        if area.abs() <= 1e-12 {
            return;
        }
        let (sign, tolerance) = (area.signum(), -EDGE_TOLERANCE * area.abs());
        let inv_area = 1.0 / (area * sign);
        let (inv_z_min, inv_z_max) = (
            v0.inv_z.min(v1.inv_z).min(v2.inv_z),
            v0.inv_z.max(v1.inv_z).max(v2.inv_z),
        );
        let (weight_min, weight_max) = (
            v0.weight.min(v1.weight).min(v2.weight),
            v0.weight.max(v1.weight).max(v2.weight),
        );
        let (wz0, wz1, wz2) = (
            v0.weight * v0.inv_z,
            v1.weight * v1.inv_z,
            v2.weight * v2.inv_z,
        );
        for py in y_lo..=y_hi {
            let dy = py as f32 - v0.y;
            for px in x_lo..=x_hi {
                let dx = px as f32 - v0.x;
                let a1 = (dx * e2y - e2x * dy) * sign;
                let a2 = (e1x * dy - dx * e1y) * sign;
                let a0 = area * sign - a1 - a2;
                if a0 < tolerance || a1 < tolerance || a2 < tolerance {
                    continue;
                }
                let (b1, b2) = (a1 * inv_area, a2 * inv_area);
                let b0 = 1.0 - b1 - b2;
                let inv_z =
                    (b0 * v0.inv_z + b1 * v1.inv_z + b2 * v2.inv_z).clamp(inv_z_min, inv_z_max);
                let z = 1.0 / inv_z;
                // Perspective-correct weight: interpolate weight / z, times z.
                let weight = ((b0 * wz0 + b1 * wz1 + b2 * wz2) * z).clamp(weight_min, weight_max);
                let key = ((z.to_bits() as u64) << 32) | weight.to_bits() as u64;
                let slot = &self.keys[py * self.width + px];
                // Keys only decrease: skip the atomic write when it cannot win.
                if key < slot.load(Ordering::Relaxed) {
                    slot.fetch_min(key, Ordering::Relaxed);
                }
            }
        }
    }
}
