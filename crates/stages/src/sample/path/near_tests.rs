//! `near_primary`: the pixels where the differential is take more primaries, and each
//! pixel gets exactly the bits a run with its own primary count everywhere gives it.

use super::tests::*;
use super::*;
use glam::Vec3;
use relume_scene::objects::Material;

/// Every layer of pixel `i` as bits.
fn pixel_bits(out: &IrradianceLayers, i: usize) -> Vec<u32> {
    let mut b = Vec::new();
    for image in [
        &out.e_r_dir,
        &out.e_r_ind,
        &out.e_rv_dir,
        &out.e_rv_ind,
        &out.k_v,
        &out.world_position,
        &out.world_normal,
    ] {
        b.extend(image.data[i].to_array().map(f32::to_bits));
    }
    for image in [
        &out.mask,
        &out.exponent,
        &out.direct_min_distance,
        &out.indirect_min_distance,
    ] {
        b.push(image.data[i].to_bits());
    }
    b.push(out.touched.data[i] as u32);
    b
}

#[test]
fn near_pixels_take_near_primary_samples_and_the_rest_their_usual_bits() {
    let scene = floor_scene();
    let table = uniform_table(4096);
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    let with = |primary, near_primary| PathParams {
        primary,
        direct: 2,
        indirect: 2,
        near_primary,
        near_distance: 0.2,
        seed: 3,
        ..Default::default()
    };
    let few = run(&scene, &objects, &table, &with(1, 0));
    let many = run(&scene, &objects, &table, &with(3, 0));
    let mixed = run(&scene, &objects, &table, &with(1, 3));
    let (mut as_few, mut as_many) = (0, 0);
    for i in 0..(W * H) as usize {
        let bits = pixel_bits(&mixed, i);
        if bits == pixel_bits(&many, i) {
            as_many += 1;
        } else {
            assert_eq!(bits, pixel_bits(&few, i), "pixel {i} is neither run's");
            as_few += 1;
        }
        // A pixel showing the sphere is near.
        if many.mask.data[i] < 1.0 {
            assert_eq!(bits, pixel_bits(&many, i), "pixel {i} shows the sphere");
        }
    }
    // The floor right under the sphere (its box reaches down to y = 0.3, 0.3 m above
    // the floor: more than near_distance) is not near; the sphere's pixels are.
    assert_eq!(
        pixel_bits(&mixed, pixel_of(Vec3::new(0.0, 0.0, 1.0))),
        pixel_bits(&few, pixel_of(Vec3::new(0.0, 0.0, 1.0)))
    );
    assert!(
        as_many > 100 && as_few > 1000,
        "{as_many} near, {as_few} not"
    );
    // Three primaries give the sphere's silhouette partial coverage.
    assert!(mixed.mask.data.iter().any(|&m| m > 0.0 && m < 1.0));
    assert!(few.mask.data.iter().all(|&m| m == 0.0 || m == 1.0));
}

#[test]
fn near_primary_out_of_range_is_refused() {
    let params = PathParams {
        near_primary: MAX_SAMPLES + 1,
        ..Default::default()
    };
    let err = params.check().unwrap_err().to_string();
    assert!(err.contains("near_primary is 65"), "{err}");
}
