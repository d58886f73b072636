//! A bounding volume hierarchy over a scene's triangles: binned surface-area heuristic
//! (16 bins per axis), nodes flattened in depth-first order (the first child follows its
//! parent), leaves of at most 8 triangles, iterative traversal with a fixed stack, nearest
//! hit (children visited near-first) and any-hit for shadow rays.
//!
//! Triangles are intersected by [`ray_triangle_edges`] on edges stored in leaf order,
//! the same arithmetic as [`super::ray_triangle`], so a BVH hit equals the brute-force hit
//! bit for bit; ties in t go to the smaller triangle index in both. Node boxes are padded
//! by a millionth of the scene's size and exits widened by a few ulps, so that rounding in
//! the slab test never culls a triangle lying on a box face (a box's own faces do).

use super::{Aabb, Triangle, ray_triangle_edges};
use glam::Vec3;

/// Centroid bins per axis for the surface-area heuristic.
const BINS: usize = 16;
/// Ranges of at most this many triangles may become leaves.
const MAX_LEAF: usize = 8;
/// Below this depth splits follow the SAH; deeper, the median, which halves every range,
/// so no leaf lies deeper than `SAH_DEPTH + 32` and the traversal stack cannot overflow.
const SAH_DEPTH: usize = 32;
/// Traversal stack entries (at most one per level above the current node).
const STACK: usize = 72;
/// Relative cost of a node visit against a triangle test in the SAH.
const TRAVERSAL_COST: f32 = 1.0;
/// Widens slab exits: 2 gamma(3) of PBRT (3rd ed., Sec. 3.9.2).
const EXIT_WIDENING: f32 =
    1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

#[derive(Clone, Copy, Debug, PartialEq)]
struct Node {
    min: Vec3,
    /// Interior: index of the second child (the first is the next node). Leaf: first slot
    /// in `edges` and `ids`.
    offset: u32,
    max: Vec3,
    /// Triangles in the leaf; 0 for interior nodes.
    count: u32,
}

/// The hierarchy of a [`super::VirtualScene`]; see the module docs. `Default` is the
/// empty, unbuilt hierarchy.
#[derive(Clone, Default, PartialEq)]
pub struct Bvh {
    nodes: Vec<Node>,
    /// Per leaf slot: v0, e1 = v1 - v0, e2 = v2 - v0 of the triangle.
    edges: Vec<[Vec3; 3]>,
    /// Per leaf slot: the triangle's index in the scene.
    ids: Vec<u32>,
    /// The exact bounds of all vertices (node boxes are padded).
    bounds: Aabb,
    depth: usize,
}

impl std::fmt::Debug for Bvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bvh")
            .field("nodes", &self.nodes.len())
            .field("triangles", &self.ids.len())
            .field("depth", &self.depth)
            .finish()
    }
}

struct Builder<'a> {
    boxes: &'a [Aabb],
    centroids: &'a [Vec3],
    order: Vec<u32>,
    nodes: Vec<Node>,
    pad: Vec3,
    depth: usize,
}

impl Bvh {
    /// Builds the hierarchy over `triangles` (single-threaded and deterministic). Empty for
    /// an empty slice.
    pub fn build(triangles: &[Triangle]) -> Bvh {
        if triangles.is_empty() || triangles.len() >= u32::MAX as usize {
            return Bvh::default();
        }
        let boxes: Vec<Aabb> = triangles
            .iter()
            .map(|t| {
                let mut b = Aabb::EMPTY;
                t.vertices.iter().for_each(|&v| b.grow(v));
                b
            })
            .collect();
        let centroids: Vec<Vec3> = boxes.iter().map(Aabb::center).collect();
        let mut scene = Aabb::EMPTY;
        for b in &boxes {
            scene.grow(b.min);
            scene.grow(b.max);
        }
        let bounds = scene;
        // Non-finite vertices would make every box non-finite: pad by a finite amount.
        let size = (scene.max - scene.min)
            .max(scene.min.abs())
            .max(scene.max.abs())
            .max_element();
        let pad = Vec3::splat(if size.is_finite() { size * 1e-6 } else { 0.0 } + 1e-12);
        let mut b = Builder {
            boxes: &boxes,
            centroids: &centroids,
            order: (0..triangles.len() as u32).collect(),
            nodes: Vec::with_capacity(triangles.len() / 2 + 1),
            pad,
            depth: 0,
        };
        b.build(0, triangles.len(), 0);
        let edges = b
            .order
            .iter()
            .map(|&i| {
                let v = &triangles[i as usize].vertices;
                [v[0], v[1] - v[0], v[2] - v[0]]
            })
            .collect();
        Bvh {
            nodes: b.nodes,
            edges,
            ids: b.order,
            bounds,
            depth: b.depth,
        }
    }

