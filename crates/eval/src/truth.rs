//! Per-frame ground truth of synthetic recordings, decoded for scoring.

use glam::{Mat3, Vec3};
use relume_graph::Frame;
use relume_graph::pipeline::SOURCE_PRODUCT;
use relume_recording::codec::decode_floats;

/// A frame's ground truth, decoded: clean depth, camera-space normals, HDR radiance and
/// the camera's color model.
pub struct FrameTruth {
    pub width: u32,
    pub height: u32,
    /// Metres, 0 where nothing is hit.
    pub depth: Vec<f32>,
    /// Camera-space unit normals facing the camera (zero where nothing is hit).
    pub normals: Vec<Vec3>,
    /// Scene radiance (linear RGB) before the camera model.
    pub radiance: Vec<Vec3>,
    /// Camera linear RGB = `color_transform` * radiance, before contrast and gamma.
    pub color_transform: Mat3,
    /// Contrast exponent applied after the linear map.
    pub contrast: f32,
}

impl FrameTruth {
    /// The truth carried by `frame`'s source record, if the recording has any. An error
    /// names the frame when the stored truth cannot be decoded.
    pub fn of(frame: &Frame) -> Result<Option<FrameTruth>, String> {
        let Ok(records) = frame.record(SOURCE_PRODUCT) else {
            return Ok(None);
        };
        let Some(truth) = &records.truth else {
            return Ok(None);
        };
        let fail = |what: &str, e: &dyn std::fmt::Display| {
            format!("frame {}: ground-truth {what}: {e}", frame.index)
        };
        let (width, height) = (truth.depth.width, truth.depth.height);
        let n = width as usize * height as usize;
        let depth = decode_floats(&truth.depth).map_err(|e| fail("depth", &e))?;
        let vec3s = |what: &str, img: &relume_recording::EncodedImage| {
            let floats = decode_floats(img).map_err(|e| fail(what, &e))?;
            if img.width != width || img.height != height || floats.len() != 3 * n {
                return Err(fail(what, &"size differs from the truth depth"));
            }
            Ok(floats
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]))
                .collect::<Vec<_>>())
        };
        if depth.len() != n {
            return Err(fail("depth", &"wrong number of samples"));
        }
        // A score against a NaN is NaN (`null` in JSON): refused here, naming the pixel.
        let at = |i: usize| format!("({}, {})", i % width as usize, i / width as usize);
        if let Some(i) = depth.iter().position(|d| !(d.is_finite() && *d >= 0.0)) {
            let why = format!("pixel {} holds {}, not a distance", at(i), depth[i]);
            return Err(fail("depth", &why));
        }
        let normals = vec3s("normals", &truth.normals)?;
        let radiance = vec3s("radiance", &truth.radiance)?;
        for (what, values) in [("normals", &normals), ("radiance", &radiance)] {
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                let why = format!("pixel {} holds {}, not a finite value", at(i), values[i]);
                return Err(fail(what, &why));
            }
        }
        let transform_finite = truth.color_transform.iter().all(|c| c.is_finite());
        let contrast_positive = truth.contrast.is_finite() && truth.contrast > 0.0;
        if !(transform_finite && contrast_positive) {
            return Err(fail(
                "camera model",
                &"holds a non-finite or non-positive value",
            ));
        }
        Ok(Some(FrameTruth {
            width,
            height,
            depth,
            normals,
            radiance,
            color_transform: Mat3::from_cols_array(&truth.color_transform).transpose(),
            contrast: truth.contrast,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_graph::Product;
    use relume_recording::codec::{encode_floats, encode_png_rgb8};
    use relume_recording::{ColorRecord, FrameRecords, RECORD, TruthRecord};
    use std::sync::Arc;

    /// Frame 3 of a 4x3 recording whose truth has `depth` and `radiance`.
    fn frame_with_truth(depth: &[f32], radiance: &[f32], contrast: f32) -> Frame {
        let color = relume_base::raster::Image::from_vec(4, 3, vec![[9u8; 3]; 12]).unwrap();
        let records = FrameRecords {
            index: 3,
            stamp_ns: 0,
            color: ColorRecord {
                stamp_ns: 0,
                image: encode_png_rgb8(&color).unwrap(),
            },
            depth: None,
            pose: None,
            truth: Some(Box::new(TruthRecord {
                stamp_ns: 0,
                color_transform: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                contrast,
                depth: encode_floats(4, 3, 1, depth, false),
                normals: encode_floats(4, 3, 3, &[0.0; 36], true),
                radiance: encode_floats(4, 3, 3, radiance, false),
            })),
        };
        let mut frame = Frame::new(3, 0);
        frame.insert(SOURCE_PRODUCT, Product::new(RECORD, Arc::new(records)));
        frame
    }

    #[test]
    fn truth_that_is_not_a_number_is_refused_naming_frame_and_pixel() {
        let mut depth = [2.0f32; 12];
        let radiance = [0.5f32; 36];
        let good = FrameTruth::of(&frame_with_truth(&depth, &radiance, 1.0));
        assert_eq!(good.unwrap().unwrap().depth, depth);
        depth[6] = f32::NAN;
        let e = FrameTruth::of(&frame_with_truth(&depth, &radiance, 1.0)).err();
        assert_eq!(
            e.as_deref(),
            Some("frame 3: ground-truth depth: pixel (2, 1) holds NaN, not a distance")
        );
        depth[6] = -1.0;
        let e = FrameTruth::of(&frame_with_truth(&depth, &radiance, 1.0)).err();
        assert_eq!(
            e.as_deref(),
            Some("frame 3: ground-truth depth: pixel (2, 1) holds -1, not a distance")
        );
        let mut radiance = radiance;
        radiance[3 * 11 + 1] = f32::INFINITY;
        let e = FrameTruth::of(&frame_with_truth(&[2.0; 12], &radiance, 1.0)).err();
        assert!(
            e.as_deref().is_some_and(|e| e
                .starts_with("frame 3: ground-truth radiance: pixel (3, 2) holds [0.5, inf, 0.5]")),
            "{e:?}"
        );
        let e = FrameTruth::of(&frame_with_truth(&[2.0; 12], &[0.5; 36], f32::NAN)).err();
        assert_eq!(
            e.as_deref(),
            Some("frame 3: ground-truth camera model: holds a non-finite or non-positive value")
        );
    }
}
