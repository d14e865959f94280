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
//! With `std`, parallel builds rotate on several threads (`optimize_par`, the first round): the
//! tree's subtrees whose nodes fill runs of slots of their own (as every builder lays them out)
//! are rotated side by side, then the nodes above them; the same tree as one thread makes (unit
//! test). One round on 1M-triangle trees of 64 bins, on 2 threads: about 25 ms (soup) and 11-15
//! ms (terrain, sphereflake) against 47-50 and 18-23 ms on one.
//!
//! Never raises the SAH cost (each applied rotation lowers it by more than a relative `1e-6` of
//! the children's areas, so rounding cannot cycle), and never makes the tree deeper than the depth
//! bound (a rotation is skipped where the deepest leaf below `N` would pass it).

use super::prims::Box8;
use super::validate::{Walk, checked_pre_order};
use super::{Bvh2, Node, ValidateError};
use alloc::vec;
use alloc::vec::Vec;

/// What [`Bvh2::optimize_rotations`] did.
///
/// ```
/// use strahl::{build::{BuildParams, Bvh2}, traverse::MAX_DEPTH};
/// let tris = strahl::scene::thin_soup(5_000, 1);
/// let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
/// let before = bvh.sah_cost(1.0, 1.0);
/// let stats = bvh.optimize_rotations(4, MAX_DEPTH).unwrap();
/// assert!(stats.rotations > 0 && (1..=4).contains(&stats.rounds));
/// assert_eq!(stats.max_depth, bvh.validate(&tris[..]).unwrap().max_depth);
/// assert!(bvh.sah_cost(1.0, 1.0) < before);
/// ```
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
    optimize_with(bvh, rounds, max_depth, true, 1)
}

/// [`optimize`], with the index-order walk allowed or not (`by_index`: see [`index_order`]), the
/// first round on up to `threads` threads where [`par_round`] can cut the tree.
fn optimize_with(
    bvh: &mut Bvh2,
    rounds: u32,
    max_depth: u32,
    by_index: bool,
    threads: usize,
) -> Result<RotationStats, ValidateError> {
    let n = bvh.nodes.len();
    let mut stats = RotationStats::default();
    if n == 0 {
        return Ok(stats);
    }
    let mut order: Vec<u32> = Vec::with_capacity(n);
    let mut depth: Vec<u32> = vec![0; n];
    let mut height: Vec<u32> = vec![0; n];
    for r in 0..rounds.max(1) {
        // NOTE: the first round only: a round's rotations move records (with their children)
        // into other slots, and the layout a cut needs is gone (a probe of 2,000 rotated trees: no
        // cut after the first round), so later rounds would pay for the plan and check in vain.
        let par = (r == 0 && by_index)
            .then(|| par_round(bvh, &mut depth, &mut height, max_depth, threads))
            .flatten();
        let applied = match par {
            Some(applied) => applied,
            None => one_round(bvh, &mut order, &mut depth, &mut height, by_index, max_depth)?,
        };
        stats.rounds += 1;
        stats.rotations += applied;
        if applied == 0 {
            break;
        }
    }
    stats.max_depth = height[0];
    Ok(stats)
}

/// One round on one thread: every node bottom-up, in reverse index order where [`index_order`]
/// applies (and `by_index`), else in reverse pre-order. The rotations applied.
fn one_round(
    bvh: &mut Bvh2,
    order: &mut Vec<u32>,
    depth: &mut [u32],
    height: &mut [u32],
    by_index: bool,
    max_depth: u32,
) -> Result<u32, ValidateError> {
    if !(by_index && index_order(bvh, order, depth)) {
        pre_order(bvh, order, depth)?;
    }
    Ok(visit_back(bvh, height, depth, order, max_depth))
}

/// [`visit`]s `nodes` (slots) from last to first over the whole tree; the rotations applied.
fn visit_back(bvh: &mut Bvh2, height: &mut [u32], depth: &[u32], nodes: &[u32], max_depth: u32) -> u32 {
    nodes.iter().rev().fold(0, |acc, &i| {
        let i = i as usize;
        acc + u32::from(visit(&mut bvh.nodes, height, 0, i, depth[i], max_depth))
    })
}

