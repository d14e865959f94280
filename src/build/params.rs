//! Every tunable of the BVH2 builders in one struct, with presets from fastest build to best tree.

use super::BuildError;
use crate::traverse::MAX_DEPTH;

/// How the builder chooses splits.
///
/// ```
/// use strahl::build::{BuildParams, Bvh2, Strategy::*};
/// let tris = strahl::scene::icosphere(3).to_soup(); // 1,280 triangles
/// for strategy in [Median, BinnedSah, SweepSah, Lbvh, Hlbvh, HlbvhSah, Ploc] {
///     let (bvh, _) = Bvh2::build(&tris[..], &BuildParams { strategy, ..BuildParams::default() }).unwrap();
///     let s = bvh.validate(&tris[..]).unwrap(); // every strategy: a valid tree of every triangle
///     assert_eq!((s.primitives, s.nodes), (1280, 2 * s.leaves - 1));
///     // The SAH cost of any valid tree (C_T = C_I = 1) lies between the root's share (1) and
///     // every node counted in full. Which strategy gives the lowest is measured, not promised:
///     // they are all greedy (see `BuildParams::quality` and `high`).
///     let cost = bvh.sah_cost(1.0, 1.0);
///     assert!(1.0 <= cost && cost <= (s.nodes - s.leaves + s.primitives) as f32, "{strategy:?}");
/// }
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Strategy {
    /// Top-down, object median on the longest axis of the centroid bounds: half the primitives
    /// (by centroid order) go to each side. Fast, SAH-blind; the baseline.
    Median,
    /// Top-down, binned SAH (Wald 2007): centroids projected into
    /// [`bins`](BuildParams::bins) bins per axis, the best of the `bins - 1` planes on all three
    /// axes.
    BinnedSah,
    /// Top-down, full-sweep SAH: every primitive boundary in centroid order on all three axes,
    /// with prefix and suffix areas. The primitives are sorted once per axis up front (three
    /// radix sorts) and kept sorted by stable partitioning, so each level costs O(n).
    SweepSah,
    /// Linear BVH (Lauterbach 2009, Karras 2012): Morton codes of the centroids, one radix sort,
    /// splits where the highest differing bit changes. No SAH.
    Lbvh,
    /// Hierarchical LBVH (Pantaleoni and Luebke 2010; Garanzha et al. 2011): the sorted Morton
    /// codes are cut into clusters of at most [`cluster_size`](BuildParams::cluster_size)
    /// primitives (runs of equal top bits, as many bits as a run needs to be that small), each
    /// cluster is built as an LBVH bottom, and binned SAH ([`bins`](BuildParams::bins),
    /// [`bin_axes`](BuildParams::bin_axes)) over the clusters' boxes builds the top. Nearly the
    /// speed of [`Lbvh`](Self::Lbvh), a better tree.
    Hlbvh,
    /// Morton clusters with SAH mini-trees: the clusters and the binned-SAH top of
    /// [`Hlbvh`](Self::Hlbvh), but each cluster built by the binned SAH builder
    /// ([`bins`](BuildParams::bins), [`bin_axes`](BuildParams::bin_axes), the SAH leaf rule)
    /// instead of as an LBVH, as Bonsai builds its mini-trees (Ganestam et al., "Bonsai: Rapid
    /// Bounding Volume Hierarchy Generation using Mini Trees", 2015). The Morton sort replaces
    /// the top-down builder's top levels, where every level streams all references through
    /// memory; within a cluster of up to [`cluster_size`](BuildParams::cluster_size) (1,024 in
    /// [`hybrid_sah`](BuildParams::hybrid_sah)) references everything is in cache. Where the
    /// clusters' boxes differ much in size (the largest more than 4 times the median's area: a
    /// multi-scale scene), the mini-trees are built first and pruned as Bonsai prunes them: their
    /// largest nodes opened (down to a tenth of the mean cluster's area, at most 8 parts per
    /// cluster) and the top built over the parts, so that a cluster's large and small primitives
    /// can join their like from other clusters. See [`BuildParams::hybrid_sah`].
    HlbvhSah,
    /// PLOC (Meister and Bittner 2018) with a search radius of one: the references sorted by
    /// Morton code, then clusters merged bottom-up with the neighbour along the curve whose union
    /// has the smaller surface area, where the two prefer each other. One-primitive leaves. About
    /// twice the build time of [`Lbvh`](Self::Lbvh), a markedly better tree. See
    /// [`BuildParams::ploc`].
    Ploc,
}

