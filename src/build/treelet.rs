//! Treelet restructuring ([`Refine::Treelets`](super::Refine::Treelets),
//! [`Bvh2::optimize_treelets`]): Karras and Aila, "Fast Parallel Construction of High-Quality
//! Bounding Volume Hierarchies" (HPG 2013, "TRBVH"), single-threaded, as a post-pass after any
//! builder.
//!
//! Input: a valid [`Bvh2`]. Output: the same tree with some interior nodes rearranged; the leaves,
//! their primitive slots and the root box are kept, every other interior box is the exact union
//! of its children's.
//!
//! 1. **Order.** One pre-order pass from the root (explicit stack, every node seen once) records
//!    each node's depth; the nodes are then visited in reverse pre-order, so every node comes
//!    after all of its descendants (bottom-up, as Karras' atomic counters order them).
//! 2. **Treelets.** At an interior node `r` with at least
//!    [`min_prims`](TreeletParams::min_prims) primitives below it (Karras' `gamma`), the treelet
//!    starts as `r`'s two children and grows by replacing its largest-area interior leaf with that
//!    node's children, until it has [`leaves`](TreeletParams::leaves) leaves (at most 8) or no
//!    interior leaf is left. Treelet leaves are whole subtrees (BVH leaves of any size included);
//!    they are moved, never changed.
//! 3. **Dynamic programming over subsets.** For every subset `S` of the treelet's `n` leaves (a bit
//!    mask), the box and half area `A(S)` come from `S` minus its lowest bit; the cost of the best
//!    subtree over `S` is `c(S) = A(S) + min_P [c(P) + c(S \ P)]`, `c({i}) = 0`, over the
//!    `2^(|S|-1) - 1` partitions with the lowest bit in `P`: about `3^n / 2` steps in all (1,100 for
//!    7 leaves). The leaves' own subtree costs and `C_I`, `C_T` drop out: every topology holds the
//!    same leaves and `n - 1` interior nodes, so the SAH cost differs only by `C_T` times the sum
//!    of the interior nodes' areas, which is what `c` minimises.
//! 4. **Accept or skip.** The new topology replaces the old one only where its interior area is
//!    smaller by a relative margin of `1e-5` (more than `f32` rounding of sums of 7 terms, so the
//!    SAH cost never rises) and it keeps the deepest leaf below `r` within the depth bound
//!    (depths and subtree heights are tracked per node; a restructuring that would break the bound
//!    is skipped).
//! 5. **Rewrite in place.** The treelet's `n - 1` sibling pairs are reused for the new topology's
//!    `n - 1` pairs, so siblings stay adjacent and the node count and leaf order are unchanged; a
//!    moved treelet leaf is one 32-byte copy (its own children stay where they are).
//!
//! Unlike Karras, leaves are never merged or split (the primitive-index array stays as it is).
//! In a parallel build ([`Builder::build_into_par`](super::Builder::build_into_par)) a round
//! runs on several threads where the tree's layout can be cut into runs of slots that each hold
//! one subtree (the top-down builders' layout; the rotations' cut): the runs side by side, then
//! the nodes above them, the same tree slot for slot (a treelet reads and writes only below its
//! root). Elsewhere it is single-threaded: see [`TreeletParams`] for the cost and the knobs.
//! [`Bvh2::optimize_treelets_agglomerative`] is the agglomerative variant (ATRBVH).

use super::prims::Box8;
use super::validate::{Walk, checked_pre_order};
use super::{Bvh2, Node, TreeletParams, ValidateError};
use alloc::vec::Vec;

/// Most leaves of a treelet.
pub(crate) const MAX_TREELET_LEAVES: usize = 8;
/// Most leaves of an agglomerative treelet (ATRBVH).
pub(crate) const MAX_AGGLOMERATIVE_LEAVES: usize = 16;
const SUBSETS: usize = 1 << MAX_TREELET_LEAVES;

/// Slots `off..` of an array (the tree's nodes, or what the pass knows of them), indexed by slot:
/// the whole tree (`off` 0), or one run of a subtree's slots on a worker thread.
pub(crate) struct At<'a, T> {
    s: &'a mut [T],
    off: usize,
}

impl<T> core::ops::Index<usize> for At<'_, T> {
    type Output = T;
    #[inline(always)]
    fn index(&self, i: usize) -> &T {
        &self.s[i - self.off]
    }
}

impl<T> core::ops::IndexMut<usize> for At<'_, T> {
    #[inline(always)]
    fn index_mut(&mut self, i: usize) -> &mut T {
        &mut self.s[i - self.off]
    }
}

