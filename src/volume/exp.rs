//! `1 - exp(-y)` for `y >= 0` (the opacity of a step), written once as a sequence of IEEE operations and instantiated for one
//! `f32` and for [`f32x8`], so that the scalar marcher and the 8-wide marcher get the same bits.
//!
//! The method is Cephes' `expf` (S. Moshier): `n = round(x log2 e)` by the magic-number trick
//! (adding `1.5 2^23` rounds to the nearest integer, ties to even, and leaves `n` in the low
//! mantissa bits), a Cody-Waite reduction `r = x - n ln2` with `ln 2` split in two, a degree-5
//! polynomial for `exp(r)` on `|r| <= ln2 / 2`, and a scale by `2^n` built from the exponent bits.
//! No fused multiply-add and no table, so any target gives the same result.
//!
//! It returns `1 - 2^n exp(r)` as `(1 - 2^n) - 2^n (exp(r) - 1)` with `exp(r) - 1` from the
//! polynomial directly, so small `y` (where `n = 0`) lose nothing to cancellation. The reference
//! is `-expm1(-y)` in `f64`: see [`ONE_MINUS_EXP_NEG_MAX_EPS`].

use crate::math::{f32x8, i32x8, max_l, min_l};

/// Largest `y` taken as is; larger ones are clamped to it, where `exp(-y) = 1.6e-38` (still a
/// normal number) and `1 - exp(-y)` rounds to exactly `1`.
const Y_MAX: f32 = 87.0;
const LOG2E: f32 = core::f32::consts::LOG2_E;
/// `1.5 2^23`: adding it rounds a float of magnitude below `2^22` to an integer.
const MAGIC: f32 = 12_582_912.0;
/// `ln 2 = LN2_HI + LN2_LO`, `LN2_HI` with few mantissa bits so that `n LN2_HI` is exact.
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
const P0: f32 = 1.987_569_1e-4;
const P1: f32 = 1.398_2e-3;
const P2: f32 = 8.333_452e-3;
const P3: f32 = 4.166_579_6e-2;
const P4: f32 = 1.666_666_5e-1;
const P5: f32 = 0.5; // Cephes: 5.0000001201e-1, which is 0.5 in f32

/// Largest relative error of [`one_minus_exp_neg_scalar`] against `1 - exp(-y)` computed in
/// `f64`, over `y` in `[0, 87]`, in units of `f32::EPSILON` (checked densely by the tests below).
///
/// ```
/// use strahl::volume::{ONE_MINUS_EXP_NEG_MAX_EPS, one_minus_exp_neg_scalar};
/// for y in [1e-30f32, 1e-7, 0.01, 0.3, 1.0, 2.5, 17.0, 86.0] {
///     let exact = -(-(y as f64)).exp_m1();
///     let rel = ((one_minus_exp_neg_scalar(y) as f64 - exact) / exact).abs();
///     assert!(rel <= (ONE_MINUS_EXP_NEG_MAX_EPS * f32::EPSILON) as f64, "y = {y}");
/// }
/// ```
pub const ONE_MINUS_EXP_NEG_MAX_EPS: f32 = 2.0;

/// The opacity of a step, `1 - exp(-y)`, for one value `y >= 0`, accurate to a few ULP also for
/// tiny `y` (where `1 - exp(-y)` itself would cancel: `exp(-1e-9)` rounds to `1`).
///
/// `y` is clamped to `[0, 87]` first (a NaN becomes `0`). The result is `0` exactly for `y = 0`
/// (which empty-space skipping relies on), lies in `[0, 1]`, and is `1` for `y >= 87`. Agrees
/// with [`one_minus_exp_neg_x8`] bit for bit.
///
/// ```
/// use strahl::volume::one_minus_exp_neg_scalar as a;
/// assert_eq!(a(0.0), 0.0);
/// assert!((a(1.0) - (1.0 - (-1.0f64).exp()) as f32).abs() <= f32::EPSILON);
/// assert!((a(1e-9) / 1e-9 - 1.0).abs() < 1e-6); // no cancellation
/// assert_eq!(a(f32::INFINITY), 1.0);
/// assert_eq!(a(f32::NAN), 0.0);
/// ```
#[inline(always)]
pub fn one_minus_exp_neg_scalar(y: f32) -> f32 {
    // Clamp: NaN -> 0 (max_l returns its second operand on NaN).
    let y = min_l(max_l(y, 0.0), Y_MAX);
    let x = 0.0 - y;
    // n = round(x log2 e), also as bits in the low mantissa of `fx`.
    let fx = x * LOG2E + MAGIC;
    let n = fx - MAGIC;
    // r = x - n ln 2, in two parts (exact for n = 0).
    let r = x - n * LN2_HI;
    let r = r - n * LN2_LO;
    let z = r * r;
    let p = ((((P0 * r + P1) * r + P2) * r + P3) * r + P4) * r + P5;
    // exp(r) - 1, without cancellation.
    let em1 = p * z + r;
    // 2^n from the exponent bits: n in [-126, 0], so the exponent field n + 127 is in [1, 127].
    let nb = fx.to_bits().wrapping_sub(MAGIC.to_bits()) as i32;
    let scale = f32::from_bits(((nb + 127) as u32) << 23);
    // 1 - 2^n exp(r) = (1 - 2^n) - 2^n (exp(r) - 1); for n = 0 just -(exp(r) - 1).
    min_l((1.0 - scale) - scale * em1, 1.0)
}

