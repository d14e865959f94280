//! Compositing kernels: premultiplied RGBA "over" (f32 and u8 pixels) and depth compositing, each
//! as a scalar reference and a SIMD form that gives the same bits.
//!
//! Every pixel type has an `EMPTY` value that is the identity of its operator, so that sparse
//! images can skip empty pixels without changing a single bit of the result. For f32 over this
//! holds where alpha is finite: with a NaN or infinite alpha in front, `(1 - a) 0` is NaN, so a
//! sparse run (which skips the empty pixel behind) and a dense one differ on that pixel (NaN
//! against the front pixel). Such input is outside what over means; it never panics.
//!
//! # Operators
//! - **Over** (Porter and Duff 1984), premultiplied colour: `front over back = front + (1 - a_front)
//!   back` per channel. Associative in exact arithmetic; in `f32` a different grouping (another
//!   compositing schedule) changes the result by rounding only: about `P` ulps of 1 for `P`
//!   images, see [`OVER_F32_TOLERANCE`].
//! - **u8 over**: `front + round((255 - a_front) back / 255)` with exact integer rounding
//!   ([`div255`]); results saturate at 255, which only matters for invalid (non-premultiplied) input.
//! - **Depth**: the nearer sample wins. The pixel is stored as one `u64` key, the depth mapped to a
//!   totally ordered integer in the high half and the colour in the low half, and compositing is
//!   `min` of keys: ties in depth go to the smaller colour value, `-0 < +0`, NaN depths are stored as
//!   `+inf`. `min` is associative and commutative, so every schedule gives the same bits as the
//!   serial reference.

use bytemuck::{Pod, Zeroable};
use wide::{f32x8, u16x16, u32x8, u64x4};

/// Largest difference, per channel, between two compositing orders of up to 64 `f32` images with
/// channels in `[0, 1]` (a stated bound for tests; the observed differences are far smaller).
///
/// ```
/// use strahl::composite::{OVER_F32_TOLERANCE, over_f32_scalar};
/// let (a, b, c) = ([0.3, 0.1, 0.2, 0.4f32], [0.2, 0.5, 0.1, 0.6], [0.7, 0.2, 0.3, 0.9]);
/// let mut left = a; // (a over b) over c
/// over_f32_scalar(&mut left, &b, true);
/// over_f32_scalar(&mut left, &c, true);
/// let mut bc = b; // a over (b over c)
/// over_f32_scalar(&mut bc, &c, true);
/// let mut right = a;
/// over_f32_scalar(&mut right, &bc, true);
/// assert!(left.iter().zip(&right).all(|(l, r)| (l - r).abs() <= OVER_F32_TOLERANCE));
/// ```
pub const OVER_F32_TOLERANCE: f32 = 64.0 * f32::EPSILON;

