//! Precomputed radiance transfer for the virtual objects (paper 004 Sec. 4.4, eqs. 9 and
//! 11, after Sloan, Kautz and Snyder 2002): per vertex, the nine SH coefficients of the
//! transfer function V(x, w) cos(theta), so that the indirect irradiance with the
//! objects' own occlusion is one dot product with the light's SH coefficients.
//!
//! Eq. 11: C_vk = int V(x, w) cos(theta) Y_k(w) dw over the hemisphere of the vertex
//! normal, V = 0 where a ray from the vertex hits a virtual object (any object of the
//! scene: the objects' self-occlusion and their occlusion of each other; the real scene
//! is not an occluder here, its indirect light is what the SH coefficients carry).
//! Eq. 9 then gives E(x) = sum_k C_k C_vk for radiance L = sum_k C_k Y_k, exactly, by
//! the basis' orthonormality: relume keeps irradiance layers, so the rho / pi of eq. 9 is
//! applied by the composite, not here.
//!
//! The integral is estimated with n = `samples` cosine-weighted directions per vertex
//! from the Hammersley set ((i + 1/2) / n, radical inverse of i), shifted modulo 1 by a
//! hashed offset keyed by (seed, vertex) so neighbouring vertices do not share their
//! error: C_vk ~ (pi / n) sum_i V(w_i) Y_k(w_i). Against stratified jitter this halved
//! the worst error on the torus at 4096 directions (1.6 % to 1.0 %: the integrand is
//! discontinuous where the object occludes). For an unoccluded vertex
//! that tends to the clamped-cosine lobe A_l Y_k(n) of Ramamoorthi and Hanrahan, so
//! E equals [`super::sh::sh9_irradiance`] there up to the estimate's noise.
//!
//! Vertices are the distinct (position, normal) corners of the scene's triangles, in the
//! order they first appear; a point on a triangle interpolates its corners' vectors
//! barycentrically, as the paper's vertex shader does. Where the code departs: the paper
//! precomputes per object in object space; here the transfer is computed for the placed
//! (world-space) scene, so it needs no SH rotation and includes the objects' shadows on
//! each other, and it is cached on disk by the scene's digest ([`cache`]).

pub mod cache;
#[cfg(test)]
mod tests;

use super::sh::sh9_basis;
use crate::objects::VirtualScene;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use relume_base::cancel::{self, Cancelled};
use relume_base::rng;
use std::collections::HashMap;

/// Settings of [`Transfer::compute`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransferParams {
    /// Cosine-weighted directions per vertex (at least 1).
    pub samples: u32,
    /// Seed of the jitter.
    pub seed: u64,
}

impl Default for TransferParams {
    fn default() -> Self {
        TransferParams {
            samples: 4096,
            seed: 0,
        }
    }
}

/// Salt of the directions' hashes.
const SALT_DIRECTIONS: u64 = 0x7072_745f_6469_7273;

/// The transfer vectors C_vk of a scene's vertices (eq. 11).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Transfer {
    /// Per triangle corner (3 per triangle, in the scene's order), its vertex index.
    pub corner_vertex: Vec<u32>,
    /// Per vertex, the nine coefficients C_vk, k = 0..9 in [`sh9_basis`]'s order.
    pub vectors: Vec<[f32; 9]>,
    /// Per vertex, the transfer of the light the *other* objects send it (paper 004
    /// Sec. 4.4, Fig. 7 bottom): the paper's own transfer, V cos(theta) with V the
    /// object's occlusion of itself only, B_vk = int [the ray's first hit is not this
    /// vertex's object] cos(theta) Y_k(w) dw, with `vectors`' directions and rays. The
    /// other objects' light is the dot product of B_vk with the SH coefficients of
    /// their radiance as seen from this object's centre (`sample.val` computes those
    /// per frame, as the paper's cube map), while the room's light keeps C_vk, which
    /// the other objects block. (A mask of the directions where the other objects
    /// stand would be exact before the SH projection, but the product of two
    /// projected caps keeps a quarter of their overlap; a smooth lobe keeps the SH9
    /// irradiance's accuracy.) Empty when the scene has fewer than two objects
    /// (objects are told apart by the triangles' material index, one per object in
    /// [`VirtualScene::from_specs`]).
    pub bounce: Vec<[f32; 9]>,
}

