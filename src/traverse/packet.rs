//! Packet traversal of wide BVHs: 8 rays in SoA lanes share one walk of the tree (Wald et al.,
//! "Interactive rendering with coherent ray tracing", 2001).
//!
//! - **Coherent packets** (every active lane with the same direction signs, e.g. a 4 x 2 pixel
//!   tile of a camera) are culled with interval arithmetic (Wald, Boulos and Shirley 2007): one
//!   test of the packet's bounding interval against a node's 8 children, like one fat ray.
//! - **Other packets** walk with per-lane masks, and use the single-ray hybrid of Benthin et al.
//!   ("Combining single and packet ray tracing", 2012): where fewer than `switch` rays still
//!   enter a node, each finishes that subtree as a single ray ([`DEFAULT_SWITCH`]).
//!
//! Each child box is tested against the 8 rays with the same per-lane arithmetic as the single-ray
//! slab test (near and far planes chosen by each lane's sign bits, the same reduction order and
//! conservative far bound), and leaves with the packet triangle kernels restricted to the lanes
//! that entered the leaf. So every lane's hit equals single-ray traversal: the same `t`, and the
//! same primitive unless two triangles tie at that `t`.

use super::TriangleTest;
use super::stack::Stack;
use super::wide::intersect_from;
use crate::geometry::{Hit, INVALID, Ray};
use crate::intersect::aabb::FAR_SLACK;
use crate::intersect::{HitLanes, PreparedPacket8, PreparedRay};
use crate::layout::{BvhWideRef, EMPTY_CHILD, LEAF_BIT, MAX_WIDE_DEPTH, leaf_packs};
use crate::math::{Lane, f32x8};

const STACK: usize = MAX_WIDE_DEPTH as usize * 7 + 1;

/// Switch to single rays where fewer than this many of 8 lanes enter a node, in packets whose
/// lanes do not share direction signs. Measured on diffuse rays (bunny and a 262k-triangle
/// sphereflake, 200k rays): thresholds 3, 5, 7 ran at 0.6-1.0x single rays, 9 (every such packet
/// starts as single rays at the root) at 1.0x, pure packets (0) at 0.3x. Coherent packets (shared
/// direction signs) always use interval culling.
pub const DEFAULT_SWITCH: u32 = 9;

fn lane_mask(bits: u32) -> f32x8 {
    f32x8::load(&core::array::from_fn::<f32, 8, _>(|i| {
        if bits >> i & 1 == 1 {
            f32::from_bits(u32::MAX)
        } else {
            0.0
        }
    }))
}

/// The slab test of one box against the 8 rays, lane by lane equal to the single-ray test.
#[inline(always)]
fn box_lanes(p: &PreparedPacket8, neg: &[f32x8; 3], lo: [f32; 3], hi: [f32; 3]) -> (f32x8, u32) {
    let mut near = p.tmin;
    let mut far = p.tmax;
    for a in (0..3).rev() {
        let (l, h) = (f32x8::splat(lo[a]), f32x8::splat(hi[a]));
        // The near plane by the sign bit of each lane's direction, as the scalar test does.
        let (n, f) = (neg[a].select(h, l), neg[a].select(l, h));
        near = ((n - p.origin[a]) * p.inv_dir[a]).max_l(near);
        far = ((f - p.origin[a]) * p.inv_dir[a]).min_l(far);
    }
    let hit = near.le(far + far.abs() * f32x8::splat(FAR_SLACK));
    (near, hit.bitmask())
}

