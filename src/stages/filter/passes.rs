//! The separable filter's passes (paper 001 Sec. 7): the X pass (eq. 21) from the input
//! planes into the column set, and the Y pass (eq. 22) with the temporal taps of the
//! previous frame (eq. 26) from the column set into the output images.
//!
//! Both passes work on groups of [`LANES`] target pixels that are consecutive along the
//! pass's direction: the X pass on pixels (x0 + l, y) of the row-major input planes,
//! the Y pass on pixels (x, y0 + l) of the column set (the transposed image). Either
//! way a tap of all eight targets is eight consecutive floats of each plane, one vector
//! load, and a task's taps stay in cache. Both passes store through 8 x 8 blocks
//! transposed in registers ([`Lanes::transpose`]): the X pass writes the column set's
//! lines eight positions at a time, the Y pass the output rows eight pixels at a time.
//! The kernel (AVX2 + FMA or portable, [`Kernel`]) is chosen
//! per band; both give the same bits.
//!
//! The lane operations are never called from closures: closures do not inherit
//! `#[target_feature]`, and their lane operations would not be inlined.

use super::gaussian::{
    Contiguous, EXP_CUTOFF, Gathered, TapPlanes, Targets, VALUE_PLANES, Window, accumulate,
};
use super::planes::{
    B2_IND, B2X_DIR, B2Y_DIR, C_B2_IND, C_B2Y_DIR, C_DIR, C_IND, C_PX, C_PY, C_PZ, COLUMN_PLANES,
    DIR, IND, INPUT_PLANES, Layout, PX, PY, PZ, Planes,
};
use super::temporal::{PreviousView, find_previous};
use crate::raster::Vec3Image;
use crate::simd::{Kernel, LANES, Lanes, Portable};
use glam::Vec3;
use rayon::prelude::*;

/// Image columns per parallel task of the X pass (its lines of the column set; a
/// multiple of [`LANES`], so that no group of lanes spans two tasks). 32 was about 8 %
/// faster than 16 once the X pass stored whole blocks; 64 was within the noise.
const COLUMN_BAND: usize = 32;
/// Image rows per parallel task of the Y pass (a multiple of [`LANES`]).
const ROW_BAND: usize = 24;
const _: () = assert!(COLUMN_BAND.is_multiple_of(LANES) && ROW_BAND.is_multiple_of(LANES));

/// The previous frame as the temporal taps read it: its column set (positions,
/// bandwidths, and its X-filtered layers, E'_X of eq. 26) and its camera.
#[derive(Clone, Copy)]
pub struct Previous<'a> {
    pub columns: &'a Planes,
    pub view: &'a PreviousView,
}

/// Lanes of `data[i..i + LANES]`.
#[inline(always)]
fn load<V: Lanes>(data: &[f32], i: usize) -> V {
    let lanes = &data[i..i + LANES];
    // SAFETY: `lanes` holds LANES floats.
    unsafe { V::load(lanes.as_ptr()) }
}

/// The taps |i| <= `radius` along a line around lane 0's target at `data[i]`: the
/// following lanes' targets and taps are the following floats.
#[inline(always)]
fn line_window(data: &[f32], i: usize, plane_stride: usize, radius: usize) -> Window {
    Window {
        planes: data[i - radius..].as_ptr(),
        plane_stride,
        tap_step: 1,
        taps: 2 * radius + 1,
    }
}

