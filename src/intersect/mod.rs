//! Ray/box and ray/triangle kernels: a scalar reference and `x4` / `x8` SIMD forms of each.
//!
//! Pipeline stage: the innermost loop of every traversal. Input: a [`PreparedRay`] (a [`Ray`] with
//! its reciprocal direction, direction signs and watertight shear computed once) and boxes or
//! triangles in structure-of-arrays form ([`AabbX4`], [`AabbX8`], [`TriangleX4`], [`TriangleX8`]).
//! Output: hit masks and distances, or the closest [`Hit`](crate::Hit).
//!
//! | kernel | scalar reference | one ray, 4 prims | one ray, 8 prims | 4 / 8 rays, one prim |
//! |---|---|---|---|---|
//! | slab test ([`aabb`]) | [`intersect_aabb_scalar`] | [`intersect_aabb_x4`] | [`intersect_aabb_x8`] | |
//! | Möller-Trumbore ([`moller`]) | [`moller::intersect_scalar`] | [`moller::intersect_x4`] | [`moller::intersect_x8`] | [`moller::intersect_packet`] |
//! | watertight ([`watertight`]) | [`watertight::intersect_scalar`] | [`watertight::intersect_x4`] | [`watertight::intersect_x8`] | [`watertight::intersect_packet`] |
//! | `f64` references and bounds ([`reference`](mod@reference)) | [`reference::intersect_triangle_f64`], [`reference::intersect_aabb_f64`] | | | |
//!
//! [`reference`](mod@reference) holds `f64` references for the triangle and box tests, and the error bounds that
//! say when an `f32` answer must agree with them (every reported hit is checked against them in
//! `tests/f64_reference.rs`).
//!
//! Every SIMD kernel performs the same IEEE operations in the same order as its scalar reference
//! (no fused multiply-add anywhere), so hit/miss, primitive and `t`, `u`, `v` agree **exactly**
//! (0 ULP) between widths. The property tests in `tests/kernels.rs` check this lane by lane.
//!
//! # Policy for bad input (the same in every width)
//! - An invalid ray (see [`Ray::is_valid`]) hits nothing: [`PreparedRay::new`] gives it the empty
//!   interval `tmin = +inf, tmax = -inf`.
//! - A degenerate triangle ([`is_degenerate`](crate::geometry::is_degenerate): a non-finite vertex,
//!   or an exactly zero edge cross product) is never hit.
//! - A reported `t` is never NaN nor infinite: it satisfies `tmin <= t < tmax`, with `tmin`
//!   taken as `-f32::MAX` where it is `-inf` by [`PreparedRay::new`] (and the packet setup; a
//!   `PreparedRay` whose fields are written by hand keeps what it is given) (a triangle whose distance along the ray overflows
//!   is a miss, as in [Range](#range)).
//! - Boxes: see [`aabb`] for `+-0` direction components, origins on slab planes and flat boxes.
//!
//! # Range
//! The triangle tests form products of three coordinates (relative to the ray origin), so they are
//! accurate while those coordinates stay within about `1e-12 ..= 1e12` in magnitude (cubes within
//! `f32`'s normal range). Beyond `~7e12` the products overflow and the result is a miss, never a
//! NaN distance; below `~1e-12` they underflow and `t` loses relative accuracy. Scenes in
//! kilometres with millimetre detail (`1e-3 ..= 1e6`) are well inside.

pub mod aabb;
pub mod moller;
mod packet;
pub mod reference;
mod soa;
pub mod watertight;

pub use aabb::{AabbLanes, AabbX4, AabbX8, intersect_aabb_scalar, intersect_aabb_x4, intersect_aabb_x8};
pub use packet::{PreparedPacket, PreparedPacket4, PreparedPacket8};
pub use soa::{HitLanes, TriangleLanes, TriangleX4, TriangleX8};

use crate::geometry::Ray;
use glam::{Vec3, Vec3A};

