//! Whole subtrees of small ranges (at most [`SMALL`] references) built in local arrays, for the
//! binned top-down builder ([`topdown`](super::topdown)) and the HLBVH's SAH mini-trees.
//!
//! Each node's split is the exact sweep of [`find_small`](super::binned::find_small) (every
//! boundary between centroids on the chosen axes, prefix and suffix areas, the first cheapest
//! boundary and axis winning), and the nodes, leaves, primitive order and counters are the ones the
//! task loop of [`topdown::subtree`](super::topdown::subtree) makes with it, in the same
//! depth-first order, tied centroids included (ranked by their position in the node's current
//! order, as the task loop's buffers hold them). What differs is how:
//!
//! - the range's boxes and centroids are read once; the references never move, a permutation of
//!   `u8` local indices (one `u128`) does;
//! - the centroid order on each axis is found once per subtree: bit `j` of `less[a][i]` says that
//!   reference `j` has a smaller centroid than reference `i` on axis `a`, bit `j` of `tied[a][i]`
//!   an equal one, so within a node's set `S` of references the rank of `i` is
//!   `popcount(less[a][i] & S) + popcount(tied[a][i] & E)`, `E` the members before `i` in the
//!   node's order;
//! - the sweeps keep areas only; the winner's boxes, centroid boxes and set are folded once;
//!   children that must be leaves are written at once, without a trip round the loop.
//!
//! PERF: `cargo test --release --lib small_speed -- --ignored --nocapture` (40,000 ranges of
//! 2..=16 references, against the task loop, taking turns): 13% faster with the longest axis,
//! 9% with all three. Whole builds of the 1M-triangle soup (same trees): `fast()`, `balanced()`
//! and `hybrid_sah()` 4-6% faster. Tried and dropped: every loop of a node running a fixed 4, 8
//! or 16 times (masked), against mispredicted loop exits: 12% *slower* with all axes (this
//! processor predicts the short loops well); boxes tracked through the sweeps with blends instead
//! of folded once: slower again. The permutation as a 32-byte array read and written 16 positions at
//! a time instead of a `u128` shifted by variable amounts (2026-12-03): fewer instructions, the
//! same time on the 256k soup (four runs each, taking turns).
//!
//! Also tried (2026-12-06, Intel Xeon, `small_speed`, longest axis): the winner's sides read from
//! prefix and suffix boxes the sweeps keep, instead of folded again (25.4 against 25.0 ms: the
//! same); and the boundaries' costs stored and their first minimum found in lanes instead of a
//! branch per boundary (30.5 ms: eight scalar stores read back as one vector stall on
//! store-to-load forwarding). A different algorithm for these ranges, greedy agglomerative
//! clustering (merge the two clusters whose union has the least area, row minima kept in
//! lanes), builds subtrees 1.7% cheaper by the SAH (0.87% of `fast()`'s whole tree on the 1M
//! soup, 483.2 -> 479.0) but took 174 ms for that build's 94,719 ranges against about 70 ms
//! here; not kept.

use super::binned::SMALL;
use super::builder::Counters;
use super::prims::{Box8, CBounds, PrimRef};
use super::topdown::split_cost;
use super::{BuildParams, Bvh2};
use crate::math::{Lane, f32x8};

/// Slot of the empty box: what order positions past a node's count point to.
const NONE: u8 = SMALL as u8;

/// A node of the subtree still to build: its slot, its positions `lo..hi` in the permutation and
/// the set of local references there, its depth, box and centroid box.
#[derive(Clone, Copy)]
struct Pending {
    node: u32,
    lo: u8,
    hi: u8,
    set: u16,
    depth: u32,
    bounds: Box8,
    /// Centroid bounds as a [`Box8`] (negated-min form); only read to pick the longest axis.
    cbox: Box8,
}

/// The local copy of a subtree's references.
struct Local<'a> {
    refs: &'a [PrimRef],
    /// Boxes, and the empty box in slot [`NONE`].
    boxes: [Box8; SMALL + 1],
    /// Doubled centroids as degenerate boxes `[-c, c]`, and the empty box in slot [`NONE`].
    cens: [Box8; SMALL + 1],
    /// Centroid keys per axis (`+inf` past the count).
    keys: [[f32; SMALL]; 3],
    /// `less[a]` and `tied[a]`, filled per axis on first use (bit `a` of `have`).
    less: [[u16; SMALL]; 3],
    tied: [[u16; SMALL]; 3],
    have: u32,
}

