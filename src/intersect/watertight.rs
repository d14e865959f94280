//! Watertight ray/triangle test of Woop, Benthin and Wald, "Watertight Ray/Triangle Intersection"
//! (JCGT 2013): scalar reference, one ray against 4 or 8 triangles, and 4 or 8 rays against one
//! triangle.
//!
//! The triangle is translated to the ray origin, permuted so that the ray's dominant axis `kz` is
//! last, and sheared so that the ray becomes the `+z` axis. The 2D edge functions `U`, `V`, `W` of
//! the sheared vertices then decide the hit. Shared edges are evaluated from the same operands in
//! every triangle, so a ray through an edge or vertex of a closed mesh never slips through. When an
//! edge function evaluates to exactly zero in `f32`, all three are recomputed in `f64`, where the
//! products of two `f32`s are exact and the sign is therefore exact.
//!
//! Operation order (the same in every width, no FMA):
//! ```text
//! A = v0 - o, B = v1 - o, C = v2 - o            (per axis)
//! Ax = A[kx] - Sx A[kz],  Ay = A[ky] - Sy A[kz]  (and B, C)
//! U = Cx By - Cy Bx,  V = Ax Cy - Ay Cx,  W = Bx Ay - By Ax   (f64 if any is 0)
//! miss if signs are mixed; det = (U + V) + W; miss if det == 0
//! T = (U Sz A[kz] + V Sz B[kz]) + W Sz C[kz];  rcp = 1 / det
//! t = T rcp,  u = V rcp,  v = W rcp;  hit if tmin <= t < tmax
//! ```
//! Both windings are hit (no back-face culling).

use super::soa::closest_lane;
use super::{HitLanes, PreparedPacket, PreparedRay, TriangleLanes, TriangleX4, TriangleX8};
use crate::geometry::{Hit, Triangle, is_degenerate};
use crate::math::Lane;
use glam::Vec3;

/// The three edge functions recomputed in `f64` (exact products, one rounding each).
#[inline(never)]
#[cold]
fn edges_f64(ax: f32, ay: f32, bx: f32, by: f32, cx: f32, cy: f32) -> (f32, f32, f32) {
    let (ax, ay, bx, by, cx, cy) = (ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64);
    (
        (cx * by - cy * bx) as f32,
        (ax * cy - ay * cx) as f32,
        (bx * ay - by * ax) as f32,
    )
}

/// Scalar reference: the hit of `ray` with `tri` (reported with `prim`), if any.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, watertight}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// // A ray exactly through the vertex v2 is hit:
/// let ray = PreparedRay::new(&Ray::new(Vec3::new(0.0, 1.0, 0.0), Vec3::Z));
/// let hit = watertight::intersect_scalar(&ray, &tri, 0).unwrap();
/// assert_eq!((hit.t, hit.u, hit.v), (2.0, 0.0, 1.0));
/// ```
#[inline]
pub fn intersect_scalar(ray: &PreparedRay, tri: &Triangle, prim: u32) -> Option<Hit> {
    if is_degenerate(tri) {
        return None;
    }
    let [kx, ky, kz] = ray.k.map(|k| k.min(2)); // in bounds: no index checks
    let s = ray.shear;
    let o = ray.origin;
    let a = (tri[0] - o).to_array();
    let b = (tri[1] - o).to_array();
    let c = (tri[2] - o).to_array();
    let (ax, ay) = (a[kx] - s.x * a[kz], a[ky] - s.y * a[kz]);
    let (bx, by) = (b[kx] - s.x * b[kz], b[ky] - s.y * b[kz]);
    let (cx, cy) = (c[kx] - s.x * c[kz], c[ky] - s.y * c[kz]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        (u, v, w) = edges_f64(ax, ay, bx, by, cx, cy);
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = (u + v) + w;
    if det == 0.0 {
        return None;
    }
    let big_t = (u * (s.z * a[kz]) + v * (s.z * b[kz])) + w * (s.z * c[kz]);
    let rcp = 1.0 / det;
    let t = big_t * rcp;
    // NaN fails both comparisons.
    (t >= ray.tmin && t < ray.tmax).then_some(Hit {
        t,
        u: v * rcp,
        v: w * rcp,
        prim,
    })
}

/// The test on lanes, from permuted origin-relative vertices `[A, B, C][kx, ky, kz]`. `relevant`
/// restricts the rare `f64` fallback to lanes whose answer matters. Returns `(hit, t, u, v)` with
/// `hit` a lane mask.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn core<L: Lane>(p: [[L; 3]; 3], s: [L; 3], tmin: L, tmax: L, relevant: u32) -> (L, L, L, L) {
    let [a, b, c] = p;
    let (ax, ay) = (a[0] - s[0] * a[2], a[1] - s[1] * a[2]);
    let (bx, by) = (b[0] - s[0] * b[2], b[1] - s[1] * b[2]);
    let (cx, cy) = (c[0] - s[0] * c[2], c[1] - s[1] * c[2]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    let zero = L::splat(0.0);
    let on_edge = (u.eq(zero) | v.eq(zero) | w.eq(zero)).bitmask() & relevant;
    if on_edge != 0 {
        // PERF: rare (rays through edges and vertices); done lane by lane like the scalar path.
        let mut l = [[0.0f32; 8]; 9];
        for (slot, x) in l.iter_mut().zip([ax, ay, bx, by, cx, cy, u, v, w]) {
            x.store(slot);
        }
        let mut m = on_edge;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            (l[6][i], l[7][i], l[8][i]) = edges_f64(l[0][i], l[1][i], l[2][i], l[3][i], l[4][i], l[5][i]);
        }
        (u, v, w) = (L::load(&l[6]), L::load(&l[7]), L::load(&l[8]));
    }
    let neg = u.lt(zero) | v.lt(zero) | w.lt(zero);
    let pos = u.gt(zero) | v.gt(zero) | w.gt(zero);
    let det = (u + v) + w;
    let big_t = (u * (s[2] * a[2]) + v * (s[2] * b[2])) + w * (s[2] * c[2]);
    let rcp = L::splat(1.0) / det;
    let t = big_t * rcp;
    let ok = det.ne(zero) & t.ge(tmin) & t.lt(tmax);
    // Mixed signs: outside. `select` keeps the result a lane mask for the packet kernels.
    let hit = (neg & pos).select(zero, ok);
    (hit, t, v * rcp, w * rcp)
}

