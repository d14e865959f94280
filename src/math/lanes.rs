//! The [`Lane`] trait: the small set of lane-wise operations the kernels need, implemented for
//! `wide`'s [`f32x4`], [`f32x8`] and [`f32x16`] with one NaN policy (see the module docs of
//! [`math`](crate::math)).

use core::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};
use wide::{f32x4, f32x8, f32x16, i32x4, i32x8, i32x16};

/// A vector of `N` `f32` lanes. Comparison results are lane masks of the same type (all bits set
/// where true), combined with `&` and `|`.
///
/// ```
/// use strahl::math::{Lane, f32x4, f32x8, max_l, min_l};
/// fn clamp01<L: Lane>(x: L) -> L { // written once for every width; NaN goes to 0
///     x.max_l(L::splat(0.0)).min_l(L::splat(1.0))
/// }
/// let x = [-1.0, 0.25, 2.0, f32::NAN, 0.5, -0.0, 1.0, 7.0];
/// let (a, b) = (clamp01(f32x8::load(&x)), clamp01(f32x4::load(&x)));
/// assert_eq!(a.to_array(), [0.0, 0.25, 1.0, 0.0, 0.5, 0.0, 1.0, 1.0]);
/// for i in 0..8 {
///     let scalar = min_l(max_l(x[i], 0.0), 1.0);
///     assert_eq!(a.lane(i).to_bits(), scalar.to_bits());
///     assert!(i >= 4 || b.lane(i).to_bits() == scalar.to_bits());
/// }
/// ```
pub trait Lane:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
    + Send
    + Sync
    + 'static
{
    /// Number of lanes.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4, f32x8, f32x16};
    /// assert_eq!((<f32x4 as Lane>::N, <f32x8 as Lane>::N, <f32x16 as Lane>::N), (4, 8, 16));
    /// assert_eq!(core::mem::size_of::<f32x8>(), <f32x8 as Lane>::N * 4);
    /// // 20 values fill two whole f32x8 and leave a tail of 4.
    /// assert_eq!([0.0f32; 20].chunks_exact(<f32x8 as Lane>::N).remainder().len(), 4);
    /// ```
    const N: usize;
    /// All lanes set to `v`.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x8};
    /// let v = <f32x8 as Lane>::splat(-0.0);
    /// assert_eq!(v.bitmask(), 0xff); // the sign of -0.0 reaches every lane
    /// assert!((0..8).all(|i| v.lane(i).to_bits() == (-0.0f32).to_bits()));
    /// assert_eq!(<f32x8 as Lane>::splat(0.0).bitmask(), 0);
    /// ```
    fn splat(v: f32) -> Self;
    /// Loads lanes from the first `N` values of `s` (`s.len() >= N`).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let data = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    /// assert_eq!(f32x4::load(&data).to_array(), [1.0, 2.0, 3.0, 4.0]); // values past N are ignored
    /// assert_eq!(f32x4::load(&data[2..]).to_array(), [3.0, 4.0, 5.0, 6.0]);
    /// ```
    fn load(s: &[f32]) -> Self;
    /// Writes the lanes to the first `N` values of `out`.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let mut out = [9.0f32; 6];
    /// f32x4::new([1.0, 2.0, 3.0, 4.0]).store(&mut out[1..]);
    /// assert_eq!(out, [9.0, 1.0, 2.0, 3.0, 4.0, 9.0]); // only N values written
    /// // A round trip through memory keeps the bits: -0.0, NaN and subnormals included.
    /// let v = f32x4::new([-0.0, f32::NAN, 1e-40, -1.0]);
    /// v.store(&mut out);
    /// assert_eq!(f32x4::load(&out).to_array().map(f32::to_bits), v.to_array().map(f32::to_bits));
    /// ```
    fn store(self, out: &mut [f32]);
    /// Lane `i` (slow; for tests and rare paths).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x8};
    /// let v = f32x8::new([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    /// assert_eq!(v.lane(5), 5.0);
    /// assert_eq!(core::array::from_fn::<f32, 8, _>(|i| v.lane(i)), v.to_array());
    /// ```
    fn lane(self, i: usize) -> f32;
    /// Per lane: `self > rhs ? self : rhs` (NaN in either yields `rhs`).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4, max_l};
    /// let a = f32x4::new([1.0, f32::NAN, 3.0, -0.0]);
    /// let b = f32x4::new([2.0, 5.0, f32::NAN, 0.0]);
    /// let m = a.max_l(b);
    /// assert_eq!(m.to_array()[..2], [2.0, 5.0]); // a NaN `self` loses
    /// assert!(m.lane(2).is_nan() && m.lane(3).is_sign_positive()); // a NaN `rhs` wins; a tie gives `rhs`
    /// for i in 0..4 {
    ///     assert_eq!(m.lane(i).to_bits(), max_l(a.lane(i), b.lane(i)).to_bits());
    /// }
    /// ```
    fn max_l(self, rhs: Self) -> Self;
    /// Per lane: `self < rhs ? self : rhs` (NaN in either yields `rhs`).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4, min_l};
    /// // A running minimum kept in `rhs` skips NaN candidates.
    /// let rows = [[3.0, f32::NAN, 1.0, 0.0], [2.0, 4.0, f32::NAN, -0.0]];
    /// let acc = rows.iter().fold(f32x4::splat(f32::INFINITY), |acc, r| f32x4::new(*r).min_l(acc));
    /// assert_eq!(acc.to_array(), [2.0, 4.0, 1.0, 0.0]);
    /// for i in 0..4 {
    ///     let scalar = rows.iter().fold(f32::INFINITY, |acc, r| min_l(r[i], acc));
    ///     assert_eq!(acc.lane(i).to_bits(), scalar.to_bits()); // same bits: lane 3 keeps +0.0
    /// }
    /// ```
    fn min_l(self, rhs: Self) -> Self;
    /// Mask of `self > rhs`.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let m = f32x4::new([1.0, 2.0, f32::NAN, 0.0]).gt(f32x4::splat(1.0));
    /// assert_eq!(m.bitmask(), 0b0010); // only lane 1; NaN compares false
    /// assert_eq!((m.lane(1).to_bits(), m.lane(0).to_bits()), (u32::MAX, 0)); // all bits or none
    /// ```
    fn gt(self, rhs: Self) -> Self;
    /// Mask of `self >= rhs`.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let (a, one) = (f32x4::new([1.0, 2.0, f32::NAN, -0.0]), f32x4::splat(1.0));
    /// assert_eq!(a.ge(one).bitmask(), 0b0011);
    /// assert_eq!(a.ge(f32x4::splat(0.0)).bitmask(), 0b1011); // -0.0 >= 0.0
    /// assert_eq!(a.ge(one).bitmask(), (a.gt(one) | a.eq(one)).bitmask());
    /// ```
    fn ge(self, rhs: Self) -> Self;
    /// Mask of `self < rhs`.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x8};
    /// let t = f32x8::new([0.5, 3.0, -1.0, f32::NAN, 2.0, f32::INFINITY, 1.999, 0.0]);
    /// let two = f32x8::splat(2.0);
    /// assert_eq!(t.lt(two).bitmask(), 0b1100_0101);
    /// // Not the complement of `ge`: a NaN lane is false in both.
    /// assert_eq!((t.lt(two) | t.ge(two)).bitmask(), 0b1111_0111);
    /// ```
    fn lt(self, rhs: Self) -> Self;
    /// Mask of `self <= rhs`.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// // Closed interval test 1 <= x <= 2: both bounds are inside, NaN is not.
    /// let x = f32x4::new([1.0, 2.0, 2.5, f32::NAN]);
    /// let inside = f32x4::splat(1.0).le(x) & x.le(f32x4::splat(2.0));
    /// assert_eq!(inside.bitmask(), 0b0011);
    /// ```
    fn le(self, rhs: Self) -> Self;
    /// Mask of `self == rhs`.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let a = f32x4::new([1.0, -0.0, f32::NAN, f32::INFINITY]);
    /// let b = f32x4::new([1.0, 0.0, f32::NAN, f32::INFINITY]);
    /// assert_eq!(a.eq(b).bitmask(), 0b1011); // -0.0 == 0.0, NaN != NaN
    /// assert_eq!(a.eq(a).bitmask(), 0b1011); // a NaN lane is not even equal to itself
    /// ```
    fn eq(self, rhs: Self) -> Self;
    /// Mask of `self != rhs` (true for NaN).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let a = f32x4::new([1.0, -0.0, f32::NAN, 2.0]);
    /// let b = f32x4::new([1.0, 0.0, 3.0, 3.0]);
    /// assert_eq!(a.ne(b).bitmask(), 0b1100);
    /// assert_eq!(a.ne(b).bitmask(), !a.eq(b).bitmask() & 0b1111); // the exact complement of `eq`
    /// assert_eq!(a.ne(a).bitmask(), 0b0100); // finds the NaN lanes
    /// ```
    fn ne(self, rhs: Self) -> Self;
    /// `mask ? a : b` per lane; `self` is the mask.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// // Keep the nearer distance per lane (a NaN candidate never wins).
    /// let t_old = f32x4::new([5.0, 1.0, 3.0, f32::INFINITY]);
    /// let t_new = f32x4::new([2.0, 4.0, f32::NAN, 7.0]);
    /// let nearer = Lane::select(t_new.lt(t_old), t_new, t_old);
    /// assert_eq!(nearer.to_array(), [2.0, 1.0, 3.0, 7.0]);
    /// ```
    fn select(self, a: Self, b: Self) -> Self;
    /// Bit `i` set where lane `i`'s sign bit (of a mask: its truth) is set.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x8};
    /// let hit = f32x8::new([1.0, 9.0, 2.0, 9.0, 9.0, 9.0, 9.0, 0.5]).lt(f32x8::splat(3.0));
    /// assert_eq!(hit.bitmask(), 0b1000_0101);
    /// assert_eq!((hit.bitmask().count_ones(), hit.bitmask().trailing_zeros()), (3, 0));
    /// // On plain values it reads the sign bits: -0.0 and -NaN count, +NaN does not.
    /// let v = f32x8::new([-1.0, 1.0, -0.0, 0.0, f32::NAN, -f32::NAN, 2.0, -2.0]);
    /// assert_eq!(v.bitmask(), 0b1010_0101);
    /// ```
    fn bitmask(self) -> u32;
    /// Flips the sign of lanes whose sign bit is set in `sign` (`self ^ (sign & -0.0)`).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4, sign_bit};
    /// let x = f32x4::new([2.0, 2.0, -3.0, 0.0]);
    /// let s = f32x4::new([1.0, -1.0, -0.5, -0.0]);
    /// let r = x.xor_sign(s);
    /// assert_eq!(r.to_array(), [2.0, -2.0, 3.0, 0.0]);
    /// for i in 0..4 {
    ///     let scalar = if sign_bit(s.lane(i)) { -x.lane(i) } else { x.lane(i) };
    ///     assert_eq!(r.lane(i).to_bits(), scalar.to_bits()); // lane 3 is -0.0
    /// }
    /// ```
    fn xor_sign(self, sign: Self) -> Self;
    /// Clears the sign bits.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let v = Lane::abs(f32x4::new([-2.5, -0.0, f32::NEG_INFINITY, -f32::NAN]));
    /// assert_eq!(v.bitmask(), 0); // every sign bit cleared, -0.0 and NaN included
    /// assert_eq!(v.to_array()[..3], [2.5, 0.0, f32::INFINITY]);
    /// assert!(v.lane(3).is_nan());
    /// ```
    fn abs(self) -> Self;
    /// `self * m + a`: fused (one rounding) where the target has FMA instructions (x86 with the
    /// `fma` feature, AArch64), else a multiply and an add, as `wide` does it; the same in every
    /// width on one target.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4, f32x8};
    /// // x * x - (1 + 2^-11) is 2^-24 exactly when fused, 0 when x * x is rounded first.
    /// let x = 1.0 + 2f32.powi(-12);
    /// let c = -(1.0 + 2f32.powi(-11));
    /// let r4 = Lane::mul_add(f32x4::splat(x), f32x4::splat(x), f32x4::splat(c));
    /// let r8 = Lane::mul_add(f32x8::splat(x), f32x8::splat(x), f32x8::splat(c));
    /// assert!(r8.lane(0) == 2f32.powi(-24) || r8.lane(0) == 0.0);
    /// assert!((0..8).all(|i| r8.lane(i).to_bits() == r4.lane(i % 4).to_bits())); // same in both widths
    /// ```
    #[inline(always)]
    fn mul_add(self, m: Self, a: Self) -> Self {
        self * m + a
    }
    /// Lane `i` (`i < N`; taken modulo `N`) read in place, without moving the vector.
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let v = f32x4::new([10.0, 11.0, 12.0, 13.0]);
    /// assert_eq!(v.at(2), v.lane(2));
    /// assert_eq!(v.at(6), 12.0); // 6 mod 4 = 2: no panic, unlike `lane`
    /// let vs = [v, v + v];
    /// assert_eq!(vs.iter().map(|v| v.at(3)).sum::<f32>(), 39.0); // read through references
    /// ```
    fn at(&self, i: usize) -> f32;
    /// A lane mask from bits: all bits set in lane `i` where bit `i` of `bits` is set, zero
    /// elsewhere (the inverse of [`bitmask`](Self::bitmask) on masks).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x8};
    /// let m = f32x8::from_bitmask(0b1010_0110);
    /// assert_eq!(m.bitmask(), 0b1010_0110);
    /// let picked = m.select(f32x8::splat(1.0), f32x8::splat(0.0));
    /// assert_eq!(picked.to_array(), [0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0]);
    /// ```
    fn from_bitmask(bits: u32) -> Self;
    /// The smallest lane, folded pairwise with [`min_l`](Self::min_l)'s rule (for NaN-free
    /// lanes: the minimum; which of `-0.0` and `0.0` it returns is unspecified).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x8};
    /// let v = f32x8::new([3.0, 9.0, -2.5, 7.0, f32::INFINITY, 0.5, -2.0, 4.0]);
    /// assert_eq!(v.min_lane(), -2.5);
    /// ```
    fn min_lane(self) -> f32;
    /// The largest lane, folded pairwise with [`max_l`](Self::max_l)'s rule (for NaN-free
    /// lanes: the maximum; which of `-0.0` and `0.0` it returns is unspecified).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// assert_eq!(f32x4::new([3.0, 9.0, -2.5, 7.0]).max_lane(), 9.0);
    /// ```
    fn max_lane(self) -> f32;
    /// The transpose of `N` rows of eight values: element `j` of the result holds `rows[i][j]` in
    /// lane `i` (`rows.len() >= N`; rows past `N` are ignored). Eight-value rows are what a
    /// [`Ray`](crate::Ray) is (`origin`, `tmin`, `direction`, `tmax`), so this turns `N` rays into
    /// the lanes of a packet in registers: shuffles where the width has them, not `8 N` scalar
    /// stores read back as vectors (which stalls on store-to-load forwarding).
    ///
    /// ```
    /// use strahl::math::{Lane, f32x4};
    /// let rows: [[f32; 8]; 4] = core::array::from_fn(|i| core::array::from_fn(|j| (10 * i + j) as f32));
    /// let t = f32x4::transpose8(&rows);
    /// assert_eq!(t[3].to_array(), [3.0, 13.0, 23.0, 33.0]);
    /// assert_eq!(t[7].to_array(), [7.0, 17.0, 27.0, 37.0]);
    /// ```
    fn transpose8(rows: &[[f32; 8]]) -> [Self; 8];
}

