//! How the Y pass reads a group's temporal taps (paper 001 eq. 26): the window over
//! the previous frame's X set around each lane's previous pixel, and the cheapest way
//! to read it for the lanes' offsets ([`TemporalTaps`]).

use super::super::gaussian::{EXP_CUTOFF, Gathered, PERMUTED_LINES, Permuted, Straddling, Window};
use super::super::lane_planes::LanePlanes;
use super::super::temporal::find_previous_lanes;
use super::Previous;
use crate::simd::{LANES, Lanes};

/// How the temporal taps of a group are read.
pub(super) enum TemporalTaps<V> {
    /// No lane has a previous pixel.
    None,
    /// Every lane's previous pixel at the same offset from its target, a multiple of
    /// 8: one window of aligned vectors, lane for lane. With the window's full kinds
    /// (bits as in [`super::FullWindows`]).
    Contiguous(Window, V, u8),
    /// Every lane's previous pixel at the same offset, 8 b + r from the block's start
    /// with 0 < r < 8: target lane l's source is lane (l + r) mod 8 of block b (l + r
    /// < 8) or b + 1. With the targets rotated up by r (positions, bandwidths, limits,
    /// sums), each lane reads its own lane of one of two windows ([`Straddling`]).
    /// With the kinds full in both windows.
    Rotated(Window, Straddling<V>, V, usize, u8),
    /// Different offsets, the previous pixels within two consecutive blocks and on at
    /// most [`PERMUTED_LINES`] lines: per line, two loads permuted ([`Permuted`]).
    /// With the kinds full in every window the lanes read (block b0, and b0 + 1 where
    /// a lane reads it; every line).
    Permuted(Window, PermutedLanes<V>, V, u8),
    /// Other offsets: gathered lane by lane.
    Gathered(Window, Gathered, V),
}

/// A [`Permuted`] fetch with its number of lines chosen at run time: the fetch sized
/// for the most lines, of which the first `count` are used.
#[derive(Clone, Copy)]
pub(super) struct PermutedLanes<V> {
    most: Permuted<V, PERMUTED_LINES>,
    count: usize,
}

impl<V: Lanes> PermutedLanes<V> {
    /// The fetch for `K` lines (`K` must be the count).
    #[inline(always)]
    pub(super) fn fetch<const K: usize>(&self) -> Permuted<V, K> {
        assert_eq!(K, self.count);
        let mut lines = [(0, V::splat(0.0)); K];
        lines.copy_from_slice(&self.most.lines[..K]);
        let Permuted {
            index,
            second,
            block_step,
            ..
        } = self.most;
        Permuted {
            index,
            second,
            block_step,
            lines,
        }
    }

    /// Lines read per tap.
    pub(super) fn count(&self) -> usize {
        self.count
    }
}

