//! Interreflection in the synthetic room: the diffuse surfaces light each other, solved
//! once for the static room ([`room`]) onto the texel atlas of [`super::indirect`].
//!
//! The solution holds, per texel centre, the irradiance that arrives from the room itself
//! (everything but the lights' direct light), found by Jacobi iteration of the rendering
//! equation for Lambertian surfaces:
//!
//! E_ind^(k)(x) = mean over cosine-distributed directions w of rho(y) (E_dir(y) + E_ind^(k-1)(y)),
//!
//! where y is the first surface along w from x, rho its albedo and E_dir its direct
//! irradiance from the two area lights and the lamp when it is on (cosine sampling makes the estimator of
//! E = integral of L cos dw the mean of pi L = rho E). Rays that reach a light add
//! nothing here: the lights' radiance is direct light, sampled on their area by the
//! renderer. Iteration stops after [`MAX_BOUNCES`] or when a bounce adds less than
//! [`CONVERGED`] of the total.
//!
//! The solution is a fixed function of the scene: its random numbers are keyed by
//! [`SOLUTION_SEED`], not by a recording's seed, so every recording of the room shows the
//! same interreflection and the truth renderer reads the same solution.

use super::indirect::{IndirectLight, Texel};
use super::room::Surface;
use super::scene::{AxisBox, Ray, Scene, direct_irradiance};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::rng::Counter;
use std::f32::consts::PI;
use std::sync::{Arc, OnceLock};

/// The most light bounces solved.
pub const MAX_BOUNCES: usize = 32;
/// A bounce that adds less than this fraction of the irradiance so far ends the solution.
pub const CONVERGED: f32 = 0.002;
/// Cosine-distributed gather rays per texel of the first bounce (the direct light
/// reflected once: sharp shadows and the lights' bright patches), a stratified grid.
pub const FIRST_GATHER_GRID: (u32, u32) = (16, 16);
/// Gather rays per texel of each later bounce, whose light is already smooth.
pub const LATER_GATHER_GRID: (u32, u32) = (8, 8);
/// Stratified shadow rays per light of a texel's direct irradiance.
pub const DIRECT_GRID: (u32, u32) = (8, 8);
/// The key of the solution's random numbers.
pub const SOLUTION_SEED: u64 = 0x4749_524f_4f4d;
/// Purpose keys of the solution's random numbers.
const DIRECT_PURPOSE: u64 = 11;
const GATHER_PURPOSE: u64 = 12;

/// The room every synthetic recording shows, with its interreflection (solved on the
/// first call, in about a second on two cores, and kept for the process): the panel
/// on, the lamp off.
pub fn room() -> Scene {
    room_lit(RoomLights::default())
}

/// Which of the room's switchable lights are on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RoomLights {
    /// The ceiling panel (on unless switched off).
    pub panel: bool,
    /// The lamp ([`super::lamp`], off unless switched on).
    pub lamp: bool,
}

impl Default for RoomLights {
    fn default() -> Self {
        RoomLights {
            panel: true,
            lamp: false,
        }
    }
}

/// The room lit by `lights`, with its own interreflection, solved on the first call for
/// those lights and kept for the process. A panel switched off keeps its rectangle with
/// zero emission (it looks black) and its light samples are still drawn, so the
/// window's samples, and their noise, are those of the lit room; the lamp draws no
/// random numbers.
pub fn room_lit(lights: RoomLights) -> Scene {
    static ROOMS: [OnceLock<Scene>; 4] = [const { OnceLock::new() }; 4];
    let index = usize::from(lights.panel) | usize::from(lights.lamp) << 1;
    ROOMS[index]
        .get_or_init(|| {
            let mut scene = Scene::room_without_interreflection();
            if !lights.panel {
                scene.lights[PANEL].radiance = Vec3::ZERO;
            }
            if lights.lamp {
                scene.lamp = Some(super::lamp::room_lamp());
            }
            scene.indirect = Some(Arc::new(solve(&scene)));
            scene
        })
        .clone()
}

