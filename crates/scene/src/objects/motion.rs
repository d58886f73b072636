//! How a virtual object moves from frame to frame ([`Motion`]): keyframes of translation
//! and rotation at frame numbers, or a constant velocity, and the object's pose at any
//! frame ([`Motion::pose_at`]).
//!
//! Keyframes interpolate translation linearly and rotation by slerp (the shortest arc
//! between the keyframes' rotations), and clamp outside the path: before the first
//! keyframe the object holds the first pose, after the last the last. A velocity moves
//! the object from its `translation` at frame 0 by `velocity` metres a frame, without
//! turning it. Both are measured in the frame the object is placed in: the world's, or
//! its anchor's (see [`super::anchor`]).
//!
//! Paper 000 rebuilds its object volume and impostor when an object moves (Sec. 6.2) and
//! paper 004 rotates its precomputed transfer with the object (eq. 11); the papers give no
//! path model, so this one is ours: the keyframe interpolation of animation tools.

use glam::{Mat3, Quat, Vec3};

/// Most keyframes an object may have.
pub const MAX_KEYFRAMES: usize = 4096;

/// One pose on an object's path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keyframe {
    /// The frame (index among the recording's frames) at which the object is here.
    pub frame: f64,
    pub translation: Vec3,
    /// Rotation angles about x, then y, then z, degrees (R = Rz Ry Rx, as
    /// [`super::ObjectSpec::rotation_deg`]).
    pub rotation_deg: Vec3,
}

/// A rigid pose: where the object's origin is and how it is turned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub translation: Vec3,
    pub rotation: Quat,
}

/// How an object moves.
#[derive(Clone, Debug, PartialEq)]
pub enum Motion {
    /// Through keyframes, in ascending frame order (at least one).
    Keyframes(Vec<Keyframe>),
    /// From `start` at frame 0, `per_frame` metres each frame, turned by `rotation_deg`.
    Velocity {
        start: Vec3,
        per_frame: Vec3,
        rotation_deg: Vec3,
    },
}

/// The rotation R = Rz Ry Rx of angles in degrees, as a unit quaternion.
pub fn rotation_of_degrees(deg: Vec3) -> Quat {
    let r = deg * (std::f32::consts::PI / 180.0);
    Quat::from_rotation_z(r.z) * Quat::from_rotation_y(r.y) * Quat::from_rotation_x(r.x)
}

impl Motion {
    /// Checks the keyframes: at least one, at most [`MAX_KEYFRAMES`], frames finite,
    /// non-negative and strictly ascending, poses finite.
    pub fn check(&self) -> Result<(), String> {
        match self {
            Motion::Keyframes(keys) => {
                if keys.is_empty() || keys.len() > MAX_KEYFRAMES {
                    return Err(format!(
                        "a path needs 1 to {MAX_KEYFRAMES} keyframes, got {}",
                        keys.len()
                    ));
                }
                for (i, k) in keys.iter().enumerate() {
                    if !(k.frame.is_finite() && k.frame >= 0.0) {
                        return Err(format!("keyframe {i}'s frame {} is not a frame", k.frame));
                    }
                    if !k.translation.is_finite() || !k.rotation_deg.is_finite() {
                        return Err(format!("keyframe {i}'s pose is not finite"));
                    }
                    if i > 0 && k.frame <= keys[i - 1].frame {
                        return Err(format!(
                            "keyframes must be in ascending frame order: frame {} follows frame {}",
                            k.frame,
                            keys[i - 1].frame
                        ));
                    }
                    if i > 0 {
                        let turn = (k.rotation_deg - keys[i - 1].rotation_deg).abs();
                        if turn.max_element() >= 180.0 {
                            return Err(format!(
                                "keyframes {} and {i} turn by {} degrees about one axis: a rotation between two keyframes takes the shorter way, so turns of 180 degrees or more need keyframes in between",
                                i - 1,
                                turn.max_element()
                            ));
                        }
                    }
                }
                Ok(())
            }
            Motion::Velocity {
                start,
                per_frame,
                rotation_deg,
            } => match start.is_finite() && per_frame.is_finite() && rotation_deg.is_finite() {
                true => Ok(()),
                false => Err("a velocity's start, speed and rotation must be finite".into()),
            },
        }
    }