/// One ray against `N` SoA triangles: `(mask of valid lanes hit, t, u, v)`.
#[inline(always)]
fn lanes_one_ray<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> (u32, L, L, L) {
    // The permutation indexes the triangle data in memory by the ray's axes; `min(2)` (a cmov)
    // proves the indices in bounds, so the loads are plain indexed loads with no branches.
    // (`array::map` or a `match` per pick cost about half the speed of the x8 kernel.)
    let [kx, ky, kz] = ray.k.map(|k| k.min(2));
    let o = [ray.origin[kx], ray.origin[ky], ray.origin[kz]].map(L::splat);
    let rel = |v: &[L; 3]| [v[kx] - o[0], v[ky] - o[1], v[kz] - o[2]];
    let p = [rel(&tris.v[0]), rel(&tris.v[1]), rel(&tris.v[2])];
    let s = ray.shear.to_array().map(L::splat);
    let (hit, t, u, v) = core(p, s, L::splat(ray.tmin), L::splat(ray.tmax), tris.valid);
    (hit.bitmask() & tris.valid, t, u, v)
}

/// Mask of the lanes of `tris` hit by `ray` within `[tmin, tmax)`.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8, watertight}};
/// // Four triangles around the vertex (0, 0, 2), one per quadrant; a ray exactly through it.
/// let quad = |sx: f32, sy: f32| [Vec3::new(0.0, 0.0, 2.0), Vec3::new(sx, 0.0, 2.0), Vec3::new(0.0, sy, 2.0)];
/// let soa = TriangleX8::pack(&[quad(1.0, 1.0), quad(-1.0, 1.0), quad(-1.0, -1.0), quad(1.0, -1.0)], &[]);
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// assert_ne!(watertight::hit_mask(&ray, &soa), 0); // no crack at the shared vertex
/// ```
#[inline(always)]
pub fn hit_mask<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> u32 {
    lanes_one_ray(ray, tris).0
}

/// [`intersect_lanes`] counting only the hits `accept` takes: the closest accepted hit, the lanes
/// computed once (the hit filters' leaf test).
#[inline(always)]
pub(crate) fn closest_accepted<L: Lane, const N: usize>(
    ray: &PreparedRay,
    tris: &TriangleLanes<L, N>,
    accept: impl FnMut(&Hit) -> bool,
) -> Option<Hit> {
    let (m, t, u, v) = lanes_one_ray(ray, tris);
    super::soa::closest_accepted(m, t, u, v, &tris.prim, accept)
}

/// Closest hit of one ray among `N` SoA triangles (ties: lowest lane).
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX4, watertight}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris = [tri(3.0), tri(2.0), tri(2.0)];
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// let hit = watertight::intersect_lanes(&ray, &TriangleX4::pack(&tris, &[5, 6, 7])).unwrap();
/// assert_eq!((hit.t, hit.prim), (2.0, 6)); // a tie at t = 2: the lower lane
/// assert_eq!(Some(hit), watertight::intersect_scalar(&ray, &tris[1], 6));
/// ```
#[inline(always)]
pub fn intersect_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> Option<Hit> {
    let (m, t, u, v) = lanes_one_ray(ray, tris);
    closest_lane(m, t, u, v, &tris.prim)
}

