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
//! 5. **Pruning** ([`Strategy::HlbvhSah`](super::Strategy::HlbvhSah) on multi-scale scenes, where
//!    the largest cluster box has more than [`MULTI_SCALE`] times the median's area): the
//!    mini-trees are built first, their large nodes opened, and the top built over the parts, as
//!    Bonsai does ([`sah_pruned`]). A Morton cluster is a cell of the grid: on a sphereflake it
//!    holds triangles of a large sphere and of the small ones around it, which a top-down SAH
//!    split would keep apart; their mini-tree separates them, and pruning lets the top regroup
//!    them with their like from other cells.
//!
//! PERF (1M-triangle scenes, one thread, best of 3, taking turns with the unpruned build; the
//! journal's builder section, benches/RESULTS.md, has the table): the sphereflake's SAH cost from 10.7% above the full
//! sweep's to 0.2% above it, at 140 -> 157 ms; the terrain's from 7.6% to 4.5% above, at
//! 128 -> 144 ms; the soup and the bunny (no cluster stands out) unchanged.
//!
//! Tried and dropped (2026-12-06, Intel Xeon, one thread, best of 3): **mini-trees split along
//! the Morton curve** (each node of a cluster's run cut where the run is, at the cheapest by the
//! SAH of `k` equal-count boundaries, every boundary below `k` references; the references never
//! move). Where `hybrid_sah()`'s time goes on the 1M sphereflake (195 ms): preparing 8 ms, codes
//! and sort 29, clusters 4.5, mini-trees 128, pruning 6, top 4, layout 14. With `k` = 8 / 64 the
//! mini-trees took 67 / about 90 ms, but the trees were 16.6% / 7.8% above the binned ones'
//! SAH cost (59.56 / 55.07 against 51.10; the soup 617.5 / 551.9 against 479.1, the terrain
//! 47.2 / 41.4 against 36.5): a contiguous run of the curve is a worse box than a binned side.
//! Nor did **sampled binning inside the mini-trees** pay (`STRAHL_CUSTOM=8,allbutsmall,S,hybrid`
//! in `tests/build_speed.rs`, best of 3): sphereflake 203 ms / SAH 51.10 without, 199 / 53.71
//! with `bin_sample` 64, 200 / 52.26 with 128; the soup 185 / 479.1, 249 / 480.6, 183 / 479.4.
//!
//! Nor did **approximate agglomerative clustering** (AAC, Gu, He, Fatahalian and Blelloch 2013;
//! tried 2026-12-06 in place of this builder: the Morton-sorted run cut with the LBVH split down
//! to runs of fewer than `delta`, each run's clusters merged greedily by smallest union area
//! (a pairwise table, nearest neighbours searched again only when theirs merged; checked against
//! a brute-force greedy) down to `ceil(c x^(1/2 - eps))`, leaves formed by the SAH afterwards,
//! one thread, not SIMD-tuned). SAH cost and time on the 1M scenes (full sweep: sphereflake 50.98
//! in 779 ms, terrain 34.93 in 697 ms): `delta = 4, eps = 0.2` (AAC-Fast) sphereflake 52.55 in
//! 298 ms, soup 514.7; `4, 0.1` sphereflake 52.04 in 359 ms, terrain **41.83** in 457 ms, soup
//! 522.4; `20, 0.1` (AAC-HQ) sphereflake 51.26 in 1,086 ms, terrain 42.10, soup 526.7. Smallest-
//! union merging groups the terrain's and the soup's equal-sized triangles worse than a binned
//! split (this builder: terrain 36.51, soup 479.1) at any speed; only on the sphereflake would a
//! build made 2.5x faster have been within 3%.
//!
//! **Depth.** With clusters of at most `M` primitives, the top is built with the depth bound
//! `max_depth - ceil(log2 M)`, so each cluster's bottom (at most `ceil(log2 M)` levels more, by
//! the LBVH's own bound) fits; the cluster size is capped so that the top still fits a balanced
//! tree over up to `n` clusters. The pruned path bounds its top by the mini-trees' depth instead
//! (see [`sah_pruned`]).

use super::binned::Bins;
use super::builder::{Builder, Counters};
use super::lbvh::{Code, codes_of, gather, order_item_runs, sort_gather30_par, split_point, walk};
use super::prims::{Box8, CBounds, PrepInfo, PrimRef, ceil_log2};
use super::radix::{Item, sort_items};
use super::{BuildParams, Bvh2, MortonBits, Strategy, topdown};
use crate::geometry::morton::{morton63_scalar, morton63_x8};
use crate::traverse::Node;
use alloc::vec::Vec;

