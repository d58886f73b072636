//! Rigid alignment of a frame to the model: Gauss-Newton over a point-to-plane ICP term
//! with projective data association (KinectFusion, Newcombe et al. 2011, Sec. 3.5, eqs.
//! 8-10) plus a photometric term (the dense RGB-D odometry of Steinbrücker et al. 2011,
//! as ElasticFusion, Whelan et al. 2016, eq. 7, and Open3D's hybrid odometry combine
//! them), coarse to fine over a [`Pyramid`], with Huber weights on both residuals.
//!
//! For a frame pixel with camera-space point p and the current estimate T (frame camera to
//! model camera), p' = T p is projected into the model view; the model's point q and
//! normal n at the nearest pixel give the geometric residual r_g = n . (p' - q), kept when
//! |p' - q| <= `max_distance_m` and the frame's rotated normal lies within `max_angle_deg`
//! of n. The photometric residual is r_i = I_model(pi(p')) - I_frame(pixel), the model's
//! intensity read bilinearly at the projection, on the same kept pixels (so that an
//! occluded model point gives no colour either). With the left increment
//! T <- (R(w), v) T, dr_g/d(v, w) = (n, p' x n) and dr_i/d(v, w) = (g, p' x g), with
//! g = grad I_model J_pi(p'). The step solves
//! sum (w_g J_g J_g^T + lambda w_i J_i J_i^T) x = -sum (w_g J_g r_g + lambda w_i J_i r_i).
//!
//! Departures: the model is the depth fusion's map in the previous frame's view (not a
//! TSDF raycast); the increment applies R(w) and v as a rotation then a translation
//! (first-order the same as the SE(3) exponential, which Gauss-Newton's fixed point does
//! not depend on). Sums are in f64 over fixed blocks of rows added in order, so the
//! result does not depend on the number of threads.

use super::pyramid::{Level, Pyramid};
use glam::{DMat3, DMat4, DVec3, Mat3, Vec3};
use rayon::prelude::*;

/// Rows summed by one job: the blocks, not the threads, fix the order of the sums.
const ROWS_PER_BLOCK: usize = 8;

/// Settings of one alignment.
#[derive(Clone, Debug, PartialEq)]
pub struct AlignParams {
    /// Gauss-Newton iterations per level, finest first (KinectFusion: 4, 5, 10; the
    /// stage's default 1, 1, 4 scores as well on both recordings measured).
    pub iterations: Vec<usize>,
    /// Frame pixels used at the finest level: every `fine_stride`-th in x and y.
    pub fine_stride: usize,
    /// A frame point farther than this from its model point is no correspondence
    /// (KinectFusion's epsilon_d).
    pub max_distance_m: f32,
    /// Normals further apart than this are no correspondence (KinectFusion's
    /// epsilon_theta, 20 degrees on bilaterally filtered depth; the default, 80, only
    /// refuses surfaces facing away, since raw depth's normals are noisy).
    pub max_angle_deg: f32,
    /// lambda, the photometric term's weight against the geometric one (residuals in
    /// metres and in intensity in [0, 1]); 0 turns it off.
    pub photometric_weight: f64,
    /// Huber thresholds of the residuals: metres, intensity.
    pub huber_m: f32,
    pub huber_intensity: f32,
}

impl Default for AlignParams {
    fn default() -> Self {
        AlignParams {
            iterations: vec![1, 1, 4],
            fine_stride: 2,
            max_distance_m: 0.1,
            max_angle_deg: 80.0,
            photometric_weight: 0.1,
            huber_m: 0.01,
            huber_intensity: 0.05,
        }
    }
}

/// The outcome of an alignment, with what decides whether to trust it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// Frame camera to model camera.
    pub model_from_frame: DMat4,
    /// Frame points at the finest level that had a model correspondence in the last
    /// iteration, and frame points with depth there.
    pub inliers: usize,
    pub valid: usize,
    /// Root mean square of the geometric residuals of the inliers, metres.
    pub rmse_m: f64,
    /// Whether every step's normal equations were solvable (not degenerate).
    pub solvable: bool,
}

