//! One sample's screen geometry: its projected ellipse ([`Raster::screen`]), its
//! tangent-plane depth over that ellipse ([`Raster::footprint`]), and the depth test of
//! a footprint into a band of keys ([`draw`]).

use glam::{Mat3, Mat4, Vec3};
use relume_base::pinhole::Pinhole;

/// Samples nearer to the camera than this (metres) are not splatted.
pub const NEAR_M: f32 = 0.01;
/// The smallest screen radius in pixels: a little more than sqrt(1/2), so that the disk
/// always contains the nearest pixel centre and every sample in view covers a pixel.
pub const MIN_RADIUS_PX: f32 = 0.75;
/// Below this cosine between the normal and the view direction a splat is drawn at the
/// sample's own depth instead of along its tangent plane.
pub const GRAZING_COS: f32 = 0.25;
/// Tangent-plane depths are clamped to the sample depth +- this many splat radii.
pub const PLANE_DEPTH_SPAN: f32 = 3.0;

/// A sample's footprint as pass 3 draws it, set up once in pass 2: inverse depth
/// `a x + b y + c` over the ellipse of centre (u, v) and radii (rx, ry) on rows
/// `top..=bottom`, clamped to `[w_min, w_max]`.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Footprint {
    u: f32,
    v: f32,
    rx: f32,
    inv_ry2: f32,
    a: f32,
    b: f32,
    c: f32,
    w_min: f32,
    w_max: f32,
    top: u32,
    bottom: u32,
    index: u32,
}

/// `ceil(x)` for the first pixel index at or after `x`, at least 0 (no libm call).
#[inline]
pub(super) fn first_index_from(x: f32) -> i64 {
    if x > 0.0 {
        let t = x.min(1e9) as i64;
        t + ((t as f32) < x) as i64
    } else {
        0
    }
}

/// `floor(x)` for the last pixel index at or before `x`, at most `last`; -1 when `x < 0`.
#[inline]
pub(super) fn last_index_to(x: f32, last: i64) -> i64 {
    if x >= 0.0 {
        (x.min(1e9) as i64).min(last)
    } else {
        -1
    }
}

/// A sample in screen space: camera-space position, projected centre, screen radii and
/// the rows its footprint spans.
pub(super) struct Screen {
    pub(super) p: Vec3,
    pub(super) u: f32,
    pub(super) v: f32,
    pub(super) rx: f32,
    pub(super) ry: f32,
    pub(super) top: u32,
    pub(super) bottom: u32,
}

/// What one sample's rasterization needs.
pub(super) struct Raster<'a> {
    pub(super) camera: &'a Pinhole,
    pub(super) world_to_camera: Mat4,
    pub(super) rotation: Mat3,
    pub(super) radius: f32,
    pub(super) max_radius_px: f32,
}

impl Raster<'_> {
    /// The screen footprint of the sample at world position `world`; `None` when it is
    /// not finite, too near or behind the camera, or its ellipse misses the image.
    #[inline]
    pub(super) fn screen(&self, world: Vec3) -> Option<Screen> {
        let cam = self.camera;
        let p = self.world_to_camera.transform_point3(world);
        if !p.is_finite() || p.z <= NEAR_M {
            return None;
        }
        let inv_z = 1.0 / p.z;
        let (u, v) = (cam.fx * p.x * inv_z + cam.cx, cam.fy * p.y * inv_z + cam.cy);
        let rx = (cam.fx * self.radius * inv_z).clamp(MIN_RADIUS_PX, self.max_radius_px);
        let ry = (cam.fy * self.radius * inv_z).clamp(MIN_RADIUS_PX, self.max_radius_px);
        let w = cam.width as f32;
        let top = first_index_from(v - ry);
        let bottom = last_index_to(v + ry, cam.height as i64 - 1);
        if top > bottom || u + rx < 0.0 || u - rx > w - 1.0 {
            return None;
        }
        Some(Screen {
            p,
            u,
            v,
            rx,
            ry,
            top: top as u32,
            bottom: bottom as u32,
        })
    }

    /// The footprint of sample `index` at world position `world` with world normal
    /// `normal` (`None` when it is not drawn): the depth along pixel (x, y)'s ray on the
    /// tangent plane n . X = n . p is z = (n . p) / (n . ray(x, y)), and
    /// n . ray(x, y) = a x + b y + c, so its inverse is linear in x and y. Near grazing,
    /// the sample's own depth. Depths are clamped to p.z +- PLANE_DEPTH_SPAN r (and
    /// beyond NEAR_M).
    #[inline]
    pub(super) fn footprint(&self, world: Vec3, normal: Vec3, index: u32) -> Option<Footprint> {
        let s = self.screen(world)?;
        let cam = self.camera;
        let p = s.p;
        let n = self.rotation * normal;
        let n_len = n.length();
        let n_dot_p = n.dot(p);
        let tangent = n_len > 0.0 && n_dot_p.abs() >= GRAZING_COS * n_len * p.length();
        let (a, b, c) = if tangent {
            let inv = 1.0 / n_dot_p;
            (
                n.x / cam.fx * inv,
                n.y / cam.fy * inv,
                (n.z - n.x * cam.cx / cam.fx - n.y * cam.cy / cam.fy) * inv,
            )
        } else {
            (0.0, 0.0, 1.0 / p.z)
        };
        let span = PLANE_DEPTH_SPAN * self.radius;
        let (near, far) = ((p.z - span).max(NEAR_M), p.z + span);
        Some(Footprint {
            u: s.u,
            v: s.v,
            rx: s.rx,
            inv_ry2: 1.0 / (s.ry * s.ry),
            a,
            b,
            c,
            w_min: 1.0 / far,
            w_max: 1.0 / near,
            top: s.top,
            bottom: s.bottom,
            index,
        })
    }
}

/// Depth-tests footprint `f` into every pixel centre of rows `rows` (inclusive) inside
/// its screen ellipse; `keys` holds those rows of an image `width` wide. A key is the
/// complemented inverse-depth bits << 32 | sample index: the smallest is the nearest
/// sample, ties going to the lower index.
#[inline]
pub(super) fn draw(f: &Footprint, width: usize, rows: (usize, usize), keys: &mut [u64]) {
    let last_x = width as i64 - 1;
    let low_index = f.index as u64;
    let (first_row, last_row) = (
        (f.top as usize).max(rows.0),
        (f.bottom as usize).min(rows.1),
    );
    for y in first_row..=last_row {
        let dy = y as f32 - f.v;
        let half = f.rx * (1.0 - dy * dy * f.inv_ry2).max(0.0).sqrt();
        let (left, right) = (
            first_index_from(f.u - half),
            last_index_to(f.u + half, last_x),
        );
        if left > right {
            continue;
        }
        let (left, right) = (left as usize, right as usize);
        let start = (y - rows.0) * width;
        let row = &mut keys[start + left..=start + right];
        let row_w = f.b * y as f32 + f.c;
        for (k, slot) in row.iter_mut().enumerate() {
            let w = f.a * (left + k) as f32 + row_w;
            // Negative inverse depths (ray past the plane's horizon) and NaN fall to near.
            let w = if w > 0.0 {
                w.max(f.w_min).min(f.w_max)
            } else {
                f.w_max
            };
            let key = ((!w.to_bits() as u64) << 32) | low_index;
            *slot = (*slot).min(key);
        }
    }
}
