//! Reprojection into the previous frame for the temporal filter (paper 001 eqs. 24-26):
//! the pixel (x', y') of the previous frame whose world position is nearest the current
//! pixel's.

use super::lane_planes::{LanePlanes, Order};
use super::layout::{MISSING_DISTANCE2, X_PX, X_PY, X_PZ};
use glam::{Affine3A, Vec3};
use relume_base::pinhole::Pinhole;
use relume_base::simd::{LANES, Lanes, dot3};

/// Half size of the search window around the projected pixel (1: 3 x 3).
pub const SEARCH_RADIUS: i32 = 1;

/// The previous frame as the temporal filter sees it.
#[derive(Clone, Copy, Debug)]
pub struct PreviousView {
    /// World to previous camera.
    pub world_to_camera: Affine3A,
    /// The previous camera (same intrinsics, same image size).
    pub camera: Pinhole,
}

/// The previous pixel (x', y') matching world position `p`: `p` is projected into the
/// previous camera and rounded to a pixel, then the [`SEARCH_RADIUS`] window around it is
/// searched for the previous pixel with the nearest world position (ties: the first in
/// row order). `previous` is the previous frame's X set.
/// `None` when `p` is behind the previous camera or projects off-screen, or
/// when no pixel of the window has a position. The filter runs its lane form,
/// `find_previous_lanes`; this is the reference the tests hold it to.
#[inline]
pub fn find_previous(
    p: Vec3,
    view: &PreviousView,
    previous: &LanePlanes,
) -> Option<(usize, usize)> {
    let (u, v) = projected_pixel(p, view, previous)?;
    let cam = &view.camera;
    let width = previous.width.min(cam.width as usize) as i32;
    let height = previous.height.min(cam.height as usize) as i32;
    let mut best: Option<(usize, usize)> = None;
    let mut best_d2 = MISSING_DISTANCE2;
    for dy in -SEARCH_RADIUS..=SEARCH_RADIUS {
        for dx in -SEARCH_RADIUS..=SEARCH_RADIUS {
            let (x, y) = (u + dx, v + dy);
            if x < 0 || y < 0 || x >= width || y >= height {
                continue;
            }
            let (x, y) = (x as usize, y as usize);
            let q = Vec3::new(
                previous.at(X_PX, x, y),
                previous.at(X_PY, x, y),
                previous.at(X_PZ, x, y),
            );
            let d2 = (q - p).length_squared();
            if d2 < best_d2 {
                best_d2 = d2;
                best = Some((x, y));
            }
        }
    }
    best
}

/// The pixel of the previous camera that `p` projects into (the centre of
/// [`find_previous`]'s search window), `None` when `p` is behind the camera or off the
/// image (or the previous planes).
#[inline]
pub fn projected_pixel(p: Vec3, view: &PreviousView, previous: &LanePlanes) -> Option<(i32, i32)> {
    let c = view.world_to_camera.transform_point3(p);
    if c.z.is_nan() || c.z <= 0.0 {
        return None;
    }
    let cam = &view.camera;
    let u = cam.fx * c.x / c.z + cam.cx + 0.5;
    let v = cam.fy * c.y / c.z + cam.cy + 0.5;
    // The search stays inside both the camera and the previous planes.
    let width = previous.width.min(cam.width as usize);
    let height = previous.height.min(cam.height as usize);
    let (w, h) = (width as f32, height as f32);
    // u, v >= 0: truncation is the floor.
    (u >= 0.0 && v >= 0.0 && u < w && v < h).then_some((u as i32, v as i32))
}

/// The previous pixels of eight points, one per lane ([`find_previous_lanes`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct PreviousLanes<V> {
    /// Per lane, where its previous pixel lies in the search window around its
    /// projected pixel: index (dy + R) (2 R + 1) + dx + R for the pixel (u + dx, v + dy)
    /// ([`window_offset`]), R = [`SEARCH_RADIUS`]; below 0 for a lane with none.
    pub best: V,
    /// Per lane, its projected pixel (u, v), the centre of its search window; (0, 0)
    /// for a lane that is not active or projects off the image.
    pub centre: ([i32; LANES], [i32; LANES]),
    /// When lane l projected onto pixel (u0 + l, v0) for every l, (u0, v0)
    /// ([`consecutive_run`]).
    pub run: Option<(i32, i32)>,
}

impl<V: Lanes> PreviousLanes<V> {
    /// Per lane, its previous pixel (x', y'), or `None`.
    #[inline(always)]
    pub fn pixels(&self) -> [Option<(usize, usize)>; LANES] {
        let best = self.best.to_array();
        let (ui, vi) = self.centre;
        std::array::from_fn(|l| {
            (best[l] >= 0.0).then(|| {
                let (dx, dy) = window_offset(best[l] as i32);
                ((ui[l] + dx) as usize, (vi[l] + dy) as usize)
            })
        })
    }
}

