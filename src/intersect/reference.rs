//! `f64` references for ray/triangle and ray/box, with the error bounds that tie the `f32` kernels
//! to them.
//!
//! Pipeline stage: none at run time. This is the judge of the [`moller`](super::moller),
//! [`watertight`](super::watertight) and [slab](super::aabb) kernels: `tests/f64_reference.rs`
//! checks every hit they report against it, and fuzz targets or callers that want to know how far
//! an `f32` answer can be trusted can ask it too. Input: the same [`Ray`], [`Triangle`] and
//! [`Aabb`] the kernels take (widened exactly to `f64`). Output: `t` and barycentrics of the ray's
//! crossing of the triangle's plane, the slab interval of a box, and for triangles a [`Verdict`]
//! that says whether every `f32` kernel must hit, must miss, or may answer either way.
//!
//! # Policy
//! The references answer for the ray the kernels see: an invalid ray ([`Ray::is_valid`]) or an
//! empty interval hits nothing, and subnormal direction components are flushed to zeros of the
//! same sign, as [`PreparedRay::new`] does. A [degenerate](crate::geometry::is_degenerate)
//! triangle (the same `f32` predicate the kernels use) is never hit. A triangle is closed (points
//! on its edges are inside) and a hit needs `tmin <= t < tmax`.
//!
//! # How exact the references are
//! Vertex differences `v_j - v_i` and `v_i - o` of two `f32`s are exact in `f64` (unless their
//! exponents differ by more than 29, where they carry one rounding of `2^-53`); the normal
//! `n = (v1 - v0) x (v2 - v0)`, `t = ((v0 - o) . n) / (d . n)` and the barycentrics
//! `b_i = d . ((v_j - o) x (v_k - v_j)) / (d . n)` (`(i, j, k)` cyclic) are each a few `f64`
//! roundings of products of those differences. The same analysis as below with `u = 2^-53` bounds
//! their error by `2^-29` times the `f32` bounds, which the slack in the constants covers.
//!
//! # The bound (both `f32` triangle kernels)
//! With `u = 2^-24` (the `f32` unit roundoff) and, all in `f64` from the inputs,
//! ```text
//! M = max_i |v_i - o|_inf        how far the vertices are from the ray origin
//! L = max_ij |v_j - v_i|_inf      the longest edge
//! D = |d|_inf                     the ray direction (after flushing)
//! N = |d . n|                     n = (v1 - v0) x (v2 - v0): small for grazing rays and needles
//! A = max(1, |b_0| + |b_1| + |b_2|)   (1 where the ray crosses inside the triangle)
//! K = D (M + A L) (A L + 8 u M)
//! G = N - 320 u K                 (G <= 0: ill-conditioned, no bound)
//! bary:  |b32 - b| <= Db = u A (400 K + 8 N) / G
//! t:     |t32 - t| <= Dt = u (600 K L / (D G) + 16 M / D)     (for exact hits)
//! ```
//! Read `K / G` as the condition number `L^2 D / |d . n| ~ 1 / (sin(grazing angle) sin(corner))`
//! times `(M + L) / L`: so `Dt ~ c u (L + M) / (|d| sin(grazing) sin(corner))`, the form
//! `c u (|t| + M / |d|)` (`|t| |d| <= M` for a hit) amplified for grazing rays and needles.
//!
//! **Why.** Every product, sum and difference of the kernels rounds with a relative error of at
//! most `u`, and no FMA is used. *Möller-Trumbore*: `det = e1 . (d x e2)` carries at most 7
//! roundings per monomial, so `|det32 - d . n| <= gamma(7) sum |e1| (|d| x |e2|) <= 42 u D L^2`;
//! the numerators of `u`, `v` (7 roundings, `s = o - v0` with `|s| <= M`) are off by at most
//! `42 u D M L` and the numerator of `t` (8) by `48 u M L^2`; dividing, `u32` and `v32` are
//! within `(42 u D L (M + A L)) / G + 3 u A` and `1 - u - v` within twice that. *Watertight*:
//! each sheared coordinate `A[kx] - Sx A[kz]` (`|Sx| <= 1`, 4 roundings) is within
//! `a = 8 u M` of exact; the sheared vertices of a crossing at barycentrics `b` lie within
//! `P = 2 A L` of the ray, so an edge function `Cx By - Cy Bx` (2 more roundings, or the `f64`
//! recomputation, which is no worse) is within `4 P a + 2 a^2 + 2 gamma(2) (P + a)^2 <= 96 u K / D`
//! of exact, where the exact edge functions sum to `N / D`; the barycentric `V / det` is then
//! within `(1 + 3 A) 96 u K / G + 2 u A N / G + 2 u`. `t32` is the barycentric combination of
//! the vertices' depths `w_i = A[kz] / d[kz]` with the computed weights, so it moves by at most
//! `sum |db_i| max_i |w_i - t| <= 6 (96 u K / G) L / D`, plus 6 roundings of `max |w_i| <= M / D`.
//! Both kernels' figures are below `Db` and `Dt` (`det != 0` follows from `G > 0`).
//!
//! The analysis assumes no `f32` overflow or underflow in between, which holds in the range of
//! the [module docs](super#range); outside `2^-90 <= u K`, `K <= 2^90` [`Crossing::is_ill_conditioned`]
//! is `true`.
//!
//! Consequences, checked by `tests/f64_reference.rs`: if the reference's barycentrics are all
//! above `Db` and `tmin + Dt <= t < tmax - Dt`, both kernels hit, in every width, within `Dt`
//! ([`Verdict::Hit`]); if one is below `-Db`, or `t` is more than `Dt` outside the interval, both
//! miss ([`Verdict::Miss`]); in between ([`Verdict::KnifeEdge`], a crossing within rounding of an
//! edge, of `tmin` or `tmax`, or ill-conditioned) either answer is correct. Barycentric `b_i` is
//! the distance to the opposite edge over the triangle's height there, so a knife edge is a hit
//! point within `Db` heights of an edge.
//!
//! # The slab test
//! Each `f32` entry or exit candidate `(bound - o) * (1 / d)` carries 3 roundings, so it is within
//! `gamma(3)` relative of its exact value, and so are the maximum and minimum of them. Hence:
//! the `f32` test hits every box the exact test hits (its far bound is widened by `2 gamma(3)`);
//! when it hits a box the exact test misses, `near - far <= AABB_GAP_REL_BOUND max(|near|, |far|)`;
//! and its entry distance is within [`AABB_ENTRY_REL_BOUND`] of the exact one, relatively.

