//! Mip-mapped voxel volumes and cone marching (paper 000 Sec. 6.1 "(Scene) Voxel
//! Volume", Sec. 6.2 and eq. 6, after Crassin et al., ref. 3).
//!
//! A [`VoxelVolume`] is a dense box of voxels, each holding radiance premultiplied by
//! opacity and the opacity itself (`Vec4(r a, g a, b a, a)`), with a chain of coarser
//! levels, each voxel the mean of the 8 below it (missing ones count as empty). Two
//! volumes are built:
//!
//! - the **scene volume** ([`VoxelVolume::from_points`]): every environment sample added
//!   to the finest level with its radiance and opacity 1 (the paper's "all samples are
//!   added to the most detailed mipmap level"); a voxel holding several samples takes
//!   their mean radiance;
//! - the **object volume** ([`crate::objects::voxelize::solid_volume`]): a solid
//!   voxelization of the virtual objects, opacity tau = 1 inside a closed mesh and 0
//!   outside (Sec. 6.2), no radiance.
//!
//! [`VoxelVolume::march`] casts a cone through a volume front to back (eq. 6): at
//! distance t its diameter is `max(voxel, 2 t spread)` (`spread` = tan of the half
//! aperture), it samples the level whose voxels are that wide (quadrilinear: trilinear
//! in the two nearest levels, blended, each voxel seen along the cone's direction),
//! steps half a diameter and accumulates `C += (1 - A) c`, `A += (1 - A) a` until the
//! cone is opaque (A >= 0.99), leaves the volume or reaches its end. `1 - A` is the
//! paper's alpha, the degree to which what lies beyond stays visible. As in Crassin et
//! al.'s marcher, a sample's opacity is not corrected for the step: at half-diameter
//! steps the two or three samples that straddle a one-voxel wall make it opaque
//! (corrected, the tent of trilinear interpolation lets a quarter of the cone through
//! every wall).
//!
//! Where it departs from the paper: the volume is a dense box over the samples'
//! bounds, its finest voxels `voxel_size` wide (default 4 cm, two cloud cells) with at
//! most [`MAX_DIM`] voxels a side, rather than a fixed 256^3 cube; levels are built
//! on the CPU.

use crate::objects::Aabb;
use glam::{Vec3, Vec4};
use thiserror::Error;

/// The most voxels along a side of the finest level (the paper's 256).
pub const MAX_DIM: u32 = 256;
/// Opacity at which a cone stops (nothing behind it can show).
pub const OPAQUE: f32 = 0.99;
/// The step between a cone's samples, in diameters.
pub const STEP: f32 = 0.5;

/// Why a volume could not be built.
#[derive(Debug, Error, PartialEq)]
pub enum VoxelError {
    #[error("voxel size {0} is not a positive finite number of metres")]
    VoxelSize(f32),
    #[error("positions and radiances differ in length ({0} and {1})")]
    Lengths(usize, usize),
}

/// One level of a volume: `dims` voxels, x fastest, then y, then z. The finest level
/// holds one value per voxel; the coarser ones hold three, what the voxel looks like
/// seen along x, y and z (anisotropic voxels, Crassin et al. Sec. 5.1: a thin wall
/// stays opaque seen head-on however coarse the level).
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelLevel {
    pub dims: [u32; 3],
    /// Values per voxel: 1 (isotropic) or 3 (seen along x, y, z).
    pub axes: usize,
    /// Per voxel and axis: radiance times opacity, and opacity.
    pub voxels: Vec<Vec4>,
}

impl VoxelLevel {
    fn empty(dims: [u32; 3], axes: usize) -> VoxelLevel {
        let n: usize = dims.iter().map(|&d| d as usize).product();
        VoxelLevel {
            dims,
            axes,
            voxels: vec![Vec4::ZERO; n * axes],
        }
    }

    /// An isotropic level from one value per voxel.
    pub fn isotropic(dims: [u32; 3], voxels: Vec<Vec4>) -> VoxelLevel {
        VoxelLevel {
            dims,
            axes: 1,
            voxels,
        }
    }

    #[inline]
    fn index(&self, x: u32, y: u32, z: u32) -> usize {
        let [w, h, _] = self.dims;
        (z as usize * h as usize + y as usize) * w as usize + x as usize
    }

