//! Writes `.relume` files atomically: everything goes to a temporary file beside the
//! target, which is renamed over the final name only when the footer is written and the
//! data synced. An interrupted write leaves no file under the final name.

use super::error::RecordingError;
use super::format::{FrameHeader, IndexEntry, PREAMBLE_LEN, TRAILER_MAGIC, Tag, encode_preamble};
use super::types::{Header, Record};
use serde::Serialize;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// A recording being written. Call [`RecordingWriter::finish`] to publish it; dropping it
/// unfinished deletes the temporary file.
pub struct RecordingWriter {
    out: Option<BufWriter<File>>,
    tmp_path: PathBuf,
    final_path: PathBuf,
    offset: u64,
    index: Vec<IndexEntry>,
}

impl RecordingWriter {
    /// Starts a recording at `path` with `header`.
    pub fn create(path: &Path, header: &Header) -> Result<Self, RecordingError> {
        let tmp_path = temp_path_for(path);
        let file = File::create(&tmp_path).map_err(|e| RecordingError::io(&tmp_path, e))?;
        let mut w = RecordingWriter {
            out: Some(BufWriter::with_capacity(1 << 20, file)),
            tmp_path,
            final_path: path.to_path_buf(),
            offset: 0,
            index: Vec::new(),
        };
        w.put(&encode_preamble())?;
        debug_assert_eq!(w.offset, PREAMBLE_LEN);
        let payload = w.encode(header)?;
        w.put_frame(Tag::Header, 0, &payload)?;
        Ok(w)
    }

    /// Appends one stream record.
    pub fn write(&mut self, record: &Record) -> Result<(), RecordingError> {
        let payload = match record {
            Record::Color(r) => self.encode(r)?,
            Record::Depth(r) => self.encode(r)?,
            Record::Pose(r) => self.encode(r)?,
            Record::Truth(r) => self.encode(r.as_ref())?,
        };
        let kind = record.kind();
        let stamp_ns = record.stamp_ns();
        let offset = self.offset;
        self.put_frame(Tag::Stream(kind), stamp_ns, &payload)?;
        self.index.push(IndexEntry {
            kind,
            stamp_ns,
            offset,
            len: payload.len() as u32,
        });
        Ok(())
    }

    /// Number of stream records written so far.
    pub fn records(&self) -> usize {
        self.index.len()
    }

    /// Writes the index footer and trailer, syncs, and renames to the final path.
    pub fn finish(mut self) -> Result<PathBuf, RecordingError> {
        let index = std::mem::take(&mut self.index);
        let payload = self.encode(&index)?;
        let footer_offset = self.offset;
        self.put_frame(Tag::Index, 0, &payload)?;
        let mut trailer = [0u8; 16];
        trailer[..8].copy_from_slice(&footer_offset.to_le_bytes());
        trailer[8..].copy_from_slice(&TRAILER_MAGIC);
        self.put(&trailer)?;
        let out = self.out.take().expect("writer is open until finish");
        let published = (|| {
            let file = out
                .into_inner()
                .map_err(|e| RecordingError::io(&self.tmp_path, e.into_error()))?;
            file.sync_all()
                .map_err(|e| RecordingError::io(&self.tmp_path, e))?;
            drop(file);
            std::fs::rename(&self.tmp_path, &self.final_path)
                .map_err(|e| RecordingError::io(&self.final_path, e))
        })();
        if let Err(e) = published {
            // `out` is taken, so Drop no longer removes the temporary file.
            let _ = std::fs::remove_file(&self.tmp_path);
            return Err(e);
        }
        Ok(self.final_path.clone())
    }

    fn encode<T: Serialize + ?Sized>(&self, value: &T) -> Result<Vec<u8>, RecordingError> {
        rmp_serde::to_vec_named(value).map_err(|e| RecordingError::Invalid {
            path: self.final_path.clone(),
            reason: format!("cannot encode record: {e}"),
        })
    }

    fn put_frame(&mut self, tag: Tag, stamp_ns: i64, payload: &[u8]) -> Result<(), RecordingError> {
        if payload.len() as u64 > super::format::MAX_PAYLOAD_LEN as u64 {
            return Err(RecordingError::Invalid {
                path: self.final_path.clone(),
                reason: format!(
                    "a record of {} bytes exceeds the format's limit of {} bytes",
                    payload.len(),
                    super::format::MAX_PAYLOAD_LEN
                ),
            });
        }
        self.put(&FrameHeader::encode(tag, stamp_ns, payload))?;
        self.put(payload)
    }

    fn put(&mut self, bytes: &[u8]) -> Result<(), RecordingError> {
        let out = self.out.as_mut().expect("writer is open until finish");
        out.write_all(bytes)
            .map_err(|e| RecordingError::io(&self.tmp_path, e))?;
        self.offset += bytes.len() as u64;
        Ok(())
    }
}

impl Drop for RecordingWriter {
    fn drop(&mut self) {
        if self.out.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp_path);
        }
    }
}

/// A hidden temporary name beside `path`, unique per process.
pub fn temp_path_for(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.{}.partial", std::process::id()))
}

/// Writes `bytes` to `path` atomically (temporary file, then rename): a process stopped
/// midway leaves the old file or the new one, never half of one. No fsync: per-frame
/// outputs guard against interruption, not power loss.
pub fn write_file_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = temp_path_for(path);
    let result = (|| {
        let mut f = File::create(&tmp)?;
        f.write_all(bytes)?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
