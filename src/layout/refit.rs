//! [`BvhWide::refit`]: new boxes and packs for moved triangles, the same wide tree.

use super::{BvhWide, EMPTY_CHILD, LEAF_BIT, MAX_WIDE_DEPTH, WideNode, leaf_packs};
use crate::build::usable_box;
use crate::geometry::{INVALID, Triangle, Triangles, is_degenerate};
use crate::intersect::TriangleLanes;
use crate::math::Lane;
#[cfg(feature = "std")]
use alloc::vec::Vec;
use glam::Vec3;

/// Most lanes of any [`Lane`] type (`f32x16`).
const MAX_LANES: usize = 16;

impl<L: Lane, const N: usize> BvhWide<L, N> {
    /// Refits the tree to the current positions of its triangles (animated geometry whose
    /// connectivity does not change): every pack is filled again from `tris` (the same
    /// primitive in the same lane) and every child box recomputed from the packs and nodes below
    /// it, the values [`from_bvh2`](Self::from_bvh2) computes (a box edge at zero may come out as
    /// `-0.0` where the collapse had `+0.0` or back; they compare equal): one pass over the packs, one
    /// over the nodes (with a stack on the call stack; one allocation, a box per pack). The
    /// tree's shape, slot order and node numbering stay as they were, so its quality (SAH cost)
    /// may degrade as triangles move far; rebuild then.
    ///
    /// A triangle of the tree that the builders would now leave out (see
    /// [`Primitives`](crate::build::Primitives): a vertex that is not finite, or a coordinate so
    /// large, beyond about `±1.7e38`, that its box's extent or `min + max` overflows), or that
    /// `tris` no longer has (an index past its end, or an indexed mesh whose vertex index is out
    /// of range), is **left out**: its lane is never hit and counts in no box; it comes back with
    /// a later refit where it is valid again. Returns how many references were left out: the
    /// number of such triangles, except on trees with spatial splits
    /// ([`Bvh2::build_spatial`](crate::build::Bvh2::build_spatial)), where a triangle counts once
    /// for every leaf that holds a part of it. The rule is
    /// [`Bvh2::refit`](crate::build::Bvh2::refit)'s and the builders'. A degenerate (zero-area)
    /// but finite triangle counts in its leaf's box and is never hit, as after `from_bvh2`.
    /// Triangles that were invalid when the tree was built are not in it: rebuild to add them.
    ///
    /// Traversal after a refit gives exactly the closest hits of brute force over the tree's
    /// triangles in their new places (`tests/refit.rs`). A [`Tlas`](crate::layout::Tlas) that
    /// instances this tree keeps its old box until [`Tlas::refit`](crate::layout::Tlas::refit)
    /// is called.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, scene, traverse::Watertight};
    /// let mut tris = scene::icosphere(2).to_soup();
    /// let (bvh2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let mut bvh8 = Bvh8::from_bvh2(&bvh2, &tris[..]).unwrap();
    /// // The sphere moves 10 units along x.
    /// for t in &mut tris {
    ///     for v in t.iter_mut() {
    ///         *v += Vec3::new(10.0, 0.0, 0.0);
    ///     }
    /// }
    /// assert_eq!(bvh8.refit(&tris[..]), 0);
    /// let ray = Ray::new(Vec3::new(10.0, 0.0, -5.0), Vec3::Z);
    /// let hit = bvh8.intersect::<Watertight>(&ray).unwrap();
    /// assert!((hit.t - 4.0).abs() < 1e-2);
    /// assert!(!bvh8.occluded::<Watertight>(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z)));
    /// ```
    pub fn refit<P: Triangles + ?Sized>(&mut self, tris: &P) -> usize {
        let mut boxes = alloc::vec![(Vec3::ZERO, Vec3::ZERO); self.packs.len()];
        let left_out = refill_all(&mut self.packs, &mut boxes, tris);
        refit_nodes(&mut self.nodes, &boxes);
        left_out
    }

