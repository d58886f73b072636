use super::accumulate::*;
use crate::OpError;
use glam::{Affine3A, Vec3};
use relume_base::pinhole::Pinhole;
use relume_base::raster::{Image, LabelImage, ScalarImage, Vec3Image};
use relume_recording::Intrinsics;
use relume_scene::objects::{Aabb, ObjectMove};

const W: u32 = 32;
const H: u32 = 24;

/// A frame's fresh layers, owned.
struct Fresh {
    irradiance: [Vec3Image; 4],
    direct_min: ScalarImage,
    indirect_min: ScalarImage,
    touched: LabelImage,
    position: Vec3Image,
    normal: Vec3Image,
}

impl Fresh {
    fn layers(&self) -> FreshLayers<'_> {
        FreshLayers {
            irradiance: [0, 1, 2, 3].map(|k| &self.irradiance[k]),
            direct_min_distance: &self.direct_min,
            indirect_min_distance: &self.indirect_min,
            touched: &self.touched,
            world_position: &self.position,
            world_normal: &self.normal,
        }
    }
}

fn camera() -> Pinhole {
    Pinhole::new(&Intrinsics::PRIMESENSE, W, H)
}

/// A wall at z = 2 (camera space of the identity pose) seen from `pose`, each pixel's
/// irradiance `value(world point)` in every layer (E_RV == E_R), untouched.
fn wall(pose: Affine3A, value: impl Fn(Vec3) -> Vec3) -> Fresh {
    let cam = camera();
    let eye = Vec3::from(pose.translation);
    let mut position = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let dir = pose.transform_vector3(cam.ray(x as f32, y as f32));
            let t = (2.0 - eye.z) / dir.z;
            position.push(eye + dir * t);
        }
    }
    let image = |data: Vec<Vec3>| Image::from_vec(W, H, data).unwrap();
    let values: Vec<Vec3> = position.iter().map(|&p| value(p)).collect();
    Fresh {
        irradiance: [0, 1, 2, 3].map(|_| image(values.clone())),
        direct_min: Image::filled(W, H, f32::INFINITY),
        indirect_min: Image::filled(W, H, f32::INFINITY),
        touched: Image::filled(W, H, 0),
        normal: Image::filled(W, H, Vec3::NEG_Z),
        position: image(position),
    }
}

/// Runs `frames` (pose, fresh layers) through the accumulator in order; the last
/// frame's result.
fn run(frames: &[(Affine3A, &Fresh)], params: &AccumulateParams) -> Accumulated {
    run_with_objects(frames, params, None)
}

/// [`run`] with the objects' moves into frame k given by `moves[k]` (objects that
/// move), or as a still world (`None`). No pixel shows an object.
fn run_with_objects(
    frames: &[(Affine3A, &Fresh)],
    params: &AccumulateParams,
    moves: Option<&[Vec<ObjectMove>]>,
) -> Accumulated {
    let real: ScalarImage = Image::filled(W, H, 1.0);
    let masks = vec![&real; frames.len()];
    run_with_masks(frames, params, moves.map(|m| (m, &masks[..])))
}

/// [`run_with_objects`] with frame k's renderer mask `masks[k]` (0 where the pixel
/// shows an object).
fn run_with_masks(
    frames: &[(Affine3A, &Fresh)],
    params: &AccumulateParams,
    world: Option<(&[Vec<ObjectMove>], &[&ScalarImage])>,
) -> Accumulated {
    let mut previous: Option<(Accumulated, &Fresh, Affine3A)> = None;
    for (k, &(pose, fresh)) in frames.iter().enumerate() {
        let history = previous.as_ref().map(|(layers, seen, pose)| {
            History::of(
                layers,
                &seen.position,
                &seen.normal,
                pose.inverse(),
                camera(),
            )
        });
        let change = world.map(|(moves, masks)| WorldChange {
            mask: masks[k],
            objects: &moves[k],
        });
        let out = accumulate(
            &fresh.layers(),
            history.as_ref(),
            camera(),
            pose,
            params,
            change,
        )
        .unwrap();
        previous = Some((out, fresh, pose));
    }
    previous.unwrap().0
}

