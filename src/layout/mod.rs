//! Wide BVHs: a [`Bvh2`](crate::build::Bvh2) collapsed into 4- or 8-wide nodes whose child boxes
//! sit in SoA lanes for the x4/x8 slab test, with leaves of triangles pre-packed in SoA form for
//! the x4/x8 triangle kernels. Traversal is in [`traverse::wide`](crate::traverse::wide).
//!
//! # Collapse
//! Cost-optimal by default ([`BvhWide::from_bvh2`]): the dynamic program of Ylitie, Karras and
//! Laine ("Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs", 2017) finds,
//! for every binary node and every `i <= N`, the cheapest way to cover its subtree with `i`
//! children of one wide node, each either a leaf (its triangles packed `N` at a time, up to two
//! packs for an interior binary node) or a wide node of its own, by an SAH with a cost per node
//! visit and per pack tested. Every binary leaf stays whole (a leaf of more than `N` triangles
//! becomes several packs, up to [`MAX_LEAF_PACKS`]; larger ones get their own node). The greedy
//! collapse ([`BvhWide::from_bvh2_greedy`], as Wald et al., "Getting rid of packets", 2008):
//! open the interior child with the largest surface area until there are `N`, and make every
//! subtree of at most `N` triangles one pack. On the bunny and a 262k sphereflake the optimal
//! collapse makes 2.6 to 3 times fewer nodes (7.7 to 7.9 of 8 children used instead of 3.9 to
//! 4.2) and traces 1 to 3% (primary rays) and 6 to 11% (diffuse rays) faster
//! (`tests/collapse_speed.rs`); by its own cost model it is never worse (tested). With `std`,
//! `BvhWide::from_bvh2_par` makes the same cost-optimal tree on several threads (subtrees side
//! by side, numbered differently; `tests/collapse_par.rs`).
//!
//! # Refit
//! [`BvhWide::refit`] (and, with `std`, `BvhWide::refit_par`) keeps the tree's shape and fills
//! its packs and boxes again from moved triangles: for animated meshes, about 16x faster than a
//! rebuild on 1M triangles, at no cost in trace time for small motion (`benches/RESULTS.md`,
//! "Refitting animated geometry").
//!
//! # Saving and loading
//! [`BvhWide::to_bytes`] writes a tree; [`BvhWide::from_bytes`] reads it back as a checked copy
//! (any alignment, any byte order), [`BvhWideRef::from_bytes`] traces the bytes in place (aligned,
//! `no_std`, no allocation): a 1M-triangle BVH8 loads 10 to 40 times faster than it is built and
//! collapsed (README, "Saving and loading wide BVHs"). Bad bytes give a [`FormatError`].
//!
//! # Instances
//! [`Tlas`] is the top level of a two-level BVH: [`Instance`]s place wide trees (BLASes) in the
//! world by affine transforms; rays are traced into each instance's object space (see
//! [`Tlas`]).

//! # Layout
//! ```text
//!  Node8 (256 bytes, 64-byte aligned)      Node4 (128 bytes)
//!   min x | min y | min z   3 x f32x8       3 x f32x4
//!   max x | max y | max z   3 x f32x8       3 x f32x4
//!   child[8]: u32           interior: node index
//!                           leaf:     LEAF_BIT | first pack << 4 | (packs - 1)
//!                           unused:   EMPTY_CHILD (its box is empty, so never hit)
//!   pad[8]: u32
//! ```

mod bytes;
#[cfg(feature = "alloc")]
mod collapse;
#[cfg(feature = "alloc")]
mod instance;
#[cfg(feature = "alloc")]
#[cfg(feature = "std")]
mod pages;
#[cfg(feature = "alloc")]
mod refit;

use crate::intersect::{AabbLanes, TriangleLanes};
use crate::math::{Lane, f32x4, f32x8};
#[cfg(feature = "alloc")]
use alloc::vec::Vec;

pub use bytes::{FormatError, HEADER_BYTES};
#[cfg(feature = "alloc")]
pub use collapse::{CollapseError, Collapser, WideBuildError};
#[cfg(feature = "alloc")]
pub use instance::{Blas, Instance, InstanceHit, Tlas};

/// Marks a leaf child code.
///
/// ```
/// # use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh8, EMPTY_CHILD, LEAF_BIT}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// for &c in b8.nodes().iter().flat_map(|n| &n.child) {
///     // Each child is unused, a leaf, or the index of another node.
///     assert!(c == EMPTY_CHILD || c & LEAF_BIT != 0 || (c as usize) < b8.nodes().len());
/// }
/// ```
pub const LEAF_BIT: u32 = 1 << 31;
/// An unused child slot.
///
/// ```
/// # use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh4, EMPTY_CHILD}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// for node in b4.nodes() {
///     for (i, &c) in node.child.iter().enumerate() {
///         assert_eq!(c == EMPTY_CHILD, node.bounds.get(i).is_empty()); // unused slots have empty boxes
///     }
/// }
/// ```
pub const EMPTY_CHILD: u32 = u32::MAX;
/// Most packs (of `N` triangles) one leaf child refers to.
///
/// ```
/// use strahl::layout::{LEAF_BIT, MAX_LEAF_PACKS, leaf_packs};
/// assert_eq!(leaf_packs(LEAF_BIT | 15).1, MAX_LEAF_PACKS); // the most a leaf code can hold
/// ```
pub const MAX_LEAF_PACKS: usize = 16;

