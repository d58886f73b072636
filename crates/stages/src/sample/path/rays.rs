//! The rays of a span, answered by the stage's radiance query
//! ([`crate::sample::query`]): with `ssrt` they are queued in camera space and
//! marched together ([`TraceBatch`], eight lanes at a time where the CPU has AVX2); with
//! the world-space queries ([`WorldQuery`]: the impostor's and the voxel volume's) each
//! is answered as it is pushed, by the caller, who knows when an answer can be had for
//! less (see `Kernel::world_direct` and [`NOT_ASKED`]). Either way [`RayBatch::hits`] holds
//! one answer per ray, in push order. The questions the estimator asks one ray at a
//! time (the object-aware candidates, the bounce off an object) are here too.

use super::bounds::Objects;
use super::kernel::{Kernel, RealPoint};
use crate::sample::query::{
    Hit, ImpostorQuery, RadianceQuery, Ray, ScreenQuery, Source, VoxelQuery,
};
use crate::sample::ssrt::RayOrigin;
use crate::sample::ssrt::batch::TraceBatch;
use glam::{Vec3, Vec3A};
use relume_base::simd;

/// The answer recorded for a world-space ray whose answer cannot matter when drawn: an
/// indirect ray from a real point outside the objects' cone (no object can be in its
/// way), any indirect ray from a real point when the object-aware differential stands
/// for them, and under `em` and `dit` every indirect ray from a real point (the
/// impostor is asked only if the ray meets an object: `Kernel::before_impostor`); the
/// environment brings indirect light nothing (direct light counts it).
pub(super) const NOT_ASKED: Hit = Hit {
    t: f32::INFINITY,
    radiance: Vec3::ZERO,
    source: Source::Environment,
};

/// The queries answered in world space, ray by ray as the rays are drawn (no
/// screen-space march to batch): the distance impostor's (`em`, `dit`) and the voxel
/// volume's (`vct`).
pub(super) enum WorldQuery<'a> {
    Impostor(ImpostorQuery),
    Voxels(VoxelQuery<'a>),
}

impl RadianceQuery for WorldQuery<'_> {
    #[inline]
    fn query(&self, ray: &Ray) -> Option<Hit> {
        match self {
            WorldQuery::Impostor(q) => q.query(ray),
            WorldQuery::Voxels(q) => q.query(ray),
        }
    }
}

/// A span's rays and their answers; reused from span to span (one per rayon worker,
/// so the box around the large screen-space batch costs nothing per ray).
pub(super) enum RayBatch<'t> {
    /// Screen-space marching: rays wait in `batch` until [`RayBatch::trace`].
    Screen {
        batch: Box<TraceBatch<'t>>,
        query: ScreenQuery<'t>,
        hits: Vec<Option<Hit>>,
    },
    /// A world-space query: answered at once.
    World {
        query: &'t WorldQuery<'t>,
        hits: Vec<Option<Hit>>,
    },
}

impl<'t> RayBatch<'t> {
    /// Removes every ray.
    pub(super) fn clear(&mut self) {
        match self {
            RayBatch::Screen { batch, hits, .. } => {
                batch.clear();
                hits.clear();
            }
            RayBatch::World { hits, .. } => hits.clear(),
        }
    }

    /// Adds a ray and returns its index. `world` answers it with the world-space
    /// query (called only by those queries), `camera` gives its projected origin and
    /// camera-space direction (called only by screen-space marching, whose rays end
    /// after `max_distance`).
    #[inline]
    pub(super) fn push(
        &mut self,
        world: impl FnOnce(&WorldQuery) -> Option<Hit>,
        camera: impl FnOnce() -> (Option<RayOrigin>, Vec3),
        max_distance: f32,
    ) -> usize {
        match self {
            RayBatch::Screen { batch, .. } => {
                let (origin, dir) = camera();
                batch.push(origin.as_ref(), dir, max_distance)
            }
            RayBatch::World { query, hits } => {
                hits.push(world(query));
                hits.len() - 1
            }
        }
    }