use super::PreparedRay;
use crate::geometry::{Aabb, Ray, Triangle, is_degenerate};

/// `f32` unit roundoff `2^-24`, in `f64`.
const U: f64 = 1.0 / 16_777_216.0;

/// `gamma(3) = 3 u / (1 - 3 u)` for `f32`, in `f64`.
const GAMMA3: f64 = 3.0 * U / (1.0 - 3.0 * U);

/// Relative error bound of the `f32` slab test's entry distance against [`intersect_aabb_f64`]:
/// `|entry32 - entry64| <= AABB_ENTRY_REL_BOUND |entry64|` (`gamma(3)`, plus `2^-50` for the `f64`
/// side).
///
/// ```
/// use strahl::intersect::reference::AABB_ENTRY_REL_BOUND;
/// assert!(AABB_ENTRY_REL_BOUND > 1.78e-7 && AABB_ENTRY_REL_BOUND < 1.8e-7);
/// ```
pub const AABB_ENTRY_REL_BOUND: f64 = GAMMA3 + 1.0 / (1u64 << 50) as f64;

/// How far apart, relatively, the exact near and far distances of a box can be when the `f32`
/// slab test still hits it: `near - far <= AABB_GAP_REL_BOUND max(|near|, |far|)` (`5 gamma(3)`:
/// `gamma(3)` on each side, `2 gamma(3)` of deliberate widening and the widening's own rounding).
///
/// ```
/// use strahl::intersect::reference::{AABB_GAP_REL_BOUND, AABB_ENTRY_REL_BOUND};
/// assert!(AABB_GAP_REL_BOUND < 5.0 * AABB_ENTRY_REL_BOUND);
/// ```
pub const AABB_GAP_REL_BOUND: f64 = 5.0 * GAMMA3;

