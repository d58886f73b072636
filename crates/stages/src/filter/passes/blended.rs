//! The rotated temporal taps' lines, blended once and kept while the Y pass walks a
//! block down the image ([`BlendedLines`]).

use super::super::gaussian::{Fetch, Straddling, Window};
use super::super::lane_planes::LanePlanes;
use super::super::layout::X_PLANES;
use relume_base::simd::{LANES, Lanes};

/// The lines of the previous X set that a rotated read ([`super::taps::TemporalTaps`])
/// takes, each line's two blocks b and b + 1 blended into one vector per plane as
/// [`Straddling`] fetches them, in a ring of 2 R + 1 lines.
///
/// A rotated group's previous pixels are (x0 + l + dx, y + dy) for one offset: its
/// window is lines y + dy - R..=y + dy + R of blocks b and b + 1 with a rotation r. The
/// next group down the block mostly has the same offset (88 % of rotated groups on
/// replayed frames), so its window is the same blocks one line down. The ring keeps
/// the blended lines: such a group blends its one new line and reads all 2 R + 1 as
/// contiguous vectors, where the straddling fetch loads two vectors and blends them for
/// every plane of every tap. The floats read are the same.
pub(super) struct BlendedLines<V> {
    /// Per slot (line t at slot t mod 2 R + 1), [`X_PLANES`] vectors.
    lines: Vec<V>,
    /// The blocks, rotation and first line of the 2 R + 1 lines the ring holds.
    held: Option<Held>,
}

#[derive(Clone, Copy, PartialEq, Debug)]
struct Held {
    block: isize,
    rotation: usize,
    first: isize,
}

impl<V: Lanes> BlendedLines<V> {
    /// An empty ring for windows of 2 `radius` + 1 lines.
    pub(super) fn new(radius: usize) -> BlendedLines<V> {
        // The windows read the vectors as floats.
        assert_eq!(size_of::<V>(), LANES * size_of::<f32>());
        BlendedLines {
            lines: vec![V::splat(0.0); (2 * radius + 1) * X_PLANES],
            held: None,
        }
    }

    /// Lines in the ring: the window's taps.
    fn slots(&self) -> usize {
        self.lines.len() / X_PLANES
    }

    /// The window of lines `first..first + 2 R + 1` of blocks `block` and `block + 1` of
    /// `x_set` blended by `straddling` (whose mask is that of rotation `rotation`), as
    /// one or two windows over the ring (two where it wraps; the second may have no
    /// taps), taps in line order. Blends the lines the ring does not hold yet.
    ///
    /// # Safety
    /// Those lines of both blocks must lie inside `x_set`, and the ring must not be
    /// written while the windows are read.
    #[inline(always)]
    pub(super) unsafe fn windows(
        &mut self,
        x_set: &LanePlanes,
        straddling: &Straddling<V>,
        (block, rotation): (isize, usize),
        first: isize,
    ) -> [Window; 2] {
        let slots = self.slots();
        let wanted = first..first + slots as isize;
        // The lines already blended, if the ring holds these blocks and rotation.
        let kept = match self.held {
            Some(held) if held.block == block && held.rotation == rotation => {
                held.first.max(first)..held.first.min(first) + slots as isize
            }
            _ => 0..0,
        };
        let (data, plane_stride) = (x_set.data().as_ptr(), x_set.plane_stride());
        for line in wanted.filter(|line| !kept.contains(line)) {
            let slot = line.rem_euclid(slots as isize) as usize;
            let source = x_set.slot_index(block, line);
            for q in 0..X_PLANES {
                // SAFETY: the line of both blocks lies inside the set (the caller).
                let blended = unsafe { straddling.fetch(data.add(source + q * plane_stride)) };
                self.lines[slot * X_PLANES + q] = blended;
            }
        }
        self.held = Some(Held {
            block,
            rotation,
            first,
        });
        let start = first.rem_euclid(slots as isize) as usize;
        let ring = self.lines.as_ptr().cast::<f32>();
        let window = |slot: usize, taps: usize| Window {
            planes: ring.wrapping_add(slot * X_PLANES * LANES),
            plane_stride: LANES,
            tap_step: X_PLANES * LANES,
            taps,
        };
        [window(start, slots - start), window(0, start)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::gaussian::Contiguous;
    use crate::filter::lane_planes::LaneLayout;
    use relume_base::rng::hash;
    use relume_base::simd::Portable;

    /// Through a walk of windows that mostly step one line down, but also stay, step
    /// up, jump, and change blocks or rotation, the ring's windows read, tap for tap and
    /// plane for plane, the floats the straddling fetch reads from the set.
    #[test]
    fn the_ring_reads_what_the_straddling_fetch_reads() {
        let (width, height, radius) = (40usize, 23usize, 3usize);
        let mut set = LanePlanes::new(LaneLayout::blocks(X_PLANES, width, height, radius));
        for (i, v) in set.data_mut().iter_mut().enumerate() {
            *v = f32::from_bits(0x3f80_0000 | (hash(&[9, i as u64]) as u32 & 0x7f_ffff));
        }
        let taps = 2 * radius + 1;
        let (s, step) = (set.plane_stride(), set.line_step());
        let mut ring = BlendedLines::<Portable>::new(radius);
        let (mut block, mut rotation, mut line) = (0isize, 3usize, 0isize);
        let mut wrapped = 0;
        for case in 0..400u64 {
            let h = |k: u64| hash(&[case, k]) as usize;
            match h(0) % 10 {
                0 => line -= 1,
                1 => {}
                2 => line = (h(1) % height) as isize,
                3 => block = (h(2) % width.div_ceil(LANES)) as isize,
                4 => rotation = 1 + h(3) % (LANES - 1),
                _ => line += 1,
            }
            line = line.clamp(0, height as isize - 1);
            let straddling = Straddling {
                second: set.slot_step() as isize,
                mask: Portable::from_mask(std::array::from_fn(|l| l < rotation)),
            };
            let first = line - radius as isize;
            // SAFETY: lines within `radius` of the image, blocks up to the last + 1.
            let windows = unsafe { ring.windows(&set, &straddling, (block, rotation), first) };
            assert_eq!(windows[0].taps + windows[1].taps, taps);
            wrapped += (windows[1].taps > 0) as usize;
            let base = set.slot_index(block, first);
            let mut tap = 0;
            for window in windows {
                for i in 0..window.taps {
                    for q in 0..X_PLANES {
                        // SAFETY: inside the ring and the set.
                        let (got, expected): (Portable, Portable) = unsafe {
                            let at = i * window.tap_step + q * window.plane_stride;
                            let p = set.data().as_ptr().add(base + (tap + i) * step + q * s);
                            (Contiguous.fetch(window.planes.add(at)), straddling.fetch(p))
                        };
                        let bits = |v: Portable| v.to_array().map(f32::to_bits);
                        assert_eq!(bits(got), bits(expected), "case {case}, tap {}", tap + i);
                    }
                }
                tap += window.taps;
            }
        }
        assert!(wrapped > 100, "{wrapped}");
    }
}
