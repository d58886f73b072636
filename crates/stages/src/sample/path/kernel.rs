//! The per-pixel estimator of `sample.path` (paper 001 Sec. 5, two-mode sampling; paper
//! 000 Sec. 7 for the object-aware differential), whole: from what a span drew at a
//! pixel (`records.rs`) and its rays' answers, the estimates at the real point, at the
//! virtual primaries' hits, the objects' outgoing radiance along a ray, and the
//! object-aware differentials. See the module docs of [`super`] for what each estimate
//! means; `span.rs` draws the samples and traces their rays, `rays.rs` answers them.
//!
//! **Object-aware sampling** (paper 000 Sec. 7: eq. 9 and the scaled estimator after
//! it): at a real point, E_RV = E_R plus a differential estimated only from the
//! directions that may meet the objects. Of N candidate directions, those meeting the
//! objects' bounding box form H; at most `cache_size` of them (H_a, a uniform random
//! subset chosen by reservoir sampling, [`Reservoir`]) are traced, and their sum of
//! L_RV - L_R is scaled by (1 + |H_b| / |H_a|) / N = |H| / (|H_a| N). The estimate is
//! unbiased, and where no traced direction meets an object there is no differential:
//! E_RV == E_R bit for bit.
//! - **Indirect** ([`Kernel::object_aware`]): N cosine directions; a direction meeting
//!   an object before the real scene brings the object's outgoing radiance instead of
//!   the real surface's.
//! - **Direct** ([`Kernel::object_aware_direct`]): N samples of the light table, drawn
//!   in N equal strata of it like the direct samples; one that an object blocks before
//!   the real scene does loses its light, L cos / pdf. The correlated direct samples
//!   then leave E_RV^dir unblocked (they estimate E_R^dir), and the differential
//!   carries the shadow, with many more directions tested against the box than the
//!   pixel's direct samples. E_RV^dir is clamped at 0 per channel where the
//!   differential exceeds the pixel's E_R^dir estimate (a noisy E_R and a large
//!   blocked sum), which biases deep shadows slightly bright instead of showing
//!   negative light.

use super::bounds::{Cone, Objects, object_pixel_bounds};
use super::object_aware::Reservoir;
use super::params::MAX_CANDIDATES;
use super::parts::{PartClock, PartTicks, since};
use super::rays::{FrameQuery, WorldQuery};
use super::records::{
    Acc, DirectRay, Drawn, IndirectRay, RealPoint, RealSamples, SURFACE_OFFSET, Surface,
    VirtualDirect, VirtualIndirect,
};
use super::sampling::{
    Basis, PixelRng, Stream, StreamId, below, cosine_hemisphere, phong_weight, strata_bounds,
    stratum_index,
};
use super::{PathInputs, PathParams};
use crate::sample::layers::PixelLayers;
use crate::sample::query::{Hit, Source, cone_spread};
use crate::sample::ssrt::ScreenTracer;
use glam::{Mat3A, Vec3, Vec3A};
use relume_base::raster::depth_is_valid;
use relume_base::{simd, ticks};
use relume_scene::light::LightSample;
use relume_scene::light::voxels::{ConeMarch, VoxelVolume};
use relume_scene::objects::VirtualHit;
use std::f32::consts::{FRAC_1_PI, PI};

/// Object visibility by voxels: how many of the object volume's voxels a cone leaving a
/// virtual surface starts off it (the solid voxelization puts the surface up to a voxel
/// from where it is, and trilinear sampling reaches a voxel further).
pub(super) const LEAVE_VOXELS: f32 = 1.5;
/// Everything constant over a frame.
pub(super) struct Kernel<'a> {
    pub(super) inputs: &'a PathInputs<'a>,
    pub(super) params: &'a PathParams,
    /// How rays meet the real scene (the stage's radiance query).
    pub(super) query: FrameQuery<'a>,
    /// With object visibility by voxels: the objects' solid volume, whose cones give
    /// their shadows.
    pub(super) object_volume: Option<&'a VoxelVolume>,
    pub(super) to_world: Mat3A,
    pub(super) to_camera: Mat3A,
    pub(super) camera_position: Vec3,
    pub(super) objects: Option<Objects<'a>>,
    /// The objects' cone from the camera.
    pub(super) camera_cone: Cone,
    /// Pixel bounds [x0, y0, x1, y1] (inclusive) outside which no primary ray can meet
    /// the objects.
    pub(super) object_pixels: [i64; 4],
    /// The table's strata of a pixel's direct samples: `primary` x `direct` of them,
    /// and `near_primary` x `direct` for the pixels near the objects.
    pub(super) strata: Vec<u32>,
    pub(super) near_strata: Vec<u32>,
    /// The same for the samples of primaries that meet an object: `primary` x
    /// `object_direct` (the same as above when `object_direct` is `direct`).
    pub(super) object_strata: Vec<u32>,
    pub(super) near_object_strata: Vec<u32>,
    /// The table's strata for the object-aware direct candidates.
    pub(super) candidate_strata: Vec<u32>,
    /// The aperture of the cones of an object's own direct samples (`primary` x
    /// `object_direct` of them share the hemisphere; the room's is the query's
    /// `direct_spread`).
    pub(super) object_direct_spread: f32,
    /// Blocked direct samples dimmer than this (largest channel of the sample's
    /// radiance) do not count towards `direct_min_distance`.
    pub(super) occluder_min_radiance: f32,
    /// How the screen-space rays are marched (the same hits with any).
    pub(super) lanes: simd::Kernel,
    /// The spans' clock ticks by part (see `parts.rs`).
    pub(super) parts: PartClock,
}

