//! The command line given a damaged recording: corrupt records, images that do not
//! decode, a file cut short. Replay stops naming the record unless `--skip-corrupt` is
//! given, `inspect --verify` finds every such record, and complete frames are kept.

mod common;

use common::{ok, run_in, small_recording, stderr, stdout};
use relume::recording::format::{FRAME_HEADER_LEN, IndexEntry};
use relume::recording::{Recording, StreamKind};
use std::path::Path;

/// The `nth` record of `kind` in the recording at `path`: its number and index entry.
fn nth_record(path: &Path, kind: StreamKind, nth: usize) -> (usize, IndexEntry) {
    let rec = Recording::open(path).unwrap();
    rec.index()
        .iter()
        .enumerate()
        .filter(|(_, e)| e.kind == kind)
        .nth(nth)
        .map(|(i, e)| (i, *e))
        .unwrap()
}

/// Flips one byte in the middle of the payload of the `nth` record of `kind`.
fn corrupt_record(path: &Path, kind: StreamKind, nth: usize) -> (usize, u64) {
    let (record, entry) = nth_record(path, kind, nth);
    let mut bytes = std::fs::read(path).unwrap();
    bytes[(entry.offset + FRAME_HEADER_LEN + entry.len as u64 / 2) as usize] ^= 0x40;
    std::fs::write(path, bytes).unwrap();
    (record, entry.offset)
}

/// `relume replay small.relume --hash --skip-corrupt` in `d`, which must succeed: the
/// frames it replayed (from the hash lines) and its stderr.
fn replay_skipping_corrupt(d: &Path) -> (Vec<String>, String) {
    let o = ok(run_in(
        d,
        &[
            "replay",
            "small.relume",
            "--hash",
            "--out",
            "o",
            "--skip-corrupt",
        ],
    ));
    let frames = stdout(&o).lines().map(|l| l[..6].to_string()).collect();
    (frames, stderr(&o))
}

#[test]
fn a_corrupt_record_stops_replay_unless_skipped() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 6);
    let (record, offset) = corrupt_record(&path, StreamKind::Color, 2);
    let o = run_in(d, &["replay", "small.relume", "--hash", "--out", "o"]);
    assert_eq!(o.status.code(), Some(1));
    let expected = format!(
        "cannot read frame 2: small.relume: record {record} (color) at byte {offset} is corrupt: checksum mismatch"
    );
    assert!(stderr(&o).contains(&expected), "{}", stderr(&o));
    assert_eq!(stdout(&o).lines().count(), 2, "frames 0 and 1 complete");

    let (frames, errors) = replay_skipping_corrupt(d);
    assert_eq!(frames, ["000000", "000001", "000003", "000004", "000005"]);
    assert!(errors.contains("1 corrupt frame(s) skipped"), "{errors}");

    let o = run_in(d, &["inspect", "small.relume", "--verify"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stdout(&o).contains("1 corrupt"), "{}", stdout(&o));
    let o = run_in(d, &["inspect", "small.relume", "--verify", "--json"]);
    assert_eq!(o.status.code(), Some(1));
    let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let streams = doc["streams"].as_array().unwrap();
    let records: u64 = streams.iter().map(|s| s["records"].as_u64().unwrap()).sum();
    assert_eq!(doc["records_verified"], records);
    assert_eq!(doc["corrupt_records"].as_array().unwrap().len(), 1);
}

/// An image whose bytes are damaged but whose checksum was made to fit: `--verify`
/// counts it, and `--skip-corrupt` skips its frame rather than stopping in `decode`.
#[test]
fn an_image_that_does_not_decode_is_skipped_like_a_corrupt_record() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 4);
    let (record, entry) = nth_record(&path, StreamKind::Depth, 1);
    let mut bytes = std::fs::read(&path).unwrap();
    let start = (entry.offset + FRAME_HEADER_LEN) as usize;
    let end = start + entry.len as usize;
    // The PNG signature sits near the start of the image bytes in the payload.
    let png = start
        + bytes[start..end]
            .windows(4)
            .position(|w| w == b"\x89PNG")
            .unwrap();
    bytes[png + 1] ^= 0xFF;
    let crc = crc32fast::hash(&bytes[entry.offset as usize + 8..end]);
    bytes[entry.offset as usize + 4..entry.offset as usize + 8].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(&path, bytes).unwrap();

    let o = run_in(d, &["replay", "small.relume", "--hash", "--out", "o"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("stage `decode` (decode) failed at frame 1"),
        "{}",
        stderr(&o)
    );
    let (frames, errors) = replay_skipping_corrupt(d);
    assert_eq!(frames, ["000000", "000002", "000003"]);
    let expected = format!(
        "skipped corrupt frame 1: small.relume: record {record} (depth) at byte {} cannot be \
         decoded: cannot decode its image: ",
        entry.offset
    );
    assert!(errors.contains(&expected), "{errors}");
}