/// Closest hits of up to 8 rays (`rays[i]` into `hits[i]`) through the wide BVH `bvh` as one
/// packet; where fewer than `switch` lanes enter a node they continue as single rays (`switch`
/// = 0 never switches, 9 switches at once). Lanes past `rays.len()` and invalid rays are inactive.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.1, 0.0, -3.0), Vec3::Z)).collect();
/// let mut hits = [None; 8];
/// packet::intersect8::<Watertight, _, 8>(b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH);
/// for (r, h) in rays.iter().zip(&hits) {
///     assert_eq!(*h, b8.intersect::<Watertight>(r));
/// }
/// ```
pub fn intersect8<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
) {
    let n = rays.len().min(hits.len()).min(8);
    let mut single = [PreparedRay::EMPTY; 8];
    for (s, r) in single.iter_mut().zip(&rays[..n]) {
        *s = PreparedRay::new(r);
    }
    let mut best: [Option<Hit>; 8] = [None; 8];
    let mut packet = PreparedPacket8::from_prepared(&single);
    let active = packet.active();
    if active != 0 && !bvh.nodes.is_empty() {
        let neg: [f32x8; 3] = core::array::from_fn(|a| {
            f32x8::load(&core::array::from_fn::<f32, 8, _>(|i| {
                if single[i].neg[a] { -0.0 } else { 0.0 }
            }))
        });
        let mut lanes = HitLanes::<f32x8, 8>::default();
        // Coherent packets (every active lane with the same direction signs) are culled with
        // interval arithmetic: one test of the packet's bounding interval per node.
        let signs = |i: usize| single[i].neg.map(|b| b as u8);
        let first = active.trailing_zeros() as usize;
        let coherent = (0..8)
            .filter(|i| active >> i & 1 == 1)
            .all(|i| signs(i) == signs(first));
        if coherent {
            walk_interval::<T, L, N, false>(bvh, &mut packet, &mut single, &mut lanes, &mut best, active);
        } else {
            walk::<T, L, N>(
                bvh,
                &mut packet,
                &neg,
                &mut single,
                &mut lanes,
                &mut best,
                active,
                switch,
            );
        }
    }
    for (h, b) in hits[..n].iter_mut().zip(best) {
        *h = b;
    }
}

/// Any-hit answers for up to 8 rays (`occluded[i]` for `rays[i]`): coherent packets walk together
/// and retire lanes as they are occluded; other packets run as single rays ([`wide::occluded`](super::wide::occluded)).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.2, 0.0, -3.0), Vec3::Z)).collect();
/// let mut occ = [false; 8];
/// packet::occluded8::<Moller, _, 8>(b8.view(), &rays, &mut occ);
/// assert_eq!(occ, [true, true, true, true, true, false, false, false]);
/// ```
pub fn occluded8<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
) {
    let n = rays.len().min(occluded.len()).min(8);
    let mut single = [PreparedRay::EMPTY; 8];
    for (s, r) in single.iter_mut().zip(&rays[..n]) {
        *s = PreparedRay::new(r);
    }
    let mut packet = PreparedPacket8::from_prepared(&single);
    let active = packet.active();
    let mut mask = 0u32;
    if active != 0 && !bvh.nodes.is_empty() {
        let signs = |i: usize| single[i].neg;
        let first = active.trailing_zeros() as usize;
        if (0..8)
            .filter(|i| active >> i & 1 == 1)
            .all(|i| signs(i) == signs(first))
        {
            let mut lanes = HitLanes::<f32x8, 8>::default();
            let mut best = [None; 8];
            mask = walk_interval::<T, L, N, true>(bvh, &mut packet, &mut single, &mut lanes, &mut best, active);
        } else {
            for (i, s) in single.iter().enumerate().take(n) {
                if active >> i & 1 == 1 && occluded_from::<T, L, N>(bvh, s) {
                    mask |= 1 << i;
                }
            }
        }
    }
    for (i, o) in occluded[..n].iter_mut().enumerate() {
        *o = mask >> i & 1 == 1;
    }
}

/// Any hit of one prepared ray from the root.
fn occluded_from<T: TriangleTest, L: Lane, const N: usize>(bvh: BvhWideRef<'_, L, N>, r: &PreparedRay) -> bool {
    super::wide::occluded_prepared::<T, L, N>(bvh, r)
}

/// Copies the packet lanes' `tmax` into the single rays after leaf hits.
#[inline(always)]
fn sync_tmax(packet: &PreparedPacket8, single: &mut [PreparedRay; 8]) {
    let mut t = [0f32; 8];
    packet.tmax.store(&mut t);
    for (s, t) in single.iter_mut().zip(t) {
        s.tmax = t;
    }
}

