//! ROS 1 bags (format 2.0, wiki.ros.org/Bags/Format/2.0), read in file order and handed
//! to the visitor as the same [`Event`]s an MCAP file gives, so that the scan, the topic
//! choice and the import serve both containers.
//!
//! A bag is a magic line and a sequence of records, each `u32` header length, header
//! fields (`u32` length, `name=value`), `u32` data length, data. The writers (rosbag,
//! Python's `rosbags`, librealsense) put connection and message records into chunks
//! (uncompressed, `bz2` or `lz4` frames), each followed by its index records; the index
//! section at the end repeats the connections and lists the chunks. Reading in file order
//! needs none of the index: a bag whose recorder was killed before writing it reads as far
//! as it goes.
//!
//! Every length is bounded before anything is allocated: a header by
//! [`MAX_HEADER_BYTES`], data by the bytes left in the file or chunk, a chunk's
//! uncompressed size by 64 times the file (as the MCAP reader does). A chunk that does not
//! decompress to its declared size, or whose records do not fit it, is damaged: the import
//! stops naming it, or with `--skip-corrupt` passes over it and says so.

use super::messages::MessageType;
use super::read::{Channel, Container, Event, ReadOptions, StreamEnd, record_limit};
use crate::error::ImportError;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;
use std::sync::Arc;

/// The first bytes of a ROS 1 bag, format 2.0.
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

/// The largest record header read. Headers hold a few short fields (the connection's
/// message definition is in its data, not its header); rosbag's own are under 200 bytes.
pub const MAX_HEADER_BYTES: u32 = 1 << 20;

/// Record op codes.
mod op {
    pub const MESSAGE_DATA: u8 = 0x02;
    pub const BAG_HEADER: u8 = 0x03;
    pub const INDEX_DATA: u8 = 0x04;
    pub const CHUNK: u8 = 0x05;
    pub const CHUNK_INFO: u8 = 0x06;
    pub const CONNECTION: u8 = 0x07;
}

/// A record's header fields, in order.
struct Fields<'a>(Vec<(&'a str, &'a [u8])>);

impl<'a> Fields<'a> {
    fn parse(header: &'a [u8]) -> Result<Fields<'a>, String> {
        let mut fields = Vec::new();
        let mut rest = header;
        while !rest.is_empty() {
            let Some((len, tail)) = rest.split_first_chunk::<4>() else {
                return Err(format!(
                    "its header ends inside a field length ({} bytes left)",
                    rest.len()
                ));
            };
            let len = u32::from_le_bytes(*len) as usize;
            if len > tail.len() {
                return Err(format!(
                    "a header field claims {len} bytes but {} are left",
                    tail.len()
                ));
            }
            let (field, tail) = tail.split_at(len);
            let eq = field
                .iter()
                .position(|&b| b == b'=')
                .ok_or("a header field has no `=`")?;
            let name = std::str::from_utf8(&field[..eq])
                .map_err(|_| "a header field's name is not UTF-8".to_string())?;
            fields.push((name, &field[eq + 1..]));
            rest = tail;
        }
        Ok(Fields(fields))
    }

    fn get(&self, name: &str) -> Result<&'a [u8], String> {
        self.0
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, v)| *v)
            .ok_or_else(|| format!("its header has no `{name}` field"))
    }

    fn bytes<const N: usize>(&self, name: &str) -> Result<[u8; N], String> {
        let v = self.get(name)?;
        v.try_into()
            .map_err(|_| format!("its `{name}` field has {} bytes, not {N}", v.len()))
    }

    fn op(&self) -> Result<u8, String> {
        Ok(self.bytes::<1>("op")?[0])
    }

    fn u32(&self, name: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.bytes(name)?))
    }

    fn text(&self, name: &str) -> Result<&'a str, String> {
        std::str::from_utf8(self.get(name)?).map_err(|_| format!("its `{name}` is not UTF-8"))
    }

    /// A ROS time field (`u32` seconds, `u32` nanoseconds) in nanoseconds.
    fn time_ns(&self, name: &str) -> Result<u64, String> {
        let raw: [u8; 8] = self.bytes(name)?;
        let sec = u32::from_le_bytes(raw[..4].try_into().expect("4 bytes"));
        let nsec = u32::from_le_bytes(raw[4..].try_into().expect("4 bytes"));
        if nsec >= 1_000_000_000 {
            return Err(format!(
                "its `{name}` has {nsec} nanoseconds, beyond a second"
            ));
        }
        Ok(sec as u64 * 1_000_000_000 + nsec as u64)
    }
}

