//! Image messages to the images a recording stores.
//!
//! - Color: raw `rgb8`, `bgr8`, `rgba8`, `bgra8`, `mono8` become 8-bit RGB (alpha
//!   dropped, gray repeated); JPEG and PNG files (`jpeg`, `png`, and image_transport's
//!   `bgr8; jpeg compressed bgr8`) are kept as found.
//! - Depth: raw `16UC1` / `mono16` are units of the recording's depth unit (REP 118:
//!   millimetres); raw `32FC1` is metres, quantized to the unit (rounded; NaN, infinite,
//!   non-positive and out-of-range values become 0, missing). compressed_depth_image_
//!   transport's `compressedDepth` format (a 12-byte header, then a PNG) is read for
//!   `16UC1` (the PNG holds the units) and for `32FC1` (the PNG holds quantized inverse
//!   depth: depth = A / (v - B), with A and B from the header).

use super::messages::ImageData;
use crate::codec::{self, wrap_image_file};
use crate::importers::StoreMode;
use crate::types::{EncodedImage, ImageEncoding};

/// What an image topic holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageRole {
    Color,
    Depth,
}

impl ImageRole {
    pub fn name(self) -> &'static str {
        match self {
            ImageRole::Color => "color",
            ImageRole::Depth => "depth",
        }
    }
}

const COLOR_ENCODINGS: &[&str] = &["rgb8", "bgr8", "rgba8", "bgra8", "mono8"];
const DEPTH_ENCODINGS: &[&str] = &["16UC1", "mono16", "32FC1"];

/// A short description of an image message's format, for listings and errors.
pub fn describe(data: &ImageData) -> String {
    match data {
        ImageData::Raw {
            width,
            height,
            encoding,
            ..
        } => format!("{width}x{height} {encoding}"),
        ImageData::Compressed { format, .. } => format!("compressed `{format}`"),
    }
}

/// Whether an image message is color or depth, from its encoding or format (and for a
/// plain PNG, from the bits per sample in its header).
pub fn role_of(data: &ImageData) -> Result<ImageRole, String> {
    match data {
        ImageData::Raw { encoding, .. } => {
            if COLOR_ENCODINGS.contains(&encoding.as_str()) {
                Ok(ImageRole::Color)
            } else if DEPTH_ENCODINGS.contains(&encoding.as_str()) {
                Ok(ImageRole::Depth)
            } else {
                Err(format!(
                    "raw encoding `{encoding}` is not read (color: {}; depth: {})",
                    COLOR_ENCODINGS.join(", "),
                    DEPTH_ENCODINGS.join(", ")
                ))
            }
        }
        ImageData::Compressed { format, data } => {
            let f = format.to_ascii_lowercase();
            if f.contains("compresseddepth") {
                return Ok(ImageRole::Depth);
            }
            if f.starts_with("16uc1") || f.starts_with("mono16") {
                return Ok(ImageRole::Depth);
            }
            if !data.is_empty()
                && let Ok((img, 16)) = wrap_image_file(data.to_vec())
                && img.channels == 1
            {
                return Ok(ImageRole::Depth);
            }
            if ["jpeg", "jpg", "png"].iter().any(|k| f.contains(k)) {
                Ok(ImageRole::Color)
            } else {
                Err(format!(
                    "compressed format `{format}` is not read (JPEG or PNG color, PNG or \
                     compressedDepth png depth)"
                ))
            }
        }
    }
}

