//! The filter's planes (paper 001 Sec. 7): one f32 plane per quantity, padded with
//! zeros so that every tap window lies inside them, and the preparation pass that fills
//! the input planes (positions, bandwidths, cleaned values) from the stage's images.
//!
//! Layout: image row by image row, each row holding its planes one after the other, each
//! plane row `stride` floats: [`LANES`] consecutive pixels of a plane are consecutive
//! floats (one vector, one target per lane), a pixel's tap to the right is the next
//! float, the next row is `planes * stride` floats further. The padding (at least
//! R + [`LANES`] - 1 columns on each side, so that the taps |i| <= R of a group of lanes
//! that starts up to [`LANES`] - 1 pixels off the image stay inside) is never written:
//! valid 0, so zero weight. The passes only read along rows, so there are no padding
//! rows.

use super::bandwidth::{brdf_bandwidth, curvature_at, direct_bandwidth, indirect_bandwidth};
use super::gaussian::VALUE_PLANES;
use super::prepare_lanes::{RowOut, prepare_group};
use crate::raster::{ScalarImage, Vec3Image};
use crate::simd::{Kernel, LANES, Lanes, Portable};
use glam::Vec3;
use rayon::prelude::*;

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

/// Plane indices of the column set, the X pass's output and the Y pass's input: the
/// planes of the transposed image (line x is image column x, position y along it), so
/// that the Y pass reads its taps as consecutive floats too. World position, the
/// squared bandwidths the Y pass uses, then the X-filtered value planes of both kinds.
pub const C_PX: usize = 0;
pub const C_PY: usize = 1;
pub const C_PZ: usize = 2;
pub const C_B2Y_DIR: usize = 3;
pub const C_B2_IND: usize = 4;
pub const C_DIR: usize = 5;
pub const C_IND: usize = C_DIR + VALUE_PLANES;
/// Planes of the column set.
pub const COLUMN_PLANES: usize = C_IND + VALUE_PLANES;

/// A missing world position is stored as this coordinate: far from every real point, so
/// its weight is exactly 0, yet finite (no NaN in the tap loop).
pub const MISSING_POSITION: f32 = 1e15;

/// The shape of a set of zero-padded planes (see the module docs) and its indexing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Layout {
    /// Image size in pixels.
    pub width: usize,
    pub height: usize,
    planes: usize,
    /// Padding columns on each side.
    pad_x: usize,
    /// Floats per plane row.
    stride: usize,
}

impl Layout {
    /// `planes` planes of `width` x `height`, padded for tap windows of `radius`.
    pub fn new(planes: usize, width: usize, height: usize, radius: usize) -> Layout {
        let pad_x = (radius + LANES - 1).next_multiple_of(LANES);
        // An odd number of cache lines (16 floats) per plane row, so that the same pixel
        // of consecutive planes falls in different cache sets: with a power-of-two
        // stride (480 + 2 * 16 = 512 floats for the 640x480 column set) the 21 planes of
        // a tap would share two L1 sets and evict each other, which cost 3x.
        let lines = (pad_x + width.next_multiple_of(LANES) + pad_x).div_ceil(16);
        let lines = if lines.is_multiple_of(2) {
            lines + 1
        } else {
            lines
        };
        Layout {
            width,
            height,
            planes,
            pad_x,
            stride: 16 * lines,
        }
    }

    /// Floats in the planes.
    pub fn floats(&self) -> usize {
        self.height * self.row_step()
    }

    /// Planes in the set.
    pub fn planes(&self) -> usize {
        self.planes
    }

    /// Whether the taps |i| <= `radius` of [`LANES`] consecutive pixels of a row stay
    /// inside the row's planes when the first pixel is anywhere from -([`LANES`] - 1)
    /// to the width.
    pub fn fits_radius(&self, radius: usize) -> bool {
        self.pad_x >= radius + LANES - 1
    }

    /// Floats per plane row: from one plane to the next in an image row.
    #[inline(always)]
    pub fn plane_stride(&self) -> usize {
        self.stride
    }

    /// Floats from an image row to the next.
    #[inline(always)]
    pub fn row_step(&self) -> usize {
        self.planes * self.stride
    }

    /// Index of plane 0 at pixel (x, y), 0 <= y < height; x may go down to -pad_x.
    #[inline(always)]
    pub fn index(&self, x: isize, y: usize) -> usize {
        y * self.row_step() + (x + self.pad_x as isize) as usize
    }

