//! BVH2, BVH4, BVH8 and brute force give the same closest hits (same `t`; the same primitive
//! unless two triangles tie at that `t`) and the same any-hit answers, for every builder, on
//! random, clustered and adversarial scenes, with NaN rays, zero direction components and -0.0.

mod common;

use common::{mixed_rays as rays, random_soup, same};
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::{Hit, Triangle};
use strahl::intersect::PreparedRay;
use strahl::layout::{Bvh4, Bvh8};
use strahl::scene::{self, Rng};
use strahl::traverse::{Fast, Moller, TriangleTest, Watertight, intersect_brute_force, occluded_brute_force, wide};
use strahl::{Ray, Vec3};

fn check_scene<T: TriangleTest>(name: &str, tris: &[Triangle], n_rays: usize) {
    let rays = rays(tris, n_rays, 7);
    for (pname, params) in [
        ("fastest", BuildParams::fastest()),
        ("fast", BuildParams::fast()),
        ("quality", BuildParams::quality()),
        ("median", BuildParams::median()),
    ] {
        let (b2, _) = Bvh2::build(tris, &params).unwrap();
        let b4 = Bvh4::from_bvh2(&b2, tris).unwrap();
        let b8 = Bvh8::from_bvh2(&b2, tris).unwrap();
        // `Fast<T>`: every answer a real hit, never closer than brute force's; misses (of hits
        // on boxes a ray grazes) counted and bounded.
        let mut fast_misses = [0usize; 6];
        for ray in &rays {
            let what = format!("{name} / {pname} / {}", T::NAME);
            let brute = intersect_brute_force::<T, _>(tris, ray);
            let fast = [
                b2.intersect::<Fast<T>, _>(tris, ray),
                b4.intersect::<Fast<T>>(ray),
                b8.intersect::<Fast<T>>(ray),
            ];
            let prepared = PreparedRay::new_for(ray, T::WATERTIGHT);
            for (k, f) in fast.into_iter().enumerate() {
                match (f, brute) {
                    (Some(h), Some(b)) => {
                        assert!(h.t >= b.t, "{what}: fast tree {k} found {h:?} before {b:?}");
                        let tri = tris[h.prim as usize];
                        assert_eq!(T::intersect(&prepared, &tri, h.prim), Some(h), "{what}: fast tree {k}");
                        fast_misses[k] += usize::from(h.t != b.t);
                    }
                    (None, Some(_)) => fast_misses[k] += 1,
                    (Some(h), None) => panic!("{what}: fast tree {k} hit {h:?}, brute force nothing"),
                    (None, None) => {}
                }
            }
            let any = occluded_brute_force::<T, _>(tris, ray);
            for (k, f) in [
                b2.occluded::<Fast<T>, _>(tris, ray),
                b4.occluded::<Fast<T>>(ray),
                b8.occluded::<Fast<T>>(ray),
            ]
            .into_iter()
            .enumerate()
            {
                assert!(!f || any, "{what}: fast tree {k} occluded, brute force not");
                fast_misses[3 + k] += usize::from(f != any);
            }
            let h2 = b2.intersect::<T, _>(tris, ray);
            same(h2, brute, tris, ray, &format!("{what}: bvh2 vs brute"));
            same(
                b4.intersect::<T>(ray),
                brute,
                tris,
                ray,
                &format!("{what}: bvh4 vs brute"),
            );
            same(
                b8.intersect::<T>(ray),
                brute,
                tris,
                ray,
                &format!("{what}: bvh8 vs brute"),
            );
            let any = occluded_brute_force::<T, _>(tris, ray);
            assert_eq!(b4.occluded::<T>(ray), any, "{what}: bvh4 occluded {ray:?}");
            assert_eq!(b8.occluded::<T>(ray), any, "{what}: bvh8 occluded {ray:?}");
        }
        assert!(
            fast_misses.iter().all(|&m| m <= rays.len() / 100 + 1),
            "{name} / {pname} / {}: fast-slab misses {fast_misses:?} of {} rays",
            T::NAME,
            rays.len()
        );
        // The incoherent batches (closest hits as two walks interleaved, each refilled as it
        // ends; any hits one walk at a time), at every
        // short length and the whole set, with an output shorter than the rays (the rest
        // untouched): the single-ray answers (checked against brute force above), bit for bit.
        let want: Vec<bool> = rays.iter().map(|r| occluded_brute_force::<T, _>(tris, r)).collect();
        let want_hits: Vec<_> = rays.iter().map(|r| b8.intersect::<T>(r)).collect();
        let want_hits4: Vec<_> = rays.iter().map(|r| b4.intersect::<T>(r)).collect();
        for len in [0, 1, 2, 3, 4, 5, rays.len()] {
            let len = len.min(rays.len());
            let what = format!("{name} / {pname} / {}: batch of {len}", T::NAME);
            let mut o4 = vec![false; len];
            let mut o8 = vec![true; len + 1];
            b4.occluded_batch_incoherent::<T>(&rays[..len], &mut o4);
            b8.occluded_batch_incoherent::<T>(&rays, &mut o8[..len]);
            assert_eq!(o4, want[..len], "{what}: bvh4 occluded");
            assert_eq!(o8[..len], want[..len], "{what}: bvh8 occluded");
            assert!(o8[len], "{what}: occluded wrote past its output");
            let mut h4 = vec![None; len];
            let sentinel = b8
                .intersect::<T>(&rays[0])
                .or(want_hits.iter().flatten().next().copied());
            let mut h8 = vec![sentinel; len + 1];
            b4.intersect_batch_incoherent::<T>(&rays[..len], &mut h4);
            b8.intersect_batch_incoherent::<T>(&rays, &mut h8[..len]);
            assert_eq!(h4, want_hits4[..len], "{what}: bvh4 intersect");
            assert_eq!(h8[..len], want_hits[..len], "{what}: bvh8 intersect");
            assert_eq!(h8[len], sentinel, "{what}: intersect wrote past its output");
            // Reordered by origin (the answers land in the rays' own slots).
            let mut o8 = vec![true; len + 1];
            b8.occluded_batch_reordered::<T>(&rays, &mut o8[..len]);
            assert_eq!(o8[..len], want[..len], "{what}: bvh8 occluded, reordered");
            assert!(o8[len], "{what}: reordered occluded wrote past its output");
            let mut h4 = vec![sentinel; len];
            b4.intersect_batch_reordered::<T>(&rays[..len], &mut h4);
            assert_eq!(h4, want_hits4[..len], "{what}: bvh4 intersect, reordered");
        }
        // Any order: reversed, with repeats and indices out of range (skipped); slots the order
        // does not name keep their value.
        let n = rays.len();
        let mut order: Vec<u32> = (0..n as u32).rev().filter(|i| i % 3 != 1).collect();
        order.extend([0, 0, n as u32, u32::MAX, 2]);
        let what = format!("{name} / {pname} / {}: ordered", T::NAME);
        let mut o8 = vec![true; n];
        wide::occluded_batch_ordered::<T, _, 8>(b8.view(), &rays, &order, &mut o8);
        // A hit as the sentinel: writing a miss into a slot not named would show.
        let sentinel = want_hits.iter().flatten().next().copied().or(Some(Hit {
            t: 1.0,
            u: 0.0,
            v: 0.0,
            prim: 0,
        }));
        let mut h8 = vec![sentinel; n];
        wide::intersect_batch_ordered::<T, _, 8>(b8.view(), &rays, &order, &mut h8);
        for i in 0..n {
            let named = i % 3 != 1;
            assert_eq!(o8[i], if named { want[i] } else { true }, "{what}: occluded {i}");
            assert_eq!(
                h8[i],
                if named { want_hits[i] } else { sentinel },
                "{what}: intersect {i}"
            );
        }
    }
}

