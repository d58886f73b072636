//! Importer of the TUM RGB-D benchmark layout:
//!
//! ```text
//! DIR/rgb.txt          # timestamp filename    ('#' starts a comment)
//! DIR/depth.txt        # timestamp filename    (16-bit PNG, 5000 units per metre)
//! DIR/groundtruth.txt  # timestamp tx ty tz qx qy qz qw   (optional)
//! ```
//! Streams keep their own stamps; association happens at replay.

use super::{
    ImportOptions, ImportSummary, check_dataset_dir, check_size, file_error, import_header,
    line_error, parse_stamp_ns, read_color, read_depth,
};
use crate::error::ImportError;
use crate::types::{ColorRecord, DepthRecord, Pose, PoseRecord, Record, StreamKind};
use crate::writer::RecordingWriter;
use glam::{DQuat, DVec3};
use std::path::{Path, PathBuf};

/// TUM depth PNGs hold 5000 units per metre.
pub const TUM_DEPTH_UNIT_M: f64 = 1.0 / 5000.0;

/// One line of a TUM listing: its line number, stamp and the other fields.
struct ListLine {
    line: usize,
    stamp_ns: i64,
    fields: Vec<String>,
}

/// Reads a TUM listing, skipping blank lines and `#` comments; checks each line has
/// `fields` fields after the stamp, and that no two lines share a stamp (replay could
/// not tell their images or poses apart). Lines may come in any order.
fn read_listing(path: &Path, fields: usize, what: &str) -> Result<Vec<ListLine>, ImportError> {
    let text =
        relume_base::files::read_regular_to_string(path).map_err(|source| ImportError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let content = raw.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let parts: Vec<&str> = content.split_whitespace().collect();
        if parts.len() != fields + 1 {
            return Err(line_error(
                path,
                line,
                format!(
                    "expected `timestamp {what}` ({} fields), found {} field(s): {content:?}",
                    fields + 1,
                    parts.len()
                ),
            ));
        }
        let stamp_ns = parse_stamp_ns(parts[0]).ok_or_else(|| {
            line_error(
                path,
                line,
                format!(
                    "invalid timestamp {:?} (expected seconds like 1305031102.175304)",
                    parts[0]
                ),
            )
        })?;
        out.push(ListLine {
            line,
            stamp_ns,
            fields: parts[1..].iter().map(|s| s.to_string()).collect(),
        });
    }
    let mut by_stamp: Vec<(i64, usize)> = out.iter().map(|l| (l.stamp_ns, l.line)).collect();
    by_stamp.sort_unstable();
    if let Some(pair) = by_stamp.windows(2).find(|w| w[0].0 == w[1].0) {
        let (first, second) = (pair[0].1, pair[1].1);
        return Err(line_error(
            path,
            second,
            format!("the same timestamp as line {first}: each line needs a stamp of its own"),
        ));
    }
    Ok(out)
}

fn parse_pose(path: &Path, l: &ListLine) -> Result<Pose, ImportError> {
    let v: Vec<f64> = l
        .fields
        .iter()
        .map(|f| f.parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            line_error(
                path,
                l.line,
                format!("pose values must be numbers: {}", l.fields.join(" ")),
            )
        })?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(line_error(
            path,
            l.line,
            "pose values must be finite".into(),
        ));
    }
    let q = DQuat::from_xyzw(v[3], v[4], v[5], v[6]);
    if (q.length() - 1.0).abs() > 0.01 {
        return Err(line_error(
            path,
            l.line,
            format!(
                "quaternion qx qy qz qw has length {:.4}, expected 1",
                q.length()
            ),
        ));
    }
    Ok(Pose::from_parts(DVec3::new(v[0], v[1], v[2]), q))
}

/// Imports the TUM RGB-D directory `dir` into `out`. `progress` is called with
/// (done, total) image counts.
pub fn import(
    dir: &Path,
    out: &Path,
    options: &ImportOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ImportSummary, ImportError> {
    check_dataset_dir(dir)?;
    let rgb_list = dir.join("rgb.txt");
    let depth_list = dir.join("depth.txt");
    let gt_list = dir.join("groundtruth.txt");
    let colors = read_listing(&rgb_list, 1, "filename")?;
    let depths = read_listing(&depth_list, 1, "filename")?;
    let poses = if gt_list.exists() {
        read_listing(&gt_list, 7, "tx ty tz qx qy qz qw")?
    } else {
        Vec::new()
    };
    if colors.is_empty() {
        return Err(file_error(&rgb_list, "lists no color images".into()));
    }

    let pose_records = poses
        .iter()
        .map(|l| {
            Ok(PoseRecord {
                stamp_ns: l.stamp_ns,
                pose: parse_pose(&gt_list, l)?,
            })
        })
        .collect::<Result<Vec<_>, ImportError>>()?;
    let image_path = |list: &Path, l: &ListLine| -> Result<PathBuf, ImportError> {
        let path = dir.join(&l.fields[0]);
        let problem = match std::fs::metadata(&path) {
            Ok(m) if m.is_file() => return Ok(path),
            Ok(m) if m.is_dir() => "is a folder, not an image",
            Ok(_) => "is not a regular file",
            Err(_) => "does not exist",
        };
        Err(line_error(
            list,
            l.line,
            format!("image {} {problem}", path.display()),
        ))
    };
    // The first image of each stream fixes the sensor size for the header.
    let first_color = read_color(&image_path(&rgb_list, &colors[0])?, options.store)?;
    let first_depth = match depths.first() {
        Some(l) => Some(read_depth(&image_path(&depth_list, l)?, options.store)?),
        None => None,
    };
    let color_size = Some((first_color.width, first_color.height));
    let depth_size = first_depth.as_ref().map(|d| (d.width, d.height));

    let mut streams = vec![StreamKind::Color];
    if !depths.is_empty() {
        streams.push(StreamKind::Depth);
    }
    if !poses.is_empty() {
        streams.push(StreamKind::Pose);
    }
    let header = import_header(
        "tum",
        dir,
        options,
        &[],
        (color_size, depth_size),
        TUM_DEPTH_UNIT_M,
        streams,
    );
    let mut writer = RecordingWriter::create(out, &header)?;
    let total = colors.len() + depths.len();
    let mut expected_color = color_size;
    for (k, l) in colors.iter().enumerate() {
        let path = image_path(&rgb_list, l)?;
        let image = if k == 0 {
            first_color.clone()
        } else {
            read_color(&path, options.store)?
        };
        check_size(&path, &image, &mut expected_color)?;
        writer.write(&Record::Color(ColorRecord {
            stamp_ns: l.stamp_ns,
            image,
        }))?;
        progress(k + 1, total);
    }
    let mut expected_depth = depth_size;
    for (k, l) in depths.iter().enumerate() {
        let path = image_path(&depth_list, l)?;
        let image = match (k, &first_depth) {
            (0, Some(d)) => d.clone(),
            _ => read_depth(&path, options.store)?,
        };
        check_size(&path, &image, &mut expected_depth)?;
        writer.write(&Record::Depth(DepthRecord {
            stamp_ns: l.stamp_ns,
            image,
        }))?;
        progress(colors.len() + k + 1, total);
    }
    for p in pose_records {
        writer.write(&Record::Pose(p))?;
    }
    writer.finish()?;
    Ok(ImportSummary {
        color: colors.len(),
        depth: depths.len(),
        poses: poses.len(),
        skipped_frames: 0,
        warnings: Vec::new(),
    })
}
