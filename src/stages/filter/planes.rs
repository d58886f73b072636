//! The separable filter's passes over structure-of-arrays planes (paper 001 Sec. 7):
//! preparation (bandwidths, cleaned values), the X pass (eq. 21) into column-major planes,
//! and the Y pass (eq. 22) with the temporal taps of the previous frame (eq. 26).
//!
//! Layout: every pass reads its taps as contiguous chunks ([`Lines`]). The X pass reads
//! the planes by image row ([`RowPlanes`]); it writes them by image column
//! ([`ColumnPlanes`]), which the Y pass reads along columns. The padding (never written,
//! always zero weight) spares the loops any border test. The previous frame's [`ColumnPlanes`] are
//! kept as they are: its X-filtered values serve as E'_X of eq. 26.

use super::bandwidth::{brdf_bandwidth, curvature_row, direct_bandwidth, indirect_bandwidth};
pub use super::gaussian::NPLANES;
use super::gaussian::{
    BothTarget, Chunk, EXP_CUTOFF, LANES, Sums, Target, VALUE_PLANES, accumulate, accumulate_r,
};
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

/// A missing world position is stored as this coordinate: far from every real point, so
/// its weight is exactly 0, yet finite (no NaN in the tap loop).
pub const MISSING_POSITION: f32 = 1e15;

/// Columns per parallel task of the X pass, rows per task of the Y pass.
const COLUMN_BAND: usize = 64;
const ROW_BAND: usize = 24;

/// Lines (image rows or columns) of planes, each a sequence of [`Chunk`]s with `pad`
/// pixels of zero padding (never written: valid 0, so zero weight) before and after the
/// pixels, so that every tap window lies inside its line.
#[derive(Clone, Debug, Default)]
pub struct Lines {
    /// Number of lines.
    pub count: usize,
    /// Pixels per line.
    pub length: usize,
    pad: usize,
    chunks_per_line: usize,
    data: Vec<Chunk>,
    /// Per line, `chunks_per_line * LANES + 1` running counts of the padded positions
    /// where E_RV differs from E_R (any bit of either kind's rgb or valid): position t's
    /// window [t - R, t + R] has E_RV == E_R throughout when the counts at t + R + 1 and
    /// t - R agree (see [`Lines::rv_same`]).
    differences: Vec<u32>,
}

/// Planes by image row (pixel (x, y) is position x of line y): the X pass's input.
pub type RowPlanes = Lines;
/// Planes by image column (pixel (x, y) is position y of line x): the Y pass's input.
pub type ColumnPlanes = Lines;

impl Lines {
    /// Squared distances at or above this mean the position is missing.
    pub const MISSING_DISTANCE2: f32 = 1e28;

    /// Zeroed lines for filter radius `radius`.
    pub fn new(count: usize, length: usize, radius: usize) -> Lines {
        let pad = radius + 2 * LANES;
        let chunks_per_line = (length + 2 * pad).div_ceil(LANES);
        Lines {
            count,
            length,
            pad,
            chunks_per_line,
            data: vec![[[0.0; LANES]; NPLANES]; count * chunks_per_line],
            differences: vec![0; count * (chunks_per_line * LANES + 1)],
        }
    }

    /// Whether E_RV == E_R (both kinds, bit for bit) over the taps |i| <= `radius`
    /// around padded position `t` of line `i`, in O(1) from the running counts.
    #[inline(always)]
    pub fn rv_same(&self, i: usize, t: usize, radius: usize) -> bool {
        let counts = &self.differences[i * (self.chunks_per_line * LANES + 1)..];
        counts[t + radius + 1] == counts[t - radius]
    }

    /// The chunks of line `i`.
    #[inline]
    pub fn line(&self, i: usize) -> &[Chunk] {
        &self.data[i * self.chunks_per_line..(i + 1) * self.chunks_per_line]
    }

    /// Plane `q` at position `pos` of line `line`.
    #[inline]
    pub fn at(&self, q: usize, line: usize, pos: usize) -> f32 {
        let t = pos + self.pad;
        self.data[line * self.chunks_per_line + t / LANES][q][t % LANES]
    }
}

