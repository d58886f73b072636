//! Tests of the image operation and the stage: exact planes, codes, densification,
//! discontinuities, noise reduction, determinism.

use super::*;
use crate::kind;
use relume_base::raster::{DepthImage, LabelImage, Vec3Image};
use relume_base::rng::Counter;
use relume_base::simd::Kernel;
use relume_graph::{BuildContext, Params};
use relume_recording::Header;
use std::collections::BTreeMap;

const W: u32 = 40;
const H: u32 = 30;

/// A 40 x 30 camera with a narrow field of view (rays within +-0.33 of the axis).
fn camera() -> Pinhole {
    Pinhole {
        width: W,
        height: H,
        fx: 60.0,
        fy: 60.0,
        cx: 19.5,
        cy: 14.5,
    }
}

/// Depth along the ray through pixel (x, y) to the plane `normal . X = offset`.
fn plane_depth(normal: Vec3, offset: f32, x: u32, y: u32) -> f32 {
    offset / normal.dot(camera().ray(x as f32, y as f32))
}

/// Camera-space positions of the plane `normal . X = offset` at every pixel.
fn plane_points(normal: Vec3, offset: f32) -> Vec3Image {
    let cam = camera();
    let data = (0..H)
        .flat_map(|y| (0..W).map(move |x| (x, y)))
        .map(|(x, y)| cam.back_project(x as f32, y as f32, plane_depth(normal, offset, x, y)))
        .collect();
    Image::from_vec(W, H, data).unwrap()
}

struct Outputs {
    normals: Vec3Image,
    depth: DepthImage,
    counts: LabelImage,
    codes: LabelImage,
}

fn run(points: &Vec3Image, params: &PlaneFitParams) -> Outputs {
    let (w, h) = (points.width, points.height);
    let mut out = Outputs {
        normals: Image::filled(w, h, Vec3::ONE),
        depth: Image::filled(w, h, -1.0),
        counts: Image::filled(w, h, 99),
        codes: Image::filled(w, h, 99),
    };
    let cam = Pinhole {
        width: w,
        height: h,
        ..camera()
    };
    plane_fit_normals(
        points,
        &cam,
        params,
        &mut out.normals,
        &mut out.depth,
        &mut out.counts,
        &mut out.codes,
    )
    .unwrap();
    out
}

fn params(sample_step: usize, radius: f32, k: usize) -> PlaneFitParams {
    PlaneFitParams {
        radius,
        k,
        sample_step,
        ..PlaneFitParams::default()
    }
}

fn pixels() -> impl Iterator<Item = (u32, u32)> {
    (0..H).flat_map(|y| (0..W).map(move |x| (x, y)))
}

#[test]
fn noise_free_planes_are_exact_in_all_three_cases() {
    // Facing the camera (n_z largest), a floor below it (n_y), a wall to its right (n_x).
    let planes = [
        (Vec3::new(0.2, -0.1, -1.0), FitCase::Z),
        (Vec3::new(0.1, -1.0, -0.5), FitCase::Y),
        (Vec3::new(-1.0, 0.1, -0.7), FitCase::X),
    ];
    for (normal, case) in planes {
        let normal = normal.normalize();
        let points = plane_points(normal, -2.0);
        // The image's own samples take the case the stage must evaluate.
        assert_eq!(fit_plane(&points.data, 1e-3).unwrap().case, case);
        for (step, radius) in [(1, 3.0), (3, 7.0)] {
            // The floor recedes to 7.7 m at the top: rows there lie more than 0.1 m
            // apart in depth, and the default gap would leave collinear samples.
            let wide_gap = PlaneFitParams {
                max_depth_gap: 10.0,
                ..params(step, radius, 16)
            };
            let out = run(&points, &wide_gap);
            for (x, y) in pixels() {
                assert_eq!(*out.codes.at(x, y), 0, "pixel ({x}, {y}) of {normal}");
                let n = *out.normals.at(x, y);
                assert!(
                    (n - normal).length() < 2e-5,
                    "{n} != {normal} at ({x}, {y})"
                );
                let (z, expected) = (*out.depth.at(x, y), plane_depth(normal, -2.0, x, y));
                assert!((z - expected).abs() < 2e-6 * expected, "{z} != {expected}");
            }
        }
    }
}

