//! Scores of `material.estimate`: its rho (paper 000 eq. 5) against the true diffuse
//! albedo of the surface each pixel sees.
//!
//! The truth stream stores no albedo; a recording made by `relume synth` shows the
//! analytic room of [`relume_recording::synth::interreflection::room`], so each pixel's
//! true albedo is that of the surface its view ray meets there. A pixel counts only
//! where that ray's depth agrees with the stored true depth (within 1 mm + 0.1 %), so
//! a recording of another room, or from another tool, scores no pixel rather than a
//! wrong one. Light sources (albedo 0) and pixels without a real surface are left out.
//!
//! - `albedo_rel_error_median`: median over pixels and channels of |rho - a| / a;
//! - `albedo_rmse`: root mean square of rho - a over pixels and channels;
//! - `albedo_ratio_mean`: mean of rho / a (above 1: light the samples missed, so
//!   surfaces look brighter than they are; below 1: light they found twice);
//! - `coverage`: the share of the scorable pixels that have an estimate;
//! - `pixels_scored`.
//!
//! rho is estimated in the compensated camera space of the first frame and the truth is
//! in scene RGB; the camera's color matrix is close to the identity (rows sum to 1, off
//! the diagonal at most 0.1), so the two agree to a few percent on saturated colors and
//! exactly on grays. The synthetic room is lit by its two area lights and by the light
//! its surfaces pass between them (`synth::indirect`); the pipeline's E_R gathers that
//! same interreflected light from the captured environment, so what the score measures
//! is how well capture and the estimator reproduce it.

use super::truth::FrameTruth;
use glam::{DMat3, Vec3};
use relume_base::raster::Vec3Image;
use relume_graph::Frame;
use relume_graph::pipeline::SOURCE_PRODUCT;
use relume_recording::synth::geometry::Ray;
use relume_recording::synth::render::pixel_direction;
use relume_recording::synth::scene::Scene;
use relume_recording::{Header, Intrinsics, Pose};
use serde_json::{Value, json};

/// Resolution of the relative-error histogram: the median is exact to this.
const BIN: f64 = 1e-3;
/// Relative errors up to this are binned; larger ones fall in the last bin.
const MAX_BINNED: f64 = 20.0;
/// True albedos below this are too dark for a relative error to mean much.
const MIN_TRUE_ALBEDO: f32 = 0.02;

/// Scores a `material.estimate` stage.
pub struct MaterialScorer {
    albedo: String,
    /// The scene of the recording, when `relume synth` made it.
    scene: Option<Scene>,
    intrinsics: Intrinsics,
    histogram: Vec<u64>,
    squared_error_sum: f64,
    ratio_sum: f64,
    samples: u64,
    pixels_scored: u64,
    pixels_scorable: u64,
}

impl MaterialScorer {
    /// A scorer of the product `albedo` on a recording with `header`.
    pub fn new(albedo: String, header: &Header) -> Self {
        let synthetic = header.provenance.tool == "relume synth";
        MaterialScorer {
            albedo,
            scene: synthetic.then(relume_recording::synth::interreflection::room),
            intrinsics: header.depth_intrinsics,
            histogram: vec![0; (MAX_BINNED / BIN) as usize + 1],
            squared_error_sum: 0.0,
            ratio_sum: 0.0,
            samples: 0,
            pixels_scored: 0,
            pixels_scorable: 0,
        }
    }

    pub fn observe(&mut self, frame: &Frame, truth: Option<&FrameTruth>) {
        let Some(truth) = truth else {
            return;
        };
        let (Ok(estimate), Ok(records)) =
            (frame.radiance(&self.albedo), frame.record(SOURCE_PRODUCT))
        else {
            return;
        };
        if let Some(pose) = records.pose {
            self.score(estimate, &pose, truth);
        }
    }

