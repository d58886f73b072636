//! Scores of `sample.path` against references computed with many more samples.
//!
//! On a scored frame (every [`SCORE_EVERY`]-th, at most [`MAX_SCORED_FRAMES`]; the last
//! frame of a replay that has none of those, see [`fallback_frame`]) the evaluator
//! re-runs the stage's own math on the frame's inputs:
//! - a reference with 4 x 64 direct and 4 x 64 indirect samples per primary sample, from
//!   four independent seeds (1024 samples per pixel and layer, 64 times the default),
//!   on every pixel or on a lattice of them ([`ReferenceSchedule`]); the scores below
//!   and those of the filter and the composite are taken where it has values;
//! - `ratio_rmse`: RMSE of the stage's E_RV / E_R (channel means of direct + indirect)
//!   against the reference ratio, over real pixels where a reference path met the
//!   object (elsewhere the ratio is exactly 1 by construction);
//! - `ratio_rmse_alternative`: the same for the other scheme (object-aware on when the
//!   stage has it off, and the reverse) at the stage's sample counts, and
//!   `object_aware` which of the two the stage runs: what the object-aware scheme buys;
//! - `unbiased_p`: the stage's estimator run with 8 further seeds; the mean of E_RV
//!   over that region is compared with the reference by a z-test (standard error from
//!   the spread of the 8 runs and the reference's share of it); a p-value far below
//!   0.01 says the estimator converges to something else. Pooled over scored frames.

use glam::{Affine3A, Vec3};
use relume_base::pinhole::Pinhole;
use relume_base::raster::{Image, ScalarImage, Vec3Image};
use relume_base::rng;
use relume_graph::{Frame, ResolvedStage};
use relume_recording::Intrinsics;
use relume_scene::light::voxels::VoxelVolume;
use relume_stages::kind::FrameProducts;
use relume_stages::sample::path::{
    IrradianceLayers, ObjectVisibility, PathInputs, PathParams, sample_path,
};
use relume_stages::sample::query::QueryKind;
use relume_stages::world::ObjectWorld;
use serde_json::{Value, json};
use std::ops::Range;
use std::sync::Arc;

/// Every how many frames `sample.path` is scored (frames 14, 29, ...: late enough that
/// the cloud-lit environment exists).
pub const SCORE_EVERY: usize = 15;
/// The most frames that get references and scores (each costs about 70 runs of the
/// stage with the sample.path scorer, 32 without it).
pub const MAX_SCORED_FRAMES: usize = 2;
/// Independent reference runs, each with 64 + 64 samples per primary sample.
pub const REFERENCE_RUNS: u64 = 4;
const REFERENCE_SAMPLES: u32 = 64;
/// Primary samples per pixel of every reference, whatever the scored stage takes, so
/// that pipelines with different sample counts are scored against the same
/// references (4 x 64 x 4 runs = 1024 samples per pixel and layer).
const REFERENCE_PRIMARY: u32 = 4;
/// Further runs of the stage's own configuration for the bias test.
const BIAS_RUNS: u64 = 8;
/// Salts of the scorer's seeds (distinct from the stage's).
const REFERENCE_SALT: u64 = 0x5245_4645;
const BIAS_SALT: u64 = 0x4249_4153;

pub(super) fn channel_mean(v: Vec3) -> f64 {
    ((v.x + v.y + v.z) / 3.0) as f64
}

/// Two-sided p-value of a standard normal z (erfc by Numerical Recipes' Chebyshev
/// fit, relative error below 1.2e-7).
pub fn two_sided_p(z: f64) -> f64 {
    let x = z.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.5 * x);
    let poly = -x * x - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    (t * poly.exp()).min(1.0)
}

