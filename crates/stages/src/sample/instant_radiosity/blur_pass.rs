//! What one pass of the blur reads, shared by the scalar pixel of `blur.rs` and the
//! lanes of `blur_lanes.rs`: the layers ([`PassInputs`]), a row's taps ([`Taps`]) and
//! the tangent-plane tolerance.

use super::points::RealSurface;
use crate::sample::layers::IrradianceLayers;

/// Metres a neighbour may lie off a pixel's tangent plane and still be averaged in.
pub const PLANE_TOLERANCE: f32 = 0.03;

/// The layers a pass reads: `input`'s light layers, `geometry`'s visible surface and
/// mask (the raw layers), and the real surface.
pub(super) struct PassInputs<'a> {
    pub geometry: &'a IrradianceLayers,
    pub input: &'a IrradianceLayers,
    pub real: &'a RealSurface,
}

/// One pass's geometry of the row: pixel `x` of `row` is pixel `start + x` of the
/// images, its taps those at `start + x + t stride`, t in `-lo..=hi`.
#[derive(Clone, Copy)]
pub(super) struct Taps {
    pub start: usize,
    pub stride: usize,
    pub lo: usize,
    pub hi: usize,
}
