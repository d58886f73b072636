//! Scores of `filter.axis_aligned` against the 1024-sample reference layers that the
//! evaluator's [`ReferenceSchedule`](super::sampling::ReferenceSchedule) computes on
//! frames 14 and 29, or on the last frame of a replay without them (on every pixel, or
//! on the lattice of `--reference-stride`: then every score below averages over the
//! lattice).
//!
//! - `mse_unfiltered`, `mse_filtered`: mean squared error of the filter's input and
//!   output layers against the reference, over the four layers, three channels and
//!   every pixel where both are finite;
//! - `mse_gaussian_same_radius`: the same for the naive alternative, a plain
//!   image-space Gaussian over the same window (|i|, |j| <= radius, sigma = radius / 2,
//!   separable, skipping pixels without an estimate);
//! - `mse_unfiltered_by_layer`, `mse_filtered_by_layer`: the same per layer, in the
//!   order e_r_dir, e_r_ind, e_rv_dir, e_rv_ind;
//! - `temporal_flicker` and `temporal_flicker_spatial_only`: a still camera over a
//!   static scene. The frame's sampling is re-run [`FLICKER_FRAMES`] times with fresh
//!   random numbers (as consecutive frames of a camera that does not move would get),
//!   each run is filtered by a fresh instance of the stage in order, with its temporal
//!   extension on and then off; the score is the per-pixel variance over the frames
//!   (after the first, which has no previous frame), averaged over pixels, layers and
//!   channels. When the pipeline has a `temporal.accumulate` stage (between the
//!   sampler and the filter), each run passes through a fresh instance of it first, as
//!   the pipeline's frames do: the score is then the spread of its first frames, while
//!   it holds 2 to 5 frames (a still camera flickers less once it holds more), and the
//!   spatial-only score too includes the accumulator's averaging over time.
//!   `flicker_as_configured` repeats the one of the two that the stage's own
//!   `temporal` setting runs (the default pipeline turns the extension off: its
//!   accumulator already reuses earlier frames).

use super::sampling::{PathRunner, ReferenceLayers};
use glam::{DVec3, Vec3};
use relume_base::raster::{Image, Vec3Image};
use relume_base::rng;
use relume_graph::{BuildContext, Frame, ParamValue, ResolvedStage, Stage};
use relume_recording::Header;
use relume_scene::objects::VirtualScene;
use relume_stages::sample::layers::LAYER_OUTPUTS;
use relume_stages::sample::path::{IrradianceLayers, PathParams};
use serde_json::{Value, json};
use std::sync::Arc;

/// Frames of the still-camera run (the first only primes the temporal state).
pub const FLICKER_FRAMES: u64 = 5;
const FLICKER_SALT: u64 = 0x464c_4943;
/// The filter's layer roles, inputs and outputs alike (`filtered_` + role).
const LAYERS: [&str; 4] = ["e_r_dir", "e_r_ind", "e_rv_dir", "e_rv_ind"];

/// Scores a `filter.axis_aligned` stage.
pub struct FilterScorer {
    stage: ResolvedStage,
    header: Header,
    objects: Arc<VirtualScene>,
    seed: u64,
    /// The pipeline's `sample.path`, whose outputs feed the filter (`None`: no flicker
    /// score).
    sampler: Option<(PathRunner, ResolvedStage)>,
    /// The pipeline's `temporal.accumulate` between the sampler and the filter, which
    /// the still-camera runs pass through too.
    accumulator: Option<ResolvedStage>,
    /// The indices of the frames scored (those with a reference).
    scored_frames: Vec<usize>,
    unfiltered: Mse,
    filtered: Mse,
    gaussian: Mse,
    /// Per layer (e_r_dir, e_r_ind, e_rv_dir, e_rv_ind): unfiltered, filtered.
    layers: [(Mse, Mse); 4],
    flicker_temporal: Mse,
    flicker_spatial: Mse,
}

/// A running mean of squared errors.
#[derive(Default)]
struct Mse {
    sum: f64,
    count: u64,
}

impl Mse {
    fn add_layers(&mut self, a: &Vec3Image, b: &Vec3Image) {
        for (x, y) in a.data.iter().zip(&b.data) {
            if x.is_finite() && y.is_finite() {
                let d = (*x - *y).as_dvec3();
                self.sum += d.length_squared();
                self.count += 3;
            }
        }
    }

    fn value(&self) -> f64 {
        if self.count == 0 {
            f64::NAN
        } else {
            self.sum / self.count as f64
        }
    }
}

