//! The parallel builds (`Builder::build_into_par`, `Bvh2::build_par`): on every scene, thread
//! count and parallel strategy, the tree is the single-threaded build's (the same nodes, boxes and
//! leaves, walked from the root; the same statistics and SAH cost), `validate()` passes, and two
//! runs with the same thread count make the same bytes.

mod common;

use strahl::build::{BuildParams, BuildStats, Builder, Bvh2, MortonBits, Refine, Strategy, TreeletParams};
use strahl::geometry::Triangle;
use strahl::scene::{self, Rng};
use strahl::traverse::{self, Moller};
use strahl::{Ray, Vec3};

/// The strategies that build in parallel, and one with a low depth bound.
fn params() -> Vec<(&'static str, BuildParams)> {
    vec![
        ("fast", BuildParams::fast()),
        ("balanced", BuildParams::balanced()),
        ("high", BuildParams::high()),
        ("median", BuildParams::median()),
        ("hybrid_sah", BuildParams::hybrid_sah()),
        (
            "fast_depth34",
            BuildParams {
                max_depth: 34,
                ..BuildParams::fast()
            },
        ),
    ]
}

/// `Ok` if `a` and `b` are the same tree walked from the root: the same boxes, the same
/// interior/leaf shape and the same primitive indices in every leaf, in order.
fn same_tree(a: &Bvh2, b: &Bvh2) -> Result<(), String> {
    if a.nodes.len() != b.nodes.len() || a.prim_indices.len() != b.prim_indices.len() {
        return Err(format!(
            "sizes: {} / {} nodes, {} / {} indices",
            a.nodes.len(),
            b.nodes.len(),
            a.prim_indices.len(),
            b.prim_indices.len()
        ));
    }
    if a.nodes.is_empty() {
        return Ok(());
    }
    let mut stack = vec![(0usize, 0usize)];
    let mut seen = 0usize;
    while let Some((i, j)) = stack.pop() {
        seen += 1;
        let (x, y) = (a.nodes[i], b.nodes[j]);
        if x.min != y.min || x.max != y.max || x.count != y.count {
            return Err(format!("node {i} / {j}: {x:?} against {y:?}"));
        }
        if x.count == 0 {
            let (l, m) = (x.index as usize, y.index as usize);
            stack.push((l, m));
            stack.push((l + 1, m + 1));
        } else {
            let (s, t) = (x.index as usize, y.index as usize);
            let n = x.count as usize;
            if a.prim_indices[s..s + n] != b.prim_indices[t..t + n] {
                return Err(format!("leaf {i} / {j}: other primitives"));
            }
        }
    }
    if seen != a.nodes.len() {
        return Err(format!("{seen} nodes reached of {}", a.nodes.len()));
    }
    Ok(())
}

fn stats_key(s: &BuildStats) -> [u32; 6] {
    [s.primitives, s.invalid, s.nodes, s.leaves, s.max_depth, s.forced_splits]
}

/// Every parallel strategy and thread count against the single-threaded build of `tris`.
fn check(scene: &str, tris: &[Triangle]) {
    check_with(scene, tris, &params(), &[1, 2, 3, 8], true);
}

/// [`check`] with other parameters and thread counts; `reordered`: the parallel trees must be
/// numbered differently (the parallel path ran; a tree whose top is split in a single round is
/// numbered the same either way).
fn check_with(
    scene: &str,
    tris: &[Triangle],
    params: &[(&str, BuildParams)],
    thread_counts: &[usize],
    reordered: bool,
) {
    let mut builder = Builder::new();
    for &(name, p) in params {
        let (seq, seq_stats) = builder.build(tris, &p).unwrap();
        let seq_sah = seq.sah_cost(1.0, 1.0);
        for &threads in thread_counts {
            let mut par = Bvh2::default();
            let stats = builder.build_into_par(tris, &p, &mut par, threads).unwrap();
            let what = format!("{scene} / {name} / {threads} threads");
            par.validate(tris).unwrap_or_else(|e| panic!("{what}: {e:?}"));
            assert_eq!(stats_key(&stats), stats_key(&seq_stats), "{what}");
            same_tree(&seq, &par).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(par.sah_cost(1.0, 1.0), seq_sah, "{what}");
            assert!(stats.max_depth <= p.max_depth, "{what}");
            // HLBVH-SAH on a multi-scale scene (of these, the clustered soup) lays its tree out
            // by shape alone after building the mini-trees: the same numbering on any number of
            // threads (checked in `sphereflake_with_pruned_mini_trees`).
            let by_shape = p.strategy == Strategy::HlbvhSah && scene == "clustered";
            if threads > 1 && reordered && !by_shape {
                // The parallel path ran: its nodes are numbered differently.
                assert_ne!(par.nodes, seq.nodes, "{what}: built on one thread?");
            }
            // The same bytes again (fresh output, same builder).
            let (again, _) = Bvh2::build_par(tris, &p, threads).unwrap();
            assert!(
                again.nodes == par.nodes && again.prim_indices == par.prim_indices,
                "{what}: not reproducible"
            );
        }
    }
}

