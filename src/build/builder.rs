//! [`Builder`]: the builders' working memory, kept between builds.

use super::lbvh::{Runs, WalkStack};
use super::prims::{self, PrimRef};
use super::radix::Item;
use super::treelet::{self, TreeletScratch, TreeletStats};
use super::{
    BuildError, BuildParams, BuildStats, Bvh2, Primitives, Refine, Strategy, TreeletParams, ValidateError, hlbvh, lbvh,
    ploc, sweep, topdown,
};
use alloc::vec::Vec;

/// Reusable working memory for [`Bvh2`] builds.
///
/// A build of `n` primitives needs scratch memory besides the tree itself (at most `64 n` bytes of
/// nodes and `4 n` of indices): `64 n` bytes for the median and binned builders, `72 n` (30-bit,
/// plus up to `16 n` where most codes share their top 8 bits) or `96 n` (63-bit) for the LBVH,
/// about `150 n` for the full sweep. Allocating that afresh costs more than the build on some
/// systems: every new page is zeroed by the kernel on first touch (measured here: 40 ms for
/// 64 MB, against 5 ms to rewrite pages already mapped). A `Builder` keeps its buffers, and
/// [`build_into`](Self::build_into) reuses the output tree's, so that rebuilding a scene every
/// frame touches no new memory. [`Bvh2::build`] is a one-off `Builder`.
///
/// ```
/// use strahl::{build::{Builder, BuildParams, Bvh2}, scene};
/// let mut builder = Builder::new();
/// let mut bvh = Bvh2::default();
/// for frame in 0..3 {
///     let soup = scene::thin_soup(1000, frame);
///     let stats = builder.build_into(&soup[..], &BuildParams::fast(), &mut bvh).unwrap();
///     assert_eq!(stats.primitives, 1000);
///     assert!(bvh.validate(&soup[..]).is_ok());
/// }
/// ```
#[derive(Clone, Debug, Default)]
pub struct Builder {
    /// References to the valid primitives.
    pub(crate) refs: Vec<PrimRef>,
    /// A second buffer of references: the other side of the binned builder's ping-pong
    /// partition, the LBVH's references in Morton order, the sweep's scratch.
    pub(crate) alt: Vec<PrimRef>,
    /// The full sweep's references sorted by centroid on y and z (x uses `alt`).
    pub(crate) sorted: [Vec<PrimRef>; 2],
    /// Radix sort items and their scratch: 30-bit Morton codes or `f32` keys ...
    pub(crate) items32: Vec<Item<u32>>,
    pub(crate) tmp32: Vec<Item<u32>>,
    /// ... and 63-bit Morton codes.
    pub(crate) items64: Vec<Item<u64>>,
    pub(crate) tmp64: Vec<Item<u64>>,
    /// The 30-bit LBVH's `(code << 32) | position` keys of one top-digit bucket, and their
    /// radix-sort scratch.
    pub(crate) packed: Vec<u64>,
    pub(crate) packed_tmp: Vec<u64>,
    /// The bottom-up LBVH's codes, in input order; after its scatter, the sub-codes of a
    /// bucket's ordered runs.
    pub(crate) codes: Vec<u32>,
    /// The full sweep's suffix areas and side flags.
    pub(crate) suffix: Vec<f32>,
    pub(crate) flags: Vec<bool>,
    /// The HLBVH's clusters (sorted ranges) and their boxes and centroid bounds, a range stack,
    /// one reference per cluster and the second buffer for them, the top tree over the clusters,
    /// and the LBVH walk's stack.
    pub(crate) clusters: Vec<[u32; 2]>,
    pub(crate) cluster_bounds: Vec<(super::prims::Box8, super::prims::CBounds)>,
    pub(crate) ranges: Vec<[u32; 2]>,
    pub(crate) crefs: Vec<PrimRef>,
    pub(crate) calt: Vec<PrimRef>,
    pub(crate) top: Bvh2,
    /// `Strategy::HlbvhSah`'s parts of pruned mini-trees (node indices), and the node array the
    /// tree is laid out in (swapped with the output's, so both stay allocated between builds).
    pub(crate) items: Vec<[u32; 2]>,
    pub(crate) parts: Vec<(u32, u32, u32)>,
    pub(crate) forest: Vec<crate::traverse::Node>,
    pub(crate) walk: WalkStack,
    /// The Morton builders' ordered runs of equal codes and their sub-codes.
    pub(crate) runs: Runs,
    /// Treelet restructuring's per-node state.
    pub(crate) treelet: TreeletScratch,
    /// Reinsertion's per-node state.
    pub(crate) reinsert: super::reinsert::ReinsertScratch,
    /// The parallel build's per-worker arrays (`std`).
    #[cfg(feature = "std")]
    pub(crate) par: Vec<super::topdown::ParScratch>,
    /// The parallel LBVH's nodes, one array per top-digit bucket (`std`).
    #[cfg(feature = "std")]
    pub(crate) bucket_nodes: Vec<Vec<crate::traverse::Node>>,
}

