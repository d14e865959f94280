//! Ray/box slab test, robust as in Ize, "Robust BVH Ray Traversal" (JCGT 2013).
//!
//! For each axis the ray's entry and exit distances are `(bound - origin) * inv_dir`, with the near
//! bound chosen by the **sign bit** of the direction component. The box is hit when
//! `near <= far + |far| 2 gamma(3)` with `near = max(near_x, near_y, near_z, tmin)` and
//! `far = min(far_x, far_y, far_z, tmax)`.
//!
//! # Policy (identical in every width)
//! - **Conservative far bound.** Each distance carries three roundings (subtraction, reciprocal,
//!   product), so the far distance is moved outwards by `|far| 2 gamma(3)` (Ize 2013, eq. 8, which
//!   writes `far (1 + 2 gamma(3))` for `far >= 0`; the absolute value keeps the bound conservative
//!   for rays with `tmin < 0`, where a box behind the origin has a negative far distance): a ray
//!   that touches a box in exact arithmetic is never culled. The price is that boxes a few ULPs
//!   away may be visited too; a BVH only loses a little time.
//! - **`+0` and `-0` direction components.** `1 / +-0 = +-inf` and the near bound follows the sign
//!   bit, so both zeros give the same answer: a ray parallel to a slab overlaps it for every `t`
//!   when its origin lies in the closed interval `[min, max]` of that axis, and never otherwise.
//! - **Origin exactly on a slab plane with a zero direction component** gives `0 * inf = NaN`.
//!   The reductions ignore NaN candidates ([`max_l`] returns its second operand
//!   on NaN), so that axis does not constrain the ray: the ray lies in the face plane and touches
//!   the closed box. This also makes a zero-thickness (flat) box hittable by rays in its plane.
//! - **Zero-thickness boxes** (`min == max` on an axis, e.g. a flat triangle's box) are hit by rays
//!   crossing their plane: near and far distances coincide and the test is `<=`.
//! - **Invalid (NaN) rays** miss: their [`PreparedRay`] has an empty interval.
//! - **Empty boxes** (`min = +inf`, `max = -inf`, as used for unused lanes) always miss.
//! - **Boxes with a NaN bound** are not culled on that axis (conservative; BVH builders never make
//!   them).
//!
//! The returned entry distance is `max(near, tmin)` (not rounded down), for near-to-far ordering.

use super::PreparedRay;
use crate::geometry::Aabb;
use crate::math::{Lane, abs, f32x4, f32x8, gamma, max_l, min_l};

/// Relative widening of the far distance that makes the test conservative: `2 gamma(3)`; the box
/// is hit when `near <= far + |far| FAR_SLACK`.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::{PreparedRay, aabb::FAR_SLACK, intersect_aabb_scalar}};
/// let b = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
/// let o = Vec3::new(0.0, 0.0, -5.0);
/// // The box is entered at t = 4: a ray that ends an ulp before it still touches it...
/// let short = PreparedRay::new(&Ray::with_range(o, Vec3::Z, 0.0, 4.0f32.next_down()));
/// assert_eq!(intersect_aabb_scalar(&short, &b), Some(4.0));
/// // ...but not one that ends more than `|far| FAR_SLACK` before it.
/// let shorter = PreparedRay::new(&Ray::with_range(o, Vec3::Z, 0.0, 4.0 * (1.0 - 2.0 * FAR_SLACK)));
/// assert_eq!(intersect_aabb_scalar(&shorter, &b), None);
/// ```
pub const FAR_SLACK: f32 = 2.0 * gamma(3);

/// `N` boxes in structure-of-arrays form: `min[axis]` holds lane `i`'s lower bound on `axis`.
///
/// ```
/// use strahl::{Aabb, Vec3, intersect::AabbX8};
/// let b = AabbX8::from_boxes(&[Aabb::new(Vec3::ZERO, Vec3::ONE)]);
/// assert_eq!(b.get(0), Aabb::new(Vec3::ZERO, Vec3::ONE));
/// assert!(b.get(7).is_empty()); // unused lanes hold the empty box
/// ```
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct AabbLanes<L> {
    /// Lower bounds per axis.
    pub min: [L; 3],
    /// Upper bounds per axis.
    pub max: [L; 3],
}

