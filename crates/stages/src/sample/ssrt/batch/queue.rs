//! The rays a [`super::TraceBatch`] holds between pushing and marching: pushed and not
//! yet set up ([`Pending`], one array per field), set up and queued ([`Queued`]), and the
//! pyramid's level tables the lanes read.

use crate::sample::ssrt::{March, RayOrigin, ScreenTracer};
use glam::Vec3;

/// A ray whose segment has samples on screen, waiting to be marched.
#[derive(Clone, Copy, Debug)]
pub(super) struct Queued {
    pub(super) march: March,
    /// Camera-space origin and unit direction, for the hit record.
    pub(super) origin: Vec3,
    pub(super) dir: Vec3,
    /// Index among the batch's rays.
    pub(super) ray: u32,
}

/// Rays pushed and not yet set up, one array per field (the lanes' setup loads eight
/// rays per vector).
#[derive(Debug, Default)]
pub(super) struct Pending {
    /// The origin: camera-space point, its 1/z and its pixel coordinates.
    pub(super) ox: Vec<f32>,
    pub(super) oy: Vec<f32>,
    pub(super) oz: Vec<f32>,
    pub(super) inv_z: Vec<f32>,
    pub(super) px: Vec<f32>,
    pub(super) py: Vec<f32>,
    /// The unit direction.
    pub(super) dx: Vec<f32>,
    pub(super) dy: Vec<f32>,
    pub(super) dz: Vec<f32>,
    pub(super) t_max: Vec<f32>,
    /// Index among the batch's rays.
    pub(super) ray: Vec<u32>,
}

impl Pending {
    /// The float arrays, in the order [`Pending::push`] fills them.
    pub(super) fn floats_mut(&mut self) -> [&mut Vec<f32>; 10] {
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

    pub(super) fn push(&mut self, o: &RayOrigin, dir: Vec3, t_max: f32, ray: u32) {
        let values = [
            o.point.x, o.point.y, o.point.z, o.inv_z, o.x, o.y, dir.x, dir.y, dir.z, t_max,
        ];
        for (field, v) in self.floats_mut().into_iter().zip(values) {
            field.push(v);
        }
        self.ray.push(ray);
    }

    pub(super) fn clear(&mut self) {
        self.floats_mut().into_iter().for_each(Vec::clear);
        self.ray.clear();
    }

    pub(super) fn len(&self) -> usize {
        self.ray.len()
    }

    /// Pending ray `i`: its origin, direction and length. (Inlined: the lanes' setup
    /// reads every ray through it.)
    #[inline(always)]
    pub(super) fn get(&self, i: usize) -> (RayOrigin, Vec3, f32) {
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
    pub(super) fn set_up(&self, i: usize, tracer: &ScreenTracer, queued: &mut Vec<Queued>) {
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

/// The pyramid's level geometry as i32 tables of 16 entries, for per-lane lookups:
/// `None` when the pyramid has more levels (the march supports images up to 8192
/// pixels on a side, 14 levels), offsets beyond i32, or a level layout other than the
/// lanes assume (one value per texel at level 0, a (min, max) pair above).
#[cfg(target_arch = "x86_64")]
pub(super) struct LevelTables {
    pub(super) origin: [i32; 16],
    pub(super) row: [i32; 16],
    pub(super) top: i32,
}

#[cfg(target_arch = "x86_64")]
impl LevelTables {
    pub(super) fn new(tracer: &ScreenTracer) -> Option<LevelTables> {
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
