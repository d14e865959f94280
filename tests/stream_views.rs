//! Hand-built wide-BVH views that break the tree's invariants in the ways a ray stream could
//! answer differently from one walk per ray (written by this session's review): empty slots with
//! boxes a ray hits, chains deeper than `MAX_WIDE_DEPTH` (one level too deep, or deep below
//! where one ray leaves the others), nodes with two parents that spend the visit budget. In each,
//! `occluded_batch_stream`, the adaptive `occluded_batch` and `occluded_batch_incoherent` must answer
//! exactly as `occluded` per ray.

use strahl::build::{BuildParams, Bvh2};
use strahl::intersect::AabbX8;
use strahl::layout::{Bvh8, Bvh8Ref, BvhWideRef, EMPTY_CHILD, LEAF_BIT, Node8};
use strahl::traverse::{Moller, wide};
use strahl::{Aabb, Ray, Vec3};

fn pack_of(tri: [Vec3; 3]) -> Bvh8 {
    let tris = [tri];
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    Bvh8::from_bvh2(&b2, &tris[..]).unwrap()
}
fn big() -> Aabb {
    Aabb::new(Vec3::splat(-10.0), Vec3::splat(10.0))
}
/// Pack 0 misses every ray of these tests (it lies far away); pack 1, which no leaf refers to
/// in most views, is hit by the rays at x < 0: found only by a scan of every pack.
fn miss_and_hit_packs() -> Vec<strahl::intersect::TriangleLanes<strahl::math::f32x8, 8>> {
    let miss = pack_of([
        Vec3::new(100.0, 100.0, 100.0),
        Vec3::new(101.0, 100.0, 100.0),
        Vec3::new(100.0, 101.0, 100.0),
    ]);
    let hit = pack_of([
        Vec3::new(-8.0, -8.0, 0.0),
        Vec3::new(-2.0, -8.0, 0.0),
        Vec3::new(-5.0, 8.0, 0.0),
    ]);
    vec![miss.packs()[0], hit.packs()[0]]
}
/// A node with the boxes `boxes` in its first slots and the children `kids`, the rest empty.
/// Two parallel rays along +z, at x = -1 and x = 1.
fn two_rays() -> [Ray; 2] {
    [
        Ray::new(Vec3::new(-1.0, 0.0, -100.0), Vec3::Z),
        Ray::new(Vec3::new(1.0, 0.0, -100.0), Vec3::Z),
    ]
}

fn node(boxes: &[Aabb], kids: &[u32]) -> Node8 {
    let mut n = Node8::empty();
    n.bounds = AabbX8::from_boxes(boxes);
    n.child = [EMPTY_CHILD; 8];
    n.child[..kids.len()].copy_from_slice(kids);
    n
}
fn check(view: Bvh8Ref, rays: &[Ray], what: &str) {
    let single: Vec<bool> = rays.iter().map(|r| wide::occluded::<Moller, _, 8>(view, r)).collect();
    let mut s = vec![false; rays.len()];
    wide::occluded_batch_stream::<Moller, _, 8>(view, rays, &mut s);
    let mut a = vec![false; rays.len()];
    wide::occluded_batch::<Moller, _, 8>(view, rays, &mut a);
    let mut inc = vec![false; rays.len()];
    wide::occluded_batch_incoherent::<Moller, _, 8>(view, rays, &mut inc);
    assert_eq!(inc, single, "{what}: incoherent");
    assert_eq!(s, single, "{what}: stream");
    assert_eq!(a, single, "{what}: adaptive");
}

/// A chain of 100 nodes, each with 8 hit boxes but only slot 0 a real child (slots 1..7
/// EMPTY_CHILD with non-empty boxes). The single walk pushes 8 per node and overflows
/// (then scans every pack, finding the unreferenced hit pack); the stream skips EMPTY_CHILD.
#[test]
fn stream_empty_slots_with_boxes() {
    let hit = pack_of([
        Vec3::new(-8.0, -8.0, 0.0),
        Vec3::new(8.0, -8.0, 0.0),
        Vec3::new(0.0, 8.0, 0.0),
    ]);
    let packs = hit.packs().to_vec();
    let d = 100;
    let nodes: Vec<Node8> = (0..d)
        .map(|j| {
            let mut n = Node8::empty();
            n.bounds = AabbX8::from_boxes(&[big(); 8]);
            n.child = [EMPTY_CHILD; 8];
            if j + 1 < d {
                n.child[0] = (j + 1) as u32;
            }
            n
        })
        .collect();
    let view: Bvh8Ref = BvhWideRef {
        nodes: &nodes,
        packs: &packs,
    };
    let rays = two_rays();
    check(view, &rays, "empty slots");
}

