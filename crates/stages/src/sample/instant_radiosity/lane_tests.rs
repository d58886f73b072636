//! The lane code of `sample.dir` (`gather_lanes.rs`, `blur_lanes.rs`,
//! `splat.rs`) against the one-at-a-time code, bit for bit, and the rectangle
//! that bounds the view rays that meet the objects.

use super::gather_lanes::gather_lanes;
use super::interleave::{object_rect, primary_hit};
use super::ism::project_point;
use super::ism::{Projection, frame_about};
use super::shade::{Gathered, LightSet, Receiver, gather};
use super::splat::project_points;
use super::splat::splat_with;
use super::tests::{RED, inputs};
use super::vpl::{Emitter, Vpl};
use super::*;
use crate::sample::path::tests::{
    SPHERE_CENTER, SPHERE_RADIUS, bits, floor_scene, pose, sphere, uniform_table,
};
use glam::Vec3;
use relume_base::rng::{hash, unit_f32};
use relume_base::simd::{Kernel, LANES};
use relume_scene::objects::VirtualScene;

/// A uniform float in [lo, hi) from hash `h` and `k`.
fn uniform(h: u64, k: u64, lo: f32, hi: f32) -> f32 {
    lo + unit_f32(hash(&[h, k])) * (hi - lo)
}

/// The bits of what a receiver gathered.
fn gathered_bits(g: &Gathered) -> [u32; 15] {
    let v = [g.r_dir, g.r_ind, g.rv_dir, g.rv_ind];
    std::array::from_fn(|i| match i {
        0..12 => v[i / 3].to_array()[i % 3].to_bits(),
        12 => g.touched as u32,
        13 => g.direct_min_distance.to_bits(),
        _ => g.indirect_min_distance.to_bits(),
    })
}

