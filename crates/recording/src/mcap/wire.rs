//! The two wire formats ROS messages travel in, read by one cursor:
//!
//! - **CDR** as ROS 2 writes it (XCDR1, "plain CDR"): a 4-byte encapsulation header
//!   (`00 01` little-endian or `00 00` big-endian, then two option bytes), then the fields
//!   in order, each primitive aligned to its own size counted from the end of the header.
//! - **ROS 1 serialization** (wiki.ros.org/msg, "Serialization"): little-endian fields in
//!   order with no header and no alignment.
//!
//! In both, strings and sequences are a `u32` count followed by the elements (CDR counts
//! a string's terminating NUL, ROS 1 has none) and fixed arrays have no count.
//!
//! Only what the messages of [`super::messages`] need. Every read is bounds-checked: a
//! count larger than the bytes left is an error, never an allocation.

/// A decoding error: what was being read and at which byte of the message.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("byte {offset}: {reason}")]
pub struct WireError {
    pub offset: usize,
    pub reason: String,
}

/// A cursor over one message in either wire format.
pub struct WireReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// CDR: alignment counts from byte 4 (after the header). ROS 1: no alignment.
    aligned: bool,
    little_endian: bool,
}

impl<'a> WireReader<'a> {
    /// A CDR message: reads the encapsulation header. Only plain CDR (`00 00` or `00 01`)
    /// is accepted: XCDR2 and parameter lists are used by other DDS types, not ROS 2
    /// messages.
    pub fn cdr(bytes: &'a [u8]) -> Result<Self, WireError> {
        let header: [u8; 4] = bytes
            .get(..4)
            .and_then(|h| h.try_into().ok())
            .ok_or_else(|| WireError {
                offset: 0,
                reason: format!(
                    "{} bytes are too short for a CDR encapsulation header",
                    bytes.len()
                ),
            })?;
        let little_endian = match header[..2] {
            [0, 1] => true,
            [0, 0] => false,
            _ => {
                return Err(WireError {
                    offset: 0,
                    reason: format!(
                        "encapsulation {:02x} {:02x} is not plain CDR (00 00 or 00 01)",
                        header[0], header[1]
                    ),
                });
            }
        };
        Ok(WireReader {
            bytes,
            pos: 4,
            aligned: true,
            little_endian,
        })
    }

    /// A ROS 1 message.
    pub fn ros1(bytes: &'a [u8]) -> Self {
        WireReader {
            bytes,
            pos: 0,
            aligned: false,
            little_endian: true,
        }
    }

    /// Whether the message is CDR (ROS 2) rather than ROS 1.
    pub fn is_cdr(&self) -> bool {
        self.aligned
    }

    /// The byte the next field starts at.
    pub fn position(&self) -> usize {
        self.pos
    }

    fn err<T>(&self, reason: impl Into<String>) -> Result<T, WireError> {
        Err(WireError {
            offset: self.pos,
            reason: reason.into(),
        })
    }

