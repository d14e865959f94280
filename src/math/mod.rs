//! Lane types and float helpers shared by every kernel.
//!
//! Every SIMD kernel in strahl is written once over the [`Lane`] trait and instantiated for
//! [`f32x4`] and [`f32x8`] (from the `wide` crate). The scalar references use the free functions
//! [`max_l`] and [`min_l`], whose NaN behaviour is defined to match the lane versions exactly, so a
//! scalar kernel and a wide kernel that perform the same operations in the same order give
//! bit-identical results.
//!
//! # NaN policy of `max_l` / `min_l`
//!
//! `max_l(a, b)` returns `a` if `a > b`, otherwise `b`; `min_l(a, b)` returns `a` if `a < b`,
//! otherwise `b`. If either operand is NaN the **second** operand is returned. This is exactly the
//! behaviour of x86's `MAXPS`/`MINPS`, and the kernels use it on purpose: an accumulator passed as
//! the second operand ignores NaN candidates (see the slab test in
//! [`intersect::aabb`](crate::intersect::aabb)).
//!
//! # Width selection
//!
//! `wide` picks its implementation from the compile-time target features: with AVX (for example
//! `-C target-cpu=native` on a recent x86-64), [`f32x8`] is one 256-bit register; without it, two
//! 128-bit halves. Results are identical either way.

mod lanes;

pub use lanes::Lane;
pub use wide::{f32x4, f32x8, f32x16, i32x4, i32x8, u32x4, u32x8};

/// Returns `a` if `a > b`, else `b` (so a NaN in either operand yields `b`).
///
/// ```
/// use strahl::math::max_l;
/// assert_eq!(max_l(2.0, 1.0), 2.0);
/// assert_eq!(max_l(f32::NAN, 1.0), 1.0);
/// assert!(max_l(1.0, f32::NAN).is_nan());
/// ```
#[inline(always)]
pub fn max_l(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// Returns `a` if `a < b`, else `b` (so a NaN in either operand yields `b`).
///
/// ```
/// use strahl::math::min_l;
/// assert_eq!(min_l(2.0, 1.0), 1.0);
/// assert_eq!(min_l(f32::NAN, 1.0), 1.0);
/// ```
#[inline(always)]
pub fn min_l(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// Machine epsilon of `f32` as used in error analysis: half an ULP of 1, `2^-24`.
///
/// ```
/// use strahl::math::UNIT_ROUNDOFF;
/// assert_eq!(UNIT_ROUNDOFF, 2f32.powi(-24));
/// assert_eq!(1.0 + UNIT_ROUNDOFF, 1.0); // a tie, rounded to even
/// ```
pub const UNIT_ROUNDOFF: f32 = f32::EPSILON * 0.5;

/// The error bound `gamma(n) = n u / (1 - n u)` of Higham (and pbrt), `u` = [`UNIT_ROUNDOFF`].
///
/// A value computed with `n` rounded operations lies within a relative `gamma(n)` of the exact
/// result.
///
/// ```
/// let g = strahl::math::gamma(3);
/// assert!(g > 3.0 * f32::EPSILON / 2.0 && g < 3.0 * f32::EPSILON);
/// ```
#[inline]
pub const fn gamma(n: u32) -> f32 {
    let nu = n as f32 * UNIT_ROUNDOFF;
    nu / (1.0 - nu)
}

/// Absolute value of an `f32` without `std` (clears the sign bit).
///
/// ```
/// use strahl::math::abs;
/// assert_eq!(abs(-2.5), 2.5);
/// assert!(abs(-0.0).is_sign_positive());
/// assert_eq!(abs(f32::NEG_INFINITY), f32::INFINITY);
/// ```
#[inline(always)]
pub fn abs(x: f32) -> f32 {
    f32::from_bits(x.to_bits() & 0x7fff_ffff)
}

/// `ceil(x)`: `std`'s where the crate has it (one instruction with SSE4.1), else `libm`'s; the
/// same IEEE result either way.
///
/// ```
/// assert_eq!(strahl::math::ceil(2.25), 3.0);
/// assert_eq!(strahl::math::ceil(-2.25), -2.0);
/// ```
#[inline(always)]
pub fn ceil(x: f32) -> f32 {
    #[cfg(feature = "std")]
    return x.ceil();
    #[cfg(not(feature = "std"))]
    return libm::ceilf(x);
}

/// `true` if the sign bit of `x` is set (also for `-0.0` and negative NaNs).
///
/// ```
/// use strahl::math::sign_bit;
/// assert!(sign_bit(-1.0) && sign_bit(-0.0) && sign_bit(-f32::NAN));
/// assert!(!sign_bit(0.0) && !sign_bit(1.0));
/// ```
#[inline(always)]
pub fn sign_bit(x: f32) -> bool {
    x.to_bits() >> 31 != 0
}

/// Asks the cache for the line holding `p` (a hint: nothing is read, and an address that is not
/// valid is fine; x86-64 only, a no-op elsewhere).
#[inline(always)]
pub(crate) fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: SSE is part of every x86_64 target; a prefetch reads nothing and never faults,
        // whatever the address.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}
