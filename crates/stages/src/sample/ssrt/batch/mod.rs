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
#[cfg(target_arch = "x86_64")]
mod setup;

use super::{March, RayOrigin, RealHit, ScreenTracer};
use glam::Vec3;
use relume_base::simd::Kernel;

/// A ray whose segment has samples on screen, waiting to be marched.
#[derive(Clone, Copy, Debug)]
struct Queued {
    march: March,
    /// Camera-space origin and unit direction, for the hit record.
    origin: Vec3,
    dir: Vec3,
    /// Index among the batch's rays.
    ray: u32,
}

/// Rays pushed and not yet set up, one array per field (the lanes' setup loads eight
/// rays per vector).
#[derive(Debug, Default)]
struct Pending {
    /// The origin: camera-space point, its 1/z and its pixel coordinates.
    ox: Vec<f32>,
    oy: Vec<f32>,
    oz: Vec<f32>,
    inv_z: Vec<f32>,
    px: Vec<f32>,
    py: Vec<f32>,
    /// The unit direction.
    dx: Vec<f32>,
    dy: Vec<f32>,
    dz: Vec<f32>,
    t_max: Vec<f32>,
    /// Index among the batch's rays.
    ray: Vec<u32>,
}

impl Pending {
    /// The float arrays, in the order [`Pending::push`] fills them.
    fn floats_mut(&mut self) -> [&mut Vec<f32>; 10] {
        [
            &mut self.ox,
            &mut self.oy,
            &mut self.oz,
            &mut self.inv_z,
            &mut self.px,
            &mut self.py,
            &mut self.dx,
            &mut self.dy,
            &mut self.dz,
            &mut self.t_max,
        ]
    }

    fn push(&mut self, o: &RayOrigin, dir: Vec3, t_max: f32, ray: u32) {
        let values = [
            o.point.x, o.point.y, o.point.z, o.inv_z, o.x, o.y, dir.x, dir.y, dir.z, t_max,
        ];
        for (field, v) in self.floats_mut().into_iter().zip(values) {
            field.push(v);
        }
        self.ray.push(ray);
    }

    fn clear(&mut self) {
        self.floats_mut().into_iter().for_each(Vec::clear);
        self.ray.clear();
    }

    fn len(&self) -> usize {
        self.ray.len()
    }

    /// Pending ray `i`: its origin, direction and length. (Inlined: the lanes' setup
    /// reads every ray through it.)
    #[inline(always)]
    fn get(&self, i: usize) -> (RayOrigin, Vec3, f32) {
        let origin = RayOrigin {
            point: Vec3::new(self.ox[i], self.oy[i], self.oz[i]),
            inv_z: self.inv_z[i],
            x: self.px[i],
            y: self.py[i],
        };
        let dir = Vec3::new(self.dx[i], self.dy[i], self.dz[i]);
        (origin, dir, self.t_max[i])
    }

    /// Sets up pending ray `i` with the scalar code, queueing it when its segment has
    /// samples.
    fn set_up(&self, i: usize, tracer: &ScreenTracer, queued: &mut Vec<Queued>) {
        let (origin, dir, t_max) = self.get(i);
        if let Some(march) = tracer.setup(&origin, dir, t_max) {
            queued.push(Queued {
                march,
                origin: origin.point,
                dir,
                ray: self.ray[i],
            });
        }
    }
}

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

    /// Marches every ray pushed since the last clear, with `kernel` where the CPU has
    /// it: afterwards [`TraceBatch::hits`] holds what [`ScreenTracer::trace_from`]
    /// returns for each. Returns the kernel that ran. Rays pushed after this call need
    /// another.
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

    /// The hit records of the samples found.
    fn record_hits(&mut self) {
        for (q, found) in self.queued.iter().zip(&self.found) {
            if let Some((a, inv)) = *found {
                let m = &q.march;
                self.hits[q.ray as usize] =
                    Some(self.tracer.hit(m, q.origin, q.dir, a, m.minor(a), inv));
            }
        }
    }

    /// Per ray, in push order: the first real surface on its way, if any.
    pub fn hits(&self) -> &[Option<RealHit>] {
        &self.hits
    }
}

/// The pyramid's level geometry as i32 tables of 16 entries, for per-lane lookups:
/// `None` when the pyramid has more levels (the march supports images up to 8192
/// pixels on a side, 14 levels), offsets beyond i32, or a level layout other than the
/// lanes assume (one value per texel at level 0, a (min, max) pair above).
#[cfg(target_arch = "x86_64")]
struct LevelTables {
    origin: [i32; 16],
    row: [i32; 16],
    top: i32,
}

#[cfg(target_arch = "x86_64")]
impl LevelTables {
    fn new(tracer: &ScreenTracer) -> Option<LevelTables> {
        let levels = tracer.pyramid.levels();
        if levels.is_empty()
            || levels.len() > 16
            || tracer.pyramid.values().len() > i32::MAX as usize
        {
            return None;
        }
        let mut tables = LevelTables {
            origin: [0; 16],
            row: [0; 16],
            top: levels.len() as i32 - 1,
        };
        for (l, level) in levels.iter().enumerate() {
            // The lanes shift x by min(level, 1) and read a texel's max as the value
            // after its min above level 0 (at level 0 its one value is both).
            let pair = (l > 0) as u32;
            if level.shift != pair || level.max_offset != pair as usize {
                return None;
            }
            tables.origin[l] = i32::try_from(level.origin).ok()?;
            tables.row[l] = i32::try_from(level.row).ok()?;
        }
        Some(tables)
    }
}