impl<'a> Kernel<'a> {
    pub(super) fn new(
        inputs: &'a PathInputs<'a>,
        params: &'a PathParams,
        tracer: ScreenTracer<'a>,
        (world_query, real_query): (Option<WorldQuery<'a>>, Option<WorldQuery<'a>>),
        object_volume: Option<&'a VoxelVolume>,
        lanes: simd::Kernel,
    ) -> Self {
        let c2w = inputs.camera_to_world;
        let to_world = c2w.matrix3;
        let to_camera = to_world.transpose();
        let camera_position = Vec3::from(c2w.translation);
        let objects = (!inputs.objects.is_empty()).then(|| {
            let aabb = inputs.objects.bounds();
            let half = (aabb.max - aabb.min) * 0.5;
            let radius = half.length() * 1.001 + 1e-4;
            Objects {
                scene: inputs.objects,
                aabb,
                center: aabb.center(),
                radius2: radius * radius,
            }
        });
        let camera_cone = objects
            .as_ref()
            .map_or(Cone::ALL, |o| o.cone(camera_position));
        let object_pixels = objects
            .as_ref()
            .map_or([0, 0, -1, -1], |o| object_pixel_bounds(inputs, &o.aabb));
        Kernel {
            inputs,
            params,
            query: FrameQuery::new(
                tracer,
                world_query,
                real_query,
                inputs.radiance,
                params.max_distance,
                inputs.table,
                to_world,
                cone_spread(params.primary * params.direct, 0.0),
                cone_spread(params.primary * params.indirect, 0.0),
            ),
            object_volume,
            to_world,
            to_camera,
            camera_position,
            objects,
            camera_cone,
            object_pixels,
            strata: strata_bounds(params.primary * params.direct, inputs.table.samples.len()),
            near_strata: strata_bounds(
                params.near_primaries() * params.direct,
                inputs.table.samples.len(),
            ),
            object_strata: strata_bounds(
                params.primary * params.object_directs(),
                inputs.table.samples.len(),
            ),
            near_object_strata: strata_bounds(
                params.near_primaries() * params.object_directs(),
                inputs.table.samples.len(),
            ),
            candidate_strata: strata_bounds(params.candidates, inputs.table.samples.len()),
            object_direct_spread: cone_spread(params.primary * params.object_directs(), 0.0),
            occluder_min_radiance: params.occluder_threshold
                * inputs
                    .table
                    .samples
                    .iter()
                    .map(|s| s.radiance.max_element())
                    .fold(0.0, f32::max),
            lanes,
            parts: PartClock::default(),
        }
    }

    /// Object visibility by voxels: the cone of a direct sample's aperture (`spread`)
    /// from `origin` along `dir` through the objects' solid volume, up to `t_max`: its
    /// opacity is the share of the light the objects block (paper 000 eq. 6's
    /// 1 - alpha).
    #[inline]
    pub(super) fn object_cone(
        &self,
        volume: &VoxelVolume,
        (origin, dir, spread): (Vec3, Vec3, f32),
        t_max: f32,
    ) -> ConeMarch {
        volume.march(origin, dir, spread, 0.0, t_max)
    }

    /// Object visibility by voxels: [`Kernel::object_cone`] of aperture `spread`
    /// leaving a virtual surface at `position` with normal `normal`: it starts
    /// [`LEAVE_VOXELS`] of the volume's voxels off the surface, out of the voxels that
    /// hold the surface itself.
    #[inline]
    pub(super) fn object_shadow(
        &self,
        volume: &VoxelVolume,
        (position, normal): (Vec3, Vec3),
        dir: Vec3,
        spread: f32,
    ) -> ConeMarch {
        let origin = position + normal * (LEAVE_VOXELS * volume.voxel_size);
        self.object_cone(volume, (origin, dir, spread), f32::INFINITY)
    }

