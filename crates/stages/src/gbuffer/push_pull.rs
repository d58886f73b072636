//! Hole filling of the splatted G-buffer by push-pull (paper 000 Sec. 3, after
//! Marroquim et al. \[31\] and Gortler et al.'s pull-push): depth, color and normal together.
//!
//! - Pull: each texel of level k + 1 is the weighted mean of its valid 2x2 children of
//!   level k, a child's weight being the number of valid level-0 pixels below it (so a
//!   coarse texel is the mean of the valid pixels it covers).
//! - Push, from the coarsest level down: each hole of level k takes the bilinear
//!   interpolation (weights 9/16, 3/16, 3/16, 1/16) of the valid texels of level k + 1
//!   around it, renormalized over the valid ones. Valid pixels are never touched.
//!
//! At most `max_levels` coarser levels are built: a hole that no texel of those levels
//! reaches stays empty (coverage 0). Filled normals are renormalized and turned towards
//! the camera.

use super::buffer::{COVERAGE_FILLED, GBuffer};
use crate::OpError;
use glam::Vec3;
use rayon::prelude::*;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{depth_is_valid, upsample_taps as taps};

/// One texel of a coarse level; a hole has depth 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Texel {
    depth: f32,
    color: Vec3,
    /// Mean of the unit normals below (not renormalized until level 0).
    normal: Vec3,
    /// Valid level-0 pixels below this texel (0 for texels filled by the push).
    weight: f32,
}

impl Texel {
    #[inline]
    fn is_valid(&self) -> bool {
        self.depth > 0.0
    }
}

#[derive(Clone, Debug, Default)]
struct Level {
    width: usize,
    height: usize,
    texels: Vec<Texel>,
}

/// The coarse levels, kept across frames to avoid reallocation.
#[derive(Clone, Debug, Default)]
pub struct Pyramid {
    levels: Vec<Level>,
}

/// A running weighted sum of texels.
#[derive(Clone, Copy, Default)]
struct Sum {
    depth: f32,
    color: Vec3,
    normal: Vec3,
    weight: f32,
}

impl Sum {
    #[inline]
    fn add(&mut self, w: f32, depth: f32, color: Vec3, normal: Vec3) {
        self.depth += w * depth;
        self.color += w * color;
        self.normal += w * normal;
        self.weight += w;
    }

    /// The weighted mean; `weight` is what the texel records.
    #[inline]
    fn mean(&self, weight: f32) -> Texel {
        if self.weight > 0.0 {
            let inv = 1.0 / self.weight;
            Texel {
                depth: self.depth * inv,
                color: self.color * inv,
                normal: self.normal * inv,
                weight,
            }
        } else {
            Texel::default()
        }
    }
}

/// The bilinear interpolation at fine pixel (x, y) over the valid texels of `coarse`.
#[inline]
fn interpolate(coarse: &Level, x: usize, y: usize) -> Sum {
    let mut sum = Sum::default();
    for (cy, wy) in taps(y, coarse.height) {
        let row = &coarse.texels[cy * coarse.width..(cy + 1) * coarse.width];
        for (cx, wx) in taps(x, coarse.width) {
            let t = &row[cx];
            let w = wx * wy;
            if w > 0.0 && t.is_valid() {
                sum.add(w, t.depth, t.color, t.normal);
            }
        }
    }
    sum
}

/// Fills the holes (depth not valid) of `gbuffer` by push-pull over at most `max_levels`
/// coarser levels; filled pixels get coverage [`COVERAGE_FILLED`], holes that stay
/// keep theirs. Pixels with valid depth are left bit-identical. `camera` (the
/// G-buffer's size) turns filled normals towards the viewer.
pub fn push_pull(
    gbuffer: &mut GBuffer,
    camera: &Pinhole,
    max_levels: usize,
    pyramid: &mut Pyramid,
) -> Result<(), OpError> {
    let (w, h) = (gbuffer.width() as usize, gbuffer.height() as usize);
    if (camera.width as usize, camera.height as usize) != (w, h) || !gbuffer.is_consistent() {
        return Err(OpError::SizeMismatch(format!(
            "G-buffer is {w}x{h}, camera is {}x{}",
            camera.width, camera.height
        )));
    }
    if w == 0 || h == 0 || max_levels == 0 {
        return Ok(());
    }
    // Level sizes: halve (rounding up) until 1x1 or max_levels.
    let mut sizes = Vec::new();
    let (mut lw, mut lh) = (w, h);
    while sizes.len() < max_levels && (lw > 1 || lh > 1) {
        (lw, lh) = (lw.div_ceil(2), lh.div_ceil(2));
        sizes.push((lw, lh));
    }
    let levels = &mut pyramid.levels;
    levels.resize_with(sizes.len(), Level::default);
    for (level, &(lw, lh)) in levels.iter_mut().zip(&sizes) {
        level.width = lw;
        level.height = lh;
        level.texels.resize(lw * lh, Texel::default());
    }
    if levels.is_empty() {
        return Ok(());
    }
    pull_from_gbuffer(gbuffer, &mut levels[0]);
    for k in 1..levels.len() {
        let (fine, coarse) = levels.split_at_mut(k);
        pull(&fine[k - 1], &mut coarse[0]);
    }
    for k in (1..levels.len()).rev() {
        let (fine, coarse) = levels.split_at_mut(k);
        push(&coarse[0], &mut fine[k - 1]);
    }
    push_into_gbuffer(&levels[0], camera, gbuffer);
    Ok(())
}

