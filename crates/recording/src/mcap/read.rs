//! Streaming through an MCAP file's records with the `mcap` crate's sans-io reader:
//! chunks (zstd, lz4 or none) are decompressed as they come, nothing but one chunk is
//! held in memory, and files without a summary section (a recorder killed before it
//! closed the file) read as far as they go.
//!
//! Every checksum the format has is checked where the writer filled it in (0 means
//! none): each chunk's CRC at the chunk's end (a damaged chunk stops the import; a
//! file cut inside a chunk still gives the messages before the cut), the data
//! section's and the summary section's. The summary's statistics, where present, must count the
//! messages read: a chunk that lost its messages (a compressed chunk declaring an
//! uncompressed size of 0) is an error, not a shorter import.

use super::messages::MessageType;
use crate::error::ImportError;
use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;
use std::sync::Arc;

/// A channel: its topic and what its messages are.
#[derive(Debug)]
pub struct Channel {
    pub id: u16,
    pub topic: String,
    pub schema: String,
    pub message_encoding: String,
    /// The type relume reads it as; `Ok(None)` for types it has no use for; `Err` with
    /// why for a type it knows in an encoding it does not read (ROS 1, protobuf).
    pub ty: Result<Option<MessageType>, String>,
}

/// What the stream hands to its visitor.
pub enum Event<'a> {
    Channel(&'a Arc<Channel>),
    Message {
        channel: &'a Arc<Channel>,
        /// The message's index in the file (0-based), for error messages.
        index: u64,
        log_time_ns: u64,
        data: &'a [u8],
    },
    Metadata {
        name: &'a str,
        values: &'a BTreeMap<String, String>,
    },
}

/// How a stream ended.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct StreamEnd {
    pub messages: u64,
    /// Set when the file ends inside a record (a recorder stopped before closing the
    /// file): what preceded it was read.
    pub truncated: Option<String>,
}

/// The largest record (or decompressed chunk) read: a damaged length field must not
/// allocate gigabytes. 64 times the file (chunks compress), from 16 MiB to 1 GiB.
fn record_limit(file_len: u64) -> usize {
    file_len
        .saturating_mul(64)
        .clamp(16 << 20, 1 << 30)
        .try_into()
        .unwrap_or(1 << 30)
}

/// Calls `visit` for every channel, message and metadata record of `path`, in file
/// order. Errors name the file and the message index or byte offset.
pub fn stream(
    path: &Path,
    visit: &mut dyn FnMut(Event<'_>) -> Result<(), ImportError>,
) -> Result<StreamEnd, ImportError> {
    let io = |source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bad = |reason: String| ImportError::File {
        path: path.to_path_buf(),
        reason,
    };
    let mut file = relume_base::files::open_regular(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len();
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_record_length_limit(record_limit(file_len))
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true),
    );
    let mut schemas: BTreeMap<u16, (String, String)> = BTreeMap::new();
    let mut channels: BTreeMap<u16, Arc<Channel>> = BTreeMap::new();
    let mut end = StreamEnd::default();
    let mut bytes_read: u64 = 0;
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            Err(mcap::McapError::UnexpectedEof) if end.messages > 0 => {
                end.truncated = Some(format!(
                    "the file ends inside a record after {} messages ({bytes_read} bytes): \
                     a recorder stopped before closing it? What precedes was read",
                    end.messages
                ));
                break;
            }
            Err(
                e @ (mcap::McapError::BadChunkCrc { .. }
                | mcap::McapError::BadDataCrc { .. }
                | mcap::McapError::BadSummaryCrc { .. }),
            ) => {
                return Err(bad(format!(
                    "the file is damaged: {e} (after {} messages, {bytes_read} bytes in)",
                    end.messages
                )));
            }
            Err(e) => {
                return Err(bad(format!(
                    "not a readable MCAP file: {} (after {} messages, {bytes_read} bytes in)",
                    super::failure::describe(&e),
                    end.messages
                )));
            }
        };
        match event {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n);
                let got = file.read(buf).map_err(io)?;
                reader.notify_read(got);
                bytes_read += got as u64;
            }
            LinearReadEvent::Record { data, opcode } => {
                super::lengths::strings_fit(opcode, data).map_err(|why| {
                    bad(format!(
                        "record {opcode:#04x} after {} messages is damaged: {why}",
                        end.messages
                    ))
                })?;
                let record = mcap::parse_record(opcode, data).map_err(|e| {
                    bad(format!(
                        "record {opcode:#04x} after {} messages is damaged: {e}",
                        end.messages
                    ))
                })?;
                match record {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, (header.name, header.encoding));
                    }
                    Record::Channel(c) => {
                        if channels.contains_key(&c.id) {
                            continue;
                        }
                        let schema = match c.schema_id {
                            0 => String::new(),
                            id => match schemas.get(&id) {
                                Some((name, _)) => name.clone(),
                                None => {
                                    return Err(bad(format!(
                                        "channel {} ({}) names schema {id}, which the file \
                                         does not define before it",
                                        c.id, c.topic
                                    )));
                                }
                            },
                        };
                        let ty = MessageType::of(&schema, &c.message_encoding);
                        let channel = Arc::new(Channel {
                            id: c.id,
                            topic: c.topic,
                            schema,
                            message_encoding: c.message_encoding,
                            ty,
                        });
                        visit(Event::Channel(&channel))?;
                        channels.insert(channel.id, channel);
                    }
                    Record::Message { header, data } => {
                        let Some(channel) = channels.get(&header.channel_id) else {
                            return Err(bad(format!(
                                "message {} names channel {}, which the file does not \
                                 define before it",
                                end.messages, header.channel_id
                            )));
                        };
                        visit(Event::Message {
                            channel,
                            index: end.messages,
                            log_time_ns: header.log_time,
                            data: &data,
                        })?;
                        end.messages += 1;
                    }
                    Record::Metadata(m) => visit(Event::Metadata {
                        name: &m.name,
                        values: &m.metadata,
                    })?,
                    Record::Statistics(stats) if stats.message_count != end.messages => {
                        return Err(bad(format!(
                            "the file is damaged: its statistics count {} messages but its \
                             chunks hold {}",
                            stats.message_count, end.messages
                        )));
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(end)
}
