//! Binned SAH split search and partition (Wald, "On fast construction of SAH-based bounding volume
//! hierarchies", 2007).
//!
//! Per node: the centroids are projected into `K` equal bins per axis over the node's centroid
//! bounds, `bin = trunc(min(max((c - cmin) k, 0), K - 1))` with `k = K / extent` (0 on a flat
//! axis). The clamp keeps the maximum centroid (where `(c - cmin) k` may round to `K`) in the last
//! bin and sends a NaN to bin 0, so the index is always in range. One pass over the references
//! grows the box and count of the bin each one falls into, on all three axes or only the longest
//! ([`BinAxes`](super::BinAxes)); sweeps over the bins from both ends give the `K - 1` candidate
//! planes per axis. Bins live in fixed arrays for the whole build; only the bins in use are reset.
//! Even and odd references grow two separate sets of bins, merged before the sweep, so that two
//! references in a row that fall into the same bin do not wait on each other's store (binning
//! took about 25% fewer profile samples on the 1M soup); nodes of fewer than
//! [`SINGLE_SET_BELOW`] references use one set.
//!
//! **Sampled binning** ([`BuildParams::bin_sample`](super::BuildParams::bin_sample): 4,096 in
//! `fast()`, 16,384 in `balanced()`): a node of at least `2 S` references bins one of every
//! `N / S` (`S` to about `1.5 S` of them, one at a hashed offset in each run: [`find_sampled`]) and
//! the partition pass that moves all `N` measures the children's boxes and counts
//! ([`partition_measured`]). The top levels of a 1M build wait on memory (32 MB of references
//! read per pass); sampling drops one of their two passes. Where the sample has no plane with
//! references on both sides (it missed the outliers), the node bins every reference. Measured
//! (2026-12-05, Intel Xeon; criterion, `STRAHL_BENCH_SCENES=soup1M,terrain1M,sphereflake1M cargo
//! bench --features embree --bench build`, SAH costs from the `build_speed` harness's `fast`,
//! `fast_exact`, `balanced`, `balanced_exact`): `fast()` (`S = 4096`) 1.17-1.19x faster on the 1M
//! soup, terrain and sphereflake, SAH cost +0.00%, +0.01%, +0.11%; `balanced()` (`S = 16384`)
//! 1.13-1.18x faster, +0.004%, -0.01%, -0.01%. `high()` (64 bins) bins every reference: +0.56% on
//! the sphereflake at `S = 16384`. Smaller samples cost more tree on multi-scale and clustered
//! scenes (`S = 256`: `balanced()`'s sphereflake +4.3%), since a sample misses the few large
//! primitives whose boxes decide the bins' areas.
//!
//! **Small ranges** (at most [`SMALL`] = 16 references) are split by an exact sweep instead
//! ([`find_small`]): binning costs about 100 ns per node in bin resets and sweeps, which
//! dominated the build when half the nodes hold 2 or 3 references. The top-down builder builds
//! such a range's whole subtree at once with the same sweep ([`small`](super::small)). (At 8, the
//! limit before, the builds ran as many instructions on the soup, with a tree 0.04 to 0.1% worse
//! by the SAH. At 32, tried with the local builder on 2026-12-02: `fast()` as fast with a tree
//! 0.13% better, `balanced()` 3% slower, `hybrid_sah()` 5% faster but 0.3% worse, as its longest-
//! axis-only sweep then reaches ranges of 17 to 32; not kept.)
//!
//! **Partition.** The references move to the other of two buffers, branch-free: each is written
//! to both the next left and the next right slot, and one of the two cursors advances; the
//! children's centroid bounds are grown on the way with a select and a `max` each, in the
//! negated-min form of [`Box8`] (`[-c, c]`). Measured on the 1M-triangle
//! soup (`BuildParams::fast()`, whole build): this 219 ms; in place, branch-free (Lomuto: swap with
//! the first right reference) 241 ms; in place with a branch per reference (Hoare) 373 ms, from
//! mispredictions. The second buffer costs `32 n` bytes, allocated once per
//! [`Builder`](super::Builder), never per node.
//!
//! Tried and dropped (2026-12-02, AMD EPYC): binning the children inside the partition pass, into
//! per-child bins that also carry each bin's centroid bounds (from which the children's binning
//! grids are known exactly before the pass, so the trees came out node for node the same), which
//! saves one of the two passes over the references per level. The whole `fast()` build of the 1M
//! soup went from 116 to 139 ms, and to 147 ms with two bin sets per child: the fused loop's bin
//! loads waited on its reference stores (37% of its samples on one bin store), which the
//! separate binning loop never does.
//!
//! Also tried and dropped (2026-12-03, same machine, trees checked byte for byte the same): with
//! one axis binned, each bin keeping its centroid bounds too, so that the partition pass only
//! moves references (about 15 fewer instructions per reference in the partition, 5 more in the
//! binning): `fast()` on 256k and 1M soups alike within the run-to-run noise (±10% here); and
//! writing each reference once, to a slot chosen by a select, instead of to both cursors: alike.
//!
//! Also tried and dropped (2026-12-06, Intel Xeon): the sampled top levels split several levels
//! at once, to cut the passes over memory. A node of at least `8 S` references took one sample
//! of `S 2^(L-1)`, split it `L <= 4` levels deep into a decision tree, then made one pass that
//! walked every reference down the tree (all 15 side tests of 8 references at a time in lanes)
//! and grew each leaf's count and bounds, and a second that moved the references to their
//! leaves' ranges. On the 1M soup the root's group cost 3.2 ms (sample and splits) + 9-11 ms
//! (walk and bounds) + 4.5-5.5 ms (move), against about 21 ms for the four measured partition
//! passes it replaced, and the groups of 65k references (in cache, where a partition pass is
//! cheap) lost: `fast()` 184 -> 199 ms, the same SAH cost (483.24). A pass that only reads the
//! references is about 3.4 ns each here against 5.2 for the measured partition: the most such a
//! scheme could save is about 10 ms of the build.

