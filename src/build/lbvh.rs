//! Linear BVH ([`Strategy::Lbvh`](super::Strategy::Lbvh)): Lauterbach et al., "Fast BVH
//! Construction on GPUs" (2009), with the split rule of Karras, "Maximizing Parallelism in the
//! Construction of BVHs, Octrees, and k-d Trees" (2012).
//!
//! 1. Morton codes of the box centroids ([`geometry::morton`](crate::geometry::morton), 30 or 63
//!    bits, eight at a time), quantised over the centroid bounds.
//! 2. The references in Morton order. 30-bit codes ([`sort_gather30`]): one stable counting pass
//!    on the top 8 bits moves the references themselves into 256 buckets (sequential reads, one
//!    write stream per bucket), then each bucket, a few thousand references in cache on an even
//!    scene, is sorted by `(code, position)` (two 11-bit LSD passes) and gathered back. 63-bit
//!    codes: an LSD radix sort of `(code, reference)` pairs ([`radix`](super::radix)), then a
//!    gather of the references in sorted order. Both orders are that of a stable sort by code.
//! 3. The hierarchy, top-down with an explicit stack: a range of sorted codes is split where its
//!    highest differing bit turns from 0 to 1, found by binary search. Duplicate codes are made
//!    unique by appending each key's position in the sorted order, as Karras does: a range of
//!    equal codes is split at the highest bit in which the positions of its ends differ (a
//!    balanced split). Leaves hold `min_leaf_size` references, or up to `max_leaf_size` whose
//!    codes are all equal.
//! 4. Boxes bottom-up in the same walk: with the references in Morton order, a leaf's box is the
//!    union of a contiguous run; an interior node's box is the union of its children's, computed
//!    when a "finish" entry below them on the stack is popped (post-order, while the children are
//!    still in cache).
//!
//! PERF (1M thin soup, one core, `BuildParams::fastest()`): the gather of step 2, 32-byte reads
//! at random over 32 MB, took as long as the radix sort before it (TLB and latency bound); the
//! bucketed sort and gather of 30-bit codes replaces both and halved that part; whole LBVH builds
//! ran 1.1 to 1.6 times faster (median 1.2) in alternating runs (see the
//! [module docs](super#measured)). Tried and dropped, no gain measured: a second,
//! cache-sized array of every 32nd (or 8th) code to narrow the split search (the search is about
//! a third of the walk's samples, but simulated cache misses did not change); `sort_unstable`
//! within the buckets (slower than the two counting passes).
//!
//! The depth bound of [`BuildParams::max_depth`] holds as in the top-down builders: a split that
//! would break it is replaced by the middle of the range.

use super::builder::{Builder, Counters};
use super::prims::{Box8, PrepInfo, PrimRef, depth_ok};
use super::radix::{Item, sort_items};
use super::{BuildParams, Bvh2, MortonBits, Node};
use crate::geometry::morton::{MortonQuantizer, morton30_scalar, morton30_x8, morton63_scalar, morton63_x8};
use crate::math::f32x8;
use alloc::vec::Vec;
use glam::Vec3;

/// A sort key: 30-bit codes in `u32`, 63-bit codes in `u64`.
pub(crate) trait Code: super::radix::RadixKey {
    /// The highest bit in which `a` and `b` differ, if any.
    fn high_bit_of_xor(a: Self, b: Self) -> Option<u32>;
    fn bit_set(self, bit: u32) -> bool;
}

impl Code for u32 {
    #[inline]
    fn high_bit_of_xor(a: Self, b: Self) -> Option<u32> {
        let x = a ^ b;
        (x != 0).then(|| 31 - x.leading_zeros())
    }
    #[inline]
    fn bit_set(self, bit: u32) -> bool {
        self >> bit & 1 != 0
    }
}

impl Code for u64 {
    #[inline]
    fn high_bit_of_xor(a: Self, b: Self) -> Option<u32> {
        let x = a ^ b;
        (x != 0).then(|| 63 - x.leading_zeros())
    }
    #[inline]
    fn bit_set(self, bit: u32) -> bool {
        self >> bit & 1 != 0
    }
}

