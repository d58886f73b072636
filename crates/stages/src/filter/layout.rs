//! The filter's planes (paper 001 Sec. 7): one f32 plane per quantity, the plane indices
//! of the input set and the X set, the markers of missing data, a row's plain layout,
//! and what the preparation reads. Every pass and the preparation share these; none of
//! them is imported back.

use super::gaussian::VALUE_PLANES;
use relume_base::raster::{ScalarImage, Vec3Image};
use relume_base::simd::LANES;

/// Input plane indices: world position, squared bandwidths, then the value planes of the
/// direct and indirect kinds (E_R rgb, E_RV rgb, valid_R, valid_RV each).
pub const PX: usize = 0;
pub const PY: usize = 1;
pub const PZ: usize = 2;
pub const B2X_DIR: usize = 3;
pub const B2Y_DIR: usize = 4;
pub const B2_IND: usize = 5;
pub const DIR: usize = 6;
pub const IND: usize = DIR + VALUE_PLANES;
/// Planes of the input set.
pub const INPUT_PLANES: usize = IND + VALUE_PLANES;

/// Plane indices of the X set, the X pass's output and the Y pass's input (lane
/// planes in blocks order, with at least R lines of zeros above and below for the Y
/// pass's taps): world position, the squared bandwidths the Y pass uses, then the
/// X-filtered value planes of both kinds.
pub const X_PX: usize = 0;
pub const X_PY: usize = 1;
pub const X_PZ: usize = 2;
pub const X_B2Y_DIR: usize = 3;
pub const X_B2_IND: usize = 4;
pub const X_DIR: usize = 5;
pub const X_IND: usize = X_DIR + VALUE_PLANES;
/// Planes of the X set.
pub const X_PLANES: usize = X_IND + VALUE_PLANES;

/// A missing world position is stored as this coordinate: far from every real point, so
/// its weight is exactly 0, yet finite (no NaN in the tap loop).
pub const MISSING_POSITION: f32 = 1e15;

/// Squared distances at or above this mean the position is missing.
pub const MISSING_DISTANCE2: f32 = 1e28;

/// The shape of one prepared row before [`fill_line`](super::lane_planes::fill_line) interleaves it: the planes one
/// after the other, each `stride` floats, pixel x of plane q at `in_row(q, x)`, with
/// zero padding on both sides (never written).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RowLayout {
    /// Image size in pixels.
    pub width: usize,
    pub height: usize,
    /// Padding columns on each side.
    pad_x: usize,
    /// Floats per plane row.
    stride: usize,
    planes: usize,
}

impl RowLayout {
    /// `planes` planes of rows of `width` pixels (of an image `height` rows high),
    /// padded by at least `pad` columns on each side.
    pub fn new(planes: usize, width: usize, height: usize, pad: usize) -> RowLayout {
        let pad_x = pad.next_multiple_of(LANES);
        RowLayout {
            width,
            height,
            pad_x,
            stride: pad_x + width.next_multiple_of(LANES) + pad_x,
            planes,
        }
    }

    /// Floats in a row.
    pub fn row_step(&self) -> usize {
        self.planes * self.stride
    }

    /// The index of pixel `x` of plane `q` within the row.
    #[inline(always)]
    pub fn in_row(&self, q: usize, x: usize) -> usize {
        q * self.stride + self.pad_x + x
    }
}

/// What the preparation pass reads (all images of the same size).
pub struct PrepareInputs<'a> {
    /// E_R^dir, E_R^ind, E_RV^dir, E_RV^ind.
    pub layers: [&'a Vec3Image; 4],
    pub world_position: &'a Vec3Image,
    pub world_normal: &'a Vec3Image,
    pub direct_min_distance: &'a ScalarImage,
    pub indirect_min_distance: &'a ScalarImage,
    pub exponent: &'a ScalarImage,
}

/// Bandwidth settings: B_f of eq. 17 and B_e (already resolved).
#[derive(Clone, Copy, Debug)]
pub struct BandwidthSettings {
    pub b_f: f32,
    pub b_e: f32,
}
