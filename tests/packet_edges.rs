//! Rays on box planes with zero direction components, through every packet entry point, against
//! single rays and brute force (regressions: the coherent walk's interval bound once dropped a
//! `0 * inf` corner and culled boxes some lane entered). And the two grazing and edge rays where
//! Möller-Trumbore disagrees with itself across traversals, which [`Watertight`] answers the same
//! everywhere.

use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::{Hit, Triangle};
use strahl::layout::{Bvh4, Bvh8};
use strahl::math::{f32x4, f32x8};
use strahl::traverse::packet::{self, f32x16};
use strahl::traverse::{Moller, TriangleTest, Watertight, intersect_brute_force, occluded_brute_force, wide};
use strahl::{Ray, Vec3};

fn trees(tris: &[Triangle]) -> (Bvh2, Bvh4, Bvh8) {
    let (b2, _) = Bvh2::build(tris, &BuildParams::default()).unwrap();
    let b4 = Bvh4::from_bvh2(&b2, tris).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, tris).unwrap();
    (b2, b4, b8)
}

/// Every packet entry point against single-ray BVH8 traversal; returns a list of mismatches.
fn compare<T: TriangleTest>(tris: &[Triangle], rays: &[Ray]) -> Vec<String> {
    let (b2, b4, b8) = trees(tris);
    let mut bad = Vec::new();
    let single: Vec<Option<Hit>> = rays.iter().map(|r| wide::intersect::<T, _, 8>(b8.view(), r)).collect();
    let any: Vec<bool> = rays.iter().map(|r| wide::occluded::<T, _, 8>(b8.view(), r)).collect();
    for (i, r) in rays.iter().enumerate() {
        let bf = intersect_brute_force::<T, _>(tris, r);
        if bf.map(|h| h.t.to_bits()) != single[i].map(|h| h.t.to_bits()) {
            bad.push(format!("single vs brute force lane {i}: {:?} vs {bf:?}", single[i]));
        }
        if occluded_brute_force::<T, _>(tris, r) != any[i] {
            bad.push(format!("single occluded vs brute force lane {i}"));
        }
    }
    let chk = |bad: &mut Vec<String>, what: &str, h: &[Option<Hit>]| {
        for i in 0..rays.len() {
            if h[i].map(|h| h.t.to_bits()) != single[i].map(|h| h.t.to_bits()) {
                bad.push(format!("{what} lane {i}: {:?}, single ray {:?}", h[i], single[i]));
            }
        }
    };
    for switch in [0, 1, 3, 5, 9, 17] {
        let n = rays.len();
        if n <= 4 {
            let mut h = [None; 4];
            packet::intersect_packet::<T, _, 8, f32x4, 4>(b8.view(), rays, &mut h, switch);
            chk(&mut bad, &format!("intersect4/bvh8 sw{switch}"), &h);
            let mut h = [None; 4];
            packet::intersect_packet::<T, _, 4, f32x4, 4>(b4.view(), rays, &mut h, switch);
            chk(&mut bad, &format!("intersect4/bvh4 sw{switch}"), &h);
        }
        if n <= 8 {
            let mut h = [None; 8];
            packet::intersect_packet::<T, _, 8, f32x8, 8>(b8.view(), rays, &mut h, switch);
            chk(&mut bad, &format!("intersect8/bvh8 sw{switch}"), &h);
            let mut h = [None; 8];
            packet::intersect_packet::<T, _, 4, f32x8, 8>(b4.view(), rays, &mut h, switch);
            chk(&mut bad, &format!("intersect8/bvh4 sw{switch}"), &h);
        }
        let mut h = [None; 16];
        packet::intersect_packet::<T, _, 8, f32x16, 16>(b8.view(), rays, &mut h, switch);
        chk(&mut bad, &format!("intersect16/bvh8 sw{switch}"), &h);
        let mut h = [None; 16];
        packet::intersect_packet::<T, _, 4, f32x16, 16>(b4.view(), rays, &mut h, switch);
        chk(&mut bad, &format!("intersect16/bvh4 sw{switch}"), &h);
        let mut o = [false; 16];
        packet::occluded_packet::<T, _, 8, f32x16, 16>(b8.view(), rays, &mut o, switch);
        if o[..n] != any[..] {
            bad.push(format!("occluded16/bvh8 sw{switch}: {:?} vs {:?}", &o[..n], any));
        }
        let mut o = [false; 16];
        packet::occluded_packet::<T, _, 4, f32x16, 16>(b4.view(), rays, &mut o, switch);
        if o[..n] != any[..] {
            bad.push(format!("occluded16/bvh4 sw{switch}: {:?} vs {:?}", &o[..n], any));
        }
        if n <= 4 {
            let mut o = [false; 4];
            packet::occluded_packet::<T, _, 8, f32x4, 4>(b8.view(), rays, &mut o, switch);
            if o[..n] != any[..] {
                bad.push(format!("occluded4/bvh8 sw{switch}: {:?} vs {:?}", &o[..n], any));
            }
        }
        if n <= 8 {
            let mut o = [false; 8];
            packet::occluded_packet::<T, _, 8, f32x8, 8>(b8.view(), rays, &mut o, switch);
            if o[..n] != any[..] {
                bad.push(format!("occluded8/bvh8 sw{switch}: {:?} vs {:?}", &o[..n], any));
            }
        }
    }
    let mut h = [None; 16];
    packet::intersect16_bvh2::<T, _>(b2.view(), tris, rays, &mut h);
    chk(&mut bad, "intersect16_bvh2", &h);
    let mut o = [false; 16];
    packet::occluded16_bvh2::<T, _>(b2.view(), tris, rays, &mut o);
    if o[..rays.len()] != any[..] {
        bad.push(format!("occluded16_bvh2: {:?} vs {:?}", &o[..rays.len()], any));
    }
    bad
}

