//! An Azure Kinect's factory calibration (the `calibration.json` a recording carries) in
//! the geometry of the recorded modes, as the Azure Kinect SDK derives it
//! (`src/calibration/calibration.c`, `src/transformation/mode_specific_calibration.c`):
//!
//! - Each camera's `ModelParameters` are cx, cy, fx, fy, k1..k6, codx, cody, p2, p1 and a
//!   metric radius, with cx, cy, fx, fy divided by the full sensor's width and height and
//!   (0, 0) at the top left pixel's corner. A mode crops and bins the sensor: the mode's
//!   principal point is `c * binned size - crop offset - 0.5` (pixel centres), its focal
//!   length `f * binned size`.
//! - Each camera's `Rt` maps the device's frame into the camera's (`X_cam = R X + t`,
//!   rotation row-major, translation in metres); depth to color is
//!   `Rt_color * Rt_depth^-1`.

use crate::lens::{Distortion, TangentialTerms};
use crate::register::Extrinsic;
use glam::{DMat3, DQuat, DVec3};
use relume_base::pinhole::Intrinsics;
use serde::Deserialize;

#[derive(Deserialize)]
struct File {
    #[serde(rename = "CalibrationInformation")]
    information: Information,
}

#[derive(Deserialize)]
struct Information {
    #[serde(rename = "Cameras")]
    cameras: Vec<CameraJson>,
}

#[derive(Deserialize)]
struct CameraJson {
    #[serde(rename = "Intrinsics")]
    intrinsics: IntrinsicsJson,
    #[serde(rename = "Location")]
    location: String,
    #[serde(rename = "MetricRadius", default)]
    metric_radius: f64,
    #[serde(rename = "Rt")]
    rt: RtJson,
    #[serde(rename = "SensorWidth")]
    sensor_width: u32,
    #[serde(rename = "SensorHeight")]
    sensor_height: u32,
}

#[derive(Deserialize)]
struct IntrinsicsJson {
    #[serde(rename = "ModelParameters")]
    parameters: Vec<f64>,
    #[serde(rename = "ModelType")]
    model: String,
}

#[derive(Deserialize)]
struct RtJson {
    #[serde(rename = "Rotation")]
    rotation: [f64; 9],
    #[serde(rename = "Translation")]
    translation: [f64; 3],
}

/// One camera as calibrated: over the whole sensor, normalized.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorCamera {
    pub sensor: (u32, u32),
    /// cx, cy, fx, fy over the sensor's width and height, 0 at the top left corner.
    pub normalized: [f64; 4],
    pub lens: Distortion,
    /// Device frame to camera frame.
    pub device_to_camera: Extrinsic,
}

/// Both cameras of a calibration file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    pub depth: SensorCamera,
    pub color: SensorCamera,
}

/// A mode's crop and binning of the sensor: (binned size, crop offset, output size).
pub type Mode = ((u32, u32), (i32, i32), (u32, u32));

/// The depth modes by their K4A_DEPTH_MODE tag (and the 2x2 modes' legacy spelling).
pub const DEPTH_MODES: [(&str, Mode); 6] = [
    ("NFOV_2X2BINNED", ((512, 512), (96, 90), (320, 288))),
    ("NFOV_2x2BINNED", ((512, 512), (96, 90), (320, 288))),
    ("NFOV_UNBINNED", ((1024, 1024), (192, 180), (640, 576))),
    ("WFOV_2X2BINNED", ((512, 512), (0, 0), (512, 512))),
    ("WFOV_2x2BINNED", ((512, 512), (0, 0), (512, 512))),
    ("WFOV_UNBINNED", ((1024, 1024), (0, 0), (1024, 1024))),
];

/// The color resolutions, told apart by their size.
pub const COLOR_MODES: [(&str, Mode); 6] = [
    ("720P", ((1280, 960), (0, 120), (1280, 720))),
    ("1080P", ((1920, 1440), (0, 180), (1920, 1080))),
    ("1440P", ((2560, 1920), (0, 240), (2560, 1440))),
    ("1536P", ((2048, 1536), (0, 0), (2048, 1536))),
    ("2160P", ((3840, 2880), (0, 360), (3840, 2160))),
    ("3072P", ((4096, 3072), (0, 0), (4096, 3072))),
];

