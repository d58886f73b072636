use super::*;
use crate::kind;
use glam::Affine3A;
use glam::Mat3;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Image, ScalarImage, Vec3Image};
use relume_base::simd::Kernel;
use relume_graph::Frame;
use relume_graph::Product;
use relume_scene::light::AreaLights;
use relume_scene::light::sh::project_sh9;
use relume_scene::light::{AreaLight, EnvMap};
use relume_scene::objects::{Material, Triangle};

const W: u32 = 160;
const H: u32 = 120;
const CAMERA: Vec3 = Vec3::new(2.0, 3.0, 0.0);
pub(super) const SPHERE: Vec3 = Vec3::new(0.0, 0.8, 0.0);
pub(super) const RADIUS: f32 = 0.3;
pub(super) const LAMP: Vec3 = Vec3::new(0.0, 3.5, 0.0);
/// Height of the real slab, between the lamp and the sphere's top.
pub(super) const SLAB_Y: f32 = 1.3;
const ALBEDO: Vec3 = Vec3::new(0.8, 0.3, 0.2);

/// A camera looking straight down (camera x = world x, camera y = world z).
pub(super) fn camera() -> (Pinhole, Affine3A) {
    let pinhole = Pinhole {
        width: W,
        height: H,
        fx: 60.0,
        fy: 60.0,
        cx: 79.5,
        cy: 59.5,
    };
    let rotation = Mat3::from_cols(Vec3::X, Vec3::Z, -Vec3::Y);
    (pinhole, Affine3A::from_mat3_translation(rotation, CAMERA))
}

/// A UV sphere of `RADIUS` at `SPHERE` with smooth normals.
pub(super) fn sphere() -> VirtualScene {
    sphere_at(SPHERE, RADIUS)
}

/// A UV sphere with smooth normals.
pub(super) fn sphere_at(centre: Vec3, radius: f32) -> VirtualScene {
    let (rings, segments) = (24, 48);
    let at = |i: usize, j: usize| {
        let theta = i as f32 / rings as f32 * std::f32::consts::PI;
        let phi = j as f32 / segments as f32 * std::f32::consts::TAU;
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    };
    let mut triangles = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let quad = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
            for [a, b, c] in [[0, 1, 2], [0, 2, 3]] {
                let n = [quad[a], quad[b], quad[c]];
                triangles.push(Triangle {
                    vertices: n.map(|d| centre + d * radius),
                    normals: n,
                    material: 0,
                });
            }
        }
    }
    VirtualScene::new(
        triangles,
        vec![Material {
            albedo: ALBEDO,
            exponent: 0.0,
        }],
    )
}

/// The real scene: the floor y = 0 and, optionally, a horizontal slab at `SLAB_Y` over
/// x in [0.1, 0.6], z in [-0.3, 0.3] (in view); its depth and (camera-space) normal maps.
pub(super) fn real_scene(slab: bool) -> (DepthImage, Vec3Image) {
    let (camera, to_world) = camera();
    let mut depth = Image::filled(W, H, 0.0);
    for y in 0..H {
        for x in 0..W {
            let dir = to_world.transform_vector3(camera.ray(x as f32, y as f32));
            // Camera depth = ray parameter for a ray with camera z = 1.
            let t_floor = -CAMERA.y / dir.y;
            let t_slab = (SLAB_Y - CAMERA.y) / dir.y;
            let p = CAMERA + dir * t_slab;
            let on_slab = slab && (0.1..=0.6).contains(&p.x) && p.z.abs() <= 0.3;
            depth.data[(y * W + x) as usize] = if on_slab { t_slab } else { t_floor };
        }
    }
    (depth, Image::filled(W, H, Vec3::new(0.0, 0.0, -1.0)))
}

pub(super) fn light(position: Vec3, intensity: f32) -> AreaLight {
    AreaLight {
        position,
        normal: -Vec3::Y,
        intensity: Vec3::splat(intensity),
        area: 0.01,
    }
}

pub(super) fn lights(list: Vec<AreaLight>) -> AreaLights {
    AreaLights {
        lights: list,
        sh9: project_sh9(&EnvMap::constant(64, 32, Vec3::new(0.2, 0.3, 0.4))),
    }
}

