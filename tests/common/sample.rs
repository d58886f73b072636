//! A small recording for the format tests: a header with ground truth and an
//! attachment, three frames of color and depth, two poses and a truth record, with the
//! byte positions of everything in the written file.
#![allow(dead_code)]

use relume::raster::Image;
use relume::recording::format::{FRAME_HEADER_LEN, FrameHeader, IndexEntry, Tag};
use relume::recording::{
    ColorRecord, DepthRecord, Header, Intrinsics, Pose, PoseRecord, Provenance, Record, Recording,
    RecordingWriter, StreamKind, TruthRecord, codec,
};
use std::path::{Path, PathBuf};

pub const MS: i64 = 1_000_000;
/// Color stamps of the three frames; depth lies 1 ms after each.
pub const FRAME_STAMPS: [i64; 3] = [0, 33 * MS, 66 * MS];

pub fn header() -> Header {
    let mut provenance = Provenance {
        tool: "relume test".into(),
        tool_version: "0.1.0".into(),
        source: "tests/format.rs".into(),
        ..Provenance::default()
    };
    provenance.settings.insert("seed".into(), "7".into());
    let intrinsics = Intrinsics::PRIMESENSE.scaled_to(4, 3);
    Header {
        name: "tiny".into(),
        provenance,
        color_intrinsics: intrinsics,
        depth_intrinsics: intrinsics,
        depth_unit_m: 0.001,
        streams: vec![
            StreamKind::Color,
            StreamKind::Depth,
            StreamKind::Pose,
            StreamKind::Truth,
        ],
        ground_truth: None,
        attachments: Vec::new(),
    }
}

pub fn color(frame: u8) -> Record {
    let pixels = (0..12u8)
        .map(|i| [i * 20 + frame, 255 - i * 7, frame.wrapping_mul(40)])
        .collect();
    let img = Image::from_vec(4, 3, pixels).unwrap();
    Record::Color(ColorRecord {
        stamp_ns: FRAME_STAMPS[frame as usize],
        image: codec::encode_png_rgb8(&img).unwrap(),
    })
}

pub fn depth(frame: u8) -> Record {
    let units = (0..12u16).map(|i| 1000 + i * 37 + frame as u16).collect();
    Record::Depth(DepthRecord {
        stamp_ns: FRAME_STAMPS[frame as usize] + MS,
        image: codec::encode_png_u16(4, 3, units).unwrap(),
    })
}

pub fn pose(frame: u8) -> Record {
    Record::Pose(PoseRecord {
        stamp_ns: FRAME_STAMPS[frame as usize],
        pose: Pose::from_parts(
            glam::DVec3::new(0.1 * frame as f64, 0.0, 1.0),
            glam::DQuat::from_rotation_y(0.2 * frame as f64),
        ),
    })
}

pub fn truth(frame: u8) -> Record {
    let floats =
        |c: u8, k: f32| -> Vec<f32> { (0..12 * c as usize).map(|i| i as f32 * k).collect() };
    Record::Truth(Box::new(TruthRecord {
        stamp_ns: FRAME_STAMPS[frame as usize],
        color_transform: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        contrast: 1.0,
        depth: codec::encode_floats(4, 3, 1, &floats(1, 0.25), false),
        normals: codec::encode_floats(4, 3, 3, &floats(3, 0.01), true),
        radiance: codec::encode_floats(4, 3, 3, &floats(3, 0.5), true),
    }))
}

/// Nine records: three frames of color and depth, a truth record for frame 1, and
/// poses at frames 0 and 2 (frame 1's pose is interpolated).
pub fn records() -> Vec<Record> {
    vec![
        color(0),
        depth(0),
        pose(0),
        color(1),
        depth(1),
        truth(1),
        color(2),
        depth(2),
        pose(2),
    ]
}

pub fn write_recording(path: &Path, header: &Header, records: &[Record]) -> PathBuf {
    let mut w = RecordingWriter::create(path, header).unwrap();
    for r in records {
        w.write(r).unwrap();
    }
    assert_eq!(w.records(), records.len());
    w.finish().unwrap()
}

/// A written recording, its bytes and where everything lies in them.
pub struct Sample {
    pub _dir: tempfile::TempDir,
    pub path: PathBuf,
    pub bytes: Vec<u8>,
    pub records: Vec<Record>,
    pub index: Vec<IndexEntry>,
    /// Offset of the first stream record (end of the header record).
    pub body_start: u64,
    /// Offset of the index footer's frame.
    pub footer_at: u64,
}

impl Sample {
    pub fn new() -> Sample {
        let dir = tempfile::tempdir().unwrap();
        let path = write_recording(&dir.path().join("tiny.relume"), &header(), &records());
        let bytes = std::fs::read(&path).unwrap();
        let rec = Recording::open(&path).unwrap();
        let index = rec.index().to_vec();
        let body_start = index[0].offset;
        let last = index.last().unwrap();
        let footer_at = last.offset + FRAME_HEADER_LEN + last.len as u64;
        Sample {
            _dir: dir,
            path,
            bytes,
            records: records(),
            index,
            body_start,
            footer_at,
        }
    }

    pub fn len(&self) -> u64 {
        self.bytes.len() as u64
    }

    /// Writes `bytes` to a new file beside the sample and returns its path.
    pub fn variant(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let path = self.path.with_file_name(name);
        // A new file each time: truncating and rewriting one is slow on some file systems.
        let _ = std::fs::remove_file(&path);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    /// The record that starts at `offset` in the original file.
    pub fn original_at(&self, offset: u64) -> Option<&Record> {
        let i = self.index.iter().position(|e| e.offset == offset)?;
        Some(&self.records[i])
    }
}

/// The payload range of index entry `e` in the file's bytes.
pub fn payload_range(e: &IndexEntry) -> std::ops::Range<usize> {
    let start = (e.offset + FRAME_HEADER_LEN) as usize;
    start..start + e.len as usize
}

pub fn frame_header(bytes: &[u8], offset: u64) -> FrameHeader {
    let at = offset as usize;
    FrameHeader::parse(
        bytes[at..at + FRAME_HEADER_LEN as usize]
            .try_into()
            .unwrap(),
    )
}

/// Overwrites the frame header at `offset` (keeping its tag and stamp) so that it
/// declares `len` payload bytes.
pub fn set_len(bytes: &mut [u8], offset: u64, len: u32) {
    let at = offset as usize;
    bytes[at..at + 4].copy_from_slice(&len.to_le_bytes());
}

/// A complete frame (header and payload) with a correct checksum.
pub fn frame(tag: Tag, stamp_ns: i64, payload: &[u8]) -> Vec<u8> {
    let mut out = FrameHeader::encode(tag, stamp_ns, payload).to_vec();
    out.extend_from_slice(payload);
    out
}

pub fn assert_all_records_read_back(rec: &Recording, s: &Sample) {
    for (i, e) in rec.index().iter().enumerate() {
        let r = rec
            .read_record(i)
            .unwrap_or_else(|err| panic!("record {i}: {err}"));
        assert_eq!(Some(&r), s.original_at(e.offset), "record {i}");
    }
}
