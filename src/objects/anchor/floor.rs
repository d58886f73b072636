//! The floor of a recorded room, from depth samples with normals (world space).
//!
//! 1. The cameras' up (the mean of their image-up directions) is only a hint: a hand-held
//!    camera rolls and pitches. Samples whose normal lies within [`MAX_TILT_DEG`] of it
//!    face upwards; the mean of their normals is a better up, and the samples within
//!    [`LEVEL_DEG`] of that are the level ones (floor, table tops, seats).
//! 2. Heights along that up are sorted and scanned for horizontal planes: the densest
//!    window [`BAND_M`] thick is a plane, its samples (and those within
//!    [`SEPARATION_M`]) are set aside, and the scan repeats.
//! 3. The floor is the lowest of those planes that lies at least [`CLEARANCE_M`] below
//!    every camera and holds at least [`MIN_SHARE`] of the samples of the best-supported
//!    one, so that a table top filling the view does not win over the floor beside it,
//!    and stray samples below the floor do not count.
//! 4. The floor's samples are refitted by least squares (the plane fit of paper 000
//!    Sec. 5, [`crate::stages::plane_fit::fit::fit_plane`]).
//!
//! The hint fails for a camera rolled more than about [`MAX_TILT_DEG`] from upright, and
//! the floor must be visible in the frames used: both are reported as errors, not
//! guessed.

use crate::stages::plane_fit::fit::fit_plane;
use glam::Vec3;

/// How far (degrees) a sample's normal may lean from the cameras' up to count as
/// facing upwards.
pub const MAX_TILT_DEG: f32 = 35.0;
/// How far (degrees) a sample's normal may lean from the refined up to count as level.
pub const LEVEL_DEG: f32 = 12.0;
/// The thickness (metres) of the height window that finds a plane.
pub const BAND_M: f32 = 0.03;
/// Samples this close (metres) to a found plane's height are set aside with it.
pub const SEPARATION_M: f32 = 0.06;
/// How far (metres) below the lowest camera the floor must lie.
pub const CLEARANCE_M: f32 = 0.2;
/// The floor holds at least this share of the samples of the best-supported plane.
pub const MIN_SHARE: f32 = 0.25;
/// At most this many planes are looked for.
const MAX_PLANES: usize = 8;

/// A point on a real surface (world space, metres) with its unit normal, turned
/// towards the camera that saw it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub position: Vec3,
    pub normal: Vec3,
}

/// The floor plane: the points p with `normal . p = offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    /// Unit normal, pointing up (towards the cameras).
    pub normal: Vec3,
    pub offset: f32,
    /// The samples it was fitted to.
    pub samples: usize,
    /// The angle between its normal and the cameras' up, degrees.
    pub tilt_from_cameras_deg: f32,
}

impl Floor {
    /// Where the ray from `origin` along `direction` meets the floor in front of it,
    /// or `None` when it runs parallel to it or away from it.
    pub fn ray_hit(&self, origin: Vec3, direction: Vec3) -> Option<Vec3> {
        let along = self.normal.dot(direction);
        let t = (self.offset - self.normal.dot(origin)) / along;
        (t > 0.0 && t.is_finite()).then(|| origin + direction * t)
    }
}

/// Why no floor was found.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FloorError {
    #[error(
        "only {found} of {total} depth samples lie on level, upward-facing surfaces (within {MAX_TILT_DEG} degrees of the cameras' up); at least {needed} are needed"
    )]
    TooFewLevel {
        found: usize,
        total: usize,
        needed: usize,
    },
    #[error(
        "no level surface at least {CLEARANCE_M} m below the cameras holds {needed} depth samples (the best holds {best})"
    )]
    NoneBelowCameras { best: usize, needed: usize },
}

/// The fewest samples a floor may hold: 1 % of all samples, and at least 100.
pub fn needed_samples(total: usize) -> usize {
    (total / 100).max(100)
}

