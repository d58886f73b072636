//! The synthetic camera: its path through the room and its per-frame color response
//! (auto exposure, white balance, a fixed color mix, contrast, gamma 2.2, 8 bits).
//!
//! The color pipeline of frame t, per pixel, is
//! `camera_linear = M_t * radiance` with `M_t = exposure_t * MIX * diag(gains_t)`
//! (stored as the frame's `color_transform`), then `v = max(v, 0)^contrast_t`, then
//! `v^(1 / 2.2)`, clipped to [0, 1] and rounded to 8 bits.

use super::scene::OBJECT_POSITION_F64;
use crate::types::Pose;
use glam::{DMat3, DQuat, DVec3, Vec3};

/// The fewest frames over which the camera's color schedule changes slowly enough for
/// `color.compensate` to follow it. The exposure sweeps 0.5x to 2x and back over the
/// whole recording, whatever its length, so a shorter one changes it faster: measured
/// on the built-in room at 640x480, compensation's median error against the truth is
/// 3.1 % at 10 frames and 0.5-0.8 % from 15 frames on, and what it costs shows in every
/// stage after it: `filter.axis_aligned`'s gain (unfiltered over filtered MSE) on the
/// last frame of a 10-frame recording is 8.4x, against 11.4x on the same frame
/// (same pose, same noise) of the 30-frame recording and 12.5x on frame 14 of 15-,
/// 20- and 30-frame recordings. Replaying 10 frames of a longer recording is fine
/// (frames 20..30: 10.0x): the filter itself needs no warm-up beyond its one previous
/// frame. `relume synth` warns below this length.
pub const STEADY_COLOR_FRAMES: usize = 15;

/// A fixed color-mixing matrix near identity (row-major, rows sum to 1 so grey stays
/// grey): the camera's color-correction matrix. As in a real image signal processor, the
/// white-balance gains act on the raw channels before it, so a white-balance change is
/// not a per-channel gain of the output (`MIX * diag(g) * MIX^-1` has off-diagonal terms).
pub const MIX: [f32; 9] = [0.90, 0.08, 0.02, 0.05, 0.90, 0.05, 0.02, 0.10, 0.88];

/// Display gamma of the stored 8-bit color.
pub const GAMMA: f32 = 2.2;

/// The true camera-to-world pose at `time_s` seconds from the start: an orbit of about
/// 1.8 m radius around the object spot at 1.2-1.5 m height, about 2.7 cm per frame at
/// 30 fps, looking at a point a little above the object spot, with gentle changes of
/// radius, height, look-at point and roll. It stays at least 0.5 m from the walls and
/// the tops of the furniture.
pub fn camera_pose(time_s: f64) -> Pose {
    let t = time_s;
    let angle = 2.3 + 0.45 * t;
    let radius = 1.8 + 0.1 * (0.5 * t + 0.3).sin();
    let height = 1.35 + 0.12 * (0.8 * t).sin();
    let eye = DVec3::new(radius * angle.cos(), height, radius * angle.sin());
    let object = OBJECT_POSITION_F64;
    let target = object
        + DVec3::new(
            0.15 * (0.6 * t).sin(),
            0.2 + 0.1 * (0.45 * t + 1.0).sin(),
            0.15 * (0.7 * t + 0.5).cos(),
        );
    let roll = 0.03 * (0.9 * t).sin();
    Pose::from_parts(eye, look_at(eye, target) * DQuat::from_rotation_z(roll))
}

/// The camera-to-world rotation of a camera at `eye` looking at `target` with world +y
/// up: camera z = forward, x = right, y = down (image rows go down).
pub fn look_at(eye: DVec3, target: DVec3) -> DQuat {
    let forward = (target - eye).normalize();
    let right = forward.cross(DVec3::Y).normalize();
    let down = forward.cross(right);
    DQuat::from_mat3(&DMat3::from_cols(right, down, forward))
}

