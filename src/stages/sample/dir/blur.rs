//! The geometry-aware blur that reassembles interleaved sampling (paper 002 Sec. 3.2,
//! after Segovia et al.): each pixel gathered the VPLs of its class only (one of k x k,
//! by its position in a k x k tile), so every k x k window holds every class once; a
//! pixel's estimate is the mean over the window's pixels that show the same surface
//! (normals within about 25 degrees, within `PLANE_TOLERANCE` of its tangent plane,
//! same kind: real or virtual).
//!
//! E_R is blurred over the real surface, E_RV over the visible one. A pixel whose window
//! holds neither a virtual pixel nor a touched one takes the same neighbours with the
//! same values for both, so its E_RV equals its E_R bit for bit; `touched` is set
//! wherever that is not so.

use super::points::RealSurface;
use super::shade::same_surface;
use crate::stages::sample::layers::{IrradianceLayers, shade_rows};
use glam::Vec3;

/// Metres a neighbour may lie off a pixel's tangent plane and still be averaged in.
pub const PLANE_TOLERANCE: f32 = 0.03;

/// Blurs `raw` (the interleaved estimates, `k` x `k` classes) into `out`.
pub fn blur_layers(
    raw: &IrradianceLayers,
    real: &RealSurface,
    k: usize,
    out: &mut IrradianceLayers,
) {
    let (w, h) = (raw.mask.width as usize, raw.mask.height as usize);
    let (lo, hi) = ((k.max(1) - 1) / 2, k.max(1) / 2);
    shade_rows(
        out,
        w,
        1,
        || (),
        |_, y, row| {
            let ys = y.saturating_sub(lo)..(y + hi + 1).min(h);
            for x in 0..w {
                let i = y * w + x;
                let xs = x.saturating_sub(lo)..(x + hi + 1).min(w);
                let virtual_here = raw.mask.data[i] < 1.0;
                let (rp, rn) = (real.position[i], real.normal[i]);
                let (vp, vn) = (raw.world_position.data[i], raw.world_normal.data[i]);
                let (mut r_dir, mut r_ind, mut r_n) = (Vec3::ZERO, Vec3::ZERO, 0u32);
                let (mut rv_dir, mut rv_ind, mut rv_n) = (Vec3::ZERO, Vec3::ZERO, 0u32);
                let (mut touched, mut direct_min, mut indirect_min) =
                    (false, f32::INFINITY, f32::INFINITY);
                for qy in ys.clone() {
                    for qx in xs.clone() {
                        let j = qy * w + qx;
                        touched |= raw.touched.data[j] != 0 || raw.mask.data[j] < 1.0;
                        let (er_dir, er_ind) = (raw.e_r_dir.data[j], raw.e_r_ind.data[j]);
                        if er_dir.is_finite()
                            && er_ind.is_finite()
                            && same_surface(
                                rp,
                                rn,
                                real.position[j],
                                real.normal[j],
                                PLANE_TOLERANCE,
                            )
                        {
                            r_dir += er_dir;
                            r_ind += er_ind;
                            r_n += 1;
                        }
                        let (erv_dir, erv_ind) = (raw.e_rv_dir.data[j], raw.e_rv_ind.data[j]);
                        let same_kind = (raw.mask.data[j] < 1.0) == virtual_here;
                        if same_kind
                            && erv_dir.is_finite()
                            && erv_ind.is_finite()
                            && same_surface(
                                vp,
                                vn,
                                raw.world_position.data[j],
                                raw.world_normal.data[j],
                                PLANE_TOLERANCE,
                            )
                        {
                            rv_dir += erv_dir;
                            rv_ind += erv_ind;
                            rv_n += 1;
                            direct_min = direct_min.min(raw.direct_min_distance.data[j]);
                            indirect_min = indirect_min.min(raw.indirect_min_distance.data[j]);
                        }
                    }
                }
                let mean = |sum: Vec3, n: u32| if n > 0 { sum / n as f32 } else { Vec3::NAN };
                row.e_r_dir[x] = if raw.e_r_dir.data[i].is_finite() {
                    mean(r_dir, r_n)
                } else {
                    raw.e_r_dir.data[i]
                };
                row.e_r_ind[x] = if raw.e_r_ind.data[i].is_finite() {
                    mean(r_ind, r_n)
                } else {
                    raw.e_r_ind.data[i]
                };
                row.e_rv_dir[x] = if raw.e_rv_dir.data[i].is_finite() {
                    mean(rv_dir, rv_n)
                } else {
                    raw.e_rv_dir.data[i]
                };
                row.e_rv_ind[x] = if raw.e_rv_ind.data[i].is_finite() {
                    mean(rv_ind, rv_n)
                } else {
                    raw.e_rv_ind.data[i]
                };
                row.mask[x] = raw.mask.data[i];
                row.k_v[x] = raw.k_v.data[i];
                row.exponent[x] = raw.exponent.data[i];
                row.world_position[x] = vp;
                row.world_normal[x] = vn;
                row.direct_min_distance[x] = direct_min;
                row.indirect_min_distance[x] = indirect_min;
                row.touched[x] = touched as u8;
            }
        },
    );
}
