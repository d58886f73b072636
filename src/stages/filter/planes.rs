//! The separable filter's passes over structure-of-arrays planes (paper 001 Sec. 7):
//! preparation (bandwidths, cleaned values), the X pass (eq. 21) into column-major planes,
//! and the Y pass (eq. 22) with the temporal taps of the previous frame (eq. 26).
//!
//! Layout: every pass reads its taps as contiguous slices. The X pass reads row-major
//! planes ([`RowPlanes`], one block of [`NPLANES`] padded rows per image row); it writes
//! column-major planes ([`ColumnPlanes`], one block of padded columns per image column),
//! which the Y pass reads along columns. The padding (never written, always zero
//! weight) spares the loops any border test. The previous frame's [`ColumnPlanes`] are
//! kept as they are: its X-filtered values serve as E'_X of eq. 26.

use super::bandwidth::{brdf_bandwidth, curvature_row, direct_bandwidth, indirect_bandwidth};
use super::gaussian::{LANES, Sums, Taps, Target, VALUE_PLANES, accumulate};
use super::temporal::{PreviousView, find_previous};
use crate::raster::{ScalarImage, Vec3Image};
use glam::Vec3;
use rayon::prelude::*;

/// Plane indices: world position, squared bandwidths, then the value planes of the
/// direct and indirect kinds (E_R rgb, E_RV rgb, valid_R, valid_RV each).
pub const PX: usize = 0;
pub const PY: usize = 1;
pub const PZ: usize = 2;
pub const B2X_DIR: usize = 3;
pub const B2Y_DIR: usize = 4;
pub const B2_IND: usize = 5;
pub const DIR: usize = 6;
pub const IND: usize = DIR + VALUE_PLANES;
pub const NPLANES: usize = IND + VALUE_PLANES;

/// A missing world position is stored as this coordinate: far from every real point, so
/// its weight is exactly 0, yet finite (no NaN in the tap loop).
pub const MISSING_POSITION: f32 = 1e15;

/// Columns per parallel task of the X pass, rows per task of the Y pass.
const COLUMN_BAND: usize = 16;
const ROW_BAND: usize = 8;

/// Taps per pass for radius `radius`: 2 radius + 1 rounded up to a multiple of [`LANES`].
pub fn tap_count(radius: usize) -> usize {
    (2 * radius + 1).div_ceil(LANES) * LANES
}

/// Padding on each side of a row or column: room for every tap of [`tap_count`].
fn padding(radius: usize) -> usize {
    radius + LANES
}

/// Row-major planes: pixel (x, y) of plane q at `y * block + q * stride + pad + x`.
#[derive(Clone, Debug, Default)]
pub struct RowPlanes {
    pub width: usize,
    pub height: usize,
    pad: usize,
    stride: usize,
    data: Vec<f32>,
}

/// Column-major planes: pixel (x, y) of plane q at `x * block + q * stride + pad + y`.
#[derive(Clone, Debug, Default)]
pub struct ColumnPlanes {
    pub width: usize,
    pub height: usize,
    pad: usize,
    stride: usize,
    data: Vec<f32>,
}

impl RowPlanes {
    pub fn new(width: usize, height: usize, radius: usize) -> RowPlanes {
        let pad = padding(radius);
        let stride = width + 2 * pad;
        RowPlanes {
            width,
            height,
            pad,
            stride,
            data: vec![0.0; height * NPLANES * stride],
        }
    }
}

impl ColumnPlanes {
    /// Squared distances at or above this mean the position is missing.
    pub const MISSING_DISTANCE2: f32 = 1e28;

    pub fn new(width: usize, height: usize, radius: usize) -> ColumnPlanes {
        let pad = padding(radius);
        let stride = height + 2 * pad;
        ColumnPlanes {
            width,
            height,
            pad,
            stride,
            data: vec![0.0; width * NPLANES * stride],
        }
    }

    /// Plane `q` at pixel (x, y).
    #[inline]
    pub fn at(&self, q: usize, x: usize, y: usize) -> f32 {
        self.data[x * NPLANES * self.stride + q * self.stride + self.pad + y]
    }
}

