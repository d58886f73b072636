//! The environment bandwidth B_e of paper 001 Sec. 7: the 99 %-energy bandwidth of the
//! environment map's 2D Fourier spectrum in lat-long coordinates.

use relume_scene::light::EnvMap;
use relume_scene::light::distribution::luminance;
use std::f64::consts::PI;

/// Width of the box-downsampled luminance map the spectrum is taken on (height is half):
/// 64 x 32 resolves angular frequencies up to 32 per radian in phi and 32 in theta, far
/// above the few per radian that the bandwidths of eq. 17 need (the paper uses B_e = 4).
pub const SPECTRUM_WIDTH: u32 = 64;

/// Fraction of the spectral energy inside the bandwidth (paper 001: 99 %).
pub const ENERGY_FRACTION: f64 = 0.99;

/// B_e of paper 001 Sec. 7: an angular frequency (per radian), like B_f and B_rho; eq. 17
/// turns it into a frequency per metre through the curvature (eq. 20) and 1 / z.
///
/// The map's Rec. 709 luminance is box-downsampled to at most
/// [`SPECTRUM_WIDTH`] x [`SPECTRUM_WIDTH`]/2 texels; its 2D DFT (a direct separable DFT,
/// no FFT at that size) gives the energy |F(k, l)|^2 per frequency, **DC included**.
/// Column frequency k (cycles over 2 pi of phi) is Omega_phi = |k| per radian; row
/// frequency l (cycles over pi of theta) is Omega_theta = 2 |l| per radian; k and l are
/// taken signed (k > W/2 stands for k - W). B_e is the smallest radius
/// sqrt(Omega_phi^2 + Omega_theta^2) that holds at least 99 % of the energy. A constant
/// map gives 0 (all energy at DC), as does an all-black or empty map.
pub fn environment_bandwidth(map: &EnvMap) -> f32 {
    let (w, h, lum) = downsampled_luminance(map);
    let bins = spectrum(w, h, &lum);
    let total = bins.iter().fold(0.0, |total, &(_, energy)| total + energy);
    if total <= 0.0 || !total.is_finite() {
        return 0.0;
    }
    let mut bins = bins;
    bins.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut inside = 0.0;
    for (radius, energy) in bins {
        inside += energy;
        if inside >= ENERGY_FRACTION * total {
            return radius as f32;
        }
    }
    0.0
}

/// The 2D DFT of the `w` x `h` map `lum` as (radius, energy) per frequency, rows of
/// l then k: energy |F(k, l)|^2, radius sqrt(Omega_phi^2 + Omega_theta^2) as in
/// [`environment_bandwidth`].
///
/// Each frequency's sums run over x (then y) in order, as a direct DFT's would, but
/// the loops keep every frequency of a row at once: the sums are independent chains
/// that vectorize, where one sum at a time waited on each addition (0.55 ms a frame
/// for the reference pipeline's 64 x 32, whose map is new every frame).
fn spectrum(w: usize, h: usize, lum: &[f64]) -> Vec<(f64, f64)> {
    assert_eq!(lum.len(), w * h);
    // Per (j, k): e^{-2 pi i j k / n} as cosines and sines, rows of j.
    let twiddles = |n: usize| -> (Vec<f64>, Vec<f64>) {
        let angle = |j: usize| -2.0 * PI * j as f64 / n as f64;
        let (cos, sin): (Vec<f64>, Vec<f64>) =
            (0..n).map(|j| (angle(j).cos(), angle(j).sin())).unzip();
        let indices = || (0..n).flat_map(move |j| (0..n).map(move |k| (j * k) % n));
        (
            indices().map(|i| cos[i]).collect(),
            indices().map(|i| sin[i]).collect(),
        )
    };
    let ((cos_w, sin_w), (cos_h, sin_h)) = (twiddles(w), twiddles(h));
    // Rows first: R(k, y) = sum_x L(x, y) e^{-2 pi i k x / w}.
    let (mut rows_re, mut rows_im) = (vec![0.0f64; w * h], vec![0.0f64; w * h]);
    for y in 0..h {
        let re = &mut rows_re[y * w..(y + 1) * w];
        let im = &mut rows_im[y * w..(y + 1) * w];
        for x in 0..w {
            let v = lum[y * w + x];
            let (c, s) = (&cos_w[x * w..(x + 1) * w], &sin_w[x * w..(x + 1) * w]);
            for k in 0..w {
                re[k] += v * c[k];
                im[k] += v * s[k];
            }
        }
    }
    // Then columns: F(k, l) = sum_y R(k, y) e^{-2 pi i l y / h}.
    let signed = |f: usize, n: usize| if f > n / 2 { n - f } else { f } as f64;
    let mut bins = Vec::with_capacity(w * h);
    let (mut re, mut im) = (vec![0.0f64; w], vec![0.0f64; w]);
    for l in 0..h {
        re.fill(0.0);
        im.fill(0.0);
        for y in 0..h {
            let (c, s) = (cos_h[l * h + y], sin_h[l * h + y]);
            let (a, b) = (&rows_re[y * w..(y + 1) * w], &rows_im[y * w..(y + 1) * w]);
            for k in 0..w {
                re[k] += a[k] * c - b[k] * s;
                im[k] += a[k] * s + b[k] * c;
            }
        }
        let omega_theta = 2.0 * signed(l, h);
        for k in 0..w {
            let energy = re[k] * re[k] + im[k] * im[k];
            bins.push((signed(k, w).hypot(omega_theta), energy));
        }
    }
    bins
}

