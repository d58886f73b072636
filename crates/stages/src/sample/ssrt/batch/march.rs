//! The AVX2 march of a [`super::TraceBatch`]: eight rays per vector, one per lane.

use super::queue::{LevelTables, Queued};
use crate::sample::ssrt::{FRACTION_BITS, ScreenTracer};
use relume_base::simd::LANES;
use std::arch::x86_64::*;

/// Groups of eight lanes marched in turn. Each step of a ray waits on its texel
/// loads (often cache misses); the groups' steps are independent, so the CPU
/// overlaps them.
const PACKETS: usize = 2;
/// Idle lanes (of `PACKETS * LANES`) that trigger a refill from the queue: each
/// refill costs about as much as a step, so it waits for a few.
const REFILL_AT: usize = 4;

/// Eight lanes: each one ray's constants and march state, in memory between steps,
/// and the result of the ray that ended there last.
#[derive(Clone, Copy, Default)]
#[repr(C, align(32))]
struct Packet {
    a: [i32; LANES],
    level: [i32; LANES],
    minor_c: [i32; LANES],
    minor_slope: [i32; LANES],
    inv_c: [f32; LANES],
    dinv: [f32; LANES],
    last: [i32; LANES],
    step: [i32; LANES],
    /// -1 where the ray marches forward (increasing major coordinate), else 0.
    forward: [i32; LANES],
    /// -1 where the major axis is y, else 0.
    transposed: [i32; LANES],
    /// -1 where the lane's ray is still marching, else 0.
    active: [i32; LANES],
    /// Where the lane's ray ended: -1 for a hit at sample `found_a` with 1/z
    /// `found_inv`, else 0.
    found: [i32; LANES],
    found_a: [i32; LANES],
    found_inv: [f32; LANES],
    /// The lane's queued ray, `usize::MAX` for none.
    slot: [usize; LANES],
    /// A bit per lane whose ray is still marching: `active` as a bit mask, set with
    /// it by `refill` and cleared with it by `step`.
    live: u32,
}

/// The bits of every lane in [`Packet::live`].
const ALL_LANES: u32 = (1 << LANES) - 1;

impl Packet {
    fn new() -> Packet {
        Packet {
            slot: [usize::MAX; LANES],
            ..Packet::default()
        }
    }

    /// Puts queued ray `slot` into idle `lane`, at its first sample and level 0.
    fn fill(&mut self, lane: usize, q: &Queued, slot: usize) {
        let m = &q.march;
        self.a[lane] = m.first;
        self.level[lane] = 0;
        self.minor_c[lane] = m.minor_c;
        self.minor_slope[lane] = m.minor_slope;
        self.inv_c[lane] = m.inv_c;
        self.dinv[lane] = m.dinv;
        self.last[lane] = m.last;
        self.step[lane] = m.step;
        self.forward[lane] = -((m.step > 0) as i32);
        self.transposed[lane] = -(m.transposed as i32);
        self.active[lane] = -1;
        self.slot[lane] = slot;
    }

    /// Hands the results of the lanes whose rays ended to `found`, and fills idle
    /// lanes from `queued` (starting at `*next`); returns the lanes now marching.
    /// Only the idle lanes are visited (a bit per lane in `live`): which lanes ended is
    /// unpredictable, so a branch per lane would mostly be mispredicted.
    fn refill(
        &mut self,
        queued: &[Queued],
        next: &mut usize,
        found: &mut [Option<(i32, f32)>],
    ) -> usize {
        let mut idle = !self.live & ALL_LANES;
        while idle != 0 {
            let lane = idle.trailing_zeros() as usize;
            idle &= idle - 1;
            let slot = self.slot[lane];
            if slot != usize::MAX {
                found[slot] =
                    (self.found[lane] != 0).then_some((self.found_a[lane], self.found_inv[lane]));
                self.slot[lane] = usize::MAX;
            }
            if *next < queued.len() {
                self.fill(lane, &queued[*next], *next);
                self.live |= 1 << lane;
                *next += 1;
            }
        }
        self.live.count_ones() as usize
    }
}

#[inline(always)]
unsafe fn load(v: &[i32; LANES]) -> __m256i {
    unsafe { _mm256_loadu_si256(v.as_ptr() as *const __m256i) }
}