/// [`optimize`] on up to `threads` threads (with `std`; else on one): the same tree (see
/// [`par_round`]).
pub(crate) fn optimize_par(
    bvh: &mut Bvh2,
    rounds: u32,
    max_depth: u32,
    threads: usize,
) -> Result<RotationStats, ValidateError> {
    optimize_with(bvh, rounds, max_depth, true, threads)
}

/// One round on up to `threads` threads, or `None` (nothing done) where the tree cannot be cut:
/// it is cut into runs of slots that hold all the descendants of one node and nothing else,
/// about eight per thread (the builders lay subtrees out that way: a node's children first,
/// then the left child's subtree, then the right one's); the runs are checked and rotated
/// bottom-up side by side (a rotation writes only below the node it is at), then the nodes above
/// them on the calling thread. Trees of fewer than [`PAR_MIN_NODES`] nodes stay on one thread.
#[cfg(feature = "std")]
fn par_round(bvh: &mut Bvh2, depth: &mut [u32], height: &mut [u32], max_depth: u32, threads: usize) -> Option<u32> {
    if threads <= 1 || bvh.nodes.len() < PAR_MIN_NODES {
        return None;
    }
    let (runs, top) = plan_runs(bvh, threads, depth)?;
    if !check_runs(bvh, &runs, depth, threads) {
        return None;
    }
    let applied = rotate_runs(bvh, height, depth, &runs, max_depth, threads);
    Some(applied + visit_back(bvh, height, depth, &top, max_depth))
}

/// Without `std`: every round on one thread.
#[cfg(not(feature = "std"))]
fn par_round(_: &mut Bvh2, _: &mut [u32], _: &mut [u32], _: u32, _: usize) -> Option<u32> {
    None
}

/// Trees with fewer nodes are rotated on one thread.
#[cfg(feature = "std")]
pub(crate) const PAR_MIN_NODES: usize = 1 << 15;

/// A run: `[node, first, end]`, slots `first..end` meant to hold exactly `node`'s descendants.
#[cfg(feature = "std")]
pub(crate) type Run = [u32; 3];

