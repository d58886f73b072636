//! The rays of a span, answered by the stage's radiance query
//! ([`crate::sample::query`]): with `ssrt` they are queued in camera space and
//! marched together ([`TraceBatch`], eight lanes at a time where the CPU has AVX2); with
//! the world-space queries ([`WorldQuery`]: the impostor's and the voxel volume's) each
//! is answered as it is pushed, by the caller, who knows when an answer can be had for
//! less (see [`FrameQuery::world_direct`] and [`NOT_ASKED`]). Either way [`RayBatch::hits`] holds
//! one answer per ray, in push order. [`FrameQuery`] is the query as the estimator
//! asks it, for the batch and for the rays asked one at a time (the object-aware
//! candidates, the bounce off an object).

use super::bounds::Objects;
use super::records::RealPoint;
use crate::sample::query::{
    Hit, ImpostorQuery, RadianceQuery, Ray, ScreenQuery, Source, VoxelQuery,
};
use crate::sample::ssrt::batch::TraceBatch;
use crate::sample::ssrt::{RayOrigin, ScreenTracer};
use glam::{Mat3A, Vec3, Vec3A};
use relume_base::raster::Vec3Image;
use relume_base::simd;
use relume_scene::light::LightTable;

/// The answer recorded for a world-space ray whose answer cannot matter when drawn: an
/// indirect ray from a real point outside the objects' cone (no object can be in its
/// way), any indirect ray from a real point when the object-aware differential stands
/// for them, and under `em` and `dit` every indirect ray from a real point (the
/// impostor is asked only if the ray meets an object: [`FrameQuery::before_impostor`]); the
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

    /// Answers every ray pushed since the last clear or trace (marching the
    /// screen-space ones with `lanes` where the CPU has it: the hits are the same with
    /// any, and the same however the rays are split between calls).
    pub(super) fn trace(&mut self, lanes: simd::Kernel) {
        if let RayBatch::Screen { batch, query, hits } = self {
            batch.trace(lanes);
            let answered = hits.len();
            let new = &batch.hits()[answered..];
            hits.extend(new.iter().map(|h| h.map(|real| query.hit(real))));
        }
    }

    /// Per ray, in push order: what the query answered.
    pub(super) fn hits(&self) -> &[Option<Hit>] {
        match self {
            RayBatch::Screen { hits, .. } | RayBatch::World { hits, .. } => hits,
        }
    }
}

/// The stage's radiance query over one frame, as the estimator asks it: the
/// screen-space tracer or the world-space query, with what it answers from (the
/// camera's radiance, the table's directions) and the cones' apertures. Constant over
/// the frame.
pub(super) struct FrameQuery<'a> {
    pub(super) tracer: ScreenTracer<'a>,
    /// The world-space query (`em`, `dit`, `vct`); `None` for screen-space marching.
    pub(super) world_query: Option<WorldQuery<'a>>,
    /// The query of the real points' rays where it is not `world_query`: `dit` for
    /// the material estimation under `em` (`material_query = "dit"`, paper 000
    /// Sec. 7: "for the material estimation DIT is also used in EM cases").
    pub(super) real_query: Option<WorldQuery<'a>>,
    /// What a real hit of the screen-space march brings: the camera's radiance.
    pub(super) radiance: &'a Vec3Image,
    /// The screen-space march's reach (metres).
    pub(super) max_distance: f32,
    pub(super) table: &'a LightTable,
    /// The table's directions in camera space (where the screen-space tracer works).
    pub(super) table_camera: Vec<Vec3>,
    /// `em`: the impostor's answer per table sample (it does not depend on the ray's
    /// origin), looked up once per frame instead of once per ray.
    pub(super) table_em: Vec<Option<Hit>>,
    /// `vct`: the cone spreads of direct and indirect samples at real points (the
    /// pixel's samples share the hemisphere: [`crate::sample::query::cone_spread`]).
    pub(super) direct_spread: f32,
    pub(super) indirect_spread: f32,
    /// Camera to world rotation.
    pub(super) to_world: Mat3A,
}