#[test]
fn a_still_camera_averages_its_frames_then_fades_the_oldest() {
    let params = AccumulateParams {
        max_history: 4,
        ..AccumulateParams::default()
    };
    let frames: Vec<Fresh> = (0..6)
        .map(|t| wall(Affine3A::IDENTITY, |_| Vec3::splat(t as f32)))
        .collect();
    let still: Vec<(Affine3A, &Fresh)> = frames.iter().map(|f| (Affine3A::IDENTITY, f)).collect();
    // Frames 0..3: the plain mean.
    let out = run(&still[..3], &params);
    assert!(out.frames.data.iter().all(|&n| n == 3.0));
    assert!(
        out.irradiance[0]
            .data
            .iter()
            .all(|v| *v == Vec3::splat(1.0))
    );
    // Past max_history the newest frame weighs 1 / 4: mean(0..4) = 1.5, then
    // 1.5 + (4 - 1.5) / 4 = 2.125, then 2.125 + (5 - 2.125) / 4 = 2.84375.
    let out = run(&still, &params);
    assert!(out.frames.data.iter().all(|&n| n == 4.0));
    for v in &out.irradiance[3].data {
        assert!((v.x - 2.84375).abs() < 1e-6, "{v}");
    }
}

#[test]
fn a_moving_camera_takes_the_history_of_the_same_surface_point() {
    // Each frame sees the wall's x coordinate plus its own offset; after two frames a
    // pixel holds the mean of its point's two values: exactly where all four bilinear
    // taps show the point, within half a pixel (7.6 cm at this image size) where the
    // image edge leaves fewer taps.
    let footprint = 2.0 / camera().fx;
    let first = Affine3A::IDENTITY;
    let second = Affine3A::from_translation(Vec3::new(0.3, 0.0, 0.0));
    let a = wall(first, |p| Vec3::splat(p.x + 10.0));
    let b = wall(second, |p| Vec3::splat(p.x + 20.0));
    let out = run(&[(first, &a), (second, &b)], &AccumulateParams::default());
    let (mut kept, mut restarted) = (0, 0);
    for (i, &p) in b.position.data.iter().enumerate() {
        let v = out.irradiance[0].data[i].x;
        if out.frames.data[i] == 2.0 {
            kept += 1;
            assert!(
                (v - (p.x + 15.0)).abs() < 0.5 * footprint,
                "pixel {i}: {v} at x = {}",
                p.x
            );
        } else {
            restarted += 1;
            assert_eq!(
                v,
                p.x + 20.0,
                "pixel {i} without history keeps this frame's"
            );
        }
    }
    // The camera moved 30 cm, about 4 pixels: the columns it uncovered start anew.
    assert!(kept > 20 * 24, "{kept} pixels kept their history");
    assert!(restarted >= 24, "{restarted} pixels started a new history");
}

#[test]
fn a_surface_that_was_not_there_before_starts_a_new_history() {
    let pose = Affine3A::IDENTITY;
    let a = wall(pose, |_| Vec3::ONE);
    // The same pixels now show a surface 50 cm nearer (the tolerance is 2 pixel
    // footprints, 15 cm at this image size), then one turned sideways.
    let mut nearer = wall(pose, |_| Vec3::splat(3.0));
    for p in &mut nearer.position.data {
        *p *= 1.5 / 2.0;
    }
    let out = run(&[(pose, &a), (pose, &nearer)], &AccumulateParams::default());
    assert!(out.frames.data.iter().all(|&n| n == 1.0));
    assert!(
        out.irradiance[1]
            .data
            .iter()
            .all(|v| *v == Vec3::splat(3.0))
    );
    let mut turned = wall(pose, |_| Vec3::splat(3.0));
    turned.normal = Image::filled(W, H, Vec3::X);
    let out = run(&[(pose, &a), (pose, &turned)], &AccumulateParams::default());
    assert!(out.frames.data.iter().all(|&n| n == 1.0));
}

#[test]
fn untouched_pixels_keep_e_rv_equal_to_e_r_bit_for_bit_and_touched_ones_stay_marked() {
    // Irrational-looking values, so that the averages round; pixels with x < 8 are
    // touched in the first frame only (E_RV darker), the rest never.
    let poses = [0.0, 0.004, 0.009].map(|dx| Affine3A::from_translation(Vec3::new(dx, 0.0, 0.0)));
    let frames: Vec<Fresh> = poses
        .iter()
        .enumerate()
        .map(|(t, &pose)| {
            let mut f = wall(pose, |p| {
                Vec3::new(
                    p.x.sin() + 1.3,
                    0.7 / (1.0 + p.y * p.y),
                    0.1 * t as f32 + 0.3331,
                )
            });
            if t == 0 {
                for i in 0..f.touched.data.len() {
                    if i % (W as usize) < 8 {
                        f.touched.data[i] = 1;
                        f.irradiance[2].data[i] *= 0.5;
                    }
                }
            }
            f
        })
        .collect();
    let sequence: Vec<(Affine3A, &Fresh)> = poses.iter().copied().zip(&frames).collect();
    let out = run(&sequence, &AccumulateParams::default());
    let (mut equal, mut marked) = (0, 0);
    for i in 0..out.touched.data.len() {
        let (e_r, e_rv) = (out.irradiance[0].data[i], out.irradiance[2].data[i]);
        if out.touched.data[i] == 0 {
            equal += 1;
            assert_eq!(
                e_r.to_array().map(f32::to_bits),
                e_rv.to_array().map(f32::to_bits),
                "pixel {i}"
            );
        } else {
            marked += 1;
            assert!(
                e_rv.x < e_r.x,
                "pixel {i}: the first frame's darkening is kept"
            );
        }
    }
    assert!(
        equal > 400 && marked > 100,
        "{equal} untouched, {marked} touched"
    );
}

