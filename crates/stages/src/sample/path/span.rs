//! Pixels are estimated a span of a row at a time: first every real point's samples are
//! drawn, each pixel's primaries meet the objects or not, and the virtual hits' samples
//! are drawn, with all their rays queued; then the rays are answered in one
//! [`RayBatch`] (with `ssrt`, marched eight at a time with AVX2); then each pixel is
//! estimated from its samples and their hits. The rays, the hits and therefore the
//! estimates are those of tracing each ray in turn. Each pixel's result goes to the
//! caller.

use super::PathParams;
use super::kernel::{Kernel, RealPoint};
use super::rays::{NOT_ASKED, RayBatch, WorldQuery};
use super::sampling::{PixelRng, StreamId, cosine_hemisphere};
use super::virtual_paths::{VirtualDirect, VirtualIndirect};
use crate::sample::layers::PixelLayers;
use crate::sample::query::RadianceQuery;
use crate::sample::ssrt::batch::TraceBatch;
use glam::Vec3;
use relume_scene::objects::VirtualHit;

/// Pixels per span: enough rays (about 23 per pixel) that the batch's lanes rarely wait
/// at its end, few enough that its buffers stay in the cache (about 50 KB).
pub(super) const SPAN_PIXELS: usize = 32;

/// A direct sample whose ray is traced: its table sample, the cosine of its direction
/// to the normal, and its ray in the batch.
#[derive(Clone, Copy, Debug)]
pub(super) struct DirectRay {
    pub(super) sample: usize,
    pub(super) cos: f32,
    pub(super) ray: usize,
}

/// An indirect sample: its camera-space direction and its ray in the batch.
#[derive(Clone, Copy, Debug)]
pub(super) struct IndirectRay {
    pub(super) dir_camera: Vec3,
    pub(super) ray: usize,
}

/// One real point's samples: per direct sample s (primary j has
/// `j * direct .. (j + 1) * direct`) its ray, `None` where it is not traced (the table
/// is empty, or the direction is below the surface or has no density); per indirect
/// sample likewise, always traced.
pub(super) struct RealSamples<'a> {
    pub(super) direct: &'a [Option<DirectRay>],
    pub(super) indirect: &'a [IndirectRay],
}

/// The samples drawn at one pixel's virtual primaries, in primary order: `direct`
/// per direct sample of each virtual primary, `indirect` per indirect sample.
pub(super) struct VirtualSamples<'a> {
    pub(super) direct: &'a [VirtualDirect],
    pub(super) indirect: &'a [VirtualIndirect],
}

