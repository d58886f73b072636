//! The geometry-aware blur that reassembles interleaved sampling (paper 002 Sec. 3.2,
//! after Segovia et al.): each pixel gathered the VPLs of its class only (one of k x k,
//! by its position in a k x k tile), so every k x k window holds every class once. The
//! blur averages a pixel with the neighbours of its k-wide window that show the same
//! surface (normals within about 25 degrees, within `PLANE_TOLERANCE` of its tangent
//! plane, same kind: real or virtual), along x and then along y (separably: 2k taps a
//! pixel instead of k^2).
//!
//! E_R is blurred over the real surface, E_RV over the visible one. A pixel whose window
//! holds neither a virtual pixel nor a touched one takes the same neighbours with the
//! same values for both, so its E_RV equals its E_R bit for bit (it is computed once and
//! copied); `touched` is set wherever that is not so.

use super::blur_lanes::blur_span;
use super::blur_pass::{PLANE_TOLERANCE, PassInputs, Taps};
use super::points::RealSurface;
use super::shade::same_surface;
use crate::sample::layers::{IrradianceLayers, LayerRow, shade_rows};
use glam::Vec3;
use relume_base::simd::Kernel;

/// Blurs `raw` (the interleaved estimates, `k` x `k` classes) into `out`, through
/// `between` (the pass along x), all of one size; with `kernel`'s lanes where all of
/// a pixel's taps lie inside the image (the same bits), else one pixel at a time.
/// `out` takes `raw`'s surface and mask layers (swapped, not copied: `raw` is left
/// with `out`'s old ones).
pub fn blur_layers(
    raw: &mut IrradianceLayers,
    real: &RealSurface,
    k: usize,
    kernel: Option<Kernel>,
    between: &mut IrradianceLayers,
    out: &mut IrradianceLayers,
) {
    let (w, h) = (raw.mask.width as usize, raw.mask.height as usize);
    let (lo, hi) = ((k.max(1) - 1) / 2, k.max(1) / 2);
    let along_x = PassInputs {
        geometry: raw,
        input: raw,
        real,
    };
    shade_rows(
        between,
        w,
        1,
        || (),
        |_, y, mut row| {
            let taps = Taps {
                start: y * w,
                stride: 1,
                lo,
                hi,
            };
            // Pixels lo..w - hi have every tap inside.
            let mut lanes_end = lo.min(w);
            if let Some(kernel) = kernel
                && w > lo + hi
            {
                lanes_end = blur_span(kernel, &along_x, taps, lo..w - hi, &mut row);
            }
            for x in (0..lo.min(w)).chain(lanes_end..w) {
                let (first, last) = (x.saturating_sub(lo), (x + hi).min(w - 1));
                let taps = y * w + first..y * w + last + 1;
                put_light(&mut row, x, &blur_pixel(&along_x, y * w + x, taps));
            }
        },
    );
    let along_y = PassInputs {
        geometry: raw,
        input: between,
        real,
    };
    shade_rows(
        out,
        w,
        1,
        || (),
        |_, y, mut row| {
            let (first, last) = (y.saturating_sub(lo), (y + hi).min(h - 1));
            let start = y * w;
            let mut lanes_end = 0;
            if let Some(kernel) = kernel
                && y >= lo
                && y + hi < h
            {
                let taps = Taps {
                    start,
                    stride: w,
                    lo,
                    hi,
                };
                lanes_end = blur_span(kernel, &along_y, taps, 0..w, &mut row);
            }
            for x in lanes_end..w {
                // Along y: pixel x of row y steps by w, within the image's height.
                let taps = (first..=last).map(|qy| qy * w + x);
                put_light(&mut row, x, &blur_pixel(&along_y, start + x, taps));
            }
        },
    );
    // The surface and mask of the raw layers, the light blurred.
    std::mem::swap(&mut out.mask, &mut raw.mask);
    std::mem::swap(&mut out.k_v, &mut raw.k_v);
    std::mem::swap(&mut out.exponent, &mut raw.exponent);
    std::mem::swap(&mut out.world_position, &mut raw.world_position);
    std::mem::swap(&mut out.world_normal, &mut raw.world_normal);
}

/// A blurred pixel.
struct Blurred {
    e_r_dir: Vec3,
    e_r_ind: Vec3,
    e_rv_dir: Vec3,
    e_rv_ind: Vec3,
    touched: bool,
    direct_min: f32,
    indirect_min: f32,
}

