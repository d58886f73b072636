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
        "material_query",
        ParamDefault::Str("same"),
        "the query of the real points' rays (the material estimation's E_R and the differential's E_RV at real pixels): same = the stage's query; dit = the impostor traced with `iterations` steps while the objects' own rays keep em's lookup (paper 000 Sec. 7: \"for the material estimation DIT is also used in EM cases\"; its \"low\"). dit needs query em or dit",
    )
    .choices(&["same", "dit"]),
    ParamSpec::new(
        "object_visibility",
        ParamDefault::Str("auto"),
        "how direct-light shadow rays are tested against the objects (their shadows on the room and on themselves): mesh = the triangles' BVH, exact and hard-edged; voxels = cones through the objects' solid volume (object_voxels a side), soft and partial, as paper 000 Sec. 6.2 does for every technique; auto = voxels for vct, mesh otherwise. Indirect rays meet the objects' mesh either way, and so do object_aware_direct's candidates",
    )
    .choices(ObjectVisibility::NAMES),
    ParamSpec::new(
        "object_voxels",
        ParamDefault::Int(32),
        "object_visibility = voxels (vct's auto): voxels along the longest side of the objects' solid volume (paper 000 Table 2: 32 for low and medium, 128 for high)",
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
        "object_direct",
        ParamDefault::Int(0),
        "direct-light samples per primary sample that meets an object (0: direct). Paper 000's \"high\" renders the object with 128 samples where the room gets 64",
    )
    .range(0.0, MAX_SAMPLES as f64),
    ParamSpec::new(
        "object_indirect",
        ParamDefault::Int(0),
        "indirect samples per primary sample that meets an object (0: indirect)",
    )
    .range(0.0, MAX_SAMPLES as f64),
    ParamSpec::new(
        "self_bounce",
        ParamDefault::Bool(true),
        "with visibility: an object's indirect ray that meets the objects again brings the light reflected there (one light-table sample: paper 000's secondary bounce, its \"high\"); off, it brings nothing (a visibility test only, its \"medium\")",
    ),
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

/// How shadow rays meet the virtual objects (the `object_visibility` parameter).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ObjectVisibility {
    /// Voxels for `vct` (its cones march volumes throughout), the mesh otherwise.
    #[default]
    Auto,
    /// The triangles' BVH: a ray is blocked or not.
    Mesh,
    /// Cones through the objects' solid volume (paper 000 Sec. 6.2): the light that
    /// passes is 1 - opacity (eq. 6).
    Voxels,
}

impl ObjectVisibility {
    /// The parameter's choices.
    pub const NAMES: &'static [&'static str] = &["auto", "mesh", "voxels"];

    /// `name`, one of [`Self::NAMES`] (anything else is `auto`).
    pub fn from_name(name: &str) -> ObjectVisibility {
        match name {
            "mesh" => ObjectVisibility::Mesh,
            "voxels" => ObjectVisibility::Voxels,
            _ => ObjectVisibility::Auto,
        }
    }
}

/// Settings of [`sample_path`](super::sample_path).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathParams {
    /// How rays meet the real scene.
    pub query: QueryKind,
    /// `dit`: refinement steps of the impostor lookup.
    pub iterations: u32,
    /// Whether the real points' rays trace the impostor (`dit`, with `iterations`
    /// steps) whatever `query` is (`em` or `dit`).
    pub material_dit: bool,
    /// How shadow rays meet the objects.
    pub object_visibility: ObjectVisibility,
    /// [`ObjectVisibility::Voxels`]: voxels along the longest side of the objects'
    /// solid volume.
    pub object_voxels: u32,
    /// Whether the objects' own rays are tested against the objects (self-occlusion).
    pub visibility: bool,
    /// Primary samples per pixel.
    pub primary: u32,
    /// Direct samples per primary sample.
    pub direct: u32,
    /// Indirect samples per primary sample.
    pub indirect: u32,
    /// Direct samples per primary sample that meets an object (0: `direct`).
    pub object_direct: u32,
    /// Indirect samples per primary sample that meets an object (0: `indirect`).
    pub object_indirect: u32,
    /// Whether an object's indirect ray that meets the objects again brings the light
    /// reflected there (else nothing).
    pub self_bounce: bool,
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
            material_dit: false,
            object_visibility: ObjectVisibility::Auto,
            object_voxels: 32,
            visibility: true,
            primary: 4,
            direct: 4,
            indirect: 4,
            object_direct: 0,
            object_indirect: 0,
            self_bounce: true,
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
            material_dit: p.str("material_query") == "dit",
            object_visibility: ObjectVisibility::from_name(p.str("object_visibility")),
            object_voxels: p.int("object_voxels") as u32,
            visibility: p.bool("visibility"),
            primary: p.int("primary") as u32,
            direct: p.int("direct") as u32,
            indirect: p.int("indirect") as u32,
            object_direct: p.int("object_direct") as u32,
            object_indirect: p.int("object_indirect") as u32,
            self_bounce: p.bool("self_bounce"),
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

    /// Direct samples per primary sample that meets an object.
    pub fn object_directs(&self) -> u32 {
        match self.object_direct {
            0 => self.direct,
            n => n,
        }
    }

    /// Indirect samples per primary sample that meets an object.
    pub fn object_indirects(&self) -> u32 {
        match self.object_indirect {
            0 => self.indirect,
            n => n,
        }
    }

    /// Whether shadow rays meet the objects as cones through their solid volume
    /// (`object_visibility`, with `auto` resolved by the query).
    pub fn object_visibility_by_voxels(&self) -> bool {
        match self.object_visibility {
            ObjectVisibility::Auto => self.query.needs_voxels(),
            ObjectVisibility::Mesh => false,
            ObjectVisibility::Voxels => true,
        }
    }

    /// The objects' solid volume whose cones give their shadows (`object_voxels` a
    /// side) when [`Self::object_visibility_by_voxels`]; `None` for the mesh. Callers
    /// build it once (again when the objects move) and pass it as
    /// [`PathInputs::object_voxels`](super::PathInputs::object_voxels).
    pub fn object_volume(&self, objects: &VirtualScene) -> Option<VoxelVolume> {
        self.object_visibility_by_voxels()
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
        let counts = [
            self.direct,
            self.indirect,
            self.object_direct,
            self.object_indirect,
        ];
        if counts.iter().any(|&n| n > MAX_SAMPLES) {
            return bad(
                "direct, indirect, object_direct or object_indirect",
                format!(
                    "{} / {} / {} / {}, expected 0..={MAX_SAMPLES}",
                    self.direct, self.indirect, self.object_direct, self.object_indirect
                ),
            );
        }
        // An object's own counts weigh in its pixel's mean as the room's count does
        // (`primary_share`): there is nothing to weigh them against when the room has none.
        let unweighable = |room: u32, object: u32| room == 0 && object > 0;
        if unweighable(self.direct, self.object_direct)
            || unweighable(self.indirect, self.object_indirect)
        {
            return bad(
                "object_direct or object_indirect",
                format!(
                    "{} / {} with direct / indirect {} / {}, expected 0 where the room's count is 0",
                    self.object_direct, self.object_indirect, self.direct, self.indirect
                ),
            );
        }
        if self.iterations > MAX_ITERATIONS {
            return bad(
                "iterations",
                format!("{}, expected 0..={MAX_ITERATIONS}", self.iterations),
            );
        }
        if self.material_dit && !self.query.needs_environment() {
            return bad(
                "material_query",
                format!(
                    "\"dit\" with query \"{}\", expected query \"em\" or \"dit\" (the impostor it traces)",
                    self.query.name()
                ),
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
