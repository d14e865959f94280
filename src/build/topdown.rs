//! The top-down builder for [`Strategy::Median`] and [`Strategy::BinnedSah`]: pbrt's
//! `BUILD(node)` (find a split; make a leaf if it does not pay; else partition and build both
//! sides) as a loop over an explicit task stack.
//!
//! The references live in two buffers of the same length. A task's range is valid in one of them;
//! the binned partition moves it to the same range of the other (branch-free, see
//! [`binned`](super::binned)), so the children's ranges are valid there; ranges of at most
//! [`binned::SMALL`] references take an exact sweep instead of binning, their whole subtree at
//! once in local arrays ([`small`](super::small)) where the depth bound cannot bind. The median
//! split reorders in place. A leaf copies its primitive indices straight from whichever buffer holds it.
//!
//! **In parallel** (`std`, [`build_refs_par`]): the same loop, in rounds. With a deferral, a task
//! no larger than the grain is pushed to a list instead of built; each round splits every task
//! above the grain once (grain: one less than the task), the round's tasks side by side, each
//! worker into its own arrays ([`build_tasks_par`]), which are then moved into the output in
//! range order. Once every task is at most `n / (8 threads)` references (at least
//! [`PAR_GRAIN`]), a last round builds their whole subtrees. Every split is the one the
//! sequential loop makes, so the tree is the same; only the nodes' numbering differs.
//!
//! A round with at most half as many tasks as threads (the first ones: one task, then two,
//! ...) would leave threads idle, so its binned-SAH tasks are split wide instead
//! ([`split_wide`]): each task's references cut into chunks of at least [`WIDE_CHUNK`], the
//! chunks binned side by side and their bins summed (unions and sums: exactly the sequential
//! bins, hence the same split), then partitioned side by side, each chunk's references to its own
//! two pieces of the other buffer, placed by the chunks' side counts so that the order is the
//! sequential partition's (left references in order, right ones from the end). A split that is
//! not plain (a leaf, a flat node, a forced or depth-bounded split) goes the sequential way.

use super::binned::{self, Binning, Bins};
use super::builder::{Builder, Counters};
use super::prims::{Box8, CBounds, PrepInfo, PrimRef, depth_ok};
use super::small;
use super::{BinAxes, BuildParams, Bvh2, Strategy};
#[cfg(feature = "std")]
use crate::math::{Lane, f32x8};
use alloc::vec::Vec;

/// A node still to build: its slot, the range of references it covers (valid in `alt` or `refs`),
/// its depth (root = 1), its box and the bounds of its doubled centroids.
#[derive(Clone, Debug)]
pub(crate) struct Task {
    node: u32,
    begin: u32,
    end: u32,
    depth: u32,
    in_alt: bool,
    bounds: Box8,
    cb: CBounds,
}

/// A chosen split: `mid` refs (from the range start) go left; `moved`: they are now in the other
/// buffer.
struct Split {
    mid: usize,
    moved: bool,
    left: Box8,
    right: Box8,
    lcb: CBounds,
    rcb: CBounds,
}

/// `C_T + C_I (sum / A)`: the SAH cost of a split whose `N_l A_l + N_r A_r` is `sum`, relative to
/// a leaf's `C_I N`. A node box without a usable area (a point, a segment, an overflow) counts
/// every primitive in full, so such a split never beats a leaf.
#[inline]
pub(crate) fn split_cost(p: &BuildParams, sum: f32, area: f32, count: u32) -> f32 {
    let rel = if area > 0.0 && area.is_finite() {
        sum / area
    } else {
        count as f32
    };
    p.traversal_cost + p.intersection_cost * rel
}

/// Builds with the median or binned strategy.
pub(crate) fn build(b: &mut Builder, info: &PrepInfo, p: &BuildParams, out: &mut Bvh2, threads: usize) -> Counters {
    #[cfg(feature = "std")]
    let Builder { refs, alt, par, .. } = b;
    #[cfg(not(feature = "std"))]
    let Builder { refs, alt, .. } = b;
    #[cfg(feature = "std")]
    if threads > 1 {
        return build_refs_par(refs, alt, info, p, out, threads, par);
    }
    let _ = threads;
    build_refs(refs, alt, info, p, out)
}

/// [`build`] over the references `refs` (reordered), with `alt` as the second buffer; `info`
/// gives their joint box and centroid bounds.
pub(crate) fn build_refs(
    refs: &mut [PrimRef],
    alt: &mut Vec<PrimRef>,
    info: &PrepInfo,
    p: &BuildParams,
    out: &mut Bvh2,
) -> Counters {
    let root = start(refs.len(), alt, info, out);
    let mut bins = Bins::new();
    let mut c = Counters::default();
    // Left children are taken first, so the stack holds at most one right sibling per level.
    let mut stack: Vec<Task> = Vec::with_capacity(p.max_depth as usize + 1);
    subtree(refs, alt, p, out, root, &mut bins, &mut stack, &mut c);
    c
}

/// Sizes `alt` and `out` for a build over `n` references and makes the root node: the root task.
fn start(n: usize, alt: &mut Vec<PrimRef>, info: &PrepInfo, out: &mut Bvh2) -> Task {
    // NOTE: resized only when the length changes; ranges are written before they are read.
    if alt.len() != n {
        alt.resize(n, PrimRef(Default::default()));
    }
    out.prim_indices.resize(n, 0);
    out.nodes.reserve((2 * n).saturating_sub(1));
    out.nodes.push(info.bounds.to_node(0, 0));
    Task::new([0, 0, n as u32, 1], info.bounds, info.cbounds)
}

