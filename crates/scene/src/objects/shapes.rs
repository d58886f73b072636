//! Primitive shapes as triangle meshes in their own (object) coordinates, y up, centred
//! on the origin, counter-clockwise seen from outside (the geometric normal points out).
//! Curved shapes carry their exact surface normal per vertex, so shading is smooth; the
//! box and the quad carry flat normals. Vertices shared by neighbouring triangles are
//! computed once, so the meshes are closed with no cracks along seams.

use super::geometry::Triangle;
use glam::{DVec3, Vec2, Vec3};
use std::f64::consts::{PI, TAU};

/// A latitude-longitude sphere of `radius` with `segments` around the y axis and
/// `segments / 2` rings from pole to pole: 2 * segments * (rings - 1) triangles
/// (2208 for the default 48). `segments` is clamped to at least 4.
pub fn sphere(radius: f32, segments: u32) -> Vec<Triangle> {
    let segments = segments.max(4);
    let rings = (segments / 2).max(2);
    let unit = |ring: u32, seg: u32| -> DVec3 {
        if ring == 0 {
            return DVec3::Y;
        }
        if ring == rings {
            return DVec3::NEG_Y;
        }
        let theta = PI * ring as f64 / rings as f64;
        let phi = TAU * (seg % segments) as f64 / segments as f64;
        DVec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    };
    let vertex = |ring, seg| {
        let n = unit(ring, seg);
        ((n * radius as f64).as_vec3(), n.as_vec3())
    };
    let mut out = Vec::with_capacity(2 * segments as usize * (rings as usize - 1));
    for ring in 0..rings {
        for seg in 0..segments {
            let a = vertex(ring, seg);
            let b = vertex(ring, seg + 1);
            let c = vertex(ring + 1, seg);
            let d = vertex(ring + 1, seg + 1);
            // Along seg is d/dphi, along ring d/dtheta: dphi x dtheta points out.
            if ring > 0 {
                out.push(triangle([a, b, c]));
            }
            if ring + 1 < rings {
                out.push(triangle([b, d, c]));
            }
        }
    }
    out
}

/// A box with edge lengths `size` (x, y, z): 12 triangles with flat normals.
pub fn cuboid(size: Vec3) -> Vec<Triangle> {
    let h = size * 0.5;
    // (normal, u, v) with u x v = normal.
    let faces = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y, Vec3::X),
    ];
    let mut out = Vec::with_capacity(12);
    for (n, u, v) in faces {
        let (c, u, v) = (n * h, u * h, v * h);
        rectangle(&mut out, c, u, v, n);
    }
    out
}

/// A rectangle in the xz plane through the origin, facing +y, `size` = (x, z) extents:
/// 2 triangles. One-sided in shading only: rays hit it from both sides.
pub fn quad(size: Vec2) -> Vec<Triangle> {
    let mut out = Vec::with_capacity(2);
    rectangle(
        &mut out,
        Vec3::ZERO,
        Vec3::Z * (size.y * 0.5),
        Vec3::X * (size.x * 0.5),
        Vec3::Y,
    );
    out
}

/// A torus around the y axis (lying flat on the xz plane): ring radius `major_radius`,
/// tube radius `minor_radius`, `segments` around the ring and `minor_segments` around
/// the tube: 2 * segments * minor_segments triangles (4096 for 64 x 32). Its inner side
/// shadows itself. Counts are clamped to at least 3.
pub fn torus(
    major_radius: f32,
    minor_radius: f32,
    segments: u32,
    minor_segments: u32,
) -> Vec<Triangle> {
    let (segments, minor_segments) = (segments.max(3), minor_segments.max(3));
    let (big, small) = (major_radius as f64, minor_radius as f64);
    let vertex = |seg: u32, tube: u32| {
        let phi = TAU * (seg % segments) as f64 / segments as f64;
        let psi = TAU * (tube % minor_segments) as f64 / minor_segments as f64;
        let n = DVec3::new(psi.cos() * phi.cos(), psi.sin(), psi.cos() * phi.sin());
        let p = DVec3::new(big * phi.cos(), 0.0, big * phi.sin()) + n * small;
        (p.as_vec3(), n.as_vec3())
    };
    let mut out = Vec::with_capacity(2 * segments as usize * minor_segments as usize);
    for seg in 0..segments {
        for tube in 0..minor_segments {
            let a = vertex(seg, tube);
            let b = vertex(seg, tube + 1);
            let c = vertex(seg + 1, tube);
            let d = vertex(seg + 1, tube + 1);
            // Along tube is d/dpsi, along seg d/dphi: dpsi x dphi points out.
            out.push(triangle([a, b, c]));
            out.push(triangle([b, d, c]));
        }
    }
    out
}

