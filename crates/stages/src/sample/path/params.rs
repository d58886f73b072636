//! The parameters of `sample.path`: their declarations (ranges and docs, checked when
//! a pipeline loads) and [`PathParams`], the settings the estimator runs with.

use crate::OpError;
use crate::sample::query::{MAX_ITERATIONS, QueryKind};
use crate::sample::ssrt::TraceParams;
use relume_graph::{ParamDefault, ParamSpec, Params};
use relume_scene::light::voxels::VoxelVolume;
use relume_scene::objects::VirtualScene;
use relume_scene::objects::voxelize::solid_volume;

/// Most primary, direct or indirect samples per pixel the stage accepts.
pub const MAX_SAMPLES: u32 = 64;
/// The most object-aware candidates per pixel (size of the H_a index cache).
pub const MAX_CANDIDATES: usize = 256;
/// Most voxels along a side of the objects' solid volume (`vct`).
pub const MAX_OBJECT_VOXELS: u32 = 256;

pub(super) const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "query",
        ParamDefault::Str("ssrt"),
        "how rays meet the real scene (paper 000 Sec. 6): ssrt = screen-space march over the depth map within max_distance, the environment map beyond; em = Environment Mapping, a direction lookup into the distance impostor; dit = Distance Impostor Tracing, the lookup refined from the impostor's distances; vct = Voxel Cone Tracing, cones through the scene's voxel volume, and the objects' shadows from cones through their solid volume. em and dit read the `environment` product (light.impostor's map), vct the `voxels` product (light.voxels)",
    )
    .choices(QueryKind::NAMES),
    ParamSpec::new(
        "iterations",
        ParamDefault::Int(6),
        "dit: refinement steps of the impostor lookup (0 gives em's answer)",
    )
    .range(0.0, MAX_ITERATIONS as f64),
    ParamSpec::new(
        "object_voxels",
        ParamDefault::Int(32),
        "vct: voxels along the longest side of the objects' solid volume, whose cones give their shadows and self-shadows (paper 000 Table 2: 32 for low and medium, 128 for high)",
    )
    .range(1.0, MAX_OBJECT_VOXELS as f64),
    ParamSpec::new(
        "visibility",
        ParamDefault::Bool(true),
        "test the virtual objects' rays against the objects themselves (self-shadowing and self-reflection; paper 000 Table 3's visibility test). Off: cheaper, objects lit as if nothing of them were in the way",
    ),
    ParamSpec::new(
        "primary",
        ParamDefault::Int(4),
        "primary samples (jittered view rays) per pixel: decide the mask and the shading point (paper 001: 4)",
    )
    .range(1.0, MAX_SAMPLES as f64),
    ParamSpec::new(
        "direct",
        ParamDefault::Int(4),
        "direct-light samples per primary sample (paper 001: 4, 16 per pixel)",
    )
    .range(0.0, MAX_SAMPLES as f64),
    ParamSpec::new(
        "indirect",
        ParamDefault::Int(4),
        "indirect (one-bounce) samples per primary sample (paper 001: 4, 16 per pixel)",
    )
    .range(0.0, MAX_SAMPLES as f64),
    ParamSpec::new(
        "object_aware",
        ParamDefault::Bool(false),
        "estimate E_RV^ind at real points as E_R^ind plus an object-aware differential (paper 000 Sec. 7)",
    ),
    ParamSpec::new(
        "object_aware_direct",
        ParamDefault::Bool(false),
        "estimate E_RV^dir at real points as E_R^dir minus the light of `candidates` table samples of which at most `cache_size` meeting the objects' box are traced (paper 000 Sec. 7's estimator after eq. 9, for direct light)",
    ),
    ParamSpec::new(
        "cache_size",
        ParamDefault::Int(16),
        "object-aware (indirect and direct): most candidates traced per pixel, |H_a| (paper 000: 8, 16 or 32)",
    )
    .range(1.0, MAX_CANDIDATES as f64),
    ParamSpec::new(
        "candidates",
        ParamDefault::Int(64),
        "object-aware: candidates (cosine directions; table samples for direct light) tested against the objects' bounding box per pixel, N",
    )
    .range(1.0, MAX_CANDIDATES as f64),
    ParamSpec::new(
        "near_primary",
        ParamDefault::Int(0),
        "primary samples (each with its direct and indirect samples) of the pixels where the differential is: those whose primaries may meet an object and those whose real point lies within near_distance of the objects' bounding box (their shadows and colour bleeding). 0: primary, as everywhere",
    )
    .range(0.0, MAX_SAMPLES as f64),
    ParamSpec::new(
        "near_distance",
        ParamDefault::Float(0.3),
        "metres from the objects' bounding box within which a real point takes near_primary samples",
    )
    .range(0.0, 1000.0),
    ParamSpec::new(
        "max_distance",
        ParamDefault::Float(1.0),
        "metres a screen-space ray marches: real geometry beyond it neither occludes nor reflects (the environment map stands for it)",
    )
    .range(0.01, 1000.0),
    ParamSpec::new(
        "normal_offset",
        ParamDefault::Float(1.0),
        "real ray origins are raised off the surface along its normal by this many pixel footprints (depth / focal length), so grazing rays do not hit their own surface between pixel centres",
    )
    .range(0.0, 16.0),
    ParamSpec::new(
        "occluder_threshold",
        ParamDefault::Float(0.1),
        "direct_min_distance counts only occluders of samples at least this bright, as a fraction of the table's brightest sample (paper 001 Sec. 7 ignores occluders of samples below an absolute 0.1; a fraction is the same for any exposure): dim light blocked nearby does not narrow the filter",
    )
    .range(0.0, 1.0),
    ParamSpec::new(
        "thickness",
        ParamDefault::Float(0.1),
        "metres behind the depth map that still count as inside a real surface",
    )
    .range(0.001, 10.0),
    ParamSpec::new(
        "skip_pixels",
        ParamDefault::Float(1.5),
        "pixels skipped at the start of a screen-space march, against self-intersection",
    )
    .range(0.0, 64.0),
];

