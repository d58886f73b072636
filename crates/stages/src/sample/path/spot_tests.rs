//! `sample.path` with spot lights: the flags of paper 002 eqs. 4-5 on the scene of
//! `sample.dir`'s spot tests (the floor, a real plate 0.3 m above it, a spot 2 m above
//! the plate, a virtual sphere between them).

use super::tests::{H, Scene, W, camera, floor_scene, pose, uniform_table};
use super::*;
use crate::sample::instant_radiosity::spot_tests::{ball, plate_scene, spot, under_spot};
use crate::sample::layers::IrradianceLayers;
use glam::Vec3;
use relume_base::threads::with_threads;
use relume_scene::light::{LightWorld, SpotLight};
use relume_scene::objects::VirtualScene;

fn render(scene: &Scene, objects: &VirtualScene, spots: &[SpotLight]) -> IrradianceLayers {
    let table = uniform_table(1024);
    let inputs = PathInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        radiance: &scene.radiance,
        camera: camera(),
        camera_to_world: pose(),
        table: &table,
        environment: None,
        voxels: None,
        objects,
        object_voxels: None,
        spots,
        frame: 7,
    };
    let mut out = IrradianceLayers::new(W, H);
    sample_path(&inputs, &PathParams::default(), &mut out).unwrap();
    out
}

fn same(a: Vec3, b: Vec3) -> bool {
    a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)
}

#[test]
fn a_virtual_light_leaves_e_r_alone_and_lights_the_real_floor_in_e_rv() {
    let scene = floor_scene();
    let objects = ball();
    let lamp = spot(LightWorld::Virtual);
    let without = render(&scene, &objects, &[]);
    let with = render(&scene, &objects, std::slice::from_ref(&lamp));
    assert!(
        with.e_r_dir
            .data
            .iter()
            .zip(&without.e_r_dir.data)
            .all(|(a, b)| same(*a, *b))
    );
    // Real floor pixels in the cone, outside the sphere's shadow (0.33 m wide): E_RV
    // gains intensity cos / d^2 exactly; right below the sphere, nothing.
    let (mut lit, mut shaded) = (0, 0);
    for i in 0..with.mask.data.len() {
        let p = with.world_position.data[i];
        if with.mask.data[i] != 1.0 || !p.is_finite() || p.y.abs() > 1e-3 {
            continue;
        }
        let r = Vec3::new(p.x, 0.0, p.z - 1.0).length();
        let gained = with.e_rv_dir.data[i] - without.e_rv_dir.data[i];
        if (0.38..0.6).contains(&r) {
            let expected = lamp.arrival(p, Vec3::Y).unwrap().irradiance;
            assert!(
                (gained - expected).abs().max_element() < 1e-4,
                "{p}: {gained} vs {expected}"
            );
            lit += 1;
        } else if r < 0.25 {
            assert_eq!(gained, Vec3::ZERO, "{p}");
            shaded += 1;
        }
    }
    assert!(lit > 20 && shaded > 5, "{lit} lit, {shaded} shaded");
}

#[test]
fn a_real_light_is_blocked_by_the_real_plate_in_both_and_by_the_sphere_in_e_rv_only() {
    let scene = plate_scene();
    let objects = ball();
    let lamp = spot(LightWorld::Real);
    let without = render(&scene, &objects, &[]);
    let with = render(&scene, &objects, std::slice::from_ref(&lamp));
    let gain = |img: fn(&IrradianceLayers) -> &relume_base::raster::Vec3Image, i: usize| {
        img(&with).data[i] - img(&without).data[i]
    };
    // The plate's top: the sphere alone blocks the spot.
    let plate = under_spot(&with, true, 0.1);
    assert!(plate.len() > 3);
    for &i in &plate {
        let light = lamp
            .arrival(with.world_position.data[i], Vec3::Y)
            .unwrap()
            .irradiance;
        assert!((gain(|o| &o.e_r_dir, i) - light).abs().max_element() < 1e-4);
        assert_eq!(gain(|o| &o.e_rv_dir, i), Vec3::ZERO);
        assert_eq!(with.touched.data[i], 1);
    }
    // The floor under the plate: the real plate blocks it in both.
    let floor = under_spot(&with, false, 0.15);
    assert!(floor.len() > 3);
    for &i in &floor {
        assert_eq!(gain(|o| &o.e_r_dir, i), Vec3::ZERO);
        assert_eq!(gain(|o| &o.e_rv_dir, i), Vec3::ZERO);
    }
}

#[test]
fn spot_lights_give_the_same_bits_on_one_and_three_threads() {
    let scene = plate_scene();
    let objects = ball();
    let lamps = [spot(LightWorld::Real), spot(LightWorld::Virtual)];
    let bits = super::tests::bits;
    let one = with_threads(1, || bits(&render(&scene, &objects, &lamps)));
    let three = with_threads(3, || bits(&render(&scene, &objects, &lamps)));
    assert_eq!(one, three);
}