#[allow(clippy::too_many_arguments)]
fn walk<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    packet: &mut PreparedPacket8,
    neg: &[f32x8; 3],
    single: &mut [PreparedRay; 8],
    lanes: &mut HitLanes<f32x8, 8>,
    best: &mut [Option<Hit>; 8],
    active: u32,
    switch: u32,
) {
    let mut stack = Stack::<STACK>::new();
    // Entries carry the lane mask that entered them in the distance slot's bits.
    let mut cur = (0u32, active);
    let mut budget = bvh.nodes.len() * 8 + 8;
    loop {
        let (code, mask) = cur;
        if budget == 0 {
            // Only a malformed view (a cycle) gets here: finish every lane as a single ray.
            let mut m = active;
            while m != 0 {
                let i = m.trailing_zeros() as usize;
                m &= m - 1;
                if let Some(h) = intersect_from::<T, L, N>(bvh, 0, &mut single[i]) {
                    best[i] = Some(h);
                }
            }
            return;
        }
        if mask != 0 {
            budget -= 1;
            if mask.count_ones() < switch {
                // Hybrid: the few rays left finish this subtree alone.
                let mut m = mask;
                while m != 0 {
                    let i = m.trailing_zeros() as usize;
                    m &= m - 1;
                    if let Some(h) = intersect_from::<T, L, N>(bvh, code, &mut single[i]) {
                        best[i] = Some(h);
                    }
                }
                let t: [f32; 8] = core::array::from_fn(|i| single[i].tmax);
                packet.tmax = f32x8::load(&t);
            } else if code & LEAF_BIT == 0 {
                if let Some(node) = bvh.nodes.get(code as usize) {
                    let mut lo = [[0f32; 8]; 3];
                    let mut hi = [[0f32; 8]; 3];
                    for a in 0..3 {
                        node.bounds.min[a].store(&mut lo[a]);
                        node.bounds.max[a].store(&mut hi[a]);
                    }
                    let base = stack.len();
                    for (c, &child) in node.child.iter().enumerate() {
                        if child == EMPTY_CHILD {
                            continue;
                        }
                        let (near, hit) = box_lanes(
                            packet,
                            neg,
                            [lo[0][c], lo[1][c], lo[2][c]],
                            [hi[0][c], hi[1][c], hi[2][c]],
                        );
                        let hit = hit & mask;
                        if hit != 0 {
                            // Order children by the nearest entry of any lane.
                            let d = hit_min(near, hit);
                            if !stack.push_sorted(base, child, pack_entry(d, hit)) {
                                break; // NOTE: unreachable for trees within MAX_WIDE_DEPTH
                            }
                        }
                    }
                }
            } else if code != EMPTY_CHILD {
                let (first, count) = leaf_packs(code);
                if let Some(packs) = bvh.packs.get(first..first + count) {
                    // Restrict the packet kernels to the lanes that entered this leaf.
                    let keep = packet.tmax;
                    let m = lane_mask(mask);
                    packet.tmax = m.select(packet.tmax, f32x8::splat(f32::NEG_INFINITY));
                    let mut hit_any = 0;
                    for pack in packs {
                        let mut v = pack.valid;
                        while v != 0 {
                            let j = v.trailing_zeros() as usize;
                            v &= v - 1;
                            hit_any |= T::intersect_packet(packet, &pack.get(j), pack.prim[j], lanes);
                        }
                    }
                    packet.tmax = m.select(packet.tmax, keep);
                    if hit_any != 0 {
                        sync_tmax(packet, single);
                        let mut h = hit_any;
                        while h != 0 {
                            let i = h.trailing_zeros() as usize;
                            h &= h - 1;
                            best[i] = Some(lanes.get(i));
                        }
                    }
                }
            }
        }
        match stack.pop() {
            None => return,
            Some((code, entry)) => {
                let (_, mask) = unpack_entry(entry);
                // Drop lanes whose closest hit is already nearer than this entry: the children
                // are tested again with their current tmax anyway, this only saves work.
                cur = (code, mask);
            }
        }
    }
}