#[test]
fn pixels_without_depth_are_densified_from_covering_disks() {
    let normal = Vec3::new(0.3, 0.2, -1.0).normalize();
    let mut points = plane_points(normal, -1.5);
    for (x, y) in pixels().filter(|&(x, y)| (10..15).contains(&x) && (8..13).contains(&y)) {
        points.data[(y * W + x) as usize] = Vec3::NAN;
    }
    let out = run(&points, &params(1, 4.0, 255));
    // The hole's centre (12, 10) is 2 pixels from the nearest sample, within the radius.
    for (x, y) in [(12, 10), (10, 8), (14, 12)] {
        assert_eq!(*out.codes.at(x, y), 0);
        assert!((*out.normals.at(x, y) - normal).length() < 2e-5);
        let expected = plane_depth(normal, -1.5, x, y);
        assert!((*out.depth.at(x, y) - expected).abs() < 2e-6 * expected);
    }
    // Disks of radius 4 (49 offsets) minus the 25 missing samples around (12, 10).
    assert_eq!(*out.counts.at(12, 10), 49 - 25);
    assert_eq!(*out.counts.at(30, 20), 49);
}

#[test]
fn neighbour_counts_follow_disks_and_k() {
    let points = plane_points(Vec3::NEG_Z, -2.0);
    // Radius 2: the offsets with dx^2 + dy^2 <= 4 are 13; at a corner 6 lie inside.
    let out = run(&points, &params(1, 2.0, 255));
    assert_eq!(*out.counts.at(20, 15), 13);
    assert_eq!(*out.counts.at(0, 0), 6);
    assert_eq!(*out.counts.at(W - 1, H - 1), 6);
    let out = run(&points, &params(1, 2.0, 5));
    assert_eq!(*out.counts.at(20, 15), 5);
    // Step 3, radius 3: a pixel on a sample has itself and its 4 axis neighbours;
    // pixel (1, 1) has the samples at (0, 0), (3, 0), (0, 3) and (3, 3) only.
    let out = run(&points, &params(3, 3.0, 255));
    assert_eq!(*out.counts.at(3, 3), 5);
    assert_eq!(*out.counts.at(4, 4), 4);
    // Pixel (4, 3) lies between the samples (3, 3) and (6, 3); the next ones, (3, 0)
    // and (3, 6), are farther than 3: two samples, too few for a plane.
    assert_eq!(*out.counts.at(4, 3), 2);
    assert_eq!(*out.codes.at(4, 3), NormalCode::TooFewSamples as u8);
    assert_eq!(*out.codes.at(4, 4), 0);
}

#[test]
fn codes_for_no_sample_too_few_and_degenerate_neighbourhoods() {
    let plane = plane_points(Vec3::new(0.1, 0.2, -1.0).normalize(), -2.0);
    let mut points = Image::filled(W, H, Vec3::NAN);
    // Two samples 2 pixels apart; radius 3.
    for x in [5, 7] {
        points.data[(10 * W + x) as usize] = plane.data[(10 * W + x) as usize];
    }
    // One full row: its points lie on a line in space (the plane cut by the row's
    // plane of view rays).
    for x in 0..W {
        points.data[(25 * W + x) as usize] = plane.data[(25 * W + x) as usize];
    }
    let out = run(&points, &params(1, 3.0, 16));
    let code = |x, y| NormalCode::from_u8(*out.codes.at(x, y));
    assert_eq!(code(6, 10), Some(NormalCode::TooFewSamples));
    assert_eq!(*out.counts.at(6, 10), 2);
    assert_eq!(code(2, 10), Some(NormalCode::TooFewSamples));
    assert_eq!(*out.counts.at(2, 10), 1);
    assert_eq!(code(6, 5), Some(NormalCode::NoSample));
    assert_eq!(*out.counts.at(6, 5), 0);
    assert_eq!(code(20, 25), Some(NormalCode::Degenerate));
    assert_eq!(code(20, 23), Some(NormalCode::Degenerate));
    assert_eq!(*out.counts.at(20, 25), 7);
    for (x, y) in pixels() {
        if *out.codes.at(x, y) != 0 {
            assert_eq!(*out.normals.at(x, y), Vec3::ZERO);
            assert_eq!(*out.depth.at(x, y), 0.0);
        }
    }
}