fn render(
    depth: &DepthImage,
    normals: &Vec3Image,
    lights: &AreaLights,
    scene: &VirtualScene,
) -> IrradianceLayers {
    render_with_spots(depth, normals, lights, scene, &[])
}

/// The layers of the test camera's view with `lights`, the objects `scene` and `spots`.
pub(super) fn render_with_spots(
    depth: &DepthImage,
    normals: &Vec3Image,
    lights: &AreaLights,
    scene: &VirtualScene,
    spots: &[relume_scene::light::SpotLight],
) -> IrradianceLayers {
    let inputs = view_inputs((depth, normals), lights, scene, None, spots);
    sample_val(&inputs, &ValShadingParams::default()).unwrap()
}

/// The inputs of the test camera's view of `depth` and `normals`, with `lights`, the
/// objects `scene`, their `transfer` and `spots`.
pub(super) fn view_inputs<'a>(
    (depth, normals): (&'a DepthImage, &'a Vec3Image),
    lights: &'a AreaLights,
    scene: &'a VirtualScene,
    transfer: Option<&'a relume_scene::light::prt::Transfer>,
    spots: &'a [relume_scene::light::SpotLight],
) -> ValInputs<'a> {
    let (camera, camera_to_world) = camera();
    ValInputs {
        depth,
        normals,
        camera,
        camera_to_world,
        lights,
        objects: scene,
        transfer,
        spots,
    }
}

/// Asserts that `a` and `b` differ only in the objects' indirect light: the same bits
/// in E_R, E_RV^dir and E_RV^ind on the real surfaces (mask not 0).
pub(super) fn only_the_objects_indirect_light_differs(a: &IrradianceLayers, b: &IrradianceLayers) {
    assert_eq!(bits(&a.e_r_dir), bits(&b.e_r_dir));
    assert_eq!(bits(&a.e_r_ind), bits(&b.e_r_ind));
    assert_eq!(bits(&a.e_rv_dir), bits(&b.e_rv_dir));
    let real = |l: &IrradianceLayers| -> Vec<[u32; 3]> {
        let values = l.e_rv_ind.data.iter().zip(&a.mask.data);
        values
            .filter(|&(_, &m)| m != 0.0)
            .map(|(v, _)| v.to_array().map(f32::to_bits))
            .collect()
    };
    assert_eq!(real(a), real(b));
}

/// Eq. 6 for a point light `l` above a receiver at `x` with normal `n`.
fn unshadowed(l: &AreaLight, x: Vec3, n: Vec3) -> f32 {
    let v = l.position - x;
    l.intensity.x * n.dot(v).max(0.0) * (-l.normal.dot(v)).max(0.0) / v.length_squared().powi(2)
}

/// The distance from the sphere's centre to the segment from `x` to the light.
pub(super) fn segment_distance(x: Vec3, light: Vec3) -> f32 {
    let d = light - x;
    let t = ((SPHERE - x).dot(d) / d.length_squared()).clamp(0.0, 1.0);
    (x + d * t).distance(SPHERE)
}

pub(super) fn bits(image: &Vec3Image) -> Vec<[u32; 3]> {
    image
        .data
        .iter()
        .map(|v| v.to_array().map(f32::to_bits))
        .collect()
}

