//! `sample.path` (paper 001 Sec. 5, two-mode sampling): per pixel, Monte Carlo
//! estimates of the irradiance with real geometry only (E_R) and with real and virtual
//! geometry (E_RV), each split into direct and one-bounce indirect parts. Real geometry
//! is the depth map, traced in screen space ([`ScreenTracer`], hierarchical over a
//! min-max pyramid); virtual geometry is the pipeline's [`VirtualScene`](relume_scene::objects::VirtualScene).
//!
//! Per pixel:
//! - **Primary samples** (`primary`, 4): jittered sub-pixel view rays. The real surface
//!   along each is the pixel's depth (one per pixel); a primary is virtual when an
//!   object is hit nearer than it. The mask M is the fraction of real primaries (1 where
//!   the pixel has neither depth nor an object). `k_v` is the mean albedo of the virtual
//!   primaries (0 where none), `exponent` their mean Phong exponent (0 where none or
//!   diffuse; the filter's bandwidths need it); `world_position` / `world_normal` are the means over
//!   primaries of the visible surface (world space; the normal renormalized).
//! - **E_R** is always estimated at the real shading point (the pixel's depth-map point
//!   and normal; NaN where either is missing), with `direct` + `indirect` samples per
//!   primary (4 + 4 by default, 16 + 16 per pixel).
//! - **Direct light** (units: irradiance, a constant environment L unoccluded gives
//!   pi L): E^dir = mean of L V cos+ / pdf over samples of the importance table
//!   ([`LightTable`](relume_scene::light::LightTable), Sec. 5.2). Direct sample (j, k) reads stratum j * direct + k of
//!   `primary * direct` equal strata of the table (the table is in stratified order), at
//!   an offset hashed per pixel. V is 0 when the screen-space tracer meets a real
//!   surface within `max_distance`, and for E_RV also when an object is hit at any
//!   distance.
//! - **Indirect light** (one bounce, next-event estimation style): cosine-weighted
//!   directions, E^ind = pi * mean(L_hit). A ray that escapes (no real surface within
//!   `max_distance`) brings 0: the environment is counted by direct light. A real hit
//!   brings that pixel's `radiance` (the camera's compensated light of the room). For
//!   E_RV, an object hit nearer than the real one brings the object's outgoing radiance
//!   there: (k_V / pi) E^dir from one table sample with virtual (self) and real
//!   visibility; glossy objects are taken as diffuse for this bounce (as paper 000
//!   Sec. 6.4 does) and the light the room reflects onto the object is left out (one
//!   bounce).
//! - **Correlation**: at a real primary, E_RV's samples are E_R's samples (same random
//!   numbers, same paths) with the objects added, and both sums are accumulated in the
//!   same order, so E_RV == E_R bit for bit wherever no path meets an object; `touched`
//!   is 1 where some path did (a virtual primary, a blocked direct sample, an indirect
//!   ray reflected by an object, or an object-aware candidate that met one; with
//!   `object_aware_direct`, direct samples are not tested and only candidates count). The
//!   virtual test runs only for rays inside the cone of the objects' bounding sphere
//!   and then through their bounding box, so the RV work concentrates near them.
//! - **At a virtual primary** E_RV is estimated at the object surface: direct from the
//!   table with self-shadowing and real occlusion; indirect by cosine sampling (diffuse)
//!   or Phong-lobe sampling about the mirror direction (glossy), each ray bringing the
//!   nearer of the object (its outgoing radiance, as above) and the real surface.
//!   Convention (paper 001 Sec. 3, "Glossy Virtual Objects"): the outgoing radiance of
//!   a virtual pixel is `k_V * E_RV / pi` for both materials. For diffuse surfaces
//!   E_RV is the irradiance; for glossy ones (normalized Phong,
//!   f = k_V (n + 2) / (2 pi) cos^n(alpha)) E_RV is pi times the outgoing radiance per
//!   unit albedo, pi * integral L f / k_V cos(theta), which also equals pi L under a
//!   constant environment.
//! - **Object-aware sampling** (paper 000 Sec. 7, `object_aware = true`): at real points,
//!   E_RV^ind = E_R^ind + a differential estimated from `candidates` cosine directions:
//!   those meeting the bounding box form H; at most `cache_size` of them (H_a, chosen
//!   uniformly by reservoir sampling when |H| is larger) are traced, and their sum of
//!   L_RV - L_R is scaled by pi (1 + |H_b| / |H_a|) / candidates. It is unbiased, and
//!   E_RV == E_R still holds exactly where no candidate meets an object. Direct light
//!   keeps the correlated table samples (they already follow the light, and a blocked
//!   sample is exactly what a shadow needs) unless `object_aware_direct = true`, which
//!   estimates E_RV^dir the same way from `candidates` table samples (see
//!   `object_aware.rs`); the correlated samples then carry no blocking.
//! - `direct_min_distance` / `indirect_min_distance` (metres, over E_R and E_RV paths,
//!   INFINITY where none; the filter's bandwidths need them): for indirect rays the
//!   smallest hit distance; for blocked direct samples the smallest t / cos(theta) of
//!   the hit distance t and the sample's angle theta to the normal. That is the
//!   z / cos^2(theta_occ) of paper 001 eq. 17, whose flatland occluder stands at depth
//!   z = t cos(theta) above the receiver (Fig. 3c): an occluder met at a grazing angle
//!   narrows the filter less than one overhead at the same distance. As in paper 001
//!   Sec. 7, occluders of dim direct samples are ignored: those whose radiance (largest
//!   channel) is below `occluder_threshold` (0.1) times the table's brightest sample.
//!   The paper's threshold is an absolute intensity of 0.1 in its own units; relative to
//!   the brightest sample, the cut is the same for any exposure or map scale. Under a
//!   map dominated by one very bright source (a sun), it ignores the occluders of all
//!   other light.
//! - **Near the objects** (`near_primary` > 0): the pixels where the differential is
//!   take `near_primary` primaries instead of `primary` (each with its `direct` +
//!   `indirect` samples): those inside the objects' pixel bounds (a primary may meet
//!   them) and those whose real point lies within `near_distance` of the objects'
//!   bounding box (their contact shadows and colour bleeding). Elsewhere the composite
//!   shows the camera's pixel unless a rare path meets an object, so few samples do.
//!   A pixel gets the bits a run with its own primary count everywhere gives it. The
//!   default pipeline draws 1 primary with 1 + 1 samples, 2 near the objects, and lets
//!   `temporal.accumulate` average them over the frames.
//! - Random numbers are counter-based per (seed, frame, pixel, stream, sample), so the
//!   products are the same for any thread count.
//!
//! **The radiance query** (`query`, paper 000 Sec. 6; see [`super::query`]) decides
//! how every ray above meets the real scene. `ssrt` (the default, described above)
//! marches the depth map within `max_distance` and takes the environment map beyond.
//! `em` and `dit` read the distance impostor (`environment`, light.impostor's map)
//! instead: every ray reaches the environment at the impostor's distance, so direct
//! samples take the radiance the query returns (for `em` the table's direction looked
//! up from the impostor's centre; for `dit` traced from the shading point), nothing is
//! near real geometry (E_R^ind = 0: the room's light is all direct light), and an
//! object farther along a ray than the environment is hidden (Sec. 6.4, ray 3).
//! `vct` reads the scene's voxel volume (`voxels`, light.voxels) the same way, each ray
//! a cone whose aperture follows its sample's share of the lobe ([`super::query::cone_spread`]:
//! 2 pi / N of the hemisphere, narrowed to a glossy object's Phong lobe), starting a
//! voxel off the surface; and the objects' shadows (direct light blocked at real
//! points, the objects' own direct samples and bounce) come from cones through their
//! solid volume (`object_voxels` a side, built once): the light that passes is
//! 1 - opacity (paper 000 eq. 6), so shadows are soft and a sample is partly
//! blocked. Where it departs from the paper: the objects' radiance along indirect rays
//! and the object-aware candidates still come from the meshes (the BVH), not from
//! normals and materials stored in the voxels.
//! `visibility = false` drops the objects' self-occlusion test (their own direct
//! samples, reflected rays and bounce radiance are not tested against them: Table 3's
//! cheaper rows). The estimates keep their correlation: E_RV == E_R bit for bit where
//! no path meets an object, with any query.
//!
//! **Paper 000's presets** (Table 2) need four more knobs. `object_visibility =
//! "voxels"` tests direct light's shadow rays against the objects' solid volume with
//! any query, as paper 000 Sec. 6.2 does for every technique ("testing the whole
//! triangle mesh for intersections is too expensive"); `auto` keeps the mesh for all
//! but `vct`. Indirect rays and `object_aware_direct`'s candidates meet the mesh.
//! `object_direct` / `object_indirect` give the primaries that meet an object their own
//! sample counts ("high": 128 for the object, 64 for the room); such a primary still
//! weighs in its pixel's mean as a real primary does. `self_bounce = false` makes an
//! object's indirect ray that meets the objects again bring nothing ("medium": a
//! visibility test only) instead of the light reflected there ("high": a secondary
//! bounce). `material_query = "dit"` under `em` traces the impostor for the real
//! points' rays (the material estimation and the differential background) while the
//! objects' own rays keep em's lookup ("low": "for the material estimation DIT is also
//! used in EM cases", Sec. 7). Where the paper's objects carry their normals and
//! materials in the volume, relume's indirect rays still take the objects' radiance
//! from the mesh.
//!
//! **Spot lights** (`spots.rs`, the pipeline's `[[light]]` tables, paper 002 Sec. 3.7):
//! a point source's direct light is exact with one shadow ray, so it is added after
//! the estimate, deterministically: a real spot to E_R (real visibility: the
//! screen-space march within `max_distance`; nothing real blocks under the world-space
//! queries) and to E_RV (also the objects' BVH), a virtual spot to E_RV only. Pixels
//! that show an object mix in the light at the object the pixel centre's ray meets.
//!
//! **Where the time goes** ([`PathTimes`], `parts.rs`): the material estimation (the
//! real points' samples, rays and E_R), the virtual object (finding the primaries that
//! meet it, their samples, rays and E_RV), the differential background (the real
//! samples' tests against the objects, the object-aware candidates) and the setup (the
//! depth pyramid, the tables, the objects' volume). The parts interleave pixel by
//! pixel, so each span reads a cheap clock around them; the stage reports them
//! ([`Renderer::parts`]) and `relume bench` prints them under its row.
//!
//! `max_distance` bounds the screen-space march (default 1 m): real geometry nearer
//! than that occludes and reflects; beyond it the environment map stands for the room.
//! It also bounds the cost of each march. Real ray origins are raised along the normal
//! by `normal_offset` pixel footprints (default 1) so that grazing rays do not hit
//! their own surface between pixel centres.
//!
//! Cost: the screen-space marches dominate. Per valid pixel there are up to
//! primary x (direct + indirect) = 32 of them (direct samples below the horizon are not
//! traced). Measured on the bench frame at 640x480: 23 marched rays per pixel, 13.9
//! iterations of the hierarchical march per ray (2 of them at level 0) where the
//! sample-by-sample march would test 132 pixels. Pixels are therefore estimated a span
//! of a row at a time: the real points' direct and indirect samples, and those of the
//! virtual primaries' hits, are drawn first, then all their rays are marched together,
//! eight per AVX2 vector where the CPU has it (see `span` and
//! [`crate::sample::ssrt::batch::TraceBatch`]; the same hits as ray by ray). The few
//! rays that depend on another ray's hit (the shadow ray of an object that an indirect
//! ray met) or are object-aware candidates are traced one at a time. The virtual objects cost a cone test per ray, then a box test
//! and the BVH only for rays inside the cone of their bounding sphere.

