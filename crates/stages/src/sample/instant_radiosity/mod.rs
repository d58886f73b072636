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
//!    the next bounce's share of the slots, their flags carried on (`render.rs`, its Bounces).
//! 4. **Interleaved gather** (`interleave.rs`, the terms in `shade.rs`): the image
//!    is split into `interleave` x `interleave` classes by pixel position; class c gathers the VPLs of slots c,
//!    c + k^2, ... (a real VPL and its ir = 1 twin share a slot)
//!    (eqs. 1-8: L_r takes a VPL when its path is real, with the real visibility st_r;
//!    L_rv takes it unless it is ir = 1, with st_rv = min(st_r, st_v); a virtual pixel
//!    gathers L_rv at the object's surface without the ir = 1 VPLs, and L_r at the
//!    real point behind it), times k^2.
//! 5. **Geometry-aware blur** (`blur.rs`) over each k x k window.
//! 6. **Spot lights** (`spots.rs`, the pipeline's `[[light]]` tables, Secs. 3.3-3.7):
//!    each real or virtual spot gets a shadow map of the real surface (every real
//!    pixel) and traces the objects' shadows, its direct light is gathered at every pixel after the blur (a real spot
//!    in L_r and L_rv, a virtual one in L_rv only), it joins the first bounce's
//!    candidates' direct light, and the virtual spots' light on the real surface
//!    takes `spot_vpls` bounce VPLs of its own. `flags = "knecht2010"` switches to the
//!    earlier method \[4\] for the comparison (one map per light, no ir = 1 VPLs).
//!
//! Where the CPU has AVX2, the gather, the blur and the maps' projections run eight
//! receivers, pixels or points at a time (`gather_lanes.rs`, `blur_lanes.rs`,
//! `splat.rs`), with the bits of the one-at-a-time code the other CPUs run.
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
mod blur_pass;
mod gather_lanes;
mod interleave;
pub mod ism;
#[cfg(test)]
mod lane_tests;
mod params;
pub mod points;
mod render;
mod shade;
pub mod splat;
#[cfg(test)]
pub(crate) mod spot_tests;
pub mod spots;
#[cfg(test)]
mod tests;
pub mod vpl;

use params::PARAMS;
pub use params::{
    DirInputs, DirParams, Flags, MAX_MAP_BYTES, MAX_SHADOW_MAP_SIZE, MAX_SPOT_MAP_SIZE, MAX_VPLS,
};
pub use points::MeshPoints;
pub use render::DirRenderer;

use super::layers::{IrradianceLayers, renderer_input_ports};
use super::renderer::{self, RenderFrame, Renderer};
use crate::OpError;
use crate::world::follow::FollowedObjects;
use relume_graph::{BuildContext, ParamSpec, Params, Port, StageError, StageInfo};
use relume_scene::light::{LightWorld, SpotLight};

pub const INFO: StageInfo = renderer::info::<SampleDir>();

/// [`DirRenderer::render`] with fresh buffers and the objects' points spread for the
/// call (for tests and one-off use).
pub fn sample_dir(inputs: &DirInputs, params: &DirParams) -> Result<IrradianceLayers, OpError> {
    let mesh = MeshPoints::new(inputs.objects, params.mesh_points as usize, params.seed);
    let mut out = IrradianceLayers::new(inputs.depth.width, inputs.depth.height);
    DirRenderer::default().render(inputs, params, &mesh, &mut out)?;
    Ok(out)
}

/// `sample.dir` as a [`Renderer`]: [`DirRenderer`] (its buffers kept from frame to
/// frame) over the frame's products, with the objects' points spread once per run, or
/// again each frame an object moved.
pub struct SampleDir {
    mesh: MeshPoints,
    params: DirParams,
    objects: FollowedObjects,
    /// The pipeline's `[[light]]` spot lights.
    spots: Vec<SpotLight>,
    renderer: DirRenderer,
}

impl Renderer for SampleDir {
    const KIND: &'static str = "sample.dir";
    const SUMMARY: &'static str = "E_R / E_RV from virtual point lights with real/virtual flags, imperfect shadow maps and interleaved sampling (paper 002 Sec. 3)";
    const PARAMS: &'static [ParamSpec] = PARAMS;

    fn inputs(_: &Params) -> Vec<Port> {
        renderer_input_ports().collect()
    }

    fn build(ctx: &BuildContext) -> Result<SampleDir, StageError> {
        let mut params = DirParams::from_params(ctx.params, ctx.seed);
        let spots = crate::world::lights(ctx).to_vec();
        if spots.iter().all(|s| s.world == LightWorld::Real) {
            // No virtual spot: no slots for its light (nor their maps' memory).
            params.spot_vpls = 0;
        }
        params.check()?;
        let objects = FollowedObjects::new(ctx);
        Ok(SampleDir {
            // Spread again only when the objects move.
            mesh: MeshPoints::new(objects.scene(), params.mesh_points as usize, params.seed),
            params,
            objects,
            spots,
            renderer: DirRenderer::default(),
        })
    }

    fn render(
        &mut self,
        frame: &RenderFrame<'_>,
        out: &mut IrradianceLayers,
    ) -> Result<(), StageError> {
        let (objects, moved) = self.objects.at(frame.index)?;
        if moved {
            let (points, seed) = (self.params.mesh_points as usize, self.params.seed);
            self.mesh = MeshPoints::new(objects, points, seed);
        }
        let inputs = DirInputs {
            depth: frame.depth,
            normals: frame.normals("normals")?,
            radiance: frame.radiance("radiance")?,
            camera: frame.camera,
            camera_to_world: frame.camera_to_world,
            table: frame.light_table("light_table")?,
            objects,
            spots: &self.spots,
            frame: frame.index,
        };
        self.renderer
            .render(&inputs, &self.params, &self.mesh, out)?;
        Ok(())
    }
}