/// Re-runs a pipeline's `sample.path` math on the inputs a finished frame holds, with
/// other parameters (more samples, other seeds).
#[derive(Clone)]
pub struct PathRunner {
    /// depth, normals, pose, radiance, light_table.
    inputs: [String; 5],
    /// The distance impostor, for the `em` and `dit` queries.
    environment: Option<String>,
    /// The scene's voxel volume, for the `vct` query, and the objects' solid volume.
    voxels: Option<String>,
    object_voxels: Option<Arc<VoxelVolume>>,
    /// The stage's own settings.
    pub params: PathParams,
    /// The pipeline's objects (posed at each frame when they move).
    objects: ObjectWorld,
    intrinsics: Intrinsics,
}

impl PathRunner {
    pub fn new(
        stage: &ResolvedStage,
        objects: ObjectWorld,
        intrinsics: Intrinsics,
        seed: u64,
    ) -> PathRunner {
        let params = PathParams::from_params(&stage.params, seed);
        PathRunner {
            inputs: ["depth", "normals", "pose", "radiance", "light_table"]
                .map(|r| super::ports::input(stage, r)),
            environment: stage.inputs.get("environment").cloned(),
            voxels: stage.inputs.get("voxels").cloned(),
            object_voxels: params.object_volume(&objects.scene).map(Arc::new),
            params,
            objects,
            intrinsics,
        }
    }

    /// A runner of the default `sample.path` (screen-space marching) on the inputs of
    /// another renderer (`sample.dir` reads the same roles; `sample.val` reads the
    /// geometry and pose, and the camera radiance and light table are then the products
    /// `sample.path` would read by default): the references that renderer is scored
    /// against are the default's.
    pub fn reference_for(
        stage: &ResolvedStage,
        objects: ObjectWorld,
        intrinsics: Intrinsics,
        seed: u64,
    ) -> PathRunner {
        let path = &relume_stages::sample::path::INFO;
        let defaults = (path.ports)(&relume_graph::Params::defaults(path.params));
        let input = |role: &str| match stage.inputs.get(role) {
            Some(bound) => bound.clone(),
            None => defaults
                .inputs
                .iter()
                .find(|p| p.role == role)
                .map_or(role.to_string(), |p| p.default_product.clone()),
        };
        PathRunner {
            inputs: ["depth", "normals", "pose", "radiance", "light_table"].map(input),
            environment: None,
            voxels: None,
            object_voxels: None,
            params: PathParams {
                seed,
                ..PathParams::default()
            },
            objects,
            intrinsics,
        }
    }

    /// The products the references read (depth, normals, pose, camera radiance, light
    /// table), for a check that the pipeline makes them.
    pub fn input_products(&self) -> &[String; 5] {
        &self.inputs
    }

    /// The stage's outputs with `params` on `frame`'s inputs; `None` when the frame
    /// lacks one of them.
    pub fn run(
        &self,
        frame: &Frame,
        params: &PathParams,
    ) -> Option<Result<IrradianceLayers, String>> {
        let [depth, normals, pose, radiance, table] = &self.inputs;
        let (Ok(depth), Ok(normals), Ok(pose), Ok(radiance), Ok(table)) = (
            frame.depth(depth),
            frame.normals(normals),
            frame.pose(pose),
            frame.radiance(radiance),
            frame.light_table(table),
        ) else {
            return None;
        };
        let environment = match &self.environment {
            Some(name) => Some(frame.environment(name).ok()?.as_ref()),
            None => None,
        };
        let voxels = match &self.voxels {
            Some(name) => Some(frame.voxels(name).ok()?.as_ref()),
            None => None,
        };
        let objects = match self.objects.scene_at(frame.index as u64) {
            Ok(objects) => objects,
            Err(e) => return Some(Err(e.to_string())),
        };
        let posed_voxels = match self.objects.moves() {
            true => params.object_volume(&objects).map(Arc::new),
            false => None,
        };
        let inputs = PathInputs {
            depth,
            normals,
            radiance,
            camera: Pinhole::new(&self.intrinsics, depth.width, depth.height),
            camera_to_world: Affine3A::from_mat4(pose.matrix().as_mat4()),
            table,
            environment,
            voxels,
            objects: &objects,
            object_voxels: posed_voxels.as_deref().or(self.object_voxels.as_deref()),
            frame: frame.index as u64,
            spots: &self.objects.lights,
        };
        let mut out = IrradianceLayers::new(depth.width, depth.height);
        Some(
            sample_path(&inputs, params, &mut out)
                .map(|_| out)
                .map_err(|e| e.to_string()),
        )
    }
}