    /// Records a blocked direct sample for the filter: its occluder at distance `t`
    /// along a direction at `cos` to the normal stands at depth z = t cos above the
    /// receiver (paper 001 Fig. 3c), so the cos^2(theta_occ) / z of eq. 17 is
    /// 1 / (t / cos); the smallest t / cos is kept. Samples too dim to matter are
    /// skipped (paper 001 Sec. 7).
    #[inline]
    pub(super) fn record_occluder(&self, acc: &mut Acc, radiance: Vec3, t: f32, cos: f32) {
        if radiance.max_element() >= self.occluder_min_radiance {
            acc.direct_min = acc.direct_min.min(t / cos);
        }
    }

    /// All estimates of pixel (x, y) from what was drawn there (see [`Drawn`]), with
    /// all its rays answered in `hits` (see `span.rs`).
    pub(super) fn shade_pixel(
        &self,
        x: u32,
        y: u32,
        drawn: &Drawn,
        hits: &[Option<Hit>],
        parts: &mut PartTicks,
    ) -> PixelLayers {
        let Drawn {
            real,
            real_samples: samples,
            primaries,
            virtual_samples,
        } = drawn;
        let real = *real;
        let inputs = self.inputs;
        let params = self.params;
        let p = y as usize * inputs.depth.width as usize + x as usize;
        let rng = PixelRng::new(params.seed, inputs.frame, p as u64);
        let mut acc = Acc {
            r_dir: Vec3::ZERO,
            r_ind: Vec3::ZERO,
            rv_dir: Vec3::ZERO,
            rv_ind: Vec3::ZERO,
            rv_dir_n: 0,
            rv_ind_n: 0,
            rv_ind_real_n: 0,
            rv_dir_real_n: 0,
            direct_min: f32::INFINITY,
            indirect_min: f32::INFINITY,
            touched: false,
            bounces: 0,
            ticks: PartTicks::default(),
        };
        let (mut virtual_count, mut albedo, mut exponent) = (0u32, Vec3::ZERO, 0.0f32);
        let (mut surfaces, mut position, mut normal) = (0u32, Vec3::ZERO, Vec3::ZERO);
        let bounce_stream = rng.stream(StreamId::Bounce);
        let real_samples = |j: u32, with_rv: bool, acc: &mut Acc| {
            if let Some(rp) = real {
                self.real_samples(rp, samples, hits, j, &bounce_stream, with_rv, acc);
            }
        };
        let (direct_n, indirect_n) = (
            params.object_directs() as usize,
            params.object_indirects() as usize,
        );
        let (mut virtual_direct, mut virtual_indirect) =
            (virtual_samples.direct, virtual_samples.indirect);
        let primary = primaries.len() as u32;
        for (j, virtual_hit) in (0..primary).zip(primaries.iter()) {
            match virtual_hit {
                None => {
                    if let Some(rp) = real {
                        surfaces += 1;
                        position += rp.surface;
                        normal += rp.normal_world;
                    }
                    real_samples(j, true, &mut acc);
                }
                Some((hit, view)) => {
                    virtual_count += 1;
                    albedo += hit.material.albedo;
                    exponent += hit.material.exponent;
                    surfaces += 1;
                    position += hit.position;
                    normal += hit.normal;
                    acc.touched = true;
                    real_samples(j, false, &mut acc);
                    let (direct, rest) = virtual_direct.split_at(direct_n);
                    let (indirect, rest_indirect) = virtual_indirect.split_at(indirect_n);
                    (virtual_direct, virtual_indirect) = (rest, rest_indirect);
                    let start = ticks::now();
                    self.virtual_samples(
                        hit,
                        -*view,
                        direct,
                        indirect,
                        hits,
                        &bounce_stream,
                        &mut acc,
                    );
                    acc.ticks.object += since(start);
                }
            }
        }
        let differential_start = ticks::now();
        let mut direct_differential = Vec3::ZERO;
        if params.object_aware_direct
            && acc.rv_dir_real_n > 0
            && let (Some(rp), Some(objects)) = (real, &self.objects)
            && let Some(d) = self.object_aware_direct(rp, objects, &rng, &mut acc)
        {
            direct_differential = d;
            acc.touched = true;
        }
        let mut differential = Vec3::ZERO;
        if params.object_aware
            && acc.rv_ind_real_n > 0
            && let (Some(rp), Some(objects)) = (real, &self.objects)
            && let Some(d) = self.object_aware(rp, objects, &rng, &bounce_stream, &mut acc)
        {
            differential = d;
            acc.touched = true;
        }
        if self.objects.is_some() && (params.object_aware || params.object_aware_direct) {
            acc.ticks.differential += since(differential_start);
        }
        *parts = PartTicks {
            object: parts.object + acc.ticks.object,
            differential: parts.differential + acc.ticks.differential,
        };
        let nan = Vec3::NAN;
        let (dir_n, ind_n) = (primary * params.direct, primary * params.indirect);
        let (e_r_dir, e_r_ind) = if real.is_some() {
            (mean(acc.r_dir, dir_n, 1.0), mean(acc.r_ind, ind_n, PI))
        } else {
            (nan, nan)
        };
        let any_surface = surfaces > 0;
        let mut e_rv_dir = if any_surface {
            mean(acc.rv_dir, acc.rv_dir_n, 1.0)
        } else {
            nan
        };
        if acc.touched && direct_differential != Vec3::ZERO {
            let share = acc.rv_dir_real_n as f32 / acc.rv_dir_n as f32;
            e_rv_dir = (e_rv_dir + direct_differential * share).max(Vec3::ZERO);
        }
        let mut e_rv_ind = if any_surface {
            mean(acc.rv_ind, acc.rv_ind_n, PI)
        } else {
            nan
        };
        if acc.touched && differential != Vec3::ZERO {
            e_rv_ind += differential * (acc.rv_ind_real_n as f32 / acc.rv_ind_n as f32);
        }
        PixelLayers {
            e_r_dir,
            e_r_ind,
            e_rv_dir,
            e_rv_ind,
            mask: 1.0 - virtual_count as f32 / primary as f32,
            k_v: if virtual_count > 0 {
                albedo / virtual_count as f32
            } else {
                Vec3::ZERO
            },
            exponent: if virtual_count > 0 {
                exponent / virtual_count as f32
            } else {
                0.0
            },
            world_position: if any_surface {
                position / surfaces as f32
            } else {
                nan
            },
            world_normal: normal.normalize_or_zero(),
            direct_min_distance: acc.direct_min,
            indirect_min_distance: acc.indirect_min,
            touched: acc.touched,
        }
    }

