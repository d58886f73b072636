//! `relume diff`: two folders of saved products (`relume replay --out`, `--save`, or
//! a `relume compare` run's `runs/LABEL/`) compared frame by frame, per product.
//!
//! A product is a sub-folder (`final/`, `depth/`, ...); its frames are the files in
//! it, matched by name. Images are compared value by value: PNG on its own scale (0-255
//! for 8-bit, 0-65535 for 16-bit: millimetres for depth), EXR in its linear values
//! (PSNR peak: the largest magnitude in the first run's frame, at least 1). Any other
//! file (JSON, PLY) is equal or not, byte for byte.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Why two runs could not be compared.
#[derive(Debug, thiserror::Error)]
pub enum DiffError {
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },
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

fn entries(dir: &Path, folders: bool) -> Result<BTreeSet<String>, DiffError> {
    let read = std::fs::read_dir(dir).map_err(|e| file_error(dir, e))?;
    let mut names = BTreeSet::new();
    for entry in read {
        let entry = entry.map_err(|e| file_error(dir, e))?;
        let is_dir = entry.path().is_dir();
        let name = entry.file_name().to_string_lossy().into_owned();
        // Hidden files: a run's half-written `.partial` files, editors' droppings.
        if is_dir == folders && !name.starts_with('.') {
            names.insert(name);
        }
    }
    Ok(names)
}

/// Compares the runs in folders `a` and `b`.
pub fn diff_runs(a: &Path, b: &Path, tolerance: Tolerance) -> Result<RunDiff, DiffError> {
    for dir in [a, b] {
        if !dir.is_dir() {
            return Err(file_error(dir, "not a folder"));
        }
    }
    let (pa, pb) = (entries(a, true)?, entries(b, true)?);
    let mut products = Vec::new();
    for product in pa.intersection(&pb) {
        let (da, db) = (a.join(product), b.join(product));
        let (fa, fb) = (entries(&da, false)?, entries(&db, false)?);
        let mut p = ProductDiff {
            product: product.clone(),
            frames: 0,
            differing: 0,
            first_differing: None,
            worst_psnr_db: f64::INFINITY,
            max_abs: 0.0,
            only_in_a: fa.difference(&fb).cloned().collect(),
            only_in_b: fb.difference(&fa).cloned().collect(),
        };
        for file in fa.intersection(&fb) {
            let f = diff_file(&da.join(file), &db.join(file))?;
            p.frames += 1;
            p.worst_psnr_db = p.worst_psnr_db.min(f.psnr_db);
            p.max_abs = p.max_abs.max(f.max_abs);
            if tolerance.exceeded(&f) {
                p.differing += 1;
                p.first_differing.get_or_insert_with(|| file.clone());
            }
        }
        products.push(p);
    }
    Ok(RunDiff {
        products,
        only_in_a: pa.difference(&pb).cloned().collect(),
        only_in_b: pb.difference(&pa).cloned().collect(),
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
            let image = image::open(path).map_err(|e| file_error(path, e))?;
            let shape = format!("{}x{} {:?}", image.width(), image.height(), image.color());
            let sixteen = image.color().bytes_per_pixel() / image.color().channel_count() == 2;
            let values: Vec<f64> = if sixteen {
                let raw = image.into_rgba16();
                raw.into_raw().into_iter().map(f64::from).collect()
            } else {
                image
                    .into_rgba8()
                    .into_raw()
                    .into_iter()
                    .map(f64::from)
                    .collect()
            };
            let peak = if sixteen { 65535.0 } else { 255.0 };
            Ok(Some(Values {
                shape,
                peak,
                values,
            }))
        }
        "exr" => {
            use exr::prelude::*;
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
                shape.push_str(&format!("{:?}", layer.size));
                for channel in &layer.channel_data.list {
                    shape.push_str(&format!(" {}", channel.name));
                    match &channel.sample_data {
                        FlatSamples::F16(v) => values.extend(v.iter().map(|x| x.to_f64())),
                        FlatSamples::F32(v) => values.extend(v.iter().map(|&x| x as f64)),
                        FlatSamples::U32(v) => values.extend(v.iter().map(|&x| x as f64)),
                    }
                }
            }
            let peak = values.iter().fold(1.0f64, |m, v| m.max(v.abs()));
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
    let (Some(va), Some(vb)) = (read_values(a)?, read_values(b)?) else {
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
        let d = if x == y { 0.0 } else { (x - y).abs() };
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
