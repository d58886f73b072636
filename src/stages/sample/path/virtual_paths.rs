//! The paths of `sample.path` that meet the virtual objects: E_RV at virtual primaries
//! (paper 001 Sec. 5), the objects' outgoing radiance along indirect rays, and the
//! object-aware differential (paper 000 Sec. 7).

use super::bounds::Objects;
use super::kernel::{Acc, Kernel, MAX_CANDIDATES, RealPoint, SURFACE_OFFSET};
use super::sampling::{
    Basis, PixelRng, Stream, StreamId, below, cosine_hemisphere, phong_lobe, phong_weight,
};
use crate::objects::VirtualHit;
use glam::{Vec3, Vec3A};
use std::f32::consts::{FRAC_1_PI, PI};

impl Kernel<'_> {
    /// E_RV samples of primary j at a virtual hit seen from direction `to_viewer`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn virtual_samples(
        &self,
        hit: &VirtualHit,
        to_viewer: Vec3,
        j: u32,
        direct_stream: &Stream,
        indirect_stream: &Stream,
        bounce_stream: &Stream,
        acc: &mut Acc,
    ) {
        let params = self.params;
        let n = hit.normal;
        let material = hit.material;
        let glossy = material.is_glossy();
        let mirror = 2.0 * n.dot(to_viewer) * n - to_viewer;
        let origin = hit.position + n * SURFACE_OFFSET;
        for k in 0..params.direct {
            let s = j * params.direct + k;
            let mut c = Vec3::ZERO;
            if let Some((_, ls)) = self.direct_sample(direct_stream, s) {
                let cos = n.dot(ls.direction);
                if cos > 0.0 && ls.pdf > 0.0 {
                    match self.occluder_distance(origin, ls.direction) {
                        Some(t) => self.record_occluder(acc, ls.radiance, t, cos),
                        None => {
                            let lobe = if glossy {
                                phong_weight(mirror.dot(ls.direction), material.exponent)
                            } else {
                                1.0
                            };
                            c = ls.radiance * (cos / ls.pdf * lobe);
                        }
                    }
                }
            }
            acc.rv_dir += c;
        }
        acc.rv_dir_n += params.direct;
        let basis = Basis::new(if glossy { mirror.normalize_or(n) } else { n });
        for k in 0..params.indirect {
            let s = j * params.indirect + k;
            let (u1, u2) = indirect_stream.pair(s as u64);
            let (dir, weight) = if glossy {
                let dir = basis.to_world(phong_lobe(u1, u2, material.exponent));
                let cos = n.dot(dir);
                let e = material.exponent;
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
            if weight > 0.0 {
                let l = self.incoming(origin, dir, bounce_stream, acc);
                acc.rv_ind += l * weight;
            }
        }
        acc.rv_ind_n += params.indirect;
    }

    /// The distance to the nearest virtual or real occluder along a ray leaving a
    /// virtual surface (real ones within `max_distance`).
    pub(super) fn occluder_distance(&self, origin: Vec3, dir: Vec3) -> Option<f32> {
        let objects = self.objects.as_ref()?;
        if let Some(hit) = objects.hit(origin, dir, f32::INFINITY) {
            return Some(hit.t);
        }
        self.tracer
            .trace(origin, dir, self.params.max_distance)
            .map(|h| h.t)
    }

    /// Radiance arriving at a virtual surface from `dir`: the nearer of the object
    /// (its outgoing radiance) and the real surface (its camera radiance); 0 when the
    /// ray escapes (the environment is counted by direct light).
    pub(super) fn incoming(
        &self,
        origin: Vec3,
        dir: Vec3,
        bounce_stream: &Stream,
        acc: &mut Acc,
    ) -> Vec3 {
        let Some(objects) = self.objects.as_ref() else {
            return Vec3::ZERO;
        };
        let real = self.tracer.trace(origin, dir, self.params.max_distance);
        let t_real = real.map_or(f32::INFINITY, |h| h.t);
        if let Some(hit) = objects.hit(origin, dir, t_real) {
            acc.indirect_min = acc.indirect_min.min(hit.t);
            return self.object_radiance(&hit, bounce_stream, acc);
        }
        match real {
            Some(h) => {
                acc.indirect_min = acc.indirect_min.min(h.t);
                self.radiance_at(h.pixel)
            }
            None => Vec3::ZERO,
        }
    }

    /// The outgoing radiance of a virtual surface towards the ray that hit it:
    /// (k_V / pi) E^dir from one importance sample of the table, with virtual
    /// (self-shadowing) and real visibility. Glossy surfaces are treated as diffuse
    /// for this bounce (as paper 000 Sec. 6.4 does); no further bounce.
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
        if self.occluder_distance(origin, ls.direction).is_some() {
            return Vec3::ZERO;
        }
        hit.material.albedo * FRAC_1_PI * ls.radiance * (cos / ls.pdf)
    }

    /// Paper 000 Sec. 7: the differential indirect irradiance E_RV - E_R at the real
    /// point from `candidates` cosine directions, of which those meeting the bounding
    /// box (H) are traced, at most `cache_size` of them (H_a, a uniform random subset
    /// by reservoir sampling), the sum scaled by (1 + |H_b| / |H_a|) / candidates.
    /// `None` when no traced direction meets an object.
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
        let cache_size = (params.cache_size as usize).clamp(1, MAX_CANDIDATES);
        // No cosine direction can meet the sphere when its cone lies below the horizon.
        let cone = rp.cone_camera;
        let sin_half = (1.0 - cone.cos_half * cone.cos_half).max(0.0).sqrt();
        if cone.cos_half > -1.0 && cone.axis.dot(rp.basis_camera.n) < -sin_half - 1e-5 {
            return None;
        }
        let candidates = rng.stream(StreamId::Candidate);
        let reservoir = rng.stream(StreamId::Reservoir);
        let direction = |i: usize| {
            let (u1, u2) = candidates.pair(i as u64);
            rp.basis_camera.to_world(cosine_hemisphere(u1, u2))
        };
        let mut cache = [0u16; MAX_CANDIDATES];
        let mut in_box = 0usize;
        for i in 0..n {
            let dir_camera = direction(i);
            if !cone.admits(dir_camera) {
                continue;
            }
            let dir = Vec3::from(self.to_world * Vec3A::from(dir_camera));
            if objects
                .aabb
                .ray_span(rp.world, dir.recip(), 0.0, f32::INFINITY)
                .is_none()
            {
                continue;
            }
            if in_box < cache_size {
                cache[in_box] = i as u16;
            } else {
                let r = below(reservoir.bits(i as u64), in_box as u32 + 1) as usize;
                if r < cache_size {
                    cache[r] = i as u16;
                }
            }
            in_box += 1;
        }
        let traced = in_box.min(cache_size);
        let mut sum = Vec3::ZERO;
        let mut met = false;
        for &i in &cache[..traced] {
            let dir_camera = direction(i as usize);
            let dir = Vec3::from(self.to_world * Vec3A::from(dir_camera));
            let Some(hit) = objects.scene.intersect(rp.world, dir, 0.0, f32::INFINITY) else {
                continue;
            };
            let real = self.trace_real(rp, dir_camera);
            if real.is_some_and(|r| r.t <= hit.t) {
                continue; // the real surface is in front: no difference
            }
            met = true;
            acc.indirect_min = acc.indirect_min.min(hit.t);
            let l_real = real.map_or(Vec3::ZERO, |r| self.radiance_at(r.pixel));
            sum += self.object_radiance(&hit, bounce_stream, acc) - l_real;
        }
        met.then(|| sum * (PI * in_box as f32 / (traced as f32 * n as f32)))
    }
}
