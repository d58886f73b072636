//! Importer of Record3D's `.r3d` exports (iPhone and iPad LiDAR or TrueDepth recordings;
//! the layout of record3d issue #93): a ZIP archive of
//!
//! ```text
//! metadata         JSON: w, h (color size), dw, dh (depth size), K (the color camera's
//!                  3x3 matrix, column-major), fps, poses ([qx, qy, qz, qw, px, py, pz]
//!                  per frame, ARKit's camera-to-world), cameraType
//! rgbd/N.jpg       color of frame N (JPEG; some exports PNG: rgbd/N.png)
//! rgbd/N.depth     depth of frame N: LZFSE-compressed little-endian f32 metres, dw x dh
//! rgbd/N.conf      confidence (0, 1, 2), dw x dh: not read
//! ```
//!
//! - Color keeps its JPEG or PNG bytes (`--store raw` stores the pixels).
//! - Depth is the color camera's view at a lower resolution (ARKit's `sceneDepth`): its
//!   intrinsics are K scaled to dw x dh, and it is registered to the color size
//!   ([`crate::register`]: upsampled, edges kept) so that stages see one camera.
//!   Stored in millimetres; 0 (or not finite) is no measurement.
//! - Poses: ARKit's camera looks down -z with y up; relume's optical frame looks down +z
//!   with y down, so each rotation is turned by 180 degrees about the camera's x axis.
//!   World: ARKit's (y up, gravity aligned).
//! - Stamps: frame N at N / fps.
//! - Every entry's size is read from the ZIP's directory and bounded before anything is
//!   read; a depth entry must decompress to exactly dw x dh x 4 bytes.

use super::{ImportOptions, ImportSummary, StoreMode, file_error, import_header, stored_color};
use crate::codec::{self, wrap_image_file};
use crate::error::ImportError;
use crate::register::{Extrinsic, Registration, Scratch, register_depth};
use crate::types::{ColorRecord, DepthRecord, EncodedImage, Pose, PoseRecord, Record, StreamKind};
use crate::writer::RecordingWriter;
use glam::{DQuat, DVec3};
use relume_base::pinhole::Intrinsics;
use serde::Deserialize;
use std::io::Read;
use std::path::Path;

/// Depth is stored in millimetres: ARKit's LiDAR reaches 5 m, far inside 65 m.
pub const DEPTH_UNIT_M: f64 = 0.001;

/// The largest entry read (a 4K JPEG is a few MB; metadata of a long recording tens).
const MAX_ENTRY_BYTES: u64 = 256 << 20;

/// The largest depth map: ARKit's is 256 x 192.
const MAX_DEPTH_PIXELS: u64 = 4096 * 4096;

#[derive(Deserialize)]
#[allow(non_snake_case)]
struct Metadata {
    w: u32,
    h: u32,
    dw: u32,
    dh: u32,
    K: [f64; 9],
    fps: f64,
    #[serde(default)]
    poses: Vec<[f64; 7]>,
}

/// An error naming frame `frame` of `path`.
fn frame_error(path: &Path, frame: usize, reason: String) -> ImportError {
    ImportError::Frame {
        path: path.to_path_buf(),
        frame,
        reason,
    }
}

/// Reads the entry `name` whole, its declared size bounded first.
fn read_entry(
    zip: &mut zip::ZipArchive<std::fs::File>,
    name: &str,
) -> Result<Option<Vec<u8>>, String> {
    let mut entry = match zip.by_name(name) {
        Ok(e) => e,
        Err(zip::result::ZipError::FileNotFound) => return Ok(None),
        Err(e) => return Err(format!("{name}: {e}")),
    };
    let size = entry.size();
    if size > MAX_ENTRY_BYTES {
        return Err(format!(
            "{name} claims {size} bytes, more than an entry's {MAX_ENTRY_BYTES}"
        ));
    }
    let mut bytes = Vec::with_capacity(size as usize);
    entry
        .by_ref()
        .take(size + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("{name}: {e}"))?;
    if bytes.len() as u64 != size {
        return Err(format!(
            "{name} holds {} bytes, its directory says {size}",
            bytes.len()
        ));
    }
    Ok(Some(bytes))
}