/// `tri` plus 1024 small triangles far away (x, y in [50, 82]), so that the wide trees
/// have several nodes (a one-node tree sends the interval walk to its single-ray fallback).
fn with_padding(tri: Triangle) -> Vec<Triangle> {
    let mut tris = vec![tri];
    for i in 0..1024 {
        let c = Vec3::new(50.0 + (i % 32) as f32, 50.0 + (i / 32) as f32, 1.5);
        tris.push([c, c + Vec3::new(0.5, 0.0, 0.0), c + Vec3::new(0.0, 0.5, 0.1)]);
    }
    tris
}

/// Coherent packet (one direction octant, close origins) where one lane has a direction
/// component of +0.0 and the largest origin on that axis lies exactly on a box's entry plane:
/// the interval bound `product_bounds` drops a corner after a `0 * inf = NaN` product.
#[test]
fn interval_walk_zero_component_origin_on_entry_plane() {
    // One triangle at z = 1.5 spanning x in [0, 1], y in [-1, 1]: its box's min x plane is x = 0.
    let tris = with_padding([
        Vec3::new(0.0, -1.0, 1.5),
        Vec3::new(1.0, -1.0, 1.5),
        Vec3::new(0.0, 1.0, 1.5),
    ]);
    // Lane 0: origin on the plane x = 0, a small positive x direction: hits at t = 1.5.
    // Lane 1: origin just left of the box, x direction +0.0: misses (but widens the interval).
    let rays = [
        Ray::new(Vec3::new(0.0, -0.5, 0.0), Vec3::new(1e-6, 0.0, 1.0)),
        Ray::new(Vec3::new(-0.001, -0.5, 0.0), Vec3::new(0.0, 0.0, 1.0)),
    ];
    let mut bad = compare::<Watertight>(&tris, &rays);
    bad.extend(compare::<Moller>(&tris, &rays));
    assert!(bad.is_empty(), "{bad:#?}");
}

/// Mirror case for the far bound: negative x directions, one lane with x direction -0.0, the
/// smallest origin exactly on the box's exit plane (min x).
#[test]
fn interval_walk_negative_zero_component_origin_on_exit_plane() {
    let tris = with_padding([
        Vec3::new(0.0, -1.0, 1.5),
        Vec3::new(1.0, -1.0, 1.5),
        Vec3::new(0.0, 1.0, 1.5),
    ]);
    let rays = [
        // origin on x = 0 (the box's min x, the exit plane for -x directions), -x direction.
        Ray::new(Vec3::new(0.0, -0.5, 0.0), Vec3::new(-1e-6, 0.0, 1.0)),
        // inside the box's x range, x direction -0.0: hits at t = 1.5.
        Ray::new(Vec3::new(0.001, -0.5, 0.0), Vec3::new(-0.0, 0.0, 1.0)),
    ];
    let mut bad = compare::<Watertight>(&tris, &rays);
    bad.extend(compare::<Moller>(&tris, &rays));
    assert!(bad.is_empty(), "{bad:#?}");
}

