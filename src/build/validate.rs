//! [`Bvh2::validate`]: every invariant of a tree, checked against its primitives, with the first
//! violation named; and the tree's depth and leaf statistics.

use super::prims::{Primitives, usable_bounds};
use super::{Bvh2, Node};
use crate::geometry::{Aabb, Triangle, Triangles};
use alloc::vec;
use alloc::vec::Vec;

/// Reusable buffers of [`checked_pre_order`]: the order it writes, and its scratch.
#[derive(Clone, Debug, Default)]
pub(crate) struct Walk {
    /// The reachable nodes in pre-order (a parent before its children, left before right).
    pub order: Vec<u32>,
    seen: Vec<bool>,
    stack: Vec<u32>,
}

impl Walk {
    /// Whether node `i` was reached by the last walk (`false` past the tree's end).
    #[inline]
    pub fn reached(&self, i: usize) -> bool {
        self.seen.get(i).copied().unwrap_or(false)
    }
}

/// The nodes reachable from the root of `nodes`, in pre-order, into `w.order` (explicit stack:
/// no recursion, so no depth can overflow it), checking what a pass over a tree that may come
/// from anywhere needs before it indexes with the tree's links: every interior node's child pair
/// in range, every leaf's slot range within `slots`, no node reached twice (which also rules out
/// cycles). `child(parent, child)` is called for each child as it is reached, parents first
/// (depths, parent links). The first break found is returned (`w.order` then holds a prefix).
/// Boxes are not looked at; [`Bvh2::validate`] checks everything, this only the links.
pub(crate) fn checked_pre_order(
    nodes: &[Node],
    slots: usize,
    w: &mut Walk,
    mut child: impl FnMut(u32, u32),
) -> Result<(), ValidateError> {
    let n = nodes.len();
    let Walk { order, seen, stack } = w;
    order.clear();
    stack.clear();
    seen.clear();
    seen.resize(n, false);
    if n == 0 {
        return Ok(());
    }
    stack.push(0);
    seen[0] = true;
    while let Some(i) = stack.pop() {
        order.push(i);
        let node = &nodes[i as usize];
        if node.is_leaf() {
            if node.prim_range().end > slots {
                return Err(ValidateError::SlotsOutOfRange {
                    node: i,
                    first: node.index,
                    count: node.count,
                });
            }
            continue;
        }
        let l = node.left();
        // `>= n - 1`, not `+ 1 >= n`: no overflow where `usize` is 32 bits.
        if l as usize >= n - 1 {
            return Err(ValidateError::ChildOutOfRange { node: i, child: l });
        }
        for c in [l, l + 1] {
            if core::mem::replace(&mut seen[c as usize], true) {
                return Err(ValidateError::NodeReachedTwice { node: c });
            }
            child(i, c);
        }
        // Right pushed first, so the left child is popped (and ordered) first.
        stack.push(l + 1);
        stack.push(l);
    }
    Ok(())
}

/// Shape statistics of a valid tree, from [`Bvh2::validate`].
///
/// ```
/// use strahl::build::{BuildParams, Bvh2};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let s = bvh.validate(&tris[..]).unwrap();
/// assert_eq!((s.primitives, s.nodes), (320, 2 * s.leaves - 1)); // a binary tree
/// assert!(1 <= s.min_leaf_size && s.max_leaf_size <= 8);
/// assert!((s.mean_leaf_size * s.leaves as f32 - 320.0).abs() < 1e-3);
/// assert!(s.mean_leaf_depth <= s.max_depth as f32);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhStats {
    /// Nodes (all reachable).
    pub nodes: u32,
    /// Leaves.
    pub leaves: u32,
    /// Primitives referenced (each exactly once).
    pub primitives: u32,
    /// Depth of the deepest leaf (root = 1; 0 for an empty tree).
    pub max_depth: u32,
    /// Fewest primitives in a leaf (0 for an empty tree).
    pub min_leaf_size: u32,
    /// Most primitives in a leaf.
    pub max_leaf_size: u32,
    /// Primitives per leaf, on average.
    pub mean_leaf_size: f32,
    /// Depth of a leaf, on average.
    pub mean_leaf_depth: f32,
}

