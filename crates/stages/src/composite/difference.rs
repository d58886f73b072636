//! Paper 002's differential form (Sec. 3.1): both solutions are tone mapped as whole
//! images and their difference is added to the captured frame,
//!
//! final = TM(L_cam) + TM(L_rv) - TM(L_r),
//!
//! where TM is relume's display transform (the inverse color compensation c_t^-1, then
//! the gamma encoding to [0, 1]) and L_r, L_rv are the outgoing radiances of the two
//! solutions. A real surface's albedo is the camera's own color (clamped to [0, 1]),
//! the approximation paper 002 makes with the Kinect's color: L_r = a E_R / pi,
//! L_rv = a E_RV / pi. A virtual pixel shows TM(k_V E_RV / pi), mixed with the real
//! part by the mask M as in paper 001 eq. 2 (the difference at a virtual pixel would
//! subtract the real surface behind it, which the camera shows only where the
//! approximation holds: elsewhere the object turns translucent).
//!
//! The trade-off against paper 001's ratio form (M (E_RV / E_R) L_cam): the difference
//! divides by nothing, so noise where E_R is small is not amplified and needs no
//! `max_ratio` clamp; but it changes the camera's levels by an absolute amount that the
//! albedo approximation sets. Where the camera color is not the albedo times E_R / pi
//! (bright or saturated surfaces, exposure changes that the compensation leaves), a
//! shadow comes out too light or too dark, while the ratio form scales the camera's own
//! pixel and keeps its texture and exposure exactly.

use glam::{Mat3, Vec3};
use std::f32::consts::FRAC_1_PI;

/// The linear camera value of one pixel by the difference form (`camera` is the
/// compensated camera radiance, `inverse` the inverse compensation); `None` where the
/// objects change nothing (a real pixel with E_RV == E_R, or with no estimate): the
/// camera's own value, which the caller keeps exactly as the ratio form does.
#[inline]
pub fn difference_pixel(
    e_r: Vec3,
    e_rv: Vec3,
    mask: f32,
    k_v: Vec3,
    camera: Vec3,
    inverse: Mat3,
    gamma: f32,
) -> Option<Vec3> {
    let m = mask.clamp(0.0, 1.0);
    let real_unchanged = !(e_r.is_finite() && e_rv.is_finite()) || e_r == e_rv;
    if m >= 1.0 && real_unchanged {
        return None;
    }
    let tone_map = |linear: Vec3| (inverse * linear).max(Vec3::ZERO).powf(1.0 / gamma);
    let untone = |display: Vec3| display.powf(gamma);
    let seen = inverse * camera;
    let real = if real_unchanged {
        seen
    } else {
        // The captured frame is low dynamic range: the difference lands on its
        // displayed levels. The camera's color stands for the albedo.
        let albedo = camera.clamp(Vec3::ZERO, Vec3::ONE);
        let (e_r, e_rv) = (
            e_r.max(Vec3::ZERO) * FRAC_1_PI,
            e_rv.max(Vec3::ZERO) * FRAC_1_PI,
        );
        let display =
            tone_map(camera).min(Vec3::ONE) + tone_map(albedo * e_rv) - tone_map(albedo * e_r);
        untone(display.clamp(Vec3::ZERO, Vec3::ONE))
    };
    if m >= 1.0 {
        return Some(real);
    }
    // The object's part, mixed linearly by the mask as in paper 001 eq. 2.
    let object = if e_rv.is_finite() {
        inverse * (k_v * e_rv.max(Vec3::ZERO) * FRAC_1_PI)
    } else {
        Vec3::ZERO
    };
    Some((1.0 - m) * object + m * real)
}
