//! Environment Mapping and Distance Impostor Tracing over a distance impostor (paper 000
//! Sec. 6.1; the tracing after Szirmay-Kalos et al., "Approximate Ray-Tracing on the
//! GPU with Distance Impostors", 2005).
//!
//! The impostor is an [`EnvMap`] seen from its `center`, with per texel the radiance
//! and the distance from the centre of the surface that sent it. A ray from a point
//! `o` (relative to the centre) along unit `d`:
//!
//! - **EM** (0 iterations) looks the radiance up in direction `d`, as if `o` were the
//!   centre, and takes the texel's stored distance as the distance of the light.
//! - **DIT** refines the lookup. It seeks where the ray crosses the stored surface:
//!   the root of g(t) = |o + t d| - r(t), r(t) being the distance the map stores in
//!   the direction of the ray's point (negative in front of the surface, positive
//!   behind it). Each of the `iterations` steps is one read of the map. The search
//!   starts [`START_DISTANCE`] along the ray, past the surface a real shading point
//!   lies on (there g(0) = 0, and a search from the origin finds the point's own
//!   surface: measured by a review, 6 % of cosine rays from a floor 1.2 m below the
//!   centre ended there). The far end is Szirmay-Kalos et al.'s first guess, the ray's
//!   exit from the sphere of radius r(d) about the centre (exact where the surface is a
//!   sphere about the centre), doubled until the ray is behind the surface; then false
//!   position (the Illinois variant) inside that bracket. Repeating the sphere step
//!   alone, as the original method does, converges slowly on surfaces that are not
//!   spheres about the centre (10 cm of mean error after 16 steps in a box room). The
//!   answer is the texel of the best guess. A hole (no distance stored) ends the
//!   search at the best guess so far; an origin already behind the surface at the
//!   start gets the EM answer.
//!
//! The map arrives as `light.impostor`'s lat-long resampling of its cube; the query
//! resamples it once per frame into a cube of `width / 2` texels a side (nearest
//! texel, finer than the lat-long map everywhere), because a cube lookup is a division
//! where a lat-long one is an arc cosine and an arc tangent: measured on the bench
//! frame, the lat-long lookups made `dit` cost 2.5x `em`. Departures from the paper:
//! nearest-texel reads, not bilinear; no cone casts (the paper's coarser final fetch for
//! a cone's solid angle): every query is a thin ray.

use super::interface::{Hit, RadianceQuery, Ray, Source};
use glam::Vec3;
use rayon::prelude::*;
use relume_scene::light::impostor::cube_texel_direction;
use relume_scene::light::{CubeImpostor, EnvMap};

/// The most refinement steps [`ImpostorQuery::trace`] takes.
pub const MAX_ITERATIONS: u32 = 64;

/// Metres along the ray where the search for the stored surface starts: past the
/// surface the ray leaves (a real shading point lies on a surface the impostor
/// stores, so g(0) = 0 there), about the radius of `light.impostor`'s splats.
pub const START_DISTANCE: f32 = 0.05;

/// The search also starts at least this fraction of the origin's distance from the
/// centre along the ray: the stored surface is quantized to texels, whose radial
/// error grows with the distance (the floor seen at a grazing angle from the centre is
/// a staircase of steps a few centimetres high at 3 m).
pub const START_FRACTION: f32 = 0.05;

/// The largest cube face the query resamples a map to (6 x 256^2 texels, 9 MB): finer
/// than `light.impostor`'s default 256 x 128 map everywhere.
pub const MAX_FACE_SIZE: u32 = 256;

/// Where a ray meets the impostor: the cube texel whose radiance arrives, and the
/// distance along the ray (metres; infinite for a hole or a distant map).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracedImpostor {
    pub texel: usize,
    pub t: f32,
}

/// The far intersection of `o + t d` (relative to the centre, `d` unit) with the sphere
/// of radius `r` about the centre, when r is finite and the intersection lies ahead.
#[inline]
fn sphere_exit(o: Vec3, d: Vec3, r: f32) -> Option<f32> {
    if !r.is_finite() {
        return None;
    }
    let b = o.dot(d);
    let disc = b * b - (o.length_squared() - r * r);
    if disc < 0.0 {
        return None;
    }
    let t = -b + disc.sqrt();
    (t >= 0.0).then_some(t)
}

/// The distance impostor as a [`RadianceQuery`]: every ray meets the environment
/// ([`Source::Environment`]) at the traced distance, with the radiance of the texel it
/// ends in.
#[derive(Clone, Debug)]
pub struct ImpostorQuery {
    /// The map resampled to a cube (radiance and distance per texel).
    pub cube: CubeImpostor,
    /// The world position the map is seen from.
    pub center: Vec3,
    /// Refinement steps: 0 = Environment Mapping, more = Distance Impostor Tracing.
    pub iterations: u32,
}