/// The first broken invariant [`Bvh2::validate`] found (node, slot and primitive numbers are
/// indices into `nodes`, `prim_indices` and the primitives).
///
/// ```
/// use strahl::build::{BuildParams, Bvh2, ValidateError};
/// let tris = strahl::scene::icosphere(1).to_soup();
/// let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// bvh.prim_indices[0] = 1000; // beyond the 80 triangles
/// assert_eq!(bvh.validate(&tris[..]), Err(ValidateError::PrimOutOfRange { slot: 0, prim: 1000 }));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValidateError {
    /// An interior node's children (`child`, `child + 1`) lie beyond the node array.
    ChildOutOfRange {
        /// The interior node.
        node: u32,
        /// Its left child index.
        child: u32,
    },
    /// A node is reached twice from the root (shared subtree or cycle).
    NodeReachedTwice {
        /// The node.
        node: u32,
    },
    /// A node cannot be reached from the root.
    NodeUnreachable {
        /// The node.
        node: u32,
    },
    /// A node's box has a NaN bound, or an infinite bound where the box is not empty (the empty
    /// box, [`Aabb::EMPTY`](crate::Aabb::EMPTY) with its infinite bounds included, is
    /// [`EmptyNode`](Self::EmptyNode)).
    BoxNotFinite {
        /// The node.
        node: u32,
    },
    /// A node's box is empty (`min > max` on some axis, no bound NaN): a subtree without
    /// primitives. A tree [`Bvh2::refit`] left with a leaf whose every primitive has become
    /// invalid (its box is [`Aabb::EMPTY`](crate::Aabb::EMPTY)) reports this for that leaf, or
    /// for the highest node above it whose subtree has no valid primitive left.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, build::{BuildParams, Bvh2, ValidateError}};
    /// let mut tris = vec![[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::Z, Vec3::ONE, Vec3::Y]];
    /// let p = BuildParams { min_leaf_size: 1, max_leaf_size: 1, ..BuildParams::default() };
    /// let (mut bvh, _) = Bvh2::build(&tris[..], &p).unwrap();
    /// tris[1][0] = Vec3::NAN;
    /// bvh.refit(&tris[..]).unwrap();
    /// let leaf = bvh.nodes.iter().position(|n| n.is_leaf() && n.aabb() == Aabb::EMPTY).unwrap();
    /// assert_eq!(bvh.validate(&tris[..]), Err(ValidateError::EmptyNode { node: leaf as u32 }));
    /// ```
    EmptyNode {
        /// The node.
        node: u32,
    },
    /// A child's box is not inside its parent's.
    ChildNotContained {
        /// The parent.
        node: u32,
        /// The child.
        child: u32,
    },
    /// A leaf's slot range runs past the primitive-index array.
    SlotsOutOfRange {
        /// The leaf.
        node: u32,
        /// Its first slot.
        first: u32,
        /// Its primitive count.
        count: u32,
    },
    /// A slot of the primitive-index array belongs to two leaves.
    SlotSharedByLeaves {
        /// The slot.
        slot: u32,
    },
    /// A slot of the primitive-index array belongs to no leaf.
    SlotUnused {
        /// The slot.
        slot: u32,
    },
    /// A slot holds a primitive index beyond the primitives.
    PrimOutOfRange {
        /// The slot.
        slot: u32,
        /// Its primitive index.
        prim: u32,
    },
    /// The tree references a primitive the builders would leave out (see
    /// [`Primitives`](super::Primitives)).
    InvalidPrimReferenced {
        /// The primitive.
        prim: u32,
    },
    /// A primitive is referenced twice.
    PrimReferencedTwice {
        /// The primitive.
        prim: u32,
    },
    /// A valid primitive is not in the tree.
    PrimMissing {
        /// The primitive.
        prim: u32,
    },
    /// A primitive's box is not inside its leaf's box ([`Bvh2::validate_split`]: does not even
    /// touch it).
    PrimNotContained {
        /// The leaf.
        node: u32,
        /// The primitive.
        prim: u32,
    },
    /// [`Bvh2::validate_split`]: part of a referenced triangle (a vertex, or a piece of its inside)
    /// lies in no box of the leaves that reference it.
    PrimNotCovered {
        /// The primitive.
        prim: u32,
    },
}

