//! Determinism: the lanes' march gives the scalar march's bits, and the outputs do not
//! depend on the thread count.

use super::tests::{
    H, SPHERE_CENTER, SPHERE_RADIUS, Scene, W, bits, camera, floor_scene, pose, run,
    run_with_kernel, sphere, uniform_table,
};
use super::*;
use glam::Vec3;
use relume_base::raster::Vec3Image;
use relume_base::threads::with_threads;
use relume_scene::objects::Material;
use relume_scene::objects::VirtualScene;

/// The floor with a wall across it at world z = `wall_z` (facing the camera).
fn floor_and_wall_scene(wall_z: f32) -> Scene {
    let (cam, pose) = (camera(), pose());
    let to_camera = pose.inverse();
    let mut scene = floor_scene();
    for v in 0..H {
        for u in 0..W {
            let ray = cam.ray(u as f32, v as f32);
            let (origin, dir) = (pose.translation, pose.transform_vector3(ray));
            let t_wall = (wall_z - origin.z) / dir.z;
            let i = (v * W + u) as usize;
            let z = scene.depth.data[i];
            if t_wall > 0.0 && (z == 0.0 || t_wall < z) {
                // t is along `ray`, whose camera z is 1: the depth is t.
                scene.depth.data[i] = t_wall;
                scene.normals.data[i] = to_camera.transform_vector3(-Vec3::Z);
            }
        }
    }
    scene
}

/// The tests' sphere, light gray, with Phong `exponent` (0: diffuse).
fn gray_sphere(exponent: f32) -> VirtualScene {
    let material = Material {
        albedo: Vec3::splat(0.6),
        exponent,
    };
    sphere(SPHERE_CENTER, SPHERE_RADIUS, material)
}

#[test]
fn the_lane_march_gives_the_bits_of_the_scalar_march() {
    // The portable kernel marches each ray in turn (`ScreenTracer`'s scalar march);
    // AVX2 marches eight at a time.
    let scene = floor_and_wall_scene(1.6);
    let table = uniform_table(1024);
    let objects = gray_sphere(0.0);
    // Every 5th pixel: rows of 20 pixels, one span shorter than SPAN_PIXELS.
    for (object_aware, pixel_stride) in [(false, 1), (true, 1), (false, 5)] {
        let params = PathParams {
            object_aware,
            pixel_stride,
            seed: 5,
            ..Default::default()
        };
        let one_by_one = run_with_kernel(&scene, &objects, &table, &params, simd::Kernel::Portable);
        let lit = |e: &Vec3Image| e.data.iter().filter(|e| e.max_element() > 0.0).count();
        // Real hits: indirect light reflected by the wall and the floor, and direct
        // light blocked by the wall (the room is not lit everywhere).
        let reflected = lit(&one_by_one.e_r_ind);
        let occluded = one_by_one
            .direct_min_distance
            .data
            .iter()
            .filter(|d| d.is_finite())
            .count();
        let enough = 1500 / (pixel_stride * pixel_stride) as usize;
        assert!(
            reflected > enough && occluded > enough,
            "{reflected} pixels with reflected light, {occluded} with an occluder"
        );
        let lanes = run_with_kernel(&scene, &objects, &table, &params, simd::Kernel::detect());
        assert!(
            bits(&one_by_one) == bits(&lanes),
            "object_aware {object_aware}, pixel_stride {pixel_stride}"
        );
    }
}

#[test]
fn outputs_are_identical_for_one_and_three_threads() {
    let scene = floor_scene();
    let table = uniform_table(1024);
    let objects = gray_sphere(8.0);
    for object_aware in [false, true] {
        let params = PathParams {
            object_aware,
            seed: 11,
            ..Default::default()
        };
        let one = with_threads(1, || bits(&run(&scene, &objects, &table, &params)));
        let three = with_threads(3, || bits(&run(&scene, &objects, &table, &params)));
        assert!(one == three, "object_aware {object_aware}");
    }
}
