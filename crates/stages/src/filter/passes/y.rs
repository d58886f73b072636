//! The Y pass (paper 001 eq. 22) with the temporal taps of the previous frame (eq. 26),
//! from the X set (blocks order) into the output images.
//!
//! A task takes one block n (pixels 8 n..8 n + 8 of every row) and walks it down the
//! image, line by line: the pair weights of the line (see the module docs of
//! `passes`), then its group of eight targets, whose results are eight consecutive
//! pixels of the line, stored as three vectors of interleaved rgb per layer
//! ([`Lanes::interleave3`]).

use super::super::MAX_RADIUS;
use super::super::gaussian::{
    Bandwidths, Contiguous, Fetch, MAX_TAPS, TapWeights, VALUE_PLANES, Window, accumulate,
    accumulate_full, tap_weights,
};
use super::super::lane_planes::{LanePlanes, Order};
use super::super::layout::{X_B2_IND, X_B2Y_DIR, X_DIR, X_IND, X_PLANES, X_PX, X_PY, X_PZ};
use super::blended::BlendedLines;
use super::sets::{PairRing, Previous, XSet, group_kinds};
use super::taps::{TemporalTaps, temporal_taps};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::raster::Vec3Image;
use relume_base::simd::{Kernel, LANES, Lanes, Portable};

/// The Y pass, eq. 22, with the temporal taps of eq. 26 when `previous` is given:
/// filters the X set along image columns into the four output layers (E_R^dir,
/// E_R^ind, E_RV^dir, E_RV^ind; NaN where the pixel has no value of that layer), and
/// finds the set's full windows, which it keeps (for the next frame's temporal taps).
pub fn y_pass(
    kernel: Kernel,
    x_set: &mut XSet,
    previous: Option<Previous>,
    radius: usize,
    out: &mut [Vec3Image; 4],
) {
    let XSet {
        planes: x_set,
        full_windows,
    } = x_set;
    let x_set = &*x_set;
    let (w, h) = (x_set.width, x_set.height);
    assert!(x_set.planes() == X_PLANES && x_set.fits_lines(radius));
    assert!(radius <= MAX_RADIUS, "radius {radius} over {MAX_RADIUS}");
    // Gather offsets are i32.
    assert!(x_set.floats() <= i32::MAX as usize);
    if let Some(p) = previous {
        assert_eq!(p.x_set.planes().layout(), x_set.layout());
    }
    let kernel = kernel.available();
    assert_eq!(x_set.order(), Order::Blocks);
    for layer in out.iter() {
        assert_eq!((layer.width as usize, layer.height as usize), (w, h));
        // `ImagesOut` writes through raw pointers.
        assert_eq!(layer.data.len(), w * h);
    }
    full_windows.reset(x_set);
    if w == 0 || h == 0 {
        return;
    }
    let out = ImagesOut::new(out);
    let source = YSource {
        x_set,
        previous,
        radius,
    };
    full_windows
        .bits
        .par_chunks_mut(h)
        .enumerate()
        .for_each(|(n, full)| match kernel {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `kernel` came from `Kernel::available`: the CPU has AVX2 and FMA.
            Kernel::Avx2Fma => unsafe { y_block_avx2(&source, n, &out, full) },
            _ => y_block::<Portable>(&source, n, &out, full),
        });
}

/// What the Y pass reads.
struct YSource<'a> {
    x_set: &'a LanePlanes,
    previous: Option<Previous<'a>>,
    radius: usize,
}

// The output rows are stored as floats: a Vec3 is three f32.
const _: () = assert!(std::mem::size_of::<Vec3>() == 3 * std::mem::size_of::<f32>());

/// The four output layers, written by the Y pass's tasks at once: a task writes the
/// pixels 8 n..8 n + 8 of every row for its block n, and no other task does.
struct ImagesOut<'a> {
    layers: [*mut Vec3; 4],
    width: usize,
    height: usize,
    images: std::marker::PhantomData<&'a mut [Vec3Image; 4]>,
}

