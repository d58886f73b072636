//! EBML, the binary layout under Matroska (RFC 8794): every element is an ID, a size and
//! its data, each ID and size a variable-length integer whose leading zero bits give its
//! length. A size of all ones is "unknown" (a live recorder's Segment or Cluster that was
//! never closed). Every read here is bounded by the file's length and by a limit the
//! caller names, before anything is allocated.

use std::io::{BufRead, Seek, SeekFrom};

/// Why an element could not be read.
#[derive(Debug)]
pub enum EbmlError {
    Io(std::io::Error),
    /// The file ends inside the element that starts at `at`: a recorder stopped before
    /// closing the file.
    Cut {
        at: u64,
        what: String,
    },
    /// The bytes at `at` are not what the layout allows.
    Damaged {
        at: u64,
        reason: String,
    },
}

impl From<std::io::Error> for EbmlError {
    fn from(e: std::io::Error) -> Self {
        EbmlError::Io(e)
    }
}

/// One element's header: its ID, where it starts, where its data starts and how long
/// that is (`None`: unknown, up to the end of its parent).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Element {
    pub id: u32,
    pub start: u64,
    pub data: u64,
    pub size: Option<u64>,
}

impl Element {
    /// Where its data ends (`parent_end` for an unknown size).
    pub fn end(&self, parent_end: u64) -> u64 {
        self.size.map_or(parent_end, |s| self.data + s)
    }
}

/// A reader of elements over a seekable file of known length.
pub struct EbmlReader<R> {
    inner: R,
    pos: u64,
    len: u64,
}

impl<R: BufRead + Seek> EbmlReader<R> {
    pub fn new(inner: R, len: u64) -> Self {
        EbmlReader { inner, pos: 0, len }
    }

    /// The file's length in bytes.
    pub fn file_len(&self) -> u64 {
        self.len
    }

    /// Where the next read starts.
    pub fn position(&self) -> u64 {
        self.pos
    }

    /// Moves to byte `pos` (a short forward move keeps the buffer).
    pub fn seek_to(&mut self, pos: u64) -> Result<(), EbmlError> {
        if pos != self.pos {
            let delta = pos as i128 - self.pos as i128;
            if (0..=1 << 16).contains(&delta) {
                self.inner.seek_relative(delta as i64)?;
            } else {
                self.inner.seek(SeekFrom::Start(pos))?;
            }
            self.pos = pos;
        }
        Ok(())
    }

    fn byte(&mut self, what: &str, at: u64) -> Result<u8, EbmlError> {
        let mut b = [0u8];
        if self.pos >= self.len {
            return Err(EbmlError::Cut {
                at,
                what: what.to_string(),
            });
        }
        self.inner.read_exact(&mut b).map_err(|e| match e.kind() {
            std::io::ErrorKind::UnexpectedEof => EbmlError::Cut {
                at,
                what: what.to_string(),
            },
            _ => EbmlError::Io(e),
        })?;
        self.pos += 1;
        Ok(b[0])
    }

    /// The element header at the current position, or `None` exactly at `end` (or at the
    /// end of the file).
    pub fn next(&mut self, end: u64) -> Result<Option<Element>, EbmlError> {
        let start = self.pos;
        if start >= end.min(self.len) {
            return Ok(None);
        }
        let first = self.byte("an element ID", start)?;
        let id_len = first.leading_zeros() as usize + 1;
        if id_len > 4 {
            return Err(EbmlError::Damaged {
                at: start,
                reason: format!("byte {first:#04x} starts no element ID"),
            });
        }
        let mut id = first as u32;
        for _ in 1..id_len {
            id = id << 8 | self.byte("an element ID", start)? as u32;
        }
        let first = self.byte("an element size", start)?;
        let size_len = first.leading_zeros() as usize + 1;
        if size_len > 8 {
            return Err(EbmlError::Damaged {
                at: start,
                reason: format!("element {id:#x} has a size that starts with byte 0"),
            });
        }
        let mut size = (first as u64) & (0xff >> size_len);
        let mut all_ones = size == 0xff >> size_len;
        for _ in 1..size_len {
            let b = self.byte("an element size", start)?;
            all_ones &= b == 0xff;
            size = size << 8 | b as u64;
        }
        let data = self.pos;
        let size = (!all_ones).then_some(size);
        if let Some(size) = size
            && data.checked_add(size).is_none()
        {
            return Err(EbmlError::Damaged {
                at: start,
                reason: format!("element {id:#x} claims {size} bytes"),
            });
        }
        Ok(Some(Element {
            id,
            start,
            data,
            size,
        }))
    }

    /// The data of `element`, at most `max` bytes (more is damage, naming `what`).
    pub fn bytes(&mut self, element: &Element, max: u64, what: &str) -> Result<Vec<u8>, EbmlError> {
        let size = element.size.ok_or_else(|| EbmlError::Damaged {
            at: element.start,
            reason: format!("{what} has an unknown size"),
        })?;
        if size > max {
            return Err(EbmlError::Damaged {
                at: element.start,
                reason: format!("{what} claims {size} bytes, more than its {max}"),
            });
        }
        self.read_at(element.data, size, element.start, what)
    }

    /// `size` bytes from `pos` (bounded by the caller), or a cut naming `what` at `at`.
    pub fn read_at(
        &mut self,
        pos: u64,
        size: u64,
        at: u64,
        what: &str,
    ) -> Result<Vec<u8>, EbmlError> {
        if pos.saturating_add(size) > self.len {
            return Err(EbmlError::Cut {
                at,
                what: what.to_string(),
            });
        }
        self.seek_to(pos)?;
        let mut out = vec![0u8; size as usize];
        self.inner.read_exact(&mut out)?;
        self.pos += size;
        Ok(out)
    }