/// Rows of `bytes_per_pixel` * `width` bytes out of a raw message, checked against its
/// step and length.
fn rows(
    data: &[u8],
    width: u32,
    height: u32,
    step: u32,
    bytes_per_pixel: usize,
) -> Result<impl Iterator<Item = &[u8]>, String> {
    let pixels = width as u64 * height as u64;
    if pixels == 0 || pixels > codec::MAX_PIXELS {
        return Err(format!("image size {width}x{height} is empty or too large"));
    }
    let row = width as usize * bytes_per_pixel;
    let step = step as usize;
    if step.saturating_mul(height as usize) > data.len().saturating_add(step) {
        return Err(format!(
            "{} bytes of pixels for {width}x{height} at step {step}",
            data.len()
        ));
    }
    if step < row {
        return Err(format!(
            "step {step} is shorter than a row of {width} pixels ({row} bytes)"
        ));
    }
    let need = step * (height as usize - 1) + row;
    if data.len() < need {
        return Err(format!(
            "{} bytes of pixels for {width}x{height} at step {step} (need {need})",
            data.len()
        ));
    }
    Ok(data
        .chunks(step)
        .take(height as usize)
        .map(move |r| &r[..row]))
}

/// compressed_depth_image_transport's (A, B): a 32FC1 depth d is sent as A / d + B.
type DepthQuantization = (f32, f32);

/// The image file inside a compressed message, and for compressed_depth_image_transport's
/// `compressedDepth` format the quantization parameters (A, B) of its 12-byte header.
pub fn compressed_file<'a>(
    format: &str,
    data: &'a [u8],
) -> Result<(Option<DepthQuantization>, &'a [u8]), String> {
    let format = format.to_ascii_lowercase();
    if !format.contains("compresseddepth") {
        return Ok((None, data));
    }
    if format.contains("rvl") {
        return Err("compressedDepth rvl is not read (only png)".into());
    }
    if data.len() <= 12 {
        return Err(format!(
            "a compressedDepth message of {} bytes has no image after its 12-byte header",
            data.len()
        ));
    }
    let f = |i: usize| f32::from_le_bytes(data[i..i + 4].try_into().expect("4 bytes"));
    let (a, b) = (f(4), f(8));
    // Only a 32FC1 image is sent quantized; a 16UC1 one carries the header unused.
    let quantized = format.trim_start().starts_with("32fc1");
    if quantized && !(a.is_finite() && a != 0.0 && b.is_finite()) {
        return Err(format!(
            "the compressedDepth header's quantization A = {a}, B = {b} cannot give a \
             depth (depth = A / (v - B): A must be finite and not 0, B finite)"
        ));
    }
    Ok((Some((a, b)), &data[12..]))
}

/// A color message as stored: JPEG/PNG kept (or decoded to raw with `StoreMode::Raw`),
/// raw pixels as 8-bit RGB. Every image is decoded once, so that a damaged one is
/// refused at import.
pub fn color_image(data: &ImageData, store: StoreMode) -> Result<EncodedImage, String> {
    let img = match data {
        ImageData::Raw {
            width,
            height,
            encoding,
            step,
            data,
            ..
        } => {
            let (bpp, order): (usize, [usize; 3]) = match encoding.as_str() {
                "rgb8" => (3, [0, 1, 2]),
                "bgr8" => (3, [2, 1, 0]),
                "rgba8" => (4, [0, 1, 2]),
                "bgra8" => (4, [2, 1, 0]),
                "mono8" => (1, [0, 0, 0]),
                other => return Err(format!("raw encoding `{other}` is not a color encoding")),
            };
            // Rows first: they check the size against the bytes sent before anything
            // is reserved for it.
            let rows = rows(data, *width, *height, *step, bpp)?;
            let mut bytes = Vec::with_capacity(*width as usize * *height as usize * 3);
            for row in rows {
                for px in row.chunks_exact(bpp) {
                    bytes.extend(order.map(|c| px[c]));
                }
            }
            return Ok(EncodedImage {
                encoding: ImageEncoding::RawU8,
                width: *width,
                height: *height,
                channels: 3,
                bytes,
            });
        }
        ImageData::Compressed { data, .. } => {
            let (img, bits) = wrap_image_file(data.to_vec()).map_err(|e| e.to_string())?;
            if bits != 8 {
                return Err(format!(
                    "a color image must have 8-bit samples, found {bits}-bit"
                ));
            }
            img
        }
    };
    crate::importers::stored_color(img, store).map_err(|e| e.to_string())
}