/// Builds an HLBVH.
pub(crate) fn build(b: &mut Builder, info: &PrepInfo, p: &BuildParams, out: &mut Bvh2, threads: usize) -> Counters {
    let cb = info.cbounds.to_aabb();
    // Runs split by their whole sub-codes: the clusters' walks bound their own depth (forced
    // splits), and the clusters stay the same under any depth bound.
    b.runs.reset(30);
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
                &mut b.runs,
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
            order_item_runs(&mut b.items64, &b.refs, &mut b.packed, &mut b.runs);
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
        let mid = split_point(codes, &b.runs, lo, hi);
        // NOTE: defensive; sorted codes always split strictly inside.
        let mid = if lo < mid && mid < hi { mid } else { lo + (hi - lo) / 2 };
        // Right first, so clusters come out in Morton order.
        ranges.push([mid, hi]);
        ranges.push([lo, mid]);
    }
    let largest = clusters.iter().map(|c| c[1] - c[0]).max().unwrap_or(1);

    // One reference per cluster: its box, the cluster number as the index.
    // Each cluster's box and centroid bounds, kept for its mini-tree.
    let crefs = &mut b.crefs;
    crefs.clear();
    b.cluster_bounds.clear();
    let (mut bounds, mut cbounds) = (Box8::EMPTY, CBounds::EMPTY);
    for (k, &[lo, hi]) in clusters.iter().enumerate() {
        let (bx, cb) = topdown::bounds_of(&b.alt[lo as usize..hi as usize]);
        b.cluster_bounds.push((bx, cb));
        let r = PrimRef::from_box(bx, k as u32);
        bounds.grow(r.bounds());
        cbounds.grow(r.c2());
        crefs.push(r);
    }
    if p.strategy == Strategy::HlbvhSah && multi_scale(crefs, &mut b.items) {
        return sah_pruned(b, n, p, out, threads);
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
            let (bx, cb) = b.cluster_bounds[k as usize];
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
        walk(nodes, &b.alt, codes, &b.runs, p, [i, lo, hi, depth], stack, &mut c);
    }
    c
}

/// Mini-tree nodes whose boxes are at most this many times the mean cluster box's (half) area
/// are kept whole; larger ones are opened (largest first, within the budget of
/// [`PARTS_PER_CLUSTER`]), their parts joining the top build on their own.
// NOTE: measured on the 1M sphereflake (`tests/build_speed.rs`, a 64-bin top, no budget), SAH
// cost against the full sweep's 50.98: no pruning 55.06, factor 1: 52.42, 0.3: 51.58, 0.1:
// 50.84 (22,085 parts; with the budget of 8 per cluster 15,768 parts and 51.09). Smaller factors
// opened more (94,394 parts at 0.02) for a worse tree and a slower top.
const PRUNE_FACTOR: f32 = 0.1;

/// Bins of the binned-SAH top over the pruned mini-trees' parts (a few thousand to tens of
/// thousands of references: cheap next to the mini-trees).
// NOTE: 1M sphereflake, factor 0.1: a 16-bin top 51.08, 64 bins 50.84, in the same time.
const TOP_BINS: u32 = 64;

/// Clusters whose largest box has more than this many times the median's half area make a
/// multi-scale scene, whose mini-trees are pruned ([`sah_pruned`]); on others (the soup's 1.6,
/// the bunny's 1.1; the sphereflake's 82, the terrain's 6.8) pruning bought nothing measurable
/// and its layout pass costs about 10% of the build, so they keep the top over whole clusters.
const MULTI_SCALE: f32 = 4.0;

/// At most this many parts per cluster: the budget that bounds the top's size (on an even
/// scene every mini-tree has many nodes above `tau`, and opening them buys nothing there).
const PARTS_PER_CLUSTER: usize = 8;

/// A pruning candidate: node `i`'s half area (as ordered bits; +inf for an empty or invalid
/// box, so it is opened first) and the complement of its leftmost reference slot (ties: the part
/// earlier in reference order first, whatever the node numbering).
fn part_key(nodes: &[Node], i: u32) -> (u32, u32, u32) {
    let a = Box8::from_node(&nodes[i as usize]).half_area_nonempty();
    let a = if a >= 0.0 { a.to_bits() } else { f32::INFINITY.to_bits() };
    (a, u32::MAX - leftmost_slot(nodes, i), i)
}

/// The first primitive slot of node `i`'s subtree (its leftmost leaf's).
fn leftmost_slot(nodes: &[Node], mut i: u32) -> u32 {
    while !nodes[i as usize].is_leaf() {
        i = nodes[i as usize].left();
    }
    nodes[i as usize].index
}