#[inline(always)]
unsafe fn store(v: &mut [i32; LANES], x: __m256i) {
    unsafe { _mm256_storeu_si256(v.as_mut_ptr() as *mut __m256i, x) }
}

/// The pairs `(values[i], values[i + 1])` of the lanes in `active` (0 elsewhere), as
/// two vectors in the lanes' order: two 64-bit gathers of four lanes each load half
/// the elements of the two 32-bit gathers they replace, and on AMD's Zen 4 a gather
/// costs about its element count. (Functions, not closures: closures do not inherit
/// the caller's target features.)
#[inline(always)]
unsafe fn gather_pairs(values: *const f32, i: __m256i, active: __m256i) -> (__m256, __m256) {
    unsafe {
        let (i_low, i_high) = (_mm256_castsi256_si128(i), _mm256_extracti128_si256::<1>(i));
        let (active_low, active_high) = (
            _mm256_castsi256_si128(active),
            _mm256_extracti128_si256::<1>(active),
        );
        let low = gather_four_pairs(values, i_low, active_low);
        let high = gather_four_pairs(values, i_high, active_high);
        // [v0 w0 v1 w1 v2 w2 v3 w3] and [v4 w4 .. v7 w7]: the first of each pair in
        // lanes 0 1 4 5 | 2 3 6 7, then back in order.
        let first = _mm256_shuffle_ps::<0b10_00_10_00>(low, high);
        let second = _mm256_shuffle_ps::<0b11_01_11_01>(low, high);
        (in_lane_order(first), in_lane_order(second))
    }
}

/// The pairs at four float indices `i` (as 64-bit elements) of the lanes in `active`
/// (0 elsewhere).
#[inline(always)]
unsafe fn gather_four_pairs(values: *const f32, i: __m128i, active: __m128i) -> __m256 {
    unsafe {
        let mask = _mm256_castsi256_pd(_mm256_cvtepi32_epi64(active));
        _mm256_castpd_ps(_mm256_mask_i32gather_pd::<4>(
            _mm256_setzero_pd(),
            values as *const f64,
            i,
            mask,
        ))
    }
}

/// `v` holding the values of lanes 0 1 4 5 2 3 6 7, in that order, put back in lane
/// order (its 64-bit halves 0, 2, 1, 3).
#[inline(always)]
unsafe fn in_lane_order(v: __m256) -> __m256 {
    unsafe { _mm256_castpd_ps(_mm256_permute4x64_pd::<0b11_01_10_00>(_mm256_castps_pd(v))) }
}

/// The entries of a 16-entry table (two halves) at per-lane indices 0..16.
#[inline(always)]
unsafe fn lookup(low: __m256i, high: __m256i, index: __m256i) -> __m256i {
    unsafe {
        let upper = _mm256_cmpgt_epi32(index, _mm256_set1_epi32(7));
        _mm256_blendv_epi8(
            _mm256_permutevar8x32_epi32(low, index),
            _mm256_permutevar8x32_epi32(high, index),
            upper,
        )
    }
}

/// The pixel index of the sample at major coordinate `a`, floor(minor + 0.5)
/// (`March::minor_index`).
#[inline(always)]
unsafe fn minor_index(minor_c: __m256i, slope: __m256i, a: __m256i) -> __m256i {
    unsafe {
        let fixed = _mm256_add_epi32(minor_c, _mm256_mullo_epi32(a, slope));
        _mm256_sub_epi32(
            _mm256_srai_epi32::<{ FRACTION_BITS as i32 }>(fixed),
            _mm256_set1_epi32(1),
        )
    }
}

/// Trailing zero bits of each lane (32 for 0), as `u32::trailing_zeros`.
#[inline(always)]
unsafe fn trailing_zeros(v: __m256i) -> __m256i {
    unsafe {
        let lowest = _mm256_and_si256(v, _mm256_sub_epi32(_mm256_setzero_si256(), v));
        // A power of two converts exactly; its exponent field is the bit's index
        // (2^31, i32::MIN, converts to -2^31: the sign bit is masked off).
        let bits = _mm256_castps_si256(_mm256_cvtepi32_ps(lowest));
        let exponent = _mm256_sub_epi32(
            _mm256_and_si256(_mm256_srli_epi32::<23>(bits), _mm256_set1_epi32(0xff)),
            _mm256_set1_epi32(127),
        );
        let zero = _mm256_cmpeq_epi32(v, _mm256_setzero_si256());
        _mm256_blendv_epi8(exponent, _mm256_set1_epi32(32), zero)
    }
}