#[test]
fn a_sphere_casts_a_shadow_disk_and_leaves_everything_else_bit_identical() {
    let (depth, normals) = real_scene(false);
    let set = lights(vec![light(LAMP, 10.0)]);
    let out = render(&depth, &normals, &set, &sphere());
    let (mut inside, mut outside, mut on_sphere) = (0, 0, 0);
    for i in 0..out.mask.len() {
        let p = out.world_position.data[i];
        if out.mask.data[i] == 0.0 {
            on_sphere += 1;
            assert_eq!(out.k_v.data[i], ALBEDO);
            assert!((p.distance(SPHERE) - RADIUS).abs() < 5e-3, "{p}");
            // No acne: the lit side gets eq. 6 unshadowed.
            let n = out.world_normal.data[i];
            let expected = unshadowed(&set.lights[0], p, n);
            if n.y > 0.3 {
                let e = out.e_rv_dir.data[i].x;
                assert!(
                    (e - expected).abs() < 1e-4 * expected,
                    "{e} vs {expected} at {p}"
                );
            }
            continue;
        }
        assert!(p.y.abs() < 1e-4, "floor point {p}");
        assert_eq!(out.world_normal.data[i], Vec3::Y);
        let e_r = out.e_r_dir.data[i];
        let expected = unshadowed(&set.lights[0], p, Vec3::Y);
        assert!(
            (e_r.x - expected).abs() < 1e-4 * expected,
            "{e_r} vs {expected}"
        );
        let d = segment_distance(p, LAMP);
        if d < RADIUS - 0.02 {
            inside += 1;
            assert_eq!(out.e_rv_dir.data[i], Vec3::ZERO, "in the shadow at {p}");
            // The shadow map holds the occluder's side facing the light: the distance is
            // to the sphere's top (1.1 m up), not its bottom.
            let d = out.direct_min_distance.data[i];
            assert!(d > 0.5 && d < 1.2 * LAMP.distance(p) / LAMP.y, "{d}");
        } else if d > RADIUS + 0.02 {
            outside += 1;
            assert_eq!(bits(&out.e_rv_dir)[i], bits(&out.e_r_dir)[i], "at {p}");
            assert_eq!(out.direct_min_distance.data[i], f32::INFINITY);
        }
        // Indirect: SH9 of a constant environment, pi L, the same for R and RV.
        assert_eq!(out.e_r_ind.data[i], out.e_rv_ind.data[i]);
        let pi_l = Vec3::new(0.2, 0.3, 0.4) * std::f32::consts::PI;
        assert!((out.e_r_ind.data[i] - pi_l).abs().max_element() < 2e-3);
        assert_eq!(out.indirect_min_distance.data[i], f32::INFINITY);
    }
    eprintln!("shadow pixels {inside}, lit {outside}, sphere {on_sphere}");
    assert!(inside > 100 && outside > 10_000 && on_sphere > 200);
}

#[test]
fn without_objects_rv_equals_r_everywhere() {
    let (depth, normals) = real_scene(true);
    let set = lights(vec![
        light(LAMP, 10.0),
        light(Vec3::new(-2.0, 2.0, 1.0), 5.0),
    ]);
    let out = render(&depth, &normals, &set, &VirtualScene::default());
    assert_eq!(bits(&out.e_rv_dir), bits(&out.e_r_dir));
    assert_eq!(bits(&out.e_rv_ind), bits(&out.e_r_ind));
    assert!(out.mask.data.iter().all(|&m| m == 1.0));
    assert!(out.k_v.data.iter().all(|&k| k == Vec3::ZERO));
    assert!(out.e_r_dir.data.iter().all(|e| e.x > 0.0));
}

#[test]
fn a_real_occluder_keeps_the_object_from_shadowing_again() {
    let (depth, normals) = real_scene(true);
    let side = light(Vec3::new(3.0, 3.0, 2.0), 4.0);
    let set = lights(vec![light(LAMP, 10.0), side]);
    let out = render(&depth, &normals, &set, &sphere());
    let (mut double, mut object_only) = (0, 0);
    for i in 0..out.mask.len() {
        let p = out.world_position.data[i];
        if out.mask.data[i] == 0.0 || p.y.abs() > 1e-3 {
            continue;
        }
        assert!(p.z.abs() > 0.3 || p.x < 0.1 || p.x > 0.6 || p.y < SLAB_Y);
        // Floor points whose ray to the lamp crosses both the slab and the sphere.
        let at_slab = p + (LAMP - p) * (SLAB_Y / LAMP.y);
        let under_slab = (0.12..=0.58).contains(&at_slab.x) && at_slab.z.abs() <= 0.28;
        // Clear of the slab by 4 cm at its height (points are splatted over their patch).
        let clear_of_slab = !(0.06..=0.64).contains(&at_slab.x) || at_slab.z.abs() > 0.34;
        let behind_sphere = segment_distance(p, LAMP) < RADIUS - 0.02;
        if under_slab && behind_sphere {
            double += 1;
            let side_only = unshadowed(&side, p, Vec3::Y);
            assert!(
                (out.e_r_dir.data[i].x - side_only).abs() < 1e-4 * side_only,
                "real shadow at {p}: E_R {} E_RV {} side {side_only} lamp {}",
                out.e_r_dir.data[i],
                out.e_rv_dir.data[i],
                unshadowed(&set.lights[0], p, Vec3::Y)
            );
            assert_eq!(
                bits(&out.e_rv_dir)[i],
                bits(&out.e_r_dir)[i],
                "no double shadow at {p}"
            );
        } else if behind_sphere
            && clear_of_slab
            && segment_distance(p, side.position) > RADIUS + 0.02
        {
            // Only the object blocks the lamp: E_RV is the side light alone.
            object_only += 1;
            let side_only = unshadowed(&side, p, Vec3::Y);
            assert!(
                (out.e_rv_dir.data[i].x - side_only).abs() < 1e-4 * side_only,
                "at {p}"
            );
            assert!(out.e_r_dir.data[i].x > 2.0 * side_only);
        }
    }
    eprintln!("pixels in both shadows: {double}, in the object's only: {object_only}");
    assert!(double > 20 && object_only > 20, "{double} {object_only}");
}

