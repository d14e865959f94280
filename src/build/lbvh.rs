//! Linear BVH ([`Strategy::Lbvh`](super::Strategy::Lbvh)): Lauterbach et al., "Fast BVH
//! Construction on GPUs" (2009), with the split rule of Karras, "Maximizing Parallelism in the
//! Construction of BVHs, Octrees, and k-d Trees" (2012).
//!
//! 1. Morton codes of the box centroids ([`geometry::morton`](crate::geometry::morton), 30 or 63
//!    bits, eight at a time), quantised over the centroid bounds.
//! 2. The order: that of a stable sort by code. Duplicate codes are made unique by appending each
//!    key's position in that order, as Karras does. A run of 8 or more equal codes (one grid cell)
//!    is first put in the Morton order of its own centroid bounds ([`order_runs`]; the codes
//!    stay), its *sub-codes*: one far outlier otherwise leaves everything else in one cell, in
//!    input order.
//! 3. The hierarchy: a range of sorted codes is split where its highest differing bit turns from
//!    0 to 1; a range of equal codes in an ordered run the same way by the top bits of its
//!    sub-codes ([`Runs`], as if appended to the codes; as many bits as the depth bound allows,
//!    [`sub_bits`]); a range where those are equal too at the highest bit in which the positions
//!    of its ends differ (a balanced split). Leaves hold `min_leaf_size` references, or up to
//!    `max_leaf_size` whose codes (and kept sub-code bits) are all equal.
//! 4. Boxes: a leaf's is the union of its references', an interior node's that of its
//!    children's.
//!
//! Two implementations of steps 2 to 4 build the same tree (tested):
//!
//! - **30-bit codes, bottom-up** ([`bucketed30`], [`BottomUp`]; whenever [`bottom_up_ok`]: for
//!   `BuildParams::fastest()` always). One stable counting pass on the top 6 code bits moves the
//!   references into 64 buckets (sequential reads, one write stream per bucket); bucket by
//!   bucket, the keys `(code, position)` are sorted in cache (three 8-bit LSD passes) and the
//!   references fed in that order to a one-pass bottom-up construction: the split of a range is
//!   its boundary of largest "separator" (highest differing bit), so the hierarchy is the
//!   Cartesian tree of the separators, which a stack builds left to right (as Apetrei, "Fast and
//!   Simple Agglomerative LBVH Construction", 2014, builds it bottom-up); boxes are unions on the
//!   way up, and the leaves are the largest subtrees that qualify. No binary searches, no sorted
//!   copy of the references; nodes laid out in post-order.
//!   On several threads ([`bucketed30_par`], `std`), the codes and the scatter run in chunks
//!   and the buckets side by side, each into its own node array; a bucket is a whole subtree
//!   of the sequential tree, so joining the buckets' roots in order and copying their arrays
//!   into place gives the sequential tree byte for byte (tested).
//! - **Top-down** ([`walk`]; 63-bit codes, HLBVH's clusters, and a `max_depth` too small for the
//!   bound below). The references in Morton order ([`sort_gather30`], or an LSD radix sort of
//!   `(code, reference)` pairs and a gather for 63-bit codes), then an explicit stack splits each
//!   range at the position found by binary search, and computes boxes when a "finish" entry below
//!   the children is popped.
//!
//! PERF (1M thin soup, one core, `BuildParams::fastest()`, warm builder): the bottom-up path
//! builds in about 47 ms where `sort_gather30` and the walk took about 60 (26 ms to sort and
//! gather the references, 26 ms to walk them). Tried on the way and dropped: one global sort of
//! the keys (a top-digit scatter, then buckets in cache) feeding the bottom-up pass with
//! prefetched reads of the references in input order: those 1M random reads took 17 of the pass's
//! 37 ms, even with the references on huge pages, where the bucketed references are read once in
//! order and then from the cache. Earlier, for the walk: a second, cache-sized array of every
//! 32nd (or 8th) code to narrow the split search (no gain), `sort_unstable` within the buckets
//! (slower than the two counting passes).
//!
//! The depth bound of [`BuildParams::max_depth`] holds as in the top-down builders: a split that
//! would break it is replaced by the middle of the range. (The bottom-up path never meets such a
//! split: see [`bottom_up_ok`].)

use super::builder::{Builder, Counters};
use super::prims::{Box8, PrepInfo, PrimRef, depth_ok};
use super::radix::{Item, sort_items};
use super::{BuildParams, Bvh2, MortonBits, Node};
use crate::geometry::morton::{MortonQuantizer, morton30_scalar, morton30_x8, morton63_scalar, morton63_x8};
use crate::math::f32x8;
use alloc::vec::Vec;
use glam::Vec3;

/// A sort key: 30-bit codes in `u32`, 63-bit codes in `u64`.
pub(crate) trait Code: super::radix::RadixKey {
    /// The highest bit in which `a` and `b` differ, if any.
    fn high_bit_of_xor(a: Self, b: Self) -> Option<u32>;
    fn bit_set(self, bit: u32) -> bool;
}

impl Code for u32 {
    #[inline]
    fn high_bit_of_xor(a: Self, b: Self) -> Option<u32> {
        let x = a ^ b;
        (x != 0).then(|| 31 - x.leading_zeros())
    }
    #[inline]
    fn bit_set(self, bit: u32) -> bool {
        self >> bit & 1 != 0
    }
}

impl Code for u64 {
    #[inline]
    fn high_bit_of_xor(a: Self, b: Self) -> Option<u32> {
        let x = a ^ b;
        (x != 0).then(|| 63 - x.leading_zeros())
    }
    #[inline]
    fn bit_set(self, bit: u32) -> bool {
        self >> bit & 1 != 0
    }
}

/// Builds an LBVH.
pub(crate) fn build(b: &mut Builder, info: &PrepInfo, p: &BuildParams, out: &mut Bvh2, threads: usize) -> Counters {
    // NOTE: the codes quantise doubled centroids `min + max` over their bounds: the same cells as
    // centroids over centroid bounds, one multiply fewer.
    let cb = info.cbounds.to_aabb();
    let Builder {
        refs,
        alt,
        items32,
        items64,
        tmp64,
        packed,
        packed_tmp,
        codes,
        runs,
        ..
    } = b;
    runs.reset(sub_bits(refs.len(), p));
    match p.morton_bits {
        MortonBits::Bits30 if bottom_up_ok(refs.len(), p) => {
            let q = p.quantizer(&cb);
            // Inputs below 65,536 references per thread (and builds without `std`) take the
            // sequential pass.
            let parts = threads.min(refs.len() / 65_536);
            #[cfg(feature = "std")]
            if parts >= 2 {
                return bucketed30_par(refs, alt, items32, &mut b.bucket_nodes, &q, p, out, parts);
            }
            let _ = parts;
            bucketed30(refs, alt, codes, packed, packed_tmp, &q, p, out)
        }
        MortonBits::Bits30 => {
            let q = p.quantizer(&cb);
            sort_gather30(refs, alt, items32, packed, packed_tmp, &q, out, runs);
            walk_sorted(refs, items32, runs, p, out)
        }
        MortonBits::Bits63 => {
            let q = p.quantizer(&cb);
            codes_of(
                refs,
                items64,
                |p| morton63_scalar(p, &q),
                |x, y, z| morton63_x8(x, y, z, &q),
            );
            sort_items(items64, tmp64, 63);
            order_item_runs(items64, refs, packed, runs);
            hierarchy(refs, alt, items64, runs, p, out)
        }
    }
}

/// The code of every reference's doubled centroid, with the reference's position, into `codes`;
/// eight at a time.
pub(crate) fn codes_of<K: Copy>(
    refs: &[PrimRef],
    codes: &mut Vec<Item<K>>,
    one: impl Fn(Vec3) -> K,
    eight: impl Fn(f32x8, f32x8, f32x8) -> [K; 8],
) {
    codes.clear();
    codes.reserve(refs.len());
    let mut chunks = refs.chunks_exact(8);
    for (k, c) in (&mut chunks).enumerate() {
        let mut xyz = [[0.0f32; 8]; 3];
        for (i, r) in c.iter().enumerate() {
            let v = r.c2().to_array();
            xyz[0][i] = v[0];
            xyz[1][i] = v[1];
            xyz[2][i] = v[2];
        }
        let keys = eight(f32x8::new(xyz[0]), f32x8::new(xyz[1]), f32x8::new(xyz[2]));
        let base = 8 * k as u32;
        codes.extend((0..8).map(|i| Item {
            key: keys[i],
            val: base + i as u32,
        }));
    }
    let base = codes.len() as u32;
    for (i, r) in chunks.remainder().iter().enumerate() {
        codes.push(Item {
            key: one(r.c2_vec3()),
            val: base + i as u32,
        });
    }
}

/// A step of the hierarchy walk.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Step {
    /// Split (or make a leaf of) sorted range `begin..end` into node `node`.
    Visit {
        node: u32,
        begin: u32,
        end: u32,
        depth: u32,
    },
    /// Both children of `node` (over `begin..end`) are done: its box is their union.
    Finish { node: u32, begin: u32, end: u32 },
}

/// The hierarchy walk's stacks, and whether it makes SAH leaves.
#[derive(Clone, Debug, Default)]
pub(crate) struct WalkStack {
    steps: Vec<Step>,
    /// SAH costs and heights of finished subtrees (with `sah_leaves`), post-order.
    costs: Vec<(f32, u32)>,
    /// Collapse a finished subtree of at most `max_leaf_size` primitives into one leaf where
    /// the leaf is cheaper by the SAH (its nodes are the last ones in the array, so this is a
    /// truncation). Off for [`Strategy::Lbvh`](super::Strategy::Lbvh).
    pub sah_leaves: bool,
}

/// Builds the tree over the sorted `codes` (each with the position of its reference).
fn hierarchy<K: Code>(
    refs: &[PrimRef],
    sorted: &mut Vec<PrimRef>,
    codes: &[Item<K>],
    runs: &Runs,
    p: &BuildParams,
    out: &mut Bvh2,
) -> Counters {
    let n = refs.len();
    gather(refs, sorted, codes, out);
    let mut c = Counters::default();
    out.nodes.reserve((2 * n).saturating_sub(1));
    out.nodes.push(<Node as bytemuck::Zeroable>::zeroed());
    // Left children are visited first; the stack holds a right sibling and a finish per level.
    let mut stack = WalkStack::default();
    stack.steps.reserve(2 * p.max_depth as usize + 2);
    walk(
        &mut out.nodes,
        sorted,
        codes,
        runs,
        p,
        [0, 0, n as u32, 1],
        &mut stack,
        &mut c,
    );
    c
}

