//! Scalar closest-hit and any-hit traversal of a binary BVH (see the [module docs](super)).

use super::{AcceptAll, Bvh2Ref, HitFilter, Node, STACK_SIZE, TriangleTest, beyond, node_scalar, prepare};
use crate::geometry::{Hit, Ray, Triangles};
use crate::intersect::PreparedRay;

/// Closest hit of `ray` in the tree `bvh` over `tris` (scalar reference).
///
/// Equal to [`intersect_brute_force`](super::intersect_brute_force) in `t` for every valid tree;
/// the primitive is the same unless two primitives are hit at exactly the same `t` (then either).
/// Never panics, whatever the slices hold (see the [module docs](super#depth-and-the-stack)).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}};
/// use strahl::traverse::{Moller, intersect_scalar};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris = [tri(5.0), tri(3.0), tri(4.0)];
/// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::quality()).unwrap();
/// let hit = intersect_scalar::<Moller, _>(bvh.view(), &tris[..], &Ray::new(Vec3::ZERO, Vec3::Z));
/// assert_eq!(hit.map(|h| (h.t, h.prim)), Some((3.0, 1)));
/// ```
#[inline]
pub fn intersect_scalar<T: TriangleTest, P: Triangles + ?Sized>(bvh: Bvh2Ref<'_>, tris: &P, ray: &Ray) -> Option<Hit> {
    walk::<T, P, AcceptAll, false>(bvh, tris, ray, &mut AcceptAll)
}

/// [`intersect_scalar`] counting only the hits `filter` accepts ([`HitFilter`]): the nearest
/// accepted hit. The reference the wide BVHs' filtered traversals are tested against.
///
/// ```
/// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}};
/// use strahl::traverse::{Moller, intersect_scalar_filtered};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris = [tri(5.0), tri(3.0), tri(4.0)];
/// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::quality()).unwrap();
/// let ray = Ray::new(Vec3::ZERO, Vec3::Z);
/// let hit = intersect_scalar_filtered::<Moller, _, _>(bvh.view(), &tris[..], &ray, |h: &Hit| h.prim != 1);
/// assert_eq!(hit.map(|h| (h.t, h.prim)), Some((4.0, 2))); // through triangle 1
/// ```
#[inline]
pub fn intersect_scalar_filtered<T: TriangleTest, P: Triangles + ?Sized, F: HitFilter>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    ray: &Ray,
    mut filter: F,
) -> Option<Hit> {
    walk::<T, P, F, false>(bvh, tris, ray, &mut filter)
}

/// `true` if `ray` hits anything in the tree within `[tmin, tmax)` (any-hit; scalar reference).
/// Stops at the first hit found.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, scene};
/// use strahl::traverse::{Watertight, occluded_scalar};
/// let mesh = scene::icosphere(1);
/// let tris = mesh.as_indexed();
/// let (bvh, _) = Bvh2::build(&tris, &BuildParams::fastest()).unwrap();
/// let toward = Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z);
/// let away = Ray::new(Vec3::new(0.0, 0.0, -3.0), -Vec3::Z);
/// assert!(occluded_scalar::<Watertight, _>(bvh.view(), &tris, &toward));
/// assert!(!occluded_scalar::<Watertight, _>(bvh.view(), &tris, &away));
/// ```
#[inline]
pub fn occluded_scalar<T: TriangleTest, P: Triangles + ?Sized>(bvh: Bvh2Ref<'_>, tris: &P, ray: &Ray) -> bool {
    walk::<T, P, AcceptAll, true>(bvh, tris, ray, &mut AcceptAll).is_some()
}

/// [`occluded_scalar`] counting only the hits `filter` accepts ([`HitFilter`]): `true` if one is.
///
/// ```
/// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, scene};
/// use strahl::traverse::{Watertight, occluded_scalar_filtered};
/// let mesh = scene::icosphere(1);
/// let tris = mesh.as_indexed();
/// let (bvh, _) = Bvh2::build(&tris, &BuildParams::fastest()).unwrap();
/// let toward = Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z);
/// assert!(occluded_scalar_filtered::<Watertight, _, _>(bvh.view(), &tris, &toward, |_: &Hit| true));
/// assert!(!occluded_scalar_filtered::<Watertight, _, _>(bvh.view(), &tris, &toward, |_: &Hit| false));
/// ```
#[inline]
pub fn occluded_scalar_filtered<T: TriangleTest, P: Triangles + ?Sized, F: HitFilter>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    ray: &Ray,
    mut filter: F,
) -> bool {
    walk::<T, P, F, true>(bvh, tris, ray, &mut filter).is_some()
}

