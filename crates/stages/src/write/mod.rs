//! `write`: saves chosen products of every frame to `OUT/<dir>/<product>/<frame>.<ext>`.
//!
//! | product | png | exr |
//! |---|---|---|
//! | color | 8-bit sRGB | R, G, B = value / 255 |
//! | depth | 16-bit, millimetres, 0 = missing | Z, f32 metres, 0 = missing |
//! | points | 16-bit, z in millimetres | X, Y, Z f32 metres |
//! | normals | 8-bit RGB = (n + 1) / 2 for viewing, black = invalid | X, Y, Z f32 |
//! | HDR radiance | 8-bit, clamped to [0, 1], gamma 1/2.2, for viewing | R, G, B f32 |
//! | scalar map | 16-bit, value x 1000 (like depth in mm) | Y f32 |
//! | label map | 8-bit gray, the raw values | Y f32 |
//!
//! A color compensation is saved as `<frame>.json` (row-major matrices, pair counts),
//! the environment-sample cloud as `<frame>.ply` (binary PLY, see [`ply`]) and a light
//! model (`lights`, paper 004's area lights and SH) as `<frame>.val` (32 bytes per light
//! plus 108 of SH, see [`relume_scene::light::record`]), whatever the formats. A light model is
//! written when it changes, once per update: with `light.val`'s `every = 8`, files
//! appear for frames 0, 8, 16, ... (0, 9, 17, ... with `lag = 1` as well), and frame
//! t's model is the file of the largest frame <= t (with this stage's own `every`, of
//! the frames it writes).
//!
//! Every file is written to a temporary name and renamed, so an interrupted run leaves
//! complete files only.

use crate::compensate::Compensation;
use crate::{OpError, kind};
use rayon::prelude::*;
use relume_base::raster::{
    DepthImage, Image, LabelImage, Rgb8Image, ScalarImage, Vec3Image, depth_is_valid,
};
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Params, Port, Ports, Product, Stage, StageError, StageInfo,
};
use relume_recording::Pose;
use relume_recording::writer::write_file_atomic;
use relume_scene::light::AreaLights;
use relume_scene::light::EnvCloud;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub mod ply;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "products",
        ParamDefault::StrList(&["depth", "normals"]),
        "products to save: images, compensations (JSON), clouds (PLY) or light models (.val records, on each update)",
    ),
    ParamSpec::new(
        "formats",
        ParamDefault::StrList(&["png"]),
        "file formats to write for each product",
    )
    .choices(&["png", "exr"]),
    ParamSpec::new(
        "dir",
        ParamDefault::Str(""),
        "sub-directory of the output directory (--out) to write into",
    )
    .checked(check_dir),
    ParamSpec::new("every", ParamDefault::Int(1), "write every n-th frame only").range(1.0, 1e9),
];

/// `dir` is a folder under --out: an absolute path or `..` would write elsewhere, and
/// no file system takes a NUL byte in a name.
fn check_dir(dir: &str) -> Result<(), String> {
    if dir.contains('\0') {
        return Err(format!(
            "dir = {dir:?} holds a NUL byte, which no folder name can"
        ));
    }
    let inside = Path::new(dir).components().all(|c| {
        matches!(
            c,
            std::path::Component::Normal(_) | std::path::Component::CurDir
        )
    });
    if inside {
        Ok(())
    } else {
        Err(format!(
            "dir = {dir:?} must be a folder under the output directory (--out): no absolute \
             path, no `..`"
        ))
    }
}

