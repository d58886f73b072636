//! Importer of Azure Kinect recordings (`k4arecorder`, the SDK's `k4a_record_*`, Open3D's
//! and pyk4a's recorders; Orbbec's Kinect-compatible cameras write the same): Matroska
//! ([`crate::matroska`]) with
//!
//! ```text
//! track COLOR   V_MS/VFW/FOURCC, its BITMAPINFOHEADER's FourCC MJPG (or BGRA; NV12 and
//!               YUY2 are named and not read), one of the color resolutions (720P ...)
//! track DEPTH   V_MS/VFW/FOURCC b16g: big-endian 16-bit millimetres, in the depth
//!               camera's own geometry (640x576 in NFOV_UNBINNED ...)
//! track IR, IMU not read (named in the listing)
//! attachment    calibration.json: both cameras' intrinsics, lens distortion, extrinsics
//! tags          K4A_DEPTH_MODE, K4A_START_OFFSET_NS, K4A_COLOR_TRACK / K4A_DEPTH_TRACK ...
//! ```
//!
//! ffmpeg writes the same tracks as V_MJPEG and as V_UNCOMPRESSED with ColourSpace b16g;
//! both are read. No poses: a recording without them replays through the tracked
//! pipelines (`pipelines/*-tracked.toml`).
//!
//! - Color keeps its JPEG bytes (`--store raw` stores the pixels); BGRA is stored as RGB.
//! - Depth is registered to the color camera ([`crate::register`]) with the calibration's
//!   extrinsic and both lenses' distortion: each depth pixel's ray undistorted, its point
//!   projected through the color lens onto the color image's own pixels. Stored in
//!   millimetres, as recorded. The stages take the color camera as a pinhole (fx, fy,
//!   cx, cy) as they do every recording's; the import warns how far the color lens bends
//!   rays at the image's corners.
//! - Stamps: the device's (a block's time plus K4A_START_OFFSET_NS), as the SDK's playback
//!   gives them.

pub mod calibration;

use super::{ImportOptions, ImportSummary, StoreMode, import_header, stored_color};
use crate::codec::{self, wrap_image_file};
use crate::error::ImportError;
use crate::matroska::{Block, Matroska, Track};
use crate::register::{Registration, Scratch, register_depth};
use crate::types::{ColorRecord, DepthRecord, EncodedImage, ImageEncoding, Record, StreamKind};
use crate::writer::RecordingWriter;
use calibration::Calibration;
use relume_base::pinhole::Intrinsics;
use std::fmt::Write as _;
use std::path::Path;

/// Depth is recorded in millimetres.
pub const DEPTH_UNIT_M: f64 = 0.001;

/// Options of `relume import k4a`.
#[derive(Clone, Debug, Default)]
pub struct K4aOptions {
    pub common: ImportOptions,
    /// The color track by name or number (default: the one named COLOR).
    pub color_track: Option<String>,
    /// The depth track by name or number (default: the one named DEPTH).
    pub depth_track: Option<String>,
}

/// What a video track's frames hold.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Format {
    Mjpg,
    Bgra,
    Depth16,
    /// Named, not read.
    Other(String),
}

impl Format {
    fn of(track: &Track) -> Format {
        let fourcc = match track.codec_id.as_str() {
            "V_MJPEG" => return Format::Mjpg,
            // BITMAPINFOHEADER: biCompression at byte 16.
            "V_MS/VFW/FOURCC" if track.codec_private.len() >= 40 => {
                track.codec_private[16..20].to_vec()
            }
            "V_UNCOMPRESSED" => track.colour_space.clone(),
            other => return Format::Other(format!("codec {other}")),
        };
        match fourcc.as_slice() {
            b"MJPG" => Format::Mjpg,
            b"BGRA" => Format::Bgra,
            b"b16g" => Format::Depth16,
            other => Format::Other(format!(
                "{} {}",
                track.codec_id,
                String::from_utf8_lossy(other).escape_debug()
            )),
        }
    }

    fn name(&self) -> String {
        match self {
            Format::Mjpg => "MJPG color".into(),
            Format::Bgra => "BGRA color".into(),
            Format::Depth16 => "b16g depth (16-bit mm)".into(),
            Format::Other(what) => format!("{what} (not read)"),
        }
    }
}

/// The value of the tag `name` in the file.
fn tag<'a>(mkv: &'a Matroska, name: &str) -> Option<&'a str> {
    mkv.tags
        .iter()
        .find(|t| t.name == name)
        .map(|t| t.value.as_str())
}

