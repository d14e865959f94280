//! Full-sweep SAH builder ([`Strategy::SweepSah`](super::Strategy::SweepSah)): every boundary
//! between consecutive primitives in centroid order, on all three axes, with prefix areas from a
//! left-to-right sweep and suffix areas from a right-to-left one (MacDonald and Booth 1990).
//!
//! **Sorted once, not per node.** The references are sorted by centroid once per axis (three
//! stable LSD radix sorts of the `f32` keys, [`radix`](super::radix)), into three arrays. A node is
//! the same range `begin..end` of all three; once the best split is known, the chosen axis's range
//! is already partitioned (left = a prefix) and the other two are partitioned *stably* by a
//! left/right flag per primitive, so they stay sorted. Each level of the tree thus costs O(n) and
//! the build O(n log n), against O(n log^2 n) for a sort per node; the price is memory: three
//! copies of the 32-byte references, a flag per primitive and a scratch array.

use super::builder::{Builder, Counters};
use super::prims::{Box8, PrepInfo, PrimRef, depth_ok};
use super::radix::{Item, f32_key, sort_items};
use super::topdown::split_cost;
use super::{BuildParams, Bvh2, Node};
use alloc::vec::Vec;

struct Task {
    node: u32,
    begin: u32,
    end: u32,
    depth: u32,
    bounds: Box8,
}

