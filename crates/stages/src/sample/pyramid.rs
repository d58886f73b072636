//! The min-max depth pyramid that the hierarchical screen-space tracer walks (paper 001
//! Sec. 5, after the hierarchical traversal of Tevs et al., TIS08): level 0 holds each
//! pixel's depth, every coarser texel the minimum and maximum valid depth of the 2x2
//! texels below it. A texel with no valid depth below it is empty: min = +inf,
//! max = -inf, so every "ray in front of the tile" test passes and the tile is skipped.
//!
//! Storage (one `f32` array, level after level, each with a border of empty texels):
//! level 0 keeps one value per pixel, its depth (+inf where invalid), which stands for
//! both its min and its max (half the bytes of a pair: the tracer's level-0 reads are
//! its cache misses); coarser levels keep (min, max) pairs side by side, so one cache
//! line serves both.

use rayon::prelude::*;
use relume_base::raster::{DepthImage, depth_is_valid};

/// The (min, max) valid depth of an empty texel.
pub const EMPTY_TEXEL: [f32; 2] = [f32::INFINITY, f32::NEG_INFINITY];

/// One level of the pyramid: `width` x `height` texels, stored with a border of one
/// empty texel on every side: texel (x, y) for x in -1..=width and y in -1..=height
/// has its min at `index(x, y)` of the pyramid's storage and its max `max_offset`
/// further.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PyramidLevel {
    pub width: u32,
    pub height: u32,
    /// Texels per stored row (width + 2).
    pub stride: usize,
    /// Storage index of texel (0, 0).
    pub origin: usize,
    /// Storage values per stored row: stride << shift.
    pub row: isize,
    /// Values per texel, as a shift: 0 at level 0 (one value), 1 above (a pair).
    pub shift: u32,
    /// Where a texel's max lies after its min: 0 at level 0, 1 above.
    pub max_offset: usize,
}

impl PyramidLevel {
    /// The storage index of texel (x, y)'s min, x in -1..=width, y in -1..=height.
    #[inline(always)]
    pub fn index(&self, x: i32, y: i32) -> usize {
        (self.origin as isize + y as isize * self.row + ((x as isize) << self.shift)) as usize
    }
}

/// Levels of 2x2 min and max of valid depth over one depth map, level 0 at full
/// resolution, the last level a single texel. Built once per frame in O(pixels).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DepthPyramid {
    levels: Vec<PyramidLevel>,
    /// Every level's texels with their borders (see the module docs).
    values: Vec<f32>,
}

/// Rows per parallel task when reducing a level (a level is cheap: keep tasks big).
const ROWS_PER_TASK: usize = 16;

impl DepthPyramid {
    /// The pyramid of `depth` (metres; 0 or non-finite = missing).
    pub fn new(depth: &DepthImage) -> DepthPyramid {
        let mut pyramid = DepthPyramid::default();
        pyramid.rebuild(depth);
        pyramid
    }

    /// Rebuilds the pyramid for `depth`, reusing the storage.
    pub fn rebuild(&mut self, depth: &DepthImage) {
        self.levels.clear();
        let (mut w, mut h) = (depth.width, depth.height);
        let mut total = 0usize;
        loop {
            let stride = w as usize + 2;
            let shift = (!self.levels.is_empty()) as u32;
            let row = stride << shift;
            self.levels.push(PyramidLevel {
                width: w,
                height: h,
                stride,
                origin: total + row + (1 << shift),
                row: row as isize,
                shift,
                max_offset: shift as usize,
            });
            total += row * (h as usize + 2);
            if w <= 1 && h <= 1 {
                break;
            }
            (w, h) = (w.div_ceil(2), h.div_ceil(2));
        }
        self.values.clear();
        self.values.resize(total, f32::INFINITY);
        // Coarse levels: empty pairs.
        if self.levels.len() > 1 {
            let start = self.levels[1].origin - self.levels[1].row as usize - 2;
            for pair in self.values[start..].chunks_exact_mut(2) {
                pair.copy_from_slice(&EMPTY_TEXEL);
            }
        }
        let (w, h) = (depth.width as usize, depth.height as usize);
        if w == 0 || h == 0 {
            return;
        }
        let l0 = self.levels[0];
        let rows = &mut self.values[l0.origin..l0.origin + (h - 1) * l0.stride + w];
        rows.par_chunks_mut(l0.stride)
            .zip(depth.data.par_chunks(w))
            .for_each(|(out, zs)| {
                for (t, &z) in out.iter_mut().zip(zs) {
                    *t = if depth_is_valid(z) { z } else { f32::INFINITY };
                }
            });
        for l in 1..self.levels.len() {
            let (fine, coarse) = (self.levels[l - 1], self.levels[l]);
            let (below, above) = self.values.split_at_mut(coarse.origin);
            let len =
                (coarse.height as usize - 1) * coarse.row as usize + 2 * coarse.width as usize;
            reduce_level(below, fine, &mut above[..len], coarse);
        }
    }

    /// Number of levels (level 0 is full resolution, the last one a single texel).
    pub fn level_count(&self) -> u32 {
        self.levels.len() as u32
    }

    /// The size and placement of level `level`.
    pub fn level(&self, level: u32) -> PyramidLevel {
        self.levels[level as usize]
    }

    /// [min, max] valid depth under texel (`x`, `y`) of level `level`
    /// ([`EMPTY_TEXEL`] when none is valid, and on the border: x or y = -1, width or
    /// height). Panics when out of range.
    #[inline]
    pub fn texel(&self, level: u32, x: i32, y: i32) -> [f32; 2] {
        let l = self.levels[level as usize];
        assert!((-1..=l.width as i32).contains(&x) && (-1..=l.height as i32).contains(&y));
        texel_at(&self.values, &l, x, y)
    }

