//! The products a replay saved (`DIR/<product>/<frame>.png` and `.ply`), as MCAP
//! messages at their frames' stamps: PNGs as `foxglove.CompressedImage`, the
//! environment cloud's PLY as `foxglove.PointCloud` with the PLY's own packed layout.

use super::export_writer::{CAMERA_FRAME, Out, WORLD_FRAME, b64, time};
use crate::error::ImportError;
use crate::{Recording, Replay, ReplayOptions};
use serde_json::json;
use std::collections::BTreeMap;
use std::path::Path;

/// The vertex layout relume's PLY writer uses (`stages::write::ply`): 39 bytes.
const PLY_PROPERTIES: &[(&str, &str)] = &[
    ("float", "x"),
    ("float", "y"),
    ("float", "z"),
    ("uchar", "red"),
    ("uchar", "green"),
    ("uchar", "blue"),
    ("float", "nx"),
    ("float", "ny"),
    ("float", "nz"),
    ("float", "r_linear"),
    ("float", "g_linear"),
    ("float", "b_linear"),
];

/// The vertex bytes of a binary little-endian PLY in relume's layout.
pub fn ply_vertices(bytes: &[u8]) -> Result<(usize, &[u8]), String> {
    const END: &[u8] = b"end_header\n";
    let end = bytes
        .windows(END.len())
        .take(4096)
        .position(|w| w == END)
        .ok_or("no PLY header (`end_header` within 4 KiB)")?;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| "PLY header is not text")?;
    let mut lines = header.lines();
    if lines.next() != Some("ply") || lines.next() != Some("format binary_little_endian 1.0") {
        return Err("not a binary little-endian PLY".into());
    }
    let mut count = None;
    let mut properties = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words[..] {
            ["element", "vertex", n] => count = n.parse::<usize>().ok(),
            ["element", other, ..] => return Err(format!("unexpected PLY element `{other}`")),
            ["property", ty, name] => properties.push((ty, name)),
            _ => {}
        }
    }
    let count = count.ok_or("PLY header has no vertex count")?;
    if properties != PLY_PROPERTIES {
        return Err(
            "PLY vertices are not in relume's layout (x y z, rgb, normal, linear rgb)".into(),
        );
    }
    let body = &bytes[end + END.len()..];
    if Some(body.len()) != count.checked_mul(39) {
        return Err(format!(
            "PLY holds {} bytes of vertices for {count} vertices of 39 bytes",
            body.len()
        ));
    }
    Ok((count, body))
}

fn cloud_message(stamp_ns: i64, body: &[u8]) -> serde_json::Value {
    // foxglove.NumericType: UINT8 = 1, FLOAT32 = 7.
    let field =
        |name: &str, offset: u32, ty: u32| json!({"name": name, "offset": offset, "type": ty});
    json!({
        "timestamp": time(stamp_ns), "frame_id": WORLD_FRAME,
        "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
        "point_stride": 39,
        "fields": [field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("red", 12, 1),
                   field("green", 13, 1), field("blue", 14, 1), field("nx", 15, 7), field("ny", 19, 7),
                   field("nz", 23, 7), field("r_linear", 27, 7), field("g_linear", 31, 7), field("b_linear", 35, 7)],
        "data": b64(body),
    })
}

/// The frame index of a saved product's file name (`000012.png` -> 12).
fn frame_of(path: &Path) -> Option<usize> {
    let stem = path.file_stem()?.to_str()?;
    (stem.len() == 6 && stem.bytes().all(|b| b.is_ascii_digit()))
        .then(|| stem.parse().ok())
        .flatten()
}

/// Writes every PNG and PLY of `dir`'s product folders, counting the files written in
/// `products` (by product name) and saying in `warnings` what was skipped.
pub(super) fn write_products(
    rec: &Recording,
    dir: &Path,
    o: &mut Out,
    products: &mut BTreeMap<String, usize>,
    warnings: &mut Vec<String>,
) -> Result<(), ImportError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ImportError::Io { path, source }
    };
    let stamps = frame_stamps(rec)?;
    let header = rec.header();
    let sizes = [
        (
            header.color_intrinsics.width,
            header.color_intrinsics.height,
        ),
        (
            header.depth_intrinsics.width,
            header.depth_intrinsics.height,
        ),
    ];
    let mut other_files = 0usize;
    let mut folders: Vec<_> = std::fs::read_dir(dir)
        .map_err(io(dir))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    folders.sort();
    for folder in folders {
        let product = folder
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let mut files: Vec<_> = std::fs::read_dir(&folder)
            .map_err(io(&folder))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        files.sort();
        let topic = format!("/relume/{product}");
        for file in files {
            let ext = file.extension().and_then(|e| e.to_str()).unwrap_or("");
            if !matches!(ext, "png" | "ply") {
                other_files += 1;
                continue;
            }
            let Some(frame) = frame_of(&file) else {
                warnings.push(format!(
                    "{}: not named by a frame (000012.{ext}): skipped",
                    file.display()
                ));
                continue;
            };
            let Some(&stamp_ns) = stamps.get(frame) else {
                warnings.push(format!(
                    "{}: frame {frame} is not in the recording ({} frames): skipped",
                    file.display(),
                    stamps.len()
                ));
                continue;
            };
            let bytes = relume_base::files::read_regular(&file).map_err(io(&file))?;
            let bad = |e: String| ImportError::File {
                path: file.clone(),
                reason: e,
            };
            if ext == "png" {
                let (img, _) =
                    crate::codec::wrap_image_file(bytes.clone()).map_err(|e| bad(e.to_string()))?;
                if !sizes.contains(&(img.width, img.height)) {
                    warnings.push(format!(
                        "{}: {}x{} is the size of neither the recording's color nor its depth \
                         images (saved from another recording?): skipped",
                        file.display(),
                        img.width,
                        img.height
                    ));
                    continue;
                }
                let msg = json!({"timestamp": time(stamp_ns), "frame_id": CAMERA_FRAME, "format": "png", "data": b64(&bytes)});
                o.write(&topic, "foxglove.CompressedImage", stamp_ns, &msg)?;
            } else {
                let (_, body) = ply_vertices(&bytes).map_err(bad)?;
                o.write(
                    &topic,
                    "foxglove.PointCloud",
                    stamp_ns,
                    &cloud_message(stamp_ns, body),
                )?;
            }
            *products.entry(product.clone()).or_default() += 1;
        }
    }
    if other_files > 0 {
        warnings.push(format!(
            "{other_files} saved files in other formats (EXR, JSON, light records) are not \
             exported: MCAP viewers show the PNGs and the clouds"
        ));
    }
    if products.is_empty() {
        warnings.push(format!(
            "{}: no products exported: the folder should hold one folder per product with \
             files named by frame (000012.png), as `relume replay --save ... --out DIR` writes",
            dir.display()
        ));
    }
    Ok(())
}

/// Frame stamps of the replay of `rec` (frame k's stamp at index k).
fn frame_stamps(rec: &Recording) -> Result<Vec<i64>, ImportError> {
    let replay = Replay::open(rec.path(), ReplayOptions::default())?;
    Ok(replay.frames.iter().map(|f| f.stamp_ns).collect())
}