/// A plain tree (every code in range, no cycles, no second parents), too deep: two rays walk a
/// chain of 50 nodes together (7 leaf siblings pending per level), then ray A alone a chain of 50
/// more. A's own walk overflows its stack and scans every pack (an unreferenced pack it hits);
/// a stream that walked A's part on a fresh stack (the first version) answered false.
#[test]
fn stream_deep_below_where_rays_part() {
    let packs = miss_and_hit_packs();
    let miss_leaf = LEAF_BIT; // pack 0, one pack
    let (l1, l2) = (50usize, 50usize);
    let mut nodes: Vec<Node8> = Vec::new();
    for j in 0..l1 {
        let mut n = Node8::empty();
        n.bounds = AabbX8::from_boxes(&[big(); 8]);
        n.child = [miss_leaf; 8];
        n.child[0] = (j + 1) as u32;
        nodes.push(n);
    }
    // Node l1: slot 0 (x < 0) for ray A, slot 1 (x > 0) for ray B.
    let mut n = Node8::empty();
    n.bounds = AabbX8::from_boxes(&[
        Aabb::new(Vec3::new(-10.0, -10.0, -10.0), Vec3::new(-0.5, 10.0, 10.0)),
        Aabb::new(Vec3::new(0.5, -10.0, -10.0), Vec3::new(10.0, 10.0, 10.0)),
    ]);
    n.child = [EMPTY_CHILD; 8];
    n.child[0] = (l1 + 1) as u32;
    n.child[1] = miss_leaf;
    nodes.push(n);
    for j in 0..l2 {
        let mut n = Node8::empty();
        n.bounds = AabbX8::from_boxes(&[big(); 8]);
        n.child = [miss_leaf; 8];
        n.child[0] = if j + 1 < l2 { (l1 + 2 + j) as u32 } else { miss_leaf };
        nodes.push(n);
    }
    // Unreferenced nodes: budget to spare (otherwise the lone walk spends it exactly and the
    // stream falls back).
    for _ in 0..10 {
        nodes.push(Node8::empty());
    }
    let view: Bvh8Ref = BvhWideRef {
        nodes: &nodes,
        packs: &packs,
    };
    let rays = [
        Ray::new(Vec3::new(-5.0, 0.0, -100.0), Vec3::Z),
        Ray::new(Vec3::new(5.0, 0.0, -100.0), Vec3::Z),
    ];
    check(view, &rays, "lone fresh stack");
}

/// Off by one, every code valid, no cycles: 72 nodes of 8 children (slot 0 the next node, 7
/// leaves), then a node with 2 leaves, entered by both rays. One ray's walk pushes both (504 + 2
/// > 505 = STACK) and overflows into the scan of every pack; the stream pushes one.
fn off_by_one() -> (
    Vec<Node8>,
    Vec<strahl::intersect::TriangleLanes<strahl::math::f32x8, 8>>,
) {
    let miss = pack_of([
        Vec3::new(100.0, 100.0, 100.0),
        Vec3::new(101.0, 100.0, 100.0),
        Vec3::new(100.0, 101.0, 100.0),
    ]);
    let hit = pack_of([
        Vec3::new(-8.0, -8.0, 0.0),
        Vec3::new(8.0, -8.0, 0.0),
        Vec3::new(0.0, 8.0, 0.0),
    ]);
    let packs = vec![miss.packs()[0], hit.packs()[0]];
    let mut nodes: Vec<Node8> = (0..72)
        .map(|j| {
            let mut n = Node8::empty();
            n.bounds = AabbX8::from_boxes(&[big(); 8]);
            n.child = [LEAF_BIT; 8];
            n.child[0] = j + 1;
            n
        })
        .collect();
    let mut last = Node8::empty();
    last.bounds = AabbX8::from_boxes(&[big(); 2]);
    last.child = [EMPTY_CHILD; 8];
    (last.child[0], last.child[1]) = (LEAF_BIT, LEAF_BIT);
    nodes.push(last);
    (nodes, packs)
}
#[test]
fn stream_off_by_one() {
    let (nodes, packs) = off_by_one();
    let view: Bvh8Ref = BvhWideRef {
        nodes: &nodes,
        packs: &packs,
    };
    let rays = two_rays();
    check(view, &rays, "off by one");
}
/// The same views through the packet path of the adaptive batches (8 coherent rays).
#[test]
fn packets_on_deep_views() {
    let (nodes, packs) = off_by_one();
    let view: Bvh8Ref = BvhWideRef {
        nodes: &nodes,
        packs: &packs,
    };
    let rays: Vec<Ray> = (0..8)
        .map(|i| Ray::new(Vec3::new(0.01 * i as f32, 0.0, -100.0), Vec3::Z))
        .collect();
    let single: Vec<bool> = rays.iter().map(|r| wide::occluded::<Moller, _, 8>(view, r)).collect();
    let mut a = vec![false; 8];
    wide::occluded_batch::<Moller, _, 8>(view, &rays, &mut a);
    assert_eq!(a, single, "packets, off by one");
    let hs: Vec<_> = rays.iter().map(|r| wide::intersect::<Moller, _, 8>(view, r)).collect();
    let mut h = vec![None; 8];
    wide::intersect_batch::<Moller, _, 8>(view, &rays, &mut h);
    assert_eq!(h, hs, "packets closest, off by one");
}

