//! The floor of a recorded room, from depth samples with normals (world space).
//!
//! 1. The cameras' up (the mean of their image-up directions) is only a hint: a hand-held
//!    camera rolls and pitches. Samples whose normal lies within [`MAX_TILT_DEG`] of it
//!    face upwards; the normal most of them share (within [`MODE_DEG`]) is a better up,
//!    and the samples within [`LEVEL_DEG`] of their mean normal are the level ones
//!    (floor, table tops, seats).
//! 2. Heights along that up are sorted and scanned for horizontal planes: the densest
//!    window [`BAND_M`] thick is a plane, its samples (and those within
//!    [`SEPARATION_M`]) are set aside, and the scan repeats.
//! 3. The floor is the lowest of those planes that lies at least [`CLEARANCE_M`] below
//!    every camera and holds at least [`MIN_SHARE`] of the samples of the best-supported
//!    one, so that a table top filling the view does not win over the floor beside it,
//!    and stray samples below the floor do not count.
//! 4. The floor's samples are refitted by least squares (the plane fit of paper 000
//!    Sec. 5, [`crate::plane_fit::fit::fit_plane`]).
//!
//! The hint fails for a camera pitched or rolled more than about [`MAX_TILT_DEG`] from
//! upright, and the floor must be visible in the frames used: both are reported as
//! errors, not guessed.

use crate::plane_fit::fit::fit_plane;
use glam::Vec3;

