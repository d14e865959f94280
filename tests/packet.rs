//! Packets of 4, 8 and 16 rays over BVH2, BVH4 and BVH8 give every lane the single-ray answer:
//! the same `t` bit for bit, the same primitive unless two triangles tie at that `t`, the same
//! any-hit answer. On random, clustered and mesh scenes, with mixed directions, coherent camera
//! tiles, inactive lanes (short slices), NaN lanes, zero direction components and -0.0, for every
//! hybrid threshold.

mod common;

use common::{bounds, mixed_rays, random_soup, same};
use proptest::prelude::*;
use std::sync::OnceLock;
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::{Hit, Triangle};
use strahl::layout::{Bvh4, Bvh8};
use strahl::math::{Lane, f32x4, f32x8};
use strahl::scene;
use strahl::traverse::packet::{self, TileShape, f32x16};
use strahl::traverse::{Moller, TriangleTest, Watertight, intersect_scalar, occluded_scalar, wide};
use strahl::{Ray, Vec3};

struct Scene {
    tris: Vec<Triangle>,
    b2: Bvh2,
    b4: Bvh4,
    b8: Bvh8,
}

fn scene_of(tris: Vec<Triangle>) -> Scene {
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    Scene { tris, b2, b4, b8 }
}

/// A pinhole camera looking at the scene, `w x h` pixels in tiles of `shape` (coherent packets),
/// plus one view straight down the z axis (direction components exactly 0 and -0.0 at the centre).
fn camera_rays(tris: &[Triangle], shape: TileShape, w: u32, h: u32) -> Vec<Ray> {
    let (lo, hi) = bounds(tris);
    let c = (lo + hi) * 0.5;
    let r = (hi - lo).length() * 0.5;
    let eye = c + Vec3::new(0.55, 0.35, 1.0).normalize() * r * 2.6;
    let fw = (c - eye).normalize();
    let right = fw.cross(Vec3::Y).normalize() * 0.45;
    let up = right.normalize().cross(fw) * 0.45;
    let mut rays = packet::image_rays(shape, w, h, |x, y| {
        let u = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
        let v = 1.0 - (y as f32 + 0.5) / h as f32 * 2.0;
        Ray::new(eye, fw + right * u + up * v)
    });
    let eye = Vec3::new(c.x, c.y, hi.z + r);
    rays.extend(packet::image_rays(shape, 8, 8, |x, y| {
        let s = |i: u32| if i == 4 { -0.0 } else { (i as f32 - 4.0) * 0.05 };
        Ray::new(eye, Vec3::new(s(x), s(y), -1.0))
    }));
    rays
}

/// A marker that the kernels never write (a lane past the slice must keep it).
const UNTOUCHED: Option<Hit> = Some(Hit {
    t: -7.0,
    u: 0.0,
    v: 0.0,
    prim: 7,
});

