//! Spatial splits ([`Bvh2::build_spatial`]; the clipping itself is tested in `src/build/spatial.rs`): the trees are
//! valid (`validate_split`) and answer every query as brute force does, through `Bvh2`, `Bvh4`
//! and `Bvh8`, with and without a hit filter; closed meshes stay closed under the watertight
//! test; the knobs do what they say (reference budget, overlap threshold, node size); bad input
//! and bad parameters get clear answers. Adversarial scenes: `tests/build_adversarial.rs`.

mod common;

use strahl::build::{
    BuildError, BuildParams, Bvh2, Refine, ReinsertParams, SpatialSplits, TreeletParams, ValidateError,
};
use strahl::geometry::{Hit, Triangle};
use strahl::layout::{Bvh4, Bvh8};
use strahl::scene::{self, Rng};
use strahl::traverse::{
    Moller, Watertight, intersect_brute_force, intersect_brute_force_filtered, occluded_brute_force,
    occluded_brute_force_filtered,
};
use strahl::{Aabb, Ray, Vec3};

/// Aggressive knobs: spatial splits wherever they pay, at every node.
const EAGER: SpatialSplits = SpatialSplits {
    alpha: 0.0,
    max_references: 4.0,
    bins: 16,
    min_node_size: 2,
};

/// Scenes where spatial splits pay (long thin and large triangles) and where they hardly do.
fn scenes() -> Vec<(&'static str, Vec<Triangle>)> {
    let mut grid = Vec::new();
    // Axis-aligned quads lying exactly on the planes a 16-bin search of the unit cube tries.
    for i in 0..=16 {
        let x = i as f32 / 16.0;
        grid.push([Vec3::new(x, 0.0, 0.0), Vec3::new(x, 1.0, 0.0), Vec3::new(x, 0.0, 1.0)]);
        grid.push([Vec3::new(x, 1.0, 1.0), Vec3::new(x, 1.0, 0.0), Vec3::new(x, 0.0, 1.0)]);
        grid.push([Vec3::new(0.0, x, 0.0), Vec3::new(1.0, x, 0.0), Vec3::new(0.0, x, 1.0)]);
    }
    // Big triangles crossing a cloud of small ones.
    let mut crossing = common::random_soup(2_000, 9);
    let mut r = Rng::new(4);
    for _ in 0..40 {
        crossing.push([
            Vec3::new(r.f32(), r.f32(), r.f32()) * 10.0,
            Vec3::new(r.f32(), r.f32(), r.f32()) * 10.0,
            Vec3::new(r.f32(), r.f32(), r.f32()) * 10.0,
        ]);
    }
    vec![
        ("thin soup", scene::thin_soup(3_000, 2)),
        ("random soup", common::random_soup(3_000, 3)),
        ("crossing", crossing),
        ("bunny", scene::bunny().to_soup()),
        ("sphereflake", scene::sphereflake(1, 2).to_soup()),
        ("terrain", scene::terrain(40, 3).to_soup()),
        ("grid on planes", grid),
    ]
}

/// Rays for `tris`: [`common::mixed_rays`] (incoherent, limited and bad ones) and rays aimed at
/// vertices and edge midpoints, where a box that cuts a triangle too tightly would show.
fn rays(tris: &[Triangle], seed: u64) -> Vec<Ray> {
    let mut out = common::mixed_rays(tris, 400, seed);
    let (lo, hi) = common::bounds(tris);
    let mut r = Rng::new(seed + 1);
    for i in 0..400 {
        let t = tris[(r.u64() % tris.len() as u64) as usize];
        let target = match i % 3 {
            0 => t[i % 3],
            1 => (t[0] + t[1]) * 0.5,
            _ => (t[1] + t[2]) * 0.5,
        };
        let o = (lo + hi) * 0.5 + r.unit_vector() * (hi - lo).max_element() * 1.5;
        out.push(Ray::new(o, target - o));
    }
    out
}