/// The X pass, eq. 21: filters both kinds of `input` along image rows into the column
/// set `columns` (0 with valid 0 where a layer has no value), with the positions and
/// the bandwidths the Y pass needs.
pub fn x_pass(kernel: Kernel, input: &Planes, radius: usize, columns: &mut Planes) {
    assert!(input.planes() == INPUT_PLANES && columns.planes() == COLUMN_PLANES);
    assert!(input.fits_radius(radius) && columns.fits_radius(radius));
    assert_eq!((columns.width, columns.height), (input.height, input.width));
    let kernel = kernel.available();
    let layout = columns.layout();
    columns
        .bands_mut(COLUMN_BAND)
        .enumerate()
        .for_each(|(band, lines)| {
            let x_start = band * COLUMN_BAND;
            match kernel {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `kernel` came from `Kernel::available`: the CPU has AVX2 and FMA.
                Kernel::Avx2Fma => unsafe { x_band_avx2(input, radius, x_start, &layout, lines) },
                _ => x_band::<Portable>(input, radius, x_start, &layout, lines),
            }
        });
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn x_band_avx2(input: &Planes, radius: usize, x_start: usize, layout: &Layout, lines: &mut [f32]) {
    x_band::<crate::simd::Avx2>(input, radius, x_start, layout, lines)
}

/// The X pass for image columns `x_start..` into `lines`, their lines of the column set
/// (`layout`). Blocks of [`LANES`] x [`LANES`] pixels: eight groups down the rows, then
/// each plane's block transposed, so that a line takes its eight positions in one vector
/// store (one float per lane into eight lines cost a quarter of the pass). Rows past the
/// last whole block are stored lane by lane.
#[inline(always)]
fn x_band<V: Lanes>(
    input: &Planes,
    radius: usize,
    x_start: usize,
    layout: &Layout,
    lines: &mut [f32],
) {
    let x_end = x_start + lines.len() / layout.row_step();
    let block_rows = input.height / LANES * LANES;
    for y0 in (0..block_rows).step_by(LANES) {
        for x0 in (x_start..x_end).step_by(LANES) {
            let lanes = LANES.min(x_end - x0);
            let mut block = [[V::splat(0.0); LANES]; COLUMN_PLANES];
            for r in 0..LANES {
                let group = x_group::<V>(input, radius, x0, y0 + r);
                for (rows, v) in block.iter_mut().zip(group) {
                    rows[r] = v;
                }
            }
            for (q, rows) in block.into_iter().enumerate() {
                let first = (x0 - x_start) * layout.row_step() + layout.in_row(q, y0);
                for (l, column) in V::transpose(rows).into_iter().enumerate().take(lanes) {
                    let at = first + l * layout.row_step();
                    let positions = &mut lines[at..at + LANES];
                    // SAFETY: `positions` holds LANES floats.
                    unsafe { column.store(positions.as_mut_ptr()) };
                }
            }
        }
    }
    for y in block_rows..input.height {
        for x0 in (x_start..x_end).step_by(LANES) {
            let lanes = LANES.min(x_end - x0);
            let group = x_group::<V>(input, radius, x0, y);
            for (q, v) in group.into_iter().enumerate() {
                let first = (x0 - x_start) * layout.row_step() + layout.in_row(q, y);
                for (l, v) in v.to_array().into_iter().enumerate().take(lanes) {
                    lines[first + l * layout.row_step()] = v;
                }
            }
        }
    }
}

/// The X pass for pixels (x0 + l, y): the column set's planes, each a vector over the
/// lanes (0 with valid 0 where a layer has no value).
#[inline(always)]
fn x_group<V: Lanes>(input: &Planes, radius: usize, x0: usize, y: usize) -> [V; COLUMN_PLANES] {
    let (data, s) = (input.data(), input.plane_stride());
    let mut out = [V::splat(0.0); COLUMN_PLANES];
    // Pixel (x0 + l, y) of any plane is inside the planes: the padding covers a group's
    // lanes past the width.
    let c = input.index(x0 as isize, y);
    let position = [
        load::<V>(data, c + PX * s),
        load::<V>(data, c + PY * s),
        load::<V>(data, c + PZ * s),
    ];
    out[C_PX] = position[0];
    out[C_PY] = position[1];
    out[C_PZ] = position[2];
    out[C_B2Y_DIR] = load(data, c + B2Y_DIR * s);
    out[C_B2_IND] = load(data, c + B2_IND * s);
    for (values, b2, first) in [(DIR, B2X_DIR, C_DIR), (IND, B2_IND, C_IND)] {
        let valid: [V; 2] = [
            load(data, c + (values + 6) * s),
            load(data, c + (values + 7) * s),
        ];
        // Kinds without a value anywhere in the group: zeros, and the valid planes.
        if valid[0].all_zero() && valid[1].all_zero() {
            out[first + 6] = valid[0];
            out[first + 7] = valid[1];
            continue;
        }
        let targets = Targets {
            position,
            b2: load(data, c + b2 * s),
        };
        let window = line_window(data, c, s, radius);
        let planes = TapPlanes {
            position: PX,
            b2,
            values,
        };
        let mut sums = [V::splat(0.0); VALUE_PLANES];
        // SAFETY: the taps |i| <= radius of the group lie inside the row's planes
        // (`fits_radius`).
        unsafe {
            let limit = V::splat(EXP_CUTOFF);
            accumulate(&Contiguous, &window, planes, &targets, limit, &mut sums)
        };
        for (layer, &ok) in valid.iter().enumerate() {
            for c in 0..3 {
                // A missing value (NaN) is stored as 0 with valid 0.
                out[first + 3 * layer + c] = sums[3 * layer + c]
                    .div(sums[6 + layer])
                    .zero_if_nan()
                    .zero_unless_positive(ok);
            }
            out[first + 6 + layer] = ok;
        }
    }
    out
}

/// The Y pass, eq. 22, with the temporal taps of eq. 26 when `previous` is given:
/// filters the column set along image columns into the four output layers (E_R^dir,
/// E_R^ind, E_RV^dir, E_RV^ind; NaN where the pixel has no value of that layer).
pub fn y_pass(
    kernel: Kernel,
    columns: &Planes,
    previous: Option<Previous>,
    radius: usize,
    out: &mut [Vec3Image; 4],
) {
    // The column set is the transposed image.
    let (w, h) = (columns.height, columns.width);
    assert!(columns.planes() == COLUMN_PLANES && columns.fits_radius(radius));
    // Gather offsets are i32.
    assert!(columns.floats() <= i32::MAX as usize);
    if let Some(p) = previous {
        assert_eq!(p.columns.layout(), columns.layout());
    }
    let kernel = kernel.available();
    for layer in out.iter() {
        assert_eq!((layer.width as usize, layer.height as usize), (w, h));
    }
    if w == 0 || h == 0 {
        return;
    }
    let [er_dir, er_ind, erv_dir, erv_ind] = out;
    er_dir
        .data
        .par_chunks_mut(ROW_BAND * w)
        .zip(er_ind.data.par_chunks_mut(ROW_BAND * w))
        .zip(erv_dir.data.par_chunks_mut(ROW_BAND * w))
        .zip(erv_ind.data.par_chunks_mut(ROW_BAND * w))
        .enumerate()
        .for_each(|(band, (((r_dir, r_ind), rv_dir), rv_ind))| {
            let mut band_out = BandOut {
                y0: band * ROW_BAND,
                width: w,
                layers: [r_dir, r_ind, rv_dir, rv_ind],
            };
            let source = YSource {
                columns,
                previous,
                radius,
            };
            match kernel {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `kernel` came from `Kernel::available`: the CPU has AVX2 and FMA.
                Kernel::Avx2Fma => unsafe { y_band_avx2(&source, &mut band_out) },
                _ => y_band::<Portable>(&source, &mut band_out),
            }
        });
}

/// What the Y pass reads.
struct YSource<'a> {
    columns: &'a Planes,
    previous: Option<Previous<'a>>,
    radius: usize,
}