/// Reads a `calibration.json`.
pub fn parse(json: &[u8]) -> Result<Calibration, String> {
    let file: File = serde_json::from_slice(json).map_err(|e| format!("calibration.json: {e}"))?;
    let find = |location: &str| -> Result<SensorCamera, String> {
        let camera = file
            .information
            .cameras
            .iter()
            .find(|c| c.location == location)
            .ok_or_else(|| format!("calibration.json has no camera at {location}"))?;
        sensor_camera(camera).map_err(|e| format!("calibration.json, camera {location}: {e}"))
    };
    Ok(Calibration {
        depth: find("CALIBRATION_CameraLocationD0")?,
        color: find("CALIBRATION_CameraLocationPV0")?,
    })
}

fn sensor_camera(camera: &CameraJson) -> Result<SensorCamera, String> {
    let tangential = match camera.intrinsics.model.as_str() {
        "CALIBRATION_LensDistortionModelBrownConrady" => TangentialTerms::BrownConrady,
        "CALIBRATION_LensDistortionModelRational6KT" => TangentialTerms::Rational6kt,
        other => {
            return Err(format!(
                "the lens model {other} is not read (Brown-Conrady and Rational 6KT are)"
            ));
        }
    };
    let p = &camera.intrinsics.parameters;
    if p.len() < 14 || p.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "{} model parameters ({} finite numbers are needed)",
            p.len(),
            14
        ));
    }
    if !(p[2] > 0.0 && p[3] > 0.0) {
        return Err(format!(
            "focal lengths fx {} and fy {} must be positive",
            p[2], p[3]
        ));
    }
    let (w, h) = (camera.sensor_width, camera.sensor_height);
    if !(1..=16384).contains(&w) || !(1..=16384).contains(&h) {
        return Err(format!("a sensor of {w}x{h}"));
    }
    let rotation = DMat3::from_cols_array(&camera.rt.rotation).transpose();
    let translation = DVec3::from_array(camera.rt.translation);
    let orthonormal = (rotation * rotation.transpose() - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .all(|v| v.abs() < 1e-4)
        && (rotation.determinant() - 1.0).abs() < 1e-4;
    if !(orthonormal && translation.is_finite() && translation.length() < 10.0) {
        return Err(format!(
            "Rt {:?} / {:?} is not a rigid transform",
            camera.rt.rotation, camera.rt.translation
        ));
    }
    Ok(SensorCamera {
        sensor: (w, h),
        normalized: [p[0], p[1], p[2], p[3]],
        lens: Distortion {
            k: [p[4], p[5], p[6], p[7], p[8], p[9]],
            p: [p[13], p[12]],
            centre: [p[10], p[11]],
            // 0: the calibration did not estimate it; the SDK's default is about 120
            // degrees of field.
            metric_radius: if camera.metric_radius > 1e-4 {
                camera.metric_radius
            } else {
                1.7
            },
            tangential,
        },
        device_to_camera: Extrinsic {
            rotation: DQuat::from_mat3(&rotation).normalize(),
            translation,
        },
    })
}

impl SensorCamera {
    /// The pinhole part of this camera in `mode`'s pixels (centres at integers).
    pub fn in_mode(&self, mode: &Mode) -> Intrinsics {
        let ((bw, bh), (ox, oy), (w, h)) = *mode;
        let [cx, cy, fx, fy] = self.normalized;
        Intrinsics {
            width: w,
            height: h,
            fx: fx * bw as f64,
            fy: fy * bh as f64,
            cx: cx * bw as f64 - ox as f64 - 0.5,
            cy: cy * bh as f64 - oy as f64 - 0.5,
        }
    }

