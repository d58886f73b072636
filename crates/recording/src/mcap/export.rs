//! `relume export mcap`: a recording, and optionally the products a replay saved, as an
//! MCAP file of Foxglove's well-known schemas in JSON (zstd-compressed chunks), which
//! Foxglove and Lichtblick open without a plug-in:
//!
//! | topic | schema | from |
//! |---|---|---|
//! | `/camera/color/image` | `foxglove.CompressedImage` (JPEG/PNG bytes as stored) or `foxglove.RawImage` `rgb8` | color records |
//! | `/camera/color/calibration` | `foxglove.CameraCalibration` | the header's color intrinsics, with each color image |
//! | `/camera/depth/image` | `foxglove.RawImage` `16UC1` (units of the recording's depth unit) | depth records |
//! | `/camera/depth/calibration` | `foxglove.CameraCalibration` | the depth intrinsics |
//! | `/tf` | `foxglove.FrameTransform` `world` -> `camera` | pose records |
//! | `/relume/<product>` | `foxglove.CompressedImage` `png` | `--products DIR`: `DIR/<product>/<frame>.png` |
//! | `/relume/<product>` | `foxglove.PointCloud` (x, y, z, rgb, normal, linear rgb) | `DIR/<product>/<frame>.ply` (the environment cloud) |
//!
//! A metadata record `relume` holds the depth unit (`depth_unit_m`), so that `relume
//! import mcap` reads the depth back exactly; ROS tools read 16UC1 as millimetres.
//! Products of frame k are stamped with the replay's k-th frame stamp.

use super::export_products::write_products;
use super::export_writer::{Out, b64, fail, time};
use super::scan::RELUME_METADATA;
use crate::Recording;
use crate::codec;
use crate::error::ImportError;
use crate::types::{EncodedImage, ImageEncoding, Intrinsics, Record};
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

pub use super::export_writer::{CAMERA_FRAME, WORLD_FRAME};

/// What to export beside the recording.
#[derive(Clone, Debug, Default)]
pub struct ExportOptions {
    /// A folder written by `relume replay --save` (or a pipeline's `write` stage).
    pub products: Option<PathBuf>,
}

/// What an export wrote.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExportSummary {
    pub color: usize,
    pub depth: usize,
    pub poses: usize,
    /// Product files written, by product name.
    pub products: BTreeMap<String, usize>,
    /// Files of the products folder not exported, one sentence each.
    pub warnings: Vec<String>,
}

