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
//! - A reported `t` is never NaN: it satisfies `tmin <= t < tmax`.
//! - Boxes: see [`aabb`] for `+-0` direction components, origins on slab planes and flat boxes.

pub mod aabb;
pub mod moller;
mod packet;
mod soa;
pub mod watertight;

pub use aabb::{AabbLanes, AabbX4, AabbX8, intersect_aabb_scalar, intersect_aabb_x4, intersect_aabb_x8};
pub use packet::{PreparedPacket, PreparedPacket4, PreparedPacket8};
pub use soa::{HitLanes, TriangleLanes, TriangleX4, TriangleX8};

use crate::geometry::Ray;
use crate::math::sign_bit;
use glam::Vec3;

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
    /// Sign bit of each direction component: selects which box bound is the near one.
    pub neg: [bool; 3],
    /// Watertight test axis permutation `[kx, ky, kz]`, `kz` the dominant axis.
    pub k: [usize; 3],
    /// Watertight shear `(Sx, Sy, Sz) = (d[kx] / d[kz], d[ky] / d[kz], 1 / d[kz])`.
    pub shear: Vec3,
}

impl PreparedRay {
    /// Prepares `ray`. An invalid ray becomes one that hits nothing.
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        if !ray.is_valid() {
            return Self::EMPTY;
        }
        let d = ray.direction;
        // Dominant axis of the direction; ties go to the lower axis.
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
        // Swap to preserve the triangles' winding when looking down a negative axis.
        if d[kz] < 0.0 {
            core::mem::swap(&mut kx, &mut ky);
        }
        let dz = d[kz];
        Self {
            origin: ray.origin,
            direction: d,
            inv_dir: Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z),
            tmin: ray.tmin,
            tmax: ray.tmax,
            neg: [sign_bit(d.x), sign_bit(d.y), sign_bit(d.z)],
            k: [kx, ky, kz],
            shear: Vec3::new(d[kx] / dz, d[ky] / dz, 1.0 / dz),
        }
    }

    /// A ray that hits nothing: empty interval (`tmin = +inf`, `tmax = -inf`), all else finite.
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
    #[inline]
    pub fn is_empty(&self) -> bool {
        !(self.tmin < self.tmax)
    }
}

impl From<&Ray> for PreparedRay {
    fn from(ray: &Ray) -> Self {
        Self::new(ray)
    }
}