/// Builds with the full-sweep SAH.
pub(crate) fn build(bld: &mut Builder, info: &PrepInfo, p: &BuildParams, out: &mut Bvh2) -> Counters {
    let Builder {
        refs,
        alt,
        sorted: [sy, sz],
        items32,
        tmp32,
        suffix,
        flags,
        ..
    } = bld;
    let n = refs.len();
    // Sort the references by centroid on each axis (stable; ties keep input order).
    for (a, dst) in [&mut *alt, &mut *sy, &mut *sz].into_iter().enumerate() {
        items32.clear();
        items32.extend(refs.iter().enumerate().map(|(i, r)| Item {
            key: f32_key(r.c2_axis(a)),
            val: i as u32,
        }));
        sort_items(items32, tmp32, 32);
        dst.clear();
        dst.extend(items32.iter().map(|it| refs[it.val as usize]));
    }
    let sx = alt;
    // Scratch: suffix areas, one side flag per primitive index, and (the unsorted references are
    // no longer needed) `refs` as the buffer of stable partitions.
    if suffix.len() != n {
        suffix.resize(n, 0.0);
    }
    flags.clear();
    flags.resize(info.total, false);
    let scratch = refs;
    let left_flag = flags;
    let mut c = Counters::default();

    out.nodes.reserve((2 * n).saturating_sub(1));
    out.nodes.push(Node::leaf(&info.bounds.to_aabb(), 0, 0));
    let mut stack: Vec<Task> = Vec::with_capacity(p.max_depth as usize + 1);
    stack.push(Task {
        node: 0,
        begin: 0,
        end: n as u32,
        depth: 1,
        bounds: info.bounds,
    });
    while let Some(t) = stack.pop() {
        c.max_depth = c.max_depth.max(t.depth);
        let count = t.end - t.begin;
        let (b, e) = (t.begin as usize, t.end as usize);
        let leaf = |out: &mut Bvh2, c: &mut Counters| {
            out.nodes[t.node as usize] = Node::leaf(&t.bounds.to_aabb(), t.begin, count);
            c.leaves += 1;
        };
        if count <= p.min_leaf_size {
            leaf(out, &mut c);
            continue;
        }
        // Sweep every axis: (axis, left count, N_l A_l + N_r A_r).
        let mut best: Option<(usize, usize, f32)> = None;
        for (a, s) in [&*sx, &*sy, &*sz].into_iter().enumerate() {
            let s = &s[b..e];
            let suf = &mut suffix[b..e];
            // Sweep from the right to get suffix areas: suf[i] = area of s[i..].
            let mut acc = Box8::EMPTY;
            for i in (1..s.len()).rev() {
                acc.grow(s[i].bounds());
                suf[i] = acc.half_area_nonempty();
            }
            // Sweep from the left; the plane after s[i] puts i + 1 refs on the left.
            let mut acc = Box8::EMPTY;
            for i in 0..s.len() - 1 {
                acc.grow(s[i].bounds());
                let nl = (i + 1) as f32;
                let cost = acc.half_area_nonempty() * nl + suf[i + 1] * (s.len() - i - 1) as f32;
                if cost < best.map_or(f32::INFINITY, |b| b.2) {
                    best = Some((a, i + 1, cost));
                }
            }
        }
        let area = t.bounds.half_area_nonempty();
        let may_leaf = count <= p.max_leaf_size;
        let leaf_cost = p.intersection_cost * count as f32;
        let (mut axis, mut mid) = match best {
            Some((a, m, sum)) => {
                if may_leaf && leaf_cost <= split_cost(p, sum, area, count) {
                    leaf(out, &mut c);
                    continue;
                }
                (a, m)
            }
            None => {
                // Only when every area overflows: no cost is finite.
                if may_leaf {
                    leaf(out, &mut c);
                    continue;
                }
                c.forced_splits += 1;
                (0, count as usize / 2)
            }
        };
        if !depth_ok(t.depth, mid as u32, count - mid as u32, p.max_depth) {
            // Balanced split on the axis of largest centroid extent (read off the sorted ends).
            c.forced_splits += 1;
            let ext = |s: &[PrimRef], a: usize| s[e - 1].c2_axis(a) - s[b].c2_axis(a);
            let ex = [ext(sx, 0), ext(sy, 1), ext(sz, 2)];
            axis = if ex[1] > ex[0] && ex[1] >= ex[2] {
                1
            } else if ex[2] > ex[0] && ex[2] > ex[1] {
                2
            } else {
                0
            };
            mid = count as usize / 2;
        }
        // Mark the sides by primitive index, from the chosen axis's order.
        let chosen = [&*sx, &*sy, &*sz][axis];
        let (mut lbox, mut rbox) = (Box8::EMPTY, Box8::EMPTY);
        for (i, r) in chosen[b..e].iter().enumerate() {
            let is_left = i < mid;
            if let Some(f) = left_flag.get_mut(r.index() as usize) {
                *f = is_left;
            }
            if is_left {
                lbox.grow(r.bounds());
            } else {
                rbox.grow(r.bounds());
            }
        }
        // Partition the other two lists stably, so they stay sorted.
        for (a, s) in [&mut *sx, &mut *sy, &mut *sz].into_iter().enumerate() {
            if a != axis {
                stable_partition(&mut s[b..e], left_flag, scratch);
            }
        }
        let left = out.nodes.len() as u32;
        out.nodes[t.node as usize] = Node::interior(&t.bounds.to_aabb(), left);
        out.nodes.push(Node::leaf(&lbox.to_aabb(), 0, 0));
        out.nodes.push(Node::leaf(&rbox.to_aabb(), 0, 0));
        let m = t.begin + mid as u32;
        stack.push(Task {
            node: left + 1,
            begin: m,
            end: t.end,
            depth: t.depth + 1,
            bounds: rbox,
        });
        stack.push(Task {
            node: left,
            begin: t.begin,
            end: m,
            depth: t.depth + 1,
            bounds: lbox,
        });
    }
    out.prim_indices.extend(sx.iter().map(PrimRef::index));
    c
}

/// Moves the refs flagged left to the front of `s`, keeping the order within each side.
fn stable_partition(s: &mut [PrimRef], left_flag: &[bool], scratch: &mut Vec<PrimRef>) {
    scratch.clear();
    let mut w = 0;
    for i in 0..s.len() {
        let r = s[i];
        if left_flag.get(r.index() as usize).copied().unwrap_or(false) {
            s[w] = r;
            w += 1;
        } else {
            scratch.push(r);
        }
    }
    s[w..].copy_from_slice(scratch);
}
