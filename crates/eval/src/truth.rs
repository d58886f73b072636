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
        Ok(Some(FrameTruth {
            width,
            height,
            depth,
            normals: vec3s("normals", &truth.normals)?,
            radiance: vec3s("radiance", &truth.radiance)?,
            color_transform: Mat3::from_cols_array(&truth.color_transform).transpose(),
            contrast: truth.contrast,
        }))
    }
}