/// A ray with everything the kernels derive from it computed once.
///
/// Build it with [`PreparedRay::new`]; during a closest-hit search, shrink [`tmax`](Self::tmax) to
/// the current hit distance so later boxes and triangles beyond it are culled.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::PreparedRay};
/// let r = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::new(0.0, -0.0, -2.0)));
/// assert_eq!(r.neg, [false, true, true]); // the sign comes from the sign bit: -0.0 is negative
/// assert_eq!(r.inv_dir.y, f32::NEG_INFINITY);
/// assert_eq!(r.k[2], 2); // the watertight test projects along z, the dominant axis
///
/// let bad = PreparedRay::new(&Ray::new(Vec3::splat(f32::NAN), Vec3::Z));
/// assert!(bad.is_empty()); // invalid rays get an empty interval and hit nothing
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreparedRay {
    /// Ray origin.
    pub origin: Vec3,
    /// Ray direction.
    pub direction: Vec3,
    /// `1 / direction` per component; `+-inf` for `+-0` (the sign follows the sign bit).
    pub inv_dir: Vec3,
    /// Smallest accepted distance (inclusive).
    pub tmin: f32,
    /// Largest distance (exclusive); shrink it to the closest hit found so far.
    pub tmax: f32,
    /// Sign bit of each direction component: selects which box bound is the near one. Always the
    /// sign bit of `inv_dir` too, which the single-ray box tests read instead (a ray built by
    /// hand must keep the two in step).
    pub neg: [bool; 3],
    /// Watertight test axis permutation `[kx, ky, kz]`, `kz` the dominant axis.
    pub k: [usize; 3],
    /// Watertight shear `(Sx, Sy, Sz) = (d[kx] / d[kz], d[ky] / d[kz], 1 / d[kz])`.
    pub shear: Vec3,
}

impl PreparedRay {
    /// For the fast slab test ([`Fast`](crate::traverse::Fast) traversals,
    /// [`aabb::intersect_aabb_fast_scalar`]): `inv_dir` with its magnitudes clamped to
    /// [`aabb::FAST_INV_MAX`] (signs kept), as Embree clamps: a zero or tiny direction component
    /// counts as `1e-18`, so that `origin * inv_dir` stays finite. Meant for directions of
    /// ordinary length: a component that is not tiny beside the others but below `1e-18` in
    /// absolute terms (a direction scaled to `1e-17` and less) is clamped too, and the fast test
    /// then misses boxes such a ray crosses. The conservative slab test expects the exact
    /// reciprocals.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::PreparedRay};
    /// let r = PreparedRay::new(&Ray::new(Vec3::ONE, Vec3::new(2.0, -0.0, 0.0))).with_fast_inv();
    /// assert_eq!(r.inv_dir, Vec3::new(0.5, -1e18, 1e18));
    /// ```
    // PERF: a cap relative to the direction's largest component (scale-free) made `Fast` closest
    // hits 10-20% slower on the trace bench's rays (bunny primary 11.5 -> 13.7 ms, best of 3,
    // even behind a branch only zero components take), so the clamp is Embree's absolute one.
    #[inline(always)]
    pub fn with_fast_inv(mut self) -> Self {
        let inv = Vec3A::from(self.inv_dir);
        self.inv_dir = inv.abs().min(Vec3A::splat(aabb::FAST_INV_MAX)).copysign(inv).into();
        self
    }

