//! `sample.val` with the pipeline's spot lights: paper 002's flags through the two
//! shadow maps of each spot, on the scene of `tests.rs` (a floor, a real slab at 1.3 m
//! beside the axis, a virtual sphere under a lamp at 3.5 m).

use super::tests::{
    LAMP, RADIUS, SLAB_Y, bits, lights, real_scene, render_with_spots, segment_distance, sphere,
};
use super::*;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_scene::light::{LightWorld, SpotLight};

/// A spot at the lamp, pointing down, of `world`.
fn spot(world: LightWorld) -> SpotLight {
    SpotLight {
        name: "spot".into(),
        world,
        position: LAMP,
        direction: Vec3::NEG_Y,
        intensity: Vec3::new(9.0, 6.0, 3.0),
        beam: 30f32.to_radians(),
        cutoff: 45f32.to_radians(),
    }
}

/// The layers with no area lights (their SH9 only) and `spots`.
fn render(depth: &DepthImage, normals: &Vec3Image, spots: &[SpotLight]) -> IrradianceLayers {
    render_with_spots(depth, normals, &lights(Vec::new()), &sphere(), spots)
}

/// Where a floor point stands: under the slab as the lamp sees it (2 cm in, or
/// `margin` metres out at the slab's height: its points are splatted over their patch
/// and a texel), behind the sphere (2 cm in or out).
struct Place {
    under_slab: bool,
    clear_of_slab: bool,
    behind_sphere: bool,
    clear_of_sphere: bool,
}

fn place(p: Vec3, margin: f32) -> Place {
    let at_slab = p + (LAMP - p) * (SLAB_Y / LAMP.y);
    Place {
        under_slab: (0.12..=0.58).contains(&at_slab.x) && at_slab.z.abs() <= 0.28,
        clear_of_slab: !(0.1 - margin..=0.6 + margin).contains(&at_slab.x)
            || at_slab.z.abs() > 0.3 + margin,
        behind_sphere: segment_distance(p, LAMP) < RADIUS - 0.02,
        clear_of_sphere: segment_distance(p, LAMP) > RADIUS + 0.02,
    }
}

#[test]
fn a_real_spot_keeps_the_flags_and_casts_no_double_shadow() {
    let (depth, normals) = real_scene(true);
    let dark = render(&depth, &normals, &[]);
    let lamp = spot(LightWorld::Real);
    let lit = render(&depth, &normals, std::slice::from_ref(&lamp));
    let (mut double, mut object_only, mut open) = (0, 0, 0);
    for i in 0..lit.mask.len() {
        let p = lit.world_position.data[i];
        if lit.mask.data[i] == 0.0 || p.y.abs() > 1e-3 {
            continue;
        }
        let Some(arrival) = lamp.arrival(p, Vec3::Y) else {
            continue;
        };
        let light = arrival.irradiance;
        let gained = |a: &Vec3Image, b: &Vec3Image| a.data[i] - b.data[i];
        let (r, rv) = (
            gained(&lit.e_r_dir, &dark.e_r_dir),
            gained(&lit.e_rv_dir, &dark.e_rv_dir),
        );
        let close = |g: Vec3, e: Vec3| (g - e).abs().max_element() <= 1e-5 * light.max_element();
        let at = place(p, 0.04);
        if at.under_slab && at.behind_sphere {
            // Behind the slab and the sphere: no light in either solution, so the
            // sphere shadows nothing again.
            double += 1;
            assert!(
                close(r, Vec3::ZERO) && close(rv, Vec3::ZERO),
                "at {p}: {r} {rv}"
            );
        } else if at.behind_sphere && at.clear_of_slab {
            object_only += 1;
            assert!(close(r, light) && close(rv, Vec3::ZERO), "at {p}: {r} {rv}");
        } else if at.clear_of_sphere && at.clear_of_slab {
            open += 1;
            assert!(close(r, light) && close(rv, light), "at {p}: {r} {rv}");
        }
    }
    eprintln!("double {double}, the object's only {object_only}, open {open}");
    assert!(double > 20 && object_only > 20 && open > 200);
    // The sphere's pixels that face the lamp gain its light in E_RV (the camera sees
    // the sphere from the side: few do).
    let mut facing = 0;
    for i in (0..lit.mask.len()).filter(|&i| lit.mask.data[i] == 0.0) {
        let (p, n) = (lit.world_position.data[i], lit.world_normal.data[i]);
        let Some(arrival) = lamp.arrival(p, n) else {
            continue;
        };
        let gained = lit.e_rv_dir.data[i] - dark.e_rv_dir.data[i];
        let light = arrival.irradiance;
        assert!(
            (gained - light).abs().max_element() < 1e-5 * lamp.intensity.max_element(),
            "sphere at {p}, normal {n}: {gained} {light}"
        );
        facing += 1;
    }
    assert!(facing > 5, "{facing} pixels of the sphere face the lamp");
}

#[test]
fn a_virtual_spot_lights_e_rv_alone_through_both_maps() {
    let (depth, normals) = real_scene(true);
    let dark = render(&depth, &normals, &[]);
    let lamp = spot(LightWorld::Virtual);
    let lit = render(&depth, &normals, std::slice::from_ref(&lamp));
    assert_eq!(
        bits(&lit.e_r_dir),
        bits(&dark.e_r_dir),
        "E_R keeps its bits"
    );
    assert_eq!(bits(&lit.e_r_ind), bits(&dark.e_r_ind));
    let (mut shadowed, mut open) = (0, 0);
    for i in 0..lit.mask.len() {
        let p = lit.world_position.data[i];
        if lit.mask.data[i] == 0.0 || p.y.abs() > 1e-3 {
            continue;
        }
        let Some(arrival) = lamp.arrival(p, Vec3::Y) else {
            continue;
        };
        let rv = lit.e_rv_dir.data[i] - dark.e_rv_dir.data[i];
        // The cone's maps have texels of 3.4 cm at the slab.
        let at = place(p, 0.1);
        let tolerance = 1e-5 * arrival.irradiance.max_element();
        if at.behind_sphere || at.under_slab {
            // The real slab blocks a virtual light too.
            shadowed += 1;
            assert!(rv.abs().max_element() <= tolerance, "at {p}: {rv}");
        } else if at.clear_of_sphere && at.clear_of_slab {
            open += 1;
            assert!(
                (rv - arrival.irradiance).abs().max_element() <= tolerance,
                "at {p}"
            );
        }
    }
    assert!(shadowed > 40 && open > 200, "{shadowed} {open}");
}

#[test]
fn spots_give_the_same_bits_at_any_thread_count() {
    let (depth, normals) = real_scene(true);
    let spots = [spot(LightWorld::Real), spot(LightWorld::Virtual)];
    let at =
        |threads| relume_base::threads::with_threads(threads, || render(&depth, &normals, &spots));
    let (one, three) = (at(1), at(3));
    for (a, b) in [
        (&one.e_r_dir, &three.e_r_dir),
        (&one.e_rv_dir, &three.e_rv_dir),
    ] {
        assert_eq!(bits(a), bits(b));
    }
}