/// Triangles a leaf of `b` holds more than once (the collapse packs small subtrees whole, and
/// with spatial splits their leaves may share a triangle: it must land in one lane only).
fn repeats_in_a_leaf<L: strahl::math::Lane, const N: usize>(b: &strahl::layout::BvhWide<L, N>) -> usize {
    let mut repeats = 0;
    for code in b.nodes().iter().flat_map(|n| n.child) {
        if code == strahl::layout::EMPTY_CHILD || code & strahl::layout::LEAF_BIT == 0 {
            continue;
        }
        let (first, count) = strahl::layout::leaf_packs(code);
        let mut prims: Vec<u32> = b.packs()[first..first + count]
            .iter()
            .flat_map(|p| (0..N).filter(|&i| p.valid >> i & 1 == 1).map(|i| p.prim[i]))
            .collect();
        let all = prims.len();
        prims.sort_unstable();
        prims.dedup();
        repeats += all - prims.len();
    }
    repeats
}

/// The closest hit, any hit and filtered hits of every tree equal brute force's.
#[test]
fn hits_equal_brute_force() {
    for (name, tris) in scenes() {
        let rays = rays(&tris, 5);
        for (kname, sp) in [("default", SpatialSplits::default()), ("eager", EAGER)] {
            let what = format!("{name}/{kname}");
            let (bvh, stats) = Bvh2::build_spatial(&tris[..], &BuildParams::default(), &sp).unwrap();
            bvh.validate_split(&tris[..]).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(stats.primitives as usize, tris.len(), "{what}");
            let b4 = Bvh4::from_bvh2(&bvh, &tris[..]).unwrap();
            let b8 = Bvh8::from_bvh2(&bvh, &tris[..]).unwrap();
            assert_eq!(repeats_in_a_leaf(&b8), 0, "{what}: BVH8");
            assert_eq!(repeats_in_a_leaf(&b4), 0, "{what}: BVH4");
            let par = Bvh8::from_bvh2_par(&bvh, &tris[..], 3).unwrap();
            assert_eq!(
                (par.packs().len(), repeats_in_a_leaf(&par)),
                (b8.packs().len(), 0),
                "{what}"
            );
            let odd = |h: &Hit| h.prim % 2 == 1;
            for ray in &rays {
                let want = intersect_brute_force::<Watertight, _>(&tris[..], ray);
                common::same(bvh.intersect::<Watertight, _>(&tris[..], ray), want, &tris, ray, &what);
                common::same(b4.intersect::<Watertight>(ray), want, &tris, ray, &what);
                common::same(b8.intersect::<Watertight>(ray), want, &tris, ray, &what);
                // Möller-Trumbore through the same tree: the watertight answers' hits (it may
                // differ from brute force at edges, where its hits can leave the boxes).
                assert_eq!(
                    b8.intersect::<Moller>(ray).is_some(),
                    bvh.intersect::<Moller, _>(&tris[..], ray).is_some()
                );
                let any = occluded_brute_force::<Watertight, _>(&tris[..], ray);
                assert_eq!(bvh.occluded::<Watertight, _>(&tris[..], ray), any, "{what}: {ray:?}");
                assert_eq!(b8.occluded::<Watertight>(ray), any, "{what}: {ray:?}");
                let want_f = intersect_brute_force_filtered::<Watertight, _, _>(&tris[..], ray, odd);
                common::same(b8.intersect_filtered::<Watertight>(ray, odd), want_f, &tris, ray, &what);
                let any_f = occluded_brute_force_filtered::<Watertight, _, _>(&tris[..], ray, odd);
                assert_eq!(b8.occluded_filtered::<Watertight>(ray, odd), any_f, "{what}: {ray:?}");
            }
        }
    }
}

