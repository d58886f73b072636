//! Tests of the estimates against constant environments and a sphere over a floor,
//! and the fixtures the other test modules share.

use super::*;
use glam::Affine3A;
use glam::Vec3;
use relume_base::pinhole::Pinhole;
use relume_base::raster::Image;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_recording::Intrinsics;
use relume_scene::light::LightSample;
use relume_scene::light::voxels::VoxelVolume;
use relume_scene::light::{EnvMap, LightTable};
use relume_scene::objects::VirtualScene;
use relume_scene::objects::{Material, Triangle};
use std::f32::consts::PI;

pub(crate) const W: u32 = 96;
pub(crate) const H: u32 = 72;
pub(crate) const SKY: Vec3 = Vec3::new(1.0, 0.5, 0.25);
pub(crate) const WALL: Vec3 = Vec3::new(0.2, 0.3, 0.4);
pub(crate) const SPHERE_CENTER: Vec3 = Vec3::new(0.0, 0.6, 1.0);
pub(crate) const SPHERE_RADIUS: f32 = 0.3;

pub(crate) fn camera() -> Pinhole {
    Pinhole::new(&Intrinsics::PRIMESENSE, W, H)
}

/// The camera 1.5 m above the floor (world y = 0) at z = -2, looking down 30 degrees
/// along +z (camera x = world -x).
pub(crate) fn pose() -> Affine3A {
    let (s, c) = (30f32.to_radians().sin(), 30f32.to_radians().cos());
    let forward = Vec3::new(0.0, -s, c);
    let right = Vec3::new(-1.0, 0.0, 0.0);
    Affine3A::from_cols(
        right.into(),
        forward.cross(right).into(),
        forward.into(),
        Vec3::new(0.0, 1.5, -2.0).into(),
    )
}

/// A floor-only scene: depth, camera-space normals and a constant camera radiance.
pub(crate) struct Scene {
    pub depth: DepthImage,
    pub normals: Vec3Image,
    pub radiance: Vec3Image,
}

pub(crate) fn floor_scene() -> Scene {
    let cam = camera();
    let pose = pose();
    let up_camera = pose.inverse().transform_vector3(Vec3::Y);
    let mut depth = Vec::new();
    let mut normals = Vec::new();
    for v in 0..H {
        for u in 0..W {
            let dir = pose.transform_vector3(cam.ray(u as f32, v as f32));
            let hit = dir.y < 0.0;
            depth.push(if hit { -1.5 / dir.y } else { 0.0 });
            normals.push(if hit { up_camera } else { Vec3::ZERO });
        }
    }
    Scene {
        depth: Image::from_vec(W, H, depth).unwrap(),
        normals: Image::from_vec(W, H, normals).unwrap(),
        radiance: Image::filled(W, H, WALL),
    }
}

/// No real geometry at all.
pub(crate) fn void_scene() -> Scene {
    Scene {
        depth: Image::filled(W, H, 0.0),
        normals: Image::filled(W, H, Vec3::ZERO),
        radiance: Image::filled(W, H, Vec3::NAN),
    }
}

/// A constant environment `SKY` sampled uniformly over the sphere, in stratified order:
/// sample i lies in the i-th of N bands of equal solid angle from world +y down.
pub(crate) fn uniform_table(n: usize) -> LightTable {
    let golden = PI * (3.0 - 5f32.sqrt());
    LightTable {
        samples: (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                let r = (1.0 - y * y).max(0.0).sqrt();
                let (s, c) = (golden * i as f32).sin_cos();
                LightSample {
                    direction: Vec3::new(r * c, y, r * s),
                    radiance: SKY,
                    pdf: 1.0 / (4.0 * PI),
                }
            })
            .collect(),
    }
}

/// A UV sphere with smooth normals.
pub(crate) fn sphere(center: Vec3, radius: f32, material: Material) -> VirtualScene {
    let (nu, nv) = (16, 8);
    let at = |i: u32, j: u32| {
        let (theta, phi) = (PI * j as f32 / nv as f32, 2.0 * PI * i as f32 / nu as f32);
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    };
    let mut triangles = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let [a, b, c, d] = [at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)];
            for n in [[a, c, b], [b, c, d]] {
                triangles.push(Triangle {
                    vertices: n.map(|p| center + p * radius),
                    normals: n,
                    material: 0,
                });
            }
        }
    }
    VirtualScene::new(triangles, vec![material])
}

