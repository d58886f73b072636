//! Absurd declared sizes (frame lengths, MessagePack lengths, footer entries, trailer
//! offsets, image sizes) are clean errors found before any allocation of that size.

mod common;

use common::sample::*;
use relume::recording::format::{
    FRAME_HEADER_LEN, IndexEntry, MAX_PAYLOAD_LEN, PREAMBLE_LEN, TRAILER_LEN, TRAILER_MAGIC, Tag,
};
use relume::recording::{
    EncodedImage, ImageEncoding, Record, Recording, RecordingError, Replay, ReplayOptions,
    StreamKind, codec,
};

use std::time::{Duration, Instant};

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
    for declared in [u32::MAX, MAX_PAYLOAD_LEN + 1, MAX_PAYLOAD_LEN, 1 << 30, 7] {
        let mut bytes = s.bytes.clone();
        set_len(&mut bytes, victim.offset, declared);
        let path = s.variant("huge.relume", &bytes);
        let rec = Recording::open(&path).unwrap();
        assert!(rec.damage().is_none());
        // In a complete file the index knows the length: the damage is named as such,
        // not taken for the file ending early.
        match quickly(|| rec.read_record(4)).unwrap_err() {
            RecordingError::Corrupt { offset, reason, .. } => {
                assert_eq!(offset, victim.offset);
                assert_eq!(
                    reason,
                    format!(
                        "record 4 (depth) has a damaged length field: its frame declares \
                         {declared} bytes, the index {}",
                        victim.len
                    )
                );
            }
            other => panic!("{declared}: {other:?}"),
        }
        assert_eq!(rec.read_record(3).unwrap(), s.records[3]);
        assert_eq!(rec.read_record(5).unwrap(), s.records[5]);

        // Without a footer the scan loses that record only: it resumes at the next
        // record whose checksum holds.
        let cut = s.footer_at as usize;
        let path = s.variant("huge-cut.relume", &bytes[..cut]);
        let rec = quickly(|| Recording::open(&path)).unwrap();
        let mut expected = s.index.clone();
        expected.remove(4);
        assert_eq!(rec.index(), &expected[..], "{declared}");
        assert_all_records_read_back(&rec, &s);
        match rec.damage() {
            Some(RecordingError::Corrupt { offset, reason, .. }) => {
                assert_eq!(*offset, victim.offset);
                let next = s.index[5].offset;
                assert!(
                    reason.starts_with(&format!("the record at byte {} is damaged", victim.offset))
                        && reason.ends_with(&format!(
                            "the scan resumed at byte {next}, the next record whose checksum \
                             holds, losing {} bytes",
                            next - victim.offset
                        )),
                    "{reason}"
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
    // Frames 1 and 2 would take their pose from the corrupt record (frame 2's own; frame
    // 1 lies between frame 0's pose and it): reading them fails with that record's
    // error, so --skip-corrupt skips them.
    let marked: Vec<Option<usize>> = replay.frames.iter().map(|f| f.corrupt_pose).collect();
    assert_eq!(marked, [None, Some(8), Some(8)]);
    assert_eq!(replay.stats.frames_with_corrupt_pose, 2);
    assert_eq!(replay.stats.frames_with_pose, 1);
    replay.read_frame(0).unwrap();
    for n in 1..3 {
        match replay.read_frame(n) {
            Err(RecordingError::Checksum { record: 8, .. }) => {}
            other => panic!("{other:?}"),
        }
    }
}

// ---------------------------------------------------- header values

/// The sample with its header replaced by `edit`ed values (the body follows unchanged;
/// its footer offsets may no longer match, which opening survives by a scan).
fn with_header(s: &Sample, edit: impl Fn(&mut relume::recording::Header)) -> std::path::PathBuf {
    let len = frame_header(&s.bytes, PREAMBLE_LEN).len as u64;
    let payload_start = (PREAMBLE_LEN + FRAME_HEADER_LEN) as usize;
    let mut h: relume::recording::Header =
        rmp_serde::from_slice(&s.bytes[payload_start..payload_start + len as usize]).unwrap();
    edit(&mut h);
    let mut bytes = s.bytes[..PREAMBLE_LEN as usize].to_vec();
    bytes.extend(frame(Tag::Header, 0, &rmp_serde::to_vec_named(&h).unwrap()));
    bytes.extend_from_slice(&s.bytes[payload_start + len as usize..]);
    s.variant("header.relume", &bytes)
}

#[test]
fn header_values_that_no_stage_can_use_are_refused_on_open() {
    let s = Sample::new();
    type Edit = fn(&mut relume::recording::Header);
    let cases: [(Edit, &str); 13] = [
        (
            |h| h.color_intrinsics.width = 100_000,
            "color intrinsics: image size 100000x3 is not between 1 and 16384 on each side",
        ),
        (
            |h| (h.depth_intrinsics.width, h.depth_intrinsics.height) = (16384, 16384),
            "depth intrinsics: image size 16384x16384 is over 67108864 pixels",
        ),
        (
            |h| h.depth_intrinsics.fx = 0.0,
            "depth intrinsics: fx = 0 is not a finite positive focal length",
        ),
        (
            |h| h.color_intrinsics.fy = f64::NAN,
            "color intrinsics: fy = NaN is not a finite positive focal length",
        ),
        (
            |h| h.depth_unit_m = -0.001,
            "depth unit -0.001 m is not a finite positive length",
        ),
        (
            |h| h.depth_unit_m = 0.0,
            "depth unit 0 m is not a finite positive length",
        ),
        // Finite but absurd: every depth would be 1e297 km, or a focal length of 1e-300
        // pixels (a field of view of 180 degrees less nothing).
        (
            |h| h.depth_unit_m = 1e300,
            "depth unit 1e300 m is not a depth sensor's: it must lie between 1e-6 m and 10 m \
             per stored unit",
        ),
        (
            |h| h.depth_unit_m = 1e-30,
            "depth unit 1e-30 m is not a depth sensor's: it must lie between 1e-6 m and 10 m \
             per stored unit",
        ),
        (
            |h| h.depth_intrinsics.fx = 1e-300,
            "depth intrinsics: fx = 1e-300 px is not a focal length for a 4x3 image: it must \
             lie between 0.05 and 100 times the image's larger side (0.2 to 400 px)",
        ),
        (
            |h| h.color_intrinsics.cx = -1e308,
            "color intrinsics: cx = -1e308 px lies further outside the 4x3 image than its own \
             size (it must lie between -4 and 8 px)",
        ),
        (
            |h| h.color_intrinsics.fy = 1e6,
            "color intrinsics: fy = 1000000 px is not a focal length for a 4x3 image: it must \
             lie between 0.05 and 100 times the image's larger side (0.2 to 400 px)",
        ),
        // Where the virtual object goes: a NaN would place it nowhere, silently.
        (
            |h| {
                h.ground_truth = Some(relume::recording::SceneTruth {
                    object_position: [0.0, f64::NAN, 1.0],
                    description: String::new(),
                })
            },
            "ground truth: the object position [0, NaN, 1] is not a point of a room: each \
             coordinate must be finite and within 10000 m",
        ),
        (
            |h| {
                h.ground_truth = Some(relume::recording::SceneTruth {
                    object_position: [0.0, 0.0, -1e9],
                    description: String::new(),
                })
            },
            "ground truth: the object position [0, 0, -1000000000] is not a point of a room: \
             each coordinate must be finite and within 10000 m",
        ),
    ];
    for (edit, reason) in cases {
        let path = with_header(&s, edit);
        let Err(err) = quickly(|| Recording::open(&path)) else {
            panic!("{reason}: the header opened");
        };
        assert_eq!(
            err.to_string(),
            format!("{}: the header is invalid: {reason}", path.display())
        );
    }
    // The writer refuses them too.
    let mut h = header();
    h.depth_intrinsics.fx = -1.0;
    let err =
        relume::recording::writer::RecordingWriter::create(&s.path.with_file_name("w.relume"), &h)
            .err()
            .expect("refused");
    assert!(err.to_string().ends_with("cannot write this header: depth intrinsics: fx = -1 is not a finite positive focal length"), "{err}");
}

#[test]
fn an_image_whose_size_differs_from_the_header_names_its_frame() {
    let s = Sample::new();
    let path = with_header(&s, |h| {
        h.color_intrinsics.width *= 2;
        h.color_intrinsics.cx *= 2.0;
    });
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let err = replay.read_frame(0).unwrap_err().to_string();
    assert!(
        err.contains("(color) at byte")
            && err.ends_with(&format!(
                "cannot be decoded: frame 0's image is {}x{}, but the header gives {}x{}",
                header().color_intrinsics.width,
                header().color_intrinsics.height,
                2 * header().color_intrinsics.width,
                header().color_intrinsics.height
            )),
        "{err}"
    );
}

/// A named pipe given as a recording is refused at once, not waited on for a writer
/// that never comes.
#[cfg(unix)]
#[test]
fn a_named_pipe_given_as_a_recording_is_refused_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let fifo = tmp.path().join("pipe.relume");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo");
    assert!(made.success());
    let mut child = common::relume()
        .args(["inspect", fifo.to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > Duration::from_secs(10) {
            child.kill().unwrap();
            panic!("relume inspect waited on the pipe");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = child.wait_with_output().unwrap();
    assert!(!o.status.success());
    assert_eq!(
        String::from_utf8_lossy(&o.stderr),
        format!(
            "error: {}: is not a regular file (a device, pipe or socket)\n",
            fifo.display()
        )
    );
}

/// Strings of a header (name, provenance, attachments) reach the terminal with their
/// control characters escaped: a recording cannot send escape sequences to it.
#[test]
fn inspect_escapes_control_characters_of_the_header() {
    let s = Sample::new();
    let path = with_header(&s, |h| {
        h.name = "room\u{1b}[2J\u{7}".into();
        h.provenance.source = "a\rb".into();
    });
    let o = common::relume()
        .args(["inspect", path.to_str().unwrap()])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}");
    assert!(
        !out.contains('\u{1b}') && !out.contains('\u{7}') && !out.contains('\r'),
        "{out:?}"
    );
    assert!(out.contains("(room\\u{1b}[2J\\u{7}, format"), "{out}");
    assert!(out.contains("from a\\u{d}b\n"), "{out}");
}

/// The sample with a footer listing `entries` (CRC-valid, trailer pointing at it).
fn with_index(s: &Sample, name: &str, entries: &[IndexEntry]) -> std::path::PathBuf {
    let mut bytes = s.bytes[..s.footer_at as usize].to_vec();
    bytes.extend(frame(
        Tag::Index,
        0,
        &rmp_serde::to_vec_named(entries).unwrap(),
    ));
    bytes.extend_from_slice(&s.footer_at.to_le_bytes());
    bytes.extend_from_slice(&TRAILER_MAGIC);
    s.variant(name, &bytes)
}

/// A footer whose checksum holds but which does not list the records as they lie
/// (one listed twice, one left out, two swapped) is damage: the records are found by a
/// scan, every one once, and `inspect --verify` says so.
#[test]
fn a_checksummed_footer_that_lies_about_the_records_is_damage() {
    let s = Sample::new();
    let true_index = Recording::open(&s.path).unwrap().index().to_vec();
    let n = true_index.len();
    let mut doubled = true_index.clone();
    doubled.insert(3, true_index[2]);
    let mut short = true_index.clone();
    short.remove(4);
    let mut swapped = true_index.clone();
    swapped.swap(1, 2);
    let all_at_one: Vec<IndexEntry> = vec![true_index[0]; 1000];
    for (name, entries, reason) in [
        (
            "doubled",
            &doubled,
            "index entry 3 says a record starts at byte",
        ),
        (
            "short",
            &short,
            "index entry 4 says a record starts at byte",
        ),
        (
            "swapped",
            &swapped,
            "index entry 1 says a record starts at byte",
        ),
        (
            "one",
            &all_at_one,
            "index entry 1 says a record starts at byte",
        ),
    ] {
        let path = with_index(&s, &format!("{name}.relume"), entries);
        let rec = quickly(|| Recording::open(&path)).unwrap();
        assert_eq!(
            rec.index(),
            &true_index[..],
            "{name}: the scan finds each record once"
        );
        let damage = rec.damage().map(|d| d.to_string()).unwrap_or_default();
        assert!(damage.contains(reason), "{name}: {damage}");
        let o = common::relume()
            .args(["inspect", path.to_str().unwrap(), "--verify"])
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        assert_eq!(o.status.code(), Some(1), "{name}: {out}");
        assert!(
            out.contains(&format!("verified  {n} records, 0 corrupt")),
            "{out}"
        );
        assert!(out.contains("DAMAGED"), "{out}");
    }
}