impl core::fmt::Display for ValidateError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::ChildOutOfRange { node, child } => {
                write!(f, "node {node}: children {child}, {child}+1 are out of range")
            }
            Self::NodeReachedTwice { node } => write!(f, "node {node} is reached twice from the root"),
            Self::NodeUnreachable { node } => write!(f, "node {node} is not reachable from the root"),
            Self::BoxNotFinite { node } => write!(f, "node {node}: box is not finite"),
            Self::EmptyNode { node } => write!(f, "node {node}: box is empty"),
            Self::ChildNotContained { node, child } => {
                write!(f, "node {node}: child {child}'s box is not inside the node's")
            }
            Self::SlotsOutOfRange { node, first, count } => {
                write!(
                    f,
                    "leaf {node}: slots {first}..{first}+{count} run past the index array"
                )
            }
            Self::SlotSharedByLeaves { slot } => write!(f, "slot {slot} belongs to two leaves"),
            Self::SlotUnused { slot } => write!(f, "slot {slot} belongs to no leaf"),
            Self::PrimOutOfRange { slot, prim } => write!(f, "slot {slot}: primitive {prim} is out of range"),
            Self::InvalidPrimReferenced { prim } => write!(f, "invalid primitive {prim} is in the tree"),
            Self::PrimReferencedTwice { prim } => write!(f, "primitive {prim} is referenced twice"),
            Self::PrimMissing { prim } => write!(f, "valid primitive {prim} is not in the tree"),
            Self::PrimNotContained { node, prim } => {
                write!(f, "leaf {node}: primitive {prim}'s box is not inside the leaf's")
            }
            Self::PrimNotCovered { prim } => {
                write!(f, "part of triangle {prim} lies outside every leaf that references it")
            }
        }
    }
}

impl core::error::Error for ValidateError {}

