//! Loading HDR lat-long environment maps: OpenEXR files (scanline or tiled, with or
//! without mip/rip levels: the largest level is read), Radiance `.hdr` (RGBE) files, and
//! the recording's `environment` attachment (kind `envmap/latlong`).
//!
//! Layout: a file's pixel rows run from the zenith (row 0, world +y) to the nadir, and
//! its columns map one to one onto ours: column c looks along phi = (c + 0.5) / W * 2 pi,
//! phi measured from world +x towards +z (the convention of [`crate::light`] and of the
//! synthetic recording's attachment). OpenEXR's own `envmap = latlong` convention
//! (longitude 0 along +z, +pi/2 along +x, +pi at the left edge) is that map turned by
//! 90 degrees about +y: `light.envmap`'s `rotation_deg = 90` reproduces it.
//!
//! Texels that are non-finite or have a negative channel carry no meaningful radiance:
//! they become 0 and the loaders return how many there were.

use super::EnvMap;
use glam::Vec3;
use relume_recording::codec::{MAX_PIXELS, decode_floats};

/// The largest side of a map read from a file, as for images elsewhere.
const MAX_SIDE: usize = 16_384;
use relume_recording::{Attachment, Header};
use rgbe::decode_rgbe;
use std::path::{Path, PathBuf};

mod rgbe;

/// The attachment kind of a lat-long environment map.
pub const LATLONG_KIND: &str = "envmap/latlong";

/// Why an environment map could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LightError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: cannot read the OpenEXR environment map: {message}", path.display())]
    Exr { path: PathBuf, message: String },
    #[error("{}: cannot read the Radiance HDR environment map: {message}", path.display())]
    Hdr { path: PathBuf, message: String },
    #[error(
        "{}: not an environment map relume reads (expected an OpenEXR file or a Radiance .hdr file)",
        path.display()
    )]
    UnknownFormat { path: PathBuf },
    #[error("attachment `{name}`: {message}")]
    Attachment { name: String, message: String },
}

/// A loaded map and the number of texels that were non-finite or negative and were set
/// to 0.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedEnvMap {
    pub map: EnvMap,
    pub replaced_texels: usize,
}

/// Loads a lat-long environment map from an OpenEXR or Radiance `.hdr` file (told apart
/// by their magic bytes), as a distant map seen from the origin. Bad texels are set to
/// 0; [`load_envmap_counted`] also says how many.
pub fn load_envmap(path: impl AsRef<Path>) -> Result<EnvMap, LightError> {
    load_envmap_counted(path).map(|l| l.map)
}

/// [`load_envmap`] with the count of texels set to 0.
pub fn load_envmap_counted(path: impl AsRef<Path>) -> Result<LoadedEnvMap, LightError> {
    let path = path.as_ref();
    let bytes = relume_base::files::read_regular(path).map_err(|source| LightError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let (width, height, mut radiance) = if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        read_exr(&bytes).map_err(|message| LightError::Exr {
            path: path.to_path_buf(),
            message,
        })?
    } else if bytes.starts_with(b"#?") {
        decode_rgbe(&bytes).map_err(|message| LightError::Hdr {
            path: path.to_path_buf(),
            message,
        })?
    } else {
        return Err(LightError::UnknownFormat {
            path: path.to_path_buf(),
        });
    };
    let replaced_texels = sanitize(&mut radiance);
    Ok(LoadedEnvMap {
        map: EnvMap::distant(width, height, radiance),
        replaced_texels,
    })
}

/// Sets every texel that is non-finite or has a negative channel to 0 and returns how
/// many there were.
pub fn sanitize(radiance: &mut [Vec3]) -> usize {
    let mut replaced = 0;
    for c in radiance {
        if !c.is_finite() || c.min_element() < 0.0 {
            *c = Vec3::ZERO;
            replaced += 1;
        }
    }
    replaced
}

