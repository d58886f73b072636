//! The AVX2 setup of a [`super::TraceBatch`]: [`ScreenTracer::setup`] for eight rays
//! per vector. Each lane does the scalar setup's operations in the same order (no fused
//! multiply-add), so the marches are the same. Lanes that need the scalar setup's rare
//! branches (a segment clipped at the near plane, a march clipped at the image's sides,
//! a degenerate or far-off projection, an origin outside the image) take the scalar
//! setup instead.

use super::queue::{Pending, Queued};
use crate::sample::ssrt::{FAR, FIXED_ONE, FRACTION_BITS, March, NEAR, ScreenTracer};
use relume_base::simd::LANES;
use std::arch::x86_64::*;

/// The largest `skip_steps` the lanes handle: with it (and sides up to [`MAX_SIDE`]), a
/// march's major coordinates stay within 8192 + 65, so `minor_c + a * minor_slope`
/// fits in i32 as it does in the scalar setup's i64.
const MAX_SKIP_STEPS: i32 = 64;

/// The largest image side the lanes handle (as [`March`] does).
const MAX_SIDE: u32 = 8192;

/// Ends of projected segments beyond this many pixels take the scalar setup (its float
/// to integer conversions saturate; the lanes' do not).
const FAR_PIXELS: f32 = (1 << 30) as f32;

/// Sets up every pending ray, queueing those whose segment has samples (in any order:
/// each carries its ray index).
///
/// # Safety
/// The CPU must have AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn set_up(tracer: &ScreenTracer, pending: &Pending, queued: &mut Vec<Queued>) {
    let n = pending.len();
    let cam = &tracer.camera;
    let small = cam.width <= MAX_SIDE && cam.height <= MAX_SIDE;
    let lanes_end = if tracer.skip_steps <= MAX_SKIP_STEPS && small {
        n / LANES * LANES
    } else {
        0
    };
    for first in (0..lanes_end).step_by(LANES) {
        // SAFETY: the CPU has AVX2; `first + LANES <= n`.
        unsafe { set_up_lanes(tracer, pending, first, queued) };
    }
    for i in lanes_end..n {
        pending.set_up(i, tracer, queued);
    }
}

/// Lanes where `m` is clear.
#[inline(always)]
unsafe fn not(m: __m256) -> __m256 {
    unsafe { _mm256_xor_ps(m, _mm256_castsi256_ps(_mm256_set1_epi32(-1))) }
}

#[inline(always)]
unsafe fn abs(v: __m256) -> __m256 {
    unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), v) }
}

/// Whether the minor pixel of the sample at major coordinate `a` lies in the image:
/// `1 << FRACTION_BITS <= minor_c + a * minor_slope < end` (the scalar setup's
/// `inside`, with `end` one past its `hi`).
#[inline(always)]
unsafe fn inside(minor_c: __m256i, minor_slope: __m256i, end: __m256i, a: __m256i) -> __m256i {
    unsafe {
        let fixed = _mm256_add_epi32(minor_c, _mm256_mullo_epi32(a, minor_slope));
        _mm256_and_si256(
            _mm256_cmpgt_epi32(fixed, _mm256_set1_epi32((1 << FRACTION_BITS) - 1)),
            _mm256_cmpgt_epi32(end, fixed),
        )
    }
}

#[inline(always)]
unsafe fn ints(v: __m256i) -> [i32; LANES] {
    let mut a = [0i32; LANES];
    unsafe { _mm256_storeu_si256(a.as_mut_ptr() as *mut __m256i, v) };
    a
}

#[inline(always)]
unsafe fn floats(v: __m256) -> [f32; LANES] {
    let mut a = [0f32; LANES];
    unsafe { _mm256_storeu_ps(a.as_mut_ptr(), v) };
    a
}