    /// The index of pixel `x` of plane `q` within one image row of the planes (as
    /// [`Planes::bands_mut`] gives them).
    #[inline(always)]
    pub fn in_row(&self, q: usize, x: usize) -> usize {
        q * self.stride + self.pad_x + x
    }
}

/// A set of zero-padded planes of one image size.
#[derive(Clone, Debug, Default)]
pub struct Planes {
    layout: Layout,
    data: Vec<f32>,
}

impl std::ops::Deref for Planes {
    type Target = Layout;
    fn deref(&self) -> &Layout {
        &self.layout
    }
}

impl Planes {
    /// Squared distances at or above this mean the position is missing.
    pub const MISSING_DISTANCE2: f32 = 1e28;

    /// `planes` zeroed planes of `width` x `height`, padded for tap windows of `radius`.
    pub fn new(planes: usize, width: usize, height: usize, radius: usize) -> Planes {
        let layout = Layout::new(planes, width, height, radius);
        Planes {
            layout,
            data: vec![0.0; layout.floats()],
        }
    }

    /// The planes' shape (the data's length always matches it).
    pub fn layout(&self) -> Layout {
        self.layout
    }

    /// The planes' floats.
    #[inline(always)]
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Plane `q` at pixel (x, y) of the planes' image (for a column set, x is the
    /// image row and y the image column).
    #[inline]
    pub fn at(&self, q: usize, x: usize, y: usize) -> f32 {
        assert!(q < self.planes && x < self.width && y < self.height);
        self.data[self.index(x as isize, y) + q * self.stride]
    }

    /// The image rows (all planes, padding columns included), top to bottom, in bands
    /// of `rows` rows (the last may be shorter), for writing in parallel.
    pub fn bands_mut(&mut self, rows: usize) -> rayon::slice::ChunksMut<'_, f32> {
        let step = self.row_step();
        self.data.par_chunks_mut((rows * step).max(1))
    }

    /// The planes' floats, for tests that fill them by hand.
    #[cfg(test)]
    pub(super) fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
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

/// Fills the input planes `input` ([`INPUT_PLANES`] planes of the images' size) with
/// positions, squared bandwidths (eqs. 17, 18 from the curvatures of eq. 20) and cleaned
/// values (0 with valid 0 where a layer has no finite value or the pixel no position),
/// and writes the filter widths sigma = 1 / B (direct: mean of the X and Y sigmas;
/// INFINITY where B = 0, NaN where there is no position). Eight pixels at a time
/// (`prepare_lanes`, with `kernel`) where a row's X neighbours of all eight exist, one
/// by one at the row's ends; the same bits either way.
pub fn prepare(
    kernel: Kernel,
    images: &PrepareInputs,
    settings: BandwidthSettings,
    input: &mut Planes,
    width_dir: &mut ScalarImage,
    width_ind: &mut ScalarImage,
) {
    let w = input.width;
    if w == 0 || input.height == 0 {
        return;
    }
    let kernel = kernel.available();
    let layout = input.layout();
    input
        .bands_mut(1)
        .zip(width_dir.data.par_chunks_mut(w))
        .zip(width_ind.data.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, ((row, width_dir), width_ind))| {
            let mut out = RowOut {
                row,
                width_dir,
                width_ind,
            };
            match kernel {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `kernel` came from `Kernel::available`: the CPU has AVX2 and FMA.
                Kernel::Avx2Fma => unsafe {
                    prepare_row_avx2(images, settings, &layout, y, &mut out)
                },
                _ => prepare_row::<Portable>(images, settings, &layout, y, &mut out),
            }
        });
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn prepare_row_avx2(
    images: &PrepareInputs,
    settings: BandwidthSettings,
    layout: &Layout,
    y: usize,
    out: &mut RowOut,
) {
    prepare_row::<crate::simd::Avx2>(images, settings, layout, y, out)
}

/// [`prepare`] for row `y`: groups of eight pixels from x = 1 while pixel x + 8 is
/// inside the row, single pixels before and after.
#[inline(always)]
fn prepare_row<V: Lanes>(
    images: &PrepareInputs,
    settings: BandwidthSettings,
    layout: &Layout,
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
    layout: &Layout,
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
    let sigma = |b: f32| 1.0 / b;
    out.width_dir[x] = if has_position {
        0.5 * (sigma(bx) + sigma(by))
    } else {
        f32::NAN
    };
    out.width_ind[x] = if has_position { sigma(bi) } else { f32::NAN };
}