/// The `query` parameter of checked parameters `p`.
pub(super) fn query_kind(p: &Params) -> QueryKind {
    QueryKind::from_name(p.str("query")).unwrap_or_default()
}

/// Settings of [`sample_path`](super::sample_path).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathParams {
    /// How rays meet the real scene.
    pub query: QueryKind,
    /// `dit`: refinement steps of the impostor lookup.
    pub iterations: u32,
    /// `vct`: voxels along the longest side of the objects' solid volume.
    pub object_voxels: u32,
    /// Whether the objects' own rays are tested against the objects (self-occlusion).
    pub visibility: bool,
    /// Primary samples per pixel.
    pub primary: u32,
    /// Direct samples per primary sample.
    pub direct: u32,
    /// Indirect samples per primary sample.
    pub indirect: u32,
    /// Primary samples of the pixels near the objects (0: `primary`).
    pub near_primary: u32,
    /// Metres from the objects' bounding box within which a real point is near.
    pub near_distance: f32,
    pub seed: u64,
    /// Object-aware differential for E_RV^ind at real points (paper 000 Sec. 7).
    pub object_aware: bool,
    /// Object-aware differential for E_RV^dir at real points (paper 000 Sec. 7's
    /// scaled estimator, after eq. 9, for direct light).
    pub object_aware_direct: bool,
    /// Object-aware: most directions traced per pixel (|H_a|).
    pub cache_size: u32,
    /// Object-aware: directions tested against the bounding box per pixel (N).
    pub candidates: u32,
    pub trace: TraceParams,
    /// Metres a screen-space ray marches.
    pub max_distance: f32,
    /// Pixel footprints (depth / focal length) by which real ray origins are raised
    /// along the normal.
    pub normal_offset: f32,
    /// Blocked direct samples whose radiance is below this fraction of the table's
    /// brightest do not set `direct_min_distance`.
    pub occluder_threshold: f32,
    /// Shade only the pixels whose x and y are multiples of this (1: every pixel); the
    /// others keep [`IrradianceLayers::new`](crate::sample::layers::IrradianceLayers::new)'s values (NaN irradiance). A shaded pixel gets
    /// the bits a full run gives it (random numbers are hashed per pixel): `relume eval`
    /// computes its many-sample references on such a lattice. Not a stage parameter.
    pub pixel_stride: u32,
}

impl Default for PathParams {
    fn default() -> Self {
        PathParams {
            query: QueryKind::Ssrt,
            iterations: 6,
            object_voxels: 32,
            visibility: true,
            primary: 4,
            direct: 4,
            indirect: 4,
            near_primary: 0,
            near_distance: 0.3,
            seed: 0,
            object_aware: false,
            object_aware_direct: false,
            cache_size: 16,
            candidates: 64,
            trace: TraceParams::default(),
            max_distance: 1.0,
            normal_offset: 1.0,
            occluder_threshold: 0.1,
            pixel_stride: 1,
        }
    }
}

