//! Spatial splits: the SBVH of Stich, Friedrich and Dietrich ("Spatial Splits in Bounding Volume
//! Hierarchies", 2009), [`Bvh2::build_spatial`].
//!
//! A top-down SAH build whose nodes may also split *space*: a plane cuts the node's box, every
//! triangle reference that straddles it is clipped into a left and a right part, and each part's
//! box is that of the triangle clipped to the side, within the reference's box. Long thin or
//! large triangles, whose boxes overlap many others, then stop spoiling every node above them.
//! The price is references: a triangle may sit in several leaves (a hit is still one triangle;
//! a [`HitFilter`](crate::traverse::HitFilter) may see it once per leaf, as with Embree's
//! spatial splits), and a leaf's box may no longer contain its triangles whole
//! ([`Bvh2::validate_split`] checks such trees).
//!
//! Per node, as in the paper: the best object split (binned SAH over centroids,
//! [`BuildParams::bins`] per axis, all three axes); if its children's boxes overlap by more than
//! [`SpatialSplits::alpha`] of the root's area (the paper's restriction: spatial splits only where
//! object splits leave overlap), also the best spatial split ([`SpatialSplits::bins`] planes per
//! axis, "chopped binning": each reference clipped into every bin it spans); then a leaf, the
//! object split or the spatial split, whichever the SAH prices lowest. Executing a spatial split
//! "unsplits" a straddling reference where putting it whole on one side is cheaper (the paper's
//! reference unsplitting). [`SpatialSplits::max_references`] caps the references (a multiple of
//! the valid triangles), shared down the tree in proportion to the children's references; where
//! a subtree's share is spent, only object splits remain there. With `std`,
//! [`Bvh2::build_spatial_par`] builds the same tree on several threads.
//!
//! Every clipped box is conservative: the crossing points of the triangle's edges with the plane
//! are widened by a bound on their rounding before they enter a box, and each part's box is
//! intersected with (so never larger than) the reference's. Every point of a triangle thus lies
//! in the box of some leaf that references it, which is what the traversals need (tested against
//! brute force, `tests/spatial.rs`).
//!
//! Bad input is handled as by [`Bvh2::build`]: triangles with a non-finite vertex are left out
//! and counted ([`BuildStats::invalid`]); no split that fails to shrink both sides is taken; a
//! subtree that could not finish within [`BuildParams::max_depth`] is split at its object median
//! ([`BuildStats::forced_splits`]).

use super::prims::usable_bounds;
use super::topdown::split_cost;
use super::{BuildError, BuildParams, BuildStats, Bvh2, MAX_PRIMITIVES, Node, Refine};
use crate::geometry::{Aabb, Triangles};
use alloc::vec::Vec;
use glam::Vec3A;

/// The knobs of [`Bvh2::build_spatial`] beyond [`BuildParams`].
///
/// ```
/// use strahl::build::SpatialSplits;
/// let s = SpatialSplits::default();
/// assert_eq!((s.alpha, s.max_references, s.bins, s.min_node_size), (1e-5, 1.5, 16, 64));
/// assert!(s.check().is_ok());
/// assert!(SpatialSplits { max_references: 0.5, ..s }.check().is_err()); // below one per triangle
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialSplits {
    /// Spatial splits are tried only at nodes whose best object split leaves children that
    /// overlap by more than `alpha` times the root's surface area (Stich et al.'s restriction;
    /// `1e-5` there and here). `0` tries them everywhere. Finite, `>= 0`.
    pub alpha: f32,
    /// Most references the tree may hold, as a multiple of the valid triangles: `1.0` allows no
    /// spatial split, `1.5` (the default) half again as many. In `1.0 ..= 16.0`. The budget is
    /// shared down the tree: a node's children get what it may still add in proportion to their
    /// references (as Embree's spatial-split builder shares its extended ranges), so each
    /// subtree's budget is its own and subtrees build alike in any order
    /// ([`Bvh2::build_spatial_par`]).
    pub max_references: f32,
    /// Planes per axis of the spatial-split search, in [`MIN_BINS`](super::MIN_BINS)`..=`
    /// [`MAX_BINS`](super::MAX_BINS).
    pub bins: u32,
    /// Spatial splits are searched only at nodes of at least this many references (`>= 2`):
    /// the search clips every reference into every bin it spans, the costliest part of the
    /// build, and the small nodes near the leaves gain least from it.
    pub min_node_size: u32,
}

impl Default for SpatialSplits {
    fn default() -> Self {
        Self {
            alpha: 1e-5,
            max_references: 1.5,
            bins: 16,
            min_node_size: 64,
        }
    }
}

impl SpatialSplits {
    /// `Ok` if every field is in its documented range.
    ///
    /// ```
    /// use strahl::build::SpatialSplits;
    /// assert!(SpatialSplits { alpha: f32::NAN, ..Default::default() }.check().is_err());
    /// assert!(SpatialSplits { bins: 3, ..Default::default() }.check().is_err());
    /// ```
    pub fn check(&self) -> Result<(), BuildError> {
        let bad = |what| Err(BuildError::InvalidParams(what));
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return bad("spatial splits: alpha must be finite and >= 0");
        }
        if !(1.0..=16.0).contains(&self.max_references) {
            return bad("spatial splits: max_references must be in 1 ..= 16");
        }
        if !(super::MIN_BINS..=super::MAX_BINS).contains(&self.bins) {
            return bad("spatial splits: bins must be in 4 ..= 64");
        }
        if self.min_node_size < 2 {
            return bad("spatial splits: min_node_size must be >= 2");
        }
        Ok(())
    }
}

/// One reference: a triangle, or the part of it within `b`.
#[derive(Clone, Copy)]
struct Ref {
    b: Bx,
    prim: u32,
}

/// A node still to build: its references are `buf[begin..end]`, always the top of the buffer.
#[derive(Clone, Copy)]
struct Task {
    begin: usize,
    end: usize,
    slot: u32,
    depth: u32,
    /// The most references the task's subtree may hold (its share of the budget).
    cap: usize,
    bounds: Bx,
}

