//! The length prefixes inside an MCAP record, checked before the `mcap` crate parses it.
//!
//! The crate reads a string by reserving its declared length, then reading: a record of
//! a few bytes whose topic says it is 3 GB long takes 3 GB before the read fails (found
//! by `fuzz/fuzz_targets/mcap.rs`). Here every string of the records that hold strings
//! must fit in what is left of the record's body. Maps and arrays are read element by
//! element, without a reservation, so only the strings inside them are checked. An
//! attachment must also hold its data length and CRC, which the crate slices between.
//! The reader parses a top-level chunk's header itself and bounds its compression
//! string; a chunk nested in a chunk is checked here. Layouts: the MCAP specification,
//! "Records".

use mcap::records::op;

/// Why a field of record `opcode` says it is longer than the rest of `body` (or does not
/// fit in it), if one does.
pub fn strings_fit(opcode: u8, body: &[u8]) -> Result<(), String> {
    let mut r = Fields { body, at: 0 };
    match opcode {
        op::HEADER => {
            r.string("profile")?;
            r.string("library")?;
        }
        op::SCHEMA => {
            r.skip(2)?;
            r.string("name")?;
            r.string("encoding")?;
        }
        op::CHANNEL => {
            r.skip(4)?;
            r.string("topic")?;
            r.string("message encoding")?;
            r.string_map("metadata")?;
        }
        // The reader parses a top-level chunk's header itself, but a chunk inside a
        // chunk reaches us as a record (a fuzz finding).
        op::CHUNK => {
            r.skip(8 + 8 + 8 + 4)?;
            r.string("compression")?;
        }
        op::CHUNK_INDEX => {
            r.skip(8 + 8 + 8 + 8)?;
            let offsets = r.u32()? as usize;
            r.skip(offsets)?;
            r.skip(8)?;
            r.string("compression")?;
        }
        op::ATTACHMENT => {
            r.skip(8 + 8)?;
            r.string("name")?;
            r.string("media type")?;
            // The crate slices the data as `body[after the length..len - 4]`, which
            // panics when the length and the CRC do not both fit (a fuzz finding).
            if r.left() < 8 + 4 {
                return Err(format!(
                    "its data length and CRC take 12 bytes, but only {} bytes of the record \
                     follow its name and media type",
                    r.left()
                ));
            }
        }
        op::ATTACHMENT_INDEX => {
            r.skip(8 * 5)?;
            r.string("name")?;
            r.string("media type")?;
        }
        op::METADATA => {
            r.string("name")?;
            r.string_map("metadata")?;
        }
        op::METADATA_INDEX => {
            r.skip(8 + 8)?;
            r.string("name")?;
        }
        _ => {}
    }
    Ok(())
}

/// A cursor over a record's body. A field cut short by the body's end is left for the
/// crate to report; only a length that would be allocated is refused here.
struct Fields<'a> {
    body: &'a [u8],
    at: usize,
}

impl Fields<'_> {
    fn left(&self) -> usize {
        self.body.len().saturating_sub(self.at)
    }

    /// Moves past `n` bytes; `Ok` but at the end when fewer are left.
    fn skip(&mut self, n: usize) -> Result<(), String> {
        self.at = self.at.saturating_add(n).min(self.body.len());
        Ok(())
    }

    fn u32(&mut self) -> Result<u32, String> {
        let Some(bytes) = self.body.get(self.at..self.at + 4) else {
            self.at = self.body.len();
            return Ok(0);
        };
        self.at += 4;
        Ok(u32::from_le_bytes(bytes.try_into().expect("four bytes")))
    }

    fn string(&mut self, what: &str) -> Result<(), String> {
        let len = self.u32()?;
        if len as usize > self.left() {
            return Err(format!(
                "its {what} says it is {len} bytes long, but only {} bytes of the record follow",
                self.left()
            ));
        }
        self.skip(len as usize)
    }

    fn string_map(&mut self, what: &str) -> Result<(), String> {
        let len = self.u32()? as usize;
        let end = self.at.saturating_add(len).min(self.body.len());
        while self.at < end {
            self.string(&format!("{what} key"))?;
            self.string(&format!("{what} value"))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn string(s: &str) -> Vec<u8> {
        let mut out = (s.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(s.as_bytes());
        out
    }

    fn channel(topic_len: u32, map: &[u8]) -> Vec<u8> {
        let mut body = vec![1, 0, 0, 0];
        body.extend_from_slice(&topic_len.to_le_bytes());
        body.extend_from_slice(b"/cam");
        body.extend(string("cdr"));
        body.extend_from_slice(&(map.len() as u32).to_le_bytes());
        body.extend_from_slice(map);
        body
    }

    #[test]
    fn a_string_longer_than_its_record_is_refused_before_it_is_allocated() {
        let mut map = string("k");
        map.extend(string("v"));
        assert_eq!(strings_fit(op::CHANNEL, &channel(4, &map)), Ok(()));
        assert_eq!(
            strings_fit(op::CHANNEL, &channel(3_086_843_275, &map)),
            Err(
                "its topic says it is 3086843275 bytes long, but only 25 bytes of the record \
                 follow"
                    .into()
            )
        );
        let mut long_value = string("k");
        long_value.extend_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(
            strings_fit(op::CHANNEL, &channel(4, &long_value)),
            Err(
                "its metadata value says it is 4294967295 bytes long, but only 0 bytes of the \
                 record follow"
                    .into()
            )
        );
        let mut metadata = string("calibration");
        metadata.extend_from_slice(&[0xFF, 0xFF, 0xFF, 0x7F]);
        assert_eq!(
            strings_fit(op::METADATA, &metadata),
            Ok(()),
            "a map's byte length is not allocated; the crate reports it as cut short"
        );
        assert_eq!(strings_fit(op::MESSAGE, &[0xFF; 8]), Ok(()));
        // A body cut short is the crate's to report.
        assert_eq!(strings_fit(op::HEADER, &[4, 0]), Ok(()));
        // An attachment must hold its data length and CRC after its strings: the crate
        // slices between them and panics otherwise.
        let mut attachment = vec![0; 16];
        attachment.extend(string("a.png"));
        attachment.extend(string("image/png"));
        assert_eq!(
            strings_fit(op::ATTACHMENT, &[&attachment[..], &[0; 11]].concat()),
            Err(
                "its data length and CRC take 12 bytes, but only 11 bytes of the record \
                 follow its name and media type"
                    .into()
            )
        );
        assert_eq!(
            strings_fit(op::ATTACHMENT, &[&attachment[..], &[0; 12]].concat()),
            Ok(())
        );
    }
}
