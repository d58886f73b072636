//! Random numbers and direction sampling for `sample.path`: counter-based streams per
//! pixel, cosine-weighted and Phong-lobe directions (paper 001 Sec. 5.1), and the
//! stratified look-up into the environment's importance-sample table (Sec. 5.2).

use glam::Vec3;
use relume_base::rng::{hash, mix64};
use std::f32::consts::FRAC_PI_2;

/// Salt of `sample.path` in the per-pixel key.
const SALT: u64 = 0x7061_7468; // "path"

/// The random streams of one pixel; each draw is a pure function of
/// (seed, frame, pixel, stream, index), so results do not depend on threads.
#[derive(Clone, Copy, Debug)]
pub struct PixelRng {
    key: u64,
}

/// One stream of draws: draw i is `mix64(key + i * golden)` (SplitMix64).
#[derive(Clone, Copy, Debug)]
pub struct Stream {
    key: u64,
}

/// The streams a pixel draws from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u64)]
pub enum StreamId {
    /// Sub-pixel jitter of primary j.
    Primary = 1,
    /// Offset inside the table stratum of direct sample (j, k).
    Direct = 2,
    /// Direction of indirect sample (j, k).
    Indirect = 3,
    /// The table sample lighting a virtual hit (the object's outgoing radiance).
    Bounce = 4,
    /// Object-aware candidate directions.
    Candidate = 5,
    /// Object-aware reservoir choices of H_a.
    Reservoir = 6,
    /// Object-aware candidate table samples for direct light.
    DirectCandidate = 7,
    /// Their reservoir choices.
    DirectReservoir = 8,
}

impl PixelRng {
    /// The streams of pixel `pixel` of frame `frame` under `seed`.
    #[inline]
    pub fn new(seed: u64, frame: u64, pixel: u64) -> PixelRng {
        PixelRng {
            key: hash(&[seed, frame, SALT, pixel]),
        }
    }

    #[inline]
    pub fn stream(&self, id: StreamId) -> Stream {
        Stream {
            key: mix64(self.key ^ (id as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93)),
        }
    }
}

impl Stream {
    /// 64 random bits for draw `index`.
    #[inline(always)]
    pub fn bits(&self, index: u64) -> u64 {
        mix64(
            self.key
                .wrapping_add(index.wrapping_mul(0x9E37_79B9_7F4A_7C15)),
        )
    }

    /// Two independent uniform floats in [0, 1) from draw `index` (24 bits each).
    #[inline(always)]
    pub fn pair(&self, index: u64) -> (f32, f32) {
        unit_pair(self.bits(index))
    }
}

/// Two uniform floats in [0, 1) from the top and the next 24 bits of `h`.
#[inline(always)]
pub fn unit_pair(h: u64) -> (f32, f32) {
    const SCALE: f32 = 1.0 / (1u32 << 24) as f32;
    (
        (h >> 40) as f32 * SCALE,
        ((h >> 16) & 0xFF_FFFF) as f32 * SCALE,
    )
}

/// A uniform integer in [0, n) from the top 32 bits of `h` (multiply-shift, no
/// division).
#[inline(always)]
pub fn below(h: u64, n: u32) -> u32 {
    (((h >> 32) * n as u64) >> 32) as u32
}

/// (sin, cos) of 2 pi `turns` for `turns` in [0, 1), by polynomials on an eighth of the
/// circle (error below 5e-7; no libm call).
#[inline(always)]
pub fn sin_cos_turns(turns: f32) -> (f32, f32) {
    let quarters = turns * 4.0;
    let q = (quarters + 0.5) as i32; // nearest quarter, 0..=4
    let x = (quarters - q as f32) * FRAC_PI_2; // in [-pi/4, pi/4]
    let x2 = x * x;
    let s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0))));
    let c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0))));
    // Rotate by q quarter turns: (sin, cos) of q pi/2 + x, that is (s, c), (c, -s),
    // (-s, -c) or (-c, s). The quarter is random, so the choice is made with bit masks
    // rather than branches (the same values: a negation flips the sign bit).
    const SIGN: u32 = 0x8000_0000;
    let odd = 0u32.wrapping_sub(q as u32 & 1); // all ones for an odd quarter
    let (s_bits, c_bits) = (s.to_bits(), c.to_bits());
    let s1 = (s_bits & !odd) | (c_bits & odd);
    let c1 = (c_bits & !odd) | ((s_bits ^ SIGN) & odd);
    let flip = (q as u32 & 2) << 30; // the sign bit for the second half turn
    (f32::from_bits(s1 ^ flip), f32::from_bits(c1 ^ flip))
}