    /// Scores the estimate `rho` of a view from `pose` whose true depth `truth` holds.
    pub fn score(&mut self, estimate: &Vec3Image, pose: &Pose, truth: &FrameTruth) {
        let Some(scene) = &self.scene else {
            return;
        };
        let (w, h) = (truth.width, truth.height);
        if (estimate.width, estimate.height) != (w, h)
            || (self.intrinsics.width, self.intrinsics.height) != (w, h)
        {
            return;
        }
        let rotation = DMat3::from_quat(pose.rotation()).as_mat3();
        let origin = pose.translation().as_vec3();
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let depth = truth.depth[i];
                if depth <= 0.0 {
                    continue;
                }
                let ray = Ray::new(origin, rotation * pixel_direction(&self.intrinsics, x, y));
                // The direction has camera z = 1: t is the camera-space depth.
                let Some(hit) = scene.intersect(&ray, 1e-4) else {
                    continue;
                };
                if (hit.t - depth).abs() > 1e-3 + 1e-3 * depth {
                    continue;
                }
                let material = scene.material(&hit);
                let albedo = material.albedo;
                if material.emission != Vec3::ZERO || albedo.min_element() < MIN_TRUE_ALBEDO {
                    continue;
                }
                self.pixels_scorable += 1;
                let rho = estimate.data[i];
                if !rho.is_finite() {
                    continue;
                }
                self.pixels_scored += 1;
                for c in 0..3 {
                    let (r, a) = (rho[c] as f64, albedo[c] as f64);
                    let relative = (r - a).abs() / a;
                    let bin = ((relative / BIN).round() as usize).min(self.histogram.len() - 1);
                    self.histogram[bin] += 1;
                    self.squared_error_sum += (r - a) * (r - a);
                    self.ratio_sum += r / a;
                    self.samples += 1;
                }
            }
        }
    }

    /// `None` where nothing could be scored: no recording by `relume synth`, no truth.
    pub fn report(&self) -> Option<Value> {
        (self.pixels_scorable > 0).then(|| {
            let n = self.samples as f64;
            let median = (self.samples > 0)
                .then(|| super::normals::median_of_histogram(&self.histogram, self.samples) * BIN);
            json!({
                "albedo_rel_error_median": median,
                "albedo_rmse": (self.samples > 0).then(|| (self.squared_error_sum / n).sqrt()),
                "albedo_ratio_mean": (self.samples > 0).then(|| self.ratio_sum / n),
                "coverage": self.pixels_scored as f64 / self.pixels_scorable as f64,
                "pixels_scored": self.pixels_scored,
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec3, Mat3};
    use relume_recording::synth::camera::look_at;

    /// A 48x36 view of the synthetic room, its true depth (from the scene itself), and
    /// the true albedo per pixel as the estimate (NaN on the lights).
    fn view() -> (MaterialScorer, Pose, FrameTruth, Vec3Image) {
        let k = Intrinsics::PRIMESENSE.scaled_to(48, 36);
        let mut header = Header::new("room", k, 0.001);
        header.provenance.tool = "relume synth".into();
        let scorer = MaterialScorer::new("real_albedo".into(), &header);
        let eye = DVec3::new(1.5, 1.4, 1.8);
        let pose = Pose::from_parts(eye, look_at(eye, DVec3::new(-0.5, 0.2, -0.8)));
        let scene = relume_recording::synth::interreflection::room();
        let rotation = DMat3::from_quat(pose.rotation()).as_mat3();
        let (mut depth, mut albedo) = (Vec::new(), Vec::new());
        for y in 0..36 {
            for x in 0..48 {
                let ray = Ray::new(eye.as_vec3(), rotation * pixel_direction(&k, x, y));
                let hit = scene.intersect(&ray, 1e-4).unwrap();
                depth.push(hit.t);
                let m = scene.material(&hit);
                let lit = m.emission == Vec3::ZERO;
                albedo.push(if lit { m.albedo } else { Vec3::NAN });
            }
        }
        let truth = FrameTruth {
            width: 48,
            height: 36,
            depth,
            normals: vec![Vec3::Z; 48 * 36],
            radiance: vec![Vec3::ONE; 48 * 36],
            color_transform: Mat3::IDENTITY,
            contrast: 1.0,
        };
        let estimate = Vec3Image::from_vec(48, 36, albedo).unwrap();
        (scorer, pose, truth, estimate)
    }

    fn scores(scorer: &MaterialScorer) -> (f64, f64, f64, f64) {
        let r = scorer.report().unwrap();
        let f = |k: &str| r[k].as_f64().unwrap();
        (
            f("albedo_rel_error_median"),
            f("albedo_ratio_mean"),
            f("albedo_rmse"),
            f("coverage"),
        )
    }

    #[test]
    fn the_true_albedo_scores_zero_and_twice_it_a_ratio_of_two() {
        let (mut scorer, pose, truth, estimate) = view();
        scorer.score(&estimate, &pose, &truth);
        assert_eq!(scores(&scorer), (0.0, 1.0, 0.0, 1.0));
        let (mut scorer, pose, truth, mut estimate) = view();
        estimate.data.iter_mut().for_each(|a| *a *= 2.0);
        // Half the pixels without an estimate: half the coverage, the same ratios.
        let half = estimate.data.len() / 2;
        estimate.data[..half].fill(Vec3::NAN);
        scorer.score(&estimate, &pose, &truth);
        let (median, ratio, rmse, coverage) = scores(&scorer);
        assert_eq!((median, ratio), (1.0, 2.0));
        assert!(rmse > 0.1 && rmse < 1.0, "{rmse}");
        assert!((coverage - 0.5).abs() < 0.05, "{coverage}");
    }

    #[test]
    fn another_room_or_another_tool_scores_nothing() {
        let (mut scorer, pose, mut truth, estimate) = view();
        // The depths of a room 10 % larger: no pixel agrees with this one.
        truth.depth.iter_mut().for_each(|d| *d *= 1.1);
        scorer.score(&estimate, &pose, &truth);
        assert_eq!(scorer.report(), None);
        let (_, pose, truth, estimate) = view();
        let header = Header::new("room", Intrinsics::PRIMESENSE.scaled_to(48, 36), 0.001);
        let mut scorer = MaterialScorer::new("real_albedo".into(), &header);
        scorer.score(&estimate, &pose, &truth);
        assert_eq!(scorer.report(), None);
    }
}