    /// A color camera calibrated at 16:9 (early firmware) turned into the 4:3 sensor the
    /// modes crop, as the SDK does; a 4:3 one as it is.
    pub fn as_four_by_three(&self) -> Result<SensorCamera, String> {
        let (w, h) = self.sensor;
        if w * 3 / 4 == h {
            return Ok(*self);
        }
        if w * 9 / 16 != h {
            return Err(format!("a color sensor of {w}x{h} is neither 4:3 nor 16:9"));
        }
        // Normalized over 4096x2304, 384 rows taken off the top of 4096x3072.
        let [cx, cy, fx, fy] = self.normalized;
        Ok(SensorCamera {
            sensor: (4096, 3072),
            normalized: [cx, (cy * 2304.0 + 384.0) / 3072.0, fx, fy * 2304.0 / 3072.0],
            ..*self
        })
    }
}

impl Calibration {
    /// Depth camera to color camera.
    pub fn depth_to_color(&self) -> Extrinsic {
        self.color
            .device_to_camera
            .after(&self.depth.device_to_camera.inverse())
    }
}

/// The mode of a depth mode tag, or of a depth image size when there is no tag.
pub fn depth_mode(tag: Option<&str>, size: (u32, u32)) -> Result<(&'static str, Mode), String> {
    match tag {
        Some(tag) => {
            let (name, mode) = DEPTH_MODES
                .iter()
                .find(|(name, _)| *name == tag)
                .ok_or_else(|| format!("the depth mode {tag:?} is not one with depth"))?;
            if mode.2 != size {
                return Err(format!(
                    "the depth mode {tag} gives {}x{} images, the depth track holds {}x{}",
                    mode.2.0, mode.2.1, size.0, size.1
                ));
            }
            Ok((name, *mode))
        }
        None => DEPTH_MODES
            .iter()
            .find(|(_, mode)| mode.2 == size)
            .map(|(name, mode)| (*name, *mode))
            .ok_or_else(|| format!("no depth mode gives {}x{} images", size.0, size.1)),
    }
}

/// The color mode of a color image size.
pub fn color_mode(size: (u32, u32)) -> Result<(&'static str, Mode), String> {
    COLOR_MODES
        .iter()
        .find(|(_, mode)| mode.2 == size)
        .map(|(name, mode)| (*name, *mode))
        .ok_or_else(|| {
            format!(
                "a color size of {}x{} is none of the Azure Kinect's resolutions (720P, \
                 1080P, 1440P, 1536P, 2160P, 3072P)",
                size.0, size.1
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mode_intrinsics_follow_the_sdk() {
        // The SDK: cx = 0.5 * 1024 - 192 - 0.5 = 319.5 for NFOV unbinned.
        let camera = SensorCamera {
            sensor: (1024, 1024),
            normalized: [0.5, 0.5, 0.5, 0.5],
            lens: Distortion {
                k: [0.0; 6],
                p: [0.0; 2],
                centre: [0.0; 2],
                metric_radius: 1.7,
                tangential: TangentialTerms::BrownConrady,
            },
            device_to_camera: Extrinsic::IDENTITY,
        };
        let (_, mode) = depth_mode(Some("NFOV_UNBINNED"), (640, 576)).unwrap();
        let k = camera.in_mode(&mode);
        assert_eq!((k.cx, k.cy, k.fx, k.fy), (319.5, 331.5, 512.0, 512.0));
        assert!(depth_mode(Some("NFOV_UNBINNED"), (320, 288)).is_err());
        assert_eq!(depth_mode(None, (320, 288)).unwrap().0, "NFOV_2X2BINNED");
        // A 16:9 color calibration: the same pixel in 720P either way.
        let wide = SensorCamera {
            sensor: (4096, 2304),
            normalized: [0.5, 0.5, 0.5, 0.9],
            ..camera
        };
        let (_, mode) = color_mode((1280, 720)).unwrap();
        let k = wide.as_four_by_three().unwrap().in_mode(&mode);
        // Over 1280x720 (a 16:9 crop of the same sensor): cy = 0.5 * 720 - 0.5.
        assert!((k.cy - 359.5).abs() < 1e-9 && (k.fy - 0.9 * 720.0).abs() < 1e-9);
        assert!(color_mode((1280, 960)).is_err());
    }
}
