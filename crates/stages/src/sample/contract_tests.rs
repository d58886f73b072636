//! The contract every renderer keeps, whatever way it computes the irradiance layers
//! (paper 001's path sampling, paper 000's radiance queries, paper 004's area lights,
//! paper 002's virtual point lights):
//!
//! - a constant environment L over a floor, nothing else, gives E_R^dir + E_R^ind =
//!   pi L on the floor (each renderer splits it between the layers its own way);
//! - with no objects, E_RV == E_R bit for bit, in both layers;
//! - with an object, the same bits at 1 and 3 threads and on the portable and AVX2
//!   paths.
//!
//! A new renderer is one line in [`RENDERERS`]: a function that renders the shared
//! floor scene under the environment `SKY` with given objects and lanes.

use super::instant_radiosity::{DirInputs, DirParams, DirRenderer, MeshPoints};
use super::layers::IrradianceLayers;
use super::path::tests::{
    SKY, SPHERE_CENTER, SPHERE_RADIUS, Scene, bits, camera, dome, floor_scene, pose, same_bits,
    sphere, uniform_table,
};
use super::path::{PathInputs, PathParams, sample_path_with_kernel};
use super::pyramid::DepthPyramid;
use super::query::QueryKind;
use super::val::{ValInputs, ValRenderer, ValShadingParams, val_layers};
use glam::Vec3;
use relume_base::simd;
use relume_base::threads::with_threads;
use relume_scene::light::split::split_direct_indirect;
use relume_scene::light::{EnvMap, ValBuilder, ValParams};
use relume_scene::objects::{Material, VirtualScene};
use std::f32::consts::PI;

/// A renderer under the contract: its layers for `scene` under the constant
/// environment `SKY`, with `objects`, on `lanes`.
type Render = fn(&Scene, &VirtualScene, simd::Kernel) -> IrradianceLayers;

/// Every renderer, by the stage kind and parameters it runs as.
const RENDERERS: &[(&str, Render)] = &[
    ("sample.path query=ssrt", |s, o, k| {
        path(QueryKind::Ssrt, s, o, k)
    }),
    ("sample.path query=em", |s, o, k| {
        path(QueryKind::Em, s, o, k)
    }),
    ("sample.path query=dit", |s, o, k| {
        path(QueryKind::Dit, s, o, k)
    }),
    ("sample.path query=vct", |s, o, k| {
        path(QueryKind::Vct, s, o, k)
    }),
    ("sample.val", val),
    ("sample.dir", dir),
];

/// `sample.path` with `query`: the importance table of the constant environment, and
/// the environment as a 6 m dome for the impostor and voxel queries.
fn path(
    query: QueryKind,
    scene: &Scene,
    objects: &VirtualScene,
    lanes: simd::Kernel,
) -> IrradianceLayers {
    let table = uniform_table(4096);
    let world = dome(Vec3::new(0.0, 1.0, 1.0), 6.0);
    let (environment, voxels) = world.world();
    let inputs = PathInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        radiance: &scene.radiance,
        camera: camera(),
        camera_to_world: pose(),
        table: &table,
        environment,
        voxels,
        objects,
        object_voxels: None,
        frame: 7,
        spots: &[],
    };
    let params = PathParams {
        query,
        seed: 3,
        ..PathParams::default()
    };
    let mut out = IrradianceLayers::new(scene.depth.width, scene.depth.height);
    let pyramid = DepthPyramid::new(&scene.depth);
    sample_path_with_kernel(&inputs, &params, &pyramid, lanes, &mut out).unwrap();
    out
}

/// `sample.val`: the constant environment split (paper 004 Sec. 4.2, 90 % of the
/// energy direct) into light.val's area lights and SH9.
fn val(scene: &Scene, objects: &VirtualScene, lanes: simd::Kernel) -> IrradianceLayers {
    let map = EnvMap::constant(128, 64, SKY);
    let (direct, indirect) = split_direct_indirect(&map, 0.9);
    let lights = ValBuilder::new(ValParams::default()).update(&direct, &indirect);
    let inputs = ValInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        camera: camera(),
        camera_to_world: pose(),
        lights: &lights,
        objects,
        transfer: None,
    };
    let mut out = val_layers(scene.depth.width, scene.depth.height);
    ValRenderer::with_kernel(lanes)
        .render(&inputs, &ValShadingParams::default(), &mut out)
        .unwrap();
    out
}

/// `sample.dir`: the importance table of the constant environment, with `lanes` (the
/// gather, blur and splats).
fn dir(scene: &Scene, objects: &VirtualScene, lanes: simd::Kernel) -> IrradianceLayers {
    let table = uniform_table(4096);
    let inputs = DirInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        radiance: &scene.radiance,
        camera: camera(),
        camera_to_world: pose(),
        table: &table,
        objects,
        spots: &[],
        frame: 7,
    };
    let params = DirParams::default();
    let mesh = MeshPoints::new(objects, params.mesh_points as usize, params.seed);
    let mut out = IrradianceLayers::new(scene.depth.width, scene.depth.height);
    DirRenderer::with_kernel(Some(lanes))
        .render(&inputs, &params, &mesh, &mut out)
        .unwrap();
    out
}

#[test]
fn every_renderer_gives_pi_l_under_a_constant_environment_and_e_rv_equal_to_e_r_without_objects() {
    let scene = floor_scene();
    let lanes = simd::Kernel::detect();
    for &(name, render) in RENDERERS {
        let out = render(&scene, &VirtualScene::default(), lanes);
        let (mut sum, mut n) = (glam::DVec3::ZERO, 0);
        for i in 0..out.e_r_dir.data.len() {
            if scene.depth.data[i] == 0.0 {
                continue;
            }
            sum += (out.e_r_dir.data[i] + out.e_r_ind.data[i]).as_dvec3();
            n += 1;
        }
        let mean = (sum / n as f64).as_vec3() / (PI * SKY);
        assert!(
            (mean - Vec3::ONE).abs().max_element() < 0.01,
            "{name}: E_R / (pi L) = {mean}"
        );
        for (r, rv, layer) in [
            (&out.e_r_dir, &out.e_rv_dir, "direct"),
            (&out.e_r_ind, &out.e_rv_ind, "indirect"),
        ] {
            let same = r.data.iter().zip(&rv.data).all(|(&a, &b)| same_bits(a, b));
            assert!(
                same,
                "{name}: E_RV differs from E_R ({layer}) with no objects"
            );
        }
    }
}

#[test]
fn every_renderer_gives_the_same_bits_at_any_thread_count_and_on_every_path() {
    let scene = floor_scene();
    let material = Material {
        albedo: Vec3::new(0.7, 0.3, 0.2),
        exponent: 0.0,
    };
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, material);
    for &(name, render) in RENDERERS {
        let detected = simd::Kernel::detect();
        let one = with_threads(1, || bits(&render(&scene, &objects, detected)));
        let three = with_threads(3, || bits(&render(&scene, &objects, detected)));
        assert!(one == three, "{name}: 1 and 3 threads differ");
        let portable = bits(&render(&scene, &objects, simd::Kernel::Portable));
        assert!(
            portable == one,
            "{name}: the portable and {detected:?} paths differ"
        );
    }
}