mod bounds;
mod inputs;
mod kernel;
mod object_aware;
mod params;
mod parts;
mod rays;
mod records;
pub mod sampling;
mod span;
mod spots;

pub use super::layers::IrradianceLayers;
use crate::kind;
pub use inputs::PathInputs;
pub use params::{MAX_CANDIDATES, MAX_SAMPLES, ObjectVisibility, PathParams};
use params::{PARAMS, query_kind};
pub use parts::{PART_NAMES, PathTimes};

use super::layers::{check_sizes, renderer_input_ports, shade_rows};
use super::pyramid::DepthPyramid;
use super::query::{ImpostorQuery, QueryKind, VoxelQuery};
use super::renderer::{self, RenderFrame, Renderer};
use super::ssrt::ScreenTracer;
use crate::OpError;
use crate::world::follow::FollowedObjects;
use kernel::Kernel;
use rays::WorldQuery;
use relume_base::simd;
use relume_graph::{BuildContext, ParamSpec, Params, Parts, Port, StageError, StageInfo};
use relume_scene::light::SpotLight;
use relume_scene::light::voxels::VoxelVolume;
use span::{SPAN_PIXELS, Span};
use std::sync::Arc;
use std::time::Instant;

pub const INFO: StageInfo = renderer::info::<SamplePath>();

