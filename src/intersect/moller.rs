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

/// The closest hits of `K` rays (SoA lanes; a lane whose `tmax` is `-inf` takes no part) among
/// the valid triangles of `packs`, each triangle against all rays at once, in pack and lane order
/// with a strict `<` (so, per ray, the same hit as [`intersect_lanes`] pack by pack: the least
/// `t`, ties to the first triangle). Returns the rays hit, and `t`, `u`, `v` and the primitive
/// index (as bits) per lane, valid in the lanes hit.
#[inline(always)]
pub(crate) fn closest_packet_leaf<R: Lane, L: Lane, const N: usize>(
    origin: [R; 3],
    direction: [R; 3],
    tmin: R,
    mut tmax: R,
    packs: &[TriangleLanes<L, N>],
) -> (u32, R, R, R, R) {
    let (mut bu, mut bv, mut bp) = (R::splat(0.0), R::splat(0.0), R::splat(0.0));
    let mut hits = 0u32;
    for pack in packs {
        let mut valid = pack.valid;
        while valid != 0 {
            let i = valid.trailing_zeros() as usize;
            valid &= valid - 1;
            let v: [[R; 3]; 3] = core::array::from_fn(|j| core::array::from_fn(|a| R::splat(pack.v[j][a].at(i))));
            let (hit, t, u, vv) = core(origin, direction, &v, tmin, tmax);
            // PERF: no branch on the hit mask (which of a leaf's triangles a packet hits is
            // unpredictable): bunny 1024 x 1024, packets that reach a triangle 13.1 -> 12.8 ms.
            tmax = hit.select(t, tmax);
            bu = hit.select(u, bu);
            bv = hit.select(vv, bv);
            // The primitive index rides in the lanes as float bits: `select` is a bitwise
            // blend on every target (no float operation touches it).
            bp = hit.select(R::splat(f32::from_bits(pack.prim[i % N])), bp);
            hits |= hit.bitmask();
        }
    }
    (hits, tmax, bu, bv, bp)
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
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX4, moller}};
/// let tri = |x: f32| [Vec3::new(x - 1.0, -1.0, 2.0), Vec3::new(x + 1.0, -1.0, 2.0), Vec3::new(x, 1.0, 2.0)];
/// let soa = TriangleX4::pack(&[tri(0.0), tri(5.0), tri(0.0)], &[0, 1, 2]);
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// assert_eq!(moller::hit_mask(&ray, &soa), 0b101); // lane 1 lies beside the ray
/// let short = PreparedRay::new(&Ray::with_range(Vec3::ZERO, Vec3::Z, 0.0, 2.0));
/// assert_eq!(moller::hit_mask(&short, &soa), 0); // `tmax` is exclusive
/// ```
#[inline(always)]
pub fn hit_mask<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> u32 {
    lanes_one_ray(ray, &tris.v).0 & tris.valid
}

/// [`intersect_lanes`] counting only the hits `accept` takes: the closest accepted hit, the lanes
/// computed once (the hit filters' leaf test).
#[inline(always)]
pub(crate) fn closest_accepted<L: Lane, const N: usize>(
    ray: &PreparedRay,
    tris: &TriangleLanes<L, N>,
    accept: impl FnMut(&Hit) -> bool,
) -> Option<Hit> {
    let (m, t, u, v) = lanes_one_ray(ray, &tris.v);
    super::soa::closest_accepted(m & tris.valid, t, u, v, &tris.prim, accept)
}

/// Closest hit of one ray among `N` SoA triangles (ties: lowest lane).
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8, moller}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris = [tri(4.0), tri(-1.0), tri(2.5), tri(3.0)];
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// let hit = moller::intersect_lanes(&ray, &TriangleX8::pack(&tris, &[10, 11, 12, 13])).unwrap();
/// assert_eq!((hit.t, hit.prim), (2.5, 12)); // the triangle behind the origin does not count
/// assert_eq!(Some(hit), moller::intersect_scalar(&ray, &tris[2], 12));
/// ```
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
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX4, moller}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let soa = TriangleX4::pack(&[tri], &[0]);
/// assert!(moller::occluded_x4(&PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z)), &soa));
/// // A shadow ray that ends before the triangle is not blocked.
/// assert!(!moller::occluded_x4(&PreparedRay::new(&Ray::with_range(Vec3::ZERO, Vec3::Z, 0.0, 1.5)), &soa));
/// ```
#[inline]
pub fn occluded_x4(ray: &PreparedRay, tris: &TriangleX4) -> bool {
    hit_mask(ray, tris) != 0
}

