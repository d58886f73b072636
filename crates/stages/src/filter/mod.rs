//! `filter.axis_aligned` (paper 001 Secs. 6-7): filters the four noisy irradiance layers
//! of `sample.path` / `sample.val` (E_R^dir, E_R^ind, E_RV^dir, E_RV^ind) with a
//! separable world-space Gaussian whose per-pixel width follows from the axis-aligned
//! frequency analysis of paper 001.
//!
//! Per frame:
//! 1. Screen-space curvatures kappa_X, kappa_Y (eq. 20, [`screen_curvature`]).
//! 2. Bandwidths (per metre): direct light per axis by eq. 17
//!    ([`direct_bandwidth`]: B_f, B_rho from the pixel's Phong exponent, B_e of the
//!    environment, the nearest occluder z = `direct_min_distance`), indirect light by
//!    eq. 18 ([`indirect_bandwidth`]: B_h / z_min, the same along X and Y).
//! 3. X pass (eq. 21) then Y pass (eq. 22) of w = exp(-2 Bbar^2 |p - p_i|^2) (eq. 23),
//!    Bbar^2 = (B^2(target) + B^2(source)) / 2, over |i| <= `radius` (the paper writes
//!    |i| < R; with R = 15 ours has 31 taps, the "31 taps"). Taps without a
//!    value or a position are skipped; a pixel without a value stays NaN. The weights
//!    are the same for E_R and E_RV of one kind, so each is computed once and applied to
//!    both: where E_RV == E_R over the footprint, the filtered values are equal bit for
//!    bit (the composite's ratio stays exactly 1 away from the objects). This departs
//!    from paper 001 Fig. 7, which filters E_R with bandwidths from the real geometry
//!    alone: here occluders and Phong exponents of the virtual objects narrow E_R's
//!    filter too, so near the objects E_R keeps a little more noise (no bias).
//! 4. Temporal (eqs. 24-26, `temporal = true`): each pixel's world position is projected
//!    into the previous camera (previous pose, same intrinsics), rounded to a pixel, and
//!    the 3 x 3 window around it is searched for the nearest previous world position
//!    (x', y'); the Y pass adds the taps w' E'_X(x', y' + j) over the same radius, with
//!    w' of eq. 25 taking eq. 23's averaged Bbar^2 (the pixel's B^2 with the previous
//!    pixel's) where eq. 25 has the pixel's B_X alone. E'_X is the previous
//!    frame's X-filtered layers (filtered about their own pixels, not re-filtered about
//!    p(x, y) as in eq. 24). A first frame, a size change, or a pixel behind the
//!    previous camera or off its image, uses the spatial filter alone.
//!
//! Recording length: the filter needs only its one previous frame. Its gain drops on
//! short synthetic recordings for another reason: their camera's color changes faster
//! than `color.compensate` follows, and the captured light inherits the error (see
//! [`relume_recording::synth::camera::STEADY_COLOR_FRAMES`] for the measurements).
//!
//! B_e (`environment_bandwidth` = 0): the 99 %-energy radius of the environment map's
//! lat-long spectrum ([`environment_bandwidth`]), computed once per map (cached on the
//! `Arc` of the map: `light.envmap` reuses one map, `light.impostor` makes a new one per
//! frame).
//!
//! Outputs: `filtered_e_r_dir`, `filtered_e_r_ind`, `filtered_e_rv_dir`,
//! `filtered_e_rv_ind` and the filter sizes 1 / B in metres (`filter_width_dir`: mean of
//! the X and Y sizes; `filter_width_ind`), as paper 001 Fig. 7 shows them (it calls 1 / B
//! the standard deviation; eq. 23's Gaussian has 1 / (2 Bbar)); INFINITY where B = 0
//! (flat over the window), NaN where there is no position.
//!
//! Cost: per pixel and kind (direct, indirect) 3 windows of 2R + 1 taps (X, Y, temporal
//! Y), each tap 8 multiply-adds and a fast `exp` ([`gaussian::exp_neg_lanes`]) shared by
//! E_R and E_RV; the X and Y windows weigh each pair of pixels once (eq. 23 is
//! symmetric), so they take R + 1 `exp` per pixel, not 2 R + 1. The passes ([`passes`])
//! take eight target pixels at a time, one per lane of an AVX2 + FMA vector where the
//! CPU has them (a portable kernel with the same bits elsewhere, [`relume_base::simd`]), from
//! lane-interleaved planes ([`lane_planes`]) in which every spatial tap of the eight
//! targets is one aligned load per plane: the X pass eight pixels S apart in a row
//! (pixels l S + j, S = 80 at 640 wide), the Y pass eight neighbours in a row (pixels
//! 8 n + l), walking down the image. The temporal taps are one aligned load per plane
//! too where the eight targets found their previous pixels at one offset that is a
//! multiple of 8, two blended loads at any other common offset, two permuted loads per
//! line where the offsets differ but the previous pixels lie in two neighbouring blocks
//! and on at most three lines (most groups under a moving camera), and gathered per
//! lane elsewhere (see `passes`). Steps 1-2 and the X pass run row by row
//! ([`passes::prepare_x_pass`]): a row's planes are prepared into a one-line set that
//! stays in the cache and filtered from there, so the input planes of the whole image
//! (38 MB at 640x480 and R = 15) are never written out and read back. No tap
//! cutting: at R = 15 and 640x480 a weight falls below e^-14 inside the window only
//! where B exceeds ~60 per metre (occluders nearer than ~8 cm), so a per-pixel radius
//! bound would rarely help.
//! E_RV is always summed in full: on real frames the objects change E_RV a little almost
//! everywhere (2-6 % of the pixels of the built-in recording's frames 10-13 have
//! E_RV == E_R), so a shortcut for E_RV == E_R rarely applies.
//! `benches/filter.rs` measures the whole filter and each pass.