/// `1 - exp(-y)` for eight values; lane `i` equals [`one_minus_exp_neg_scalar`]`(y[i])` bit for
/// bit.
///
/// ```
/// use strahl::math::f32x8;
/// use strahl::volume::{one_minus_exp_neg_scalar, one_minus_exp_neg_x8};
/// let y = [0.0, 1e-9, 0.5, 1.0, 10.0, 80.0, 1e9, f32::NAN];
/// let a = one_minus_exp_neg_x8(f32x8::new(y)).to_array();
/// for i in 0..8 {
///     assert_eq!(a[i].to_bits(), one_minus_exp_neg_scalar(y[i]).to_bits());
/// }
/// ```
#[inline(always)]
pub fn one_minus_exp_neg_x8(y: f32x8) -> f32x8 {
    use crate::math::Lane;
    let s = f32x8::splat;
    let y = y.max_l(s(0.0)).min_l(s(Y_MAX));
    let x = s(0.0) - y;
    let fx = x * s(LOG2E) + s(MAGIC);
    let n = fx - s(MAGIC);
    let r = x - n * s(LN2_HI);
    let r = r - n * s(LN2_LO);
    let z = r * r;
    let p = ((((s(P0) * r + s(P1)) * r + s(P2)) * r + s(P3)) * r + s(P4)) * r + s(P5);
    let em1 = p * z + r;
    let nb: i32x8 = bytemuck::cast::<f32x8, i32x8>(fx) - i32x8::splat(MAGIC.to_bits() as i32);
    let scale: f32x8 = bytemuck::cast((nb + i32x8::splat(127)) << 23u32);
    ((s(1.0) - scale) - scale * em1).min_l(s(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel_eps(y: f32) -> f32 {
        let want = -libm::expm1(-(y as f64));
        let got = one_minus_exp_neg_scalar(y) as f64;
        if want == 0.0 {
            return if got == 0.0 { 0.0 } else { f32::INFINITY };
        }
        ((got - want).abs() / want / f32::EPSILON as f64) as f32
    }

    #[test]
    fn accurate_over_the_whole_range() {
        let mut worst = 0.0f32;
        let n = 2_000_000;
        for i in 0..=n {
            worst = worst.max(rel_eps(Y_MAX * i as f32 / n as f32));
        }
        // Tiny and small y, where 1 - exp(-y) would cancel.
        let mut y = 1e-30f32;
        while y < 1.0 {
            worst = worst.max(rel_eps(y));
            y *= 1.0001;
        }
        assert!(worst <= ONE_MINUS_EXP_NEG_MAX_EPS, "worst {worst} eps");
    }

    #[test]
    fn edge_cases() {
        let a = one_minus_exp_neg_scalar;
        assert_eq!(a(0.0).to_bits(), 0.0f32.to_bits());
        assert_eq!(a(-0.0).to_bits(), 0.0f32.to_bits());
        assert_eq!(a(-5.0), 0.0); // negative y clamps to 0
        assert_eq!(a(f32::NAN), 0.0);
        assert_eq!(a(f32::INFINITY), 1.0);
        assert_eq!(a(Y_MAX), 1.0);
        assert_eq!(a(1e-40), 1e-40);
        // Monotone non-decreasing and within [0, 1] on a sweep.
        let mut prev = 0.0;
        for i in 0..200_000 {
            let v = a(i as f32 * 5e-4);
            assert!(v >= prev && v <= 1.0, "{i}");
            prev = v;
        }
    }

    #[test]
    fn lanes_equal_scalar() {
        let specials = [
            0.0,
            -0.0,
            1e-40,
            1e-7,
            0.3466,
            0.3467,
            0.5,
            1.0,
            10.0,
            86.9,
            87.0,
            88.0,
            1e30,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -1.0,
        ];
        let value = |i: usize| {
            if i < specials.len() {
                specials[i]
            } else {
                i as f32 * 0.0221
            }
        };
        for c in 0..500 {
            let y: [f32; 8] = core::array::from_fn(|l| value(c * 8 + l));
            let e = one_minus_exp_neg_x8(f32x8::new(y)).to_array();
            for i in 0..8 {
                assert_eq!(e[i].to_bits(), one_minus_exp_neg_scalar(y[i]).to_bits(), "y = {}", y[i]);
            }
        }
    }
}
