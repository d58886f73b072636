//! The filter against eqs. 21-23 evaluated directly, the kernels against each other,
//! and the stage wrapper.

use super::*;
use crate::kind;

/// Values of a layer per pixel (`None`: no value), f64.
type Values = Vec<Option<[f64; 3]>>;

/// A tap outside the pass's own line (the temporal taps of eq. 26): source position,
/// source B^2 and value.
type ExtraTap = (glam::DVec3, f64, [f64; 3]);

/// One pass of eqs. 21-23 (or 22 with the extra taps of eq. 26) evaluated directly in
/// f64 with exact exp, along X or Y, over the taps |i| <= `radius`.
fn pass(
    position: &Vec3Image,
    values: &Values,
    b2: &[f64],
    along_x: bool,
    radius: i64,
    extra: &dyn Fn(i64, i64) -> Vec<ExtraTap>,
) -> Values {
    let (w, h) = (position.width as i64, position.height as i64);
    let p = |x: i64, y: i64| position.data[(y * w + x) as usize].as_dvec3();
    let mut out = vec![None; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            if values[(y * w + x) as usize].is_none() {
                continue;
            }
            let b2_target = b2[(y * w + x) as usize];
            let (mut sum, mut weight) = ([0.0; 3], 0.0);
            let mut add = |q: glam::DVec3, b2_source: f64, v: [f64; 3]| {
                let bbar2 = 0.5 * (b2_target + b2_source);
                let wt = (-2.0 * bbar2 * (p(x, y) - q).length_squared()).exp();
                for c in 0..3 {
                    sum[c] += wt * v[c];
                }
                weight += wt;
            };
            for i in -radius..=radius {
                let (sx, sy) = if along_x { (x + i, y) } else { (x, y + i) };
                if sx < 0 || sy < 0 || sx >= w || sy >= h {
                    continue;
                }
                let Some(v) = values[(sy * w + sx) as usize] else {
                    continue;
                };
                add(p(sx, sy), b2[(sy * w + sx) as usize], v);
            }
            for (q, b2_source, v) in extra(x, y) {
                add(q, b2_source, v);
            }
            out[(y * w + x) as usize] = Some(sum.map(|s| s / weight));
        }
    }
    out
}

/// Layer `layer` of `scene` as [`Values`] (no value where it or the position is not
/// finite).
fn layer_values(scene: &Scene, layer: usize) -> Values {
    scene.layers[layer]
        .data
        .iter()
        .zip(&scene.position.data)
        .map(|(v, p)| (v.is_finite() && p.is_finite()).then(|| v.as_dvec3().to_array()))
        .collect()
}

fn no_taps(_: i64, _: i64) -> Vec<ExtraTap> {
    Vec::new()
}

/// Eqs. 21-23 evaluated directly in f64 with exact exp: the X pass, then the Y pass.
fn brute_force(
    scene: &Scene,
    b2x: &[f64],
    b2y: &[f64],
    layer: usize,
    radius: i64,
) -> Vec<[f64; 3]> {
    let values = layer_values(scene, layer);
    let ex = pass(&scene.position, &values, b2x, true, radius, &no_taps);
    pass(&scene.position, &ex, b2y, false, radius, &no_taps)
        .into_iter()
        .map(|v| v.unwrap_or([f64::NAN; 3]))
        .collect()
}

/// The squared bandwidths of `scene` (B_e = 3, B_f = 1) from the filter's own
/// (separately tested) formulas: X and Y direct, indirect.
fn squared_bandwidths(scene: &Scene) -> [Vec<f64>; 3] {
    let (w, h) = (scene.position.width, scene.position.height);
    let mut kx = Image::filled(w, h, 0.0);
    let mut ky = Image::filled(w, h, 0.0);
    screen_curvature(&scene.position, &scene.normal, &mut kx, &mut ky).unwrap();
    let b2 = |f: &dyn Fn(usize) -> f32| {
        (0..(w * h) as usize)
            .map(|i| (f(i) as f64).powi(2))
            .collect::<Vec<f64>>()
    };
    let b_rho = |i: usize| bandwidth::brdf_bandwidth(scene.exponent.data[i]);
    [
        b2(&|i| direct_bandwidth(kx.data[i], scene.zd.data[i], 1.0, b_rho(i), 3.0)),
        b2(&|i| direct_bandwidth(ky.data[i], scene.zd.data[i], 1.0, b_rho(i), 3.0)),
        b2(&|i| indirect_bandwidth(scene.zi.data[i], scene.exponent.data[i])),
    ]
}