use super::params::MAX_BINS;
use super::prims::{Box8, CBounds, PrimRef};
use crate::math::{Lane, f32x4, f32x8};

const K: usize = MAX_BINS as usize;

/// The binning of one node: bin index of a doubled centroid on each axis.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Binning {
    /// Lower centroid bound.
    origin: f32x4,
    /// Bins per unit (doubled-centroid) length per axis; 0 on a flat axis and in lane 3.
    scale: f32x4,
    /// Index of the last bin, as `f32`.
    top: f32x4,
}

impl Binning {
    /// The binning of centroid bounds `cb` into `bins` bins per axis (`bins <= MAX_BINS`).
    pub fn new(cb: &CBounds, bins: u32) -> Self {
        let e = cb.extent();
        let k = bins as f32;
        let axis = |e: f32| {
            let s = k / e;
            // NOTE: `e > 0` is false for NaN: such axes are flat and put everything in bin 0.
            if e > 0.0 && s.is_finite() { s } else { 0.0 }
        };
        Self {
            origin: cb.lo,
            scale: f32x4::new([axis(e[0]), axis(e[1]), axis(e[2]), 0.0]),
            top: f32x4::splat(bins as f32 - 1.0),
        }
    }

    /// `true` if no axis can be split (all centroids coincide).
    pub fn is_flat(&self) -> bool {
        let s = self.scale.to_array();
        s[0] == 0.0 && s[1] == 0.0 && s[2] == 0.0
    }

    /// Bin indices of a doubled centroid on the three axes (lane 3: 0), each in `0..bins`.
    #[inline(always)]
    pub fn bins_of(&self, c2: f32x4) -> [i32; 4] {
        let q = (c2 - self.origin) * self.scale;
        // `max_l(q, 0)` returns 0 for a NaN q; the clamp keeps the index in [0, bins - 1].
        q.max_l(f32x4::ZERO).min_l(self.top).fast_trunc_int().to_array()
    }
}

/// Per-axis bin boxes and counts, kept for a whole build (only the bins in use are reset). Two
/// sets: even and odd references go to different sets, merged before the sweep.
// PERF: with one set, a reference that falls into the same bin as the one before waits for that
// bin's store (load, max, store: a dependency chain through memory); two sets halve the chains.
pub(crate) struct Bins {
    boxes: [[[Box8; K]; 3]; 2],
    counts: [[[u32; K]; 3]; 2],
}

impl Bins {
    pub fn new() -> Self {
        Self {
            boxes: [[[Box8::EMPTY; K]; 3]; 2],
            counts: [[[0; K]; 3]; 2],
        }
    }
}

/// The best plane found by [`find`]: refs whose bin on `axis` is `<= plane` go left.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BinSplit {
    pub axis: usize,
    pub plane: usize,
    /// `N_l A_l + N_r A_r` (half areas).
    pub cost: f32,
    pub left_count: u32,
    pub left: Box8,
    pub right: Box8,
}

/// The stride of the sampled binning of a node of `count` references
/// ([`BuildParams::bin_sample`](super::BuildParams::bin_sample) = `sample`), or 1 where every
/// reference is binned: nodes of at least `2 * sample` references, and only where the node may
/// not become a leaf (`may_leaf`), bin one reference of every `count / sample` ([`find_sampled`]).
#[inline]
pub(crate) fn sample_stride(count: u32, sample: u32, may_leaf: bool) -> usize {
    if sample == 0 || may_leaf || (count as u64) < 2 * sample as u64 {
        1
    } else {
        (count / sample) as usize
    }
}

/// The position of the `j`-th reference of a sample with `stride`: one at a hashed offset within
/// each run `[j stride, (j + 1) stride)` (stratified, so that a repeating input order whose period
/// divides the stride cannot make every sampled reference the same one).
#[inline]
pub(crate) fn sample_index(j: usize, stride: usize) -> usize {
    // A multiplicative hash of `j`, mapped onto `0..stride`.
    let h = (j as u32).wrapping_mul(0x9E37_79B9) as u64;
    j * stride + ((h * stride as u64) >> 32) as usize
}

