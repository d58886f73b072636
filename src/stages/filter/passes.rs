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
//! lines eight positions at a time, the Y pass the output rows eight pixels at a time
//! (three vector stores of interleaved rgb, [`Lanes::interleave3`]).
//! The kernel (AVX2 + FMA or portable, [`Kernel`]) is chosen
//! per band; both give the same bits.
//!
//! The lane operations are never called from closures: closures do not inherit
//! `#[target_feature]`, and their lane operations would not be inlined.

use super::MAX_RADIUS;
use super::gaussian::{
    Bandwidths, Contiguous, EXP_CUTOFF, Fetch, Gathered, MAX_TAPS, TapWeights, VALUE_PLANES,
    Window, accumulate, tap_weights,
};
use super::planes::{
    B2_IND, B2X_DIR, B2Y_DIR, C_B2_IND, C_B2Y_DIR, C_DIR, C_IND, C_PX, C_PY, C_PZ, COLUMN_PLANES,
    DIR, IND, INPUT_PLANES, Layout, PX, PY, PZ, Planes,
};
use super::temporal::{PreviousView, find_previous_lanes};
use crate::raster::Vec3Image;
use crate::simd::{Kernel, LANES, Lanes, Portable};
use glam::Vec3;
use rayon::prelude::*;

/// Image columns per parallel task of the X pass (its lines of the column set; a
/// multiple of [`LANES`], so that no group of lanes spans two tasks). 32 was about 8 %
/// faster than 16 once the X pass stored whole blocks; 64 was within the noise.
const COLUMN_BAND: usize = 32;
/// Image rows per parallel task of the Y pass (a multiple of [`LANES`]). A task reads
/// R rows above and below its band: 48 rows took the temporal Y pass from 41 to 35 ms
/// against 24 (fewer rows read twice); 96 was no faster.
const ROW_BAND: usize = 48;
const _: () = assert!(COLUMN_BAND.is_multiple_of(LANES) && ROW_BAND.is_multiple_of(LANES));

