//! `composite.differential` (paper 001 eq. 2, paper 000 Sec. 6.6): the finished
//! mixed-reality frame from the camera image and the four irradiance layers.
//!
//! Per pixel, in the compensated (reference) linear space where the light was sampled:
//!
//! L_final = (1 - M) k_V E_RV / pi + M (E_RV / E_R) L_cam
//!
//! with E = E^dir + E^ind per channel, M the fraction of the pixel that shows real
//! geometry and L_cam the compensated camera radiance. The `/ pi` is relume's
//! convention for the virtual term: `sample.*` report E in irradiance units (a constant
//! environment L gives pi L), and a Lambertian surface of albedo k_V reflects
//! k_V E / pi (paper 001 writes k_V E_RV with the pi folded into E). Then the inverse
//! color compensation c_t^-1 takes the frame back into the camera's linear space
//! (`final_hdr`), and gamma encoding to 8 bits gives `final`, which looks like the
//! camera's own image wherever the objects change nothing.
//!
//! `form = "difference"` composites by paper 002's tone-mapped difference instead
//! (see `difference.rs` for the form and its trade-off against the ratio).
//!
//! The differential ratio E_RV / E_R is exactly 1 wherever the two estimates are equal
//! (`sample.path` makes them equal bit for bit where no path met an object, and
//! `filter.axis_aligned` keeps them so), so those pixels come back as the camera's
//! levels. Elsewhere it is E_RV / max(E_R, `min_irradiance`), clamped to
//! [0, `max_ratio`]; where either estimate is missing (no real shading point) the
//! camera pixel is kept (ratio 1).

mod difference;
mod encode;
#[cfg(test)]
mod tests;

pub use encode::GammaEncoder;

use crate::kind::FrameProducts;
use crate::{OpError, kind};
use glam::{Mat3, Vec3, Vec3A};
use rayon::prelude::*;
use relume_base::raster::{Image, Rgb8Image, ScalarImage, Vec3Image};
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Params, Port, Ports, Product, ProductKind, Stage, StageError,
    StageInfo,
};
use std::f32::consts::FRAC_1_PI;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "gamma",
        ParamDefault::Float(2.2),
        "display gamma of the 8-bit output; keep it equal to color.compensate's input_gamma \
         so that untouched pixels come back as the camera's own levels",
    )
    .range(1.0, 3.0),
    ParamSpec::new(
        "form",
        ParamDefault::Str("ratio"),
        "ratio = paper 001 eq. 2, the camera pixel scaled by E_RV / E_R; difference = paper 002 Sec. 3.1, TM(L_rv) - TM(L_r) added to the tone-mapped camera pixel, the camera's color as the real albedo (no division, but an absolute change that the albedo approximation sets)",
    )
    .choices(&["ratio", "difference"]),
    ParamSpec::new(
        "max_ratio",
        ParamDefault::Float(4.0),
        "the differential ratio E_RV / E_R is clamped to [0, max_ratio]: where E_R is \
         tiny, noise in it would otherwise blow up dark camera pixels",
    )
    .range(1.0, 1e6),
    ParamSpec::new(
        "min_irradiance",
        ParamDefault::Float(1e-4),
        "E_R below this (per channel) counts as this in the ratio",
    )
    .range(0.0, 1e9),
];

/// (role, default product, kinds) of the inputs, in [`CompositeStage::inputs`] order.
const INPUTS: [(&str, &str, &[ProductKind]); 8] = [
    ("e_r_dir", "filtered_e_r_dir", &[kind::RADIANCE]),
    ("e_r_ind", "filtered_e_r_ind", &[kind::RADIANCE]),
    ("e_rv_dir", "filtered_e_rv_dir", &[kind::RADIANCE]),
    ("e_rv_ind", "filtered_e_rv_ind", &[kind::RADIANCE]),
    ("mask", "mask", &[kind::SCALAR]),
    ("k_v", "k_v", &[kind::RADIANCE]),
    ("radiance", "compensated", &[kind::RADIANCE]),
    ("compensation", "compensation", &[kind::COMPENSATION]),
];