pub mod bandwidth;
pub mod gaussian;
pub mod lane_planes;
pub mod layout;
pub mod passes;
pub mod planes;
mod prepare_lanes;
#[cfg(test)]
mod prepare_tests;
pub mod spectrum;
pub mod temporal;

#[cfg(test)]
mod tests;

pub use bandwidth::{direct_bandwidth, indirect_bandwidth, screen_curvature};
pub use spectrum::environment_bandwidth;

use crate::kind::FrameProducts;
use crate::{OpError, kind};
use glam::{Affine3A, Vec3};
use lane_planes::LaneLayout;
use layout::{BandwidthSettings, PrepareInputs, X_PLANES};
use passes::{Previous, XSet};
use relume_base::pinhole::Pinhole;
use relume_base::raster::{Image, ScalarImage, Vec3Image};
use relume_base::simd::Kernel;
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Params, Port, Ports, Product, ProductKind, Stage, StageError,
    StageInfo,
};
use relume_recording::{Intrinsics, Pose};
use relume_scene::light::EnvMap;
use std::sync::Arc;
use temporal::PreviousView;

pub use gaussian::MAX_RADIUS;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "radius",
        ParamDefault::Int(15),
        "taps |i| <= radius on each side per pass (15: 31 taps, the paper's 30 x 30 neighbourhood)",
    )
    .range(1.0, MAX_RADIUS as f64),
    ParamSpec::new(
        "b_f",
        ParamDefault::Float(1.0),
        "angular bandwidth B_f of the diffuse cosine in eq. 17, per radian (paper 001 Fig. 4: 1)",
    )
    .range(0.0, 100.0),
    ParamSpec::new(
        "environment_bandwidth",
        ParamDefault::Float(0.0),
        "B_e of eq. 17 per radian; 0 = the 99 % energy bandwidth of the environment map's spectrum (paper 001 Sec. 7; the paper's scenes use 4)",
    )
    .range(0.0, 1000.0),
    ParamSpec::new(
        "temporal",
        ParamDefault::Bool(true),
        "extend the Y pass to the previous frame's X-filtered layers at the reprojected pixel (eqs. 24-26)",
    ),
];

/// Input roles; `environment` only when B_e is computed, `pose` only when temporal.
const INPUTS: [(&str, &[ProductKind]); 11] = [
    ("e_r_dir", &[kind::RADIANCE]),
    ("e_r_ind", &[kind::RADIANCE]),
    ("e_rv_dir", &[kind::RADIANCE]),
    ("e_rv_ind", &[kind::RADIANCE]),
    ("world_position", &[kind::POINTS]),
    ("world_normal", &[kind::NORMALS]),
    ("direct_min_distance", &[kind::SCALAR]),
    ("indirect_min_distance", &[kind::SCALAR]),
    ("exponent", &[kind::SCALAR]),
    ("environment", &[kind::ENVIRONMENT]),
    ("pose", &[kind::POSE]),
];