/// [`find`] over a stratified sample of `refs`: `floor(N / stride)` references, one per run of
/// `stride` ([`sample_index`]), so `S` to about `1.5 S` of them for the stride of
/// [`sample_stride`]. The split's counts and boxes are the sample's: [`partition_measured`] gives
/// the node's. `None` also where the sample has no plane with references on both sides (the
/// caller then bins every reference).
pub(crate) fn find_sampled(
    refs: &[PrimRef],
    binning: &Binning,
    bins: usize,
    longest_only: bool,
    stride: usize,
    scratch: &mut Bins,
) -> Option<BinSplit> {
    let stride = stride.max(1);
    let picks = (0..refs.len() / stride).filter_map(|j| refs.get(sample_index(j, stride)));
    match axes_mask(binning, longest_only) {
        1 => bin_picks::<1>(picks, binning, bins, scratch),
        2 => bin_picks::<2>(picks, binning, bins, scratch),
        4 => bin_picks::<4>(picks, binning, bins, scratch),
        _ => bin_picks::<7>(picks, binning, bins, scratch),
    }
}

/// Bins the references `picks` into the first set of `scratch` (one set: the sample is small) and
/// sweeps it.
fn bin_picks<'a, const AXES: u32>(
    picks: impl Iterator<Item = &'a PrimRef>,
    binning: &Binning,
    bins: usize,
    scratch: &mut Bins,
) -> Option<BinSplit> {
    let n = bins.clamp(2, K);
    for a in 0..3 {
        if AXES >> a & 1 != 0 {
            scratch.boxes[0][a][..n].fill(Box8::EMPTY);
            scratch.counts[0][a][..n].fill(0);
        }
    }
    for r in picks {
        let b = binning.bins_of(r.c2());
        for (a, &ba) in b.iter().enumerate().take(3) {
            if AXES >> a & 1 != 0 {
                let i = ba as usize & (K - 1);
                scratch.boxes[0][a][i].grow(r.bounds());
                scratch.counts[0][a][i] += 1;
            }
        }
    }
    sweep::<AXES>(scratch, binning, bins)
}

/// Bins `refs` with `binning` (`bins` bins per axis) and returns the cheapest plane with primitives
/// on both sides, or `None` where every plane leaves one side empty.
pub(crate) fn find(
    refs: &[PrimRef],
    binning: &Binning,
    bins: usize,
    longest_only: bool,
    scratch: &mut Bins,
) -> Option<BinSplit> {
    // One copy of the binning loop per axis mask, so the axes are constants.
    match axes_mask(binning, longest_only) {
        1 => find_axes::<1>(refs, binning, bins, scratch),
        2 => find_axes::<2>(refs, binning, bins, scratch),
        4 => find_axes::<4>(refs, binning, bins, scratch),
        _ => find_axes::<7>(refs, binning, bins, scratch),
    }
}

/// [`find`] on the axes in the bit mask `AXES`.
#[inline(never)]
fn find_axes<const AXES: u32>(
    refs: &[PrimRef],
    binning: &Binning,
    bins: usize,
    scratch: &mut Bins,
) -> Option<BinSplit> {
    if refs.len() < SINGLE_SET_BELOW {
        // Few references: one set of bins (no second set to reset and merge).
        bin_picks::<AXES>(refs.iter(), binning, bins, scratch)
    } else {
        bin_refs::<AXES>(refs, binning, bins, scratch);
        sweep::<AXES>(scratch, binning, bins)
    }
}

/// Nodes of fewer references than this are binned into one set of bins: resetting and merging
/// the second set cost more than its shorter store chains save there. The bins, and so the trees,
/// are the same (a union and a sum do not depend on the order they are taken in).
// PERF: 1M soup, `STRAHL_ONLY=fast,balanced,hybrid_sah STRAHL_REPS=5 cargo test --release --test
// build_speed -- --ignored --nocapture speed`, old and new binaries taking turns six times
// (2026-12-06, Intel Xeon): `fast()` 188.5-197.7 -> 182.2-189.0 ms, faster in every pair (by 0.4
// to 15 ms, 5 on average); `balanced()` within the noise (about 1% faster); `hybrid_sah()` the
// same. 32 and 128 measured alike.
const SINGLE_SET_BELOW: usize = 64;