/// A pass that improves a finished tree, after any [`Strategy`] ([`BuildParams::refine`]).
///
/// ```
/// use strahl::build::{BuildParams, Bvh2, Refine};
/// let tris = strahl::scene::thin_soup(5_000, 1);
/// let p = BuildParams::fastest();
/// let (plain, _) = Bvh2::build(&tris[..], &p).unwrap();
/// let (rotated, stats) = Bvh2::build(&tris[..], &BuildParams { refine: Refine::Rotations(2), ..p }).unwrap();
/// assert!(stats.restructured > 0);
/// assert!(rotated.sah_cost(1.0, 1.0) <= plain.sah_cost(1.0, 1.0)); // never worse by the SAH
/// assert!(BuildParams { refine: Refine::Rotations(0), ..p }.check().is_err()); // rounds: 1 ..= 64
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Refine {
    /// No pass: the tree as the strategy built it.
    None,
    /// Treelet restructuring (Karras and Aila 2013), see
    /// [`Bvh2::optimize_treelets`](super::Bvh2::optimize_treelets).
    Treelets(TreeletParams),
    /// Up to this many rounds (`1 ..= 64`) of tree rotations (Kensler 2008), see
    /// [`Bvh2::optimize_rotations`](super::Bvh2::optimize_rotations): cheap, local, and never
    /// worse by the SAH.
    Rotations(u32),
    /// Reinsertion (Bittner et al. 2013), see
    /// [`Bvh2::optimize_reinsertion`](super::Bvh2::optimize_reinsertion): subtrees moved to where
    /// they cost least; never worse by the SAH.
    Reinsertion(super::ReinsertParams),
    /// Agglomerative treelet restructuring (ATRBVH, Domingues and Pedrini 2015), see
    /// [`Bvh2::optimize_treelets_agglomerative`](super::Bvh2::optimize_treelets_agglomerative):
    /// larger treelets (up to 16 leaves) for less work than [`Treelets`](Self::Treelets)' exact
    /// search; never worse by the SAH.
    AgglomerativeTreelets(TreeletParams),
}

/// The knobs of treelet restructuring ([`Refine::Treelets`],
/// [`Bvh2::optimize_treelets`](super::Bvh2::optimize_treelets)).
///
/// Cost: one treelet is about `3^leaves / 2` steps of a dynamic program (1,100 for 7 leaves,
/// 120 for 5), and one is formed at every interior node with at least `min_prims` primitives
/// below it, once per round. Karras and Aila use 7 leaves, `gamma` = 7 and three rounds on a GPU;
/// on one core that costs more than the build it refines, hence the default (measured in the
/// [module docs](super#measured)).
///
/// ```
/// use strahl::build::{BuildParams, Refine, TreeletParams};
/// let t = TreeletParams { rounds: 2, ..TreeletParams::default() };
/// let p = BuildParams { refine: Refine::Treelets(t), ..BuildParams::fastest() };
/// assert!(p.check().is_ok());
/// let bad = TreeletParams { leaves: 9, ..t };
/// assert!(BuildParams { refine: Refine::Treelets(bad), ..p }.check().is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TreeletParams {
    /// Leaves per treelet, in `3 ..= 8` (Karras: 7); `3 ..= 16` for the agglomerative pass
    /// (Domingues and Pedrini: 9).
    pub leaves: u32,
    /// Treelets are formed only at nodes with at least this many primitives below them
    /// (Karras' `gamma`; 1: at every interior node). `>= 1`.
    pub min_prims: u32,
    /// Bottom-up passes over the tree, in `1 ..= 16` (Karras: 3).
    pub rounds: u32,
}

impl TreeletParams {
    /// The default: 7 leaves, every node with at least 2 primitives, one round.
    ///
    /// ```
    /// use strahl::build::{BuildParams, Refine, TreeletParams};
    /// const T: TreeletParams = TreeletParams::new(); // usable in constants
    /// assert_eq!((T.leaves, T.min_prims, T.rounds), (7, 2, 1));
    /// assert_eq!(T, TreeletParams::default());
    /// assert!(BuildParams { refine: Refine::Treelets(T), ..BuildParams::default() }.check().is_ok());
    /// ```
    pub const fn new() -> Self {
        Self {
            leaves: 7,
            min_prims: 2,
            rounds: 1,
        }
    }
}

impl TreeletParams {
    /// The agglomerative pass's knobs ([`Refine::AgglomerativeTreelets`]): 9 leaves (Domingues
    /// and Pedrini's choice), every node with at least 2 primitives, two rounds.
    ///
    /// ```
    /// use strahl::build::{BuildParams, Bvh2, Refine, TreeletParams};
    /// let t = TreeletParams::agglomerative();
    /// assert_eq!((t.leaves, t.min_prims, t.rounds), (9, 2, 2));
    /// let p = BuildParams { refine: Refine::AgglomerativeTreelets(t), ..BuildParams::fastest() };
    /// assert!(p.check().is_ok());
    /// assert!(BuildParams { refine: Refine::Treelets(t), ..p }.check().is_err()); // 9 > 8
    /// let soup = strahl::scene::thin_soup(2_000, 3);
    /// let (plain, _) = Bvh2::build(&soup[..], &BuildParams::fastest()).unwrap();
    /// let (better, _) = Bvh2::build(&soup[..], &p).unwrap();
    /// assert!(better.sah_cost(1.0, 1.0) < plain.sah_cost(1.0, 1.0));
    /// ```
    pub const fn agglomerative() -> Self {
        Self {
            leaves: 9,
            min_prims: 2,
            rounds: 2,
        }
    }
}

impl Default for TreeletParams {
    /// [`TreeletParams::new`].
    fn default() -> Self {
        Self::new()
    }
}

