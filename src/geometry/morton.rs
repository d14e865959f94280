//! Morton codes (Z-order keys) of points in a bounding box: the first stage of an LBVH build.
//!
//! Pipeline stage: a linear BVH builder (Lauterbach et al., "Fast BVH Construction on GPUs",
//! 2009; Karras, "Maximizing Parallelism in the Construction of BVHs, Octrees, and k-d Trees",
//! 2012) quantises every primitive centroid to a grid over the scene bounds, interleaves the bits
//! of the three grid coordinates into one integer, sorts the primitives by that integer and splits
//! the sorted list where the codes' leading bits change. This module is the first step.
//!
//! Input: points (primitive centroids) as `&[Vec3]` or as three `&[f32]` (structure of arrays),
//! and a [`MortonQuantizer`] built once from their bounds. Output: codes written to a
//! caller-provided slice, 30-bit in a `u32` (10 bits per axis) or 63-bit in a `u64` (21 bits per
//! axis). Nothing here allocates, and nothing panics, whatever the input (NaN, infinities,
//! empty or inverted bounds, slices of different lengths).
//!
//! | stage | scalar reference | 8 lanes | slices |
//! |---|---|---|---|
//! | quantise | [`MortonQuantizer::quantize_scalar`] | [`MortonQuantizer::quantize_x8`] | |
//! | 30-bit code | [`morton30_scalar`] (= [`encode30`] of the above) | [`morton30_x8`] | [`morton30_slice`], [`morton30_slice_soa`] |
//! | 63-bit code | [`morton63_scalar`] (= [`encode63`] of the above) | [`morton63_x8`] | [`morton63_slice`], [`morton63_slice_soa`] |
//!
//! # Quantisation
//!
//! With `bits` bits per axis (10 or 21) there are `levels = 2^bits` cells per axis. Per axis,
//! [`MortonQuantizer::new`] computes `scale = levels / (max - min)` once, and each coordinate `p`
//! becomes
//!
//! ```text
//! q    = (p - min) * scale                      two f32 operations, in this order, no FMA
//! cell = trunc(min_l(max_l(q, 0), levels - 1))  clamp (a NaN q becomes 0), then truncate
//! ```
//!
//! where [`max_l`] and [`min_l`] return their **second** operand when either is NaN (as x86
//! `MAXPS`/`MINPS` do). The scalar and the 8-lane kernels perform exactly these operations in
//! this order, so their codes agree bit for bit on every input (checked by `tests/morton.rs`).
//! `f32` has 24 mantissa bits, so even 21-bit cell indices are exact.
//!
//! # Policy (identical in every width)
//!
//! - **The maximum corner** maps to `levels - 1` on every axis, so `bounds.max` gets the all-ones
//!   code ([`MORTON30_MAX`], [`MORTON63_MAX`]) and never wraps to 0: `(max - min) * scale` may round
//!   to `levels` or a hair below, and the clamp sends both to the last cell.
//! - **The minimum corner** maps to cell 0, code 0.
//! - **Points outside the bounds** clamp to the first or last cell of each axis.
//! - **A flat axis** (extent zero, negative or not finite; also a positive extent so small that
//!   `levels / extent` overflows) gets `scale = 0` instead of an infinite or NaN scale, and every
//!   point quantises to cell 0 on it. The empty box [`Aabb::EMPTY`] and boxes with a NaN bound are
//!   flat on every axis: all their codes are 0.
//! - **A NaN coordinate** quantises to cell 0 on that axis; `+inf` to the last cell (or 0 on a flat
//!   axis, where `inf * 0` is NaN); `-inf` to cell 0.
//! - **Order.** Cells, and hence codes, never decrease when one coordinate grows and the others
//!   stay put (every step of the rule is monotone), so sorting by code is a Z-order sort.
//!
//! # Bit layout
//!
//! The bits of the three cell indices are interleaved with `x` the most significant bit of each
//! triple (as in Karras 2012):
//!
//! ```text
//! 30-bit code (u32), 10 bits per axis:
//!
//!   bit  31 30 | 29 28 27 | 26 25 24 | ... |  5  4  3 |  2  1  0
//!         0  0 | x9 y9 z9 | x8 y8 z8 | ... | x1 y1 z1 | x0 y0 z0
//!
//! 63-bit code (u64), 21 bits per axis:
//!
//!   bit  63 |  62  61  60 |  59  58  57 | ... |  2  1  0
//!         0 | x20 y20 z20 | x19 y19 z19 | ... | x0 y0 z0
//! ```
//!
//! Each axis is "spread" (Morton's part1by2: two zero bits inserted after every bit) with a few
//! shift/or/mask steps that move ever smaller groups of bits apart, then the three spread values
//! are combined as `(spread(x) << 2) | (spread(y) << 1) | spread(z)`. For 10 bits in a `u32`:
//!
//! ```text
//!   v               ---- ---- ---- ---- ---- --98 7654 3210
//!   (v | v << 16)   ---- --98 ---- ---- ---- ---- 7654 3210   & 0x0300_00FF
//!   (v | v <<  8)   ---- --98 ---- ---- 7654 ---- ---- 3210   & 0x0300_F00F
//!   (v | v <<  4)   ---- --98 ---- 76-- --54 ---- 32-- --10   & 0x030C_30C3
//!   (v | v <<  2)   ---- 9--8 --7- -6-- 5--4 --3- -2-- 1--0   & 0x0924_9249
//! ```
//!
//! The 8-lane kernels do the same in six operations per axis instead of thirteen: one byte shuffle
//! and a mask do the first two steps (they only move whole bytes and nibbles), and a multiply by
//! `5 << s` does the last step together with the final `<< s` (see `spread_x8_shuffle`). Targets
//! without byte shuffles and 32-bit multiplies (plain SSE2) use the shift steps; both forms are
//! compiled everywhere and tested against each other. No `pdep` (BMI2): it is microcoded and slow
//! on AMD Zen 1 and 2.
//!
//! # Performance
//!
//! The 8-lane kernels use `wide`'s [`f32x8`]/[`u32x8`]; build with `-C target-cpu=native` (or at
//! least AVX2) so that each is one 256-bit register. The 63-bit kernel never touches 64-bit
//! lanes: the low and high 32-bit words of the code are interleaved separately, from the low 10 or
//! 11 and the high 11 or 10 bits of each cell index, and zipped at the end. The AoS slice
//! functions read eight `Vec3` (96 bytes) at a time and transpose them to three [`f32x8`] with two
//! blends and one permute per axis; the SoA ones load the lanes directly and are the fastest.
//!
//! Measured with `benches/morton.rs` on one core of an AMD EPYC (Zen 3, AVX2), 2^20 points in the
//! unit cube, codes per second:
//!
//! | | scalar | x8 | slice (AoS) | slice (SoA) |
//! |---|---|---|---|---|
//! | 30-bit | 0.25 G | 1.6 G | 1.1 G | 1.65 G |
//! | 63-bit | 0.18 G | 0.88 G | 0.61 G | 0.90 G |
//!
//! [`max_l`]: crate::math::max_l
//! [`min_l`]: crate::math::min_l

use crate::geometry::Aabb;
use crate::math::{Lane, f32x8, max_l, min_l, u32x8};
use glam::Vec3;