/// Resets the bins in use and bins `refs` into `scratch`'s first set (the second merged into it).
#[inline(always)]
fn bin_refs<const AXES: u32>(refs: &[PrimRef], binning: &Binning, bins: usize, scratch: &mut Bins) {
    let bins = bins.clamp(2, K);
    let Bins {
        boxes: sets,
        counts: set_counts,
    } = scratch;
    for set in 0..2 {
        for a in 0..3 {
            if AXES >> a & 1 != 0 {
                sets[set][a][..bins].fill(Box8::EMPTY);
                set_counts[set][a][..bins].fill(0);
            }
        }
    }
    // `& (K - 1)` is a no-op on the clamped index; it lets the compiler drop the bounds check.
    let mut pairs = refs.chunks_exact(2);
    for pair in &mut pairs {
        let (r0, r1) = (&pair[0], &pair[1]);
        let (b0, b1) = (binning.bins_of(r0.c2()), binning.bins_of(r1.c2()));
        let (rb0, rb1) = (r0.bounds(), r1.bounds());
        for a in 0..3 {
            if AXES >> a & 1 != 0 {
                let (i0, i1) = (b0[a] as usize & (K - 1), b1[a] as usize & (K - 1));
                sets[0][a][i0].grow(rb0);
                set_counts[0][a][i0] += 1;
                sets[1][a][i1].grow(rb1);
                set_counts[1][a][i1] += 1;
            }
        }
    }
    for r in pairs.remainder() {
        let b = binning.bins_of(r.c2());
        for a in 0..3 {
            if AXES >> a & 1 != 0 {
                let i = b[a] as usize & (K - 1);
                sets[0][a][i].grow(r.bounds());
                set_counts[0][a][i] += 1;
            }
        }
    }
    // Merge the second set into the first.
    let ([boxes, boxes1], [counts, counts1]) = (sets, set_counts);
    for a in 0..3 {
        if AXES >> a & 1 != 0 {
            for i in 0..bins {
                boxes[a][i].grow(boxes1[a][i]);
                counts[a][i] += counts1[a][i];
            }
        }
    }
}

/// The cheapest plane over the binned first set of `scratch` (see [`find`]).
#[inline(always)]
fn sweep<const AXES: u32>(scratch: &Bins, binning: &Binning, bins: usize) -> Option<BinSplit> {
    let bins = bins.clamp(2, K);
    let (boxes, counts) = (&scratch.boxes[0], &scratch.counts[0]);
    let scale = binning.scale.to_array();
    let mut best: Option<BinSplit> = None;
    // Every entry read below is written first (1 ..= bins - 1).
    let mut right_area = [0.0f32; K];
    let mut right_count = [0u32; K];
    for a in 0..3 {
        if AXES >> a & 1 == 0 || scale[a] == 0.0 {
            continue;
        }
        // Sweep from the right to get suffix areas and counts.
        let (mut acc, mut n) = (Box8::EMPTY, 0u32);
        for i in (1..bins).rev() {
            acc.grow(boxes[a][i]);
            n += counts[a][i];
            // An empty suffix gets +inf, but is never used (its count is 0).
            right_area[i] = acc.half_area_nonempty();
            right_count[i] = n;
        }
        // Sweep from the left, evaluating the plane after each bin.
        let (mut acc, mut n) = (Box8::EMPTY, 0u32);
        for i in 0..bins - 1 {
            acc.grow(boxes[a][i]);
            n += counts[a][i];
            let nr = right_count[i + 1];
            // NOTE: an empty side has area +inf and count 0: a NaN cost. A NaN or +inf cost
            // never wins (so no test for empty sides; overflowing areas make no split, not a bad
            // one).
            let cost = acc.half_area_nonempty() * n as f32 + right_area[i + 1] * nr as f32;
            if cost < best.map_or(f32::INFINITY, |b| b.cost) {
                best = Some(BinSplit {
                    axis: a,
                    plane: i,
                    cost,
                    left_count: n,
                    left: Box8::EMPTY,
                    right: Box8::EMPTY,
                });
            }
        }
    }
    // The children's boxes are unions of bins: no pass over the references needed.
    let mut best = best?;
    let bx = &boxes[best.axis];
    best.left = bx[..=best.plane].iter().fold(Box8::EMPTY, |acc, b| acc.union(*b));
    best.right = bx[best.plane + 1..bins]
        .iter()
        .fold(Box8::EMPTY, |acc, b| acc.union(*b));
    Some(best)
}

/// The axes [`find`] bins, as a bit mask: all three, or the longest alone (`longest_only`; the
/// longest axis has the smallest non-zero scale, ties to the lowest axis).
pub(crate) fn axes_mask(binning: &Binning, longest_only: bool) -> u32 {
    if !longest_only {
        return 7;
    }
    let s = binning.scale.to_array();
    let (mut a, mut smallest) = (0, f32::INFINITY);
    for (i, &si) in s[..3].iter().enumerate() {
        if si > 0.0 && si < smallest {
            (a, smallest) = (i, si);
        }
    }
    1 << a
}

/// The first half of [`find`], for one chunk of a node's references (the parallel build splits
/// a large node with its references in chunks, one per thread): resets the bins of the axes in
/// `mask` ([`axes_mask`]) and bins `refs` into `scratch`.
#[cfg(feature = "std")]
pub(crate) fn bin_chunk(refs: &[PrimRef], binning: &Binning, bins: usize, mask: u32, scratch: &mut Bins) {
    match mask {
        1 => bin_refs::<1>(refs, binning, bins, scratch),
        2 => bin_refs::<2>(refs, binning, bins, scratch),
        4 => bin_refs::<4>(refs, binning, bins, scratch),
        _ => bin_refs::<7>(refs, binning, bins, scratch),
    }
}

