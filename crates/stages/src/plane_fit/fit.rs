//! The SVD-free least-squares plane of paper 000 (Rohmer et al., NEI), Sec. 5: shift the
//! samples so that their mean is the origin, then solve the normal equations of the
//! three cases n = (n_x, n_y, 1), (n_x, 1, n_z), (1, n_y, n_z) by Cramer's rule, keeping
//! only the case with the largest determinant (the method of E. Emerfeldt, "Fitting a
//! plane to many points in 3D", 2015, cited by the paper).

use super::params::NormalCode;
use glam::{BVec3A, Vec3, Vec3A, Vec3Swizzles};

/// Which normal component the fit fixed to 1 (the case with the largest determinant).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitCase {
    /// n = (1, n_y, n_z): the normal is closest to the x axis.
    X,
    /// n = (n_x, 1, n_z).
    Y,
    /// n = (n_x, n_y, 1): the paper's first case, a surface facing the camera.
    Z,
}

/// A fitted plane in camera space: it contains `centroid` (the mean of the samples) and
/// has the unit `normal`, turned to face the camera at the origin (`normal . centroid <=
/// 0`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: Vec3,
    pub centroid: Vec3,
    pub case: FitCase,
}

impl Plane {
    /// The camera-space depth (z) at which the view ray `ray` (with `ray.z == 1`) meets
    /// the plane: t = (n . c) / (n . ray). Infinite or NaN when the ray is parallel to it.
    #[inline]
    pub fn depth_along(&self, ray: Vec3) -> f32 {
        self.normal.dot(self.centroid) / self.normal.dot(ray)
    }
}

/// Running sums of samples for a mean-centred scatter matrix. The sums are taken relative
/// to `origin` (a sample: the first one, or the stage's reference) and centred at the end, which is exactly the mean shift
/// of paper 000 Sec. 5 but needs one pass and keeps f32 sums small (no cancellation).
/// The six distinct products are kept in two SIMD vectors.
#[derive(Clone, Copy, Debug)]
pub struct Scatter {
    origin: Vec3A,
    count: u32,
    sum: Vec3A,
    /// sum(d * d): (xx, yy, zz).
    squares: Vec3A,
    /// sum(d * d.yzx): (xy, yz, zx).
    cross: Vec3A,
}

impl Scatter {
    /// An empty scatter whose sums are relative to `origin` (any point near the samples).
    #[inline]
    pub fn new(origin: Vec3A) -> Scatter {
        Scatter {
            origin,
            count: 0,
            sum: Vec3A::ZERO,
            squares: Vec3A::ZERO,
            cross: Vec3A::ZERO,
        }
    }

    /// A scatter from sums taken elsewhere (the lane-wise gather's, eight pixels at a
    /// time), with the meaning of the fields of one built by [`Scatter::add`].
    #[inline]
    pub(crate) fn from_sums(
        origin: Vec3A,
        count: u32,
        sum: Vec3A,
        squares: Vec3A,
        cross: Vec3A,
    ) -> Scatter {
        Scatter {
            origin,
            count,
            sum,
            squares,
            cross,
        }
    }

    /// Number of samples added (k-hat of the paper).
    #[inline]
    pub fn count(&self) -> u32 {
        self.count
    }

    /// Adds `p` when `keep` holds, without a branch (a zero offset otherwise), so that
    /// hot loops do not pay for mispredicted holes and rejections.
    #[inline]
    pub fn add_if(&mut self, keep: bool, p: Vec3A) {
        let d = Vec3A::select(BVec3A::splat(keep), p - self.origin, Vec3A::ZERO);
        self.count += keep as u32;
        self.sum += d;
        self.squares += d * d;
        self.cross += d * d.yzx();
    }

    /// Adds one sample.
    #[inline]
    pub fn add(&mut self, p: Vec3A) {
        let d = p - self.origin;
        self.count += 1;
        self.sum += d;
        self.squares += d * d;
        self.cross += d * d.yzx();
    }

