//! Importer of the Redwood / Open3D layout:
//!
//! ```text
//! DIR/color/*.jpg|png   (or DIR/image/)   8-bit color, paired with depth by sorted name
//! DIR/depth/*.png                          16-bit depth in millimetres, 0 = missing
//! DIR/*.log                                trajectory: per frame a line of three integers,
//!                                          then four rows of a 4x4 camera-to-world matrix
//! ```
//! The layout has no timestamps: frame k is stamped k / fps.

use super::{
    ImportOptions, ImportSummary, check_dataset_dir, check_size, file_error, import_header,
    line_error, read_color, read_depth,
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
}

impl Default for RedwoodOptions {
    fn default() -> Self {
        RedwoodOptions {
            common: ImportOptions::default(),
            fps: 30.0,
            trajectory: None,
        }
    }
}

/// The image files of `dir`, sorted by name.
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
    files.sort();
    Ok(files)
}

/// A sentence on the first gap in the numbers that end the file names of `files`
/// (`000002.png`, `000004.png`: 000003 is missing), when every name ends in one.
/// Frames are paired and stamped by position, so a gap shifts every later frame.
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
         frames are paired and stamped by position (frame k at k / fps, with the \
         trajectory's k-th pose), so every frame after a gap is stamped early and may \
         take another frame's pose",
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
    if colors.len() != depths.len() {
        return Err(file_error(
            dir,
            format!(
                "{} holds {} images but {} holds {}: color and depth must pair up",
                color_dir.display(),
                colors.len(),
                depth_dir.display(),
                depths.len()
            ),
        ));
    }
    let trajectory = match &options.trajectory {
        Some(p) => Some(p.clone()),
        None => find_trajectory(dir)?,
    };
    let poses = match &trajectory {
        Some(p) => read_trajectory(p)?,
        None => Vec::new(),
    };
    if poses.len() > colors.len() {
        let p = trajectory.as_deref().unwrap_or(dir);
        return Err(file_error(
            p,
            format!("holds {} poses for {} frames", poses.len(), colors.len()),
        ));
    }

    let first_color = read_color(&colors[0], options.common.store)?;
    let first_depth = read_depth(&depths[0], options.common.store)?;
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
    let header = import_header(
        "redwood",
        dir,
        &options.common,
        &[
            ("fps", options.fps.to_string()),
            ("trajectory", trajectory_setting),
        ],
        (color_size, depth_size),
        REDWOOD_DEPTH_UNIT_M,
        streams,
    );
    let mut writer = RecordingWriter::create(out, &header)?;
    let stamp = |k: usize| (k as f64 / options.fps * 1e9).round() as i64;
    for (k, (color_path, depth_path)) in colors.iter().zip(&depths).enumerate() {
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
        progress(k + 1, colors.len());
    }
    writer.finish()?;
    let warnings = [(&color_dir, &colors), (&depth_dir, &depths)]
        .into_iter()
        .filter_map(|(folder, files)| numbering_gap(folder, files))
        .collect();
    Ok(ImportSummary {
        color: colors.len(),
        depth: depths.len(),
        poses: poses.len(),
        skipped_frames: 0,
        warnings,
    })
}
