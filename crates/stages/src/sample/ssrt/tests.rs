use super::batch::TraceBatch;
use super::*;
use relume_base::raster::Image;
use relume_base::rng::Counter;
use relume_recording::Intrinsics;

const W: u32 = 160;
const H: u32 = 120;

fn camera() -> Pinhole {
    Pinhole::new(&Intrinsics::PRIMESENSE, W, H)
}

/// The camera 1.5 m above a floor (world y = 0), looking down 30 degrees along +z:
/// camera x = world -x, camera y (down) and z (forward) in the y-z plane.
pub(crate) fn floor_camera_pose() -> Affine3A {
    let (s, c) = (30f32.to_radians().sin(), 30f32.to_radians().cos());
    let forward = Vec3::new(0.0, -s, c);
    let right = Vec3::new(-1.0, 0.0, 0.0);
    let down = forward.cross(right);
    Affine3A::from_cols(
        right.into(),
        down.into(),
        forward.into(),
        Vec3::new(0.0, 1.5, -2.0).into(),
    )
}

/// Ray-casts world geometry (a floor at y = 0 and an axis-aligned box) into a depth
/// map seen by `camera` at `pose`; `noise` adds uniform depth noise of that
/// amplitude and 3 % holes.
fn render(camera: &Pinhole, pose: Affine3A, noise: f32) -> DepthImage {
    let boxes = relume_scene::objects::Aabb {
        min: Vec3::new(-0.6, 0.0, 0.4),
        max: Vec3::new(0.2, 0.5, 1.0),
    };
    let mut r = Counter::new(&[9, noise.to_bits() as u64]);
    let mut data = Vec::new();
    for v in 0..camera.height {
        for u in 0..camera.width {
            let ray_c = camera.ray(u as f32, v as f32);
            let dir = pose.transform_vector3(ray_c);
            let o = pose.translation.into();
            let mut t = if dir.y < 0.0 {
                -1.5 / dir.y
            } else {
                f32::INFINITY
            };
            if let Some((t0, _)) = boxes.ray_span(o, dir.recip(), 0.0, t) {
                t = t0;
            }
            // t is along ray_c, whose z is 1: depth = t.
            let mut z = if t < 20.0 { t } else { 0.0 };
            if noise > 0.0 {
                z += noise * (2.0 * r.next_f32() - 1.0);
                if r.next_f32() < 0.03 {
                    z = 0.0;
                }
            }
            data.push(z);
        }
    }
    Image::from_vec(camera.width, camera.height, data).unwrap()
}

/// Random rays from surface points of the map (and a few from mid-air), in camera
/// space, with unit directions.
fn random_rays(cam: &Pinhole, depth: &DepthImage, n: usize, seed: u64) -> Vec<(Vec3, Vec3, f32)> {
    let mut r = Counter::new(&[seed]);
    let mut rays = Vec::new();
    while rays.len() < n {
        let (u, v) = (
            r.next_f32() * cam.width as f32,
            r.next_f32() * cam.height as f32,
        );
        let z = *depth.at(u as u32, v as u32);
        let z = if depth_is_valid(z) && r.next_f32() < 0.9 {
            z
        } else {
            0.3 + 4.0 * r.next_f32()
        };
        let o = cam.back_project(u.floor(), v.floor(), z);
        let d = Vec3::new(
            2.0 * r.next_f32() - 1.0,
            2.0 * r.next_f32() - 1.0,
            2.0 * r.next_f32() - 1.0,
        )
        .normalize_or(Vec3::Z);
        let t_max = [0.3, 1.0, 3.0, f32::INFINITY][(r.next_u64() % 4) as usize];
        rays.push((o, d, t_max));
    }
    rays
}

#[test]
fn hierarchical_march_equals_the_linear_march_bit_for_bit() {
    let cam = camera();
    let pose = floor_camera_pose();
    for (noise, thickness) in [(0.0, 0.1), (0.02, 0.05), (0.05, 0.3)] {
        let depth = render(&cam, pose, noise);
        let params = TraceParams {
            thickness,
            ..Default::default()
        };
        let tracer = ScreenTracer::new(&depth, cam, pose, params);
        let (mut hits, mut iterations, mut traced) = (0, 0u64, 0);
        for (o, d, t_max) in random_rays(&cam, &depth, 20_000, noise.to_bits() as u64) {
            let (ow, dw) = (pose.transform_point3(o), pose.transform_vector3(d));
            let linear = tracer.trace_linear(ow, dw, t_max);
            let to_camera = tracer.world_to_camera();
            let (oc, dc) = (
                to_camera.transform_point3(ow),
                to_camera.transform_vector3(dw),
            );
            let mut n = 0;
            let fast = tracer.trace_camera_counting(oc, dc, t_max, &mut n);
            assert_eq!(
                fast.map(|h| (h.t.to_bits(), h.pixel)),
                linear.map(|h| (h.t.to_bits(), h.pixel)),
                "ray {o} {d} {t_max}"
            );
            assert_eq!(tracer.trace(ow, dw, t_max), fast);
            hits += linear.is_some() as u32;
            iterations += n as u64;
            traced += (n > 0) as u32;
        }
        println!(
            "noise {noise}: {hits} hits of 20000, {:.1} iterations per marched ray",
            iterations as f64 / traced as f64
        );
        assert!(
            hits > 3_000,
            "the scene is hit often enough to test: {hits}"
        );
    }
}

