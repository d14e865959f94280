//! The parallel collapse (`BvhWide::from_bvh2_par`): on every scene and thread count, the same
//! wide tree as `from_bvh2` (walked from the root: the same child boxes, the same shape, the same
//! triangles in every pack, the same depth), and the same bytes on a second run.

mod common;

use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::Triangle;
use strahl::intersect::TriangleLanes;
use strahl::layout::{BvhWide, Collapser, EMPTY_CHILD, LEAF_BIT, leaf_packs};
use strahl::math::{Lane, f32x4, f32x8};
use strahl::scene;
use strahl::traverse::{Moller, Watertight};

/// A pack as plain data: vertex lanes, primitive indices, valid mask.
fn pack_key<L: Lane, const N: usize>(p: &TriangleLanes<L, N>) -> (Vec<u32>, [u32; N], u32) {
    let v =
        p.v.iter()
            .flatten()
            .flat_map(|l| (0..N).map(move |i| l.lane(i)))
            .map(f32::to_bits)
            .collect();
    (v, p.prim, p.valid)
}

/// `Ok` if `a` and `b` are the same tree walked from their roots.
fn same_tree<L: Lane, const N: usize>(a: &BvhWide<L, N>, b: &BvhWide<L, N>) -> Result<(), String> {
    let (an, bn) = (a.nodes(), b.nodes());
    if an.len() != bn.len() || a.packs().len() != b.packs().len() || a.depth() != b.depth() {
        return Err(format!(
            "sizes: {} / {} nodes, {} / {} packs, depth {} / {}",
            an.len(),
            bn.len(),
            a.packs().len(),
            b.packs().len(),
            a.depth(),
            b.depth()
        ));
    }
    if an.is_empty() {
        return Ok(());
    }
    let bits = |l: &L| (0..N).map(|i| l.lane(i).to_bits()).collect::<Vec<u32>>();
    let mut todo = vec![(0usize, 0usize)];
    let mut seen = 0;
    while let Some((i, j)) = todo.pop() {
        seen += 1;
        let (x, y) = (&an[i], &bn[j]);
        for (p, q) in x
            .bounds
            .min
            .iter()
            .chain(&x.bounds.max)
            .zip(y.bounds.min.iter().chain(&y.bounds.max))
        {
            if bits(p) != bits(q) {
                return Err(format!("node {i} / {j}: other child boxes"));
            }
        }
        for (&c, &d) in x.child.iter().zip(&y.child) {
            match (c == EMPTY_CHILD, c & LEAF_BIT != 0, d == EMPTY_CHILD, d & LEAF_BIT != 0) {
                (true, _, true, _) => {}
                (false, true, false, true) => {
                    let ((f, n), (g, m)) = (leaf_packs(c), leaf_packs(d));
                    if n != m || (0..n).any(|k| pack_key(&a.packs()[f + k]) != pack_key(&b.packs()[g + k])) {
                        return Err(format!("node {i} / {j}: other packs"));
                    }
                }
                (false, false, false, false) => todo.push((c as usize, d as usize)),
                _ => return Err(format!("node {i} / {j}: child {c:#x} against {d:#x}")),
            }
        }
    }
    if seen != an.len() {
        return Err(format!("{seen} nodes reached of {}", an.len()));
    }
    Ok(())
}

/// A wide tree as plain data, numbering included: each node's child box bits and child codes,
/// and every pack.
type Raw<const N: usize> = (Vec<(Vec<u32>, [u32; N])>, Vec<(Vec<u32>, [u32; N], u32)>);
fn raw<L: Lane, const N: usize>(w: &BvhWide<L, N>) -> Raw<N> {
    let nodes = w
        .nodes()
        .iter()
        .map(|n| {
            let b = n.bounds.min.iter().chain(&n.bounds.max);
            (
                b.flat_map(|l| (0..N).map(move |i| l.lane(i).to_bits())).collect(),
                n.child,
            )
        })
        .collect();
    (nodes, w.packs().iter().map(pack_key).collect())
}