#[test]
fn deterministic_across_thread_counts() {
    let (depth, normals) = real_scene(true);
    let set = lights(vec![
        light(LAMP, 10.0),
        light(Vec3::new(3.0, 3.0, 2.0), 4.0),
    ]);
    let scene = sphere();
    let one = relume_base::threads::with_threads(1, || render(&depth, &normals, &set, &scene));
    let three = relume_base::threads::with_threads(3, || render(&depth, &normals, &set, &scene));
    for (a, b) in [
        (&one.e_r_dir, &three.e_r_dir),
        (&one.e_rv_dir, &three.e_rv_dir),
        (&one.e_rv_ind, &three.e_rv_ind),
        (&one.world_position, &three.world_position),
    ] {
        assert_eq!(bits(a), bits(b));
    }
    let scalar_bits = |s: &ScalarImage| s.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        scalar_bits(&one.direct_min_distance),
        scalar_bits(&three.direct_min_distance)
    );
    assert_eq!(one.mask, three.mask);
}

#[test]
fn missing_depth_and_normals_give_nan_irradiance_not_a_failure() {
    let (mut depth, mut normals) = real_scene(false);
    depth.data[0] = 0.0;
    normals.data[1] = Vec3::ZERO;
    let empty_lights = lights(Vec::new());
    let scene_for_empty = sphere();
    let out = render(&depth, &normals, &empty_lights, &scene_for_empty);
    assert!(out.e_r_dir.data[0].is_nan() && out.e_rv_dir.data[1].is_nan());
    assert!(out.world_position.data[0].is_nan());
    assert!(out.world_position.data[1].is_finite());
    assert_eq!(out.world_normal.data[1], Vec3::ZERO);
    assert_eq!(
        out.e_r_dir.data[2],
        Vec3::ZERO,
        "no lights: no direct light"
    );
    // Mismatched sizes are refused.
    let small = Image::filled(4, 4, Vec3::ZERO);
    let (camera, camera_to_world) = camera();
    let inputs = ValInputs {
        depth: &depth,
        normals: &small,
        camera,
        camera_to_world,
        lights: &empty_lights,
        objects: &VirtualScene::default(),
        transfer: None,
        spots: &[],
    };
    let err = sample_val(&inputs, &ValShadingParams::default()).unwrap_err();
    assert!(err.to_string().contains("normals 4x4"), "{err}");
    // So are shadow maps of no texels or past the size the shading indexes exactly.
    let inputs = ValInputs {
        normals: &normals,
        ..inputs
    };
    for size in [0, 4097] {
        let params = ValShadingParams {
            shadow_map_size: size,
            ..ValShadingParams::default()
        };
        let err = sample_val(&inputs, &params).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!("sample.val: shadow_map_size must be 1 to 4096, not {size}")
        );
    }
    // An empty frame renders to empty outputs (shadow maps are still built).
    let one_light = lights(vec![light(LAMP, 10.0)]);
    let (empty_depth, empty_normals) = (Image::filled(0, 0, 0.0), Image::filled(0, 0, Vec3::ZERO));
    let inputs = ValInputs {
        depth: &empty_depth,
        normals: &empty_normals,
        camera: Pinhole {
            width: 0,
            height: 0,
            ..camera
        },
        objects: &scene_for_empty,
        lights: &one_light,
        ..inputs
    };
    assert!(
        sample_val(&inputs, &ValShadingParams::default())
            .unwrap()
            .mask
            .data
            .is_empty()
    );
}

