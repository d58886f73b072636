//! A bounding volume hierarchy over a scene's triangles: built by the binned
//! surface-area heuristic and collapsed into four-wide nodes (module `build`), whose four
//! child boxes a ray tests at once in 4-lane vectors ([`Vec4`]: SSE on x86-64). The
//! traversal is iterative with a fixed stack: nearest hit (hit children visited
//! near-first) and any-hit for shadow rays.
//!
//! A leaf's triangles are stored four to a pack (`leaf.rs`) and intersected four at a
//! time, each lane with the arithmetic of [`super::ray_triangle_edges`] (that of
//! [`super::ray_triangle`]), so a BVH hit equals the brute-force hit bit for bit; ties
//! in t go to the smaller triangle index in both. The box tests only cull, conservatively:
//! node boxes are padded by a millionth of the scene's size, exits are widened by a few
//! ulps so that rounding in the slab test never culls a triangle lying on a box face,
//! and infinite inverse directions are clamped to the largest finite float, so that no
//! slab test gives NaN. A ray lying in a face plane of a box
//! then enters or leaves it there (t = 0); padding keeps every triangle off that plane,
//! so culling it is harmless. Direction components under about 3e-39 get an inverse
//! that is too small, which can shorten a box only beyond t ~ 1e26.

mod build;
mod leaf;

use super::geometry::{Aabb, Triangle};
use build::{MAX_DEPTH, WideNode};
use glam::{Vec3, Vec4};
use leaf::{PACK, PackRay, TrianglePack};

/// Traversal stack entries: a wide node visit pops one entry and pushes at most four.
const STACK: usize = 3 * MAX_DEPTH + 4;
/// Widens slab exits: 2 gamma(3) of PBRT (3rd ed., Sec. 3.9.2).
const EXIT_WIDENING: f32 =
    1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);
/// Inverse direction components beyond this are clamped to it (see the module docs).
const INVERSE_LIMIT: f32 = f32::MAX;

/// The hierarchy of a [`super::VirtualScene`]; see the module docs. `Default` is the
/// empty, unbuilt hierarchy.
#[derive(Clone, Default, PartialEq)]
pub struct Bvh {
    /// Wide nodes, the root first.
    nodes: Vec<WideNode>,
    /// The leaves' triangles, four to a pack (a leaf of n triangles has n / 4 packs,
    /// rounded up).
    packs: Vec<TrianglePack>,
    triangle_count: usize,
    /// The exact bounds of the vertices of the triangles in the tree (node boxes are
    /// padded).
    bounds: Aabb,
    depth: usize,
}

impl std::fmt::Debug for Bvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bvh")
            .field("nodes", &self.nodes.len())
            .field("triangles", &self.triangle_count)
            .field("depth", &self.depth)
            .finish()
    }
}

/// A child to visit: a wide node (`count` 0) or a leaf, and where the ray enters its box.
#[derive(Clone, Copy, Default)]
struct Visit {
    index: u32,
    count: u32,
    near: f32,
}

impl Bvh {
    /// Builds the hierarchy over `triangles` (single-threaded and deterministic). Empty for
    /// an empty slice.
    pub fn build(triangles: &[Triangle]) -> Bvh {
        match build::build(triangles) {
            Some(tree) => Bvh {
                nodes: tree.nodes,
                packs: tree.packs,
                triangle_count: triangles.len(),
                bounds: tree.bounds,
                depth: tree.depth,
            },
            None => Bvh::default(),
        }
    }

    /// True when the hierarchy was built over `triangle_count` triangles.
    pub fn is_built_for(&self, triangle_count: usize) -> bool {
        !self.nodes.is_empty() && self.triangle_count == triangle_count
    }

    /// The bounds of the triangles it was built over ([`Aabb::EMPTY`] when not built).
    pub fn bounds(&self) -> Aabb {
        if self.nodes.is_empty() {
            Aabb::EMPTY
        } else {
            self.bounds
        }
    }

    /// Number of wide nodes (0 when not built).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Levels of wide nodes below the root.
    pub fn depth(&self) -> usize {
        self.depth
    }

    /// The nearest hit (t, triangle, u, v) with t in (t_min, t_max); equal t goes to the
    /// smaller triangle index.
    pub fn nearest(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, u32, f32, f32)> {
        if self.nodes.is_empty() {
            return None;
        }
        let ray = SlabRay::new(origin, dir);
        let lanes = PackRay::new(origin, dir);
        let mut best_t = t_max;
        let mut best: Option<(u32, f32, f32)> = None;
        let mut stack = Stack::new();
        let mut at = Visit::default();
        loop {
            if at.count == 0 {
                let node = &self.nodes[at.index as usize];
                let (near, hits) = ray.hits(node, t_min, best_t);
                if hits != 0 {
                    // Push the hit children far to near; visit the nearest now.
                    let order = near_first(near, hits);
                    let visit = |k: usize| Visit {
                        index: node.index[k],
                        count: node.count[k],
                        near: near[k],
                    };
                    for &k in order.children[1..order.len].iter().rev() {
                        stack.push(visit(k));
                    }
                    at = visit(order.children[0]);
                    continue;
                }
            } else {
                let first = at.index as usize;
                for pack in &self.packs[first..first + (at.count as usize).div_ceil(PACK)] {
                    let found = pack.intersect(&lanes);
                    let mut hits = found.hits & found.t.cmpgt(Vec4::splat(t_min)).bitmask();
                    // In lane order, as the scalar loop over the leaf's triangles.
                    while hits != 0 {
                        let k = hits.trailing_zeros() as usize;
                        hits &= hits - 1;
                        let (t, id) = (found.t[k], pack.ids[k]);
                        let closer = t < best_t || (t == best_t && best.is_some_and(|b| id < b.0));
                        if closer {
                            best_t = t;
                            best = Some((id, found.u[k], found.v[k]));
                        }
                    }
                }
            }
            // Pop the next child that may still hold a hit at or before best_t.
            loop {
                let Some(next) = stack.pop() else {
                    return best.map(|(id, u, v)| (best_t, id, u, v));
                };
                if next.near <= best_t {
                    at = next;
                    break;
                }
            }
        }
    }

