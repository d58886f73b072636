use super::*;
use crate::cloud::{CloudBuilder, CloudParams, FrameView};
use crate::compensate::Compensation;
use crate::kind;
use glam::{DQuat, DVec3, Vec3};
use relume_base::raster::Image;
use relume_graph::{BuildContext, Params};
use relume_recording::{Header, Intrinsics, Pose};
use std::collections::BTreeMap;
use std::sync::Arc;

const W: u32 = 160;
const H: u32 = 120;

fn intrinsics() -> Intrinsics {
    Intrinsics::PRIMESENSE.scaled_to(W, H)
}

/// The stage as a pipeline builds it, from its defaults with `cloud` bound to `cloud`.
fn stage(params: Params) -> Box<dyn Stage> {
    let header = Header::new("t", intrinsics(), 0.001);
    let inputs = BTreeMap::from([("cloud".to_string(), "cloud".to_string())]);
    let ctx = BuildContext {
        stage_name: "gbuffer",
        params: &params,
        inputs: &inputs,
        outputs: &BTreeMap::new(),
        header: &header,
        out_dir: std::path::Path::new("."),
        seed: 1,
        world: &crate::world::world_of(relume_scene::objects::VirtualScene::default()),
    };
    (INFO.build)(&ctx).unwrap()
}

fn frame_with(pose: Pose, cloud: Option<EnvCloud>) -> Frame {
    let mut f = Frame::new(3, 0);
    f.insert("pose", Product::new(kind::POSE, pose));
    if let Some(c) = cloud {
        f.insert("cloud", Product::new(kind::CLOUD, Arc::new(c)));
    }
    f
}

fn assert_all_invalid(f: &Frame) {
    assert!(
        f.radiance("reference")
            .unwrap()
            .data
            .iter()
            .all(|c| c.is_nan())
    );
    assert!(
        f.depth("reference_depth")
            .unwrap()
            .data
            .iter()
            .all(|&d| d == 0.0)
    );
    let normals = f.normals("reference_normals").unwrap();
    assert!(normals.data.iter().all(|&n| n == Vec3::ZERO));
    let coverage = f.labels("reference_coverage").unwrap();
    assert!(coverage.data.iter().all(|&c| c == COVERAGE_NONE));
    assert_eq!((coverage.width, coverage.height), (W, H));
}

#[test]
fn absent_and_empty_clouds_give_empty_outputs() {
    let mut s = stage(Params::defaults(PARAMS));
    let mut f = frame_with(Pose::IDENTITY, None);
    s.process(&mut f).unwrap();
    assert_all_invalid(&f);
    let mut f = frame_with(Pose::IDENTITY, Some(EnvCloud::default()));
    s.process(&mut f).unwrap();
    assert_all_invalid(&f);
    let mut wrong = frame_with(Pose::IDENTITY, None);
    wrong.insert("cloud", Product::new(kind::POSE, Pose::IDENTITY));
    assert!(matches!(
        s.process(&mut wrong),
        Err(StageError::WrongKind { .. })
    ));
}

#[test]
fn the_default_binding_reads_the_previous_frames_cloud() {
    let ports = (INFO.ports)(&Params::defaults(PARAMS));
    assert_eq!(ports.inputs[0].default_product, "cloud@prev");
}

/// A wall at 2 m seen by the camera at `pose`, captured by `cloud.samples` with its
/// defaults (step 4, 5 cm cells), then splatted by this stage from the same pose: the
/// G-buffer reproduces the wall's depth and normal over the whole image.
#[test]
fn a_captured_wall_comes_back_with_its_depth_and_normal() {
    let pose = Pose::from_parts(DVec3::new(0.3, -0.2, 1.0), DQuat::from_rotation_y(-0.3));
    let camera = Pinhole::new(&intrinsics(), W, H);
    let depth = Image::filled(W, H, 2.0f32);
    let normals = Image::filled(W, H, Vec3::NEG_Z);
    let compensated = Image::filled(W, H, Vec3::new(0.2, 0.4, 0.6));
    let color = Image::filled(W, H, [100u8, 120, 140]);
    let compensation = Compensation::initial();
    let mut builder = CloudBuilder::new(1 << 20, 0.05, CloudParams::default(), 9).unwrap();
    for index in 0..4 {
        let view = FrameView {
            index,
            depth: &depth,
            normals: &normals,
            compensated: &compensated,
            color: &color,
            compensation: &compensation,
            pose: &pose,
            camera: &camera,
        };
        builder.update(&view).unwrap();
    }
    let cloud = builder.snapshot();
    assert!(cloud.len() > 1000, "{} samples", cloud.len());
    let mut s = stage(Params::defaults(PARAMS));
    let mut f = frame_with(pose, Some(cloud));
    s.process(&mut f).unwrap();
    let d = f.depth("reference_depth").unwrap();
    let n = f.normals("reference_normals").unwrap();
    let c = f.radiance("reference").unwrap();
    let coverage = f.labels("reference_coverage").unwrap();
    let hits = coverage
        .data
        .iter()
        .filter(|&&c| c == COVERAGE_SPLAT)
        .count();
    assert!(hits as f32 > 0.95 * (W * H) as f32, "{hits} splat hits");
    for i in 0..(W * H) as usize {
        assert_ne!(coverage.data[i], COVERAGE_NONE, "pixel {i} filled");
        assert!((d.data[i] - 2.0).abs() < 1e-4, "pixel {i}: {}", d.data[i]);
        assert!((n.data[i] - Vec3::NEG_Z).length() < 1e-4);
        assert!((c.data[i] - Vec3::new(0.2, 0.4, 0.6)).length() < 1e-6);
    }
}

#[test]
fn without_push_pull_holes_stay_empty() {
    let mut cloud = EnvCloud::default();
    for x in [-0.3f32, 0.3] {
        cloud.positions.push(Vec3::new(x, 0.0, 2.0));
        cloud.colors.push(Vec3::ONE);
        cloud.normals.push(Vec3::NEG_Z);
    }
    let mut params = Params::defaults(PARAMS);
    params.set("push_pull", relume_graph::ParamValue::Bool(false));
    let mut s = stage(params);
    let mut f = frame_with(Pose::IDENTITY, Some(cloud.clone()));
    s.process(&mut f).unwrap();
    let coverage = f.labels("reference_coverage").unwrap();
    assert!(coverage.data.iter().all(|&c| c != COVERAGE_FILLED));
    // Two disks of radius 0.035 * 131.25 / 2 = 2.3 px.
    let hits = coverage
        .data
        .iter()
        .filter(|&&c| c == COVERAGE_SPLAT)
        .count();
    assert!((2 * 13..=2 * 21).contains(&hits), "{hits}");
    // With push-pull, 5 levels reach about 32 px around each disk, not the far corners.
    let mut s = stage(Params::defaults(PARAMS));
    let mut f = frame_with(Pose::IDENTITY, Some(cloud));
    s.process(&mut f).unwrap();
    let coverage = f.labels("reference_coverage").unwrap();
    assert_eq!(coverage.data[(H / 2 * W + W / 2) as usize], COVERAGE_FILLED);
    assert_eq!(coverage.data[0], COVERAGE_NONE);
}
