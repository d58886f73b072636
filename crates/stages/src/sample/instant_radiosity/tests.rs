//! Tests of Differential Instant Radiosity: the maps, the flags and the layers over the
//! floor scene that the other renderers' tests share.

use super::ism::{Projection, fill_holes, frame_about};
use super::shade::{LightSet, Receiver, gather};
use super::splat::splat;
use super::vpl::{Candidate, Emitter, Vpl, resample};
use super::*;
use crate::sample::path::tests::{
    SPHERE_CENTER, SPHERE_RADIUS, Scene, assert_untouched_pixels_equal, bits, camera, floor_scene,
    pixel_of, pose, sphere, uniform_table,
};
use glam::Vec3;
use relume_base::threads::with_threads;
use relume_scene::light::LightTable;
use relume_scene::objects::Material;
use relume_scene::objects::VirtualScene;

/// The shared floor scene's inputs with `objects` under `table`, at `frame`.
pub(super) fn inputs<'a>(
    scene: &'a Scene,
    objects: &'a VirtualScene,
    table: &'a LightTable,
    frame: u64,
) -> DirInputs<'a> {
    DirInputs {
        depth: &scene.depth,
        normals: &scene.normals,
        radiance: &scene.radiance,
        camera: camera(),
        camera_to_world: pose(),
        table,
        objects,
        spots: &[],
        frame,
    }
}

fn render(
    scene: &Scene,
    objects: &VirtualScene,
    table: &LightTable,
    params: &DirParams,
) -> IrradianceLayers {
    sample_dir(&inputs(scene, objects, table, 5), params).unwrap()
}

pub(super) const RED: Material = Material {
    albedo: Vec3::new(0.9, 0.1, 0.05),
    exponent: 0.0,
};

/// The floor pixels whose point lies between `from` and `to` metres (horizontally)
/// from the point below the sphere's centre.
fn floor_ring(out: &IrradianceLayers, from: f32, to: f32) -> Vec<usize> {
    let below = Vec3::new(SPHERE_CENTER.x, 0.0, SPHERE_CENTER.z);
    (0..out.mask.data.len())
        .filter(|&i| {
            let p = out.world_position.data[i];
            out.mask.data[i] == 1.0 && p.is_finite() && (from..to).contains(&p.distance(below))
        })
        .collect()
}

#[test]
fn an_ism_of_a_dense_point_set_matches_a_brute_force_depth_map_where_it_has_no_holes() {
    // A wavy sheet 1 m in front of a VPL, sampled densely on a jittered grid.
    let projection = Projection::Paraboloid {
        origin: Vec3::ZERO,
        frame: frame_about(Vec3::Z),
    };
    let size = 64;
    let mut points = Vec::new();
    for j in 0..400 {
        for i in 0..400 {
            let h = relume_base::rng::hash(&[i, j]);
            let (u, v) = (
                (i as f32 + relume_base::rng::unit_f32(h)) / 400.0 * 3.0 - 1.5,
                (j as f32 + relume_base::rng::unit_f32(relume_base::rng::mix64(h))) / 400.0 * 3.0
                    - 1.5,
            );
            points.push(Vec3::new(
                u,
                v,
                1.0 + 0.2 * (3.0 * u).sin() * (2.0 * v).cos(),
            ));
        }
    }
    // Brute force: per texel, the nearest of the points that project into it.
    let mut brute = vec![f32::INFINITY; size * size];
    for &p in &points {
        let l = p.normalize();
        let (u, v) = (l.x / (1.0 + l.z), l.y / (1.0 + l.z));
        let (x, y) = (
            ((u * 0.5 + 0.5) * size as f32) as usize,
            ((v * 0.5 + 0.5) * size as f32) as usize,
        );
        if x < size && y < size {
            brute[y * size + x] = brute[y * size + x].min(p.length());
        }
    }
    let mut ism = vec![f32::INFINITY; size * size];
    let splatted = splat(
        &mut ism,
        size,
        &projection,
        points.iter().map(|&p| (p, 0.0)),
    );
    let mut whole = ism.clone();
    let rect = fill_holes(&mut ism, size, 2, splatted, &mut Vec::new());
    // Filling only the splatted blocks gives what filling the whole map gives, and the
    // rectangle returned holds every depth.
    fill_holes(&mut whole, size, 2, [0, 0, size, size], &mut Vec::new());
    assert!(
        ism.iter()
            .zip(&whole)
            .all(|(a, b)| a.to_bits() == b.to_bits())
    );
    for (i, d) in ism.iter().enumerate() {
        let (x, y) = (i % size, i / size);
        let inside = x >= rect[0] as usize
            && x < rect[2] as usize
            && y >= rect[1] as usize
            && y < rect[3] as usize;
        assert!(
            inside || !d.is_finite(),
            "texel ({x}, {y}) outside {rect:?}"
        );
    }
    let (mut compared, mut filled) = (0, 0);
    let window = |x: usize, y: usize, r: i32| -> Vec<f32> {
        let mut v = Vec::new();
        for dy in -r..=r {
            for dx in -r..=r {
                let (qx, qy) = (x as i32 + dx, y as i32 + dy);
                if qx >= 0 && qy >= 0 && (qx as usize) < size && (qy as usize) < size {
                    v.push(brute[qy as usize * size + qx as usize]);
                }
            }
        }
        v.retain(|d| d.is_finite());
        v
    };
    for y in 0..size {
        for x in 0..size {
            let i = y * size + x;
            if brute[i].is_finite() {
                // Where the map has no hole: the brute-force depth, to the bit.
                assert_eq!(ism[i], brute[i], "texel ({x}, {y}) holds a point");
                compared += 1;
            } else if ism[i].is_finite() {
                // A hole, filled from the points of its 2^2 x 2^2 pull-push block.
                let near = window(x, y, 4);
                let (lo, hi) = near
                    .iter()
                    .fold((f32::INFINITY, 0.0f32), |(l, h), &v| (l.min(v), h.max(v)));
                assert!(
                    ism[i] >= lo && ism[i] <= hi,
                    "hole ({x}, {y}): {} not in [{lo}, {hi}]",
                    ism[i]
                );
                filled += 1;
            }
        }
    }
    assert!(compared > 1000, "{compared} texels compared");
    assert!(filled > 0, "the point set should leave some holes to fill");
}