const OUTPUTS: [(&str, &[ProductKind]); 6] = [
    ("filtered_e_r_dir", &[kind::RADIANCE]),
    ("filtered_e_r_ind", &[kind::RADIANCE]),
    ("filtered_e_rv_dir", &[kind::RADIANCE]),
    ("filtered_e_rv_ind", &[kind::RADIANCE]),
    ("filter_width_dir", &[kind::SCALAR]),
    ("filter_width_ind", &[kind::SCALAR]),
];

fn uses_input(params: &Params, role: &str) -> bool {
    match role {
        "environment" => params.float("environment_bandwidth") <= 0.0,
        "pose" => params.bool("temporal"),
        _ => true,
    }
}

pub const INFO: StageInfo = StageInfo {
    kind: "filter.axis_aligned",
    summary: "axis-aligned world-space Gaussian filtering of the irradiance layers, with temporal reuse (paper 001 Secs. 6-7)",
    params: PARAMS,
    ports: |p| Ports {
        inputs: INPUTS
            .iter()
            .filter(|(role, _)| uses_input(p, role))
            .map(|(role, kinds)| Port::new(role, role, kinds))
            .collect(),
        outputs: OUTPUTS
            .iter()
            .map(|(role, kinds)| Port::new(role, role, kinds))
            .collect(),
    },
    build: |ctx| {
        let params = FilterParams::from_params(ctx.params);
        params.check()?;
        Ok(Box::new(FilterStage {
            inputs: INPUTS.map(|(role, _)| ctx.input(role)),
            outputs: OUTPUTS.map(|(role, _)| ctx.output(role)),
            intrinsics: ctx.header.depth_intrinsics,
            filter: AxisAlignedFilter::new(params),
        }))
    },
};

/// Settings of [`AxisAlignedFilter`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterParams {
    /// Taps |i| <= radius per pass.
    pub radius: usize,
    /// B_f of eq. 17, per radian.
    pub b_f: f32,
    /// B_e of eq. 17, per radian; 0 = computed from the environment map.
    pub environment_bandwidth: f32,
    /// Temporal extension (eqs. 24-26).
    pub temporal: bool,
}

impl Default for FilterParams {
    fn default() -> Self {
        FilterParams {
            radius: 15,
            b_f: 1.0,
            environment_bandwidth: 0.0,
            temporal: true,
        }
    }
}

impl FilterParams {
    pub fn from_params(p: &Params) -> FilterParams {
        FilterParams {
            radius: p.int("radius") as usize,
            b_f: p.float("b_f") as f32,
            environment_bandwidth: p.float("environment_bandwidth") as f32,
            temporal: p.bool("temporal"),
        }
    }

    /// Checks the radius and bandwidths; the error names the bad value.
    pub fn check(&self) -> Result<(), OpError> {
        if !(1..=MAX_RADIUS).contains(&self.radius) {
            return Err(OpError::BadParameter(format!(
                "filter.axis_aligned: radius is {}, expected 1..={MAX_RADIUS}",
                self.radius
            )));
        }
        let ok = |b: f32| b.is_finite() && b >= 0.0;
        if !ok(self.b_f) || !ok(self.environment_bandwidth) {
            return Err(OpError::BadParameter(format!(
                "filter.axis_aligned: b_f {} / environment_bandwidth {} must be finite and >= 0",
                self.b_f, self.environment_bandwidth
            )));
        }
        Ok(())
    }
}

/// What [`AxisAlignedFilter::filter`] reads for one frame (all images of one size).
#[derive(Clone, Copy)]
pub struct FilterInputs<'a> {
    /// E_R^dir, E_R^ind, E_RV^dir, E_RV^ind (NaN = no estimate).
    pub layers: [&'a Vec3Image; 4],
    /// World positions (non-finite = none) and normals (zero = invalid).
    pub world_position: &'a Vec3Image,
    pub world_normal: &'a Vec3Image,
    /// `sample.*`'s nearest direct occluder as t / cos(theta) (so eq. 17's
    /// cos^2(theta_occ) / z is its inverse) and nearest indirect hit, in metres
    /// (INFINITY = none).
    pub direct_min_distance: &'a ScalarImage,
    pub indirect_min_distance: &'a ScalarImage,
    /// Mean Phong exponent of the virtual primaries (0 = diffuse).
    pub exponent: &'a ScalarImage,
    /// The environment map for B_e (unused when `environment_bandwidth` > 0).
    pub environment: Option<&'a Arc<EnvMap>>,
    /// The camera's pose and the camera at this image size, for the temporal filter.
    pub view: Option<(Pose, Pinhole)>,
}

