//! Reinsertion (`Bvh2::optimize_reinsertion`, `Refine::Reinsertion`): never a higher SAH cost,
//! leaves and primitive order untouched, the depth bound kept, deterministic, and clear errors on
//! malformed trees (the tree left as it was). Hits through the optimised trees against brute force
//! are in `tests/build.rs` (the `*-reinsert` builders) and `tests/build_adversarial.rs`.

use strahl::build::{BuildParams, Builder, Bvh2, Node, Refine, ReinsertParams, ValidateError};
use strahl::geometry::Triangle;
use strahl::scene;
use strahl::{Aabb, Vec3};

const ALL: ReinsertParams = ReinsertParams {
    rounds: 4,
    per_mille: 1000,
};

/// The leaves of a tree as (box, slot range) in depth-first order of their slots.
fn leaves(b: &Bvh2) -> Vec<([f32; 3], [f32; 3], u32, u32)> {
    let mut v: Vec<_> = b
        .nodes
        .iter()
        .filter(|n| n.is_leaf())
        .map(|n| (n.min, n.max, n.index, n.count))
        .collect();
    v.sort_by_key(|l| l.2);
    v
}

fn scenes() -> Vec<(&'static str, Vec<Triangle>)> {
    vec![
        ("soup", scene::thin_soup(20_000, 3)),
        ("clustered", scene::clustered_soup(20_000, 12, 4)),
        ("bunny", scene::bunny().to_soup()),
        ("sphereflake", scene::sphereflake(2, 2).to_soup()),
        ("terrain", scene::terrain(64, 2).to_soup()),
    ]
}

#[test]
fn never_raises_the_cost_and_keeps_leaves() {
    let mut builder = Builder::new();
    for (name, tris) in scenes() {
        for (bname, p) in [
            ("fastest", BuildParams::fastest()),
            ("fast", BuildParams::fast()),
            ("ploc", BuildParams::ploc()),
            ("median", BuildParams::median()),
        ] {
            let (mut bvh, _) = builder.build(&tris[..], &p).unwrap();
            let (before, leaves_before, prims) = (bvh.sah_cost(1.0, 1.0), leaves(&bvh), bvh.prim_indices.clone());
            let stats = builder.optimize_reinsertion(&mut bvh, &ALL, 64).unwrap();
            let after = bvh.sah_cost(1.0, 1.0);
            let check = bvh.validate(&tris[..]).unwrap();
            // The sums run in another node order after the relayout: a relative 1e-5 of slack.
            assert!(after <= before * (1.0 + 1e-5), "{name}/{bname}: {before} -> {after}");
            assert_eq!(stats.max_depth, check.max_depth, "{name}/{bname}");
            assert_eq!(leaves(&bvh), leaves_before, "{name}/{bname}: leaves changed");
            assert_eq!(bvh.prim_indices, prims);
            assert_eq!(bvh.nodes.len(), 2 * leaves_before.len() - 1);
            // No search on a builder's tree comes near the budget.
            assert_eq!(stats.cut, 0, "{name}/{bname}");
            if bname == "fastest" || bname == "median" {
                // Morton and median trees leave room: the pass must find some of it.
                assert!(
                    stats.moved > 0 && after < before * 0.99,
                    "{name}/{bname}: {before} -> {after}"
                );
            }
        }
    }
}

/// Sum of the half areas of the interior nodes below `max` on every axis, in f64 (the SAH cost of
/// that part of the tree, without the root's area, which a far outlier makes so large that the
/// rest vanishes from `sah_cost` in f32).
fn interior_area_below(b: &Bvh2, max: f32) -> f64 {
    b.nodes
        .iter()
        .filter(|n| !n.is_leaf() && n.max.iter().all(|&m| m < max))
        .map(|n| {
            let d = (Vec3::from(n.max) - Vec3::from(n.min)).as_dvec3();
            d.x * d.y + d.y * d.z + d.z * d.x
        })
        .sum()
}

