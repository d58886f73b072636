//! A Matroska (`.mkv`) reader for what RGB-D recorders write: the Azure Kinect's
//! `k4arecorder` (and Orbbec's Kinect-compatible one), ffmpeg and mkvmerge. It reads the
//! segment's info, tracks, attachments and tags whole and indexes every block of every
//! cluster (where it lies, its track and time) without reading frames; [`Matroska::frames`]
//! reads one block's frames when asked.
//!
//! Hand-written (a few hundred lines over [`ebml`]) rather than `matroska-demuxer`, which
//! does not read attachments (where a Kinect recording keeps its calibration) or a track's
//! ColourSpace, and allocates element sizes read from the file unbounded. Here every size
//! is bounded before allocation; an element running past the end of the file is a cut (a
//! recorder stopped before closing it: the blocks before the cut are kept and the cut is
//! reported), one running past its parent inside the file is damage (an error naming its
//! byte). Compressed tracks (ContentEncoding) are named and not read.

pub mod ebml;
pub mod lacing;

use crate::error::ImportError;
use ebml::{EbmlError, EbmlReader, Element};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// Element IDs (RFC 9559, Matroska).
mod id {
    pub const EBML: u32 = 0x1A45DFA3;
    pub const DOC_TYPE: u32 = 0x4282;
    pub const SEGMENT: u32 = 0x18538067;
    pub const INFO: u32 = 0x1549A966;
    pub const TIMESTAMP_SCALE: u32 = 0x2AD7B1;
    pub const TRACKS: u32 = 0x1654AE6B;
    pub const TRACK_ENTRY: u32 = 0xAE;
    pub const TRACK_NUMBER: u32 = 0xD7;
    pub const TRACK_UID: u32 = 0x73C5;
    pub const TRACK_TYPE: u32 = 0x83;
    pub const NAME: u32 = 0x536E;
    pub const CODEC_ID: u32 = 0x86;
    pub const CODEC_PRIVATE: u32 = 0x63A2;
    pub const DEFAULT_DURATION: u32 = 0x23E383;
    pub const VIDEO: u32 = 0xE0;
    pub const PIXEL_WIDTH: u32 = 0xB0;
    pub const PIXEL_HEIGHT: u32 = 0xBA;
    pub const COLOUR_SPACE: u32 = 0x2EB524;
    pub const CONTENT_ENCODINGS: u32 = 0x6D80;
    pub const ATTACHMENTS: u32 = 0x1941A469;
    pub const ATTACHED_FILE: u32 = 0x61A7;
    pub const FILE_NAME: u32 = 0x466E;
    pub const FILE_MIME_TYPE: u32 = 0x4660;
    pub const FILE_DATA: u32 = 0x465C;
    pub const FILE_UID: u32 = 0x46AE;
    pub const TAGS: u32 = 0x1254C367;
    pub const TAG: u32 = 0x7373;
    pub const TARGETS: u32 = 0x63C0;
    pub const TAG_TRACK_UID: u32 = 0x63C5;
    pub const TAG_ATTACHMENT_UID: u32 = 0x63C6;
    pub const SIMPLE_TAG: u32 = 0x67C8;
    pub const TAG_NAME: u32 = 0x45A3;
    pub const TAG_STRING: u32 = 0x4487;
    pub const CLUSTER: u32 = 0x1F43B675;
    pub const TIMESTAMP: u32 = 0xE7;
    pub const SIMPLE_BLOCK: u32 = 0xA3;
    pub const BLOCK_GROUP: u32 = 0xA0;
    pub const BLOCK: u32 = 0xA1;
    /// Children a Cluster may hold; any other ID ends a Cluster of unknown size.
    pub const CLUSTER_CHILDREN: [u32; 9] = [
        TIMESTAMP,
        0x5854,
        0xA7,
        0xAB,
        SIMPLE_BLOCK,
        BLOCK_GROUP,
        0xAF,
        0xEC,
        0xBF,
    ];
}

