//! Pixels are estimated a span of a row at a time: first every real point's samples are
//! drawn and their rays answered in the span's [`RayBatch`] (with `ssrt`, marched
//! eight at a time with AVX2); then each pixel's primaries meet the objects or not, the
//! virtual hits' samples are drawn and their rays answered in a second pass over the
//! batch (so that the clock can tell the material estimation from the object); then
//! each pixel is estimated from its samples and their hits. The rays, the hits and
//! therefore the estimates are those of tracing each ray in turn. Each pixel's result
//! goes to the caller.

use super::PathParams;
use super::kernel::Kernel;
use super::parts::{PartTicks, since};
use super::rays::{NOT_ASKED, RayBatch, WorldQuery};
use super::records::{
    DirectRay, Drawn, IndirectRay, RealPoint, RealSamples, Surface, VirtualDirect, VirtualIndirect,
    VirtualSamples,
};
use super::sampling::{Basis, PixelRng, Stream, StreamId, cosine_hemisphere, phong_lobe};
use crate::sample::layers::PixelLayers;
use crate::sample::query::{RadianceQuery, Ray, cone_spread};
use crate::sample::ssrt::batch::TraceBatch;
use glam::Vec3;
use relume_base::ticks;
use relume_scene::light::voxels::OPAQUE;
use relume_scene::objects::VirtualHit;

/// Pixels per span: enough rays (about 23 per pixel) that the batch's lanes rarely wait
/// at its end, few enough that its buffers stay in the cache (about 50 KB).
pub(super) const SPAN_PIXELS: usize = 32;

/// A span's samples and rays; reused from span to span.
pub(super) struct Span<'t> {
    batch: RayBatch<'t>,
    real: Vec<Option<RealPoint>>,
    direct: Vec<Option<DirectRay>>,
    indirect: Vec<IndirectRay>,
    /// Per pixel, per primary: its virtual hit and view direction, if any.
    primaries: Vec<Option<(VirtualHit, Vec3)>>,
    /// Per pixel, its number of primaries ([`Kernel::primaries_at`]).
    primary_counts: Vec<u32>,
    /// The samples of the virtual primaries, pixel after pixel, primary after primary.
    virtual_direct: Vec<VirtualDirect>,
    virtual_indirect: Vec<VirtualIndirect>,
}