/// Builds an LBVH.
pub(crate) fn build(b: &mut Builder, info: &PrepInfo, p: &BuildParams, out: &mut Bvh2) -> Counters {
    // NOTE: the codes quantise doubled centroids `min + max` over their bounds: the same cells as
    // centroids over centroid bounds, one multiply fewer.
    let cb = info.cbounds.to_aabb();
    let Builder {
        refs,
        alt,
        items32,
        items64,
        tmp64,
        packed,
        packed_tmp,
        ..
    } = b;
    match p.morton_bits {
        MortonBits::Bits30 => {
            let q = MortonQuantizer::new30(&cb);
            sort_gather30(refs, alt, items32, packed, packed_tmp, &q, out);
            walk_sorted(refs, items32, p, out)
        }
        MortonBits::Bits63 => {
            let q = MortonQuantizer::new63(&cb);
            codes_of(
                refs,
                items64,
                |p| morton63_scalar(p, &q),
                |x, y, z| morton63_x8(x, y, z, &q),
            );
            sort_items(items64, tmp64, 63);
            hierarchy(refs, alt, items64, p, out)
        }
    }
}

/// The code of every reference's doubled centroid, with the reference's position, into `codes`;
/// eight at a time.
pub(crate) fn codes_of<K: Copy>(
    refs: &[PrimRef],
    codes: &mut Vec<Item<K>>,
    one: impl Fn(Vec3) -> K,
    eight: impl Fn(f32x8, f32x8, f32x8) -> [K; 8],
) {
    codes.clear();
    codes.reserve(refs.len());
    let mut chunks = refs.chunks_exact(8);
    for (k, c) in (&mut chunks).enumerate() {
        let mut xyz = [[0.0f32; 8]; 3];
        for (i, r) in c.iter().enumerate() {
            let v = r.c2().to_array();
            xyz[0][i] = v[0];
            xyz[1][i] = v[1];
            xyz[2][i] = v[2];
        }
        let keys = eight(f32x8::new(xyz[0]), f32x8::new(xyz[1]), f32x8::new(xyz[2]));
        let base = 8 * k as u32;
        codes.extend((0..8).map(|i| Item {
            key: keys[i],
            val: base + i as u32,
        }));
    }
    let base = codes.len() as u32;
    for (i, r) in chunks.remainder().iter().enumerate() {
        let v = r.c2().to_array();
        codes.push(Item {
            key: one(Vec3::new(v[0], v[1], v[2])),
            val: base + i as u32,
        });
    }
}

/// A step of the hierarchy walk.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Step {
    /// Split (or make a leaf of) sorted range `begin..end` into node `node`.
    Visit {
        node: u32,
        begin: u32,
        end: u32,
        depth: u32,
    },
    /// Both children of `node` (over `begin..end`) are done: its box is their union.
    Finish { node: u32, begin: u32, end: u32 },
}

/// The hierarchy walk's stacks, and whether it makes SAH leaves.
#[derive(Clone, Debug, Default)]
pub(crate) struct WalkStack {
    steps: Vec<Step>,
    /// SAH costs and heights of finished subtrees (with `sah_leaves`), post-order.
    costs: Vec<(f32, u32)>,
    /// Collapse a finished subtree of at most `max_leaf_size` primitives into one leaf where
    /// the leaf is cheaper by the SAH (its nodes are the last ones in the array, so this is a
    /// truncation). Off for [`Strategy::Lbvh`](super::Strategy::Lbvh).
    pub sah_leaves: bool,
}

/// Builds the tree over the sorted `codes` (each with the position of its reference).
fn hierarchy<K: Code>(
    refs: &[PrimRef],
    sorted: &mut Vec<PrimRef>,
    codes: &[Item<K>],
    p: &BuildParams,
    out: &mut Bvh2,
) -> Counters {
    let n = refs.len();
    gather(refs, sorted, codes, out);
    let mut c = Counters::default();
    out.nodes.reserve((2 * n).saturating_sub(1));
    out.nodes.push(<Node as bytemuck::Zeroable>::zeroed());
    // Left children are visited first; the stack holds a right sibling and a finish per level.
    let mut stack = WalkStack::default();
    stack.steps.reserve(2 * p.max_depth as usize + 2);
    walk(
        &mut out.nodes,
        sorted,
        codes,
        p,
        [0, 0, n as u32, 1],
        &mut stack,
        &mut c,
    );
    c
}