/// Two triangles covering centre +- u +- v, with flat normal `n` = u x v (normalized).
fn rectangle(out: &mut Vec<Triangle>, c: Vec3, u: Vec3, v: Vec3, n: Vec3) {
    let corners = [c - u - v, c + u - v, c + u + v, c - u + v];
    for [i, j, k] in [[0, 1, 2], [0, 2, 3]] {
        out.push(Triangle {
            vertices: [corners[i], corners[j], corners[k]],
            normals: [n; 3],
            material: 0,
        });
    }
}

fn triangle(v: [(Vec3, Vec3); 3]) -> Triangle {
    Triangle {
        vertices: [v[0].0, v[1].0, v[2].0],
        normals: [v[0].1, v[1].1, v[2].1],
        material: 0,
    }
}

/// Enclosed volume by the divergence theorem (exact for closed meshes).
#[cfg(test)]
pub(crate) fn volume(triangles: &[Triangle]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.vertices.map(|v| v.as_dvec3());
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

/// Total surface area.
#[cfg(test)]
pub(crate) fn area(triangles: &[Triangle]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.vertices.map(|v| v.as_dvec3());
            (b - a).cross(c - a).length() / 2.0
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::tri_normal;

    /// Every geometric normal points the way of its vertex normals (outward winding),
    /// and vertex normals are unit length.
    fn check_winding(tris: &[Triangle]) {
        for (i, t) in tris.iter().enumerate() {
            let g = tri_normal(&t.vertices);
            assert!(g.length() > 0.99, "triangle {i} is degenerate");
            for n in t.normals {
                assert!(
                    (n.length() - 1.0).abs() < 1e-5,
                    "triangle {i}: |n| = {}",
                    n.length()
                );
                assert!(g.dot(n) > 0.5, "triangle {i} winds inward: {g} vs {n}");
            }
        }
    }

    /// Each directed edge appears once and its reverse once: closed, no cracks.
    fn check_closed(tris: &[Triangle]) {
        let key = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut edges = std::collections::BTreeMap::new();
        for t in tris {
            for k in 0..3 {
                let e = (key(t.vertices[k]), key(t.vertices[(k + 1) % 3]));
                *edges.entry(e).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1, "directed edge used {n} times");
            assert_eq!(edges.get(&(b, a)), Some(&1), "edge without its twin");
        }
    }

    #[test]
    fn sphere_is_closed_round_and_close_to_the_true_sphere() {
        let tris = sphere(0.5, 48);
        assert_eq!(tris.len(), 2208);
        check_winding(&tris);
        check_closed(&tris);
        for t in &tris {
            for v in t.vertices {
                assert!((v.length() - 0.5).abs() < 1e-6);
            }
        }
        // Inscribed polyhedron: slightly less than 4/3 pi r^3 and 4 pi r^2.
        let (v, a) = (volume(&tris), area(&tris));
        let (v_true, a_true) = (4.0 / 3.0 * PI * 0.125, 4.0 * PI * 0.25);
        assert!(v < v_true && v > 0.99 * v_true, "volume {v} vs {v_true}");
        assert!(a < a_true && a > 0.99 * a_true, "area {a} vs {a_true}");
    }

    #[test]
    fn torus_is_closed_and_matches_pappus() {
        let tris = torus(0.25, 0.08, 64, 32);
        assert_eq!(tris.len(), 4096);
        check_winding(&tris);
        check_closed(&tris);
        let (big, small) = (0.25f64, 0.08f64);
        let (v, a) = (volume(&tris), area(&tris));
        let (v_true, a_true) = (
            2.0 * PI * PI * big * small * small,
            4.0 * PI * PI * big * small,
        );
        assert!((v / v_true - 1.0).abs() < 0.01, "volume {v} vs {v_true}");
        assert!((a / a_true - 1.0).abs() < 0.01, "area {a} vs {a_true}");
        let ys: Vec<f32> = tris.iter().flat_map(|t| t.vertices.map(|v| v.y)).collect();
        let top = ys.iter().cloned().fold(f32::MIN, f32::max);
        assert!((top - 0.08).abs() < 1e-6, "top of the tube at y = {top}");
    }

    #[test]
    fn box_and_quad_are_exact() {
        let tris = cuboid(Vec3::new(0.2, 0.4, 0.6));
        assert_eq!(tris.len(), 12);
        check_winding(&tris);
        check_closed(&tris);
        assert!((volume(&tris) - 0.048).abs() < 1e-8, "{}", volume(&tris));
        assert!((area(&tris) - 2.0 * (0.08 + 0.24 + 0.12)).abs() < 1e-7);
        for t in &tris {
            assert_eq!(tri_normal(&t.vertices), t.normals[0], "flat normals");
        }
        let q = quad(Vec2::new(2.0, 1.0));
        check_winding(&q);
        assert!((area(&q) - 2.0).abs() < 1e-12);
        let xs: Vec<f32> = q.iter().flat_map(|t| t.vertices.map(|v| v.x)).collect();
        assert_eq!(xs.iter().cloned().fold(f32::MIN, f32::max), 1.0);
    }
}
