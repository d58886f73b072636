//! Scores of `depth.fuse`: error and holes of raw and fused depth against the clean
//! depth, and, with or without ground truth, self-consistency: the previous frame's depth
//! forward-warped into the current view against the current raw depth.

use super::truth::FrameTruth;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, depth_is_valid};
use relume_graph::Frame;
use relume_recording::{Intrinsics, Pose};
use serde_json::{Value, json};

/// Sums for one depth product against the truth.
#[derive(Default)]
struct ErrorSums {
    squared: f64,
    measured: u64,
    holes: u64,
}

impl ErrorSums {
    fn add(&mut self, estimate: &[f32], truth: &[f32]) {
        for (&e, &t) in estimate.iter().zip(truth) {
            if !depth_is_valid(t) {
                continue;
            }
            if depth_is_valid(e) {
                self.squared += ((e - t) as f64).powi(2);
                self.measured += 1;
            } else {
                self.holes += 1;
            }
        }
    }

    /// `None` (null, not a perfect 0) where no pixel had both a depth and the truth's.
    fn rmse(&self) -> Option<f64> {
        (self.measured > 0).then(|| (self.squared / self.measured as f64).sqrt())
    }

    /// `None` where the truth saw no pixel.
    fn hole_fraction(&self) -> Option<f64> {
        let seen = self.measured + self.holes;
        (seen > 0).then(|| self.holes as f64 / seen as f64)
    }
}

/// Sums of the warp self-consistency of one depth product.
#[derive(Default)]
struct WarpSums {
    squared: f64,
    overlap: u64,
    target_valid: u64,
}

/// Scores a `depth.fuse` stage.
pub struct DepthScorer {
    raw: String,
    fused: String,
    pose: String,
    intrinsics: Intrinsics,
    raw_sums: ErrorSums,
    fused_sums: ErrorSums,
    warp_raw: WarpSums,
    warp_fused: WarpSums,
    previous: Option<(DepthImage, DepthImage, Pose)>,
    frames_with_truth: usize,
}

impl DepthScorer {
    pub fn new(raw: String, fused: String, pose: String, intrinsics: Intrinsics) -> Self {
        DepthScorer {
            raw,
            fused,
            pose,
            intrinsics,
            raw_sums: ErrorSums::default(),
            fused_sums: ErrorSums::default(),
            warp_raw: WarpSums::default(),
            warp_fused: WarpSums::default(),
            previous: None,
            frames_with_truth: 0,
        }
    }

    pub fn observe(&mut self, frame: &Frame, truth: Option<&FrameTruth>) {
        let (Ok(raw), Ok(fused)) = (frame.depth(&self.raw), frame.depth(&self.fused)) else {
            self.previous = None;
            return;
        };
        if let Some(t) = truth.filter(|t| t.depth.len() == raw.data.len()) {
            self.raw_sums.add(&raw.data, &t.depth);
            self.fused_sums.add(&fused.data, &t.depth);
            self.frames_with_truth += 1;
        }
        let pose = frame.pose(&self.pose).ok().copied();
        if let (Some((prev_raw, prev_fused, prev_pose)), Some(pose)) = (&self.previous, pose)
            && prev_raw.same_size(raw)
        {
            let camera = Pinhole::new(&self.intrinsics, raw.width, raw.height);
            for (source, sums) in [
                (prev_raw, &mut self.warp_raw),
                (prev_fused, &mut self.warp_fused),
            ] {
                let warped = forward_warp(source, prev_pose, &pose, &camera);
                for (&w, &r) in warped.data.iter().zip(&raw.data) {
                    if depth_is_valid(r) {
                        sums.target_valid += 1;
                        if depth_is_valid(w) {
                            sums.squared += ((w - r) as f64).powi(2);
                            sums.overlap += 1;
                        }
                    }
                }
            }
        }
        self.previous = pose.map(|p| (raw.clone(), fused.clone(), p));
    }