/// How far (degrees) a sample's normal may lean from the cameras' image-up to count as
/// facing upwards: a camera pitched down at a desk or rolled this far still finds the
/// floor, while walls (90 degrees from the up of a camera that is not rolled) do not
/// count.
pub const MAX_TILT_DEG: f32 = 70.0;
/// Samples this close (degrees) to the most shared upward normal give the first up.
pub const MODE_DEG: f32 = 15.0;
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
        "only {found} of {total} depth samples lie on level, upward-facing surfaces (within {within_deg} degrees of {of}); at least {needed} are needed"
    )]
    TooFewLevel {
        found: usize,
        total: usize,
        needed: usize,
        within_deg: f32,
        /// "the cameras' up" or "the level surfaces' mean normal".
        of: &'static str,
    },
    #[error(
        "no level surface at least {CLEARANCE_M} m below the cameras holds {needed} depth samples (the largest below them holds {best_below}, the largest anywhere {best})"
    )]
    NoneBelowCameras {
        best_below: usize,
        best: usize,
        needed: usize,
    },
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
    let too_few = |found: usize, within_deg: f32, of: &'static str| FloorError::TooFewLevel {
        found,
        total: points.len(),
        needed,
        within_deg,
        of,
    };
    let upward: Vec<&SurfacePoint> = points
        .iter()
        .filter(|p| p.normal.dot(hint) >= MAX_TILT_DEG.to_radians().cos())
        .collect();
    if upward.len() < needed {
        return Err(too_few(upward.len(), MAX_TILT_DEG, "the cameras' up"));
    }
    // The directions many upward normals share (a wall seen by a pitched and rolled
    // camera may be in the cone too, with more samples than the floor; a mean would
    // lean towards it): the one nearest the cameras' up, then the level samples about it.
    let shared = nearest_shared_normal(&upward, hint, needed);
    let near = |p: &&SurfacePoint, deg: f32| p.normal.dot(shared) >= deg.to_radians().cos();
    let around: Vec<&SurfacePoint> = upward
        .iter()
        .copied()
        .filter(|p| near(p, MODE_DEG))
        .collect();
    let up = mean_normal(&around);
    let level: Vec<&SurfacePoint> = upward
        .into_iter()
        .filter(|p| p.normal.dot(up) >= LEVEL_DEG.to_radians().cos())
        .collect();
    if level.len() < needed {
        return Err(too_few(
            level.len(),
            LEVEL_DEG,
            "the level surfaces' mean normal",
        ));
    }
    let up = mean_normal(&level);
    let mut heights: Vec<f32> = level.iter().map(|p| p.position.dot(up)).collect();
    heights.sort_by(f32::total_cmp);
    let ceiling = cameras
        .iter()
        .map(|c| c.dot(up))
        .fold(f32::INFINITY, f32::min)
        - CLEARANCE_M;
    let all_planes = horizontal_planes(heights);
    let best_anywhere = all_planes.iter().map(|&(_, c)| c).max().unwrap_or(0);
    let below: Vec<(f32, usize)> = all_planes
        .into_iter()
        .filter(|&(h, _)| h < ceiling)
        .collect();
    let best_below = below.iter().map(|&(_, c)| c).max().unwrap_or(0);
    let Some(&(height, _)) = below
        .iter()
        .filter(|&&(_, c)| c >= needed && c as f32 >= MIN_SHARE * best_below as f32)
        .min_by(|a, b| a.0.total_cmp(&b.0))
    else {
        return Err(FloorError::NoneBelowCameras {
            best_below,
            best: best_anywhere,
            needed,
        });
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

/// Of the directions that many normals share, the nearest to `hint`. The directions:
/// repeatedly, of about 400 samples taken evenly, the normal with the most of about
/// 4000 others within [`MODE_DEG`] (the first on a tie), its samples then set aside;
/// those with at least `needed` samples (scaled to the subsample) and [`MIN_SHARE`] of
/// the best-supported one compete. A floor seen by a camera pitched by p is nearer the
/// camera's up than a wall beside it while the roll r keeps tan r < cos p (p = 60
/// degrees: r up to 26 degrees).
fn nearest_shared_normal(points: &[&SurfacePoint], hint: Vec3, needed: usize) -> Vec3 {
    let every = |n: usize| (points.len() / n).max(1);
    let cos = MODE_DEG.to_radians().cos();
    let mut sample: Vec<Vec3> = points
        .iter()
        .step_by(every(4000))
        .map(|p| p.normal)
        .collect();
    let needed = (needed * sample.len()).div_ceil(points.len());
    let candidates: Vec<Vec3> = points
        .iter()
        .step_by(every(400))
        .map(|p| p.normal)
        .collect();
    let mut directions: Vec<(usize, Vec3)> = Vec::new();
    while directions.len() < 4 {
        let mut best = (0, Vec3::ZERO);
        for &candidate in &candidates {
            let support = sample.iter().filter(|n| n.dot(candidate) >= cos).count();
            if support > best.0 {
                best = (support, candidate);
            }
        }
        if best.0 == 0 || best.0 < needed {
            break;
        }
        sample.retain(|n| n.dot(best.1) < cos);
        directions.push(best);
    }
    let most = directions.iter().map(|d| d.0).max().unwrap_or(0);
    directions
        .iter()
        .filter(|d| d.0 as f32 >= MIN_SHARE * most as f32)
        .max_by(|a, b| a.1.dot(hint).total_cmp(&b.1.dot(hint)))
        .map_or(hint, |d| d.1)
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
    fn a_camera_pitched_at_a_desk_and_rolled_towards_a_wall_finds_the_floor() {
        // A camera looking along -z, pitched down 60 degrees and rolled 20 towards
        // +x: its image-up lies 62 degrees from the true up and 70 from the normal of
        // the wall at its left, inside the 70-degree cone; the wall has more samples
        // there than the floor.
        let (pitch, roll) = (60f32.to_radians(), 20f32.to_radians());
        let level_up = Vec3::new(0.0, pitch.cos(), -pitch.sin());
        let hint = level_up * roll.cos() + Vec3::X * roll.sin() * 1.001;
        let mut points = patch(Vec2::ZERO, 2.0, 0.0, 40);
        points.extend((0..2500).map(|k| SurfacePoint {
            position: Vec3::new(-1.5, (k / 50) as f32 * 0.04, (k % 50) as f32 * 0.04 - 1.0),
            normal: Vec3::X,
        }));
        assert!(angle_between(Vec3::X, hint) < 70.0);
        let floor = fit_floor(&points, &[Vec3::new(0.0, 1.2, 1.0)], hint).unwrap();
        assert!(floor.normal.abs_diff_eq(Vec3::Y, 1e-3), "{floor:?}");
        assert_eq!(floor.samples, 1600);
    }

    fn angle_between(a: Vec3, b: Vec3) -> f32 {
        a.normalize().dot(b.normalize()).acos().to_degrees()
    }

    #[test]
    fn a_plane_above_the_cameras_or_too_few_samples_is_no_floor() {
        // Only a level surface at the cameras' own height (a shelf they look along).
        let points = patch(Vec2::ZERO, 2.0, 1.4, 30);
        let e = fit_floor(&points, &[Vec3::new(0.0, 1.5, 0.0)], Vec3::Y).unwrap_err();
        assert_eq!(
            e,
            FloorError::NoneBelowCameras {
                best_below: 0,
                best: 900,
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
                needed: 100,
                within_deg: 70.0,
                of: "the cameras' up"
            }
        );
        assert_eq!(
            e.to_string(),
            "only 0 of 1600 depth samples lie on level, upward-facing surfaces (within 70 \
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
