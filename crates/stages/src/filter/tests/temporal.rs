//! The reprojection of the temporal filter: `find_previous` on points it must reject,
//! and its lane form against it.

use super::*;
use crate::filter::lane_planes::{LaneLayout, LanePlanes};
use crate::filter::layout::{X_PLANES, X_PX, X_PY, X_PZ};
use crate::filter::temporal::{
    PreviousView, consecutive_run, find_previous_lanes, projected_pixel, run_positions,
};
use relume_base::simd::{LANES, Portable};

#[test]
fn a_point_behind_or_beside_the_previous_camera_has_no_match() {
    let scene = Scene::new(plane(2.0), 1.0, 1.0);
    let mut filter = AxisAlignedFilter::new(params(true));
    let mut out = FilterOutputs::new(W, H);
    filter
        .filter(&scene.inputs(Some((Pose::IDENTITY, camera()))), &mut out)
        .unwrap();
    let view = filter.previous_view.unwrap();
    assert_eq!(
        find_previous(
            Vec3::new(0.0, 0.0, -1.0),
            &view,
            filter.previous_x_set.planes()
        ),
        None
    );
    assert_eq!(
        find_previous(
            Vec3::new(50.0, 0.0, 2.0),
            &view,
            filter.previous_x_set.planes()
        ),
        None
    );
}

