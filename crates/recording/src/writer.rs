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
        header.check().map_err(|reason| RecordingError::Invalid {
            path: path.to_path_buf(),
            reason: format!("cannot write this header: {reason}"),
        })?;
        let (final_path, tmp_path) = output_paths(path).map_err(|e| RecordingError::io(path, e))?;
        // A missing folder is reported under the name the caller gave, not the
        // temporary one.
        let file = File::create(&tmp_path).map_err(|e| RecordingError::io(path, e))?;
        let mut w = RecordingWriter {
            out: Some(BufWriter::with_capacity(1 << 20, file)),
            tmp_path,
            final_path,
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

/// The file that an output written to `path` replaces: `path` itself, or the file a
/// symbolic link there leads to (so that the link stays a link). Outputs are written
/// to a temporary file and renamed over their target, which would replace anything
/// else that stands there, so a path holding something other than a regular file (a
/// device such as /dev/null, a FIFO, a directory) is an error.
pub fn output_target(path: &Path) -> std::io::Result<PathBuf> {
    use std::io::{Error, ErrorKind};
    // "out/" would be written as the file "out" (or fail if that is missing).
    if path.as_os_str().to_string_lossy().ends_with('/') {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            "ends in `/`, which names a folder: give a file name",
        ));
    }
    let mut target = path.to_path_buf();
    // As many links as Linux follows (MAXSYMLINKS).
    for _ in 0..40 {
        let meta = match std::fs::symlink_metadata(&target) {
            Err(e) if e.kind() == ErrorKind::NotFound => return Ok(target),
            other => other?,
        };
        if meta.is_file() {
            return Ok(target);
        }
        if meta.is_dir() {
            return Err(Error::new(
                ErrorKind::InvalidInput,
                "is a folder: give a file name",
            ));
        }
        if !meta.file_type().is_symlink() {
            return Err(Error::new(
                ErrorKind::InvalidInput,
                "not a regular file (outputs are written beside their target and renamed \
                 over it, which would replace it)",
            ));
        }
        // A relative link leads from the link's folder; `join` keeps an absolute one.
        let link = std::fs::read_link(&target)?;
        target = match target.parent() {
            Some(folder) => folder.join(link),
            None => link,
        };
    }
    Err(Error::new(
        ErrorKind::InvalidInput,
        "too many levels of symbolic links",
    ))
}

/// Where an output to `path` goes: its [`output_target`], and the temporary file beside
/// it ([`temp_path_for`]) that is written first and renamed over it.
pub fn output_paths(path: &Path) -> std::io::Result<(PathBuf, PathBuf)> {
    let target = output_target(path)?;
    let temporary = temp_path_for(&target);
    Ok((target, temporary))
}

/// A hidden temporary name beside `path`, unique per process.
pub fn temp_path_for(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.{}.partial", std::process::id()))
}

/// Whether `path` is a temporary file that [`temp_path_for`] named for a process that
/// is no longer running (a killed run's half-written output). Only on systems with
/// `/proc`; elsewhere nothing is known stale.
pub fn is_stale_partial(path: &Path) -> bool {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return false;
    };
    let Some(rest) = name
        .strip_prefix('.')
        .and_then(|n| n.strip_suffix(".partial"))
    else {
        return false;
    };
    let Some(pid) = rest
        .rsplit_once('.')
        .and_then(|(_, p)| p.parse::<u32>().ok())
    else {
        return false;
    };
    let proc = Path::new("/proc");
    proc.join("self").exists() && !proc.join(pid.to_string()).exists()
}

/// Writes `bytes` to `path` ([`output_target`]) atomically (temporary file, then
/// rename): a process stopped midway leaves the old file or the new one, never half of
/// one. No fsync: per-frame outputs guard against interruption, not power loss.
pub fn write_file_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let (target, tmp) = output_paths(path)?;
    let result = (|| {
        let mut f = File::create(&tmp)?;
        f.write_all(bytes)?;
        std::fs::rename(&tmp, &target)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn outputs_replace_a_link_target_and_refuse_what_is_not_a_file() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        std::fs::write(d.join("real.png"), b"old").unwrap();
        std::os::unix::fs::symlink("real.png", d.join("link.png")).unwrap();
        std::os::unix::fs::symlink("link.png", d.join("link2.png")).unwrap();
        write_file_atomic(&d.join("link2.png"), b"new").unwrap();
        assert_eq!(std::fs::read(d.join("real.png")).unwrap(), b"new");
        for link in ["link.png", "link2.png"] {
            let meta = std::fs::symlink_metadata(d.join(link)).unwrap();
            assert!(meta.file_type().is_symlink(), "{link} stays a link");
        }
        // A dangling link: the file is created where it leads.
        std::os::unix::fs::symlink("made.png", d.join("dangling.png")).unwrap();
        write_file_atomic(&d.join("dangling.png"), b"made").unwrap();
        assert_eq!(std::fs::read(d.join("made.png")).unwrap(), b"made");

        std::fs::create_dir(d.join("folder")).unwrap();
        let e = write_file_atomic(&d.join("folder"), b"x").unwrap_err();
        assert_eq!(e.to_string(), "is a folder: give a file name");
        assert!(d.join("folder").is_dir());
        let e = write_file_atomic(&d.join("new/"), b"x").unwrap_err();
        assert_eq!(
            e.to_string(),
            "ends in `/`, which names a folder: give a file name"
        );
        let fifo = d.join("fifo");
        assert!(
            std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .unwrap()
                .success()
        );
        let e = write_file_atomic(&fifo, b"x").unwrap_err();
        assert_eq!(
            e.to_string(),
            "not a regular file (outputs are written beside their target and renamed over \
             it, which would replace it)"
        );
        std::fs::remove_file(&fifo).unwrap();
        std::os::unix::fs::symlink("loop.png", d.join("loop.png")).unwrap();
        let e = write_file_atomic(&d.join("loop.png"), b"x").unwrap_err();
        assert_eq!(e.to_string(), "too many levels of symbolic links");
        // Nothing temporary is left behind by the refusals.
        let mut names: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(
            names,
            [
                "dangling.png",
                "folder",
                "link.png",
                "link2.png",
                "loop.png",
                "made.png",
                "real.png"
            ]
        );
    }

    #[test]
    fn a_recording_into_a_missing_folder_names_the_path_given() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("no/such/x.relume");
        let header = Header::new("x", crate::Intrinsics::PRIMESENSE, 0.001);
        let e = match RecordingWriter::create(&path, &header) {
            Err(e) => e,
            Ok(_) => panic!("the folder does not exist"),
        };
        let cause = std::fs::File::create(&path).unwrap_err();
        assert_eq!(e.to_string(), format!("{}: {cause}", path.display()));
    }
}
