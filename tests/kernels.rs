//! Every SIMD kernel equals its scalar reference lane by lane, for the three input modes of
//! `common` (bounded, raw bits, integer grid).
//!
//! Stated tolerance: **0 ULP**. The kernels perform the same IEEE operations in the same order as
//! the references (no FMA), so hit/miss, primitive, `t`, `u` and `v` must be bit-identical.

mod common;

use common::{bounded, grid, raw, vec3};
use proptest::prelude::*;
use strahl::intersect::{
    AabbX4, AabbX8, HitLanes, PreparedPacket4, PreparedPacket8, PreparedRay, TriangleX4, TriangleX8,
    intersect_aabb_scalar, intersect_aabb_x4, intersect_aabb_x8, moller, watertight,
};
use strahl::{Aabb, Hit, Ray, Vec3, geometry::Triangle};

type Scalar = fn(&PreparedRay, &Triangle, u32) -> Option<Hit>;
const TESTS: [(&str, Scalar); 2] = [
    ("moller", moller::intersect_scalar),
    ("watertight", watertight::intersect_scalar),
];

fn same_hit(a: Option<Hit>, b: Option<Hit>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            a.prim == b.prim
                && a.t.to_bits() == b.t.to_bits()
                && a.u.to_bits() == b.u.to_bits()
                && a.v.to_bits() == b.v.to_bits()
        }
        _ => false,
    }
}

/// Closest hit over `tris` by the scalar reference (ties: first).
fn scalar_closest(f: Scalar, ray: &PreparedRay, tris: &[Triangle]) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for (i, t) in tris.iter().enumerate() {
        if let Some(h) = f(ray, t, i as u32)
            && best.is_none_or(|b| h.t < b.t)
        {
            best = Some(h);
        }
    }
    best
}

fn check_triangles(ray: &Ray, tris: &[Triangle; 8]) -> Result<(), TestCaseError> {
    let pre = PreparedRay::new(ray);
    let prims: Vec<u32> = (0..8).collect();
    let x4 = TriangleX4::pack(&tris[..4], &prims);
    let x8 = TriangleX8::pack(tris, &prims);
    for (name, f) in TESTS {
        let (i4, i8, m4, m8): (Option<Hit>, Option<Hit>, u32, u32) = if name == "moller" {
            (
                moller::intersect_x4(&pre, &x4),
                moller::intersect_x8(&pre, &x8),
                moller::hit_mask(&pre, &x4),
                moller::hit_mask(&pre, &x8),
            )
        } else {
            (
                watertight::intersect_x4(&pre, &x4),
                watertight::intersect_x8(&pre, &x8),
                watertight::hit_mask(&pre, &x4),
                watertight::hit_mask(&pre, &x8),
            )
        };
        for (i, t) in tris.iter().enumerate() {
            let s = f(&pre, t, i as u32).is_some();
            prop_assert_eq!(s, m8 >> i & 1 == 1, "{} x8 lane {}", name, i);
            if i < 4 {
                prop_assert_eq!(s, m4 >> i & 1 == 1, "{} x4 lane {}", name, i);
            }
        }
        prop_assert!(
            same_hit(i4, scalar_closest(f, &pre, &tris[..4])),
            "{} x4 {:?}",
            name,
            i4
        );
        prop_assert!(same_hit(i8, scalar_closest(f, &pre, tris)), "{} x8 {:?}", name, i8);
        if let Some(h) = i8 {
            prop_assert!(h.t >= pre.tmin && h.t < pre.tmax, "t outside [tmin, tmax)");
        }
    }
    Ok(())
}

fn check_packets(rays: &[Ray; 8], tri: &Triangle) -> Result<(), TestCaseError> {
    for (name, f) in TESTS {
        let mut p8 = PreparedPacket8::new(rays);
        let mut h8 = HitLanes::default();
        let mut p4 = PreparedPacket4::new(&rays[..4]);
        let mut h4 = HitLanes::default();
        let (m8, m4) = if name == "moller" {
            (
                moller::intersect_packet(&mut p8, tri, 5, &mut h8),
                moller::intersect_packet(&mut p4, tri, 5, &mut h4),
            )
        } else {
            (
                watertight::intersect_packet(&mut p8, tri, 5, &mut h8),
                watertight::intersect_packet(&mut p4, tri, 5, &mut h4),
            )
        };
        for (i, r) in rays.iter().enumerate() {
            let s = f(&PreparedRay::new(r), tri, 5);
            prop_assert_eq!(s.is_some(), m8 >> i & 1 == 1, "{} packet8 lane {}", name, i);
            prop_assert!(
                same_hit(s, h8.get(i).is_hit().then(|| h8.get(i))),
                "{} packet8 lane {}",
                name,
                i
            );
            if i < 4 {
                prop_assert_eq!(s.is_some(), m4 >> i & 1 == 1, "{} packet4 lane {}", name, i);
                prop_assert!(
                    same_hit(s, h4.get(i).is_hit().then(|| h4.get(i))),
                    "{} packet4 lane {}",
                    name,
                    i
                );
            }
        }
    }
    Ok(())
}

