//! `sample.val` with the objects' radiance transfer (paper 004 eqs. 9, 11).

use super::tests::{
    bits, camera, lights, only_the_objects_indirect_light_differs, real_scene, view_inputs,
};
use super::*;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_scene::light::AreaLights;
use relume_scene::light::prt::{Transfer, TransferParams};
use relume_scene::objects::{Material, shapes};

/// The inputs of the floor seen by the test camera, with `scene`, `lights` and
/// `transfer` and no spots.
fn floor_inputs<'a>(
    (depth, normals): &'a (DepthImage, Vec3Image),
    lights: &'a AreaLights,
    scene: &'a VirtualScene,
    transfer: Option<&'a Transfer>,
) -> ValInputs<'a> {
    view_inputs((depth, normals), lights, scene, transfer, &[])
}

/// A torus lying on the floor right under the camera: its inner side faces its own
/// tube across the hole.
fn torus() -> VirtualScene {
    let mut triangles = shapes::torus(0.8, 0.3, 32, 16);
    let origin = camera().1.translation;
    for t in &mut triangles {
        t.vertices = t.vertices.map(|v| v + Vec3::new(origin.x, 0.3, origin.z));
    }
    VirtualScene::new(triangles, vec![Material::DIFFUSE_GRAY])
}

#[test]
fn the_transfer_darkens_the_objects_where_they_occlude_themselves_and_nothing_else() {
    let floor = real_scene(false);
    let scene = torus();
    // No area lights: the constant sky's SH9 is all the light.
    let sky = lights(Vec::new());
    let transfer = Transfer::compute(&scene, TransferParams::default()).unwrap();
    let render = |transfer: Option<&Transfer>| {
        let inputs = floor_inputs(&floor, &sky, &scene, transfer);
        sample_val(&inputs, &ValShadingParams::default()).unwrap()
    };
    let (open, occluded) = (render(None), render(Some(&transfer)));
    // Real surfaces: the same bits (the transfer is for the objects only).
    only_the_objects_indirect_light_differs(&open, &occluded);
    let (mut virtual_pixels, mut darker, mut top) = (0, 0, 0);
    for i in 0..open.mask.data.len() {
        let (a, b) = (open.e_rv_ind.data[i], occluded.e_rv_ind.data[i]);
        if open.mask.data[i] != 0.0 {
            continue;
        }
        virtual_pixels += 1;
        // Occlusion only takes light away (up to the transfer's 2 %).
        assert!(b.x <= a.x * 1.02, "pixel {i}: {b} brighter than {a}");
        if b.x < 0.9 * a.x {
            darker += 1;
        }
        // The top of the tube sees the whole sky: as without occlusion.
        if open.world_normal.data[i].y > 0.99 {
            top += 1;
            assert!((b.x - a.x).abs() <= 0.02 * a.x, "pixel {i}: {b} vs {a}");
        }
    }
    assert!(virtual_pixels > 500 && top > 20, "{virtual_pixels} {top}");
    // The inner side of the ring, facing the tube across the hole, loses light.
    assert!(darker > virtual_pixels / 10, "{darker} of {virtual_pixels}");
}

/// A red sphere right under the camera and a white one beside it, objects 0 and 1:
/// the white one's side facing the red is seen from above.
fn red_and_white() -> (VirtualScene, Vec3, f32) {
    let origin = camera().1.translation;
    let (red_centre, red_radius) = (Vec3::new(origin.x, 0.4, origin.z), 0.4);
    let red = super::tests::sphere_at(red_centre, red_radius);
    let mut white = super::tests::sphere_at(red_centre + WHITE_OFFSET, 0.2);
    for t in &mut white.triangles {
        t.material = 1;
    }
    let mut triangles = red.triangles;
    triangles.extend(white.triangles);
    let materials = vec![
        Material {
            albedo: RED,
            exponent: 0.0,
        },
        Material {
            albedo: Vec3::splat(0.8),
            exponent: 0.0,
        },
    ];
    (
        VirtualScene::new(triangles, materials),
        red_centre,
        red_radius,
    )
}

const RED: Vec3 = Vec3::new(0.8, 0.1, 0.1);

/// The white sphere's centre from the red's.
const WHITE_OFFSET: Vec3 = Vec3::new(1.2, -0.2, 0.0);

/// The room's constant radiance in [`lights`].
const ROOM: Vec3 = Vec3::new(0.2, 0.3, 0.4);

/// The light the red sphere sends a point at `p` with normal `n` when it lies wholly
/// above the point's horizon (else `None`): its radiance is rho_red E_red / pi with
/// E_red = pi L (the room's constant radiance; the white sphere hides a little of
/// it), and a sphere of radius R whose centre lies d away at angle beta from the
/// normal covers the view factor (R / d)^2 cos(beta).
fn red_light(p: Vec3, n: Vec3, red_centre: Vec3, red_radius: f32) -> Option<Vec3> {
    let to_red = red_centre - p;
    let (d, cos_beta) = (to_red.length(), n.dot(to_red.normalize()));
    (cos_beta > red_radius / d)
        .then(|| RED * ROOM * std::f32::consts::PI * (red_radius / d).powi(2) * cos_beta)
}