/// What the pass knows of a node: primitives below it (saturating), depth (root = 1) and height
/// (leaf = 1), both saturating at 255 (an over-estimate only makes the depth check stricter).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct NodeInfo {
    prims: u32,
    depth: u8,
    height: u8,
}

/// The pass's working memory, kept in a [`Builder`](super::Builder).
#[derive(Clone, Debug, Default)]
pub(crate) struct TreeletScratch {
    walk: Walk,
    info: Vec<NodeInfo>,
}

/// What [`Bvh2::optimize_treelets`] did.
///
/// ```
/// use strahl::{build::{Bvh2, BuildParams, TreeletParams}, scene};
/// let soup = scene::thin_soup(500, 2);
/// let (mut bvh, _) = Bvh2::build(&soup[..], &BuildParams::median()).unwrap();
/// let s = bvh.optimize_treelets(&TreeletParams { rounds: 2, ..TreeletParams::default() }, 64).unwrap();
/// assert!(s.restructured <= s.treelets);
/// assert_eq!(s.max_depth, bvh.validate(&soup[..]).unwrap().max_depth);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TreeletStats {
    /// Treelets evaluated (over all rounds).
    pub treelets: u32,
    /// Treelets rearranged.
    pub restructured: u32,
    /// Depth of the deepest leaf afterwards (root = 1; 0 for an empty tree; saturates at 255).
    pub max_depth: u32,
}

/// The dynamic program's tables for one treelet (on the stack: about 12 KB).
struct Tables {
    boxes: [Box8; SUBSETS],
    cost: [f32; SUBSETS],
    part: [u8; SUBSETS],
    height: [u8; SUBSETS],
    prims: [u32; SUBSETS],
}

/// Runs the pass over `bvh` (see [`Bvh2::optimize_treelets`]).
pub(crate) fn optimize(
    bvh: &mut Bvh2,
    tp: &TreeletParams,
    max_depth: u32,
    s: &mut TreeletScratch,
) -> Result<TreeletStats, ValidateError> {
    optimize_with(bvh, tp, false, max_depth, s, 1)
}

/// [`optimize`], or with `agglomerative` the agglomerative variant (ATRBVH).
pub(crate) fn optimize_with(
    bvh: &mut Bvh2,
    tp: &TreeletParams,
    agglomerative: bool,
    max_depth: u32,
    s: &mut TreeletScratch,
    threads: usize,
) -> Result<TreeletStats, ValidateError> {
    let mut stats = TreeletStats::default();
    let most = if agglomerative {
        MAX_AGGLOMERATIVE_LEAVES
    } else {
        MAX_TREELET_LEAVES
    };
    let leaves = (tp.leaves as usize).clamp(2, most);
    let mut t = tables();
    // The documented range (`1 ..= 16`) holds here too: this is also reached without
    // `BuildParams::check`, through `Bvh2::optimize_treelets`.
    let mut before = u32::MAX;
    for _ in 0..tp.rounds.clamp(1, 16) {
        if stats.restructured == before {
            // The last round changed nothing, so another would find the same tree.
            break;
        }
        before = stats.restructured;
        // NOTE: checked every round, not only the first: one linear walk beside a round of
        // treelet searches.
        pre_order(&bvh.nodes, bvh.prim_indices.len(), s)?;
        let pass = Pass {
            min_prims: tp.min_prims,
            leaves,
            agglomerative,
            max_depth,
        };
        if let Some((treelets, restructured)) = par_round(bvh, &mut s.info, &pass, threads) {
            stats.treelets += treelets;
            stats.restructured += restructured;
            continue;
        }
        let TreeletScratch { walk, info } = s;
        let mut nodes = At {
            s: &mut bvh.nodes,
            off: 0,
        };
        let mut info = At { s: info, off: 0 };
        for &r in walk.order.iter().rev() {
            let (treelet, changed) = pass.visit(&mut nodes, &mut info, r, &mut t);
            stats.treelets += u32::from(treelet);
            stats.restructured += u32::from(changed);
        }
    }
    stats.max_depth = match bvh.nodes.first() {
        Some(_) => s.info[0].height as u32,
        None => 0,
    };
    Ok(stats)
}

/// One round's settings.
struct Pass {
    min_prims: u32,
    leaves: usize,
    agglomerative: bool,
    max_depth: u32,
}

