//! Möller-Trumbore ray/triangle test (Möller and Trumbore, "Fast, Minimum Storage Ray/Triangle
//! Intersection", JGT 1997): scalar reference, one ray against 4 or 8 triangles, and 4 or 8 rays
//! against one triangle.
//!
//! Fast, but not watertight: a ray through a shared edge or vertex can slip between the
//! triangles, because each triangle's barycentric test rounds differently. `tests/watertight.rs`
//! measures how often; use [`watertight`](super::watertight) where that matters.
//!
//! Operation order (every width performs exactly these IEEE operations, no FMA):
//! ```text
//! e1 = v1 - v0;  e2 = v2 - v0;  p = d x e2;  det = e1 . p;  inv = 1 / det
//! s = o - v0;    u = (s . p) inv;  q = s x e1;  v = (d . q) inv;  t = (e2 . q) inv
//! hit: det != 0, u >= 0, v >= 0, u + v <= 1, tmin <= t < tmax
//! ```
//! with `a . b = (ax bx + ay by) + az bz` and `(a x b).x = ay bz - az by` (and cyclic).

use super::soa::closest_lane;
use super::{HitLanes, PreparedPacket, PreparedRay, TriangleLanes, TriangleX4, TriangleX8};
use crate::geometry::{Hit, Triangle, is_degenerate};
use crate::math::Lane;

/// Scalar reference: the hit of `ray` with `tri` (reported with `prim`), if any.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, moller}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// let hit = moller::intersect_scalar(&ray, &tri, 7).unwrap();
/// assert_eq!((hit.t, hit.prim), (2.0, 7));
/// assert_eq!((hit.u, hit.v), (0.25, 0.5));
/// ```
#[inline]
pub fn intersect_scalar(ray: &PreparedRay, tri: &Triangle, prim: u32) -> Option<Hit> {
    if is_degenerate(tri) {
        return None;
    }
    let [v0, v1, v2] = *tri;
    let (o, d) = (ray.origin, ray.direction);
    let (e1x, e1y, e1z) = (v1.x - v0.x, v1.y - v0.y, v1.z - v0.z);
    let (e2x, e2y, e2z) = (v2.x - v0.x, v2.y - v0.y, v2.z - v0.z);
    let px = d.y * e2z - d.z * e2y;
    let py = d.z * e2x - d.x * e2z;
    let pz = d.x * e2y - d.y * e2x;
    let det = (e1x * px + e1y * py) + e1z * pz;
    let inv = 1.0 / det;
    let (sx, sy, sz) = (o.x - v0.x, o.y - v0.y, o.z - v0.z);
    let u = ((sx * px + sy * py) + sz * pz) * inv;
    let qx = sy * e1z - sz * e1y;
    let qy = sz * e1x - sx * e1z;
    let qz = sx * e1y - sy * e1x;
    let v = ((d.x * qx + d.y * qy) + d.z * qz) * inv;
    let t = ((e2x * qx + e2y * qy) + e2z * qz) * inv;
    // Written so that any NaN fails a comparison and misses.
    let hit = det != 0.0 && u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t >= ray.tmin && t < ray.tmax;
    hit.then_some(Hit { t, u, v, prim })
}

/// The test on lanes: ray components `o`, `d` and triangle vertices `v` (either side may be
/// splatted). Returns the hit mask (lanes not yet restricted to valid triangles), `t`, `u`, `v`.
#[inline(always)]
fn core<L: Lane>(o: [L; 3], d: [L; 3], v: &[[L; 3]; 3], tmin: L, tmax: L) -> (L, L, L, L) {
    let [dx, dy, dz] = d;
    let [v0, v1, v2] = v;
    let (e1x, e1y, e1z) = (v1[0] - v0[0], v1[1] - v0[1], v1[2] - v0[2]);
    let (e2x, e2y, e2z) = (v2[0] - v0[0], v2[1] - v0[1], v2[2] - v0[2]);
    let px = dy * e2z - dz * e2y;
    let py = dz * e2x - dx * e2z;
    let pz = dx * e2y - dy * e2x;
    let det = (e1x * px + e1y * py) + e1z * pz;
    let inv = L::splat(1.0) / det;
    let (sx, sy, sz) = (o[0] - v0[0], o[1] - v0[1], o[2] - v0[2]);
    let u = ((sx * px + sy * py) + sz * pz) * inv;
    let qx = sy * e1z - sz * e1y;
    let qy = sz * e1x - sx * e1z;
    let qz = sx * e1y - sy * e1x;
    let vv = ((dx * qx + dy * qy) + dz * qz) * inv;
    let t = ((e2x * qx + e2y * qy) + e2z * qz) * inv;
    let zero = L::splat(0.0);
    let hit = det.ne(zero) & u.ge(zero) & vv.ge(zero) & (u + vv).le(L::splat(1.0)) & t.ge(tmin) & t.lt(tmax);
    (hit, t, u, vv)
}

