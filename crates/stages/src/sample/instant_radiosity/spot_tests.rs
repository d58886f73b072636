//! `sample.dir` with spot lights (paper 002 Secs. 3.3-3.7): what the flags say each
//! light reaches, and the \[4\] switch. The scene: the shared floor with a real plate
//! 0.3 m above it, a spot 2 m above the plate shining down, and a virtual sphere
//! between the spot and the plate.

use super::tests::inputs;
use super::*;
use crate::sample::layers::IrradianceLayers;
use crate::sample::path::tests::{Scene, W, camera, floor_scene, pose, sphere, uniform_table};
use glam::Vec3;
use relume_base::raster::Image;
use relume_base::threads::with_threads;
use relume_scene::light::{LightWorld, SpotLight};
use relume_scene::objects::{Material, VirtualScene};

/// The plate: x in [-0.3, 0.3], z in [0.7, 1.3], at this height.
pub(crate) const PLATE_Y: f32 = 0.3;
const PLATE: [f32; 4] = [-0.3, 0.3, 0.7, 1.3];
pub(crate) const SPOT_AT: Vec3 = Vec3::new(0.0, 2.3, 1.0);
pub(crate) const SPHERE_AT: Vec3 = Vec3::new(0.0, 0.9, 1.0);

fn on_plate(p: Vec3) -> bool {
    (PLATE[0]..=PLATE[1]).contains(&p.x) && (PLATE[2]..=PLATE[3]).contains(&p.z)
}

/// The floor scene with the real plate in its depth map.
pub(crate) fn plate_scene() -> Scene {
    let mut scene = floor_scene();
    let (cam, pose) = (camera(), pose());
    let origin: Vec3 = pose.translation.into();
    for i in 0..scene.depth.data.len() {
        let (u, v) = ((i % W as usize) as f32, (i / W as usize) as f32);
        let dir = pose.transform_vector3(cam.ray(u, v));
        let t = (PLATE_Y - origin.y) / dir.y;
        if dir.y < 0.0 && on_plate(origin + dir * t) {
            scene.depth.data[i] = t;
        }
    }
    scene
}

pub(crate) fn spot(world: LightWorld) -> SpotLight {
    SpotLight {
        name: "lamp".into(),
        world,
        position: SPOT_AT,
        direction: Vec3::NEG_Y,
        intensity: Vec3::new(8.0, 7.0, 6.0),
        beam: 30f32.to_radians(),
        cutoff: 40f32.to_radians(),
    }
}

pub(crate) fn ball() -> VirtualScene {
    sphere(SPHERE_AT, 0.2, Material::DIFFUSE_GRAY)
}

fn render(
    scene: &Scene,
    objects: &VirtualScene,
    spots: &[SpotLight],
    params: &DirParams,
) -> IrradianceLayers {
    let table = uniform_table(4096);
    let inputs = DirInputs {
        spots,
        ..inputs(scene, objects, &table, 5)
    };
    sample_dir(&inputs, params).unwrap()
}

/// The real pixels whose point is on the floor (`plate` false) or the plate, within
/// `radius` metres of the vertical through the spot.
pub(crate) fn under_spot(out: &IrradianceLayers, plate: bool, radius: f32) -> Vec<usize> {
    (0..out.mask.data.len())
        .filter(|&i| {
            let p = out.world_position.data[i];
            let near = Vec3::new(p.x - SPOT_AT.x, 0.0, p.z - SPOT_AT.z).length() < radius;
            let height = if plate { PLATE_Y } else { 0.0 };
            out.mask.data[i] == 1.0 && p.is_finite() && near && (p.y - height).abs() < 1e-3
        })
        .collect()
}