/// The settings of reference run `k` (of [`REFERENCE_RUNS`]) for a stage with
/// `params`, on the lattice of `stride`. Every query and sample count is scored against
/// the same reference: screen-space marching with self-occlusion, as `sample.path` runs
/// by default, with [`REFERENCE_PRIMARY`] primaries on every pixel, the objects tested
/// as meshes with as many samples as the room and their secondary bounce (whatever
/// paper 000's presets set for them).
fn reference_params(params: &PathParams, k: u64, stride: u32) -> PathParams {
    let defaults = PathParams::default();
    PathParams {
        query: QueryKind::Ssrt,
        material_dit: false,
        visibility: true,
        object_visibility: ObjectVisibility::Mesh,
        object_direct: 0,
        object_indirect: 0,
        self_bounce: true,
        object_aware_direct: false,
        primary: REFERENCE_PRIMARY,
        near_primary: 0,
        direct: REFERENCE_SAMPLES,
        indirect: REFERENCE_SAMPLES,
        object_aware: false,
        seed: rng::hash(&[params.seed, REFERENCE_SALT, k]),
        pixel_stride: stride,
        // Unused by the reference: reset so that pipelines differing only in them share
        // one (`reference_key`).
        iterations: defaults.iterations,
        object_voxels: defaults.object_voxels,
        candidates: defaults.candidates,
        cache_size: defaults.cache_size,
        ..*params
    }
}

/// The four irradiance layers of a frame with 1024 samples per pixel and layer: the
/// mean of [`REFERENCE_RUNS`] independent runs with 64 + 64 samples per primary
/// sample. `sample.path`, `filter.axis_aligned` and `composite.differential` are scored
/// against it.
pub struct ReferenceLayers {
    pub frame: usize,
    /// Only pixels whose x and y are multiples of this have values (NaN elsewhere).
    pub stride: u32,
    pub e_r_dir: Vec3Image,
    pub e_r_ind: Vec3Image,
    pub e_rv_dir: Vec3Image,
    pub e_rv_ind: Vec3Image,
    /// Where some reference path met an object.
    pub touched: Vec<bool>,
    /// Seconds its runs took.
    pub render_s: f64,
}

impl ReferenceLayers {
    /// The reference of `frame` for the stage's configuration in `runner`, on the
    /// pixels whose x and y are multiples of `stride`; `None` when the frame lacks an
    /// input.
    pub fn compute(
        runner: &PathRunner,
        frame: &Frame,
        stride: u32,
    ) -> Option<Result<ReferenceLayers, String>> {
        let started = std::time::Instant::now();
        let mut sums: Option<ReferenceLayers> = None;
        for k in 0..REFERENCE_RUNS {
            let params = runner.reference_params(k, stride);
            let out = match runner.run(frame, &params)? {
                Ok(out) => out,
                Err(e) => return Some(Err(e)),
            };
            let sums = sums.get_or_insert_with(|| {
                let zero = Image::filled(out.e_r_dir.width, out.e_r_dir.height, Vec3::ZERO);
                ReferenceLayers {
                    frame: frame.index,
                    stride,
                    e_r_dir: zero.clone(),
                    e_r_ind: zero.clone(),
                    e_rv_dir: zero.clone(),
                    e_rv_ind: zero,
                    touched: vec![false; out.touched.data.len()],
                    render_s: 0.0,
                }
            });
            let layers = [
                (&mut sums.e_r_dir, &out.e_r_dir),
                (&mut sums.e_r_ind, &out.e_r_ind),
                (&mut sums.e_rv_dir, &out.e_rv_dir),
                (&mut sums.e_rv_ind, &out.e_rv_ind),
            ];
            for (sum, run) in layers {
                for (s, v) in sum.data.iter_mut().zip(&run.data) {
                    *s += *v / REFERENCE_RUNS as f32;
                }
            }
            for (t, &o) in sums.touched.iter_mut().zip(&out.touched.data) {
                *t |= o != 0;
            }
        }
        sums.map(|mut layers| {
            layers.render_s = started.elapsed().as_secs_f64();
            Ok(layers)
        })
    }