    /// Answers every ray pushed since the last clear (marching the screen-space ones
    /// with `lanes` where the CPU has it: the hits are the same with any).
    pub(super) fn trace(&mut self, lanes: simd::Kernel) {
        if let RayBatch::Screen { batch, query, hits } = self {
            batch.trace(lanes);
            hits.clear();
            hits.extend(batch.hits().iter().map(|h| h.map(|real| query.hit(real))));
        }
    }

    /// Per ray, in push order: what the query answered.
    pub(super) fn hits(&self) -> &[Option<Hit>] {
        match self {
            RayBatch::Screen { hits, .. } | RayBatch::World { hits, .. } => hits,
        }
    }
}

/// The one-off questions the estimator asks the stage's query (those not batched).
impl Kernel<'_> {
    /// The screen-space query over this frame's depth map.
    #[inline]
    pub(super) fn screen(&self) -> ScreenQuery<'_> {
        ScreenQuery {
            tracer: &self.tracer,
            radiance: self.inputs.radiance,
            max_distance: self.params.max_distance,
        }
    }

    /// The world cone (of an indirect sample's aperture) from the real point along
    /// camera-space direction `dir_camera`.
    #[inline]
    pub(super) fn real_ray(&self, rp: &RealPoint, dir_camera: Vec3) -> Ray {
        Ray::cone(
            rp.query_origin,
            Vec3::from(self.to_world * Vec3A::from(dir_camera)),
            self.indirect_spread,
        )
    }

    /// What the screen-space march meets along camera-space direction `dir_camera`
    /// from the real point (its projected origin).
    #[inline]
    fn screen_from_real(&self, rp: &RealPoint, dir_camera: Vec3) -> Option<Hit> {
        let origin = rp.origin.as_ref()?;
        self.tracer
            .trace_from(origin, dir_camera, self.params.max_distance)
            .map(|real| self.screen().hit(real))
    }

    /// What the stage's query answers along camera-space direction `dir_camera` from
    /// the real point.
    #[inline]
    pub(super) fn query_from_real(&self, rp: &RealPoint, dir_camera: Vec3) -> Option<Hit> {
        match &self.world_query {
            Some(query) => query.query(&self.real_ray(rp, dir_camera)),
            None => self.screen_from_real(rp, dir_camera),
        }
    }

    /// The world-space query's answer for table sample `sample` from `origin` (a
    /// cone of a direct sample's aperture): looked up once per frame for `em`.
    #[inline]
    pub(super) fn world_direct(
        &self,
        query: &WorldQuery,
        origin: Vec3,
        sample: usize,
    ) -> Option<Hit> {
        match self.table_em.get(sample) {
            Some(&answer) => answer,
            None => {
                let dir = self.inputs.table.samples[sample].direction;
                query.query(&Ray::cone(origin, dir, self.direct_spread))
            }
        }
    }

    /// What the stage's query answers along table sample `sample`'s direction from
    /// the real point.
    #[inline]
    pub(super) fn direct_arrival(&self, rp: &RealPoint, sample: usize) -> Option<Hit> {
        match &self.world_query {
            Some(query) => self.world_direct(query, rp.query_origin, sample),
            None => self.screen_from_real(rp, self.table_camera[sample]),
        }
    }

    /// What the stage's query answers along world direction `dir` from `origin` (a
    /// cone of a direct sample's aperture).
    #[inline]
    pub(super) fn query_world(&self, origin: Vec3, dir: Vec3) -> Option<Hit> {
        let ray = Ray::cone(origin, dir, self.direct_spread);
        match &self.world_query {
            Some(query) => query.query(&ray),
            None => self.screen().query(&ray),
        }
    }

    /// `em`, `dit`: whether the objects' nearest hit at `t` along world direction
    /// `dir` (camera space `dir_camera`) from real point `rp` comes before the
    /// impostor's surface: exactly when `objects.hit` bounded by the impostor's
    /// distance (the ray's answer had it been asked when drawn) finds it, box test
    /// included. The nearest hit before a bound is the nearest hit, if nearer.
    pub(super) fn before_impostor(
        &self,
        objects: &Objects,
        rp: &RealPoint,
        dir: Vec3,
        dir_camera: Vec3,
        t: f32,
    ) -> bool {
        match self.query_from_real(rp, dir_camera) {
            None => true,
            Some(real) => t < real.t && objects.box_admits(rp.world, dir, real.t),
        }
    }
}
