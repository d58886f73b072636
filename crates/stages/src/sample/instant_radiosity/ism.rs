//! Imperfect shadow maps (paper 002 Sec. 3.3, after Ritschel et al. 2008): per light,
//! a small depth map splatted from a sparse set of points (each point a square of
//! texels as wide as the patch of surface it stands for, one texel when that is
//! smaller), with the holes between them filled by pull-push. Two projections: a paraboloid over the
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

/// Where a point falls in a map: its texel's column and row, and its depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Texel {
    pub x: u32,
    pub y: u32,
    pub depth: f32,
}

impl Texel {
    /// The texel's index in a map of `size` x `size` texels.
    #[inline]
    pub fn index(&self, size: usize) -> usize {
        self.y as usize * size + self.x as usize
    }
}

/// A right-handed orthonormal frame whose third axis is `axis` (unit).
pub fn frame_about(axis: Vec3) -> [Vec3; 3] {
    let (t1, t2) = axis.any_orthonormal_pair();
    [t1, t2, axis]
}

impl Projection {
    /// The texel of a `size`-texel map that `p` falls in, with its depth; `None` outside
    /// the map.
    #[inline]
    pub fn project(&self, p: Vec3, size: usize) -> Option<Texel> {
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
        Some(Texel {
            x: u as u32,
            y: v as u32,
            depth,
        })
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

/// Where the point `p` standing for a patch of `radius` falls in the map, and how many
/// texels its splat reaches; `None` outside the map.
#[inline]
pub(super) fn project_point(
    projection: &Projection,
    size: usize,
    p: Vec3,
    radius: f32,
) -> Option<(Texel, i32)> {
    let texel = projection.project(p, size)?;
    let reach = (radius / projection.texel_size(texel.depth, size) - 0.5).ceil();
    let reach = if reach > 0.0 {
        (reach as i32).min(MAX_SPLAT_RADIUS)
    } else {
        0
    };
    Some((texel, reach))
}

/// Keeps `texel.depth` where it is nearer in the square of `reach` texels about
/// `texel`, and grows `written` to hold it.
#[inline]
pub(super) fn splat_square(
    map: &mut [f32],
    size: usize,
    texel: Texel,
    reach: i32,
    written: &mut [usize; 4],
) {
    let [x0, y0, x1, y1] = square_bounds(size, texel, reach, written);
    for ty in y0..y1 {
        keep_nearer(&mut map[ty * size + x0..ty * size + x1], texel.depth);
    }
}

/// Puts `depth` in each of `texels` whose depth is farther.
#[inline(always)]
pub(super) fn keep_nearer(texels: &mut [f32], depth: f32) {
    for t in texels {
        if depth < *t {
            *t = depth;
        }
    }
}

/// The square of `reach` texels about `texel`, clipped to the map (`[x0, y0, x1,
/// y1)`), with `written` grown to hold it.
#[inline(always)]
pub(super) fn square_bounds(
    size: usize,
    texel: Texel,
    reach: i32,
    written: &mut [usize; 4],
) -> [usize; 4] {
    let last = size as i32 - 1;
    let (x, y) = (texel.x as i32, texel.y as i32);
    let square = [
        (x - reach).max(0) as usize,
        (y - reach).max(0) as usize,
        (x + reach).min(last) as usize + 1,
        (y + reach).min(last) as usize + 1,
    ];
    written[0] = written[0].min(square[0]);
    written[1] = written[1].min(square[1]);
    written[2] = written[2].max(square[2]);
    written[3] = written[3].max(square[3]);
    square
}

/// Pull-push hole filling (Marroquim et al., as imperfect shadow maps use it): the map
/// is averaged down `levels` times over the texels that hold a depth (a coarse texel
/// holds one when any of its four children does), and every empty texel takes the
/// value of its nearest filled ancestor. Filled texels keep their depth bit for bit;
/// holes narrower than 2^levels texels close (wider ones close when the blocks they
/// straddle hold depths; one that fills an aligned block of 2^levels stays open), and
/// a silhouette grows by less than 2^levels texels.
///
/// Only the blocks of 2^levels texels that meet `splatted` (the rectangle `[x0, y0,
/// x1, y1)` holding every depth, from [`splat`](super::splat::splat)) are visited: nothing outside them can
/// be filled. Returns the rectangle `[x0, y0, x1, y1)` that holds every depth
/// afterwards (`[0; 4]` when none: lookups outside it need not read the map).
/// `scratch` is reused between calls.
pub fn fill_holes(
    map: &mut [f32],
    size: usize,
    levels: usize,
    splatted: [usize; 4],
    scratch: &mut Vec<f32>,
) -> [u16; 4] {
    let [sx0, sy0, sx1, sy1] = splatted;
    if sx1 <= sx0 || sy1 <= sy0 {
        return [0; 4];
    }
    // Levels that halve the map exactly, and the splatted blocks at the coarsest.
    let mut levels = levels;
    while levels > 0 && !size.is_multiple_of(1 << levels) {
        levels -= 1;
    }
    let block = 1usize << levels;
    let region = [
        sx0 / block * block,
        sy0 / block * block,
        sx1.div_ceil(block) * block,
        sy1.div_ceil(block) * block,
    ];
    // Level l is (size >> l)^2 texels at offsets[l - 1] of `scratch`.
    let mut offsets = Vec::with_capacity(levels);
    let mut total = 0;
    for l in 1..=levels {
        offsets.push(total);
        total += (size >> l) * (size >> l);
    }
    scratch.resize(total.max(scratch.len()), f32::INFINITY);
    // Pull: level l from level l - 1 (the map for l = 1).
    for l in 1..=levels {
        let (side, half) = (size >> (l - 1), size >> l);
        let coarse_region = region.map(|v| v >> l);
        if l == 1 {
            let coarse = &mut scratch[..half * half];
            pull_level(map, side, coarse, half, coarse_region);
        } else {
            let (finer, coarser) = scratch.split_at_mut(offsets[l - 1]);
            let fine = &finer[offsets[l - 2]..];
            pull_level(fine, side, &mut coarser[..half * half], half, coarse_region);
        }
    }
    // Push: coarse to fine, empty texels take their parent's value.
    for l in (1..=levels).rev() {
        let (side, half) = (size >> (l - 1), size >> l);
        let fine_region = region.map(|v| v >> (l - 1));
        if l == 1 {
            push_level(&scratch[..half * half], half, map, side, fine_region);
        } else {
            let (finer, coarser) = scratch.split_at_mut(offsets[l - 1]);
            let fine = &mut finer[offsets[l - 2]..];
            push_level(&coarser[..half * half], half, fine, side, fine_region);
        }
    }
    let mut rect = [u16::MAX, u16::MAX, 0, 0];
    for y in region[1]..region[3] {
        let row = &map[y * size + region[0]..y * size + region[2]];
        let Some(first) = row.iter().position(|v| v.is_finite()) else {
            continue;
        };
        let last = row.iter().rposition(|v| v.is_finite()).unwrap_or(first);
        rect[0] = rect[0].min((region[0] + first) as u16);
        rect[1] = rect[1].min(y as u16);
        rect[2] = rect[2].max((region[0] + last + 1) as u16);
        rect[3] = y as u16 + 1;
    }
    if rect[2] <= rect[0] { [0; 4] } else { rect }
}

/// One level of the pull: texel (x, y) of `coarse` (`half` wide), for (x, y) in the
/// rectangle `[x0, y0, x1, y1)`, the mean of the finite ones of its four children in
/// `fine` (`side` wide), INFINITY when none. The children are added in the order
/// (0, 0), (1, 0), (0, 1), (1, 1), an empty one as +0 (depths are never -0, so the
/// sum keeps its bits), without branches so that the rows vectorize.
fn pull_level(fine: &[f32], side: usize, coarse: &mut [f32], half: usize, rect: [usize; 4]) {
    let [x0, y0, x1, y1] = rect;
    for y in y0..y1 {
        let top = &fine[2 * y * side + 2 * x0..2 * y * side + 2 * x1];
        let bottom = &fine[(2 * y + 1) * side + 2 * x0..(2 * y + 1) * side + 2 * x1];
        let out = &mut coarse[y * half + x0..y * half + x1];
        for ((texel, top), bottom) in out
            .iter_mut()
            .zip(top.chunks_exact(2))
            .zip(bottom.chunks_exact(2))
        {
            let (mut sum, mut n) = (0.0f32, 0u32);
            for v in [top[0], top[1], bottom[0], bottom[1]] {
                let filled = v.is_finite();
                sum += if filled { v } else { 0.0 };
                n += filled as u32;
            }
            *texel = if n > 0 { sum / n as f32 } else { f32::INFINITY };
        }
    }
}

/// One level of the push: every empty texel of `fine` (`side` wide) in the rectangle
/// `[x0, y0, x1, y1)` (even corners) takes its parent's value in `coarse` (`half` wide).
fn push_level(coarse: &[f32], half: usize, fine: &mut [f32], side: usize, rect: [usize; 4]) {
    let [x0, y0, x1, y1] = rect;
    for y in y0..y1 {
        let parents = &coarse[(y / 2) * half + x0 / 2..(y / 2) * half + x1 / 2];
        let row = &mut fine[y * side + x0..y * side + x1];
        for (pair, &parent) in row.chunks_exact_mut(2).zip(parents) {
            for v in pair {
                if !v.is_finite() {
                    *v = parent;
                }
            }
        }
    }
}

/// One light's map with where it sits and what it covers.
#[derive(Clone, Copy)]
pub struct MapView<'a> {
    pub projection: &'a Projection,
    pub depth: &'a [f32],
    pub size: usize,
    /// The rectangle of `depth` that holds every finite texel ([`fill_holes`]).
    pub rect: [u16; 4],
    /// Metres a point must lie behind the map's depth to be hidden, plus `slope`
    /// texel sizes times the tangent of the light's angle to the receiver's normal.
    pub bias: f32,
    pub slope: f32,
}

/// The largest tangent the slope bias takes (about 83 degrees of incidence).
pub(super) const MAX_SLOPE: f32 = 8.0;

impl MapView<'_> {
    /// 1 when nothing in the map lies in front of `p` (see the module docs), else 0;
    /// with the occluder's depth difference when hidden. `cos` is the cosine of the
    /// light's angle to the receiver's normal (the slope bias grows with its tangent:
    /// a texel's depth, averaged by the hole filling, varies that much over it).
    #[inline]
    pub fn visibility(&self, p: Vec3, cos: f32) -> (f32, f32) {
        if self.is_empty() {
            return (1.0, f32::INFINITY);
        }
        self.test(self.projection.project(p, self.size), cos)
    }

    /// True when the map holds no depth: everything is visible.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.rect[2] <= self.rect[0]
    }

    /// [`MapView::visibility`] of a point already projected (`projected`: its texel and
    /// depth from this map's projection).
    #[inline]
    pub fn test(&self, projected: Option<Texel>, cos: f32) -> (f32, f32) {
        let Some(texel) = projected else {
            return (1.0, f32::INFINITY);
        };
        let [x0, y0, x1, y1] = self.rect.map(u32::from);
        if texel.x < x0 || texel.x >= x1 || texel.y < y0 || texel.y >= y1 {
            return (1.0, f32::INFINITY);
        }
        let depth = texel.depth;
        let stored = self.depth[texel.index(self.size)];
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
