//! Linear BVH ([`Strategy::Lbvh`](super::Strategy::Lbvh)): Lauterbach et al., "Fast BVH
//! Construction on GPUs" (2009), with the split rule of Karras, "Maximizing Parallelism in the
//! Construction of BVHs, Octrees, and k-d Trees" (2012).
//!
//! 1. Morton codes of the box centroids ([`geometry::morton`](crate::geometry::morton), 30 or 63
//!    bits, eight at a time), quantised over the centroid bounds.
//! 2. An LSD radix sort of `(code, reference)` pairs ([`radix`](super::radix)).
//! 3. The hierarchy, top-down with an explicit stack: a range of sorted codes is split where its
//!    highest differing bit turns from 0 to 1, found by binary search. Duplicate codes are made
//!    unique by appending each key's position in the sorted order, as Karras does: a range of
//!    equal codes is split at the highest bit in which the positions of its ends differ (a
//!    balanced split). Leaves hold `min_leaf_size` references, or up to `max_leaf_size` whose
//!    codes are all equal.
//! 4. Boxes bottom-up in the same walk: the references are first gathered into Morton order (one
//!    tight pass), so a leaf's box is the union of a contiguous run; an interior node's box is
//!    the union of its children's, computed when a "finish" entry below them on the stack is
//!    popped (post-order, while the children are still in cache).
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
        tmp32,
        items64,
        tmp64,
        ..
    } = b;
    match p.morton_bits {
        MortonBits::Bits30 => {
            let q = MortonQuantizer::new30(&cb);
            codes_of(
                refs,
                items32,
                |p| morton30_scalar(p, &q),
                |x, y, z| morton30_x8(x, y, z, &q).to_array(),
            );
            sort_items(items32, tmp32, 30);
            hierarchy(refs, alt, items32, p, out)
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