    /// The texel (`x`, `y`) of `level` without a bounds check, for the tracer's inner
    /// loop; at level 0 an invalid pixel reads [+inf, +inf] (a tile the tracer skips,
    /// as it skips an empty one).
    ///
    /// # Safety
    /// `level` is one of [`DepthPyramid::levels`] and x in -1..=width, y in -1..=height
    /// of that level (checked in debug builds).
    #[inline(always)]
    pub(crate) unsafe fn texel_unchecked(&self, level: &PyramidLevel, x: i32, y: i32) -> [f32; 2] {
        debug_assert!(
            (-1..=level.width as i32).contains(&x) && (-1..=level.height as i32).contains(&y),
            "texel ({x}, {y}) outside {}x{} and its border",
            level.width,
            level.height
        );
        let i = level.index(x, y);
        // SAFETY: the caller keeps (x, y) within the level's border, whose texels are
        // all stored.
        unsafe {
            [
                *self.values.get_unchecked(i),
                *self.values.get_unchecked(i + level.max_offset),
            ]
        }
    }

    /// Every level's texels, at the levels' [`PyramidLevel::index`].
    pub(crate) fn values(&self) -> &[f32] {
        &self.values
    }

    /// The levels, finest first.
    pub(crate) fn levels(&self) -> &[PyramidLevel] {
        &self.levels
    }
}

/// [min, max] of texel (x, y) of level `l` in `values` (level 0's +inf is empty).
#[inline(always)]
fn texel_at(values: &[f32], l: &PyramidLevel, x: i32, y: i32) -> [f32; 2] {
    let i = l.index(x, y);
    let (min, max) = (values[i], values[i + l.max_offset]);
    if min == f32::INFINITY {
        EMPTY_TEXEL
    } else {
        [min, max]
    }
}

/// Fills the texels of level `coarse` (`above` starts at its texel (0, 0)) with the 2x2
/// min and max of level `fine` in `below`; children beyond the fine level's edge are
/// its empty border.
fn reduce_level(below: &[f32], fine: PyramidLevel, above: &mut [f32], coarse: PyramidLevel) {
    let cw = coarse.width as usize;
    let row = coarse.row as usize;
    above
        .par_chunks_mut(row * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(task, rows)| {
            for (r, out) in rows.chunks_mut(row).enumerate() {
                let y = ((task * ROWS_PER_TASK + r) * 2) as i32;
                let n = cw.min(out.len() / 2);
                for (x, t) in out[..2 * n].chunks_exact_mut(2).enumerate() {
                    let x = 2 * x as i32;
                    let [a, b, c, d] = [
                        texel_at(below, &fine, x, y),
                        texel_at(below, &fine, x + 1, y),
                        texel_at(below, &fine, x, y + 1),
                        texel_at(below, &fine, x + 1, y + 1),
                    ];
                    t[0] = a[0].min(b[0]).min(c[0].min(d[0]));
                    t[1] = a[1].max(b[1]).max(c[1].max(d[1]));
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::raster::Image;
    use relume_base::rng::Counter;

    /// Depth with holes (zeros and NaN) on an odd-sized image.
    fn holey_depth(w: u32, h: u32) -> DepthImage {
        let mut r = Counter::new(&[5, 1]);
        let data = (0..w * h)
            .map(|_| match r.next_f32() {
                u if u < 0.1 => 0.0,
                u if u < 0.15 => f32::NAN,
                _ => 0.5 + 4.0 * r.next_f32(),
            })
            .collect();
        Image::from_vec(w, h, data).unwrap()
    }

    #[test]
    fn every_texel_is_the_min_and_max_of_valid_depth_beneath_it() {
        let depth = holey_depth(37, 21);
        let pyramid = DepthPyramid::new(&depth);
        assert_eq!(
            pyramid.level_count(),
            7,
            "37 -> 19 -> 10 -> 5 -> 3 -> 2 -> 1"
        );
        for level in 0..pyramid.level_count() {
            let l = pyramid.level(level);
            for y in 0..l.height {
                for x in 0..l.width {
                    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                    for py in (y << level)..((y + 1) << level).min(depth.height) {
                        for px in (x << level)..((x + 1) << level).min(depth.width) {
                            let z = *depth.at(px, py);
                            if depth_is_valid(z) {
                                lo = lo.min(z);
                                hi = hi.max(z);
                            }
                        }
                    }
                    let t = pyramid.texel(level, x as i32, y as i32);
                    assert_eq!(t, [lo, hi], "level {level} ({x}, {y})");
                }
            }
        }
        let top = pyramid.level(pyramid.level_count() - 1);
        assert_eq!((top.width, top.height), (1, 1));
        for level in 0..pyramid.level_count() {
            let l = pyramid.level(level);
            let (w, h) = (l.width as i32, l.height as i32);
            for (x, y) in [(-1, 0), (w, 0), (0, -1), (0, h), (-1, -1), (w, h)] {
                assert_eq!(
                    pyramid.texel(level, x, y),
                    EMPTY_TEXEL,
                    "border of level {level}"
                );
            }
        }
    }

    #[test]
    fn empty_and_all_invalid_maps_build() {
        let empty = DepthPyramid::new(&Image::filled(0, 0, 0.0));
        assert_eq!(empty.level_count(), 1);
        let invalid = DepthPyramid::new(&Image::filled(5, 3, 0.0));
        assert_eq!(invalid.texel(invalid.level_count() - 1, 0, 0), EMPTY_TEXEL);
        let mut reused = invalid.clone();
        reused.rebuild(&holey_depth(37, 21));
        assert_eq!(reused, DepthPyramid::new(&holey_depth(37, 21)));
    }
}
