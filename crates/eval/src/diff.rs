//! `relume diff`: two folders of saved products (`relume replay --out`, `--save`, or
//! a `relume compare` run's `runs/LABEL/`) compared frame by frame, per product.
//!
//! A product is a folder holding files (`final/`, `depth/`, `x/final/` for a `write`
//! stage with `dir = "x"`: paths relative to the run); its frames are the files in it,
//! matched by name. Images are compared value by value over the file's own channels:
//! PNG on its own scale (0-255 for 8-bit, 0-65535 for 16-bit: millimetres for depth),
//! EXR in its linear values (PSNR peak: the largest finite magnitude in the first run's
//! frame, at least 1; NaN in both counts as equal). Any other file (JSON, PLY) is equal
//! or not, byte for byte. A frame that does not decode, or is larger than
//! [`MAX_SIDE`] a side or [`MAX_PIXELS`] in all, cannot be compared: the diff stops
//! with an error naming the file (the command exits 2, "unreadable", not 1, "differ").
//! Folders are followed through symbolic links, each real folder once.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Why two runs could not be compared.
#[derive(Debug, thiserror::Error)]
pub enum DiffError {
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },
}

/// The widest or tallest image a diff decodes.
pub const MAX_SIDE: u64 = 16384;
/// The most pixels of one image a diff decodes (each value is held as an f64: 64
/// megapixels of RGB are 1.5 GB).
pub const MAX_PIXELS: u64 = 64 << 20;

/// Refuses an image of `width` x `height` beyond [`MAX_SIDE`] or [`MAX_PIXELS`].
fn check_size(path: &Path, width: u64, height: u64) -> Result<(), DiffError> {
    if width > MAX_SIDE || height > MAX_SIDE || width * height > MAX_PIXELS {
        return Err(file_error(
            path,
            format!(
                "the image is {width}x{height}: relume diff compares images of up to \
                 {MAX_SIDE} pixels a side and {} megapixels",
                MAX_PIXELS >> 20
            ),
        ));
    }
    Ok(())
}

fn file_error(path: &Path, message: impl std::fmt::Display) -> DiffError {
    DiffError::File {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// When a frame counts as differing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Tolerance {
    /// The largest absolute difference of one value that still counts as equal
    /// (`None` with `min_psnr_db` set: not checked; both `None`: 0, exact).
    pub max_abs: Option<f64>,
    /// The lowest PSNR that still counts as equal.
    pub min_psnr_db: Option<f64>,
}

impl Tolerance {
    fn exceeded(&self, f: &FrameDiff) -> bool {
        let abs = match (self.max_abs, self.min_psnr_db) {
            (Some(t), _) => f.max_abs > t,
            (None, None) => f.max_abs > 0.0,
            (None, Some(_)) => false,
        };
        let psnr = self.min_psnr_db.is_some_and(|m| f.psnr_db < m);
        abs || psnr || f.incomparable.is_some()
    }
}

/// One frame file of one product in both runs.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FrameDiff {
    pub file: String,
    /// The largest absolute difference of one value (infinite where incomparable).
    pub max_abs: f64,
    /// Infinite when equal.
    pub psnr_db: f64,
    /// Why the two could not be compared value by value (size, channels, bytes).
    pub incomparable: Option<String>,
}

/// One product in both runs.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ProductDiff {
    pub product: String,
    /// Frames (files) in both runs.
    pub frames: usize,
    /// Frames beyond the tolerance.
    pub differing: usize,
    /// The first of them (file name).
    pub first_differing: Option<String>,
    /// The lowest PSNR and largest difference over the frames.
    pub worst_psnr_db: f64,
    pub max_abs: f64,
    /// Files in one run only.
    pub only_in_a: Vec<String>,
    pub only_in_b: Vec<String>,
}

impl ProductDiff {
    /// True when the product differs beyond the tolerance, or a frame is missing.
    pub fn differs(&self) -> bool {
        self.differing > 0 || !self.only_in_a.is_empty() || !self.only_in_b.is_empty()
    }
}

