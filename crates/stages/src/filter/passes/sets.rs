//! The sets the passes share (see [`super`]): the X set between them, the previous
//! frame's view for the temporal taps, the full windows of a row, and the ring of pair
//! weights each pass walks.

#[cfg(doc)]
use super::super::gaussian::accumulate_full;
use super::super::gaussian::{Bandwidths, Contiguous, EXP_CUTOFF, Window, tap_weights};
use super::super::lane_planes::{LaneLayout, LanePlanes};
use super::super::temporal::PreviousView;
#[cfg(doc)]
use relume_base::simd::Kernel;
use relume_base::simd::{LANES, Lanes};

/// The previous frame as the temporal taps read it: its X set (positions, bandwidths,
/// and its X-filtered layers, E'_X of eq. 26, with the full windows its Y pass found)
/// and its camera.
#[derive(Clone, Copy)]
pub struct Previous<'a> {
    pub x_set: &'a XSet,
    pub view: &'a PreviousView,
}

/// The X set (the X pass's output, the Y pass's input: [`X_PLANES`](crate::filter::layout::X_PLANES)
/// lane planes in blocks order) with the full windows the Y pass found in it, kept
/// together so that a frame's temporal taps read the windows of the planes they read.
/// Writing the planes ([`XSet::planes_mut`]) forgets the windows; the Y pass finds
/// them again.
#[derive(Clone, Debug, Default)]
pub struct XSet {
    pub(super) planes: LanePlanes,
    pub(super) full_windows: FullWindows,
}

impl XSet {
    /// Planes of `layout` (zeros), with no window known to be full.
    pub fn new(layout: LaneLayout) -> XSet {
        XSet::from_planes(LanePlanes::new(layout))
    }

    /// `planes`, with no window known to be full.
    pub fn from_planes(planes: LanePlanes) -> XSet {
        XSet {
            planes,
            full_windows: FullWindows::default(),
        }
    }

    /// The planes.
    pub fn planes(&self) -> &LanePlanes {
        &self.planes
    }

    /// The planes, for writing: forgets which windows are full.
    pub fn planes_mut(&mut self) -> &mut LanePlanes {
        self.full_windows.forget();
        &mut self.planes
    }

    /// The full windows found by the last Y pass over these planes (none before it).
    pub fn full_windows(&self) -> &FullWindows {
        &self.full_windows
    }
}

/// Which Y windows of an X set are full: per block n and line y, bit k (0 direct, 1
/// indirect) is set when every tap of the window of kind k there (lines y - R..=y + R
/// of block n, all eight lanes) has both layers' values, so that its sums may skip the
/// valid planes ([`accumulate_full`]: the same bits). The Y pass finds them as it walks
/// each block down, for its own spatial taps, and keeps them with the set ([`XSet`]);
/// a frame later, the temporal taps whose window lies on one or two blocks of that set
/// read them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FullWindows {
    pub(super) lines: usize,
    /// Block n's bits at `n * lines..(n + 1) * lines`.
    pub(super) bits: Vec<u8>,
}

impl FullWindows {
    /// Sized for `x_set` (a block per eight pixels of a line), every window marked not
    /// full.
    pub(super) fn reset(&mut self, x_set: &LanePlanes) {
        self.lines = x_set.height;
        self.bits.clear();
        self.bits
            .resize(x_set.width.div_ceil(LANES) * x_set.height, 0);
    }

    /// No window marked full (the allocation kept for the next [`FullWindows::reset`]).
    pub(super) fn forget(&mut self) {
        self.lines = 0;
        self.bits.clear();
    }

    /// The bits of the window at block `block`, line `line` (0 outside the image's
    /// blocks and lines, e.g. the zero blocks on each side, before the first frame, and
    /// after the planes were rewritten: [`XSet::planes_mut`]).
    #[inline(always)]
    pub(super) fn get(&self, block: isize, line: isize) -> u8 {
        if block < 0 || line < 0 || line as usize >= self.lines {
            return 0;
        }
        let i = block as usize * self.lines + line as usize;
        self.bits.get(i).copied().unwrap_or(0)
    }
}

/// The pair weights of the groups along a pass's direction (slots j of a row in the X
/// pass, lines y of a slot in the Y pass), as each group's taps: for group j and kind,
/// tap i = -R..=R at entry R + i of its row, the weight of pair (j, j + i). The walk
/// weighs group j's forward pairs (j, j + k), k = 0..=R (k = 0: the targets with
/// themselves) into entries R + k of its row and, as tap -k of group j + k, into entry
/// R - k of that group's row; so when the walk reaches target j, after weighing it,
/// its row is complete. Rows j..=j + R are live at once: R + 1 rows, row j at
/// (j + R) mod (R + 1). See the module docs.
pub(super) struct PairRing<V> {
    pub(super) radius: usize,
    pub(super) weights: Vec<V>,
}

