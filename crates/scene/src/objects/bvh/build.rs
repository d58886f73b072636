//! Building the arrays a [`Bvh`](super::Bvh) holds ([`Tree`]): a binary hierarchy by the
//! binned surface-area heuristic, then collapsed into the four-wide nodes
//! ([`WideNode`]) that the traversal reads.
//!
//! The binary tree is built top-down (16 centroid bins per axis, leaves of at most 8
//! triangles, costed by the packs of four that hold them, the median below a depth so
//! that ranges keep halving) and flattened in depth-first order. Collapsing opens, from
//! each binary interior node, the largest of its descendants until the node has four
//! children (or only leaves are left), and makes them one wide node; the children stay
//! in the binary order. Each leaf's triangles then go into packs of four. Triangles with
//! a NaN coordinate, which no ray meets, stay out of the tree.

use super::leaf::{PACK, TrianglePack};
use crate::objects::geometry::{Aabb, Triangle};
use glam::{Vec3, Vec4};

/// Deepest wide node below the root (the binary tree's bound, which collapsing can only
/// lower).
pub(super) const MAX_DEPTH: usize = 64;

/// Centroid bins per axis for the surface-area heuristic.
const BINS: usize = 16;
/// Ranges of at most this many triangles may become leaves.
const MAX_LEAF: usize = 8;
/// Below this depth splits follow the SAH; deeper, the median, which halves every range,
/// so no leaf lies deeper than `SAH_DEPTH + 32` (`MAX_DEPTH`).
const SAH_DEPTH: usize = 32;
const _: () = assert!(SAH_DEPTH + 32 <= MAX_DEPTH);
/// Relative cost of a node visit against a leaf pack's test (four triangles at once) in
/// the SAH.
const TRAVERSAL_COST: f32 = 1.0;
/// The packs holding `triangles` triangles: what a leaf of them costs in the SAH.
fn packs(triangles: usize) -> f32 {
    triangles.div_ceil(PACK) as f32
}

/// Four children's boxes, one lane each (structure of arrays), and what they are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct WideNode {
    /// The children's padded boxes: `planes[0][axis]` their minima along axis x, y or
    /// z, `planes[1][axis]` their maxima.
    pub(super) planes: [[Vec4; 3]; 2],
    /// Per child: the wide node's index (interior), or its first pack in `packs`
    /// (leaf).
    pub(super) index: [u32; 4],
    /// Per child: 0 for an interior node, else the leaf's triangles.
    pub(super) count: [u32; 4],
    /// Bit k set when child k exists.
    pub(super) live: u32,
}

/// The built hierarchy's arrays, which a [`Bvh`](super::Bvh) holds.
pub(super) struct Tree {
    /// Wide nodes, the root first.
    pub(super) nodes: Vec<WideNode>,
    /// The leaves' triangles, four to a pack.
    pub(super) packs: Vec<TrianglePack>,
    /// The exact bounds of the vertices of the triangles in the tree.
    pub(super) bounds: Aabb,
    /// Levels of wide nodes below the root.
    pub(super) depth: usize,
}

/// A node of the binary tree, in depth-first order (the first child follows its parent).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Node {
    /// The padded box.
    min: Vec3,
    max: Vec3,
    /// Interior: index of the second child. Leaf: first slot in the leaf order.
    offset: u32,
    /// Triangles in the leaf; 0 for interior nodes.
    count: u32,
}

struct Builder<'a> {
    boxes: &'a [Aabb],
    centroids: &'a [Vec3],
    order: Vec<u32>,
    nodes: Vec<Node>,
    pad: Vec3,
}

