//! [`BatchError`]: what can go wrong in a batch around its runs, which the manifest,
//! the shards, the markers and the summary all return.

use std::path::PathBuf;

/// What can go wrong in a batch, before or around the runs themselves.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// The manifest is wrong at a place in it (line and column).
    #[error("{0}")]
    Manifest(#[from] relume_graph::ConfigError),
    /// A `--shard` value, or the scheduler variables `--shard auto` reads, are wrong.
    #[error("{0}")]
    Shard(String),
    /// A file or folder of the batch could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
}

impl BatchError {
    /// An [`BatchError::Io`] about `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> BatchError {
        BatchError::Io {
            path: path.into(),
            source,
        }
    }
}
