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
//! (a back face seen through a gap is shaded with its front's vectors). Virtual pixels: E_RV at the object's surface
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
//! Cost: the surfaces are shaded eight pixels at a time (`shade_lanes.rs`, AVX2 +
//! FMA where the CPU has them, [`relume_base::simd`]), with the bits of the per-point
//! `shade_point` (tested). The shadow maps are built for up to eight lights per pass,
//! one light per lane: the triangles (`virtual_maps.rs`) and the real points of the
//! tiles that may reach a frustum (`real_splat.rs`) are moved into all the group's light
//! spaces at once, with the bits of the one-light code (tested). The rest of the time
//! goes to the camera raster and the per-pixel outputs.

mod pixel;
mod raster;
mod real_splat;
#[cfg(test)]
mod round_robin_tests;
mod shade;
mod shade_lanes;
mod shadow;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod transfer_tests;
mod virtual_maps;

use super::layers::{IrradianceLayers, LAYER_OUTPUTS, shade_rows};
use crate::kind;
use crate::kind::FrameProducts;
use glam::{Affine3A, Vec2, Vec3, Vec3A};
use pixel::{PixelContext, sampling_of};
use raster::{DepthTarget, NO_ID, ScreenTriangle, raster_screen_triangle, screen_triangles};
use rayon::prelude::*;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Vec3Image, depth_is_valid};
use relume_base::simd::{Kernel, Portable};
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Ports, ProductKind, Stage, StageError, StageInfo,
};
use relume_recording::Intrinsics;
use relume_scene::light::AreaLights;
use relume_scene::light::prt::cache::{self, CacheOutcome};
use relume_scene::light::prt::{Transfer, TransferParams};
use relume_scene::objects::VirtualScene;
use shade::{Biases, Maps, Sh9Irradiance};
use shadow::{MAX_SHADOW_MAP_SIZE, TILE, Tile, tile_of};
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
        "transfer_samples",
        ParamDefault::Int(4096),
        "cosine-weighted directions per vertex of the transfer precomputation (4096: within 2 % of a brute-force integral on the torus)",
    )
    .range(1.0, 1_000_000.0),
];

/// The output roles: every layer but `touched` (no path is traced, so no pixel is
/// known to be untouched).
const OUTPUTS: &[(&str, &[ProductKind])] = LAYER_OUTPUTS.split_at(11).0;

pub const INFO: StageInfo = StageInfo {
    kind: "sample.val",
    summary: "noise-free E_R / E_RV from virtual area lights with real and virtual shadow maps plus SH9 (paper 004 Sec. 5)",
    params: PARAMS,
    ports: |_| {
        let mut ports = Ports::fixed(
            &[
                ("depth", &[kind::DEPTH]),
                ("normals", &[kind::NORMALS]),
                ("pose", &[kind::POSE]),
                ("lights", &[kind::AREA_LIGHTS]),
            ],
            OUTPUTS,
        );
        ports.inputs[0].default_product = "refined_depth".into();
        ports
    },
    build: |ctx| {
        let p = ctx.params;
        let transfer =
            (p.str("transfer") == "prt" && !crate::world::objects(ctx).is_empty()).then(|| {
                let params = TransferParams {
                    samples: p.int("transfer_samples") as u32,
                    seed: ctx.seed,
                };
                Arc::new(load_transfer(
                    ctx.stage_name,
                    crate::world::objects(ctx),
                    params,
                ))
            });
        Ok(Box::new(SampleVal {
            inputs: ["depth", "normals", "pose", "lights"].map(|r| ctx.input(r)),
            outputs: OUTPUTS.iter().map(|(r, _)| ctx.output(r)).collect(),
            intrinsics: ctx.header.depth_intrinsics,
            objects: crate::world::objects(ctx).clone(),
            transfer,
            params: ValShadingParams {
                shadow_map_size: p.int("shadow_map_size") as usize,
                virtual_bias: p.float("virtual_bias") as f32,
                real_bias: p.float("real_bias") as f32,
                slope_bias: p.float("slope_bias") as f32,
                real_occluder_reach: p.float("real_occluder_reach") as f32,
                shadow_updates: p.int("shadow_updates") as usize,
            },
            renderer: ValRenderer::default(),
        }))
    },
};

