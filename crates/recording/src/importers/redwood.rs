//! Importer of the Redwood / Open3D layout:
//!
//! ```text
//! DIR/color/*.jpg|png   (or DIR/image/)   8-bit color, paired with depth by file number
//! DIR/depth/*.png                          16-bit depth in millimetres, 0 = missing
//! DIR/*.log                                trajectory: per frame a line of three integers,
//!                                          then four rows of a 4x4 camera-to-world matrix
//!                                          (optional: without it, no poses)
//! DIR/camera_intrinsic.json                Open3D's intrinsics (optional, or
//!   or DIR/intrinsic.json                  intrinsic.json with a depth scale: see
//!                                          [`super::open3d_intrinsics`])
//! ```
//! The intrinsics file is used unless the options give intrinsics.
//! The layout has no timestamps: frame k is stamped k / fps. Files are ordered by the
//! numbers in their names (`2.png` before `10.png`), and where every name ends in a
//! number, color and depth pair by that number (`color/000012.jpg` with
//! `depth/000012.png`); a file without a partner is left out, with a warning. Names
//! without numbers pair by position.

use super::{
    CameraIntrinsics, ImportOptions, ImportSummary, check_dataset_dir, check_size, file_error,
    import_header, line_error, open3d_intrinsics, read_color, read_depth,
};
use crate::error::ImportError;
use crate::types::{ColorRecord, DepthRecord, Pose, PoseRecord, Record, StreamKind};
use crate::writer::RecordingWriter;
use glam::{DMat3, DMat4, DQuat, DVec4};
use std::path::{Path, PathBuf};

/// Redwood depth PNGs hold millimetres.
pub const REDWOOD_DEPTH_UNIT_M: f64 = 0.001;

/// Options of the Redwood importer beyond the common ones.
#[derive(Clone, Debug)]
pub struct RedwoodOptions {
    pub common: ImportOptions,
    /// Frames per second used to stamp frame k at k / fps.
    pub fps: f64,
    /// The trajectory file; by default the directory's only `.log` file (or `trajectory.log`).
    pub trajectory: Option<PathBuf>,
    /// `common.intrinsics` was given: the folder's Open3D intrinsics file is not read.
    pub override_intrinsics: bool,
}

impl Default for RedwoodOptions {
    fn default() -> Self {
        RedwoodOptions {
            common: ImportOptions::default(),
            fps: 30.0,
            trajectory: None,
            override_intrinsics: false,
        }
    }
}

/// The image files of `dir`, in [`natural_order`].
fn list_images(dir: &Path, extensions: &[&str]) -> Result<Vec<PathBuf>, ImportError> {
    let entries = std::fs::read_dir(dir).map_err(|source| ImportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry
            .map_err(|source| ImportError::Io {
                path: dir.to_path_buf(),
                source,
            })?
            .path();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        if ext.is_some_and(|e| extensions.contains(&e.as_str())) {
            files.push(path);
        }
    }
    files.sort_by(|a, b| natural_order(a, b));
    Ok(files)
}

/// Orders file names as people number them: runs of digits by their value (`2` before
/// `10`, `007` beside `7`), the rest by its characters; ties by the whole name.
pub fn natural_order(a: &Path, b: &Path) -> std::cmp::Ordering {
    fn runs(name: &str) -> Vec<(bool, &str)> {
        let mut runs = Vec::new();
        let mut rest = name;
        while let Some(c) = rest.chars().next() {
            let digit = c.is_ascii_digit();
            let end = rest
                .find(|c: char| c.is_ascii_digit() != digit)
                .unwrap_or(rest.len());
            runs.push((digit, &rest[..end]));
            rest = &rest[end..];
        }
        runs
    }
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
    let (na, nb) = (name(a).unwrap_or_default(), name(b).unwrap_or_default());
    let key = |runs: Vec<(bool, &str)>| -> Vec<(bool, usize, String)> {
        runs.into_iter()
            .map(|(digit, run)| match digit {
                // By value: fewer significant digits first, then digit by digit.
                true => {
                    let value = run.trim_start_matches('0');
                    (true, value.len(), value.to_string())
                }
                false => (false, 0, run.to_string()),
            })
            .collect()
    };
    key(runs(&na))
        .cmp(&key(runs(&nb)))
        .then_with(|| na.cmp(&nb))
}

/// The number that ends a file's stem (`frame-000012.png`: 12), if it ends in one that
/// fits in 64 bits.
fn file_number(path: &Path) -> Option<u64> {
    let stem = path.file_stem()?.to_str()?;
    let digits = stem.len() - stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    stem[stem.len() - digits..].parse().ok()
}

