//! Scores of `pose.track` against the recording's poses, by the TUM RGB-D benchmark's
//! definitions (Sturm et al. 2012, Sec. VI):
//!
//! - ATE: the absolute trajectory error, the RMS distance between the tracked and the
//!   recorded camera positions after the rigid motion that best aligns the first onto the
//!   second (least squares, Horn's closed form, as the benchmark's Umeyama alignment
//!   without scale);
//! - RPE: the relative pose error E_i = (Q_i^-1 Q_{i+d})^-1 (P_i^-1 P_{i+d}) over a step
//!   d of one frame and of one second (the frame whose stamp is nearest one second
//!   later), as the RMS of its translations and of its rotation angles.
//!
//! Frames the tracker lost, or that the recording has no pose for, are left out of both;
//! lost frames are counted.

use glam::{DMat4, DQuat, DVec3};
use relume_graph::Frame;
use relume_graph::pipeline::SOURCE_PRODUCT;
use relume_recording::Pose;
use serde_json::{Value, json};

/// One frame's poses: tracked (if not lost) and recorded (if the recording has one).
#[derive(Clone, Copy, Debug)]
struct Sample {
    stamp_ns: i64,
    tracked: Option<Pose>,
    recorded: Option<Pose>,
}

/// Scores a `pose.track` stage.
pub struct TrajectoryScorer {
    pose: String,
    samples: Vec<Sample>,
}

impl TrajectoryScorer {
    /// A scorer of the poses the stage writes as `pose`.
    pub fn new(pose: String) -> TrajectoryScorer {
        TrajectoryScorer {
            pose,
            samples: Vec::new(),
        }
    }

    pub fn observe(&mut self, frame: &Frame) {
        let records = frame.record(SOURCE_PRODUCT).ok();
        self.samples.push(Sample {
            stamp_ns: records.map_or(0, |r| r.stamp_ns),
            tracked: frame.pose(&self.pose).ok().copied(),
            recorded: records.and_then(|r| r.pose),
        });
    }

    pub fn report(&self) -> Value {
        let both: Vec<(&Sample, Pose, Pose)> = self
            .samples
            .iter()
            .filter_map(|s| Some((s, s.tracked?, s.recorded?)))
            .collect();
        let tracked: Vec<Pose> = both.iter().map(|b| b.1).collect();
        let recorded: Vec<Pose> = both.iter().map(|b| b.2).collect();
        let lost = self.samples.iter().filter(|s| s.tracked.is_none()).count();
        let per_frame = relative_errors(&self.samples, |i, _| i + 1);
        let per_second = relative_errors(&self.samples, |i, s| {
            let target = s[i].stamp_ns + 1_000_000_000;
            (i + 1..s.len())
                .find(|&j| s[j].stamp_ns >= target)
                .map_or(s.len(), |j| {
                    // The nearer of the frame at or after one second and the one before it.
                    if j > i + 1 && target - s[j - 1].stamp_ns < s[j].stamp_ns - target {
                        j - 1
                    } else {
                        j
                    }
                })
        });
        json!({
            "frames": self.samples.len(),
            "lost_frames": lost,
            "frames_scored": both.len(),
            "ate_rmse_m": ate_rmse(&tracked, &recorded),
            "rpe_translation_m_per_frame": per_frame.map(|e| e.0),
            "rpe_rotation_deg_per_frame": per_frame.map(|e| e.1),
            "rpe_translation_m_per_s": per_second.map(|e| e.0),
            "rpe_rotation_deg_per_s": per_second.map(|e| e.1),
        })
    }
}

/// RMS translation (metres) and rotation (degrees) of the relative pose errors between
/// frame i and frame `step(i, samples)`, over the pairs where both frames have both poses;
/// `None` without such a pair.
fn relative_errors(
    samples: &[Sample],
    step: impl Fn(usize, &[Sample]) -> usize,
) -> Option<(f64, f64)> {
    let (mut t2, mut r2, mut n) = (0.0f64, 0.0f64, 0usize);
    for i in 0..samples.len() {
        let j = step(i, samples);
        let (Some(a), Some(b)) = (samples.get(i), samples.get(j)) else {
            continue;
        };
        let (Some(pa), Some(qa), Some(pb), Some(qb)) =
            (a.tracked, a.recorded, b.tracked, b.recorded)
        else {
            continue;
        };
        let (t, r) = relative_error(&qa, &qb, &pa, &pb);
        t2 += t * t;
        r2 += r * r;
        n += 1;
    }
    (n > 0).then(|| ((t2 / n as f64).sqrt(), (r2 / n as f64).sqrt()))
}

/// Translation (metres) and rotation angle (degrees) of
/// E = (Q_a^-1 Q_b)^-1 (P_a^-1 P_b), Q recorded, P tracked.
pub fn relative_error(qa: &Pose, qb: &Pose, pa: &Pose, pb: &Pose) -> (f64, f64) {
    let q = qa.matrix().inverse() * qb.matrix();
    let p = pa.matrix().inverse() * pb.matrix();
    let e = q.inverse() * p;
    (
        e.w_axis.truncate().length(),
        DQuat::from_mat4(&e)
            .normalize()
            .angle_between(DQuat::IDENTITY)
            .to_degrees(),
    )
}