/// The distinct (position, normal) corners of `scene` and, per corner, its index among
/// them.
pub fn scene_vertices(scene: &VirtualScene) -> (Vec<(Vec3, Vec3)>, Vec<u32>) {
    let mut index: HashMap<[u32; 6], u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut corner_vertex = Vec::with_capacity(scene.triangles.len() * 3);
    for tri in &scene.triangles {
        for c in 0..3 {
            let (p, n) = (tri.vertices[c], tri.normals[c]);
            let key = [p.x, p.y, p.z, n.x, n.y, n.z].map(f32::to_bits);
            let next = vertices.len() as u32;
            let i = *index.entry(key).or_insert_with(|| {
                vertices.push((p, n));
                next
            });
            corner_vertex.push(i);
        }
    }
    (vertices, corner_vertex)
}

/// The number of objects of `scene`: one more than the largest material index of
/// its triangles (0 for an empty scene).
pub fn object_count(scene: &VirtualScene) -> usize {
    scene
        .triangles
        .iter()
        .map(|t| t.material as usize + 1)
        .max()
        .unwrap_or(0)
}

/// Per vertex, the object (material index) of the first triangle that has it.
fn vertex_objects(scene: &VirtualScene, corner_vertex: &[u32], vertices: usize) -> Vec<u32> {
    let mut owners = vec![u32::MAX; vertices];
    for (corner, &v) in corner_vertex.iter().enumerate() {
        let owner = &mut owners[v as usize];
        if *owner == u32::MAX {
            *owner = scene.triangles[corner / 3].material;
        }
    }
    owners
}

/// The base-2 radical inverse of `i`: bit-reversed, as a fraction in [0, 1).
fn radical_inverse(i: u32) -> f64 {
    i.reverse_bits() as f64 / (1u64 << 32) as f64
}

/// A unit direction about unit `n` from a cosine-weighted square sample (u1, u2).
fn cosine_direction(n: DVec3, u1: f64, u2: f64) -> DVec3 {
    let (t1, t2) = n.any_orthonormal_pair();
    let r = u1.sqrt();
    let phi = std::f64::consts::TAU * u2;
    let z = (1.0 - u1).max(0.0).sqrt();
    (t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + n * z).normalize()
}

impl Transfer {
    /// The transfer vectors of every vertex of `scene` (its BVH built), computed in
    /// parallel over vertices; the result does not depend on the thread count.
    ///
    /// A vertex whose normal is zero or not finite (a degenerate corner) gets the zero
    /// vector: it receives no indirect light. Rays leave from the vertex moved along its
    /// normal by 1e-4 of the scene's diagonal (at least 1e-5 m), so that the triangles
    /// around it do not shadow it.
    ///
    /// Gives up with [`Cancelled`] when the process is asked to stop
    /// ([`relume_base::cancel`]), checked before each vertex.
    ///
    /// With two objects or more, each ray is a closest-hit query that also says
    /// whether another object is hit first ([`Transfer::bounce`]); whether anything is
    /// hit, and so `vectors`, is the same as with the any-hit query of one object.
    pub fn compute(scene: &VirtualScene, params: TransferParams) -> Result<Transfer, Cancelled> {
        let (vertices, corner_vertex) = scene_vertices(scene);
        let owners = vertex_objects(scene, &corner_vertex, vertices.len());
        let several_objects = object_count(scene) > 1;
        let n = params.samples.max(1) as u64;
        let bounds = scene.bounds();
        let offset = ((bounds.max - bounds.min).length() * 1e-4).max(1e-5);
        let pairs = vertices
            .par_iter()
            .enumerate()
            .map(|(v, &(position, normal))| {
                if cancel::requested() {
                    return None;
                }
                let normal = normal.normalize_or_zero().as_dvec3();
                if normal == DVec3::ZERO || !normal.is_finite() {
                    return Some(([0.0; 9], [0.0; 9]));
                }
                let origin = position + normal.as_vec3() * offset;
                let (mut open, mut self_open) = ([0.0f64; 9], [0.0f64; 9]);
                let h = rng::hash(&[params.seed, SALT_DIRECTIONS, v as u64]);
                let (shift1, shift2) = (rng::unit_f64(h), rng::unit_f64(rng::mix64(h)));
                for i in 0..n {
                    let u1 = ((i as f64 + 0.5) / n as f64 + shift1).fract();
                    let u2 = (radical_inverse(i as u32) + shift2).fract();
                    let d = cosine_direction(normal, u1, u2);
                    // Which sums the direction adds to: the room's light comes where
                    // nothing is hit, the other objects' where the object itself is not.
                    let (to_open, to_self_open) = if several_objects {
                        match scene.intersect(origin, d.as_vec3(), 0.0, f32::INFINITY) {
                            None => (true, true),
                            Some(hit) => {
                                let object = scene.triangles[hit.triangle as usize].material;
                                (false, object != owners[v])
                            }
                        }
                    } else {
                        (
                            !scene.occluded(origin, d.as_vec3(), 0.0, f32::INFINITY),
                            false,
                        )
                    };
                    if !to_self_open {
                        if to_open {
                            for (s, y) in open.iter_mut().zip(sh9_basis(d)) {
                                *s += y;
                            }
                        }
                        continue;
                    }
                    for ((o, s), y) in open.iter_mut().zip(&mut self_open).zip(sh9_basis(d)) {
                        if to_open {
                            *o += y;
                        }
                        *s += y;
                    }
                }
                let scale =
                    |sum: [f64; 9]| sum.map(|s| (s * std::f64::consts::PI / n as f64) as f32);
                Some((scale(open), scale(self_open)))
            })
            .collect::<Option<Vec<_>>>()
            .ok_or(Cancelled)?;
        let (vectors, bounce): (Vec<_>, Vec<_>) = pairs.into_iter().unzip();
        Ok(Transfer {
            corner_vertex,
            vectors,
            bounce: if several_objects { bounce } else { Vec::new() },
        })
    }

