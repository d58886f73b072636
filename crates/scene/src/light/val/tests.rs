use super::*;
use crate::light::split::{split_direct_indirect, total_intensity};

const LAMP: Vec3 = Vec3::new(0.0, 1.0, 0.0);

fn window() -> Vec3 {
    Vec3::new(1.0, 0.3, 0.5).normalize()
}

/// A room-like impostor seen from (0, 0.3, 0): a dim background, a small warm lamp
/// overhead and a larger bluish window, every texel 2.5 m away (or distant).
fn room(distance: f32, lamp_gain: f32) -> EnvMap {
    let mut map = EnvMap::from_fn(128, 64, |d| {
        let lamp = d.dot(LAMP) > 0.985;
        let window = d.dot(window()) > 0.95;
        Vec3::splat(0.15 + 0.05 * d.y)
            + if lamp {
                Vec3::new(100.0, 85.0, 70.0) * lamp_gain
            } else {
                Vec3::ZERO
            }
            + if window {
                Vec3::new(10.0, 11.0, 14.0)
            } else {
                Vec3::ZERO
            }
    });
    map.distance = vec![distance; map.radiance.len()];
    map.center = Vec3::new(0.0, 0.3, 0.0);
    map
}

fn params(lights: usize) -> ValParams {
    ValParams {
        lights,
        seed: 5,
        ..Default::default()
    }
}

#[test]
fn static_light_gives_static_lights_and_slow_change_moves_them_little() {
    let (direct, indirect) = split_direct_indirect(&room(2.5, 1.0), 0.9);
    let mut builder = ValBuilder::new(params(16));
    let first = builder.update(&direct, &indirect);
    assert!(
        builder.last_report.unwrap().converged,
        "cold start converges"
    );
    let second = builder.update(&direct, &indirect);
    assert_eq!(builder.last_report.unwrap().iterations, 1);
    assert_eq!(val_center_drift(&first, &second), 0.0);
    assert_eq!(first, second);
    // The lamp 5 % brighter, with a ratio that keeps the same texels direct: the
    // warm-started centres barely move.
    let mut builder = ValBuilder::new(params(16));
    let (direct, indirect) = split_direct_indirect(&room(2.5, 1.0), 0.8);
    let before = builder.update(&direct, &indirect);
    let (direct, indirect) = split_direct_indirect(&room(2.5, 1.05), 0.8);
    let after = builder.update(&direct, &indirect);
    assert_eq!(after.lights.len(), before.lights.len());
    let drift = val_center_drift(&before, &after);
    // A cold start on the changed map lands elsewhere: the warm start is what keeps
    // the lights in place.
    let cold = ValBuilder::new(ValParams {
        seed: 6,
        ..params(16)
    })
    .update(&direct, &indirect);
    let cold_drift = val_center_drift(&before, &cold);
    eprintln!("warm drift {drift} m, cold drift {cold_drift} m");
    // Less than half a texel (12 cm at 2.5 m for 128 columns).
    assert!(drift < 0.05 && drift < cold_drift, "drift {drift} m");
}

#[test]
fn intensities_integrate_the_whole_direct_part() {
    for distance in [2.5, f32::INFINITY] {
        let (direct, indirect) = split_direct_indirect(&room(distance, 1.0), 0.9);
        let set = ValBuilder::new(params(16)).update(&direct, &indirect);
        assert!(set.lights.len() >= 8, "{}", set.lights.len());
        let mut total = total_intensity(&direct);
        if !distance.is_finite() {
            // Distant texels sit at the far radius: dA = dOmega R^2.
            total = total.map(|t| t * 100.0 * 100.0);
        }
        let sum = set
            .lights
            .iter()
            .fold(DVec3::ZERO, |s, l| s + l.intensity.as_dvec3());
        for c in 0..3 {
            assert!(
                (sum[c] - total[c]).abs() < 1e-5 * total[c],
                "{sum} vs {total:?}"
            );
        }
        // The SH9 term is the indirect part's.
        assert_eq!(set.sh9, project_sh9(&indirect));
    }
}