/// Both widths and several thread counts against the single-threaded collapse of `bvh`.
fn check(name: &str, tris: &[Triangle], bvh: &Bvh2) {
    fn width<L: Lane + Send + Sync, const N: usize>(name: &str, tris: &[Triangle], bvh: &Bvh2) {
        let seq = BvhWide::<L, N>::from_bvh2(bvh, tris).unwrap();
        let rays = common::mixed_rays(tris, 200, 3);
        for threads in [1, 2, 3, 8, 64] {
            let what = format!("{name} / {N}-wide / {threads} threads");
            let par = BvhWide::<L, N>::from_bvh2_par(bvh, tris, threads).unwrap();
            same_tree(&seq, &par).unwrap_or_else(|e| panic!("{what}: {e}"));
            let again = BvhWide::<L, N>::from_bvh2_par(bvh, tris, threads).unwrap();
            assert!(raw(&again) == raw(&par), "{what}: not reproducible");
            for ray in &rays {
                assert_eq!(
                    seq.intersect::<Watertight>(ray),
                    par.intersect::<Watertight>(ray),
                    "{what}"
                );
                assert_eq!(seq.occluded::<Moller>(ray), par.occluded::<Moller>(ray), "{what}");
            }
        }
    }
    width::<f32x8, 8>(name, tris, bvh);
    width::<f32x4, 4>(name, tris, bvh);
}

#[test]
fn same_wide_tree_as_the_single_threaded_collapse() {
    for (name, tris) in [
        ("thin_soup", scene::thin_soup(40_000, 3)),
        ("clustered", scene::clustered_soup(30_000, 9, 2)),
        ("small", scene::thin_soup(5_000, 1)),
    ] {
        for (pname, p) in [("fast", BuildParams::fast()), ("fastest", BuildParams::fastest())] {
            let (bvh, _) = Bvh2::build(&tris[..], &p).unwrap();
            check(&format!("{name} / {pname}"), &tris, &bvh);
            // A parallel build's tree (numbered differently) collapses to the same wide tree.
            let (par, _) = Bvh2::build_par(&tris[..], &p, 2).unwrap();
            let (a, b) = (
                BvhWide::<f32x8, 8>::from_bvh2_par(&bvh, &tris[..], 2).unwrap(),
                BvhWide::<f32x8, 8>::from_bvh2_par(&par, &tris[..], 2).unwrap(),
            );
            same_tree(&a, &b).unwrap_or_else(|e| panic!("{name} / {pname} / parallel build: {e}"));
        }
    }
    // Every triangle the same: forced middle splits down to leaves of 200 (25,600 / 2^7), more
    // than 16 packs, so each gets a wide node of its own.
    let t = [strahl::Vec3::ZERO, strahl::Vec3::X, strahl::Vec3::Y];
    let same = vec![t; 25_600];
    let p = BuildParams {
        max_leaf_size: 200,
        ..BuildParams::fast()
    };
    let (bvh, _) = Bvh2::build(&same[..], &p).unwrap();
    assert!(
        bvh.nodes.iter().any(|n| n.count > 128),
        "leaves of more than 16 packs expected"
    );
    check("same_triangle", &same, &bvh);
}

#[test]
fn the_parallel_path_runs_and_odd_inputs_collapse_alike() {
    let tris = scene::thin_soup(40_000, 6);
    let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::fast()).unwrap();
    let seq = BvhWide::<f32x8, 8>::from_bvh2(&bvh, &tris[..]).unwrap();
    let par = BvhWide::<f32x8, 8>::from_bvh2_par(&bvh, &tris[..], 2).unwrap();
    // Renumbered: the subtrees were made apart.
    assert!(seq.nodes().iter().zip(par.nodes()).any(|(a, b)| a.child != b.child));
    // Thread counts 0 (taken as 1) and usize::MAX (capped).
    for threads in [0, usize::MAX] {
        let w = BvhWide::<f32x8, 8>::from_bvh2_par(&bvh, &tris[..], threads).unwrap();
        same_tree(&seq, &w).unwrap_or_else(|e| panic!("{threads} threads: {e}"));
    }
    // A root that is one leaf of 20,000 triangles (wide nodes over its packs).
    let one_leaf = BuildParams {
        min_leaf_size: 20_000,
        max_leaf_size: 20_000,
        ..BuildParams::fast()
    };
    let few = &tris[..20_000];
    let (leaf, _) = Bvh2::build(few, &one_leaf).unwrap();
    assert_eq!(leaf.nodes.len(), 1);
    let a = BvhWide::<f32x8, 8>::from_bvh2(&leaf, few).unwrap();
    let b = BvhWide::<f32x8, 8>::from_bvh2_par(&leaf, few, 2).unwrap();
    same_tree(&a, &b).unwrap();
}

