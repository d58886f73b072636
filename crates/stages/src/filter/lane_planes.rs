//! Lane-interleaved planes: the layouts the filter's passes read their taps from.
//!
//! A set of planes holds `height` lines (image rows) of `width` pixels, plane by
//! plane, as vectors of [`LANES`] floats ("slots"). Two orders of pixels in a line
//! ([`Order`]):
//!
//! - **Segments** (the input planes, for the X pass). The line is cut into eight
//!   segments of S pixels (S = ceil(width / 8), rounded up to a multiple of 8), and lane
//!   l holds segment l: slot j is the vector of pixels (l S + j) for l = 0..8 (S = 80
//!   at 640 pixels wide). A group
//!   of eight targets at slot j finds its taps along the row, pixels (l S + j + i), as
//!   one vector at slot j + i: every tap load is aligned, never split across cache
//!   lines, and the symmetric Gaussian weight of a pair of slots serves both ends (see
//!   `passes`). Loading eight consecutive pixels per tap instead cost the X pass about
//!   30 %, most of it loads that cross a cache line. Each segment is extended by `halo`
//!   slots on both sides, holding its neighbours' pixels (lane l's slot -1 is pixel
//!   l S - 1, the last of segment l - 1) or zeros off the line, so that taps |i| <= halo
//!   of every slot stay inside the line.
//! - **Blocks** (the X set, for the Y pass): slot n is pixels 8 n..8 n + 8, stored
//!   block by block (each block plane by plane, each plane line by line), with one
//!   block of zeros on each side. A group of eight targets at block n of line y finds
//!   its taps along the column, pixels (8 n + l, y + i), as consecutive aligned vectors
//!   (so a walk down a block reads a window that slides by one vector), and their
//!   previous pixels (the temporal taps) in at most two neighbouring blocks where they
//!   all moved alike, as neighbouring pixels mostly do between frames. (Lanes S
//!   pixels apart, as in segments, mostly find theirs at different offsets, which cost
//!   gathers.) Blocks sets have `pad_lines` lines of zeros above and below, so that
//!   taps |i| <= pad_lines across lines stay inside.
//!
//! Zeros are harmless in the sums: their values and valid flags are 0.

use rayon::prelude::*;
use relume_base::simd::{LANES, Lanes};

/// Floats per cache line.
const LINE_FLOATS: usize = 16;

/// One cache line of floats, the unit of allocation: slots never straddle two lines.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
struct CacheLine([f32; LINE_FLOATS]);

/// How a line's pixels are ordered (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Order {
    /// Lane l of slot j is pixel l S + j.
    #[default]
    Segments,
    /// Lane l of slot n is pixel 8 n + l.
    Blocks,
}

/// The shape of a set of lane-interleaved planes (see the module docs) and its indexing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LaneLayout {
    /// Pixels per line.
    pub width: usize,
    /// Lines.
    pub height: usize,
    planes: usize,
    order: Order,
    /// Slots per line, halos left out: S for segments (a multiple of 8), the number of
    /// blocks for blocks. Both orders of one width have the same count.
    slots: usize,
    /// Extra slots on each side of a line (segments: of each segment).
    halo: usize,
    /// Lines of zeros above and below.
    pad_lines: usize,
    /// Floats from a plane to the next, at the same slot and line.
    plane_stride: usize,
}

/// Lines per plane of a blocks set: an odd number of cache lines (two lines each), so
/// that the same line of consecutive planes falls in different cache sets.
fn block_lines(height: usize, pad_lines: usize) -> usize {
    (height + 2 * pad_lines).next_multiple_of(4) + 2
}

impl LaneLayout {
    /// Segments order: `planes` planes of `height` lines of `width` pixels, with `halo`
    /// slots on each side of a segment.
    pub fn segments(planes: usize, width: usize, height: usize, halo: usize) -> LaneLayout {
        LaneLayout::new(planes, width, height, Order::Segments, halo, 0)
    }

    /// Blocks order: `planes` planes of `height` lines of `width` pixels, with
    /// `pad_lines` lines of zeros above and below.
    pub fn blocks(planes: usize, width: usize, height: usize, pad_lines: usize) -> LaneLayout {
        // Line 0 starts a cache line, so that tasks that write bands of an even number
        // of lines never share one.
        let pad_lines = pad_lines.next_multiple_of(2);
        LaneLayout {
            plane_stride: LANES * block_lines(height, pad_lines),
            ..LaneLayout::new(planes, width, height, Order::Blocks, 1, pad_lines)
        }
    }