#[test]
fn rays_from_a_shared_origin_give_the_results_of_single_rays() {
    let cam = camera();
    let pose = floor_camera_pose();
    let depth = render(&cam, pose, 0.02);
    let tracer = ScreenTracer::new(&depth, cam, pose, TraceParams::default());
    let mut hits = 0;
    for (o, d, t_max) in random_rays(&cam, &depth, 4_000, 77) {
        let Some(origin) = tracer.origin(o) else {
            assert_eq!(tracer.trace_camera(o, d, t_max), None);
            continue;
        };
        let hit = tracer.trace_from(&origin, d, t_max);
        assert_eq!(hit, tracer.trace_camera(o, d, t_max));
        hits += hit.is_some() as u32;
    }
    assert!(hits > 500, "{hits} hits");
}

#[test]
fn a_batch_gives_the_hits_of_single_rays_with_every_kernel() {
    use relume_base::simd::Kernel;
    let pose = floor_camera_pose();
    // Levels 8 and up (the second half of the lanes' level tables) are only reached by
    // marches crossing a multiple of 256 pixels: at 640x480, not at 160x120. With no
    // skipped pixels, a march may start one pixel further (behind the origin's centre);
    // with more than 64 the setup runs ray by ray.
    // The last field is the fewest hits for the comparison to mean something.
    for (scale, noise, thickness, skip_pixels, min_hits) in [
        (1, 0.0, 0.1, 1.5, 1_000),
        (1, 0.02, 0.05, 1.5, 1_000),
        (1, 0.05, 0.3, 0.0, 1_000),
        (4, 0.02, 0.1, 1.5, 1_000),
        (4, 0.0, 0.1, 0.0, 1_000),
        (4, 0.0, 0.1, 70.0, 300),
    ] {
        let cam = Pinhole::new(&Intrinsics::PRIMESENSE, W * scale, H * scale);
        let depth = render(&cam, pose, noise);
        let params = TraceParams {
            thickness,
            skip_pixels,
        };
        let tracer = ScreenTracer::new(&depth, cam, pose, params);
        let rays = random_rays(&cam, &depth, 6_000, 31 + noise.to_bits() as u64);
        let expected: Vec<_> = rays
            .iter()
            .map(|&(o, d, t_max)| tracer.trace_camera(o, d, t_max))
            .collect();
        let hits = expected.iter().filter(|h| h.is_some()).count();
        assert!(
            hits > min_hits,
            "the scene is hit often enough to test: {hits}"
        );
        for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
            let mut batch = TraceBatch::new(&tracer, 0);
            // Two batches through the same buffers: the second starts clean.
            let half = rays.len() / 2 + 1;
            for (part, rays) in rays.chunks(half).enumerate() {
                batch.clear();
                for (i, &(o, d, t_max)) in rays.iter().enumerate() {
                    assert_eq!(batch.push(tracer.origin(o).as_ref(), d, t_max), i);
                }
                assert_eq!(batch.len(), rays.len());
                assert_eq!(batch.trace(kernel), kernel.available());
                for (i, hit) in batch.hits().iter().enumerate() {
                    let want = expected[part * half + i];
                    assert_eq!(
                        hit.map(|h| (h.t.to_bits(), h.pixel)),
                        want.map(|h| (h.t.to_bits(), h.pixel)),
                        "{kernel:?}, {scale}x, ray {:?}",
                        rays[i]
                    );
                }
            }
        }
    }
}