/// Bits per axis of a 30-bit code ([`morton30_scalar`] and friends).
///
/// ```
/// use strahl::geometry::morton::{BITS_PER_AXIS_30, MORTON30_MAX};
/// assert_eq!(3 * BITS_PER_AXIS_30, 30);
/// assert_eq!(MORTON30_MAX, (1 << (3 * BITS_PER_AXIS_30)) - 1);
/// ```
pub const BITS_PER_AXIS_30: u32 = 10;
/// Bits per axis of a 63-bit code ([`morton63_scalar`] and friends).
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::{BITS_PER_AXIS_63, MortonQuantizer}};
/// assert_eq!(3 * BITS_PER_AXIS_63, 63);
/// assert_eq!(MortonQuantizer::new63(&Aabb::new(Vec3::ZERO, Vec3::ONE)).bits(), BITS_PER_AXIS_63);
/// ```
pub const BITS_PER_AXIS_63: u32 = 21;
/// The largest 30-bit code, that of the maximum corner: `0x3FFF_FFFF`.
///
/// ```
/// use strahl::geometry::morton::{MORTON30_MAX, encode30};
/// assert_eq!(encode30([1023, 1023, 1023]), MORTON30_MAX);
/// ```
pub const MORTON30_MAX: u32 = (1 << 30) - 1;
/// The largest 63-bit code, that of the maximum corner: `2^63 - 1`.
///
/// ```
/// use strahl::geometry::morton::{MORTON63_MAX, encode63};
/// let top = (1 << 21) - 1;
/// assert_eq!(encode63([top, top, top]), MORTON63_MAX);
/// ```
pub const MORTON63_MAX: u64 = (1 << 63) - 1;

/// Maps points in a box to integer grid cells, `2^bits` cells per axis (see the
/// [module docs](self) for the rule and its edge cases).
///
/// Build it once per point set from the points' bounds, with [`new30`](Self::new30) for the
/// 30-bit kernels ([`morton30_scalar`], [`morton30_x8`], [`morton30_slice`], ...) or
/// [`new63`](Self::new63) for the 63-bit ones. A quantiser with more bits per axis than a kernel's
/// code holds still gives codes without panicking, but only the low bits of each cell are kept and
/// the codes lose their order; one with fewer bits gives ordered codes with unused high bits.
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer};
/// let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::new(1.0, 2.0, 0.0)));
/// assert_eq!(q.quantize_scalar(Vec3::new(0.5, 0.5, 0.0)), [512, 256, 0]);
/// assert_eq!(q.quantize_scalar(Vec3::new(1.0, 2.0, 0.0)), [1023, 1023, 0]); // max corner, flat z
/// assert_eq!(q.quantize_scalar(Vec3::new(-5.0, f32::NAN, 7.0)), [0, 0, 0]); // clamped, NaN -> 0
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MortonQuantizer {
    /// Lower corner of the bounds: the origin of cell 0.
    min: Vec3,
    /// Cells per unit length on each axis; 0 on a flat axis.
    scale: Vec3,
    /// `levels - 1` as `f32`: the index of the last cell.
    top: f32,
    /// Bits per axis.
    bits: u32,
}

impl MortonQuantizer {
    /// A quantiser with `2^bits_per_axis` cells per axis over `bounds`; `bits_per_axis` is
    /// clamped to at most 21 (the 63-bit code). `bits_per_axis = 0` puts everything in cell 0.
    ///
    /// Per axis `scale = 2^bits / extent`, or 0 where the extent is zero, negative or not finite,
    /// or where that division overflows (a flat axis).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer};
    /// let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    /// assert_eq!(MortonQuantizer::new(&b, 10), MortonQuantizer::new30(&b));
    /// let q4 = MortonQuantizer::new(&b, 4);
    /// assert_eq!(q4.quantize_scalar(Vec3::ONE), [15, 15, 15]);
    /// assert_eq!(MortonQuantizer::new(&b, 99).bits(), 21);
    /// ```
    pub fn new(bounds: &Aabb, bits_per_axis: u32) -> Self {
        let bits = bits_per_axis.min(BITS_PER_AXIS_63);
        let levels = (1u32 << bits) as f32;
        let e = bounds.extent();
        let axis = |e: f32| {
            let s = levels / e;
            // NOTE: `e > 0` is false for NaN, so NaN and inverted (empty) bounds are flat too.
            if e > 0.0 && e.is_finite() && s.is_finite() {
                s
            } else {
                0.0
            }
        };
        Self {
            min: bounds.min,
            scale: Vec3::new(axis(e.x), axis(e.y), axis(e.z)),
            top: levels - 1.0,
            bits,
        }
    }

    /// [`new`](Self::new) with cells as close to cubes as powers of two allow: the *extended*
    /// Morton codes of Vinkler, Bittner and Havran ("Extended Morton Codes for High Performance
    /// Bounding Volume Hierarchy Construction", HPG 2017) in their simplest form. An axis whose
    /// extent `e` is `d` halvings shorter than the longest extent `E` (`d` the integer nearest
    /// `log2(E / e)`, at most `bits_per_axis`) gets cells `2^d` times as long, `scale = 2^bits /
    /// (2^d e)`: its cell index stays below about `2^(bits - d)`, so the code's first `d` levels
    /// split only the longer axes and its cells stay near-cubic all the way down. That axis's
    /// top `d` bits stay 0 (the paper hands their resolution to the longer axes; here it is left
    /// unused).
    ///
    /// On a plain Morton curve every level halves all three axes whatever their lengths, so on a
    /// flat scene (a terrain, a building's floor) the cells are as flat as the scene and the short
    /// axis is cut as often as the long ones. LBVH and PLOC trees over such scenes are much
    /// better with these codes (the 1M-triangle terrain, 5:1: SAH cost 53% above the full sweep's
    /// -> 25%; measured in [`build`](crate::build#measured)). Where every extent is within a
    /// factor `sqrt(2)` of the longest, `d = 0` on every axis and this is [`new`](Self::new).
    ///
    /// Same rule and policy as [`new`](Self::new) otherwise (flat axes, NaN, clamping), except
    /// that on a shortened axis the maximum corner maps to cell `2^(bits - d)` (or one below,
    /// by rounding), not `2^bits - 1`: cells stay monotone in the coordinate.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer};
    /// // A 4 x 1 x 1.2 box: y and z are two halvings shorter than x (4 / 1.2 = 3.3 rounds to 4).
    /// let b = Aabb::new(Vec3::ZERO, Vec3::new(4.0, 1.0, 1.2));
    /// let q = MortonQuantizer::new_extended(&b, 10);
    /// assert_eq!(q.scale(), Vec3::new(1024.0 / 4.0, 1024.0 / 4.0, 1024.0 / 4.8));
    /// assert_eq!(q.quantize_scalar(Vec3::new(2.0, 0.5, 0.6)), [512, 128, 128]);
    /// // Near-cubic boxes are quantised as by `new`.
    /// let c = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 0.8, 1.1));
    /// assert_eq!(MortonQuantizer::new_extended(&c, 10), MortonQuantizer::new30(&c));
    /// ```
    pub fn new_extended(bounds: &Aabb, bits_per_axis: u32) -> Self {
        let mut q = Self::new(bounds, bits_per_axis);
        let e = bounds.extent();
        let longest = e.x.max(e.y).max(e.z);
        let shorten = |scale: f32, e: f32| {
            // NOTE: flat axes (scale 0: extent zero, negative, NaN or infinite) keep theirs, and
            // beside an infinite extent no axis is shortened.
            if scale == 0.0 || !longest.is_finite() {
                return scale;
            }
            // The nearest integer to log2(longest / e): halve while e 2^d sqrt(2) < longest.
            let mut d = 0;
            let mut len = e * core::f32::consts::SQRT_2;
            while d < q.bits && len < longest {
                len *= 2.0;
                d += 1;
            }
            scale / (1u32 << d) as f32
        };
        q.scale = Vec3::new(
            shorten(q.scale.x, e.x),
            shorten(q.scale.y, e.y),
            shorten(q.scale.z, e.z),
        );
        q
    }