/// Builds of at most this many (valid) primitives run on the calling thread.
const PAR_MIN: usize = 8192;

/// The most threads a parallel build or collapse starts ([`Builder::build_into_par`],
/// [`Bvh2::build_par`], `BvhWide::from_bvh2_par`); larger requests are capped (`std`).
///
/// ```
/// use strahl::{build::{BuildParams, Bvh2, MAX_THREADS}, scene};
/// let soup = scene::thin_soup(10_000, 1);
/// // Asking for more threads than MAX_THREADS is allowed: the build uses at most that many.
/// let (bvh, _) = Bvh2::build_par(&soup[..], &BuildParams::fast(), MAX_THREADS + 1).unwrap();
/// assert!(bvh.validate(&soup[..]).is_ok());
/// ```
#[cfg(feature = "std")]
pub const MAX_THREADS: usize = 256;

/// What a builder reports besides the tree.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Counters {
    pub leaves: u32,
    pub max_depth: u32,
    pub forced_splits: u32,
}

impl Builder {
    /// A builder without memory yet (it grows on the first build and is kept).
    ///
    /// ```
    /// use strahl::build::{Builder, BuildParams, Bvh2};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (mine, _) = Builder::new().build(&tris[..], &BuildParams::default()).unwrap();
    /// let (once, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// assert_eq!(mine, once); // `Bvh2::build` is a one-off builder: the same tree
    /// ```
    pub fn new() -> Self {
        Self::default()
    }

    /// Builds a tree over `prims` (see [`Bvh2::build`]).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Builder, BuildParams}, traverse::{Watertight, intersect_brute_force}};
    /// let mut builder = Builder::new(); // one builder, scenes of several sizes
    /// for n in [1, 3] {
    ///     let tris = strahl::scene::icosphere(n).to_soup();
    ///     let (bvh, stats) = builder.build(&tris[..], &BuildParams::fast()).unwrap();
    ///     assert_eq!(stats.primitives as usize, tris.len());
    ///     let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    ///     let brute = intersect_brute_force::<Watertight, _>(&tris[..], &ray);
    ///     assert_eq!(bvh.intersect::<Watertight, _>(&tris[..], &ray), brute);
    /// }
    /// ```
    pub fn build<P: Primitives + ?Sized>(
        &mut self,
        prims: &P,
        params: &BuildParams,
    ) -> Result<(Bvh2, BuildStats), BuildError> {
        let mut bvh = Bvh2::default();
        let stats = self.build_into(prims, params, &mut bvh)?;
        Ok((bvh, stats))
    }

    /// Builds a tree over `prims` into `out`, replacing its contents and reusing its memory.
    /// On error `out` is left unchanged.
    ///
    /// ```
    /// use strahl::build::{Builder, BuildParams, Bvh2};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (mut builder, mut bvh) = (Builder::new(), Bvh2::default());
    /// let stats = builder.build_into(&tris[..], &BuildParams::default(), &mut bvh).unwrap();
    /// assert_eq!(stats.nodes as usize, bvh.nodes.len());
    /// let before = bvh.clone();
    /// let bad = BuildParams { bins: 2, ..BuildParams::default() };
    /// assert!(builder.build_into(&tris[..], &bad, &mut bvh).is_err());
    /// assert_eq!(bvh, before); // the failed build left the tree alone
    /// ```
    pub fn build_into<P: Primitives + ?Sized>(
        &mut self,
        prims: &P,
        params: &BuildParams,
        out: &mut Bvh2,
    ) -> Result<BuildStats, BuildError> {
        params.check()?;
        let info = prims::prepare(prims, &mut self.refs)?;
        self.build_prepared(&info, params, out, 1)
    }

