//! What a Differential Instant Radiosity frame is asked to do: the stage's parameters
//! ([`PARAMS`], [`DirParams`]) and the frame's inputs ([`DirInputs`]), shared by the
//! stage, the renderer and its passes.

use crate::OpError;
use glam::Affine3A;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_graph::{ParamDefault, ParamSpec, Params};
use relume_scene::light::{LightTable, SpotLight};
use relume_scene::objects::VirtualScene;

/// Most texels per side of a shadow map.
pub const MAX_SHADOW_MAP_SIZE: u32 = 512;
/// Most VPLs per frame.
pub const MAX_VPLS: u32 = 4096;
/// Most bytes of shadow maps a frame may hold (the defaults take 32 MiB).
pub const MAX_MAP_BYTES: u64 = 1 << 30;

pub(super) const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "vpls",
        ParamDefault::Int(256),
        "virtual point lights per frame, environment and bounce together (paper 002 Sec. 6: 256)",
    )
    .range(1.0, MAX_VPLS as f64),
    ParamSpec::new(
        "environment_vpls",
        ParamDefault::Int(64),
        "of them, importance samples of the environment (the direct light); the rest are one-bounce VPLs on real and virtual surfaces",
    )
    .range(0.0, MAX_VPLS as f64),
    ParamSpec::new(
        "bounces",
        ParamDefault::Int(1),
        "light bounces carried by VPLs (paper 002 Sec. 3.6): 1 = the environment's light reflected once; each further bounce takes an even share of the bounce VPLs, placed where the last bounce's light lands, with the paths' real/virtual flags carried on",
    )
    .range(1.0, 4.0),
    ParamSpec::new(
        "virtual_share",
        ParamDefault::Float(0.25),
        "share of the bounce VPLs placed on the virtual objects (the rest on the real surface); each group is importance-resampled by power within itself. The objects' VPLs make the colour bleeding that the differential shows, the real ones mostly cancel in it",
    )
    .range(0.0, 1.0),
    ParamSpec::new(
        "points_per_vpl",
        ParamDefault::Int(1024),
        "points splatted into each of a VPL's two imperfect shadow maps, real and virtual (paper 002 Sec. 6: 1024)",
    )
    .range(1.0, 1e6),
    ParamSpec::new(
        "shadow_map_size",
        ParamDefault::Int(128),
        "texels per side of each imperfect shadow map (paper 002 Sec. 6: 128)",
    )
    .range(4.0, MAX_SHADOW_MAP_SIZE as f64),
    ParamSpec::new(
        "fill_levels",
        ParamDefault::Int(2),
        "pull-push levels of hole filling: holes up to 2^levels texels wide are closed",
    )
    .range(0.0, 8.0),
    ParamSpec::new(
        "interleave",
        ParamDefault::Int(4),
        "side of the interleaving tile: each pixel gathers 1 / side^2 of the VPLs and a geometry-aware side x side blur reassembles them (paper 002 Sec. 6: 4); 1 = every pixel gathers every VPL",
    )
    .range(1.0, 8.0),
    ParamSpec::new(
        "max_distance",
        ParamDefault::Float(1.0),
        "metres: how far a surface VPL lights, and how far around the objects real geometry blocks the environment's light",
    )
    .range(0.01, 100.0),
    ParamSpec::new(
        "clamp_distance",
        ParamDefault::Float(0.1),
        "metres: a surface VPL's 1 / d^2 is clamped below this distance (each VPL brings at most power / clamp^2; the light lost within it darkens contacts and corners)",
    )
    .range(0.0, 10.0),
    ParamSpec::new(
        "bias",
        ParamDefault::Float(0.02),
        "metres a receiver must lie behind a shadow map's depth to be shadowed",
    )
    .range(0.0, 10.0),
    ParamSpec::new(
        "slope_bias",
        ParamDefault::Float(6.0),
        "extra shadow bias in texel sizes times the tangent of the incidence angle (a splat is flat over up to 4 texels, and the hole filling averages)",
    )
    .range(0.0, 100.0),
    ParamSpec::new(
        "real_grid",
        ParamDefault::Int(8),
        "pixels per side of the grid cells that each give one real bounce candidate",
    )
    .range(1.0, 256.0),
    ParamSpec::new(
        "mesh_points",
        ParamDefault::Int(16384),
        "points spread over the virtual meshes once (the maps and the virtual candidates take subsets)",
    )
    .range(1.0, 1e7),
    ParamSpec::new(
        "flags",
        ParamDefault::Str("reciprocal"),
        "how light paths are sorted into L_r and L_rv (paper 002 Sec. 3.3): reciprocal = the paper's two shadow maps per light (a real and a virtual blocker behind each other both count) and its ir = 1 VPLs that cancel the real colour bleeding the objects take away; knecht2010 = the earlier method [4] it compares against: one map per light whose nearest blocker alone counts (double shadows where a virtual object stands in front of a real shadow) and no ir = 1 VPLs (inconsistent colour bleeding)",
    )
    .choices(Flags::NAMES),
    ParamSpec::new(
        "spot_vpls",
        ParamDefault::Int(32),
        "bounce VPLs of the virtual [[light]] spots' light on the real surface (in L_rv only), on top of vpls: the colour bleeding of a virtual lamp",
    )
    .range(0.0, MAX_VPLS as f64),
    ParamSpec::new(
        "spot_split",
        ParamDefault::Str("flux"),
        "how the spot_vpls slots are shared between the real surfaces and the objects the virtual spots light: flux = in proportion to the light each reflects (one resampling over both); coverage = paper 002 Sec. 3.7's split, by the solid angle each kind covers as the spots see it (its two RSMs' pixel counts), slot by slot with a Halton sequence, then by light within each",
    )
    .choices(&["flux", "coverage"]),
    ParamSpec::new(
        "spot_map_size",
        ParamDefault::Int(512),
        "texels per side of each [[light]] spot light's shadow map of the real surface (every pixel of the depth map), a paraboloid over the hemisphere about its axis; the objects' shadows of a spot are traced",
    )
    .range(16.0, MAX_SPOT_MAP_SIZE as f64),
];