/// One ray against `N` triangles: `(mask, t, u, v)`.
#[inline(always)]
fn lanes_one_ray<L: Lane>(ray: &PreparedRay, v: &[[L; 3]; 3]) -> (u32, L, L, L) {
    let o = ray.origin.to_array().map(L::splat);
    let d = ray.direction.to_array().map(L::splat);
    let (hit, t, u, vv) = core(o, d, v, L::splat(ray.tmin), L::splat(ray.tmax));
    (hit.bitmask(), t, u, vv)
}

/// Mask of the lanes of `tris` hit by `ray` within `[tmin, tmax)`.
#[inline(always)]
pub fn hit_mask<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> u32 {
    lanes_one_ray(ray, &tris.v).0 & tris.valid
}

/// Closest hit of one ray among `N` SoA triangles (ties: lowest lane).
#[inline(always)]
pub fn intersect_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> Option<Hit> {
    let (m, t, u, v) = lanes_one_ray(ray, &tris.v);
    closest_lane(m & tris.valid, t, u, v, &tris.prim)
}

/// Closest hit of one ray among 4 triangles; equals the best [`intersect_scalar`] over the lanes.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX4, moller}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let soa = TriangleX4::pack(&[tri(5.0), tri(3.0), tri(4.0)], &[0, 1, 2]);
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// assert_eq!(moller::intersect_x4(&ray, &soa).unwrap().prim, 1);
/// ```
#[inline]
pub fn intersect_x4(ray: &PreparedRay, tris: &TriangleX4) -> Option<Hit> {
    intersect_lanes(ray, tris)
}

/// Closest hit of one ray among 8 triangles; see [`intersect_x4`].
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8, moller}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let soa = TriangleX8::pack(&[tri(5.0), tri(3.0)], &[40, 41]);
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// assert_eq!(moller::intersect_x8(&ray, &soa).unwrap().t, 3.0);
/// assert!(moller::occluded_x8(&ray, &soa));
/// ```
#[inline]
pub fn intersect_x8(ray: &PreparedRay, tris: &TriangleX8) -> Option<Hit> {
    intersect_lanes(ray, tris)
}

/// `true` if `ray` hits any of the 4 triangles within `[tmin, tmax)`.
#[inline]
pub fn occluded_x4(ray: &PreparedRay, tris: &TriangleX4) -> bool {
    hit_mask(ray, tris) != 0
}

/// `true` if `ray` hits any of the 8 triangles within `[tmin, tmax)`.
#[inline]
pub fn occluded_x8(ray: &PreparedRay, tris: &TriangleX8) -> bool {
    hit_mask(ray, tris) != 0
}

/// Packet form: `N` rays (4 or 8) against one triangle. Lanes that hit closer than their current
/// `tmax` get their hit written to `hits` and their `tmax` shrunk to it; returns the mask of lanes
/// hit. Per lane this equals [`intersect_scalar`] on that lane's ray.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{HitLanes, PreparedPacket8, moller}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.2, 0.0, 0.0), Vec3::Z)).collect();
/// let mut packet = PreparedPacket8::new(&rays);
/// let mut hits = HitLanes::default();
/// let mask = moller::intersect_packet(&mut packet, &tri, 3, &mut hits);
/// assert_eq!(mask, 0b0000_0111); // x = 0.0, 0.2, 0.4 hit; 0.6 .. 1.4 pass beside the triangle
/// assert_eq!(hits.get(0).prim, 3);
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
    let v = tri.map(|p| p.to_array().map(L::splat));
    let (hit, t, u, v) = core(rays.origin, rays.direction, &v, rays.tmin, rays.tmax);
    super::packet::commit(rays, hits, hit, t, u, v, prim)
}
