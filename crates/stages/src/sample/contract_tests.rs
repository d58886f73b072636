//! The contract every renderer keeps, whatever way it computes the irradiance layers
//! (paper 001's path sampling, paper 000's radiance queries, paper 004's area lights,
//! paper 002's virtual point lights):
//!
//! - a constant environment L over a floor, nothing else, gives E_R^dir + E_R^ind =
//!   pi L on the floor (each renderer splits it between the layers its own way);
//! - with no objects, E_RV == E_R bit for bit, in both layers;
//! - with an object, the same bits at 1 and 3 threads and on the portable and AVX2
//!   paths;
//! - a renderer that takes the pipeline's `[[light]]` spot lights keeps paper 002's
//!   flags: a virtual spot leaves E_R bit for bit and adds its irradiance to E_RV on
//!   the real floor it reaches, a real one adds it to both; the same bits at 1 and 3
//!   threads and on every path with lights too.
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
use relume_scene::light::{EnvMap, LightWorld, SpotLight, ValBuilder, ValParams};
use relume_scene::objects::{Material, VirtualScene};
use std::f32::consts::PI;

/// A renderer under the contract: its layers for `scene` under the constant
/// environment `SKY`, with `objects` and the spot lights `spots`, on `lanes`.
type Render = fn(&Scene, &VirtualScene, &[SpotLight], simd::Kernel) -> IrradianceLayers;

/// Every renderer, by the stage kind and parameters it runs as, and whether it takes
/// spot lights.
const RENDERERS: &[(&str, Render, bool)] = &[
    (
        "sample.path query=ssrt",
        |s, o, l, k| path(QueryKind::Ssrt, s, o, l, k),
        true,
    ),
    (
        "sample.path query=em",
        |s, o, l, k| path(QueryKind::Em, s, o, l, k),
        true,
    ),
    (
        "sample.path query=dit",
        |s, o, l, k| path(QueryKind::Dit, s, o, l, k),
        true,
    ),
    (
        "sample.path query=vct",
        |s, o, l, k| path(QueryKind::Vct, s, o, l, k),
        true,
    ),
    ("sample.val", val, true),
    ("sample.dir", dir, true),
];

/// `sample.path` with `query`: the importance table of the constant environment, and
/// the environment as a 6 m dome for the impostor and voxel queries.
fn path(
    query: QueryKind,
    scene: &Scene,
    objects: &VirtualScene,
    spots: &[SpotLight],
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
        spots,
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
fn val(
    scene: &Scene,
    objects: &VirtualScene,
    spots: &[SpotLight],
    lanes: simd::Kernel,
) -> IrradianceLayers {
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
        spots,
    };
    let mut out = val_layers(scene.depth.width, scene.depth.height);
    ValRenderer::with_kernel(lanes)
        .render(&inputs, &ValShadingParams::default(), &mut out)
        .unwrap();
    out
}

/// `sample.dir`: the importance table of the constant environment, with `lanes` (the
/// gather, blur and splats).
fn dir(
    scene: &Scene,
    objects: &VirtualScene,
    spots: &[SpotLight],
    lanes: simd::Kernel,
) -> IrradianceLayers {
    let table = uniform_table(4096);
    let inputs = DirInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        radiance: &scene.radiance,
        camera: camera(),
        camera_to_world: pose(),
        table: &table,
        objects,
        spots,
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
    for &(name, render, _) in RENDERERS {
        let out = render(&scene, &VirtualScene::default(), &[], lanes);
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
    for &(name, render, lights) in RENDERERS {
        let spots = if lights { lamps() } else { Vec::new() };
        let detected = simd::Kernel::detect();
        let one = with_threads(1, || bits(&render(&scene, &objects, &spots, detected)));
        let three = with_threads(3, || bits(&render(&scene, &objects, &spots, detected)));
        assert!(one == three, "{name}: 1 and 3 threads differ");
        let portable = bits(&render(&scene, &objects, &spots, simd::Kernel::Portable));
        assert!(
            portable == one,
            "{name}: the portable and {detected:?} paths differ"
        );
    }
}

/// A spot 2 m above the floor below the sphere, shining down (its shadow of the
/// sphere is 0.44 m wide), real or virtual.
fn lamp(world: LightWorld) -> SpotLight {
    SpotLight {
        name: "lamp".into(),
        world,
        position: Vec3::new(SPHERE_CENTER.x, 2.0, SPHERE_CENTER.z),
        direction: Vec3::NEG_Y,
        intensity: Vec3::new(6.0, 5.0, 4.0),
        beam: 30f32.to_radians(),
        cutoff: 40f32.to_radians(),
    }
}

/// A real and a virtual spot, the virtual one aside.
fn lamps() -> Vec<SpotLight> {
    let mut aside = lamp(LightWorld::Virtual);
    aside.position.x += 0.6;
    vec![lamp(LightWorld::Real), aside]
}

#[test]
fn every_renderer_that_takes_lights_keeps_their_flags() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    let lanes = simd::Kernel::detect();
    for &(name, render, lights) in RENDERERS.iter().filter(|r| r.2) {
        assert!(lights);
        let dark = render(&scene, &objects, &[], lanes);
        for world in [LightWorld::Virtual, LightWorld::Real] {
            let spot = lamp(world);
            let lit = render(&scene, &objects, std::slice::from_ref(&spot), lanes);
            let mut checked = 0;
            for i in 0..lit.mask.data.len() {
                let p = lit.world_position.data[i];
                let below = Vec3::new(p.x - spot.position.x, 0.0, p.z - spot.position.z);
                let ring = (0.55..0.9).contains(&below.length());
                if lit.mask.data[i] != 1.0 || !p.is_finite() || !ring {
                    continue;
                }
                let light = spot.arrival(p, Vec3::Y).unwrap().irradiance;
                let close = |gained: Vec3| {
                    (gained - light).abs().max_element() < 1e-3 * light.max_element()
                };
                let (r, rv) = (
                    lit.e_r_dir.data[i] - dark.e_r_dir.data[i],
                    lit.e_rv_dir.data[i] - dark.e_rv_dir.data[i],
                );
                assert!(
                    close(rv),
                    "{name} {world:?} at {p}: E_RV gained {rv}, the light brings {light}"
                );
                match world {
                    LightWorld::Virtual => assert!(
                        same_bits(lit.e_r_dir.data[i], dark.e_r_dir.data[i]),
                        "{name}: a virtual light changed E_R at {p}"
                    ),
                    LightWorld::Real => assert!(close(r), "{name} at {p}: E_R gained {r}"),
                }
                checked += 1;
            }
            assert!(checked > 20, "{name}: {checked} floor pixels in the ring");
            if world == LightWorld::Virtual {
                for (a, b) in [(&lit.e_r_dir, &dark.e_r_dir), (&lit.e_r_ind, &dark.e_r_ind)] {
                    let same = a.data.iter().zip(&b.data).all(|(&x, &y)| same_bits(x, y));
                    assert!(same, "{name}: a virtual light changed E_R");
                }
            }
        }
    }
}