/// The cut for [`optimize_par`], read off the layout without reading the runs: the builders put
/// a node's children in a pair of slots and every subtree's nodes below them in a run of slots of
/// its own, so the run of a node's descendants starts at its children's pair and ends at the
/// next pair of any node above the cut (or at the end). From the root, the node whose run is
/// largest is opened (it goes above the cut, its children to the frontier) until about eight runs
/// per thread are left over a size. Returns the runs (sorted by slot) and the nodes above them and
/// their roots (sorted), with those nodes' depths written to `depth`; `None` where the layout is
/// not so (children before their parent, out of range, runs overlapping) or there are fewer than
/// two runs. [`check_runs`] then checks that every run holds what it should.
#[cfg(feature = "std")]
pub(crate) fn plan_runs(bvh: &Bvh2, threads: usize, depth: &mut [u32]) -> Option<(Vec<Run>, Vec<u32>)> {
    use alloc::collections::{BTreeSet, BinaryHeap};
    let nodes = &bvh.nodes;
    let n = nodes.len() as u32;
    let target = (n as usize / (8 * threads)).max(2) as u32;
    // Pairs' first slots (and the end).
    let mut bounds: BTreeSet<u32> = BTreeSet::from([n]);
    let run_end = |bounds: &BTreeSet<u32>, l: u32| bounds.range(l + 1..).next().copied().unwrap_or(n);
    let mut top = vec![0u32];
    depth[0] = 1;
    // Frontier of interior nodes: (run size, node), the largest on top.
    let mut frontier = BinaryHeap::new();
    let open = |x: u32, bounds: &mut BTreeSet<u32>, frontier: &mut BinaryHeap<(u32, u32)>| -> Option<()> {
        let node = nodes[x as usize];
        if node.is_leaf() {
            return Some(());
        }
        let l = node.left();
        if l <= x || l >= n - 1 || !bounds.insert(l) {
            return None;
        }
        // Sized when popped (first: above every sized entry).
        frontier.push((u32::MAX, x));
        Some(())
    };
    open(0, &mut bounds, &mut frontier)?;
    let limit = 64 * threads;
    let mut opened = 0usize;
    // Opens `x`: its children go above the cut, or (interior) to the frontier.
    let mut open_node = |x: u32,
                         depth: &mut [u32],
                         top: &mut Vec<u32>,
                         bounds: &mut BTreeSet<u32>,
                         frontier: &mut BinaryHeap<(u32, u32)>|
     -> Option<()> {
        opened += 1;
        if opened > limit {
            return None;
        }
        let l = nodes[x as usize].left();
        let d = depth[x as usize] + 1;
        for c in [l, l + 1] {
            depth[c as usize] = d;
            top.push(c);
            open(c, bounds, frontier)?;
        }
        Some(())
    };
    // The largest runs first, down to the target size.
    while let Some((size, x)) = frontier.pop() {
        let l = nodes[x as usize].left();
        let now = run_end(&bounds, l) - l;
        if now != size {
            // A stale size (new pairs since): queue it again.
            frontier.push((now, x));
            continue;
        }
        if size <= target {
            frontier.push((size, x));
            break;
        }
        open_node(x, depth, &mut top, &mut bounds, &mut frontier)?;
    }
    // Then every node whose children's pairs lie outside its run (the breadth-first top of a
    // parallel build) is opened too, until all fit.
    let fits = |bounds: &BTreeSet<u32>, x: u32| {
        let l = nodes[x as usize].left();
        let end = run_end(bounds, l);
        [l, l + 1].iter().all(|&c| {
            let cn = nodes[c as usize];
            cn.is_leaf() || (l + 2 <= cn.left() && cn.left() < end)
        })
    };
    // At most 64 passes (a parallel build's breadth-first top is a few levels deep): each pass
    // tests the whole frontier.
    for pass in 0.. {
        if pass == 64 {
            return None;
        }
        let mut misfit = Vec::new();
        for (size, x) in core::mem::take(&mut frontier).into_vec() {
            if fits(&bounds, x) {
                frontier.push((size, x));
            } else {
                misfit.push((size, x));
            }
        }
        if misfit.is_empty() {
            break;
        }
        for (_, x) in misfit {
            open_node(x, depth, &mut top, &mut bounds, &mut frontier)?;
        }
    }
    let mut runs: Vec<Run> = frontier
        .into_iter()
        .map(|(_, x)| {
            let l = nodes[x as usize].left();
            [x, l, run_end(&bounds, l)]
        })
        .collect();
    if runs.len() < 2 {
        return None;
    }
    runs.sort_unstable_by_key(|r| r[1]);
    top.sort_unstable();
    // Disjoint runs, no node above them twice, and none inside a run.
    let disjoint = runs.windows(2).all(|w| w[0][2] <= w[1][1]) && runs.iter().all(|r| r[2] - r[1] >= 2);
    let unique = top.windows(2).all(|w| w[0] < w[1]);
    let outside = top.iter().all(|&t| {
        let k = runs.partition_point(|r| r[1] <= t);
        k == 0 || t >= runs[k - 1][2]
    });
    (disjoint && unique && outside).then_some((runs, top))
}

/// Checks, side by side, that each run `[node, first, end]` holds exactly `node`'s descendants,
/// each reached once (children after their parents, within the run), and writes their depths.
#[cfg(feature = "std")]
pub(crate) fn check_runs(bvh: &Bvh2, runs: &[Run], depth: &mut [u32], threads: usize) -> bool {
    use core::sync::atomic::{AtomicBool, Ordering};
    let nodes = &bvh.nodes[..];
    let roots: Vec<u32> = runs.iter().map(|r| depth[r[0] as usize]).collect();
    let parts = crate::par::split_ranges(depth, runs.iter().map(|r| (r[1] as usize, r[2] as usize)));
    let jobs: Vec<_> = runs.iter().zip(roots).zip(parts).collect();
    let ok = AtomicBool::new(true);
    crate::par::each_job(jobs, threads, |((&[node, first, end], d), dep)| {
        let (first, end) = (first as usize, end as usize);
        // Depth 0: not reached (yet).
        dep.fill(0);
        let mut good = nodes[node as usize].left() as usize == first;
        if good {
            (dep[0], dep[1]) = (d + 1, d + 1);
        }
        for j in first..end {
            if !good {
                break;
            }
            let dj = dep[j - first];
            let node = nodes[j];
            if dj == 0 {
                good = false;
            } else if !node.is_leaf() {
                let c = node.left() as usize;
                good = c > j && c < end - 1 && dep[c - first] == 0 && dep[c + 1 - first] == 0;
                if good {
                    (dep[c - first], dep[c + 1 - first]) = (dj + 1, dj + 1);
                }
            }
        }
        if !good {
            ok.store(false, Ordering::Relaxed);
        }
    });
    ok.into_inner()
}

