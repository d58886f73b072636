//! A damaged `.relume` file: every cut point recovers exactly the complete records and
//! names the offset; flipped bits are checksum errors naming the record, never data
//! read back different from what was written.

mod common;

use common::sample::*;
use relume::recording::format::{FRAME_HEADER_LEN, IndexEntry, PREAMBLE_LEN, TRAILER_LEN};
use relume::recording::{Recording, RecordingError, Replay, ReplayOptions};
use std::io::Write;
use std::os::unix::fs::FileExt;

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
                    None => assert_eq!(
                        what,
                        "the index footer is missing (the file was cut short, or has bytes \
                         appended)",
                        "cut {cut}"
                    ),
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

/// A frame header whose stamp differs from the index's, with the checksum made to fit
/// (as a buggy writer could leave it), is a corrupt record, not a silent reorder.
#[test]
fn a_stamp_that_disagrees_with_the_index_is_a_corrupt_record() {
    let s = Sample::new();
    let e = s.index[0];
    let mut bytes = s.bytes.clone();
    let at = e.offset as usize;
    let stamp = e.stamp_ns + 5;
    bytes[at + 12..at + 20].copy_from_slice(&stamp.to_le_bytes());
    let end = at + FRAME_HEADER_LEN as usize + e.len as usize;
    let crc = crc32fast::hash(&bytes[at + 8..end]);
    bytes[at + 4..at + 8].copy_from_slice(&crc.to_le_bytes());
    let path = s.variant("restamped.relume", &bytes);
    let rec = Recording::open(&path).unwrap();
    match rec.read_record(0) {
        Err(RecordingError::Corrupt { offset, reason, .. }) => {
            assert_eq!(offset, e.offset);
            assert_eq!(
                reason,
                format!(
                    "record 0 is stamped {stamp} ns in its frame header but {} ns in the index",
                    e.stamp_ns
                )
            );
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(rec.read_record(1).unwrap(), s.records[1]);
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
