//! Interreflection in the synthetic room: the diffuse surfaces light each other, solved
//! once for the static room and looked up per shaded point.
//!
//! Every surface of the room (floor, ceiling, the four walls, the visible faces of the
//! boxes, the sphere) is covered by a grid of texels about [`TEXEL_M`] on a side. The
//! solution holds, per texel centre, the irradiance that arrives from the room itself
//! (everything but the lights' direct light), found by Jacobi iteration of the rendering
//! equation for Lambertian surfaces:
//!
//! E_ind^(k)(x) = mean over cosine-distributed directions w of rho(y) (E_dir(y) + E_ind^(k-1)(y)),
//!
//! where y is the first surface along w from x, rho its albedo and E_dir its direct
//! irradiance from the two area lights (cosine sampling makes the estimator of
//! E = integral of L cos dw the mean of pi L = rho E). Rays that reach a light add
//! nothing here: the lights' radiance is direct light, sampled on their area by the
//! renderer. Iteration stops after [`MAX_BOUNCES`] or when a bounce adds less than
//! [`CONVERGED`] of the total.
//!
//! A shaded point reads E_ind by bilinear interpolation of its surface's grid, over the
//! texels whose centres are open (not inside a box, the sphere or behind a wall), so that
//! the dark inside of a box does not bleed into the floor around it.
//!
//! The solution is a fixed function of the scene: its random numbers are keyed by
//! [`SOLUTION_SEED`], not by a recording's seed, so every recording of the room shows the
//! same interreflection and the truth renderer reads the same solution.

use super::render::direct_irradiance;
use super::room::Surface;
use super::scene::{AxisBox, Hit, Ray, Scene};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::rng::Counter;
use std::f32::consts::PI;

/// Side of a texel of the solution, metres (rounded per surface to a whole count).
pub const TEXEL_M: f32 = 0.05;
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

/// A grid of texels over one planar face: texel (i, j) is centred at
/// `corner + (i + 0.5) / nu * edge_u + (j + 0.5) / nv * edge_v`.
#[derive(Clone, Debug, PartialEq)]
struct FaceGrid {
    surface: Surface,
    corner: Vec3,
    edge_u: Vec3,
    edge_v: Vec3,
    /// Unit normal pointing into the room (the side light arrives from).
    normal: Vec3,
    nu: usize,
    nv: usize,
    /// Index of texel (0, 0) in the solution's arrays.
    first: usize,
}

/// The sphere's grid: `n_theta` rings from +y down, `n_phi` columns from +x towards +z.
#[derive(Clone, Debug, PartialEq)]
struct SphereGrid {
    n_theta: usize,
    n_phi: usize,
    first: usize,
}

/// The room's interreflection: indirect irradiance per texel of every surface.
#[derive(Clone, Debug, PartialEq)]
pub struct IndirectLight {
    faces: Vec<FaceGrid>,
    sphere: SphereGrid,
    /// Indirect irradiance per texel (linear RGB).
    irradiance: Vec<Vec3>,
    /// Whether each texel's centre is open (a surface point light can reach).
    open: Vec<bool>,
    /// Bounces solved.
    pub bounces: usize,
}

/// A texel centre to solve at: position, unit normal and its surface.
struct Texel {
    position: Vec3,
    normal: Vec3,
    surface: Surface,
}