    /// Where the values of the voxel at integer coordinates start in `voxels`; `None`
    /// outside the level.
    #[inline]
    fn slot(&self, x: i64, y: i64, z: i64) -> Option<usize> {
        let [w, h, d] = self.dims;
        if x < 0 || y < 0 || z < 0 || x >= w as i64 || y >= h as i64 || z >= d as i64 {
            return None;
        }
        Some(self.index(x as u32, y as u32, z as u32) * self.axes)
    }

    /// The voxel at integer coordinates seen along axis `axis` (empty outside).
    #[inline]
    fn along(&self, x: i64, y: i64, z: i64, axis: usize) -> Vec4 {
        self.slot(x, y, z)
            .map_or(Vec4::ZERO, |i| self.voxels[i + axis.min(self.axes - 1)])
    }

    /// The voxel at integer coordinates seen along a direction whose squared
    /// components are `weights` (empty outside).
    #[inline]
    fn get(&self, x: i64, y: i64, z: i64, weights: Vec3) -> Vec4 {
        self.slot(x, y, z)
            .map_or(Vec4::ZERO, |i| self.seen(i, weights))
    }

    /// The voxel whose values start at `i`, seen along a direction whose squared
    /// components are `weights`.
    #[inline(always)]
    fn seen(&self, i: usize, weights: Vec3) -> Vec4 {
        if self.axes == 1 {
            return self.voxels[i];
        }
        let v = &self.voxels[i..i + 3];
        v[0] * weights.x + v[1] * weights.y + v[2] * weights.z
    }

    /// Trilinear interpolation at `p` in voxel units of this level (voxel centres at
    /// i + 0.5), seen along a direction with squared components `weights`.
    #[inline(always)]
    fn trilinear(&self, p: Vec3, weights: Vec3) -> Vec4 {
        let q = p - Vec3::splat(0.5);
        // Floor without a libm call: truncation, one less where that rounded up.
        let truncated = q.as_ivec3();
        let base = glam::IVec3::select(
            q.cmplt(truncated.as_vec3()),
            truncated - glam::IVec3::ONE,
            truncated,
        );
        let f = q - base.as_vec3();
        let (x, y, z) = (base.x as i64, base.y as i64, base.z as i64);
        let lerp = |a: Vec4, b: Vec4, t: f32| a + (b - a) * t;
        let [w, h, d] = self.dims.map(|v| v as i64);
        if x >= 0 && y >= 0 && z >= 0 && x + 1 < w && y + 1 < h && z + 1 < d {
            // All eight neighbours inside: fetched by strides.
            let axes = self.axes;
            let (sx, sy) = (axes, w as usize * axes);
            let sz = sy * h as usize;
            let i = self.index(x as u32, y as u32, z as u32) * axes;
            let corners = [0, sx, sy, sx + sy, sz, sz + sx, sz + sy, sz + sx + sy];
            let c = corners.map(|o| self.seen(i + o, weights));
            let y0 = lerp(lerp(c[0], c[1], f.x), lerp(c[2], c[3], f.x), f.y);
            let y1 = lerp(lerp(c[4], c[5], f.x), lerp(c[6], c[7], f.x), f.y);
            return lerp(y0, y1, f.z);
        }
        let at = |xx: i64, yy: i64, zz: i64| self.get(xx, yy, zz, weights);
        let row = |yy: i64, zz: i64| lerp(at(x, yy, zz), at(x + 1, yy, zz), f.x);
        let plane = |zz: i64| lerp(row(y, zz), row(y + 1, zz), f.y);
        lerp(plane(z), plane(z + 1), f.z)
    }

