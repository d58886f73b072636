use super::*;
use crate::compensate::PairCounts;
use glam::{DQuat, DVec3, Mat3};
use relume_base::raster::Image;

const W: u32 = 64;
const H: u32 = 48;

fn camera() -> Pinhole {
    Pinhole::new(&Intrinsics::PRIMESENSE, W, H)
}

/// A view of a fronto-parallel wall at `z` metres with normal -z and color 0.5.
struct Inputs {
    depth: DepthImage,
    normals: Vec3Image,
    compensated: Vec3Image,
    color: Rgb8Image,
    compensation: Compensation,
    pose: Pose,
    camera: Pinhole,
}

impl Inputs {
    fn wall(z: f32) -> Inputs {
        Inputs {
            depth: Image::filled(W, H, z),
            normals: Image::filled(W, H, Vec3::NEG_Z),
            compensated: Image::from_vec(
                W,
                H,
                (0..W * H).map(|i| Vec3::splat(i as f32 / 4096.0)).collect(),
            )
            .unwrap(),
            color: Image::filled(W, H, [128, 128, 128]),
            compensation: Compensation {
                matrix: Mat3::IDENTITY,
                inverse: Mat3::IDENTITY,
                gains: Vec3::ONE,
                approximate: false,
                initial: false,
                pairs: PairCounts::default(),
            },
            pose: Pose::IDENTITY,
            camera: camera(),
        }
    }

    fn view(&self, index: u64) -> FrameView<'_> {
        FrameView {
            index,
            depth: &self.depth,
            normals: &self.normals,
            compensated: &self.compensated,
            color: &self.color,
            compensation: &self.compensation,
            pose: &self.pose,
            camera: &self.camera,
        }
    }
}

fn builder(capacity: usize, step: usize) -> CloudBuilder {
    let params = CloudParams {
        step,
        ..Default::default()
    };
    CloudBuilder::new(capacity, 0.05, params, 7).unwrap()
}

#[test]
fn samples_are_back_projected_into_world_space() {
    let mut inputs = Inputs::wall(2.0);
    let rotation = DQuat::from_rotation_y(0.3) * DQuat::from_rotation_x(-0.2);
    let translation = DVec3::new(0.5, -1.0, 3.0);
    inputs.pose = Pose::from_parts(translation, rotation);
    let mut b = builder(1 << 16, 1);
    let counts = b.update(&inputs.view(0)).unwrap();
    assert_eq!(counts.candidates, (W * H) as usize, "step 1: every pixel");
    let cloud = b.snapshot();
    assert_eq!(cloud.len(), counts.added);
    assert!(
        cloud.len() > 100,
        "a 2.4 x 1.8 m view of the wall spans many cells"
    );
    b.grid().check_invariants();
    let to_camera = inputs.pose.matrix().inverse();
    let normal = (rotation * glam::DVec3::NEG_Z).as_vec3();
    for i in 0..cloud.len() {
        let p = to_camera.transform_point3(cloud.positions[i].as_dvec3());
        assert!((p.z - 2.0).abs() < 1e-5, "on the wall: {p:?}");
        // It is the back-projection of the pixel its color encodes.
        let pixel = (cloud.colors[i].x * 4096.0).round() as u32;
        let (u, v) = (pixel % W, pixel / W);
        let expected = inputs.camera.back_project(u as f32, v as f32, 2.0);
        assert!((p.as_vec3() - expected).length() < 1e-5);
        assert!((cloud.normals[i] - normal).length() < 1e-6);
    }
}

#[test]
fn approximate_frames_add_nothing_but_still_remove() {
    let mut inputs = Inputs::wall(2.0);
    let mut b = builder(1 << 16, 2);
    b.update(&inputs.view(0)).unwrap();
    let before = b.snapshot();
    assert!(!before.is_empty());
    inputs.compensation.approximate = true;
    let counts = b.update(&inputs.view(1)).unwrap();
    assert_eq!(counts, UpdateCounts::default());
    assert_eq!(b.snapshot(), before, "approximate frame: cloud unchanged");
    // The wall moved back to 3 m: everything at 2 m is now in front and goes.
    inputs.depth = Image::filled(W, H, 3.0);
    let counts = b.update(&inputs.view(2)).unwrap();
    assert_eq!(counts.removed, before.len());
    assert_eq!(counts.added, 0);
    assert!(b.snapshot().is_empty());
}

#[test]
fn removal_needs_the_sample_in_front_by_more_than_the_margin() {
    // Margin at depth d: 0.05 + 0.02 d. Samples at 2 m against walls at various depths.
    let cases = [
        (2.0, false),  // on the surface
        (1.9, false),  // behind the current surface
        (2.08, false), // in front by 0.08 < 0.05 + 0.0416
        (2.1, true),   // in front by 0.1 > 0.05 + 0.042
        (5.0, true),
    ];
    for (wall, removed) in cases {
        let mut inputs = Inputs::wall(2.0);
        let mut b = builder(1 << 16, 3);
        b.update(&inputs.view(0)).unwrap();
        let n = b.grid().len();
        inputs.depth = Image::filled(W, H, wall);
        inputs.compensation.approximate = true;
        let counts = b.update(&inputs.view(1)).unwrap();
        let expected = if removed { n } else { 0 };
        assert_eq!(counts.removed, expected, "wall at {wall}");
        b.grid().check_invariants();
    }
}