/// Rotates every run of `runs` (sorted, disjoint) bottom-up, side by side on `threads` threads;
/// the rotations applied.
#[cfg(feature = "std")]
fn rotate_runs(bvh: &mut Bvh2, height: &mut [u32], depth: &[u32], runs: &[Run], max_depth: u32, threads: usize) -> u32 {
    use core::sync::atomic::{AtomicU32, Ordering};
    let ranges = || runs.iter().map(|r| (r[1] as usize, r[2] as usize));
    let parts = crate::par::split_ranges(&mut bvh.nodes, ranges());
    let mut jobs: Vec<_> = ranges()
        .zip(parts)
        .zip(crate::par::split_ranges(height, ranges()))
        .collect();
    // Largest runs first.
    jobs.sort_unstable_by_key(|((r, _), _)| core::cmp::Reverse(r.1 - r.0));
    let applied = AtomicU32::new(0);
    crate::par::each_job(jobs, threads, |(((first, _), nodes), height)| {
        let mut here = 0;
        for i in (first..first + nodes.len()).rev() {
            here += u32::from(visit(nodes, height, first, i, depth[i], max_depth));
        }
        applied.fetch_add(here, Ordering::Relaxed);
    });
    applied.into_inner()
}

/// The best rotation at node `i` (at depth `depth`), if any pays and keeps the leaves below within
/// `max_depth`; then `i`'s height. `nodes` and `height` hold slots `off..`: `i` and every slot
/// below it (which is all the rotation reads and writes). `true` if a rotation was applied.
#[inline]
fn visit(nodes: &mut [Node], height: &mut [u32], off: usize, i: usize, depth: u32, max_depth: u32) -> bool {
    let i = i - off;
    let node = nodes[i];
    if node.is_leaf() {
        height[i] = 1;
        return false;
    }
    // Local slots: a record's child index minus `off`.
    let l = node.left() as usize - off;
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
    let kids = |n: &Node| -> Option<(usize, Box8, Box8)> {
        (!n.is_leaf()).then(|| {
            let k = n.left() as usize - off;
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
    let mut applied = false;
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
                let k = cn.left() as usize - off;
                let bx = Box8::from_node(&nodes[k]).union(Box8::from_node(&nodes[k + 1]));
                nodes[c] = bx.to_node((k + off) as u32, 0);
                height[c] = height[k].max(height[k + 1]) + 1;
            }
        }
        if depth + height[l].max(height[r]) <= max_depth {
            applied = true;
        } else {
            // The deepest leaf below would pass the depth bound: undo.
            for (s, (node, h)) in slots.into_iter().zip(saved).rev() {
                nodes[s] = node;
                height[s] = h;
            }
        }
    }
    height[i] = height[l].max(height[r]) + 1;
    applied
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
            if l <= i || l >= n - 1 || depth[l] != 0 || depth[l + 1] != 0 {
                return false;
            }
            depth[l] = d + 1;
            depth[l + 1] = d + 1;
        }
    }
    true
}