/// Eight points at a time through `find_previous_lanes`, each lane against
/// `find_previous`: the scene's own positions seen from a turned camera (ties between
/// equal distances included: the plane behind the sphere is flat), jittered points,
/// points behind the camera, off the screen, on its edges, NaN, and inactive lanes.
fn check_find_previous_lanes<V: Lanes>(name: &str, view: &PreviousView, previous: &LanePlanes) {
    let cam = camera();
    let mut points: Vec<Vec3> = Scene::new(sphere(Vec3::new(0.0, 0.0, 1.5), 0.3, 2.0), 1.0, 1.0)
        .position
        .data
        .iter()
        .enumerate()
        .map(|(i, &p)| p + 0.01 * Vec3::new(noise(60, i), noise(61, i), noise(62, i)))
        .collect();
    // Midway between the positions of two neighbouring previous pixels (and a few
    // ulps off): the nearest is decided by the last bits of the distances, or is a tie.
    let q = |x: usize, y: usize| {
        Vec3::new(
            previous.at(X_PX, x, y),
            previous.at(X_PY, x, y),
            previous.at(X_PZ, x, y),
        )
    };
    for y in (1..H as usize - 1).step_by(3) {
        for x in (1..W as usize - 1).step_by(2) {
            for (a, b) in [(q(x, y), q(x + 1, y)), (q(x, y), q(x, y + 1))] {
                let mid = (a + b) * 0.5;
                points.extend([mid, mid + Vec3::splat(1e-7), mid - Vec3::splat(2e-7)]);
            }
        }
    }
    // On the borders between previous pixels: the pixel a point falls in is decided by
    // the last bits of its projection.
    let to_world = view.world_to_camera.inverse();
    for y in (0..H).step_by(5) {
        for x in 0..W {
            for du in [-1e-4, -4e-6, -2e-6, 0.0, 2e-6, 4e-6, 1e-4] {
                let ray = cam.ray(x as f32 - 0.5 + du, y as f32 - 0.5 - du);
                points.push(to_world.transform_point3(ray * 2.0));
            }
        }
    }
    // Runs: the previous pixels' own positions, eight consecutive pixels of a line per
    // group (block-aligned or not, on the first and last lines and columns too), which
    // the lane form reads as runs rather than gathers.
    points.resize(points.len().next_multiple_of(LANES), Vec3::ZERO);
    let runs_start = points.len();
    for y in (0..H as usize).step_by(7).chain([H as usize - 1]) {
        for start in [0, 3, 5] {
            for x in (start..W as usize - LANES + 1)
                .step_by(LANES)
                .chain([W as usize - LANES])
            {
                points.extend((x..x + LANES).map(|x| q(x, y)));
            }
        }
    }
    let runs = points[runs_start..]
        .chunks(LANES)
        .filter(|group| {
            let pixels: [_; LANES] =
                std::array::from_fn(|l| projected_pixel(group[l], view, previous));
            let (ui, vi) = (
                pixels.map(|p| p.map_or(-1, |p| p.0)),
                pixels.map(|p| p.map_or(-1, |p| p.1)),
            );
            let inside = pixels.map(|p| f32::from_bits(if p.is_some() { !0 } else { 0 }));
            consecutive_run(&ui, &vi, inside, previous).is_some()
        })
        .count();
    assert!(runs > 100, "{name}: only {runs} groups are runs");
    let runs_end = points.len();
    points.extend([
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(50.0, 0.0, 2.0),
        Vec3::NAN,
        Vec3::ZERO,
        cam.ray(0.0, 0.0) * 2.0,
        cam.ray(W as f32 - 0.5, H as f32 - 0.5) * 2.0,
        cam.ray(-0.6, 3.0) * 2.0,
        cam.ray(W as f32 + 0.1, 3.0) * 2.0,
    ]);
    let mut found = 0;
    for (g, group) in points.chunks(LANES).enumerate() {
        let lane = |l: usize| group.get(l).copied().unwrap_or(Vec3::ZERO);
        let p = [0, 1, 2].map(|c| V::from_array(std::array::from_fn(|l| lane(l)[c])));
        // Some lanes inactive, except in the runs (a run needs all eight).
        let in_runs = (runs_start..runs_end).contains(&(LANES * g));
        let active: [bool; LANES] =
            std::array::from_fn(|l| l < group.len() && (in_runs || (g + l) % 7 != 3));
        let got = find_previous_lanes(p, V::from_mask(active), view, previous).pixels();
        for l in 0..LANES {
            let expected = active[l]
                .then(|| find_previous(lane(l), view, previous))
                .flatten();
            assert_eq!(
                got[l],
                expected,
                "{name}: point {} {}",
                LANES * g + l,
                lane(l)
            );
            found += expected.is_some() as usize;
        }
    }
    assert!(
        found > points.len() / 2,
        "{name}: {found} of {} found",
        points.len()
    );
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn check_find_previous_lanes_avx2(view: &PreviousView, previous: &LanePlanes) {
    check_find_previous_lanes::<lanes::Avx2>("Avx2", view, previous);
}

#[test]
fn a_run_reads_eight_consecutive_pixels() {
    let scene = Scene::new(sphere(Vec3::new(0.0, 0.0, 1.5), 0.3, 2.0), 1.0, 1.0);
    let mut filter = AxisAlignedFilter::new(params(true));
    let mut out = FilterOutputs::new(W, H);
    filter.filter(&scene.inputs(None), &mut out).unwrap();
    // Also a set 64 wide, whose runs at the right edge reach the zero block past the
    // last one (8 blocks of 8: no spare block inside the line).
    let mut narrow = LanePlanes::new(LaneLayout::blocks(X_PLANES, 64, 5, 2));
    for q in [X_PX, X_PY, X_PZ] {
        for y in 0..5 {
            for x in 0..64 {
                let i = narrow.pixel_index(x, y) + q * narrow.plane_stride();
                narrow.data_mut()[i] = (1000 * q as isize + 100 * y + x + 1) as f32;
            }
        }
    }
    for set in [filter.previous_x_set.planes(), &narrow] {
        let (w, h) = (set.width as i32, set.height as i32);
        let at = |q: usize, x: i32, y: i32| {
            // Outside the image: the set's zero blocks or padding lines.
            let inside = x >= 0 && y >= 0 && x < w && y < h;
            if inside {
                set.at(q, x as usize, y as usize)
            } else {
                0.0
            }
        };
        for y in [-1, 0, 1, h / 2, h - 1, h] {
            for x0 in -1..w - LANES as i32 + 2 {
                let got = run_positions::<Portable>(set, x0, y);
                for (c, q) in [X_PX, X_PY, X_PZ].into_iter().enumerate() {
                    let expected: [f32; LANES] = std::array::from_fn(|l| at(q, x0 + l as i32, y));
                    assert_eq!(
                        got[c].to_array().map(f32::to_bits),
                        expected.map(f32::to_bits),
                        "{w} wide, x0 {x0}, line {y}"
                    );
                }
            }
        }
    }
}

#[test]
fn find_previous_in_lanes_gives_the_scalar_answers() {
    let scene = Scene::new(sphere(Vec3::new(0.0, 0.0, 1.5), 0.3, 2.0), 1.0, 1.0);
    let turned = Pose::from_parts(
        glam::DVec3::new(0.02, 0.01, 0.0),
        glam::DQuat::from_rotation_y(0.03),
    );
    let mut filter = AxisAlignedFilter::new(params(true));
    let mut out = FilterOutputs::new(W, H);
    filter
        .filter(&scene.inputs(Some((turned, camera()))), &mut out)
        .unwrap();
    let view = filter.previous_view.unwrap();
    check_find_previous_lanes::<Portable>("Portable", &view, filter.previous_x_set.planes());
    #[cfg(target_arch = "x86_64")]
    if lanes::Kernel::detect() == lanes::Kernel::Avx2Fma {
        // SAFETY: the CPU has AVX2 and FMA.
        unsafe { check_find_previous_lanes_avx2(&view, filter.previous_x_set.planes()) };
    }
}