    /// The pixel's depth-map point and normal, when both are valid.
    pub(super) fn real_point(
        &self,
        x: u32,
        y: u32,
        z: f32,
        normal_camera: Vec3,
    ) -> Option<RealPoint> {
        if !depth_is_valid(z) || !normal_camera.is_finite() || normal_camera == Vec3::ZERO {
            return None;
        }
        let normal_camera = normal_camera.normalize();
        let cam = &self.inputs.camera;
        let surface = cam.back_project(x as f32, y as f32, z);
        // Raised by `normal_offset` pixel footprints: a ray grazing the surface then
        // stays in front of the depth map's pixel centres.
        let raise = z / cam.fx.max(cam.fy) * self.params.normal_offset;
        let camera = surface + normal_camera * raise;
        let world = self.inputs.camera_to_world.transform_point3(camera);
        let surface = self.inputs.camera_to_world.transform_point3(surface);
        let normal_world = Vec3::from(self.to_world * Vec3A::from(normal_camera));
        let query_origin = match &self.query.world_query {
            // Cones leave the surface's own voxel (raised a voxel along the normal,
            // as voxel cone tracers do).
            Some(WorldQuery::Voxels(q)) => world + normal_world * q.volume.voxel_size,
            _ => world,
        };
        let (cone_world, cone_camera) = match &self.objects {
            Some(o) => {
                let c = o.cone(world);
                let axis = Vec3::from(self.to_camera * Vec3A::from(c.axis));
                (c, Cone { axis, ..c })
            }
            None => (Cone::ALL, Cone::ALL),
        };
        Some(RealPoint {
            world,
            query_origin,
            origin: self.query.tracer.origin(camera),
            surface,
            normal_world,
            basis_camera: Basis::new(normal_camera),
            cone_world,
            cone_camera,
        })
    }

    /// The virtual hit of primary ray j (jittered inside the pixel) when it is nearer
    /// than the pixel's real surface, with the ray's world direction.
    pub(super) fn primary_hit(
        &self,
        stream: &Stream,
        j: u32,
        x: u32,
        y: u32,
        z: f32,
    ) -> Option<(VirtualHit, Vec3)> {
        let objects = self.objects.as_ref()?;
        let (ju, jv) = stream.pair(j as u64);
        let ray = self
            .inputs
            .camera
            .ray(x as f32 + ju - 0.5, y as f32 + jv - 0.5);
        let length = ray.length();
        let dir = Vec3::from(self.to_world * Vec3A::from(ray / length));
        if !self.camera_cone.admits(dir) {
            return None;
        }
        let t_real = if depth_is_valid(z) {
            z * length
        } else {
            f32::INFINITY
        };
        objects
            .hit(self.camera_position, dir, t_real)
            .map(|h| (h, dir))
    }