pub(crate) fn run(
    scene: &Scene,
    objects: &VirtualScene,
    table: &LightTable,
    params: &PathParams,
) -> IrradianceLayers {
    run_with_kernel(scene, objects, table, params, simd::Kernel::detect())
}

pub(crate) fn run_with_kernel(
    scene: &Scene,
    objects: &VirtualScene,
    table: &LightTable,
    params: &PathParams,
    lanes: simd::Kernel,
) -> IrradianceLayers {
    run_with_environment(scene, objects, table, (None, None), params, lanes)
}

/// [`run_with_kernel`] with a distance impostor for the `em` and `dit` queries and a
/// voxel volume for `vct`.
pub(crate) fn run_with_environment(
    scene: &Scene,
    objects: &VirtualScene,
    table: &LightTable,
    (environment, voxels): (Option<&EnvMap>, Option<&VoxelVolume>),
    params: &PathParams,
    lanes: simd::Kernel,
) -> IrradianceLayers {
    let inputs = PathInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        radiance: &scene.radiance,
        camera: camera(),
        camera_to_world: pose(),
        table,
        environment,
        voxels,
        objects,
        object_voxels: None,
        frame: 7,
        spots: &[],
    };
    let mut out = IrradianceLayers::new(W, H);
    let pyramid = DepthPyramid::new(&scene.depth);
    sample_path_with_kernel(&inputs, params, &pyramid, lanes, &mut out).unwrap();
    out
}

/// The pixel where world point `p` is seen.
pub(crate) fn pixel_of(p: Vec3) -> usize {
    let (u, v) = camera()
        .pixel_of(pose().inverse().transform_point3(p))
        .unwrap();
    (v * W + u) as usize
}

/// Every output as bits, for exact comparisons (NaN included).
pub(crate) fn bits(out: &IrradianceLayers) -> Vec<u32> {
    let mut b = Vec::new();
    for image in [
        &out.e_r_dir,
        &out.e_r_ind,
        &out.e_rv_dir,
        &out.e_rv_ind,
        &out.k_v,
        &out.world_position,
        &out.world_normal,
    ] {
        b.extend(
            image
                .data
                .iter()
                .flat_map(|v| v.to_array().map(f32::to_bits)),
        );
    }
    for image in [
        &out.mask,
        &out.direct_min_distance,
        &out.indirect_min_distance,
    ] {
        b.extend(image.data.iter().map(|v| v.to_bits()));
    }
    b.extend(out.touched.data.iter().map(|&t| t as u32));
    b
}

pub(crate) fn same_bits(a: Vec3, b: Vec3) -> bool {
    a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)
}

/// E_RV equals E_R bit for bit (both parts) at every untouched pixel; returns how many
/// pixels were touched.
pub(crate) fn assert_untouched_pixels_equal(out: &IrradianceLayers) -> usize {
    let mut touched = 0;
    for i in 0..out.touched.data.len() {
        if out.touched.data[i] != 0 {
            touched += 1;
            continue;
        }
        assert!(
            same_bits(out.e_rv_dir.data[i], out.e_r_dir.data[i]),
            "pixel {i}"
        );
        assert!(
            same_bits(out.e_rv_ind.data[i], out.e_r_ind.data[i]),
            "pixel {i}"
        );
    }
    touched
}

#[test]
fn constant_environment_over_a_floor_gives_pi_l_and_no_indirect_light() {
    let scene = floor_scene();
    let table = uniform_table(4096);
    for object_aware in [false, true] {
        let params = PathParams {
            object_aware,
            ..Default::default()
        };
        let out = run(&scene, &VirtualScene::default(), &table, &params);
        let (mut sum, mut n, mut worst) = (glam::DVec3::ZERO, 0, 0f32);
        for i in 0..out.e_r_dir.data.len() {
            if scene.depth.data[i] == 0.0 {
                assert!(out.e_r_dir.data[i].is_nan() && out.e_rv_ind.data[i].is_nan());
                assert!(out.world_position.data[i].is_nan());
                continue;
            }
            let e = out.e_r_dir.data[i];
            sum += e.as_dvec3();
            n += 1;
            worst = worst.max(((e / (PI * SKY)) - 1.0).abs().max_element());
            assert_eq!(
                out.e_r_ind.data[i],
                Vec3::ZERO,
                "nothing to hit above a floor"
            );
            assert_eq!(out.indirect_min_distance.data[i], f32::INFINITY);
            assert_eq!(out.direct_min_distance.data[i], f32::INFINITY);
            assert_eq!(out.mask.data[i], 1.0);
            assert_eq!(out.k_v.data[i], Vec3::ZERO);
            assert_eq!(out.exponent.data[i], 0.0);
            assert!(out.world_position.data[i].y.abs() < 1e-4);
            assert!((out.world_normal.data[i] - Vec3::Y).length() < 1e-5);
        }
        let mean = (sum / n as f64).as_vec3() / (PI * SKY);
        println!(
            "object_aware {object_aware}: mean E_R^dir / (pi L) = {mean}, worst pixel {worst}"
        );
        assert!((mean - Vec3::ONE).abs().max_element() < 0.005, "{mean}");
        assert!(worst < 0.12, "worst pixel off by {worst}");
        assert_eq!(assert_untouched_pixels_equal(&out), 0);
        assert!(bits(&out) == bits(&run(&scene, &VirtualScene::default(), &table, &params)));
    }
}