#[test]
fn random_scenes() {
    let tris = random_soup(3000, 1);
    check_scene::<Watertight>("random soup", &tris, 600);
    check_scene::<Moller>("random soup", &tris, 600);
    check_scene::<Watertight>("thin soup", &scene::thin_soup(2000, 3), 400);
}

#[test]
fn clustered_and_mesh_scenes() {
    check_scene::<Watertight>("clustered", &scene::clustered_soup(3000, 5, 2), 500);
    check_scene::<Watertight>("bunny", &scene::bunny().to_soup(), 500);
    check_scene::<Moller>("icosphere", &scene::icosphere(3).to_soup(), 300);
}

#[test]
fn adversarial_scenes() {
    let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
    // Identical triangles: every hit ties.
    check_scene::<Watertight>("same triangle x 500", &vec![t; 500], 200);
    // Degenerate, NaN and infinite triangles mixed in.
    let mut bad = random_soup(500, 4);
    bad.push([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]);
    bad.push([Vec3::NAN, Vec3::X, Vec3::Y]);
    bad.push([Vec3::splat(f32::INFINITY), Vec3::X, Vec3::Y]);
    bad.push([Vec3::splat(5.0); 3]);
    check_scene::<Watertight>("with degenerate and non-finite", &bad, 400);
    // Coordinates from 1e-8 to 1e8.
    let mut rng = Rng::new(9);
    let scales: Vec<Triangle> = (0..1000)
        .map(|i| {
            let s = 10f32.powf(-8.0 + 16.0 * (i as f32 / 1000.0));
            let c = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * s;
            [c, c + Vec3::X * s * 0.1, c + Vec3::Y * s * 0.1]
        })
        .collect();
    check_scene::<Watertight>("1e-8 .. 1e8", &scales, 400);
    // A geometric series: a deep tree.
    let series: Vec<Triangle> = (0..200)
        .map(|i| {
            let x = 2f32.powi(-i);
            [Vec3::new(x, 0.0, 0.0), Vec3::new(x, 1.0, 0.0), Vec3::new(x, 0.0, 1.0)]
        })
        .collect();
    check_scene::<Watertight>("geometric series", &series, 300);
    // Empty and single-triangle scenes.
    check_scene::<Watertight>("one triangle", &[t], 50);
    let none: Vec<Triangle> = Vec::new();
    let (b2, _) = Bvh2::build(&none[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &none[..]).unwrap();
    assert!(b8.intersect::<Watertight>(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
    assert!(!b8.occluded::<Watertight>(&Ray::new(Vec3::ZERO, Vec3::X)));
}

#[test]
fn batch_and_parallel_batch_agree_with_single_rays() {
    let tris = scene::bunny().to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let rays = rays(&tris, 5000, 11);
    let mut hits = vec![None; rays.len()];
    b8.intersect_batch_par::<Watertight>(&rays, &mut hits, 3);
    let mut occ = vec![false; rays.len()];
    b8.occluded_batch_par::<Watertight>(&rays, &mut occ, 2);
    // Reordered by origin on 1-4 threads, outputs longer and shorter than the rays.
    for threads in 1..=4 {
        let sentinel = hits.iter().flatten().next().copied();
        assert!(sentinel.is_some());
        let mut hits_r = vec![sentinel; rays.len() + 1];
        b8.intersect_batch_reordered_par::<Watertight>(&rays, &mut hits_r, threads);
        let mut occ_r = vec![true; rays.len() - 7];
        b8.occluded_batch_reordered_par::<Watertight>(&rays, &mut occ_r, threads);
        assert_eq!(hits_r[..rays.len()], hits[..], "{threads} threads");
        assert_eq!(hits_r[rays.len()], sentinel, "{threads} threads: wrote past the rays");
        assert_eq!(occ_r[..], occ[..rays.len() - 7], "{threads} threads");
    }
    for (i, r) in rays.iter().enumerate() {
        assert_eq!(hits[i], b8.intersect::<Watertight>(r));
        assert_eq!(occ[i], b8.occluded::<Watertight>(r));
    }
}

/// Every lane of a packet equals single-ray traversal, for every switch threshold, with mixed
/// directions, inactive lanes (short slices), NaN lanes, zero components and -0.0.
#[test]
fn packets_equal_single_rays() {
    use strahl::traverse::packet;
    for (name, tris) in [
        ("bunny", scene::bunny().to_soup()),
        ("random", random_soup(2000, 3)),
        ("same triangle", vec![[Vec3::ZERO, Vec3::X, Vec3::Y]; 100]),
    ] {
        let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
        let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
        let mut all = rays(&tris, 800, 21);
        // Coherent packets too: 8 rays from one eye through neighbouring points.
        let b = tris.iter().flatten().fold(Vec3::NEG_INFINITY, |m, v| m.max(*v));
        for i in 0..400 {
            let eye = b * 2.0 + Vec3::splat(1.0);
            let target = Vec3::new((i % 20) as f32 / 20.0, (i / 20) as f32 / 20.0, 0.3) * b;
            all.push(Ray::new(eye, target - eye));
        }
        for switch in [0, 3, 9] {
            for (k, chunk) in all.chunks(8).enumerate() {
                // Some packets are short (inactive lanes), some get NaN lanes.
                let mut chunk = chunk.to_vec();
                if k % 5 == 1 {
                    chunk[0] = Ray::new(Vec3::NAN, Vec3::X);
                }
                let len = if k % 7 == 3 { 3.min(chunk.len()) } else { chunk.len() };
                let mut h8 = [None; 8];
                let mut h4 = [None; 8];
                packet::intersect8::<Watertight, _, 8>(b8.view(), &chunk[..len], &mut h8, switch);
                packet::intersect8::<Watertight, _, 4>(b4.view(), &chunk[..len], &mut h4, switch);
                for (i, r) in chunk[..len].iter().enumerate() {
                    let single = b8.intersect::<Watertight>(r);
                    same(h8[i], single, &tris, r, &format!("{name} packet8/bvh8 switch {switch}"));
                    same(h4[i], single, &tris, r, &format!("{name} packet8/bvh4 switch {switch}"));
                }
                assert!(h8[len..].iter().all(|h| h.is_none()));
                let mut o8 = [false; 8];
                let mut o4 = [false; 8];
                packet::occluded8::<Watertight, _, 8>(b8.view(), &chunk[..len], &mut o8);
                packet::occluded8::<Watertight, _, 4>(b4.view(), &chunk[..len], &mut o4);
                for (i, r) in chunk[..len].iter().enumerate() {
                    let single = b8.occluded::<Watertight>(r);
                    assert_eq!(o8[i], single, "{name} occluded8/bvh8 {r:?}");
                    assert_eq!(o4[i], single, "{name} occluded8/bvh4 {r:?}");
                }
            }
        }
    }
}

/// Views that break the tree's invariants (a child pointing back at the root, codes out of range,
/// a leaf code past the packs): the single-ray functions and the incoherent and ordered batches never panic
/// or hang, and the batches answer exactly as one call per ray (the same walk, bit for bit). With
/// a real child replaced by the root (a cycle that also cuts the child's subtree off), the answers
/// are still exact: a ray that enters the child's box goes round the cycle until its walk exceeds
/// its budget, then scans every pack, keeping the hit it had.
#[test]
fn malformed_views_batches_equal_single_rays() {
    use strahl::layout::{Bvh8Ref, BvhWideRef, EMPTY_CHILD, LEAF_BIT, Node8};
    use strahl::traverse::wide;
    let tris = scene::bunny().to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let rays = rays(&tris, 400, 5);
    // Camera rays in 4 x 2 tiles (packets in the adaptive batches).
    let (lo, hi) = tris
        .iter()
        .flatten()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
    let eye = hi + (hi - lo);
    let tiles: Vec<Ray> = (0..256)
        .map(|i| {
            let (x, y) = (
                (i % 4 + 4 * (i / 8 % 8)) as f32 / 32.0,
                (i / 4 % 2 + 2 * (i / 64)) as f32 / 8.0,
            );
            Ray::new(eye, lo + (hi - lo) * Vec3::new(x, y, 0.5) - eye)
        })
        .collect();
    let tile_hits = tiles.iter().filter(|r| b8.intersect::<Watertight>(r).is_some()).count();
    assert!(tile_hits > 20 && tile_hits < 250, "{tile_hits} of the tiles' rays hit");
    let n = b8.nodes().len();
    // The first slot holding a real child.
    let used = |node: &Node8| node.child.iter().position(|&c| c != EMPTY_CHILD).unwrap_or(0);
    type Edit = fn(&mut [Node8], usize, usize);
    let edits: [(&str, Edit); 5] = [
        ("cycle", |nodes, i, slot| nodes[i].child[slot] = 0),
        // The last node gets a second parent (a cycle where it is the node edited).
        ("two parents", |nodes, i, slot| {
            nodes[i].child[slot] = (nodes.len() - 1) as u32
        }),
        ("node out of range", |nodes, i, slot| nodes[i].child[slot] = 1 << 30),
        ("leaf past the packs", |nodes, i, slot| {
            nodes[i].child[slot] = LEAF_BIT | (1 << 26) << 4
        }),
        ("root into itself", |nodes, _, _| nodes[0].child[0] = 0),
    ];
    let mut cycles_checked = 0;
    for (what, edit) in edits {
        for at in [0, 1.min(n - 1), n / 2, n - 1] {
            let mut nodes = b8.nodes().to_vec();
            let slot = used(&nodes[at]);
            edit(&mut nodes, at, slot);
            let view: Bvh8Ref = BvhWideRef {
                nodes: &nodes,
                packs: b8.packs(),
            };
            let (mut hits, mut occ) = (vec![None; rays.len()], vec![false; rays.len()]);
            wide::intersect_batch_incoherent::<Watertight, _, 8>(view, &rays, &mut hits);
            wide::occluded_batch_incoherent::<Watertight, _, 8>(view, &rays, &mut occ);
            let order: Vec<u32> = (0..rays.len() as u32).rev().collect();
            let (mut hits_o, mut occ_o) = (vec![None; rays.len()], vec![false; rays.len()]);
            wide::intersect_batch_ordered::<Watertight, _, 8>(view, &rays, &order, &mut hits_o);
            wide::occluded_batch_ordered::<Watertight, _, 8>(view, &rays, &order, &mut occ_o);
            assert_eq!((&hits_o, &occ_o), (&hits, &occ), "{what} at {at}: ordered batches");
            // The adaptive batches, over the rays and over camera tiles (their packet path).
            let (mut hits_a, mut occ_a) = (vec![None; rays.len()], vec![false; rays.len()]);
            wide::intersect_batch::<Watertight, _, 8>(view, &rays, &mut hits_a);
            wide::occluded_batch::<Watertight, _, 8>(view, &rays, &mut occ_a);
            assert_eq!((&hits_a, &occ_a), (&hits, &occ), "{what} at {at}: adaptive batches");
            let mut occ_s = vec![false; rays.len()];
            wide::occluded_batch_stream::<Watertight, _, 8>(view, &rays, &mut occ_s);
            assert_eq!(occ_s, occ, "{what} at {at}: ray streams");
            let (mut hits_t, mut occ_t) = (vec![None; tiles.len()], vec![false; tiles.len()]);
            wide::intersect_batch::<Watertight, _, 8>(view, &tiles, &mut hits_t);
            wide::occluded_batch::<Watertight, _, 8>(view, &tiles, &mut occ_t);
            for (i, r) in tiles.iter().enumerate() {
                assert_eq!(
                    hits_t[i],
                    wide::intersect::<Watertight, _, 8>(view, r),
                    "{what} at {at}: tile ray {i}"
                );
                assert_eq!(
                    occ_t[i],
                    wide::occluded::<Watertight, _, 8>(view, r),
                    "{what} at {at}: tile ray {i}"
                );
            }
            for (i, r) in rays.iter().enumerate() {
                let single = wide::intersect::<Watertight, _, 8>(view, r);
                let any = wide::occluded::<Watertight, _, 8>(view, r);
                assert_eq!(hits[i], single, "{what} at {at}: intersect {r:?}");
                assert_eq!(occ[i], any, "{what} at {at}: occluded {r:?}");
                if what == "cycle" {
                    let want = intersect_brute_force::<Watertight, _>(&tris[..], r);
                    same(single, want, &tris, r, &format!("{what} at {at}: vs brute force"));
                    assert_eq!(
                        any,
                        occluded_brute_force::<Watertight, _>(&tris[..], r),
                        "{what} at {at}"
                    );
                    cycles_checked += 1;
                }
            }
        }
    }
    assert_eq!(cycles_checked, 4 * rays.len());
}

/// `Fast<T>` answers the same for a direction and the same direction scaled by 1e-5 to 1e30
/// (directions of ordinary length: its reciprocals are clamped to 1e18 as Embree's are), and the
/// packet traversals keep the conservative test under `Fast<T>`: every lane equals `T`'s
/// single-ray answer.
#[test]
fn fast_slabs_are_scale_free_and_packets_stay_conservative() {
    use strahl::traverse::packet;
    let tris = scene::icosphere(3).to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let base = rays(&tris, 400, 21);
    let mut hits = 0;
    for r in &base {
        let want = b8.intersect::<Fast<Watertight>>(r);
        let want2 = b2.intersect::<Fast<Watertight>, _>(&tris[..], r);
        hits += usize::from(want.is_some());
        for s in [1e-5f32, 1e5, 1e30] {
            let scaled = Ray::with_range(r.origin, r.direction * s, r.tmin / s, r.tmax / s);
            if !scaled.is_valid() || !(r.direction * s).is_finite() {
                continue;
            }
            let got = b8.intersect::<Fast<Watertight>>(&scaled);
            assert_eq!(got.is_some(), want.is_some(), "scale {s}: {r:?}");
            assert_eq!(got.map(|h| h.prim), want.map(|h| h.prim), "scale {s}: {r:?}");
            let got2 = b2.intersect::<Fast<Watertight>, _>(&tris[..], &scaled);
            assert_eq!(got2.map(|h| h.prim), want2.map(|h| h.prim), "bvh2, scale {s}: {r:?}");
        }
    }
    assert!(hits > 100, "{hits}");
    // Rays aimed at the mesh's vertices meet boxes exactly on their faces, where the two box
    // tests differ (a few single rays do); the packets answer as `T` on every one.
    let mut m = scene::icosphere(3);
    for p in &mut m.positions {
        *p = *p * 3.7 + Vec3::new(0.31, -1.7, 2.1);
    }
    let aimed = scene::aimed_rays(&m, scene::Aim::Vertices, 8, 3.0, 2);
    let tris = m.to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let differ = aimed
        .iter()
        .filter(|r| b8.intersect::<Fast<Watertight>>(r) != b8.intersect::<Watertight>(r))
        .count();
    assert!(differ > 0, "no ray tells the box tests apart");
    for chunk in aimed.chunks(8) {
        let mut fast = [None; 8];
        let mut plain = [None; 8];
        packet::intersect8::<Fast<Watertight>, _, 8>(b8.view(), chunk, &mut fast, packet::DEFAULT_SWITCH);
        packet::intersect8::<Watertight, _, 8>(b8.view(), chunk, &mut plain, packet::DEFAULT_SWITCH);
        assert_eq!(fast, plain);
        let mut occ_fast = [false; 8];
        let mut occ_plain = [false; 8];
        packet::occluded8::<Fast<Watertight>, _, 8>(b8.view(), chunk, &mut occ_fast);
        packet::occluded8::<Watertight, _, 8>(b8.view(), chunk, &mut occ_plain);
        assert_eq!(occ_fast, occ_plain);
        let mut b2_fast = [None; 8];
        packet::intersect_packet_bvh2::<Fast<Watertight>, _, strahl::math::f32x8, 8>(
            b2.view(),
            &tris[..],
            chunk,
            &mut b2_fast,
        );
        let mut b2_plain = [None; 8];
        packet::intersect_packet_bvh2::<Watertight, _, strahl::math::f32x8, 8>(
            b2.view(),
            &tris[..],
            chunk,
            &mut b2_plain,
        );
        assert_eq!(b2_fast, b2_plain);
    }
}

/// A hit is reported at a finite `t` only. With `tmin = -inf`, a triangle 1,000 units behind the
/// origin of a ray whose direction has length 1e-37 lies at `t = -1e40`, which overflows: every
/// path (the kernels, brute force, BVH2, BVH4, BVH8, batches, packets) reports no hit, where
/// before this policy they reported one at `t = -inf`. The same ray with a unit direction finds
/// it at `t = -1000`, and so does every path.
#[test]
fn hits_beyond_f32_range_are_misses() {
    use strahl::traverse::packet;
    let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let mut tris = [tri; 3];
    tris[1] = [
        Vec3::new(5.0, 5.0, 0.0),
        Vec3::new(6.0, 5.0, 0.0),
        Vec3::new(5.0, 6.0, 0.0),
    ];
    tris[2] = [
        Vec3::new(-5.0, 5.0, 2.0),
        Vec3::new(-4.0, 5.0, 2.0),
        Vec3::new(-5.0, 6.0, 2.0),
    ];
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let (b4, b8) = (
        Bvh4::from_bvh2(&b2, &tris[..]).unwrap(),
        Bvh8::from_bvh2(&b2, &tris[..]).unwrap(),
    );
    let o = Vec3::new(0.25, 0.25, 1000.0);
    for (d, want) in [(Vec3::new(0.0, 0.0, 1e-37), None), (Vec3::Z, Some(-1000.0f32))] {
        let ray = Ray::with_range(o, d, f32::NEG_INFINITY, f32::INFINITY);
        let p = PreparedRay::new(&ray);
        let kernels = [
            strahl::intersect::moller::intersect_scalar(&p, &tri, 0),
            strahl::intersect::watertight::intersect_scalar(&p, &tri, 0),
        ];
        let hits = [
            intersect_brute_force::<Moller, _>(&tris[..], &ray),
            intersect_brute_force::<Watertight, _>(&tris[..], &ray),
            b2.intersect::<Moller, _>(&tris[..], &ray),
            b4.intersect::<Watertight>(&ray),
            b8.intersect::<Moller>(&ray),
            b8.intersect::<Fast<Moller>>(&ray),
        ];
        let mut batch = [None; 2];
        b8.intersect_batch_incoherent::<Watertight>(&[ray, ray], &mut batch);
        let mut packed = [None; 8];
        packet::intersect8::<Watertight, _, 8>(b8.view(), &[ray; 8], &mut packed, 0);
        let all = kernels.iter().chain(&hits).chain(&batch).chain(&packed);
        for (k, h) in all.enumerate() {
            assert_eq!(h.map(|h| h.t), want, "path {k}, direction {d}");
            if let Some(h) = h {
                assert!(h.u.is_finite() && h.v.is_finite(), "path {k}: {h:?}");
            }
        }
        let mut occ = [false; 8];
        packet::occluded8::<Moller, _, 8>(b8.view(), &[ray; 8], &mut occ);
        let any = [
            occluded_brute_force::<Moller, _>(&tris[..], &ray),
            b2.occluded::<Watertight, _>(&tris[..], &ray),
            b8.occluded::<Moller>(&ray),
            occ[0],
            occ[7],
        ];
        assert!(any.iter().all(|&a| a == want.is_some()), "{any:?}, direction {d}");
    }
}

/// The adaptive batches (`wide::intersect_batch`, `wide::occluded_batch` and the `BvhWide`
/// methods) answer exactly as one call per ray on batches that mix every kind of group: camera
/// tiles (packets), rays from one point in every direction (one at a time), rays from scattered
/// origins (interleaved), NaN and zero-length rays inside otherwise coherent groups, -0.0
/// components, shortened rays; at every offset (groups straddle the kinds), with outputs
/// shorter and longer than the rays, through BVH4 and BVH8, Möller, watertight and `Fast`.
#[test]
fn adaptive_batches_equal_single_rays() {
    fn check<T: TriangleTest>(tris: &[Triangle], rays: &[Ray], what: &str) {
        let (b2, _) = Bvh2::build(tris, &BuildParams::default()).unwrap();
        let b8 = Bvh8::from_bvh2(&b2, tris).unwrap();
        let b4 = Bvh4::from_bvh2(&b2, tris).unwrap();
        for skip in [0, 1, 3, 5, 8] {
            let rays = &rays[skip.min(rays.len())..];
            for extra in [0usize, 1] {
                // One slot more than the rays keeps its value; one fewer drops the last ray.
                let len = (rays.len() + extra).saturating_sub(1 - extra.min(1));
                let sentinel = Some(Hit {
                    t: -7.0,
                    u: 0.0,
                    v: 0.0,
                    prim: 7,
                });
                let (mut h8, mut h4) = (vec![sentinel; len], vec![sentinel; len]);
                b8.intersect_batch::<T>(rays, &mut h8);
                wide::intersect_batch::<T, _, 4>(b4.view(), rays, &mut h4);
                let (mut o8, mut o4) = (vec![true; len], vec![true; len]);
                wide::occluded_batch::<T, _, 8>(b8.view(), rays, &mut o8);
                b4.occluded_batch::<T>(rays, &mut o4);
                let (mut s8, mut s4) = (vec![true; len], vec![true; len]);
                wide::occluded_batch_stream::<T, _, 8>(b8.view(), rays, &mut s8);
                wide::occluded_batch_stream::<T, _, 4>(b4.view(), rays, &mut s4);
                assert_eq!(s8, o8, "{what} skip {skip}: bvh8 streams");
                assert_eq!(s4, o4, "{what} skip {skip}: bvh4 streams");
                let n = rays.len().min(len);
                for (i, r) in rays[..n].iter().enumerate() {
                    let (hit, occ) = (b8.intersect::<T>(r), b8.occluded::<T>(r));
                    // The same `t`; the same primitive unless two tie there (packets visit nodes
                    // in another order).
                    same(h8[i], hit, tris, r, &format!("{what} skip {skip}: bvh8 ray {i}"));
                    same(
                        h4[i],
                        b4.intersect::<T>(r),
                        tris,
                        r,
                        &format!("{what} skip {skip}: bvh4 ray {i}"),
                    );
                    assert_eq!(o8[i], occ, "{what} skip {skip}: bvh8 occluded ray {i} {r:?}");
                    assert_eq!(
                        o4[i],
                        b4.occluded::<T>(r),
                        "{what} skip {skip}: bvh4 occluded ray {i} {r:?}"
                    );
                }
                assert!(
                    h8[n..].iter().chain(&h4[n..]).all(|h| *h == sentinel),
                    "{what}: wrote past the rays"
                );
                assert!(
                    o8[n..].iter().chain(&o4[n..]).all(|&o| o),
                    "{what}: wrote past the rays"
                );
            }
        }
    }
    for (name, tris) in [
        ("bunny", scene::bunny().to_soup()),
        ("random", random_soup(1500, 9)),
        ("same triangle", vec![[Vec3::ZERO, Vec3::X, Vec3::Y]; 50]),
        ("sphereflake", scene::sphereflake(2, 1).to_soup()),
    ] {
        let (lo, hi) = tris
            .iter()
            .flatten()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
        let centre = (lo + hi) * 0.5;
        let mut batch: Vec<Ray> = Vec::new();
        // Camera tiles of 4 x 2 pixels from one eye (packets).
        let eye = hi + (hi - lo);
        for i in 0..64 {
            let (x, y) = (
                (i % 4 + 4 * (i / 8 % 4)) as f32 / 16.0,
                (i / 4 % 2 + 2 * (i / 32)) as f32 / 4.0,
            );
            batch.push(Ray::new(eye, lo + (hi - lo) * Vec3::new(x, y, 0.5) - eye));
        }
        // Rays from one point in every direction (one at a time).
        let mut rng = Rng::new(4);
        batch.extend((0..21).map(|_| Ray::new(centre, rng.unit_vector())));
        // Scattered origins (interleaved): the mixed rays, with NaN and degenerate ones at the end.
        batch.extend(rays(&tris, 90, 17));
        // Coherent tiles again, one with a NaN ray, one with a zero direction, one shortened, one
        // with -0.0 components.
        for k in 0..4 {
            for i in 0..8 {
                let d = lo + (hi - lo) * Vec3::new(i as f32 / 8.0, 0.4, 0.5) - eye;
                let mut r = Ray::new(eye, d);
                if i == 3 {
                    r = match k {
                        0 => Ray::new(Vec3::NAN, d),
                        1 => Ray::new(eye, Vec3::ZERO),
                        2 => Ray::with_range(eye, d, 0.0, 0.3),
                        _ => Ray::new(centre + Vec3::X * 1e-3, Vec3::new(-0.0, -0.0, -1.0)),
                    };
                }
                batch.push(r);
            }
        }
        check::<Watertight>(&tris, &batch, name);
        check::<Moller>(&tris, &batch, name);
        check::<Fast<Moller>>(&tris, &batch, name);
    }
    // Long rays from scattered points through a sparse soup of small triangles: each enters many
    // subtrees alone, more than a stream holds back at once.
    let mut rng = Rng::new(8);
    let sparse: Vec<Triangle> = random_soup(6000, 12)
        .into_iter()
        .map(|t| t.map(|v| (v - t[0]) * 0.1 + t[0]))
        .collect();
    let long: Vec<Ray> = (0..200)
        .map(|_| {
            let o = Vec3::new(rng.f32(), rng.f32(), 0.0) * 10.0;
            Ray::new(o, Vec3::new(rng.f32() * 10.0, rng.f32() * 10.0, 10.0) - o)
        })
        .collect();
    check::<Moller>(&sparse, &long, "sparse soup");
    // An empty tree and an empty batch.
    let none: Vec<Triangle> = Vec::new();
    check::<Watertight>(&none, &rays(&random_soup(10, 1), 30, 2), "empty tree");
    check::<Watertight>(&random_soup(10, 1), &[], "empty batch");
}

/// `BvhWide::build` / `build_par` (one call) make the two steps' tree, hits and statistics;
/// bad parameters come back as the binary build's error, and an empty or all-invalid scene is an
/// empty tree that nothing hits.
#[test]
fn one_call_builds_are_the_two_steps() {
    let mut tris = random_soup(3000, 21);
    tris[5] = [Vec3::NAN, Vec3::ONE, Vec3::ZERO]; // left out, counted
    let rays = rays(&tris, 300, 22);
    for params in [BuildParams::fastest(), BuildParams::default(), BuildParams::quality()] {
        let (b2, want_stats) = Bvh2::build(&tris[..], &params).unwrap();
        let two_step = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
        let (one, stats) = Bvh8::build(&tris[..], &params).unwrap();
        let (par, par_stats) = Bvh8::build_par(&tris[..], &params, 2).unwrap();
        let (four, _) = Bvh4::build(&tris[..], &params).unwrap();
        assert_eq!((stats.invalid, stats.primitives), (1, 2999)); // primitives in the tree
        assert_eq!(
            (stats.nodes, stats.leaves, stats.max_depth),
            (want_stats.nodes, want_stats.leaves, want_stats.max_depth)
        );
        assert_eq!(par_stats.invalid, 1);
        assert_eq!(
            (one.nodes().len(), one.packs().len()),
            (two_step.nodes().len(), two_step.packs().len())
        );
        for r in &rays {
            let want = two_step.intersect::<Watertight>(r);
            assert_eq!(one.intersect::<Watertight>(r), want);
            same(par.intersect::<Watertight>(r), want, &tris, r, "build_par");
            same(four.intersect::<Watertight>(r), want, &tris, r, "Bvh4::build");
        }
    }
    let bad = BuildParams {
        bins: 3,
        ..BuildParams::default()
    };
    assert!(matches!(
        Bvh8::build(&tris[..], &bad),
        Err(strahl::layout::WideBuildError::Build(_))
    ));
    let ray = Ray::new(Vec3::new(0.1, 0.2, -5.0), Vec3::Z);
    for scene in [Vec::new(), vec![[Vec3::NAN; 3]; 4]] {
        let (b8, stats) = Bvh8::build(&scene[..], &BuildParams::default()).unwrap();
        assert_eq!(stats.invalid as usize, scene.len());
        assert!(b8.intersect::<Moller>(&ray).is_none() && !b8.occluded::<Moller>(&ray));
    }
}

/// A `StridedMesh` over interleaved vertices (position after one padding byte, then 20 bytes
/// of other attributes: a 36-byte stride, unaligned) gives the very triangles, trees and hits
/// of the `IndexedMesh` over the same positions; indices past the last vertex are left out.
#[test]
fn strided_meshes_trace_as_indexed_meshes() {
    use strahl::geometry::{IndexedMesh, StridedMesh, Triangles};
    let bunny = scene::bunny();
    let mut indices = bunny.indices.clone();
    indices[7][2] = bunny.positions.len() as u32; // one past the last vertex
    indices[9][0] = u32::MAX;
    let stride = 36;
    let mut bytes = vec![0xAAu8; 1 + stride * bunny.positions.len()];
    for (i, p) in bunny.positions.iter().enumerate() {
        let at = 1 + i * stride;
        bytes[at..at + 12].copy_from_slice(bytemuck::cast_slice(&p.to_array()));
    }
    let strided = StridedMesh::new(&bytes[1..], stride, &indices).unwrap();
    let indexed = IndexedMesh::new(&bunny.positions, &indices);
    assert_eq!(
        (strided.len(), strided.vertices()),
        (indexed.len(), bunny.positions.len())
    );
    for i in 0..indexed.len() + 2 {
        assert_eq!(strided.triangle(i), indexed.triangle(i), "triangle {i}");
    }
    let (a, sa) = Bvh8::build(&strided, &BuildParams::default()).unwrap();
    let (b, sb) = Bvh8::build(&indexed, &BuildParams::default()).unwrap();
    assert_eq!((sa.invalid, sb.invalid), (2, 2));
    assert_eq!((a.nodes().len(), a.packs().len()), (b.nodes().len(), b.packs().len()));
    let soup: Vec<Triangle> = (0..indexed.len()).filter_map(|i| indexed.triangle(i)).collect();
    for r in &rays(&soup, 500, 31) {
        assert_eq!(a.intersect::<Watertight>(r), b.intersect::<Watertight>(r));
        assert_eq!(a.occluded::<Moller>(r), b.occluded::<Moller>(r));
    }
}