/// The best split found on one axis of a node: cost, references on the left, the node's order on
/// that axis, and both sides' boxes, centroid boxes and sets.
#[derive(Clone, Copy)]
struct Best {
    cost: f32,
    left_count: usize,
    order: u128,
    left: Box8,
    right: Box8,
    lcen: Box8,
    rcen: Box8,
    lset: u16,
}

/// Builds the subtree of node `node` (already in `out.nodes`, at `depth`, with box `bounds` and
/// centroid bounds `cb`) over `refs` (`2..=SMALL` of them, whose primitive indices go to
/// `out.prim_indices[begin..]`). `all_axes`: sweep all three axes, else the longest centroid axis
/// of each node. The caller guarantees `depth + refs.len() <= p.max_depth`, so no split can break
/// the depth bound (a chain of splits of `n` references is at most `n - 1` deep).
#[allow(clippy::too_many_arguments)]
pub(crate) fn subtree(
    refs: &[PrimRef],
    begin: u32,
    [node, depth]: [u32; 2],
    bounds: Box8,
    cb: CBounds,
    all_axes: bool,
    p: &BuildParams,
    out: &mut Bvh2,
    c: &mut Counters,
) {
    let n = refs.len().min(SMALL);
    debug_assert!((2..=SMALL).contains(&refs.len()));
    debug_assert!(depth + refs.len() as u32 <= p.max_depth);
    let mut l = Local {
        refs: &refs[..n],
        boxes: [Box8::EMPTY; SMALL + 1],
        cens: [Box8::EMPTY; SMALL + 1],
        keys: [[f32::INFINITY; SMALL]; 3],
        less: [[0; SMALL]; 3],
        tied: [[0; SMALL]; 3],
        have: 0,
    };
    for (i, r) in refs[..n].iter().enumerate() {
        l.boxes[i] = r.bounds();
        let c2 = r.c2();
        l.cens[i] = Box8(bytemuck::cast([-c2, c2]));
        let k = c2.to_array();
        l.keys[0][i] = k[0];
        l.keys[1][i] = k[1];
        l.keys[2][i] = k[2];
    }
    // Position k holds local index k.
    let mut perm = u128::from_le_bytes(core::array::from_fn(|i| i as u8));
    let root = Pending {
        node,
        lo: 0,
        hi: n as u8,
        set: ((1u32 << n) - 1) as u16,
        depth,
        bounds,
        cbox: Box8(bytemuck::cast([-cb.lo, cb.hi])),
    };
    // Pending right siblings (at most one per level below the root: < SMALL); the left child is
    // built next without a trip through memory.
    // PERF: through the stack, the just-stored left child was reloaded at once: a failed
    // store-to-load forwarding, the hottest instruction of the build's profile.
    let mut stack = [root; SMALL];
    let mut top = 0usize;
    let mut next = Some(root);
    loop {
        let t = match next.take() {
            Some(t) => t,
            None if top > 0 => {
                top -= 1;
                stack[top & (SMALL - 1)]
            }
            None => break,
        };
        c.max_depth = c.max_depth.max(t.depth);
        let (lo, hi) = (t.lo as usize, t.hi as usize);
        let m = hi - lo;
        if m as u32 <= p.min_leaf_size || m < 2 {
            write_leaf(out, c, &l, begin, t.node, t.bounds, perm, lo, m);
            continue;
        }
        let may_leaf = m as u32 <= p.max_leaf_size;
        let members = perm >> (8 * lo);
        // The cheapest split (`forced`: none pays, and the node may not be a leaf).
        let (best, forced) = if m == 2 {
            // One partition only, in the current order.
            let (i, j) = (members as usize & 15, (members >> 8) as usize & 15);
            let (bi, bj) = (l.boxes[i], l.boxes[j]);
            let b = Best {
                cost: bi.half_area_nonempty() + bj.half_area_nonempty(),
                left_count: 1,
                order: members & 0xffff,
                left: bi,
                right: bj,
                lcen: l.cens[i],
                rcen: l.cens[j],
                lset: 1 << i,
            };
            (b, false)
        } else {
            let (cost, left, order) = if all_axes {
                let mut best = sweep(&mut l, 0, members, m, t.set);
                for axis in 1..3 {
                    let b = sweep(&mut l, axis, members, m, t.set);
                    // Strictly cheaper: the lowest axis wins ties.
                    if b.0 < best.0 {
                        best = b;
                    }
                }
                best
            } else {
                sweep(&mut l, longest_axis(t.cbox), members, m, t.set)
            };
            if cost < f32::INFINITY {
                (sides(&l, cost, left, order, m), false)
            } else if may_leaf {
                // No usable split (every cost overflowed).
                write_leaf(out, c, &l, begin, t.node, t.bounds, perm, lo, m);
                continue;
            } else {
                // Cut in the middle of the current order, as the task loop does.
                c.forced_splits += 1;
                (sides(&l, f32::INFINITY, m / 2, members, m), true)
            }
        };
        if !forced
            && may_leaf
            && p.intersection_cost * m as f32 <= split_cost(p, best.cost, t.bounds.half_area_nonempty(), m as u32)
        {
            write_leaf(out, c, &l, begin, t.node, t.bounds, perm, lo, m);
            continue;
        }
        // The node's positions take the chosen order.
        let span = if m >= 16 { u128::MAX } else { (1u128 << (8 * m)) - 1 } << (8 * lo);
        perm = perm & !span | (best.order << (8 * lo)) & span;
        let mid = lo + best.left_count;
        let left = out.nodes.len() as u32;
        out.nodes[t.node as usize] = t.bounds.to_node(left, 0);
        out.nodes.push(best.left.to_node(0, 0));
        out.nodes.push(best.right.to_node(0, 0));
        let d = t.depth + 1;
        // A child that must be a leaf is written at once: it makes no nodes, so the layout is the
        // task loop's.
        let is_leaf = |k: usize| k as u32 <= p.min_leaf_size || k < 2;
        let (nl, nr) = (best.left_count, hi - mid);
        if is_leaf(nl) || is_leaf(nr) {
            c.max_depth = c.max_depth.max(d);
        }
        if is_leaf(nr) {
            write_leaf(out, c, &l, begin, left + 1, best.right, perm, mid, nr);
        } else {
            stack[top & (SMALL - 1)] = Pending {
                node: left + 1,
                lo: mid as u8,
                hi: t.hi,
                set: t.set & !best.lset,
                depth: d,
                bounds: best.right,
                cbox: best.rcen,
            };
            top += 1;
        }
        if is_leaf(nl) {
            write_leaf(out, c, &l, begin, left, best.left, perm, lo, nl);
        } else {
            // The left child next, the right one later (the task loop's order).
            next = Some(Pending {
                node: left,
                lo: t.lo,
                hi: mid as u8,
                set: best.lset,
                depth: d,
                bounds: best.left,
                cbox: best.lcen,
            });
        }
    }
}

