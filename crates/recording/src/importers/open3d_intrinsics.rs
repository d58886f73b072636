//! Open3D's camera intrinsics files, found beside a Redwood-layout folder's images:
//!
//! - `camera_intrinsic.json`, as Open3D's RealSense recorder
//!   (`examples/python/reconstruction_system/sensors/realsense_recorder.py`) and
//!   `o3d.io.write_pinhole_camera_intrinsic` write it: `width`, `height` and
//!   `intrinsic_matrix`, the 3 x 3 matrix column by column
//!   (`[fx, 0, 0, 0, fy, 0, cx, cy, 1]`);
//! - `intrinsic.json`, as Open3D's `RSBagReader.save_frames` writes it beside frames
//!   taken from a RealSense `.bag`: the same keys and more, of which `depth_scale`
//!   (stored depth units per metre) is read too.
//!
//! The intrinsics are those of the color images, to which the depth images are
//! registered (both writers align depth to color).

use super::file_error;
use crate::error::ImportError;
use crate::types::{DEPTH_UNIT_RANGE_M, Intrinsics};
use std::path::{Path, PathBuf};

/// The file names looked for, in this order.
pub const FILE_NAMES: &[&str] = &["camera_intrinsic.json", "intrinsic.json"];

/// The largest intrinsics file read: the files are a few hundred bytes.
const MAX_FILE_BYTES: u64 = 1 << 20;

/// What an Open3D intrinsics file says.
#[derive(Clone, Debug, PartialEq)]
pub struct Open3dIntrinsics {
    pub path: PathBuf,
    pub intrinsics: Intrinsics,
    /// Metres per stored depth unit, where the file gives `depth_scale`.
    pub depth_unit_m: Option<f64>,
}

/// The intrinsics file in `dir`, if there is one (the first of [`FILE_NAMES`]).
pub fn find(dir: &Path) -> Result<Option<Open3dIntrinsics>, ImportError> {
    for name in FILE_NAMES {
        let path = dir.join(name);
        if path.is_file() {
            return read(&path).map(Some);
        }
    }
    Ok(None)
}

/// Reads and checks an intrinsics file.
pub fn read(path: &Path) -> Result<Open3dIntrinsics, ImportError> {
    let io = |source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let size = std::fs::metadata(path).map_err(io)?.len();
    if size > MAX_FILE_BYTES {
        return Err(file_error(
            path,
            format!("is {size} bytes: not a camera intrinsics file (at most {MAX_FILE_BYTES})"),
        ));
    }
    let text = std::fs::read_to_string(path).map_err(io)?;
    parse(&text)
        .map(|(intrinsics, depth_unit_m)| Open3dIntrinsics {
            path: path.to_path_buf(),
            intrinsics,
            depth_unit_m,
        })
        .map_err(|reason| file_error(path, reason))
}