    fn align(&mut self, size: usize) -> Result<(), WireError> {
        if !self.aligned {
            return Ok(());
        }
        let rel = self.pos - 4;
        let pad = (size - rel % size) % size;
        if self.pos + pad > self.bytes.len() {
            return self.err("message ends inside alignment padding");
        }
        self.pos += pad;
        Ok(())
    }

    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], WireError> {
        self.align(N)?;
        let Some(slice) = self.bytes.get(self.pos..self.pos + N) else {
            return self.err(format!("message ends before its {what}"));
        };
        let mut raw: [u8; N] = slice.try_into().expect("slice of N bytes");
        if !self.little_endian {
            raw.reverse();
        }
        self.pos += N;
        Ok(raw)
    }

    /// A `u8` field; `what` names it in errors.
    pub fn u8(&mut self, what: &str) -> Result<u8, WireError> {
        Ok(self.take::<1>(what)?[0])
    }

    /// A `u32` field; `what` names it in errors.
    pub fn u32(&mut self, what: &str) -> Result<u32, WireError> {
        Ok(u32::from_le_bytes(self.take::<4>(what)?))
    }

    /// A `i32` field; `what` names it in errors.
    pub fn i32(&mut self, what: &str) -> Result<i32, WireError> {
        Ok(i32::from_le_bytes(self.take::<4>(what)?))
    }

    /// A `f32` field; `what` names it in errors.
    pub fn f32(&mut self, what: &str) -> Result<f32, WireError> {
        Ok(f32::from_le_bytes(self.take::<4>(what)?))
    }

    /// A `f64` field; `what` names it in errors.
    pub fn f64(&mut self, what: &str) -> Result<f64, WireError> {
        Ok(f64::from_le_bytes(self.take::<8>(what)?))
    }

    /// A sequence or array count, checked against the bytes left (each element at least
    /// `min_element_size` bytes).
    fn count(&mut self, what: &str, min_element_size: usize) -> Result<usize, WireError> {
        let n = self.u32(what)? as usize;
        let left = self.bytes.len() - self.pos;
        if n.saturating_mul(min_element_size) > left {
            return self.err(format!(
                "{what} claims {n} elements but only {left} bytes are left"
            ));
        }
        Ok(n)
    }

    /// A string (u32 length, the bytes); a closing NUL, which CDR counts in the length, is
    /// dropped in either format; UTF-8 checked.
    pub fn string(&mut self, what: &str) -> Result<String, WireError> {
        let n = self.count(what, 1)?;
        let start = self.pos;
        let raw = &self.bytes[start..start + n];
        let text = match raw.split_last() {
            Some((0, text)) => text,
            // Some writers omit the NUL; an empty string may be written as length 0.
            Some(_) => raw,
            None => &[],
        };
        self.pos += n;
        match std::str::from_utf8(text) {
            Ok(s) => Ok(s.to_string()),
            Err(_) => Err(WireError {
                offset: start,
                reason: format!("{what} is not UTF-8"),
            }),
        }
    }

    /// A `uint8[]` sequence, borrowed.
    pub fn bytes(&mut self, what: &str) -> Result<&'a [u8], WireError> {
        let n = self.count(what, 1)?;
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    /// A `float64[]` sequence.
    pub fn f64_seq(&mut self, what: &str) -> Result<Vec<f64>, WireError> {
        let n = self.count(what, 8)?;
        (0..n).map(|_| self.f64(what)).collect()
    }

    /// A fixed `float64[N]` array (no count on the wire).
    pub fn f64_array<const N: usize>(&mut self, what: &str) -> Result<[f64; N], WireError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }

    /// A sequence count of structs (each at least `min_element_size` bytes).
    pub fn seq_len(&mut self, what: &str, min_element_size: usize) -> Result<usize, WireError> {
        self.count(what, min_element_size)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_align_from_the_end_of_the_header() {
        // u8 1, then a u32 aligned to 4 (3 padding bytes), then a f64 aligned to 8.
        let mut msg = vec![0, 1, 0, 0, 7, 0, 0, 0];
        msg.extend(5u32.to_le_bytes());
        msg.extend(2.5f64.to_le_bytes());
        let mut r = WireReader::cdr(&msg).unwrap();
        assert_eq!(r.u8("a").unwrap(), 7);
        assert_eq!(r.u32("b").unwrap(), 5);
        assert_eq!(r.f64("c").unwrap(), 2.5);
    }

    #[test]
    fn big_endian_and_strings() {
        let mut msg = vec![0, 0, 0, 0];
        msg.extend(4u32.to_be_bytes());
        msg.extend(b"abc\0");
        msg.extend(9i32.to_be_bytes());
        let mut r = WireReader::cdr(&msg).unwrap();
        assert_eq!(r.string("s").unwrap(), "abc");
        assert_eq!(r.i32("i").unwrap(), 9);
    }

    #[test]
    fn counts_beyond_the_message_are_errors_not_allocations() {
        let mut msg = vec![0, 1, 0, 0];
        msg.extend(u32::MAX.to_le_bytes());
        let e = WireReader::cdr(&msg).unwrap().bytes("data").unwrap_err();
        assert_eq!(
            e.to_string(),
            "byte 8: data claims 4294967295 elements but only 0 bytes are left"
        );
        let mut r = WireReader::cdr(&[0, 1, 0, 0, 1]).unwrap();
        r.u8("is_bigendian").unwrap();
        let e = r.u32("step");
        assert_eq!(
            e.unwrap_err().to_string(),
            "byte 5: message ends inside alignment padding"
        );
        let e = WireReader::cdr(&[0, 1, 0, 0]).unwrap().u32("width");
        assert_eq!(
            e.unwrap_err().to_string(),
            "byte 4: message ends before its width"
        );
        assert!(WireReader::cdr(&[0, 2, 0, 0]).is_err());
        assert!(WireReader::cdr(&[0, 1]).is_err());
    }

    #[test]
    fn ros1_fields_are_packed_little_endian_without_a_header() {
        // u8 1, u32 5 right after it, a string without NUL, a f32.
        let mut msg = vec![1];
        msg.extend(5u32.to_le_bytes());
        msg.extend(3u32.to_le_bytes());
        msg.extend(b"abc");
        msg.extend(0.5f32.to_le_bytes());
        let mut r = WireReader::ros1(&msg);
        assert_eq!(r.u8("a").unwrap(), 1);
        assert_eq!(r.u32("b").unwrap(), 5);
        assert_eq!(r.string("s").unwrap(), "abc");
        assert_eq!(r.f32("f").unwrap(), 0.5);
        assert_eq!(r.position(), msg.len());
        let e = WireReader::ros1(&[1, 0]).u32("seq").unwrap_err();
        assert_eq!(e.to_string(), "byte 0: message ends before its seq");
    }
}