/// Bits of the top digit that [`sort_gather30`] buckets by (256 buckets).
const TOP_BITS: u32 = 8;

/// Sorts `refs` by the 30-bit Morton codes of their doubled centroids (quantised by `q`) without
/// random reads over all of `refs`:
///
/// 1. One pass computes the codes (eight at a time) into `items` and counts the top
///    [`TOP_BITS`] bits.
/// 2. One stable counting pass on the top digit moves the references into `alt` (sequential
///    reads, one write stream per bucket); each one's code travels along in its lane 7
///    ([`PrimRef::with_tag`]).
/// 3. Each bucket (a few thousand references on an even scene, in cache) is sorted by
///    `(code, position)` and gathered back into `refs`, lane 7 cleared.
///
/// The order is that of a stable sort by code. On return `items` holds the sorted codes (values:
/// their positions), `refs` the references in that order and `out.prim_indices` their primitive
/// indices; `alt` and `packed` hold garbage.
// PERF: measured on the 1M soup against codes, a full LSD radix sort of (code, position) and a
// gather of the references in sorted order (random 32-byte reads, TLB and latency bound): about
// half the time (phase timings under load: 80 to 40 ms; see the module docs).
pub(crate) fn sort_gather30(
    refs: &mut [PrimRef],
    alt: &mut Vec<PrimRef>,
    items: &mut Vec<Item<u32>>,
    packed: &mut Vec<u64>,
    packed_tmp: &mut Vec<u64>,
    q: &MortonQuantizer,
    out: &mut Bvh2,
) {
    const BUCKETS: usize = 1 << TOP_BITS;
    const SHIFT: u32 = 30 - TOP_BITS;
    let n = refs.len();
    let digit = |code: u32| (code >> SHIFT) as usize & (BUCKETS - 1);
    // Codes (into `items`, in input order), and the histogram of the top digit.
    let mut start = [0u32; BUCKETS + 1];
    items.resize(n, Item::default());
    let mut chunks = refs.chunks_exact(8);
    let mut out_chunks = items.chunks_exact_mut(8);
    for (c, o) in (&mut chunks).zip(&mut out_chunks) {
        let mut xyz = [[0.0f32; 8]; 3];
        for (i, r) in c.iter().enumerate() {
            let v = r.c2().to_array();
            xyz[0][i] = v[0];
            xyz[1][i] = v[1];
            xyz[2][i] = v[2];
        }
        let codes = morton30_x8(f32x8::new(xyz[0]), f32x8::new(xyz[1]), f32x8::new(xyz[2]), q).to_array();
        for (it, &code) in o.iter_mut().zip(&codes) {
            it.key = code;
            start[digit(code)] += 1;
        }
    }
    for (r, it) in chunks.remainder().iter().zip(out_chunks.into_remainder()) {
        let v = r.c2().to_array();
        let code = morton30_scalar(Vec3::new(v[0], v[1], v[2]), q);
        it.key = code;
        start[digit(code)] += 1;
    }
    // Exclusive prefix sums: the first slot of each bucket.
    let mut sum = 0u32;
    for c in start.iter_mut() {
        let v = *c;
        *c = sum;
        sum += v;
    }
    // NOTE: resized only when the length changes; every slot is written before it is read.
    if alt.len() != n {
        alt.resize(n, PrimRef(Default::default()));
    }
    out.prim_indices.resize(n, 0);
    // Stable scatter by the top digit; the code travels in lane 7 of the reference (one write
    // stream per bucket, not two).
    let mut cursor = start;
    for (r, it) in refs.iter().zip(items.iter()) {
        let slot = &mut cursor[digit(it.key)];
        // `*slot < n`: the prefix sums of a histogram of n keys.
        if let Some(d) = alt.get_mut(*slot as usize) {
            *d = r.with_tag(it.key);
        }
        *slot += 1;
    }
    // Sort each bucket by (code, position in the bucket) and gather it back.
    for w in start.windows(2) {
        let (a, b) = (w[0] as usize, (w[1] as usize).min(n));
        if a >= b {
            continue;
        }
        packed.clear();
        packed.extend(
            alt[a..b]
                .iter()
                .enumerate()
                .map(|(j, r)| (r.tag() as u64) << 32 | j as u64),
        );
        sort_bucket(packed, packed_tmp);
        let src = &alt[a..b];
        let dst = refs[a..b]
            .iter_mut()
            .zip(&mut items[a..b])
            .zip(&mut out.prim_indices[a..b]);
        for (((d, it), pi), (j, &k)) in dst.zip(packed.iter().enumerate()) {
            // `k as u32` is a position in the bucket: in range.
            let r = src.get(k as u32 as usize).map_or(*d, |r| r.with_tag(0));
            *d = r;
            *it = Item {
                key: (k >> 32) as u32,
                val: (a + j) as u32,
            };
            *pi = r.index();
        }
    }
}

