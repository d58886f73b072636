//! An item's output folder, `OUT/<item id>/`, and its completion marker `DONE`.
//!
//! The folder holds the item's saved products (those of the pipeline's `write` stages
//! and of `save`), [`REPORT`] (what the run produced: deterministic), [`TIMINGS`] (how
//! long it took: differs from run to run), and last, written atomically once all else
//! is in place, [`DONE`]: the item's id, a digest of its settings and pipeline, and the
//! number, size and digest of its output files (all but `DONE`, [`FAILED`] and
//! [`TIMINGS`]). A rerun skips an item whose marker is valid: readable, for the same id
//! and configuration, with the same number and total size of files (the files' content
//! is not read again). A folder without a valid marker is cleared and the item redone.
//! An item that failed holds [`FAILED`] (the error) instead.

use super::error::BatchError;
use std::path::{Path, PathBuf};
use xxhash_rust::xxh3::{Xxh3, xxh3_64};

/// The completion marker's file name.
pub const DONE: &str = "DONE";
/// The file that holds a failed item's error.
pub const FAILED: &str = "FAILED";
/// The item's report: frames, skipped frames, per-frame product digests.
pub const REPORT: &str = "report.json";
/// The item's timings (not part of the digest: they differ between runs).
pub const TIMINGS: &str = "timings.json";

const MAGIC: &str = "relume-batch-done 1";

/// What a `DONE` marker says.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Marker {
    /// The item's id.
    pub id: String,
    /// xxh3 of the item's settings and pipeline text ([`config_digest`]).
    pub config: u64,
    /// How many output files the folder holds (sub-folders counted through).
    pub files: u64,
    /// Their total size in bytes.
    pub bytes: u64,
    /// xxh3 over their relative paths and contents ([`Outputs::digest`]).
    pub digest: u64,
}

/// A marker's state in a folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MarkerState {
    /// No marker (no folder, or a folder a killed or failed run left).
    Absent,
    /// A marker that fits the item and the files beside it: the item is done.
    Valid(Marker),
    /// A marker that does not fit: why.
    Invalid(String),
}

/// A digest of what configures an item's run: its settings (canonical line) and its
/// pipeline file's text. A changed pipeline or setting makes an earlier marker invalid.
/// What identifies a recording's content without reading all of it: its size and a
/// digest of its first and last 64 KiB (the header, and the index footer that every
/// write changes). A recording imported again at the same path makes its items stale.
pub fn recording_digest(path: &Path) -> std::io::Result<u64> {
    use std::io::{Read, Seek, SeekFrom};
    const SPAN: u64 = 64 << 10;
    let mut file = relume_base::files::open_regular(path)?;
    let len = file.metadata()?.len();
    let mut bytes = Vec::with_capacity(2 * SPAN as usize + 8);
    bytes.extend(len.to_le_bytes());
    file.by_ref().take(SPAN).read_to_end(&mut bytes)?;
    file.seek(SeekFrom::Start(len.saturating_sub(SPAN)))?;
    file.take(SPAN).read_to_end(&mut bytes)?;
    Ok(xxh3_64(&bytes))
}

pub fn config_digest(settings: &str, pipeline_text: &str) -> u64 {
    xxh3_64(format!("{settings}\n--\n{pipeline_text}").as_bytes())
}

/// The output files of an item's folder: every regular file under it but the marker,
/// [`FAILED`], [`TIMINGS`] and hidden temporary files, sorted by relative path.
#[derive(Clone, Debug, Default)]
pub struct Outputs {
    /// Relative path (with `/`) and size of each file.
    pub files: Vec<(String, u64)>,
}

impl Outputs {
    /// Lists the output files under `dir`.
    pub fn list(dir: &Path) -> Result<Outputs, BatchError> {
        let mut files = Vec::new();
        walk(dir, "", &mut files)?;
        files.sort();
        Ok(Outputs { files })
    }

    /// Total size in bytes.
    pub fn bytes(&self) -> u64 {
        self.files.iter().map(|(_, n)| n).sum()
    }

    /// xxh3 over each file's relative path, size and content, in order.
    pub fn digest(&self, dir: &Path) -> Result<u64, BatchError> {
        let mut h = Xxh3::new();
        for (name, size) in &self.files {
            let path = dir.join(name);
            let bytes = std::fs::read(&path).map_err(|e| BatchError::io(&path, e))?;
            h.update(name.as_bytes());
            h.update(&[0]);
            h.update(&size.to_le_bytes());
            h.update(&xxh3_64(&bytes).to_le_bytes());
        }
        Ok(h.digest())
    }
}