/// Index of the ceiling panel in [`Scene::lights`].
pub const PANEL: usize = 0;

/// Solves the interreflection of `scene` (its lights, boxes, sphere and room).
pub fn solve(scene: &Scene) -> IndirectLight {
    let mut layout = layout_of(scene);
    let texels = layout.texels(&scene.ball);
    layout.open = texels.iter().map(|t| is_open(scene, t)).collect();
    let direct: Vec<Vec3> = texels
        .par_iter()
        .enumerate()
        .map(|(i, t)| {
            let mut rng = Counter::new(&[SOLUTION_SEED, DIRECT_PURPOSE, i as u64]);
            direct_irradiance(scene, t.position, t.normal, &mut rng, DIRECT_GRID)
        })
        .collect();
    // Bounce k's light is gathered from bounce k - 1's alone (the direct light for
    // the first), and the bounces are summed.
    let mut previous = IndirectLight {
        irradiance: direct,
        ..layout.clone()
    };
    let mut solution = IndirectLight {
        irradiance: vec![Vec3::ZERO; texels.len()],
        ..layout
    };
    let total = |v: &[Vec3]| v.iter().map(|e| e.element_sum() as f64).sum::<f64>();
    let direct_total = total(&previous.irradiance);
    for bounce in 0..MAX_BOUNCES {
        let grid = if bounce == 0 {
            FIRST_GATHER_GRID
        } else {
            LATER_GATHER_GRID
        };
        let next: Vec<Vec3> = texels
            .par_iter()
            .enumerate()
            .map(|(i, t)| {
                if !solution.open[i] {
                    return Vec3::ZERO;
                }
                let mut rng =
                    Counter::new(&[SOLUTION_SEED, GATHER_PURPOSE, bounce as u64, i as u64]);
                gather(scene, t, &previous, &mut rng, grid)
            })
            .collect();
        for (sum, added) in solution.irradiance.iter_mut().zip(&next) {
            *sum += *added;
        }
        solution.bounces = bounce + 1;
        let added = total(&next);
        previous.irradiance = next;
        if added < CONVERGED as f64 * (direct_total + total(&solution.irradiance)) {
            break;
        }
    }
    solution
}

/// The atlas of `scene`'s surfaces, with no values yet.
fn layout_of(scene: &Scene) -> IndirectLight {
    IndirectLight::layout(
        &scene.room,
        scene.blocks.iter().map(|b| b.bounds),
        &scene.ball,
    )
}

/// Whether light can reach texel `t`: a point just off it, on its normal's side, lies
/// inside the room and outside every box and the sphere.
fn is_open(scene: &Scene, t: &Texel) -> bool {
    let p = t.position + t.normal * 1e-3;
    let inside = |b: &AxisBox| p.cmpgt(b.min).all() && p.cmplt(b.max).all();
    inside(&scene.room)
        && !scene.blocks.iter().any(|b| inside(&b.bounds))
        && (t.surface == Surface::Ball || p.distance(scene.ball.center) > scene.ball.radius)
}