/// The track `given` names (a name or a number), else the one named `name` or that the
/// tag `tag_name` gives by UID.
fn find_track<'a>(
    mkv: &'a Matroska,
    given: Option<&str>,
    name: &str,
    tag_name: &str,
) -> Result<&'a Track, String> {
    let tracks = || {
        mkv.tracks
            .iter()
            .map(|t| format!("{} {:?}", t.number, t.name))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some(given) = given {
        return mkv
            .tracks
            .iter()
            .find(|t| t.name == given || t.number.to_string() == given)
            .ok_or_else(|| format!("no track {given:?}; the file has {}", tracks()));
    }
    let by_tag = tag(mkv, tag_name).and_then(|uid| uid.trim().parse::<u64>().ok());
    mkv.tracks
        .iter()
        .find(|t| t.name == name)
        .or_else(|| by_tag.and_then(|uid| mkv.tracks.iter().find(|t| t.uid == uid)))
        .ok_or_else(|| {
            format!(
                "no track named {name}: not an Azure Kinect recording? The file has {} \
                 (choose with --{}-track)",
                tracks(),
                name.to_lowercase()
            )
        })
}

/// The calibration attachment: the one the K4A_CALIBRATION_FILE tag names, else
/// `calibration.json`.
fn calibration_json(mkv: &Matroska) -> Option<&[u8]> {
    let name = tag(mkv, "K4A_CALIBRATION_FILE").unwrap_or("calibration.json");
    mkv.attachments
        .iter()
        .find(|a| a.name == name)
        .or_else(|| {
            mkv.attachments
                .iter()
                .find(|a| a.name == "calibration.json")
        })
        .map(|a| a.data.as_slice())
}

/// `relume import k4a --list`: the tracks, attachments and tags, and what an import takes.
pub fn listing(path: &Path) -> Result<String, ImportError> {
    let mkv = Matroska::open(path)?;
    let counts = mkv.blocks_per_track();
    let mut out = String::new();
    let _ = writeln!(out, "{} ({})", path.display(), mkv.doc_type);
    let _ = writeln!(out, "tracks:");
    for t in &mkv.tracks {
        let what = match t.kind {
            // k4arecorder's infrared track is b16g too: brightness, not depth.
            1 if t.name == "IR" => format!("{}x{} infrared (not read)", t.width, t.height),
            1 => format!("{}x{} {}", t.width, t.height, Format::of(t).name()),
            _ => format!("type {} {} (not read)", t.kind, t.codec_id),
        };
        let _ = writeln!(
            out,
            "  {:>2} {:<8} {:>6} blocks  {what}{}",
            t.number,
            t.name,
            counts.get(&t.number).copied().unwrap_or(0),
            if t.encoded {
                ", compressed (not read)"
            } else {
                ""
            }
        );
    }
    if !mkv.attachments.is_empty() {
        let _ = writeln!(out, "attachments:");
        for a in &mkv.attachments {
            let _ = writeln!(out, "  {} ({}, {} bytes)", a.name, a.mime, a.data.len());
        }
    }
    if !mkv.tags.is_empty() {
        let _ = writeln!(out, "tags:");
        for t in &mkv.tags {
            let _ = writeln!(out, "  {} = {}", t.name, t.value);
        }
    }
    match Setup::of(&mkv, &K4aOptions::default()) {
        Ok(setup) => {
            let _ = writeln!(out, "imports: {}", setup.describe());
        }
        Err(e) => {
            let _ = writeln!(out, "cannot import as it is: {e}");
        }
    }
    if let Some(cut) = &mkv.cut {
        let _ = writeln!(out, "warning: {cut}");
    }
    Ok(out)
}

/// The tracks and cameras an import takes.
struct Setup {
    color_track: u64,
    color_format: Format,
    depth_track: u64,
    depth_size: (u32, u32),
    depth_mode: &'static str,
    color_mode: &'static str,
    registration: Registration,
    start_offset_ns: i64,
}