    /// Whether pixel `i` of the image has reference values (lies on the lattice).
    pub fn has_pixel(&self, i: usize) -> bool {
        let (w, s) = (self.e_r_dir.width as usize, self.stride as usize);
        w > 0 && (i % w).is_multiple_of(s) && (i / w).is_multiple_of(s)
    }
}

/// The frame that gets a reference in a replay of `frames` with none of frames 14, 29,
/// ... (a short recording, or a range between them): its last, so that the scores are
/// never empty for want of a frame (its cloud-lit environment is younger than frame
/// 14's). `None` where the replay has one of them, or `frames` is not known.
pub fn fallback_frame(frames: Option<Range<usize>>) -> Option<usize> {
    let frames = frames?;
    let last = frames.end.checked_sub(1).filter(|&l| l >= frames.start)?;
    // Any SCORE_EVERY consecutive frames hold one of them.
    let has_scored = (frames.start..=last)
        .take(SCORE_EVERY)
        .any(|f| f % SCORE_EVERY == SCORE_EVERY - 1);
    (!has_scored).then_some(last)
}

/// Which frames get a reference: every [`SCORE_EVERY`]-th (frames 14, 29, ...) whose
/// inputs are there, at most [`MAX_SCORED_FRAMES`], or the [`fallback_frame`]; each on
/// the lattice of `stride` pixels.
pub struct ReferenceSchedule {
    runner: PathRunner,
    stride: u32,
    fallback: Option<usize>,
    /// Every frame of this range instead (`relume eval --score-frames`).
    every: Option<Range<usize>>,
    computed: usize,
    shared: Option<ReferenceCache>,
}

/// References computed on the frames in flight, shared by the evaluators of several
/// pipelines replayed together (`relume compare`): a reference is computed once for
/// all the pipelines whose renderers read the same products (the same allocations,
/// as the shared stages of one run hand them out) with the same settings. The owner
/// clears it once every evaluator has seen the frame, so that an allocation's address
/// is never taken for a later product's.
/// The true frames ([`super::true_frame`]) are shared the same way.
#[derive(Clone, Default)]
pub struct ReferenceCache(
    Arc<std::sync::Mutex<Vec<KeyedReference>>>,
    pub(crate) super::true_frame::TruthCache,
);

/// A reference and what it depends on ([`PathRunner::reference_key`]).
type KeyedReference = (String, Arc<ReferenceLayers>);