impl<'t> Span<'t> {
    /// Buffers for spans of up to [`SPAN_PIXELS`] pixels whose rays `kernel`'s query
    /// answers.
    pub(super) fn new(kernel: &'t Kernel<'t>, params: &PathParams) -> Span<'t> {
        let most = params.primary.max(params.near_primaries());
        let direct = SPAN_PIXELS * (most * params.direct) as usize;
        let indirect = SPAN_PIXELS * (most * params.indirect) as usize;
        let hits = Vec::with_capacity(direct + indirect);
        let batch = match &kernel.query.world_query {
            Some(query) => RayBatch::World { query, hits },
            None => RayBatch::Screen {
                batch: Box::new(TraceBatch::new(&kernel.query.tracer, direct + indirect)),
                query: kernel.query.screen(),
                hits,
            },
        };
        Span {
            batch,
            real: Vec::with_capacity(SPAN_PIXELS),
            direct: Vec::with_capacity(direct),
            indirect: Vec::with_capacity(indirect),
            primaries: Vec::with_capacity(SPAN_PIXELS * most as usize),
            primary_counts: Vec::with_capacity(SPAN_PIXELS),
            virtual_direct: Vec::new(),
            virtual_indirect: Vec::new(),
        }
    }

    /// Estimates pixels `xs` of row `y` with `kernel`, handing each result to `emit`.
    /// The real points' samples are drawn and their rays answered first, then the
    /// virtual hits' (the same rays and answers in any order), so that the clock can
    /// tell the material estimation from the object (see `parts.rs`).
    pub(super) fn shade(
        &mut self,
        kernel: &Kernel<'_>,
        y: u32,
        xs: &[u32],
        mut emit: impl FnMut(u32, &PixelLayers),
    ) {
        let start = ticks::now();
        let mut parts = PartTicks::default();
        let span = self;
        let inputs = kernel.inputs;
        span.batch.clear();
        span.real.clear();
        span.direct.clear();
        span.indirect.clear();
        span.primaries.clear();
        span.primary_counts.clear();
        span.virtual_direct.clear();
        span.virtual_indirect.clear();
        let pixel = |x: u32| y as usize * inputs.depth.width as usize + x as usize;
        let rng = |x: u32| PixelRng::new(kernel.params.seed, inputs.frame, pixel(x) as u64);
        for &x in xs {
            let p = pixel(x);
            let real = kernel.real_point(x, y, inputs.depth.data[p], inputs.normals.data[p]);
            let primary = kernel.primaries_at(x, y, real.as_ref());
            if let Some(rp) = &real {
                span.draw_real_samples(kernel, rp, &rng(x), primary);
            }
            span.real.push(real);
            span.primary_counts.push(primary);
        }
        span.batch.trace(kernel.lanes);
        let object_start = ticks::now();
        for (i, &x) in xs.iter().enumerate() {
            let (z, primary) = (inputs.depth.data[pixel(x)], span.primary_counts[i]);
            span.draw_primaries(kernel, x, y, z, &rng(x), primary);
        }
        span.batch.trace(kernel.lanes);
        parts.object += since(object_start);
        let params = kernel.params;
        let (mut direct, mut indirect) = (&span.direct[..], &span.indirect[..]);
        let (mut virtual_direct, mut virtual_indirect) =
            (&span.virtual_direct[..], &span.virtual_indirect[..]);
        let mut all_primaries = &span.primaries[..];
        let pixels = xs.iter().zip(&span.real).zip(&span.primary_counts);
        for ((&x, real), &primary) in pixels {
            let (direct_n, indirect_n) = (
                (primary * params.direct) as usize,
                (primary * params.indirect) as usize,
            );
            let (primaries, rest) = all_primaries.split_at(primary as usize);
            all_primaries = rest;
            let samples = match real {
                Some(_) => {
                    let samples = RealSamples {
                        direct: &direct[..direct_n],
                        indirect: &indirect[..indirect_n],
                    };
                    (direct, indirect) = (&direct[direct_n..], &indirect[indirect_n..]);
                    samples
                }
                None => RealSamples {
                    direct: &[],
                    indirect: &[],
                },
            };
            let virtual_count = primaries.iter().flatten().count();
            let (pixel_direct, rest) =
                virtual_direct.split_at(virtual_count * params.object_directs() as usize);
            let (pixel_indirect, rest_indirect) =
                virtual_indirect.split_at(virtual_count * params.object_indirects() as usize);
            (virtual_direct, virtual_indirect) = (rest, rest_indirect);
            let drawn = Drawn {
                real: real.as_ref(),
                real_samples: samples,
                primaries,
                virtual_samples: VirtualSamples {
                    direct: pixel_direct,
                    indirect: pixel_indirect,
                },
            };
            let result = kernel.shade_pixel(x, y, &drawn, span.batch.hits(), &mut parts);
            emit(x, &result);
        }
        kernel.parts.add(since(start), parts);
    }

    /// Finds which primaries of pixel (x, y) (depth `z`) meet the objects, and draws
    /// the samples of their virtual hits, queueing their screen-space rays.
    fn draw_primaries(
        &mut self,
        kernel: &Kernel<'_>,
        x: u32,
        y: u32,
        z: f32,
        rng: &PixelRng,
        primary: u32,
    ) {
        let [x0, y0, x1, y1] = kernel.object_pixels;
        let may_see_objects = (x0..=x1).contains(&(x as i64)) && (y0..=y1).contains(&(y as i64));
        if !may_see_objects {
            let real_only = (0..primary).map(|_| None);
            self.primaries.extend(real_only);
            return;
        }
        let (primary_stream, direct_stream, indirect_stream) = (
            rng.stream(StreamId::Primary),
            rng.stream(StreamId::Direct),
            rng.stream(StreamId::Indirect),
        );
        for j in 0..primary {
            let hit = kernel.primary_hit(&primary_stream, j, x, y, z);
            if let Some((hit, view)) = &hit {
                self.draw_virtual_samples(
                    kernel,
                    hit,
                    -*view,
                    j,
                    primary,
                    &direct_stream,
                    &indirect_stream,
                );
            }
            self.primaries.push(hit);
        }
    }

    /// Draws the direct and indirect samples of real point `rp` (from its pixel's
    /// streams `rng`) for every primary, queueing their screen-space rays.
    fn draw_real_samples(
        &mut self,
        kernel: &Kernel<'_>,
        rp: &RealPoint,
        rng: &PixelRng,
        primary: u32,
    ) {
        let params = kernel.params;
        let query = &kernel.query;
        let (direct_stream, indirect_stream) =
            (rng.stream(StreamId::Direct), rng.stream(StreamId::Indirect));
        let t_max = params.max_distance;
        let strata = kernel.real_strata(primary);
        for s in 0..primary * params.direct {
            let drawn = kernel
                .direct_sample(&direct_stream, s, strata)
                .and_then(|(sample, ls)| {
                    let cos = rp.normal_world.dot(ls.direction);
                    (cos > 0.0 && ls.pdf > 0.0).then(|| DirectRay {
                        sample,
                        cos,
                        ray: self.batch.push(
                            |q| query.real_direct(q, rp.query_origin, sample),
                            || (rp.origin, query.table_camera[sample]),
                            t_max,
                        ),
                    })
                });
            self.direct.push(drawn);
        }
        for s in 0..primary * params.indirect {
            let (u1, u2) = indirect_stream.pair(s as u64);
            let dir_camera = rp.basis_camera.to_world(cosine_hemisphere(u1, u2));
            // For the world-space queries, only rays that may meet an object need
            // their distance (see `real_samples`); the impostor's is asked there, and
            // only of the rays that do meet one.
            let world = |_: &WorldQuery| {
                if params.object_aware
                    || query.impostor_bounds_reflectors()
                    || !rp.cone_camera.admits(dir_camera)
                {
                    return Some(NOT_ASKED);
                }
                query.answer_from_real(rp, dir_camera)
            };
            self.indirect.push(IndirectRay {
                dir_camera,
                ray: self.batch.push(world, || (rp.origin, dir_camera), t_max),
            });
        }
    }

    /// Draws the E_RV samples of primary j at a virtual hit seen from direction
    /// `to_viewer`: direct samples are tested against the objects here (unless
    /// `visibility` is off), and the rays of the open ones and of the indirect samples
    /// are queued in the batch. `Kernel::virtual_samples` then estimates from them.
    #[allow(clippy::too_many_arguments)]
    fn draw_virtual_samples(
        &mut self,
        kernel: &Kernel<'_>,
        hit: &VirtualHit,
        to_viewer: Vec3,
        j: u32,
        primary: u32,
        direct_stream: &Stream,
        indirect_stream: &Stream,
    ) {
        let params = kernel.params;
        let query = &kernel.query;
        let (batch, direct, indirect) = (
            &mut self.batch,
            &mut self.virtual_direct,
            &mut self.virtual_indirect,
        );
        let surface = Surface::new(hit, to_viewer);
        let n = hit.normal;
        let t_max = params.max_distance;
        // Self-occlusion of the objects' own illumination (paper 000 Table 3's
        // visibility test).
        let objects = kernel.objects.as_ref().filter(|_| params.visibility);
        let (directs, indirects) = (params.object_directs(), params.object_indirects());
        let strata = kernel.object_strata(primary);
        for k in 0..directs {
            let s = j * directs + k;
            let drawn = match kernel.direct_sample(direct_stream, s, strata) {
                Some((sample, ls)) => {
                    let cos = n.dot(ls.direction);
                    if cos > 0.0 && ls.pdf > 0.0 {
                        let (blocker, visible) = match (objects, kernel.object_volume) {
                            (Some(_), Some(volume)) => {
                                let spread = kernel.object_direct_spread;
                                let cone = kernel.object_shadow(
                                    volume,
                                    (hit.position, n),
                                    ls.direction,
                                    spread,
                                );
                                let blocked = cone.opacity >= OPAQUE;
                                (blocked.then_some(cone.t_half), 1.0 - cone.opacity)
                            }
                            (Some(o), None) => (
                                o.hit(surface.origin, ls.direction, f32::INFINITY)
                                    .map(|b| b.t),
                                1.0,
                            ),
                            _ => (None, 1.0),
                        };
                        match blocker {
                            Some(t) => VirtualDirect::Blocked { sample, cos, t },
                            None => VirtualDirect::Open {
                                sample,
                                cos,
                                ray: batch.push(
                                    |q| query.world_direct(q, surface.origin, sample),
                                    || query.tracer.camera_ray(surface.origin, ls.direction),
                                    t_max,
                                ),
                                visible,
                            },
                        }
                    } else {
                        VirtualDirect::Unlit
                    }
                }
                None => VirtualDirect::Unlit,
            };
            direct.push(drawn);
        }
        let basis = Basis::new(if surface.glossy {
            surface.mirror.normalize_or(n)
        } else {
            n
        });
        // `vct`: the cones share the lobe (narrowed to the Phong lobe when glossy).
        let spread = if surface.glossy {
            cone_spread(primary * indirects, hit.material.exponent)
        } else if indirects == params.indirect {
            query.indirect_spread
        } else {
            cone_spread(params.primary * indirects, 0.0)
        };
        for k in 0..indirects {
            let s = j * indirects + k;
            let (u1, u2) = indirect_stream.pair(s as u64);
            let (dir, weight) = if surface.glossy {
                let dir = basis.to_world(phong_lobe(u1, u2, hit.material.exponent));
                let cos = n.dot(dir);
                let e = hit.material.exponent;
                (
                    dir,
                    if cos > 0.0 {
                        (e + 2.0) / (e + 1.0) * cos
                    } else {
                        0.0
                    },
                )
            } else {
                (basis.to_world(cosine_hemisphere(u1, u2)), 1.0)
            };
            let ray = (weight > 0.0).then(|| {
                batch.push(
                    |q| q.query(&Ray::cone(surface.origin, dir, spread)),
                    || query.tracer.camera_ray(surface.origin, dir),
                    t_max,
                )
            });
            indirect.push(VirtualIndirect { dir, weight, ray });
        }
    }
}
