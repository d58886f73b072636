//! The real surface seen at one pixel: a least-squares plane in inverse depth (see
//! [`fit_inverse_depth`]) through the depth samples of a small window around it, and
//! the point where the pixel's view ray meets that plane. A
//! single depth sample would do for the point but not for the normal, and a hole in
//! the depth at the pixel itself is common; the window covers both.
//!
//! The samples used are those connected to the one nearest the pixel by steps between
//! neighbouring pixels of at most [`STEP_TOLERANCE_M`] plus [`STEP_TOLERANCE_SHARE`] of
//! the depth: a slanted floor changes smoothly from pixel to pixel, while the step to
//! the object behind or to a table's side is left out.

use glam::Vec3;
use relume_base::pinhole::Pinhole;
use relume_base::raster::DepthImage;

/// The largest depth step (metres, plus a share of the depth) between neighbouring
/// pixels of one surface.
pub const STEP_TOLERANCE_M: f32 = 0.02;
/// See [`STEP_TOLERANCE_M`].
pub const STEP_TOLERANCE_SHARE: f32 = 0.05;

/// A plane through the surface seen along a view ray, in the camera's space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceFit {
    /// Where the view ray meets the fitted plane (camera space, metres).
    pub point: Vec3,
    /// Unit normal, facing the camera.
    pub normal: Vec3,
    /// Depth samples the plane was fitted to.
    pub samples: usize,
    /// The side of the square window, in depth pixels.
    pub window: u32,
    /// The share of the depth samples in the small window around the pixel that lie on
    /// this surface: well below 1 at a depth edge, where the pixel may sit on the
    /// surface the user did not mean.
    pub on_surface_share: f32,
}

/// Why no surface was found along a view ray.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SurfaceError {
    #[error("the pixel falls outside the {width}x{height} depth image")]
    OutsideDepthImage { width: u32, height: u32 },
    #[error(
        "the depth image has {found} usable samples in the {window}x{window} window around the pixel, fewer than the {needed} a plane needs"
    )]
    TooFewSamples {
        found: usize,
        needed: usize,
        window: u32,
    },
    #[error("the depth samples around the pixel lie on a line, not a surface")]
    Degenerate,
    #[error(
        "the surface there is seen edge-on ({angle_deg:.0} degrees from facing the camera): its plane is not measured well enough to stand an object on"
    )]
    Grazing { angle_deg: f32 },
}

/// The window around the pixel reaches about this far (metres) on the surface, within
/// 1/80 and 1/20 of the image's width: depth noise grows with distance, and the normal
/// of a plane is only as good as the extent it is fitted over.
pub const WINDOW_RADIUS_M: f32 = 0.1;
/// The window's samples within 2 robust standard deviations of the plane (those of the
/// seed window's residuals), and at least this far (metres), refine it.
pub const MIN_OUTLIER_M: f32 = 0.005;
/// How many times the plane is refined.
const REFINEMENTS: usize = 3;

/// The most a surface may turn away from the view ray (degrees) and still be used.
pub const MAX_GRAZING_DEG: f32 = 80.0;