impl ReferenceCache {
    /// Forgets every reference and true frame (call after each frame).
    pub fn clear(&self) {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).clear();
        self.1.clear();
    }

    /// How many references it holds.
    pub fn len(&self) -> usize {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl PathRunner {
    /// The settings of reference run `k` (of [`REFERENCE_RUNS`]) on the lattice of
    /// `stride`: [`reference_params`] of the stage's.
    fn reference_params(&self, k: u64, stride: u32) -> PathParams {
        reference_params(&self.params, k, stride)
    }

    /// What a reference of `frame` depends on, as one string: the frame, the stride,
    /// the settings, the addresses of the products and objects it reads, and the
    /// spot lights.
    fn reference_key(&self, frame: &Frame, stride: u32) -> String {
        let mut key = format!(
            "{} {:?} {:?} {:p}",
            frame.index,
            self.reference_params(0, stride),
            self.intrinsics,
            // Moving objects: their own motions, which no other pipeline shares.
            match &self.objects.moving {
                Some(moving) => Arc::as_ptr(moving) as *const (),
                None => Arc::as_ptr(&self.objects.scene) as *const (),
            }
        );
        // The spot lights: pipelines whose objects are one allocation may differ in them.
        key.push_str(&format!(" {:?}", self.objects.lights));
        let names = self
            .inputs
            .iter()
            .chain(&self.environment)
            .chain(&self.voxels);
        for name in names {
            let at = frame.get_shared(name).map(Arc::as_ptr);
            key.push_str(&format!(" {name}={at:?}"));
        }
        key
    }
}

impl ReferenceSchedule {
    /// The schedule for a replay of `frames` (`None`: not known, no fallback).
    pub fn new(runner: PathRunner, stride: u32, frames: Option<Range<usize>>) -> ReferenceSchedule {
        ReferenceSchedule {
            runner,
            stride: stride.max(1),
            fallback: fallback_frame(frames),
            every: None,
            computed: 0,
            shared: None,
        }
    }

    /// The schedule that scores every frame of `frames` (and no other), without the
    /// limit of [`MAX_SCORED_FRAMES`].
    pub fn scoring(self, frames: Range<usize>) -> ReferenceSchedule {
        ReferenceSchedule {
            every: Some(frames),
            fallback: None,
            ..self
        }
    }

    /// Takes references from `cache` when another evaluator computed them, and leaves
    /// those it computes there.
    pub fn share(&mut self, cache: ReferenceCache) {
        self.shared = Some(cache);
    }

    /// The reference layers of `frame` when it is a scored frame and holds the
    /// sampling's inputs, else `None`.
    pub fn reference(&mut self, frame: &Frame) -> Result<Option<Arc<ReferenceLayers>>, String> {
        let wanted = match &self.every {
            Some(frames) => frames.contains(&frame.index),
            None => {
                let scored = frame.index % SCORE_EVERY == SCORE_EVERY - 1;
                self.computed < MAX_SCORED_FRAMES && (scored || self.fallback == Some(frame.index))
            }
        };
        if !wanted {
            return Ok(None);
        }
        let key = self
            .shared
            .as_ref()
            .map(|_| self.runner.reference_key(frame, self.stride));
        if let (Some(cache), Some(key)) = (&self.shared, &key) {
            let held = cache.0.lock().unwrap_or_else(|p| p.into_inner());
            if let Some((_, reference)) = held.iter().find(|(k, _)| k == key) {
                self.computed += 1;
                return Ok(Some(reference.clone()));
            }
        }
        let Some(reference) = ReferenceLayers::compute(&self.runner, frame, self.stride) else {
            return Ok(None);
        };
        self.computed += 1;
        let reference = Arc::new(reference?);
        if let (Some(cache), Some(key)) = (&self.shared, key) {
            let mut held = cache.0.lock().unwrap_or_else(|p| p.into_inner());
            held.push((key, reference.clone()));
        }
        Ok(Some(reference))
    }
}

/// The layers a renderer wrote into a frame that its ratio is scored on.
pub(super) struct OwnLayers<'a> {
    pub e_r_dir: &'a Vec3Image,
    pub e_r_ind: &'a Vec3Image,
    pub e_rv_dir: &'a Vec3Image,
    pub e_rv_ind: &'a Vec3Image,
    pub mask: &'a ScalarImage,
}