/// Bits of the top digit that [`sort_gather30`] and [`bucketed30`] bucket by (64 buckets).
// PERF: 1M soup, `fastest()`, Intel Xeon (2026-12-06; phases timed by hand, best of 7 builds,
// three binaries taking turns three times): with 256 buckets the scatter of the 32-byte
// references took 17.9-18.5 ms, with 128 buckets 17.4, with 64 buckets 5.0-6.1 (64 write streams
// stay in the L1 cache's reach). The buckets (about 16,000 references, 512 KB) are still sorted
// in the 2 MB L2 cache: their phase grew from 24.3-24.9 ms to 26.8-28.0, and the whole build went
// from 56.0-57.2 ms to 45.4-47.7.
const TOP_BITS: u32 = 6;

/// Sorts `refs` by the 30-bit Morton codes of their doubled centroids (quantised by `q`) without
/// random reads over all of `refs`:
///
/// 1. One pass computes the codes (eight at a time) into `items` and counts the top
///    [`TOP_BITS`] bits.
/// 2. One stable counting pass on the top digit moves the references into `alt` (sequential
///    reads, one write stream per bucket); each one's code travels along in its lane 7
///    ([`PrimRef::with_tag`]).
/// 3. Each bucket (about 16,000 references of a 1M-triangle even scene, in the L2 cache) is sorted by
///    `(code, position)` and gathered back into `refs`, lane 7 cleared.
///
/// The order is that of a stable sort by code, with runs of equal codes then ordered by
/// [`order_runs`]. On return `items` holds the sorted codes (values: their positions), `refs` the
/// references in that order, `out.prim_indices` their primitive indices and `runs` (reset by the
/// caller to its sub-code bits) the ordered runs; `alt` and `packed` hold garbage.
// PERF: measured on the 1M soup against codes, a full LSD radix sort of (code, position) and a
// gather of the references in sorted order (random 32-byte reads, TLB and latency bound): about
// half the time (phase timings under load: 80 to 40 ms; see the module docs).
#[allow(clippy::too_many_arguments)]
pub(crate) fn sort_gather30(
    refs: &mut [PrimRef],
    alt: &mut Vec<PrimRef>,
    items: &mut Vec<Item<u32>>,
    packed: &mut Vec<u64>,
    packed_tmp: &mut Vec<u64>,
    q: &MortonQuantizer,
    out: &mut Bvh2,
    runs: &mut Runs,
) {
    const BUCKETS: usize = 1 << TOP_BITS;
    const SHIFT: u32 = 30 - TOP_BITS;
    let n = refs.len();
    let digit = |code: u32| (code >> SHIFT) as usize & (BUCKETS - 1);
    // Codes (into `items`, in input order), and the histogram of the top digit.
    let mut start = [0u32; BUCKETS + 1];
    items.resize(n, Item::default());
    codes30(refs, items, q);
    for it in items.iter() {
        start[digit(it.key)] += 1;
    }
    // Exclusive prefix sums: the first slot of each bucket.
    let mut sum = 0u32;
    for c in start.iter_mut() {
        let v = *c;
        *c = sum;
        sum += v;
    }
    // NOTE: resized only when the length changes; every slot is written before it is read.
    if alt.len() != n {
        alt.resize(n, PrimRef(Default::default()));
    }
    out.prim_indices.resize(n, 0);
    // Stable scatter by the top digit; the code travels in lane 7 of the reference (one write
    // stream per bucket, not two).
    let mut cursor = start;
    for (r, it) in refs.iter().zip(items.iter()) {
        let slot = &mut cursor[digit(it.key)];
        // `*slot < n`: the prefix sums of a histogram of n keys.
        if let Some(d) = alt.get_mut(*slot as usize) {
            *d = r.with_tag(it.key);
        }
        *slot += 1;
    }
    // Sort each bucket by (code, position in the bucket) and gather it back.
    for w in start.windows(2) {
        let (a, b) = (w[0] as usize, (w[1] as usize).min(n));
        if a >= b {
            continue;
        }
        sort_bucket_gather(
            a,
            &alt[a..b],
            &mut refs[a..b],
            &mut items[a..b],
            &mut out.prim_indices[a..b],
            packed,
            packed_tmp,
            runs,
        );
    }
}

/// [`sort_gather30`] on up to `threads` threads (`std`): the same order, codes, references,
/// primitive indices and runs. The references in equal chunks, one per thread: each computes its chunk's
/// codes and top-digit histogram; the chunks then scatter side by side, each into its own run of
/// every bucket (runs in chunk order: the order of the stable sequential scatter); then the
/// buckets are sorted and gathered side by side. Inputs below 65,536 references per thread (and
/// builds without `std`) take the sequential function.
#[allow(clippy::too_many_arguments)]
pub(crate) fn sort_gather30_par(
    refs: &mut [PrimRef],
    alt: &mut Vec<PrimRef>,
    items: &mut Vec<Item<u32>>,
    packed: &mut Vec<u64>,
    packed_tmp: &mut Vec<u64>,
    q: &MortonQuantizer,
    out: &mut Bvh2,
    runs: &mut Runs,
    threads: usize,
) {
    let parts = threads.min(refs.len() / 65_536);
    #[cfg(feature = "std")]
    if parts >= 2 {
        sort_gather30_chunks(refs, alt, items, q, out, runs, parts);
        return;
    }
    let _ = parts;
    sort_gather30(refs, alt, items, packed, packed_tmp, q, out, runs);
}

/// [`sort_gather30_par`] in `parts` chunks.
#[cfg(feature = "std")]
fn sort_gather30_chunks(
    refs: &mut [PrimRef],
    alt: &mut Vec<PrimRef>,
    items: &mut Vec<Item<u32>>,
    q: &MortonQuantizer,
    out: &mut Bvh2,
    runs: &mut Runs,
    parts: usize,
) {
    use core::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    const BUCKETS: usize = 1 << TOP_BITS;
    let n = refs.len();
    let start = scatter30_chunks(refs, alt, items, q, parts);
    out.prim_indices.resize(n, 0);
    // 3. Each bucket sorted and gathered back, side by side.
    // Each bucket's runs, joined in order at the end.
    let mut bucket_runs: Vec<Runs> = (0..BUCKETS)
        .map(|_| Runs {
            bits: runs.bits,
            ..Runs::default()
        })
        .collect();
    {
        type BucketJob<'a> = (
            usize,
            &'a mut [PrimRef],
            &'a mut [Item<u32>],
            &'a mut [u32],
            &'a mut Runs,
        );
        let (mut r, mut it, mut pi) = (&mut refs[..], &mut items[..n], &mut out.prim_indices[..n]);
        let mut jobs: Vec<Mutex<Option<BucketJob<'_>>>> = Vec::with_capacity(BUCKETS);
        for (w, br) in start.windows(2).zip(bucket_runs.iter_mut()) {
            // NOTE: the lengths before `take` empties the slices.
            let len = ((w[1] - w[0]) as usize).min(r.len()).min(it.len()).min(pi.len());
            let (a, ra) = core::mem::take(&mut r).split_at_mut(len);
            let (b, rb) = core::mem::take(&mut it).split_at_mut(len);
            let (c, rc) = core::mem::take(&mut pi).split_at_mut(len);
            (r, it, pi) = (ra, rb, rc);
            jobs.push(Mutex::new(Some((w[0] as usize, a, b, c, br))));
        }
        let alt = &alt[..n];
        let next = AtomicUsize::new(0);
        crate::par::each(0..parts, |_| {
            let (mut keys, mut tmp) = (Vec::new(), Vec::new());
            while let Some(job) = jobs.get(next.fetch_add(1, Ordering::Relaxed)) {
                let Some((a, dr, di, dp, br)) = job.lock().ok().and_then(|mut g| g.take()) else {
                    continue;
                };
                sort_bucket_gather(a, &alt[a..a + dr.len()], dr, di, dp, &mut keys, &mut tmp, br);
            }
        });
    }
    for br in &bucket_runs {
        runs.append(br);
    }
}

/// Phases 1 and 2 of [`sort_gather30_chunks`] and [`bucketed30_par`] in `parts` chunks side by
/// side: the 30-bit codes of `refs` (into `items`' keys) with each chunk's histogram of the top
/// digit, then the stable scatter of the references, tagged with their codes
/// ([`PrimRef::with_tag`]), into the buckets of `alt`, each chunk into its own run of every
/// bucket (runs in chunk order: the order of the sequential scatter). Returns the buckets'
/// starts (and `n` at the end).
#[cfg(feature = "std")]
fn scatter30_chunks(
    refs: &[PrimRef],
    alt: &mut Vec<PrimRef>,
    items: &mut Vec<Item<u32>>,
    q: &MortonQuantizer,
    parts: usize,
) -> [u32; (1 << TOP_BITS) + 1] {
    use core::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    const BUCKETS: usize = 1 << TOP_BITS;
    let n = refs.len();
    let chunk = n.div_ceil(parts.max(1));
    items.resize(n, Item::default());
    // NOTE: resized only when the length changes; every slot is written before it is read.
    if alt.len() != n {
        alt.resize(n, PrimRef(Default::default()));
    }
    // 1. Codes and histograms, chunk by chunk.
    type CodeJob<'a> = (&'a [PrimRef], &'a mut [Item<u32>], &'a mut [u32; BUCKETS]);
    let mut hist = alloc::vec![[0u32; BUCKETS]; parts];
    {
        let jobs: Vec<Mutex<Option<CodeJob<'_>>>> = refs
            .chunks(chunk)
            .zip(items.chunks_mut(chunk))
            .zip(hist.iter_mut())
            .map(|((r, it), h)| Mutex::new(Some((r, it, h))))
            .collect();
        let next = AtomicUsize::new(0);
        crate::par::each(0..parts, |_| {
            while let Some(job) = jobs.get(next.fetch_add(1, Ordering::Relaxed)) {
                let Some((r, it, h)) = job.lock().ok().and_then(|mut g| g.take()) else {
                    continue;
                };
                codes30(r, it, q);
                for i in it.iter() {
                    h[top_digit(i.key)] += 1;
                }
            }
        });
    }
    // Bucket starts, and each chunk's run in each bucket (bucket-major, chunks in order).
    let mut start = [0u32; BUCKETS + 1];
    let mut sum = 0u32;
    for b in 0..BUCKETS {
        start[b] = sum;
        for h in &hist {
            sum += h[b];
        }
    }
    start[BUCKETS] = sum;
    // 2. The scatter: chunk `t` writes its references of bucket `b` to its own run of `alt`.
    let mut runs: Vec<Vec<&mut [PrimRef]>> = (0..parts).map(|_| Vec::with_capacity(BUCKETS)).collect();
    let mut rest = &mut alt[..n];
    for b in 0..BUCKETS {
        for (t, h) in hist.iter().enumerate() {
            // NOTE: the length before `take` empties `rest`.
            let len = (h[b] as usize).min(rest.len());
            let (run, r) = core::mem::take(&mut rest).split_at_mut(len);
            rest = r;
            runs[t].push(run);
        }
    }
    type ScatterJob<'a> = (&'a [PrimRef], &'a [Item<u32>], Vec<&'a mut [PrimRef]>);
    let jobs: Vec<Mutex<Option<ScatterJob<'_>>>> = refs
        .chunks(chunk)
        .zip(items.chunks(chunk))
        .zip(runs)
        .map(|((r, it), runs)| Mutex::new(Some((r, it, runs))))
        .collect();
    let next = AtomicUsize::new(0);
    crate::par::each(0..parts, |_| {
        while let Some(job) = jobs.get(next.fetch_add(1, Ordering::Relaxed)) {
            let Some((r, it, mut runs)) = job.lock().ok().and_then(|mut g| g.take()) else {
                continue;
            };
            let mut at = [0usize; BUCKETS];
            for (r, i) in r.iter().zip(it) {
                let d = top_digit(i.key);
                // The run was cut to this chunk's count of digit `d`: in range.
                if let Some(slot) = runs[d].get_mut(at[d]) {
                    *slot = r.with_tag(i.key);
                }
                at[d] += 1;
            }
        }
    });
    start
}

