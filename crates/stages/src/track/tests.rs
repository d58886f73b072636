//! The tracker on frames of the synthetic room rendered from known poses (noise-free
//! depth, shaded color).

use super::*;
use glam::{DVec3, Mat3, Vec3};
use relume_base::raster::Image;
use relume_recording::synth::camera::camera_pose;
use relume_recording::synth::interreflection::room;
use relume_recording::synth::render::{View, render_view};

const SIZE: (u32, u32) = (320, 240);

fn intrinsics() -> Intrinsics {
    Intrinsics::PRIMESENSE.scaled_to(SIZE.0, SIZE.1)
}

/// Color (the radiance through a fixed exposure and gamma 2.2) and exact depth of the
/// room seen from `pose`. The shading's sampling noise is keyed by the pose, so that two
/// views do not share a noise pattern fixed on the screen (which would pull the
/// photometric term towards no motion).
fn render(pose: &Pose) -> (Rgb8Image, DepthImage) {
    let view = View {
        rotation: Mat3::from_quat(pose.rotation().as_quat()),
        position: pose.translation().as_vec3(),
        intrinsics: intrinsics(),
    };
    let key = pose
        .translation
        .iter()
        .fold(0u64, |h, t| h.rotate_left(17) ^ t.to_bits());
    let maps = render_view(&room(), &view, 1, key);
    let color = maps
        .radiance
        .iter()
        .map(|r| {
            let c = (*r * 0.6).clamp(Vec3::ZERO, Vec3::ONE).powf(1.0 / 2.2) * 255.0;
            [c.x.round() as u8, c.y.round() as u8, c.z.round() as u8]
        })
        .collect();
    (
        Image::from_vec(SIZE.0, SIZE.1, color).unwrap(),
        Image::from_vec(SIZE.0, SIZE.1, maps.depth).unwrap(),
    )
}

/// `pose` moved by `translation` (metres, in its own camera frame) and turned by
/// `degrees` about `axis` (camera frame).
fn moved(pose: &Pose, translation: DVec3, axis: DVec3, degrees: f64) -> Pose {
    let motion = DMat4::from_rotation_translation(
        DQuat::from_axis_angle(axis.normalize(), degrees.to_radians()),
        translation,
    );
    pose_of(&(pose.matrix() * motion))
}

/// Translation (metres) and rotation (degrees) between two poses.
fn error(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        a.translation().distance(b.translation()),
        a.rotation().angle_between(b.rotation()).to_degrees(),
    )
}

#[test]
fn a_known_motion_is_recovered_within_a_millimetre_and_a_twentieth_of_a_degree() {
    let first = camera_pose(1.0);
    let second = moved(
        &first,
        DVec3::new(0.03, -0.01, 0.02),
        DVec3::new(0.3, 1.0, 0.2),
        2.0,
    );
    let mut tracker = Tracker::new(intrinsics(), TrackParams::default());
    let (c0, d0) = render(&first);
    let (c1, d1) = render(&second);
    assert_eq!(
        tracker.track(&c0, &d0, Some(&first), None, None).unwrap(),
        Tracked::Started(first)
    );
    let Tracked::Pose(got, alignment) = tracker.track(&c1, &d1, None, None, None).unwrap() else {
        panic!("lost");
    };
    let (t, r) = error(&got, &second);
    eprintln!(
        "error {:.3} mm, {r:.4} deg; {} of {} points matched, rmse {:.2} mm",
        t * 1e3,
        alignment.inliers,
        alignment.valid,
        alignment.rmse_m * 1e3
    );
    assert!(t < 1e-3 && r < 0.05, "{t} m, {r} deg");
    // Without tracking, the error would be the whole motion.
    let (t0, r0) = error(&first, &second);
    assert!(t0 > 0.03 && r0 > 1.9);
}

