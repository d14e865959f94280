//! Scalar BVH2 traversal on trees the builders do not make: deeper than the stack, read from raw
//! bytes, malformed. Exact against brute force where the tree is valid; never a panic or an
//! endless loop where it is not.

use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::Triangle;
use strahl::scene::{self, Rng};
use strahl::traverse::{
    Bvh2Ref, MAX_DEPTH, Moller, Node, STACK_SIZE, Watertight, intersect_brute_force, intersect_scalar,
    occluded_brute_force, occluded_scalar,
};
use strahl::{Aabb, Ray, Vec3};

/// `n` big triangles stacked at `z = 0 .. n`, in a chain tree: node `2k` is interior with the
/// leaf of triangle `k` on the left and the rest of the chain on the right. Depth `n`.
fn chain(n: usize) -> (Vec<Triangle>, Bvh2) {
    let tris: Vec<Triangle> = (0..n)
        .map(|k| {
            let z = k as f32;
            [
                Vec3::new(-10.0, -10.0, z),
                Vec3::new(10.0, -10.0, z),
                Vec3::new(0.0, 10.0, z),
            ]
        })
        .collect();
    let b = |from: usize| {
        Aabb::new(
            Vec3::new(-10.0, -10.0, from as f32),
            Vec3::new(10.0, 10.0, (n - 1) as f32),
        )
    };
    let mut nodes = Vec::new();
    // Root = chain over 0..n at index 0; chain node over k..n at index 2k; leaf k at 2k + 1.
    for (k, tri) in tris.iter().enumerate().take(n - 1) {
        let left = nodes.len() as u32 + 1;
        nodes.push(Node::interior(&b(k), left));
        // Left child (index 2k + 1) is leaf k; right child (2k + 2) is the chain over k + 1.. .
        let leaf_box = Aabb::from_points(tri);
        nodes.push(Node::leaf(&leaf_box, k as u32, 1));
    }
    nodes.push(Node::leaf(&Aabb::from_points(&tris[n - 1]), (n - 1) as u32, 1));
    let bvh = Bvh2 {
        nodes,
        prim_indices: (0..n as u32).collect(),
    };
    (tris, bvh)
}

#[test]
fn deeper_than_the_stack_is_still_exact() {
    let n = 300;
    let (tris, bvh) = chain(n);
    let stats = bvh.validate(&tris[..]).unwrap();
    assert_eq!(stats.max_depth as usize, n);
    assert!(stats.max_depth > MAX_DEPTH && n > STACK_SIZE);
    let mut rays = vec![
        // From above, looking down: the rest of the chain is always nearer than the leaf, so every
        // level pushes a node and the stack overflows after STACK_SIZE levels.
        Ray::new(Vec3::new(0.0, 0.0, n as f32 + 1.0), -Vec3::Z),
        // From below: leaves are nearer, the stack stays shallow.
        Ray::new(Vec3::new(0.0, 0.0, -1.0), Vec3::Z),
        // Limited range: only deep leaves qualify.
        Ray::with_range(Vec3::new(0.0, 0.0, n as f32 + 1.0), -Vec3::Z, 0.0, 5.5),
        Ray::with_range(Vec3::new(1.0, 1.0, -1.0), Vec3::Z, 250.5, f32::INFINITY),
        Ray::new(Vec3::new(0.0, 0.0, 100.5), Vec3::X),
    ];
    let mut r = Rng::new(1);
    for _ in 0..50 {
        let o = Vec3::new(r.range(-5.0, 5.0), r.range(-5.0, 5.0), r.range(-10.0, n as f32 + 10.0));
        rays.push(Ray::new(o, r.unit_vector()));
    }
    for ray in &rays {
        let want = intersect_brute_force::<Watertight, _>(&tris[..], ray);
        let got = intersect_scalar::<Watertight, _>(bvh.view(), &tris[..], ray);
        assert_eq!(got.map(|h| h.t), want.map(|h| h.t), "{ray:?}");
        assert_eq!(
            occluded_scalar::<Moller, _>(bvh.view(), &tris[..], ray),
            occluded_brute_force::<Moller, _>(&tris[..], ray)
        );
    }
    let top = intersect_scalar::<Watertight, _>(bvh.view(), &tris[..], &rays[0]).unwrap();
    assert_eq!((top.prim, top.t), (n as u32 - 1, 2.0));
}