    /// [`build_into`](Self::build_into) on up to `threads` threads (`std`). The tree is the one
    /// the single-threaded build makes (the same nodes, boxes and leaves, so the same SAH cost
    /// and the same hits), numbered in another order; for a given `threads`, every run makes
    /// the same bytes.
    ///
    /// Parallel: the checks of the primitives' boxes (in chunks); the median and binned SAH
    /// builders ([`Strategy::Median`], [`Strategy::BinnedSah`]: the top of the tree in rounds,
    /// each splitting every large task once, the round's tasks side by side, or, while there are
    /// at most half as many tasks as threads, each binned task with all threads, its references
    /// in chunks;
    /// then the remaining subtrees side by side), the LBVH ([`Strategy::Lbvh`] with 30-bit codes:
    /// the Morton codes and the top-digit scatter in chunks side by side, then each top-digit
    /// bucket's subtree, which the joins across buckets put together on the calling thread; the
    /// same nodes in the same order as the single-threaded build), PLOC's Morton sort
    /// ([`Strategy::Ploc`], 30-bit codes; its agglomeration stays on the calling thread) and the
    /// HLBVH ([`Strategy::Hlbvh`],
    /// [`Strategy::HlbvhSah`]: with 30-bit codes, the Morton codes, the top-digit scatter and the
    /// bucket sorts in chunks side by side; the SAH mini-trees side by side), and the first
    /// round of rotations ([`Refine::Rotations`]: subtrees side by side, then the nodes above
    /// them). The other strategies, treelet refinement and reinsertion run on the calling thread. Up to
    /// 8,192 (valid) primitives the build is single-threaded; `threads` is taken as at least 1 and
    /// at most [`MAX_THREADS`].
    /// The primitives are read from several threads, so they must be `Sync`.
    ///
    /// ```
    /// use strahl::{build::{Builder, BuildParams, Bvh2}, scene};
    /// let soup = scene::thin_soup(50_000, 1);
    /// let mut builder = Builder::new();
    /// let (one, _) = builder.build(&soup[..], &BuildParams::fast()).unwrap();
    /// let mut two = Bvh2::default();
    /// builder.build_into_par(&soup[..], &BuildParams::fast(), &mut two, 2).unwrap();
    /// assert!(two.validate(&soup[..]).is_ok());
    /// assert_eq!(one.sah_cost(1.0, 1.0), two.sah_cost(1.0, 1.0));
    /// ```
    #[cfg(feature = "std")]
    pub fn build_into_par<P: Primitives + Sync + ?Sized>(
        &mut self,
        prims: &P,
        params: &BuildParams,
        out: &mut Bvh2,
        threads: usize,
    ) -> Result<BuildStats, BuildError> {
        let threads = threads.clamp(1, MAX_THREADS);
        params.check()?;
        let info = prims::prepare_par(prims, &mut self.refs, threads)?;
        self.build_prepared(&info, params, out, threads)
    }

    /// The build over the references [`prims::prepare`] left in `self.refs`.
    fn build_prepared(
        &mut self,
        info: &prims::PrepInfo,
        params: &BuildParams,
        out: &mut Bvh2,
        threads: usize,
    ) -> Result<BuildStats, BuildError> {
        out.nodes.clear();
        out.prim_indices.clear();
        let n = self.refs.len();
        // Small builds stay on this thread (the threads would cost more than they save).
        let threads = if n <= PAR_MIN { 1 } else { threads };
        let c = if n == 0 {
            Counters::default()
        } else {
            match params.strategy {
                Strategy::Median | Strategy::BinnedSah => topdown::build(self, info, params, out, threads),
                Strategy::SweepSah => sweep::build(self, info, params, out),
                Strategy::Lbvh => lbvh::build(self, info, params, out, threads),
                Strategy::Hlbvh | Strategy::HlbvhSah => hlbvh::build(self, info, params, out, threads),
                Strategy::Ploc => ploc::build(self, info, params, out, threads),
            }
        };
        debug_assert_eq!(out.prim_indices.len(), n);
        let mut stats = BuildStats {
            primitives: n as u32,
            invalid: info.invalid,
            nodes: out.nodes.len() as u32,
            leaves: c.leaves,
            max_depth: c.max_depth,
            forced_splits: c.forced_splits,
            restructured: 0,
        };
        if let (Refine::Rotations(r), true) = (params.refine, n > 0) {
            // NOTE: a tree just built is well formed; the pass cannot fail on it.
            if let Ok(r) = super::rotate::optimize_par(out, r, params.max_depth, threads) {
                stats.max_depth = r.max_depth;
                stats.restructured = r.rotations;
            }
        }
        if let (Refine::Treelets(t) | Refine::AgglomerativeTreelets(t), true) = (params.refine, n > 0) {
            let agglomerative = matches!(params.refine, Refine::AgglomerativeTreelets(_));
            // NOTE: a tree just built is well formed; the pass cannot fail on it.
            if let Ok(r) = treelet::optimize_with(out, &t, agglomerative, params.max_depth, &mut self.treelet, threads)
            {
                stats.max_depth = r.max_depth;
                stats.restructured = r.restructured;
            }
        }
        if let (Refine::Reinsertion(r), true) = (params.refine, n > 0) {
            // NOTE: a tree just built is well formed; the pass cannot fail on it.
            if let Ok(r) = super::reinsert::optimize(out, &r, params.max_depth, &mut self.reinsert) {
                stats.max_depth = r.max_depth;
                stats.restructured = r.moved;
                stats.nodes = out.nodes.len() as u32;
            }
        }
        Ok(stats)
    }

