//! Helpers shared by the fuzz targets (each target includes this file as a module).
#![allow(dead_code)]

use std::path::Path;

/// Splits `data` at 0xFF bytes (never in UTF-8 text) into at most `n` parts, the last
/// part keeping any further 0xFF; missing parts are empty. Lets one input carry several
/// text files.
pub fn sections(data: &[u8], n: usize) -> Vec<&[u8]> {
    let mut out: Vec<&[u8]> = data.splitn(n, |b| *b == 0xFF).collect();
    out.resize(n, &[]);
    out
}

/// Writes a 2x2 RGB PNG and a 2x2 16-bit depth PNG to `color` and `depth`.
pub fn write_tiny_images(color: &Path, depth: &Path) {
    use relume::raster::Image;
    use relume::recording::codec;
    let rgb = codec::encode_png_rgb8(&Image::filled(2, 2, [90u8, 120, 200])).expect("png");
    std::fs::write(color, rgb.bytes).expect("write color");
    let d = codec::encode_png_u16(2, 2, vec![1000, 1200, 1400, 1600]).expect("png");
    std::fs::write(depth, d.bytes).expect("write depth");
}

/// Recomputes the CRC32 of every `.relume` record frame that fits in `bytes`, so that
/// mutations of payloads, stamps and tags reach the decoders instead of stopping at the
/// checksum (layout in `relume::recording::format`).
pub fn fix_relume_crcs(bytes: &mut [u8]) {
    use relume::recording::format::{FRAME_HEADER_LEN, FrameHeader, PREAMBLE_LEN};
    let head = FRAME_HEADER_LEN as usize;
    let mut at = PREAMBLE_LEN as usize;
    while at + head <= bytes.len() {
        let frame = FrameHeader::parse(bytes[at..at + head].try_into().expect("20 bytes"));
        let end = at + head + frame.len as usize;
        if end > bytes.len() {
            return;
        }
        let crc = FrameHeader::checksum(frame.tag_byte, frame.stamp_ns, &bytes[at + head..end]);
        bytes[at + 4..at + 8].copy_from_slice(&crc.to_le_bytes());
        at = end;
    }
}

/// Makes the checksums of an MCAP file agree with its bytes: each uncompressed chunk's
/// CRC is recomputed, and the data-section and summary CRCs are set to 0 ("not
/// computed" in the MCAP spec). Compressed chunks keep theirs (the CRC covers the
/// decompressed records).
pub fn fix_mcap_crcs(bytes: &mut [u8]) {
    const MAGIC: &[u8] = b"\x89MCAP0\r\n";
    if !bytes.starts_with(MAGIC) {
        return;
    }
    let u64_at = |b: &[u8], i: usize| {
        b.get(i..i + 8)
            .map(|s| u64::from_le_bytes(s.try_into().unwrap()))
    };
    let u32_at = |b: &[u8], i: usize| {
        b.get(i..i + 4)
            .map(|s| u32::from_le_bytes(s.try_into().unwrap()))
    };
    let mut at = MAGIC.len();
    while let (Some(&op), Some(len)) = (bytes.get(at), u64_at(bytes, at + 1)) {
        let body = at + 9;
        let Some(end) = usize::try_from(len).ok().and_then(|l| body.checked_add(l)) else {
            return;
        };
        if end > bytes.len() {
            return;
        }
        match op {
            // Chunk: start u64, end u64, uncompressed size u64, uncompressed crc u32,
            // compression string, records (u64 length + bytes).
            0x06 => {
                let crc_at = body + 24;
                let Some(name_len) = u32_at(bytes, crc_at + 4) else {
                    return;
                };
                let records_len_at = crc_at + 8 + name_len as usize;
                if name_len == 0 {
                    if let Some(n) = u64_at(bytes, records_len_at) {
                        let start = records_len_at + 8;
                        if let Some(stop) =
                            usize::try_from(n).ok().and_then(|n| start.checked_add(n))
                        {
                            if stop <= end {
                                let crc = crc32fast::hash(&bytes[start..stop]);
                                bytes[crc_at..crc_at + 4].copy_from_slice(&crc.to_le_bytes());
                            }
                        }
                    }
                }
            }
            // Data End: data section crc u32.
            0x0F if body + 4 <= end => bytes[body..body + 4].fill(0),
            // Footer: summary start u64, summary offset start u64, summary crc u32.
            0x02 if body + 20 <= end => bytes[body + 16..body + 20].fill(0),
            _ => {}
        }
        at = end;
    }
}