#[test]
fn random_and_clustered_soups() {
    check("thin_soup", &scene::thin_soup(40_000, 7));
    check("clustered", &scene::clustered_soup(30_000, 12, 3));
}

/// A multi-scale scene: HLBVH-SAH prunes its mini-trees (built side by side on threads) and
/// lays the tree out by shape, the same tree on any number of threads.
#[test]
fn sphereflake_with_pruned_mini_trees() {
    let tris = scene::sphereflake(2, 2).to_soup();
    let params = [
        ("hybrid_sah", BuildParams::hybrid_sah()),
        // Clusters of one primitive: every mini-tree a leaf, up to `n` parts under the top.
        (
            "hybrid_sah_cluster1",
            BuildParams {
                cluster_size: 1,
                ..BuildParams::hybrid_sah()
            },
        ),
    ];
    check_with("sphereflake", &tris, &params, &[1, 2, 3, 8], false);
    for (name, p) in params {
        let (seq, stats) = Bvh2::build(&tris[..], &p).unwrap();
        // The SAH splits the top wherever the depth bound leaves room: none forced.
        assert_eq!(stats.forced_splits, 0, "{name}");
        for threads in [2, 3] {
            let (par, _) = Bvh2::build_par(&tris[..], &p, threads).unwrap();
            assert!(par.nodes == seq.nodes, "{name}: laid out by shape, numbered the same");
        }
    }
}

#[test]
fn adversarial_scenes() {
    // 70,000 copies of one triangle: every centroid coincides (forced middle splits).
    let t = [
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(0.0, 1.0, 1.0),
    ];
    check("same_triangle", &vec![t; 70_000]);
    // NaN and infinite vertices among valid triangles (excluded, counted), and a far outlier.
    let mut r = Rng::new(4);
    let mut tris: Vec<Triangle> = (0..30_000)
        .map(|i| {
            let p = Vec3::new(r.f32(), r.f32(), r.f32());
            let q = match i % 997 {
                0 => Vec3::NAN,
                1 => Vec3::INFINITY,
                _ => p + r.unit_vector() * 0.01,
            };
            [p, q, p + r.unit_vector() * 0.01]
        })
        .collect();
    tris.push([Vec3::splat(1e7), Vec3::splat(1e7) + Vec3::X, Vec3::splat(1e7) + Vec3::Y]);
    check("nan_inf_outlier", &tris);
    // A geometric series (nested boxes: a chain without the depth bound) beside a random soup.
    let mut tris = scene::thin_soup(20_000, 9);
    tris.extend((0..200).map(|i| {
        let x = 2f32.powf(-(i as f32));
        [Vec3::new(x, 0.0, 0.0), Vec3::new(x, x, 0.0), Vec3::new(x, 0.0, x)]
    }));
    check("geometric_beside_soup", &tris);
}

