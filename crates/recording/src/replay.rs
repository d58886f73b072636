//! Replay access to a recording: association once at open, then each frame's records
//! by seeking through the index.

use super::association::{AssociationStats, FrameRef, associate};
use super::codec;
use super::error::RecordingError;
use super::reader::Recording;
use super::types::{ColorRecord, DepthRecord, Pose, Record, StreamKind, TruthRecord};
use std::ops::Range;
use std::path::Path;

/// How to open a recording for replay.
#[derive(Clone, Copy, Debug)]
pub struct ReplayOptions {
    /// Tolerance between color and depth (and truth) stamps.
    pub tolerance_ns: i64,
    /// Skip (and count) records that fail their checksum or decoding instead of failing.
    pub skip_corrupt: bool,
    /// The largest gap between pose samples a frame's pose is interpolated across
    /// (`None`: [`super::association::default_max_pose_gap_ns`]).
    pub max_pose_gap_ns: Option<i64>,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        ReplayOptions {
            tolerance_ns: super::association::DEFAULT_TOLERANCE_NS,
            skip_corrupt: false,
            max_pose_gap_ns: None,
        }
    }
}

/// The records of one associated frame, still encoded.
#[derive(Clone, Debug)]
pub struct FrameRecords {
    /// Position among the associated frames.
    pub index: usize,
    pub stamp_ns: i64,
    pub color: ColorRecord,
    pub depth: Option<DepthRecord>,
    pub pose: Option<Pose>,
    pub truth: Option<Box<TruthRecord>>,
}

/// A recording opened for replay.
#[derive(Debug)]
pub struct Replay {
    pub recording: Recording,
    pub frames: Vec<FrameRef>,
    pub stats: AssociationStats,
}

impl Replay {
    /// Opens and associates `path`. Pose records are read now; a corrupt one is an error
    /// unless `skip_corrupt` is set, in which case it is skipped and counted.
    pub fn open(path: &Path, options: ReplayOptions) -> Result<Replay, RecordingError> {
        let recording = Recording::open(path)?;
        let mut poses = Vec::new();
        let mut skipped_corrupt_poses = 0;
        let mut corrupt_poses = Vec::new();
        for (i, e) in recording.index().iter().enumerate() {
            if e.kind != StreamKind::Pose {
                continue;
            }
            match recording.read_record(i) {
                Ok(Record::Pose(p)) => poses.push((p.stamp_ns, p.pose)),
                Ok(_) => unreachable!("read_record checks the kind against the index"),
                Err(_) if options.skip_corrupt => {
                    skipped_corrupt_poses += 1;
                    corrupt_poses.push((e.stamp_ns, i));
                }
                Err(e) => return Err(e),
            }
        }
        poses.sort_by_key(|p| p.0);
        let has_depth = recording.header().streams.contains(&StreamKind::Depth);
        let (frames, mut stats) = associate(
            recording.index(),
            &poses,
            has_depth,
            options.tolerance_ns,
            options.max_pose_gap_ns,
        );
        stats.skipped_corrupt_poses = skipped_corrupt_poses;
        let mut frames = frames;
        stats.frames_with_corrupt_pose =
            super::association::mark_corrupt_poses(&mut frames, &poses, &corrupt_poses);
        stats.frames_with_pose = frames.iter().filter(|f| f.pose.is_some()).count();
        Ok(Replay {
            recording,
            frames,
            stats,
        })
    }

    /// Number of associated frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Duration from the first to the last frame stamp, in seconds.
    pub fn duration_s(&self) -> f64 {
        match (self.frames.first(), self.frames.last()) {
            (Some(a), Some(b)) => b.stamp_ns.abs_diff(a.stamp_ns) as f64 * 1e-9,
            _ => 0.0,
        }
    }

