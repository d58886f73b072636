//! A chunk opened whole before any of its records is read, for `--skip-corrupt`.
//!
//! The `mcap` crate checks a chunk's CRC at the chunk's end, after it has handed out the
//! chunk's records, and cannot go on after a bad one. To pass over a damaged chunk
//! instead, [`unpack`] decompresses the chunk record's body into memory, checks its size
//! and CRC (MCAP specification, "Chunk" op 0x06: `uncompressed_size`,
//! `uncompressed_crc`, where 0 means the writer computed none), and only then are its
//! records walked ([`Records`]), each bounded by the chunk as the reader bounds records
//! by the file. A chunk that fails is the caller's to skip: its record's own length
//! still says where the next record starts.

use super::lengths;
use mcap::records::{Record, op};
use std::io::Read;

/// The records of a chunk, decompressed and checked against the chunk's size and CRC,
/// or why the chunk is damaged. `body` is the chunk record without its opcode and
/// length; `limit` bounds the decompressed size (the reader's record limit).
pub(super) fn unpack(body: &[u8], limit: usize) -> Result<Vec<u8>, String> {
    lengths::strings_fit(op::CHUNK, body)?;
    let (header, compressed) = match mcap::parse_record(op::CHUNK, body) {
        Ok(Record::Chunk { header, data }) => (header, data),
        Ok(_) => unreachable!("a chunk's opcode parses as a chunk"),
        Err(e) => return Err(e.to_string()),
    };
    let size = header.uncompressed_size;
    let size = usize::try_from(size)
        .ok()
        .filter(|&s| s <= limit)
        .ok_or_else(|| {
            format!("it says it holds {size} bytes, over the {limit} bytes this file's size allows")
        })?;
    let records = match header.compression.as_str() {
        "" => compressed.to_vec(),
        "zstd" => zstd::bulk::decompress(&compressed, size)
            .map_err(|e| format!("its zstd data does not decompress: {e}"))?,
        "lz4" => {
            let mut out = Vec::new();
            lz4::Decoder::new(&compressed[..])
                .and_then(|d| d.take(size as u64 + 1).read_to_end(&mut out))
                .map_err(|e| format!("its lz4 data does not decompress: {e}"))?;
            out
        }
        other => {
            return Err(format!(
                "its compression {other:?} is none of \"\", \"zstd\" and \"lz4\""
            ));
        }
    };
    if records.len() != size {
        return Err(format!(
            "it holds {} bytes of records, not the {size} its header says",
            records.len()
        ));
    }
    let crc = crc32fast::hash(&records);
    if header.uncompressed_crc != 0 && crc != header.uncompressed_crc {
        return Err(format!(
            "its CRC is {:#010x}, but its records' is {crc:#010x}",
            header.uncompressed_crc
        ));
    }
    Ok(records)
}

/// The records of an unpacked chunk: `(opcode, body)`, or why the next one does not fit.
pub(super) struct Records<'a> {
    rest: &'a [u8],
}

impl<'a> Records<'a> {
    pub(super) fn new(records: &'a [u8]) -> Self {
        Records { rest: records }
    }
}

impl<'a> Iterator for Records<'a> {
    type Item = Result<(u8, &'a [u8]), String>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.rest.is_empty() {
            return None;
        }
        let Some((head, after)) = self.rest.split_first_chunk::<9>() else {
            let left = self.rest.len();
            self.rest = &[];
            return Some(Err(format!(
                "its last {left} bytes are too few for a record's opcode and length"
            )));
        };
        let opcode = head[0];
        let len = u64::from_le_bytes(head[1..].try_into().expect("8 bytes"));
        match usize::try_from(len).ok().filter(|&l| l <= after.len()) {
            Some(len) => {
                let (body, rest) = after.split_at(len);
                self.rest = rest;
                Some(Ok((opcode, body)))
            }
            None => {
                self.rest = &[];
                Some(Err(format!(
                    "a record {opcode:#04x} in it says it is {len} bytes long, but only {} \
                     bytes of the chunk follow",
                    after.len()
                )))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk record's body holding `records`, compressed as `compression` says.
    fn chunk(records: &[u8], compression: &str, crc: u32) -> Vec<u8> {
        let data = match compression {
            "" => records.to_vec(),
            "zstd" => zstd::bulk::compress(records, 0).unwrap(),
            _ => records.to_vec(),
        };
        let mut body = Vec::new();
        body.extend(0u64.to_le_bytes());
        body.extend(0u64.to_le_bytes());
        body.extend((records.len() as u64).to_le_bytes());
        body.extend(crc.to_le_bytes());
        body.extend((compression.len() as u32).to_le_bytes());
        body.extend(compression.as_bytes());
        body.extend((data.len() as u64).to_le_bytes());
        body.extend(data);
        body
    }

    fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
        let mut r = vec![opcode];
        r.extend((body.len() as u64).to_le_bytes());
        r.extend(body);
        r
    }

    #[test]
    fn a_chunk_whose_crc_matches_gives_its_records() {
        let records = [record(0x05, b"abc"), record(0x80, b"")].concat();
        for compression in ["", "zstd"] {
            let body = chunk(&records, compression, crc32fast::hash(&records));
            let got = unpack(&body, 1 << 20).unwrap();
            assert_eq!(got, records);
            let walked: Vec<_> = Records::new(&got).map(Result::unwrap).collect();
            assert_eq!(walked, vec![(0x05, &b"abc"[..]), (0x80, &b""[..])]);
        }
        // A CRC of 0 is a writer that computed none: nothing to check.
        assert_eq!(unpack(&chunk(&records, "", 0), 1 << 20).unwrap(), records);
    }

    #[test]
    fn a_damaged_chunk_says_why() {
        let records = record(0x05, b"abcdef");
        let crc = crc32fast::hash(&records);
        let mut flipped = chunk(&records, "", crc);
        let last = flipped.len() - 1;
        flipped[last] ^= 1;
        let why = unpack(&flipped, 1 << 20).unwrap_err();
        assert!(why.starts_with("its CRC is "), "{why}");
        let mut zstd = chunk(&records, "zstd", crc);
        let last = zstd.len() - 3;
        zstd[last] ^= 0xFF;
        let why = unpack(&zstd, 1 << 20).unwrap_err();
        assert!(
            why.starts_with("its zstd data does not decompress") || why.starts_with("its CRC"),
            "{why}"
        );
        let why = unpack(&chunk(&records, "", crc), 4).unwrap_err();
        assert_eq!(
            why,
            "it says it holds 15 bytes, over the 4 bytes this file's size allows"
        );
        let why = unpack(&chunk(&records, "brotli", crc), 1 << 20).unwrap_err();
        assert_eq!(
            why,
            "its compression \"brotli\" is none of \"\", \"zstd\" and \"lz4\""
        );
    }

    #[test]
    fn a_record_running_past_its_chunk_is_an_error_not_a_slice_panic() {
        let mut records = record(0x05, b"abcdef");
        records.truncate(records.len() - 2);
        let got: Vec<_> = Records::new(&records).collect();
        assert_eq!(
            got,
            vec![Err(
                "a record 0x05 in it says it is 6 bytes long, but only 4 bytes of the chunk \
                 follow"
                    .to_string()
            )]
        );
        let got: Vec<_> = Records::new(&[0x05, 1, 2]).collect();
        assert_eq!(
            got,
            vec![Err(
                "its last 3 bytes are too few for a record's opcode and length".to_string()
            )]
        );
    }
}
