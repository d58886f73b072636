//! `relume eval`: scores every stage of a pipeline that has something to be scored
//! against, frame by frame as the frames leave the pipeline.
//!
//! | stage kind | keys | needs ground truth |
//! |---|---|---|
//! | `pose.track` | `ate_rmse_m`, `rpe_translation_m_per_frame`, `rpe_rotation_deg_per_frame`, `rpe_translation_m_per_s`, `rpe_rotation_deg_per_s`, `lost_frames`, `frames_scored` (against the recording's poses, TUM RGB-D's definitions; see [`trajectory`]) | no (the recording's poses) |
//! | `depth.fuse` | `rmse_raw_m`, `rmse_fused_m`, `holes_raw`, `holes_fused` | yes |
//! | `depth.fuse` | `warp_rmse_raw_m`, `warp_rmse_fused_m`, `warp_overlap_raw`, `warp_overlap_fused` (frame t-1 forward-warped into frame t against raw depth t; null where no two consecutive frames were compared) | no |
//! | `normals.*` | `mean_angle_deg`, `median_angle_deg`, `valid_fraction` | yes |
//! | `material.estimate` | `albedo_rel_error_median`, `albedo_rmse`, `albedo_ratio_mean`, `coverage`, `pixels_scored` (rho against the true albedo of recordings made by `relume synth`; see [`material`]) | yes |
//! | `color.compensate` | `transform_rel_error_median` (relative Frobenius error of c_t against `M_0 M_t^-1`), `gain_transform_rel_error_median` (the same for A_t), `image_rel_error_median`, `gain_image_rel_error_median` (relative RMS error of the compensated image, and of A_t applied instead, against the true reference image) | yes |
//! | `color.compensate` | `frames`, `approximate_frames`, `pairs_kept_median` | no |
//! | `gbuffer.splat` | `reference_psnr_db` (reference against the compensated camera image where both exist and the camera pixel is not clipped, peak 1), `coverage` | no |
//! | `light.importance` | `pdf_integral`, `irradiance_rel_error`, `maps_scored` (against brute-force integration of each map; see [`light`]) | no |
//! | `light.val` | `sh_irradiance_rel_error`, `val_center_drift_m`, `environment_static`, `lights` | no |
//! | `sample.path` | `ratio_rmse`, `ratio_rmse_alternative`, `object_aware`, `unbiased_p`, `frames_scored`, `scored_frames` (their indices), `region_pixels` (against 1024-sample references; see [`sampling`]) | no |
//! | `sample.dir`, `sample.val` | `ratio_rmse`, `ratio_rmse_all`, `frames_scored`, `scored_frames`, `region_pixels` (against the default `sample.path`'s 1024-sample references on the renderer's inputs; see [`renderer`]) | no |
//! | `filter.axis_aligned` | `mse_unfiltered`, `mse_filtered`, `mse_gaussian_same_radius`, `mse_unfiltered_by_layer`, `mse_filtered_by_layer` (per layer: E_R^dir, E_R^ind, E_RV^dir, E_RV^ind), `temporal_flicker`, `temporal_flicker_spatial_only`, `flicker_as_configured`, `frames_scored`, `scored_frames` (against the same references; see [`filter`]) | no |
//! | `composite.differential` | `psnr_db`, `psnr_db_unfiltered`, `psnr_db_by_frame`, `frames_scored`, `scored_frames` (against a composite of the references; see [`composite`]) | no |
//! | `composite.differential` | `psnr_db_truth`, `psnr_db_truth_differential`, `psnr_db_truth_objects`, `shadow_ratio_bias`, `differential_pixels`, `object_pixels`, `truth_noise_psnr_db`, `psnr_db_truth_by_frame`, `differential_ratio_by_frame`; over a light change (`relume synth --panel-off-at`): `change_frame`, `change_lag_frames`, `change_final_ratio`, `change_ratio_before` or `change_unmeasured` (see [`change`]) (against the true frame with the objects in the room, on recordings of `relume synth`; `truth_unavailable` says why a recording of another generator version has none; see [`composite`] and [`true_frame`]) | yes |
//!
//! Ground truth comes from the recording's truth stream (synthetic recordings).