/// Sorts one bucket of [`sort_gather30`] (its references `src`, tagged with their codes, from
/// slot `a` on) by `(code, position)` and gathers it into `refs` (tags cleared), `items` (codes,
/// and their slots as values) and `prim_indices`, all as long as `src`. `keys` and `tmp` are
/// scratch. Runs of equal codes are ordered ([`order_runs`]) and recorded in `runs`.
#[allow(clippy::too_many_arguments)]
fn sort_bucket_gather(
    a: usize,
    src: &[PrimRef],
    refs: &mut [PrimRef],
    items: &mut [Item<u32>],
    prim_indices: &mut [u32],
    keys: &mut Vec<u64>,
    tmp: &mut Vec<u64>,
    runs: &mut Runs,
) {
    keys.clear();
    keys.extend(src.iter().enumerate().map(|(j, r)| (r.tag() as u64) << 32 | j as u64));
    sort_bucket(keys, tmp);
    order_bucket_runs(keys, src, tmp, |b, k| runs.push(a + b, k));
    let dst = refs.iter_mut().zip(items.iter_mut()).zip(prim_indices.iter_mut());
    for (((d, it), pi), (j, &k)) in dst.zip(keys.iter().enumerate()) {
        // `k as u32` is a position in the bucket: in range.
        let r = src.get(k as u32 as usize).map_or(*d, |r| r.with_tag(0));
        *d = r;
        *it = Item {
            key: (k >> 32) as u32,
            val: (a + j) as u32,
        };
        *pi = r.index();
    }
}

/// The 30-bit codes of `refs`' doubled centroids into `items`' keys (as long), eight at a time.
fn codes30(refs: &[PrimRef], items: &mut [Item<u32>], q: &MortonQuantizer) {
    each_code30(refs, q, |i, code| {
        if let Some(it) = items.get_mut(i) {
            it.key = code;
        }
    });
}

/// `f(i, code)` for the 30-bit code of every reference's doubled centroid, in order, eight at a
/// time.
#[inline(always)]
fn each_code30(refs: &[PrimRef], q: &MortonQuantizer, mut f: impl FnMut(usize, u32)) {
    let mut chunks = refs.chunks_exact(8);
    let mut at = 0;
    for c in &mut chunks {
        let mut xyz = [[0.0f32; 8]; 3];
        for (i, r) in c.iter().enumerate() {
            let v = r.c2().to_array();
            xyz[0][i] = v[0];
            xyz[1][i] = v[1];
            xyz[2][i] = v[2];
        }
        let codes = morton30_x8(f32x8::new(xyz[0]), f32x8::new(xyz[1]), f32x8::new(xyz[2]), q).to_array();
        for (j, &code) in codes.iter().enumerate() {
            f(at + j, code);
        }
        at += 8;
    }
    for (j, r) in chunks.remainder().iter().enumerate() {
        f(at + j, morton30_scalar(r.c2_vec3(), q));
    }
}

/// Runs of at least this many equal codes are put in the Morton order of their own bounds
/// ([`order_runs`]).
const RUN_MIN: usize = 8;
/// Levels of [`order_runs`]: a run's sub-runs of equal sub-codes are re-coded in turn, this many
/// times in all.
const RUN_LEVELS: u32 = 3;

/// Puts each run of at least [`RUN_MIN`] equal codes among sorted `items` in the Morton order of
/// its own centroids: the 30-bit codes of its references' doubled centroids (`c2` of a
/// position) quantised over the run's bounds ([`MortonQuantizer::new_extended`]), ties by
/// position; runs of equal sub-codes again, up to [`RUN_LEVELS`] levels. `pos` reads an item's
/// position and `set` writes one; `same` says whether two items' codes are equal; `emit` gets
/// each ordered run's first index and its keys, `(level-1 sub-code << 32) | position`, in the new
/// order (for [`Runs`]). Only the positions move, never the codes, so every path gets the same
/// order, and the hierarchy splits a run by its sub-codes' high bits ([`Runs`]), then where the
/// sorted positions' highest bit differs.
///
/// Why: a run is a cell of the grid over all centroids, and without this its references stay in
/// input order, so the balanced splits of the run cut nothing in space and every box in it spans
/// the cell. Runs are rare where the centroids spread over the grid, and long where they do not:
/// one far outlier puts everything else in one cell (100,000 triangles in the unit cube beside
/// one at 10^7: the LBVH's cost inside the cube 318x that without the outlier; ordered, 2.6x;
/// split by the sub-codes too, 1.04x).
pub(crate) fn order_runs<T>(
    items: &mut [T],
    same: impl Fn(&T, &T) -> bool,
    pos: impl Fn(&T) -> u32,
    set: impl Fn(&mut T, u32),
    c2: impl Fn(u32) -> Vec3,
    scratch: &mut Vec<u64>,
    mut emit: impl FnMut(usize, &[u64]),
) {
    // The items are sorted, so a run of RUN_MIN or more holds two items 4 apart at a position
    // that is a multiple of 4 from where the search starts: one test per 4 items, and a branch
    // taken only at runs of 5 or more.
    const _: () = assert!(RUN_MIN >= 8);
    let n = items.len();
    let mut i = 0;
    while i + 4 < n {
        let Some(k) = items[i..]
            .iter()
            .step_by(4)
            .zip(items[i + 4..].iter().step_by(4))
            .position(|(a, b)| same(a, b))
        else {
            break;
        };
        i += 4 * k;
        let (mut b, mut e) = (i, i + 5);
        while b > 0 && same(&items[b - 1], &items[i]) {
            b -= 1;
        }
        while e < n && same(&items[e], &items[i]) {
            e += 1;
        }
        if e - b >= RUN_MIN {
            let run = &mut items[b..e];
            scratch.clear();
            scratch.extend(run.iter().map(|it| u64::from(pos(it))));
            recode(scratch, &c2, 1);
            for (it, &k) in run.iter_mut().zip(scratch.iter()) {
                set(it, k as u32);
            }
            emit(b, scratch);
        }
        i = e;
    }
}

/// Sorts `keys` (positions in the low halves) by the 30-bit codes of their centroids over their
/// own bounds, then position; recurses into runs of equal codes up to level [`RUN_LEVELS`]. On
/// return the high halves hold this level's codes (0 where the centroids are all one point).
fn recode(keys: &mut [u64], c2: &impl Fn(u32) -> Vec3, level: u32) {
    let mut b = crate::geometry::Aabb::EMPTY;
    for &k in keys.iter() {
        b.grow(c2(k as u32));
    }
    // All centroids on one point (or a NaN extent): nothing to order by.
    if b.extent().max_element().partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
        return;
    }
    let q = MortonQuantizer::new_extended(&b, crate::geometry::morton::BITS_PER_AXIS_30);
    for k in keys.iter_mut() {
        let at = *k as u32;
        *k = u64::from(morton30_scalar(c2(at), &q)) << 32 | u64::from(at);
    }
    keys.sort_unstable();
    if level >= RUN_LEVELS {
        return;
    }
    let mut s = 0;
    while let Some(&first) = keys.get(s) {
        let len = 1 + keys[s + 1..].iter().take_while(|&&k| k >> 32 == first >> 32).count();
        if len >= RUN_MIN {
            let sub = &mut keys[s..s + len];
            recode(sub, c2, level + 1);
            // This level's code back in the high halves.
            for k in sub.iter_mut() {
                *k = first >> 32 << 32 | *k & 0xffff_ffff;
            }
        }
        s += len;
    }
}

/// [`order_runs`] on sorted `items` whose values are positions in `refs`; the runs into `runs`.
pub(crate) fn order_item_runs<K: PartialEq>(
    items: &mut [Item<K>],
    refs: &[PrimRef],
    scratch: &mut Vec<u64>,
    runs: &mut Runs,
) {
    order_runs(
        items,
        |a, b| a.key == b.key,
        |it| it.val,
        |it, at| it.val = at,
        |at| refs.get(at as usize).map_or(Vec3::ZERO, PrimRef::c2_vec3),
        scratch,
        |b, keys| runs.push(b, keys),
    );
}

/// [`order_runs`] on a bucket's sorted keys `(code << 32) | position in src`; `emit` as there.
fn order_bucket_runs(keys: &mut [u64], src: &[PrimRef], scratch: &mut Vec<u64>, emit: impl FnMut(usize, &[u64])) {
    order_runs(
        keys,
        |a, b| a >> 32 == b >> 32,
        |&k| k as u32,
        |k, at| *k = *k >> 32 << 32 | u64::from(at),
        |at| src.get(at as usize).map_or(Vec3::ZERO, PrimRef::c2_vec3),
        scratch,
        emit,
    );
}

/// The runs [`order_runs`] ordered, by sorted position, with the top [`bits`](Self::reset)
/// bits of their level-1 sub-codes: within a run of equal codes the hierarchy splits where
/// those differ (as if they were appended to the code), then where the positions do. Empty
/// where there are no runs or no bits.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Runs {
    /// Each run: its first sorted position, its end, and where its sub-codes start in `subs`.
    spans: Vec<[u32; 3]>,
    /// The runs' sub-codes (cut to `bits`), run after run.
    subs: Vec<u32>,
    bits: u32,
}

impl Runs {
    /// Empties it for sub-codes of `bits` bits (at most 30; 0: none kept, no splits by them).
    pub(crate) fn reset(&mut self, bits: u32) {
        self.spans.clear();
        self.subs.clear();
        self.bits = bits.min(30);
    }