#[test]
fn rays_that_miss_the_plane_near_its_samples_are_invalid() {
    // A wall x = 0.5 parallel to the optical axis, measured only at columns 24 and right
    // of them (from 6.7 m at column 24 to 2.5 m at the right border).
    let cam = camera();
    let mut points = Image::filled(W, H, Vec3::NAN);
    for (x, y) in pixels().filter(|&(x, _)| x >= 24) {
        let ray = cam.ray(x as f32, y as f32);
        points.data[(y * W + x) as usize] = ray * (0.5 / ray.x);
    }
    let wide_gap = PlaneFitParams {
        max_depth_gap: 3.0,
        ..params(1, 7.0, 64)
    };
    let out = run(&points, &wide_gap);
    // Column 19 looks left of the optical axis: its ray meets the wall behind the
    // camera. Column 21 meets it at 20 m, far beyond its samples (about 6 m).
    for x in [19, 21] {
        assert_eq!(
            *out.codes.at(x, 10),
            NormalCode::RayMissesPlane as u8,
            "{x}"
        );
        assert_eq!(*out.normals.at(x, 10), Vec3::ZERO);
        assert_eq!(*out.depth.at(x, 10), 0.0);
    }
    assert_eq!(*out.codes.at(30, 10), 0);
    assert!((*out.normals.at(30, 10) - Vec3::NEG_X).length() < 1e-5);
}

#[test]
fn pixels_next_to_a_depth_step_keep_their_own_side() {
    // Left: a wall at 1 m facing the camera; right (x >= 20): a tilted wall 0.5 m behind.
    let near = plane_points(Vec3::NEG_Z, -1.0);
    let far_normal = Vec3::new(0.3, -0.2, -1.0).normalize();
    let far = plane_points(far_normal, -1.5 * far_normal.dot(Vec3::NEG_Z).abs());
    let split = |x: u32| {
        if x < 20 {
            (&near, Vec3::NEG_Z)
        } else {
            (&far, far_normal)
        }
    };
    let points =
        Image::from_vec(W, H, pixels().map(|(x, y)| *split(x).0.at(x, y)).collect()).unwrap();
    for step in [1, 2] {
        let out = run(&points, &params(step, 2.5 * step as f32, 16));
        // Every pixel on a sample is its own nearest sample, so it keeps its side; with
        // step 1 that is every pixel, including both columns at the step.
        for (x, y) in pixels().filter(|&(x, y)| x % step as u32 == 0 && y % step as u32 == 0) {
            let (side, normal) = split(x);
            assert_eq!(*out.codes.at(x, y), 0);
            assert!(
                (*out.normals.at(x, y) - normal).length() < 2e-5,
                "({x}, {y})"
            );
            let z = side.at(x, y).z;
            assert!((*out.depth.at(x, y) - z).abs() < 2e-6 * z, "({x}, {y})");
        }
        if step == 1 {
            // Pixel (19, 15) lists its 16 nearest of 21 covering samples: the 13 within
            // distance 2 and 3 of the 8 at sqrt(5), by row then column. 5 of them lie
            // right of the step and are dropped: k-hat = 11.
            assert_eq!(*out.counts.at(19, 15), 11);
            assert_eq!(*out.counts.at(10, 15), 16);
        }
    }
}

/// The plane through (0, 0, 2) with normal (0.2, -0.1, -1) and depth noise of 5 mm
/// (plus holes where `holes`), keyed by pixel so it is the same on every run.
fn noisy_plane(holes: bool) -> (Vec3Image, Vec3) {
    let normal = Vec3::new(0.2, -0.1, -1.0).normalize();
    let clean = plane_points(normal, -2.0 * normal.dot(Vec3::NEG_Z).abs());
    let mut points = clean.clone();
    for (i, p) in points.data.iter_mut().enumerate() {
        let mut rng = Counter::new(&[7, i as u64]);
        if holes && rng.next_f32() < 0.1 {
            *p = Vec3::NAN;
        } else {
            *p *= 1.0 + 0.0025 * rng.next_gaussian() as f32;
        }
    }
    (points, normal)
}