#[test]
fn removal_ignores_missing_depth_and_samples_outside_the_view() {
    let mut inputs = Inputs::wall(2.0);
    let mut b = builder(1 << 16, 2);
    b.update(&inputs.view(0)).unwrap();
    let n = b.grid().len();
    inputs.compensation.approximate = true;
    // Holes everywhere but the left half, which is far behind.
    inputs.depth = Image::from_vec(
        W,
        H,
        (0..W * H)
            .map(|i| if i % W < W / 2 { 4.0 } else { 0.0 })
            .collect(),
    )
    .unwrap();
    let removed = b.update(&inputs.view(1)).unwrap().removed;
    let left = b
        .snapshot()
        .positions
        .iter()
        .filter(|p| inputs.camera.project(**p).unwrap().x < (W / 2) as f32 - 1.0)
        .count();
    assert!(removed > 0 && removed < n);
    assert_eq!(left, 0, "every sample over valid far depth is gone");
    // Turned around: nothing is in view, nothing is removed.
    inputs.pose = Pose::from_parts(DVec3::ZERO, DQuat::from_rotation_y(std::f64::consts::PI));
    inputs.depth = Image::filled(W, H, 0.5);
    assert_eq!(b.update(&inputs.view(2)).unwrap().removed, 0);
}

#[test]
fn saturated_and_invalid_pixels_add_no_samples() {
    let mut inputs = Inputs::wall(2.0);
    inputs.color.data.iter_mut().for_each(|c| c[1] = 255);
    let mut b = builder(1 << 16, 1);
    assert_eq!(b.update(&inputs.view(0)).unwrap().candidates, 0);
    b.params.skip_saturated = false;
    inputs.depth.data[0] = 0.0;
    inputs.normals.data[1] = Vec3::ZERO;
    inputs.compensated.data[2] = Vec3::NAN;
    let counts = b.update(&inputs.view(1)).unwrap();
    assert_eq!(counts.candidates, (W * H) as usize - 3);
}

#[test]
fn size_mismatch_is_an_error_and_empty_images_are_fine() {
    let mut inputs = Inputs::wall(2.0);
    inputs.normals = Image::filled(W, H - 1, Vec3::NEG_Z);
    let mut b = builder(64, 1);
    assert!(matches!(
        b.update(&inputs.view(0)),
        Err(OpError::SizeMismatch(_))
    ));
    let mut empty = Inputs::wall(2.0);
    empty.depth = Image::filled(0, 0, 0.0);
    empty.normals = Image::filled(0, 0, Vec3::ZERO);
    empty.compensated = Image::filled(0, 0, Vec3::ZERO);
    empty.color = Image::filled(0, 0, [0; 3]);
    empty.camera = Pinhole::new(&Intrinsics::PRIMESENSE, 0, 0);
    assert_eq!(b.update(&empty.view(0)).unwrap(), UpdateCounts::default());
}

#[test]
fn a_tiny_grid_never_exceeds_its_capacity() {
    let mut inputs = Inputs::wall(2.0);
    let mut b = builder(5, 1);
    for frame in 0..4u64 {
        inputs.depth = Image::filled(W, H, 1.0 + frame as f32);
        b.update(&inputs.view(frame)).unwrap();
        assert!(b.grid().len() <= 5);
        b.grid().check_invariants();
    }
}

/// Several frames from a moving camera over a wall with a step, run on 1 and 3 threads.
fn run_sequence() -> EnvCloud {
    let mut inputs = Inputs::wall(2.0);
    for (i, d) in inputs.depth.data.iter_mut().enumerate() {
        *d = if (i as u32 % W) < 20 {
            1.5
        } else {
            2.5 + (i as f32) * 1e-4
        };
    }
    let mut b = builder(1 << 10, 2);
    for frame in 0..6u64 {
        inputs.pose = Pose::from_parts(
            DVec3::new(0.01 * frame as f64, 0.0, -0.05 * frame as f64),
            DQuat::from_rotation_y(0.02 * frame as f64),
        );
        b.update(&inputs.view(frame)).unwrap();
    }
    b.snapshot()
}

#[test]
fn deterministic_for_any_thread_count() {
    let runs: Vec<EnvCloud> = [1, 3]
        .iter()
        .map(|&n| relume_base::threads::with_threads(n, run_sequence))
        .collect();
    assert!(!runs[0].is_empty());
    let bits = |c: &EnvCloud| -> Vec<u32> {
        c.positions
            .iter()
            .chain(&c.colors)
            .chain(&c.normals)
            .flat_map(|v| v.to_array().map(f32::to_bits))
            .collect()
    };
    assert_eq!(bits(&runs[0]), bits(&runs[1]));
    assert_eq!(bits(&runs[0]), bits(&run_sequence()), "and run to run");
}