    fn new(
        planes: usize,
        width: usize,
        height: usize,
        order: Order,
        halo: usize,
        pad_lines: usize,
    ) -> LaneLayout {
        let slots = width.div_ceil(LANES).next_multiple_of(LANES);
        // Whole blocks of eight slots (the fill transposes eight at a time), then two
        // more so that a plane line is an odd number of cache lines: the same slot of
        // consecutive planes falls in different cache sets.
        let line_slots = (slots + 2 * halo).next_multiple_of(LANES) + 2;
        LaneLayout {
            width,
            height,
            planes,
            order,
            slots,
            halo,
            pad_lines,
            plane_stride: LANES * line_slots,
        }
    }

    /// Planes in the set.
    pub fn planes(&self) -> usize {
        self.planes
    }

    /// The set's order.
    pub fn order(&self) -> Order {
        self.order
    }

    /// Slots per line (segments: per segment), halos left out.
    #[inline(always)]
    pub fn slots(&self) -> usize {
        self.slots
    }

    /// Slots on each side of a line or segment that hold neighbours or zeros.
    #[inline(always)]
    pub fn halo(&self) -> usize {
        self.halo
    }

    /// Whether the taps |i| <= `radius` of every slot of a segment stay in the line.
    pub fn fits_radius(&self, radius: usize) -> bool {
        self.halo >= radius
    }

    /// Whether the taps |i| <= `radius` across lines stay in the set.
    pub fn fits_lines(&self, radius: usize) -> bool {
        self.pad_lines >= radius
    }

    /// Floats from a plane to the next.
    #[inline(always)]
    pub fn plane_stride(&self) -> usize {
        self.plane_stride
    }

    /// Floats from a line to the next.
    #[inline(always)]
    pub fn line_step(&self) -> usize {
        match self.order {
            Order::Segments => self.planes * self.plane_stride,
            Order::Blocks => LANES,
        }
    }

    /// Floats from a slot to the next.
    #[inline(always)]
    pub fn slot_step(&self) -> usize {
        match self.order {
            Order::Segments => LANES,
            Order::Blocks => self.planes * self.plane_stride,
        }
    }

    /// Floats in the set.
    pub fn floats(&self) -> usize {
        match self.order {
            Order::Segments => (self.height + 2 * self.pad_lines) * self.line_step(),
            Order::Blocks => (self.slots + 2 * self.halo) * self.slot_step(),
        }
    }

    /// Index of plane 0, lane 0 of slot `j` of line `line` (-halo <= j < slots + halo,
    /// -pad_lines <= line < height + pad_lines).
    #[inline(always)]
    pub fn slot_index(&self, j: isize, line: isize) -> usize {
        debug_assert!(j >= -(self.halo as isize) && j < (self.slots + self.halo) as isize);
        debug_assert!(line >= -(self.pad_lines as isize));
        let line = (line + self.pad_lines as isize) as usize;
        (self.halo as isize + j) as usize * self.slot_step() + line * self.line_step()
    }

    /// Index of plane `q`, slot `j` within one line of a segments set (as
    /// [`LanePlanes::bands_mut`] gives them).
    #[inline(always)]
    pub fn in_line(&self, q: usize, j: isize) -> usize {
        debug_assert_eq!(self.order, Order::Segments);
        q * self.plane_stride + LANES * (self.halo as isize + j) as usize
    }

    /// Index of plane 0 at pixel `x` of line `line` (segments: 0 <= x < 8 S; blocks:
    /// -8 <= x < 8 slots + 8).
    #[inline(always)]
    pub fn pixel_index(&self, x: isize, line: isize) -> usize {
        let (j, lane) = match self.order {
            Order::Segments => (x % self.slots as isize, x / self.slots as isize),
            Order::Blocks => (x.div_euclid(LANES as isize), x.rem_euclid(LANES as isize)),
        };
        self.slot_index(j, line) + lane as usize
    }
}