#[test]
fn refined_depth_is_less_noisy_than_the_input() {
    let (points, normal) = noisy_plane(false);
    let offset = -2.0 * normal.dot(Vec3::NEG_Z).abs();
    let out = run(&points, &params(1, 3.0, 32));
    let (mut raw, mut refined, mut angle) = (0.0f64, 0.0f64, 0.0f64);
    for (x, y) in pixels() {
        let truth = plane_depth(normal, offset, x, y) as f64;
        raw += (points.at(x, y).z as f64 - truth).powi(2);
        refined += (*out.depth.at(x, y) as f64 - truth).powi(2);
        angle += out.normals.at(x, y).angle_between(normal) as f64;
    }
    let n = (W * H) as f64;
    let (raw, refined) = ((raw / n).sqrt(), (refined / n).sqrt());
    // 29 samples per disk: about 1 / sqrt(29) of the noise at the centre, more at the
    // borders where the disks are cut.
    assert!(refined < 0.3 * raw, "refined {refined} m, raw {raw} m");
    assert!(angle / n < 0.05, "mean angle {} rad", angle / n);
}

#[test]
fn same_bits_for_any_thread_count() {
    let (points, _) = noisy_plane(true);
    let p = params(3, 7.0, 16);
    let bits = |threads: usize| {
        let out = relume_base::threads::with_threads(threads, || run(&points, &p));
        let normals: Vec<[u32; 3]> = out
            .normals
            .data
            .iter()
            .map(|n| n.to_array().map(f32::to_bits))
            .collect();
        let depth: Vec<u32> = out.depth.data.iter().map(|z| z.to_bits()).collect();
        (normals, depth, out.counts.data, out.codes.data)
    };
    let one = bits(1);
    assert!(one.3.iter().filter(|&&c| c == 0).count() > 1000);
    assert_eq!(one, bits(3));
}

/// Every output of a fit of `points` with `kernel`'s lanes (`None`: one pixel at a
/// time), as bits.
type FitBits = (Vec<[u32; 3]>, Vec<u32>, Vec<u8>, Vec<u8>);
fn fit_bits(kernel: Option<Kernel>, points: &Vec3Image, p: &PlaneFitParams) -> FitBits {
    let mut out = Outputs {
        normals: Image::filled(W, H, Vec3::ONE),
        depth: Image::filled(W, H, -1.0),
        counts: Image::filled(W, H, 99),
        codes: Image::filled(W, H, 99),
    };
    super::driver::plane_fit_normals_by(
        kernel,
        points,
        &camera(),
        p,
        &mut out.normals,
        &mut out.depth,
        &mut out.counts,
        &mut out.codes,
    )
    .unwrap();
    let normals: Vec<[u32; 3]> = (out.normals.data.iter())
        .map(|n| n.to_array().map(f32::to_bits))
        .collect();
    let depth: Vec<u32> = out.depth.data.iter().map(|z| z.to_bits()).collect();
    (normals, depth, out.counts.data, out.codes.data)
}

