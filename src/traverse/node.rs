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
    #[inline(always)]
    pub fn is_leaf(&self) -> bool {
        self.count != 0
    }

    /// The node's box.
    #[inline(always)]
    pub fn aabb(&self) -> Aabb {
        Aabb::new(Vec3::from_array(self.min), Vec3::from_array(self.max))
    }

    /// Replaces the node's box.
    #[inline]
    pub fn set_aabb(&mut self, b: &Aabb) {
        self.min = b.min.to_array();
        self.max = b.max.to_array();
    }

    /// Left child of an interior node.
    #[inline(always)]
    pub fn left(&self) -> u32 {
        self.index
    }

    /// Right child of an interior node (`left + 1`, wrapping instead of panicking on a malformed
    /// node).
    #[inline(always)]
    pub fn right(&self) -> u32 {
        self.index.wrapping_add(1)
    }

    /// The slots of a leaf's primitives in the primitive-index array (`index .. index + count`,
    /// saturating), empty for an interior node.
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
    #[inline]
    pub const fn new(nodes: &'a [Node], prim_indices: &'a [u32]) -> Self {
        Self { nodes, prim_indices }
    }

    /// The root's box, or [`Aabb::EMPTY`] for an empty tree.
    #[inline]
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, Node::aabb)
    }
}