const OUTPUTS: [(&str, &[ProductKind]); 3] = [
    ("final", &[kind::COLOR]),
    ("final_hdr", &[kind::RADIANCE]),
    ("differential", &[kind::RADIANCE]),
];

pub const INFO: StageInfo = StageInfo {
    kind: "composite.differential",
    summary: "the finished frame: (1 - M) k_V E_RV / pi + M (E_RV / E_R) L_cam, then c_t^-1 and gamma (paper 001 eq. 2)",
    params: PARAMS,
    ports: |_| Ports {
        inputs: INPUTS
            .iter()
            .map(|(role, product, kinds)| Port::new(role, product, kinds))
            .collect(),
        outputs: OUTPUTS
            .iter()
            .map(|(role, kinds)| Port::new(role, role, kinds))
            .collect(),
    },
    build: |ctx| {
        let params = CompositeParams::from_params(ctx.params);
        Ok(Box::new(CompositeStage {
            inputs: INPUTS.map(|(role, _, _)| ctx.input(role)),
            outputs: OUTPUTS.map(|(role, _)| ctx.output(role)),
            encoder: GammaEncoder::new(params.gamma),
            params,
        }))
    },
};

/// Settings of [`composite`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositeParams {
    pub gamma: f32,
    /// Paper 002's tone-mapped difference instead of the ratio.
    pub difference: bool,
    pub max_ratio: f32,
    pub min_irradiance: f32,
}

impl CompositeParams {
    pub fn from_params(p: &Params) -> CompositeParams {
        CompositeParams {
            gamma: p.float("gamma") as f32,
            difference: p.str("form") == "difference",
            max_ratio: p.float("max_ratio") as f32,
            min_irradiance: p.float("min_irradiance") as f32,
        }
    }
}

impl Default for CompositeParams {
    fn default() -> Self {
        CompositeParams {
            gamma: 2.2,
            difference: false,
            max_ratio: 4.0,
            min_irradiance: 1e-4,
        }
    }
}

/// What [`composite`] reads.
#[derive(Clone, Copy)]
pub struct CompositeInputs<'a> {
    /// E_R^dir, E_R^ind, E_RV^dir, E_RV^ind (filtered or not; NaN = no estimate).
    pub e_r_dir: &'a Vec3Image,
    pub e_r_ind: &'a Vec3Image,
    pub e_rv_dir: &'a Vec3Image,
    pub e_rv_ind: &'a Vec3Image,
    /// M: the fraction of the pixel showing real geometry.
    pub mask: &'a ScalarImage,
    /// k_V: the albedo of the virtual primaries.
    pub k_v: &'a Vec3Image,
    /// L_cam: the camera image in the compensated linear space.
    pub radiance: &'a Vec3Image,
    /// c_t^-1: from the compensated space back to the camera's linear space.
    pub inverse_compensation: Mat3,
}

/// The products of [`composite`].
#[derive(Clone, Debug, PartialEq)]
pub struct CompositeOutputs {
    /// The finished frame, gamma-encoded 8-bit in the camera's color space.
    pub final_color: Rgb8Image,
    /// The finished frame, linear HDR in the camera's color space.
    pub final_hdr: Vec3Image,
    /// E_RV / E_R per channel as used (1 where unchanged or unknown).
    pub differential: Vec3Image,
}

impl CompositeOutputs {
    pub fn new(width: u32, height: u32) -> CompositeOutputs {
        CompositeOutputs {
            final_color: Image::zeroed(width, height),
            final_hdr: Image::zeroed(width, height),
            differential: Image::zeroed(width, height),
        }
    }
}

