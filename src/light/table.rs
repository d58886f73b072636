//! The precomputed table of environment importance samples (paper 001 Sec. 5.2).

use glam::Vec3;

/// One importance sample of the environment: a direction, the radiance arriving from it
/// and the exact pdf (per steradian) of drawing it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit world direction towards the light.
    pub direction: Vec3,
    /// Radiance arriving from `direction`.
    pub radiance: Vec3,
    /// Probability density of `direction` per steradian.
    pub pdf: f32,
}

/// Importance samples of an environment map drawn from a 2D piecewise-constant
/// distribution weighted by sin(theta), in stratified order: sample i was drawn from the
/// i-th of `samples.len()` equal strata of the primary sample space, so any contiguous
/// range of the table is itself a stratified set. Pixels index it with stratification.
#[derive(Clone, Debug, PartialEq)]
pub struct LightTable {
    pub samples: Vec<LightSample>,
}