/// The previous frame as the temporal taps read it: its column set (positions,
/// bandwidths, and its X-filtered layers, E'_X of eq. 26) and its camera.
#[derive(Clone, Copy)]
pub struct Previous<'a> {
    pub columns: &'a Planes,
    pub view: &'a PreviousView,
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
    assert!(radius <= MAX_RADIUS, "radius {radius} over {MAX_RADIUS}");
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
    let mut weights = [[V::splat(0.0); MAX_TAPS]; 2];
    for y0 in (0..block_rows).step_by(LANES) {
        for x0 in (x_start..x_end).step_by(LANES) {
            let lanes = LANES.min(x_end - x0);
            let mut block = [[V::splat(0.0); LANES]; COLUMN_PLANES];
            for r in 0..LANES {
                let group = x_group::<V>(input, radius, x0, y0 + r, &mut weights);
                for (rows, v) in block.iter_mut().zip(group) {
                    rows[r] = v;
                }
            }
            for (q, rows) in block.into_iter().enumerate() {
                let first = (x0 - x_start) * layout.row_step() + layout.in_row(q, y0);
                for (l, column) in V::transpose(rows).into_iter().enumerate().take(lanes) {
                    column.store_slice(lines, first + l * layout.row_step());
                }
            }
        }
    }
    for y in block_rows..input.height {
        for x0 in (x_start..x_end).step_by(LANES) {
            let lanes = LANES.min(x_end - x0);
            let group = x_group::<V>(input, radius, x0, y, &mut weights);
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
/// lanes (0 with valid 0 where a layer has no value). `weights` is scratch.
#[inline(always)]
fn x_group<V: Lanes>(
    input: &Planes,
    radius: usize,
    x0: usize,
    y: usize,
    weights: &mut TapWeights<V>,
) -> [V; COLUMN_PLANES] {
    let (data, s) = (input.data(), input.plane_stride());
    let mut out = [V::splat(0.0); COLUMN_PLANES];
    // Pixel (x0 + l, y) of any plane is inside the planes: the padding covers a group's
    // lanes past the width.
    let c = input.index(x0 as isize, y);
    let position = [
        V::load_slice(data, c + PX * s),
        V::load_slice(data, c + PY * s),
        V::load_slice(data, c + PZ * s),
    ];
    out[C_PX] = position[0];
    out[C_PY] = position[1];
    out[C_PZ] = position[2];
    out[C_B2Y_DIR] = V::load_slice(data, c + B2Y_DIR * s);
    out[C_B2_IND] = V::load_slice(data, c + B2_IND * s);
    let kinds_planes = [(DIR, B2X_DIR, C_DIR), (IND, B2_IND, C_IND)];
    let (valid, kinds) = group_kinds(data, c, s, kinds_planes.map(|(v, b2, _)| (v, b2)));
    let window = line_window(data, c, s, radius);
    // SAFETY: the taps |i| <= radius of the group lie inside the row's planes
    // (`fits_radius`).
    unsafe {
        let limit = V::splat(EXP_CUTOFF);
        tap_weights(&Contiguous, &window, PX, position, kinds, limit, weights);
    }
    for (k, (values, _, first)) in kinds_planes.into_iter().enumerate() {
        if kinds[k].is_none() {
            out[first + 6] = valid[k][0];
            out[first + 7] = valid[k][1];
            continue;
        }
        let mut sums = [V::splat(0.0); VALUE_PLANES];
        // SAFETY: as for the weights.
        unsafe { accumulate(&Contiguous, &window, values, &weights[k], &mut sums) };
        for (layer, &ok) in valid[k].iter().enumerate() {
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
    assert!(radius <= MAX_RADIUS, "radius {radius} over {MAX_RADIUS}");
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

// The output rows are stored as floats: a Vec3 is three f32.
const _: () = assert!(std::mem::size_of::<Vec3>() == 3 * std::mem::size_of::<f32>());

impl BandOut<'_> {
    /// Stores pixels `i..i + LANES` of the band's layer of kind `k` (direct,
    /// indirect) and `layer` (E_R, E_RV) from their r, g and b lanes.
    #[inline(always)]
    fn store_row<V: Lanes>(&mut self, k: usize, layer: usize, i: usize, rgb: [V; 3]) {
        let pixels = &mut self.layers[k + 2 * layer][i..i + LANES];
        let floats = pixels.as_mut_ptr().cast::<f32>();
        for (r, triples) in V::interleave3(rgb).into_iter().enumerate() {
            // SAFETY: the LANES pixels are 3 LANES floats (Vec3 is #[repr(C)], three
            // f32); this stores floats LANES r.. LANES r + LANES of them.
            unsafe { triples.store(floats.add(LANES * r)) };
        }
    }

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
    let mut weights = [[V::splat(0.0); MAX_TAPS]; 2];
    for x0 in (0..block_columns).step_by(LANES) {
        for dy0 in (0..rows).step_by(LANES) {
            let mut groups = [[[V::splat(0.0); 6]; 2]; LANES];
            for (dx, group) in groups.iter_mut().enumerate() {
                *group = y_group::<V>(source, x0 + dx, out.y0 + dy0, &mut weights);
            }
            // by_row[k][p][l], lane dx: kind k, plane p (E_R rgb, E_RV rgb) of pixel
            // (x0 + dx, dy0 + l).
            let mut by_row = [[[V::splat(0.0); LANES]; 6]; 2];
            for (k, kind) in by_row.iter_mut().enumerate() {
                for (p, plane) in kind.iter_mut().enumerate() {
                    let mut columns = [V::splat(0.0); LANES];
                    for (column, group) in columns.iter_mut().zip(&groups) {
                        *column = group[k][p];
                    }
                    *plane = V::transpose(columns);
                }
            }
            for l in 0..LANES.min(rows - dy0) {
                let i = (dy0 + l) * out.width + x0;
                for (k, kind) in by_row.iter().enumerate() {
                    for layer in 0..2 {
                        let c = 3 * layer;
                        let rgb = [kind[c][l], kind[c + 1][l], kind[c + 2][l]];
                        out.store_row(k, layer, i, rgb);
                    }
                }
            }
        }
    }
    for x in block_columns..out.width {
        for dy0 in (0..rows).step_by(LANES) {
            let kinds = y_group::<V>(source, x, out.y0 + dy0, &mut weights);
            let mut by_lane = [[[0.0; LANES]; 6]; 2];
            for (k, kind) in kinds.iter().enumerate() {
                for (q, plane) in kind.iter().enumerate() {
                    by_lane[k][q] = plane.to_array();
                }
            }
            let [dir, ind] = by_lane;
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
/// where the target has no value of the layer). `weights` is scratch.
#[inline(always)]
fn y_group<V: Lanes>(
    source: &YSource,
    x: usize,
    y0: usize,
    weights: &mut TapWeights<V>,
) -> [[V; 6]; 2] {
    let (columns, radius) = (source.columns, source.radius);
    let (data, s) = (columns.data(), columns.plane_stride());
    // Position y0 + l of line x: inside the planes (the padding covers lanes past the
    // height).
    let c = columns.index(y0 as isize, x);
    let kinds_planes = [(C_DIR, C_B2Y_DIR), (C_IND, C_B2_IND)];
    let (valid, kinds) = group_kinds(data, c, s, kinds_planes);
    let nan = V::splat(f32::NAN);
    let mut result = [[nan; 6]; 2];
    if kinds.iter().all(Option::is_none) {
        return result;
    }
    let position = [
        V::load_slice(data, c + C_PX * s),
        V::load_slice(data, c + C_PY * s),
        V::load_slice(data, c + C_PZ * s),
    ];
    let mut sums = [[V::splat(0.0); VALUE_PLANES]; 2];
    let group = GroupTaps {
        position,
        kinds,
        first: kinds_planes.map(|(first, _)| first),
    };
    // SAFETY: the taps |i| <= radius lie inside the planes (`fits_radius`), and the
    // temporal window's taps too (see `temporal_taps`).
    unsafe {
        let spatial = line_window(data, c, s, radius);
        // The next line's window, which the next group reads (see `prefetch_next_line`).
        prefetch_next_line(&spatial, columns.row_step());
        let limit = V::splat(EXP_CUTOFF);
        group.add(&Contiguous, &spatial, limit, weights, &mut sums);
        if let Some(previous) = source.previous {
            match temporal_taps::<V>(previous, position, &valid, x, y0, radius) {
                Some((window, TemporalFetch::Contiguous, limit)) => {
                    prefetch_next_line(&window, previous.columns.row_step());
                    group.add(&Contiguous, &window, limit, weights, &mut sums)
                }
                Some((window, TemporalFetch::Gathered(g), limit)) => {
                    group.add(&g, &window, limit, weights, &mut sums)
                }
                None => {}
            }
        }
    }
    for (k, sums) in sums.iter().enumerate() {
        if kinds[k].is_none() {
            continue;
        }
        for (layer, ok) in valid[k].iter().enumerate() {
            let ok = ok.gt(V::splat(0.0));
            for c in 0..3 {
                let value = sums[3 * layer + c].div(sums[6 + layer]);
                result[k][3 * layer + c] = V::select(ok, value, nan);
            }
        }
    }
    result
}

/// The valid planes (valid_R, valid_RV) of both kinds at index `c` of the planes (plane
/// stride `s`), each kind given by its first value plane and its squared-bandwidth
/// plane; and the bandwidths of the kinds with a value somewhere in the group (`None`
/// for the others: they are not filtered). A loop, not closures: closures do not
/// inherit `#[target_feature]`.
#[inline(always)]
#[allow(clippy::type_complexity)]
fn group_kinds<V: Lanes>(
    data: &[f32],
    c: usize,
    s: usize,
    kinds_planes: [(usize, usize); 2],
) -> ([[V; 2]; 2], [Option<Bandwidths<V>>; 2]) {
    let mut valid = [[V::splat(0.0); 2]; 2];
    let mut kinds = [None; 2];
    for (k, (values, b2)) in kinds_planes.into_iter().enumerate() {
        valid[k] = [
            V::load_slice(data, c + (values + 6) * s),
            V::load_slice(data, c + (values + 7) * s),
        ];
        if !(valid[k][0].all_zero() && valid[k][1].all_zero()) {
            kinds[k] = Some(Bandwidths {
                plane: b2,
                target: V::load_slice(data, c + b2 * s),
            });
        }
    }
    (valid, kinds)
}

/// A group's targets in the Y pass: their positions, the kinds being filtered, and
/// each kind's first value plane.
struct GroupTaps<V> {
    position: [V; 3],
    kinds: [Option<Bandwidths<V>>; 2],
    first: [usize; 2],
}

impl<V: Lanes> GroupTaps<V> {
    /// Adds the weighted taps of `window` to each filtered kind's `sums`.
    ///
    /// # Safety
    /// Every tap of `window` that `fetch` reads must lie inside its planes.
    #[inline(always)]
    unsafe fn add<F: Fetch<V>>(
        &self,
        fetch: &F,
        window: &Window,
        limit: V,
        weights: &mut TapWeights<V>,
        sums: &mut [[V; VALUE_PLANES]; 2],
    ) {
        // SAFETY: forwarded from the caller.
        unsafe {
            tap_weights(
                fetch,
                window,
                C_PX,
                self.position,
                self.kinds,
                limit,
                weights,
            );
            for k in 0..2 {
                if self.kinds[k].is_some() {
                    accumulate(fetch, window, self.first[k], &weights[k], &mut sums[k]);
                }
            }
        }
    }
}

/// How the temporal taps of a group are read.
enum TemporalFetch {
    Contiguous,
    Gathered(Gathered),
}

/// The temporal taps (eq. 26) of pixels (x, y0 + l): the window over the previous
/// frame's column set around each lane's previous pixel (x', y')
/// ([`find_previous_lanes`]),
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
    let valid = [
        valid[0][0].to_array(),
        valid[0][1].to_array(),
        valid[1][0].to_array(),
        valid[1][1].to_array(),
    ];
    let columns = previous.columns;
    let height = columns.width;
    let active: [bool; LANES] =
        std::array::from_fn(|l| y0 + l < height && valid.iter().any(|a| a[l] > 0.0));
    let found = find_previous_lanes(position, active, previous.view, columns);
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

/// Asks the CPU to fetch the window `window` of the next line of a column set
/// (`row_step` floats further): the next group of the Y pass reads it (the groups of a
/// block go line by line). Each group's taps are some 3 cache lines in each of the 21
/// planes, too short a run for the hardware prefetchers; the previous frame's column
/// set does not fit the L3 beside the current one. This took the temporal Y pass from
/// 34 to 27-29 ms and the spatial one from 13.5 to 11.4-12 ms (640x480, 2 threads).
/// The X pass has none: prefetching its next row made it 1 ms slower, 8 rows ahead
/// was within the noise.
#[inline(always)]
fn prefetch_next_line(window: &Window, row_step: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // The window's floats in a plane: its taps and the lanes past the last.
        let floats = window.taps + LANES - 1;
        let next = window.planes.wrapping_add(row_step);
        for q in 0..COLUMN_PLANES {
            let first = next.wrapping_add(q * window.plane_stride);
            // Every cache line (16 floats) from the first float to the last.
            let mut i = 0;
            while i < floats {
                // SAFETY (both): a prefetch reads nothing and never faults, whatever
                // the address (past the last line it fetches nothing useful).
                unsafe { _mm_prefetch::<_MM_HINT_T0>(first.wrapping_add(i).cast()) };
                i += 16;
            }
            unsafe { _mm_prefetch::<_MM_HINT_T0>(first.wrapping_add(floats - 1).cast()) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (window, row_step);
}