impl Pass {
    /// Node `r`, after every node below it: what the pass knows of it from its children, and its
    /// treelet restructured where that pays. (treelet formed, tree changed).
    #[inline]
    fn visit(&self, nodes: &mut At<'_, Node>, info: &mut At<'_, NodeInfo>, r: u32, t: &mut Tables) -> (bool, bool) {
        let node = nodes[r as usize];
        if node.is_leaf() {
            info[r as usize].prims = node.count;
            info[r as usize].height = 1;
            return (false, false);
        }
        let l = node.left() as usize;
        let (a, b) = (info[l], info[l + 1]);
        let ir = &mut info[r as usize];
        ir.prims = a.prims.saturating_add(b.prims);
        ir.height = a.height.max(b.height).saturating_add(1);
        if ir.prims < self.min_prims || self.leaves < 3 {
            return (false, false);
        }
        let changed = match form(nodes, r, self.leaves) {
            None => false,
            Some(tl) if self.agglomerative => agglomerate(nodes, info, r, &tl, self.max_depth),
            Some(tl) => restructure(nodes, info, r, &tl, self.max_depth, t),
        };
        (true, changed)
    }
}

/// The dynamic program's tables, empty.
fn tables() -> Tables {
    Tables {
        boxes: [Box8::EMPTY; SUBSETS],
        cost: [0.0; SUBSETS],
        part: [0; SUBSETS],
        height: [0; SUBSETS],
        prims: [0; SUBSETS],
    }
}

/// One round on up to `threads` threads (`std`), or `None` (nothing done) where the tree cannot
/// be cut: the cut of the parallel rotations ([`rotate::plan_runs`](super::rotate), runs of slots
/// that hold all the descendants of one node and nothing else, checked), each run's nodes visited
/// bottom-up (in reverse slot order: every node after its descendants) side by side, then the
/// nodes above the runs on this thread. A treelet reads and writes only below the node it is
/// at, so this is the sequential round's tree, slot for slot. `info` holds the depths of the
/// round's pre-order walk.
#[cfg(feature = "std")]
fn par_round(bvh: &mut Bvh2, info: &mut [NodeInfo], pass: &Pass, threads: usize) -> Option<(u32, u32)> {
    use super::rotate;
    use core::sync::atomic::{AtomicU32, Ordering};
    if threads <= 1 || bvh.nodes.len() < rotate::PAR_MIN_NODES {
        return None;
    }
    let mut depth = alloc::vec![0u32; bvh.nodes.len()];
    let (runs, top) = rotate::plan_runs(bvh, threads, &mut depth)?;
    if !rotate::check_runs(bvh, &runs, &mut depth, threads) {
        return None;
    }
    let ranges = || runs.iter().map(|r| (r[1] as usize, r[2] as usize));
    let (treelets, restructured) = (AtomicU32::new(0), AtomicU32::new(0));
    {
        let parts = crate::par::split_ranges(&mut bvh.nodes, ranges());
        let mut jobs: Vec<_> = ranges()
            .zip(parts)
            .zip(crate::par::split_ranges(info, ranges()))
            .collect();
        // Largest runs first.
        jobs.sort_unstable_by_key(|((r, _), _)| core::cmp::Reverse(r.1 - r.0));
        crate::par::each_job(jobs, threads, |(((first, end), nodes), info)| {
            let mut t = tables();
            let (mut tl, mut ch) = (0, 0);
            let mut nodes = At { s: nodes, off: first };
            let mut info = At { s: info, off: first };
            for r in (first..end).rev() {
                let (a, b) = pass.visit(&mut nodes, &mut info, r as u32, &mut t);
                tl += u32::from(a);
                ch += u32::from(b);
            }
            treelets.fetch_add(tl, Ordering::Relaxed);
            restructured.fetch_add(ch, Ordering::Relaxed);
        });
    }
    let (mut tl, mut ch) = (treelets.into_inner(), restructured.into_inner());
    let mut t = tables();
    let mut nodes = At {
        s: &mut bvh.nodes,
        off: 0,
    };
    let mut info = At { s: info, off: 0 };
    for &r in top.iter().rev() {
        let (a, b) = pass.visit(&mut nodes, &mut info, r, &mut t);
        tl += u32::from(a);
        ch += u32::from(b);
    }
    Some((tl, ch))
}

/// Without `std`: every round on one thread.
#[cfg(not(feature = "std"))]
fn par_round(_: &mut Bvh2, _: &mut [NodeInfo], _: &Pass, _: usize) -> Option<(u32, u32)> {
    None
}

/// Pre-order from the root into `s.walk.order` ([`checked_pre_order`]: the tree may come from
/// anywhere), with each node's depth in `s.info`.
fn pre_order(nodes: &[Node], slots: usize, s: &mut TreeletScratch) -> Result<(), ValidateError> {
    let TreeletScratch { walk, info } = s;
    // NOTE: resized only when the length changes; every reachable entry is written before use.
    if info.len() != nodes.len() {
        info.resize(nodes.len(), NodeInfo::default());
    }
    if let Some(root) = info.first_mut() {
        root.depth = 1;
    }
    checked_pre_order(nodes, slots, walk, |p, c| {
        info[c as usize].depth = info[p as usize].depth.saturating_add(1);
    })
}