    /// The next coarser level: seen along each axis, each voxel is the mean over the
    /// four columns of the 2 x 2 x 2 voxels below it of the two composited (in both
    /// orders, averaged: radiance does not depend on the side it is seen from).
    fn downsample(&self) -> VoxelLevel {
        let dims = self.dims.map(|d| d.div_ceil(2));
        let mut coarse = VoxelLevel::empty(dims, 3);
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let base = [2 * x as i64, 2 * y as i64, 2 * z as i64];
                    let i = coarse.index(x, y, z) * 3;
                    for axis in 0..3 {
                        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                        let mut sum = Vec4::ZERO;
                        for column in 0..4 {
                            let mut c = base;
                            c[u] += column & 1;
                            c[v] += column >> 1;
                            let front = self.along(c[0], c[1], c[2], axis);
                            c[axis] += 1;
                            let back = self.along(c[0], c[1], c[2], axis);
                            let over = |a: Vec4, b: Vec4| a + b * (1.0 - a.w);
                            sum += (over(front, back) + over(back, front)) * 0.5;
                        }
                        coarse.voxels[i + axis] = sum * 0.25;
                    }
                }
            }
        }
        coarse
    }
}

/// A mip-mapped voxel volume (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelVolume {
    /// World position of the outer corner of voxel (0, 0, 0).
    pub origin: Vec3,
    /// Edge of a finest-level voxel (metres); level l's voxels are 2^l times as wide.
    pub voxel_size: f32,
    /// The finest level first; empty for a volume that holds nothing.
    pub levels: Vec<VoxelLevel>,
}

/// What a cone met in a volume: the radiance it gathered (premultiplied: the sum of
/// each sample's radiance times its share of the view), its opacity A (1 - alpha of
/// eq. 6), and the distance at which A first reached one half (infinite if never).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConeMarch {
    pub radiance: Vec3,
    pub opacity: f32,
    pub t_half: f32,
}

impl ConeMarch {
    /// A cone that met nothing.
    pub const CLEAR: ConeMarch = ConeMarch {
        radiance: Vec3::ZERO,
        opacity: 0.0,
        t_half: f32::INFINITY,
    };
}

impl VoxelVolume {
    /// A volume that holds nothing: every cone through it stays clear.
    pub fn empty() -> VoxelVolume {
        VoxelVolume {
            origin: Vec3::ZERO,
            voxel_size: 1.0,
            levels: Vec::new(),
        }
    }

    /// True when no level exists (nothing was added).
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// Voxels along each side of the finest level.
    pub fn dims(&self) -> [u32; 3] {
        self.levels.first().map_or([0; 3], |l| l.dims)
    }

    /// The scene volume of `positions` with their `radiances` (see the module docs):
    /// finest voxels `voxel_size` wide over the finite samples' bounds, grown so that
    /// no side has more than [`MAX_DIM`] voxels. Samples with a non-finite position or
    /// radiance are skipped.
    pub fn from_points(
        positions: &[Vec3],
        radiances: &[Vec3],
        voxel_size: f32,
    ) -> Result<VoxelVolume, VoxelError> {
        if !(voxel_size.is_finite() && voxel_size > 0.0) {
            return Err(VoxelError::VoxelSize(voxel_size));
        }
        if positions.len() != radiances.len() {
            return Err(VoxelError::Lengths(positions.len(), radiances.len()));
        }
        let valid = |i: usize| positions[i].is_finite() && radiances[i].is_finite();
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for i in (0..positions.len()).filter(|&i| valid(i)) {
            lo = lo.min(positions[i]);
            hi = hi.max(positions[i]);
        }
        if !(lo.cmple(hi).all()) {
            return Ok(VoxelVolume::empty());
        }
        let Some((origin, voxel_size, dims)) = grid_over(lo, hi, voxel_size) else {
            return Ok(VoxelVolume::empty());
        };
        let mut finest = VoxelLevel::empty(dims, 1);
        let mut counts = vec![0u32; finest.voxels.len()];
        for i in (0..positions.len()).filter(|&i| valid(i)) {
            let v = ((positions[i] - origin) / voxel_size).floor();
            let c = v.as_uvec3().min(glam::UVec3::from(dims) - 1);
            let k = finest.index(c.x, c.y, c.z);
            finest.voxels[k] += radiances[i].extend(1.0);
            counts[k] += 1;
        }
        for (v, &n) in finest.voxels.iter_mut().zip(&counts) {
            if n > 0 {
                // Mean radiance, opacity 1.
                *v = (v.truncate() / n as f32).extend(1.0);
            }
        }
        Ok(VoxelVolume::with_levels(origin, voxel_size, finest))
    }

