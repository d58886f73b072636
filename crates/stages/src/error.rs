//! Why an op could not compute: [`OpError`], the error of the plain functions over
//! buffers that the stages wrap (`sample_path`, `merge_depth`, `splat`, `filter`, ...).
//!
//! An op knows nothing of frames or pipelines, so it does not return the runtime's
//! [`StageError`]; a stage turns an [`OpError`] into one with `?` (the message is kept
//! word for word). The variants say what went wrong, so that a caller outside a
//! pipeline (a test, a benchmark, `relume eval`) can tell a caller's mistake (sizes,
//! parameters) from an input that cannot be used; each message names the op.

use relume_graph::StageError;
use std::path::PathBuf;

/// Why an op failed.
#[derive(Debug, thiserror::Error)]
pub enum OpError {
    /// Buffers the op reads or writes disagree in size (the message names both sizes).
    #[error("{0}")]
    SizeMismatch(String),
    /// A parameter outside the range the op can compute with.
    #[error("{0}")]
    BadParameter(String),
    /// An input the op cannot use: a non-finite pose, a map without light, a query
    /// without the product it reads.
    #[error("{0}")]
    BadInput(String),
    /// A product that cannot be written in the asked format, or an encoder's failure.
    #[error("{0}")]
    Unwritable(String),
    /// A file the op writes.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

impl From<OpError> for StageError {
    /// The stage fails with the op's message, word for word; a file error keeps its
    /// path and cause.
    fn from(e: OpError) -> StageError {
        match e {
            OpError::Io { path, source } => StageError::Io { path, source },
            e => StageError::Failed(e.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_fails_with_the_ops_message_and_keeps_a_files_path() {
        let e: StageError =
            OpError::SizeMismatch("merge: weight is 2x2, depth is 3x3".into()).into();
        assert_eq!(e.to_string(), "merge: weight is 2x2, depth is 3x3");
        assert!(matches!(e, StageError::Failed(_)));
        let io = std::io::Error::new(std::io::ErrorKind::PermissionDenied, "denied");
        let e: StageError = OpError::Io {
            path: "out/a.png".into(),
            source: io,
        }
        .into();
        assert_eq!(e.to_string(), "out/a.png: denied");
        assert!(matches!(e, StageError::Io { .. }));
    }
}