/// [`build_refs`] on `threads` threads (`std`). In rounds, every task of more than
/// `n / (8 threads)` references (at least [`PAR_GRAIN`]) is split once, the tasks of a round side
/// by side (the root alone in the first); then [`build_tasks_par`] builds the remaining tasks'
/// subtrees side by side. The tree has the sequential build's nodes, boxes and leaves; only the
/// numbering of the nodes differs.
#[cfg(feature = "std")]
pub(crate) fn build_refs_par(
    refs: &mut [PrimRef],
    alt: &mut Vec<PrimRef>,
    info: &PrepInfo,
    p: &BuildParams,
    out: &mut Bvh2,
    threads: usize,
    scratch: &mut Vec<ParScratch>,
) -> Counters {
    let n = refs.len();
    if threads <= 1 {
        return build_refs(refs, alt, info, p, out);
    }
    let mut c = Counters::default();
    let grain = (n / threads.saturating_mul(8)).max(PAR_GRAIN) as u32;
    let mut tasks = alloc::vec![start(n, alt, info, out)];
    let mut pool = Vec::new();
    loop {
        let (big, done): (Vec<Task>, Vec<Task>) = tasks.into_iter().partition(|t| t.end - t.begin > grain);
        if big.is_empty() {
            build_tasks_par(refs, alt, done, p, out, threads, &mut c, scratch, false);
            return c;
        }
        tasks = if big.len() * 2 <= threads && p.strategy == Strategy::BinnedSah {
            // Too few tasks to keep the threads busy: split each with all of them.
            let (mut split, rest) = split_wide(refs, alt, big, p, out, threads, &mut c, &mut pool);
            split.extend(build_tasks_par(refs, alt, rest, p, out, threads, &mut c, scratch, true));
            split
        } else {
            build_tasks_par(refs, alt, big, p, out, threads, &mut c, scratch, true)
        };
        tasks.extend(done);
    }
}

/// The ranges of `tasks` (disjoint, sorted by start, within both buffers: the callers check) in
/// `refs` and in `alt`, as separate slices: `(refs part, alt part)` per task.
#[cfg(feature = "std")]
fn task_ranges<'a>(
    refs: &'a mut [PrimRef],
    alt: &'a mut [PrimRef],
    tasks: &[Task],
) -> Vec<(&'a mut [PrimRef], &'a mut [PrimRef])> {
    let ranges = || tasks.iter().map(|t| (t.begin as usize, t.end as usize));
    let r = crate::par::split_ranges(refs, ranges());
    r.into_iter().zip(crate::par::split_ranges(alt, ranges())).collect()
}

/// A wide split's chunks of references get at least this many each.
#[cfg(feature = "std")]
const WIDE_CHUNK: usize = 16_384;