pub mod change;
mod color;
pub mod composite;
mod depth;
pub mod diff;
pub mod filter;
pub mod ghost;
pub mod light;
pub mod material;
mod normals;
mod ports;
pub mod renderer;
pub mod report;
pub mod sampling;
pub mod trajectory;
pub mod true_frame;
mod truth;

pub use depth::forward_warp;
pub use truth::FrameTruth;

use ports::{input, output};
use relume_graph::{Frame, Pipeline, ResolvedStage};
use relume_recording::{Header, StreamKind};
use relume_stages::sample::{RENDERERS, renderer_kind};
use serde_json::{Map, Value, json};
use std::sync::Arc;

enum Scorer {
    Depth(depth::DepthScorer),
    Normals(normals::NormalsScorer),
    Material(material::MaterialScorer),
    Compensation(color::CompensationScorer),
    Reference(color::ReferenceScorer),
    Importance(light::ImportanceScorer),
    Val(light::ValScorer),
    Path(Box<sampling::PathScorer>),
    Renderer(Box<renderer::RatioScorer>),
    Filter(Box<filter::FilterScorer>),
    Composite(Box<composite::CompositeScorer>),
    Trajectory(trajectory::TrajectoryScorer),
}

impl Scorer {
    /// True for a scorer with nothing to report without ground truth (see the module
    /// table): the normals and the real albedo, compared with the truth alone.
    fn needs_truth(&self) -> bool {
        matches!(self, Scorer::Normals(_) | Scorer::Material(_))
    }

    /// What a scorer that needs ground truth compares with, for messages.
    fn truth_name(&self) -> &'static str {
        match self {
            Scorer::Material(_) => "the true albedo",
            _ => "the true normals",
        }
    }
}

/// Stage names for a message: "a, b" or "none".
fn name_list<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let names: Vec<&str> = names.collect();
    if names.is_empty() {
        "none".to_string()
    } else {
        names.join(", ")
    }
}

/// Scores a pipeline's stages over the frames given to [`Evaluator::observe`].
pub struct Evaluator {
    scorers: Vec<(String, &'static str, Scorer)>,
    /// The many-sample references, when a scorer needs them.
    references: Option<sampling::ReferenceSchedule>,
    /// The true frames with the objects in the room, when the recording is the
    /// synthetic room and a composite is scored.
    truths: Option<true_frame::TruthRenderer>,
    /// Why a recording of `relume synth` has no true frame (another generator version).
    truth_unavailable: Option<String>,
    reference_stride: u32,
    frames: usize,
    frames_with_truth: usize,
}

/// What `relume eval` scores, and how.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Names of the stages to score (empty: every stage that can be scored).
    pub stages: Vec<String>,
    /// The references of `sample.path`, `filter.axis_aligned` and
    /// `composite.differential` are computed on the pixels whose x and y are multiples
    /// of this (1: every pixel; n: n^2 times less work, the scores then average over
    /// that lattice).
    pub reference_stride: u32,
    /// The frames the run will replay (`None`: not known). A replay without frames 14
    /// and 29 gets references on its last frame ([`sampling::fallback_frame`]).
    pub frames: Option<std::ops::Range<usize>>,
    /// Score every frame of this range (its references and true frames computed on
    /// each) instead of frames 14 and 29: the scores over time, e.g. while an object
    /// moves. `None`: the usual schedule.
    pub score_frames: Option<std::ops::Range<usize>>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            stages: Vec::new(),
            reference_stride: 1,
            frames: None,
            score_frames: None,
        }
    }
}