/// The 3x3 block of pixels around the one that sees world point `p`.
pub(crate) fn block_around(p: Vec3) -> Vec<usize> {
    let c = pixel_of(p) as i64;
    let w = W as i64;
    [-w - 1, -w, -w + 1, -1, 0, 1, w - 1, w, w + 1]
        .iter()
        .map(|d| (c + d) as usize)
        .collect()
}

#[test]
fn a_sphere_above_the_floor_shadows_and_lights_it_and_nothing_else_changes() {
    let scene = floor_scene();
    let table = uniform_table(4096);
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    let below = block_around(Vec3::new(0.0, 0.0, 1.0));
    for object_aware in [false, true] {
        let (mut r, mut rv, mut ind) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        for seed in 0..8 {
            let params = PathParams {
                object_aware,
                seed,
                ..Default::default()
            };
            let out = run(&scene, &objects, &table, &params);
            let touched = assert_untouched_pixels_equal(&out);
            assert!(
                touched > 100 && touched < (W * H) as usize,
                "{touched} touched"
            );
            // Blocking only darkens real points where every primary is real.
            for i in 0..out.mask.data.len() {
                if out.mask.data[i] == 1.0 && scene.depth.data[i] > 0.0 {
                    assert!(
                        out.e_rv_dir.data[i].cmple(out.e_r_dir.data[i]).all(),
                        "pixel {i}"
                    );
                }
            }
            for &p in &below {
                assert_eq!(
                    out.mask.data[p], 1.0,
                    "the floor is visible under the sphere"
                );
                assert_eq!(out.touched.data[p], 1);
                assert_eq!(out.e_r_ind.data[p], Vec3::ZERO);
                r += out.e_r_dir.data[p];
                rv += out.e_rv_dir.data[p];
                ind += out.e_rv_ind.data[p];
            }
            let nearest = below.iter().map(|&p| out.direct_min_distance.data[p]);
            let nearest = nearest.fold(f32::INFINITY, f32::min);
            assert!(
                nearest > 0.25 && nearest < 0.4,
                "sphere bottom 0.3 m up: {nearest}"
            );
            // Where the sphere is in front: a virtual pixel.
            let centre = pixel_of(SPHERE_CENTER);
            assert_eq!(out.mask.data[centre], 0.0);
            assert_eq!(out.k_v.data[centre], Material::DIFFUSE_GRAY.albedo);
            assert_eq!(out.touched.data[centre], 1);
            let n = out.world_normal.data[centre];
            let p = out.world_position.data[centre];
            assert!(
                ((p - SPHERE_CENTER).length() - SPHERE_RADIUS).abs() < 0.02,
                "{p}"
            );
            assert!((n - (p - SPHERE_CENTER).normalize()).length() < 0.1, "{n}");
            assert!(out.e_rv_dir.data[centre].min_element() > 0.0);
        }
        // Under the sphere it covers sin^2(30 deg) = 1/4 of the cosine-weighted sky.
        let ratio = rv / r;
        let ind = ind / (8 * below.len()) as f32;
        println!("object_aware {object_aware}: E_RV/E_R under the sphere {ratio}, E_RV^ind {ind}");
        assert!(
            (ratio - Vec3::splat(0.75)).abs().max_element() < 0.05,
            "{ratio}"
        );
        // The gray sphere reflects sky light onto the floor below it.
        assert!(ind.min_element() > 0.0, "{ind}");
    }
}

