//! Any-hit visiting orders, counted (ignored: run by hand):
//! `cargo test --release --test anyhit_order -- --ignored --nocapture`. The bench's shadow rays
//! (`benches/common`, 262,144 from surface points to random points in the box) through the BVH8
//! of `BuildParams::default()`; for the rays that are blocked, the nodes visited and packs tested
//! before the first hit under several child orders, beside the fewest possible (the shallowest
//! leaf holding an occluder). `STRAHL_SCENE`: `sphereflake` (1M, default) or `bunny`.

#[path = "../benches/common/mod.rs"]
mod common;
use strahl::build::{BuildParams, Bvh2};
use strahl::intersect::{PreparedRay, aabb::intersect_aabb_lanes};
use strahl::layout::{Bvh8, EMPTY_CHILD, LEAF_BIT, leaf_packs};
use strahl::math::Lane;
use strahl::traverse::{Moller, TriangleTest};

#[derive(Clone, Copy, Debug)]
enum Order {
    Slot,
    ReverseSlot,
    Near,
    Far,
    LeavesFirst,
    /// Decreasing summed triangle area below the child (the expected hits of a random line).
    Geometry,
}

/// (nodes visited, packs tested, blocked) of one any-hit walk in `order`.
fn walk(b8: &Bvh8, geo: &Geo, r: &PreparedRay, order: Order) -> (u32, u32, bool) {
    let (mut nodes, mut packs) = (0, 0);
    let mut stack = vec![0u32];
    while let Some(cur) = stack.pop() {
        if cur & LEAF_BIT != 0 {
            let (first, count) = leaf_packs(cur);
            for p in &b8.packs()[first..first + count] {
                packs += 1;
                if Moller::hit_mask_lanes(r, p) != 0 {
                    return (nodes, packs, true);
                }
            }
            continue;
        }
        nodes += 1;
        let node = &b8.nodes()[cur as usize];
        let (tn, mask) = intersect_aabb_lanes(r, &node.bounds);
        let t: Vec<f32> = (0..8).map(|i| tn.lane(i)).collect();
        let mut kids: Vec<(f32, u32, usize)> = (0..8)
            .filter(|&i| mask >> i & 1 == 1 && node.child[i] != EMPTY_CHILD)
            .map(|i| (t[i], node.child[i], i))
            .collect();
        // The stack pops the last pushed first: push in the reverse of the visiting order.
        match order {
            Order::Slot => kids.sort_by_key(|k| std::cmp::Reverse(k.2)),
            Order::ReverseSlot => kids.sort_by_key(|k| k.2),
            Order::Near => kids.sort_by(|a, b| b.0.total_cmp(&a.0)),
            Order::Far => kids.sort_by(|a, b| a.0.total_cmp(&b.0)),
            Order::LeavesFirst => kids.sort_by_key(|k| (k.1 & LEAF_BIT != 0, std::cmp::Reverse(k.2))),
            Order::Geometry => kids.sort_by(|a, b| geo.of(b8, a.1).total_cmp(&geo.of(b8, b.1))),
        }
        stack.extend(kids.iter().map(|k| k.1));
    }
    (nodes, packs, false)
}

/// Summed triangle areas below each wide node and in each leaf's packs.
struct Geo {
    nodes: Vec<f32>,
    tris: Vec<f32>,
}

impl Geo {
    fn new(b8: &Bvh8, tris: &[strahl::geometry::Triangle]) -> Self {
        let area = |t: &strahl::geometry::Triangle| (t[1] - t[0]).cross(t[2] - t[0]).length() * 0.5;
        let mut g = Geo {
            nodes: vec![-1.0; b8.nodes().len()],
            tris: tris.iter().map(area).collect(),
        };
        // Children come after their parents: fill from the back.
        for i in (0..b8.nodes().len()).rev() {
            let s: f32 = b8.nodes()[i].child.iter().map(|&c| g.of_code(b8, c)).sum();
            g.nodes[i] = s;
        }
        g
    }
    fn of_code(&self, b8: &Bvh8, c: u32) -> f32 {
        if c == EMPTY_CHILD {
            0.0
        } else if c & LEAF_BIT != 0 {
            let (first, count) = leaf_packs(c);
            b8.packs()[first..first + count]
                .iter()
                .flat_map(|p| {
                    (0..8)
                        .filter(|&i| p.valid >> i & 1 == 1)
                        .map(|i| self.tris[p.prim[i] as usize])
                })
                .sum()
        } else {
            self.nodes[c as usize]
        }
    }
    fn of(&self, b8: &Bvh8, c: u32) -> f32 {
        self.of_code(b8, c)
    }
}

/// The fewest nodes a walk must visit to reach an occluder: the depth of the shallowest leaf
/// (in wide nodes above it) with a hit, over every leaf the ray enters.
fn shallowest(b8: &Bvh8, r: &PreparedRay) -> Option<u32> {
    let mut best = None;
    let mut stack = vec![(0u32, 0u32)];
    while let Some((cur, depth)) = stack.pop() {
        if best.is_some_and(|b| depth >= b) {
            continue;
        }
        if cur & LEAF_BIT != 0 {
            let (first, count) = leaf_packs(cur);
            if b8.packs()[first..first + count]
                .iter()
                .any(|p| Moller::hit_mask_lanes(r, p) != 0)
            {
                best = Some(depth);
            }
            continue;
        }
        let node = &b8.nodes()[cur as usize];
        let (_, mask) = intersect_aabb_lanes(r, &node.bounds);
        for i in 0..8 {
            if mask >> i & 1 == 1 && node.child[i] != EMPTY_CHILD {
                stack.push((node.child[i], depth + 1));
            }
        }
    }
    best
}

#[test]
#[ignore]
fn orders() {
    let tris = match std::env::var("STRAHL_SCENE").as_deref() {
        Ok("bunny") => strahl::scene::bunny().to_soup(),
        _ => strahl::scene::sphereflake(3, 3).to_soup(),
    };
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let b = common::bounds(&tris);
    let rays = common::shadow_rays(&tris, &b, 1 << 18, (b.max - b.min).length());
    let geo = Geo::new(&b8, &tris);
    let prepared: Vec<PreparedRay> = rays.iter().map(PreparedRay::new).collect();
    let blocked: Vec<&PreparedRay> = prepared.iter().filter(|r| walk(&b8, &geo, r, Order::Slot).2).collect();
    let n = blocked.len() as f64;
    println!(
        "{} of {} rays blocked; BVH8 depth {}",
        blocked.len(),
        rays.len(),
        b8.depth()
    );
    let ideal: u64 = blocked.iter().map(|r| shallowest(&b8, r).unwrap_or(0) as u64).sum();
    println!("fewest nodes to an occluder: {:.2} per blocked ray", ideal as f64 / n);
    for order in [
        Order::Slot,
        Order::ReverseSlot,
        Order::Near,
        Order::Far,
        Order::LeavesFirst,
        Order::Geometry,
    ] {
        let (mut nodes, mut packs) = (0u64, 0u64);
        for r in &blocked {
            let (a, p, hit) = walk(&b8, &geo, r, order);
            assert!(hit);
            nodes += a as u64;
            packs += p as u64;
        }
        println!(
            "{order:?}: {:.2} nodes, {:.2} packs per blocked ray",
            nodes as f64 / n,
            packs as f64 / n
        );
    }
}
