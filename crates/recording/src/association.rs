//! Association of independently stamped streams into frames, at the color stamps:
//! depth is the nearest depth stamp within a tolerance (20 ms by default, as the TUM
//! tools use), the pose is interpolated (lerp + slerp) at the color stamp when that stamp
//! lies inside the pose stream, and ground truth is the nearest truth record within the
//! same tolerance.

use super::format::IndexEntry;
use super::types::{Pose, StreamKind};
use serde::Serialize;

/// Default tolerance between a color stamp and its depth stamp.
pub const DEFAULT_TOLERANCE_NS: i64 = 20_000_000;

/// One associated frame: positions in the recording's index and the interpolated pose.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRef {
    pub stamp_ns: i64,
    pub color: usize,
    pub depth: Option<usize>,
    pub truth: Option<usize>,
    pub pose: Option<Pose>,
    /// A corrupt pose record (skipped under `--skip-corrupt`) that this frame's pose
    /// would be interpolated from: reading the frame fails with that record's error, so
    /// that the frame is skipped and counted rather than given an invented pose.
    pub corrupt_pose: Option<usize>,
}

/// Marks the frames whose pose would come from a corrupt pose record: those for which
/// a corrupt stamp lies between the valid samples around them (`poses` sorted by
/// stamp; `corrupt` as (stamp, record)). Returns how many were marked.
pub fn mark_corrupt_poses(
    frames: &mut [FrameRef],
    poses: &[(i64, Pose)],
    corrupt: &[(i64, usize)],
) -> usize {
    let mut marked = 0;
    for f in frames.iter_mut() {
        let t = f.stamp_ns;
        let at = poses.partition_point(|&(s, _)| s < t);
        let exact = poses.get(at).is_some_and(|&(s, _)| s == t);
        let before = if exact {
            t
        } else {
            at.checked_sub(1).map_or(i64::MIN, |i| poses[i].0)
        };
        let after = poses.get(at).map_or(i64::MAX, |&(s, _)| s);
        // Outside the valid samples only a corrupt stamp on the frame's far side would
        // have given it a pose: at or before it when no valid sample precedes it, at or
        // after it when none follows.
        let hit = corrupt.iter().find(|&&(c, _)| {
            (before..=after).contains(&c)
                && (before != i64::MIN || c <= t)
                && (after != i64::MAX || c >= t)
        });
        if let Some(&(_, record)) = hit {
            f.corrupt_pose = Some(record);
            f.pose = None;
            marked += 1;
        }
    }
    marked
}

/// Counts of what association found.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct AssociationStats {
    pub color_records: usize,
    pub depth_records: usize,
    pub pose_records: usize,
    pub truth_records: usize,
    /// Frames built (color records with a depth match, or all color records when the
    /// recording has no depth stream).
    pub frames: usize,
    pub frames_with_pose: usize,
    pub frames_with_truth: usize,
    /// Color records skipped because no depth stamp lay within the tolerance.
    pub skipped_no_depth: usize,
    /// Pose records skipped because they could not be read (with `--skip-corrupt`).
    pub skipped_corrupt_poses: usize,
    /// Frames whose pose would come from such a record: replay skips and counts them.
    pub frames_with_corrupt_pose: usize,
    /// Frames inside the pose stream that have no pose because the samples around them
    /// are further apart than the largest interpolation gap.
    pub frames_in_pose_gaps: usize,
    /// That gap, ns (`None`: no pose stream to interpolate).
    pub max_pose_gap_ns: Option<i64>,
    /// Frames whose color stamp is the previous frame's (a writer that stamped twice):
    /// each is still a frame of its own, with the same depth and pose.
    pub duplicate_color_stamps: usize,
    /// The first such stamp, ns.
    pub first_duplicate_stamp_ns: Option<i64>,
}

/// Stamps and index positions of one stream, sorted by stamp.
fn stream(index: &[IndexEntry], kind: StreamKind) -> Vec<(i64, usize)> {
    let mut v: Vec<(i64, usize)> = index
        .iter()
        .enumerate()
        .filter(|(_, e)| e.kind == kind)
        .map(|(i, e)| (e.stamp_ns, i))
        .collect();
    v.sort();
    v
}

/// The entry of `sorted` nearest to `t`, if within `tolerance_ns`.
fn nearest(sorted: &[(i64, usize)], t: i64, tolerance_ns: i64) -> Option<usize> {
    let at = sorted.partition_point(|&(s, _)| s < t);
    let candidates = [at.checked_sub(1), Some(at)];
    candidates
        .into_iter()
        .flatten()
        .filter_map(|i| sorted.get(i))
        .map(|&(s, i)| (s.abs_diff(t), i))
        .filter(|&(d, _)| d <= tolerance_ns.unsigned_abs())
        .min()
        .map(|(_, i)| i)
}