    /// True when this transfer was made for a scene of `triangles` triangles.
    pub fn fits(&self, triangles: usize) -> bool {
        self.corner_vertex.len() == triangles * 3
            && (self.bounce.is_empty() || self.bounce.len() == self.vectors.len())
            && self
                .corner_vertex
                .iter()
                .all(|&v| (v as usize) < self.vectors.len())
    }

    /// The transfer vector at barycentrics (u, v) of triangle `triangle` (weights
    /// 1 - u - v, u, v on its corners 0, 1, 2).
    pub fn at(&self, triangle: u32, u: f32, v: f32) -> [f32; 9] {
        self.interpolate(&self.vectors, triangle, u, v)
    }

    /// The bounce transfer ([`Transfer::bounce`]) at barycentrics (u, v) of triangle
    /// `triangle`; `None` for a scene of one object.
    pub fn bounce_at(&self, triangle: u32, u: f32, v: f32) -> Option<[f32; 9]> {
        (!self.bounce.is_empty()).then(|| self.interpolate(&self.bounce, triangle, u, v))
    }

    fn interpolate(&self, per_vertex: &[[f32; 9]], triangle: u32, u: f32, v: f32) -> [f32; 9] {
        let base = triangle as usize * 3;
        let weights = [1.0 - u - v, u, v];
        let mut out = [0.0f32; 9];
        for (c, w) in weights.into_iter().enumerate() {
            let vector = &per_vertex[self.corner_vertex[base + c] as usize];
            for (o, t) in out.iter_mut().zip(vector) {
                *o += w * t;
            }
        }
        out
    }

    /// Eq. 9 in irradiance form: sum_k C_k C_vk for radiance coefficients `sh9`.
    pub fn irradiance(vector: &[f32; 9], sh9: &[Vec3; 9]) -> Vec3 {
        sh9.iter()
            .zip(vector)
            .fold(Vec3::ZERO, |e, (c, t)| e + *c * *t)
    }
}

/// The barycentrics (u, v) of `p` in the triangle `vertices` (p projected onto its
/// plane), for a hit found without them; (0, 0) for a degenerate triangle.
pub fn barycentrics(vertices: &[Vec3; 3], p: Vec3) -> (f32, f32) {
    let (e1, e2, d) = (
        vertices[1] - vertices[0],
        vertices[2] - vertices[0],
        p - vertices[0],
    );
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det.abs() <= f32::MIN_POSITIVE || !det.is_finite() {
        return (0.0, 0.0);
    }
    let u = (d22 * d1 - d12 * d2) / det;
    let v = (d11 * d2 - d12 * d1) / det;
    (u, v)
}