/// The worst relative difference of `out` from `expected` (floored at 0.1); NaN must
/// match NaN.
fn worst_difference(expected: &[[f64; 3]], out: &Vec3Image) -> f64 {
    let mut worst = 0.0f64;
    for (e, v) in expected.iter().zip(&out.data) {
        for c in 0..3 {
            if e[c].is_nan() {
                assert!(v[c].is_nan());
            } else {
                worst = worst.max((v[c] as f64 - e[c]).abs() / e[c].abs().max(0.1));
            }
        }
    }
    worst
}

#[test]
fn the_filter_matches_eqs_21_to_23_evaluated_directly() {
    let mut scene = Scene::new(sphere(Vec3::new(0.05, 0.0, 1.5), 0.3, 2.0), 0.3, 0.2);
    scene.set_layers(|i| Vec3::new(1.0 + noise(20, i), 0.5 + noise(21, i), 2.0 * noise(22, i)));
    scene.layers[0].data[700] = Vec3::NAN;
    scene.exponent.data[(30 * W + 48) as usize..(30 * W + 60) as usize].fill(20.0);
    // The full image, a crop whose size is no multiple of the lanes (groups of lanes
    // past the right and bottom edges, partial bands), and narrow crops whose segments
    // are narrower than the taps' reach (X taps cross several segments).
    let mut worst = 0.0f64;
    for scene in [
        scene.clone(),
        scene.crop(93, 70),
        scene.crop(9, 11),
        scene.crop(1, 4),
    ] {
        let (w, h) = (scene.position.width, scene.position.height);
        let mut filter = AxisAlignedFilter::new(params(false));
        let mut out = FilterOutputs::new(w, h);
        filter.filter(&scene.inputs(None), &mut out).unwrap();
        let [bx, by, bi] = squared_bandwidths(&scene);
        for (layer, (b2x, b2y)) in [(0, (&bx, &by)), (1, (&bi, &bi))] {
            let expected = brute_force(&scene, b2x, b2y, layer, 15);
            worst = worst.max(worst_difference(&expected, &out.layers[layer]));
        }
    }
    eprintln!("filter vs direct eqs. 21-23: worst relative difference {worst:e}");
    assert!(worst < 1e-4, "{worst}");
}