/// The default largest gap between two pose samples that a frame's pose is
/// interpolated across: five times the stream's median interval, at least 50 ms
/// (100 Hz motion capture: 50 ms; poses per 30 Hz frame: 167 ms). `None` with fewer
/// than two poses.
pub fn default_max_pose_gap_ns(poses: &[(i64, Pose)]) -> Option<i64> {
    let mut steps: Vec<i64> = poses
        .windows(2)
        .map(|w| w[1].0.saturating_sub(w[0].0))
        .filter(|&d| d > 0)
        .collect();
    if steps.is_empty() {
        return None;
    }
    let mid = steps.len() / 2;
    let median = *steps.select_nth_unstable(mid).1;
    Some(median.saturating_mul(5).max(50_000_000))
}

/// The pose at `t`, interpolated between the bracketing samples of `poses` (sorted by
/// stamp); `None` outside the pose stream, and inside a gap between two samples longer
/// than `max_gap_ns`, where interpolation would invent the motion.
pub fn pose_at(poses: &[(i64, Pose)], t: i64, max_gap_ns: i64) -> Option<Pose> {
    let (first, last) = (poses.first()?, poses.last()?);
    if t < first.0 || t > last.0 {
        return None;
    }
    let at = poses.partition_point(|&(s, _)| s < t);
    let (s1, p1) = poses[at];
    if s1 == t || at == 0 {
        return Some(p1);
    }
    let (s0, p0) = poses[at - 1];
    if (s1 as i128 - s0 as i128) > max_gap_ns as i128 {
        return None;
    }
    // i128: stamps may span the whole i64 range (e.g. from a damaged file).
    let w = (t as i128 - s0 as i128) as f64 / (s1 as i128 - s0 as i128) as f64;
    Some(Pose::interpolate(&p0, &p1, w))
}

/// For each color stamp of `index`, the signed distance (ns) to the nearest depth stamp
/// (positive: the depth image comes later), whatever the tolerance: what an import
/// where nothing associates reports. Empty when either stream is.
pub fn depth_offsets(index: &[IndexEntry]) -> Vec<i64> {
    let depths = stream(index, StreamKind::Depth);
    if depths.is_empty() {
        return Vec::new();
    }
    stream(index, StreamKind::Color)
        .iter()
        .map(|&(t, _)| {
            let at = depths.partition_point(|&(s, _)| s < t);
            [at.checked_sub(1), Some(at)]
                .into_iter()
                .flatten()
                .filter_map(|i| depths.get(i))
                .map(|&(s, _)| s.saturating_sub(t))
                .min_by_key(|d| d.unsigned_abs())
                .expect("a depth stamp exists")
        })
        .collect()
}