/// Most texels per side of a spot light's shadow map.
pub const MAX_SPOT_MAP_SIZE: u32 = 1024;

/// How light paths are sorted into L_r and L_rv (the `flags` parameter).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Flags {
    /// Paper 002's: two shadow maps per light, ir = 1 VPLs.
    #[default]
    Reciprocal,
    /// Knecht et al. 2010 (\[4\] of paper 002): one map per light, the nearest blocker
    /// decides; no ir = 1 VPLs.
    Knecht2010,
}

impl Flags {
    /// The parameter's choices.
    pub const NAMES: &'static [&'static str] = &["reciprocal", "knecht2010"];

    /// `name`, one of [`Self::NAMES`] (anything else is `reciprocal`).
    pub fn from_name(name: &str) -> Flags {
        match name {
            "knecht2010" => Flags::Knecht2010,
            _ => Flags::Reciprocal,
        }
    }
}

/// The settings [`DirRenderer::render`](super::DirRenderer::render) runs with (the stage's parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirParams {
    pub vpls: u32,
    pub environment_vpls: usize,
    pub bounces: u32,
    pub virtual_share: f32,
    pub points_per_vpl: u32,
    pub shadow_map_size: u32,
    pub fill_levels: u32,
    pub interleave: u32,
    pub max_distance: f32,
    pub clamp_distance: f32,
    pub bias: f32,
    pub slope_bias: f32,
    pub real_grid: u32,
    pub mesh_points: u32,
    pub flags: Flags,
    pub spot_vpls: u32,
    /// The `spot_split` parameter is `coverage` (paper 002 Sec. 3.7's Halton split).
    pub spot_coverage_split: bool,
    pub spot_map_size: u32,
    pub seed: u64,
}

