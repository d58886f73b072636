//! Imperfect shadow maps (paper 002 Sec. 3.3, after Ritschel et al. 2008): per light,
//! a small depth map splatted from a sparse set of points, one texel per point, with
//! the holes between them filled by pull-push. Two projections: a paraboloid over the
//! hemisphere of a surface VPL, and an orthographic disc for a light at infinity
//! (paper 002 places the environment's VPLs on a far hemisphere; relume takes them as
//! directions, see `vpl.rs`).
//!
//! A map answers `visible(p)`: 1 when `p` lies no farther from the light than the
//! map's depth there plus a bias, 0 when something is in front of it; a point the map
//! does not cover (outside the disc, behind the paraboloid, or over an empty texel) is
//! visible. Maps are plain `f32` slices of `size * size` texels (INFINITY: empty), so a
//! frame's maps live in one buffer.

use glam::Vec3;

/// How a light's map sees the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// A surface VPL at `origin` whose hemisphere about `frame[2]` (its normal) maps
    /// onto the disc by the paraboloid u = l.xy / (1 + l.z), l the unit direction in
    /// the frame; depth is the distance to `origin`.
    Paraboloid { origin: Vec3, frame: [Vec3; 3] },
    /// A light from direction `frame[2]` (towards it): the disc of `radius` about
    /// `center` seen along it; depth is `radius - (p - center) . frame[2]`, the distance
    /// below the plane that touches the disc's sphere on the light's side. Points above
    /// that plane (depth < 0) are neither occluders nor receivers.
    Orthographic {
        center: Vec3,
        radius: f32,
        frame: [Vec3; 3],
    },
}

/// A right-handed orthonormal frame whose third axis is `axis` (unit).
pub fn frame_about(axis: Vec3) -> [Vec3; 3] {
    let (t1, t2) = axis.any_orthonormal_pair();
    [t1, t2, axis]
}

impl Projection {
    /// The texel of a `size`-texel map that `p` falls in, and its depth; `None` outside
    /// the map.
    #[inline]
    pub fn project(&self, p: Vec3, size: usize) -> Option<(usize, f32)> {
        let (uv, depth) = match *self {
            Projection::Paraboloid { origin, frame } => {
                let d = p - origin;
                let r = d.length();
                let z = d.dot(frame[2]);
                if r.is_nan() || r <= 0.0 || z <= 0.0 {
                    return None;
                }
                let k = 1.0 / (r + z);
                ((d.dot(frame[0]) * k, d.dot(frame[1]) * k), r)
            }
            Projection::Orthographic {
                center,
                radius,
                frame,
            } => {
                let d = p - center;
                let depth = radius - d.dot(frame[2]);
                if depth.is_nan() || depth < 0.0 {
                    return None;
                }
                let k = 1.0 / radius;
                ((d.dot(frame[0]) * k, d.dot(frame[1]) * k), depth)
            }
        };
        let s = size as f32;
        let (u, v) = ((uv.0 * 0.5 + 0.5) * s, (uv.1 * 0.5 + 0.5) * s);
        if !(u >= 0.0 && v >= 0.0 && u < s && v < s) {
            return None;
        }
        Some((v as usize * size + u as usize, depth))
    }

    /// The world size of one texel at `depth` (at the disc's centre for the
    /// paraboloid, where its texels are smallest): the bias scales with it.
    #[inline]
    pub fn texel_size(&self, depth: f32, size: usize) -> f32 {
        match *self {
            // u = tan(theta / 2): one texel (du = 2 / size) spans dtheta = 4 / size
            // on the axis.
            Projection::Paraboloid { .. } => depth * 4.0 / size as f32,
            Projection::Orthographic { radius, .. } => 2.0 * radius / size as f32,
        }
    }
}

/// The most texels a splat reaches from its centre.
pub const MAX_SPLAT_RADIUS: i32 = 4;

/// Splats `points` into `map` (`size * size` texels, cleared to INFINITY by the caller):
/// each point that projects into the map keeps the nearest depth of the texels its patch
/// covers. A point stands for a disc of the surface of the radius given with it (metres:
/// a sparse subset of a surface stands for all of it); the splat is the square of texels
/// within that radius of its texel (at most [`MAX_SPLAT_RADIUS`]), one texel when the
/// patch is smaller than a texel.
pub fn splat(
    map: &mut [f32],
    size: usize,
    projection: &Projection,
    points: impl Iterator<Item = (Vec3, f32)>,
) {
    let last = size as i32 - 1;
    for (p, radius) in points {
        let Some((texel, depth)) = projection.project(p, size) else {
            continue;
        };
        let reach = (radius / projection.texel_size(depth, size) - 0.5).ceil();
        let reach = if reach > 0.0 {
            (reach as i32).min(MAX_SPLAT_RADIUS)
        } else {
            0
        };
        let (x, y) = ((texel % size) as i32, (texel / size) as i32);
        for ty in (y - reach).max(0)..=(y + reach).min(last) {
            for tx in (x - reach).max(0)..=(x + reach).min(last) {
                let t = &mut map[ty as usize * size + tx as usize];
                if depth < *t {
                    *t = depth;
                }
            }
        }
    }
}