impl Evaluator {
    /// An evaluator for the scorable stages of `pipeline` run with `seed` (see the
    /// module table), or those `options` names. Fails when a named stage is not in the
    /// pipeline or cannot be scored, or when the stages to score need ground truth the
    /// recording lacks (normals).
    pub fn new(
        pipeline: &Pipeline,
        header: &Header,
        seed: u64,
        options: &EvalOptions,
    ) -> Result<Evaluator, String> {
        let compensated = pipeline
            .stages
            .iter()
            .find(|s| s.kind == "color.compensate")
            .map(|s| (output(s, "compensated"), input(s, "color")));
        // The renderer whose references every score takes: a renderer that references
        // itself (sample.path: its own math with 1024 samples), or else the first
        // renderer of the registry's order in the pipeline, with the default
        // sample.path's references on its inputs.
        let find = |kind: &str| pipeline.stages.iter().find(|s| s.kind == kind);
        let renderers = || {
            let by_reference = |own: bool| {
                RENDERERS
                    .iter()
                    .filter(move |r| r.references_itself == own)
                    .filter_map(|r| find(r.info.kind))
            };
            by_reference(true).chain(by_reference(false))
        };
        let sampler = renderers().next();
        let references_itself =
            |s: &ResolvedStage| renderer_kind(s.kind).is_some_and(|r| r.references_itself);
        let (objects, k) = (
            relume_stages::world::object_world(&pipeline.world).clone(),
            header.depth_intrinsics,
        );
        let runner = sampler.map(|s| match references_itself(s) {
            true => sampling::PathRunner::new(s, objects.clone(), k, seed),
            false => sampling::PathRunner::reference_for(s, objects.clone(), k, seed),
        });
        // The filter's flicker scores re-run the sampler itself: one that references
        // itself only.
        let resampler = sampler.filter(|s| references_itself(s));
        // The frame at which a synthetic room's light changes, whose lag the composite's
        // scores measure.
        let light_change = (header.provenance.tool == relume_recording::synth::SYNTH_TOOL)
            .then(|| relume_recording::synth::LightSwitches::of(&header.provenance).ok())
            .flatten()
            .and_then(|s| s.change_frame());
        let mut scorers: Vec<_> = pipeline
            .stages
            .iter()
            .filter_map(|s| {
                let scorer = match s.kind {
                    _ if references_itself(s) => Scorer::Path(Box::new(sampling::PathScorer::new(
                        s,
                        objects.clone(),
                        header.depth_intrinsics,
                        seed,
                    ))),
                    k if renderer_kind(k).is_some() => {
                        Scorer::Renderer(Box::new(renderer::RatioScorer::new(s)))
                    }
                    "pose.track" => {
                        Scorer::Trajectory(trajectory::TrajectoryScorer::new(output(s, "pose")))
                    }
                    "depth.fuse" => Scorer::Depth(depth::DepthScorer::new(
                        input(s, "depth"),
                        output(s, "fused_depth"),
                        input(s, "pose"),
                        header.depth_intrinsics,
                    )),
                    k if k.starts_with("normals.") => {
                        Scorer::Normals(normals::NormalsScorer::new(output(s, "normals")))
                    }
                    "material.estimate" => Scorer::Material(material::MaterialScorer::new(
                        output(s, "real_albedo"),
                        header,
                    )),
                    "color.compensate" => Scorer::Compensation(color::CompensationScorer::new(
                        input(s, "color"),
                        output(s, "compensated"),
                        output(s, "compensation"),
                    )),
                    "gbuffer.splat" => Scorer::Reference(color::ReferenceScorer::new(
                        output(s, "reference"),
                        output(s, "reference_coverage"),
                        compensated.clone(),
                    )),
                    "light.importance" => Scorer::Importance(light::ImportanceScorer::new(
                        input(s, "environment"),
                        output(s, "light_table"),
                    )),
                    "light.val" => Scorer::Val(light::ValScorer::new(
                        input(s, "indirect_light"),
                        output(s, "lights"),
                    )),
                    "filter.axis_aligned" => Scorer::Filter(Box::new(filter::FilterScorer::new(
                        s,
                        header,
                        relume_stages::world::object_world(&pipeline.world)
                            .scene
                            .clone(),
                        seed,
                        runner
                            .clone()
                            .filter(|_| resampler.is_some())
                            .zip(resampler.cloned()),
                        find("temporal.accumulate"),
                    ))),
                    "composite.differential" => {
                        Scorer::Composite(Box::new(composite::CompositeScorer::new(
                            s,
                            sampler,
                            light_change,
                            objects.moving.is_some(),
                        )))
                    }
                    _ => return None,
                };
                Some((s.name.clone(), s.kind, scorer))
            })
            .collect();
        for name in &options.stages {
            if !scorers.iter().any(|(n, _, _)| n == name) {
                let what = if pipeline.stages.iter().any(|s| &s.name == name) {
                    "cannot be scored"
                } else {
                    "is not in the pipeline"
                };
                let scorable = name_list(scorers.iter().map(|(n, _, _)| n.as_str()));
                return Err(format!(
                    "stage `{name}` {what}; the stages eval can score here: {scorable}"
                ));
            }
        }
        // Normals are scored against the truth alone: named on a recording without a
        // truth stream, or the only stages to score, they would run the whole pipeline
        // to report nothing.
        let has_truth = header.streams.contains(&StreamKind::Truth);
        if !has_truth
            && let Some((name, kind, scorer)) = scorers
                .iter()
                .find(|(n, _, s)| options.stages.contains(n) && s.needs_truth())
        {
            let scorable = name_list(
                scorers
                    .iter()
                    .filter(|(_, _, s)| !s.needs_truth())
                    .map(|(n, _, _)| n.as_str()),
            );
            return Err(format!(
                "stage `{name}` ({kind}) is scored against {}, and the recording \
                 has no ground truth; the stages eval can score on it: {scorable}",
                scorer.truth_name()
            ));
        }
        if !options.stages.is_empty() {
            scorers.retain(|(n, _, _)| options.stages.contains(n));
        }
        if !has_truth && !scorers.is_empty() && scorers.iter().all(|(_, _, s)| s.needs_truth()) {
            let names: Vec<String> = scorers.iter().map(|(n, _, _)| format!("`{n}`")).collect();
            let mut truths: Vec<&str> = scorers.iter().map(|(_, _, s)| s.truth_name()).collect();
            truths.dedup();
            return Err(format!(
                "the pipeline's only stages to score, {}, are scored against {}, and the \
                 recording has no ground truth",
                names.join(", "),
                truths.join(" and ")
            ));
        }
        let needs_references = scorers.iter().any(|(_, _, s)| {
            matches!(
                s,
                Scorer::Path(_) | Scorer::Renderer(_) | Scorer::Filter(_) | Scorer::Composite(_)
            )
        });
        // A renderer scored against another's references (sample.val reads neither
        // the camera radiance nor a light table): without them every reference score
        // would be left empty without a word.
        if let (true, Some(runner), Some(sampler)) = (needs_references, &runner, sampler) {
            let made = |product: &str| {
                pipeline
                    .stages
                    .iter()
                    .any(|s| s.outputs.values().any(|o| o == product))
            };
            if let Some(missing) = runner.input_products().iter().find(|p| !made(p)) {
                return Err(format!(
                    "the 1024-sample references that `{}` ({}) and the stages after it are scored against read `{missing}`, which no stage of the pipeline makes (light.importance makes `light_table`, color.compensate `compensated`); add that stage, or name only other stages with --stage",
                    sampler.name, sampler.kind
                ));
            }
        }
        let references = runner.filter(|_| needs_references).map(|r| {
            let schedule = sampling::ReferenceSchedule::new(
                r,
                options.reference_stride,
                options.frames.clone(),
            );
            match &options.score_frames {
                Some(frames) => schedule.scoring(frames.clone()),
                None => schedule,
            }
        });
        let scores_composite = scorers
            .iter()
            .any(|(_, _, s)| matches!(s, Scorer::Composite(_)));
        let truths = scores_composite
            .then(|| true_frame::TruthRenderer::new(header, objects.clone(), seed))
            .flatten();
        let synthetic = header.provenance.tool == relume_recording::synth::SYNTH_TOOL;
        let truth_unavailable =
            true_frame::unavailable(header).filter(|_| scores_composite && synthetic);
        Ok(Evaluator {
            scorers,
            references,
            truths,
            truth_unavailable,
            reference_stride: options.reference_stride.max(1),
            frames: 0,
            frames_with_truth: 0,
        })
    }

