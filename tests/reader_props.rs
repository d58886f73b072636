//! Property tests of the `.relume` reader: random bytes, and random mutations of a
//! valid small recording (bit flips, overwrites, truncations, insertions, removals,
//! duplicated chunks, rewritten frame fields) never make `Recording::open`,
//! `read_record`, `Replay::open` or `read_frame` panic; whatever reads back must be
//! consistent with the index, and after a few bit flips every record that still reads
//! back is the one that was written.

mod common;

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::RngSeed;
use relume::raster::Image;
use relume::recording::format::{FRAME_HEADER_LEN, MAX_PAYLOAD_LEN, PREAMBLE_LEN};
use relume::recording::{
    ColorRecord, DepthRecord, Header, Pose, PoseRecord, Record, Recording, RecordingError,
    RecordingWriter, Replay, ReplayOptions, TruthRecord, codec,
};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const MS: i64 = 1_000_000;

/// A valid recording and what was written into it.
struct Sample {
    bytes: Vec<u8>,
    header: Header,
    /// Each stream record with the offset of its frame.
    records: Vec<(u64, Record)>,
    /// Offsets of every frame: header, stream records, index footer.
    frames: Vec<u64>,
}

fn sample() -> &'static Sample {
    static SAMPLE: OnceLock<Sample> = OnceLock::new();
    SAMPLE.get_or_init(build_sample)
}

fn build_sample() -> Sample {
    let header = common::sample::header();
    let mut records = Vec::new();
    for f in 0..3u8 {
        let stamp_ns = f as i64 * 33 * MS;
        let pixels = (0..12u8).map(|i| [i * 20 + f, 100, 255 - i]).collect();
        records.push(Record::Color(ColorRecord {
            stamp_ns,
            image: codec::encode_png_rgb8(&Image::from_vec(4, 3, pixels).unwrap()).unwrap(),
        }));
        let units = (0..12u16).map(|i| 1000 + 10 * i + f as u16).collect();
        records.push(Record::Depth(DepthRecord {
            stamp_ns: stamp_ns + MS,
            image: codec::encode_png_u16(4, 3, units).unwrap(),
        }));
        if f != 1 {
            records.push(Record::Pose(PoseRecord {
                stamp_ns,
                pose: Pose::from_parts(
                    glam::DVec3::new(f as f64, 0.0, 0.0),
                    glam::DQuat::from_rotation_z(0.1 * f as f64),
                ),
            }));
        }
    }
    let floats: Vec<f32> = (0..36).map(|i| i as f32 * 0.1).collect();
    records.push(Record::Truth(Box::new(TruthRecord {
        stamp_ns: 33 * MS,
        color_transform: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        contrast: 1.0,
        depth: codec::encode_floats(4, 3, 1, &floats[..12], false),
        normals: codec::encode_floats(4, 3, 3, &floats, true),
        radiance: codec::encode_floats(4, 3, 3, &floats, true),
    })));

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sample.relume");
    let mut w = RecordingWriter::create(&path, &header).unwrap();
    for r in &records {
        w.write(r).unwrap();
    }
    w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let rec = Recording::open(&path).unwrap();
    assert!(rec.damage().is_none());
    let index = rec.index();
    assert_eq!(index.len(), records.len());
    let last = index.last().unwrap();
    let mut frames = vec![PREAMBLE_LEN];
    frames.extend(index.iter().map(|e| e.offset));
    frames.push(last.offset + FRAME_HEADER_LEN + last.len as u64);
    Sample {
        bytes,
        header,
        records: index.iter().map(|e| e.offset).zip(records).collect(),
        frames,
    }
}

/// A file holding `bytes` in a fresh temporary directory (a new file per case:
/// rewriting one file over and over is slow on some file systems).
struct Scratch {
    _dir: tempfile::TempDir,
    path: PathBuf,
}

fn scratch(bytes: &[u8]) -> Scratch {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("case.relume");
    std::fs::write(&path, bytes).unwrap();
    Scratch { _dir: dir, path }
}

/// What reading a file gave: the header, and each indexed record by offset.
struct Outcome {
    header: Option<Header>,
    records: Vec<(u64, Result<Record, RecordingError>)>,
}

