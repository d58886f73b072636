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

impl Pyramid {
    /// Builds `levels` levels (at least 1) from a frame's `color` and `depth` (same size)
    /// seen through `intrinsics`; each level at most half as wide as the one below and
    /// at least 8 x 8 pixels (fewer levels when the image is small). The finest level's
    /// normals are made only at every `fine_stride`-th pixel in x and y (1: all), the
    /// pixels a frame is aligned by (its normals cost the pyramid a third of its time).
    pub fn build(
        intrinsics: &Intrinsics,
        color: &Rgb8Image,
        depth: &DepthImage,
        levels: usize,
        fine_stride: usize,
    ) -> Pyramid {
        let (w, h) = (color.width as usize, color.height as usize);
        let mut out = Pyramid::default();
        for (lw, lh) in level_sizes(w, h, levels) {
            let intensity: Vec<f32> = match out.levels.last() {
                None => color.data.par_iter().map(|c| luma(*c)).collect(),
                Some(below) => halve_intensity(&below.intensity, below.width, below.height),
            };
            let gradient = gradient_of(&intensity, lw, lh);
            out.levels.push(Level {
                camera: Pinhole::new(intrinsics, lw as u32, lh as u32),
                width: lw,
                height: lh,
                points: Vec::new(),
                normals: Vec::new(),
                intensity,
                gradient,
            });
        }
        out.with_depth_every(depth, fine_stride)
    }

    /// This pyramid's intensity and gradient with the points and normals of another
    /// `depth` of the same view and size (the tracker's model: the fused depth seen
    /// from the frame whose color it keeps).
    pub fn with_depth(self, depth: &DepthImage) -> Pyramid {
        self.with_depth_every(depth, 1)
    }

    /// [`Pyramid::with_depth`] with the finest level's normals at every `fine_stride`-th
    /// pixel in x and y only (zero elsewhere).
    fn with_depth_every(mut self, depth: &DepthImage, fine_stride: usize) -> Pyramid {
        let mut z: Vec<f32> = depth
            .data
            .iter()
            .map(|&z| if depth_is_valid(z) { z } else { 0.0 })
            .collect();
        for l in 0..self.levels.len() {
            if l > 0 {
                let below = &self.levels[l - 1];
                z = halve_depth(&z, below.width, below.height);
            }
            let level = &mut self.levels[l];
            let every = if l == 0 { fine_stride.max(1) } else { 1 };
            (level.points, level.normals) =
                geometry_of(&z, level.width, level.height, &level.camera, every);
        }
        self
    }
}

/// The sizes of up to `levels` levels (at least 1) of a `w` x `h` image: each half the
/// one below (a last odd row or column dropped), none under 8 x 8.
fn level_sizes(w: usize, h: usize, levels: usize) -> Vec<(usize, usize)> {
    let mut sizes = vec![(w, h)];
    while sizes.len() < levels.max(1) {
        let (w, h) = *sizes.last().expect("one level");
        if w / 2 < 8 || h / 2 < 8 {
            break;
        }
        sizes.push((w / 2, h / 2));
    }
    sizes
}

/// Rec. 601 luma of an 8-bit sRGB color, in [0, 1].
pub fn luma(c: [u8; 3]) -> f32 {
    (0.299 * c[0] as f32 + 0.587 * c[1] as f32 + 0.114 * c[2] as f32) / 255.0
}

/// The next level's intensity: the mean of each 2 x 2 block (a last odd row or column
/// is dropped).
fn halve_intensity(intensity: &[f32], width: usize, height: usize) -> Vec<f32> {
    let (w, h) = (width / 2, height / 2);
    let mut out = vec![0.0f32; w * h];
    for (y, row) in out.chunks_mut(w.max(1)).enumerate().take(h) {
        let (a, b) = (
            &intensity[2 * y * width..],
            &intensity[(2 * y + 1) * width..],
        );
        for (x, o) in row.iter_mut().enumerate() {
            *o = (a[2 * x] + a[2 * x + 1] + b[2 * x] + b[2 * x + 1]) * 0.25;
        }
    }
    out
}

/// The next level's depth: the mean of each 2 x 2 block's valid depths when they lie
/// within [`BLOCK_SPREAD`] of it, else missing (0).
fn halve_depth(depth: &[f32], width: usize, height: usize) -> Vec<f32> {
    let (w, h) = (width / 2, height / 2);
    let mut out = vec![0.0f32; w * h];
    for (y, row) in out.chunks_mut(w.max(1)).enumerate().take(h) {
        for (x, o) in row.iter_mut().enumerate() {
            let idx = [
                2 * y * width + 2 * x,
                2 * y * width + 2 * x + 1,
                (2 * y + 1) * width + 2 * x,
                (2 * y + 1) * width + 2 * x + 1,
            ];
            let (mut sum, mut n, mut lo, mut hi) = (0.0f32, 0u32, f32::INFINITY, 0.0f32);
            for &i in &idx {
                let z = depth[i];
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
                    *o = mean;
                }
            }
        }
    }
    out
}

/// The intensity gradient of a `w` x `h` level: central differences, zero on the border.
fn gradient_of(g: &[f32], w: usize, h: usize) -> Vec<[f32; 2]> {
    let mut gradient = vec![[0.0f32; 2]; w * h];
    gradient
        .par_chunks_mut(w.max(1))
        .enumerate()
        .filter(|(y, _)| *y >= 1 && *y + 1 < h)
        .for_each(|(y, row)| {
            let inner = 1..w.saturating_sub(1).max(1);
            for (x, d) in inner.clone().zip(&mut row[inner]) {
                let i = y * w + x;
                *d = [(g[i + 1] - g[i - 1]) * 0.5, (g[i + w] - g[i - w]) * 0.5];
            }
        });
    gradient
}

/// Points and normals of a `w` x `h` level's depth (rows in parallel), normals at every
/// `every`-th pixel in x and y.
fn geometry_of(
    depth: &[f32],
    w: usize,
    h: usize,
    camera: &Pinhole,
    every: usize,
) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut points = vec![Vec3::ZERO; w * h];
    points
        .par_chunks_mut(w.max(1))
        .zip(depth.par_chunks(w.max(1)))
        .enumerate()
        .for_each(|(y, (row, depth))| {
            for (x, (p, &z)) in row.iter_mut().zip(depth).enumerate() {
                if z > 0.0 {
                    *p = camera.back_project(x as f32, y as f32, z);
                }
            }
        });
    let mut normals = vec![Vec3::ZERO; w * h];
    normals
        .par_chunks_mut(w.max(1))
        .enumerate()
        .filter(|(y, _)| *y >= 1 && *y + 1 < h && y % every == 0)
        .for_each(|(y, row)| {
            for x in (every..w.saturating_sub(1)).step_by(every) {
                row[x] = normal_at(&points, w, y * w + x);
            }
        });
    (points, normals)
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
        let p = Pyramid::build(&k, &color, &depth, 3, 1);
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
        let p = Pyramid::build(&k, &color, &depth, 2, 1);
        let l1 = &p.levels[1];
        // Block x = 4 covers columns 8 and 9: 1 m and 3 m.
        assert_eq!(l1.points[4 * 8 + 4], Vec3::ZERO);
        assert!((l1.points[4 * 8 + 3].z - 1.0).abs() < 1e-6);
        assert!((l1.points[4 * 8 + 5].z - 3.0).abs() < 1e-6);
    }
}
