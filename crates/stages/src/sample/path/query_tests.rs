//! What `sample.path`'s radiance queries (`query = "ssrt" | "em" | "dit" | "vct"`)
//! keep beyond the renderers' contract (`stages::sample::contract_tests`): E_RV == E_R
//! bit for bit wherever no path met an object, with and without object-aware
//! sampling, at 1 and 3 threads and with the portable and AVX2 marches. A new query
//! adds one line to [`QUERIES`]. Then what tells the queries apart: the impostor's distances hide objects beyond them (paper
//! 000 Sec. 6.4, ray 3), and `visibility` switches the objects' self-occlusion.

use super::tests::{
    Dome, H, SKY, SPHERE_CENTER, SPHERE_RADIUS, W, assert_untouched_pixels_equal, bits, dome,
    floor_scene, pixel_of, run_with_environment, same_bits, sphere, uniform_table,
};
use super::*;
use glam::Vec3;
use relume_base::threads::with_threads;
use relume_scene::light::LightTable;
use relume_scene::objects::Material;
use relume_scene::objects::VirtualScene;
use std::f32::consts::PI;

/// Every query, with its iterations.
const QUERIES: &[(QueryKind, u32)] = &[
    (QueryKind::Ssrt, 0),
    (QueryKind::Em, 0),
    (QueryKind::Dit, 4),
    (QueryKind::Vct, 0),
];

/// The floor scene with `objects` under `dome`, marched with the CPU's own lanes.
fn run_floor(
    objects: &VirtualScene,
    table: &LightTable,
    dome: &Dome,
    params: &PathParams,
) -> IrradianceLayers {
    let lanes = simd::Kernel::detect();
    run_with_environment(&floor_scene(), objects, table, dome.world(), params, lanes)
}

fn params(query: QueryKind, iterations: u32) -> PathParams {
    PathParams {
        query,
        iterations,
        seed: 3,
        ..Default::default()
    }
}

fn gray_sphere(center: Vec3) -> VirtualScene {
    let material = Material {
        albedo: Vec3::splat(0.6),
        exponent: 0.0,
    };
    sphere(center, SPHERE_RADIUS, material)
}

#[test]
fn every_query_keeps_e_rv_equal_to_e_r_where_no_path_met_an_object() {
    let table = uniform_table(1024);
    let env = dome(Vec3::new(0.0, 1.0, 1.0), 6.0);
    let objects = gray_sphere(SPHERE_CENTER);
    for &(query, iterations) in QUERIES {
        for (object_aware, object_aware_direct) in [(false, false), (true, false), (true, true)] {
            let p = PathParams {
                object_aware,
                object_aware_direct,
                ..params(query, iterations)
            };
            let run = || run_floor(&objects, &table, &env, &p);
            let out = run();
            let touched = assert_untouched_pixels_equal(&out);
            // Enough touched pixels that the objects were met, and enough untouched
            // ones that the equality was checked (a renderer marking every pixel
            // touched would pass it vacuously): 2882 to 4937 of 6912 are untouched.
            let pixels = out.touched.data.len();
            assert!(
                touched > 200 && pixels - touched > 1500,
                "{query:?}: {touched} of {pixels} pixels touched"
            );
            // The sphere's shadow on the floor below it.
            let below = pixel_of(Vec3::new(SPHERE_CENTER.x, 0.0, SPHERE_CENTER.z));
            let (r, rv) = (out.e_r_dir.data[below], out.e_rv_dir.data[below]);
            assert!(rv.x < 0.8 * r.x, "{query:?}: no shadow, E_RV {rv} E_R {r}");
            let one = with_threads(1, || bits(&run()));
            let three = with_threads(3, || bits(&run()));
            assert!(
                one == three && one == bits(&out),
                "{query:?}: thread counts differ"
            );
            let portable = run_with_environment(
                &floor_scene(),
                &objects,
                &table,
                env.world(),
                &p,
                simd::Kernel::Portable,
            );
            assert!(bits(&portable) == one, "{query:?}: the lanes differ");
        }
    }
}