/// Decodes a leaf child code into `(first pack, number of packs)`.
///
/// ```
/// use strahl::layout::{LEAF_BIT, leaf_packs};
/// assert_eq!(leaf_packs(LEAF_BIT | 5 << 4 | 2), (5, 3)); // packs 5, 6 and 7
/// assert_eq!(leaf_packs(LEAF_BIT), (0, 1));
/// ```
#[inline(always)]
pub const fn leaf_packs(code: u32) -> (usize, usize) {
    (((code & !LEAF_BIT) >> 4) as usize, (code & 15) as usize + 1)
}

/// One node of an `N`-wide BVH: `N` child boxes in SoA lanes and `N` child codes.
///
/// ```
/// use strahl::{Aabb, build::{Bvh2, BuildParams}, layout::Bvh4};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// let root = &b4.nodes()[0];
/// // The root's child boxes together make the box of the whole tree.
/// let all = (0..4).fold(Aabb::EMPTY, |acc, i| acc.union(&root.bounds.get(i)));
/// assert_eq!(all, b2.bounds());
/// ```
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct WideNode<L, const N: usize> {
    /// Child boxes, lane `i` for child `i` (empty boxes for unused slots).
    pub bounds: AabbLanes<L>,
    /// Child codes: a node index, a leaf ([`LEAF_BIT`], see [`leaf_packs`]) or [`EMPTY_CHILD`].
    pub child: [u32; N],
    _pad: [u32; N],
}

/// A 4-wide node (128 bytes).
///
/// ```
/// use strahl::layout::Node4;
/// assert_eq!((size_of::<Node4>(), align_of::<Node4>()), (128, 64)); // two cache lines
/// ```
pub type Node4 = WideNode<f32x4, 4>;
/// An 8-wide node (256 bytes).
///
/// ```
/// use strahl::layout::Node8;
/// assert_eq!((size_of::<Node8>(), align_of::<Node8>()), (256, 64)); // four cache lines
/// ```
pub type Node8 = WideNode<f32x8, 8>;

const _: () = assert!(core::mem::size_of::<Node4>() == 128);
const _: () = assert!(core::mem::size_of::<Node8>() == 256);
const _: () = assert!(core::mem::size_of::<TriangleLanes<f32x8, 8>>() == 8 * 4 * 9 + 8 * 4 + 32);

impl<L: Lane, const N: usize> WideNode<L, N> {
    /// One box lane per child slot: the traversals read child `i` for a hit in lane `i`.
    /// (No wider than 8: the traversals' per-node arrays hold 8 lanes.)
    const LANES_MATCH: () = assert!(L::N == N && N <= 8, "a wide node needs a lane type with N <= 8 lanes");

    /// A node with every slot empty.
    ///
    /// ```
    /// use strahl::layout::{EMPTY_CHILD, Node8};
    /// let n = Node8::empty();
    /// assert!(n.child.iter().all(|&c| c == EMPTY_CHILD));
    /// assert!((0..8).all(|i| n.bounds.get(i).is_empty()));
    /// ```
    ///
    /// The lane type must have `N` lanes, one box per child slot, and `N` be at most 8 (this and,
    /// for [`Node4`] and [`Node8`] only, `bytemuck::Zeroable::zeroed` are the only ways to make a
    /// node outside the crate, so every view's nodes have it):
    ///
    /// ```compile_fail
    /// use strahl::{layout::WideNode, math::f32x8};
    /// let n = WideNode::<f32x8, 4>::empty(); // 8 box lanes for 4 children: a compile error
    /// ```
    ///
    /// ```compile_fail
    /// use strahl::{layout::WideNode, math::f32x16};
    /// let n = WideNode::<f32x16, 16>::empty(); // wider than the traversals take: a compile error
    /// ```
    pub fn empty() -> Self {
        let () = Self::LANES_MATCH;
        Self {
            bounds: AabbLanes::empty(),
            child: [EMPTY_CHILD; N],
            _pad: [0; N],
        }
    }
}