/// The temporal taps (eq. 26) of pixels (x0 + l, y): the window over the previous
/// frame's X set around each lane's previous pixel (x', y') ([`find_previous_lanes`]),
/// along its column (lines y' - R..=y' + R), and how to read it.
#[inline(always)]
pub(super) fn temporal_taps<V: Lanes>(
    previous: Previous,
    position: [V; 3],
    valid: &[[V; 2]; 2],
    x0: usize,
    y: usize,
    radius: usize,
) -> TemporalTaps<V> {
    let valid = [
        valid[0][0].to_array(),
        valid[0][1].to_array(),
        valid[1][0].to_array(),
        valid[1][1].to_array(),
    ];
    let x_set = previous.x_set.planes();
    let active: [bool; LANES] =
        std::array::from_fn(|l| x0 + l < x_set.width && valid.iter().any(|a| a[l] > 0.0));
    let found = find_previous_lanes(position, active, previous.view, x_set);
    if found.iter().all(Option::is_none) {
        return TemporalTaps::None;
    }
    // The lanes' common offset (dx, dy), if they have one.
    let mut common = None;
    for (l, f) in found.iter().enumerate() {
        let Some((xp, yp)) = *f else { continue };
        let offset = (xp as isize - (x0 + l) as isize, yp as isize - y as isize);
        match common {
            None => common = Some(offset),
            Some(c) if c == offset => {}
            Some(_) => {
                common = None;
                break;
            }
        }
    }
    let limit = V::from_array(found.map(|f| if f.is_some() { EXP_CUTOFF } else { -1.0 }));
    // The window of 2 R + 1 taps down the X set from index `first` of plane 0 (for
    // gathered taps, the planes' start).
    let window_from = |first: usize| Window {
        planes: x_set.data()[first..].as_ptr(),
        plane_stride: x_set.plane_stride(),
        tap_step: x_set.line_step(),
        taps: 2 * radius + 1,
    };
    if let Some((dx, dy)) = common {
        // Pixels x0 + dx.. of lines y + dy - R..=y + dy + R: x0 + dx >= -7 (some lane's
        // x0 + l + dx is a pixel), so blocks -1..=slots, inside the set with its block
        // of zeros on each side; y + dy inside the image, so the lines are inside the
        // set (`fits_lines`). Lanes without a previous pixel read the same windows, with
        // no weight.
        let x = x0 as isize + dx;
        let (b, r) = (
            x.div_euclid(LANES as isize),
            x.rem_euclid(LANES as isize) as usize,
        );
        let line = y as isize + dy;
        let window = window_from(x_set.slot_index(b, line - radius as isize));
        let full = previous.x_set.full_windows().get(b, line);
        if r == 0 {
            return TemporalTaps::Contiguous(window, limit, full);
        }
        let full = full & previous.x_set.full_windows().get(b + 1, line);
        // Rotated lane s reads block b + 1 where s < r.
        let straddling = Straddling {
            second: x_set.slot_step() as isize,
            mask: V::from_mask(std::array::from_fn(|s| s < r)),
        };
        return TemporalTaps::Rotated(window, straddling, limit, r, full);
    }
    if let Some((permuted, [b0, b1], lines)) = permuted_lanes::<V>(&found, x_set) {
        // Lines y'_0 - R.. of block b_0, each lane's line and block an offset from there:
        // blocks b_0 and b_0 + 1 <= slots, inside the set with its block of zeros on
        // each side; every y'_k inside the image, so lines y'_k - R..=y'_k + R are
        // inside the set (`fits_lines`).
        let window = window_from(x_set.slot_index(b0, lines[0] as isize - radius as isize));
        let mut full = 0b11;
        for &line in &lines[..permuted.count()] {
            for b in b0..=b1 {
                full &= previous.x_set.full_windows().get(b, line as isize);
            }
        }
        return TemporalTaps::Permuted(window, permuted, limit, full);
    }
    // Gather, each lane from its previous pixel's window (a lane without one from its
    // own pixel's, with no weight).
    let first_tap: [i32; LANES] = std::array::from_fn(|l| {
        let (x, y) = found[l].unwrap_or((x0 + l, y));
        x_set.pixel_index(x as isize, y as isize - radius as isize) as i32
    });
    TemporalTaps::Gathered(window_from(0), Gathered(first_tap), limit)
}

