//! Importer of ScanNet's `.sens` files (the layout of ScanNet's SensReader,
//! `sensorData.h` / `SensorData.py`), all little-endian:
//!
//! ```text
//! header  version u32 (4), sensor name (u64 length, then its bytes),
//!         intrinsic_color, extrinsic_color, intrinsic_depth, extrinsic_depth
//!           (4x4 f32 each, row-major),
//!         color_compression_type i32 (-1 unknown, 0 raw RGB8, 1 PNG, 2 JPEG),
//!         depth_compression_type i32 (-1 unknown, 0 raw u16, 1 zlib u16, 2 occi),
//!         color_width, color_height, depth_width, depth_height u32,
//!         depth_shift f32 (depth units per metre: 1000 = millimetres), num_frames u64
//! frame   camera_to_world 4x4 f32 (row-major), timestamp_color u64,
//!         timestamp_depth u64 (microseconds, often 0), color_size_bytes u64,
//!         depth_size_bytes u64, then the color bytes and the depth bytes
//! ```
//! IMU data after the frames is ignored.
//!
//! - Intrinsics: fx, fy, cx, cy of each camera's own matrix, for its own image size;
//!   `--intrinsics` replaces both. The extrinsics are not used (a warning says so when
//!   they are not the identity): every frame has one pose for both cameras.
//! - Depth unit: 1 / depth_shift metres. Zlib depth is inflated and stored as PNG (raw
//!   u16 with `--store raw`); raw depth is stored raw. JPEG or PNG color keeps its bytes
//!   (decoded once at import, to check it); `--store raw` stores the pixels.
//! - Stamps: the file's, when every color and every depth stamp is non-zero and each
//!   stream's increase; otherwise frame k (its place in the file) at k / fps, with a
//!   warning unless they are all 0. The provenance setting `stamps` says which.
//! - Frames whose pose is not a rigid transform (ScanNet writes -inf where tracking was
//!   lost) are skipped, color and depth too, and counted in
//!   [`ImportSummary::skipped_frames`]: no frame without a pose is written.
//! - The whole file's framing is read first (frame headers, sizes checked against the
//!   file's length), so a truncated or damaged file is refused before anything is
//!   written and nothing allocates more than the file holds.

use super::{ImportOptions, ImportSummary, StoreMode, file_error, import_header};
use crate::codec::{self, wrap_image_file};
use crate::error::ImportError;
use crate::types::{
    ColorRecord, DepthRecord, EncodedImage, ImageEncoding, PoseRecord, Record, StreamKind,
};
use crate::writer::RecordingWriter;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

mod sens;
pub use sens::{FRAME_HEADER_BYTES, SENS_VERSION, intrinsics_from, rigid_pose};
use sens::{Sens, SensHeader, read_header, scan_frame};

/// Options of the ScanNet importer beyond the common ones.
#[derive(Clone, Debug)]
pub struct ScannetOptions {
    pub common: ImportOptions,
    /// Frames per second used to stamp frame k at k / fps when the file has no stamps.
    pub fps: f64,
    /// Use `common.intrinsics` (the user gave `--intrinsics`) instead of the file's.
    pub override_intrinsics: bool,
}

impl Default for ScannetOptions {
    fn default() -> Self {
        ScannetOptions {
            common: ImportOptions::default(),
            fps: 30.0,
            override_intrinsics: false,
        }
    }
}

fn frame_error(path: &Path, frame: usize, reason: String) -> ImportError {
    ImportError::Frame {
        path: path.to_path_buf(),
        frame,
        reason,
    }
}

/// The stamps (ns) of the written frames: `(color, depth)` of each, and the setting
/// saying which were used. `frames` holds (index in the file, color us, depth us).
/// The file's stamps when every one is non-zero and each stream's increase; else k / fps,
/// with a warning unless every stamp is 0.
pub fn choose_stamps(
    frames: &[(usize, u64, u64)],
    fps: f64,
) -> (Vec<(i64, i64)>, String, Option<String>) {
    let ns = |us: u64| us.checked_mul(1000).and_then(|v| i64::try_from(v).ok());
    let all_zero = frames.iter().all(|&(_, c, d)| c == 0 && d == 0);
    let mut problem = None;
    if !all_zero {
        for (i, &(k, c, d)) in frames.iter().enumerate() {
            let previous = i.checked_sub(1).map(|p| frames[p]);
            let why = if c == 0 || d == 0 {
                Some("a stamp of 0")
            } else if ns(c).is_none() || ns(d).is_none() {
                Some("a stamp past the year 2262")
            } else if previous.is_some_and(|(_, pc, pd)| c <= pc || d <= pd) {
                Some("a stamp no later than the previous frame's")
            } else {
                None
            };
            if let Some(why) = why {
                problem = Some(format!(
                    "frame {k} has {why} (color {c} us, depth {d} us): the file's stamps are \
                     not used; frame k is stamped k / fps ({fps} fps)"
                ));
                break;
            }
        }
    }
    if all_zero || problem.is_some() {
        let stamp = |k: usize| (k as f64 / fps * 1e9).round() as i64;
        let stamps = frames
            .iter()
            .map(|&(k, _, _)| (stamp(k), stamp(k)))
            .collect();
        (stamps, format!("k / fps ({fps})"), problem)
    } else {
        let stamps = frames
            .iter()
            .map(|&(_, c, d)| (ns(c).unwrap_or(0), ns(d).unwrap_or(0)))
            .collect();
        (stamps, "file".into(), None)
    }
}