/// A borrowed `N`-wide BVH: nodes (the root is `nodes[0]`) and the triangle packs the leaves refer
/// to. Traversal ([`traverse::wide`](crate::traverse::wide)) works on this view, without `alloc`.
///
/// Nothing is checked on construction (only that a node's lane type has `N` lanes, which
/// [`WideNode::empty`] checks at compile time): traversal never panics and always terminates on
/// any slices. Codes out of range are skipped; a walk that would overflow its stack (a tree deeper
/// than [`MAX_WIDE_DEPTH`]) or visits more nodes than the view has (a cycle, a node with two
/// parents) stops and answers from a scan of every pack instead, so the answer stays exact, only
/// slow. Trees from [`BvhWide::from_bvh2`] (and its parallel form) are always within bounds.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, intersect::AabbX8, layout::{Bvh8Ref, Node8}, traverse::{Moller, wide}};
/// // A node whose only child is a node index past the end of the slice.
/// let mut node = Node8::empty();
/// node.child[0] = 7;
/// node.bounds = AabbX8::from_boxes(&[Aabb::new(Vec3::splat(-1.0), Vec3::ONE)]);
/// let view = Bvh8Ref { nodes: &[node], packs: &[] };
/// let ray = Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z);
/// assert_eq!(wide::intersect::<Moller, _, 8>(view, &ray), None); // skipped, no panic
/// ```
#[derive(Clone, Copy, Debug)]
pub struct BvhWideRef<'a, L, const N: usize> {
    /// Nodes; the root is `nodes[0]`.
    pub nodes: &'a [WideNode<L, N>],
    /// Triangle packs referenced by leaf codes.
    pub packs: &'a [TriangleLanes<L, N>],
}

/// A borrowed [`Bvh4`].
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh4, Bvh4Ref}, traverse::{Moller, wide}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// // Nodes and packs may come from anywhere (a file, shared memory); here, the tree's own.
/// let view = Bvh4Ref { nodes: b4.nodes(), packs: b4.packs() };
/// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
/// assert_eq!(wide::intersect::<Moller, _, 4>(view, &ray), b2.intersect::<Moller, _>(&tris[..], &ray));
/// ```
pub type Bvh4Ref<'a> = BvhWideRef<'a, f32x4, 4>;
/// A borrowed [`Bvh8`].
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Bvh8Ref}, traverse::{Watertight, wide}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let view: Bvh8Ref = b8.view();
/// assert!(wide::occluded::<Watertight, _, 8>(view, &Ray::new(Vec3::ZERO, Vec3::new(0.3, -0.5, 1.0))));
/// assert!(!wide::occluded::<Watertight, _, 8>(Bvh8Ref { nodes: &[], packs: &[] }, &Ray::new(Vec3::ZERO, Vec3::Z)));
/// ```
pub type Bvh8Ref<'a> = BvhWideRef<'a, f32x8, 8>;

/// An `N`-wide BVH over triangles, owning its nodes and packs. Build it with
/// [`BvhWide::from_bvh2`] (or, with `std`, on several threads with `BvhWide::from_bvh2_par`);
/// trace it with [`BvhWide::intersect`] and [`BvhWide::occluded`].
///
/// The fields are private so that every value keeps the invariants traversal is exact under:
/// every code in range and the depth within [`MAX_WIDE_DEPTH`].
///
/// With the `hugepages` feature (default) on Linux, [`from_bvh2`](Self::from_bvh2) (and its
/// parallel form) makes node and pack arrays of 4 MiB or more in memory advised for transparent
/// huge pages (the parallel form moves its nodes there at the end), as Embree does with its
/// trees (measured: about 1.2x on 1M-triangle scenes, whose node and leaf reads miss the TLB on
/// 4 KiB pages). A hint only; a `clone` is an ordinary allocation.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, traverse::{Watertight, intersect_brute_force}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// let ray = Ray::new(Vec3::new(-0.3, 0.2, 4.0), -Vec3::Z);
/// assert_eq!(b4.intersect::<Watertight>(&ray), intersect_brute_force::<Watertight, _>(&tris[..], &ray));
/// assert!(b4.depth() < b2.validate(&tris[..]).unwrap().max_depth); // fewer levels than the BVH2
/// ```
#[cfg(feature = "alloc")]
#[derive(Clone, Debug)]
pub struct BvhWide<L, const N: usize> {
    pub(crate) nodes: Vec<WideNode<L, N>>,
    pub(crate) packs: Vec<TriangleLanes<L, N>>,
    pub(crate) depth: u32,
}

