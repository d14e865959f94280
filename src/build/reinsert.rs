//! Reinsertion ([`Refine::Reinsertion`](super::Refine::Reinsertion),
//! [`Bvh2::optimize_reinsertion`]): Bittner, Hapala and Havran, "Fast Insertion-Based
//! Optimization of Bounding Volume Hierarchies" (2013), in the one-subtree form of Meister and
//! Bittner's parallel variant (2018).
//!
//! A move takes a subtree `N` out of the tree (its parent `P` goes with it: the sibling `S` takes
//! `P`'s place, and the boxes above shrink), finds the place where putting it back costs least,
//! and puts it there (a new interior node over `N` and the node `X` it joins; the boxes above
//! `X` grow). Leaves never change, so the SAH cost changes by `C_T` times the change of the sum
//! of interior areas, and the cost of joining `X` is exact: `A(X ∪ N)` for the new node plus,
//! for every ancestor `a` of `X`, `A(a ∪ N) - A(a)` (its induced cost). The search is the branch
//! and bound of the paper: nodes in a priority queue by induced cost, children pushed with
//! `induced + A(X ∪ N) - A(X)`, the walk ended where `induced + A(N)` cannot beat the best so
//! far. `N`'s old place (next to `S`) is one of the candidates and wins ties, so a move never
//! raises the cost: the tree is put back as it was where nothing is cheaper.
//!
//! Each search visits at most [`REINSERT_SEARCH_BUDGET`] nodes and otherwise takes the best
//! place found so far (the old place if nothing cheaper was seen); the constant says why.
//!
//! Each round scores every node by how much it enlarges its parent (`A(P) - A(S)`), moves the
//! highest-scoring `per_mille` of them one after another, and stops early when a round moves
//! nothing. Interior nodes are reused where they were freed, so siblings stay adjacent; at the end
//! the nodes are laid out again in depth-first order, as the builders lay them out (a subtree's
//! nodes close together). Moves that would put a leaf deeper than the depth bound are skipped.
//!
//! Measured in the [module docs](super#measured).

use super::prims::Box8;
use super::validate::{Walk, checked_pre_order};
use super::{Bvh2, Node, ValidateError};
use alloc::collections::BinaryHeap;
use alloc::vec::Vec;
use core::cmp::Reverse;

/// The knobs of reinsertion ([`Refine::Reinsertion`](super::Refine::Reinsertion),
/// [`Bvh2::optimize_reinsertion`]).
///
/// ```
/// use strahl::build::{BuildParams, Refine, ReinsertParams};
/// let r = ReinsertParams { rounds: 2, ..ReinsertParams::default() };
/// let p = BuildParams { refine: Refine::Reinsertion(r), ..BuildParams::fast() };
/// assert!(p.check().is_ok());
/// let bad = ReinsertParams { per_mille: 0, ..r };
/// assert!(BuildParams { refine: Refine::Reinsertion(bad), ..p }.check().is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ReinsertParams {
    /// Rounds, in `1 ..= 64` (fewer where a round moves nothing).
    pub rounds: u32,
    /// Nodes taken out and put back per round, in thousandths of the tree's nodes, `1 ..= 1000`
    /// (at least one node per round).
    pub per_mille: u32,
}

impl ReinsertParams {
    /// The default: 2 rounds over every node.
    ///
    /// ```
    /// use strahl::build::ReinsertParams;
    /// const R: ReinsertParams = ReinsertParams::new(); // usable in constants
    /// assert_eq!((R.rounds, R.per_mille), (2, 1000));
    /// assert_eq!(R, ReinsertParams::default());
    /// ```
    pub const fn new() -> Self {
        Self {
            rounds: 2,
            per_mille: 1000,
        }
    }
}

impl Default for ReinsertParams {
    /// [`ReinsertParams::new`].
    fn default() -> Self {
        Self::new()
    }
}

/// What [`Bvh2::optimize_reinsertion`] did.
///
/// ```
/// use strahl::build::{BuildParams, Bvh2, ReinsertParams};
/// let tris = strahl::scene::thin_soup(5_000, 1);
/// let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
/// let stats = bvh.optimize_reinsertion(&ReinsertParams::default(), 64).unwrap();
/// assert!(stats.moved > 0 && (1..=2).contains(&stats.rounds));
/// assert_eq!(stats.max_depth, bvh.validate(&tris[..]).unwrap().max_depth);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReinsertStats {
    /// Subtrees put back somewhere else than where they were taken out, over all rounds.
    pub moved: u32,
    /// Searches stopped at [`REINSERT_SEARCH_BUDGET`] node visits (each took the best place it
    /// had seen), over all rounds: none on the trees of the builders measured, many on trees
    /// whose boxes overlap wholesale.
    pub cut: u32,
    /// Rounds run.
    pub rounds: u32,
    /// Depth of the deepest leaf afterwards (root = 1; 0 for an empty tree).
    pub max_depth: u32,
}