/// Four boxes, SoA.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::{AabbX4, PreparedRay, intersect_aabb_scalar, intersect_aabb_x4}};
/// let boxes = [Aabb::new(Vec3::splat(-1.0), Vec3::ONE), Aabb::new(Vec3::splat(2.0), Vec3::splat(3.0))];
/// let r = PreparedRay::new(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z));
/// let (near, mask) = intersect_aabb_x4(&r, &AabbX4::from_boxes(&boxes));
/// assert_eq!(mask, 0b01);
/// assert_eq!(Some(near.to_array()[0]), intersect_aabb_scalar(&r, &boxes[0])); // the scalar reference's distance
/// ```
pub type AabbX4 = AabbLanes<f32x4>;
/// Eight boxes, SoA.
///
/// ```
/// use strahl::{Aabb, Vec3, intersect::AabbX8};
/// let boxes: Vec<Aabb> = (0..8).map(|i| Aabb::new(Vec3::ZERO, Vec3::splat(i as f32 + 1.0))).collect();
/// let lanes = AabbX8::from_boxes(&boxes);
/// assert!((0..8).all(|i| lanes.get(i) == boxes[i]));
/// assert_eq!(lanes.max[1].to_array(), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
/// ```
pub type AabbX8 = AabbLanes<f32x8>;

impl<L: Lane> AabbLanes<L> {
    /// All lanes empty.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::{AabbX8, PreparedRay, intersect_aabb_x8}};
    /// let b = AabbX8::empty();
    /// assert!((0..8).all(|i| b.get(i).is_empty()));
    /// let r = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
    /// assert_eq!(intersect_aabb_x8(&r, &b).1, 0); // empty boxes are never hit
    /// ```
    pub fn empty() -> Self {
        Self {
            min: [L::splat(f32::INFINITY); 3],
            max: [L::splat(f32::NEG_INFINITY); 3],
        }
    }

    /// Packs up to `N` boxes; lanes past `boxes.len()` are empty. Extra boxes are ignored.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, intersect::AabbX4};
    /// let boxes: Vec<Aabb> = (0..6).map(|i| Aabb::new(Vec3::splat(i as f32), Vec3::splat(i as f32 + 1.0))).collect();
    /// let lanes = AabbX4::from_boxes(&boxes);
    /// assert_eq!(lanes.min[0].to_array(), [0.0, 1.0, 2.0, 3.0]); // boxes 4 and 5 do not fit
    /// assert!((0..4).all(|i| lanes.get(i) == boxes[i]));
    /// ```
    pub fn from_boxes(boxes: &[Aabb]) -> Self {
        let mut lo = [[f32::INFINITY; 8]; 3];
        let mut hi = [[f32::NEG_INFINITY; 8]; 3];
        for (i, b) in boxes.iter().take(L::N).enumerate() {
            for a in 0..3 {
                lo[a][i] = b.min[a];
                hi[a][i] = b.max[a];
            }
        }
        Self {
            min: lo.map(|v| L::load(&v)),
            max: hi.map(|v| L::load(&v)),
        }
    }

    /// Lane `i` as an [`Aabb`].
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, intersect::AabbX4};
    /// let b = Aabb::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0));
    /// assert_eq!(AabbX4::from_boxes(&[Aabb::EMPTY, b]).get(1), b);
    /// ```
    pub fn get(&self, i: usize) -> Aabb {
        let f = |v: &[L; 3]| glam::Vec3::new(v[0].lane(i), v[1].lane(i), v[2].lane(i));
        Aabb::new(f(&self.min), f(&self.max))
    }

    /// The union of every lane's box (empty lanes hold the empty box, which the lane
    /// reductions skip; all lanes empty give [`Aabb::EMPTY`]).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, intersect::AabbX8};
    /// let (a, b) = (Aabb::new(Vec3::ZERO, Vec3::ONE), Aabb::new(Vec3::splat(-2.0), Vec3::splat(-1.0)));
    /// assert_eq!(AabbX8::from_boxes(&[a, Aabb::EMPTY, b]).union(), a.union(&b));
    /// assert_eq!(AabbX8::empty().union(), Aabb::EMPTY);
    /// ```
    #[inline]
    pub fn union(&self) -> Aabb {
        let (b, t) = (&self.min, &self.max);
        Aabb::new(
            glam::Vec3::new(b[0].min_lane(), b[1].min_lane(), b[2].min_lane()),
            glam::Vec3::new(t[0].max_lane(), t[1].max_lane(), t[2].max_lane()),
        )
    }
}