#[test]
fn the_result_does_not_depend_on_the_thread_count() {
    let poses = [0.0, 0.011].map(|dx| Affine3A::from_translation(Vec3::new(dx, 0.003, 0.0)));
    let frames: Vec<Fresh> = poses
        .iter()
        .map(|&pose| wall(pose, |p| Vec3::new(p.x.cos(), p.y.sin(), p.x * p.y)))
        .collect();
    let sequence: Vec<(Affine3A, &Fresh)> = poses.iter().copied().zip(&frames).collect();
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run(&sequence, &AccumulateParams::default()))
    };
    assert_eq!(on(1), on(3));
}

#[test]
fn a_layer_of_another_size_is_refused_by_name() {
    let fresh = wall(Affine3A::IDENTITY, |_| Vec3::ONE);
    let small: ScalarImage = Image::filled(W - 1, H, 0.0);
    let layers = FreshLayers {
        indirect_min_distance: &small,
        ..fresh.layers()
    };
    let Err(OpError::SizeMismatch(message)) = accumulate(
        &layers,
        None,
        camera(),
        Affine3A::IDENTITY,
        &AccumulateParams::default(),
        None,
    ) else {
        panic!("a 31x24 layer was accepted");
    };
    assert_eq!(
        message,
        "temporal.accumulate: indirect_min_distance is 31x24, the camera's image is 32x24"
    );
}

#[test]
fn a_slow_pan_does_not_drag_the_history_behind_the_surface() {
    // A sharp edge on the wall (world x = 0.3) under a camera panning 0.4 pixels a
    // frame for 20 frames: the accumulated edge stays within a pixel of the true one
    // (taking the nearest previous pixel, the history would trail by several).
    let footprint = 2.0 / camera().fx;
    let poses: Vec<Affine3A> = (0..20)
        .map(|t| Affine3A::from_translation(Vec3::new(0.4 * footprint * t as f32, 0.0, 0.0)))
        .collect();
    let frames: Vec<Fresh> = poses
        .iter()
        .map(|&pose| wall(pose, |p| Vec3::splat(if p.x > 0.3 { 1.0 } else { 0.0 })))
        .collect();
    let sequence: Vec<(Affine3A, &Fresh)> = poses.iter().copied().zip(&frames).collect();
    let out = run(&sequence, &AccumulateParams::default());
    let last = frames.last().unwrap();
    let row = (H / 2) as usize * W as usize;
    let crossing = (0..W as usize - 1)
        .find_map(|x| {
            let (a, b) = (
                out.irradiance[0].data[row + x].x,
                out.irradiance[0].data[row + x + 1].x,
            );
            (a < 0.5 && b >= 0.5).then(|| {
                let (pa, pb) = (
                    last.position.data[row + x].x,
                    last.position.data[row + x + 1].x,
                );
                pa + (pb - pa) * (0.5 - a) / (b - a)
            })
        })
        .expect("the edge is in view");
    assert!(
        (crossing - 0.3).abs() < footprint,
        "the edge shows at x = {crossing}, a pixel is {footprint} m"
    );
    assert!(out.frames.data[row + W as usize / 2] > 15.0);
}

/// A wall whose pixels in columns `shadow` are touched by an object that darkens E_RV
/// there to `dark` (E_R is `lit` everywhere).
fn shadowed_wall(shadow: std::ops::Range<u32>, lit: f32, dark: f32) -> Fresh {
    let mut f = wall(Affine3A::IDENTITY, |_| Vec3::splat(lit));
    for y in 0..H {
        for x in shadow.clone() {
            let i = (y * W + x) as usize;
            f.irradiance[2].data[i] = Vec3::splat(dark);
            f.irradiance[3].data[i] = Vec3::splat(dark);
            f.touched.data[i] = 1;
            f.direct_min.data[i] = 0.5;
        }
    }
    f
}