/// Sets `into`'s bins (of the axes in `mask`) to the sum of `parts` (each binned by
/// [`bin_chunk`] with the same arguments): boxes by union, counts by sum, so the result is that
/// of binning all the chunks at once (bit for bit: the references' bounds hold no -0.0, see
/// `prims::prepare`, so no union depends on its order).
#[cfg(feature = "std")]
pub(crate) fn sum_bins(into: &mut Bins, parts: &[Bins], bins: usize, mask: u32) {
    let bins = bins.clamp(2, K);
    for a in 0..3 {
        if mask >> a & 1 != 0 {
            into.boxes[0][a][..bins].fill(Box8::EMPTY);
            into.counts[0][a][..bins].fill(0);
            for other in parts {
                for i in 0..bins {
                    into.boxes[0][a][i].grow(other.boxes[0][a][i]);
                    into.counts[0][a][i] += other.counts[0][a][i];
                }
            }
        }
    }
}

/// The second half of [`find`]: the cheapest plane over bins filled by [`bin_chunk`] (and
/// [`sum_bins`]).
#[cfg(feature = "std")]
pub(crate) fn sweep_bins(scratch: &Bins, binning: &Binning, bins: usize, mask: u32) -> Option<BinSplit> {
    match mask {
        1 => sweep::<1>(scratch, binning, bins),
        2 => sweep::<2>(scratch, binning, bins),
        4 => sweep::<4>(scratch, binning, bins),
        _ => sweep::<7>(scratch, binning, bins),
    }
}

/// How many of a chunk's references, binned into `scratch` by [`bin_chunk`], go left of `split`.
#[cfg(feature = "std")]
pub(crate) fn left_count(scratch: &Bins, split: &BinSplit) -> usize {
    scratch.counts[0][split.axis][..=split.plane]
        .iter()
        .map(|&c| c as usize)
        .sum()
}

/// Moves `src` into `dst` (same length) partitioned by `split`: the left side at the front, the
/// right side (in reverse order) at the back. Returns the left count and both sides' centroid
/// bounds.
///
/// The side test is the bin test of [`find`] on one axis, so the counts agree: with
/// `q = (c - cmin) k`, `trunc(min(max(q, 0), K - 1)) <= plane` holds exactly when
/// `!(q >= plane + 1)` (a NaN `q` is bin 0: left).
pub(crate) fn partition_into(
    src: &[PrimRef],
    dst: &mut [PrimRef],
    binning: &Binning,
    split: &BinSplit,
) -> (usize, CBounds, CBounds) {
    // One copy of the loop per axis, so the axis lane is a constant.
    let (l, lcb, rcb, _, _) = match split.axis {
        0 => partition_axis::<0, false>(src, dst, binning, split.plane),
        1 => partition_axis::<1, false>(src, dst, binning, split.plane),
        _ => partition_axis::<2, false>(src, dst, binning, split.plane),
    };
    (l, lcb, rcb)
}

/// The partition pass of [`partition_into`] on axis `A`; with `MEASURE` it also grows both sides'
/// boxes (two more selects and `max`es per reference: free on the top levels
/// [`partition_measured`] runs on, whose pass waits on memory), else they are returned empty.
#[inline(never)]
fn partition_axis<const A: usize, const MEASURE: bool>(
    src: &[PrimRef],
    dst: &mut [PrimRef],
    binning: &Binning,
    plane: usize,
) -> (usize, CBounds, CBounds, Box8, Box8) {
    let n = src.len().min(dst.len());
    let (origin, scale) = (binning.origin.to_array()[A], binning.scale.to_array()[A]);
    let limit = (plane + 1) as f32;
    let (mut l, mut r) = (0usize, n);
    // Centroid bounds in negated-min form, `[-c, c]` per side: one `max` grows a side.
    let ninf = f32x8::splat(f32::NEG_INFINITY);
    let (mut lacc, mut racc) = (ninf, ninf);
    let (mut lbox, mut rbox) = (ninf, ninf);
    for x in &src[..n] {
        let c = x.c2();
        // `q < limit`, or NaN (bin 0): anything but `q >= limit`.
        let right = (c.to_array()[A] - origin) * scale >= limit;
        let left = !right;
        // While refs remain, `l < r`: both slots are in range. One of the two writes is kept.
        dst[l] = *x;
        dst[r - 1] = *x;
        l += left as usize;
        r -= !left as usize;
        // Grow the side's bounds without a branch: the other side grows by -inf.
        let cc: f32x8 = bytemuck::cast([-c, c]);
        let m = f32x8::splat(f32::from_bits(0u32.wrapping_sub(left as u32)));
        lacc = m.select(cc, ninf).max_l(lacc);
        racc = m.select(ninf, cc).max_l(racc);
        if MEASURE {
            let bb = x.bounds().0;
            lbox = m.select(bb, ninf).max_l(lbox);
            rbox = m.select(ninf, bb).max_l(rbox);
        }
    }
    (l, cbounds_of(lacc), cbounds_of(racc), Box8(lbox), Box8(rbox))
}