/// Splits each of `tasks` (binned SAH, more than [`PAR_GRAIN`] references each) once, every task's
/// references cut into chunks binned side by side on up to `threads` threads, then partitioned
/// side by side into the other buffer (`binned::bin_chunk`, `binned::partition_chunk`): the very
/// split, order and child bounds of the sequential loop, since bins merge exactly (unions and
/// sums) and each chunk's side counts place its pieces. A task the sequential loop splits from a
/// sample ([`BuildParams::bin_sample`]) takes the same sample's split, found here on the calling
/// thread; its chunks are then only counted (`binned::count_left`), and its children's boxes are
/// the chunks' boxes measured by the partition, merged. Returns the children (two per task split
/// here) and the tasks to split the sequential way (a leaf, a forced or depth-bounded split, a
/// flat node: the rare cases, left to [`subtree_with`]), whose ranges are still valid where they
/// were (only the other buffer may have been written).
#[cfg(feature = "std")]
#[allow(clippy::too_many_arguments)]
fn split_wide(
    refs: &mut [PrimRef],
    alt: &mut [PrimRef],
    mut tasks: Vec<Task>,
    p: &BuildParams,
    out: &mut Bvh2,
    threads: usize,
    c: &mut Counters,
    pool: &mut Vec<Bins>,
) -> (Vec<Task>, Vec<Task>) {
    use core::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    tasks.sort_by_key(|t| t.begin);
    let disjoint = tasks.windows(2).all(|w| w[0].end <= w[1].begin)
        && tasks
            .iter()
            .all(|t| t.begin <= t.end && t.end as usize <= refs.len().min(alt.len()));
    if !disjoint {
        return (Vec::new(), tasks);
    }
    let total: usize = tasks.iter().map(|t| (t.end - t.begin) as usize).sum();
    // Per task: its binning, axes, chunk length and first chunk (in `pool`).
    // `sampled`: the split found on a sample of the task (`BuildParams::bin_sample`), whose
    // chunks are then counted, not binned.
    struct Plan {
        binning: Binning,
        nb: usize,
        mask: u32,
        chunk: usize,
        first: usize,
        chunks: usize,
        sampled: Option<binned::BinSplit>,
    }
    let mut plans = Vec::with_capacity(tasks.len());
    let mut chunks_total = 0;
    let mut sampler: Option<Bins> = None;
    for t in &tasks {
        let count = (t.end - t.begin) as usize;
        let nb = p.bins.min(t.end - t.begin);
        let binning = Binning::new(&t.cb, nb);
        // In `u64`: `threads * count` can pass `u32::MAX` (32-bit targets).
        let share = (threads as u64 * count as u64 / total.max(1) as u64).min(usize::MAX as u64) as usize;
        let k = share.clamp(1, (count / WIDE_CHUNK).max(1));
        let chunk = count.div_ceil(k);
        let chunks = count.div_ceil(chunk.max(1));
        let ok = count as u32 > p.min_leaf_size && !binning.is_flat() && chunks >= 2;
        // The sequential loop's sampled split, from the same sample.
        let may_leaf = count as u32 <= p.max_leaf_size;
        let stride = binned::sample_stride(count as u32, p.bin_sample, may_leaf);
        let longest = p.bin_axes == BinAxes::Longest;
        let sampled = (ok && stride > 1)
            .then(|| {
                let holder = if t.in_alt { &alt[..] } else { &refs[..] };
                let src = &holder[t.begin as usize..t.end as usize];
                let scratch = sampler.get_or_insert_with(Bins::new);
                binned::find_sampled(src, &binning, nb as usize, longest, stride, scratch)
            })
            .flatten();
        plans.push(ok.then(|| Plan {
            mask: binned::axes_mask(&binning, longest),
            binning,
            nb: nb as usize,
            chunk,
            first: chunks_total,
            chunks,
            sampled,
        }));
        if ok {
            chunks_total += chunks;
        }
    }
    if pool.len() < chunks_total + 1 {
        pool.resize_with(chunks_total + 1, Bins::new);
    }
    // Each task's range in both buffers: `(holder, other)`.
    let mut parts: Vec<(&mut [PrimRef], &mut [PrimRef])> = task_ranges(refs, alt, &tasks)
        .into_iter()
        .zip(&tasks)
        .map(|((r, a), t)| if t.in_alt { (a, r) } else { (r, a) })
        .collect();
    // Pass 1: every chunk binned (or, for a sampled split, its left references counted), side by
    // side.
    let (bins_of_chunks, total_bins) = pool.split_at_mut(chunks_total);
    let counted: Vec<AtomicUsize> = (0..chunks_total).map(|_| AtomicUsize::new(0)).collect();
    {
        type BinJob<'a> = (&'a [PrimRef], &'a Plan, &'a mut Bins, &'a AtomicUsize);
        let mut jobs: Vec<Mutex<Option<BinJob<'_>>>> = Vec::with_capacity(chunks_total);
        let mut bins_left = &mut bins_of_chunks[..];
        for (plan, (src, _)) in plans.iter().zip(&parts) {
            let Some(plan) = plan else { continue };
            let (mine, rest) = core::mem::take(&mut bins_left).split_at_mut(plan.chunks);
            bins_left = rest;
            let slots = &counted[plan.first..plan.first + plan.chunks];
            for ((ch, b), slot) in src.chunks(plan.chunk).zip(mine).zip(slots) {
                jobs.push(Mutex::new(Some((ch, plan, b, slot))));
            }
        }
        let next = AtomicUsize::new(0);
        crate::par::each(0..threads.min(jobs.len()), |_| {
            while let Some(job) = jobs.get(next.fetch_add(1, Ordering::Relaxed)) {
                if let Some((ch, plan, b, slot)) = job.lock().ok().and_then(|mut g| g.take()) {
                    match &plan.sampled {
                        Some(s) => slot.store(binned::count_left(ch, &plan.binning, s), Ordering::Relaxed),
                        None => binned::bin_chunk(ch, &plan.binning, plan.nb, plan.mask, b),
                    }
                }
            }
        });
    }
    // The splits, from the merged bins (or the sample), and the checks of the sequential loop;
    // each chunk's left count.
    let all = &mut total_bins[0];
    let mut splits: Vec<Option<binned::BinSplit>> = Vec::with_capacity(tasks.len());
    let mut chunk_lefts = alloc::vec![0usize; chunks_total];
    for (t, plan) in tasks.iter().zip(&plans) {
        let split = plan.as_ref().and_then(|plan| {
            let mine = &bins_of_chunks[plan.first..plan.first + plan.chunks];
            let lefts = &mut chunk_lefts[plan.first..plan.first + plan.chunks];
            let count = t.end - t.begin;
            let mut s = if let Some(s) = plan.sampled {
                for (l, c) in lefts.iter_mut().zip(&counted[plan.first..]) {
                    *l = c.load(Ordering::Relaxed);
                }
                // The sample's counts and boxes: the node's come from the chunks.
                binned::BinSplit {
                    left_count: lefts.iter().sum::<usize>().min(count as usize) as u32,
                    ..s
                }
            } else {
                binned::sum_bins(all, mine, plan.nb, plan.mask);
                let s = binned::sweep_bins(all, &plan.binning, plan.nb, plan.mask)?;
                let leaf_cost = p.intersection_cost * count as f32;
                if count <= p.max_leaf_size && leaf_cost <= split_cost(p, s.cost, t.bounds.half_area_nonempty(), count)
                {
                    return None;
                }
                for (l, b) in lefts.iter_mut().zip(mine) {
                    *l = binned::left_count(b, &s);
                }
                s
            };
            let (nl, nr) = (s.left_count, count - s.left_count.min(count));
            // NOTE: equal to `nl` (the bins were summed from these); checked because the pieces
            // below are cut by it.
            let sum: usize = lefts.iter().sum();
            s.left_count = nl;
            (nl > 0 && nr > 0 && sum == nl as usize && depth_ok(t.depth, nl, nr, p.max_depth)).then_some(s)
        });
        splits.push(split);
    }
    // Pass 2: every chunk partitioned into its pieces of the other buffer, side by side.
    type PartJob<'a> = (
        &'a [PrimRef],
        &'a mut [PrimRef],
        &'a mut [PrimRef],
        &'a Binning,
        &'a binned::BinSplit,
    );
    let mut jobs: Vec<Mutex<Option<PartJob<'_>>>> = Vec::with_capacity(chunks_total);
    let mut job_task = Vec::with_capacity(chunks_total);
    for (i, ((plan, split), (src, dst))) in plans.iter().zip(&splits).zip(parts.iter_mut()).enumerate() {
        let (Some(plan), Some(split)) = (plan, split) else {
            continue;
        };
        let lefts = &chunk_lefts[plan.first..plan.first + plan.chunks];
        let (mut lpart, mut rpart) = dst.split_at_mut(split.left_count as usize);
        let mut pieces: Vec<(&mut [PrimRef], &mut [PrimRef])> = Vec::with_capacity(plan.chunks);
        for &nl in lefts {
            let (l, rest) = core::mem::take(&mut lpart).split_at_mut(nl);
            lpart = rest;
            pieces.push((l, &mut []));
        }
        // The right pieces from the back: chunk 0's at the end.
        for ((ch, &nl), piece) in src.chunks(plan.chunk).zip(lefts).zip(pieces.iter_mut()).rev() {
            let nr = ch.len() - nl;
            let (r, rest) = core::mem::take(&mut rpart).split_at_mut(nr);
            rpart = rest;
            piece.1 = r;
        }
        for (ch, (l, r)) in src.chunks(plan.chunk).zip(pieces) {
            jobs.push(Mutex::new(Some((ch, l, r, &plan.binning, split))));
            job_task.push(i);
        }
    }
    let results: Vec<Mutex<Option<[f32x8; 4]>>> = (0..jobs.len()).map(|_| Mutex::new(None)).collect();
    {
        let next = AtomicUsize::new(0);
        crate::par::each(0..threads.min(jobs.len()), |_| {
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(job) = jobs.get(i) else { break };
                if let Some((ch, l, r, binning, split)) = job.lock().ok().and_then(|mut g| g.take()) {
                    let got = binned::partition_chunk(ch, l, r, binning, split);
                    if let Ok(mut g) = results[i].lock() {
                        *g = got;
                    }
                }
            }
        });
    }
    drop(jobs);
    // Per task, the chunks' centroid bounds and boxes merged (`None`: a chunk failed).
    let ninf = f32x8::splat(f32::NEG_INFINITY);
    let mut acc: Vec<Option<[f32x8; 4]>> = splits.iter().map(|s| s.map(|_| [ninf; 4])).collect();
    for (&i, res) in job_task.iter().zip(results) {
        let got = res.into_inner().ok().flatten();
        acc[i] = acc[i].zip(got).map(|(a, g)| core::array::from_fn(|k| g[k].max_l(a[k])));
    }
    let (mut children, mut rest) = (Vec::new(), Vec::new());
    for (((t, split), acc), plan) in tasks.into_iter().zip(splits).zip(acc).zip(&plans) {
        let (Some(mut s), Some([la, ra, lb, rb])) = (split, acc) else {
            rest.push(t);
            continue;
        };
        if plan.as_ref().is_some_and(|p| p.sampled.is_some()) {
            // The node's boxes, measured by the partition (the sequential loop's too).
            (s.left, s.right) = (Box8(lb), Box8(rb));
        }
        c.max_depth = c.max_depth.max(t.depth);
        let left = out.nodes.len() as u32;
        out.nodes[t.node as usize] = t.bounds.to_node(left, 0);
        out.nodes.push(s.left.to_node(0, 0));
        out.nodes.push(s.right.to_node(0, 0));
        let mid = t.begin + s.left_count;
        let in_alt = !t.in_alt;
        children.push(Task {
            node: left,
            begin: t.begin,
            end: mid,
            depth: t.depth + 1,
            in_alt,
            bounds: s.left,
            cb: binned::cbounds_of(la),
        });
        children.push(Task {
            node: left + 1,
            begin: mid,
            end: t.end,
            depth: t.depth + 1,
            in_alt,
            bounds: s.right,
            cb: binned::cbounds_of(ra),
        });
    }
    (children, rest)
}

