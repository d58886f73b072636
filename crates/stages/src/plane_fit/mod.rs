//! `normals.plane_fit` (paper 000, Rohmer et al., NEI, Sec. 5 and Fig. 4): normals and
//! refined depth from a least-squares plane per pixel. Each pixel's neighbourhood is the
//! set of depth samples whose disk covers it (up to k, nearest first); samples farther in
//! depth than 0.1 m from the nearest one are dropped as lying across a discontinuity; the
//! mean-centred plane is solved without an SVD by the three Cramer's-rule cases, keeping
//! the one with the largest determinant; the view ray through the pixel meets the plane
//! at the refined depth. Pixels without raw depth but covered by disks get a normal and a
//! depth too (densification).
//!
//! It reads the same `points` as `normals.cross` and writes the same `normals`, so a
//! pipeline swaps the two by changing the stage kind. It also writes `refined_depth`
//! (0 where there is no plane), `neighbours` (k-hat, the samples in the fit) and
//! `normal_codes` ([`NormalCode`]: why a pixel has no normal).
//!
//! On the synthetic recording's raw 640x480 depth (Kinect-like noise, disparity
//! quantization, holes) the defaults give a mean angle to the true normals of about 12
//! degrees where forward-difference cross products give 66, halve the depth error, and
//! fill most holes. Cost: one pass over the covering samples per pixel (about 17 with
//! the defaults), then the fit; both eight pixels at a time where the CPU has AVX2
//! (`lanes.rs`, the same bits as one pixel at a time): about 8 ms of one core per
//! 640x480 frame on livingroom1, against 25 ms one pixel at a time (measured
//! alternately, the machine's speed drifting over the hour).

mod driver;
pub mod fit;
mod gather;
mod lanes;
#[cfg(test)]
mod synth_tests;
#[cfg(test)]
mod tests;

pub use driver::plane_fit_normals;
pub use fit::{FitCase, Plane, Scatter, fit_plane};

use crate::kind;
use glam::Vec3;
use relume_base::pinhole::Pinhole;
use relume_base::raster::Image;
use relume_graph::{Frame, ParamDefault, ParamSpec, Product, Stage, StageError, StageInfo};
use relume_recording::Intrinsics;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "radius",
        ParamDefault::Float(RADIUS),
        "disk radius around each sample (pixels of the depth image); scale it with the \
         resolution: the default suits 640x480 Kinect-like depth",
    )
    .range(1.0, 64.0),
    ParamSpec::new(
        "k",
        ParamDefault::Int(K as i64),
        "length of each pixel's list of covering samples, nearest first (the paper's k); \
         the discontinuity rejection may leave fewer",
    )
    .range(3.0, 255.0),
    ParamSpec::new(
        "sample_step",
        ParamDefault::Int(SAMPLE_STEP as i64),
        "take every n-th pixel in x and y as a sample (1: all of the dense depth)",
    )
    .range(1.0, 16.0),
    ParamSpec::new(
        "max_depth_gap",
        ParamDefault::Float(0.1),
        "samples farther than this in depth (metres) from the pixel's nearest sample are \
         dropped (paper: 0.1), as is a refined depth this far from the samples' mean",
    )
    .range(0.0, 100.0),
    ParamSpec::new(
        "min_determinant",
        ParamDefault::Float(MIN_DETERMINANT),
        "the fit is invalid when its largest determinant is below this times the squared \
         trace of the scatter matrix (collinear samples)",
    )
    .range(0.0, 0.25),
];

// Defaults for 640x480 Kinect-like depth: every 6th pixel is a sample (8560 samples,
// inside the 3000 to 14000 per frame of the paper's sensor), and the radius makes about
// k = 16 disks overlap each pixel (pi 14^2 / 6^2 = 17), as the paper prescribes.
const RADIUS: f64 = 14.0;
const K: usize = 16;
const SAMPLE_STEP: usize = 6;
const MIN_DETERMINANT: f64 = 1e-3;

pub const INFO: StageInfo = StageInfo {
    kind: "normals.plane_fit",
    summary: "normals and refined depth from per-pixel plane fits over disk neighbourhoods \
              (paper 000 Sec. 5)",
    params: PARAMS,
    ports: |_| {
        super::fixed_ports(
            &[("points", &[kind::POINTS])],
            &[
                ("normals", &[kind::NORMALS]),
                ("refined_depth", &[kind::DEPTH]),
                ("neighbours", &[kind::LABELS]),
                ("normal_codes", &[kind::LABELS]),
            ],
        )
    },
    build: |ctx| {
        let p = ctx.params;
        let params = PlaneFitParams {
            radius: p.float("radius") as f32,
            k: p.int("k") as usize,
            sample_step: p.int("sample_step") as usize,
            max_depth_gap: p.float("max_depth_gap") as f32,
            min_determinant: p.float("min_determinant") as f32,
        };
        params.check()?;
        Ok(Box::new(PlaneFitStage {
            points: ctx.input("points"),
            normals: ctx.output("normals"),
            refined_depth: ctx.output("refined_depth"),
            neighbours: ctx.output("neighbours"),
            codes: ctx.output("normal_codes"),
            intrinsics: ctx.header.depth_intrinsics,
            params,
        }))
    },
};

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

/// Parameters of [`plane_fit_normals`].
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
    /// Relative threshold of [`Scatter::fit`].
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
    pub fn check(&self) -> Result<(), StageError> {
        let bad = |what: String| Err(StageError::Failed(what));
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

struct PlaneFitStage {
    points: String,
    normals: String,
    refined_depth: String,
    neighbours: String,
    codes: String,
    intrinsics: Intrinsics,
    params: PlaneFitParams,
}

impl Stage for PlaneFitStage {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let points = frame.points(&self.points)?;
        let (w, h) = (points.width, points.height);
        let camera = Pinhole::new(&self.intrinsics, w, h);
        let mut normals = Image::filled(w, h, Vec3::ZERO);
        let mut refined_depth = Image::filled(w, h, 0.0f32);
        let mut neighbours = Image::filled(w, h, 0u8);
        let mut codes = Image::filled(w, h, 0u8);
        plane_fit_normals(
            points,
            &camera,
            &self.params,
            &mut normals,
            &mut refined_depth,
            &mut neighbours,
            &mut codes,
        )?;
        frame.insert(&self.normals, Product::new(kind::NORMALS, normals));
        frame.insert(
            &self.refined_depth,
            Product::new(kind::DEPTH, refined_depth),
        );
        frame.insert(&self.neighbours, Product::new(kind::LABELS, neighbours));
        frame.insert(&self.codes, Product::new(kind::LABELS, codes));
        Ok(())
    }
}
