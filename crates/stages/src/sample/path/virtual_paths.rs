//! The paths of `sample.path` that meet the virtual objects: E_RV at virtual primaries
//! (paper 001 Sec. 5) and the objects' outgoing radiance along indirect rays. The
//! object-aware differential (paper 000 Sec. 7) is in `object_aware`.

use super::kernel::{Acc, Kernel, SURFACE_OFFSET};
use super::rays::RayBatch;
use super::sampling::{Basis, Stream, below, cosine_hemisphere, phong_lobe, phong_weight};
use crate::sample::query::{Hit, RadianceQuery, Ray, Source, cone_spread};
use glam::Vec3;
use relume_scene::light::voxels::OPAQUE;
use relume_scene::objects::VirtualHit;
use std::f32::consts::FRAC_1_PI;

/// A direct sample at a virtual primary, as drawn before the span's rays are traced.
#[derive(Clone, Copy, Debug)]
pub(super) enum VirtualDirect {
    /// No light: the table is empty, or the sample lies below the surface or has no
    /// density.
    Unlit,
    /// Table sample `sample` at cosine `cos` to the normal, blocked by a virtual surface
    /// at distance `t`.
    Blocked { sample: usize, cos: f32, t: f32 },
    /// Table sample `sample` at cosine `cos`, whose ray is `ray` in the span's batch,
    /// `visible` the share of its light the objects let through (1 but under `vct`,
    /// whose cones are partly blocked).
    Open {
        sample: usize,
        cos: f32,
        ray: usize,
        visible: f32,
    },
}

/// An indirect sample at a virtual primary: its world direction and weight, and its
/// ray in the span's batch (none where the weight is 0: the direction lies below the
/// surface, and the sample brings nothing).
#[derive(Clone, Copy, Debug)]
pub(super) struct VirtualIndirect {
    pub(super) dir: Vec3,
    pub(super) weight: f32,
    pub(super) ray: Option<usize>,
}

/// Where a virtual primary's rays leave its surface (raised off it), and the mirror
/// direction of its view.
struct Surface {
    origin: Vec3,
    mirror: Vec3,
    glossy: bool,
}

impl Surface {
    fn new(hit: &VirtualHit, to_viewer: Vec3) -> Surface {
        let n = hit.normal;
        Surface {
            origin: hit.position + n * SURFACE_OFFSET,
            mirror: 2.0 * n.dot(to_viewer) * n - to_viewer,
            glossy: hit.material.is_glossy(),
        }
    }
}

impl Kernel<'_> {
    /// Draws the E_RV samples of primary j at a virtual hit seen from direction
    /// `to_viewer`: direct samples are tested against the objects here (unless
    /// `visibility` is off), and the rays of the open ones and of the indirect samples
    /// are queued in `batch`. [`Kernel::virtual_samples`] then estimates from them.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn draw_virtual_samples(
        &self,
        hit: &VirtualHit,
        to_viewer: Vec3,
        j: u32,
        primary: u32,
        direct_stream: &Stream,
        indirect_stream: &Stream,
        batch: &mut RayBatch<'_>,
        direct: &mut Vec<VirtualDirect>,
        indirect: &mut Vec<VirtualIndirect>,
    ) {
        let params = self.params;
        let surface = Surface::new(hit, to_viewer);
        let n = hit.normal;
        let t_max = params.max_distance;
        // Self-occlusion of the objects' own illumination (paper 000 Table 3's
        // visibility test).
        let objects = self.objects.as_ref().filter(|_| params.visibility);
        for k in 0..params.direct {
            let s = j * params.direct + k;
            let drawn = match self.direct_sample(direct_stream, s, primary) {
                Some((sample, ls)) => {
                    let cos = n.dot(ls.direction);
                    if cos > 0.0 && ls.pdf > 0.0 {
                        let (blocker, visible) = match (objects, self.object_volume) {
                            (Some(_), Some(volume)) => {
                                let cone =
                                    self.object_shadow(volume, hit.position, n, ls.direction);
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
                                    |q| self.world_direct(q, surface.origin, sample),
                                    || self.tracer.camera_ray(surface.origin, ls.direction),
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
            cone_spread(primary * params.indirect, hit.material.exponent)
        } else {
            self.indirect_spread
        };
        for k in 0..params.indirect {
            let s = j * params.indirect + k;
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
                    || self.tracer.camera_ray(surface.origin, dir),
                    t_max,
                )
            });
            indirect.push(VirtualIndirect { dir, weight, ray });
        }
    }

    /// The E_RV samples of a virtual primary's hit seen from direction `to_viewer`,
    /// from its `direct` and `indirect` samples drawn by
    /// [`Kernel::draw_virtual_samples`] and their rays' `hits`.
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
            acc.rv_dir += c;
        }
        acc.rv_dir_n += self.params.direct;
        for sample in indirect {
            if let Some(ray) = sample.ray {
                let l = self.incoming(surface.origin, sample.dir, hits[ray], bounce_stream, acc);
                acc.rv_ind += l * sample.weight;
            }
        }
        acc.rv_ind_n += self.params.indirect;
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
            return self.object_radiance(&hit, bounce_stream, acc);
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
                    visible -= self
                        .object_shadow(volume, hit.position, hit.normal, ls.direction)
                        .opacity;
                }
                None if objects.hit(origin, ls.direction, f32::INFINITY).is_some() => {
                    return Vec3::ZERO;
                }
                None => {}
            }
        }
        let radiance = match self.query_world(origin, ls.direction) {
            Some(Hit {
                source: Source::Surface,
                ..
            }) => return Vec3::ZERO,
            Some(h) => h.radiance,
            None => ls.radiance,
        };
        hit.material.albedo * FRAC_1_PI * radiance * (cos / ls.pdf * visible)
    }
}