/// The exact sweep of a node of `m` references on `axis`: `members` holds their local indices in
/// its low bytes (the node's positions onward), `set` their bits. Returns the cheapest boundary
/// (its cost and how many references go left; the first cheapest wins, `find_small`'s rule) and
/// the members in centroid order (one byte each, the rest [`NONE`]).
#[inline(always)]
fn sweep(l: &mut Local, axis: usize, members: u128, m: usize, set: u16) -> (f32, usize, u128) {
    if l.have >> axis & 1 == 0 {
        l.have |= 1 << axis;
        order_masks(&l.keys[axis], l.refs.len(), &mut l.less[axis], &mut l.tied[axis]);
    }
    let m = m.min(SMALL);
    // Members in centroid order: the rank of a member is its position. Tied members keep the
    // node's order (`earlier`: the members before this one), as `find_small`'s stable rank does.
    let mut order = [NONE; SMALL];
    let mut earlier = 0u16;
    for k in 0..m {
        let i = (members >> (8 * k)) as usize & 15;
        let rank = ((l.less[axis][i] & set).count_ones() + (l.tied[axis][i] & earlier).count_ones()) as usize;
        order[rank & (SMALL - 1)] = i as u8;
        earlier |= 1 << i;
    }
    // Sweep from the right to get suffix areas.
    let mut right_area = [0.0f32; SMALL];
    let mut acc = Box8::EMPTY;
    for k in (1..m).rev() {
        acc.grow(l.boxes[order[k] as usize]);
        right_area[k] = acc.half_area_nonempty();
    }
    // Sweep from the left; the boundary after position k puts k + 1 references left.
    let mut acc = Box8::EMPTY;
    let (mut best, mut left) = (f32::INFINITY, 0usize);
    for k in 0..m - 1 {
        acc.grow(l.boxes[order[k] as usize]);
        let cost = acc.half_area_nonempty() * (k + 1) as f32 + right_area[k + 1] * (m - k - 1) as f32;
        if cost < best {
            (best, left) = (cost, k + 1);
        }
    }
    (best, left, u128::from_le_bytes(order))
}

