//! Robust secondary rays: where to start a ray that leaves a surface so that it does not hit that
//! surface again ("self-intersection", shadow acne).
//!
//! Pipeline stage: between a [`Hit`] and the next ray (shadow, ambient occlusion, reflection).
//! Input: the hit triangle, the hit and the geometric normal. Output: a new ray origin.
//!
//! Follows Wächter and Binder, "A Fast and Robust Method for Avoiding Self-Intersection" (Ray
//! Tracing Gems, ch. 6, 2019):
//! 1. **Reconstruct the point from barycentrics** ([`hit_point`]), not as `o + t d`: the error of
//!    `o + t d` grows with the distance travelled, the error of `(1 - u - v) a + u b + v c` only
//!    with the size of the coordinates (a few ULPs of `max |a|, |b|, |c|`).
//! 2. **Offset along the normal in integer ULPs** ([`offset_origin`]): each coordinate moves by
//!    `256 |n_i|` units in the last place, towards the side of the normal. An ULP scales with the
//!    coordinate, so the offset is relative: a fixed number of floats away from the surface, at
//!    `1e-8` and at `1e8` alike. Near the origin (`|p_i| < 1/32`), where ULPs become tiny, a fixed
//!    offset of `n_i / 65536` is used instead.
//!
//! The guarantee tested in this module and in `tests/offset.rs`: for triangles with coordinates
//! from `1e-8` to `1e8`, a ray started at `offset_origin(hit_point(..), n)` towards the side of
//! `n` never hits its own triangle again, and the origin moves by at most `256 + 1` ULPs of the
//! point per axis (or `1 / 65536` near 0).
//!
//! ```
//! use strahl::{Ray, Vec3, geometry::offset::{hit_point, offset_origin}, intersect::{PreparedRay, watertight}};
//! let tri = [Vec3::new(1e6, 0.0, 0.0), Vec3::new(1e6 + 1.0, 0.0, 0.0), Vec3::new(1e6, 1.0, 0.0)];
//! let ray = Ray::new(Vec3::new(1e6 + 0.25, 0.25, 5.0), -Vec3::Z);
//! let hit = watertight::intersect_scalar(&PreparedRay::new(&ray), &tri, 0).unwrap();
//! let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]); // +z: the side the ray came from
//! let p = offset_origin(hit_point(&tri, &hit), n);
//! assert!(p.z > 0.0);
//! let bounce = Ray::new(p, Vec3::new(0.3, -0.2, 1.0));
//! assert!(watertight::intersect_scalar(&PreparedRay::new(&bounce), &tri, 0).is_none());
//! ```

use super::{Hit, Triangle};
use glam::Vec3;

/// Below this magnitude a coordinate is offset by a fixed amount instead of in ULPs.
///
/// ```
/// use strahl::{Vec3, geometry::offset::{OFFSET_FLOAT_SCALE, OFFSET_ORIGIN, offset_origin}};
/// let near = Vec3::new(OFFSET_ORIGIN / 2.0, 0.0, 0.0);
/// assert_eq!(offset_origin(near, Vec3::X).x, near.x + OFFSET_FLOAT_SCALE); // fixed step
/// let far = Vec3::new(OFFSET_ORIGIN, 0.0, 0.0);
/// assert_ne!(offset_origin(far, Vec3::X).x, far.x + OFFSET_FLOAT_SCALE); // ULP step
/// ```
pub const OFFSET_ORIGIN: f32 = 1.0 / 32.0;
/// The fixed offset near the origin, per unit of the normal.
///
/// ```
/// use strahl::{Vec3, geometry::offset::{OFFSET_FLOAT_SCALE, offset_origin}};
/// let q = offset_origin(Vec3::ZERO, Vec3::new(0.0, -2.0, 0.0)); // the normal is normalised
/// assert_eq!(q, Vec3::new(0.0, -OFFSET_FLOAT_SCALE, 0.0));
/// ```
pub const OFFSET_FLOAT_SCALE: f32 = 1.0 / 65536.0;
/// ULPs per unit of the normal elsewhere.
///
/// ```
/// use strahl::{Vec3, geometry::offset::{OFFSET_INT_SCALE, offset_origin}};
/// let p = Vec3::new(1.0, 5.0, -7.0);
/// let q = offset_origin(p, Vec3::X);
/// assert_eq!(q.x.to_bits() - p.x.to_bits(), OFFSET_INT_SCALE as u32);
/// assert_eq!((q.y, q.z), (p.y, p.z)); // no normal there, no offset
/// ```
pub const OFFSET_INT_SCALE: f32 = 256.0;

/// The hit point `(1 - u - v) a + u b + v c` of `hit` on `tri`, from its barycentrics.
///
/// More accurate than `origin + t direction` for a ray that travelled far (see the
/// [module docs](self)).
///
/// ```
/// use strahl::{Hit, Vec3, geometry::offset::hit_point};
/// let tri = [Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0)];
/// let hit = Hit { t: 1.0, u: 0.25, v: 0.5, prim: 0 };
/// assert_eq!(hit_point(&tri, &hit), Vec3::new(1.0, 1.0, 0.0));
/// ```
#[inline]
pub fn hit_point(tri: &Triangle, hit: &Hit) -> Vec3 {
    let w = 1.0 - hit.u - hit.v;
    tri[0] * w + tri[1] * hit.u + tri[2] * hit.v
}