/// Pull-push hole filling (Marroquim et al., as imperfect shadow maps use it): the map
/// is averaged down `levels` times over the texels that hold a depth (a coarse texel
/// holds one when any of its four children does), and every empty texel takes
/// the value of its nearest filled ancestor. Filled texels keep their depth bit for
/// bit; a hole wider than 2^levels texels stays empty, and a silhouette grows by less
/// than 2^levels texels.
/// `scratch` is reused between calls.
pub fn fill_holes(map: &mut [f32], size: usize, levels: usize, scratch: &mut Vec<f32>) {
    scratch.clear();
    // Pull: level l (side size >> l) follows level l - 1 in `scratch`.
    let mut offsets = Vec::with_capacity(levels);
    let mut side = size;
    let mut from: Option<usize> = None; // None: the map itself
    for _ in 0..levels {
        if side < 2 {
            break;
        }
        let half = side / 2;
        let start = scratch.len();
        scratch.resize(start + half * half, f32::INFINITY);
        for y in 0..half {
            for x in 0..half {
                let (mut sum, mut n) = (0.0f32, 0u32);
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let i = (2 * y + dy) * side + 2 * x + dx;
                    let v = match from {
                        None => map[i],
                        Some(o) => scratch[o + i],
                    };
                    if v.is_finite() {
                        sum += v;
                        n += 1;
                    }
                }
                if n > 0 {
                    scratch[start + y * half + x] = sum / n as f32;
                }
            }
        }
        offsets.push((start, half));
        from = Some(start);
        side = half;
    }
    // Push: coarse to fine, empty texels take their parent's value.
    for l in (0..offsets.len()).rev() {
        let (parent, half) = offsets[l];
        let (child, side) = match l {
            0 => (None, size),
            _ => (Some(offsets[l - 1].0), offsets[l - 1].1),
        };
        for y in 0..side {
            for x in 0..side {
                let up = scratch[parent + (y / 2).min(half - 1) * half + (x / 2).min(half - 1)];
                let i = y * side + x;
                let v = match child {
                    None => &mut map[y * size + x],
                    Some(o) => &mut scratch[o + i],
                };
                if !v.is_finite() {
                    *v = up;
                }
            }
        }
    }
}

/// The texel rectangle `[x0, x1) x [y0, y1)` that holds every finite depth of `map`
/// (empty when none): lookups outside it need not read the map.
pub fn filled_rect(map: &[f32], size: usize) -> [u16; 4] {
    let (mut x0, mut y0, mut x1, mut y1) = (size, size, 0, 0);
    for (y, row) in map.chunks_exact(size.max(1)).enumerate() {
        let Some(first) = row.iter().position(|v| v.is_finite()) else {
            continue;
        };
        let last = row.iter().rposition(|v| v.is_finite()).unwrap_or(first);
        x0 = x0.min(first);
        x1 = x1.max(last + 1);
        y0 = y0.min(y);
        y1 = y + 1;
    }
    if x1 <= x0 {
        return [0; 4];
    }
    [x0 as u16, y0 as u16, x1 as u16, y1 as u16]
}

/// One light's map with where it sits and what it covers.
#[derive(Clone, Copy)]
pub struct MapView<'a> {
    pub projection: &'a Projection,
    pub depth: &'a [f32],
    pub size: usize,
    /// [`filled_rect`] of `depth`.
    pub rect: [u16; 4],
    /// Metres a point must lie behind the map's depth to be hidden, plus `slope`
    /// texel sizes times the tangent of the light's angle to the receiver's normal.
    pub bias: f32,
    pub slope: f32,
}

/// The largest tangent the slope bias takes (about 83 degrees of incidence).
const MAX_SLOPE: f32 = 8.0;

impl MapView<'_> {
    /// 1 when nothing in the map lies in front of `p` (see the module docs), else 0;
    /// with the occluder's depth difference when hidden. `cos` is the cosine of the
    /// light's angle to the receiver's normal (the slope bias grows with its tangent:
    /// a texel's depth, averaged by the hole filling, varies that much over it).
    #[inline]
    pub fn visibility(&self, p: Vec3, cos: f32) -> (f32, f32) {
        let Some((texel, depth)) = self.projection.project(p, self.size) else {
            return (1.0, f32::INFINITY);
        };
        let (x, y) = ((texel % self.size) as u16, (texel / self.size) as u16);
        let [x0, y0, x1, y1] = self.rect;
        if x < x0 || x >= x1 || y < y0 || y >= y1 {
            return (1.0, f32::INFINITY);
        }
        let stored = self.depth[texel];
        let cos = cos.clamp(1e-3, 1.0);
        let tan = ((1.0 - cos * cos).sqrt() / cos).min(MAX_SLOPE);
        let bias = self.bias + self.slope * tan * self.projection.texel_size(depth, self.size);
        if depth > stored + bias {
            (0.0, depth - stored)
        } else {
            (1.0, f32::INFINITY)
        }
    }
}
