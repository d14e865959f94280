//! Hierarchical LBVH ([`Strategy::Hlbvh`](super::Strategy::Hlbvh)): Pantaleoni and Luebke,
//! "HLBVH: Hierarchical LBVH Construction for Real-Time Ray Tracing of Dynamic Geometry" (2010),
//! with the SAH top of Garanzha, Pantaleoni and McAllister, "Simpler and Faster HLBVH with Work
//! Queues" (2011).
//!
//! 1. Morton codes and one radix sort, as in the [LBVH](super::lbvh); the references are gathered
//!    into Morton order.
//! 2. **Clusters**: the sorted range is cut top-down with the LBVH split (where the highest
//!    differing bit changes) until every piece holds at most
//!    [`cluster_size`](super::BuildParams::cluster_size) primitives. Each cluster is a run of
//!    codes that share their top bits; dense regions get more bits than sparse ones (a fixed
//!    number of top bits would give clusters of any size on uneven scenes).
//! 3. **Top**: binned SAH ([`topdown`](super::topdown)) over one reference per cluster (the
//!    cluster's box), split down to single clusters.
//! 4. **Bottoms**: each top leaf becomes the LBVH hierarchy of its cluster's run, built into that
//!    node with the LBVH walk (same leaf rules, boxes bottom-up); for
//!    [`Strategy::HlbvhSah`](super::Strategy::HlbvhSah), the binned-SAH subtree of the run, built
//!    by the top-down builder (everything in cache for clusters of a few thousand).
//!
//! **Depth.** With clusters of at most `M` primitives, the top is built with the depth bound
//! `max_depth - ceil(log2 M)`, so each cluster's bottom (at most `ceil(log2 M)` levels more, by
//! the LBVH's own bound) fits; the cluster size is capped so that the top still fits a balanced
//! tree over up to `n` clusters.

use super::binned::Bins;
use super::builder::{Builder, Counters};
use super::lbvh::{Code, codes_of, gather, sort_gather30_par, split_point, walk};
use super::prims::{Box8, CBounds, PrepInfo, PrimRef, ceil_log2};
use super::radix::{Item, sort_items};
use super::{BuildParams, Bvh2, MortonBits, Strategy, topdown};
use crate::geometry::morton::{morton63_scalar, morton63_x8};
use alloc::vec::Vec;

/// Builds an HLBVH.
pub(crate) fn build(b: &mut Builder, info: &PrepInfo, p: &BuildParams, out: &mut Bvh2, threads: usize) -> Counters {
    let cb = info.cbounds.to_aabb();
    match p.morton_bits {
        MortonBits::Bits30 => {
            let q = p.quantizer(&cb);
            // The references in Morton order end up in `refs`; the bottoms read them from `alt`.
            sort_gather30_par(
                &mut b.refs,
                &mut b.alt,
                &mut b.items32,
                &mut b.packed,
                &mut b.packed_tmp,
                &q,
                out,
                threads,
            );
            core::mem::swap(&mut b.refs, &mut b.alt);
            let mut codes = core::mem::take(&mut b.items32);
            let c = hierarchy(b, &codes, true, info, p, out, threads);
            core::mem::swap(&mut b.items32, &mut codes);
            c
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
            let mut codes = core::mem::take(&mut b.items64);
            let c = hierarchy(b, &codes, false, info, p, out, threads);
            core::mem::swap(&mut b.items64, &mut codes);
            c
        }
    }
}