/// The surface of `depth` (metres, 0 = none; seen by `camera`) along the camera-space
/// view `ray` (z = 1): a plane through the samples of a window about 1/40 of the
/// image wide around the ray's pixel.
pub fn surface_at(
    depth: &DepthImage,
    camera: &Pinhole,
    ray: Vec3,
) -> Result<SurfaceFit, SurfaceError> {
    let (width, height) = (depth.width, depth.height);
    let Some((cu, cv)) = camera.pixel_of(ray) else {
        return Err(SurfaceError::OutsideDepthImage { width, height });
    };
    // A seed plane from a small window, then a window about 2 * WINDOW_RADIUS_M across
    // on the surface (within pixel bounds), of which the samples near the plane refine
    // it: a large window alone would mix in the surfaces beyond an edge, which depth
    // crosses continuously (a floor meeting a wall, a box's top meeting its side).
    let (min_radius, max_radius) = ((width / 80).max(2), (width / 20).max(2));
    let seed = connected_samples(depth, (cu, cv), min_radius);
    let needed = ((min_radius * 2 + 1).pow(2) as usize / 4).max(6);
    if seed.len() < needed {
        return Err(SurfaceError::TooFewSamples {
            found: seed.len(),
            needed,
            window: 2 * min_radius + 1,
        });
    }
    let valid_near = {
        let (u0, v0) = (cu.saturating_sub(min_radius), cv.saturating_sub(min_radius));
        let (u1, v1) = (
            (cu + min_radius).min(width - 1),
            (cv + min_radius).min(height - 1),
        );
        (v0..=v1)
            .flat_map(|v| (u0..=u1).map(move |u| (u, v)))
            .filter(|&(u, v)| {
                let z = depth.data[(v * width + u) as usize];
                z > 0.0 && z.is_finite()
            })
            .count()
    };
    let on_surface_share = seed.len() as f32 / valid_near as f32;
    let mut plane = fit_inverse_depth(&seed, camera).ok_or(SurfaceError::Degenerate)?;
    let z = seed[0].2;
    let radius = ((WINDOW_RADIUS_M * camera.fx / z).round() as u32).clamp(min_radius, max_radius);
    let window = connected_samples(depth, (cu, cv), radius);
    let residual = |plane: Vec3, &(u, v, z): &(u32, u32, f32)| {
        (z - 1.0 / plane.dot(camera.ray(u as f32, v as f32))).abs()
    };
    let mut samples = seed.len();
    for _ in 0..REFINEMENTS {
        let mut seed_residuals: Vec<f32> = seed.iter().map(|s| residual(plane, s)).collect();
        seed_residuals.sort_by(f32::total_cmp);
        let bound = (2.0 * 1.4826 * seed_residuals[seed_residuals.len() / 2]).max(MIN_OUTLIER_M);
        let near: Vec<_> = window
            .iter()
            .copied()
            .filter(|s| residual(plane, s) <= bound)
            .collect();
        match fit_inverse_depth(&near, camera) {
            Some(refined) if near.len() >= needed => (plane, samples) = (refined, near.len()),
            _ => break,
        }
    }
    let window = 2 * radius + 1;
    // 1 / z = plane . ray for a ray with z = 1: the plane's normal, away from the camera.
    let normal = -plane.normalize();
    let facing = normal.dot(-ray.normalize()).clamp(-1.0, 1.0);
    let angle_deg = facing.acos().to_degrees();
    if angle_deg > MAX_GRAZING_DEG {
        return Err(SurfaceError::Grazing { angle_deg });
    }
    let t = 1.0 / plane.dot(ray);
    Ok(SurfaceFit {
        point: ray * t,
        normal,
        samples,
        window,
        on_surface_share,
    })
}