/// The temporal extension (eq. 26) with a moving camera against a direct evaluation:
/// the Y pass of frame 2 adds, at the previous pixel (x', y') that [`find_previous`]
/// picks (tested separately), the taps (x', y' + j) of frame 1's X-filtered layer, with
/// frame 1's positions and bandwidths. The camera turns, so lane groups find their
/// previous pixels off the block boundaries (the filter then rotates the lanes) or at
/// different offsets (it then permutes two blocks per line, or gathers per lane where
/// the pixels are further apart).
#[test]
fn the_temporal_taps_match_eq_26_evaluated_directly() {
    let mut first = Scene::new(sphere(Vec3::new(0.05, 0.0, 1.5), 0.3, 2.0), 0.3, 0.2);
    first.set_layers(|i| Vec3::new(1.0 + noise(30, i), 0.5 + noise(31, i), noise(32, i)));
    // Values missing here and there in the previous frame (about 0.2 % of the pixels of
    // a layer), so that some of the windows its temporal taps read are not full.
    // Layers 0 and 1 (direct and indirect E_R): the ones compared below.
    for (layer, seed) in [(0, 38), (1, 39)] {
        for (i, v) in first.layers[layer].data.iter_mut().enumerate() {
            // `noise` is uniform in [-0.5, 0.5).
            if noise(seed, i) < -0.498 {
                *v = Vec3::NAN;
            }
        }
    }
    let mut second = Scene::new(sphere(Vec3::new(0.08, 0.01, 1.52), 0.3, 2.1), 0.3, 0.2);
    second.set_layers(|i| Vec3::new(1.0 + noise(33, i), 0.5 + noise(34, i), noise(35, i)));
    second.layers[1].data[900] = Vec3::NAN;
    let turned = Pose::from_parts(
        glam::DVec3::new(0.02, 0.0, 0.0),
        glam::DQuat::from_rotation_y(0.03),
    );
    // Frame 2's positions scattered by up to 5 cm (some 4 pixels at this size):
    // neighbours find their previous pixels blocks or lines apart, which the filter
    // gathers.
    let mut scattered = second.clone();
    for (i, p) in scattered.position.data.iter_mut().enumerate() {
        *p += 0.1 * Vec3::new(noise(36, i), noise(37, i), 0.0);
    }
    // The full image, a crop whose width is no multiple of the lanes (a last block of
    // the X set partly past the width), and the scattered positions.
    let mut paths = [0usize; 3];
    for (first, second) in [
        (first.clone(), second.clone()),
        (first.crop(93, 70), second.crop(93, 70)),
        (first.clone(), scattered),
    ] {
        let (width, height) = (first.position.width, first.position.height);
        let mut filter = AxisAlignedFilter::new(params(true));
        let mut out = FilterOutputs::new(width, height);
        filter
            .filter(&first.inputs(Some((turned, camera()))), &mut out)
            .unwrap();
        let view = filter.previous_view.unwrap();
        let found: Vec<Option<(usize, usize)>> = second
            .position
            .data
            .iter()
            .map(|&p| find_previous(p, &view, filter.previous_x_set.planes()))
            .collect();
        filter
            .filter(&second.inputs(Some((Pose::IDENTITY, camera()))), &mut out)
            .unwrap();
        // How the lane groups of the Y pass (eight pixels along a row, x0 = 8 n) read
        // their temporal taps: at one offset from a block boundary (rotated); at mixed
        // offsets within two blocks and three lines (permuted), or beyond (gathered).
        let lanes = relume_base::simd::LANES as u32;
        let (mut rotated, mut permuted, mut gathered) = (0, 0, 0);
        for y in 0..height {
            for x0 in (0..width).step_by(lanes as usize) {
                let sources: Vec<(usize, usize)> = (x0..(x0 + lanes).min(width))
                    .filter_map(|x| found[(y * width + x) as usize])
                    .collect();
                let offsets: Vec<(i64, i64)> = (x0..)
                    .zip(&sources)
                    .map(|(x, &(xp, yp))| (xp as i64 - x as i64, yp as i64 - y as i64))
                    .collect();
                let Some(&first) = offsets.first() else {
                    continue;
                };
                let blocks = sources.iter().map(|&(xp, _)| xp / 8);
                let span = blocks.clone().max().unwrap() - blocks.min().unwrap();
                let mut lines: Vec<usize> = sources.iter().map(|&(_, yp)| yp).collect();
                lines.sort_unstable();
                lines.dedup();
                if offsets.iter().all(|&o| o == first) {
                    rotated += usize::from((x0 as i64 + first.0).rem_euclid(8) != 0);
                } else if span <= 1 && lines.len() <= 3 {
                    permuted += 1;
                } else {
                    gathered += 1;
                }
            }
        }
        eprintln!(
            "temporal: lane groups {rotated} rotated, {permuted} permuted, {gathered} gathered"
        );
        for (total, count) in paths.iter_mut().zip([rotated, permuted, gathered]) {
            *total += count;
        }
        let ([b1x, b1y, b1i], [b2x, b2y, b2i]) =
            (squared_bandwidths(&first), squared_bandwidths(&second));
        let (radius, w) = (15i64, width as i64);
        let mut worst = 0.0f64;
        for (layer, (prev_b2x, prev_b2y, b2x, b2y)) in
            [(0, (&b1x, &b1y, &b2x, &b2y)), (1, (&b1i, &b1i, &b2i, &b2i))]
        {
            let prev_x = pass(
                &first.position,
                &layer_values(&first, layer),
                prev_b2x,
                true,
                radius,
                &no_taps,
            );
            let ex = pass(
                &second.position,
                &layer_values(&second, layer),
                b2x,
                true,
                radius,
                &no_taps,
            );
            let temporal_taps = |x: i64, y: i64| -> Vec<ExtraTap> {
                let Some((xp, yp)) = found[(y * w + x) as usize] else {
                    return Vec::new();
                };
                (yp as i64 - radius..=yp as i64 + radius)
                    .filter(|&sy| sy >= 0 && sy < height as i64)
                    .filter_map(|sy| {
                        let i = (sy * w + xp as i64) as usize;
                        prev_x[i].map(|v| (first.position.data[i].as_dvec3(), prev_b2y[i], v))
                    })
                    .collect()
            };
            let expected: Vec<[f64; 3]> =
                pass(&second.position, &ex, b2y, false, radius, &temporal_taps)
                    .into_iter()
                    .map(|v| v.unwrap_or([f64::NAN; 3]))
                    .collect();
            worst = worst.max(worst_difference(&expected, &out.layers[layer]));
        }
        eprintln!("temporal filter vs direct eq. 26: worst relative difference {worst:e}");
        assert!(worst < 1e-4, "{worst}");
    }
    // Every way of reading the taps was checked.
    let [rotated, permuted, gathered] = paths;
    assert!(
        rotated > 100 && permuted > 20 && gathered > 20,
        "{rotated} rotated, {permuted} permuted, {gathered} gathered"
    );
}