    /// True when any triangle is hit with t in (t_min, t_max).
    pub fn any_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let ray = SlabRay::new(origin, dir);
        let lanes = PackRay::new(origin, dir);
        let mut stack = Stack::new();
        stack.push(Visit::default());
        while let Some(at) = stack.pop() {
            if at.count == 0 {
                let node = &self.nodes[at.index as usize];
                let (_, hits) = ray.hits(node, t_min, t_max);
                for k in 0..4 {
                    if hits & (1 << k) != 0 {
                        stack.push(Visit {
                            index: node.index[k],
                            count: node.count[k],
                            near: 0.0,
                        });
                    }
                }
                continue;
            }
            let first = at.index as usize;
            for pack in &self.packs[first..first + (at.count as usize).div_ceil(PACK)] {
                let found = pack.intersect(&lanes);
                let within = found.t.cmpgt(Vec4::splat(t_min)) & found.t.cmplt(Vec4::splat(t_max));
                if found.hits & within.bitmask() != 0 {
                    return true;
                }
            }
        }
        false
    }
}

/// The hit children of a wide node, nearest first.
struct NearFirst {
    children: [usize; 4],
    len: usize,
}

/// The children whose bits are set in `hits` (at least one), by increasing `near`;
/// equal entries keep the children's order. An insertion sort: at most four.
#[inline(always)]
fn near_first(near: Vec4, hits: u32) -> NearFirst {
    let mut order = NearFirst {
        children: [0; 4],
        len: 0,
    };
    for k in 0..4 {
        if hits & (1 << k) == 0 {
            continue;
        }
        let mut at = order.len;
        while at > 0 && near[order.children[at - 1]] > near[k] {
            order.children[at] = order.children[at - 1];
            at -= 1;
        }
        order.children[at] = k;
        order.len += 1;
    }
    order
}

/// The traversal stack: [`STACK`] entries, left uninitialized (a zeroed array cost a
/// `memset` per ray).
struct Stack {
    entries: [std::mem::MaybeUninit<Visit>; STACK],
    len: usize,
}

impl Stack {
    #[inline(always)]
    fn new() -> Stack {
        Stack {
            entries: [const { std::mem::MaybeUninit::uninit() }; STACK],
            len: 0,
        }
    }

    /// Panics past [`STACK`] entries, which a tree of at most [`MAX_DEPTH`] levels
    /// cannot reach.
    #[inline(always)]
    fn push(&mut self, visit: Visit) {
        self.entries[self.len].write(visit);
        self.len += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<Visit> {
        self.len = self.len.checked_sub(1)?;
        // SAFETY: entries below the length were written by `push`.
        Some(unsafe { self.entries[self.len].assume_init() })
    }
}

/// A ray as the slab test of four boxes reads it: origin and clamped inverse direction,
/// each coordinate in all four lanes, and per axis the side of a box (0 its minimum, 1
/// its maximum) where the ray enters it.
struct SlabRay {
    origin: [Vec4; 3],
    inverse: [Vec4; 3],
    entry_side: [usize; 3],
}

impl SlabRay {
    fn new(origin: Vec3, dir: Vec3) -> SlabRay {
        let inverse = dir
            .recip()
            .clamp(Vec3::splat(-INVERSE_LIMIT), Vec3::splat(INVERSE_LIMIT));
        SlabRay {
            origin: [0, 1, 2].map(|a| Vec4::splat(origin[a])),
            inverse: [0, 1, 2].map(|a| Vec4::splat(inverse[a])),
            entry_side: [0, 1, 2].map(|a| inverse[a].is_sign_negative() as usize),
        }
    }

    /// Where the ray enters each child's box within [t_min, t_max], and the bits of the
    /// live children it meets there. The entry plane's distance is the smaller of the
    /// two planes' (rounding keeps their order, and every box has its minimum at most
    /// its maximum: triangles with NaN coordinates stay out of the tree), so no min or
    /// max is needed per axis.
    #[inline(always)]
    fn hits(&self, node: &WideNode, t_min: f32, t_max: f32) -> (Vec4, u32) {
        let mut near = Vec4::splat(t_min);
        let mut exit = Vec4::INFINITY;
        for axis in 0..3 {
            let side = self.entry_side[axis];
            let entry = node.planes[side][axis];
            let leave = node.planes[1 - side][axis];
            near = near.max((entry - self.origin[axis]) * self.inverse[axis]);
            exit = exit.min((leave - self.origin[axis]) * self.inverse[axis]);
        }
        let far = (exit * EXIT_WIDENING).max(exit).min(Vec4::splat(t_max));
        (near, near.cmple(far).bitmask() & node.live)
    }
}

#[cfg(test)]
mod tests;
