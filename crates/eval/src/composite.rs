//! Scores of `composite.differential` against a reference composite: the same camera
//! image, mask, k_V and compensation composited from the 1024-sample reference layers
//! (see [`super::sampling::ReferenceSchedule`]), on the frames that get references.
//!
//! - `psnr_db`: PSNR of the stage's 8-bit `final` image against the reference composite
//!   (peak 255, over all channels of the pixels that have a reference: all of them, or
//!   the lattice of `relume eval --reference-stride`);
//! - `psnr_db_unfiltered`: the same for a composite of the sampling's unfiltered layers
//!   (what the filter buys; absent without a `sample.path`);
//! - `psnr_db_by_frame`: `psnr_db` of each scored frame alone, in `scored_frames` order.
//!
//! On recordings of the synthetic room, the same frames and pixels are scored against
//! the true frame as well ([`super::true_frame`]: the room with the objects, and the
//! pipeline's virtual lamps, really in it), the model-consistent scores above separating noise from the model's own error:
//! - `psnr_db_truth`: the whole frame against the truth;
//! - `psnr_db_truth_differential`: over the differential region, the pixels off the
//!   objects where the truth differs from the recorded frame by more than one level in
//!   a channel (shadows, bleeding, reflections); `differential_pixels` counts them;
//! - `psnr_db_truth_objects`: over the objects' own pixels (`object_pixels`);
//! - `shadow_ratio_bias`: in the shadow region (the differential region where the truth
//!   is darker than the recorded frame), the mean over pixels and channels of the
//!   composite's ratio to the recorded frame minus the truth's, both in the camera's
//!   linear values (negative: shadows too dark); channels below level 16 or clipped in
//!   the recorded frame are left out;
//! - `truth_noise_psnr_db`: the truth's own error (one standard error, in levels) as a
//!   PSNR over the pixels it changed: a method scored far below it is scored on its
//!   own error, not the truth's;
//! - `psnr_db_truth_by_frame`;
//! - `differential_ratio_by_frame`: per frame, the composite's differential over the
//!   pixels off the objects as a share of the truth's ([`super::change`]), and, on a
//!   recording whose light changes (`relume synth --panel-off-at`), `change_frame`,
//!   `change_lag_frames` (frames until that share settles within 5 % of its final value),
//!   `change_final_ratio` and `change_ratio_before` (the median share on the scored
//!   frames before it), or `change_unmeasured` saying why not;
//! - when the pipeline's objects move, the ghost they leave ([`super::ghost`]), per age
//!   1 to 5 (frames since their shadows and light left a point): `ghost_pixels_by_age`,
//!   `ghost_share_by_age` (how much of what the truth lost there the composite still
//!   shows, beyond its usual share of the truth's differential) and
//!   `ghost_psnr_db_by_age`, and `ghost_gone_after_frames` (the age from
//!   which every share is within 5 % of 0) or `ghost_unmeasured` saying why not.
//!
//! What the references and the truth cost is reported apart ([`CompositeScorer::costs`]).

use super::change::{self, DifferentialSums};
use super::ghost::{self, GHOST_AGES, GhostSums};
use super::sampling::ReferenceLayers;
use super::true_frame::{TrueComposite, linear_of_level};
use glam::Vec3;
use relume_base::raster::Rgb8Image;
use relume_graph::{Frame, ResolvedStage};
use relume_stages::composite::{
    CompositeInputs, CompositeOutputs, CompositeParams, GammaEncoder, composite,
};
use relume_stages::kind::FrameProducts;
use serde_json::{Value, json};
use std::sync::Arc;

/// Scores a `composite.differential` stage.
pub struct CompositeScorer {
    stage: ResolvedStage,
    params: CompositeParams,
    encoder: GammaEncoder,
    /// The sampling's unfiltered layers: e_r_dir, e_r_ind, e_rv_dir, e_rv_ind.
    unfiltered: Option<[String; 4]>,
    /// The indices of the frames scored (those with a reference).
    scored_frames: Vec<usize>,
    squared: f64,
    squared_unfiltered: f64,
    values: u64,
    /// `psnr_db` of each scored frame.
    by_frame: Vec<f64>,
    /// The reference composite of each scored frame (for viewing beside the stage's).
    references: Vec<(usize, Rgb8Image)>,
    /// Seconds each scored frame's reference layers took.
    reference_render_s: Vec<f64>,
    /// The scores against the true frames, when the recording has them.
    truth: TruthScores,
}

