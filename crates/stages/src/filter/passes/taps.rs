//! How the Y pass reads a group's temporal taps (paper 001 eq. 26): the window over
//! the previous frame's X set around each lane's previous pixel, and the cheapest way
//! to read it for the lanes' offsets ([`TemporalTaps`]).

use super::super::gaussian::{
    EXP_CUTOFF, Gathered, PERMUTED_LINES, Permuted, ROUNDING_MAGIC, Straddling, Window,
};
use super::super::lane_planes::LanePlanes;
#[cfg(any(test, doc))]
use super::super::temporal::PreviousLanes;
use super::super::temporal::{SEARCH_RADIUS, find_previous_lanes, window_offset};
use super::sets::Previous;
use relume_base::simd::{LANES, Lanes};

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
    /// sums), each lane reads its own lane of one of two windows ([`Straddling`]), the
    /// lines from `first_line` on. With the kinds full in both windows.
    Rotated {
        straddling: Straddling<V>,
        limit: V,
        block: isize,
        rotation: usize,
        first_line: isize,
        full: u8,
    },
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
    /// The fetch for lanes whose float lies at lane `index` ([`Lanes::lane_indices`])
    /// of block b0, or b0 + 1 where `second` is set, on the first `count` of `lines`
    /// (increasing), lane masks `masks` (of the same lines) in `x_set`.
    #[inline(always)]
    fn new(
        (index, second): (V, V),
        lines: &[usize; PERMUTED_LINES],
        masks: [V; PERMUTED_LINES],
        count: usize,
        x_set: &LanePlanes,
    ) -> PermutedLanes<V> {
        let step = x_set.line_step() as isize;
        let mut most = Permuted {
            index,
            second,
            block_step: x_set.slot_step() as isize,
            lines: [(0, V::splat(0.0)); PERMUTED_LINES],
        };
        for k in 0..PERMUTED_LINES {
            let offset = (lines[k.min(count - 1)] as isize - lines[0] as isize) * step;
            most.lines[k] = (offset, masks[k]);
        }
        PermutedLanes { most, count }
    }

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
    let x_set = previous.x_set.planes();
    let zero = V::splat(0.0);
    // Lanes inside the image with a value of some layer.
    let lane_x = V::from_array(std::array::from_fn(|l| (x0 + l) as f32));
    let mut active = zero;
    // A loop, not a closure: closures do not inherit the kernel's target features.
    for v in valid.iter().flatten() {
        active = active.or(v.gt(zero));
    }
    let active = active.and(lane_x.lt(V::splat(x_set.width as f32)));
    let lanes = find_previous_lanes(position, active, previous.view, x_set);
    let has_previous = lanes.best.ge(zero);
    if !has_previous.any() {
        return TemporalTaps::None;
    }
    let limit = V::select(has_previous, V::splat(EXP_CUTOFF), V::splat(-1.0));
    // Scattered lanes' pixels, decoded once; a run's are read from its indices.
    let projected = match lanes.run {
        Some(run) => Projected::Run(run),
        None => Projected::Scattered(lanes.pixels()),
    };
    let common = common_offset(lanes.best, &projected, x0, y);
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
        let full = previous.x_set.full_windows().get(b, line);
        if r == 0 {
            let window = window_from(x_set.slot_index(b, line - radius as isize));
            return TemporalTaps::Contiguous(window, limit, full);
        }
        let full = full & previous.x_set.full_windows().get(b + 1, line);
        // Rotated lane s reads block b + 1 where s < r.
        let straddling = Straddling {
            second: x_set.slot_step() as isize,
            mask: V::from_mask(std::array::from_fn(|s| s < r)),
        };
        return TemporalTaps::Rotated {
            straddling,
            limit,
            block: b,
            rotation: r,
            first_line: line - radius as isize,
            full,
        };
    }
    let permuted = match &projected {
        Projected::Run(run) => permuted_run(lanes.best, *run, x_set),
        Projected::Scattered(found) => permuted_lanes(found, x_set),
    };
    if let Some((permuted, [b0, b1], lines)) = permuted {
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
    let found = match projected {
        Projected::Run(_) => lanes.pixels(),
        Projected::Scattered(found) => found,
    };
    let first_tap: [i32; LANES] = std::array::from_fn(|l| {
        let (x, y) = found[l].unwrap_or((x0 + l, y));
        x_set.pixel_index(x as isize, y as isize - radius as isize) as i32
    });
    TemporalTaps::Gathered(window_from(0), Gathered(first_tap), limit)
}

/// Where a group's lanes projected into the previous frame ([`PreviousLanes`]).
enum Projected {
    /// Onto the run of pixels (u0 + l, v0).
    Run((i32, i32)),
    /// Elsewhere: each lane's previous pixel.
    Scattered([Option<(usize, usize)>; LANES]),
}