/// Scenes large enough that the first rounds split each node with all threads (chunks of at least
/// 16,384 references binned and partitioned side by side), the references are prepared in
/// parallel (chunks of at least 32,768 primitives) and the HLBVH's Morton front end runs in
/// parallel (chunks of at least 65,536), with invalid triangles in every chunk, a flat
/// cluster (a node whose centroids coincide inside a wide split's round) and a low depth bound;
/// and the rotation rounds of `high()` run by subtree on the threads.
#[test]
fn large_scenes_split_wide() {
    let mut tris = scene::thin_soup(150_000, 21);
    for (i, t) in tris.iter_mut().enumerate() {
        match i % 4_999 {
            0 => t[1] = Vec3::NAN,
            1 => t[2] = Vec3::NEG_INFINITY,
            _ => {}
        }
    }
    // 40,000 copies of one triangle far off: a subtree whose centroids all coincide.
    let far = [
        Vec3::new(9.0, 9.0, 9.0),
        Vec3::new(9.5, 9.0, 9.0),
        Vec3::new(9.0, 9.5, 9.0),
    ];
    tris.extend(std::iter::repeat_n(far, 40_000));
    let params = [
        ("fast", BuildParams::fast()),
        ("balanced", BuildParams::balanced()),
        // Its Morton codes, scatter and bucket sorts run on the threads too.
        ("hybrid_sah", BuildParams::hybrid_sah()),
        // The bottom-up LBVH: its buckets built side by side, then joined (190,000 references:
        // 2 threads and more take the parallel path).
        ("fastest", BuildParams::fastest()),
        // PLOC: its Morton sort in chunks side by side.
        ("ploc", BuildParams::ploc()),
        (
            "fastest_leaves_3",
            BuildParams {
                min_leaf_size: 3,
                max_leaf_size: 6,
                ..BuildParams::fastest()
            },
        ),
        (
            "hlbvh",
            BuildParams {
                strategy: Strategy::Hlbvh,
                max_leaf_size: 4,
                ..BuildParams::fastest()
            },
        ),
        (
            "binned64_depth40",
            BuildParams {
                bins: 64,
                max_depth: 40,
                ..BuildParams::balanced()
            },
        ),
        (
            "big_leaves",
            BuildParams {
                min_leaf_size: 20_000,
                max_leaf_size: 30_000,
                ..BuildParams::fast()
            },
        ),
        // Rotations by subtree side by side, the second round after the first moved records.
        ("high", BuildParams::high()),
        (
            "high_depth40_2rounds",
            BuildParams {
                max_depth: 40,
                refine: Refine::Rotations(2),
                ..BuildParams::high()
            },
        ),
    ];
    check_with("wide", &tris, &params, &[2, 3, 5, 16], false);
    check_with(
        "wide_clustered",
        &scene::clustered_soup(120_000, 40, 8),
        &params[..2],
        &[4, 16],
        true,
    );
}

/// Sampled binning (`BuildParams::bin_sample`, on in `fast()`) in the wide rounds: the sample's
/// split, the chunks counted and their boxes measured while partitioned, is the sequential
/// loop's; and where the root's sample misses the one far outlier (every sampled reference in one
/// bin), both bin every reference.
#[test]
fn sampled_splits_in_wide_rounds() {
    let tris = common::cube_and_far_outlier(12);
    let params = [
        ("fast", BuildParams::fast()),
        (
            "balanced_sample1024",
            BuildParams {
                bin_sample: 1024,
                ..BuildParams::balanced()
            },
        ),
    ];
    check_with("outlier", &tris, &params, &[2, 4], true);
}

#[test]
fn small_inputs_take_the_single_threaded_path() {
    let mut builder = Builder::new();
    for n in [0usize, 1, 2, 100, 8192] {
        let tris = scene::thin_soup(n, 2);
        for (name, p) in params() {
            let (seq, s) = builder.build(&tris[..], &p).unwrap();
            let mut par = Bvh2::default();
            let t = builder.build_into_par(&tris[..], &p, &mut par, 4).unwrap();
            assert!(
                par.nodes == seq.nodes && par.prim_indices == seq.prim_indices,
                "{n} / {name}"
            );
            assert_eq!(stats_key(&s), stats_key(&t));
        }
    }
}

#[test]
fn parallel_tree_gives_brute_force_hits() {
    let tris = scene::thin_soup(20_000, 5);
    let (bvh, _) = Bvh2::build_par(&tris[..], &BuildParams::fast(), 3).unwrap();
    let mut r = Rng::new(8);
    for _ in 0..300 {
        let o = Vec3::new(r.f32(), r.f32(), r.f32()) * 1.4 - Vec3::splat(0.2);
        let ray = Ray::new(o, r.unit_vector());
        let got = traverse::intersect_scalar::<Moller, _>(bvh.view(), &tris[..], &ray);
        let want = traverse::intersect_brute_force::<Moller, _>(&tris[..], &ray);
        assert_eq!(got.map(|h| h.t), want.map(|h| h.t), "{ray:?}");
    }
}