/// Sorts one bucket of [`sort_gather30`]: `(code << 32) | position` keys whose codes share their
/// top [`TOP_BITS`] bits. Positions are in increasing order on entry, so a stable sort by the
/// low `30 - TOP_BITS` code bits is a sort by value: two LSD counting passes of 11 bits (one read
/// for both histograms), or `sort_unstable` for short buckets. `tmp` is scratch.
// PERF: measured on the 1M soup (buckets of about 4,000, under load): the bucket phase of
// `sort_gather30` took 25 ms with `sort_unstable` on every bucket, 18 ms with these two passes.
fn sort_bucket(keys: &mut Vec<u64>, tmp: &mut Vec<u64>) {
    const W: u32 = 11;
    const B: usize = 1 << W;
    const _: () = assert!(2 * W >= 30 - TOP_BITS);
    let m = keys.len();
    if m <= 256 {
        keys.sort_unstable();
        return;
    }
    let mut hist = [[0u32; B]; 2];
    let digit = |k: u64, pass: u32| (k >> (32 + pass * W)) as usize & (B - 1);
    for &k in keys.iter() {
        hist[0][digit(k, 0)] += 1;
        hist[1][digit(k, 1)] += 1;
    }
    tmp.resize(m, 0);
    for (pass, h) in hist.iter_mut().enumerate() {
        // Exclusive prefix sums: the first output slot of each digit.
        let mut sum = 0u32;
        for c in h.iter_mut() {
            let v = *c;
            *c = sum;
            sum += v;
        }
        for &k in keys.iter() {
            let slot = &mut h[digit(k, pass as u32)];
            // `*slot < m`: the prefix sums of a histogram of m keys.
            if let Some(d) = tmp.get_mut(*slot as usize) {
                *d = k;
            }
            *slot += 1;
        }
        core::mem::swap(keys, tmp);
    }
}

/// The LBVH over `sorted` references whose codes are `codes` (as [`hierarchy`] after its
/// gather; `out.prim_indices` already holds the primitive indices).
fn walk_sorted<K: Code>(sorted: &[PrimRef], codes: &[Item<K>], p: &BuildParams, out: &mut Bvh2) -> Counters {
    let n = sorted.len();
    let mut c = Counters::default();
    out.nodes.reserve((2 * n).saturating_sub(1));
    out.nodes.push(<Node as bytemuck::Zeroable>::zeroed());
    let mut stack = WalkStack::default();
    stack.steps.reserve(2 * p.max_depth as usize + 2);
    walk(
        &mut out.nodes,
        sorted,
        codes,
        p,
        [0, 0, n as u32, 1],
        &mut stack,
        &mut c,
    );
    c
}

/// Gathers the references into Morton order (one tight pass of random reads, after which every
/// leaf reads a contiguous run) and writes the primitive indices in that order.
pub(crate) fn gather<K>(refs: &[PrimRef], sorted: &mut Vec<PrimRef>, codes: &[Item<K>], out: &mut Bvh2) {
    sorted.clear();
    sorted.extend(codes.iter().map(|it| refs[it.val as usize]));
    out.prim_indices.extend(sorted.iter().map(PrimRef::index));
}