/// The camera's color settings of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColorResponse {
    /// Auto-exposure gain.
    pub exposure: f32,
    /// White-balance gains of red, green and blue.
    pub gains: [f32; 3],
    /// Contrast exponent applied to the linear values (1 = none).
    pub contrast: f32,
}

impl ColorResponse {
    /// The settings of `frame` of `frames`. Exposure moves smoothly (in log space) from
    /// the geometric middle of `exposure_range` up to its top about a third of the way
    /// through and down to its bottom at the last frame, so every sequence of two or more
    /// frames reaches both ends. White-balance gains are `1 + white_balance * sin(...)`
    /// with a different slow phase per channel; the contrast exponent is
    /// `1 + contrast * sin(...)` (exactly 1 when `contrast` is 0).
    pub fn for_frame(
        frame: usize,
        frames: usize,
        exposure_range: (f32, f32),
        white_balance: f32,
        contrast: f32,
    ) -> ColorResponse {
        let u = if frames > 1 {
            frame as f64 / (frames - 1) as f64
        } else {
            0.0
        };
        let wave = |cycles: f64, phase: f64| (std::f64::consts::TAU * (cycles * u + phase)).sin();
        let gains = [(0.7, 0.1), (0.45, 0.6), (0.85, 0.35)]
            .map(|(cycles, phase)| (1.0 + white_balance as f64 * wave(cycles, phase)) as f32);
        let contrast = if contrast == 0.0 {
            1.0
        } else {
            (1.0 + contrast as f64 * wave(0.8, 0.2)) as f32
        };
        ColorResponse {
            exposure: exposure_at(frame, frames, exposure_range),
            gains,
            contrast,
        }
    }

    /// `M = exposure * MIX * diag(gains)`, row-major.
    pub fn color_transform(&self) -> [f32; 9] {
        std::array::from_fn(|i| self.exposure * MIX[i] * self.gains[i % 3])
    }
}

/// The auto-exposure gain of `frame` of `frames` (see [`ColorResponse::for_frame`]).
pub fn exposure_at(frame: usize, frames: usize, range: (f32, f32)) -> f32 {
    let (low, high) = ((range.0 as f64).ln(), (range.1 as f64).ln());
    let middle = 0.5 * (low + high);
    let ease =
        |a: f64, b: f64, s: f64| a + (b - a) * (0.5 - 0.5 * (std::f64::consts::PI * s).cos());
    if frames < 2 {
        return middle.exp() as f32;
    }
    let last = frames - 1;
    let peak = if frames == 2 {
        0
    } else {
        ((last as f64 / 3.0).round() as usize).clamp(1, last - 1)
    };
    // The ends are returned as given, free of ln/exp rounding.
    if frame == peak {
        return range.1;
    }
    if frame >= last {
        return range.0;
    }
    let level = if frame < peak {
        ease(middle, high, frame as f64 / peak as f64)
    } else {
        ease(high, low, (frame - peak) as f64 / (last - peak) as f64)
    };
    level.exp() as f32
}

/// One 8-bit level from a camera-linear value: contrast exponent, gamma 1/2.2, clip,
/// round. Negative and NaN values give 0.
#[inline]
pub fn encode_level(linear: f32, contrast: f32) -> u8 {
    let v = linear.max(0.0);
    let v = if contrast == 1.0 { v } else { v.powf(contrast) };
    let v = v.powf(1.0 / GAMMA).min(1.0);
    (v * 255.0).round() as u8
}

