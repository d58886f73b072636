//! Screen-space ray tracing against real geometry (paper 001 Sec. 5): rays are
//! intersected with the current frame's depth map, which stands for the real scene.
//!
//! A ray is marched over a fixed sequence of samples: its segment is projected to the
//! image, and one sample is taken per pixel column (or row, for rays steeper than 45
//! degrees on screen) at integer coordinates of that major axis, from `skip_pixels`
//! past the origin's pixel to the end of the segment or the image edge. At each sample
//! the ray's camera depth z (from 1/z, which is linear on screen) is compared with the
//! depth map at the sample's pixel: a hit when z is in [surface, surface + thickness],
//! evaluated as `(1/z) * surface <= 1 && (1/z) * (surface + thickness) >= 1`.
//!
//! [`ScreenTracer::trace`] walks that sequence hierarchically over a min-max
//! [`DepthPyramid`] (as in TIS08, which the paper adapts): the samples inside a tile
//! of 2^L x 2^L pixels (and its neighbour across the minor axis, which they cross at
//! most once) are skipped whole when the ray is in front of the tiles' minimum depth,
//! behind their maximum by more than the thickness, or the tiles are empty; otherwise
//! the march descends a level, and after each skip it climbs again, to the largest tile
//! the next sample starts. The skip tests are conservative in
//! floating point too (the ray's 1/z is monotonic along the samples, and products and
//! sums round monotonically), so the hierarchical march returns exactly the first hit
//! of the sample-by-sample march, [`ScreenTracer::trace_linear`]: the same pixel and
//! the same t, bit for bit.
//!
//! Documented limits shared by both marches: only the current depth map is seen (no
//! off-screen geometry: samples outside the image never hit); a ray whose origin
//! projects outside the image, or whose segment is shorter on screen than
//! `skip_pixels`, finds nothing; segments are clipped to 1 mm in front of the camera and
//! to [`FAR`] metres.
//!
//! Rays leaving one point share its projection: [`ScreenTracer::origin`] once, then
//! [`ScreenTracer::trace_from`] per ray. A [`TraceBatch`](batch::TraceBatch) marches many rays together
//! (eight per vector with AVX2), with the same hits.

pub mod batch;

use super::pyramid::DepthPyramid;
use glam::{Affine3A, Vec3};
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, depth_is_valid};
use std::borrow::Cow;

/// Segments are clipped to this camera depth (metres) in front of the camera.
pub const NEAR: f32 = 1e-3;
/// Segments are clipped to this length (metres), so infinite `t_max` stays finite.
pub const FAR: f32 = 1e4;

/// Where a world ray met the real surface of the depth map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RealHit {
    /// Ray parameter (metres along a unit direction).
    pub t: f32,
    /// The pixel whose surface was hit.
    pub pixel: (u32, u32),
}

/// Settings of the screen-space tracer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceParams {
    /// A ray is behind the surface (a hit) when it is deeper than the depth map by at
    /// most this much, in metres: surfaces are this thick.
    pub thickness: f32,
    /// Pixels skipped at the start of the march, so a ray does not hit its own surface
    /// (rounded up to whole pixels of the major axis).
    pub skip_pixels: f32,
}

impl Default for TraceParams {
    fn default() -> Self {
        TraceParams {
            thickness: 0.1,
            skip_pixels: 1.5,
        }
    }
}

/// Traces world-space or camera-space rays against one depth map seen from one camera.
pub struct ScreenTracer<'a> {
    depth: &'a DepthImage,
    pyramid: Cow<'a, DepthPyramid>,
    camera: Pinhole,
    camera_to_world: Affine3A,
    world_to_camera: Affine3A,
    params: TraceParams,
    /// `skip_pixels` rounded up.
    skip_steps: i32,
}

/// A ray origin in camera space with its projection, shared by every ray leaving it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayOrigin {
    point: Vec3,
    /// 1 / z of the origin.
    inv_z: f32,
    /// Its pixel coordinates.
    x: f32,
    y: f32,
}

/// Fractional bits of the fixed-point minor coordinate of a march.
const FRACTION_BITS: u32 = 16;
const FIXED_ONE: f32 = (1u32 << FRACTION_BITS) as f32;