    /// The primary samples of pixel (x, y) with real point `real`: `near_primary`
    /// where a primary may meet an object or the real point lies within
    /// `near_distance` of the objects' box, else `primary`.
    #[inline]
    pub(super) fn primaries_at(&self, x: u32, y: u32, real: Option<&RealPoint>) -> u32 {
        let params = self.params;
        let near = params.near_primaries();
        if near == params.primary {
            return near;
        }
        let Some(objects) = &self.objects else {
            return params.primary;
        };
        let [x0, y0, x1, y1] = self.object_pixels;
        let sees_objects = (x0..=x1).contains(&(x as i64)) && (y0..=y1).contains(&(y as i64));
        let beside_objects = real.is_some_and(|rp| {
            let gap = (objects.aabb.min - rp.surface).max(rp.surface - objects.aabb.max);
            gap.max(Vec3::ZERO).length() <= params.near_distance
        });
        if sees_objects || beside_objects {
            near
        } else {
            params.primary
        }
    }

    /// The table's strata of the direct samples of a real point whose pixel has
    /// `primary` primary samples.
    #[inline]
    pub(super) fn real_strata(&self, primary: u32) -> &[u32] {
        if primary == self.params.primary {
            &self.strata
        } else {
            &self.near_strata
        }
    }

    /// The table's strata of the direct samples of the virtual hits of a pixel with
    /// `primary` primary samples.
    #[inline]
    pub(super) fn object_strata(&self, primary: u32) -> &[u32] {
        if primary == self.params.primary {
            &self.object_strata
        } else {
            &self.near_object_strata
        }
    }

    /// The table sample of direct sample `s` drawn from `strata` ([`Self::real_strata`]
    /// or [`Self::object_strata`]), with its index, if the table has any.
    #[inline]
    pub(super) fn direct_sample(
        &self,
        stream: &Stream,
        s: u32,
        strata: &[u32],
    ) -> Option<(usize, &'a LightSample)> {
        let table = &self.inputs.table.samples;
        let i = stratum_index(strata, s as usize, table.len(), stream.bits(s as u64))?;
        Some((i, &table[i]))
    }