    /// True when the hierarchy was built over `triangle_count` triangles.
    pub fn is_built_for(&self, triangle_count: usize) -> bool {
        !self.nodes.is_empty() && self.ids.len() == triangle_count
    }

    /// The bounds of the triangles it was built over ([`Aabb::EMPTY`] when not built).
    pub fn bounds(&self) -> Aabb {
        if self.nodes.is_empty() {
            Aabb::EMPTY
        } else {
            self.bounds
        }
    }

    /// Number of nodes (0 when not built).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Levels below the root of the deepest leaf.
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
        let inv = dir.recip();
        let nodes = &self.nodes;
        nodes
            .first()
            .and_then(|root| slab(root, origin, inv, t_min, t_max))?;
        let mut best_t = t_max;
        let mut best: Option<(u32, f32, f32)> = None;
        let mut stack = [(0u32, 0f32); STACK];
        let mut sp = 0;
        let mut at = 0usize;
        loop {
            let node = &nodes[at];
            if node.count == 0 {
                let (a, b) = (at + 1, node.offset as usize);
                let near_a = slab(&nodes[a], origin, inv, t_min, best_t);
                let near_b = slab(&nodes[b], origin, inv, t_min, best_t);
                match (near_a, near_b) {
                    (Some(ta), Some(tb)) => {
                        let (first, second, t_second) =
                            if tb < ta { (b, a, ta) } else { (a, b, tb) };
                        stack[sp] = (second as u32, t_second);
                        sp += 1;
                        at = first;
                        continue;
                    }
                    (Some(_), None) => {
                        at = a;
                        continue;
                    }
                    (None, Some(_)) => {
                        at = b;
                        continue;
                    }
                    (None, None) => {}
                }
            } else {
                let first = node.offset as usize;
                for slot in first..first + node.count as usize {
                    let [v0, e1, e2] = self.edges[slot];
                    let Some((t, u, v)) = ray_triangle_edges(origin, dir, v0, e1, e2) else {
                        continue;
                    };
                    let id = self.ids[slot];
                    let closer = t < best_t || (t == best_t && best.is_some_and(|b| id < b.0));
                    if t > t_min && closer {
                        best_t = t;
                        best = Some((id, u, v));
                    }
                }
            }
            // Pop the next subtree that may still hold a hit at or before best_t.
            loop {
                if sp == 0 {
                    return best.map(|(id, u, v)| (best_t, id, u, v));
                }
                sp -= 1;
                let (next, near) = stack[sp];
                if near <= best_t {
                    at = next as usize;
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
        let inv = dir.recip();
        let mut stack = [0u32; STACK];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let at = stack[sp] as usize;
            let node = &self.nodes[at];
            if slab(node, origin, inv, t_min, t_max).is_none() {
                continue;
            }
            if node.count == 0 {
                stack[sp] = node.offset;
                stack[sp + 1] = at as u32 + 1;
                sp += 2;
                continue;
            }
            let first = node.offset as usize;
            for slot in first..first + node.count as usize {
                let [v0, e1, e2] = self.edges[slot];
                if let Some((t, _, _)) = ray_triangle_edges(origin, dir, v0, e1, e2)
                    && t > t_min
                    && t < t_max
                {
                    return true;
                }
            }
        }
        false
    }
}

/// The entry parameter of the ray into `node`'s box within [t_min, t_max], if it meets it.
#[inline(always)]
fn slab(node: &Node, origin: Vec3, inv_dir: Vec3, t_min: f32, t_max: f32) -> Option<f32> {
    let t0 = (node.min - origin) * inv_dir;
    let t1 = (node.max - origin) * inv_dir;
    let near = t0.min(t1).max_element().max(t_min);
    let exit = t0.max(t1).min_element();
    let far = (exit * EXIT_WIDENING).max(exit).min(t_max);
    (near <= far).then_some(near)
}

impl Builder<'_> {
    /// Builds the node for `order[start..end]` and its subtree; returns its index.
    fn build(&mut self, start: usize, end: usize, depth: usize) -> u32 {
        self.depth = self.depth.max(depth);
        let index = self.nodes.len();
        let mut bounds = Aabb::EMPTY;
        let mut centroid_bounds = Aabb::EMPTY;
        for &i in &self.order[start..end] {
            let b = &self.boxes[i as usize];
            bounds.grow(b.min);
            bounds.grow(b.max);
            centroid_bounds.grow(self.centroids[i as usize]);
        }
        self.nodes.push(Node {
            min: bounds.min - self.pad,
            offset: start as u32,
            max: bounds.max + self.pad,
            count: (end - start) as u32,
        });
        let count = end - start;
        if count <= 2 {
            return index as u32;
        }
        let sah = if depth < SAH_DEPTH {
            self.sah_split(start, end, &bounds, &centroid_bounds)
        } else {
            None
        };
        let mid = match sah {
            Some(Some(mid)) => mid,
            // The SAH prefers a leaf, or the range is small and cannot be split usefully.
            _ if count <= MAX_LEAF => return index as u32,
            _ => self.median_split(start, end, &centroid_bounds),
        };
        self.build(start, mid, depth + 1);
        let second = self.build(mid, end, depth + 1);
        let node = &mut self.nodes[index];
        node.offset = second;
        node.count = 0;
        index as u32
    }