/// The parallel build does not cut the tree below this many references per task.
#[cfg(feature = "std")]
pub(crate) const PAR_GRAIN: usize = 4096;

/// One worker's memory in a parallel build, kept by the [`Builder`] so that a rebuild touches no
/// new pages: the subtrees it built, one after the other, its task stack and the tasks it left
/// (splitting once).
#[cfg(feature = "std")]
#[derive(Clone, Debug, Default)]
pub(crate) struct ParScratch {
    out: Bvh2,
    stack: Vec<Task>,
    left: Vec<Task>,
}

/// Where a job's subtree landed: its worker, its first node there (the task's own node) and
/// how many, its first primitive slot there, the tasks it left (a range of the worker's `left`),
/// and its counters.
#[cfg(feature = "std")]
struct Landed {
    worker: usize,
    node: usize,
    nodes: usize,
    slot: usize,
    left: core::ops::Range<usize>,
    c: Counters,
}

/// Builds the subtrees of `tasks` (disjoint ranges, each valid in `refs` or `alt` as its
/// `in_alt` says, each node already in `out`) on up to `threads` threads, largest first, each
/// worker into its own arrays in `scratch`; then moves them into `out` in range order (on the
/// same threads), so the result does not depend on which thread built what. `split_once`: each
/// task is only split (or made a leaf), and its children are returned as tasks, in range order.
#[cfg(feature = "std")]
#[allow(clippy::too_many_arguments)]
pub(crate) fn build_tasks_par(
    refs: &mut [PrimRef],
    alt: &mut [PrimRef],
    mut tasks: Vec<Task>,
    p: &BuildParams,
    out: &mut Bvh2,
    threads: usize,
    c: &mut Counters,
    scratch: &mut Vec<ParScratch>,
    split_once: bool,
) -> Vec<Task> {
    use core::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    tasks.sort_by_key(|t| t.begin);
    let disjoint = tasks.windows(2).all(|w| w[0].end <= w[1].begin)
        && tasks
            .iter()
            .all(|t| t.begin <= t.end && t.end as usize <= refs.len().min(alt.len()));
    let mut left = Vec::new();
    if !disjoint || threads <= 1 || tasks.len() <= 1 {
        // One after the other on the whole buffers (a lone task gains nothing from a thread;
        // tasks that were not disjoint ranges would be a bug of the caller).
        let (mut bins, mut stack) = (Bins::new(), Vec::new());
        for t in tasks {
            let defer = split_once.then(|| (&mut left, (t.end - t.begin).saturating_sub(1)));
            subtree_with::<true>(refs, alt, p, out, t, &mut bins, &mut stack, c, defer, 0);
        }
        left.sort_by_key(|t| t.begin);
        return left;
    }
    // One job per task: the task rebased to its own slices of both buffers.
    type Job<'a> = (Task, &'a mut [PrimRef], &'a mut [PrimRef]);
    let mut jobs: Vec<Mutex<Option<Job<'_>>>> = Vec::with_capacity(tasks.len());
    for ((mine, amine), t) in task_ranges(refs, alt, &tasks).into_iter().zip(&tasks) {
        let local = Task {
            node: 0,
            begin: 0,
            end: t.end - t.begin,
            ..*t
        };
        jobs.push(Mutex::new(Some((local, mine, amine))));
    }
    let workers = threads.min(jobs.len());
    if scratch.len() < workers {
        scratch.resize_with(workers, ParScratch::default);
    }
    let mut order: Vec<usize> = (0..jobs.len()).collect();
    order.sort_by_key(|&i| core::cmp::Reverse(tasks[i].end - tasks[i].begin));
    let landed: Vec<Mutex<Option<Landed>>> = (0..jobs.len()).map(|_| Mutex::new(None)).collect();
    let next = AtomicUsize::new(0);
    {
        let (jobs, order, landed, next) = (&jobs, &order, &landed, &next);
        crate::par::each(scratch[..workers].iter_mut().enumerate(), |(w, ws)| {
            let mut bins = Bins::new();
            ws.out.nodes.clear();
            ws.out.prim_indices.clear();
            ws.left.clear();
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(&j) = order.get(i) else { break };
                let Some((mut t, r, a)) = jobs[j].lock().ok().and_then(|mut g| g.take()) else {
                    continue;
                };
                let (node, slot) = (ws.out.nodes.len(), ws.out.prim_indices.len());
                t.node = node as u32;
                ws.out.nodes.push(t.bounds.to_node(0, 0));
                ws.out.prim_indices.resize(slot + t.end as usize, 0);
                let mut lc = Counters::default();
                let first_left = ws.left.len();
                let defer = split_once.then(|| (&mut ws.left, t.end.saturating_sub(1)));
                let (wout, wstack) = (&mut ws.out, &mut ws.stack);
                subtree_with::<true>(r, a, p, wout, t, &mut bins, wstack, &mut lc, defer, slot as u32);
                let nodes = ws.out.nodes.len() - node;
                if let Ok(mut g) = landed[j].lock() {
                    *g = Some(Landed {
                        worker: w,
                        node,
                        nodes,
                        slot,
                        left: first_left..ws.left.len(),
                        c: lc,
                    });
                }
            }
        });
    }
    let landed: Vec<Landed> = landed
        .into_iter()
        .filter_map(|m| m.into_inner().ok().flatten())
        .collect();
    if landed.len() != tasks.len() {
        // NOTE: unreachable (every job is taken once and lands); a worker that panicked has
        // already ended the scope with its panic.
        return left;
    }
    // In range order, subtree k's nodes other than its own go to `base[k]..`; its own node to
    // the task's slot in the top.
    let mut base = Vec::with_capacity(tasks.len());
    let mut end = out.nodes.len();
    for l in &landed {
        base.push(end);
        end += l.nodes - 1;
    }
    out.nodes.resize(end, out.nodes[0]);
    // NOTE: wrapping: a node left to a later round is still a placeholder (index 0, count 0);
    // its slot is written again when that round builds it.
    let at = |l: &Landed, b: usize, i: u32| (b + i as usize).wrapping_sub(l.node + 1) as u32;
    let relocate = |l: &Landed, b: usize, t: &Task, mut nd: crate::traverse::Node| {
        if nd.count == 0 {
            nd.index = at(l, b, nd.index);
        } else {
            nd.index = (nd.index as usize - l.slot) as u32 + t.begin;
        }
        nd
    };
    for ((t, l), &b) in tasks.iter().zip(&landed).zip(&base) {
        let w = &scratch[l.worker];
        out.nodes[t.node as usize] = relocate(l, b, t, w.out.nodes[l.node]);
        c.leaves += l.c.leaves;
        c.max_depth = c.max_depth.max(l.c.max_depth);
        c.forced_splits += l.c.forced_splits;
        left.extend(w.left[l.left.clone()].iter().map(|d| Task {
            node: at(l, b, d.node),
            begin: d.begin + t.begin,
            end: d.end + t.begin,
            ..d.clone()
        }));
    }
    // The moves, side by side: each subtree's slices of `out` are disjoint.
    type Move<'a> = (&'a mut [crate::traverse::Node], &'a mut [u32], usize);
    let mut moves: Vec<Mutex<Option<Move<'_>>>> = Vec::with_capacity(tasks.len());
    let (mut nodes, mut prims) = (
        &mut out.nodes[base.first().copied().unwrap_or(0)..],
        &mut out.prim_indices[..],
    );
    let mut pat = 0usize;
    for (k, (t, l)) in tasks.iter().zip(&landed).enumerate() {
        let (mine, rest) = core::mem::take(&mut nodes).split_at_mut(l.nodes - 1);
        nodes = rest;
        let (_, prest) = core::mem::take(&mut prims).split_at_mut(t.begin as usize - pat);
        let (pmine, prest) = prest.split_at_mut((t.end - t.begin) as usize);
        prims = prest;
        pat = t.end as usize;
        moves.push(Mutex::new(Some((mine, pmine, k))));
    }
    let next = AtomicUsize::new(0);
    let scratch = &*scratch;
    {
        let (moves, order, next, tasks, landed, base) = (&moves, &order, &next, &tasks, &landed, &base);
        crate::par::each(0..workers, |_| {
            {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&j) = order.get(i) else { break };
                    let Some((dst, pdst, k)) = moves[j].lock().ok().and_then(|mut g| g.take()) else {
                        continue;
                    };
                    let (t, l) = (&tasks[k], &landed[k]);
                    let w = &scratch[l.worker].out;
                    for (d, &nd) in dst.iter_mut().zip(&w.nodes[l.node + 1..l.node + l.nodes]) {
                        *d = relocate(l, base[k], t, nd);
                    }
                    // Only leaves write slots (a split-once job that made none leaves its range
                    // to a later round).
                    if l.c.leaves > 0 {
                        pdst.copy_from_slice(&w.prim_indices[l.slot..l.slot + pdst.len()]);
                    }
                }
            }
        });
    }
    left
}

