//! Errors of reading, writing and importing recordings. Every variant names the file,
//! and where it applies the byte offset, record, frame or line.

use std::path::PathBuf;

/// What went wrong with a recording file.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: not a relume recording (the file does not start with the relume magic bytes)", path.display())]
    BadMagic { path: PathBuf },
    #[error(
        "{}: written in format {found} and needs a reader of at least {min_reader}; this relume reads format {supported} (upgrade relume)",
        path.display()
    )]
    UnsupportedVersion {
        path: PathBuf,
        found: String,
        min_reader: String,
        supported: String,
    },
    #[error("{}: truncated at byte {offset}: {what}", path.display())]
    Truncated {
        path: PathBuf,
        offset: u64,
        what: String,
    },
    #[error(
        "{}: record {record} ({kind}) at byte {offset} is corrupt: checksum mismatch (stored {stored:08x}, computed {computed:08x})",
        path.display()
    )]
    Checksum {
        path: PathBuf,
        record: usize,
        kind: &'static str,
        offset: u64,
        stored: u32,
        computed: u32,
    },
    #[error("{}: corrupt data at byte {offset}: {reason}", path.display())]
    Corrupt {
        path: PathBuf,
        offset: u64,
        reason: String,
    },
    #[error("{}: record {record} ({kind}) at byte {offset} cannot be decoded: {reason}", path.display())]
    Decode {
        path: PathBuf,
        record: usize,
        kind: &'static str,
        offset: u64,
        reason: String,
    },
    #[error("{}: frame {frame} does not exist (the recording has {frames} frames)", path.display())]
    FrameOutOfRange {
        path: PathBuf,
        frame: usize,
        frames: usize,
    },
    #[error("{}: {reason}", path.display())]
    Invalid { path: PathBuf, reason: String },
}

impl RecordingError {
    /// The message without the file name in front (for an error quoted inside another).
    pub fn reason(&self) -> String {
        let text = self.to_string();
        let path = match self {
            RecordingError::Io { path, .. }
            | RecordingError::BadMagic { path }
            | RecordingError::UnsupportedVersion { path, .. }
            | RecordingError::Truncated { path, .. }
            | RecordingError::Checksum { path, .. }
            | RecordingError::Corrupt { path, .. }
            | RecordingError::Decode { path, .. }
            | RecordingError::FrameOutOfRange { path, .. }
            | RecordingError::Invalid { path, .. } => path,
        };
        let prefix = format!("{}: ", path.display());
        text.strip_prefix(&prefix).unwrap_or(&text).to_string()
    }

    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        RecordingError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// An error of an importer: names the file and, for text files, the line; for binary
/// files with frames, the frame.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}:{line}: {reason}", path.display())]
    Line {
        path: PathBuf,
        line: usize,
        reason: String,
    },
    #[error("{}: {reason}", path.display())]
    File { path: PathBuf, reason: String },
    /// A frame of a binary recording file (ScanNet `.sens`), by its index in the file.
    #[error("{}: frame {frame}: {reason}", path.display())]
    Frame {
        path: PathBuf,
        frame: usize,
        reason: String,
    },
    #[error(transparent)]
    Recording(#[from] RecordingError),
}
