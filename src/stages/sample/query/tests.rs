//! The impostor queries against an analytic box room: Distance Impostor Tracing
//! converges to the exact ray hit as its iterations grow, and with none it is
//! Environment Mapping.

use super::*;
use crate::light::EnvMap;
use glam::Vec3;

const ROOM_MIN: Vec3 = Vec3::new(-2.0, 0.0, -3.0);
const ROOM_MAX: Vec3 = Vec3::new(2.0, 2.5, 3.0);
const CENTER: Vec3 = Vec3::new(0.0, 1.2, 0.0);

/// Where the ray `origin + t dir` (inside the room) leaves it, and at what t.
fn exit(origin: Vec3, dir: Vec3) -> f32 {
    let far = |lo: f32, hi: f32, o: f32, d: f32| {
        if d > 0.0 {
            (hi - o) / d
        } else if d < 0.0 {
            (lo - o) / d
        } else {
            f32::INFINITY
        }
    };
    far(ROOM_MIN.x, ROOM_MAX.x, origin.x, dir.x)
        .min(far(ROOM_MIN.y, ROOM_MAX.y, origin.y, dir.y))
        .min(far(ROOM_MIN.z, ROOM_MAX.z, origin.z, dir.z))
}

/// Radiance of a wall point: a smooth ramp, so a wrong hit shows a wrong color.
fn wall_radiance(p: Vec3) -> Vec3 {
    (p - ROOM_MIN) / (ROOM_MAX - ROOM_MIN)
}

/// The box room's distance impostor seen from `CENTER`, `width` x `width / 2`.
fn box_impostor(width: u32) -> EnvMap {
    let mut map = EnvMap::from_fn(width, width / 2, |d| {
        wall_radiance(CENTER + d * exit(CENTER, d))
    });
    map.center = CENTER;
    map.distance = (0..map.radiance.len())
        .map(|i| exit(CENTER, map.texel_direction(i)))
        .collect();
    map
}

/// Unit directions spread over the sphere (a golden spiral).
fn directions(n: usize) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).sqrt();
            let (s, c) = (golden * i as f32).sin_cos();
            Vec3::new(r * c, y, r * s)
        })
        .collect()
}

/// Mean distance (metres) between the point DIT finds and the exact hit, over rays
/// from `origin`.
fn mean_hit_error(map: &EnvMap, origin: Vec3, iterations: u32) -> f32 {
    let query = ImpostorQuery::new(map, iterations);
    let dirs = directions(2000);
    let total: f32 = dirs
        .iter()
        .map(|&d| {
            let traced = query.trace(origin, d);
            let found = origin + d * traced.t;
            (found - (origin + d * exit(origin, d))).length()
        })
        .sum();
    total / dirs.len() as f32
}

#[test]
fn dit_converges_to_the_exact_hit_in_a_box_room_seen_from_off_centre() {
    let map = box_impostor(1024);
    let origin = CENTER + Vec3::new(0.7, -0.8, 0.9);
    let errors: Vec<f32> = [0, 1, 2, 4, 8, 16]
        .iter()
        .map(|&k| mean_hit_error(&map, origin, k))
        .collect();
    for pair in errors.windows(2) {
        assert!(
            pair[1] <= pair[0],
            "errors by iterations 0,1,2,4,8,16: {errors:?}"
        );
    }
    // Measured: 1.02 m, 0.22 m, 5.3 cm, 4.4 mm, 3.7 mm, 3.7 mm. Environment Mapping
    // puts the light about a metre off from here; tracing brings it to the map's
    // resolution (a texel of 1024 x 512 spans about 2 cm at 3 m).
    assert!(errors[0] > 0.5, "{errors:?}");
    assert!(errors[3] < 0.01, "{errors:?}");
    assert!(errors[5] < 0.005, "{errors:?}");
}

