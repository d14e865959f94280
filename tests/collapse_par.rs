//! The parallel collapse (`BvhWide::from_bvh2_par`): on every scene and thread count, the same
//! wide tree as `from_bvh2` (walked from the root: the same child boxes, the same shape, the same
//! triangles in every pack, the same depth), and the same bytes on a second run.

mod common;

use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::Triangle;
use strahl::intersect::TriangleLanes;
use strahl::layout::{BvhWide, EMPTY_CHILD, LEAF_BIT, leaf_packs};
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
            let raw = |w: &BvhWide<L, N>| {
                let nodes: Vec<(Vec<u32>, [u32; N])> = w
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
                (nodes, w.packs().iter().map(pack_key).collect::<Vec<_>>())
            };
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
    // Every triangle the same: big leaves (more than 16 packs get a node of their own).
    let t = [strahl::Vec3::ZERO, strahl::Vec3::X, strahl::Vec3::Y];
    let same = vec![t; 20_000];
    let (bvh, _) = Bvh2::build(
        &same[..],
        &BuildParams {
            max_leaf_size: 64,
            ..BuildParams::fast()
        },
    )
    .unwrap();
    check("same_triangle", &same, &bvh);
}

#[test]
fn malformed_trees_are_errors_in_parallel_too() {
    let tris = scene::thin_soup(20_000, 5);
    let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::fast()).unwrap();
    // A leaf pointing past the primitive indices, deep in the tree.
    let k = bvh.nodes.iter().rposition(|n| n.count > 0).unwrap();
    bvh.nodes[k].index = u32::MAX - 4;
    assert!(BvhWide::<f32x8, 8>::from_bvh2_par(&bvh, &tris[..], 2).is_err());
    assert!(BvhWide::<f32x8, 8>::from_bvh2(&bvh, &tris[..]).is_err());
}
