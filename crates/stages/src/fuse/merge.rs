//! The merging step of paper 002 Sec. 4.2: the warped depth and weight of the previous
//! frame meet the new sensor depth per pixel, as in KinectFusion's weighted running
//! average (Newcombe et al., the paper's ref. 26).

use crate::OpError;
use rayon::prelude::*;
use relume_base::raster::{DepthImage, ScalarImage, depth_is_valid};

/// Parameters of [`merge_depth`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MergeParams {
    /// The new and the warped depth agree (same surface) when they differ by at most
    /// this fraction of the new depth.
    pub agreement: f32,
    /// Cap of the weight: the running average never gives a new measurement less than
    /// 1 / (max_weight + 1), so the map follows slow drift.
    pub max_weight: f32,
    /// Where the new depth has a hole, the warped depth is kept only when its weight is
    /// at least this.
    pub min_fill_weight: f32,
    /// A warped value kept over a hole keeps its weight times this factor, so values
    /// that are never measured again fade out of the map.
    pub fill_decay: f32,
    /// A hole is not filled from the warped map where a new measurement within this many
    /// pixels lies in front of the warped depth (nearer by more than `agreement`): a
    /// nearer object may have moved over that spot with its rim unmeasured, and the
    /// warped background would show through it. 0 turns the test off and fills every
    /// hole as paper 002 does; this test is an addition to the paper.
    pub occlusion_radius: usize,
}

impl Default for MergeParams {
    fn default() -> Self {
        MergeParams {
            agreement: 0.05,
            max_weight: 20.0,
            min_fill_weight: 2.0,
            fill_decay: 0.9,
            occlusion_radius: 2,
        }
    }
}

/// Merges the warped previous map with `new_depth` into `fused_depth` and
/// `fused_weight` (all the same size), per pixel:
/// - both valid and `|d_new - d_warp| <= agreement * d_new`: d = (w d_warp + d_new) /
///   (w + 1), weight min(w + 1, max_weight);
/// - new valid, warped missing or disagreeing (another surface, paper 002): d = d_new,
///   weight 1;
/// - new missing, warped weight >= `min_fill_weight`, and no new depth within
///   `occlusion_radius` pixels in front of the warped one: the warped depth, weight
///   w * `fill_decay`;
/// - otherwise 0 with weight 0.
///
/// Warped depth counts as missing where its weight is not positive. With an empty
/// warped map this is the first frame: the new depth with weight 1 where valid.
pub fn merge_depth(
    warped_depth: &DepthImage,
    warped_weight: &ScalarImage,
    new_depth: &DepthImage,
    params: &MergeParams,
    fused_depth: &mut DepthImage,
    fused_weight: &mut ScalarImage,
) -> Result<(), OpError> {
    let sizes = [
        (warped_weight.width, warped_weight.height),
        (new_depth.width, new_depth.height),
        (fused_depth.width, fused_depth.height),
        (fused_weight.width, fused_weight.height),
    ];
    if sizes
        .iter()
        .any(|&s| s != (warped_depth.width, warped_depth.height))
    {
        return Err(OpError::SizeMismatch(format!(
            "depth merge: warped depth is {}x{}, but (warped weight, new depth, fused \
             depth, fused weight) are {sizes:?}",
            warped_depth.width, warped_depth.height
        )));
    }
    let p = *params;
    let row = new_depth.width.max(1) as usize;
    let height = new_depth.height as usize;
    let new_all = &new_depth.data;
    fused_depth
        .data
        .par_chunks_mut(row)
        .zip(fused_weight.data.par_chunks_mut(row))
        .zip(
            warped_depth
                .data
                .par_chunks(row)
                .zip(warped_weight.data.par_chunks(row)),
        )
        .enumerate()
        .for_each(|(y, ((out_d, out_w), (warp_d, warp_w)))| {
            let new = &new_all[y * row..(y + 1) * row];
            for (x, (((d, w), &d_warp), &w_warp)) in out_d
                .iter_mut()
                .zip(out_w.iter_mut())
                .zip(warp_d)
                .zip(warp_w)
                .enumerate()
            {
                (*d, *w) = merge_pixel(new[x], d_warp, w_warp, &p);
                if p.occlusion_radius > 0
                    && *d > 0.0
                    && !depth_is_valid(new[x])
                    && occluded(new_all, row, height, x, y, d_warp, &p)
                {
                    (*d, *w) = (0.0, 0.0);
                }
            }
        });
    Ok(())
}

