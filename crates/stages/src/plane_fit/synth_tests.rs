//! Accuracy against the synthetic recording's ground truth: plane-fit normals on raw
//! Kinect-like depth (noise, disparity quantization, holes) against `normals.cross`.

use super::*;
use crate::normals::{CrossParams, cross_normals};
use crate::points::depth_to_points;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_recording::synth::{DEPTH_UNIT_M, SynthConfig, frame_records};
use relume_recording::{Record, codec};

/// One frame of the synthetic room: camera, raw depth, truth normals (zero: no surface),
/// truth depth.
fn synth_frame(
    width: u32,
    height: u32,
    frame: usize,
) -> (Pinhole, DepthImage, Vec<Vec3>, Vec<f32>) {
    let config = SynthConfig {
        frames: 30,
        width,
        height,
        ..SynthConfig::default()
    };
    let records = frame_records(
        &config,
        &relume_recording::synth::interreflection::room(),
        frame,
    )
    .unwrap();
    let (mut depth, mut truth, mut truth_depth) = (None, None, None);
    for record in records {
        match record {
            Record::Depth(d) => depth = Some(codec::decode_depth(&d.image, DEPTH_UNIT_M).unwrap()),
            Record::Truth(t) => {
                truth_depth = Some(codec::decode_floats(&t.depth).unwrap());
                let n = codec::decode_floats(&t.normals).unwrap();
                truth = Some(
                    n.chunks_exact(3)
                        .map(|c| Vec3::new(c[0], c[1], c[2]))
                        .collect(),
                )
            }
            _ => {}
        }
    }
    let camera = Pinhole::new(&config.intrinsics(), width, height);
    (camera, depth.unwrap(), truth.unwrap(), truth_depth.unwrap())
}

/// Mean angle (degrees) to the truth over pixels where `valid` holds, and their count.
fn mean_angle(normals: &Vec3Image, truth: &[Vec3], valid: impl Fn(usize) -> bool) -> (f64, usize) {
    let (mut sum, mut count) = (0.0f64, 0usize);
    for (i, (n, t)) in normals.data.iter().zip(truth).enumerate() {
        if *n != Vec3::ZERO && *t != Vec3::ZERO && valid(i) {
            sum += (n.dot(*t).clamp(-1.0, 1.0) as f64).acos().to_degrees();
            count += 1;
        }
    }
    (sum / count.max(1) as f64, count)
}

struct Comparison {
    cross: f64,
    cross_count: usize,
    plane: f64,
    plane_count: usize,
    /// Both over the pixels where both are valid.
    cross_common: f64,
    plane_common: f64,
    common: usize,
    /// Mean absolute depth error (m) of the raw and the refined depth, over the pixels
    /// where both are valid.
    raw_depth_error: f64,
    refined_depth_error: f64,
    depth_count: usize,
}

fn compare(
    camera: &Pinhole,
    depth: &DepthImage,
    truth: &[Vec3],
    truth_depth: &[f32],
    params: &PlaneFitParams,
) -> Comparison {
    let (w, h) = (depth.width, depth.height);
    let k = Intrinsics {
        width: w,
        height: h,
        fx: camera.fx as f64,
        fy: camera.fy as f64,
        cx: camera.cx as f64,
        cy: camera.cy as f64,
    };
    let mut points = Image::filled(w, h, Vec3::NAN);
    depth_to_points(depth, &k, &mut points).unwrap();
    let mut cross = Image::filled(w, h, Vec3::ZERO);
    cross_normals(&points, &CrossParams::default(), &mut cross).unwrap();
    let mut plane = Image::filled(w, h, Vec3::ZERO);
    let mut refined = Image::filled(w, h, 0.0f32);
    let mut counts = Image::filled(w, h, 0u8);
    let mut codes = Image::filled(w, h, 0u8);
    plane_fit_normals(
        &points,
        camera,
        params,
        &mut plane,
        &mut refined,
        &mut counts,
        &mut codes,
    )
    .unwrap();
    let (cross_mean, cross_count) = mean_angle(&cross, truth, |_| true);
    let (plane_mean, plane_count) = mean_angle(&plane, truth, |_| true);
    let both = |i: usize| cross.data[i] != Vec3::ZERO && plane.data[i] != Vec3::ZERO;
    let (cross_common, common) = mean_angle(&cross, truth, both);
    let (plane_common, _) = mean_angle(&plane, truth, both);
    let (mut raw_error, mut refined_error, mut depth_count) = (0.0f64, 0.0f64, 0usize);
    for ((&raw, &z), &t) in depth.data.iter().zip(&refined.data).zip(truth_depth) {
        if raw > 0.0 && z > 0.0 && t > 0.0 {
            raw_error += (raw - t).abs() as f64;
            refined_error += (z - t).abs() as f64;
            depth_count += 1;
        }
    }
    let depth_mean = |e: f64| e / depth_count.max(1) as f64;
    Comparison {
        cross: cross_mean,
        cross_count,
        plane: plane_mean,
        plane_count,
        cross_common,
        plane_common,
        common,
        raw_depth_error: depth_mean(raw_error),
        refined_depth_error: depth_mean(refined_error),
        depth_count,
    }
}

/// Runs both estimators on frames of a `width` x `height` recording and checks the
/// plane fit against the cross products and the raw depth against the truth.
fn assert_plane_fit_beats_cross(width: u32, height: u32, params: &PlaneFitParams, bound: f64) {
    for frame in [0, 17] {
        let (camera, depth, truth, truth_depth) = synth_frame(width, height, frame);
        let c = compare(&camera, &depth, &truth, &truth_depth, params);
        eprintln!(
            "{width}x{height} frame {frame}: cross {:.2} deg on {} px, plane fit {:.2} deg on {} px; \
             on the {} px of both: cross {:.2}, plane fit {:.2} (ratio {:.3}); depth error \
             raw {:.2} mm, refined {:.2} mm on {} px",
            c.cross,
            c.cross_count,
            c.plane,
            c.plane_count,
            c.common,
            c.cross_common,
            c.plane_common,
            c.plane_common / c.cross_common,
            c.raw_depth_error * 1e3,
            c.refined_depth_error * 1e3,
            c.depth_count,
        );
        // The task's target is 0.7 (30 % lower); `bound` keeps the margin measured.
        assert!(c.plane_common < bound * c.cross_common);
        assert!(c.plane < bound * c.cross);
        // Densification: more pixels with a normal than the raw depth gives cross
        // products, most of the frame.
        assert!(c.plane_count > c.cross_count);
        assert!(c.plane_count as f64 > 0.95 * (width * height) as f64);
        assert!(c.refined_depth_error < 0.7 * c.raw_depth_error);
    }
}

#[test]
fn defaults_beat_cross_products_on_raw_kinect_like_depth_at_640x480() {
    assert_plane_fit_beats_cross(640, 480, &PlaneFitParams::default(), 0.3);
}

#[test]
fn radius_scaled_to_160x120_beats_cross_products_too() {
    // A quarter of the resolution: radius 14 / 4 and every pixel a sample, so that about
    // as many disks overlap as with the defaults at 640x480.
    let params = PlaneFitParams {
        radius: 3.5,
        sample_step: 1,
        ..PlaneFitParams::default()
    };
    assert_plane_fit_beats_cross(160, 120, &params, 0.6);
}