/// One bounce at texel `t`: the mean over `grid` stratified cosine-distributed rays of
/// rho(y) E(y), E being the previous bounce's irradiance `previous` at the first
/// surface y each ray meets (lights add nothing: they are direct light).
fn gather(
    scene: &Scene,
    t: &Texel,
    previous: &IndirectLight,
    rng: &mut Counter,
    grid: (u32, u32),
) -> Vec3 {
    let origin = t.position + t.normal * 1e-4;
    let (tangent, bitangent) = t.normal.any_orthonormal_pair();
    let (gu, gv) = grid;
    let mut sum = Vec3::ZERO;
    for j in 0..gv {
        for i in 0..gu {
            let u1 = (j as f32 + rng.next_f32()) / gv as f32;
            let u2 = (i as f32 + rng.next_f32()) / gu as f32;
            let r = u1.sqrt();
            let (s, c) = (2.0 * PI * u2).sin_cos();
            let z = (1.0 - u1).max(0.0).sqrt();
            let direction = tangent * (r * c) + bitangent * (r * s) + t.normal * z;
            let Some(hit) = scene.intersect(&Ray { origin, direction }, 0.0) else {
                continue;
            };
            let material = scene.material(&hit);
            if material.emission != Vec3::ZERO {
                continue;
            }
            sum += material.albedo * previous.at(&hit);
        }
    }
    sum / (gu * gv) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids_cover_every_surface_and_lookups_land_on_their_texel() {
        let scene = Scene::room_without_interreflection();
        let layout = layout_of(&scene);
        // Floor and ceiling 100 x 100, four walls 100 x 52, the boxes' five faces each,
        // the sphere 22 x 44.
        assert_eq!(layout.faces.len(), 6 + 4 * 5);
        assert_eq!((layout.sphere.n_theta, layout.sphere.n_phi), (22, 44));
        let texels = layout.texels(&scene.ball);
        assert_eq!(texels.len(), layout.irradiance.len());
        // Each texel's own lookup returns its own value.
        let mut marked = layout.clone();
        for (k, v) in marked.irradiance.iter_mut().enumerate() {
            *v = Vec3::splat(k as f32);
        }
        for (k, t) in texels.iter().enumerate().step_by(97) {
            let got = marked.lookup(t.surface, t.position, t.normal);
            let error = (got - Vec3::splat(k as f32)).abs().max_element();
            assert!(!marked.open[k] || error < 0.01, "texel {k}: {got}");
        }
    }

    /// The share of the irradiance at `position` (normal `normal`) that comes from the
    /// room itself rather than straight from the lights.
    fn room_share(scene: &Scene, surface: Surface, position: Vec3, normal: Vec3) -> f32 {
        let mut rng = Counter::new(&[7]);
        let direct = direct_irradiance(scene, position, normal, &mut rng, (32, 32));
        let indirect = scene
            .indirect
            .as_ref()
            .unwrap()
            .lookup(surface, position, normal);
        indirect.element_sum() / (direct + indirect).element_sum()
    }

    #[test]
    fn the_room_lights_itself() {
        let started = std::time::Instant::now();
        let scene = room();
        let solution = scene.indirect.as_ref().unwrap();
        eprintln!(
            "solved in {:?}, {} bounces",
            started.elapsed(),
            solution.bounces
        );
        assert!(solution.bounces >= 3);
        // On the floor beside a wall: 10 cm from the west wall's green paint and the
        // south wall's red, away from the boxes.
        for (name, p) in [
            ("west", Vec3::new(-2.4, 0.0, -0.3)),
            ("south", Vec3::new(0.3, 0.0, 2.4)),
            ("middle", Vec3::new(0.0, 0.0, 0.0)),
        ] {
            let share = room_share(&scene, Surface::Floor, p, Vec3::Y);
            eprintln!(
                "floor beside the {name} wall at {p}: {:.1} % from the room",
                100.0 * share
            );
            if name != "middle" {
                assert!(share >= 0.10, "{name}: {share}");
            }
        }
        // Colour bleeding: the floor beside the red south wall gets redder indirect light
        // than the floor beside the green west wall.
        let west = solution.lookup(Surface::Floor, Vec3::new(-2.4, 0.0, -0.3), Vec3::Y);
        let south = solution.lookup(Surface::Floor, Vec3::new(0.3, 0.0, 2.4), Vec3::Y);
        assert!(
            south.x / south.y > west.x / west.y,
            "south {south} west {west}"
        );
        // The ceiling, which no light reaches directly, is lit by the room alone.
        let ceiling = solution.lookup(Surface::Ceiling, Vec3::new(2.0, 2.6, 2.0), Vec3::NEG_Y);
        assert!(ceiling.min_element() > 0.0, "{ceiling}");
    }
}