/// Estimates E_R and E_RV (direct and indirect), the mask, k_V, the mean visible
/// surface and the minimum hit distances of every pixel (paper 001 Sec. 5; see the
/// module docs). Builds the depth pyramid of the frame (O(pixels)) and fills `out`,
/// which must be the depth map's size. Returns where the time went ([`PathTimes`],
/// paper 000 Table 2's rows).
pub fn sample_path(
    inputs: &PathInputs,
    params: &PathParams,
    out: &mut IrradianceLayers,
) -> Result<PathTimes, OpError> {
    let start = Instant::now();
    params.check()?;
    let pyramid = DepthPyramid::new(inputs.depth);
    let mut times = sample_path_with_pyramid(inputs, params, &pyramid, out)?;
    let (total, parts) = (start.elapsed(), times.ns.iter().sum::<u64>());
    times.ns[3] += (total.as_nanos() as u64).saturating_sub(parts);
    Ok(times)
}

/// [`sample_path`] with the depth map's pyramid already built (a stage reuses its
/// buffers across frames).
pub fn sample_path_with_pyramid(
    inputs: &PathInputs,
    params: &PathParams,
    pyramid: &DepthPyramid,
    out: &mut IrradianceLayers,
) -> Result<PathTimes, OpError> {
    sample_path_with_kernel(inputs, params, pyramid, simd::Kernel::detect(), out)
}