/// A pixel that can be composited: `EMPTY` is the identity of the operator.
///
/// ```
/// use strahl::composite::{DepthPixel, Pixel, Rgba8, RgbaF32};
/// // Compositing with `EMPTY` changes nothing, for every pixel type.
/// fn unchanged<P: Pixel>(p: P) -> bool {
///     let mut acc = [p];
///     P::composite_behind(&mut acc, &[P::EMPTY]);
///     acc[0] == p
/// }
/// assert!(unchanged(RgbaF32([0.2, 0.1, 0.0, 0.5])));
/// assert!(unchanged(Rgba8([10, 20, 30, 40])));
/// assert!(unchanged(DepthPixel::new(3.0, 7)));
/// assert_eq!(RgbaF32::BYTES, 16);
/// ```
pub trait Pixel: Pod + PartialEq + Send + Sync + core::fmt::Debug + 'static {
    /// The identity: compositing with it changes nothing (bit for bit).
    ///
    /// ```
    /// use strahl::composite::{Pixel, Rgba8};
    /// let p = Rgba8([10, 20, 30, 40]);
    /// let mut acc = [Rgba8::EMPTY]; // empty in front: the back pixel shows through unchanged
    /// Rgba8::composite_behind(&mut acc, &[p]);
    /// assert_eq!(acc, [p]);
    /// assert_eq!(Rgba8::EMPTY, Rgba8([0; 4]));
    /// ```
    const EMPTY: Self;
    /// Bytes per pixel on the wire.
    ///
    /// ```
    /// use strahl::composite::{DepthPixel, Pixel, Rgba8, RgbaF32};
    /// assert_eq!((RgbaF32::BYTES, Rgba8::BYTES, DepthPixel::BYTES), (16, 4, 8));
    /// ```
    const BYTES: usize = core::mem::size_of::<Self>();
    /// `front[i] = front[i] op back[i]`, where `front` is nearer the viewer. Both the same length.
    ///
    /// ```
    /// use strahl::composite::{Pixel, RgbaF32};
    /// let mut front = [RgbaF32([0.5, 0.0, 0.0, 0.5])]; // half-transparent red
    /// RgbaF32::composite_behind(&mut front, &[RgbaF32([0.0, 1.0, 0.0, 1.0])]); // opaque green behind
    /// assert_eq!(front, [RgbaF32([0.5, 0.5, 0.0, 1.0])]);
    /// ```
    fn composite_behind(front: &mut [Self], back: &[Self]);
    /// `back[i] = front[i] op back[i]`, where `front` is nearer the viewer. Both the same length.
    ///
    /// ```
    /// use strahl::composite::{Pixel, RgbaF32};
    /// let (front, back) = (RgbaF32([0.25, 0.0, 0.0, 0.5]), RgbaF32([0.0, 0.5, 0.5, 0.5]));
    /// let mut acc = [back];
    /// RgbaF32::composite_in_front(&mut acc, &[front]);
    /// assert_eq!(acc, [RgbaF32([0.25, 0.25, 0.25, 0.75])]);
    /// // The same pixel as blending the back one behind the front one.
    /// let mut other = [front];
    /// RgbaF32::composite_behind(&mut other, &[back]);
    /// assert_eq!(acc, other);
    /// ```
    fn composite_in_front(back: &mut [Self], front: &[Self]);
}

/// A premultiplied RGBA pixel with `f32` channels.
///
/// ```
/// use strahl::composite::{Pixel, RgbaF32};
/// // Half-transparent orange (1, 0.5, 0): the colour channels are multiplied by alpha.
/// let orange = RgbaF32([0.5, 0.25, 0.0, 0.5]);
/// let mut acc = [orange];
/// RgbaF32::composite_behind(&mut acc, &[orange]);
/// assert_eq!(acc, [RgbaF32([0.75, 0.375, 0.0, 0.75])]);
/// assert_eq!(RgbaF32::default(), RgbaF32::EMPTY);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Default, Pod, Zeroable)]
#[repr(C)]
pub struct RgbaF32(pub [f32; 4]);

/// A premultiplied RGBA pixel with `u8` channels.
///
/// Aligned like a `u32`: the over kernels work on the four channels as one word, so slices of
/// `Rgba8` (the empty ones included) are cast to `u32` slices, which needs 4-byte alignment.
/// Byte buffers cast to `&[Rgba8]` must be 4-aligned too.
///
/// ```
/// use strahl::composite::{Pixel, Rgba8, over_u8_scalar};
/// let (front, back) = (Rgba8([128, 0, 0, 128]), Rgba8([0, 255, 0, 255]));
/// let mut acc = [front];
/// Rgba8::composite_behind(&mut acc, &[back]);
/// assert_eq!(acc, [Rgba8([128, 127, 0, 255])]);
/// // The scalar reference on the little-endian `u32` form (R in the low byte) agrees.
/// let mut word = [u32::from_le_bytes(front.0)];
/// over_u8_scalar(&mut word, &[u32::from_le_bytes(back.0)], true);
/// assert_eq!(acc[0].0, word[0].to_le_bytes());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Pod, Zeroable)]
#[repr(C, align(4))]
pub struct Rgba8(pub [u8; 4]);

/// A depth sample: depth and an RGBA8 colour packed into one totally ordered `u64` key.
///
/// ```
/// use strahl::composite::{DepthPixel, Pixel};
/// let near = DepthPixel::new(1.0, 0xff00_00ff);
/// let far = DepthPixel::new(2.0, 0xffff_ffff);
/// let mut acc = [far];
/// DepthPixel::composite_behind(&mut acc, &[near]);
/// assert_eq!(acc[0], near);
/// assert_eq!(acc[0].depth(), 1.0);
/// assert!(DepthPixel::EMPTY.is_empty());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Pod, Zeroable)]
#[repr(transparent)]
pub struct DepthPixel(pub u64);