#[test]
fn the_sphere_shadows_the_floor_below_it_in_e_rv_only() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, RED);
    let out = render(
        &scene,
        &objects,
        &uniform_table(4096),
        &DirParams::default(),
    );
    let (mut r, mut rv) = (0.0, 0.0);
    for i in floor_ring(&out, 0.0, 0.2) {
        r += out.e_r_dir.data[i].x;
        rv += out.e_rv_dir.data[i].x;
    }
    // Below a sphere of angular radius 30 degrees, a quarter of the cosine-weighted sky
    // is blocked; the imperfect maps and the blur give or take.
    let ratio = rv / r;
    assert!(
        (0.6..0.9).contains(&ratio),
        "E_RV^dir / E_R^dir below the sphere = {ratio}"
    );
    let far = floor_ring(&out, 1.5, 10.0);
    let open: f32 = far.iter().map(|&i| out.e_r_dir.data[i].x).sum::<f32>() / far.len() as f32;
    assert!(
        (open / std::f32::consts::PI - 1.0).abs() < 0.03,
        "open floor: E_R^dir / pi L = {}",
        open / std::f32::consts::PI
    );
}

#[test]
fn a_virtual_vpl_lights_the_real_floor_beside_a_red_object() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, RED);
    let out = render(
        &scene,
        &objects,
        &uniform_table(4096),
        &DirParams::default(),
    );
    let mut gain = Vec3::ZERO;
    for i in floor_ring(&out, 0.35, 0.8) {
        // The flat floor sends no light onto itself: E_R^ind is 0 there.
        assert_eq!(out.e_r_ind.data[i], Vec3::ZERO);
        gain += out.e_rv_ind.data[i] - out.e_r_ind.data[i];
    }
    assert!(gain.x > 0.0, "E_RV^ind - E_R^ind beside the sphere: {gain}");
    assert!(
        gain.x > 5.0 * gain.y && gain.x > 5.0 * gain.z,
        "not red-shifted: {gain}"
    );
}

/// A light set of `vpls` with empty maps: every visibility is 1.
fn open_lights(vpls: &[Vpl], projections: &[[Projection; 2]], maps: &[f32]) -> LightSet<'static> {
    let vpls: &'static [Vpl] = Vec::leak(vpls.to_vec());
    let projections: &'static [[Projection; 2]] = Vec::leak(projections.to_vec());
    let rects: &'static [[[u16; 4]; 2]] = Vec::leak(vec![[[0; 4]; 2]; vpls.len()]);
    let maps: &'static [f32] = Vec::leak(maps.to_vec());
    LightSet {
        vpls,
        projections,
        rects,
        maps,
        size: 4,
        bias: 0.0,
        slope: 0.0,
        clamp_squared: 0.0,
        reach: 10.0,
        flags: Flags::Reciprocal,
    }
}

