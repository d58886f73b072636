//! The previous fused map as a triangle mesh seen from the current camera (paper 002
//! eqs. 11-14): one vertex per pixel, back-projected, moved and projected
//! ([`Mesh::warp_row`]), and each 2x2 quad's two triangles z-tested into the target's
//! keys ([`Mesh::quad`], [`Mesh::triangle`]; `mesh_lanes.rs` does eight quads at a
//! time with the same bits, `warp.rs` runs the bands).

use glam::{Mat3, Vec3};
use relume_base::pinhole::Pinhole;
use relume_base::raster::depth_is_valid;
use std::sync::atomic::{AtomicU64, Ordering};

/// Warped vertices nearer to the current camera than this (metres) are dropped.
const NEAR_M: f32 = 1e-3;
/// Triangles whose bounding box in the current view is wider or taller than this many
/// pixels are dropped. Between neighbouring frames a 2x2-pixel quad stays about a pixel
/// wide; a huge one comes from a vertex almost in the camera plane (degenerate).
pub const MAX_TRIANGLE_SPAN_PX: f32 = 16.0;
/// Barycentric tolerance: pixel centres on a shared edge belong to both triangles, so
/// rounding never opens a crack between them (the z-test picks one value).
pub(super) const EDGE_TOLERANCE: f32 = 1e-5;

/// One warped vertex: current-view pixel coordinates, 1 / current depth (0 = invalid)
/// and weight.
#[derive(Clone, Copy, Default)]
pub(super) struct Vertex {
    pub x: f32,
    pub y: f32,
    pub inv_z: f32,
    pub weight: f32,
}

/// The warped vertices of a band's rows, one plane per field, so that eight
/// neighbours load at once.
#[derive(Default)]
pub(super) struct VertexRows {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub inv_z: Vec<f32>,
    pub weight: Vec<f32>,
}

impl VertexRows {
    pub fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.inv_z.clear();
        self.weight.clear();
    }

    fn push(&mut self, v: Vertex) {
        self.x.push(v.x);
        self.y.push(v.y);
        self.inv_z.push(v.inv_z);
        self.weight.push(v.weight);
    }

    /// Vertex `i` (of the band's rows, row-major).
    #[inline]
    pub fn get(&self, i: usize) -> Vertex {
        Vertex {
            x: self.x[i],
            y: self.y[i],
            inv_z: self.inv_z[i],
            weight: self.weight[i],
        }
    }
}

/// The pixel indices `ceil(lo).max(0)..=floor(hi).min(last)` of the centres in
/// `[lo, hi]`, or `None` when there are none (or a bound is NaN). Truncating casts
/// instead of `floor`/`ceil`, which are library calls without SSE4.1.
#[inline]
fn centre_range(lo: f32, hi: f32, last: f32) -> Option<(usize, usize)> {
    if !(hi >= 0.0 && lo <= last) {
        return None;
    }
    // lo <= last and hi >= 0, so both casts are in range (hi saturates when huge).
    let first = if lo > 0.0 {
        let t = lo as usize;
        t + ((t as f32) < lo) as usize
    } else {
        0
    };
    let end = (hi as usize).min(last as usize);
    (first <= end).then_some((first, end))
}

/// The previous map as a mesh, with the transform into the current view.
pub(super) struct Mesh<'a> {
    pub depth: &'a [f32],
    pub weight: &'a [f32],
    pub width: usize,
    pub rotation: Mat3,
    pub translation: Vec3,
    pub camera: Pinhole,
    pub columns: Vec<Vec3>,
    pub max_stretch: f32,
    /// The last pixel column and row, as floats.
    pub x_last: f32,
    pub y_last: f32,
    pub keys: &'a [AtomicU64],
}