    /// The quantiser of 30-bit codes: 10 bits, 1024 cells per axis.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer};
    /// let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::splat(1024.0)));
    /// assert_eq!(q.bits(), 10);
    /// assert_eq!(q.quantize_scalar(Vec3::new(3.5, 1023.0, 1024.0)), [3, 1023, 1023]);
    /// ```
    pub fn new30(bounds: &Aabb) -> Self {
        Self::new(bounds, BITS_PER_AXIS_30)
    }

    /// The quantiser of 63-bit codes: 21 bits, 2^21 cells per axis.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer};
    /// let q = MortonQuantizer::new63(&Aabb::new(Vec3::ZERO, Vec3::ONE));
    /// assert_eq!(q.bits(), 21);
    /// assert_eq!(q.quantize_scalar(Vec3::new(0.5, 1.0, 0.0)), [1 << 20, (1 << 21) - 1, 0]);
    /// ```
    pub fn new63(bounds: &Aabb) -> Self {
        Self::new(bounds, BITS_PER_AXIS_63)
    }

    /// Bits per axis (10 for [`new30`](Self::new30), 21 for [`new63`](Self::new63)).
    ///
    /// ```
    /// use strahl::{Aabb, geometry::morton::MortonQuantizer};
    /// assert_eq!(MortonQuantizer::new63(&Aabb::EMPTY).bits(), 21);
    /// ```
    #[inline]
    pub fn bits(&self) -> u32 {
        self.bits
    }

    /// The origin of cell 0 (the `min` corner of the bounds).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer};
    /// let q = MortonQuantizer::new30(&Aabb::new(Vec3::NEG_ONE, Vec3::ONE));
    /// assert_eq!(q.origin(), Vec3::NEG_ONE);
    /// ```
    #[inline]
    pub fn origin(&self) -> Vec3 {
        self.min
    }

    /// Cells per unit length on each axis (0 on a flat axis). A cell `c` on an axis covers
    /// `origin + [c, c + 1) / scale`.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer};
    /// let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::new(2.0, 0.0, f32::NAN)));
    /// assert_eq!(q.scale(), Vec3::new(512.0, 0.0, 0.0));
    /// ```
    #[inline]
    pub fn scale(&self) -> Vec3 {
        self.scale
    }

    /// The cell of `p`: `trunc(min_l(max_l((p - min) * scale, 0), 2^bits - 1))` per axis (the
    /// scalar reference of [`quantize_x8`](Self::quantize_x8)).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer};
    /// let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::ONE));
    /// assert_eq!(q.quantize_scalar(Vec3::new(0.25, 2.0, f32::INFINITY)), [256, 1023, 1023]);
    /// assert_eq!(q.quantize_scalar(Vec3::new(f32::NAN, -2.0, f32::NEG_INFINITY)), [0, 0, 0]);
    /// ```
    #[inline]
    pub fn quantize_scalar(&self, p: Vec3) -> [u32; 3] {
        [
            quantize_axis(p.x, self.min.x, self.scale.x, self.top),
            quantize_axis(p.y, self.min.y, self.scale.y, self.top),
            quantize_axis(p.z, self.min.z, self.scale.z, self.top),
        ]
    }

    /// The cells of eight points given as lanes of `x`, `y`, `z`; lane `i` equals
    /// [`quantize_scalar`](Self::quantize_scalar) of point `i` exactly.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, geometry::morton::MortonQuantizer, math::f32x8};
    /// let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::ONE));
    /// let x = f32x8::new([0.0, 0.5, 1.0, 2.0, -1.0, f32::NAN, 0.25, 0.999]);
    /// let [cx, _, _] = q.quantize_x8(x, x, x);
    /// assert_eq!(cx.to_array(), [0, 512, 1023, 1023, 0, 0, 256, 1022]);
    /// ```
    #[inline(always)]
    pub fn quantize_x8(&self, x: f32x8, y: f32x8, z: f32x8) -> [u32x8; 3] {
        let (zero, top) = (f32x8::ZERO, f32x8::splat(self.top));
        let axis = |p: f32x8, min: f32, scale: f32| -> u32x8 {
            // Same operations, same order, same operand order as `quantize_axis`.
            let q = (p - f32x8::splat(min)) * f32x8::splat(scale);
            // NOTE: the clamp leaves [0, top] (top < 2^21), where the plain conversion is exact.
            bytemuck::cast(q.max_l(zero).min_l(top).fast_trunc_int())
        };
        [
            axis(x, self.min.x, self.scale.x),
            axis(y, self.min.y, self.scale.y),
            axis(z, self.min.z, self.scale.z),
        ]
    }
}

/// One axis of [`MortonQuantizer::quantize_scalar`].
#[inline(always)]
fn quantize_axis(p: f32, min: f32, scale: f32, top: f32) -> u32 {
    let q = (p - min) * scale;
    // `max_l(q, 0)` returns 0 for a NaN q; the result lies in [0, top], so the cast truncates.
    min_l(max_l(q, 0.0), top) as u32
}

// ---------------------------------------------------------------------------------------------
// Bit interleaving, scalar
// ---------------------------------------------------------------------------------------------

/// Inserts two zero bits after each of the low 10 bits of `v` (bit `i` moves to bit `3 i`).
#[inline(always)]
const fn spread10(v: u32) -> u32 {
    let mut x = v & 0x0000_03FF;
    x = (x | x << 16) & 0x0300_00FF;
    x = (x | x << 8) & 0x0300_F00F;
    x = (x | x << 4) & 0x030C_30C3;
    x = (x | x << 2) & 0x0924_9249;
    x
}

/// Inverse of [`spread10`]: gathers bits `0, 3, 6, ..., 27` of `v` into bits `0..10`.
#[inline(always)]
const fn compact10(v: u32) -> u32 {
    let mut x = v & 0x0924_9249;
    x = (x | x >> 2) & 0x030C_30C3;
    x = (x | x >> 4) & 0x0300_F00F;
    x = (x | x >> 8) & 0x0300_00FF;
    x = (x | x >> 16) & 0x0000_03FF;
    x
}