/// Pending rays `first..first + LANES`.
///
/// # Safety
/// The CPU must have AVX2, and `first + LANES <= pending.len()`.
#[inline(always)]
unsafe fn set_up_lanes(
    tracer: &ScreenTracer,
    pending: &Pending,
    first: usize,
    queued: &mut Vec<Queued>,
) {
    // SAFETY: AVX2 is there; every load reads LANES floats from `first`, which the
    // caller keeps inside the arrays (all `pending.len()` long).
    unsafe {
        let p = pending;
        let splat = _mm256_set1_ps;
        let splat_i = _mm256_set1_epi32;
        let cam = &tracer.camera;
        let (w, h) = (cam.width as i32, cam.height as i32);
        let (ox, oy, oz) = (
            _mm256_loadu_ps(p.ox.as_ptr().add(first)),
            _mm256_loadu_ps(p.oy.as_ptr().add(first)),
            _mm256_loadu_ps(p.oz.as_ptr().add(first)),
        );
        let (dx, dy, dz) = (
            _mm256_loadu_ps(p.dx.as_ptr().add(first)),
            _mm256_loadu_ps(p.dy.as_ptr().add(first)),
            _mm256_loadu_ps(p.dz.as_ptr().add(first)),
        );
        let (inv_z, sx, sy) = (
            _mm256_loadu_ps(p.inv_z.as_ptr().add(first)),
            _mm256_loadu_ps(p.px.as_ptr().add(first)),
            _mm256_loadu_ps(p.py.as_ptr().add(first)),
        );
        let t_max = _mm256_loadu_ps(p.t_max.as_ptr().add(first));
        // Lanes the scalar setup takes over.
        let mut rare = _mm256_setzero_ps();
        let inside_image = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(sx, splat(-0.5)),
                _mm256_cmp_ps::<_CMP_LT_OQ>(sx, splat(w as f32 - 0.5)),
            ),
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(sy, splat(-0.5)),
                _mm256_cmp_ps::<_CMP_LT_OQ>(sy, splat(h as f32 - 0.5)),
            ),
        );
        rare = _mm256_or_ps(rare, not(inside_image));
        // `t_max.min(FAR)`: FAR for a NaN t_max, as `f32::min`.
        let t_end = _mm256_min_ps(t_max, splat(FAR));
        let near_clip =
            _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_add_ps(oz, _mm256_mul_ps(t_end, dz)), splat(NEAR));
        rare = _mm256_or_ps(rare, near_clip);
        rare = _mm256_or_ps(rare, not(_mm256_cmp_ps::<_CMP_GT_OQ>(t_end, splat(0.0))));
        let ex = _mm256_add_ps(ox, _mm256_mul_ps(dx, t_end));
        let ey = _mm256_add_ps(oy, _mm256_mul_ps(dy, t_end));
        let ez = _mm256_add_ps(oz, _mm256_mul_ps(dz, t_end));
        let inv1 = _mm256_div_ps(splat(1.0), ez);
        rare = _mm256_or_ps(
            rare,
            not(_mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GT_OQ>(inv1, splat(0.0)),
                _mm256_cmp_ps::<_CMP_LT_OQ>(inv1, splat(f32::INFINITY)),
            )),
        );
        let px = _mm256_add_ps(
            _mm256_mul_ps(_mm256_mul_ps(splat(cam.fx), ex), inv1),
            splat(cam.cx),
        );
        let py = _mm256_add_ps(
            _mm256_mul_ps(_mm256_mul_ps(splat(cam.fy), ey), inv1),
            splat(cam.cy),
        );
        let transposed =
            _mm256_cmp_ps::<_CMP_GT_OQ>(abs(_mm256_sub_ps(py, sy)), abs(_mm256_sub_ps(px, sx)));
        let transposed_i = _mm256_castps_si256(transposed);
        let sa = _mm256_blendv_ps(sx, sy, transposed);
        let sb = _mm256_blendv_ps(sy, sx, transposed);
        let ea = _mm256_blendv_ps(px, py, transposed);
        let eb = _mm256_blendv_ps(py, px, transposed);
        let major_extent = _mm256_blendv_epi8(splat_i(w), splat_i(h), transposed_i);
        let minor_extent = _mm256_blendv_epi8(splat_i(h), splat_i(w), transposed_i);
        let da = _mm256_sub_ps(ea, sa);
        rare = _mm256_or_ps(rare, not(_mm256_cmp_ps::<_CMP_NEQ_OQ>(da, splat(0.0))));
        rare = _mm256_or_ps(
            rare,
            not(_mm256_cmp_ps::<_CMP_LT_OQ>(abs(ea), splat(FAR_PIXELS))),
        );
        let r = _mm256_div_ps(splat(1.0), da);
        let forward_f = _mm256_cmp_ps::<_CMP_GT_OQ>(da, splat(0.0));
        let forward = _mm256_castps_si256(forward_f);
        let step = _mm256_blendv_epi8(splat_i(-1), splat_i(1), forward);
        let start_pixel = _mm256_cvttps_epi32(_mm256_add_ps(sa, splat(0.5)));
        let mut first_a = _mm256_add_epi32(
            start_pixel,
            _mm256_mullo_epi32(step, splat_i(tracer.skip_steps)),
        );
        let behind = _mm256_cmp_ps::<_CMP_LT_OQ>(
            _mm256_mul_ps(
                _mm256_sub_ps(_mm256_cvtepi32_ps(first_a), sa),
                _mm256_cvtepi32_ps(step),
            ),
            splat(0.0),
        );
        first_a = _mm256_add_epi32(first_a, _mm256_and_si256(step, _mm256_castps_si256(behind)));
        // floor_i32 / ceil_i32 of ea (in range: |ea| < 2^30 or the lane is rare).
        let t = _mm256_cvttps_epi32(ea);
        let t_f = _mm256_cvtepi32_ps(t);
        let floor = _mm256_add_epi32(t, _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GT_OQ>(t_f, ea)));
        let ceil = _mm256_sub_epi32(t, _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LT_OQ>(t_f, ea)));
        let last_a = _mm256_blendv_epi8(
            _mm256_max_epi32(ceil, _mm256_setzero_si256()),
            _mm256_min_epi32(floor, _mm256_sub_epi32(major_extent, splat_i(1))),
            forward,
        );
        // (last - first) * step < 0: no sample.
        let empty = _mm256_blendv_epi8(
            _mm256_cmpgt_epi32(last_a, first_a),
            _mm256_cmpgt_epi32(first_a, last_a),
            forward,
        );
        let slope = _mm256_mul_ps(_mm256_sub_ps(eb, sb), r);
        let dinv = _mm256_mul_ps(_mm256_sub_ps(inv1, inv_z), r);
        let minor_c = _mm256_cvttps_epi32(_mm256_mul_ps(
            _mm256_sub_ps(_mm256_add_ps(sb, splat(1.5)), _mm256_mul_ps(sa, slope)),
            splat(FIXED_ONE),
        ));
        let minor_slope = _mm256_cvttps_epi32(_mm256_mul_ps(slope, splat(FIXED_ONE)));
        // Both ends inside the image along the minor axis, else the scalar clipping.
        let end = _mm256_slli_epi32::<{ FRACTION_BITS as i32 }>(_mm256_add_epi32(
            minor_extent,
            splat_i(1),
        ));
        let ends_inside = _mm256_and_si256(
            inside(minor_c, minor_slope, end, first_a),
            inside(minor_c, minor_slope, end, last_a),
        );
        let clipped = _mm256_andnot_si256(empty, _mm256_xor_si256(ends_inside, splat_i(-1)));
        rare = _mm256_or_ps(rare, _mm256_castsi256_ps(clipped));
        let inv_c = _mm256_sub_ps(inv_z, _mm256_mul_ps(sa, dinv));

        let (rare, empty) = (
            _mm256_movemask_ps(rare) as u32,
            _mm256_movemask_ps(_mm256_castsi256_ps(empty)) as u32,
        );
        let (transposed, step) = (ints(transposed_i), ints(step));
        let (minor_c, minor_slope) = (ints(minor_c), ints(minor_slope));
        let (first_a, last_a) = (ints(first_a), ints(last_a));
        let (inv_c, dinv) = (floats(inv_c), floats(dinv));
        // Each lane queues at most one ray. Whether a ray's segment is empty is
        // unpredictable, so every non-rare lane's march is written past the end and
        // kept by moving the end, without a branch.
        queued.reserve(LANES);
        for lane in 0..LANES {
            let i = first + lane;
            if rare >> lane & 1 == 1 {
                pending.set_up(i, tracer, queued);
                continue;
            }
            let (origin, dir, _) = pending.get(i);
            let len = queued.len();
            queued.spare_capacity_mut()[0].write(Queued {
                march: March {
                    transposed: transposed[lane] != 0,
                    minor_c: minor_c[lane],
                    minor_slope: minor_slope[lane],
                    inv_c: inv_c[lane],
                    dinv: dinv[lane],
                    first: first_a[lane],
                    last: last_a[lane],
                    step: step[lane],
                },
                origin: origin.point,
                dir,
                ray: pending.ray[i],
            });
            // SAFETY (inside the function's unsafe block): element `len` was just
            // written (the reserve leaves a slot for every lane).
            queued.set_len(len + (empty >> lane & 1 == 0) as usize);
        }
    }
}