#[test]
fn a_real_vpl_whose_light_an_object_blocks_is_cancelled_in_the_combined_world() {
    // A wall point of which the objects leave a quarter of its direct light (Fig. 6:
    // the real light along ray R that the virtual cube blocks).
    let wall = Candidate {
        position: Vec3::new(0.0, 1.0, 0.0),
        normal: Vec3::NEG_Y,
        power_r: Vec3::new(0.8, 0.4, 0.2),
        power_rv: 0.25 * Vec3::new(0.8, 0.4, 0.2),
        real: true,
        area: 0.01,
    };
    let mut vpls = Vec::new();
    resample(&[wall], 64, 0, 9, &mut vpls);
    // Every slot holds the VPL and its ir = 1 twin, at the same point.
    assert_eq!(vpls.len(), 128);
    for pair in vpls.chunks(2) {
        assert_eq!(pair[0].slot, pair[1].slot);
        assert_eq!((pair[0].real_only, pair[1].real_only), (false, true));
        assert!((pair[1].power - 3.0 * pair[0].power).abs().max_element() < 1e-6);
    }
    assert!(
        vpls.iter().all(|v| v.real_path),
        "the wall is real, its light is real"
    );
    let projection = Projection::Paraboloid {
        origin: wall.position,
        frame: frame_about(wall.normal),
    };
    let lights = open_lights(&vpls, &[[projection; 2]; 64], &[f32::INFINITY; 2 * 16 * 64]);
    let all: Vec<u32> = (0..vpls.len() as u32).collect();
    // A real floor point below: L_r gets all of the wall's light, L_rv a quarter (the
    // ir = 1 VPLs light L_r only, eqs. 6-7).
    let floor = gather(&lights, &all, Vec3::ZERO, Vec3::Y, Receiver::Real);
    let expected = wall.power_r; // cos 1 * cos 1 / 1 m^2
    assert!(
        (floor.r_ind - expected).abs().max_element() < 1e-5,
        "E_R {}",
        floor.r_ind
    );
    assert!(
        (floor.rv_ind - 0.25 * expected).abs().max_element() < 1e-5,
        "E_RV {}",
        floor.rv_ind
    );
    assert!(floor.touched);
    // A virtual point there: the cancelling VPLs do not light virtual objects.
    let object = gather(&lights, &all, Vec3::ZERO, Vec3::Y, Receiver::Virtual);
    assert!(
        (object.rv_ind - 0.25 * expected).abs().max_element() < 1e-5,
        "{}",
        object.rv_ind
    );
    assert_eq!(object.r_ind, Vec3::ZERO);
    // Unblocked, the same wall makes no cancelling VPL and E_RV == E_R.
    let mut open = Vec::new();
    resample(
        &[Candidate {
            power_rv: wall.power_r,
            ..wall
        }],
        64,
        0,
        9,
        &mut open,
    );
    assert_eq!(open.len(), 64);
    assert!(open.iter().all(|v| !v.real_only && v.real_path));
    let lights = open_lights(&open, &[[projection; 2]; 64], &[f32::INFINITY; 2 * 16 * 64]);
    let floor = gather(&lights, &all[..64], Vec3::ZERO, Vec3::Y, Receiver::Real);
    assert_eq!(floor.r_ind, floor.rv_ind);
    assert!(!floor.touched);
}

#[test]
fn a_virtual_vpl_lights_only_the_combined_world() {
    let vpl = Vpl {
        emitter: Emitter::Surface {
            position: Vec3::new(0.0, 1.0, 0.0),
            normal: Vec3::NEG_Y,
        },
        power: Vec3::ONE,
        real_path: false,
        real_only: false,
        patch: 0.0,
        slot: 0,
    };
    let projection = Projection::Paraboloid {
        origin: Vec3::Y,
        frame: frame_about(Vec3::NEG_Y),
    };
    let lights = open_lights(&[vpl], &[[projection; 2]], &[f32::INFINITY; 32]);
    let g = gather(&lights, &[0], Vec3::ZERO, Vec3::Y, Receiver::Real);
    assert_eq!(
        (g.r_ind, g.rv_ind, g.touched),
        (Vec3::ZERO, Vec3::ONE, true)
    );
}