/// Spatial splits happen where they should, cut the SAH cost on long thin triangles, and keep to
/// their budget; with no budget the tree is a plain one.
#[test]
fn knobs_do_what_they_say() {
    let soup = scene::thin_soup(20_000, 1);
    let n = soup.len();
    let p = BuildParams::default();
    let (plain, _) = Bvh2::build(&soup[..], &BuildParams::quality()).unwrap();
    let (sbvh, _) = Bvh2::build_spatial(&soup[..], &p, &SpatialSplits::default()).unwrap();
    let (plain_cost, cost) = (plain.sah_cost(1.0, 1.0), sbvh.sah_cost(1.0, 1.0));
    assert!(cost < 0.95 * plain_cost, "{cost} against the full sweep's {plain_cost}");
    assert!(sbvh.prim_indices.len() > n && sbvh.prim_indices.len() <= n * 3 / 2);
    for budget in [1.1f32, 2.0, 4.0] {
        let sp = SpatialSplits {
            max_references: budget,
            ..EAGER
        };
        let (b, _) = Bvh2::build_spatial(&soup[..], &p, &sp).unwrap();
        let refs = b.prim_indices.len();
        assert!(refs > n && refs <= (n as f32 * budget) as usize, "{budget}: {refs}");
    }
    // No budget: no spatial split, so a tree `validate` accepts as well.
    let none = SpatialSplits {
        max_references: 1.0,
        ..EAGER
    };
    let (b, _) = Bvh2::build_spatial(&soup[..], &p, &none).unwrap();
    assert_eq!(b.prim_indices.len(), n);
    assert!(b.validate(&soup[..]).is_ok());
    // A threshold larger than any overlap, or nodes larger than the scene: none either.
    for sp in [
        SpatialSplits { alpha: 10.0, ..EAGER },
        SpatialSplits {
            min_node_size: n as u32 + 1,
            ..EAGER
        },
    ] {
        let (b, _) = Bvh2::build_spatial(&soup[..], &p, &sp).unwrap();
        assert_eq!(b.prim_indices.len(), n, "{sp:?}");
    }
    // The leaf sizes are honoured.
    let small = BuildParams {
        min_leaf_size: 1,
        max_leaf_size: 3,
        ..p
    };
    let (b, _) = Bvh2::build_spatial(&soup[..], &small, &EAGER).unwrap();
    assert!(b.validate_split(&soup[..]).unwrap().max_leaf_size <= 3);
}

/// A closed cylinder of long thin side triangles (radius 1, height 10, `n` segments) with fan
/// caps, its axis along the diagonal (so that the side triangles' boxes overlap a lot): the kind
/// of mesh spatial splits cut up.
fn cylinder(n: usize) -> Vec<Triangle> {
    let turn = strahl::glam::Quat::from_rotation_arc(Vec3::Y, Vec3::ONE.normalize());
    let ring = |i: usize, y: f32| {
        let a = i as f32 / n as f32 * std::f32::consts::TAU;
        turn * Vec3::new(a.cos(), y, a.sin())
    };
    let mut tris = Vec::new();
    for i in 0..n {
        let (a0, a1, b0, b1) = (ring(i, 0.0), ring(i + 1, 0.0), ring(i, 10.0), ring(i + 1, 10.0));
        tris.push([a0, a1, b1]);
        tris.push([a0, b1, b0]);
        tris.push([Vec3::ZERO, a1, a0]);
        tris.push([turn * Vec3::Y * 10.0, b0, b1]);
    }
    tris
}

/// Rays from inside a closed mesh to its vertices and edge midpoints never escape with the
/// watertight test, through trees whose boxes cut its triangles.
#[test]
fn closed_mesh_stays_closed() {
    let (tris, turn) = (
        cylinder(200),
        strahl::glam::Quat::from_rotation_arc(Vec3::Y, Vec3::ONE.normalize()),
    );
    let (bvh, _) = Bvh2::build_spatial(&tris[..], &BuildParams::default(), &EAGER).unwrap();
    assert!(
        bvh.prim_indices.len() > tris.len() * 5 / 4,
        "{} references",
        bvh.prim_indices.len()
    );
    let b8 = Bvh8::from_bvh2(&bvh, &tris[..]).unwrap();
    let mut rays = 0;
    for t in &tris {
        for target in [
            t[0],
            t[1],
            t[2],
            (t[0] + t[1]) * 0.5,
            (t[1] + t[2]) * 0.5,
            (t[2] + t[0]) * 0.5,
        ] {
            for o in [
                Vec3::new(0.0, 5.0, 0.0),
                Vec3::new(0.1, 0.01, -0.2),
                Vec3::new(-0.3, 9.9, 0.05),
            ] {
                let o = turn * o;
                let ray = Ray::new(o, target - o);
                assert!(b8.intersect::<Watertight>(&ray).is_some(), "{ray:?} escaped");
                assert!(bvh.occluded::<Watertight, _>(&tris[..], &ray), "{ray:?} escaped");
                rays += 1;
            }
        }
    }
    assert!(rays > 10_000);
}