/// `f` folded over the lanes as a tree (halves, then quarters): a horizontal reduction in
/// registers, the same pairing for every width.
#[inline(always)]
fn fold_tree<const N: usize>(mut a: [f32; N], f: fn(f32, f32) -> f32) -> f32 {
    let mut w = N / 2;
    while w > 0 {
        for i in 0..w {
            a[i] = f(a[i], a[i + w]);
        }
        w /= 2;
    }
    a[0]
}

macro_rules! impl_lane {
    ($t:ty, $i:ty, $n:expr, |$rows:ident| $transpose:block) => {
        impl Lane for $t {
            const N: usize = $n;
            #[inline(always)]
            fn splat(v: f32) -> Self {
                <$t>::splat(v)
            }
            #[inline(always)]
            fn load(s: &[f32]) -> Self {
                let mut a = [0.0f32; $n];
                a.copy_from_slice(&s[..$n]);
                <$t>::new(a)
            }
            #[inline(always)]
            fn store(self, out: &mut [f32]) {
                out[..$n].copy_from_slice(&self.to_array());
            }
            #[inline(always)]
            fn lane(self, i: usize) -> f32 {
                self.to_array()[i]
            }
            #[inline(always)]
            fn max_l(self, rhs: Self) -> Self {
                // x86 MAXPS is exactly `a > b ? a : b`; elsewhere spell it out.
                #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
                {
                    self.fast_max(rhs)
                }
                #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
                {
                    <$t>::select(self.simd_gt(rhs), self, rhs)
                }
            }
            #[inline(always)]
            fn min_l(self, rhs: Self) -> Self {
                #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
                {
                    self.fast_min(rhs)
                }
                #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
                {
                    <$t>::select(self.simd_lt(rhs), self, rhs)
                }
            }
            #[inline(always)]
            fn gt(self, rhs: Self) -> Self {
                self.simd_gt(rhs)
            }
            #[inline(always)]
            fn ge(self, rhs: Self) -> Self {
                self.simd_ge(rhs)
            }
            #[inline(always)]
            fn lt(self, rhs: Self) -> Self {
                self.simd_lt(rhs)
            }
            #[inline(always)]
            fn le(self, rhs: Self) -> Self {
                self.simd_le(rhs)
            }
            #[inline(always)]
            fn eq(self, rhs: Self) -> Self {
                self.simd_eq(rhs)
            }
            #[inline(always)]
            fn ne(self, rhs: Self) -> Self {
                self.simd_ne(rhs)
            }
            #[inline(always)]
            fn select(self, a: Self, b: Self) -> Self {
                <$t>::select::<$t>(self, a, b)
            }
            #[inline(always)]
            fn bitmask(self) -> u32 {
                self.to_bitmask() as u32
            }
            #[inline(always)]
            fn xor_sign(self, sign: Self) -> Self {
                self ^ (sign & <$t>::splat(-0.0))
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn mul_add(self, m: Self, a: Self) -> Self {
                <$t>::mul_add(self, m, a)
            }
            #[inline(always)]
            fn at(&self, i: usize) -> f32 {
                bytemuck::cast_ref::<$t, [f32; $n]>(self)[i % $n]
            }
            #[inline(always)]
            fn from_bitmask(bits: u32) -> Self {
                let pow2: [i32; $n] = core::array::from_fn(|i| 1 << i);
                let pow2 = <$i>::new(pow2);
                bytemuck::cast((<$i>::splat(bits as i32) & pow2).simd_eq(pow2))
            }
            #[inline(always)]
            fn min_lane(self) -> f32 {
                fold_tree(self.to_array(), crate::math::min_l)
            }
            #[inline(always)]
            fn max_lane(self) -> f32 {
                fold_tree(self.to_array(), crate::math::max_l)
            }
            #[inline(always)]
            fn transpose8($rows: &[[f32; 8]]) -> [Self; 8] {
                $transpose
            }
        }
    };
}

impl_lane!(f32x4, i32x4, 4, |rows| {
    let rows = &rows[..4];
    let half = |h: usize| {
        f32x4::transpose(core::array::from_fn(|i| {
            f32x4::new([
                rows[i][4 * h],
                rows[i][4 * h + 1],
                rows[i][4 * h + 2],
                rows[i][4 * h + 3],
            ])
        }))
    };
    let (lo, hi) = (half(0), half(1));
    [lo[0], lo[1], lo[2], lo[3], hi[0], hi[1], hi[2], hi[3]]
});
impl_lane!(f32x8, i32x8, 8, |rows| {
    let rows = &rows[..8];
    f32x8::transpose(core::array::from_fn(|i| f32x8::new(rows[i])))
});
impl_lane!(f32x16, i32x16, 16, |rows| {
    let rows = &rows[..16];
    let half = |h: usize| f32x8::transpose(core::array::from_fn(|i| f32x8::new(rows[8 * h + i])));
    let (lo, hi) = (half(0), half(1));
    core::array::from_fn(|j| bytemuck::cast::<[f32x8; 2], f32x16>([lo[j], hi[j]]))
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{max_l, min_l};

    const SPECIALS: [f32; 8] = [0.0, -0.0, 1.0, -1.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e-40];

    fn check<L: Lane>() {
        for &a in &SPECIALS {
            for &b in &SPECIALS {
                let (la, lb) = (L::splat(a), L::splat(b));
                for i in 0..L::N {
                    assert_eq!(la.max_l(lb).lane(i).to_bits(), max_l(a, b).to_bits(), "max {a} {b}");
                    assert_eq!(la.min_l(lb).lane(i).to_bits(), min_l(a, b).to_bits(), "min {a} {b}");
                    assert_eq!(la.gt(lb).bitmask() >> i & 1 == 1, a > b);
                    assert_eq!(la.ge(lb).bitmask() >> i & 1 == 1, a >= b);
                    assert_eq!(la.lt(lb).bitmask() >> i & 1 == 1, a < b);
                    assert_eq!(la.le(lb).bitmask() >> i & 1 == 1, a <= b);
                    assert_eq!(la.eq(lb).bitmask() >> i & 1 == 1, a == b);
                    assert_eq!(la.ne(lb).bitmask() >> i & 1 == 1, a != b);
                }
            }
        }
    }

    /// `from_bitmask` inverts `bitmask` on every mask, and `min_lane` is the minimum of NaN-free
    /// lanes wherever the smallest value sits (checked with every lane in turn as the minimum,
    /// among values that repeat).
    fn check_masks_and_min<L: Lane>() {
        let n = L::N as u32;
        for bits in 0..(1u32 << n).min(1 << 16) {
            let m = L::from_bitmask(bits);
            assert_eq!(m.bitmask(), bits);
            for i in 0..L::N {
                let all = m.lane(i).to_bits() == u32::MAX;
                assert!(all == (bits >> i & 1 == 1) && (all || m.lane(i).to_bits() == 0));
            }
        }
        for lo in 0..L::N {
            let mut v = [0f32; 16];
            for (i, x) in v.iter_mut().enumerate().take(L::N) {
                *x = [3.0, f32::INFINITY, 1.5, 2.0][i % 4];
            }
            v[lo] = -7.25;
            assert_eq!(L::load(&v).min_lane(), -7.25);
            let mut w = v.map(|x| if x == f32::INFINITY { -9.0 } else { x });
            w[lo] = 17.5;
            assert_eq!(L::load(&w).max_lane(), 17.5);
        }
        assert_eq!(L::splat(f32::INFINITY).min_lane(), f32::INFINITY);
        assert_eq!(L::splat(f32::NEG_INFINITY).max_lane(), f32::NEG_INFINITY);
    }

    #[test]
    fn lanes_match_scalar_semantics() {
        check::<f32x4>();
        check::<f32x8>();
        check::<f32x16>();
        check_masks_and_min::<f32x4>();
        check_masks_and_min::<f32x8>();
        check_masks_and_min::<f32x16>();
    }

    fn check_transpose<L: Lane>() {
        let rows: [[f32; 8]; 16] = core::array::from_fn(|i| core::array::from_fn(|j| (100 * i + j) as f32 - 0.5));
        let t = L::transpose8(&rows);
        for (j, v) in t.iter().enumerate() {
            for (i, row) in rows.iter().enumerate().take(L::N) {
                assert_eq!(v.lane(i).to_bits(), row[j].to_bits());
            }
        }
    }

    #[test]
    fn transpose8_is_the_transpose() {
        check_transpose::<f32x4>();
        check_transpose::<f32x8>();
        check_transpose::<f32x16>();
    }
}