#[derive(Clone, Copy)]
/// A treelet: its leaves (subtrees, moved whole) and interior nodes (`inner[0]` its root), and
/// the interior nodes' summed half areas but the root's.
struct Treelet {
    leaf: [u32; MAX_AGGLOMERATIVE_LEAVES],
    inner: [u32; MAX_AGGLOMERATIVE_LEAVES],
    n: usize,
    old_area: f32,
}

/// Forms the treelet at interior node `r`: expands the largest-area interior leaf until there are
/// `max_leaves` leaves (or none is interior). `None` for fewer than 3 leaves or a box that is not
/// finite anywhere in it (left alone).
fn form(nodes: &At<'_, Node>, r: u32, max_leaves: usize) -> Option<Treelet> {
    let max_leaves = max_leaves.min(MAX_AGGLOMERATIVE_LEAVES);
    let mut leaf = [0u32; MAX_AGGLOMERATIVE_LEAVES];
    let mut area = [0f32; MAX_AGGLOMERATIVE_LEAVES];
    let mut inner = [0u32; MAX_AGGLOMERATIVE_LEAVES];
    let l = nodes[r as usize].left();
    leaf[0] = l;
    leaf[1] = l + 1;
    area[0] = Box8::from_node(&nodes[l as usize]).half_area_nonempty();
    area[1] = Box8::from_node(&nodes[l as usize + 1]).half_area_nonempty();
    inner[0] = r;
    let (mut n, mut ni) = (2usize, 1usize);
    let mut old_area = 0.0f32;
    while n < max_leaves {
        let mut pick = usize::MAX;
        let mut best = f32::NEG_INFINITY;
        for i in 0..n {
            // NOTE: `>` skips NaN areas; such a leaf is never expanded.
            if !nodes[leaf[i] as usize].is_leaf() && area[i] > best {
                (pick, best) = (i, area[i]);
            }
        }
        if pick == usize::MAX {
            break;
        }
        let s = leaf[pick];
        inner[ni] = s;
        ni += 1;
        old_area += area[pick];
        let c = nodes[s as usize].left();
        leaf[pick] = c;
        leaf[n] = c + 1;
        area[pick] = Box8::from_node(&nodes[c as usize]).half_area_nonempty();
        area[n] = Box8::from_node(&nodes[c as usize + 1]).half_area_nonempty();
        n += 1;
    }
    // NOTE: a NaN or infinite box anywhere in the treelet leaves it alone.
    if n < 3 || !(old_area + area[..n].iter().sum::<f32>()).is_finite() {
        return None;
    }
    debug_assert_eq!(ni, n - 1);
    Some(Treelet {
        leaf,
        inner,
        n,
        old_area,
    })
}

/// Finds the best topology of treelet `tl` (at `r`) by dynamic programming over its leaf subsets
/// and writes it if it is cheaper and within the depth bound. Returns `true` if the tree changed.
fn restructure(
    nodes: &mut At<'_, Node>,
    info: &mut At<'_, NodeInfo>,
    r: u32,
    tl: &Treelet,
    max_depth: u32,
    t: &mut Tables,
) -> bool {
    let Treelet { leaf, n, old_area, .. } = *tl;
    if n > MAX_TREELET_LEAVES {
        return false;
    }

    // Subsets of the leaves, in increasing order: every proper subset of `S` comes before `S`.
    let full = (1usize << n) - 1;
    for i in 0..n {
        let b = 1usize << i;
        t.boxes[b] = Box8::from_node(&nodes[leaf[i] as usize]);
        t.cost[b] = 0.0;
        t.height[b] = info[leaf[i] as usize].height;
        t.prims[b] = info[leaf[i] as usize].prims;
    }
    for set in 3..=full {
        let low = set & set.wrapping_neg();
        if low == set {
            continue;
        }
        let rest = set ^ low;
        let bx = t.boxes[rest].union(t.boxes[low]);
        t.boxes[set] = bx;
        t.prims[set] = t.prims[rest].saturating_add(t.prims[low]);
        // Every partition {P, S \ P} once: P holds the lowest bit and any proper subset of the rest.
        // PERF: the minimum of `cost bits << 8 | P` as one integer (costs are >= 0, so their bits
        // order as the floats do; NaN sorts last): one compare and move per partition instead of
        // a float compare and two selects, measured 2x faster for the whole pass.
        let mut best = u64::MAX;
        let mut q = rest;
        loop {
            q = (q - 1) & rest;
            let p = low | q;
            let c = t.cost[p & (SUBSETS - 1)] + t.cost[(set ^ p) & (SUBSETS - 1)];
            best = best.min((c.to_bits() as u64) << 8 | p as u64);
            if q == 0 {
                break;
            }
        }
        let best_p = (best & 0xff) as usize;
        t.cost[set] = bx.half_area_nonempty() + f32::from_bits((best >> 8) as u32);
        t.part[set] = best_p as u8;
        t.height[set] = t.height[best_p].max(t.height[set ^ best_p]).saturating_add(1);
    }

    // The root's area is in both; compare the other interior nodes.
    let new_area = t.cost[full] - t.boxes[full].half_area_nonempty();
    // NOTE: false for NaN.
    let cheaper = new_area < old_area * (1.0 - 1e-5);
    if !cheaper {
        return false;
    }
    let deepest = info[r as usize].depth as u32 - 1 + t.height[full] as u32;
    if deepest > max_depth {
        return false;
    }

    // Topology nodes are leaf subsets; a one-bit subset is treelet leaf `i`.
    rewrite(nodes, info, r, tl, full, |set| {
        let p = t.part[set] as usize;
        let leaf = |sub: usize| (sub & (sub - 1) == 0).then(|| sub.trailing_zeros() as usize);
        (
            t.boxes[set],
            t.prims[set],
            t.height[set],
            [p, set ^ p].map(|sub| (sub, leaf(sub))),
        )
    });
    true
}