fn walk(dir: &Path, prefix: &str, files: &mut Vec<(String, u64)>) -> Result<(), BatchError> {
    let entries = std::fs::read_dir(dir).map_err(|e| BatchError::io(dir, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| BatchError::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let meta = entry
            .metadata()
            .map_err(|e| BatchError::io(entry.path(), e))?;
        let rel = format!("{prefix}{name}");
        if meta.is_dir() {
            walk(&entry.path(), &format!("{rel}/"), files)?;
        } else {
            let own = [DONE, FAILED, TIMINGS].contains(&name.as_str());
            if (prefix.is_empty() && own) || name.starts_with('.') {
                continue;
            }
            files.push((rel, meta.len()));
        }
    }
    Ok(())
}

impl Marker {
    /// The marker for the item `id` (configuration `config`) whose outputs are in
    /// `dir`: reads every output file once for the digest.
    pub fn of(dir: &Path, id: &str, config: u64) -> Result<Marker, BatchError> {
        let outputs = Outputs::list(dir)?;
        Ok(Marker {
            id: id.to_string(),
            config,
            files: outputs.files.len() as u64,
            bytes: outputs.bytes(),
            digest: outputs.digest(dir)?,
        })
    }

    /// The marker's text: one `key value` per line after a first line naming the format.
    pub fn text(&self) -> String {
        format!(
            "{MAGIC}\nid {}\nconfig {:016x}\nfiles {}\nbytes {}\ndigest {:016x}\n",
            self.id, self.config, self.files, self.bytes, self.digest
        )
    }

    /// Parses [`Marker::text`]; `None` for anything else.
    pub fn parse(text: &str) -> Option<Marker> {
        let mut lines = text.lines();
        if lines.next()? != MAGIC {
            return None;
        }
        let mut field = |key: &str| {
            let line = lines.next()?;
            line.strip_prefix(key)?
                .strip_prefix(' ')
                .map(str::to_string)
        };
        let id = field("id")?;
        let config = u64::from_str_radix(&field("config")?, 16).ok()?;
        let files = field("files")?.parse().ok()?;
        let bytes = field("bytes")?.parse().ok()?;
        let digest = u64::from_str_radix(&field("digest")?, 16).ok()?;
        Some(Marker {
            id,
            config,
            files,
            bytes,
            digest,
        })
    }

    /// Writes the marker into `dir` atomically: the last file of a finished item.
    pub fn write(&self, dir: &Path) -> Result<(), BatchError> {
        let path = dir.join(DONE);
        relume_recording::writer::write_file_atomic(&path, self.text().as_bytes())
            .map_err(|e| BatchError::io(path, e))
    }

    /// The marker in `dir` and whether it fits the item `id` with configuration
    /// `config` (`None`: any) and the files beside it.
    pub fn check(dir: &Path, id: &str, config: Option<u64>) -> MarkerState {
        let path = dir.join(DONE);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return MarkerState::Absent,
            Err(e) => return MarkerState::Invalid(format!("its DONE marker is unreadable ({e})")),
        };
        let Some(marker) = Marker::parse(&text) else {
            return MarkerState::Invalid("its DONE marker is not one relume wrote".into());
        };
        if marker.id != id {
            return MarkerState::Invalid(format!("its DONE marker is for item {}", marker.id));
        }
        if config.is_some_and(|c| c != marker.config) {
            return MarkerState::Invalid(
                "its recording, settings or pipeline changed since it was done".into(),
            );
        }
        match Outputs::list(dir) {
            Ok(o) if o.files.len() as u64 == marker.files && o.bytes() == marker.bytes => {
                MarkerState::Valid(marker)
            }
            Ok(o) => MarkerState::Invalid(format!(
                "it holds {} file(s) of {} bytes where its DONE marker says {} of {}",
                o.files.len(),
                o.bytes(),
                marker.files,
                marker.bytes
            )),
            Err(e) => MarkerState::Invalid(e.to_string()),
        }
    }
}

/// Removes `dir` with everything in it (what an unfinished run left) and creates it
/// empty.
pub fn clear(dir: &Path) -> Result<(), BatchError> {
    match std::fs::remove_dir_all(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(BatchError::io(dir, e)),
    }
    std::fs::create_dir_all(dir).map_err(|e| BatchError::io(dir, e))
}

/// Writes `message` to `dir/FAILED` (atomically).
pub fn write_failed(dir: &Path, message: &str) -> Result<(), BatchError> {
    let path: PathBuf = dir.join(FAILED);
    relume_recording::writer::write_file_atomic(&path, format!("{message}\n").as_bytes())
        .map_err(|e| BatchError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markers_fit_their_folder_or_say_why_not() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("a__p__00000000");
        clear(&dir).unwrap();
        assert_eq!(
            Marker::check(&dir, "a__p__00000000", Some(7)),
            MarkerState::Absent
        );
        std::fs::create_dir_all(dir.join("normals")).unwrap();
        std::fs::write(dir.join("normals/000000.png"), b"png").unwrap();
        std::fs::write(dir.join(REPORT), b"{}").unwrap();
        std::fs::write(dir.join(TIMINGS), b"{\"wall_s\": 1}").unwrap();
        let marker = Marker::of(&dir, "a__p__00000000", 7).unwrap();
        assert_eq!((marker.files, marker.bytes), (2, 5));
        assert_eq!(Marker::parse(&marker.text()), Some(marker.clone()));
        marker.write(&dir).unwrap();
        let id = "a__p__00000000";
        assert_eq!(
            Marker::check(&dir, id, Some(7)),
            MarkerState::Valid(marker.clone())
        );
        // Timings change from run to run and are not outputs.
        std::fs::write(dir.join(TIMINGS), b"{\"wall_s\": 12}").unwrap();
        assert_eq!(Marker::of(&dir, id, 7).unwrap(), marker);
        assert!(matches!(
            Marker::check(&dir, id, Some(8)),
            MarkerState::Invalid(_)
        ));
        assert!(matches!(
            Marker::check(&dir, "b", Some(7)),
            MarkerState::Invalid(_)
        ));
        std::fs::remove_file(dir.join("normals/000000.png")).unwrap();
        assert!(matches!(
            Marker::check(&dir, id, Some(7)),
            MarkerState::Invalid(_)
        ));
        std::fs::write(dir.join(DONE), b"half").unwrap();
        assert!(matches!(
            Marker::check(&dir, id, Some(7)),
            MarkerState::Invalid(_)
        ));
        clear(&dir).unwrap();
        assert!(Outputs::list(&dir).unwrap().files.is_empty());
    }
}
