//! Exact references for grid inputs: integer arithmetic for triangles, exact rational comparisons
//! for boxes, with the error bounds that say where an `f32` kernel may legitimately differ.
//!
//! They apply to rays and primitives whose coordinates are integers (origins and vertices within
//! [`COORD_LIMIT`], directions within [`DIR_LIMIT`]) and whose `tmin`, `tmax` are not NaN; then
//! every intermediate value of Möller-Trumbore stays below `2^24` and is exact in `f32`, and the
//! only roundings are the reciprocal of the determinant and the products with it.

use strahl::geometry::Triangle;
use strahl::{Aabb, Ray, Vec3};

/// Largest `|coordinate|` of an origin or vertex the exact references accept.
pub const COORD_LIMIT: f32 = 8.0;
/// Largest `|component|` of a direction the exact references accept: aimed grid rays reach
/// `12 * 16 = 192`, and Möller-Trumbore's determinant then stays below `3 * 16 * 2 * 192 * 16`,
/// far under `2^24`.
pub const DIR_LIMIT: f32 = 192.0;

/// Unit roundoff of `f32`, `2^-24`.
const EPS: f64 = 1.0 / 16_777_216.0;

/// The components of `v` as integers, if all are integers within `limit`.
pub fn int3(v: Vec3, limit: f32) -> Option<[i64; 3]> {
    let ok = |x: f32| x.is_finite() && x.fract() == 0.0 && x.abs() <= limit;
    (ok(v.x) && ok(v.y) && ok(v.z)).then_some([v.x as i64, v.y as i64, v.z as i64])
}

fn sub(a: [i64; 3], b: [i64; 3]) -> [i64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [i64; 3], b: [i64; 3]) -> i64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [i64; 3], b: [i64; 3]) -> [i64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// What exact arithmetic says a kernel must answer for one ray and one triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Expect {
    /// The kernel must miss.
    Miss,
    /// The kernel must hit, with `t`, `u`, `v` within `tol` (absolute) of these exact values.
    Hit {
        /// Exact distance (rounded to `f64`).
        t: f64,
        /// Exact barycentric `u`.
        u: f64,
        /// Exact barycentric `v`.
        v: f64,
        /// Allowed absolute error of the kernel's `t`.
        t_tol: f64,
        /// Allowed absolute error of the kernel's `u` and `v` (`INFINITY`: not checked).
        uv_tol: f64,
    },
    /// On a knife edge for this kernel (the hit point on an edge or vertex, `t` at a bound, the ray
    /// in the triangle's plane): either answer is right.
    Either,
}

/// The exact expectations for Möller-Trumbore and watertight, or `None` if the inputs are not
/// grid inputs (see the module docs) or the ray is invalid (its policy is checked elsewhere).
///
/// Error bounds (`e = 2^-24`, each with a safety factor of 4):
/// - Möller-Trumbore: all dot and cross products are exact, so the signs of `u`, `v`, `t - tmin`
///   are exact; `u + v <= 1` and `t`, `u`, `v` carry two roundings each (`|err| <= 2.1 e |x|`).
/// - Watertight: with `M` the largest L1 norm of an origin-relative vertex, each sheared coordinate
///   is off by at most `3 e M`, each edge function by `16 e M^2`, the determinant by `50 e M^2`
///   and `T` by `80 e M^3`, so `|t err| <= e (80 M^3 + 50 M^2 |t|) / |det| + 4 e |t|`, where
///   `|det| = |det_mt| / |d[kz]|`. A nonzero edge function on the grid is a multiple of
///   `1 / |d[kz]| >= 1/192`, larger than its error (`M <= 48`), so in effect only an exactly-zero
///   edge function (a hit on an edge or vertex) is ambiguous.
pub fn expect_triangle(ray: &Ray, tri: &Triangle) -> Option<[Expect; 2]> {
    if ray.tmin.is_nan() || ray.tmax.is_nan() {
        return None;
    }
    let o = int3(ray.origin, COORD_LIMIT)?;
    let d = int3(ray.direction, DIR_LIMIT)?;
    if d == [0; 3] {
        return None;
    }
    let v0 = int3(tri[0], COORD_LIMIT)?;
    let v1 = int3(tri[1], COORD_LIMIT)?;
    let v2 = int3(tri[2], COORD_LIMIT)?;
    let (e1, e2) = (sub(v1, v0), sub(v2, v0));
    let n = cross(e1, e2);
    if n == [0; 3] {
        // Degenerate: never hit (the kernels' policy).
        return Some([Expect::Miss; 2]);
    }
    let p = cross(d, e2);
    let mut det = dot(e1, p);
    let s = sub(o, v0);
    if det == 0 {
        // Parallel to the plane: a miss unless the ray lies in it (then it grazes: either).
        let e = if dot(s, n) == 0 { Expect::Either } else { Expect::Miss };
        return Some([e; 2]);
    }
    let q = cross(s, e1);
    let (mut un, mut vn, mut tn) = (dot(s, p), dot(d, q), dot(e2, q));
    if det < 0 {
        (det, un, vn, tn) = (-det, -un, -vn, -tn);
    }
    let wn = det - un - vn;
    debug_assert!(
        [det, un, vn, tn].iter().all(|x| x.abs() < 1 << 24),
        "grid bounds keep f32 exact"
    );
    let detf = det as f64;
    let (t, u, v) = (tn as f64 / detf, un as f64 / detf, vn as f64 / detf);
    // Signed distances of t from the bounds, exact: tmin * det is exact in f64.
    let (tn, tmin, tmax) = (tn as f64, f64::from(ray.tmin), f64::from(ray.tmax));
    let above_min = tn - tmin * detf; // >= 0: t >= tmin
    let below_max = tmax * detf - tn; // > 0: t < tmax
    let in_range = above_min >= 0.0 && below_max > 0.0;
    let inside = un >= 0 && vn >= 0 && wn >= 0;
    // |t - bound| <= tol: either.
    let near_bound = |tol: f64| above_min.abs() <= tol * detf || below_max.abs() <= tol * detf;
    let decide = |either: bool, t_tol: f64, uv_tol: f64| {
        if either {
            Expect::Either
        } else if inside && in_range {
            Expect::Hit { t, u, v, t_tol, uv_tol }
        } else {
            Expect::Miss
        }
    };

    // Möller-Trumbore: only u + v <= 1 (w near 0) and t near a bound are rounded decisions.
    let mt_tol = 4.0 * 2.1 * EPS;
    let mt_either = (wn as f64).abs() <= 4.0 * 3.0 * EPS * detf || near_bound(mt_tol * t.abs());
    let moller = decide(mt_either, mt_tol * t.abs(), mt_tol * u.abs().max(v.abs()));

    // Watertight.
    let m = [v0, v1, v2]
        .iter()
        .map(|vtx| sub(*vtx, o).iter().map(|c| c.unsigned_abs()).sum::<u64>())
        .max()
        .unwrap_or(0) as f64;
    let dz = d.iter().map(|c| c.unsigned_abs()).max().unwrap_or(1) as f64;
    let det_ww = detf / dz;
    let wt_tol = 4.0 * EPS * ((80.0 * m * m * m + 50.0 * m * m * t.abs()) / det_ww + 4.0 * t.abs());
    let edge_err = 4.0 * 16.0 * EPS * m * m;
    let on_edge = [un, vn, wn]
        .iter()
        .any(|&x| (x as f64 / detf * det_ww).abs() <= edge_err);
    let watertight = decide(on_edge || near_bound(wt_tol), wt_tol, f64::INFINITY);
    Some([moller, watertight])
}