/// Builds frames at the color stamps of `index`. `poses` are the decoded pose records,
/// sorted by stamp; `has_depth_stream` says whether frames must have depth.
pub fn associate(
    index: &[IndexEntry],
    poses: &[(i64, Pose)],
    has_depth_stream: bool,
    tolerance_ns: i64,
    max_pose_gap_ns: Option<i64>,
) -> (Vec<FrameRef>, AssociationStats) {
    let max_gap = max_pose_gap_ns
        .or_else(|| default_max_pose_gap_ns(poses))
        .unwrap_or(i64::MAX);
    let colors = stream(index, StreamKind::Color);
    let depths = stream(index, StreamKind::Depth);
    let truths = stream(index, StreamKind::Truth);
    let mut stats = AssociationStats {
        color_records: colors.len(),
        depth_records: depths.len(),
        pose_records: index.iter().filter(|e| e.kind == StreamKind::Pose).count(),
        truth_records: truths.len(),
        ..Default::default()
    };
    let mut frames = Vec::with_capacity(colors.len());
    for &(stamp_ns, color) in &colors {
        let depth = nearest(&depths, stamp_ns, tolerance_ns);
        if has_depth_stream && depth.is_none() {
            stats.skipped_no_depth += 1;
            continue;
        }
        let frame = FrameRef {
            stamp_ns,
            color,
            depth,
            truth: nearest(&truths, stamp_ns, tolerance_ns),
            pose: pose_at(poses, stamp_ns, max_gap),
            corrupt_pose: None,
        };
        if frame.pose.is_none() && pose_at(poses, stamp_ns, i64::MAX).is_some() {
            stats.frames_in_pose_gaps += 1;
        }
        stats.frames_with_pose += frame.pose.is_some() as usize;
        stats.frames_with_truth += frame.truth.is_some() as usize;
        if frames
            .last()
            .is_some_and(|f: &FrameRef| f.stamp_ns == stamp_ns)
        {
            stats.duplicate_color_stamps += 1;
            stats.first_duplicate_stamp_ns.get_or_insert(stamp_ns);
        }
        frames.push(frame);
    }
    stats.frames = frames.len();
    stats.max_pose_gap_ns = (poses.len() > 1).then_some(max_gap);
    (frames, stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};

    fn entry(kind: StreamKind, stamp_ns: i64) -> IndexEntry {
        IndexEntry {
            kind,
            stamp_ns,
            offset: 0,
            len: 0,
        }
    }

    #[test]
    fn depth_is_nearest_within_tolerance_and_unmatched_color_is_skipped() {
        let ms = 1_000_000;
        let index = vec![
            entry(StreamKind::Color, 100 * ms),
            entry(StreamKind::Color, 200 * ms),
            entry(StreamKind::Color, 300 * ms),
            entry(StreamKind::Depth, 95 * ms),
            entry(StreamKind::Depth, 112 * ms),
            entry(StreamKind::Depth, 225 * ms),
            entry(StreamKind::Depth, 318 * ms),
        ];
        let (frames, stats) = associate(&index, &[], true, DEFAULT_TOLERANCE_NS, None);
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[0].depth, Some(3));
        assert_eq!(frames[1].stamp_ns, 300 * ms);
        assert_eq!(frames[1].depth, Some(6));
        assert_eq!(stats.skipped_no_depth, 1);
        assert_eq!(stats.frames_with_pose, 0);
        assert_eq!(stats.duplicate_color_stamps, 0);
    }

    #[test]
    fn color_records_sharing_a_stamp_are_counted() {
        let ms = 1_000_000;
        let index = vec![
            entry(StreamKind::Color, 100 * ms),
            entry(StreamKind::Color, 200 * ms),
            entry(StreamKind::Color, 200 * ms),
            entry(StreamKind::Color, 200 * ms),
            entry(StreamKind::Color, 300 * ms),
        ];
        let (frames, stats) = associate(&index, &[], false, DEFAULT_TOLERANCE_NS, None);
        assert_eq!(frames.len(), 5, "each record stays a frame");
        assert_eq!(stats.duplicate_color_stamps, 2);
        assert_eq!(stats.first_duplicate_stamp_ns, Some(200 * ms));
    }

    #[test]
    fn pose_is_interpolated_inside_the_stream_only() {
        let a = Pose::from_parts(DVec3::ZERO, DQuat::IDENTITY);
        let b = Pose::from_parts(DVec3::new(2.0, 0.0, 0.0), DQuat::from_rotation_y(1.0));
        let poses = vec![(0, a), (100, b)];
        let mid = pose_at(&poses, 25, i64::MAX).unwrap();
        assert!((mid.translation() - DVec3::new(0.5, 0.0, 0.0)).length() < 1e-12);
        let angle = mid.rotation().angle_between(DQuat::IDENTITY);
        assert!((angle - 0.25).abs() < 1e-9, "angle {angle}");
        assert_eq!(pose_at(&poses, 100, i64::MAX), Some(b));
        assert_eq!(pose_at(&poses, -1, i64::MAX), None);
        assert_eq!(pose_at(&poses, 101, i64::MAX), None);
        // Across a gap longer than allowed: no pose, but the samples themselves stay.
        assert_eq!(pose_at(&poses, 25, 99), None);
        assert_eq!(pose_at(&poses, 100, 99), Some(b));
    }

    #[test]
    fn the_default_gap_is_five_median_intervals_and_at_least_50_ms() {
        let p = Pose::IDENTITY;
        let at = |stamps: &[i64]| -> Vec<(i64, Pose)> { stamps.iter().map(|&t| (t, p)).collect() };
        let ms = 1_000_000;
        // 100 Hz with one 300 ms hole: 5 x 10 ms = 50 ms.
        let mocap: Vec<i64> = (0..50)
            .map(|k| k * 10 * ms)
            .chain((0..50).map(|k| 790 * ms + k * 10 * ms))
            .collect();
        assert_eq!(default_max_pose_gap_ns(&at(&mocap)), Some(50 * ms));
        // A pose per 30 Hz frame: 5 x 33.3 ms.
        let frames: Vec<i64> = (0..30).map(|k| k * 33_333_333).collect();
        assert_eq!(default_max_pose_gap_ns(&at(&frames)), Some(5 * 33_333_333));
        assert_eq!(default_max_pose_gap_ns(&at(&[0])), None);
    }
}