/// The chosen split of a node.
#[derive(Clone, Copy)]
enum Split {
    /// Centroid bin `plane` and below on `axis` go left (bins of the node's centroid bounds).
    Object { axis: usize, plane: usize, cost: f32 },
    /// Plane `lo + (plane + 1) * width` on `axis` (the node's box cut into bins).
    Spatial {
        axis: usize,
        pos: f32,
        cost: f32,
        left: Bx,
        right: Bx,
        nl: u32,
        nr: u32,
    },
}

impl Split {
    /// The split's SAH sum `A(L) N_L + A(R) N_R`.
    fn cost(self) -> f32 {
        match self {
            Self::Object { cost, .. } | Self::Spatial { cost, .. } => cost,
        }
    }
}

/// Scratch of one build, reused from node to node.
#[derive(Default)]
struct Scratch {
    bins: Vec<(Bx, u32)>,
    sbins: Vec<(Bx, u32, u32)>,
    suffix: Vec<(Bx, u32)>,
    rbox: Vec<Bx>,
    left: Vec<Ref>,
    right: Vec<Ref>,
}

/// A box in SIMD registers (the builder's own; every bound finite or the empty box's infinities).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Bx {
    min: Vec3A,
    max: Vec3A,
}

impl Bx {
    const EMPTY: Self = Self {
        min: Vec3A::INFINITY,
        max: Vec3A::NEG_INFINITY,
    };

    #[inline(always)]
    fn from_aabb(b: &Aabb) -> Self {
        Self {
            min: b.min.into(),
            max: b.max.into(),
        }
    }

    #[inline(always)]
    pub(crate) fn to_aabb(self) -> Aabb {
        Aabb::new(self.min.into(), self.max.into())
    }

    #[inline(always)]
    fn grow_aabb(&mut self, o: &Bx) {
        self.min = self.min.min(o.min);
        self.max = self.max.max(o.max);
    }