/// Fills `counts` (length `line.len() * LANES + 1`) with the running counts of the
/// positions of `line` where E_RV differs from E_R (see [`Lines::rv_same`]).
fn count_differences(line: &[Chunk], counts: &mut [u32]) {
    let mut n = 0;
    counts[0] = 0;
    for (chunk, out) in line.iter().zip(counts[1..].chunks_exact_mut(LANES)) {
        for (l, out) in out.iter_mut().enumerate() {
            let differs = [DIR, IND].iter().any(|&k| {
                (0..3).any(|c| chunk[k + c][l].to_bits() != chunk[k + 3 + c][l].to_bits())
                    || chunk[k + 6][l] != chunk[k + 7][l]
            });
            n += differs as u32;
            *out = n;
        }
    }
}

/// Plane `q` at padded position `t` of a line.
#[inline(always)]
fn get(line: &[Chunk], q: usize, t: usize) -> f32 {
    line[t / LANES][q][t % LANES]
}

#[inline(always)]
fn put(line: &mut [Chunk], q: usize, t: usize, v: f32) {
    line[t / LANES][q][t % LANES] = v;
}

/// The tap masks of radius R: for each alignment m = (t - R) mod 4 of a window's first
/// tap, `chunks` chunks of per-lane exp cutoffs: [`EXP_CUTOFF`] for the taps |i| <= R of
/// the window, -1 (weight 0) for the others in the same chunks.
#[derive(Clone, Debug)]
pub struct TapMasks {
    pub radius: usize,
    pub chunks: usize,
    masks: Vec<[f32; LANES]>,
}

impl TapMasks {
    pub fn new(radius: usize) -> TapMasks {
        let chunks = (2 * radius + 1 + LANES - 1).div_ceil(LANES);
        let masks = (0..LANES)
            .flat_map(|m| {
                (0..chunks).map(move |c| {
                    std::array::from_fn(|l| {
                        let k = c * LANES + l;
                        if k >= m && k <= m + 2 * radius {
                            EXP_CUTOFF
                        } else {
                            -1.0
                        }
                    })
                })
            })
            .collect();
        TapMasks {
            radius,
            chunks,
            masks,
        }
    }