/// ATRBVH (Domingues and Pedrini 2015): the topology of treelet `tl` (at `r`) by agglomerative
/// clustering of its leaves, the two clusters whose union has the smallest surface area merged
/// first (over a distance matrix updated per merge: about `n^3 / 6` steps for `n` leaves, 120
/// for 9, against the dynamic program's `3^n / 2`); written as [`restructure`] writes its own,
/// where cheaper and within the depth bound. Returns `true` if the tree changed.
// NOTE: the distance matrix is read and written by row and by column at once; index loops say so
// more plainly than iterators.
#[allow(clippy::needless_range_loop)]
fn agglomerate(nodes: &mut At<'_, Node>, info: &mut At<'_, NodeInfo>, r: u32, tl: &Treelet, max_depth: u32) -> bool {
    const M: usize = MAX_AGGLOMERATIVE_LEAVES;
    let Treelet { leaf, n, old_area, .. } = *tl;
    // Clusters `0..n` are the leaves, `n..2n - 1` the merges (the last one the root).
    let mut bx = [Box8::EMPTY; 2 * M];
    let mut height = [0u8; 2 * M];
    let mut prims = [0u32; 2 * M];
    let mut kids = [(0u8, 0u8); 2 * M];
    for i in 0..n {
        bx[i] = Box8::from_node(&nodes[leaf[i] as usize]);
        height[i] = info[leaf[i] as usize].height;
        prims[i] = info[leaf[i] as usize].prims;
    }
    // The live clusters, and their pairwise union areas (symmetric).
    let mut live: [u8; M] = core::array::from_fn(|i| i as u8);
    let mut d = [[0f32; M]; M];
    for i in 0..n {
        for j in i + 1..n {
            let a = bx[i].union(bx[j]).half_area_nonempty();
            (d[i][j], d[j][i]) = (a, a);
        }
    }
    let (mut k, mut next, mut new_area) = (n, n, 0.0f32);
    while k > 1 {
        // The closest pair, the first in scan order on ties.
        let (mut bi, mut bj, mut best) = (0, 1, f32::INFINITY);
        for i in 0..k {
            for j in i + 1..k {
                if d[i][j] < best {
                    (bi, bj, best) = (i, j, d[i][j]);
                }
            }
        }
        let (a, b) = (live[bi] as usize, live[bj] as usize);
        bx[next] = bx[a].union(bx[b]);
        kids[next] = (a as u8, b as u8);
        height[next] = height[a].max(height[b]).saturating_add(1);
        prims[next] = prims[a].saturating_add(prims[b]);
        if k > 2 {
            // The root's area is the same in every topology.
            new_area += bx[next].half_area_nonempty();
        }
        // The merge takes `bi`'s place; the last live cluster takes `bj`'s.
        live[bi] = next as u8;
        k -= 1;
        if bj != k {
            live[bj] = live[k];
            for o in 0..=k {
                d[bj][o] = d[k][o];
                d[o][bj] = d[o][k];
            }
        }
        for o in 0..k {
            if o != bi {
                let a = bx[next].union(bx[live[o] as usize]).half_area_nonempty();
                (d[bi][o], d[o][bi]) = (a, a);
            }
        }
        next += 1;
    }
    let root = next - 1;
    // NOTE: false for NaN.
    let cheaper = new_area < old_area * (1.0 - 1e-5);
    if !cheaper {
        return false;
    }
    if info[r as usize].depth as u32 - 1 + height[root] as u32 > max_depth {
        return false;
    }

    // Topology nodes are clusters; cluster `i < n` is treelet leaf `i`.
    rewrite(nodes, info, r, tl, root, |c| {
        let (a, b) = kids[c];
        let leaf = |sub: usize| (sub < n).then_some(sub);
        (
            bx[c],
            prims[c],
            height[c],
            [a as usize, b as usize].map(|sub| (sub, leaf(sub))),
        )
    });
    true
}

