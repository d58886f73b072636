//! Importers of common RGB-D dataset layouts into `.relume` recordings.
//!
//! - [`tum`]: the TUM RGB-D benchmark layout (`rgb.txt`, `depth.txt`, `groundtruth.txt`).
//! - [`redwood`]: the Redwood / Open3D layout (`color/` or `image/`, `depth/`, a `.log`
//!   trajectory, Open3D's intrinsics file: [`open3d_intrinsics`]).
//! - [`scannet`]: ScanNet's `.sens` files (one binary file: a header, then per frame a
//!   pose, stamps and the color and depth images).
//!
//! All keep the images' compressed bytes (ScanNet's zlib depth is stored as PNG; all are
//! decoded on replay) unless asked to store raw, check every image's header (format,
//! size, bit depth) at import, and write atomically.

pub mod k4a;
pub mod open3d_intrinsics;
pub mod record3d;
pub mod redwood;
pub mod scannet;
pub mod tum;

use super::codec::{self, wrap_image_file};
use super::error::ImportError;
use super::types::{EncodedImage, Header, Intrinsics, Provenance, StreamKind};
use std::path::Path;

/// Named intrinsics presets for `--intrinsics`.
pub const INTRINSICS_PRESETS: &[(&str, Intrinsics)] = &[
    ("primesense", Intrinsics::PRIMESENSE),
    (
        "tum-fr1",
        Intrinsics {
            width: 640,
            height: 480,
            fx: 517.3,
            fy: 516.5,
            cx: 318.6,
            cy: 255.3,
        },
    ),
    (
        "tum-fr2",
        Intrinsics {
            width: 640,
            height: 480,
            fx: 520.9,
            fy: 521.0,
            cx: 325.1,
            cy: 249.7,
        },
    ),
    (
        "tum-fr3",
        Intrinsics {
            width: 640,
            height: 480,
            fx: 535.4,
            fy: 539.2,
            cx: 320.1,
            cy: 247.6,
        },
    ),
];

/// The camera's intrinsics as `--intrinsics` gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraIntrinsics {
    /// A named preset, for the image size it names; images of another size get it
    /// rescaled (`relume import` prints a note saying so).
    Preset(&'static str, Intrinsics),
    /// fx, fy, cx, cy as the user gave them, in pixels of the images' own size: never
    /// rescaled.
    Given { fx: f64, fy: f64, cx: f64, cy: f64 },
}

impl Default for CameraIntrinsics {
    fn default() -> Self {
        CameraIntrinsics::Preset("primesense", Intrinsics::PRIMESENSE)
    }
}

impl CameraIntrinsics {
    /// The intrinsics of a stream whose images are `size` (`None`: a stream without
    /// images, which takes `other`'s size, or the preset's).
    pub fn for_size(&self, size: Option<ImageSize>, other: Option<ImageSize>) -> Intrinsics {
        match *self {
            CameraIntrinsics::Preset(_, k) => match size {
                Some((w, h)) if (w, h) != (k.width, k.height) => k.scaled_to(w, h),
                _ => k,
            },
            CameraIntrinsics::Given { fx, fy, cx, cy } => {
                let (width, height) = size.or(other).unwrap_or((640, 480));
                Intrinsics {
                    width,
                    height,
                    fx,
                    fy,
                    cx,
                    cy,
                }
            }
        }
    }

    /// As `--intrinsics` takes it: the preset's name, or the four numbers.
    pub fn setting(&self) -> String {
        match self {
            CameraIntrinsics::Preset(name, _) => name.to_string(),
            CameraIntrinsics::Given { fx, fy, cx, cy } => format!("{fx},{fy},{cx},{cy}"),
        }
    }

    /// A note when a preset is rescaled for images of `size`.
    pub fn rescale_note(&self, stream: &str, size: ImageSize) -> Option<String> {
        let CameraIntrinsics::Preset(name, k) = self else {
            return None;
        };
        if size == (k.width, k.height) {
            return None;
        }
        let r = self.for_size(Some(size), None);
        Some(format!(
            "the intrinsics preset `{name}` is for {}x{} images; the {stream} images are \
             {}x{}, so it is rescaled to fx,fy,cx,cy = {},{},{},{} (give --intrinsics \
             fx,fy,cx,cy in pixels of the images' own size to set them exactly)",
            k.width, k.height, size.0, size.1, r.fx, r.fy, r.cx, r.cy
        ))
    }
}

