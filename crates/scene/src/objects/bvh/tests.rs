//! Tests of the BVH against brute force: random rays on every shape and a triangle
//! soup, exact ties, stale or missing hierarchies, determinism.

use super::*;
use crate::objects::{Material, VirtualScene, shapes};
use glam::Vec2;
use relume_base::rng::Counter;

fn scene(triangles: Vec<Triangle>) -> VirtualScene {
    VirtualScene::new(triangles, vec![Material::DIFFUSE_GRAY])
}

fn unit_vector(rng: &mut Counter) -> Vec3 {
    let z = 2.0 * rng.next_f32() - 1.0;
    let phi = std::f32::consts::TAU * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

fn point_in(rng: &mut Counter, b: &Aabb, grow: f32) -> Vec3 {
    // Around flat bounds (a quad), a box as high as half their largest side.
    let flat = Vec3::splat((b.max - b.min).max_element() * 0.5);
    let size = if grow > 0.0 {
        (b.max - b.min).max(flat)
    } else {
        b.max - b.min
    };
    let lo = b.min - size * grow;
    let span = size * (1.0 + 2.0 * grow);
    lo + span * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
}

/// 500 triangles of random size and orientation in a unit cube, many overlapping.
fn soup(seed: u64, count: usize) -> Vec<Triangle> {
    let mut rng = Counter::new(&[seed, 0x50]);
    (0..count)
        .map(|_| {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let size = 0.02 + 0.2 * rng.next_f32();
            let vertices = [0; 3].map(|_| c + unit_vector(&mut rng) * size);
            let n = crate::objects::tri_normal(&vertices);
            Triangle {
                vertices,
                normals: [n; 3],
                material: 0,
            }
        })
        .collect()
}

/// Compares BVH and brute force on `rays` rays of three kinds: aimed at random points
/// of the bounds from around them, random directions from around them, and rays
/// leaving the surface (as shadow and bounce rays do). Returns the hits seen.
fn agree(scene: &VirtualScene, rays: usize, seed: u64) -> usize {
    assert!(scene.bvh.is_built_for(scene.triangles.len()));
    let b = scene.bounds();
    let mut rng = Counter::new(&[seed, 0xb4]);
    let mut hits = 0;
    for k in 0..rays {
        let (origin, dir, t_min) = match k % 3 {
            0 => {
                let o = point_in(&mut rng, &b, 1.0);
                let target = point_in(&mut rng, &b, 0.0);
                (o, (target - o).normalize(), 0.0)
            }
            1 => (point_in(&mut rng, &b, 0.5), unit_vector(&mut rng), 0.0),
            _ => {
                let t = &scene.triangles[rng.next_u64() as usize % scene.triangles.len()];
                let (u, v) = (rng.next_f32(), rng.next_f32());
                let (u, v) = if u + v > 1.0 {
                    (1.0 - u, 1.0 - v)
                } else {
                    (u, v)
                };
                let p = t.vertices[0] * (1.0 - u - v) + t.vertices[1] * u + t.vertices[2] * v;
                (p, unit_vector(&mut rng), 1e-4)
            }
        };
        let t_max = if k % 5 == 0 {
            0.05 + rng.next_f32()
        } else {
            f32::INFINITY
        };
        let fast = scene.intersect(origin, dir, t_min, t_max);
        let slow = scene.intersect_brute_force(origin, dir, t_min, t_max);
        assert_eq!(
            fast, slow,
            "ray {k}: origin {origin}, dir {dir}, t in ({t_min}, {t_max})"
        );
        assert_eq!(
            scene.occluded(origin, dir, t_min, t_max),
            slow.is_some(),
            "occluded, ray {k}"
        );
        assert_eq!(
            scene.occluded_brute_force(origin, dir, t_min, t_max),
            slow.is_some()
        );
        hits += slow.is_some() as usize;
    }
    hits
}

#[test]
fn bvh_hits_equal_brute_force_on_random_rays() {
    let cases = [
        ("sphere", shapes::sphere(0.25, 48)),
        ("torus", shapes::torus(0.25, 0.08, 64, 32)),
        ("box", shapes::cuboid(Vec3::new(0.3, 0.2, 0.4))),
        ("quad", shapes::quad(Vec2::new(1.0, 2.0))),
        ("soup", soup(7, 500)),
    ];
    for (name, triangles) in cases {
        let count = triangles.len();
        let s = scene(triangles);
        let hits = agree(&s, 3000, count as u64);
        // Every third ray aims at the object, every third leaves its surface.
        eprintln!("{name}: {count} triangles, {hits} of 3000 rays hit");
        assert!(hits > 600, "{name}: only {hits} of 3000 rays hit");
        assert!(
            s.bvh.depth() <= MAX_DEPTH,
            "{name}: depth {}",
            s.bvh.depth()
        );
    }
}

#[test]
fn axis_parallel_rays_on_face_planes_agree_with_brute_force() {
    // Directions with zero components (infinite inverses) from origins on the planes
    // of the triangles' faces and edges, of a box and of a grid of boxes.
    let half = Vec3::new(0.15, 0.1, 0.2);
    let mut triangles = shapes::cuboid(2.0 * half);
    for k in 0..4 {
        let shift = Vec3::new(0.3 * k as f32, 0.0, 0.45 * (k % 2) as f32);
        triangles.extend(shapes::cuboid(2.0 * half).iter().map(|t| Triangle {
            vertices: t.vertices.map(|v| v + shift),
            ..*t
        }));
    }
    let s = scene(triangles);
    let coordinates = |axis: usize| {
        let h = half[axis];
        let mut c = vec![-1.0, -h, -0.5 * h, 0.0, 0.5 * h, h, 1.5];
        c.extend((0..4).map(|k| 0.3 * k as f32 * (axis == 0) as i32 as f32 + h));
        c
    };
    let (mut rays, mut hits) = (0, 0);
    for dir in [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ] {
        for &x in &coordinates(0) {
            for &y in &coordinates(1) {
                for &z in &coordinates(2) {
                    let o = Vec3::new(x, y, z) - dir * 2.0;
                    let slow = s.intersect_brute_force(o, dir, 0.0, f32::INFINITY);
                    assert_eq!(s.intersect(o, dir, 0.0, f32::INFINITY), slow, "{o} {dir}");
                    assert_eq!(s.occluded(o, dir, 0.0, 9.0), slow.is_some(), "{o} {dir}");
                    rays += 1;
                    hits += slow.is_some() as usize;
                }
            }
        }
    }
    assert!(hits > rays / 4, "{hits} of {rays}");
}

#[test]
fn the_torus_shadows_itself_through_the_bvh() {
    let s = scene(shapes::torus(0.25, 0.08, 64, 32));
    // From the inner side of the tube across the hole to the other side.
    let origin = Vec3::new(0.17 - 1e-3, 0.0, 0.0);
    let hit = s
        .intersect(origin, Vec3::NEG_X, 1e-4, f32::INFINITY)
        .unwrap();
    assert!((hit.t - 0.339).abs() < 2e-3, "t = {}", hit.t);
    assert!(hit.normal.abs_diff_eq(Vec3::X, 0.01), "{}", hit.normal);
    assert!(s.occluded(origin, Vec3::NEG_X, 1e-4, 1.0));
    assert!(!s.occluded(origin, Vec3::NEG_X, 1e-4, 0.3));
    // Straight up through the hole: nothing.
    assert!(
        s.intersect(Vec3::new(0.0, -1.0, 0.0), Vec3::Y, 0.0, 9.0)
            .is_none()
    );
}

#[test]
fn exact_ties_go_to_the_smaller_index_in_both() {
    // The soup, then the same triangles again: every hit ties with its copy.
    let mut triangles = soup(11, 300);
    triangles.extend(triangles.clone());
    let s = scene(triangles);
    let mut rng = Counter::new(&[3]);
    let mut hits = 0;
    for k in 0..2000 {
        let o = point_in(&mut rng, &s.bounds(), 1.0);
        let dir = (point_in(&mut rng, &s.bounds(), 0.0) - o).normalize();
        let fast = s.intersect(o, dir, 0.0, f32::INFINITY);
        assert_eq!(
            fast,
            s.intersect_brute_force(o, dir, 0.0, f32::INFINITY),
            "ray {k}"
        );
        if let Some(h) = fast {
            assert!(h.triangle < 300, "ray {k} took the copy {}", h.triangle);
            hits += 1;
        }
    }
    assert!(hits > 1000, "{hits}");
    // Many identical triangles: all centroids coincide, the build still terminates
    // with a balanced tree, and triangle 0 wins.
    let one = soup(5, 1)[0];
    let s = scene(vec![one; 1000]);
    assert!(s.bvh.depth() <= 5, "depth {}", s.bvh.depth());
    let c = (one.vertices[0] + one.vertices[1] + one.vertices[2]) / 3.0;
    let n = crate::objects::tri_normal(&one.vertices);
    let hit = s.intersect(c + n, -n, 0.0, 9.0).unwrap();
    assert_eq!(hit.triangle, 0);
}

#[test]
fn scenes_without_a_current_bvh_fall_back_to_brute_force() {
    let triangles = shapes::sphere(1.0, 16);
    let built = scene(triangles.clone());
    let literal = VirtualScene {
        triangles: triangles.clone(),
        materials: vec![Material::DIFFUSE_GRAY],
        bvh: Bvh::default(),
    };
    assert_eq!(built, literal, "the BVH is not part of equality");
    assert_eq!(
        built.bounds(),
        literal.bounds(),
        "kept by the BVH, or computed"
    );
    assert!(built.bounds().max.abs_diff_eq(Vec3::ONE, 1e-6));
    let (o, d) = (Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    let hit = literal.intersect(o, d, 0.0, 9.0).unwrap();
    assert_eq!(Some(hit), built.intersect(o, d, 0.0, 9.0));
    assert!(literal.occluded(o, d, 0.0, 9.0));
    // Triangles added after the build: the stale BVH is not used.
    let mut grown = built.clone();
    grown
        .triangles
        .extend(shapes::cuboid(Vec3::ONE).iter().map(|t| Triangle {
            vertices: t.vertices.map(|v| v + Vec3::new(0.0, 0.0, -2.0)),
            ..*t
        }));
    let hit = grown.intersect(o, d, 0.0, 9.0).unwrap();
    assert!((hit.t - 0.5).abs() < 1e-6 && hit.triangle as usize >= triangles.len());
    grown.rebuild();
    assert!(grown.bvh.is_built_for(grown.triangles.len()));
    assert_eq!(grown.intersect(o, d, 0.0, 9.0), Some(hit));
    let empty = VirtualScene::default();
    assert!(empty.is_empty() && empty.intersect(o, d, 0.0, 9.0).is_none());
    assert!(!empty.occluded(o, d, 0.0, 9.0));
    assert_eq!(empty.bounds(), Aabb::EMPTY);
    assert_eq!(
        VirtualScene::new(Vec::new(), Vec::new()).bvh.node_count(),
        0
    );
}

#[test]
fn the_build_is_deterministic_and_queries_are_the_same_on_any_thread_count() {
    use rayon::prelude::*;
    let triangles = [shapes::torus(0.25, 0.08, 64, 32), soup(1, 200)].concat();
    let (a, b) = (Bvh::build(&triangles), Bvh::build(&triangles));
    assert_eq!(a, b);
    let s = scene(triangles);
    let rays: Vec<(Vec3, Vec3)> = {
        let mut rng = Counter::new(&[9]);
        let bounds = s.bounds();
        (0..2000)
            .map(|_| {
                let o = point_in(&mut rng, &bounds, 1.0);
                (o, (point_in(&mut rng, &bounds, 0.0) - o).normalize())
            })
            .collect()
    };
    let trace = || -> Vec<(u32, u32)> {
        rays.par_iter()
            .map(|&(o, d)| {
                s.intersect(o, d, 0.0, f32::INFINITY)
                    .map_or((u32::MAX, 0), |h| (h.triangle, h.t.to_bits()))
            })
            .collect()
    };
    let one = relume_base::threads::with_threads(1, trace);
    let three = relume_base::threads::with_threads(3, trace);
    assert_eq!(one, three);
    let hits = one.iter().filter(|h| h.0 != u32::MAX).count();
    assert!(hits > 100, "{hits}");
}

#[test]
fn triangles_without_finite_coordinates_change_no_hit() {
    // Triangles with a NaN coordinate in every vertex (all three, or x alone) can meet
    // no ray. Their NaN centroids once scrambled the build, so that rays missed nearer
    // hits among the rest; they now stay out of the tree, and the rest is found as
    // brute force finds it.
    let soup = soup(3, 300);
    let cube = scene(soup.clone()).bounds();
    let mut triangles = soup;
    for corner in [Vec3::NAN, Vec3::new(f32::NAN, 0.5, 0.5)] {
        for k in 0..8 {
            let v = corner + Vec3::Y * (k as f32 * 0.1);
            triangles.push(Triangle {
                vertices: [v, v + Vec3::X * 0.2, v + Vec3::Z * 0.2],
                normals: [Vec3::Y; 3],
                material: 0,
            });
        }
    }
    let s = scene(triangles);
    let mut rng = Counter::new(&[5, 0xf1]);
    let mut hits = 0;
    for k in 0..3000 {
        let origin = point_in(&mut rng, &cube, 1.0);
        let dir = if k % 2 == 0 {
            (point_in(&mut rng, &cube, 0.0) - origin).normalize()
        } else {
            unit_vector(&mut rng)
        };
        let slow = s.intersect_brute_force(origin, dir, 0.0, f32::INFINITY);
        assert_eq!(
            s.intersect(origin, dir, 0.0, f32::INFINITY),
            slow,
            "ray {k}"
        );
        assert_eq!(s.occluded(origin, dir, 0.0, f32::INFINITY), slow.is_some());
        hits += slow.is_some() as usize;
    }
    assert!(hits > 300, "only {hits} of 3000 rays hit");
}
