//! Per-pixel neighbourhoods from overlapping disks around depth samples and the plane
//! fit over them (paper 000 Sec. 5, Fig. 4). The paper rasterizes a disk around every
//! sample and lets each pixel collect the ids of the disks that cover it; here each pixel
//! walks the sample grid instead, over the offsets of the samples whose disk covers it,
//! precomputed once per pixel phase and sorted nearest first. The result is the same set
//! of covering disks, visited in a fixed order, so the list of at most k is deterministic.

use super::fit::Scatter;
use super::{NormalCode, PlaneFitParams};
use crate::graph::StageError;
use crate::pinhole::Pinhole;
use crate::raster::{DepthImage, LabelImage, Vec3Image};
use glam::{Vec3, Vec3A};
use rayon::prelude::*;

/// The samples of a points image on a grid of step `step`, padded by `margin` grid cells
/// of NaN on every side so that no window read leaves the buffer. Invalid samples are NaN.
struct SampleGrid {
    samples: Vec<Vec3A>,
    /// Width of the padded grid (grid columns + 2 margin).
    stride: usize,
    margin: usize,
}

impl SampleGrid {
    fn new(points: &Vec3Image, step: usize, margin: usize) -> SampleGrid {
        let (w, h) = (points.width as usize, points.height as usize);
        let (columns, rows) = (w.div_ceil(step), h.div_ceil(step));
        let stride = columns + 2 * margin;
        let mut samples = vec![Vec3A::NAN; stride * (rows + 2 * margin)];
        samples
            .par_chunks_mut(stride)
            .skip(margin)
            .take(rows)
            .enumerate()
            .for_each(|(gy, out)| {
                let row = &points.data[gy * step * w..][..w];
                for (o, p) in out[margin..].iter_mut().zip(row.iter().step_by(step)) {
                    if p.is_finite() && p.z > 0.0 {
                        *o = (*p).into();
                    }
                }
            });
        SampleGrid {
            samples,
            stride,
            margin,
        }
    }
}

/// For each pixel phase (x mod step, y mod step), row-major: the index offsets in the
/// padded sample grid of the samples whose disk of radius `radius` covers the pixel,
/// sorted by distance (ties by row, then column).
fn covering_offsets(step: usize, radius: f32, stride: usize) -> Vec<Vec<isize>> {
    let (s, reach) = (step as i64, radius.floor() as i64);
    let r2 = radius * radius;
    let mut tables = Vec::with_capacity(step * step);
    for py in 0..s {
        for px in 0..s {
            let mut entries: Vec<(i64, i64, i64)> = Vec::new();
            for gy in (py - reach).div_euclid(s)..=(py + reach).div_euclid(s) {
                for gx in (px - reach).div_euclid(s)..=(px + reach).div_euclid(s) {
                    let (dx, dy) = (gx * s - px, gy * s - py);
                    let d2 = dx * dx + dy * dy;
                    if d2 as f32 <= r2 {
                        entries.push((d2, gy, gx));
                    }
                }
            }
            entries.sort_unstable();
            tables.push(
                entries
                    .iter()
                    .map(|&(_, gy, gx)| (gy * stride as i64 + gx) as isize)
                    .collect(),
            );
        }
    }
    tables
}

/// The largest grid offset any window reaches: samples up to `radius` pixels away.
fn margin(step: usize, radius: f32) -> usize {
    (radius.floor() as usize).div_ceil(step)
}