impl Setup {
    fn of(mkv: &Matroska, options: &K4aOptions) -> Result<Setup, String> {
        let color = find_track(
            mkv,
            options.color_track.as_deref(),
            "COLOR",
            "K4A_COLOR_TRACK",
        )?;
        let depth = find_track(
            mkv,
            options.depth_track.as_deref(),
            "DEPTH",
            "K4A_DEPTH_TRACK",
        )?;
        for (track, role) in [(color, "color"), (depth, "depth")] {
            if track.kind != 1 {
                return Err(format!(
                    "the {role} track {} is not a video track",
                    track.number
                ));
            }
            if track.encoded {
                return Err(format!(
                    "the {role} track {} is compressed (ContentEncoding): not read",
                    track.number
                ));
            }
        }
        let color_format = Format::of(color);
        if !matches!(color_format, Format::Mjpg | Format::Bgra) {
            return Err(format!(
                "the color track {} holds {}: relume reads MJPG and BGRA color",
                color.number,
                color_format.name()
            ));
        }
        let depth_format = Format::of(depth);
        if depth_format != Format::Depth16 {
            return Err(format!(
                "the depth track {} holds {}: relume reads b16g depth",
                depth.number,
                depth_format.name()
            ));
        }
        let json = calibration_json(mkv).ok_or_else(|| {
            "no calibration.json attachment: depth cannot be registered to color without \
             the cameras' calibration"
                .to_string()
        })?;
        let calibration: Calibration = calibration::parse(json)?;
        let depth_size = (depth.width, depth.height);
        let (depth_mode, depth_geometry) =
            calibration::depth_mode(tag(mkv, "K4A_DEPTH_MODE"), depth_size)?;
        let (color_mode, color_geometry) = calibration::color_mode((color.width, color.height))?;
        if calibration.depth.sensor != (1024, 1024) {
            return Err(format!(
                "calibration.json: the depth sensor is {}x{}, the Azure Kinect's is 1024x1024",
                calibration.depth.sensor.0, calibration.depth.sensor.1
            ));
        }
        let color_camera = calibration.color.as_four_by_three()?;
        let mut registration = Registration::new(
            calibration.depth.in_mode(&depth_geometry),
            color_camera.in_mode(&color_geometry),
            calibration.depth_to_color(),
        );
        registration.depth_lens = Some(calibration.depth.lens);
        registration.color_lens = Some(color_camera.lens);
        let start_offset_ns = match tag(mkv, "K4A_START_OFFSET_NS") {
            Some(v) => v
                .trim()
                .parse::<i64>()
                .map_err(|_| format!("the tag K4A_START_OFFSET_NS holds {v:?}, not a number"))?,
            None => 0,
        };
        Ok(Setup {
            color_track: color.number,
            color_format,
            depth_track: depth.number,
            depth_size,
            depth_mode,
            color_mode,
            registration,
            start_offset_ns,
        })
    }

    fn describe(&self) -> String {
        let c = &self.registration.color;
        format!(
            "color track {} ({}x{} {}, {}), depth track {} ({}x{} {}) registered to it \
             (baseline {:.1} mm)",
            self.color_track,
            c.width,
            c.height,
            self.color_mode,
            self.color_format.name(),
            self.depth_track,
            self.depth_size.0,
            self.depth_size.1,
            self.depth_mode,
            self.registration.depth_to_color.translation.length() * 1e3
        )
    }

    /// How far (pixels) the color lens moves a ray at the image's corners and edge
    /// midpoints: what taking the color camera as a pinhole costs.
    fn color_lens_bend_px(&self) -> f64 {
        let k = &self.registration.color;
        let Some(lens) = &self.registration.color_lens else {
            return 0.0;
        };
        let (w, h) = (k.width as f64 - 1.0, k.height as f64 - 1.0);
        let mut worst: f64 = 0.0;
        for (u, v) in [
            (0.0, 0.0),
            (w, 0.0),
            (0.0, h),
            (w, h),
            (w / 2.0, 0.0),
            (0.0, h / 2.0),
        ] {
            let (xd, yd) = ((u - k.cx) / k.fx, (v - k.cy) / k.fy);
            if let Some((x, y)) = lens.undistort(xd, yd) {
                worst = worst.max(((x - xd) * k.fx).hypot((y - yd) * k.fy));
            }
        }
        worst
    }
}

/// An error naming frame `frame` of `path`.
fn frame_error(
    path: &Path,
    role: &str,
    frame: usize,
    block: &Block,
    reason: String,
) -> ImportError {
    ImportError::File {
        path: path.to_path_buf(),
        reason: format!(
            "{role} frame {frame} (block at byte {}): {reason}",
            block.at
        ),
    }
}

