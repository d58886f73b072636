//! `sample.val` (paper 004 Sec. 5, eqs. 6, 12, 13; in irradiance form as in paper 001
//! eq. 2): the cheap, noise-free counterpart of `sample.path`, with the same output roles
//! so the two are interchangeable in a pipeline.
//!
//! Per pixel, the real surface point comes from the depth map and the normal map; the
//! virtual objects are rasterized into the camera (one sample at the pixel centre, the
//! hit refined by a ray-triangle test), so `mask` is 0 or 1. Direct light comes from the
//! virtual area lights (`light.val`): E_j = I_j cos(theta_j)+ cos(theta)+ / r^2 (eq. 6,
//! r^2 clamped below at A_j / pi), E_R^dir = sum V_j E_j and E_RV^dir = sum V_j V^_j E_j
//! (eqs. 12-13), V_j the visibility of light j through the real scene and V^_j through
//! the virtual objects. Both come from two shadow maps per light over a frustum fitted
//! to the objects' bounding sphere (see `shadow.rs`); outside a light's frustum both are 1.
//! Consequences: E_RV^dir = E_R^dir bit for bit wherever no virtual object shadows the
//! point (both sums add the same f32 terms in the same order), and E_R^dir carries real
//! shadows only inside the frustums (elsewhere it is the irradiance unshadowed by real
//! geometry); so E_R alone is not a real-shadow estimate, but the ratio E_RV / E_R that
//! the differential composite uses is exact there (1) and correct near the objects.
//! A real occluder between a light and a receiver (V_j = 0) keeps the object from
//! shadowing that receiver again (no double shadow, paper 004 Fig. 9).
//!
//! Indirect light is the SH9 irradiance of the indirect part at the normal:
//! E_R^ind = E_RV^ind at real pixels. As in paper 004 (eq. 13 subtracts direct light
//! only) the occlusion of indirect light by the virtual objects is ignored on real
//! surfaces. On the objects (`transfer = "prt"`, the default) it is eq. 9 with the
//! transfer vectors C_vk of eq. 11 interpolated from the hit triangle's corners
//! ([`relume_scene::light::prt`]): their occlusion of themselves and of each other is in it
//! (a back face seen through a gap is shaded with its front's vectors), and with two
//! objects or more (`object_bounce = "sh"`) the light they reflect onto each other
//! (Sec. 4.4, Fig. 7 bottom; `bounce.rs`). Virtual pixels: E_RV at the object's surface
//! (self-shadowing through V^_j, real occluders through V_j), E_R at the real point
//! behind it (NaN where the depth has none); `k_v` is the albedo (with E in irradiance
//! units the Lambertian outgoing radiance is k_V E_RV / pi; glossy lobes are not
//! evaluated, a glossy object is shaded as diffuse, so `exponent` is 0 everywhere).
//! `indirect_min_distance` is INFINITY everywhere (no indirect rays);
//! `direct_min_distance` is the distance to the nearest shadow-map occluder of a light
//! that faces the point, over the cosine of that light's direction at the point (as
//! `sample.path` records it: the z / cos^2(theta_occ) of paper 001 eq. 17). Pixels with
//! no surface (no depth, or a zero normal, and no object) get NaN irradiance.
//!
//! Spot lights (`spots.rs`, the pipeline's `[[light]]` tables, paper 002 Sec. 3.7) get
//! the two maps an area light gets and are added after the area lights with paper
//! 002's flags: a real spot to E_R (V_j E_j) and E_RV (V_j V^_j E_j), a virtual one to
//! E_RV only; E_j is the spot's own profile, not eq. 6.
//!
//! Cost: the surfaces are shaded eight pixels at a time (`shade_lanes.rs`, AVX2 +
//! FMA where the CPU has them, [`relume_base::simd`]), with the bits of the per-point
//! `shade_point` (tested). The shadow maps are built for up to eight lights per pass,
//! one light per lane: the triangles (`virtual_maps.rs`) and the real points of the
//! tiles that may reach a frustum (`real_splat.rs`) are moved into all the group's light
//! spaces at once, with the bits of the one-light code (tested). The rest of the time
//! goes to the camera raster and the per-pixel outputs.

mod bounce;
mod inputs;
mod pixel;
mod raster;
mod real_splat;
mod renderer;
#[cfg(test)]
mod round_robin_tests;
mod shade;
mod shade_lanes;
mod shadow;
#[cfg(test)]
mod spot_tests;
mod spots;
mod targets;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod transfer_tests;
mod virtual_maps;