/// One ray's sample sequence on screen, in (major, minor) axes: samples at integer
/// major coordinates `first, first + step, ..., last`, all inside the image along both
/// axes (`setup` clips the sequence to the samples whose pixel lies in the image: the
/// others never hit, and the march then needs no bounds tests). The minor coordinate
/// is fixed-point (exactly linear in the major coordinate, so pixel indices are
/// monotonic along the march), 1/z is linear in the major coordinate.
/// Images up to 8192 pixels on a side.
#[derive(Clone, Copy, Debug, Default)]
struct March {
    /// The major axis is y (the ray is steeper than 45 degrees on screen).
    transposed: bool,
    /// (minor coordinate + 1.5) * 2^16 at major coordinate a is
    /// `minor_c + a * minor_slope`.
    minor_c: i32,
    minor_slope: i32,
    /// 1/z at major coordinate a is `inv_c + a * dinv`.
    inv_c: f32,
    dinv: f32,
    first: i32,
    last: i32,
    /// +1 or -1: the march direction along the major axis.
    step: i32,
}

impl March {
    #[inline(always)]
    fn minor_fixed(&self, a: i32) -> i32 {
        self.minor_c.wrapping_add(a.wrapping_mul(self.minor_slope))
    }

    /// The minor coordinate of the sample at major coordinate `a`.
    #[inline(always)]
    fn minor(&self, a: i32) -> f32 {
        self.minor_fixed(a) as f32 / FIXED_ONE - 1.5
    }

    /// The pixel row (or column) of the sample at `a`: floor(minor + 0.5), inside the
    /// image for every sample of the march.
    #[inline(always)]
    fn minor_index(&self, a: i32) -> i32 {
        (self.minor_fixed(a) >> FRACTION_BITS) - 1
    }

    /// 1/z of the ray at the sample at `a` (monotonic in `a`).
    #[inline(always)]
    fn inv_depth(&self, a: i32) -> f32 {
        self.inv_c + a as f32 * self.dinv
    }

    /// (x, y) of (major, minor).
    #[inline(always)]
    fn untranspose<T>(&self, major: T, minor: T) -> (T, T) {
        if self.transposed {
            (minor, major)
        } else {
            (major, minor)
        }
    }
}

/// The range of integers a (inclusive, possibly empty) with
/// `lo <= c + a * s <= hi`, for the rare marches that leave the image sideways.
fn fixed_range(c: i64, s: i64, lo: i64, hi: i64) -> (i64, i64) {
    let floor_div = |n: i64, d: i64| n.div_euclid(d);
    let ceil_div = |n: i64, d: i64| -(-n).div_euclid(d);
    match s.signum() {
        0 if (lo..=hi).contains(&c) => (i64::MIN, i64::MAX),
        0 => (1, 0),
        1 => (ceil_div(lo - c, s), floor_div(hi - c, s)),
        _ => (ceil_div(c - hi, -s), floor_div(c - lo, -s)),
    }
}

/// Largest integer <= x (saturating), without a libm call or a branch.
#[inline(always)]
fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t.saturating_sub(((t as f32) > x) as i32)
}

/// Smallest integer >= x (saturating), without a libm call or a branch.
#[inline(always)]
fn ceil_i32(x: f32) -> i32 {
    let t = x as i32;
    t.saturating_add(((t as f32) < x) as i32)
}

impl<'a> ScreenTracer<'a> {
    /// A tracer over `depth` (metres, 0 = missing) seen by `camera` placed by
    /// `camera_to_world`; builds the depth pyramid (O(pixels)).
    ///
    /// Panics when `camera` is not the size of `depth` (a programming error).
    pub fn new(
        depth: &'a DepthImage,
        camera: Pinhole,
        camera_to_world: Affine3A,
        params: TraceParams,
    ) -> Self {
        Self::build(
            depth,
            Cow::Owned(DepthPyramid::new(depth)),
            camera,
            camera_to_world,
            params,
        )
    }

    /// A tracer over `depth` with its prebuilt `pyramid` (built from the same map).
    ///
    /// Panics when the pyramid's finest level or `camera` is not the size of `depth`
    /// (a programming error).
    pub fn with_pyramid(
        depth: &'a DepthImage,
        pyramid: &'a DepthPyramid,
        camera: Pinhole,
        camera_to_world: Affine3A,
        params: TraceParams,
    ) -> Self {
        let l0 = pyramid.level(0);
        assert_eq!(
            (l0.width, l0.height),
            (depth.width, depth.height),
            "the pyramid was built from another depth map"
        );
        Self::build(
            depth,
            Cow::Borrowed(pyramid),
            camera,
            camera_to_world,
            params,
        )
    }