/// A chain: every interior node has a leaf of `leaf` triangles on the left and the rest of the
/// chain on the right, `depth` interior nodes deep.
fn chain(tris: &[Triangle], depth: usize, leaf: usize) -> Bvh2 {
    let bounds = |r: core::ops::Range<usize>| {
        let mut b = strahl::Aabb::EMPTY;
        for t in &tris[r] {
            for v in t {
                b.grow(*v);
            }
        }
        b
    };
    let node = |b: strahl::Aabb, index: u32, count: u32| strahl::build::Node {
        min: b.min.to_array(),
        index,
        max: b.max.to_array(),
        count,
    };
    let n = tris.len();
    let mut bvh = Bvh2 {
        nodes: vec![node(bounds(0..n), 0, 0)],
        prim_indices: (0..n as u32).collect(),
    };
    let mut at = 0;
    for d in 0..depth {
        let lo = d * leaf;
        let left = bvh.nodes.len() as u32;
        bvh.nodes[at].index = left;
        bvh.nodes.push(node(bounds(lo..lo + leaf), lo as u32, leaf as u32));
        let rest = lo + leaf..n;
        if d + 1 == depth {
            bvh.nodes
                .push(node(bounds(rest.clone()), rest.start as u32, rest.len() as u32));
        } else {
            bvh.nodes.push(node(bounds(rest), 0, 0));
        }
        at = left as usize + 1;
    }
    bvh
}

#[test]
fn errors_are_the_single_threaded_ones() {
    let tris = scene::thin_soup(20_000, 5);
    let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::fast()).unwrap();
    // A leaf pointing past the primitive indices, deep in the tree.
    let k = bvh.nodes.iter().rposition(|n| n.count > 0).unwrap();
    bvh.nodes[k].index = u32::MAX - 4;
    let want = BvhWide::<f32x8, 8>::from_bvh2(&bvh, &tris[..]).unwrap_err();
    for threads in [2, 3] {
        assert_eq!(
            BvhWide::<f32x8, 8>::from_bvh2_par(&bvh, &tris[..], threads).unwrap_err(),
            want
        );
    }
    // Too deep: a chain of 15,000 interior nodes with a one-triangle leaf beside each; then the
    // same chain with a malformed leaf far down.
    let tris = scene::thin_soup(16_000, 2);
    let mut deep = chain(&tris, 15_000, 1);
    for threads in [2, usize::MAX] {
        let want8 = BvhWide::<f32x8, 8>::from_bvh2(&deep, &tris[..]).unwrap_err();
        assert_eq!(
            BvhWide::<f32x8, 8>::from_bvh2_par(&deep, &tris[..], threads).unwrap_err(),
            want8
        );
        let want4 = BvhWide::<f32x4, 4>::from_bvh2(&deep, &tris[..]).unwrap_err();
        assert_eq!(
            BvhWide::<f32x4, 4>::from_bvh2_par(&deep, &tris[..], threads).unwrap_err(),
            want4
        );
    }
    let k = deep.nodes.len() - 2;
    deep.nodes[k].count = 70_000;
    let want = BvhWide::<f32x8, 8>::from_bvh2(&deep, &tris[..]).unwrap_err();
    assert_eq!(
        BvhWide::<f32x8, 8>::from_bvh2_par(&deep, &tris[..], 2).unwrap_err(),
        want
    );
    // A chain of leaves of 300 triangles (more than 16 packs each), shallow enough to collapse.
    let tris = scene::thin_soup(30_000, 8);
    let ok = chain(&tris, 60, 300);
    assert!(ok.validate(&tris[..]).is_ok());
    let a = BvhWide::<f32x8, 8>::from_bvh2(&ok, &tris[..]).unwrap();
    let b = BvhWide::<f32x8, 8>::from_bvh2_par(&ok, &tris[..], 2).unwrap();
    same_tree(&a, &b).unwrap();
}