/// The objects' radiance transfer from the cache, or computed (and cached), saying on
/// stderr what it cost when it was computed and where the cache could not be written.
fn load_transfer(stage: &str, objects: &VirtualScene, params: TransferParams) -> Transfer {
    let started = std::time::Instant::now();
    let dir = cache::cache_dir_from_env();
    let (transfer, outcome) = cache::load_or_compute(objects, params, dir.as_deref());
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
    transfer
}

/// Settings of [`ValRenderer::render`] (the stage's parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValShadingParams {
    pub shadow_map_size: usize,
    pub virtual_bias: f32,
    pub real_bias: f32,
    pub slope_bias: f32,
    pub real_occluder_reach: f32,
    /// Lights whose shadow maps are rebuilt per frame, in turn; 0 = all.
    pub shadow_updates: usize,
}

impl Default for ValShadingParams {
    fn default() -> Self {
        ValShadingParams {
            shadow_map_size: 128,
            virtual_bias: 0.005,
            real_bias: 0.02,
            slope_bias: 1.5,
            real_occluder_reach: 1.0,
            shadow_updates: 0,
        }
    }
}

/// One frame's inputs.
#[derive(Clone, Copy)]
pub struct ValInputs<'a> {
    /// Metres, 0 or non-finite = missing.
    pub depth: &'a DepthImage,
    /// Camera-space unit normals facing the camera (zero = invalid), same size.
    pub normals: &'a Vec3Image,
    /// The camera of `depth` (rescaled to its size).
    pub camera: Pinhole,
    pub camera_to_world: Affine3A,
    pub lights: &'a AreaLights,
    pub objects: &'a VirtualScene,
    /// The objects' radiance transfer (paper 004 eq. 11) for their indirect light, or
    /// `None` for the unoccluded SH9 irradiance at the normal.
    pub transfer: Option<&'a Transfer>,
}

/// Buffers for [`ValRenderer::render`], which overwrites every pixel: irradiance NaN
/// where there is neither a real point nor an object, `exponent` 0 (glossy objects
/// are shaded as diffuse), `indirect_min_distance` infinite and `touched` 1 (not an
/// output: no pixel is known to be untouched).
pub fn val_layers(width: u32, height: u32) -> IrradianceLayers {
    IrradianceLayers::filled(width, height, Vec3::ZERO)
}

/// Shades frames with reusable buffers (real points, camera raster, shadow maps).
#[derive(Default)]
pub struct ValRenderer {
    real_points: Vec<Vec3A>,
    real_normals: Vec<Vec3A>,
    /// Per real point, the world size of the patch it stands for
    /// ([`shadow::PointSampling::footprint`]; computed once, used per light).
    real_patches: Vec<f32>,
    camera_depth: Vec<f32>,
    camera_ids: Vec<u32>,
    /// The virtual triangles clipped and projected into the camera.
    screen: Vec<ScreenTriangle>,
    /// Bounding spheres of the real points per tile (row-major tile grid).
    tiles: Vec<Option<Tile>>,
    /// Per tile, bit j set when the tile's real points may be inside light j's frustum.
    lookup: Vec<u64>,
    maps: Vec<f32>,
    /// The frustum each light's maps in `maps` were built with, their size, and the
    /// calls so far (the round robin of `shadow_updates`, see `shadow.rs`).
    map_frusta: Vec<Option<shadow::ShadowFrustum>>,
    /// The (position, normal) of the light each map was built for.
    map_lights: Vec<(Vec3, Vec3)>,
    map_size: usize,
    shadow_calls: u64,
    /// The shading and splatting kernel; `None`: the fastest the CPU runs (all give the
    /// same bits).
    kernel: Option<Kernel>,
    /// Shade every pixel with the scalar `shade_point`, and splat the real shadow maps
    /// one light and one point at a time, instead (the kernels' reference).
    #[cfg(test)]
    scalar_reference: bool,
}

/// The near plane of the camera raster, metres.
const CAMERA_NEAR: f32 = 1e-3;

/// Rows per band of the parallel camera raster.
const RASTER_BAND_ROWS: usize = 16;