#[test]
fn lights_sit_at_the_two_sources_and_reproduce_their_irradiance() {
    let map = room(2.5, 1.0);
    // 80 %: the two sources hold about 85 % of the light, the background the rest.
    let (direct, indirect) = split_direct_indirect(&map, 0.8);
    let set = ValBuilder::new(params(8)).update(&direct, &indirect);
    let (mut at_lamp, mut at_window) = (0, 0);
    for l in &set.lights {
        let d = (l.position - map.center).normalize();
        assert!((l.position - map.center).length() - 2.5 < 1e-3);
        assert!((l.normal + d).length() < 1e-5, "faces the centre");
        if d.dot(LAMP) > 0.97 {
            at_lamp += 1;
        } else if d.dot(window()) > 0.93 {
            at_window += 1;
        } else {
            panic!("a light away from both sources: {d}");
        }
    }
    assert!(at_lamp >= 1 && at_window >= 1, "{at_lamp} {at_window}");
    // Irradiance at the centre from the VALs (eq. 6) against the direct part.
    for n in [Vec3::Y, window(), Vec3::new(0.5, 1.0, 0.0).normalize()] {
        let e: Vec3 = set
            .lights
            .iter()
            .map(|l| {
                let v = l.position - map.center;
                let r2 = v.length_squared();
                l.intensity * (n.dot(v).max(0.0) * (-l.normal.dot(v)).max(0.0) / (r2 * r2))
            })
            .sum();
        let reference = direct.irradiance_brute_force(n);
        let error = (e - reference).abs().max_element() / reference.max_element();
        eprintln!("VAL irradiance at the centre, n = {n}: relative error {error}");
        assert!(error < 0.03, "n {n}: {e} vs {reference}");
    }
}

#[test]
fn black_and_empty_maps_give_no_lights() {
    let black = EnvMap::constant(32, 16, Vec3::ZERO);
    let set = ValBuilder::new(params(16)).update(&black, &black);
    assert!(set.lights.is_empty());
    assert_eq!(set.sh9, [Vec3::ZERO; 9]);
    let empty = EnvMap::distant(0, 0, Vec::new());
    assert!(
        ValBuilder::new(params(16))
            .update(&empty, &empty)
            .lights
            .is_empty()
    );
    // One bright texel: one light, the others' clusters are dropped.
    let mut one = black.clone();
    one.radiance[100] = Vec3::ONE;
    let set = ValBuilder::new(params(16)).update(&one, &black);
    assert_eq!(set.lights.len(), 1);
    assert!(set.lights[0].intensity.is_finite());
}

#[test]
fn deterministic_across_thread_counts() {
    let (direct, indirect) = split_direct_indirect(&room(2.5, 1.0), 0.9);
    let run = || {
        let mut b = ValBuilder::new(params(16));
        b.update(&direct, &indirect);
        b.update(&direct, &indirect)
    };
    let one = relume_base::threads::with_threads(1, run);
    let three = relume_base::threads::with_threads(3, run);
    let bits = |s: &AreaLights| {
        s.lights
            .iter()
            .flat_map(|l| {
                [l.position, l.normal, l.intensity]
                    .into_iter()
                    .flat_map(|v| v.to_array())
                    .chain([l.area])
            })
            .map(f32::to_bits)
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&one), bits(&three));
}

#[test]
fn drift_matches_lights_by_index() {
    let light = |x: f32| AreaLight {
        position: Vec3::new(x, 0.0, 0.0),
        normal: Vec3::Y,
        intensity: Vec3::ONE,
        area: 1.0,
    };
    let a = AreaLights {
        lights: vec![light(0.0), light(1.0), light(5.0)],
        sh9: [Vec3::ZERO; 9],
    };
    let b = AreaLights {
        lights: vec![light(0.5), light(2.0)],
        sh9: [Vec3::ZERO; 9],
    };
    assert_eq!(val_center_drift(&a, &b), 0.75);
    assert_eq!(
        val_center_drift(
            &a,
            &AreaLights {
                lights: vec![],
                sh9: b.sh9
            }
        ),
        0.0
    );
}