/// Which axes [`Strategy::BinnedSah`] bins.
///
/// ```
/// use strahl::build::{BinAxes, BuildParams, Bvh2};
/// assert_eq!(BuildParams::fast().bin_axes, BinAxes::Longest);
/// assert_eq!(BuildParams::balanced().bin_axes, BinAxes::All);
/// assert_eq!(BuildParams::hybrid_sah().bin_axes, BinAxes::AllButSmall);
/// let tris = strahl::scene::thin_soup(2_000, 3);
/// for bin_axes in [BinAxes::All, BinAxes::Longest, BinAxes::AllButSmall] {
///     let (bvh, _) = Bvh2::build(&tris[..], &BuildParams { bin_axes, ..BuildParams::fast() }).unwrap();
///     assert!(bvh.validate(&tris[..]).is_ok());
/// }
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BinAxes {
    /// All three: the best plane of `3 (bins - 1)` candidates.
    All,
    /// Only the axis of largest centroid extent, as in Wald 2007: a third of the binning work,
    /// a slightly worse tree (measured in the [module docs](super#measured)).
    Longest,
    /// All three where a range is binned; only the longest in the exact sweep of small ranges
    /// (at most 16 references), where the three sweeps cost most of the build. Between the
    /// other two in speed and tree quality (see [`BuildParams::hybrid_sah`]).
    AllButSmall,
}

/// Bits of the Morton codes an [`Lbvh`](Strategy::Lbvh) build sorts by.
///
/// ```
/// use strahl::{Vec3, build::{BuildParams, Bvh2, MortonBits}};
/// // 1,000 clusters of 4 tiny triangles in a unit cube: a 30-bit cell (1/1024 wide) holds a
/// // cluster, 63-bit cells (1/2^21) tell its triangles apart.
/// # let mut rng = strahl::scene::Rng::new(1);
/// let tris: Vec<_> = (0..4000).map(|i| {
///     let mut r = strahl::scene::Rng::new(i / 4);
///     let c = Vec3::new(r.f32(), r.f32(), r.f32());
///     let p = c + Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 1e-5;
///     [p, p + Vec3::X * 1e-6, p + Vec3::Y * 1e-6]
/// }).collect();
/// let p = BuildParams::fastest();
/// assert_eq!(p.morton_bits, MortonBits::Bits30);
/// let leaves = |morton_bits| Bvh2::build(&tris[..], &BuildParams { morton_bits, ..p }).unwrap().1.leaves;
/// assert!(leaves(MortonBits::Bits63) > leaves(MortonBits::Bits30)); // equal codes: leaves of up to 4
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MortonBits {
    /// 30-bit codes, 10 bits (1,024 cells) per axis: fewer radix passes (3), coarser cells.
    Bits30,
    /// 63-bit codes, 21 bits per axis: for scenes with detail at very different scales (more
    /// passes: 6).
    Bits63,
}

/// The Morton grid of the [`Lbvh`](Strategy::Lbvh), [`Hlbvh`](Strategy::Hlbvh),
/// [`HlbvhSah`](Strategy::HlbvhSah) and [`Ploc`](Strategy::Ploc) builders.
///
/// ```
/// use strahl::{build::{BuildParams, Bvh2, MortonCells}, scene};
/// // A terrain: centroid bounds about 1 x 0.2 x 1.
/// let flat = scene::terrain(32, 1).to_soup();
/// let p = BuildParams::fastest();
/// assert_eq!(p.morton_cells, MortonCells::Extended);
/// let classic = BuildParams { morton_cells: MortonCells::Normalized, ..p };
/// let (a, _) = Bvh2::build(&flat[..], &p).unwrap();
/// let (b, _) = Bvh2::build(&flat[..], &classic).unwrap();
/// // Measured on this scene (the builds are deterministic), not promised for every scene:
/// assert!(a.sah_cost(1.0, 1.0) < b.sah_cost(1.0, 1.0));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MortonCells {
    /// Near-cubic cells ([`MortonQuantizer::new_extended`](crate::geometry::morton::MortonQuantizer::new_extended),
    /// Vinkler et al. 2017): an axis `d` halvings shorter than the longest gets cells `2^d` times
    /// as long. The same codes as [`Normalized`](Self::Normalized) where the centroid bounds'
    /// extents are within `sqrt(2)` of each other; much better trees on flat scenes. Every preset.
    Extended,
    /// `2^bits` cells on every axis ([`MortonQuantizer::new`](crate::geometry::morton::MortonQuantizer::new)),
    /// the classic LBVH grid: cells as flat as the scene's box.
    Normalized,
}