fn check_boxes(ray: &Ray, boxes: &[Aabb; 8]) -> Result<(), TestCaseError> {
    let pre = PreparedRay::new(ray);
    let (n4, m4) = intersect_aabb_x4(&pre, &AabbX4::from_boxes(&boxes[..4]));
    let (n8, m8) = intersect_aabb_x8(&pre, &AabbX8::from_boxes(boxes));
    for (i, b) in boxes.iter().enumerate() {
        let s = intersect_aabb_scalar(&pre, b);
        prop_assert_eq!(s.is_some(), m8 >> i & 1 == 1, "x8 lane {}", i);
        if let Some(t) = s {
            prop_assert_eq!(t.to_bits(), n8.to_array()[i].to_bits());
            prop_assert!(!t.is_nan());
        }
        if i < 4 {
            prop_assert_eq!(s.is_some(), m4 >> i & 1 == 1, "x4 lane {}", i);
            if let Some(t) = s {
                prop_assert_eq!(t.to_bits(), n4.to_array()[i].to_bits());
            }
        }
    }
    Ok(())
}

/// A ray from a random origin towards a random point of triangle `k` (so hits are common), or in a
/// random direction; random `[tmin, tmax)`.
fn ray_towards<S: Strategy<Value = f32> + Clone + 'static>(s: S, tris: [Triangle; 8]) -> impl Strategy<Value = Ray> {
    (
        vec3(s.clone()),
        vec3(s),
        0usize..8,
        0.0f32..1.0,
        0.0f32..1.0,
        any::<bool>(),
        0u8..4,
    )
        .prop_map(move |(o, d, k, a, b, aim, range)| {
            let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
            let tri = tris[k];
            let target = tri[0] + (tri[1] - tri[0]) * a + (tri[2] - tri[0]) * b;
            let dir = if aim { target - o } else { d };
            let (tmin, tmax) = match range {
                0 => (0.0, f32::INFINITY),
                1 => (0.5, 1.5),
                2 => (1.0, 1.0),
                _ => (0.0, 0.999),
            };
            Ray::with_range(o, dir, tmin, tmax)
        })
}

fn scene<S: Strategy<Value = f32> + Clone + 'static>(s: S) -> impl Strategy<Value = (Ray, [Triangle; 8])> {
    let tri = (vec3(s.clone()), vec3(s.clone()), vec3(s.clone())).prop_map(|(a, b, c)| [a, b, c]);
    proptest::array::uniform8(tri).prop_flat_map(move |tris| (ray_towards(s.clone(), tris), Just(tris)))
}

fn raw_ray() -> impl Strategy<Value = Ray> {
    (vec3(raw()), vec3(raw()), raw(), raw()).prop_map(|(o, d, t0, t1)| Ray::with_range(o, d, t0, t1))
}

