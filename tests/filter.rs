//! Hit filters (`traverse::HitFilter`): the filtered closest and any hit of BVH2 (scalar
//! reference), BVH4 and BVH8 equal filtered brute force on random, clustered, mesh and
//! adversarial scenes, for filters by primitive, by barycentric (an alpha test), by distance,
//! none and all; malformed packs and filters with state.

mod common;

use common::{mixed_rays, random_soup, same};
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::{Hit, Triangle};
use strahl::layout::{Bvh4, Bvh8, BvhWideRef};
use strahl::scene::{self, Rng};
use strahl::traverse::{
    Moller, TriangleTest, Watertight, intersect_brute_force, intersect_brute_force_filtered,
    occluded_brute_force_filtered, wide,
};
use strahl::{Ray, Vec3};

/// A filter under test (a function of the hit).
type Filter = fn(&Hit) -> bool;

/// The filters under test, by name.
fn filters() -> [(&'static str, Filter); 5] {
    [
        ("even primitives", |h| h.prim % 2 == 0),
        ("alpha stripes in u", |h| (h.u * 7.0).fract() < 0.5),
        ("beyond t = 2", |h| h.t > 2.0),
        ("all", |_| true),
        ("none", |_| false),
    ]
}

fn check_scene<T: TriangleTest>(name: &str, tris: &[Triangle], n_rays: usize) -> usize {
    let rays = mixed_rays(tris, n_rays, 13);
    let mut filtered_out = 0;
    for (pname, params) in [
        ("fastest", BuildParams::fastest()),
        ("fast", BuildParams::fast()),
        ("quality", BuildParams::quality()),
    ] {
        let (b2, _) = Bvh2::build(tris, &params).unwrap();
        let b4 = Bvh4::from_bvh2(&b2, tris).unwrap();
        let b8 = Bvh8::from_bvh2(&b2, tris).unwrap();
        for (fname, f) in filters() {
            let what = format!("{name} / {pname} / {} / {fname}", T::NAME);
            for ray in &rays {
                let want = intersect_brute_force_filtered::<T, _, _>(tris, ray, f);
                if let Some(h) = want {
                    assert!(f(&h), "{what}: brute force returned a rejected hit");
                }
                let got = [
                    b2.intersect_filtered::<T, _>(tris, ray, f),
                    b4.intersect_filtered::<T>(ray, f),
                    b8.intersect_filtered::<T>(ray, f),
                ];
                for (k, g) in got.into_iter().enumerate() {
                    same(g, want, tris, ray, &format!("{what}: tree {k}"));
                    assert!(g.is_none_or(|h| f(&h)), "{what}: tree {k} returned a rejected hit");
                }
                let any = occluded_brute_force_filtered::<T, _, _>(tris, ray, f);
                assert_eq!(any, want.is_some(), "{what}: brute-force any hit");
                assert_eq!(
                    b2.occluded_filtered::<T, _>(tris, ray, f),
                    any,
                    "{what}: BVH2 any hit {ray:?}"
                );
                assert_eq!(b4.occluded_filtered::<T>(ray, f), any, "{what}: BVH4 any hit {ray:?}");
                assert_eq!(b8.occluded_filtered::<T>(ray, f), any, "{what}: BVH8 any hit {ray:?}");
                // Accepting every hit is the unfiltered traversal.
                if fname == "all" {
                    assert_eq!(got[2], b8.intersect::<T>(ray), "{what}");
                    assert_eq!(any, b8.occluded::<T>(ray), "{what}");
                }
                let plain = intersect_brute_force::<T, _>(tris, ray);
                filtered_out += usize::from(plain.is_some() && plain != want);
            }
        }
    }
    filtered_out
}

#[test]
fn filtered_hits_equal_filtered_brute_force() {
    // Each scene must see filters change answers, or the comparison says little.
    let soup = random_soup(2000, 1);
    assert!(check_scene::<Watertight>("random soup", &soup, 300) > 100);
    assert!(check_scene::<Moller>("random soup", &soup, 300) > 100);
    assert!(check_scene::<Watertight>("clustered", &scene::clustered_soup(2000, 5, 2), 300) > 100);
    // A closed mesh: behind a rejected front face lies a back face to find.
    assert!(check_scene::<Watertight>("bunny", &scene::bunny().to_soup(), 300) > 100);
}

#[test]
fn filtered_hits_on_adversarial_scenes() {
    let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
    // Identical triangles: every hit ties, and the filter picks among the tied ones.
    check_scene::<Watertight>("same triangle x 300", &vec![t; 300], 100);
    // Stacked coplanar layers, several per pack.
    let layers: Vec<Triangle> = (0..64)
        .map(|i| t.map(|v| v + Vec3::Z * (i / 4) as f32 * 0.25))
        .collect();
    assert!(check_scene::<Moller>("stacked layers", &layers, 200) > 10);
    // Degenerate, NaN and infinite triangles mixed in.
    let mut bad = random_soup(400, 4);
    bad.push([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]);
    bad.push([Vec3::NAN, Vec3::X, Vec3::Y]);
    bad.push([Vec3::splat(f32::INFINITY), Vec3::X, Vec3::Y]);
    check_scene::<Watertight>("with degenerate and non-finite", &bad, 200);
    // Empty scene, and rays that are not rays.
    let none: Vec<Triangle> = Vec::new();
    let (b2, _) = Bvh2::build(&none[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &none[..]).unwrap();
    let ray = Ray::new(Vec3::ZERO, Vec3::X);
    assert!(
        b8.intersect_filtered::<Watertight>(&ray, |_: &Hit| panic!("offered a hit in an empty scene"))
            .is_none()
    );
    let (b2, _) = Bvh2::build(&[t][..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &[t][..]).unwrap();
    for bad in [
        Ray::new(Vec3::NAN, Vec3::Z),
        Ray::new(Vec3::new(0.2, 0.2, -1.0), Vec3::ZERO),
        Ray::new(Vec3::new(0.2, 0.2, -1.0), Vec3::splat(f32::NAN)),
    ] {
        let never = |_: &Hit| panic!("offered a hit for {bad:?}");
        assert!(b8.intersect_filtered::<Watertight>(&bad, never).is_none());
        assert!(!b8.occluded_filtered::<Watertight>(&bad, never));
        assert!(!b2.occluded_filtered::<Watertight, _>(&[t][..], &bad, never));
    }
}

/// A filter with state sees every candidate it decides on, and nothing rejected comes back; in
/// a pack whose lanes all report the same primitive (a malformed view), rejecting it ends after
/// at most one test per lane.
#[test]
fn stateful_filters_and_malformed_packs() {
    let tris = scene::icosphere(2).to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    // From inside the sphere: exactly one triangle is hit (or two or three at an edge), and a
    // filter that rejects everything is offered each at least once.
    let mut rng = Rng::new(3);
    for _ in 0..200 {
        let ray = Ray::new(Vec3::ZERO, rng.unit_vector());
        let mut offered = Vec::new();
        let hit = b8.intersect_filtered::<Watertight>(&ray, |h: &Hit| {
            offered.push(h.prim);
            false
        });
        assert!(hit.is_none());
        let plain = b8.intersect::<Watertight>(&ray).unwrap();
        assert!(offered.contains(&plain.prim), "{offered:?} lacks {}", plain.prim);
        // Counting calls: accepting the first hit offered takes one call.
        let mut calls = 0;
        let first = b8.intersect_filtered::<Watertight>(&ray, |_: &Hit| {
            calls += 1;
            true
        });
        assert_eq!(first, Some(plain));
        assert!(calls >= 1);
    }
    // Every lane of every pack reports primitive 0.
    let mut packs = b8.packs().to_vec();
    for p in &mut packs {
        p.prim = [0; 8];
    }
    let view = BvhWideRef {
        nodes: b8.nodes(),
        packs: &packs,
    };
    for _ in 0..50 {
        let ray = Ray::new(
            Vec3::new(0.0, 0.0, -3.0),
            Vec3::new(0.1 * rng.f32(), 0.1 * rng.f32(), 1.0),
        );
        let mut calls = 0;
        let hit = wide::intersect_filtered::<Watertight, _, 8, _>(view, &ray, |_: &Hit| {
            calls += 1;
            false
        });
        assert!(hit.is_none());
        assert!(calls >= 1 && calls <= 8 * packs.len(), "{calls} calls");
        assert!(!wide::occluded_filtered::<Watertight, _, 8, _>(
            view,
            &ray,
            |h: &Hit| h.prim != 0
        ));
        // Accepting hits beyond the front of the sphere finds the back.
        let back = wide::intersect_filtered::<Watertight, _, 8, _>(view, &ray, |h: &Hit| h.t > 3.0);
        assert!(back.is_some_and(|h| h.t > 3.5), "{back:?}");
    }
}

/// The incoherent batches with a filter that reads the ray's index answer as one filtered call
/// per ray, on BVH4 and BVH8, for every batch length up to 9 and a long one.
#[test]
fn filtered_incoherent_batches_equal_single_rays() {
    use strahl::traverse::BatchHit;
    let tris = scene::clustered_soup(3000, 5, 2);
    let rays = mixed_rays(&tris, 600, 21);
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let keep = |ray: usize, h: &Hit| !(ray as u32 + h.prim).is_multiple_of(3);
    let mut changed = 0;
    for len in (0..=9).chain([rays.len()]) {
        let rays = &rays[..len];
        let (mut h8, mut h4) = (vec![None; len], vec![None; len]);
        let (mut o8, mut o4) = (vec![false; len], vec![false; len]);
        b8.intersect_batch_incoherent_filtered::<Watertight>(rays, &mut h8, |h: &BatchHit| keep(h.ray, &h.hit));
        b4.intersect_batch_incoherent_filtered::<Watertight>(rays, &mut h4, |h: &BatchHit| keep(h.ray, &h.hit));
        b8.occluded_batch_incoherent_filtered::<Watertight>(rays, &mut o8, |h: &BatchHit| keep(h.ray, &h.hit));
        b4.occluded_batch_incoherent_filtered::<Watertight>(rays, &mut o4, |h: &BatchHit| keep(h.ray, &h.hit));
        for (i, r) in rays.iter().enumerate() {
            let f = |h: &Hit| keep(i, h);
            let want = intersect_brute_force_filtered::<Watertight, _, _>(&tris[..], r, f);
            same(h8[i], want, &tris, r, &format!("batch of {len}, BVH8, ray {i}"));
            same(h4[i], want, &tris, r, &format!("batch of {len}, BVH4, ray {i}"));
            assert_eq!(
                h8[i],
                b8.intersect_filtered::<Watertight>(r, f),
                "batch of {len}, ray {i}"
            );
            assert_eq!(o8[i], want.is_some(), "batch of {len}, BVH8 any hit, ray {i}");
            assert_eq!(o4[i], want.is_some(), "batch of {len}, BVH4 any hit, ray {i}");
            changed += usize::from(want != b8.intersect::<Watertight>(r));
        }
    }
    assert!(changed > 50, "the filter changed {changed} answers");
    // Accepting every hit is the unfiltered batch.
    let (mut a, mut b) = (vec![None; rays.len()], vec![None; rays.len()]);
    b8.intersect_batch_incoherent_filtered::<Watertight>(&rays, &mut a, |_: &BatchHit| true);
    b8.intersect_batch_incoherent::<Watertight>(&rays, &mut b);
    assert_eq!(a, b);
}

/// The fallbacks for malformed views (a cycle: the walks give up after as many visits as there
/// are nodes and scan every pack or primitive) apply the filter too: BVH8 and BVH2 views with a
/// child pointing back at the root answer as filtered brute force.
#[test]
fn filtered_fallbacks_on_malformed_views() {
    use strahl::layout::{Bvh8Ref, EMPTY_CHILD};
    use strahl::traverse::{Bvh2Ref, intersect_scalar_filtered, occluded_scalar_filtered};
    let tris = scene::bunny().to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let rays = mixed_rays(&tris, 150, 17);
    let even = |h: &Hit| h.prim.is_multiple_of(2);
    let n = b8.nodes().len();
    let mut checked = 0;
    for at in [0, n / 2, n - 1] {
        let mut nodes = b8.nodes().to_vec();
        let slot = nodes[at].child.iter().position(|&c| c != EMPTY_CHILD).unwrap_or(0);
        nodes[at].child[slot] = 0;
        let view: Bvh8Ref = BvhWideRef {
            nodes: &nodes,
            packs: b8.packs(),
        };
        for r in &rays {
            let want = intersect_brute_force_filtered::<Watertight, _, _>(&tris[..], r, even);
            let got = wide::intersect_filtered::<Watertight, _, 8, _>(view, r, even);
            same(got, want, &tris, r, &format!("BVH8 cycle at {at}"));
            assert!(got.is_none_or(|h| even(&h)));
            assert_eq!(
                wide::occluded_filtered::<Watertight, _, 8, _>(view, r, even),
                want.is_some()
            );
            checked += 1;
        }
    }
    // A binary interior node whose left child is the root.
    let k = (1..b2.nodes.len()).find(|&k| !b2.nodes[k].is_leaf()).unwrap();
    let mut nodes = b2.nodes.clone();
    nodes[k].index = 0;
    let view = Bvh2Ref::new(&nodes, &b2.prim_indices);
    for r in &rays {
        let want = intersect_brute_force_filtered::<Watertight, _, _>(&tris[..], r, even);
        let got = intersect_scalar_filtered::<Watertight, _, _>(view, &tris[..], r, even);
        same(got, want, &tris, r, "BVH2 cycle");
        assert_eq!(
            occluded_scalar_filtered::<Watertight, _, _>(view, &tris[..], r, even),
            want.is_some()
        );
        checked += 1;
    }
    assert_eq!(checked, 4 * rays.len());
    // Empty scenes: no filter call, no hit, in every tree.
    let none: Vec<Triangle> = Vec::new();
    let (e2, _) = Bvh2::build(&none[..], &BuildParams::default()).unwrap();
    let e4 = Bvh4::from_bvh2(&e2, &none[..]).unwrap();
    let ray = Ray::new(Vec3::ZERO, Vec3::X);
    let never = |_: &Hit| panic!("offered a hit in an empty scene");
    assert!(e2.intersect_filtered::<Watertight, _>(&none[..], &ray, never).is_none());
    assert!(!e2.occluded_filtered::<Watertight, _>(&none[..], &ray, never));
    assert!(e4.intersect_filtered::<Watertight>(&ray, never).is_none());
    assert!(!e4.occluded_filtered::<Watertight>(&ray, never));
}

/// A triangle test of its own (Möller-Trumbore's kernels) that keeps `TriangleTest`'s default
/// `closest_accepted_lanes` (the pack tested again without each rejected lane).
struct OwnTest;

impl TriangleTest for OwnTest {
    const NAME: &'static str = "own";
    const WATERTIGHT: bool = false;
    fn intersect(ray: &strahl::intersect::PreparedRay, tri: &Triangle, prim: u32) -> Option<Hit> {
        Moller::intersect(ray, tri, prim)
    }
    fn intersect_lanes<L: strahl::math::Lane, const N: usize>(
        ray: &strahl::intersect::PreparedRay,
        tris: &strahl::intersect::TriangleLanes<L, N>,
    ) -> Option<Hit> {
        Moller::intersect_lanes(ray, tris)
    }
    fn hit_mask_lanes<L: strahl::math::Lane, const N: usize>(
        ray: &strahl::intersect::PreparedRay,
        tris: &strahl::intersect::TriangleLanes<L, N>,
    ) -> u32 {
        Moller::hit_mask_lanes(ray, tris)
    }
    fn intersect_packet<L: strahl::math::Lane, const N: usize>(
        rays: &mut strahl::intersect::PreparedPacket<L, N>,
        tri: &Triangle,
        prim: u32,
        hits: &mut strahl::intersect::HitLanes<L, N>,
    ) -> u32 {
        Moller::intersect_packet(rays, tri, prim, hits)
    }
}

/// The default leaf test of a filter (the pack tested again) and Möller-Trumbore's own (the lanes
/// computed once) offer the same hits in the same order and answer the same, in packs and
/// through whole trees.
#[test]
fn default_and_compute_once_leaf_tests_agree() {
    use strahl::intersect::{PreparedRay, TriangleX8};
    let mut rng = Rng::new(31);
    // Stacks of triangles along z, some tied, some shared primitives (a malformed pack).
    for round in 0..300 {
        let n = 1 + round % 8;
        let tris: Vec<Triangle> = (0..n)
            .map(|_| {
                let z = (rng.u64() % 4) as f32 + 1.0;
                [
                    Vec3::new(-1.0, -1.0, z),
                    Vec3::new(1.0, -1.0, z),
                    Vec3::new(0.0, 1.0, z),
                ]
            })
            .collect();
        let prims: Vec<u32> = (0..n as u32).map(|i| if round % 5 == 0 { i / 2 } else { i }).collect();
        let pack = TriangleX8::pack(&tris, &prims);
        let ray = PreparedRay::new(&Ray::new(Vec3::new(0.1, -0.2, 0.0), Vec3::Z));
        let reject = rng.u64() as u32;
        let run = |own: bool| {
            let mut offered = Vec::new();
            let f = |h: &Hit| {
                offered.push((h.prim, h.t.to_bits()));
                reject >> (h.prim % 32) & 1 == 0
            };
            let got = if own {
                OwnTest::closest_accepted_lanes(&ray, &pack, f)
            } else {
                Moller::closest_accepted_lanes(&ray, &pack, f)
            };
            (got, offered)
        };
        let (a, b) = (run(true), run(false));
        if round % 5 == 0 {
            // Repeated primitives: the default may drop another lane of the same primitive, so
            // only the answer's validity is compared.
            assert!(a.0.is_none_or(|h| reject >> (h.prim % 32) & 1 == 0), "round {round}");
        } else {
            assert_eq!(a, b, "round {round}");
        }
    }
    // Through trees.
    let tris = random_soup(1500, 8);
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    for (i, r) in mixed_rays(&tris, 300, 3).iter().enumerate() {
        let f = |h: &Hit| (h.u * 5.0).fract() < 0.6;
        assert_eq!(
            b8.intersect_filtered::<OwnTest>(r, f),
            b8.intersect_filtered::<Moller>(r, f),
            "ray {i}"
        );
        assert_eq!(
            b8.occluded_filtered::<OwnTest>(r, f),
            b8.occluded_filtered::<Moller>(r, f),
            "ray {i}"
        );
    }
}
