//! Tree rotations ([`Refine::Rotations`](super::Refine::Rotations),
//! [`Bvh2::optimize_rotations`]): Kensler, "Tree Rotations for Improving Bounding Volume
//! Hierarchies" (2008).
//!
//! At an interior node `N` with children `L` and `R`, a rotation swaps a child with a grandchild
//! on the other side (`L <-> R.left`, `L <-> R.right`, `R <-> L.left`, `R <-> L.right`) or two
//! grandchildren across (`L.left <-> R.left`, `L.left <-> R.right`). Every swapped subtree keeps
//! its box and its leaves, so only the boxes of `L` and `R` change (of `R` alone where `L` moves
//! down, and the other way round), and the SAH cost changes by `C_T` times the change of their
//! surface areas: a rotation pays exactly when it shrinks them.
//! One round visits every interior node bottom-up (children first, so a node sees its
//! children's rotations) and applies the rotation that shrinks `L` and `R` most, if any. Nodes
//! keep their slots' pairing (siblings stay adjacent; the swapped records carry their children
//! with them) and the primitive-index array is not touched.
//!
//! Never raises the SAH cost (each applied rotation lowers it by more than a relative `1e-6` of
//! the children's areas, so rounding cannot cycle), and never makes the tree deeper than the depth
//! bound (a rotation is skipped where the deepest leaf below `N` would pass it).

use super::prims::Box8;
use super::{Bvh2, ValidateError};
use alloc::vec;
use alloc::vec::Vec;

/// What [`Bvh2::optimize_rotations`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RotationStats {
    /// Rotations applied, over all rounds.
    pub rotations: u32,
    /// Rounds run (stops early when a round applies none).
    pub rounds: u32,
    /// Depth of the deepest leaf afterwards (root = 1).
    pub max_depth: u32,
}

/// Half the surface area of a box that is not empty.
#[inline(always)]
fn area(b: Box8) -> f32 {
    b.half_area_nonempty()
}

/// Runs up to `rounds` rounds of rotations over `bvh` keeping every leaf within `max_depth`.
pub(crate) fn optimize(bvh: &mut Bvh2, rounds: u32, max_depth: u32) -> Result<RotationStats, ValidateError> {
    optimize_with(bvh, rounds, max_depth, true)
}