/// A hit found by the `f64` reference.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::reference::intersect_triangle_f64};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let h = intersect_triangle_f64(&Ray::new(Vec3::ZERO, Vec3::Z), &tri).unwrap();
/// assert_eq!((h.t, h.u, h.v, h.margin), (2.0, 0.25, 0.5, 0.25));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitF64 {
    /// Distance along the ray, in units of the direction's length.
    pub t: f64,
    /// Barycentric weight of the second vertex (as [`Hit::u`](crate::Hit::u)).
    pub u: f64,
    /// Barycentric weight of the third vertex (as [`Hit::v`](crate::Hit::v)).
    pub v: f64,
    /// The smallest of the three barycentrics, `>= 0`: how far inside the triangle the hit is, in
    /// heights of the triangle (0 on an edge). Compare it with [`Crossing::bary_bound`].
    pub margin: f64,
}

/// Where a ray crosses a triangle's plane, in `f64`, with the error bounds of the `f32` kernels
/// for this ray and triangle (see the [module docs](self)).
///
/// ```
/// use strahl::{Ray, Vec3, intersect::reference::crossing_f64};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let c = crossing_f64(&Ray::new(Vec3::new(3.0, 0.0, 0.0), Vec3::Z), &tri).unwrap();
/// assert_eq!(c.t, 2.0);
/// assert!(c.bary.iter().any(|&b| b < 0.0)); // outside: the crossing exists, the hit does not
/// assert!(c.hit().is_none());
/// let inside = crossing_f64(&Ray::new(Vec3::new(0.1, -0.2, 0.0), Vec3::Z), &tri).unwrap();
/// assert!(inside.hit().is_some() && inside.t_bound < 1e-3 && inside.bary_bound < 1e-3);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crossing {
    /// Distance to the plane (NaN for a ray exactly parallel to it).
    pub t: f64,
    /// Barycentrics `[b0, b1, b2]` of the crossing (weights of the three vertices; summing to 1,
    /// all `>= 0` inside). NaN for a parallel ray.
    pub bary: [f64; 3],
    /// The ray's `tmin` (inclusive).
    pub tmin: f64,
    /// The ray's `tmax` (exclusive).
    pub tmax: f64,
    /// `Dt`: bound on `|t32 - t|` for a hit of an `f32` kernel where the exact answer is a hit;
    /// `+inf` when ill-conditioned.
    pub t_bound: f64,
    /// `Db`: bound on the error of each `f32` barycentric (and of the kernels' inside tests);
    /// `+inf` when ill-conditioned.
    pub bary_bound: f64,
}

/// What the `f32` kernels may answer for one ray and triangle, by the `f64` reference and its
/// bound.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::reference::{Verdict, classify_triangle}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let v = classify_triangle(&Ray::new(Vec3::ZERO, Vec3::Z), &tri);
/// assert!(matches!(v, Verdict::Hit(h) if h.t == 2.0));
/// // A ray exactly through the vertex (0, 1): within rounding of two edges.
/// let v = classify_triangle(&Ray::new(Vec3::new(0.0, 1.0, 0.0), Vec3::Z), &tri);
/// assert!(matches!(v, Verdict::KnifeEdge(Some(_))));
/// assert_eq!(classify_triangle(&Ray::new(Vec3::new(5.0, 0.0, 0.0), Vec3::Z), &tri), Verdict::Miss);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Verdict {
    /// A clear miss: every `f32` kernel must miss.
    Miss,
    /// A clear hit: every `f32` kernel must hit, with `|t32 - t| <= t_bound`.
    Hit(HitF64),
    /// Within rounding of an edge, of `tmin` or `tmax`, or ill-conditioned: an `f32` kernel may
    /// answer either way. Holds the reference's own answer.
    KnifeEdge(Option<HitF64>),
}

