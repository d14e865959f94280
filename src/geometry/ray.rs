use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// The invalid index: a [`Hit`] with `prim == INVALID` is a miss.
///
/// ```
/// use strahl::{Hit, geometry::INVALID};
/// assert_eq!(INVALID, u32::MAX);
/// let h = Hit { t: 1.0, u: 0.25, v: 0.25, prim: INVALID };
/// assert!(!h.is_hit()); // `prim` decides, whatever `t` says
/// ```
pub const INVALID: u32 = u32::MAX;

/// A ray `origin + t direction` for `t` in the half-open interval `[tmin, tmax)`.
///
/// 32 bytes, `#[repr(C)]`, [`Pod`]: a `&[u8]` of packed rays can be viewed as `&[Ray]` with
/// [`bytemuck::cast_slice`].
///
/// # Which rays are valid
///
/// A ray is [valid](Ray::is_valid) when its origin and direction are finite, the direction is not
/// zero, and `tmin`, `tmax` are not NaN (`tmax = +inf` is the usual "no limit"). Every kernel treats
/// an invalid ray as a ray that hits nothing; no kernel panics on one.
///
/// ```
/// use strahl::{Ray, Vec3};
/// let r = Ray::new(Vec3::ZERO, Vec3::Z);
/// assert!(r.is_valid());
/// assert_eq!(r.at(2.0), Vec3::new(0.0, 0.0, 2.0));
/// assert!(!Ray::new(Vec3::ZERO, Vec3::ZERO).is_valid());
/// let bytes: &[u8] = bytemuck::bytes_of(&r);
/// assert_eq!(bytemuck::from_bytes::<Ray>(bytes), &r);
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Ray {
    /// Where the ray starts.
    pub origin: Vec3,
    /// Smallest accepted distance (inclusive), in units of `direction`'s length.
    pub tmin: f32,
    /// Direction; need not be normalised (distances `t` are then in units of its length).
    pub direction: Vec3,
    /// Largest distance (exclusive).
    pub tmax: f32,
}

const _: () = assert!(core::mem::size_of::<Ray>() == 32);

impl Ray {
    /// A ray over `[0, +inf)`.
    ///
    /// ```
    /// use strahl::{Ray, Vec3};
    /// let r = Ray::new(Vec3::new(1.0, 2.0, 3.0), Vec3::X);
    /// assert_eq!((r.tmin, r.tmax), (0.0, f32::INFINITY));
    /// assert_eq!(r.at(1.5), Vec3::new(2.5, 2.0, 3.0));
    /// ```
    #[inline]
    pub const fn new(origin: Vec3, direction: Vec3) -> Self {
        Self {
            origin,
            tmin: 0.0,
            direction,
            tmax: f32::INFINITY,
        }
    }

    /// A ray over `[tmin, tmax)`.
    ///
    /// ```
    /// use strahl::{Ray, Vec3};
    /// // A shadow ray towards a light 4 units away, skipping self-hits near t = 0.
    /// let r = Ray::with_range(Vec3::ZERO, Vec3::Y, 1e-4, 4.0);
    /// assert!(r.is_valid());
    /// assert_eq!(r.at(r.tmax), Vec3::new(0.0, 4.0, 0.0));
    /// assert!(!Ray::with_range(Vec3::ZERO, Vec3::Y, 0.0, f32::NAN).is_valid());
    /// ```
    #[inline]
    pub const fn with_range(origin: Vec3, direction: Vec3, tmin: f32, tmax: f32) -> Self {
        Self {
            origin,
            tmin,
            direction,
            tmax,
        }
    }

    /// The point at distance `t`.
    ///
    /// ```
    /// use strahl::{Ray, Vec3};
    /// let r = Ray::new(Vec3::X, Vec3::new(0.0, 2.0, 0.0)); // not normalised
    /// assert_eq!(r.at(0.0), r.origin);
    /// assert_eq!(r.at(1.5), Vec3::new(1.0, 3.0, 0.0)); // t in units of |direction| = 2
    /// assert_eq!(r.at(-1.0), Vec3::new(1.0, -2.0, 0.0)); // [tmin, tmax) is not checked
    /// ```
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.direction * t
    }

    /// `true` if kernels may report hits for this ray (see the type's docs).
    ///
    /// ```
    /// use strahl::{Ray, Vec3};
    /// assert!(Ray::with_range(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY).is_valid());
    /// assert!(!Ray::new(Vec3::ZERO, Vec3::new(-0.0, 0.0, -0.0)).is_valid()); // zero direction
    /// assert!(!Ray::new(Vec3::new(f32::INFINITY, 0.0, 0.0), Vec3::X).is_valid());
    /// assert!(!Ray::new(Vec3::ZERO, Vec3::new(1.0, f32::NAN, 0.0)).is_valid());
    /// assert!(!Ray::with_range(Vec3::ZERO, Vec3::X, f32::NAN, 1.0).is_valid());
    /// ```
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.direction.is_finite()
            && self.direction != Vec3::ZERO
            && !self.tmin.is_nan()
            && !self.tmax.is_nan()
    }
}

/// The result of a ray/primitive test: distance `t`, barycentric `u` (weight of the second vertex)
/// and `v` (weight of the third), and the primitive's index.
///
/// The hit point is `(1 - u - v) v0 + u v1 + v v2` and also `ray.at(t)`.
/// [`Hit::NONE`] (`t = +inf`, `prim = INVALID`) stands for a miss where an `Option` is not used.
///
/// ```
/// use strahl::{Hit, geometry::INVALID};
/// assert_eq!(Hit::NONE.prim, INVALID);
/// assert!(!Hit::NONE.is_hit());
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
    /// Index of the primitive that was hit, or [`INVALID`].
    pub prim: u32,
}

const _: () = assert!(core::mem::size_of::<Hit>() == 16);

impl Hit {
    /// No hit.
    ///
    /// ```
    /// use strahl::{Hit, geometry::INVALID};
    /// assert_eq!((Hit::NONE.t, Hit::NONE.prim), (f32::INFINITY, INVALID));
    /// assert_eq!(Hit::default(), Hit::NONE);
    /// // Every real hit is nearer, so NONE starts a closest-hit search.
    /// let hits = [Hit { t: 3.0, u: 0.1, v: 0.2, prim: 4 }, Hit { t: 2.0, u: 0.5, v: 0.0, prim: 7 }];
    /// let best = hits.iter().fold(Hit::NONE, |best, h| if h.t < best.t { *h } else { best });
    /// assert_eq!(best.prim, 7);
    /// ```
    pub const NONE: Self = Self {
        t: f32::INFINITY,
        u: 0.0,
        v: 0.0,
        prim: INVALID,
    };

    /// `true` unless this is a miss.
    ///
    /// ```
    /// use strahl::Hit;
    /// assert!(Hit { t: 0.0, u: 0.0, v: 0.0, prim: 0 }.is_hit()); // t = 0 and prim 0 are a hit
    /// assert!(!Hit::NONE.is_hit());
    /// ```
    #[inline]
    pub fn is_hit(&self) -> bool {
        self.prim != INVALID
    }
}

impl Default for Hit {
    fn default() -> Self {
        Self::NONE
    }
}