/// Nodes one search for a subtree's new place visits at most, in reinsertion
/// ([`Bvh2::optimize_reinsertion`], [`Refine::Reinsertion`](super::Refine::Reinsertion)); past
/// it the search takes the best place it has seen (the old place if nothing cheaper).
///
/// On trees whose boxes overlap wholesale nothing can be pruned, and an unbounded search visits
/// most of the tree for every move: the LBVH of 100,000 triangles in a unit cube beside one
/// triangle 10^7 away, when the Morton builders still left the cube's one grid cell in input
/// order, took 84 s for 3 rounds over every node (AMD EPYC, Zen 1), its searches visiting
/// 10,810 nodes at the median and up to 40,684; with the budget about 5 s (the build itself
/// 0.35 s). Such trees still come from triangles whose boxes all share a point. On the trees of `fastest()` and `fast()` over a 100,000-triangle soup, the cube
/// alone, a 116,000-triangle sphereflake and the bunny (3 rounds over every node) no search
/// visited more than 169 nodes (the median 23-39), so the budget cuts none there.
///
/// ```
/// use strahl::build::{BuildParams, Bvh2, ReinsertParams, REINSERT_SEARCH_BUDGET};
/// assert!(REINSERT_SEARCH_BUDGET >= 169); // the most a search on a builder's tree needed
/// let tris = strahl::scene::thin_soup(5_000, 1);
/// let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
/// let stats = bvh.optimize_reinsertion(&ReinsertParams::default(), 64).unwrap();
/// assert_eq!(stats.cut, 0);
/// ```
pub const REINSERT_SEARCH_BUDGET: u32 = 256;

/// Working memory of the pass, kept in a [`Builder`](super::Builder).
#[derive(Clone, Debug, Default)]
pub(crate) struct ReinsertScratch {
    parent: Vec<u32>,
    height: Vec<u32>,
    walk: Walk,
    cand: Vec<u64>,
    heap: BinaryHeap<Reverse<(u32, u32, u32)>>,
    stack: Vec<(u32, u32)>,
    nodes: Vec<Node>,
}

#[inline(always)]
fn bx(n: &Node) -> Box8 {
    Box8::from_node(n)
}

#[inline(always)]
fn area(b: Box8) -> f32 {
    b.half_area_nonempty()
}

/// Runs the pass over `bvh` (see [`Bvh2::optimize_reinsertion`]).
pub(crate) fn optimize(
    bvh: &mut Bvh2,
    rp: &ReinsertParams,
    max_depth: u32,
    s: &mut ReinsertScratch,
) -> Result<ReinsertStats, ValidateError> {
    let mut stats = ReinsertStats::default();
    if bvh.nodes.is_empty() {
        return Ok(stats);
    }
    scan(bvh, s)?;
    let n = bvh.nodes.len();
    let reachable = s.walk.order.len();
    let take = (reachable * rp.per_mille.clamp(1, 1000) as usize / 1000).max(1);
    for _ in 0..rp.rounds.clamp(1, 64) {
        if reachable < 5 {
            // A root with two leaves, or one leaf: no other place for anything.
            break;
        }
        stats.rounds += 1;
        // Score every node but the root by how much it enlarges its parent.
        s.cand.clear();
        for c in 1..n {
            if !s.walk.reached(c) {
                continue;
            }
            let p = s.parent[c] as usize;
            let l = bvh.nodes[p].index as usize;
            let sib = if c == l { l + 1 } else { l };
            let ap = area(bx(&bvh.nodes[p]));
            let score = ((ap - area(bx(&bvh.nodes[sib]))) / ap).max(0.0);
            let score = if score.is_finite() { score } else { 0.0 };
            // Highest score first; ties: the lower slot.
            s.cand
                .push((score.to_bits() as u64) << 32 | (u32::MAX - c as u32) as u64);
        }
        let k = take.min(s.cand.len());
        if k < s.cand.len() {
            s.cand.select_nth_unstable_by(k - 1, |a, b| b.cmp(a));
        }
        // The chosen ones in slot order: neighbours in the tree's depth-first layout are
        // neighbours in memory, and their searches walk much of the same path.
        // PERF: 1M sphereflake, `balanced()` + 3 rounds of 10%: 640 -> 420 ms against the order
        // of their scores, and a tree as good (SAH 49.93 against 50.02); a prefetch of the
        // children pushed in the search gained nothing measurable on top.
        s.cand[..k].sort_unstable_by_key(|&c| u32::MAX - c as u32);
        let mut moved = 0;
        for i in 0..k {
            let c = u32::MAX - s.cand[i] as u32;
            let (went, cut) = move_subtree(&mut bvh.nodes, s, c, max_depth);
            moved += went as u32;
            stats.cut += cut as u32;
        }
        stats.moved += moved;
        if moved == 0 {
            break;
        }
    }
    stats.max_depth = s.height[0];
    if stats.moved > 0 {
        relayout(bvh, s);
    }
    Ok(stats)
}

