//! A frame's color compensation as a product: c_t, its inverse, A_t and the pair counts
//! (paper 000 Sec. 4).

use glam::{Mat3, Vec3};
use relume_base::payload::{Payload, ProductKind, digest};
use xxhash_rust::xxh3::Xxh3;

/// A frame's color compensation c_t, its inverse and diagnostics ([`Compensation`]).
pub const COMPENSATION: ProductKind = ProductKind::of::<Compensation>("color compensation");

/// Why sample pairs were kept or rejected by `color.compensate` (paper 000 Sec. 4.1), in
/// the order the tests run: a pair is counted under the first test it fails.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairCounts {
    /// Pixels considered (the whole image).
    pub candidates: u32,
    /// No data in the reference image at that pixel.
    pub no_reference: u32,
    /// Under- or over-saturated in the camera image.
    pub saturated: u32,
    /// A strong color gradient in either image.
    pub gradient: u32,
    /// Too far apart in the hue-saturation plane (first, coarse pass).
    pub hue_saturation: u32,
    /// Too far apart in HSV after applying c_{t-1} (second, strict pass).
    pub hsv: u32,
    /// Pairs that entered the fit.
    pub kept: u32,
}

/// The color compensation of one frame (paper 000 Sec. 4): the 3x3 map c_t from the
/// camera's linearized color to the reference color space, its inverse, the per-channel
/// approximation A_t and what the estimation saw.
#[derive(Clone, Debug, PartialEq)]
pub struct Compensation {
    /// c_t: reference linear RGB = `matrix` * camera linear RGB (C_t of eq. 2, or A_t
    /// when the frame is approximate).
    pub matrix: Mat3,
    /// c_t^-1: back from the reference space into the camera's linear space.
    pub inverse: Mat3,
    /// The diagonal of A_t (per-channel scale s of Sec. 4.2).
    pub gains: Vec3,
    /// Fewer pairs than the minimum: `matrix` is A_t (or c_{t-1} when even A_t had no
    /// pairs), and the frame adds no environment samples.
    pub approximate: bool,
    /// The first frame with no reference: c_0 = I defines the reference space.
    pub initial: bool,
    pub pairs: PairCounts,
}

impl Compensation {
    /// The identity compensation of the first frame (C_0 = I).
    pub fn initial() -> Compensation {
        Compensation {
            matrix: Mat3::IDENTITY,
            inverse: Mat3::IDENTITY,
            gains: Vec3::ONE,
            approximate: false,
            initial: true,
            pairs: PairCounts::default(),
        }
    }

    /// A JSON object with row-major matrices, for files and `relume eval`.
    pub fn to_json(&self) -> serde_json::Value {
        let rows = |m: &Mat3| -> Vec<[f32; 3]> { (0..3).map(|r| m.row(r).to_array()).collect() };
        let p = &self.pairs;
        serde_json::json!({
            "matrix": rows(&self.matrix),
            "inverse": rows(&self.inverse),
            "gains": self.gains.to_array(),
            "approximate": self.approximate,
            "initial": self.initial,
            "pairs": {
                "candidates": p.candidates,
                "kept": p.kept,
                "rejected": {
                    "no_reference": p.no_reference,
                    "saturated": p.saturated,
                    "gradient": p.gradient,
                    "hue_saturation": p.hue_saturation,
                    "hsv": p.hsv,
                },
            },
        })
    }
}

/// The matrices, the gains, the flags, then the pair counts.
impl Payload for Compensation {
    fn digest(&self, h: &mut Xxh3) {
        digest::floats(h, &self.matrix.to_cols_array());
        digest::floats(h, &self.inverse.to_cols_array());
        digest::floats(h, &self.gains.to_array());
        h.update(&[self.approximate as u8, self.initial as u8]);
        let p = &self.pairs;
        for n in [
            p.candidates,
            p.no_reference,
            p.saturated,
            p.gradient,
            p.hue_saturation,
            p.hsv,
            p.kept,
        ] {
            h.update(&n.to_le_bytes());
        }
    }
}