    /// Prepares `ray`. An invalid ray becomes one that hits nothing.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::PreparedRay};
    /// let r = PreparedRay::new(&Ray::with_range(Vec3::ONE, Vec3::new(2.0, -4.0, 0.5), 0.0, 10.0));
    /// assert_eq!(r.inv_dir, Vec3::new(0.5, -0.25, 2.0));
    /// assert_eq!(r.neg, [false, true, false]);
    /// assert_eq!(r.k[2], 1); // y dominates the direction
    /// assert_eq!((r.tmin, r.tmax), (0.0, 10.0));
    /// ```
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        Self::new_for(ray, true)
    }

    /// [`new`](Self::new), with the watertight test's fields ([`k`](Self::k),
    /// [`shear`](Self::shear)) left at [`EMPTY`](Self::EMPTY)'s unless `watertight`: for the
    /// traversals, which know their test at compile time ([`TriangleTest::WATERTIGHT`](crate::traverse::TriangleTest::WATERTIGHT)).
    /// Every other field is the same.
    #[doc(hidden)]
    #[inline(always)]
    pub fn new_for(ray: &Ray, watertight: bool) -> Self {
        // NOTE: subnormal direction components are flushed to a zero of the same sign: their
        // reciprocal overflows to infinity, so the slab test would treat the ray as parallel to
        // that slab while the triangle tests still moved along it, and a BVH could cull a hit
        // brute force finds (found by the `bvh` fuzz target). Every kernel sees the flushed
        // direction, so they all answer for the same ray.
        // PERF: three lanes at a time and without branches but the one for invalid rays (this
        // setup was a fifth of the cost of a primary ray that misses the scene).
        let raw = Vec3A::from(ray.direction);
        let tiny = raw.abs().cmplt(Vec3A::splat(f32::MIN_POSITIVE));
        let d = Vec3A::select(tiny, Vec3A::ZERO.copysign(raw), raw);
        // `Ray::is_valid`, with a direction that is zero once flushed also refused.
        if !(ray.origin.is_finite()
            && raw.is_finite()
            && d.cmpne(Vec3A::ZERO).any()
            && !ray.tmin.is_nan()
            && !ray.tmax.is_nan())
        {
            return Self::EMPTY;
        }
        let inv = Vec3A::ONE / d;
        let neg = d.is_negative_bitmask();
        // A hit is reported at a finite `t` only: with `tmin = -inf`, a ray whose direction is
        // tiny next to its distance from a triangle behind it would find it at `t = -inf` (the
        // quotient overflows), with barycentrics that can be NaN.
        let tmin = ray.tmin.max(-f32::MAX);
        // PERF: a return of its own, not one struct literal with `(k, shear)` chosen by an `if`:
        // that form made 8-ray packets 7% slower (bunny, 1024 x 1024, best of 120; the K-lane
        // preparation loop compiled worse), single rays the same.
        if !watertight {
            return Self {
                origin: ray.origin,
                direction: d.into(),
                inv_dir: inv.into(),
                tmin,
                tmax: ray.tmax,
                neg: [neg & 1 != 0, neg & 2 != 0, neg & 4 != 0],
                k: Self::EMPTY.k,
                shear: Self::EMPTY.shear,
            };
        }
        // Dominant axis of the direction; ties go to the lower axis.
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let (kx, ky) = ([1, 2, 0][kz], [2, 0, 1][kz]);
        let dz = d[kz];
        // Swap to preserve the triangles' winding when looking down a negative axis.
        let (kx, ky) = if dz < 0.0 { (ky, kx) } else { (kx, ky) };
        let shear = Vec3A::new(d[kx], d[ky], 1.0) / Vec3A::splat(dz);
        Self {
            origin: ray.origin,
            direction: d.into(),
            inv_dir: inv.into(),
            tmin,
            tmax: ray.tmax,
            neg: [neg & 1 != 0, neg & 2 != 0, neg & 4 != 0],
            k: [kx, ky, kz],
            shear: shear.into(),
        }
    }

    /// A ray that hits nothing: empty interval (`tmin = +inf`, `tmax = -inf`), all else finite.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::{PreparedRay, moller, watertight}};
    /// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
    /// // Aimed straight at the triangle, but its interval is empty: no kernel reports a hit.
    /// assert!(PreparedRay::EMPTY.is_empty());
    /// assert!(watertight::intersect_scalar(&PreparedRay::EMPTY, &tri, 0).is_none());
    /// assert!(moller::intersect_scalar(&PreparedRay::EMPTY, &tri, 0).is_none());
    /// assert_eq!(PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::ZERO)), PreparedRay::EMPTY); // an invalid ray
    /// ```
    pub const EMPTY: Self = Self {
        origin: Vec3::ZERO,
        direction: Vec3::Z,
        inv_dir: Vec3::new(f32::INFINITY, f32::INFINITY, 1.0),
        tmin: f32::INFINITY,
        tmax: f32::NEG_INFINITY,
        neg: [false; 3],
        k: [0, 1, 2],
        shear: Vec3::new(0.0, 0.0, 1.0),
    };

    /// `true` if the interval `[tmin, tmax)` is empty (or NaN): no kernel reports a hit.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::PreparedRay};
    /// assert!(!PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z)).is_empty());
    /// assert!(PreparedRay::new(&Ray::with_range(Vec3::ZERO, Vec3::Z, 2.0, 2.0)).is_empty()); // `[2, 2)` holds nothing
    /// assert!(PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::ZERO)).is_empty()); // invalid
    /// ```
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.tmin.partial_cmp(&self.tmax) != Some(core::cmp::Ordering::Less)
    }
}

