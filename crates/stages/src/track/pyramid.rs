//! The image pyramid the tracker aligns on: per level, camera-space points, normals,
//! intensity and its gradient, each level half the size of the one below (KinectFusion,
//! Newcombe et al. 2011, Sec. 3.1: a three-level pyramid of vertex and normal maps).
//!
//! Depth halves by 2 x 2 blocks: the mean of the block's valid depths when they lie
//! within [`BLOCK_SPREAD`] of each other (one surface), else missing, so that a level never
//! invents a point between a foreground edge and the background behind it. Intensity
//! (Rec. 601 luma of the 8-bit sRGB color, in [0, 1], as Open3D's RGB-D odometry uses)
//! halves by the plain 2 x 2 mean. Normals come from the cross product of central
//! differences of the points (KinectFusion eq. 2), missing where a neighbour is missing
//! or lies beyond [`EDGE_JUMP`] of the pixel's depth.

use glam::Vec3;
use rayon::prelude::*;
use relume_base::pinhole::{Intrinsics, Pinhole};
use relume_base::raster::{DepthImage, Rgb8Image, depth_is_valid};

/// Depths of a 2 x 2 block closer than this fraction of their mean are one surface.
pub const BLOCK_SPREAD: f32 = 0.03;
/// A neighbour whose depth differs from the pixel's by more than this fraction lies
/// across a depth edge: no normal there.
pub const EDGE_JUMP: f32 = 0.05;

/// One level of the pyramid. Pixel `i` is at (i % width, i / width); a missing point is
/// [`Vec3::ZERO`] (z = 0), a missing normal likewise.
#[derive(Clone, Debug)]
pub struct Level {
    pub camera: Pinhole,
    pub width: usize,
    pub height: usize,
    pub points: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub intensity: Vec<f32>,
    /// Intensity gradient per pixel (d/du, d/dv), central differences; zero on the border.
    pub gradient: Vec<[f32; 2]>,
}

/// A pyramid of [`Level`]s, finest first.
#[derive(Clone, Debug, Default)]
pub struct Pyramid {
    pub levels: Vec<Level>,
}

/// Depth and intensity of one level before points and normals are derived.
struct Raw {
    width: usize,
    height: usize,
    depth: Vec<f32>,
    intensity: Vec<f32>,
}

impl Pyramid {
    /// Builds `levels` levels (at least 1) from a frame's `color` and `depth` (same size)
    /// seen through `intrinsics`; each level at most half as wide as the one below and
    /// at least 8 x 8 pixels (fewer levels when the image is small).
    pub fn build(
        intrinsics: &Intrinsics,
        color: &Rgb8Image,
        depth: &DepthImage,
        levels: usize,
    ) -> Pyramid {
        let (w, h) = (depth.width as usize, depth.height as usize);
        let mut raw = Raw {
            width: w,
            height: h,
            depth: depth
                .data
                .iter()
                .map(|&z| if depth_is_valid(z) { z } else { 0.0 })
                .collect(),
            intensity: color.data.par_iter().map(|c| luma(*c)).collect(),
        };
        let mut out = Pyramid::default();
        for l in 0..levels.max(1) {
            if l > 0 {
                if raw.width / 2 < 8 || raw.height / 2 < 8 {
                    break;
                }
                raw = halve(&raw);
            }
            let camera = Pinhole::new(intrinsics, raw.width as u32, raw.height as u32);
            out.levels.push(level_of(&raw, camera));
        }
        out
    }
}

/// Rec. 601 luma of an 8-bit sRGB color, in [0, 1].
pub fn luma(c: [u8; 3]) -> f32 {
    (0.299 * c[0] as f32 + 0.587 * c[1] as f32 + 0.114 * c[2] as f32) / 255.0
}

/// The next level: 2 x 2 blocks (a last odd row or column is dropped).
fn halve(raw: &Raw) -> Raw {
    let (w, h) = (raw.width / 2, raw.height / 2);
    let mut depth = vec![0.0f32; w * h];
    let mut intensity = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let idx = [
                2 * y * raw.width + 2 * x,
                2 * y * raw.width + 2 * x + 1,
                (2 * y + 1) * raw.width + 2 * x,
                (2 * y + 1) * raw.width + 2 * x + 1,
            ];
            intensity[y * w + x] = idx.iter().map(|&i| raw.intensity[i]).sum::<f32>() * 0.25;
            let (mut sum, mut n, mut lo, mut hi) = (0.0f32, 0u32, f32::INFINITY, 0.0f32);
            for &i in &idx {
                let z = raw.depth[i];
                if z > 0.0 {
                    sum += z;
                    n += 1;
                    lo = lo.min(z);
                    hi = hi.max(z);
                }
            }
            if n > 0 {
                let mean = sum / n as f32;
                if hi - lo <= BLOCK_SPREAD * mean {
                    depth[y * w + x] = mean;
                }
            }
        }
    }
    Raw {
        width: w,
        height: h,
        depth,
        intensity,
    }
}