impl Task {
    /// The task of building node `node` (already in the array) over `refs[begin..end]` at
    /// `depth`: `[node, begin, end, depth]`, with the range's box and centroid bounds.
    pub(crate) fn new(task: [u32; 4], bounds: Box8, cb: CBounds) -> Self {
        let [node, begin, end, depth] = task;
        Self {
            node,
            begin,
            end,
            depth,
            in_alt: false,
            bounds,
            cb,
        }
    }
}

/// Builds the subtree of task `root`, whose range is valid in `refs` (`alt` is the second buffer,
/// as long), into `out` (whose primitive-index array covers the range); `bins` and `stack` are
/// scratch.
#[allow(clippy::too_many_arguments)]
pub(crate) fn subtree(
    refs: &mut [PrimRef],
    alt: &mut [PrimRef],
    p: &BuildParams,
    out: &mut Bvh2,
    root: Task,
    bins: &mut Bins,
    stack: &mut Vec<Task>,
    c: &mut Counters,
) {
    subtree_with::<true>(refs, alt, p, out, root, bins, stack, c, None, 0);
}

/// [`subtree`]; `LOCAL_SMALL`: small ranges go to [`small::subtree`] (`false`: the task loop
/// builds them with the same splits, node by node; kept as the reference the tests and the speed
/// harness compare with). With `defer = Some((tasks, grain))`, a task of at most `grain`
/// references is not built but pushed to `tasks` (its node is in `out`, still a placeholder):
/// the rounds of the parallel build, which split each task once. Leaves take the slots `off`
/// after their range (0 but in the parallel build's workers).
#[allow(clippy::too_many_arguments)]
pub(crate) fn subtree_with<const LOCAL_SMALL: bool>(
    refs: &mut [PrimRef],
    alt: &mut [PrimRef],
    p: &BuildParams,
    out: &mut Bvh2,
    root: Task,
    bins: &mut Bins,
    stack: &mut Vec<Task>,
    c: &mut Counters,
    mut defer: Option<(&mut Vec<Task>, u32)>,
    off: u32,
) {
    let bins = &mut *bins;
    let c = &mut *c;
    stack.clear();
    // The left child is built next, without a trip through the stack.
    let mut next = Some(root);
    while let Some(t) = next.take().or_else(|| stack.pop()) {
        if let Some((tasks, grain)) = defer.as_mut()
            && t.end - t.begin <= *grain
        {
            tasks.push(t);
            continue;
        }
        c.max_depth = c.max_depth.max(t.depth);
        let count = t.end - t.begin;
        let range = t.begin as usize..t.end as usize;
        let (src, dst) = if t.in_alt {
            (&mut alt[range.clone()], &mut refs[range.clone()])
        } else {
            (&mut refs[range.clone()], &mut alt[range.clone()])
        };
        if count <= p.min_leaf_size {
            make_leaf(out, c, &t, src, off);
            continue;
        }
        let area = t.bounds.half_area_nonempty();
        let leaf_cost = p.intersection_cost * count as f32;
        let may_leaf = count <= p.max_leaf_size;

        // Find a split, or decide on a leaf. `None`: all centroids coincide.
        let found: Option<Option<Split>> = match p.strategy {
            Strategy::BinnedSah
                if LOCAL_SMALL && count as usize <= binned::SMALL && count >= 2 && t.depth + count <= p.max_depth =>
            {
                // The whole subtree in local arrays (the same splits as the branch below).
                let all = p.bin_axes == BinAxes::All;
                small::subtree(src, t.begin + off, [t.node, t.depth], t.bounds, t.cb, all, p, out, c);
                continue;
            }
            Strategy::BinnedSah if count as usize <= binned::SMALL => {
                // Small ranges: an exact sweep (cheaper than binning at this size).
                let axes = match p.bin_axes {
                    BinAxes::All => 7,
                    BinAxes::Longest | BinAxes::AllButSmall => 1 << t.cb.longest_axis().0,
                };
                binned::find_small(src, axes).map(|(s, order)| {
                    if may_leaf && leaf_cost <= split_cost(p, s.cost, area, count) {
                        return None;
                    }
                    let k = s.left_count as usize;
                    let (lcb, rcb) = binned::reorder_small(src, dst, &order, k);
                    Some(Split {
                        mid: k,
                        moved: true,
                        left: s.left,
                        right: s.right,
                        lcb,
                        rcb,
                    })
                })
            }
            Strategy::BinnedSah => {
                // NOTE: a node with fewer references than bins uses fewer bins (the rest would be
                // empty): the bin sweep then costs O(N), not O(K), near the bottom of the tree.
                let nb = p.bins.min(count);
                let binning = Binning::new(&t.cb, nb);
                let longest = p.bin_axes == BinAxes::Longest;
                let stride = binned::sample_stride(count, p.bin_sample, may_leaf);
                let sampled = match binning.is_flat() {
                    false if stride > 1 => binned::find_sampled(src, &binning, nb as usize, longest, stride, bins),
                    _ => None,
                };
                if let Some(s) = sampled {
                    // The sample's plane; the sides' counts and boxes from the pass that moves
                    // them (both sides hold some of the sample's references: neither is empty).
                    let (mid, lcb, rcb, left, right) = binned::partition_measured(src, dst, &binning, &s);
                    Some(Some(Split {
                        mid,
                        moved: true,
                        left,
                        right,
                        lcb,
                        rcb,
                    }))
                } else {
                    let best = if binning.is_flat() {
                        None
                    } else {
                        binned::find(src, &binning, nb as usize, longest, bins)
                    };
                    best.map(|s| {
                        if may_leaf && leaf_cost <= split_cost(p, s.cost, area, count) {
                            return None;
                        }
                        let (mid, lcb, rcb) = binned::partition_into(src, dst, &binning, &s);
                        debug_assert_eq!(mid, s.left_count as usize);
                        Some(Split {
                            mid,
                            moved: true,
                            left: s.left,
                            right: s.right,
                            lcb,
                            rcb,
                        })
                    })
                }
            }
            _ => {
                let (_, extent) = t.cb.longest_axis();
                // `!(extent > 0)`: every centroid coincides (or NaN): no spatial split.
                (extent > 0.0).then(|| {
                    let s = median_split(src, &t.cb);
                    let (nl, nr) = (s.mid as f32, (count as usize - s.mid) as f32);
                    let sum = s.left.half_area_nonempty() * nl + s.right.half_area_nonempty() * nr;
                    (!(may_leaf && leaf_cost <= split_cost(p, sum, area, count))).then_some(s)
                })
            }
        };
        let split = match found {
            // A split that does not pay.
            Some(None) => {
                make_leaf(out, c, &t, src, off);
                continue;
            }
            Some(Some(s)) => s,
            None if may_leaf => {
                make_leaf(out, c, &t, src, off);
                continue;
            }
            None => {
                // All centroids coincide and the node is too big for a leaf: cut the range in the
                // middle (any order is as good as any other).
                c.forced_splits += 1;
                split_at(src, count as usize / 2)
            }
        };
        let (nl, nr) = (split.mid as u32, count - split.mid as u32);
        let split = if nl == 0 || nr == 0 || !depth_ok(t.depth, nl, nr, p.max_depth) {
            // Keep the depth bound (and, defensively, non-empty sides): balanced object median,
            // on whichever buffer now holds the range.
            c.forced_splits += 1;
            let holder = if split.moved { dst } else { src };
            Split {
                moved: split.moved,
                ..median_split(holder, &t.cb)
            }
        } else {
            split
        };
        let left = out.nodes.len() as u32;
        out.nodes[t.node as usize] = t.bounds.to_node(left, 0);
        out.nodes.push(split.left.to_node(0, 0));
        out.nodes.push(split.right.to_node(0, 0));
        let mid = t.begin + split.mid as u32;
        let in_alt = t.in_alt ^ split.moved;
        stack.push(Task {
            node: left + 1,
            begin: mid,
            end: t.end,
            depth: t.depth + 1,
            in_alt,
            bounds: split.right,
            cb: split.rcb,
        });
        next = Some(Task {
            node: left,
            begin: t.begin,
            end: mid,
            depth: t.depth + 1,
            in_alt,
            bounds: split.left,
            cb: split.lcb,
        });
    }
}

