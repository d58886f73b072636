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
//!
//! With [`ReadOptions::skip_corrupt`] each chunk is opened and checked whole before its
//! records are read (`chunk.rs`), and one that fails is passed over and named in
//! [`StreamEnd::skipped_chunks`]; damage outside the chunks still stops the import.

use super::chunk;
use super::messages::{Encoding, MessageType};
use crate::error::ImportError;
use mcap::records::{Record, op};
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
    /// The type relume reads it as and the messages' wire format; `Ok(None)` for types
    /// it has no use for; `Err` with why for a type it knows in an encoding it does not
    /// read (protobuf).
    pub ty: Result<Option<(MessageType, Encoding)>, String>,
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

/// How [`stream`](super::container::stream) meets damage it can place.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Pass over a chunk that fails its CRC, its size or its decompression, and say so
    /// in [`StreamEnd::skipped_chunks`], instead of stopping (`--skip-corrupt`).
    pub skip_corrupt: bool,
}

/// The two containers [`stream`](super::container::stream) reads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Container {
    /// An MCAP file.
    #[default]
    Mcap,
    /// A ROS 1 bag, format 2.0.
    RosBag,
}

impl Container {
    /// The importer's name in a recording's provenance.
    pub fn importer(self) -> &'static str {
        match self {
            Container::Mcap => "mcap",
            Container::RosBag => "rosbag",
        }
    }
}

/// How a stream ended.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct StreamEnd {
    /// What the file was.
    pub container: Container,
    pub messages: u64,
    /// Set when the file ends inside a record (a recorder stopped before closing the
    /// file): what preceded it was read.
    pub truncated: Option<String>,
    /// With `skip_corrupt`: each chunk passed over, where and why, one sentence each.
    pub skipped_chunks: Vec<String>,
    /// With `skip_corrupt`: messages passed over because their channel (or its schema)
    /// was defined only in a skipped chunk.
    pub orphaned_messages: u64,
    /// With `skip_corrupt`: how many messages the summary's statistics count, where that
    /// differs from what was read because chunks were skipped.
    pub summary_messages: Option<u64>,
}

impl StreamEnd {
    /// What skipping damaged chunks cost, in one sentence, if it cost anything.
    pub fn skipped(&self) -> Option<String> {
        if self.skipped_chunks.is_empty() {
            return None;
        }
        let mut s = format!(
            "skipped {} damaged chunk{} (--skip-corrupt): {}",
            self.skipped_chunks.len(),
            if self.skipped_chunks.len() == 1 {
                ""
            } else {
                "s"
            },
            self.skipped_chunks.join("; ")
        );
        if let Some(n) = self.summary_messages {
            s += &format!(
                "; the file's statistics count {n} messages, {} were read",
                self.messages
            );
        }
        if self.orphaned_messages > 0 {
            s += &format!(
                "; {} later messages are passed over too: their channel was defined in a \
                 skipped chunk",
                self.orphaned_messages
            );
        }
        Some(s)
    }
}

/// The largest record (or decompressed chunk) read: a damaged length field must not
/// allocate gigabytes. 64 times the file (chunks compress), from 16 MiB to 1 GiB.
pub(super) fn record_limit(file_len: u64) -> usize {
    file_len
        .saturating_mul(64)
        .clamp(16 << 20, 1 << 30)
        .try_into()
        .unwrap_or(1 << 30)
}

