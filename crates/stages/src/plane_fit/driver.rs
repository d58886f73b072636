//! The image operation of `normals.plane_fit`: checks, the sample grid and its tables,
//! then the rows in parallel, eight pixels at a time where the CPU has AVX2
//! ([`super::lanes`]) and one at a time elsewhere ([`super::gather`]), with the same bits.

use super::gather::{RowFit, RowOut, SampleGrid, covering_offsets, fit_row, margin};
use super::lanes::fit_row_lanes;
use super::params::PlaneFitParams;
use crate::OpError;
use rayon::prelude::*;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, LabelImage, Vec3Image};
use relume_base::simd::Kernel;

/// Normals by per-pixel plane fits (paper 000 Sec. 5) from the camera-space position map
/// `points` (NaN = missing), seen by `camera` (at the size of `points`).
///
/// Samples are the valid positions at pixels on a grid of step `params.sample_step`. Each
/// pixel lists, nearest first, up to `params.k` samples whose disk of radius
/// `params.radius` pixels covers it; the nearest one is the reference and listed samples
/// farther than `params.max_depth_gap` from it in depth are discarded (so k-hat <= k). The plane of
/// [`super::Scatter::fit`] gives the pixel's unit normal (facing the camera) and its refined
/// depth, where the view ray through the pixel centre meets the plane. Pixels without
/// raw depth get both from the covering disks (densification).
///
/// Writes, for every pixel: `normals` (zero unless valid), `refined_depth` (0 unless
/// valid), `neighbours` (k-hat, the samples used) and `codes` ([`super::NormalCode`]).
#[allow(clippy::too_many_arguments)]
pub fn plane_fit_normals(
    points: &Vec3Image,
    camera: &Pinhole,
    params: &PlaneFitParams,
    normals: &mut Vec3Image,
    refined_depth: &mut DepthImage,
    neighbours: &mut LabelImage,
    codes: &mut LabelImage,
) -> Result<(), OpError> {
    // The portable lanes compute what one pixel at a time does, only slower.
    let kernel = (Kernel::detect() == Kernel::Avx2Fma).then_some(Kernel::Avx2Fma);
    plane_fit_normals_by(
        kernel,
        points,
        camera,
        params,
        normals,
        refined_depth,
        neighbours,
        codes,
    )
}

/// [`plane_fit_normals`] with the lanes of `kernel`, or one pixel at a time for `None`
/// (all give the same bits).
#[allow(clippy::too_many_arguments)]
pub(super) fn plane_fit_normals_by(
    kernel: Option<Kernel>,
    points: &Vec3Image,
    camera: &Pinhole,
    params: &PlaneFitParams,
    normals: &mut Vec3Image,
    refined_depth: &mut DepthImage,
    neighbours: &mut LabelImage,
    codes: &mut LabelImage,
) -> Result<(), OpError> {
    let size = |what: &str, w: u32, h: u32| {
        OpError::SizeMismatch(format!(
            "{what} is {w}x{h}, points are {}x{}",
            points.width, points.height
        ))
    };
    if !points.same_size(normals) {
        return Err(size("normal map", normals.width, normals.height));
    }
    if !points.same_size(refined_depth) {
        return Err(size(
            "refined depth",
            refined_depth.width,
            refined_depth.height,
        ));
    }
    if !points.same_size(neighbours) {
        return Err(size("neighbour count", neighbours.width, neighbours.height));
    }
    if !points.same_size(codes) {
        return Err(size("code map", codes.width, codes.height));
    }
    if camera.width != points.width || camera.height != points.height {
        return Err(size("camera", camera.width, camera.height));
    }
    params.check()?;
    if points.is_empty() {
        return Ok(());
    }
    let (w, step) = (points.width as usize, params.sample_step);
    let grid = SampleGrid::new(points, step, margin(step, params.radius));
    let tables = covering_offsets(step, params.radius, grid.stride);
    let ray_x: Vec<f32> = (0..w).map(|x| (x as f32 - camera.cx) / camera.fx).collect();
    let fit = RowFit {
        grid: &grid,
        tables: &tables,
        ray_x: &ray_x,
        camera_cy: camera.cy,
        camera_fy: camera.fy,
        step,
        k: params.k.min(u8::MAX as usize) as u32,
        gap: params.max_depth_gap,
        min_determinant: params.min_determinant,
    };
    normals
        .data
        .par_chunks_mut(w)
        .zip(refined_depth.data.par_chunks_mut(w))
        .zip(neighbours.data.par_chunks_mut(w))
        .zip(codes.data.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (((normals, depth), counts), codes))| {
            let mut out = RowOut {
                normals,
                depth,
                counts,
                codes,
            };
            match kernel {
                Some(kernel) => fit_row_lanes(kernel, &fit, y, &mut out),
                None => fit_row(&fit, y, &mut out),
            }
        });
    Ok(())
}