/// The traversal loop. `ANY`: return the first hit found instead of the closest. Only hits `f`
/// accepts count.
#[inline(always)]
fn walk<T: TriangleTest, P: Triangles + ?Sized, F: HitFilter, const ANY: bool>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    ray: &Ray,
    f: &mut F,
) -> Option<Hit> {
    let nodes = bvh.nodes;
    let mut r = prepare::<T>(ray);
    let root = nodes.first()?;
    node_scalar::<T>(&r, &root.aabb())?;

    // (node, entry distance) of the far children still to visit.
    let mut stack = [(0u32, 0.0f32); STACK_SIZE];
    let mut sp = 0usize;
    let mut node: &Node = root;
    let mut best: Option<Hit> = None;
    // A valid tree visits each node at most once; more visits mean a cycle.
    let mut budget = nodes.len();
    loop {
        if budget == 0 {
            return linear_rest::<T, P, F, ANY>(bvh, tris, r, best, f);
        }
        budget -= 1;
        if node.is_leaf() {
            for slot in node.prim_range() {
                let Some(&prim) = bvh.prim_indices.get(slot) else {
                    break;
                };
                if let Some(tri) = tris.triangle(prim as usize)
                    && let Some(h) = T::intersect(&r, &tri, prim)
                    && (F::ACCEPTS_ALL || f.accept(&h))
                {
                    if ANY {
                        return Some(h);
                    }
                    r.tmax = h.t;
                    best = Some(h);
                }
            }
        } else {
            let (li, ri) = (node.left(), node.right());
            let (ln, rn) = (nodes.get(li as usize), nodes.get(ri as usize));
            let tl = ln.and_then(|n| node_scalar::<T>(&r, &n.aabb()));
            let tr = rn.and_then(|n| node_scalar::<T>(&r, &n.aabb()));
            match (ln, tl, rn, tr) {
                (Some(ln), Some(tl), Some(rn), Some(tr)) => {
                    // Both hit: descend into the nearer (ties: left), push the farther.
                    let (near, far, far_t) = if tr < tl { (rn, li, tl) } else { (ln, ri, tr) };
                    if sp == STACK_SIZE {
                        // NOTE: only a tree deeper than the builders make gets here.
                        return linear_rest::<T, P, F, ANY>(bvh, tris, r, best, f);
                    }
                    stack[sp] = (far, far_t);
                    sp += 1;
                    node = near;
                    continue;
                }
                (Some(ln), Some(_), _, _) => {
                    node = ln;
                    continue;
                }
                (_, _, Some(rn), Some(_)) => {
                    node = rn;
                    continue;
                }
                _ => {}
            }
        }
        // Pop the next far child that can still hold a closer hit. Re-testing its box with the
        // shrunken tmax reduces to this comparison (the slab test's own, with far = tmax).
        loop {
            if sp == 0 {
                return best;
            }
            sp -= 1;
            let (n, near) = stack[sp];
            if beyond::<T>(near, r.tmax) {
                continue;
            }
            if let Some(n) = nodes.get(n as usize) {
                node = n;
                break;
            }
        }
    }
}

/// Finishes a search that cannot go on through the tree (stack overflow, cycle): tests every
/// primitive the tree references, with the current `tmax`.
#[cold]
#[inline(never)]
fn linear_rest<T: TriangleTest, P: Triangles + ?Sized, F: HitFilter, const ANY: bool>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    mut r: PreparedRay,
    mut best: Option<Hit>,
    f: &mut F,
) -> Option<Hit> {
    for &prim in bvh.prim_indices {
        if let Some(tri) = tris.triangle(prim as usize)
            && let Some(h) = T::intersect(&r, &tri, prim)
            && (F::ACCEPTS_ALL || f.accept(&h))
        {
            if ANY {
                return Some(h);
            }
            r.tmax = h.t;
            best = Some(h);
        }
    }
    best
}