/// The absolute trajectory error: RMS distance between `recorded` positions and the
/// `tracked` ones moved by the rigid motion that best aligns them; `None` for no poses.
pub fn ate_rmse(tracked: &[Pose], recorded: &[Pose]) -> Option<f64> {
    let n = tracked.len().min(recorded.len());
    if n == 0 {
        return None;
    }
    let a: Vec<DVec3> = tracked[..n].iter().map(|p| p.translation()).collect();
    let b: Vec<DVec3> = recorded[..n].iter().map(|p| p.translation()).collect();
    let m = rigid_alignment(&a, &b);
    let sum: f64 = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (m.transform_point3(*x) - *y).length_squared())
        .sum();
    Some((sum / n as f64).sqrt())
}

/// The rigid motion M minimizing sum |M a_i - b_i|^2 (Horn 1987: the rotation is the
/// eigenvector of the largest eigenvalue of a 4 x 4 symmetric matrix of the
/// cross-covariance, as a unit quaternion).
pub fn rigid_alignment(a: &[DVec3], b: &[DVec3]) -> DMat4 {
    let n = a.len().min(b.len()).max(1) as f64;
    let ca = a.iter().copied().sum::<DVec3>() / n;
    let cb = b.iter().copied().sum::<DVec3>() / n;
    // S[k][l] = sum (a_k - ca_k)(b_l - cb_l).
    let mut s = [[0.0f64; 3]; 3];
    for (x, y) in a.iter().zip(b) {
        let (x, y) = ((*x - ca).to_array(), (*y - cb).to_array());
        for k in 0..3 {
            for l in 0..3 {
                s[k][l] += x[k] * y[l];
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let horn = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let [w, x, y, z] = largest_eigenvector(horn);
    let rotation = DQuat::from_xyzw(x, y, z, w).normalize();
    let translation = cb - rotation * ca;
    DMat4::from_rotation_translation(rotation, translation)
}

/// The unit eigenvector of the largest eigenvalue of symmetric `m`, by cyclic Jacobi
/// rotations.
#[allow(clippy::needless_range_loop)] // Jacobi rotations in textbook index form
fn largest_eigenvector(mut m: [[f64; 4]; 4]) -> [f64; 4] {
    let mut v = [[0.0f64; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _ in 0..64 {
        let off: f64 = (0..4)
            .flat_map(|i| (0..4).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| m[i][j] * m[i][j])
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if m[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..4 {
                    let (mkp, mkq) = (m[k][p], m[k][q]);
                    m[k][p] = c * mkp - s * mkq;
                    m[k][q] = s * mkp + c * mkq;
                }
                for k in 0..4 {
                    let (mpk, mqk) = (m[p][k], m[q][k]);
                    m[p][k] = c * mpk - s * mqk;
                    m[q][k] = s * mpk + c * mqk;
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    let best = (0..4)
        .max_by(|&i, &j| m[i][i].total_cmp(&m[j][j]))
        .unwrap_or(0);
    [v[0][best], v[1][best], v[2][best], v[3][best]]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn path(n: usize) -> Vec<Pose> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.1;
                Pose::from_parts(
                    DVec3::new(t.sin(), 0.3 * t, t.cos() * 0.5),
                    DQuat::from_rotation_y(0.2 * t) * DQuat::from_rotation_x(0.05 * t),
                )
            })
            .collect()
    }

    fn moved(poses: &[Pose], m: DMat4) -> Vec<Pose> {
        poses
            .iter()
            .map(|p| {
                let (_, r, t) = (m * p.matrix()).to_scale_rotation_translation();
                Pose::from_parts(t, r)
            })
            .collect()
    }

    #[test]
    fn a_rigidly_moved_trajectory_has_no_absolute_or_relative_error() {
        let truth = path(40);
        let m = DMat4::from_rotation_translation(
            DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 0.5).normalize(), 2.0),
            DVec3::new(3.0, -1.0, 0.5),
        );
        let tracked = moved(&truth, m);
        assert!(ate_rmse(&tracked, &truth).unwrap() < 1e-9);
        for i in 0..39 {
            let (t, r) = relative_error(&truth[i], &truth[i + 1], &tracked[i], &tracked[i + 1]);
            assert!(t < 1e-9 && r < 1e-5, "{t} {r}");
        }
    }

    #[test]
    fn a_known_offset_gives_its_error() {
        // Every other position 1 cm off along +x and -x: no rigid motion removes it.
        let truth = path(40);
        let tracked: Vec<Pose> = truth
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
                Pose::from_parts(p.translation() + DVec3::X * 0.01 * sign, p.rotation())
            })
            .collect();
        let ate = ate_rmse(&tracked, &truth).unwrap();
        assert!((ate - 0.01).abs() < 2e-4, "{ate}");
        // Each step's relative error: 2 cm.
        let (t, _) = relative_error(&truth[0], &truth[1], &tracked[0], &tracked[1]);
        assert!((t - 0.02).abs() < 1e-3, "{t}");
    }

    #[test]
    fn lost_frames_are_counted_and_left_out() {
        let truth = path(30);
        let mut scorer = TrajectoryScorer::new("pose".into());
        for (i, p) in truth.iter().enumerate() {
            scorer.samples.push(Sample {
                stamp_ns: i as i64 * 100_000_000,
                tracked: (i != 4).then_some(*p),
                recorded: Some(*p),
            });
        }
        let r = scorer.report();
        assert_eq!(r["lost_frames"], 1);
        assert_eq!(r["frames_scored"], 29);
        assert!(r["ate_rmse_m"].as_f64().unwrap() < 1e-9);
        assert!(r["rpe_translation_m_per_s"].as_f64().unwrap() < 1e-9);
    }
}