/// The differential ratio E_RV / E_R of one channel: exactly 1 where the estimates are
/// equal or either is missing; else E_RV / max(E_R, `min_irradiance`) in
/// [0, `max_ratio`].
#[inline]
pub fn differential_ratio(e_r: f32, e_rv: f32, params: &CompositeParams) -> f32 {
    if e_rv == e_r || !e_r.is_finite() || !e_rv.is_finite() {
        1.0
    } else {
        // max(E_R, min) spelled out (f32::max leaves the sign of a zero open), so that
        // [`differential_ratio3`] gives the same bits; E_R = -0 counts as min.
        let min = params.min_irradiance;
        (e_rv / if e_r > min { e_r } else { min }).clamp(0.0, params.max_ratio)
    }
}

/// [`differential_ratio`] of the three channels at once (one SIMD division; the same
/// bits per channel: real frames take this path on most pixels, because the objects
/// block some light everywhere).
#[inline]
pub fn differential_ratio3(e_r: Vec3, e_rv: Vec3, params: &CompositeParams) -> Vec3 {
    let (e_r, e_rv) = (Vec3A::from(e_r), Vec3A::from(e_rv));
    let keep = e_rv.cmpeq(e_r) | !e_r.is_finite_mask() | !e_rv.is_finite_mask();
    let min = Vec3A::splat(params.min_irradiance);
    let quotient = e_rv / Vec3A::select(e_r.cmpgt(min), e_r, min);
    // f32::clamp's comparisons (which keep -0.0, unlike maxps).
    let max_ratio = Vec3A::splat(params.max_ratio);
    let bounded = Vec3A::select(
        quotient.cmplt(Vec3A::ZERO),
        Vec3A::ZERO,
        Vec3A::select(quotient.cmpgt(max_ratio), max_ratio, quotient),
    );
    Vec3A::select(keep, Vec3A::ONE, bounded).into()
}

/// The composite of one pixel in the compensated linear space (paper 001 eq. 2 with
/// relume's `/ pi`), and the ratio it used.
#[inline]
pub fn composite_pixel(
    e_r: Vec3,
    e_rv: Vec3,
    mask: f32,
    k_v: Vec3,
    camera: Vec3,
    params: &CompositeParams,
) -> (Vec3, Vec3) {
    // Real, and no path met an object: the ratio is exactly 1 (on real frames only a
    // few percent of pixels: the objects block some light everywhere).
    if mask >= 1.0 && e_rv == e_r {
        return (camera, Vec3::ONE);
    }
    let ratio = differential_ratio3(e_r, e_rv, params);
    let real = ratio * camera;
    if mask >= 1.0 {
        return (real, ratio);
    }
    let virtual_radiance = if e_rv.is_finite() {
        k_v * e_rv.max(Vec3::ZERO) * FRAC_1_PI
    } else {
        Vec3::ZERO
    };
    let m = mask.clamp(0.0, 1.0);
    ((1.0 - m) * virtual_radiance + m * real, ratio)
}