/// The largest header element read whole (Tracks, Tags, a TrackEntry's CodecPrivate).
const MAX_HEADER_BYTES: u64 = 1 << 20;
/// The largest attachment read (a Kinect's calibration is about 10 kB).
const MAX_ATTACHMENT_BYTES: u64 = 16 << 20;
/// The largest block: a 4096x3072 BGRA frame is 50 MB.
pub const MAX_BLOCK_BYTES: u64 = 64 << 20;
/// The most blocks indexed: about four days of two 30 Hz tracks.
const MAX_BLOCKS: usize = 20_000_000;
/// Nesting of SimpleTags within SimpleTags.
const MAX_TAG_DEPTH: usize = 8;

/// One track's entry.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Track {
    pub number: u64,
    pub uid: u64,
    /// 1 video, 2 audio, 17 subtitle, 18 buttons, 32 complex, 33 logo, 0x12 etc.
    pub kind: u64,
    pub name: String,
    pub codec_id: String,
    pub codec_private: Vec<u8>,
    pub width: u32,
    pub height: u32,
    /// The Video element's ColourSpace (a FourCC for V_UNCOMPRESSED).
    pub colour_space: Vec<u8>,
    pub default_duration_ns: Option<u64>,
    /// Its blocks are compressed or encrypted (ContentEncodings): not read.
    pub encoded: bool,
}

/// One attached file.
#[derive(Clone, Debug, PartialEq)]
pub struct Attachment {
    pub name: String,
    pub mime: String,
    pub uid: u64,
    pub data: Vec<u8>,
}

/// One SimpleTag, with the targets of its Tag.
#[derive(Clone, Debug, PartialEq)]
pub struct SimpleTag {
    pub track_uids: Vec<u64>,
    pub attachment_uids: Vec<u64>,
    pub name: String,
    pub value: String,
}

/// One block: its track, time and where its payload (after its header) lies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Block {
    pub track: u64,
    /// The cluster's timestamp plus the block's, scaled to nanoseconds.
    pub time_ns: i64,
    /// The block element's first byte (for errors).
    pub at: u64,
    pub payload: u64,
    pub payload_len: u64,
    pub lacing: lacing::Lacing,
}

/// A Matroska file's header and block index.
pub struct Matroska {
    path: PathBuf,
    reader: EbmlReader<BufReader<File>>,
    pub doc_type: String,
    pub timestamp_scale_ns: u64,
    pub tracks: Vec<Track>,
    pub attachments: Vec<Attachment>,
    pub tags: Vec<SimpleTag>,
    pub blocks: Vec<Block>,
    /// Where the file ends early, if it does: a recorder stopped before closing it.
    pub cut: Option<String>,
}

