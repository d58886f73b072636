//! The Radiance RGBE (`.hdr`) decoder of [`super::load_envmap`] (Greg Ward's format:
//! a text header, then scanlines of shared-exponent RGB quads, flat or run-length
//! encoded).

use glam::Vec3;
use relume_recording::codec::MAX_PIXELS;

/// Decodes a Radiance RGBE file (`#?RADIANCE` / `#?RGBE` header, `FORMAT=32-bit_rle_rgbe`,
/// resolution `-Y H +X W`, flat, old run-length or new per-channel run-length
/// scanlines). `EXPOSURE` lines are ignored: the values are taken as stored.
pub(super) fn decode_rgbe(bytes: &[u8]) -> Result<(u32, u32, Vec<Vec3>), String> {
    let mut pos = 0;
    let line = |pos: &mut usize| -> Result<String, String> {
        let end = bytes[*pos..]
            .iter()
            .position(|&b| b == b'\n')
            .ok_or("the header ends before the resolution line")?;
        let text = String::from_utf8_lossy(&bytes[*pos..*pos + end]).into_owned();
        *pos += end + 1;
        Ok(text)
    };
    loop {
        let text = line(&mut pos)?;
        if text.trim().is_empty() {
            break;
        }
        if let Some(format) = text.strip_prefix("FORMAT=")
            && format.trim() != "32-bit_rle_rgbe"
        {
            return Err(format!(
                "pixel format {} is not supported (only 32-bit_rle_rgbe)",
                format.trim()
            ));
        }
    }
    let resolution = line(&mut pos)?;
    let fields: Vec<&str> = resolution.split_whitespace().collect();
    let (height, width) = match fields.as_slice() {
        ["-Y", h, "+X", w] => (h.parse::<usize>().ok(), w.parse::<usize>().ok()),
        _ => (None, None),
    };
    let (Some(width), Some(height)) = (width, height) else {
        return Err(format!(
            "resolution line `{resolution}` is not `-Y <height> +X <width>` (other orientations are not supported)"
        ));
    };
    if width == 0 || height == 0 || (width as u64 * height as u64) > MAX_PIXELS {
        return Err(format!("implausible map size {width}x{height}"));
    }
    let mut out = Vec::with_capacity(width * height);
    let mut scanline = vec![[0u8; 4]; width];
    for row in 0..height {
        pos =
            read_scanline(bytes, pos, &mut scanline).map_err(|m| format!("scanline {row}: {m}"))?;
        out.extend(scanline.iter().map(|&q| rgbe_to_rgb(q)));
    }
    Ok((width as u32, height as u32, out))
}

/// Reads one scanline of RGBE quads starting at `pos`; returns the position after it.
fn read_scanline(bytes: &[u8], mut pos: usize, out: &mut [[u8; 4]]) -> Result<usize, String> {
    let width = out.len();
    let truncated = || "the file ends inside it".to_string();
    let head = bytes.get(pos..pos + 4).ok_or_else(truncated)?;
    if (8..=0x7fff).contains(&width) && head[0] == 2 && head[1] == 2 && head[2] & 0x80 == 0 {
        // New run-length encoding: each channel separately, in runs and literals.
        if ((head[2] as usize) << 8 | head[3] as usize) != width {
            return Err("run-length scanline width does not match the image".into());
        }
        pos += 4;
        for channel in 0..4 {
            let mut x = 0;
            while x < width {
                let count = *bytes.get(pos).ok_or_else(truncated)? as usize;
                pos += 1;
                if count > 128 {
                    let n = count - 128;
                    let value = *bytes.get(pos).ok_or_else(truncated)?;
                    pos += 1;
                    if x + n > width {
                        return Err("a run overruns the scanline".into());
                    }
                    out[x..x + n].iter_mut().for_each(|q| q[channel] = value);
                    x += n;
                } else {
                    if count == 0 || x + count > width {
                        return Err("a literal overruns the scanline or is empty".into());
                    }
                    let values = bytes.get(pos..pos + count).ok_or_else(truncated)?;
                    pos += count;
                    for (q, &v) in out[x..x + count].iter_mut().zip(values) {
                        q[channel] = v;
                    }
                    x += count;
                }
            }
        }
        return Ok(pos);
    }
    // Flat quads, with the old run-length code (1, 1, 1, n): repeat the previous quad.
    let (mut x, mut shift) = (0usize, 0u32);
    while x < width {
        let q = bytes.get(pos..pos + 4).ok_or_else(truncated)?;
        pos += 4;
        if q[0] == 1 && q[1] == 1 && q[2] == 1 {
            let repeat = (q[3] as usize) << shift;
            if x == 0 || x + repeat > width || shift > 16 {
                return Err("an old-style run has nothing to repeat or overruns".into());
            }
            let previous = out[x - 1];
            out[x..x + repeat].iter_mut().for_each(|o| *o = previous);
            x += repeat;
            shift += 8;
        } else {
            out[x] = [q[0], q[1], q[2], q[3]];
            x += 1;
            shift = 0;
        }
    }
    Ok(pos)
}