/// Refit makes boxes of whole triangles again: still valid, still brute force's hits.
#[test]
fn refit_after_spatial_build() {
    let mut tris = scene::thin_soup(2_000, 5);
    let (mut bvh, _) = Bvh2::build_spatial(&tris[..], &BuildParams::default(), &EAGER).unwrap();
    let mut r = Rng::new(3);
    for t in tris.iter_mut() {
        let d = r.unit_vector() * 0.01;
        *t = t.map(|v| v + d);
    }
    bvh.refit(&tris[..]).unwrap();
    bvh.validate_split(&tris[..]).unwrap();
    let b8 = Bvh8::from_bvh2(&bvh, &tris[..]).unwrap();
    for ray in rays(&tris, 8) {
        let want = intersect_brute_force::<Watertight, _>(&tris[..], &ray);
        common::same(b8.intersect::<Watertight>(&ray), want, &tris, &ray, "refit");
    }
}

/// Empty, all-invalid and one-triangle scenes; bad parameters; trees `validate_split` rejects.
#[test]
fn bad_input_and_parameters() {
    let p = BuildParams::default();
    let sp = SpatialSplits::default();
    let none: [Triangle; 0] = [];
    let (b, s) = Bvh2::build_spatial(&none[..], &p, &sp).unwrap();
    assert!(b.is_empty() && s.primitives == 0 && b.validate_split(&none[..]).is_ok());
    let bad = [[Vec3::NAN, Vec3::X, Vec3::Y], [Vec3::ZERO, Vec3::INFINITY, Vec3::Y]];
    let (b, s) = Bvh2::build_spatial(&bad[..], &p, &sp).unwrap();
    assert!(b.is_empty() && (s.primitives, s.invalid) == (0, 2));
    let one = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
    let (b, s) = Bvh2::build_spatial(&one[..], &p, &EAGER).unwrap();
    assert_eq!(
        (b.nodes.len(), b.prim_indices.as_slice(), s.leaves),
        (1, &[0u32][..], 1)
    );
    let ray = Ray::new(Vec3::new(0.2, 0.2, -1.0), Vec3::Z);
    assert_eq!(b.intersect::<Watertight, _>(&one[..], &ray).map(|h| h.prim), Some(0));
    for wrong in [
        SpatialSplits { alpha: -1.0, ..sp },
        SpatialSplits {
            alpha: f32::INFINITY,
            ..sp
        },
        SpatialSplits {
            max_references: 0.99,
            ..sp
        },
        SpatialSplits {
            max_references: f32::NAN,
            ..sp
        },
        SpatialSplits {
            max_references: 17.0,
            ..sp
        },
        SpatialSplits { bins: 3, ..sp },
        SpatialSplits { bins: 65, ..sp },
        SpatialSplits { min_node_size: 1, ..sp },
    ] {
        assert!(
            matches!(
                Bvh2::build_spatial(&one[..], &p, &wrong),
                Err(BuildError::InvalidParams(_))
            ),
            "{wrong:?}"
        );
    }
    let wrong = BuildParams { bins: 1, ..p };
    assert!(matches!(
        Bvh2::build_spatial(&one[..], &wrong, &sp),
        Err(BuildError::InvalidParams(_))
    ));
    // `validate_split` still names what breaks: a triangle twice in one leaf, one missing, a leaf
    // box that misses its triangle.
    let soup = scene::thin_soup(300, 2);
    let (good, _) = Bvh2::build_spatial(&soup[..], &p, &EAGER).unwrap();
    let leaf = good.nodes.iter().position(|n| n.is_leaf() && n.count >= 2).unwrap();
    let slots = good.nodes[leaf].prim_range();
    let mut twice = good.clone();
    twice.prim_indices[slots.start + 1] = twice.prim_indices[slots.start];
    assert!(matches!(
        twice.validate_split(&soup[..]),
        Err(ValidateError::PrimReferencedTwice { .. } | ValidateError::PrimMissing { .. })
    ));
    let mut moved = good.clone();
    let far = Aabb::new(Vec3::splat(100.0), Vec3::splat(101.0));
    moved.nodes[leaf].set_aabb(&far);
    assert!(moved.validate_split(&soup[..]).is_err());
}

