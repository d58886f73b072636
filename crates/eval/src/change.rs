//! How fast a composite follows a change in the world (issue "things move"): the lag of
//! its differential after a change event, against the true frames.
//!
//! Per scored frame t, over the pixel channels off the objects (neither the truth nor the
//! composite's mask shows one), the composite's differential `d` is its linear camera
//! value minus the recorded frame's, and the truth's `d*` the same with the true frame.
//! The share of the true differential the composite shows is the least-squares gain
//! `r_t = sum(d d*) / sum(d* d*)`: 1 when the composite's shadows and bleeding are the
//! truth's, 0 when it shows none of them, and, unlike a ratio of sums, not cancelled
//! where shadows (negative) and bleeding (positive) meet; noise uncorrelated with the
//! truth's pattern adds nothing on average. The camera's motion changes the pattern but,
//! where the method is consistent, not the share. After a change at frame `c` (the
//! ceiling panel switched off), the lag is the fewest frames `k` such that every scored
//! frame from `c + k` on has `r_t` within [`SETTLED_TOLERANCE`] of its final value, the
//! median of the last [`FINAL_FRAMES`] scored frames' ratios.

use super::color::median;

/// A ratio within this fraction of the final one has settled (the 5 %).
pub const SETTLED_TOLERANCE: f64 = 0.05;
/// The final ratio is the median of this many last scored frames.
pub const FINAL_FRAMES: usize = 5;
/// Scored frames needed after the change: the final window and as many before it.
pub const FRAMES_AFTER_CHANGE: usize = 2 * FINAL_FRAMES;

/// The settling of a composite's differential after a change.
#[derive(Clone, Debug, PartialEq)]
pub struct Settling {
    /// The median ratio of the scored frames before the change (`None`: none scored).
    pub ratio_before: Option<f64>,
    /// The final ratio of the composite's differential to the truth's.
    pub final_ratio: f64,
    /// Frames from the change until the ratio stays within the tolerance of the final one.
    pub lag_frames: usize,
}

/// The settling of `ratios` (one per frame of `frames`, ascending) after a change at
/// frame `change`; an error saying why it cannot be measured.
pub fn settling(frames: &[usize], ratios: &[f64], change: usize) -> Result<Settling, String> {
    let after: Vec<(usize, f64)> = frames
        .iter()
        .zip(ratios)
        .filter(|(f, _)| **f >= change)
        .map(|(f, r)| (*f, *r))
        .collect();
    if after.len() < FRAMES_AFTER_CHANGE {
        return Err(format!(
            "the change at frame {change} needs {FRAMES_AFTER_CHANGE} scored frames from it on, {} were scored (give --score-frames a range that runs further past it)",
            after.len()
        ));
    }
    if after.windows(2).any(|w| w[1].0 != w[0].0 + 1) || after[0].0 != change {
        return Err(format!(
            "the frames from the change at frame {change} on are not all scored (give --score-frames a range that covers them)"
        ));
    }
    if let Some((f, _)) = after.iter().find(|(_, r)| !r.is_finite()) {
        return Err(format!(
            "frame {f} has no differential to compare (the truth changes no pixel off the objects)"
        ));
    }
    let last: Vec<f64> = after[after.len() - FINAL_FRAMES..]
        .iter()
        .map(|(_, r)| *r)
        .collect();
    let final_ratio = median(&last);
    let before: Vec<f64> = frames
        .iter()
        .zip(ratios)
        .filter(|(f, r)| **f < change && r.is_finite())
        .map(|(_, r)| *r)
        .collect();
    let ratio_before = Some(median(&before)).filter(|m| !m.is_nan());
    let settled = |r: f64| (r - final_ratio).abs() <= SETTLED_TOLERANCE * final_ratio.abs();
    // The first frame after which every ratio has settled.
    let unsettled = after.iter().rposition(|(_, r)| !settled(*r));
    let lag_frames = unsettled.map_or(0, |i| after[i].0 + 1 - change);
    Ok(Settling {
        ratio_before,
        final_ratio,
        lag_frames,
    })
}