/// All knobs of the BVH2 builders. Start from a preset and change fields as needed.
///
/// | preset | strategy | bins | leaf size | builds | tree |
/// |---|---|---|---|---|---|
/// | [`fastest`](Self::fastest) | LBVH, 30-bit | | 2, up to 4 on equal codes (and kept sub-codes) | fastest | worst SAH |
/// | [`fast`](Self::fast) | binned SAH, longest axis, large nodes from a sample | 8 | 1 ..= 8 | fast | good |
/// | [`balanced`](Self::balanced) (= `default()`) | binned SAH, all axes, nodes of 32K+ from a sample | 16 | 1 ..= 8 | medium | better |
/// | [`high`](Self::high) | binned SAH, all axes, + one round of rotations | 64 | 1 ..= 8 | medium-slow | best: at or below `quality` on the 1M scenes |
/// | [`quality`](Self::quality) | full-sweep SAH | | 1 ..= 8 | slowest | the exact greedy SAH split |
/// | [`median`](Self::median) | object median | | 1 ..= 4 | fast | SAH-blind baseline |
/// | [`hybrid`](Self::hybrid) | HLBVH (clusters of 32) + treelets of 7 | 16 (top) | 1 ..= 4 (SAH collapse) | slow on one core | within 3 to 5% of `quality` |
/// | [`hybrid_sah`](Self::hybrid_sah) | Morton clusters of 1,024 + binned-SAH mini-trees and top | 8 | 1 ..= 8 | faster than `fast` | within 3% of `quality` on the soup, 8 to 11% on structured scenes |
///
/// Measured throughput and SAH cost of each are in the [module docs](super#measured).
///
/// # The SAH and termination
/// A split of a node with box area `A` into children with `N_l`, `N_r` primitives and box areas
/// `A_l`, `A_r` costs `C_T + C_I (N_l A_l + N_r A_r) / A`; making the node a leaf costs `C_I N`.
/// A node with `N <= min_leaf_size` primitives is always a leaf; one with
/// `N > max_leaf_size` is always split; in between the cheaper option wins (SAH termination,
/// for the SAH strategies and the median alike). LBVH does not evaluate the SAH: it splits down
/// to `min_leaf_size`, or to `max_leaf_size` where the Morton codes of a range are all equal.
/// HLBVH bottoms split as the LBVH does, then collapse bottom-up every subtree of at most
/// `max_leaf_size` primitives whose leaf would cost no more (`C_I N A <= C_T A + children`). The
/// top of an HLBVH splits down to single clusters; [`refine`](Self::refine) never changes leaves.
///
/// ```
/// use strahl::build::{BuildParams, Strategy};
/// let p = BuildParams { bins: 16, ..BuildParams::fast() };
/// assert_eq!(p.strategy, Strategy::BinnedSah);
/// assert!(p.check().is_ok());
/// assert!(BuildParams { bins: 3, ..p }.check().is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildParams {
    /// How splits are chosen.
    pub strategy: Strategy,
    /// `C_T`: cost of visiting an interior node (box tests), relative to `C_I`. Finite, `>= 0`.
    pub traversal_cost: f32,
    /// `C_I`: cost of one primitive test. Finite, `> 0`.
    pub intersection_cost: f32,
    /// Nodes with at most this many primitives become leaves. `>= 1`.
    pub min_leaf_size: u32,
    /// Nodes with more primitives than this are always split. `>= min_leaf_size`, `<= 2^16`.
    pub max_leaf_size: u32,
    /// Bins per axis of [`Strategy::BinnedSah`], in [`MIN_BINS`]`..=`[`MAX_BINS`].
    pub bins: u32,
    /// Axes binned by [`Strategy::BinnedSah`].
    pub bin_axes: BinAxes,
    /// Sampled binning of large nodes ([`Strategy::BinnedSah`], and the binned-SAH tops and
    /// mini-trees of the HLBVH strategies): a node of at least `2 * bin_sample` references that
    /// may not be a leaf bins one of every `k` of them, `k = N / bin_sample`, at a hashed offset in
    /// each run of `k` (so `bin_sample` to about `1.5 * bin_sample` references), and the pass that
    /// partitions all `N` by the plane found
    /// measures the children's counts and boxes. The top levels of a large build, which wait on
    /// memory, then read the references once per level instead of twice. The plane is the
    /// sample's cheapest, not always the node's; where no plane of the sample has references on
    /// both sides, every reference is binned. 4,096 in [`fast`](Self::fast), 16,384 in
    /// [`balanced`](Self::balanced), `0` in the other presets: every reference binned, as Wald
    /// 2007 does. `0` or at least [`MIN_BIN_SAMPLE`].
    pub bin_sample: u32,
    /// Code width of [`Strategy::Lbvh`] (and of the other Morton-code builders).
    pub morton_bits: MortonBits,
    /// Cell shape of the Morton grid of the Morton-code builders.
    pub morton_cells: MortonCells,
    /// The deepest tree the builder may make (root = depth 1), in `34 ..=`
    /// [`MAX_DEPTH`](crate::traverse::MAX_DEPTH) (at least 34 so that a balanced tree over
    /// `2^31` primitives fits). Where a split would make a subtree that cannot be finished within
    /// this depth, the builder splits that node at its object median instead (a balanced subtree
    /// needs only `ceil(log2 N)` more levels); [`BuildStats::forced_splits`](super::BuildStats)
    /// counts how often.
    pub max_depth: u32,
    /// Largest cluster of [`Strategy::Hlbvh`]: a run of sorted Morton codes with more
    /// primitives is cut where its highest differing bit changes (the LBVH split), so clusters
    /// are runs of equal top bits, as many bits as it takes. In `1 ..=`
    /// [`MAX_CLUSTER_SIZE`]; 1 makes the build binned SAH over single primitives. Smaller
    /// clusters: more of the tree is SAH, slower. (Capped further where the depth bound needs
    /// it: clusters of at most `2^(max_depth - 1 - ceil(log2 n))`.)
    pub cluster_size: u32,
    /// A pass over the finished tree ([`Refine::None`] in every preset but
    /// [`hybrid`](Self::hybrid) and [`high`](Self::high)).
    pub refine: Refine,
}