fn decode_color(bytes: Vec<u8>, h: &SensHeader, store: StoreMode) -> Result<EncodedImage, String> {
    let (w, ht) = (h.color.width, h.color.height);
    if h.color_type == 0 {
        let img = EncodedImage {
            encoding: ImageEncoding::RawU8,
            width: w,
            height: ht,
            channels: 3,
            bytes,
        };
        return Ok(img);
    }
    let (img, bits) = wrap_image_file(bytes).map_err(|e| e.to_string())?;
    if bits != 8 {
        return Err(format!(
            "a color image must have 8-bit samples, found {bits}-bit"
        ));
    }
    if (img.width, img.height) != (w, ht) {
        return Err(format!(
            "the image is {}x{}, but the header says {w}x{ht}",
            img.width, img.height
        ));
    }
    super::stored_color(img, store).map_err(|e| e.to_string())
}

fn decode_depth(bytes: Vec<u8>, h: &SensHeader, store: StoreMode) -> Result<EncodedImage, String> {
    let (w, ht) = (h.depth.width, h.depth.height);
    let raw_len = w as usize * ht as usize * 2;
    let bytes = if h.depth_type == 1 {
        let inflated = miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(&bytes, raw_len)
            .map_err(|e| {
                let why = crate::codec::inflate_failure(&e, raw_len);
                format!("cannot inflate the zlib data: {why}")
            })?;
        if inflated.len() != raw_len {
            return Err(format!(
                "the zlib depth inflates to {} bytes, but {w}x{ht} u16 take {raw_len}",
                inflated.len()
            ));
        }
        inflated
    } else {
        bytes
    };
    if store == StoreMode::Raw || h.depth_type == 0 {
        return Ok(EncodedImage {
            encoding: ImageEncoding::RawU16,
            width: w,
            height: ht,
            channels: 1,
            bytes,
        });
    }
    let units = bytes
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    codec::encode_png_u16(w, ht, units).map_err(|e| e.to_string())
}

