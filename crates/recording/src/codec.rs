//! Encoding and decoding of the images stored in recordings. Color and depth keep their
//! compressed form from import (PNG/JPEG) and are decoded on replay; float ground truth
//! is stored as byte-plane-shuffled, deflated f32 or f16.

use super::types::{EncodedImage, ImageEncoding};
use image::{DynamicImage, ImageFormat};
use relume_base::raster::{DepthImage, Image, Rgb8Image};

/// The largest image a recording may hold, in pixels (sanity limit before allocation).
pub const MAX_PIXELS: u64 = 64 << 20;

/// Why an image could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct CodecError(pub String);

fn err<T>(msg: impl Into<String>) -> Result<T, CodecError> {
    Err(CodecError(msg.into()))
}

fn checked_len(img: &EncodedImage, bytes_per_sample: u64) -> Result<usize, CodecError> {
    let pixels = img.width as u64 * img.height as u64;
    if pixels == 0 || pixels > MAX_PIXELS || img.channels == 0 || img.channels > 4 {
        return err(format!(
            "implausible image size {}x{}x{}",
            img.width, img.height, img.channels
        ));
    }
    Ok((pixels * img.channels as u64 * bytes_per_sample) as usize)
}

/// Encodes 8-bit RGB as PNG (fast compression).
pub fn encode_png_rgb8(img: &Rgb8Image) -> Result<EncodedImage, CodecError> {
    let flat: Vec<u8> = img.data.iter().flatten().copied().collect();
    let buf = image::RgbImage::from_raw(img.width, img.height, flat)
        .ok_or_else(|| CodecError("pixel count does not match the size".into()))?;
    encode_png(DynamicImage::ImageRgb8(buf), 3, img.width, img.height)
}

/// Encodes 16-bit gray (depth units) as PNG (fast compression).
pub fn encode_png_u16(
    width: u32,
    height: u32,
    units: Vec<u16>,
) -> Result<EncodedImage, CodecError> {
    let buf = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(width, height, units)
        .ok_or_else(|| CodecError("pixel count does not match the size".into()))?;
    encode_png(DynamicImage::ImageLuma16(buf), 1, width, height)
}

fn encode_png(
    img: DynamicImage,
    channels: u8,
    width: u32,
    height: u32,
) -> Result<EncodedImage, CodecError> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let mut bytes = Vec::new();
    let encoder =
        PngEncoder::new_with_quality(&mut bytes, CompressionType::Fast, FilterType::Adaptive);
    img.write_with_encoder(encoder)
        .map_err(|e| CodecError(format!("PNG encoding failed: {e}")))?;
    Ok(EncodedImage {
        encoding: ImageEncoding::Png,
        width,
        height,
        channels,
        bytes,
    })
}

/// Wraps an image file's bytes (PNG or JPEG) without decoding its pixels; reads only
/// its header for the size. Returns the image and its bits per sample (8 or 16).
/// Fails when the bytes are neither.
pub fn wrap_image_file(bytes: Vec<u8>) -> Result<(EncodedImage, u16), CodecError> {
    let format =
        image::guess_format(&bytes).map_err(|e| CodecError(format!("not an image: {e}")))?;
    let encoding = match format {
        ImageFormat::Png => ImageEncoding::Png,
        ImageFormat::Jpeg => ImageEncoding::Jpeg,
        other => {
            return err(format!(
                "unsupported image format {other:?} (expected PNG or JPEG)"
            ));
        }
    };
    let (width, height, color) = {
        use image::ImageDecoder;
        let reader = image::ImageReader::with_format(std::io::Cursor::new(&bytes), format);
        let decoder = reader
            .into_decoder()
            .map_err(|e| CodecError(format!("unreadable {format:?} header: {e}")))?;
        let (w, h) = decoder.dimensions();
        (w, h, decoder.color_type())
    };
    let channels = color.channel_count();
    let bits = color.bits_per_pixel() / channels as u16;
    if bits != 8 && bits != 16 {
        return err(format!("unsupported sample depth of {bits} bits"));
    }
    let image = EncodedImage {
        encoding,
        width,
        height,
        channels,
        bytes,
    };
    Ok((image, bits))
}