fn calibration(stamp_ns: i64, k: &Intrinsics) -> Value {
    json!({
        "timestamp": time(stamp_ns), "frame_id": CAMERA_FRAME,
        "width": k.width, "height": k.height, "distortion_model": "plumb_bob",
        "D": [0.0, 0.0, 0.0, 0.0, 0.0],
        "K": [k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
        "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "P": [k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    })
}

fn color_message(stamp_ns: i64, img: &EncodedImage) -> Result<(&'static str, Value), String> {
    Ok(match img.encoding {
        ImageEncoding::Jpeg | ImageEncoding::Png => {
            let format = if img.encoding == ImageEncoding::Jpeg {
                "jpeg"
            } else {
                "png"
            };
            let msg = json!({"timestamp": time(stamp_ns), "frame_id": CAMERA_FRAME, "format": format, "data": b64(&img.bytes)});
            ("foxglove.CompressedImage", msg)
        }
        _ => {
            let rgb = codec::decode_color(img).map_err(|e| e.to_string())?;
            let bytes: Vec<u8> = rgb.data.iter().flatten().copied().collect();
            let msg = json!({"timestamp": time(stamp_ns), "frame_id": CAMERA_FRAME, "width": rgb.width, "height": rgb.height,
                             "encoding": "rgb8", "step": rgb.width * 3, "data": b64(&bytes)});
            ("foxglove.RawImage", msg)
        }
    })
}

fn depth_message(stamp_ns: i64, img: &EncodedImage) -> Result<Value, String> {
    let units = codec::decode_depth_units(img).map_err(|e| e.to_string())?;
    let bytes: Vec<u8> = units.data.iter().flat_map(|u| u.to_le_bytes()).collect();
    Ok(
        json!({"timestamp": time(stamp_ns), "frame_id": CAMERA_FRAME, "width": units.width, "height": units.height,
              "encoding": "16UC1", "step": units.width * 2, "data": b64(&bytes)}),
    )
}

/// Exports `recording` to `out` (written to a temporary file and renamed).
/// `progress` gets (done, total) records.
pub fn export(
    recording: &Path,
    out: &Path,
    options: &ExportOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ExportSummary, ImportError> {
    let rec = Recording::open(recording)?;
    let (target, tmp) = crate::writer::output_paths(out).map_err(|e| fail(out, e.to_string()))?;
    let result = (|| {
        let file = std::fs::File::create(&tmp).map_err(|source| ImportError::Io {
            path: out.to_path_buf(),
            source,
        })?;
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(format!("relume {}", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| fail(out, super::failure::describe(&e)))?;
        let mut o = Out::new(writer, out);
        let summary = write_all(&rec, &mut o, options, progress)?;
        o.writer
            .finish()
            .map_err(|e| fail(out, super::failure::describe(&e)))?;
        drop(o);
        std::fs::rename(&tmp, &target).map_err(|source| ImportError::Io {
            path: out.to_path_buf(),
            source,
        })?;
        Ok(summary)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

fn write_all(
    rec: &Recording,
    o: &mut Out,
    options: &ExportOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ExportSummary, ImportError> {
    let header = rec.header().clone();
    let mut metadata = BTreeMap::new();
    metadata.insert("depth_unit_m".to_string(), header.depth_unit_m.to_string());
    metadata.insert("recording".to_string(), header.name.clone());
    o.writer
        .write_metadata(&mcap::records::Metadata {
            name: RELUME_METADATA.into(),
            metadata,
        })
        .map_err(|e| fail(o.path, e.to_string()))?;
    let mut summary = ExportSummary::default();
    if let Some(damage) = rec.damage() {
        summary.warnings.push(format!(
            "{}: {}; the records before it are exported",
            rec.path().display(),
            damage.reason()
        ));
    }
    let n = rec.index().len();
    for i in 0..n {
        let record = rec.read_record(i)?;
        let at = |e: String| fail(rec.path(), format!("record {i}: {e}"));
        match record {
            Record::Color(c) => {
                let (schema, msg) = color_message(c.stamp_ns, &c.image).map_err(at)?;
                o.write("/camera/color/image", schema, c.stamp_ns, &msg)?;
                let cal = calibration(c.stamp_ns, &header.color_intrinsics);
                o.write(
                    "/camera/color/calibration",
                    "foxglove.CameraCalibration",
                    c.stamp_ns,
                    &cal,
                )?;
                summary.color += 1;
            }
            Record::Depth(d) => {
                let msg = depth_message(d.stamp_ns, &d.image).map_err(at)?;
                o.write("/camera/depth/image", "foxglove.RawImage", d.stamp_ns, &msg)?;
                let cal = calibration(d.stamp_ns, &header.depth_intrinsics);
                o.write(
                    "/camera/depth/calibration",
                    "foxglove.CameraCalibration",
                    d.stamp_ns,
                    &cal,
                )?;
                summary.depth += 1;
            }
            Record::Pose(p) => {
                let [x, y, z] = p.pose.translation;
                let [qx, qy, qz, qw] = p.pose.rotation;
                let msg = json!({"timestamp": time(p.stamp_ns), "parent_frame_id": WORLD_FRAME, "child_frame_id": CAMERA_FRAME,
                                 "translation": {"x": x, "y": y, "z": z}, "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}});
                o.write("/tf", "foxglove.FrameTransform", p.stamp_ns, &msg)?;
                summary.poses += 1;
            }
            Record::Truth(_) => {}
        }
        progress(i + 1, n);
    }
    if let Some(dir) = &options.products {
        write_products(rec, dir, o, &mut summary.products, &mut summary.warnings)?;
    }
    Ok(summary)
}
