//! The `.relume` format: round trips, the byte layout, atomic writing, magic bytes and
//! versions, and replay of extreme stamps. Every test builds a small recording with the
//! public API (tests/common/sample.rs).

mod common;

use common::sample::*;
use relume::recording::format::{
    FORMAT_VERSION, FRAME_HEADER_LEN, FrameHeader, IndexEntry, MAGIC, PREAMBLE_LEN, TRAILER_LEN,
    TRAILER_MAGIC, Tag,
};
use relume::recording::{
    Attachment, ColorRecord, DepthRecord, Pose, PoseRecord, Record, Recording, RecordingError,
    RecordingWriter, Replay, ReplayOptions, SceneTruth, codec,
};
use std::path::Path;

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
        let names = common::file_names(dir.path());
        assert_eq!(names.len(), 1, "{names:?}");
        assert!(names[0].starts_with(".import.relume.") && names[0].ends_with(".partial"));
    }
    assert_eq!(common::file_names(dir.path()), Vec::<String>::new());

    // Finishing renames onto the final name and leaves nothing else behind.
    let written = write_recording(&path, &header(), &records());
    assert_eq!(written, path);
    assert_eq!(
        common::file_names(dir.path()),
        vec!["import.relume".to_string()]
    );

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
    assert_eq!(
        common::file_names(dir.path()),
        vec!["import.relume".to_string()]
    );
}

#[test]
fn a_failed_finish_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    // The final name becomes a non-empty directory while the recording is written:
    // the rename in finish fails. (A directory there from the start is refused by
    // create.)
    let path = dir.path().join("blocked.relume");
    let mut w = RecordingWriter::create(&path, &header()).unwrap();
    w.write(&records()[0]).unwrap();
    std::fs::create_dir(&path).unwrap();
    std::fs::write(path.join("keep"), b"x").unwrap();
    match w.finish() {
        Err(RecordingError::Io { path: p, .. }) => assert_eq!(p, path),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        common::file_names(dir.path()),
        vec!["blocked.relume".to_string()]
    );
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

/// A pose record that is intact (its CRC holds) but not a rigid transform is an error
/// naming the record, so that --verify counts it and --skip-corrupt skips it.
#[test]
fn poses_that_are_not_rigid_are_refused_when_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("poses.relume");
    let bad = |translation: [f64; 3], rotation: [f64; 4]| {
        Record::Pose(PoseRecord {
            stamp_ns: FRAME_STAMPS[0],
            pose: Pose {
                translation,
                rotation,
            },
        })
    };
    let recs = vec![
        bad([0.0; 3], [0.0, 0.0, 0.0, 2.0]),
        bad([0.0; 3], [0.0; 4]),
        bad([f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]),
        bad([0.0; 3], [0.0, f64::INFINITY, 0.0, 1.0]),
        pose(1),
    ];
    write_recording(&path, &header(), &recs);
    let rec = Recording::open(&path).unwrap();
    let reason = |i: usize| match rec.read_record(i) {
        Err(RecordingError::Decode { record, reason, .. }) => {
            assert_eq!(record, i);
            reason
        }
        other => panic!("record {i}: {other:?}"),
    };
    assert_eq!(
        reason(0),
        "the pose's rotation quaternion has length 2.0000, expected 1"
    );
    assert_eq!(
        reason(1),
        "the pose's rotation quaternion has length 0.0000, expected 1"
    );
    assert!(reason(2).starts_with("the pose holds a non-finite value"));
    assert!(reason(3).starts_with("the pose holds a non-finite value"));
    assert_eq!(rec.read_record(4).unwrap(), pose(1));
}

/// Writes the seed corpus of the fuzz target (`fuzz/seeds/reader`): a complete
/// recording, the same without its footer, and one with a corrupt record (no `.relume`
/// extension: git ignores those). Run with
/// `cargo test --test format_roundtrip write_fuzz_seeds -- --ignored`.
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
