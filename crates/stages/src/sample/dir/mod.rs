//! `sample.dir`: Differential Instant Radiosity (paper 002 Sec. 3), the third way to
//! compute the irradiance layers, from virtual point lights (VPLs) instead of Monte
//! Carlo paths (`sample.path`) or area lights (`sample.val`), with the same output
//! roles so that `filter.axis_aligned` and `composite.differential` run on it
//! unchanged.
//!
//! Per frame, in the order of paper 002 Fig. 2:
//! 1. **VPLs of the primary light** (`vpl.rs`): `environment_vpls` importance samples
//!    of the environment from the light table (`light.importance`), a real light
//!    (r(pl) = 1) at infinity. They give the direct layers.
//! 2. **Their imperfect shadow maps** (`ism.rs`): per VPL a real map, splatted from
//!    `points_per_vpl` points of the depth map, and a virtual one from as many points
//!    of the meshes (`points.rs`), each VPL its own subset, holes filled by pull-push
//!    (`fill_levels`). An environment VPL's maps are orthographic discs about the
//!    objects: the virtual one fitted to their bounding sphere, the real one
//!    `max_distance` wider (real geometry within that reach of the objects occludes
//!    the environment; beyond it the environment stands for the room, as with
//!    `sample.path`'s default query).
//! 3. **One bounce** (Sec. 3.7): candidates on the real surface (a grid of pixels, one
//!    per `real_grid` square, carrying the camera's compensated radiance times their
//!    area, split by how much of their direct light the objects block into an ordinary
//!    real VPL and the paper's ir = 1 VPL that cancels real colour bleeding) and on the
//!    meshes (k_V E_RV^dir / pi times their area, r(VPL) = 0), importance-resampled by
//!    power into the `vpls - environment_vpls` remaining slots, `virtual_share` of
//!    them for the meshes (paper 002 shares a light's slots between its real and
//!    virtual RSM by coverage; relume gives the objects a fixed share, since their
//!    VPLs make the bleeding the differential shows while real VPLs mostly cancel). Their maps are
//!    paraboloids over their hemispheres, 128 x 128 by default. With `bounces` > 1
//!    the same candidates are lit again by the last bounce's VPLs and resampled into
//!    the next bounce's share of the slots, their flags carried on (`bounce.rs`).
//! 4. **Interleaved gather** (`interleave.rs`, the terms in `shade.rs`): the image
//!    is split into `interleave` x `interleave` classes by pixel position; class c gathers the VPLs of slots c,
//!    c + k^2, ... (a real VPL and its ir = 1 twin share a slot)
//!    (eqs. 1-8: L_r takes a VPL when its path is real, with the real visibility st_r;
//!    L_rv takes it unless it is ir = 1, with st_rv = min(st_r, st_v); a virtual pixel
//!    gathers L_rv at the object's surface without the ir = 1 VPLs, and L_r at the
//!    real point behind it), times k^2.
//! 5. **Geometry-aware blur** (`blur.rs`) over each k x k window.
//!
//! Where the CPU has AVX2, the gather, the blur and the maps' projections run eight
//! receivers, pixels or points at a time (`gather_lanes.rs`, `blur_lanes.rs`,
//! `splat_lanes.rs`), with the bits of the one-at-a-time code the other CPUs run.
//!
//! **The VPL singularity**: a surface VPL at distance d brings power cos cos / d^2,
//! unbounded as d -> 0; the stage divides by max(d^2, `clamp_distance`^2, A / pi),
//! A the patch of surface the VPL stands for (its candidate's area, grown by the
//! resampling as its power is: a dim candidate drawn once stands for much surface), so
//! one VPL brings at most power / clamp_distance^2. The bias is a loss of light within
//! `clamp_distance` (10 cm), or within the patch's radius when larger, of the VPLs:
//! corners and contact regions of the indirect layers come out darker than the
//! path-traced reference. It is the same in E_R and
//! E_RV, so their ratio, which the composite uses on real pixels, keeps little of it.
//!
//! Where relume departs from paper 002: the environment's VPLs are directions with
//! orthographic maps (the paper's fisheye probe places them on a far hemisphere); a
//! real VPL's light is the camera's observed radiance rather than an albedo times
//! its irradiance (what `sample.path` brings from a real hit too), and from the second
//! bounce on, the albedo the camera and the real solution imply; a surface VPL lights
//! only receivers within `max_distance`; later bounces are placed on the first
//! bounce's candidates, not by the paper's previous-frame VPL buffer; glossy objects are shaded as diffuse (`exponent` stays 0). The random choices
//! (table strata, candidate pixels, map subsets, resampling) are hashed from (seed,
//! frame, index), so the layers are the same at any thread count.

mod blur;
mod blur_lanes;
mod bounce;
mod gather_lanes;
mod interleave;
pub mod ism;
#[cfg(test)]
mod lane_tests;
pub mod points;
mod render;
mod shade;
mod splat_lanes;
#[cfg(test)]
mod tests;
pub mod vpl;