/// Closest hit of one ray among 4 triangles; equals the best [`intersect_scalar`] over the lanes.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX4, watertight}};
/// // Two triangles sharing the edge x = 0; a ray exactly through the edge hits one of them.
/// let l = [Vec3::new(-1.0, -1.0, 1.0), Vec3::new(0.0, -1.0, 1.0), Vec3::new(0.0, 1.0, 1.0)];
/// let r = [Vec3::new(0.0, -1.0, 1.0), Vec3::new(1.0, -1.0, 1.0), Vec3::new(0.0, 1.0, 1.0)];
/// let soa = TriangleX4::pack(&[l, r], &[0, 1]);
/// let ray = PreparedRay::new(&Ray::new(Vec3::new(0.0, 0.3, 0.0), Vec3::Z));
/// assert!(watertight::intersect_x4(&ray, &soa).is_some());
/// ```
#[inline]
pub fn intersect_x4(ray: &PreparedRay, tris: &TriangleX4) -> Option<Hit> {
    intersect_lanes(ray, tris)
}

/// Closest hit of one ray among 8 triangles; see [`intersect_x4`].
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8, watertight}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let soa = TriangleX8::pack(&[tri; 8], &[0, 1, 2, 3, 4, 5, 6, 7]);
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// assert_eq!(watertight::intersect_x8(&ray, &soa).unwrap().prim, 0); // ties: lowest lane
/// assert!(watertight::occluded_x8(&ray, &soa));
/// ```
#[inline]
pub fn intersect_x8(ray: &PreparedRay, tris: &TriangleX8) -> Option<Hit> {
    intersect_lanes(ray, tris)
}

/// `true` if `ray` hits any of the 4 triangles within `[tmin, tmax)`.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX4, watertight}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let soa = TriangleX4::pack(&[tri], &[0]);
/// assert!(watertight::occluded_x4(&PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z)), &soa));
/// // Both windings are hit; a ray pointing away is not.
/// assert!(watertight::occluded_x4(&PreparedRay::new(&Ray::new(Vec3::new(0.0, 0.0, 4.0), -Vec3::Z)), &soa));
/// assert!(!watertight::occluded_x4(&PreparedRay::new(&Ray::new(Vec3::ZERO, -Vec3::Z)), &soa));
/// ```
#[inline]
pub fn occluded_x4(ray: &PreparedRay, tris: &TriangleX4) -> bool {
    hit_mask(ray, tris) != 0
}

/// `true` if `ray` hits any of the 8 triangles within `[tmin, tmax)`.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8, watertight}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let soa = TriangleX8::pack(&[tri, [Vec3::NAN; 3]], &[0, 1]); // lane 1 is degenerate: never hit
/// let from = |x: f32| PreparedRay::new(&Ray::new(Vec3::new(x, 0.0, 0.0), Vec3::Z));
/// assert!(watertight::occluded_x8(&from(0.0), &soa));
/// assert!(!watertight::occluded_x8(&from(2.0), &soa));
/// ```
#[inline]
pub fn occluded_x8(ray: &PreparedRay, tris: &TriangleX8) -> bool {
    hit_mask(ray, tris) != 0
}

/// Packet form: `N` rays (4 or 8) against one triangle. Lanes that hit closer than their current
/// `tmax` get their hit written to `hits` and their `tmax` shrunk to it; returns the mask of lanes
/// hit. Per lane this equals [`intersect_scalar`] on that lane's ray.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{HitLanes, PreparedPacket8, watertight}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.2, 0.0, 0.0), Vec3::Z)).collect();
/// let mut packet = PreparedPacket8::new(&rays);
/// let mut hits = HitLanes::default();
/// assert_eq!(watertight::intersect_packet(&mut packet, &tri, 3, &mut hits), 0b0000_0111); // x = 0.0, 0.2, 0.4 hit
/// ```
#[inline]
pub fn intersect_packet<L: Lane, const N: usize>(
    rays: &mut PreparedPacket<L, N>,
    tri: &Triangle,
    prim: u32,
    hits: &mut HitLanes<L, N>,
) -> u32 {
    if is_degenerate(tri) {
        return 0;
    }
    // Written out rather than with `array::map`, which did not inline here (measured: 3.6x slower).
    let o = rays.origin;
    let p = match rays.k_uniform {
        // Coherent packets: permute the scalar vertices once (same values as the per-lane blend).
        Some(k) => {
            let [kx, ky, kz] = k.map(|k| k.min(2));
            let rel = |v: Vec3| {
                [
                    L::splat(v[kx]) - o[kx],
                    L::splat(v[ky]) - o[ky],
                    L::splat(v[kz]) - o[kz],
                ]
            };
            [rel(tri[0]), rel(tri[1]), rel(tri[2])]
        }
        None => {
            let rel = |v: Vec3| {
                let r = [L::splat(v.x) - o[0], L::splat(v.y) - o[1], L::splat(v.z) - o[2]];
                [rays.pick(0, &r), rays.pick(1, &r), rays.pick(2, &r)]
            };
            [rel(tri[0]), rel(tri[1]), rel(tri[2])]
        }
    };
    let (hit, t, u, v) = core(p, rays.shear, rays.tmin, rays.tmax, rays.active());
    super::packet::commit(rays, hits, hit, t, u, v, prim)
}