    /// [`refit`](Self::refit) on up to `threads` threads (`std`; at least 1): the packs are
    /// filled again in `threads` runs side by side, then the nodes' boxes computed from them on
    /// the calling thread. The same tree, bit for bit, as `refit`, and the same count of
    /// triangles left out.
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, scene};
    /// let mut tris = scene::thin_soup(20_000, 1);
    /// let (bvh2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let mut one = Bvh8::from_bvh2(&bvh2, &tris[..]).unwrap();
    /// let mut two = one.clone();
    /// tris[7][1] = Vec3::splat(f32::NAN);
    /// assert_eq!(one.refit(&tris[..]), 1);
    /// assert_eq!(two.refit_par(&tris[..], 2), 1);
    /// assert_eq!(one.nodes()[0].bounds.min[0].to_array(), two.nodes()[0].bounds.min[0].to_array());
    /// ```
    #[cfg(feature = "std")]
    pub fn refit_par<P: Triangles + Sync + ?Sized>(&mut self, tris: &P, threads: usize) -> usize
    where
        L: Send,
    {
        use core::sync::atomic::{AtomicUsize, Ordering};
        let threads = threads.clamp(1, crate::build::MAX_THREADS);
        // Below this many packs per thread, the threads' start costs more than they save.
        const GRAIN: usize = 1024;
        let runs = threads.min(self.packs.len() / GRAIN).max(1);
        if runs == 1 {
            return self.refit(tris);
        }
        let mut boxes = alloc::vec![(Vec3::ZERO, Vec3::ZERO); self.packs.len()];
        let per = self.packs.len().div_ceil(runs);
        let left_out = AtomicUsize::new(0);
        let parts: Vec<_> = self.packs.chunks_mut(per).zip(boxes.chunks_mut(per)).collect();
        crate::par::each_job(parts, runs, |(packs, boxes)| {
            left_out.fetch_add(refill_all(packs, boxes, tris), Ordering::Relaxed);
        });
        refit_nodes(&mut self.nodes, &boxes);
        left_out.into_inner()
    }
}

/// Fills every pack of `packs` again ([`refill`]), its box into `boxes`; returns how many
/// triangles were left out.
// PERF: one pass over the packs in memory order, then the nodes from the kept boxes: the 1M
// sphereflake's BVH8 refit 34.4 -> 30.8 ms (best of 20, by hand) against filling each leaf's
// packs as the node walk meets them (in the same order, but behind the walk's own work); the
// same time on a 116k-triangle one. The price: a box per pack (24 bytes) allocated per refit.
fn refill_all<L: Lane, const N: usize, P: Triangles + ?Sized>(
    packs: &mut [TriangleLanes<L, N>],
    boxes: &mut [(Vec3, Vec3)],
    tris: &P,
) -> usize {
    let mut out = 0;
    for (pack, b) in packs.iter_mut().zip(boxes.iter_mut()) {
        let (lo, hi, o) = refill(pack, tris);
        (*b, out) = ((lo, hi), out + o);
    }
    out
}

/// Recomputes every child box of `nodes` (the root is `nodes[0]`), a leaf child's from the boxes
/// of its packs (`boxes[k]` for pack `k`), in post-order with a stack on the call stack: a frame
/// per node on the path from the root, with the next slot to do. A node's child boxes go into
/// its lanes as they are done; its own box (the union of its lanes) into its parent's lane when
/// all are.
fn refit_nodes<L: Lane, const N: usize>(nodes: &mut [WideNode<L, N>], boxes: &[(Vec3, Vec3)]) {
    if nodes.is_empty() {
        return;
    }
    let mut stack = [(0u32, 0usize); MAX_WIDE_DEPTH as usize + 1];
    let mut top = 1usize;
    while top > 0 {
        let (node, slot) = stack[top - 1];
        if slot == N {
            top -= 1;
            let (lo, hi) = node_box(&nodes[node as usize]);
            if top > 0 {
                let (parent, pslot) = stack[top - 1];
                set_box(&mut nodes[parent as usize], pslot, lo, hi);
                stack[top - 1].1 += 1;
            }
            continue;
        }
        stack[top - 1].1 += 1;
        let code = nodes[node as usize].child[slot];
        if code == EMPTY_CHILD {
            continue;
        }
        if code & LEAF_BIT != 0 {
            let (first, count) = leaf_packs(code);
            let (lo, hi) = boxes
                .iter()
                .skip(first)
                .take(count)
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &(l, h)| {
                    (lo.min(l), hi.max(h))
                });
            set_box(&mut nodes[node as usize], slot, lo, hi);
            continue;
        }
        if (code as usize) < nodes.len() && top < stack.len() {
            // Undo the slot step: the child's box lands in this slot when it is done.
            stack[top - 1].1 -= 1;
            stack[top] = (code, 0);
            top += 1;
        }
    }
}