/// Points, normals and the intensity gradient of one level (rows in parallel).
fn level_of(raw: &Raw, camera: Pinhole) -> Level {
    let (w, h) = (raw.width, raw.height);
    let mut points = vec![Vec3::ZERO; w * h];
    points
        .par_chunks_mut(w.max(1))
        .zip(raw.depth.par_chunks(w.max(1)))
        .enumerate()
        .for_each(|(y, (row, depth))| {
            for (x, (p, &z)) in row.iter_mut().zip(depth).enumerate() {
                if z > 0.0 {
                    *p = camera.back_project(x as f32, y as f32, z);
                }
            }
        });
    let mut normals = vec![Vec3::ZERO; w * h];
    let mut gradient = vec![[0.0f32; 2]; w * h];
    normals
        .par_chunks_mut(w.max(1))
        .zip(gradient.par_chunks_mut(w.max(1)))
        .enumerate()
        .filter(|(y, _)| *y >= 1 && *y + 1 < h)
        .for_each(|(y, (normal_row, gradient_row))| {
            let g = &raw.intensity;
            for x in 1..w.saturating_sub(1) {
                let i = y * w + x;
                gradient_row[x] = [(g[i + 1] - g[i - 1]) * 0.5, (g[i + w] - g[i - w]) * 0.5];
                normal_row[x] = normal_at(&points, w, i);
            }
        });
    Level {
        camera,
        width: w,
        height: h,
        points,
        normals,
        intensity: raw.intensity.clone(),
        gradient,
    }
}

/// The normal at inner pixel `i` of a `w`-wide point map: the cross product of central
/// differences, facing the camera; zero at a missing point or across a depth edge.
#[inline]
fn normal_at(points: &[Vec3], w: usize, i: usize) -> Vec3 {
    let p = points[i];
    if p.z <= 0.0 {
        return Vec3::ZERO;
    }
    let near = |q: Vec3| q.z > 0.0 && (q.z - p.z).abs() <= EDGE_JUMP * p.z;
    let (l, r, u, d) = (points[i - 1], points[i + 1], points[i - w], points[i + w]);
    if !(near(l) && near(r) && near(u) && near(d)) {
        return Vec3::ZERO;
    }
    let n = (r - l).cross(d - u);
    let len = n.length();
    if len > 0.0 {
        let n = n / len;
        if n.dot(p) > 0.0 { -n } else { n }
    } else {
        Vec3::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::raster::Image;

    #[test]
    fn a_plane_gives_its_normal_and_levels_halve_with_their_camera() {
        // A wall 2 m ahead, tilted: z = 2 + 0.5 x.
        let k = Intrinsics::PRIMESENSE.scaled_to(64, 48);
        let cam = Pinhole::new(&k, 64, 48);
        let mut depth = Image::filled(64, 48, 0.0f32);
        for y in 0..48 {
            for x in 0..64 {
                let r = cam.ray(x as f32, y as f32);
                // Point r z on the plane z = 2 + 0.5 X: z = 2 / (1 - 0.5 r.x).
                depth.data[y * 64 + x] = 2.0 / (1.0 - 0.5 * r.x);
            }
        }
        let color = Image::filled(64, 48, [128u8, 128, 128]);
        let p = Pyramid::build(&k, &color, &depth, 3);
        assert_eq!(p.levels.len(), 3);
        assert_eq!((p.levels[2].width, p.levels[2].height), (16, 12));
        let want = Vec3::new(0.5, 0.0, -1.0).normalize();
        for level in &p.levels {
            let w = level.width;
            let i = (level.height / 2) * w + w / 2;
            assert!(
                (level.normals[i] - want).length() < 1e-3,
                "{}",
                level.normals[i]
            );
            // The halved depth still lies on the plane.
            let q = level.points[i];
            assert!((q.z - (2.0 + 0.5 * q.x)).abs() < 1e-3, "{q}");
        }
    }

    #[test]
    fn blocks_across_a_depth_edge_are_missing_not_averaged() {
        let k = Intrinsics::PRIMESENSE.scaled_to(16, 16);
        let mut depth = Image::filled(16, 16, 1.0f32);
        for y in 0..16 {
            for x in 9..16 {
                depth.data[y * 16 + x] = 3.0;
            }
        }
        let color = Image::filled(16, 16, [0u8, 0, 0]);
        let p = Pyramid::build(&k, &color, &depth, 2);
        let l1 = &p.levels[1];
        // Block x = 4 covers columns 8 and 9: 1 m and 3 m.
        assert_eq!(l1.points[4 * 8 + 4], Vec3::ZERO);
        assert!((l1.points[4 * 8 + 3].z - 1.0).abs() < 1e-6);
        assert!((l1.points[4 * 8 + 5].z - 3.0).abs() < 1e-6);
    }
}
