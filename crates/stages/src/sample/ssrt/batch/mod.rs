//! Many rays marched together: a [`TraceBatch`] of one tracer takes rays one by one,
//! then sets them up (projects and clips them, as [`ScreenTracer::trace_from`] does)
//! and marches them all, and holds one [`RealHit`] per ray, bit for bit what
//! `trace_from` returns for it.
//!
//! With AVX2 the hierarchical march runs eight rays at a time, one per lane, each lane
//! at its own sample and pyramid level; a lane whose ray ends takes the next queued ray,
//! so lanes do not wait for the longest ray of a group (rays of one pixel march 14 tile
//! visits on average, the longest of eight about 35). Every lane computes the scalar
//! march's operations in the same order with the same roundings (no fused multiply-add),
//! so the samples found are the same. The setup also runs eight rays per vector, with
//! the scalar setup for the rare rays that need clipping (near plane, image sides) or
//! meet a degenerate case. Without AVX2, or for a pyramid of more than 16
//! levels, the scalar march runs ray by ray.

#[cfg(target_arch = "x86_64")]
mod march;
mod queue;
#[cfg(target_arch = "x86_64")]
mod setup;

use super::{RayOrigin, RealHit, ScreenTracer};
use glam::Vec3;
#[cfg(target_arch = "x86_64")]
use queue::LevelTables;
use queue::{Pending, Queued};
use relume_base::simd::Kernel;

/// Rays traced together against one tracer's depth map; reusable (its buffers keep
/// their capacity from batch to batch).
pub struct TraceBatch<'t> {
    /// Every queued march was set up by this tracer, so its samples lie in this
    /// tracer's image: the march reads its pyramid unchecked.
    tracer: &'t ScreenTracer<'t>,
    /// The pyramid's levels for the lanes (`None`: march ray by ray).
    #[cfg(target_arch = "x86_64")]
    tables: Option<LevelTables>,
    pending: Pending,
    queued: Vec<Queued>,
    /// Per queued ray: the sample found, as (major coordinate, ray 1/z).
    found: Vec<Option<(i32, f32)>>,
    hits: Vec<Option<RealHit>>,
}

impl<'t> TraceBatch<'t> {
    /// An empty batch of rays against `tracer`'s depth map, with room for `capacity`
    /// rays.
    pub fn new(tracer: &'t ScreenTracer<'t>, capacity: usize) -> TraceBatch<'t> {
        TraceBatch {
            tracer,
            #[cfg(target_arch = "x86_64")]
            tables: LevelTables::new(tracer),
            pending: Pending::default(),
            queued: Vec::with_capacity(capacity),
            found: Vec::with_capacity(capacity),
            hits: Vec::with_capacity(capacity),
        }
    }

    /// Removes every ray.
    pub fn clear(&mut self) {
        self.pending.clear();
        self.hits.clear();
    }

    /// Number of rays pushed since the last clear.
    pub fn len(&self) -> usize {
        self.hits.len()
    }

    /// Whether no ray was pushed since the last clear.
    pub fn is_empty(&self) -> bool {
        self.hits.is_empty()
    }

    /// Adds the ray `origin + t dir` (camera space, `dir` unit, t <= `t_max`) and
    /// returns its index. A `None` origin (one that [`ScreenTracer::origin`] rejected)
    /// finds nothing.
    pub fn push(&mut self, origin: Option<&RayOrigin>, dir: Vec3, t_max: f32) -> usize {
        let ray = self.hits.len();
        self.hits.push(None);
        if let Some(o) = origin {
            self.pending.push(o, dir, t_max, ray as u32);
        }
        ray
    }

    /// Marches every ray pushed since the last clear or trace, with `kernel` where the
    /// CPU has it: afterwards [`TraceBatch::hits`] holds what
    /// [`ScreenTracer::trace_from`] returns for each ray pushed since the last clear.
    /// Returns the kernel that ran. Rays pushed after this call need another (which
    /// marches only them).
    pub fn trace(&mut self, kernel: Kernel) -> Kernel {
        let tracer = self.tracer;
        self.queued.clear();
        #[cfg(target_arch = "x86_64")]
        if kernel.available() == Kernel::Avx2Fma
            && let Some(tables) = &self.tables
        {
            // SAFETY: `available` returned Avx2Fma, so the CPU has AVX2; the tables are
            // this tracer's, whose `setup` (or its lanes' twin) made every queued march.
            unsafe {
                setup::set_up(tracer, &self.pending, &mut self.queued);
                self.found.clear();
                self.found.resize(self.queued.len(), None);
                march::march(tracer, tables, &self.queued, &mut self.found);
            }
            self.record_hits();
            return Kernel::Avx2Fma;
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = kernel; // no other kernel here
        for i in 0..self.pending.len() {
            self.pending.set_up(i, tracer, &mut self.queued);
        }
        self.found.clear();
        self.found.resize(self.queued.len(), None);
        for (q, found) in self.queued.iter().zip(&mut self.found) {
            *found = tracer
                .march_hierarchical(&q.march, &mut 0)
                .map(|(a, _, inv)| (a, inv));
        }
        self.record_hits();
        Kernel::Portable
    }

    /// The hit records of the samples found; the rays are then marched.
    fn record_hits(&mut self) {
        for (q, found) in self.queued.iter().zip(&self.found) {
            if let Some((a, inv)) = *found {
                let m = &q.march;
                self.hits[q.ray as usize] =
                    Some(self.tracer.hit(m, q.origin, q.dir, a, m.minor(a), inv));
            }
        }
        self.pending.clear();
    }

    /// Per ray, in push order: the first real surface on its way, if any.
    pub fn hits(&self) -> &[Option<RealHit>] {
        &self.hits
    }
}