impl Crossing {
    /// The reference's hit: inside the closed triangle and `tmin <= t < tmax`.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::reference::crossing_f64};
    /// let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
    /// let c = crossing_f64(&Ray::new(Vec3::new(0.0, 0.0, 1.0), -Vec3::Z), &tri).unwrap();
    /// assert_eq!(c.hit().unwrap().margin, 0.0); // on the vertex v0: inside a closed triangle
    /// ```
    pub fn hit(&self) -> Option<HitF64> {
        let [b0, b1, b2] = self.bary;
        let margin = b0.min(b1).min(b2);
        // NaN fails every comparison and misses.
        (margin >= 0.0 && self.t >= self.tmin && self.t < self.tmax).then_some(HitF64 {
            t: self.t,
            u: b1,
            v: b2,
            margin,
        })
    }

    /// `true` if the bounds do not apply (`G <= 0`, a parallel ray, or magnitudes where `f32`
    /// intermediates may overflow or underflow): any `f32` answer is then acceptable.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::reference::crossing_f64};
    /// let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
    /// let grazing = Ray::new(Vec3::new(-1.0, 0.25, 1e-7), Vec3::new(1.0, 0.0, -1e-7));
    /// assert!(crossing_f64(&grazing, &tri).unwrap().is_ill_conditioned());
    /// let steep = Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z);
    /// assert!(!crossing_f64(&steep, &tri).unwrap().is_ill_conditioned());
    /// ```
    pub fn is_ill_conditioned(&self) -> bool {
        self.bary_bound.is_infinite()
    }

    /// The [`Verdict`] for this crossing.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::reference::{Verdict, crossing_f64}};
    /// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
    /// // t = 2 exactly at tmax: within rounding of the (exclusive) end of the interval.
    /// let c = crossing_f64(&Ray::with_range(Vec3::ZERO, Vec3::Z, 0.0, 2.0), &tri).unwrap();
    /// assert_eq!(c.verdict(), Verdict::KnifeEdge(None));
    /// ```
    pub fn verdict(&self) -> Verdict {
        let hit = self.hit();
        if self.is_ill_conditioned() {
            return Verdict::KnifeEdge(hit);
        }
        let (db, dt) = (self.bary_bound, self.t_bound);
        let margin = self.bary[0].min(self.bary[1]).min(self.bary[2]);
        if margin < -db {
            return Verdict::Miss;
        }
        if margin > db {
            // `hit` is always `Some` here: margin > 0 and t in range.
            if self.t >= self.tmin + dt
                && self.t < self.tmax - dt
                && let Some(h) = hit
            {
                return Verdict::Hit(h);
            }
            if self.t < self.tmin - dt || self.t >= self.tmax + dt {
                return Verdict::Miss;
            }
        }
        Verdict::KnifeEdge(hit)
    }
}

