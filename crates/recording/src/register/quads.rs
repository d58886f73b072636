//! The drawing half of [`super::register_depth`]: depth pixels projected into the color
//! view ([`Projector`], [`Projected`]), and the quads between them rasterized into a
//! z-buffer of 1/z ([`Quads`], [`rasterize`]); `lanes` draws eight quads at a time.

use crate::lens::Distortion;
use glam::{DMat3, DQuat, DVec3};
use relume_base::pinhole::Intrinsics;

/// Each depth pixel's place in the color image, as planes (so that eight neighbouring
/// pixels load at once).
#[derive(Default)]
pub(super) struct Projected {
    pub(super) x: Vec<f32>,
    pub(super) y: Vec<f32>,
    /// 1/z in the color camera; 0: not seen (behind the camera, outside a lens's field,
    /// or no depth).
    pub(super) w: Vec<f32>,
}

impl Projected {
    #[inline(always)]
    pub(super) fn at(&self, i: usize) -> [f32; 3] {
        [self.x[i], self.y[i], self.w[i]]
    }
}

/// The surface between neighbouring depth pixels, drawn into the color view: the quad of
/// depth pixels i, i + 1 (top) and i + w, i + w + 1 (bottom) is two triangles, (0, 1, 2)
/// and (1, 3, 2) of its corners.
pub(super) struct Quads<'a> {
    pub(super) depth_m: &'a [f32],
    pub(super) projected: &'a Projected,
    pub(super) camera: Projector<'a>,
    /// The color image's width and height.
    pub(super) size: (usize, usize),
    /// The largest relative depth step between a triangle's corners on one surface.
    pub(super) step: f32,
    /// The most pixels a triangle's bounding box may hold to be drawn.
    pub(super) max_pixels: i64,
    /// The nearest surface's 1/z at each color pixel.
    pub(super) nearest: &'a mut [f32],
    /// The nearest 1/z of edge triangles covering each color pixel.
    pub(super) edge_nearest: &'a mut [f32],
}

impl Quads<'_> {
    /// Draws the quad whose top left corner is depth pixel `i`.
    pub(super) fn draw(&mut self, i: usize) {
        let (depth_m, projected) = (self.depth_m, self.projected);
        let dw = self.camera.width;
        let quad = [i, i + 1, i + dw, i + dw + 1];
        // Most quads lie on one surface, all four corners seen: both triangles are
        // drawn in one pass. (The quad's depth range holds each triangle's.)
        let z = quad.map(|i| depth_m[i]);
        let (lo, hi) = (
            z[0].min(z[1]).min(z[2]).min(z[3]),
            z[0].max(z[1]).max(z[2]).max(z[3]),
        );
        let p = quad.map(|i| projected.at(i));
        let step = self.step;
        if lo > 0.0 && p.iter().all(|p| p[2] > 0.0) && hi - lo <= lo * step {
            rasterize_quad(p, self.size, self.max_pixels, self.nearest);
            return;
        }
        for tri in [[quad[0], quad[1], quad[2]], [quad[1], quad[3], quad[2]]] {
            let z = tri.map(|i| depth_m[i]);
            let (lo, hi) = (z[0].min(z[1]).min(z[2]), z[0].max(z[1]).max(z[2]));
            let p = tri.map(|i| projected.at(i));
            if lo <= 0.0 || p.iter().any(|p| p[2] <= 0.0) {
                continue;
            }
            if hi - lo <= lo * step {
                rasterize(p, self.size, self.max_pixels, self.nearest);
                continue;
            }
            // An edge: the near surface may reach across the whole triangle, at any
            // depth it can have there (its nearest corner's, up to a surface step
            // beyond). Swept in three slices, each flat at its nearest 1/z.
            for z in [lo, lo * (1.0 + step / 2.0), lo * (1.0 + step)] {
                let reach = tri.map(|i| self.camera.project(i, z));
                if reach.iter().all(|p| p[2] > 0.0) {
                    let w = reach[0][2].max(reach[1][2]).max(reach[2][2]);
                    rasterize(
                        reach.map(|[x, y, _]| [x, y, w]),
                        self.size,
                        self.max_pixels,
                        self.edge_nearest,
                    );
                }
            }
        }
    }
}