/// Leaves larger than the parallel build's grain (big tasks become leaves in the split rounds),
/// refinement passes after a parallel build, HLBVH-SAH variants, and unusual thread counts.
#[test]
fn other_parameters_and_thread_counts() {
    let tris = scene::thin_soup(30_000, 11);
    let fast = BuildParams::fast();
    let mut list = Vec::new();
    for (min, max) in [(1, 4097), (1, 20_000), (4097, 5000), (1, 65_536)] {
        list.push((
            "leaf sizes",
            BuildParams {
                min_leaf_size: min,
                max_leaf_size: max,
                // Leaves are cheap: big ones pay.
                intersection_cost: 1e-6,
                ..fast
            },
        ));
    }
    list.push((
        "rotations",
        BuildParams {
            refine: Refine::Rotations(2),
            ..fast
        },
    ));
    list.push((
        "treelets",
        BuildParams {
            refine: Refine::Treelets(TreeletParams::new()),
            ..BuildParams::hybrid_sah()
        },
    ));
    list.push((
        "agglomerative treelets",
        BuildParams {
            refine: Refine::AgglomerativeTreelets(TreeletParams {
                rounds: 3,
                ..TreeletParams::agglomerative()
            }),
            ..fast
        },
    ));
    list.push((
        "treelets after binning",
        BuildParams {
            refine: Refine::Treelets(TreeletParams::new()),
            ..fast
        },
    ));
    for (bits, cluster) in [
        (MortonBits::Bits63, 1),
        (MortonBits::Bits30, 5000),
        (MortonBits::Bits63, 65_536),
    ] {
        list.push((
            "hlbvh_sah",
            BuildParams {
                strategy: Strategy::HlbvhSah,
                morton_bits: bits,
                cluster_size: cluster,
                ..BuildParams::hybrid_sah()
            },
        ));
    }
    for (name, p) in &list {
        assert!(p.check().is_ok(), "{name}: {p:?}");
    }
    check_with("soup30k", &tris, &list, &[2, 17], false);
    // Just above the single-threaded limit, and far more threads than work (or than exist).
    let tris = scene::thin_soup(8193, 4);
    check_with("soup8193", &tris, &params(), &[2, 64, 200, usize::MAX], false);
}

/// Signed zeros: boxes touching 0 from both sides, with -0.0 and +0.0 at positions that put them
/// in different chunks and bin sets of a wide split. The parallel tree's boxes equal the
/// sequential tree's bit for bit (a union keeps whichever equal zero it met first, so the
/// references' bounds carry no -0.0).
#[test]
fn signed_zeros_give_the_same_bits() {
    use strahl::Aabb;
    let mut r = Rng::new(17);
    let mut boxes: Vec<Aabb> = (0..65_536)
        .map(|_| {
            let p = Vec3::new(r.f32(), r.f32(), r.f32());
            Aabb::new(p, p + Vec3::splat(0.01))
        })
        .collect();
    for (i, sign) in [(1, -0.0f32), (32_768, 0.0), (40_001, -0.0), (3, 0.0)] {
        // All four in the same bins: the same box but for the sign of its zeros.
        boxes[i] = Aabb::new(Vec3::new(sign, sign, sign), Vec3::splat(0.01));
    }
    for p in [BuildParams::fast(), BuildParams::balanced()] {
        let (seq, _) = Bvh2::build(&boxes[..], &p).unwrap();
        for threads in [2, 3, 4] {
            let (par, _) = Bvh2::build_par(&boxes[..], &p, threads).unwrap();
            same_tree(&seq, &par).unwrap();
            let bits = |b: &Bvh2| {
                let mut v: Vec<[u32; 6]> = b
                    .nodes
                    .iter()
                    .map(|n| {
                        let (a, c) = (n.min, n.max);
                        [a[0], a[1], a[2], c[0], c[1], c[2]].map(f32::to_bits)
                    })
                    .collect();
                v.sort();
                v
            };
            assert_eq!(bits(&seq), bits(&par), "{threads} threads");
        }
    }
}