impl PathParams {
    /// The settings of a `sample.path` stage with (checked) parameters `p`, run with
    /// `seed` (`relume eval` re-runs the stage's math with them).
    pub fn from_params(p: &Params, seed: u64) -> PathParams {
        PathParams {
            query: query_kind(p),
            iterations: p.int("iterations") as u32,
            object_voxels: p.int("object_voxels") as u32,
            visibility: p.bool("visibility"),
            primary: p.int("primary") as u32,
            direct: p.int("direct") as u32,
            indirect: p.int("indirect") as u32,
            near_primary: p.int("near_primary") as u32,
            near_distance: p.float("near_distance") as f32,
            seed,
            object_aware: p.bool("object_aware"),
            object_aware_direct: p.bool("object_aware_direct"),
            cache_size: p.int("cache_size") as u32,
            candidates: p.int("candidates") as u32,
            trace: TraceParams {
                thickness: p.float("thickness") as f32,
                skip_pixels: p.float("skip_pixels") as f32,
            },
            max_distance: p.float("max_distance") as f32,
            normal_offset: p.float("normal_offset") as f32,
            occluder_threshold: p.float("occluder_threshold") as f32,
            pixel_stride: 1,
        }
    }

    /// The primary samples of a pixel near the objects.
    pub fn near_primaries(&self) -> u32 {
        if self.near_primary == 0 {
            self.primary
        } else {
            self.near_primary
        }
    }

    /// The objects' solid volume the `vct` query marches for their shadows
    /// (`object_voxels` a side); `None` for the other queries. Objects do not move:
    /// callers build it once and pass it as [`PathInputs::object_voxels`](super::PathInputs::object_voxels).
    pub fn object_volume(&self, objects: &VirtualScene) -> Option<VoxelVolume> {
        self.query
            .needs_voxels()
            .then(|| solid_volume(objects, self.object_voxels))
    }

    /// Checks the counts and distances; the error names the bad value.
    pub fn check(&self) -> Result<(), OpError> {
        let bad = |what: &str, value: String| {
            Err(OpError::BadParameter(format!(
                "sample.path: {what} is {value}"
            )))
        };
        if !(1..=MAX_SAMPLES).contains(&self.primary) {
            return bad(
                "primary",
                format!("{}, expected 1..={MAX_SAMPLES}", self.primary),
            );
        }
        if self.near_primary > MAX_SAMPLES {
            return bad(
                "near_primary",
                format!("{}, expected 0..={MAX_SAMPLES}", self.near_primary),
            );
        }
        if self.near_distance.is_nan() || self.near_distance < 0.0 {
            return bad(
                "near_distance",
                format!("{}, expected 0 or more metres", self.near_distance),
            );
        }
        if self.direct > MAX_SAMPLES || self.indirect > MAX_SAMPLES {
            return bad(
                "direct or indirect",
                format!(
                    "{} / {}, expected 0..={MAX_SAMPLES}",
                    self.direct, self.indirect
                ),
            );
        }
        if self.iterations > MAX_ITERATIONS {
            return bad(
                "iterations",
                format!("{}, expected 0..={MAX_ITERATIONS}", self.iterations),
            );
        }
        if !(1..=MAX_OBJECT_VOXELS).contains(&self.object_voxels) {
            return bad(
                "object_voxels",
                format!("{}, expected 1..={MAX_OBJECT_VOXELS}", self.object_voxels),
            );
        }
        if self.pixel_stride == 0 {
            return bad("pixel_stride", "0, expected 1 or more".into());
        }
        let max = MAX_CANDIDATES as u32;
        if !(1..=max).contains(&self.candidates) || !(1..=max).contains(&self.cache_size) {
            return bad(
                "candidates or cache_size",
                format!(
                    "{} / {}, expected 1..={max}",
                    self.candidates, self.cache_size
                ),
            );
        }
        let distances_valid = self.max_distance > 0.0
            && self.trace.thickness >= 0.0
            && self.normal_offset >= 0.0
            && self.normal_offset.is_finite();
        if !distances_valid {
            return bad(
                "max_distance, thickness or normal_offset",
                format!(
                    "{} / {} / {}",
                    self.max_distance, self.trace.thickness, self.normal_offset
                ),
            );
        }
        Ok(())
    }
}