/// The camera-to-world pose of ARKit's `[qx, qy, qz, qw, px, py, pz]`, in relume's optical
/// convention (x right, y down, z forward).
pub fn optical_pose(arkit: &[f64; 7]) -> Result<Pose, String> {
    let [qx, qy, qz, qw, px, py, pz] = *arkit;
    let q = DQuat::from_xyzw(qx, qy, qz, qw);
    let t = DVec3::new(px, py, pz);
    let norm = q.length();
    if !(t.is_finite() && (norm - 1.0).abs() < 1e-3) {
        return Err(format!(
            "pose {arkit:?} is not a rigid transform (a unit quaternion and a finite position)"
        ));
    }
    Ok(Pose::from_parts(
        t,
        q.normalize() * DQuat::from_rotation_x(std::f64::consts::PI),
    ))
}

/// Imports the Record3D export `path` into `out`. `progress` gets (done, total) frames.
pub fn import(
    path: &Path,
    out: &Path,
    options: &ImportOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ImportSummary, ImportError> {
    let io = |source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = relume_base::files::open_regular(path).map_err(io)?;
    let mut zip = zip::ZipArchive::new(file)
        .map_err(|e| file_error(path, format!("not a Record3D export (a ZIP archive): {e}")))?;
    let meta_bytes = read_entry(&mut zip, "metadata")
        .map_err(|e| file_error(path, e))?
        .ok_or_else(|| file_error(path, "no `metadata` entry: not a Record3D export".into()))?;
    let meta: Metadata = serde_json::from_slice(&meta_bytes)
        .map_err(|e| file_error(path, format!("metadata: {e}")))?;
    if !(meta.fps.is_finite() && crate::FPS_RANGE.contains(&meta.fps)) {
        return Err(file_error(
            path,
            format!("metadata: fps {} is out of range", meta.fps),
        ));
    }
    if meta.dw == 0 || meta.dh == 0 || meta.dw as u64 * meta.dh as u64 > MAX_DEPTH_PIXELS {
        return Err(file_error(
            path,
            format!(
                "metadata: a depth size of {}x{} is no depth camera's",
                meta.dw, meta.dh
            ),
        ));
    }
    // K is column-major: [fx 0 0; 0 fy 0; cx cy 1] read down the columns.
    let k = &meta.K;
    let color_k = Intrinsics {
        width: meta.w,
        height: meta.h,
        fx: k[0],
        fy: k[4],
        cx: k[6],
        cy: k[7],
    };
    color_k
        .check()
        .map_err(|e| file_error(path, format!("metadata: the camera matrix K = {k:?}: {e}")))?;
    // The same field of view at a lower resolution, pixel centres kept in place.
    let (sx, sy) = (
        meta.dw as f64 / meta.w as f64,
        meta.dh as f64 / meta.h as f64,
    );
    let depth_k = if (meta.dw, meta.dh) == (meta.w, meta.h) {
        color_k
    } else {
        Intrinsics {
            width: meta.dw,
            height: meta.dh,
            fx: color_k.fx * sx,
            fy: color_k.fy * sy,
            cx: (color_k.cx + 0.5) * sx - 0.5,
            cy: (color_k.cy + 0.5) * sy - 0.5,
        }
    };
    let registration = Registration::new(depth_k, color_k, Extrinsic::IDENTITY);
    let frames = (0..)
        .take_while(|n| zip.index_for_name(&format!("rgbd/{n}.depth")).is_some())
        .count();
    if frames == 0 {
        return Err(file_error(path, "no rgbd/0.depth entry: no frames".into()));
    }
    let mut warnings = Vec::new();
    let with_poses = !meta.poses.is_empty();
    if with_poses && meta.poses.len() < frames {
        return Err(file_error(
            path,
            format!(
                "metadata has {} poses for {frames} frames",
                meta.poses.len()
            ),
        ));
    }
    if !with_poses {
        warnings.push(format!(
            "{}: the metadata has no poses: the recording has none (track them with \
             pipelines/*-tracked.toml)",
            path.display()
        ));
    }
    let mut streams = vec![StreamKind::Color, StreamKind::Depth];
    if with_poses {
        streams.push(StreamKind::Pose);
    }
    let mut header = import_header(
        "record3d",
        path,
        options,
        &[("fps", meta.fps.to_string())],
        (Some((meta.w, meta.h)), Some((meta.w, meta.h))),
        DEPTH_UNIT_M,
        streams,
    );
    header.color_intrinsics = color_k;
    header.depth_intrinsics = color_k;
    let settings = &mut header.provenance.settings;
    settings.insert("intrinsics".into(), "file".into());
    settings.insert(
        "registered".into(),
        format!("depth {}x{} to color (the same camera)", meta.dw, meta.dh),
    );
    let mut writer = RecordingWriter::create(out, &header)?;
    let mut scratch = Scratch::default();
    let expected = meta.dw as usize * meta.dh as usize * 4;
    for n in 0..frames {
        let fail = |reason: String| frame_error(path, n, reason);
        let stamp_ns = (n as f64 / meta.fps * 1e9).round() as i64;
        let color_bytes = match read_entry(&mut zip, &format!("rgbd/{n}.jpg")).map_err(fail)? {
            Some(b) => b,
            None => read_entry(&mut zip, &format!("rgbd/{n}.png"))
                .map_err(fail)?
                .ok_or_else(|| fail(format!("no rgbd/{n}.jpg or rgbd/{n}.png")))?,
        };
        let color = color_image(color_bytes, &color_k, options.store).map_err(fail)?;
        let packed = read_entry(&mut zip, &format!("rgbd/{n}.depth"))
            .map_err(fail)?
            .expect("counted above");
        let mut raw = Vec::with_capacity(expected);
        lzfse_rust::LzfseRingDecoder::default()
            .reader_bytes(&packed)
            .take(expected as u64 + 1)
            .read_to_end(&mut raw)
            .map_err(|e| fail(format!("rgbd/{n}.depth does not decompress (LZFSE): {e}")))?;
        if raw.len() != expected {
            return Err(fail(format!(
                "rgbd/{n}.depth decompresses to {}{} bytes, not {}x{} float32 ({expected})",
                if raw.len() > expected {
                    "more than "
                } else {
                    ""
                },
                raw.len().min(expected),
                meta.dw,
                meta.dh
            )));
        }
        let units: Vec<u16> = raw
            .chunks_exact(4)
            .map(|b| {
                codec::depth_units_of(f32::from_le_bytes([b[0], b[1], b[2], b[3]]), DEPTH_UNIT_M)
            })
            .collect();
        let mut registered = Vec::new();
        register_depth(
            &units,
            DEPTH_UNIT_M,
            &registration,
            &mut registered,
            &mut scratch,
        )
        .map_err(|e| fail(e.to_string()))?;
        let depth = codec::raw_depth(meta.w, meta.h, registered);
        writer.write(&Record::Color(ColorRecord {
            stamp_ns,
            image: color,
        }))?;
        writer.write(&Record::Depth(DepthRecord {
            stamp_ns,
            image: depth,
        }))?;
        if with_poses {
            let pose = optical_pose(&meta.poses[n]).map_err(fail)?;
            writer.write(&Record::Pose(PoseRecord { stamp_ns, pose }))?;
        }
        progress(n + 1, frames);
    }
    writer.finish()?;
    Ok(ImportSummary {
        color: frames,
        depth: frames,
        poses: if with_poses { frames } else { 0 },
        skipped_frames: 0,
        warnings,
    })
}

/// A color entry as stored: its file checked by decoding, of the metadata's size.
fn color_image(bytes: Vec<u8>, k: &Intrinsics, store: StoreMode) -> Result<EncodedImage, String> {
    let (image, _) = wrap_image_file(bytes).map_err(|e| format!("color: {e}"))?;
    if (image.width, image.height) != (k.width, k.height) {
        return Err(format!(
            "the color image is {}x{}, the metadata says {}x{}",
            image.width, image.height, k.width, k.height
        ));
    }
    stored_color(image, store).map_err(|e| format!("color: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arkit_poses_turn_into_the_optical_frame() {
        // ARKit's identity camera looks down world -z with y up: in the optical frame
        // its forward (+z) is world -z and its down (+y) is world -y.
        let pose = optical_pose(&[0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 3.0]).unwrap();
        let r = pose.rotation();
        assert!((r * DVec3::Z - DVec3::NEG_Z).length() < 1e-12);
        assert!((r * DVec3::Y - DVec3::NEG_Y).length() < 1e-12);
        assert_eq!(pose.translation(), DVec3::new(1.0, 2.0, 3.0));
        assert!(optical_pose(&[0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0]).is_err());
    }
}