/// An exact rational `num / den`, `den > 0`; `num` may be an infinite `tmin` / `tmax`.
#[derive(Clone, Copy, Debug)]
struct Frac {
    num: f64,
    den: f64,
}

impl Frac {
    /// `self <= other`, exact while the products stay within 53 bits (they do on the grid).
    fn le(self, other: Frac) -> bool {
        self.num * other.den <= other.num * self.den
    }
    fn value(self) -> f64 {
        self.num / self.den
    }
}

/// The exact slab test: does the ray meet the closed box for some `t` in the **closed** range
/// `[tmin, tmax]`? Returns `(hit, near_far)`, where `near_far` holds the exact entry and exit
/// distances (rounded to `f64`) when both are finite, for judging how close a miss is. `None` if
/// not a grid input (including boxes whose bounds are not integers within [`COORD_LIMIT`]) or the
/// ray is invalid.
///
/// The kernel is conservative (its far distance is scaled up by `1 + 2 gamma(3)`), so it must hit
/// whenever this hits, and may hit a miss only when `gap` is within rounding of zero.
pub fn expect_box(ray: &Ray, b: &Aabb) -> Option<(bool, Option<(f64, f64)>)> {
    if ray.tmin.is_nan() || ray.tmax.is_nan() {
        return None;
    }
    let o = int3(ray.origin, COORD_LIMIT)?;
    let d = int3(ray.direction, DIR_LIMIT)?;
    let lo = int3(b.min, COORD_LIMIT)?;
    let hi = int3(b.max, COORD_LIMIT)?;
    if d == [0; 3] {
        return None;
    }
    let mut near = Frac {
        num: f64::from(ray.tmin),
        den: 1.0,
    };
    let mut far = Frac {
        num: f64::from(ray.tmax),
        den: 1.0,
    };
    let mut empty = false;
    for a in 0..3 {
        let (o, d, lo, hi) = (o[a], d[a], lo[a], hi[a]);
        if d == 0 {
            empty |= o < lo || o > hi;
            continue;
        }
        let (n, f) = if d > 0 {
            (
                Frac {
                    num: (lo - o) as f64,
                    den: d as f64,
                },
                Frac {
                    num: (hi - o) as f64,
                    den: d as f64,
                },
            )
        } else {
            (
                Frac {
                    num: (o - hi) as f64,
                    den: -d as f64,
                },
                Frac {
                    num: (o - lo) as f64,
                    den: -d as f64,
                },
            )
        };
        if !n.le(near) {
            near = n;
        }
        if !far.le(f) {
            far = f;
        }
    }
    if empty {
        return Some((false, None));
    }
    let (n, f) = (near.value(), far.value());
    Some((near.le(far), (n.is_finite() && f.is_finite()).then_some((n, f))))
}