pub(crate) fn luminance(v: Vec3) -> f32 {
    v.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

#[test]
fn a_virtual_light_leaves_e_r_alone_and_brightens_e_rv_on_the_real_floor() {
    let scene = floor_scene();
    let objects = ball();
    let params = DirParams::default();
    let without = render(&scene, &objects, &[], &params);
    let with = render(&scene, &objects, &[spot(LightWorld::Virtual)], &params);
    // E_R: the bits of a run without the light (r(pl) = 0: no L_r path has it).
    for (a, b) in [
        (&without.e_r_dir, &with.e_r_dir),
        (&without.e_r_ind, &with.e_r_ind),
    ] {
        assert!(
            a.data
                .iter()
                .zip(&b.data)
                .all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits))
        );
    }
    // E_RV gains the light's irradiance on the floor in its cone (away from the
    // sphere's shadow, 0.33 m wide): intensity cos / d^2.
    let lit: Vec<usize> = (0..with.mask.data.len())
        .filter(|&i| {
            let p = with.world_position.data[i];
            let r = Vec3::new(p.x, 0.0, p.z - SPOT_AT.z).length();
            with.mask.data[i] == 1.0 && p.is_finite() && (0.42..0.6).contains(&r)
        })
        .collect();
    assert!(lit.len() > 20, "{} pixels", lit.len());
    for &i in &lit {
        let p = with.world_position.data[i];
        let expected = spot(LightWorld::Virtual)
            .arrival(p, Vec3::Y)
            .unwrap()
            .irradiance;
        let gained = with.e_rv_dir.data[i] - without.e_rv_dir.data[i];
        assert!(
            (gained - expected).abs().max_element() < 1e-3 * expected.max_element().max(1.0),
            "pixel {i} at {p}: gained {gained}, the light brings {expected}"
        );
        assert_eq!(with.touched.data[i], 1);
    }
    // Its bounce off the floor lands in E_RV's indirect light alone.
    let sum = |img: &Image<Vec3>| -> f32 {
        img.data
            .iter()
            .filter(|v| v.is_finite())
            .map(|&v| luminance(v))
            .sum()
    };
    assert!(sum(&with.e_rv_ind) > sum(&without.e_rv_ind) * 1.01);
}

#[test]
fn a_virtual_light_leaves_e_r_alone_over_two_bounces_too() {
    // Its light on the objects and on the real surface takes slots of its own: no
    // bounce's slots, and no second bounce, carry it.
    let scene = floor_scene();
    let objects = ball();
    let params = DirParams {
        bounces: 2,
        ..DirParams::default()
    };
    let without = render(&scene, &objects, &[], &params);
    let with = render(&scene, &objects, &[spot(LightWorld::Virtual)], &params);
    let bits = |img: &Image<Vec3>| -> Vec<[u32; 3]> {
        img.data
            .iter()
            .map(|v| v.to_array().map(f32::to_bits))
            .collect()
    };
    assert_eq!(bits(&with.e_r_dir), bits(&without.e_r_dir));
    assert_eq!(bits(&with.e_r_ind), bits(&without.e_r_ind));
    assert_ne!(bits(&with.e_rv_ind), bits(&without.e_rv_ind));
}

#[test]
fn a_real_light_blocked_by_a_virtual_object_darkens_e_rv_only() {
    let scene = floor_scene();
    let objects = ball();
    let params = DirParams::default();
    let lamp = spot(LightWorld::Real);
    let lit = render(&scene, &objects, std::slice::from_ref(&lamp), &params);
    let dark = render(&scene, &objects, &[], &params);
    // Right below the sphere the spot is blocked: E_R has its light, E_RV does not.
    let below = under_spot(&lit, false, 0.1);
    assert!(below.len() > 3, "{} pixels", below.len());
    for &i in &below {
        let p = lit.world_position.data[i];
        let light = lamp.arrival(p, Vec3::Y).unwrap().irradiance;
        let e_r = lit.e_r_dir.data[i] - dark.e_r_dir.data[i];
        let e_rv = lit.e_rv_dir.data[i] - dark.e_rv_dir.data[i];
        assert!(
            (e_r - light).abs().max_element() < 1e-3,
            "E_R gained {e_r}, expected {light}"
        );
        assert_eq!(e_rv, Vec3::ZERO, "pixel {i}: E_RV gained {e_rv}");
    }
    // Outside the sphere's shadow, both gain the same light.
    let open: Vec<usize> = (0..lit.mask.data.len())
        .filter(|&i| {
            let p = lit.world_position.data[i];
            let r = Vec3::new(p.x, 0.0, p.z - SPOT_AT.z).length();
            lit.mask.data[i] == 1.0 && p.is_finite() && (0.4..0.6).contains(&r)
        })
        .collect();
    assert!(open.len() > 20);
    for &i in &open {
        let e_r = lit.e_r_dir.data[i] - dark.e_r_dir.data[i];
        let e_rv = lit.e_rv_dir.data[i] - dark.e_rv_dir.data[i];
        assert!(luminance(e_r) > 0.5, "pixel {i}: {e_r}");
        assert!((e_r - e_rv).abs().max_element() < 1e-4, "{e_r} vs {e_rv}");
    }
}