/// Scalar reference: the entry distance if `ray` hits `b`, else `None`.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::{PreparedRay, intersect_aabb_scalar}};
/// let b = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
/// let r = PreparedRay::new(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z));
/// assert_eq!(intersect_aabb_scalar(&r, &b), Some(4.0));
/// // A flat box (zero thickness in z) is hit by a ray crossing its plane:
/// let flat = Aabb::new(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0));
/// assert_eq!(intersect_aabb_scalar(&r, &flat), Some(5.0));
/// ```
#[inline]
pub fn intersect_aabb_scalar(ray: &PreparedRay, b: &Aabb) -> Option<f32> {
    let mut near = ray.tmin;
    let mut far = ray.tmax;
    // Walk the axes from z to x so the reduction order matches the lane kernels.
    for a in (0..3).rev() {
        // The sign of `inv_dir[a]` is `neg[a]`, read as the lane kernels do.
        let (lo, hi) = if ray.inv_dir[a].is_sign_negative() {
            (b.max[a], b.min[a])
        } else {
            (b.min[a], b.max[a])
        };
        let o = ray.origin[a];
        let inv = ray.inv_dir[a];
        // NaN candidates (0 * inf) are dropped by max_l / min_l (second operand wins).
        near = max_l((lo - o) * inv, near);
        far = min_l((hi - o) * inv, far);
    }
    if near <= far + abs(far) * FAR_SLACK {
        Some(near)
    } else {
        None
    }
}

/// One ray against `N` boxes: entry distances and the bit mask of lanes hit.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, math::f32x8};
/// use strahl::intersect::{AabbLanes, PreparedRay, aabb::intersect_aabb_lanes, intersect_aabb_scalar};
/// let boxes: Vec<Aabb> = (0..8)
///     .map(|i| Aabb::new(Vec3::new(i as f32 - 4.0, -1.0, 0.0), Vec3::new(i as f32 - 3.0, 1.0, 1.0)))
///     .collect();
/// let r = PreparedRay::new(&Ray::new(Vec3::new(-5.0, 0.0, -0.5), Vec3::new(1.0, 0.0, 0.2)));
/// let (near, mask) = intersect_aabb_lanes(&r, &AabbLanes::<f32x8>::from_boxes(&boxes));
/// assert_eq!(mask, 0b0111_1110); // the ray is within z = 0 ..= 1 for x = -2.5 ..= 2.5
/// for i in 1..7 {
///     assert_eq!(Some(near.to_array()[i]), intersect_aabb_scalar(&r, &boxes[i]));
/// }
/// ```
#[inline(always)]
pub fn intersect_aabb_lanes<L: Lane>(ray: &PreparedRay, b: &AabbLanes<L>) -> (L, u32) {
    let mut near = L::splat(ray.tmin);
    let mut far = L::splat(ray.tmax);
    for a in (0..3).rev() {
        // NOTE: the sign of `inv_dir[a]` is `neg[a]` (for every ray `PreparedRay::new` makes).
        // PERF: the plane choice written out here, not in a helper returning the two bounds by
        // value: that form loaded both and blended (any-hit rays 9%, batches of 8 AO rays 19%
        // slower on the bunny), where this one selects the address.
        // PERF: `neg`'s three bytes, just stored one by one, were reloaded as one word, a failed
        // store-to-load forwarding that held up every ray (a third of the time of a primary ray
        // that misses the scene).
        let (lo, hi) = if ray.inv_dir[a].is_sign_negative() {
            (b.max[a], b.min[a])
        } else {
            (b.min[a], b.max[a])
        };
        let o = L::splat(ray.origin[a]);
        let inv = L::splat(ray.inv_dir[a]);
        near = ((lo - o) * inv).max_l(near);
        far = ((hi - o) * inv).min_l(far);
    }
    let hit = near.le(far + far.abs() * L::splat(FAR_SLACK));
    (near, hit.bitmask())
}