#[test]
fn lanes_give_the_bits_of_one_pixel_at_a_time() {
    // Noise, holes (NaN, and zero depth), and patches pushed 0.3 m back (depth steps
    // beyond the gap): references found late, lists thinned, too few samples.
    let (mut points, _) = noisy_plane(true);
    for (i, p) in points.data.iter_mut().enumerate() {
        let (x, y) = (i % W as usize, i / W as usize);
        if (x / 7 + y / 5) % 3 == 0 {
            *p *= 1.15;
        }
        if (x * 31 + y * 17) % 53 == 0 {
            *p = Vec3::ZERO;
        }
    }
    let bits = |kernel: Option<Kernel>, p: &PlaneFitParams| fit_bits(kernel, &points, p);
    let mut invalid = 0;
    for (step, radius, k) in [(1, 2.5, 16), (2, 5.0, 8), (3, 7.0, 255), (4, 9.0, 3)] {
        let p = params(step, radius, k);
        let reference = bits(None, &p);
        let codes = &reference.3;
        let valid = codes.iter().filter(|&&c| c == 0).count();
        assert!(valid > 300, "step {step}: {valid} valid");
        invalid += codes.len() - valid;
        // The depth steps thin some lists: without the gap test, other counts.
        let no_gap = PlaneFitParams {
            max_depth_gap: 100.0,
            ..p
        };
        assert!(bits(None, &no_gap).2 != reference.2, "step {step}");
        for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
            assert!(
                bits(Some(kernel), &p) == reference,
                "step {step}, {kernel:?}"
            );
        }
    }
    assert!(invalid > 20, "{invalid} pixels without a plane");
}

#[test]
fn lanes_give_the_bits_of_one_pixel_at_a_time_in_every_case_of_the_fit() {
    // Noisy planes whose normals lie nearest the y and the x axis (the fit's Y and X
    // cases; the plane above is its Z case), and one with a patch stretched 1e21
    // times along x, whose sums overflow (NaN determinants, which go to the scalar
    // fit; here the lanes would agree with it anyway).
    let noisy = |normal: Vec3, offset: f32| {
        let mut points = plane_points(normal.normalize(), offset);
        for (i, p) in points.data.iter_mut().enumerate() {
            *p *= 1.0 + 0.0025 * Counter::new(&[9, i as u64]).next_gaussian() as f32;
        }
        points
    };
    let floor = noisy(Vec3::new(0.1, 1.0, 0.6), 1.0);
    let wall = noisy(Vec3::new(1.0, 0.1, 0.6), 1.0);
    let mut stretched = noisy_plane(false).0;
    for (i, p) in stretched.data.iter_mut().enumerate() {
        if i % W as usize >= 24 && i / W as usize >= 12 {
            p.x *= 1e21;
        }
    }
    let p = params(2, 5.0, 16);
    for (name, points, axis) in [
        ("floor", &floor, 1),
        ("wall", &wall, 0),
        ("stretched", &stretched, 2),
    ] {
        let reference = fit_bits(None, points, &p);
        // Most normals lie nearest the case's axis.
        let nearest = |n: &[u32; 3]| {
            let a = n.map(|c| f32::from_bits(c).abs());
            (0..3).max_by(|&i, &j| a[i].total_cmp(&a[j])).unwrap()
        };
        let valid = (reference.3.iter().zip(&reference.0)).filter(|&(&c, _)| c == 0);
        let on_axis = valid.filter(|&(_, n)| nearest(n) == axis).count();
        assert!(
            on_axis > 600,
            "{name}: {on_axis} normals nearest axis {axis}"
        );
        for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
            assert!(
                fit_bits(Some(kernel), points, &p) == reference,
                "{name}, {kernel:?}"
            );
        }
    }
}

#[test]
fn all_invalid_and_empty_inputs() {
    let out = run(&Image::filled(W, H, Vec3::NAN), &PlaneFitParams::default());
    assert!(
        out.codes
            .data
            .iter()
            .all(|&c| c == NormalCode::NoSample as u8)
    );
    assert!(out.counts.data.iter().all(|&c| c == 0));
    assert!(out.normals.data.iter().all(|&n| n == Vec3::ZERO));
    assert!(out.depth.data.iter().all(|&z| z == 0.0));
    // Zero or negative depth is missing too.
    let out = run(&Image::filled(W, H, Vec3::ZERO), &PlaneFitParams::default());
    assert!(
        out.codes
            .data
            .iter()
            .all(|&c| c == NormalCode::NoSample as u8)
    );
    let empty = run(&Image::filled(0, 0, Vec3::NAN), &PlaneFitParams::default());
    assert!(empty.codes.is_empty());
}