/// Sums of the scores against the true frames.
#[derive(Default)]
struct TruthScores {
    /// The true frames scored against, in `scored_frames` order.
    frames: Vec<Arc<TrueComposite>>,
    /// Squared 8-bit errors and their channel counts: whole frame, differential
    /// region, objects, and the truth's own noise over the pixels it changed.
    whole: (f64, u64),
    differential: (f64, u64),
    objects: (f64, u64),
    noise: (f64, u64),
    /// Sum and count of the ratio errors in the shadow region.
    shadow_bias: (f64, u64),
    by_frame: Vec<f64>,
    /// The composite's and the truth's differential off the objects, per frame.
    differential_by_frame: Vec<DifferentialSums>,
    /// The frame at which the recording's world changes (its light), if it does.
    change: Option<usize>,
    /// The ghost of the objects, per age, when they move.
    ghosts: Option<[GhostSums; GHOST_AGES]>,
}

impl CompositeScorer {
    /// The scorer of `stage`, whose layers `sampler` renders; `change` is the frame at
    /// which the recording's light changes, whose lag is measured; `moving`: the
    /// pipeline's objects move, and the ghost they leave is measured.
    pub fn new(
        stage: &ResolvedStage,
        sampler: Option<&ResolvedStage>,
        change: Option<usize>,
        moving: bool,
    ) -> CompositeScorer {
        let params = CompositeParams::from_params(&stage.params);
        CompositeScorer {
            stage: stage.clone(),
            encoder: GammaEncoder::new(params.gamma),
            params,
            unfiltered: sampler.map(|s| {
                ["e_r_dir", "e_r_ind", "e_rv_dir", "e_rv_ind"].map(|r| super::ports::output(s, r))
            }),
            scored_frames: Vec::new(),
            squared: 0.0,
            squared_unfiltered: 0.0,
            values: 0,
            by_frame: Vec::new(),
            references: Vec::new(),
            reference_render_s: Vec::new(),
            truth: TruthScores {
                change,
                ghosts: moving.then(|| [GhostSums::default(); GHOST_AGES]),
                ..TruthScores::default()
            },
        }
    }

    /// The composite of `layers` with the stage's other inputs on `frame`.
    fn composite_of(
        &self,
        frame: &Frame,
        layers: [&relume_base::raster::Vec3Image; 4],
    ) -> Result<Rgb8Image, String> {
        let input = |role: &str| super::ports::input(&self.stage, role);
        let e = |e: relume_graph::StageError| e.to_string();
        let radiance = frame.radiance(&input("radiance")).map_err(e)?;
        let inputs = CompositeInputs {
            e_r_dir: layers[0],
            e_r_ind: layers[1],
            e_rv_dir: layers[2],
            e_rv_ind: layers[3],
            mask: frame.scalar(&input("mask")).map_err(e)?,
            k_v: frame.radiance(&input("k_v")).map_err(e)?,
            radiance,
            inverse_compensation: frame
                .compensation(&input("compensation"))
                .map_err(e)?
                .inverse,
        };
        let mut out = CompositeOutputs::new(radiance.width, radiance.height);
        composite(&inputs, &self.params, &self.encoder, &mut out).map_err(|e| e.to_string())?;
        Ok(out.final_color)
    }

    /// Scores `frame` when `reference` holds its reference layers, and against
    /// `truth` when the recording has a true frame for it.
    pub fn observe(
        &mut self,
        frame: &Frame,
        reference: Option<&ReferenceLayers>,
        truth_frame: Option<&Arc<TrueComposite>>,
    ) -> Result<(), String> {
        let Some(reference) = reference.filter(|r| r.frame == frame.index) else {
            return Ok(());
        };
        let Ok(own) = frame.color(&super::ports::output(&self.stage, "final")) else {
            return Ok(());
        };
        let truth = self.composite_of(
            frame,
            [
                &reference.e_r_dir,
                &reference.e_r_ind,
                &reference.e_rv_dir,
                &reference.e_rv_ind,
            ],
        )?;
        let scored = |i: usize| reference.has_pixel(i);
        let squared = squared_error(own, &truth, scored);
        self.squared += squared;
        if let Some(names) = &self.unfiltered {
            let layers: Vec<_> = names.iter().map(|n| frame.radiance(n)).collect();
            if let [Ok(a), Ok(b), Ok(c), Ok(d)] = layers.as_slice() {
                let unfiltered = self.composite_of(frame, [a, b, c, d])?;
                self.squared_unfiltered += squared_error(&unfiltered, &truth, scored);
            } else {
                self.unfiltered = None;
            }
        }
        let values = (0..own.data.len()).filter(|&i| scored(i)).count() as u64 * 3;
        self.values += values;
        self.by_frame.push(psnr_db(squared / values.max(1) as f64));
        self.scored_frames.push(frame.index);
        self.references.push((frame.index, truth));
        self.reference_render_s.push(reference.render_s);
        if let Some(t) = truth_frame {
            let mask = frame
                .scalar(&super::ports::input(&self.stage, "mask"))
                .map_err(|e| e.to_string())?;
            self.truth.observe(own, t, &mask.data);
        }
        Ok(())
    }