impl Default for DirParams {
    fn default() -> Self {
        DirParams::from_params(&Params::defaults(PARAMS), 0)
    }
}

impl DirParams {
    /// The settings of a stage's `params` with the pipeline's `seed`.
    pub fn from_params(p: &Params, seed: u64) -> DirParams {
        DirParams {
            vpls: p.int("vpls") as u32,
            environment_vpls: p.int("environment_vpls") as usize,
            bounces: p.int("bounces") as u32,
            virtual_share: p.float("virtual_share") as f32,
            points_per_vpl: p.int("points_per_vpl") as u32,
            shadow_map_size: p.int("shadow_map_size") as u32,
            fill_levels: p.int("fill_levels") as u32,
            interleave: p.int("interleave") as u32,
            max_distance: p.float("max_distance") as f32,
            clamp_distance: p.float("clamp_distance") as f32,
            bias: p.float("bias") as f32,
            slope_bias: p.float("slope_bias") as f32,
            real_grid: p.int("real_grid") as u32,
            mesh_points: p.int("mesh_points") as u32,
            flags: Flags::from_name(p.str("flags")),
            spot_vpls: p.int("spot_vpls") as u32,
            spot_coverage_split: p.str("spot_split") == "coverage",
            spot_map_size: p.int("spot_map_size") as u32,
            seed,
        }
    }

    /// Refuses settings the renderer cannot run with.
    pub fn check(&self) -> Result<(), OpError> {
        let fail = |m: String| Err(OpError::BadParameter(format!("sample.dir: {m}")));
        if self.environment_vpls > self.vpls as usize {
            return fail(format!(
                "environment_vpls ({}) is more than vpls ({})",
                self.environment_vpls, self.vpls
            ));
        }
        if !(4..=MAX_SHADOW_MAP_SIZE).contains(&self.shadow_map_size) {
            return fail(format!(
                "shadow_map_size must be 4 to {MAX_SHADOW_MAP_SIZE}, not {}",
                self.shadow_map_size
            ));
        }
        let slots = self.vpls as u64 + self.spot_vpls as u64;
        let bytes = 2 * slots * (self.shadow_map_size as u64).pow(2) * 4;
        if bytes > MAX_MAP_BYTES {
            return fail(format!(
                "{} + {} VPLs (vpls + spot_vpls) with two {}x{} maps each need {} MiB of shadow maps; at most {} MiB: lower vpls, spot_vpls or shadow_map_size",
                self.vpls,
                self.spot_vpls,
                self.shadow_map_size,
                self.shadow_map_size,
                bytes >> 20,
                MAX_MAP_BYTES >> 20
            ));
        }
        if !(16..=MAX_SPOT_MAP_SIZE).contains(&self.spot_map_size) {
            return fail(format!(
                "spot_map_size must be 16 to {MAX_SPOT_MAP_SIZE}, not {}",
                self.spot_map_size
            ));
        }
        if self.interleave == 0 || self.real_grid == 0 || self.points_per_vpl == 0 {
            return fail("interleave, real_grid and points_per_vpl must be at least 1".into());
        }
        Ok(())
    }
}

/// What [`DirRenderer::render`](super::DirRenderer::render) reads for one frame.
#[derive(Clone, Copy)]
pub struct DirInputs<'a> {
    /// Depth in metres (0 or non-finite = missing): the real geometry.
    pub depth: &'a DepthImage,
    /// Camera-space unit normals facing the camera, zero = invalid.
    pub normals: &'a Vec3Image,
    /// Compensated linear camera radiance: the light real VPLs send on.
    pub radiance: &'a Vec3Image,
    /// The depth camera, at the depth map's size.
    pub camera: Pinhole,
    pub camera_to_world: Affine3A,
    /// Importance samples of the environment, in stratified order.
    pub table: &'a LightTable,
    pub objects: &'a VirtualScene,
    /// The pipeline's spot lights (`[[light]]`), real and virtual.
    pub spots: &'a [SpotLight],
    /// The frame index (a key of the random choices).
    pub frame: u64,
}