/// What a step needs besides the packet: the pyramid and its level tables.
struct Pyramid {
    values: *const f32,
    origin_low: __m256i,
    origin_high: __m256i,
    row_low: __m256i,
    row_high: __m256i,
    top: __m256i,
    thickness: __m256,
}

/// One step of [`ScreenTracer::march`] in every marching lane of `p`; a lane whose
/// ray ends records its result and falls idle. Returns the number of lanes that
/// ended.
#[inline(always)]
unsafe fn step(p: &mut Packet, pyramid: &Pyramid) -> u32 {
    unsafe {
        let active = load(&p.active);
        if _mm256_testz_si256(active, active) != 0 {
            return 0;
        }
        let one = _mm256_set1_epi32(1);
        let (a, level) = (load(&p.a), load(&p.level));
        let (minor_c, slope) = (load(&p.minor_c), load(&p.minor_slope));
        let inv_c = _mm256_loadu_ps(p.inv_c.as_ptr());
        let dinv = _mm256_loadu_ps(p.dinv.as_ptr());
        let (last, forward, transposed) = (load(&p.last), load(&p.forward), load(&p.transposed));
        let inv_a = _mm256_add_ps(inv_c, _mm256_mul_ps(_mm256_cvtepi32_ps(a), dinv));
        let ta = _mm256_srav_epi32(a, level);
        let tb = _mm256_srav_epi32(minor_index(minor_c, slope, a), level);
        // The last sample of the march inside this tile.
        let ae = _mm256_blendv_epi8(
            _mm256_max_epi32(_mm256_sllv_epi32(ta, level), last),
            _mm256_min_epi32(
                _mm256_sub_epi32(_mm256_sllv_epi32(_mm256_add_epi32(ta, one), level), one),
                last,
            ),
            forward,
        );
        let tb_end = _mm256_srav_epi32(minor_index(minor_c, slope, ae), level);
        let inv_e = _mm256_add_ps(inv_c, _mm256_mul_ps(_mm256_cvtepi32_ps(ae), dinv));
        let (x0, y0) = (
            _mm256_blendv_epi8(ta, tb, transposed),
            _mm256_blendv_epi8(tb, ta, transposed),
        );
        let (x1, y1) = (
            _mm256_blendv_epi8(ta, tb_end, transposed),
            _mm256_blendv_epi8(tb_end, ta, transposed),
        );
        // Texel indices, as `PyramidLevel::index`; level 0 holds one value per
        // texel, the others a (min, max) pair.
        let origin = lookup(pyramid.origin_low, pyramid.origin_high, level);
        let row = lookup(pyramid.row_low, pyramid.row_high, level);
        let shift = _mm256_min_epi32(level, one);
        let i0 = _mm256_add_epi32(
            _mm256_add_epi32(origin, _mm256_mullo_epi32(y0, row)),
            _mm256_sllv_epi32(x0, shift),
        );
        let i1 = _mm256_add_epi32(
            _mm256_add_epi32(origin, _mm256_mullo_epi32(y1, row)),
            _mm256_sllv_epi32(x1, shift),
        );
        // Each texel's min with the value after it: its max above level 0, where
        // the texel's one value is both.
        let values = pyramid.values;
        let (min0, next0) = gather_pairs(values, i0, active);
        let (min1, next1) = gather_pairs(values, i1, active);
        let at_level0 = _mm256_cmpeq_epi32(level, _mm256_setzero_si256());
        let level0_f = _mm256_castsi256_ps(at_level0);
        let (max0, max1) = (
            _mm256_blendv_ps(next0, min0, level0_f),
            _mm256_blendv_ps(next1, min1, level0_f),
        );
        let zmin = _mm256_min_ps(min0, min1);
        let zmax = _mm256_max_ps(max0, max1);
        let ordered = _mm256_cmp_ps::<_CMP_LT_OQ>(inv_a, inv_e);
        let lo = _mm256_blendv_ps(inv_e, inv_a, ordered);
        let hi = _mm256_blendv_ps(inv_a, inv_e, ordered);
        let one_f = _mm256_set1_ps(1.0);
        let skip = _mm256_castps_si256(_mm256_or_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_mul_ps(lo, zmin), one_f),
            _mm256_cmp_ps::<_CMP_LT_OQ>(
                _mm256_mul_ps(hi, _mm256_add_ps(zmax, pyramid.thickness)),
                one_f,
            ),
        ));
        let hit = _mm256_and_si256(_mm256_andnot_si256(skip, at_level0), active);
        let miss = _mm256_and_si256(_mm256_and_si256(skip, _mm256_cmpeq_epi32(ae, last)), active);
        let ended = _mm256_or_si256(hit, miss);
        // After a skip: the next sample, and the largest tile it starts.
        let a_next = _mm256_add_epi32(ae, load(&p.step));
        let aligned = trailing_zeros(_mm256_blendv_epi8(
            _mm256_add_epi32(a_next, one),
            a_next,
            forward,
        ));
        store(
            &mut p.level,
            _mm256_blendv_epi8(
                _mm256_sub_epi32(level, one),
                _mm256_min_epi32(aligned, pyramid.top),
                skip,
            ),
        );
        store(&mut p.a, _mm256_blendv_epi8(a, a_next, skip));
        // Recorded without a branch: which steps end a ray is unpredictable.
        let (found, found_a) = (load(&p.found), load(&p.found_a));
        store(&mut p.found, _mm256_blendv_epi8(found, hit, ended));
        store(&mut p.found_a, _mm256_blendv_epi8(found_a, a, ended));
        // Blended as integers: the compiler turns a float blend into a masked store,
        // which is microcoded and slow on AMD's CPUs.
        let found_inv = _mm256_loadu_si256(p.found_inv.as_ptr() as *const __m256i);
        let found_inv = _mm256_blendv_epi8(found_inv, _mm256_castps_si256(inv_a), ended);
        _mm256_storeu_si256(p.found_inv.as_mut_ptr() as *mut __m256i, found_inv);
        store(&mut p.active, _mm256_andnot_si256(ended, active));
        let ended_bits = _mm256_movemask_ps(_mm256_castsi256_ps(ended)) as u32;
        p.live &= !ended_bits;
        ended_bits.count_ones()
    }
}