/// The lane gather of eight receivers equals the scalar gather of each, bit for bit,
/// over VPLs of every kind (directions with orthographic maps, surfaces with
/// paraboloids; real, virtual and ir = 1) with partly filled maps of random depths,
/// and receivers of both kinds at random points: some at a VPL, beyond its reach,
/// behind its paraboloid, NaN, with zero normals or facing away.
#[test]
fn the_lane_gather_equals_the_scalar_gather_of_each_receiver() {
    let size = 16;
    let mut vpls = Vec::new();
    let mut projections = Vec::new();
    let mut rects = Vec::new();
    for slot in 0..24u64 {
        let h = hash(&[0x6A7E, slot]);
        let axis = Vec3::new(
            uniform(h, 0, -1.0, 1.0),
            uniform(h, 1, 0.1, 1.0),
            uniform(h, 2, -1.0, 1.0),
        )
        .normalize();
        let origin = Vec3::new(uniform(h, 3, -1.0, 1.0), uniform(h, 4, 0.0, 1.0), 0.0);
        let (emitter, projection) = if slot % 3 == 0 {
            let frame = frame_about(axis);
            let center = Vec3::new(0.1, 0.3, -0.2);
            let real = Projection::Orthographic {
                center,
                radius: 1.4,
                frame,
            };
            let virtual_ = Projection::Orthographic {
                center,
                radius: 0.4,
                frame,
            };
            (Emitter::Direction(axis), [real, virtual_])
        } else {
            let p = Projection::Paraboloid {
                origin,
                frame: frame_about(-axis),
            };
            let emitter = Emitter::Surface {
                position: origin,
                normal: -axis,
            };
            (emitter, [p, p])
        };
        vpls.push(Vpl {
            emitter,
            power: Vec3::new(uniform(h, 5, 0.1, 2.0), 0.7, uniform(h, 6, 0.0, 1.0)),
            real_path: h % 4 != 1,
            real_only: h % 5 == 2,
            patch: uniform(h, 7, 0.0, 0.05),
            slot: slot as u32,
        });
        projections.push(projection);
        let x0 = (h >> 8) as u16 % 6;
        let y0 = (h >> 16) as u16 % 6;
        let empty_virtual = h % 7 == 3;
        rects.push([
            [x0, y0, 16 - x0 / 2, 16 - y0 % 3],
            if empty_virtual {
                [0; 4]
            } else {
                [0, 0, 16, 16]
            },
        ]);
    }
    let maps: Vec<f32> = (0..vpls.len() * 2 * size * size)
        .map(|i| {
            let h = hash(&[0x3A95, i as u64]);
            if h % 10 < 3 {
                f32::INFINITY
            } else {
                uniform(h, 1, 0.0, 3.0)
            }
        })
        .collect();
    let lights = LightSet {
        vpls: &vpls,
        projections: &projections,
        rects: &rects,
        maps: &maps,
        size,
        bias: 0.02,
        slope: 6.0,
        clamp_squared: 0.01,
        reach: 1.5,
        flags: Flags::Reciprocal,
    };
    let members: Vec<u32> = (0..vpls.len() as u32).collect();
    let (mut touched, mut shadowed, mut lit) = (0, 0, 0);
    for group in 0..300u64 {
        let point = |l: usize| {
            let h = hash(&[0x9017, group, l as u64]);
            let p = Vec3::new(
                uniform(h, 0, -2.0, 2.0),
                uniform(h, 1, -0.5, 1.5),
                uniform(h, 2, -1.0, 1.0),
            );
            let n = Vec3::new(
                uniform(h, 3, -1.0, 1.0),
                uniform(h, 4, -0.3, 1.0),
                uniform(h, 5, -1.0, 1.0),
            )
            .normalize();
            match h % 16 {
                0 => (Vec3::NAN, n),
                1 => (p, Vec3::ZERO),
                // At a surface VPL (d = 0).
                2 => {
                    let h = hash(&[0x6A7E, 1]);
                    let origin = Vec3::new(uniform(h, 3, -1.0, 1.0), uniform(h, 4, 0.0, 1.0), 0.0);
                    (origin, n)
                }
                _ => (p, n),
            }
        };
        let points: [(Vec3, Vec3); 8] = std::array::from_fn(point);
        let positions = points.map(|(p, _)| p);
        let normals = points.map(|(_, n)| n);
        for receiver in [Receiver::Real, Receiver::Virtual] {
            let scalar = points.map(|(p, n)| gather(&lights, &members, p, n, receiver));
            for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
                let lanes = gather_lanes(kernel, &lights, &members, receiver, &positions, &normals);
                for l in 0..8 {
                    assert_eq!(
                        gathered_bits(&lanes[l]),
                        gathered_bits(&scalar[l]),
                        "{kernel:?} {receiver:?} at {:?}: {:?} != {:?}",
                        points[l],
                        lanes[l],
                        scalar[l]
                    );
                }
            }
            touched += scalar.iter().filter(|g| g.touched).count();
            shadowed += scalar
                .iter()
                .filter(|g| g.direct_min_distance.is_finite())
                .count();
            lit += scalar
                .iter()
                .filter(|g| g.indirect_min_distance.is_finite())
                .count();
        }
    }
    // Every branch of the gather ran many times.
    assert!(
        touched > 500 && shadowed > 500 && lit > 500,
        "touched {touched}, shadowed {shadowed}, lit by a surface {lit}"
    );
}