/// The split of a node into the first `left` of `order` (local indices, one byte each) and the
/// rest of its `m`: both sides' boxes, centroid boxes and the left set.
#[inline(always)]
fn sides(l: &Local, cost: f32, left: usize, order: u128, m: usize) -> Best {
    let mut b = Best {
        cost,
        left_count: left,
        order,
        left: Box8::EMPTY,
        right: Box8::EMPTY,
        lcen: Box8::EMPTY,
        rcen: Box8::EMPTY,
        lset: 0,
    };
    for k in 0..m.min(SMALL) {
        let i = (order >> (8 * k)) as usize & 15;
        if k < left {
            b.left.grow(l.boxes[i]);
            b.lcen.grow(l.cens[i]);
            b.lset |= 1 << i;
        } else {
            b.right.grow(l.boxes[i]);
            b.rcen.grow(l.cens[i]);
        }
    }
    b
}

/// The longest axis of a centroid box (ties: the lowest), as [`CBounds::longest_axis`].
#[inline(always)]
fn longest_axis(cbox: Box8) -> usize {
    let (nlo, hi) = cbox.halves();
    CBounds { lo: -nlo, hi }.longest_axis().0
}

/// Makes node `node` (box `bounds`) a leaf over the `count` references at positions `pos..` of
/// the permutation (the subtree's range starts at `begin`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn write_leaf(
    out: &mut Bvh2,
    c: &mut Counters,
    l: &Local,
    begin: u32,
    node: u32,
    bounds: Box8,
    perm: u128,
    pos: usize,
    count: usize,
) {
    let first = begin as usize + pos;
    out.nodes[node as usize] = bounds.to_node(first as u32, count as u32);
    let members = perm >> (8 * (pos & 15));
    for (k, s) in out.prim_indices[first..first + count].iter_mut().enumerate() {
        *s = l.refs[(members >> (8 * (k & 15))) as usize & 15].index();
    }
    c.leaves += 1;
}