/// [`sample_path_with_pyramid`] marching the screen-space rays with `lanes` where the
/// CPU has it (the outputs are the same with any).
pub(crate) fn sample_path_with_kernel(
    inputs: &PathInputs,
    params: &PathParams,
    pyramid: &DepthPyramid,
    lanes: simd::Kernel,
    out: &mut IrradianceLayers,
) -> Result<PathTimes, OpError> {
    let start = Instant::now();
    params.check()?;
    let (w, h) = (inputs.depth.width, inputs.depth.height);
    check_sizes(
        "sample.path",
        (w, h),
        &[
            ("normals", inputs.normals.width, inputs.normals.height),
            ("radiance", inputs.radiance.width, inputs.radiance.height),
            ("camera", inputs.camera.width, inputs.camera.height),
        ],
    )?;
    if out.size() != Some((w, h)) {
        return Err(OpError::SizeMismatch(format!(
            "sample.path: output buffers are not all {w}x{h}"
        )));
    }
    if !inputs.camera_to_world.is_finite() {
        return Err(OpError::BadInput(
            "sample.path: the camera pose is not finite".into(),
        ));
    }
    let world_query = query_over(inputs, params, params.query)?;
    // The material estimation's own query: dit where the objects' rays look up em.
    let real_query = match params.query {
        QueryKind::Em if params.material_dit => query_over(inputs, params, QueryKind::Dit)?,
        _ => None,
    };
    if w == 0 || h == 0 {
        return Ok(PathTimes::default());
    }
    let built;
    let object_volume = match inputs.object_voxels {
        Some(volume) if params.object_visibility_by_voxels() => Some(volume),
        _ => {
            built = params.object_volume(inputs.objects);
            built.as_ref()
        }
    };
    let tracer = ScreenTracer::with_pyramid(
        inputs.depth,
        pyramid,
        inputs.camera,
        inputs.camera_to_world,
        params.trace,
    );
    let queries = (world_query, real_query);
    let kernel = Kernel::new(inputs, params, tracer, queries, object_volume, lanes);
    let stride = params.pixel_stride as usize;
    let xs: Vec<u32> = (0..w).step_by(stride).collect();
    let rows_start = Instant::now();
    shade_rows(
        out,
        w as usize,
        params.pixel_stride as usize,
        || Span::new(&kernel, params),
        |span, y, mut row| {
            for xs in xs.chunks(SPAN_PIXELS) {
                span.shade(&kernel, y as u32, xs, |x, r| row.set(x as usize, r));
            }
        },
    );
    let rows = rows_start.elapsed();
    if !inputs.spots.is_empty() {
        // Their time is the setup's (the renderer's wall time less the parts).
        spots::add_spots(&kernel, inputs.spots, stride, out);
    }
    Ok(kernel.parts.times(rows, rows_start - start))
}