#[test]
fn an_origin_outside_the_image_finds_nothing() {
    // An origin projected by a larger camera's tracer, outside this tracer's image:
    // marching from it would read outside this pyramid.
    let pose = floor_camera_pose();
    let big_camera = Pinhole::new(&Intrinsics::PRIMESENSE, 4 * W, 4 * H);
    let big_depth = render(&big_camera, pose, 0.0);
    let big = ScreenTracer::new(&big_depth, big_camera, pose, TraceParams::default());
    let cam = camera();
    let depth = render(&cam, pose, 0.0);
    let tracer = ScreenTracer::new(&depth, cam, pose, TraceParams::default());
    let point = big_camera.back_project(600.0, 400.0, 2.0);
    let origin = big.origin(point).unwrap();
    assert!(origin.x > W as f32 && origin.y > H as f32, "{origin:?}");
    let mut batch = TraceBatch::new(&tracer, 1);
    for dir in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z] {
        assert_eq!(tracer.trace_from(&origin, dir, 10.0), None);
        batch.push(Some(&origin), dir, 10.0);
    }
    batch.trace(relume_base::simd::Kernel::Avx2Fma);
    assert!(batch.hits().iter().all(Option::is_none));
}

#[test]
fn a_ray_down_to_the_floor_hits_where_geometry_says() {
    let cam = camera();
    let pose = floor_camera_pose();
    let depth = render(&cam, pose, 0.0);
    let tracer = ScreenTracer::new(&depth, cam, pose, TraceParams::default());
    // From 1 m above the floor point (0.8, 0, 2.5) straight down.
    let origin = Vec3::new(0.8, 1.0, 2.5);
    let hit = tracer.trace(origin, -Vec3::Y, 5.0).expect("the floor");
    assert!((hit.t - 1.0).abs() < 0.02, "t = {}", hit.t);
    let expected = cam
        .pixel_of(pose.inverse().transform_point3(Vec3::new(0.8, 0.0, 2.5)))
        .unwrap();
    let (du, dv) = (
        hit.pixel.0 as i32 - expected.0 as i32,
        hit.pixel.1 as i32 - expected.1 as i32,
    );
    assert!(
        du.abs() <= 1 && dv.abs() <= 1,
        "{:?} vs {expected:?}",
        hit.pixel
    );
    // Upward from the same point: nothing but air.
    assert_eq!(tracer.trace(origin, Vec3::Y, 5.0), None);
    // Too short to reach the floor.
    assert_eq!(tracer.trace(origin, -Vec3::Y, 0.5), None);
}

#[test]
fn degenerate_inputs_find_nothing() {
    let cam = camera();
    let pose = floor_camera_pose();
    let holes = Image::filled(W, H, 0.0);
    let tracer = ScreenTracer::new(&holes, cam, pose, TraceParams::default());
    let o = pose.transform_point3(Vec3::new(0.0, 0.0, 2.0));
    for d in [
        Vec3::X,
        Vec3::Y,
        -Vec3::Z,
        Vec3::new(0.3, -0.2, 0.9).normalize(),
    ] {
        assert_eq!(tracer.trace(o, d, f32::INFINITY), None);
    }
    let empty = Image::filled(0, 0, 0.0);
    let tracer = ScreenTracer::new(
        &empty,
        Pinhole::new(&Intrinsics::PRIMESENSE, 0, 0),
        pose,
        TraceParams::default(),
    );
    assert_eq!(tracer.trace(o, Vec3::X, 1.0), None);
    // NaN directions and origins behind the camera.
    let depth = render(&cam, pose, 0.0);
    let tracer = ScreenTracer::new(&depth, cam, pose, TraceParams::default());
    assert_eq!(
        tracer.trace_camera(Vec3::new(0.0, 0.0, 1.0), Vec3::NAN, 1.0),
        None
    );
    assert_eq!(
        tracer.trace_camera(Vec3::new(0.0, 0.0, -1.0), Vec3::Z, 9.0),
        None
    );
}

#[test]
fn clipping_to_the_image_keeps_exactly_the_samples_inside() {
    // `fixed_range` against testing every a: the samples whose fixed-point minor
    // coordinate lies in [lo, hi] (the pixel rows or columns of the image).
    let mut r = Counter::new(&[31]);
    let (lo, hi) = (1i64 << 16, (481i64 << 16) - 1);
    for case in 0..2_000 {
        let s = match case % 4 {
            0 => 0,
            1 => 65_536,
            2 => -65_536,
            _ => (r.next_u64() % 131_073) as i64 - 65_536,
        };
        let c = (r.next_u64() % (2_000 << 16)) as i64 - (700 << 16);
        let (a0, a1) = fixed_range(c, s, lo, hi);
        for a in -900i64..900 {
            let inside = (lo..=hi).contains(&(c + a * s));
            assert_eq!(
                inside,
                (a0..=a1).contains(&a),
                "c {c} s {s} a {a}: {a0}..={a1}"
            );
        }
    }
}