/// The packet's bounding interval: per axis the range of origins and of reciprocal directions
/// over the active lanes, and the union of their `[tmin, tmax)`.
struct Interval {
    o: [(f32, f32); 3],
    inv: [(f32, f32); 3],
    tmin: f32,
    tmax: f32,
}

impl Interval {
    fn new(single: &[PreparedRay; 8], active: u32) -> Self {
        let mut iv = Interval {
            o: [(f32::INFINITY, f32::NEG_INFINITY); 3],
            inv: [(f32::INFINITY, f32::NEG_INFINITY); 3],
            tmin: f32::INFINITY,
            tmax: f32::NEG_INFINITY,
        };
        for (i, r) in single.iter().enumerate() {
            if active >> i & 1 == 0 {
                continue;
            }
            for a in 0..3 {
                iv.o[a] = (iv.o[a].0.min(r.origin[a]), iv.o[a].1.max(r.origin[a]));
                iv.inv[a] = (iv.inv[a].0.min(r.inv_dir[a]), iv.inv[a].1.max(r.inv_dir[a]));
            }
            iv.tmin = iv.tmin.min(r.tmin);
        }
        iv.tmax = single
            .iter()
            .enumerate()
            .filter(|(i, _)| active >> i & 1 == 1)
            .fold(f32::NEG_INFINITY, |m, (_, r)| m.max(r.tmax));
        iv
    }
}

/// Lower and upper bounds of `[a0, a1] * [b0, b1]` per lane (NaN products, from `0 * inf`, are
/// dropped: the bound then ignores that corner, which only widens nothing it must keep since the
/// other corners are infinite).
#[inline(always)]
fn product_bounds<L: Lane>(a0: L, a1: L, b0: f32, b1: f32) -> (L, L) {
    let (b0, b1) = (L::splat(b0), L::splat(b1));
    let (p0, p1, p2, p3) = (a0 * b0, a0 * b1, a1 * b0, a1 * b1);
    (p0.min_l(p1).min_l(p2).min_l(p3), p0.max_l(p1).max_l(p2).max_l(p3))
}