impl<'a> OwnLayers<'a> {
    /// The products `names` (e_r_dir, e_r_ind, e_rv_dir, e_rv_ind, mask) of `frame`;
    /// `None` when one is missing.
    pub fn of(frame: &'a Frame, names: &[String; 5]) -> Option<OwnLayers<'a>> {
        let [e_r_dir, e_r_ind, e_rv_dir, e_rv_ind, mask] = names;
        Some(OwnLayers {
            e_r_dir: frame.radiance(e_r_dir).ok()?,
            e_r_ind: frame.radiance(e_r_ind).ok()?,
            e_rv_dir: frame.radiance(e_rv_dir).ok()?,
            e_rv_ind: frame.radiance(e_rv_ind).ok()?,
            mask: frame.scalar(mask).ok()?,
        })
    }
}

/// Scores a `sample.path` stage.
pub struct PathScorer {
    runner: PathRunner,
    /// e_r_dir, e_r_ind, e_rv_dir, e_rv_ind, mask.
    outputs: [String; 5],
    /// The indices of the frames scored (those with a reference).
    scored_frames: Vec<usize>,
    pixels: u64,
    squared: f64,
    alternative_squared: f64,
    z_scores: Vec<f64>,
}

impl PathScorer {
    pub fn new(
        stage: &ResolvedStage,
        objects: ObjectWorld,
        intrinsics: Intrinsics,
        seed: u64,
    ) -> Self {
        PathScorer {
            runner: PathRunner::new(stage, objects, intrinsics, seed),
            outputs: ["e_r_dir", "e_r_ind", "e_rv_dir", "e_rv_ind", "mask"]
                .map(|r| super::ports::output(stage, r)),
            scored_frames: Vec::new(),
            pixels: 0,
            squared: 0.0,
            alternative_squared: 0.0,
            z_scores: Vec::new(),
        }
    }

    /// Scores `frame` when `reference` holds its reference layers and the frame the
    /// stage's outputs.
    pub fn observe(
        &mut self,
        frame: &Frame,
        reference: Option<&ReferenceLayers>,
    ) -> Result<(), String> {
        let Some(reference) = reference.filter(|r| r.frame == frame.index) else {
            return Ok(());
        };
        let Some(OwnLayers {
            e_r_dir,
            e_r_ind,
            e_rv_dir,
            e_rv_ind,
            mask,
        }) = OwnLayers::of(frame, &self.outputs)
        else {
            return Ok(());
        };
        let n = reference.touched.len();
        let sum_of = |a: &Vec3Image, b: &Vec3Image, i: usize| channel_mean(a.data[i] + b.data[i]);
        let ref_r: Vec<f64> = (0..n)
            .map(|i| sum_of(&reference.e_r_dir, &reference.e_r_ind, i))
            .collect();
        let ref_rv: Vec<f64> = (0..n)
            .map(|i| sum_of(&reference.e_rv_dir, &reference.e_rv_ind, i))
            .collect();
        let region: Vec<bool> = (0..n)
            .map(|i| {
                reference.touched[i]
                    && mask.data[i] == 1.0
                    && ref_r[i].is_finite()
                    && ref_r[i] > 1e-6
            })
            .collect();
        let ratio = |r: Vec3, rv: Vec3| channel_mean(rv) / channel_mean(r);
        let params = self.runner.params;
        let run = |params: &PathParams| -> Result<IrradianceLayers, String> {
            self.runner
                .run(frame, params)
                .unwrap_or_else(|| Err("the frame lost its inputs".into()))
        };
        let alternative = run(&PathParams {
            object_aware: !params.object_aware,
            ..params
        })?;
        for i in (0..n).filter(|&i| region[i]) {
            let reference = ref_rv[i] / ref_r[i];
            let own = ratio(
                e_r_dir.data[i] + e_r_ind.data[i],
                e_rv_dir.data[i] + e_rv_ind.data[i],
            );
            let alt = ratio(
                alternative.e_r_dir.data[i] + alternative.e_r_ind.data[i],
                alternative.e_rv_dir.data[i] + alternative.e_rv_ind.data[i],
            );
            if own.is_finite() && alt.is_finite() {
                self.pixels += 1;
                self.squared += (own - reference).powi(2);
                self.alternative_squared += (alt - reference).powi(2);
            }
        }
        // The bias test: region means of E_RV over further runs of the stage's estimator.
        let region_mean = |values: &dyn Fn(usize) -> f64| {
            let (sum, count) = (0..n)
                .filter(|&i| region[i])
                .map(values)
                .filter(|v| v.is_finite())
                .fold((0.0, 0usize), |(s, c), v| (s + v, c + 1));
            sum / count.max(1) as f64
        };
        let reference_mean = region_mean(&|i| ref_rv[i]);
        let mut means = Vec::new();
        for k in 0..BIAS_RUNS {
            let out = run(&PathParams {
                seed: rng::hash(&[params.seed, BIAS_SALT, k]),
                ..params
            })?;
            means.push(region_mean(&|i| {
                channel_mean(out.e_rv_dir.data[i] + out.e_rv_ind.data[i])
            }));
        }
        let m = means.iter().sum::<f64>() / means.len() as f64;
        let var = means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (means.len() - 1) as f64;
        // The reference holds this many times the direct samples of one run (at the
        // pixels with the most primaries, near the objects: the smaller share).
        let run_primary = params.primary.max(params.near_primaries());
        let reference_share = (REFERENCE_RUNS * (REFERENCE_PRIMARY * REFERENCE_SAMPLES) as u64)
            as f64
            / (run_primary * params.direct.max(1)) as f64;
        let se = (var / BIAS_RUNS as f64 + var / reference_share).sqrt();
        if se > 0.0 && region.iter().any(|&r| r) {
            self.z_scores.push((m - reference_mean) / se);
        }
        self.scored_frames.push(frame.index);
        Ok(())
    }