/// Imports the Azure Kinect recording `path` into `out`. `progress` gets (done, total)
/// frames.
pub fn import(
    path: &Path,
    out: &Path,
    options: &K4aOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ImportSummary, ImportError> {
    let mut mkv = Matroska::open(path)?;
    let setup = Setup::of(&mkv, options).map_err(|reason| ImportError::File {
        path: path.to_path_buf(),
        reason,
    })?;
    let color_k = setup.registration.color;
    let mut warnings = vec![format!(
        "{}: an Azure Kinect recording has no poses: track them with \
         pipelines/*-tracked.toml",
        path.display()
    )];
    let bend = setup.color_lens_bend_px();
    if bend >= 0.5 {
        warnings.push(format!(
            "{}: the color lens bends rays by up to {bend:.1} px at the image's edges; \
             relume's stages take the color camera as a pinhole (its fx, fy, cx, cy), and \
             the registered depth lies on the color image's own pixels",
            path.display()
        ));
    }
    if let Some(cut) = &mkv.cut {
        warnings.push(format!("{}: {cut}", path.display()));
    }
    let blocks: Vec<Block> = mkv
        .blocks
        .iter()
        .filter(|b| b.track == setup.color_track || b.track == setup.depth_track)
        .copied()
        .collect();
    let mut header = import_header(
        "k4a",
        path,
        &options.common,
        &[],
        (
            Some((color_k.width, color_k.height)),
            Some((color_k.width, color_k.height)),
        ),
        DEPTH_UNIT_M,
        vec![StreamKind::Color, StreamKind::Depth],
    );
    header.color_intrinsics = color_k;
    header.depth_intrinsics = color_k;
    let settings = &mut header.provenance.settings;
    settings.insert("intrinsics".into(), "file".into());
    settings.insert("registered".into(), setup.describe());
    let mut writer = RecordingWriter::create(out, &header)?;
    let mut scratch = Scratch::default();
    let (mut colors, mut depths) = (0usize, 0usize);
    let (dw, dh) = setup.depth_size;
    for (done, block) in blocks.iter().enumerate() {
        let is_color = block.track == setup.color_track;
        let (role, frame) = match is_color {
            true => ("color", colors),
            false => ("depth", depths),
        };
        let fail = |reason: String| frame_error(path, role, frame, block, reason);
        for (time_ns, bytes) in mkv.frames(block).map_err(fail)? {
            let stamp_ns = time_ns.saturating_add(setup.start_offset_ns);
            if is_color {
                let image = color_image(bytes, &setup.color_format, &color_k, options.common.store)
                    .map_err(fail)?;
                writer.write(&Record::Color(ColorRecord { stamp_ns, image }))?;
                colors += 1;
            } else {
                let expected = dw as usize * dh as usize * 2;
                if bytes.len() != expected {
                    return Err(fail(format!(
                        "{} bytes, not {dw}x{dh} 16-bit depth ({expected})",
                        bytes.len()
                    )));
                }
                let units: Vec<u16> = bytes
                    .chunks_exact(2)
                    .map(|b| u16::from_be_bytes([b[0], b[1]]))
                    .collect();
                let mut registered = Vec::new();
                register_depth(
                    &units,
                    DEPTH_UNIT_M,
                    &setup.registration,
                    &mut registered,
                    &mut scratch,
                )
                .map_err(|e| fail(e.to_string()))?;
                let image = codec::raw_depth(color_k.width, color_k.height, registered);
                writer.write(&Record::Depth(DepthRecord { stamp_ns, image }))?;
                depths += 1;
            }
        }
        progress(done + 1, blocks.len());
    }
    writer.finish()?;
    Ok(ImportSummary {
        color: colors,
        depth: depths,
        poses: 0,
        skipped_frames: 0,
        warnings,
    })
}

/// A color frame as stored: JPEG bytes checked (decoded) or BGRA turned into RGB.
fn color_image(
    bytes: Vec<u8>,
    format: &Format,
    k: &Intrinsics,
    store: StoreMode,
) -> Result<EncodedImage, String> {
    if *format == Format::Bgra {
        let expected = k.width as usize * k.height as usize * 4;
        if bytes.len() != expected {
            return Err(format!(
                "{} bytes, not {}x{} BGRA ({expected})",
                bytes.len(),
                k.width,
                k.height
            ));
        }
        return Ok(EncodedImage {
            encoding: ImageEncoding::RawU8,
            width: k.width,
            height: k.height,
            channels: 3,
            bytes: bytes
                .chunks_exact(4)
                .flat_map(|p| [p[2], p[1], p[0]])
                .collect(),
        });
    }
    let (image, _) = wrap_image_file(bytes).map_err(|e| format!("color: {e}"))?;
    if image.encoding != ImageEncoding::Jpeg {
        return Err("an MJPG frame that is not a JPEG image".into());
    }
    if (image.width, image.height) != (k.width, k.height) {
        return Err(format!(
            "the JPEG is {}x{}, the track {}x{}",
            image.width, image.height, k.width, k.height
        ));
    }
    stored_color(image, store).map_err(|e| format!("color: {e}"))
}