    /// The chunks of `line` and their masks for the window around padded position `t`.
    #[inline(always)]
    fn window<'a>(&'a self, line: &'a [Chunk], t: usize) -> (&'a [Chunk], &'a [[f32; LANES]]) {
        let s = t - self.radius;
        let (c0, m) = (s / LANES, s % LANES);
        // Only the chunks that hold taps of the window (8 or 9 at R = 15).
        let n = (m + 2 * self.radius + 1).div_ceil(LANES);
        (
            &line[c0..c0 + n],
            &self.masks[m * self.chunks..m * self.chunks + n],
        )
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
    let (w, pad) = (rows.length, rows.pad);
    if w == 0 || rows.count == 0 {
        return;
    }
    let counts_per_line = rows.chunks_per_line * LANES + 1;
    rows.data
        .par_chunks_mut(rows.chunks_per_line)
        .zip(rows.differences.par_chunks_mut(counts_per_line))
        .zip(width_dir.data.par_chunks_mut(w))
        .zip(width_ind.data.par_chunks_mut(w))
        .enumerate()
        .for_each_init(
            || (vec![0.0f32; w], vec![0.0f32; w]),
            |(kx, ky), (y, (((line, counts), wd), wi))| {
                curvature_row(input.world_position, input.world_normal, y, kx, ky);
                for x in 0..w {
                    let i = y * w + x;
                    let t = x + pad;
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
                    let chunk = &mut line[t / LANES];
                    let l = t % LANES;
                    let stored = if has_position {
                        p
                    } else {
                        Vec3::splat(MISSING_POSITION)
                    };
                    chunk[PX][l] = stored.x;
                    chunk[PY][l] = stored.y;
                    chunk[PZ][l] = stored.z;
                    let keep = |b: f32| if has_position { b * b } else { 0.0 };
                    chunk[B2X_DIR][l] = keep(bx);
                    chunk[B2Y_DIR][l] = keep(by);
                    chunk[B2_IND][l] = keep(bi);
                    for (kind, r, rv) in [(DIR, 0, 2), (IND, 1, 3)] {
                        for (slot, layer) in [(0, r), (3, rv)] {
                            let v = input.layers[layer].data[i];
                            let ok = has_position && v.is_finite();
                            let v = if ok { v } else { Vec3::ZERO };
                            chunk[kind + slot][l] = v.x;
                            chunk[kind + slot + 1][l] = v.y;
                            chunk[kind + slot + 2][l] = v.z;
                            chunk[kind + 6 + slot / 3][l] = if ok { 1.0 } else { 0.0 };
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
                count_differences(line, counts);
            },
        );
}

/// Normalizes the sums of one kind (E_R rgb, E_RV rgb, valid_R, valid_RV); a layer whose
/// target has no value (`valid` 0) gets `missing`.
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

/// The tap sums of one kind for the target at padded position `t` of `line`, plus those
/// of `previous` (a line of the previous frame and a padded position) when given.
#[inline(always)]
fn kind_sums<const B2: usize, const VALUES: usize>(
    masks: &TapMasks,
    line: &[Chunk],
    t: usize,
    previous: Option<(&[Chunk], usize)>,
) -> [f32; VALUE_PLANES] {
    let valid = [get(line, VALUES + 6, t), get(line, VALUES + 7, t)];
    if valid == [0.0, 0.0] {
        return [0.0; VALUE_PLANES];
    }
    let target = Target {
        position: [get(line, PX, t), get(line, PY, t), get(line, PZ, t)],
        b2: get(line, B2, t),
    };
    let mut sums = Sums::default();
    let (chunks, mask) = masks.window(line, t);
    accumulate::<B2, VALUES>(target, chunks, mask, &mut sums);
    if let Some((prev_line, tp)) = previous {
        let (chunks, mask) = masks.window(prev_line, tp);
        accumulate::<B2, VALUES>(target, chunks, mask, &mut sums);
    }
    normalize(&sums, valid, f32::NAN)
}

/// The tap sums of both kinds ([`kind_sums`] of the direct kind with B^2 plane `B2D`,
/// then of the indirect kind) for the target at padded position `t` of `line`, plus
/// those of `previous` when given. `rv_same`: E_RV == E_R over every window summed (the
/// caller checks with [`Lines::rv_same`]); then only E_R's planes are summed and E_RV's
/// sums are copies of them, which are the bits the full sums would give (same weights,
/// same values, same order).
#[inline(always)]
fn pixel_sums<const B2D: usize>(
    masks: &TapMasks,
    line: &[Chunk],
    t: usize,
    previous: Option<(&[Chunk], usize)>,
    rv_same: bool,
) -> [[f32; VALUE_PLANES]; 2] {
    if !rv_same {
        return [
            kind_sums::<B2D, DIR>(masks, line, t, previous),
            kind_sums::<B2_IND, IND>(masks, line, t, previous),
        ];
    }
    let valid = [DIR + 6, DIR + 7, IND + 6, IND + 7].map(|q| get(line, q, t));
    if valid == [0.0; 4] {
        return [[0.0; VALUE_PLANES]; 2];
    }
    let target = BothTarget {
        position: [get(line, PX, t), get(line, PY, t), get(line, PZ, t)],
        b2: [get(line, B2D, t), get(line, B2_IND, t)],
    };
    let mut sums = [Sums::default(); 2];
    let (chunks, mask) = masks.window(line, t);
    accumulate_r::<B2D, B2_IND, DIR, IND>(target, chunks, mask, &mut sums);
    if let Some((prev_line, tp)) = previous {
        let (chunks, mask) = masks.window(prev_line, tp);
        accumulate_r::<B2D, B2_IND, DIR, IND>(target, chunks, mask, &mut sums);
    }
    let kind = |sums: &mut Sums, valid: [f32; 2]| {
        if valid == [0.0, 0.0] {
            return [0.0; VALUE_PLANES];
        }
        for c in 0..3 {
            sums.0[3 + c] = sums.0[c];
        }
        sums.0[7] = sums.0[6];
        normalize(sums, valid, f32::NAN)
    };
    let [dir, ind] = &mut sums;
    [
        kind(dir, [valid[0], valid[1]]),
        kind(ind, [valid[2], valid[3]]),
    ]
}

/// The X pass, eq. 21: filters both kinds of `rows` along image rows and writes the
/// results (0 with valid 0 where a layer has no value), with the positions and the Y
/// bandwidths, into `columns`.
pub fn x_pass(rows: &RowPlanes, masks: &TapMasks, columns: &mut ColumnPlanes) {
    let (w, h) = (rows.length, rows.count);
    if w == 0 || h == 0 {
        return;
    }
    let (rp, cp, cpl) = (rows.pad, columns.pad, columns.chunks_per_line);
    let (radius, counts_per_line) = (masks.radius, cpl * LANES + 1);
    columns
        .data
        .par_chunks_mut(COLUMN_BAND * cpl)
        .zip(
            columns
                .differences
                .par_chunks_mut(COLUMN_BAND * counts_per_line),
        )
        .enumerate()
        .for_each(|(band, (out, counts))| {
            let x0 = band * COLUMN_BAND;
            for y in 0..h {
                let line = rows.line(y);
                let tc = y + cp;
                for (dx, col) in out.chunks_mut(cpl).enumerate() {
                    let t = x0 + dx + rp;
                    for q in [PX, PY, PZ, B2Y_DIR, B2_IND] {
                        put(col, q, tc, get(line, q, t));
                    }
                    let rv_same = rows.rv_same(y, t, radius);
                    let [dir, ind] = pixel_sums::<B2X_DIR>(masks, line, t, None, rv_same);
                    for q in 0..VALUE_PLANES {
                        // A missing value (NaN) is stored as 0 with valid 0.
                        let clean = |v: f32| if v.is_nan() { 0.0 } else { v };
                        put(col, DIR + q, tc, clean(dir[q]));
                        put(col, IND + q, tc, clean(ind[q]));
                    }
                }
            }
            for (col, counts) in out.chunks_mut(cpl).zip(counts.chunks_mut(counts_per_line)) {
                count_differences(col, counts);
            }
        });
}

/// The Y pass, eq. 22, with the temporal taps of eq. 26 when `previous` is given: filters
/// `columns` along image columns into the four output layers (E_R^dir, E_R^ind,
/// E_RV^dir, E_RV^ind; NaN where the pixel has no value of that layer).
pub fn y_pass(
    columns: &ColumnPlanes,
    previous: Option<(&ColumnPlanes, &PreviousView)>,
    masks: &TapMasks,
    out: &mut [Vec3Image; 4],
) {
    let (w, h) = (columns.count, columns.length);
    if w == 0 || h == 0 {
        return;
    }
    let (cp, radius) = (columns.pad, masks.radius);
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
                let line = columns.line(x);
                for dy in 0..o_r_dir.len() / w {
                    let (i, t) = (dy * w + x, y0 + dy + cp);
                    let rgb = |r: &[f32; VALUE_PLANES], layer: usize| {
                        Vec3::new(r[3 * layer], r[3 * layer + 1], r[3 * layer + 2])
                    };
                    let valid = [DIR + 6, DIR + 7, IND + 6, IND + 7].map(|q| get(line, q, t));
                    let (dir, ind) = if valid == [0.0; 4] {
                        ([f32::NAN; VALUE_PLANES], [f32::NAN; VALUE_PLANES])
                    } else {
                        let p = Vec3::new(get(line, PX, t), get(line, PY, t), get(line, PZ, t));
                        let mut rv_same = columns.rv_same(x, t, radius);
                        let matched = previous.and_then(|(planes, view)| {
                            find_previous(p, view, planes).map(|(xp, yp)| {
                                let tp = yp + planes.pad;
                                rv_same &= planes.rv_same(xp, tp, radius);
                                (planes.line(xp), tp)
                            })
                        });
                        let nan_if_missing = |mut r: [f32; VALUE_PLANES], ok: [f32; 2]| {
                            for (layer, &ok) in ok.iter().enumerate() {
                                if ok == 0.0 {
                                    r[3 * layer..3 * layer + 3].fill(f32::NAN);
                                }
                            }
                            r
                        };
                        let [dir, ind] = pixel_sums::<B2Y_DIR>(masks, line, t, matched, rv_same);
                        (
                            nan_if_missing(dir, [valid[0], valid[1]]),
                            nan_if_missing(ind, [valid[2], valid[3]]),
                        )
                    };
                    o_r_dir[i] = rgb(&dir, 0);
                    o_rv_dir[i] = rgb(&dir, 1);
                    o_r_ind[i] = rgb(&ind, 0);
                    o_rv_ind[i] = rgb(&ind, 1);
                }
            }
        });
}
