//! Tests of the stage wrapper, input checks and a cost probe.

use super::tests::{
    H, SPHERE_CENTER, SPHERE_RADIUS, W, camera, floor_scene, pose, run, same_bits, sphere,
    uniform_table,
};
use super::*;
use crate::kind;
use crate::sample::layers::LAYER_OUTPUTS;
use glam::Affine3A;
use glam::Vec3;
use glam::{DQuat, DVec3};
use relume_base::pinhole::Pinhole;
use relume_base::raster::Image;
use relume_graph::Frame;
use relume_graph::Product;
use relume_graph::{BuildContext, Params};
use relume_recording::Intrinsics;
use relume_recording::{Header, Pose};
use relume_scene::light::LightTable;
use relume_scene::objects::Material;
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
        environment: None,
        voxels: None,
        object_voxels: None,
        objects: &objects,
        frame: 0,
        spots: &[],
    };
    sample_path(
        &inputs,
        &PathParams::default(),
        &mut IrradianceLayers::new(0, 0),
    )
    .unwrap();
    let small = Image::filled(3, 2, Vec3::ZERO);
    let bad = PathInputs {
        depth: &scene.depth,
        normals: &small,
        radiance: &scene.radiance,
        camera: camera(),
        ..inputs
    };
    let err = sample_path(
        &bad,
        &PathParams::default(),
        &mut IrradianceLayers::new(W, H),
    )
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
        world: &crate::world::world_of(objects.clone()),
    };
    let mut stage = (INFO.build)(&ctx).unwrap();
    assert_eq!(ports.inputs[0].default_product, "refined_depth");
    assert_eq!(ports.inputs[3].default_product, "compensated");
    let rotation = glam::Mat3::from(pose().matrix3).as_dmat3();
    let pose_record = Pose::from_parts(DVec3::new(0.0, 1.5, -2.0), DQuat::from_mat3(&rotation));
    let mut frame = Frame::new(7, 0);
    frame.insert(
        "refined_depth",
        Product::new(kind::DEPTH, scene.depth.clone()),
    );
    frame.insert(
        "normals",
        Product::new(kind::NORMALS, scene.normals.clone()),
    );
    frame.insert(
        "compensated",
        Product::new(kind::RADIANCE, scene.radiance.clone()),
    );
    frame.insert("pose", Product::new(kind::POSE, pose_record));
    frame.insert(
        "light_table",
        Product::new(kind::LIGHT_TABLE, Arc::new(table.clone())),
    );
    stage.process(&mut frame).unwrap();
    let inputs = PathInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        radiance: &scene.radiance,
        camera: camera(),
        camera_to_world: Affine3A::from_mat4(pose_record.matrix().as_mat4()),
        table: &table,
        environment: None,
        voxels: None,
        object_voxels: None,
        objects: &objects,
        frame: 7,
        spots: &[],
    };
    let mut direct = IrradianceLayers::new(W, H);
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
    for (role, _) in LAYER_OUTPUTS {
        assert!(frame.get(role).is_some(), "{role}");
    }
    assert_eq!(frame.labels("touched").unwrap().data, direct.touched.data);
}

#[test]
fn a_pixel_stride_shades_the_lattice_with_the_bits_of_a_full_run() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    let table = uniform_table(512);
    let full = run(&scene, &objects, &table, &PathParams::default());
    let params = PathParams {
        pixel_stride: 3,
        ..Default::default()
    };
    let lattice = run(&scene, &objects, &table, &params);
    let fresh = IrradianceLayers::new(W, H);
    let layers = |o: &IrradianceLayers| {
        [
            &o.e_r_dir,
            &o.e_r_ind,
            &o.e_rv_dir,
            &o.e_rv_ind,
            &o.world_position,
        ]
        .map(|l| l.data.clone())
    };
    let (full, lattice_layers, fresh) = (layers(&full), layers(&lattice), layers(&fresh));
    for y in 0..H as usize {
        for x in 0..W as usize {
            let i = y * W as usize + x;
            let expected = if x % 3 == 0 && y % 3 == 0 {
                &full
            } else {
                &fresh
            };
            for (k, layer) in lattice_layers.iter().enumerate() {
                assert!(
                    same_bits(layer[i], expected[k][i]),
                    "layer {k} at ({x}, {y})"
                );
            }
        }
    }
    assert!(lattice.e_r_dir.data.iter().any(|v| v.is_finite()));
    let zero = PathParams {
        pixel_stride: 0,
        ..Default::default()
    };
    assert_eq!(
        zero.check().unwrap_err().to_string(),
        "sample.path: pixel_stride is 0, expected 1 or more"
    );
}
