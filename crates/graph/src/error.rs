//! Why a stage failed: [`StageError`], which stages return and the frame's typed
//! getters give for a missing or mistyped product.

use relume_recording::RecordingError;
use std::path::PathBuf;

/// Why a stage failed on a frame.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    #[error("input product `{0}` is missing from the frame")]
    MissingInput(String),
    #[error("product `{product}` is a {found}, expected a {expected}")]
    WrongKind {
        product: String,
        expected: &'static str,
        found: &'static str,
    },
    #[error("{0}")]
    Failed(String),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Recording(#[from] RecordingError),
}