const _: () = assert!(core::mem::size_of::<RgbaF32>() == 16);
const _: () = assert!(core::mem::size_of::<Rgba8>() == 4 && core::mem::align_of::<Rgba8>() == 4);
const _: () = assert!(core::mem::size_of::<DepthPixel>() == 8);

impl DepthPixel {
    /// A sample at depth `z` (NaN is stored as `+inf`) with colour `rgba` (any `u32`).
    ///
    /// ```
    /// use strahl::composite::DepthPixel;
    /// assert!(DepthPixel::new(-1.0, 0) < DepthPixel::new(0.5, 0)); // keys order like depths
    /// assert!(DepthPixel::new(1.0, 2) < DepthPixel::new(1.0, 3)); // a tie goes to the smaller colour
    /// assert_eq!(DepthPixel::new(f32::NAN, 5).depth(), f32::INFINITY);
    /// ```
    pub fn new(z: f32, rgba: u32) -> Self {
        let z = if z.is_nan() { f32::INFINITY } else { z };
        let b = z.to_bits();
        // Map the float's bits to an unsigned integer in the same order as `f32::total_cmp`.
        let key = if b >> 31 == 1 { !b } else { b | 0x8000_0000 };
        Self(((key as u64) << 32) | rgba as u64)
    }

    /// `true` for [`Pixel::EMPTY`] (no sample).
    ///
    /// ```
    /// use strahl::composite::{DepthPixel, Pixel};
    /// assert!(DepthPixel::EMPTY.is_empty());
    /// assert!(!DepthPixel::new(f32::INFINITY, u32::MAX).is_empty()); // a sample at +inf is a sample
    /// ```
    pub fn is_empty(self) -> bool {
        self == Self::EMPTY
    }

    /// The depth (`+inf` for an empty pixel).
    ///
    /// ```
    /// use strahl::composite::{DepthPixel, Pixel};
    /// assert_eq!(DepthPixel::new(-2.5, 0xff).depth(), -2.5);
    /// assert_eq!(DepthPixel::EMPTY.depth(), f32::INFINITY);
    /// ```
    pub fn depth(self) -> f32 {
        if self.is_empty() {
            return f32::INFINITY;
        }
        let key = (self.0 >> 32) as u32;
        let b = if key >> 31 == 1 { key & 0x7fff_ffff } else { !key };
        f32::from_bits(b)
    }

    /// The colour (0 for an empty pixel).
    ///
    /// ```
    /// use strahl::composite::{DepthPixel, Pixel};
    /// assert_eq!(DepthPixel::new(1.0, 0x8000_00ff).rgba(), 0x8000_00ff);
    /// assert_eq!(DepthPixel::EMPTY.rgba(), 0);
    /// ```
    pub fn rgba(self) -> u32 {
        if self.is_empty() { 0 } else { self.0 as u32 }
    }
}

impl Pixel for RgbaF32 {
    const EMPTY: Self = Self([0.0; 4]);
    #[inline]
    fn composite_behind(front: &mut [Self], back: &[Self]) {
        over_f32_x8(bytemuck::cast_slice_mut(front), bytemuck::cast_slice(back), true);
    }
    #[inline]
    fn composite_in_front(back: &mut [Self], front: &[Self]) {
        over_f32_x8(bytemuck::cast_slice_mut(back), bytemuck::cast_slice(front), false);
    }
}

impl Pixel for Rgba8 {
    const EMPTY: Self = Self([0; 4]);
    #[inline]
    fn composite_behind(front: &mut [Self], back: &[Self]) {
        over_u8_x8(bytemuck::cast_slice_mut(front), bytemuck::cast_slice(back), true);
    }
    #[inline]
    fn composite_in_front(back: &mut [Self], front: &[Self]) {
        over_u8_x8(bytemuck::cast_slice_mut(back), bytemuck::cast_slice(front), false);
    }
}

impl Pixel for DepthPixel {
    /// The largest key: no sample. (`min` with it is the identity.)
    const EMPTY: Self = Self(u64::MAX);
    #[inline]
    fn composite_behind(front: &mut [Self], back: &[Self]) {
        depth_x4(bytemuck::cast_slice_mut(front), bytemuck::cast_slice(back));
    }
    #[inline]
    fn composite_in_front(back: &mut [Self], front: &[Self]) {
        depth_x4(bytemuck::cast_slice_mut(back), bytemuck::cast_slice(front));
    }
}