/// Depth pixels to the color image: back-projection along each depth pixel's ray, the
/// extrinsic, projection with the color intrinsics (and the color lens's distortion).
pub(super) struct Projector<'a> {
    pub(super) rays: &'a [[f32; 2]],
    /// The depth image's width.
    pub(super) width: usize,
    pub(super) color: [f32; 4],
    pub(super) color_lens: Option<Distortion>,
    pub(super) rotation: glam::Mat3,
    pub(super) translation: glam::Vec3,
}

impl<'a> Projector<'a> {
    /// The color camera `color` (with its lens) and the transform from the depth camera
    /// (`depth_width` pixels a row, each pixel's ray in `rays`) to it.
    pub(super) fn new(
        color: &Intrinsics,
        color_lens: Option<Distortion>,
        (rotation, translation): (DQuat, DVec3),
        depth_width: usize,
        rays: &'a [[f32; 2]],
    ) -> Self {
        Projector {
            rays,
            width: depth_width,
            color: [
                color.fx as f32,
                color.fy as f32,
                color.cx as f32,
                color.cy as f32,
            ],
            color_lens: color_lens.filter(|lens| !lens.is_none()),
            rotation: DMat3::from_quat(rotation).as_mat3(),
            translation: translation.as_vec3(),
        }
    }

    /// Depth pixel `i` at depth `z` metres in the color image: x, y and 1/z there (all 0
    /// when it lies behind the color camera or outside either lens's field).
    pub(super) fn project(&self, i: usize, z: f32) -> [f32; 3] {
        let [rx, ry] = self.rays[i];
        let [cfx, cfy, ccx, ccy] = self.color;
        let point = glam::Vec3::new(rx * z, ry * z, z);
        let c = self.rotation * point + self.translation;
        // Also rejects NaN, which fails every comparison.
        if c.z.is_nan() || c.z <= 0.0 {
            return [0.0; 3];
        }
        let w = 1.0 / c.z;
        let (mut x, mut y) = (c.x * w, c.y * w);
        if let Some(lens) = &self.color_lens {
            match lens.distort(x as f64, y as f64) {
                Some((dx, dy)) => (x, y) = (dx as f32, dy as f32),
                None => return [0.0; 3],
            }
        }
        [x * cfx + ccx, y * cfy + ccy, w]
    }
}

/// The smallest integer at or above `x` (saturating; NaN gives 0), without the libm call
/// `f32::ceil` is on a baseline x86-64 target.
pub(super) fn ceil(x: f32) -> i32 {
    let i = x as i32;
    i + ((i as f32) < x) as i32
}

/// The largest integer at or below `x` (saturating; NaN gives 0).
pub(super) fn floor(x: f32) -> i32 {
    let i = x as i32;
    i - ((i as f32) > x) as i32
}

/// The least barycentric weight a pixel centre inside a triangle may have: a hair of
/// tolerance keeps pixels on a shared edge from falling between its two triangles by
/// rounding.
pub(super) const EDGE_TOLERANCE: f32 = -1e-5;

/// One triangle (color-image x, y and 1/z at each corner) set up for drawing: the pixels
/// of its bounding box, clipped to the image, and its signed area's reciprocal.
struct Triangle {
    p: [[f32; 3]; 3],
    x: (i32, i32),
    y: (i32, i32),
    inv_area: f32,
}