/// Coherent packets: children are culled against the packet's interval, leaves run the packet
/// triangle kernels for every active lane (exact per lane, so the answers equal single rays).
fn walk_interval<T: TriangleTest, L: Lane, const N: usize, const ANY: bool>(
    bvh: BvhWideRef<'_, L, N>,
    packet: &mut PreparedPacket8,
    single: &mut [PreparedRay; 8],
    lanes: &mut HitLanes<f32x8, 8>,
    best: &mut [Option<Hit>; 8],
    mut active: u32,
) -> u32 {
    let mut occluded = 0u32;
    let mut iv = Interval::new(single, active);
    let neg = single[active.trailing_zeros() as usize].neg;
    let slack = L::splat(FAR_SLACK);
    let mut stack = Stack::<STACK>::new();
    let mut cur = 0u32;
    let mut budget = bvh.nodes.len();
    let widened = |t: f32| t + t.abs() * FAR_SLACK;
    loop {
        if budget == 0 {
            let mut m = active;
            while m != 0 {
                let i = m.trailing_zeros() as usize;
                m &= m - 1;
                if ANY {
                    if occluded_from::<T, L, N>(bvh, &single[i]) {
                        occluded |= 1 << i;
                    }
                } else if let Some(h) = intersect_from::<T, L, N>(bvh, 0, &mut single[i]) {
                    best[i] = Some(h);
                }
            }
            return occluded;
        }
        if cur & LEAF_BIT == 0 {
            budget -= 1;
            if let Some(node) = bvh.nodes.get(cur as usize) {
                let mut near = L::splat(iv.tmin);
                let mut far = L::splat(iv.tmax);
                for (a, &negative) in neg.iter().enumerate() {
                    let (entry, exit) = if negative {
                        (node.bounds.max[a], node.bounds.min[a])
                    } else {
                        (node.bounds.min[a], node.bounds.max[a])
                    };
                    let (o0, o1) = (L::splat(iv.o[a].0), L::splat(iv.o[a].1));
                    let (n_lo, _) = product_bounds(entry - o1, entry - o0, iv.inv[a].0, iv.inv[a].1);
                    let (_, f_hi) = product_bounds(exit - o1, exit - o0, iv.inv[a].0, iv.inv[a].1);
                    near = n_lo.max_l(near);
                    far = f_hi.min_l(far);
                }
                // Both bounds widened by the slab test's slack (conservative for every lane).
                let lo = near - near.abs() * slack;
                let mut mask = lo.le(far + far.abs() * slack).bitmask() & ((1u32 << N) - 1);
                if mask != 0 {
                    let mut nears = [0f32; 8];
                    lo.store(&mut nears);
                    let base = stack.len();
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        if node.child[i] != EMPTY_CHILD && !stack.push_sorted(base, node.child[i], nears[i]) {
                            budget = 0; // NOTE: unreachable within MAX_WIDE_DEPTH; finish as singles
                            break;
                        }
                    }
                }
            }
        } else if cur != EMPTY_CHILD {
            let (first, count) = leaf_packs(cur);
            if let Some(packs) = bvh.packs.get(first..first + count) {
                let mut hit_any = 0;
                for pack in packs {
                    let mut v = pack.valid;
                    while v != 0 {
                        let j = v.trailing_zeros() as usize;
                        v &= v - 1;
                        hit_any |= T::intersect_packet(packet, &pack.get(j), pack.prim[j], lanes);
                    }
                }
                if hit_any != 0 && ANY {
                    // Any hit: retire the lanes hit; stop when none is left.
                    occluded |= hit_any;
                    active &= !hit_any;
                    if active == 0 {
                        return occluded;
                    }
                    packet.tmax = lane_mask(active).select(packet.tmax, f32x8::splat(f32::NEG_INFINITY));
                    iv = Interval::new(single, active);
                } else if hit_any != 0 {
                    sync_tmax(packet, single);
                    let mut h = hit_any;
                    while h != 0 {
                        let i = h.trailing_zeros() as usize;
                        h &= h - 1;
                        best[i] = Some(lanes.get(i));
                    }
                    iv.tmax = (0..8)
                        .filter(|i| active >> i & 1 == 1)
                        .fold(f32::NEG_INFINITY, |m, i| m.max(single[i].tmax));
                }
            }
        }
        if budget == 0 {
            continue;
        }
        loop {
            match stack.pop() {
                None => return occluded,
                Some((code, near)) if near <= widened(iv.tmax) => {
                    cur = code;
                    break;
                }
                Some(_) => {}
            }
        }
    }
}

#[inline(always)]
fn hit_min(near: f32x8, mask: u32) -> f32 {
    let mut n = [0f32; 8];
    near.store(&mut n);
    let mut d = f32::INFINITY;
    for (i, &x) in n.iter().enumerate() {
        if mask >> i & 1 == 1 && x < d {
            d = x;
        }
    }
    d
}

/// A stack entry's `f32` slot holds the lane mask in its low 8 mantissa bits and the (rounded
/// down) distance above; ordering by it orders by distance up to 2^-15 relative, which only
/// affects the visiting order, never the result.
#[inline(always)]
fn pack_entry(d: f32, mask: u32) -> f32 {
    // Finite, so that the mask bits never turn the value into a NaN.
    let d = if d.is_nan() {
        f32::MAX
    } else {
        d.clamp(-f32::MAX, f32::MAX)
    };
    f32::from_bits((d.to_bits() & !0xff) | (mask & 0xff))
}

#[inline(always)]
fn unpack_entry(e: f32) -> (f32, u32) {
    (f32::from_bits(e.to_bits() & !0xff), e.to_bits() & 0xff)
}

/// Closest hits of a batch of rays, 8 at a time as packets ([`intersect8`]).
pub fn intersect_batch<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
) {
    let n = rays.len().min(hits.len());
    for (r, h) in rays[..n].chunks(8).zip(hits[..n].chunks_mut(8)) {
        intersect8::<T, L, N>(bvh, r, h, switch);
    }
}

const _: () = assert!(INVALID == u32::MAX);