    /// The true frames scored against, as (frame, true frame).
    pub fn truths(&self) -> &[Arc<TrueComposite>] {
        &self.truth.frames
    }

    /// What scoring cost, per scored frame: `reference_render_s` (the reference layers;
    /// shared references: what the evaluator that computed them took) and
    /// `truth_render_s` (the true frame). Timings, so not among the scores, which are
    /// the same on every run.
    pub fn costs(&self) -> Value {
        json!({
            "reference_render_s": self.reference_render_s,
            "truth_render_s": self.truth.frames.iter().map(|t| t.render_s).collect::<Vec<_>>(),
        })
    }

    /// The reference composite of each scored frame, as (frame, image). Off the
    /// reference's pixel lattice (`--reference-stride` above 1) its pixels mean nothing.
    pub fn references(&self) -> &[(usize, Rgb8Image)] {
        &self.references
    }

    pub fn report(&self) -> Value {
        let psnr = |squared: f64| {
            if self.values == 0 {
                f64::NAN
            } else {
                psnr_db(squared / self.values as f64)
            }
        };
        let mut report = json!({
            "frames_scored": self.scored_frames.len(),
            "scored_frames": self.scored_frames,
            "psnr_db": psnr(self.squared),
            "psnr_db_by_frame": self.by_frame,
        });
        if self.unfiltered.is_some() {
            report["psnr_db_unfiltered"] = json!(psnr(self.squared_unfiltered));
        }
        if let Value::Object(truth) = self.truth.report() {
            report
                .as_object_mut()
                .into_iter()
                .for_each(|r| r.extend(truth.clone()));
        }
        report
    }
}

impl TruthScores {
    /// Scores the composite `own` (whose object coverage is `mask`) against the true
    /// frame `t` on its lattice.
    fn observe(&mut self, own: &Rgb8Image, t: &Arc<TrueComposite>, mask: &[f32]) {
        let mut frame = (0.0f64, 0u64);
        let mut sums = DifferentialSums::default();
        let linear = |level: u8| linear_of_level(level, t.contrast) as f64;
        for i in (0..own.data.len()).filter(|&i| t.has_pixel(i)) {
            let (mine, truth, camera) = (own.data[i], t.image.data[i], t.camera.data[i]);
            let error = level_distance(mine, truth);
            frame.0 += error;
            frame.1 += 3;
            let changed = t.object[i] || t.noise_levels[i] > 0.0;
            if changed {
                let sigma = t.noise_levels[i] as f64;
                self.noise.0 += 3.0 * sigma * sigma;
                self.noise.1 += 3;
            }
            if t.object[i] {
                self.objects.0 += error;
                self.objects.1 += 3;
                continue;
            }
            // The mask is 1 on real pixels (paper 001 eq. 2), below on the objects.
            if mask.get(i).is_some_and(|&m| m >= 1.0) {
                for c in 0..3 {
                    let base = linear(camera[c]);
                    sums.add(linear(mine[c]) - base, linear(truth[c]) - base);
                }
            }
            let differs = (0..3).any(|c| truth[c].abs_diff(camera[c]) > 1);
            if !differs {
                continue;
            }
            self.differential.0 += error;
            self.differential.1 += 3;
            let darker = (0..3)
                .map(|c| truth[c] as i32 - camera[c] as i32)
                .sum::<i32>()
                < 0;
            if darker {
                for c in (0..3).filter(|&c| (16..255).contains(&camera[c])) {
                    let base = linear_of_level(camera[c], t.contrast);
                    let ratio = |level: u8| linear_of_level(level, t.contrast) / base;
                    self.shadow_bias.0 += (ratio(mine[c]) - ratio(truth[c])) as f64;
                    self.shadow_bias.1 += 1;
                }
            }
        }
        self.whole.0 += frame.0;
        self.whole.1 += frame.1;
        self.by_frame.push(psnr_db(frame.0 / frame.1.max(1) as f64));
        if let Some(ghosts) = &mut self.ghosts {
            let gain = sums.ratio();
            for (age, ghost) in (1..).zip(ghosts.iter_mut()) {
                let then = t.frame.checked_sub(age);
                if let Some(before) = self.frames.iter().rev().find(|b| Some(b.frame) == then) {
                    ghost.observe(own, t, before, gain);
                }
            }
        }
        self.differential_by_frame.push(sums);
        self.frames.push(t.clone());
    }