/// The 8-bit color of a pixel of scene `radiance` under the row-major `transform` and
/// `contrast` exponent.
#[inline]
pub fn camera_pixel(transform: &[f32; 9], contrast: f32, radiance: Vec3) -> [u8; 3] {
    let l = radiance.to_array();
    std::array::from_fn(|c| {
        let row = &transform[3 * c..3 * c + 3];
        encode_level(row[0] * l[0] + row[1] * l[1] + row[2] * l[2], contrast)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_model_maps_known_values() {
        assert_eq!(encode_level(0.0, 1.0), 0);
        assert_eq!(encode_level(-1.0, 1.0), 0);
        assert_eq!(encode_level(f32::NAN, 1.0), 0);
        assert_eq!(encode_level(1.0, 1.0), 255);
        assert_eq!(encode_level(7.0, 1.3), 255);
        // 0.5^(1/2.2) = 0.7297 -> 186.
        assert_eq!(encode_level(0.5, 1.0), 186);
        // Contrast exponent 2: 0.5 -> 0.25 -> 0.5325 -> 136.
        assert_eq!(encode_level(0.5, 2.0), 136);
        let identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        assert_eq!(
            camera_pixel(&identity, 1.0, Vec3::new(0.5, 0.0, 2.0)),
            [186, 0, 255]
        );
        let swap = [0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5];
        assert_eq!(
            camera_pixel(&swap, 1.0, Vec3::new(0.5, 0.0, 1.0)),
            [0, 186, 186]
        );
    }

    #[test]
    fn transform_is_exposure_times_mix_times_gains() {
        let r = ColorResponse {
            exposure: 2.0,
            gains: [1.1, 1.0, 0.9],
            contrast: 1.0,
        };
        let m = r.color_transform();
        assert!((m[0] - 2.0 * MIX[0] * 1.1).abs() < 1e-6);
        assert!((m[5] - 2.0 * MIX[5] * 0.9).abs() < 1e-6);
        assert!((m[7] - 2.0 * MIX[7] * 1.0).abs() < 1e-6);
        for row in MIX.chunks(3) {
            assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn exposure_reaches_both_ends_smoothly_and_gains_stay_in_range() {
        for frames in [2usize, 3, 4, 7, 30, 301] {
            let e: Vec<f32> = (0..frames)
                .map(|i| exposure_at(i, frames, (0.5, 2.0)))
                .collect();
            let min = e.iter().cloned().fold(f32::INFINITY, f32::min);
            let max = e.iter().cloned().fold(0.0, f32::max);
            assert_eq!((min, max), (0.5, 2.0), "frames {frames}: {e:?}");
        }
        assert!((exposure_at(0, 1, (0.5, 2.0)) - 1.0).abs() < 1e-6);
        let e: Vec<f32> = (0..300).map(|i| exposure_at(i, 300, (0.5, 2.0))).collect();
        assert!(e.windows(2).all(|w| (w[1] / w[0]).ln().abs() < 0.03));
        for i in 0..100 {
            let r = ColorResponse::for_frame(i, 100, (0.5, 2.0), 0.2, 0.0);
            assert!(
                r.gains
                    .iter()
                    .all(|g| (0.8 - 1e-6..=1.2 + 1e-6).contains(g))
            );
            assert_eq!(r.contrast, 1.0);
            let c = ColorResponse::for_frame(i, 100, (0.5, 2.0), 0.2, 0.25).contrast;
            assert!((0.75 - 1e-6..=1.25 + 1e-6).contains(&c));
        }
    }

    #[test]
    fn camera_path_stays_in_the_room_looks_at_the_object_and_moves_a_few_cm_per_frame() {
        let mut previous: Option<Pose> = None;
        for i in 0..900 {
            let pose = camera_pose(i as f64 / 30.0);
            let eye = pose.translation();
            assert!(eye.x.abs() < 2.0 && eye.z.abs() < 2.0 && (1.1..1.6).contains(&eye.y));
            let forward = pose.rotation() * DVec3::Z;
            let to_object = (OBJECT_POSITION_F64 - eye).normalize();
            assert!(forward.dot(to_object) > 0.95);
            // Image rows go down: camera +y points roughly to world -y.
            assert!((pose.rotation() * DVec3::Y).y < -0.5);
            if let Some(p) = previous {
                let step = p.translation().distance(eye);
                assert!((0.01..0.05).contains(&step), "step {step}");
            }
            previous = Some(pose);
        }
    }
}