/// Composites every pixel (see the module docs) into `out`, which must have the camera
/// image's size.
pub fn composite<'a>(
    inputs: &CompositeInputs<'a>,
    params: &CompositeParams,
    encoder: &GammaEncoder,
    out: &mut CompositeOutputs,
) -> Result<(), OpError> {
    let (w, h) = (inputs.radiance.width, inputs.radiance.height);
    let sizes = [
        ("e_r_dir", inputs.e_r_dir.width, inputs.e_r_dir.height),
        ("e_r_ind", inputs.e_r_ind.width, inputs.e_r_ind.height),
        ("e_rv_dir", inputs.e_rv_dir.width, inputs.e_rv_dir.height),
        ("e_rv_ind", inputs.e_rv_ind.width, inputs.e_rv_ind.height),
        ("mask", inputs.mask.width, inputs.mask.height),
        ("k_v", inputs.k_v.width, inputs.k_v.height),
        ("final", out.final_color.width, out.final_color.height),
        ("final_hdr", out.final_hdr.width, out.final_hdr.height),
        (
            "differential",
            out.differential.width,
            out.differential.height,
        ),
    ];
    for (what, ww, hh) in sizes {
        if (ww, hh) != (w, h) {
            return Err(OpError::SizeMismatch(format!(
                "composite.differential: {what} is {ww}x{hh}, the camera image is {w}x{h}"
            )));
        }
    }
    if !inputs.inverse_compensation.is_finite() {
        return Err(OpError::BadInput(
            "composite.differential: the inverse color compensation is not finite".into(),
        ));
    }
    let width = w as usize;
    if width == 0 || h == 0 {
        return Ok(());
    }
    let inverse = inputs.inverse_compensation;
    (
        out.final_color.data.par_chunks_mut(width),
        out.final_hdr.data.par_chunks_mut(width),
        out.differential.data.par_chunks_mut(width),
    )
        .into_par_iter()
        .enumerate()
        .for_each(|(y, (color_row, hdr_row, ratio_row))| {
            // Rows of exactly `width` pixels: the loop below needs no bounds checks.
            let rows = y * width..(y + 1) * width;
            let row = |image: &'a Vec3Image| &image.data[rows.clone()];
            let (e_r_dir, e_r_ind) = (row(inputs.e_r_dir), row(inputs.e_r_ind));
            let (e_rv_dir, e_rv_ind) = (row(inputs.e_rv_dir), row(inputs.e_rv_ind));
            let (k_v, radiance) = (row(inputs.k_v), row(inputs.radiance));
            let mask = &inputs.mask.data[rows.clone()];
            let (color_row, hdr_row, ratio_row) = (
                &mut color_row[..width],
                &mut hdr_row[..width],
                &mut ratio_row[..width],
            );
            for x in 0..width {
                let e_r = e_r_dir[x] + e_r_ind[x];
                let e_rv = e_rv_dir[x] + e_rv_ind[x];
                let difference = params.difference.then(|| {
                    difference::difference_pixel(
                        e_r,
                        e_rv,
                        mask[x],
                        k_v[x],
                        radiance[x],
                        inverse,
                        params.gamma,
                    )
                });
                if let Some(Some(camera)) = difference {
                    hdr_row[x] = camera;
                    ratio_row[x] = differential_ratio3(e_r, e_rv, params);
                    color_row[x] = [
                        encoder.level(camera.x),
                        encoder.level(camera.y),
                        encoder.level(camera.z),
                    ];
                    continue;
                }
                let (reference, ratio) =
                    composite_pixel(e_r, e_rv, mask[x], k_v[x], radiance[x], params);
                let camera = inverse * reference;
                hdr_row[x] = camera;
                ratio_row[x] = ratio;
                color_row[x] = [
                    encoder.level(camera.x),
                    encoder.level(camera.y),
                    encoder.level(camera.z),
                ];
            }
        });
    Ok(())
}

struct CompositeStage {
    /// Product names in [`INPUTS`] order.
    inputs: [String; 8],
    outputs: [String; 3],
    params: CompositeParams,
    encoder: GammaEncoder,
}

impl Stage for CompositeStage {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let [
            e_r_dir,
            e_r_ind,
            e_rv_dir,
            e_rv_ind,
            mask,
            k_v,
            radiance,
            compensation,
        ] = &self.inputs;
        let radiance = frame.radiance(radiance)?;
        let inputs = CompositeInputs {
            e_r_dir: frame.radiance(e_r_dir)?,
            e_r_ind: frame.radiance(e_r_ind)?,
            e_rv_dir: frame.radiance(e_rv_dir)?,
            e_rv_ind: frame.radiance(e_rv_ind)?,
            mask: frame.scalar(mask)?,
            k_v: frame.radiance(k_v)?,
            radiance,
            inverse_compensation: frame.compensation(compensation)?.inverse,
        };
        let mut out = CompositeOutputs::new(radiance.width, radiance.height);
        composite(&inputs, &self.params, &self.encoder, &mut out)?;
        let [final_color, final_hdr, differential] = &self.outputs;
        frame.insert(final_color, Product::new(kind::COLOR, out.final_color));
        frame.insert(final_hdr, Product::new(kind::RADIANCE, out.final_hdr));
        frame.insert(differential, Product::new(kind::RADIANCE, out.differential));
        Ok(())
    }
}
