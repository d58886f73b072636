//! Per-pixel neighbourhoods from overlapping disks around depth samples and the plane
//! fit over them (paper 000 Sec. 5, Fig. 4). The paper rasterizes a disk around every
//! sample and lets each pixel collect the ids of the disks that cover it; here each pixel
//! walks the sample grid instead, over the offsets of the samples whose disk covers it,
//! precomputed once per pixel phase and sorted nearest first. The result is the same set
//! of covering disks, visited in a fixed order, so the list of at most k is deterministic.

use super::fit::Scatter;
use super::params::NormalCode;
use glam::{Vec3, Vec3A};
use rayon::prelude::*;
use relume_base::raster::Vec3Image;

/// The samples of a points image on a grid of step `step`, padded by `margin` grid cells
/// of NaN on every side so that no window read leaves the buffer. Invalid samples are NaN.
pub(super) struct SampleGrid {
    pub samples: Vec<Vec3A>,
    /// The same samples as three planes (x, y, z), for the lane-wise gather.
    pub planes: [Vec<f32>; 3],
    /// Width of the padded grid (grid columns + 2 margin).
    pub stride: usize,
    pub margin: usize,
}

impl SampleGrid {
    pub fn new(points: &Vec3Image, step: usize, margin: usize) -> SampleGrid {
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
        let planes = [0, 1, 2].map(|c| samples.iter().map(|p| p[c]).collect());
        SampleGrid {
            samples,
            planes,
            stride,
            margin,
        }
    }
}

/// For each pixel phase (x mod step, y mod step), row-major: the index offsets in the
/// padded sample grid of the samples whose disk of radius `radius` covers the pixel,
/// sorted by distance (ties by row, then column).
pub(super) fn covering_offsets(step: usize, radius: f32, stride: usize) -> Vec<Vec<isize>> {
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
pub(super) fn margin(step: usize, radius: f32) -> usize {
    (radius.floor() as usize).div_ceil(step)
}

/// What the fits of every row share.
pub(super) struct RowFit<'a> {
    pub grid: &'a SampleGrid,
    /// [`covering_offsets`] of every pixel phase.
    pub tables: &'a [Vec<isize>],
    /// Per column, the x of its view ray (whose z is 1).
    pub ray_x: &'a [f32],
    pub camera_cy: f32,
    pub camera_fy: f32,
    pub step: usize,
    pub k: u32,
    pub gap: f32,
    pub min_determinant: f32,
}

impl RowFit<'_> {
    /// The view ray through the centre of pixel (x, y), with z = 1.
    #[inline]
    pub fn ray(&self, x: usize, y: usize) -> Vec3 {
        Vec3::new(
            self.ray_x[x],
            (y as f32 - self.camera_cy) / self.camera_fy,
            1.0,
        )
    }

    /// The tables of row `y`'s pixel phases.
    #[inline]
    pub fn row_tables(&self, y: usize) -> &[Vec<isize>] {
        &self.tables[(y % self.step) * self.step..][..self.step]
    }

    /// The grid index of the sample at column 0 of row `y`'s grid row; pixel x's
    /// windows are centred `x / step` further on.
    #[inline]
    pub fn row_base(&self, y: usize) -> usize {
        (y / self.step + self.grid.margin) * self.grid.stride + self.grid.margin
    }
}

/// One row of the four outputs.
pub(super) struct RowOut<'a> {
    pub normals: &'a mut [Vec3],
    pub depth: &'a mut [f32],
    pub counts: &'a mut [u8],
    pub codes: &'a mut [u8],
}

impl RowOut<'_> {
    /// Writes pixel `x`: k-hat, and the normal and refined depth or why there is none.
    #[inline]
    pub fn set(&mut self, x: usize, count: u32, result: Result<(Vec3, f32), NormalCode>) {
        self.counts[x] = count as u8;
        (self.normals[x], self.depth[x], self.codes[x]) = match result {
            Ok((n, z)) => (n, z, NormalCode::Valid as u8),
            Err(code) => (Vec3::ZERO, 0.0, code as u8),
        };
    }
}

/// Fits row `y` one pixel at a time (the reference the lane-wise rows match bit for
/// bit, and what they do with the pixels left over).
pub(super) fn fit_row(fit: &RowFit, y: usize, out: &mut RowOut) {
    let row_tables = fit.row_tables(y);
    let mut base = fit.row_base(y);
    let mut phase = 0;
    for x in 0..out.normals.len() {
        let (count, result) = fit_pixel(fit, base, &row_tables[phase], fit.ray(x, y));
        out.set(x, count, result);
        phase += 1;
        if phase == fit.step {
            (phase, base) = (0, base + 1);
        }
    }
}

/// Gathers and fits one pixel's neighbourhood: the first `k` valid samples at `base +
/// offsets` (nearest first), the first one as the reference, those within `gap` of its
/// depth used.
/// Returns k-hat and the normal with the depth at which `ray` meets the plane, or why
/// there is none.
#[inline]
pub(super) fn fit_pixel(
    fit: &RowFit,
    base: usize,
    offsets: &[isize],
    ray: Vec3,
) -> (u32, Result<(Vec3, f32), NormalCode>) {
    let (samples, k, gap) = (&fit.grid.samples, fit.k, fit.gap);
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
    (scatter.count(), plane_along(&scatter, fit, ray))
}

/// The plane of `scatter` and the depth at which `ray` meets it, or why there is none.
#[inline]
pub(super) fn plane_along(
    scatter: &Scatter,
    fit: &RowFit,
    ray: Vec3,
) -> Result<(Vec3, f32), NormalCode> {
    scatter.fit(fit.min_determinant).and_then(|plane| {
        let z = plane.depth_along(ray);
        // The ray must meet the plane near the samples' mean depth: a farther (or
        // negative) depth is an extrapolation along a plane seen at a grazing angle.
        if (z - plane.centroid.z).abs() <= fit.gap && z > 0.0 {
            Ok((plane.normal, z))
        } else {
            Err(NormalCode::RayMissesPlane)
        }
    })
}