/// A band of rows of the four output layers, from row `y0` on.
struct BandOut<'a> {
    y0: usize,
    width: usize,
    layers: [&'a mut [Vec3]; 4],
}

impl BandOut<'_> {
    /// Sets pixel `i` of the band from its values per kind (direct, indirect) and layer
    /// (E_R, E_RV): into E_R^dir, E_RV^dir, E_R^ind, E_RV^ind.
    #[inline(always)]
    fn set(&mut self, i: usize, kinds: [[Vec3; 2]; 2]) {
        let [[r_dir, rv_dir], [r_ind, rv_ind]] = kinds;
        self.layers[0][i] = r_dir;
        self.layers[2][i] = rv_dir;
        self.layers[1][i] = r_ind;
        self.layers[3][i] = rv_ind;
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn y_band_avx2(source: &YSource, out: &mut BandOut) {
    y_band::<crate::simd::Avx2>(source, out)
}

/// The Y pass over one band of rows, [`LANES`] rows of an image column at a time.
/// Blocks of [`LANES`] x [`LANES`] pixels: eight groups along the row, then each output
/// plane's block transposed, so that an output row takes its eight pixels at once (a
/// pixel per lane into eight rows cost a quarter of the pass). Columns past the last
/// whole block are stored lane by lane.
#[inline(always)]
fn y_band<V: Lanes>(source: &YSource, out: &mut BandOut) {
    let rows = out.layers[0].len() / out.width;
    let block_columns = out.width / LANES * LANES;
    for x0 in (0..block_columns).step_by(LANES) {
        for dy0 in (0..rows).step_by(LANES) {
            let mut groups = [[[[0.0; LANES]; 6]; 2]; LANES];
            for (dx, group) in groups.iter_mut().enumerate() {
                *group = y_group::<V>(source, x0 + dx, out.y0 + dy0);
            }
            // by_row[k][p][l][dx]: kind k, plane p (E_R rgb, E_RV rgb) of pixel
            // (x0 + dx, dy0 + l).
            let mut by_row = [[[[0.0; LANES]; LANES]; 6]; 2];
            for (k, kind) in by_row.iter_mut().enumerate() {
                for (p, plane) in kind.iter_mut().enumerate() {
                    let mut columns = [V::splat(0.0); LANES];
                    for (column, group) in columns.iter_mut().zip(&groups) {
                        *column = V::from_array(group[k][p]);
                    }
                    for (row, v) in plane.iter_mut().zip(V::transpose(columns)) {
                        *row = v.to_array();
                    }
                }
            }
            for l in 0..LANES.min(rows - dy0) {
                let i = (dy0 + l) * out.width + x0;
                for dx in 0..LANES {
                    let rgb = |k: usize, layer: usize| {
                        let p = &by_row[k];
                        let c = 3 * layer;
                        Vec3::new(p[c][l][dx], p[c + 1][l][dx], p[c + 2][l][dx])
                    };
                    out.set(i + dx, [[rgb(0, 0), rgb(0, 1)], [rgb(1, 0), rgb(1, 1)]]);
                }
            }
        }
    }
    for x in block_columns..out.width {
        for dy0 in (0..rows).step_by(LANES) {
            let [dir, ind] = y_group::<V>(source, x, out.y0 + dy0);
            for l in 0..LANES.min(rows - dy0) {
                let i = (dy0 + l) * out.width + x;
                let rgb = |r: &[[f32; LANES]; 6], layer: usize| {
                    Vec3::new(r[3 * layer][l], r[3 * layer + 1][l], r[3 * layer + 2][l])
                };
                out.set(
                    i,
                    [[rgb(&dir, 0), rgb(&dir, 1)], [rgb(&ind, 0), rgb(&ind, 1)]],
                );
            }
        }
    }
}

/// The Y pass for pixels (x, y0 + l): per kind, E_R rgb then E_RV rgb per lane (NaN
/// where the target has no value of the layer).
#[inline(always)]
fn y_group<V: Lanes>(source: &YSource, x: usize, y0: usize) -> [[[f32; LANES]; 6]; 2] {
    let (columns, radius) = (source.columns, source.radius);
    let (data, s) = (columns.data(), columns.plane_stride());
    // Position y0 + l of line x: inside the planes (the padding covers lanes past the
    // height).
    let c = columns.index(y0 as isize, x);
    let mut valid = [[V::splat(0.0); 2]; 2];
    let mut any = false;
    for (k, first) in [C_DIR, C_IND].into_iter().enumerate() {
        for (layer, valid) in valid[k].iter_mut().enumerate() {
            *valid = load(data, c + (first + 6 + layer) * s);
            any |= !valid.all_zero();
        }
    }
    let mut result = [[[f32::NAN; LANES]; 6]; 2];
    if !any {
        return result;
    }
    let position = [
        load::<V>(data, c + C_PX * s),
        load::<V>(data, c + C_PY * s),
        load::<V>(data, c + C_PZ * s),
    ];
    let spatial = line_window(data, c, s, radius);
    let temporal = match source.previous {
        Some(previous) => temporal_taps::<V>(previous, position, &valid, x, y0, radius),
        None => None,
    };
    let kinds = [(C_DIR, C_B2Y_DIR), (C_IND, C_B2_IND)];
    for (k, (first, b2)) in kinds.into_iter().enumerate() {
        let [valid_r, valid_rv] = valid[k];
        if valid_r.all_zero() && valid_rv.all_zero() {
            continue;
        }
        let targets = Targets {
            position,
            b2: load(data, c + b2 * s),
        };
        let planes = TapPlanes {
            position: C_PX,
            b2,
            values: first,
        };
        let mut sums = [V::splat(0.0); VALUE_PLANES];
        // SAFETY: the taps |i| <= radius lie inside the planes (`fits_radius`), and the
        // temporal window's taps too (see `temporal_taps`).
        unsafe {
            let limit = V::splat(EXP_CUTOFF);
            accumulate(&Contiguous, &spatial, planes, &targets, limit, &mut sums);
            match &temporal {
                Some((window, TemporalFetch::Contiguous, limit)) => {
                    accumulate(&Contiguous, window, planes, &targets, *limit, &mut sums)
                }
                Some((window, TemporalFetch::Gathered(g), limit)) => {
                    accumulate(g, window, planes, &targets, *limit, &mut sums)
                }
                None => {}
            }
        }
        for (layer, ok) in valid[k].iter().enumerate() {
            let ok = ok.to_array();
            let weight = sums[6 + layer].to_array();
            for c in 0..3 {
                let sum = sums[3 * layer + c].to_array();
                for l in 0..LANES {
                    if ok[l] > 0.0 {
                        result[k][3 * layer + c][l] = sum[l] / weight[l];
                    }
                }
            }
        }
    }
    result
}

/// How the temporal taps of a group are read.
enum TemporalFetch {
    Contiguous,
    Gathered(Gathered),
}

/// The temporal taps (eq. 26) of pixels (x, y0 + l): the window over the previous
/// frame's column set around each lane's previous pixel (x', y') ([`find_previous`]),
/// how to read it, and the per-lane exp limit ([`EXP_CUTOFF`], or -1 for lanes without
/// a previous pixel: no weight). `None` when no lane has one.
#[inline(always)]
fn temporal_taps<V: Lanes>(
    previous: Previous,
    position: [V; 3],
    valid: &[[V; 2]; 2],
    x: usize,
    y0: usize,
    radius: usize,
) -> Option<(Window, TemporalFetch, V)> {
    let (px, py, pz) = (
        position[0].to_array(),
        position[1].to_array(),
        position[2].to_array(),
    );
    let valid = [
        valid[0][0].to_array(),
        valid[0][1].to_array(),
        valid[1][0].to_array(),
        valid[1][1].to_array(),
    ];
    let columns = previous.columns;
    let height = columns.width;
    let found: [Option<(usize, usize)>; LANES] = std::array::from_fn(|l| {
        let has_value = valid.iter().any(|a| a[l] > 0.0);
        let p = Vec3::new(px[l], py[l], pz[l]);
        (y0 + l < height && has_value)
            .then(|| find_previous(p, previous.view, columns))
            .flatten()
    });
    let (m, (xm, ym)) = found
        .iter()
        .enumerate()
        .find_map(|(l, f)| f.map(|p| (l, p)))?;
    // Lane m's offset along the column; lanes without a previous pixel read at the same
    // offset, at most LANES - 1 positions from lane m's pixel (inside the planes by
    // `fits_radius`), with no weight.
    let dy = ym as isize - (y0 + m) as isize;
    let same_offset = found.iter().enumerate().all(|(l, f)| match *f {
        Some((xp, yp)) => xp == xm && yp as isize == (y0 + l) as isize + dy,
        None => true,
    });
    let limit = found.map(|f| if f.is_some() { EXP_CUTOFF } else { -1.0 });
    let limit = V::from_array(limit);
    let (data, s) = (columns.data(), columns.plane_stride());
    if same_offset {
        let i = columns.index(y0 as isize + dy, xm);
        return Some((
            line_window(data, i, s, radius),
            TemporalFetch::Contiguous,
            limit,
        ));
    }
    // Different offsets: gather, each lane from its previous pixel's window (a lane
    // without one from its own pixel's, with no weight).
    let first_tap: [i32; LANES] = std::array::from_fn(|l| {
        let (x, y) = found[l].unwrap_or((x, y0 + l));
        columns.index(y as isize - radius as isize, x) as i32
    });
    let window = Window {
        planes: data.as_ptr(),
        plane_stride: s,
        tap_step: 1,
        taps: 2 * radius + 1,
    };
    Some((window, TemporalFetch::Gathered(Gathered(first_tap)), limit))
}