/// Largest accepted [`BuildParams::cluster_size`].
///
/// ```
/// use strahl::build::{BuildParams, MAX_CLUSTER_SIZE};
/// let p = BuildParams { cluster_size: MAX_CLUSTER_SIZE, ..BuildParams::hybrid() };
/// assert!(p.check().is_ok());
/// assert!(BuildParams { cluster_size: MAX_CLUSTER_SIZE + 1, ..p }.check().is_err());
/// ```
pub const MAX_CLUSTER_SIZE: u32 = 1 << 16;

/// Smallest non-zero [`BuildParams::bin_sample`].
///
/// ```
/// use strahl::build::{BuildParams, MIN_BIN_SAMPLE};
/// let p = BuildParams { bin_sample: MIN_BIN_SAMPLE, ..BuildParams::balanced() };
/// assert!(p.check().is_ok());
/// assert!(BuildParams { bin_sample: MIN_BIN_SAMPLE - 1, ..p }.check().is_err());
/// assert!(BuildParams { bin_sample: 0, ..p }.check().is_ok()); // every reference binned
/// ```
pub const MIN_BIN_SAMPLE: u32 = 64;

/// Fewest bins per axis of the binned builder.
///
/// ```
/// use strahl::build::{BuildParams, MIN_BINS};
/// let p = BuildParams { bins: MIN_BINS, ..BuildParams::fast() };
/// assert!(p.check().is_ok());
/// assert!(BuildParams { bins: MIN_BINS - 1, ..p }.check().is_err());
/// ```
pub const MIN_BINS: u32 = 4;
/// Most bins per axis of the binned builder (the bins are fixed arrays of this size).
///
/// ```
/// use strahl::build::{BuildParams, Bvh2, MAX_BINS};
/// let p = BuildParams { bins: MAX_BINS, ..BuildParams::fast() };
/// assert!(BuildParams { bins: MAX_BINS + 1, ..p }.check().is_err());
/// let tris = strahl::scene::icosphere(2).to_soup();
/// assert!(Bvh2::build(&tris[..], &p).unwrap().0.validate(&tris[..]).is_ok());
/// ```
pub const MAX_BINS: u32 = 64;
/// Largest accepted [`BuildParams::max_leaf_size`].
///
/// ```
/// use strahl::build::{BuildParams, Bvh2, MAX_LEAF_SIZE};
/// let p = BuildParams { max_leaf_size: MAX_LEAF_SIZE, ..BuildParams::median() };
/// assert!(p.check().is_ok());
/// assert!(BuildParams { max_leaf_size: MAX_LEAF_SIZE + 1, ..p }.check().is_err());
/// let tris = strahl::scene::icosphere(2).to_soup();
/// // Leaves as large as the SAH likes: at most all 320 triangles.
/// assert!(Bvh2::build(&tris[..], &p).unwrap().0.validate(&tris[..]).unwrap().max_leaf_size <= 320);
/// ```
pub const MAX_LEAF_SIZE: u32 = 1 << 16;
/// Smallest accepted [`BuildParams::max_depth`].
///
/// ```
/// use strahl::build::{BuildParams, Bvh2, MIN_DEPTH};
/// let p = BuildParams { max_depth: MIN_DEPTH, ..BuildParams::fastest() };
/// assert!(p.check().is_ok());
/// assert!(BuildParams { max_depth: MIN_DEPTH - 1, ..p }.check().is_err());
/// let tris = strahl::scene::thin_soup(10_000, 1);
/// assert!(Bvh2::build(&tris[..], &p).unwrap().0.validate(&tris[..]).unwrap().max_depth <= MIN_DEPTH);
/// ```
pub const MIN_DEPTH: u32 = 34;

impl Default for BuildParams {
    /// [`BuildParams::balanced`].
    fn default() -> Self {
        Self::balanced()
    }
}

impl BuildParams {
    /// The Morton quantiser of centroid bounds `cb` for these parameters (code width and cells).
    pub(crate) fn quantizer(&self, cb: &crate::geometry::Aabb) -> crate::geometry::morton::MortonQuantizer {
        use crate::geometry::morton::{BITS_PER_AXIS_30, BITS_PER_AXIS_63, MortonQuantizer};
        let bits = match self.morton_bits {
            MortonBits::Bits30 => BITS_PER_AXIS_30,
            MortonBits::Bits63 => BITS_PER_AXIS_63,
        };
        match self.morton_cells {
            MortonCells::Extended => MortonQuantizer::new_extended(cb, bits),
            MortonCells::Normalized => MortonQuantizer::new(cb, bits),
        }
    }

