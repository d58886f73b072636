//! What a plane fit is asked and what it answers per pixel: [`PlaneFitParams`] and the
//! [`NormalCode`] of each pixel, shared by the driver, the scalar and lane fits.

use crate::OpError;

// Defaults for 640x480 Kinect-like depth: every 6th pixel is a sample (8560 samples,
// inside the 3000 to 14000 per frame of the paper's sensor), and the radius makes about
// k = 16 disks overlap each pixel (pi 14^2 / 6^2 = 17), as the paper prescribes.
pub(super) const RADIUS: f64 = 14.0;
pub(super) const K: usize = 16;
pub(super) const SAMPLE_STEP: usize = 6;
pub(super) const MIN_DETERMINANT: f64 = 1e-3;

/// Why a pixel has no normal: the values of the `normal_codes` label map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum NormalCode {
    /// A plane was fitted: normal and refined depth are valid.
    Valid = 0,
    /// No sample's disk covers the pixel (black in the paper's Fig. 4).
    NoSample = 1,
    /// Two or fewer samples: no plane can be estimated (dark gray in Fig. 4).
    TooFewSamples = 2,
    /// The largest determinant is close to zero: the samples are (nearly) collinear and
    /// the system is badly conditioned (light gray in Fig. 4).
    Degenerate = 3,
    /// The view ray through the pixel meets the plane farther than `max_depth_gap` from
    /// the samples' mean depth, or behind the camera: a plane seen at a grazing angle
    /// (or one so noisy that it is).
    RayMissesPlane = 4,
}

impl NormalCode {
    /// The code of a `normal_codes` label, or `None` for a value that is no code.
    pub fn from_u8(label: u8) -> Option<NormalCode> {
        [
            NormalCode::Valid,
            NormalCode::NoSample,
            NormalCode::TooFewSamples,
            NormalCode::Degenerate,
            NormalCode::RayMissesPlane,
        ]
        .into_iter()
        .find(|&c| c as u8 == label)
    }
}

/// Parameters of [`plane_fit_normals`](super::plane_fit_normals).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFitParams {
    /// Disk radius around each sample, in pixels.
    pub radius: f32,
    /// Length of each pixel's list of samples, before the rejection (3 to 255).
    pub k: usize,
    /// Samples are the pixels on a grid of this step (1: every pixel).
    pub sample_step: usize,
    /// Discontinuity threshold against the nearest sample (metres; paper: 0.1), and the
    /// largest distance of a refined depth from the samples' mean depth.
    pub max_depth_gap: f32,
    /// Relative threshold of [`Scatter::fit`](super::Scatter::fit).
    pub min_determinant: f32,
}

impl Default for PlaneFitParams {
    fn default() -> Self {
        PlaneFitParams {
            radius: RADIUS as f32,
            k: K,
            sample_step: SAMPLE_STEP,
            max_depth_gap: 0.1,
            min_determinant: MIN_DETERMINANT as f32,
        }
    }
}

impl PlaneFitParams {
    /// Fails with a message when a value is out of its range.
    pub fn check(&self) -> Result<(), OpError> {
        let bad = |what: String| Err(OpError::BadParameter(what));
        if !(self.radius >= 1.0 && self.radius <= 64.0) {
            return bad(format!("radius {} must lie in [1, 64]", self.radius));
        }
        if !(3..=255).contains(&self.k) {
            return bad(format!("k {} must lie in [3, 255]", self.k));
        }
        if !(1..=16).contains(&self.sample_step) {
            return bad(format!(
                "sample_step {} must lie in [1, 16]",
                self.sample_step
            ));
        }
        if self.max_depth_gap.is_nan() || self.max_depth_gap < 0.0 {
            return bad(format!(
                "max_depth_gap {} must be at least 0",
                self.max_depth_gap
            ));
        }
        if self.min_determinant.is_nan() || self.min_determinant < 0.0 {
            return bad(format!(
                "min_determinant {} must be at least 0",
                self.min_determinant
            ));
        }
        Ok(())
    }
}
