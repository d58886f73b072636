//! Scores of `color.compensate` and `gbuffer.splat`.
//!
//! The reference color space is the first scored frame's linearized camera space
//! (c_0 = I, paper 000 Sec. 4.3). With the synthetic camera, camera linear =
//! `(M_t radiance)^contrast_t`, so the true frame-to-reference map is `M_0 M_t^-1` when
//! there is no contrast change, and the true reference image of frame t is
//! `(M_0 radiance_t)^contrast_0`.

use super::truth::FrameTruth;
use glam::{Mat3, Vec3};
use relume_graph::Frame;
use relume_stages::kind::FrameProducts;
use serde_json::{Value, json};

/// The camera's 8-bit level to linear, gamma 2.2 (as `color.compensate` assumes).
fn linear(level: u8) -> f32 {
    (level as f32 / 255.0).powf(2.2)
}

fn frobenius(m: Mat3) -> f32 {
    m.to_cols_array().iter().map(|v| v * v).sum::<f32>().sqrt()
}

/// The median of `values` (the mean of the middle two for an even count), NaN for none.
pub(crate) fn median(values: &[f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Scores a `color.compensate` stage.
pub struct CompensationScorer {
    color: String,
    compensated: String,
    compensation: String,
    /// The first frame's color model (M_0, contrast_0): it defines the reference space.
    first: Option<(Mat3, f32)>,
    matrix_errors: Vec<f64>,
    gain_errors: Vec<f64>,
    image_errors: Vec<f64>,
    gain_image_errors: Vec<f64>,
    frames: usize,
    approximate_frames: usize,
    pairs_kept: Vec<f64>,
}

impl CompensationScorer {
    pub fn new(color: String, compensated: String, compensation: String) -> Self {
        CompensationScorer {
            color,
            compensated,
            compensation,
            first: None,
            matrix_errors: Vec::new(),
            gain_errors: Vec::new(),
            image_errors: Vec::new(),
            gain_image_errors: Vec::new(),
            frames: 0,
            approximate_frames: 0,
            pairs_kept: Vec::new(),
        }
    }

    pub fn observe(&mut self, frame: &Frame, truth: Option<&FrameTruth>) {
        let Ok(comp) = frame.compensation(&self.compensation) else {
            return;
        };
        self.frames += 1;
        self.approximate_frames += comp.approximate as usize;
        if !comp.initial {
            self.pairs_kept.push(comp.pairs.kept as f64);
        }
        let Some(truth) = truth else { return };
        let Some((m0, contrast0)) = self.first else {
            self.first = Some((truth.color_transform, truth.contrast));
            return;
        };
        let true_map = m0 * truth.color_transform.inverse();
        let norm = frobenius(true_map) as f64;
        self.matrix_errors
            .push(frobenius(comp.matrix - true_map) as f64 / norm);
        self.gain_errors
            .push(frobenius(Mat3::from_diagonal(comp.gains) - true_map) as f64 / norm);
        let (Ok(color), Ok(compensated)) =
            (frame.color(&self.color), frame.radiance(&self.compensated))
        else {
            return;
        };
        if color.data.len() != truth.radiance.len() || compensated.data.len() != color.data.len() {
            return;
        }
        // Relative RMS error of the compensated image (and of A_t applied to the same
        // pixels) against the true reference image, over unclipped pixels.
        let (mut err, mut gain_err, mut total) = (0.0f64, 0.0f64, 0.0f64);
        for ((pixel, c), l) in color
            .data
            .iter()
            .zip(&compensated.data)
            .zip(&truth.radiance)
        {
            if pixel.iter().any(|&v| v == 0 || v == 255) {
                continue;
            }
            let reference = (m0 * *l).max(Vec3::ZERO).powf(contrast0);
            let camera = Vec3::from_array(pixel.map(linear));
            err += (*c - reference).length_squared() as f64;
            gain_err += (comp.gains * camera - reference).length_squared() as f64;
            total += reference.length_squared() as f64;
        }
        if total > 0.0 {
            self.image_errors.push((err / total).sqrt());
            self.gain_image_errors.push((gain_err / total).sqrt());
        }
    }

    pub fn report(&self) -> Value {
        let mut out = json!({
            "frames": self.frames,
            "approximate_frames": self.approximate_frames,
            "pairs_kept_median": median(&self.pairs_kept),
        });
        if self.first.is_some() {
            let o = out.as_object_mut().expect("an object");
            for (key, values) in [
                ("transform_rel_error_median", &self.matrix_errors),
                ("gain_transform_rel_error_median", &self.gain_errors),
                ("image_rel_error_median", &self.image_errors),
                ("gain_image_rel_error_median", &self.gain_image_errors),
            ] {
                o.insert(key.into(), json!(median(values)));
            }
        }
        out
    }
}

/// Scores a `gbuffer.splat` stage: the reference image against the compensated camera
/// image of the same frame (no ground truth needed).
pub struct ReferenceScorer {
    reference: String,
    coverage: String,
    /// The compensated image and the camera image it came from.
    compensated: Option<(String, String)>,
    squared: f64,
    samples: u64,
    pixels: u64,
    covered: u64,
}

impl ReferenceScorer {
    pub fn new(reference: String, coverage: String, compensated: Option<(String, String)>) -> Self {
        ReferenceScorer {
            reference,
            coverage,
            compensated,
            squared: 0.0,
            samples: 0,
            pixels: 0,
            covered: 0,
        }
    }

    pub fn observe(&mut self, frame: &Frame) {
        let (Ok(reference), Ok(coverage)) = (
            frame.radiance(&self.reference),
            frame.labels(&self.coverage),
        ) else {
            return;
        };
        self.pixels += coverage.data.len() as u64;
        self.covered += coverage.data.iter().filter(|&&c| c > 0).count() as u64;
        let Some((compensated, color)) = self
            .compensated
            .as_ref()
            .and_then(|(c, k)| Some((frame.radiance(c).ok()?, frame.color(k).ok()?)))
        else {
            return;
        };
        if !compensated.same_size(reference)
            || !coverage.same_size(reference)
            || !color.same_size(reference)
        {
            return;
        }
        let pixels = reference.data.iter().zip(&compensated.data);
        for (((r, c), &k), camera) in pixels.zip(&coverage.data).zip(&color.data) {
            // Clipped camera pixels say nothing about the true color.
            let clipped = camera.iter().any(|&v| v == 0 || v == 255);
            if k > 0 && !clipped && r.is_finite() && c.is_finite() {
                self.squared += (*r - *c).length_squared() as f64 / 3.0;
                self.samples += 1;
            }
        }
    }

    /// null where nothing was compared (no frame, or no pixel both covered and
    /// unclipped), as every other scorer gives it; 0 would be a score.
    pub fn report(&self) -> Value {
        json!({
            "coverage": (self.pixels > 0).then(|| self.covered as f64 / self.pixels as f64),
            "reference_psnr_db": (self.samples > 0)
                .then(|| -10.0 * (self.squared / self.samples as f64).log10()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_and_norms() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
        assert_eq!(frobenius(Mat3::IDENTITY * 2.0), 12f32.sqrt());
    }

    #[test]
    fn a_reference_with_nothing_compared_scores_null() {
        let mut scorer = ReferenceScorer::new("reference".into(), "coverage".into(), None);
        let report = scorer.report();
        assert_eq!(report["coverage"], Value::Null);
        assert_eq!(report["reference_psnr_db"], Value::Null);
        // Covered pixels, none comparable (every camera pixel clipped, say).
        (scorer.pixels, scorer.covered) = (4, 3);
        let report = scorer.report();
        assert_eq!(report["coverage"], 0.75);
        assert_eq!(report["reference_psnr_db"], Value::Null);
        (scorer.squared, scorer.samples) = (0.04, 4); // mse 0.01: 20 dB
        assert!((scorer.report()["reference_psnr_db"].as_f64().unwrap() - 20.0).abs() < 1e-9);
    }
}
