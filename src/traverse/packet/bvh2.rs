//! Packet walks of a binary BVH ([`Bvh2Ref`]): both children of a node tested against every lane
//! that entered it, the nearer (by the nearest entry of any lane) visited first, the other pushed
//! with the mask of lanes that hit it.

use super::leaf::Leaves;
use super::stack::{Entry, MaskStack};
use super::wide::{box_lanes, hit_min, open_lanes, prepare_into, sign_lanes};
use crate::geometry::{Hit, Ray, Triangles};
use crate::intersect::{PreparedPacket, PreparedRay};
use crate::math::Lane;
use crate::traverse::{Bvh2Ref, STACK_SIZE, TriangleTest, intersect_scalar, occluded_scalar};

/// Closest hits (`ANY = false`) or any-hit answers of up to `K` rays. Returns the occluded lanes
/// (`ANY`) and writes the closest hits into `best`.
pub(super) fn run<T: TriangleTest, P: Triangles + ?Sized, R: Lane, const K: usize, const ANY: bool>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    rays: &[Ray],
    best: &mut [Option<Hit>; K],
) -> u32 {
    let n = rays.len().min(K);
    let mut single = [PreparedRay::EMPTY; K];
    prepare_into(&rays[..n], &mut single, true);
    let mut packet = PreparedPacket::<R, K>::from_prepared(&single);
    let mut active = packet.active();
    let nodes = bvh.nodes;
    let Some(root) = nodes.first() else {
        return 0;
    };
    if active == 0 {
        return 0;
    }
    let neg = sign_lanes::<R, K>(&single);
    let mut lanes = Leaves::<R, K>::new(&single);
    let mut occluded = 0u32;
    let (near, hit) = box_lanes(&packet, &neg, root.min, root.max);
    let mut cur = Entry {
        code: 0,
        dist: hit_min::<R, K>(near, hit & active),
        mask: hit & active,
    };
    if cur.mask == 0 {
        return 0;
    }
    let mut stack = MaskStack::<STACK_SIZE>::new();
    // A valid tree visits each node at most once per packet; more visits mean a cycle.
    let mut budget = nodes.len();
    let finish_as_singles = |active: u32, best: &mut [Option<Hit>; K]| {
        // Only a cycle or a tree deeper than the builders make gets here: the scalar reference
        // answers the lanes still active, exactly.
        let mut occluded = 0;
        let mut m = active;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            if ANY {
                if occluded_scalar::<T, P>(bvh, tris, &rays[i]) {
                    occluded |= 1 << i;
                }
            } else {
                best[i] = intersect_scalar::<T, P>(bvh, tris, &rays[i]);
            }
        }
        occluded
    };
    loop {
        if budget == 0 {
            return occluded | finish_as_singles(active, best);
        }
        budget -= 1;
        let Entry { code, mask, .. } = cur;
        let Some(node) = nodes.get(code as usize) else {
            return occluded | finish_as_singles(active, best);
        };
        if node.is_leaf() {
            // Restrict the packet kernels to the lanes that entered this leaf.
            lanes.begin(&mut packet, mask);
            let mut hit_any = 0;
            for slot in node.prim_range() {
                let Some(&prim) = bvh.prim_indices.get(slot) else {
                    break;
                };
                if let Some(tri) = tris.triangle(prim as usize) {
                    hit_any |= lanes.test::<T>(&mut packet, &tri, prim);
                }
            }
            lanes.end(&mut packet);
            if hit_any != 0 {
                if ANY {
                    // Any hit: retire the lanes hit (an empty interval); stop when none is left.
                    occluded |= hit_any;
                    active &= !hit_any;
                    if active == 0 {
                        return occluded;
                    }
                    packet.tmax = R::from_bitmask(active).select(packet.tmax, R::splat(f32::NEG_INFINITY));
                } else {
                    let mut h = hit_any;
                    while h != 0 {
                        let i = h.trailing_zeros() as usize;
                        h &= h - 1;
                        best[i] = Some(lanes.get(i));
                    }
                }
            }
        } else {
            let (li, ri) = (node.left(), node.right());
            let test = |i: u32, packet: &PreparedPacket<R, K>| match nodes.get(i as usize) {
                Some(c) => {
                    let (near, hit) = box_lanes(packet, &neg, c.min, c.max);
                    let hit = hit & mask;
                    (hit_min::<R, K>(near, hit), hit)
                }
                None => (f32::INFINITY, 0),
            };
            let (dl, ml) = test(li, &packet);
            let (dr, mr) = test(ri, &packet);
            let l = Entry {
                code: li,
                dist: dl,
                mask: ml,
            };
            let r = Entry {
                code: ri,
                dist: dr,
                mask: mr,
            };
            match (ml != 0, mr != 0) {
                (true, true) => {
                    // Both hit: descend into the nearer (ties: left), push the farther.
                    let (near, far) = if dr < dl { (r, l) } else { (l, r) };
                    if !stack.push_sorted(stack.len(), far) {
                        // NOTE: only a tree deeper than the builders make gets here.
                        return occluded | finish_as_singles(active, best);
                    }
                    cur = near;
                    continue;
                }
                (true, false) => {
                    cur = l;
                    continue;
                }
                (false, true) => {
                    cur = r;
                    continue;
                }
                (false, false) => {}
            }
        }
        // Pop the next far child that some lane can still hit, keeping only those lanes.
        loop {
            match stack.pop() {
                None => return occluded,
                Some(e) => {
                    let m = e.mask & active & open_lanes(packet.tmax, e.dist);
                    if m != 0 {
                        cur = Entry { mask: m, ..e };
                        break;
                    }
                }
            }
        }
    }
}