/// Color and depth files paired into frames, in order, and a warning on the files
/// left out.
struct Pairing {
    frames: Vec<(PathBuf, PathBuf)>,
    warning: Option<String>,
}

/// The [`Pairing`] of a dataset's color and depth files. Where every name of both folders ends in a number (unique within its
/// folder), files pair by number and a file whose number the other folder lacks is
/// left out; otherwise they pair by position, and the counts must agree.
fn pair_frames(
    (color_dir, colors): (&Path, Vec<PathBuf>),
    (depth_dir, depths): (&Path, Vec<PathBuf>),
) -> Result<Pairing, ImportError> {
    let numbers = |dir: &Path, files: &[PathBuf]| -> Result<Option<Vec<u64>>, ImportError> {
        let Some(numbers) = files
            .iter()
            .map(|f| file_number(f))
            .collect::<Option<Vec<_>>>()
        else {
            return Ok(None);
        };
        // Sorted naturally, equal numbers are neighbours (`7.png`, `007.png`).
        if let Some(i) = numbers.windows(2).position(|w| w[0] == w[1]) {
            return Err(file_error(
                dir,
                format!(
                    "{} and {} carry the same frame number {}: keep one",
                    files[i].display(),
                    files[i + 1].display(),
                    numbers[i]
                ),
            ));
        }
        Ok(Some(numbers))
    };
    let (Some(color_numbers), Some(depth_numbers)) =
        (numbers(color_dir, &colors)?, numbers(depth_dir, &depths)?)
    else {
        if colors.len() != depths.len() {
            return Err(file_error(
                color_dir.parent().unwrap_or(color_dir),
                format!(
                    "{} holds {} images but {} holds {}: color and depth must pair up",
                    color_dir.display(),
                    colors.len(),
                    depth_dir.display(),
                    depths.len()
                ),
            ));
        }
        return Ok(Pairing {
            frames: colors.into_iter().zip(depths).collect(),
            warning: None,
        });
    };
    let depth_of: std::collections::HashMap<u64, &PathBuf> =
        depth_numbers.iter().copied().zip(&depths).collect();
    let color_set: std::collections::HashSet<u64> = color_numbers.iter().copied().collect();
    let pairs: Vec<(PathBuf, PathBuf)> = color_numbers
        .iter()
        .zip(&colors)
        .filter_map(|(n, c)| depth_of.get(n).map(|d| (c.clone(), (*d).clone())))
        .collect();
    let lone_colors: Vec<&PathBuf> = color_numbers
        .iter()
        .zip(&colors)
        .filter(|(n, _)| !depth_of.contains_key(n))
        .map(|(_, c)| c)
        .collect();
    let lone_depths: Vec<&PathBuf> = depth_numbers
        .iter()
        .zip(&depths)
        .filter(|(n, _)| !color_set.contains(n))
        .map(|(_, d)| d)
        .collect();
    if pairs.is_empty() {
        return Err(file_error(
            color_dir.parent().unwrap_or(color_dir),
            format!(
                "no image of {} has a depth image of the same number in {} (color {}, depth {})",
                color_dir.display(),
                depth_dir.display(),
                first_of(&color_numbers),
                first_of(&depth_numbers)
            ),
        ));
    }
    let lone = |files: &[&PathBuf], partner: &Path| -> Option<String> {
        let first = files.first()?;
        Some(format!(
            "{} file(s) with no partner in {} (the first: {})",
            files.len(),
            partner.display(),
            first.display()
        ))
    };
    let unpaired: Vec<String> = [lone(&lone_colors, depth_dir), lone(&lone_depths, color_dir)]
        .into_iter()
        .flatten()
        .collect();
    let warning = (!unpaired.is_empty()).then(|| {
        format!(
            "color and depth pair by the numbers in their names: left out {}",
            unpaired.join("; ")
        )
    });
    Ok(Pairing {
        frames: pairs,
        warning,
    })
}

/// "7..." for numbers from 7 on, for an error; "none" for no numbers.
fn first_of(numbers: &[u64]) -> String {
    numbers
        .first()
        .map_or("none".to_string(), |n| format!("{n}..."))
}

/// A sentence on the first gap in the numbers that end the file names of `files`
/// (`000002.png`, `000004.png`: 000003 is missing), when every name ends in one.
/// Frames are stamped by position (the layout has no time), so a gap shifts every later
/// frame.
pub fn numbering_gap(folder: &Path, files: &[PathBuf]) -> Option<String> {
    let number = |p: &PathBuf| -> Option<u64> {
        let stem = p.file_stem()?.to_str()?;
        let digits = stem.len() - stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        stem[stem.len() - digits..].parse().ok()
    };
    let mut numbers: Vec<u64> = files.iter().map(number).collect::<Option<_>>()?;
    numbers.sort_unstable();
    let missing: u64 = numbers
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]).saturating_sub(1))
        .sum();
    let first = numbers.windows(2).find(|w| w[1] > w[0].saturating_add(1))?;
    Some(format!(
        "{}: the file numbers jump from {} to {} ({missing} number(s) missing in all): \
         frames are stamped by position (frame k at k / fps, with the trajectory's \
         k-th pose), so every frame after a gap is stamped early and may take another \
         frame's pose",
        folder.display(),
        first[0],
        first[1]
    ))
}

