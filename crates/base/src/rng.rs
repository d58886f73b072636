//! Counter-based random numbers: every value is a pure function of its coordinates
//! (seed, frame, stage, pixel, sample), so results never depend on thread scheduling.

/// SplitMix64 finalizer: a bijective 64-bit mix with good avalanche.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hashes a list of coordinates into one 64-bit value.
#[inline]
pub fn hash(coords: &[u64]) -> u64 {
    coords
        .iter()
        .fold(0x243F_6A88_85A3_08D3, |acc, &c| mix64(acc ^ mix64(c)))
}

/// A uniform float in [0, 1) from the top 24 bits of a hash.
#[inline]
pub fn unit_f32(h: u64) -> f32 {
    (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// A uniform float in [0, 1) from the top 53 bits of a hash.
#[inline]
pub fn unit_f64(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A stream of random numbers for one set of coordinates: the n-th draw is
/// `hash(coords ++ [n])`, so draws can be taken in any order on any thread.
#[derive(Clone, Copy, Debug)]
pub struct Counter {
    key: u64,
    next: u64,
}

impl Counter {
    /// A stream keyed by `coords`, e.g. `[seed, frame, stage, pixel]`.
    pub fn new(coords: &[u64]) -> Self {
        Counter {
            key: hash(coords),
            next: 0,
        }
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        let v = mix64(self.key ^ mix64(self.next));
        self.next += 1;
        v
    }

    /// The next uniform float in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        unit_f32(self.next_u64())
    }

    /// The next uniform double in [0, 1).
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        unit_f64(self.next_u64())
    }

    /// A standard normal deviate (Box-Muller, one of the pair).
    pub fn next_gaussian(&mut self) -> f64 {
        let u1 = self.next_f64().max(f64::MIN_POSITIVE);
        let u2 = self.next_f64();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_depend_only_on_coordinates() {
        let mut a = Counter::new(&[7, 3, 1, 42]);
        let mut b = Counter::new(&[7, 3, 1, 42]);
        let mut c = Counter::new(&[7, 3, 1, 43]);
        let xs: Vec<u64> = (0..4).map(|_| a.next_u64()).collect();
        let ys: Vec<u64> = (0..4).map(|_| b.next_u64()).collect();
        let zs: Vec<u64> = (0..4).map(|_| c.next_u64()).collect();
        assert_eq!(xs, ys);
        assert_ne!(xs, zs);
    }

    #[test]
    fn uniform_mean_and_gaussian_moments() {
        let mut r = Counter::new(&[1]);
        let n = 200_000;
        let mean: f64 = (0..n).map(|_| r.next_f64()).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
        let g: Vec<f64> = (0..n).map(|_| r.next_gaussian()).collect();
        let m = g.iter().sum::<f64>() / n as f64;
        let v = g.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n as f64;
        assert!(m.abs() < 0.01 && (v - 1.0).abs() < 0.02, "mean {m} var {v}");
    }
}