    /// The fastest build: LBVH over 30-bit Morton codes, leaves of up to 2 primitives (up to 4
    /// where codes coincide, and within a long run of equal codes the finer codes kept by
    /// [`BuildParams::max_depth`] too). Measured: two-primitive leaves build about 20% faster than Karras'
    /// single-primitive ones, with an SAH cost within 2% either way.
    ///
    /// **Far outliers.** Morton codes quantise the box of all centroids: one triangle far from the
    /// rest (a sky or a distant ground triangle) leaves the rest in a few grid cells. Runs of
    /// equal codes are put in the Morton order of their own bounds and split by those finer
    /// codes, so such a tree still cuts the cell in space. Measured (AMD EPYC, Zen 1; 100,000
    /// triangles in a unit cube beside one 10^7 away, 100,000 rays into the cube through the
    /// BVH8; `tests/build_speed.rs`'s `far_outlier`): 230 ms with `fastest()` against 225 ms
    /// without the outlier (46.7 s before runs were ordered).
    ///
    /// ```
    /// use strahl::build::{BuildParams, Bvh2, MortonBits, Strategy};
    /// let p = BuildParams::fastest();
    /// assert_eq!((p.strategy, p.morton_bits), (Strategy::Lbvh, MortonBits::Bits30));
    /// assert_eq!((p.min_leaf_size, p.max_leaf_size), (2, 4));
    /// assert!(p.check().is_ok());
    /// let tris = strahl::scene::thin_soup(1_000, 1);
    /// assert!(Bvh2::build(&tris[..], &p).unwrap().0.validate(&tris[..]).unwrap().max_leaf_size <= 4);
    /// ```
    pub const fn fastest() -> Self {
        Self {
            strategy: Strategy::Lbvh,
            traversal_cost: 1.0,
            intersection_cost: 1.0,
            min_leaf_size: 2,
            max_leaf_size: 4,
            bins: 8,
            bin_axes: BinAxes::All,
            bin_sample: 0,
            morton_bits: MortonBits::Bits30,
            morton_cells: MortonCells::Extended,
            max_depth: MAX_DEPTH,
            cluster_size: 32,
            refine: Refine::None,
        }
    }

    /// A fast build of a good tree: binned SAH with 8 bins on the longest centroid axis
    /// (Wald 2007), nodes of 8,192 references or more binned from a sample of 4,096 to about 6,144
    /// ([`bin_sample`](Self::bin_sample): 1.17-1.19x faster on the 1M-triangle bench scenes,
    /// SAH cost within 0.11% of binning every reference).
    ///
    /// ```
    /// use strahl::build::{BinAxes, BuildParams, Bvh2, Strategy};
    /// let p = BuildParams::fast();
    /// assert_eq!((p.strategy, p.bins, p.bin_axes), (Strategy::BinnedSah, 8, BinAxes::Longest));
    /// assert_eq!(p.bin_sample, 4096);
    /// assert_eq!((p.min_leaf_size, p.max_leaf_size), (1, 8));
    /// assert!(p.check().is_ok());
    /// let tris = strahl::scene::thin_soup(1_000, 1);
    /// assert!(Bvh2::build(&tris[..], &p).unwrap().0.validate(&tris[..]).unwrap().max_leaf_size <= 8);
    /// ```
    pub const fn fast() -> Self {
        Self {
            strategy: Strategy::BinnedSah,
            bins: 8,
            bin_axes: BinAxes::Longest,
            bin_sample: 4096,
            min_leaf_size: 1,
            max_leaf_size: 8,
            ..Self::fastest()
        }
    }

    /// The default: binned SAH with 16 bins on all three axes, nodes of 32,768 references or
    /// more binned from a sample of 16,384 to about 24,576 ([`bin_sample`](Self::bin_sample):
    /// 1.13-1.18x faster on the 1M-triangle bench scenes, SAH cost within 0.01% of binning every
    /// reference; scenes under 32,768 triangles are not sampled at all).
    ///
    /// ```
    /// use strahl::build::{BinAxes, BuildParams, Strategy};
    /// let p = BuildParams::balanced();
    /// assert_eq!((p.strategy, p.bins, p.bin_axes), (Strategy::BinnedSah, 16, BinAxes::All));
    /// assert_eq!(p.bin_sample, 16384);
    /// assert_eq!(p, BuildParams::default());
    /// assert!(p.check().is_ok());
    /// ```
    pub const fn balanced() -> Self {
        Self {
            bins: 16,
            bin_axes: BinAxes::All,
            bin_sample: 16384,
            ..Self::fast()
        }
    }

    /// A better tree than [`quality`](Self::quality)'s in less time: binned SAH with 64 bins on
    /// all three axes, then one round of tree rotations ([`Refine::Rotations`]; Kensler 2008).
    /// On the 1M-triangle soup, terrain and sphereflake its SAH cost is 0.05% to 2.5% below the
    /// full sweep's, and on the smaller scenes measured (the bunny, 10k to 100k triangles of each
    /// kind) from 1.4% below to 0.15% above it (binning and the sweep are both greedy top-down,
    /// and the rotations then mend what greed left), at 1.4 to 2.8 times the full sweep's speed
    /// single-threaded and 1.2 to 1.4 times slower than [`balanced`](Self::balanced) (measured
    /// in the [module docs](super#measured)). Parallel builds rotate its subtrees side by side
    /// (the same tree).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams, Refine}, scene};
    /// let bunny = scene::bunny();
    /// let tris = bunny.as_indexed();
    /// let p = BuildParams::high();
    /// assert_eq!((p.bins, p.refine), (64, Refine::Rotations(1)));
    /// let (bvh, stats) = Bvh2::build(&tris, &p).unwrap();
    /// assert!(stats.restructured > 0); // rotations applied
    /// let (sweep, _) = Bvh2::build(&tris, &BuildParams::quality()).unwrap();
    /// // Measured on this scene (the builds are deterministic), not promised for every scene:
    /// assert!(bvh.sah_cost(1.0, 1.0) <= sweep.sah_cost(1.0, 1.0));
    /// ```
    pub const fn high() -> Self {
        Self {
            bins: 64,
            bin_sample: 0,
            refine: Refine::Rotations(1),
            ..Self::balanced()
        }
    }