/// Inserts two zero bits after each of the low 21 bits of `v` (bit `i` moves to bit `3 i`).
#[inline(always)]
const fn spread21(v: u32) -> u64 {
    let mut x = (v & 0x001F_FFFF) as u64;
    x = (x | x << 32) & 0x001F_0000_0000_FFFF;
    x = (x | x << 16) & 0x001F_0000_FF00_00FF;
    x = (x | x << 8) & 0x100F_00F0_0F00_F00F;
    x = (x | x << 4) & 0x10C3_0C30_C30C_30C3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// Inverse of [`spread21`]: gathers bits `0, 3, 6, ..., 60` of `v` into bits `0..21`.
#[inline(always)]
const fn compact21(v: u64) -> u32 {
    let mut x = v & 0x1249_2492_4924_9249;
    x = (x | x >> 2) & 0x10C3_0C30_C30C_30C3;
    x = (x | x >> 4) & 0x100F_00F0_0F00_F00F;
    x = (x | x >> 8) & 0x001F_0000_FF00_00FF;
    x = (x | x >> 16) & 0x001F_0000_0000_FFFF;
    x = (x | x >> 32) & 0x0000_0000_001F_FFFF;
    x as u32
}

/// Interleaves the low 10 bits of each cell index into a 30-bit code, `x` most significant:
/// `... x1 y1 z1 x0 y0 z0` (see the [bit layout](self#bit-layout)). Higher input bits are ignored.
///
/// ```
/// use strahl::geometry::morton::encode30;
/// assert_eq!(encode30([1, 0, 0]), 0b100);
/// assert_eq!(encode30([0, 1, 0]), 0b010);
/// assert_eq!(encode30([0, 0, 3]), 0b001_001);
/// assert_eq!(encode30([1 << 9, 0, 0]), 1 << 29);
/// assert_eq!(encode30([1024 + 1, 0, 0]), 0b100); // bit 10 and above are masked off
/// ```
#[inline]
pub const fn encode30(cell: [u32; 3]) -> u32 {
    (spread10(cell[0]) << 2) | (spread10(cell[1]) << 1) | spread10(cell[2])
}

/// The cell indices of a 30-bit code: the inverse of [`encode30`] (bits 30 and 31 are ignored).
///
/// ```
/// use strahl::geometry::morton::{decode30, encode30};
/// assert_eq!(decode30(encode30([1023, 5, 700])), [1023, 5, 700]);
/// assert_eq!(decode30(0b110_001), [2, 2, 1]);
/// ```
#[inline]
pub const fn decode30(code: u32) -> [u32; 3] {
    [compact10(code >> 2), compact10(code >> 1), compact10(code)]
}

/// Interleaves the low 21 bits of each cell index into a 63-bit code, `x` most significant:
/// `... x1 y1 z1 x0 y0 z0` (see the [bit layout](self#bit-layout)). Higher input bits are ignored.
///
/// ```
/// use strahl::geometry::morton::encode63;
/// assert_eq!(encode63([1, 0, 0]), 0b100);
/// assert_eq!(encode63([0, 0, 1 << 20]), 1 << 60);
/// assert_eq!(encode63([1 << 20, 0, 0]), 1 << 62);
/// assert_eq!(encode63([(1 << 21) | 2, 0, 0]), 0b100_000); // bit 21 and above are masked off
/// ```
#[inline]
pub const fn encode63(cell: [u32; 3]) -> u64 {
    (spread21(cell[0]) << 2) | (spread21(cell[1]) << 1) | spread21(cell[2])
}

/// The cell indices of a 63-bit code: the inverse of [`encode63`] (bit 63 is ignored).
///
/// ```
/// use strahl::geometry::morton::{decode63, encode63};
/// assert_eq!(decode63(encode63([2_000_000, 5, 1 << 20])), [2_000_000, 5, 1 << 20]);
/// assert_eq!(decode63(u64::MAX), [(1 << 21) - 1; 3]);
/// ```
#[inline]
pub const fn decode63(code: u64) -> [u32; 3] {
    [compact21(code >> 2), compact21(code >> 1), compact21(code)]
}

// ---------------------------------------------------------------------------------------------
// Kernels
// ---------------------------------------------------------------------------------------------

/// The 30-bit code of `p`: [`encode30`] of [`MortonQuantizer::quantize_scalar`]. Scalar reference
/// of [`morton30_x8`]; `q` should come from [`MortonQuantizer::new30`] (a finer quantizer's cells
/// are cut to their top 10 bits, so the codes stay in Z-order).
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::{MORTON30_MAX, MortonQuantizer, morton30_scalar}};
/// let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::ONE));
/// assert_eq!(morton30_scalar(Vec3::ZERO, &q), 0);
/// assert_eq!(morton30_scalar(Vec3::ONE, &q), MORTON30_MAX);
/// assert_eq!(morton30_scalar(Vec3::new(0.5, 0.0, 0.0), &q), 1 << 29);
/// // A 63-bit quantizer gives the same code here.
/// let q63 = MortonQuantizer::new63(&Aabb::new(Vec3::ZERO, Vec3::ONE));
/// assert_eq!(morton30_scalar(Vec3::new(0.5, 0.0, 0.0), &q63), 1 << 29);
/// ```
#[inline]
pub fn morton30_scalar(p: Vec3, q: &MortonQuantizer) -> u32 {
    let sh = q.bits().saturating_sub(10);
    encode30(q.quantize_scalar(p).map(|c| c >> sh))
}

/// The 63-bit code of `p`: [`encode63`] of [`MortonQuantizer::quantize_scalar`]. Scalar reference
/// of [`morton63_x8`]; `q` should come from [`MortonQuantizer::new63`].
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::{MORTON63_MAX, MortonQuantizer, morton63_scalar}};
/// let q = MortonQuantizer::new63(&Aabb::new(Vec3::ZERO, Vec3::ONE));
/// assert_eq!(morton63_scalar(Vec3::ZERO, &q), 0);
/// assert_eq!(morton63_scalar(Vec3::ONE, &q), MORTON63_MAX);
/// assert_eq!(morton63_scalar(Vec3::new(0.0, 0.0, 0.5), &q), 1 << 60);
/// ```
#[inline]
pub fn morton63_scalar(p: Vec3, q: &MortonQuantizer) -> u64 {
    encode63(q.quantize_scalar(p))
}

/// Whether the byte-shuffle-and-multiply form of the spread is native on this target (SSSE3 byte
/// shuffles and SSE4.1 32-bit multiplies, or NEON); otherwise the shift form is used. Both are
/// always compiled and give identical results (unit-tested against each other in every build).
const FAST_SPREAD: bool = cfg!(all(
    target_endian = "little",
    any(
        all(target_feature = "ssse3", target_feature = "sse4.1"),
        all(target_arch = "aarch64", target_feature = "neon"),
        target_feature = "simd128",
    )
));

/// Masks of the spread steps for `B` = 10 or 11 input bits. Bit 10 of an 11-bit input travels in
/// byte 3 next to bits 8 and 9, then moves from bit 26 to bit 30 in the nibble step.
const fn spread_masks(b: u32) -> [u32; 4] {
    if b == 11 {
        [0x0700_00FF, 0x0700_F00F, 0x430C_30C3, 0x4924_9249]
    } else {
        [0x0300_00FF, 0x0300_F00F, 0x030C_30C3, 0x0924_9249]
    }
}