// SAFETY: the tasks write disjoint pixels (see the type's docs).
unsafe impl Sync for ImagesOut<'_> {}

impl<'a> ImagesOut<'a> {
    fn new(images: &'a mut [Vec3Image; 4]) -> ImagesOut<'a> {
        let (width, height) = (images[0].width as usize, images[0].height as usize);
        ImagesOut {
            layers: images.each_mut().map(|image| image.data.as_mut_ptr()),
            width,
            height,
            images: std::marker::PhantomData,
        }
    }

    /// Stores pixels x..x + LANES of row y of the layer of kind `k` (direct,
    /// indirect) and `layer` (E_R, E_RV) from their r, g and b lanes.
    ///
    /// # Safety
    /// No other thread may access those pixels meanwhile.
    #[inline(always)]
    unsafe fn store_run<V: Lanes>(&self, k: usize, layer: usize, x: usize, y: usize, rgb: [V; 3]) {
        assert!(x + LANES <= self.width && y < self.height);
        // SAFETY: the LANES pixels are inside the image (asserted), 3 LANES floats
        // (Vec3 is #[repr(C)], three f32); exclusive by the caller.
        unsafe {
            let floats = self.layers[k + 2 * layer]
                .add(y * self.width + x)
                .cast::<f32>();
            for (r, triples) in V::interleave3(rgb).into_iter().enumerate() {
                triples.store(floats.add(LANES * r));
            }
        }
    }

    /// Sets pixel (x, y) of the layer of kind `k` and `layer`.
    ///
    /// # Safety
    /// As for [`ImagesOut::store_run`].
    #[inline(always)]
    unsafe fn set(&self, k: usize, layer: usize, x: usize, y: usize, value: Vec3) {
        assert!(x < self.width && y < self.height);
        // SAFETY: inside the image (asserted); exclusive by the caller.
        unsafe { *self.layers[k + 2 * layer].add(y * self.width + x) = value };
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn y_block_avx2(source: &YSource, n: usize, out: &ImagesOut, full: &mut [u8]) {
    y_block::<relume_base::simd::Avx2>(source, n, out, full)
}

/// The Y pass for block n, walked down the image: the pair weights of each line from
/// -R on, then from line 0 on the line's group, stored into `out`, and whether its
/// windows are full into `full` (the block's bits of [`FullWindows`]).
#[inline(always)]
fn y_block<V: Lanes>(source: &YSource, n: usize, out: &ImagesOut, full: &mut [u8]) {
    let (x_set, radius) = (source.x_set, source.radius);
    let (data, s) = (x_set.data(), x_set.plane_stride());
    let mut ring = PairRing::<V>::new(radius);
    let mut blended = BlendedLines::<V>::new(radius);
    let mut weights = [[V::splat(0.0); MAX_TAPS]; 2];
    let x0 = n * LANES;
    let pixels = LANES.min(out.width - x0);
    let height = x_set.height as isize;
    let r = radius as isize;
    // Per kind, the last line up to y + R where some lane misses a value (the padding
    // lines before line 0 and from the height on have none).
    let mut last_gap = [-1isize; 2];
    for y in -r..height {
        let c = x_set.slot_index(n as isize, y);
        ring.weigh(
            y,
            data,
            (c, x_set.line_step(), s),
            X_PX,
            [X_B2Y_DIR, X_B2_IND],
        );
        let ahead = y + r;
        for (k, first) in [X_DIR, X_IND].into_iter().enumerate() {
            if ahead >= height || has_gap::<V>(data, x_set.slot_index(n as isize, ahead), s, first)
            {
                last_gap[k] = ahead;
            }
        }
        if y < 0 {
            continue;
        }
        let full_kinds = [y - r > last_gap[0], y - r > last_gap[1]];
        let y = y as usize;
        full[y] = full_kinds[0] as u8 | (full_kinds[1] as u8) << 1;
        let group = y_group::<V>(source, n, y, &ring, &mut blended, &mut weights, full_kinds);
        for (k, kind) in group.iter().enumerate() {
            for layer in 0..2 {
                let c = 3 * layer;
                let rgb = [kind[c], kind[c + 1], kind[c + 2]];
                if pixels == LANES {
                    // SAFETY: pixels x0..x0 + 8 of row y belong to this task's block.
                    unsafe { out.store_run(k, layer, x0, y, rgb) };
                } else {
                    let (r, g, b) = (rgb[0].to_array(), rgb[1].to_array(), rgb[2].to_array());
                    for l in 0..pixels {
                        // SAFETY: as above.
                        unsafe { out.set(k, layer, x0 + l, y, Vec3::new(r[l], g[l], b[l])) };
                    }
                }
            }
        }
    }
}

/// Whether some lane of the X set at index `c` (plane stride `s`) misses a value of the
/// kind whose value planes start at `first` (either valid plane below 1).
#[inline(always)]
fn has_gap<V: Lanes>(data: &[f32], c: usize, s: usize, first: usize) -> bool {
    let valid_r = V::load_slice(data, c + (first + 6) * s);
    let valid_rv = V::load_slice(data, c + (first + 7) * s);
    valid_r.min(valid_rv).lt(V::splat(1.0)).any()
}

/// The Y pass for the group at block n of line y (pixels (8 n + l, y)): per kind, E_R
/// rgb then E_RV rgb per lane (NaN where the target has no value of the layer). Lines
/// y - R..=y must be in `ring`; `full` says which kinds' spatial windows are full.
/// `blended` keeps the rotated temporal taps' lines from group to group; `weights` is
/// scratch for the temporal taps.
#[inline(always)]
fn y_group<V: Lanes>(
    source: &YSource,
    n: usize,
    y: usize,
    ring: &PairRing<V>,
    blended: &mut BlendedLines<V>,
    weights: &mut TapWeights<V>,
    full: [bool; 2],
) -> [[V; 6]; 2] {
    let (x_set, radius) = (source.x_set, source.radius);
    let (data, s) = (x_set.data(), x_set.plane_stride());
    let c = x_set.slot_index(n as isize, y as isize);
    let kinds_planes = [(X_DIR, X_B2Y_DIR), (X_IND, X_B2_IND)];
    let (valid, kinds) = group_kinds(data, c, s, kinds_planes);
    let nan = V::splat(f32::NAN);
    let mut result = [[nan; 6]; 2];
    if kinds.iter().all(Option::is_none) {
        return result;
    }
    let position = [
        V::load_slice(data, c + X_PX * s),
        V::load_slice(data, c + X_PY * s),
        V::load_slice(data, c + X_PZ * s),
    ];
    let mut sums = [[V::splat(0.0); VALUE_PLANES]; 2];
    let spatial = Window {
        planes: data[c - radius * x_set.line_step()..].as_ptr(),
        plane_stride: s,
        tap_step: x_set.line_step(),
        taps: 2 * radius + 1,
    };
    for (k, (values, _)) in kinds_planes.into_iter().enumerate() {
        if kinds[k].is_some() {
            let taps = ring.taps(y as isize, k);
            let sums = &mut sums[k];
            // SAFETY: lines y - R..=y + R lie inside the set (`fits_lines`).
            unsafe {
                if full[k] {
                    accumulate_full(&Contiguous, &spatial, values, taps, sums)
                } else {
                    accumulate(&Contiguous, &spatial, values, taps, sums)
                }
            }
        }
    }
    if let Some(previous) = source.previous {
        let group = GroupTaps {
            position,
            kinds,
            first: kinds_planes.map(|(first, _)| first),
        };
        // SAFETY: the temporal windows' taps lie inside the previous set (see
        // `temporal_taps`).
        unsafe {
            match temporal_taps::<V>(previous, position, &valid, n * LANES, y, radius) {
                TemporalTaps::Contiguous(window, limit, full) => {
                    group.add(&Contiguous, &[window], limit, full, weights, &mut sums)
                }
                TemporalTaps::Rotated {
                    straddling,
                    limit,
                    block,
                    rotation: r,
                    first_line,
                    full,
                } => {
                    let windows = blended.windows(
                        previous.x_set.planes(),
                        &straddling,
                        (block, r),
                        first_line,
                    );
                    // Each target to the lane of its source (see `TemporalTaps`), and
                    // its sums back after.
                    let mut rotated = group;
                    for p in &mut rotated.position {
                        *p = p.rotate_up(r);
                    }
                    for b in rotated.kinds.iter_mut().flatten() {
                        b.target = b.target.rotate_up(r);
                    }
                    rotate_sums(&mut sums, r);
                    let limit = limit.rotate_up(r);
                    rotated.add(&Contiguous, &windows, limit, full, weights, &mut sums);
                    rotate_sums(&mut sums, LANES - r);
                }
                TemporalTaps::Permuted(window, permuted, limit, full) => {
                    let (w, s) = (weights, &mut sums);
                    match permuted.count() {
                        1 => group.add(&permuted.fetch::<1>(), &[window], limit, full, w, s),
                        2 => group.add(&permuted.fetch::<2>(), &[window], limit, full, w, s),
                        _ => group.add(&permuted.fetch::<3>(), &[window], limit, full, w, s),
                    }
                }
                TemporalTaps::Gathered(window, g, limit) => {
                    group.add(&g, &[window], limit, 0, weights, &mut sums)
                }
                TemporalTaps::None => {}
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

/// Rotates every lane of `sums` up by `r` ([`Lanes::rotate_up`]).
#[inline(always)]
fn rotate_sums<V: Lanes>(sums: &mut [[V; VALUE_PLANES]; 2], r: usize) {
    for kind in sums.iter_mut() {
        for sum in kind.iter_mut() {
            *sum = sum.rotate_up(r);
        }
    }
}

/// A group's targets in the Y pass: their positions, the kinds being filtered, and
/// each kind's first value plane.
#[derive(Clone, Copy)]
struct GroupTaps<V> {
    position: [V; 3],
    kinds: [Option<Bandwidths<V>>; 2],
    first: [usize; 2],
}

impl<V: Lanes> GroupTaps<V> {
    /// Adds the weighted taps of `windows` (taps of one window in pieces, in order) to
    /// each filtered kind's `sums`; the kinds whose bit is set in `full` are full in
    /// the window ([`FullWindows`]).
    ///
    /// # Safety
    /// Every tap of `windows` that `fetch` reads must lie inside its planes.
    #[inline(always)]
    unsafe fn add<F: Fetch<V>>(
        &self,
        fetch: &F,
        windows: &[Window],
        limit: V,
        full: u8,
        weights: &mut TapWeights<V>,
        sums: &mut [[V; VALUE_PLANES]; 2],
    ) {
        // SAFETY (all calls): forwarded from the caller.
        unsafe {
            let mut first_tap = 0;
            for window in windows {
                let [direct, indirect] = weights;
                tap_weights(
                    fetch,
                    window,
                    X_PX,
                    self.position,
                    self.kinds,
                    limit,
                    [&mut direct[first_tap..], &mut indirect[first_tap..]],
                );
                first_tap += window.taps;
            }
            for k in 0..2 {
                if self.kinds[k].is_none() {
                    continue;
                }
                let (first, sums) = (self.first[k], &mut sums[k]);
                let mut first_tap = 0;
                for window in windows {
                    let weights = &weights[k][first_tap..];
                    if full & (1 << k) != 0 {
                        accumulate_full(fetch, window, first, weights, sums);
                    } else {
                        accumulate(fetch, window, first, weights, sums);
                    }
                    first_tap += window.taps;
                }
            }
        }
    }
}