/// `Collapser::collapse_into` / `collapse_into_par` into one tree, frame after frame, over
/// trees that grow, shrink and fail: each time the bytes of a fresh `from_bvh2` /
/// `from_bvh2_par` (numbering included), the arrays kept where they were large enough, and an
/// empty tree after an error.
#[test]
fn collapser_reuses_memory_and_matches_fresh_collapses() {
    fn width<L: Lane + Send + Sync, const N: usize>() {
        let scenes: Vec<(Vec<Triangle>, Bvh2)> = [40_000, 6_000, 40_000, 60_000, 30_000]
            .into_iter()
            .enumerate()
            .map(|(i, n)| {
                let tris = scene::thin_soup(n, i as u64 + 1);
                let (b, _) = Bvh2::build(&tris[..], &BuildParams::fast()).unwrap();
                (tris, b)
            })
            .collect();
        let mut c = Collapser::new();
        let mut out = BvhWide::<L, N>::from_bvh2(&scenes[0].1, &scenes[0].0[..]).unwrap();
        let mut big_nodes = 0usize;
        for (k, (tris, bvh)) in scenes.iter().enumerate() {
            for threads in [1, 2, 5] {
                let what = format!("{N}-wide, frame {k}, {threads} threads");
                let (before, cap) = (out.nodes().as_ptr(), big_nodes);
                let fits = out.nodes().len() >= BvhWide::<L, N>::from_bvh2(bvh, &tris[..]).unwrap().nodes().len();
                if threads == 1 {
                    c.collapse_into(bvh, &tris[..], &mut out).unwrap();
                    let fresh = BvhWide::<L, N>::from_bvh2(bvh, &tris[..]).unwrap();
                    assert!(raw(&out) == raw(&fresh) && out.depth() == fresh.depth(), "{what}");
                } else {
                    c.collapse_into_par(bvh, &tris[..], &mut out, threads).unwrap();
                    let fresh = BvhWide::<L, N>::from_bvh2_par(bvh, &tris[..], threads).unwrap();
                    assert!(raw(&out) == raw(&fresh) && out.depth() == fresh.depth(), "{what}");
                }
                // A tree that fits in the arrays of a larger one before it stays in them.
                if fits && cap > 0 {
                    assert_eq!(out.nodes().as_ptr(), before, "{what}: reallocated");
                }
                big_nodes = big_nodes.max(out.nodes().len());
            }
        }
        // A malformed tree: an error, and an empty tree (that still traces: no hits).
        let (tris, bvh) = &scenes[1];
        let mut broken = bvh.clone();
        broken.prim_indices[0] = tris.len() as u32;
        assert!(c.collapse_into(&broken, &tris[..], &mut out).is_err());
        assert!(out.nodes().is_empty() && out.packs().is_empty());
        let ray = strahl::Ray::new(strahl::Vec3::splat(-1.0), strahl::Vec3::ONE);
        assert!(out.intersect::<Moller>(&ray).is_none());
        assert!(c.collapse_into_par(&broken, &tris[..], &mut out, 3).is_err());
        assert!(out.nodes().is_empty());
        // And whole again.
        c.collapse_into_par(bvh, &tris[..], &mut out, 3).unwrap();
        assert!(raw(&out) == raw(&BvhWide::<L, N>::from_bvh2_par(bvh, &tris[..], 3).unwrap()));
    }
    width::<f32x8, 8>();
    width::<f32x4, 4>();
}