/// `less[i]`: bit `j` set where key `j` is smaller than key `i`; `tied[i]`: where it is equal (`i`
/// itself included); for the first `n` keys (the others are `+inf` padding and never set).
#[inline]
fn order_masks(keys: &[f32; SMALL], n: usize, less: &mut [u16; SMALL], tied: &mut [u16; SMALL]) {
    let (k0, k1) = (f32x8::load(&keys[..8]), f32x8::load(&keys[8..]));
    let valid = (1u32 << n) - 1;
    for i in 0..n {
        let ki = f32x8::splat(keys[i]);
        less[i] = ((k0.lt(ki).bitmask() | k1.lt(ki).bitmask() << 8) & valid) as u16;
        tied[i] = ((k0.eq(ki).bitmask() | k1.eq(ki).bitmask() << 8) & valid) as u16;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::binned::Bins;
    use crate::build::topdown::{self, Task};
    use crate::build::{BinAxes, Strategy};
    use crate::geometry::Aabb;
    use crate::scene::Rng;
    use alloc::vec::Vec;
    use glam::Vec3;

    /// Random ranges of 2..=SMALL references: boxes on a coarse grid (some tied centroids),
    /// spread, or centred on a grid of 4 values per axis with boxes of different sizes (many tied
    /// centroids of unlike boxes, whose order decides the splits below the root).
    fn ranges(count: usize, seed: u64) -> Vec<Vec<PrimRef>> {
        let mut rng = Rng::new(seed);
        (0..count)
            .map(|r| {
                let n = 2 + (rng.u64() as usize) % (SMALL - 1);
                let kind = r % 3;
                let cells = if kind == 0 { 3.0 } else { 1000.0 };
                (0..n)
                    .map(|i| {
                        let p = Vec3::new(rng.range(0.0, cells), rng.range(0.0, cells), rng.range(0.0, cells)).floor();
                        let e = Vec3::new(rng.range(0.0, 40.0), rng.range(0.0, 2.0), rng.range(0.0, 9.0));
                        let b = if kind == 2 {
                            let c = (p / 250.0).floor();
                            Aabb::new(c - e, c + e)
                        } else {
                            Aabb::new(p, p + e)
                        };
                        PrimRef::new(&b, 1000 + i as u32)
                    })
                    .collect()
            })
            .collect()
    }

    /// Scratch of [`build`].
    #[derive(Default)]
    struct Scratch {
        out: Bvh2,
        a: Vec<PrimRef>,
        b: Vec<PrimRef>,
        stack: Vec<Task>,
        bins: Option<alloc::boxed::Box<Bins>>,
    }

    /// Builds `refs` as one subtree into `s.out`, locally (`LOCAL`) or by the task loop.
    fn build<const LOCAL: bool>(refs: &[PrimRef], p: &BuildParams, s: &mut Scratch) -> Counters {
        let (bx, cb) = topdown::bounds_of(refs);
        let out = &mut s.out;
        out.nodes.clear();
        out.prim_indices.clear();
        out.prim_indices.resize(refs.len(), 0);
        out.nodes.push(bx.to_node(0, 0));
        let mut c = Counters::default();
        s.a.clear();
        s.a.extend_from_slice(refs);
        s.b.clear();
        s.b.extend_from_slice(refs);
        let bins = s.bins.get_or_insert_with(|| alloc::boxed::Box::new(Bins::new()));
        let task = Task::new([0, 0, refs.len() as u32, 1], bx, cb);
        topdown::subtree_with::<LOCAL>(&mut s.a, &mut s.b, p, out, task, bins, &mut s.stack, &mut c, None, 0);
        c
    }

    fn params() -> [BuildParams; 5] {
        let leafy = BuildParams {
            min_leaf_size: 3,
            max_leaf_size: 5,
            ..BuildParams::fast()
        };
        let costly = BuildParams {
            traversal_cost: 0.25,
            intersection_cost: 2.0,
            bin_axes: BinAxes::All,
            ..BuildParams::balanced()
        };
        let no_leaves = BuildParams {
            max_leaf_size: 1,
            ..BuildParams::fast()
        };
        [BuildParams::fast(), BuildParams::balanced(), leafy, costly, no_leaves]
    }

    #[test]
    fn same_tree_as_the_task_loop() {
        let (mut x, mut y) = (Scratch::default(), Scratch::default());
        for (k, p) in params().iter().enumerate() {
            assert_eq!(p.strategy, Strategy::BinnedSah);
            for (r, refs) in ranges(300, 11 + k as u64).iter().enumerate() {
                let ca = build::<true>(refs, p, &mut x);
                let cb = build::<false>(refs, p, &mut y);
                let (a, b) = (&x.out, &y.out);
                assert_eq!(a.nodes.len(), b.nodes.len(), "params {k} range {r}");
                assert_eq!(
                    (ca.leaves, ca.max_depth, ca.forced_splits),
                    (cb.leaves, cb.max_depth, cb.forced_splits)
                );
                for (x, y) in a.nodes.iter().zip(&b.nodes) {
                    assert_eq!(bytemuck::bytes_of(x), bytemuck::bytes_of(y), "params {k} range {r}");
                }
                assert_eq!(a.prim_indices, b.prim_indices, "params {k} range {r}");
            }
        }
    }

    /// `cargo test --release --lib small_speed -- --ignored --nocapture`: the local builder
    /// against the task loop on the same ranges, taking turns, best of 7.
    #[test]
    #[ignore]
    fn small_speed() {
        let sets = ranges(40_000, 3);
        let mut s = Scratch::default();
        for p in [BuildParams::fast(), BuildParams::balanced()] {
            let (mut best_local, mut best_loop) = (f64::INFINITY, f64::INFINITY);
            let mut sink = 0usize;
            for _ in 0..7 {
                let t = std::time::Instant::now();
                for refs in &sets {
                    sink += build::<true>(refs, &p, &mut s).leaves as usize;
                }
                best_local = best_local.min(t.elapsed().as_secs_f64());
                let t = std::time::Instant::now();
                for refs in &sets {
                    sink += build::<false>(refs, &p, &mut s).leaves as usize;
                }
                best_loop = best_loop.min(t.elapsed().as_secs_f64());
            }
            std::println!(
                "{:?}: local {:.2} ms, task loop {:.2} ms ({sink})",
                p.bin_axes,
                best_local * 1e3,
                best_loop * 1e3
            );
        }
    }
}