/// Interior and leaf nodes in pre-order from the root, with their depths (root = 1), by
/// [`checked_pre_order`] (which names what is malformed).
fn pre_order(bvh: &Bvh2, order: &mut Vec<u32>, depth: &mut [u32]) -> Result<(), ValidateError> {
    let mut walk = Walk::default();
    walk.order = core::mem::take(order);
    // 0: not reached.
    depth.fill(0);
    if let Some(d) = depth.first_mut() {
        *d = 1;
    }
    // NOTE: slots unchecked (`usize::MAX`): rotations never read them, and `index_order` (the
    // other walk of a round) does not check them either, so a later round must not refuse a tree
    // that round 0 already rotated.
    let r = checked_pre_order(&bvh.nodes, usize::MAX, &mut walk, |p, c| {
        depth[c as usize] = depth[p as usize] + 1;
    });
    *order = walk.order;
    r
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
                    let sa = optimize_with(&mut a, rounds, max_depth, true, 1).unwrap();
                    let sb = optimize_with(&mut b, rounds, max_depth, false, 1).unwrap();
                    assert_eq!(sa, sb);
                    assert_eq!(a, b);
                    assert!(sa.rotations > 0 || max_depth < 64, "{rounds} {max_depth}");
                    assert!(a.validate(tris).is_ok());
                }
            }
        }
        assert!(walked_by_index);
        // The parallel form: the same tree, from sequential and parallel builds' layouts.
        #[cfg(feature = "std")]
        {
            let big = scene::clustered_soup(60_000, 30, 4);
            let p = BuildParams {
                bins: 64,
                ..BuildParams::balanced()
            };
            let mut b = Builder::new();
            let (seq, _) = b.build(&big[..], &p).unwrap();
            let mut par = Bvh2::default();
            b.build_into_par(&big[..], &p, &mut par, 3).unwrap();
            for tree in [seq, par] {
                assert!(tree.nodes.len() >= PAR_MIN_NODES);
                let mut depth = vec![0; tree.nodes.len()];
                let (runs, top) = plan_runs(&tree, 2, &mut depth).unwrap();
                assert!(check_runs(&tree, &runs, &mut depth, 2));
                // Runs and the nodes above them cover every node once, at its depth.
                let covered: usize = runs.iter().map(|r| (r[2] - r[1]) as usize).sum::<usize>() + top.len();
                assert_eq!(covered, tree.nodes.len());
                assert!(runs.len() >= 8);
                let (mut order, mut want_depth) = (Vec::new(), vec![0; tree.nodes.len()]);
                pre_order(&tree, &mut order, &mut want_depth).unwrap();
                assert_eq!(depth, want_depth);
                // A run that holds a node of another subtree: refused.
                let mut broken = tree.clone();
                let [_, first, end] = runs[runs.len() / 2];
                let j = (first..end).find(|&j| !broken.nodes[j as usize].is_leaf()).unwrap() as usize;
                let other = runs[0][1];
                broken.nodes[j].index = other;
                let mut d = vec![0; tree.nodes.len()];
                let plan = plan_runs(&broken, 2, &mut d);
                assert!(plan.is_none_or(|(runs, _)| !check_runs(&broken, &runs, &mut d, 2)));
                for rounds in [1, 2] {
                    let mut want = tree.clone();
                    let ws = optimize(&mut want, rounds, 64).unwrap();
                    assert!(ws.rotations > 0);
                    for threads in [2, 3, 8] {
                        let mut got = tree.clone();
                        assert_eq!(optimize_par(&mut got, rounds, 64, threads).unwrap(), ws);
                        assert_eq!(got, want, "{rounds} rounds, {threads} threads");
                    }
                }
            }
        }
        // A node reached twice: refused, unchanged, whichever walk looks first.
        let (mut bad, _) = Builder::new().build(&soup[..], &BuildParams::balanced()).unwrap();
        let k = bad.nodes[0].left() as usize;
        let grand = bad.nodes[k].left();
        bad.nodes[k + 1] = bad.nodes[k];
        bad.nodes[k + 1].index = grand;
        let before = bad.clone();
        assert!(optimize(&mut bad, 1, 64).is_err());
        assert_eq!(bad, before);
        #[cfg(feature = "std")]
        {
            assert!(bad.nodes.len() >= PAR_MIN_NODES);
            assert!(optimize_par(&mut bad, 1, 64, 2).is_err());
            assert_eq!(bad, before);
        }
    }
}