/// The map's luminance box-downsampled to at most [`SPECTRUM_WIDTH`] x
/// [`SPECTRUM_WIDTH`]/2 (integer texel ranges per target texel; a smaller map is kept as
/// it is). Non-finite and negative radiance counts as 0.
fn downsampled_luminance(map: &EnvMap) -> (usize, usize, Vec<f64>) {
    let (sw, sh) = (map.width as usize, map.height as usize);
    if sw == 0 || sh == 0 || map.radiance.len() != sw * sh {
        return (0, 0, Vec::new());
    }
    let w = sw.min(SPECTRUM_WIDTH as usize);
    let h = sh.min(SPECTRUM_WIDTH as usize / 2);
    let mut out = vec![0.0; w * h];
    for ty in 0..h {
        let (y0, y1) = (ty * sh / h, (ty + 1) * sh / h);
        for tx in 0..w {
            let (x0, x1) = (tx * sw / w, (tx + 1) * sw / w);
            let mut sum = 0.0f64;
            for y in y0..y1 {
                for x in x0..x1 {
                    sum += luminance(map.radiance[y * sw + x]) as f64;
                }
            }
            out[ty * w + tx] = sum / ((y1 - y0) * (x1 - x0)) as f64;
        }
    }
    (w, h, out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::rng::hash;

    /// The spectrum as a direct DFT computes it, one frequency at a time.
    fn direct_spectrum(w: usize, h: usize, lum: &[f64]) -> Vec<(f64, f64)> {
        let twiddle = |j: usize, n: usize| {
            let a = -2.0 * PI * j as f64 / n as f64;
            (a.cos(), a.sin())
        };
        let mut rows = vec![(0.0f64, 0.0f64); w * h];
        for y in 0..h {
            for k in 0..w {
                let (mut re, mut im) = (0.0, 0.0);
                for x in 0..w {
                    let (c, s) = twiddle((k * x) % w, w);
                    re += lum[y * w + x] * c;
                    im += lum[y * w + x] * s;
                }
                rows[y * w + k] = (re, im);
            }
        }
        let signed = |f: usize, n: usize| if f > n / 2 { n - f } else { f } as f64;
        let mut bins = Vec::new();
        for l in 0..h {
            for k in 0..w {
                let (mut re, mut im) = (0.0, 0.0);
                for y in 0..h {
                    let (c, s) = twiddle((l * y) % h, h);
                    let (a, b) = rows[y * w + k];
                    re += a * c - b * s;
                    im += a * s + b * c;
                }
                let radius = signed(k, w).hypot(2.0 * signed(l, h));
                bins.push((radius, re * re + im * im));
            }
        }
        bins
    }

    /// The row-at-a-time loops give the direct DFT's numbers bit for bit, on maps of
    /// the full size and of odd sizes.
    #[test]
    fn spectrum_is_the_direct_dft_bit_for_bit() {
        for (case, (w, h)) in [(64usize, 32usize), (7, 5), (1, 1), (33, 16)]
            .into_iter()
            .enumerate()
        {
            let lum: Vec<f64> = (0..w * h)
                .map(|i| (hash(&[case as u64, i as u64]) % 10_000) as f64 / 997.0)
                .collect();
            let fast = spectrum(w, h, &lum);
            let direct = direct_spectrum(w, h, &lum);
            assert_eq!(fast.len(), direct.len());
            for (i, (a, b)) in fast.iter().zip(&direct).enumerate() {
                assert_eq!(
                    (a.0.to_bits(), a.1.to_bits()),
                    (b.0.to_bits(), b.1.to_bits()),
                    "{w}x{h}, bin {i}: {a:?} against {b:?}"
                );
            }
        }
    }
}