/// The plane through depth samples (u, v, z) as the vector q with 1 / z = q . ray(u, v)
/// for the view ray with z = 1: a plane n . p = d gives q = n / d. Inverse depth is
/// linear in the pixel coordinates, which are exact, so least squares on it is not
/// biased by depth noise the way a fit of back-projected points is (their x and y
/// carry the depth's error along the view ray); and a depth camera's noise is close to
/// uniform in inverse depth (disparity). `None` for collinear samples.
pub fn fit_inverse_depth(samples: &[(u32, u32, f32)], camera: &Pinhole) -> Option<Vec3> {
    // Normal equations of w = a x + b y + c in the normalized coordinates, in f64 and
    // about the samples' mean, which keeps them well conditioned.
    let coordinates = |&(u, v, z): &(u32, u32, f32)| {
        let r = camera.ray(u as f32, v as f32).as_dvec3();
        (r.x, r.y, 1.0 / z as f64)
    };
    let n = samples.len() as f64;
    let (mx, my, mw) = samples
        .iter()
        .map(coordinates)
        .fold((0.0, 0.0, 0.0), |s, c| {
            (s.0 + c.0 / n, s.1 + c.1 / n, s.2 + c.2 / n)
        });
    let (mut sxx, mut sxy, mut syy, mut sxw, mut syw) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for c in samples.iter().map(coordinates) {
        let (x, y, w) = (c.0 - mx, c.1 - my, c.2 - mw);
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        sxw += x * w;
        syw += y * w;
    }
    let det = sxx * syy - sxy * sxy;
    // Written so that NaN sums count as degenerate too.
    let well_conditioned = det > 1e-9 * (sxx + syy).powi(2);
    if !well_conditioned {
        return None;
    }
    let a = (sxw * syy - syw * sxy) / det;
    let b = (syw * sxx - sxw * sxy) / det;
    let c = mw - a * mx - b * my;
    let q = glam::DVec3::new(a, b, c).as_vec3();
    q.is_finite().then_some(q)
}