/// Clusters, top and bottoms over the sorted `codes`; `gathered`: `b.alt` already holds the
/// references in that order (and `out` their primitive indices), else they are gathered here.
/// `threads > 1` (`std`): SAH mini-trees side by side.
fn hierarchy<K: Code>(
    b: &mut Builder,
    codes: &[Item<K>],
    gathered: bool,
    info: &PrepInfo,
    p: &BuildParams,
    out: &mut Bvh2,
    threads: usize,
) -> Counters {
    let n = codes.len() as u32;
    if !gathered {
        gather(&b.refs, &mut b.alt, codes, out);
    }

    // Clusters: cut the sorted range with the LBVH split until every piece is small enough. The
    // cap keeps `1 + ceil(log2 n) + ceil(log2 M) <= max_depth` for any number of clusters.
    let cap_bits = p.max_depth.saturating_sub(1 + ceil_log2(n)).min(16);
    let limit = p.cluster_size.clamp(1, 1 << cap_bits);
    let clusters = &mut b.clusters;
    clusters.clear();
    let ranges = &mut b.ranges;
    ranges.clear();
    ranges.push([0, n]);
    while let Some([lo, hi]) = ranges.pop() {
        if hi - lo <= limit {
            clusters.push([lo, hi]);
            continue;
        }
        let mid = split_point(codes, lo, hi);
        // NOTE: defensive; sorted codes always split strictly inside.
        let mid = if lo < mid && mid < hi { mid } else { lo + (hi - lo) / 2 };
        // Right first, so clusters come out in Morton order.
        ranges.push([mid, hi]);
        ranges.push([lo, mid]);
    }
    let largest = clusters.iter().map(|c| c[1] - c[0]).max().unwrap_or(1);

    // One reference per cluster: its box, the cluster number as the index.
    let crefs = &mut b.crefs;
    crefs.clear();
    let (mut bounds, mut cbounds) = (Box8::EMPTY, CBounds::EMPTY);
    for (k, &[lo, hi]) in clusters.iter().enumerate() {
        let bx = b.alt[lo as usize..hi as usize]
            .iter()
            .fold(Box8::EMPTY, |acc, r| acc.union(r.bounds()));
        let r = PrimRef::from_box(bx, k as u32);
        bounds.grow(r.bounds());
        cbounds.grow(r.c2());
        crefs.push(r);
    }
    let top_info = PrepInfo {
        bounds,
        cbounds,
        invalid: 0,
        total: clusters.len(),
    };
    debug_assert!(info.total >= n as usize);
    let top_params = BuildParams {
        strategy: Strategy::BinnedSah,
        min_leaf_size: 1,
        max_leaf_size: 1,
        max_depth: p.max_depth - ceil_log2(largest),
        ..*p
    };
    let top = &mut b.top;
    top.nodes.clear();
    top.prim_indices.clear();
    let mut c = topdown::build_refs(crefs, &mut b.calt, &top_info, &top_params, top);
    let forced_top = c.forced_splits;
    c = Counters {
        forced_splits: forced_top,
        ..Counters::default()
    };

    // Bottoms: copy the top, then grow each top leaf into its cluster's subtree.
    out.nodes.reserve((2 * n as usize).saturating_sub(1));
    out.nodes.extend_from_slice(&top.nodes);
    if p.strategy == Strategy::HlbvhSah {
        // SAH mini-trees: the binned builder over each cluster's run of sorted references (in
        // `alt`, with `refs` as its second buffer).
        let bp = BuildParams {
            strategy: Strategy::BinnedSah,
            ..*p
        };
        let mut bins = Bins::new();
        let mut tasks = Vec::new();
        // With threads: the mini-trees' tasks, built side by side at the end.
        let mut par: Vec<topdown::Task> = Vec::new();
        let tstack = &mut b.ranges;
        tstack.clear();
        tstack.push([0, 1]);
        while let Some([i, depth]) = tstack.pop() {
            let node = top.nodes[i as usize];
            if !node.is_leaf() {
                tstack.push([node.left(), depth + 1]);
                tstack.push([node.left() + 1, depth + 1]);
                continue;
            }
            let k = top.prim_indices.get(node.index as usize).copied().unwrap_or(0);
            let [lo, hi] = clusters[k as usize];
            let (bx, cb) = topdown::bounds_of(&b.alt[lo as usize..hi as usize]);
            let task = topdown::Task::new([i, lo, hi, depth], bx, cb);
            if threads > 1 {
                par.push(task);
            } else {
                topdown::subtree(&mut b.alt, &mut b.refs, &bp, out, task, &mut bins, &mut tasks, &mut c);
            }
        }
        #[cfg(feature = "std")]
        if !par.is_empty() {
            topdown::build_tasks_par(
                &mut b.alt,
                &mut b.refs,
                par,
                &bp,
                out,
                threads,
                &mut c,
                &mut b.par,
                false,
            );
        }
        return c;
    }
    let nodes = &mut out.nodes;
    let (stack, tstack) = (&mut b.walk, &mut b.ranges);
    stack.sah_leaves = true;
    tstack.clear();
    tstack.push([0, 1]);
    while let Some([i, depth]) = tstack.pop() {
        let node = top.nodes[i as usize];
        if !node.is_leaf() {
            tstack.push([node.left(), depth + 1]);
            tstack.push([node.left() + 1, depth + 1]);
            continue;
        }
        let k = top.prim_indices.get(node.index as usize).copied().unwrap_or(0);
        let [lo, hi] = clusters[k as usize];
        walk(nodes, &b.alt, codes, p, [i, lo, hi, depth], stack, &mut c);
    }
    c
}