/// The refinement passes work on node boxes alone, so they take spatial-split trees as they are:
/// still valid, never a higher SAH cost, still brute force's hits.
#[test]
fn refinement_after_spatial_build() {
    let tris = scene::thin_soup(3_000, 6);
    let rays = rays(&tris, 9);
    let (base, _) = Bvh2::build_spatial(&tris[..], &BuildParams::default(), &EAGER).unwrap();
    let before = base.sah_cost(1.0, 1.0);
    type Pass = fn(&mut Bvh2) -> bool;
    let passes: [(&str, Pass); 3] = [
        ("rotations", |b| b.optimize_rotations(2, 64).is_ok()),
        ("reinsertion", |b| {
            b.optimize_reinsertion(&strahl::build::ReinsertParams::new(), 64)
                .is_ok()
        }),
        ("treelets", |b| {
            b.optimize_treelets(&strahl::build::TreeletParams::new(), 64).is_ok()
        }),
    ];
    for (name, pass) in passes {
        let mut b = base.clone();
        assert!(pass(&mut b), "{name}");
        b.validate_split(&tris[..]).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(b.prim_indices.len(), base.prim_indices.len(), "{name}");
        let after = b.sah_cost(1.0, 1.0);
        assert!(after <= before * (1.0 + 1e-5), "{name}: {before} -> {after}");
        let b8 = Bvh8::from_bvh2(&b, &tris[..]).unwrap();
        for ray in &rays {
            let want = intersect_brute_force::<Watertight, _>(&tris[..], ray);
            common::same(b8.intersect::<Watertight>(ray), want, &tris, ray, name);
        }
    }
}

/// Two valid triangles far out (the root's area overflows `f32`) do not turn spatial splits off;
/// `clip_triangle` gives both sides the whole box where a crossing overflows or the plane is NaN.
#[test]
fn far_triangles_and_overflowing_clips() {
    let mut soup = scene::thin_soup(5_000, 1);
    let n = soup.len();
    let (near, _) = Bvh2::build_spatial(&soup[..], &BuildParams::default(), &EAGER).unwrap();
    soup.push([
        Vec3::splat(1e38),
        Vec3::splat(1e38) + Vec3::X,
        Vec3::splat(1e38) + Vec3::Y,
    ]);
    soup.push([
        Vec3::splat(-1e38),
        Vec3::splat(-1e38) + Vec3::X,
        Vec3::splat(-1e38) + Vec3::Y,
    ]);
    let (far, _) = Bvh2::build_spatial(&soup[..], &BuildParams::default(), &EAGER).unwrap();
    assert!(
        near.prim_indices.len() > n && far.prim_indices.len() > n + 2,
        "{}",
        far.prim_indices.len()
    );
    far.validate_split(&soup[..]).unwrap();
    let t = [
        Vec3::new(0.0, -3e38, 0.0),
        Vec3::new(4.0, 3e38, 0.0),
        Vec3::new(0.0, 3e38, 1.0),
    ];
    let within = Aabb::from_points(&t);
    for pos in [1.0, f32::NAN] {
        let (l, r) = strahl::build::clip_triangle(&t, &within, 0, pos);
        assert!(l == within && r == within, "{pos}: {l:?} {r:?}");
    }
}

/// A balanced tree whose leaves have `boxes` and each reference triangle 0.
fn balanced_tree(boxes: &[Aabb]) -> Bvh2 {
    use strahl::build::Node;
    let mut nodes = vec![Node::leaf(&Aabb::EMPTY, 0, 1)];
    // (slot, boxes' range): a node, then its two children adjacent.
    let mut todo = vec![(0usize, 0usize, boxes.len())];
    while let Some((at, lo, hi)) = todo.pop() {
        let b = boxes[lo..hi].iter().fold(Aabb::EMPTY, |a, x| a.union(x));
        if hi - lo == 1 {
            nodes[at] = Node::leaf(&b, lo as u32, 1);
            continue;
        }
        let l = nodes.len();
        nodes.extend([Node::leaf(&b, 0, 1); 2]);
        nodes[at] = Node::interior(&b, l as u32);
        let mid = (lo + hi) / 2;
        todo.extend([(l, lo, mid), (l + 1, mid, hi)]);
    }
    Bvh2 {
        nodes,
        prim_indices: vec![0; boxes.len()],
    }
}