    /// The least-squares plane of the samples (paper 000 Sec. 5). Fails with
    /// [`NormalCode::NoSample`] for none, [`NormalCode::TooFewSamples`] for 1 or 2, and
    /// [`NormalCode::Degenerate`] when the largest of the three 2x2 determinants is at most
    /// `min_determinant` times the squared trace of the centred scatter matrix (a
    /// scale-invariant "close to zero": collinear or coincident samples).
    #[inline]
    pub fn fit(&self, min_determinant: f32) -> Result<Plane, NormalCode> {
        match self.count {
            0 => return Err(NormalCode::NoSample),
            1 | 2 => return Err(NormalCode::TooFewSamples),
            _ => {}
        }
        // Centre: S = sum(d d^T) - sum(d) mean^T, with d relative to the origin.
        let mean = self.sum / self.count as f32;
        let s = self.sum;
        let squares = self.squares - s * mean;
        let cross = self.cross - s * mean.yzx();
        let (xx, yy, zz) = (squares.x, squares.y, squares.z);
        let (xy, yz, xz) = (cross.x, cross.y, cross.z);
        // The determinants of the three normal-equation systems: n_x = 1 leaves the
        // unknowns (n_y, n_z) with matrix [yy yz; yz zz], and so on.
        let det_x = yy * zz - yz * yz;
        let det_y = xx * zz - xz * xz;
        let det_z = xx * yy - xy * xy;
        let trace = xx + yy + zz;
        let det_max = det_x.max(det_y).max(det_z);
        // Written so that NaN sums (non-finite samples) count as degenerate too.
        let well_conditioned = det_max > min_determinant * trace * trace;
        if !well_conditioned {
            return Err(NormalCode::Degenerate);
        }
        // Cramer's rule for the chosen case, every component multiplied by its
        // determinant (which is positive), so no division is needed before normalizing:
        // n_z = 1: [xx xy; xy yy] (n_x, n_y) = -(xz, yz).
        let (direction, case) = if det_max == det_z {
            (
                Vec3::new(xy * yz - xz * yy, xy * xz - yz * xx, det_z),
                FitCase::Z,
            )
        } else if det_max == det_y {
            (
                Vec3::new(xz * yz - xy * zz, det_y, xy * xz - yz * xx),
                FitCase::Y,
            )
        } else {
            (
                Vec3::new(det_x, xz * yz - xy * zz, xy * yz - xz * yy),
                FitCase::X,
            )
        };
        let centroid = Vec3::from(self.origin + mean);
        let unit = direction / direction.length();
        if !unit.is_finite() {
            return Err(NormalCode::Degenerate);
        }
        let normal = if unit.dot(centroid) > 0.0 {
            -unit
        } else {
            unit
        };
        Ok(Plane {
            normal,
            centroid,
            case,
        })
    }
}