/// Pixel `i` of `pass.input` averaged over `taps` (see the module docs).
fn blur_pixel(pass: &PassInputs, i: usize, taps: impl Iterator<Item = usize> + Clone) -> Blurred {
    let (geometry, input, real) = (pass.geometry, pass.input, pass.real);
    let mask = &geometry.mask.data;
    let touched = taps
        .clone()
        .any(|j| input.touched.data[j] != 0 || mask[j] < 1.0);
    let (rp, rn) = (real.position[i], real.normal[i]);
    let mean = |sum: Vec3, n: u32| if n > 0 { sum / n as f32 } else { Vec3::NAN };
    let keep_nan = |own: Vec3, blurred: Vec3| if own.is_finite() { blurred } else { own };
    let (mut r_dir, mut r_ind, mut r_n) = (Vec3::ZERO, Vec3::ZERO, 0u32);
    let (mut direct_min, mut indirect_min) = (f32::INFINITY, f32::INFINITY);
    let real_taps = |j: usize| {
        let (er_dir, er_ind) = (input.e_r_dir.data[j], input.e_r_ind.data[j]);
        (er_dir.is_finite()
            && er_ind.is_finite()
            && same_surface(rp, rn, real.position[j], real.normal[j], PLANE_TOLERANCE))
        .then_some((er_dir, er_ind))
    };
    if !touched {
        // Every tap real and untouched: E_RV is E_R, tap for tap.
        for j in taps {
            if let Some((d, n)) = real_taps(j) {
                r_dir += d;
                r_ind += n;
                r_n += 1;
                direct_min = direct_min.min(input.direct_min_distance.data[j]);
                indirect_min = indirect_min.min(input.indirect_min_distance.data[j]);
            }
        }
        let e_r_dir = keep_nan(input.e_r_dir.data[i], mean(r_dir, r_n));
        let e_r_ind = keep_nan(input.e_r_ind.data[i], mean(r_ind, r_n));
        return Blurred {
            e_r_dir,
            e_r_ind,
            e_rv_dir: e_r_dir,
            e_rv_ind: e_r_ind,
            touched,
            direct_min,
            indirect_min,
        };
    }
    let virtual_here = mask[i] < 1.0;
    let (vp, vn) = (
        geometry.world_position.data[i],
        geometry.world_normal.data[i],
    );
    let (mut rv_dir, mut rv_ind, mut rv_n) = (Vec3::ZERO, Vec3::ZERO, 0u32);
    for j in taps {
        if let Some((d, n)) = real_taps(j) {
            r_dir += d;
            r_ind += n;
            r_n += 1;
        }
        let (erv_dir, erv_ind) = (input.e_rv_dir.data[j], input.e_rv_ind.data[j]);
        if (mask[j] < 1.0) == virtual_here
            && erv_dir.is_finite()
            && erv_ind.is_finite()
            && same_surface(
                vp,
                vn,
                geometry.world_position.data[j],
                geometry.world_normal.data[j],
                PLANE_TOLERANCE,
            )
        {
            rv_dir += erv_dir;
            rv_ind += erv_ind;
            rv_n += 1;
            direct_min = direct_min.min(input.direct_min_distance.data[j]);
            indirect_min = indirect_min.min(input.indirect_min_distance.data[j]);
        }
    }
    Blurred {
        e_r_dir: keep_nan(input.e_r_dir.data[i], mean(r_dir, r_n)),
        e_r_ind: keep_nan(input.e_r_ind.data[i], mean(r_ind, r_n)),
        e_rv_dir: keep_nan(input.e_rv_dir.data[i], mean(rv_dir, rv_n)),
        e_rv_ind: keep_nan(input.e_rv_ind.data[i], mean(rv_ind, rv_n)),
        touched,
        direct_min,
        indirect_min,
    }
}

/// Writes the blurred values of pixel `x` of `row` (its surface and mask come from the
/// raw layers, swapped in after the passes).
fn put_light(row: &mut LayerRow<'_>, x: usize, px: &Blurred) {
    row.e_r_dir[x] = px.e_r_dir;
    row.e_r_ind[x] = px.e_r_ind;
    row.e_rv_dir[x] = px.e_rv_dir;
    row.e_rv_ind[x] = px.e_rv_ind;
    row.direct_min_distance[x] = px.direct_min;
    row.indirect_min_distance[x] = px.indirect_min;
    row.touched[x] = px.touched as u8;
}