/// A depth message as stored, in units of `unit_m` metres.
pub fn depth_image(
    data: &ImageData,
    unit_m: f64,
    store: StoreMode,
) -> Result<EncodedImage, String> {
    let img = match data {
        ImageData::Raw {
            width,
            height,
            encoding,
            big_endian,
            step,
            data,
        } => {
            let float = match encoding.as_str() {
                "16UC1" | "mono16" => false,
                "32FC1" => true,
                other => return Err(format!("raw encoding `{other}` is not a depth encoding")),
            };
            let bpp = if float { 4 } else { 2 };
            let rows = rows(data, *width, *height, *step, bpp)?;
            let mut units = Vec::with_capacity(*width as usize * *height as usize);
            for row in rows {
                for px in row.chunks_exact(bpp) {
                    units.push(match (float, *big_endian) {
                        (false, false) => u16::from_le_bytes([px[0], px[1]]),
                        (false, true) => u16::from_be_bytes([px[0], px[1]]),
                        (true, be) => {
                            let raw = [px[0], px[1], px[2], px[3]];
                            let m = if be {
                                f32::from_be_bytes(raw)
                            } else {
                                f32::from_le_bytes(raw)
                            };
                            codec::depth_units_of(m, unit_m)
                        }
                    });
                }
            }
            codec::raw_depth(*width, *height, units)
        }
        ImageData::Compressed { format, data } => {
            let (header, png) = compressed_file(format, data)?;
            let (img, bits) = wrap_image_file(png.to_vec()).map_err(|e| e.to_string())?;
            if bits != 16 || img.channels != 1 {
                return Err(format!(
                    "depth must be a 16-bit single-channel PNG, found {} channel(s) of {bits} bits",
                    img.channels
                ));
            }
            let inverse = format
                .trim_start()
                .to_ascii_uppercase()
                .starts_with("32FC1");
            match (inverse, header) {
                (true, Some((a, b))) => {
                    // compressed_depth_image_transport: v = A / depth + B, 0 = none.
                    let v = codec::decode_depth_units(&img).map_err(|e| e.to_string())?;
                    let units = v.data.iter().map(|&v| {
                        if v == 0 {
                            0
                        } else {
                            codec::depth_units_of(a / (v as f32 - b), unit_m)
                        }
                    });
                    codec::raw_depth(img.width, img.height, units)
                }
                _ => img,
            }
        }
    };
    match store {
        StoreMode::Compressed => codec::decode_depth_units(&img).map(|_| img),
        StoreMode::Raw => codec::to_raw_depth(&img),
    }
    .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::borrow::Cow;

    fn raw(encoding: &str, width: u32, step: u32, data: Vec<u8>) -> ImageData<'static> {
        ImageData::Raw {
            width,
            height: 1,
            encoding: encoding.into(),
            big_endian: false,
            step,
            data: Cow::Owned(data),
        }
    }

    #[test]
    fn raw_color_orders_become_rgb_and_padding_is_dropped() {
        let bgra = raw("bgra8", 2, 10, vec![1, 2, 3, 255, 4, 5, 6, 255, 0, 0]);
        let img = color_image(&bgra, StoreMode::Compressed).unwrap();
        assert_eq!(img.bytes, [3, 2, 1, 6, 5, 4]);
        let mono = raw("mono8", 2, 2, vec![7, 9]);
        assert_eq!(
            color_image(&mono, StoreMode::Compressed).unwrap().bytes,
            [7, 7, 7, 9, 9, 9]
        );
        // A claimed size far beyond the bytes sent is refused before any allocation.
        let huge = ImageData::Raw {
            width: u32::MAX,
            height: u32::MAX,
            encoding: "rgb8".into(),
            big_endian: false,
            step: u32::MAX,
            data: Cow::Owned(vec![0; 16]),
        };
        assert!(color_image(&huge, StoreMode::Compressed).is_err());
        let big = ImageData::Raw {
            width: 8000,
            height: 8000,
            encoding: "32FC1".into(),
            big_endian: false,
            step: 32000,
            data: Cow::Owned(vec![0; 16]),
        };
        assert_eq!(
            depth_image(&big, 0.001, StoreMode::Compressed).unwrap_err(),
            "16 bytes of pixels for 8000x8000 at step 32000"
        );
        let short = raw("rgb8", 2, 6, vec![0; 5]);
        assert_eq!(
            color_image(&short, StoreMode::Compressed).unwrap_err(),
            "5 bytes of pixels for 2x1 at step 6 (need 6)"
        );
        assert_eq!(role_of(&bgra), Ok(ImageRole::Color));
        assert!(role_of(&raw("yuv422", 2, 4, vec![])).is_err());
    }

    #[test]
    fn float_depth_is_quantized_to_the_unit() {
        let metres = [1.2344f32, f32::NAN, -1.0, 70.0, 0.0004];
        let bytes = metres.iter().flat_map(|m| m.to_le_bytes()).collect();
        let img = depth_image(&raw("32FC1", 5, 20, bytes), 0.001, StoreMode::Compressed);
        let units: Vec<u16> = img
            .unwrap()
            .bytes
            .chunks(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        assert_eq!(units, [1234, 0, 0, 0, 0]);
        let be = ImageData::Raw {
            width: 1,
            height: 1,
            encoding: "16UC1".into(),
            big_endian: true,
            step: 2,
            data: Cow::Owned(vec![0x01, 0x02]),
        };
        let img = depth_image(&be, 0.001, StoreMode::Compressed).unwrap();
        assert_eq!(img.bytes, [0x02, 0x01]);
    }

    #[test]
    fn a_compressed_depth_header_that_cannot_give_a_depth_is_refused() {
        let header = |a: f32, b: f32| {
            let mut data = 0i32.to_le_bytes().to_vec();
            data.extend(a.to_le_bytes());
            data.extend(b.to_le_bytes());
            data.extend([0u8; 8]);
            data
        };
        for (a, b) in [(f32::NAN, 1.0), (1.0, f32::INFINITY), (0.0, 1.0)] {
            let e = compressed_file("32FC1; compressedDepth png", &header(a, b)).unwrap_err();
            assert_eq!(
                e,
                format!(
                    "the compressedDepth header's quantization A = {a}, B = {b} cannot give a \
                     depth (depth = A / (v - B): A must be finite and not 0, B finite)"
                )
            );
        }
        // 16UC1 sends the units themselves: its header is not read.
        let unused = header(f32::NAN, 0.0);
        let (_, png) = compressed_file("16UC1; compressedDepth", &unused).unwrap();
        assert_eq!(png, [0u8; 8]);
    }

    #[test]
    fn compressed_depth_inverse_quantization_round_trips() {
        // As compressed_depth_image_transport encodes 32FC1: A = z0 (z0 + 1), B = 1 - A / max.
        let (z0, max) = (100.0f32, 10.0f32);
        let (a, b) = (z0 * (z0 + 1.0), 1.0 - z0 * (z0 + 1.0) / max);
        let depth = [0.5f32, 2.0, 9.0];
        let inv: Vec<u16> = depth.iter().map(|d| (a / d + b) as u16).collect();
        let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(3, 1, inv).unwrap();
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let mut data = 0i32.to_le_bytes().to_vec();
        data.extend(a.to_le_bytes());
        data.extend(b.to_le_bytes());
        data.extend(png);
        let msg = ImageData::Compressed {
            format: "32FC1; compressedDepth png".into(),
            data: Cow::Owned(data),
        };
        assert_eq!(role_of(&msg), Ok(ImageRole::Depth));
        let img = depth_image(&msg, 0.001, StoreMode::Compressed).unwrap();
        let mm: Vec<u16> = img
            .bytes
            .chunks(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        // Quantized inverse depth: within a few mm at these ranges.
        for (got, want) in mm.iter().zip(depth) {
            assert!(
                (*got as f32 - want * 1000.0).abs() < 0.01 * want * 1000.0,
                "{mm:?}"
            );
        }
    }
}