/// `spread(v & (2^B - 1)) << S` in eight lanes (`B` = 10 or 11, bits shifted past 31 are lost):
/// dispatches to [`spread_x8_shuffle`] or [`spread_x8_shift`].
#[inline(always)]
fn spread_x8<const B: u32, const S: u32>(v: u32x8) -> u32x8 {
    if FAST_SPREAD {
        spread_x8_shuffle::<B, S>(v)
    } else {
        spread_x8_shift::<B, S>(v)
    }
}

/// [`spread_x8`] with the four shift/or/mask steps of [`spread10`], then the shift by `S`.
/// Lanes must be below `2^24` (cells are): the first mask already drops bits `B..24`.
#[inline(always)]
fn spread_x8_shift<const B: u32, const S: u32>(v: u32x8) -> u32x8 {
    let m = spread_masks(B);
    let mut x = v;
    x = (x | x << 16) & u32x8::splat(m[0]);
    x = (x | x << 8) & u32x8::splat(m[1]);
    x = (x | x << 4) & u32x8::splat(m[2]);
    x = (x | x << 2) & u32x8::splat(m[3]);
    x << S
}

/// [`spread_x8`] in six operations instead of thirteen, for any lane value:
///
/// ```text
///   v                  ---- ---- ---- ---- ---- -a98 7654 3210   byte shuffle: [b0, b0, -, b1]
///   & m1               ---- -a98 ---- ---- 7654 ---- ---- 3210   (= the first two shift steps)
///   (x | x << 4) & m2  -a-- --98 ---- 76-- --54 ---- 32-- --10
///   (x * 5 << S) & m3  -a-- 9--8 --7- -6-- 5--4 --3- -2-- 1--0   (<< S)
/// ```
///
/// The last step is a multiply because `x | x << 2 == x * 5` when the two never overlap, and a
/// multiply by `5 << S` also does the final shift for free.
#[inline(always)]
fn spread_x8_shuffle<const B: u32, const S: u32>(v: u32x8) -> u32x8 {
    // Within each 128-bit half, lane k's bytes 4k..4k+4 become [b0, b0, 0, b1].
    const IDX: [i8; 32] = {
        let mut a = [0i8; 32];
        let mut k = 0;
        while k < 8 {
            let base = (4 * (k % 4)) as i8;
            a[4 * k] = base;
            a[4 * k + 1] = base;
            a[4 * k + 2] = -128; // high bit set: zero
            a[4 * k + 3] = base + 1;
            k += 1;
        }
        a
    };
    let m = spread_masks(B);
    let bytes: wide::u8x32 = bytemuck::cast(v);
    let mut x: u32x8 = bytemuck::cast(bytes.swizzle_half_relaxed(bytemuck::cast(IDX)));
    x &= u32x8::splat(m[1]);
    x = (x | x << 4) & u32x8::splat(m[2]);
    // PERF: one multiply replaces shift, or and shift; LLVM turns `* 5` (S = 0) back into shifts.
    (x * u32x8::splat(5 << S)) & u32x8::splat(m[3] << S)
}

/// The 30-bit codes of eight points given as lanes of `x`, `y`, `z`. Lane `i` equals
/// [`morton30_scalar`] of point `i` exactly, for every input (same operations, same NaN policy).
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::*, math::f32x8};
/// let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::ONE));
/// let x = f32x8::new([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 1.0, f32::NAN]);
/// let (y, z) = (x * f32x8::splat(0.5), f32x8::splat(0.25));
/// let codes = morton30_x8(x, y, z, &q).to_array();
/// for i in 0..8 {
///     let p = Vec3::new(x.to_array()[i], y.to_array()[i], z.to_array()[i]);
///     assert_eq!(codes[i], morton30_scalar(p, &q));
/// }
/// ```
#[inline(always)]
pub fn morton30_x8(x: f32x8, y: f32x8, z: f32x8, q: &MortonQuantizer) -> u32x8 {
    let [mut cx, mut cy, mut cz] = q.quantize_x8(x, y, z);
    let sh = q.bits().saturating_sub(10);
    if sh > 0 {
        // A finer quantizer than `new30`'s: its cells cut to their top 10 bits, as the scalar's.
        (cx, cy, cz) = (cx >> sh, cy >> sh, cz >> sh);
    }
    spread_x8::<10, 2>(cx) | spread_x8::<10, 1>(cy) | spread_x8::<10, 0>(cz)
}

/// The 63-bit codes of eight points given as lanes of `x`, `y`, `z`. Element `i` equals
/// [`morton63_scalar`] of point `i` exactly, for every input.
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::*, math::f32x8};
/// let q = MortonQuantizer::new63(&Aabb::new(Vec3::ZERO, Vec3::ONE));
/// let x = f32x8::new([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 1.0, f32::INFINITY]);
/// let (y, z) = (x * f32x8::splat(0.5), f32x8::splat(0.75));
/// let codes = morton63_x8(x, y, z, &q);
/// for i in 0..8 {
///     let p = Vec3::new(x.to_array()[i], y.to_array()[i], z.to_array()[i]);
///     assert_eq!(codes[i], morton63_scalar(p, &q));
/// }
/// ```
#[inline(always)]
pub fn morton63_x8(x: f32x8, y: f32x8, z: f32x8, q: &MortonQuantizer) -> [u64; 8] {
    let [cx, cy, cz] = q.quantize_x8(x, y, z);
    // PERF: stay in 32-bit lanes. Per axis c = h * 2^11 + m * 2^10 + l (l, h: 10 bits, m: 1 bit);
    // the code's bits 0..32 and 32..63 are
    //
    //   lo word:  31 30 | 29 .......... 0        hi word:  31 | 30 ........... 1 | 0
    //             ym zm | interleave(l)                     0 | interleave(h)    | xm
    //
    // so the low word interleaves y and z with 11 bits (their bit 10 lands on 31 and 30) and x
    // with 10, and the high word x with 11 bits from bit 10 on and y, z with 10 bits from bit 11.
    let lo = spread_x8::<10, 2>(cx) | spread_x8::<11, 1>(cy) | spread_x8::<11, 0>(cz);
    let hi = spread_x8::<11, 0>(cx >> 10) | spread_x8::<10, 2>(cy >> 11) | spread_x8::<10, 1>(cz >> 11);
    // Zip the words into u64 lanes: [lo0, hi0, lo1, hi1, ...] in memory is lo | hi << 32 on a
    // little-endian target, [hi0, lo0, ...] on a big-endian one.
    let (a, b) = if cfg!(target_endian = "little") {
        (lo, hi)
    } else {
        (hi, lo)
    };
    bytemuck::cast([a.unpack_lo(b), a.unpack_hi(b)])
}

// ---------------------------------------------------------------------------------------------
// Slices
// ---------------------------------------------------------------------------------------------

/// Transposes eight `Vec3` (24 floats `x0 y0 z0 x1 ...`) to lanes of `x`, `y`, `z`: with blends and
/// one cross-lane permute per axis where AVX2 has the permute ([`transpose8_permute`]), otherwise
/// by gathering ([`transpose8_gather`]). Both are always compiled and unit-tested.
#[inline(always)]
fn transpose8(p: &[f32; 24]) -> [f32x8; 3] {
    if cfg!(target_feature = "avx2") {
        transpose8_permute(p)
    } else {
        transpose8_gather(p)
    }
}