    /// An error naming the record when frame `n`'s color or depth image (`records`, as
    /// [`Replay::read_frame`] gave them) does not decode, as `inspect --verify` finds:
    /// the checksum says the bytes are as written, not that they are an image.
    pub fn check_images(&self, n: usize, records: &FrameRecords) -> Result<(), RecordingError> {
        let Some(f) = self.frames.get(n) else {
            return Ok(());
        };
        let color = codec::decode_color(&records.color.image).map(drop);
        let depth = records
            .depth
            .as_ref()
            .map_or(Ok(()), |d| codec::decode_depth_units(&d.image).map(drop));
        for (record, result) in [(Some(f.color), color), (f.depth, depth)] {
            if let (Some(i), Err(e)) = (record, result) {
                let entry = self.recording.index()[i];
                return Err(RecordingError::Decode {
                    path: self.recording.path().to_path_buf(),
                    record: i,
                    kind: entry.kind.name(),
                    offset: entry.offset,
                    reason: format!("cannot decode its image: {e}"),
                });
            }
        }
        Ok(())
    }

    /// Reads frame `n`'s records (a seek per record, no scan).
    pub fn read_frame(&self, n: usize) -> Result<FrameRecords, RecordingError> {
        let f = self
            .frames
            .get(n)
            .ok_or_else(|| RecordingError::FrameOutOfRange {
                path: self.recording.path().to_path_buf(),
                frame: n,
                frames: self.frames.len(),
            })?;
        if let Some(record) = f.corrupt_pose {
            // The record's own error (it failed when the recording was opened).
            self.recording.read_record(record)?;
        }
        let color = match self.recording.read_record(f.color)? {
            Record::Color(c) => c,
            _ => unreachable!("read_record checks the kind against the index"),
        };
        let depth = match f.depth.map(|i| self.recording.read_record(i)).transpose()? {
            Some(Record::Depth(d)) => Some(d),
            None => None,
            _ => unreachable!("read_record checks the kind against the index"),
        };
        // A record whose image is not the size the header gives would be read past
        // or short by every stage that trusts the header.
        let header = self.recording.header();
        let sized = [
            (Some(f.color), Some(&color.image), &header.color_intrinsics),
            (
                f.depth,
                depth.as_ref().map(|d| &d.image),
                &header.depth_intrinsics,
            ),
        ];
        for (record, image, k) in sized {
            if let (Some(i), Some(image)) = (record, image)
                && (image.width, image.height) != (k.width, k.height)
            {
                let entry = self.recording.index()[i];
                return Err(RecordingError::Decode {
                    path: self.recording.path().to_path_buf(),
                    record: i,
                    kind: entry.kind.name(),
                    offset: entry.offset,
                    reason: format!(
                        "frame {n}'s image is {}x{}, but the header gives {}x{}",
                        image.width, image.height, k.width, k.height
                    ),
                });
            }
        }
        let truth = match f.truth.map(|i| self.recording.read_record(i)).transpose()? {
            Some(Record::Truth(t)) => Some(t),
            None => None,
            _ => unreachable!("read_record checks the kind against the index"),
        };
        Ok(FrameRecords {
            index: n,
            stamp_ns: f.stamp_ns,
            color,
            depth,
            pose: f.pose,
            truth,
        })
    }
}
/// A frame range as `relume replay --frames` takes it: `A..B` (B excluded), `A..`, `..B`
/// or `N`.
pub fn parse_frames(text: &str) -> Result<Range<usize>, String> {
    let invalid = || format!("invalid frame range {text:?}: expected A..B, A.., ..B or N");
    let num = |s: &str, default: usize| {
        if s.is_empty() {
            Ok(default)
        } else {
            s.parse::<usize>().map_err(|_| invalid())
        }
    };
    let range = match text.split_once("..") {
        Some((a, b)) => num(a, 0)?..num(b, usize::MAX)?,
        // A single index; an empty one is a mistake, not frame 0.
        None if text.is_empty() => return Err(invalid()),
        None => {
            let n = num(text, 0)?;
            n..n.saturating_add(1)
        }
    };
    if range.start >= range.end {
        return Err(format!("frame range {text:?} is empty"));
    }
    Ok(range)
}
