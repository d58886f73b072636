//! The room's interreflection as a texel atlas: the indirect irradiance on every surface
//! of the synthetic room, and its lookup at a shaded point. [`super::interreflection`]
//! solves it.
//!
//! Every surface of the room (floor, ceiling, the four walls, the visible faces of the
//! boxes, the sphere) is covered by a grid of texels about [`TEXEL_M`] on a side, each
//! holding the irradiance that arrives at its centre from the room itself (everything but
//! the lights' direct light).
//!
//! A shaded point reads it by bilinear interpolation of its surface's grid, over the
//! texels whose centres are open (not inside a box, the sphere or behind a wall), so that
//! the dark inside of a box does not bleed into the floor around it.

use super::geometry::{AxisBox, Hit, Sphere};
use super::room::Surface;
use glam::Vec3;
use std::f32::consts::PI;

/// Side of a texel of the solution, metres (rounded per surface to a whole count).
pub const TEXEL_M: f32 = 0.05;
/// A grid of texels over one planar face: texel (i, j) is centred at
/// `corner + (i + 0.5) / nu * edge_u + (j + 0.5) / nv * edge_v`.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct FaceGrid {
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
pub(super) struct SphereGrid {
    pub(super) n_theta: usize,
    pub(super) n_phi: usize,
    first: usize,
}

/// The room's interreflection: indirect irradiance per texel of every surface.
#[derive(Clone, Debug, PartialEq)]
pub struct IndirectLight {
    pub(super) faces: Vec<FaceGrid>,
    pub(super) sphere: SphereGrid,
    /// Indirect irradiance per texel (linear RGB).
    pub(super) irradiance: Vec<Vec3>,
    /// Whether each texel's centre is open (a surface point light can reach).
    pub(super) open: Vec<bool>,
    /// Bounces solved.
    pub bounces: usize,
}

/// A texel centre to solve at: position, unit normal and its surface.
pub(super) struct Texel {
    pub(super) position: Vec3,
    pub(super) normal: Vec3,
    pub(super) surface: Surface,
}

impl IndirectLight {
    /// The grids over the inside of `room`, the faces of `blocks` (all but the bottom,
    /// which stands on the floor) and the sphere `ball`, with no values yet: every texel
    /// open, zero irradiance.
    pub fn layout(
        room: &AxisBox,
        blocks: impl IntoIterator<Item = AxisBox>,
        ball: &Sphere,
    ) -> IndirectLight {
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
        for (surface, b, normal) in box_faces(room, true) {
            add(surface, b.0, b.1, b.2, normal);
        }
        for (i, bounds) in blocks.into_iter().enumerate() {
            for (_, b, normal) in box_faces(&bounds, false) {
                // The bottom face stands on the floor: nothing reaches it.
                if normal != Vec3::NEG_Y {
                    add(Surface::Block(i), b.0, b.1, b.2, normal);
                }
            }
        }
        let r = ball.radius;
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

    /// Every texel centre, in the order of the solution's arrays (`ball` the sphere the
    /// layout was made for).
    pub(super) fn texels(&self, ball: &Sphere) -> Vec<Texel> {
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