/// The offset (x' - x, y' - y) from every lane's pixel (x0 + l, y) to its previous
/// pixel (x', y'), if all the lanes that have one share it; `best` are the lanes'
/// window indices ([`PreviousLanes::best`]).
#[inline(always)]
fn common_offset<V: Lanes>(
    best: V,
    projected: &Projected,
    x0: usize,
    y: usize,
) -> Option<(isize, isize)> {
    let found = match *projected {
        Projected::Run((u0, v0)) => {
            // Lane l's previous pixel is (u0 + l + dx, v0 + dy) for its window index:
            // the offset is common if the index is.
            let mut best = best.to_array().into_iter().filter(|&k| k >= 0.0);
            let k = best.next()?;
            if best.any(|other| other != k) {
                return None;
            }
            let (dx, dy) = window_offset(k as i32);
            return Some((
                (u0 + dx) as isize - x0 as isize,
                (v0 + dy) as isize - y as isize,
            ));
        }
        Projected::Scattered(ref found) => found,
    };
    let mut common = None;
    for (l, f) in found.iter().enumerate() {
        let Some((xp, yp)) = *f else { continue };
        let offset = (xp as isize - (x0 + l) as isize, yp as isize - y as isize);
        match common {
            None => common = Some(offset),
            Some(c) if c == offset => {}
            Some(_) => return None,
        }
    }
    common
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
    let index = V::lane_indices(std::array::from_fn(|l| {
        found[l].map_or(0, |(x, _)| (x % LANES) as u32)
    }));
    let second = V::from_mask(std::array::from_fn(|l| {
        found[l].is_some_and(|(x, _)| x / LANES > b0)
    }));
    let mut masks = [V::splat(0.0); PERMUTED_LINES];
    // A loop, not a closure: closures do not inherit the kernel's target features.
    for (k, mask) in masks.iter_mut().enumerate() {
        *mask = V::from_mask(std::array::from_fn(|l| lane_line[l] == k));
    }
    let permuted = PermutedLanes::new((index, second), &lines, masks, count, x_set);
    Some((permuted, [b0 as isize, b1 as isize], lines))
}

