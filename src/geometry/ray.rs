use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// The invalid index: a [`Hit`] with `prim == INVALID` is a miss.
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
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.direction * t
    }

    /// `true` if kernels may report hits for this ray (see the type's docs).
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
    pub const NONE: Self = Self {
        t: f32::INFINITY,
        u: 0.0,
        v: 0.0,
        prim: INVALID,
    };

    /// `true` unless this is a miss.
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