/// True when a valid new depth within `occlusion_radius` pixels of hole (x, y) lies in
/// front of `d_warp` by more than `agreement` (relative to the new depth).
#[inline]
fn occluded(
    new: &[f32],
    width: usize,
    height: usize,
    x: usize,
    y: usize,
    d_warp: f32,
    p: &MergeParams,
) -> bool {
    let r = p.occlusion_radius;
    let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(width));
    (y.saturating_sub(r)..(y + r + 1).min(height)).any(|ny| {
        new[ny * width + x0..ny * width + x1]
            .iter()
            .any(|&d| depth_is_valid(d) && d_warp - d > p.agreement * d)
    })
}

/// One pixel of [`merge_depth`]: (depth, weight).
#[inline]
fn merge_pixel(d_new: f32, d_warp: f32, w_warp: f32, p: &MergeParams) -> (f32, f32) {
    let warped = depth_is_valid(d_warp) && w_warp > 0.0 && w_warp.is_finite();
    if depth_is_valid(d_new) {
        if warped && (d_new - d_warp).abs() <= p.agreement * d_new {
            (
                (w_warp * d_warp + d_new) / (w_warp + 1.0),
                (w_warp + 1.0).min(p.max_weight),
            )
        } else {
            (d_new, 1.0)
        }
    } else if warped && w_warp >= p.min_fill_weight {
        (d_warp, w_warp * p.fill_decay)
    } else {
        (0.0, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::raster::Image;

    fn merge_one(d_new: f32, d_warp: f32, w_warp: f32, p: &MergeParams) -> (f32, f32) {
        let img = |v: f32| Image::filled(1, 1, v);
        let (mut d, mut w) = (img(-1.0), img(-1.0));
        merge_depth(&img(d_warp), &img(w_warp), &img(d_new), p, &mut d, &mut w).unwrap();
        (d.data[0], w.data[0])
    }

    #[test]
    fn agreeing_depths_average_and_the_weight_is_capped() {
        let p = MergeParams::default();
        // 2% apart at 2 m: same surface. (3 * 2.0 + 2.04) / 4 = 2.01.
        let (d, w) = merge_one(2.04, 2.0, 3.0, &p);
        assert!((d - 2.01).abs() < 1e-6 && w == 4.0, "{d} {w}");
        let (d, w) = merge_one(2.04, 2.0, 20.0, &p);
        assert!((d - (40.0 + 2.04) / 21.0).abs() < 1e-6, "{d}");
        assert_eq!(w, 20.0, "weight stays at the cap");
        let (_, w) = merge_one(2.0, 2.0, 19.5, &p);
        assert_eq!(w, 20.0);
    }

    #[test]
    fn disagreement_takes_the_new_depth_and_resets_the_weight() {
        let p = MergeParams::default();
        // 20 cm apart at about 2 m is 9% or more, beyond the 5% agreement.
        assert_eq!(merge_one(2.2, 2.0, 20.0, &p), (2.2, 1.0));
        assert_eq!(merge_one(1.8, 2.0, 20.0, &p), (1.8, 1.0));
        // Exactly at the threshold: 0.1 <= 0.05 * 2.0 agrees.
        assert_eq!(merge_one(2.0, 2.1, 3.0, &p).1, 4.0);
        // Nothing warped: the new depth, weight 1 (the first frame's rule).
        assert_eq!(merge_one(1.9, 0.0, 0.0, &p), (1.9, 1.0));
        assert_eq!(
            merge_one(1.9, 2.0, 0.0, &p),
            (1.9, 1.0),
            "zero weight = missing"
        );
    }

    #[test]
    fn holes_are_filled_only_from_confident_warped_depth() {
        let p = MergeParams::default();
        assert_eq!(merge_one(0.0, 2.0, 2.0, &p), (2.0, 2.0 * 0.9));
        assert_eq!(merge_one(f32::NAN, 2.0, 10.0, &p), (2.0, 9.0));
        assert_eq!(
            merge_one(0.0, 2.0, 1.9, &p),
            (0.0, 0.0),
            "below min_fill_weight"
        );
        assert_eq!(merge_one(0.0, 0.0, 0.0, &p), (0.0, 0.0), "both missing");
        assert_eq!(merge_one(0.0, f32::INFINITY, 5.0, &p), (0.0, 0.0));
    }

    #[test]
    fn holes_next_to_a_nearer_surface_are_not_filled() {
        // Row 0 of a 7x1 map: new depth sees a near surface (2 m) at x = 0 and holes
        // elsewhere; the warped map has the wall (3 m) everywhere.
        let new = Image::from_vec(7, 1, vec![2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.05]).unwrap();
        let (warp_d, warp_w) = (Image::filled(7, 1, 3.0f32), Image::filled(7, 1, 10.0f32));
        let (mut d, mut w) = (Image::filled(7, 1, -1.0), Image::filled(7, 1, -1.0));
        let p = MergeParams::default();
        merge_depth(&warp_d, &warp_w, &new, &p, &mut d, &mut w).unwrap();
        // Within 2 pixels of the near surface: holes; the far end agrees (3.05 vs 3).
        assert_eq!(
            d.data,
            vec![2.0, 0.0, 0.0, 3.0, 3.0, 3.0, (30.0 + 3.05) / 11.0]
        );
        assert_eq!(w.data, vec![1.0, 0.0, 0.0, 9.0, 9.0, 9.0, 11.0]);
        // Without the test every hole is filled, as in the paper.
        let paper = MergeParams {
            occlusion_radius: 0,
            ..p
        };
        merge_depth(&warp_d, &warp_w, &new, &paper, &mut d, &mut w).unwrap();
        assert_eq!(&d.data[..3], &[2.0, 3.0, 3.0]);
        // A nearer surface only within the agreement does not count: 2.9 vs 3.0 is 3%.
        let close = Image::from_vec(7, 1, vec![2.9, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]).unwrap();
        merge_depth(&warp_d, &warp_w, &close, &p, &mut d, &mut w).unwrap();
        assert_eq!(&d.data[..3], &[(30.0 + 2.9) / 11.0, 3.0, 3.0]);
    }

    #[test]
    fn static_noise_falls_with_frames() {
        // A static camera sees a plane at 2 m with +-1 cm alternating noise: the running
        // average converges to 2 m while the weight grows to the cap.
        let p = MergeParams::default();
        let (mut d, mut w) = (0.0f32, 0.0f32);
        let mut errors = Vec::new();
        for frame in 0..40 {
            let noisy = if frame % 2 == 0 { 2.01 } else { 1.99 };
            (d, w) = merge_one(noisy, d, w, &p);
            errors.push((d - 2.0).abs());
        }
        assert!((errors[0] - 0.01).abs() < 1e-6);
        assert!(errors[1] < 1e-6, "{}", errors[1]);
        assert!(errors[38] < 0.01 / 20.0, "{}", errors[38]);
        assert_eq!(w, 20.0);
    }

    #[test]
    fn mismatched_sizes_are_an_error() {
        let a = Image::filled(2, 2, 1.0f32);
        let b = Image::filled(2, 3, 1.0f32);
        let (mut d, mut w) = (a.clone(), a.clone());
        let err = merge_depth(&a, &a, &b, &MergeParams::default(), &mut d, &mut w);
        assert!(matches!(err, Err(OpError::SizeMismatch(_))));
        let empty = Image::filled(0, 0, 0.0f32);
        let (mut d, mut w) = (empty.clone(), empty.clone());
        merge_depth(
            &empty,
            &empty,
            &empty,
            &MergeParams::default(),
            &mut d,
            &mut w,
        )
        .unwrap();
    }
}