/// `p` moved off its surface towards the side of `n` (any length; it is normalised here), by
/// [`OFFSET_INT_SCALE`] ULPs per unit of the normal per axis, or [`OFFSET_FLOAT_SCALE`] near the
/// origin. To leave on the other side (transmission), pass `-n`.
///
/// A zero or non-finite `n`, or a non-finite `p`, returns `p` unchanged (nothing can be known of
/// the surface); never panics.
///
/// ```
/// use strahl::{Vec3, geometry::offset::offset_origin};
/// let p = Vec3::new(1e8, -3.0, 0.0);
/// let q = offset_origin(p, Vec3::X);
/// assert!(q.x > p.x && q.x - p.x <= 256.0 * 8.0); // 256 ULPs of 1e8 (an ULP is 8 there)
/// assert_eq!((q.y, q.z), (-3.0, 0.0));
/// assert_eq!(offset_origin(p, Vec3::ZERO), p);
/// // Any length: the normal of a triangle with 1e-12 edges (1e-24), or a huge one, as `Vec3::X`.
/// assert_eq!(offset_origin(p, Vec3::X * 1e-24), q);
/// assert_eq!(offset_origin(p, Vec3::X * 1e30), q);
/// ```
#[inline]
pub fn offset_origin(p: Vec3, n: Vec3) -> Vec3 {
    // Scaled by its largest component first, so that normals whose squared length overflows
    // (components beyond about 1e19) or underflows (below about 1e-19: the cross product of a
    // triangle with 1e-10 edges) still normalise.
    let m = n.abs().max_element();
    let Some(n) = (if m > 0.0 && m.is_finite() { n / m } else { n }).try_normalize() else {
        return p;
    };
    if !p.is_finite() {
        return p;
    }
    let axis = |p: f32, n: f32| -> f32 {
        if p.abs() < OFFSET_ORIGIN {
            return p + OFFSET_FLOAT_SCALE * n;
        }
        // |n| <= 1, so at most 256 ULPs. Moving the bits of |p| up or down moves p away from or
        // towards zero; the sign of n decides which way p must go.
        let ulps = (OFFSET_INT_SCALE * n.abs()) as i32;
        let away = (p > 0.0) == (n > 0.0);
        let bits = p.to_bits() as i32;
        let moved = if away {
            bits.saturating_add(ulps)
        } else {
            bits.saturating_sub(ulps)
        };
        let q = f32::from_bits(moved as u32);
        // NOTE: |p| >= 1/32, so moving towards zero by <= 256 ULPs never crosses it; moving away
        // can reach infinity only from the largest finite floats: keep p then.
        if q.is_finite() { q } else { p }
    };
    Vec3::new(axis(p.x, n.x), axis(p.y, n.y), axis(p.z, n.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_go_to_the_normal_side_by_bounded_ulps() {
        let cases = [
            (1.0f32, 1.0f32),
            (1.0, -1.0),
            (-1.0, 1.0),
            (-1.0, -1.0),
            (1e8, 0.5),
            (-1e8, -0.5),
            (1e-8, 1.0),
            (-1e-8, -1.0),
            (0.0, 1.0),
            (-0.0, -1.0),
            (0.03, 1.0),
            (f32::MAX, 1.0),
        ];
        for (p, n) in cases {
            let q = offset_origin(Vec3::new(p, 0.0, 0.0), Vec3::new(n, 0.0, 0.0)).x;
            assert!(q.is_finite(), "{p} {n}");
            if p == f32::MAX {
                assert_eq!(q, p); // would overflow: unchanged
                continue;
            }
            assert!(if n > 0.0 { q > p } else { q < p }, "{p} {n} -> {q}");
            if p.abs() >= OFFSET_ORIGIN {
                let ulps = (q.to_bits() as i64 - p.to_bits() as i64).abs();
                assert!(ulps <= 256, "{p} {n}: {ulps} ulps");
            } else {
                assert!((q - p).abs() <= OFFSET_FLOAT_SCALE * 1.0001);
            }
        }
    }

    #[test]
    fn bad_input_is_returned_unchanged() {
        let p = Vec3::new(1.0, 2.0, 3.0);
        assert_eq!(offset_origin(p, Vec3::ZERO), p);
        assert_eq!(offset_origin(p, Vec3::NAN), p);
        assert_eq!(offset_origin(p, Vec3::INFINITY), p);
        let inf = Vec3::new(f32::INFINITY, 0.0, 0.0);
        assert_eq!(offset_origin(inf, Vec3::X), inf);
        assert!(offset_origin(Vec3::NAN, Vec3::X).is_nan());
    }

    #[test]
    fn hit_point_interpolates_the_vertices() {
        let tri = [Vec3::ZERO, Vec3::X * 4.0, Vec3::Y * 2.0];
        let hit = Hit {
            t: 1.0,
            u: 0.25,
            v: 0.5,
            prim: 0,
        };
        assert_eq!(hit_point(&tri, &hit), Vec3::new(1.0, 1.0, 0.0));
    }
}
