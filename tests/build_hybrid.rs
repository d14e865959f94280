//! The hybrid and refinement builders: HLBVH ([`Strategy::Hlbvh`]), treelet restructuring
//! ([`Refine::Treelets`], [`Bvh2::optimize_treelets`]), tree rotations ([`Refine::Rotations`],
//! [`Bvh2::optimize_rotations`]) and their preset
//! ([`BuildParams::hybrid`]). (Every builder, these included, is also checked against brute
//! force on random, clustered and adversarial scenes in `tests/build.rs`.)

use std::time::Instant;
use strahl::build::{BuildParams, Builder, Bvh2, Refine, Strategy, TreeletParams, ValidateError};
use strahl::geometry::Triangle;
use strahl::scene::{self, Rng};
use strahl::traverse::{Watertight, intersect_brute_force};
use strahl::{Ray, Vec3};

fn treelets(leaves: u32, min_prims: u32, rounds: u32) -> TreeletParams {
    TreeletParams {
        leaves,
        min_prims,
        rounds,
    }
}

/// Triangles at `x = 2^-i`: nested boxes, trees as deep as the bound allows.
fn geometric() -> Vec<Triangle> {
    (0..200)
        .map(|i| {
            let x = 2f32.powf(-(i as f32));
            [Vec3::new(x, 0.0, 0.0), Vec3::new(x, x, 0.0), Vec3::new(x, 0.0, x)]
        })
        .collect()
}

fn scenes() -> Vec<(&'static str, Vec<Triangle>)> {
    vec![
        ("thin_soup", scene::thin_soup(4000, 3)),
        ("clustered", scene::clustered_soup(4000, 6, 4)),
        ("bunny", scene::bunny().to_soup()),
        ("geometric", geometric()),
        ("same", vec![[Vec3::ZERO, Vec3::X, Vec3::Y]; 300]),
    ]
}

/// The refinement after every builder never raises the SAH cost (for several `C_T`, `C_I`), keeps
/// the tree valid, its leaves, slots and node count, and respects the depth bound.
#[test]
fn treelets_never_increase_sah_cost() {
    let bases = [
        BuildParams::fastest(),
        BuildParams::fast(),
        BuildParams::quality(),
        BuildParams::median(),
        BuildParams {
            refine: Refine::None,
            ..BuildParams::hybrid()
        },
    ];
    let mut builder = Builder::new();
    for (scene, tris) in scenes() {
        for base in bases {
            for max_depth in [34, 64] {
                let base = BuildParams { max_depth, ..base };
                let (bvh, _) = builder.build(&tris[..], &base).unwrap();
                for (agglomerative, tp) in [
                    (false, treelets(3, 1, 1)),
                    (false, treelets(7, 2, 2)),
                    (false, treelets(8, 1, 1)),
                    (false, treelets(5, 50, 3)),
                    (true, treelets(3, 1, 1)),
                    (true, TreeletParams::agglomerative()),
                    (true, treelets(16, 1, 2)),
                    (true, treelets(12, 40, 1)),
                ] {
                    let mut t = bvh.clone();
                    let stats = if agglomerative {
                        builder.optimize_treelets_agglomerative(&mut t, &tp, max_depth).unwrap()
                    } else {
                        builder.optimize_treelets(&mut t, &tp, max_depth).unwrap()
                    };
                    let v = t
                        .validate(&tris[..])
                        .unwrap_or_else(|e| panic!("{scene}/{base:?}: {e}"));
                    assert!(v.max_depth <= max_depth, "{scene}: depth {}", v.max_depth);
                    assert_eq!(stats.max_depth, v.max_depth, "{scene}");
                    assert_eq!(t.nodes.len(), bvh.nodes.len());
                    assert_eq!(t.prim_indices, bvh.prim_indices);
                    assert_eq!(t.nodes[0].aabb(), bvh.nodes[0].aabb(), "the root keeps its box");
                    let leaves = |b: &Bvh2| {
                        let mut l: Vec<_> = b.nodes.iter().filter(|n| n.is_leaf()).copied().collect();
                        l.sort_by_key(|n| n.index);
                        l
                    };
                    assert_eq!(leaves(&t), leaves(&bvh), "leaves are moved, never changed");
                    for (ct, ci) in [(1.0, 1.0), (4.0, 1.0), (0.5, 2.0)] {
                        let (before, after) = (bvh.sah_cost(ct, ci), t.sah_cost(ct, ci));
                        assert!(after <= before, "{scene}/{base:?}/{tp:?}: {before} -> {after}");
                    }
                }
            }
        }
    }
}