/// [`Strategy::HlbvhSah`]'s hierarchy over the clusters in `b.clusters` (ranges of the `n`
/// references in `b.alt`, in Morton order), with mini-tree pruning after Bonsai (Ganestam et al.,
/// "Bonsai: Rapid Bounding Volume Hierarchy Generation using Mini Trees", 2015):
///
/// 1. **Mini-trees**: each cluster's binned-SAH subtree, built in cache, into `out` as a forest
///    (on `threads` threads side by side, the same trees).
/// 2. **Pruning**: the largest mini-tree node is opened while its box is larger than
///    [`PRUNE_FACTOR`] times the mean cluster box (by half area), it is not a leaf, and the parts
///    stay within [`PARTS_PER_CLUSTER`] per cluster; the parts are then put in reference order
///    (ties in size broken by it too), so the result does not depend on node numbering. A Morton
///    cluster is a cell of the grid, so on multi-scale scenes (a sphereflake's large and small
///    spheres, a terrain's slopes) it mixes primitives that a top-down SAH split would keep
///    apart; the opened parts let the top group them with their like from other cells.
/// 3. **Top**: binned SAH ([`TOP_BINS`] bins on all axes) over one reference per part.
/// 4. **Layout**: the top's nodes, then each part's subtree copied below its top leaf, depth
///    first, into `b.forest` (kept between builds, so no fresh pages), which becomes `out.nodes`.
///    The copy numbers nodes by the tree's shape alone, so the threaded build lays out the same
///    array as the single-threaded one.
///
/// **Depth.** There are at most `m = min(n, 8 clusters)` parts, so mini-trees start at depth
/// `s = 1 + ceil(log2 m)`, where a balanced top over any `m` parts ends. If the deepest mini-tree
/// leaf lands at depth `D` (`D <= max_depth`), no part reaches more than `D - s` levels below its
/// root, so the top is built with the bound `max_depth - (D - s) >= s`: every leaf stays within
/// `max_depth`, and the top is split by the SAH wherever that leaves room (a bound of `s` alone
/// forced median splits once the parts came close to `n`, as with clusters of 1 primitive). The
/// cluster cap in [`hierarchy`] keeps `1 + ceil(log2 n) + ceil(log2 M) <= max_depth` for
/// clusters of `M` references, so the mini-trees fit below `s`.
fn sah_pruned(b: &mut Builder, n: u32, p: &BuildParams, out: &mut Bvh2, threads: usize) -> Counters {
    let bp = BuildParams {
        strategy: Strategy::BinnedSah,
        ..*p
    };
    let parts_max = (n as usize).min(b.clusters.len().saturating_mul(PARTS_PER_CLUSTER));
    let s = (1 + ceil_log2(parts_max as u32)).min(p.max_depth);
    let mut c = Counters::default();

    // 1. The mini-trees, roots first (one per cluster, in cluster order).
    out.nodes.clear();
    out.nodes.reserve((2 * n as usize).saturating_sub(1) + b.clusters.len());
    let mut tasks: Vec<topdown::Task> = Vec::with_capacity(b.clusters.len());
    let mut area_sum = 0.0f64;
    for (&[lo, hi], &(bx, cb)) in b.clusters.iter().zip(&b.cluster_bounds) {
        let root = out.nodes.len() as u32;
        out.nodes.push(bx.to_node(0, 0));
        area_sum += f64::from(bx.half_area_nonempty());
        tasks.push(topdown::Task::new([root, lo, hi, s], bx, cb));
    }
    let roots = tasks.len() as u32;
    #[cfg(feature = "std")]
    let threaded = threads > 1;
    #[cfg(not(feature = "std"))]
    let threaded = {
        let _ = threads;
        false
    };
    if threaded {
        #[cfg(feature = "std")]
        topdown::build_tasks_par(
            &mut b.alt,
            &mut b.refs,
            tasks,
            &bp,
            out,
            threads,
            &mut c,
            &mut b.par,
            false,
        );
    } else {
        let mut bins = Bins::new();
        let mut stack = Vec::new();
        for task in tasks {
            topdown::subtree(&mut b.alt, &mut b.refs, &bp, out, task, &mut bins, &mut stack, &mut c);
        }
    }

    // 2. Pruning: the parts, the largest mini-tree node opened first, while larger than `tau`
    //    and the parts number fewer than the budget.
    let tau = PRUNE_FACTOR * (area_sum / f64::from(roots.max(1))) as f32;
    let budget = (roots as usize).saturating_mul(PARTS_PER_CLUSTER);
    let items = &mut b.items;
    items.clear();
    let heap = &mut b.parts;
    heap.clear();
    heap.extend((0..roots).map(|root| part_key(&out.nodes, root)));
    let mut heap = alloc::collections::BinaryHeap::from(core::mem::take(heap));
    while let Some((area, slot, i)) = heap.pop() {
        let node = out.nodes[i as usize];
        if node.is_leaf() {
            items.push([u32::MAX - slot, i]);
        } else if f32::from_bits(area) <= tau || items.len() + heap.len() + 1 >= budget {
            items.push([u32::MAX - slot, i]);
            break;
        } else {
            heap.push(part_key(&out.nodes, node.left()));
            heap.push(part_key(&out.nodes, node.left() + 1));
        }
    }
    let mut rest = heap.into_vec();
    items.extend(rest.iter().map(|&(_, slot, i)| [u32::MAX - slot, i]));
    rest.clear();
    b.parts = rest;
    // In reference order (each part's leftmost slot): the same order in threaded builds.
    items.sort_unstable();

    // 3. The top over the parts.
    let crefs = &mut b.crefs;
    crefs.clear();
    let (mut bounds, mut cbounds) = (Box8::EMPTY, CBounds::EMPTY);
    for (k, &[_, i]) in items.iter().enumerate() {
        let r = PrimRef::from_box(Box8::from_node(&out.nodes[i as usize]), k as u32);
        bounds.grow(r.bounds());
        cbounds.grow(r.c2());
        crefs.push(r);
    }
    let top_info = PrepInfo {
        bounds,
        cbounds,
        invalid: 0,
        total: items.len(),
    };
    let top_params = BuildParams {
        strategy: Strategy::BinnedSah,
        min_leaf_size: 1,
        max_leaf_size: 1,
        bins: TOP_BINS,
        bin_axes: super::BinAxes::All,
        max_depth: p.max_depth - (c.max_depth.max(s) - s),
        ..*p
    };
    let top = &mut b.top;
    top.nodes.clear();
    top.prim_indices.clear();
    c.forced_splits += topdown::build_refs(crefs, &mut b.calt, &top_info, &top_params, top).forced_splits;

    // 4. The layout: the top, then each part's subtree below its top leaf, depth first, with the
    //    depth of the deepest leaf. Stack entries: destination, source, and the depth with bit
    //    `TOP` set for a source in the top.
    // PERF: about 14 ms on the 1M sphereflake (1.2M nodes). Each part's subtree copied as one run
    // with its child indices moved (the mini-trees are laid out depth first, so the run is this
    // copy's order; the same bytes, checked) took the same 14 ms (2026-12-06): the pass is bound
    // by its 38 MB read and 38 MB written, not by the walk.
    const TOP: u32 = 1 << 31;
    let fin = &mut b.forest;
    fin.clear();
    fin.reserve(out.nodes.len() + top.nodes.len());
    fin.push(top.nodes[0]);
    let stack = &mut b.parts;
    stack.clear();
    stack.push((0, 0, 1 | TOP));
    c.max_depth = 0;
    while let Some((dst, src, tagged)) = stack.pop() {
        let depth = tagged & !TOP;
        let (node, in_top) = if tagged & TOP != 0 {
            let t = top.nodes[src as usize];
            if t.is_leaf() {
                let k = top.prim_indices[t.index as usize];
                (out.nodes[items[k as usize][1] as usize], false)
            } else {
                (t, true)
            }
        } else {
            (out.nodes[src as usize], false)
        };
        if node.is_leaf() {
            fin[dst as usize] = node;
            c.max_depth = c.max_depth.max(depth);
            continue;
        }
        let left = fin.len() as u32;
        fin[dst as usize] = Node::interior(&node.aabb(), left);
        fin.extend_from_slice(&[node, node]);
        let next = (depth + 1) | if in_top { TOP } else { 0 };
        stack.push((left + 1, node.left() + 1, next));
        stack.push((left, node.left(), next));
    }
    core::mem::swap(&mut out.nodes, fin);
    c
}

/// Whether the clusters' boxes (`crefs`) differ enough in size for pruning to pay: the largest
/// half area more than [`MULTI_SCALE`] times the median. `scratch` holds the areas.
fn multi_scale(crefs: &[PrimRef], scratch: &mut Vec<[u32; 2]>) -> bool {
    scratch.clear();
    scratch.extend(crefs.iter().map(|r| {
        let a = r.bounds().half_area_nonempty();
        [if a >= 0.0 { a.to_bits() } else { f32::INFINITY.to_bits() }, 0]
    }));
    let Some(&[max, _]) = scratch.iter().max() else {
        return false;
    };
    let mid = scratch.len() / 2;
    let median = f32::from_bits(scratch.select_nth_unstable(mid).1[0]);
    f32::from_bits(max) > MULTI_SCALE * median
}