/// The floor of `points` seen from cameras at `cameras` whose image-up directions
/// average to `up_hint` (see the module's steps).
pub fn fit_floor(
    points: &[SurfacePoint],
    cameras: &[Vec3],
    up_hint: Vec3,
) -> Result<Floor, FloorError> {
    let needed = needed_samples(points.len());
    let hint = up_hint.normalize();
    let upward: Vec<&SurfacePoint> = points
        .iter()
        .filter(|p| p.normal.dot(hint) >= MAX_TILT_DEG.to_radians().cos())
        .collect();
    let too_few = |found: usize| FloorError::TooFewLevel {
        found,
        total: points.len(),
        needed,
    };
    if upward.len() < needed {
        return Err(too_few(upward.len()));
    }
    let up = mean_normal(&upward);
    let level: Vec<&SurfacePoint> = upward
        .into_iter()
        .filter(|p| p.normal.dot(up) >= LEVEL_DEG.to_radians().cos())
        .collect();
    if level.len() < needed {
        return Err(too_few(level.len()));
    }
    let up = mean_normal(&level);
    let mut heights: Vec<f32> = level.iter().map(|p| p.position.dot(up)).collect();
    heights.sort_by(f32::total_cmp);
    let ceiling = cameras
        .iter()
        .map(|c| c.dot(up))
        .fold(f32::INFINITY, f32::min)
        - CLEARANCE_M;
    let planes: Vec<(f32, usize)> = horizontal_planes(heights)
        .into_iter()
        .filter(|&(h, count)| h < ceiling && count >= needed)
        .collect();
    let best = planes.iter().map(|&(_, c)| c).max().unwrap_or(0);
    let Some(&(height, _)) = planes
        .iter()
        .filter(|&&(_, c)| c as f32 >= MIN_SHARE * best as f32)
        .min_by(|a, b| a.0.total_cmp(&b.0))
    else {
        return Err(FloorError::NoneBelowCameras { best, needed });
    };
    let on_floor: Vec<Vec3> = level
        .iter()
        .map(|p| p.position)
        .filter(|p| (p.dot(up) - height).abs() <= BAND_M)
        .collect();
    // Thousands of samples spread over metres: the fit is well conditioned; should it
    // not be, the level samples' mean normal and the window's height are the plane.
    let (normal, offset) = match fit_plane(&on_floor, 1e-6) {
        Ok(plane) => {
            let n = if plane.normal.dot(up) < 0.0 {
                -plane.normal
            } else {
                plane.normal
            };
            (n, n.dot(plane.centroid))
        }
        Err(_) => (up, height),
    };
    Ok(Floor {
        normal,
        offset,
        samples: on_floor.len(),
        tilt_from_cameras_deg: normal.dot(hint).clamp(-1.0, 1.0).acos().to_degrees(),
    })
}

/// The normalized mean of the samples' normals.
fn mean_normal(points: &[&SurfacePoint]) -> Vec3 {
    points
        .iter()
        .fold(Vec3::ZERO, |sum, p| sum + p.normal)
        .normalize()
}

