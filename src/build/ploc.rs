//! PLOC ([`Strategy::Ploc`](super::Strategy::Ploc)): Meister and Bittner, "Parallel Locally-Ordered
//! Clustering for Bounding Volume Hierarchy Construction" (2018), with a search radius of one, as
//! the `obvhs` crate's fastest preset builds.
//!
//! The references are sorted by the Morton codes of their centroids (as the LBVH sorts them), and
//! every reference starts as a cluster of its own, a one-primitive leaf. Then, until one cluster
//! is left, a sweep along the curve merges neighbours that prefer each other: with `d(i)` the
//! surface area of the union of clusters `i` and `i + 1`, cluster `i` (whose left neighbour is
//! already taken, or is farther: `d(i - 1) > d(i)`) merges with cluster `i + 1` where `d(i) <=
//! d(i + 1)`, and stays alone otherwise. A merge writes the two clusters' nodes as a sibling pair;
//! the survivors move left in place. So every level of the agglomeration is one pass over the
//! clusters, and the tree is built bottom-up with the surface area deciding each pairing.
//!
//! Where a sweep merges fewer than a sixteenth of the clusters (long runs of monotone areas, as
//! in a geometric series of triangles, where mutual nearest neighbours are rare), a second pass
//! pairs the clusters that are left two by two, so the number of clusters at least shrinks by a
//! constant factor every round and the build stays O(n log n). A tree deeper than
//! [`BuildParams::max_depth`](super::BuildParams::max_depth) is replaced by the LBVH of the same
//! references (which keeps the bound); the build statistics count that as one forced split.
//!
//! Leaves hold one primitive each (the [`BuildParams`](super::BuildParams) leaf sizes are not
//! used); the nodes are laid out bottom-up, children before their parent, the root at index 0.

use super::builder::{Builder, Counters};
use super::lbvh::{codes_of, gather, order_item_runs, sort_gather30_par};
use super::prims::{Box8, PrepInfo, PrimRef};
use super::radix::sort_items;
use super::{BuildParams, Bvh2, MortonBits, Node};
use crate::geometry::morton::{morton63_scalar, morton63_x8};

/// A cluster's node: `[index, count]` of a leaf (its sorted position, 1) or `[left child, 0]`.
type Link = [u32; 2];

/// Builds the PLOC tree over `b.refs` into `out`.
/// `threads > 1` (`std`): the Morton codes, scatter and bucket sorts of 30-bit codes in chunks
/// side by side ([`sort_gather30_par`]: the same order); the agglomeration stays on the calling
/// thread.
pub(crate) fn build(b: &mut Builder, info: &PrepInfo, p: &BuildParams, out: &mut Bvh2, threads: usize) -> Counters {
    let cb = info.cbounds.to_aabb();
    // PLOC merges neighbours in the sorted order: the runs' order is all it needs of them.
    b.runs.reset(0);
    // The references in Morton order: in `refs` (30-bit codes) or in `alt` (63-bit).
    let sorted_in_alt = match p.morton_bits {
        MortonBits::Bits30 => {
            let q = p.quantizer(&cb);
            sort_gather30_par(
                &mut b.refs,
                &mut b.alt,
                &mut b.items32,
                &mut b.packed,
                &mut b.packed_tmp,
                &q,
                out,
                &mut b.runs,
                threads,
            );
            false
        }
        MortonBits::Bits63 => {
            let q = p.quantizer(&cb);
            codes_of(
                &b.refs,
                &mut b.items64,
                |p| morton63_scalar(p, &q),
                |x, y, z| morton63_x8(x, y, z, &q),
            );
            sort_items(&mut b.items64, &mut b.tmp64, 63);
            order_item_runs(&mut b.items64, &b.refs, &mut b.packed, &mut b.runs);
            out.prim_indices.clear();
            gather(&b.refs, &mut b.alt, &b.items64, out);
            true
        }
    };
    let sorted = if sorted_in_alt { &b.alt } else { &b.refs };
    let n = sorted.len();
    // Clusters: boxes, links and heights, compacted in place round by round.
    let (boxes, links, heights) = (&mut b.crefs, &mut b.clusters, &mut b.codes);
    boxes.clear();
    boxes.extend(sorted.iter().map(|r| PrimRef(r.bounds().0)));
    links.clear();
    links.extend((0..n as u32).map(|k| [k, 1]));
    heights.clear();
    heights.resize(n, 1);
    out.nodes.clear();
    out.nodes.reserve((2 * n).saturating_sub(1));
    // The root's slot.
    out.nodes.push(<Node as bytemuck::Zeroable>::zeroed());
    let mut m = n;
    while m > 1 {
        let merged = sweep(&mut boxes[..m], &mut links[..m], &mut heights[..m], &mut out.nodes);
        let left = m - merged;
        m = if merged * 16 < m {
            left - pair_all(
                &mut boxes[..left],
                &mut links[..left],
                &mut heights[..left],
                &mut out.nodes,
            )
        } else {
            left
        };
    }
    let height = heights.first().copied().unwrap_or(0);
    if height > p.max_depth {
        // NOTE: the LBVH sorts the references again (`refs` holds them, in some order).
        out.nodes.clear();
        out.prim_indices.clear();
        let mut c = super::lbvh::build(b, info, p, out, threads);
        c.forced_splits += 1;
        return c;
    }
    if let (Some(bx), Some(&link)) = (boxes.first(), links.first()) {
        out.nodes[0] = node(bx, link);
    }
    Counters {
        leaves: n as u32,
        max_depth: height,
        forced_splits: 0,
    }
}

