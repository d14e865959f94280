//! Brute force over every primitive: the ground truth the BVH traversals are tested against.

use super::{AcceptAll, HitFilter, TriangleTest};
use crate::geometry::{Hit, Ray, Triangles};
use crate::intersect::PreparedRay;

/// The closest hit of `ray` among all of `tris`, testing every triangle in index order (ties in
/// `t`: the lowest index). Triangles that cannot be formed are skipped.
///
/// ```
/// use strahl::{Ray, Vec3, traverse::{Moller, intersect_brute_force}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris = [tri(3.0), tri(2.0), tri(2.0)];
/// let hit = intersect_brute_force::<Moller, _>(&tris[..], &Ray::new(Vec3::ZERO, Vec3::Z)).unwrap();
/// assert_eq!((hit.t, hit.prim), (2.0, 1));
/// ```
pub fn intersect_brute_force<T: TriangleTest, P: Triangles + ?Sized>(tris: &P, ray: &Ray) -> Option<Hit> {
    intersect_brute_force_filtered::<T, P, _>(tris, ray, AcceptAll)
}

/// [`intersect_brute_force`] counting only the hits `filter` accepts ([`HitFilter`](super::HitFilter)):
/// the nearest accepted hit (ties in `t`: the lowest index), each triangle's hit offered once,
/// in index order, while no closer one has been accepted.
///
/// ```
/// use strahl::{Hit, Ray, Vec3, traverse::{Moller, intersect_brute_force_filtered}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris = [tri(3.0), tri(2.0), tri(2.5)];
/// let ray = Ray::new(Vec3::ZERO, Vec3::Z);
/// let hit = intersect_brute_force_filtered::<Moller, _, _>(&tris[..], &ray, |h: &Hit| h.t > 2.0).unwrap();
/// assert_eq!((hit.t, hit.prim), (2.5, 2));
/// ```
pub fn intersect_brute_force_filtered<T: TriangleTest, P: Triangles + ?Sized, F: HitFilter>(
    tris: &P,
    ray: &Ray,
    mut filter: F,
) -> Option<Hit> {
    let mut r = PreparedRay::new(ray);
    let mut best = None;
    for i in 0..tris.len() {
        if let Some(tri) = tris.triangle(i)
            && let Some(h) = T::intersect(&r, &tri, i as u32)
            && (F::ACCEPTS_ALL || filter.accept(&h))
        {
            r.tmax = h.t;
            best = Some(h);
        }
    }
    best
}

/// `true` if `ray` hits any of `tris` within `[tmin, tmax)`.
///
/// ```
/// use strahl::{Ray, Vec3, traverse::{Watertight, occluded_brute_force}};
/// let tris = [[Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)]];
/// assert!(occluded_brute_force::<Watertight, _>(&tris[..], &Ray::new(Vec3::ZERO, Vec3::Z)));
/// assert!(!occluded_brute_force::<Watertight, _>(&tris[..], &Ray::new(Vec3::ZERO, -Vec3::Z)));
/// ```
pub fn occluded_brute_force<T: TriangleTest, P: Triangles + ?Sized>(tris: &P, ray: &Ray) -> bool {
    occluded_brute_force_filtered::<T, P, _>(tris, ray, AcceptAll)
}

/// [`occluded_brute_force`] counting only the hits `filter` accepts ([`HitFilter`](super::HitFilter)).
///
/// ```
/// use strahl::{Hit, Ray, Vec3, traverse::{Watertight, occluded_brute_force_filtered}};
/// let tris = [[Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)]];
/// let ray = Ray::new(Vec3::ZERO, Vec3::Z);
/// assert!(occluded_brute_force_filtered::<Watertight, _, _>(&tris[..], &ray, |h: &Hit| h.u < 0.5));
/// assert!(!occluded_brute_force_filtered::<Watertight, _, _>(&tris[..], &ray, |h: &Hit| h.prim != 0));
/// ```
pub fn occluded_brute_force_filtered<T: TriangleTest, P: Triangles + ?Sized, F: HitFilter>(
    tris: &P,
    ray: &Ray,
    mut filter: F,
) -> bool {
    let r = PreparedRay::new(ray);
    (0..tris.len()).any(|i| {
        tris.triangle(i)
            .is_some_and(|tri| T::intersect(&r, &tri, i as u32).is_some_and(|h| F::ACCEPTS_ALL || filter.accept(&h)))
    })
}