/// The crossing of `ray` with the plane of `tri`, in `f64`, with the `f32` kernels' error bounds.
///
/// `None` where no kernel can hit by policy: an invalid ray, an empty `[tmin, tmax)`, or a
/// degenerate triangle. A ray exactly parallel to the plane gives a NaN crossing and infinite
/// bounds (an `f32` kernel may still find a hit on it, from rounded edges).
///
/// ```
/// use strahl::{Ray, Vec3, intersect::reference::crossing_f64};
/// let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
/// let c = crossing_f64(&Ray::new(Vec3::new(0.25, 0.5, 4.0), Vec3::new(0.0, 0.0, -2.0)), &tri).unwrap();
/// assert_eq!((c.t, c.bary), (2.0, [0.25, 0.25, 0.5]));
/// assert!(crossing_f64(&Ray::new(Vec3::ZERO, Vec3::ZERO), &tri).is_none());
/// assert!(crossing_f64(&Ray::new(Vec3::Z, -Vec3::Z), &[Vec3::ZERO, Vec3::X, Vec3::X]).is_none());
/// ```
pub fn crossing_f64(ray: &Ray, tri: &Triangle) -> Option<Crossing> {
    // The kernels' view of the ray: invalid rays are empty, subnormal components flushed.
    let pre = PreparedRay::new(ray);
    if pre.is_empty() || is_degenerate(tri) {
        return None;
    }
    let w = |v: glam::Vec3| [v.x as f64, v.y as f64, v.z as f64];
    let (o, d) = (w(pre.origin), w(pre.direction));
    let v = [w(tri[0]), w(tri[1]), w(tri[2])];
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let inf_norm = |a: [f64; 3]| a[0].abs().max(a[1].abs()).max(a[2].abs());
    // Differences of two f32s: exact in f64 (see the module docs).
    let rel = [sub(v[0], o), sub(v[1], o), sub(v[2], o)];
    let edge = [sub(v[2], v[1]), sub(v[0], v[2]), sub(v[1], v[0])]; // edge[i] is opposite v_i
    let n = cross(edge[2], sub(v[2], v[0]));
    let det = dot(d, n);
    let t = dot(rel[0], n) / det;
    // b_i = d . ((v_j - o) x (v_k - v_j)) / det for (i, j, k) cyclic; edge[i] = v_k - v_j.
    let bary: [f64; 3] = core::array::from_fn(|i| dot(d, cross(rel[(i + 1) % 3], edge[i])) / det);
    // The bound's magnitudes.
    let m = inf_norm(rel[0]).max(inf_norm(rel[1])).max(inf_norm(rel[2]));
    let l = inf_norm(edge[0]).max(inf_norm(edge[1])).max(inf_norm(edge[2]));
    let dd = inf_norm(d);
    let nn = det.abs();
    let a = (bary[0].abs() + bary[1].abs() + bary[2].abs()).max(1.0);
    let k = dd * (m + a * l) * (a * l + 8.0 * U * m);
    let g = nn - 320.0 * U * k;
    // Range where f32 intermediates neither overflow nor underflow (see the module docs).
    let in_range = U * k >= libm::ldexp(1.0, -90) && k <= libm::ldexp(1.0, 90);
    let (t_bound, bary_bound) = if g > 0.0 && in_range && t.is_finite() {
        (
            U * (600.0 * k * l / (dd * g) + 16.0 * m / dd),
            U * a * (400.0 * k + 8.0 * nn) / g,
        )
    } else {
        (f64::INFINITY, f64::INFINITY)
    };
    Some(Crossing {
        t,
        bary,
        tmin: pre.tmin as f64,
        tmax: pre.tmax as f64,
        t_bound,
        bary_bound,
    })
}

/// `f64` reference ray/triangle test: the exact-to-`f64`-rounding hit of `ray` with `tri`, if any.
///
/// Same policy as the `f32` kernels (invalid ray or degenerate triangle: miss; `tmin <= t < tmax`;
/// both windings; edges and vertices inside).
///
/// ```
/// use strahl::{Ray, Vec3, intersect::reference::intersect_triangle_f64};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// assert!(intersect_triangle_f64(&Ray::new(Vec3::ZERO, -Vec3::Z), &tri).is_none()); // behind
/// let edge = Ray::new(Vec3::new(0.0, -1.0, 0.0), Vec3::Z); // exactly on the edge v0 v1
/// assert_eq!(intersect_triangle_f64(&edge, &tri).unwrap().margin, 0.0);
/// ```
pub fn intersect_triangle_f64(ray: &Ray, tri: &Triangle) -> Option<HitF64> {
    crossing_f64(ray, tri)?.hit()
}

/// The [`Verdict`] for `ray` and `tri`: [`Verdict::Miss`] where [`crossing_f64`] is `None`.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, moller, reference::{Verdict, classify_triangle}}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let ray = Ray::new(Vec3::new(0.1, -0.2, 0.0), Vec3::new(0.01, 0.02, 1.0));
/// let Verdict::Hit(h) = classify_triangle(&ray, &tri) else { panic!() };
/// let t32 = moller::intersect_scalar(&PreparedRay::new(&ray), &tri, 0).unwrap().t;
/// let bound = strahl::intersect::reference::t_error_bound(&ray, &tri);
/// assert!((t32 as f64 - h.t).abs() <= bound);
/// ```
pub fn classify_triangle(ray: &Ray, tri: &Triangle) -> Verdict {
    crossing_f64(ray, tri).map_or(Verdict::Miss, |c| c.verdict())
}

