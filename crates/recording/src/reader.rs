//! Reads `.relume` files robustly: the index footer makes every record a seek; when the
//! footer is missing or damaged, a linear scan of the frame headers recovers every
//! complete record before the damage, and [`Recording::damage`] says what and where.

use super::error::RecordingError;
use super::format::{
    FORMAT_VERSION, FRAME_HEADER_LEN, FrameHeader, IndexEntry, MAGIC, MAX_PAYLOAD_LEN,
    PREAMBLE_LEN, TRAILER_LEN, TRAILER_MAGIC, Tag, Version, decode_versions,
};
use super::types::{ColorRecord, DepthRecord, Header, PoseRecord, Record, StreamKind, TruthRecord};
use serde::de::DeserializeOwned;
use std::fs::File;
use std::path::{Path, PathBuf};

/// An open recording: its header and the index of its records.
#[derive(Debug)]
pub struct Recording {
    path: PathBuf,
    file: File,
    file_len: u64,
    version: Version,
    header: Header,
    index: Vec<IndexEntry>,
    damage: Option<RecordingError>,
}

impl Recording {
    /// Opens `path`. Fails on a file that is not a recording, of a newer format, or whose
    /// header is unreadable; a damaged body opens with the complete records recovered and
    /// the damage reported by [`Recording::damage`].
    pub fn open(path: &Path) -> Result<Recording, RecordingError> {
        // A named pipe or device would block or read without end: refused first.
        let file =
            relume_base::files::open_regular(path).map_err(|e| RecordingError::io(path, e))?;
        let file_len = file
            .metadata()
            .map_err(|e| RecordingError::io(path, e))?
            .len();
        let mut rec = Recording {
            path: path.to_path_buf(),
            file,
            file_len,
            version: FORMAT_VERSION,
            header: placeholder_header(),
            index: Vec::new(),
            damage: None,
        };
        rec.read_preamble()?;
        let (header_frame, header_payload) = rec.read_frame_at(PREAMBLE_LEN, "the header")?;
        if Tag::from_byte(header_frame.tag_byte) != Some(Tag::Header) {
            return Err(rec.corrupt(PREAMBLE_LEN, "the first record is not a header".into()));
        }
        rec.check_crc(&header_frame, &header_payload, 0, "header", PREAMBLE_LEN)?;
        rec.header = rec.decode(&header_payload, 0, "header", PREAMBLE_LEN)?;
        // Values every stage trusts: refused here rather than met as a huge allocation
        // or a frame of NaN.
        rec.header
            .check()
            .map_err(|reason| RecordingError::Invalid {
                path: path.to_path_buf(),
                reason: format!("the header is invalid: {reason}"),
            })?;
        let body_start = PREAMBLE_LEN + FRAME_HEADER_LEN + header_payload.len() as u64;
        match rec.read_footer(body_start) {
            Ok(index) => rec.index = index,
            Err(footer_problem) => {
                let (index, scan_problem) = rec.scan(body_start);
                rec.index = index;
                rec.damage = Some(scan_problem.unwrap_or(footer_problem));
            }
        }
        Ok(rec)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The format version the file was written in.
    pub fn version(&self) -> Version {
        self.version
    }

    /// Size of the file in bytes.
    pub fn file_len(&self) -> u64 {
        self.file_len
    }

    /// Every stream record, in file order.
    pub fn index(&self) -> &[IndexEntry] {
        &self.index
    }

    /// Why the index had to be rebuilt by a scan, if it had to: a truncated file or a
    /// damaged footer. The records listed by [`Recording::index`] are all complete.
    pub fn damage(&self) -> Option<&RecordingError> {
        self.damage.as_ref()
    }

    /// Reads and checks record `i` of the index.
    pub fn read_record(&self, i: usize) -> Result<Record, RecordingError> {
        let entry = *self.index.get(i).ok_or_else(|| RecordingError::Invalid {
            path: self.path.clone(),
            reason: format!("record {i} does not exist ({} records)", self.index.len()),
        })?;
        let what = entry.kind.name();
        // A length field that disagrees with the index is damage in a complete file, not
        // the file ending early: say so before following it.
        if entry.offset + FRAME_HEADER_LEN <= self.file_len {
            let mut b = [0u8; FRAME_HEADER_LEN as usize];
            self.read_exact_at(&mut b, entry.offset)?;
            let declared = FrameHeader::parse(&b).len;
            if declared != entry.len {
                return Err(self.corrupt(
                    entry.offset,
                    format!(
                        "record {i} ({what}) has a damaged length field: its frame declares \
                         {declared} bytes, the index {}",
                        entry.len
                    ),
                ));
            }
        }
        let (frame, payload) = self.read_frame_at(entry.offset, what)?;
        if frame.len != entry.len || Tag::from_byte(frame.tag_byte) != Some(Tag::Stream(entry.kind))
        {
            return Err(self.corrupt(
                entry.offset,
                format!(
                    "record {i} does not match the index (expected a {what} record of {} bytes)",
                    entry.len
                ),
            ));
        }
        self.check_crc(&frame, &payload, i, what, entry.offset)?;
        // The checksum holds, so the stamps are as written; a writer wrote them equal.
        if frame.stamp_ns != entry.stamp_ns {
            return Err(self.corrupt(
                entry.offset,
                format!(
                    "record {i} is stamped {} ns in its frame header but {} ns in the index",
                    frame.stamp_ns, entry.stamp_ns
                ),
            ));
        }
        let at = entry.offset;
        let record = match entry.kind {
            StreamKind::Color => Record::Color(self.decode::<ColorRecord>(&payload, i, what, at)?),
            StreamKind::Depth => Record::Depth(self.decode::<DepthRecord>(&payload, i, what, at)?),
            StreamKind::Pose => {
                let record = self.decode::<PoseRecord>(&payload, i, what, at)?;
                // The CRC says the bytes are as written, not that a writer wrote a pose.
                record
                    .pose
                    .check()
                    .map_err(|reason| RecordingError::Decode {
                        path: self.path.clone(),
                        record: i,
                        kind: what,
                        offset: at,
                        reason,
                    })?;
                Record::Pose(record)
            }
            StreamKind::Truth => {
                Record::Truth(Box::new(self.decode::<TruthRecord>(&payload, i, what, at)?))
            }
        };
        // Replay orders frames by the index's stamps, and by the headers' without an
        // index: the record's own stamp must agree with both.
        if record.stamp_ns() != frame.stamp_ns {
            return Err(self.corrupt(
                at,
                format!(
                    "record {i} ({what}) is stamped {} ns, but its frame header says {} ns",
                    record.stamp_ns(),
                    frame.stamp_ns
                ),
            ));
        }
        Ok(record)
    }

    fn read_preamble(&mut self) -> Result<(), RecordingError> {
        let mut pre = [0u8; PREAMBLE_LEN as usize];
        let n = (self.file_len.min(PREAMBLE_LEN)) as usize;
        self.read_exact_at(&mut pre[..n], 0)?;
        if pre[..n.min(MAGIC.len())] != MAGIC[..n.min(MAGIC.len())] || n == 0 {
            return Err(RecordingError::BadMagic {
                path: self.path.clone(),
            });
        }
        if n < PREAMBLE_LEN as usize {
            return Err(self.truncated(self.file_len, "inside the preamble".into()));
        }
        let (version, min_reader) = decode_versions(&pre);
        if version.major > FORMAT_VERSION.major || min_reader > FORMAT_VERSION {
            return Err(RecordingError::UnsupportedVersion {
                path: self.path.clone(),
                found: version.to_string(),
                min_reader: min_reader.to_string(),
                supported: FORMAT_VERSION.to_string(),
            });
        }
        self.version = version;
        Ok(())
    }

    /// Reads the frame header at `offset` and its payload, checking sizes first.
    fn read_frame_at(
        &self,
        offset: u64,
        what: &str,
    ) -> Result<(FrameHeader, Vec<u8>), RecordingError> {
        let frame = self.frame_header_at(offset, what)?;
        let mut payload = vec![0u8; frame.len as usize];
        self.read_exact_at(&mut payload, offset + FRAME_HEADER_LEN)?;
        Ok((frame, payload))
    }

    /// Reads and validates a frame header: sane length, fits in the file.
    fn frame_header_at(&self, offset: u64, what: &str) -> Result<FrameHeader, RecordingError> {
        if offset + FRAME_HEADER_LEN > self.file_len {
            return Err(self.truncated(
                self.file_len,
                format!("the file ends inside the frame of {what} at byte {offset}"),
            ));
        }
        let mut b = [0u8; FRAME_HEADER_LEN as usize];
        self.read_exact_at(&mut b, offset)?;
        let frame = FrameHeader::parse(&b);
        if frame.reserved != [0; 3] || Tag::from_byte(frame.tag_byte).is_none() {
            return Err(self.corrupt(offset, format!("no valid record frame for {what}")));
        }
        if frame.len > MAX_PAYLOAD_LEN {
            return Err(self.corrupt(
                offset,
                format!(
                    "{what} declares {} bytes, over the limit of {MAX_PAYLOAD_LEN}",
                    frame.len
                ),
            ));
        }
        let end = offset + FRAME_HEADER_LEN + frame.len as u64;
        if end > self.file_len {
            return Err(self.truncated(
                self.file_len,
                format!(
                    "{what} at byte {offset} needs {} bytes up to byte {end}",
                    frame.len
                ),
            ));
        }
        Ok(frame)
    }

    /// Reads the index footer through the trailer; any problem is reported, not fatal.
    fn read_footer(&self, body_start: u64) -> Result<Vec<IndexEntry>, RecordingError> {
        let no_footer = || {
            self.truncated(
                self.file_len,
                "the index footer is missing (the file was cut short, or has bytes appended)"
                    .into(),
            )
        };
        if self.file_len < body_start + TRAILER_LEN {
            return Err(no_footer());
        }
        let trailer_at = self.file_len - TRAILER_LEN;
        let mut t = [0u8; TRAILER_LEN as usize];
        self.read_exact_at(&mut t, trailer_at)?;
        if t[8..] != TRAILER_MAGIC {
            return Err(no_footer());
        }
        let footer_at = u64::from_le_bytes(t[..8].try_into().expect("8 bytes"));
        if footer_at < body_start || footer_at > trailer_at.saturating_sub(FRAME_HEADER_LEN) {
            return Err(self.corrupt(
                trailer_at,
                format!(
                    "the trailer points to byte {footer_at}, outside the records (bytes {body_start} to {})",
                    trailer_at.saturating_sub(FRAME_HEADER_LEN)
                ),
            ));
        }
        let (frame, payload) = self.read_frame_at(footer_at, "the index footer")?;
        if Tag::from_byte(frame.tag_byte) != Some(Tag::Index)
            || footer_at + FRAME_HEADER_LEN + frame.len as u64 != trailer_at
        {
            return Err(self.corrupt(
                footer_at,
                "the index footer is not where the trailer says".into(),
            ));
        }
        let n = self.index.len();
        self.check_crc(&frame, &payload, n, "index", footer_at)?;
        let index: Vec<IndexEntry> = self.decode(&payload, n, "index", footer_at)?;
        for (i, e) in index.iter().enumerate() {
            let end = e.offset.checked_add(FRAME_HEADER_LEN + e.len as u64);
            if e.offset < body_start
                || e.len > MAX_PAYLOAD_LEN
                || end.is_none_or(|end| end > footer_at)
            {
                return Err(self.corrupt(
                    footer_at,
                    format!("index entry {i} points outside the records"),
                ));
            }
        }
        // The records lie back to back between the header and the footer, so a true
        // index tiles that span exactly, in order: an entry listed twice, one left out
        // or two swapped break the tiling (checked in one pass, no record read).
        let mut expected = body_start;
        for (i, e) in index.iter().enumerate() {
            if e.offset != expected {
                return Err(self.corrupt(
                    footer_at,
                    format!(
                        "index entry {i} says a record starts at byte {}, but the records \
                         before it end at byte {expected}: the footer does not list the \
                         records as they lie",
                        e.offset
                    ),
                ));
            }
            expected = e.offset + FRAME_HEADER_LEN + e.len as u64;
        }
        if expected != footer_at {
            return Err(self.corrupt(
                footer_at,
                format!(
                    "the index lists records up to byte {expected}, but they run on to the \
                     footer at byte {footer_at}: the footer leaves records out"
                ),
            ));
        }
        Ok(index)
    }

    /// Rebuilds the index by walking frame headers from `start`. Returns the complete
    /// records and, if the walk stopped before a clean end, why.
    fn scan(&self, start: u64) -> (Vec<IndexEntry>, Option<RecordingError>) {
        let mut index: Vec<IndexEntry> = Vec::new();
        let mut offset = start;
        let mut damage = None;
        while offset < self.file_len {
            let frame = match self.frame_header_at(offset, &format!("record {}", index.len())) {
                Ok(f) => f,
                Err(e) => {
                    // A damaged length field sends the scan into the middle of a record
                    // (or past the end). Where the last record's checksum fails, its
                    // length was the damage: drop it and look for the next record whose
                    // checksum holds from just after its frame header.
                    let last_is_damaged = index
                        .last()
                        .is_some_and(|last| !self.payload_checks(last.offset, last.len));
                    let (from, dropped) = match index.last() {
                        Some(last) if last_is_damaged => (last.offset + FRAME_HEADER_LEN, true),
                        _ => (offset + 1, false),
                    };
                    let lost_at = if dropped {
                        index.last().map_or(offset, |l| l.offset)
                    } else {
                        offset
                    };
                    let Some(next) = self.next_valid_frame(from) else {
                        return (index, damage.or(Some(e)));
                    };
                    if dropped {
                        index.pop();
                    }
                    damage.get_or_insert_with(|| {
                        self.corrupt(
                            lost_at,
                            format!(
                                "the record at byte {lost_at} is damaged (a bad length field or \
                                 frame header: {}); the scan resumed at byte {next}, the next \
                                 record whose checksum holds, losing {} bytes",
                                e.reason(),
                                next - lost_at
                            ),
                        )
                    });
                    offset = next;
                    continue;
                }
            };
            match Tag::from_byte(frame.tag_byte) {
                Some(Tag::Stream(kind)) => index.push(IndexEntry {
                    kind,
                    stamp_ns: frame.stamp_ns,
                    offset,
                    len: frame.len,
                }),
                // A footer that failed to read: everything before it is recovered.
                Some(Tag::Index) => return (index, damage),
                Some(Tag::Header) => {
                    return (
                        index,
                        damage.or_else(|| {
                            Some(self.corrupt(offset, "a second header inside the records".into()))
                        }),
                    );
                }
                None => unreachable!("frame_header_at checks the tag"),
            }
            offset += FRAME_HEADER_LEN + frame.len as u64;
        }
        (index, damage)
    }

    /// Whether the stream record framed at `offset` with `len` payload bytes has a
    /// checksum that holds.
    fn payload_checks(&self, offset: u64, len: u32) -> bool {
        let Ok((frame, payload)) = self.read_frame_at(offset, "a record") else {
            return false;
        };
        frame.len == len
            && FrameHeader::checksum(frame.tag_byte, frame.stamp_ns, &payload) == frame.crc
    }

    /// Whether `offset` is the end of the file or holds what looks like a frame header
    /// (a cheap test before a candidate's checksum is computed).
    fn frame_starts_or_file_ends(&self, offset: u64) -> bool {
        if offset == self.file_len {
            return true;
        }
        if offset + FRAME_HEADER_LEN > self.file_len {
            return false;
        }
        let mut b = [0u8; FRAME_HEADER_LEN as usize];
        if self.read_exact_at(&mut b, offset).is_err() {
            return false;
        }
        let frame = FrameHeader::parse(&b);
        frame.reserved == [0; 3] && Tag::from_byte(frame.tag_byte).is_some()
    }

    /// The first offset at or after `from` where a stream record (or the footer) starts
    /// whose frame fits in the file and whose checksum holds.
    fn next_valid_frame(&self, from: u64) -> Option<u64> {
        const WINDOW: u64 = 1 << 20;
        // Payload bytes checksummed in the search at most: a crafted file full of
        // plausible headers ends the search instead of reading for hours.
        let mut budget: u64 = 1 << 30;
        let mut at = from;
        while at + FRAME_HEADER_LEN <= self.file_len {
            let n = WINDOW.min(self.file_len - at) as usize;
            let mut buf = vec![0u8; n];
            self.read_exact_at(&mut buf, at).ok()?;
            for i in 0..n.saturating_sub(FRAME_HEADER_LEN as usize - 1) {
                let b: &[u8; FRAME_HEADER_LEN as usize] = buf[i..i + FRAME_HEADER_LEN as usize]
                    .try_into()
                    .expect("a header's length");
                let frame = FrameHeader::parse(b);
                let tag = Tag::from_byte(frame.tag_byte);
                let offset = at + i as u64;
                let end = offset + FRAME_HEADER_LEN + frame.len as u64;
                let plausible = frame.reserved == [0; 3]
                    && matches!(tag, Some(Tag::Stream(_)) | Some(Tag::Index))
                    && frame.len <= MAX_PAYLOAD_LEN
                    && end <= self.file_len
                    && self.frame_starts_or_file_ends(end);
                if plausible {
                    if budget < frame.len as u64 {
                        return None;
                    }
                    budget -= frame.len as u64;
                    if self.payload_checks(offset, frame.len) {
                        return Some(offset);
                    }
                }
            }
            at += (n as u64).saturating_sub(FRAME_HEADER_LEN - 1).max(1);
        }
        None
    }

    fn check_crc(
        &self,
        frame: &FrameHeader,
        payload: &[u8],
        record: usize,
        kind: &'static str,
        offset: u64,
    ) -> Result<(), RecordingError> {
        let computed = FrameHeader::checksum(frame.tag_byte, frame.stamp_ns, payload);
        if computed != frame.crc {
            return Err(RecordingError::Checksum {
                path: self.path.clone(),
                record,
                kind,
                offset,
                stored: frame.crc,
                computed,
            });
        }
        Ok(())
    }

    fn decode<T: DeserializeOwned>(
        &self,
        payload: &[u8],
        record: usize,
        kind: &'static str,
        offset: u64,
    ) -> Result<T, RecordingError> {
        rmp_serde::from_slice(payload).map_err(|e| RecordingError::Decode {
            path: self.path.clone(),
            record,
            kind,
            offset,
            reason: e.to_string(),
        })
    }

    fn read_exact_at(&self, buf: &mut [u8], offset: u64) -> Result<(), RecordingError> {
        use std::os::unix::fs::FileExt;
        self.file
            .read_exact_at(buf, offset)
            .map_err(|e| RecordingError::io(&self.path, e))
    }

    fn truncated(&self, offset: u64, what: String) -> RecordingError {
        RecordingError::Truncated {
            path: self.path.clone(),
            offset,
            what,
        }
    }

    fn corrupt(&self, offset: u64, reason: String) -> RecordingError {
        RecordingError::Corrupt {
            path: self.path.clone(),
            offset,
            reason,
        }
    }
}

fn placeholder_header() -> Header {
    Header::new("", super::types::Intrinsics::PRIMESENSE, 0.001)
}
