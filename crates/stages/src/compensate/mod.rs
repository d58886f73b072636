//! `color.compensate` (paper 000 Sec. 4): estimates the map c_t from the camera's
//! linearized color (gamma 2.2) to the reference color space of the environment-sample
//! cloud, and applies it.
//!
//! Per frame: sample pairs between the camera image and the reference image splatted
//! from the cloud after frame t-1 are filtered in two passes ([`pairs`]: saturation,
//! missing reference, gradients, hue-saturation distance; then HSV distance after
//! c_{t-1}), weighted by eq. (1), and reduced in one deterministic pass to the sums of the
//! per-channel approximation A_t (Sec. 4.2) and of the regularized least squares C_t of
//! eq. (2) ([`fit`]). Under `min_pairs` kept pairs the frame is approximate and c_t = A_t.
//! The first frame processed defines the reference space: C_0 = I. Outputs the
//! compensated linear HDR image `C_t * linearize(color)` and the [`Compensation`]
//! (c_t, c_t^-1, diag(A_t), flags, pair counts by rejection reason).

pub mod compensation;
pub mod fit;
pub mod hsv;
pub mod pairs;
#[cfg(test)]
mod tests;

use crate::{OpError, kind};
pub use compensation::{COMPENSATION, Compensation, PairCounts};
use fit::{FitParams, Model};
use glam::{Mat3, Vec3};
use hsv::Linearize;
use pairs::{PairMoments, PairParams};
use rayon::prelude::*;
use relume_base::raster::{Image, LabelImage, Rgb8Image, Vec3Image};
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Params, Ports, Product, Stage, StageError, StageInfo,
};

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "model",
        ParamDefault::Str("linear"),
        "linear: C_t of eq. (2), A_t under min_pairs; gain: always the per-channel A_t",
    )
    .choices(&["linear", "gain"]),
    ParamSpec::new(
        "input_gamma",
        ParamDefault::Float(2.2),
        "camera levels are linearized as (v / 255)^input_gamma",
    )
    .range(1.0, 3.0),
    ParamSpec::new(
        "min_coverage",
        ParamDefault::Int(1),
        "lowest reference coverage label used (1 = push-pull filled, 2 = splatted sample)",
    )
    .range(0.0, 2.0),
    ParamSpec::new(
        "dark_level",
        ParamDefault::Int(5),
        "camera pixels with a channel at or below this level are under-saturated",
    )
    .range(0.0, 255.0),
    ParamSpec::new(
        "bright_level",
        ParamDefault::Int(250),
        "camera pixels with a channel at or above this level are over-saturated",
    )
    .range(0.0, 255.0),
    ParamSpec::new(
        "max_gradient",
        ParamDefault::Float(0.1),
        "largest relative luminance gradient (|dL_x| + |dL_y|) / sum of the 4 neighbours, in either image",
    )
    .range(0.0, 1.0),
    ParamSpec::new(
        "max_hs_distance",
        ParamDefault::Float(0.4),
        "coarse filter: largest hue-saturation distance between camera and reference (hexcone plane, 1 = red to yellow)",
    )
    .range(0.0, 2.0),
    ParamSpec::new(
        "max_hsv_distance",
        ParamDefault::Float(0.25),
        "strict filter: largest HSV distance between c_{t-1}(camera) and reference (brightness as relative difference)",
    )
    .range(0.0, 3.0),
    ParamSpec::new(
        "beta_gain",
        ParamDefault::Int(2),
        "exponent of the pair weights of eq. (1) for A_t",
    )
    .range(0.0, 64.0),
    ParamSpec::new(
        "beta_linear",
        ParamDefault::Int(8),
        "exponent of the pair weights of eq. (1) for C_t",
    )
    .range(0.0, 64.0),
    ParamSpec::new(
        "gamma",
        ParamDefault::Float(0.05),
        "regularization of C_t towards A_t in eq. (2)",
    )
    .range(0.0, 1e9),
    ParamSpec::new(
        "gamma_per_pair",
        ParamDefault::Float(0.0),
        "added to gamma per kept pair (0 = eq. (2) as in the paper): eq. (2)'s sums grow \
         with the pairs, so a fixed gamma fades at video resolution; a per-pair pull keeps \
         C_t near A_t in color directions the scene hardly spans (gray rooms), where C_t \
         otherwise drifts through the feedback loop",
    )
    .range(0.0, 1e3),
    ParamSpec::new(
        "min_pairs",
        ParamDefault::Int(2000),
        "fewer kept pairs make the frame approximate (c_t = A_t, no environment samples)",
    )
    .range(0.0, 1e9),
];

pub const INFO: StageInfo = StageInfo {
    kind: "color.compensate",
    summary: "color compensation c_t from camera to reference space by A_t / C_t of eq. (2) (paper 000 Sec. 4)",
    params: PARAMS,
    ports: |_| {
        Ports::fixed(
            &[
                ("color", &[kind::COLOR]),
                ("reference", &[kind::RADIANCE]),
                ("reference_coverage", &[kind::LABELS]),
            ],
            &[
                ("compensated", &[kind::RADIANCE]),
                ("compensation", &[kind::COMPENSATION]),
            ],
        )
    },
    build: |ctx| {
        let params = CompensateParams::from_params(ctx.params);
        Ok(Box::new(Compensate {
            color: ctx.input("color"),
            reference: ctx.input("reference"),
            coverage: ctx.input("reference_coverage"),
            compensated: ctx.output("compensated"),
            compensation: ctx.output("compensation"),
            linearize: Linearize::new(params.input_gamma),
            params,
            previous: None,
        }))
    },
};