/// A node with two parents (3 visits for 2 nodes) under ray A's part of the tree, while rays B and
/// C walk the other part: A's own walk (budget 4) ends normally and answers false; the stream's
/// one budget for all rays runs out (the first version's held-back walk did, and answered from the
/// scan of every pack, an unreferenced pack A hits), so every ray is answered by its own walk.
#[test]
fn two_parents_spend_the_shared_budget() {
    let packs = miss_and_hit_packs();
    let right = Aabb::new(Vec3::new(0.5, -10.0, -10.0), Vec3::splat(10.0));
    let left = Aabb::new(Vec3::splat(-10.0), Vec3::new(-0.5, 10.0, 10.0));
    let nodes = vec![
        node(&[right, left], &[1, 2]),
        node(&[big()], &[LEAF_BIT]),
        node(&[big(), big()], &[3, 3]),
        node(&[big()], &[LEAF_BIT]),
    ];
    let view: Bvh8Ref = BvhWideRef {
        nodes: &nodes,
        packs: &packs,
    };
    let rays = [
        Ray::new(Vec3::new(-5.0, 0.0, -100.0), Vec3::Z),
        Ray::new(Vec3::new(5.0, 0.0, -100.0), Vec3::Z),
        Ray::new(Vec3::new(5.0, 1.0, -100.0), Vec3::Z),
    ];
    assert!(!wide::occluded::<Moller, _, 8>(view, &rays[0]));
    check(view, &rays, "shared budget");
}

/// Two parts of ray A's walk, each with a node of two parents, that fit the budget one by one but
/// not together: A's own walk runs out of budget and answers from the scan of every pack (true).
#[test]
fn two_parts_overspend_the_budget_together() {
    let packs = miss_and_hit_packs();
    let right = Aabb::new(Vec3::new(0.5, -10.0, -10.0), Vec3::splat(10.0));
    let left = Aabb::new(Vec3::splat(-10.0), Vec3::new(-0.5, 10.0, 10.0));
    let nodes = vec![
        node(&[right, left, left], &[1, 2, 3]),
        node(&[big()], &[LEAF_BIT]),
        node(&[big(), big()], &[4, 4]),
        node(&[big(), big()], &[5, 5]),
        node(&[big()], &[LEAF_BIT]),
        node(&[big()], &[LEAF_BIT]),
    ];
    let view: Bvh8Ref = BvhWideRef {
        nodes: &nodes,
        packs: &packs,
    };
    let rays = [
        Ray::new(Vec3::new(-5.0, 0.0, -100.0), Vec3::Z),
        Ray::new(Vec3::new(5.0, 0.0, -100.0), Vec3::Z),
        Ray::new(Vec3::new(5.0, 1.0, -100.0), Vec3::Z),
    ];
    assert!(wide::occluded::<Moller, _, 8>(view, &rays[0])); // its own walk runs out: the scan
    check(view, &rays, "two parts over budget");
}