    /// [`Bvh2::optimize_treelets`] with this builder's memory (kept for the next call).
    ///
    /// ```
    /// use strahl::{build::{Builder, BuildParams, TreeletParams}, scene};
    /// let soup = scene::clustered_soup(3000, 5, 1);
    /// let mut builder = Builder::new();
    /// let (mut bvh, _) = builder.build(&soup[..], &BuildParams::fast()).unwrap();
    /// let before = bvh.sah_cost(1.0, 1.0);
    /// let p = TreeletParams { leaves: 5, rounds: 2, ..TreeletParams::default() };
    /// builder.optimize_treelets(&mut bvh, &p, 64).unwrap();
    /// assert!(bvh.sah_cost(1.0, 1.0) <= before);
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// ```
    pub fn optimize_treelets(
        &mut self,
        bvh: &mut Bvh2,
        params: &TreeletParams,
        max_depth: u32,
    ) -> Result<TreeletStats, ValidateError> {
        let max_depth = max_depth.min(crate::traverse::MAX_DEPTH);
        treelet::optimize(bvh, params, max_depth, &mut self.treelet)
    }

    /// [`Bvh2::optimize_treelets_agglomerative`] with this builder's memory (kept for the next
    /// call).
    ///
    /// ```
    /// use strahl::{build::{Builder, BuildParams, TreeletParams}, scene};
    /// let soup = scene::clustered_soup(3000, 5, 1);
    /// let mut builder = Builder::new();
    /// let (mut bvh, _) = builder.build(&soup[..], &BuildParams::fastest()).unwrap();
    /// let before = bvh.sah_cost(1.0, 1.0);
    /// builder.optimize_treelets_agglomerative(&mut bvh, &TreeletParams::agglomerative(), 64).unwrap();
    /// assert!(bvh.sah_cost(1.0, 1.0) < before);
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// ```
    pub fn optimize_treelets_agglomerative(
        &mut self,
        bvh: &mut Bvh2,
        params: &TreeletParams,
        max_depth: u32,
    ) -> Result<TreeletStats, ValidateError> {
        let max_depth = max_depth.min(crate::traverse::MAX_DEPTH);
        treelet::optimize_with(bvh, params, true, max_depth, &mut self.treelet, 1)
    }

    /// [`Bvh2::optimize_reinsertion`] with this builder's memory (kept for the next call).
    ///
    /// ```
    /// use strahl::{build::{Builder, BuildParams, ReinsertParams}, scene};
    /// let soup = scene::clustered_soup(3000, 5, 1);
    /// let mut builder = Builder::new();
    /// let (mut bvh, _) = builder.build(&soup[..], &BuildParams::fast()).unwrap();
    /// let before = bvh.sah_cost(1.0, 1.0);
    /// builder.optimize_reinsertion(&mut bvh, &ReinsertParams::default(), 64).unwrap();
    /// assert!(bvh.sah_cost(1.0, 1.0) <= before);
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// ```
    pub fn optimize_reinsertion(
        &mut self,
        bvh: &mut Bvh2,
        params: &super::ReinsertParams,
        max_depth: u32,
    ) -> Result<super::ReinsertStats, ValidateError> {
        let max_depth = max_depth.min(crate::traverse::MAX_DEPTH);
        super::reinsert::optimize(bvh, params, max_depth, &mut self.reinsert)
    }
}