    /// Records the run at sorted positions `begin..` with keys `keys` (see [`order_runs`]),
    /// unless its sub-codes' kept bits are all equal (nothing to split by).
    fn push(&mut self, begin: usize, keys: &[u64]) {
        let sub = |k: u64| kept_sub(k, self.bits);
        if self.bits == 0 || keys.first().map(|&k| sub(k)) == keys.last().map(|&k| sub(k)) {
            return;
        }
        self.spans
            .push([begin as u32, (begin + keys.len()) as u32, self.subs.len() as u32]);
        self.subs.extend(keys.iter().map(|&k| sub(k)));
    }

    /// Appends `other`'s runs (at later positions).
    #[cfg(feature = "std")]
    fn append(&mut self, other: &Runs) {
        let at = self.subs.len() as u32;
        self.spans.extend(other.spans.iter().map(|&[b, e, o]| [b, e, o + at]));
        self.subs.extend_from_slice(&other.subs);
    }

    /// The sub-codes of sorted positions `b..e` where they lie in one recorded run.
    #[inline]
    pub(crate) fn subs_of(&self, b: u32, e: u32) -> Option<&[u32]> {
        let [sb, se, at] = *self
            .spans
            .get(self.spans.partition_point(|s| s[0] <= b).checked_sub(1)?)?;
        if e > se {
            return None;
        }
        self.subs.get((at + b - sb) as usize..(at + e - sb) as usize)
    }

    /// Whether sorted positions `b..e`, whose codes are equal, have equal sub-codes too.
    #[inline]
    fn same_subs(&self, b: u32, e: u32) -> bool {
        self.subs_of(b, e).is_none_or(|s| s.first() == s.last())
    }
}

/// The top `bits` bits (at most 30) of the level-1 sub-code in the high half of an
/// [`order_runs`] key.
#[inline]
fn kept_sub(key: u64, bits: u32) -> u32 {
    (key >> 32) as u32 >> (30 - bits.min(30))
}

/// Sub-code bits the LBVH splits runs by ([`Runs`]) for `n` references: what the depth bound
/// leaves beside 30 code bits and the positions' bits (see [`bottom_up_ok`]), at most 30; 13 for
/// a million references under the default bound of 64. (HLBVH keeps all 30: its clusters' walks
/// force splits where the bound needs them.)
pub(crate) fn sub_bits(n: usize, p: &BuildParams) -> u32 {
    p.max_depth
        .saturating_sub(31 + super::prims::ceil_log2(n.min(u32::MAX as usize) as u32))
        .min(30)
}

/// Sorts one bucket of [`sort_gather30`]: `(code << 32) | position` keys whose codes share their
/// top [`TOP_BITS`] bits. Positions are in increasing order on entry, so a stable sort by the
/// low `30 - TOP_BITS` code bits is a sort by value: three LSD counting passes of 8 bits (one read
/// for the three histograms), or `sort_unstable` for short buckets. The sorted keys end in `keys`
/// (the two vectors may have been swapped); `tmp` is scratch.
// PERF: measured on the 1M soup (buckets of about 4,000, under load): the bucket phase of
// `sort_gather30` took 25 ms with `sort_unstable` on every bucket, 18 ms with two 11-bit passes.
// With buckets of about 16,000 (2026-12-06, Intel Xeon): two 12-bit passes 7.3-7.5 ms, these
// three 8-bit passes 6.1-6.5 ms (4,096 destinations per pass scatter worse than 256).
fn sort_bucket(keys: &mut Vec<u64>, tmp: &mut Vec<u64>) {
    const W: u32 = 8;
    const B: usize = 1 << W;
    const _: () = assert!(3 * W >= 30 - TOP_BITS);
    let m = keys.len();
    if m <= 256 {
        keys.sort_unstable();
        return;
    }
    let mut hist = [[0u32; B]; 3];
    let digit = |k: u64, pass: u32| (k >> (32 + pass * W)) as usize & (B - 1);
    for &k in keys.iter() {
        for (pass, h) in (0..).zip(hist.iter_mut()) {
            h[digit(k, pass)] += 1;
        }
    }
    tmp.resize(m, 0);
    for h in hist.iter_mut() {
        // Exclusive prefix sums: the first output slot of each digit.
        let mut sum = 0u32;
        for c in h.iter_mut() {
            let v = *c;
            *c = sum;
            sum += v;
        }
    }
    // Into `tmp`, back into `keys`, into `tmp` again; then the two swap.
    for (pass, h) in (0..).zip(hist.iter_mut()) {
        let (from, to) = if pass == 1 {
            (&*tmp, &mut *keys)
        } else {
            (&*keys, &mut *tmp)
        };
        for &k in from.iter() {
            let slot = &mut h[digit(k, pass)];
            // `*slot < m`: the prefix sums of a histogram of m keys.
            if let Some(d) = to.get_mut(*slot as usize) {
                *d = k;
            }
            *slot += 1;
        }
    }
    core::mem::swap(keys, tmp);
}

/// The LBVH over `sorted` references whose codes are `codes` (as [`hierarchy`] after its
/// gather; `out.prim_indices` already holds the primitive indices).
fn walk_sorted<K: Code>(
    sorted: &[PrimRef],
    codes: &[Item<K>],
    runs: &Runs,
    p: &BuildParams,
    out: &mut Bvh2,
) -> Counters {
    let n = sorted.len();
    let mut c = Counters::default();
    out.nodes.reserve((2 * n).saturating_sub(1));
    out.nodes.push(<Node as bytemuck::Zeroable>::zeroed());
    let mut stack = WalkStack::default();
    stack.steps.reserve(2 * p.max_depth as usize + 2);
    walk(
        &mut out.nodes,
        sorted,
        codes,
        runs,
        p,
        [0, 0, n as u32, 1],
        &mut stack,
        &mut c,
    );
    c
}

/// Gathers the references into Morton order (one tight pass of random reads, after which every
/// leaf reads a contiguous run) and writes the primitive indices in that order.
pub(crate) fn gather<K>(refs: &[PrimRef], sorted: &mut Vec<PrimRef>, codes: &[Item<K>], out: &mut Bvh2) {
    sorted.clear();
    sorted.extend(codes.iter().map(|it| refs[it.val as usize]));
    out.prim_indices.extend(sorted.iter().map(PrimRef::index));
}

/// Where the LBVH splits sorted range `b..e` (`e - b >= 2`): the first code with the highest
/// differing bit of the range set, or, where all codes are equal, the same by the sub-codes of
/// an ordered run ([`Runs`]), or, where those are equal too, at the highest bit in which the
/// ends' positions differ. Always strictly inside the range for sorted codes.
#[inline]
pub(crate) fn split_point<K: Code>(codes: &[Item<K>], runs: &Runs, b: u32, e: u32) -> u32 {
    let (first, last) = (codes[b as usize].key, codes[e as usize - 1].key);
    match K::high_bit_of_xor(first, last) {
        // The first code in the range with that bit set (the range shares every higher bit).
        Some(bit) => b + codes[b as usize..e as usize].partition_point(|c| !c.key.bit_set(bit)) as u32,
        None => {
            // Sub-codes, sorted within the run: the same rule.
            if let Some(subs) = runs.subs_of(b, e)
                && let (Some(&f), Some(&l)) = (subs.first(), subs.last())
                && let Some(bit) = u32::high_bit_of_xor(f, l)
            {
                return b + subs.partition_point(|&x| !x.bit_set(bit)) as u32;
            }
            // All equal: split the appended positions at their highest differing bit.
            let bit = 31 - (b ^ (e - 1)).leading_zeros();
            (e - 1) >> bit << bit
        }
    }
}

/// The hierarchy over sorted range `begin..end` into the existing node `root` at `depth`
/// (`task = [root, begin, end, depth]`), appending nodes; `sorted` holds the gathered references,
/// `runs` the ordered runs of equal codes. `stack` is scratch (left empty).
#[allow(clippy::too_many_arguments)]
pub(crate) fn walk<K: Code>(
    nodes: &mut Vec<Node>,
    sorted: &[PrimRef],
    codes: &[Item<K>],
    runs: &Runs,
    p: &BuildParams,
    task: [u32; 4],
    ws: &mut WalkStack,
    c: &mut Counters,
) {
    let blank = <Node as bytemuck::Zeroable>::zeroed();
    let [node, begin, end, depth] = task;
    let WalkStack {
        steps: stack,
        costs,
        sah_leaves,
    } = ws;
    let sah = *sah_leaves;
    stack.clear();
    costs.clear();
    stack.push(Step::Visit {
        node,
        begin,
        end,
        depth,
    });
    while let Some(step) = stack.pop() {
        let (node, b, e, depth) = match step {
            Step::Finish { node, begin, end } => {
                let l = nodes[node as usize].left() as usize;
                let bx = Box8::from_node(&nodes[l]).union(Box8::from_node(&nodes[l + 1]));
                nodes[node as usize] = bx.to_node(l as u32, 0);
                if sah {
                    // Post-order: the children's costs are the top two.
                    let ((cr, hr), (cl, hl)) = (costs.pop().unwrap_or_default(), costs.pop().unwrap_or_default());
                    let area = bx.half_area_nonempty();
                    let count = end - begin;
                    let split = p.traversal_cost * area + cl + cr;
                    let leaf = p.intersection_cost * count as f32 * area;
                    if count <= p.max_leaf_size && leaf <= split {
                        // The subtree's nodes are the last ones: drop them, keep the leaf.
                        c.leaves -= leaves_below(count, &nodes[l..]);
                        c.leaves += 1;
                        nodes.truncate(l);
                        nodes[node as usize] = bx.to_node(begin, count);
                        costs.push((leaf, 1));
                    } else {
                        costs.push((split, hl.max(hr) + 1));
                    }
                }
                continue;
            }
            Step::Visit {
                node,
                begin,
                end,
                depth,
            } => (node, begin, end, depth),
        };
        if !sah {
            c.max_depth = c.max_depth.max(depth);
        }
        let count = e - b;
        let (first, last) = (codes[b as usize].key, codes[e as usize - 1].key);
        if count <= p.min_leaf_size || (count <= p.max_leaf_size && first == last && runs.same_subs(b, e)) {
            let bx = sorted[b as usize..e as usize]
                .iter()
                .fold(Box8::EMPTY, |acc, r| acc.union(r.bounds()));
            nodes[node as usize] = bx.to_node(b, count);
            c.leaves += 1;
            if sah {
                costs.push((p.intersection_cost * count as f32 * bx.half_area_nonempty(), 1));
            }
            continue;
        }
        let mut mid = split_point(codes, runs, b, e);
        debug_assert!(b < mid && mid < e);
        if !(b < mid && mid < e && depth_ok(depth, mid - b, e - mid, p.max_depth)) {
            c.forced_splits += 1;
            mid = b + count / 2;
        }
        let left = nodes.len() as u32;
        nodes[node as usize].index = left;
        nodes.push(blank);
        nodes.push(blank);
        stack.push(Step::Finish { node, begin: b, end: e });
        stack.push(Step::Visit {
            node: left + 1,
            begin: mid,
            end: e,
            depth: depth + 1,
        });
        stack.push(Step::Visit {
            node: left,
            begin: b,
            end: mid,
            depth: depth + 1,
        });
    }
    if let Some(&(_, h)) = costs.last() {
        c.max_depth = c.max_depth.max(depth + h - 1);
    }
}

