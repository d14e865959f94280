//! Every tunable of the BVH2 builders in one struct, with presets from fastest build to best tree.

use super::BuildError;
use crate::traverse::MAX_DEPTH;

/// How the builder chooses splits.
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
}

/// Which axes [`Strategy::BinnedSah`] bins.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BinAxes {
    /// All three: the best plane of `3 (bins - 1)` candidates.
    All,
    /// Only the axis of largest centroid extent, as in Wald 2007: a third of the binning work,
    /// a slightly worse tree (measured in the [module docs](super#measured)).
    Longest,
}

/// Bits of the Morton codes an [`Lbvh`](Strategy::Lbvh) build sorts by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MortonBits {
    /// 30-bit codes, 10 bits (1,024 cells) per axis: fewer radix passes (3), coarser cells.
    Bits30,
    /// 63-bit codes, 21 bits per axis: for scenes with detail at very different scales (more
    /// passes: 6).
    Bits63,
}

/// All knobs of the BVH2 builders. Start from a preset and change fields as needed.
///
/// | preset | strategy | bins | leaf size | builds | tree |
/// |---|---|---|---|---|---|
/// | [`fastest`](Self::fastest) | LBVH, 30-bit | | 2, up to 4 on equal codes | fastest | worst SAH |
/// | [`fast`](Self::fast) | binned SAH, longest axis | 8 | 1 ..= 8 | fast | good |
/// | [`balanced`](Self::balanced) (= `default()`) | binned SAH, all axes | 16 | 1 ..= 8 | medium | better |
/// | [`quality`](Self::quality) | full-sweep SAH | | 1 ..= 8 | slowest | best |
/// | [`median`](Self::median) | object median | | 1 ..= 4 | fast | SAH-blind baseline |
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
    /// Code width of [`Strategy::Lbvh`].
    pub morton_bits: MortonBits,
    /// The deepest tree the builder may make (root = depth 1), in `34 ..=`
    /// [`MAX_DEPTH`](crate::traverse::MAX_DEPTH) (at least 34 so that a balanced tree over
    /// `2^31` primitives fits). Where a split would make a subtree that cannot be finished within
    /// this depth, the builder splits that node at its object median instead (a balanced subtree
    /// needs only `ceil(log2 N)` more levels); [`BuildStats::forced_splits`](super::BuildStats)
    /// counts how often.
    pub max_depth: u32,
}

/// Fewest bins per axis of the binned builder.
pub const MIN_BINS: u32 = 4;
/// Most bins per axis of the binned builder (the bins are fixed arrays of this size).
pub const MAX_BINS: u32 = 64;
/// Largest accepted [`BuildParams::max_leaf_size`].
pub const MAX_LEAF_SIZE: u32 = 1 << 16;
/// Smallest accepted [`BuildParams::max_depth`].
pub const MIN_DEPTH: u32 = 34;

impl Default for BuildParams {
    /// [`BuildParams::balanced`].
    fn default() -> Self {
        Self::balanced()
    }
}

impl BuildParams {
    /// The fastest build: LBVH over 30-bit Morton codes, leaves of up to 2 primitives (up to 4
    /// where codes coincide). Measured: two-primitive leaves build about 20% faster than Karras'
    /// single-primitive ones, with an SAH cost within 2% either way.
    pub const fn fastest() -> Self {
        Self {
            strategy: Strategy::Lbvh,
            traversal_cost: 1.0,
            intersection_cost: 1.0,
            min_leaf_size: 2,
            max_leaf_size: 4,
            bins: 8,
            bin_axes: BinAxes::All,
            morton_bits: MortonBits::Bits30,
            max_depth: MAX_DEPTH,
        }
    }

    /// A fast build of a good tree: binned SAH with 8 bins on the longest centroid axis
    /// (Wald 2007).
    pub const fn fast() -> Self {
        Self {
            strategy: Strategy::BinnedSah,
            bins: 8,
            bin_axes: BinAxes::Longest,
            min_leaf_size: 1,
            max_leaf_size: 8,
            ..Self::fastest()
        }
    }

    /// The default: binned SAH with 16 bins on all three axes.
    pub const fn balanced() -> Self {
        Self {
            bins: 16,
            bin_axes: BinAxes::All,
            ..Self::fast()
        }
    }

    /// The best tree: full-sweep SAH over every primitive boundary on all three axes.
    pub const fn quality() -> Self {
        Self {
            strategy: Strategy::SweepSah,
            ..Self::balanced()
        }
    }

    /// The SAH-blind baseline: object median on the longest centroid axis, leaves of up to 4.
    pub const fn median() -> Self {
        Self {
            strategy: Strategy::Median,
            max_leaf_size: 4,
            ..Self::balanced()
        }
    }

    /// `Ok` if every field is in its documented range, else [`BuildError::InvalidParams`] naming
    /// the first field that is not. The builders call this first.
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
        if !(MIN_DEPTH..=MAX_DEPTH).contains(&self.max_depth) {
            return bad("max_depth must be in 34 ..= traverse::MAX_DEPTH");
        }
        Ok(())
    }
}