impl Bvh2 {
    /// Checks every invariant of the tree against `prims` (the primitives it was built over):
    /// every node reachable from the root exactly once, children and slot ranges in range, every
    /// box finite, non-empty and containing its children's boxes and its primitives' boxes, every
    /// slot in exactly one leaf, every valid primitive referenced exactly once and no invalid one
    /// referenced. Returns the tree's statistics, or the first violation found. O(nodes + prims),
    /// iterative; allocates a node bitmap, a slot bitmap and a word per primitive.
    ///
    /// Boxes are compared exactly: the builders and [`refit`](Self::refit) compute them with
    /// `min`/`max` only, so no tolerance is needed.
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams, ValidateError}};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::Z, Vec3::ONE, Vec3::Y]];
    /// let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::quality()).unwrap();
    /// assert_eq!(bvh.validate(&tris[..]).unwrap().primitives, 2);
    /// bvh.prim_indices[0] = bvh.prim_indices[1];
    /// assert!(matches!(bvh.validate(&tris[..]), Err(ValidateError::PrimReferencedTwice { .. })));
    /// ```
    pub fn validate<P: Primitives + ?Sized>(&self, prims: &P) -> Result<BvhStats, ValidateError> {
        self.check_tree(prims, None::<fn(usize) -> Option<Triangle>>)
    }

    /// [`validate`](Self::validate) for trees with spatial splits
    /// ([`build_spatial`](Self::build_spatial)), whose leaves may share a triangle and cut
    /// through it: the same checks, except that a valid triangle must be referenced at least once
    /// (never twice by one leaf), each referencing leaf's box must touch the triangle's box
    /// (intersect it: [`ValidateError::PrimNotContained`] otherwise), and the boxes of the leaves
    /// that reference a triangle must together cover all of it ([`ValidateError::PrimNotCovered`]):
    /// its vertices, and its inside, checked by cutting the triangle by each box in f64 (slivers
    /// up to `1e-12` of the coordinates' magnitude outside every box are taken as rounding).
    /// [`BvhStats::primitives`] counts distinct triangles; [`BvhStats::mean_leaf_size`]
    /// references. A tree that passes [`validate`](Self::validate) passes this too.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, build::{Bvh2, BuildParams, SpatialSplits, ValidateError}};
    /// let soup = strahl::scene::thin_soup(500, 1);
    /// let (mut bvh, _) = Bvh2::build_spatial(&soup[..], &BuildParams::default(), &SpatialSplits::default()).unwrap();
    /// let s = bvh.validate_split(&soup[..]).unwrap();
    /// assert_eq!(s.primitives, 500);
    /// assert!(bvh.validate(&soup[..]).is_err()); // shared or cut triangles
    /// // A leaf box shrunk to a point misses its triangles' vertices.
    /// let leaf = bvh.nodes.iter().position(|n| n.is_leaf()).unwrap();
    /// bvh.nodes[leaf].set_aabb(&Aabb::new(Vec3::splat(9.0), Vec3::splat(9.0)));
    /// assert!(bvh.validate_split(&soup[..]).is_err());
    /// ```
    pub fn validate_split<P: Triangles + ?Sized>(&self, tris: &P) -> Result<BvhStats, ValidateError> {
        self.check_tree(tris, Some(|i| tris.triangle(i)))
    }

    /// [`validate`](Self::validate), or with `split` (the triangles) [`validate_split`](Self::validate_split).
    fn check_tree<P: Primitives + ?Sized, V: Fn(usize) -> Option<Triangle>>(
        &self,
        prims: &P,
        split: Option<V>,
    ) -> Result<BvhStats, ValidateError> {
        let nodes = &self.nodes;
        let total = prims.prim_count();
        let mut node_seen = vec![false; nodes.len()];
        let mut slot_seen = vec![false; self.prim_indices.len()];
        // The last leaf that referenced each primitive (`u32::MAX`: none yet), and with `split`
        // which of its vertices some referencing leaf's box holds (bits 0-2; bit 3: one box holds
        // all three, so the whole triangle), and the boxes of the leaves that hold part of it.
        let mut prim_seen = vec![u32::MAX; total];
        let mut covered = vec![0u8; if split.is_some() { total } else { 0 }];
        let mut parts: Vec<(u32, Aabb)> = Vec::new();
        let mut slots = 0u64;
        let mut stats = BvhStats::default();
        let mut depth_sum = 0u64;
        let mut stack: Vec<(u32, u32)> = Vec::new();
        if !nodes.is_empty() {
            stack.push((0, 1));
            node_seen[0] = true;
        }
        while let Some((i, depth)) = stack.pop() {
            let node: &Node = &nodes[i as usize];
            stats.nodes += 1;
            let b = node.aabb();
            // NOTE: emptiness before finiteness: the empty box has infinite bounds, and an empty
            // node (a leaf `refit` left without a valid primitive) is named as such.
            if b.min.is_nan() || b.max.is_nan() {
                return Err(ValidateError::BoxNotFinite { node: i });
            }
            if b.is_empty() {
                return Err(ValidateError::EmptyNode { node: i });
            }
            if !(b.min.is_finite() && b.max.is_finite()) {
                return Err(ValidateError::BoxNotFinite { node: i });
            }
            if node.is_leaf() {
                stats.leaves += 1;
                stats.max_depth = stats.max_depth.max(depth);
                depth_sum += depth as u64;
                stats.min_leaf_size = if stats.leaves == 1 {
                    node.count
                } else {
                    stats.min_leaf_size.min(node.count)
                };
                stats.max_leaf_size = stats.max_leaf_size.max(node.count);
                let range = node.prim_range();
                if range.end > self.prim_indices.len() {
                    return Err(ValidateError::SlotsOutOfRange {
                        node: i,
                        first: node.index,
                        count: node.count,
                    });
                }
                for slot in range {
                    if core::mem::replace(&mut slot_seen[slot], true) {
                        return Err(ValidateError::SlotSharedByLeaves { slot: slot as u32 });
                    }
                    let prim = self.prim_indices[slot];
                    let Some(seen) = prim_seen.get_mut(prim as usize) else {
                        return Err(ValidateError::PrimOutOfRange {
                            slot: slot as u32,
                            prim,
                        });
                    };
                    let before = core::mem::replace(seen, i);
                    if before == i || (before != u32::MAX && split.is_none()) {
                        return Err(ValidateError::PrimReferencedTwice { prim });
                    }
                    let Some(pb) = usable_bounds(prims, prim as usize) else {
                        return Err(ValidateError::InvalidPrimReferenced { prim });
                    };
                    slots += 1;
                    stats.primitives += u32::from(before == u32::MAX);
                    if let Some(tri) = split.as_ref() {
                        let touch = Aabb::new(b.min.max(pb.min), b.max.min(pb.max));
                        if touch.is_empty() {
                            return Err(ValidateError::PrimNotContained { node: i, prim });
                        }
                        if let (Some(t), Some(c)) = (tri(prim as usize), covered.get_mut(prim as usize)) {
                            let mut held = 0;
                            for (k, v) in t.iter().enumerate() {
                                if b.contains_point(*v) {
                                    held |= 1 << k;
                                }
                            }
                            *c |= held | if held == 7 { 8 } else { 0 };
                            if held != 7 {
                                parts.push((prim, b));
                            }
                        }
                    } else if !b.contains(&pb) {
                        return Err(ValidateError::PrimNotContained { node: i, prim });
                    }
                }
            } else {
                let l = node.left();
                if l as usize >= nodes.len().saturating_sub(1) {
                    return Err(ValidateError::ChildOutOfRange { node: i, child: l });
                }
                for c in [l, l + 1] {
                    if !b.contains(&nodes[c as usize].aabb()) {
                        return Err(ValidateError::ChildNotContained { node: i, child: c });
                    }
                    if core::mem::replace(&mut node_seen[c as usize], true) {
                        return Err(ValidateError::NodeReachedTwice { node: c });
                    }
                    stack.push((c, depth + 1));
                }
            }
        }
        if let Some(n) = node_seen.iter().position(|s| !s) {
            return Err(ValidateError::NodeUnreachable { node: n as u32 });
        }
        if let Some(s) = slot_seen.iter().position(|s| !s) {
            return Err(ValidateError::SlotUnused { slot: s as u32 });
        }
        for (p, seen) in prim_seen.iter().enumerate() {
            if *seen == u32::MAX && usable_bounds(prims, p).is_some() {
                return Err(ValidateError::PrimMissing { prim: p as u32 });
            }
        }
        if let Some(p) = covered
            .iter()
            .zip(&prim_seen)
            .position(|(&c, &s)| s != u32::MAX && c & 7 != 7)
        {
            return Err(ValidateError::PrimNotCovered { prim: p as u32 });
        }
        // Triangles no single leaf box holds: the union of their leaves' boxes must cover them.
        if let Some(tri) = split.as_ref() {
            parts.retain(|&(p, _)| covered[p as usize] & 8 == 0);
            parts.sort_unstable_by_key(|&(p, _)| p);
            let mut boxes = Vec::new();
            for run in parts.chunk_by(|a, b| a.0 == b.0) {
                let prim = run[0].0;
                boxes.clear();
                boxes.extend(run.iter().map(|&(_, b)| b));
                if let Some(t) = tri(prim as usize)
                    && !covered_by(&t, &boxes)
                {
                    return Err(ValidateError::PrimNotCovered { prim });
                }
            }
        }
        if stats.leaves > 0 {
            stats.mean_leaf_size = slots as f32 / stats.leaves as f32;
            stats.mean_leaf_depth = (depth_sum as f64 / stats.leaves as f64) as f32;
        }
        Ok(stats)
    }
}