#[test]
fn the_stage_reads_its_products_caches_b_e_and_writes_every_output() {
    use relume_graph::{BuildContext, Params};
    use relume_recording::Header;
    use std::collections::BTreeMap;
    let params = Params::defaults(PARAMS);
    let ports = (INFO.ports)(&params);
    let roles: Vec<&str> = ports.inputs.iter().map(|p| p.role.as_str()).collect();
    assert!(roles.contains(&"environment") && roles.contains(&"pose"));
    let mut fixed = params.clone();
    fixed.set(
        "environment_bandwidth",
        relume_graph::ParamValue::Float(4.0),
    );
    fixed.set("temporal", relume_graph::ParamValue::Bool(false));
    let fixed_roles = (INFO.ports)(&fixed).inputs;
    assert_eq!(fixed_roles.len(), 9, "no environment, no pose");
    let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
    let objects = Arc::new(relume_scene::objects::VirtualScene::default());
    let ctx = BuildContext {
        stage_name: "filter",
        params: &params,
        inputs: &BTreeMap::new(),
        outputs: &BTreeMap::new(),
        header: &header,
        out_dir: std::path::Path::new("."),
        seed: 0,
        world: &crate::world::world_of(objects.clone()),
    };
    let mut stage = (INFO.build)(&ctx).unwrap();
    let mut scene = Scene::new(sphere(Vec3::new(0.0, 0.0, 2.0), 0.5, 3.0), 0.5, 0.5);
    scene.set_layers(|i| Vec3::splat(1.0 + noise(12, i)));
    let map = Arc::new(EnvMap::from_fn(64, 32, |d| {
        Vec3::splat(1.0 + 0.5 * (3.0 * d.z.atan2(d.x)).cos())
    }));
    let mut direct = AxisAlignedFilter::new(FilterParams::default());
    let mut expected = FilterOutputs::new(W, H);
    for index in 0..2 {
        let mut frame = Frame::new(index, 0);
        let names = ["e_r_dir", "e_r_ind", "e_rv_dir", "e_rv_ind"];
        for (name, layer) in names.iter().zip(&scene.layers) {
            frame.insert(name, Product::new(kind::RADIANCE, layer.clone()));
        }
        frame.insert(
            "world_position",
            Product::new(kind::POINTS, scene.position.clone()),
        );
        frame.insert(
            "world_normal",
            Product::new(kind::NORMALS, scene.normal.clone()),
        );
        frame.insert(
            "direct_min_distance",
            Product::new(kind::SCALAR, scene.zd.clone()),
        );
        frame.insert(
            "indirect_min_distance",
            Product::new(kind::SCALAR, scene.zi.clone()),
        );
        frame.insert(
            "exponent",
            Product::new(kind::SCALAR, scene.exponent.clone()),
        );
        frame.insert(
            "environment",
            Product::new(kind::ENVIRONMENT, Arc::clone(&map)),
        );
        frame.insert("pose", Product::new(kind::POSE, Pose::IDENTITY));
        stage.process(&mut frame).unwrap();
        let inputs = FilterInputs {
            environment: Some(&map),
            ..scene.inputs(Some((Pose::IDENTITY, camera())))
        };
        expected = FilterOutputs::new(W, H);
        direct.filter(&inputs, &mut expected).unwrap();
        for (role, _) in OUTPUTS {
            assert!(frame.get(role).is_some(), "{role}");
        }
        assert!(same_bits(
            frame.radiance("filtered_e_rv_ind").unwrap(),
            &expected.layers[3]
        ));
        assert_eq!(
            frame.scalar("filter_width_ind").unwrap(),
            &expected.width_ind
        );
    }
    // B_e = 3 of the map: the plane behind the sphere has kappa 0 and z = 0.5:
    // B = 2 (1 + 3) = 8, sigma 1 / 8 m.
    assert_eq!(direct.environment_cache.as_ref().unwrap().1, 3.0);
    assert_eq!(*expected.width_dir.at(0, 0), 0.125);
    let missing = Frame::new(0, 0);
    let mut stage = (INFO.build)(&ctx).unwrap();
    let err = stage.process(&mut missing.clone()).unwrap_err().to_string();
    assert!(err.contains("e_r_dir"), "{err}");
    let bad = FilterParams {
        radius: 0,
        ..Default::default()
    };
    assert!(bad.check().unwrap_err().to_string().contains("radius is 0"));
}