#[test]
fn untouched_pixels_have_e_rv_equal_to_e_r_bit_for_bit() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, RED);
    let out = render(
        &scene,
        &objects,
        &uniform_table(4096),
        &DirParams::default(),
    );
    let touched = assert_untouched_pixels_equal(&out);
    let surface = out.e_r_dir.data.iter().filter(|e| e.is_finite()).count();
    assert!(
        touched > 100 && touched < surface / 2,
        "{touched} of {surface} pixels touched"
    );
    // And the touched ones are where the sphere is: its pixels and a band around them.
    let below = pixel_of(Vec3::new(0.0, 0.0, SPHERE_CENTER.z));
    assert_eq!(out.touched.data[below], 1);
}

#[test]
fn one_and_two_threads_give_identical_products() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, RED);
    let table = uniform_table(4096);
    let params = DirParams::default();
    let one = with_threads(1, || bits(&render(&scene, &objects, &table, &params)));
    let two = with_threads(2, || bits(&render(&scene, &objects, &table, &params)));
    assert!(one == two, "1 and 2 threads differ");
    let other_frame = render(&scene, &objects, &table, &DirParams { seed: 8, ..params });
    assert!(bits(&other_frame) != one, "the seed should change the VPLs");
}

#[test]
fn settings_it_cannot_run_with_are_refused_with_the_reason() {
    let params = DirParams {
        vpls: 16,
        environment_vpls: 32,
        ..DirParams::default()
    };
    assert_eq!(
        params.check().unwrap_err().to_string(),
        "sample.dir: environment_vpls (32) is more than vpls (16)"
    );
    let scene = floor_scene();
    let (table, objects) = (uniform_table(64), VirtualScene::default());
    let mut inputs = inputs(&scene, &objects, &table, 0);
    let small = relume_base::raster::Image::filled(4, 4, Vec3::ONE);
    inputs.radiance = &small;
    let err = sample_dir(&inputs, &DirParams::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("sample.dir: radiance is 4x4, depth is 96x72"),
        "{err}"
    );
}

/// A stage keeps its renderer (maps, VPLs, layers) from frame to frame and clears the
/// maps only where they held depths: a frame rendered after another one has the bits
/// of the same frame rendered fresh.
#[test]
fn a_reused_renderer_gives_the_bits_of_a_fresh_one() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, RED);
    let table = uniform_table(4096);
    let params = DirParams::default();
    let mesh = MeshPoints::new(&objects, params.mesh_points as usize, params.seed);
    let inputs = |frame| inputs(&scene, &objects, &table, frame);
    let mut renderer = DirRenderer::default();
    let mut out = IrradianceLayers::new(scene.depth.width, scene.depth.height);
    renderer
        .render(&inputs(1), &params, &mesh, &mut out)
        .unwrap();
    renderer
        .render(&inputs(2), &params, &mesh, &mut out)
        .unwrap();
    let fresh = sample_dir(&inputs(2), &params).unwrap();
    assert!(bits(&out) == bits(&fresh));
}

