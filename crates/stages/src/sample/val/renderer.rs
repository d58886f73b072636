//! The renderer of `sample.val`: its reusable buffers, a frame's phases (the real
//! points, the camera raster, the tiles), and each light's frustum and shadow maps,
//! built in groups of eight and in turn (`shadow_updates`, paper 004 Sec. 5).

use super::bounce::{BounceLights, object_bounce};
use super::inputs::{ValInputs, ValShadingParams};
use super::pixel;
use super::pixel::{PixelContext, sampling_of};
use super::raster::{DepthTarget, NO_ID, ScreenTriangle, raster_screen_triangle, screen_triangles};
use super::real_splat::{RealSurface, real_shadow_maps};
use super::shade::PreparedLight;
use super::shade::{Biases, Maps, Sh9Irradiance};
use super::shadow::{self, ShadowFrustum};
use super::shadow::{MAX_SHADOW_MAP_SIZE, TILE, Tile, tile_of};
use super::spots::{self, SpotMaps};
use super::targets::light_targets;
use super::virtual_maps::virtual_shadow_maps;
#[cfg(test)]
use super::{real_splat, virtual_maps};
use crate::OpError;
use crate::sample::layers::{IrradianceLayers, shade_rows};
use glam::{Vec2, Vec3, Vec3A};
use rayon::prelude::*;
use relume_base::raster::depth_is_valid;
use relume_base::simd::{Kernel, LANES, Portable};