/// The largest `|1 / direction|` the fast slab test uses: a zero (or tiny) direction component
/// counts as `1e-18`, as in Embree, so that `origin * inv` stays finite
/// ([`PreparedRay::with_fast_inv`]).
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, aabb::FAST_INV_MAX}};
/// let r = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::new(1.0, 0.0, -1e-30))).with_fast_inv();
/// assert_eq!(r.inv_dir, Vec3::new(1.0, FAST_INV_MAX, -FAST_INV_MAX));
/// ```
pub const FAST_INV_MAX: f32 = 1e18;

/// The fast slab test, scalar: the entry distance if `ray` hits `b`, else `None`, for a ray
/// prepared with [`PreparedRay::with_fast_inv`] (on other rays a zero direction component can
/// leave its axis unconstrained: never a wrong miss, but more boxes hit). Each plane's
/// distance is one fused multiply-add, `bound * inv - origin * inv` (Embree's default form), and
/// the box is hit when `near <= far`, without the conservative widening of
/// [`intersect_aabb_scalar`]: the rounding of `origin * inv` can move a distance by about
/// `|origin * inv| 2^-24`, so a ray that grazes a box, or starts on its surface, may be culled
/// (tested: away from the boxes' surfaces it answers as the conservative test). Used by the traversals of
/// [`Fast`](crate::traverse::Fast) tests. The same planes, reduction order and NaN rule as
/// [`intersect_aabb_scalar`] otherwise; the multiply-add is the lanes' (fused exactly where the
/// lane kernels are), so this equals [`intersect_aabb_fast_lanes`] lane by lane.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::{PreparedRay, aabb::intersect_aabb_fast_scalar}};
/// let b = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
/// let r = PreparedRay::new(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z)).with_fast_inv();
/// assert_eq!(intersect_aabb_fast_scalar(&r, &b), Some(4.0));
/// // Parallel to two slabs (zero direction components): inside them, hit; outside, missed.
/// let beside = PreparedRay::new(&Ray::new(Vec3::new(2.0, 0.0, -5.0), Vec3::Z)).with_fast_inv();
/// assert_eq!(intersect_aabb_fast_scalar(&beside, &b), None);
/// ```
#[inline]
pub fn intersect_aabb_fast_scalar(ray: &PreparedRay, b: &Aabb) -> Option<f32> {
    let fma = |x: f32, m: f32, a: f32| f32x4::splat(x).mul_add(f32x4::splat(m), f32x4::splat(a)).at(0);
    let mut near = ray.tmin;
    let mut far = ray.tmax;
    for a in (0..3).rev() {
        let (lo, hi) = if ray.inv_dir[a].is_sign_negative() {
            (b.max[a], b.min[a])
        } else {
            (b.min[a], b.max[a])
        };
        let (inv, neg_oi) = (ray.inv_dir[a], -(ray.origin[a] * ray.inv_dir[a]));
        near = max_l(fma(lo, inv, neg_oi), near);
        far = min_l(fma(hi, inv, neg_oi), far);
    }
    if near <= far { Some(near) } else { None }
}