fn boxes<S: Strategy<Value = f32> + Clone + 'static>(s: S) -> impl Strategy<Value = [Aabb; 8]> {
    proptest::array::uniform8((vec3(s.clone()), vec3(s), any::<bool>()).prop_map(|(a, b, sorted)| {
        if sorted {
            Aabb::new(a.min(b), a.max(b))
        } else {
            Aabb::new(a, b)
        }
    }))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn triangles_bounded((ray, tris) in scene(bounded())) {
        check_triangles(&ray, &tris)?;
    }

    #[test]
    fn triangles_grid((ray, tris) in scene(grid())) {
        check_triangles(&ray, &tris)?;
    }

    #[test]
    fn triangles_raw_bits(ray in raw_ray(), tris in proptest::array::uniform8((vec3(raw()), vec3(raw()), vec3(raw())).prop_map(|(a, b, c)| [a, b, c]))) {
        check_triangles(&ray, &tris)?;
    }

    #[test]
    fn triangles_raw_rays_bounded_scene((_, tris) in scene(bounded()), ray in raw_ray()) {
        check_triangles(&ray, &tris)?;
    }

    #[test]
    fn packets_bounded((r0, tris) in scene(bounded()), rays in proptest::array::uniform8(raw_ray())) {
        // Lane 0 aims at the triangle; the others are raw.
        let mut rays = rays;
        rays[0] = r0;
        check_packets(&rays, &tris[0])?;
    }

    #[test]
    fn packets_grid(tris in proptest::array::uniform8((vec3(grid()), vec3(grid()), vec3(grid())).prop_map(|(a, b, c)| [a, b, c]))
        .prop_flat_map(|tris| (Just(tris), proptest::array::uniform8(ray_towards(grid(), tris))))) {
        let (tris, rays) = tris;
        check_packets(&rays, &tris[0])?;
    }

    #[test]
    fn packets_coherent((r0, tris) in scene(bounded()), origins in proptest::array::uniform8(vec3(bounded())), invalid in 0u8..=255) {
        // One direction for every lane (the watertight packet kernel's shared-permutation path),
        // some lanes invalid (NaN origin) so that they are inactive.
        let rays: [Ray; 8] = core::array::from_fn(|i| {
            let o = if invalid >> i & 1 == 1 && i > 0 { Vec3::NAN } else if i == 0 { r0.origin } else { origins[i] };
            Ray::new(o, r0.direction)
        });
        check_packets(&rays, &tris[0])?;
    }

    #[test]
    fn boxes_bounded(ray in (vec3(bounded()), vec3(bounded())).prop_map(|(o, d)| Ray::new(o, d)), b in boxes(bounded())) {
        check_boxes(&ray, &b)?;
    }

    #[test]
    fn boxes_grid(ray in (vec3(grid()), vec3(grid())).prop_map(|(o, d)| Ray::new(o, d)), b in boxes(grid())) {
        check_boxes(&ray, &b)?;
    }

    #[test]
    fn boxes_raw_bits(ray in raw_ray(), b in boxes(raw())) {
        check_boxes(&ray, &b)?;
    }
}

/// On the integer grid a ray from a grid point hits a box iff the box, intersected with the ray's
/// exact parametric range, is non-empty: checked against exact rational arithmetic.
#[test]
fn boxes_grid_against_exact() {
    let mut rng = 0x1234_5678_9abc_def0u64;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng % 9) as i64 - 4
    };
    for _ in 0..200_000 {
        let o = [next(), next(), next()];
        let d = [next(), next(), next()];
        let (mut lo, mut hi) = ([0i64; 3], [0i64; 3]);
        for a in 0..3 {
            let (p, q) = (next(), next());
            lo[a] = p.min(q);
            hi[a] = p.max(q);
        }
        if d == [0, 0, 0] {
            continue;
        }
        // Exact: the set of t >= 0 with lo <= o + t d <= hi, as fractions num/den with den > 0.
        let (mut tn_num, mut tn_den) = (0i64, 1i64); // near = 0
        let (mut tf_num, mut tf_den, mut tf_inf) = (0i64, 1i64, true);
        let mut empty = false;
        for a in 0..3 {
            if d[a] == 0 {
                if o[a] < lo[a] || o[a] > hi[a] {
                    empty = true;
                }
                continue;
            }
            let (mut n, mut f) = ((lo[a] - o[a], d[a]), (hi[a] - o[a], d[a]));
            if d[a] < 0 {
                n = (-(hi[a] - o[a]), -d[a]);
                f = (-(lo[a] - o[a]), -d[a]);
            }
            if n.0 * tn_den > tn_num * n.1 {
                (tn_num, tn_den) = n;
            }
            if tf_inf || f.0 * tf_den < tf_num * f.1 {
                (tf_num, tf_den, tf_inf) = (f.0, f.1, false);
            }
        }
        let exact = !empty && (tf_inf || tn_num * tf_den <= tf_num * tn_den);
        let to = |v: [i64; 3]| Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
        let ray = PreparedRay::new(&Ray::new(to(o), to(d)));
        let b = Aabb::new(to(lo), to(hi));
        let got = intersect_aabb_scalar(&ray, &b).is_some();
        // Conservative: never a false miss. A false hit may only happen within rounding of a touch.
        assert!(!exact || got, "false miss: o {o:?} d {d:?} box {lo:?}..{hi:?}");
        if got && !exact {
            // The exact near/far gap must be tiny relative to the distances.
            let gap = tn_num as f64 / tn_den as f64 - tf_num as f64 / tf_den as f64;
            assert!(
                gap <= 1e-5 * (tn_num as f64 / tn_den as f64).abs().max(1.0),
                "false hit: o {o:?} d {d:?} box {lo:?}..{hi:?}"
            );
        }
    }
}