#[test]
fn no_objects_means_e_rv_is_e_r_everywhere() {
    let scene = floor_scene();
    let mut radiance = scene.radiance.clone();
    radiance.data[5] = Vec3::NAN;
    let scene = Scene { radiance, ..scene };
    // A table smaller than a multiple of the strata, odd sample counts, a missing
    // radiance pixel.
    let table = uniform_table(300);
    for object_aware in [false, true] {
        let params = PathParams {
            object_aware,
            primary: 2,
            direct: 3,
            indirect: 5,
            ..Default::default()
        };
        let out = run(&scene, &VirtualScene::default(), &table, &params);
        assert_eq!(assert_untouched_pixels_equal(&out), 0);
        assert!(out.touched.data.iter().all(|&t| t == 0));
    }
}

#[test]
fn virtual_pixels_are_shaded_at_the_object_surface() {
    // A large sphere in the void (no real geometry): where its surface faces the
    // camera, E_RV^dir is pi L for diffuse and (by the convention of the module docs)
    // for glossy materials too; nothing is there to bring indirect light.
    let scene = void_scene();
    let table = uniform_table(4096);
    let camera_position = Vec3::from(pose().translation);
    let center = Vec3::new(0.0, 0.9, 0.0);
    for exponent in [0.0, 2.0] {
        let material = Material {
            albedo: Vec3::new(0.8, 0.5, 0.2),
            exponent,
        };
        let objects = sphere(center, 0.5, material);
        let (mut e, mut ind, mut n) = (glam::DVec3::ZERO, glam::DVec3::ZERO, 0);
        for seed in 0..16 {
            let params = PathParams {
                seed,
                ..Default::default()
            };
            let out = run(&scene, &objects, &table, &params);
            for i in 0..out.mask.data.len() {
                if out.mask.data[i] == 1.0 {
                    assert!(out.e_r_dir.data[i].is_nan(), "no real shading point");
                    if out.touched.data[i] == 0 {
                        assert!(out.e_rv_dir.data[i].is_nan(), "nothing at all");
                    }
                    continue;
                }
                let (p, normal) = (out.world_position.data[i], out.world_normal.data[i]);
                let facing = normal.dot((camera_position - p).normalize());
                if out.mask.data[i] == 0.0 && facing > 0.98 {
                    assert_eq!(out.k_v.data[i], material.albedo);
                    assert_eq!(out.exponent.data[i], exponent);
                    e += out.e_rv_dir.data[i].as_dvec3();
                    ind += out.e_rv_ind.data[i].as_dvec3();
                    n += 1;
                }
            }
        }
        let e = (e / n as f64).as_vec3() / (PI * SKY);
        let ind = (ind / n as f64).as_vec3() / (PI * SKY);
        println!(
            "exponent {exponent}: E_RV^dir / (pi L) = {e} over {n} pixel-runs, E_RV^ind {ind}"
        );
        assert!(n > 300, "{n}");
        assert!((e - Vec3::ONE).abs().max_element() < 0.05, "{e}");
        assert!(
            ind.max_element() < 0.01,
            "a convex object in the void: {ind}"
        );
    }
}

#[test]
fn the_floor_blocks_the_sky_and_lights_a_sphere_where_it_faces_down() {
    // The sphere of the floor tests, 0.3 m above the floor: below its equator the floor
    // (within max_distance, found by the screen-space march) fills part of each surface
    // point's hemisphere. What it takes from the sky's direct light, E_RV^dir / (pi SKY),
    // it gives back as the floor's indirect light, E_RV^ind / (pi WALL): both estimate
    // the same cosine-weighted share of the hemisphere, so the two sum to 1.
    let scene = floor_scene();
    let table = uniform_table(4096);
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    let (mut sky, mut floor, mut n) = (glam::DVec3::ZERO, glam::DVec3::ZERO, 0);
    for seed in 0..8 {
        let params = PathParams {
            seed,
            ..Default::default()
        };
        let out = run(&scene, &objects, &table, &params);
        for i in 0..out.mask.data.len() {
            if out.mask.data[i] == 0.0 && out.world_normal.data[i].y < -0.2 {
                sky += (out.e_rv_dir.data[i] / (PI * SKY)).as_dvec3();
                floor += (out.e_rv_ind.data[i] / (PI * WALL)).as_dvec3();
                n += 1;
            }
        }
    }
    let (sky, floor) = ((sky / n as f64).as_vec3(), (floor / n as f64).as_vec3());
    println!("{n} pixel-runs facing down: sky {sky}, floor {floor}");
    assert!(n > 100, "{n}");
    assert!(
        floor.min_element() > 0.1,
        "the floor lights the sphere: {floor}"
    );
    assert!(
        (sky + floor - Vec3::ONE).abs().max_element() < 0.05,
        "sky {sky} + floor {floor}"
    );
}

