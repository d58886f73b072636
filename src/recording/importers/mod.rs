//! Importers of common RGB-D dataset layouts into `.relume` recordings.
//!
//! - [`tum`]: the TUM RGB-D benchmark layout (`rgb.txt`, `depth.txt`, `groundtruth.txt`).
//! - [`redwood`]: the Redwood / Open3D layout (`color/` or `image/`, `depth/`, a `.log`
//!   trajectory).
//!
//! Both keep the images' compressed bytes (decoded on replay) unless asked to store raw,
//! check every image's header (format, size, bit depth) at import, and write atomically.

pub mod redwood;
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

/// Parses `--intrinsics`: a preset name or `fx,fy,cx,cy` (pixels, for 640x480 unless the
/// images say otherwise).
pub fn parse_intrinsics(text: &str) -> Result<Intrinsics, String> {
    if let Some((_, k)) = INTRINSICS_PRESETS.iter().find(|(n, _)| *n == text) {
        return Ok(*k);
    }
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| intrinsics_hint(text))?;
    match values[..] {
        [fx, fy, cx, cy] if values.iter().all(|v| v.is_finite()) && fx > 0.0 && fy > 0.0 => {
            Ok(Intrinsics {
                width: 640,
                height: 480,
                fx,
                fy,
                cx,
                cy,
            })
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
    pub intrinsics: Intrinsics,
    pub store: StoreMode,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            intrinsics: Intrinsics::PRIMESENSE,
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
    // Decoded either way: a damaged file (a truncated PNG) is refused here, naming it,
    // rather than stored to fail the replay at its frame.
    match store {
        StoreMode::Compressed => codec::decode_color(&img).map(|_| img),
        StoreMode::Raw => codec::to_raw_color(&img),
    }
    .map_err(|e| file_error(path, e.to_string()))
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
    let bytes = crate::files::read_regular(path).map_err(|source| ImportError::Io {
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
    let k = &options.intrinsics;
    settings.insert(
        "intrinsics".into(),
        format!("{},{},{},{}", k.fx, k.fy, k.cx, k.cy),
    );
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
        color_intrinsics: intrinsics_for(&options.intrinsics, color_size),
        depth_intrinsics: intrinsics_for(&options.intrinsics, depth_size),
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

/// The color/depth intrinsics for images of `size`: the given intrinsics, rescaled when
/// the images are not the size the intrinsics are for.
pub(crate) fn intrinsics_for(k: &Intrinsics, size: Option<(u32, u32)>) -> Intrinsics {
    match size {
        Some((w, h)) if (w, h) != (k.width, k.height) => k.scaled_to(w, h),
        _ => *k,
    }
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
        assert_eq!(parse_intrinsics("tum-fr1").unwrap().fx, 517.3);
        assert_eq!(parse_intrinsics("500, 501, 320, 240").unwrap().fy, 501.0);
        let e = parse_intrinsics("500,501").unwrap_err();
        assert!(e.contains("fx,fy,cx,cy") && e.contains("tum-fr3"), "{e}");
    }
}