/// The offset (dx, dy) from the projected pixel of the search window's pixel `k`
/// ([`PreviousLanes::best`]).
#[inline(always)]
pub(super) fn window_offset(k: i32) -> (i32, i32) {
    let side = 2 * SEARCH_RADIUS + 1;
    (k % side - SEARCH_RADIUS, k / side - SEARCH_RADIUS)
}

/// [`find_previous`] for eight points at once, one per lane, with the same answers bit
/// for bit (the same operations in the same order: glam's `transform_point3` and
/// `length_squared` use no fused multiply-adds, and neither does this). Lanes not in
/// the mask `active` get none.
///
/// The window's positions are read per lane by gathers, or, where the eight points
/// project onto consecutive pixels of one line (most groups: the Y pass's targets are
/// eight neighbours in a row), as runs of eight pixels by aligned loads
/// ([`consecutive_run`]). Gathering every group's window cost about 7 ms a frame at
/// 640x480 (`benches/filter.rs`, `pass/y_temporal`).
///
/// `previous` must be an X set (its position planes are gathered, at i32 offsets).
#[inline(always)]
pub(super) fn find_previous_lanes<V: Lanes>(
    p: [V; 3],
    active: V,
    view: &PreviousView,
    previous: &LanePlanes,
) -> PreviousLanes<V> {
    assert!(previous.planes() > X_PZ && previous.floats() <= i32::MAX as usize);
    // Runs and gathered indices are read in blocks order.
    assert!(previous.order() == Order::Blocks);
    let s = V::splat;
    let [px, py, pz] = p;
    let (m, t) = (
        view.world_to_camera.matrix3,
        view.world_to_camera.translation,
    );
    // ((x_axis x + y_axis y) + z_axis z) + translation, per component: a dot product
    // of a matrix row with p, in glam's order.
    let cx = dot3([s(m.x_axis.x), s(m.y_axis.x), s(m.z_axis.x)], p).add(s(t.x));
    let cy = dot3([s(m.x_axis.y), s(m.y_axis.y), s(m.z_axis.y)], p).add(s(t.y));
    let cz = dot3([s(m.x_axis.z), s(m.y_axis.z), s(m.z_axis.z)], p).add(s(t.z));
    let cam = &view.camera;
    let u = s(cam.fx).mul(cx).div(cz).add(s(cam.cx)).add(s(0.5));
    let v = s(cam.fy).mul(cy).div(cz).add(s(cam.cy)).add(s(0.5));
    let width = previous.width.min(cam.width as usize) as i32;
    let height = previous.height.min(cam.height as usize) as i32;
    let (w, h) = (s(width as f32), s(height as f32));
    let zero = s(0.0);
    // In front of the camera (false for NaN) and on screen.
    let inside = active
        .and(cz.gt(zero))
        .and(u.ge(zero))
        .and(v.ge(zero))
        .and(u.lt(w))
        .and(v.lt(h));
    if !inside.any() {
        return PreviousLanes {
            best: s(-1.0),
            centre: ([0; LANES], [0; LANES]),
            run: None,
        };
    }
    // u, v >= 0 where inside: truncation is the floor. Other lanes look at pixel (0, 0),
    // masked out.
    let (u, v) = (
        V::select(inside, u, zero).trunc(),
        V::select(inside, v, zero).trunc(),
    );
    let (ui, vi) = (u.trunc_to_i32(), v.trunc_to_i32());
    let run = consecutive_run(&ui, &vi, inside.to_array(), previous);
    let data = previous.data().as_ptr();
    let stride = previous.plane_stride();
    // For the gathered pixels' indices (see below).
    let (origin, slot_step) = (
        previous.pixel_index(0, 0) as i32,
        previous.slot_step() as i32,
    );
    let mut best_d2 = s(MISSING_DISTANCE2);
    // Index of the best window pixel so far, -1 for none.
    let mut best = s(-1.0);
    let mut k = 0;
    for dy in -SEARCH_RADIUS..=SEARCH_RADIUS {
        for dx in -SEARCH_RADIUS..=SEARCH_RADIUS {
            let (x, y) = (u.add(s(dx as f32)), v.add(s(dy as f32)));
            let ok = inside
                .and(x.ge(zero))
                .and(y.ge(zero))
                .and(x.lt(w))
                .and(y.lt(h));
            let [qx, qy, qz] = match run {
                Some((u0, v0)) => run_positions(previous, u0 + dx, v0 + dy),
                None => {
                    // Lanes outside read pixel (0, 0). Blocks order: pixel (x, y) is
                    // block x / 8, then line y, lane x mod 8 in the block, from pixel
                    // (0, 0). The block and the index in it in floats (small integers,
                    // exact), the sum in integers, which hold any set's index. Lane by
                    // lane with bounds checks this cost some 300 rdtsc ticks a group.
                    let (x, y) = (V::select(ok, x, zero), V::select(ok, y, zero));
                    let block = x.mul(s(1.0 / LANES as f32)).trunc();
                    let in_block = y
                        .mul(s(LANES as f32))
                        .add(x.sub(block.mul(s(LANES as f32))));
                    let (block, in_block) = (block.trunc_to_i32(), in_block.trunc_to_i32());
                    let offset: [i32; LANES] =
                        std::array::from_fn(|l| origin + block[l] * slot_step + in_block[l]);
                    // SAFETY: every offset is a pixel of plane 0; the position planes
                    // are inside the set.
                    unsafe {
                        [
                            V::gather(data.add(X_PX * stride), &offset),
                            V::gather(data.add(X_PY * stride), &offset),
                            V::gather(data.add(X_PZ * stride), &offset),
                        ]
                    }
                }
            };
            let offset = [qx.sub(px), qy.sub(py), qz.sub(pz)];
            let d2 = dot3(offset, offset);
            let better = ok.and(d2.lt(best_d2));
            best_d2 = V::select(better, d2, best_d2);
            best = V::select(better, s(k as f32), best);
            k += 1;
        }
    }
    PreviousLanes {
        best,
        centre: (ui, vi),
        run,
    }
}

