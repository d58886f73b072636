//! Object-aware sampling (paper 000 Sec. 7: eq. 9 and the scaled estimator after it):
//! at a real point, E_RV = E_R plus a
//! differential estimated only from the directions that may meet the objects.
//!
//! Of N candidate directions, those meeting the objects' bounding box form H; at most
//! `cache_size` of them (H_a, a uniform random subset chosen by reservoir sampling)
//! are traced, and their sum of L_RV - L_R is scaled by
//! (1 + |H_b| / |H_a|) / N = |H| / (|H_a| N). The estimate is unbiased, and where no
//! traced direction meets an object there is no differential: E_RV == E_R bit for bit.
//! - **Indirect** (`object_aware`): N cosine directions; a direction meeting an object
//!   before the real scene brings the object's outgoing radiance instead of the real
//!   surface's.
//! - **Direct** (`object_aware_direct`): N samples of the light table, drawn in N equal
//!   strata of it like the direct samples; one that an object blocks before the real
//!   scene does loses its light, L cos / pdf. The correlated direct samples then leave
//!   E_RV^dir unblocked (they estimate E_R^dir), and the differential carries the
//!   shadow, with many more directions tested against the box than the pixel's direct
//!   samples. E_RV^dir is clamped at 0 per channel where the differential exceeds the
//!   pixel's E_R^dir estimate (a noisy E_R and a large blocked sum), which biases deep
//!   shadows slightly bright instead of showing negative light.

use super::bounds::Objects;
use super::kernel::{Acc, Kernel, MAX_CANDIDATES, RealPoint};
use super::sampling::{PixelRng, Stream, StreamId, below, cosine_hemisphere, stratum_index};
use crate::sample::query::{Hit, Source};
use glam::{Vec3, Vec3A};
use std::f32::consts::PI;

/// H_a: the candidates kept from H by reservoir sampling (a uniform random subset of
/// at most `size`).
struct Reservoir<'s> {
    kept: [u16; MAX_CANDIDATES],
    size: usize,
    /// |H|: candidates offered so far.
    offered: usize,
    choices: &'s Stream,
}

impl<'s> Reservoir<'s> {
    fn new(size: usize, choices: &'s Stream) -> Reservoir<'s> {
        Reservoir {
            kept: [0; MAX_CANDIDATES],
            size: size.clamp(1, MAX_CANDIDATES),
            offered: 0,
            choices,
        }
    }

    /// Offers candidate `i` (a member of H).
    #[inline]
    fn offer(&mut self, i: usize) {
        if self.offered < self.size {
            self.kept[self.offered] = i as u16;
        } else {
            let r = below(self.choices.bits(i as u64), self.offered as u32 + 1) as usize;
            if r < self.size {
                self.kept[r] = i as u16;
            }
        }
        self.offered += 1;
    }

    /// H_a, in the order kept.
    fn kept(&self) -> &[u16] {
        &self.kept[..self.offered.min(self.size)]
    }

    /// `factor` |H| / (|H_a| N): the weight of each traced candidate's difference.
    fn scale(&self, candidates: usize, factor: f32) -> f32 {
        factor * self.offered as f32 / (self.kept().len() as f32 * candidates as f32)
    }
}

impl Kernel<'_> {
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
            let real = self.query_from_real(rp, dir_camera);
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
            let radiance = match self.direct_arrival(rp, s) {
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