/// Every packet of `K` consecutive rays of `rays` (some shortened, some with a NaN lane) against
/// single rays, over BVH2, BVH4 and BVH8, closest hit for each `switch` and any hit.
fn check_k<T: TriangleTest, R: Lane, const K: usize>(s: &Scene, rays: &[Ray], what: &str) {
    let tris = &s.tris[..];
    let switches = [0, 1, 3, K as u32 / 2, packet::default_switch(K)];
    for (k, chunk) in rays.chunks(K).enumerate() {
        let mut chunk = chunk.to_vec();
        if k % 5 == 1 {
            let at = k % chunk.len();
            chunk[at] = Ray::new(Vec3::NAN, Vec3::X);
        }
        if k % 11 == 4 {
            chunk[0].direction.y = f32::NAN;
        }
        let len = if k % 7 == 3 {
            (K / 2 - 1).min(chunk.len())
        } else {
            chunk.len()
        };
        let chunk = &chunk[..len];
        let single8: Vec<Option<Hit>> = chunk
            .iter()
            .map(|r| wide::intersect::<T, _, 8>(s.b8.view(), r))
            .collect();
        let single2: Vec<Option<Hit>> = chunk
            .iter()
            .map(|r| intersect_scalar::<T, _>(s.b2.view(), tris, r))
            .collect();
        for switch in switches {
            let mut h8 = [UNTOUCHED; K];
            let mut h4 = [UNTOUCHED; K];
            packet::intersect_packet::<T, _, 8, R, K>(s.b8.view(), chunk, &mut h8, switch);
            packet::intersect_packet::<T, _, 4, R, K>(s.b4.view(), chunk, &mut h4, switch);
            for (i, r) in chunk.iter().enumerate() {
                let w = format!("{what}: packet{K}/bvh8 switch {switch} lane {i}");
                same(h8[i], single8[i], tris, r, &w);
                let w = format!("{what}: packet{K}/bvh4 switch {switch} lane {i}");
                same(h4[i], single8[i], tris, r, &w);
            }
            assert!(
                h8[len..].iter().chain(&h4[len..]).all(|h| *h == UNTOUCHED),
                "{what}: lanes past the slice"
            );
        }
        let mut h2 = [UNTOUCHED; K];
        packet::intersect_packet_bvh2::<T, _, R, K>(s.b2.view(), tris, chunk, &mut h2);
        for (i, r) in chunk.iter().enumerate() {
            same(h2[i], single2[i], tris, r, &format!("{what}: packet{K}/bvh2 lane {i}"));
        }
        assert!(
            h2[len..].iter().all(|h| *h == UNTOUCHED),
            "{what}: bvh2 lanes past the slice"
        );

        let any: Vec<bool> = chunk
            .iter()
            .map(|r| wide::occluded::<T, _, 8>(s.b8.view(), r))
            .collect();
        for switch in [0, 3, packet::default_switch(K)] {
            let mut o8 = [false; K];
            let mut o4 = [false; K];
            packet::occluded_packet::<T, _, 8, R, K>(s.b8.view(), chunk, &mut o8, switch);
            packet::occluded_packet::<T, _, 4, R, K>(s.b4.view(), chunk, &mut o4, switch);
            assert_eq!(&o8[..len], &any[..], "{what}: occluded{K}/bvh8 switch {switch}");
            assert_eq!(&o4[..len], &any[..], "{what}: occluded{K}/bvh4 switch {switch}");
        }
        let mut o2 = [false; K];
        packet::occluded_packet_bvh2::<T, _, R, K>(s.b2.view(), tris, chunk, &mut o2);
        for (i, r) in chunk.iter().enumerate() {
            assert_eq!(
                o2[i],
                occluded_scalar::<T, _>(s.b2.view(), tris, r),
                "{what}: occluded{K}/bvh2 {r:?}"
            );
            assert_eq!(o2[i], any[i], "{what}: bvh2 vs bvh8 any hit {r:?}");
        }
    }
}

fn check_scene<T: TriangleTest>(name: &str, s: &Scene, n_mixed: usize, w: u32, h: u32) {
    let mixed = mixed_rays(&s.tris, n_mixed, 21);
    check_k::<T, f32x4, 4>(s, &mixed, &format!("{name} mixed"));
    check_k::<T, f32x8, 8>(s, &mixed, &format!("{name} mixed"));
    check_k::<T, f32x16, 16>(s, &mixed, &format!("{name} mixed"));
    for shape in [TileShape::X4_1, TileShape::X2_2] {
        check_k::<T, f32x4, 4>(s, &camera_rays(&s.tris, shape, w, h), &format!("{name} {shape:?}"));
    }
    check_k::<T, f32x8, 8>(s, &camera_rays(&s.tris, TileShape::X4_2, w, h), &format!("{name} 4x2"));
    for shape in [TileShape::X4_4, TileShape::X8_2] {
        check_k::<T, f32x16, 16>(s, &camera_rays(&s.tris, shape, w, h), &format!("{name} {shape:?}"));
    }
}

#[test]
fn random_scenes() {
    let s = scene_of(random_soup(2000, 1));
    check_scene::<Watertight>("random soup", &s, 600, 24, 20);
    check_scene::<Moller>("random soup", &s, 300, 16, 12);
}

#[test]
fn clustered_scenes() {
    let s = scene_of(scene::clustered_soup(3000, 5, 2));
    check_scene::<Watertight>("clustered", &s, 600, 24, 20);
    // Every hit ties: the same triangle 100 times.
    let s = scene_of(vec![[Vec3::ZERO, Vec3::X, Vec3::Y]; 100]);
    check_scene::<Watertight>("same triangle", &s, 200, 12, 12);
}

