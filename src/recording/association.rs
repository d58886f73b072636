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

/// The pose at `t`, interpolated between the bracketing samples of `poses` (sorted by
/// stamp); `None` outside the pose stream.
pub fn pose_at(poses: &[(i64, Pose)], t: i64) -> Option<Pose> {
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
) -> (Vec<FrameRef>, AssociationStats) {
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
            pose: pose_at(poses, stamp_ns),
        };
        stats.frames_with_pose += frame.pose.is_some() as usize;
        stats.frames_with_truth += frame.truth.is_some() as usize;
        frames.push(frame);
    }
    stats.frames = frames.len();
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
        let (frames, stats) = associate(&index, &[], true, DEFAULT_TOLERANCE_NS);
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[0].depth, Some(3));
        assert_eq!(frames[1].stamp_ns, 300 * ms);
        assert_eq!(frames[1].depth, Some(6));
        assert_eq!(stats.skipped_no_depth, 1);
        assert_eq!(stats.frames_with_pose, 0);
    }

    #[test]
    fn pose_is_interpolated_inside_the_stream_only() {
        let a = Pose::from_parts(DVec3::ZERO, DQuat::IDENTITY);
        let b = Pose::from_parts(DVec3::new(2.0, 0.0, 0.0), DQuat::from_rotation_y(1.0));
        let poses = vec![(0, a), (100, b)];
        let mid = pose_at(&poses, 25).unwrap();
        assert!((mid.translation() - DVec3::new(0.5, 0.0, 0.0)).length() < 1e-12);
        let angle = mid.rotation().angle_between(DQuat::IDENTITY);
        assert!((angle - 0.25).abs() < 1e-9, "angle {angle}");
        assert_eq!(pose_at(&poses, 100), Some(b));
        assert_eq!(pose_at(&poses, -1), None);
        assert_eq!(pose_at(&poses, 101), None);
    }
}