#[test]
fn the_objects_light_each_other_as_their_view_factors_say() {
    // Paper 004 Fig. 7 bottom, at the white sphere's vertices: the SH9 of the red
    // sphere seen from the white one's centre (the paper's cube map), through each
    // vertex's bounce transfer. As in the paper, the light is the one the centre sees:
    // a vertex gains rho_red pi L (R / D)^2 cos(beta), D and beta measured from the
    // white sphere's centre. It comes out up to 15 % lower: the white sphere hides up
    // to 6 % of the room from the red face that sees it, and SH9 blurs the red disk.
    let (scene, red_centre, red_radius) = red_and_white();
    let white_centre = red_centre + WHITE_OFFSET;
    let room = lights(Vec::new());
    let transfer = Transfer::compute(&scene, TransferParams::default()).unwrap();
    let floor = real_scene(false);
    let inputs = floor_inputs(&floor, &room, &scene, Some(&transfer));
    let light = super::bounce::BounceLights {
        lights: &[],
        maps: super::shade::Maps {
            data: &[],
            stride: 0,
            texels: 0,
        },
        biases: super::shade::Biases {
            virtual_bias: 0.0,
            real_bias: 0.0,
            slope: 0.0,
        },
        spot_maps: None,
        sampling: super::pixel::sampling_of(&inputs),
    };
    let others = super::bounce::object_bounce(&inputs, &transfer, &light);
    assert_eq!(others.len(), 2);
    let (vertices, _) = relume_scene::light::prt::scene_vertices(&scene);
    let (mut lit, mut unlit, mut sum_error) = (0, 0, 0.0f32);
    let to_red = (red_centre - white_centre).normalize();
    let sin_half_angle = red_radius / (red_centre - white_centre).length();
    let brightest = red_light(white_centre, to_red, red_centre, red_radius).unwrap();
    for (v, &(p, n)) in vertices.iter().enumerate() {
        if (p - red_centre).length() < red_radius * 1.01 {
            continue;
        }
        let gain = Transfer::irradiance(&transfer.bounce[v], &others[1]);
        if let Some(expected) = red_light(white_centre, n, red_centre, red_radius) {
            let error = (gain.x - expected.x) / expected.x;
            assert!(
                (-0.15..0.02).contains(&error),
                "vertex {p}: {gain} vs {expected}"
            );
            // The red sphere's colour: rho_red times the room's, red over green.
            let ratio = (gain.x / gain.y) / (RED.x * ROOM.x / (RED.y * ROOM.y));
            assert!((ratio - 1.0).abs() < 0.02, "vertex {p}: {gain}");
            sum_error += error;
            lit += 1;
        } else if n.dot(to_red) < -sin_half_angle {
            // The red sphere lies wholly below the horizon: SH9's ringing only.
            assert!(gain.x.abs() < 0.05 * brightest.x, "vertex {p}: {gain}");
            unlit += 1;
        }
    }
    assert!(lit > 100 && unlit > 100, "{lit} {unlit}");
    let mean = sum_error / lit as f32;
    assert!((-0.12..0.0).contains(&mean), "mean relative error {mean}");
}

#[test]
fn light_between_the_objects_moves_only_their_indirect_light_on_any_thread_count() {
    let floor = real_scene(false);
    let (scene, red_centre, red_radius) = red_and_white();
    let room = lights(vec![super::tests::light(super::tests::LAMP, 2.0)]);
    let transfer = Transfer::compute(&scene, TransferParams::default()).unwrap();
    let render = |object_bounce: bool| {
        let inputs = floor_inputs(&floor, &room, &scene, Some(&transfer));
        let params = ValShadingParams {
            object_bounce,
            ..ValShadingParams::default()
        };
        sample_val(&inputs, &params).unwrap()
    };
    let (alone, together) = (render(false), render(true));
    let three = relume_base::threads::with_threads(3, || render(true));
    let one = relume_base::threads::with_threads(1, || render(true));
    assert_eq!(bits(&one.e_rv_ind), bits(&three.e_rv_ind));
    // The real surfaces and all direct light keep their bits.
    only_the_objects_indirect_light_differs(&alone, &together);
    let (mut red_pixels, mut white_gains) = (0, Vec::new());
    for i in 0..alone.mask.data.len() {
        let (a, b) = (alone.e_rv_ind.data[i], together.e_rv_ind.data[i]);
        if alone.mask.data[i] != 0.0 {
            continue;
        }
        let gain = b - a;
        let p = together.world_position.data[i];
        if (p - red_centre).length() < red_radius * 1.01 {
            // The white sphere's light, lit by the room and the lamp: no hue of its own.
            red_pixels += usize::from(gain.x > 0.0);
        } else {
            white_gains.push(gain);
        }
    }
    // On the white sphere, the red one's light: red, up to SH9's ringing (a few
    // per cent of the brightest, either sign) where the red sphere is out of sight.
    let brightest = white_gains.iter().map(|g| g.x).fold(0.0, f32::max);
    let reddened = white_gains.iter().filter(|g| g.x > 0.1 * brightest).count();
    for gain in &white_gains {
        if gain.x > 0.1 * brightest {
            assert!(gain.x > 2.0 * gain.y, "{gain}");
        }
        assert!(
            gain.min_element() > -0.05 * brightest,
            "{gain} of {brightest}"
        );
    }
    assert!(red_pixels > 50 && reddened > 20, "{red_pixels} {reddened}");
}