/// Where the LBVH splits sorted range `b..e` (`e - b >= 2`): the first code with the highest
/// differing bit of the range set, or, where all codes are equal, at the highest bit in which
/// the ends' positions differ. Always strictly inside the range for sorted codes.
#[inline]
pub(crate) fn split_point<K: Code>(codes: &[Item<K>], b: u32, e: u32) -> u32 {
    let (first, last) = (codes[b as usize].key, codes[e as usize - 1].key);
    match K::high_bit_of_xor(first, last) {
        // The first code in the range with that bit set (the range shares every higher bit).
        Some(bit) => b + codes[b as usize..e as usize].partition_point(|c| !c.key.bit_set(bit)) as u32,
        // All codes equal: split the appended positions at their highest differing bit.
        None => {
            let bit = 31 - (b ^ (e - 1)).leading_zeros();
            (e - 1) >> bit << bit
        }
    }
}

/// The hierarchy over sorted range `begin..end` into the existing node `root` at `depth`
/// (`task = [root, begin, end, depth]`), appending nodes; `sorted` holds the gathered references.
/// `stack` is scratch (left empty).
pub(crate) fn walk<K: Code>(
    nodes: &mut Vec<Node>,
    sorted: &[PrimRef],
    codes: &[Item<K>],
    p: &BuildParams,
    task: [u32; 4],
    ws: &mut WalkStack,
    c: &mut Counters,
) {
    let blank = <Node as bytemuck::Zeroable>::zeroed();
    let [node, begin, end, depth] = task;
    let WalkStack {
        steps: stack,
        costs,
        sah_leaves,
    } = ws;
    let sah = *sah_leaves;
    stack.clear();
    costs.clear();
    stack.push(Step::Visit {
        node,
        begin,
        end,
        depth,
    });
    while let Some(step) = stack.pop() {
        let (node, b, e, depth) = match step {
            Step::Finish { node, begin, end } => {
                let l = nodes[node as usize].left() as usize;
                let bx = Box8::from_node(&nodes[l]).union(Box8::from_node(&nodes[l + 1]));
                nodes[node as usize] = bx.to_node(l as u32, 0);
                if sah {
                    // Post-order: the children's costs are the top two.
                    let ((cr, hr), (cl, hl)) = (costs.pop().unwrap_or_default(), costs.pop().unwrap_or_default());
                    let area = bx.half_area_nonempty();
                    let count = end - begin;
                    let split = p.traversal_cost * area + cl + cr;
                    let leaf = p.intersection_cost * count as f32 * area;
                    if count <= p.max_leaf_size && leaf <= split {
                        // The subtree's nodes are the last ones: drop them, keep the leaf.
                        c.leaves -= leaves_below(count, &nodes[l..]);
                        c.leaves += 1;
                        nodes.truncate(l);
                        nodes[node as usize] = bx.to_node(begin, count);
                        costs.push((leaf, 1));
                    } else {
                        costs.push((split, hl.max(hr) + 1));
                    }
                }
                continue;
            }
            Step::Visit {
                node,
                begin,
                end,
                depth,
            } => (node, begin, end, depth),
        };
        if !sah {
            c.max_depth = c.max_depth.max(depth);
        }
        let count = e - b;
        let (first, last) = (codes[b as usize].key, codes[e as usize - 1].key);
        if count <= p.min_leaf_size || (count <= p.max_leaf_size && first == last) {
            let bx = sorted[b as usize..e as usize]
                .iter()
                .fold(Box8::EMPTY, |acc, r| acc.union(r.bounds()));
            nodes[node as usize] = bx.to_node(b, count);
            c.leaves += 1;
            if sah {
                costs.push((p.intersection_cost * count as f32 * bx.half_area_nonempty(), 1));
            }
            continue;
        }
        let mut mid = split_point(codes, b, e);
        debug_assert!(b < mid && mid < e);
        if !(b < mid && mid < e && depth_ok(depth, mid - b, e - mid, p.max_depth)) {
            c.forced_splits += 1;
            mid = b + count / 2;
        }
        let left = nodes.len() as u32;
        nodes[node as usize].index = left;
        nodes.push(blank);
        nodes.push(blank);
        stack.push(Step::Finish { node, begin: b, end: e });
        stack.push(Step::Visit {
            node: left + 1,
            begin: mid,
            end: e,
            depth: depth + 1,
        });
        stack.push(Step::Visit {
            node: left,
            begin: b,
            end: mid,
            depth: depth + 1,
        });
    }
    if let Some(&(_, h)) = costs.last() {
        c.max_depth = c.max_depth.max(depth + h - 1);
    }
}