/// `x / 255` rounded to nearest, exact for `0 <= x <= 255 * 255` (larger `x` give an unspecified
/// value, never a panic).
///
/// ```
/// use strahl::composite::div255;
/// const FULL: u32 = div255(255 * 255);
/// assert_eq!(FULL, 255);
/// assert_eq!(div255(127), 0); // 0.498 rounds down
/// assert_eq!(div255(128), 1); // 0.502 rounds up
/// assert_eq!(div255(200 * 100), 78); // 78.43
/// let _ = (div255(u32::MAX), div255(0xFFFF_0000)); // out of range: no overflow
/// ```
#[inline(always)]
pub const fn div255(x: u32) -> u32 {
    let x = x.wrapping_add(128);
    x.wrapping_add(x >> 8) >> 8
}

/// Scalar reference for f32 over on interleaved RGBA (`acc.len() == other.len()`, a multiple of 4;
/// a trailing partial pixel is left alone). `acc_in_front`: `acc = acc over other`, else
/// `acc = other over acc`.
///
/// ```
/// use strahl::composite::over_f32_scalar;
/// let mut front = [0.5, 0.0, 0.0, 0.5];
/// over_f32_scalar(&mut front, &[0.0, 1.0, 0.0, 1.0], true);
/// assert_eq!(front, [0.5, 0.5, 0.0, 1.0]);
/// ```
pub fn over_f32_scalar(acc: &mut [f32], other: &[f32], acc_in_front: bool) {
    for (a, o) in acc.chunks_exact_mut(4).zip(other.chunks_exact(4)) {
        let (f, b) = if acc_in_front {
            ([a[0], a[1], a[2], a[3]], o)
        } else {
            ([o[0], o[1], o[2], o[3]], &*a)
        };
        let k = 1.0 - f[3];
        let r = [f[0] + k * b[0], f[1] + k * b[1], f[2] + k * b[2], f[3] + k * b[3]];
        a.copy_from_slice(&r);
    }
}

/// f32 over, two pixels per `f32x8`; the same operations as [`over_f32_scalar`], so the same bits.
///
/// ```
/// use strahl::composite::{over_f32_scalar, over_f32_x8};
/// let back: Vec<f32> = (0..12).map(|i| i as f32 / 16.0).collect();
/// let mut simd = vec![0.5, 0.25, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3, 0.9];
/// let mut scalar = simd.clone();
/// over_f32_x8(&mut simd, &back, true); // three pixels: one vector of two, then a scalar tail
/// over_f32_scalar(&mut scalar, &back, true);
/// assert_eq!(simd, scalar);
/// assert_eq!(&simd[4..8], &back[4..8]); // an empty front pixel lets the back one through
/// ```
pub fn over_f32_x8(acc: &mut [f32], other: &[f32], acc_in_front: bool) {
    let n = acc.len().min(other.len()) / 8 * 8;
    let (acc_v, acc_t) = acc.split_at_mut(n);
    let (oth_v, oth_t) = other.split_at(n);
    let one = f32x8::splat(1.0);
    for (a, o) in acc_v.chunks_exact_mut(8).zip(oth_v.chunks_exact(8)) {
        let av = f32x8::from(<[f32; 8]>::try_from(&*a).unwrap_or([0.0; 8]));
        let ov = f32x8::from(<[f32; 8]>::try_from(o).unwrap_or([0.0; 8]));
        let (f, b, fa0, fa1) = if acc_in_front {
            (av, ov, a[3], a[7])
        } else {
            (ov, av, o[3], o[7])
        };
        let alpha = f32x8::from([fa0, fa0, fa0, fa0, fa1, fa1, fa1, fa1]);
        let r = f + (one - alpha) * b;
        a.copy_from_slice(&r.to_array());
    }
    over_f32_scalar(acc_t, oth_t, acc_in_front);
}