/// The node of a cluster.
#[inline(always)]
fn node(bx: &PrimRef, [index, count]: Link) -> Node {
    Box8(bx.0).to_node(index, count)
}

/// Clusters `i` and `i + 1` of the arrays as one, at slot `w`: their nodes written as a sibling
/// pair.
#[inline(always)]
fn merge(
    boxes: &mut [PrimRef],
    links: &mut [Link],
    heights: &mut [u32],
    nodes: &mut alloc::vec::Vec<Node>,
    i: usize,
    w: usize,
) {
    let pair = nodes.len() as u32;
    nodes.push(node(&boxes[i], links[i]));
    nodes.push(node(&boxes[i + 1], links[i + 1]));
    boxes[w] = PrimRef(Box8(boxes[i].0).union(Box8(boxes[i + 1].0)).0);
    links[w] = [pair, 0];
    heights[w] = heights[i].max(heights[i + 1]) + 1;
}

/// Cluster `i` moved to slot `w` (`w <= i`).
#[inline(always)]
fn keep(boxes: &mut [PrimRef], links: &mut [Link], heights: &mut [u32], i: usize, w: usize) {
    boxes[w] = boxes[i];
    links[w] = links[i];
    heights[w] = heights[i];
}

/// One agglomeration round (see the module docs): merges the neighbours that prefer each other,
/// moves the clusters left, and returns the number of merges.
fn sweep(boxes: &mut [PrimRef], links: &mut [Link], heights: &mut [u32], nodes: &mut alloc::vec::Vec<Node>) -> usize {
    let m = boxes.len();
    let area = |a: &PrimRef, b: &PrimRef| Box8(a.0).union(Box8(b.0)).half_area_nonempty();
    let (mut i, mut w, mut merged) = (0, 0, 0);
    // `d(i - 1)` and `d(i)`, carried along.
    let mut dp = f32::INFINITY;
    let mut di = if m > 1 {
        area(&boxes[0], &boxes[1])
    } else {
        f32::INFINITY
    };
    while i < m {
        if i + 1 == m {
            // The last cluster, alone.
            keep(boxes, links, heights, i, w);
            break;
        }
        // `d(i + 1)`; infinite past the end.
        let dn = if i + 2 < m {
            area(&boxes[i + 1], &boxes[i + 2])
        } else {
            f32::INFINITY
        };
        // Cluster `i` prefers its right neighbour where `d(i) <= d(i - 1)`, cluster `i + 1` its
        // left one where `d(i) < d(i + 1)` (ties to the right, so the two rules agree).
        if di <= dp && di < dn {
            merge(boxes, links, heights, nodes, i, w);
            merged += 1;
            w += 1;
            i += 2;
            dp = dn;
            di = if i + 1 < m {
                area(&boxes[i], &boxes[i + 1])
            } else {
                f32::INFINITY
            };
        } else {
            keep(boxes, links, heights, i, w);
            w += 1;
            i += 1;
            (dp, di) = (di, dn);
        }
    }
    merged
}