/// Leaves among `nodes` (a collapsed subtree's nodes, at most `2 count - 2` of them).
#[inline]
fn leaves_below(count: u32, nodes: &[Node]) -> u32 {
    debug_assert!(nodes.len() <= 2 * count as usize);
    nodes.iter().filter(|n| n.is_leaf()).count() as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::prims::prepare;
    use crate::geometry::Aabb;
    use crate::scene::Rng;

    /// `sort_gather30` against the plain pipeline: codes, a stable radix sort, a gather.
    fn check(boxes: &[Aabb]) {
        let mut refs = Vec::new();
        let info = prepare(boxes, &mut refs).unwrap();
        let q = MortonQuantizer::new30(&info.cbounds.to_aabb());
        let mut want_items = Vec::new();
        codes_of(
            &refs,
            &mut want_items,
            |p| morton30_scalar(p, &q),
            |x, y, z| morton30_x8(x, y, z, &q).to_array(),
        );
        sort_items(&mut want_items, &mut Vec::new(), 30);
        let (mut want_sorted, mut want_out) = (Vec::new(), Bvh2::default());
        gather(&refs, &mut want_sorted, &want_items, &mut want_out);

        let (mut alt, mut items, mut packed, mut tmp, mut out) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Bvh2::default());
        sort_gather30(&mut refs, &mut alt, &mut items, &mut packed, &mut tmp, &q, &mut out);
        let keys = |v: &[Item<u32>]| v.iter().map(|it| it.key).collect::<Vec<_>>();
        assert_eq!(keys(&items), keys(&want_items));
        assert!(items.iter().enumerate().all(|(i, it)| it.val == i as u32));
        assert_eq!(out.prim_indices, want_out.prim_indices);
        let bits = |v: &[PrimRef]| v.iter().map(|r| bytemuck::cast::<_, [u32; 8]>(r.0)).collect::<Vec<_>>();
        assert_eq!(bits(&refs), bits(&want_sorted), "lane 7 must be cleared");
    }

    #[test]
    fn sort_gather30_matches_sort_and_gather() {
        let mut r = Rng::new(9);
        let mut b = |lo: f32, hi: f32| {
            let p = Vec3::new(r.range(lo, hi), r.range(lo, hi), r.range(lo, hi));
            Aabb::new(p, p + Vec3::splat(0.01))
        };
        for n in [0, 1, 2, 7, 8, 9, 300, 5000] {
            // Spread out (small buckets, `sort_unstable`), and on a coarse grid (many equal codes,
            // big buckets: the radix path).
            let spread: Vec<Aabb> = (0..n).map(|_| b(-1.0, 1.0)).collect();
            check(&spread);
            let grid: Vec<Aabb> = spread
                .iter()
                .map(|a| {
                    let p = (a.min * 2.0).round();
                    Aabb::new(p, p + Vec3::ONE)
                })
                .collect();
            check(&grid);
            // One cluster and one far box: nearly everything in one bucket.
            let mut cluster: Vec<Aabb> = (0..n).map(|_| b(0.0, 0.001)).collect();
            cluster.push(Aabb::new(Vec3::splat(100.0), Vec3::splat(101.0)));
            // Invalid boxes are left out by `prepare`: positions and indices differ.
            cluster.push(Aabb::new(Vec3::splat(f32::NAN), Vec3::ONE));
            check(&cluster);
        }
    }
}