/// The sums of one frame's share of the true differential (`r_t` above).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DifferentialSums {
    /// sum(d d*).
    pub product: f64,
    /// sum(d* d*).
    pub truth_squared: f64,
}

impl DifferentialSums {
    /// Adds one pixel channel: the composite's differential `d` and the truth's `d*`.
    pub fn add(&mut self, d: f64, d_true: f64) {
        self.product += d * d_true;
        self.truth_squared += d_true * d_true;
    }

    /// `r_t`, NaN where the truth changes nothing.
    pub fn ratio(&self) -> f64 {
        if self.truth_squared == 0.0 {
            f64::NAN
        } else {
            self.product / self.truth_squared
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(range: std::ops::Range<usize>) -> Vec<usize> {
        range.collect()
    }

    #[test]
    fn the_lag_is_the_frames_until_the_ratio_stays_near_its_end() {
        // Change at 15: 0.5 until 17, then settled at 0.8 (one frame 4 % off).
        let f = frames(10..30);
        let mut r = vec![0.5; 8];
        r.extend([
            0.6, 0.82, 0.8, 0.78, 0.8, 0.8, 0.81, 0.8, 0.79, 0.8, 0.8, 0.8,
        ]);
        let s = settling(&f, &r, 15).unwrap();
        assert_eq!((s.ratio_before, s.final_ratio), (Some(0.5), 0.8));
        // Frame 18 (0.6) is the last unsettled one: 4 frames after 15.
        assert_eq!(s.lag_frames, 4);
        // A ratio settled at the change has lag 0; a late outlier sets the lag.
        assert_eq!(settling(&f, &[0.8; 20], 15).unwrap().lag_frames, 0);
        let from_the_change = settling(&frames(15..30), &[0.8; 15], 15).unwrap();
        assert_eq!(from_the_change.ratio_before, None);
        let mut late = vec![0.8; 20];
        late[13] = 0.9;
        assert_eq!(settling(&f, &late, 15).unwrap().lag_frames, 9);
    }

    #[test]
    fn the_share_is_the_gain_of_the_composites_differential_on_the_truths() {
        let truth = [-0.2, -0.1, 0.05, 0.0];
        let mut half = DifferentialSums::default();
        let mut shadow_and_bleeding = DifferentialSums::default();
        for d in truth {
            half.add(0.5 * d, d);
            // Only the shadows, and noise orthogonal to the pattern.
            shadow_and_bleeding.add(d.min(0.0) + if d == 0.0 { 0.3 } else { 0.0 }, d);
        }
        assert!((half.ratio() - 0.5).abs() < 1e-12);
        // (0.04 + 0.01) / (0.04 + 0.01 + 0.0025)
        assert!((shadow_and_bleeding.ratio() - 0.05 / 0.0525).abs() < 1e-12);
        assert!(DifferentialSums::default().ratio().is_nan());
    }

    #[test]
    fn too_few_or_gappy_frames_are_refused() {
        let e = settling(&frames(10..20), &[1.0; 10], 15).unwrap_err();
        assert!(
            e.contains("needs 10 scored frames from it on, 5 were scored"),
            "{e}"
        );
        let mut f = frames(10..30);
        f.remove(12);
        let e = settling(&f, &[1.0; 19], 15).unwrap_err();
        assert!(e.contains("not all scored"), "{e}");
        let e = settling(&frames(16..30), &[1.0; 14], 15).unwrap_err();
        assert!(e.contains("not all scored"), "{e}");
        let mut r = vec![1.0; 20];
        r[7] = f64::NAN;
        let e = settling(&frames(10..30), &r, 15).unwrap_err();
        assert!(e.starts_with("frame 17 has no differential"), "{e}");
    }
}