/// A tree whose boxes overlap wholesale (20,000 triangles of sizes from 0.001 to 1, each with its
/// vertices' mean at one point, so that every box holds that point; and one triangle 10^7 away,
/// so that the root's area dwarfs theirs) leaves a search nothing to prune: each one stops at
/// `REINSERT_SEARCH_BUDGET` visits with the best place seen, and the pass still lowers the cost
/// without raising it anywhere. (Unbounded, 3 rounds over such a tree of 100,000 triangles took
/// 84 s: the LBVH of triangles in a unit cube beside one 10^7 away, when the Morton builders left
/// the cube's one grid cell in input order.)
#[test]
fn searches_stop_at_the_budget_where_boxes_overlap() {
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut f = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    let c = Vec3::splat(0.5);
    let mut tris: Vec<Triangle> = (0..20_000)
        .map(|_| {
            let size = 10f32.powf(-3.0 * f());
            let u = (Vec3::new(f(), f(), f()) - 0.5) * size;
            let v = (Vec3::new(f(), f(), f()) - 0.5) * size;
            [c + u, c + v, c - u - v]
        })
        .collect();
    let far = Vec3::splat(1e7);
    tris.push([far, far + Vec3::X, far + Vec3::Y]);
    let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
    let (before, leaves_before) = (interior_area_below(&bvh, 2.0), leaves(&bvh));
    let whole_before = interior_area_below(&bvh, f32::INFINITY);
    let stats = bvh.optimize_reinsertion(&ALL, 64).unwrap();
    bvh.validate(&tris[..]).unwrap();
    assert_eq!(leaves(&bvh), leaves_before);
    assert!(stats.cut > 1000, "{stats:?}");
    let after = interior_area_below(&bvh, 2.0);
    assert!(stats.moved > 0 && after < before * 0.9, "{before} -> {after}");
    // Nowhere higher: the whole tree's interior area (the outlier's ancestors included) has not
    // grown either.
    let whole_after = interior_area_below(&bvh, f32::INFINITY);
    assert!(whole_after <= whole_before, "{whole_before} -> {whole_after}");
}