/// [`partition_into`] that also grows both sides' boxes (for a split found on a sample, whose
/// boxes and counts are the sample's): returns the left count, both sides' centroid bounds and
/// both sides' boxes.
pub(crate) fn partition_measured(
    src: &[PrimRef],
    dst: &mut [PrimRef],
    binning: &Binning,
    split: &BinSplit,
) -> (usize, CBounds, CBounds, Box8, Box8) {
    match split.axis {
        0 => partition_axis::<0, true>(src, dst, binning, split.plane),
        1 => partition_axis::<1, true>(src, dst, binning, split.plane),
        _ => partition_axis::<2, true>(src, dst, binning, split.plane),
    }
}

/// How many of `refs` go left of `split` (the side test of [`partition_into`]).
#[cfg(feature = "std")]
pub(crate) fn count_left(refs: &[PrimRef], binning: &Binning, split: &BinSplit) -> usize {
    let a = split.axis.min(2);
    let (origin, scale) = (binning.origin.to_array()[a], binning.scale.to_array()[a]);
    let limit = (split.plane + 1) as f32;
    // Everything but `q >= limit` goes left (a NaN `q` too).
    let right = refs
        .iter()
        .filter(|x| (x.c2().to_array()[a] - origin) * scale >= limit)
        .count();
    refs.len() - right
}

/// [`partition_into`] for one chunk of a node's references (the parallel build partitions a
/// large node in chunks, one per thread): the chunk's left references go, in order, to `left`,
/// its right ones, the first last, to `right` from its end. With the chunks' pieces laid out as
/// `[L_0, L_1, .., L_k, R_k, .., R_1, R_0]` the node's order is exactly [`partition_into`]'s.
/// Returns the two sides' centroid bounds and boxes in the negated-min form (`[-lo, hi]`, grown
/// by `max`: left, right centroid bounds, left, right boxes), or `None` where the pieces' lengths do not match the chunk's sides (nothing is then to be
/// trusted in them; the caller splits the node the sequential way, from the untouched `src`).
#[cfg(feature = "std")]
pub(crate) fn partition_chunk(
    src: &[PrimRef],
    left: &mut [PrimRef],
    right: &mut [PrimRef],
    binning: &Binning,
    split: &BinSplit,
) -> Option<[f32x8; 4]> {
    match split.axis {
        0 => partition_chunk_axis::<0>(src, left, right, binning, split.plane),
        1 => partition_chunk_axis::<1>(src, left, right, binning, split.plane),
        _ => partition_chunk_axis::<2>(src, left, right, binning, split.plane),
    }
}

#[cfg(feature = "std")]
fn partition_chunk_axis<const A: usize>(
    src: &[PrimRef],
    left: &mut [PrimRef],
    right: &mut [PrimRef],
    binning: &Binning,
    plane: usize,
) -> Option<[f32x8; 4]> {
    let (origin, scale) = (binning.origin.to_array()[A], binning.scale.to_array()[A]);
    let limit = (plane + 1) as f32;
    let (mut l, mut r) = (0usize, right.len());
    let ninf = f32x8::splat(f32::NEG_INFINITY);
    let (mut lacc, mut racc) = (ninf, ninf);
    let (mut lbox, mut rbox) = (ninf, ninf);
    // NOTE: a branch per reference (two separate destination slices leave no room for the
    // sequential pass's write-to-both trick); this runs only on the top levels of a parallel
    // build, where the pass is bound by memory traffic.
    for x in src {
        let c = x.c2();
        let cc: f32x8 = bytemuck::cast([-c, c]);
        // The side test of `partition_axis`: `q >= limit` goes right (a NaN `q` goes left).
        if (c.to_array()[A] - origin) * scale >= limit {
            r = r.checked_sub(1)?;
            *right.get_mut(r)? = *x;
            racc = cc.max_l(racc);
            rbox = x.bounds().0.max_l(rbox);
        } else {
            *left.get_mut(l)? = *x;
            l += 1;
            lacc = cc.max_l(lacc);
            lbox = x.bounds().0.max_l(lbox);
        }
    }
    (l == left.len() && r == 0).then_some([lacc, racc, lbox, rbox])
}

/// Centroid bounds from the negated-min form (`[-lo, hi]`, grown by `max`).
pub(crate) fn cbounds_of(acc: f32x8) -> CBounds {
    let [nlo, hi]: [f32x4; 2] = bytemuck::cast(acc);
    CBounds { lo: -nlo, hi }
}

/// Ranges of at most this many references are split by [`find_small`], not by binning.
pub(crate) const SMALL: usize = 16;