#[test]
fn an_object_beyond_the_impostor_casts_no_shadow_but_one_at_infinity_does() {
    // A sphere 2.7 m above the floor, out of the camera's view. The impostor is a dome
    // of 1.5 m: from the floor, the environment stands in front of the sphere (ray 3 of
    // paper 000 Fig. 7), so em and dit see no difference; ssrt's environment is at
    // infinity, behind the sphere, which shadows the floor.
    let table = uniform_table(1024);
    let env = dome(Vec3::new(0.0, 0.0, 1.0), 1.5);
    let high = Vec3::new(0.0, 2.7, 1.0);
    let objects = gray_sphere(high);
    for &(query, iterations) in QUERIES {
        let out = run_floor(&objects, &table, &env, &params(query, iterations));
        assert!(
            out.mask.data.iter().all(|&m| m == 1.0),
            "the sphere is out of view"
        );
        let touched = out.touched.data.iter().filter(|&&t| t != 0).count();
        let below = pixel_of(Vec3::new(high.x, 0.0, high.z));
        let (r, rv) = (out.e_r_dir.data[below], out.e_rv_dir.data[below]);
        if query == QueryKind::Ssrt {
            assert!(
                touched > 100 && rv.x < r.x,
                "ssrt: {touched} touched, {rv} vs {r}"
            );
        } else if query == QueryKind::Vct {
            // The volume holds the dome as what it is, a shell: floor points outside
            // it see the sphere with nothing in between. Inside, the dome hides it.
            let inside = (0..out.touched.data.len())
                .filter(|&i| (out.world_position.data[i] - env.env.center).length() < 1.2);
            let touched_inside = inside.filter(|&i| out.touched.data[i] != 0).count();
            assert_eq!(touched_inside, 0, "{query:?}");
            assert!(same_bits(r, rv), "{query:?}");
        } else {
            assert_eq!(touched, 0, "{query:?}");
            assert!(same_bits(r, rv), "{query:?}");
        }
    }
}

#[test]
fn visibility_switches_the_objects_self_occlusion() {
    // Two spheres, one above the other, under a constant sky and with no near real
    // geometry (the impostor queries): with the visibility test the upper sphere
    // shadows the lower one; without it every virtual point gets the pi L of its
    // whole hemisphere.
    let table = uniform_table(4096);
    let env = dome(Vec3::new(0.0, 1.0, 1.0), 6.0);
    let mut objects = gray_sphere(SPHERE_CENTER);
    let above = gray_sphere(SPHERE_CENTER + Vec3::new(0.0, 2.2 * SPHERE_RADIUS, 0.0));
    objects.triangles.extend(above.triangles);
    objects.rebuild();
    for query in [QueryKind::Em, QueryKind::Dit, QueryKind::Vct] {
        let run = |visibility| {
            let p = PathParams {
                visibility,
                ..params(query, 4)
            };
            run_floor(&objects, &table, &env, &p)
        };
        let (with, without) = (run(true), run(false));
        let mean = |out: &IrradianceLayers| {
            let virtual_pixels: Vec<f32> = (0..(W * H) as usize)
                .filter(|&i| out.mask.data[i] == 0.0)
                .map(|i| out.e_rv_dir.data[i].x / (PI * SKY.x))
                .collect();
            assert!(virtual_pixels.len() > 150, "{}", virtual_pixels.len());
            virtual_pixels.iter().sum::<f32>() / virtual_pixels.len() as f32
        };
        let (a, b) = (mean(&with), mean(&without));
        // 16 samples per pixel over about 260 pixels: the mean is within 2 % (1 sigma).
        assert!((b - 1.0).abs() < 0.06, "{query:?}: without visibility {b}");
        assert!(a < b - 0.03, "{query:?}: with visibility {a}, without {b}");
    }
}

#[test]
fn vct_cones_leave_a_convex_object_unshadowed_by_itself() {
    // A lone sphere cannot shadow itself: the cones of its direct samples start off
    // its surface (LEAVE_VOXELS) and must find its solid volume clear.
    let table = uniform_table(4096);
    let env = dome(Vec3::new(0.0, 1.0, 1.0), 6.0);
    let objects = gray_sphere(SPHERE_CENTER);
    let out = run_floor(&objects, &table, &env, &params(QueryKind::Vct, 0));
    let virtual_pixels: Vec<f32> = (0..(W * H) as usize)
        .filter(|&i| out.mask.data[i] == 0.0)
        .map(|i| out.e_rv_dir.data[i].x / (PI * SKY.x))
        .collect();
    assert!(virtual_pixels.len() > 150, "{}", virtual_pixels.len());
    let mean = virtual_pixels.iter().sum::<f32>() / virtual_pixels.len() as f32;
    assert!((mean - 1.0).abs() < 0.06, "E_dir / (pi L) = {mean}");
}