/// [`transpose8`] float by float.
#[inline(always)]
fn transpose8_gather(p: &[f32; 24]) -> [f32x8; 3] {
    [0, 1, 2].map(|a| f32x8::new(core::array::from_fn(|i| p[3 * i + a])))
}

/// [`transpose8`] with six blends and three permutes.
#[inline(always)]
fn transpose8_permute(p: &[f32; 24]) -> [f32x8; 3] {
    //   v0 = x0 y0 z0 x1 y1 z1 x2 y2 | v1 = z2 x3 y3 z3 x4 y4 z4 x5 | v2 = y5 z5 x6 y6 z6 x7 y7 z7
    // Lane l of v_k holds float 8k + l, of axis (8k + l) % 3. Per axis, take each lane from the
    // vector that has that axis there (two blends), then put the lanes in order (one permute).
    let [v0, v1, v2]: [[u32; 8]; 3] = bytemuck::cast(*p);
    let (v0, v1, v2) = (u32x8::new(v0), u32x8::new(v1), u32x8::new(v2));
    const ON: u32 = u32::MAX;
    const A: [u32; 8] = [ON, 0, 0, ON, 0, 0, ON, 0];
    const B: [u32; 8] = [0, ON, 0, 0, ON, 0, 0, ON];
    const C: [u32; 8] = [0, 0, ON, 0, 0, ON, 0, 0];
    // `from1`/`from2`: lanes taken from v1/v2, the rest from v0.
    let pick = |from1: [u32; 8], from2: [u32; 8]| u32x8::new(from2).select(v2, u32x8::new(from1).select(v1, v0));
    // x: [x0 x3 x6 x1 x4 x7 x2 x5], y: [y5 y0 y3 y6 y1 y4 y7 y2], z: [z2 z5 z0 z3 z6 z1 z4 z7]
    let x = pick(B, C).shuffle(u32x8::new([0, 3, 6, 1, 4, 7, 2, 5]));
    let y = pick(C, A).shuffle(u32x8::new([1, 4, 7, 2, 5, 0, 3, 6]));
    let z = pick(A, B).shuffle(u32x8::new([2, 5, 0, 3, 6, 1, 4, 7]));
    [bytemuck::cast(x), bytemuck::cast(y), bytemuck::cast(z)]
}

/// Writes the 30-bit code of `points[i]` to `out[i]` for `i < min(points.len(), out.len())`;
/// the rest of `out` is left alone. Equal to [`morton30_scalar`] per element (eight points at a
/// time with [`morton30_x8`], the remainder with the scalar kernel).
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::*};
/// let pts: Vec<Vec3> = (0..11).map(|i| Vec3::new(i as f32, 0.0, 10.0 - i as f32)).collect();
/// let q = MortonQuantizer::new30(&Aabb::from_points(&pts));
/// let mut codes = [0u32; 11];
/// morton30_slice(&pts, &q, &mut codes);
/// assert_eq!(codes[0], encode30([0, 0, 1023]));
/// assert_eq!(codes[10], encode30([1023, 0, 0]));
/// for (p, c) in pts.iter().zip(codes) {
///     assert_eq!(c, morton30_scalar(*p, &q));
/// }
/// ```
pub fn morton30_slice(points: &[Vec3], q: &MortonQuantizer, out: &mut [u32]) {
    let n = points.len().min(out.len());
    let (points, out) = (&points[..n], &mut out[..n]);
    let (p8, _) = bytemuck::cast_slice::<Vec3, f32>(points).as_chunks::<24>();
    let (o8, _) = out.as_chunks_mut::<8>();
    let done = p8.len() * 8;
    for (p, o) in p8.iter().zip(o8) {
        let [x, y, z] = transpose8(p);
        *o = morton30_x8(x, y, z, q).to_array();
    }
    for (p, o) in points[done..].iter().zip(&mut out[done..]) {
        *o = morton30_scalar(*p, q);
    }
}

/// Writes the 63-bit code of `points[i]` to `out[i]` for `i < min(points.len(), out.len())`;
/// the rest of `out` is left alone. Equal to [`morton63_scalar`] per element.
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::*};
/// let pts: Vec<Vec3> = (0..11).map(|i| Vec3::splat(i as f32)).collect();
/// let q = MortonQuantizer::new63(&Aabb::from_points(&pts));
/// let mut codes = [7u64; 12];
/// morton63_slice(&pts, &q, &mut codes);
/// assert_eq!((codes[0], codes[10], codes[11]), (0, MORTON63_MAX, 7));
/// assert!(codes[..11].is_sorted());
/// ```
pub fn morton63_slice(points: &[Vec3], q: &MortonQuantizer, out: &mut [u64]) {
    let n = points.len().min(out.len());
    let (points, out) = (&points[..n], &mut out[..n]);
    let (p8, _) = bytemuck::cast_slice::<Vec3, f32>(points).as_chunks::<24>();
    let (o8, _) = out.as_chunks_mut::<8>();
    let done = p8.len() * 8;
    for (p, o) in p8.iter().zip(o8) {
        let [x, y, z] = transpose8(p);
        *o = morton63_x8(x, y, z, q);
    }
    for (p, o) in points[done..].iter().zip(&mut out[done..]) {
        *o = morton63_scalar(*p, q);
    }
}

/// [`morton30_slice`] for points in structure-of-arrays form: writes the code of
/// `(xs[i], ys[i], zs[i])` to `out[i]` for `i` below the shortest of the four lengths.
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::*};
/// let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::ONE));
/// let xs = [0.0, 0.5, 1.0, 0.25, 0.75, 0.1, 0.2, 0.3, 0.9, 0.0];
/// let mut codes = [u32::MAX; 10];
/// morton30_slice_soa(&xs, &xs, &xs[..9], &q, &mut codes); // 9 points: zs is the shortest
/// assert_eq!(codes[0], 0);
/// assert_eq!(codes[2], MORTON30_MAX);
/// assert_eq!(codes[9], u32::MAX); // untouched
/// ```
pub fn morton30_slice_soa(xs: &[f32], ys: &[f32], zs: &[f32], q: &MortonQuantizer, out: &mut [u32]) {
    let n = xs.len().min(ys.len()).min(zs.len()).min(out.len());
    let (xs, ys, zs, out) = (&xs[..n], &ys[..n], &zs[..n], &mut out[..n]);
    let (x8, _) = xs.as_chunks::<8>();
    let (y8, _) = ys.as_chunks::<8>();
    let (z8, _) = zs.as_chunks::<8>();
    let (o8, _) = out.as_chunks_mut::<8>();
    let done = o8.len() * 8;
    for (((x, y), z), o) in x8.iter().zip(y8).zip(z8).zip(o8) {
        *o = morton30_x8(f32x8::new(*x), f32x8::new(*y), f32x8::new(*z), q).to_array();
    }
    for (i, o) in out.iter_mut().enumerate().skip(done) {
        *o = morton30_scalar(Vec3::new(xs[i], ys[i], zs[i]), q);
    }
}