/// Shading reads the lights of the last `lights` call: without lights for a frame of
/// its size and interleaving, or into layers of another size, it is an error.
#[test]
fn shading_without_lights_of_the_frame_is_an_error() {
    let scene = floor_scene();
    let (objects, table) = (VirtualScene::default(), uniform_table(64));
    let (params, inputs) = (DirParams::default(), inputs(&scene, &objects, &table, 0));
    let mesh = MeshPoints::new(&objects, params.mesh_points as usize, params.seed);
    let (w, h) = (scene.depth.width, scene.depth.height);
    let mut renderer = DirRenderer::default();
    let mut out = IrradianceLayers::new(w, h);
    let no_lights = "sample.dir: no lights made for a 96x72 frame with interleave 4, 128x128 maps, 0 spot lights and flags Reciprocal to shade";
    let err = renderer.shade(&inputs, &params, &mut out).unwrap_err();
    assert_eq!(err.to_string(), no_lights);
    renderer.lights(&inputs, &params, &mesh).unwrap();
    for (other, what) in [
        (
            DirParams {
                interleave: 2,
                ..params
            },
            "96x72 frame with interleave 2, 128x128 maps, 0 spot lights and flags Reciprocal",
        ),
        (
            DirParams {
                shadow_map_size: 256,
                ..params
            },
            "96x72 frame with interleave 4, 256x256 maps, 0 spot lights and flags Reciprocal",
        ),
        (
            DirParams {
                flags: Flags::Knecht2010,
                ..params
            },
            "96x72 frame with interleave 4, 128x128 maps, 0 spot lights and flags Knecht2010",
        ),
    ] {
        let err = renderer.shade(&inputs, &other, &mut out).unwrap_err();
        let expected = format!("sample.dir: no lights made for a {what} to shade");
        assert_eq!(err.to_string(), expected);
    }
    // Spots the lights were not made with (their maps would be missing).
    let lamp = [relume_scene::light::SpotLight {
        name: "lamp".into(),
        world: relume_scene::light::LightWorld::Real,
        position: Vec3::new(0.0, 2.0, 1.0),
        direction: Vec3::NEG_Y,
        intensity: Vec3::ONE,
        beam: 0.3,
        cutoff: 0.5,
    }];
    let with_spot = DirInputs {
        spots: &lamp,
        ..inputs
    };
    let err = renderer.shade(&with_spot, &params, &mut out).unwrap_err();
    assert_eq!(
        err.to_string(),
        "sample.dir: no lights made for a 96x72 frame with interleave 4, 128x128 maps, 1 spot lights and flags Reciprocal to shade"
    );
    // A frame of the same pixel count in another shape.
    let transposed = relume_base::raster::Image::filled(h, w, 1.0f32);
    let mut other_shape = inputs;
    other_shape.depth = &transposed;
    let err = renderer.shade(&other_shape, &params, &mut out).unwrap_err();
    assert_eq!(
        err.to_string(),
        "sample.dir: no lights made for a 72x96 frame with interleave 4, 128x128 maps, 0 spot lights and flags Reciprocal to shade"
    );
    let mut small = IrradianceLayers::new(w / 2, h);
    let err = renderer.shade(&inputs, &params, &mut small).unwrap_err();
    assert_eq!(
        err.to_string(),
        "sample.dir: output buffers are not all 96x72"
    );
    renderer.shade(&inputs, &params, &mut out).unwrap();
}

#[test]
fn shadow_maps_beyond_a_gibibyte_are_refused_before_allocating() {
    let params = DirParams {
        vpls: 4096,
        shadow_map_size: 512,
        ..DirParams::default()
    };
    assert_eq!(
        params.check().unwrap_err().to_string(),
        "sample.dir: 4096 + 32 VPLs (vpls + spot_vpls) with two 512x512 maps each need 8256 MiB of shadow maps; at most 1024 MiB: lower vpls, spot_vpls or shadow_map_size"
    );
}

#[test]
fn a_candidate_splits_into_the_light_both_worlds_share_and_what_only_one_has() {
    let c = Candidate {
        position: Vec3::ZERO,
        normal: Vec3::Y,
        power_r: Vec3::new(1.0, 1.0, 1.0),
        power_rv: Vec3::new(0.5, 2.0, 1.0),
        real: true,
        area: 0.01,
    };
    let [both, r_only, rv_only] = super::vpl::split(&c);
    assert_eq!(both, Vec3::new(0.5, 1.0, 1.0));
    assert_eq!(r_only, Vec3::new(0.5, 0.0, 0.0));
    assert_eq!(rv_only, Vec3::new(0.0, 1.0, 0.0));
}

/// A second bounce carries the flags on (eq. 9): the floor lit by the red sphere's VPLs
/// sends that light on in the combined world only, so the real solution of the flat
/// floor still has no indirect light, E_RV == E_R where nothing virtual is near, and
/// the layers do not depend on the thread count.
#[test]
fn a_second_bounce_keeps_light_that_met_an_object_out_of_the_real_solution() {
    let scene = floor_scene();
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, RED);
    let table = uniform_table(4096);
    let params = DirParams {
        bounces: 2,
        ..DirParams::default()
    };
    let out = with_threads(1, || render(&scene, &objects, &table, &params));
    let real_floor: Vec<usize> = (0..out.mask.data.len())
        .filter(|&i| out.mask.data[i] == 1.0 && out.e_r_ind.data[i].is_finite())
        .collect();
    assert!(real_floor.len() > 1000);
    for &i in &real_floor {
        assert_eq!(out.e_r_ind.data[i], Vec3::ZERO, "pixel {i}");
    }
    assert_untouched_pixels_equal(&out);
    let two = with_threads(2, || render(&scene, &objects, &table, &params));
    assert!(
        bits(&out) == bits(&two),
        "1 and 2 threads differ with two bounces"
    );
    let one_bounce = render(&scene, &objects, &table, &DirParams::default());
    assert!(
        bits(&out) != bits(&one_bounce),
        "the second bounce changed nothing"
    );
}