#[test]
fn same_tree_every_time_and_as_the_build_option() {
    let tris = scene::clustered_soup(8_000, 6, 9);
    let p = BuildParams {
        refine: Refine::Reinsertion(ALL),
        ..BuildParams::fastest()
    };
    let (once, stats) = Bvh2::build(&tris[..], &p).unwrap();
    let (mut after, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
    let r = after.optimize_reinsertion(&ALL, p.max_depth).unwrap();
    assert_eq!(once, after);
    assert_eq!((stats.restructured, stats.max_depth), (r.moved, r.max_depth));
    assert_eq!(stats.nodes as usize, once.nodes.len());
    // A reused builder (scratch from a larger tree) makes the same tree.
    let mut b = Builder::new();
    b.build(&scene::thin_soup(30_000, 1)[..], &p).unwrap();
    assert_eq!(b.build(&tris[..], &p).unwrap().0, once);
}

#[test]
fn more_work_costs_less() {
    let tris = scene::sphereflake(2, 2).to_soup();
    let (base, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
    let cost = |rounds, per_mille| {
        let mut b = base.clone();
        b.optimize_reinsertion(&ReinsertParams { rounds, per_mille }, 64)
            .unwrap();
        b.sah_cost(1.0, 1.0)
    };
    let (none, some, all) = (base.sah_cost(1.0, 1.0), cost(1, 10), cost(3, 1000));
    assert!(all < some && some < none, "{none} {some} {all}");
    // Reinsertion over the whole LBVH tree beats the full-sweep builder's tree on this scene.
    let (sweep, _) = Bvh2::build(&tris[..], &BuildParams::quality()).unwrap();
    assert!(
        all < sweep.sah_cost(1.0, 1.0) * 1.02,
        "{all} vs {}",
        sweep.sah_cost(1.0, 1.0)
    );
}

#[test]
fn depth_bound_is_kept() {
    // A geometric series of triangles: a deep, lopsided tree.
    let tris: Vec<Triangle> = (0..200)
        .map(|i| {
            let x = (2.0f32).powi(-i);
            [Vec3::new(x, 0.0, 0.0), Vec3::new(x, 1.0, 0.0), Vec3::new(x, 0.0, 1.0)]
        })
        .chain(scene::thin_soup(2_000, 5))
        .collect();
    let p = BuildParams {
        max_leaf_size: 1,
        min_leaf_size: 1,
        ..BuildParams::fast()
    };
    let (base, _) = Bvh2::build(&tris[..], &p).unwrap();
    let depth = base.validate(&tris[..]).unwrap().max_depth;
    for bound in [depth, depth + 1, 64] {
        let mut b = base.clone();
        let s = b.optimize_reinsertion(&ALL, bound).unwrap();
        let got = b.validate(&tris[..]).unwrap().max_depth;
        assert!(got <= bound && s.max_depth == got, "bound {bound}: depth {got}");
    }
    // A bound below the tree's own depth: nothing goes deeper than it already was.
    let mut b = base.clone();
    b.optimize_reinsertion(&ALL, 34).unwrap();
    assert!(b.validate(&tris[..]).unwrap().max_depth <= depth.max(34));
}

#[test]
fn small_and_empty_trees() {
    let mut empty = Bvh2::default();
    assert_eq!(empty.optimize_reinsertion(&ALL, 64).unwrap().moved, 0);
    assert!(empty.nodes.is_empty());
    for n in 1..=6 {
        let tris = scene::thin_soup(n, 7);
        let p = BuildParams {
            max_leaf_size: 1,
            ..BuildParams::fast()
        };
        let (mut b, _) = Bvh2::build(&tris[..], &p).unwrap();
        let before = b.sah_cost(1.0, 1.0);
        let s = b.optimize_reinsertion(&ALL, 64).unwrap();
        assert!(b.validate(&tris[..]).is_ok());
        assert!(b.sah_cost(1.0, 1.0) <= before * (1.0 + 1e-5));
        assert_eq!(s.max_depth, b.validate(&tris[..]).unwrap().max_depth);
    }
}

#[test]
fn malformed_trees_are_refused_untouched() {
    let tris = scene::thin_soup(500, 2);
    let (good, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
    let cases: Vec<(Bvh2, ValidateError)> = {
        let mut v = vec![];
        let mut b = good.clone();
        let last = b.nodes.len() as u32;
        b.nodes[0].index = last; // children past the end
        v.push((b, ValidateError::ChildOutOfRange { node: 0, child: last }));
        let mut b = good.clone();
        let i = b.nodes.iter().position(|n| n.is_leaf()).unwrap();
        b.nodes[i].min[1] = f32::NAN;
        v.push((b, ValidateError::BoxNotFinite { node: i as u32 }));
        let mut b = good.clone();
        b.nodes[i].min[0] = b.nodes[i].max[0] + 1.0;
        v.push((b, ValidateError::EmptyNode { node: i as u32 }));
        let mut b = good.clone();
        let (first, count) = (b.nodes[i].index, b.nodes[i].count);
        b.nodes[i].index = u32::MAX - 1;
        v.push((
            b,
            ValidateError::SlotsOutOfRange {
                node: i as u32,
                first: u32::MAX - 1,
                count,
            },
        ));
        let _ = first;
        let mut b = good.clone();
        let l = b.nodes[0].index;
        b.nodes[l as usize] = b.nodes[0]; // a cycle: the left child is the root again
        v.push((b, ValidateError::NodeReachedTwice { node: l }));
        v
    };
    for (mut b, want) in cases {
        let copy = b.clone();
        let e = b.optimize_reinsertion(&ALL, 64).unwrap_err();
        assert_eq!(e, want);
        assert!(
            b.nodes
                .iter()
                .zip(&copy.nodes)
                .all(|(x, y)| bytemuck::bytes_of(x) == bytemuck::bytes_of(y))
        );
        assert_eq!(b.prim_indices, copy.prim_indices);
    }
}

#[test]
fn unreachable_nodes_are_dropped() {
    // A hand-made tree with a pair nothing points to: the pass works on the reachable tree and
    // numbers it again without them.
    let tris: Vec<Triangle> = (0..4)
        .map(|i| {
            let x = [0.0, 10.0, 1.0, 11.0][i];
            [
                Vec3::new(x, 0.0, 0.0),
                Vec3::new(x + 0.5, 1.0, 0.0),
                Vec3::new(x, 0.0, 1.0),
            ]
        })
        .collect();
    let b = |i: usize| Aabb::from_points(&tris[i]);
    let u = |i: usize, j: usize| b(i).union(&b(j));
    // Root over (0, 1) and (2, 3): the worst pairing (each pair spans the whole scene).
    let all = u(0, 1).union(&u(2, 3));
    let nodes = vec![
        Node::interior(&all, 1),
        Node::interior(&u(0, 1), 5),
        Node::interior(&u(2, 3), 7),
        Node::leaf(&b(0), 0, 1), // unreachable pair
        Node::leaf(&b(1), 1, 1),
        Node::leaf(&b(0), 0, 1),
        Node::leaf(&b(1), 1, 1),
        Node::leaf(&b(2), 2, 1),
        Node::leaf(&b(3), 3, 1),
    ];
    let mut bvh = Bvh2 {
        nodes,
        prim_indices: vec![0, 1, 2, 3],
    };
    let before = bvh.sah_cost(1.0, 1.0);
    let s = bvh.optimize_reinsertion(&ALL, 64).unwrap();
    assert!(s.moved > 0);
    assert_eq!(bvh.nodes.len(), 7);
    assert!(bvh.validate(&tris[..]).is_ok());
    // The best pairing puts the near triangles together: 0 with 2, 1 with 3.
    assert!(
        bvh.sah_cost(1.0, 1.0) < before * 0.6,
        "{before} -> {}",
        bvh.sah_cost(1.0, 1.0)
    );
}