/// [`morton63_slice`] for points in structure-of-arrays form: writes the code of
/// `(xs[i], ys[i], zs[i])` to `out[i]` for `i` below the shortest of the four lengths.
///
/// ```
/// use strahl::{Aabb, Vec3, geometry::morton::*};
/// let q = MortonQuantizer::new63(&Aabb::new(Vec3::ZERO, Vec3::ONE));
/// let xs = [0.0, 0.5, 1.0, 0.25, 0.75, 0.1, 0.2, 0.3, 0.9];
/// let mut codes = [0u64; 9];
/// morton63_slice_soa(&xs, &xs, &xs, &q, &mut codes);
/// assert_eq!((codes[0], codes[2]), (0, MORTON63_MAX));
/// assert_eq!(codes[8], morton63_scalar(Vec3::splat(0.9), &q)); // the scalar remainder
/// ```
pub fn morton63_slice_soa(xs: &[f32], ys: &[f32], zs: &[f32], q: &MortonQuantizer, out: &mut [u64]) {
    let n = xs.len().min(ys.len()).min(zs.len()).min(out.len());
    let (xs, ys, zs, out) = (&xs[..n], &ys[..n], &zs[..n], &mut out[..n]);
    let (x8, _) = xs.as_chunks::<8>();
    let (y8, _) = ys.as_chunks::<8>();
    let (z8, _) = zs.as_chunks::<8>();
    let (o8, _) = out.as_chunks_mut::<8>();
    let done = o8.len() * 8;
    for (((x, y), z), o) in x8.iter().zip(y8).zip(z8).zip(o8) {
        *o = morton63_x8(f32x8::new(*x), f32x8::new(*y), f32x8::new(*z), q);
    }
    for (i, o) in out.iter_mut().enumerate().skip(done) {
        *o = morton63_scalar(Vec3::new(xs[i], ys[i], zs[i]), q);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T30: u32 = (1 << 10) - 1;
    const T63: u32 = (1 << 21) - 1;
    const NAN: f32 = f32::NAN;
    const INF: f32 = f32::INFINITY;

    fn unit() -> Aabb {
        Aabb::new(Vec3::ZERO, Vec3::ONE)
    }

    /// Bit-by-bit interleave, the definition the magic numbers must match.
    fn naive_encode(c: [u32; 3], bits: u32) -> u64 {
        let mut code = 0u64;
        for i in 0..bits {
            for (a, &v) in c.iter().enumerate() {
                code |= u64::from(v >> i & 1) << (3 * i + 2 - a as u32);
            }
        }
        code
    }

    /// A small xorshift generator: deterministic inputs without a dependency.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 32) as u32
        }
        fn f(&mut self) -> f32 {
            (self.next() >> 8) as f32 / (1 << 24) as f32 * 200.0 - 100.0
        }
    }

    #[test]
    fn edge_cases() {
        let flat_z = Aabb::new(Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 1.0, 1.0));
        let nan_box = Aabb::new(Vec3::splat(NAN), Vec3::ONE);
        let huge = Aabb::new(Vec3::splat(f32::MIN), Vec3::splat(f32::MAX));
        let tiny = Aabb::new(Vec3::ZERO, Vec3::splat(1.0e-40));
        let inverted = Aabb::new(Vec3::ONE, Vec3::ZERO);
        let odd = Aabb::new(Vec3::new(0.1, -3.7, 1.0e-3), Vec3::new(0.7, 12.3, 2.0e-3));
        let h30 = 1 << 9;
        let h63 = 1 << 20;
        // (name, bounds, point, cells with 10 bits, cells with 21 bits)
        type Case = (&'static str, Aabb, Vec3, [u32; 3], [u32; 3]);
        #[rustfmt::skip]
        let table: [Case; 19] = [
            ("min corner", unit(), Vec3::ZERO, [0; 3], [0; 3]),
            ("max corner", unit(), Vec3::ONE, [T30; 3], [T63; 3]),
            ("max corner, odd box", odd, odd.max, [T30; 3], [T63; 3]),
            ("min corner, odd box", odd, odd.min, [0; 3], [0; 3]),
            ("centre", unit(), Vec3::splat(0.5), [h30; 3], [h63; 3]),
            ("-0", unit(), Vec3::splat(-0.0), [0; 3], [0; 3]),
            ("below min clamps", unit(), Vec3::new(-1.0, -1e30, 0.5), [0, 0, h30], [0, 0, h63]),
            ("above max clamps", unit(), Vec3::new(2.0, 1e30, 0.5), [T30, T30, h30], [T63, T63, h63]),
            ("NaN axis -> 0", unit(), Vec3::new(NAN, 1.0, 0.5), [0, T30, h30], [0, T63, h63]),
            ("all NaN", unit(), Vec3::splat(NAN), [0; 3], [0; 3]),
            ("+inf -> top", unit(), Vec3::new(INF, 0.0, 1.0), [T30, 0, T30], [T63, 0, T63]),
            ("-inf -> 0", unit(), Vec3::new(-INF, 1.0, 1.0), [0, T30, T30], [0, T63, T63]),
            ("flat axis -> 0", flat_z, Vec3::new(1.0, 0.5, 1.0), [T30, h30, 0], [T63, h63, 0]),
            ("flat axis, off-plane", flat_z, Vec3::new(1.0, 0.5, 7.0), [T30, h30, 0], [T63, h63, 0]),
            ("flat axis, +inf", flat_z, Vec3::new(0.0, 0.0, INF), [0; 3], [0; 3]),
            ("empty bounds", Aabb::EMPTY, Vec3::new(1.0, INF, NAN), [0; 3], [0; 3]),
            ("NaN bounds", nan_box, Vec3::ONE, [0; 3], [0; 3]),
            ("inverted bounds", inverted, Vec3::ONE, [0; 3], [0; 3]),
            ("infinite extent", huge, Vec3::splat(f32::MAX), [0; 3], [0; 3]),
        ];
        for (name, b, p, c30, c63) in table {
            let (q30, q63) = (MortonQuantizer::new30(&b), MortonQuantizer::new63(&b));
            assert_eq!(q30.quantize_scalar(p), c30, "{name} (30)");
            assert_eq!(q63.quantize_scalar(p), c63, "{name} (63)");
            assert_eq!(morton30_scalar(p, &q30), encode30(c30), "{name} (30)");
            assert_eq!(morton63_scalar(p, &q63), encode63(c63), "{name} (63)");
            let s = |v: f32| f32x8::splat(v);
            assert_eq!(
                morton30_x8(s(p.x), s(p.y), s(p.z), &q30),
                u32x8::splat(encode30(c30)),
                "{name} x8"
            );
            assert_eq!(
                morton63_x8(s(p.x), s(p.y), s(p.z), &q63),
                [encode63(c63); 8],
                "{name} x8"
            );
        }
        // A positive extent whose `levels / extent` overflows is flat, not infinitely fine.
        assert_eq!(MortonQuantizer::new30(&tiny).scale(), Vec3::ZERO);
        assert_eq!(morton30_scalar(Vec3::splat(1.0e-40), &MortonQuantizer::new30(&tiny)), 0);
        assert_eq!(
            morton30_scalar(Vec3::ONE, &MortonQuantizer::new30(&unit())),
            MORTON30_MAX
        );
        assert_eq!(
            morton63_scalar(Vec3::ONE, &MortonQuantizer::new63(&unit())),
            MORTON63_MAX
        );
    }

    #[test]
    fn max_corner_is_all_ones_for_random_boxes() {
        let mut r = Rng(0x9E37_79B9_7F4A_7C15);
        for _ in 0..20_000 {
            let (a, b) = (Vec3::new(r.f(), r.f(), r.f()), Vec3::new(r.f(), r.f(), r.f()));
            let b = Aabb::new(a.min(b), a.max(b));
            assert_eq!(
                morton30_scalar(b.max, &MortonQuantizer::new30(&b)),
                MORTON30_MAX,
                "{b:?}"
            );
            assert_eq!(
                morton63_scalar(b.max, &MortonQuantizer::new63(&b)),
                MORTON63_MAX,
                "{b:?}"
            );
            assert_eq!(morton30_scalar(b.min, &MortonQuantizer::new30(&b)), 0, "{b:?}");
            assert_eq!(morton63_scalar(b.min, &MortonQuantizer::new63(&b)), 0, "{b:?}");
        }
    }

    #[test]
    fn magic_numbers_match_naive_interleave() {
        for v in 0..1024 {
            for c in [[v, 0, 0], [0, v, 0], [0, 0, v], [v, v ^ 0x155, 1023 - v]] {
                assert_eq!(u64::from(encode30(c)), naive_encode(c, 10), "{c:?}");
                assert_eq!(decode30(encode30(c)), c);
            }
        }
        let mut r = Rng(12345);
        for _ in 0..100_000 {
            let c = [r.next(), r.next(), r.next()];
            let c21 = c.map(|v| v & T63);
            let c10 = c.map(|v| v & T30);
            assert_eq!(encode63(c), naive_encode(c21, 21), "{c:?}");
            assert_eq!(decode63(encode63(c)), c21);
            assert_eq!(encode30(c), naive_encode(c10, 10) as u32);
            assert_eq!(decode30(encode30(c)), c10);
            // The top bits are never set, and decode ignores them.
            assert_eq!(encode30(c) >> 30, 0);
            assert_eq!(encode63(c) >> 63, 0);
            assert_eq!(decode30(encode30(c) | 3 << 30), c10);
            assert_eq!(decode63(encode63(c) | 1 << 63), c21);
        }
    }

    #[test]
    fn transpose8_matches_layout() {
        let p: [f32; 24] = core::array::from_fn(|i| i as f32);
        for [x, y, z] in [transpose8(&p), transpose8_gather(&p), transpose8_permute(&p)] {
            for i in 0..8 {
                assert_eq!(x.to_array()[i], (3 * i) as f32);
                assert_eq!(y.to_array()[i], (3 * i + 1) as f32);
                assert_eq!(z.to_array()[i], (3 * i + 2) as f32);
            }
        }
    }

    /// Both forms of the lane spread equal the scalar one, for every 11-bit value and every shift
    /// (and for the high bits of the input, which both ignore).
    #[test]
    fn spread_forms_agree() {
        fn check<const B: u32, const S: u32>() {
            let mask = (1u32 << B) - 1;
            for base in (0..1u32 << 12).step_by(8) {
                // Values below 2^24 (the kernels' cells are below 2^21), with junk above bit B.
                let v = u32x8::new(core::array::from_fn(|i| {
                    let c = base + i as u32; // every 12-bit value ...
                    (c | (c.wrapping_mul(0x9E37) << 12)) & 0x00FF_FFFF // ... with junk up to bit 23
                }));
                let want = v.to_array().map(|c| {
                    let c = c & mask;
                    let s = if B == 10 {
                        spread10(c)
                    } else {
                        spread10(c & 1023) | (c >> 10 & 1) << 30
                    };
                    s.wrapping_shl(S) // bits past 31 are lost
                });
                assert_eq!(spread_x8_shift::<B, S>(v).to_array(), want, "shift B {B} S {S}");
                // The byte indices assume little-endian lanes (`FAST_SPREAD` checks the same).
                if cfg!(target_endian = "little") {
                    let got = spread_x8_shuffle::<B, S>(v).to_array();
                    assert_eq!(got, want, "shuffle B {B} S {S}");
                }
                assert_eq!(spread_x8::<B, S>(v).to_array(), want);
            }
        }
        check::<10, 0>();
        check::<10, 1>();
        check::<10, 2>();
        check::<10, 3>();
        check::<11, 0>();
        check::<11, 1>();
        check::<11, 2>();
    }

    #[test]
    fn x8_matches_scalar_on_random_and_special_lanes() {
        let specials = [
            0.0,
            -0.0,
            1.0,
            NAN,
            INF,
            -INF,
            1e-40,
            f32::MAX,
            f32::MIN,
            0.5,
            -3.0,
            100.0,
        ];
        let boxes = [
            unit(),
            Aabb::EMPTY,
            Aabb::new(Vec3::splat(-100.0), Vec3::new(100.0, 0.0, 3.0)),
        ];
        let mut r = Rng(777);
        for b in boxes {
            let (q30, q63) = (MortonQuantizer::new30(&b), MortonQuantizer::new63(&b));
            for round in 0..2000 {
                let mut v = [[0.0f32; 8]; 3];
                for a in &mut v {
                    for l in a.iter_mut() {
                        let k = r.next();
                        *l = if round % 2 == 0 {
                            specials[k as usize % specials.len()]
                        } else {
                            r.f()
                        };
                    }
                }
                let (x, y, z) = (f32x8::new(v[0]), f32x8::new(v[1]), f32x8::new(v[2]));
                let c30 = morton30_x8(x, y, z, &q30).to_array();
                let c63 = morton63_x8(x, y, z, &q63);
                for i in 0..8 {
                    let p = Vec3::new(v[0][i], v[1][i], v[2][i]);
                    assert_eq!(c30[i], morton30_scalar(p, &q30), "{p:?} {b:?}");
                    assert_eq!(c63[i], morton63_scalar(p, &q63), "{p:?} {b:?}");
                }
            }
        }
    }

    #[test]
    fn slices_handle_every_length() {
        let q30 = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::splat(20.0)));
        let q63 = MortonQuantizer::new63(&Aabb::new(Vec3::ZERO, Vec3::splat(20.0)));
        let pts: [Vec3; 20] = core::array::from_fn(|i| Vec3::new(i as f32, 20.0 - i as f32, (i * i) as f32 * 0.1));
        for n in 0..=20 {
            for m in 0..=20 {
                let (mut o30, mut o63) = ([u32::MAX; 20], [u64::MAX; 20]);
                morton30_slice(&pts[..n], &q30, &mut o30[..m]);
                morton63_slice(&pts[..n], &q63, &mut o63[..m]);
                for i in 0..20 {
                    let (e30, e63) = if i < n.min(m) {
                        (morton30_scalar(pts[i], &q30), morton63_scalar(pts[i], &q63))
                    } else {
                        (u32::MAX, u64::MAX)
                    };
                    assert_eq!((o30[i], o63[i]), (e30, e63), "n {n} m {m} i {i}");
                }
            }
        }
    }
}