/// Makes `t` a leaf over `refs` (its range, in the buffer that holds it), its slots `off` after
/// its range's start.
fn make_leaf(out: &mut Bvh2, c: &mut Counters, t: &Task, refs: &[PrimRef], off: u32) {
    let (begin, end) = (t.begin + off, t.end + off);
    out.nodes[t.node as usize] = t.bounds.to_node(begin, end - begin);
    let slots = &mut out.prim_indices[begin as usize..end as usize];
    for (s, r) in slots.iter_mut().zip(refs) {
        *s = r.index();
    }
    c.leaves += 1;
}

/// Object median on the longest axis of `cb`: the lower half of the references (by centroid on
/// that axis) goes left. O(n) (`select_nth_unstable`); both sides non-empty for `refs.len() >= 2`.
fn median_split(refs: &mut [PrimRef], cb: &CBounds) -> Split {
    let (axis, _) = cb.longest_axis();
    let mid = refs.len() / 2;
    refs.select_nth_unstable_by(mid, |a, b| a.c2_axis(axis).total_cmp(&b.c2_axis(axis)));
    split_at(refs, mid)
}

/// Boxes and centroid bounds of `refs[..mid]` and `refs[mid..]` (in place).
fn split_at(refs: &[PrimRef], mid: usize) -> Split {
    let (l, r) = refs.split_at(mid);
    let (left, lcb) = bounds_of(l);
    let (right, rcb) = bounds_of(r);
    Split {
        mid,
        moved: false,
        left,
        right,
        lcb,
        rcb,
    }
}