#[test]
fn bunny() {
    let s = scene_of(scene::bunny().to_soup());
    check_scene::<Watertight>("bunny", &s, 800, 32, 32);
    check_scene::<Moller>("bunny", &s, 200, 16, 16);
}

/// A hit filter under test (a function of the hit).
type Filter = fn(&Hit) -> bool;

/// Filtered packets (`intersect_packet_filtered`, `occluded_packet_filtered`) of `K` rays over
/// BVH4 and BVH8 give every lane the filtered single ray's answer, for several hybrid thresholds;
/// returns how many answers the filter changed.
fn check_filtered_k<T: TriangleTest, R: Lane, const K: usize>(s: &Scene, rays: &[Ray], f: Filter, what: &str) -> usize {
    let tris = &s.tris[..];
    let mut changed = 0;
    for (k, chunk) in rays.chunks(K).enumerate() {
        let len = if k % 7 == 3 {
            (K / 2).min(chunk.len())
        } else {
            chunk.len()
        };
        let chunk = &chunk[..len];
        let want: Vec<Option<Hit>> = chunk.iter().map(|r| s.b8.intersect_filtered::<T>(r, f)).collect();
        let any: Vec<bool> = chunk.iter().map(|r| s.b8.occluded_filtered::<T>(r, f)).collect();
        for (r, w) in chunk.iter().zip(&want) {
            changed += usize::from(*w != s.b8.intersect::<T>(r));
            assert!(w.is_none_or(|h| f(&h)), "{what}: single ray returned a rejected hit");
        }
        for switch in [0, 3, packet::default_switch(K)] {
            let (mut h8, mut h4) = ([UNTOUCHED; K], [UNTOUCHED; K]);
            packet::intersect_packet_filtered::<T, _, 8, R, K>(s.b8.view(), chunk, &mut h8, switch, f);
            packet::intersect_packet_filtered::<T, _, 4, R, K>(s.b4.view(), chunk, &mut h4, switch, f);
            for (i, r) in chunk.iter().enumerate() {
                same(
                    h8[i],
                    want[i],
                    tris,
                    r,
                    &format!("{what}: packet{K}/bvh8 switch {switch} lane {i}"),
                );
                same(
                    h4[i],
                    want[i],
                    tris,
                    r,
                    &format!("{what}: packet{K}/bvh4 switch {switch} lane {i}"),
                );
            }
            assert!(
                h8[len..].iter().chain(&h4[len..]).all(|h| *h == UNTOUCHED),
                "{what}: lanes past the slice"
            );
            let (mut o8, mut o4) = ([false; K], [false; K]);
            packet::occluded_packet_filtered::<T, _, 8, R, K>(s.b8.view(), chunk, &mut o8, switch, f);
            packet::occluded_packet_filtered::<T, _, 4, R, K>(s.b4.view(), chunk, &mut o4, switch, f);
            assert_eq!(&o8[..len], &any[..], "{what}: occluded{K}/bvh8 switch {switch}");
            assert_eq!(&o4[..len], &any[..], "{what}: occluded{K}/bvh4 switch {switch}");
        }
    }
    changed
}

#[test]
fn filtered_packets_equal_filtered_single_rays() {
    let filters: [(&str, Filter); 4] = [
        ("even primitives", |h| h.prim % 2 == 0),
        ("alpha stripes in u", |h| (h.u * 7.0).fract() < 0.5),
        ("none", |_| false),
        ("all, as a closure", |_| true),
    ];
    for (name, s) in [
        ("bunny", scene_of(scene::bunny().to_soup())),
        ("clustered", scene_of(scene::clustered_soup(3000, 5, 2))),
    ] {
        let mixed = mixed_rays(&s.tris, 240, 31);
        let cam8 = camera_rays(&s.tris, TileShape::X4_2, 24, 16);
        let cam16 = camera_rays(&s.tris, TileShape::X4_4, 24, 16);
        for (fname, f) in filters {
            let what = format!("{name} / {fname}");
            let mut changed = check_filtered_k::<Watertight, f32x8, 8>(&s, &cam8, f, &format!("{what} 4x2"));
            changed += check_filtered_k::<Moller, f32x8, 8>(&s, &mixed, f, &format!("{what} mixed"));
            changed += check_filtered_k::<Watertight, f32x16, 16>(&s, &cam16, f, &format!("{what} 4x4"));
            changed += check_filtered_k::<Watertight, f32x4, 4>(&s, &mixed, f, &format!("{what} mixed"));
            // The filters change answers (all but the one that accepts everything).
            assert_eq!(
                changed == 0,
                fname.starts_with("all"),
                "{what}: {changed} answers changed"
            );
        }
    }
}