#[test]
fn a_truncated_recording_replays_its_complete_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 6);
    let rec = Recording::open(&path).unwrap();
    // Cut inside frame 4's color record: frames 0-3 stay complete.
    let cut = rec
        .index()
        .iter()
        .filter(|e| e.kind == StreamKind::Color)
        .nth(4)
        .unwrap()
        .offset
        + 30;
    drop(rec);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..cut as usize]).unwrap();
    let o = ok(run_in(
        d,
        &["replay", "small.relume", "--hash", "--out", "o"],
    ));
    assert_eq!(stdout(&o).lines().count(), 4);
    let err = stderr(&o);
    assert!(
        err.contains(&format!("warning: small.relume: truncated at byte {cut}")),
        "{err}"
    );
    let inspect = stdout(&ok(run_in(d, &["inspect", "small.relume"])));
    assert!(inspect.contains("DAMAGED"), "{inspect}");
}

#[test]
fn verify_decodes_images_and_fails_on_damage() {
    use relume::recording::{
        ColorRecord, DepthRecord, EncodedImage, Header, ImageEncoding, Intrinsics, Record,
        RecordingWriter,
    };
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let intrinsics = Intrinsics {
        width: 4,
        height: 3,
        fx: 4.0,
        fy: 4.0,
        cx: 1.5,
        cy: 1.0,
    };
    let mut w =
        RecordingWriter::create(&d.join("x.relume"), &Header::new("x", intrinsics, 0.001)).unwrap();
    // A PNG signature and nothing else: the record's checksum is right, its image is not.
    let color = EncodedImage {
        encoding: ImageEncoding::Png,
        width: 4,
        height: 3,
        channels: 3,
        bytes: b"\x89PNG\r\n\x1a\n".to_vec(),
    };
    let depth = EncodedImage {
        encoding: ImageEncoding::RawU16,
        width: 4,
        height: 3,
        channels: 1,
        bytes: vec![0x10; 24],
    };
    for r in [
        Record::Color(ColorRecord {
            stamp_ns: 0,
            image: color,
        }),
        Record::Depth(DepthRecord {
            stamp_ns: 0,
            image: depth,
        }),
    ] {
        w.write(&r).unwrap();
    }
    w.finish().unwrap();
    let o = run_in(d, &["inspect", "x.relume", "--verify"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("  verified  2 records, 1 corrupt\n"), "{out}");
    assert!(
        out.contains("\n    x.relume: record 0 (color): cannot decode its image: "),
        "{out}"
    );
    // A damaged file (its index cut off) fails the check too; without --verify,
    // inspect describes what it can and succeeds.
    let bytes = std::fs::read(d.join("x.relume")).unwrap();
    std::fs::write(d.join("cut.relume"), &bytes[..bytes.len() - 30]).unwrap();
    let o = run_in(d, &["inspect", "cut.relume", "--verify"]);
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    assert!(
        stdout(&o).contains("  DAMAGED   cut.relume: "),
        "{}",
        stdout(&o)
    );
    ok(run_in(d, &["inspect", "cut.relume"]));
}

#[test]
fn a_run_with_every_frame_skipped_as_corrupt_fails() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 2);
    for nth in 0..2 {
        corrupt_record(&path, StreamKind::Color, nth);
    }
    let expected = "error: small.relume: all 2 frames in the range are corrupt and were \
                    skipped: nothing was replayed\n";
    for args in [
        &["replay", "small.relume", "--skip-corrupt", "-p", "p.toml"][..],
        &[
            "bench",
            "small.relume",
            "--skip-corrupt",
            "-p",
            "p.toml",
            "--repeat",
            "1",
        ],
        &["eval", "small.relume", "--skip-corrupt", "-p", "p.toml"],
    ] {
        std::fs::write(
            d.join("p.toml"),
            "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nkind = \"normals.cross\"\n",
        )
        .unwrap();
        let o = run_in(d, args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(err.ends_with(expected), "{args:?}: {err}");
    }
}

#[test]
fn a_corrupt_pose_skips_the_frames_that_take_their_pose_from_it() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 6);
    // Frame 0's pose (nothing before it to interpolate from) and frame 3's (mid-run:
    // it used to be interpolated from frames 2 and 4, silently).
    corrupt_record(&path, StreamKind::Pose, 0);
    corrupt_record(&path, StreamKind::Pose, 3);
    let (frames, errors) = replay_skipping_corrupt(d);
    assert_eq!(frames, ["000001", "000002", "000004", "000005"]);
    assert!(
        errors.contains("2 corrupt frame(s) skipped: 2 with a corrupt pose record"),
        "{errors}"
    );
    assert!(errors.contains("skipped corrupt frame 3: "), "{errors}");
    let o = ok(run_in(d, &["inspect", "small.relume", "--json"]));
    let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(doc["association"]["frames_with_corrupt_pose"], 2);
    assert_eq!(doc["frames_with_pose"], 4);
}
