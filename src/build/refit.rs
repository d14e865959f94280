//! [`Bvh2::refit`] (new boxes for moved primitives, same topology) and [`Bvh2::sah_cost`].

use super::prims::{Primitives, usable_bounds};
use super::validate::{Walk, checked_pre_order};
use super::{Bvh2, ValidateError};
use crate::geometry::Aabb;

impl Bvh2 {
    /// Recomputes every node's box from the primitives' current boxes, keeping the topology
    /// (for animated geometry whose connectivity does not change; the SAH cost of the tree may
    /// degrade as primitives move).
    ///
    /// Primitives that have become invalid (say, a NaN vertex, or a coordinate beyond about
    /// `±1.7e38`: see [`Primitives`]) contribute nothing to their leaf's box and stay in the
    /// tree; a leaf left with no valid primitive gets the empty box ([`Aabb::EMPTY`]), which rays
    /// never hit. [`validate`](Self::validate) then names the first of these it meets:
    /// [`ValidateError::EmptyNode`] for a node with no valid primitive left below it (the
    /// highest such node on its path from the root), [`ValidateError::InvalidPrimReferenced`]
    /// for an invalid primitive in a leaf that still has a valid one. Rebuild to drop them.
    /// Errors, without changing the tree, if the structure is malformed (indices out of range, a
    /// node reached twice).
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams}};
    /// let mut tris = vec![[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::Z, Vec3::ONE, Vec3::Y]];
    /// let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::fast()).unwrap();
    /// for t in &mut tris {
    ///     for v in t.iter_mut() {
    ///         *v += Vec3::new(10.0, 0.0, 0.0);
    ///     }
    /// }
    /// bvh.refit(&tris[..]).unwrap();
    /// assert_eq!(bvh.bounds().min.x, 10.0);
    /// assert!(bvh.validate(&tris[..]).is_ok());
    /// // Every triangle NaN: refitted to nothing, and an empty tree by `validate`.
    /// let nan = vec![[Vec3::NAN; 3]; 2];
    /// bvh.refit(&nan[..]).unwrap();
    /// assert_eq!(bvh.bounds(), strahl::Aabb::EMPTY);
    /// assert_eq!(bvh.validate(&nan[..]), Err(strahl::build::ValidateError::EmptyNode { node: 0 }));
    /// ```
    pub fn refit<P: Primitives + ?Sized>(&mut self, prims: &P) -> Result<(), ValidateError> {
        // A parent precedes its descendants in pre-order, so the reverse order visits children
        // first.
        let mut walk = Walk::default();
        checked_pre_order(&self.nodes, self.prim_indices.len(), &mut walk, |_, _| {})?;
        let order = walk.order;
        for &i in order.iter().rev() {
            let node = self.nodes[i as usize];
            let b = if node.is_leaf() {
                self.prim_indices[node.prim_range()]
                    .iter()
                    .filter_map(|&p| usable_bounds(prims, p as usize))
                    .fold(Aabb::EMPTY, |acc, b| acc.union(&b))
            } else {
                let l = node.left() as usize;
                self.nodes[l].aabb().union(&self.nodes[l + 1].aabb())
            };
            self.nodes[i as usize].set_aabb(&b);
        }
        Ok(())
    }

    /// The SAH cost of the tree with traversal cost `c_t` and intersection cost `c_i`,
    /// normalised by the root's surface area (the expected cost of a ray that hits the root, as
    /// usual):
    ///
    /// ```text
    /// cost = sum over interior nodes n of  c_t A(n) / A(root)
    ///      + sum over leaves l of          c_i N(l) A(l) / A(root)
    /// ```
    ///
    /// Sums over every node of the array (all of them are reachable in a valid tree), in `f64`.
    /// 0 for an empty tree. If the root's area is 0 (all primitives on a point or a segment) every
    /// node counts in full (ratio 1).
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams}};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// assert_eq!(bvh.sah_cost(1.0, 2.0), 2.0); // one leaf with one triangle
    /// assert_eq!(Bvh2::default().sah_cost(1.0, 1.0), 0.0);
    /// ```
    pub fn sah_cost(&self, c_t: f32, c_i: f32) -> f32 {
        let Some(root) = self.nodes.first() else {
            return 0.0;
        };
        let a0 = root.aabb().half_area() as f64;
        let norm = if a0 > 0.0 && a0.is_finite() { 1.0 / a0 } else { 0.0 };
        let mut sum = 0.0f64;
        for n in &self.nodes {
            let ratio = if norm > 0.0 {
                n.aabb().half_area() as f64 * norm
            } else {
                1.0
            };
            sum += ratio
                * if n.is_leaf() {
                    c_i as f64 * n.count as f64
                } else {
                    c_t as f64
                };
        }
        sum as f32
    }
}
