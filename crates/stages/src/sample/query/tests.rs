//! The impostor queries against an analytic box room: Distance Impostor Tracing
//! converges to the exact ray hit as its iterations grow, and with none it is
//! Environment Mapping.

use super::*;
use glam::Vec3;
use relume_scene::light::EnvMap;

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
    let query = ImpostorQuery::new(map, iterations).unwrap();
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
    let errors: Vec<f32> = [0, 1, 2, 4, 6, 8, 16]
        .iter()
        .map(|&k| mean_hit_error(&map, origin, k))
        .collect();
    // Measured: 1.02 m, 0.62 m, 0.53 m, 2.1 cm, 5 mm, 4.1 mm, 4.2 mm. Environment
    // Mapping puts the light about a metre off from here; tracing brings it to the
    // map's resolution (a texel of the 256-texel cube spans about 1.5 cm at 2.5 m),
    // where more steps only move it within a texel.
    for k in 0..4 {
        assert!(
            errors[k + 1] <= errors[k],
            "by iterations 0,1,2,4,6,8,16: {errors:?}"
        );
    }
    assert!(errors[0] > 0.5, "{errors:?}");
    assert!(errors[3] < 0.03, "{errors:?}");
    assert!(errors[5] < 0.006 && errors[6] < 0.006, "{errors:?}");
}

#[test]
fn dit_radiance_approaches_the_wall_seen_along_the_ray() {
    let map = box_impostor(1024);
    let origin = CENTER + Vec3::new(-0.9, 0.6, -1.1);
    let query = |iterations| ImpostorQuery::new(&map, iterations).unwrap();
    let error = |iterations| {
        let q = query(iterations);
        directions(1000)
            .iter()
            .map(|&d| {
                let ray = Ray {
                    origin,
                    dir: d,
                    t_max: f32::INFINITY,
                    spread: 0.0,
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
    let em = ImpostorQuery::new(&map, 0).unwrap();
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
            spread: 0.0,
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
    let query = ImpostorQuery::new(&map, 0).unwrap();
    assert_eq!(query.cube.face_size, 64);
    assert_eq!(
        ImpostorQuery::new(&box_impostor(1024), 0)
            .unwrap()
            .cube
            .face_size,
        MAX_FACE_SIZE
    );
    assert_eq!(query.center, CENTER);
    for i in (0..query.cube.radiance.len()).step_by(97) {
        let d = query.cube.texel_direction(i);
        assert_eq!(query.cube.texel_of(d), i, "texel {i}");
        assert_eq!(query.cube.radiance[i], map.radiance(d));
        assert_eq!(query.cube.distance[i], map.distance[map.texel_of(d)]);
    }
}

#[test]
fn a_distant_map_answers_as_environment_mapping() {
    let map = EnvMap::from_fn(64, 32, |d| d.abs());
    let origin = Vec3::new(0.3, -0.2, 0.1);
    let dit = ImpostorQuery::new(&map, 8).unwrap();
    for d in directions(200) {
        let traced = dit.trace(origin, d);
        assert_eq!(traced.texel, dit.cube.texel_of(d));
        assert!(traced.t.is_infinite());
    }
}

#[test]
fn dit_from_the_floor_finds_the_far_wall_not_the_floor_it_starts_on() {
    // A real shading point lies on a surface the impostor stores: the search must not
    // stop at the point's own surface (g(0) = 0). Floor points around the room, rays
    // over the upper hemisphere, their exact hits at least 20 cm away.
    let map = box_impostor(512);
    let dit = ImpostorQuery::new(&map, 8).unwrap();
    let (mut total, mut n, mut stuck) = (0.0, 0, 0);
    for origin in [
        Vec3::new(1.5, 0.002, 2.5),
        Vec3::new(-1.2, 0.002, -2.0),
        Vec3::new(0.3, 0.002, 0.4),
    ] {
        for d in directions(1000).into_iter().filter(|d| d.y > 0.0) {
            let exact = exit(origin, d);
            if exact < 0.2 {
                continue;
            }
            let traced = dit.trace(origin, d);
            stuck += (traced.t < 0.1) as usize;
            total += ((traced.t - exact) * d).length();
            n += 1;
        }
    }
    let mean = total / n as f32;
    assert_eq!(stuck, 0, "{stuck} of {n} rays ended at their own floor");
    // Measured: 3.2 cm, the staircase of the floor seen at grazing angles from the
    // centre (a texel of the 256-texel cube is a step of a few centimetres at 3 m).
    assert!(
        mean < 0.04,
        "mean hit error from the floor {mean} m over {n} rays"
    );
}

#[test]
fn dit_never_answers_with_a_hole() {
    // A sphere of 2 m about the centre with one hole where a ray from off-centre
    // crosses it: the answer keeps a texel that holds light.
    let mut map = EnvMap::from_fn(128, 64, |d| d.abs());
    map.distance = vec![2.0; map.radiance.len()];
    let origin = Vec3::new(0.9, -0.4, 0.3);
    let d = Vec3::new(1.0, 0.2, 0.0).normalize();
    let exact = ImpostorQuery::new(&map, 8).unwrap().trace(origin, d);
    assert!(
        ((origin + d * exact.t).length() - 2.0).abs() < 0.01,
        "{exact:?}"
    );
    let mut dit = ImpostorQuery::new(&map, 8).unwrap();
    dit.cube.distance[exact.texel] = f32::INFINITY;
    let traced = dit.trace(origin, d);
    assert!(dit.cube.distance[traced.texel].is_finite(), "{traced:?}");
}

#[test]
fn a_malformed_map_is_refused() {
    let mut map = EnvMap::constant(8, 4, Vec3::ONE);
    map.distance.pop();
    let err = ImpostorQuery::new(&map, 4).unwrap_err();
    assert_eq!(
        err,
        "the environment map is 8x4 with 32 radiance and 31 distance texels"
    );
    let empty = EnvMap::constant(0, 0, Vec3::ONE);
    assert!(ImpostorQuery::new(&empty, 4).is_err());
    let mut far = EnvMap::constant(8, 4, Vec3::ONE);
    far.center = Vec3::new(f32::NAN, 0.0, 0.0);
    assert!(ImpostorQuery::new(&far, 4).is_err());
    // Non-finite radiance brings no light.
    let mut bad = EnvMap::constant(8, 4, Vec3::ONE);
    bad.radiance[0] = Vec3::NAN;
    let q = ImpostorQuery::new(&bad, 0).unwrap();
    assert!(q.cube.radiance.iter().all(|l| l.is_finite()));
}

#[test]
fn query_kinds_round_trip_their_names() {
    for &name in QueryKind::NAMES {
        assert_eq!(QueryKind::from_name(name).unwrap().name(), name);
    }
    assert_eq!(QueryKind::from_name("vtc"), None);
    assert!(QueryKind::Vct.needs_voxels() && !QueryKind::Vct.needs_environment());
    assert_eq!(QueryKind::default(), QueryKind::Ssrt);
}