/// Decodes an encoded color image and stores it raw (8-bit RGB, no compression).
pub fn to_raw_color(img: &EncodedImage) -> Result<EncodedImage, CodecError> {
    let rgb = decode_color(img)?;
    Ok(EncodedImage {
        encoding: ImageEncoding::RawU8,
        width: rgb.width,
        height: rgb.height,
        channels: 3,
        bytes: rgb.data.iter().flatten().copied().collect(),
    })
}

/// Decodes an encoded depth image and stores it raw (little-endian u16 units).
pub fn to_raw_depth(img: &EncodedImage) -> Result<EncodedImage, CodecError> {
    let units = decode_depth_units(img)?;
    Ok(raw_depth(units.width, units.height, units.data))
}

/// Depth units stored raw: a `width` x `height` little-endian u16 image.
pub fn raw_depth(width: u32, height: u32, units: impl IntoIterator<Item = u16>) -> EncodedImage {
    EncodedImage {
        encoding: ImageEncoding::RawU16,
        width,
        height,
        channels: 1,
        bytes: units.into_iter().flat_map(u16::to_le_bytes).collect(),
    }
}

/// A metric depth in units of `unit_m`, rounded; 0 (no measurement) for a depth that is
/// not finite, not positive or beyond the 16-bit range.
pub fn depth_units_of(metres: f32, unit_m: f64) -> u16 {
    let units = (metres as f64 / unit_m).round();
    if metres.is_finite() && metres > 0.0 && (1.0..=65535.0).contains(&units) {
        units as u16
    } else {
        0
    }
}

fn decode_file(img: &EncodedImage) -> Result<DynamicImage, CodecError> {
    let format = match img.encoding {
        ImageEncoding::Png => ImageFormat::Png,
        ImageEncoding::Jpeg => ImageFormat::Jpeg,
        _ => unreachable!("decode_file is called for PNG and JPEG only"),
    };
    checked_len(img, 1)?;
    // The JPEG decoder fills a truncated image with gray and says nothing.
    if img.encoding == ImageEncoding::Jpeg && !jpeg_reaches_its_end(&img.bytes) {
        return err(
            "the JPEG is truncated or damaged: its marker segments do not reach \
             the end-of-image marker",
        );
    }
    let mut reader = image::ImageReader::with_format(std::io::Cursor::new(&img.bytes), format);
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(MAX_PIXELS * 8);
    reader.limits(limits);
    let decoded = reader
        .decode()
        .map_err(|e| CodecError(format!("cannot decode {format:?}: {e}")))?;
    if decoded.width() != img.width || decoded.height() != img.height {
        return err(format!(
            "decoded size {}x{} differs from the stored {}x{}",
            decoded.width(),
            decoded.height(),
            img.width,
            img.height
        ));
    }
    Ok(decoded)
}

/// Whether the JPEG `bytes` can be walked from its start-of-image marker through its
/// marker segments and entropy-coded scans to an end-of-image marker (ITU T.81, B.1).
/// Bytes after the end (some cameras append a trailer) are allowed. Segments are skipped
/// by their lengths, so markers inside an EXIF thumbnail do not count.
pub fn jpeg_reaches_its_end(bytes: &[u8]) -> bool {
    const SOS: u8 = 0xDA;
    const EOI: u8 = 0xD9;
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return false;
    }
    let mut at = 2;
    loop {
        // Fill bytes (0xFF) may precede a marker.
        while bytes.get(at) == Some(&0xFF) && bytes.get(at + 1) == Some(&0xFF) {
            at += 1;
        }
        let (Some(&0xFF), Some(&marker)) = (bytes.get(at), bytes.get(at + 1)) else {
            return false;
        };
        at += 2;
        match marker {
            EOI => return true,
            // Markers without a length: TEM and the restart markers.
            0x01 | 0xD0..=0xD7 => continue,
            _ => {}
        }
        let Some(len) = bytes
            .get(at..at + 2)
            .map(|b| u16::from_be_bytes([b[0], b[1]]))
        else {
            return false;
        };
        if len < 2 {
            return false;
        }
        at += len as usize;
        if marker == SOS {
            // Entropy-coded data: 0xFF is followed by 0x00 (a stuffed byte) or a restart
            // marker inside it, maybe after fill bytes (0xFF); any other marker ends the
            // scan.
            loop {
                match bytes.get(at..at + 2) {
                    None => return false,
                    Some([0xFF, 0x00 | 0xD0..=0xD7]) => at += 2,
                    Some([0xFF, 0xFF]) => at += 1,
                    Some([0xFF, _]) => break,
                    Some(_) => at += 1,
                }
            }
        }
    }
}