    pub fn report(&self) -> Value {
        // null, not 0, where nothing was compared (a single frame, or no overlap):
        // 0 would read as a perfect score.
        let warp = |s: &WarpSums| {
            (
                (s.overlap > 0).then(|| (s.squared / s.overlap as f64).sqrt()),
                (s.target_valid > 0).then(|| s.overlap as f64 / s.target_valid as f64),
            )
        };
        let (raw_rmse, raw_overlap) = warp(&self.warp_raw);
        let (fused_rmse, fused_overlap) = warp(&self.warp_fused);
        let mut out = json!({
            "warp_rmse_raw_m": raw_rmse,
            "warp_rmse_fused_m": fused_rmse,
            "warp_overlap_raw": raw_overlap,
            "warp_overlap_fused": fused_overlap,
        });
        if self.frames_with_truth > 0 {
            let o = out.as_object_mut().expect("an object");
            o.insert("rmse_raw_m".into(), json!(self.raw_sums.rmse()));
            o.insert("rmse_fused_m".into(), json!(self.fused_sums.rmse()));
            o.insert("holes_raw".into(), json!(self.raw_sums.hole_fraction()));
            o.insert("holes_fused".into(), json!(self.fused_sums.hole_fraction()));
        }
        out
    }
}

/// The depth of `source` (seen from `from`) forward-projected point by point into the
/// view `to`, nearest surface kept. An independent, simple warp for scoring: holes where
/// no source pixel lands.
pub fn forward_warp(source: &DepthImage, from: &Pose, to: &Pose, camera: &Pinhole) -> DepthImage {
    let transform = (to.matrix().inverse() * from.matrix()).as_mat4();
    let mut out = DepthImage::filled(source.width, source.height, 0.0);
    for (i, &z) in source.data.iter().enumerate() {
        if !depth_is_valid(z) {
            continue;
        }
        let (u, v) = (
            (i % source.width as usize) as f32,
            (i / source.width as usize) as f32,
        );
        let p = transform.transform_point3(camera.back_project(u, v, z));
        if let Some((x, y)) = camera.pixel_of(p) {
            let slot = &mut out.data[y as usize * out.width as usize + x as usize];
            if *slot == 0.0 || p.z < *slot {
                *slot = p.z;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};
    use relume_graph::Product;
    use relume_stages::kind;

    #[test]
    fn nothing_compared_gives_no_error_not_a_perfect_zero() {
        let mut sums = ErrorSums::default();
        assert_eq!((sums.rmse(), sums.hole_fraction()), (None, None));
        // Only holes: no error to give, every seen pixel a hole.
        sums.add(&[0.0, 0.0], &[1.0, 2.0]);
        assert_eq!((sums.rmse(), sums.hole_fraction()), (None, Some(1.0)));
        sums.add(&[1.5], &[1.0]);
        assert_eq!(
            (sums.rmse(), sums.hole_fraction()),
            (Some(0.5), Some(2.0 / 3.0))
        );
    }

    #[test]
    fn warp_of_a_wall_under_a_sideways_move_shifts_it_in_the_image() {
        let camera = Pinhole::new(&Intrinsics::PRIMESENSE, 64, 48);
        let source = DepthImage::filled(64, 48, 2.0);
        let from = Pose::IDENTITY;
        let to = Pose::from_parts(DVec3::new(0.1, 0.0, 0.0), DQuat::IDENTITY);
        let warped = forward_warp(&source, &from, &to, &camera);
        // 0.1 m at 2 m is 0.1 * 525 / 10 / 2 = 2.6 pixels at this size (fx = 52.5).
        let shift = 0.1 * camera.fx / 2.0;
        assert!((2.0..3.0).contains(&shift));
        assert_eq!(*warped.at(10, 10), 2.0);
        assert_eq!(*warped.at(63, 10), 0.0, "uncovered on the right");
    }

    #[test]
    fn warp_scores_are_null_until_two_frames_are_compared() {
        let mut scorer = DepthScorer::new(
            "depth".into(),
            "fused".into(),
            "pose".into(),
            Intrinsics::PRIMESENSE,
        );
        let frame = |index: usize| {
            let mut f = Frame::new(index, 0);
            f.insert(
                "depth",
                Product::new(kind::DEPTH, DepthImage::filled(64, 48, 2.0)),
            );
            f.insert(
                "fused",
                Product::new(kind::DEPTH, DepthImage::filled(64, 48, 2.0)),
            );
            f.insert("pose", Product::new(kind::POSE, Pose::IDENTITY));
            f
        };
        scorer.observe(&frame(0), None);
        let report = scorer.report();
        for key in ["warp_rmse_raw_m", "warp_overlap_raw", "warp_rmse_fused_m"] {
            assert_eq!(report[key], Value::Null, "{key} after one frame");
        }
        scorer.observe(&frame(1), None);
        let report = scorer.report();
        assert_eq!(
            report["warp_rmse_raw_m"], 0.0,
            "a still wall warps onto itself"
        );
        assert_eq!(report["warp_overlap_raw"], 1.0);
    }
}