/// Writes treelet `tl`'s new topology in place: its `n - 1` sibling pairs reused for the new
/// topology's pairs, so siblings stay adjacent and the node count is unchanged, and each treelet
/// leaf moved whole (one 32-byte copy: its own children stay where they are). `node(id)` gives a
/// topology node's box, primitives, height and children (their ids, and for a treelet leaf its
/// index); `root` is the id of the topology's root, written at `r` (which keeps its box).
fn rewrite(
    nodes: &mut At<'_, Node>,
    info: &mut At<'_, NodeInfo>,
    r: u32,
    tl: &Treelet,
    root: usize,
    node: impl Fn(usize) -> (Box8, u32, u8, [(usize, Option<usize>); 2]),
) {
    const M: usize = MAX_AGGLOMERATIVE_LEAVES;
    let n = tl.n;
    let mut pairs = [0u32; M];
    for (p, &i) in pairs.iter_mut().zip(&tl.inner[..n - 1]) {
        *p = nodes[i as usize].left();
    }
    let mut saved = [<Node as bytemuck::Zeroable>::zeroed(); M];
    let mut saved_info = [NodeInfo::default(); M];
    for i in 0..n {
        saved[i] = nodes[tl.leaf[i] as usize];
        saved_info[i] = info[tl.leaf[i] as usize];
    }
    // An explicit stack of (slot, topology node); at most n - 1 entries are ever pushed.
    let mut stack = [(0u32, 0usize); M];
    let (mut top, mut np) = (1usize, n - 1);
    stack[0] = (r, root);
    while top > 0 {
        top -= 1;
        let (slot, id) = stack[top];
        np -= 1;
        let pair = pairs[np];
        let (bx, prims, height, kids) = node(id);
        let sn = &mut nodes[slot as usize];
        if slot == r {
            // The root keeps its box (its parent's box holds it).
            sn.index = pair;
        } else {
            *sn = bx.to_node(pair, 0);
        }
        sn.count = 0;
        info[slot as usize].prims = prims;
        info[slot as usize].height = height;
        for (child, (sub, leaf)) in [pair, pair + 1].into_iter().zip(kids) {
            match leaf {
                Some(i) => {
                    nodes[child as usize] = saved[i];
                    info[child as usize] = saved_info[i];
                }
                None => {
                    stack[top] = (child, sub);
                    top += 1;
                }
            }
        }
    }
    debug_assert_eq!(np, 0);
}