    pub fn report(&self) -> Value {
        let rmse = |sq: f64| (sq / self.pixels.max(1) as f64).sqrt();
        let pooled_z =
            self.z_scores.iter().sum::<f64>() / (self.z_scores.len().max(1) as f64).sqrt();
        json!({
            "frames_scored": self.scored_frames.len(),
            "scored_frames": self.scored_frames,
            "region_pixels": self.pixels,
            "object_aware": self.runner.params.object_aware,
            "ratio_rmse": if self.pixels > 0 { rmse(self.squared) } else { f64::NAN },
            "ratio_rmse_alternative": if self.pixels > 0 { rmse(self.alternative_squared) } else { f64::NAN },
            "unbiased_p": if self.z_scores.is_empty() { f64::NAN } else { two_sided_p(pooled_z) },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::{ObjectVisibility, PathParams, QueryKind, fallback_frame, two_sided_p};

    #[test]
    fn paper_000s_presets_are_scored_against_the_default_reference() {
        let seed = 9;
        let default = PathParams {
            seed,
            ..PathParams::default()
        };
        let preset = PathParams {
            query: QueryKind::Em,
            material_dit: true,
            visibility: false,
            object_visibility: ObjectVisibility::Voxels,
            object_direct: 32,
            object_indirect: 32,
            self_bounce: false,
            object_aware: true,
            iterations: 8,
            object_voxels: 128,
            candidates: 64,
            cache_size: 32,
            ..default
        };
        for (k, stride) in [(0, 1), (3, 4)] {
            assert_eq!(
                super::reference_params(&preset, k, stride),
                super::reference_params(&default, k, stride)
            );
        }
    }

    #[test]
    fn a_replay_without_frames_14_or_29_is_scored_on_its_last() {
        for frames in [0..30, 0..15, 14..15, 20..50, 0..100] {
            assert_eq!(fallback_frame(Some(frames.clone())), None, "{frames:?}");
        }
        assert_eq!(fallback_frame(Some(0..6)), Some(5));
        assert_eq!(fallback_frame(Some(0..14)), Some(13));
        assert_eq!(fallback_frame(Some(15..29)), Some(28));
        assert_eq!(fallback_frame(Some(30..31)), Some(30));
        assert_eq!(fallback_frame(Some(3..3)), None);
        assert_eq!(fallback_frame(None), None);
    }

    #[test]
    fn p_values_of_the_normal_distribution() {
        assert!((two_sided_p(0.0) - 1.0).abs() < 1e-6);
        assert!((two_sided_p(1.959_964) - 0.05).abs() < 1e-6);
        assert!((two_sided_p(-2.575_829) - 0.01).abs() < 1e-6);
        assert!(two_sided_p(8.0) < 1e-14);
    }
}