impl Matroska {
    /// Reads the header elements of `path` and indexes its blocks.
    pub fn open(path: &Path) -> Result<Matroska, ImportError> {
        let file = relume_base::files::open_regular(path).map_err(|source| ImportError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let len = file
            .metadata()
            .map_err(|source| ImportError::Io {
                path: path.to_path_buf(),
                source,
            })?
            .len();
        let reader = EbmlReader::new(BufReader::with_capacity(1 << 16, file), len);
        let mut mkv = Matroska {
            path: path.to_path_buf(),
            reader,
            doc_type: String::new(),
            timestamp_scale_ns: 1_000_000,
            tracks: Vec::new(),
            attachments: Vec::new(),
            tags: Vec::new(),
            blocks: Vec::new(),
            cut: None,
        };
        match mkv.read_all() {
            Ok(()) => Ok(mkv),
            Err(e) => Err(mkv.error(e)),
        }
    }

    /// The error of `e` naming the file and the byte.
    pub fn error(&self, e: EbmlError) -> ImportError {
        match e {
            EbmlError::Io(source) => ImportError::Io {
                path: self.path.clone(),
                source,
            },
            EbmlError::Cut { at, what } => self.bad(format!(
                "the file ends inside {what} (the element at byte {at}) before any frame"
            )),
            EbmlError::Damaged { at, reason } => {
                self.bad(format!("damaged at byte {at}: {reason}"))
            }
        }
    }

    fn bad(&self, reason: String) -> ImportError {
        ImportError::File {
            path: self.path.clone(),
            reason,
        }
    }

    fn read_all(&mut self) -> Result<(), EbmlError> {
        let len = self.reader.file_len();
        let header = self.reader.next(len)?.ok_or(EbmlError::Damaged {
            at: 0,
            reason: "an empty file".into(),
        })?;
        if header.id != id::EBML {
            return Err(EbmlError::Damaged {
                at: 0,
                reason: "not a Matroska file (no EBML header)".into(),
            });
        }
        let end = self.known_end(&header, len, "the EBML header")?;
        while let Some(e) = self.reader.next(end)? {
            if e.id == id::DOC_TYPE {
                self.doc_type = self.reader.string(&e, "the DocType")?;
            }
            self.reader
                .seek_to(self.known_end(&e, end, "an EBML header field")?)?;
        }
        if !matches!(self.doc_type.as_str(), "matroska" | "webm") {
            return Err(EbmlError::Damaged {
                at: 0,
                reason: format!("an EBML file of type {:?}, not Matroska", self.doc_type),
            });
        }
        let segment = loop {
            let e = self.reader.next(len)?.ok_or(EbmlError::Damaged {
                at: self.reader.position(),
                reason: "no Segment".into(),
            })?;
            if e.id == id::SEGMENT {
                break e;
            }
            self.reader
                .seek_to(self.known_end(&e, len, "a top-level element")?)?;
        };
        // A segment claiming more than the file holds: a recorder stopped early.
        let end = segment.end(len).min(len);
        while let Some(e) = self.reader.next(end).or_else(|err| self.cut_or(err))? {
            let result = match e.id {
                id::INFO => self.read_info(&e, end),
                id::TRACKS => self.read_tracks(&e, end),
                id::ATTACHMENTS => self.read_attachments(&e, end),
                id::TAGS => self.read_tags(&e, end),
                id::CLUSTER => self.read_cluster(&e, end),
                _ => self
                    .known_end(&e, end, "a segment element")
                    .and_then(|to| self.reader.seek_to(to)),
            };
            match result {
                Ok(()) => {}
                Err(err) => {
                    self.cut_or(err)?;
                    break;
                }
            }
            if self.cut.is_some() {
                break;
            }
        }
        if self.cut.is_none()
            && let Some(size) = segment.size
            && segment.data + size > len
        {
            self.cut = Some(format!(
                "the Segment claims {size} bytes from byte {}, the file ends at byte {len}: \
                 a recorder stopped before closing it? What precedes was read",
                segment.data
            ));
        }
        Ok(())
    }

    /// A cut after some blocks ends the reading there (kept as [`Matroska::cut`]); before
    /// any, or any other error, is returned.
    fn cut_or(&mut self, err: EbmlError) -> Result<Option<Element>, EbmlError> {
        match err {
            EbmlError::Cut { at, what } if !self.blocks.is_empty() => {
                self.cut = Some(format!(
                    "the file ends inside {what} at byte {at} after {} blocks: a recorder \
                     stopped before closing it? What precedes was read",
                    self.blocks.len()
                ));
                Ok(None)
            }
            err => Err(err),
        }
    }

    /// Where `e` ends: its size must be known and inside `parent_end` (past the end of the
    /// file is a cut, inside it damage).
    fn known_end(&self, e: &Element, parent_end: u64, what: &str) -> Result<u64, EbmlError> {
        let size = e.size.ok_or_else(|| EbmlError::Damaged {
            at: e.start,
            reason: format!("{what} ({:#x}) has an unknown size", e.id),
        })?;
        let end = e.data + size;
        // Past a parent that the file holds whole: damage. Past the end of the file
        // inside a parent that runs past it too: a cut.
        if end > parent_end && parent_end >= self.reader.file_len() {
            return Err(EbmlError::Cut {
                at: e.start,
                what: format!("{what} ({:#x}, {size} bytes)", e.id),
            });
        }
        if end > parent_end {
            return Err(EbmlError::Damaged {
                at: e.start,
                reason: format!(
                    "{what} ({:#x}) claims {size} bytes, past its parent's end at byte {parent_end}",
                    e.id
                ),
            });
        }
        Ok(end)
    }

    fn read_info(&mut self, info: &Element, parent: u64) -> Result<(), EbmlError> {
        let end = self.known_end(info, parent, "the segment Info")?;
        while let Some(e) = self.reader.next(end)? {
            let to = self.known_end(&e, end, "an Info field")?;
            if e.id == id::TIMESTAMP_SCALE {
                let scale = self.reader.uint(&e, "the TimestampScale")?;
                if !(1..=1_000_000_000).contains(&scale) {
                    return Err(EbmlError::Damaged {
                        at: e.start,
                        reason: format!("a TimestampScale of {scale} ns"),
                    });
                }
                self.timestamp_scale_ns = scale;
            }
            self.reader.seek_to(to)?;
        }
        Ok(())
    }

    fn read_tracks(&mut self, tracks: &Element, parent: u64) -> Result<(), EbmlError> {
        let end = self.known_end(tracks, parent, "the Tracks")?;
        while let Some(entry) = self.reader.next(end)? {
            let entry_end = self.known_end(&entry, end, "a TrackEntry")?;
            if entry.id != id::TRACK_ENTRY {
                self.reader.seek_to(entry_end)?;
                continue;
            }
            let mut track = Track::default();
            while let Some(e) = self.reader.next(entry_end)? {
                let to = self.known_end(&e, entry_end, "a TrackEntry field")?;
                match e.id {
                    id::TRACK_NUMBER => track.number = self.reader.uint(&e, "a TrackNumber")?,
                    id::TRACK_UID => track.uid = self.reader.uint(&e, "a TrackUID")?,
                    id::TRACK_TYPE => track.kind = self.reader.uint(&e, "a TrackType")?,
                    id::NAME => track.name = self.reader.string(&e, "a track Name")?,
                    id::CODEC_ID => track.codec_id = self.reader.string(&e, "a CodecID")?,
                    id::CODEC_PRIVATE => {
                        track.codec_private =
                            self.reader.bytes(&e, MAX_HEADER_BYTES, "a CodecPrivate")?
                    }
                    id::DEFAULT_DURATION => {
                        track.default_duration_ns = Some(self.reader.uint(&e, "a DefaultDuration")?)
                    }
                    id::CONTENT_ENCODINGS => track.encoded = true,
                    id::VIDEO => {
                        while let Some(v) = self.reader.next(to)? {
                            let v_to = self.known_end(&v, to, "a Video field")?;
                            let dimension = |v: u64| u32::try_from(v).unwrap_or(u32::MAX);
                            match v.id {
                                id::PIXEL_WIDTH => {
                                    track.width = dimension(self.reader.uint(&v, "a PixelWidth")?)
                                }
                                id::PIXEL_HEIGHT => {
                                    track.height = dimension(self.reader.uint(&v, "a PixelHeight")?)
                                }
                                id::COLOUR_SPACE => {
                                    track.colour_space =
                                        self.reader.bytes(&v, 64, "a ColourSpace")?
                                }
                                _ => {}
                            }
                            self.reader.seek_to(v_to)?;
                        }
                    }
                    _ => {}
                }
                self.reader.seek_to(to)?;
            }
            if track.number == 0 {
                return Err(EbmlError::Damaged {
                    at: entry.start,
                    reason: "a TrackEntry without a TrackNumber".into(),
                });
            }
            if self.tracks.iter().any(|t| t.number == track.number) {
                return Err(EbmlError::Damaged {
                    at: entry.start,
                    reason: format!("track number {} is given twice", track.number),
                });
            }
            self.tracks.push(track);
        }
        Ok(())
    }

    fn read_attachments(&mut self, attachments: &Element, parent: u64) -> Result<(), EbmlError> {
        let end = self.known_end(attachments, parent, "the Attachments")?;
        while let Some(file) = self.reader.next(end)? {
            let file_end = self.known_end(&file, end, "an AttachedFile")?;
            if file.id == id::ATTACHED_FILE {
                let mut attachment = Attachment {
                    name: String::new(),
                    mime: String::new(),
                    uid: 0,
                    data: Vec::new(),
                };
                while let Some(e) = self.reader.next(file_end)? {
                    let to = self.known_end(&e, file_end, "an AttachedFile field")?;
                    match e.id {
                        id::FILE_NAME => attachment.name = self.reader.string(&e, "a FileName")?,
                        id::FILE_MIME_TYPE => {
                            attachment.mime = self.reader.string(&e, "a FileMimeType")?
                        }
                        id::FILE_UID => attachment.uid = self.reader.uint(&e, "a FileUID")?,
                        id::FILE_DATA => {
                            attachment.data =
                                self.reader
                                    .bytes(&e, MAX_ATTACHMENT_BYTES, "an attachment")?
                        }
                        _ => {}
                    }
                    self.reader.seek_to(to)?;
                }
                self.attachments.push(attachment);
            }
            self.reader.seek_to(file_end)?;
        }
        Ok(())
    }

    fn read_tags(&mut self, tags: &Element, parent: u64) -> Result<(), EbmlError> {
        let end = self.known_end(tags, parent, "the Tags")?;
        while let Some(tag) = self.reader.next(end)? {
            let tag_end = self.known_end(&tag, end, "a Tag")?;
            if tag.id == id::TAG {
                let (mut tracks, mut attachments, mut simple) =
                    (Vec::new(), Vec::new(), Vec::new());
                while let Some(e) = self.reader.next(tag_end)? {
                    let to = self.known_end(&e, tag_end, "a Tag field")?;
                    match e.id {
                        id::TARGETS => {
                            while let Some(t) = self.reader.next(to)? {
                                let t_to = self.known_end(&t, to, "a Targets field")?;
                                match t.id {
                                    id::TAG_TRACK_UID => {
                                        tracks.push(self.reader.uint(&t, "a TagTrackUID")?)
                                    }
                                    id::TAG_ATTACHMENT_UID => attachments
                                        .push(self.reader.uint(&t, "a TagAttachmentUID")?),
                                    _ => {}
                                }
                                self.reader.seek_to(t_to)?;
                            }
                        }
                        id::SIMPLE_TAG => self.read_simple_tag(&e, to, 0, &mut simple)?,
                        _ => {}
                    }
                    self.reader.seek_to(to)?;
                }
                for (name, value) in simple {
                    self.tags.push(SimpleTag {
                        track_uids: tracks.clone(),
                        attachment_uids: attachments.clone(),
                        name,
                        value,
                    });
                }
            }
            self.reader.seek_to(tag_end)?;
        }
        Ok(())
    }

    fn read_simple_tag(
        &mut self,
        tag: &Element,
        end: u64,
        depth: usize,
        out: &mut Vec<(String, String)>,
    ) -> Result<(), EbmlError> {
        if depth > MAX_TAG_DEPTH {
            return Err(EbmlError::Damaged {
                at: tag.start,
                reason: format!("SimpleTags nested deeper than {MAX_TAG_DEPTH}"),
            });
        }
        let (mut name, mut value) = (String::new(), String::new());
        while let Some(e) = self.reader.next(end)? {
            let to = self.known_end(&e, end, "a SimpleTag field")?;
            match e.id {
                id::TAG_NAME => name = self.reader.string(&e, "a TagName")?,
                id::TAG_STRING => value = self.reader.string(&e, "a TagString")?,
                id::SIMPLE_TAG => self.read_simple_tag(&e, to, depth + 1, out)?,
                _ => {}
            }
            self.reader.seek_to(to)?;
        }
        out.push((name, value));
        Ok(())
    }

    fn read_cluster(&mut self, cluster: &Element, parent: u64) -> Result<(), EbmlError> {
        let len = self.reader.file_len();
        // Unknown size: up to the first element a cluster cannot hold.
        let end = match cluster.size {
            Some(_) => self
                .known_end(cluster, parent, "a Cluster")
                .or_else(|e| match e {
                    // A cluster cut short: its blocks up to the cut are read.
                    EbmlError::Cut { .. } => Ok(len),
                    e => Err(e),
                })?,
            None => parent,
        };
        let mut timestamp: Option<u64> = None;
        while let Some(e) = self.reader.next(end)? {
            if cluster.size.is_none() && !id::CLUSTER_CHILDREN.contains(&e.id) {
                self.reader.seek_to(e.start)?;
                return Ok(());
            }
            let to = self.known_end(&e, end, "a Cluster element")?;
            match e.id {
                id::TIMESTAMP => timestamp = Some(self.reader.uint(&e, "a cluster Timestamp")?),
                id::SIMPLE_BLOCK => self.index_block(&e, timestamp)?,
                id::BLOCK_GROUP => {
                    while let Some(b) = self.reader.next(to)? {
                        let b_to = self.known_end(&b, to, "a BlockGroup element")?;
                        if b.id == id::BLOCK {
                            self.index_block(&b, timestamp)?;
                        }
                        self.reader.seek_to(b_to)?;
                    }
                }
                _ => {}
            }
            self.reader.seek_to(to)?;
        }
        if end == len && cluster.size.is_some_and(|s| cluster.data + s > len) {
            return Err(EbmlError::Cut {
                at: cluster.start,
                what: "a Cluster".into(),
            });
        }
        Ok(())
    }

    fn index_block(&mut self, e: &Element, cluster_time: Option<u64>) -> Result<(), EbmlError> {
        let size = e.size.expect("known_end checked it");
        if size > MAX_BLOCK_BYTES {
            return Err(EbmlError::Damaged {
                at: e.start,
                reason: format!("a block of {size} bytes, more than {MAX_BLOCK_BYTES}"),
            });
        }
        let cluster_time = cluster_time.ok_or_else(|| EbmlError::Damaged {
            at: e.start,
            reason: "a block before its cluster's Timestamp".into(),
        })?;
        let head = self
            .reader
            .read_at(e.data, size.min(11), e.start, "a block header")?;
        let (track, n) = ebml::vint(&head).ok_or_else(|| EbmlError::Damaged {
            at: e.start,
            reason: "a block without a track number".into(),
        })?;
        if head.len() < n + 3 {
            return Err(EbmlError::Damaged {
                at: e.start,
                reason: "a block shorter than its header".into(),
            });
        }
        let relative = i16::from_be_bytes([head[n], head[n + 1]]) as i64;
        let flags = head[n + 2];
        let ticks = cluster_time as i128 + relative as i128;
        let time_ns = i64::try_from(ticks * self.timestamp_scale_ns as i128).map_err(|_| {
            EbmlError::Damaged {
                at: e.start,
                reason: format!("a block time of {ticks} ticks is out of range"),
            }
        })?;
        if self.blocks.len() >= MAX_BLOCKS {
            return Err(EbmlError::Damaged {
                at: e.start,
                reason: format!("more than {MAX_BLOCKS} blocks"),
            });
        }
        let header = n as u64 + 3;
        self.blocks.push(Block {
            track,
            time_ns,
            at: e.start,
            payload: e.data + header,
            payload_len: size - header,
            lacing: lacing::Lacing::from_flags(flags),
        });
        Ok(())
    }

    /// The track numbered `number`.
    pub fn track(&self, number: u64) -> Option<&Track> {
        self.tracks.iter().find(|t| t.number == number)
    }

    /// How many blocks each track has.
    pub fn blocks_per_track(&self) -> BTreeMap<u64, usize> {
        let mut counts = BTreeMap::new();
        for b in &self.blocks {
            *counts.entry(b.track).or_default() += 1;
        }
        counts
    }

    /// The frames of `block`: its payload split by its lacing, each with its time
    /// (laced frames follow the first at the track's DefaultDuration).
    pub fn frames(&mut self, block: &Block) -> Result<Vec<(i64, Vec<u8>)>, String> {
        let payload = self
            .reader
            .read_at(block.payload, block.payload_len, block.at, "a block")
            .map_err(|e| match e {
                EbmlError::Io(e) => e.to_string(),
                EbmlError::Cut { .. } => "the file ends inside the block".into(),
                EbmlError::Damaged { reason, .. } => reason,
            })?;
        if block.lacing == lacing::Lacing::None {
            return Ok(vec![(block.time_ns, payload)]);
        }
        let step = self
            .track(block.track)
            .and_then(|t| t.default_duration_ns)
            .unwrap_or(0) as i64;
        Ok(lacing::frames(&payload, block.lacing)?
            .into_iter()
            .enumerate()
            .map(|(i, range)| {
                (
                    block.time_ns.saturating_add(step.saturating_mul(i as i64)),
                    payload[range].to_vec(),
                )
            })
            .collect())
    }
}
