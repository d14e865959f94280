//! Proptest strategies shared by the property tests, and the ray sets of the traversal tests
//! ([`mixed_rays`]).
//!
//! Three input modes, as in the house style:
//! - [`bounded`]: finite floats in `[-BOUND, BOUND]`. Bounded so that products of a few of them
//!   (cross products, determinants) stay finite and far from subnormal, where answers are
//!   well-conditioned and comparisons of `t` are meaningful.
//! - [`raw`]: any bit pattern, biased towards specials (NaN, +-inf, +-0, subnormals, MAX): only
//!   "no panic" and "SIMD equals scalar" can be asked of these.
//! - [`grid`]: small integers, where every product is exact and every answer unambiguous: SIMD,
//!   scalar and brute force must agree exactly.
#![allow(dead_code)]

use proptest::prelude::*;
use strahl::geometry::{Hit, Triangle};
use strahl::scene::Rng;
use strahl::{Ray, Vec3};

/// Bound of the [`bounded`] strategy.
pub const BOUND: f32 = 1.0e3;

/// Finite floats in `[-BOUND, BOUND]`.
pub fn bounded() -> impl Strategy<Value = f32> + Clone {
    -BOUND..=BOUND
}

/// Special values that every kernel must survive.
pub const SPECIALS: [f32; 12] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MIN_POSITIVE,
    1.0e-40, // subnormal
    -1.0e-40,
    f32::MAX,
    f32::MIN,
];

/// Any `f32` bit pattern, half the time one of [`SPECIALS`].
pub fn raw() -> impl Strategy<Value = f32> + Clone {
    prop_oneof![
        any::<u32>().prop_map(f32::from_bits),
        proptest::sample::select(&SPECIALS[..]),
        -4.0f32..4.0,
    ]
}

/// Integers in `[-4, 4]` as floats.
pub fn grid() -> impl Strategy<Value = f32> + Clone {
    (-4i32..=4).prop_map(|i| i as f32)
}

/// A `Vec3` from a scalar strategy.
pub fn vec3<S: Strategy<Value = f32> + Clone>(s: S) -> impl Strategy<Value = Vec3> + Clone {
    (s.clone(), s.clone(), s).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// The bounds of the finite vertices of `tris` (the unit cube where there are none).
pub fn bounds(tris: &[Triangle]) -> (Vec3, Vec3) {
    let b = tris
        .iter()
        .flatten()
        .filter(|v| v.is_finite())
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    if b.0.x <= b.1.x { b } else { (Vec3::ZERO, Vec3::ONE) }
}

/// Incoherent rays for traversal tests: aimed from outside, from inside in random directions,
/// axis-aligned with exact zeros and -0.0, limited ranges; then bad rays.
pub fn mixed_rays(tris: &[Triangle], n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed);
    let (lo, hi) = bounds(tris);
    let size = (hi - lo).max_element().max(1e-6);
    let mut out = Vec::with_capacity(n + 8);
    for i in 0..n {
        let r = match i % 4 {
            0 => {
                let t = tris[(rng.u64() % tris.len() as u64) as usize];
                let target = (t[0] + t[1] + t[2]) / 3.0;
                let o = (lo + hi) * 0.5 + rng.unit_vector() * size * 2.0;
                Ray::new(o, target - o)
            }
            1 => Ray::new(
                lo + (hi - lo) * Vec3::new(rng.f32(), rng.f32(), rng.f32()),
                rng.unit_vector(),
            ),
            2 => {
                let mut d = [0.0f32; 3];
                let a = (rng.u64() % 3) as usize;
                d[a] = if rng.f32() < 0.5 { 1.0 } else { -1.0 };
                for (k, x) in d.iter_mut().enumerate() {
                    if k != a && rng.f32() < 0.5 {
                        *x = -0.0;
                    }
                }
                Ray::new(
                    lo + (hi - lo) * Vec3::new(rng.f32(), rng.f32(), rng.f32()),
                    Vec3::from_array(d),
                )
            }
            _ => {
                let o = (lo + hi) * 0.5 + rng.unit_vector() * size;
                Ray::with_range(o, rng.unit_vector(), size * rng.f32() * 0.5, size * (0.5 + rng.f32()))
            }
        };
        out.push(r);
    }
    out.push(Ray::new(Vec3::NAN, Vec3::X));
    out.push(Ray::new(Vec3::ZERO, Vec3::new(f32::NAN, 1.0, 0.0)));
    out.push(Ray::new(Vec3::ZERO, Vec3::ZERO));
    out.push(Ray::new(Vec3::splat(f32::INFINITY), Vec3::X));
    out.push(Ray::with_range(lo, hi - lo, 1.0, 0.5));
    out
}

/// `a` and `b` are the same closest hit: the same `t` bits, and the same primitive unless both
/// primitives are hit at exactly that `t` (a tie).
pub fn same(a: Option<Hit>, b: Option<Hit>, tris: &[Triangle], ray: &Ray, what: &str) {
    match (a, b) {
        (None, None) => {}
        (Some(x), Some(y)) if x.t.to_bits() == y.t.to_bits() => {
            if x.prim != y.prim {
                // A tie: both triangles must be hit at exactly this t.
                let r = strahl::intersect::PreparedRay::new(ray);
                let t = |p: u32| strahl::intersect::watertight::intersect_scalar(&r, &tris[p as usize], p).map(|h| h.t);
                let m = |p: u32| strahl::intersect::moller::intersect_scalar(&r, &tris[p as usize], p).map(|h| h.t);
                assert!(
                    (t(x.prim) == Some(x.t) || m(x.prim) == Some(x.t))
                        && (t(y.prim) == Some(y.t) || m(y.prim) == Some(y.t)),
                    "{what}: different primitives {} and {} at t {}",
                    x.prim,
                    y.prim,
                    x.t
                );
            }
        }
        _ => panic!("{what}: {a:?} vs {b:?} for {ray:?}"),
    }
}

/// 100,000 small triangles in the unit cube (random positions, edges of 0.01 in random
/// directions, from `Rng::new(seed)`) and one far outlier at `1e7` (the last, index 100,000).
pub fn cube_and_far_outlier(seed: u64) -> Vec<Triangle> {
    let mut r = Rng::new(seed);
    let mut tris: Vec<Triangle> = (0..100_000)
        .map(|_| {
            let p = Vec3::new(r.f32(), r.f32(), r.f32());
            [p, p + r.unit_vector() * 0.01, p + r.unit_vector() * 0.01]
        })
        .collect();
    let far = Vec3::splat(1e7);
    tris.push([far, far + Vec3::X, far + Vec3::Y]);
    tris
}

/// `n` random triangles in a 10-unit cube: centres uniform, vertices within 0.3 of the centre in
/// random directions (from `Rng::new(seed)`).
pub fn random_soup(n: usize, seed: u64) -> Vec<Triangle> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let c = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 10.0;
            [
                c + rng.unit_vector() * 0.3,
                c + rng.unit_vector() * 0.3,
                c + rng.unit_vector() * 0.3,
            ]
        })
        .collect()
}