/// Parses `--intrinsics`: a preset name (for the size it names, 640x480 for all of
/// today's) or `fx,fy,cx,cy` (pixels of the images' own size).
pub fn parse_intrinsics(text: &str) -> Result<CameraIntrinsics, String> {
    if let Some((name, k)) = INTRINSICS_PRESETS.iter().find(|(n, _)| *n == text) {
        return Ok(CameraIntrinsics::Preset(name, *k));
    }
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| intrinsics_hint(text))?;
    match values[..] {
        [fx, fy, cx, cy] if values.iter().all(|v| v.is_finite()) && fx > 0.0 && fy > 0.0 => {
            Ok(CameraIntrinsics::Given { fx, fy, cx, cy })
        }
        _ => Err(intrinsics_hint(text)),
    }
}

fn intrinsics_hint(text: &str) -> String {
    let names: Vec<&str> = INTRINSICS_PRESETS.iter().map(|(n, _)| *n).collect();
    format!(
        "invalid intrinsics {text:?}: expected fx,fy,cx,cy (four positive numbers) or one of {}",
        names.join(", ")
    )
}

/// How image bytes are stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum StoreMode {
    /// Keep the PNG/JPEG bytes as found (decoded once at import, to check them); decode
    /// on replay.
    #[default]
    Compressed,
    /// Decode at import and store raw pixels (bigger files, no decoding on replay).
    Raw,
}

/// Options shared by the importers.
#[derive(Clone, Debug)]
pub struct ImportOptions {
    pub intrinsics: CameraIntrinsics,
    pub store: StoreMode,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            intrinsics: CameraIntrinsics::default(),
            store: StoreMode::Compressed,
        }
    }
}

/// What an importer wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImportSummary {
    pub color: usize,
    pub depth: usize,
    pub poses: usize,
    /// Frames found in the source but not imported (ScanNet: lost tracking; MCAP: an
    /// image without a pose on its stamp), counted so that the user sees them.
    pub skipped_frames: usize,
    /// What the importer found odd but imported anyway, one sentence each.
    pub warnings: Vec<String>,
}

/// An error unless `dir`, a dataset folder given by the user, is a directory.
pub(crate) fn check_dataset_dir(dir: &Path) -> Result<(), ImportError> {
    if dir.is_dir() {
        return Ok(());
    }
    let why = if dir.exists() {
        "not a directory"
    } else {
        "no such directory"
    };
    Err(file_error(dir, why.into()))
}

/// Reads an image file and checks it is a color image (8-bit, 1, 3 or 4 channels).
pub(crate) fn read_color(path: &Path, store: StoreMode) -> Result<EncodedImage, ImportError> {
    let (img, bits) = read_image(path)?;
    if bits != 8 {
        return Err(file_error(
            path,
            format!("a color image must have 8-bit samples, found {bits}-bit"),
        ));
    }
    stored_color(img, store).map_err(|e| file_error(path, e.to_string()))
}

/// A color image as `store` keeps it: compressed as found, or as raw pixels. Decoded
/// either way, so that a damaged file (a truncated JPEG or PNG) is refused at import,
/// naming it, rather than stored to fail the replay at its frame.
pub(crate) fn stored_color(
    img: EncodedImage,
    store: StoreMode,
) -> Result<EncodedImage, codec::CodecError> {
    match store {
        StoreMode::Compressed => codec::decode_color(&img).map(|_| img),
        StoreMode::Raw => codec::to_raw_color(&img),
    }
}

/// Reads an image file and checks it is a 16-bit single-channel depth image.
pub(crate) fn read_depth(path: &Path, store: StoreMode) -> Result<EncodedImage, ImportError> {
    let (img, bits) = read_image(path)?;
    if bits != 16 || img.channels != 1 {
        return Err(file_error(
            path,
            format!(
                "a depth image must be a 16-bit single-channel PNG, found {} channel(s) of {bits} bits",
                img.channels
            ),
        ));
    }
    match store {
        StoreMode::Compressed => codec::decode_depth_units(&img).map(|_| img),
        StoreMode::Raw => codec::to_raw_depth(&img),
    }
    .map_err(|e| file_error(path, e.to_string()))
}

fn read_image(path: &Path) -> Result<(EncodedImage, u16), ImportError> {
    let bytes = relume_base::files::read_regular(path).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    wrap_image_file(bytes).map_err(|e| file_error(path, e.to_string()))
}

/// Checks an image has the size of the sensor; the first image of a stream sets it.
pub(crate) fn check_size(
    path: &Path,
    img: &EncodedImage,
    expected: &mut Option<(u32, u32)>,
) -> Result<(), ImportError> {
    match *expected {
        None => {
            *expected = Some((img.width, img.height));
            Ok(())
        }
        Some((w, h)) if (w, h) == (img.width, img.height) => Ok(()),
        Some((w, h)) => Err(file_error(
            path,
            format!(
                "image is {}x{}, but the sequence's images are {w}x{h}",
                img.width, img.height
            ),
        )),
    }
}