/// The intrinsics and depth unit (metres) an intrinsics file's text gives, or why it
/// gives none.
pub fn parse(text: &str) -> Result<(Intrinsics, Option<f64>), String> {
    let json: serde_json::Value =
        serde_json::from_str(text).map_err(|e| format!("is not JSON: {e}"))?;
    let size = |key: &str| {
        json.get(key)
            .and_then(serde_json::Value::as_u64)
            .and_then(|v| u32::try_from(v).ok())
            .ok_or_else(|| format!("has no `{key}` (the image {key} in pixels)"))
    };
    let (width, height) = (size("width")?, size("height")?);
    let matrix = json
        .get("intrinsic_matrix")
        .and_then(serde_json::Value::as_array)
        .ok_or("has no `intrinsic_matrix` (nine numbers, the 3 x 3 matrix column by column)")?;
    let m: Vec<f64> = matrix
        .iter()
        .filter_map(serde_json::Value::as_f64)
        .collect();
    if matrix.len() != 9 || m.len() != 9 {
        return Err(format!(
            "`intrinsic_matrix` must hold nine numbers (the 3 x 3 matrix column by column), \
             not {}",
            matrix.len()
        ));
    }
    // Column-major: [fx, 0, 0,  skew, fy, 0,  cx, cy, 1].
    let zeros = [
        (1, "row 2 of column 1"),
        (2, "row 3 of column 1"),
        (5, "row 3 of column 2"),
    ];
    for (i, what) in zeros {
        if m[i] != 0.0 {
            return Err(format!(
                "`intrinsic_matrix` has {} in {what}, where a pinhole camera's matrix has 0 \
                 (is it written row by row? Open3D writes it column by column)",
                m[i]
            ));
        }
    }
    if m[3] != 0.0 {
        return Err(format!(
            "`intrinsic_matrix` has a skew of {}: relume's cameras have none",
            m[3]
        ));
    }
    if m[8] != 1.0 {
        return Err(format!("`intrinsic_matrix` ends in {}, not 1", m[8]));
    }
    let intrinsics = Intrinsics {
        width,
        height,
        fx: m[0],
        fy: m[4],
        cx: m[6],
        cy: m[7],
    };
    intrinsics.check()?;
    let depth_unit_m = match json.get("depth_scale") {
        None => None,
        Some(v) => {
            let scale = v
                .as_f64()
                .ok_or_else(|| format!("`depth_scale` is {v}, not a number"))?;
            let unit = 1.0 / scale;
            let (lo, hi) = DEPTH_UNIT_RANGE_M;
            if !(scale.is_finite() && scale > 0.0 && (lo..=hi).contains(&unit)) {
                return Err(format!(
                    "`depth_scale` = {scale} is not a count of depth units per metre from \
                     {} to {}",
                    1.0 / hi,
                    1.0 / lo
                ));
            }
            Some(unit)
        }
    };
    Ok((intrinsics, depth_unit_m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_realsense_recorders_file_gives_its_camera() {
        let text = r#"{
    "width": 640,
    "height": 480,
    "intrinsic_matrix": [
        616.3648681640625, 0, 0, 0, 616.5162353515625, 0, 318.2539367675781,
        244.2213592529297, 1
    ]
}"#;
        let (k, unit) = parse(text).unwrap();
        assert_eq!(
            k,
            Intrinsics {
                width: 640,
                height: 480,
                fx: 616.3648681640625,
                fy: 616.5162353515625,
                cx: 318.2539367675781,
                cy: 244.2213592529297,
            }
        );
        assert_eq!(unit, None);
    }

    #[test]
    fn the_bag_readers_file_gives_its_depth_unit() {
        let text = r#"{"color_channels": 3, "color_format": "RGB8", "depth_format": "Z16",
            "depth_scale": 4000.0, "device_name": "Intel RealSense L515", "fps": 30.0,
            "height": 540, "width": 960, "serial_number": "f0000000",
            "stream_length_usec": 5000000,
            "intrinsic_matrix": [689.0, 0.0, 0.0, 0.0, 689.2, 0.0, 480.5, 270.0, 1.0]}"#;
        let (k, unit) = parse(text).unwrap();
        assert_eq!((k.width, k.height, k.fx, k.cy), (960, 540, 689.0, 270.0));
        assert_eq!(unit, Some(0.00025));
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        let with = |matrix: &str, extra: &str| {
            parse(&format!(
                r#"{{"width": 640, "height": 480, "intrinsic_matrix": {matrix}{extra}}}"#
            ))
            .unwrap_err()
        };
        let k = "[525, 0, 0, 0, 525, 0, 319.5, 239.5, 1]";
        assert_eq!(
            with("[525, 0, 319.5, 0, 525, 239.5, 0, 0, 1]", ""),
            "`intrinsic_matrix` has 319.5 in row 3 of column 1, where a pinhole camera's \
             matrix has 0 (is it written row by row? Open3D writes it column by column)"
        );
        assert_eq!(
            with("[525, 0, 0, 0, 525]", ""),
            "`intrinsic_matrix` must hold nine numbers (the 3 x 3 matrix column by column), \
             not 5"
        );
        assert_eq!(
            with(k, r#", "depth_scale": 0"#),
            "`depth_scale` = 0 is not a count of depth units per metre from 0.1 to 1000000"
        );
        assert_eq!(
            with("[0.525, 0, 0, 0, 0.525, 0, 319.5, 239.5, 1]", ""),
            "fx = 0.525 px is not a focal length for a 640x480 image: it must lie between \
             0.05 and 100 times the image's larger side (32 to 64000 px)"
        );
        assert_eq!(
            parse(r#"{"height": 480, "intrinsic_matrix": [1]}"#).unwrap_err(),
            "has no `width` (the image width in pixels)"
        );
        assert!(parse("not json").unwrap_err().starts_with("is not JSON: "));
    }
}
