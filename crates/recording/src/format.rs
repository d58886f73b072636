//! The byte layout of a `.relume` file.
//!
//! ```text
//! preamble   magic "\x89RELUME\n" (8) | version major u16 | minor u16 | min reader major u16 | minor u16
//! record*    payload length u32 | CRC32 u32 | tag u8 | 3 zero bytes | stamp i64 | MessagePack payload
//! trailer    index offset u64 | "RLMINDEX"
//! ```
//! All integers are little-endian. The CRC32 covers the tag, the zero bytes, the stamp
//! and the payload. The first record is the header (tag 0), the last the index footer
//! (tag 255): a MessagePack list of [`IndexEntry`], so that a frame is a seek, not a scan.
//! Tag and stamp sit outside the payload so a reader can rebuild the index of a file
//! whose footer is missing without decoding any payload.

use super::types::StreamKind;
use serde::{Deserialize, Serialize};

/// The first eight bytes of every recording.
pub const MAGIC: [u8; 8] = *b"\x89RELUME\n";
/// The last eight bytes of a complete recording.
pub const TRAILER_MAGIC: [u8; 8] = *b"RLMINDEX";
/// Bytes before the first record.
pub const PREAMBLE_LEN: u64 = 16;
/// Bytes of a record's frame before its payload.
pub const FRAME_HEADER_LEN: u64 = 20;
/// Bytes of the trailer.
pub const TRAILER_LEN: u64 = 16;
/// The largest payload a reader accepts (sanity limit checked before any allocation).
pub const MAX_PAYLOAD_LEN: u32 = 256 << 20;

/// A format version: readers accept any file whose minimum reader version they meet.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Version {
    pub major: u16,
    pub minor: u16,
}

impl std::fmt::Display for Version {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}", self.major, self.minor)
    }
}

/// The version this crate writes and reads.
pub const FORMAT_VERSION: Version = Version { major: 1, minor: 0 };
/// The oldest reader that can read what this crate writes.
pub const MIN_READER_VERSION: Version = Version { major: 1, minor: 0 };

/// The tag byte of a record frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tag {
    Header,
    Stream(StreamKind),
    Index,
}

impl Tag {
    pub fn to_byte(self) -> u8 {
        match self {
            Tag::Header => 0,
            Tag::Stream(StreamKind::Color) => 1,
            Tag::Stream(StreamKind::Depth) => 2,
            Tag::Stream(StreamKind::Pose) => 3,
            Tag::Stream(StreamKind::Truth) => 4,
            Tag::Index => 255,
        }
    }

    pub fn from_byte(b: u8) -> Option<Tag> {
        Some(match b {
            0 => Tag::Header,
            1 => Tag::Stream(StreamKind::Color),
            2 => Tag::Stream(StreamKind::Depth),
            3 => Tag::Stream(StreamKind::Pose),
            4 => Tag::Stream(StreamKind::Truth),
            255 => Tag::Index,
            _ => return None,
        })
    }
}

/// Where one stream record lives in the file.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
pub struct IndexEntry {
    pub kind: StreamKind,
    pub stamp_ns: i64,
    /// Offset of the record's frame header.
    pub offset: u64,
    /// Payload length in bytes.
    pub len: u32,
}

/// The fixed part of a record frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameHeader {
    pub len: u32,
    pub crc: u32,
    pub tag_byte: u8,
    pub reserved: [u8; 3],
    pub stamp_ns: i64,
}

impl FrameHeader {
    pub fn parse(b: &[u8; FRAME_HEADER_LEN as usize]) -> FrameHeader {
        FrameHeader {
            len: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            crc: u32::from_le_bytes([b[4], b[5], b[6], b[7]]),
            tag_byte: b[8],
            reserved: [b[9], b[10], b[11]],
            stamp_ns: i64::from_le_bytes(b[12..20].try_into().expect("8 bytes")),
        }
    }

    /// The CRC32 of a frame with this tag and stamp over `payload`.
    pub fn checksum(tag_byte: u8, stamp_ns: i64, payload: &[u8]) -> u32 {
        let mut h = crc32fast::Hasher::new();
        h.update(&[tag_byte, 0, 0, 0]);
        h.update(&stamp_ns.to_le_bytes());
        h.update(payload);
        h.finalize()
    }

    /// Encodes a frame header for `payload`.
    pub fn encode(tag: Tag, stamp_ns: i64, payload: &[u8]) -> [u8; FRAME_HEADER_LEN as usize] {
        let tag_byte = tag.to_byte();
        let mut out = [0u8; FRAME_HEADER_LEN as usize];
        out[0..4].copy_from_slice(&(payload.len() as u32).to_le_bytes());
        out[4..8].copy_from_slice(&Self::checksum(tag_byte, stamp_ns, payload).to_le_bytes());
        out[8] = tag_byte;
        out[12..20].copy_from_slice(&stamp_ns.to_le_bytes());
        out
    }
}

/// Encodes the preamble.
pub fn encode_preamble() -> [u8; PREAMBLE_LEN as usize] {
    let mut out = [0u8; PREAMBLE_LEN as usize];
    out[0..8].copy_from_slice(&MAGIC);
    out[8..10].copy_from_slice(&FORMAT_VERSION.major.to_le_bytes());
    out[10..12].copy_from_slice(&FORMAT_VERSION.minor.to_le_bytes());
    out[12..14].copy_from_slice(&MIN_READER_VERSION.major.to_le_bytes());
    out[14..16].copy_from_slice(&MIN_READER_VERSION.minor.to_le_bytes());
    out
}

/// Decodes the two versions of a preamble whose magic has been checked.
pub fn decode_versions(b: &[u8; PREAMBLE_LEN as usize]) -> (Version, Version) {
    let u = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
    (
        Version {
            major: u(8),
            minor: u(10),
        },
        Version {
            major: u(12),
            minor: u(14),
        },
    )
}