/// All settings of `color.compensate`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompensateParams {
    /// Gamma of the camera's 8-bit values (2.2 in paper 000).
    pub input_gamma: f32,
    pub pairs: PairParams,
    pub fit: FitParams,
}

impl Default for CompensateParams {
    fn default() -> Self {
        CompensateParams {
            input_gamma: hsv::DEFAULT_INPUT_GAMMA,
            pairs: PairParams::default(),
            fit: FitParams::default(),
        }
    }
}

impl CompensateParams {
    /// The settings from checked stage parameters.
    pub fn from_params(p: &Params) -> CompensateParams {
        let level = |name| p.int(name).clamp(0, 255) as u8;
        let exponent = |name| p.int(name).clamp(0, 64) as u32;
        CompensateParams {
            input_gamma: p.float("input_gamma") as f32,
            pairs: PairParams {
                min_coverage: level("min_coverage"),
                dark_level: level("dark_level"),
                bright_level: level("bright_level"),
                max_gradient: p.float("max_gradient") as f32,
                max_hs_distance: p.float("max_hs_distance") as f32,
                max_hsv_distance: p.float("max_hsv_distance") as f32,
                beta_gain: exponent("beta_gain"),
                beta_linear: exponent("beta_linear"),
            },
            fit: FitParams {
                model: if p.str("model") == "gain" {
                    Model::Gain
                } else {
                    Model::Linear
                },
                gamma: p.float("gamma"),
                gamma_per_pair: p.float("gamma_per_pair"),
                min_pairs: p.int("min_pairs").clamp(0, u32::MAX as i64) as u32,
            },
        }
    }
}

/// The compensation of a frame after the first (paper 000 Sec. 4): pair selection
/// against `reference` (radiance and coverage labels; `None` when the frame has none,
/// which leaves every pixel without reference) and the fit, given c_{t-1} `previous`.
pub fn estimate_compensation(
    color: &Rgb8Image,
    reference: Option<(&Vec3Image, &LabelImage)>,
    previous: &Mat3,
    linearize: &Linearize,
    params: &CompensateParams,
) -> Result<Compensation, OpError> {
    let moments = match reference {
        Some((radiance, coverage)) => pairs::select_pairs(
            color,
            radiance,
            coverage,
            linearize,
            previous,
            &params.pairs,
        )?,
        None => PairMoments::without_reference(color.len()),
    };
    Ok(fit::estimate(&moments, previous, &params.fit))
}

/// Writes `matrix * linearize(color)` into `compensated`: the camera image in the
/// reference color space, linear HDR (paper 000 Sec. 4, Fig. 3 bottom right).
/// `compensated` takes the size of `color`; its buffer is reused when large enough, and
/// filled in parallel without clearing it first.
pub fn apply_compensation(
    color: &Rgb8Image,
    linearize: &Linearize,
    matrix: &Mat3,
    compensated: &mut Vec3Image,
) {
    // Column c of the matrix times every linear level: 3 lookups and 2 additions per
    // pixel, summed in the order of `Mat3 * Vec3`, so the result equals `matrix * u`.
    let cols = [matrix.x_axis, matrix.y_axis, matrix.z_axis];
    let lin = linearize.table();
    let table: [[Vec3; 3]; 256] = std::array::from_fn(|level| cols.map(|c| c * lin[level]));
    color
        .data
        .par_iter()
        .with_min_len(1024)
        .map(|c| table[c[0] as usize][0] + table[c[1] as usize][1] + table[c[2] as usize][2])
        .collect_into_vec(&mut compensated.data);
    compensated.width = color.width;
    compensated.height = color.height;
}

struct Compensate {
    color: String,
    reference: String,
    coverage: String,
    compensated: String,
    compensation: String,
    linearize: Linearize,
    params: CompensateParams,
    /// c_{t-1}; `None` before the first frame.
    previous: Option<Mat3>,
}

impl Stage for Compensate {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let color = frame.color(&self.color)?;
        let compensation = match &self.previous {
            None => Compensation::initial(),
            Some(previous) => {
                // Fed back from the previous frame: absent on the first frames.
                let radiance = frame
                    .get(&self.reference)
                    .map(|_| frame.radiance(&self.reference))
                    .transpose()?;
                let coverage = frame
                    .get(&self.coverage)
                    .map(|_| frame.labels(&self.coverage))
                    .transpose()?;
                estimate_compensation(
                    color,
                    radiance.zip(coverage),
                    previous,
                    &self.linearize,
                    &self.params,
                )?
            }
        };
        let mut compensated = Image::filled(0, 0, Vec3::ZERO);
        apply_compensation(
            color,
            &self.linearize,
            &compensation.matrix,
            &mut compensated,
        );
        self.previous = Some(compensation.matrix);
        frame.insert(&self.compensated, Product::new(kind::RADIANCE, compensated));
        frame.insert(
            &self.compensation,
            Product::new(kind::COMPENSATION, compensation),
        );
        Ok(())
    }
}
