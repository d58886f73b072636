//! The filter's planes (paper 001 Sec. 7): one f32 plane per quantity (the plane
//! indices of the input set and the X set), and the preparation pass that fills the
//! input planes (positions, bandwidths, cleaned values) from the stage's images. The
//! sets are lane-interleaved ([`super::lane_planes`]); the preparation writes each row
//! plainly first, eight consecutive pixels at a time ([`RowLayout`]), then interleaves it.

use super::bandwidth::{brdf_bandwidth, curvature_at, direct_bandwidth, indirect_bandwidth};
use super::gaussian::VALUE_PLANES;
use super::lane_planes::{LaneLayout, LanePlanes, fill_line};
use super::prepare_lanes::{RowOut, prepare_group};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::{ScalarImage, Vec3Image};
use relume_base::simd::{Kernel, LANES, Lanes, Portable};

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

/// The shape of one prepared row before [`fill_line`] interleaves it: the planes one
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

/// Fills the input planes `input` ([`INPUT_PLANES`] lane-interleaved planes of the
/// images' size) with positions, squared bandwidths (eqs. 17, 18 from the curvatures of
/// eq. 20) and cleaned values (0 with valid 0 where a layer has no finite value or the
/// pixel no position), and writes the filter sizes 1 / B (paper 001 Fig. 7; direct: mean
/// of the X and Y sizes; INFINITY where B = 0, NaN where there is no position). Eight pixels
/// at a time (`prepare_lanes`, with `kernel`) where a row's X neighbours of all eight
/// exist, one by one at the row's ends; the same bits either way. Each row is prepared
/// in row-major order (`row_scratch`), then interleaved ([`fill_line`]). The stage
/// prepares one row at a time instead, each just before its X pass
/// ([`super::passes::prepare_x_pass`], the same bits).
pub fn prepare(
    kernel: Kernel,
    images: &PrepareInputs,
    settings: BandwidthSettings,
    input: &mut LanePlanes,
    width_dir: &mut ScalarImage,
    width_ind: &mut ScalarImage,
) {
    let (w, h) = (input.width, input.height);
    if w == 0 || h == 0 {
        return;
    }
    let kernel = kernel.available();
    let lanes = input.layout();
    let layout = row_scratch(&lanes);
    input
        .bands_mut(1)
        .zip(width_dir.data.par_chunks_mut(w))
        .zip(width_ind.data.par_chunks_mut(w))
        .enumerate()
        .for_each_init(
            || vec![0.0; layout.row_step()],
            |scratch, (y, ((line, width_dir), width_ind))| {
                let mut out = RowOut {
                    row: scratch,
                    width_dir,
                    width_ind,
                };
                match kernel {
                    #[cfg(target_arch = "x86_64")]
                    // SAFETY: `kernel` came from `Kernel::available`: the CPU has AVX2 and
                    // FMA.
                    Kernel::Avx2Fma => unsafe {
                        prepare_row_avx2(images, settings, &layout, &lanes, y, &mut out, line)
                    },
                    _ => prepare_line::<Portable>(
                        images, settings, &layout, &lanes, y, &mut out, line,
                    ),
                }
            },
        );
}

/// The layout of one prepared row before [`fill_line`] interleaves it: padded wide
/// enough for the lane planes' halos (and the runs of eight that the fill reads).
pub(super) fn row_scratch(lanes: &LaneLayout) -> RowLayout {
    let pad = lanes.slots() * LANES - lanes.width + 2 * LANES + lanes.halo();
    RowLayout::new(INPUT_PLANES, lanes.width, lanes.height, pad)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn prepare_row_avx2(
    images: &PrepareInputs,
    settings: BandwidthSettings,
    layout: &RowLayout,
    lanes: &LaneLayout,
    y: usize,
    out: &mut RowOut,
    line: &mut [f32],
) {
    prepare_line::<relume_base::simd::Avx2>(images, settings, layout, lanes, y, out, line);
}

/// [`prepare`] for row `y` into `line`, a line of a set of `lanes`' layout: the row's
/// planes into `out` (row-major, in `layout`), then interleaved into the line.
#[inline(always)]
pub(super) fn prepare_line<V: Lanes>(
    images: &PrepareInputs,
    settings: BandwidthSettings,
    layout: &RowLayout,
    lanes: &LaneLayout,
    y: usize,
    out: &mut RowOut,
    line: &mut [f32],
) {
    prepare_row::<V>(images, settings, layout, y, out);
    fill_line::<V>(lanes, out.row, |q| layout.in_row(q, 0), line);
}

/// [`prepare`] for row `y`: groups of eight pixels from x = 1 while pixel x + 8 is
/// inside the row, single pixels before and after.
#[inline(always)]
fn prepare_row<V: Lanes>(
    images: &PrepareInputs,
    settings: BandwidthSettings,
    layout: &RowLayout,
    y: usize,
    out: &mut RowOut,
) {
    let w = layout.width;
    let groups = if w > LANES + 1 { (w - 2) / LANES } else { 0 };
    let lanes_end = 1 + groups * LANES;
    for x0 in (1..lanes_end).step_by(LANES) {
        prepare_group::<V>(images, settings, layout, y, x0, out);
    }
    for x in (0..1.min(w)).chain(lanes_end..w) {
        prepare_pixel(images, settings, layout, y, x, out);
    }
}

/// [`prepare`] for pixel (x, y) alone.
pub(super) fn prepare_pixel(
    images: &PrepareInputs,
    settings: BandwidthSettings,
    layout: &RowLayout,
    y: usize,
    x: usize,
    out: &mut RowOut,
) {
    let i = y * layout.width + x;
    let (kx, ky) = curvature_at(images.world_position, images.world_normal, x, y);
    let mut put = |q: usize, v: f32| out.row[layout.in_row(q, x)] = v;
    let p = images.world_position.data[i];
    let has_position = p.is_finite();
    let m = images.exponent.data[i];
    let m = if m.is_finite() { m.max(0.0) } else { 0.0 };
    let b_rho = brdf_bandwidth(m);
    let zd = images.direct_min_distance.data[i];
    let zi = images.indirect_min_distance.data[i];
    let bx = direct_bandwidth(kx, zd, settings.b_f, b_rho, settings.b_e);
    let by = direct_bandwidth(ky, zd, settings.b_f, b_rho, settings.b_e);
    let bi = indirect_bandwidth(zi, m);
    let stored = if has_position {
        p
    } else {
        Vec3::splat(MISSING_POSITION)
    };
    put(PX, stored.x);
    put(PY, stored.y);
    put(PZ, stored.z);
    let keep = |b: f32| if has_position { b * b } else { 0.0 };
    put(B2X_DIR, keep(bx));
    put(B2Y_DIR, keep(by));
    put(B2_IND, keep(bi));
    for (kind, r, rv) in [(DIR, 0, 2), (IND, 1, 3)] {
        for (slot, layer) in [(0, r), (3, rv)] {
            let v = images.layers[layer].data[i];
            let ok = has_position && v.is_finite();
            let v = if ok { v } else { Vec3::ZERO };
            put(kind + slot, v.x);
            put(kind + slot + 1, v.y);
            put(kind + slot + 2, v.z);
            put(kind + 6 + slot / 3, if ok { 1.0 } else { 0.0 });
        }
    }
    let size = |b: f32| 1.0 / b;
    out.width_dir[x] = if has_position {
        0.5 * (size(bx) + size(by))
    } else {
        f32::NAN
    };
    out.width_ind[x] = if has_position { size(bi) } else { f32::NAN };
}