/// [`optimize`], with the index-order walk allowed or not (`by_index`: see [`index_order`]).
fn optimize_with(bvh: &mut Bvh2, rounds: u32, max_depth: u32, by_index: bool) -> Result<RotationStats, ValidateError> {
    let n = bvh.nodes.len();
    let mut stats = RotationStats::default();
    if n == 0 {
        return Ok(stats);
    }
    let mut order: Vec<u32> = Vec::with_capacity(n);
    let mut depth: Vec<u32> = vec![0; n];
    let mut height: Vec<u32> = vec![0; n];
    for _ in 0..rounds.max(1) {
        if !(by_index && index_order(bvh, &mut order, &mut depth)) {
            pre_order(bvh, &mut order, &mut depth)?;
        }
        let nodes = &mut bvh.nodes;
        let mut applied = 0u32;
        for &i in order.iter().rev() {
            let i = i as usize;
            let node = nodes[i];
            if node.is_leaf() {
                height[i] = 1;
                continue;
            }
            let l = node.left() as usize;
            let r = l + 1;
            let (nl, nr) = (nodes[l], nodes[r]);
            let (bl, br) = (Box8::from_node(&nl), Box8::from_node(&nr));
            let (al, ar) = (area(bl), area(br));
            // Only the boxes of L and R change: a candidate's gain is the change of their areas.
            let eps = 1e-6 * (al + ar);
            let mut best: Option<(usize, usize, f32)> = None;
            let mut consider = |a: usize, b: usize, delta: f32| {
                if delta < best.map_or(-eps, |(_, _, d)| d) {
                    best = Some((a, b, delta));
                }
            };
            let kids = |n: &crate::traverse::Node| -> Option<(usize, Box8, Box8)> {
                (!n.is_leaf()).then(|| {
                    let k = n.left() as usize;
                    (k, Box8::from_node(&nodes[k]), Box8::from_node(&nodes[k + 1]))
                })
            };
            let (kl, kr) = (kids(&nl), kids(&nr));
            if let Some((k, b0, b1)) = kr {
                // L <-> R.left: R becomes (L, R.right).
                consider(l, k, area(bl.union(b1)) - ar);
                // L <-> R.right: R becomes (R.left, L).
                consider(l, k + 1, area(b0.union(bl)) - ar);
            }
            if let Some((k, a0, a1)) = kl {
                // R <-> L.left: L becomes (R, L.right).
                consider(r, k, area(br.union(a1)) - al);
                // R <-> L.right: L becomes (L.left, R).
                consider(r, k + 1, area(a0.union(br)) - al);
            }
            if let (Some((ka, a0, a1)), Some((kb, b0, b1))) = (kl, kr) {
                // L.left <-> R.left: L = (R.left, L.right), R = (L.left, R.right).
                consider(ka, kb, area(b0.union(a1)) + area(a0.union(b1)) - al - ar);
                // L.left <-> R.right: L = (R.right, L.right), R = (R.left, L.left).
                consider(ka, kb + 1, area(b1.union(a1)) + area(b0.union(a0)) - al - ar);
            }
            if let Some((a, b, _)) = best {
                // Swap the subtrees in slots `a` and `b` (each record carries its children),
                // then refresh the boxes and heights of L and R from their children.
                let slots = [a, b, l, r];
                let saved = slots.map(|s| (nodes[s], height[s]));
                nodes.swap(a, b);
                height.swap(a, b);
                for c in [l, r] {
                    let cn = nodes[c];
                    if !cn.is_leaf() {
                        let k = cn.left() as usize;
                        let bx = Box8::from_node(&nodes[k]).union(Box8::from_node(&nodes[k + 1]));
                        nodes[c] = bx.to_node(k as u32, 0);
                        height[c] = height[k].max(height[k + 1]) + 1;
                    }
                }
                if depth[i] + height[l].max(height[r]) <= max_depth {
                    applied += 1;
                } else {
                    // The deepest leaf below would pass the depth bound: undo.
                    for (s, (node, h)) in slots.into_iter().zip(saved).rev() {
                        nodes[s] = node;
                        height[s] = h;
                    }
                }
            }
            height[i] = height[l].max(height[r]) + 1;
        }
        stats.rounds += 1;
        stats.rotations += applied;
        if applied == 0 {
            break;
        }
    }
    stats.max_depth = height[0];
    Ok(stats)
}

/// The nodes reached from the root in index order, with their depths (root = 1), where that is a
/// bottom-up order read backwards: every interior node's children lie after it (as the top-down
/// builders lay them out) and in range, and no node is reached twice. `false` (and `order`,
/// `depth` to be refilled) otherwise, e.g. after a round of rotations moved a record with its
/// children below a later slot, or for the LBVH's post-order layout; [`pre_order`] then orders the
/// tree (or names what is malformed).
// PERF: the pre-order walk and the loop over it read the nodes in tree order: on 1M-triangle
// trees of 64 bins, most of a round's samples sat on those two node loads. In index order both
// loops stream through the array: one round 62-64 -> 47-50 ms (soup), 27 -> 18-20 ms (terrain),
// 31 -> 21-23 ms (sphereflake), best of 5, old and new taking turns. Each subtree sees its
// rotations in the same order, so the tree is the same (unit test). (A branch-free form of the
// leaf test here, through spare depth slots: no faster.)
fn index_order(bvh: &Bvh2, order: &mut Vec<u32>, depth: &mut [u32]) -> bool {
    let n = bvh.nodes.len();
    order.clear();
    depth.fill(0);
    depth[0] = 1;
    for (i, node) in bvh.nodes.iter().enumerate() {
        let d = depth[i];
        // Not reached from the root: not part of the tree.
        if d == 0 {
            continue;
        }
        order.push(i as u32);
        if !node.is_leaf() {
            let l = node.left() as usize;
            if l <= i || l + 1 >= n || depth[l] != 0 || depth[l + 1] != 0 {
                return false;
            }
            depth[l] = d + 1;
            depth[l + 1] = d + 1;
        }
    }
    true
}