/// The best split of a small range (`2 ..= SMALL` references) by an exact sweep on the axes in the
/// bit mask `axes`: on each axis the references are ordered by centroid and every boundary is
/// evaluated with prefix and suffix areas. Cheaper than binning at this size (no bins to clear and
/// sweep) and exact. Returns the split and the order: `order[..left_count]` go left.
pub(crate) fn find_small(refs: &[PrimRef], axes: u32) -> Option<(BinSplit, [u8; SMALL])> {
    let n = refs.len();
    if !(2..=SMALL).contains(&n) {
        return None;
    }
    if n == 2 {
        // One partition only.
        let (l, r) = (refs[0].bounds(), refs[1].bounds());
        let mut order = [0u8; SMALL];
        order[1] = 1;
        let split = BinSplit {
            axis: 0,
            plane: 0,
            cost: l.half_area_nonempty() + r.half_area_nonempty(),
            left_count: 1,
            left: l,
            right: r,
        };
        return Some((split, order));
    }
    // Local copies: boxes, and centroids per axis (unused lanes +inf, so they sort last).
    let mut boxes = [Box8::EMPTY; SMALL];
    let mut cen = [[f32::INFINITY; SMALL]; 3];
    for (i, r) in refs.iter().enumerate() {
        boxes[i] = r.bounds();
        let c = r.c2().to_array();
        cen[0][i] = c[0];
        cen[1][i] = c[1];
        cen[2][i] = c[2];
    }
    let mut best: Option<(BinSplit, [u8; SMALL])> = None;
    for (axis, keys) in cen.iter().enumerate() {
        if axes >> axis & 1 == 0 {
            continue;
        }
        // Ranks without branches: rank(i) = #{j : k_j < k_i}; where keys tie (rare), the stable
        // rank(i) = #{j : k_j < k_i} + #{j < i : k_j == k_i} instead.
        let (kv0, kv1) = (f32x8::load(&keys[..8]), f32x8::load(&keys[8..]));
        let mut order = [0u8; SMALL];
        let mut seen = 0u32;
        for (i, &k) in keys[..n].iter().enumerate() {
            let ki = f32x8::splat(k);
            let rank = (kv0.lt(ki).bitmask() | kv1.lt(ki).bitmask() << 8).count_ones() as usize;
            order[rank & (SMALL - 1)] = i as u8;
            seen |= 1 << (rank & (SMALL - 1));
        }
        if seen != (1u32 << n) - 1 {
            // Some ranks coincide: ties.
            for (i, &k) in keys[..n].iter().enumerate() {
                let ki = f32x8::splat(k);
                let less = kv0.lt(ki).bitmask() | kv1.lt(ki).bitmask() << 8;
                let tied = kv0.eq(ki).bitmask() | kv1.eq(ki).bitmask() << 8;
                let tied_before = tied & ((1u32 << i) - 1);
                let rank = (less.count_ones() + tied_before.count_ones()) as usize;
                order[rank & (SMALL - 1)] = i as u8;
            }
        }
        // Sweep from the right to get suffix areas.
        let mut right_area = [0.0f32; SMALL];
        let mut acc = Box8::EMPTY;
        for i in (1..n).rev() {
            acc.grow(boxes[order[i] as usize & (SMALL - 1)]);
            right_area[i] = acc.half_area_nonempty();
        }
        // Sweep from the left; the boundary after position i puts i + 1 refs left.
        let mut acc = Box8::EMPTY;
        let mut axis_best = (f32::INFINITY, 0usize);
        for i in 0..n - 1 {
            acc.grow(boxes[order[i] as usize & (SMALL - 1)]);
            let cost = acc.half_area_nonempty() * (i + 1) as f32 + right_area[i + 1] * (n - i - 1) as f32;
            if cost < axis_best.0 {
                axis_best = (cost, i);
            }
        }
        let (cost, i) = axis_best;
        if cost < best.as_ref().map_or(f32::INFINITY, |b| b.0.cost) {
            let split = BinSplit {
                axis,
                plane: i,
                cost,
                left_count: (i + 1) as u32,
                left: Box8::EMPTY,
                right: Box8::EMPTY,
            };
            best = Some((split, order));
        }
    }
    let (mut split, order) = best?;
    let k = split.left_count as usize;
    split.left = order[..k]
        .iter()
        .fold(Box8::EMPTY, |a, &i| a.union(boxes[i as usize & (SMALL - 1)]));
    split.right = order[k..n]
        .iter()
        .fold(Box8::EMPTY, |a, &i| a.union(boxes[i as usize & (SMALL - 1)]));
    Some((split, order))
}