    /// The best tree of a single greedy top-down pass: full-sweep SAH over every primitive
    /// boundary on all three axes (the exact SAH split at every node, the reference the other
    /// presets are measured against; [`high`](Self::high) refines a binned tree past it).
    ///
    /// ```
    /// use strahl::build::{BuildParams, Bvh2, Strategy};
    /// let p = BuildParams::quality();
    /// assert_eq!(p.strategy, Strategy::SweepSah);
    /// assert!(p.check().is_ok());
    /// let tris = strahl::scene::thin_soup(5_000, 1);
    /// let (best, stats) = Bvh2::build(&tris[..], &p).unwrap();
    /// let s = best.validate(&tris[..]).unwrap();
    /// assert_eq!((s.primitives, s.leaves), (5_000, stats.leaves));
    /// assert!(s.max_leaf_size <= p.max_leaf_size && s.max_depth <= p.max_depth);
    /// // Usually below `fast()`'s binned tree's cost, but greedy top-down splits promise no order.
    /// let cost = best.sah_cost(1.0, 1.0);
    /// assert!(cost.is_finite() && cost >= 1.0);
    /// ```
    pub const fn quality() -> Self {
        Self {
            strategy: Strategy::SweepSah,
            bin_sample: 0,
            ..Self::balanced()
        }
    }

    /// The SAH-blind baseline: object median on the longest centroid axis, leaves of up to 4.
    ///
    /// ```
    /// use strahl::build::{BuildParams, Bvh2, Strategy};
    /// let p = BuildParams::median();
    /// assert_eq!((p.strategy, p.max_leaf_size), (Strategy::Median, 4));
    /// assert!(p.check().is_ok());
    /// let tris = strahl::scene::thin_soup(1_000, 1);
    /// let stats = Bvh2::build(&tris[..], &p).unwrap().0.validate(&tris[..]).unwrap();
    /// assert!(stats.max_leaf_size <= 4);
    /// assert!(stats.max_depth <= 11); // object medians: a balanced tree, at most ceil(log2 1000) + 1 deep
    /// ```
    pub const fn median() -> Self {
        Self {
            strategy: Strategy::Median,
            bin_sample: 0,
            max_leaf_size: 4,
            ..Self::balanced()
        }
    }

    /// HLBVH with clusters of up to 32 primitives and a 16-bin SAH top, then one round of treelet
    /// restructuring (7 leaves) at every node with 2 primitives or more: an SAH cost within 3%
    /// (soup) to 5% (bunny) of [`quality`](Self::quality)'s. NOTE: single-threaded, the treelet
    /// round costs about as much as a full-sweep build, so this preset is no faster than
    /// `quality()` (measured in the [module docs](super#measured)); it is the starting point for
    /// the refinement's knobs ([`TreeletParams`]).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams, Strategy}, scene};
    /// let bunny = scene::bunny();
    /// let tris = bunny.as_indexed();
    /// let p = BuildParams::hybrid();
    /// assert_eq!(p.strategy, Strategy::Hlbvh);
    /// let (bvh, stats) = Bvh2::build(&tris, &p).unwrap();
    /// assert!(stats.restructured > 0);
    /// assert!(bvh.validate(&tris).unwrap().max_depth <= p.max_depth);
    /// let (lbvh, _) = Bvh2::build(&tris, &BuildParams::fastest()).unwrap();
    /// // Measured on this scene (the builds are deterministic), not promised for every scene:
    /// assert!(bvh.sah_cost(1.0, 1.0) < lbvh.sah_cost(1.0, 1.0));
    /// ```
    pub const fn hybrid() -> Self {
        Self {
            strategy: Strategy::Hlbvh,
            min_leaf_size: 1,
            max_leaf_size: 4,
            bins: 16,
            bin_axes: BinAxes::All,
            refine: Refine::Treelets(TreeletParams::new()),
            ..Self::fastest()
        }
    }