/// A cosine-weighted direction about +z (pdf cos(theta) / pi) from two uniforms.
#[inline(always)]
pub fn cosine_hemisphere(u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let (s, c) = sin_cos_turns(u2);
    Vec3::new(r * c, r * s, (1.0 - u1).max(0.0).sqrt())
}

/// A direction about +z distributed as the Phong lobe, pdf (n + 1) / (2 pi) cos^n(alpha)
/// where alpha is the angle to +z.
#[inline]
pub fn phong_lobe(u1: f32, u2: f32, exponent: f32) -> Vec3 {
    let cos_a = (1.0 - u1).powf(1.0 / (exponent + 1.0));
    let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
    let (s, c) = sin_cos_turns(u2);
    Vec3::new(sin_a * c, sin_a * s, cos_a)
}

/// pi times the normalized Phong BRDF per unit albedo, pi (n + 2) / (2 pi) cos^n(alpha)
/// = (n + 2) / 2 cos^n(alpha), for the cosine `cos_alpha` to the mirror direction.
#[inline]
pub fn phong_weight(cos_alpha: f32, exponent: f32) -> f32 {
    if cos_alpha > 0.0 {
        0.5 * (exponent + 2.0) * cos_alpha.powf(exponent)
    } else {
        0.0
    }
}

/// An orthonormal basis with `n` (unit) as its third axis (Duff et al. 2017,
/// branchless).
#[derive(Clone, Copy, Debug)]
pub struct Basis {
    pub t: Vec3,
    pub b: Vec3,
    pub n: Vec3,
}

