//! `sample.val`'s round robin of shadow-map updates (`shadow_updates`, paper 004 Sec. 5).

use super::tests::{bits, camera, light, lights, real_scene, sphere};
use super::*;
use relume_scene::light::AreaLights;

/// Four lights around the sphere, all casting its shadow on the floor or the slab.
fn four_lights() -> AreaLights {
    lights(
        [
            (0.0, 3.5, 0.0),
            (0.6, 3.2, 0.2),
            (-0.5, 3.0, -0.3),
            (0.2, 2.8, 0.6),
        ]
        .map(|(x, y, z)| light(Vec3::new(x, y, z), 10.0))
        .to_vec(),
    )
}

/// Renders with `renderer`, the camera of the tests, the real scene with or without
/// its slab, the sphere and four lights.
fn render_with(renderer: &mut ValRenderer, slab: bool, updates: usize) -> IrradianceLayers {
    render_lit(renderer, slab, updates, &four_lights())
}

fn render_lit(
    renderer: &mut ValRenderer,
    slab: bool,
    updates: usize,
    set: &AreaLights,
) -> IrradianceLayers {
    let (depth, normals) = real_scene(slab);
    let (camera, camera_to_world) = camera();
    let scene = sphere();
    let inputs = ValInputs {
        depth: &depth,
        normals: &normals,
        camera,
        camera_to_world,
        lights: set,
        objects: &scene,
        transfer: None,
        spots: &[],
    };
    let params = ValShadingParams {
        shadow_updates: updates,
        ..ValShadingParams::default()
    };
    let mut out = val_layers(depth.width, depth.height);
    renderer.render(&inputs, &params, &mut out).unwrap();
    out
}

/// Light j's maps (virtual, real) in a renderer.
fn maps_of(renderer: &ValRenderer, j: usize) -> Vec<u32> {
    let stride = renderer.maps.len() / 4;
    let maps = &renderer.maps[j * stride..(j + 1) * stride];
    // The virtual and real maps, not the real map's scratch.
    maps[..2 * stride / 3].iter().map(|x| x.to_bits()).collect()
}

#[test]
fn lights_take_turns_and_keep_their_last_maps_between() {
    // The real scene changes between the first frame (no slab) and the next ones.
    let mut full_before = ValRenderer::default();
    render_with(&mut full_before, false, 0);
    let mut full_after = ValRenderer::default();
    let after = render_with(&mut full_after, true, 0);
    // The slab is in the real maps: they differ, so the test can tell them apart.
    assert!((0..4).all(|j| maps_of(&full_before, j) != maps_of(&full_after, j)));

    let mut turns = ValRenderer::default();
    // Call 0: nothing built before, so every light's maps are.
    render_with(&mut turns, false, 2);
    assert!((0..4).all(|j| maps_of(&turns, j) == maps_of(&full_before, j)));
    // Call 1: lights 2 and 3 are rebuilt; 0 and 1 keep the first frame's maps.
    let midway = render_with(&mut turns, true, 2);
    for j in 0..4 {
        let expected = if j >= 2 { &full_after } else { &full_before };
        assert_eq!(maps_of(&turns, j), maps_of(expected, j), "light {j}");
    }
    assert_ne!(bits(&midway.e_r_dir), bits(&after.e_r_dir));
    // Call 2: lights 0 and 1; every map is now the frame's, and so is every layer.
    let caught_up = render_with(&mut turns, true, 2);
    assert!((0..4).all(|j| maps_of(&turns, j) == maps_of(&full_after, j)));
    for (a, b) in [
        (&caught_up.e_r_dir, &after.e_r_dir),
        (&caught_up.e_rv_dir, &after.e_rv_dir),
        (&caught_up.e_rv_ind, &after.e_rv_ind),
    ] {
        assert_eq!(bits(a), bits(b));
    }
    // As many updates as lights is every light every frame.
    let mut all = ValRenderer::default();
    render_with(&mut all, false, 4);
    let every = render_with(&mut all, true, 4);
    assert_eq!(bits(&every.e_rv_dir), bits(&after.e_rv_dir));
}

#[test]
fn a_light_that_moved_gets_new_maps_whatever_its_turn() {
    let mut turns = ValRenderer::default();
    render_with(&mut turns, true, 1);
    // A new light model: light 3 moved, the others did not.
    let mut moved = four_lights();
    moved.lights[3].position += Vec3::new(0.3, 0.0, -0.2);
    let mut full = ValRenderer::default();
    render_lit(&mut full, true, 0, &moved);
    // Call 1 rebuilds light 1 (its turn) and light 3 (it moved); 0 and 2 had the
    // same inputs, so every map is the full build's.
    let out = render_lit(&mut turns, true, 1, &moved);
    assert!((0..4).all(|j| maps_of(&turns, j) == maps_of(&full, j)));
    let expected = render_lit(&mut ValRenderer::default(), true, 0, &moved);
    assert_eq!(bits(&out.e_rv_dir), bits(&expected.e_rv_dir));
}
