//! Tests of [`super::warp`]: exact plane warps without holes, depth steps without skin,
//! determinism, degenerate input.

use super::warp::*;
use crate::OpError;
use glam::{DQuat, DVec3};
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Image, ScalarImage};
use relume_base::simd::Kernel;
use relume_recording::Intrinsics;
use relume_recording::Pose;

fn camera(w: u32, h: u32) -> Pinhole {
    Pinhole::new(&Intrinsics::PRIMESENSE, w, h)
}

fn pose(t: [f64; 3], axis: [f64; 3], angle: f64) -> Pose {
    Pose::from_parts(
        DVec3::from_array(t),
        DQuat::from_axis_angle(DVec3::from_array(axis).normalize(), angle),
    )
}

/// Depth of the world plane n . X = c seen from `pose` (0 where it is missed).
fn plane_depth(cam: &Pinhole, pose: &Pose, n: DVec3, c: f64) -> DepthImage {
    let (origin, rotation) = (pose.translation(), pose.rotation());
    let data = (0..cam.height)
        .flat_map(|v| (0..cam.width).map(move |u| (u, v)))
        .map(|(u, v)| {
            let ray = DVec3::new(
                (u as f64 - cam.cx as f64) / cam.fx as f64,
                (v as f64 - cam.cy as f64) / cam.fy as f64,
                1.0,
            );
            let t = (c - n.dot(origin)) / n.dot(rotation * ray);
            if t > 0.0 { t as f32 } else { 0.0 }
        })
        .collect();
    Image::from_vec(cam.width, cam.height, data).unwrap()
}

fn warp(
    depth: &DepthImage,
    weight: &ScalarImage,
    from: &Pose,
    to: &Pose,
    params: &WarpParams,
) -> WarpedDepth {
    let cam = camera(depth.width, depth.height);
    let mut out = WarpedDepth::new(depth.width, depth.height);
    warp_depth(depth, weight, from, to, &cam, params, &mut out).unwrap();
    out
}

