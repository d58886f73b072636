//! Pixels are estimated a span of a row at a time: first every real point's samples are
//! drawn, each pixel's primaries meet the objects or not, and the virtual hits' samples
//! are drawn, with all their rays queued; then the rays are answered in one
//! [`RayBatch`] (with `ssrt`, marched eight at a time with AVX2); then each pixel is
//! estimated from its samples and their hits. The rays, the hits and therefore the
//! estimates are those of tracing each ray in turn. Results go to [`RowOut`], one row
//! of every output.

use super::kernel::{Kernel, RealPoint};
use super::rays::{NOT_ASKED, RayBatch};
use super::sampling::{PixelRng, StreamId, cosine_hemisphere};
use super::virtual_paths::{VirtualDirect, VirtualIndirect};
use super::{PathOutputs, PathParams, PixelResult};
use crate::objects::VirtualHit;
use crate::stages::sample::query::{ImpostorQuery, RadianceQuery, Ray, ScreenQuery};
use crate::stages::sample::ssrt::TraceBatch;
use glam::{Vec3, Vec3A};

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
    /// The samples of the virtual primaries, pixel after pixel, primary after primary.
    virtual_direct: Vec<VirtualDirect>,
    virtual_indirect: Vec<VirtualIndirect>,
}

impl<'t> Span<'t> {
    /// Buffers for spans of up to [`SPAN_PIXELS`] pixels whose rays `kernel`'s query
    /// answers.
    pub(super) fn new(kernel: &'t Kernel<'t>, params: &PathParams) -> Span<'t> {
        let direct = SPAN_PIXELS * (params.primary * params.direct) as usize;
        let indirect = SPAN_PIXELS * (params.primary * params.indirect) as usize;
        let hits = Vec::with_capacity(direct + indirect);
        let batch = match &kernel.impostor {
            Some(query) => RayBatch::Impostor { query, hits },
            None => RayBatch::Screen {
                batch: Box::new(TraceBatch::new(&kernel.tracer, direct + indirect)),
                query: ScreenQuery {
                    tracer: &kernel.tracer,
                    radiance: kernel.inputs.radiance,
                    max_distance: params.max_distance,
                },
                hits,
            },
        };
        Span {
            batch,
            real: Vec::with_capacity(SPAN_PIXELS),
            direct: Vec::with_capacity(direct),
            indirect: Vec::with_capacity(indirect),
            primaries: Vec::with_capacity(SPAN_PIXELS * params.primary as usize),
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
        mut emit: impl FnMut(u32, &PixelResult),
    ) {
        let inputs = self.inputs;
        span.batch.clear();
        span.real.clear();
        span.direct.clear();
        span.indirect.clear();
        span.primaries.clear();
        span.virtual_direct.clear();
        span.virtual_indirect.clear();
        for &x in xs {
            let p = y as usize * inputs.depth.width as usize + x as usize;
            let rng = PixelRng::new(self.params.seed, inputs.frame, p as u64);
            let z = inputs.depth.data[p];
            let real = self.real_point(x, y, z, inputs.normals.data[p]);
            if let Some(rp) = &real {
                self.draw_real_samples(rp, &rng, span);
            }
            span.real.push(real);
            self.draw_primaries(x, y, z, &rng, span);
        }
        span.batch.trace(self.lanes);
        let params = self.params;
        let (direct_n, indirect_n) = (
            (params.primary * params.direct) as usize,
            (params.primary * params.indirect) as usize,
        );
        let primary_n = params.primary as usize;
        let (mut direct, mut indirect) = (&span.direct[..], &span.indirect[..]);
        let (mut virtual_direct, mut virtual_indirect) =
            (&span.virtual_direct[..], &span.virtual_indirect[..]);
        let pixels = xs.iter().zip(&span.real);
        for ((&x, real), primaries) in pixels.zip(span.primaries.chunks(primary_n)) {
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
    fn draw_primaries(&self, x: u32, y: u32, z: f32, rng: &PixelRng, span: &mut Span<'_>) {
        let [x0, y0, x1, y1] = self.object_pixels;
        let may_see_objects = (x0..=x1).contains(&(x as i64)) && (y0..=y1).contains(&(y as i64));
        if !may_see_objects {
            let real_only = (0..self.params.primary).map(|_| None);
            span.primaries.extend(real_only);
            return;
        }
        let (primary_stream, direct_stream, indirect_stream) = (
            rng.stream(StreamId::Primary),
            rng.stream(StreamId::Direct),
            rng.stream(StreamId::Indirect),
        );
        for j in 0..self.params.primary {
            let hit = self.primary_hit(&primary_stream, j, x, y, z);
            if let Some((hit, view)) = &hit {
                self.draw_virtual_samples(
                    hit,
                    -*view,
                    j,
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
    fn draw_real_samples(&self, rp: &RealPoint, rng: &PixelRng, span: &mut Span<'_>) {
        let params = self.params;
        let (direct_stream, indirect_stream) =
            (rng.stream(StreamId::Direct), rng.stream(StreamId::Indirect));
        let t_max = params.max_distance;
        for s in 0..params.primary * params.direct {
            let drawn = self
                .direct_sample(&direct_stream, s)
                .and_then(|(sample, ls)| {
                    let cos = rp.normal_world.dot(ls.direction);
                    (cos > 0.0 && ls.pdf > 0.0).then(|| DirectRay {
                        sample,
                        cos,
                        ray: span.batch.push(
                            |q| self.impostor_direct(q, rp.world, sample),
                            || (rp.origin, self.table_camera[sample]),
                            t_max,
                        ),
                    })
                });
            span.direct.push(drawn);
        }
        for s in 0..params.primary * params.indirect {
            let (u1, u2) = indirect_stream.pair(s as u64);
            let dir_camera = rp.basis_camera.to_world(cosine_hemisphere(u1, u2));
            // For the impostor, only rays that may meet an object need their
            // distance (see `real_samples`).
            let impostor = |q: &ImpostorQuery| {
                if self.params.object_aware || !rp.cone_camera.admits(dir_camera) {
                    return Some(NOT_ASKED);
                }
                q.query(&Ray {
                    origin: rp.world,
                    dir: Vec3::from(self.to_world * Vec3A::from(dir_camera)),
                    t_max: f32::INFINITY,
                })
            };
            span.indirect.push(IndirectRay {
                dir_camera,
                ray: span.batch.push(impostor, || (rp.origin, dir_camera), t_max),
            });
        }
    }
}

/// One row of every output buffer.
pub(super) struct RowOut<'a> {
    e_r_dir: &'a mut [Vec3],
    e_r_ind: &'a mut [Vec3],
    e_rv_dir: &'a mut [Vec3],
    e_rv_ind: &'a mut [Vec3],
    mask: &'a mut [f32],
    k_v: &'a mut [Vec3],
    exponent: &'a mut [f32],
    world_position: &'a mut [Vec3],
    world_normal: &'a mut [Vec3],
    direct_min_distance: &'a mut [f32],
    indirect_min_distance: &'a mut [f32],
    touched: &'a mut [u8],
}

impl RowOut<'_> {
    #[inline]
    pub(super) fn set(&mut self, x: usize, r: &PixelResult) {
        self.e_r_dir[x] = r.e_r_dir;
        self.e_r_ind[x] = r.e_r_ind;
        self.e_rv_dir[x] = r.e_rv_dir;
        self.e_rv_ind[x] = r.e_rv_ind;
        self.mask[x] = r.mask;
        self.k_v[x] = r.k_v;
        self.exponent[x] = r.exponent;
        self.world_position[x] = r.world_position;
        self.world_normal[x] = r.world_normal;
        self.direct_min_distance[x] = r.direct_min_distance;
        self.indirect_min_distance[x] = r.indirect_min_distance;
        self.touched[x] = r.touched as u8;
    }
}

/// The rows of every output buffer, top to bottom.
pub(super) fn rows(out: &mut PathOutputs, width: usize) -> Vec<RowOut<'_>> {
    let mut e_r_dir = out.e_r_dir.data.chunks_mut(width);
    let mut e_r_ind = out.e_r_ind.data.chunks_mut(width);
    let mut e_rv_dir = out.e_rv_dir.data.chunks_mut(width);
    let mut e_rv_ind = out.e_rv_ind.data.chunks_mut(width);
    let mut mask = out.mask.data.chunks_mut(width);
    let mut k_v = out.k_v.data.chunks_mut(width);
    let mut exponent = out.exponent.data.chunks_mut(width);
    let mut world_position = out.world_position.data.chunks_mut(width);
    let mut world_normal = out.world_normal.data.chunks_mut(width);
    let mut direct_min = out.direct_min_distance.data.chunks_mut(width);
    let mut indirect_min = out.indirect_min_distance.data.chunks_mut(width);
    let mut touched = out.touched.data.chunks_mut(width);
    let mut rows = Vec::new();
    while let (Some(a), Some(b), Some(c), Some(d), Some(e), Some(f)) = (
        e_r_dir.next(),
        e_r_ind.next(),
        e_rv_dir.next(),
        e_rv_ind.next(),
        mask.next(),
        k_v.next(),
    ) {
        let (Some(exponent), Some(g), Some(h), Some(i), Some(j), Some(k)) = (
            exponent.next(),
            world_position.next(),
            world_normal.next(),
            direct_min.next(),
            indirect_min.next(),
            touched.next(),
        ) else {
            break;
        };
        rows.push(RowOut {
            e_r_dir: a,
            e_r_ind: b,
            e_rv_dir: c,
            e_rv_ind: d,
            mask: e,
            k_v: f,
            exponent,
            world_position: g,
            world_normal: h,
            direct_min_distance: i,
            indirect_min_distance: j,
            touched: k,
        });
    }
    rows
}