/// `validate_split` checks that the leaves' boxes cover all of each triangle, not only its
/// corners: two leaves holding a triangle's ends but not a strip across its middle fail, boxes
/// meeting exactly (or overlapping) pass, and one f32 ulp of gap fails.
#[test]
fn validate_split_sees_a_gap_inside_a_triangle() {
    use strahl::build::Node;
    let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
    let tree = |right_min_x: f32| {
        let left = Aabb::new(Vec3::ZERO, Vec3::new(0.4, 1.0, 0.0));
        let right = Aabb::new(Vec3::new(right_min_x, 0.0, 0.0), Vec3::new(1.0, 0.6, 0.0));
        let root = left.union(&right);
        Bvh2 {
            nodes: vec![
                Node::interior(&root, 1),
                Node::leaf(&left, 0, 1),
                Node::leaf(&right, 1, 1),
            ],
            prim_indices: vec![0, 0],
        }
    };
    // Every vertex lies in a box; the strip 0.4 < x < 0.6 in none.
    assert_eq!(
        tree(0.6).validate_split(&tris[..]).unwrap_err(),
        ValidateError::PrimNotCovered { prim: 0 }
    );
    assert_eq!(
        tree(0.4f32.next_up()).validate_split(&tris[..]).unwrap_err(),
        ValidateError::PrimNotCovered { prim: 0 }
    );
    assert_eq!(tree(0.4).validate_split(&tris[..]).unwrap().primitives, 1);
    assert_eq!(tree(0.3).validate_split(&tris[..]).unwrap().primitives, 1);
    // A left box reaching far away (to -1e30) does not hide the strip: the tolerance is the
    // triangle's own scale.
    let mut far = tree(0.6);
    let wide = Aabb::new(Vec3::splat(-1e30), Vec3::new(0.4, 1.0, 0.0));
    far.nodes[1] = Node::leaf(&wide, 0, 1);
    far.nodes[0] = Node::interior(&wide.union(&far.nodes[2].aabb()), 1);
    assert_eq!(
        far.validate_split(&tris[..]).unwrap_err(),
        ValidateError::PrimNotCovered { prim: 0 }
    );
    // Nor do many boxes that touch the triangle's box but not the triangle: 500 strips covering
    // half of each band of y, then 2,000 leaves in the corner x, y > 0.9 (they used to cut the
    // gaps into pieces until the check gave up and passed).
    let mut boxes = Vec::new();
    for i in 0..500 {
        let y0 = i as f32 / 500.0;
        boxes.push(Aabb::new(Vec3::new(0.0, y0, 0.0), Vec3::new(1.0, y0 + 0.001, 0.0)));
    }
    boxes.push(Aabb::new(Vec3::new(0.0, 0.99, 0.0), Vec3::new(0.01, 1.0, 0.0))); // vertex 2
    boxes.extend([Aabb::new(Vec3::new(0.9, 0.9, 0.0), Vec3::new(1.0, 1.0, 0.0)); 2_000]);
    assert_eq!(
        balanced_tree(&boxes).validate_split(&tris[..]).unwrap_err(),
        ValidateError::PrimNotCovered { prim: 0 }
    );
    // A triangle cut into 6,000 strips in shuffled order, all covered, passes.
    let mut bands: Vec<usize> = (0..6_000).collect();
    let mut r = Rng::new(1);
    for i in (1..bands.len()).rev() {
        bands.swap(i, (r.u64() % (i as u64 + 1)) as usize);
    }
    let strips: Vec<Aabb> = bands
        .iter()
        .map(|&i| {
            let (y0, y1) = (i as f32 / 6_000.0, (i + 1) as f32 / 6_000.0);
            Aabb::new(Vec3::new(0.0, y0, 0.0), Vec3::new(1.0, y1, 0.0))
        })
        .collect();
    assert_eq!(balanced_tree(&strips).validate_split(&tris[..]).unwrap().primitives, 1);
    // A right box one ulp too low in y misses the triangle's sliver above it near x = 0.4.
    let mut t = tree(0.4);
    let short = Aabb::new(Vec3::new(0.4, 0.0, 0.0), Vec3::new(1.0, 0.6f32.next_down(), 0.0));
    t.nodes[2] = Node::leaf(&short, 1, 1);
    assert_eq!(
        t.validate_split(&tris[..]).unwrap_err(),
        ValidateError::PrimNotCovered { prim: 0 }
    );
}

