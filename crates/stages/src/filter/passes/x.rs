//! The X pass (paper 001 eq. 21): filters both kinds of the input planes along image
//! rows into the X set. Each row is walked slot by slot, weighing each pair of slots
//! once (see the module docs of `passes`). The stage runs it fused with the preparation
//! ([`prepare_x_pass`]); [`x_pass`] is the pass alone, over a whole input set (the
//! reference the fused pass is tested against, and benched apart).

use super::super::MAX_RADIUS;
use super::super::gaussian::{Contiguous, VALUE_PLANES, Window, accumulate};
use super::super::lane_planes::{LaneLayout, LanePlanes, Order};
use super::super::layout::{
    B2_IND, B2X_DIR, B2Y_DIR, BandwidthSettings, DIR, IND, INPUT_PLANES, PX, PrepareInputs,
    RowLayout, X_B2_IND, X_B2Y_DIR, X_DIR, X_IND, X_PLANES, X_PX, X_PY, X_PZ,
};
use super::super::planes::{prepare_line, row_scratch};
use super::super::prepare_lanes::RowOut;
use super::sets::{PairRing, XSet, group_kinds};
use rayon::prelude::*;
use relume_base::raster::ScalarImage;
use relume_base::simd::{Kernel, LANES, Lanes, Portable};
use std::ops::Range;

/// Image rows per parallel task (even: see [`LaneLayout::blocks`]).
const ROW_BAND: usize = 16;

/// The X pass, eq. 21: filters both kinds of `input` (segments order) along image rows
/// into the X set `output` (blocks order; 0 with valid 0 where a layer has no value),
/// with the positions and the bandwidths the Y pass needs.
pub fn x_pass(kernel: Kernel, input: &LanePlanes, radius: usize, output: &mut XSet) {
    let output = output.planes_mut();
    assert!(input.planes() == INPUT_PLANES && output.planes() == X_PLANES);
    assert_eq!(
        (input.order(), output.order()),
        (Order::Segments, Order::Blocks)
    );
    assert!(input.fits_radius(radius));
    assert!(radius <= MAX_RADIUS, "radius {radius} over {MAX_RADIUS}");
    assert_eq!(
        (output.width, output.height, output.slots()),
        (input.width, input.height, input.slots())
    );
    let kernel = kernel.available();
    let height = input.height;
    let out = SetOut::new(output);
    (0..height.div_ceil(ROW_BAND))
        .into_par_iter()
        .for_each(|band| {
            let rows = band * ROW_BAND..((band + 1) * ROW_BAND).min(height);
            match kernel {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `kernel` came from `Kernel::available`: the CPU has AVX2 and FMA.
                Kernel::Avx2Fma => unsafe { x_band_avx2(input, radius, rows, &out) },
                _ => x_band::<Portable>(input, radius, rows, &out),
            }
        });
}

