//! Recordings: the `.relume` format, association of streams into frames, importers of
//! common RGB-D layouts, and the synthetic scene generator with ground truth.

pub mod association;
pub mod codec;
pub mod error;
pub mod format;
pub mod importers;
pub mod reader;
pub mod replay;
pub mod synth;
pub mod types;
pub mod writer;

pub use error::{ImportError, RecordingError};
pub use reader::Recording;
pub use replay::{FrameRecords, Replay, ReplayOptions};
pub use types::*;
pub use writer::RecordingWriter;
