//! A small triangle depth rasterizer for the virtual objects: the camera's G-buffer of
//! virtual triangles (paper 004 Sec. 5, first pass) and the virtual shadow maps of the
//! area lights. Pixel (x, y) has its centre at integer coordinates (as in
//! [`relume_base::pinhole::Pinhole`]); coverage is sampled at pixel centres; depth is the
//! view-space z, interpolated as 1/z (perspective-correct); the nearest triangle wins,
//! and on an exact depth tie the one rasterized first (the smaller index).

use glam::{Vec2, Vec3};

/// No triangle covers the pixel.
pub(crate) const NO_ID: u32 = u32::MAX;

/// A depth buffer (view-space z, `INFINITY` = empty) with optional triangle ids: rows
/// `first_row..first_row + depth.len() / width` of a `width` x `height` image (a band,
/// so that bands can be rasterized in parallel; the pixels written do not depend on
/// the banding).
pub(crate) struct DepthTarget<'a> {
    pub width: usize,
    pub height: usize,
    pub first_row: usize,
    pub depth: &'a mut [f32],
    pub ids: Option<&'a mut [u32]>,
}

/// A triangle ready to rasterize: (pixel position, 1/z) per vertex, and its id.
pub(crate) type ScreenTriangle = ([(Vec2, f32); 3], u32);

/// Clips a view-space triangle (z forward) to z >= `near` (Sutherland-Hodgman with one
/// plane): the clipped convex polygon's vertices in `out`, and how many (0, 3 or 4).
#[inline]
pub(crate) fn clip_near(v: &[Vec3; 3], near: f32, out: &mut [Vec3; 4]) -> usize {
    let mut n = 0;
    for i in 0..3 {
        let (a, b) = (v[i], v[(i + 1) % 3]);
        let (a_in, b_in) = (a.z >= near, b.z >= near);
        if a_in {
            out[n] = a;
            n += 1;
        }
        if a_in != b_in {
            let t = (near - a.z) / (b.z - a.z);
            out[n] = a + (b - a) * t;
            n += 1;
        }
    }
    n
}

/// Rasterizes a view-space triangle: clips it at `near`, projects its vertices to pixel
/// coordinates with `project` and writes its depth where it is nearer.
pub(crate) fn raster_view_triangle(
    target: &mut DepthTarget,
    view: &[Vec3; 3],
    near: f32,
    project: impl Fn(Vec3) -> Vec2,
    id: u32,
) {
    screen_triangles(view, near, project, id, |t| {
        raster_screen_triangle(target, t.0, t.1)
    });
}

/// Clips a view-space triangle at `near` and projects it with `project`: the one or
/// two screen triangles of [`raster_view_triangle`], in its order, passed to `emit`.
pub(crate) fn screen_triangles(
    view: &[Vec3; 3],
    near: f32,
    project: impl Fn(Vec3) -> Vec2,
    id: u32,
    mut emit: impl FnMut(ScreenTriangle),
) {
    let mut polygon = [Vec3::ZERO; 4];
    let n = clip_near(view, near, &mut polygon);
    if n < 3 {
        return;
    }
    let screen = polygon.map(|p| (project(p), 1.0 / p.z));
    for k in 1..n - 1 {
        emit(([screen[0], screen[k], screen[k + 1]], id));
    }
}

/// (b - a) x (p - a): positive when p is left of a -> b (y down: clockwise on screen).
#[inline]
fn edge(a: Vec2, b: Vec2, p: Vec2) -> f32 {
    (b - a).perp_dot(p - a)
}

