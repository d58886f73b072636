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

use super::mesh::{Mesh, QuadRow, VertexRows};
use super::mesh_lanes::rasterize_quads;
use crate::OpError;
use glam::{DMat4, Mat3};
use rayon::prelude::*;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Image, ScalarImage};
use relume_base::simd::Kernel;
use relume_recording::Pose;
use std::sync::atomic::AtomicU64;

pub use super::mesh::MAX_TRIANGLE_SPAN_PX;

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
) -> Result<(), OpError> {
    // The portable lanes compute what one quad at a time does, only slower.
    let kernel = (Kernel::detect() == Kernel::Avx2Fma).then_some(Kernel::Avx2Fma);
    let poses = (prev_pose, cur_pose);
    warp_depth_by(
        kernel,
        prev_depth,
        prev_weight,
        poses,
        camera,
        params,
        warped,
    )
}

/// [`warp_depth`] rasterizing eight quads at a time with `kernel`'s lanes, or one at a
/// time for `None` (the same bits).
pub(super) fn warp_depth_by(
    kernel: Option<Kernel>,
    prev_depth: &DepthImage,
    prev_weight: &ScalarImage,
    (prev_pose, cur_pose): (&Pose, &Pose),
    camera: &Pinhole,
    params: &WarpParams,
    warped: &mut WarpedDepth,
) -> Result<(), OpError> {
    if !prev_depth.same_size(prev_weight) || !prev_depth.same_size(&warped.depth) {
        return Err(OpError::SizeMismatch(format!(
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
        return Err(OpError::SizeMismatch(format!(
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
            .for_each_init(VertexRows::default, |vertices, band| {
                let first = band * BAND_ROWS;
                let end = (first + BAND_ROWS).min(quad_rows);
                rasterize_band(&mesh, kernel, first, end, vertices);
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

/// Rasterizes the quads of rows `first..end` (vertex rows `first..=end`): eight at a
/// time with `kernel`'s lanes where given, the rest one at a time.
fn rasterize_band(
    mesh: &Mesh,
    kernel: Option<Kernel>,
    first: usize,
    end: usize,
    vertices: &mut VertexRows,
) {
    let w = mesh.width;
    vertices.clear();
    for y in first..=end {
        mesh.warp_row(y, vertices);
    }
    for y in first..end {
        let row = QuadRow {
            top: (y - first) * w,
            bottom: (y - first + 1) * w,
            z_top: &mesh.depth[y * w..(y + 1) * w],
            z_bottom: &mesh.depth[(y + 1) * w..(y + 2) * w],
        };
        let done = kernel.map_or(0, |kernel| rasterize_quads(kernel, mesh, vertices, &row));
        for x in done..w - 1 {
            mesh.quad(vertices, &row, x);
        }
    }
}
