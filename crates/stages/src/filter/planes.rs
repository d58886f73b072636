//! The preparation pass of the filter (paper 001 Sec. 7) that fills the input planes
//! ([`super::layout`]) (positions, bandwidths, cleaned values) from the stage's images. The
//! sets are lane-interleaved ([`super::lane_planes`]); the preparation writes each row
//! plainly first, eight consecutive pixels at a time ([`RowLayout`]), then interleaves it.

use super::bandwidth::{brdf_bandwidth, curvature_at, direct_bandwidth, indirect_bandwidth};
use super::lane_planes::{LaneLayout, LanePlanes, fill_line};
use super::layout::{
    B2_IND, B2X_DIR, B2Y_DIR, BandwidthSettings, DIR, IND, INPUT_PLANES, MISSING_POSITION, PX, PY,
    PZ, PrepareInputs, RowLayout,
};
use super::prepare_lanes::{RowOut, prepare_group};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::ScalarImage;
use relume_base::simd::{Kernel, LANES, Lanes, Portable};

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