#[test]
fn view_from_raw_bytes() {
    let mesh = scene::icosphere(3);
    let tris = mesh.as_indexed();
    let (bvh, _) = Bvh2::build(&tris, &BuildParams::default()).unwrap();
    // Store and reload as bytes (say, a file): no copy, no alloc needed to traverse.
    let node_bytes: Vec<u8> = bytemuck::cast_slice(&bvh.nodes).to_vec();
    let idx_bytes: Vec<u8> = bytemuck::cast_slice(&bvh.prim_indices).to_vec();
    // A Vec<u8> need not be 4-byte aligned: read the records unaligned.
    let nodes: Vec<Node> = node_bytes.chunks_exact(32).map(bytemuck::pod_read_unaligned).collect();
    let idx: Vec<u32> = idx_bytes.chunks_exact(4).map(bytemuck::pod_read_unaligned).collect();
    assert_eq!(nodes, bvh.nodes);
    let view = Bvh2Ref::new(&nodes, &idx);
    let mut r = Rng::new(2);
    for _ in 0..200 {
        let ray = Ray::new(r.unit_vector() * 3.0, r.unit_vector());
        assert_eq!(
            intersect_scalar::<Moller, _>(view, &tris, &ray),
            intersect_scalar::<Moller, _>(bvh.view(), &tris, &ray)
        );
    }
}

#[test]
fn malformed_trees_never_panic_or_hang() {
    let tris = scene::thin_soup(64, 3);
    let mut r = Rng::new(4);
    let coord = |r: &mut Rng| match r.u64() % 8 {
        0 => f32::NAN,
        1 => f32::INFINITY,
        2 => f32::NEG_INFINITY,
        _ => r.range(-1.0, 2.0),
    };
    for round in 0..2000 {
        let n = 1 + (r.u64() % 40) as usize;
        let nodes: Vec<Node> = (0..n)
            .map(|_| Node {
                min: [coord(&mut r), coord(&mut r), coord(&mut r)],
                index: match r.u64() % 4 {
                    0 => u32::MAX,
                    1 => (r.u64() % 100) as u32,
                    _ => (r.u64() % n as u64) as u32,
                },
                max: [coord(&mut r), coord(&mut r), coord(&mut r)],
                count: match r.u64() % 3 {
                    0 => 0,
                    1 => u32::MAX,
                    _ => (r.u64() % 5) as u32,
                },
            })
            .collect();
        let idx: Vec<u32> = (0..(r.u64() % 80)).map(|_| (r.u64() % 100) as u32).collect();
        let view = Bvh2Ref::new(&nodes, &idx);
        let ray = Ray::new(
            Vec3::new(r.f32(), r.f32(), -1.0),
            Vec3::new(0.0, 0.0, 1.0) + r.unit_vector() * 0.3,
        );
        let hit = intersect_scalar::<Watertight, _>(view, &tris[..], &ray);
        let _ = occluded_scalar::<Moller, _>(view, &tris[..], &ray);
        if let Some(h) = hit {
            assert!(h.t >= 0.0 && !h.t.is_nan(), "round {round}");
        }
        let mut b = Bvh2 {
            nodes,
            prim_indices: idx,
        };
        let _ = b.validate(&tris[..]);
        let _ = b.refit(&tris[..]);
        let _ = b.sah_cost(1.0, 1.0);
    }
}