impl Bvh2 {
    /// Rearranges the tree in place by treelet restructuring (Karras and Aila 2013): bottom-up,
    /// at every interior node with at least [`min_prims`](TreeletParams::min_prims) primitives,
    /// the treelet of up to [`leaves`](TreeletParams::leaves) subtrees (grown by expanding the
    /// largest-area one) gets the topology of least interior area, found by dynamic programming
    /// over all subsets of its leaves. Usable after any builder, or on a tree from anywhere. The SAH cost
    /// ([`sah_cost`](Self::sah_cost), any `C_T`, `C_I`) never rises; leaves, the primitive-index
    /// array, the node count and the root box stay as they are; no leaf ends up deeper than
    /// `max_depth` (clamped to [`traverse::MAX_DEPTH`](crate::traverse::MAX_DEPTH)) unless it
    /// already was. Interior boxes are recomputed as exact unions of the treelet leaves' boxes,
    /// so a tree whose boxes contain their children's stays valid.
    ///
    /// Errors, without changing the tree, if its structure is malformed (child or slot indices out
    /// of range, a node reached twice). Allocates its working memory; to reuse it, see
    /// [`Builder::optimize_treelets`](super::Builder::optimize_treelets), or set
    /// [`BuildParams::refine`](super::BuildParams::refine) to run the pass inside a build.
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams, TreeletParams}, scene};
    /// let soup = scene::thin_soup(5000, 1);
    /// let (mut bvh, _) = Bvh2::build(&soup[..], &BuildParams::fastest()).unwrap();
    /// let before = bvh.sah_cost(1.0, 1.0);
    /// let stats = bvh.optimize_treelets(&TreeletParams::default(), 64).unwrap();
    /// assert!(stats.restructured > 0 && stats.max_depth <= 64);
    /// assert!(bvh.sah_cost(1.0, 1.0) < before);
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// ```
    pub fn optimize_treelets(&mut self, params: &TreeletParams, max_depth: u32) -> Result<TreeletStats, ValidateError> {
        super::Builder::new().optimize_treelets(self, params, max_depth)
    }

    /// [`optimize_treelets`](Self::optimize_treelets) with agglomerative treelets (ATRBVH,
    /// Domingues and Pedrini, "Bounding Volume Hierarchy Optimization through Agglomerative
    /// Treelet Restructuring", HPG 2015): the same treelets (up to 16 leaves, `params.leaves` in
    /// `3 ..= 16`; their paper uses 9), but each topology is built by merging the two clusters
    /// whose union has the smallest surface area until one is left, instead of the exact search
    /// over all subsets: about `n^3 / 6` steps for `n` leaves instead of `3^n / 2`, so larger
    /// treelets for less work. Kept only where cheaper, so the SAH cost never rises; the same
    /// guarantees and errors as [`optimize_treelets`](Self::optimize_treelets).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams, TreeletParams}, scene};
    /// let soup = scene::thin_soup(5000, 1);
    /// let (mut bvh, _) = Bvh2::build(&soup[..], &BuildParams::fastest()).unwrap();
    /// let before = bvh.sah_cost(1.0, 1.0);
    /// let stats = bvh.optimize_treelets_agglomerative(&TreeletParams::agglomerative(), 64).unwrap();
    /// assert!(stats.restructured > 0 && stats.max_depth <= 64);
    /// assert!(bvh.sah_cost(1.0, 1.0) < before);
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// ```
    pub fn optimize_treelets_agglomerative(
        &mut self,
        params: &TreeletParams,
        max_depth: u32,
    ) -> Result<TreeletStats, ValidateError> {
        super::Builder::new().optimize_treelets_agglomerative(self, params, max_depth)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;
    use alloc::vec;
    use glam::Vec3;

    fn cube(x: f32) -> Aabb {
        Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x + 0.1, 0.1, 0.1))
    }

    /// Root over `(a, c)` and `(b, d)`: four one-primitive leaves at slots 3..7.
    fn crossed(xs: [f32; 4]) -> Bvh2 {
        let [a, b, c, d] = xs.map(cube);
        let ac = a.union(&c);
        let bd = b.union(&d);
        Bvh2 {
            nodes: vec![
                Node::interior(&ac.union(&bd), 1),
                Node::interior(&ac, 3),
                Node::interior(&bd, 5),
                Node::leaf(&a, 0, 1),
                Node::leaf(&c, 2, 1),
                Node::leaf(&b, 1, 1),
                Node::leaf(&d, 3, 1),
            ],
            prim_indices: vec![0, 1, 2, 3],
        }
    }

    /// The leaf slots under each child of the root.
    fn groups(b: &Bvh2) -> [Vec<u32>; 2] {
        let l = b.nodes[0].left() as usize;
        [l, l + 1].map(|c| {
            let n = b.nodes[c];
            let mut v: Vec<u32> = if n.is_leaf() {
                vec![n.index]
            } else {
                let k = n.left() as usize;
                vec![b.nodes[k].index, b.nodes[k + 1].index]
            };
            v.sort();
            v
        })
    }

    #[test]
    fn edge_cases() {
        let p = TreeletParams::new();
        // (scene, restructured, root groups afterwards)
        let cases: [([f32; 4], u32, [Vec<u32>; 2]); 3] = [
            // a, b near each other, c, d far: pair them up.
            ([0.0, 0.2, 10.0, 10.2], 1, [vec![0, 1], vec![2, 3]]),
            // Already optimal (a next to c, b next to d): left alone.
            ([0.0, 10.0, 0.2, 10.2], 0, [vec![0, 2], vec![1, 3]]),
            // All four coincide: no strictly better topology, left alone.
            ([1.0; 4], 0, [vec![0, 2], vec![1, 3]]),
        ];
        for (xs, restructured, want) in cases {
            let mut b = crossed(xs);
            let before = b.sah_cost(1.0, 1.0);
            let s = optimize(&mut b, &p, 64, &mut TreeletScratch::default()).unwrap();
            assert_eq!(
                (s.treelets, s.restructured, s.max_depth),
                (3, restructured, 3),
                "{xs:?}"
            );
            assert_eq!(groups(&b), want, "{xs:?}");
            assert!(b.sah_cost(1.0, 1.0) <= before);
            let boxes: Vec<Aabb> = xs.map(cube).to_vec();
            b.validate(&boxes[..]).unwrap();
        }
        // A depth bound that the better topology would not break (it is no deeper) is kept; a
        // tree already at the bound stays within it.
        let mut b = crossed([0.0, 0.2, 10.0, 10.2]);
        let s = optimize(&mut b, &p, 3, &mut TreeletScratch::default()).unwrap();
        assert_eq!((s.restructured, s.max_depth), (1, 3));
        // A non-finite box: nothing changes.
        let mut b = crossed([0.0, 0.2, 10.0, 10.2]);
        b.nodes[1].min[0] = f32::NAN;
        let before = b.clone();
        let s = optimize(&mut b, &p, 64, &mut TreeletScratch::default()).unwrap();
        assert_eq!(s.restructured, 0);
        let bytes = |b: &Bvh2| bytemuck::cast_slice::<Node, u8>(&b.nodes).to_vec();
        assert_eq!(bytes(&b), bytes(&before)); // (NaN != NaN: compare the bits)
    }

    /// The agglomerative pass on the same four-leaf trees: it pairs the close leaves, leaves an
    /// optimal or tied tree alone, and keeps to the depth bound.
    #[test]
    fn agglomerative_edge_cases() {
        let p = TreeletParams::agglomerative();
        let run = |b: &mut Bvh2, depth| optimize_with(b, &p, true, depth, &mut TreeletScratch::default(), 1).unwrap();
        for (xs, restructured, want) in [
            ([0.0, 0.2, 10.0, 10.2], 1, [vec![0, 1], vec![2, 3]]),
            ([0.0, 10.0, 0.2, 10.2], 0, [vec![0, 2], vec![1, 3]]),
            ([1.0; 4], 0, [vec![0, 2], vec![1, 3]]),
        ] {
            let mut b = crossed(xs);
            let before = b.sah_cost(1.0, 1.0);
            let s = run(&mut b, 64);
            // Two rounds, the second only where the first changed something.
            let rounds = 1 + restructured;
            assert_eq!(
                (s.treelets, s.restructured, s.max_depth),
                (3 * rounds, restructured, 3),
                "{xs:?}"
            );
            assert_eq!(groups(&b), want, "{xs:?}");
            assert!(b.sah_cost(1.0, 1.0) <= before);
            b.validate(&xs.map(cube)[..]).unwrap();
        }
        // a, b, c close, d far: merging the closest first gives the chain (((a, b), c), d), one
        // level deeper; taken without a bound, refused at depth 3.
        let mut free = crossed([0.0, 0.2, 10.0, 0.4]);
        assert_eq!(run(&mut free, 64).max_depth, 4);
        let mut b = crossed([0.0, 0.2, 10.0, 0.4]);
        let before = b.sah_cost(1.0, 1.0);
        assert!(run(&mut b, 3).max_depth <= 3);
        assert!(b.sah_cost(1.0, 1.0) <= before);
        // A non-finite box: nothing changes.
        let mut b = crossed([0.0, 0.2, 10.0, 10.2]);
        b.nodes[1].min[0] = f32::NAN;
        let before = bytemuck::cast_slice::<Node, u8>(&b.nodes).to_vec();
        assert_eq!(run(&mut b, 64).restructured, 0);
        assert_eq!(bytemuck::cast_slice::<Node, u8>(&b.nodes), &before[..]);
    }

    /// A topology exactly at the depth bound is taken (the `- 1` in the check).
    #[test]
    fn agglomerative_depth_exactly_at_the_bound() {
        let p = TreeletParams::agglomerative();
        let mut b = crossed([0.0, 0.2, 10.0, 0.4]);
        let s = optimize_with(&mut b, &p, true, 4, &mut TreeletScratch::default(), 1).unwrap();
        assert_eq!((s.restructured > 0, s.max_depth), (true, 4));
    }

    #[test]
    fn depth_bound_rejects_deeper_topologies() {
        // A balanced tree over 4 leaves where a chain would be cheaper: leaves at 0, 0.2, 0.4
        // and 10 (a, b, c close; d far): best is ((a, b), c), d) — one level deeper.
        let mut b = crossed([0.0, 0.2, 10.0, 0.4]);
        let before = b.sah_cost(1.0, 1.0);
        let s = optimize(
            &mut b.clone(),
            &TreeletParams::new(),
            64,
            &mut TreeletScratch::default(),
        )
        .unwrap();
        assert_eq!(s.max_depth, 4, "the free optimum is a chain");
        let s = optimize(&mut b, &TreeletParams::new(), 3, &mut TreeletScratch::default()).unwrap();
        assert!(s.max_depth <= 3);
        assert!(b.sah_cost(1.0, 1.0) <= before);
    }
}