#[test]
fn dit_radiance_approaches_the_wall_seen_along_the_ray() {
    let map = box_impostor(1024);
    let origin = CENTER + Vec3::new(-0.9, 0.6, -1.1);
    let query = |iterations| ImpostorQuery::new(&map, iterations);
    let error = |iterations| {
        let q = query(iterations);
        directions(1000)
            .iter()
            .map(|&d| {
                let ray = Ray {
                    origin,
                    dir: d,
                    t_max: f32::INFINITY,
                };
                let hit = q.query(&ray).expect("every ray meets the impostor");
                assert_eq!(hit.source, Source::Environment);
                let truth = wall_radiance(origin + d * exit(origin, d));
                (hit.radiance - truth).abs().max_element()
            })
            .sum::<f32>()
            / 1000.0
    };
    let (em, dit) = (error(0), error(8));
    assert!(dit < em / 5.0, "mean radiance error: em {em}, dit {dit}");
    assert!(dit < 0.01, "mean radiance error of dit: {dit}");
}

#[test]
fn dit_with_zero_iterations_is_environment_mapping() {
    let map = box_impostor(256);
    let em = ImpostorQuery::new(&map, 0);
    let origin = CENTER + Vec3::new(0.5, -0.3, 0.2);
    let mut resampling_error = 0.0;
    for d in directions(500) {
        // The lookup along the ray's own direction, from anywhere.
        let texel = em.cube.texel_of(d);
        let expected = TracedImpostor {
            texel,
            t: em.cube.distance[texel],
        };
        assert_eq!(em.trace(origin, d), expected);
        let ray = Ray {
            origin,
            dir: d,
            t_max: f32::INFINITY,
        };
        let hit = em.query(&ray).unwrap();
        assert_eq!(hit.radiance, em.cube.radiance[texel]);
        assert_eq!(hit.t.to_bits(), em.cube.distance[texel].to_bits());
        resampling_error += (hit.radiance - map.radiance(d)).abs().max_element() / 500.0;
    }
    // The cube holds the lat-long map's texels: those of its texel centres, within a
    // lat-long texel of d (a ramp of about 0.01 per texel, steps at the room's edges).
    assert!(resampling_error < 0.01, "{resampling_error}");
}

#[test]
fn the_cube_holds_the_maps_texel_at_each_centre_direction() {
    let map = box_impostor(128);
    let query = ImpostorQuery::new(&map, 0);
    assert_eq!(query.cube.face_size, 64);
    assert_eq!(query.center, CENTER);
    for i in (0..query.cube.radiance.len()).step_by(97) {
        let d = query.cube.texel_direction(i);
        assert_eq!(query.cube.texel_of(d), i, "texel {i}");
        assert_eq!(query.cube.radiance[i], map.radiance(d));
        assert_eq!(query.cube.distance[i], map.distance[map.texel_of(d)]);
    }
}

#[test]
fn from_the_centre_dit_keeps_the_lookup_direction() {
    // At the centre every sphere step lands on the texel it read: tracing cannot do
    // better than the map, and must not do worse.
    let map = box_impostor(256);
    let dit = ImpostorQuery::new(&map, 8);
    for d in directions(500) {
        assert_eq!(dit.trace(CENTER, d).texel, dit.cube.texel_of(d));
    }
}

#[test]
fn a_distant_map_or_a_hole_answers_as_environment_mapping() {
    let map = EnvMap::from_fn(64, 32, |d| d.abs());
    let origin = Vec3::new(0.3, -0.2, 0.1);
    let dit = ImpostorQuery::new(&map, 8);
    for d in directions(200) {
        let traced = dit.trace(origin, d);
        assert_eq!(traced.texel, dit.cube.texel_of(d));
        assert!(traced.t.is_infinite());
    }
    // Finite everywhere but a hole where the first step would land: the step keeps
    // the texel it had instead of reading the hole's missing light.
    let mut dit = ImpostorQuery::new(&map, 1);
    dit.cube.distance.fill(2.0);
    let d = Vec3::new(1.0, 0.2, 0.0).normalize();
    let first = dit.trace(origin, d).texel;
    assert_ne!(first, dit.cube.texel_of(d), "the step moves the lookup");
    dit.cube.distance[first] = f32::INFINITY;
    assert_eq!(dit.trace(origin, d).texel, dit.cube.texel_of(d));
}

#[test]
fn query_kinds_round_trip_their_names() {
    for &name in QueryKind::NAMES {
        assert_eq!(QueryKind::from_name(name).unwrap().name(), name);
    }
    assert_eq!(QueryKind::from_name("vct"), None);
    assert_eq!(QueryKind::default(), QueryKind::Ssrt);
}