#[test]
fn invalid_rays_hit_nothing() {
    let mesh = scene::icosphere(2);
    let tris = mesh.as_indexed();
    let (bvh, _) = Bvh2::build(&tris, &BuildParams::fastest()).unwrap();
    let nan = Vec3::splat(f32::NAN);
    for ray in [
        Ray::new(nan, Vec3::Z),
        Ray::new(Vec3::new(0.0, 0.0, -3.0), nan),
        Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::ZERO),
        Ray::with_range(Vec3::new(0.0, 0.0, -3.0), Vec3::Z, 0.0, f32::NAN),
        Ray::with_range(Vec3::new(0.0, 0.0, -3.0), Vec3::Z, 5.0, 1.0),
    ] {
        assert_eq!(bvh.intersect::<Watertight, _>(&tris, &ray), None, "{ray:?}");
        assert!(!bvh.occluded::<Moller, _>(&tris, &ray), "{ray:?}");
    }
}

#[test]
fn axis_parallel_and_grazing_rays_match_brute_force() {
    // Rays with +-0 direction components along grid lines of a terrain (shared edges, vertices).
    let mesh = scene::terrain(16, 6);
    let tris = mesh.to_soup();
    let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::quality()).unwrap();
    for i in 0..=16 {
        for j in 0..=16 {
            let (x, z) = (i as f32 / 16.0, j as f32 / 16.0);
            for d in [
                Vec3::new(0.0, -1.0, 0.0),
                Vec3::new(-0.0, -1.0, -0.0),
                Vec3::new(1.0, 0.0, 0.0),
            ] {
                let o = if d.y != 0.0 {
                    Vec3::new(x, 1.0, z)
                } else {
                    Vec3::new(-1.0, 0.15, z)
                };
                let ray = Ray::new(o, d);
                let want = intersect_brute_force::<Watertight, _>(&tris[..], &ray);
                let got = intersect_scalar::<Watertight, _>(bvh.view(), &tris[..], &ray);
                assert_eq!(got.map(|h| h.t), want.map(|h| h.t), "{ray:?}");
            }
        }
    }
}

/// 12,000 nested coplanar triangles (one centroid, sizes 0.001 to 12, all in `z = 0`): every ray
/// through the centre ties them all in exact arithmetic, and the watertight test's rounding ranks
/// them by a few ulps, some just before their boxes' entry. Every traversal returns one of the
/// triangles brute force hits (with that triangle's own `t`), within 64 ulps of brute force's `t`
/// (30 measured), and any-hit agrees.
#[test]
fn coplanar_stack_hits_one_of_the_tied_triangles() {
    let tris: Vec<Triangle> = (1..=12_000)
        .map(|i| {
            let s = i as f32 * 0.001;
            [Vec3::new(-s, -s, 0.0), Vec3::new(s, -s, 0.0), Vec3::new(0.0, s, 0.0)]
        })
        .collect();
    let mut rng = Rng::new(3);
    let rays: Vec<Ray> = (0..300)
        .map(|_| {
            let target = Vec3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), 0.0);
            let origin = target + Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), -rng.range(0.5, 2.0));
            Ray::new(origin, target - origin)
        })
        .collect();
    let ulps = |a: f32, b: f32| (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs();
    let (mut apart, mut worst) = (0, 0);
    for p in [BuildParams::median(), BuildParams::default(), BuildParams::fastest()] {
        let (b2, _) = Bvh2::build(&tris[..], &p).unwrap();
        let b8 = strahl::layout::Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
        for r in &rays {
            let bf = intersect_brute_force::<Watertight, _>(&tris[..], r).expect("every ray hits");
            for h in [
                intersect_scalar::<Watertight, _>(b2.view(), &tris[..], r),
                b8.intersect::<Watertight>(r),
            ] {
                let h = h.expect("a traversal missed the stack");
                let own = intersect_brute_force::<Watertight, _>(&tris[h.prim as usize..h.prim as usize + 1], r);
                assert_eq!(own.map(|o| o.t.to_bits()), Some(h.t.to_bits()), "{r:?}");
                worst = worst.max(ulps(h.t, bf.t));
                apart += (h.t != bf.t) as usize;
            }
            assert!(occluded_scalar::<Watertight, _>(b2.view(), &tris[..], r));
        }
    }
    println!(
        "{apart} of {} answers apart from brute force's, at most {worst} ulps",
        2 * 3 * rays.len()
    );
    assert!(worst <= 64, "{worst} ulps");
}