    /// Morton clusters with SAH mini-trees ([`Strategy::HlbvhSah`]): clusters of up to 1,024
    /// primitives, each built by binned SAH (8 bins on all three axes, the exact sweep of ranges
    /// of at most 16 on the longest axis), and a binned-SAH top over the clusters. On the
    /// 1M-triangle soup, single-threaded: an SAH cost within 3% of [`quality`](Self::quality)'s
    /// at more than 5 times its speed, and a better tree than [`fast`](Self::fast) in less time
    /// (measured in the [module docs](super#measured)). On multi-scale scenes, whose Morton
    /// clusters mix large and small primitives, the mini-trees are built first and their large
    /// nodes opened for the top to regroup (pruning, as Bonsai does; see [`Strategy::HlbvhSah`]):
    /// on the 1M sphereflake the tree's SAH cost is then within 0.3% of `quality()`'s (10.7%
    /// above it without pruning), on the 1M terrain 4.5% above it (7.6% without), where
    /// [`balanced`](Self::balanced) stays within 2%.
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams, Strategy}, scene};
    /// let soup = scene::thin_soup(20_000, 1);
    /// let p = BuildParams::hybrid_sah();
    /// assert_eq!(p.strategy, Strategy::HlbvhSah);
    /// let (bvh, stats) = Bvh2::build(&soup[..], &p).unwrap();
    /// assert_eq!(stats.primitives, 20_000);
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// let (lbvh, _) = Bvh2::build(&soup[..], &BuildParams::fastest()).unwrap();
    /// // Measured on this scene (the builds are deterministic), not promised for every scene:
    /// assert!(bvh.sah_cost(1.0, 1.0) < lbvh.sah_cost(1.0, 1.0));
    /// ```
    pub const fn hybrid_sah() -> Self {
        Self {
            strategy: Strategy::HlbvhSah,
            min_leaf_size: 1,
            max_leaf_size: 8,
            bins: 8,
            bin_axes: BinAxes::AllButSmall,
            cluster_size: 1024,
            ..Self::fastest()
        }
    }

    /// PLOC ([`Strategy::Ploc`]) with 30-bit Morton codes: between [`fastest`](Self::fastest)
    /// and [`hybrid`](Self::hybrid) in build time, with a markedly better tree than the LBVH's
    /// (measured in the [module docs](super#measured)). Leaves hold one primitive.
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams, Strategy}, scene};
    /// let soup = scene::thin_soup(20_000, 1);
    /// let p = BuildParams::ploc();
    /// assert_eq!(p.strategy, Strategy::Ploc);
    /// let (bvh, stats) = Bvh2::build(&soup[..], &p).unwrap();
    /// assert_eq!((stats.primitives, stats.leaves), (20_000, 20_000));
    /// assert!(bvh.validate(&soup[..]).is_ok());
    /// let (lbvh, _) = Bvh2::build(&soup[..], &BuildParams::fastest()).unwrap();
    /// // Measured on this scene (the builds are deterministic), not promised for every scene:
    /// assert!(bvh.sah_cost(1.0, 1.0) < lbvh.sah_cost(1.0, 1.0));
    /// ```
    pub const fn ploc() -> Self {
        Self {
            strategy: Strategy::Ploc,
            min_leaf_size: 1,
            max_leaf_size: 1,
            ..Self::fastest()
        }
    }

    /// `Ok` if every field is in its documented range, else [`BuildError::InvalidParams`] naming
    /// the first field that is not. The builders call this first.
    ///
    /// ```
    /// use strahl::build::{BuildError, BuildParams};
    /// assert!(BuildParams::default().check().is_ok());
    /// let bad = BuildParams { min_leaf_size: 4, max_leaf_size: 2, ..BuildParams::default() };
    /// let Err(BuildError::InvalidParams(why)) = bad.check() else { panic!("accepted") };
    /// assert!(why.starts_with("max_leaf_size"));
    /// assert!(BuildParams { traversal_cost: f32::NAN, ..BuildParams::default() }.check().is_err());
    /// ```
    pub fn check(&self) -> Result<(), BuildError> {
        let bad = |what| Err(BuildError::InvalidParams(what));
        if !(self.traversal_cost.is_finite() && self.traversal_cost >= 0.0) {
            return bad("traversal_cost must be finite and >= 0");
        }
        if !(self.intersection_cost.is_finite() && self.intersection_cost > 0.0) {
            return bad("intersection_cost must be finite and > 0");
        }
        if self.min_leaf_size == 0 {
            return bad("min_leaf_size must be >= 1");
        }
        if self.max_leaf_size < self.min_leaf_size || self.max_leaf_size > MAX_LEAF_SIZE {
            return bad("max_leaf_size must be in min_leaf_size ..= 65536");
        }
        if !(MIN_BINS..=MAX_BINS).contains(&self.bins) {
            return bad("bins must be in 4 ..= 64");
        }
        if self.bin_sample != 0 && self.bin_sample < MIN_BIN_SAMPLE {
            return bad("bin_sample must be 0 or >= 64");
        }
        if !(MIN_DEPTH..=MAX_DEPTH).contains(&self.max_depth) {
            return bad("max_depth must be in 34 ..= traverse::MAX_DEPTH");
        }
        if !(1..=MAX_CLUSTER_SIZE).contains(&self.cluster_size) {
            return bad("cluster_size must be in 1 ..= 65536");
        }
        if let Refine::Rotations(r) = self.refine
            && !(1..=64).contains(&r)
        {
            return bad("refine: rotation rounds must be in 1 ..= 64");
        }
        if let Refine::Treelets(t) | Refine::AgglomerativeTreelets(t) = self.refine {
            if matches!(self.refine, Refine::Treelets(_)) && !(3..=8).contains(&t.leaves) {
                return bad("refine: treelet leaves must be in 3 ..= 8");
            }
            if !(3..=16).contains(&t.leaves) {
                return bad("refine: agglomerative treelet leaves must be in 3 ..= 16");
            }
            if t.min_prims == 0 {
                return bad("refine: treelet min_prims must be >= 1");
            }
            if !(1..=16).contains(&t.rounds) {
                return bad("refine: treelet rounds must be in 1 ..= 16");
            }
        }
        if let Refine::Reinsertion(r) = self.refine {
            if !(1..=64).contains(&r.rounds) {
                return bad("refine: reinsertion rounds must be in 1 ..= 64");
            }
            if !(1..=1000).contains(&r.per_mille) {
                return bad("refine: reinsertion per_mille must be in 1 ..= 1000");
            }
        }
        Ok(())
    }
}
