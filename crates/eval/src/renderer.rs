//! Scores of a renderer other than `sample.path` (`sample.dir`, `sample.val`) against the same
//! 1024-sample references (`super::sampling::ReferenceLayers`: the default
//! `sample.path` run on the renderer's own inputs), on the same frames:
//!
//! - `ratio_rmse`: RMSE of the stage's E_RV / E_R (channel means of direct +
//!   indirect) against the reference ratio, over the real pixels where a reference
//!   path met an object, as `sample.path`'s own score;
//! - `ratio_rmse_all`: the same over every real pixel with a reference (a renderer
//!   whose ratio strays from 1 away from the objects pays for it here).

use super::sampling::{OwnLayers, ReferenceLayers, channel_mean};
use relume_graph::{Frame, ResolvedStage};
use serde_json::{Value, json};

/// Scores a renderer's E_RV / E_R.
pub struct RatioScorer {
    /// e_r_dir, e_r_ind, e_rv_dir, e_rv_ind, mask.
    outputs: [String; 5],
    scored_frames: Vec<usize>,
    /// (pixels, squared error): near the objects, everywhere.
    near: (u64, f64),
    all: (u64, f64),
}

impl RatioScorer {
    pub fn new(stage: &ResolvedStage) -> RatioScorer {
        RatioScorer {
            outputs: ["e_r_dir", "e_r_ind", "e_rv_dir", "e_rv_ind", "mask"]
                .map(|r| super::ports::output(stage, r)),
            scored_frames: Vec::new(),
            near: (0, 0.0),
            all: (0, 0.0),
        }
    }

    /// Scores `frame` when `reference` is its reference and the frame holds the
    /// stage's outputs.
    pub fn observe(&mut self, frame: &Frame, reference: Option<&ReferenceLayers>) {
        let Some(reference) = reference.filter(|r| r.frame == frame.index) else {
            return;
        };
        let Some(OwnLayers {
            e_r_dir,
            e_r_ind,
            e_rv_dir,
            e_rv_ind,
            mask,
        }) = OwnLayers::of(frame, &self.outputs)
        else {
            return;
        };
        for i in 0..reference.touched.len() {
            let ref_r = channel_mean(reference.e_r_dir.data[i] + reference.e_r_ind.data[i]);
            let ref_rv = channel_mean(reference.e_rv_dir.data[i] + reference.e_rv_ind.data[i]);
            if mask.data[i] != 1.0 || !ref_r.is_finite() || ref_r <= 1e-6 || !ref_rv.is_finite() {
                continue;
            }
            let own = channel_mean(e_rv_dir.data[i] + e_rv_ind.data[i])
                / channel_mean(e_r_dir.data[i] + e_r_ind.data[i]);
            if !own.is_finite() {
                continue;
            }
            let squared = (own - ref_rv / ref_r).powi(2);
            self.all = (self.all.0 + 1, self.all.1 + squared);
            if reference.touched[i] {
                self.near = (self.near.0 + 1, self.near.1 + squared);
            }
        }
        self.scored_frames.push(frame.index);
    }

    pub fn report(&self) -> Value {
        let rmse = |(n, sq): (u64, f64)| {
            if n > 0 {
                (sq / n as f64).sqrt()
            } else {
                f64::NAN
            }
        };
        json!({
            "frames_scored": self.scored_frames.len(),
            "scored_frames": self.scored_frames,
            "region_pixels": self.near.0,
            "ratio_rmse": rmse(self.near),
            "ratio_rmse_all": rmse(self.all),
        })
    }
}