/// Why a deflate or zlib stream meant to hold `expected` bytes would not inflate, in
/// words (the error's `Debug` would print every byte inflated so far).
pub fn inflate_failure(e: &miniz_oxide::inflate::DecompressError, expected: usize) -> String {
    use miniz_oxide::inflate::TINFLStatus;
    let so_far = e.output.len();
    match e.status {
        TINFLStatus::HasMoreOutput => {
            format!("it inflates to more than the {expected} bytes the image's size allows")
        }
        TINFLStatus::NeedsMoreInput | TINFLStatus::FailedCannotMakeProgress => {
            format!("the compressed data ends early (truncated after {so_far} of {expected} bytes)")
        }
        TINFLStatus::Adler32Mismatch => {
            "the zlib checksum does not match the inflated bytes (damaged data)".to_string()
        }
        _ => format!("the compressed data is invalid (after {so_far} of {expected} bytes)"),
    }
}

/// Decodes a color image to 8-bit RGB.
pub fn decode_color(img: &EncodedImage) -> Result<Rgb8Image, CodecError> {
    let rgb: Vec<u8> = match img.encoding {
        ImageEncoding::Png | ImageEncoding::Jpeg => decode_file(img)?.into_rgb8().into_raw(),
        ImageEncoding::RawU8 if img.channels == 3 => {
            if img.bytes.len() != checked_len(img, 1)? {
                return err("raw color has the wrong number of bytes");
            }
            img.bytes.clone()
        }
        other => {
            return err(format!(
                "{other:?} with {} channels is not a color encoding",
                img.channels
            ));
        }
    };
    let pixels = rgb.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    Ok(
        Image::from_vec(img.width, img.height, pixels)
            .expect("decoder returns width*height pixels"),
    )
}

/// Decodes a depth image in units to raw 16-bit units.
pub fn decode_depth_units(img: &EncodedImage) -> Result<Image<u16>, CodecError> {
    let units: Vec<u16> = match img.encoding {
        ImageEncoding::Png => match decode_file(img)? {
            DynamicImage::ImageLuma16(b) => b.into_raw(),
            other => {
                return err(format!(
                    "depth must be a 16-bit single-channel PNG, found {:?}",
                    other.color()
                ));
            }
        },
        ImageEncoding::RawU16 if img.channels == 1 => {
            if img.bytes.len() != checked_len(img, 2)? {
                return err("raw depth has the wrong number of bytes");
            }
            img.bytes
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect()
        }
        other => {
            return err(format!(
                "{other:?} with {} channels is not a depth encoding",
                img.channels
            ));
        }
    };
    Ok(Image::from_vec(img.width, img.height, units).expect("decoder returns width*height pixels"))
}

/// Decodes a depth image to metres (`unit_m` metres per unit); 0 stays 0 (missing).
pub fn decode_depth(img: &EncodedImage, unit_m: f64) -> Result<DepthImage, CodecError> {
    let units = decode_depth_units(img)?;
    let scale = unit_m as f32;
    Ok(Image {
        width: units.width,
        height: units.height,
        data: units.data.iter().map(|&u| u as f32 * scale).collect(),
    })
}