#[test]
fn empty_scene_and_empty_slices() {
    let s = scene_of(Vec::new());
    let rays = [Ray::new(Vec3::ZERO, Vec3::X); 16];
    let mut hits = [UNTOUCHED; 16];
    packet::intersect16::<Watertight, _, 8>(s.b8.view(), &rays, &mut hits, 0);
    assert!(hits.iter().all(|h| h.is_none()));
    let mut hits = [UNTOUCHED; 4];
    packet::intersect4_bvh2::<Watertight, _>(s.b2.view(), &s.tris[..], &rays, &mut hits);
    assert!(hits.iter().all(|h| h.is_none()));
    let mut occ = [true; 8];
    packet::occluded8_bvh2::<Watertight, _>(s.b2.view(), &s.tris[..], &rays, &mut occ);
    assert_eq!(occ, [false; 8]);
    // Empty ray or output slices write nothing.
    let s = scene_of(random_soup(50, 2));
    let mut hits = [UNTOUCHED; 8];
    packet::intersect8::<Watertight, _, 8>(s.b8.view(), &[], &mut hits, 0);
    packet::intersect8_bvh2::<Watertight, _>(s.b2.view(), &s.tris[..], &[], &mut hits);
    assert_eq!(hits, [UNTOUCHED; 8]);
    packet::intersect16::<Watertight, _, 4>(s.b4.view(), &rays, &mut [], 0);
}

#[test]
fn batches_equal_single_rays() {
    let s = scene_of(scene::bunny().to_soup());
    let mut rays = mixed_rays(&s.tris, 333, 5);
    rays.extend(camera_rays(&s.tris, TileShape::X4_4, 20, 18));
    let single: Vec<Option<Hit>> = rays.iter().map(|r| s.b8.intersect::<Watertight>(r)).collect();
    let any: Vec<bool> = rays.iter().map(|r| s.b8.occluded::<Watertight>(r)).collect();
    let check = |hits: &[Option<Hit>], what: &str| {
        for (i, r) in rays.iter().enumerate() {
            same(hits[i], single[i], &s.tris, r, what);
        }
    };
    let mut hits = vec![None; rays.len()];
    packet::intersect_batch::<Watertight, _, 8>(s.b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH);
    check(&hits, "batch8");
    packet::intersect_batch_packets::<Watertight, _, 4, f32x4, 4>(s.b4.view(), &rays, &mut hits, 0);
    check(&hits, "batch4/bvh4");
    packet::intersect_batch_packets::<Watertight, _, 8, f32x16, 16>(s.b8.view(), &rays, &mut hits, 5);
    check(&hits, "batch16/bvh8");
    packet::intersect_batch_bvh2::<Watertight, _, f32x16, 16>(s.b2.view(), &s.tris[..], &rays, &mut hits);
    check(&hits, "batch16/bvh2");
    let mut occ = vec![false; rays.len()];
    packet::occluded_batch_packets::<Watertight, _, 8, f32x8, 8>(s.b8.view(), &rays, &mut occ);
    assert_eq!(occ, any);
    let mut occ = vec![false; rays.len()];
    packet::occluded_batch_bvh2::<Watertight, _, f32x4, 4>(s.b2.view(), &s.tris[..], &rays, &mut occ);
    assert_eq!(occ, any);
}

fn prop_scene() -> &'static Scene {
    static S: OnceLock<Scene> = OnceLock::new();
    S.get_or_init(|| {
        let mut tris = random_soup(400, 9);
        tris.extend(scene::clustered_soup(400, 3, 4));
        scene_of(tris)
    })
}

