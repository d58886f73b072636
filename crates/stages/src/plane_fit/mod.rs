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
mod params;
#[cfg(test)]
mod synth_tests;
#[cfg(test)]
mod tests;

pub use driver::plane_fit_normals;
pub use fit::{FitCase, Plane, Scatter, fit_plane};
use params::{K, MIN_DETERMINANT, RADIUS, SAMPLE_STEP};
pub use params::{NormalCode, PlaneFitParams};

use crate::kind;
use glam::Vec3;
use relume_base::pinhole::Pinhole;
use relume_base::raster::Image;
use relume_graph::{Frame, ParamDefault, ParamSpec, Ports, Product, Stage, StageError, StageInfo};
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

pub const INFO: StageInfo = StageInfo {
    kind: "normals.plane_fit",
    summary: "normals and refined depth from per-pixel plane fits over disk neighbourhoods \
              (paper 000 Sec. 5)",
    params: PARAMS,
    ports: |_| {
        Ports::fixed(
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