impl ValRenderer {
    /// A renderer that shades with `kernel` (all kernels give the same bits).
    pub fn with_kernel(kernel: Kernel) -> ValRenderer {
        ValRenderer {
            kernel: Some(kernel),
            ..ValRenderer::default()
        }
    }

    /// Computes every output for one frame (see the module docs for the model).
    pub fn render(
        &mut self,
        inputs: &ValInputs,
        params: &ValShadingParams,
        out: &mut IrradianceLayers,
    ) -> Result<(), StageError> {
        let (w, h) = (inputs.depth.width, inputs.depth.height);
        if !inputs.depth.same_size(inputs.normals) || out.size() != Some((w, h)) {
            return Err(StageError::Failed(format!(
                "sample.val: depth is {w}x{h}, normals {}x{}, outputs {}x{}",
                inputs.normals.width, inputs.normals.height, out.mask.width, out.mask.height
            )));
        }
        if (inputs.camera.width, inputs.camera.height) != (w, h) {
            return Err(StageError::Failed(format!(
                "sample.val: the camera is {}x{} but the depth map {w}x{h}",
                inputs.camera.width, inputs.camera.height
            )));
        }
        if !(1..=MAX_SHADOW_MAP_SIZE).contains(&params.shadow_map_size) {
            return Err(StageError::Failed(format!(
                "sample.val: shadow_map_size must be 1 to {MAX_SHADOW_MAP_SIZE}, not {}",
                params.shadow_map_size
            )));
        }
        let (wu, hu) = (w as usize, h as usize);
        self.real_surface(inputs);
        self.camera_raster(inputs);
        self.build_tiles(wu, hu);
        let lights = self.shadow_maps(inputs, params);
        let size = params.shadow_map_size;
        let maps = Maps {
            data: &self.maps,
            stride: 3 * size * size,
            texels: size * size,
        };
        let biases = Biases {
            virtual_bias: params.virtual_bias,
            real_bias: params.real_bias,
            slope: params.slope_bias,
        };
        let sh = Sh9Irradiance::new(&inputs.lights.sh9);
        let kernel = self.kernel.unwrap_or_else(Kernel::detect).available();
        #[cfg(test)]
        let scalar_reference = self.scalar_reference;
        let context = PixelContext {
            inputs,
            real_points: &self.real_points,
            real_normals: &self.real_normals,
            real_patches: &self.real_patches,
            lookup: &self.lookup,
            tiles_per_row: wu.div_ceil(TILE),
            ids: &self.camera_ids,
            lights: &lights,
            maps,
            biases,
            sh,
            sampling: sampling_of(inputs),
        };
        shade_rows(
            out,
            wu,
            1,
            || (),
            |_, y, mut row| {
                #[cfg(test)]
                if scalar_reference {
                    for x in 0..wu {
                        context.pixel(x, y, &mut row);
                    }
                    return;
                }
                match kernel {
                    #[cfg(target_arch = "x86_64")]
                    // SAFETY: `kernel` came from `Kernel::available`: the CPU has AVX2 and FMA.
                    Kernel::Avx2Fma => unsafe { pixel::row_avx2(&context, y, &mut row) },
                    _ => context.row::<Portable>(y, &mut row),
                }
            },
        );
        Ok(())
    }

    /// World points, normals and patch sizes of the real surface (NaN / zero / NaN
    /// where missing).
    fn real_surface(&mut self, inputs: &ValInputs) {
        let (w, n) = (inputs.depth.width as usize, inputs.depth.len());
        self.real_points.resize(n, Vec3A::NAN);
        self.real_normals.resize(n, Vec3A::ZERO);
        self.real_patches.resize(n, f32::NAN);
        let m = inputs.camera_to_world;
        let camera = inputs.camera;
        let sampling = sampling_of(inputs);
        self.real_points
            .par_chunks_mut(w.max(1))
            .zip(self.real_normals.par_chunks_mut(w.max(1)))
            .zip(self.real_patches.par_chunks_mut(w.max(1)))
            .enumerate()
            .for_each(|(y, ((points, normals), patches))| {
                let row = points
                    .iter_mut()
                    .zip(normals.iter_mut())
                    .zip(patches.iter_mut());
                for (x, ((p, nrm), patch)) in row.enumerate() {
                    let i = y * w + x;
                    let z = inputs.depth.data[i];
                    *p = if depth_is_valid(z) {
                        m.transform_point3a(camera.back_project(x as f32, y as f32, z).into())
                    } else {
                        Vec3A::NAN
                    };
                    *patch = sampling.footprint(*p);
                    let n_cam = inputs.normals.data[i];
                    *nrm = if n_cam != Vec3::ZERO && n_cam.is_finite() {
                        m.transform_vector3a(n_cam.into()).normalize_or_zero()
                    } else {
                        Vec3A::ZERO
                    };
                }
            });
    }

