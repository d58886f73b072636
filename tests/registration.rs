//! Depth registration against exact ground truth: the synthetic room seen by a color
//! camera and by a separate depth camera (other intrinsics, size and principal point,
//! 5 cm to the side and turned by 2 degrees). The depth camera's true depth, in
//! millimetres, registered into the color view must give the color camera's true depth
//! within a unit wherever both cameras see the same plane, and nothing where the depth
//! camera saw nothing.

use glam::{DQuat, DVec3, Mat3, Vec3};
use relume::pinhole::Intrinsics;
use relume::recording::register::{Extrinsic, Registration, Scratch, register_depth};
use relume::recording::synth::camera::camera_pose;
use relume::recording::synth::render::pixel_direction;
use relume::recording::synth::room::Surface;
use relume::recording::synth::scene::{Ray, Scene};

const UNIT_M: f64 = 0.001;

/// What a camera sees through each pixel centre: the hit's world position, camera-space
/// depth and the plane it lies on (surface and normal; `None` for the ball, which is
/// curved, and for rays that hit nothing).
struct Truth {
    depth_m: Vec<f32>,
    position: Vec<Vec3>,
    plane: Vec<Option<(Surface, [i32; 3])>>,
}

fn render(scene: &Scene, rotation: Mat3, position: Vec3, k: &Intrinsics) -> Truth {
    let n = (k.width * k.height) as usize;
    let mut truth = Truth {
        depth_m: vec![0.0; n],
        position: vec![Vec3::ZERO; n],
        plane: vec![None; n],
    };
    for y in 0..k.height {
        for x in 0..k.width {
            let i = (y * k.width + x) as usize;
            let ray = Ray::new(position, rotation * pixel_direction(k, x, y));
            let Some(hit) = scene.intersect(&ray, 0.0) else {
                continue;
            };
            truth.depth_m[i] = hit.t;
            truth.position[i] = hit.position;
            if hit.surface != Surface::Ball {
                let normal = (hit.normal * 1000.0).round().as_ivec3().to_array();
                truth.plane[i] = Some((hit.surface, normal));
            }
        }
    }
    truth
}

#[test]
fn depth_from_a_separate_camera_registers_to_the_color_views_true_depth() {
    let scene = Scene::room_without_interreflection();
    // A RealSense-like pair at a quarter of its resolution: the color camera narrower
    // than the depth camera, but for the top rows, which the depth camera does not see.
    let color_k = Intrinsics {
        width: 320,
        height: 240,
        fx: 305.0,
        fy: 305.0,
        cx: 159.5,
        cy: 119.5,
    };
    let depth_k = Intrinsics {
        width: 212,
        height: 90,
        fx: 106.0,
        fy: 106.5,
        cx: 105.0,
        cy: 40.0,
    };
    let depth_to_color = Extrinsic {
        rotation: DQuat::from_rotation_y(2f64.to_radians()),
        translation: DVec3::new(-0.05, 0.004, 0.002),
    };
    for time_s in [0.0, 3.0, 7.5] {
        let pose = camera_pose(time_s);
        let color_rotation = glam::DMat3::from_quat(pose.rotation());
        let color_position = pose.translation();
        // The depth camera's pose: its origin is at `translation` in the color camera.
        let depth_rotation = color_rotation * glam::DMat3::from_quat(depth_to_color.rotation);
        let depth_position = color_position + color_rotation * depth_to_color.translation;
        let color = render(
            &scene,
            color_rotation.as_mat3(),
            color_position.as_vec3(),
            &color_k,
        );
        let depth = render(
            &scene,
            depth_rotation.as_mat3(),
            depth_position.as_vec3(),
            &depth_k,
        );
        let units: Vec<u16> = depth
            .depth_m
            .iter()
            .map(|&z| (z as f64 / UNIT_M).round() as u16)
            .collect();
        let mut registered = Vec::new();
        let registration = Registration::new(depth_k, color_k, depth_to_color);
        register_depth(
            &units,
            UNIT_M,
            &registration,
            &mut registered,
            &mut Scratch::default(),
        )
        .unwrap();

        let world_to_depth = depth_rotation.transpose().as_mat3();
        let (mut seen_on_a_plane, mut outside, mut elsewhere) = (0usize, 0usize, 0usize);
        let mut elsewhere_error = 0f64;
        let mut holes = 0usize;
        let step =
            registration.max_obliquity_deg.to_radians().tan() * 1.5 / depth_k.fx.min(depth_k.fy);
        for (i, &got) in registered.iter().enumerate() {
            let (x, y) = (i as u32 % color_k.width, i as u32 / color_k.width);
            let want_m = color.depth_m[i];
            let want = (want_m as f64 / UNIT_M).round() as i64;
            // Where the color pixel's surface point lies in the depth image.
            let p = world_to_depth * (color.position[i] - depth_position.as_vec3());
            let (u, v) = (
                p.x / p.z * depth_k.fx as f32 + depth_k.cx as f32,
                p.y / p.z * depth_k.fy as f32 + depth_k.cy as f32,
            );
            let inside = want_m > 0.0
                && p.z > 0.0
                && (0.0..=(depth_k.width - 1) as f32).contains(&u)
                && (0.0..=(depth_k.height - 1) as f32).contains(&v);
            if !inside {
                assert_eq!(
                    got, 0,
                    "t {time_s}: color pixel {x},{y} lies outside the depth camera's view \
                     but got depth {got}"
                );
                outside += 1;
                continue;
            }
            // The four depth pixels around it all on the color pixel's plane: the depth
            // camera sampled that plane there.
            let (u0, v0) = (u.floor() as u32, v.floor() as u32);
            let corners = [(u0, v0), (u0 + 1, v0), (u0, v0 + 1), (u0 + 1, v0 + 1)];
            let on_plane = color.plane[i].is_some()
                && corners.iter().all(|&(cu, cv)| {
                    let (cu, cv) = (cu.min(depth_k.width - 1), cv.min(depth_k.height - 1));
                    depth.plane[(cv * depth_k.width + cu) as usize] == color.plane[i]
                });
            if on_plane {
                // A hole here is a pixel within a depth pixel of a silhouette, which the
                // color camera may see differently (counted below).
                assert!(
                    got == 0 || (got as i64 - want).abs() <= 1,
                    "t {time_s}: color pixel {x},{y} (seen by both on {:?}): registered \
                     {got} mm, true {want} mm",
                    color.plane[i]
                );
                seen_on_a_plane += 1;
                holes += (got == 0) as usize;
            } else if got != 0 {
                // Beside an edge, a crease or on the ball: depth between two samples of
                // the depth camera, off by at most the step the obliquity limit lets
                // a triangle span.
                let error = (got as f64 - want as f64).abs() / want as f64;
                assert!(
                    error <= step,
                    "t {time_s}: color pixel {x},{y}: registered {got} mm, true {want} mm"
                );
                elsewhere_error = elsewhere_error.max(error);
                elsewhere += 1;
            }
        }
        eprintln!(
            "t {time_s}: {seen_on_a_plane} pixels seen by both on a plane (within 1 mm; \
             {holes} of them holes beside a silhouette), \
             {elsewhere} near edges or on the ball (at most {:.2} % off), {outside} outside \
             the depth camera's view (no depth)",
            elsewhere_error * 100.0
        );
        assert!(
            seen_on_a_plane > 40_000 && outside > 1_000,
            "a weak test view"
        );
        assert!(
            holes * 100 <= seen_on_a_plane * 2,
            "t {time_s}: {holes} of {seen_on_a_plane} pixels seen by both are holes"
        );
    }
}