/// A frame rendered with either kernel's lanes (the gather at real and virtual
/// receivers and bounce candidates, the blur, the splats' projections) has the bits of
/// one receiver, pixel and point at a time: over a floor whose normals are tilted
/// every which way (some away from the light, some past the horizon), with holes (no
/// depth, NaN depth, no normal), under one and two bounces, two interleavings and a
/// reach short enough that some surface VPLs light only part of a group of eight.
#[test]
fn the_lanes_give_the_bits_of_one_receiver_pixel_and_point_at_a_time() {
    let mut scene = floor_scene();
    for i in 0..scene.depth.data.len() {
        let h = relume_base::rng::hash(&[0x1A_4E5, i as u64]);
        let tilt = Vec3::new(
            relume_base::rng::unit_f32(h) - 0.5,
            relume_base::rng::unit_f32(h >> 21) - 0.5,
            relume_base::rng::unit_f32(h >> 42) - 0.5,
        );
        let n = scene.normals.data[i];
        if n != Vec3::ZERO {
            scene.normals.data[i] = (n + 1.5 * tilt).normalize();
        }
        scene.radiance.data[i] *= 0.5 + tilt.abs();
        match h % 37 {
            0 => scene.depth.data[i] = 0.0,
            1 => scene.depth.data[i] = f32::NAN,
            2 => scene.normals.data[i] = Vec3::ZERO,
            _ => {}
        }
    }
    let objects = sphere(SPHERE_CENTER, SPHERE_RADIUS, RED);
    let table = uniform_table(4096);
    let mesh_params = DirParams::default();
    let mesh = MeshPoints::new(&objects, mesh_params.mesh_points as usize, 1);
    let settings = [
        DirParams::default(),
        DirParams {
            bounces: 2,
            interleave: 3,
            max_distance: 0.6,
            ..DirParams::default()
        },
    ];
    for params in settings {
        let render = |kernel| {
            let mut out = IrradianceLayers::new(scene.depth.width, scene.depth.height);
            DirRenderer::with_kernel(kernel)
                .render(
                    &inputs(&scene, &objects, &table, 3),
                    &params,
                    &mesh,
                    &mut out,
                )
                .unwrap();
            bits(&out)
        };
        let one_pixel = render(None);
        for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
            assert!(
                render(Some(kernel)) == one_pixel,
                "{kernel:?} lanes differ from one pixel at a time ({params:?})"
            );
        }
    }
}

/// The gather looks for the objects only inside `object_rect`: every pixel whose view
/// ray meets the sphere lies in it, for spheres in view (one off-axis near the camera)
/// and for the camera inside the objects' box (the whole image).
#[test]
fn every_view_ray_that_meets_an_object_lies_in_the_object_rectangle() {
    let scene = floor_scene();
    let table = uniform_table(64);
    let (w, h) = (scene.depth.width as usize, scene.depth.height as usize);
    let camera_position = Vec3::from(pose().translation);
    for (center, radius, whole) in [
        (SPHERE_CENTER, SPHERE_RADIUS, false),
        (Vec3::new(0.4, 0.2, 0.5), 0.05, false),
        // Off-axis, 0.75 m in front of the camera.
        (Vec3::new(0.25, 1.2, -1.3), 0.1, false),
        (camera_position, 0.5, true),
    ] {
        let objects = sphere(center, radius, RED);
        let inputs = inputs(&scene, &objects, &table, 0);
        let [x0, y0, x1, y1] = object_rect(&inputs);
        let mut hits = 0;
        for y in 0..h {
            for x in 0..w {
                if primary_hit(&inputs, x, y, None).is_some() {
                    hits += 1;
                    assert!(
                        (x0..x1).contains(&x) && (y0..y1).contains(&y),
                        "({x}, {y}) meets the sphere at {center} outside [{x0}, {y0}, {x1}, {y1})"
                    );
                }
            }
        }
        assert!(hits > 0, "the sphere at {center} is in view");
        let area = (x1 - x0) * (y1 - y0);
        if whole {
            assert_eq!([x0, y0, x1, y1], [0, 0, w, h]);
        } else {
            assert!(area < w * h / 4, "[{x0}, {y0}, {x1}, {y1}) is not tight");
        }
    }
    let none = VirtualScene::default();
    assert_eq!(object_rect(&inputs(&scene, &none, &table, 0)), [0; 4]);
}

