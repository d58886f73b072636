//! Lens distortion of the cameras relume imports from: the Brown-Conrady model with a
//! rational radial term, as the Azure Kinect (and Orbbec's Kinect-compatible cameras)
//! calibrate both of their cameras. The formulas are the Azure Kinect SDK's
//! (`src/transformation/intrinsic_transformation.c`, `transformation_project_internal`):
//!
//! ```text
//! (xp, yp) = (x, y) - (codx, cody)          a point on the z = 1 plane
//! r2 = xp^2 + yp^2                           must not exceed metric_radius^2
//! d  = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
//! xd = xp d + (r2 + 2 xp^2) p2 + 2 xp yp p1
//! yd = yp d + (r2 + 2 yp^2) p1 + 2 xp yp p2
//! (u, v) = (xd + codx, yd + cody) * (fx, fy) + (cx, cy)
//! ```
//!
//! The deprecated Rational 6KT model differs only in the tangential cross terms (`xp yp p1`
//! without the factor 2). Undistortion inverts this by Newton's method, as the SDK's
//! `transformation_iterative_unproject` does, from the undistorted guess.

/// Which tangential terms the model has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TangentialTerms {
    /// Brown-Conrady: `2 xp yp p1` (the retail Azure Kinect's model).
    BrownConrady,
    /// Rational 6KT: `xp yp p1` (early devices' recordings).
    Rational6kt,
}

/// A lens's distortion on the z = 1 plane (the intrinsics' focal lengths and principal
/// point stay in [`relume_base::pinhole::Intrinsics`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Distortion {
    /// Radial numerator k1, k2, k3 and denominator k4, k5, k6.
    pub k: [f64; 6],
    /// Tangential p1, p2.
    pub p: [f64; 2],
    /// Centre of distortion on the z = 1 plane (0 for Brown-Conrady).
    pub centre: [f64; 2],
    /// Points farther than this from the centre on the z = 1 plane are outside the lens's
    /// calibrated field: not projected.
    pub metric_radius: f64,
    pub tangential: TangentialTerms,
}

impl Distortion {
    /// Whether the lens bends no ray (every coefficient 0).
    pub fn is_none(&self) -> bool {
        self.k.iter().chain(&self.p).all(|&c| c == 0.0)
    }

    /// The distorted point of the undistorted point `(x, y)` on the z = 1 plane, or `None`
    /// outside the metric radius (or where the rational term's denominator vanishes).
    pub fn distort(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let [k1, k2, k3, k4, k5, k6] = self.k;
        let [p1, p2] = self.p;
        let (xp, yp) = (x - self.centre[0], y - self.centre[1]);
        let r2 = xp * xp + yp * yp;
        if r2 > self.metric_radius * self.metric_radius {
            return None;
        }
        let num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6));
        if den.abs() < 1e-12 {
            return None;
        }
        let d = num / den;
        let cross = match self.tangential {
            TangentialTerms::BrownConrady => 2.0 * xp * yp,
            TangentialTerms::Rational6kt => xp * yp,
        };
        let xd = xp * d + (r2 + 2.0 * xp * xp) * p2 + cross * p1;
        let yd = yp * d + (r2 + 2.0 * yp * yp) * p1 + cross * p2;
        Some((xd + self.centre[0], yd + self.centre[1]))
    }

    /// The undistorted point whose distortion is `(xd, yd)`, by Newton's method with a
    /// numerical Jacobian; `None` where it does not converge to within 1e-9 on the plane
    /// (about a millionth of a pixel) inside the metric radius.
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        const H: f64 = 1e-7;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let (fx, fy) = self.distort(x, y)?;
            let (ex, ey) = (fx - xd, fy - yd);
            if ex.abs().max(ey.abs()) < 1e-9 {
                return Some((x, y));
            }
            let (ax, ay) = self.distort(x + H, y)?;
            let (bx, by) = self.distort(x, y + H)?;
            let (j11, j21) = ((ax - fx) / H, (ay - fy) / H);
            let (j12, j22) = ((bx - fx) / H, (by - fy) / H);
            let det = j11 * j22 - j12 * j21;
            if det.abs() < 1e-12 {
                return None;
            }
            let dx = (j22 * ex - j12 * ey) / det;
            let dy = (j11 * ey - j21 * ex) / det;
            // Halve steps that would leave the calibrated field.
            let (mut nx, mut ny) = (x - dx, y - dy);
            for _ in 0..20 {
                if self.distort(nx, ny).is_some() {
                    break;
                }
                (nx, ny) = ((x + nx) / 2.0, (y + ny) / 2.0);
            }
            (x, y) = (nx, ny);
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An Azure Kinect's depth lens (NFOV, retail unit's calibration).
    fn kinect_depth() -> Distortion {
        Distortion {
            k: [3.364, 2.195, 0.109, 3.697, 3.437, 0.580],
            p: [-4.1e-5, 6.4e-5],
            centre: [0.0, 0.0],
            metric_radius: 1.7,
            tangential: TangentialTerms::BrownConrady,
        }
    }

    #[test]
    fn the_sdk_formula_at_a_point() {
        // By hand: xp = 0.3, yp = -0.2, r2 = 0.13.
        let lens = Distortion {
            k: [0.1, 0.01, 0.001, 0.2, 0.02, 0.002],
            p: [0.003, -0.004],
            centre: [0.0, 0.0],
            metric_radius: 2.0,
            tangential: TangentialTerms::BrownConrady,
        };
        let r2: f64 = 0.13;
        let d = (1.0 + 0.1 * r2 + 0.01 * r2 * r2 + 0.001 * r2.powi(3))
            / (1.0 + 0.2 * r2 + 0.02 * r2 * r2 + 0.002 * r2.powi(3));
        let xd = 0.3 * d + (r2 + 2.0 * 0.09) * -0.004 + 2.0 * 0.3 * -0.2 * 0.003;
        let yd = -0.2 * d + (r2 + 2.0 * 0.04) * 0.003 + 2.0 * 0.3 * -0.2 * -0.004;
        let (x, y) = lens.distort(0.3, -0.2).unwrap();
        assert!((x - xd).abs() < 1e-15 && (y - yd).abs() < 1e-15);
        let six = Distortion {
            tangential: TangentialTerms::Rational6kt,
            ..lens
        };
        let (x6, _) = six.distort(0.3, -0.2).unwrap();
        assert!((x6 - (xd - 0.3 * -0.2 * 0.003)).abs() < 1e-15);
    }

    #[test]
    fn undistortion_inverts_distortion_across_the_field() {
        let lens = kinect_depth();
        for i in -10..=10 {
            for j in -10..=10 {
                let (x, y) = (i as f64 * 0.08, j as f64 * 0.08);
                let (xd, yd) = lens.distort(x, y).unwrap();
                let (ux, uy) = lens.undistort(xd, yd).unwrap();
                assert!(
                    (ux - x).abs() < 1e-8 && (uy - y).abs() < 1e-8,
                    "({x}, {y}) -> ({xd}, {yd}) -> ({ux}, {uy})"
                );
            }
        }
    }

    #[test]
    fn outside_the_metric_radius_nothing_projects() {
        let lens = kinect_depth();
        assert!(lens.distort(1.3, 1.3).is_none());
        assert!(lens.distort(1.0, 1.0).is_some());
    }
}