/// The filtered layers (same order as the inputs) and the filter widths.
#[derive(Clone, Debug, PartialEq)]
pub struct FilterOutputs {
    pub layers: [Vec3Image; 4],
    pub width_dir: ScalarImage,
    pub width_ind: ScalarImage,
}

impl FilterOutputs {
    pub fn new(width: u32, height: u32) -> FilterOutputs {
        let v = || Image::filled(width, height, Vec3::NAN);
        FilterOutputs {
            layers: [v(), v(), v(), v()],
            width_dir: Image::filled(width, height, f32::NAN),
            width_ind: Image::filled(width, height, f32::NAN),
        }
    }
}

/// The filter with its buffers and the previous frame's state (kept across frames).
pub struct AxisAlignedFilter {
    params: FilterParams,
    kernel: Kernel,
    /// This frame's X set (the X pass's output).
    x_set: XSet,
    /// The previous frame's X set (swapped with `x_set` after each frame).
    previous_x_set: XSet,
    previous_view: Option<PreviousView>,
    /// B_e of the last environment map, keyed by its `Arc`.
    environment_cache: Option<(Arc<EnvMap>, f32)>,
}

impl AxisAlignedFilter {
    /// The filter with the fastest kernel this CPU runs.
    pub fn new(params: FilterParams) -> AxisAlignedFilter {
        AxisAlignedFilter::with_kernel(params, Kernel::detect())
    }

    /// The filter with the given kernel (all kernels give the same bits).
    pub fn with_kernel(params: FilterParams, kernel: Kernel) -> AxisAlignedFilter {
        AxisAlignedFilter {
            params,
            kernel,
            x_set: XSet::default(),
            previous_x_set: XSet::default(),
            previous_view: None,
            environment_cache: None,
        }
    }

    /// B_e for this frame: the parameter, or the (cached) spectrum bandwidth of the map.
    fn environment_bandwidth(&mut self, map: Option<&Arc<EnvMap>>) -> Result<f32, OpError> {
        if self.params.environment_bandwidth > 0.0 {
            return Ok(self.params.environment_bandwidth);
        }
        let map = map.ok_or_else(|| {
            OpError::BadInput(
                "filter.axis_aligned: no environment map given and environment_bandwidth is 0"
                    .into(),
            )
        })?;
        if let Some((cached, b_e)) = &self.environment_cache
            && Arc::ptr_eq(cached, map)
        {
            return Ok(*b_e);
        }
        let b_e = environment_bandwidth(map);
        self.environment_cache = Some((Arc::clone(map), b_e));
        Ok(b_e)
    }