/// One record split into its header fields and data, from a buffer.
fn split_record(buf: &[u8]) -> Result<(Fields<'_>, &[u8], usize), String> {
    let len = |at: usize, what: &str| -> Result<usize, String> {
        let raw = buf
            .get(at..at + 4)
            .ok_or_else(|| format!("it ends inside its {what} length"))?;
        Ok(u32::from_le_bytes(raw.try_into().expect("4 bytes")) as usize)
    };
    let header_len = len(0, "header")?;
    if header_len > buf.len() - 4 {
        return Err(format!(
            "its header claims {header_len} bytes but {} are left",
            buf.len() - 4
        ));
    }
    let header = &buf[4..4 + header_len];
    let data_at = 4 + header_len + 4;
    let data_len = len(4 + header_len, "data")?;
    if data_len > buf.len() - data_at {
        return Err(format!(
            "its data claims {data_len} bytes but {} are left",
            buf.len() - data_at
        ));
    }
    let fields = Fields::parse(header)?;
    Ok((
        fields,
        &buf[data_at..data_at + data_len],
        data_at + data_len,
    ))
}

/// Reads into `buf` until it is full or the file ends; the bytes read.
fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// Decompresses a chunk's data into at most `size` bytes. On failure, what came out
/// before it (a cut chunk's complete records are still good) and why.
fn decompress(compression: &str, data: &[u8], size: usize) -> (Vec<u8>, Option<String>) {
    let mut out = Vec::with_capacity(size);
    let result = match compression {
        "none" => {
            // More data than declared is reported below (as "more than"), not dropped.
            out.extend_from_slice(&data[..data.len().min(size + 1)]);
            Ok(())
        }
        // `take` keeps a chunk that decompresses to more than it declares from growing
        // past the bound; the length check below names it.
        "lz4" => lz4::Decoder::new(data)
            .and_then(|d| d.take(size as u64 + 1).read_to_end(&mut out).map(drop)),
        "bz2" => bzip2::read::BzDecoder::new(data)
            .take(size as u64 + 1)
            .read_to_end(&mut out)
            .map(drop),
        other => {
            return (
                Vec::new(),
                Some(format!(
                    "compression `{other}` is not one of a bag's (none, bz2, lz4)"
                )),
            );
        }
    };
    let why = match result {
        Err(e) => Some(format!("its {compression} data does not decompress: {e}")),
        Ok(()) if out.len() != size => Some(format!(
            "it decompresses to {}{} bytes, its header says {size}",
            if out.len() > size { "more than " } else { "" },
            out.len().min(size)
        )),
        Ok(()) => None,
    };
    out.truncate(size);
    (out, why)
}

/// Why a record could not be read: the bag's damage, or the visitor's own error (a
/// message that does not decode), which passes through untouched.
enum Failure {
    Damaged(String),
    Visit(ImportError),
}

impl From<String> for Failure {
    fn from(why: String) -> Self {
        Failure::Damaged(why)
    }
}

/// The connections and messages read so far.
struct Bag<'p> {
    path: &'p Path,
    skip: bool,
    /// By the bag's connection id; channel ids are given in order of appearance.
    channels: BTreeMap<u32, Arc<Channel>>,
    end: StreamEnd,
}