impl Mesh<'_> {
    /// Warps the vertices of pixel row `y` into `out` (appended).
    pub fn warp_row(&self, y: usize, out: &mut VertexRows) {
        let c = &self.camera;
        let row_ray = self.rotation.y_axis * ((y as f32 - c.cy) / c.fy) + self.rotation.z_axis;
        let start = y * self.width;
        let depths = &self.depth[start..start + self.width];
        let weights = &self.weight[start..start + self.width];
        for ((&z, &weight), column) in depths.iter().zip(weights).zip(&self.columns) {
            let mut v = Vertex::default();
            if depth_is_valid(z) && weight.is_finite() && weight > 0.0 {
                // eqs. 11, 13: p = ray * z in the previous camera, then R p + t.
                let p = (*column + row_ray) * z + self.translation;
                if p.z > NEAR_M {
                    let inv_z = 1.0 / p.z;
                    v = Vertex {
                        x: c.fx * p.x * inv_z + c.cx,
                        y: c.fy * p.y * inv_z + c.cy,
                        inv_z,
                        weight,
                    };
                }
            }
            out.push(v);
        }
    }

    /// Rasterizes quad `x` of `row`: its two triangles, split along the diagonal whose
    /// end depths differ less.
    #[inline]
    pub fn quad(&self, vertices: &VertexRows, row: &QuadRow, x: usize) {
        // a b
        // c d
        let (a, b) = (vertices.get(row.top + x), vertices.get(row.top + x + 1));
        let (c, d) = (
            vertices.get(row.bottom + x),
            vertices.get(row.bottom + x + 1),
        );
        let (za, zb) = (row.z_top[x], row.z_top[x + 1]);
        let (zc, zd) = (row.z_bottom[x], row.z_bottom[x + 1]);
        if (za - zd).abs() <= (zb - zc).abs() {
            self.triangle([a, b, d], [za, zb, zd]);
            self.triangle([a, d, c], [za, zd, zc]);
        } else {
            self.triangle([a, b, c], [za, zb, zc]);
            self.triangle([b, d, c], [zb, zd, zc]);
        }
    }

    /// Z-tests the pixel centres inside one triangle; `z_prev` are its vertex depths in
    /// the previous map.
    #[inline]
    pub fn triangle(&self, v: [Vertex; 3], z_prev: [f32; 3]) {
        let [v0, v1, v2] = v;
        if v0.inv_z <= 0.0 || v1.inv_z <= 0.0 || v2.inv_z <= 0.0 {
            return;
        }
        let z_near = z_prev[0].min(z_prev[1]).min(z_prev[2]);
        let z_far = z_prev[0].max(z_prev[1]).max(z_prev[2]);
        if z_far - z_near > self.max_stretch * z_near {
            return;
        }
        let (x_min, x_max) = (v0.x.min(v1.x).min(v2.x), v0.x.max(v1.x).max(v2.x));
        let (y_min, y_max) = (v0.y.min(v1.y).min(v2.y), v0.y.max(v1.y).max(v2.y));
        // Most triangles of a 1-pixel quad hold no pixel centre. Also false for NaN.
        let (Some((x_lo, x_hi)), Some((y_lo, y_hi))) = (
            centre_range(x_min, x_max, self.x_last),
            centre_range(y_min, y_max, self.y_last),
        ) else {
            return;
        };
        if x_max - x_min > MAX_TRIANGLE_SPAN_PX || y_max - y_min > MAX_TRIANGLE_SPAN_PX {
            return;
        }
        let (e1x, e1y) = (v1.x - v0.x, v1.y - v0.y);
        let (e2x, e2y) = (v2.x - v0.x, v2.y - v0.y);
        // Twice the signed area; the edge functions below are barycentrics times it.
        let area = e1x * e2y - e2x * e1y;
        if area.abs() <= 1e-12 {
            return;
        }
        let (sign, tolerance) = (area.signum(), -EDGE_TOLERANCE * area.abs());
        let inv_area = 1.0 / (area * sign);
        let (inv_z_min, inv_z_max) = (
            v0.inv_z.min(v1.inv_z).min(v2.inv_z),
            v0.inv_z.max(v1.inv_z).max(v2.inv_z),
        );
        let (weight_min, weight_max) = (
            v0.weight.min(v1.weight).min(v2.weight),
            v0.weight.max(v1.weight).max(v2.weight),
        );
        let (wz0, wz1, wz2) = (
            v0.weight * v0.inv_z,
            v1.weight * v1.inv_z,
            v2.weight * v2.inv_z,
        );
        for py in y_lo..=y_hi {
            let dy = py as f32 - v0.y;
            for px in x_lo..=x_hi {
                let dx = px as f32 - v0.x;
                let a1 = (dx * e2y - e2x * dy) * sign;
                let a2 = (e1x * dy - dx * e1y) * sign;
                let a0 = area * sign - a1 - a2;
                if a0 < tolerance || a1 < tolerance || a2 < tolerance {
                    continue;
                }
                let (b1, b2) = (a1 * inv_area, a2 * inv_area);
                let b0 = 1.0 - b1 - b2;
                let inv_z =
                    (b0 * v0.inv_z + b1 * v1.inv_z + b2 * v2.inv_z).clamp(inv_z_min, inv_z_max);
                let z = 1.0 / inv_z;
                // Perspective-correct weight: interpolate weight / z, times z.
                let weight = ((b0 * wz0 + b1 * wz1 + b2 * wz2) * z).clamp(weight_min, weight_max);
                let key = ((z.to_bits() as u64) << 32) | weight.to_bits() as u64;
                self.z_test(py * self.width + px, key);
            }
        }
    }

    /// Keeps `key` at pixel `i` if it is nearer than what is there.
    #[inline]
    pub fn z_test(&self, i: usize, key: u64) {
        let slot = &self.keys[i];
        // Keys only decrease: skip the atomic write when it cannot win.
        if key < slot.load(Ordering::Relaxed) {
            slot.fetch_min(key, Ordering::Relaxed);
        }
    }
}

/// One row of quads: where its top and bottom vertices start in the band's
/// [`VertexRows`], and their depths in the previous map.
pub(super) struct QuadRow<'a> {
    pub top: usize,
    pub bottom: usize,
    pub z_top: &'a [f32],
    pub z_bottom: &'a [f32],
}