    /// An unsigned integer element (0 to 8 bytes, big-endian).
    pub fn uint(&mut self, element: &Element, what: &str) -> Result<u64, EbmlError> {
        let bytes = self.bytes(element, 8, what)?;
        Ok(bytes.iter().fold(0u64, |v, &b| v << 8 | b as u64))
    }

    /// A signed integer element.
    pub fn int(&mut self, element: &Element, what: &str) -> Result<i64, EbmlError> {
        let bytes = self.bytes(element, 8, what)?;
        let unsigned = bytes.iter().fold(0u64, |v, &b| v << 8 | b as u64);
        let bits = 8 * bytes.len() as u32;
        Ok(match bits {
            0 => 0,
            64 => unsigned as i64,
            _ => ((unsigned << (64 - bits)) as i64) >> (64 - bits),
        })
    }

    /// A float element (0, 4 or 8 bytes).
    pub fn float(&mut self, element: &Element, what: &str) -> Result<f64, EbmlError> {
        let bytes = self.bytes(element, 8, what)?;
        match bytes.len() {
            0 => Ok(0.0),
            4 => Ok(f32::from_be_bytes(bytes.try_into().expect("4 bytes")) as f64),
            8 => Ok(f64::from_be_bytes(bytes.try_into().expect("8 bytes"))),
            n => Err(EbmlError::Damaged {
                at: element.start,
                reason: format!("{what} is a float of {n} bytes (4 or 8)"),
            }),
        }
    }

    /// A string element (ASCII or UTF-8, zero padding dropped), at most 64 KiB.
    pub fn string(&mut self, element: &Element, what: &str) -> Result<String, EbmlError> {
        let mut bytes = self.bytes(element, 1 << 16, what)?;
        if let Some(nul) = bytes.iter().position(|&b| b == 0) {
            bytes.truncate(nul);
        }
        String::from_utf8(bytes).map_err(|_| EbmlError::Damaged {
            at: element.start,
            reason: format!("{what} is not UTF-8"),
        })
    }
}

/// A variable-length integer at the start of `bytes` (a block's track number or an EBML
/// lace size): its value and length, or `None` if `bytes` is too short or it is longer
/// than 8 bytes.
pub fn vint(bytes: &[u8]) -> Option<(u64, usize)> {
    let first = *bytes.first()?;
    let len = first.leading_zeros() as usize + 1;
    if len > 8 || bytes.len() < len {
        return None;
    }
    let mut value = (first as u64) & (0xff >> len);
    for &b in &bytes[1..len] {
        value = value << 8 | b as u64;
    }
    Some((value, len))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{BufReader, Cursor};

    fn reader(bytes: &[u8]) -> EbmlReader<BufReader<Cursor<Vec<u8>>>> {
        EbmlReader::new(
            BufReader::new(Cursor::new(bytes.to_vec())),
            bytes.len() as u64,
        )
    }

    #[test]
    fn ids_sizes_and_values() {
        // EBML header ID, size 0x84 = 4, then a 4-byte payload; a 2-byte ID with a 2-byte
        // size (0x4002 = 2) and an unsigned 0x0102.
        let mut r = reader(&[
            0x1A, 0x45, 0xDF, 0xA3, 0x84, 1, 2, 3, 4, 0x42, 0x86, 0x40, 0x02, 1, 2,
        ]);
        let e = r.next(u64::MAX).unwrap().unwrap();
        assert_eq!((e.id, e.start, e.data, e.size), (0x1A45DFA3, 0, 5, Some(4)));
        r.seek_to(e.end(0)).unwrap();
        let v = r.next(u64::MAX).unwrap().unwrap();
        assert_eq!((v.id, v.size), (0x4286, Some(2)));
        assert_eq!(r.uint(&v, "version").unwrap(), 0x0102);
        assert!(r.next(u64::MAX).unwrap().is_none());
    }

    #[test]
    fn unknown_sizes_signed_values_and_vints() {
        let mut r = reader(&[0x18, 0x53, 0x80, 0x67, 0xFF]);
        assert_eq!(r.next(u64::MAX).unwrap().unwrap().size, None);
        let mut r = reader(&[0xFB, 0x82, 0xFF, 0xFE]);
        let e = r.next(u64::MAX).unwrap().unwrap();
        assert_eq!(r.int(&e, "reference").unwrap(), -2);
        assert_eq!(vint(&[0x81]), Some((1, 1)));
        assert_eq!(vint(&[0x40, 0x02]), Some((2, 2)));
        assert_eq!(vint(&[0x40]), None);
        assert_eq!(vint(&[0x00, 1, 2, 3, 4, 5, 6, 7, 8]), None);
    }

    #[test]
    fn cuts_and_damage_are_told_apart() {
        // The file ends inside a size.
        let mut r = reader(&[0x1A, 0x45, 0xDF, 0xA3, 0x40]);
        assert!(matches!(
            r.next(u64::MAX),
            Err(EbmlError::Cut { at: 0, .. })
        ));
        // A zero byte starts no ID.
        let mut r = reader(&[0x00, 0x81]);
        assert!(matches!(
            r.next(u64::MAX),
            Err(EbmlError::Damaged { at: 0, .. })
        ));
        // A payload past the end of the file is a cut; one over its limit is damage.
        let mut r = reader(&[0x86, 0x88, b'V', b'_']);
        let e = r.next(u64::MAX).unwrap().unwrap();
        assert!(matches!(
            r.bytes(&e, 100, "codec"),
            Err(EbmlError::Cut { .. })
        ));
        assert!(matches!(
            r.bytes(&e, 4, "codec"),
            Err(EbmlError::Damaged { .. })
        ));
    }
}
