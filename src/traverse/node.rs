//! The BVH2 node format and a borrowed view of a tree: core-only, so that traversal works on
//! caller-provided slices (a tree built elsewhere and read zero-copy from bytes) without `alloc`.

use crate::geometry::Aabb;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// One node of a binary BVH ([`Bvh2`](crate::build::Bvh2)): a box and two `u32`, 32 bytes.
///
/// ```text
///  bytes  0..12   min: [f32; 3]   lower corner of the node's box
///  bytes 12..16   index: u32      interior: left child (the right child is index + 1)
///                                 leaf:     first slot in the primitive-index array
///  bytes 16..28   max: [f32; 3]   upper corner
///  bytes 28..32   count: u32      interior: 0;  leaf: number of primitives (>= 1)
/// ```
///
/// Siblings are adjacent, so an interior node needs one index. Two sibling nodes fill one 64-byte
/// cache line when the pair starts at an even index (the builders put the root at 0 and pairs at
/// odd indices; the line split costs little in the scalar reference).
///
/// ```
/// use strahl::{Aabb, Vec3, traverse::Node};
/// let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
/// let leaf = Node::leaf(&b, 10, 3);
/// assert!(leaf.is_leaf());
/// assert_eq!(leaf.prim_range(), 10..13);
/// let inner = Node::interior(&b, 1);
/// assert_eq!((inner.is_leaf(), inner.left(), inner.right()), (false, 1, 2));
/// assert_eq!(inner.aabb(), b);
/// let bytes: &[u8] = bytemuck::bytes_of(&inner);
/// assert_eq!(bytes.len(), 32);
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Node {
    /// Lower corner of the box.
    pub min: [f32; 3],
    /// Left child (interior node) or first primitive slot (leaf).
    pub index: u32,
    /// Upper corner of the box.
    pub max: [f32; 3],
    /// Number of primitives of a leaf; 0 marks an interior node.
    pub count: u32,
}

const _: () = assert!(core::mem::size_of::<Node>() == 32);

impl Node {
    /// A leaf holding slots `first .. first + count` of the primitive-index array (`count >= 1`;
    /// a `count` of 0 would make it an interior node).
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, build::{Bvh2, Node}};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::Z, Vec3::X, Vec3::Y]];
    /// let leaf = Node::leaf(&Aabb::new(Vec3::ZERO, Vec3::ONE), 0, 2);
    /// assert_eq!((leaf.index, leaf.count, leaf.prim_range()), (0, 2, 0..2));
    /// // One leaf holding both triangles is a whole tree.
    /// let bvh = Bvh2 { nodes: vec![leaf], prim_indices: vec![1, 0] };
    /// assert_eq!(bvh.validate(&tris[..]).unwrap().leaves, 1);
    /// ```
    #[inline]
    pub fn leaf(bounds: &Aabb, first: u32, count: u32) -> Self {
        Self {
            min: bounds.min.to_array(),
            index: first,
            max: bounds.max.to_array(),
            count,
        }
    }

    /// An interior node whose children are `left` and `left + 1`.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, build::{Bvh2, Node, ValidateError}};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::Z, Vec3::ONE, Vec3::Y]];
    /// let b = |i: usize| Aabb::from_points(&tris[i]);
    /// let root = Node::interior(&b(0).union(&b(1)), 1); // children 1 and 2
    /// let nodes = vec![root, Node::leaf(&b(0), 0, 1), Node::leaf(&b(1), 1, 1)];
    /// let mut bvh = Bvh2 { nodes, prim_indices: vec![0, 1] };
    /// assert_eq!(bvh.validate(&tris[..]).unwrap().max_depth, 2);
    /// bvh.nodes[0] = Node::interior(&root.aabb(), 2); // children 2 and 3: past the end
    /// assert_eq!(bvh.validate(&tris[..]), Err(ValidateError::ChildOutOfRange { node: 0, child: 2 }));
    /// ```
    #[inline]
    pub fn interior(bounds: &Aabb, left: u32) -> Self {
        Self {
            min: bounds.min.to_array(),
            index: left,
            max: bounds.max.to_array(),
            count: 0,
        }
    }

    /// `true` for a leaf (`count != 0`).
    ///
    /// ```
    /// use strahl::build::{BuildParams, Bvh2};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, stats) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// assert_eq!(bvh.nodes.iter().filter(|n| n.is_leaf()).count(), stats.leaves as usize);
    /// assert!(!bvh.nodes[0].is_leaf()); // 320 triangles do not fit in one leaf
    /// ```
    #[inline(always)]
    pub fn is_leaf(&self) -> bool {
        self.count != 0
    }

    /// The node's box.
    ///
    /// ```
    /// use strahl::{Aabb, build::{BuildParams, Bvh2}};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let all = tris.iter().fold(Aabb::EMPTY, |b, t| b.union(&Aabb::from_points(t)));
    /// assert_eq!(bvh.nodes[0].aabb(), all); // the root's box: exactly the scene's
    /// ```
    #[inline(always)]
    pub fn aabb(&self) -> Aabb {
        Aabb::new(Vec3::from_array(self.min), Vec3::from_array(self.max))
    }

    /// Replaces the node's box.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, build::{BuildParams, Bvh2}};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let tight = bvh.nodes[0].aabb();
    /// bvh.nodes[0].set_aabb(&Aabb::new(Vec3::ZERO, Vec3::ONE)); // too small for the sphere
    /// assert!(bvh.validate(&tris[..]).is_err());
    /// bvh.nodes[0].set_aabb(&tight);
    /// assert!(bvh.validate(&tris[..]).is_ok());
    /// ```
    #[inline]
    pub fn set_aabb(&mut self, b: &Aabb) {
        self.min = b.min.to_array();
        self.max = b.max.to_array();
    }

    /// Left child of an interior node.
    ///
    /// ```
    /// use strahl::build::{BuildParams, Bvh2};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// for n in bvh.nodes.iter().filter(|n| !n.is_leaf()) {
    ///     let (l, r) = (bvh.nodes[n.left() as usize].aabb(), bvh.nodes[n.right() as usize].aabb());
    ///     assert_eq!(l.union(&r), n.aabb()); // built trees: the children's boxes fill the parent's
    /// }
    /// ```
    #[inline(always)]
    pub fn left(&self) -> u32 {
        self.index
    }

    /// Right child of an interior node (`left + 1`, wrapping instead of panicking on a malformed
    /// node).
    ///
    /// ```
    /// use strahl::{Aabb, build::Node};
    /// let inner = Node::interior(&Aabb::EMPTY, 7);
    /// assert_eq!((inner.left(), inner.right()), (7, 8)); // siblings are adjacent
    /// assert_eq!(Node::interior(&Aabb::EMPTY, u32::MAX).right(), 0); // wraps, no panic
    /// ```
    #[inline(always)]
    pub fn right(&self) -> u32 {
        self.index.wrapping_add(1)
    }

    /// The slots of a leaf's primitives in the primitive-index array (`index .. index + count`,
    /// saturating), empty for an interior node.
    ///
    /// ```
    /// use strahl::build::{BuildParams, Bvh2};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let slots: usize = bvh.nodes.iter().map(|n| n.prim_range().len()).sum();
    /// assert_eq!(slots, bvh.prim_indices.len()); // the leaves share the slots out, interior nodes have none
    /// ```
    #[inline]
    pub fn prim_range(&self) -> core::ops::Range<usize> {
        let first = self.index as usize;
        first..first.saturating_add(self.count as usize)
    }
}