/// The fast slab test ([`intersect_aabb_fast_scalar`]), one ray against `N` boxes: entry
/// distances and the bit mask of lanes hit.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::{AabbX4, PreparedRay}};
/// use strahl::intersect::aabb::{intersect_aabb_fast_lanes, intersect_aabb_fast_scalar};
/// let beside = Aabb::new(Vec3::new(2.0, -1.0, -1.0), Vec3::new(3.0, 1.0, 1.0));
/// let boxes = [Aabb::new(Vec3::splat(-1.0), Vec3::ONE), beside];
/// let r = PreparedRay::new(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z)).with_fast_inv();
/// let (near, mask) = intersect_aabb_fast_lanes(&r, &AabbX4::from_boxes(&boxes));
/// assert_eq!(mask, 0b01); // the second box lies beside the ray
/// assert_eq!(Some(near.to_array()[0]), intersect_aabb_fast_scalar(&r, &boxes[0]));
/// ```
#[inline(always)]
pub fn intersect_aabb_fast_lanes<L: Lane>(ray: &PreparedRay, b: &AabbLanes<L>) -> (L, u32) {
    let mut near = L::splat(ray.tmin);
    let mut far = L::splat(ray.tmax);
    for a in (0..3).rev() {
        let (lo, hi) = if ray.inv_dir[a].is_sign_negative() {
            (b.max[a], b.min[a])
        } else {
            (b.min[a], b.max[a])
        };
        let (m, c) = (L::splat(ray.inv_dir[a]), L::splat(-(ray.origin[a] * ray.inv_dir[a])));
        near = lo.mul_add(m, c).max_l(near);
        far = hi.mul_add(m, c).min_l(far);
    }
    (near, near.le(far).bitmask())
}

/// One ray against 4 boxes. Bit `i` of the mask is set where lane `i` is hit; the entry distances of
/// missed lanes are meaningless.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::{AabbX4, PreparedRay, intersect_aabb_x4}};
/// let boxes = AabbX4::from_boxes(&[
///     Aabb::new(Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, 1.0, 3.0)),
///     Aabb::new(Vec3::new(5.0, 5.0, 2.0), Vec3::new(6.0, 6.0, 3.0)),
/// ]);
/// let r = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// let (near, mask) = intersect_aabb_x4(&r, &boxes);
/// assert_eq!(mask, 0b0001);
/// assert_eq!(near.to_array()[0], 2.0);
/// ```
#[inline]
pub fn intersect_aabb_x4(ray: &PreparedRay, b: &AabbX4) -> (f32x4, u32) {
    intersect_aabb_lanes(ray, b)
}