    /// Shares the many-sample references with the other evaluators given `cache`
    /// (see [`sampling::ReferenceCache`]): the scores do not change.
    pub fn share_references(&mut self, cache: sampling::ReferenceCache) {
        if let Some(truths) = &mut self.truths {
            truths.share(cache.1.clone());
        }
        if let Some(schedule) = &mut self.references {
            schedule.share(cache);
        }
    }

    /// The true frames the first `composite.differential` stage was scored against.
    pub fn true_composites(&self) -> Vec<Arc<true_frame::TrueComposite>> {
        self.scorers
            .iter()
            .find_map(|(_, _, s)| match s {
                Scorer::Composite(c) => Some(c.truths().to_vec()),
                _ => None,
            })
            .unwrap_or_default()
    }

    /// The reference composites of the scored frames of the first
    /// `composite.differential` stage, as (frame, image).
    pub fn reference_composites(&self) -> Vec<(usize, &relume_base::raster::Rgb8Image)> {
        self.scorers
            .iter()
            .find_map(|(_, _, s)| match s {
                Scorer::Composite(c) => Some(c.references().iter().map(|(f, i)| (*f, i)).collect()),
                _ => None,
            })
            .unwrap_or_default()
    }

    /// True when no stage of the pipeline can be scored.
    pub fn is_empty(&self) -> bool {
        self.scorers.is_empty()
    }