/// Calls `visit` for every channel, message and metadata record of the MCAP file `path`
/// (opened as `file`, at its start), in file order. Errors name the file and the message
/// index or byte offset.
pub(super) fn stream_mcap(
    path: &Path,
    mut file: std::fs::File,
    file_len: u64,
    options: ReadOptions,
    visit: &mut dyn FnMut(Event<'_>) -> Result<(), ImportError>,
) -> Result<StreamEnd, ImportError> {
    let io = |source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let limit = record_limit(file_len);
    let skip = options.skip_corrupt;
    // Skipping needs each chunk whole before its records are read: the reader hands it
    // over as a record (`chunk::unpack` checks it).
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_record_length_limit(limit)
            .with_emit_chunks(skip)
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true),
    );
    let mut records = Records {
        path,
        skip,
        schemas: BTreeMap::new(),
        channels: BTreeMap::new(),
        end: StreamEnd::default(),
    };
    let mut bytes_read: u64 = 0;
    // Where the next top-level record starts (exact while chunks are emitted whole).
    let mut offset = mcap::MAGIC.len() as u64;
    let mut chunks = 0u64;
    while let Some(event) = reader.next_event() {
        let messages = records.end.messages;
        let event = match event {
            Ok(e) => e,
            Err(mcap::McapError::UnexpectedEof) if messages > 0 => {
                records.end.truncated = Some(format!(
                    "the file ends inside a record after {messages} messages ({bytes_read} bytes): \
                     a recorder stopped before closing it? What precedes was read"
                ));
                break;
            }
            // The skipped chunks are in the data section's CRC: its failure is theirs.
            // What follows the data section is the summary, which a skipping import has
            // no need of.
            Err(mcap::McapError::BadDataCrc { .. } | mcap::McapError::BadSummaryCrc { .. })
                if records.lost_some() =>
            {
                break;
            }
            Err(
                e @ (mcap::McapError::BadChunkCrc { .. }
                | mcap::McapError::BadDataCrc { .. }
                | mcap::McapError::BadSummaryCrc { .. }),
            ) => {
                let outside = match (&e, skip) {
                    (_, true) => {
                        ": the damage is outside every chunk, which --skip-corrupt cannot \
                         pass over"
                    }
                    (mcap::McapError::BadChunkCrc { .. }, false) => {
                        "; --skip-corrupt passes over a damaged chunk"
                    }
                    _ => "",
                };
                return Err(records.bad(format!(
                    "the file is damaged: {e} (after {messages} messages, {bytes_read} bytes \
                     in){outside}"
                )));
            }
            Err(e) => {
                return Err(records.bad(format!(
                    "not a readable MCAP file: {} (after {messages} messages, {bytes_read} bytes \
                     in)",
                    super::failure::describe(&e),
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
            LinearReadEvent::Record { data, opcode } if skip && opcode == op::CHUNK => {
                let at = offset;
                offset += 9 + data.len() as u64;
                chunks += 1;
                let unpacked = match chunk::unpack(data, limit) {
                    Ok(unpacked) => unpacked,
                    Err(why) => {
                        records.skip_chunk(chunks, at, &why);
                        continue;
                    }
                };
                for record in chunk::Records::new(&unpacked) {
                    match record {
                        Ok((opcode, body)) => records.record(opcode, body, visit)?,
                        Err(why) => {
                            records.skip_chunk(chunks, at, &format!("{why}; the rest is lost"));
                            break;
                        }
                    }
                }
            }
            LinearReadEvent::Record { data, opcode } => {
                offset += 9 + data.len() as u64;
                records.record(opcode, data, visit)?;
            }
        }
    }
    Ok(records.end)
}

/// The records read so far, and what they defined.
struct Records<'p> {
    path: &'p Path,
    skip: bool,
    schemas: BTreeMap<u16, (String, String)>,
    channels: BTreeMap<u16, Arc<Channel>>,
    end: StreamEnd,
}

impl Records<'_> {
    fn bad(&self, reason: String) -> ImportError {
        ImportError::File {
            path: self.path.to_path_buf(),
            reason,
        }
    }

    /// Whether chunks were skipped, so that what they defined may be missing.
    fn lost_some(&self) -> bool {
        self.skip && !self.end.skipped_chunks.is_empty()
    }

    fn skip_chunk(&mut self, ordinal: u64, at: u64, why: &str) {
        self.end.skipped_chunks.push(format!(
            "chunk {ordinal} at byte {at} after {} messages: {why}",
            self.end.messages
        ));
    }

    /// Reads one record (from the file or from a chunk) and visits what it holds.
    fn record(
        &mut self,
        opcode: u8,
        data: &[u8],
        visit: &mut dyn FnMut(Event<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        let messages = self.end.messages;
        super::lengths::strings_fit(opcode, data).map_err(|why| {
            self.bad(format!(
                "record {opcode:#04x} after {messages} messages is damaged: {why}"
            ))
        })?;
        let record = mcap::parse_record(opcode, data).map_err(|e| {
            self.bad(format!(
                "record {opcode:#04x} after {messages} messages is damaged: {e}"
            ))
        })?;
        match record {
            Record::Schema { header, .. } => {
                self.schemas
                    .insert(header.id, (header.name, header.encoding));
            }
            Record::Channel(c) => {
                if self.channels.contains_key(&c.id) {
                    return Ok(());
                }
                let schema = match c.schema_id {
                    0 => String::new(),
                    id => match self.schemas.get(&id) {
                        Some((name, _)) => name.clone(),
                        // Its schema was in a skipped chunk: so are its messages, as
                        // far as this import can tell.
                        None if self.lost_some() => return Ok(()),
                        None => {
                            return Err(self.bad(format!(
                                "channel {} ({}) names schema {id}, which the file does not \
                                 define before it",
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
                self.channels.insert(channel.id, channel);
            }
            Record::Message { header, data } => {
                let Some(channel) = self.channels.get(&header.channel_id) else {
                    if self.lost_some() {
                        self.end.orphaned_messages += 1;
                        return Ok(());
                    }
                    return Err(self.bad(format!(
                        "message {messages} names channel {}, which the file does not define \
                         before it",
                        header.channel_id
                    )));
                };
                visit(Event::Message {
                    channel,
                    index: messages,
                    log_time_ns: header.log_time,
                    data: &data,
                })?;
                self.end.messages += 1;
            }
            Record::Metadata(m) => visit(Event::Metadata {
                name: &m.name,
                values: &m.metadata,
            })?,
            Record::Statistics(stats) if stats.message_count != messages => {
                if self.lost_some() {
                    self.end.summary_messages = Some(stats.message_count);
                } else {
                    return Err(self.bad(format!(
                        "the file is damaged: its statistics count {} messages but its \
                         chunks hold {messages}",
                        stats.message_count
                    )));
                }
            }
            _ => {}
        }
        Ok(())
    }
}