/// A 4-wide BVH (SSE / NEON lanes).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, traverse::Watertight};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// assert_eq!(b4.packs().iter().map(|p| p.valid.count_ones()).sum::<u32>(), 320); // each triangle once
/// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
/// assert_eq!(b4.intersect::<Watertight>(&ray), b2.intersect::<Watertight, _>(&tris[..], &ray));
/// ```
#[cfg(feature = "alloc")]
pub type Bvh4 = BvhWide<f32x4, 4>;
/// An 8-wide BVH (AVX lanes, or two SSE halves).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh4, Bvh8}, traverse::Watertight};
/// let tris = strahl::scene::icosphere(3).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let (b4, b8) = (Bvh4::from_bvh2(&b2, &tris[..]).unwrap(), Bvh8::from_bvh2(&b2, &tris[..]).unwrap());
/// assert!(b8.nodes().len() < b4.nodes().len()); // wider nodes: fewer of them
/// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
/// assert_eq!(b8.intersect::<Watertight>(&ray), b4.intersect::<Watertight>(&ray));
/// ```
#[cfg(feature = "alloc")]
pub type Bvh8 = BvhWide<f32x8, 8>;

/// The deepest wide tree traversal handles exactly (root = 1); [`BvhWide::from_bvh2`] (and its
/// parallel form) refuses deeper ones. The traversal stack holds `MAX_WIDE_DEPTH * (N - 1) + 1` entries.
///
/// ```
/// use strahl::{Aabb, Vec3, build::{Bvh2, Node}, layout::{Bvh8, CollapseError, MAX_WIDE_DEPTH}};
/// let n = 8 * MAX_WIDE_DEPTH;
/// let tris: Vec<_> = (0..n).map(|i| [Vec3::ZERO, Vec3::X, Vec3::Y].map(|v| v + Vec3::Z * i as f32)).collect();
/// let b = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 1.0, n as f32));
/// // A chain: each interior node has a leaf on the left and the rest of the chain on the right.
/// let mut nodes = Vec::new();
/// for i in 0..n - 1 {
///     nodes.extend([Node::interior(&b, 2 * i + 1), Node::leaf(&b, i, 1)]);
/// }
/// nodes.push(Node::leaf(&b, n - 1, 1));
/// let chain = Bvh2 { nodes, prim_indices: (0..n).collect() };
/// assert_eq!(Bvh8::from_bvh2(&chain, &tris[..]).unwrap_err(), CollapseError::TooDeep);
/// ```
pub const MAX_WIDE_DEPTH: u32 = 72;

#[cfg(feature = "alloc")]
impl<L: Lane, const N: usize> BvhWide<L, N> {
    /// The borrowed view traversal works on.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, wide}};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// assert_eq!(wide::intersect::<Watertight, _, 8>(b8.view(), &ray), b8.intersect::<Watertight>(&ray));
    /// ```
    #[inline]
    pub fn view(&self) -> BvhWideRef<'_, L, N> {
        BvhWideRef {
            nodes: &self.nodes,
            packs: &self.packs,
        }
    }

    /// The nodes; `nodes()[0]` is the root (empty slice for an empty tree).
    ///
    /// ```
    /// # use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh8, LEAF_BIT}};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let interior = b8.nodes().iter().flat_map(|n| n.child).filter(|&c| c & LEAF_BIT == 0).count();
    /// assert_eq!(interior, b8.nodes().len() - 1); // every node but the root is one node's child
    /// ```
    pub fn nodes(&self) -> &[WideNode<L, N>] {
        &self.nodes
    }

    /// The triangle packs the leaves refer to.
    ///
    /// ```
    /// # use strahl::{build::{Bvh2, BuildParams}, layout::Bvh8};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let mut prims: Vec<u32> = b8.packs().iter()
    ///     .flat_map(|p| (0..8).filter(|&i| p.valid >> i & 1 == 1).map(|i| p.prim[i]))
    ///     .collect();
    /// prims.sort();
    /// assert_eq!(prims, (0..320).collect::<Vec<u32>>()); // every triangle in exactly one lane
    /// ```
    pub fn packs(&self) -> &[TriangleLanes<L, N>] {
        &self.packs
    }

    /// Depth of the tree (root = 1, 0 when empty).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams}, geometry::Triangle, layout::{Bvh8, MAX_WIDE_DEPTH}};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// assert!((2..=MAX_WIDE_DEPTH).contains(&b8.depth())); // 320 triangles need more than one node
    /// assert_eq!(Bvh8::from_bvh2(&Bvh2::default(), &[] as &[Triangle]).unwrap().depth(), 0);
    /// ```
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// `true` for a tree without nodes (no valid triangles).
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams}, layout::Bvh4};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::NAN]]; // invalid: left out by the builder
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// assert!(Bvh4::from_bvh2(&b2, &tris[..]).unwrap().is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Bytes of nodes and packs.
    ///
    /// ```
    /// # use strahl::{build::{Bvh2, BuildParams}, layout::Bvh8};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// assert_eq!(b8.memory_bytes(), size_of_val(b8.nodes()) + size_of_val(b8.packs()));
    /// ```
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * core::mem::size_of::<WideNode<L, N>>()
            + self.packs.len() * core::mem::size_of::<TriangleLanes<L, N>>()
    }
}