#[test]
fn size_mismatches_and_bad_parameters_are_errors() {
    let points = plane_points(Vec3::NEG_Z, -2.0);
    let mut normals = Image::filled(W, H, Vec3::ZERO);
    let mut depth = Image::filled(W, H, 0.0);
    let mut counts = Image::filled(W, H, 0);
    let mut short = Image::filled(W, H - 1, 0);
    let err = plane_fit_normals(
        &points,
        &camera(),
        &PlaneFitParams::default(),
        &mut normals,
        &mut depth,
        &mut counts,
        &mut short,
    )
    .unwrap_err();
    assert_eq!(err.to_string(), "code map is 40x29, points are 40x30");
    assert!(matches!(err, crate::OpError::SizeMismatch(_)), "{err:?}");
    let mut codes = Image::filled(W, H, 0);
    let bad = PlaneFitParams {
        k: 2,
        ..PlaneFitParams::default()
    };
    let err = plane_fit_normals(
        &points,
        &camera(),
        &bad,
        &mut normals,
        &mut depth,
        &mut counts,
        &mut codes,
    )
    .unwrap_err();
    assert_eq!(err.to_string(), "k 2 must lie in [3, 255]");
    assert!(matches!(err, crate::OpError::BadParameter(_)), "{err:?}");
}

#[test]
fn stage_reads_points_and_writes_four_products() {
    let params = Params::defaults(INFO.params);
    let ports = (INFO.ports)(&params);
    let names = |ports: &[relume_graph::Port]| -> BTreeMap<String, String> {
        ports
            .iter()
            .map(|p| (p.role.clone(), p.default_product.clone()))
            .collect()
    };
    let (inputs, outputs) = (names(&ports.inputs), names(&ports.outputs));
    assert_eq!(inputs.keys().collect::<Vec<_>>(), ["points"]);
    let intrinsics = Intrinsics {
        width: 80,
        height: 60,
        fx: 120.0,
        fy: 120.0,
        cx: 39.5,
        cy: 29.5,
    };
    let header = Header::new("t", intrinsics, 0.001);
    let dir = std::env::temp_dir();
    let ctx = BuildContext {
        stage_name: "n",
        params: &params,
        inputs: &inputs,
        outputs: &outputs,
        header: &header,
        out_dir: &dir,
        seed: 1,
        world: &crate::world::world_of(relume_scene::objects::VirtualScene::default()),
    };
    let mut stage = (INFO.build)(&ctx).unwrap();
    let mut frame = Frame::new(0, 0);
    // At half the intrinsics' size, the camera is the scaled one of `camera()`.
    frame.insert(
        "points",
        Product::new(kind::POINTS, plane_points(Vec3::NEG_Z, -2.0)),
    );
    stage.process(&mut frame).unwrap();
    let normals = frame.normals("normals").unwrap();
    assert!((*normals.at(20, 15) - Vec3::NEG_Z).length() < 1e-5);
    let depth = frame.depth("refined_depth").unwrap();
    assert!((*depth.at(20, 15) - 2.0).abs() < 1e-5);
    assert_eq!(*frame.labels("normal_codes").unwrap().at(20, 15), 0);
    assert_eq!(*frame.labels("neighbours").unwrap().at(20, 15), 16);
}

#[test]
fn swaps_with_normals_cross_in_the_geometry_pipeline() {
    use relume_graph::{Pipeline, SourceFile};
    const GEOMETRY: &str = include_str!("../../../../pipelines/geometry.toml");
    let cross = "kind = \"normals.cross\"\nparams = { step = 1, difference = \"forward\", \
                 max_depth_jump = 0.1 }\n";
    assert!(GEOMETRY.contains(cross));
    let text = GEOMETRY.replace(cross, "kind = \"normals.plane_fit\"\n");
    let src = SourceFile {
        name: "pipelines/plane_fit.toml".into(),
        text,
    };
    let pipeline = Pipeline::parse(&src, &crate::registry()).unwrap();
    let kinds: Vec<&str> = pipeline.stages.iter().map(|s| s.kind).collect();
    assert_eq!(
        kinds,
        ["decode", "depth.to_points", "normals.plane_fit", "write"]
    );
}