/// An object's move on the wall (z = 2) of [`wall`]: its box around `x` (metres, at
/// the wall) and, when it moved, by how much along x since the frame before.
fn object_at(x: f32, moved_by: Option<f32>) -> ObjectMove {
    ObjectMove {
        bounds: Aabb {
            min: Vec3::new(x - 0.05, -1.0, 1.9),
            max: Vec3::new(x + 0.05, 1.0, 1.95),
        },
        moved: moved_by.is_some(),
        to_earlier: Affine3A::from_translation(Vec3::new(-moved_by.unwrap_or(0.0), 0.0, 0.0)),
    }
}

/// The wall's x (metres at z = 2) seen at column `x` of the identity camera.
fn wall_x(x: u32) -> f32 {
    camera().ray(x as f32, 0.0).x * 2.0
}

#[test]
fn a_still_world_gives_the_same_bits_with_and_without_change_detection() {
    let frames: Vec<Fresh> = (0..5)
        .map(|t| shadowed_wall(8..16, 1.0 + t as f32 * 0.37, 0.3 + t as f32 * 0.11))
        .collect();
    let pose = Affine3A::from_translation(Vec3::new(0.01, 0.0, 0.0));
    let moving: Vec<(Affine3A, &Fresh)> = frames
        .iter()
        .enumerate()
        .map(|(t, f)| (if t % 2 == 0 { Affine3A::IDENTITY } else { pose }, f))
        .collect();
    let params = AccumulateParams::default();
    let plain = run(&moving, &params);
    // The object stands still beside the shadow in every frame.
    let still = vec![vec![object_at(wall_x(12), None)]; 5];
    let watched = run_with_objects(&moving, &params, Some(&still));
    assert_eq!(plain.irradiance, watched.irradiance);
    assert_eq!(plain.frames, watched.frames);
    assert_eq!(plain.touched, watched.touched);
    let change = watched.change.unwrap();
    assert_eq!(change.differential_frames, plain.frames);
    assert!(plain.change.is_none());
}

/// Four frames of an object's shadow over columns 8..16 of a still camera (each
/// frame's shadow a little darker or lighter: the history is their mean 0.3), then the
/// object moves by 12 columns and its shadow (0.1) covers columns 20..28: the fresh
/// frames, and each frame's objects.
fn shadow_then_move() -> (Vec<Fresh>, Vec<Vec<ObjectMove>>) {
    let shift = wall_x(20) - wall_x(8);
    let mut fresh: Vec<Fresh> = [0.2, 0.4, 0.2, 0.4]
        .iter()
        .map(|&d| shadowed_wall(8..16, 1.0, d))
        .collect();
    fresh.push(shadowed_wall(20..28, 1.0, 0.1));
    let mut moves = vec![vec![object_at(wall_x(12), None)]; 4];
    moves.push(vec![object_at(wall_x(24), Some(shift))]);
    (fresh, moves)
}

#[test]
fn a_moved_objects_shadow_takes_its_history_along_and_leaves_no_ghost() {
    let (fresh, moves) = shadow_then_move();
    let frames: Vec<(Affine3A, &Fresh)> = fresh.iter().map(|f| (Affine3A::IDENTITY, f)).collect();
    let params = AccumulateParams::default();
    let moved = run_with_objects(&frames, &params, Some(&moves));
    let ignored = run(&frames, &params);
    let at = |x: u32| (12 * W + x) as usize;
    // The old footprint: no ghost (its point relative to the object, 12 columns to
    // the left, was unshadowed); E_R keeps its five frames.
    let old = at(14);
    assert_eq!(moved.irradiance[2].data[old], Vec3::ONE);
    assert_eq!(moved.irradiance[0].data[old], Vec3::ONE);
    assert_eq!(moved.frames.data[old], 5.0);
    // Without change detection the ghost holds four fifths of the old shadow:
    // 0.3 + (1 - 0.3) / 5.
    assert!((ignored.irradiance[2].data[old].x - 0.44).abs() < 1e-6);
    // The new footprint: the old shadow's history (mean 0.3 over four frames)
    // carried along and averaged with this frame's 0.1: (4 * 0.3 + 0.1) / 5 = 0.26.
    let new = at(24);
    let v = moved.irradiance[2].data[new].x;
    assert!((v - 0.26).abs() < 1e-5, "{v}");
    assert!((ignored.irradiance[2].data[new].x - 0.82).abs() < 1e-5);
    let change = moved.change.as_ref().unwrap();
    assert_eq!(change.differential_frames.data[new], 5.0);
    // Where no object was or is, the history is whole, E_RV == E_R bit for bit.
    let clear = at(2);
    assert_eq!(change.differential_frames.data[clear], 5.0);
    assert_eq!(
        moved.irradiance[2].data[clear],
        moved.irradiance[0].data[clear]
    );
    // A point whose place relative to the object was not seen a frame ago (past the
    // image's left edge) starts its differential anew.
    let mut far = vec![vec![object_at(wall_x(12), None)]; 4];
    far.push(vec![object_at(wall_x(24), Some(10.0))]);
    let lost = run_with_objects(&frames, &params, Some(&far));
    let v = lost.irradiance[2].data[new].x;
    assert!((v - 0.1).abs() < 1e-6, "{v}");
    assert_eq!(lost.change.unwrap().differential_frames.data[new], 1.0);
}

