//! Depth order for "over": a k-d decomposition of the scene's (or volume's) bounds into one box per
//! rank, and the order of those boxes from the viewer, so partial images blend in visibility order.
//!
//! A k-d decomposition is separable by its split planes, so walking the implicit tree and
//! visiting, at each plane, the side that holds the eye first gives a correct front-to-back order
//! for every view (unlike sorting box centres by distance, which fails for unequal boxes).

use crate::geometry::Aabb;
use glam::Vec3;

/// Splits `bounds` into `out.len()` boxes (one per rank, `P >= 1`): `P` parts split into `floor(P/2)`
/// and `ceil(P/2)` parts along the longest axis, the plane placed in proportion, recursively.
/// Part `i` goes to `out[i]`; recursion depth is `ceil(log2 P)`.
///
/// ```
/// use strahl::{Aabb, Vec3, composite::kd_decompose};
/// let mut parts = [Aabb::EMPTY; 3];
/// kd_decompose(&Aabb::new(Vec3::ZERO, Vec3::new(3.0, 1.0, 1.0)), &mut parts);
/// assert_eq!(parts[0].max.x, 1.0); // 1 part of 3 on the left
/// assert_eq!(parts[2].min.x, 2.0);
/// ```
pub fn kd_decompose(bounds: &Aabb, out: &mut [Aabb]) {
    match out.len() {
        0 => {}
        1 => out[0] = *bounds,
        p => {
            let (axis, plane) = split(bounds, p);
            let (mut l, mut r) = (*bounds, *bounds);
            l.max[axis] = plane;
            r.min[axis] = plane;
            let (a, b) = out.split_at_mut(p / 2);
            kd_decompose(&l, a);
            kd_decompose(&r, b);
        }
    }
}

fn split(b: &Aabb, p: usize) -> (usize, f32) {
    let axis = b.longest_axis();
    let f = (p / 2) as f32 / p as f32;
    (axis, b.min[axis] + (b.max[axis] - b.min[axis]) * f)
}

/// Where the viewer is.
///
/// ```
/// use strahl::{Aabb, Vec3, composite::{View, visibility_order}};
/// let b = Aabb::new(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0)); // two parts: x < 1 and x > 1
/// let mut order = [0; 2];
/// visibility_order(&b, View::Eye(Vec3::new(1.5, 0.5, 0.5)), &mut order);
/// assert_eq!(order, [1, 0]); // an eye inside part 1 sees it first
/// visibility_order(&b, View::Direction(Vec3::X), &mut order);
/// assert_eq!(order, [0, 1]); // looking along +x, part 0 is in front
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum View {
    /// A perspective eye point.
    Eye(Vec3),
    /// An orthographic view along a direction.
    Direction(Vec3),
}

/// Fills `order` (length `P`, the same `P` as [`kd_decompose`]) with the part indices from
/// nearest to farthest for `view`.
///
/// ```
/// use strahl::{Aabb, Vec3, composite::{View, visibility_order}};
/// let b = Aabb::new(Vec3::ZERO, Vec3::new(4.0, 1.0, 1.0));
/// let mut order = [0; 4];
/// visibility_order(&b, View::Eye(Vec3::new(10.0, 0.5, 0.5)), &mut order);
/// assert_eq!(order, [3, 2, 1, 0]); // seen from +x, the rightmost part is nearest
/// visibility_order(&b, View::Direction(Vec3::X), &mut order);
/// assert_eq!(order, [0, 1, 2, 3]);
/// ```
pub fn visibility_order(bounds: &Aabb, view: View, order: &mut [u32]) {
    walk(bounds, view, 0, order);
}

fn walk(b: &Aabb, view: View, first: u32, order: &mut [u32]) {
    let p = order.len();
    if p == 0 {
        return;
    }
    if p == 1 {
        order[0] = first;
        return;
    }
    let (axis, plane) = split(b, p);
    let (mut l, mut r) = (*b, *b);
    l.max[axis] = plane;
    r.min[axis] = plane;
    let left_first = match view {
        View::Eye(e) => e[axis] <= plane,
        // NOTE: -0.0 and NaN directions count as "not positive": the right side first.
        View::Direction(d) => d[axis] > 0.0,
    };
    let nl = p / 2;
    if left_first {
        let (a, c) = order.split_at_mut(nl);
        walk(&l, view, first, a);
        walk(&r, view, first + nl as u32, c);
    } else {
        let (a, c) = order.split_at_mut(p - nl);
        walk(&r, view, first + nl as u32, a);
        walk(&l, view, first, c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_is_a_permutation_and_front_to_back() {
        let b = Aabb::new(Vec3::new(-1.0, -2.0, -3.0), Vec3::new(5.0, 2.0, 1.0));
        for p in 1..=16usize {
            let mut parts = [Aabb::EMPTY; 16];
            kd_decompose(&b, &mut parts[..p]);
            // Parts tile the bounds: volumes add up.
            let vol = |a: &Aabb| (a.max - a.min).x * (a.max - a.min).y * (a.max - a.min).z;
            let total: f32 = parts[..p].iter().map(vol).sum();
            assert!((total - vol(&b)).abs() < 1e-3 * vol(&b));
            for eye in [
                Vec3::new(9.0, 0.1, 0.2),
                Vec3::new(-7.0, 3.0, -9.0),
                Vec3::new(0.3, -0.2, -0.4),
            ] {
                let mut order = [0u32; 16];
                visibility_order(&b, View::Eye(eye), &mut order[..p]);
                let mut seen = [false; 16];
                for &o in &order[..p] {
                    assert!(!seen[o as usize]);
                    seen[o as usize] = true;
                }
                // Front to back: no part later in the order occludes an earlier one, checked along
                // rays from the eye through sample points: the parts a ray enters appear in order.
                for (i, &a) in order[..p].iter().enumerate() {
                    for &c in &order[i + 1..p] {
                        let (pa, pc) = (parts[a as usize], parts[c as usize]);
                        // A ray from the eye to pc's centre must not pass through pa after pc.
                        let target = pc.centroid();
                        let d = target - eye;
                        let r = crate::intersect::PreparedRay::new(&crate::geometry::Ray::new(eye, d));
                        if let Some(t) = crate::intersect::intersect_aabb_scalar(&r, &pa) {
                            assert!(t <= 1.0 + 1e-4, "p {p} eye {eye}: part {a} lies behind part {c}");
                        }
                    }
                }
            }
        }
    }
}