/// What was drawn at one pixel before its span's rays were traced: its real point, if
/// any, with its samples; per primary its virtual hit and view direction, if any; and
/// the samples of those virtual hits.
pub(super) struct Drawn<'a> {
    pub(super) real: Option<&'a RealPoint>,
    pub(super) real_samples: RealSamples<'a>,
    pub(super) primaries: &'a [Option<(VirtualHit, Vec3)>],
    pub(super) virtual_samples: VirtualSamples<'a>,
}

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
        let batch = match &kernel.world_query {
            Some(query) => RayBatch::World { query, hits },
            None => RayBatch::Screen {
                batch: Box::new(TraceBatch::new(&kernel.tracer, direct + indirect)),
                query: kernel.screen(),
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
}

impl Kernel<'_> {
    /// Estimates pixels `xs` of row `y`, handing each result to `emit`.
    pub(super) fn shade_span(
        &self,
        y: u32,
        xs: &[u32],
        span: &mut Span<'_>,
        mut emit: impl FnMut(u32, &PixelLayers),
    ) {
        let inputs = self.inputs;
        span.batch.clear();
        span.real.clear();
        span.direct.clear();
        span.indirect.clear();
        span.primaries.clear();
        span.primary_counts.clear();
        span.virtual_direct.clear();
        span.virtual_indirect.clear();
        for &x in xs {
            let p = y as usize * inputs.depth.width as usize + x as usize;
            let rng = PixelRng::new(self.params.seed, inputs.frame, p as u64);
            let z = inputs.depth.data[p];
            let real = self.real_point(x, y, z, inputs.normals.data[p]);
            let primary = self.primaries_at(x, y, real.as_ref());
            if let Some(rp) = &real {
                self.draw_real_samples(rp, &rng, primary, span);
            }
            span.real.push(real);
            span.primary_counts.push(primary);
            self.draw_primaries(x, y, z, &rng, primary, span);
        }
        span.batch.trace(self.lanes);
        let params = self.params;
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
                virtual_direct.split_at(virtual_count * params.direct as usize);
            let (pixel_indirect, rest_indirect) =
                virtual_indirect.split_at(virtual_count * params.indirect as usize);
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
            let result = self.shade_pixel(x, y, &drawn, span.batch.hits());
            emit(x, &result);
        }
    }

    /// Finds which primaries of pixel (x, y) (depth `z`) meet the objects, and draws
    /// the samples of their virtual hits, queueing their screen-space rays.
    fn draw_primaries(
        &self,
        x: u32,
        y: u32,
        z: f32,
        rng: &PixelRng,
        primary: u32,
        span: &mut Span<'_>,
    ) {
        let [x0, y0, x1, y1] = self.object_pixels;
        let may_see_objects = (x0..=x1).contains(&(x as i64)) && (y0..=y1).contains(&(y as i64));
        if !may_see_objects {
            let real_only = (0..primary).map(|_| None);
            span.primaries.extend(real_only);
            return;
        }
        let (primary_stream, direct_stream, indirect_stream) = (
            rng.stream(StreamId::Primary),
            rng.stream(StreamId::Direct),
            rng.stream(StreamId::Indirect),
        );
        for j in 0..primary {
            let hit = self.primary_hit(&primary_stream, j, x, y, z);
            if let Some((hit, view)) = &hit {
                self.draw_virtual_samples(
                    hit,
                    -*view,
                    j,
                    primary,
                    &direct_stream,
                    &indirect_stream,
                    &mut span.batch,
                    &mut span.virtual_direct,
                    &mut span.virtual_indirect,
                );
            }
            span.primaries.push(hit);
        }
    }

    /// Draws the direct and indirect samples of real point `rp` (from its pixel's
    /// streams `rng`) for every primary, queueing their screen-space rays.
    fn draw_real_samples(&self, rp: &RealPoint, rng: &PixelRng, primary: u32, span: &mut Span<'_>) {
        let params = self.params;
        let (direct_stream, indirect_stream) =
            (rng.stream(StreamId::Direct), rng.stream(StreamId::Indirect));
        let t_max = params.max_distance;
        for s in 0..primary * params.direct {
            let drawn = self
                .direct_sample(&direct_stream, s, primary)
                .and_then(|(sample, ls)| {
                    let cos = rp.normal_world.dot(ls.direction);
                    (cos > 0.0 && ls.pdf > 0.0).then(|| DirectRay {
                        sample,
                        cos,
                        ray: span.batch.push(
                            |q| self.world_direct(q, rp.query_origin, sample),
                            || (rp.origin, self.table_camera[sample]),
                            t_max,
                        ),
                    })
                });
            span.direct.push(drawn);
        }
        for s in 0..primary * params.indirect {
            let (u1, u2) = indirect_stream.pair(s as u64);
            let dir_camera = rp.basis_camera.to_world(cosine_hemisphere(u1, u2));
            // For the world-space queries, only rays that may meet an object need
            // their distance (see `real_samples`); the impostor's is asked there, and
            // only of the rays that do meet one.
            let world = |q: &WorldQuery| {
                if self.params.object_aware
                    || self.impostor_bounds_reflectors()
                    || !rp.cone_camera.admits(dir_camera)
                {
                    return Some(NOT_ASKED);
                }
                q.query(&self.real_ray(rp, dir_camera))
            };
            span.indirect.push(IndirectRay {
                dir_camera,
                ray: span.batch.push(world, || (rp.origin, dir_camera), t_max),
            });
        }
    }
}