    /// Direct and indirect samples of primary j at the real point, drawn in `samples`
    /// with their rays' `hits`: always for E_R, and for E_RV too when `with_rv` (a real
    /// primary), with the same random numbers and paths, adding the virtual objects'
    /// blocking and reflection.
    #[allow(clippy::too_many_arguments)]
    fn real_samples(
        &self,
        rp: &RealPoint,
        samples: &RealSamples,
        hits: &[Option<Hit>],
        j: u32,
        bounce_stream: &Stream,
        with_rv: bool,
        acc: &mut Acc,
    ) {
        let params = self.params;
        // The objects E_RV sees from here with the correlated samples (direct ones:
        // unless the object-aware differential stands for them).
        let rv_objects = if with_rv { self.objects.as_ref() } else { None };
        let rv_blockers = rv_objects.filter(|_| !params.object_aware_direct);
        for k in 0..params.direct {
            let s = (j * params.direct + k) as usize;
            let mut c = Vec3::ZERO;
            let mut c_rv = Vec3::ZERO;
            if let Some(DirectRay { sample, cos, ray }) = samples.direct[s] {
                let ls = &self.inputs.table.samples[sample];
                match hits[ray] {
                    Some(Hit {
                        source: Source::Surface,
                        t,
                        ..
                    }) => self.record_occluder(acc, ls.radiance, t, cos),
                    arrival => {
                        // The environment: at infinity with the table's radiance, or
                        // where the impostor query met it (an object beyond it is
                        // hidden: paper 000 Sec. 6.4, ray 3).
                        let (radiance, t_light) =
                            arrival.map_or((ls.radiance, f32::INFINITY), |h| (h.radiance, h.t));
                        c = radiance * (cos / ls.pdf);
                        c_rv = c;
                        match (rv_blockers, self.object_volume) {
                            (Some(_), Some(volume)) if rp.cone_world.admits(ls.direction) => {
                                let start = ticks::now();
                                let ray = (rp.world, ls.direction, self.query.direct_spread);
                                let cone = self.object_cone(volume, ray, t_light);
                                if cone.opacity > 0.0 {
                                    c_rv = c * (1.0 - cone.opacity);
                                    acc.touched = true;
                                    self.record_occluder(acc, ls.radiance, cone.t_half, cos);
                                }
                                acc.ticks.differential += since(start);
                            }
                            (Some(o), None) if rp.cone_world.admits(ls.direction) => {
                                let start = ticks::now();
                                if let Some(hit) = o.hit(rp.world, ls.direction, t_light) {
                                    c_rv = Vec3::ZERO;
                                    acc.touched = true;
                                    self.record_occluder(acc, ls.radiance, hit.t, cos);
                                }
                                acc.ticks.differential += since(start);
                            }
                            _ => {}
                        }
                    }
                }
            }
            acc.r_dir += c;
            if with_rv {
                acc.rv_dir += c_rv;
            }
        }
        if with_rv {
            acc.rv_dir_n += params.direct;
            acc.rv_ind_n += params.indirect;
            acc.rv_ind_real_n += params.indirect;
            acc.rv_dir_real_n += params.direct;
        }
        for k in 0..params.indirect {
            let s = (j * params.indirect + k) as usize;
            let IndirectRay { dir_camera, ray } = samples.indirect[s];
            let (l, t_real) = match hits[ray] {
                Some(Hit {
                    source: Source::Surface,
                    t,
                    radiance,
                }) => {
                    acc.indirect_min = acc.indirect_min.min(t);
                    (radiance, t)
                }
                // The environment is counted by direct light; an object nearer than
                // it still reflects.
                Some(hit) => (Vec3::ZERO, hit.t),
                None => (Vec3::ZERO, f32::INFINITY),
            };
            acc.r_ind += l;
            if with_rv {
                let mut l_rv = l;
                // With object-aware sampling the candidates stand for these paths.
                if let Some(o) = rv_objects
                    && !params.object_aware
                    && rp.cone_camera.admits(dir_camera)
                {
                    let start = ticks::now();
                    let dir = Vec3::from(self.to_world * Vec3A::from(dir_camera));
                    let reflector = o.hit(rp.world, dir, t_real).filter(|hit| {
                        !self.query.impostor_bounds_reflectors()
                            || self.query.before_impostor(o, rp, dir, dir_camera, hit.t)
                    });
                    if let Some(hit) = reflector {
                        l_rv = self.object_radiance(&hit, bounce_stream, acc);
                        acc.touched = true;
                        acc.indirect_min = acc.indirect_min.min(hit.t);
                    }
                    acc.ticks.differential += since(start);
                }
                acc.rv_ind += l_rv;
            }
        }
    }