/// Pairs the clusters two by two (`0` with `1`, `2` with `3`, ...), moving them left; returns the
/// number of merges.
fn pair_all(
    boxes: &mut [PrimRef],
    links: &mut [Link],
    heights: &mut [u32],
    nodes: &mut alloc::vec::Vec<Node>,
) -> usize {
    let m = boxes.len();
    let mut w = 0;
    let mut i = 0;
    while i + 1 < m {
        merge(boxes, links, heights, nodes, i, w);
        w += 1;
        i += 2;
    }
    if i < m {
        keep(boxes, links, heights, i, w);
    }
    m / 2
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::{Bvh2, Strategy};
    use crate::geometry::Aabb;
    use glam::Vec3;

    fn build_checked(boxes: &[Aabb], p: &BuildParams) -> (Bvh2, crate::build::BuildStats) {
        let (bvh, stats) = Bvh2::build(boxes, p).unwrap();
        // The reported depth is the tree's (root = 1 in both).
        assert_eq!(bvh.validate(boxes).unwrap().max_depth, stats.max_depth);
        (bvh, stats)
    }

    /// Boxes at `x` on a line, unit size: the sweep pairs the closest neighbours first.
    #[test]
    fn mutual_nearest_neighbours_merge_first() {
        let at = |x: f32| Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x + 1.0, 1.0, 1.0));
        // Gaps 0, 10, 0: the pairs (0, 1) and (2, 3) are each other's nearest.
        let boxes = [at(0.0), at(1.0), at(12.0), at(13.0)];
        let (bvh, stats) = build_checked(&boxes, &BuildParams::ploc());
        assert_eq!((stats.leaves, stats.max_depth, stats.forced_splits), (4, 3, 0));
        let root = bvh.nodes[0];
        let (l, r) = (bvh.nodes[root.left() as usize], bvh.nodes[root.left() as usize + 1]);
        let span = |n: Node| (n.min[0], n.max[0]);
        let mut kids = [span(l), span(r)];
        kids.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(kids, [(0.0, 2.0), (12.0, 14.0)]);
    }

    /// Equal boxes give no mutual preferences (but the last pair's); the pairing pass keeps the
    /// rounds logarithmic and the tree within twice the balanced depth (`ceil(log2 70000)` = 17).
    #[test]
    fn equal_boxes_pair_up_in_balanced_rounds() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let boxes = alloc::vec![b; 70_000];
        let (_, stats) = build_checked(&boxes, &BuildParams::ploc());
        assert_eq!(stats.forced_splits, 0);
        assert!(stats.max_depth <= 2 * 17 + 1, "depth {}", stats.max_depth);
    }

    /// A tree deeper than `max_depth` is replaced by the LBVH (which keeps the bound), counted
    /// as one forced split. (`max_depth` below the public minimum, to reach it on a small scene.)
    #[test]
    fn too_deep_a_tree_becomes_the_lbvh() {
        let boxes: alloc::vec::Vec<Aabb> = (0..16)
            .map(|i| {
                let s = 0.5f32.powi(i);
                Aabb::new(Vec3::splat(s), Vec3::splat(s) + Vec3::splat(s * 0.5))
            })
            .collect();
        let run = |max_depth: u32| {
            let mut b = Builder::new();
            let info = crate::build::prims::prepare(&boxes[..], &mut b.refs).unwrap();
            let mut out = Bvh2::default();
            let p = BuildParams {
                max_depth,
                ..BuildParams::ploc()
            };
            let c = build(&mut b, &info, &p, &mut out, 1);
            let v = out.validate(&boxes[..]).unwrap();
            assert_eq!(v.max_depth, c.max_depth);
            c
        };
        let free = run(64);
        assert!(free.max_depth > 6 && free.forced_splits == 0, "{free:?}");
        let bounded = run(6);
        assert!(bounded.max_depth <= 6 && bounded.forced_splits >= 1, "{bounded:?}");
    }

    /// A chain of ever smaller boxes (each area decision the same way) would make a tree as deep
    /// as the scene is long; the pairing pass and, past `max_depth`, the LBVH keep it bounded.
    #[test]
    fn deep_chains_stay_within_max_depth() {
        let boxes: alloc::vec::Vec<Aabb> = (0..3000)
            .map(|i| {
                let s = 0.999f32.powi(i);
                Aabb::new(Vec3::splat(s), Vec3::splat(s) + Vec3::splat(s * 1e-3))
            })
            .collect();
        for bits in [MortonBits::Bits30, MortonBits::Bits63] {
            let p = BuildParams {
                morton_bits: bits,
                max_depth: 34,
                ..BuildParams::ploc()
            };
            assert_eq!(p.strategy, Strategy::Ploc);
            let (_, stats) = build_checked(&boxes, &p);
            assert!(stats.max_depth <= 34, "{bits:?}: depth {}", stats.max_depth);
        }
    }
}