/// Rotations after every builder never raise the SAH cost (for several `C_T`, `C_I`), keep the
/// tree valid, its leaves, slots, node count and root box, respect the depth bound, and do
/// improve an LBVH.
#[test]
fn rotations_never_increase_sah_cost() {
    let bases = [
        BuildParams::fastest(),
        BuildParams::fast(),
        BuildParams::quality(),
        BuildParams::median(),
        BuildParams::hybrid_sah(),
    ];
    let mut builder = Builder::new();
    for (scene, tris) in scenes() {
        for base in bases {
            for max_depth in [34, 64] {
                let base = BuildParams { max_depth, ..base };
                let (bvh, _) = builder.build(&tris[..], &base).unwrap();
                for rounds in [1, 3] {
                    let mut t = bvh.clone();
                    let stats = t.optimize_rotations(rounds, max_depth).unwrap();
                    let v = t
                        .validate(&tris[..])
                        .unwrap_or_else(|e| panic!("{scene}/{base:?}: {e}"));
                    assert!(v.max_depth <= max_depth, "{scene}: depth {}", v.max_depth);
                    assert_eq!(stats.max_depth, v.max_depth, "{scene}");
                    assert!(stats.rounds <= rounds);
                    assert_eq!(t.nodes.len(), bvh.nodes.len());
                    assert_eq!(t.prim_indices, bvh.prim_indices);
                    assert_eq!(t.nodes[0].aabb(), bvh.nodes[0].aabb(), "the root keeps its box");
                    let leaves = |b: &Bvh2| {
                        let mut l: Vec<_> = b.nodes.iter().filter(|n| n.is_leaf()).copied().collect();
                        l.sort_by_key(|n| n.index);
                        l
                    };
                    assert_eq!(leaves(&t), leaves(&bvh), "leaves are moved, never changed");
                    for (ct, ci) in [(1.0, 1.0), (4.0, 1.0), (0.5, 2.0)] {
                        let (before, after) = (bvh.sah_cost(ct, ci), t.sah_cost(ct, ci));
                        assert!(after <= before, "{scene}/{base:?}/{rounds}: {before} -> {after}");
                    }
                }
            }
        }
    }
    // On the LBVH of a random soup, one round cuts the cost by more than 1%.
    let soup = scene::thin_soup(20_000, 5);
    let (mut lbvh, _) = Bvh2::build(&soup[..], &BuildParams::fastest()).unwrap();
    let before = lbvh.sah_cost(1.0, 1.0);
    let stats = lbvh.optimize_rotations(1, 64).unwrap();
    assert!(stats.rotations > 0);
    assert!(
        lbvh.sah_cost(1.0, 1.0) < before * 0.99,
        "{before} -> {}",
        lbvh.sah_cost(1.0, 1.0)
    );
    // Malformed trees are errors, and nothing changes.
    let mut bad = lbvh.clone();
    bad.nodes[0].index = bad.nodes.len() as u32;
    let copy = bad.clone();
    assert!(bad.optimize_rotations(2, 64).is_err());
    assert_eq!(bad, copy);
    let mut twice = lbvh.clone();
    let l = twice.nodes[0].left();
    let inner = (1..twice.nodes.len())
        .find(|&i| !twice.nodes[i].is_leaf() && i as u32 != l)
        .unwrap();
    twice.nodes[inner].index = l; // the root's children, reached a second time
    let copy = twice.clone();
    assert!(twice.optimize_rotations(1, 64).is_err());
    assert_eq!(twice, copy);
    let mut empty = Bvh2::default();
    assert_eq!(empty.optimize_rotations(1, 64).unwrap().rotations, 0);
}

