//! The report's images: composites as PNG, reduced to the reference's pixel lattice,
//! and false-colour differences from the reference.

use relume_base::raster::Rgb8Image;

/// The largest difference the false-colour scale shows (8-bit levels, mean over the
/// channels); larger ones saturate.
pub const DIFFERENCE_SCALE: f32 = 32.0;

/// The pixels of `image` whose x and y are multiples of `stride`, as an image.
pub fn on_lattice(image: &Rgb8Image, stride: u32) -> Rgb8Image {
    let s = stride.max(1) as usize;
    let (w, h) = (image.width as usize, image.height as usize);
    let (lw, lh) = (w.div_ceil(s), h.div_ceil(s));
    let mut data = Vec::with_capacity(lw * lh);
    for y in (0..h).step_by(s) {
        for x in (0..w).step_by(s) {
            data.push(image.data[y * w + x]);
        }
    }
    Rgb8Image {
        width: lw as u32,
        height: lh as u32,
        data,
    }
}

/// A colour for `t` in [0, 1]: black, blue, magenta, orange, yellow-white (a
/// perceptually ordered ramp in the manner of "inferno"); 0 is black.
pub fn ramp(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [0.0, 0.0, 0.0],
        [0.23, 0.06, 0.44],
        [0.73, 0.21, 0.33],
        [0.98, 0.55, 0.04],
        [0.99, 1.0, 0.64],
    ];
    let t = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f32;
    let i = (t.floor() as usize).min(STOPS.len() - 2);
    let f = t - i as f32;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [0, 1, 2].map(|c| ((a[c] + (b[c] - a[c]) * f) * 255.0).round() as u8)
}

/// The false-colour difference of two images of one size: per pixel the mean absolute
/// difference over the channels, on [`ramp`], [`DIFFERENCE_SCALE`] levels at the top.
pub fn difference(a: &Rgb8Image, b: &Rgb8Image) -> Rgb8Image {
    let data = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(p, q)| {
            let d: f32 = (0..3)
                .map(|c| (p[c] as f32 - q[c] as f32).abs())
                .sum::<f32>()
                / 3.0;
            ramp(d / DIFFERENCE_SCALE)
        })
        .collect();
    Rgb8Image {
        width: a.width,
        height: a.height,
        data,
    }
}

/// `image` encoded as PNG.
pub fn png_bytes(image: &Rgb8Image) -> Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    let raw: Vec<u8> = image.data.iter().flatten().copied().collect();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(
            &raw,
            image.width,
            image.height,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| format!("cannot encode a PNG: {e}"))?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lattice_keeps_every_strided_pixel() {
        let image = Rgb8Image {
            width: 5,
            height: 3,
            data: (0..15u8).map(|i| [i, 0, 0]).collect(),
        };
        let l = on_lattice(&image, 2);
        assert_eq!((l.width, l.height), (3, 2));
        let red: Vec<u8> = l.data.iter().map(|p| p[0]).collect();
        assert_eq!(red, [0, 2, 4, 10, 12, 14]);
    }

    #[test]
    fn equal_pixels_are_black_and_large_differences_saturate() {
        let a = Rgb8Image {
            width: 3,
            height: 1,
            data: vec![[10, 10, 10], [0, 0, 0], [0, 0, 0]],
        };
        let b = Rgb8Image {
            width: 3,
            height: 1,
            data: vec![[10, 10, 10], [16, 16, 16], [255, 255, 255]],
        };
        let d = difference(&a, &b);
        assert_eq!(d.data[0], [0, 0, 0]);
        assert_eq!(d.data[2], ramp(1.0));
        assert_eq!(d.data[1], ramp(0.5));
        assert_ne!(d.data[1], d.data[2]);
    }
}