/// `true` if [`BottomUp`] builds exactly the tree of [`walk`] for `n` references: the depth
/// bound can never force a split. On the path to any node the splits consume distinct code bits
/// (at most 30), then distinct kept sub-code bits (at most [`sub_bits`], chosen to fit) and then
/// distinct bits of the positions (at most `ceil(log2 n)`), so a child of `m` references at
/// depth `d + 1` has `d + 1 + ceil(log2 m) <= 31 + sub_bits + ceil(log2 n) <= max_depth`.
#[inline]
pub(crate) fn bottom_up_ok(n: usize, p: &BuildParams) -> bool {
    n <= super::MAX_PRIMITIVES && 31 + super::prims::ceil_log2(n as u32) <= p.max_depth
}

/// A finished subtree of [`BottomUp`], waiting for its parent.
#[derive(Clone, Copy, Debug)]
struct Pending {
    bx: Box8,
    /// Its range of sorted positions.
    begin: u32,
    end: u32,
    /// The keys (code and sub-code, [`BottomUp::feed`]) at `begin` and `end - 1`.
    first: u64,
    last: u64,
    /// Its left child's index (the right one follows), or [`LEAF`] while the subtree may still
    /// become (part of) one leaf.
    pair: u32,
    /// Height (a leaf is 1).
    height: u32,
}

/// [`Pending::pair`] of a leaf candidate.
const LEAF: u32 = u32::MAX;

impl Pending {
    /// Its node: a leaf over its range, or an interior node.
    #[inline(always)]
    fn node(&self) -> Node {
        if self.pair == LEAF {
            self.bx.to_node(self.begin, self.end - self.begin)
        } else {
            self.bx.to_node(self.pair, 0)
        }
    }
}

/// The LBVH built bottom-up from references fed in Morton order ([`feed`](Self::feed), then
/// [`finish`](Self::finish)), the same tree as [`walk`] where [`bottom_up_ok`] holds (tested),
/// laid out in post-order.
///
/// With the sub-code ([`Runs`]) and the position appended to every code (Karras 2012), the split
/// of a range is the one boundary `i | i + 1` inside it of largest "separator": the highest
/// differing bit of the two keys (code and sub-code), above every bit of the positions where the
/// keys are equal. So the hierarchy is the
/// Cartesian tree of the separators (largest at the root), which a stack builds in one pass, as
/// Apetrei ("Fast and Simple Agglomerative LBVH Construction", 2014) builds it bottom-up: a
/// subtree on the stack joins the one to its right while its separator is smaller than the
/// next. Boxes are unions on the way up; the leaves are the largest subtrees that qualify (at
/// most `min_leaf_size` references, or at most `max_leaf_size` with equal keys), exactly those
/// where the top-down walk stops. A finished interior node appends its children's pair to the
/// node array, so every subtree's nodes are contiguous and children come before their parent
/// (the root, at index 0, excepted). No binary searches, and the references are read once.
struct BottomUp {
    /// Subtrees with the separator to their right, `len` of them; separators decrease from
    /// bottom to top, and there are at most 92 values (`0 ..= 91`, see [`separator`]), so at
    /// most 92 entries.
    subs: [Pending; 128],
    seps: [u32; 128],
    len: usize,
    /// The last reference fed and its key (its separator needs the next key).
    prev: PrimRef,
    prev_code: u64,
    /// Sub-code bits below the code in a key ([`Runs`]).
    bits: u32,
    /// The sorted position of the next reference.
    at: u32,
    /// References fed so far.
    fed: u32,
    min_leaf: u32,
    max_leaf: u32,
    c: Counters,
}

impl BottomUp {
    /// A construction over sorted positions `at..` (a bucket of the parallel build starts past
    /// 0). Nodes go to the array the calls pass, each interior node's children at the array's
    /// index where they were appended.
    fn new(p: &BuildParams, at: u32, bits: u32) -> Self {
        Self {
            subs: [Pending {
                bx: Box8::EMPTY,
                begin: 0,
                end: 0,
                first: 0,
                last: 0,
                pair: LEAF,
                height: 0,
            }; 128],
            seps: [0; 128],
            len: 0,
            prev: PrimRef(f32x8::ZERO),
            prev_code: 0,
            bits,
            at,
            fed: 0,
            min_leaf: p.min_leaf_size,
            max_leaf: p.max_leaf_size,
            c: Counters::default(),
        }
    }

    /// The parent of `l` and `r` (adjacent ranges): one leaf candidate if the joint range
    /// qualifies, else an interior node whose children are written out.
    #[inline(always)]
    fn join(&mut self, l: Pending, r: Pending, nodes: &mut impl NodeSink) -> Pending {
        let bx = l.bx.union(r.bx);
        let count = r.end - l.begin;
        // NOTE: qualifying is monotone (a part of a qualifying range qualifies), so a parent can
        // only qualify if both children do.
        if l.pair == LEAF && r.pair == LEAF && (count <= self.min_leaf || (count <= self.max_leaf && l.first == r.last))
        {
            return Pending {
                bx,
                end: r.end,
                last: r.last,
                ..l
            };
        }
        self.c.leaves += u32::from(l.pair == LEAF) + u32::from(r.pair == LEAF);
        let pair = nodes.next_index();
        nodes.push_node(l.node());
        nodes.push_node(r.node());
        Pending {
            bx,
            begin: l.begin,
            end: r.end,
            first: l.first,
            last: r.last,
            pair,
            height: l.height.max(r.height) + 1,
        }
    }

    /// Puts `cur`, whose separator to the right is `sep`, on the stack, first joining the
    /// subtrees on top whose separators are smaller.
    #[inline(always)]
    fn push(&mut self, mut cur: Pending, sep: u32, nodes: &mut impl NodeSink) {
        // `& 127`: a no-op on lengths up to 92 (see `subs`) that drops the bounds checks.
        while self.len > 0 && self.seps[(self.len - 1) & 127] < sep {
            self.len -= 1;
            let l = self.subs[self.len & 127];
            cur = self.join(l, cur, nodes);
        }
        self.subs[self.len & 127] = cur;
        self.seps[self.len & 127] = sep;
        self.len += 1;
    }

    /// The next reference in Morton order (as [`order_runs`] leaves it), its code and its
    /// sub-code (0 outside ordered runs, at most `bits` bits; [`Runs`]).
    #[inline(always)]
    fn feed(&mut self, code: u32, sub: u32, r: PrimRef, nodes: &mut Vec<Node>) {
        let code = self.key(code, sub);
        let (pcode, pr) = (self.prev_code, self.prev);
        self.prev_code = code;
        self.prev = r;
        let i = self.at;
        self.at += 1;
        self.fed += 1;
        // The first reference waits for the second.
        if self.fed == 1 {
            return;
        }
        let i = i - 1;
        self.push(Self::leaf(&pr, i, pcode), separator(pcode, code, i), nodes);
    }

    /// The key of a code and its sub-code (0 outside ordered runs, at most `bits` bits): the
    /// sub-code appended below the code.
    #[inline(always)]
    fn key(&self, code: u32, sub: u32) -> u64 {
        u64::from(code) << self.bits | u64::from(sub)
    }

    #[inline(always)]
    fn leaf(r: &PrimRef, i: u32, code: u64) -> Pending {
        Pending {
            bx: r.bounds(),
            begin: i,
            end: i + 1,
            first: code,
            last: code,
            pair: LEAF,
            height: 1,
        }
    }

    /// Joins what is left into one subtree: its root (not written to `nodes`), or `None` if
    /// nothing was fed.
    fn root(&mut self, nodes: &mut Vec<Node>) -> Option<Pending> {
        if self.fed == 0 {
            return None;
        }
        let last = Self::leaf(&self.prev, self.at - 1, self.prev_code);
        Some(self.close(last, nodes))
    }

    /// Joins every subtree on the stack onto `cur`, the rightmost: the root over all of them.
    fn close(&mut self, mut cur: Pending, nodes: &mut impl NodeSink) -> Pending {
        while self.len > 0 {
            self.len -= 1;
            let l = self.subs[self.len & 127];
            cur = self.join(l, cur, nodes);
        }
        cur
    }

    /// Writes the root of everything fed to `nodes[0]` (the slot kept for it), or empties `nodes`
    /// if nothing was fed; the counters.
    fn finish(mut self, nodes: &mut Vec<Node>) -> Counters {
        let Some(root) = self.root(nodes) else {
            nodes.clear();
            return self.c;
        };
        if root.pair == LEAF {
            self.c.leaves += 1;
        }
        self.c.max_depth = root.height;
        nodes[0] = root.node();
        self.c
    }
}

/// Where [`BottomUp`] appends nodes: a node array, or (for the parallel build's joins across
/// buckets) a record of the nodes and the slots they will take.
trait NodeSink {
    /// The index the next node appended gets.
    fn next_index(&self) -> u32;
    fn push_node(&mut self, n: Node);
}

impl NodeSink for Vec<Node> {
    #[inline(always)]
    fn next_index(&self) -> u32 {
        self.len() as u32
    }
    #[inline(always)]
    fn push_node(&mut self, n: Node) {
        self.push(n);
    }
}

/// Nodes to be written later: each with its slot in a node array that so far holds `len`
/// nodes (the parallel build's joins across buckets, made before the buckets' nodes are
/// copied into place).
#[cfg(feature = "std")]
struct Placed {
    len: u32,
    nodes: Vec<(u32, Node)>,
}

#[cfg(feature = "std")]
impl NodeSink for Placed {
    fn next_index(&self) -> u32 {
        self.len
    }
    fn push_node(&mut self, n: Node) {
        self.nodes.push((self.len, n));
        self.len += 1;
    }
}

