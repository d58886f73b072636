//! A Matroska block's payload split into its frames (Matroska's lacing: several frames in
//! one block, their sizes in Xiph, EBML or fixed form before them).

use super::ebml::vint;
use std::ops::Range;

/// Lacing of a block, from bits 1-2 of its flags.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lacing {
    None,
    Xiph,
    Fixed,
    Ebml,
}

impl Lacing {
    pub fn from_flags(flags: u8) -> Lacing {
        match (flags >> 1) & 3 {
            0 => Lacing::None,
            1 => Lacing::Xiph,
            2 => Lacing::Fixed,
            _ => Lacing::Ebml,
        }
    }
}

/// The byte ranges of the frames in `payload` (a block's bytes after its flags).
pub fn frames(payload: &[u8], lacing: Lacing) -> Result<Vec<Range<usize>>, String> {
    if lacing == Lacing::None {
        return Ok(std::iter::once(0..payload.len()).collect());
    }
    let count = *payload
        .first()
        .ok_or("a laced block without its frame count")? as usize
        + 1;
    let mut at = 1;
    let mut sizes = Vec::with_capacity(count);
    match lacing {
        Lacing::None => unreachable!("handled above"),
        Lacing::Fixed => {
            let rest = payload.len() - 1;
            if !rest.is_multiple_of(count) {
                return Err(format!(
                    "{rest} bytes do not split into {count} frames of one size"
                ));
            }
            sizes.resize(count - 1, rest / count);
        }
        Lacing::Xiph => {
            for _ in 0..count - 1 {
                let mut size = 0usize;
                loop {
                    let b = *payload.get(at).ok_or("the lace sizes run past the block")?;
                    at += 1;
                    size += b as usize;
                    if b != 255 {
                        break;
                    }
                }
                sizes.push(size);
            }
        }
        Lacing::Ebml if count > 1 => {
            let (first, len) = vint(&payload[at..]).ok_or("a damaged first lace size")?;
            at += len;
            let mut size = first as i64;
            sizes.push(first as usize);
            for _ in 1..count - 1 {
                let (raw, len) = vint(&payload[at..]).ok_or("a damaged lace size")?;
                at += len;
                // Signed: the value less half its range.
                let bias = (1i64 << (7 * len - 1)) - 1;
                size += raw as i64 - bias;
                if size < 0 {
                    return Err("a lace size below 0".into());
                }
                sizes.push(size as usize);
            }
        }
        Lacing::Ebml => {}
    }
    let mut ranges = Vec::with_capacity(count);
    for size in sizes {
        let end = at
            .checked_add(size)
            .filter(|&e| e <= payload.len())
            .ok_or("the laced frames run past the block")?;
        ranges.push(at..end);
        at = end;
    }
    ranges.push(at..payload.len());
    Ok(ranges)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_lacing_splits_as_the_specification_shows() {
        assert_eq!(frames(b"abc", Lacing::None).unwrap(), vec![0..3]);
        // Xiph: 3 frames, sizes 2 and 256 (255 + 1), the rest the last.
        let mut xiph = vec![2, 2, 255, 1];
        xiph.extend(std::iter::repeat_n(7u8, 2 + 256 + 3));
        assert_eq!(
            frames(&xiph, Lacing::Xiph).unwrap(),
            vec![4..6, 6..262, 262..265]
        );
        // Fixed: 2 frames of 3 bytes.
        assert_eq!(
            frames(&[1, 0, 0, 0, 0, 0, 0], Lacing::Fixed).unwrap(),
            vec![1..4, 4..7]
        );
        assert!(frames(&[1, 0, 0, 0], Lacing::Fixed).is_err());
        // EBML: 3 frames, first size 3 (0x83), then a difference of -1 (0xBE = 62 - 63).
        let mut ebml = vec![2, 0x83, 0xBE];
        ebml.extend([0u8; 3 + 2 + 4]);
        assert_eq!(
            frames(&ebml, Lacing::Ebml).unwrap(),
            vec![3..6, 6..8, 8..12]
        );
        assert!(frames(&[2, 0xFF], Lacing::Ebml).is_err());
        assert!(frames(&[1, 200, 0], Lacing::Xiph).is_err());
    }
}