/// Checks the tree reachable from the root ([`checked_pre_order`]: children and slot ranges in
/// range, no node reached twice; then every reachable box finite and not empty) and fills
/// `s.parent`, `s.height` and `s.walk` (the reachable nodes).
fn scan(bvh: &Bvh2, s: &mut ReinsertScratch) -> Result<(), ValidateError> {
    let nodes = &bvh.nodes;
    let n = nodes.len();
    s.parent.clear();
    s.parent.resize(n, 0);
    s.height.clear();
    s.height.resize(n, 1);
    let parent = &mut s.parent;
    checked_pre_order(nodes, bvh.prim_indices.len(), &mut s.walk, |p, c| {
        parent[c as usize] = p
    })?;
    for &i in &s.walk.order {
        let b = nodes[i as usize].aabb();
        if !(b.min.is_finite() && b.max.is_finite()) {
            return Err(ValidateError::BoxNotFinite { node: i });
        }
        if b.min.cmpgt(b.max).any() {
            return Err(ValidateError::EmptyNode { node: i });
        }
    }
    // Heights bottom-up: reverse pre-order visits children before parents.
    for &i in s.walk.order.iter().rev() {
        let node = &nodes[i as usize];
        if !node.is_leaf() {
            let l = node.left() as usize;
            s.height[i as usize] = 1 + s.height[l].max(s.height[l + 1]);
        }
    }
    Ok(())
}

/// Sets the box and height of interior node `a` and its ancestors from their children, upward
/// until one is unchanged.
fn refit_up(nodes: &mut [Node], s: &mut ReinsertScratch, mut a: usize) {
    loop {
        let l = nodes[a].index as usize;
        let b = bx(&nodes[l]).union(bx(&nodes[l + 1])).to_node(l as u32, 0);
        let h = 1 + s.height[l].max(s.height[l + 1]);
        if b == nodes[a] && h == s.height[a] {
            return;
        }
        nodes[a] = b;
        s.height[a] = h;
        if a == 0 {
            return;
        }
        a = s.parent[a] as usize;
    }
}

