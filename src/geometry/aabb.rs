use crate::math::{max_l, min_l};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// An axis-aligned bounding box, closed on both sides: a point `p` is inside when
/// `min <= p <= max` on every axis.
///
/// The empty box has `min = +inf` and `max = -inf`, so that growing it by anything gives that
/// thing's box, and every ray misses it. A box with `min == max` on an axis (a flat triangle's box)
/// is not empty: it has zero thickness and rays that cross its plane hit it.
///
/// ```
/// use strahl::{Aabb, Vec3};
/// let mut b = Aabb::EMPTY;
/// assert!(b.is_empty());
/// b.grow(Vec3::ZERO);
/// b.grow(Vec3::new(1.0, 2.0, 3.0));
/// assert_eq!(b.surface_area(), 2.0 * (1.0 * 2.0 + 2.0 * 3.0 + 3.0 * 1.0));
/// assert_eq!(b.longest_axis(), 2);
/// assert_eq!(b.centroid(), Vec3::new(0.5, 1.0, 1.5));
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

const _: () = assert!(core::mem::size_of::<Aabb>() == 24);

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box (`min = +inf`, `max = -inf`): the identity of [`union`](Self::union).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    /// assert_eq!(Aabb::EMPTY.union(&b), b);
    /// assert_eq!(Aabb::EMPTY.surface_area(), 0.0);
    /// assert!(!Aabb::EMPTY.contains_point(Vec3::ZERO));
    /// ```
    pub const EMPTY: Self = Self {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    /// The box with the given corners (not checked; `min > max` on an axis makes it empty).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::new(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0));
    /// assert_eq!(b.extent(), Vec3::new(2.0, 1.0, 1.0));
    /// assert!(Aabb::new(Vec3::ONE, Vec3::ZERO).is_empty()); // min > max: empty, no panic
    /// ```
    #[inline]
    pub const fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    /// The smallest box containing all `points` (empty for no points).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::from_points(&[Vec3::X, Vec3::Y]);
    /// assert_eq!(b, Aabb::new(Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)));
    /// ```
    #[inline]
    pub fn from_points(points: &[Vec3]) -> Self {
        let mut b = Self::EMPTY;
        for &p in points {
            b.grow(p);
        }
        b
    }

    /// `true` if the box contains no point (`min > max` on some axis, or a NaN bound).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// assert!(Aabb::EMPTY.is_empty());
    /// assert!(!Aabb::new(Vec3::ONE, Vec3::ONE).is_empty()); // a single point is not empty
    /// assert!(Aabb::new(Vec3::ZERO, Vec3::new(1.0, f32::NAN, 1.0)).is_empty());
    /// ```
    #[inline]
    pub fn is_empty(&self) -> bool {
        !(self.min.x <= self.max.x && self.min.y <= self.max.y && self.min.z <= self.max.z)
    }

    /// Extends the box to contain `p`. NaN coordinates are ignored.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let mut b = Aabb::EMPTY;
    /// b.grow(Vec3::new(1.0, -2.0, 3.0));
    /// assert_eq!(b, Aabb::new(Vec3::new(1.0, -2.0, 3.0), Vec3::new(1.0, -2.0, 3.0)));
    /// b.grow(Vec3::new(f32::NAN, 5.0, 0.0)); // the NaN x is ignored, y and z still grow
    /// assert_eq!(b, Aabb::new(Vec3::new(1.0, -2.0, 0.0), Vec3::new(1.0, 5.0, 3.0)));
    /// ```
    #[inline]
    pub fn grow(&mut self, p: Vec3) {
        // min_l / max_l return their second operand when the first is NaN.
        self.min = Vec3::new(min_l(p.x, self.min.x), min_l(p.y, self.min.y), min_l(p.z, self.min.z));
        self.max = Vec3::new(max_l(p.x, self.max.x), max_l(p.y, self.max.y), max_l(p.z, self.max.z));
    }

    /// Extends the box to contain `other`.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let mut b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    /// b.grow_aabb(&Aabb::new(Vec3::splat(-1.0), Vec3::splat(0.5)));
    /// assert_eq!(b, Aabb::new(Vec3::splat(-1.0), Vec3::ONE));
    /// b.grow_aabb(&Aabb::EMPTY); // growing by the empty box changes nothing
    /// assert_eq!(b, Aabb::new(Vec3::splat(-1.0), Vec3::ONE));
    /// ```
    #[inline]
    pub fn grow_aabb(&mut self, other: &Aabb) {
        *self = self.union(other);
    }

    /// The smallest box containing both boxes.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let a = Aabb::new(Vec3::ZERO, Vec3::ONE);
    /// let b = Aabb::new(Vec3::splat(2.0), Vec3::splat(3.0)); // disjoint from `a`
    /// let u = a.union(&b);
    /// assert_eq!(u, Aabb::new(Vec3::ZERO, Vec3::splat(3.0)));
    /// assert_eq!(u, b.union(&a));
    /// assert!(u.contains(&a) && u.contains(&b));
    /// ```
    #[inline]
    #[must_use]
    pub fn union(&self, other: &Aabb) -> Aabb {
        let lo = |a: f32, b: f32| min_l(a, b);
        let hi = |a: f32, b: f32| max_l(a, b);
        Aabb {
            min: Vec3::new(
                lo(other.min.x, self.min.x),
                lo(other.min.y, self.min.y),
                lo(other.min.z, self.min.z),
            ),
            max: Vec3::new(
                hi(other.max.x, self.max.x),
                hi(other.max.y, self.max.y),
                hi(other.max.z, self.max.z),
            ),
        }
    }

    /// `max - min` (negative or NaN components for the empty box).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.0, 0.0, 5.0));
    /// assert_eq!(b.extent(), Vec3::new(2.0, 0.0, 3.0));
    /// assert!(Aabb::EMPTY.extent().cmplt(Vec3::ZERO).all()); // -inf - +inf = -inf
    /// ```
    #[inline]
    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// Surface area `2 (dx dy + dy dz + dz dx)`; `0` for an empty box.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0));
    /// assert_eq!(b.surface_area(), 22.0); // 2 (2 + 6 + 3)
    /// let flat = Aabb::new(Vec3::ZERO, Vec3::new(2.0, 3.0, 0.0));
    /// assert_eq!(flat.surface_area(), 12.0); // both faces of a 2 x 3 rectangle
    /// // Inverted: the extent (-1, -1, -1) would give 6, but the box is empty.
    /// assert_eq!(Aabb::new(Vec3::ONE, Vec3::ZERO).surface_area(), 0.0);
    /// ```
    #[inline]
    pub fn surface_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let d = self.extent();
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }

    /// Half the surface area, which is all the SAH needs (it only compares ratios).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0));
    /// assert_eq!(b.half_area(), 11.0);
    /// assert_eq!(2.0 * b.half_area(), b.surface_area());
    /// assert_eq!(Aabb::EMPTY.half_area(), 0.0);
    /// ```
    #[inline]
    pub fn half_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let d = self.extent();
        d.x * d.y + d.y * d.z + d.z * d.x
    }

    /// The centre `(min + max) / 2`.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::new(Vec3::new(-2.0, 0.0, 1.0), Vec3::new(4.0, 0.0, 2.0));
    /// assert_eq!(b.centroid(), Vec3::new(1.0, 0.0, 1.5));
    /// assert!(b.contains_point(b.centroid()));
    /// assert!(Aabb::EMPTY.centroid().is_nan()); // +inf + -inf
    /// ```
    #[inline]
    pub fn centroid(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// The axis (0 = x, 1 = y, 2 = z) of largest extent; ties go to the lower axis; 0 for an
    /// empty box.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// assert_eq!(Aabb::new(Vec3::ZERO, Vec3::new(1.0, 3.0, 2.0)).longest_axis(), 1);
    /// assert_eq!(Aabb::new(Vec3::ZERO, Vec3::new(2.0, 1.0, 2.0)).longest_axis(), 0); // x and z tie
    /// assert_eq!(Aabb::EMPTY.longest_axis(), 0);
    /// ```
    #[inline]
    pub fn longest_axis(&self) -> usize {
        let d = self.extent();
        if d.y > d.x && d.y >= d.z {
            1
        } else if d.z > d.x && d.z > d.y {
            2
        } else {
            0
        }
    }

    /// `true` if `p` lies in the closed box.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    /// assert!(b.contains_point(Vec3::ONE)); // a corner: the box is closed
    /// assert!(b.contains_point(Vec3::new(-0.0, 0.5, 0.5))); // -0.0 == 0.0
    /// assert!(!b.contains_point(Vec3::new(0.5, 1.5, 0.5)));
    /// assert!(!b.contains_point(Vec3::new(f32::NAN, 0.5, 0.5)));
    /// ```
    #[inline]
    pub fn contains_point(&self, p: Vec3) -> bool {
        self.min.cmple(p).all() && p.cmple(self.max).all()
    }

    /// `true` if `other` lies in the closed box (an empty `other` is contained in everything).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3};
    /// let b = Aabb::new(Vec3::ZERO, Vec3::splat(2.0));
    /// assert!(b.contains(&b)); // closed: a box contains itself
    /// assert!(b.contains(&Aabb::new(Vec3::ONE, Vec3::ONE)));
    /// assert!(!b.contains(&Aabb::new(Vec3::ONE, Vec3::splat(3.0)))); // sticks out
    /// assert!(Aabb::EMPTY.contains(&Aabb::EMPTY) && !Aabb::EMPTY.contains(&b));
    /// ```
    #[inline]
    pub fn contains(&self, other: &Aabb) -> bool {
        other.is_empty() || (self.min.cmple(other.min).all() && other.max.cmple(self.max).all())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_box_properties() {
        let e = Aabb::EMPTY;
        assert!(e.is_empty());
        assert_eq!(e.surface_area(), 0.0);
        assert_eq!(e.longest_axis(), 0);
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert_eq!(e.union(&b), b);
        assert!(b.contains(&e));
    }

    #[test]
    fn flat_box_is_not_empty() {
        let b = Aabb::from_points(&[Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)]);
        assert!(!b.is_empty());
        assert_eq!(b.surface_area(), 2.0);
        assert!(b.contains_point(Vec3::new(0.5, 0.5, 0.0)));
    }

    #[test]
    fn grow_ignores_nan() {
        let mut b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        b.grow(Vec3::splat(f32::NAN));
        assert_eq!(b, Aabb::new(Vec3::ZERO, Vec3::ONE));
    }

    #[test]
    fn longest_axis_ties_go_low() {
        assert_eq!(Aabb::new(Vec3::ZERO, Vec3::ONE).longest_axis(), 0);
        assert_eq!(Aabb::new(Vec3::ZERO, Vec3::new(1.0, 2.0, 2.0)).longest_axis(), 1);
        assert_eq!(Aabb::new(Vec3::ZERO, Vec3::new(1.0, 1.0, 2.0)).longest_axis(), 2);
    }
}