    /// Filters one frame into `out` (sized like the inputs) and keeps what the next
    /// frame's temporal filter needs.
    pub fn filter(&mut self, input: &FilterInputs, out: &mut FilterOutputs) -> Result<(), OpError> {
        let first = input.layers[0];
        let (w, h) = (first.width, first.height);
        let sizes = [
            (input.layers[1].width, input.layers[1].height),
            (input.layers[2].width, input.layers[2].height),
            (input.layers[3].width, input.layers[3].height),
            (input.world_position.width, input.world_position.height),
            (input.world_normal.width, input.world_normal.height),
            (
                input.direct_min_distance.width,
                input.direct_min_distance.height,
            ),
            (
                input.indirect_min_distance.width,
                input.indirect_min_distance.height,
            ),
            (input.exponent.width, input.exponent.height),
            (out.layers[0].width, out.layers[0].height),
            (out.layers[1].width, out.layers[1].height),
            (out.layers[2].width, out.layers[2].height),
            (out.layers[3].width, out.layers[3].height),
            (out.width_dir.width, out.width_dir.height),
            (out.width_ind.width, out.width_ind.height),
        ];
        if let Some(bad) = sizes.iter().position(|&s| s != (w, h)) {
            return Err(OpError::SizeMismatch(format!(
                "filter.axis_aligned: e_r_dir is {w}x{h} but input/output #{} is {}x{} \
                 (order: e_r_ind, e_rv_dir, e_rv_ind, world_position, world_normal, \
                 direct_min_distance, indirect_min_distance, exponent, outputs)",
                bad + 2,
                sizes[bad].0,
                sizes[bad].1
            )));
        }
        if w == 0 || h == 0 {
            return Ok(());
        }
        let b_e = self.environment_bandwidth(input.environment)?;
        let (wu, hu) = (w as usize, h as usize);
        let planes = self.x_set.planes();
        if (planes.width, planes.height) != (wu, hu) {
            let radius = self.params.radius;
            self.x_set = XSet::new(LaneLayout::blocks(X_PLANES, wu, hu, radius));
            self.previous_x_set = self.x_set.clone();
            self.previous_view = None;
        }
        let settings = BandwidthSettings {
            b_f: self.params.b_f,
            b_e,
        };
        let prepare_inputs = PrepareInputs {
            layers: input.layers,
            world_position: input.world_position,
            world_normal: input.world_normal,
            direct_min_distance: input.direct_min_distance,
            indirect_min_distance: input.indirect_min_distance,
            exponent: input.exponent,
        };
        let radius = self.params.radius;
        passes::prepare_x_pass(
            self.kernel,
            &prepare_inputs,
            settings,
            radius,
            &mut self.x_set,
            [&mut out.width_dir, &mut out.width_ind],
        );
        let previous = match (&self.previous_view, self.params.temporal) {
            (Some(view), true) => Some(Previous {
                x_set: &self.previous_x_set,
                view,
            }),
            _ => None,
        };
        passes::y_pass(
            self.kernel,
            &mut self.x_set,
            previous,
            radius,
            &mut out.layers,
        );
        std::mem::swap(&mut self.x_set, &mut self.previous_x_set);
        self.previous_view = match (self.params.temporal, input.view) {
            (true, Some((pose, camera))) => Some(PreviousView {
                world_to_camera: Affine3A::from_mat4(pose.matrix().inverse().as_mat4()),
                camera,
            }),
            _ => None,
        };
        Ok(())
    }
}

struct FilterStage {
    inputs: [String; 11],
    outputs: [String; 6],
    intrinsics: Intrinsics,
    filter: AxisAlignedFilter,
}

impl Stage for FilterStage {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let [
            e_r_dir,
            e_r_ind,
            e_rv_dir,
            e_rv_ind,
            position,
            normal,
            zd,
            zi,
            exponent,
            env,
            pose,
        ] = &self.inputs;
        let params = self.filter.params;
        let layers = [
            frame.radiance(e_r_dir)?,
            frame.radiance(e_r_ind)?,
            frame.radiance(e_rv_dir)?,
            frame.radiance(e_rv_ind)?,
        ];
        let (w, h) = (layers[0].width, layers[0].height);
        let environment = if params.environment_bandwidth > 0.0 {
            None
        } else {
            Some(frame.environment(env)?)
        };
        let view = if params.temporal {
            Some((*frame.pose(pose)?, Pinhole::new(&self.intrinsics, w, h)))
        } else {
            None
        };
        let input = FilterInputs {
            layers,
            world_position: frame.points(position)?,
            world_normal: frame.normals(normal)?,
            direct_min_distance: frame.scalar(zd)?,
            indirect_min_distance: frame.scalar(zi)?,
            exponent: frame.scalar(exponent)?,
            environment,
            view,
        };
        let mut out = FilterOutputs::new(w, h);
        self.filter.filter(&input, &mut out)?;
        let FilterOutputs {
            layers: [a, b, c, d],
            width_dir,
            width_ind,
        } = out;
        let products = [
            Product::new(kind::RADIANCE, a),
            Product::new(kind::RADIANCE, b),
            Product::new(kind::RADIANCE, c),
            Product::new(kind::RADIANCE, d),
            Product::new(kind::SCALAR, width_dir),
            Product::new(kind::SCALAR, width_ind),
        ];
        for (name, product) in self.outputs.iter().zip(products) {
            frame.insert(name, product);
        }
        Ok(())
    }
}