/// Takes the subtree at slot `c` (not the root) out and puts it back where it costs least (of
/// the places the search reaches within [`REINSERT_SEARCH_BUDGET`] visits). Returns whether it went
/// somewhere else, and whether the search was cut at the budget.
fn move_subtree(nodes: &mut [Node], s: &mut ReinsertScratch, c: u32, max_depth: u32) -> (bool, bool) {
    let c = c as usize;
    let n_rec = nodes[c];
    let nb = bx(&n_rec);
    let an = area(nb);
    let hn = s.height[c];
    let p = s.parent[c] as usize;
    let pair = nodes[p].index as usize;
    let sib = if c == pair { pair + 1 } else { pair };
    // Out: the sibling takes the parent's slot; the pair's two slots are free.
    let s_rec = nodes[sib];
    nodes[p] = s_rec;
    s.height[p] = s.height[sib];
    if !s_rec.is_leaf() {
        let l = s_rec.index as usize;
        s.parent[l] = p as u32;
        s.parent[l + 1] = p as u32;
    }
    if p != 0 {
        refit_up(nodes, s, s.parent[p] as usize);
    }
    // The old place, next to the sibling (now at `p`): what any other place must beat.
    let mut induced = 0.0f32;
    let mut a = p;
    while a != 0 {
        a = s.parent[a] as usize;
        let ab = bx(&nodes[a]);
        induced += area(ab.union(nb)) - area(ab);
    }
    let baseline = induced + area(bx(&nodes[p]).union(nb));
    // NOTE: a relative margin, so that rounding in the sums never moves a subtree to a place of
    // the same cost (and rounds cannot cycle).
    let mut best = (p, baseline * (1.0 - 1e-6));
    let mut cut = false;
    if baseline.is_finite() {
        s.heap.clear();
        s.heap.push(Reverse((0, 0, 1)));
        let mut visits = 0;
        while let Some(Reverse((ci, x, d))) = s.heap.pop() {
            let ci = f32::from_bits(ci);
            if ci + an >= best.1 {
                break;
            }
            if visits == REINSERT_SEARCH_BUDGET {
                cut = true;
                break;
            }
            visits += 1;
            let x = x as usize;
            let xb = bx(&nodes[x]);
            let ax = area(xb);
            let total = ci + area(xb.union(nb));
            // `X` and `N` go one level down, under the new node at `X`'s depth `d`.
            if total < best.1 && d.saturating_add(s.height[x].max(hn)) <= max_depth {
                best = (x, total);
            }
            if !nodes[x].is_leaf() {
                let cc = (total - ax).max(0.0);
                if cc + an < best.1 {
                    let l = nodes[x].index;
                    s.heap.push(Reverse((cc.to_bits(), l, d + 1)));
                    s.heap.push(Reverse((cc.to_bits(), l + 1, d + 1)));
                }
            }
        }
    }
    // In: the node at `x` moves to the free pair beside `N`; a new interior node takes its slot.
    let x = best.0;
    let x_rec = nodes[x];
    nodes[pair] = x_rec;
    nodes[pair + 1] = n_rec;
    s.height[pair] = s.height[x];
    s.height[pair + 1] = hn;
    s.parent[pair] = x as u32;
    s.parent[pair + 1] = x as u32;
    for (slot, rec) in [(pair, x_rec), (pair + 1, n_rec)] {
        if !rec.is_leaf() {
            let l = rec.index as usize;
            s.parent[l] = slot as u32;
            s.parent[l + 1] = slot as u32;
        }
    }
    nodes[x] = bx(&x_rec).union(nb).to_node(pair as u32, 0);
    s.height[x] = 1 + s.height[pair].max(hn);
    if x != 0 {
        refit_up(nodes, s, s.parent[x] as usize);
    }
    (x != p, cut)
}

/// Lays the reachable nodes out again in depth-first order (root at 0, each interior node's
/// children as the next free pair when it is reached, left subtree first), as the builders do.
fn relayout(bvh: &mut Bvh2, s: &mut ReinsertScratch) {
    let old = &bvh.nodes;
    let out = &mut s.nodes;
    out.clear();
    out.push(old[0]);
    s.stack.clear();
    s.stack.push((0, 0));
    while let Some((o, w)) = s.stack.pop() {
        let rec = old[o as usize];
        if rec.is_leaf() {
            out[w as usize] = rec;
            continue;
        }
        let at = out.len() as u32;
        out[w as usize] = Node { index: at, ..rec };
        out.push(rec);
        out.push(rec);
        s.stack.push((rec.index + 1, at + 1));
        s.stack.push((rec.index, at));
    }
    core::mem::swap(&mut bvh.nodes, &mut s.nodes);
}

impl Bvh2 {
    /// Improves the tree by reinsertion (Bittner et al. 2013, see [`ReinsertParams`]): subtrees
    /// that enlarge their parents most are taken out and put back where they cost least by the
    /// SAH, never deeper than `max_depth` (at most [`traverse::MAX_DEPTH`](crate::traverse::MAX_DEPTH)).
    /// Never raises the SAH cost; the leaves and the primitive-index array are not touched; the
    /// nodes are numbered again (depth-first) where anything moved. Errors, with the tree
    /// untouched, where it is malformed or a reachable box is not finite or empty (as
    /// [`validate`](Self::validate) reports them).
    ///
    /// ```
    /// use strahl::{build::{BuildParams, Bvh2, ReinsertParams}, scene};
    /// let soup = scene::thin_soup(5000, 1);
    /// let (mut bvh, _) = Bvh2::build(&soup[..], &BuildParams::fastest()).unwrap();
    /// let before = bvh.sah_cost(1.0, 1.0);
    /// let stats = bvh.optimize_reinsertion(&ReinsertParams::default(), 64).unwrap();
    /// assert!(stats.moved > 0 && stats.max_depth <= 64);
    /// assert!(bvh.sah_cost(1.0, 1.0) < before);
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// ```
    pub fn optimize_reinsertion(
        &mut self,
        params: &ReinsertParams,
        max_depth: u32,
    ) -> Result<ReinsertStats, ValidateError> {
        super::Builder::new().optimize_reinsertion(self, params, max_depth)
    }
}