/// `Dt` of the [module docs](self): for a ray that hits `tri` in exact arithmetic, a hit reported
/// by an `f32` kernel has `|t32 - t| <= t_error_bound`. `+inf` where ill-conditioned or where no
/// crossing exists.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::reference::t_error_bound};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let b = t_error_bound(&Ray::new(Vec3::ZERO, Vec3::Z), &tri);
/// assert!(b > 2.0 * f32::EPSILON as f64 && b < 1e-3);
/// ```
pub fn t_error_bound(ray: &Ray, tri: &Triangle) -> f64 {
    crossing_f64(ray, tri).map_or(f64::INFINITY, |c| c.t_bound)
}

/// `Db` of the [module docs](self): bound on the error of the `f32` kernels' barycentrics (and of
/// their inside/outside decisions). `+inf` where ill-conditioned or where no crossing exists.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::reference::bary_error_bound};
/// let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
/// let steep = bary_error_bound(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z), &tri);
/// let grazing = bary_error_bound(&Ray::new(Vec3::new(-1.0, 0.2, 1e-3), Vec3::new(1.0, 0.0, -1e-3)), &tri);
/// assert!(steep < 1e-3 && grazing > 100.0 * steep); // grazing rays are worse conditioned
/// ```
pub fn bary_error_bound(ray: &Ray, tri: &Triangle) -> f64 {
    crossing_f64(ray, tri).map_or(f64::INFINITY, |c| c.bary_bound)
}

/// `f64` slab interval of `ray` and `b`: `(near, far)` with `near = max(entries, tmin)`,
/// `far = min(exits, tmax)`; the box is hit iff `near <= far`. `None` for an invalid ray or an
/// empty `[tmin, tmax)`.
///
/// Same policy as [`intersect_aabb_scalar`](super::intersect_aabb_scalar) (near bound by the sign
/// bit, a `0 * inf` candidate ignored, subnormal direction components flushed), without rounding
/// slack: every candidate `(bound - o) / d` is one `f64` division of an exact difference.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::reference::aabb_interval_f64};
/// let b = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
/// let r = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::new(0.0, -0.0, 2.0));
/// assert_eq!(aabb_interval_f64(&r, &b), Some((2.0, 3.0)));
/// ```
pub fn aabb_interval_f64(ray: &Ray, b: &Aabb) -> Option<(f64, f64)> {
    let pre = PreparedRay::new(ray);
    if pre.is_empty() {
        return None;
    }
    let mut near = pre.tmin as f64;
    let mut far = pre.tmax as f64;
    for a in 0..3 {
        let (lo, hi) = if pre.neg[a] {
            (b.max[a], b.min[a])
        } else {
            (b.min[a], b.max[a])
        };
        let o = pre.origin[a] as f64;
        // 1 / +-0 = +-inf as in the f32 kernels; a NaN candidate (0 * inf) fails `>` / `<`.
        let inv = 1.0 / pre.direction[a] as f64;
        let (n, f) = ((lo as f64 - o) * inv, (hi as f64 - o) * inv);
        if n > near {
            near = n;
        }
        if f < far {
            far = f;
        }
    }
    Some((near, far))
}

/// `f64` reference slab test: the entry distance `max(near, tmin)` if `ray` hits `b`
/// (`near <= far`, no widening), else `None`.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::{PreparedRay, intersect_aabb_scalar, reference::intersect_aabb_f64}};
/// let b = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
/// let r = Ray::new(Vec3::new(0.3, 0.1, -5.0), Vec3::new(0.1, 0.2, 1.0));
/// let exact = intersect_aabb_f64(&r, &b).unwrap();
/// let f32_entry = intersect_aabb_scalar(&PreparedRay::new(&r), &b).unwrap() as f64;
/// assert!((f32_entry - exact).abs() <= strahl::intersect::reference::AABB_ENTRY_REL_BOUND * exact);
/// assert_eq!(intersect_aabb_f64(&r, &Aabb::EMPTY), None);
/// ```
pub fn intersect_aabb_f64(ray: &Ray, b: &Aabb) -> Option<f64> {
    let (near, far) = aabb_interval_f64(ray, b)?;
    (near <= far).then_some(near)
}
