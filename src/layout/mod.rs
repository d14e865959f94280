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
//! rebuild on 1M triangles, at no cost in trace time for small motion (README, "Refitting
//! animated geometry").

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

#[cfg(feature = "alloc")]
mod collapse;
#[cfg(feature = "alloc")]
#[cfg(feature = "std")]
mod pages;
#[cfg(feature = "alloc")]
mod refit;

use crate::intersect::{AabbLanes, TriangleLanes};
use crate::math::{Lane, f32x4, f32x8};
#[cfg(feature = "alloc")]
use alloc::vec::Vec;

#[cfg(feature = "alloc")]
pub use collapse::CollapseError;

/// Marks a leaf child code.
pub const LEAF_BIT: u32 = 1 << 31;
/// An unused child slot.
pub const EMPTY_CHILD: u32 = u32::MAX;
/// Most packs (of `N` triangles) one leaf child refers to.
pub const MAX_LEAF_PACKS: usize = 16;

/// Decodes a leaf child code into `(first pack, number of packs)`.
#[inline(always)]
pub const fn leaf_packs(code: u32) -> (usize, usize) {
    (((code & !LEAF_BIT) >> 4) as usize, (code & 15) as usize + 1)
}

/// One node of an `N`-wide BVH: `N` child boxes in SoA lanes and `N` child codes.
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
pub type Node4 = WideNode<f32x4, 4>;
/// An 8-wide node (256 bytes).
pub type Node8 = WideNode<f32x8, 8>;

const _: () = assert!(core::mem::size_of::<Node4>() == 128);
const _: () = assert!(core::mem::size_of::<Node8>() == 256);
const _: () = assert!(core::mem::size_of::<TriangleLanes<f32x8, 8>>() == 8 * 4 * 9 + 8 * 4 + 32);

impl<L: Lane, const N: usize> WideNode<L, N> {
    /// A node with every slot empty.
    pub fn empty() -> Self {
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
/// Nothing is checked on construction: traversal never panics and always terminates on any
/// slices (codes out of range are skipped, a tree deeper than [`MAX_WIDE_DEPTH`] loses the nodes
/// that do not fit on the stack). Trees from [`BvhWide::from_bvh2`] (and its parallel form) are
/// always within bounds.
#[derive(Clone, Copy, Debug)]
pub struct BvhWideRef<'a, L, const N: usize> {
    /// Nodes; the root is `nodes[0]`.
    pub nodes: &'a [WideNode<L, N>],
    /// Triangle packs referenced by leaf codes.
    pub packs: &'a [TriangleLanes<L, N>],
}

/// A borrowed [`Bvh4`].
pub type Bvh4Ref<'a> = BvhWideRef<'a, f32x4, 4>;
/// A borrowed [`Bvh8`].
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
#[cfg(feature = "alloc")]
#[derive(Clone, Debug)]
pub struct BvhWide<L, const N: usize> {
    pub(crate) nodes: Vec<WideNode<L, N>>,
    pub(crate) packs: Vec<TriangleLanes<L, N>>,
    pub(crate) depth: u32,
}

/// A 4-wide BVH (SSE / NEON lanes).
#[cfg(feature = "alloc")]
pub type Bvh4 = BvhWide<f32x4, 4>;
/// An 8-wide BVH (AVX lanes, or two SSE halves).
#[cfg(feature = "alloc")]
pub type Bvh8 = BvhWide<f32x8, 8>;

/// The deepest wide tree traversal handles exactly (root = 1); [`BvhWide::from_bvh2`] (and its
/// parallel form) refuses deeper ones. The traversal stack holds `MAX_WIDE_DEPTH * (N - 1) + 1` entries.
pub const MAX_WIDE_DEPTH: u32 = 72;

#[cfg(feature = "alloc")]
impl<L: Lane, const N: usize> BvhWide<L, N> {
    /// The borrowed view traversal works on.
    #[inline]
    pub fn view(&self) -> BvhWideRef<'_, L, N> {
        BvhWideRef {
            nodes: &self.nodes,
            packs: &self.packs,
        }
    }

    /// The nodes; `nodes()[0]` is the root (empty slice for an empty tree).
    pub fn nodes(&self) -> &[WideNode<L, N>] {
        &self.nodes
    }

    /// The triangle packs the leaves refer to.
    pub fn packs(&self) -> &[TriangleLanes<L, N>] {
        &self.packs
    }

    /// Depth of the tree (root = 1, 0 when empty).
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// `true` for a tree without nodes (no valid triangles).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Bytes of nodes and packs.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * core::mem::size_of::<WideNode<L, N>>()
            + self.packs.len() * core::mem::size_of::<TriangleLanes<L, N>>()
    }
}