/// The preparation ([`super::super::planes::prepare`]) and the X pass ([`x_pass`]) at
/// once, row by row: each row is prepared into a one-line input set (about 80 KB at
/// 640 pixels wide and R = 15, which stays in the core's L2 cache) and filtered from
/// there into the X set `output`; the filter widths go
/// to `width_dir` and `width_ind`. The same bits as the two passes one after the
/// other, without writing the whole input set to memory and reading it back.
pub fn prepare_x_pass(
    kernel: Kernel,
    images: &PrepareInputs,
    settings: BandwidthSettings,
    radius: usize,
    output: &mut XSet,
    widths: [&mut ScalarImage; 2],
) {
    let output = output.planes_mut();
    let (w, h) = (output.width, output.height);
    assert!(output.planes() == X_PLANES && output.order() == Order::Blocks);
    assert!(radius <= MAX_RADIUS, "radius {radius} over {MAX_RADIUS}");
    let [width_dir, width_ind] = widths;
    for image in [&*width_dir, &*width_ind] {
        assert_eq!((image.width as usize, image.height as usize), (w, h));
    }
    if w == 0 || h == 0 {
        return;
    }
    let kernel = kernel.available();
    // The row scratch of the whole image's input set (its rows know the image height),
    // and the layout of one of its lines.
    let layout = row_scratch(&LaneLayout::segments(INPUT_PLANES, w, h, radius));
    let line = LaneLayout::segments(INPUT_PLANES, w, 1, radius);
    // The line's groups transposed are blocks of the X set (`x_row`).
    assert_eq!(output.slots(), line.slots());
    let band = ROW_BAND * w;
    let out = SetOut::new(output);
    width_dir
        .data
        .par_chunks_mut(band)
        .zip(width_ind.data.par_chunks_mut(band))
        .enumerate()
        .for_each(|(b, (width_dir, width_ind))| {
            let rows = b * ROW_BAND..b * ROW_BAND + width_dir.len() / w;
            let mut input = LanePlanes::new(line);
            let mut row = vec![0.0; layout.row_step()];
            let mut scratch = RowOut {
                row: &mut row,
                width_dir,
                width_ind,
            };
            let band = PreparedBand {
                images,
                settings,
                layout: &layout,
                radius,
                rows,
            };
            match kernel {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `kernel` came from `Kernel::available`: the CPU has AVX2 and FMA.
                Kernel::Avx2Fma => unsafe {
                    prepare_x_band_avx2(&band, &mut input, &mut scratch, &out)
                },
                _ => prepare_x_band::<Portable>(&band, &mut input, &mut scratch, &out),
            }
        });
}

/// What a task of [`prepare_x_pass`] prepares and filters: the images' rows `rows`.
struct PreparedBand<'a> {
    images: &'a PrepareInputs<'a>,
    settings: BandwidthSettings,
    layout: &'a RowLayout,
    radius: usize,
    rows: Range<usize>,
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn prepare_x_band_avx2(
    band: &PreparedBand,
    input: &mut LanePlanes,
    scratch: &mut RowOut,
    out: &SetOut,
) {
    prepare_x_band::<relume_base::simd::Avx2>(band, input, scratch, out)
}

/// [`prepare_x_pass`] for the band's rows, each prepared into the one-line set
/// `input` through `scratch` (whose filter widths are the band's), then filtered.
#[inline(always)]
fn prepare_x_band<V: Lanes>(
    band: &PreparedBand,
    input: &mut LanePlanes,
    scratch: &mut RowOut,
    out: &SetOut,
) {
    let mut ring = PairRing::<V>::new(band.radius);
    let lanes = input.layout();
    let w = lanes.width;
    for (k, y) in band.rows.clone().enumerate() {
        let mut row = RowOut {
            row: &mut *scratch.row,
            width_dir: &mut scratch.width_dir[k * w..(k + 1) * w],
            width_ind: &mut scratch.width_ind[k * w..(k + 1) * w],
        };
        let (images, settings, layout) = (band.images, band.settings, band.layout);
        prepare_line::<V>(
            images,
            settings,
            layout,
            &lanes,
            y,
            &mut row,
            input.data_mut(),
        );
        x_row::<V>(input, band.radius, 0, y, &mut ring, out);
    }
}

/// The X set, written by the X pass's tasks at once: each task writes the lines of its
/// rows (in every block and plane), and no other task does.
struct SetOut<'a> {
    data: *mut f32,
    len: usize,
    layout: LaneLayout,
    set: std::marker::PhantomData<&'a mut LanePlanes>,
}

// SAFETY: the tasks write disjoint floats (see the type's docs).
unsafe impl Sync for SetOut<'_> {}