/// A ray component: bounded, or a special (NaN, +-inf, +-0, subnormal) a quarter of the time.
fn component() -> impl Strategy<Value = f32> + Clone {
    prop_oneof![
        3 => -12.0f32..12.0,
        1 => proptest::sample::select(&common::SPECIALS[..]),
    ]
}

fn any_ray() -> impl Strategy<Value = Ray> {
    (
        common::vec3(component()),
        common::vec3(component()),
        prop_oneof![Just((0.0f32, f32::INFINITY)), (0.0f32..5.0, 0.0f32..30.0)],
    )
        .prop_map(|(o, d, (tmin, tmax))| Ray::with_range(o, d, tmin, tmax))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Arbitrary packets (incoherent, with specials in any lane, any length up to 16).
    #[test]
    fn arbitrary_packets_equal_single_rays(rays in proptest::collection::vec(any_ray(), 0..=16), switch in 0u32..18) {
        let s = prop_scene();
        let tris = &s.tris[..];
        let single: Vec<Option<Hit>> = rays.iter().map(|r| s.b8.intersect::<Watertight>(r)).collect();
        let mut h16 = [None; 16];
        packet::intersect16::<Watertight, _, 8>(s.b8.view(), &rays, &mut h16, switch);
        let mut h2 = [None; 16];
        packet::intersect16_bvh2::<Watertight, _>(s.b2.view(), tris, &rays, &mut h2);
        for (i, r) in rays.iter().enumerate() {
            same(h16[i], single[i], tris, r, "prop packet16/bvh8");
            same(h2[i], single[i], tris, r, "prop packet16/bvh2");
        }
        for (c, chunk) in rays.chunks(4).enumerate() {
            let mut h4 = [None; 4];
            packet::intersect4::<Watertight, _, 4>(s.b4.view(), chunk, &mut h4, switch);
            for (i, r) in chunk.iter().enumerate() {
                same(h4[i], single[c * 4 + i], tris, r, "prop packet4/bvh4");
            }
        }
        let mut o16 = [false; 16];
        packet::occluded_packet::<Watertight, _, 8, f32x16, 16>(s.b8.view(), &rays, &mut o16, switch);
        let mut o2 = [false; 16];
        packet::occluded16_bvh2::<Watertight, _>(s.b2.view(), tris, &rays, &mut o2);
        for (i, r) in rays.iter().enumerate() {
            let any = s.b8.occluded::<Watertight>(r);
            prop_assert_eq!(o16[i], any, "occluded16 {:?}", r);
            prop_assert_eq!(o2[i], any, "occluded16_bvh2 {:?}", r);
        }
    }

    /// Coherent packets: one origin, directions in one octant spread over a small cone.
    #[test]
    fn coherent_packets_equal_single_rays(
        o in common::vec3(-15.0f32..25.0),
        d in common::vec3(-1.0f32..1.0),
        spread in 0.0f32..0.2,
        len in 1usize..=16,
    ) {
        let s = prop_scene();
        let tris = &s.tris[..];
        let rays: Vec<Ray> = (0..len)
            .map(|i| {
                let j = Vec3::new((i % 4) as f32, (i / 4) as f32, 0.0) * spread;
                Ray::new(o, d + j * d.signum())
            })
            .collect();
        let mut h8 = [None; 16];
        let mut h16 = [None; 16];
        let mut h2 = [None; 16];
        packet::intersect_batch::<Watertight, _, 8>(s.b8.view(), &rays, &mut h8, 0);
        packet::intersect16::<Watertight, _, 4>(s.b4.view(), &rays, &mut h16, 0);
        packet::intersect_batch_bvh2::<Watertight, _, f32x4, 4>(s.b2.view(), tris, &rays, &mut h2);
        let mut o16 = [false; 16];
        packet::occluded16::<Watertight, _, 8>(s.b8.view(), &rays, &mut o16);
        for (i, r) in rays.iter().enumerate() {
            let single = s.b8.intersect::<Watertight>(r);
            same(h8[i], single, tris, r, "prop coherent packet8");
            same(h16[i], single, tris, r, "prop coherent packet16/bvh4");
            same(h2[i], single, tris, r, "prop coherent packet4/bvh2");
            prop_assert_eq!(o16[i], s.b8.occluded::<Watertight>(r));
        }
    }
}
