//! The filter against eqs. 21-23 evaluated directly, and the stage wrapper.

use super::*;

/// Eqs. 21-23 evaluated directly in f64 with exact exp: the X pass, then the Y pass.
fn brute_force(
    scene: &Scene,
    b2x: &[f64],
    b2y: &[f64],
    layer: usize,
    radius: i64,
) -> Vec<[f64; 3]> {
    let (w, h) = (W as i64, H as i64);
    let p = |x: i64, y: i64| scene.position.data[(y * w + x) as usize].as_dvec3();
    let value = |x: i64, y: i64| {
        let v = scene.layers[layer].data[(y * w + x) as usize];
        (v.is_finite() && scene.position.data[(y * w + x) as usize].is_finite())
            .then(|| v.as_dvec3().to_array())
    };
    let pass = |values: &dyn Fn(i64, i64) -> Option<[f64; 3]>, b2: &[f64], along_x: bool| {
        let mut out = vec![None; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                if values(x, y).is_none() {
                    continue;
                }
                let (mut sum, mut weight) = ([0.0; 3], 0.0);
                for i in -radius..=radius {
                    let (sx, sy) = if along_x { (x + i, y) } else { (x, y + i) };
                    if sx < 0 || sy < 0 || sx >= w || sy >= h {
                        continue;
                    }
                    let Some(v) = values(sx, sy) else { continue };
                    let bbar2 = 0.5 * (b2[(y * w + x) as usize] + b2[(sy * w + sx) as usize]);
                    let wt = (-2.0 * bbar2 * (p(x, y) - p(sx, sy)).length_squared()).exp();
                    for c in 0..3 {
                        sum[c] += wt * v[c];
                    }
                    weight += wt;
                }
                out[(y * w + x) as usize] = Some(sum.map(|s| s / weight));
            }
        }
        out
    };
    let ex = pass(&value, b2x, true);
    let ex_at = |x: i64, y: i64| ex[(y * w + x) as usize];
    pass(&ex_at, b2y, false)
        .into_iter()
        .map(|v| v.unwrap_or([f64::NAN; 3]))
        .collect()
}

#[test]
fn the_filter_matches_eqs_21_to_23_evaluated_directly() {
    let mut scene = Scene::new(sphere(Vec3::new(0.05, 0.0, 1.5), 0.3, 2.0), 0.3, 0.2);
    scene.set_layers(|i| Vec3::new(1.0 + noise(20, i), 0.5 + noise(21, i), 2.0 * noise(22, i)));
    scene.layers[0].data[700] = Vec3::NAN;
    scene.exponent.data[(30 * W + 48) as usize..(30 * W + 60) as usize].fill(20.0);
    let p = params(false);
    let out = filter_frames(&[&scene], p, None);
    // The bandwidths the filter uses, from its own (separately tested) formulas.
    let mut kx = Image::filled(W, H, 0.0);
    let mut ky = Image::filled(W, H, 0.0);
    screen_curvature(&scene.position, &scene.normal, &mut kx, &mut ky).unwrap();
    let b2 = |f: &dyn Fn(usize) -> f32| {
        (0..(W * H) as usize)
            .map(|i| (f(i) as f64).powi(2))
            .collect::<Vec<f64>>()
    };
    let b_rho = |i: usize| bandwidth::brdf_bandwidth(scene.exponent.data[i]);
    let bx = b2(&|i| direct_bandwidth(kx.data[i], scene.zd.data[i], 1.0, b_rho(i), 3.0));
    let by = b2(&|i| direct_bandwidth(ky.data[i], scene.zd.data[i], 1.0, b_rho(i), 3.0));
    let bi = b2(&|i| indirect_bandwidth(scene.zi.data[i], scene.exponent.data[i]));
    let mut worst = 0.0f64;
    for (layer, (b2x, b2y)) in [(0, (&bx, &by)), (1, (&bi, &bi))] {
        let expected = brute_force(&scene, b2x, b2y, layer, 15);
        for (e, v) in expected.iter().zip(&out.layers[layer].data) {
            for c in 0..3 {
                if e[c].is_nan() {
                    assert!(v[c].is_nan());
                } else {
                    worst = worst.max((v[c] as f64 - e[c]).abs() / e[c].abs().max(0.1));
                }
            }
        }
    }
    eprintln!("filter vs direct eqs. 21-23: worst relative difference {worst:e}");
    assert!(worst < 1e-4, "{worst}");
}

#[test]
fn the_stage_reads_its_products_caches_b_e_and_writes_every_output() {
    use crate::graph::{BuildContext, Params};
    use crate::recording::Header;
    use std::collections::BTreeMap;
    let params = Params::defaults(PARAMS);
    let ports = (INFO.ports)(&params);
    let roles: Vec<&str> = ports.inputs.iter().map(|p| p.role.as_str()).collect();
    assert!(roles.contains(&"environment") && roles.contains(&"pose"));
    let mut fixed = params.clone();
    fixed.set(
        "environment_bandwidth",
        crate::graph::ParamValue::Float(4.0),
    );
    fixed.set("temporal", crate::graph::ParamValue::Bool(false));
    let fixed_roles = (INFO.ports)(&fixed).inputs;
    assert_eq!(fixed_roles.len(), 9, "no environment, no pose");
    let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
    let objects = Arc::new(crate::objects::VirtualScene::default());
    let ctx = BuildContext {
        stage_name: "filter",
        params: &params,
        inputs: &BTreeMap::new(),
        outputs: &BTreeMap::new(),
        header: &header,
        out_dir: std::path::Path::new("."),
        seed: 0,
        objects: &objects,
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
            frame.insert(name, Product::Radiance(layer.clone()));
        }
        frame.insert("world_position", Product::Points(scene.position.clone()));
        frame.insert("world_normal", Product::Normals(scene.normal.clone()));
        frame.insert("direct_min_distance", Product::Scalar(scene.zd.clone()));
        frame.insert("indirect_min_distance", Product::Scalar(scene.zi.clone()));
        frame.insert("exponent", Product::Scalar(scene.exponent.clone()));
        frame.insert("environment", Product::Environment(Arc::clone(&map)));
        frame.insert("pose", Product::Pose(Pose::IDENTITY));
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