/// [`ScreenTracer::march`] for every queued ray: `found[i]` becomes the sample
/// found for `queued[i]`.
///
/// # Safety
/// The CPU must have AVX2; `tables` must be `tracer`'s, and every queued march set
/// up by `tracer` (so that its samples lie in the tracer's image).
#[target_feature(enable = "avx2")]
pub(super) unsafe fn march(
    tracer: &ScreenTracer,
    tables: &LevelTables,
    queued: &[Queued],
    found: &mut [Option<(i32, f32)>],
) {
    // SAFETY (the intrinsics): the CPU has AVX2. The gathers read only marching
    // lanes (masked), whose texels lie in the pyramid as in the scalar march:
    // their samples lie in the image (`setup` clips them), and the tables hold the
    // levels' own offsets. The value after a texel is stored too: above level 0 it
    // is the texel's max; at level 0 the march visits only the image's texels
    // (x <= width - 1), so it is the next texel or the right border's.
    unsafe {
        let pyramid = Pyramid {
            values: tracer.pyramid.values().as_ptr(),
            origin_low: _mm256_loadu_si256(tables.origin.as_ptr() as *const __m256i),
            origin_high: _mm256_loadu_si256(tables.origin[8..].as_ptr() as *const __m256i),
            row_low: _mm256_loadu_si256(tables.row.as_ptr() as *const __m256i),
            row_high: _mm256_loadu_si256(tables.row[8..].as_ptr() as *const __m256i),
            top: _mm256_set1_epi32(tables.top),
            thickness: _mm256_set1_ps(tracer.params.thickness),
        };
        let mut packets = [Packet::new(); PACKETS];
        let mut next = 0usize;
        loop {
            let mut marching = 0;
            for p in &mut packets {
                marching += p.refill(queued, &mut next, found);
            }
            if marching == 0 {
                return;
            }
            // Step until enough lanes fall idle to refill (or, with the queue
            // empty, until every ray ended).
            let until = if next < queued.len() {
                PACKETS * LANES - REFILL_AT
            } else {
                0
            };
            while marching > until {
                for p in &mut packets {
                    marching -= step(p, &pyramid) as usize;
                }
            }
        }
    }
}