#[test]
fn a_moved_objects_own_pixels_take_the_history_of_the_same_object_points() {
    // An object covers columns 8..16 (mask 0, its surface standing in the wall's
    // plane) for four frames, then moves 12 columns on, to 20..28. Its pixels there
    // take the four frames of the same object points.
    let object = |columns: std::ops::Range<u32>| {
        let mut mask: ScalarImage = Image::filled(W, H, 1.0);
        for y in 0..H {
            for x in columns.clone() {
                mask.data[(y * W + x) as usize] = 0.0;
            }
        }
        mask
    };
    let (before, after) = (object(8..16), object(20..28));
    let masks = [&before, &before, &before, &before, &after];
    let (fresh, moves) = shadow_then_move();
    let frames: Vec<(Affine3A, &Fresh)> = fresh.iter().map(|f| (Affine3A::IDENTITY, f)).collect();
    let params = AccumulateParams::default();
    let out = run_with_masks(&frames, &params, Some((&moves, &masks)));
    let at = |x: u32| (12 * W + x) as usize;
    // The object's pixels: (4 * 0.3 + 0.1) / 5 of the same points, five frames.
    let v = out.irradiance[2].data[at(24)].x;
    assert!((v - 0.26).abs() < 1e-5, "{v}");
    assert_eq!(out.frames.data[at(24)], 5.0);
    assert_eq!(out.change.as_ref().unwrap().object.data[at(24)], 1);
    // Where it stood the wall shows again, its differential that of the point as far
    // from the object a frame ago (none): E_RV is E_R, whose history (the real surface
    // behind the object, estimated all along) holds its five frames.
    assert_eq!(out.irradiance[2].data[at(12)], Vec3::ONE);
    assert_eq!(
        out.irradiance[2].data[at(12)],
        out.irradiance[0].data[at(12)]
    );
    assert_eq!(out.frames.data[at(12)], 5.0);
}

#[test]
fn a_point_uncovered_by_the_move_takes_the_carried_points_history() {
    // As in shadow_then_move, but the previous frames did not see columns 20..28 (no
    // surface there then: the moved object uncovers them, as a torus's hole moves over
    // the floor). Their E_R and differential come from the points as far from the
    // object a frame ago: E_R 1 over four frames, the shadow's mean 0.3.
    let (mut fresh, moves) = shadow_then_move();
    for f in &mut fresh[..4] {
        for y in 0..H {
            for x in 20..28 {
                f.position.data[(y * W + x) as usize] = Vec3::NAN;
            }
        }
    }
    let frames: Vec<(Affine3A, &Fresh)> = fresh.iter().map(|f| (Affine3A::IDENTITY, f)).collect();
    let params = AccumulateParams::default();
    let out = run_with_objects(&frames, &params, Some(&moves));
    let new = (12 * W + 24) as usize;
    let v = out.irradiance[2].data[new].x;
    assert!((v - 0.26).abs() < 1e-5, "{v}");
    assert_eq!(out.irradiance[0].data[new], Vec3::ONE);
    assert_eq!(out.frames.data[new], 5.0);
    assert_eq!(out.change.unwrap().differential_frames.data[new], 5.0);
    // Without a move, the same unseen points start anew: this frame's 0.1 alone.
    let mut still = moves.clone();
    still[4] = vec![object_at(wall_x(24), None)];
    let out = run_with_objects(&frames, &params, Some(&still));
    assert_eq!(out.irradiance[2].data[new], Vec3::splat(0.1));
    assert_eq!(out.frames.data[new], 1.0);
}