/// The samples (u, v, depth) of the window of `radius` around `centre` that are
/// connected, through 4-neighbours within the step tolerance, to the valid sample
/// nearest the centre (the first in row order on a tie); empty when the window has none.
fn connected_samples(depth: &DepthImage, centre: (u32, u32), radius: u32) -> Vec<(u32, u32, f32)> {
    let (width, height) = (depth.width, depth.height);
    let (u0, v0) = (
        centre.0.saturating_sub(radius),
        centre.1.saturating_sub(radius),
    );
    let (u1, v1) = (
        (centre.0 + radius).min(width - 1),
        (centre.1 + radius).min(height - 1),
    );
    let at = |u: u32, v: u32| depth.data[(v * width + u) as usize];
    let valid = |z: f32| z > 0.0 && z.is_finite();
    let distance = |u: u32, v: u32| u.abs_diff(centre.0).pow(2) + v.abs_diff(centre.1).pow(2);
    let start = (v0..=v1)
        .flat_map(|v| (u0..=u1).map(move |u| (u, v)))
        .filter(|&(u, v)| valid(at(u, v)))
        .min_by_key(|&(u, v)| distance(u, v));
    let Some(start) = start else {
        return Vec::new();
    };
    let side = (u1 - u0 + 1) as usize;
    let mut seen = vec![false; side * (v1 - v0 + 1) as usize];
    let index = |u: u32, v: u32| (v - v0) as usize * side + (u - u0) as usize;
    seen[index(start.0, start.1)] = true;
    let mut queue = std::collections::VecDeque::from([start]);
    let mut found = Vec::new();
    while let Some((u, v)) = queue.pop_front() {
        let z = at(u, v);
        found.push((u, v, z));
        let neighbours = [
            (u > u0).then(|| (u - 1, v)),
            (u < u1).then(|| (u + 1, v)),
            (v > v0).then(|| (u, v - 1)),
            (v < v1).then(|| (u, v + 1)),
        ];
        for (nu, nv) in neighbours.into_iter().flatten() {
            let nz = at(nu, nv);
            let step = STEP_TOLERANCE_M + STEP_TOLERANCE_SHARE * z.min(nz);
            if !seen[index(nu, nv)] && valid(nz) && (nz - z).abs() <= step {
                seen[index(nu, nv)] = true;
                queue.push_back((nu, nv));
            }
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_recording::Intrinsics;

    fn camera() -> Pinhole {
        Pinhole::new(&Intrinsics::PRIMESENSE, 160, 120)
    }

    /// The depth image of the plane `normal . p = offset` (camera space), with the
    /// pixels where `hole` holds left empty.
    fn plane_depth(normal: Vec3, offset: f32, hole: impl Fn(u32, u32) -> bool) -> DepthImage {
        let cam = camera();
        let mut depth = DepthImage::zeroed(cam.width, cam.height);
        for v in 0..cam.height {
            for u in 0..cam.width {
                let ray = cam.ray(u as f32, v as f32);
                let z = offset / normal.dot(ray);
                if !hole(u, v) && z > 0.0 {
                    depth.data[(v * cam.width + u) as usize] = z;
                }
            }
        }
        depth
    }

    #[test]
    fn a_tilted_plane_gives_its_normal_and_the_point_on_the_ray_even_through_a_hole() {
        // A floor 1.2 m below a camera pitched down: in camera space (y down) the plane
        // n . p = 1.2 with n turned towards +y and +z.
        let n = Vec3::new(0.1, 0.8, 0.4).normalize();
        let depth = plane_depth(n, 1.2, |u, v| u.abs_diff(100) < 2 && v.abs_diff(90) < 2);
        let ray = camera().ray(100.0, 90.0);
        let fit = surface_at(&depth, &camera(), ray).unwrap();
        assert!(fit.normal.abs_diff_eq(-n, 1e-4), "{fit:?}");
        let expected = ray * (1.2 / n.dot(ray));
        assert!(
            fit.point.abs_diff_eq(expected, 1e-4),
            "{fit:?} vs {expected}"
        );
        // 0.1 m at about 1.7 m is 7 pixels each way; every sample but the hole's is on
        // the plane.
        assert_eq!(fit.window, 15);
        assert_eq!(fit.samples, 15 * 15 - 9);
    }

    #[test]
    fn samples_across_an_edge_are_left_out() {
        // A wall 2 m away with a box face 0.5 m in front of it over the left columns.
        let cam = camera();
        let mut depth = plane_depth(Vec3::Z, 2.0, |_, _| false);
        for v in 0..cam.height {
            for u in 0..79 {
                depth.data[(v * cam.width + u) as usize] = 1.5;
            }
        }
        let fit = surface_at(&depth, &cam, cam.ray(80.0, 60.0)).unwrap();
        assert!((fit.point.z - 2.0).abs() < 1e-4, "{fit:?}");
        assert_eq!(
            fit.on_surface_share,
            20.0 / 25.0,
            "one column of five is the box's"
        );
        // Right at the edge, two columns of the 5 x 5 samples are the box's: the
        // placement says the pixel lies at an edge.
        let fit = surface_at(&depth, &cam, cam.ray(79.0, 60.0)).unwrap();
        assert!((fit.point.z - 2.0).abs() < 1e-4, "{fit:?}");
        assert_eq!(fit.on_surface_share, 15.0 / 25.0);
        assert!(fit.normal.abs_diff_eq(Vec3::NEG_Z, 1e-4));
    }

    #[test]
    fn no_depth_or_no_pixel_is_an_error_saying_which() {
        let cam = camera();
        let depth = plane_depth(Vec3::Z, 2.0, |u, _| u < 40);
        let e = surface_at(&depth, &cam, cam.ray(20.0, 60.0)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the depth image has 0 usable samples in the 5x5 window around the pixel, fewer than the 6 a plane needs"
        );
        let e = surface_at(&depth, &cam, cam.ray(200.0, 60.0)).unwrap_err();
        assert_eq!(
            e,
            SurfaceError::OutsideDepthImage {
                width: 160,
                height: 120
            }
        );
    }

    #[test]
    fn a_surface_seen_edge_on_is_refused() {
        // A plane whose normal is 84 degrees from the view ray at the image centre.
        let a = 84f32.to_radians();
        let n = Vec3::new(a.sin(), 0.0, a.cos());
        let depth = plane_depth(n, 0.5 * a.cos(), |_, _| false);
        let cam = camera();
        let e = surface_at(&depth, &cam, cam.ray(cam.cx, cam.cy)).unwrap_err();
        assert!(
            matches!(e, SurfaceError::Grazing { angle_deg } if angle_deg > 80.0),
            "{e}"
        );
    }
}