/// Reads a Redwood `.log` trajectory: 5-line records of `i j k` and a row-major 4x4
/// camera-to-world matrix. Record k is frame k's pose, so its `i` must be k: poses are
/// paired with the images by their place in the file.
pub fn read_trajectory(path: &Path) -> Result<Vec<Pose>, ImportError> {
    let text =
        relume_base::files::read_regular_to_string(path).map_err(|source| ImportError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    let lines: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty())
        .collect();
    if !lines.len().is_multiple_of(5) {
        let (line, _) = lines[lines.len() - lines.len() % 5];
        return Err(line_error(
            path,
            line,
            format!(
                "incomplete record: {} lines are not a multiple of 5 (a line of three integers, then four matrix rows)",
                lines.len()
            ),
        ));
    }
    let mut poses = Vec::with_capacity(lines.len() / 5);
    for (k, record) in lines.chunks_exact(5).enumerate() {
        let (line, ids) = record[0];
        let ints: Vec<&str> = ids.split_whitespace().collect();
        if ints.len() != 3 || ints.iter().any(|v| v.parse::<i64>().is_err()) {
            return Err(line_error(
                path,
                line,
                format!("expected three integers starting a pose record, found {ids:?}"),
            ));
        }
        if ints[0].parse::<i64>() != Ok(k as i64) {
            return Err(line_error(
                path,
                line,
                format!(
                    "record {k} is for frame {}: records must list frames 0, 1, 2, ... in order, one each",
                    ints[0]
                ),
            ));
        }
        let mut rows = [DVec4::ZERO; 4];
        for (r, &(line, text)) in record[1..].iter().enumerate() {
            let v: Vec<f64> = text
                .split_whitespace()
                .map(|x| x.parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| {
                    line_error(
                        path,
                        line,
                        format!(
                            "matrix row {} must hold four numbers, found {text:?}",
                            r + 1
                        ),
                    )
                })?;
            if v.len() != 4 || v.iter().any(|x| !x.is_finite()) {
                return Err(line_error(
                    path,
                    line,
                    format!(
                        "matrix row {} must hold four finite numbers, found {text:?}",
                        r + 1
                    ),
                ));
            }
            rows[r] = DVec4::new(v[0], v[1], v[2], v[3]);
        }
        let m = DMat4::from_cols(rows[0], rows[1], rows[2], rows[3]).transpose();
        let rotation = DMat3::from_mat4(m);
        let (first_line, _) = record[1];
        let orthonormal = (rotation * rotation.transpose() - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .all(|x| x.abs() < 1e-3);
        if !orthonormal || rotation.determinant() < 0.0 || (rows[3] - DVec4::W).length() > 1e-6 {
            return Err(line_error(
                path,
                first_line,
                "the matrix is not a rigid transform (rotation and translation, last row 0 0 0 1)"
                    .into(),
            ));
        }
        poses.push(Pose::from_parts(
            m.w_axis.truncate(),
            DQuat::from_mat3(&rotation),
        ));
    }
    Ok(poses)
}

fn find_trajectory(dir: &Path) -> Result<Option<PathBuf>, ImportError> {
    let logs = list_images(dir, &["log"])?;
    Ok(match logs.len() {
        0 => None,
        1 => Some(logs[0].clone()),
        _ => match logs
            .iter()
            .find(|p| p.file_name().is_some_and(|n| n == "trajectory.log"))
        {
            Some(p) => Some(p.clone()),
            None => {
                return Err(file_error(
                    dir,
                    format!(
                        "holds {} .log files and none is trajectory.log: pick one with --trajectory",
                        logs.len()
                    ),
                ));
            }
        },
    })
}

/// Imports the Redwood directory `dir` into `out`. `progress` gets (done, total) frames.
pub fn import(
    dir: &Path,
    out: &Path,
    options: &RedwoodOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ImportSummary, ImportError> {
    if !crate::FPS_RANGE.contains(&options.fps) {
        return Err(file_error(
            dir,
            format!(
                "--fps must be a number from 0.001 to 1e6 (stamps are k / fps in nanoseconds), got {}",
                options.fps
            ),
        ));
    }
    check_dataset_dir(dir)?;
    let color_dir = ["color", "image", "rgb"]
        .iter()
        .map(|d| dir.join(d))
        .find(|d| d.is_dir())
        .ok_or_else(|| file_error(dir, "has no color/ or image/ directory".into()))?;
    let depth_dir = dir.join("depth");
    if !depth_dir.is_dir() {
        return Err(file_error(dir, "has no depth/ directory".into()));
    }
    let colors = list_images(&color_dir, &["jpg", "jpeg", "png"])?;
    let depths = list_images(&depth_dir, &["png"])?;
    if colors.is_empty() {
        return Err(file_error(&color_dir, "holds no JPG or PNG images".into()));
    }
    if depths.is_empty() {
        return Err(file_error(&depth_dir, "holds no PNG images".into()));
    }
    let Pairing {
        frames,
        warning: pairing_warning,
    } = pair_frames((&color_dir, colors.clone()), (&depth_dir, depths.clone()))?;
    let trajectory = match &options.trajectory {
        Some(p) => Some(p.clone()),
        None => find_trajectory(dir)?,
    };
    let poses = match &trajectory {
        Some(p) => read_trajectory(p)?,
        None => Vec::new(),
    };
    if poses.len() > frames.len() {
        let p = trajectory.as_deref().unwrap_or(dir);
        return Err(file_error(
            p,
            format!("holds {} poses for {} frames", poses.len(), frames.len()),
        ));
    }

    let first_color = read_color(&frames[0].0, options.common.store)?;
    let first_depth = read_depth(&frames[0].1, options.common.store)?;
    let mut color_size = Some((first_color.width, first_color.height));
    let mut depth_size = Some((first_depth.width, first_depth.height));
    let mut streams = vec![StreamKind::Color, StreamKind::Depth];
    if !poses.is_empty() {
        streams.push(StreamKind::Pose);
    }
    let trajectory_setting = trajectory
        .as_ref()
        .map(|p| p.display().to_string())
        .unwrap_or_default();
    let mut common = options.common.clone();
    let mut settings = vec![
        ("fps", options.fps.to_string()),
        ("trajectory", trajectory_setting),
    ];
    let mut depth_unit_m = REDWOOD_DEPTH_UNIT_M;
    let file = match options.override_intrinsics {
        true => None,
        false => open3d_intrinsics::find(dir)?,
    };
    if let Some(file) = file {
        let k = &file.intrinsics;
        if (first_color.width, first_color.height) != (k.width, k.height) {
            return Err(file_error(
                &file.path,
                format!(
                    "is for {}x{} images, but {} is {}x{} (give --intrinsics fx,fy,cx,cy for \
                     the images' own size)",
                    k.width,
                    k.height,
                    frames[0].0.display(),
                    first_color.width,
                    first_color.height
                ),
            ));
        }
        common.intrinsics = CameraIntrinsics::Given {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
        };
        depth_unit_m = file.depth_unit_m.unwrap_or(REDWOOD_DEPTH_UNIT_M);
        settings.push(("intrinsics_file", file.path.display().to_string()));
    }
    let header = import_header(
        "redwood",
        dir,
        &common,
        &settings,
        (color_size, depth_size),
        depth_unit_m,
        streams,
    );
    let mut writer = RecordingWriter::create(out, &header)?;
    let stamp = |k: usize| (k as f64 / options.fps * 1e9).round() as i64;
    for (k, (color_path, depth_path)) in frames.iter().enumerate() {
        let color = if k == 0 {
            first_color.clone()
        } else {
            read_color(color_path, options.common.store)?
        };
        check_size(color_path, &color, &mut color_size)?;
        let depth = if k == 0 {
            first_depth.clone()
        } else {
            read_depth(depth_path, options.common.store)?
        };
        check_size(depth_path, &depth, &mut depth_size)?;
        writer.write(&Record::Color(ColorRecord {
            stamp_ns: stamp(k),
            image: color,
        }))?;
        writer.write(&Record::Depth(DepthRecord {
            stamp_ns: stamp(k),
            image: depth,
        }))?;
        if let Some(pose) = poses.get(k) {
            writer.write(&Record::Pose(PoseRecord {
                stamp_ns: stamp(k),
                pose: *pose,
            }))?;
        }
        progress(k + 1, frames.len());
    }
    writer.finish()?;
    let warnings = pairing_warning
        .into_iter()
        .chain(
            [(&color_dir, &colors), (&depth_dir, &depths)]
                .into_iter()
                .filter_map(|(folder, files)| numbering_gap(folder, files)),
        )
        .collect();
    Ok(ImportSummary {
        color: frames.len(),
        depth: frames.len(),
        poses: poses.len(),
        skipped_frames: 0,
        warnings,
    })
}