/// A set of lane-interleaved planes, zeroed where never written.
#[derive(Clone, Debug, Default)]
pub struct LanePlanes {
    layout: LaneLayout,
    lines: Vec<CacheLine>,
}

impl std::ops::Deref for LanePlanes {
    type Target = LaneLayout;
    fn deref(&self) -> &LaneLayout {
        &self.layout
    }
}

impl LanePlanes {
    /// Zeroed planes of `layout` (as [`LaneLayout::segments`] or [`LaneLayout::blocks`]
    /// made it: the passes index it through raw pointers).
    pub fn new(layout: LaneLayout) -> LanePlanes {
        let made = match layout.order {
            Order::Segments => {
                LaneLayout::segments(layout.planes, layout.width, layout.height, layout.halo)
            }
            Order::Blocks => {
                LaneLayout::blocks(layout.planes, layout.width, layout.height, layout.pad_lines)
            }
        };
        assert_eq!(layout, made, "a lane layout changed after it was made");
        // Plane strides are whole cache lines.
        assert!(layout.plane_stride().is_multiple_of(LINE_FLOATS));
        LanePlanes {
            layout,
            lines: vec![CacheLine::default(); layout.floats() / LINE_FLOATS],
        }
    }

    /// The planes' shape.
    pub fn layout(&self) -> LaneLayout {
        self.layout
    }

    /// The planes' floats (64-byte aligned).
    #[inline(always)]
    pub fn data(&self) -> &[f32] {
        // SAFETY: a CacheLine is LINE_FLOATS f32 with no padding (repr C, size 64).
        unsafe {
            std::slice::from_raw_parts(self.lines.as_ptr().cast(), self.lines.len() * LINE_FLOATS)
        }
    }

    /// The planes' floats, mutable.
    #[inline(always)]
    pub fn data_mut(&mut self) -> &mut [f32] {
        // SAFETY: as for `data`.
        unsafe {
            std::slice::from_raw_parts_mut(
                self.lines.as_mut_ptr().cast(),
                self.lines.len() * LINE_FLOATS,
            )
        }
    }

    /// Plane `q` at pixel `x` of line `line`.
    pub fn at(&self, q: usize, x: usize, line: usize) -> f32 {
        assert!(q < self.planes && x < self.width && line < self.height);
        self.data()[self.pixel_index(x as isize, line as isize) + q * self.plane_stride()]
    }

    /// The lines 0..height of a segments set in bands of `lines` lines (the last may be
    /// shorter), for writing in parallel.
    pub fn bands_mut(&mut self, lines: usize) -> rayon::slice::ChunksMut<'_, f32> {
        assert_eq!(self.order, Order::Segments);
        let step = (lines * self.line_step()).max(1);
        let pad = self.pad_lines * self.line_step();
        let end = self.data().len() - pad;
        self.data_mut()[pad..end].par_chunks_mut(step)
    }
}

/// Fills one line of lane planes in segments order, `line` (a chunk of
/// [`LanePlanes::bands_mut`], or the whole of a one-line set), from the same planes in
/// row-major order: plane q's
/// pixel x at `row[first(q) + x]`. It reads x = -halo..8 S + halo + 7, which must be
/// zeros off 0..width (at least up to 8 S + halo: the halos and the lanes past the
/// width). Eight slots at a time: the eight
/// segments' runs of eight pixels, transposed.
#[inline(always)]
pub fn fill_line<V: Lanes>(
    layout: &LaneLayout,
    row: &[f32],
    first: impl Fn(usize) -> usize,
    line: &mut [f32],
) {
    assert_eq!(layout.order, Order::Segments);
    let (s, halo) = (layout.slots as isize, layout.halo as isize);
    let used = layout.plane_stride / LANES - 2;
    for q in 0..layout.planes {
        let start = first(q) as isize;
        for s0 in (0..used).step_by(LANES) {
            let j0 = s0 as isize - halo;
            let mut runs = [V::splat(0.0); LANES];
            for (l, run) in runs.iter_mut().enumerate() {
                let x = l as isize * s + j0;
                *run = V::load_slice(row, (start + x) as usize);
            }
            for (m, slot) in V::transpose(runs).into_iter().enumerate() {
                slot.store_slice(line, layout.in_line(q, j0 + m as isize));
            }
        }
    }
}