/// Fills `pack` again from `tris` (each lane's primitive), returning the box of its [`kept`]
/// triangles and how many of its triangles were left out (not kept, or not in `tris`). The
/// lanes are those [`TriangleLanes::pack`] makes of the same triangles (a left-out one as an
/// unused lane: zero and not valid).
// PERF: written lane by lane here rather than through `TriangleLanes::pack` (a triangle array
// first): the 1M sphereflake's BVH8 refit 47 -> 39 ms, BVH4 87 -> 75 ms (criterion). Tried and
// dropped (BVH8 of sphereflakes of 12,800 to 1M triangles, best of many, by hand): boxes and the
// finiteness and degeneracy tests in `Vec3A` (13 -> 20 ns per triangle in cache); asking for the
// triangles of the packs 4 ahead (`Triangles::prefetch`): 2-10% slower; the lanes made by
// `Lane::transpose8` of eight-float rows (fewer stores read back as vectors): 2-4% slower.
#[inline]
fn refill<L: Lane, const N: usize, P: Triangles + ?Sized>(
    pack: &mut TriangleLanes<L, N>,
    tris: &P,
) -> (Vec3, Vec3, usize) {
    let mut c = [[[0.0f32; MAX_LANES]; 3]; 3];
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    let (mut out, mut valid) = (0, 0u32);
    for (i, &p) in pack.prim.iter().enumerate() {
        if p == INVALID {
            continue;
        }
        match tris.triangle(p as usize) {
            Some(tri) if kept(&tri) => {
                for (j, v) in tri.iter().enumerate() {
                    (lo, hi) = (lo.min(*v), hi.max(*v));
                    c[j][0][i & (MAX_LANES - 1)] = v.x;
                    c[j][1][i & (MAX_LANES - 1)] = v.y;
                    c[j][2][i & (MAX_LANES - 1)] = v.z;
                }
                if !is_degenerate(&tri) {
                    valid |= 1 << i;
                }
            }
            _ => out += 1,
        }
    }
    for (vtx, lanes) in pack.v.iter_mut().zip(&c) {
        for (axis, lane) in vtx.iter_mut().zip(lanes) {
            *axis = L::load(&lane[..N]);
        }
    }
    pack.valid = valid;
    (lo, hi, out)
}

/// `true` if the refit keeps `tri` in the tree: its vertices finite and its box one the builders
/// accept ([`usable_box`]), the rule of the builders and `Bvh2::refit` (a triangle's
/// `Primitives::prim_bounds`, then `usable_bounds`).
#[inline(always)]
pub(super) fn kept(tri: &Triangle) -> bool {
    let [a, b, c] = *tri;
    a.is_finite() && b.is_finite() && c.is_finite() && usable_box(a.min(b).min(c), a.max(b).max(c))
}

/// The union of a node's child boxes (empty slots hold the empty box).
fn node_box<L: Lane, const N: usize>(node: &WideNode<L, N>) -> (Vec3, Vec3) {
    let b = node.bounds.union();
    (b.min, b.max)
}

/// Sets child `slot`'s box of `node`.
// PERF: lanes replaced by a select in registers; writing the lane to memory and loading the
// vector back (a failed store-to-load forwarding each) took a third of the refit of a
// 12,800-triangle BVH8 (in cache).
#[inline]
fn set_box<L: Lane, const N: usize>(node: &mut WideNode<L, N>, slot: usize, lo: Vec3, hi: Vec3) {
    let lane = L::from_bitmask(1 << (slot % N));
    for a in 0..3 {
        node.bounds.min[a] = lane.select(L::splat(lo[a]), node.bounds.min[a]);
        node.bounds.max[a] = lane.select(L::splat(hi[a]), node.bounds.max[a]);
    }
}