pub const INFO: StageInfo = StageInfo {
    kind: "write",
    summary: "save chosen products per frame as PNG (depth 16-bit mm, normals for viewing) or EXR (f32)",
    params: PARAMS,
    ports,
    build: |ctx| {
        let p = ctx.params;
        check_dir(p.str("dir")).map_err(StageError::Failed)?;
        let dir = ctx.out_dir.join(p.str("dir"));
        let products: Vec<(String, PathBuf)> = p
            .str_list("products")
            .iter()
            .map(|role| (ctx.input(role), dir.join(role)))
            .collect();
        for (_, d) in &products {
            std::fs::create_dir_all(d).map_err(|source| StageError::Io {
                path: d.clone(),
                source,
            })?;
        }
        Ok(Box::new(Write {
            products,
            png: p.str_list("formats").iter().any(|f| f == "png"),
            exr: p.str_list("formats").iter().any(|f| f == "exr"),
            every: p.int("every") as usize,
            last_lights: Default::default(),
        }))
    },
};

fn ports(params: &Params) -> Ports {
    Ports {
        inputs: params
            .str_list("products")
            .iter()
            .map(|p| Port::new(p, p, kind::WRITABLE))
            .collect(),
        outputs: Vec::new(),
    }
}

struct Write {
    /// (product name in the frame, directory for its files)
    products: Vec<(String, PathBuf)>,
    png: bool,
    exr: bool,
    every: usize,
    /// Per product, the light model written last (a model is written once per update).
    last_lights: HashMap<String, Arc<AreaLights>>,
}

impl Stage for Write {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        if !frame.index.is_multiple_of(self.every) {
            return Ok(());
        }
        let stamp_ns = frame.stamp_ns;
        let mut jobs = Vec::new();
        for (name, dir) in &self.products {
            let product = frame
                .get(name)
                .ok_or_else(|| StageError::MissingInput(name.clone()))?;
            let stem = dir.join(format!("{:06}", frame.index));
            if let Some(model) = product.get::<Arc<AreaLights>>(kind::AREA_LIGHTS) {
                let last = self.last_lights.get(name);
                if last.is_some_and(|last| Arc::ptr_eq(last, model) || **last == **model) {
                    continue;
                }
                self.last_lights.insert(name.clone(), model.clone());
            }
            if !kind::is_image(product.kind()) {
                jobs.push((product, stem, false));
                continue;
            }
            if self.png {
                jobs.push((product, stem.with_extension("png"), false));
            }
            if self.exr {
                jobs.push((product, stem.with_extension("exr"), true));
            }
        }
        jobs.par_iter()
            .map(|(product, path, exr)| {
                if !kind::is_image(product.kind()) {
                    write_record(product, path, stamp_ns)
                } else if *exr {
                    write_exr(product, path)
                } else {
                    write_png(product, path)
                }
            })
            .collect::<Result<(), OpError>>()?;
        Ok(())
    }
}