/// `true` if `ray` hits any of the 8 triangles within `[tmin, tmax)`.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8, moller}};
/// let tri = |x: f32| [Vec3::new(x - 1.0, -1.0, 2.0), Vec3::new(x + 1.0, -1.0, 2.0), Vec3::new(x, 1.0, 2.0)];
/// let soa = TriangleX8::pack(&[tri(-3.0), tri(3.0)], &[0, 1]);
/// assert!(!moller::occluded_x8(&PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z)), &soa)); // between the two
/// assert!(moller::occluded_x8(&PreparedRay::new(&Ray::new(Vec3::new(3.0, 0.0, 0.0), Vec3::Z)), &soa));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ray;
    use crate::math::{f32x4, f32x8, f32x16};
    use crate::scene::Rng;
    use glam::Vec3;

    /// `closest_packet_leaf` (each triangle against all rays) equals `intersect_lanes` pack by
    /// pack for every ray, bit for bit: random packs with repeated triangles (ties), a degenerate
    /// lane, unused lanes, rays from one origin and from several, and lanes retired with
    /// `tmax = -inf`.
    fn check<R: Lane, const K: usize, L: Lane, const N: usize>() {
        let mut rng = Rng::new(3);
        let (mut n_hits, mut n_ties) = (0, 0);
        for case in 0..300 {
            let mut tris: alloc::vec::Vec<Triangle> = (0..(N + 3))
                .map(|_| {
                    let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(2.0, 4.0));
                    [c, c + rng.unit_vector() * 1.5, c + rng.unit_vector() * 1.5]
                })
                .collect();
            tris[2] = tris[0]; // a tie
            tris[3] = [tris[3][0], tris[3][0], tris[3][1]]; // degenerate
            let prims: alloc::vec::Vec<u32> = (0..tris.len() as u32).map(|i| 100 + i).collect();
            let packs = [
                TriangleLanes::<L, N>::pack(&tris[..N], &prims[..N]),
                TriangleLanes::<L, N>::pack(&tris[N..], &prims[N..]),
            ];
            let origin = |i: usize| {
                if case % 2 == 0 {
                    Vec3::ZERO
                } else {
                    Vec3::new(i as f32 * 0.01, 0.0, -0.1)
                }
            };
            let rays: [PreparedRay; K] = core::array::from_fn(|i| {
                let d = Vec3::new(rng.range(-0.4, 0.4), rng.range(-0.4, 0.4), 1.0);
                let mut r = PreparedRay::new(&Ray::new(origin(i), d));
                r.tmax = if i % 5 == 4 { 3.0 } else { f32::INFINITY };
                r
            });
            let retired = 0b1000_0010u32 & ((1u64 << K) - 1) as u32;
            let lanes = |f: &dyn Fn(&PreparedRay) -> f32| {
                let a: [f32; K] = core::array::from_fn(|i| f(&rays[i]));
                R::load(&a)
            };
            let o = [lanes(&|r| r.origin.x), lanes(&|r| r.origin.y), lanes(&|r| r.origin.z)];
            let d = [
                lanes(&|r| r.direction.x),
                lanes(&|r| r.direction.y),
                lanes(&|r| r.direction.z),
            ];
            let tmax = R::from_bitmask(retired).select(R::splat(f32::NEG_INFINITY), lanes(&|r| r.tmax));
            let (hits, t, u, v, prim) = closest_packet_leaf(o, d, lanes(&|r| r.tmin), tmax, &packs);
            for (i, ray) in rays.iter().enumerate() {
                let mut r = *ray;
                let mut want = None;
                if retired >> i & 1 == 0 {
                    for p in &packs {
                        if let Some(h) = intersect_lanes(&r, p) {
                            r.tmax = h.t;
                            want = Some(h);
                        }
                    }
                }
                let got = (hits >> i & 1 == 1).then(|| Hit {
                    t: t.lane(i),
                    u: u.lane(i),
                    v: v.lane(i),
                    prim: prim.lane(i).to_bits(),
                });
                let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim));
                assert_eq!(bits(got), bits(want), "case {case}, ray {i}");
                n_hits += want.is_some() as u32;
                n_ties += want.is_some_and(|h| h.prim == 100) as u32;
            }
        }
        // The cases do what they are for: many hits, some of them on the tied pair.
        assert!(n_hits > 100 && n_ties > 10, "{n_hits} hits, {n_ties} on the tie");
    }

    #[test]
    fn packet_leaf_equals_per_ray_packs() {
        check::<f32x8, 8, f32x8, 8>();
        check::<f32x16, 16, f32x8, 8>();
        check::<f32x4, 4, f32x4, 4>();
        check::<f32x8, 8, f32x4, 4>();
    }
}