/// Normals by per-pixel plane fits (paper 000 Sec. 5) from the camera-space position map
/// `points` (NaN = missing), seen by `camera` (at the size of `points`).
///
/// Samples are the valid positions at pixels on a grid of step `params.sample_step`. Each
/// pixel lists, nearest first, up to `params.k` samples whose disk of radius
/// `params.radius` pixels covers it; the nearest one is the reference and listed samples
/// farther than `params.max_depth_gap` from it in depth are discarded (so k-hat <= k). The plane of
/// [`Scatter::fit`] gives the pixel's unit normal (facing the camera) and its refined
/// depth, where the view ray through the pixel centre meets the plane. Pixels without
/// raw depth get both from the covering disks (densification).
///
/// Writes, for every pixel: `normals` (zero unless valid), `refined_depth` (0 unless
/// valid), `neighbours` (k-hat, the samples used) and `codes` ([`NormalCode`]).
#[allow(clippy::too_many_arguments)]
pub fn plane_fit_normals(
    points: &Vec3Image,
    camera: &Pinhole,
    params: &PlaneFitParams,
    normals: &mut Vec3Image,
    refined_depth: &mut DepthImage,
    neighbours: &mut LabelImage,
    codes: &mut LabelImage,
) -> Result<(), StageError> {
    let size = |what: &str, w: u32, h: u32| {
        StageError::Failed(format!(
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
    let k = params.k.min(u8::MAX as usize) as u32;
    let (gap, min_det) = (params.max_depth_gap, params.min_determinant);

    normals
        .data
        .par_chunks_mut(w)
        .zip(refined_depth.data.par_chunks_mut(w))
        .zip(neighbours.data.par_chunks_mut(w))
        .zip(codes.data.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (((normal_row, depth_row), count_row), code_row))| {
            let ray_y = (y as f32 - camera.cy) / camera.fy;
            let row_tables = &tables[(y % step) * step..][..step];
            let mut base = (y / step + grid.margin) * grid.stride + grid.margin;
            let mut phase = 0;
            for x in 0..w {
                let ray = Vec3::new(ray_x[x], ray_y, 1.0);
                let (count, result) = fit_pixel(
                    &grid.samples,
                    base,
                    &row_tables[phase],
                    k,
                    gap,
                    min_det,
                    ray,
                );
                phase += 1;
                if phase == step {
                    (phase, base) = (0, base + 1);
                }
                count_row[x] = count as u8;
                (normal_row[x], depth_row[x], code_row[x]) = match result {
                    Ok((n, z)) => (n, z, NormalCode::Valid as u8),
                    Err(code) => (Vec3::ZERO, 0.0, code as u8),
                };
            }
        });
    Ok(())
}

/// Gathers and fits one pixel's neighbourhood: the first `k` valid samples at `base +
/// offsets` (nearest first), the first one as the reference, those within `gap` of its
/// depth used.
/// Returns k-hat and the normal with the depth at which `ray` meets the plane, or why
/// there is none.
#[inline]
fn fit_pixel(
    samples: &[Vec3A],
    base: usize,
    offsets: &[isize],
    k: u32,
    gap: f32,
    min_determinant: f32,
    ray: Vec3,
) -> (u32, Result<(Vec3, f32), NormalCode>) {
    let mut rest = offsets.iter();
    let reference = rest
        .by_ref()
        .map(|&d| samples[base.wrapping_add_signed(d)])
        .find(|p| p.z > 0.0);
    let Some(reference) = reference else {
        return (0, Err(NormalCode::NoSample));
    };
    let mut scatter = Scatter::new(reference);
    scatter.add(reference);
    // The list holds the k nearest samples (paper: "a list of size k"); the rejection
    // then thins it, so k-hat <= k.
    let mut listed = 1;
    for &d in rest {
        if listed >= k {
            break;
        }
        let p = samples[base.wrapping_add_signed(d)];
        listed += (p.z > 0.0) as u32;
        // Branch-free: holes (NaN) and samples across a discontinuity add nothing.
        scatter.add_if((p.z - reference.z).abs() <= gap, p);
    }
    let result = scatter.fit(min_determinant).and_then(|plane| {
        let z = plane.depth_along(ray);
        // The ray must meet the plane near the samples' mean depth: a farther (or
        // negative) depth is an extrapolation along a plane seen at a grazing angle.
        if (z - plane.centroid.z).abs() <= gap && z > 0.0 {
            Ok((plane.normal, z))
        } else {
            Err(NormalCode::RayMissesPlane)
        }
    });
    (scatter.count(), result)
}