#[test]
fn the_transform_follows_camera_to_world_poses() {
    // The previous camera sits 1 m to the right (world +x) of the current one, both
    // looking down +z: its origin is at x = +1 in the current camera's space.
    let prev = pose([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.0);
    let cur = Pose::IDENTITY;
    let p = previous_to_current(&prev, &cur).transform_point3(DVec3::ZERO);
    assert!((p - DVec3::X).length() < 1e-12, "{p}");
}

#[test]
fn identity_warp_reproduces_depth_and_weight() {
    let cam = camera(32, 24);
    let depth = plane_depth(&cam, &Pose::IDENTITY, DVec3::new(0.2, 0.1, 1.0), 2.0);
    let weight =
        Image::from_vec(32, 24, (0..32 * 24).map(|i| 1.0 + (i % 7) as f32).collect()).unwrap();
    let out = warp(
        &depth,
        &weight,
        &Pose::IDENTITY,
        &Pose::IDENTITY,
        &WarpParams::default(),
    );
    for i in 0..depth.len() {
        assert!(
            (out.depth.data[i] - depth.data[i]).abs() < 1e-5,
            "pixel {i}"
        );
        assert!(
            (out.weight.data[i] - weight.data[i]).abs() < 1e-4,
            "pixel {i}"
        );
    }
}

#[test]
fn a_plane_warps_to_its_exact_depth_without_holes() {
    let cam = camera(64, 48);
    let (n, c) = (DVec3::new(0.3, -0.2, 1.0).normalize(), 2.0);
    let prev = pose([0.1, -0.05, 0.2], [0.3, 1.0, 0.1], 0.05);
    let cur = pose([0.16, -0.03, 0.23], [1.0, -0.4, 0.5], 0.08);
    let depth = plane_depth(&cam, &prev, n, c);
    assert!(depth.data.iter().all(|&z| z > 1.0 && z < 4.0));
    let out = warp(
        &depth,
        &Image::filled(64, 48, 3.0),
        &prev,
        &cur,
        &WarpParams::default(),
    );
    let truth = plane_depth(&cam, &cur, n, c);
    // Pixels of the current view whose surface point lies inside the previous view
    // (at least half a pixel from its border) must all be covered.
    let to_prev = previous_to_current(&cur, &prev).as_mat4();
    let (mut covered, mut inside) = (0, 0);
    for v in 0..48u32 {
        for u in 0..64u32 {
            let i = (v * 64 + u) as usize;
            let (z, t) = (out.depth.data[i], truth.data[i]);
            if z > 0.0 {
                assert!((z - t).abs() < 1e-4, "({u}, {v}): {z} vs {t}");
                assert_eq!(out.weight.data[i], 3.0);
                covered += 1;
            }
            let q = to_prev.transform_point3(cam.back_project(u as f32, v as f32, t));
            let uv = cam.project(q).unwrap();
            if uv.x >= 0.5 && uv.y >= 0.5 && uv.x <= 62.5 && uv.y <= 46.5 {
                inside += 1;
                assert!(z > 0.0, "hole at ({u}, {v})");
            }
        }
    }
    assert!(
        inside > 64 * 48 / 2 && covered >= inside,
        "{inside} {covered}"
    );
}

#[test]
fn a_depth_step_leaves_a_gap_not_a_skin() {
    // Left half at 1 m in front of a wall at 2 m; the camera moves 10 cm to the right
    // (world +x), so the wall appears from behind the near half's right edge.
    let (w, h) = (64u32, 48u32);
    let depth = Image::from_vec(
        w,
        h,
        (0..w * h)
            .map(|i| if i % w < 32 { 1.0 } else { 2.0 })
            .collect(),
    )
    .unwrap();
    let weight = Image::filled(w, h, 5.0);
    let cur = pose([0.1, 0.0, 0.0], [0.0, 1.0, 0.0], 0.0);
    let out = warp(
        &depth,
        &weight,
        &Pose::IDENTITY,
        &cur,
        &WarpParams::default(),
    );
    let mut gap = 0;
    for (i, &z) in out.depth.data.iter().enumerate() {
        assert!(
            z == 0.0 || (z - 1.0).abs() < 1e-5 || (z - 2.0).abs() < 1e-5,
            "pixel {i} lies between the surfaces: {z}"
        );
        if z == 0.0 && (24..32).contains(&(i % w as usize)) {
            gap += 1;
        }
    }
    // At 64 px the focal length is 52.5: the near surface's last column (31) moves
    // 5.25 px left to 25.75, the wall's first (32) 2.625 px to 29.375, so columns 26
    // to 29 stay empty (the dropped quad between them and the newly seen wall).
    assert_eq!(gap, 4 * h as usize, "gap of {gap} pixels");
    assert!(out.weight.data.iter().all(|&wt| wt == 0.0 || wt == 5.0));
    // With a loose stretch limit the same step is bridged by a skin.
    let loose = warp(
        &depth,
        &weight,
        &Pose::IDENTITY,
        &cur,
        &WarpParams { max_stretch: 2.0 },
    );
    assert!(loose.depth.data.iter().any(|&z| z > 1.01 && z < 1.99));
}

/// A rough scene: a tilted plane with a box in front, noise and holes.
fn rough_scene(w: u32, h: u32) -> (DepthImage, ScalarImage) {
    let cam = camera(w, h);
    let mut depth = plane_depth(&cam, &Pose::IDENTITY, DVec3::new(0.1, 0.3, 1.0), 2.5);
    let mut weight = Image::filled(w, h, 0.0f32);
    for (i, (z, wt)) in depth.data.iter_mut().zip(&mut weight.data).enumerate() {
        let r = relume_base::rng::hash(&[7, i as u64]);
        let (x, y) = (i as u32 % w, i as u32 / w);
        if (w / 4..w / 2).contains(&x) && (h / 3..2 * h / 3).contains(&y) {
            *z = 1.2;
        }
        *z += 0.01 * (relume_base::rng::unit_f32(r) - 0.5);
        if r.is_multiple_of(11) {
            *z = 0.0;
        }
        *wt = 1.0 + (r >> 20) as f32 % 20.0;
    }
    (depth, weight)
}

#[test]
fn warping_is_bit_identical_for_any_thread_count() {
    let (depth, weight) = rough_scene(96, 72);
    let cur = pose([0.07, 0.02, -0.05], [0.2, 1.0, 0.3], 0.06);
    let run = |threads: usize| {
        relume_base::threads::with_threads(threads, || {
            let out = warp(
                &depth,
                &weight,
                &Pose::IDENTITY,
                &cur,
                &WarpParams::default(),
            );
            let bits = |d: &[f32]| d.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            (bits(&out.depth.data), bits(&out.weight.data))
        })
    };
    let one = run(1);
    assert!(one.0.iter().filter(|&&b| b != 0).count() > 96 * 72 / 2);
    assert_eq!(one, run(3));
    assert_eq!(one, run(3));
}

#[test]
fn lanes_give_the_bits_of_one_quad_at_a_time() {
    // 99 columns: 12 groups of eight quads and two quads left over per row.
    let (depth, weight) = rough_scene(99, 72);
    let cam = camera(99, 72);
    let moves = [
        // A small step: triangles about a pixel wide (the lanes' case).
        pose([0.07, 0.02, -0.05], [0.2, 1.0, 0.3], 0.06),
        // Forward by a third of the depth: triangles up to three pixels wide (the
        // scalar fallback's case).
        pose([0.0, 0.0, 0.8], [0.0, 1.0, 0.0], 0.0),
        // Rolled: edges at all angles.
        pose([0.01, 0.0, 0.0], [0.0, 0.0, 1.0], 0.7),
    ];
    for cur in moves {
        let run = |kernel: Option<Kernel>| {
            let mut out = WarpedDepth::new(99, 72);
            let poses = (&Pose::IDENTITY, &cur);
            let p = WarpParams::default();
            warp_depth_by(kernel, &depth, &weight, poses, &cam, &p, &mut out).unwrap();
            let bits = |d: &[f32]| d.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            (bits(&out.depth.data), bits(&out.weight.data))
        };
        let reference = run(None);
        assert!(reference.0.iter().filter(|&&b| b != 0).count() > 99 * 72 / 3);
        for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
            assert!(run(Some(kernel)) == reference, "{cur:?}, {kernel:?}");
        }
    }
}