impl Bag<'_> {
    fn bad(&self, reason: String) -> ImportError {
        ImportError::File {
            path: self.path.to_path_buf(),
            reason,
        }
    }

    /// Visits a connection or message record; the others say nothing a reader in file
    /// order needs.
    fn record(
        &mut self,
        fields: &Fields,
        data: &[u8],
        visit: &mut dyn FnMut(Event<'_>) -> Result<(), ImportError>,
    ) -> Result<(), Failure> {
        match fields.op()? {
            op::CONNECTION => {
                let conn = fields.u32("conn")?;
                if self.channels.contains_key(&conn) {
                    return Ok(());
                }
                let topic = fields.text("topic")?.to_string();
                let described =
                    Fields::parse(data).map_err(|e| format!("connection {conn} ({topic}): {e}"))?;
                let schema = described
                    .text("type")
                    .map_err(|e| format!("connection {conn} ({topic}): {e}"))?
                    .to_string();
                let id = u16::try_from(self.channels.len())
                    .map_err(|_| "the bag has more than 65536 connections".to_string())?;
                let channel = Arc::new(Channel {
                    id,
                    ty: MessageType::of(&schema, "ros1"),
                    topic,
                    schema,
                    message_encoding: "ros1".into(),
                });
                visit(Event::Channel(&channel)).map_err(Failure::Visit)?;
                self.channels.insert(conn, channel);
            }
            op::MESSAGE_DATA => {
                let conn = fields.u32("conn")?;
                let log_time_ns = fields.time_ns("time")?;
                let messages = self.end.messages;
                let Some(channel) = self.channels.get(&conn) else {
                    if self.skip && !self.end.skipped_chunks.is_empty() {
                        self.end.orphaned_messages += 1;
                        return Ok(());
                    }
                    return Err(Failure::Damaged(format!(
                        "message {messages} names connection {conn}, which the bag does not \
                         define before it"
                    )));
                };
                visit(Event::Message {
                    channel,
                    index: messages,
                    log_time_ns,
                    data,
                })
                .map_err(Failure::Visit)?;
                self.end.messages += 1;
            }
            op::BAG_HEADER | op::INDEX_DATA | op::CHUNK_INFO => {}
            other => return Err(format!("op {other:#04x} is not a bag record's").into()),
        }
        Ok(())
    }

    /// Visits the records of one decompressed chunk (or as much of a cut chunk as
    /// `data` holds, when `cut`).
    fn chunk(
        &mut self,
        data: &[u8],
        cut: bool,
        visit: &mut dyn FnMut(Event<'_>) -> Result<(), ImportError>,
    ) -> Result<(), Failure> {
        let mut at = 0;
        while at < data.len() {
            let (fields, body, len) = match split_record(&data[at..]) {
                Ok(r) => r,
                Err(_) if cut => return Ok(()),
                Err(e) => {
                    return Err(format!("the record at byte {at} of the chunk: {e}").into());
                }
            };
            self.record(&fields, body, visit).map_err(|f| match f {
                Failure::Damaged(e) => {
                    Failure::Damaged(format!("the record at byte {at} of the chunk: {e}"))
                }
                visit => visit,
            })?;
            at += len;
        }
        Ok(())
    }
}

/// Calls `visit` for every connection and message of the bag `path` (opened as `file`,
/// just past its magic, which the caller has checked), in file order.
pub(super) fn stream(
    path: &Path,
    file: File,
    file_len: u64,
    options: ReadOptions,
    visit: &mut dyn FnMut(Event<'_>) -> Result<(), ImportError>,
) -> Result<StreamEnd, ImportError> {
    let io = |source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let limit = record_limit(file_len);
    let mut bag = Bag {
        path,
        skip: options.skip_corrupt,
        channels: BTreeMap::new(),
        end: StreamEnd {
            container: Container::RosBag,
            ..StreamEnd::default()
        },
    };
    let mut r = BufReader::with_capacity(1 << 20, file);
    let mut offset = MAGIC.len() as u64;
    let mut chunks = 0u64;
    let mut buf = Vec::new();
    loop {
        let at = offset;
        let messages = bag.end.messages;
        // The file ends inside this record: a recorder stopped before closing the bag.
        let cut = |bag: &mut Bag, what: &str| -> Result<(), ImportError> {
            // Counted now: a cut chunk may have given messages before its cut.
            if bag.end.messages == 0 {
                return Err(bag.bad(format!(
                    "the file ends inside {what} at byte {at}, before any message"
                )));
            }
            bag.end.truncated = Some(format!(
                "the file ends inside {what} at byte {at} after {} messages: a recorder \
                 stopped before closing it? What precedes was read",
                bag.end.messages
            ));
            Ok(())
        };
        let mut len = [0u8; 4];
        match read_up_to(&mut r, &mut len).map_err(io)? {
            0 => break,
            4 => {}
            _ => {
                cut(&mut bag, "a record's header length")?;
                break;
            }
        }
        let header_len = u32::from_le_bytes(len);
        if header_len > MAX_HEADER_BYTES {
            return Err(bag.bad(format!(
                "the record at byte {at} after {messages} messages is damaged: its header \
                 claims {header_len} bytes, more than a bag record's {MAX_HEADER_BYTES}"
            )));
        }
        // A header (and the data length after it) running past the end of the file is a
        // cut, as a killed recorder leaves it.
        let left_after_length = file_len.saturating_sub(offset + 4);
        if header_len as u64 + 4 > left_after_length {
            cut(&mut bag, "a record's header")?;
            break;
        }
        let mut header = vec![0u8; header_len as usize];
        let mut data_len_bytes = [0u8; 4];
        if read_up_to(&mut r, &mut header).map_err(io)? != header.len()
            || read_up_to(&mut r, &mut data_len_bytes).map_err(io)? != 4
        {
            return Err(bag.bad(format!(
                "the file changed while it was read (record at byte {at})"
            )));
        }
        let damaged = |bag: &Bag, e: String| {
            bag.bad(format!(
                "the record at byte {at} after {messages} messages is damaged: {e}"
            ))
        };
        let fields = Fields::parse(&header).map_err(|e| damaged(&bag, e))?;
        let op = fields.op().map_err(|e| damaged(&bag, e))?;
        let data_len = u32::from_le_bytes(data_len_bytes) as u64;
        offset += 8 + header_len as u64;
        let left = file_len.saturating_sub(offset);
        // Data cut by the file's end is read as far as it goes, for a chunk's sake.
        let whole = data_len <= left;
        if !whole && op != op::CHUNK {
            cut(&mut bag, &format!("record {op:#04x}"))?;
            break;
        }
        buf.resize(data_len.min(left) as usize, 0);
        let got = read_up_to(&mut r, &mut buf).map_err(io)?;
        if got != buf.len() {
            return Err(bag.bad(format!(
                "the file changed while it was read (record at byte {at})"
            )));
        }
        offset += got as u64;
        if op != op::CHUNK {
            match bag.record(&fields, &buf, visit) {
                Ok(()) => continue,
                Err(Failure::Damaged(e)) => return Err(damaged(&bag, e)),
                Err(Failure::Visit(e)) => return Err(e),
            }
        }
        chunks += 1;
        let (compression, size) = match (fields.text("compression"), fields.u32("size")) {
            (Ok(c), Ok(s)) => (c.to_string(), s as usize),
            (Err(e), _) | (_, Err(e)) => return Err(damaged(&bag, e)),
        };
        let place = format!("chunk {chunks} at byte {at} after {messages} messages");
        if size > limit {
            let why = format!(
                "it declares {size} bytes uncompressed, more than this file's limit of \
                 {limit} (64 times its size)"
            );
            if bag.skip {
                bag.end.skipped_chunks.push(format!("{place}: {why}"));
                continue;
            }
            return Err(bag.bad(format!("{place} is damaged: {why}")));
        }
        let (unpacked, why) = decompress(&compression, &buf, size);
        if !whole {
            // What the cut chunk's complete records hold is kept.
            match bag.chunk(&unpacked, true, visit) {
                Ok(()) => {}
                Err(Failure::Damaged(e)) => return Err(bag.bad(format!("{place}: {e}"))),
                Err(Failure::Visit(e)) => return Err(e),
            }
            cut(&mut bag, &format!("chunk {chunks}"))?;
            break;
        }
        let result = match (why, bag.skip) {
            (None, _) => bag.chunk(&unpacked, false, visit),
            // Passing over a damaged chunk keeps the complete records that came out of
            // it before the damage.
            (Some(why), true) => bag
                .chunk(&unpacked, true, visit)
                .and(Err(Failure::Damaged(why))),
            (Some(why), false) => Err(Failure::Damaged(why)),
        };
        if let Err(failure) = result {
            let why = match failure {
                Failure::Damaged(why) => why,
                Failure::Visit(e) => return Err(e),
            };
            if bag.skip {
                // Messages the chunk gave before its damage have been visited.
                let read = match bag.end.messages - messages {
                    0 => String::new(),
                    n => format!(" (its first {n} messages were read)"),
                };
                bag.end.skipped_chunks.push(format!("{place}: {why}{read}"));
                continue;
            }
            return Err(bag.bad(format!(
                "{place} is damaged: {why}; --skip-corrupt passes over a damaged chunk"
            )));
        }
    }
    Ok(bag.end)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(name: &str, value: &[u8]) -> Vec<u8> {
        let mut out = ((name.len() + 1 + value.len()) as u32)
            .to_le_bytes()
            .to_vec();
        out.extend(name.as_bytes());
        out.push(b'=');
        out.extend(value);
        out
    }

    fn record(fields: &[Vec<u8>], data: &[u8]) -> Vec<u8> {
        let header: Vec<u8> = fields.concat();
        let mut out = (header.len() as u32).to_le_bytes().to_vec();
        out.extend(header);
        out.extend((data.len() as u32).to_le_bytes());
        out.extend(data);
        out
    }

    #[test]
    fn header_fields_split_at_the_first_equals_sign() {
        let header = [field("op", &[7]), field("topic", b"/a=b")].concat();
        let fields = Fields::parse(&header).unwrap();
        assert_eq!(fields.op().unwrap(), 7);
        assert_eq!(fields.text("topic").unwrap(), "/a=b");
        assert_eq!(
            fields.u32("conn").unwrap_err(),
            "its header has no `conn` field"
        );
        let mut bad = field("op", &[7]);
        bad[0] = 200;
        assert_eq!(
            Fields::parse(&bad).err().unwrap(),
            "a header field claims 200 bytes but 4 are left"
        );
    }

    #[test]
    fn records_longer_than_their_buffer_are_refused() {
        let rec = record(&[field("op", &[2])], b"abcd");
        let (fields, data, len) = split_record(&rec).unwrap();
        assert_eq!(
            (fields.op().unwrap(), data, len),
            (2, &b"abcd"[..], rec.len())
        );
        let cut = &rec[..rec.len() - 1];
        assert_eq!(
            split_record(cut).err().unwrap(),
            "its data claims 4 bytes but 3 are left"
        );
    }

    #[test]
    fn chunks_decompress_to_their_declared_size_or_are_damaged() {
        let data = b"records records records".repeat(20);
        let mut lz4 = Vec::new();
        {
            let mut enc = lz4::EncoderBuilder::new().build(&mut lz4).unwrap();
            std::io::Write::write_all(&mut enc, &data).unwrap();
            enc.finish().1.unwrap();
        }
        assert_eq!(decompress("lz4", &lz4, data.len()), (data.clone(), None));
        let (short, why) = decompress("lz4", &lz4, data.len() - 1);
        assert_eq!(short.len(), data.len() - 1);
        assert_eq!(
            why.unwrap(),
            format!(
                "it decompresses to more than {} bytes, its header says {}",
                data.len() - 1,
                data.len() - 1
            )
        );
        let (_, why) = decompress("lz4", &lz4[..lz4.len() / 2], data.len());
        assert!(why.is_some(), "a cut lz4 frame passed");
        let (_, why) = decompress("zstd", &lz4, 10);
        assert_eq!(
            why.unwrap(),
            "compression `zstd` is not one of a bag's (none, bz2, lz4)"
        );
    }
}