#[test]
fn the_stage_reads_its_inputs_and_writes_every_role() {
    use glam::DQuat;
    use relume_graph::{BuildContext, Params};
    use relume_recording::{Header, Pose};
    use std::collections::BTreeMap;
    let (depth, normals) = real_scene(false);
    let intrinsics = relume_recording::Intrinsics {
        width: W,
        height: H,
        fx: 60.0,
        fy: 60.0,
        cx: 79.5,
        cy: 59.5,
    };
    let header = Header::new("t", intrinsics, 0.001);
    let params = Params::defaults(PARAMS);
    let objects = Arc::new(sphere());
    let ctx = BuildContext {
        stage_name: "val",
        params: &params,
        inputs: &BTreeMap::new(),
        outputs: &BTreeMap::new(),
        header: &header,
        out_dir: std::path::Path::new("."),
        seed: 1,
        world: &crate::world::world_of(objects.clone()),
    };
    let ports = (INFO.ports)(&params);
    assert_eq!(ports.inputs[0].default_product, "refined_depth");
    let mut stage = (INFO.build)(&ctx).unwrap();
    let (_, to_world) = camera();
    let rotation = DQuat::from_mat3(&Mat3::from(to_world.matrix3).as_dmat3());
    let pose = Pose::from_parts(CAMERA.as_dvec3(), rotation);
    let mut frame = Frame::new(0, 0);
    frame.insert("depth", Product::new(kind::DEPTH, depth.clone()));
    frame.insert("normals", Product::new(kind::NORMALS, normals.clone()));
    frame.insert("pose", Product::new(kind::POSE, pose));
    let set = lights(vec![light(LAMP, 10.0)]);
    frame.insert(
        "lights",
        Product::new(kind::AREA_LIGHTS, Arc::new(set.clone())),
    );
    stage.process(&mut frame).unwrap();
    let direct = render(&depth, &normals, &set, &sphere());
    let e_rv = frame.radiance("e_rv_dir").unwrap();
    let max_difference = e_rv
        .data
        .iter()
        .zip(&direct.e_rv_dir.data)
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0f32, f32::max);
    assert!(max_difference < 1e-3, "{max_difference}");
    for (role, kind) in OUTPUTS {
        assert_eq!(frame.get(role).map(|p| p.kind()), Some(kind[0]), "{role}");
    }
}

#[test]
fn objects_shadow_each_other_through_the_virtual_map() {
    // A small ball above the sphere: the sphere's top is in its shadow.
    let (ball, ball_radius) = (Vec3::new(0.0, 1.6, 0.0), 0.15);
    let mut scene = sphere();
    scene
        .triangles
        .extend(sphere_at(ball, ball_radius).triangles);
    let (depth, normals) = real_scene(false);
    let set = lights(vec![light(LAMP, 10.0)]);
    let out = render(&depth, &normals, &set, &scene);
    let (mut shadowed, mut lit) = (0, 0);
    for i in 0..out.mask.len() {
        let p = out.world_position.data[i];
        if out.mask.data[i] != 0.0 || (p.distance(SPHERE) - RADIUS).abs() > 5e-3 {
            continue;
        }
        let n = out.world_normal.data[i];
        let d = LAMP - p;
        let t = ((ball - p).dot(d) / d.length_squared()).clamp(0.0, 1.0);
        let miss = (p + d * t).distance(ball);
        if miss < ball_radius - 0.02 {
            shadowed += 1;
            assert_eq!(out.e_rv_dir.data[i], Vec3::ZERO, "at {p}");
        } else if miss > ball_radius + 0.02 && n.y > 0.3 {
            lit += 1;
            let expected = unshadowed(&set.lights[0], p, n);
            assert!(
                (out.e_rv_dir.data[i].x - expected).abs() < 1e-4 * expected,
                "at {p}"
            );
        }
    }
    eprintln!("sphere pixels in the ball's shadow {shadowed}, lit {lit}");
    assert!(shadowed > 10 && lit > 50, "{shadowed} {lit}");
}

