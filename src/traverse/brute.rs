//! Brute force over every primitive: the ground truth the BVH traversals are tested against.

use super::TriangleTest;
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
    let mut r = PreparedRay::new(ray);
    let mut best = None;
    for i in 0..tris.len() {
        if let Some(tri) = tris.triangle(i)
            && let Some(h) = T::intersect(&r, &tri, i as u32)
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
    let r = PreparedRay::new(ray);
    (0..tris.len()).any(|i| {
        tris.triangle(i)
            .is_some_and(|tri| T::intersect(&r, &tri, i as u32).is_some())
    })
}