use super::layers::{IrradianceLayers, LAYER_OUTPUTS};
use super::renderer::{RenderFrame, Renderer, info};
use crate::OpError;
use crate::kind;
use crate::world::follow::FollowedObjects;
use glam::Vec3;
pub use inputs::{ValInputs, ValShadingParams};
use relume_graph::{
    BuildContext, ParamDefault, ParamSpec, Params, Port, ProductKind, StageError, StageInfo,
};
use relume_scene::light::SpotLight;
use relume_scene::light::prt::cache::{self, CacheOutcome};
use relume_scene::light::prt::{Transfer, TransferParams};
use relume_scene::objects::VirtualScene;
pub use renderer::ValRenderer;
use shadow::MAX_SHADOW_MAP_SIZE;
use std::sync::Arc;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "shadow_map_size",
        ParamDefault::Int(128),
        "texels per side of each light's two shadow maps (virtual and real), over a frustum fitted to the objects",
    )
    .range(8.0, MAX_SHADOW_MAP_SIZE as f64),
    ParamSpec::new(
        "virtual_bias",
        ParamDefault::Float(0.005),
        "metres a receiver must lie behind the virtual shadow map's depth to be in the objects' shadow",
    )
    .range(0.0, 10.0),
    ParamSpec::new(
        "real_bias",
        ParamDefault::Float(0.02),
        "metres a receiver must lie behind the real shadow map's depth to be in real shadow (covers depth noise)",
    )
    .range(0.0, 10.0),
    ParamSpec::new(
        "slope_bias",
        ParamDefault::Float(1.5),
        "extra bias in texel footprints times tan(angle of incidence), against shadow acne on oblique receivers",
    )
    .range(0.0, 100.0),
    ParamSpec::new(
        "real_occluder_reach",
        ParamDefault::Float(1.0),
        "real points count as occluders only from this many metres in front of the objects (seen from the light) onward, so the emitter's own wall or a distant light's room does not shadow everything",
    )
    .range(0.0, 1e6),
    ParamSpec::new(
        "shadow_updates",
        ParamDefault::Int(0),
        "lights whose two shadow maps are rebuilt per frame, in turn (paper 004 Sec. 5's round robin), besides every light that moved; the others keep their last maps, whose real occluders then come from an earlier frame's depth; 0 = every light every frame",
    )
    .range(0.0, 1024.0),
    ParamSpec::new(
        "transfer",
        ParamDefault::Str("prt"),
        "indirect light on the objects: prt = SH9 times each vertex's precomputed transfer, with the objects' occlusion of themselves and each other (paper 004 eqs. 9, 11; computed when the pipeline loads, cached in RELUME_CACHE, else $XDG_CACHE_HOME/relume or ~/.cache/relume; RELUME_CACHE=off computes every run); none = unoccluded SH9 irradiance at the normal",
    )
    .choices(&["prt", "none"]),
    ParamSpec::new(
        "object_bounce",
        ParamDefault::Str("sh"),
        "light between the objects (paper 004 Sec. 4.4, Fig. 7 bottom): sh = per frame, each object's view of the others' radiance (lit by the lights and the room) as SH9 (the paper's cube map from the object's centre), through its self-occlusion-only transfer (needs transfer = prt; with none there is nothing to carry it); none = the objects only block each other's light",
    )
    .choices(&["sh", "none"]),
    ParamSpec::new(
        "transfer_samples",
        ParamDefault::Int(4096),
        "cosine-weighted directions per vertex of the transfer precomputation (4096: within 2 % of a brute-force integral on the torus)",
    )
    .range(1.0, 1_000_000.0),
];

/// The output roles: every layer but `touched` (no path is traced, so no pixel is
/// known to be untouched).
const OUTPUTS: &[(&str, &[ProductKind])] = LAYER_OUTPUTS.split_at(11).0;

pub const INFO: StageInfo = info::<SampleVal>();

/// The objects' radiance transfer from the cache, or computed (and cached), saying on
/// stderr what it cost when it was computed and where the cache could not be written;
/// an error when the computation was interrupted.
fn load_transfer(
    stage: &str,
    objects: &VirtualScene,
    params: TransferParams,
) -> Result<Transfer, StageError> {
    let started = std::time::Instant::now();
    let dir = cache::cache_dir_from_env();
    let (transfer, outcome) =
        cache::load_or_compute(objects, params, dir.as_deref()).map_err(|_| {
            StageError::Failed(format!(
                "stage `{stage}` (sample.val): interrupted while computing the objects' \
                 radiance transfer"
            ))
        })?;
    let computed = format!(
        "stage `{stage}` (sample.val): radiance transfer of {} object vertices ({} directions each) computed in {:.1} s",
        transfer.vectors.len(),
        params.samples,
        started.elapsed().as_secs_f64()
    );
    match outcome {
        CacheOutcome::Loaded(_) => {}
        CacheOutcome::Written { path, .. } => {
            eprintln!("{computed}, cached in {}", path.display())
        }
        CacheOutcome::NotWritten { path, reason } => {
            eprintln!(
                "{computed}; cannot cache it in {}: {reason}",
                path.display()
            )
        }
        CacheOutcome::Disabled => eprintln!("{computed} (cache off)"),
    }
    Ok(transfer)
}