/// The same defect with an orthographic camera: four rays with direction exactly +Z, origins
/// x = -0.3, -0.2, -0.1, 0.0; the last lies on the plane x = 0 where a quad's edge is (the
/// watertight test hits its boundary). All lanes have x direction +0.0 (inv +inf), so the interval
/// bound of the entry plane is `min(NaN, NaN, inf, inf)` = inf and the quad's box is culled.
#[test]
fn orthographic_packet_on_box_boundary() {
    let quad = |x0: f32, x1: f32| {
        [
            [
                Vec3::new(x0, -1.0, 1.5),
                Vec3::new(x1, -1.0, 1.5),
                Vec3::new(x1, 1.0, 1.5),
            ],
            [
                Vec3::new(x0, -1.0, 1.5),
                Vec3::new(x1, 1.0, 1.5),
                Vec3::new(x0, 1.0, 1.5),
            ],
        ]
    };
    let mut tris = with_padding(quad(0.0, 1.0)[0]);
    tris.push(quad(0.0, 1.0)[1]);
    let rays: Vec<Ray> = [-0.3f32, -0.2, -0.1, 0.0]
        .iter()
        .map(|&x| Ray::new(Vec3::new(x, 0.25, 0.0), Vec3::Z))
        .collect();
    let bad = compare::<Watertight>(&tris, &rays);
    assert!(bad.is_empty(), "{bad:#?}");
}

/// The fuzz scene: axis-aligned unit quads on an integer grid (seed 7).
fn grid_scene() -> Vec<Triangle> {
    use strahl::scene::Rng;
    let mut rng = Rng::new(7);
    let mut tris: Vec<Triangle> = Vec::new();
    for i in 0..150 {
        let p = Vec3::new((rng.u64() % 8) as f32, (rng.u64() % 8) as f32, (rng.u64() % 8) as f32);
        let (u, v) = match i % 3 {
            0 => (Vec3::X, Vec3::Y),
            1 => (Vec3::Y, Vec3::Z),
            _ => (Vec3::Z, Vec3::X),
        };
        tris.push([p, p + u, p + u + v]);
        tris.push([p, p + u + v, p + v]);
    }
    tris
}

/// A ray almost parallel to a grid quad's plane (x direction -1e-8), from a point on that
/// plane, `tmin = -inf`: Möller's `t` is ill-conditioned here (brute force and BVH8 once
/// reported a hit at t = -5.5 outside the triangle's box, which BVH4 and BVH2 never open; see
/// [`Moller`]'s docs). The watertight test gives every traversal the same answer.
#[test]
fn grazing_ray_behind_the_origin_is_the_same_everywhere_with_watertight() {
    let tris = grid_scene();
    let (b2, b4, b8) = trees(&tris);
    let r = Ray::with_range(
        Vec3::new(7.0, 6.5, 3.0),
        Vec3::new(-1e-8, 1.0, -0.5),
        f32::NEG_INFINITY,
        f32::INFINITY,
    );
    let bf = intersect_brute_force::<Watertight, _>(&tris[..], &r);
    let s8 = wide::intersect::<Watertight, _, 8>(b8.view(), &r);
    let s4 = wide::intersect::<Watertight, _, 4>(b4.view(), &r);
    let s2 = strahl::traverse::intersect_scalar::<Watertight, _>(b2.view(), &tris[..], &r);
    assert_eq!((s8, s4, s2), (bf, bf, bf));
    let mut bad = compare::<Watertight>(&tris, &[r]);
    bad.extend(compare::<Watertight>(&tris, &[r, Ray::new(r.origin, -r.direction)]));
    assert!(bad.is_empty(), "{bad:#?}");
}

/// A ray from a box's max-z plane with z direction 1e-8 that meets a quad's top edge: Möller
/// rounds a point 1.25e-9 above the edge into the triangle (t = 0.125; brute force once found it,
/// BVH2 did not, as the point is outside the triangle's box). Watertight rejects it everywhere and
/// every traversal finds the next hit, t = 0.625.
#[test]
fn edge_ray_from_a_box_plane_is_the_same_everywhere_with_watertight() {
    let tris = grid_scene();
    let (b2, b4, b8) = trees(&tris);
    let r = Ray::new(Vec3::new(-0.25, 3.25, 7.0), Vec3::new(2.0, 0.02, 1e-8));
    let bf = intersect_brute_force::<Watertight, _>(&tris[..], &r);
    assert_eq!(bf.map(|h| h.t), Some(0.625));
    let s8 = wide::intersect::<Watertight, _, 8>(b8.view(), &r);
    let s4 = wide::intersect::<Watertight, _, 4>(b4.view(), &r);
    let s2 = strahl::traverse::intersect_scalar::<Watertight, _>(b2.view(), &tris[..], &r);
    assert_eq!((s8, s4, s2), (bf, bf, bf));
    let bad = compare::<Watertight>(&tris, &[r]);
    assert!(bad.is_empty(), "{bad:#?}");
}
