//! `sample.val` with the objects' radiance transfer (paper 004 eqs. 9, 11).

use super::tests::{camera, lights, real_scene};
use super::*;
use relume_base::raster::Vec3Image;
use relume_scene::light::prt::{Transfer, TransferParams};
use relume_scene::objects::{Material, shapes};

/// A torus lying on the floor right under the camera: its inner side faces its own
/// tube across the hole.
fn torus() -> VirtualScene {
    let mut triangles = shapes::torus(0.8, 0.3, 32, 16);
    let origin = camera().1.translation;
    for t in &mut triangles {
        t.vertices = t.vertices.map(|v| v + Vec3::new(origin.x, 0.3, origin.z));
    }
    VirtualScene::new(triangles, vec![Material::DIFFUSE_GRAY])
}

#[test]
fn the_transfer_darkens_the_objects_where_they_occlude_themselves_and_nothing_else() {
    let (depth, normals) = real_scene(false);
    let (camera, camera_to_world) = camera();
    let scene = torus();
    // No area lights: the constant sky's SH9 is all the light.
    let sky = lights(Vec::new());
    let transfer = Transfer::compute(&scene, TransferParams::default()).unwrap();
    let render = |transfer: Option<&Transfer>| {
        let inputs = ValInputs {
            depth: &depth,
            normals: &normals,
            camera,
            camera_to_world,
            lights: &sky,
            objects: &scene,
            transfer,
            spots: &[],
        };
        sample_val(&inputs, &ValShadingParams::default()).unwrap()
    };
    let (open, occluded) = (render(None), render(Some(&transfer)));
    // Real surfaces: the same bits (the transfer is for the objects only).
    let bits = |image: &Vec3Image| -> Vec<[u32; 3]> {
        image
            .data
            .iter()
            .map(|v| v.to_array().map(f32::to_bits))
            .collect()
    };
    assert_eq!(bits(&open.e_r_dir), bits(&occluded.e_r_dir));
    assert_eq!(bits(&open.e_r_ind), bits(&occluded.e_r_ind));
    assert_eq!(bits(&open.e_rv_dir), bits(&occluded.e_rv_dir));
    let (mut virtual_pixels, mut darker, mut top) = (0, 0, 0);
    for i in 0..open.mask.data.len() {
        let (a, b) = (open.e_rv_ind.data[i], occluded.e_rv_ind.data[i]);
        if open.mask.data[i] != 0.0 {
            assert_eq!(
                a.to_array().map(f32::to_bits),
                b.to_array().map(f32::to_bits)
            );
            continue;
        }
        virtual_pixels += 1;
        // Occlusion only takes light away (up to the transfer's 2 %).
        assert!(b.x <= a.x * 1.02, "pixel {i}: {b} brighter than {a}");
        if b.x < 0.9 * a.x {
            darker += 1;
        }
        // The top of the tube sees the whole sky: as without occlusion.
        if open.world_normal.data[i].y > 0.99 {
            top += 1;
            assert!((b.x - a.x).abs() <= 0.02 * a.x, "pixel {i}: {b} vs {a}");
        }
    }
    assert!(virtual_pixels > 500 && top > 20, "{virtual_pixels} {top}");
    // The inner side of the ring, facing the tube across the hole, loses light.
    assert!(darker > virtual_pixels / 10, "{darker} of {virtual_pixels}");
}