/// The pixels are shaded eight at a time (`shade_lanes`); with either kernel every
/// output has the bits of the scalar `shade_point` per pixel, in a scene with real and
/// virtual shadows (masked lanes, the slope-bias test, occluder distances).
#[test]
fn every_kernel_gives_the_scalar_bits() {
    let (depth, normals) = real_scene(true);
    let set = lights(vec![
        light(LAMP, 10.0),
        light(Vec3::new(3.0, 3.0, 2.0), 4.0),
        light(Vec3::new(-2.0, 2.5, -1.0), 2.0),
    ]);
    let scene = sphere();
    // Also a crop whose width is no multiple of the lanes (a partial last group).
    for (w, h) in [(W, H), (157, 117)] {
        let (depth, normals) = (crop(&depth, w, h), crop(&normals, w, h));
        let params = ValShadingParams::default();
        let (shadowed, occluded) =
            kernels_match_the_scalar_path(&depth, &normals, &set, &scene, &params);
        eprintln!("{shadowed} real pixels in the objects' shadow, {occluded} with an occluder");
        assert!(shadowed > 100 && occluded > 100, "{shadowed} {occluded}");
    }
}

/// More lights than the tiles' lookup masks have bits (64): a light past them is always
/// looked up. And slope biases of 0 and below (no bias, or a stricter test).
#[test]
fn every_kernel_gives_the_scalar_bits_with_many_lights_and_any_slope_bias() {
    let (depth, normals) = real_scene(true);
    let ring: Vec<AreaLight> = (0..70)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 70.0;
            light(Vec3::new(4.0 * a.cos(), 3.0, 4.0 * a.sin()), 0.05)
        })
        .collect();
    let with_lamp = [ring.clone(), vec![light(LAMP, 10.0)]].concat();
    let scene = sphere();
    for slope_bias in [0.0, -0.5] {
        let params = ValShadingParams {
            slope_bias,
            ..ValShadingParams::default()
        };
        let run = |set: Vec<AreaLight>| {
            kernels_match_the_scalar_path(&depth, &normals, &lights(set), &scene, &params)
        };
        let (ring_only, _) = run(ring.clone());
        // The lamp, light 70, casts the sphere's shadow below it.
        let (shadowed, _) = run(with_lamp.clone());
        assert!(shadowed > ring_only + 100, "{shadowed} vs {ring_only}");
    }
}

fn crop<T: Copy>(image: &Image<T>, w: u32, h: u32) -> Image<T> {
    let data = (0..h)
        .flat_map(|y| (0..w).map(move |x| *image.at(x, y)))
        .collect();
    Image::from_vec(w, h, data).unwrap()
}

fn kernels_match_the_scalar_path(
    depth: &DepthImage,
    normals: &Vec3Image,
    set: &AreaLights,
    scene: &VirtualScene,
    params: &ValShadingParams,
) -> (usize, usize) {
    let (mut camera, camera_to_world) = camera();
    (camera.width, camera.height) = (depth.width, depth.height);
    let inputs = ValInputs {
        depth,
        normals,
        camera,
        camera_to_world,
        lights: set,
        objects: scene,
        transfer: None,
        spots: &[],
    };
    let run = |mut renderer: ValRenderer| {
        let mut out = val_layers(depth.width, depth.height);
        renderer.render(&inputs, params, &mut out).unwrap();
        out
    };
    let reference = run(ValRenderer {
        scalar_reference: true,
        ..ValRenderer::default()
    });
    let shadowed = (0..reference.mask.len())
        .filter(|&i| reference.mask.data[i] == 1.0)
        .filter(|&i| reference.e_rv_dir.data[i] != reference.e_r_dir.data[i])
        .count();
    let occluded = reference
        .direct_min_distance
        .data
        .iter()
        .filter(|d| d.is_finite())
        .count();
    let scalar_bits = |s: &ScalarImage| s.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for kernel in [Kernel::Portable, Kernel::detect()] {
        let out = run(ValRenderer::with_kernel(kernel));
        for (a, b) in [
            (&reference.e_r_dir, &out.e_r_dir),
            (&reference.e_rv_dir, &out.e_rv_dir),
            (&reference.e_r_ind, &out.e_r_ind),
            (&reference.e_rv_ind, &out.e_rv_ind),
            (&reference.world_position, &out.world_position),
            (&reference.k_v, &out.k_v),
        ] {
            assert_eq!(bits(a), bits(b), "{kernel:?}");
        }
        assert_eq!(
            scalar_bits(&reference.direct_min_distance),
            scalar_bits(&out.direct_min_distance),
            "{kernel:?}"
        );
        assert_eq!(reference.mask, out.mask);
    }
    (shadowed, occluded)
}