/// Interior and leaf nodes in pre-order from the root, with their depths (root = 1); errors on
/// child indices out of range (or pointing at the root) and on a node reached twice.
fn pre_order(bvh: &Bvh2, order: &mut Vec<u32>, depth: &mut [u32]) -> Result<(), ValidateError> {
    let n = bvh.nodes.len();
    order.clear();
    // Depth 0: not reached yet.
    depth.fill(0);
    let mut stack = vec![(0u32, 1u32)];
    while let Some((i, d)) = stack.pop() {
        if core::mem::replace(&mut depth[i as usize], d) != 0 {
            return Err(ValidateError::NodeReachedTwice { node: i });
        }
        order.push(i);
        let node = bvh.nodes[i as usize];
        if !node.is_leaf() {
            let l = node.left();
            if l as usize + 1 >= n || l == 0 {
                return Err(ValidateError::ChildOutOfRange { node: i, child: l });
            }
            stack.push((l + 1, d + 1));
            stack.push((l, d + 1));
        }
    }
    Ok(())
}

impl Bvh2 {
    /// Improves the tree by up to `rounds` rounds of tree rotations (Kensler, "Tree Rotations for
    /// Improving Bounding Volume Hierarchies", 2008): at every interior node, bottom-up, the
    /// best of the six swaps of a child with a grandchild on the other side, or of two
    /// grandchildren across, where it shrinks the two children's boxes (it never changes a leaf
    /// or another box). Keeps every leaf within `max_depth` (clamped to
    /// [`traverse::MAX_DEPTH`](crate::traverse::MAX_DEPTH)). Never raises the SAH cost, for any
    /// `C_T > 0` and `C_I`: a rotation changes no leaf, only the boxes of two interior nodes,
    /// and is applied only where their areas shrink. Errors, without changing the tree, if its
    /// structure is malformed.
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams}, scene};
    /// let soup = scene::clustered_soup(3000, 5, 1);
    /// let (mut bvh, _) = Bvh2::build(&soup[..], &BuildParams::fastest()).unwrap();
    /// let before = bvh.sah_cost(1.0, 1.0);
    /// let stats = bvh.optimize_rotations(4, 64).unwrap();
    /// assert!(stats.rotations > 0);
    /// assert!(bvh.sah_cost(1.0, 1.0) < before);
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// ```
    pub fn optimize_rotations(&mut self, rounds: u32, max_depth: u32) -> Result<RotationStats, ValidateError> {
        optimize(self, rounds, max_depth.min(crate::traverse::MAX_DEPTH))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::{BuildParams, Builder};
    use crate::scene;

    #[test]
    fn index_order_makes_the_pre_order_tree() {
        // Top-down trees (children after parents: the index-order walk, then pre-order once a
        // round has moved records) and the LBVH's post-order layout (pre-order throughout):
        // the same nodes, statistics and errors either way.
        let soup = scene::clustered_soup(20_000, 12, 3);
        let flake = scene::sphereflake(1, 2).to_soup();
        let mut walked_by_index = false;
        for tris in [&soup[..], &flake[..]] {
            for p in [BuildParams::balanced(), BuildParams::fast(), BuildParams::fastest()] {
                let (tree, _) = Builder::new().build(tris, &p).unwrap();
                let mut order = Vec::new();
                let mut depth = vec![0; tree.nodes.len()];
                walked_by_index |= index_order(&tree, &mut order, &mut depth);
                for (rounds, max_depth) in [(1, 64), (3, 64), (2, 12)] {
                    let (mut a, mut b) = (tree.clone(), tree.clone());
                    let sa = optimize_with(&mut a, rounds, max_depth, true).unwrap();
                    let sb = optimize_with(&mut b, rounds, max_depth, false).unwrap();
                    assert_eq!(sa, sb);
                    assert_eq!(a, b);
                    assert!(sa.rotations > 0 || max_depth < 64, "{rounds} {max_depth}");
                    assert!(a.validate(tris).is_ok());
                }
            }
        }
        assert!(walked_by_index);
        // A node reached twice: refused, unchanged, whichever walk looks first.
        let (mut bad, _) = Builder::new().build(&soup[..], &BuildParams::balanced()).unwrap();
        let k = bad.nodes[0].left() as usize;
        let grand = bad.nodes[k].left();
        bad.nodes[k + 1] = bad.nodes[k];
        bad.nodes[k + 1].index = grand;
        let before = bad.clone();
        assert!(optimize(&mut bad, 1, 64).is_err());
        assert_eq!(bad, before);
    }
}