/// Opens `path`, reads every indexed record, then replays every frame with and
/// without `skip_corrupt`, checking what must hold whatever the bytes.
fn exercise(path: &Path) -> Outcome {
    let mut outcome = Outcome {
        header: None,
        records: Vec::new(),
    };
    let opened = Recording::open(path);
    match &opened {
        Err(e) => {
            let _ = e.to_string();
        }
        Ok(rec) => {
            outcome.header = Some(rec.header().clone());
            if let Some(d) = rec.damage() {
                let _ = d.to_string();
            }
            for (i, e) in rec.index().iter().enumerate() {
                // Only complete records are listed.
                assert!(e.offset >= PREAMBLE_LEN + FRAME_HEADER_LEN, "{e:?}");
                assert!(e.len <= MAX_PAYLOAD_LEN, "{e:?}");
                assert!(
                    e.offset + FRAME_HEADER_LEN + e.len as u64 <= rec.file_len(),
                    "{e:?} in a file of {} bytes",
                    rec.file_len()
                );
                let got = rec.read_record(i);
                match &got {
                    Ok(r) => assert_eq!(r.kind(), e.kind),
                    Err(err) => {
                        let _ = err.to_string();
                    }
                }
                outcome.records.push((e.offset, got));
            }
            let past = rec.read_record(rec.index().len());
            assert!(
                matches!(past, Err(RecordingError::Invalid { .. })),
                "{past:?}"
            );
        }
    }
    for skip_corrupt in [false, true] {
        let options = ReplayOptions {
            skip_corrupt,
            ..ReplayOptions::default()
        };
        match Replay::open(path, options) {
            Err(e) => {
                let _ = e.to_string();
                // Replay fails only where the recording does, or on a bad pose.
                assert!(opened.is_err() || !skip_corrupt, "{e}");
            }
            Ok(replay) => {
                assert!(opened.is_ok());
                assert_eq!(replay.len(), replay.stats.frames);
                for n in 0..replay.len() {
                    match replay.read_frame(n) {
                        Ok(f) => assert_eq!(f.index, n),
                        Err(e) => {
                            let _ = e.to_string();
                        }
                    }
                }
                let past = replay.read_frame(replay.len());
                assert!(
                    matches!(past, Err(RecordingError::FrameOutOfRange { .. })),
                    "{past:?}"
                );
            }
        }
    }
    outcome
}

/// One change to a recording's bytes. Positions are drawn as [`Index`]es and resolved
/// against the current length, so mutations compose.
#[derive(Clone, Debug)]
enum Mutation {
    FlipBit(Index, u8),
    Overwrite(Index, Vec<u8>),
    Truncate(Index),
    Insert(Index, Vec<u8>),
    Remove(Index, usize),
    /// Copies `len` bytes from one place to another (inserted, not overwritten).
    Duplicate {
        from: Index,
        len: usize,
        to: Index,
    },
    /// Rewrites the length field of one of the original frames.
    FrameLen(Index, u32),
    /// Rewrites the tag byte of one of the original frames.
    FrameTag(Index, u8),
    /// Rewrites the stamp of one of the original frames.
    FrameStamp(Index, i64),
    /// Rewrites the footer offset in the trailer (the last 16 bytes).
    TrailerOffset(u64),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let bytes = prop::collection::vec(any::<u8>(), 1..16);
    let len = prop_oneof![
        Just(0u32),
        Just(1),
        Just(MAX_PAYLOAD_LEN),
        Just(MAX_PAYLOAD_LEN + 1),
        Just(u32::MAX),
        0..4096u32,
        any::<u32>(),
    ];
    // Stamps anywhere in the i64 range, ends included.
    let stamp = prop_oneof![
        Just(0i64),
        Just(i64::MIN),
        Just(i64::MAX),
        -1000 * MS..1000 * MS,
        any::<i64>()
    ];
    prop_oneof![
        3 => (any::<Index>(), 0..8u8).prop_map(|(i, b)| Mutation::FlipBit(i, b)),
        2 => (any::<Index>(), bytes.clone()).prop_map(|(i, b)| Mutation::Overwrite(i, b)),
        2 => any::<Index>().prop_map(Mutation::Truncate),
        1 => (any::<Index>(), bytes).prop_map(|(i, b)| Mutation::Insert(i, b)),
        1 => (any::<Index>(), 1..64usize).prop_map(|(i, n)| Mutation::Remove(i, n)),
        1 => (any::<Index>(), 1..256usize, any::<Index>())
            .prop_map(|(from, len, to)| Mutation::Duplicate { from, len, to }),
        1 => (any::<Index>(), len).prop_map(|(i, n)| Mutation::FrameLen(i, n)),
        1 => (any::<Index>(), any::<u8>()).prop_map(|(i, t)| Mutation::FrameTag(i, t)),
        1 => (any::<Index>(), stamp).prop_map(|(i, s)| Mutation::FrameStamp(i, s)),
        1 => prop_oneof![any::<u64>(), u64::MAX - 64..=u64::MAX, 0..4096u64]
            .prop_map(Mutation::TrailerOffset),
    ]
}