#[test]
fn a_frame_that_sees_none_of_the_model_is_lost_and_tracking_resumes() {
    let first = camera_pose(1.0);
    let behind = moved(&first, DVec3::ZERO, DVec3::Y, 180.0);
    let near = moved(
        &first,
        DVec3::new(0.01, 0.0, 0.01),
        DVec3::new(0.0, 1.0, 0.0),
        1.0,
    );
    let mut tracker = Tracker::new(intrinsics(), TrackParams::default());
    let (c0, d0) = render(&first);
    tracker.track(&c0, &d0, Some(&first), None, None).unwrap();
    let (c1, d1) = render(&behind);
    match tracker.track(&c1, &d1, None, None, None).unwrap() {
        Tracked::Lost(Lost::TooFewInliers { inliers, valid }, _) => {
            assert!(valid > 1000 && inliers * 10 < valid, "{inliers} of {valid}");
        }
        other => panic!("{other:?}"),
    }
    // The next frame near the last good one is tracked against the unchanged model.
    let (c2, d2) = render(&near);
    let Tracked::Pose(got, _) = tracker.track(&c2, &d2, None, None, None).unwrap() else {
        panic!("not resumed");
    };
    let (t, r) = error(&got, &near);
    assert!(t < 1e-3 && r < 0.05, "{t} m, {r} deg");
    assert_eq!((tracker.tracked, tracker.lost), (2, 1));
}

#[test]
fn poses_are_the_same_bits_on_one_and_two_threads() {
    let poses: Vec<Pose> = (0..3).map(|i| camera_pose(1.0 + i as f64 / 30.0)).collect();
    let frames: Vec<_> = poses.iter().map(render).collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut tracker = Tracker::new(intrinsics(), TrackParams::default());
            frames
                .iter()
                .map(
                    |(c, d)| match tracker.track(c, d, Some(&poses[0]), None, None).unwrap() {
                        Tracked::Started(p) | Tracked::Pose(p, _) => p,
                        Tracked::Lost(l, _) => panic!("{l}"),
                    },
                )
                .collect::<Vec<Pose>>()
        })
    };
    let (one, two) = (run(1), run(2));
    assert_eq!(one, two);
    for (got, want) in one.iter().zip(&poses) {
        let (t, r) = error(got, want);
        assert!(t < 2e-3 && r < 0.1, "{t} m, {r} deg");
    }
}

#[test]
fn color_and_depth_of_different_sizes_are_refused() {
    let mut tracker = Tracker::new(intrinsics(), TrackParams::default());
    let color = Image::filled(320, 240, [0u8; 3]);
    let depth = Image::filled(160, 120, 1.0f32);
    let e = tracker.track(&color, &depth, None, None, None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "pose.track: color 320x240 and depth 160x120 differ (depth must be registered to \
         color)"
    );
}

/// The model made from the pipeline's fused depth (`depth.fuse` a frame back, fusing
/// with the tracked poses) is the one the tracker's own fusion makes: the same poses,
/// bit for bit.
#[test]
fn the_pipelines_fused_depth_gives_the_poses_of_the_trackers_own_fusion() {
    let poses: Vec<Pose> = (0..4).map(|i| camera_pose(1.0 + i as f64 / 30.0)).collect();
    let frames: Vec<_> = poses.iter().map(render).collect();
    let pose_of_outcome = |t: Tracked| match t {
        Tracked::Started(p) | Tracked::Pose(p, _) => p,
        Tracked::Lost(l, _) => panic!("{l}"),
    };
    let mut own = Tracker::new(intrinsics(), TrackParams::default());
    let alone: Vec<Pose> = frames
        .iter()
        .map(|(c, d)| pose_of_outcome(own.track(c, d, Some(&poses[0]), None, None).unwrap()))
        .collect();
    let mut tracker = Tracker::new(intrinsics(), TrackParams::default());
    let mut fusion = DepthFusion::new(intrinsics(), FuseParams::default());
    let mut fused_before: Option<DepthImage> = None;
    let mut shared = Vec::new();
    for (c, d) in &frames {
        let outcome = tracker.track(c, d, Some(&poses[0]), None, fused_before.as_ref());
        let pose = pose_of_outcome(outcome.unwrap());
        let (fused, _) = fusion.push(d, &pose).unwrap();
        fused_before = fused.get::<DepthImage>(kind::DEPTH).cloned();
        shared.push(pose);
    }
    assert_eq!(shared, alone);
    // And frame to frame differs: the fused model is in use.
    let frame_params = TrackParams {
        fused_model: false,
        ..TrackParams::default()
    };
    let mut frame_to_frame = Tracker::new(intrinsics(), frame_params);
    let last = frames
        .iter()
        .map(|(c, d)| {
            pose_of_outcome(
                frame_to_frame
                    .track(c, d, Some(&poses[0]), None, None)
                    .unwrap(),
            )
        })
        .last();
    assert_ne!(last.as_ref(), alone.last());
}