#[test]
fn the_target_is_reusable_and_degenerate_input_does_not_panic() {
    let (depth, weight) = rough_scene(40, 30);
    let cam = camera(40, 30);
    let cur = pose([0.05, 0.0, 0.0], [0.0, 1.0, 0.0], 0.02);
    let mut target = WarpedDepth::new(40, 30);
    let p = WarpParams::default();
    warp_depth(
        &depth,
        &weight,
        &Pose::IDENTITY,
        &cur,
        &cam,
        &p,
        &mut target,
    )
    .unwrap();
    let first = (target.depth.clone(), target.weight.clone());
    warp_depth(
        &depth,
        &weight,
        &Pose::IDENTITY,
        &cur,
        &cam,
        &p,
        &mut target,
    )
    .unwrap();
    assert_eq!(first, (target.depth.clone(), target.weight.clone()));
    // All invalid, a camera pointing away, a NaN pose: an empty result.
    let zeros = Image::filled(40, 30, 0.0f32);
    warp_depth(
        &zeros,
        &weight,
        &Pose::IDENTITY,
        &cur,
        &cam,
        &p,
        &mut target,
    )
    .unwrap();
    assert!(
        target
            .depth
            .data
            .iter()
            .chain(&target.weight.data)
            .all(|&v| v == 0.0)
    );
    let away = pose([0.0; 3], [0.0, 1.0, 0.0], std::f64::consts::PI);
    warp_depth(
        &depth,
        &weight,
        &Pose::IDENTITY,
        &away,
        &cam,
        &p,
        &mut target,
    )
    .unwrap();
    assert!(target.depth.data.iter().all(|&v| v == 0.0));
    let nan = Pose {
        translation: [f64::NAN; 3],
        rotation: [0.0, 0.0, 0.0, 1.0],
    };
    warp_depth(&depth, &weight, &nan, &cur, &cam, &p, &mut target).unwrap();
    assert!(target.depth.data.iter().all(|&v| v == 0.0));
    // Empty and single-row images.
    for (w, h) in [(0, 0), (5, 1), (1, 5)] {
        let d = Image::filled(w, h, 1.0f32);
        let mut t = WarpedDepth::new(w, h);
        warp_depth(&d, &d, &Pose::IDENTITY, &cur, &camera(w, h), &p, &mut t).unwrap();
        assert!(t.depth.data.iter().all(|&v| v == 0.0));
    }
    // Sizes that do not match are an error.
    let mut small = WarpedDepth::new(20, 15);
    let err = warp_depth(&depth, &weight, &Pose::IDENTITY, &cur, &cam, &p, &mut small);
    assert!(matches!(err, Err(OpError::SizeMismatch(_))));
    let err = warp_depth(
        &depth,
        &weight,
        &Pose::IDENTITY,
        &cur,
        &camera(20, 15),
        &p,
        &mut target,
    );
    assert!(matches!(err, Err(OpError::SizeMismatch(_))));
}