impl FilterScorer {
    pub fn new(
        stage: &ResolvedStage,
        header: &Header,
        objects: Arc<VirtualScene>,
        seed: u64,
        sampler: Option<(PathRunner, ResolvedStage)>,
        accumulator: Option<&ResolvedStage>,
    ) -> FilterScorer {
        FilterScorer {
            stage: stage.clone(),
            header: header.clone(),
            objects,
            seed,
            sampler,
            accumulator: accumulator.cloned(),
            scored_frames: Vec::new(),
            unfiltered: Mse::default(),
            filtered: Mse::default(),
            gaussian: Mse::default(),
            layers: Default::default(),
            flicker_temporal: Mse::default(),
            flicker_spatial: Mse::default(),
        }
    }

    fn input(&self, role: &str) -> String {
        super::ports::input(&self.stage, role)
    }

    fn output(&self, role: &str) -> String {
        super::ports::output(&self.stage, role)
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
        let truth = [
            &reference.e_r_dir,
            &reference.e_r_ind,
            &reference.e_rv_dir,
            &reference.e_rv_ind,
        ];
        let radius = self.stage.params.int("radius").max(0) as usize;
        for (k, (role, truth)) in LAYERS.into_iter().zip(truth).enumerate() {
            let (Ok(input), Ok(output)) = (
                frame.radiance(&self.input(role)),
                frame.radiance(&self.output(&format!("filtered_{role}"))),
            ) else {
                return Ok(());
            };
            self.unfiltered.add_layers(input, truth);
            self.filtered.add_layers(output, truth);
            self.layers[k].0.add_layers(input, truth);
            self.layers[k].1.add_layers(output, truth);
            self.gaussian
                .add_layers(&plain_gaussian(input, radius, radius as f32 / 2.0), truth);
        }
        if let Some((runner, sampler)) = &self.sampler {
            let runs = flicker_runs(runner, frame)?;
            let (sum, count) = self.flicker(frame, sampler, &runs, true)?;
            self.flicker_temporal.sum += sum;
            self.flicker_temporal.count += count;
            let (sum, count) = self.flicker(frame, sampler, &runs, false)?;
            self.flicker_spatial.sum += sum;
            self.flicker_spatial.count += count;
        }
        self.scored_frames.push(frame.index);
        Ok(())
    }

    /// A fresh instance of `stage` (no state from earlier frames) with `params`.
    fn build(
        &self,
        stage: &ResolvedStage,
        params: &relume_graph::Params,
    ) -> Result<Box<dyn Stage>, String> {
        let registry = relume_stages::registry();
        let info = registry
            .get(stage.kind)
            .ok_or_else(|| format!("no stage kind {}", stage.kind))?;
        let ctx = BuildContext {
            stage_name: &stage.name,
            params,
            inputs: &stage.inputs,
            outputs: &stage.outputs,
            header: &self.header,
            out_dir: std::path::Path::new("."),
            seed: self.seed,
            world: &relume_stages::world::world_of(self.objects.clone()),
        };
        (info.build)(&ctx).map_err(|e| e.to_string())
    }

    /// The summed per-pixel variance over the still-camera frames (after the first) of
    /// the filtered layers, and the number of values it sums.
    fn flicker(
        &self,
        frame: &Frame,
        sampler: &ResolvedStage,
        runs: &[IrradianceLayers],
        temporal: bool,
    ) -> Result<(f64, u64), String> {
        let mut params = self.stage.params.clone();
        params.set("temporal", ParamValue::Bool(temporal));
        let mut filter = self.build(&self.stage, &params)?;
        let mut accumulator = match &self.accumulator {
            Some(stage) => Some(self.build(stage, &stage.params)?),
            None => None,
        };
        let mut outputs: Vec<[Vec3Image; 4]> = Vec::new();
        for (k, run) in runs.iter().enumerate() {
            let mut still = frame.clone();
            still.index = frame.index + k;
            insert_outputs(&mut still, sampler, run);
            if let Some(accumulator) = &mut accumulator {
                accumulator.process(&mut still).map_err(|e| e.to_string())?;
            }
            filter.process(&mut still).map_err(|e| e.to_string())?;
            let layer = |role: &str| {
                still
                    .radiance(&self.output(&format!("filtered_{role}")))
                    .cloned()
                    .map_err(|e| e.to_string())
            };
            outputs.push([
                layer(LAYERS[0])?,
                layer(LAYERS[1])?,
                layer(LAYERS[2])?,
                layer(LAYERS[3])?,
            ]);
        }
        let settled = &outputs[1..];
        let (mut sum, mut count) = (0.0, 0u64);
        for layer in 0..4 {
            for i in 0..settled[0][layer].data.len() {
                let values: Vec<DVec3> = settled
                    .iter()
                    .map(|o| o[layer].data[i].as_dvec3())
                    .collect();
                if !values.iter().all(|v| v.is_finite()) {
                    continue;
                }
                let mean = values.iter().sum::<DVec3>() / values.len() as f64;
                let var = values
                    .iter()
                    .map(|v| (*v - mean) * (*v - mean))
                    .sum::<DVec3>()
                    / (values.len() - 1) as f64;
                sum += var.x + var.y + var.z;
                count += 3;
            }
        }
        Ok((sum, count))
    }