/// Builds the hierarchy over `triangles` (single-threaded and deterministic); see
/// [`Bvh::build`](super::Bvh::build). `None` when there is nothing to build: no
/// triangles, too many to index, or only ones with a NaN coordinate.
pub(super) fn build(triangles: &[Triangle]) -> Option<Tree> {
    if triangles.is_empty() || triangles.len() >= u32::MAX as usize {
        return None;
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
    // A triangle with a NaN coordinate meets no ray (its test is NaN throughout), and its
    // NaN centroid would scramble the binning: it stays out of the tree.
    let order: Vec<u32> = (0..triangles.len() as u32)
        .filter(|&i| !triangles[i as usize].vertices.iter().any(|v| v.is_nan()))
        .collect();
    if order.is_empty() {
        return None;
    }
    let mut scene = Aabb::EMPTY;
    for &i in &order {
        scene.grow(boxes[i as usize].min);
        scene.grow(boxes[i as usize].max);
    }
    // Infinite vertices would make every box infinite: pad by a finite amount.
    let size = (scene.max - scene.min)
        .max(scene.min.abs())
        .max(scene.max.abs())
        .max_element();
    let pad = Vec3::splat(if size.is_finite() { size * 1e-6 } else { 0.0 } + 1e-12);
    let mut b = Builder {
        boxes: &boxes,
        centroids: &centroids,
        nodes: Vec::with_capacity(order.len() / 2 + 1),
        order,
        pad,
    };
    b.build(0, b.order.len(), 0);
    let mut nodes = Vec::with_capacity(b.nodes.len() / 2 + 1);
    let root = &b.nodes[0];
    let depth = if root.count > 0 {
        // A single leaf: one wide node with one child.
        nodes.push(WideNode::new(&[*root]));
        0
    } else {
        collapse(&b.nodes, 0, &mut nodes)
    };
    // Each leaf's triangles, in leaf order, four to a pack; the leaf child then
    // indexes its first pack.
    let mut packs = Vec::with_capacity(triangles.len() / 2 + 1);
    for node in &mut nodes {
        for k in 0..4 {
            let count = node.count[k] as usize;
            if node.live & (1 << k) == 0 || count == 0 {
                continue;
            }
            let first = node.index[k] as usize;
            node.index[k] = packs.len() as u32;
            let leaf: Vec<([Vec3; 3], u32)> = b.order[first..first + count]
                .iter()
                .map(|&i| {
                    let v = &triangles[i as usize].vertices;
                    ([v[0], v[1] - v[0], v[2] - v[0]], i)
                })
                .collect();
            packs.extend(leaf.chunks(PACK).map(TrianglePack::new));
        }
    }
    Some(Tree {
        nodes,
        packs,
        bounds: scene,
        depth,
    })
}

impl WideNode {
    /// The wide node over up to four binary nodes (its children); children that are
    /// interior nodes get their wide index filled in by [`collapse`].
    fn new(children: &[Node]) -> WideNode {
        assert!((1..=4).contains(&children.len()));
        let mut planes = [[Vec4::ZERO; 3]; 2];
        let mut index = [0; 4];
        let mut count = [0; 4];
        for (k, child) in children.iter().enumerate() {
            for (side, corner) in [child.min, child.max].into_iter().enumerate() {
                for (axis, plane) in planes[side].iter_mut().enumerate() {
                    plane[k] = corner[axis];
                }
            }
            (index[k], count[k]) = (child.offset, child.count);
        }
        WideNode {
            planes,
            index,
            count,
            live: (1 << children.len()) - 1,
        }
    }
}

/// Collapses the binary subtree at interior node `at` into wide nodes appended to
/// `wide` (the subtree's root first); returns the depth of its deepest wide node below
/// that root.
fn collapse(binary: &[Node], at: usize, wide: &mut Vec<WideNode>) -> usize {
    let mut children = vec![at + 1, binary[at].offset as usize];
    while children.len() < 4 {
        // Open the interior child of the largest box (the first of equals).
        let mut open: Option<(usize, f32)> = None;
        for (k, &c) in children.iter().enumerate() {
            let area = half_area(&Aabb {
                min: binary[c].min,
                max: binary[c].max,
            });
            if binary[c].count == 0 && open.is_none_or(|(_, a)| area > a) {
                open = Some((k, area));
            }
        }
        let Some((k, _)) = open else { break };
        let c = children[k];
        children[k] = c + 1;
        children.insert(k + 1, binary[c].offset as usize);
    }
    let nodes: Vec<Node> = children.iter().map(|&c| binary[c]).collect();
    let index = wide.len();
    wide.push(WideNode::new(&nodes));
    let mut depth = 0;
    for (k, &c) in children.iter().enumerate() {
        if binary[c].count == 0 {
            wide[index].index[k] = wide.len() as u32;
            depth = depth.max(1 + collapse(binary, c, wide));
        }
    }
    depth
}

impl Builder<'_> {
    /// Builds the node for `order[start..end]` and its subtree; returns its index.
    fn build(&mut self, start: usize, end: usize, depth: usize) -> u32 {
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
            max: bounds.max + self.pad,
            offset: start as u32,
            count: (end - start) as u32,
        });
        let count = end - start;
        if count <= PACK {
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
                right_cost[k] = half_area(&acc.0) * packs(acc.1 as usize);
            }
            let mut left = (Aabb::EMPTY, 0u32);
            for k in 1..BINS {
                grow_by(&mut left, &bins[k - 1]);
                let right_count = (end - start) as u32 - left.1;
                if left.1 == 0 || right_count == 0 {
                    continue;
                }
                let cost = half_area(&left.0) * packs(left.1 as usize) + right_cost[k];
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, k));
                }
            }
        }
        let (cost, axis, split_bin) = best?;
        let area = half_area(bounds);
        let split_cost = TRAVERSAL_COST + if area > 0.0 { cost / area } else { 0.0 };
        if split_cost >= packs(end - start) && end - start <= MAX_LEAF {
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
