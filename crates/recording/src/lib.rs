//! Recordings: the `.relume` format, association of streams into frames, importers of
//! common RGB-D layouts, and the synthetic scene generator with ground truth.

pub mod association;
pub mod codec;
pub mod error;
pub mod format;
pub mod importers;
pub mod lens;
pub mod matroska;
pub mod mcap;
pub mod products;
pub mod reader;
pub mod register;
pub mod replay;
pub mod synth;
pub mod types;
pub mod writer;

pub use error::{ImportError, RecordingError};
pub use products::{POSE, RECORD};
pub use reader::Recording;
pub use replay::{FrameRecords, Replay, ReplayOptions};
pub use types::*;
pub use writer::RecordingWriter;

/// The frame rates that stamping frame k at k / fps accepts: from one frame in 1000 s
/// to a million frames a second, so that stamps stay distinct in nanoseconds.
pub const FPS_RANGE: std::ops::RangeInclusive<f64> = 0.001..=1e6;