/// Shades frames with reusable buffers (real points, camera raster, shadow maps).
#[derive(Default)]
pub struct ValRenderer {
    pub(super) real_points: Vec<Vec3A>,
    pub(super) real_normals: Vec<Vec3A>,
    /// Per real point, the world size of the patch it stands for
    /// ([`shadow::PointSampling::footprint`]; computed once, used per light).
    pub(super) real_patches: Vec<f32>,
    pub(super) camera_depth: Vec<f32>,
    pub(super) camera_ids: Vec<u32>,
    /// The virtual triangles clipped and projected into the camera.
    pub(super) screen: Vec<ScreenTriangle>,
    /// Bounding spheres of the real points per tile (row-major tile grid).
    pub(super) tiles: Vec<Option<Tile>>,
    /// Per tile, bit j set when the tile's real points may be inside light j's frustum.
    pub(super) lookup: Vec<u64>,
    pub(super) maps: Vec<f32>,
    /// The frustum each light's maps in `maps` were built with, their size, and the
    /// calls so far (the round robin of `shadow_updates`, see `shadow.rs`).
    pub(super) map_frusta: Vec<Option<shadow::ShadowFrustum>>,
    /// The (position, normal) of the light each map was built for.
    pub(super) map_lights: Vec<(Vec3, Vec3)>,
    pub(super) map_size: usize,
    pub(super) shadow_calls: u64,
    /// The shading and splatting kernel; `None`: the fastest the CPU runs (all give the
    /// same bits).
    pub(super) kernel: Option<Kernel>,
    /// Shade every pixel with the scalar `shade_point`, and splat the real shadow maps
    /// one light and one point at a time, instead (the kernels' reference).
    /// The spot lights' frusta and maps (`spots.rs`).
    pub(super) spot_maps: SpotMaps,
    #[cfg(test)]
    pub(super) scalar_reference: bool,
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
    ) -> Result<(), OpError> {
        let (w, h) = (inputs.depth.width, inputs.depth.height);
        if !inputs.depth.same_size(inputs.normals) || out.size() != Some((w, h)) {
            return Err(OpError::SizeMismatch(format!(
                "sample.val: depth is {w}x{h}, normals {}x{}, outputs {}x{}",
                inputs.normals.width, inputs.normals.height, out.mask.width, out.mask.height
            )));
        }
        if (inputs.camera.width, inputs.camera.height) != (w, h) {
            return Err(OpError::SizeMismatch(format!(
                "sample.val: the camera is {}x{} but the depth map {w}x{h}",
                inputs.camera.width, inputs.camera.height
            )));
        }
        if !(1..=MAX_SHADOW_MAP_SIZE).contains(&params.shadow_map_size) {
            return Err(OpError::BadParameter(format!(
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
        let surface = RealSurface {
            points: &self.real_points,
            patches: &self.real_patches,
            width: wu,
            tiles: &self.tiles,
        };
        if !inputs.spots.is_empty() {
            let map_kernel = self.kernel.unwrap_or_else(Kernel::detect);
            self.spot_maps.build(inputs, params, &surface, map_kernel);
        }
        let bounce = match inputs.transfer {
            Some(transfer) if params.object_bounce => {
                let light = BounceLights {
                    lights: &lights,
                    maps,
                    biases,
                    spot_maps: (!inputs.spots.is_empty()).then_some(&self.spot_maps),
                    sampling: sampling_of(inputs),
                };
                object_bounce(inputs, transfer, &light)
            }
            _ => Vec::new(),
        };
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
            object_bounce: &bounce,
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
        if !inputs.spots.is_empty() {
            let sampling = sampling_of(inputs);
            let real = (
                &self.real_points[..],
                &self.real_normals[..],
                &self.real_patches[..],
            );
            let patch_of = |p: Vec3| sampling.footprint(p.into());
            spots::add_spots(inputs, &self.spot_maps, real, patch_of, biases, out);
        }
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

impl ValRenderer {
    /// Fits each light's frustum and builds its two shadow maps (in groups of up to
    /// eight lights, the groups in parallel); returns the lights prepared for shading.
    ///
    /// With `shadow_updates` = u between 1 and the number of lights M, only u lights'
    /// maps are built per call, in turn (paper 004 Sec. 5's round robin: call c builds
    /// lights (c u + i) mod M, i < u), and those of every light that moved (position
    /// or normal not bit for bit the one its maps were built for): the maps of the
    /// others hold their objects' shadows still, and only their real occluders come
    /// from an earlier frame's points (a static scene seen from elsewhere). Where
    /// nothing was built before, or M or the map size changed, every map is built.
    pub(super) fn shadow_maps(
        &mut self,
        inputs: &ValInputs,
        params: &ValShadingParams,
    ) -> Vec<PreparedLight> {
        let size = params.shadow_map_size;
        let bounds = inputs.objects.bounds();
        let fitted: Vec<Option<ShadowFrustum>> = inputs
            .lights
            .lights
            .iter()
            .map(|l| {
                if inputs.objects.is_empty() {
                    return None;
                }
                ShadowFrustum::fit(
                    l.position,
                    l.normal,
                    &bounds,
                    size,
                    params.real_occluder_reach,
                )
            })
            .collect();
        let m = fitted.len();
        let updates = params.shadow_updates;
        let round_robin =
            (1..m).contains(&updates) && self.map_frusta.len() == m && self.map_size == size;
        let start = (self.shadow_calls as usize).wrapping_mul(updates) % m.max(1);
        let placed = |l: &relume_scene::light::AreaLight| (l.position, l.normal);
        let rebuilt: Vec<bool> = (0..m)
            .map(|j| {
                let moved = self.map_lights.get(j) != Some(&placed(&inputs.lights.lights[j]));
                !round_robin || moved || (j + m - start) % m < updates
            })
            .collect();
        self.shadow_calls = self.shadow_calls.wrapping_add(1);
        let frusta: Vec<Option<ShadowFrustum>> = (0..m)
            .map(|j| {
                if rebuilt[j] {
                    fitted[j]
                } else {
                    self.map_frusta[j]
                }
            })
            .collect();
        let stride = 3 * size * size;
        self.maps.resize(stride * m, f32::INFINITY);
        let surface = RealSurface {
            points: &self.real_points,
            patches: &self.real_patches,
            width: inputs.depth.width as usize,
            tiles: &self.tiles,
        };
        let kernel = self.kernel.unwrap_or_else(Kernel::detect);
        // The maps to build and their frusta.
        let mut targets: Vec<(&mut [f32], &ShadowFrustum)> = self
            .maps
            .chunks_mut(stride)
            .zip(&frusta)
            .zip(&rebuilt)
            .filter(|(_, rebuilt)| **rebuilt)
            .filter_map(|((maps, frustum), _)| Some((maps, frustum.as_ref()?)))
            .collect();
        #[cfg(test)]
        if self.scalar_reference {
            targets.par_iter_mut().for_each(|(maps, frustum)| {
                let (virtual_target, mut real_target) = light_targets(frustum, maps);
                let objects = inputs.objects;
                virtual_maps::virtual_shadow_map_reference(frustum, objects, virtual_target.map);
                real_splat::real_shadow_map_reference(&mut real_target, &surface);
            });
            targets.clear();
        }
        // Up to eight lights per pass over the triangles and the points, in as many
        // passes as there are threads where the lights allow (the maps do not depend on
        // the grouping).
        let group = targets
            .len()
            .div_ceil(rayon::current_num_threads())
            .clamp(1, LANES);
        targets.par_chunks_mut(group).for_each(|chunk| {
            let (mut virtual_targets, mut real_targets): (Vec<_>, Vec<_>) = chunk
                .iter_mut()
                .map(|(maps, frustum)| light_targets(frustum, maps))
                .unzip();
            virtual_shadow_maps(kernel, &mut virtual_targets, inputs.objects);
            real_shadow_maps(kernel, &mut real_targets, &surface);
        });
        self.map_frusta = frusta.clone();
        self.map_lights = inputs.lights.lights.iter().map(placed).collect();
        self.map_size = size;
        self.prepare_lights(inputs, &frusta)
    }

    /// Which tiles need which lights' shadow maps ([`ValRenderer::lookup`]), and the
    /// lights prepared for shading.
    fn prepare_lights(
        &mut self,
        inputs: &ValInputs,
        frusta: &[Option<ShadowFrustum>],
    ) -> Vec<PreparedLight> {
        // Which tiles need shadow-map lookups for which lights.
        self.lookup = self
            .tiles
            .par_iter()
            .map(|tile| {
                let Some(tile) = tile else { return 0 };
                let mut mask = 0u64;
                for (j, f) in frusta.iter().enumerate().take(64) {
                    if f.is_some_and(|f| f.may_hold(tile.centre, tile.radius, 0.0)) {
                        mask |= 1 << j;
                    }
                }
                mask
            })
            .collect();
        inputs
            .lights
            .lights
            .iter()
            .zip(frusta)
            .map(|(l, f)| PreparedLight::new(l, *f))
            .collect()
    }
}