impl<'a> SetOut<'a> {
    fn new(set: &'a mut LanePlanes) -> SetOut<'a> {
        let layout = set.layout();
        let data = set.data_mut();
        SetOut {
            data: data.as_mut_ptr(),
            len: data.len(),
            layout,
            set: std::marker::PhantomData,
        }
    }

    /// Stores plane `q` of block n, line y.
    ///
    /// # Safety
    /// No other thread may access line y meanwhile.
    #[inline(always)]
    unsafe fn store<V: Lanes>(&self, n: usize, y: usize, q: usize, v: V) {
        assert!(n < self.layout.slots() && y < self.layout.height && q < X_PLANES);
        let i = self.layout.slot_index(n as isize, y as isize) + q * self.layout.plane_stride();
        assert!(i + LANES <= self.len);
        // SAFETY: inside the set (asserted); exclusive by the caller.
        unsafe { v.store(self.data.add(i)) };
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn x_band_avx2(input: &LanePlanes, radius: usize, rows: Range<usize>, out: &SetOut) {
    x_band::<relume_base::simd::Avx2>(input, radius, rows, out)
}

/// The X pass for image rows `rows`.
#[inline(always)]
fn x_band<V: Lanes>(input: &LanePlanes, radius: usize, rows: Range<usize>, out: &SetOut) {
    let mut ring = PairRing::<V>::new(radius);
    for y in rows {
        x_row::<V>(input, radius, y, y, &mut ring, out);
    }
}

/// Row `y` of the image, line `line` of `input`, slot by slot: the pair weights of
/// each slot from -R on into `ring`, and from slot 0 on each group's X-set planes.
/// Every eight slots j0..j0 + 8 (S is a multiple of 8), their groups transposed are
/// blocks (l S + j0) / 8 of line y of the X set.
#[inline(always)]
fn x_row<V: Lanes>(
    input: &LanePlanes,
    radius: usize,
    line: usize,
    y: usize,
    ring: &mut PairRing<V>,
    out: &SetOut,
) {
    let mut groups = [[V::splat(0.0); X_PLANES]; LANES];
    let segment = input.slots();
    let (data, s) = (input.data(), input.plane_stride());
    for j in -(radius as isize)..segment as isize {
        let c = input.slot_index(j, line as isize);
        let position = ring.weigh(j, data, (c, LANES, s), PX, [B2X_DIR, B2_IND]);
        if j >= 0 {
            let j = j as usize;
            groups[j % LANES] = x_group(input, radius, c, position, ring, j as isize);
            if j % LANES == LANES - 1 {
                let j0 = j + 1 - LANES;
                for q in 0..X_PLANES {
                    let mut by_group = [V::splat(0.0); LANES];
                    for (v, group) in by_group.iter_mut().zip(&groups) {
                        *v = group[q];
                    }
                    for (l, block) in V::transpose(by_group).into_iter().enumerate() {
                        let n = (l * segment + j0) / LANES;
                        // SAFETY: line y belongs to this task.
                        unsafe { out.store(n, y, q, block) };
                    }
                }
            }
        }
    }
}

/// The X pass for the group at `c` (slot j of a row): the X set's planes, each a
/// vector over the lanes (0 with valid 0 where a layer has no value). Slots j - R..=j
/// must be in `ring`.
#[inline(always)]
fn x_group<V: Lanes>(
    input: &LanePlanes,
    radius: usize,
    c: usize,
    position: [V; 3],
    ring: &PairRing<V>,
    j: isize,
) -> [V; X_PLANES] {
    let (data, s) = (input.data(), input.plane_stride());
    let mut out = [V::splat(0.0); X_PLANES];
    out[X_PX] = position[0];
    out[X_PY] = position[1];
    out[X_PZ] = position[2];
    out[X_B2Y_DIR] = V::load_slice(data, c + B2Y_DIR * s);
    out[X_B2_IND] = V::load_slice(data, c + B2_IND * s);
    let kinds_planes = [(DIR, B2X_DIR, X_DIR), (IND, B2_IND, X_IND)];
    let (valid, kinds) = group_kinds::<V>(data, c, s, kinds_planes.map(|(v, b2, _)| (v, b2)));
    let window = Window {
        planes: data[c - radius * LANES..].as_ptr(),
        plane_stride: s,
        tap_step: LANES,
        taps: 2 * radius + 1,
    };
    for (k, (values, _, first)) in kinds_planes.into_iter().enumerate() {
        if kinds[k].is_none() {
            out[first + 6] = valid[k][0];
            out[first + 7] = valid[k][1];
            continue;
        }
        let mut sums = [V::splat(0.0); VALUE_PLANES];
        // SAFETY: the taps |i| <= radius of the slot lie inside the line (`fits_radius`).
        unsafe { accumulate(&Contiguous, &window, values, ring.taps(j, k), &mut sums) };
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
