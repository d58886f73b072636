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
//! There is no score against a ground-truth render with the objects really in the
//! room: the synthetic generator renders the room without them.

use super::sampling::ReferenceLayers;
use glam::Vec3;
use relume_base::raster::Rgb8Image;
use relume_graph::{Frame, ResolvedStage};
use relume_stages::composite::{
    CompositeInputs, CompositeOutputs, CompositeParams, GammaEncoder, composite,
};
use relume_stages::kind::FrameProducts;
use serde_json::{Value, json};

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
}

impl CompositeScorer {
    pub fn new(stage: &ResolvedStage, sampler: Option<&ResolvedStage>) -> CompositeScorer {
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

    /// Scores `frame` when `reference` holds its reference layers.
    pub fn observe(
        &mut self,
        frame: &Frame,
        reference: Option<&ReferenceLayers>,
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
        Ok(())
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
        report
    }
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