#[test]
fn the_earlier_method_casts_a_double_shadow_where_a_virtual_object_hides_a_real_blocker() {
    let scene = plate_scene();
    let objects = ball();
    let lamp = [spot(LightWorld::Real)];
    let paper = DirParams::default();
    let earlier = DirParams {
        flags: Flags::Knecht2010,
        ..paper
    };
    let (a, b) = (
        render(&scene, &objects, &lamp, &paper),
        render(&scene, &objects, &lamp, &earlier),
    );
    let (a0, b0) = (
        render(&scene, &objects, &[], &paper),
        render(&scene, &objects, &[], &earlier),
    );
    // The floor under the plate, behind both blockers: the paper keeps the real
    // shadow in both worlds; [4] sees only the sphere, so its E_R takes the spot's
    // light there and the composite's E_RV / E_R darkens the real shadow again.
    let shadowed = under_spot(&a, false, 0.15);
    assert!(
        shadowed.len() > 3,
        "{} floor pixels under the plate",
        shadowed.len()
    );
    for &i in &shadowed {
        let p = a.world_position.data[i];
        let light = lamp[0].arrival(p, Vec3::Y).unwrap().irradiance;
        let paper_r = a.e_r_dir.data[i] - a0.e_r_dir.data[i];
        let earlier_r = b.e_r_dir.data[i] - b0.e_r_dir.data[i];
        assert_eq!(paper_r, Vec3::ZERO, "pixel {i}");
        assert!(
            (earlier_r - light).abs().max_element() < 1e-3,
            "pixel {i}: {earlier_r}"
        );
        assert_eq!(a.e_rv_dir.data[i] - a0.e_rv_dir.data[i], Vec3::ZERO);
        assert_eq!(b.e_rv_dir.data[i] - b0.e_rv_dir.data[i], Vec3::ZERO);
    }
    // The plate's top, where the sphere is the only blocker: the same for both.
    let plate = under_spot(&a, true, 0.1);
    assert!(plate.len() > 3);
    for &i in &plate {
        assert_eq!(
            a.e_r_dir.data[i] - a0.e_r_dir.data[i],
            b.e_r_dir.data[i] - b0.e_r_dir.data[i]
        );
        assert_eq!(a.e_rv_dir.data[i] - a0.e_rv_dir.data[i], Vec3::ZERO);
    }
}

#[test]
fn without_objects_the_switch_changes_no_bit() {
    // Only the flagged terms move: with nothing virtual to hide a real blocker and
    // no ir = 1 VPL to drop, [4] and the paper agree bit for bit.
    let scene = plate_scene();
    let none = VirtualScene::default();
    let lamp = [spot(LightWorld::Real)];
    let paper = DirParams::default();
    let earlier = DirParams {
        flags: Flags::Knecht2010,
        ..paper
    };
    let bits = crate::sample::path::tests::bits;
    assert_eq!(
        bits(&render(&scene, &none, &lamp, &paper)),
        bits(&render(&scene, &none, &lamp, &earlier))
    );
}

#[test]
fn spot_lights_give_the_same_bits_on_one_and_three_threads() {
    let scene = plate_scene();
    let objects = ball();
    let lamps = [spot(LightWorld::Real), {
        let mut v = spot(LightWorld::Virtual);
        v.position = Vec3::new(0.8, 1.5, 0.6);
        v.direction = (Vec3::new(0.0, 0.0, 1.2) - v.position).normalize();
        v
    }];
    let params = DirParams::default();
    let bits = crate::sample::path::tests::bits;
    let one = with_threads(1, || bits(&render(&scene, &objects, &lamps, &params)));
    let three = with_threads(3, || bits(&render(&scene, &objects, &lamps, &params)));
    assert_eq!(one, three);
}