/// A convex polygon in f64 (at most 9 corners: a triangle cut by six planes).
type Polygon = Vec<[f64; 3]>;

/// Whether the boxes together cover every point of triangle `t`, in f64: the parts of `t` outside
/// each box in turn are cut off, box by box (Sutherland-Hodgman against the six planes), and what
/// is left must be nothing but slivers on the boxes' faces (at most `1e-12` of the triangle's
/// coordinates' magnitude outside: the clipping's own rounding, so each box is widened by that
/// much; the builder pads its boxes by 8 f32 epsilons). A box that misses a piece leaves it whole. Past 4,096 pieces or 2^22 piece
/// visits (a few hundred milliseconds) the answer is `true` (the vertices were checked already),
/// so that no input makes this slower.
fn covered_by(t: &Triangle, boxes: &[Aabb]) -> bool {
    let mut scale = 0.0f64;
    for v in t.iter() {
        scale = scale.max(v.abs().max_element() as f64);
    }
    let tol = scale * 1e-12;
    let mut pieces: Vec<Polygon> = vec![t.iter().map(|v| [v.x as f64, v.y as f64, v.z as f64]).collect()];
    let mut next = Vec::new();
    let mut work = 0usize;
    for b in boxes {
        // The box widened by the tolerance: a sliver the clipping leaves on a face counts as
        // inside (left outside, a sliver wholly past the face by less than `tol` was kept whole
        // as a miss; found by the `bvh` fuzz target, seed `crash-spatial-sliver`).
        let (lo, hi) = (
            b.min.to_array().map(|x| f64::from(x) - tol),
            b.max.to_array().map(|x| f64::from(x) + tol),
        );
        for mut piece in pieces.drain(..) {
            work += 1;
            if work > 1 << 22 {
                return true;
            }
            // A box that misses the piece leaves it whole (no fragments that cover nothing).
            let misses = (0..3).any(|a| {
                let (pl, ph) = piece.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                    (l.min(v[a]), h.max(v[a]))
                });
                ph < lo[a] || pl > hi[a]
            });
            if misses {
                next.push(piece);
                continue;
            }
            let (whole, cut) = (piece.clone(), next.len());
            // Cut off the part beyond each plane; what stays inside all six is covered by `b`.
            for a in 0..3 {
                for (bound, sign) in [(hi[a], 1.0), (lo[a], -1.0)] {
                    let depth = |v: &[f64; 3]| (v[a] - bound) * sign;
                    if piece.iter().all(|v| depth(v) <= 0.0) {
                        continue;
                    }
                    let (outside, inside) = (clip(&piece, |v| depth(v)), clip(&piece, |v| -depth(v)));
                    if outside.iter().any(|v| depth(v) > tol) {
                        next.push(outside);
                    }
                    piece = inside;
                    if piece.is_empty() {
                        break;
                    }
                }
                if piece.is_empty() {
                    break;
                }
            }
            if piece.is_empty() {
                // Nothing of the piece inside the box: the piece whole, not its fragments.
                next.truncate(cut);
                next.push(whole);
            }
        }
        core::mem::swap(&mut pieces, &mut next);
        if pieces.is_empty() {
            return true;
        }
        if pieces.len() > 4096 {
            return true;
        }
    }
    false
}