fn vpl_params(lights: usize) -> ValParams {
    ValParams {
        method: LightMethod::Vpls,
        ..params(lights)
    }
}

#[test]
fn vpls_carry_their_texels_radiance_and_estimate_the_whole_intensity() {
    let (direct, indirect) = split_direct_indirect(&room(2.5, 1.0), 1.0);
    let set = ValBuilder::new(vpl_params(64)).update(&direct, &indirect);
    assert_eq!(set.lights.len(), 64);
    // Ratio 1: everything is direct, nothing is left for the SH term.
    assert!(set.sh9.iter().all(|c| *c == Vec3::ZERO));
    let map = room(2.5, 1.0);
    for l in &set.lights {
        // At its texel's position, facing the centre, with that texel's radiance.
        let d = (l.position - map.center).normalize();
        assert!(((l.position - map.center).length() - 2.5).abs() < 1e-3);
        assert!((l.normal + d).length() < 1e-5);
        let radiance = map.radiance[map.texel_of(d)];
        let ratio = l.intensity / l.area;
        assert!(
            (ratio - radiance).length() < 1e-3 * radiance.length(),
            "{ratio} vs {radiance}"
        );
    }
    // Sampled by luminance, each light carries exactly 1/N of the total luminance, so
    // the lights' sum is exact in luminance; per channel eq. 14 is an unbiased estimate,
    // here (64 stratified samples) within 1 %.
    let total = total_intensity(&direct);
    let sum = set
        .lights
        .iter()
        .fold(DVec3::ZERO, |s, l| s + l.intensity.as_dvec3());
    let lum = |v: [f64; 3]| 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2];
    let (sum_lum, total_lum) = (lum(sum.to_array()), lum(total));
    assert!(
        (sum_lum / total_lum - 1.0).abs() < 1e-5,
        "{sum_lum} vs {total_lum}"
    );
    for c in 0..3 {
        let err = (sum[c] / total[c] - 1.0).abs();
        assert!(err < 0.01, "channel {c}: {} vs {}", sum[c], total[c]);
    }
}

#[test]
fn vpls_concentrate_where_the_light_is_and_follow_the_split() {
    // With the split, the samples come from the lamp and the window only; without it,
    // the dim background takes its share of the lights.
    let map = room(2.5, 1.0);
    let on_sources = |set: &AreaLights| {
        set.lights
            .iter()
            .filter(|l| {
                let d = (l.position - map.center).normalize();
                d.dot(LAMP) > 0.98 || d.dot(window()) > 0.94
            })
            .count()
    };
    let (direct, indirect) = split_direct_indirect(&map, 0.8);
    let split = ValBuilder::new(vpl_params(32)).update(&direct, &indirect);
    assert_eq!(on_sources(&split), 32);
    assert_eq!(split.sh9, project_sh9(&indirect));
    let (direct, indirect) = split_direct_indirect(&map, 1.0);
    let whole = ValBuilder::new(vpl_params(32)).update(&direct, &indirect);
    assert!(on_sources(&whole) < 32, "{}", on_sources(&whole));
}

#[test]
fn prt_only_has_no_lights_and_all_of_the_map_in_sh() {
    let map = room(2.5, 1.0);
    let (direct, indirect) = split_direct_indirect(&map, 0.0);
    for method in [LightMethod::Clusters, LightMethod::Vpls] {
        let set = ValBuilder::new(ValParams {
            method,
            ..params(16)
        })
        .update(&direct, &indirect);
        assert!(set.lights.is_empty(), "{method:?}");
        assert_eq!(set.sh9, project_sh9(&map));
    }
}