pub(crate) fn file_error(path: &Path, reason: String) -> ImportError {
    ImportError::File {
        path: path.to_path_buf(),
        reason,
    }
}

pub(crate) fn line_error(path: &Path, line: usize, reason: String) -> ImportError {
    ImportError::Line {
        path: path.to_path_buf(),
        line,
        reason,
    }
}

/// Width and height of a stream's images.
pub(crate) type ImageSize = (u32, u32);

/// The header of a recording imported from the `layout` directory `dir`: its name,
/// provenance (tool, version, source, settings), intrinsics fitted to the image sizes.
pub(crate) fn import_header(
    layout: &str,
    dir: &Path,
    options: &ImportOptions,
    extra_settings: &[(&str, String)],
    (color_size, depth_size): (Option<ImageSize>, Option<ImageSize>),
    depth_unit_m: f64,
    streams: Vec<StreamKind>,
) -> Header {
    let mut settings: std::collections::BTreeMap<String, String> = extra_settings
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect();
    // As `--intrinsics` and `--store` take them, so the settings can be given again.
    settings.insert("intrinsics".into(), options.intrinsics.setting());
    let store = match options.store {
        StoreMode::Compressed => "compressed",
        StoreMode::Raw => "raw",
    };
    settings.insert("store".into(), store.into());
    Header {
        name: dir
            .file_name()
            .map_or_else(|| layout.to_string(), |n| n.to_string_lossy().into_owned()),
        provenance: Provenance {
            tool: format!("relume import {layout}"),
            tool_version: env!("CARGO_PKG_VERSION").into(),
            source: dir.display().to_string(),
            settings,
        },
        color_intrinsics: options.intrinsics.for_size(color_size, depth_size),
        depth_intrinsics: options.intrinsics.for_size(depth_size, color_size),
        depth_unit_m,
        streams,
        ground_truth: None,
        attachments: Vec::new(),
    }
}

/// Parses a decimal seconds stamp ("1305031102.175304") exactly into nanoseconds.
pub fn parse_stamp_ns(text: &str) -> Option<i64> {
    let (neg, digits) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text),
    };
    let (int, frac) = digits.split_once('.').unwrap_or((digits, ""));
    if int.is_empty() && frac.is_empty()
        || !int.bytes().all(|b| b.is_ascii_digit())
        || !frac.bytes().all(|b| b.is_ascii_digit())
    {
        return None;
    }
    let secs: i64 = if int.is_empty() { 0 } else { int.parse().ok()? };
    let mut nanos: i64 = 0;
    for (i, b) in frac.bytes().enumerate() {
        if i < 9 {
            nanos = nanos * 10 + (b - b'0') as i64;
        }
    }
    nanos *= 10i64.pow(9u32.saturating_sub(frac.len() as u32));
    let total = secs.checked_mul(1_000_000_000)?.checked_add(nanos)?;
    Some(if neg { -total } else { total })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_parse_exactly() {
        assert_eq!(
            parse_stamp_ns("1305031102.175304"),
            Some(1_305_031_102_175_304_000)
        );
        assert_eq!(parse_stamp_ns("12"), Some(12_000_000_000));
        assert_eq!(parse_stamp_ns("0.0000000019"), Some(1));
        assert_eq!(parse_stamp_ns("1.5e3"), None);
        assert_eq!(parse_stamp_ns(""), None);
        assert_eq!(parse_stamp_ns("."), None);
    }

    #[test]
    fn intrinsics_presets_and_lists() {
        let fr1 = parse_intrinsics("tum-fr1").unwrap();
        assert_eq!(fr1.for_size(Some((640, 480)), None).fx, 517.3);
        // A preset is rescaled to other sizes, with a note; given numbers never are.
        assert_eq!(fr1.for_size(Some((320, 240)), None).fx, 517.3 / 2.0);
        assert!(fr1.rescale_note("color", (320, 240)).is_some());
        assert!(fr1.rescale_note("color", (640, 480)).is_none());
        let given = parse_intrinsics("500, 501, 160, 120").unwrap();
        let k = given.for_size(Some((320, 240)), None);
        assert_eq!(
            (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
            (320, 240, 500.0, 501.0, 160.0, 120.0)
        );
        assert!(given.rescale_note("color", (320, 240)).is_none());
        assert_eq!(given.setting(), "500,501,160,120");
        assert_eq!(fr1.setting(), "tum-fr1");
        let e = parse_intrinsics("500,501").unwrap_err();
        assert!(e.contains("fx,fy,cx,cy") && e.contains("tum-fr3"), "{e}");
    }
}