/// Imports the ScanNet `.sens` file `path` into `out`. `progress` gets (done, total)
/// frames of the file.
pub fn import(
    path: &Path,
    out: &Path,
    options: &ScannetOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ImportSummary, ImportError> {
    if !crate::FPS_RANGE.contains(&options.fps) {
        return Err(file_error(
            path,
            format!(
                "--fps must be a number from 0.001 to 1e6 (stamps are k / fps in nanoseconds), got {}",
                options.fps
            ),
        ));
    }
    let io = |source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        let why = if meta.is_dir() {
            "is a folder, not a .sens file"
        } else {
            "is not a regular file"
        };
        return Err(file_error(path, why.into()));
    }
    let mut sens = Sens {
        file: BufReader::with_capacity(1 << 20, File::open(path).map_err(io)?),
        len: meta.len(),
        pos: 0,
    };
    let h = read_header(&mut sens).map_err(|e| file_error(path, e))?;
    // First the framing of every frame, so that damage is found before anything is written.
    let mut frames = Vec::with_capacity(h.frames.min(1 << 16) as usize);
    let mut skipped = Vec::new();
    for k in 0..h.frames as usize {
        match scan_frame(&mut sens, k, &h).map_err(|e| frame_error(path, k, e))? {
            Some(f) => frames.push(f),
            None => skipped.push(k),
        }
    }
    if frames.is_empty() {
        return Err(file_error(
            path,
            format!(
                "none of the {} frames has a valid camera pose: nothing to import",
                h.frames
            ),
        ));
    }
    let mut warnings = Vec::new();
    let listed: Vec<(usize, u64, u64)> = frames
        .iter()
        .map(|f| (f.index, f.color_us, f.depth_us))
        .collect();
    let (stamps, stamp_setting, stamp_warning) = choose_stamps(&listed, options.fps);
    warnings.extend(stamp_warning.map(|w| format!("{}: {w}", path.display())));
    if !skipped.is_empty() {
        let shown: Vec<String> = skipped.iter().take(10).map(|k| k.to_string()).collect();
        let more = if skipped.len() > 10 { ", ..." } else { "" };
        warnings.push(format!(
            "{}: {} frame(s) have no valid camera pose (frames {}{more}; ScanNet writes -inf \
             where tracking was lost): they are skipped, color and depth too",
            path.display(),
            skipped.len(),
            shown.join(", ")
        ));
    }
    if !h.identity_extrinsics {
        warnings.push(format!(
            "{}: the header's color or depth extrinsics are not the identity: they are not \
             used (each frame has one pose for both cameras)",
            path.display()
        ));
    }

    let color_size = Some((h.color.width, h.color.height));
    let depth_size = Some((h.depth.width, h.depth.height));
    let mut header = import_header(
        "scannet",
        path,
        &options.common,
        &[
            ("fps", options.fps.to_string()),
            ("stamps", stamp_setting),
            ("sensor", h.sensor.clone()),
        ],
        (color_size, depth_size),
        1.0 / h.depth_shift as f64,
        vec![StreamKind::Color, StreamKind::Depth, StreamKind::Pose],
    );
    if !options.override_intrinsics {
        header.color_intrinsics = h.color;
        header.depth_intrinsics = h.depth;
        let settings = &mut header.provenance.settings;
        settings.insert("intrinsics".into(), "file".into());
    }
    let mut writer = RecordingWriter::create(out, &header)?;
    let store = options.common.store;
    let total = h.frames as usize;
    // The file pairs color k with depth k: both are written at the color stamp, so that
    // replay's nearest-stamp association cannot pair a color image with the depth of a
    // neighbouring frame when the sensor's depth clock is offset by half a frame or more.
    for (f, &(color_ns, _depth_ns)) in frames.iter().zip(&stamps) {
        let k = f.index;
        let mut read = |(offset, len): (u64, u64), what: &str| -> Result<Vec<u8>, ImportError> {
            let mut buf = vec![0; len as usize];
            sens.seek_to(offset, what)
                .and_then(|_| sens.fill(&mut buf, what))
                .map_err(|e| frame_error(path, k, e))?;
            Ok(buf)
        };
        let color_bytes = read(f.color, "color image")?;
        let depth_bytes = read(f.depth, "depth image")?;
        let color = decode_color(color_bytes, &h, store)
            .map_err(|e| frame_error(path, k, format!("color: {e}")))?;
        let depth = decode_depth(depth_bytes, &h, store)
            .map_err(|e| frame_error(path, k, format!("depth: {e}")))?;
        writer.write(&Record::Color(ColorRecord {
            stamp_ns: color_ns,
            image: color,
        }))?;
        writer.write(&Record::Depth(DepthRecord {
            stamp_ns: color_ns,
            image: depth,
        }))?;
        // At the color stamp, where replay builds the frame: its own pose, exactly.
        writer.write(&Record::Pose(PoseRecord {
            stamp_ns: color_ns,
            pose: f.pose,
        }))?;
        progress(k + 1, total);
    }
    writer.finish()?;
    let n = frames.len();
    Ok(ImportSummary {
        color: n,
        depth: n,
        poses: n,
        skipped_frames: skipped.len(),
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn scannet_stamps_come_from_the_file_only_when_usable() {
        // All 0: k / fps, by the frame's place in the file (frame 2 was skipped).
        let (stamps, setting, warning) = choose_stamps(&[(0, 0, 0), (1, 0, 0), (3, 0, 0)], 10.0);
        assert_eq!(
            stamps,
            [
                (0, 0),
                (100_000_000, 100_000_000),
                (300_000_000, 300_000_000)
            ]
        );
        assert_eq!((setting.as_str(), warning), ("k / fps (10)", None));
        let (stamps, setting, warning) = choose_stamps(&[(0, 10, 12), (1, 20, 22)], 10.0);
        assert_eq!(stamps, [(10_000, 12_000), (20_000, 22_000)]);
        assert_eq!((setting.as_str(), warning), ("file", None));
        // Depth stamps missing: not usable.
        let (stamps, _, warning) = choose_stamps(&[(0, 10, 0), (1, 20, 0)], 10.0);
        assert_eq!(stamps[1], (100_000_000, 100_000_000));
        assert!(warning.unwrap().starts_with("frame 0 has a stamp of 0"));
        let (_, _, warning) = choose_stamps(&[(0, 10, 10), (1, 20, 10)], 10.0);
        assert!(warning.unwrap().starts_with("frame 1 has a stamp no later"));
        let (_, _, warning) = choose_stamps(&[(0, u64::MAX, 1)], 10.0);
        assert!(warning.unwrap().contains("past the year 2262"));
    }
}