/// A borrowed binary BVH: nodes (root at index 0) and the primitive-index array the leaves point
/// into. Get one from [`Bvh2::view`](crate::build::Bvh2::view), or wrap slices from anywhere (a
/// file, another builder) with [`Bvh2Ref::new`].
///
/// Nothing is checked on construction, and nothing needs to be: traversal never panics and always
/// terminates on any slices (out-of-range indices are skipped, cycles are cut off). The answers
/// are exact for every tree that passes [`Bvh2::validate`](crate::build::Bvh2::validate).
///
/// ```
/// use strahl::{Aabb, Vec3, traverse::{Bvh2Ref, Node}};
/// let nodes = [Node::leaf(&Aabb::new(Vec3::ZERO, Vec3::ONE), 0, 1)];
/// let view = Bvh2Ref::new(&nodes, &[0]);
/// assert_eq!(view.bounds(), Aabb::new(Vec3::ZERO, Vec3::ONE));
/// assert!(Bvh2Ref::new(&[], &[]).bounds().is_empty());
/// ```
#[derive(Clone, Copy, Debug)]
pub struct Bvh2Ref<'a> {
    /// Nodes; the root is `nodes[0]`. Empty for an empty tree.
    pub nodes: &'a [Node],
    /// Primitive indices, referenced by leaves through [`Node::prim_range`].
    pub prim_indices: &'a [u32],
}

impl<'a> Bvh2Ref<'a> {
    /// Wraps node and primitive-index slices (not checked; see the type's docs).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{BuildParams, Bvh2}, traverse::{Bvh2Ref, Watertight, intersect_scalar}};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// // Slices from anywhere, e.g. a copy read back from bytes:
    /// let (nodes, prims) = (bvh.nodes.clone(), bvh.prim_indices.clone());
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// let hit = intersect_scalar::<Watertight, _>(Bvh2Ref::new(&nodes, &prims), &tris[..], &ray);
    /// assert!(hit.is_some() && hit == bvh.intersect::<Watertight, _>(&tris[..], &ray));
    /// ```
    #[inline]
    pub const fn new(nodes: &'a [Node], prim_indices: &'a [u32]) -> Self {
        Self { nodes, prim_indices }
    }

    /// The root's box, or [`Aabb::EMPTY`] for an empty tree.
    ///
    /// ```
    /// use strahl::{Aabb, build::{BuildParams, Bvh2}};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b = bvh.view().bounds();
    /// assert!(tris.iter().all(|t| b.contains(&Aabb::from_points(t))));
    /// assert_eq!(b, bvh.bounds());
    /// ```
    #[inline]
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, Node::aabb)
    }
}
