//! Virtual area lights and SH9 indirect light (paper 004 Secs. 4.2-4.4).

use glam::Vec3;

/// One virtual area light (VAL, paper 004 Sec. 4.3): a Lambertian emitter at `position`
/// facing `normal`, with radiant intensity `intensity` = sum of L_k dA_k over its texels
/// (eq. 7) and total area `area`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    pub position: Vec3,
    pub normal: Vec3,
    pub intensity: Vec3,
    pub area: f32,
}

/// The lights of one frame: VALs from the direct part of the environment and the nine
/// SH coefficients of its indirect part (eq. 10).
#[derive(Clone, Debug, PartialEq)]
pub struct AreaLights {
    pub lights: Vec<AreaLight>,
    /// Radiance SH coefficients C_k of the indirect part, k = 0..9.
    pub sh9: [Vec3; 9],
}
