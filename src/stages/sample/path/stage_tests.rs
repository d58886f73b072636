//! Tests of the stage wrapper, input checks and a cost probe.

use super::tests::{
    H, SPHERE_CENTER, SPHERE_RADIUS, W, WALL, camera, floor_scene, pose, run, same_bits, sphere,
    uniform_table,
};
use super::*;
use crate::graph::{BuildContext, Params};
use crate::objects::Material;
use crate::recording::{Header, Pose};
use crate::stages::sample::ssrt::ScreenTracer;
use glam::{DQuat, DVec3};
use std::collections::BTreeMap;

#[test]
fn empty_tables_images_and_bad_sizes_are_handled() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    let out = run(
        &scene,
        &objects,
        &LightTable { samples: vec![] },
        &PathParams::default(),
    );
    let valid = scene.depth.data.iter().position(|&z| z > 0.0).unwrap();
    assert_eq!(out.e_r_dir.data[valid], Vec3::ZERO);
    let empty = Image::filled(0, 0, 0.0);
    let empty3 = Image::filled(0, 0, Vec3::ZERO);
    let table = uniform_table(16);
    let inputs = PathInputs {
        depth: &empty,
        normals: &empty3,
        radiance: &empty3,
        camera: Pinhole::new(&Intrinsics::PRIMESENSE, 0, 0),
        camera_to_world: pose(),
        table: &table,
        objects: &objects,
        frame: 0,
    };
    sample_path(&inputs, &PathParams::default(), &mut PathOutputs::new(0, 0)).unwrap();
    let small = Image::filled(3, 2, Vec3::ZERO);
    let bad = PathInputs {
        depth: &scene.depth,
        normals: &small,
        radiance: &scene.radiance,
        camera: camera(),
        ..inputs
    };
    let err = sample_path(&bad, &PathParams::default(), &mut PathOutputs::new(W, H))
        .unwrap_err()
        .to_string();
    assert!(err.contains("normals is 3x2, depth is 96x72"), "{err}");
    let params = PathParams {
        primary: 0,
        ..Default::default()
    };
    assert!(
        params
            .check()
            .unwrap_err()
            .to_string()
            .contains("primary is 0")
    );
}

#[test]
fn the_stage_reads_its_products_and_writes_every_output() {
    let scene = floor_scene();
    let table = uniform_table(512);
    let objects = Arc::new(sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY));
    let params = Params::defaults(PARAMS);
    let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
    let ports = (INFO.ports)(&params);
    let ctx = BuildContext {
        stage_name: "path",
        params: &params,
        inputs: &ports
            .inputs
            .iter()
            .map(|p| (p.role.clone(), p.default_product.clone()))
            .collect(),
        outputs: &BTreeMap::new(),
        header: &header,
        out_dir: std::path::Path::new("."),
        seed: 3,
        objects: &objects,
    };
    let mut stage = (INFO.build)(&ctx).unwrap();
    assert_eq!(ports.inputs[0].default_product, "refined_depth");
    assert_eq!(ports.inputs[3].default_product, "compensated");
    let rotation = glam::Mat3::from(pose().matrix3).as_dmat3();
    let pose_record = Pose::from_parts(DVec3::new(0.0, 1.5, -2.0), DQuat::from_mat3(&rotation));
    let mut frame = Frame::new(7, 0);
    frame.insert("refined_depth", Product::Depth(scene.depth.clone()));
    frame.insert("normals", Product::Normals(scene.normals.clone()));
    frame.insert("compensated", Product::Radiance(scene.radiance.clone()));
    frame.insert("pose", Product::Pose(pose_record));
    frame.insert("light_table", Product::LightTable(Arc::new(table.clone())));
    stage.process(&mut frame).unwrap();
    let inputs = PathInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        radiance: &scene.radiance,
        camera: camera(),
        camera_to_world: Affine3A::from_mat4(pose_record.matrix().as_mat4()),
        table: &table,
        objects: &objects,
        frame: 7,
    };
    let mut direct = PathOutputs::new(W, H);
    let p = PathParams {
        seed: 3,
        ..Default::default()
    };
    sample_path(&inputs, &p, &mut direct).unwrap();
    let e = frame.radiance("e_rv_dir").unwrap();
    assert!(
        e.data
            .iter()
            .zip(&direct.e_rv_dir.data)
            .all(|(a, b)| same_bits(*a, *b))
    );
    for (role, _) in OUTPUTS {
        assert!(frame.get(role).is_some(), "{role}");
    }
    assert_eq!(frame.labels("touched").unwrap().data, direct.touched.data);
}

/// Not a test: prints what a 640x480 frame costs in work (rays, march iterations,
/// pixels whose paths meet a sphere covering about a tenth of the image), for cost
/// estimates; run with `--ignored --nocapture`. Timings belong to the benchmarks.
#[test]
#[ignore]
fn work_of_a_640x480_frame() {
    let cam = Pinhole::new(&Intrinsics::PRIMESENSE, 640, 480);
    let pose = pose();
    let up_camera = pose.inverse().transform_vector3(Vec3::Y);
    let (mut depth, mut normals) = (Vec::new(), Vec::new());
    for v in 0..480 {
        for u in 0..640 {
            let dir = pose.transform_vector3(cam.ray(u as f32, v as f32));
            let hit = dir.y < 0.0;
            depth.push(if hit { -1.5 / dir.y } else { 0.0 });
            normals.push(if hit { up_camera } else { Vec3::ZERO });
        }
    }
    let depth = Image::from_vec(640, 480, depth).unwrap();
    let normals = Image::from_vec(640, 480, normals).unwrap();
    // The march's iterations for cosine rays from every 7th floor pixel.
    let tracer = ScreenTracer::new(&depth, cam, pose, TraceParams::default());
    let rng = sampling::PixelRng::new(1, 2, 3).stream(sampling::StreamId::Indirect);
    let basis = sampling::Basis::new(up_camera);
    let (mut rays, mut iterations) = (0u64, 0u64);
    for p in (0..depth.len()).step_by(7).filter(|&p| depth.data[p] > 0.0) {
        let z = depth.data[p];
        let o = cam.back_project((p % 640) as f32, (p / 640) as f32, z) + up_camera * (z / cam.fx);
        for k in 0..16 {
            let (u1, u2) = rng.pair((p * 16 + k) as u64);
            let d = basis.to_world(sampling::cosine_hemisphere(u1, u2));
            let mut n = 0;
            tracer.trace_camera_counting(o, d, 1.0, &mut n);
            rays += 1;
            iterations += n as u64;
        }
    }
    println!(
        "{:.2} march iterations per 1 m indirect ray",
        iterations as f64 / rays as f64
    );
    let radiance = Image::filled(640, 480, WALL);
    let table = uniform_table(4096);
    let objects = sphere(Vec3::new(0.0, 0.7, 0.6), 0.55, Material::DIFFUSE_GRAY);
    let inputs = PathInputs {
        depth: &depth,
        normals: &normals,
        radiance: &radiance,
        camera: cam,
        camera_to_world: pose,
        table: &table,
        objects: &objects,
        frame: 0,
    };
    let mut out = PathOutputs::new(640, 480);
    sample_path(&inputs, &PathParams::default(), &mut out).unwrap();
    let share = |n: usize| n as f64 / out.mask.len() as f64;
    println!(
        "virtual pixels {:.3}, touched pixels {:.3}",
        share(out.mask.data.iter().filter(|&&m| m < 1.0).count()),
        share(out.touched.data.iter().filter(|&&t| t > 0).count())
    );
}
