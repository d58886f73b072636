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
//! [`DepthPyramid`] (as in [TIS08], which the paper adapts): a tile of 2^L x 2^L pixels
//! is skipped whole when every sample in it has the ray in front of the tile's minimum
//! depth, behind its maximum by more than the thickness, or when the tile is empty;
//! otherwise the march descends a level, and it climbs again after each skip. The
//! skip tests are conservative in floating point too (the ray's 1/z is monotonic along
//! the samples, and products and sums round monotonically), so the hierarchical march
//! returns exactly the first hit of the sample-by-sample march,
//! [`ScreenTracer::trace_linear`]: the same pixel and the same t, bit for bit.
//!
//! Documented limits shared by both marches: only the current depth map is seen (no
//! off-screen geometry); a ray whose origin projects outside the image, or whose
//! segment is shorter on screen than `skip_pixels`, finds nothing; segments are clipped
//! to 1 mm in front of the camera and to [`FAR`] metres.

use super::pyramid::DepthPyramid;
use crate::pinhole::Pinhole;
use crate::raster::{DepthImage, depth_is_valid};
use glam::{Affine3A, Vec3};
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

/// One ray's sample sequence on screen, in (major, minor) axes: samples at integer
/// major coordinates `first, first + step, ..., last`, all inside the image.
#[derive(Clone, Copy, Debug)]
struct March {
    /// The major axis is y (the ray is steeper than 45 degrees on screen).
    transposed: bool,
    /// Start of the projected segment (major, minor).
    sa: f32,
    sb: f32,
    /// Minor coordinate per unit of major coordinate, and its reciprocal.
    slope: f32,
    inv_slope: f32,
    /// 1/z at the start and its change per unit of major coordinate.
    inv0: f32,
    dinv: f32,
    first: i32,
    last: i32,
    /// +1 or -1: the march direction along the major axis.
    step: i32,
    /// Image extent along the minor axis.
    minor_extent: f32,
}

impl March {
    /// The minor coordinate of the sample at major coordinate `a`.
    #[inline(always)]
    fn minor(&self, a: i32) -> f32 {
        self.sb + (a as f32 - self.sa) * self.slope
    }

    /// The minor pixel index of the sample at `a` (valid for samples inside the image).
    #[inline(always)]
    fn minor_pixel(&self, a: i32) -> i32 {
        (self.minor(a) + 0.5) as i32
    }

    #[inline(always)]
    fn minor_in_image(&self, a: i32) -> bool {
        let v = self.minor(a) + 0.5;
        v >= 0.0 && v < self.minor_extent
    }

    /// 1/z of the ray at the sample at `a` (monotonic in `a`).
    #[inline(always)]
    fn inv_depth(&self, a: i32) -> f32 {
        self.inv0 + (a as f32 - self.sa) * self.dinv
    }