/// The separator between sorted positions `i` and `i + 1` with keys `a` and `b` (codes with
/// their sub-codes appended, [`BottomUp::key`]: at most 60 bits): 32 + the highest differing key
/// bit, or, where the keys are equal, the highest differing bit of the positions (see
/// [`BottomUp`]).
#[inline(always)]
fn separator(a: u64, b: u64, i: u32) -> u32 {
    let x = a ^ b;
    if x != 0 {
        95 - x.leading_zeros()
    } else {
        31 - (i ^ (i + 1)).leading_zeros()
    }
}

/// The 30-bit LBVH of `refs` (in input order) through [`BottomUp`], with the references put in
/// Morton order bucket by bucket:
///
/// 1. One pass computes the codes (eight at a time) into `codes` and counts their top
///    [`TOP_BITS`] bits.
/// 2. One stable counting pass on that digit moves the references into `alt` (sequential reads,
///    one write stream per bucket); each one's code travels in its lane 7
///    ([`PrimRef::with_tag`]).
/// 3. Bucket by bucket (about 16,000 references of a 1M-triangle even scene): a sequential read of its
///    references makes the keys `(code << 32) | position in the bucket` and brings them into the
///    cache; [`sort_bucket`] sorts the keys and [`order_runs`] orders the runs of equal codes,
///    whose sub-codes go to `codes` (free after step 2); the references are fed to [`BottomUp`]
///    in that order with their sub-codes, from the cache.
///
/// The order is [`sort_gather30`]'s, but the sorted references are never written out.
// PERF: see the module docs.
#[allow(clippy::too_many_arguments)]
fn bucketed30(
    refs: &[PrimRef],
    alt: &mut Vec<PrimRef>,
    codes: &mut Vec<u32>,
    keys: &mut Vec<u64>,
    tmp: &mut Vec<u64>,
    q: &MortonQuantizer,
    p: &BuildParams,
    out: &mut Bvh2,
) -> Counters {
    const BUCKETS: usize = 1 << TOP_BITS;
    let n = refs.len();
    // Codes (into `codes`, in input order), and the histogram of the top digit.
    let mut start = [0u32; BUCKETS + 1];
    codes.resize(n, 0);
    each_code30(refs, q, |i, code| {
        if let Some(c) = codes.get_mut(i) {
            *c = code;
        }
        start[top_digit(code)] += 1;
    });
    // Exclusive prefix sums: the first slot of each bucket.
    let mut sum = 0u32;
    for c in start.iter_mut() {
        let v = *c;
        *c = sum;
        sum += v;
    }
    // NOTE: resized only when the length changes; every slot is written before it is read.
    if alt.len() != n {
        alt.resize(n, PrimRef(Default::default()));
    }
    let mut cursor = start;
    for (r, &code) in refs.iter().zip(codes.iter()) {
        let slot = &mut cursor[top_digit(code)];
        // `*slot < n`: the prefix sums of a histogram of n keys.
        if let Some(d) = alt.get_mut(*slot as usize) {
            *d = r.with_tag(code);
        }
        *slot += 1;
    }
    out.prim_indices.clear();
    out.prim_indices.reserve(n);
    out.nodes.clear();
    out.nodes.reserve((2 * n).saturating_sub(1));
    // The root's slot.
    out.nodes.push(<Node as bytemuck::Zeroable>::zeroed());
    let bits = sub_bits(n, p);
    let mut bu = BottomUp::new(p, 0, bits);
    // `codes` is free after the scatter: the sub-codes of a bucket's runs.
    let subs = codes;
    for w in start.windows(2) {
        let (a, b) = (w[0] as usize, (w[1] as usize).min(n));
        let Some(bucket) = alt.get(a..b) else { continue };
        let ordered = sorted_keys(bucket, keys, tmp, subs, bits);
        for (j, &k) in keys.iter().enumerate() {
            // The low half of a key is a position in the bucket.
            if let Some(r) = bucket.get(k as u32 as usize) {
                let sub = if ordered { subs.get(j).copied().unwrap_or(0) } else { 0 };
                out.prim_indices.push(r.index());
                bu.feed((k >> 32) as u32, sub, r.with_tag(0), &mut out.nodes);
            }
        }
    }
    bu.finish(&mut out.nodes)
}

/// The top [`TOP_BITS`] bits of a 30-bit code: its bucket.
#[inline(always)]
fn top_digit(code: u32) -> usize {
    (code >> (30 - TOP_BITS)) as usize & ((1 << TOP_BITS) - 1)
}

/// The keys `(code << 32) | position` of a bucket's references (tagged with their codes),
/// sorted ([`sort_bucket`]) and with runs of equal codes ordered ([`order_runs`]), into `keys`;
/// `tmp` is scratch. Returns whether a run was ordered with `bits > 0`: then `subs[j]` holds the
/// top `bits` bits of key `j`'s sub-code (0 outside runs), else `subs` is untouched.
#[inline]
fn sorted_keys(bucket: &[PrimRef], keys: &mut Vec<u64>, tmp: &mut Vec<u64>, subs: &mut Vec<u32>, bits: u32) -> bool {
    keys.clear();
    keys.extend(
        bucket
            .iter()
            .enumerate()
            .map(|(j, r)| u64::from(r.tag()) << 32 | j as u64),
    );
    sort_bucket(keys, tmp);
    let mut ordered = false;
    order_bucket_runs(keys, bucket, tmp, |b, run| {
        if bits == 0 {
            return;
        }
        if !ordered {
            ordered = true;
            subs.clear();
            subs.resize(bucket.len(), 0);
        }
        for (d, &k) in subs.iter_mut().skip(b).zip(run) {
            *d = kept_sub(k, bits);
        }
    });
    ordered
}

/// [`bucketed30`] on `parts` threads (`std`), the same tree, node for node: the codes, the
/// top-digit scatter ([`scatter30_chunks`]) and the buckets in chunks side by side, each bucket
/// built by its own [`BottomUp`] into its own array of `bucket_nodes`; then, on the calling
/// thread, the buckets' nodes are appended in order and the buckets' roots joined as the
/// sequential pass joins them.
///
/// Why a bucket is a subtree of the sequential tree: the separator between two buckets is at
/// least `32 + bits + 30 - TOP_BITS` (their codes differ in the top digit; `bits` sub-code bits
/// below them), larger than any separator inside a bucket, so the sequential pass joins a bucket's subtrees into one before it joins
/// anything across a bucket's edge, in the same order as the bucket's own pass does; the
/// buckets' roots (leaf candidates included) then meet in the order their separators give.
#[cfg(feature = "std")]
#[allow(clippy::too_many_arguments)]
fn bucketed30_par(
    refs: &[PrimRef],
    alt: &mut Vec<PrimRef>,
    items: &mut Vec<Item<u32>>,
    bucket_nodes: &mut Vec<Vec<Node>>,
    q: &MortonQuantizer,
    p: &BuildParams,
    out: &mut Bvh2,
    parts: usize,
) -> Counters {
    const BUCKETS: usize = 1 << TOP_BITS;
    let n = refs.len();
    let start = scatter30_chunks(refs, alt, items, q, parts);
    let bits = sub_bits(n, p);
    out.prim_indices.resize(n, 0);
    bucket_nodes.resize_with(BUCKETS, Vec::new);
    // Each bucket's root, counters and first and last keys.
    type Built = (Pending, Counters, u64, u64);
    let mut built: Vec<Option<Built>> = alloc::vec![None; BUCKETS];
    {
        type Job<'a> = (usize, &'a mut [u32], &'a mut Vec<Node>, &'a mut Option<Built>);
        let ranges = start.windows(2).map(|w| (w[0] as usize, (w[1] as usize).min(n)));
        let prims = crate::par::split_ranges(&mut out.prim_indices[..n], ranges);
        let mut jobs: Vec<Job<'_>> = Vec::with_capacity(BUCKETS);
        for (((prim, nodes), slot), &a) in prims
            .into_iter()
            .zip(bucket_nodes.iter_mut())
            .zip(&mut built)
            .zip(&start)
        {
            nodes.clear();
            if !prim.is_empty() {
                jobs.push((a as usize, prim, nodes, slot));
            }
        }
        // The largest buckets first, for balance.
        jobs.sort_by_key(|j| core::cmp::Reverse(j.1.len()));
        let alt = &alt[..n];
        let next = core::sync::atomic::AtomicUsize::new(0);
        let jobs: Vec<std::sync::Mutex<Option<Job<'_>>>> =
            jobs.into_iter().map(|j| std::sync::Mutex::new(Some(j))).collect();
        crate::par::each(0..parts, |_| {
            let (mut keys, mut tmp, mut subs) = (Vec::new(), Vec::new(), Vec::new());
            while let Some(job) = jobs.get(next.fetch_add(1, core::sync::atomic::Ordering::Relaxed)) {
                let Some((a, prim, nodes, slot)) = job.lock().ok().and_then(|mut g| g.take()) else {
                    continue;
                };
                let Some(bucket) = alt.get(a..a + prim.len()) else {
                    continue;
                };
                let ordered = sorted_keys(bucket, &mut keys, &mut tmp, &mut subs, bits);
                let sub = |j: usize| if ordered { subs.get(j).copied().unwrap_or(0) } else { 0 };
                let mut bu = BottomUp::new(p, a as u32, bits);
                for (j, (&k, pi)) in keys.iter().zip(prim.iter_mut()).enumerate() {
                    if let Some(r) = bucket.get(k as u32 as usize) {
                        *pi = r.index();
                        bu.feed((k >> 32) as u32, sub(j), r.with_tag(0), nodes);
                    }
                }
                let first = keys.first().map_or(0, |&k| bu.key((k >> 32) as u32, sub(0)));
                let last = keys
                    .last()
                    .map_or(0, |&k| bu.key((k >> 32) as u32, sub(keys.len() - 1)));
                *slot = bu.root(nodes).map(|root| (root, bu.c, first, last));
            }
        });
    }
    // The layout: the root's slot, then the buckets' nodes in order, each followed by the joins
    // its right edge makes (as the sequential pass appends them), those joins recorded with
    // their slots; then the buckets' nodes copied into place side by side.
    let mut top = BottomUp::new(p, 0, bits);
    let mut placed = Placed {
        len: 1,
        nodes: Vec::new(),
    };
    let mut c = Counters::default();
    // Each bucket's slots in the node array, and its array.
    let mut regions: Vec<(usize, usize)> = Vec::with_capacity(BUCKETS);
    let mut sources: Vec<&Vec<Node>> = Vec::with_capacity(BUCKETS);
    let mut pending: Option<(Pending, u64)> = None;
    for (b, nodes) in built.iter().zip(bucket_nodes.iter()) {
        let Some((mut root, bc, first, last)) = *b else {
            continue;
        };
        if let Some((prev, prev_last)) = pending.take() {
            // `root.begin`: the bucket's first sorted position, one past the previous bucket's last.
            top.push(prev, separator(prev_last, first, root.begin - 1), &mut placed);
        }
        let offset = placed.len;
        regions.push((offset as usize, offset as usize + nodes.len()));
        sources.push(nodes);
        placed.len += nodes.len() as u32;
        if root.pair != LEAF {
            root.pair += offset;
        }
        c.leaves += bc.leaves;
        pending = Some((root, last));
    }
    out.nodes.clear();
    let Some((last, _)) = pending else {
        return c;
    };
    let root = top.close(last, &mut placed);
    c.leaves += top.c.leaves + u32::from(root.pair == LEAF);
    c.max_depth = root.height;
    let total = placed.len as usize;
    out.nodes.reserve(total);
    // Every slot in `1..total` is in one bucket's region or recorded in `placed`: its length
    // grew by each region's length and by one for each node it recorded, from 1.
    let covered = 1 + regions.iter().map(|&(lo, hi)| hi - lo).sum::<usize>() + placed.nodes.len();
    let Some(spare) = out
        .nodes
        .spare_capacity_mut()
        .get_mut(..total)
        .filter(|_| covered == total)
    else {
        // Not reached (see above); the tree is then left empty rather than half written.
        return Counters::default();
    };
    let dst = crate::par::split_ranges(spare, regions.iter().copied());
    // A bucket's slots, its nodes and its offset.
    type CopyJob<'a> = (&'a mut [core::mem::MaybeUninit<Node>], &'a Vec<Node>, u32);
    let jobs: Vec<CopyJob<'_>> = dst
        .into_iter()
        .zip(sources)
        .zip(&regions)
        .map(|((d, s), &(lo, _))| (d, s, lo as u32))
        .collect();
    crate::par::each_job(jobs, parts, |(d, src, offset)| {
        for (d, &nd) in d.iter_mut().zip(src) {
            let mut nd = nd;
            // Interior nodes (no primitives) point at children within the bucket's array.
            if nd.count == 0 {
                nd.index += offset;
            }
            d.write(nd);
        }
    });
    for &(at, nd) in &placed.nodes {
        if let Some(slot) = spare.get_mut(at as usize) {
            slot.write(nd);
        }
    }
    spare[0].write(root.node());
    // PERF: writing into the spare capacity instead of zeroing the array first (`resize`) and
    // then overwriting it: the zeroing of the 43 MB of the 1M soup's nodes took 5.3-6.1 ms of a
    // 37-39 ms build on 2 threads (2026-12-06, Intel Xeon).
    // SAFETY: slots `0..total` of the spare capacity (`total <= capacity`, reserved above) were
    // all initialised: slot 0 just now, and every other slot either in its bucket's region
    // (each region is exactly as long as the array copied into it, and `each_job` runs every
    // job before it returns) or from `placed`; `covered == total` checked that the regions and
    // the recorded nodes account for every slot, and no two overlap (`placed` hands out each
    // slot once, past every region before it). `Node` is plain data.
    unsafe { out.nodes.set_len(total) };
    c
}