/// Two frames with a moving camera (so the temporal taps take several of the ways of
/// reading them) give the same bits with the portable kernel as with AVX2 + FMA.
#[test]
fn kernels_give_the_same_bits() {
    let mut first = Scene::new(sphere(Vec3::new(0.1, -0.05, 2.0), 0.4, 3.0), 0.7, 0.4);
    first.set_layers(|i| Vec3::new(1.0 + noise(12, i), noise(13, i), 3.0 * noise(14, i)));
    first.layers[3].data[200] = Vec3::NAN;
    let mut second = first.clone();
    second.set_layers(|i| Vec3::new(1.0 + noise(15, i), noise(16, i), noise(17, i)));
    let moved = Pose::from_parts(
        glam::DVec3::new(0.03, 0.01, 0.02),
        glam::DQuat::from_rotation_y(0.02),
    );
    let run = |kernel| {
        let mut filter = AxisAlignedFilter::with_kernel(params(true), kernel);
        filter_still_then_moved(&mut filter, &first, &second, moved)
    };
    let detected = lanes::Kernel::detect();
    if detected == lanes::Kernel::Portable {
        eprintln!("this CPU runs the portable kernel only: nothing to compare");
        return;
    }
    let (portable, fast) = (run(lanes::Kernel::Portable), run(detected));
    for k in 0..4 {
        assert!(same_bits(&portable.layers[k], &fast.layers[k]), "layer {k}");
    }
}
