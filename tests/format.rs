//! The `.relume` recording format: round trips, atomic writing, and a reader that is
//! robust against wrong magic, newer versions, truncation, bit flips and absurd
//! declared sizes. Every test builds a small recording with the public API.

use relume::raster::Image;
use relume::recording::format::{
    FORMAT_VERSION, FRAME_HEADER_LEN, FrameHeader, IndexEntry, MAGIC, MAX_PAYLOAD_LEN,
    PREAMBLE_LEN, TRAILER_LEN, TRAILER_MAGIC, Tag,
};
use relume::recording::{
    Attachment, ColorRecord, DepthRecord, EncodedImage, Header, ImageEncoding, Intrinsics, Pose,
    PoseRecord, Provenance, Record, Recording, RecordingError, RecordingWriter, Replay,
    ReplayOptions, SceneTruth, StreamKind, TruthRecord, codec,
};
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const MS: i64 = 1_000_000;
/// Color stamps of the three frames; depth lies 1 ms after each.
const FRAME_STAMPS: [i64; 3] = [0, 33 * MS, 66 * MS];

fn header() -> Header {
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

fn color(frame: u8) -> Record {
    let pixels = (0..12u8)
        .map(|i| [i * 20 + frame, 255 - i * 7, frame.wrapping_mul(40)])
        .collect();
    let img = Image::from_vec(4, 3, pixels).unwrap();
    Record::Color(ColorRecord {
        stamp_ns: FRAME_STAMPS[frame as usize],
        image: codec::encode_png_rgb8(&img).unwrap(),
    })
}

fn depth(frame: u8) -> Record {
    let units = (0..12u16).map(|i| 1000 + i * 37 + frame as u16).collect();
    Record::Depth(DepthRecord {
        stamp_ns: FRAME_STAMPS[frame as usize] + MS,
        image: codec::encode_png_u16(4, 3, units).unwrap(),
    })
}

fn pose(frame: u8) -> Record {
    Record::Pose(PoseRecord {
        stamp_ns: FRAME_STAMPS[frame as usize],
        pose: Pose::from_parts(
            glam::DVec3::new(0.1 * frame as f64, 0.0, 1.0),
            glam::DQuat::from_rotation_y(0.2 * frame as f64),
        ),
    })
}

fn truth(frame: u8) -> Record {
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
fn records() -> Vec<Record> {
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

fn write_recording(path: &Path, header: &Header, records: &[Record]) -> PathBuf {
    let mut w = RecordingWriter::create(path, header).unwrap();
    for r in records {
        w.write(r).unwrap();
    }
    assert_eq!(w.records(), records.len());
    w.finish().unwrap()
}

/// A written recording, its bytes and where everything lies in them.
struct Sample {
    _dir: tempfile::TempDir,
    path: PathBuf,
    bytes: Vec<u8>,
    records: Vec<Record>,
    index: Vec<IndexEntry>,
    /// Offset of the first stream record (end of the header record).
    body_start: u64,
    /// Offset of the index footer's frame.
    footer_at: u64,
}

impl Sample {
    fn new() -> Sample {
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

    fn len(&self) -> u64 {
        self.bytes.len() as u64
    }

    /// Writes `bytes` to a new file beside the sample and returns its path.
    fn variant(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let path = self.path.with_file_name(name);
        // A new file each time: truncating and rewriting one is slow on some file systems.
        let _ = std::fs::remove_file(&path);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    /// The record that starts at `offset` in the original file.
    fn original_at(&self, offset: u64) -> Option<&Record> {
        let i = self.index.iter().position(|e| e.offset == offset)?;
        Some(&self.records[i])
    }
}

/// The payload range of index entry `e` in the file's bytes.
fn payload_range(e: &IndexEntry) -> std::ops::Range<usize> {
    let start = (e.offset + FRAME_HEADER_LEN) as usize;
    start..start + e.len as usize
}

fn frame_header(bytes: &[u8], offset: u64) -> FrameHeader {
    let at = offset as usize;
    FrameHeader::parse(
        bytes[at..at + FRAME_HEADER_LEN as usize]
            .try_into()
            .unwrap(),
    )
}

/// Overwrites the frame header at `offset` (keeping its tag and stamp) so that it
/// declares `len` payload bytes.
fn set_len(bytes: &mut [u8], offset: u64, len: u32) {
    let at = offset as usize;
    bytes[at..at + 4].copy_from_slice(&len.to_le_bytes());
}

/// A complete frame (header and payload) with a correct checksum.
fn frame(tag: Tag, stamp_ns: i64, payload: &[u8]) -> Vec<u8> {
    let mut out = FrameHeader::encode(tag, stamp_ns, payload).to_vec();
    out.extend_from_slice(payload);
    out
}

fn assert_all_records_read_back(rec: &Recording, s: &Sample) {
    for (i, e) in rec.index().iter().enumerate() {
        let r = rec
            .read_record(i)
            .unwrap_or_else(|err| panic!("record {i}: {err}"));
        assert_eq!(Some(&r), s.original_at(e.offset), "record {i}");
    }
}

// ---------------------------------------------------------------- round trip

#[test]
fn round_trip_gives_back_identical_header_and_records() {
    let s = Sample::new();
    let rec = Recording::open(&s.path).unwrap();
    assert_eq!(rec.header(), &header());
    assert_eq!(rec.version(), FORMAT_VERSION);
    assert_eq!(rec.file_len(), s.len());
    assert!(rec.damage().is_none(), "{:?}", rec.damage());
    assert_eq!(rec.index().len(), s.records.len());
    for (i, (e, r)) in rec.index().iter().zip(&s.records).enumerate() {
        assert_eq!(e.kind, r.kind(), "record {i}");
        assert_eq!(e.stamp_ns, r.stamp_ns(), "record {i}");
        assert_eq!(&rec.read_record(i).unwrap(), r, "record {i}");
    }
    // Asking for a record past the end is an error, not a panic.
    match rec.read_record(9) {
        Err(RecordingError::Invalid { reason, .. }) => {
            assert!(
                reason.contains("record 9 does not exist (9 records)"),
                "{reason}"
            )
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_header_with_attachments_and_no_records_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = header();
    h.ground_truth = Some(SceneTruth {
        object_position: [0.0, 0.3, -1.5],
        description: "a spot on the floor".into(),
    });
    h.attachments.push(Attachment {
        name: "environment".into(),
        kind: "envmap/latlong".into(),
        image: codec::encode_floats(8, 4, 3, &[0.5; 96], false),
    });
    let path = write_recording(&dir.path().join("empty.relume"), &h, &[]);
    let rec = Recording::open(&path).unwrap();
    assert_eq!(rec.header(), &h);
    assert!(rec.index().is_empty());
    assert!(rec.damage().is_none());
    let env = rec.header().attachment("environment").unwrap();
    assert_eq!(codec::decode_floats(&env.image).unwrap(), vec![0.5; 96]);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    assert!(replay.is_empty());
    assert_eq!(replay.duration_s(), 0.0);
}

#[test]
fn byte_layout_matches_the_format_description() {
    let s = Sample::new();
    let b = &s.bytes;
    assert_eq!(b[..8], MAGIC);
    assert_eq!(b[8..16], [1, 0, 0, 0, 1, 0, 0, 0]);
    // The header is the first record, tag 0, stamp 0, with a valid checksum.
    let h = frame_header(b, PREAMBLE_LEN);
    assert_eq!((h.tag_byte, h.reserved, h.stamp_ns), (0, [0; 3], 0));
    assert_eq!(PREAMBLE_LEN + FRAME_HEADER_LEN + h.len as u64, s.body_start);
    let payload = &b[(PREAMBLE_LEN + FRAME_HEADER_LEN) as usize..s.body_start as usize];
    assert_eq!(h.crc, FrameHeader::checksum(0, 0, payload));
    // Stream records follow back to back, each with its tag, stamp and checksum.
    let mut offset = s.body_start;
    for (e, r) in s.index.iter().zip(&s.records) {
        assert_eq!(e.offset, offset);
        let f = frame_header(b, offset);
        assert_eq!(f.len, e.len);
        assert_eq!(Tag::from_byte(f.tag_byte), Some(Tag::Stream(r.kind())));
        assert_eq!(f.reserved, [0; 3]);
        assert_eq!(f.stamp_ns, r.stamp_ns());
        assert_eq!(
            f.crc,
            FrameHeader::checksum(f.tag_byte, f.stamp_ns, &b[payload_range(e)])
        );
        offset += FRAME_HEADER_LEN + e.len as u64;
    }
    // Then the index footer (tag 255) and the trailer pointing at it.
    assert_eq!(offset, s.footer_at);
    let f = frame_header(b, s.footer_at);
    assert_eq!(f.tag_byte, 255);
    assert_eq!(
        s.footer_at + FRAME_HEADER_LEN + f.len as u64 + TRAILER_LEN,
        s.len()
    );
    let trailer = &b[b.len() - TRAILER_LEN as usize..];
    assert_eq!(
        u64::from_le_bytes(trailer[..8].try_into().unwrap()),
        s.footer_at
    );
    assert_eq!(trailer[8..], TRAILER_MAGIC);
    let at = (s.footer_at + FRAME_HEADER_LEN) as usize;
    let index: Vec<IndexEntry> = rmp_serde::from_slice(&b[at..at + f.len as usize]).unwrap();
    assert_eq!(index, s.index);
}

#[test]
fn replay_associates_and_reads_every_frame() {
    let s = Sample::new();
    let replay = Replay::open(&s.path, ReplayOptions::default()).unwrap();
    assert_eq!(replay.len(), 3);
    assert_eq!(replay.stats.frames_with_pose, 3);
    assert_eq!(replay.stats.frames_with_truth, 1);
    let (Record::Pose(p0), Record::Pose(p2)) = (&s.records[2], &s.records[8]) else {
        unreachable!()
    };
    let poses = [p0.pose, Pose::interpolate(&p0.pose, &p2.pose, 0.5), p2.pose];
    let colors = [0, 3, 6];
    for n in 0..3 {
        let f = replay.read_frame(n).unwrap();
        assert_eq!(f.index, n);
        assert_eq!(f.stamp_ns, FRAME_STAMPS[n]);
        assert_eq!(Record::Color(f.color), s.records[colors[n]]);
        assert_eq!(Record::Depth(f.depth.unwrap()), s.records[colors[n] + 1]);
        let pose = f.pose.unwrap();
        for k in 0..3 {
            assert!((pose.translation[k] - poses[n].translation[k]).abs() < 1e-12);
        }
        assert_eq!(f.truth.is_some(), n == 1);
    }
    assert_eq!(
        Record::Truth(replay.read_frame(1).unwrap().truth.unwrap()),
        s.records[5]
    );
    match replay.read_frame(3) {
        Err(RecordingError::FrameOutOfRange { frame, frames, .. }) => {
            assert_eq!((frame, frames), (3, 3))
        }
        other => panic!("{other:?}"),
    }
}

// ------------------------------------------------------------ atomic writing

fn dir_entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn writer_publishes_only_on_finish_and_cleans_up_when_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("import.relume");
    // An import interrupted after a few records: nothing under the final name, and the
    // temporary file is gone too.
    {
        let mut w = RecordingWriter::create(&path, &header()).unwrap();
        for r in &records()[..4] {
            w.write(r).unwrap();
        }
        assert!(!path.exists(), "the final name appears before finish");
        let names = dir_entries(dir.path());
        assert_eq!(names.len(), 1, "{names:?}");
        assert!(names[0].starts_with(".import.relume.") && names[0].ends_with(".partial"));
    }
    assert_eq!(dir_entries(dir.path()), Vec::<String>::new());

    // Finishing renames onto the final name and leaves nothing else behind.
    let written = write_recording(&path, &header(), &records());
    assert_eq!(written, path);
    assert_eq!(dir_entries(dir.path()), vec!["import.relume".to_string()]);

    // Rewriting replaces the old file atomically: until finish, readers see the old one.
    let mut other = header();
    other.name = "second".into();
    let mut w = RecordingWriter::create(&path, &other).unwrap();
    w.write(&records()[0]).unwrap();
    assert_eq!(Recording::open(&path).unwrap().header().name, "tiny");
    w.finish().unwrap();
    let rec = Recording::open(&path).unwrap();
    assert_eq!(rec.header(), &other);
    assert_eq!(rec.index().len(), 1);
    assert_eq!(dir_entries(dir.path()), vec!["import.relume".to_string()]);
}

#[test]
fn a_failed_finish_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    // The final name is a non-empty directory: the rename in finish fails.
    let path = dir.path().join("blocked.relume");
    std::fs::create_dir(&path).unwrap();
    std::fs::write(path.join("keep"), b"x").unwrap();
    let mut w = RecordingWriter::create(&path, &header()).unwrap();
    w.write(&records()[0]).unwrap();
    match w.finish() {
        Err(RecordingError::Io { path: p, .. }) => assert_eq!(p, path),
        other => panic!("{other:?}"),
    }
    assert_eq!(dir_entries(dir.path()), vec!["blocked.relume".to_string()]);
}

// ------------------------------------------------------- magic and versions

#[test]
fn wrong_magic_is_bad_magic() {
    let s = Sample::new();
    let mut not_ours = s.bytes.clone();
    not_ours[1] = b'X';
    let cases: [(&str, &[u8]); 4] = [
        ("empty", b""),
        ("text", b"hello, this is not a recording at all"),
        (
            "png",
            &[
                0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n', 0, 0, 0, 13,
            ],
        ),
        ("flipped", &not_ours),
    ];
    for (name, bytes) in cases {
        let path = s.variant(name, bytes);
        match Recording::open(&path) {
            Err(RecordingError::BadMagic { path: p }) => assert_eq!(p, path, "{name}"),
            other => panic!("{name}: {other:?}"),
        }
        assert!(Replay::open(&path, ReplayOptions::default()).is_err());
    }
    // A missing file is an I/O error naming it.
    let missing = s.path.with_file_name("missing.relume");
    match Recording::open(&missing) {
        Err(RecordingError::Io { path, source }) => {
            assert_eq!(path, missing);
            assert_eq!(source.kind(), std::io::ErrorKind::NotFound);
        }
        other => panic!("{other:?}"),
    }
}

fn with_versions(bytes: &[u8], version: (u16, u16), min_reader: (u16, u16)) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[8..10].copy_from_slice(&version.0.to_le_bytes());
    b[10..12].copy_from_slice(&version.1.to_le_bytes());
    b[12..14].copy_from_slice(&min_reader.0.to_le_bytes());
    b[14..16].copy_from_slice(&min_reader.1.to_le_bytes());
    b
}

#[test]
fn newer_versions_are_unsupported_and_newer_minors_open() {
    let s = Sample::new();
    let unsupported = [
        ((2, 0), (1, 0)),
        ((2, 0), (2, 0)),
        ((1, 1), (1, 1)),
        ((1, 0), (1, 1)),
        ((u16::MAX, u16::MAX), (u16::MAX, u16::MAX)),
    ];
    for (version, min_reader) in unsupported {
        let path = s.variant(
            "newer.relume",
            &with_versions(&s.bytes, version, min_reader),
        );
        match Recording::open(&path) {
            Err(RecordingError::UnsupportedVersion {
                path: p,
                found,
                min_reader: m,
                supported,
            }) => {
                assert_eq!(p, path);
                assert_eq!(found, format!("{}.{}", version.0, version.1));
                assert_eq!(m, format!("{}.{}", min_reader.0, min_reader.1));
                assert_eq!(supported, FORMAT_VERSION.to_string());
            }
            other => panic!("{version:?} {min_reader:?}: {other:?}"),
        }
    }
    // A newer minor version that this reader may read opens, and reads the same.
    let path = s.variant("minor.relume", &with_versions(&s.bytes, (1, 7), (1, 0)));
    let rec = Recording::open(&path).unwrap();
    assert_eq!((rec.version().major, rec.version().minor), (1, 7));
    assert_all_records_read_back(&rec, &s);
}

// --------------------------------------------------------------- truncation

#[test]
fn every_cut_point_recovers_exactly_the_complete_records() {
    let s = Sample::new();
    // Frame starts of the stream records and the footer: the frame a cut lands in.
    let mut frames: Vec<(u64, u64)> = s
        .index
        .iter()
        .map(|e| (e.offset, e.offset + FRAME_HEADER_LEN + e.len as u64))
        .collect();
    let footer_end = s.len() - TRAILER_LEN;
    frames.push((s.footer_at, footer_end));
    // Grown a byte at a time: rewriting (truncating) a file thousands of times is slow
    // on some file systems.
    let path = s.path.with_file_name("cut.relume");
    let mut file = std::fs::File::create(&path).unwrap();
    for cut in 0..=s.len() {
        if cut > 0 {
            file.write_all(&s.bytes[cut as usize - 1..cut as usize])
                .unwrap();
        }
        let opened = Recording::open(&path);
        if cut == 0 {
            assert!(
                matches!(opened, Err(RecordingError::BadMagic { .. })),
                "{opened:?}"
            );
            continue;
        }
        if cut < s.body_start {
            let where_ = if cut < PREAMBLE_LEN {
                "inside the preamble"
            } else {
                "the header"
            };
            match opened {
                Err(RecordingError::Truncated { offset, what, .. }) => {
                    assert_eq!(offset, cut);
                    assert!(what.contains(where_), "cut {cut}: {what}");
                }
                other => panic!("cut {cut}: {other:?}"),
            }
            continue;
        }
        let rec = opened.unwrap_or_else(|e| panic!("cut {cut}: {e}"));
        let expected: Vec<IndexEntry> = s
            .index
            .iter()
            .copied()
            .filter(|e| e.offset + FRAME_HEADER_LEN + e.len as u64 <= cut)
            .collect();
        assert_eq!(rec.index(), &expected[..], "cut {cut}");
        assert_all_records_read_back(&rec, &s);
        if cut == s.len() {
            assert!(rec.damage().is_none());
            continue;
        }
        match rec.damage() {
            Some(RecordingError::Truncated { offset, what, .. }) => {
                assert_eq!(*offset, cut, "cut {cut}: {what}");
                match frames
                    .iter()
                    .find(|&&(start, end)| start < cut && cut < end)
                {
                    // The cut lands inside a frame: the message names where it starts.
                    Some((start, _)) => {
                        assert!(
                            what.contains(&format!("at byte {start}")),
                            "cut {cut}: {what}"
                        )
                    }
                    None => assert_eq!(what, "the index footer is missing", "cut {cut}"),
                }
            }
            other => panic!("cut {cut}: {other:?}"),
        }
        let message = rec.damage().unwrap().to_string();
        assert!(
            message.contains(&format!("truncated at byte {cut}")),
            "{message}"
        );
        // Replay of what is left works frame by frame.
        let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
        for n in 0..replay.len() {
            replay
                .read_frame(n)
                .unwrap_or_else(|e| panic!("cut {cut}, frame {n}: {e}"));
        }
    }
}

// ---------------------------------------------------------------- checksums

#[test]
fn a_flipped_payload_bit_is_a_checksum_error_naming_the_record() {
    let s = Sample::new();
    for (i, e) in s.index.iter().enumerate() {
        let mut bytes = s.bytes.clone();
        let range = payload_range(e);
        bytes[range.start + range.len() / 2] ^= 0x10;
        let path = s.variant("flip.relume", &bytes);
        let rec = Recording::open(&path).unwrap();
        assert!(rec.damage().is_none());
        assert_eq!(rec.index(), &s.index[..]);
        for j in 0..s.index.len() {
            let got = rec.read_record(j);
            if j != i {
                assert_eq!(got.unwrap(), s.records[j], "record {j} with {i} corrupt");
                continue;
            }
            let err = got.unwrap_err();
            let message = err.to_string();
            match err {
                RecordingError::Checksum {
                    path: p,
                    record,
                    kind,
                    offset,
                    stored,
                    computed,
                } => {
                    assert_eq!(p, path);
                    assert_eq!(record, i);
                    assert_eq!(kind, e.kind.name());
                    assert_eq!(offset, e.offset);
                    assert_eq!(stored, frame_header(&s.bytes, e.offset).crc);
                    assert_ne!(stored, computed);
                }
                other => panic!("record {i}: {other:?}"),
            }
            assert!(
                message.contains(&format!(
                    "record {i} ({}) at byte {}",
                    e.kind.name(),
                    e.offset
                )),
                "{message}"
            );
        }
    }
}

#[test]
fn a_corrupt_header_fails_to_open() {
    let s = Sample::new();
    let mut bytes = s.bytes.clone();
    bytes[(PREAMBLE_LEN + FRAME_HEADER_LEN + 3) as usize] ^= 1;
    let path = s.variant("header.relume", &bytes);
    match Recording::open(&path) {
        Err(RecordingError::Checksum {
            record,
            kind,
            offset,
            ..
        }) => assert_eq!((record, kind, offset), (0, "header", PREAMBLE_LEN)),
        other => panic!("{other:?}"),
    }
}

/// Which part of the file a byte belongs to.
#[derive(Debug, PartialEq)]
enum Part {
    Preamble,
    Header,
    /// Record `i`; `field` is the byte's position in the frame (20 and up: payload).
    Record {
        i: usize,
        field: u64,
    },
    Footer,
}

fn part_of(s: &Sample, at: u64) -> Part {
    if at < PREAMBLE_LEN {
        Part::Preamble
    } else if at < s.body_start {
        Part::Header
    } else if at < s.footer_at {
        let i = s.index.iter().rposition(|e| e.offset <= at).unwrap();
        Part::Record {
            i,
            field: at - s.index[i].offset,
        }
    } else {
        Part::Footer
    }
}

#[test]
fn every_single_bit_flip_is_detected_or_harmless() {
    let s = Sample::new();
    // One file, patched in place a byte at a time.
    let path = s.variant("flipped.relume", &s.bytes);
    let file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    let mut bytes = s.bytes.clone();
    for at in 0..s.len() {
        for bit in 0..8 {
            bytes[at as usize] ^= 1 << bit;
            file.write_all_at(&bytes[at as usize..at as usize + 1], at)
                .unwrap();
            let ctx = format!("byte {at} bit {bit} ({:?})", part_of(&s, at));
            let opened = Recording::open(&path);
            match (part_of(&s, at), opened) {
                (Part::Preamble, Err(e)) => match e {
                    RecordingError::BadMagic { .. } => assert!(at < 8, "{ctx}"),
                    RecordingError::UnsupportedVersion { .. } => assert!(at >= 8, "{ctx}"),
                    other => panic!("{ctx}: {other:?}"),
                },
                (Part::Preamble, Ok(rec)) => {
                    // Only an older major (1 -> 0), an older minimum reader or a newer
                    // minor version still opens.
                    assert!(
                        (at == 8 || at == 12) && bit == 0 || at == 10 || at == 11,
                        "{ctx}"
                    );
                    assert!(rec.damage().is_none(), "{ctx}");
                    assert_eq!(rec.index(), &s.index[..], "{ctx}");
                    assert_all_records_read_back(&rec, &s);
                }
                (Part::Header, Err(e)) => assert!(
                    matches!(
                        e,
                        RecordingError::Checksum { .. }
                            | RecordingError::Corrupt { .. }
                            | RecordingError::Truncated { .. }
                    ),
                    "{ctx}: {e:?}"
                ),
                (Part::Header, Ok(_)) => panic!("{ctx}: a damaged header opens"),
                (_, Err(e)) => panic!("{ctx}: {e}"),
                (Part::Record { i, field }, Ok(rec)) => {
                    // The footer is intact: the index is the written one, and only the
                    // flipped record fails.
                    assert!(rec.damage().is_none(), "{ctx}");
                    assert_eq!(rec.index(), &s.index[..], "{ctx}");
                    let e = s.index[i];
                    for j in (0..s.index.len()).filter(|&j| j != i) {
                        assert_eq!(rec.read_record(j).unwrap(), s.records[j], "{ctx}");
                    }
                    let err = rec.read_record(i).unwrap_err();
                    match (field, err) {
                        // Length: over the limit, past the end, or not the indexed one.
                        (0..4, RecordingError::Corrupt { offset, .. }) => {
                            assert_eq!(offset, e.offset, "{ctx}")
                        }
                        (0..4, RecordingError::Truncated { offset, .. }) => {
                            assert_eq!(offset, s.len(), "{ctx}")
                        }
                        // Tag or reserved bytes.
                        (8..12, RecordingError::Corrupt { offset, .. }) => {
                            assert_eq!(offset, e.offset, "{ctx}")
                        }
                        // Checksum, stamp or payload.
                        (4..8 | 12.., RecordingError::Checksum { record, offset, .. }) => {
                            assert_eq!((record, offset), (i, e.offset), "{ctx}")
                        }
                        (_, other) => panic!("{ctx}: {other:?}"),
                    }
                }
                (Part::Footer, Ok(rec)) => {
                    // A damaged footer or trailer: a scan recovers every record.
                    let damage = rec.damage().unwrap_or_else(|| panic!("{ctx}: no damage"));
                    assert!(
                        matches!(
                            damage,
                            RecordingError::Checksum { .. }
                                | RecordingError::Corrupt { .. }
                                | RecordingError::Truncated { .. }
                        ),
                        "{ctx}: {damage:?}"
                    );
                    assert_eq!(rec.index(), &s.index[..], "{ctx}");
                    assert_all_records_read_back(&rec, &s);
                }
            }
            bytes[at as usize] ^= 1 << bit;
        }
        file.write_all_at(&bytes[at as usize..at as usize + 1], at)
            .unwrap();
    }
}

// ---------------------------------------------------- absurd declared sizes

/// Runs `f`, which must fail fast (no allocation of a declared size can be that fast).
fn quickly<T>(f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    assert!(
        t.elapsed() < Duration::from_secs(2),
        "took {:?}",
        t.elapsed()
    );
    out
}

#[test]
fn a_record_declaring_4_gib_is_rejected_before_allocation() {
    let s = Sample::new();
    let victim = s.index[4];
    for declared in [u32::MAX, MAX_PAYLOAD_LEN + 1, MAX_PAYLOAD_LEN, 1 << 30] {
        let mut bytes = s.bytes.clone();
        set_len(&mut bytes, victim.offset, declared);
        let path = s.variant("huge.relume", &bytes);
        let rec = Recording::open(&path).unwrap();
        assert!(rec.damage().is_none());
        let err = quickly(|| rec.read_record(4)).unwrap_err();
        if declared > MAX_PAYLOAD_LEN {
            match err {
                RecordingError::Corrupt { offset, reason, .. } => {
                    assert_eq!(offset, victim.offset);
                    assert!(
                        reason.contains(&format!("declares {declared} bytes, over the limit")),
                        "{reason}"
                    );
                }
                other => panic!("{declared}: {other:?}"),
            }
        } else {
            match err {
                RecordingError::Truncated { offset, what, .. } => {
                    assert_eq!(offset, s.len());
                    assert!(
                        what.contains(&format!("at byte {}", victim.offset)),
                        "{what}"
                    );
                }
                other => panic!("{declared}: {other:?}"),
            }
        }
        assert_eq!(rec.read_record(3).unwrap(), s.records[3]);
        assert_eq!(rec.read_record(5).unwrap(), s.records[5]);

        // Without a footer the scan stops there, keeping the records before it.
        let cut = s.footer_at as usize;
        let path = s.variant("huge-cut.relume", &bytes[..cut]);
        let rec = quickly(|| Recording::open(&path)).unwrap();
        assert_eq!(rec.index(), &s.index[..4]);
        assert_all_records_read_back(&rec, &s);
        match rec.damage() {
            Some(RecordingError::Corrupt { offset, .. }) => {
                assert!(declared > MAX_PAYLOAD_LEN);
                assert_eq!(*offset, victim.offset);
            }
            Some(RecordingError::Truncated { offset, what, .. }) => {
                assert!(declared <= MAX_PAYLOAD_LEN);
                assert_eq!(*offset, cut as u64);
                assert!(
                    what.contains(&format!("record 4 at byte {}", victim.offset)),
                    "{what}"
                );
            }
            other => panic!("{declared}: {other:?}"),
        }
    }
}

#[test]
fn a_header_declaring_4_gib_fails_to_open() {
    let s = Sample::new();
    let mut bytes = s.bytes.clone();
    set_len(&mut bytes, PREAMBLE_LEN, u32::MAX);
    let path = s.variant("huge-header.relume", &bytes);
    match quickly(|| Recording::open(&path)) {
        Err(RecordingError::Corrupt { offset, reason, .. }) => {
            assert_eq!(offset, PREAMBLE_LEN);
            assert!(reason.contains("over the limit"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

/// The file up to the footer (no footer, no trailer) followed by `tail`, so the scan
/// indexes whatever frames `tail` holds.
fn without_footer_then(s: &Sample, tail: &[u8]) -> Vec<u8> {
    let mut bytes = s.bytes[..s.footer_at as usize].to_vec();
    bytes.extend_from_slice(tail);
    bytes
}

#[test]
fn payloads_declaring_huge_messagepack_lengths_are_decode_errors() {
    let s = Sample::new();
    // A color record whose image bytes claim u32::MAX bytes (bin32), one whose map
    // claims u32::MAX entries (map32), one whose pixels array claims u32::MAX entries,
    // and a pose whose string key claims u32::MAX bytes (str32).
    let mut bin = b"\x82\xa8stamp_ns\x00\xa5image\x85\xa8encoding\xa3Png\xa5width\x04\xa6height\x03\xa8channels\x03\xa5bytes\xc6".to_vec();
    bin.extend_from_slice(&[0xff; 4]);
    bin.extend_from_slice(&[0; 64]);
    let map = [0xdf, 0xff, 0xff, 0xff, 0xff, 0xa1, b'x', 0x00];
    let array = [0xdd, 0xff, 0xff, 0xff, 0xff, 0x01, 0x02];
    let str32 = [0x81, 0xdb, 0xff, 0xff, 0xff, 0xff, b'a', b'b'];
    // An unknown field nesting arrays 100 000 deep: must not overflow the stack.
    let mut deep = vec![0x81, 0xa1, b'z'];
    deep.extend(std::iter::repeat_n(0x91, 100_000));
    deep.push(0xc0);
    let cases: [(StreamKind, &[u8]); 5] = [
        (StreamKind::Color, &bin),
        (StreamKind::Color, &map),
        (StreamKind::Depth, &array),
        (StreamKind::Pose, &str32),
        (StreamKind::Color, &deep),
    ];
    for (kind, payload) in cases {
        let bytes = without_footer_then(&s, &frame(Tag::Stream(kind), 5, payload));
        let path = s.variant("msgpack.relume", &bytes);
        let rec = Recording::open(&path).unwrap();
        assert_eq!(rec.index().len(), 10);
        assert_eq!(rec.index()[9].offset, s.footer_at);
        let err = quickly(|| rec.read_record(9)).unwrap_err();
        match err {
            RecordingError::Decode {
                record,
                kind: k,
                offset,
                ..
            } => assert_eq!((record, k, offset), (9, kind.name(), s.footer_at)),
            other => panic!("{kind:?}: {other:?}"),
        }
        // Replay reads poses at open: a bad one fails the open with the same error.
        let replay = Replay::open(&path, ReplayOptions::default());
        if kind == StreamKind::Pose {
            assert!(matches!(
                replay,
                Err(RecordingError::Decode { record: 9, .. })
            ));
        } else {
            let replay = replay.unwrap();
            for n in 0..replay.len() {
                let got = replay.read_frame(n);
                let uses_9 = replay.frames[n].color == 9 || replay.frames[n].depth == Some(9);
                assert_eq!(got.is_err(), uses_9, "frame {n}");
            }
        }
    }
}

#[test]
fn an_index_footer_with_absurd_entries_falls_back_to_a_scan() {
    let s = Sample::new();
    let absurd = [
        IndexEntry {
            offset: u64::MAX,
            ..s.index[0]
        },
        IndexEntry {
            offset: u64::MAX - 10,
            len: u32::MAX,
            ..s.index[0]
        },
        IndexEntry {
            len: u32::MAX,
            ..s.index[0]
        },
        IndexEntry {
            offset: 0,
            ..s.index[0]
        },
        IndexEntry {
            offset: s.footer_at,
            ..s.index[0]
        },
    ];
    for entry in absurd {
        let mut index = s.index.clone();
        index[0] = entry;
        let payload = rmp_serde::to_vec_named(&index).unwrap();
        let mut tail = frame(Tag::Index, 0, &payload);
        tail.extend_from_slice(&s.footer_at.to_le_bytes());
        tail.extend_from_slice(&TRAILER_MAGIC);
        let path = s.variant("index.relume", &without_footer_then(&s, &tail));
        let rec = quickly(|| Recording::open(&path)).unwrap();
        match rec.damage() {
            Some(RecordingError::Corrupt { offset, reason, .. }) => {
                assert_eq!(*offset, s.footer_at);
                assert!(reason.contains("index entry 0 points outside"), "{reason}");
            }
            other => panic!("{entry:?}: {other:?}"),
        }
        assert_eq!(rec.index(), &s.index[..]);
        assert_all_records_read_back(&rec, &s);
    }
}

#[test]
fn a_trailer_pointing_anywhere_falls_back_to_a_scan() {
    let s = Sample::new();
    let trailer_at = s.len() - TRAILER_LEN;
    let targets = [
        0,
        PREAMBLE_LEN,
        s.index[3].offset,
        s.footer_at + 1,
        trailer_at,
        trailer_at - FRAME_HEADER_LEN + 1,
        s.len(),
        u64::MAX - FRAME_HEADER_LEN + 1,
        u64::MAX - 5,
        u64::MAX,
    ];
    for target in targets {
        let mut bytes = s.bytes.clone();
        bytes[trailer_at as usize..trailer_at as usize + 8].copy_from_slice(&target.to_le_bytes());
        let path = s.variant("trailer.relume", &bytes);
        let rec = quickly(|| Recording::open(&path)).unwrap_or_else(|e| panic!("{target}: {e}"));
        match rec.damage() {
            Some(RecordingError::Corrupt { offset, .. }) => {
                assert!([trailer_at, target].contains(offset), "{target}: {offset}")
            }
            other => panic!("{target}: {other:?}"),
        }
        assert_eq!(rec.index(), &s.index[..], "{target}");
        assert_all_records_read_back(&rec, &s);
    }
}

#[test]
fn images_declaring_absurd_sizes_are_codec_errors() {
    let png = match &color(0) {
        Record::Color(c) => c.image.clone(),
        _ => unreachable!(),
    };
    for (w, h) in [(u32::MAX, u32::MAX), (1 << 16, 1 << 16), (0, 3), (4, 0)] {
        let img = EncodedImage {
            width: w,
            height: h,
            ..png.clone()
        };
        let err = quickly(|| codec::decode_color(&img)).unwrap_err();
        assert!(
            err.0.contains("implausible image size"),
            "{w}x{h}: {}",
            err.0
        );
        let raw = EncodedImage {
            encoding: ImageEncoding::RawU16,
            channels: 1,
            ..img.clone()
        };
        assert!(quickly(|| codec::decode_depth_units(&raw)).is_err());
        let floats = EncodedImage {
            encoding: ImageEncoding::ShuffledF32,
            ..img
        };
        assert!(quickly(|| codec::decode_floats(&floats)).is_err());
    }
    // A PNG whose stored size disagrees with its own header is an error, not a panic.
    let lying = EncodedImage { width: 8, ..png };
    let err = codec::decode_color(&lying).unwrap_err();
    assert!(err.0.contains("differs from the stored 8x3"), "{}", err.0);
}

// ------------------------------------------------------------------- replay

#[test]
fn replay_of_a_corrupt_color_record_names_it_in_read_frame() {
    let s = Sample::new();
    let color1 = s.index[3];
    assert_eq!(color1.kind, StreamKind::Color);
    let mut bytes = s.bytes.clone();
    bytes[payload_range(&color1).end - 2] ^= 0x80;
    let path = s.variant("corrupt-color.relume", &bytes);
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    assert_eq!(replay.len(), 3);
    let err = replay.read_frame(1).unwrap_err();
    let message = err.to_string();
    match err {
        RecordingError::Checksum {
            path: p,
            record,
            kind,
            offset,
            ..
        } => {
            assert_eq!(p, path);
            assert_eq!((record, kind, offset), (3, "color", color1.offset));
        }
        other => panic!("{other:?}"),
    }
    assert!(message.contains(&format!("record 3 (color) at byte {}", color1.offset)));
    assert_eq!(
        Record::Color(replay.read_frame(0).unwrap().color),
        s.records[0]
    );
    assert_eq!(
        Record::Color(replay.read_frame(2).unwrap().color),
        s.records[6]
    );
}

#[test]
fn replay_of_a_corrupt_pose_fails_at_open_unless_skipping() {
    let s = Sample::new();
    let pose2 = s.index[8];
    assert_eq!(pose2.kind, StreamKind::Pose);
    let mut bytes = s.bytes.clone();
    bytes[payload_range(&pose2).start + 5] ^= 0x01;
    let path = s.variant("corrupt-pose.relume", &bytes);
    match Replay::open(&path, ReplayOptions::default()) {
        Err(RecordingError::Checksum {
            record,
            kind,
            offset,
            ..
        }) => assert_eq!((record, kind, offset), (8, "pose", pose2.offset)),
        other => panic!("{other:?}"),
    }
    let options = ReplayOptions {
        skip_corrupt: true,
        ..ReplayOptions::default()
    };
    let replay = Replay::open(&path, options).unwrap();
    assert_eq!(replay.stats.skipped_corrupt_poses, 1);
    assert_eq!(replay.len(), 3);
    // Only frame 0 lies inside the remaining pose stream.
    assert_eq!(replay.stats.frames_with_pose, 1);
    for n in 0..3 {
        replay.read_frame(n).unwrap();
    }
}

/// Stamps anywhere in the i64 range are accepted by the writer, so replay must cope
/// with them (nearest-stamp and interpolation arithmetic must not overflow).
#[test]
fn replay_copes_with_extreme_stamps() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("extreme.relume");
    let stamped = |r: Record, stamp_ns: i64| match r {
        Record::Color(c) => Record::Color(ColorRecord { stamp_ns, ..c }),
        Record::Depth(d) => Record::Depth(DepthRecord { stamp_ns, ..d }),
        Record::Pose(p) => Record::Pose(PoseRecord { stamp_ns, ..p }),
        other => other,
    };
    let recs = vec![
        stamped(color(0), i64::MAX),
        stamped(color(1), -5),
        stamped(color(2), i64::MIN),
        stamped(depth(0), i64::MIN),
        stamped(depth(1), i64::MAX),
        stamped(pose(0), i64::MIN),
        stamped(pose(2), i64::MAX),
    ];
    write_recording(&path, &header(), &recs);
    for tolerance_ns in [0, 20 * MS, i64::MAX] {
        let options = ReplayOptions {
            tolerance_ns,
            ..ReplayOptions::default()
        };
        let replay = Replay::open(&path, options).unwrap();
        assert!(replay.duration_s().is_finite());
        for n in 0..replay.len() {
            replay.read_frame(n).unwrap();
        }
    }
}

/// Writes the seed corpus of the fuzz target (`fuzz/seeds/reader`): a complete
/// recording, the same without its footer, and one with a corrupt record (no `.relume`
/// extension: git ignores those). Run with
/// `cargo test --test format write_fuzz_seeds -- --ignored`.
#[test]
#[ignore = "writes files into fuzz/seeds/reader"]
fn write_fuzz_seeds() {
    let s = Sample::new();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/reader");
    std::fs::create_dir_all(&dir).unwrap();
    let mut corrupt = s.bytes.clone();
    corrupt[payload_range(&s.index[3]).start + 9] ^= 0x04;
    std::fs::write(dir.join("complete"), &s.bytes).unwrap();
    std::fs::write(dir.join("no-footer"), &s.bytes[..s.footer_at as usize]).unwrap();
    std::fs::write(dir.join("corrupt-color"), &corrupt).unwrap();
}
