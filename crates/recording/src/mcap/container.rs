//! The two containers relume reads robotics logs from, told apart by their first bytes:
//! MCAP files ([`super::read`]) and ROS 1 bags (`bag.rs`). Both are streamed as the
//! same [`Event`]s, so the scan, the topic choice and the import serve either.

use super::read::{Event, ReadOptions, StreamEnd, stream_mcap};
use crate::error::ImportError;
use std::io::{Read, Seek};
use std::path::Path;

/// Calls `visit` for every channel, message and metadata record of `path`, an MCAP file
/// or a ROS 1 bag, in file order. Errors name the file and the message index or byte
/// offset.
pub fn stream(
    path: &Path,
    options: ReadOptions,
    visit: &mut dyn FnMut(Event<'_>) -> Result<(), ImportError>,
) -> Result<StreamEnd, ImportError> {
    let io = |source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = relume_base::files::open_regular(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len();
    let mut magic = [0u8; super::bag::MAGIC.len()];
    let got = file.read(&mut magic).map_err(io)?;
    if got == magic.len() && magic == super::bag::MAGIC {
        super::bag::stream(path, file, file_len, options, visit)
    } else {
        file.rewind().map_err(io)?;
        stream_mcap(path, file, file_len, options, visit)
    }
}