    /// The pose at `frame`: interpolated between the keyframes around it (linear
    /// translation, slerp rotation), the first or last keyframe's outside them; or
    /// `start + frame * per_frame` for a velocity.
    pub fn pose_at(&self, frame: f64) -> Pose {
        match self {
            Motion::Velocity {
                start,
                per_frame,
                rotation_deg,
            } => Pose {
                translation: *start + *per_frame * frame as f32,
                rotation: rotation_of_degrees(*rotation_deg),
            },
            Motion::Keyframes(keys) => {
                let pose = |k: &Keyframe| Pose {
                    translation: k.translation,
                    rotation: rotation_of_degrees(k.rotation_deg),
                };
                // The first keyframe after `frame`; clamp outside the path.
                let next = keys.partition_point(|k| k.frame <= frame);
                if next == 0 {
                    return pose(&keys[0]);
                }
                if next == keys.len() {
                    return pose(&keys[keys.len() - 1]);
                }
                let (a, b) = (&keys[next - 1], &keys[next]);
                if frame == a.frame {
                    // On the keyframe itself, exactly its pose.
                    return pose(a);
                }
                let s = ((frame - a.frame) / (b.frame - a.frame)) as f32;
                let (pa, pb) = (pose(a), pose(b));
                // a + (b - a) s, not a (1 - s) + b s: a pose held between two keyframes
                // stays the same bits, so that nothing counts as moved.
                Pose {
                    translation: pa.translation + (pb.translation - pa.translation) * s,
                    // q and -q are the same rotation.
                    rotation: match pa.rotation == pb.rotation || pa.rotation == -pb.rotation {
                        true => pa.rotation,
                        false => pa.rotation.slerp(pb.rotation, s).normalize(),
                    },
                }
            }
        }
    }

    /// The linear part R (scale I) at `frame`.
    pub fn linear_at(&self, frame: f64, scale: f32) -> Mat3 {
        Mat3::from_quat(self.pose_at(frame).rotation) * Mat3::from_diagonal(Vec3::splat(scale))
    }

