//! Scores of `normals.*` stages: the angle to the true normals and the fraction of
//! pixels with a normal where the truth has one.

use super::truth::FrameTruth;
use glam::Vec3;
use relume_graph::Frame;
use serde_json::{Value, json};

/// Angle histogram resolution: the median is exact to this many degrees.
const BIN_DEG: f64 = 0.01;
const BINS: usize = (180.0 / BIN_DEG) as usize + 1;

pub struct NormalsScorer {
    normals: String,
    angle_sum_deg: f64,
    histogram: Vec<u64>,
    estimated: u64,
    truth_valid: u64,
}

impl NormalsScorer {
    pub fn new(normals: String) -> Self {
        NormalsScorer {
            normals,
            angle_sum_deg: 0.0,
            histogram: vec![0; BINS],
            estimated: 0,
            truth_valid: 0,
        }
    }

    pub fn observe(&mut self, frame: &Frame, truth: Option<&FrameTruth>) {
        let (Ok(estimate), Some(truth)) = (frame.normals(&self.normals), truth) else {
            return;
        };
        if truth.normals.len() != estimate.data.len() {
            return;
        }
        for (e, t) in estimate.data.iter().zip(&truth.normals) {
            if *t == Vec3::ZERO || !t.is_finite() {
                continue;
            }
            self.truth_valid += 1;
            if *e == Vec3::ZERO || !e.is_finite() {
                continue;
            }
            let cos = (e.dot(*t) / (e.length() * t.length())).clamp(-1.0, 1.0);
            let angle = (cos as f64).acos().to_degrees();
            self.angle_sum_deg += angle;
            self.histogram[((angle / BIN_DEG).round() as usize).min(BINS - 1)] += 1;
            self.estimated += 1;
        }
    }

    /// `None` without ground truth.
    pub fn report(&self) -> Option<Value> {
        (self.truth_valid > 0).then(|| {
            json!({
                // null, not a perfect 0, where no pixel had a normal to score.
                "mean_angle_deg": (self.estimated > 0)
                    .then(|| self.angle_sum_deg / self.estimated as f64),
                "median_angle_deg": median_of_histogram(&self.histogram, self.estimated) * BIN_DEG,
                "valid_fraction": self.estimated as f64 / self.truth_valid as f64,
            })
        })
    }
}

/// The bin index of the median of `count` entries (NaN for none).
pub(super) fn median_of_histogram(histogram: &[u64], count: u64) -> f64 {
    if count == 0 {
        return f64::NAN;
    }
    let half = count.div_ceil(2);
    let mut seen = 0;
    for (bin, &n) in histogram.iter().enumerate() {
        seen += n;
        if seen >= half {
            return bin as f64;
        }
    }
    (histogram.len() - 1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_a_histogram() {
        assert_eq!(median_of_histogram(&[0, 3, 1, 5], 9), 3.0);
        assert_eq!(median_of_histogram(&[2, 2], 4), 0.0);
        assert!(median_of_histogram(&[0, 0], 0).is_nan());
    }

    #[test]
    fn no_normal_to_score_gives_null_angles_not_a_perfect_zero() {
        let mut scorer = NormalsScorer::new("normals".into());
        scorer.truth_valid = 48; // the truth saw pixels, the stage fitted none
        let report = scorer.report().unwrap();
        assert_eq!(report["mean_angle_deg"], Value::Null);
        assert_eq!(report["median_angle_deg"], Value::Null);
        assert_eq!(report["valid_fraction"], 0.0);
    }
}