/// The normal equations of one sum: upper triangle of J^T W J (row-major), J^T W r,
/// the weighted cost and the counts.
#[derive(Clone, Copy, Debug, Default)]
struct Normal {
    jtj: [f64; 21],
    jtr: [f64; 6],
    squared_geometric: f64,
    inliers: usize,
    valid: usize,
}

/// The sums of one row in f32 (a row of a 640-pixel image keeps f32's precision),
/// added into a [`Normal`] at the row's end: half the work of f64 sums per pixel.
#[derive(Clone, Copy, Debug, Default)]
struct RowSum {
    jtj: [f32; 21],
    jtr: [f32; 6],
    squared_geometric: f32,
    inliers: usize,
    valid: usize,
}

impl RowSum {
    #[inline]
    #[allow(clippy::needless_range_loop)] // index math of a packed triangle
    fn add(&mut self, j: [f32; 6], r: f32, w: f32) {
        let mut k = 0;
        for a in 0..6 {
            let wa = w * j[a];
            for b in a..6 {
                self.jtj[k] += wa * j[b];
                k += 1;
            }
            self.jtr[a] += wa * r;
        }
    }
}

impl Normal {
    fn absorb(&mut self, row: &RowSum) {
        for (a, b) in self.jtj.iter_mut().zip(&row.jtj) {
            *a += *b as f64;
        }
        for (a, b) in self.jtr.iter_mut().zip(&row.jtr) {
            *a += *b as f64;
        }
        self.squared_geometric += row.squared_geometric as f64;
        self.inliers += row.inliers;
        self.valid += row.valid;
    }

    fn merge(&mut self, o: &Normal) {
        for (a, b) in self.jtj.iter_mut().zip(&o.jtj) {
            *a += b;
        }
        for (a, b) in self.jtr.iter_mut().zip(&o.jtr) {
            *a += b;
        }
        self.squared_geometric += o.squared_geometric;
        self.inliers += o.inliers;
        self.valid += o.valid;
    }

    #[allow(clippy::needless_range_loop)] // index math of a packed triangle
    /// The step x solving (J^T W J) x = -J^T W r, or `None` when the system is singular.
    fn solve(&self) -> Option<[f64; 6]> {
        let mut a = [[0.0f64; 6]; 6];
        let mut k = 0;
        for r in 0..6 {
            for c in r..6 {
                a[r][c] = self.jtj[k];
                a[c][r] = self.jtj[k];
                k += 1;
            }
        }
        let b = self.jtr.map(|x| -x);
        cholesky_solve(a, b)
    }
}