/// The R, G, B channels of the first layer that has them, at its largest resolution
/// level (tiled multi-resolution files keep their full map there).
fn read_exr(bytes: &[u8]) -> Result<(u32, u32, Vec<Vec3>), String> {
    use exr::prelude::*;
    // The headers first: the exr crate sizes its decompression buffers by each layer's
    // data window, and a window whose minimum lies past its maximum made it ask for
    // gigabytes (a fuzz finding: x from 788529152 to 7, 9.4 GB for one block).
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| e.to_string())?;
    for header in meta.headers.iter() {
        let size = header.layer_size;
        let area = size.width() as u64 * size.height() as u64;
        if size.width() > MAX_SIDE || size.height() > MAX_SIDE || area > MAX_PIXELS {
            return Err(format!(
                "a layer's data window is {}x{} pixels: over {MAX_SIDE} a side or {MAX_PIXELS} \
                 pixels (a damaged header?)",
                size.width(),
                size.height()
            ));
        }
    }
    struct Pixels {
        width: usize,
        data: Vec<Vec3>,
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            |size, _| {
                // Implausible sizes are refused below instead of allocated.
                let area = size.width() as u64 * size.height() as u64;
                let n = if area <= MAX_PIXELS { area as usize } else { 0 };
                Pixels {
                    width: size.width(),
                    data: vec![Vec3::ZERO; n],
                }
            },
            |pixels: &mut Pixels, at: Vec2<usize>, (r, g, b): (f32, f32, f32)| {
                if let Some(p) = pixels.data.get_mut(at.y() * pixels.width + at.x()) {
                    *p = Vec3::new(r, g, b);
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| match e {
            exr::error::Error::Invalid(m) if m.contains("no layer") => {
                format!("{m} (a map needs R, G and B channels in one layer)")
            }
            other => other.to_string(),
        })?;
    let size = image.layer_data.size;
    let (w, h) = (size.width(), size.height());
    let data = image.layer_data.channel_data.pixels.data;
    if w == 0 || h == 0 || data.len() != w * h {
        return Err(format!("implausible map size {w}x{h}"));
    }
    Ok((w as u32, h as u32, data))
}

/// The lat-long map of an `envmap/latlong` attachment (float RGB, or RGBA whose alpha is
/// ignored, or gray), as a distant map seen from the origin (the caller sets `center`;
/// see [`environment_from_header`]). Bad texels are set to 0.
pub fn envmap_from_attachment(attachment: &Attachment) -> Result<EnvMap, LightError> {
    envmap_from_attachment_counted(attachment).map(|l| l.map)
}

/// [`envmap_from_attachment`] with the count of texels set to 0.
pub fn envmap_from_attachment_counted(attachment: &Attachment) -> Result<LoadedEnvMap, LightError> {
    let fail = |message: String| LightError::Attachment {
        name: attachment.name.clone(),
        message,
    };
    if attachment.kind != LATLONG_KIND {
        return Err(fail(format!(
            "is a `{}`, not an `{LATLONG_KIND}` environment map",
            attachment.kind
        )));
    }
    let image = &attachment.image;
    let samples = decode_floats(image).map_err(|e| fail(e.to_string()))?;
    let channels = image.channels as usize;
    let mut radiance: Vec<Vec3> = match channels {
        1 => samples.iter().map(|&v| Vec3::splat(v)).collect(),
        3 | 4 => samples
            .chunks_exact(channels)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect(),
        n => return Err(fail(format!("has {n} channels (expected 1, 3 or 4)"))),
    };
    if radiance.len() != image.width as usize * image.height as usize {
        return Err(fail(format!(
            "holds {} texels for a {}x{} map",
            radiance.len(),
            image.width,
            image.height
        )));
    }
    let replaced_texels = sanitize(&mut radiance);
    Ok(LoadedEnvMap {
        map: EnvMap::distant(image.width, image.height, radiance),
        replaced_texels,
    })
}

/// The environment map of `header`'s attachment `name`, seen from the ground truth's
/// `object_position` when the header has one (the synthetic recording renders it from
/// there), else from the origin. A missing attachment is an error that lists the
/// attachments the recording has.
pub fn environment_from_header(header: &Header, name: &str) -> Result<LoadedEnvMap, LightError> {
    let Some(attachment) = header.attachment(name) else {
        let have: Vec<String> = header
            .attachments
            .iter()
            .map(|a| format!("`{}` ({})", a.name, a.kind))
            .collect();
        return Err(LightError::Attachment {
            name: name.to_string(),
            message: format!(
                "recording `{}` has no such attachment (it has {}); light from a file with `source = \"file\"` and `path`, or from the cloud with `light.impostor`",
                header.name,
                if have.is_empty() {
                    "none".to_string()
                } else {
                    have.join(", ")
                }
            ),
        });
    };
    let mut loaded = envmap_from_attachment_counted(attachment)?;
    if let Some(truth) = &header.ground_truth {
        loaded.map.center = glam::DVec3::from_array(truth.object_position).as_vec3();
    }
    Ok(loaded)
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_recording::codec::encode_floats;
    use relume_recording::{Intrinsics, SceneTruth};

    /// A test map whose texel (x, y) has radiance (x, y, x + y) / 8, with a few bad
    /// texels.
    fn texel_value(x: usize, y: usize) -> (f32, f32, f32) {
        match (x, y) {
            (1, 0) => (f32::NAN, 1.0, 1.0),
            (2, 1) => (1.0, -0.5, 1.0),
            (3, 2) => (f32::INFINITY, 0.0, 0.0),
            _ => (x as f32 / 8.0, y as f32 / 8.0, (x + y) as f32 / 8.0),
        }
    }

    fn check_test_map(loaded: &LoadedEnvMap, w: u32, h: u32) {
        assert_eq!((loaded.map.width, loaded.map.height), (w, h));
        assert_eq!(loaded.replaced_texels, 3);
        assert!(loaded.map.distance.iter().all(|d| *d == f32::INFINITY));
        for y in 0..h as usize {
            for x in 0..w as usize {
                let got = loaded.map.radiance[y * w as usize + x];
                let expected = match (x, y) {
                    (1, 0) | (2, 1) | (3, 2) => Vec3::ZERO,
                    _ => Vec3::from(texel_value(x, y)),
                };
                assert_eq!(got, expected, "texel ({x}, {y})");
            }
        }
    }

    #[test]
    fn scanline_exr_loads_with_rows_and_columns_in_place_and_bad_texels_zeroed() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scan.exr");
        exr::prelude::write_rgb_file(&path, 16, 8, texel_value).unwrap();
        check_test_map(&load_envmap_counted(&path).unwrap(), 16, 8);
    }

    #[test]
    fn tiled_mipmapped_exr_loads_its_largest_level() {
        use exr::math::RoundingMode;
        use exr::prelude::*;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("tiled.exr");
        let full = Vec2(32usize, 16usize);
        let levels: Vec<_> = exr::meta::mip_map_levels(RoundingMode::Down, full).collect();
        let channel = |name: &str, pick: fn((f32, f32, f32)) -> f32| {
            // Level 0 holds the test map; the smaller levels hold 7 (not what we want).
            let data = levels
                .iter()
                .map(|&(index, size)| {
                    let samples = (0..size.area())
                        .map(|i| {
                            if index == 0 {
                                pick(texel_value(i % size.width(), i / size.width()))
                            } else {
                                7.0
                            }
                        })
                        .collect();
                    FlatSamples::F32(samples)
                })
                .collect();
            AnyChannel::new(
                name,
                Levels::Mip {
                    level_data: data,
                    rounding_mode: RoundingMode::Down,
                },
            )
        };
        let channels = AnyChannels::sort(
            vec![
                channel("R", |c| c.0),
                channel("G", |c| c.1),
                channel("B", |c| c.2),
            ]
            .into(),
        );
        let encoding = Encoding {
            compression: Compression::ZIP16,
            blocks: Blocks::Tiles(Vec2(8, 8)),
            line_order: LineOrder::Increasing,
        };
        let layer = Layer::new(full, LayerAttributes::default(), encoding, channels);
        Image::from_layer(layer).write().to_file(&path).unwrap();
        check_test_map(&load_envmap_counted(&path).unwrap(), 32, 16);
    }

    #[test]
    fn a_radiance_hdr_loads_as_decoded_row_by_row() {
        // decode_rgbe's own test checks the values; this one, that the loader keeps its
        // layout: row 0 of the file is row 0 of the map, x runs along the row.
        let value = |x: usize, y: usize| ((x / 4) as f32 + 1.0, 2f32.powi(y as i32 - 3), 0.25);
        let bytes = super::rgbe::tests::hdr_bytes(32, 8, value, true);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.hdr");
        std::fs::write(&path, &bytes).unwrap();
        let map = load_envmap(&path).unwrap();
        let (width, height, radiance) = decode_rgbe(&bytes).unwrap();
        assert_eq!((map.width, map.height), (width, height));
        assert_eq!((map.width, map.height), (32, 8));
        assert_eq!(map.radiance, radiance);
        let first = map.radiance[0];
        let last = map.radiance[7 * 32 + 31];
        assert!(first.x < last.x && first.y < last.y, "{first} {last}");
    }

    #[test]
    fn missing_unknown_and_broken_files_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nope.exr");
        assert!(
            load_envmap(&missing)
                .unwrap_err()
                .to_string()
                .contains("nope.exr")
        );
        let text = dir.path().join("notes.txt");
        std::fs::write(&text, "hello").unwrap();
        let message = load_envmap(&text).unwrap_err().to_string();
        assert!(
            message.contains("notes.txt") && message.contains("OpenEXR"),
            "{message}"
        );
        let broken = dir.path().join("broken.exr");
        std::fs::write(&broken, [0x76, 0x2f, 0x31, 0x01, 2, 0, 0]).unwrap();
        let message = load_envmap(&broken).unwrap_err().to_string();
        assert!(
            message.contains("broken.exr") && message.contains("OpenEXR"),
            "{message}"
        );
        // A Radiance file cut off after its header (the decoder is tested in `rgbe`).
        let broken_hdr = dir.path().join("broken.hdr");
        std::fs::write(
            &broken_hdr,
            "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n",
        )
        .unwrap();
        let message = load_envmap(&broken_hdr).unwrap_err().to_string();
        assert!(
            message.contains("broken.hdr")
                && message.contains("Radiance HDR")
                && message.contains("scanline 0"),
            "{message}"
        );
        // An EXR without color channels.
        use exr::prelude::WritableImage;
        let gray = dir.path().join("gray.exr");
        let layer = exr::prelude::Layer::new(
            (4, 2),
            exr::prelude::LayerAttributes::default(),
            exr::prelude::Encoding::FAST_LOSSLESS,
            exr::prelude::AnyChannels::sort(
                vec![exr::prelude::AnyChannel::new(
                    "Y",
                    exr::prelude::FlatSamples::F32(vec![1.0; 8]),
                )]
                .into(),
            ),
        );
        exr::prelude::Image::from_layer(layer)
            .write()
            .to_file(&gray)
            .unwrap();
        let message = load_envmap(&gray).unwrap_err().to_string();
        assert!(
            message.contains("gray.exr") && message.contains("R, G and B"),
            "{message}"
        );
    }

    #[test]
    fn attachment_decodes_with_the_object_position_as_centre() {
        let samples: Vec<f32> = (0..8 * 4)
            .flat_map(|i| [i as f32, 1.0, if i == 5 { f32::NAN } else { 0.5 }])
            .collect();
        let attachment = Attachment {
            name: "environment".into(),
            kind: LATLONG_KIND.into(),
            image: encode_floats(8, 4, 3, &samples, false),
        };
        let map = envmap_from_attachment(&attachment).unwrap();
        assert_eq!((map.width, map.height), (8, 4));
        assert_eq!(map.radiance[9], Vec3::new(9.0, 1.0, 0.5));
        assert_eq!(map.radiance[5], Vec3::ZERO);

        let mut header = Header::new("room", Intrinsics::PRIMESENSE, 0.001);
        let message = environment_from_header(&header, "environment")
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("has none") && message.contains("source = \"file\""),
            "{message}"
        );
        header.attachments.push(attachment.clone());
        header.ground_truth = Some(SceneTruth {
            object_position: [0.0, 0.3, 0.0],
            description: String::new(),
        });
        let loaded = environment_from_header(&header, "environment").unwrap();
        assert_eq!(loaded.replaced_texels, 1);
        assert_eq!(loaded.map.center, Vec3::new(0.0, 0.3, 0.0));
        let message = environment_from_header(&header, "probe")
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("`environment` (envmap/latlong)"),
            "{message}"
        );

        let wrong = Attachment {
            kind: "image/png".into(),
            ..attachment
        };
        assert!(
            envmap_from_attachment(&wrong)
                .unwrap_err()
                .to_string()
                .contains("image/png")
        );
    }

    /// `RELUME_DATA`, else `../shared/data` beside the workspace.
    pub(crate) fn shared_data() -> PathBuf {
        std::env::var_os("RELUME_DATA")
            .map(PathBuf::from)
            .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"))
    }

    #[test]
    fn kerner_map_loads_at_full_resolution() {
        let path = shared_data().join("envmaps/KernerEnvLatLong.exr");
        assert!(
            path.exists(),
            "{} is missing: set RELUME_DATA to the shared data directory",
            path.display()
        );
        let loaded = load_envmap_counted(&path).unwrap();
        let map = &loaded.map;
        assert_eq!((map.width, map.height), (1024, 512));
        let max = map
            .radiance
            .iter()
            .map(|c| c.max_element())
            .fold(0.0, f32::max);
        eprintln!(
            "Kerner: max {max}, {} texels replaced",
            loaded.replaced_texels
        );
        assert!((1600.0..1750.0).contains(&max), "{max}");
        let dist = crate::light::Distribution2D::from_env(map);
        let integral = crate::light::pdf_integral(&dist);
        assert!((integral - 1.0).abs() < 1e-3, "{integral}");
    }

    /// Writes the seed corpus of the `envmap` fuzz target (`fuzz/seeds/envmap`): small
    /// scanline EXRs (uncompressed, ZIP, RLE, PIZ), and Radiance `.hdr` files flat and
    /// run-length encoded. Run with
    /// `cargo test -p relume-scene write_fuzz_seeds -- --ignored`.
    #[test]
    #[ignore = "writes files into fuzz/seeds/envmap"]
    fn write_fuzz_seeds() {
        use exr::prelude::*;
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/seeds/envmap");
        std::fs::create_dir_all(&dir).unwrap();
        for (name, compression) in [
            ("scanline-uncompressed.exr", Compression::Uncompressed),
            ("scanline-zip.exr", Compression::ZIP1),
            ("scanline-rle.exr", Compression::RLE),
            ("scanline-piz.exr", Compression::PIZ),
        ] {
            let channels = SpecificChannels::rgb(|p: Vec2<usize>| texel_value(p.x(), p.y()));
            let layer = Layer::new(
                Vec2(8usize, 4usize),
                LayerAttributes::default(),
                Encoding {
                    compression,
                    blocks: Blocks::ScanLines,
                    line_order: LineOrder::Increasing,
                },
                channels,
            );
            Image::from_layer(layer)
                .write()
                .to_file(dir.join(name))
                .unwrap();
        }
        let value = |x: usize, y: usize| (x as f32 + 0.5, y as f32 * 0.25, 1.0);
        for (name, rle) in [("flat.hdr", false), ("rle.hdr", true)] {
            let bytes = super::rgbe::tests::hdr_bytes(16, 4, value, rle);
            std::fs::write(dir.join(name), bytes).unwrap();
        }
    }
}