/// [`PermutedLanes`] for lanes whose previous pixels (`found`) lie in two consecutive
/// blocks and on at most [`PERMUTED_LINES`] lines, with the first and last block and
/// the lines (in increasing order, the first `count`); `None` otherwise. Lanes without
/// a previous pixel read lane 0 of the first line of the first block (with no weight).
#[inline(always)]
fn permuted_lanes<V: Lanes>(
    found: &[Option<(usize, usize)>; LANES],
    x_set: &LanePlanes,
) -> Option<(PermutedLanes<V>, [isize; 2], [usize; PERMUTED_LINES])> {
    let blocks = found.iter().flatten().map(|&(x, _)| x / LANES);
    let (b0, b1) = (blocks.clone().min()?, blocks.max()?);
    if b1 > b0 + 1 {
        return None;
    }
    let mut lines = [0usize; PERMUTED_LINES];
    let mut count = 0;
    for &(_, y) in found.iter().flatten() {
        if !lines[..count].contains(&y) {
            if count == PERMUTED_LINES {
                return None;
            }
            lines[count] = y;
            count += 1;
        }
    }
    lines[..count].sort_unstable();
    let lane_line: [usize; LANES] = std::array::from_fn(|l| {
        found[l].map_or(0, |(_, y)| {
            lines[..count]
                .iter()
                .position(|&line| line == y)
                .unwrap_or(0)
        })
    });
    let step = x_set.line_step() as isize;
    let mut most = Permuted {
        index: V::lane_indices(std::array::from_fn(|l| {
            found[l].map_or(0, |(x, _)| (x % LANES) as u32)
        })),
        second: V::from_mask(std::array::from_fn(|l| {
            found[l].is_some_and(|(x, _)| x / LANES > b0)
        })),
        block_step: x_set.slot_step() as isize,
        lines: [(0, V::splat(0.0)); PERMUTED_LINES],
    };
    // A loop, not a closure: closures do not inherit the kernel's target features.
    for k in 0..PERMUTED_LINES {
        let offset = (lines[k.min(count - 1)] as isize - lines[0] as isize) * step;
        most.lines[k] = (
            offset,
            V::from_mask(std::array::from_fn(|l| lane_line[l] == k)),
        );
    }
    let permuted = PermutedLanes { most, count };
    Some((permuted, [b0 as isize, b1 as isize], lines))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::hash;
    use crate::simd::Portable;
    use crate::stages::filter::gaussian::Fetch;
    use crate::stages::filter::lane_planes::LaneLayout;

    /// The permuted reads give, lane for lane and bit for bit, the floats the gathers
    /// read, on every plane and tap, for lanes whose previous pixels lie in two
    /// neighbouring blocks on one to three lines (the image's first and last blocks and
    /// lines included); other lanes get no previous pixel.
    #[test]
    fn permuted_reads_give_the_gathered_floats() {
        let (width, height, radius) = (64usize, 9usize, 2usize);
        let mut set = LanePlanes::new(LaneLayout::blocks(5, width, height, radius));
        for (i, v) in set.data_mut().iter_mut().enumerate() {
            *v = f32::from_bits(0x3f80_0000 | (hash(&[7, i as u64]) as u32 & 0x7f_ffff));
        }
        let (data, s, step) = (set.data(), set.plane_stride(), set.line_step());
        let taps = 2 * radius + 1;
        let mut counts = [0usize; PERMUTED_LINES + 1];
        for case in 0..3000u64 {
            let h = |k: u64| hash(&[case, k]) as usize;
            let b = h(0) % (width / LANES);
            let lines: Vec<usize> = (1..=3).map(|k| h(k) % height).collect();
            let found: [Option<(usize, usize)>; LANES] = std::array::from_fn(|l| {
                let x = (b * LANES + h(10 + l as u64) % (2 * LANES)).min(width - 1);
                (h(20 + l as u64) % 5 != 0).then(|| (x, lines[h(30 + l as u64) % 3]))
            });
            let Some((permuted, [b0, b1], lines)) = permuted_lanes::<Portable>(&found, &set) else {
                assert!(found.iter().all(Option::is_none), "{found:?}");
                continue;
            };
            counts[permuted.count()] += 1;
            // The blocks and lines read, which say where the windows must be full.
            let blocks = found.iter().flatten().map(|&(x, _)| (x / LANES) as isize);
            assert_eq!(
                [b0, b1],
                [blocks.clone().min().unwrap(), blocks.max().unwrap()]
            );
            let mut expected_lines: Vec<usize> = found.iter().flatten().map(|&(_, y)| y).collect();
            expected_lines.sort_unstable();
            expected_lines.dedup();
            assert_eq!(lines[..permuted.count()], expected_lines[..], "{found:?}");
            let base = set.slot_index(b0, lines[0] as isize - radius as isize);
            let offsets: [i32; LANES] = std::array::from_fn(|l| {
                let (x, y) = found[l].unwrap_or((0, radius));
                set.pixel_index(x as isize, y as isize - radius as isize) as i32
            });
            for q in 0..5 {
                for i in 0..taps {
                    let at = q * s + i * step;
                    // SAFETY: the windows lie inside the set (lines within `radius` of
                    // the image, blocks b0 and b0 + 1 <= slots).
                    let (got, expected) = unsafe {
                        let p = data.as_ptr().add(base + at);
                        let got = match permuted.count() {
                            1 => permuted.fetch::<1>().fetch(p),
                            2 => permuted.fetch::<2>().fetch(p),
                            _ => permuted.fetch::<3>().fetch(p),
                        };
                        let gathered: Portable = Gathered(offsets).fetch(data.as_ptr().add(at));
                        (got, gathered)
                    };
                    let (got, expected) = (got.to_array(), expected.to_array());
                    for l in (0..LANES).filter(|&l| found[l].is_some()) {
                        assert_eq!(got[l].to_bits(), expected[l].to_bits(), "{found:?}");
                    }
                }
            }
        }
        assert!(counts[1..].iter().all(|&c| c > 100), "{counts:?}");
    }
}