/// Scalar reference for u8 over on RGBA pixels packed little-endian in `u32` (R in the low byte,
/// A in the high byte). Each channel: `f + div255((255 - a_f) b)`, saturating at 255.
///
/// ```
/// use strahl::composite::over_u8_scalar;
/// let mut front = [0x80_00_00_80u32]; // R = 128, A = 128
/// over_u8_scalar(&mut front, &[0xff_00_ff_00], true); // opaque green behind
/// assert_eq!(front, [0xff_00_7f_80]);
/// ```
pub fn over_u8_scalar(acc: &mut [u32], other: &[u32], acc_in_front: bool) {
    for (a, &o) in acc.iter_mut().zip(other) {
        let (f, b) = if acc_in_front { (*a, o) } else { (o, *a) };
        let k = 255 - (f >> 24);
        let mut r = 0;
        for c in 0..4 {
            let ch = ((f >> (8 * c)) & 0xff) + div255(((b >> (8 * c)) & 0xff) * k);
            r |= ch.min(255) << (8 * c);
        }
        *a = r;
    }
}

/// u8 over, eight pixels at a time in 16-bit lanes: the even bytes (R, B) and the odd bytes
/// (G, A) of each pixel are spread to 16-bit fields, where `channel * (255 - alpha) <= 65025`
/// fits, so one 16-bit multiply does 16 channels. The same exact rounding and saturation as
/// [`over_u8_scalar`], so the same bits.
///
/// ```
/// use strahl::composite::{over_u8_scalar, over_u8_x8};
/// // Alpha 0, 25, .., 225 with some red below it, in front of opaque green.
/// let front: Vec<u32> = (0..10).map(|i| ((i * 25) << 24) | (i * 12)).collect();
/// let back = vec![0xff_00_ff_00u32; 10];
/// let (mut simd, mut scalar) = (front.clone(), front.clone());
/// over_u8_x8(&mut simd, &back, true); // one vector of eight, then a scalar tail of two
/// over_u8_scalar(&mut scalar, &back, true);
/// assert_eq!(simd, scalar);
/// assert_eq!(simd[0], 0xff_00_ff_00); // a transparent front shows the back
/// ```
pub fn over_u8_x8(acc: &mut [u32], other: &[u32], acc_in_front: bool) {
    let n = acc.len().min(other.len()) / 8 * 8;
    let (acc_v, acc_t) = acc.split_at_mut(n);
    let (oth_v, oth_t) = other.split_at(n);
    let fields = u32x8::splat(0x00ff_00ff);
    let c255 = u32x8::splat(255);
    let h128 = u16x16::splat(128);
    let h255 = u16x16::splat(255);
    let h257 = u16x16::splat(257);
    // `f + div255(b k)` per 16-bit field, saturated at 255.
    let blend = |f: u32x8, b: u32x8, k: u16x16| -> u32x8 {
        let (f, b): (u16x16, u16x16) = (bytemuck::cast(f), bytemuck::cast(b));
        // div255 of `y = b k + 128` as `(y 257) >> 16`, which equals `(y + (y >> 8)) >> 8` for
        // every `y <= 65153` (checked exhaustively in the tests): one high multiply.
        let y: u16x16 = b * k + h128;
        let q = y.mul_keep_high(h257);
        let r: u16x16 = (f + q).min(h255);
        bytemuck::cast(r)
    };
    for (a, o) in acc_v.chunks_exact_mut(8).zip(oth_v.chunks_exact(8)) {
        let av = u32x8::from(<[u32; 8]>::try_from(&*a).unwrap_or([0; 8]));
        let ov = u32x8::from(<[u32; 8]>::try_from(o).unwrap_or([0; 8]));
        let (f, b) = if acc_in_front { (av, ov) } else { (ov, av) };
        let k32 = c255 - (f >> 24);
        let k: u16x16 = bytemuck::cast(k32 | (k32 << 16));
        let even = blend(f & fields, b & fields, k);
        let odd = blend((f >> 8) & fields, (b >> 8) & fields, k);
        let r: u32x8 = even | (odd << 8);
        a.copy_from_slice(&r.to_array());
    }
    over_u8_scalar(acc_t, oth_t, acc_in_front);
}

/// Scalar reference for depth compositing on keys ([`DepthPixel`]): `acc[i] = min(acc[i], other[i])`.
///
/// ```
/// use strahl::composite::{DepthPixel, depth_scalar};
/// let (near, far) = (DepthPixel::new(1.0, 0xff), DepthPixel::new(2.0, 0xee));
/// let mut acc = [near.0, far.0];
/// depth_scalar(&mut acc, &[far.0, near.0]);
/// assert_eq!(acc, [near.0, near.0]); // the nearer sample wins on either side
/// ```
pub fn depth_scalar(acc: &mut [u64], other: &[u64]) {
    for (a, &o) in acc.iter_mut().zip(other) {
        *a = (*a).min(o);
    }
}