    /// Scores one finished frame (frames must come in order). Fails only when the
    /// recording's ground truth cannot be decoded.
    pub fn observe(&mut self, frame: &Frame) -> Result<(), String> {
        let truth = FrameTruth::of(frame)?;
        self.frames += 1;
        self.frames_with_truth += truth.is_some() as usize;
        // The 1024-sample reference layers on scored frames.
        let reference = match &mut self.references {
            Some(schedule) => schedule.reference(frame)?,
            None => None,
        };
        // The true frame on the frames and lattice of the references.
        let true_composite = match (&self.truths, &reference) {
            (Some(truths), Some(_)) => truths.render(frame, self.reference_stride)?,
            _ => None,
        };
        for (_, _, scorer) in &mut self.scorers {
            match scorer {
                Scorer::Depth(s) => s.observe(frame, truth.as_ref()),
                Scorer::Normals(s) => s.observe(frame, truth.as_ref()),
                Scorer::Material(s) => s.observe(frame, truth.as_ref()),
                Scorer::Compensation(s) => s.observe(frame, truth.as_ref()),
                Scorer::Reference(s) => s.observe(frame),
                Scorer::Importance(s) => s.observe(frame),
                Scorer::Val(s) => s.observe(frame),
                Scorer::Path(s) => s.observe(frame, reference.as_deref())?,
                Scorer::Renderer(s) => s.observe(frame, reference.as_deref()),
                Scorer::Filter(s) => s.observe(frame, reference.as_deref())?,
                Scorer::Composite(s) => {
                    s.observe(frame, reference.as_deref(), true_composite.as_ref())?
                }
                Scorer::Trajectory(s) => s.observe(frame),
            }
        }
        Ok(())
    }

    /// What the first composite's references and true frames cost per scored frame
    /// (seconds: `reference_render_s`, `truth_render_s`), `None` without a scored
    /// composite.
    pub fn scoring_costs(&self) -> Option<Value> {
        self.scorers.iter().find_map(|(_, _, s)| match s {
            Scorer::Composite(c) => Some(c.costs()),
            _ => None,
        })
    }

    /// True when every observed frame carried ground truth.
    pub fn has_truth(&self) -> bool {
        self.frames > 0 && self.frames_with_truth == self.frames
    }

    /// The scores: `{frames, ground_truth, stages: {<stage name>: {kind, <keys>}}}`.
    pub fn report(&self) -> Value {
        let mut stages = Map::new();
        for (name, kind, scorer) in &self.scorers {
            let scores = match scorer {
                Scorer::Depth(s) => s.report(),
                Scorer::Normals(s) => s.report().unwrap_or_else(|| json!({})),
                Scorer::Material(s) => s.report().unwrap_or_else(|| json!({})),
                Scorer::Compensation(s) => s.report(),
                Scorer::Reference(s) => s.report(),
                Scorer::Importance(s) => s.report(),
                Scorer::Val(s) => s.report(),
                Scorer::Path(s) => s.report(),
                Scorer::Renderer(s) => s.report(),
                Scorer::Filter(s) => s.report(),
                Scorer::Composite(s) => s.report(),
                Scorer::Trajectory(s) => s.report(),
            };
            let mut entry = Map::new();
            entry.insert("kind".into(), json!(kind));
            if let Value::Object(scores) = scores {
                entry.extend(scores);
            }
            if let (Scorer::Composite(_), Some(why)) = (scorer, &self.truth_unavailable) {
                entry.insert("truth_unavailable".into(), json!(why));
            }
            stages.insert(name.clone(), Value::Object(entry));
        }
        json!({
            "frames": self.frames,
            "ground_truth": self.has_truth(),
            "stages": stages,
        })
    }
}
pub mod batch;