/// Level 1 from the G-buffer: mean of the valid pixels of each 2x2 block.
fn pull_from_gbuffer(g: &GBuffer, out: &mut Level) {
    let (w, h) = (g.width() as usize, g.height() as usize);
    let width = out.width;
    out.texels
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, texel) in row.iter_mut().enumerate() {
                let mut sum = Sum::default();
                for fy in 2 * y..(2 * y + 2).min(h) {
                    for fx in 2 * x..(2 * x + 2).min(w) {
                        let i = fy * w + fx;
                        let d = g.depth.data[i];
                        if depth_is_valid(d) {
                            sum.add(1.0, d, g.color.data[i], g.normals.data[i]);
                        }
                    }
                }
                *texel = sum.mean(sum.weight);
            }
        });
}

/// Level k + 1 from level k: weighted mean of the valid children.
fn pull(fine: &Level, coarse: &mut Level) {
    let width = coarse.width;
    coarse
        .texels
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, texel) in row.iter_mut().enumerate() {
                let mut sum = Sum::default();
                for fy in 2 * y..(2 * y + 2).min(fine.height) {
                    for fx in 2 * x..(2 * x + 2).min(fine.width) {
                        let t = &fine.texels[fy * fine.width + fx];
                        if t.is_valid() {
                            sum.add(t.weight, t.depth, t.color, t.normal);
                        }
                    }
                }
                *texel = sum.mean(sum.weight);
            }
        });
}

/// Fills the holes of level k from level k + 1.
fn push(coarse: &Level, fine: &mut Level) {
    let width = fine.width;
    fine.texels
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, texel) in row.iter_mut().enumerate() {
                if !texel.is_valid() {
                    *texel = interpolate(coarse, x, y).mean(0.0);
                }
            }
        });
}

/// Fills the holes of the G-buffer from level 1.
fn push_into_gbuffer(coarse: &Level, camera: &Pinhole, g: &mut GBuffer) {
    let w = g.width() as usize;
    g.par_bands_mut(1).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            if depth_is_valid(row.depth[x]) {
                continue;
            }
            let t = interpolate(coarse, x, y).mean(0.0);
            if !t.is_valid() {
                continue;
            }
            let n = t.normal.normalize_or_zero();
            let facing = n.dot(camera.ray(x as f32, y as f32)) > 0.0;
            row.depth[x] = t.depth;
            row.color[x] = t.color;
            row.normals[x] = if facing { -n } else { n };
            row.coverage[x] = COVERAGE_FILLED;
        }
    });
}

#[cfg(test)]
mod tests {
    use super::super::buffer::{COVERAGE_NONE, COVERAGE_SPLAT};
    use super::*;
    use relume_base::rng;
    use relume_recording::Intrinsics;

    const W: u32 = 45;
    const H: u32 = 31;

    fn camera() -> Pinhole {
        Pinhole::new(&Intrinsics::PRIMESENSE, W, H)
    }

    /// A G-buffer with smoothly varying values where `keep(x, y)`, holes elsewhere.
    fn masked(keep: impl Fn(u32, u32) -> bool) -> GBuffer {
        let mut g = GBuffer::new(W, H);
        for y in 0..H {
            for x in 0..W {
                if keep(x, y) {
                    let i = (y * W + x) as usize;
                    g.depth.data[i] = 1.0 + 0.01 * x as f32 + 0.003 * y as f32;
                    g.color.data[i] = Vec3::new(x as f32 / W as f32, y as f32 / H as f32, 0.3);
                    g.normals.data[i] =
                        Vec3::new(0.1 * (x as f32 / W as f32), 0.05, -1.0).normalize();
                    g.coverage.data[i] = COVERAGE_SPLAT;
                }
            }
        }
        g
    }