/// The splat's projection in lanes gives each point the texel, depth and reach of the
/// one-point code, for both projections and patch radii from none through whole texel
/// counts to past the largest reach, NaN and infinite.
#[test]
fn the_splat_lanes_project_as_one_point_at_a_time() {
    let size = 128;
    let frame = frame_about(Vec3::new(0.3, 0.8, -0.2).normalize());
    let projections = [
        Projection::Paraboloid {
            origin: Vec3::new(0.1, 0.2, 0.3),
            frame,
        },
        Projection::Orthographic {
            center: Vec3::new(-0.2, 0.1, 0.0),
            radius: 1.3,
            frame,
        },
    ];
    let mut reaches = std::collections::BTreeSet::new();
    for projection in &projections {
        for group in 0..400u64 {
            let points: [(Vec3, f32); 8] = std::array::from_fn(|l| {
                let h = relume_base::rng::hash(&[0x5B1A7, group, l as u64]);
                let u = |k: u64| {
                    relume_base::rng::unit_f32(relume_base::rng::hash(&[h, k])) * 3.0 - 1.5
                };
                let p = Vec3::new(u(0), u(1), u(2));
                let texel = projection.texel_size(1.0, size);
                let radius = match h % 9 {
                    0 => 0.0,
                    1 => f32::NAN,
                    2 => f32::INFINITY,
                    // Whole and half texel counts at depth 1 (exact ceilings).
                    3 => texel * (1.5 + (h % 5) as f32),
                    4 => texel * (h % 7) as f32,
                    _ => relume_base::rng::unit_f32(h >> 40) * 0.2,
                };
                (p, radius)
            });
            let one_at_a_time = points.map(|(p, r)| project_point(projection, size, p, r));
            for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
                assert_eq!(
                    project_points(kernel, projection, size, &points),
                    one_at_a_time,
                    "{kernel:?}, {projection:?}, {points:?}"
                );
            }
            reaches.extend(one_at_a_time.iter().flatten().map(|&(_, reach)| reach));
        }
    }
    assert_eq!(reaches.into_iter().collect::<Vec<_>>(), [0, 1, 2, 3, 4]);
}

/// Splatting eight points at a time writes the maps of one point at a time bit for bit
/// (the squares' rows in lanes, clipped at every edge, the last rows one at a time),
/// with the same written rectangle.
#[test]
fn the_splat_lanes_write_the_maps_of_one_point_at_a_time() {
    let size = 32;
    let frame = frame_about(Vec3::new(-0.4, 0.7, 0.5).normalize());
    let projections = [
        Projection::Paraboloid {
            origin: Vec3::ZERO,
            frame,
        },
        Projection::Orthographic {
            center: Vec3::ZERO,
            radius: 1.0,
            frame,
        },
    ];
    // Squares in the last row whose eight lanes would pass the map's end.
    let mut past_the_end = 0;
    for projection in &projections {
        for set in 0..40u64 {
            // 8 k + 5 points: the group loop and its tail both run.
            let points: Vec<(Vec3, f32)> = (0..8 * (set % 6) + 5)
                .map(|i| {
                    let h = relume_base::rng::hash(&[0x5B1A8, set, i]);
                    let u = |k: u64| {
                        relume_base::rng::unit_f32(relume_base::rng::hash(&[h, k])) * 2.4 - 1.2
                    };
                    let texel = projection.texel_size(1.0, size);
                    (Vec3::new(u(0), u(1), u(2)), texel * (h % 11) as f32 * 0.5)
                })
                .collect();
            let mut one_at_a_time = vec![f32::INFINITY; size * size];
            let expected = splat_with(
                None,
                &mut one_at_a_time,
                size,
                projection,
                points.iter().copied(),
            );
            past_the_end += points
                .iter()
                .filter_map(|&(p, r)| project_point(projection, size, p, r))
                .filter(|&(t, reach)| {
                    let (x0, last_row) = (t.x as i32 - reach, t.y as i32 + reach);
                    reach > 0 && last_row >= size as i32 - 1 && x0 > (size - LANES) as i32
                })
                .count();
            for kernel in [Kernel::Portable, Kernel::Avx2Fma] {
                let mut map = vec![f32::INFINITY; size * size];
                let written = splat_with(
                    Some(kernel),
                    &mut map,
                    size,
                    projection,
                    points.iter().copied(),
                );
                assert_eq!(written, expected, "{kernel:?}, {projection:?}, set {set}");
                let map_bits = |m: &[f32]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    map_bits(&map),
                    map_bits(&one_at_a_time),
                    "{kernel:?}, {projection:?}, set {set}"
                );
            }
        }
    }
    assert!(
        past_the_end > 0,
        "some square's last row is written one texel at a time"
    );
}
