//! Gamma encoding of linear values to 8-bit levels, the inverse of
//! [`Linearize`](crate::compensate::hsv::Linearize): level k stands for the
//! linear value (k / 255)^gamma, and a linear value x gets the level
//! round(255 x^(1 / gamma)), clamped to [0, 255]. So every level survives the round trip
//! level -> linear -> level exactly, and any value within half a level of it (in the
//! gamma-encoded scale) comes back to it.
//!
//! `powf` per channel would cost about as much as the rest of the composite; the level
//! is found instead by one lookup on the float's bits and at most one comparison with
//! the exact rounding thresholds.

/// Exponent bits plus the top [`MANTISSA_BITS`] mantissa bits index the table: a
/// bucket then spans a ratio of at most 1 + 2^-9, below the smallest ratio of two
/// consecutive thresholds (255.5 / 254.5 at gamma 1), so at most one threshold lies in
/// a bucket.
const MANTISSA_BITS: u32 = 9;
const SHIFT: u32 = 23 - MANTISSA_BITS;
/// Values below 2^-27 are level 0 whatever the gamma in [1, 3]: the first threshold,
/// (0.5 / 255)^3 = 7.54e-9, lies above it (2^-27 = 7.45e-9).
const LOWEST: f32 = 1.0 / (1u32 << 27) as f32;
/// Table entries: a power of two above the 27 * 2^9 buckets of [LOWEST, 1), so that a
/// masked index needs no bounds check.
const TABLE: usize = 1 << 14;
/// The largest float below 1.
const BELOW_ONE: f32 = 0.999_999_94;
const _: () = assert!(27 << MANTISSA_BITS < TABLE);

/// Linear value -> 8-bit level by rounding in the gamma-encoded scale.
#[derive(Clone, Debug)]
pub struct GammaEncoder {
    /// `thresholds[k]` = ((k + 0.5) / 255)^gamma: the smallest value of level k + 1
    /// (k < 255), then +inf.
    thresholds: [f32; 256],
    /// The level of the smallest value of every table bucket (then unused zeros).
    levels: Box<[u8; TABLE]>,
    /// The bucket index of [`LOWEST`].
    first_bucket: u32,
}

impl GammaEncoder {
    /// The encoder for display gamma `gamma` (2.2 matches `color.compensate`'s default
    /// linearization). `gamma` must lie in [1, 3].
    pub fn new(gamma: f32) -> GammaEncoder {
        assert!((1.0..=3.0).contains(&gamma), "gamma {gamma} outside [1, 3]");
        let thresholds: [f32; 256] = std::array::from_fn(|k| {
            if k < 255 {
                ((k as f64 + 0.5) / 255.0).powf(gamma as f64) as f32
            } else {
                f32::INFINITY
            }
        });
        let first_bucket = LOWEST.to_bits() >> SHIFT;
        let last_bucket = 1.0f32.to_bits() >> SHIFT;
        let mut levels = Box::new([0; TABLE]);
        for (level, bucket) in levels.iter_mut().zip(first_bucket..=last_bucket) {
            *level = search(&thresholds, f32::from_bits(bucket << SHIFT));
        }
        GammaEncoder {
            thresholds,
            levels,
            first_bucket,
        }
    }

    /// round(255 x^(1 / gamma)) clamped to [0, 255]; 0 for negative values and NaN.
    #[inline]
    pub fn level(&self, x: f32) -> u8 {
        // Branch-free clamping into [LOWEST, 1) (one maxss and one minss: a comparison
        // with NaN is false): NaN, negatives and values below LOWEST become LOWEST
        // (level 0), values from 1 up the float below 1 (level 255 for every gamma in
        // [1, 3]: the last threshold is at most 0.998).
        let x = if x > LOWEST { x } else { LOWEST };
        let x = if x < BELOW_ONE { x } else { BELOW_ONE };
        // The bucket lies in the table; the mask only spares the bounds check.
        let bucket = (x.to_bits() >> SHIFT) - self.first_bucket;
        let level = self.levels[bucket as usize & (TABLE - 1)];
        // At most one threshold lies inside a bucket (see MANTISSA_BITS).
        level + (x >= self.thresholds[level as usize]) as u8
    }

    /// The level by binary search over the thresholds (the reference of the table).
    pub fn level_by_search(&self, x: f32) -> u8 {
        search(&self.thresholds, x)
    }
}

/// The number of thresholds at or below `x`: the level of `x`.
fn search(thresholds: &[f32; 256], x: f32) -> u8 {
    let mut level = 0usize;
    for step in [128, 64, 32, 16, 8, 4, 2, 1] {
        if thresholds[level + step - 1] <= x {
            level += step;
        }
    }
    level as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compensate::hsv::Linearize;

    #[test]
    fn every_level_survives_the_round_trip_through_linear() {
        for gamma in [1.0, 1.8, 2.2, 2.4, 3.0] {
            let encoder = GammaEncoder::new(gamma);
            let linear = Linearize::new(gamma);
            for (level, &x) in linear.table().iter().enumerate() {
                assert_eq!(encoder.level(x) as usize, level, "gamma {gamma}");
                // Slightly perturbed values (a 3x3 matrix and its inverse) too.
                assert_eq!(encoder.level(x * (1.0 + 1e-5)) as usize, level);
                assert_eq!(encoder.level(x * (1.0 - 1e-5)) as usize, level);
            }
        }
    }

    #[test]
    fn the_table_agrees_with_rounding_in_the_encoded_scale() {
        let encoder = GammaEncoder::new(2.2);
        // Every 61st float from 2^-30 to 1.5, plus the clamps.
        let (lo, hi) = ((1.0f32 / (1u64 << 30) as f32).to_bits(), 1.5f32.to_bits());
        for bits in (lo..hi).step_by(61) {
            let x = f32::from_bits(bits);
            assert_eq!(encoder.level(x), encoder.level_by_search(x), "x = {x:e}");
        }
        // Each threshold and its neighbouring floats (where a bucket's compare decides).
        for gamma in [1.0, 2.2, 3.0] {
            let encoder = GammaEncoder::new(gamma);
            for &t in &encoder.thresholds[..255] {
                for x in [t.to_bits() - 1, t.to_bits(), t.to_bits() + 1].map(f32::from_bits) {
                    assert_eq!(
                        encoder.level(x),
                        encoder.level_by_search(x),
                        "{gamma} {x:e}"
                    );
                }
            }
        }
        assert_eq!(BELOW_ONE, f32::from_bits(1.0f32.to_bits() - 1));
        let clamps = [
            (-1.0, 0),
            (0.0, 0),
            (f32::NAN, 0),
            (f32::NEG_INFINITY, 0),
            (2.0, 255),
            (1.0, 255),
            (f32::INFINITY, 255),
        ];
        for (x, level) in clamps {
            assert_eq!(encoder.level(x), level, "x = {x}");
        }
        // And the search is the rounding it stands for, away from ties.
        for i in 0..10_000 {
            let x = i as f32 / 10_000.0;
            let exact = 255.0 * (x as f64).powf(1.0 / 2.2);
            if (exact - exact.floor() - 0.5).abs() > 1e-3 {
                assert_eq!(encoder.level(x) as f64, exact.round(), "x = {x}");
            }
        }
    }
}