    /// The frames where the path's poses are extreme: every keyframe's (between them
    /// the positions lie on the segments joining them), or, for a velocity, frame 0
    /// and `last_frame`.
    pub fn extreme_frames(&self, last_frame: f64) -> Vec<f64> {
        match self {
            Motion::Keyframes(keys) => keys.iter().map(|k| k.frame).collect(),
            Motion::Velocity { .. } => vec![0.0, last_frame],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(frame: f64, x: f32, yaw: f32) -> Keyframe {
        Keyframe {
            frame,
            translation: Vec3::new(x, 0.1, 0.0),
            rotation_deg: Vec3::new(0.0, yaw, 0.0),
        }
    }

    #[test]
    fn keyframes_interpolate_linearly_and_by_slerp() {
        let path = Motion::Keyframes(vec![key(10.0, -0.5, 0.0), key(30.0, 0.5, 90.0)]);
        path.check().unwrap();
        let mid = path.pose_at(20.0);
        assert!(mid.translation.abs_diff_eq(Vec3::new(0.0, 0.1, 0.0), 1e-6));
        // Halfway between 0 and 90 degrees about y: 45 degrees, by slerp.
        let want = Quat::from_rotation_y(45f32.to_radians());
        assert!(mid.rotation.abs_diff_eq(want, 1e-6), "{:?}", mid.rotation);
        let quarter = path.pose_at(15.0);
        assert!(
            quarter
                .translation
                .abs_diff_eq(Vec3::new(-0.25, 0.1, 0.0), 1e-6)
        );
        let (axis, angle) = quarter.rotation.to_axis_angle();
        assert!(axis.abs_diff_eq(Vec3::Y, 1e-5) && (angle.to_degrees() - 22.5).abs() < 1e-3);
        // Slerp turns at a constant rate, also on a wide turn, where a normalized linear
        // blend of the quaternions would lag (34.5 degrees at a quarter of 160).
        let wide = Motion::Keyframes(vec![key(0.0, 0.0, 0.0), key(4.0, 0.0, 160.0)]);
        let angle = wide.pose_at(1.0).rotation.to_axis_angle().1.to_degrees();
        assert!((angle - 40.0).abs() < 1e-3, "{angle}");
    }

    #[test]
    fn a_path_clamps_outside_its_keyframes_and_hits_them_exactly() {
        let path = Motion::Keyframes(vec![
            key(5.0, 1.0, 0.0),
            key(10.0, 2.0, 30.0),
            key(12.0, 0.0, 60.0),
        ]);
        for (frame, x) in [(0.0, 1.0), (5.0, 1.0), (10.0, 2.0), (12.0, 0.0), (1e6, 0.0)] {
            assert_eq!(path.pose_at(frame).translation.x, x, "frame {frame}");
        }
        assert_eq!(path.pose_at(11.0).translation.x, 1.0);
        let single = Motion::Keyframes(vec![key(3.0, 0.7, 10.0)]);
        assert_eq!(single.pose_at(0.0), single.pose_at(100.0));
        // On a keyframe, exactly its pose.
        let turned = Motion::Keyframes(vec![key(0.0, 0.0, 30.0), key(10.0, 0.0, 60.0)]);
        let pose = turned.pose_at(0.0);
        assert_eq!(
            pose.rotation,
            rotation_of_degrees(Vec3::new(0.0, 30.0, 0.0))
        );
        let full = Motion::Keyframes(vec![
            key(0.0, 0.0, 0.0),
            key(10.0, 0.0, 179.0),
            key(20.0, 0.0, 358.0),
        ]);
        assert!(full.check().is_ok());
        // A pose held between keyframes is the same bits at every frame.
        let held = Motion::Keyframes(vec![key(0.0, 0.1333, 17.0), key(40.0, 0.1333, 17.0)]);
        for frame in [1.0, 13.0, 29.0, 39.5] {
            assert_eq!(held.pose_at(frame), held.pose_at(0.0), "frame {frame}");
        }
    }

    #[test]
    fn keyframe_rotation_matches_the_objects_euler_convention() {
        let deg = Vec3::new(20.0, -35.0, 70.0);
        let r = deg * (std::f32::consts::PI / 180.0);
        let euler =
            Mat3::from_rotation_z(r.z) * Mat3::from_rotation_y(r.y) * Mat3::from_rotation_x(r.x);
        let path = Motion::Keyframes(vec![Keyframe {
            frame: 0.0,
            translation: Vec3::ZERO,
            rotation_deg: deg,
        }]);
        assert!(path.linear_at(0.0, 1.0).abs_diff_eq(euler, 1e-6));
        assert!(path.linear_at(0.0, 2.0).abs_diff_eq(euler * 2.0, 1e-6));
    }

    #[test]
    fn a_velocity_moves_the_object_from_its_start() {
        let v = Motion::Velocity {
            start: Vec3::new(-0.5, 0.09, 0.0),
            per_frame: Vec3::new(1.0 / 30.0, 0.0, 0.0),
            rotation_deg: Vec3::ZERO,
        };
        assert_eq!(v.pose_at(0.0).translation, Vec3::new(-0.5, 0.09, 0.0));
        assert!(
            v.pose_at(30.0)
                .translation
                .abs_diff_eq(Vec3::new(0.5, 0.09, 0.0), 1e-6)
        );
    }

    #[test]
    fn bad_keyframes_say_what_is_wrong() {
        let e = Motion::Keyframes(vec![key(3.0, 0.0, 0.0), key(3.0, 1.0, 0.0)])
            .check()
            .unwrap_err();
        assert_eq!(
            e,
            "keyframes must be in ascending frame order: frame 3 follows frame 3"
        );
        let e = Motion::Keyframes(vec![]).check().unwrap_err();
        assert_eq!(e, "a path needs 1 to 4096 keyframes, got 0");
        let e = Motion::Keyframes(vec![key(0.0, 0.0, 0.0), key(9.0, 0.0, 270.0)])
            .check()
            .unwrap_err();
        assert_eq!(
            e,
            "keyframes 0 and 1 turn by 270 degrees about one axis: a rotation between two \
             keyframes takes the shorter way, so turns of 180 degrees or more need keyframes \
             in between"
        );
        let e = Motion::Keyframes(vec![key(f64::NAN, 0.0, 0.0)])
            .check()
            .unwrap_err();
        assert_eq!(e, "keyframe 0's frame NaN is not a frame");
    }
}