    fn report(&self) -> Value {
        if self.frames.is_empty() {
            return Value::Null;
        }
        let psnr =
            |(squared, values): (f64, u64)| (values > 0).then(|| psnr_db(squared / values as f64));
        let ratios: Vec<f64> = self
            .differential_by_frame
            .iter()
            .map(DifferentialSums::ratio)
            .collect();
        let mut report = json!({
            "psnr_db_truth": psnr(self.whole),
            "psnr_db_truth_differential": psnr(self.differential),
            "psnr_db_truth_objects": psnr(self.objects),
            "differential_pixels": self.differential.1 / 3,
            "object_pixels": self.objects.1 / 3,
            "shadow_ratio_bias": (self.shadow_bias.1 > 0)
                .then(|| self.shadow_bias.0 / self.shadow_bias.1 as f64),
            "truth_noise_psnr_db": psnr(self.noise),
            "psnr_db_truth_by_frame": self.by_frame,
            "differential_ratio_by_frame": ratios.iter().map(|r| r.is_finite().then_some(*r)).collect::<Vec<_>>(),
        });
        if let Some(ghosts) = &self.ghosts {
            report["ghost_pixels_by_age"] = json!(ghosts.map(|g| g.pixels));
            report["ghost_share_by_age"] = json!(ghosts.map(|g| g.share()));
            report["ghost_psnr_db_by_age"] = json!(ghosts.map(|g| g.mean_squared().map(psnr_db)));
            match ghost::gone_after(ghosts) {
                Ok(frames) => report["ghost_gone_after_frames"] = json!(frames),
                Err(why) => report["ghost_unmeasured"] = json!(why),
            }
        }
        if let Some(at) = self.change {
            let frames: Vec<usize> = self.frames.iter().map(|t| t.frame).collect();
            report["change_frame"] = json!(at);
            match change::settling(&frames, &ratios, at) {
                Ok(s) => {
                    report["change_lag_frames"] = json!(s.lag_frames);
                    report["change_final_ratio"] = json!(s.final_ratio);
                    report["change_ratio_before"] = json!(s.ratio_before);
                }
                Err(why) => report["change_unmeasured"] = json!(why),
            }
        }
        report
    }
}

/// The squared distance of two 8-bit colors, summed over the channels.
fn level_distance(a: [u8; 3], b: [u8; 3]) -> f64 {
    (0..3).map(|c| (a[c] as f64 - b[c] as f64).powi(2)).sum()
}

/// The sum of squared 8-bit differences over the pixels `scored` keeps, all channels.
fn squared_error(a: &Rgb8Image, b: &Rgb8Image, scored: impl Fn(usize) -> bool) -> f64 {
    a.data
        .iter()
        .zip(&b.data)
        .enumerate()
        .filter(|(i, _)| scored(*i))
        .map(|(_, (p, q))| {
            let d = Vec3::from_array(p.map(f32::from)) - Vec3::from_array(q.map(f32::from));
            d.length_squared() as f64
        })
        .sum()
}

/// PSNR in dB of a mean squared error on the 8-bit scale (infinite when 0).
pub fn psnr_db(mse: f64) -> f64 {
    10.0 * (255.0f64 * 255.0 / mse).log10()
}

#[cfg(test)]
mod tests {
    use super::psnr_db;

    #[test]
    fn psnr_of_known_errors() {
        assert!((psnr_db(1.0) - 48.1308).abs() < 1e-3);
        assert!((psnr_db(255.0 * 255.0) - 0.0).abs() < 1e-9);
        assert_eq!(psnr_db(0.0), f64::INFINITY);
    }
}