/// Leaves among `nodes` (a collapsed subtree's nodes, at most `2 count - 2` of them).
#[inline]
fn leaves_below(count: u32, nodes: &[Node]) -> u32 {
    debug_assert!(nodes.len() <= 2 * count as usize);
    nodes.iter().filter(|n| n.is_leaf()).count() as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::prims::prepare;
    use crate::geometry::Aabb;
    use crate::scene::Rng;
    use alloc::{format, vec};

    /// `sort_gather30` against the plain pipeline: codes, a stable radix sort, runs of equal codes
    /// ordered ([`order_item_runs`]), a gather.
    fn check(boxes: &[Aabb]) {
        let mut refs = Vec::new();
        let info = prepare(boxes, &mut refs).unwrap();
        let q = MortonQuantizer::new30(&info.cbounds.to_aabb());
        let mut want_items = Vec::new();
        codes_of(
            &refs,
            &mut want_items,
            |p| morton30_scalar(p, &q),
            |x, y, z| morton30_x8(x, y, z, &q).to_array(),
        );
        sort_items(&mut want_items, &mut Vec::new(), 30);
        let mut want_runs = Runs::default();
        want_runs.reset(12);
        order_item_runs(&mut want_items, &refs, &mut Vec::new(), &mut want_runs);
        let (mut want_sorted, mut want_out) = (Vec::new(), Bvh2::default());
        gather(&refs, &mut want_sorted, &want_items, &mut want_out);

        let (mut alt, mut items, mut packed, mut tmp, mut out) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Bvh2::default());
        let mut runs = Runs::default();
        runs.reset(12);
        sort_gather30(
            &mut refs,
            &mut alt,
            &mut items,
            &mut packed,
            &mut tmp,
            &q,
            &mut out,
            &mut runs,
        );
        let keys = |v: &[Item<u32>]| v.iter().map(|it| it.key).collect::<Vec<_>>();
        assert_eq!(keys(&items), keys(&want_items));
        assert_eq!(runs, want_runs);
        assert!(items.iter().enumerate().all(|(i, it)| it.val == i as u32));
        assert_eq!(out.prim_indices, want_out.prim_indices);
        let bits = |v: &[PrimRef]| v.iter().map(|r| bytemuck::cast::<_, [u32; 8]>(r.0)).collect::<Vec<_>>();
        assert_eq!(bits(&refs), bits(&want_sorted), "lane 7 must be cleared");
    }

    /// `n` small boxes spread over a cube, the same snapped to a grid (many equal codes), and the
    /// spread boxes shrunk to a tight cluster with one far outlier (`n + 1` boxes).
    #[cfg(feature = "std")]
    fn large_scenes(n: usize, seed: u64) -> [Vec<Aabb>; 3] {
        let mut r = Rng::new(seed);
        let spread: Vec<Aabb> = (0..n)
            .map(|_| {
                let p = Vec3::new(r.range(-1.0, 1.0), r.range(-1.0, 1.0), r.range(-1.0, 1.0));
                Aabb::new(p, p + Vec3::splat(0.01))
            })
            .collect();
        let grid: Vec<Aabb> = spread
            .iter()
            .map(|a| {
                let p = (a.min * 3.0).round();
                Aabb::new(p, p + Vec3::ONE)
            })
            .collect();
        let mut cluster: Vec<Aabb> = spread.iter().map(|a| Aabb::new(a.min * 1e-3, a.max * 1e-3)).collect();
        cluster.push(Aabb::new(Vec3::splat(100.0), Vec3::splat(101.0)));
        [spread, grid, cluster]
    }

    /// Runs of equal codes after [`order_item_runs`]: a short run keeps its order; a long run
    /// takes the Morton order of its own bounds, and a cluster within it (one sub-code) that of
    /// the cluster's bounds; a run on one point keeps its order.
    #[test]
    fn runs_take_the_morton_order_of_their_own_bounds() {
        let mut r = Rng::new(5);
        let mut pts: Vec<Vec3> = (0..5).map(|_| Vec3::splat(r.f32())).collect();
        // 30 points in the unit cube, 10 of them in a cluster of 1e-5 at (0.5, 0.5, 0.5).
        pts.extend((0..20).map(|_| Vec3::new(r.f32(), r.f32(), r.f32())));
        pts.extend((0..10).map(|_| Vec3::splat(0.5) + Vec3::new(r.f32(), r.f32(), r.f32()) * 1e-5));
        pts.extend((0..12).map(|_| Vec3::splat(3.0)));
        let boxes: Vec<Aabb> = pts.iter().map(|&p| Aabb::new(p, p)).collect();
        let mut refs = Vec::new();
        prepare(&boxes[..], &mut refs).unwrap();
        // Codes 1, 2, 3 for the three groups; positions reversed within each.
        let group = |i: usize| {
            if i < 5 {
                1u64
            } else if i < 35 {
                2
            } else {
                3
            }
        };
        let mut items: Vec<Item<u64>> = (0..pts.len())
            .map(|i| Item {
                key: group(i),
                val: i as u32,
            })
            .collect();
        for g in [0..5, 5..35, 35..47] {
            items[g].reverse();
        }
        let mut runs = Runs::default();
        runs.reset(30);
        order_item_runs(&mut items, &refs, &mut Vec::new(), &mut runs);
        let vals = |g: core::ops::Range<usize>| items[g].iter().map(|it| it.val).collect::<Vec<_>>();
        // A short run and a run on one point: untouched.
        assert_eq!(vals(0..5), [4, 3, 2, 1, 0]);
        assert_eq!(vals(35..47), (35..47).rev().collect::<Vec<u32>>());
        // The long run: sorted by the codes over its bounds, the cluster's 10 together.
        let morton = |set: &[u32], at: u32| {
            let mut b = Aabb::EMPTY;
            for &i in set {
                b.grow(pts[i as usize] * 2.0);
            }
            let q = MortonQuantizer::new_extended(&b, crate::geometry::morton::BITS_PER_AXIS_30);
            morton30_scalar(pts[at as usize] * 2.0, &q)
        };
        let run = vals(5..35);
        let level1: Vec<u32> = run.iter().map(|&i| morton(&run, i)).collect();
        assert!(level1.windows(2).all(|w| w[0] <= w[1]), "{level1:?}");
        let cluster: Vec<u32> = run.iter().copied().filter(|&i| i >= 25).collect();
        let at = run.iter().position(|&i| i >= 25).unwrap();
        assert_eq!(run[at..at + 10], cluster[..], "the cluster is one sub-run");
        let level2: Vec<u32> = cluster.iter().map(|&i| morton(&cluster, i)).collect();
        assert!(level2.windows(2).all(|w| w[0] < w[1]), "{level2:?}");
        assert!(level1[at..at + 10].iter().all(|&c| c == level1[at]));
        // The long run recorded with its level-1 sub-codes (in full: 30 bits), nothing else.
        assert_eq!(runs.spans, [[5, 35, 0]]);
        assert_eq!(runs.subs, level1);
        assert_eq!(runs.subs_of(5, 35), Some(&level1[..]));
        assert_eq!(runs.subs_of(10, 20), Some(&level1[5..15]));
        assert_eq!((runs.subs_of(4, 10), runs.subs_of(30, 36)), (None, None));
    }

    /// The parallel front end gives the sequential one's codes, references (bit for bit),
    /// primitive indices and runs, on spread, gridded and clustered boxes and thread counts that
    /// leave ragged last chunks.
    #[cfg(feature = "std")]
    #[test]
    fn sort_gather30_par_matches_sequential() {
        let [spread, grid, cluster] = large_scenes(200_003, 12);
        for boxes in [&spread, &grid, &cluster] {
            let mut refs = Vec::new();
            let info = prepare(&boxes[..], &mut refs).unwrap();
            let q = MortonQuantizer::new(&info.cbounds.to_aabb(), 10);
            let bits = |v: &[PrimRef]| v.iter().map(|r| bytemuck::cast::<_, [u32; 8]>(r.0)).collect::<Vec<_>>();
            let keys = |v: &[Item<u32>]| v.iter().map(|it| (it.key, it.val)).collect::<Vec<_>>();
            let (mut alt, mut items, mut packed, mut tmp, mut want) =
                (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Bvh2::default());
            let mut seq = refs.clone();
            let (mut want_runs, mut runs) = (Runs::default(), Runs::default());
            want_runs.reset(14);
            sort_gather30(
                &mut seq,
                &mut alt,
                &mut items,
                &mut packed,
                &mut tmp,
                &q,
                &mut want,
                &mut want_runs,
            );
            let want_items = keys(&items);
            for threads in [2, 3, 16] {
                let mut par = refs.clone();
                let mut out = Bvh2::default();
                runs.reset(14);
                sort_gather30_par(
                    &mut par,
                    &mut alt,
                    &mut items,
                    &mut packed,
                    &mut tmp,
                    &q,
                    &mut out,
                    &mut runs,
                    threads,
                );
                assert_eq!(runs, want_runs, "{threads} threads");
                assert_eq!(bits(&par), bits(&seq), "{threads} threads");
                assert_eq!(keys(&items), want_items, "{threads} threads");
                assert_eq!(out.prim_indices, want.prim_indices, "{threads} threads");
            }
        }
    }

    /// The parallel bottom-up LBVH ([`bucketed30_par`]) makes the sequential pass's tree byte for
    /// byte (nodes, primitive order, counters) on 2, 3 and 16 threads: even and gridded scenes
    /// (equal codes: position separators), all boxes equal (one bucket), a cluster with a far
    /// outlier (a bucket of one), and lone boxes in buckets of their own beside one another, whose
    /// leaf candidates join across the buckets' edges (`min_leaf_size` 2 to 4).
    #[cfg(feature = "std")]
    #[test]
    fn bucketed30_par_matches_sequential() {
        use crate::build::Builder;
        let n = 140_001;
        let [spread, grid, cluster] = large_scenes(n, 21);
        let same = vec![Aabb::new(Vec3::ZERO, Vec3::ONE); n];
        // A cluster at one corner and three boxes along the diagonal, each alone in its cell of
        // the 4 x 4 x 4 top-digit grid: buckets of one box, whose leaf candidates join.
        let mut lone = cluster[..n].to_vec();
        for x in [30.0, 55.0, 80.0] {
            lone.push(Aabb::new(Vec3::splat(x), Vec3::splat(x + 0.5)));
        }
        let bytes = |b: &Bvh2| bytemuck::cast_slice::<Node, u8>(&b.nodes).to_vec();
        for (s, boxes) in [&spread, &grid, &same, &cluster, &lone].into_iter().enumerate() {
            for (min_leaf, max_leaf) in [(1, 1), (2, 4), (3, 3), (4, 8)] {
                let p = BuildParams {
                    min_leaf_size: min_leaf,
                    max_leaf_size: max_leaf,
                    ..BuildParams::fastest()
                };
                let mut b = Builder::new();
                let mut want = Bvh2::default();
                let ws = b.build_into(&boxes[..], &p, &mut want).unwrap();
                for threads in [2, 3, 16] {
                    let mut got = Bvh2::default();
                    let gs = b.build_into_par(&boxes[..], &p, &mut got, threads).unwrap();
                    let what = format!("scene {s}, leaves {min_leaf}..={max_leaf}, {threads} threads");
                    assert_eq!(got.prim_indices, want.prim_indices, "{what}");
                    assert!(bytes(&got) == bytes(&want), "{what}");
                    assert_eq!(
                        (gs.leaves, gs.max_depth, gs.nodes),
                        (ws.leaves, ws.max_depth, ws.nodes),
                        "{what}"
                    );
                }
                assert!(want.validate(&boxes[..]).is_ok(), "scene {s}");
                if s == 4 && min_leaf >= 2 {
                    // The lone boxes' buckets did join: one leaf holds two of them.
                    let joined = want.nodes.iter().filter(|nd| nd.is_leaf()).any(|nd| {
                        let prims = &want.prim_indices[nd.index as usize..(nd.index + nd.count) as usize];
                        prims.iter().filter(|&&i| i as usize >= n).count() >= 2
                    });
                    assert!(joined, "leaves {min_leaf}..={max_leaf}");
                }
            }
        }
    }

    #[test]
    fn sort_gather30_matches_sort_and_gather() {
        let mut r = Rng::new(9);
        let mut b = |lo: f32, hi: f32| {
            let p = Vec3::new(r.range(lo, hi), r.range(lo, hi), r.range(lo, hi));
            Aabb::new(p, p + Vec3::splat(0.01))
        };
        for n in [0, 1, 2, 7, 8, 9, 300, 5000] {
            // Spread out (small buckets, `sort_unstable`), and on a coarse grid (many equal codes,
            // big buckets: the radix path).
            let spread: Vec<Aabb> = (0..n).map(|_| b(-1.0, 1.0)).collect();
            check(&spread);
            let grid: Vec<Aabb> = spread
                .iter()
                .map(|a| {
                    let p = (a.min * 2.0).round();
                    Aabb::new(p, p + Vec3::ONE)
                })
                .collect();
            check(&grid);
            // One cluster and one far box: nearly everything in one bucket.
            let mut cluster: Vec<Aabb> = (0..n).map(|_| b(0.0, 0.001)).collect();
            cluster.push(Aabb::new(Vec3::splat(100.0), Vec3::splat(101.0)));
            // Invalid boxes are left out by `prepare`: positions and indices differ.
            cluster.push(Aabb::new(Vec3::splat(f32::NAN), Vec3::ONE));
            check(&cluster);
        }
    }

    /// The tree below `node` as nested tuples: boxes and primitive slots, ignoring where the
    /// nodes sit in the array.
    fn canonical(b: &Bvh2, node: u32, out: &mut Vec<[u32; 8]>) {
        let n = b.nodes[node as usize];
        let bits: [u32; 8] = bytemuck::cast(n);
        if n.is_leaf() {
            out.push(bits);
        } else {
            out.push([bits[0], bits[1], bits[2], u32::MAX, bits[4], bits[5], bits[6], 0]);
            canonical(b, n.left(), out);
            canonical(b, n.left() + 1, out);
        }
    }

    /// The bottom-up LBVH against the top-down walk over the same order: the same tree (up to
    /// where nodes sit in the array), leaves, slots, depth; under the default depth bound and one
    /// that leaves runs 2 or 3 sub-code bits.
    #[test]
    fn bottom_up_equals_the_top_down_walk() {
        let mut r = Rng::new(17);
        let mut scenes: Vec<Vec<Aabb>> = Vec::new();
        for n in [1, 2, 3, 5, 8, 9, 100, 3000, 20_000] {
            let spread: Vec<Aabb> = (0..n)
                .map(|_| {
                    let p = Vec3::new(r.f32(), r.f32(), r.f32());
                    Aabb::new(p, p + Vec3::splat(r.range(0.0, 0.05)))
                })
                .collect();
            // Many equal codes: a coarse grid, and every box the same.
            let grid: Vec<Aabb> = spread
                .iter()
                .map(|a| {
                    let p = (a.min * 3.0).round();
                    Aabb::new(p, p + Vec3::ONE)
                })
                .collect();
            let same = vec![Aabb::new(Vec3::ZERO, Vec3::ONE); n];
            // A tight cluster and a far outlier (one bucket holds almost everything).
            let mut cluster: Vec<Aabb> = spread.iter().map(|a| Aabb::new(a.min * 1e-3, a.max * 1e-3)).collect();
            cluster.push(Aabb::new(Vec3::splat(1e3), Vec3::splat(1e3 + 1.0)));
            scenes.extend([spread, grid, same, cluster]);
        }
        let mut partial = 0;
        for (s, boxes) in scenes.iter().enumerate() {
            // The default depth bound, and one that leaves 2 or 3 sub-code bits (or 0 where the
            // least accepted bound leaves none).
            let tight = (33 + super::super::prims::ceil_log2(boxes.len() as u32)).max(super::super::MIN_DEPTH);
            let cases = [(1, 1), (1, 4), (2, 4), (4, 8), (3, 3)]
                .into_iter()
                .flat_map(|leaves| [(leaves, 64), (leaves, tight)]);
            for ((min_leaf, max_leaf), max_depth) in cases {
                let p = BuildParams {
                    min_leaf_size: min_leaf,
                    max_leaf_size: max_leaf,
                    max_depth,
                    ..BuildParams::fastest()
                };
                let mut b = Builder::new();
                let info = prepare(&boxes[..], &mut b.refs).unwrap();
                assert!(bottom_up_ok(b.refs.len(), &p));
                let q = MortonQuantizer::new30(&info.cbounds.to_aabb());
                let refs = b.refs.clone();
                let Builder {
                    refs: r2,
                    alt,
                    items32,
                    packed,
                    packed_tmp,
                    codes,
                    runs,
                    ..
                } = &mut b;
                let mut want = Bvh2::default();
                runs.reset(sub_bits(refs.len(), &p));
                sort_gather30(r2, alt, items32, packed, packed_tmp, &q, &mut want, runs);
                let cw = walk_sorted(r2, items32, runs, &p, &mut want);
                // Runs split by some but not all of their sub-code bits.
                partial += usize::from(!runs.spans.is_empty() && (1..30).contains(&runs.bits));
                let mut got = Bvh2::default();
                let cg = bucketed30(&refs, alt, codes, packed, packed_tmp, &q, &p, &mut got);
                let what = format!(
                    "scene {s} ({} boxes), leaves {min_leaf}..={max_leaf}, depth {max_depth}",
                    boxes.len()
                );
                assert_eq!(got.prim_indices, want.prim_indices, "{what}");
                assert_eq!(got.nodes.len(), want.nodes.len(), "{what}");
                assert_eq!(
                    (cg.leaves, cg.max_depth, cg.forced_splits),
                    (cw.leaves, cw.max_depth, 0),
                    "{what}"
                );
                let (mut a, mut w) = (Vec::new(), Vec::new());
                canonical(&got, 0, &mut a);
                canonical(&want, 0, &mut w);
                assert!(a == w, "{what}");
                assert!(got.validate(&boxes[..]).is_ok(), "{what}");
                // Post-order: children before their parent, the root excepted.
                assert!(
                    got.nodes
                        .iter()
                        .enumerate()
                        .skip(1)
                        .all(|(i, n)| n.is_leaf() || (n.left() as usize) < i)
                );
            }
        }
        assert!(partial > 10, "{partial} builds split runs by part of their sub-codes");
    }
}