impl<V: Lanes> PairRing<V> {
    pub(super) fn new(radius: usize) -> PairRing<V> {
        PairRing {
            radius,
            weights: vec![V::splat(0.0); (radius + 1) * 2 * (2 * radius + 1)],
        }
    }

    /// Index of kind `kind`'s tap -R of group j in the ring (j >= -R).
    #[inline(always)]
    pub(super) fn first(&self, j: isize, kind: usize) -> usize {
        let taps = 2 * self.radius + 1;
        let row = (j + self.radius as isize) as usize % (self.radius + 1);
        (2 * row + kind) * taps
    }

    /// Both kinds' forward pair weights of group j (its taps 0..=R), for writing.
    #[inline(always)]
    pub(super) fn forward_mut(&mut self, j: isize) -> [&mut [V]; 2] {
        let (r, taps) = (self.radius, 2 * self.radius + 1);
        let first = self.first(j, 0);
        let (direct, indirect) = self.weights[first..first + 2 * taps].split_at_mut(taps);
        [&mut direct[r..], &mut indirect[r..]]
    }

    /// Weighs group j's pairs (j, j + k), k = 0..=R, both kinds: the eight targets at
    /// `data[c..]`, the groups `step` floats apart, planes `plane_stride` apart, the
    /// positions in three planes from `position` on, the squared bandwidths of the
    /// kinds in planes `bandwidths`. Returns the targets' positions.
    #[inline(always)]
    pub(super) fn weigh(
        &mut self,
        j: isize,
        data: &[f32],
        (c, step, plane_stride): (usize, usize, usize),
        position: usize,
        bandwidths: [usize; 2],
    ) -> [V; 3] {
        let s = plane_stride;
        let last_plane = bandwidths.into_iter().max().unwrap_or(0).max(position + 2);
        assert!(c + self.radius * step + last_plane * s + LANES <= data.len());
        let targets = [
            V::load_slice(data, c + position * s),
            V::load_slice(data, c + (position + 1) * s),
            V::load_slice(data, c + (position + 2) * s),
        ];
        let [direct, indirect] = bandwidths;
        let both = [
            Some(Bandwidths {
                plane: direct,
                target: V::load_slice(data, c + direct * s),
            }),
            Some(Bandwidths {
                plane: indirect,
                target: V::load_slice(data, c + indirect * s),
            }),
        ];
        let pairs = Window {
            planes: data[c..].as_ptr(),
            plane_stride: s,
            tap_step: step,
            taps: self.radius + 1,
        };
        let limit = V::splat(EXP_CUTOFF);
        // SAFETY: the R + 1 groups' planes lie inside `data` (asserted).
        unsafe {
            tap_weights(
                &Contiguous,
                &pairs,
                position,
                targets,
                both,
                limit,
                self.forward_mut(j),
            )
        };
        // Pair (j, j + k) is also tap -k of group j + k. Rows follow each other in the
        // ring, so group j + k's row is found by stepping, not by a division per k.
        let (r, taps) = (self.radius, 2 * self.radius + 1);
        let (row_step, ring) = (2 * taps, (r + 1) * 2 * taps);
        for kind in 0..2 {
            let mut row = self.first(j, kind);
            let forward = row + r;
            for k in 1..=r {
                row += row_step;
                if row >= ring {
                    row -= ring;
                }
                self.weights[row + r - k] = self.weights[forward + k];
            }
        }
        targets
    }

    /// Group j's weights of `kind` for its taps i = -R..=R, tap -R first. Groups
    /// j - R..=j must have been weighed and no later one yet: weighing group j + 1
    /// starts reusing row j's place, for group j + R + 1.
    #[inline(always)]
    pub(super) fn taps(&self, j: isize, kind: usize) -> &[V] {
        let first = self.first(j, kind);
        &self.weights[first..first + 2 * self.radius + 1]
    }
}

/// The valid planes (valid_R, valid_RV) of both kinds at index `c` of the planes (plane
/// stride `s`), each kind given by its first value plane and its squared-bandwidth
/// plane; and the bandwidths of the kinds with a value somewhere in the group (`None`
/// for the others: they are not filtered). A loop, not closures: closures do not
/// inherit `#[target_feature]`.
#[inline(always)]
#[allow(clippy::type_complexity)]
pub(super) fn group_kinds<V: Lanes>(
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