impl<'a> FrameQuery<'a> {
    /// The query of one frame: `tracer` or `world_query` over it (`real_query`, where
    /// given, for the real points' rays), the table's directions turned into camera
    /// space by `to_camera` (and, for `em`, answered once here).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        tracer: ScreenTracer<'a>,
        world_query: Option<WorldQuery<'a>>,
        real_query: Option<WorldQuery<'a>>,
        radiance: &'a Vec3Image,
        max_distance: f32,
        table: &'a LightTable,
        to_world: Mat3A,
        direct_spread: f32,
        indirect_spread: f32,
    ) -> FrameQuery<'a> {
        let to_camera = to_world.transpose();
        // Environment Mapping's answer does not depend on the ray's origin.
        let table_em = match &world_query {
            Some(WorldQuery::Impostor(q)) if q.iterations == 0 => table
                .samples
                .iter()
                .map(|ls| q.query(&Ray::unbounded(q.center, ls.direction)))
                .collect(),
            _ => Vec::new(),
        };
        FrameQuery {
            tracer,
            world_query,
            real_query,
            radiance,
            max_distance,
            table,
            table_camera: table
                .samples
                .iter()
                .map(|ls| Vec3::from(to_camera * Vec3A::from(ls.direction)))
                .collect(),
            table_em,
            direct_spread,
            indirect_spread,
            to_world,
        }
    }

    /// `em`, `dit`: a real point's indirect rays are not asked of the impostor when
    /// drawn (its answer brings them no light, see [`NOT_ASKED`]); a ray of a real
    /// primary that meets an object asks it then, to learn whether the impostor's
    /// surface comes first ([`FrameQuery::before_impostor`]).
    #[inline]
    pub(super) fn impostor_bounds_reflectors(&self) -> bool {
        matches!(self.world_query, Some(WorldQuery::Impostor(_)))
    }

    /// The screen-space query over this frame's depth map.
    #[inline]
    pub(super) fn screen(&self) -> ScreenQuery<'_> {
        ScreenQuery {
            tracer: &self.tracer,
            radiance: self.radiance,
            max_distance: self.max_distance,
        }
    }

    /// The world cone (of an indirect sample's aperture) from the real point along
    /// camera-space direction `dir_camera`.
    #[inline]
    fn real_ray(&self, rp: &RealPoint, dir_camera: Vec3) -> Ray {
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
            .trace_from(origin, dir_camera, self.max_distance)
            .map(|real| self.screen().hit(real))
    }

    /// What the query answers along camera-space direction `dir_camera` from the
    /// real point.
    #[inline]
    pub(super) fn answer_from_real(&self, rp: &RealPoint, dir_camera: Vec3) -> Option<Hit> {
        match self.real_query.as_ref().or(self.world_query.as_ref()) {
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
                let dir = self.table.samples[sample].direction;
                query.query(&Ray::cone(origin, dir, self.direct_spread))
            }
        }
    }

    /// [`Self::world_direct`] from a real point's `origin`, asked of `real_query`
    /// where there is one (`query` is then not asked).
    #[inline]
    pub(super) fn real_direct(
        &self,
        query: &WorldQuery,
        origin: Vec3,
        sample: usize,
    ) -> Option<Hit> {
        match &self.real_query {
            Some(real) => {
                let dir = self.table.samples[sample].direction;
                real.query(&Ray::cone(origin, dir, self.direct_spread))
            }
            None => self.world_direct(query, origin, sample),
        }
    }

    /// What the query answers along table sample `sample`'s direction from the real
    /// point.
    #[inline]
    pub(super) fn direct_arrival(&self, rp: &RealPoint, sample: usize) -> Option<Hit> {
        match &self.world_query {
            Some(query) => self.real_direct(query, rp.query_origin, sample),
            None => self.screen_from_real(rp, self.table_camera[sample]),
        }
    }

    /// What the query answers along world direction `dir` from `origin` (a cone of a
    /// direct sample's aperture).
    #[inline]
    pub(super) fn answer_from(&self, origin: Vec3, dir: Vec3) -> Option<Hit> {
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
        match self.answer_from_real(rp, dir_camera) {
            None => true,
            Some(real) => t < real.t && objects.box_admits(rp.world, dir, real.t),
        }
    }
}