    pub fn report(&self) -> Value {
        json!({
            "frames_scored": self.scored_frames.len(),
            "scored_frames": self.scored_frames,
            "mse_unfiltered": self.unfiltered.value(),
            "mse_filtered": self.filtered.value(),
            "mse_gaussian_same_radius": self.gaussian.value(),
            "mse_unfiltered_by_layer": self.layers.iter().map(|l| l.0.value()).collect::<Vec<_>>(),
            "mse_filtered_by_layer": self.layers.iter().map(|l| l.1.value()).collect::<Vec<_>>(),
            "temporal_flicker": self.flicker_temporal.value(),
            "temporal_flicker_spatial_only": self.flicker_spatial.value(),
            "flicker_as_configured": if self.stage.params.bool("temporal") {
                self.flicker_temporal.value()
            } else {
                self.flicker_spatial.value()
            },
        })
    }
}

/// The sampling of `frame` re-run [`FLICKER_FRAMES`] times with fresh random numbers.
fn flicker_runs(runner: &PathRunner, frame: &Frame) -> Result<Vec<IrradianceLayers>, String> {
    (0..FLICKER_FRAMES)
        .map(|k| {
            let params = PathParams {
                seed: rng::hash(&[runner.params.seed, FLICKER_SALT, k]),
                ..runner.params
            };
            runner
                .run(frame, &params)
                .unwrap_or_else(|| Err("the frame lost the sampling's inputs".into()))
        })
        .collect()
}

/// Puts a sampling run's products into `frame` under the names `sampler` gives them.
pub fn insert_outputs(frame: &mut Frame, sampler: &ResolvedStage, run: &IrradianceLayers) {
    let names: Vec<String> = LAYER_OUTPUTS
        .iter()
        .map(|(role, _)| super::ports::output(sampler, role))
        .collect();
    run.clone().insert_into(frame, &names);
}

/// A separable image-space Gaussian over |i| <= `radius` with standard deviation
/// `sigma` pixels; pixels without an estimate neither contribute nor receive one.
pub fn plain_gaussian(layer: &Vec3Image, radius: usize, sigma: f32) -> Vec3Image {
    let (w, h) = (layer.width as usize, layer.height as usize);
    let weights: Vec<f32> = (0..=radius)
        .map(|i| (-0.5 * (i as f32 / sigma.max(1e-6)).powi(2)).exp())
        .collect();
    let pass = |src: &Vec3Image, step: (usize, usize)| {
        let mut dst = Image::filled(layer.width, layer.height, Vec3::NAN);
        for y in 0..h {
            for x in 0..w {
                if !src.data[y * w + x].is_finite() {
                    continue;
                }
                let (mut sum, mut total) = (Vec3::ZERO, 0.0);
                for (d, &weight) in (-(radius as isize)..=radius as isize)
                    .zip(weights.iter().rev().chain(weights.iter().skip(1)))
                {
                    let (sx, sy) = (
                        x as isize + d * step.0 as isize,
                        y as isize + d * step.1 as isize,
                    );
                    if sx < 0 || sy < 0 || sx >= w as isize || sy >= h as isize {
                        continue;
                    }
                    let v = src.data[sy as usize * w + sx as usize];
                    if v.is_finite() {
                        sum += weight * v;
                        total += weight;
                    }
                }
                dst.data[y * w + x] = sum / total;
            }
        }
        dst
    };
    pass(&pass(layer, (1, 0)), (0, 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plain_gaussian_keeps_constants_and_holes() {
        let mut layer = Image::filled(20, 10, Vec3::splat(2.0));
        layer.data[25] = Vec3::NAN;
        let out = plain_gaussian(&layer, 4, 2.0);
        assert!(out.data[25].is_nan());
        for (i, v) in out.data.iter().enumerate().filter(|(i, _)| *i != 25) {
            assert!(
                (*v - Vec3::splat(2.0)).abs().max_element() < 1e-6,
                "{i}: {v}"
            );
        }
        // An impulse spreads as the normalized 1D weights along each axis.
        let mut impulse = Image::filled(21, 21, Vec3::ZERO);
        impulse.data[10 * 21 + 10] = Vec3::ONE;
        let out = plain_gaussian(&impulse, 3, 1.0);
        let norm: f32 = (-3..=3).map(|i: i32| (-0.5 * (i * i) as f32).exp()).sum();
        let expect = (-0.5f32).exp() / norm * (1.0 / norm);
        assert!((out.data[10 * 21 + 11].x - expect).abs() < 1e-6);
        assert_eq!(out.data[10 * 21 + 14].x, 0.0, "outside the radius");
    }
}