/// The part of convex polygon `p` where `f >= 0` (`f` affine), by Sutherland-Hodgman; the
/// crossing points are computed in f64.
fn clip(p: &[[f64; 3]], f: impl Fn(&[f64; 3]) -> f64) -> Polygon {
    let mut out = Vec::with_capacity(p.len() + 1);
    for (i, a) in p.iter().enumerate() {
        let b = &p[(i + 1) % p.len()];
        let (fa, fb) = (f(a), f(b));
        if fa >= 0.0 {
            out.push(*a);
        }
        if (fa >= 0.0) != (fb >= 0.0) {
            let s = fa / (fa - fb);
            out.push([0, 1, 2].map(|k| a[k] + (b[k] - a[k]) * s));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slivers_on_a_face_count_as_covered() {
        use glam::Vec3;
        // A triangle split by spatial splits into three leaves (the `bvh` fuzz target's seed
        // `crash-spatial-sliver`): they cover it, but clipping by the first two leaves left a
        // sliver of the cut at y = 0 lying 5e-16 above the third box's top face, which the
        // check took for a miss.
        let t = [
            Vec3::new(6.0, 8.0, -3.0),
            Vec3::new(-3.0, -5.0, -4.0),
            Vec3::new(7.0, -6.0, 6.0),
        ];
        let boxes = [
            Aabb::new(Vec3::new(0.4615326, 0.0, -3.6153884), Vec3::new(6.2777843, 8.0, -0.5)),
            Aabb::new(
                Vec3::new(0.49999332, 0.0, -0.5),
                Vec3::new(6.5714355, 4.1111183, 2.1428628),
            ),
            Aabb::new(Vec3::new(-3.0, -6.0, -4.0), Vec3::new(7.0, 0.0, 6.0)),
        ];
        assert!(covered_by(&t, &boxes));
        // In any order.
        assert!(covered_by(&t, &[boxes[2], boxes[0], boxes[1]]));
        // Without the third box the part below y = 0 is uncovered; without the second, a
        // triangle of the part above.
        assert!(!covered_by(&t, &boxes[..2]));
        assert!(!covered_by(&t, &[boxes[0], boxes[2]]));
        // A box short of the triangle by far more than the tolerance still leaves a piece.
        let mut short = boxes;
        short[2].max.y = -1e-3;
        assert!(!covered_by(&t, &short));
    }
}