/// The whole comparison.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RunDiff {
    pub products: Vec<ProductDiff>,
    /// Products (folders) in one run only.
    pub only_in_a: Vec<String>,
    pub only_in_b: Vec<String>,
}

impl RunDiff {
    pub fn differs(&self) -> bool {
        !self.only_in_a.is_empty()
            || !self.only_in_b.is_empty()
            || self.products.iter().any(ProductDiff::differs)
    }
}

/// The files of `root`, by the folder (relative to `root`, `/`-separated; `.` for
/// `root` itself) that holds them. Hidden entries (a killed run's `.partial` files) are
/// left out. A folder reached twice (a symbolic link back up the tree) is read once.
fn products(root: &Path) -> Result<BTreeMap<String, BTreeSet<String>>, DiffError> {
    let mut out = BTreeMap::new();
    let mut folders = vec![(root.to_path_buf(), String::from("."))];
    let mut seen = BTreeSet::new();
    while let Some((dir, name)) = folders.pop() {
        let real = std::fs::canonicalize(&dir).map_err(|e| file_error(&dir, e))?;
        if !seen.insert(real) {
            continue;
        }
        let read = std::fs::read_dir(&dir).map_err(|e| file_error(&dir, e))?;
        let mut files = BTreeSet::new();
        for entry in read {
            let entry = entry.map_err(|e| file_error(&dir, e))?;
            let file = entry.file_name().to_string_lossy().into_owned();
            if file.starts_with('.') {
                continue;
            }
            if entry.path().is_dir() {
                let sub = if name == "." {
                    file
                } else {
                    format!("{name}/{file}")
                };
                folders.push((entry.path(), sub));
            } else {
                files.insert(file);
            }
        }
        if !files.is_empty() {
            out.insert(name, files);
        }
    }
    Ok(out)
}

/// Compares the runs in folders `a` and `b`.
pub fn diff_runs(a: &Path, b: &Path, tolerance: Tolerance) -> Result<RunDiff, DiffError> {
    for dir in [a, b] {
        if !dir.is_dir() {
            return Err(file_error(dir, "not a folder"));
        }
    }
    let (pa, pb) = (products(a)?, products(b)?);
    let mut diffs = Vec::new();
    for (product, fa) in &pa {
        let Some(fb) = pb.get(product) else { continue };
        let (da, db) = (a.join(product), b.join(product));
        let mut p = ProductDiff {
            product: product.clone(),
            frames: 0,
            differing: 0,
            first_differing: None,
            worst_psnr_db: f64::INFINITY,
            max_abs: 0.0,
            only_in_a: fa.difference(fb).cloned().collect(),
            only_in_b: fb.difference(fa).cloned().collect(),
        };
        for file in fa.intersection(fb) {
            let f = diff_file(&da.join(file), &db.join(file))?;
            p.frames += 1;
            p.worst_psnr_db = p.worst_psnr_db.min(f.psnr_db);
            p.max_abs = p.max_abs.max(f.max_abs);
            if tolerance.exceeded(&f) {
                p.differing += 1;
                p.first_differing.get_or_insert_with(|| file.clone());
            }
        }
        diffs.push(p);
    }
    let only = |x: &BTreeMap<String, BTreeSet<String>>, y: &BTreeMap<String, BTreeSet<String>>| {
        x.keys().filter(|k| !y.contains_key(*k)).cloned().collect()
    };
    Ok(RunDiff {
        products: diffs,
        only_in_a: only(&pa, &pb),
        only_in_b: only(&pb, &pa),
    })
}

/// Values of an image file and the PSNR peak of their scale.
struct Values {
    shape: String,
    peak: f64,
    values: Vec<f64>,
}

