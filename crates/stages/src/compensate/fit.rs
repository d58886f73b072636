//! The color maps of paper 000 Sec. 4.2-4.3 from the pair moments: the per-channel
//! approximation A_t, the regularized linear map C_t of eq. (2), the inverse c_t^-1, and
//! the choice between them (fallback to A_t under the minimum number of pairs).

use super::compensation::Compensation;
use super::pairs::PairMoments;
use glam::{DMat3, DVec3, Mat3};

/// Smallest Hadamard ratio `|det C| / (|c_0| |c_1| |c_2|)` (1 for orthogonal columns, 0
/// for a singular matrix) of a usable C_t. Color maps are near-diagonal (ratio near 1);
/// below this the inverse c_t^-1 would amplify rounding by more than a thousand.
pub const MIN_HADAMARD_RATIO: f64 = 1e-3;

/// Which map c_t is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    /// C_t of eq. (2), falling back to A_t under the minimum number of pairs.
    Linear,
    /// Always A_t (Sec. 4.2), to compare with the linear model.
    Gain,
}

/// Settings of [`estimate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitParams {
    pub model: Model,
    /// Regularization weight gamma of eq. (2) towards A_t (0.05 in paper 000).
    pub gamma: f64,
    /// Added to gamma per kept pair, so that the pull towards A_t does not fade as the
    /// number of pairs (and the unnormalized sums of eq. (2)) grows.
    pub gamma_per_pair: f64,
    /// Fewer kept pairs make the frame approximate (2000 in paper 000).
    pub min_pairs: u32,
}

impl Default for FitParams {
    fn default() -> Self {
        FitParams {
            model: Model::Linear,
            gamma: 0.05,
            gamma_per_pair: 0.0,
            min_pairs: 2000,
        }
    }
}

/// The per-channel scale s = sum(r w) / sum(u w) of Sec. 4.2 (the diagonal of A_t).
/// Channels without weighted pairs are NaN.
pub fn channel_gains(moments: &PairMoments) -> DVec3 {
    moments.weighted_r / moments.weighted_u
}

/// True when the gains define A_t: every channel positive and finite.
pub fn gains_are_usable(gains: DVec3) -> bool {
    gains.is_finite() && gains.min_element() > 0.0
}

/// C_t of eq. (2): `((U W^2 U^T + gamma I)^-1 (U W^2 R^T + gamma A_t))^T`, with the sums
/// of the moments (unnormalized, as in the paper) and `A_t = diag(gains)`. `None` when
/// the system cannot be solved or C_t is not finite.
pub fn linear_map(moments: &PairMoments, gains: DVec3, gamma: f64) -> Option<DMat3> {
    let system = moments.uu + DMat3::from_diagonal(DVec3::splat(gamma));
    let det = system.determinant();
    if !(det.is_finite() && det.abs() > 0.0) {
        return None;
    }
    let target = moments.ur + gamma * DMat3::from_diagonal(gains);
    let map = (system.inverse() * target).transpose();
    map.is_finite().then_some(map)
}

/// `c^-1` when `c` is well conditioned (Hadamard ratio at least [`MIN_HADAMARD_RATIO`])
/// and both are finite in f32.
pub fn well_conditioned_inverse(c: DMat3) -> Option<DMat3> {
    let norms = c.x_axis.length() * c.y_axis.length() * c.z_axis.length();
    let det = c.determinant();
    if !(norms.is_finite() && norms > 0.0 && det.abs() >= MIN_HADAMARD_RATIO * norms) {
        return None;
    }
    let inverse = c.inverse();
    (c.as_mat3().is_finite() && inverse.as_mat3().is_finite()).then_some(inverse)
}

/// The compensation of a frame after the first (paper 000 Sec. 4.2-4.3) from its pair
/// moments and the previous frame's map c_{t-1}:
/// - enough pairs (`min_pairs`): c_t = C_t (eq. (2)) for the linear model, A_t for the
///   gain model;
/// - otherwise, or when that map is undefined or ill-conditioned: the frame is
///   approximate and c_t = A_t when its gains are positive and finite, else c_{t-1}.
///
/// `gains` holds the diagonal of A_t, with 0 for channels that had no weighted pairs.
pub fn estimate(moments: &PairMoments, previous: &Mat3, params: &FitParams) -> Compensation {
    let gains = channel_gains(moments);
    let approximation = gains_are_usable(gains).then(|| DMat3::from_diagonal(gains));
    let enough = moments.counts.kept >= params.min_pairs;
    let fitted = match params.model {
        _ if !enough => None,
        Model::Gain => approximation,
        Model::Linear => {
            let pull = DVec3::select(gains.is_finite_mask(), gains, DVec3::ZERO);
            let gamma = params.gamma + params.gamma_per_pair * moments.counts.kept as f64;
            linear_map(moments, pull, gamma)
        }
    };
    let with_inverse = |m: Option<DMat3>| m.and_then(|m| Some((m, well_conditioned_inverse(m)?)));
    let (matrix, inverse, approximate) = match with_inverse(fitted) {
        Some((m, inv)) => (m, inv, false),
        None => match with_inverse(approximation) {
            Some((m, inv)) => (m, inv, true),
            None => {
                let m = previous.as_dmat3();
                (m, m.inverse(), true)
            }
        },
    };
    Compensation {
        matrix: matrix.as_mat3(),
        inverse: inverse.as_mat3(),
        gains: DVec3::select(gains.is_finite_mask(), gains, DVec3::ZERO).as_vec3(),
        approximate,
        initial: false,
        pairs: moments.counts,
    }
}