/// [`permuted_lanes`] for lanes that projected onto a run of pixels (`run`, see
/// [`PreviousLanes`]), from their window indices `best`: lane l's previous pixel is
/// (u0 + l + dx, v0 + dy), so its block, its lane in the block and its line come from
/// arithmetic on the indices, for all lanes at once. The same result as
/// [`permuted_lanes`] on the lanes' pixels, but for the lanes without a previous pixel,
/// which read some lane of the same blocks and lines. On replayed frames
/// `permuted_lanes` took some 60-100 more rdtsc ticks a group (of about 550 for
/// finding the pixels and choosing the read): its loops branch on each lane's block
/// and line.
#[inline(always)]
fn permuted_run<V: Lanes>(
    best: V,
    (u0, v0): (i32, i32),
    x_set: &LanePlanes,
) -> Option<(PermutedLanes<V>, [isize; 2], [usize; PERMUTED_LINES])> {
    // The window is 3 x 3: index k = 3 (dy + 1) + dx + 1.
    const _: () = assert!(SEARCH_RADIUS == 1);
    let s = V::splat;
    let found = best.ge(s(0.0));
    // Row dy + 1 = trunc((k + 0.5) / 3) and column dx + 1, exact for k in 0..9.
    let row = best.add(s(0.5)).mul(s(1.0 / 3.0)).trunc();
    let column = best.sub(row.mul(s(3.0)));
    // x' = u0 + l + dx: small integers, exact.
    let lane = V::from_array(std::array::from_fn(|l| l as f32));
    let x = s((u0 - 1) as f32).add(lane).add(column);
    // x' >= 0 where found: truncation is the floor.
    let block = x.mul(s(1.0 / LANES as f32)).trunc();
    let b0 = V::select(found, block, s(f32::INFINITY))
        .to_array()
        .into_iter()
        .fold(f32::INFINITY, f32::min);
    let b1 = V::select(found, block, s(f32::NEG_INFINITY))
        .to_array()
        .into_iter()
        .fold(f32::NEG_INFINITY, f32::max);
    if b1 > b0 + 1.0 {
        return None;
    }
    // The lines v0 + dy that some lane reads, in increasing order, and their lanes.
    let mut lines = [0usize; PERMUTED_LINES];
    let mut masks = [s(0.0); PERMUTED_LINES];
    let mut count = 0;
    for r in 0..3 {
        let on = found
            .and(row.ge(s(r as f32)))
            .and(row.lt(s(r as f32 + 1.0)));
        if on.any() {
            // A lane's line is inside the image.
            lines[count] = (v0 - 1 + r) as usize;
            masks[count] = on;
            count += 1;
        }
    }
    // x + 1.5 2^23 holds x in its low mantissa bits (two's complement where x is
    // negative, as it may be in a lane without a previous pixel): the low three,
    // x' mod 8, are the lane of x' in its block.
    let index = x.add(s(ROUNDING_MAGIC));
    let second = found.and(block.gt(s(b0)));
    let permuted = PermutedLanes::new((index, second), &lines, masks, count, x_set);
    Some((permuted, [b0 as isize, b1 as isize], lines))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::gaussian::Fetch;
    use crate::filter::lane_planes::LaneLayout;
    use relume_base::rng::hash;
    use relume_base::simd::Portable;

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

    /// For lanes that projected onto a run of pixels, [`permuted_run`] gives what
    /// [`permuted_lanes`] gives on their pixels: the same blocks and lines, and for the
    /// lanes with a previous pixel the same floats on every plane and tap (the first
    /// and last blocks and lines of the image included). Runs whose lanes span three
    /// blocks are left to the gathers by both.
    #[test]
    fn run_lanes_permute_as_their_pixels_do() {
        let (width, height, radius) = (64usize, 9usize, 2usize);
        let mut set = LanePlanes::new(LaneLayout::blocks(5, width, height, radius));
        for (i, v) in set.data_mut().iter_mut().enumerate() {
            *v = f32::from_bits(0x3f80_0000 | (hash(&[8, i as u64]) as u32 & 0x7f_ffff));
        }
        let (s, step) = (set.plane_stride(), set.line_step());
        let mut counts = [0usize; PERMUTED_LINES + 2];
        for case in 0..3000u64 {
            let h = |k: u64| hash(&[case, k]) as usize;
            let (u0, v0) = ((h(0) % (width - LANES + 1)) as i32, (h(1) % height) as i32);
            // Window indices whose pixels lie in the image; a fifth of the lanes none.
            let best: [f32; LANES] = std::array::from_fn(|l| {
                let (dx, dy) = window_offset((h(10 + l as u64) % 9) as i32);
                let (x, y) = (u0 + l as i32 + dx, v0 + dy);
                let inside = x >= 0 && y >= 0 && x < width as i32 && y < height as i32;
                if inside && h(20 + l as u64) % 5 != 0 {
                    ((dy + 1) * 3 + dx + 1) as f32
                } else {
                    -1.0
                }
            });
            let lanes = PreviousLanes {
                best: Portable::from_array(best),
                centre: (std::array::from_fn(|l| u0 + l as i32), [v0; LANES]),
                run: Some((u0, v0)),
            };
            let found = lanes.pixels();
            if found.iter().all(Option::is_none) {
                continue;
            }
            let expected = permuted_lanes::<Portable>(&found, &set);
            let got = permuted_run(lanes.best, (u0, v0), &set);
            let (Some(expected), Some(got)) = (expected, got) else {
                assert!(expected.is_none() && got.is_none(), "{found:?}");
                counts[PERMUTED_LINES + 1] += 1;
                continue;
            };
            let count = got.0.count();
            counts[count] += 1;
            assert_eq!(count, expected.0.count(), "{found:?}");
            assert_eq!((got.1, &got.2[..count]), (expected.1, &expected.2[..count]));
            let base = set.slot_index(got.1[0], got.2[0] as isize - radius as isize);
            for q in 0..5 {
                for i in 0..2 * radius + 1 {
                    // SAFETY: the windows lie inside the set (lines within `radius` of
                    // the image, blocks b0 and b0 + 1 <= slots).
                    let read = |permuted: &PermutedLanes<Portable>| unsafe {
                        let p = set.data().as_ptr().add(base + q * s + i * step);
                        match count {
                            1 => permuted.fetch::<1>().fetch(p),
                            2 => permuted.fetch::<2>().fetch(p),
                            _ => permuted.fetch::<3>().fetch(p),
                        }
                        .to_array()
                    };
                    let (a, b) = (read(&got.0), read(&expected.0));
                    for l in (0..LANES).filter(|&l| found[l].is_some()) {
                        assert_eq!(a[l].to_bits(), b[l].to_bits(), "{found:?}");
                    }
                }
            }
        }
        // Lines 1, 2, 3, and three blocks (rarer: u0 a block's first pixel, lane 0
        // back one pixel and lane 7 on one).
        assert!(
            counts[1..=PERMUTED_LINES].iter().all(|&c| c > 50),
            "{counts:?}"
        );
        assert!(counts[PERMUTED_LINES + 1] > 10, "{counts:?}");
    }
}