impl Triangle {
    /// `None` when no pixel centre (integer coordinates) can lie inside: outside the image,
    /// degenerate, or a bounding box over `max_pixels` pixels.
    #[inline(always)]
    fn new(p: [[f32; 3]; 3], (width, height): (usize, usize), max_pixels: i64) -> Option<Self> {
        let min_x = ceil(p[0][0].min(p[1][0]).min(p[2][0])).max(0);
        let max_x = floor(p[0][0].max(p[1][0]).max(p[2][0])).min(width as i32 - 1);
        let min_y = ceil(p[0][1].min(p[1][1]).min(p[2][1])).max(0);
        let max_y = floor(p[0][1].max(p[1][1]).max(p[2][1])).min(height as i32 - 1);
        if min_x > max_x
            || min_y > max_y
            || (max_x - min_x + 1) as i64 * (max_y - min_y + 1) as i64 > max_pixels
        {
            return None;
        }
        let area =
            (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
        if area.abs() < 1e-12 {
            return None;
        }
        Some(Triangle {
            p,
            x: (min_x, max_x),
            y: (min_y, max_y),
            inv_area: 1.0 / area,
        })
    }

    /// The 1/z at pixel centre (qx, qy), interpolated from the corners, or `None` outside.
    #[inline(always)]
    fn weight_at(&self, qx: i32, qy: i32) -> Option<f32> {
        let p = &self.p;
        if qx < self.x.0 || qx > self.x.1 || qy < self.y.0 || qy > self.y.1 {
            return None;
        }
        let (qx, qy) = (qx as f32, qy as f32);
        // Edge function of the edge from a to b at q, over the triangle's signed area: the
        // barycentric weight of the corner opposite the edge.
        let edge = |a: [f32; 3], b: [f32; 3]| {
            ((b[0] - a[0]) * (qy - a[1]) - (qx - a[0]) * (b[1] - a[1])) * self.inv_area
        };
        let l0 = edge(p[1], p[2]);
        let l1 = edge(p[2], p[0]);
        let l2 = 1.0 - l0 - l1;
        if l0 < EDGE_TOLERANCE || l1 < EDGE_TOLERANCE || l2 < EDGE_TOLERANCE {
            return None;
        }
        Some(l0 * p[0][2] + l1 * p[1][2] + l2 * p[2][2])
    }
}

/// Draws one triangle (color-image x, y and 1/z at each corner) into `nearest`, keeping
/// the larger 1/z at each pixel whose centre (integer coordinates) lies inside or on it.
/// A triangle whose bounding box holds more than `max_pixels` pixels is not drawn.
pub(super) fn rasterize(
    p: [[f32; 3]; 3],
    size: (usize, usize),
    max_pixels: i64,
    nearest: &mut [f32],
) {
    if let Some(t) = Triangle::new(p, size, max_pixels) {
        draw(&[t], size.0, nearest);
    }
}

/// Both triangles of a quad of neighbouring depth pixels (corners 0 1 over 2 3), as
/// `rasterize` draws (0, 1, 2) and (1, 3, 2), in one pass over their bounding boxes: the
/// same pixels get the same values.
pub(super) fn rasterize_quad(
    p: [[f32; 3]; 4],
    size: (usize, usize),
    max_pixels: i64,
    nearest: &mut [f32],
) {
    let a = Triangle::new([p[0], p[1], p[2]], size, max_pixels);
    let b = Triangle::new([p[1], p[3], p[2]], size, max_pixels);
    match (a, b) {
        (Some(a), Some(b)) => draw(&[a, b], size.0, nearest),
        (Some(t), None) | (None, Some(t)) => draw(&[t], size.0, nearest),
        (None, None) => {}
    }
}

/// Keeps at each pixel of the triangles' bounding boxes the largest of its 1/z so far and
/// theirs.
#[inline(always)]
fn draw<const N: usize>(triangles: &[Triangle; N], width: usize, nearest: &mut [f32]) {
    let x0 = triangles.iter().map(|t| t.x.0).min().unwrap_or(0);
    let x1 = triangles.iter().map(|t| t.x.1).max().unwrap_or(-1);
    let y0 = triangles.iter().map(|t| t.y.0).min().unwrap_or(0);
    let y1 = triangles.iter().map(|t| t.y.1).max().unwrap_or(-1);
    for y in y0..=y1 {
        for x in x0..=x1 {
            let slot = &mut nearest[y as usize * width + x as usize];
            for t in triangles {
                if let Some(w) = t.weight_at(x, y)
                    && w > *slot
                {
                    *slot = w;
                }
            }
        }
    }
}