/// When the eight lanes all project inside the image onto consecutive pixels of one
/// line, (u0 + l, v0) for lane l, that line's first pixel (u0, v0): then each pixel of
/// the search window is a run of eight consecutive pixels, read by two aligned loads
/// per plane ([`run_positions`]) instead of a gather. `None` otherwise, or where the
/// window's lines would leave the set. `previous` must be in blocks order.
#[inline(always)]
pub(super) fn consecutive_run(
    ui: &[i32; LANES],
    vi: &[i32; LANES],
    inside: [f32; LANES],
    previous: &LanePlanes,
) -> Option<(i32, i32)> {
    let (u0, v0) = (ui[0], vi[0]);
    let run = (0..LANES).all(|l| inside[l].to_bits() != 0 && ui[l] == u0 + l as i32 && vi[l] == v0);
    // Lines v0 - 1..=v0 + 1 and pixels u0 - 1..u0 + 9 (blocks -1..=slots) are in the
    // set: u0 >= 0 and u0 + 7 < width <= 8 slots since the lanes are inside.
    let lines = previous.fits_lines(SEARCH_RADIUS as usize);
    debug_assert!(previous.order() == Order::Blocks);
    (run && lines).then_some((u0, v0))
}

/// The positions of pixels x0 + l (lane l) of line `line` of the X set `previous`
/// (blocks order): the two blocks they straddle, blended and rotated into place.
/// Blocks x0.div_euclid(8) and the next one, and line `line`, must be in the set: a
/// block outside its data panics (the loads are bounds-checked), a line beyond the
/// padding would read the next plane's floats.
#[inline(always)]
pub(super) fn run_positions<V: Lanes>(previous: &LanePlanes, x0: i32, line: i32) -> [V; 3] {
    let (b, r) = (
        x0.div_euclid(LANES as i32),
        x0.rem_euclid(LANES as i32) as usize,
    );
    let first = previous.slot_index(b as isize, line as isize);
    let second = first + previous.slot_step();
    let data = previous.data();
    // Lane m of the blend holds pixel 8 b + m (m >= r) or 8 (b + 1) + m (m < r); lane l
    // of the result is its lane (l + r) mod 8, pixel x0 + l.
    let next = V::from_mask(std::array::from_fn(|m| m < r));
    let (s, up) = (previous.plane_stride(), (LANES - r) % LANES);
    let (x, y, z) = (X_PX * s, X_PY * s, X_PZ * s);
    let px = V::select(
        next,
        V::load_slice(data, second + x),
        V::load_slice(data, first + x),
    );
    let py = V::select(
        next,
        V::load_slice(data, second + y),
        V::load_slice(data, first + y),
    );
    let pz = V::select(
        next,
        V::load_slice(data, second + z),
        V::load_slice(data, first + z),
    );
    [px.rotate_up(up), py.rotate_up(up), pz.rotate_up(up)]
}
