//! Proptest strategies shared by the property tests.
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
use strahl::Vec3;

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