fn read_values(path: &Path) -> Result<Option<Values>, DiffError> {
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    match extension.to_ascii_lowercase().as_str() {
        "png" => {
            let open = || {
                image::ImageReader::open(path)
                    .map_err(|e| file_error(path, e))?
                    .with_guessed_format()
                    .map_err(|e| file_error(path, e))
            };
            let (width, height) = open()?.into_dimensions().map_err(|e| file_error(path, e))?;
            check_size(path, width as u64, height as u64)?;
            let image = open()?.decode().map_err(|e| file_error(path, e))?;
            let color = image.color();
            let shape = format!("{}x{} {color:?}", image.width(), image.height());
            // The file's own channels: an alpha added here would always match and
            // dilute the error.
            let bytes = image.as_bytes();
            let sixteen = color.bytes_per_pixel() / color.channel_count().max(1) == 2;
            let (peak, values) = match sixteen {
                true => (
                    65535.0,
                    bytes
                        .chunks_exact(2)
                        .map(|b| u16::from_ne_bytes([b[0], b[1]]) as f64)
                        .collect(),
                ),
                false => (255.0, bytes.iter().map(|&b| b as f64).collect()),
            };
            Ok(Some(Values {
                shape,
                peak,
                values,
            }))
        }
        "exr" => {
            use exr::prelude::*;
            let meta = exr::meta::MetaData::read_from_file(path, false)
                .map_err(|e| file_error(path, e))?;
            for header in &meta.headers {
                let size = header.layer_size;
                check_size(path, size.width() as u64, size.height() as u64)?;
            }
            let image = read()
                .no_deep_data()
                .largest_resolution_level()
                .all_channels()
                .all_layers()
                .all_attributes()
                .from_file(path)
                .map_err(|e| file_error(path, e))?;
            let mut values = Vec::new();
            let mut shape = String::new();
            for layer in &image.layer_data {
                let name = layer.attributes.layer_name.as_ref().map(|n| n.to_string());
                shape.push_str(&format!("{name:?} {:?}", layer.size));
                for channel in &layer.channel_data.list {
                    shape.push_str(&format!(" {}", channel.name));
                    match &channel.sample_data {
                        FlatSamples::F16(v) => values.extend(v.iter().map(|x| x.to_f64())),
                        FlatSamples::F32(v) => values.extend(v.iter().map(|&x| x as f64)),
                        FlatSamples::U32(v) => values.extend(v.iter().map(|&x| x as f64)),
                    }
                }
            }
            let peak = values
                .iter()
                .filter(|v| v.is_finite())
                .fold(1.0f64, |m, v| m.max(v.abs()));
            Ok(Some(Values {
                shape,
                peak,
                values,
            }))
        }
        _ => Ok(None),
    }
}

/// Compares one frame file of both runs.
pub fn diff_file(a: &Path, b: &Path) -> Result<FrameDiff, DiffError> {
    let file = a
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let incomparable = |why: String| FrameDiff {
        file: file.clone(),
        max_abs: f64::INFINITY,
        psnr_db: f64::NEG_INFINITY,
        incomparable: Some(why),
    };
    // A frame that does not decode is not a difference: the runs cannot be compared.
    let (va, vb) = (read_values(a)?, read_values(b)?);
    let (Some(va), Some(vb)) = (va, vb) else {
        let bytes = |p: &Path| std::fs::read(p).map_err(|e| file_error(p, e));
        return Ok(if bytes(a)? == bytes(b)? {
            FrameDiff {
                file,
                max_abs: 0.0,
                psnr_db: f64::INFINITY,
                incomparable: None,
            }
        } else {
            incomparable("the bytes differ".into())
        });
    };
    if va.shape != vb.shape || va.values.len() != vb.values.len() {
        return Ok(incomparable(format!("{} against {}", va.shape, vb.shape)));
    }
    let (mut max_abs, mut squared) = (0.0f64, 0.0f64);
    for (x, y) in va.values.iter().zip(&vb.values) {
        let d = if x == y || (x.is_nan() && y.is_nan()) {
            0.0
        } else {
            (x - y).abs()
        };
        // NaN in one file only is as far apart as values get.
        let d = if d.is_nan() { f64::INFINITY } else { d };
        max_abs = max_abs.max(d);
        squared += d * d;
    }
    let mse = squared / va.values.len().max(1) as f64;
    Ok(FrameDiff {
        file,
        max_abs,
        psnr_db: 10.0 * (va.peak * va.peak / mse).log10(),
        incomparable: None,
    })
}