impl From<&Ray> for PreparedRay {
    fn from(ray: &Ray) -> Self {
        Self::new(ray)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Hit, Triangle};

    type Kernel = fn(&PreparedRay, &Triangle, u32) -> Option<Hit>;

    /// `PreparedRay::new` as first written: one component at a time, with branches.
    fn prepare_reference(ray: &Ray) -> PreparedRay {
        if !ray.is_valid() {
            return PreparedRay::EMPTY;
        }
        let flush = |x: f32| {
            if x.abs() < f32::MIN_POSITIVE {
                0.0f32.copysign(x)
            } else {
                x
            }
        };
        let d = Vec3::new(flush(ray.direction.x), flush(ray.direction.y), flush(ray.direction.z));
        if d == Vec3::ZERO {
            return PreparedRay::EMPTY;
        }
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = if kz == 2 { 0 } else { kz + 1 };
        let mut ky = if kx == 2 { 0 } else { kx + 1 };
        if d[kz] < 0.0 {
            core::mem::swap(&mut kx, &mut ky);
        }
        let dz = d[kz];
        PreparedRay {
            origin: ray.origin,
            direction: d,
            inv_dir: Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z),
            tmin: ray.tmin.max(-f32::MAX),
            tmax: ray.tmax,
            neg: [d.x.is_sign_negative(), d.y.is_sign_negative(), d.z.is_sign_negative()],
            k: [kx, ky, kz],
            shear: Vec3::new(d[kx] / dz, d[ky] / dz, 1.0 / dz),
        }
    }

    #[test]
    fn prepared_rays_equal_the_reference_bit_for_bit() {
        let specials = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            -3.0,
            1e-39,
            -1e-39,
            1e-45,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let bits = |r: &PreparedRay| {
            let v = [r.origin, r.direction, r.inv_dir, r.shear];
            (
                v.map(|v| v.to_array().map(f32::to_bits)),
                r.tmin.to_bits(),
                r.tmax.to_bits(),
                r.neg,
                r.k,
            )
        };
        let mut rng = crate::scene::Rng::new(9);
        for i in 0..20_000 {
            let mut pick = || {
                if rng.u64().is_multiple_of(3) {
                    specials[(rng.u64() % specials.len() as u64) as usize]
                } else {
                    rng.range(-2.0, 2.0)
                }
            };
            let ray = Ray {
                origin: Vec3::new(pick(), pick(), pick()),
                direction: Vec3::new(pick(), pick(), pick()),
                tmin: if i % 7 == 0 { pick() } else { 0.0 },
                tmax: if i % 5 == 0 { pick() } else { f32::INFINITY },
            };
            let full = PreparedRay::new(&ray);
            assert_eq!(bits(&full), bits(&prepare_reference(&ray)), "{ray:?}");
            // Without the watertight fields: every other field the same, those at EMPTY's.
            let lean = PreparedRay::new_for(&ray, false);
            let watertight = |r: &PreparedRay| PreparedRay {
                k: full.k,
                shear: full.shear,
                ..*r
            };
            assert_eq!(bits(&watertight(&lean)), bits(&full), "{ray:?}");
            assert_eq!(
                (lean.k, bits(&lean).0[3]),
                (PreparedRay::EMPTY.k, bits(&PreparedRay::EMPTY).0[3])
            );
        }
    }

    /// Every width of both tests on one ray and one triangle; asserts they agree, returns the hit.
    fn all_widths(ray: &Ray, tri: &Triangle) -> [Option<Hit>; 2] {
        let pre = PreparedRay::new(ray);
        let x4 = TriangleX4::pack(&[*tri], &[0]);
        let x8 = TriangleX8::pack(&[*tri], &[0]);
        let wide = [
            [moller::intersect_x4(&pre, &x4), moller::intersect_x8(&pre, &x8)],
            [watertight::intersect_x4(&pre, &x4), watertight::intersect_x8(&pre, &x8)],
        ];
        let scalar: [Kernel; 2] = [moller::intersect_scalar, watertight::intersect_scalar];
        core::array::from_fn(|k| {
            let s = scalar[k](&pre, tri, 0);
            assert_eq!(wide[k], [s, s], "test {k}: widths disagree on {ray:?} {tri:?}");
            let mut p = PreparedPacket8::new(&[*ray; 8]);
            let mut h = HitLanes::default();
            let m = if k == 0 {
                moller::intersect_packet(&mut p, tri, 0, &mut h)
            } else {
                watertight::intersect_packet(&mut p, tri, 0, &mut h)
            };
            assert_eq!(m, if s.is_some() { 0xff } else { 0 });
            s
        })
    }

    #[test]
    fn triangle_edge_case_table() {
        let tri = [
            Vec3::new(-1.0, -1.0, 2.0),
            Vec3::new(1.0, -1.0, 2.0),
            Vec3::new(0.0, 1.0, 2.0),
        ];
        let flipped = [tri[0], tri[2], tri[1]];
        let nan = Vec3::splat(f32::NAN);
        let o = Vec3::ZERO;
        // (name, ray, triangle, expected t for both tests or None)
        let cases: &[(&str, Ray, Triangle, Option<f32>)] = &[
            ("front", Ray::new(o, Vec3::Z), tri, Some(2.0)),
            (
                "back face (both windings hit)",
                Ray::new(o, Vec3::Z),
                flipped,
                Some(2.0),
            ),
            ("behind the origin", Ray::new(o, -Vec3::Z), tri, None),
            ("unnormalised direction", Ray::new(o, Vec3::Z * 4.0), tri, Some(0.5)),
            (
                "parallel, in the plane",
                Ray::new(Vec3::new(-5.0, 0.0, 2.0), Vec3::X),
                tri,
                None,
            ),
            ("parallel, off the plane", Ray::new(o, Vec3::X), tri, None),
            ("tmax exclusive", Ray::with_range(o, Vec3::Z, 0.0, 2.0), tri, None),
            ("tmin inclusive", Ray::with_range(o, Vec3::Z, 2.0, 3.0), tri, Some(2.0)),
            ("beyond tmax", Ray::with_range(o, Vec3::Z, 0.0, 1.0), tri, None),
            (
                "-0 direction components",
                Ray::new(o, Vec3::new(-0.0, -0.0, 1.0)),
                tri,
                Some(2.0),
            ),
            ("outside", Ray::new(Vec3::new(5.0, 0.0, 0.0), Vec3::Z), tri, None),
            ("NaN origin", Ray::new(nan, Vec3::Z), tri, None),
            ("NaN direction", Ray::new(o, Vec3::new(0.0, f32::NAN, 1.0)), tri, None),
            (
                "inf direction",
                Ray::new(o, Vec3::new(0.0, 0.0, f32::INFINITY)),
                tri,
                None,
            ),
            ("zero direction", Ray::new(o, Vec3::ZERO), tri, None),
            ("NaN tmax", Ray::with_range(o, Vec3::Z, 0.0, f32::NAN), tri, None),
            ("NaN vertex", Ray::new(o, Vec3::Z), [tri[0], nan, tri[2]], None),
            (
                "inf vertex",
                Ray::new(o, Vec3::Z),
                [tri[0], Vec3::INFINITY, tri[2]],
                None,
            ),
            (
                "zero area (two equal vertices)",
                Ray::new(Vec3::new(0.0, -1.0, 0.0), Vec3::Z),
                [tri[0], tri[1], tri[1]],
                None,
            ),
            (
                "zero area (collinear)",
                Ray::new(o, Vec3::Z),
                [
                    Vec3::new(-1.0, 0.0, 2.0),
                    Vec3::new(0.0, 0.0, 2.0),
                    Vec3::new(1.0, 0.0, 2.0),
                ],
                None,
            ),
            (
                "all vertices equal",
                Ray::new(Vec3::new(1.0, 1.0, 0.0), Vec3::Z),
                [Vec3::new(1.0, 1.0, 2.0); 3],
                None,
            ),
            (
                "needle",
                Ray::new(o, Vec3::Z),
                [
                    Vec3::new(0.0, -1.0, 2.0),
                    Vec3::new(1e-6, 1.0, 2.0),
                    Vec3::new(0.0, 1.0, 2.0),
                ],
                Some(2.0),
            ),
            ("large (1e12)", Ray::new(o, Vec3::Z), tri.map(|v| v * 1e12), Some(2e12)),
            (
                "small (1e-12)",
                Ray::new(o, Vec3::Z),
                tri.map(|v| v * 1e-12),
                Some(2e-12),
            ),
            (
                "out of range (1e18): overflow is a miss, never NaN",
                Ray::new(o, Vec3::Z),
                tri.map(|v| v * 1e18),
                None,
            ),
        ];
        // Tolerance on t: 4 ULP (relative 2^-21).
        let close = |a: Option<f32>, b: Option<f32>| match (a, b) {
            (Some(a), Some(b)) => (a - b).abs() <= b.abs() * 4.8e-7,
            (a, b) => a == b,
        };
        for (name, ray, t, want) in cases {
            for (k, got) in all_widths(ray, t).iter().enumerate() {
                let got = got.map(|h| h.t);
                assert!(close(got, *want), "{name} (test {k}): got {got:?}, want {want:?}");
            }
        }
    }

    /// The edge function `U` rounds to 0 in `f32` but is `+2^-30` exactly, while `V` and `W` are
    /// negative: the origin lies just outside the edge BC, so the exact answer is a miss. Without
    /// the `f64` recomputation the `f32` test would report a hit.
    #[test]
    fn watertight_f64_fallback_rejects_rounded_edge() {
        let e = |k: i32| libm::ldexpf(1.0, -k);
        let tri = [
            Vec3::new(1.0, -1.0, 1.0),
            Vec3::new(1.0 + e(15), 1.0 + e(14), 1.0),
            Vec3::new(-1.0, -(1.0 + e(15)), 1.0),
        ];
        let (bx, by, cx, cy) = (tri[1].x, tri[1].y, tri[2].x, tri[2].y);
        assert_eq!(cx * by - cy * bx, 0.0, "the f32 edge function rounds to zero");
        assert!(
            (cx as f64) * (by as f64) - (cy as f64) * (bx as f64) > 0.0,
            "but is positive"
        );
        let [_, wt] = all_widths(&Ray::new(Vec3::ZERO, Vec3::Z), &tri);
        assert_eq!(wt, None);
    }
    /// Subnormal direction components become zeros of the same sign (their reciprocal would
    /// overflow), so the slab test and the triangle tests answer for the same ray; a direction
    /// with nothing but subnormals is invalid.
    #[test]
    fn subnormal_directions_are_flushed() {
        let r = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::new(-7e-15, 1e-45, -1.128e-42)));
        assert_eq!(r.direction.x, -7e-15);
        assert_eq!(
            (r.direction.y.to_bits(), r.direction.z.to_bits()),
            (0, (-0.0f32).to_bits())
        );
        assert_eq!((r.inv_dir.y, r.inv_dir.z), (f32::INFINITY, f32::NEG_INFINITY));
        assert!(r.neg[2] && !r.neg[1]);
        assert!(PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::splat(1e-40))).is_empty());
    }
}