/// One ray against 8 boxes; see [`intersect_aabb_x4`].
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::{AabbX8, PreparedRay, intersect_aabb_x8}};
/// let boxes = AabbX8::from_boxes(&[Aabb::new(Vec3::splat(-1.0), Vec3::ONE); 8]);
/// let r = PreparedRay::new(&Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z));
/// assert_eq!(intersect_aabb_x8(&r, &boxes).1, 0xff);
/// ```
#[inline]
pub fn intersect_aabb_x8(ray: &PreparedRay, b: &AabbX8) -> (f32x8, u32) {
    intersect_aabb_lanes(ray, b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Ray, Vec3};

    fn hit(o: Vec3, d: Vec3, b: Aabb) -> bool {
        let r = PreparedRay::new(&Ray::new(o, d));
        let s = intersect_aabb_scalar(&r, &b).is_some();
        assert_eq!(s, intersect_aabb_x4(&r, &AabbX4::from_boxes(&[b; 4])).1 == 0xf);
        assert_eq!(s, intersect_aabb_x8(&r, &AabbX8::from_boxes(&[b; 8])).1 == 0xff);
        s
    }

    #[test]
    fn edge_case_table() {
        let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let flat = Aabb::new(Vec3::new(0.0, 0.0, 0.5), Vec3::new(1.0, 1.0, 0.5));
        let cases: &[(&str, Vec3, Vec3, Aabb, bool)] = &[
            ("straight in", Vec3::new(0.5, 0.5, -1.0), Vec3::Z, unit, true),
            ("behind", Vec3::new(0.5, 0.5, 2.0), Vec3::Z, unit, false),
            ("origin inside", Vec3::splat(0.5), Vec3::X, unit, true),
            (
                "+0 parallel inside",
                Vec3::new(0.5, 0.5, -1.0),
                Vec3::new(0.0, 0.0, 1.0),
                unit,
                true,
            ),
            (
                "-0 parallel inside",
                Vec3::new(0.5, 0.5, -1.0),
                Vec3::new(-0.0, -0.0, 1.0),
                unit,
                true,
            ),
            (
                "+0 parallel outside",
                Vec3::new(1.5, 0.5, -1.0),
                Vec3::new(0.0, 0.0, 1.0),
                unit,
                false,
            ),
            (
                "-0 parallel outside",
                Vec3::new(1.5, 0.5, -1.0),
                Vec3::new(-0.0, 0.0, 1.0),
                unit,
                false,
            ),
            (
                "+0 origin on min plane",
                Vec3::new(0.0, 0.5, -1.0),
                Vec3::new(0.0, 0.0, 1.0),
                unit,
                true,
            ),
            (
                "-0 origin on min plane",
                Vec3::new(0.0, 0.5, -1.0),
                Vec3::new(-0.0, 0.0, 1.0),
                unit,
                true,
            ),
            (
                "+0 origin on max plane",
                Vec3::new(1.0, 0.5, -1.0),
                Vec3::new(0.0, 0.0, 1.0),
                unit,
                true,
            ),
            (
                "-0 origin on max plane",
                Vec3::new(1.0, 0.5, -1.0),
                Vec3::new(-0.0, 0.0, 1.0),
                unit,
                true,
            ),
            (
                "origin on an edge line",
                Vec3::new(1.0, 1.0, -1.0),
                Vec3::new(0.0, -0.0, 1.0),
                unit,
                true,
            ),
            ("flat box crossed", Vec3::new(0.5, 0.5, -1.0), Vec3::Z, flat, true),
            (
                "flat box crossed backwards",
                Vec3::new(0.5, 0.5, 2.0),
                -Vec3::Z,
                flat,
                true,
            ),
            (
                "flat box, ray in its plane",
                Vec3::new(-1.0, 0.5, 0.5),
                Vec3::X,
                flat,
                true,
            ),
            (
                "flat box, ray above its plane",
                Vec3::new(-1.0, 0.5, 0.6),
                Vec3::X,
                flat,
                false,
            ),
            ("flat box missed", Vec3::new(1.5, 0.5, -1.0), Vec3::Z, flat, false),
            ("diagonal through corner", Vec3::splat(-1.0), Vec3::ONE, unit, true),
            ("empty box", Vec3::ZERO, Vec3::ONE, Aabb::EMPTY, false),
            ("NaN origin", Vec3::new(f32::NAN, 0.5, -1.0), Vec3::Z, unit, false),
            (
                "NaN direction",
                Vec3::new(0.5, 0.5, -1.0),
                Vec3::new(0.0, f32::NAN, 1.0),
                unit,
                false,
            ),
            ("zero direction", Vec3::splat(0.5), Vec3::ZERO, unit, false),
            ("inf origin", Vec3::new(f32::INFINITY, 0.5, 0.5), -Vec3::X, unit, false),
        ];
        for (name, o, d, b, want) in cases {
            assert_eq!(hit(*o, *d, *b), *want, "{name}");
        }
    }

    #[test]
    fn tmin_tmax_are_honoured() {
        let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let r = |t0, t1| PreparedRay::new(&Ray::with_range(Vec3::new(0.5, 0.5, -1.0), Vec3::Z, t0, t1));
        assert!(intersect_aabb_scalar(&r(0.0, 0.5), &unit).is_none());
        assert!(intersect_aabb_scalar(&r(2.5, 9.0), &unit).is_none());
        assert_eq!(intersect_aabb_scalar(&r(1.5, 9.0), &unit), Some(1.5));
        assert!(intersect_aabb_scalar(&r(0.0, 1.0), &unit).is_some()); // touching at t = 1
    }

    /// Found by fuzzing (`fuzz/seeds/kernels/crash-box-*-negative-t`): with `tmin < 0`, a box
    /// touched at a single negative `t` must be hit; scaling the far distance by `1 + 2 gamma(3)`
    /// moved a negative far distance inwards and missed it.
    #[test]
    fn boxes_touched_at_negative_t() {
        let flat = Aabb::new(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0));
        let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let all = |o: Vec3, d: Vec3| Ray::with_range(o, d, f32::NEG_INFINITY, f32::INFINITY);
        let cases = [
            (
                "flat box behind the origin",
                all(Vec3::new(0.0, 0.0, 1.0), Vec3::Z),
                flat,
            ),
            (
                "flat box far behind",
                all(Vec3::new(0.3, 0.7, 12345.6), Vec3::new(1e-5, -1e-5, 3.0)),
                flat,
            ),
            (
                "edge grazed behind",
                all(Vec3::new(2.0, 1.0, 3.0), Vec3::new(1.0, 0.0, 1.0)),
                unit,
            ),
            ("corner grazed behind", all(Vec3::new(3.0, 3.0, 3.0), Vec3::ONE), unit),
        ];
        for (name, ray, b) in cases {
            let r = PreparedRay::new(&ray);
            let s = intersect_aabb_scalar(&r, &b);
            assert!(s.is_some_and(|t| t < 0.0), "{name}: {s:?}");
            assert_eq!(intersect_aabb_x4(&r, &AabbX4::from_boxes(&[b; 4])).1, 0xf, "{name}");
            assert_eq!(intersect_aabb_x8(&r, &AabbX8::from_boxes(&[b; 8])).1, 0xff, "{name}");
        }
    }

    /// The fast slab test: the scalar form equals both lane widths bit for bit (masks and entry
    /// distances), on random rays and boxes with zero direction components and origins on slab
    /// planes; and away from the boxes' surfaces it answers as the conservative test.
    #[test]
    fn fast_slabs_equal_in_every_width() {
        let mut rng = crate::scene::Rng::new(11);
        let mut hits = 0usize;
        for i in 0..20_000 {
            let mut d = rng.unit_vector();
            if i % 3 == 0 {
                d[(i / 3) % 3] = if i % 2 == 0 { 0.0 } else { -0.0 };
            }
            let mut o = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 4.0 - 2.0;
            let boxes: [Aabb; 8] = core::array::from_fn(|_| {
                let a = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 2.0 - 1.0;
                let b = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 2.0 - 1.0;
                Aabb::new(a.min(b), a.max(b))
            });
            if i % 5 == 0 {
                o.x = boxes[0].min.x; // on a slab plane
            }
            let r = PreparedRay::new(&Ray::new(o, d)).with_fast_inv();
            let exact = PreparedRay::new(&Ray::new(o, d));
            let (n4, m4) = intersect_aabb_fast_lanes(&r, &AabbX4::from_boxes(&boxes[..4]));
            let (n8, m8) = intersect_aabb_fast_lanes(&r, &AabbX8::from_boxes(&boxes));
            for (k, b) in boxes.iter().enumerate() {
                let s = intersect_aabb_fast_scalar(&r, b);
                assert_eq!(s.is_some(), m8 >> k & 1 != 0, "ray {i} box {k}");
                if let Some(t) = s {
                    assert_eq!(t.to_bits(), n8.lane(k).to_bits(), "ray {i} box {k}");
                }
                if k < 4 {
                    assert_eq!(s.is_some(), m4 >> k & 1 != 0, "ray {i} box {k}");
                    if let Some(t) = s {
                        assert_eq!(t.to_bits(), n4.lane(k).to_bits(), "ray {i} box {k}");
                    }
                }
                // Away from the surfaces (every box but the one whose plane holds the origin),
                // as the conservative test.
                if i % 5 != 0 || k != 0 {
                    assert_eq!(
                        s.is_some(),
                        intersect_aabb_scalar(&exact, b).is_some(),
                        "ray {i} box {k}"
                    );
                    hits += usize::from(s.is_some());
                }
            }
        }
        // Both answers well represented among the boxes compared.
        assert!((1_000..150_000).contains(&hits), "{hits} of 156,000 boxes hit");
    }
}