/// An RGBE quad as linear RGB: (m + 0.5) 2^(e - 136), 0 when e = 0 (Ward's decoder).
#[inline]
fn rgbe_to_rgb(q: [u8; 4]) -> Vec3 {
    if q[3] == 0 {
        return Vec3::ZERO;
    }
    let f = 2f64.powi(q[3] as i32 - 136);
    Vec3::new(
        ((q[0] as f64 + 0.5) * f) as f32,
        ((q[1] as f64 + 0.5) * f) as f32,
        ((q[2] as f64 + 0.5) * f) as f32,
    )
}

#[cfg(test)]
pub(super) mod tests {
    use super::decode_rgbe;
    use glam::Vec3;

    /// Encodes linear RGB as RGBE (Ward's encoder: mantissas scaled so the largest
    /// channel is in [128, 256)).
    fn rgbe(c: (f32, f32, f32)) -> [u8; 4] {
        let v = c.0.max(c.1).max(c.2);
        if v.is_nan() || v <= 1e-32 {
            return [0; 4];
        }
        let e = v.log2().floor() as i32 + 1;
        let scale = 256.0 / 2f32.powi(e);
        let m = |x: f32| (x.max(0.0) * scale) as u8;
        [m(c.0), m(c.1), m(c.2), (e + 128) as u8]
    }

    /// A .hdr file of `w` x `h` texels from `value`: flat quads, or per-channel runs.
    pub(crate) fn hdr_bytes(
        w: usize,
        h: usize,
        value: impl Fn(usize, usize) -> (f32, f32, f32),
        rle: bool,
    ) -> Vec<u8> {
        let mut out =
            format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1.0\n\n-Y {h} +X {w}\n")
                .into_bytes();
        for y in 0..h {
            let quads: Vec<[u8; 4]> = (0..w).map(|x| rgbe(value(x, y))).collect();
            if !rle {
                quads.iter().for_each(|q| out.extend_from_slice(q));
                continue;
            }
            out.extend_from_slice(&[2, 2, (w >> 8) as u8, w as u8]);
            for channel in 0..4 {
                let bytes: Vec<u8> = quads.iter().map(|q| q[channel]).collect();
                let mut x = 0;
                while x < w {
                    let run = bytes[x..]
                        .iter()
                        .take(127)
                        .take_while(|&&b| b == bytes[x])
                        .count();
                    if run >= 3 {
                        out.extend_from_slice(&[128 + run as u8, bytes[x]]);
                        x += run;
                    } else {
                        let n = (w - x).min(3);
                        out.push(n as u8);
                        out.extend_from_slice(&bytes[x..x + n]);
                        x += n;
                    }
                }
            }
        }
        out
    }

    #[test]
    fn radiance_hdr_loads_flat_and_run_length_scanlines() {
        // Runs of equal values along rows. RGBE shares one exponent per texel: each
        // channel is off by at most half a mantissa step of the largest, 1/256 of it.
        let value = |x: usize, y: usize| ((x / 4) as f32 + 1.0, 2f32.powi(y as i32 - 3), 0.25);
        for rle in [false, true] {
            let (width, height, radiance) = decode_rgbe(&hdr_bytes(32, 8, value, rle)).unwrap();
            assert_eq!((width, height), (32, 8));
            for y in 0..8 {
                for x in 0..32 {
                    let expected = Vec3::from(value(x, y));
                    let got = radiance[y * 32 + x];
                    let err = (got - expected).abs().max_element() / expected.max_element();
                    assert!(
                        err <= 1.0 / 256.0,
                        "({x}, {y}) rle {rle}: {got} vs {expected}"
                    );
                }
            }
        }
        let mut truncated = hdr_bytes(32, 8, value, true);
        truncated.truncate(truncated.len() - 10);
        let message = decode_rgbe(&truncated).unwrap_err();
        assert!(message.contains("scanline 7"), "{message}");
    }
}