/// Buffers for [`ValRenderer::render`], which overwrites every pixel: irradiance NaN
/// where there is neither a real point nor an object, `exponent` 0 (glossy objects
/// are shaded as diffuse), `indirect_min_distance` infinite and `touched` 1 (not an
/// output: no pixel is known to be untouched).
pub fn val_layers(width: u32, height: u32) -> IrradianceLayers {
    IrradianceLayers::filled(width, height, Vec3::ZERO)
}

/// [`ValRenderer::render`] with fresh buffers (for `relume eval` and one-off use).
pub fn sample_val(
    inputs: &ValInputs,
    params: &ValShadingParams,
) -> Result<IrradianceLayers, OpError> {
    let mut out = val_layers(inputs.depth.width, inputs.depth.height);
    ValRenderer::default().render(inputs, params, &mut out)?;
    Ok(out)
}

/// `sample.val` as a [`Renderer`]: [`ValRenderer`] (its shadow maps kept from frame
/// to frame) over the frame's products, with the objects' radiance transfer loaded
/// once per run.
pub struct SampleVal {
    objects: FollowedObjects,
    transfer: Option<Arc<Transfer>>,
    /// The pipeline's `[[light]]` spot lights.
    spots: Vec<SpotLight>,
    params: ValShadingParams,
    renderer: ValRenderer,
}

impl Renderer for SampleVal {
    const KIND: &'static str = "sample.val";
    const SUMMARY: &'static str = "noise-free E_R / E_RV from virtual area lights with real and virtual shadow maps plus SH9 (paper 004 Sec. 5)";
    const PARAMS: &'static [ParamSpec] = PARAMS;
    const OUTPUTS: &'static [(&'static str, &'static [ProductKind])] = OUTPUTS;

    fn inputs(_: &Params) -> Vec<Port> {
        vec![
            Port::new("depth", "refined_depth", &[kind::DEPTH]),
            Port::new("normals", "normals", &[kind::NORMALS]),
            Port::new("pose", "pose", &[kind::POSE]),
            Port::new("lights", "lights", &[kind::AREA_LIGHTS]),
        ]
    }

    fn build(ctx: &BuildContext) -> Result<SampleVal, StageError> {
        let p = ctx.params;
        let objects = crate::world::objects(ctx);
        let transfer = match p.str("transfer") == "prt" && !objects.is_empty() {
            true if crate::world::object_world(ctx.world).moves() => {
                return Err(StageError::Failed(format!(
                    "stage `{}` (sample.val): transfer = \"prt\" precomputes the objects' occlusion of each other where they stand, and an object of this pipeline moves; use transfer = \"none\" (unoccluded SH9 irradiance) with moving objects",
                    ctx.stage_name
                )));
            }
            true => {
                let params = TransferParams {
                    samples: p.int("transfer_samples") as u32,
                    seed: ctx.seed,
                };
                Some(Arc::new(load_transfer(ctx.stage_name, objects, params)?))
            }
            false => None,
        };
        Ok(SampleVal {
            objects: FollowedObjects::new(ctx),
            transfer,
            spots: crate::world::lights(ctx).to_vec(),
            params: ValShadingParams {
                shadow_map_size: p.int("shadow_map_size") as usize,
                virtual_bias: p.float("virtual_bias") as f32,
                real_bias: p.float("real_bias") as f32,
                slope_bias: p.float("slope_bias") as f32,
                real_occluder_reach: p.float("real_occluder_reach") as f32,
                shadow_updates: p.int("shadow_updates") as usize,
                object_bounce: p.str("object_bounce") == "sh",
            },
            renderer: ValRenderer::default(),
        })
    }

    fn layers(width: u32, height: u32) -> IrradianceLayers {
        val_layers(width, height)
    }

    fn render(
        &mut self,
        frame: &RenderFrame<'_>,
        out: &mut IrradianceLayers,
    ) -> Result<(), StageError> {
        let (objects, moved) = self.objects.at(frame.index)?;
        if moved {
            // Maps of the objects where they stood: every light's is built again.
            self.renderer.map_frusta.clear();
        }
        let inputs = ValInputs {
            depth: frame.depth,
            normals: frame.normals("normals")?,
            camera: frame.camera,
            camera_to_world: frame.camera_to_world,
            lights: frame.area_lights("lights")?,
            objects,
            transfer: self.transfer.as_deref(),
            spots: &self.spots,
        };
        self.renderer.render(&inputs, &self.params, out)?;
        Ok(())
    }
}
