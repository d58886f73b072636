//! `relume inspect`: what a recording holds.

use clap::Args;
use relume::recording::{Record, Recording, Replay, ReplayOptions, StreamKind, codec};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct InspectArgs {
    /// The recording (.relume).
    recording: PathBuf,
    /// Print JSON (keys include frames, frames_with_pose, streams, association; with
    /// --verify, records_verified and corrupt_records).
    #[arg(long)]
    json: bool,
    /// Read every record and check its checksum and encoding, images decoded; the exit
    /// status is 1 when a record is corrupt or the file is damaged.
    #[arg(long)]
    verify: bool,
    /// The largest gap between two pose samples that a frame's pose is interpolated
    /// across, in milliseconds (default: five times the pose stream's median interval,
    /// at least 50 ms); frames in longer gaps have no pose.
    #[arg(long, value_name = "MS", value_parser = super::replay::parse_gap_ms)]
    max_pose_gap: Option<i64>,
}

pub fn inspect(a: InspectArgs) -> anyhow::Result<i32> {
    let replay = Replay::open(
        &a.recording,
        ReplayOptions {
            skip_corrupt: true,
            max_pose_gap_ns: a.max_pose_gap,
            ..Default::default()
        },
    )?;
    let rec = &replay.recording;
    let h = rec.header();
    let index = rec.index();
    let streams: Vec<serde_json::Value> = StreamKind::ALL
        .iter()
        .filter_map(|&kind| {
            let stamps: Vec<i64> = index.iter().filter(|e| e.kind == kind).map(|e| e.stamp_ns).collect();
            let (first, last) = (stamps.iter().min()?, stamps.iter().max()?);
            let span_s = last.abs_diff(*first) as f64 * 1e-9;
            let rate = if span_s > 0.0 { (stamps.len() - 1) as f64 / span_s } else { 0.0 };
            let bytes: u64 = index.iter().filter(|e| e.kind == kind).map(|e| e.len as u64).sum();
            Some(serde_json::json!({ "stream": kind.name(), "records": stamps.len(), "first_ns": first, "last_ns": last, "rate_hz": rate, "bytes": bytes }))
        })
        .collect();
    let corrupt: Vec<String> = if a.verify {
        (0..index.len())
            .filter_map(|i| verify_record(rec, i).err())
            .collect()
    } else {
        Vec::new()
    };
    let s = &replay.stats;
    let doc = serde_json::json!({
        "path": rec.path().display().to_string(),
        "format_version": rec.version().to_string(),
        "bytes": rec.file_len(),
        "name": h.name,
        "provenance": { "tool": h.provenance.tool, "tool_version": h.provenance.tool_version, "source": h.provenance.source, "settings": h.provenance.settings },
        "color_intrinsics": h.color_intrinsics,
        "depth_intrinsics": h.depth_intrinsics,
        "depth_unit_m": h.depth_unit_m,
        "streams": streams,
        "frames": s.frames,
        "frames_with_pose": s.frames_with_pose,
        "frames_with_truth": s.frames_with_truth,
        "duration_s": replay.duration_s(),
        "association": s,
        "ground_truth": h.ground_truth,
        "attachments": h.attachments.iter().map(|a| serde_json::json!({ "name": a.name, "kind": a.kind, "width": a.image.width, "height": a.image.height, "channels": a.image.channels })).collect::<Vec<_>>(),
        "damage": rec.damage().map(|d| d.to_string()),
        "verified": a.verify,
        "records_verified": a.verify.then_some(index.len()),
        "corrupt_records": corrupt,
    });
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&doc)?)?;
    } else {
        outln!(
            "{} ({}, format {}, {:.1} MB)",
            rec.path().display(),
            printable(&h.name),
            rec.version(),
            rec.file_len() as f64 / 1e6
        )?;
        outln!(
            "  made by   {} {} from {}",
            printable(&h.provenance.tool),
            printable(&h.provenance.tool_version),
            printable(&h.provenance.source)
        )?;
        let k = &h.color_intrinsics;
        outln!(
            "  color     {}x{}  fx {:.2} fy {:.2} cx {:.2} cy {:.2}",
            k.width,
            k.height,
            k.fx,
            k.fy,
            k.cx,
            k.cy
        )?;
        let k = &h.depth_intrinsics;
        outln!(
            "  depth     {}x{}  fx {:.2} fy {:.2} cx {:.2} cy {:.2}  unit {} m",
            k.width,
            k.height,
            k.fx,
            k.fy,
            k.cx,
            k.cy,
            h.depth_unit_m
        )?;
        for st in &streams {
            outln!(
                "  stream    {:<6} {:>6} records  {:>7.2} Hz  {:>9.1} MB",
                st["stream"].as_str().unwrap_or(""),
                st["records"],
                st["rate_hz"].as_f64().unwrap_or(0.0),
                st["bytes"].as_u64().unwrap_or(0) as f64 / 1e6
            )?;
        }
        outln!(
            "  frames    {} associated over {:.2} s: {} with pose, {} with ground truth",
            s.frames,
            replay.duration_s(),
            s.frames_with_pose,
            s.frames_with_truth
        )?;
        outln!(
            "  skipped   {} color records without depth within {} ms, {} corrupt pose records \
             ({} frames take their pose from one: a replay with --skip-corrupt skips them)",
            s.skipped_no_depth,
            relume::recording::association::DEFAULT_TOLERANCE_NS / 1_000_000,
            s.skipped_corrupt_poses,
            s.frames_with_corrupt_pose
        )?;
        if s.frames_in_pose_gaps > 0 {
            outln!(
                "  pose gaps {} frames lie in gaps of the pose stream longer than {:.0} ms: \
                 they have no pose (--max-pose-gap sets the limit)",
                s.frames_in_pose_gaps,
                s.max_pose_gap_ns.unwrap_or(0) as f64 * 1e-6
            )?;
        }
        if let Some(stamp) = s.first_duplicate_stamp_ns {
            outln!(
                "  stamps    {} color records share their stamp with the one before (the \
                 first at {stamp} ns): each replays as a frame of its own",
                s.duplicate_color_stamps
            )?;
        }
        if let Some(gt) = &h.ground_truth {
            outln!(
                "  truth     {} (object at {:?})",
                printable(&gt.description),
                gt.object_position
            )?;
        }
        for att in &h.attachments {
            outln!(
                "  attached  {} ({}, {}x{})",
                printable(&att.name),
                printable(&att.kind),
                att.image.width,
                att.image.height
            )?;
        }
        if let Some(d) = rec.damage() {
            outln!("  DAMAGED   {d}")?;
        }
        if a.verify {
            outln!(
                "  verified  {} records, {} corrupt",
                index.len(),
                corrupt.len()
            )?;
            for c in &corrupt {
                outln!("    {c}")?;
            }
        }
    }
    let damaged = a.verify && rec.damage().is_some();
    Ok(if corrupt.is_empty() && !damaged { 0 } else { 1 })
}

/// `text` from a recording's header with its control characters escaped (`\u{1b}`),
/// so that a recording cannot move the cursor, clear the screen or retitle the terminal
/// of the person inspecting it.
fn printable(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.chars().any(char::is_control) {
        return text.into();
    }
    text.chars()
        .map(|c| match c.is_control() {
            true => c.escape_unicode().to_string(),
            false => c.to_string(),
        })
        .collect::<String>()
        .into()
}

/// Reads record `i` and decodes its image, if it has one: what is wrong with it.
fn verify_record(rec: &Recording, i: usize) -> Result<(), String> {
    let image = match rec.read_record(i).map_err(|e| e.to_string())? {
        Record::Color(r) => codec::decode_color(&r.image).map(drop),
        Record::Depth(r) => codec::decode_depth_units(&r.image).map(drop),
        Record::Pose(_) | Record::Truth(_) => Ok(()),
    };
    let kind = rec.index()[i].kind.name();
    image.map_err(|e| {
        format!(
            "{}: record {i} ({kind}): cannot decode its image: {e}",
            rec.path().display()
        )
    })
}