/// Stores float samples (`channels` per pixel, interleaved) as shuffled, deflated f32,
/// or f16 when `half` is set (about 3 significant digits, enough for normals and radiance).
pub fn encode_floats(
    width: u32,
    height: u32,
    channels: u8,
    samples: &[f32],
    half: bool,
) -> EncodedImage {
    let (encoding, raw): (_, Vec<u8>) = if half {
        let bytes = samples
            .iter()
            .flat_map(|&v| half::f16::from_f32(v).to_le_bytes())
            .collect();
        (ImageEncoding::ShuffledF16, bytes)
    } else {
        (
            ImageEncoding::ShuffledF32,
            samples.iter().flat_map(|v| v.to_le_bytes()).collect(),
        )
    };
    let size = if half { 2 } else { 4 };
    let n = samples.len();
    let mut shuffled = vec![0u8; raw.len()];
    for (i, sample) in raw.chunks_exact(size).enumerate() {
        for (plane, &b) in sample.iter().enumerate() {
            shuffled[plane * n + i] = b;
        }
    }
    EncodedImage {
        encoding,
        width,
        height,
        channels,
        bytes: miniz_oxide::deflate::compress_to_vec(&shuffled, 1),
    }
}

/// Decodes samples stored by [`encode_floats`] (interleaved, `channels` per pixel).
pub fn decode_floats(img: &EncodedImage) -> Result<Vec<f32>, CodecError> {
    let size = match img.encoding {
        ImageEncoding::ShuffledF32 => 4,
        ImageEncoding::ShuffledF16 => 2,
        other => return err(format!("{other:?} is not a float encoding")),
    };
    let expected = checked_len(img, size as u64)?;
    let shuffled = miniz_oxide::inflate::decompress_to_vec_with_limit(&img.bytes, expected)
        .map_err(|e| {
            CodecError(format!(
                "corrupt float data: {}",
                inflate_failure(&e, expected)
            ))
        })?;
    if shuffled.len() != expected {
        return err(format!(
            "float data holds {} bytes, expected {expected}",
            shuffled.len()
        ));
    }
    let n = expected / size;
    Ok((0..n)
        .map(|i| {
            if size == 4 {
                f32::from_le_bytes([0, 1, 2, 3].map(|p| shuffled[p * n + i]))
            } else {
                half::f16::from_le_bytes([shuffled[i], shuffled[n + i]]).to_f32()
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_round_trip_exactly_in_f32_and_closely_in_f16() {
        let samples: Vec<f32> = (0..300).map(|i| (i as f32 * 0.37).sin() * 3.0).collect();
        let full = decode_floats(&encode_floats(10, 10, 3, &samples, false)).unwrap();
        assert_eq!(full, samples);
        let halfs = decode_floats(&encode_floats(10, 10, 3, &samples, true)).unwrap();
        for (a, b) in halfs.iter().zip(&samples) {
            assert!((a - b).abs() <= 2e-3 * b.abs().max(1.0), "{a} vs {b}");
        }
    }

    fn jpeg_of(w: u32, h: u32) -> Vec<u8> {
        let img =
            image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 7) as u8, (y * 5) as u8, 99]));
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Jpeg).unwrap();
        out.into_inner()
    }

    #[test]
    fn a_truncated_jpeg_is_refused_though_the_decoder_would_fill_it() {
        let whole = jpeg_of(32, 24);
        assert!(jpeg_reaches_its_end(&whole));
        let encoded = |bytes: Vec<u8>| EncodedImage {
            encoding: ImageEncoding::Jpeg,
            width: 32,
            height: 24,
            channels: 3,
            bytes,
        };
        assert!(decode_color(&encoded(whole.clone())).is_ok());
        // Every cut inside the file is refused, the headers and the scan alike.
        for cut in 0..whole.len() {
            assert!(
                !jpeg_reaches_its_end(&whole[..cut]),
                "cut at {cut} of {}",
                whole.len()
            );
        }
        let cut = whole[..whole.len() * 2 / 3].to_vec();
        assert_eq!(
            decode_color(&encoded(cut)).unwrap_err().to_string(),
            "the JPEG is truncated or damaged: its marker segments do not reach the \
             end-of-image marker"
        );
        // A trailer after the end is allowed; a whole thumbnail inside an APP1 segment
        // does not make a cut image whole.
        let mut trailer = whole.clone();
        trailer.extend_from_slice(b"camera trailer");
        assert!(jpeg_reaches_its_end(&trailer));
        let thumb = jpeg_of(4, 4);
        let mut with_thumb = vec![0xFF, 0xD8, 0xFF, 0xE1];
        with_thumb.extend_from_slice(&(thumb.len() as u16 + 2).to_be_bytes());
        with_thumb.extend_from_slice(&thumb);
        with_thumb.extend_from_slice(&whole[2..]);
        assert!(jpeg_reaches_its_end(&with_thumb));
        assert!(!jpeg_reaches_its_end(&with_thumb[..with_thumb.len() - 40]));
        // Fill bytes may precede a restart marker inside a scan (T.81, B.1.1.2), as they
        // may precede any marker; the scan goes on after it.
        let scan = |between: &[u8]| {
            let head = [0xFF, 0xD8, 0xFF, 0xDA, 0x00, 0x02, 0x12, 0x34];
            [
                &head[..],
                between,
                &[0x56, 0xFF, 0x00, 0x78, 0xFF, 0xFF, 0xD9],
            ]
            .concat()
        };
        assert!(jpeg_reaches_its_end(&scan(&[0xFF, 0xD0])));
        assert!(jpeg_reaches_its_end(&scan(&[0xFF, 0xFF, 0xFF, 0xD3])));
        assert!(!jpeg_reaches_its_end(&scan(&[0xFF, 0xFF])[..14]));
    }

    #[test]
    fn damaged_float_data_is_described_in_words_not_bytes() {
        let samples: Vec<f32> = (0..4096).map(|i| i as f32).collect();
        let good = encode_floats(64, 64, 1, &samples, false);
        let mut cut = good.clone();
        cut.bytes.truncate(good.bytes.len() / 2);
        let e = decode_floats(&cut).unwrap_err().to_string();
        assert!(
            e.starts_with("corrupt float data: the compressed data ends early (truncated after ")
                && e.ends_with(" of 16384 bytes)")
                && e.len() < 120,
            "{e}"
        );
        let mut small = good.clone();
        small.width = 32;
        let e = decode_floats(&small).unwrap_err().to_string();
        assert_eq!(
            e,
            "corrupt float data: it inflates to more than the 8192 bytes the image's size allows"
        );
    }

    #[test]
    fn png_round_trips_color_and_depth() {
        let color = Image::from_vec(
            4,
            2,
            (0..8).map(|i| [i as u8 * 30, 7, 255 - i as u8]).collect(),
        )
        .unwrap();
        assert_eq!(
            decode_color(&encode_png_rgb8(&color).unwrap()).unwrap(),
            color
        );
        let units: Vec<u16> = (0..8).map(|i| i * 5000 + 3).collect();
        let enc = encode_png_u16(4, 2, units.clone()).unwrap();
        assert_eq!(decode_depth_units(&enc).unwrap().data, units);
        let metres = decode_depth(&enc, 0.0002).unwrap();
        assert!((metres.data[1] - 5003.0 * 0.0002).abs() < 1e-6);
    }

    #[test]
    fn wrong_sizes_and_garbage_are_errors() {
        let mut enc = encode_floats(2, 2, 1, &[1.0, 2.0, 3.0, 4.0], false);
        enc.width = 3;
        assert!(decode_floats(&enc).is_err());
        let garbage = EncodedImage {
            encoding: ImageEncoding::Png,
            width: 2,
            height: 2,
            channels: 3,
            bytes: vec![1, 2, 3],
        };
        assert!(decode_color(&garbage).is_err());
        assert!(wrap_image_file(vec![0; 10]).is_err());
    }
}