#[test]
fn object_aware_sampling_is_unbiased_and_lowers_the_variance() {
    let scene = floor_scene();
    let table = uniform_table(4096);
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, Material::DIFFUSE_GRAY);
    // Floor pixels under and beside the sphere.
    let blocks = [Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.45, 0.0, 0.9)].map(block_around);
    let seeds = 40;
    // Per mode: per block, the block mean of every seed; the per-pixel variance over
    // seeds, pooled over the pixels of both blocks.
    let mut block_means = [[[0f64; 40]; 2]; 2];
    let mut pooled_variance = [0f64; 2];
    for (mode, object_aware) in [false, true].into_iter().enumerate() {
        let mut values = vec![[0f64; 40]; 18];
        for seed in 0..seeds {
            let params = PathParams {
                seed: seed as u64,
                object_aware,
                ..Default::default()
            };
            let out = run(&scene, &objects, &table, &params);
            for (b, block) in blocks.iter().enumerate() {
                for (k, &p) in block.iter().enumerate() {
                    let v = out.e_rv_ind.data[p].y as f64;
                    values[b * 9 + k][seed] = v;
                    block_means[mode][b][seed] += v / 9.0;
                }
            }
        }
        pooled_variance[mode] = values.iter().map(|xs| variance(xs)).sum::<f64>() / 18.0;
    }
    for (b, (correlated, aware)) in block_means[0].iter().zip(&block_means[1]).enumerate() {
        let (m0, m1) = (mean(correlated), mean(aware));
        let se = ((variance(correlated) + variance(aware)) / seeds as f64).sqrt();
        println!(
            "block {b}: mean E_RV^ind correlated {m0:.5}, object-aware {m1:.5} (se of the difference {se:.5})"
        );
        assert!(m0 > 0.0 && m1 > 0.0);
        assert!((m0 - m1).abs() < 4.0 * se, "biased: {m0} vs {m1} (se {se})");
    }
    let [v0, v1] = pooled_variance;
    println!(
        "per-pixel sd of E_RV^ind: correlated {:.5}, object-aware {:.5}",
        v0.sqrt(),
        v1.sqrt()
    );
    assert!(
        v1 < 0.8 * v0,
        "object-aware sampling should lower the variance: {v1} vs {v0}"
    );
}

pub(crate) fn mean(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len() as f64
}

pub(crate) fn variance(xs: &[f64]) -> f64 {
    let m = mean(xs);
    xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (xs.len() - 1) as f64
}

/// A constant environment `SKY` at `radius` metres around a centre, as the distance
/// impostor the impostor queries trace and as the voxel volume `vct` marches.
pub(crate) struct Dome {
    pub(crate) env: EnvMap,
    pub(crate) voxels: VoxelVolume,
}

impl Dome {
    pub(crate) fn world(&self) -> (Option<&EnvMap>, Option<&VoxelVolume>) {
        (Some(&self.env), Some(&self.voxels))
    }
}

pub(crate) fn dome(center: Vec3, radius: f32) -> Dome {
    let mut env = EnvMap::constant(128, 64, SKY);
    env.center = center;
    env.distance = vec![radius; env.radiance.len()];
    // Samples on the sphere about half a voxel apart.
    let voxel = 0.1;
    let rings = (std::f32::consts::PI * radius / (0.5 * voxel)) as u32;
    let mut positions = Vec::new();
    for ring in 0..=rings {
        let theta = std::f32::consts::PI * ring as f32 / rings as f32;
        let around = ((2.0 * rings as f32 * theta.sin()) as u32).max(1);
        for k in 0..around {
            let phi = 2.0 * PI * k as f32 / around as f32;
            let d = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            positions.push(center + d * radius);
        }
    }
    let radiances = vec![SKY; positions.len()];
    let voxels = VoxelVolume::from_points(&positions, &radiances, voxel).unwrap();
    Dome { env, voxels }
}