#[test]
fn the_earlier_method_places_no_vpl_that_cancels_real_bleeding() {
    // Under the environment alone, the floor the sphere shades gets the paper's
    // ir = 1 VPLs (light only L_r has); [4] has none, and every real VPL it draws
    // counts in both worlds.
    let scene = floor_scene();
    let objects = ball();
    let table = uniform_table(4096);
    let inputs = inputs(&scene, &objects, &table, 5);
    let paper = DirParams::default();
    let mesh = MeshPoints::new(&objects, paper.mesh_points as usize, paper.seed);
    let real_only = |params: &DirParams| {
        let mut r = DirRenderer::default();
        r.lights(&inputs, params, &mesh).unwrap();
        r.vpls.iter().filter(|v| v.real_only).count()
    };
    assert!(real_only(&paper) > 0);
    let earlier = DirParams {
        flags: Flags::Knecht2010,
        ..paper
    };
    assert_eq!(real_only(&earlier), 0);
}

#[test]
fn coverage_splits_the_spot_slots_as_the_maps_pixel_counts_and_halton_say() {
    // Paper 002 Sec. 3.7: a virtual spot straight above a floor patch (100 real
    // candidates, 2 m below it) and a small bright object top (10 candidates, 1 m
    // below). By light the object would take half the slots; by coverage it takes the
    // Halton count of its share of the solid angle.
    let lamp = SpotLight {
        position: Vec3::new(0.0, 2.0, 0.0),
        cutoff: 80f32.to_radians(),
        beam: 70f32.to_radians(),
        ..spot(LightWorld::Virtual)
    };
    let candidate = |position: Vec3, real: bool, power: f32| super::vpl::Candidate {
        position,
        normal: Vec3::Y,
        power_r: Vec3::ZERO,
        power_rv: Vec3::splat(power),
        real,
        area: 0.01,
    };
    let mut candidates: Vec<_> = (0..100)
        .map(|i| {
            let (x, z) = ((i % 10) as f32 * 0.1 - 0.45, (i / 10) as f32 * 0.1 - 0.45);
            candidate(Vec3::new(x, 0.0, z), true, 1.0)
        })
        .collect();
    candidates
        .extend((0..10).map(|i| candidate(Vec3::new(i as f32 * 0.01, 1.0, 0.0), false, 10.0)));
    // The solid angles, written out: A cos / d^2 per candidate.
    let solid_angle = |c: &super::vpl::Candidate| {
        let v = lamp.position - c.position;
        (c.area * v.normalize().y / v.length_squared()) as f64
    };
    let real: f64 = candidates.iter().filter(|c| c.real).map(solid_angle).sum();
    let objects: f64 = candidates.iter().filter(|c| !c.real).map(solid_angle).sum();
    let p = objects / (real + objects);
    let coverage = super::spots::virtual_coverage(&candidates, std::slice::from_ref(&lamp));
    assert!((coverage - p).abs() < 1e-6, "{coverage} vs {p}");
    let slots = 32u32;
    // Halton base 2: 0, 1/2, 1/4, 3/4, 1/8, ...
    let expected_virtual = (0..slots)
        .filter(|&i| (i.reverse_bits() as f64 / 4294967296.0) < p)
        .count();
    assert!(
        (9..=10).contains(&expected_virtual),
        "{expected_virtual} (p = {p})"
    );
    let count = |coverage_split: bool| {
        let mut out = Vec::new();
        if coverage_split {
            super::spots::split_by_coverage(
                &candidates,
                std::slice::from_ref(&lamp),
                32,
                100,
                7,
                &mut out,
            );
        } else {
            super::vpl::resample(&candidates, 32, 100, 7, &mut out);
        }
        let slots_of = |real: bool| {
            let mut s: Vec<u32> = out
                .iter()
                .filter(|v| match v.emitter {
                    super::vpl::Emitter::Surface { position, .. } => (position.y < 0.5) == real,
                    _ => false,
                })
                .map(|v| v.slot)
                .collect();
            s.dedup();
            s.len()
        };
        let all: std::collections::BTreeSet<u32> = out.iter().map(|v| v.slot).collect();
        assert_eq!(all.len(), 32);
        assert_eq!((all.first(), all.last()), (Some(&100), Some(&131)));
        (slots_of(true), slots_of(false))
    };
    assert_eq!(count(true), (32 - expected_virtual, expected_virtual));
    assert_eq!(count(false), (16, 16));
}