/// An atlas of a 4 x 4 m floor (dim, 5 cm texels) with a 1 x 0.6 m panel at 2.5 m
/// facing down (bright) and a 0.5 x 0.5 m patch of the wall x = 2 facing -x.
fn room_atlas() -> Vec<atlas::AtlasTexel> {
    let mut atlas = Vec::new();
    let mut grid = |origin: Vec3, u: Vec3, v: Vec3, (nu, nv): (usize, usize), normal, l| {
        for i in 0..nu {
            for j in 0..nv {
                atlas.push(atlas::AtlasTexel {
                    position: origin + u * (i as f32 + 0.5) + v * (j as f32 + 0.5),
                    normal,
                    radiance: l,
                    area: u.length() * v.length(),
                });
            }
        }
    };
    let s = 0.05;
    let floor = Vec3::new(-2.0, 0.0, -2.0);
    grid(
        floor,
        Vec3::X * s,
        Vec3::Z * s,
        (80, 80),
        Vec3::Y,
        Vec3::splat(0.2),
    );
    let panel = Vec3::new(-0.5, 2.5, -0.3);
    grid(
        panel,
        Vec3::X * s,
        Vec3::Z * s,
        (20, 12),
        Vec3::NEG_Y,
        Vec3::new(9.0, 8.0, 7.0),
    );
    let wall = Vec3::new(2.0, 1.0, -0.25);
    grid(
        wall,
        Vec3::Y * s,
        Vec3::Z * s,
        (10, 10),
        Vec3::NEG_X,
        Vec3::new(4.0, 5.0, 7.0),
    );
    atlas
}

#[test]
fn atlas_lights_sit_on_the_bright_surfaces_and_carry_their_intensity() {
    let atlas = room_atlas();
    let direct = atlas::direct_part(&atlas, 0.6);
    // The panel (0.6 m^2 of luminance 8.1: 4.9) holds 52 % of the light, with the wall
    // patch (0.25 m^2 of 4.9: 1.2) 65 %; the floor (16 m^2 of 0.2: 3.2) is left to the
    // indirect part.
    assert_eq!(direct.len(), 20 * 12 + 10 * 10);
    let lights = ValBuilder::new(params(8)).update_atlas(&direct, &room(2.5, 1.0));
    assert!(!lights.lights.is_empty() && lights.lights.len() <= 8);
    let (mut on_panel, mut on_wall) = (Vec3::ZERO, Vec3::ZERO);
    for l in &lights.lights {
        let p = l.position;
        if (p.y - 2.5).abs() < 1e-4 {
            assert!(p.x.abs() <= 0.5 && (-0.3..=0.3).contains(&p.z), "{p}");
            assert!((l.normal - Vec3::NEG_Y).length() < 1e-5);
            on_panel += l.intensity;
        } else {
            assert!(
                (p.x - 2.0).abs() < 1e-4,
                "a light off the bright surfaces: {p}"
            );
            assert!((l.normal - Vec3::NEG_X).length() < 1e-5);
            on_wall += l.intensity;
        }
    }
    // Eq. 7: each surface's lights carry its L dA.
    let close = |a: Vec3, b: Vec3| (a - b).abs().max_element() < 1e-3 * b.max_element();
    assert!(
        close(on_panel, Vec3::new(9.0, 8.0, 7.0) * 0.6),
        "{on_panel}"
    );
    assert!(close(on_wall, Vec3::new(4.0, 5.0, 7.0) * 0.25), "{on_wall}");
    // The same atlas gives the same lights (warm start from converged centres).
    let mut builder = ValBuilder::new(params(8));
    let first = builder.update_atlas(&direct, &room(2.5, 1.0));
    assert_eq!(
        first,
        ValBuilder::new(params(8)).update_atlas(&direct, &room(2.5, 1.0))
    );
    assert!(builder.update_atlas(&[], &room(2.5, 1.0)).lights.is_empty());
}