impl ImpostorQuery {
    /// The query over `map` (its radiance and distances resampled to a cube of
    /// `map.width / 2` texels a side, at least 8 and at most [`MAX_FACE_SIZE`]; texels
    /// whose radiance is not finite bring none), with `iterations` refinement steps.
    /// The error says what is wrong with the map.
    pub fn new(map: &EnvMap, iterations: u32) -> Result<ImpostorQuery, String> {
        let texels = map.width as usize * map.height as usize;
        if texels == 0 || map.radiance.len() != texels || map.distance.len() != texels {
            return Err(format!(
                "the environment map is {}x{} with {} radiance and {} distance texels",
                map.width,
                map.height,
                map.radiance.len(),
                map.distance.len()
            ));
        }
        if !map.center.is_finite() {
            return Err("the environment map's centre is not finite".into());
        }
        let face_size = (map.width / 2).clamp(8, MAX_FACE_SIZE);
        let n = face_size as usize;
        let mut cube = CubeImpostor {
            face_size,
            radiance: vec![Vec3::ZERO; 6 * n * n],
            distance: vec![f32::INFINITY; 6 * n * n],
        };
        cube.radiance
            .par_chunks_mut(n)
            .zip(cube.distance.par_chunks_mut(n))
            .enumerate()
            .for_each(|(row, (radiance, distance))| {
                for i in 0..n {
                    let texel = map.texel_of(cube_texel_direction(face_size, row * n + i));
                    let l = map.radiance[texel];
                    radiance[i] = if l.is_finite() { l } else { Vec3::ZERO };
                    distance[i] = map.distance[texel];
                }
            });
        Ok(ImpostorQuery {
            cube,
            center: map.center,
            iterations,
        })
    }

    /// Traces the ray `origin + t dir` (world, `dir` unit) with the query's
    /// refinement steps (0 = Environment Mapping; see the module docs).
    pub fn trace(&self, origin: Vec3, dir: Vec3) -> TracedImpostor {
        let cube = &self.cube;
        let first = cube.texel_of(dir);
        let r_first = cube.distance[first];
        let em = TracedImpostor {
            texel: first,
            t: r_first,
        };
        if self.iterations == 0 || !r_first.is_finite() {
            // Environment Mapping; or a hole or a distant map along the ray's own
            // direction, with nothing to refine by.
            return em;
        }
        let o = origin - self.center;
        // g(t) = |o + t d| - r: negative in front of the stored surface, positive
        // behind it; `None` at a hole (no distance stored there).
        let gap = |t: f32| {
            let p = o + dir * t;
            let at = cube.texel_of(p);
            let r = cube.distance[at];
            r.is_finite().then(|| (p.length() - r, at))
        };
        let mut steps = self.iterations.min(MAX_ITERATIONS);
        let step = |t: f32, steps: &mut u32| {
            *steps = steps.saturating_sub(1);
            gap(t)
        };
        // Szirmay-Kalos et al.'s first guess: the ray's exit from the sphere of the
        // distance stored along it (exact where the surface is a sphere about the
        // centre); without one ahead, a step of that distance.
        let start = START_DISTANCE.max(START_FRACTION * o.length());
        let mut hi = sphere_exit(o, dir, r_first)
            .filter(|&t| t > start)
            .unwrap_or(start + r_first);
        let Some((mut g_hi, at)) = step(hi, &mut steps) else {
            return em;
        };
        let mut best = (g_hi.abs(), hi, at);
        // The low end: a point in front of the stored surface, past the surface the
        // ray leaves (a real shading point lies on a stored surface: g(0) = 0).
        let mut lo = start;
        let mut g_lo = -1.0;
        if g_hi < 0.0 {
            // In front of the surface still: push on until behind it.
            while g_hi < 0.0 && steps > 0 {
                (lo, g_lo) = (hi, g_hi);
                hi *= 2.0;
                let Some((g, at)) = step(hi, &mut steps) else {
                    break;
                };
                if g.abs() < best.0 {
                    best = (g.abs(), hi, at);
                }
                g_hi = g;
            }
        } else if steps > 0 {
            match step(lo, &mut steps) {
                Some((g, _)) if g < 0.0 => g_lo = g,
                // The origin is behind the stored surface at the start: no crossing
                // ahead to refine towards.
                _ => {
                    return TracedImpostor {
                        texel: best.2,
                        t: best.1,
                    };
                }
            }
        }
        // False position inside [lo, hi], with the Illinois halving of the end that
        // stays, so that both ends move.
        let mut kept_end = 0i8;
        while steps > 0 && g_hi >= 0.0 && g_lo < 0.0 {
            let t = lo - g_lo * (hi - lo) / (g_hi - g_lo);
            let Some((g, at)) = step(t, &mut steps) else {
                break;
            };
            best = (g.abs(), t, at);
            if g < 0.0 {
                (lo, g_lo) = (t, g);
                if kept_end == 1 {
                    g_hi *= 0.5;
                }
                kept_end = 1;
            } else {
                (hi, g_hi) = (t, g);
                if kept_end == -1 {
                    g_lo *= 0.5;
                }
                kept_end = -1;
            }
            if g == 0.0 {
                break;
            }
        }
        TracedImpostor {
            texel: best.2,
            t: best.1,
        }
    }
}

impl RadianceQuery for ImpostorQuery {
    #[inline]
    fn query(&self, ray: &Ray) -> Option<Hit> {
        let traced = self.trace(ray.origin, ray.dir);
        (traced.t <= ray.t_max).then(|| Hit {
            t: traced.t,
            radiance: self.cube.radiance[traced.texel],
            source: Source::Environment,
        })
    }
}