/// The world-space query of kind `kind` with `params` (`None` for screen-space
/// marching), over the inputs' environment map or voxel volume; the error says what is
/// missing or malformed.
fn query_over<'a>(
    inputs: &PathInputs<'a>,
    params: &PathParams,
    kind: QueryKind,
) -> Result<Option<WorldQuery<'a>>, OpError> {
    let query = kind.name();
    let iterations = match kind {
        QueryKind::Ssrt => return Ok(None),
        QueryKind::Vct => {
            let Some(volume) = inputs.voxels else {
                return Err(OpError::BadInput(format!(
                    "sample.path: query \"{query}\" needs a voxel volume (the `voxels` of light.voxels)"
                )));
            };
            return Ok(Some(WorldQuery::Voxels(VoxelQuery::new(volume))));
        }
        QueryKind::Em => 0,
        QueryKind::Dit => params.iterations,
    };
    let Some(map) = inputs.environment else {
        return Err(OpError::BadInput(format!(
            "sample.path: query \"{query}\" needs an environment map (the distance impostor of light.impostor)"
        )));
    };
    ImpostorQuery::new(map, iterations)
        .map(|q| Some(WorldQuery::Impostor(q)))
        .map_err(|e| OpError::BadInput(format!("sample.path: query \"{query}\": {e}")))
}

/// `sample.path` as a [`Renderer`]: the estimator of [`sample_path`] over the
/// frame's products, with the objects' solid volume (`vct`) built once per run, or
/// again each frame an object moved.
pub struct SamplePath {
    params: PathParams,
    objects: FollowedObjects,
    /// The pipeline's `[[light]]` spot lights.
    spots: Vec<SpotLight>,
    /// The objects' solid volume (visibility by voxels).
    object_voxels: Option<Arc<VoxelVolume>>,
    /// Where the last frame's time went.
    times: Option<PathTimes>,
}

impl Renderer for SamplePath {
    const KIND: &'static str = "sample.path";
    const SUMMARY: &'static str =
        "two-mode Monte Carlo estimates of E_R and E_RV, direct and indirect (paper 001 Sec. 5)";
    const PARAMS: &'static [ParamSpec] = PARAMS;
    const REFERENCES_ITSELF: bool = true;

    fn inputs(p: &Params) -> Vec<Port> {
        renderer_input_ports()
            .chain(
                query_kind(p)
                    .needs_environment()
                    .then(|| Port::new("environment", "environment", &[kind::ENVIRONMENT])),
            )
            .chain(
                query_kind(p)
                    .needs_voxels()
                    .then(|| Port::new("voxels", "voxels", &[kind::VOXELS])),
            )
            .collect()
    }

    fn build(ctx: &BuildContext) -> Result<SamplePath, StageError> {
        let params = PathParams::from_params(ctx.params, ctx.seed);
        params.check()?;
        let objects = FollowedObjects::new(ctx);
        Ok(SamplePath {
            // Built again only when the objects move.
            object_voxels: params.object_volume(objects.scene()).map(Arc::new),
            params,
            objects,
            spots: crate::world::lights(ctx).to_vec(),
            times: None,
        })
    }

    fn render(
        &mut self,
        frame: &RenderFrame<'_>,
        out: &mut IrradianceLayers,
    ) -> Result<(), StageError> {
        let start = Instant::now();
        // A frame that fails reports no parts (not the last good frame's).
        self.times = None;
        let query = self.params.query;
        let (objects, moved) = self.objects.at(frame.index)?;
        if moved {
            self.object_voxels = self.params.object_volume(objects).map(Arc::new);
        }
        let inputs = PathInputs {
            depth: frame.depth,
            normals: frame.normals("normals")?,
            radiance: frame.radiance("radiance")?,
            camera: frame.camera,
            camera_to_world: frame.camera_to_world,
            table: frame.light_table("light_table")?,
            environment: match query.needs_environment() {
                true => Some(frame.environment("environment")?),
                false => None,
            },
            voxels: match query.needs_voxels() {
                true => Some(frame.voxels("voxels")?),
                false => None,
            },
            objects,
            object_voxels: self.object_voxels.as_deref(),
            frame: frame.index,
            spots: &self.spots,
        };
        let mut times = sample_path(&inputs, &self.params, out)?;
        let (total, parts) = (start.elapsed(), times.ns.iter().sum::<u64>());
        times.ns[3] += (total.as_nanos() as u64).saturating_sub(parts);
        self.times = Some(times);
        Ok(())
    }

    fn parts(&self) -> Option<Parts> {
        let times = self.times?;
        Some(Parts {
            names: PART_NAMES,
            ns: times.ns,
        })
    }
}

#[cfg(test)]
mod determinism_tests;
#[cfg(test)]
mod near_tests;
#[cfg(test)]
mod object_aware_tests;
#[cfg(test)]
mod preset_tests;
#[cfg(test)]
mod query_tests;
#[cfg(test)]
mod spot_tests;
#[cfg(test)]
mod stage_tests;
#[cfg(test)]
pub(crate) mod tests;