    #[inline(always)]
    fn grow(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    #[inline(always)]
    fn union(&self, o: &Bx) -> Bx {
        Bx {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    #[inline(always)]
    fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// Half the surface area; 0 for the empty box.
    #[inline(always)]
    fn half_area(&self) -> f32 {
        let d = (self.max - self.min).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// `a` and `b` intersected (empty where they do not meet).
#[inline(always)]
fn intersect(a: &Bx, b: &Bx) -> Bx {
    Bx {
        min: a.min.max(b.min),
        max: a.max.min(b.max),
    }
}

#[inline(always)]
fn area(b: &Bx) -> f32 {
    b.half_area()
}

/// Triangle `t` clipped at `pos` on `axis`, within `within`: the boxes of its parts on either
/// side (either may be empty). Conservative: see the module docs.
#[inline(always)]
pub(crate) fn clip(t: &[Vec3A; 3], within: &Bx, axis: usize, pos: f32) -> (Bx, Bx) {
    let (mut l, mut r) = (Bx::EMPTY, Bx::EMPTY);
    for e in 0..3 {
        let (v0, v1) = (t[e], t[(e + 1) % 3]);
        let (p0, p1) = (v0[axis], v1[axis]);
        if p0 <= pos {
            l.grow(v0);
        }
        if p0 >= pos {
            r.grow(v0);
        }
        if (p0 < pos && pos < p1) || (p1 < pos && pos < p0) {
            let s = ((pos - p0) / (p1 - p0)).clamp(0.0, 1.0);
            let mut x = v0 + (v1 - v0) * s;
            // NOTE: `x` carries a few roundings of the vertices' magnitudes (a subtraction, a
            // division, a product, a sum); widen by eight units of the larger magnitude and the
            // smallest normal, then put the split coordinate exactly on the plane.
            let mut pad = v0.abs().max(v1.abs()) * (8.0 * f32::EPSILON) + Vec3A::splat(f32::MIN_POSITIVE);
            x[axis] = pos;
            pad[axis] = 0.0;
            if !(x.is_finite() && pad.is_finite()) {
                // Overflow (inf - inf, inf * 0): no bound; see below.
                return (*within, *within);
            }
            for side in [&mut l, &mut r] {
                side.grow(x - pad);
                side.grow(x + pad);
            }
        }
    }
    // A NaN plane: both sides get the whole box. (So does a crossing point that overflowed, an
    // edge longer than `f32::MAX`, which the builder never sees: such triangles are left out.)
    if pos.is_nan() {
        return (*within, *within);
    }
    (intersect(&l, within), intersect(&r, within))
}

/// The boxes of the parts of triangle `t` on either side of the plane `pos` on `axis` (0, 1, 2
/// for x, y, z), each within `within` (the box of the part of `t` being split, or its whole box):
/// the clipping [`Bvh2::build_spatial`] uses, for split callbacks of other builders (Embree's
/// `splitPrimitive`). Conservative: every point of `t` inside `within` on a side lies in that
/// side's box (crossing points are widened by a bound on their rounding); a side with no part of
/// `t` is [`Aabb::EMPTY`] or another empty box. An axis above 2 is taken as 2.
///
/// ```
/// use strahl::{Aabb, Vec3, build::clip_triangle};
/// let t = [Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 4.0, 0.0)];
/// let (left, right) = clip_triangle(&t, &Aabb::from_points(&t), 0, 1.0);
/// assert_eq!((left.min.x, left.max.x, right.min.x, right.max.x), (0.0, 1.0, 1.0, 4.0));
/// assert!(right.max.y >= 3.0 && right.max.y < 3.0 + 1e-5); // the edge crosses x = 1 at y = 3
/// let (l, r) = clip_triangle(&t, &Aabb::from_points(&t), 0, 5.0); // all on the left
/// assert!(l == Aabb::from_points(&t) && r.is_empty());
/// ```
pub fn clip_triangle(t: &crate::geometry::Triangle, within: &Aabb, axis: usize, pos: f32) -> (Aabb, Aabb) {
    let (l, r) = clip(&t.map(Vec3A::from), &Bx::from_aabb(within), axis.min(2), pos);
    let out = |b: Bx| if b.is_empty() { Aabb::EMPTY } else { b.to_aabb() };
    (out(l), out(r))
}

impl Bvh2 {
    /// Builds a tree with spatial splits (SBVH, Stich et al. 2009; see
    /// [`SpatialSplits`] and the notes in `build/spatial.rs`): triangles only,
    /// since references are clipped against planes. From `params` it takes the costs, the leaf
    /// sizes, `bins` (the object splits' binning), `max_depth` and `refine` (the passes work on
    /// node boxes, so they keep the clipped ones); the other fields are not used.
    ///
    /// A triangle may be referenced by several leaves (`prim_indices` holds at most
    /// `max_references` times the valid triangles), and leaf boxes may cut through triangles:
    /// check such trees with [`validate_split`](Self::validate_split). The wide collapse and every
    /// traversal take them as they are; [`refit`](Self::refit) makes boxes of whole triangles
    /// again (valid, but without the splits' gain).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{BuildParams, Bvh2, SpatialSplits}, traverse::Moller};
    /// let soup = strahl::scene::thin_soup(2_000, 7); // long thin triangles
    /// let p = BuildParams::quality();
    /// let (sbvh, stats) = Bvh2::build_spatial(&soup[..], &p, &SpatialSplits::default()).unwrap();
    /// assert!(sbvh.validate_split(&soup[..]).is_ok());
    /// assert_eq!(stats.primitives, 2_000);
    /// assert!(sbvh.prim_indices.len() > 2_000 && sbvh.prim_indices.len() <= 3_000);
    /// let (plain, _) = Bvh2::build(&soup[..], &p).unwrap();
    /// assert!(sbvh.sah_cost(1.0, 1.0) < plain.sah_cost(1.0, 1.0));
    /// let ray = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z);
    /// assert_eq!(sbvh.intersect::<Moller, _>(&soup[..], &ray), plain.intersect::<Moller, _>(&soup[..], &ray));
    /// ```
    pub fn build_spatial<P: Triangles + ?Sized>(
        tris: &P,
        params: &BuildParams,
        splits: &SpatialSplits,
    ) -> Result<(Bvh2, BuildStats), BuildError> {
        spatial_build(tris, params, splits, |cx, root, mut buf, out, stats| {
            cx.run(alloc::vec![root], &mut buf, out, stats, &mut Scratch::default(), None);
        })
    }

    /// [`build_spatial`](Self::build_spatial) on `threads` threads (feature `std`; at most
    /// [`MAX_THREADS`](super::MAX_THREADS)): the same tree, node for node and slot for slot (so
    /// `params.refine` finds the same tree too). The top of the tree is split in rounds, every
    /// large task once per round, the tasks side by side; then each subtree below is built whole
    /// by one worker (its share of the reference budget is its own, so the order does not
    /// matter); the parts are joined and numbered as the sequential build numbers them.
    /// `threads <= 1` is the sequential build.
    ///
    /// ```
    /// use strahl::build::{BuildParams, Bvh2, SpatialSplits};
    /// let soup = strahl::scene::thin_soup(20_000, 7);
    /// let (p, sp) = (BuildParams::default(), SpatialSplits::default());
    /// let (one, _) = Bvh2::build_spatial(&soup[..], &p, &sp).unwrap();
    /// let (four, _) = Bvh2::build_spatial_par(&soup[..], &p, &sp, 4).unwrap();
    /// four.validate_split(&soup[..]).unwrap();
    /// assert_eq!(four, one);
    /// ```
    #[cfg(feature = "std")]
    pub fn build_spatial_par<P: Triangles + Sync + ?Sized>(
        tris: &P,
        params: &BuildParams,
        splits: &SpatialSplits,
        threads: usize,
    ) -> Result<(Bvh2, BuildStats), BuildError> {
        let threads = threads.clamp(1, super::MAX_THREADS);
        spatial_build(tris, params, splits, |cx, root, mut buf, out, stats| {
            if threads > 1 {
                par::run(cx, root, buf, threads, out, stats);
            } else {
                cx.run(alloc::vec![root], &mut buf, out, stats, &mut Scratch::default(), None);
            }
        })
    }
}

/// [`Bvh2::build_spatial`] with `build` making the tree below the root: it gets the build's
/// context, the root task (node 0 is in the output), the references and the output.
fn spatial_build<P: Triangles + ?Sized>(
    tris: &P,
    params: &BuildParams,
    splits: &SpatialSplits,
    build: impl FnOnce(&Ctx<'_, P>, Task, Vec<Ref>, &mut Bvh2, &mut BuildStats),
) -> Result<(Bvh2, BuildStats), BuildError> {
    {
        params.check()?;
        splits.check()?;
        let total = tris.len();
        if total > MAX_PRIMITIVES {
            return Err(BuildError::TooManyPrimitives { count: total });
        }
        let mut out = Bvh2::default();
        let mut stats = BuildStats::default();
        let mut buf: Vec<Ref> = Vec::with_capacity(total);
        let mut root = Bx::EMPTY;
        for i in 0..total {
            match usable_bounds(tris, i) {
                Some(b) => {
                    let b = Bx::from_aabb(&b);
                    root.grow_aabb(&b);
                    buf.push(Ref { b, prim: i as u32 });
                }
                None => stats.invalid += 1,
            }
        }
        let n = buf.len();
        stats.primitives = n as u32;
        if n == 0 {
            return Ok((out, stats));
        }
        // Within `MAX_PRIMITIVES` (so every slot fits a `u32`).
        let budget = ((n as f64 * f64::from(splits.max_references)) as usize).min(MAX_PRIMITIVES);
        let cx = Ctx {
            tris,
            params,
            splits,
            root_area: {
                let d = (root.max.to_array(), root.min.to_array());
                let e: [f64; 3] = core::array::from_fn(|a| f64::from(d.0[a]) - f64::from(d.1[a]));
                e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
            },
        };
        out.nodes.push(Node::leaf(&root.to_aabb(), 0, 1));
        out.prim_indices.reserve(n);
        let root = Task {
            begin: 0,
            end: n,
            slot: 0,
            depth: 1,
            cap: budget,
            bounds: root,
        };
        build(&cx, root, buf, &mut out, &mut stats);
        stats.nodes = out.nodes.len() as u32;
        // The refinement passes work on node boxes alone, so they keep the clipped ones.
        // NOTE: a tree just built is well formed; the passes cannot fail on it.
        let depth = params.max_depth;
        match params.refine {
            Refine::None => {}
            Refine::Rotations(r) => {
                if let Ok(r) = out.optimize_rotations(r, depth) {
                    (stats.max_depth, stats.restructured) = (r.max_depth, r.rotations);
                }
            }
            Refine::Treelets(t) => {
                if let Ok(r) = out.optimize_treelets(&t, depth) {
                    (stats.max_depth, stats.restructured) = (r.max_depth, r.restructured);
                }
            }
            Refine::AgglomerativeTreelets(t) => {
                if let Ok(r) = out.optimize_treelets_agglomerative(&t, depth) {
                    (stats.max_depth, stats.restructured) = (r.max_depth, r.restructured);
                }
            }
            Refine::Reinsertion(p) => {
                if let Ok(r) = out.optimize_reinsertion(&p, depth) {
                    (stats.max_depth, stats.restructured) = (r.max_depth, r.moved);
                    stats.nodes = out.nodes.len() as u32;
                }
            }
        }
        Ok((out, stats))
    }
}

/// What every node of one spatial build reads.
struct Ctx<'a, P: ?Sized> {
    tris: &'a P,
    params: &'a BuildParams,
    splits: &'a SpatialSplits,
    /// The root box's surface area (half), in f64: the overlap threshold's unit.
    root_area: f64,
}

/// A subtree left for a worker: its task and references.
type Job = (Task, Vec<Ref>);

impl<P: Triangles + ?Sized> Ctx<'_, P> {
    /// Builds `tasks` (their references the top of `buf`, each task's node already in `out`)
    /// into `out`, depth first. With `defer = Some((grain, jobs))`, a task of at most `grain`
    /// references is not built but moved to `jobs` with its references (the parallel build).
    fn run(
        &self,
        mut tasks: Vec<Task>,
        buf: &mut Vec<Ref>,
        out: &mut Bvh2,
        stats: &mut BuildStats,
        s: &mut Scratch,
        mut defer: Option<(usize, &mut Vec<Job>)>,
    ) {
        while let Some(t) = tasks.pop() {
            let count = t.end - t.begin;
            if let Some((grain, jobs)) = defer.as_mut()
                && count <= *grain
            {
                // Its references are the top of `buf` (see `Task`).
                jobs.push((t, buf.split_off(t.begin)));
                continue;
            }
            let node_area = area(&t.bounds);
            stats.max_depth = stats.max_depth.max(t.depth);
            let leaf_ok = count as u32 <= self.params.max_leaf_size;
            // A subtree of `count` references split at medians needs `ceil(log2 count)` levels.
            let levels = usize::BITS - (count.max(1) - 1).leading_zeros();
            let forced = t.depth + levels >= self.params.max_depth;
            let mut object = None;
            let mut choice = None;
            if count as u32 > self.params.min_leaf_size && !forced {
                let refs = &buf[t.begin..t.end];
                let best = best_object(refs, object_bins(self.params, count), s);
                let try_spatial = count < t.cap
                    && count >= self.splits.min_node_size as usize
                    && match best {
                        // In f64: a root area that overflows `f32` must not turn the test off.
                        Some((_, _, _, ref lb, ref rb)) => {
                            self.splits.alpha == 0.0
                                || f64::from(area(&intersect(lb, rb))) > f64::from(self.splits.alpha) * self.root_area
                        }
                        None => true,
                    };
                object = best.map(|(axis, plane, cost, _, _)| Split::Object { axis, plane, cost });
                choice = object;
                if try_spatial
                    && let Some(sp) =
                        best_spatial(self.tris, refs, &t.bounds, self.splits.bins as usize, t.cap - count, s)
                    && sp.cost() < choice.map_or(f32::INFINITY, Split::cost)
                {
                    choice = Some(sp);
                }
                if let Some(c) = choice
                    && leaf_ok
                    && self.params.intersection_cost * count as f32
                        <= split_cost(self.params, c.cost(), node_area, count as u32)
                {
                    choice = None;
                    object = None;
                }
            }
            let leaf = count as u32 <= self.params.min_leaf_size || (choice.is_none() && (leaf_ok || count < 2));
            if leaf {
                let first = out.prim_indices.len() as u32;
                out.prim_indices.extend(buf[t.begin..t.end].iter().map(|r| r.prim));
                out.nodes[t.slot as usize] = Node::leaf(&t.bounds.to_aabb(), first, count as u32);
                stats.leaves += 1;
                buf.truncate(t.begin);
                continue;
            }
            // Into `s.left` and `s.right`. A spatial split that fails to shrink both sides falls
            // back to the object split; one whose bins put every centroid on one side, or none
            // (the depth bound, coincident centroids), to the median.
            let mut done = false;
            if let Some(Split::Spatial {
                axis,
                pos,
                left,
                right,
                nl,
                nr,
                ..
            }) = choice
            {
                done = split_spatial(self.tris, &buf[t.begin..t.end], axis, pos, (left, nl), (right, nr), s)
                    && s.left.len() < count
                    && s.right.len() < count
                    && s.left.len() + s.right.len() <= t.cap;
            }
            if !done && let Some(Split::Object { axis, plane, .. }) = object {
                s.left.clear();
                s.right.clear();
                let refs = &buf[t.begin..t.end];
                let bins = object_bins(self.params, count);
                let (lo, scale) = centroid_binning(refs, bins)[axis];
                for r in refs {
                    let c = r.b.min[axis] + r.b.max[axis];
                    let bin = (((c - lo) * scale) as usize).min(bins - 1);
                    if bin <= plane {
                        s.left.push(*r);
                    } else {
                        s.right.push(*r);
                    }
                }
                done = !s.left.is_empty() && !s.right.is_empty();
            }
            if !done {
                stats.forced_splits += 1;
                let refs = &mut buf[t.begin..t.end];
                median(refs);
                s.left.clear();
                s.right.clear();
                s.left.extend_from_slice(&refs[..count / 2]);
                s.right.extend_from_slice(&refs[count / 2..]);
            }
            buf.truncate(t.begin);
            let (nl, nr) = (s.left.len(), s.right.len());
            let lb = s.left.iter().fold(Bx::EMPTY, |a, r| a.union(&r.b));
            let rb = s.right.iter().fold(Bx::EMPTY, |a, r| a.union(&r.b));
            buf.extend_from_slice(&s.left);
            buf.extend_from_slice(&s.right);
            let l = out.nodes.len() as u32;
            out.nodes[t.slot as usize] = Node::interior(&t.bounds.to_aabb(), l);
            out.nodes.push(Node::leaf(&lb.to_aabb(), 0, 1));
            out.nodes.push(Node::leaf(&rb.to_aabb(), 0, 1));
            // The references the node may still add, shared in proportion to the children's
            // (as Embree's spatial-split builder shares its extended ranges): each subtree's
            // budget is its own, so subtrees build alike in any order (or on other threads).
            let spare = t.cap - (nl + nr);
            let lspare = (spare as u64 * nl as u64 / (nl + nr) as u64) as usize;
            tasks.push(Task {
                begin: t.begin,
                end: t.begin + nl,
                slot: l,
                depth: t.depth + 1,
                cap: nl + lspare,
                bounds: lb,
            });
            tasks.push(Task {
                begin: t.begin + nl,
                end: t.begin + nl + nr,
                slot: l + 1,
                depth: t.depth + 1,
                cap: nr + (spare - lspare),
                bounds: rb,
            });
        }
    }
}

/// Bins of a node's object-split search: [`BuildParams::bins`], or as many as the node has
/// references where that is fewer (at least 4): the small nodes near the leaves, the most
/// numerous, then sweep fewer empty bins.
// PERF: the 262k thin soup's spatial build (`tests/spatial_speed.rs`, best of 3): 649 -> 588 ms
// with 16 bins, 885 -> 609 ms with 64 (SAH cost +0.05% and +0.09%).
#[inline]
fn object_bins(params: &BuildParams, count: usize) -> usize {
    (params.bins as usize).min(count.max(4))
}

/// Per axis, the origin and scale that put doubled centroids `min + max` of `refs` into `bins`
/// bins (scale 0 on a flat axis: everything in bin 0).
fn centroid_binning(refs: &[Ref], bins: usize) -> [(f32, f32); 3] {
    let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for r in refs {
        let c = r.b.min + r.b.max;
        lo = lo.min(c);
        hi = hi.max(c);
    }
    let ext = hi - lo;
    core::array::from_fn(|a| {
        let scale = if ext[a] > 0.0 {
            bins as f32 * (1.0 - 1e-6) / ext[a]
        } else {
            0.0
        };
        (lo[a], if scale.is_finite() { scale } else { 0.0 })
    })
}

/// The cheapest binned object split of `refs`: axis, last left bin, SAH sum
/// `A(L) N_L + A(R) N_R` and both boxes; `None` where every axis is flat or no plane has
/// references on both sides.
fn best_object(refs: &[Ref], bins: usize, s: &mut Scratch) -> Option<(usize, usize, f32, Bx, Bx)> {
    let binning = centroid_binning(refs, bins);
    let lo = Vec3A::from_array(binning.map(|b| b.0));
    let scale = Vec3A::from_array(binning.map(|b| b.1));
    let last = Vec3A::splat((bins - 1) as f32);
    // All three axes in one pass: bins `a * bins ..` of axis `a`.
    s.bins.clear();
    s.bins.resize(3 * bins, (Bx::EMPTY, 0));
    for r in refs {
        let q = ((r.b.min + r.b.max - lo) * scale).min(last);
        for a in 0..3 {
            let bin = &mut s.bins[a * bins + q[a] as usize];
            bin.0.grow_aabb(&r.b);
            bin.1 += 1;
        }
    }
    let mut best: Option<(usize, usize, f32, Bx, Bx)> = None;
    for (axis, &(_, scale)) in binning.iter().enumerate() {
        if scale == 0.0 {
            continue;
        }
        sweep(
            &s.bins[axis * bins..(axis + 1) * bins],
            &mut s.suffix,
            |plane, cost, lb, rb| {
                if best.is_none_or(|b| cost < b.2) {
                    best = Some((axis, plane, cost, lb, rb));
                }
            },
        );
    }
    best
}

/// Every plane between `bins` (box and count each): `f(plane, A(L) N_L + A(R) N_R, L, R)` for
/// the planes with references on both sides (`plane` = last bin on the left).
fn sweep(bins: &[(Bx, u32)], suffix: &mut Vec<(Bx, u32)>, mut f: impl FnMut(usize, f32, Bx, Bx)) {
    suffix.clear();
    suffix.resize(bins.len(), (Bx::EMPTY, 0));
    let mut acc = (Bx::EMPTY, 0u32);
    for i in (0..bins.len()).rev() {
        acc = (acc.0.union(&bins[i].0), acc.1 + bins[i].1);
        suffix[i] = acc;
    }
    let mut left = (Bx::EMPTY, 0u32);
    for i in 0..bins.len().saturating_sub(1) {
        left = (left.0.union(&bins[i].0), left.1 + bins[i].1);
        let right = suffix[i + 1];
        if left.1 > 0 && right.1 > 0 {
            let cost = area(&left.0) * left.1 as f32 + area(&right.0) * right.1 as f32;
            f(i, cost, left.0, right.0);
        }
    }
}

/// The cheapest spatial split of `refs` (box `bounds`) that adds at most `spare` references.
fn best_spatial<P: Triangles + ?Sized>(
    tris: &P,
    refs: &[Ref],
    bounds: &Bx,
    bins: usize,
    spare: usize,
    s: &mut Scratch,
) -> Option<Split> {
    let n = refs.len() as u32;
    let mut best: Option<Split> = None;
    // Per axis: origin, bin width, its inverse; `None` where the box is too thin to cut.
    let grid: [Option<(f32, f32, f32)>; 3] = core::array::from_fn(|axis| {
        let (lo, hi) = (bounds.min[axis], bounds.max[axis]);
        let width = (hi - lo) / bins as f32;
        (width > 0.0 && width.is_finite() && lo + width != lo).then(|| (lo, width, 1.0 / width))
    });
    if grid.iter().all(Option::is_none) {
        return None;
    }
    // All three axes in one pass (bins `axis * bins ..`), each triangle read at most once.
    s.sbins.clear();
    s.sbins.resize(3 * bins, (Bx::EMPTY, 0, 0));
    for r in refs {
        let mut tri: Option<[Vec3A; 3]> = None;
        for (axis, g) in grid.iter().enumerate() {
            let Some((lo, width, inv)) = *g else { continue };
            let bin_of = |x: f32| (((x - lo) * inv).max(0.0) as usize).min(bins - 1);
            let (first, last) = (bin_of(r.b.min[axis]), bin_of(r.b.max[axis]));
            let sb = &mut s.sbins[axis * bins..(axis + 1) * bins];
            sb[first].1 += 1;
            sb[last].2 += 1;
            if first == last {
                sb[first].0.grow_aabb(&r.b);
                continue;
            }
            if tri.is_none() {
                tri = tris.triangle(r.prim as usize).map(|t| t.map(Vec3A::from));
            }
            let Some(t) = tri else {
                // Not for a reference the build made; its whole box in every bin it spans.
                for b in &mut sb[first..=last] {
                    b.0.grow_aabb(&r.b);
                }
                continue;
            };
            let mut rest = r.b;
            for (k, b) in sb[first..last].iter_mut().enumerate() {
                let (l, rr) = clip(&t, &rest, axis, lo + (first + k + 1) as f32 * width);
                b.0.grow_aabb(&l);
                rest = rr;
            }
            sb[last].0.grow_aabb(&rest);
        }
    }
    for (axis, g) in grid.iter().enumerate() {
        let Some((lo, width, _)) = *g else { continue };
        let sb = &s.sbins[axis * bins..(axis + 1) * bins];
        // Left of plane k: references entering at or before bin k; right: leaving after it.
        s.rbox.clear();
        s.rbox.resize(bins, Bx::EMPTY);
        let mut acc = Bx::EMPTY;
        for k in (0..bins).rev() {
            acc = acc.union(&sb[k].0);
            s.rbox[k] = acc;
        }
        let (mut lb, mut nl, mut nr) = (Bx::EMPTY, 0u32, n);
        for (k, bin) in sb[..bins - 1].iter().enumerate() {
            lb = lb.union(&bin.0);
            nl += bin.1;
            nr -= bin.2;
            let rb = s.rbox[k + 1];
            if nl == 0 || nr == 0 || nl >= n && nr >= n || (nl + nr - n) as usize > spare {
                continue;
            }
            let cost = area(&lb) * nl as f32 + area(&rb) * nr as f32;
            if best.is_none_or(|b| matches!(b, Split::Spatial { cost: c, .. } if cost < c)) {
                best = Some(Split::Spatial {
                    axis,
                    pos: lo + (k + 1) as f32 * width,
                    cost,
                    left: lb,
                    right: rb,
                    nl,
                    nr,
                });
            }
        }
    }
    best
}

/// Puts `refs` into `s.left` and `s.right` by the plane `pos` on `axis`, clipping the straddling
/// ones unless one side can take them whole for less (reference unsplitting). `left` and `right`
/// are the binned estimate of the sides (box, count), which the unsplitting test prices against.
/// `false` if a side stays empty.
fn split_spatial<P: Triangles + ?Sized>(
    tris: &P,
    refs: &[Ref],
    axis: usize,
    pos: f32,
    (mut lb, mut nl): (Bx, u32),
    (mut rb, mut nr): (Bx, u32),
    s: &mut Scratch,
) -> bool {
    s.left.clear();
    s.right.clear();
    for r in refs {
        if r.b.max[axis] <= pos {
            s.left.push(*r);
        } else if r.b.min[axis] >= pos {
            s.right.push(*r);
        } else {
            let Some(t) = tris.triangle(r.prim as usize).map(|t| t.map(Vec3A::from)) else {
                s.left.push(*r);
                continue;
            };
            let (l, rr) = clip(&t, &r.b, axis, pos);
            match (l.is_empty(), rr.is_empty()) {
                (true, true) => s.left.push(*r),
                (false, true) => s.left.push(Ref { b: l, prim: r.prim }),
                (true, false) => s.right.push(Ref { b: rr, prim: r.prim }),
                (false, false) => {
                    let (nlf, nrf) = (nl as f32, nr as f32);
                    let split = area(&lb) * nlf + area(&rb) * nrf;
                    let to_left = area(&lb.union(&r.b)) * nlf + area(&rb) * (nrf - 1.0);
                    let to_right = area(&lb) * (nlf - 1.0) + area(&rb.union(&r.b)) * nrf;
                    if to_left < split && to_left <= to_right && nr > 1 {
                        s.left.push(*r);
                        lb = lb.union(&r.b);
                        nr -= 1;
                    } else if to_right < split && nl > 1 {
                        s.right.push(*r);
                        rb = rb.union(&r.b);
                        nl -= 1;
                    } else {
                        s.left.push(Ref { b: l, prim: r.prim });
                        s.right.push(Ref { b: rr, prim: r.prim });
                    }
                }
            }
        }
    }
    !s.left.is_empty() && !s.right.is_empty()
}

/// Orders `refs` so that the first half holds the smaller centroids on the longest centroid axis.
fn median(refs: &mut [Ref]) {
    let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for r in refs.iter() {
        let c = r.b.min + r.b.max;
        lo = lo.min(c);
        hi = hi.max(c);
    }
    let e = hi - lo;
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    let half = refs.len() / 2;
    if half > 0 {
        refs.select_nth_unstable_by(half, |a, b| {
            let (ca, cb) = (a.b.min[axis] + a.b.max[axis], b.b.min[axis] + b.b.max[axis]);
            ca.total_cmp(&cb)
        });
    }
}

/// The parallel spatial build ([`Bvh2::build_spatial_par`]).
#[cfg(feature = "std")]
mod par {
    use super::{BuildStats, Bvh2, Ctx, Job, Node, Ref, Scratch, Task};
    use crate::geometry::Triangles;
    use alloc::vec::Vec;
    use std::sync::Mutex;

    /// The smallest subtree handed to a worker whole.
    const GRAIN_MIN: usize = 2048;

    /// A job's result: its part of the tree (node 0 the job's node), its counters, and the jobs
    /// it left (slots in the part).
    type Part = (Bvh2, BuildStats, Vec<Job>);

    /// Builds the tree below `root` (node 0 of `out`) in rounds: each round splits every job
    /// above the grain (`n / (8 threads)` references, at least [`GRAIN_MIN`]) once, the jobs side
    /// by side; then each job's whole subtree, largest first. Every part is moved into `out` in
    /// job order, and the tree is then numbered as the sequential build numbers it.
    pub(super) fn run<P: Triangles + Sync + ?Sized>(
        cx: &Ctx<'_, P>,
        root: Task,
        buf: Vec<Ref>,
        threads: usize,
        out: &mut Bvh2,
        stats: &mut BuildStats,
    ) {
        let grain = ((root.end - root.begin) / (threads * 8)).max(GRAIN_MIN);
        let mut jobs: Vec<Job> = alloc::vec![(root, buf)];
        while jobs.iter().any(|j| j.1.len() > grain) {
            let (big, small): (Vec<Job>, Vec<Job>) = jobs.into_iter().partition(|j| j.1.len() > grain);
            // Split once: a task of `count` references defers its children (fewer each).
            let parts = map_par(big, threads, |(t, mut refs)| part(cx, t, &mut refs, true));
            jobs = small;
            for (slot, p) in parts {
                jobs.extend(join(out, stats, slot, p));
            }
        }
        jobs.sort_by_key(|j| core::cmp::Reverse(j.1.len()));
        for (slot, p) in map_par(jobs, threads, |(t, mut refs)| part(cx, t, &mut refs, false)) {
            join(out, stats, slot, p);
        }
        *out = sequential_order(out);
    }

    /// `b` numbered as the sequential build numbers it (children made as a pair when their parent
    /// is built; the right subtree built first; a leaf's slots taken when it is made), so that
    /// the trees are equal and numbering-dependent passes (reinsertion) agree.
    fn sequential_order(b: &Bvh2) -> Bvh2 {
        let mut out = Bvh2 {
            nodes: Vec::with_capacity(b.nodes.len()),
            prim_indices: Vec::with_capacity(b.prim_indices.len()),
        };
        out.nodes.push(b.nodes[0]);
        let mut todo = alloc::vec![(0u32, 0u32)];
        while let Some((old, new)) = todo.pop() {
            let n = &b.nodes[old as usize];
            if n.is_leaf() {
                let first = out.prim_indices.len() as u32;
                out.prim_indices.extend_from_slice(&b.prim_indices[n.prim_range()]);
                out.nodes[new as usize] = Node::leaf(&n.aabb(), first, n.count);
            } else {
                let l = out.nodes.len() as u32;
                out.nodes[new as usize] = Node::interior(&n.aabb(), l);
                out.nodes.push(b.nodes[n.left() as usize]);
                out.nodes.push(b.nodes[n.left() as usize + 1]);
                todo.push((n.left(), l));
                todo.push((n.left() + 1, l + 1));
            }
        }
        out
    }

    /// The part of the tree of job `t` over `refs`: its whole subtree, or with `once` its split
    /// (or leaf) and the children left as jobs.
    fn part<P: Triangles + ?Sized>(cx: &Ctx<'_, P>, t: Task, refs: &mut Vec<Ref>, once: bool) -> (u32, Part) {
        let mut sub = Bvh2::default();
        sub.nodes.push(Node::leaf(&t.bounds.to_aabb(), 0, 1));
        let local = Task {
            begin: 0,
            end: refs.len(),
            slot: 0,
            ..t
        };
        let (mut st, mut left) = (BuildStats::default(), Vec::new());
        let defer = once.then(|| (refs.len() - 1, &mut left));
        cx.run(
            alloc::vec![local],
            refs,
            &mut sub,
            &mut st,
            &mut Scratch::default(),
            defer,
        );
        (t.slot, (sub, st, left))
    }

    /// Moves `part` into `out` at node `slot`: its node `i >= 1` to `base + i - 1`, its leaves'
    /// slots after `out`'s; the jobs it left, with their slots moved the same way.
    fn join(out: &mut Bvh2, stats: &mut BuildStats, slot: u32, (sub, st, left): Part) -> Vec<Job> {
        let base = out.nodes.len() as u32;
        let first = out.prim_indices.len() as u32;
        let relocate = |n: &Node| {
            if n.is_leaf() {
                Node::leaf(&n.aabb(), n.index + first, n.count)
            } else {
                Node::interior(&n.aabb(), base + n.left() - 1)
            }
        };
        out.nodes[slot as usize] = relocate(&sub.nodes[0]);
        for n in &sub.nodes[1..] {
            out.nodes.push(relocate(n));
        }
        out.prim_indices.extend_from_slice(&sub.prim_indices);
        stats.leaves += st.leaves;
        stats.forced_splits += st.forced_splits;
        stats.max_depth = stats.max_depth.max(st.max_depth);
        left.into_iter()
            .map(|(t, refs)| {
                let slot = base + t.slot - 1;
                (Task { slot, ..t }, refs)
            })
            .collect()
    }

    /// `f` of every job on up to `threads` threads, the results in job order. A job no thread
    /// took (none could be started) runs on this one.
    fn map_par<J: Send, R: Send>(jobs: Vec<J>, threads: usize, f: impl Fn(J) -> R + Sync) -> Vec<R> {
        let slots: Vec<Mutex<Option<J>>> = jobs.into_iter().map(|j| Mutex::new(Some(j))).collect();
        let done: Vec<Mutex<Option<R>>> = slots.iter().map(|_| Mutex::new(None)).collect();
        let run = |i: usize| {
            if let Some(j) = slots[i].lock().ok().and_then(|mut g| g.take()) {
                let r = f(j);
                if let Ok(mut g) = done[i].lock() {
                    *g = Some(r);
                }
            }
        };
        crate::par::each_job((0..slots.len()).collect(), threads, run);
        (0..slots.len())
            .filter_map(|i| {
                run(i);
                done[i].lock().ok().and_then(|mut g| g.take())
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Triangle;
    use crate::scene::Rng;
    use glam::Vec3;

    /// Every point of a triangle (vertices, and barycentric points computed in f64 and rounded
    /// once) inside the reference's box lies in the box of each side it is on, over magnitudes
    /// from 1e-30 to 1e33, needles and sub-boxes; the boxes stay within the reference's and on
    /// their side of the plane.
    #[test]
    fn clip_is_conservative() {
        let mut r = Rng::new(11);
        let (mut checked, mut crossings) = (0, 0);
        for case in 0..4_000 {
            // Subnormal (1e-42: the `MIN_POSITIVE` term of the padding) to near `f32::MAX`.
            let scale = [1.0, 1e-30, 1e30, 3.0e5, 1e-42, 1e37][(r.u64() % 6) as usize];
            let far = if scale > 1e35 { 1.0 } else { 1e3 };
            let offset = Vec3::new(r.f32(), r.f32(), r.f32()) * scale * [0.0, 1.0, far][case % 3];
            let mut t: Triangle = [0, 1, 2].map(|_| offset + Vec3::new(r.f32(), r.f32(), r.f32()) * scale);
            if case % 7 == 0 {
                t[2] = t[0] + (t[1] - t[0]) * 1e-3; // a needle
            }
            let tb = Aabb::from_points(&t);
            // Within the triangle's box, or a random sub-box of it (a reference clipped before).
            let within = if case % 2 == 0 {
                tb
            } else {
                let a = tb.min + (tb.max - tb.min) * Vec3::new(r.f32(), r.f32(), r.f32()) * 0.5;
                let b = tb.max - (tb.max - tb.min) * Vec3::new(r.f32(), r.f32(), r.f32()) * 0.5;
                Aabb::new(a, b)
            };
            let axis = case % 3;
            let pos = tb.min[axis] + (tb.max[axis] - tb.min[axis]) * r.f32();
            let (l, rt) = clip(&t.map(Vec3A::from), &Bx::from_aabb(&within), axis, pos);
            let (l, rt) = (l.to_aabb(), rt.to_aabb());
            for side in [&l, &rt] {
                assert!(
                    side.is_empty() || within.contains(side),
                    "{case}: {side:?} outside {within:?}"
                );
            }
            assert!(l.is_empty() || l.max[axis] <= pos);
            assert!(rt.is_empty() || rt.min[axis] >= pos);
            // Where the edges cross the plane, in f64 and not rounded to f32 (so that a padding
            // short of the clipping's own rounding shows): in both boxes, if inside `within`.
            let holds = |b: &Aabb, x: &[f64; 3]| {
                (0..3).all(|a| a == axis || (b.min[a] as f64 <= x[a] && x[a] <= b.max[a] as f64))
            };
            for e in 0..3 {
                let (v0, v1) = (t[e], t[(e + 1) % 3]);
                let (p0, p1) = (v0[axis] as f64, v1[axis] as f64);
                if (p0 < pos as f64) == (p1 < pos as f64) || p0 == p1 {
                    continue;
                }
                let s = (pos as f64 - p0) / (p1 - p0);
                let x: [f64; 3] = core::array::from_fn(|a| v0[a] as f64 + (v1[a] as f64 - v0[a] as f64) * s);
                if holds(&within, &x) {
                    assert!(
                        holds(&l, &x) && holds(&rt, &x),
                        "{case}: crossing {x:?} not in {l:?} and {rt:?}"
                    );
                    crossings += 1;
                }
            }
            // Points of the triangle (barycentric in f64, rounded once) inside `within`.
            for k in 0..200 {
                let (mut u, mut v) = (r.f32() as f64, r.f32() as f64);
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                if k < 3 {
                    (u, v) = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)][k];
                }
                let exact: [f64; 3] = core::array::from_fn(|a| {
                    let (a0, a1, a2) = (t[0][a] as f64, t[1][a] as f64, t[2][a] as f64);
                    a0 + (a1 - a0) * u + (a2 - a0) * v
                });
                let p = Vec3::from_array(exact.map(|x| x as f32));
                if !within.contains_point(p) {
                    continue;
                }
                // The side by the exact point: rounding may move a point of a slanted triangle
                // onto the plane, far along the plane from where the triangle crosses it.
                let side = exact[axis];
                if side <= pos as f64 {
                    assert!(
                        l.contains_point(p),
                        "{case}: {p:?} (left of {pos} on {axis}) not in {l:?}, triangle {t:?}"
                    );
                }
                if side >= pos as f64 {
                    assert!(
                        rt.contains_point(p),
                        "{case}: {p:?} (right of {pos} on {axis}) not in {rt:?}, triangle {t:?}"
                    );
                }
                checked += 1;
            }
        }
        assert!(checked > 100_000 && crossings > 2_000, "{checked} {crossings}");
    }
}