impl Basis {
    #[inline]
    pub fn new(n: Vec3) -> Basis {
        let sign = 1f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Basis {
            t: Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            b: Vec3::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    /// The direction with coordinates `local` in this basis.
    #[inline(always)]
    pub fn to_world(&self, local: Vec3) -> Vec3 {
        self.t * local.x + self.b * local.y + self.n * local.z
    }
}

/// The first index of each of `strata` equal strata of a table of `len` samples, plus
/// `len` at the end: stratum s is `bounds[s]..bounds[s + 1]` (empty strata, when the
/// table is smaller than the count, reuse the sample at their start).
pub fn strata_bounds(strata: u32, len: usize) -> Vec<u32> {
    (0..=strata as u64)
        .map(|s| (s * len as u64 / strata.max(1) as u64) as u32)
        .collect()
}

/// The table index of stratum `s` drawn with random bits `h`, or `None` for an empty
/// table.
#[inline(always)]
pub fn stratum_index(bounds: &[u32], s: usize, len: usize, h: u64) -> Option<usize> {
    let (lo, hi) = (bounds[s], bounds[s + 1]);
    if hi > lo {
        Some((lo + below(h, hi - lo)) as usize)
    } else {
        (len > 0).then(|| (lo as usize).min(len - 1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;

    #[test]
    fn polynomial_sin_cos_matches_libm() {
        let mut worst = 0f32;
        for i in 0..100_000 {
            let u = i as f32 / 100_000.0;
            let (s, c) = sin_cos_turns(u);
            let (s0, c0) = (2.0 * PI * u).sin_cos();
            worst = worst.max((s - s0).abs()).max((c - c0).abs());
        }
        assert!(worst < 1e-6, "worst error {worst}");
        let (s, c) = sin_cos_turns(1.0 - f32::EPSILON);
        assert!((s - 0.0).abs() < 1e-5 && (c - 1.0).abs() < 1e-6);
    }

    #[test]
    fn the_quarter_rotation_has_the_bits_of_the_branches() {
        // The rotation as it was written with branches.
        let branches = |turns: f32| {
            let quarters = turns * 4.0;
            let q = (quarters + 0.5) as i32;
            let x = (quarters - q as f32) * FRAC_PI_2;
            let x2 = x * x;
            let s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0))));
            let c =
                1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0))));
            let (s1, c1) = if q & 1 == 0 { (s, c) } else { (c, -s) };
            if q & 2 == 0 { (s1, c1) } else { (-s1, -c1) }
        };
        let mut turns: Vec<f32> = (0..=4000).map(|k| k as f32 / 4000.0).collect();
        // Quarter boundaries, outside [0, 1) (negative and saturating quarters), NaN.
        turns.extend([
            0.125,
            0.375,
            0.625,
            0.875,
            1.0 - f32::EPSILON,
            -0.3,
            -2.6,
            7.1,
        ]);
        turns.extend([1e12, -1e12, f32::INFINITY, f32::NAN]);
        for t in turns {
            let (s, c) = sin_cos_turns(t);
            let (s0, c0) = branches(t);
            assert_eq!(
                (s.to_bits(), c.to_bits()),
                (s0.to_bits(), c0.to_bits()),
                "{t}"
            );
        }
    }

    #[test]
    fn cosine_and_phong_samples_have_their_moments() {
        let rng = PixelRng::new(3, 0, 17).stream(StreamId::Indirect);
        let n = 200_000;
        let (mut mean_cos, mut norm_err, mut lobe) = (0f64, 0f32, 0f64);
        let exponent = 20.0;
        for i in 0..n {
            let (u1, u2) = rng.pair(i);
            let d = cosine_hemisphere(u1, u2);
            norm_err = norm_err.max((d.length() - 1.0).abs());
            assert!(d.z >= 0.0);
            mean_cos += d.z as f64;
            // Lobe sampling of pi * integral of f' cos: with the lobe about the normal,
            // the estimator (n + 2) / (n + 1) cos(theta) averages to 1.
            let l = phong_lobe(u1, u2, exponent);
            lobe += ((exponent + 2.0) / (exponent + 1.0) * l.z) as f64;
        }
        mean_cos /= n as f64;
        lobe /= n as f64;
        assert!((mean_cos - 2.0 / 3.0).abs() < 2e-3, "E[cos] {mean_cos}");
        assert!(norm_err < 1e-5, "{norm_err}");
        assert!((lobe - 1.0).abs() < 2e-3, "lobe integral {lobe}");
        // The Phong weight integrates to 1 against cos over the hemisphere (lobe at z):
        // (n+2)/2 * integral cos^n cos dw / pi = (n+2)/2 * 2pi/(n+2) / pi = 1.
        let mut acc = 0f64;
        for i in 0..n {
            let (u1, u2) = rng.pair(n + i);
            let d = cosine_hemisphere(u1, u2); // pdf cos / pi
            acc += phong_weight(d.z, exponent) as f64; // (weight cos / pi) / (cos / pi)
        }
        assert!((acc / n as f64 - 1.0).abs() < 0.02, "{}", acc / n as f64);
    }

    #[test]
    fn bases_are_orthonormal_and_strata_cover_the_table() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(0.3, -0.5, 0.1).normalize(),
            -Vec3::X,
        ] {
            let b = Basis::new(n);
            assert!((b.t.dot(b.b)).abs() < 1e-6 && (b.t.dot(n)).abs() < 1e-6);
            assert!((b.t.length() - 1.0).abs() < 1e-6 && (b.b.length() - 1.0).abs() < 1e-6);
            assert!((b.t.cross(b.b) - n).length() < 1e-5, "right-handed");
        }
        let bounds = strata_bounds(16, 4096);
        assert_eq!((bounds[0], bounds[1], bounds[16]), (0, 256, 4096));
        assert_eq!(stratum_index(&bounds, 3, 4096, u64::MAX), Some(1023));
        assert_eq!(stratum_index(&bounds, 3, 4096, 0), Some(768));
        let small = strata_bounds(16, 5);
        assert!((0..16).all(|s| stratum_index(&small, s, 5, 7).unwrap() < 5));
        assert_eq!(stratum_index(&strata_bounds(16, 0), 2, 0, 7), None);
    }
}