    /// The nearest virtual triangle per pixel centre: the triangles are clipped and
    /// projected once, then rasterized in parallel over bands of rows, each band taking
    /// every triangle in index order (so ties resolve as in one sequential pass and the
    /// result does not depend on the thread count).
    fn camera_raster(&mut self, inputs: &ValInputs) {
        let n = inputs.depth.len();
        self.camera_depth.clear();
        self.camera_depth.resize(n, f32::INFINITY);
        self.camera_ids.clear();
        self.camera_ids.resize(n, NO_ID);
        if inputs.objects.is_empty() {
            return;
        }
        let to_camera = inputs.camera_to_world.inverse();
        let c = inputs.camera;
        let project = |p: Vec3| Vec2::new(c.fx * p.x / p.z + c.cx, c.fy * p.y / p.z + c.cy);
        self.screen.clear();
        for (i, tri) in inputs.objects.triangles.iter().enumerate() {
            let view = tri.vertices.map(|v| to_camera.transform_point3(v));
            screen_triangles(&view, CAMERA_NEAR, project, i as u32, |t| {
                self.screen.push(t)
            });
        }
        let (width, height) = (c.width as usize, c.height as usize);
        let band = RASTER_BAND_ROWS * width.max(1);
        let screen = &self.screen;
        self.camera_depth
            .par_chunks_mut(band)
            .zip(self.camera_ids.par_chunks_mut(band))
            .enumerate()
            .for_each(|(b, (depth, ids))| {
                let mut target = DepthTarget {
                    width,
                    height,
                    first_row: b * RASTER_BAND_ROWS,
                    depth,
                    ids: Some(ids),
                };
                for &(tri, id) in screen {
                    raster_screen_triangle(&mut target, tri, id);
                }
            });
    }

    /// Bounding spheres of the real points per TILE x TILE block.
    fn build_tiles(&mut self, w: usize, h: usize) {
        let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let points = &self.real_points;
        self.tiles = (0..tx * ty)
            .into_par_iter()
            .map(|t| {
                let (x0, y0) = ((t % tx) * TILE, (t / tx) * TILE);
                tile_of(points, w, x0, (x0 + TILE).min(w), y0, (y0 + TILE).min(h))
            })
            .collect();
    }
}

/// [`ValRenderer::render`] with fresh buffers (for `relume eval` and one-off use).
pub fn sample_val(
    inputs: &ValInputs,
    params: &ValShadingParams,
) -> Result<IrradianceLayers, StageError> {
    let mut out = val_layers(inputs.depth.width, inputs.depth.height);
    ValRenderer::default().render(inputs, params, &mut out)?;
    Ok(out)
}

struct SampleVal {
    inputs: [String; 4],
    outputs: Vec<String>,
    intrinsics: Intrinsics,
    objects: Arc<VirtualScene>,
    transfer: Option<Arc<Transfer>>,
    params: ValShadingParams,
    renderer: ValRenderer,
}

impl Stage for SampleVal {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let [depth, normals, pose, lights] = &self.inputs;
        let depth = frame.depth(depth)?;
        let normals = frame.normals(normals)?;
        let pose = frame.pose(pose)?;
        let lights = frame.area_lights(lights)?;
        let inputs = ValInputs {
            depth,
            normals,
            camera: Pinhole::new(&self.intrinsics, depth.width, depth.height),
            camera_to_world: Affine3A::from_mat4(pose.matrix().as_mat4()),
            lights,
            objects: &self.objects,
            transfer: self.transfer.as_deref(),
        };
        let mut out = val_layers(depth.width, depth.height);
        self.renderer.render(&inputs, &self.params, &mut out)?;
        out.insert_into(frame, &self.outputs);
        Ok(())
    }
}