    /// A volume from its finest level, with the coarser levels built down to one
    /// voxel.
    pub fn with_levels(origin: Vec3, voxel_size: f32, finest: VoxelLevel) -> VoxelVolume {
        let mut levels = vec![finest];
        while levels.last().is_some_and(|l| l.dims.iter().any(|&d| d > 1)) {
            let next = levels.last().map(VoxelLevel::downsample);
            levels.extend(next);
        }
        VoxelVolume {
            origin,
            voxel_size,
            levels,
        }
    }

    /// The volume's world bounds.
    pub fn bounds(&self) -> Aabb {
        let size = glam::UVec3::from(self.dims()).as_vec3() * self.voxel_size;
        Aabb {
            min: self.origin,
            max: self.origin + size,
        }
    }

    /// Quadrilinear sample at world point `p` for a footprint `lod` levels above the
    /// finest (fractional: the two nearest levels blended), seen along unit `dir`.
    #[inline(always)]
    pub fn sample(&self, p: Vec3, lod: f32, dir: Vec3) -> Vec4 {
        let top = (self.levels.len() - 1) as f32;
        let lod = lod.clamp(0.0, top);
        let l0 = lod as usize; // lod >= 0: truncation floors it.
        let local = (p - self.origin) / self.voxel_size;
        let weights = dir * dir;
        let scale = 1.0 / (1u32 << l0) as f32;
        let s0 = self.levels[l0].trilinear(local * scale, weights);
        let f = lod - l0 as f32;
        if f > 0.0 && l0 + 1 < self.levels.len() {
            let s1 = self.levels[l0 + 1].trilinear(local * (0.5 * scale), weights);
            s0 + (s1 - s0) * f
        } else {
            s0
        }
    }

    /// Marches a cone from `origin` along unit `dir` (see the module docs) over
    /// `t_start <= t <= t_end`, its diameter at t being `max(voxel, 2 t spread)`.
    pub fn march(
        &self,
        origin: Vec3,
        dir: Vec3,
        spread: f32,
        t_start: f32,
        t_end: f32,
    ) -> ConeMarch {
        if self.levels.is_empty() {
            return ConeMarch::CLEAR;
        }
        // The volume grown by a voxel: samples there still blend in its edge voxels.
        let bounds = self.bounds();
        let margin = Vec3::splat(self.voxel_size);
        let grown = Aabb {
            min: bounds.min - margin,
            max: bounds.max + margin,
        };
        let Some((mut t, end)) = grown.ray_span(origin, dir.recip(), t_start, t_end) else {
            return ConeMarch::CLEAR;
        };
        let mut march = ConeMarch::CLEAR;
        let spread = spread.max(0.0);
        while t <= end && march.opacity < OPAQUE {
            let diameter = (2.0 * spread * t).max(self.voxel_size);
            let lod = (diameter / self.voxel_size).log2();
            let s = self.sample(origin + dir * t, lod, dir);
            if s.w > 0.0 {
                let share = 1.0 - march.opacity;
                march.radiance += s.truncate() * share;
                march.opacity += s.w.min(1.0) * share;
                if march.opacity >= 0.5 && march.t_half.is_infinite() {
                    march.t_half = t;
                }
            }
            t += diameter * STEP;
        }
        march
    }
}

/// The grid over [lo, hi]: its origin, voxel size (grown where a side would need more
/// than [`MAX_DIM`] voxels) and dimensions; `None` when the bounds are not finite.
fn grid_over(lo: Vec3, hi: Vec3, voxel_size: f32) -> Option<(Vec3, f32, [u32; 3])> {
    let extent = hi - lo;
    if !extent.is_finite() {
        return None;
    }
    let voxel_size = voxel_size.max(extent.max_element() / (MAX_DIM - 1) as f32);
    let dims = ((extent / voxel_size).floor() + 1.0)
        .min(Vec3::splat(MAX_DIM as f32))
        .as_uvec3();
    // Centre the samples' bounds in the grid.
    let size = dims.as_vec3() * voxel_size;
    let origin = (lo + hi) * 0.5 - size * 0.5;
    Some((origin, voxel_size, dims.to_array()))
}

#[cfg(test)]
mod tests;