/// A tree in pre-order from the root (left before right), whatever its numbering: each node's
/// box, and each leaf's primitives in order.
fn canonical(b: &Bvh2) -> Vec<(Aabb, Option<Vec<u32>>)> {
    let mut out = Vec::new();
    let mut stack = if b.nodes.is_empty() { vec![] } else { vec![0u32] };
    while let Some(i) = stack.pop() {
        let n = &b.nodes[i as usize];
        if n.is_leaf() {
            out.push((n.aabb(), Some(b.prim_indices[n.prim_range()].to_vec())));
        } else {
            out.push((n.aabb(), None));
            stack.push(n.left() + 1);
            stack.push(n.left());
        }
    }
    out
}

/// `build_spatial_par` builds the sequential build's tree (equal nodes and slots, so the same
/// tree in pre-order) on any thread count, with the same statistics, also with each refinement
/// pass after it (reinsertion depends on the numbering) and with forced splits (a deep series
/// under a depth bound); bad input, bad knobs and absurd thread counts get the same answers.
#[test]
fn parallel_build_is_the_same_tree() {
    let mut big = scene::thin_soup(30_000, 4);
    big.extend(scene::sphereflake(2, 3).to_soup());
    big.push([Vec3::ZERO, Vec3::X, Vec3::NAN]); // left out, counted
    let mut deep = scene::thin_soup(12_000, 5);
    deep.extend((0..120).map(|i| {
        let x = 0.5f32.powi(i);
        [Vec3::new(x, 0.0, 0.0), Vec3::new(x, x, 0.0), Vec3::new(x, 0.0, x)]
    }));
    let mut list = scenes();
    list.push(("thin soup and sphereflake", big));
    list.push(("empty", vec![]));
    list.push(("one", vec![[Vec3::ZERO, Vec3::X, Vec3::Y]]));
    let base = BuildParams::default();
    let mut cases: Vec<(String, Vec<Triangle>, BuildParams)> =
        list.into_iter().map(|(n, t)| (n.to_string(), t, base)).collect();
    let refined = [
        ("rotations", Refine::Rotations(2)),
        ("treelets", Refine::Treelets(TreeletParams::new())),
        (
            "agglomerative",
            Refine::AgglomerativeTreelets(TreeletParams::agglomerative()),
        ),
        ("reinsertion", Refine::Reinsertion(ReinsertParams::new())),
    ];
    for (name, refine) in refined {
        let p = BuildParams {
            refine,
            max_depth: 34,
            ..base
        };
        cases.push((format!("deep/{name}"), deep.clone(), p));
    }
    for (name, tris, p) in cases {
        for (kname, sp) in [("default", SpatialSplits::default()), ("eager", EAGER)] {
            let what = format!("{name}/{kname}");
            let (one, s1) = Bvh2::build_spatial(&tris[..], &p, &sp).unwrap();
            let want = canonical(&one);
            if name.starts_with("deep") {
                assert!(s1.forced_splits > 0, "{what}: no forced split");
            }
            for threads in [0, 1, 2, 3, 8, usize::MAX] {
                let (par, sp_stats) = Bvh2::build_spatial_par(&tris[..], &p, &sp, threads).unwrap();
                if !tris.is_empty() {
                    par.validate_split(&tris[..])
                        .unwrap_or_else(|e| panic!("{what} x{threads}: {e}"));
                }
                assert!(canonical(&par) == want, "{what} x{threads}: another tree");
                assert!(par == one, "{what} x{threads}: numbered differently");
                assert_eq!(sp_stats, s1, "{what} x{threads}");
            }
        }
    }
    let bad = SpatialSplits {
        bins: 1,
        ..SpatialSplits::default()
    };
    let tris = scene::thin_soup(100, 1);
    assert!(matches!(
        Bvh2::build_spatial_par(&tris[..], &BuildParams::default(), &bad, 2),
        Err(BuildError::InvalidParams(_))
    ));
}