/// The taps of one kind (`values` = [`DIR`] or [`IND`], squared bandwidth plane `b2`) in
/// a block of planes, starting at offset `start` of each plane.
#[inline(always)]
fn taps<'a>(
    block: &'a [f32],
    stride: usize,
    start: usize,
    count: usize,
    b2: usize,
    values: usize,
    mask: &'a [f32],
) -> Taps<'a> {
    let plane = |q: usize| &block[q * stride + start..q * stride + start + count];
    Taps {
        px: plane(PX),
        py: plane(PY),
        pz: plane(PZ),
        b2: plane(b2),
        mask,
        values: std::array::from_fn(|i| plane(values + i)),
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

/// Fills `rows` with positions, squared bandwidths (eqs. 17, 18 from the curvatures of
/// eq. 20) and cleaned values, and writes the filter widths sigma = 1 / B (direct: mean
/// of the X and Y sigmas; INFINITY where B = 0, NaN where there is no position).
pub fn prepare(
    input: &PrepareInputs,
    settings: BandwidthSettings,
    rows: &mut RowPlanes,
    width_dir: &mut ScalarImage,
    width_ind: &mut ScalarImage,
) {
    let (w, stride, pad) = (rows.width, rows.stride, rows.pad);
    if w == 0 || rows.height == 0 {
        return;
    }
    rows.data
        .par_chunks_mut(NPLANES * stride)
        .zip(width_dir.data.par_chunks_mut(w))
        .zip(width_ind.data.par_chunks_mut(w))
        .enumerate()
        .for_each_init(
            || (vec![0.0f32; w], vec![0.0f32; w]),
            |(kx, ky), (y, ((block, wd), wi))| {
                curvature_row(input.world_position, input.world_normal, y, kx, ky);
                for x in 0..w {
                    let i = y * w + x;
                    let at = |q: usize| q * stride + pad + x;
                    let p = input.world_position.data[i];
                    let has_position = p.is_finite();
                    let m = input.exponent.data[i];
                    let m = if m.is_finite() { m.max(0.0) } else { 0.0 };
                    let b_rho = brdf_bandwidth(m);
                    let zd = input.direct_min_distance.data[i];
                    let zi = input.indirect_min_distance.data[i];
                    let bx = direct_bandwidth(kx[x], zd, settings.b_f, b_rho, settings.b_e);
                    let by = direct_bandwidth(ky[x], zd, settings.b_f, b_rho, settings.b_e);
                    let bi = indirect_bandwidth(zi, m);
                    let stored = if has_position {
                        p
                    } else {
                        Vec3::splat(MISSING_POSITION)
                    };
                    block[at(PX)] = stored.x;
                    block[at(PY)] = stored.y;
                    block[at(PZ)] = stored.z;
                    let keep = |b: f32| if has_position { b * b } else { 0.0 };
                    block[at(B2X_DIR)] = keep(bx);
                    block[at(B2Y_DIR)] = keep(by);
                    block[at(B2_IND)] = keep(bi);
                    for (kind, r, rv) in [(DIR, 0, 2), (IND, 1, 3)] {
                        for (slot, layer) in [(0, r), (3, rv)] {
                            let v = input.layers[layer].data[i];
                            let ok = has_position && v.is_finite();
                            let v = if ok { v } else { Vec3::ZERO };
                            block[at(kind + slot)] = v.x;
                            block[at(kind + slot + 1)] = v.y;
                            block[at(kind + slot + 2)] = v.z;
                            block[at(kind + 6 + slot / 3)] = if ok { 1.0 } else { 0.0 };
                        }
                    }
                    let sigma = |b: f32| 1.0 / b;
                    wd[x] = if has_position {
                        0.5 * (sigma(bx) + sigma(by))
                    } else {
                        f32::NAN
                    };
                    wi[x] = if has_position { sigma(bi) } else { f32::NAN };
                }
            },
        );
}

/// Normalizes the sums of one kind into `out` (E_R rgb, E_RV rgb, valid_R, valid_RV);
/// a layer whose target has no value (`valid` 0) gets `missing`.
#[inline]
fn normalize(sums: &Sums, valid: [f32; 2], missing: f32) -> [f32; VALUE_PLANES] {
    let mut out = [missing; VALUE_PLANES];
    for (layer, &ok) in valid.iter().enumerate() {
        if ok > 0.0 {
            let weight = sums.total(6 + layer);
            for c in 0..3 {
                out[3 * layer + c] = sums.total(3 * layer + c) / weight;
            }
        }
        out[6 + layer] = ok;
    }
    out
}

/// The X pass, eq. 21: filters both kinds of `rows` along image rows and writes the
/// results, with the positions and the Y bandwidths, into `columns`.
pub fn x_pass(rows: &RowPlanes, radius: usize, mask: &[f32], columns: &mut ColumnPlanes) {
    let (w, h) = (rows.width, rows.height);
    if w == 0 || h == 0 {
        return;
    }
    let count = tap_count(radius);
    let (rs, rp) = (rows.stride, rows.pad);
    let (cs, cp) = (columns.stride, columns.pad);
    columns
        .data
        .par_chunks_mut(COLUMN_BAND * NPLANES * cs)
        .enumerate()
        .for_each(|(band, out)| {
            let x0 = band * COLUMN_BAND;
            let x1 = (x0 + COLUMN_BAND).min(w);
            for y in 0..h {
                let block = &rows.data[y * NPLANES * rs..(y + 1) * NPLANES * rs];
                for x in x0..x1 {
                    let get = |q: usize| block[q * rs + rp + x];
                    let col = &mut out[(x - x0) * NPLANES * cs..(x - x0 + 1) * NPLANES * cs];
                    let mut put = |q: usize, v: f32| col[q * cs + cp + y] = v;
                    for q in [PX, PY, PZ, B2Y_DIR, B2_IND] {
                        put(q, get(q));
                    }
                    let target = |b2: usize| Target {
                        position: [get(PX), get(PY), get(PZ)],
                        b2: get(b2),
                    };
                    for (kind, b2) in [(DIR, B2X_DIR), (IND, B2_IND)] {
                        let valid = [get(kind + 6), get(kind + 7)];
                        let mut sums = Sums::default();
                        if valid[0] > 0.0 || valid[1] > 0.0 {
                            let t = taps(block, rs, rp + x - radius, count, b2, kind, mask);
                            accumulate(target(b2), &t, &mut sums);
                        }
                        for (q, v) in normalize(&sums, valid, 0.0).into_iter().enumerate() {
                            put(kind + q, v);
                        }
                    }
                }
            }
        });
}

/// The Y pass, eq. 22, with the temporal taps of eq. 26 when `previous` is given: filters
/// `columns` along image columns into the four output layers (E_R^dir, E_R^ind,
/// E_RV^dir, E_RV^ind; NaN where the pixel has no value of that layer).
pub fn y_pass(
    columns: &ColumnPlanes,
    previous: Option<(&ColumnPlanes, &PreviousView)>,
    radius: usize,
    mask: &[f32],
    out: &mut [Vec3Image; 4],
) {
    let (w, h) = (columns.width, columns.height);
    if w == 0 || h == 0 {
        return;
    }
    let count = tap_count(radius);
    let (cs, cp) = (columns.stride, columns.pad);
    fn block_of(planes: &ColumnPlanes, x: usize) -> &[f32] {
        let size = NPLANES * planes.stride;
        &planes.data[x * size..(x + 1) * size]
    }
    let [er_dir, er_ind, erv_dir, erv_ind] = out;
    er_dir
        .data
        .par_chunks_mut(ROW_BAND * w)
        .zip(er_ind.data.par_chunks_mut(ROW_BAND * w))
        .zip(erv_dir.data.par_chunks_mut(ROW_BAND * w))
        .zip(erv_ind.data.par_chunks_mut(ROW_BAND * w))
        .enumerate()
        .for_each(|(band, (((o_r_dir, o_r_ind), o_rv_dir), o_rv_ind))| {
            let y0 = band * ROW_BAND;
            for x in 0..w {
                let block = block_of(columns, x);
                for (dy, i) in (0..o_r_dir.len() / w).map(|dy| (dy, dy * w + x)) {
                    let y = y0 + dy;
                    let get = |q: usize| block[q * cs + cp + y];
                    let p = Vec3::new(get(PX), get(PY), get(PZ));
                    let mut results = [[f32::NAN; VALUE_PLANES]; 2];
                    let any_valid = [DIR + 6, DIR + 7, IND + 6, IND + 7]
                        .iter()
                        .any(|&q| get(q) > 0.0);
                    if any_valid {
                        let matched = previous.and_then(|(planes, view)| {
                            find_previous(p, view, planes)
                                .map(|(xp, yp)| (block_of(planes, xp), yp))
                        });
                        for (k, (kind, b2)) in
                            [(DIR, B2Y_DIR), (IND, B2_IND)].into_iter().enumerate()
                        {
                            let valid = [get(kind + 6), get(kind + 7)];
                            if valid[0] == 0.0 && valid[1] == 0.0 {
                                continue;
                            }
                            let target = Target {
                                position: p.to_array(),
                                b2: get(b2),
                            };
                            let mut sums = Sums::default();
                            let t = taps(block, cs, cp + y - radius, count, b2, kind, mask);
                            accumulate(target, &t, &mut sums);
                            if let Some((prev_block, yp)) = matched {
                                let t =
                                    taps(prev_block, cs, cp + yp - radius, count, b2, kind, mask);
                                accumulate(target, &t, &mut sums);
                            }
                            results[k] = normalize(&sums, valid, f32::NAN);
                        }
                    }
                    let rgb = |r: &[f32; VALUE_PLANES], layer: usize| {
                        Vec3::new(r[3 * layer], r[3 * layer + 1], r[3 * layer + 2])
                    };
                    o_r_dir[i] = rgb(&results[0], 0);
                    o_rv_dir[i] = rgb(&results[0], 1);
                    o_r_ind[i] = rgb(&results[1], 0);
                    o_rv_ind[i] = rgb(&results[1], 1);
                }
            }
        });
}