    fn build(
        depth: &'a DepthImage,
        pyramid: Cow<'a, DepthPyramid>,
        camera: Pinhole,
        camera_to_world: Affine3A,
        params: TraceParams,
    ) -> Self {
        assert_eq!(
            (camera.width, camera.height),
            (depth.width, depth.height),
            "the camera and the depth map differ in size"
        );
        let skip = params.skip_pixels;
        ScreenTracer {
            depth,
            pyramid,
            camera,
            camera_to_world,
            world_to_camera: camera_to_world.inverse(),
            params,
            skip_steps: if skip > 0.0 {
                ceil_i32(skip.min(1e6))
            } else {
                0
            },
        }
    }

    /// The transform from world to camera space.
    pub fn world_to_camera(&self) -> Affine3A {
        self.world_to_camera
    }

    /// The transform from camera to world space.
    pub fn camera_to_world(&self) -> Affine3A {
        self.camera_to_world
    }

    /// The camera the depth map is seen from.
    pub fn camera(&self) -> &Pinhole {
        &self.camera
    }

    /// The first real surface along `origin + t dir` (world, `dir` unit) with
    /// t <= t_max, or `None` when the depth map has no surface on its way within the
    /// image. Hierarchical over the depth pyramid.
    pub fn trace(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<RealHit> {
        self.trace_camera(
            self.world_to_camera.transform_point3(origin),
            self.world_to_camera.transform_vector3(dir),
            t_max,
        )
    }

    /// A world-space ray as [`ScreenTracer::trace`] traces it: its projected origin
    /// (`None` where no ray from there finds anything) and its camera-space direction,
    /// to queue in a [`TraceBatch`](batch::TraceBatch).
    #[inline]
    pub fn camera_ray(&self, origin: Vec3, dir: Vec3) -> (Option<RayOrigin>, Vec3) {
        (
            self.origin(self.world_to_camera.transform_point3(origin)),
            self.world_to_camera.transform_vector3(dir),
        )
    }

    /// [`ScreenTracer::trace`] for a ray already in camera space (`dir` unit).
    #[inline]
    pub fn trace_camera(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<RealHit> {
        self.trace_from(&self.origin(origin)?, dir, t_max)
    }

    /// The projection of camera-space point `origin`, for tracing several rays from it;
    /// `None` when it is behind the near plane or projects outside the image (no ray
    /// from there finds anything).
    #[inline]
    pub fn origin(&self, origin: Vec3) -> Option<RayOrigin> {
        if origin.z.is_nan() || origin.z < NEAR {
            return None;
        }
        let cam = &self.camera;
        let inv_z = 1.0 / origin.z;
        let (x, y) = (
            cam.fx * origin.x * inv_z + cam.cx,
            cam.fy * origin.y * inv_z + cam.cy,
        );
        self.projects_inside(x, y).then_some(RayOrigin {
            point: origin,
            inv_z,
            x,
            y,
        })
    }

    /// Whether pixel coordinates (x, y) round to a pixel of the image.
    #[inline(always)]
    fn projects_inside(&self, x: f32, y: f32) -> bool {
        let cam = &self.camera;
        x >= -0.5 && x < cam.width as f32 - 0.5 && y >= -0.5 && y < cam.height as f32 - 0.5
    }

    /// [`ScreenTracer::trace_camera`] from a projected origin.
    #[inline]
    pub fn trace_from(&self, origin: &RayOrigin, dir: Vec3, t_max: f32) -> Option<RealHit> {
        let m = self.setup(origin, dir, t_max)?;
        let (a, b, inv) = self.march_hierarchical(&m, &mut 0)?;
        Some(self.hit(&m, origin.point, dir, a, b, inv))
    }

    /// The same as [`ScreenTracer::trace`] by testing every sample in turn (the
    /// reference the hierarchical march is tested against).
    pub fn trace_linear(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<RealHit> {
        let (o, d) = (
            self.world_to_camera.transform_point3(origin),
            self.world_to_camera.transform_vector3(dir),
        );
        let m = self.setup(&self.origin(o)?, d, t_max)?;
        let (a, b, inv) = self.march_linear(&m)?;
        Some(self.hit(&m, o, d, a, b, inv))
    }

    /// [`ScreenTracer::trace_camera`] that also counts the march's iterations (tile
    /// visits) into `iterations`, for tests and cost estimates.
    pub fn trace_camera_counting(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        iterations: &mut u32,
    ) -> Option<RealHit> {
        let m = self.setup(&self.origin(origin)?, dir, t_max)?;
        let (a, b, inv) = self.march_hierarchical(&m, iterations)?;
        Some(self.hit(&m, origin, dir, a, b, inv))
    }

    /// Projects the camera-space segment and clips its samples to the image; `None`
    /// when no sample is left.
    #[inline]
    fn setup(&self, origin: &RayOrigin, d: Vec3, t_max: f32) -> Option<March> {
        // An origin another tracer projected may lie outside this image: the march
        // relies on starting inside it.
        if !self.projects_inside(origin.x, origin.y) {
            return None;
        }
        let o = origin.point;
        let mut t_end = t_max.min(FAR);
        // Clipped to the near plane (the origin is in front of it): the division only
        // for the few rays that reach it.
        if o.z + t_end * d.z < NEAR {
            t_end = (NEAR - o.z) / d.z;
        }
        if t_end.is_nan() || t_end <= 0.0 {
            return None;
        }
        let e = o + d * t_end;
        let cam = &self.camera;
        let inv1 = 1.0 / e.z;
        if !(inv1 > 0.0 && inv1.is_finite()) {
            return None;
        }
        let (sx, sy) = (origin.x, origin.y);
        let (ex, ey) = (cam.fx * e.x * inv1 + cam.cx, cam.fy * e.y * inv1 + cam.cy);
        let transposed = (ey - sy).abs() > (ex - sx).abs();
        let (sa, sb, ea, eb, major_extent, minor_extent) = if transposed {
            (sy, sx, ey, ex, cam.height as i32, cam.width as i32)
        } else {
            (sx, sy, ex, ey, cam.width as i32, cam.height as i32)
        };
        let da = ea - sa;
        if da.is_nan() || da == 0.0 {
            return None;
        }
        let r = 1.0 / da;
        let step = if da > 0.0 { 1 } else { -1 };
        let start_pixel = (sa + 0.5) as i32;
        let mut first = start_pixel + step * self.skip_steps;
        if (first as f32 - sa) * (step as f32) < 0.0 {
            first += step;
        }
        let (forward_last, backward_last) =
            (floor_i32(ea).min(major_extent - 1), ceil_i32(ea).max(0));
        let mut last = if step > 0 {
            forward_last
        } else {
            backward_last
        };
        if (last - first) * step < 0 {
            return None;
        }
        let slope = (eb - sb) * r;
        let dinv = (inv1 - origin.inv_z) * r;
        let minor_c = ((sb + 1.5 - sa * slope) * FIXED_ONE) as i32;
        let minor_slope = (slope * FIXED_ONE) as i32;
        // Samples whose pixel lies outside the image along the minor axis never hit:
        // keep those inside, which are consecutive (the pixel index is monotonic).
        let (lo, hi) = (
            1i64 << FRACTION_BITS,
            ((minor_extent as i64 + 1) << FRACTION_BITS) - 1,
        );
        let fixed = |a: i32| minor_c as i64 + a as i64 * minor_slope as i64;
        let inside = |a: i32| (lo..=hi).contains(&fixed(a));
        if !(inside(first) && inside(last)) {
            let (a0, a1) = fixed_range(minor_c as i64, minor_slope as i64, lo, hi);
            let (a0, a1) = (
                a0.max(i32::MIN as i64) as i32,
                a1.min(i32::MAX as i64) as i32,
            );
            (first, last) = if step > 0 {
                (first.max(a0), last.min(a1))
            } else {
                (first.min(a1), last.max(a0))
            };
            if (last - first) * step < 0 {
                return None;
            }
        }
        Some(March {
            transposed,
            minor_c,
            minor_slope,
            inv_c: origin.inv_z - sa * dinv,
            dinv,
            first,
            last,
            step,
        })
    }

    /// The sample-by-sample march: the first sample whose pixel's surface holds the
    /// ray, as (major, minor, 1/z).
    fn march_linear(&self, m: &March) -> Option<(i32, f32, f32)> {
        let th = self.params.thickness;
        let mut a = m.first;
        loop {
            let (x, y) = m.untranspose(a, m.minor_index(a));
            let surface = *self.depth.at(x as u32, y as u32);
            let inv = m.inv_depth(a);
            if depth_is_valid(surface) && inv * surface <= 1.0 && inv * (surface + th) >= 1.0 {
                return Some((a, m.minor(a), inv));
            }
            if a == m.last {
                return None;
            }
            a += m.step;
        }
    }

    /// The hierarchical march over the pyramid; the same result as [`Self::march_linear`].
    #[inline]
    fn march_hierarchical(&self, m: &March, iterations: &mut u32) -> Option<(i32, f32, f32)> {
        match (m.transposed, m.step > 0) {
            (false, true) => self.march::<false, true>(m, iterations),
            (false, false) => self.march::<false, false>(m, iterations),
            (true, true) => self.march::<true, true>(m, iterations),
            (true, false) => self.march::<true, false>(m, iterations),
        }
    }

    /// The hierarchical march for one axis order (`TRANSPOSED`: y is the major axis)
    /// and direction (`FORWARD`: increasing major coordinate). Each step takes the
    /// samples from the current one to the last inside the current tile of the level
    /// (a tile along the major axis: the samples' minor pixels cross into at most one
    /// neighbouring tile, which is tested with it) and skips them when the ray is in
    /// front of the tiles' nearest surface, behind their farthest one by more than the
    /// thickness, or the tiles are empty; the march then climbs to the largest tile the
    /// next sample starts (staying at this level when it starts none larger), else it
    /// descends, and a sample not skipped at level 0 is a hit.
    #[inline]
    fn march<const TRANSPOSED: bool, const FORWARD: bool>(
        &self,
        m: &March,
        iterations: &mut u32,
    ) -> Option<(i32, f32, f32)> {
        let levels = self.pyramid.levels();
        let top = levels.len() as i32 - 1;
        let thickness = self.params.thickness;
        let step = if FORWARD { 1 } else { -1 };
        let xy = |major: i32, minor: i32| {
            if TRANSPOSED {
                (minor, major)
            } else {
                (major, minor)
            }
        };
        let (mut a, mut level) = (m.first, 0i32);
        loop {
            *iterations += 1;
            debug_assert!((0..=top).contains(&level));
            // SAFETY: `level` stays in 0..=top: it climbs at most to `top` and descends
            // only above level 0.
            let lv = unsafe { levels.get_unchecked(level as usize) };
            let inv_a = m.inv_depth(a);
            let ta = a >> level;
            let tb = m.minor_index(a) >> level;
            // The last sample of the march inside this tile.
            let ae = if FORWARD {
                (((ta + 1) << level) - 1).min(m.last)
            } else {
                (ta << level).max(m.last)
            };
            let tb_end = m.minor_index(ae) >> level;
            let inv_e = m.inv_depth(ae);
            let ((x0, y0), (x1, y1)) = (xy(ta, tb), xy(ta, tb_end));
            // SAFETY: the samples' pixels lie in the image (`setup` clips them to it,
            // and its size is the pyramid's: checked in `build`), so their tiles lie in
            // the level.
            let (t0, t1) = unsafe {
                (
                    self.pyramid.texel_unchecked(lv, x0, y0),
                    self.pyramid.texel_unchecked(lv, x1, y1),
                )
            };
            // Plain comparisons (none of these is NaN) compile to one instruction each.
            let zmin = if t0[0] < t1[0] { t0[0] } else { t1[0] };
            let zmax = if t0[1] > t1[1] { t0[1] } else { t1[1] };
            let (lo, hi) = if inv_a < inv_e {
                (inv_a, inv_e)
            } else {
                (inv_e, inv_a)
            };
            let skip = (lo * zmin > 1.0) | (hi * (zmax + thickness) < 1.0);
            if !skip & (level == 0) {
                return Some((a, m.minor(a), inv_a));
            }
            if skip & (ae == m.last) {
                return None;
            }
            // A branch, not a select: when predicted, the next step starts early.
            if skip {
                a = ae + step;
                // Climb as far as the new sample starts a tile along the march. After a
                // skip it starts a tile of this level at least; where it starts no
                // larger one (it enters the second half of its parent tile), the parent
                // would test the same samples against a looser bound, so the march
                // stays at this level.
                let aligned = if FORWARD { a } else { a + 1 }.trailing_zeros() as i32;
                debug_assert!(aligned >= level, "a skip ends at a tile boundary");
                level = aligned.min(top);
            } else {
                level -= 1;
            }
        }
    }

    /// The hit record of the sample at (major `a`, minor `b`) with ray 1/z `inv`.
    fn hit(&self, m: &March, o: Vec3, d: Vec3, a: i32, b: f32, inv: f32) -> RealHit {
        let (u, v) = m.untranspose(a as f32, b);
        let point = self.camera.back_project(u, v, 1.0 / inv);
        let (px, py) = m.untranspose(a, m.minor_index(a));
        RealHit {
            t: (point - o).dot(d).max(0.0),
            pixel: (px as u32, py as u32),
        }
    }
}

#[cfg(test)]
mod tests;
