//! The X pass (paper 001 eq. 21): filters both kinds of the input planes along image
//! rows into the X set. Each row is walked slot by slot, weighing each pair of slots
//! once (see the module docs of `passes`).

use super::super::MAX_RADIUS;
use super::super::gaussian::{Contiguous, MAX_TAPS, TapWeights, VALUE_PLANES, Window, accumulate};
use super::super::lane_planes::{LaneLayout, LanePlanes, Order};
use super::super::planes::{
    B2_IND, B2X_DIR, B2Y_DIR, DIR, IND, INPUT_PLANES, PX, X_B2_IND, X_B2Y_DIR, X_DIR, X_IND,
    X_PLANES, X_PX, X_PY, X_PZ,
};
use super::{PairRing, group_kinds};
use crate::simd::{Kernel, LANES, Lanes, Portable};
use rayon::prelude::*;
use std::ops::Range;

/// Image rows per parallel task (even: see [`LaneLayout::blocks`]).
const ROW_BAND: usize = 16;

/// The X pass, eq. 21: filters both kinds of `input` (segments order) along image rows
/// into the X set `output` (blocks order; 0 with valid 0 where a layer has no value),
/// with the positions and the bandwidths the Y pass needs.
pub fn x_pass(kernel: Kernel, input: &LanePlanes, radius: usize, output: &mut LanePlanes) {
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
    x_band::<crate::simd::Avx2>(input, radius, rows, out)
}

/// The X pass for image rows `rows`.
#[inline(always)]
fn x_band<V: Lanes>(input: &LanePlanes, radius: usize, rows: Range<usize>, out: &SetOut) {
    let mut ring = PairRing::<V>::new(radius);
    let mut weights = [[V::splat(0.0); MAX_TAPS]; 2];
    for y in rows {
        x_row::<V>(input, radius, y, &mut ring, &mut weights, out);
    }
}

/// Row `y`, slot by slot: the pair weights of each slot from -R on into `ring`, and
/// from slot 0 on each group's X-set planes. Every eight slots j0..j0 + 8 (S is a
/// multiple of 8), their groups transposed are blocks (l S + j0) / 8 of line y of the
/// X set.
#[inline(always)]
fn x_row<V: Lanes>(
    input: &LanePlanes,
    radius: usize,
    y: usize,
    ring: &mut PairRing<V>,
    weights: &mut TapWeights<V>,
    out: &SetOut,
) {
    let mut groups = [[V::splat(0.0); X_PLANES]; LANES];
    let segment = input.slots();
    let (data, s) = (input.data(), input.plane_stride());
    for j in -(radius as isize)..segment as isize {
        let c = input.slot_index(j, y as isize);
        let position = ring.weigh(j, data, (c, LANES, s), PX, [B2X_DIR, B2_IND]);
        if j >= 0 {
            let j = j as usize;
            groups[j % LANES] = x_group(input, radius, c, position, ring, j as isize, weights);
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
/// must be in `ring`. `weights` is scratch.
#[inline(always)]
fn x_group<V: Lanes>(
    input: &LanePlanes,
    radius: usize,
    c: usize,
    position: [V; 3],
    ring: &PairRing<V>,
    j: isize,
    weights: &mut TapWeights<V>,
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
        ring.group_taps(j, k, &mut weights[k]);
        let mut sums = [V::splat(0.0); VALUE_PLANES];
        // SAFETY: the taps |i| <= radius of the slot lie inside the line (`fits_radius`).
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