/// Rasterizes one screen-space triangle given as (pixel position, 1/z) per vertex.
/// (Inlined: most triangles of a shadow map cover a texel or none, and a call would
/// pass the vertices through memory just written.)
#[inline(always)]
pub(crate) fn raster_screen_triangle(target: &mut DepthTarget, v: [(Vec2, f32); 3], id: u32) {
    let [(s0, iz0), (s1, iz1), (s2, iz2)] = v;
    let area = edge(s0, s1, s2);
    if area.is_nan() || area.abs() <= 1e-12 {
        return;
    }
    let (w, h) = (target.width as f32, target.height as f32);
    let lo = s0.min(s1).min(s2);
    let hi = s0.max(s1).max(s2);
    // Pixel centres inside the bounding box, clamped to the target (NaN-safe: a NaN
    // bound makes the range empty).
    let x0 = lo.x.max(0.0).ceil();
    let y0 = lo.y.max(0.0).ceil();
    let x1 = hi.x.min(w - 1.0);
    let y1 = hi.y.min(h - 1.0);
    if !(x0 <= x1 && y0 <= y1) {
        return;
    }
    // The rows of the band held by the target.
    let rows = target.depth.len() / target.width.max(1);
    let first = (y0 as usize).max(target.first_row);
    let end = (y1 as usize + 1).min(target.first_row + rows);
    let inv_area = 1.0 / area;
    for y in first..end {
        for x in x0 as usize..=x1 as usize {
            let p = Vec2::new(x as f32, y as f32);
            let b0 = edge(s1, s2, p) * inv_area;
            let b1 = edge(s2, s0, p) * inv_area;
            let b2 = edge(s0, s1, p) * inv_area;
            if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                continue;
            }
            let inv_z = b0 * iz0 + b1 * iz1 + b2 * iz2;
            if inv_z.is_nan() || inv_z <= 0.0 {
                continue;
            }
            let z = 1.0 / inv_z;
            let i = (y - target.first_row) * target.width + x;
            if z < target.depth[i] {
                target.depth[i] = z;
                if let Some(ids) = target.ids.as_deref_mut() {
                    ids[i] = id;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn target<'a>(depth: &'a mut [f32], ids: &'a mut [u32]) -> DepthTarget<'a> {
        DepthTarget {
            width: 8,
            height: 8,
            first_row: 0,
            depth,
            ids: Some(ids),
        }
    }

    #[test]
    fn covers_pixel_centres_with_perspective_correct_depth() {
        let (mut depth, mut ids) = ([f32::INFINITY; 64], [NO_ID; 64]);
        // A plane z = 2 + x / 2 (view space) seen by a camera with f = 4, c = 3.5.
        let project = |p: Vec3| Vec2::new(4.0 * p.x / p.z + 3.5, 4.0 * p.y / p.z + 3.5);
        let plane = |x: f32, y: f32| {
            let z = 2.0 / (1.0 - (x - 3.5) / 8.0);
            Vec3::new((x - 3.5) / 4.0 * z, (y - 3.5) / 4.0 * z, z)
        };
        let tri = [plane(-0.5, -0.5), plane(7.7, -0.5), plane(-0.5, 7.7)];
        raster_view_triangle(&mut target(&mut depth, &mut ids), &tri, 0.01, project, 3);
        for y in 0..8 {
            for x in 0..8 {
                let inside = x + y <= 7;
                let i = y * 8 + x;
                assert_eq!(ids[i] == 3, inside, "pixel {x},{y}");
                if inside {
                    let expected = plane(x as f32, y as f32).z;
                    assert!((depth[i] - expected).abs() < 1e-5 * expected, "{x},{y}");
                }
            }
        }
        // A nearer triangle over part of it wins there; a farther one nowhere.
        let near = [
            Vec3::new(-1.0, -1.0, 1.0),
            Vec3::new(1.0, -1.0, 1.0),
            Vec3::new(-1.0, 1.0, 1.0),
        ];
        raster_view_triangle(&mut target(&mut depth, &mut ids), &near, 0.01, project, 4);
        let far = near.map(|v| v * 10.0);
        raster_view_triangle(&mut target(&mut depth, &mut ids), &far, 0.01, project, 5);
        assert_eq!(ids[3 * 8 + 3], 4);
        assert!(!ids.contains(&5));
    }

    #[test]
    fn clips_at_the_near_plane() {
        let mut out = [Vec3::ZERO; 4];
        let tri = [
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ];
        assert_eq!(clip_near(&tri, 0.5, &mut out), 4);
        assert!(out.iter().all(|p| p.z >= 0.5 - 1e-6));
        let behind = tri.map(|v| Vec3::new(v.x, v.y, -2.0));
        assert_eq!(clip_near(&behind, 0.5, &mut out), 0);
        assert_eq!(clip_near(&tri.map(|v| v + Vec3::Z * 3.0), 0.5, &mut out), 3);
    }
}
