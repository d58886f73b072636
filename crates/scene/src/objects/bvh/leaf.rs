//! A leaf's triangles four at a time: [`TrianglePack`] holds four triangles in
//! structure-of-arrays form, one per lane of [`Vec4`], and [`TrianglePack::intersect`]
//! runs [`ray_triangle_edges`] on all four at once. Each lane computes the scalar
//! function's operations in the same order with the same roundings (no fused
//! multiply-add), so a lane finds exactly the hit, t, u and v that the scalar test
//! finds for its triangle; the scalar test's early exits become one mask, so a leaf
//! costs no branch per triangle.
//!
//! [`ray_triangle_edges`]: crate::objects::ray_triangle_edges

use glam::{Vec3, Vec4};

/// Triangles per pack: the lanes of a [`Vec4`].
pub(super) const PACK: usize = 4;

/// Four triangles, one per lane: v0, e1 = v1 - v0 and e2 = v2 - v0 per axis, and the
/// triangles' indices in the scene. Unused lanes hold a degenerate triangle (all zero),
/// which no ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct TrianglePack {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    pub(super) ids: [u32; 4],
}

/// A ray as a pack reads it: each coordinate of its origin and direction in all four
/// lanes.
pub(super) struct PackRay {
    origin: [Vec4; 3],
    dir: [Vec4; 3],
}

impl PackRay {
    pub(super) fn new(origin: Vec3, dir: Vec3) -> PackRay {
        PackRay {
            origin: [0, 1, 2].map(|a| Vec4::splat(origin[a])),
            dir: [0, 1, 2].map(|a| Vec4::splat(dir[a])),
        }
    }
}

/// Per lane of a pack: the hit distance t and barycentrics u, v, valid in the lanes
/// whose bit is set in `hits`.
pub(super) struct PackHits {
    pub(super) t: Vec4,
    pub(super) u: Vec4,
    pub(super) v: Vec4,
    pub(super) hits: u32,
}

/// The cross product a x b per lane, in [`Vec3::cross`]'s order.
#[inline(always)]
fn cross(a: &[Vec4; 3], b: &[Vec4; 3]) -> [Vec4; 3] {
    [
        a[1] * b[2] - b[1] * a[2],
        a[2] * b[0] - b[2] * a[0],
        a[0] * b[1] - b[0] * a[1],
    ]
}

/// The dot product per lane, in [`Vec3::dot`]'s order.
#[inline(always)]
fn dot(a: &[Vec4; 3], b: &[Vec4; 3]) -> Vec4 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl TrianglePack {
    /// Packs up to four triangles given as (v0, e1, e2) with their scene indices.
    pub(super) fn new(triangles: &[([Vec3; 3], u32)]) -> TrianglePack {
        assert!((1..=PACK).contains(&triangles.len()));
        let mut pack = TrianglePack {
            v0: [Vec4::ZERO; 3],
            e1: [Vec4::ZERO; 3],
            e2: [Vec4::ZERO; 3],
            ids: [u32::MAX; 4],
        };
        for (lane, &([v0, e1, e2], id)) in triangles.iter().enumerate() {
            for axis in 0..3 {
                pack.v0[axis][lane] = v0[axis];
                pack.e1[axis][lane] = e1[axis];
                pack.e2[axis][lane] = e2[axis];
            }
            pack.ids[lane] = id;
        }
        pack
    }

    /// [`ray_triangle_edges`](crate::objects::ray_triangle_edges) in every lane.
    #[inline(always)]
    pub(super) fn intersect(&self, ray: &PackRay) -> PackHits {
        let p = cross(&ray.dir, &self.e2);
        let det = dot(&self.e1, &p);
        let inv = Vec4::ONE / det;
        let s = [0, 1, 2].map(|a| ray.origin[a] - self.v0[a]);
        let u = dot(&s, &p) * inv;
        let q = cross(&s, &self.e1);
        let v = dot(&ray.dir, &q) * inv;
        let t = dot(&self.e2, &q) * inv;
        // The scalar test's exits, as masks: a degenerate triangle, u outside [0, 1],
        // v < 0 or u + v > 1 (NaN compares false in both, as it does there).
        let degenerate = det.abs().cmplt(Vec4::splat(1e-12));
        let u_inside = u.cmpge(Vec4::ZERO) & u.cmple(Vec4::ONE);
        let outside = v.cmplt(Vec4::ZERO) | (u + v).cmpgt(Vec4::ONE);
        let hits = u_inside.bitmask() & !degenerate.bitmask() & !outside.bitmask();
        PackHits { t, u, v, hits }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::ray_triangle_edges;
    use relume_base::rng::Counter;

    /// Every lane gives the scalar test's answer, bit for bit: random triangles and
    /// rays, rays through edges and vertices, degenerate and tiny triangles, and
    /// non-finite inputs.
    #[test]
    fn lanes_equal_the_scalar_test_bit_for_bit() {
        let mut rng = Counter::new(&[11, 0x1eaf]);
        let mut point = |scale: f32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * (2.0 * scale) - scale
        };
        let mut triangles: Vec<[Vec3; 3]> = (0..4000)
            .map(|_| [point(1.0), point(0.5), point(0.5)])
            .collect();
        triangles.extend([
            [Vec3::ZERO; 3],
            [Vec3::ONE, Vec3::X * 1e-7, Vec3::Y * 1e-7],
            [Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            [Vec3::ZERO, Vec3::X, Vec3::Y],
            [Vec3::splat(f32::NAN), Vec3::X, Vec3::Y],
            [Vec3::ZERO, Vec3::splat(f32::INFINITY), Vec3::Y],
        ]);
        let mut hits = 0;
        for (i, chunk) in triangles.chunks(4).enumerate() {
            let items: Vec<([Vec3; 3], u32)> = chunk
                .iter()
                .enumerate()
                .map(|(k, &tri)| (tri, (4 * i + k) as u32))
                .collect();
            let pack = TrianglePack::new(&items);
            for r in 0..8 {
                let [v0, e1, e2] = chunk[r % chunk.len()];
                // Aimed at a vertex, an edge's middle, the inside, or anywhere.
                let target = match r {
                    0 => v0,
                    1 => v0 + e1 * 0.5,
                    2 => v0 + e1 * 0.25 + e2 * 0.25,
                    3 => v0 + e2,
                    _ => point(1.0),
                };
                let origin = if r == 7 { Vec3::NAN } else { point(3.0) };
                let dir = (target - origin).normalize_or(Vec3::Z);
                let lanes = pack.intersect(&PackRay::new(origin, dir));
                for (lane, &([v0, e1, e2], _)) in items.iter().enumerate() {
                    let scalar = ray_triangle_edges(origin, dir, v0, e1, e2);
                    let lane_hit = (lanes.hits >> lane) & 1 != 0;
                    assert_eq!(lane_hit, scalar.is_some(), "triangle {i}.{lane}, ray {r}");
                    if let Some((t, u, v)) = scalar {
                        let got = (lanes.t[lane], lanes.u[lane], lanes.v[lane]);
                        assert_eq!(
                            [got.0, got.1, got.2].map(f32::to_bits),
                            [t, u, v].map(f32::to_bits),
                            "triangle {i}.{lane}, ray {r}"
                        );
                        hits += 1;
                    }
                }
                // Unused lanes never hit.
                assert_eq!(lanes.hits >> chunk.len(), 0);
            }
        }
        assert!(hits > 2000, "only {hits} hits");
    }
}