/// A product the writer can save, by kind.
enum W<'a> {
    Color(&'a Rgb8Image),
    Depth(&'a DepthImage),
    Points(&'a Vec3Image),
    Normals(&'a Vec3Image),
    Radiance(&'a Vec3Image),
    Scalar(&'a ScalarImage),
    Labels(&'a LabelImage),
    Compensation(&'a Compensation),
    Cloud(&'a Arc<EnvCloud>),
    AreaLights(&'a Arc<AreaLights>),
    Pose(&'a Pose),
}

/// `product` as the writer sees it; `None` for kinds it cannot save.
fn view(product: &Product) -> Option<W<'_>> {
    let k = product.kind();
    Some(if k == kind::COLOR {
        W::Color(product.value()?)
    } else if k == kind::DEPTH {
        W::Depth(product.value()?)
    } else if k == kind::POINTS {
        W::Points(product.value()?)
    } else if k == kind::NORMALS {
        W::Normals(product.value()?)
    } else if k == kind::RADIANCE {
        W::Radiance(product.value()?)
    } else if k == kind::SCALAR {
        W::Scalar(product.value()?)
    } else if k == kind::LABELS {
        W::Labels(product.value()?)
    } else if k == kind::COMPENSATION {
        W::Compensation(product.value()?)
    } else if k == kind::CLOUD {
        W::Cloud(product.value()?)
    } else if k == kind::AREA_LIGHTS {
        W::AreaLights(product.value()?)
    } else if k == kind::POSE {
        W::Pose(product.value()?)
    } else {
        return None;
    })
}

/// Writes a product as PNG (see the module table).
pub fn write_png(product: &Product, path: &Path) -> Result<(), OpError> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let mm = |z: f32| {
        if depth_is_valid(z) {
            (z * 1000.0).round().clamp(0.0, 65535.0) as u16
        } else {
            0
        }
    };
    let (w, h) = image_size(product)?;
    let img = match view(product) {
        Some(W::Color(c)) => image::DynamicImage::ImageRgb8(
            image::RgbImage::from_raw(w, h, bytemuck::cast_slice(&c.data).to_vec())
                .expect("size checked"),
        ),
        Some(W::Depth(d)) => image::DynamicImage::ImageLuma16(
            image::ImageBuffer::from_raw(w, h, d.data.iter().map(|&z| mm(z)).collect())
                .expect("size checked"),
        ),
        Some(W::Points(p)) => image::DynamicImage::ImageLuma16(
            image::ImageBuffer::from_raw(w, h, p.data.iter().map(|v| mm(v.z)).collect())
                .expect("size checked"),
        ),
        Some(W::Normals(n)) => {
            let bytes = n
                .data
                .iter()
                .flat_map(|v| {
                    if *v == glam::Vec3::ZERO {
                        [0; 3]
                    } else {
                        v.to_array()
                            .map(|c| ((c + 1.0) * 127.5).round().clamp(0.0, 255.0) as u8)
                    }
                })
                .collect();
            image::DynamicImage::ImageRgb8(
                image::RgbImage::from_raw(w, h, bytes).expect("size checked"),
            )
        }
        Some(W::Radiance(r)) => {
            let bytes = r
                .data
                .iter()
                .flat_map(|v| v.to_array().map(ply::display_level))
                .collect();
            image::DynamicImage::ImageRgb8(
                image::RgbImage::from_raw(w, h, bytes).expect("size checked"),
            )
        }
        Some(W::Scalar(s)) => image::DynamicImage::ImageLuma16(
            image::ImageBuffer::from_raw(
                w,
                h,
                s.data
                    .iter()
                    .map(|&v| {
                        if v.is_finite() {
                            (v * 1000.0).round().clamp(0.0, 65535.0) as u16
                        } else {
                            0
                        }
                    })
                    .collect(),
            )
            .expect("size checked"),
        ),
        Some(W::Labels(l)) => image::DynamicImage::ImageLuma8(
            image::GrayImage::from_raw(w, h, l.data.clone()).expect("size checked"),
        ),
        _ => unreachable!("image_size accepts images only"),
    };
    let mut bytes = Vec::new();
    img.write_with_encoder(PngEncoder::new_with_quality(
        &mut bytes,
        CompressionType::Fast,
        FilterType::Adaptive,
    ))
    .map_err(|e| OpError::Unwritable(format!("{}: PNG encoding failed: {e}", path.display())))?;
    write_file_atomic(path, &bytes).map_err(|source| OpError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes a non-image product of the frame stamped `stamp_ns` next to `stem`: a
/// compensation as `.json`, a cloud as `.ply`, a light model as `.val`, a pose as
/// `.txt` (one line of a TUM trajectory, see [`tum_pose_line`]: the files of a run,
/// concatenated in order, are the trajectory).
pub fn write_record(product: &Product, stem: &Path, stamp_ns: i64) -> Result<(), OpError> {
    let (path, bytes) = match view(product) {
        Some(W::Pose(pose)) => (
            stem.with_extension("txt"),
            tum_pose_line(stamp_ns, pose).into_bytes(),
        ),
        Some(W::Compensation(c)) => (
            stem.with_extension("json"),
            serde_json::to_vec_pretty(&c.to_json()).expect("JSON of plain values"),
        ),
        Some(W::Cloud(cloud)) => (stem.with_extension("ply"), ply::ply_bytes(cloud)),
        Some(W::AreaLights(model)) => (
            stem.with_extension("val"),
            relume_scene::light::record::encode(model)
                .map_err(|e| OpError::Unwritable(e.to_string()))?,
        ),
        _ => {
            return Err(OpError::Unwritable(format!(
                "a {} cannot be written to a file",
                product.kind().name()
            )));
        }
    };
    write_file_atomic(&path, &bytes).map_err(|source| OpError::Io { path, source })
}

/// A pose as a line of a TUM RGB-D trajectory file: `timestamp tx ty tz qx qy qz qw`,
/// seconds and metres, the camera's position and orientation in the world (the format
/// the TUM benchmark's tools, evo and Open3D read).
pub fn tum_pose_line(stamp_ns: i64, pose: &Pose) -> String {
    let (t, q) = (pose.translation(), pose.rotation());
    let (sign, ns) = (if stamp_ns < 0 { "-" } else { "" }, stamp_ns.unsigned_abs());
    let seconds = format!("{sign}{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000);
    format!(
        "{seconds} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}\n",
        t.x, t.y, t.z, q.x, q.y, q.z, q.w
    )
}

/// Writes a product as EXR with f32 channels (see the module table).
pub fn write_exr(product: &Product, path: &Path) -> Result<(), OpError> {
    let channels: Vec<(&str, Vec<f32>)> = match view(product) {
        Some(W::Color(c)) => (0..3)
            .map(|i| {
                (
                    ["R", "G", "B"][i],
                    c.data.iter().map(|p| p[i] as f32 / 255.0).collect(),
                )
            })
            .collect(),
        Some(W::Depth(d)) => vec![(
            "Z",
            d.data
                .iter()
                .map(|&z| if depth_is_valid(z) { z } else { 0.0 })
                .collect(),
        )],
        Some(W::Points(v) | W::Normals(v)) => (0..3)
            .map(|i| (["X", "Y", "Z"][i], v.data.iter().map(|p| p[i]).collect()))
            .collect(),
        Some(W::Radiance(v)) => (0..3)
            .map(|i| (["R", "G", "B"][i], v.data.iter().map(|p| p[i]).collect()))
            .collect(),
        Some(W::Scalar(s)) => vec![("Y", s.data.clone())],
        Some(W::Labels(l)) => vec![("Y", l.data.iter().map(|&v| v as f32).collect())],
        _ => {
            return Err(OpError::Unwritable(format!(
                "a {} cannot be written as an image",
                product.kind().name()
            )));
        }
    };
    let (w, h) = image_size(product)?;
    // Radiance is a renderer's f32 estimate, noise down to its last bits: run-length
    // coding never shortens it (the default's final_hdr: 3,689,030 bytes as RLE tiles,
    // 3,694,445 as plain scan lines, the difference the layout's) and took half of
    // write.hdr's time. Depth, masks, labels and colours hold runs of equal values.
    let compress = !product.is(kind::RADIANCE);
    let bytes = exr_bytes(w, h, channels, compress).map_err(|e| {
        OpError::Unwritable(format!("{}: EXR encoding failed: {e}", path.display()))
    })?;
    write_file_atomic(path, &bytes).map_err(|source| OpError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Encodes named f32 channels as a single-layer EXR: losslessly compressed (RLE, 64 x 64
/// tiles) when `compress`, else uncompressed scan lines.
pub fn exr_bytes(
    width: u32,
    height: u32,
    channels: Vec<(&str, Vec<f32>)>,
    compress: bool,
) -> Result<Vec<u8>, exr::error::Error> {
    use exr::prelude::*;
    let list: Vec<AnyChannel<FlatSamples>> = channels
        .into_iter()
        .map(|(name, samples)| AnyChannel::new(name, FlatSamples::F32(samples)))
        .collect();
    let layer = Layer::new(
        (width as usize, height as usize),
        LayerAttributes::default(),
        if compress {
            Encoding::FAST_LOSSLESS
        } else {
            Encoding::UNCOMPRESSED
        },
        AnyChannels::sort(list.into()),
    );
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut out)?;
    Ok(out.into_inner())
}

fn image_size(product: &Product) -> Result<(u32, u32), OpError> {
    fn size<T>(i: &Image<T>) -> (u32, u32) {
        (i.width, i.height)
    }
    match view(product) {
        Some(W::Color(i)) => Ok(size(i)),
        Some(W::Depth(i)) => Ok(size(i)),
        Some(W::Points(i) | W::Normals(i) | W::Radiance(i)) => Ok(size(i)),
        Some(W::Scalar(i)) => Ok(size(i)),
        Some(W::Labels(i)) => Ok(size(i)),
        _ => Err(OpError::Unwritable(format!(
            "a {} cannot be written as an image",
            product.kind().name()
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use relume_graph::{BuildContext, ParamValue};
    use relume_recording::{Header, Intrinsics};
    use relume_scene::light::{AreaLight, AreaLights, record};
    use std::collections::BTreeMap;

    #[test]
    fn a_pose_is_a_tum_trajectory_line() {
        let half_turn_about_y = glam::DQuat::from_rotation_y(std::f64::consts::PI);
        let pose = Pose::from_parts(glam::DVec3::new(1.0, -0.25, 3.5), half_turn_about_y);
        assert_eq!(
            tum_pose_line(1_305_031_102_175_304_000, &pose),
            "1305031102.175304000 1.000000000 -0.250000000 3.500000000 0.000000000 \
             1.000000000 0.000000000 0.000000000\n"
        );
        assert!(tum_pose_line(-5, &Pose::IDENTITY).starts_with("-0.000000005 "));
    }

    fn model(intensity: f32) -> Arc<AreaLights> {
        Arc::new(AreaLights {
            lights: vec![AreaLight {
                position: Vec3::new(0.0, 2.5, 0.0),
                normal: -Vec3::Y,
                intensity: Vec3::splat(intensity),
                area: 0.5,
            }],
            sh9: [Vec3::splat(0.1); 9],
        })
    }

    #[test]
    fn a_light_model_is_written_once_per_update_as_a_record() {
        let out = std::env::temp_dir().join(format!("relume-write-val-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let mut params = Params::defaults(PARAMS);
        params.set("products", ParamValue::StrList(vec!["lights".into()]));
        let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
        let ctx = BuildContext {
            stage_name: "write",
            params: &params,
            inputs: &BTreeMap::new(),
            outputs: &BTreeMap::new(),
            header: &header,
            out_dir: &out,
            seed: 0,
            world: &crate::world::world_of(relume_scene::objects::VirtualScene::default()),
        };
        let mut stage = (INFO.build)(&ctx).unwrap();
        // Frames 0-2 share one update (as `every = 3` lends it), frame 3 brings a new
        // one, frame 4 an equal model in a new allocation (no change: not written).
        let (first, second) = (model(1.0), model(2.0));
        for (index, m) in [&first, &first, &first, &second, &model(2.0)]
            .into_iter()
            .enumerate()
        {
            let mut frame = Frame::new(index, 0);
            frame.insert("lights", Product::new(kind::AREA_LIGHTS, m.clone()));
            stage.process(&mut frame).unwrap();
        }
        let mut files: Vec<String> = std::fs::read_dir(out.join("lights"))
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        files.sort();
        assert_eq!(files, ["000000.val", "000003.val"]);
        let bytes = std::fs::read(out.join("lights/000003.val")).unwrap();
        assert_eq!(bytes.len(), 8 + 32 + 108);
        assert_eq!(record::decode(&bytes).unwrap(), *second);
        std::fs::remove_dir_all(&out).unwrap();
    }
}