/// The box and centroid bounds of `refs`.
pub(crate) fn bounds_of(refs: &[PrimRef]) -> (Box8, CBounds) {
    let (mut b, mut cb) = (Box8::EMPTY, CBounds::EMPTY);
    for r in refs {
        b.grow(r.bounds());
        cb.grow(r.c2());
    }
    (b, cb)
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::build::prims::prepare;

    /// The root of a scene split once by `subtree_with` (sequential) and by `split_wide` on
    /// `threads` threads: the same children (ranges, boxes, centroid bounds, buffer) and the same
    /// references in the children's ranges, in the same order. Returns how many tasks
    /// `split_wide` split (0 or 1).
    fn compare(tris: &[crate::geometry::Triangle], p: &BuildParams, threads: usize) -> usize {
        let mut refs = Vec::new();
        let info = prepare(tris, &mut refs).unwrap();
        let n = refs.len();
        let (mut alt, mut out) = (Vec::new(), Bvh2::default());
        out.prim_indices.resize(n, 0);
        let root = start(n, &mut alt, &info, &mut out);
        let (mut seq_refs, mut seq_alt, mut seq_out) = (refs.clone(), alt.clone(), out.clone());
        let mut want = Vec::new();
        let (mut bins, mut stack, mut c) = (Bins::new(), Vec::new(), Counters::default());
        let grain = (root.end - root.begin).saturating_sub(1);
        let defer = Some((&mut want, grain));
        subtree_with::<true>(
            &mut seq_refs,
            &mut seq_alt,
            p,
            &mut seq_out,
            root.clone(),
            &mut bins,
            &mut stack,
            &mut c,
            defer,
            0,
        );
        let mut pool = Vec::new();
        let (got, rest) = split_wide(
            &mut refs,
            &mut alt,
            alloc::vec![root],
            p,
            &mut out,
            threads,
            &mut c,
            &mut pool,
        );
        if got.is_empty() {
            assert_eq!(rest.len(), 1);
            return 0;
        }
        assert!(rest.is_empty());
        assert_eq!(got.len(), 2);
        want.sort_by_key(|t| t.begin);
        for (g, w) in got.iter().zip(&want) {
            assert_eq!((g.begin, g.end, g.depth, g.in_alt), (w.begin, w.end, w.depth, w.in_alt));
            assert_eq!(g.bounds.to_aabb(), w.bounds.to_aabb());
            assert_eq!(g.cb.to_aabb(), w.cb.to_aabb());
            let (gb, wb) = if g.in_alt { (&alt, &seq_alt) } else { (&refs, &seq_refs) };
            for i in g.begin as usize..g.end as usize {
                assert_eq!(gb[i].index(), wb[i].index(), "reference {i}");
            }
        }
        1
    }

    #[test]
    fn split_wide_is_the_sequential_split() {
        let soup = crate::scene::thin_soup(100_000, 3);
        let clustered = crate::scene::clustered_soup(70_000, 9, 5);
        let all = BuildParams::balanced();
        let bins64 = BuildParams {
            bins: 64,
            ..BuildParams::balanced()
        };
        for tris in [&soup, &clustered] {
            for p in [BuildParams::fast(), all, bins64] {
                for threads in [2, 3, 4, 16] {
                    assert_eq!(compare(tris, &p, threads), 1);
                }
            }
        }
        // Every centroid the same: no plain split, left to the sequential path.
        let t = [crate::Vec3::ZERO, crate::Vec3::X, crate::Vec3::Y];
        assert_eq!(compare(&alloc::vec![t; 40_000], &BuildParams::fast(), 4), 0);
        // A leaf is cheaper (huge leaves allowed): left to the sequential path too.
        let big = BuildParams {
            max_leaf_size: 200_000,
            intersection_cost: 1e-6,
            ..BuildParams::fast()
        };
        assert_eq!(compare(&soup, &big, 4), 0);
    }
}