#[allow(clippy::needless_range_loop)] // textbook index form
/// Solves A x = b for symmetric positive definite A by Cholesky; `None` when a pivot is
/// not positive against the matrix's scale.
fn cholesky_solve(a: [[f64; 6]; 6], b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = (0..6).map(|i| a[i][i]).fold(0.0f64, f64::max);
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    let mut l = [[0.0f64; 6]; 6];
    for i in 0..6 {
        for j in 0..=i {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if s <= 1e-12 * scale {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [0.0f64; 6];
    for i in 0..6 {
        let s: f64 = (0..i).map(|k| l[i][k] * y[k]).sum();
        y[i] = (b[i] - s) / l[i][i];
    }
    let mut x = [0.0f64; 6];
    for i in (0..6).rev() {
        let s: f64 = (i + 1..6).map(|k| l[k][i] * x[k]).sum();
        x[i] = (y[i] - s) / l[i][i];
    }
    Some(x)
}

/// Aligns `frame` to `model` starting from `guess` (frame camera to model camera).
pub fn align(model: &Pyramid, frame: &Pyramid, guess: DMat4, params: &AlignParams) -> Alignment {
    let mut pose = guess;
    let levels = model.levels.len().min(frame.levels.len());
    let mut last = Normal::default();
    let mut solvable = true;
    for l in (0..levels).rev() {
        let iterations = params
            .iterations
            .get(l)
            .or(params.iterations.last())
            .copied()
            .unwrap_or(0);
        let stride = if l == 0 { params.fine_stride.max(1) } else { 1 };
        for _ in 0..iterations {
            let normal = accumulate(&model.levels[l], &frame.levels[l], &pose, stride, params);
            let step = normal.solve();
            if l == 0 {
                last = normal;
            }
            let Some(x) = step else {
                solvable = false;
                break;
            };
            pose = increment(x) * pose;
            let size =
                DVec3::new(x[0], x[1], x[2]).length() + DVec3::new(x[3], x[4], x[5]).length();
            if size < 1e-5 {
                break;
            }
        }
    }
    if levels > 0 && last.valid == 0 {
        // The finest level ran no iteration: measure the final pose there.
        last = accumulate(
            &model.levels[0],
            &frame.levels[0],
            &pose,
            params.fine_stride.max(1),
            params,
        );
    }
    Alignment {
        model_from_frame: pose,
        inliers: last.inliers,
        valid: last.valid,
        rmse_m: if last.inliers > 0 {
            (last.squared_geometric / last.inliers as f64).sqrt()
        } else {
            f64::INFINITY
        },
        solvable,
    }
}

/// The rigid motion of step x = (v, w): rotation by w (axis-angle), then translation v.
fn increment(x: [f64; 6]) -> DMat4 {
    let w = DVec3::new(x[3], x[4], x[5]);
    let angle = w.length();
    let rotation = if angle > 0.0 {
        DMat3::from_axis_angle(w / angle, angle)
    } else {
        DMat3::IDENTITY
    };
    DMat4::from_cols(
        rotation.x_axis.extend(0.0),
        rotation.y_axis.extend(0.0),
        rotation.z_axis.extend(0.0),
        DVec3::new(x[0], x[1], x[2]).extend(1.0),
    )
}

/// The normal equations of both terms at `pose` over the frame pixels of one level.
fn accumulate(
    model: &Level,
    frame: &Level,
    pose: &DMat4,
    stride: usize,
    params: &AlignParams,
) -> Normal {
    let rotation = Mat3::from_cols(
        pose.x_axis.truncate().as_vec3(),
        pose.y_axis.truncate().as_vec3(),
        pose.z_axis.truncate().as_vec3(),
    );
    let translation = pose.w_axis.truncate().as_vec3();
    let cos_max = params.max_angle_deg.to_radians().cos();
    let rows: Vec<usize> = (0..frame.height).step_by(stride).collect();
    let blocks: Vec<Normal> = rows
        .par_chunks(ROWS_PER_BLOCK)
        .map(|block| {
            let mut sum = Normal::default();
            for &y in block {
                let mut row = RowSum::default();
                for x in (0..frame.width).step_by(stride) {
                    pixel(
                        model,
                        frame,
                        (rotation, translation),
                        cos_max,
                        (x, y),
                        params,
                        &mut row,
                    );
                }
                sum.absorb(&row);
            }
            sum
        })
        .collect();
    let mut total = Normal::default();
    for b in &blocks {
        total.merge(b);
    }
    total
}

/// Adds frame pixel (x, y)'s residuals to `sum`.
#[inline]
fn pixel(
    model: &Level,
    frame: &Level,
    (rotation, translation): (Mat3, Vec3),
    cos_max: f32,
    (x, y): (usize, usize),
    params: &AlignParams,
    sum: &mut RowSum,
) {
    let i = y * frame.width + x;
    let p = frame.points[i];
    if p.z <= 0.0 {
        return;
    }
    let frame_normal = frame.normals[i];
    if frame_normal == Vec3::ZERO {
        return;
    }
    sum.valid += 1;
    let q = rotation * p + translation;
    let cam = &model.camera;
    let Some(uv) = cam.project(q) else {
        return;
    };
    // The nearest pixel. Casts truncate, which is the floor here, where they are not
    // negative (a call to floorf per pixel cost 7 % of the tracker's time; x86-64's
    // baseline has no rounding instruction).
    if !(uv.x >= -0.5 && uv.y >= -0.5) {
        return;
    }
    let (u, v) = ((uv.x + 0.5) as usize, (uv.y + 0.5) as usize);
    if u >= model.width || v >= model.height {
        return;
    }
    let m = v * model.width + u;
    let (mp, mn) = (model.points[m], model.normals[m]);
    if mp.z <= 0.0 || mn == Vec3::ZERO {
        return;
    }
    let d = q - mp;
    if d.length_squared() > params.max_distance_m * params.max_distance_m {
        return;
    }
    if (rotation * frame_normal).dot(mn) < cos_max {
        return;
    }
    // Point to plane.
    let r = mn.dot(d);
    let c = q.cross(mn);
    sum.add(
        [mn.x, mn.y, mn.z, c.x, c.y, c.z],
        r,
        huber(r, params.huber_m),
    );
    sum.squared_geometric += r * r;
    sum.inliers += 1;
    // Photometric, where the projection has a 2 x 2 neighbourhood in the model.
    if params.photometric_weight <= 0.0 {
        return;
    }
    if !(uv.x >= 0.0 && uv.y >= 0.0) {
        return;
    }
    let (fx, fy) = (uv.x as usize, uv.y as usize);
    if fx + 1 >= model.width || fy + 1 >= model.height {
        return;
    }
    let (ax, ay) = (uv.x - fx as f32, uv.y - fy as f32);
    let k = fy * model.width + fx;
    let corners = [
        (k, (1.0 - ax) * (1.0 - ay)),
        (k + 1, ax * (1.0 - ay)),
        (k + model.width, (1.0 - ax) * ay),
        (k + model.width + 1, ax * ay),
    ];
    let (mut intensity, mut gx, mut gy) = (0.0f32, 0.0f32, 0.0f32);
    for (j, w) in corners {
        intensity += w * model.intensity[j];
        gx += w * model.gradient[j][0];
        gy += w * model.gradient[j][1];
    }
    let ri = intensity - frame.intensity[i];
    let inv_z = 1.0 / q.z;
    let g = Vec3::new(
        gx * cam.fx * inv_z,
        gy * cam.fy * inv_z,
        -(gx * cam.fx * q.x + gy * cam.fy * q.y) * inv_z * inv_z,
    );
    let c = q.cross(g);
    sum.add(
        [g.x, g.y, g.z, c.x, c.y, c.z],
        ri,
        params.photometric_weight as f32 * huber(ri, params.huber_intensity),
    );
}

/// The Huber weight of residual `r` with threshold `delta`.
#[inline]
fn huber(r: f32, delta: f32) -> f32 {
    let a = r.abs();
    if a <= delta { 1.0 } else { delta / a }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_a_known_system() {
        let mut a = [[0.0f64; 6]; 6];
        for (i, row) in a.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = if i == j { 4.0 + i as f64 } else { 0.5 };
            }
        }
        let x = [1.0, -2.0, 0.5, 3.0, 0.0, -1.0];
        let b: [f64; 6] = std::array::from_fn(|i| (0..6).map(|j| a[i][j] * x[j]).sum());
        let got = cholesky_solve(a, b).unwrap();
        for (g, w) in got.iter().zip(&x) {
            assert!((g - w).abs() < 1e-12, "{got:?}");
        }
        let mut singular = a;
        singular[5] = singular[4];
        for row in singular.iter_mut() {
            row[5] = row[4];
        }
        assert!(cholesky_solve(singular, b).is_none());
    }
}