/// Writes `field` at `at` where it fits.
fn put(bytes: &mut [u8], at: usize, field: &[u8]) {
    if let Some(dst) = bytes.get_mut(at..at + field.len()) {
        dst.copy_from_slice(field);
    }
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    let frames = &sample().frames;
    let frame = |i: &Index| frames[i.index(frames.len())] as usize;
    let n = bytes.len();
    match m {
        Mutation::FlipBit(i, bit) if n > 0 => bytes[i.index(n)] ^= 1 << bit,
        Mutation::Overwrite(i, b) if n > 0 => {
            let at = i.index(n);
            let end = (at + b.len()).min(n);
            bytes[at..end].copy_from_slice(&b[..end - at]);
        }
        Mutation::Truncate(i) => bytes.truncate(i.index(n + 1)),
        Mutation::Insert(i, b) => {
            let at = i.index(n + 1);
            bytes.splice(at..at, b.iter().copied());
        }
        Mutation::Remove(i, len) if n > 0 => {
            let at = i.index(n);
            bytes.drain(at..(at + len).min(n));
        }
        Mutation::Duplicate { from, len, to } if n > 0 => {
            let at = from.index(n);
            let chunk = bytes[at..(at + len).min(n)].to_vec();
            let to = to.index(n + 1);
            bytes.splice(to..to, chunk);
        }
        Mutation::FrameLen(i, len) => put(bytes, frame(i), &len.to_le_bytes()),
        Mutation::FrameTag(i, tag) => put(bytes, frame(i) + 8, &[*tag]),
        Mutation::FrameStamp(i, stamp) => put(bytes, frame(i) + 12, &stamp.to_le_bytes()),
        Mutation::TrailerOffset(offset) if n >= 16 => put(bytes, n - 16, &offset.to_le_bytes()),
        _ => {}
    }
}

/// `cases` per property from a fixed seed, so that the CI gate is deterministic.
/// For longer, exploring runs set `PROPTEST_CASES` and `PROPTEST_RNG_SEED`, e.g.
/// `PROPTEST_CASES=20000 PROPTEST_RNG_SEED=$RANDOM cargo test --test reader_props`.
fn config(cases: u32) -> ProptestConfig {
    fn env<T: std::str::FromStr>(name: &str) -> Option<T> {
        std::env::var(name).ok()?.parse().ok()
    }
    ProptestConfig {
        cases: env("PROPTEST_CASES").unwrap_or(cases),
        rng_seed: RngSeed::Fixed(env("PROPTEST_RNG_SEED").unwrap_or(0x5eed_2e1c)),
        // Shrinking a failure can take long; the first failure is reported either way.
        max_shrink_iters: 2048,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config(256))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..2048)) {
        let file = scratch(&bytes);
        let outcome = exercise(&file.path);
        if bytes.len() < 8 || bytes[..8] != *b"\x89RELUME\n" {
            prop_assert!(outcome.header.is_none());
        }
    }

    /// Past the magic: a valid preamble (and maybe the valid header) then garbage, so
    /// that frame parsing and the scan see arbitrary frames.
    #[test]
    fn garbage_after_a_valid_prefix_never_panics(
        keep in any::<Index>(),
        tail in prop::collection::vec(any::<u8>(), 0..1024),
    ) {
        let s = sample();
        // Anything from the preamble alone up to the whole recording.
        let kept = PREAMBLE_LEN as usize + keep.index(s.bytes.len() - PREAMBLE_LEN as usize + 1);
        let mut bytes = s.bytes[..kept].to_vec();
        bytes.extend_from_slice(&tail);
        let file = scratch(&bytes);
        let outcome = exercise(&file.path);
        // With the header intact, every record before the garbage reads back unchanged.
        if kept >= s.frames[1] as usize {
            prop_assert_eq!(outcome.header.as_ref(), Some(&s.header));
            let complete = s.frames.windows(2).skip(1).filter(|w| w[1] <= kept as u64);
            for (w, (offset, record)) in complete.zip(&s.records) {
                prop_assert_eq!(w[0], *offset);
                let got = outcome.records.iter().find(|(o, _)| o == offset);
                match got {
                    Some((_, Ok(got))) => prop_assert_eq!(got, record),
                    other => prop_assert!(false, "record at byte {}: {:?}", offset, other),
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(config(512))]

    #[test]
    fn mutated_recordings_never_panic(mutations in prop::collection::vec(mutation(), 1..6)) {
        let mut bytes = sample().bytes.clone();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        let file = scratch(&bytes);
        exercise(&file.path);
    }

    /// CRC32 detects every error of up to three bits in records this small: whatever
    /// still reads back after a few flips is exactly what was written.
    #[test]
    fn bit_flips_never_change_what_reads_back(
        flips in prop::collection::vec((any::<Index>(), 0..8u8), 1..=3),
    ) {
        let s = sample();
        let mut bytes = s.bytes.clone();
        let n = bytes.len();
        for (i, bit) in &flips {
            bytes[i.index(n)] ^= 1 << bit;
        }
        let file = scratch(&bytes);
        let outcome = exercise(&file.path);
        if let Some(header) = &outcome.header {
            prop_assert_eq!(header, &s.header);
        }
        for (offset, got) in &outcome.records {
            if let Ok(got) = got {
                let original = s.records.iter().find(|(o, _)| o == offset).map(|(_, r)| r);
                prop_assert_eq!(Some(got), original, "record at byte {}", offset);
            }
        }
    }
}