/// The least-squares plane through camera-space `samples` (paper 000 Sec. 5); see
/// [`Scatter::fit`] for the failure codes and `min_determinant`.
pub fn fit_plane(samples: &[Vec3], min_determinant: f32) -> Result<Plane, NormalCode> {
    let origin = samples.first().copied().unwrap_or(Vec3::ZERO);
    let mut scatter = Scatter::new(origin.into());
    for &p in samples {
        scatter.add(p.into());
    }
    scatter.fit(min_determinant)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 5 x 4 grid of points on the plane through `centre` spanned by `a` and `b`,
    /// with irregular spacing so that the scatter is not isotropic.
    fn grid(centre: Vec3, a: Vec3, b: Vec3) -> Vec<Vec3> {
        let mut pts = Vec::new();
        for i in 0..5 {
            for j in 0..4 {
                let (s, t) = (i as f32 * 0.03 - 0.06, (j * j) as f32 * 0.01 - 0.02);
                pts.push(centre + a * s + b * t);
            }
        }
        pts
    }

    fn assert_plane(normal: Vec3, centre: Vec3, case: FitCase) {
        let normal = normal.normalize();
        let a = normal.any_orthonormal_vector();
        let b = normal.cross(a);
        let pts = grid(centre, a, b);
        let plane = fit_plane(&pts, 1e-4).unwrap();
        let facing = if normal.dot(centre) > 0.0 {
            -normal
        } else {
            normal
        };
        assert_eq!(plane.case, case, "normal {normal:?}");
        assert!(
            (plane.normal - facing).length() < 2e-5,
            "{:?} != {facing:?}",
            plane.normal
        );
        let mean = pts.iter().sum::<Vec3>() / pts.len() as f32;
        assert!((plane.centroid - mean).length() < 1e-5);
    }

    #[test]
    fn noise_free_planes_are_exact_in_all_three_cases() {
        let centre = Vec3::new(0.3, -0.2, 2.0);
        assert_plane(Vec3::new(0.2, -0.1, -1.0), centre, FitCase::Z);
        assert_plane(Vec3::new(0.3, 1.0, -0.4), centre, FitCase::Y);
        assert_plane(Vec3::new(-1.0, 0.5, 0.6), centre, FitCase::X);
        // Exactly axis-aligned normals: the other two determinants are zero.
        assert_plane(Vec3::Z, centre, FitCase::Z);
        assert_plane(Vec3::Y, centre, FitCase::Y);
        assert_plane(Vec3::X, centre, FitCase::X);
    }

    #[test]
    fn normal_faces_the_camera() {
        // Wall at z = 3 seen head-on: the normal points back towards the origin.
        let pts = grid(Vec3::new(0.0, 0.0, 3.0), Vec3::X, Vec3::Y);
        assert_eq!(fit_plane(&pts, 1e-4).unwrap().normal, Vec3::NEG_Z);
        // Floor below the camera (y down): the normal points up, to -y.
        let pts = grid(Vec3::new(0.0, 1.2, 2.0), Vec3::X, Vec3::Z);
        assert_eq!(fit_plane(&pts, 1e-4).unwrap().normal, Vec3::NEG_Y);
    }

    #[test]
    fn scale_and_translation_do_not_change_the_result() {
        let pts = grid(
            Vec3::new(0.1, 0.2, 1.5),
            Vec3::new(1.0, 0.2, 0.1).normalize(),
            Vec3::new(0.0, 1.0, 0.4).normalize(),
        );
        let base = fit_plane(&pts, 1e-4).unwrap();
        for scale in [1e-3f32, 1e3] {
            let scaled: Vec<Vec3> = pts.iter().map(|p| *p * scale).collect();
            let plane = fit_plane(&scaled, 1e-4).unwrap();
            assert!(
                (plane.normal - base.normal).length() < 1e-5,
                "scale {scale}"
            );
        }
    }

    #[test]
    fn too_few_and_degenerate_samples_have_their_codes() {
        let p = Vec3::new(0.0, 0.0, 2.0);
        assert_eq!(fit_plane(&[], 1e-4), Err(NormalCode::NoSample));
        assert_eq!(fit_plane(&[p], 1e-4), Err(NormalCode::TooFewSamples));
        assert_eq!(
            fit_plane(&[p, p + Vec3::X], 1e-4),
            Err(NormalCode::TooFewSamples)
        );
        let line: Vec<Vec3> = (0..6)
            .map(|i| p + Vec3::new(0.3, 0.1, 0.2) * i as f32)
            .collect();
        assert_eq!(fit_plane(&line, 1e-4), Err(NormalCode::Degenerate));
        assert_eq!(fit_plane(&[p; 5], 1e-4), Err(NormalCode::Degenerate));
        // Three points that do span a plane are enough.
        let tri = [p, p + Vec3::X * 0.1, p + Vec3::Y * 0.1];
        assert_eq!(fit_plane(&tri, 1e-4).unwrap().normal, Vec3::NEG_Z);
    }
}