/// The horizontal planes in sorted `heights`, as (height, samples): repeatedly the
/// densest window [`BAND_M`] thick (the lowest on a tie), its height the median of
/// the window, with the samples within [`SEPARATION_M`] of it set aside.
fn horizontal_planes(mut heights: Vec<f32>) -> Vec<(f32, usize)> {
    let mut planes = Vec::new();
    while planes.len() < MAX_PLANES && !heights.is_empty() {
        let (mut best_start, mut best_count, mut end) = (0, 0, 0);
        for start in 0..heights.len() {
            while end < heights.len() && heights[end] <= heights[start] + BAND_M {
                end += 1;
            }
            if end - start > best_count {
                (best_start, best_count) = (start, end - start);
            }
        }
        let height = heights[best_start + best_count / 2];
        let before = heights.len();
        heights.retain(|h| (h - height).abs() > SEPARATION_M);
        planes.push((height, before - heights.len()));
    }
    planes
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Vec2};

    /// Level samples on an `n` x `n` grid of `size` metres at height `y` (y up).
    fn patch(centre: Vec2, size: f32, y: f32, n: usize) -> Vec<SurfacePoint> {
        let mut points = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (s, t) = (i as f32 / n as f32 - 0.5, j as f32 / n as f32 - 0.5);
                // A little deterministic roughness, as depth noise gives.
                let wobble = 0.002 * ((i * 7 + j * 13) % 5) as f32;
                points.push(SurfacePoint {
                    position: Vec3::new(centre.x + s * size, y + wobble, centre.y + t * size),
                    normal: Vec3::new(0.02 * s, 1.0, -0.02 * t).normalize(),
                });
            }
        }
        points
    }

    /// Samples of a wall at x = `x`, facing -x.
    fn wall(x: f32, n: usize) -> Vec<SurfacePoint> {
        (0..n * n)
            .map(|k| SurfacePoint {
                position: Vec3::new(x, (k / n) as f32 * 2.5 / n as f32, (k % n) as f32 * 0.01),
                normal: Vec3::NEG_X,
            })
            .collect()
    }

    #[test]
    fn the_floor_wins_over_a_larger_table_top_above_it() {
        let mut points = patch(Vec2::new(0.0, 0.0), 3.0, 0.0, 40); // 1600 floor samples
        points.extend(patch(Vec2::new(0.5, 0.5), 1.0, 0.72, 70)); // 4900 on a table
        points.extend(wall(2.0, 60));
        let floor = fit_floor(&points, &[Vec3::new(0.0, 1.5, 2.0)], Vec3::Y).unwrap();
        assert!(floor.normal.abs_diff_eq(Vec3::Y, 1e-3), "{floor:?}");
        assert!((floor.offset - 0.004).abs() < 0.003, "{floor:?}");
        assert_eq!(floor.samples, 1600);
    }

    #[test]
    fn a_tilted_world_and_a_rolled_camera_still_find_the_floor() {
        // The same room in a world whose up is not +y, seen by cameras whose image-up
        // leans 25 degrees from the true up.
        let tilt = Mat3::from_rotation_x(0.7) * Mat3::from_rotation_z(-0.4);
        let mut points = patch(Vec2::ZERO, 3.0, 0.0, 50);
        points.extend(patch(Vec2::new(1.0, -1.0), 0.6, 0.45, 20));
        let points: Vec<SurfacePoint> = points
            .iter()
            .map(|p| SurfacePoint {
                position: tilt * p.position + Vec3::new(3.0, -1.0, 7.0),
                normal: tilt * p.normal,
            })
            .collect();
        let up = tilt * Vec3::Y;
        let hint = tilt * Vec3::new(25f32.to_radians().sin(), 25f32.to_radians().cos(), 0.0);
        let camera = up * 1.4 + Vec3::new(3.0, -1.0, 7.0);
        let floor = fit_floor(&points, &[camera], hint).unwrap();
        assert!(floor.normal.abs_diff_eq(up, 2e-3), "{floor:?} vs {up}");
        let on_floor = tilt * Vec3::new(0.3, 0.004, -0.2) + Vec3::new(3.0, -1.0, 7.0);
        assert!((floor.normal.dot(on_floor) - floor.offset).abs() < 0.003);
        assert!(
            (floor.tilt_from_cameras_deg - 25.0).abs() < 0.5,
            "{floor:?}"
        );
    }

    #[test]
    fn a_plane_above_the_cameras_or_too_few_samples_is_no_floor() {
        // Only a level surface at the cameras' own height (a shelf they look along).
        let points = patch(Vec2::ZERO, 2.0, 1.4, 30);
        let e = fit_floor(&points, &[Vec3::new(0.0, 1.5, 0.0)], Vec3::Y).unwrap_err();
        assert_eq!(
            e,
            FloorError::NoneBelowCameras {
                best: 0,
                needed: 100
            }
        );
        // Walls only.
        let e = fit_floor(&wall(1.0, 40), &[Vec3::new(0.0, 1.5, 0.0)], Vec3::Y).unwrap_err();
        assert_eq!(
            e,
            FloorError::TooFewLevel {
                found: 0,
                total: 1600,
                needed: 100
            }
        );
        assert_eq!(
            e.to_string(),
            "only 0 of 1600 depth samples lie on level, upward-facing surfaces (within 35 \
             degrees of the cameras' up); at least 100 are needed"
        );
    }

    #[test]
    fn stray_samples_below_the_floor_do_not_make_a_floor() {
        let mut points = patch(Vec2::ZERO, 3.0, 0.0, 40);
        // 120 samples of noise 0.5 m under the floor (a reflection, a depth artefact):
        // enough to pass the 1 % bar, far short of a quarter of the floor's.
        points.extend(patch(Vec2::ZERO, 0.5, -0.5, 11).into_iter().take(120));
        let floor = fit_floor(&points, &[Vec3::new(0.0, 1.5, 0.0)], Vec3::Y).unwrap();
        assert!(floor.offset.abs() < 0.01, "{floor:?}");
    }

    #[test]
    fn rays_meet_the_floor_only_in_front() {
        let floor = Floor {
            normal: Vec3::Y,
            offset: 0.0,
            samples: 1,
            tilt_from_cameras_deg: 0.0,
        };
        let eye = Vec3::new(0.0, 1.5, 0.0);
        let hit = floor.ray_hit(eye, Vec3::new(0.0, -1.0, -1.0)).unwrap();
        assert!(hit.abs_diff_eq(Vec3::new(0.0, 0.0, -1.5), 1e-6));
        assert_eq!(floor.ray_hit(eye, Vec3::new(0.0, 0.2, -1.0)), None);
        assert_eq!(floor.ray_hit(eye, Vec3::Z), None);
    }
}