    #[test]
    fn fills_every_hole_and_leaves_valid_pixels_bit_identical() {
        let keep = |x: u32, y: u32| rng::unit_f32(rng::hash(&[3, x as u64, y as u64])) < 0.2;
        let before = masked(keep);
        let mut g = masked(keep);
        push_pull(&mut g, &camera(), 16, &mut Pyramid::default()).unwrap();
        let (b, a) = (before.bits(), g.bits());
        for i in 0..(W * H) as usize {
            if before.coverage.data[i] == COVERAGE_SPLAT {
                assert_eq!(a[i], b[i], "valid pixel {i} unchanged");
            } else {
                assert_eq!(g.coverage.data[i], COVERAGE_FILLED, "pixel {i}");
                assert!(depth_is_valid(g.depth.data[i]) && g.color.data[i].is_finite());
                let n = g.normals.data[i];
                assert!(
                    (n.length() - 1.0).abs() < 1e-5 && n.z < 0.0,
                    "unit, facing: {n:?}"
                );
                // Filled values stay within the range of the valid ones.
                assert!((1.0..=1.6).contains(&g.depth.data[i]));
            }
        }
    }

    #[test]
    fn a_constant_image_stays_constant() {
        let mut g = GBuffer::new(W, H);
        let n = Vec3::new(0.2, -0.1, -1.0).normalize();
        for i in 0..(W * H) as usize {
            if i % 7 == 0 || i % 11 == 3 {
                g.depth.data[i] = 2.5;
                g.color.data[i] = Vec3::new(0.3, 0.7, 1.1);
                g.normals.data[i] = n;
            }
        }
        push_pull(&mut g, &camera(), 16, &mut Pyramid::default()).unwrap();
        for i in 0..(W * H) as usize {
            assert!((g.depth.data[i] - 2.5).abs() < 1e-6, "{i}");
            assert!((g.color.data[i] - Vec3::new(0.3, 0.7, 1.1)).length() < 1e-6);
            assert!((g.normals.data[i] - n).length() < 1e-6);
        }
    }

    #[test]
    fn a_single_pixel_fills_the_whole_image() {
        let mut g = masked(|x, y| (x, y) == (40, 3));
        push_pull(&mut g, &camera(), 16, &mut Pyramid::default()).unwrap();
        let expected = 1.0 + 0.01 * 40.0 + 0.003 * 3.0;
        assert!(g.depth.data.iter().all(|&d| (d - expected).abs() < 1e-6));
        assert!(g.coverage.data.iter().all(|&c| c != COVERAGE_NONE));
    }

    #[test]
    fn holes_beyond_the_fill_levels_stay_empty() {
        // Only columns 0..3 are valid. Level 1 holds columns 0..2 (fine 0..4), level 2
        // column 0; the push fills level-1 column 2 from it, then fine columns 3..7.
        let mut g = masked(|x, _| x < 3);
        push_pull(&mut g, &camera(), 2, &mut Pyramid::default()).unwrap();
        for y in 0..H as usize {
            assert_eq!(g.coverage.data[y * W as usize + 6], COVERAGE_FILLED);
            for x in 7..W as usize {
                let i = y * W as usize + x;
                assert_eq!(g.coverage.data[i], COVERAGE_NONE);
                assert_eq!(g.depth.data[i], 0.0);
                assert!(g.color.data[i].is_nan());
            }
        }
        let mut none = masked(|x, _| x < 3);
        push_pull(&mut none, &camera(), 0, &mut Pyramid::default()).unwrap();
        assert_eq!(
            none.bits(),
            masked(|x, _| x < 3).bits(),
            "0 levels: no change"
        );
    }

    #[test]
    fn all_invalid_and_empty_images_do_not_panic() {
        let mut g = GBuffer::new(W, H);
        push_pull(&mut g, &camera(), 8, &mut Pyramid::default()).unwrap();
        assert!(g.coverage.data.iter().all(|&c| c == COVERAGE_NONE));
        let mut empty = GBuffer::new(0, 0);
        let cam = Pinhole::new(&Intrinsics::PRIMESENSE, 0, 0);
        push_pull(&mut empty, &cam, 8, &mut Pyramid::default()).unwrap();
        assert!(push_pull(&mut g, &cam, 8, &mut Pyramid::default()).is_err());
    }

    #[test]
    fn deterministic_for_any_thread_count() {
        let keep = |x: u32, y: u32| rng::unit_f32(rng::hash(&[5, x as u64, y as u64])) < 0.1;
        let run = || {
            let mut g = masked(keep);
            push_pull(&mut g, &camera(), 16, &mut Pyramid::default()).unwrap();
            g
        };
        let a = relume_base::threads::with_threads(1, run);
        let b = relume_base::threads::with_threads(3, run);
        assert_eq!(a.bits(), b.bits());
    }
}