    /// The E_RV samples of a virtual primary's hit seen from direction `to_viewer`,
    /// from its `direct` and `indirect` samples drawn by
    /// `Span::draw_virtual_samples` (`span.rs`) and their rays' `hits`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn virtual_samples(
        &self,
        hit: &VirtualHit,
        to_viewer: Vec3,
        direct: &[VirtualDirect],
        indirect: &[VirtualIndirect],
        hits: &[Option<Hit>],
        bounce_stream: &Stream,
        acc: &mut Acc,
    ) {
        let surface = Surface::new(hit, to_viewer);
        let table = &self.inputs.table.samples;
        // The primary weighs in the pixel's means as a real primary does: its samples
        // count `direct` (`indirect`) however many there are (a weight of exactly 1
        // when there are as many).
        let (direct_weight, direct_count) = primary_share(direct.len(), self.params.direct);
        let (indirect_weight, indirect_count) = primary_share(indirect.len(), self.params.indirect);
        for drawn in direct {
            let mut c = Vec3::ZERO;
            match *drawn {
                VirtualDirect::Unlit => {}
                VirtualDirect::Blocked { sample, cos, t } => {
                    self.record_occluder(acc, table[sample].radiance, t, cos);
                }
                VirtualDirect::Open {
                    sample,
                    cos,
                    ray,
                    visible,
                } => {
                    let ls = &table[sample];
                    match hits[ray] {
                        Some(Hit {
                            source: Source::Surface,
                            t,
                            ..
                        }) => self.record_occluder(acc, ls.radiance, t, cos),
                        arrival => {
                            let radiance = arrival.map_or(ls.radiance, |h| h.radiance);
                            let lobe = if surface.glossy {
                                phong_weight(
                                    surface.mirror.dot(ls.direction),
                                    hit.material.exponent,
                                )
                            } else {
                                1.0
                            };
                            c = radiance * (cos / ls.pdf * lobe * visible);
                        }
                    }
                }
            }
            acc.rv_dir += c * direct_weight;
        }
        acc.rv_dir_n += direct_count;
        for sample in indirect {
            if let Some(ray) = sample.ray {
                let l = self.incoming(surface.origin, sample.dir, hits[ray], bounce_stream, acc);
                acc.rv_ind += l * (sample.weight * indirect_weight);
            }
        }
        acc.rv_ind_n += indirect_count;
    }

    /// Radiance arriving at a virtual surface from `dir`: the nearer of the object
    /// (its outgoing radiance; not tested when `visibility` is off) and the real
    /// surface `real` that the query met (its camera radiance); 0 when the ray reaches
    /// the environment (it is counted by direct light).
    pub(super) fn incoming(
        &self,
        origin: Vec3,
        dir: Vec3,
        real: Option<Hit>,
        bounce_stream: &Stream,
        acc: &mut Acc,
    ) -> Vec3 {
        let Some(objects) = self.objects.as_ref() else {
            return Vec3::ZERO;
        };
        let t_real = real.map_or(f32::INFINITY, |h| h.t);
        if self.params.visibility
            && let Some(hit) = objects.hit(origin, dir, t_real)
        {
            acc.indirect_min = acc.indirect_min.min(hit.t);
            return match self.params.self_bounce {
                true => self.object_radiance(&hit, bounce_stream, acc),
                false => Vec3::ZERO,
            };
        }
        match real {
            Some(Hit {
                source: Source::Surface,
                t,
                radiance,
            }) => {
                acc.indirect_min = acc.indirect_min.min(t);
                radiance
            }
            _ => Vec3::ZERO,
        }
    }

    /// The outgoing radiance of a virtual surface towards the ray that hit it:
    /// (k_V / pi) E^dir from one importance sample of the table, with virtual
    /// (self-shadowing, when `visibility` is on) and real visibility, and the radiance
    /// the query brings along the sample's direction. Glossy surfaces are treated as
    /// diffuse for this bounce (as paper 000 Sec. 6.4 does); no further bounce.
    pub(super) fn object_radiance(
        &self,
        hit: &VirtualHit,
        bounce_stream: &Stream,
        acc: &mut Acc,
    ) -> Vec3 {
        let table = &self.inputs.table.samples;
        if table.is_empty() {
            return Vec3::ZERO;
        }
        let h = bounce_stream.bits(acc.bounces);
        acc.bounces += 1;
        let ls = &table[below(h, table.len() as u32) as usize];
        let cos = hit.normal.dot(ls.direction);
        if !(cos > 0.0 && ls.pdf > 0.0) {
            return Vec3::ZERO;
        }
        let origin = hit.position + hit.normal * SURFACE_OFFSET;
        let mut visible = 1.0;
        if self.params.visibility
            && let Some(objects) = &self.objects
        {
            match self.object_volume {
                Some(volume) => {
                    let surface = (hit.position, hit.normal);
                    let spread = self.query.direct_spread;
                    visible -= self
                        .object_shadow(volume, surface, ls.direction, spread)
                        .opacity;
                }
                None if objects.hit(origin, ls.direction, f32::INFINITY).is_some() => {
                    return Vec3::ZERO;
                }
                None => {}
            }
        }
        let radiance = match self.query.answer_from(origin, ls.direction) {
            Some(Hit {
                source: Source::Surface,
                ..
            }) => return Vec3::ZERO,
            Some(h) => h.radiance,
            None => ls.radiance,
        };
        hit.material.albedo * FRAC_1_PI * radiance * (cos / ls.pdf * visible)
    }

    /// The differential indirect irradiance E_RV - E_R at the real point (see the
    /// module docs). `None` when no traced direction meets an object.
    pub(super) fn object_aware(
        &self,
        rp: &RealPoint,
        objects: &Objects,
        rng: &PixelRng,
        bounce_stream: &Stream,
        acc: &mut Acc,
    ) -> Option<Vec3> {
        let params = self.params;
        let n = (params.candidates as usize).min(MAX_CANDIDATES);
        // No cosine direction can meet the sphere when its cone lies below the horizon.
        let cone = rp.cone_camera;
        let sin_half = (1.0 - cone.cos_half * cone.cos_half).max(0.0).sqrt();
        if cone.cos_half > -1.0 && cone.axis.dot(rp.basis_camera.n) < -sin_half - 1e-5 {
            return None;
        }
        let candidates = rng.stream(StreamId::Candidate);
        let choices = rng.stream(StreamId::Reservoir);
        let direction = |i: usize| {
            let (u1, u2) = candidates.pair(i as u64);
            rp.basis_camera.to_world(cosine_hemisphere(u1, u2))
        };
        let mut reservoir = Reservoir::new(params.cache_size as usize, &choices);
        for i in 0..n {
            let dir_camera = direction(i);
            if !cone.admits(dir_camera) {
                continue;
            }
            let dir = Vec3::from(self.to_world * Vec3A::from(dir_camera));
            if objects
                .aabb
                .ray_span(rp.world, dir.recip(), 0.0, f32::INFINITY)
                .is_some()
            {
                reservoir.offer(i);
            }
        }
        let mut sum = Vec3::ZERO;
        let mut met = false;
        for &i in reservoir.kept() {
            let dir_camera = direction(i as usize);
            let dir = Vec3::from(self.to_world * Vec3A::from(dir_camera));
            let Some(hit) = objects.scene.intersect(rp.world, dir, 0.0, f32::INFINITY) else {
                continue;
            };
            let real = self.query.answer_from_real(rp, dir_camera);
            if real.is_some_and(|r| r.t <= hit.t) {
                continue; // the real scene is in front: no difference
            }
            met = true;
            acc.indirect_min = acc.indirect_min.min(hit.t);
            // Environment light is counted by direct light.
            let l_real = match real {
                Some(r) if r.source == Source::Surface => r.radiance,
                _ => Vec3::ZERO,
            };
            sum += self.object_radiance(&hit, bounce_stream, acc) - l_real;
        }
        met.then(|| sum * reservoir.scale(n, PI))
    }

    /// The differential direct irradiance E_RV^dir - E_R^dir at the real point (see
    /// the module docs): minus the light of the candidate table samples the objects
    /// block. `None` when no traced candidate is blocked.
    pub(super) fn object_aware_direct(
        &self,
        rp: &RealPoint,
        objects: &Objects,
        rng: &PixelRng,
        acc: &mut Acc,
    ) -> Option<Vec3> {
        let table = &self.inputs.table.samples;
        let n = (self.params.candidates as usize).min(MAX_CANDIDATES);
        let candidates = rng.stream(StreamId::DirectCandidate);
        let choices = rng.stream(StreamId::DirectReservoir);
        let sample = |i: usize| {
            let bits = candidates.bits(i as u64);
            stratum_index(&self.candidate_strata, i, table.len(), bits)
        };
        let mut reservoir = Reservoir::new(self.params.cache_size as usize, &choices);
        for i in 0..n {
            let Some(s) = sample(i) else { continue };
            let ls = &table[s];
            let lit = rp.normal_world.dot(ls.direction) > 0.0 && ls.pdf > 0.0;
            if lit
                && rp.cone_world.admits(ls.direction)
                && objects
                    .aabb
                    .ray_span(rp.world, ls.direction.recip(), 0.0, f32::INFINITY)
                    .is_some()
            {
                reservoir.offer(i);
            }
        }
        let mut sum = Vec3::ZERO;
        let mut met = false;
        for &i in reservoir.kept() {
            let Some(s) = sample(i as usize) else {
                continue;
            };
            let ls = &table[s];
            let Some(hit) = objects
                .scene
                .intersect(rp.world, ls.direction, 0.0, f32::INFINITY)
            else {
                continue;
            };
            // The light as the real scene delivers it: none behind a real occluder,
            // none the object can block beyond the environment's distance.
            let radiance = match self.query.direct_arrival(rp, s) {
                Some(Hit {
                    source: Source::Surface,
                    ..
                }) => continue,
                Some(h) if h.t <= hit.t => continue,
                Some(h) => h.radiance,
                None => ls.radiance,
            };
            met = true;
            let cos = rp.normal_world.dot(ls.direction);
            self.record_occluder(acc, ls.radiance, hit.t, cos);
            sum -= radiance * (cos / ls.pdf);
        }
        met.then(|| sum * reservoir.scale(n, 1.0))
    }
}

/// How a virtual primary's `drawn` samples (direct or indirect) enter its pixel's
/// sums, where a real primary brings `per_primary`: each weighted by
/// `per_primary / drawn`, counting `per_primary` (exactly 1 and `drawn` when the two
/// are equal; 1 and `drawn` when real primaries bring none).
pub(super) fn primary_share(drawn: usize, per_primary: u32) -> (f32, u32) {
    match (drawn as u32, per_primary) {
        (n, m) if n == m || m == 0 || n == 0 => (1.0, n),
        (n, m) => (m as f32 / n as f32, m),
    }
}

/// `sum` / `count` times `scale`, 0 for no samples.
#[inline]
fn mean(sum: Vec3, count: u32, scale: f32) -> Vec3 {
    if count == 0 {
        Vec3::ZERO
    } else {
        sum * (scale / count as f32)
    }
}