    /// `Some(Some(mid))` for the best binned-SAH split (partitioning `order`),
    /// `Some(None)` when a leaf is cheaper, `None` when all centroids coincide.
    fn sah_split(
        &mut self,
        start: usize,
        end: usize,
        bounds: &Aabb,
        centroids: &Aabb,
    ) -> Option<Option<usize>> {
        let extent = centroids.max - centroids.min;
        let mut best: Option<(f32, usize, usize)> = None; // cost, axis, first bin on the right
        for axis in 0..3 {
            if extent[axis].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
                || !extent[axis].is_finite()
            {
                continue;
            }
            let mut bins = [(Aabb::EMPTY, 0u32); BINS];
            for &i in &self.order[start..end] {
                let bin = bin_of(
                    self.centroids[i as usize][axis],
                    centroids.min[axis],
                    extent[axis],
                );
                let b = &self.boxes[i as usize];
                bins[bin].0.grow(b.min);
                bins[bin].0.grow(b.max);
                bins[bin].1 += 1;
            }
            // right_cost[k]: area * count of bins k..BINS.
            let mut right_cost = [0f32; BINS];
            let mut acc = (Aabb::EMPTY, 0u32);
            for k in (1..BINS).rev() {
                grow_by(&mut acc, &bins[k]);
                right_cost[k] = half_area(&acc.0) * acc.1 as f32;
            }
            let mut left = (Aabb::EMPTY, 0u32);
            for k in 1..BINS {
                grow_by(&mut left, &bins[k - 1]);
                let right_count = (end - start) as u32 - left.1;
                if left.1 == 0 || right_count == 0 {
                    continue;
                }
                let cost = half_area(&left.0) * left.1 as f32 + right_cost[k];
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, k));
                }
            }
        }
        let (cost, axis, split_bin) = best?;
        let area = half_area(bounds);
        let split_cost = TRAVERSAL_COST + if area > 0.0 { cost / area } else { 0.0 };
        if split_cost >= (end - start) as f32 && end - start <= MAX_LEAF {
            return Some(None);
        }
        let (lo, ext) = (centroids.min[axis], extent[axis]);
        let cs = self.centroids;
        let mid = start
            + partition(&mut self.order[start..end], |i| {
                bin_of(cs[i as usize][axis], lo, ext) < split_bin
            });
        if mid == start || mid == end {
            return None;
        }
        Some(Some(mid))
    }

    /// Splits `order[start..end]` in half by centroid along the widest axis (ties by
    /// triangle index), so that every level halves the range.
    fn median_split(&mut self, start: usize, end: usize, centroids: &Aabb) -> usize {
        let axis = (centroids.max - centroids.min).max_position();
        let cs = self.centroids;
        let mid = (end - start) / 2;
        self.order[start..end].select_nth_unstable_by(mid, |&a, &b| {
            cs[a as usize][axis]
                .total_cmp(&cs[b as usize][axis])
                .then(a.cmp(&b))
        });
        start + mid
    }
}

/// The bin of a centroid coordinate `c` in [lo, lo + extent].
#[inline]
fn bin_of(c: f32, lo: f32, extent: f32) -> usize {
    (((c - lo) / extent * BINS as f32) as usize).min(BINS - 1)
}

fn grow_by(acc: &mut (Aabb, u32), bin: &(Aabb, u32)) {
    if bin.1 > 0 {
        acc.0.grow(bin.0.min);
        acc.0.grow(bin.0.max);
        acc.1 += bin.1;
    }
}

/// Half the surface area of a box (0 for an empty one).
fn half_area(b: &Aabb) -> f32 {
    let d = (b.max - b.min).max(Vec3::ZERO);
    d.x * d.y + d.y * d.z + d.z * d.x
}

/// Moves the elements satisfying `left` to the front; returns how many there are.
fn partition(items: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let mut first_right = 0;
    for k in 0..items.len() {
        if left(items[k]) {
            items.swap(first_right, k);
            first_right += 1;
        }
    }
    first_right
}

#[cfg(test)]
#[path = "bvh_tests.rs"]
mod tests;