/// Moves `src` into `dst` in `order` (from [`find_small`]); returns both sides' centroid bounds.
pub(crate) fn reorder_small(
    src: &[PrimRef],
    dst: &mut [PrimRef],
    order: &[u8],
    left_count: usize,
) -> (CBounds, CBounds) {
    let (mut lcb, mut rcb) = (CBounds::EMPTY, CBounds::EMPTY);
    for (k, (d, &o)) in dst.iter_mut().zip(order).enumerate() {
        let r = src[o as usize];
        *d = r;
        if k < left_count {
            lcb.grow(r.c2());
        } else {
            rcb.grow(r.c2());
        }
    }
    (lcb, rcb)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;
    use crate::scene::Rng;
    use alloc::vec::Vec;
    use glam::Vec3;

    /// The exact sweep by brute force: every axis, references sorted stably by centroid.
    fn brute(refs: &[PrimRef], axes: u32) -> (f32, usize, Vec<u32>) {
        let mut best = (f32::INFINITY, 0, Vec::new());
        for axis in 0..3 {
            if axes >> axis & 1 == 0 {
                continue;
            }
            let mut order: Vec<usize> = (0..refs.len()).collect();
            order.sort_by(|&a, &b| refs[a].c2_axis(axis).total_cmp(&refs[b].c2_axis(axis)));
            for k in 1..refs.len() {
                let side = |o: &[usize]| o.iter().fold(Box8::EMPTY, |acc, &i| acc.union(refs[i].bounds()));
                let (l, r) = (side(&order[..k]), side(&order[k..]));
                let cost = l.half_area_nonempty() * k as f32 + r.half_area_nonempty() * (refs.len() - k) as f32;
                if cost < best.0 {
                    best = (cost, axis, order.iter().map(|&i| refs[i].index()).collect());
                }
            }
        }
        best
    }

    #[test]
    fn sample_stride_and_indices() {
        // Sampling starts at `2 S` references, never where the node may be a leaf or `S` is 0.
        assert_eq!(sample_stride(2 * 64 - 1, 64, false), 1);
        assert_eq!(sample_stride(2 * 64, 64, false), 2);
        assert_eq!(sample_stride(3 * 64 - 1, 64, false), 2);
        assert_eq!(sample_stride(1 << 20, 4096, false), 256);
        assert_eq!(sample_stride(1 << 20, 4096, true), 1);
        assert_eq!(sample_stride(u32::MAX, 0, false), 1);
        assert_eq!(sample_stride(u32::MAX, u32::MAX, false), 1);
        assert_eq!(sample_stride(u32::MAX, 1 << 31, false), 1);
        for stride in [1usize, 2, 3, 5, 20, 256, 1 << 20] {
            for j in [0usize, 1, 2, 7, 1000, 123_456] {
                let i = sample_index(j, stride);
                assert!((j * stride..(j + 1) * stride).contains(&i), "{j} {stride}");
            }
        }
        // A repeating order (period 5, dividing the stride 20): every residue sampled.
        let residues: alloc::collections::BTreeSet<usize> = (0..1000).map(|j| sample_index(j, 20) % 5).collect();
        assert_eq!(residues.len(), 5);
    }

    /// The sample's split, on boxes repeating with a period that divides the stride: the
    /// stratified sample sees all five boxes (its sides' union is the node's box), where every
    /// `stride`-th reference from the first would be the same box, and no plane.
    #[test]
    fn sampled_split_sees_a_periodic_order() {
        let five: Vec<Aabb> = (0..5)
            .map(|i| {
                let p = Vec3::new(i as f32 * 10.0, 0.0, 0.0);
                Aabb::new(p, p + Vec3::ONE)
            })
            .collect();
        let refs: Vec<PrimRef> = (0..20_000).map(|i| PrimRef::new(&five[i % 5], i as u32)).collect();
        let (bx, cb) = crate::build::topdown::bounds_of(&refs);
        let binning = Binning::new(&cb, 8);
        let mut bins = Bins::new();
        let stride = sample_stride(20_000, 1000, false);
        assert_eq!(stride % 5, 0);
        let s = find_sampled(&refs, &binning, 8, true, stride, &mut bins).unwrap();
        // Lanes 0..3 `-min`, 4..7 `max` (lanes 3 and 7 are not coordinates).
        let (got, want) = (s.left.union(s.right).0.to_array(), bx.0.to_array());
        for k in [0, 1, 2, 4, 5, 6] {
            assert_eq!(got[k], want[k], "lane {k}");
        }
        let plain: Vec<PrimRef> = refs.iter().step_by(stride).copied().collect();
        assert!(find(&plain, &binning, 8, true, &mut bins).is_none());
    }

    #[test]
    fn find_small_matches_brute_force_with_ties() {
        let mut rng = Rng::new(5);
        for round in 0..400 {
            let n = 2 + round % (SMALL - 1);
            // Integer grid of few cells: many tied centroids (the stable-rank path).
            let cells = if round % 2 == 0 { 3.0 } else { 1000.0 };
            let refs: Vec<PrimRef> = (0..n)
                .map(|i| {
                    let p = Vec3::new(rng.range(0.0, cells), rng.range(0.0, cells), rng.range(0.0, cells)).floor();
                    let e = Vec3::new(rng.range(0.1, 2.0), rng.range(0.1, 2.0), rng.range(0.1, 2.0));
                    PrimRef::new(&Aabb::new(p, p + e), i as u32)
                })
                .collect();
            for axes in [7, 1, 2, 4] {
                let (split, order) = find_small(&refs, axes).unwrap();
                let (cost, axis, want) = brute(&refs, axes);
                assert_eq!(split.cost, cost, "round {round} axes {axes}");
                if n > 2 {
                    assert_eq!(split.axis, axis);
                    let got: Vec<u32> = order[..n].iter().map(|&i| refs[i as usize].index()).collect();
                    assert_eq!(got, want, "round {round} axes {axes}");
                }
            }
        }
    }
}
