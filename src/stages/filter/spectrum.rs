//! The environment bandwidth B_e of paper 001 Sec. 7: the 99 %-energy bandwidth of the
//! environment map's 2D Fourier spectrum in lat-long coordinates.

use crate::light::EnvMap;
use crate::light::distribution::luminance;
use std::f64::consts::PI;

/// Width of the box-downsampled luminance map the spectrum is taken on (height is half):
/// 64 x 32 resolves angular frequencies up to 32 per radian in phi and 32 in theta, far
/// above the few per radian that the bandwidths of eq. 17 need (the paper uses B_e = 4).
pub const SPECTRUM_WIDTH: u32 = 64;

/// Fraction of the spectral energy inside the bandwidth (paper 001: 99 %).
pub const ENERGY_FRACTION: f64 = 0.99;

/// B_e of paper 001 Sec. 7, per radian, in the units of the curvature of eq. 20.
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
    if w == 0 || h == 0 {
        return 0.0;
    }
    // Rows first: R(k, y) = sum_x L(x, y) e^{-2 pi i k x / w}.
    let twiddles = |n: usize| -> Vec<(f64, f64)> {
        (0..n)
            .map(|j| {
                let a = -2.0 * PI * j as f64 / n as f64;
                (a.cos(), a.sin())
            })
            .collect()
    };
    let (tw, th) = (twiddles(w), twiddles(h));
    let mut rows = vec![(0.0f64, 0.0f64); w * h];
    for y in 0..h {
        for k in 0..w {
            let (mut re, mut im) = (0.0, 0.0);
            for x in 0..w {
                let (c, s) = tw[(k * x) % w];
                let v = lum[y * w + x];
                re += v * c;
                im += v * s;
            }
            rows[y * w + k] = (re, im);
        }
    }
    // Then columns: F(k, l) = sum_y R(k, y) e^{-2 pi i l y / h}; keep (radius, energy).
    let mut bins = Vec::with_capacity(w * h);
    let mut total = 0.0;
    for l in 0..h {
        for k in 0..w {
            let (mut re, mut im) = (0.0, 0.0);
            for y in 0..h {
                let (c, s) = th[(l * y) % h];
                let (a, b) = rows[y * w + k];
                re += a * c - b * s;
                im += a * s + b * c;
            }
            let energy = re * re + im * im;
            let signed = |f: usize, n: usize| if f > n / 2 { n - f } else { f } as f64;
            let omega_phi = signed(k, w);
            let omega_theta = 2.0 * signed(l, h);
            total += energy;
            bins.push((omega_phi.hypot(omega_theta), energy));
        }
    }
    if total <= 0.0 || !total.is_finite() {
        return 0.0;
    }
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