/// Depth compositing, four keys per `u64x4`; equal to [`depth_scalar`].
///
/// ```
/// use strahl::composite::{DepthPixel, depth_scalar, depth_x4};
/// let keys: Vec<u64> = (0..6u32).map(|i| DepthPixel::new(i as f32, i).0).collect();
/// let mut simd = vec![DepthPixel::new(2.5, 0).0; 6];
/// let mut scalar = simd.clone();
/// depth_x4(&mut simd, &keys); // one vector of four keys, then a scalar tail of two
/// depth_scalar(&mut scalar, &keys);
/// assert_eq!(simd, scalar);
/// assert_eq!(DepthPixel(simd[5]).depth(), 2.5);
/// ```
pub fn depth_x4(acc: &mut [u64], other: &[u64]) {
    let n = acc.len().min(other.len()) / 4 * 4;
    let (acc_v, acc_t) = acc.split_at_mut(n);
    let (oth_v, oth_t) = other.split_at(n);
    for (a, o) in acc_v.chunks_exact_mut(4).zip(oth_v.chunks_exact(4)) {
        let av = u64x4::from(<[u64; 4]>::try_from(&*a).unwrap_or([0; 4]));
        let ov = u64x4::from(<[u64; 4]>::try_from(o).unwrap_or([0; 4]));
        a.copy_from_slice(&av.min(ov).to_array());
    }
    depth_scalar(acc_t, oth_t);
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec::Vec;

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn unit(&mut self) -> f32 {
            (self.next() >> 40) as f32 / (1u64 << 24) as f32
        }
        fn premul(&mut self) -> [f32; 4] {
            let a = self.unit();
            [self.unit() * a, self.unit() * a, self.unit() * a, a]
        }
        fn premul8(&mut self) -> u32 {
            let a = (self.next() & 0xff) as u32;
            let c = |r: &mut Self| ((r.next() & 0xff) as u32 * a) / 255;
            c(self) | c(self) << 8 | c(self) << 16 | a << 24
        }
    }

    /// Found by the `composite` fuzz target: `Rgba8` had alignment 1, so casting an empty
    /// `Vec<Rgba8>` (dangling pointer 0x1) or a misaligned slice to `u32` panicked.
    #[test]
    fn empty_and_vec_rgba8_slices_composite() {
        let mut empty: Vec<Rgba8> = Vec::new();
        Rgba8::composite_behind(&mut empty, &[]);
        Rgba8::composite_in_front(&mut empty, &[]);
        let mut v: Vec<Rgba8> = (0..9).map(|i| Rgba8([i, i, i, 255])).collect();
        let back = [Rgba8([1, 2, 3, 4]); 9];
        Rgba8::composite_behind(&mut v[1..], &back[1..]);
        assert_eq!(v[1], Rgba8([1, 1, 1, 255])); // opaque front wins
    }

    #[test]
    fn simd_equals_scalar_bit_for_bit() {
        let mut rng = Rng(7);
        for n in [0, 1, 2, 3, 7, 8, 9, 31, 64, 77] {
            let a: Vec<f32> = (0..n).flat_map(|_| rng.premul()).collect();
            let b: Vec<f32> = (0..n).flat_map(|_| rng.premul()).collect();
            for front in [true, false] {
                let (mut s, mut v) = (a.clone(), a.clone());
                over_f32_scalar(&mut s, &b, front);
                over_f32_x8(&mut v, &b, front);
                assert_eq!(
                    s.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    v.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
                );
            }
            // Premultiplied pixels, and arbitrary ones (channels above alpha saturate).
            let a8: Vec<u32> = (0..n)
                .map(|i| if i % 3 == 0 { rng.next() as u32 } else { rng.premul8() })
                .collect();
            let b8: Vec<u32> = (0..n).map(|_| rng.premul8()).collect();
            for front in [true, false] {
                let (mut s, mut v) = (a8.clone(), a8.clone());
                over_u8_scalar(&mut s, &b8, front);
                over_u8_x8(&mut v, &b8, front);
                assert_eq!(s, v);
            }
            let az: Vec<u64> = (0..n).map(|_| rng.next()).collect();
            let bz: Vec<u64> = (0..n).map(|_| rng.next()).collect();
            let (mut s, mut v) = (az.clone(), az.clone());
            depth_scalar(&mut s, &bz);
            depth_x4(&mut v, &bz);
            assert_eq!(s, v);
        }
    }

    #[test]
    fn u8_simd_equals_scalar_for_every_channel_and_alpha() {
        // Every (alpha of the front, channel of the back) pair, in every byte position.
        let mut front = Vec::new();
        let mut back = Vec::new();
        for a in 0..256u32 {
            for c in 0..256u32 {
                front.push((a << 24) | ((a / 2) << 16) | ((a / 3) << 8) | (a / 5));
                back.push(c * 0x0101_0101);
            }
        }
        for acc_in_front in [true, false] {
            let (mut s, mut v) = if acc_in_front {
                (front.clone(), front.clone())
            } else {
                (back.clone(), back.clone())
            };
            let other = if acc_in_front { &back } else { &front };
            over_u8_scalar(&mut s, other, acc_in_front);
            over_u8_x8(&mut v, other, acc_in_front);
            assert_eq!(s, v);
        }
    }

    #[test]
    fn div255_is_exact() {
        for x in 0..=255 * 255u32 {
            assert_eq!(div255(x), (x as f64 / 255.0).round() as u32, "{x}");
        }
    }

    #[test]
    fn u8_over_matches_float_within_half_a_step() {
        let mut rng = Rng(3);
        for _ in 0..10_000 {
            let (f, b) = (rng.premul8(), rng.premul8());
            let mut r = [f];
            over_u8_scalar(&mut r, &[b], true);
            let a = (f >> 24) as f64 / 255.0;
            for c in 0..4 {
                let ch = |x: u32| ((x >> (8 * c)) & 0xff) as f64;
                let exact = ch(f) + (1.0 - a) * ch(b);
                assert!((ch(r[0]) - exact).abs() <= 0.5 + 1e-9, "{f:08x} over {b:08x}");
            }
        }
    }

    #[test]
    fn empty_is_the_identity() {
        let mut rng = Rng(11);
        for _ in 0..1000 {
            let p = RgbaF32(rng.premul());
            for op in [RgbaF32::composite_behind, RgbaF32::composite_in_front] {
                let mut x = [p; 3];
                op(&mut x, &[RgbaF32::EMPTY; 3]);
                assert_eq!(x, [p; 3]);
            }
            let p8 = Rgba8(rng.premul8().to_le_bytes());
            for op in [Rgba8::composite_behind, Rgba8::composite_in_front] {
                let mut x = [p8; 9];
                op(&mut x, &[Rgba8::EMPTY; 9]);
                assert_eq!(x, [p8; 9]);
            }
            let d = DepthPixel::new(rng.unit() * 100.0 - 50.0, rng.next() as u32);
            let mut x = [d; 5];
            DepthPixel::composite_behind(&mut x, &[DepthPixel::EMPTY; 5]);
            assert_eq!(x, [d; 5]);
        }
    }

    #[test]
    fn depth_keys_order_like_total_cmp() {
        let zs = [
            f32::NEG_INFINITY,
            -1e30,
            -1.0,
            -f32::MIN_POSITIVE,
            -1e-45,
            -0.0,
            0.0,
            1e-45,
            1.0,
            3e38,
            f32::INFINITY,
        ];
        for w in zs.windows(2) {
            assert!(
                DepthPixel::new(w[0], 0) < DepthPixel::new(w[1], 0),
                "{} < {}",
                w[0],
                w[1]
            );
        }
        for &z in &zs {
            assert_eq!(DepthPixel::new(z, 5).depth().to_bits(), z.to_bits());
            assert!(DepthPixel::new(z, u32::MAX) < DepthPixel::EMPTY);
        }
        assert_eq!(DepthPixel::new(f32::NAN, 1).depth(), f32::INFINITY);
        // Ties in depth: the smaller colour wins.
        assert!(DepthPixel::new(1.0, 2) < DepthPixel::new(1.0, 3));
        assert_eq!(DepthPixel::EMPTY.depth(), f32::INFINITY);
        assert_eq!(DepthPixel::EMPTY.rgba(), 0);
    }
}