    /// The major coordinate where the minor coordinate reaches `minor` (an estimate
    /// for [`last_true`]).
    #[inline(always)]
    fn major_at_minor(&self, minor: f32) -> f32 {
        self.sa + (minor - self.sb) * self.inv_slope
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

/// Largest integer <= x (saturating), without a libm call.
#[inline(always)]
fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    if (t as f32) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// Smallest integer >= x (saturating), without a libm call.
#[inline(always)]
fn ceil_i32(x: f32) -> i32 {
    let t = x as i32;
    if (t as f32) < x {
        t.saturating_add(1)
    } else {
        t
    }
}

/// The last coordinate of `first, first + step, ..., last` where `pred` holds, given
/// that it holds at `first`, fails at `last` and is monotonic (true, then false).
/// `hint` is an estimate of the answer; with a good one this costs 2 or 3 tests.
#[inline]
fn last_true(first: i32, last: i32, step: i32, hint: f32, pred: impl Fn(i32) -> bool) -> i32 {
    let guess = floor_i32(hint + 0.5);
    let mut a = if step > 0 {
        guess.clamp(first, last)
    } else {
        guess.clamp(last, first)
    };
    if pred(a) {
        while a != last && pred(a + step) {
            a += step;
        }
    } else {
        while !pred(a) {
            a -= step;
        }
    }
    a
}

impl<'a> ScreenTracer<'a> {
    /// A tracer over `depth` (metres, 0 = missing) seen by `camera` placed by
    /// `camera_to_world`; builds the depth pyramid (O(pixels)).
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
    /// Panics when the pyramid's finest level is not the size of `depth` (a
    /// programming error).
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
    /// t <= t_max, or `None` when the ray leaves the image or the depth map has no
    /// surface on its way. Hierarchical over the depth pyramid.
    pub fn trace(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<RealHit> {
        self.trace_camera(
            self.world_to_camera.transform_point3(origin),
            self.world_to_camera.transform_vector3(dir),
            t_max,
        )
    }

    /// [`ScreenTracer::trace`] for a ray already in camera space (`dir` unit).
    #[inline]
    pub fn trace_camera(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<RealHit> {
        let m = self.setup(origin, dir, t_max)?;
        let (a, b, inv) = self.march_hierarchical(&m, &mut 0)?;
        Some(self.hit(&m, origin, dir, a, b, inv))
    }

    /// The same as [`ScreenTracer::trace`] by testing every sample in turn (the
    /// reference the hierarchical march is tested against).
    pub fn trace_linear(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<RealHit> {
        let (o, d) = (
            self.world_to_camera.transform_point3(origin),
            self.world_to_camera.transform_vector3(dir),
        );
        let m = self.setup(o, d, t_max)?;
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
        let m = self.setup(origin, dir, t_max)?;
        let (a, b, inv) = self.march_hierarchical(&m, iterations)?;
        Some(self.hit(&m, origin, dir, a, b, inv))
    }

    /// Projects the camera-space segment and clips it to the image.
    #[inline]
    fn setup(&self, o: Vec3, d: Vec3, t_max: f32) -> Option<March> {
        if o.z.is_nan() || o.z < NEAR {
            return None;
        }
        let mut t_end = t_max.min(FAR);
        if d.z < 0.0 {
            t_end = t_end.min((NEAR - o.z) / d.z);
        }
        if t_end.is_nan() || t_end <= 0.0 {
            return None;
        }
        let e = o + d * t_end;
        let cam = &self.camera;
        let inv0 = 1.0 / o.z;
        let inv1 = 1.0 / e.z;
        if !(inv1 > 0.0 && inv1.is_finite()) {
            return None;
        }
        let (sx, sy) = (cam.fx * o.x * inv0 + cam.cx, cam.fy * o.y * inv0 + cam.cy);
        let (ex, ey) = (cam.fx * e.x * inv1 + cam.cx, cam.fy * e.y * inv1 + cam.cy);
        let (w, h) = (cam.width as f32, cam.height as f32);
        if !(sx >= -0.5 && sx < w - 0.5 && sy >= -0.5 && sy < h - 0.5) {
            return None;
        }
        let transposed = (ey - sy).abs() > (ex - sx).abs();
        let (sa, sb, ea, eb, major_extent, minor_extent) = if transposed {
            (sy, sx, ey, ex, cam.height as i32, w)
        } else {
            (sx, sy, ex, ey, cam.width as i32, h)
        };
        let da = ea - sa;
        if da.is_nan() || da == 0.0 {
            return None;
        }
        let r = 1.0 / da;
        let slope = (eb - sb) * r;
        let step = if da > 0.0 { 1 } else { -1 };
        let start_pixel = (sa + 0.5) as i32;
        let mut first = start_pixel + step * self.skip_steps;
        if (first as f32 - sa) * (step as f32) < 0.0 {
            first += step;
        }
        let last = if step > 0 {
            floor_i32(ea).min(major_extent - 1)
        } else {
            ceil_i32(ea).max(0)
        };
        if (last - first) * step < 0 {
            return None;
        }
        let mut m = March {
            transposed,
            sa,
            sb,
            slope,
            inv_slope: 1.0 / slope,
            inv0,
            dinv: (inv1 - inv0) * r,
            first,
            last,
            step,
            minor_extent,
        };
        if !m.minor_in_image(first) {
            return None;
        }
        if !m.minor_in_image(last) {
            let edge = if slope * step as f32 > 0.0 {
                minor_extent - 0.5
            } else {
                -0.5
            };
            let hint = m.major_at_minor(edge);
            m.last = last_true(first, last, step, hint, |a| m.minor_in_image(a));
        }
        Some(m)
    }

    /// The sample-by-sample march: the first sample whose pixel's surface holds the
    /// ray, as (major, minor, 1/z).
    fn march_linear(&self, m: &March) -> Option<(i32, f32, f32)> {
        let th = self.params.thickness;
        let mut a = m.first;
        loop {
            let b = m.minor(a);
            let (x, y) = m.untranspose(a, (b + 0.5) as i32);
            let surface = *self.depth.at(x as u32, y as u32);
            let inv = m.inv_depth(a);
            if depth_is_valid(surface) && inv * surface <= 1.0 && inv * (surface + th) >= 1.0 {
                return Some((a, b, inv));
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
        let levels = self.pyramid.levels();
        let top = levels.len() as u32 - 1;
        let th = self.params.thickness;
        let mut a = m.first;
        let mut b = m.minor(a);
        let mut pb = (b + 0.5) as i32;
        let mut inv_a = m.inv_depth(a);
        let mut level = 0u32;
        loop {
            *iterations += 1;
            let lv = &levels[level as usize];
            let (ta, tb) = (a >> level, pb >> level);
            // The last sample of the march inside this tile.
            let mut ae = if m.step > 0 {
                (((ta + 1) << level) - 1).min(m.last)
            } else {
                (ta << level).max(m.last)
            };
            if ae != a && (m.minor_pixel(ae) >> level) != tb {
                let edge = if m.slope * m.step as f32 > 0.0 {
                    ((tb + 1) << level) as f32 - 0.5
                } else {
                    (tb << level) as f32 - 0.5
                };
                ae = last_true(a, ae, m.step, m.major_at_minor(edge), |x| {
                    (m.minor_pixel(x) >> level) == tb
                });
            }
            let inv_e = m.inv_depth(ae);
            let (lo, hi) = if inv_a < inv_e {
                (inv_a, inv_e)
            } else {
                (inv_e, inv_a)
            };
            let (tx, ty) = m.untranspose(ta, tb);
            let [zmin, zmax] = self.pyramid.texel_in(lv, tx, ty);
            if lo * zmin > 1.0 || hi * (zmax + th) < 1.0 {
                if ae == m.last {
                    return None;
                }
                a = ae + m.step;
                b = m.minor(a);
                pb = (b + 0.5) as i32;
                inv_a = m.inv_depth(a);
                level = (level + 1).min(top);
            } else if level == 0 {
                return Some((a, b, inv_a));
            } else {
                level -= 1;
            }
        }
    }

    /// The hit record of the sample at (major `a`, minor `b`) with ray 1/z `inv`.
    fn hit(&self, m: &March, o: Vec3, d: Vec3, a: i32, b: f32, inv: f32) -> RealHit {
        let (u, v) = m.untranspose(a as f32, b);
        let point = self.camera.back_project(u, v, 1.0 / inv);
        let (px, py) = m.untranspose(a, (b + 0.5) as i32);
        RealHit {
            t: (point - o).dot(d).max(0.0),
            pixel: (px as u32, py as u32),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Image;
    use crate::recording::Intrinsics;
    use crate::rng::Counter;

    const W: u32 = 160;
    const H: u32 = 120;

    fn camera() -> Pinhole {
        Pinhole::new(&Intrinsics::PRIMESENSE, W, H)
    }

    /// The camera 1.5 m above a floor (world y = 0), looking down 30 degrees along +z:
    /// camera x = world -x, camera y (down) and z (forward) in the y-z plane.
    pub(crate) fn floor_camera_pose() -> Affine3A {
        let (s, c) = (30f32.to_radians().sin(), 30f32.to_radians().cos());
        let forward = Vec3::new(0.0, -s, c);
        let right = Vec3::new(-1.0, 0.0, 0.0);
        let down = forward.cross(right);
        Affine3A::from_cols(
            right.into(),
            down.into(),
            forward.into(),
            Vec3::new(0.0, 1.5, -2.0).into(),
        )
    }

    /// Ray-casts world geometry (a floor at y = 0 and an axis-aligned box) into a depth
    /// map seen by `camera` at `pose`; `noise` adds uniform depth noise of that
    /// amplitude and 3 % holes.
    fn render(camera: &Pinhole, pose: Affine3A, noise: f32) -> DepthImage {
        let boxes = crate::objects::Aabb {
            min: Vec3::new(-0.6, 0.0, 0.4),
            max: Vec3::new(0.2, 0.5, 1.0),
        };
        let mut r = Counter::new(&[9, noise.to_bits() as u64]);
        let mut data = Vec::new();
        for v in 0..camera.height {
            for u in 0..camera.width {
                let ray_c = camera.ray(u as f32, v as f32);
                let dir = pose.transform_vector3(ray_c);
                let o = pose.translation.into();
                let mut t = if dir.y < 0.0 {
                    -1.5 / dir.y
                } else {
                    f32::INFINITY
                };
                if let Some((t0, _)) = boxes.ray_span(o, dir.recip(), 0.0, t) {
                    t = t0;
                }
                // t is along ray_c, whose z is 1: depth = t.
                let mut z = if t < 20.0 { t } else { 0.0 };
                if noise > 0.0 {
                    z += noise * (2.0 * r.next_f32() - 1.0);
                    if r.next_f32() < 0.03 {
                        z = 0.0;
                    }
                }
                data.push(z);
            }
        }
        Image::from_vec(camera.width, camera.height, data).unwrap()
    }

    /// Random rays from surface points of the map (and a few from mid-air), in camera
    /// space, with unit directions.
    fn random_rays(depth: &DepthImage, n: usize, seed: u64) -> Vec<(Vec3, Vec3, f32)> {
        let cam = camera();
        let mut r = Counter::new(&[seed]);
        let mut rays = Vec::new();
        while rays.len() < n {
            let (u, v) = (r.next_f32() * W as f32, r.next_f32() * H as f32);
            let z = *depth.at(u as u32, v as u32);
            let z = if depth_is_valid(z) && r.next_f32() < 0.9 {
                z
            } else {
                0.3 + 4.0 * r.next_f32()
            };
            let o = cam.back_project(u.floor(), v.floor(), z);
            let d = Vec3::new(
                2.0 * r.next_f32() - 1.0,
                2.0 * r.next_f32() - 1.0,
                2.0 * r.next_f32() - 1.0,
            )
            .normalize_or(Vec3::Z);
            let t_max = [0.3, 1.0, 3.0, f32::INFINITY][(r.next_u64() % 4) as usize];
            rays.push((o, d, t_max));
        }
        rays
    }

    #[test]
    fn hierarchical_march_equals_the_linear_march_bit_for_bit() {
        let cam = camera();
        let pose = floor_camera_pose();
        for (noise, thickness) in [(0.0, 0.1), (0.02, 0.05), (0.05, 0.3)] {
            let depth = render(&cam, pose, noise);
            let params = TraceParams {
                thickness,
                ..Default::default()
            };
            let tracer = ScreenTracer::new(&depth, cam, pose, params);
            let (mut hits, mut iterations, mut traced) = (0, 0u64, 0);
            for (o, d, t_max) in random_rays(&depth, 20_000, noise.to_bits() as u64) {
                let (ow, dw) = (pose.transform_point3(o), pose.transform_vector3(d));
                let linear = tracer.trace_linear(ow, dw, t_max);
                let to_camera = tracer.world_to_camera();
                let (oc, dc) = (
                    to_camera.transform_point3(ow),
                    to_camera.transform_vector3(dw),
                );
                let mut n = 0;
                let fast = tracer.trace_camera_counting(oc, dc, t_max, &mut n);
                assert_eq!(
                    fast.map(|h| (h.t.to_bits(), h.pixel)),
                    linear.map(|h| (h.t.to_bits(), h.pixel)),
                    "ray {o} {d} {t_max}"
                );
                assert_eq!(tracer.trace(ow, dw, t_max), fast);
                hits += linear.is_some() as u32;
                iterations += n as u64;
                traced += (n > 0) as u32;
            }
            println!(
                "noise {noise}: {hits} hits of 20000, {:.1} iterations per marched ray",
                iterations as f64 / traced as f64
            );
            assert!(
                hits > 3_000,
                "the scene is hit often enough to test: {hits}"
            );
        }
    }

    #[test]
    fn a_ray_down_to_the_floor_hits_where_geometry_says() {
        let cam = camera();
        let pose = floor_camera_pose();
        let depth = render(&cam, pose, 0.0);
        let tracer = ScreenTracer::new(&depth, cam, pose, TraceParams::default());
        // From 1 m above the floor point (0.8, 0, 2.5) straight down.
        let origin = Vec3::new(0.8, 1.0, 2.5);
        let hit = tracer.trace(origin, -Vec3::Y, 5.0).expect("the floor");
        assert!((hit.t - 1.0).abs() < 0.02, "t = {}", hit.t);
        let expected = cam
            .pixel_of(pose.inverse().transform_point3(Vec3::new(0.8, 0.0, 2.5)))
            .unwrap();
        let (du, dv) = (
            hit.pixel.0 as i32 - expected.0 as i32,
            hit.pixel.1 as i32 - expected.1 as i32,
        );
        assert!(
            du.abs() <= 1 && dv.abs() <= 1,
            "{:?} vs {expected:?}",
            hit.pixel
        );
        // Upward from the same point: nothing but air.
        assert_eq!(tracer.trace(origin, Vec3::Y, 5.0), None);
        // Too short to reach the floor.
        assert_eq!(tracer.trace(origin, -Vec3::Y, 0.5), None);
    }

    #[test]
    fn degenerate_inputs_find_nothing() {
        let cam = camera();
        let pose = floor_camera_pose();
        let holes = Image::filled(W, H, 0.0);
        let tracer = ScreenTracer::new(&holes, cam, pose, TraceParams::default());
        let o = pose.transform_point3(Vec3::new(0.0, 0.0, 2.0));
        for d in [
            Vec3::X,
            Vec3::Y,
            -Vec3::Z,
            Vec3::new(0.3, -0.2, 0.9).normalize(),
        ] {
            assert_eq!(tracer.trace(o, d, f32::INFINITY), None);
        }
        let empty = Image::filled(0, 0, 0.0);
        let tracer = ScreenTracer::new(
            &empty,
            Pinhole::new(&Intrinsics::PRIMESENSE, 0, 0),
            pose,
            TraceParams::default(),
        );
        assert_eq!(tracer.trace(o, Vec3::X, 1.0), None);
        // NaN directions and origins behind the camera.
        let depth = render(&cam, pose, 0.0);
        let tracer = ScreenTracer::new(&depth, cam, pose, TraceParams::default());
        assert_eq!(
            tracer.trace_camera(Vec3::new(0.0, 0.0, 1.0), Vec3::NAN, 1.0),
            None
        );
        assert_eq!(
            tracer.trace_camera(Vec3::new(0.0, 0.0, -1.0), Vec3::Z, 9.0),
            None
        );
    }
}