/// On an LBVH of a random scene, one round of 7-leaf treelets cuts the SAH cost by several
/// percent; the hybrid beats both the HLBVH alone and the LBVH.
#[test]
fn treelets_reduce_lbvh_cost_and_hybrid_beats_lbvh() {
    for (scene, tris) in [
        ("soup", scene::thin_soup(20_000, 5)),
        ("clustered", scene::clustered_soup(20_000, 9, 6)),
        ("bunny", scene::bunny().to_soup()),
    ] {
        let cost = |p: BuildParams| Bvh2::build(&tris[..], &p).unwrap().0.sah_cost(1.0, 1.0);
        let (mut lbvh, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
        let before = lbvh.sah_cost(1.0, 1.0);
        let stats = lbvh.optimize_treelets(&TreeletParams::default(), 64).unwrap();
        let after = lbvh.sah_cost(1.0, 1.0);
        assert!(stats.restructured > 0 && stats.treelets >= stats.restructured);
        assert!(after < before * 0.97, "{scene}: {before} -> {after}");
        lbvh.validate(&tris[..]).unwrap();
        // The agglomerative pass (ATRBVH) with 9 leaves, two rounds: as good a tree.
        let (mut atr, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
        let stats = atr
            .optimize_treelets_agglomerative(&TreeletParams::agglomerative(), 64)
            .unwrap();
        let agg = atr.sah_cost(1.0, 1.0);
        assert!(stats.restructured > 0 && stats.treelets >= stats.restructured);
        assert!(
            agg < before * 0.97 && agg < after * 1.01,
            "{scene}: {before} -> {agg} ({after})"
        );
        atr.validate(&tris[..]).unwrap();
        let hl = cost(BuildParams {
            refine: Refine::None,
            ..BuildParams::hybrid()
        });
        let hybrid = cost(BuildParams::hybrid());
        assert!(hl < before, "{scene}: hlbvh {hl} lbvh {before}");
        assert!(hybrid < hl, "{scene}: hybrid {hybrid} hlbvh {hl}");
    }
}

/// HLBVH with SAH mini-trees on a multi-scale scene: Morton clusters mix the sphereflake's large
/// and small spheres' triangles, and the pruned mini-trees' parts, regrouped by the top, bring
/// the tree within 3% of the full sweep's SAH cost (9.2% above it with the top over whole
/// clusters, before pruning); on an even scene (the soup), where no cluster stands out, the
/// tree is the one of the top over whole clusters, whose cost is checked against `fast()`.
#[test]
fn pruned_mini_trees_reach_the_full_sweep_on_a_sphereflake() {
    let tris = scene::sphereflake(2, 2).to_soup();
    let cost = |p: BuildParams| Bvh2::build(&tris[..], &p).unwrap().0.sah_cost(1.0, 1.0);
    let (hybrid, sweep) = (cost(BuildParams::hybrid_sah()), cost(BuildParams::quality()));
    assert!(
        hybrid < sweep * 1.03,
        "hybrid_sah {hybrid} against the full sweep's {sweep}"
    );
    let soup = scene::thin_soup(30_000, 4);
    let (tree, stats) = Bvh2::build(&soup[..], &BuildParams::hybrid_sah()).unwrap();
    tree.validate(&soup[..]).unwrap();
    assert_eq!(stats.primitives, 30_000);
    let fast = Bvh2::build(&soup[..], &BuildParams::fast()).unwrap().0;
    assert!(tree.sah_cost(1.0, 1.0) < fast.sah_cost(1.0, 1.0));
}

/// Closest hits through the new trees equal brute force on random rays.
#[test]
fn closest_hits_equal_brute_force() {
    let mut r = Rng::new(21);
    for (scene, tris) in scenes() {
        let b = tris.iter().flatten().fold(strahl::Aabb::EMPTY, |mut b, v| {
            b.grow(*v);
            b
        });
        let rays: Vec<Ray> = (0..300)
            .map(|_| {
                let o = b.centroid() + r.unit_vector() * b.extent().length();
                let t = b.min + b.extent() * Vec3::new(r.f32(), r.f32(), r.f32());
                Ray::new(o, t - o)
            })
            .collect();
        for p in [
            BuildParams::hybrid(),
            BuildParams {
                cluster_size: 8,
                refine: Refine::Treelets(treelets(4, 1, 2)),
                ..BuildParams::hybrid()
            },
            BuildParams {
                refine: Refine::AgglomerativeTreelets(treelets(16, 1, 2)),
                ..BuildParams::fastest()
            },
        ] {
            let (bvh, _) = Bvh2::build(&tris[..], &p).unwrap();
            bvh.validate(&tris[..]).unwrap();
            for ray in &rays {
                let want = intersect_brute_force::<Watertight, _>(&tris[..], ray).map(|h| h.t);
                let got = bvh.intersect::<Watertight, _>(&tris[..], ray).map(|h| h.t);
                assert_eq!(got, want, "{scene}: {ray:?}");
            }
        }
    }
}

/// A reused builder gives the same trees as fresh ones, across scenes of different sizes.
#[test]
fn builder_reuse_is_deterministic() {
    let mut b = Builder::new();
    let mut out = Bvh2::default();
    for (_, tris) in scenes().into_iter().chain([("big", scene::thin_soup(9000, 8))]) {
        for p in [BuildParams::hybrid(), BuildParams::fastest()] {
            let s1 = b.build_into(&tris[..], &p, &mut out).unwrap();
            let (fresh, s2) = Bvh2::build(&tris[..], &p).unwrap();
            assert_eq!((&out, s1), (&fresh, s2));
        }
    }
}

/// The pass errors on malformed trees without touching them, and accepts empty and one-leaf
/// trees.
#[test]
fn treelets_on_malformed_and_tiny_trees() {
    let tris = scene::thin_soup(100, 2);
    let (good, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
    let interior = good.nodes.iter().position(|n| !n.is_leaf()).unwrap();
    let leaf = good.nodes.iter().position(|n| n.is_leaf()).unwrap();
    let mut cases = Vec::new();
    let mut b = good.clone();
    b.nodes[interior].index = 1_000_000;
    cases.push(b);
    let mut b = good.clone();
    b.nodes[leaf].count = 10_000;
    cases.push(b);
    let mut b = good.clone();
    b.nodes[interior + 1].index = 0;
    b.nodes[interior + 1].count = 0;
    cases.push(b);
    for bad in cases {
        for agglomerative in [false, true] {
            let mut t = bad.clone();
            let e = if agglomerative {
                t.optimize_treelets_agglomerative(&TreeletParams::agglomerative(), 64)
            } else {
                t.optimize_treelets(&TreeletParams::default(), 64)
            }
            .unwrap_err();
            assert!(matches!(
                e,
                ValidateError::ChildOutOfRange { .. }
                    | ValidateError::SlotsOutOfRange { .. }
                    | ValidateError::NodeReachedTwice { .. }
            ));
            assert_eq!(t, bad);
        }
    }
    assert_eq!(
        Bvh2::default()
            .optimize_treelets_agglomerative(&TreeletParams::agglomerative(), 64)
            .unwrap()
            .max_depth,
        0
    );
    let mut empty = Bvh2::default();
    assert_eq!(
        empty
            .optimize_treelets(&TreeletParams::default(), 64)
            .unwrap()
            .max_depth,
        0
    );
    let one = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
    let (mut bvh, _) = Bvh2::build(&one[..], &BuildParams::fastest()).unwrap();
    let before = bvh.clone();
    let s = bvh.optimize_treelets(&TreeletParams::default(), 64).unwrap();
    assert_eq!((s.treelets, s.restructured, s.max_depth), (0, 0, 1));
    assert_eq!(bvh, before);
    let s = bvh
        .optimize_treelets_agglomerative(&TreeletParams::agglomerative(), 64)
        .unwrap();
    assert_eq!((s.treelets, s.restructured, s.max_depth), (0, 0, 1));
    assert_eq!(bvh, before);
}

/// Build speed and SAH cost of the new builders beside the presets (not a test: run with
/// `cargo test --release --test build_hybrid -- --ignored --nocapture timing`; `STRAHL_N` sets
/// the soup size, default 2^20).
#[test]
#[ignore]
fn timing() {
    let n: usize = std::env::var("STRAHL_N")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1 << 20);
    let soup = scene::thin_soup(n, 1);
    let bunny = scene::bunny().to_soup();
    let t = |leaves, min_prims, rounds| {
        Refine::Treelets(TreeletParams {
            leaves,
            min_prims,
            rounds,
        })
    };
    let hl = |cluster_size, min_leaf_size, refine| BuildParams {
        strategy: Strategy::Hlbvh,
        cluster_size,
        min_leaf_size,
        max_leaf_size: 4,
        bins: 16,
        refine,
        ..BuildParams::fastest()
    };
    let only = std::env::var("STRAHL_ONLY").ok();
    let list: Vec<(String, BuildParams)> = vec![
        ("fastest".into(), BuildParams::fastest()),
        ("fast".into(), BuildParams::fast()),
        ("balanced".into(), BuildParams::balanced()),
        ("quality".into(), BuildParams::quality()),
        ("hybrid".into(), BuildParams::hybrid()),
        ("hlbvh32".into(), hl(32, 1, Refine::None)),
        ("hlbvh32+t5".into(), hl(32, 1, t(5, 2, 1))),
        ("hlbvh32+t7".into(), hl(32, 1, t(7, 2, 1))),
        ("hlbvh32+t6".into(), hl(32, 1, t(6, 2, 1))),
        (
            "fast+t5g8".into(),
            BuildParams {
                refine: t(5, 8, 1),
                ..BuildParams::fast()
            },
        ),
        (
            "fast+t7g16".into(),
            BuildParams {
                refine: t(7, 16, 1),
                ..BuildParams::fast()
            },
        ),
    ];
    let list: Vec<_> = list
        .into_iter()
        .filter(|(n, _)| only.as_ref().is_none_or(|o| o == n))
        .collect();
    for (scene, tris) in [("soup", &soup), ("bunny", &bunny)] {
        for (name, p) in &list {
            let mut b = Builder::new();
            let mut bvh = Bvh2::default();
            b.build_into(&tris[..], p, &mut bvh).unwrap();
            let reps = if tris.len() > 100_000 { 3 } else { 50 };
            let mut best = f64::INFINITY;
            for _ in 0..reps {
                let t0 = Instant::now();
                b.build_into(&tris[..], p, &mut bvh).unwrap();
                best = best.min(t0.elapsed().as_secs_f64());
            }
            let v = bvh.validate(&tris[..]).unwrap();
            println!(
                "{scene:6} {name:16} {:7.2} Mtri/s {:8.2} ms  SAH {:8.2}  depth {}",
                tris.len() as f64 / best / 1e6,
                best * 1e3,
                bvh.sah_cost(1.0, 1.0),
                v.max_depth
            );
        }
    }
}

#[test]
fn rotations_never_read_slots() {
    // A leaf whose slot range lies out of range: rotations (which only move interior nodes and
    // boxes) treat the tree as the same tree with a good range, in every round, whichever walk a
    // round takes (index order or pre-order); they never stop half-way with an error.
    use strahl::build::{BuildParams, Bvh2, Strategy};
    let soup = strahl::scene::clustered_soup(3000, 5, 1);
    for strategy in [Strategy::BinnedSah, Strategy::Median, Strategy::Lbvh] {
        let (good, _) = Bvh2::build(
            &soup[..],
            &BuildParams {
                strategy,
                ..BuildParams::balanced()
            },
        )
        .unwrap();
        let i = good.nodes.iter().position(|n| n.is_leaf()).unwrap();
        let mut bad = good.clone();
        bad.nodes[i].index = u32::MAX - 1;
        let (mut a, mut b) = (good.clone(), bad.clone());
        let sa = a.optimize_rotations(3, 64).unwrap();
        let sb = b.optimize_rotations(3, 64).unwrap();
        assert_eq!(sa, sb, "{strategy:?}");
        for (k, (x, y)) in a.nodes.iter().zip(&b.nodes).enumerate() {
            if y.index != u32::MAX - 1 {
                assert_eq!(bytemuck::bytes_of(x), bytemuck::bytes_of(y), "{strategy:?} node {k}");
            }
        }
    }
}