pub use points::MeshPoints;
pub use render::DirRenderer;

use super::layers::{
    IrradianceLayers, LAYER_OUTPUTS, RENDERER_INPUTS, layer_output_ports, renderer_input_ports,
};
use crate::kind::FrameProducts;
use glam::Affine3A;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_graph::{Frame, ParamDefault, ParamSpec, Params, Ports, Stage, StageError, StageInfo};
use relume_recording::Intrinsics;
use relume_scene::light::LightTable;
use relume_scene::objects::VirtualScene;
use std::sync::Arc;

/// Most texels per side of a shadow map.
pub const MAX_SHADOW_MAP_SIZE: u32 = 512;
/// Most VPLs per frame.
pub const MAX_VPLS: u32 = 4096;
/// Most bytes of shadow maps a frame may hold (the defaults take 32 MiB).
pub const MAX_MAP_BYTES: u64 = 1 << 30;

const PARAMS: &[ParamSpec] = &[
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
];

/// The settings [`DirRenderer::render`] runs with (the stage's parameters).
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
            seed,
        }
    }

    /// Refuses settings the renderer cannot run with.
    pub fn check(&self) -> Result<(), StageError> {
        let fail = |m: String| Err(StageError::Failed(format!("sample.dir: {m}")));
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
        let bytes = 2 * self.vpls as u64 * (self.shadow_map_size as u64).pow(2) * 4;
        if bytes > MAX_MAP_BYTES {
            return fail(format!(
                "{} VPLs with two {}x{} maps each need {} MiB of shadow maps; at most {} MiB: lower vpls or shadow_map_size",
                self.vpls,
                self.shadow_map_size,
                self.shadow_map_size,
                bytes >> 20,
                MAX_MAP_BYTES >> 20
            ));
        }
        if self.interleave == 0 || self.real_grid == 0 || self.points_per_vpl == 0 {
            return fail("interleave, real_grid and points_per_vpl must be at least 1".into());
        }
        Ok(())
    }
}

pub const INFO: StageInfo = StageInfo {
    kind: "sample.dir",
    summary: "E_R / E_RV from virtual point lights with real/virtual flags, imperfect shadow maps and interleaved sampling (paper 002 Sec. 3)",
    params: PARAMS,
    ports: |_| Ports {
        inputs: renderer_input_ports().collect(),
        outputs: layer_output_ports(),
    },
    build: |ctx| {
        let params = DirParams::from_params(ctx.params, ctx.seed);
        params.check()?;
        Ok(Box::new(DirStage {
            inputs: RENDERER_INPUTS.map(|(role, _, _)| ctx.input(role)),
            outputs: LAYER_OUTPUTS.map(|(role, _)| ctx.output(role)),
            // The objects do not move: their points are spread once.
            mesh: MeshPoints::new(
                crate::world::objects(ctx),
                params.mesh_points as usize,
                params.seed,
            ),
            params,
            intrinsics: ctx.header.depth_intrinsics,
            objects: Arc::clone(crate::world::objects(ctx)),
            renderer: DirRenderer::default(),
        }))
    },
};

/// What [`DirRenderer::render`] reads for one frame.
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
    /// The frame index (a key of the random choices).
    pub frame: u64,
}

/// [`DirRenderer::render`] with fresh buffers and the objects' points spread for the
/// call (for tests and one-off use).
pub fn sample_dir(inputs: &DirInputs, params: &DirParams) -> Result<IrradianceLayers, StageError> {
    let mesh = MeshPoints::new(inputs.objects, params.mesh_points as usize, params.seed);
    let mut out = IrradianceLayers::new(inputs.depth.width, inputs.depth.height);
    DirRenderer::default().render(inputs, params, &mesh, &mut out)?;
    Ok(out)
}

struct DirStage {
    inputs: [String; 5],
    outputs: [String; 12],
    mesh: MeshPoints,
    params: DirParams,
    intrinsics: Intrinsics,
    objects: Arc<VirtualScene>,
    renderer: DirRenderer,
}

impl Stage for DirStage {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let [depth, normals, pose, radiance, table] = &self.inputs;
        let depth = frame.depth(depth)?;
        let inputs = DirInputs {
            depth,
            normals: frame.normals(normals)?,
            radiance: frame.radiance(radiance)?,
            camera: Pinhole::new(&self.intrinsics, depth.width, depth.height),
            camera_to_world: Affine3A::from_mat4(frame.pose(pose)?.matrix().as_mat4()),
            table: frame.light_table(table)?,
            objects: &self.objects,
            frame: frame.index as u64,
        };
        let mut out = IrradianceLayers::new(depth.width, depth.height);
        self.renderer
            .render(&inputs, &self.params, &self.mesh, &mut out)?;
        out.insert_into(frame, &self.outputs);
        Ok(())
    }
}