impl IndirectLight {
    /// Solves the interreflection of `scene` (its lights, boxes, sphere and room).
    pub fn solve(scene: &Scene) -> IndirectLight {
        let mut layout = IndirectLight::layout(scene);
        let texels = layout.texels(scene);
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

    /// The grids of `scene`'s surfaces, with no values yet.
    fn layout(scene: &Scene) -> IndirectLight {
        let mut faces = Vec::new();
        let mut count = 0usize;
        let mut add = |surface, corner: Vec3, edge_u: Vec3, edge_v: Vec3, normal: Vec3| {
            let nu = (edge_u.length() / TEXEL_M).ceil().max(1.0) as usize;
            let nv = (edge_v.length() / TEXEL_M).ceil().max(1.0) as usize;
            faces.push(FaceGrid {
                surface,
                corner,
                edge_u,
                edge_v,
                normal,
                nu,
                nv,
                first: count,
            });
            count += nu * nv;
        };
        for (surface, b, normal) in box_faces(&scene.room, true) {
            add(surface, b.0, b.1, b.2, normal);
        }
        for (i, block) in scene.blocks.iter().enumerate() {
            for (_, b, normal) in box_faces(&block.bounds, false) {
                // The bottom face stands on the floor: nothing reaches it.
                if normal != Vec3::NEG_Y {
                    add(Surface::Block(i), b.0, b.1, b.2, normal);
                }
            }
        }
        let r = scene.ball.radius;
        let n_theta = (PI * r / TEXEL_M).ceil().max(2.0) as usize;
        let n_phi = (2.0 * PI * r / TEXEL_M).ceil().max(3.0) as usize;
        let sphere = SphereGrid {
            n_theta,
            n_phi,
            first: count,
        };
        count += n_theta * n_phi;
        IndirectLight {
            faces,
            sphere,
            irradiance: vec![Vec3::ZERO; count],
            open: vec![true; count],
            bounces: 0,
        }
    }

    /// Every texel centre, in the order of the solution's arrays.
    fn texels(&self, scene: &Scene) -> Vec<Texel> {
        let mut texels = Vec::with_capacity(self.irradiance.len());
        for f in &self.faces {
            for j in 0..f.nv {
                for i in 0..f.nu {
                    let u = (i as f32 + 0.5) / f.nu as f32;
                    let v = (j as f32 + 0.5) / f.nv as f32;
                    texels.push(Texel {
                        position: f.corner + f.edge_u * u + f.edge_v * v,
                        normal: f.normal,
                        surface: f.surface,
                    });
                }
            }
        }
        let ball = &scene.ball;
        for j in 0..self.sphere.n_theta {
            for i in 0..self.sphere.n_phi {
                let n = sphere_direction(
                    (j as f32 + 0.5) / self.sphere.n_theta as f32,
                    (i as f32 + 0.5) / self.sphere.n_phi as f32,
                );
                texels.push(Texel {
                    position: ball.center + n * ball.radius,
                    normal: n,
                    surface: Surface::Ball,
                });
            }
        }
        texels
    }

    /// The indirect irradiance at `hit` (zero on surfaces the solution does not cover).
    pub fn at(&self, hit: &Hit) -> Vec3 {
        self.lookup(hit.surface, hit.position, hit.normal)
    }

    /// The indirect irradiance at `position` on `surface`, whose normal towards the
    /// room is `normal`.
    pub fn lookup(&self, surface: Surface, position: Vec3, normal: Vec3) -> Vec3 {
        if surface == Surface::Ball {
            return self.sphere_lookup(position, normal);
        }
        let Some(f) = self.faces.iter().find(|f| {
            f.surface == surface && (!matches!(surface, Surface::Block(_)) || f.normal == normal)
        }) else {
            return Vec3::ZERO;
        };
        let d = position - f.corner;
        let s = d.dot(f.edge_u) / f.edge_u.length_squared() * f.nu as f32 - 0.5;
        let t = d.dot(f.edge_v) / f.edge_v.length_squared() * f.nv as f32 - 0.5;
        self.bilinear(f.first, f.nu, f.nv, s, t, false)
    }

    fn sphere_lookup(&self, _position: Vec3, normal: Vec3) -> Vec3 {
        let g = &self.sphere;
        let theta = normal.y.clamp(-1.0, 1.0).acos() / PI;
        let phi = normal.z.atan2(normal.x).rem_euclid(2.0 * PI) / (2.0 * PI);
        let s = phi * g.n_phi as f32 - 0.5;
        let t = theta * g.n_theta as f32 - 0.5;
        self.bilinear(g.first, g.n_phi, g.n_theta, s, t, true)
    }

    /// Bilinear interpolation of the `nu` x `nv` grid starting at `first` at texel
    /// coordinates (s, t) (texel centres at whole numbers), over its open texels only;
    /// `wrap_u` wraps the u direction (the sphere's longitude).
    fn bilinear(&self, first: usize, nu: usize, nv: usize, s: f32, t: f32, wrap_u: bool) -> Vec3 {
        let t = t.clamp(0.0, (nv - 1) as f32);
        let s = if wrap_u {
            s.rem_euclid(nu as f32)
        } else {
            s.clamp(0.0, (nu - 1) as f32)
        };
        let (i0, j0) = (s.floor() as usize, t.floor() as usize);
        let (fs, ft) = (s - i0 as f32, t - j0 as f32);
        let i1 = if wrap_u {
            (i0 + 1) % nu
        } else {
            (i0 + 1).min(nu - 1)
        };
        let j1 = (j0 + 1).min(nv - 1);
        let mut sum = Vec3::ZERO;
        let mut weight = 0.0f32;
        for (i, j, w) in [
            (i0 % nu, j0, (1.0 - fs) * (1.0 - ft)),
            (i1, j0, fs * (1.0 - ft)),
            (i0 % nu, j1, (1.0 - fs) * ft),
            (i1, j1, fs * ft),
        ] {
            let k = first + j * nu + i;
            if self.open[k] && w > 0.0 {
                sum += self.irradiance[k] * w;
                weight += w;
            }
        }
        if weight > 0.0 {
            sum / weight
        } else {
            // No open texel around: the nearest one's value, open or not.
            let i = (s.round() as usize).min(nu - 1);
            let j = (t.round() as usize).min(nv - 1);
            self.irradiance[first + j * nu + i]
        }
    }
}

/// The unit direction at fractions (`theta`, `phi`) of the sphere grid: theta from +y,
/// phi from +x towards +z.
fn sphere_direction(theta: f32, phi: f32) -> Vec3 {
    let (st, ct) = (theta * PI).sin_cos();
    let (sp, cp) = (phi * 2.0 * PI).sin_cos();
    Vec3::new(st * cp, ct, st * sp)
}

/// The faces of box `b` as (surface, (corner, edge_u, edge_v), normal): for the room's
/// interior (`inside`) the six room surfaces with inward normals, otherwise the box's
/// faces with outward normals (surface `Floor` as a placeholder).
fn box_faces(b: &AxisBox, inside: bool) -> Vec<(Surface, (Vec3, Vec3, Vec3), Vec3)> {
    let (lo, hi) = (b.min, b.max);
    let size = hi - lo;
    let (ex, ey, ez) = (
        Vec3::new(size.x, 0.0, 0.0),
        Vec3::new(0.0, size.y, 0.0),
        Vec3::new(0.0, 0.0, size.z),
    );
    let sign = if inside { -1.0 } else { 1.0 };
    vec![
        (Surface::WestWall, (lo, ez, ey), Vec3::NEG_X * sign),
        (
            Surface::EastWall,
            (Vec3::new(hi.x, lo.y, lo.z), ez, ey),
            Vec3::X * sign,
        ),
        (Surface::Floor, (lo, ex, ez), Vec3::NEG_Y * sign),
        (
            Surface::Ceiling,
            (Vec3::new(lo.x, hi.y, lo.z), ex, ez),
            Vec3::Y * sign,
        ),
        (Surface::NorthWall, (lo, ex, ey), Vec3::NEG_Z * sign),
        (
            Surface::SouthWall,
            (Vec3::new(lo.x, lo.y, hi.z), ex, ey),
            Vec3::Z * sign,
        ),
    ]
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
        let layout = IndirectLight::layout(&scene);
        // Floor and ceiling 100 x 100, four walls 100 x 52, the boxes' five faces each,
        // the sphere 22 x 44.
        assert_eq!(layout.faces.len(), 6 + 4 * 5);
        assert_eq!((layout.sphere.n_theta, layout.sphere.n_phi), (22, 44));
        let texels = layout.texels(&scene);
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
        let scene = Scene::room();
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
