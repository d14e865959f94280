//! BVH2 -> BVH4/BVH8: the cost-optimal and the greedy collapse, and the cost-optimal one on
//! several threads ([`BvhWide::from_bvh2_par`], `std`).

#[cfg(feature = "std")]
use super::EMPTY_CHILD;
use super::{BvhWide, LEAF_BIT, MAX_LEAF_PACKS, MAX_WIDE_DEPTH, WideNode};
use crate::build::Bvh2;
use crate::geometry::{Aabb, Triangle, Triangles};
use crate::intersect::TriangleLanes;
use crate::math::Lane;
use alloc::vec;
use alloc::vec::Vec;

/// Why a wide BVH could not be made.
///
/// ```
/// use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh8, CollapseError}};
/// let tris = strahl::scene::icosphere(1).to_soup();
/// let (mut bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// bvh.prim_indices[0] = tris.len() as u32; // a primitive that does not exist
/// let err = Bvh8::from_bvh2(&bvh, &tris[..]).unwrap_err();
/// assert_eq!(err, CollapseError::Malformed);
/// assert!(err.to_string().contains("does not exist"));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CollapseError {
    /// A node or primitive index of the binary tree is out of range (run
    /// [`Bvh2::validate`](crate::build::Bvh2::validate) to see what broke).
    Malformed,
    /// The wide tree would be deeper than [`MAX_WIDE_DEPTH`].
    TooDeep,
    /// More triangle packs than leaf codes can address (2^27).
    TooLarge,
}

impl core::fmt::Display for CollapseError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Malformed => "the binary BVH refers to a node or primitive that does not exist",
            Self::TooDeep => "the wide BVH would be deeper than MAX_WIDE_DEPTH",
            Self::TooLarge => "too many triangle packs for the leaf encoding",
        })
    }
}

impl core::error::Error for CollapseError {}

/// Why a one-call wide build ([`BvhWide::build`]) failed: the binary build's error or the
/// collapse's.
///
/// ```
/// use strahl::{build::{BuildError, BuildParams}, layout::{Bvh8, WideBuildError}};
/// let tris = strahl::scene::icosphere(1).to_soup();
/// let mut bad = BuildParams::default();
/// bad.bins = 3; // out of range
/// let err = Bvh8::build(&tris[..], &bad).unwrap_err();
/// assert!(matches!(err, WideBuildError::Build(BuildError::InvalidParams(_))));
/// assert!(err.to_string().starts_with("building the binary BVH: invalid build parameters"));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WideBuildError {
    /// The binary build refused (too many primitives, parameters out of range).
    Build(crate::build::BuildError),
    /// The collapse refused (a wide tree deeper than [`MAX_WIDE_DEPTH`], too many packs).
    Collapse(CollapseError),
}

impl core::fmt::Display for WideBuildError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Build(e) => write!(f, "building the binary BVH: {e}"),
            Self::Collapse(e) => write!(f, "collapsing to the wide BVH: {e}"),
        }
    }
}

impl core::error::Error for WideBuildError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Build(e) => Some(e),
            Self::Collapse(e) => Some(e),
        }
    }
}

impl From<crate::build::BuildError> for WideBuildError {
    fn from(e: crate::build::BuildError) -> Self {
        Self::Build(e)
    }
}

impl From<CollapseError> for WideBuildError {
    fn from(e: CollapseError) -> Self {
        Self::Collapse(e)
    }
}

/// Memory for repeated collapses: the subtree counts and the cost-optimal collapse's table, kept
/// between calls, as [`build::Builder`](crate::build::Builder) keeps the binary builders'. With
/// [`collapse_into`](Self::collapse_into) the wide tree's own arrays are reused too, so an engine
/// that rebuilds every frame touches no new memory once the arrays have grown (a first collapse
/// faults in about 140 MB for a million triangles). Measured on the 1M soup's `balanced()` tree
/// (2026-12-06, Intel Xeon, best of 8, two runs): `from_bvh2` 181.8 ms, `collapse_into` 172.1-172.3;
/// `from_bvh2_par` on 2 threads 124.3-125.7, `collapse_into_par` 114.2-114.4. What is left is
/// the plan (about a quarter) and reading the triangles in leaf order.
///
/// ```
/// use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh8, Collapser}, scene, traverse::Moller};
/// let tris = scene::icosphere(3).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let mut collapser = Collapser::new();
/// let mut wide = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// // Next frame: the same tree shape as `from_bvh2`, in the same memory.
/// collapser.collapse_into(&b2, &tris[..], &mut wide).unwrap();
/// let fresh = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// assert_eq!((wide.nodes().len(), wide.packs().len()), (fresh.nodes().len(), fresh.packs().len()));
/// let ray = strahl::Ray::new(strahl::Vec3::splat(-2.0), strahl::Vec3::ONE);
/// assert_eq!(wide.intersect::<Moller>(&ray), fresh.intersect::<Moller>(&ray));
/// ```
#[derive(Clone, Debug, Default)]
pub struct Collapser {
    counts: Vec<u32>,
    plan: Plan,
}

impl Collapser {
    /// A collapser without memory yet (it grows on the first collapse and is kept).
    ///
    /// ```
    /// let mut c = strahl::layout::Collapser::new();
    /// # let _ = &mut c;
    /// ```
    pub fn new() -> Self {
        Self::default()
    }

    /// [`BvhWide::from_bvh2`] into `out` (its old contents replaced): the same tree, with this
    /// collapser's tables and `out`'s arrays reused where large enough. On an error `out` is left
    /// empty (its memory kept).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh4, Collapser}, scene};
    /// let tris = scene::thin_soup(5_000, 1);
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::fast()).unwrap();
    /// let mut wide = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
    /// let mut broken = b2.clone();
    /// broken.prim_indices[0] = u32::MAX; // no such triangle
    /// let mut c = Collapser::new();
    /// assert!(c.collapse_into(&broken, &tris[..], &mut wide).is_err());
    /// assert!(wide.nodes().is_empty()); // left empty
    /// c.collapse_into(&b2, &tris[..], &mut wide).unwrap();
    /// assert_eq!(wide.nodes().len(), Bvh4::from_bvh2(&b2, &tris[..]).unwrap().nodes().len());
    /// ```
    pub fn collapse_into<L: Lane, const N: usize, P: Triangles + ?Sized>(
        &mut self,
        bvh: &Bvh2,
        tris: &P,
        out: &mut BvhWide<L, N>,
    ) -> Result<(), CollapseError> {
        let () = BvhWide::<L, N>::LANES_MATCH;
        let made = counts_and_plan(bvh, &mut self.counts, &mut self.plan, N, false, 1);
        if let Err(e) = made {
            out.clear();
            return Err(e);
        }
        BvhWide::collapse_with(bvh, tris, &self.counts, &self.plan, out)
    }

    /// [`BvhWide::from_bvh2_par`] into `out`, reusing memory as
    /// [`collapse_into`](Self::collapse_into) does (`std`).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh8, Collapser}, scene};
    /// let tris = scene::thin_soup(20_000, 2);
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::fast()).unwrap();
    /// let mut c = Collapser::new();
    /// let mut wide = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// c.collapse_into_par(&b2, &tris[..], &mut wide, 2).unwrap();
    /// let par = Bvh8::from_bvh2_par(&b2, &tris[..], 2).unwrap();
    /// assert_eq!(wide.nodes().len(), par.nodes().len());
    /// ```
    #[cfg(feature = "std")]
    pub fn collapse_into_par<L: Lane + Send + Sync, const N: usize, P: Triangles + Sync + ?Sized>(
        &mut self,
        bvh: &Bvh2,
        tris: &P,
        out: &mut BvhWide<L, N>,
        threads: usize,
    ) -> Result<(), CollapseError> {
        BvhWide::collapse_par_into(bvh, tris, threads, self, out)
    }
}

/// A wide node still to fill: binary node, wide node slot, depth.
type Job = (u32, usize, u32);

struct Builder<'a, L, const N: usize, P: ?Sized> {
    bvh: &'a Bvh2,
    tris: &'a P,
    /// Primitives below each binary node.
    counts: &'a [u32],
    /// The cost-optimal collapse's table (empty: the greedy collapse).
    plan: &'a Plan,
    /// Some triangle is referenced twice (spatial splits): a subtree packed whole may meet it
    /// twice, and its packs are counted after [`subtree_prims`](Self::subtree_prims) drops the
    /// repeats.
    repeats: bool,
    nodes: Vec<WideNode<L, N>>,
    packs: Vec<TriangleLanes<L, N>>,
    /// Where the packs go instead of `packs` (the parallel collapse: a worker's part of the
    /// output array), and how many are written there.
    #[cfg(feature = "std")]
    sink: Option<&'a mut [core::mem::MaybeUninit<TriangleLanes<L, N>>]>,
    #[cfg(feature = "std")]
    sunk: usize,
    depth: u32,
}

/// Empties `v` and makes room for `n` elements: in its own memory where that is large enough
/// (a collapse into arrays kept from the last one: no new pages), else in a new allocation,
/// advised for huge pages where large (`std`; see `layout::pages`).
fn reserve_advised<T>(v: &mut Vec<T>, n: usize) {
    v.clear();
    if v.capacity() >= n {
        return;
    }
    #[cfg(feature = "std")]
    {
        *v = super::pages::advised_with_capacity(n);
    }
    #[cfg(not(feature = "std"))]
    v.reserve_exact(n);
}

/// `true` if some triangle is referenced twice by `bvh`'s leaves (spatial splits). Exact:
/// invalid triangles can keep the count of references low.
fn has_repeats<P: Triangles + ?Sized>(bvh: &Bvh2, tris: &P) -> bool {
    let mut seen = vec![0u64; tris.len().div_ceil(64)];
    bvh.prim_indices.iter().any(|&p| {
        let (w, b) = (p as usize / 64, 1u64 << (p % 64));
        seen.get_mut(w).is_some_and(|x| core::mem::replace(x, *x | b) & b != 0)
    })
}

fn half_area(b: &Aabb) -> f32 {
    if b.is_empty() { -1.0 } else { b.half_area() }
}

impl<'a, L: Lane, const N: usize, P: Triangles + ?Sized> Builder<'a, L, N, P> {
    /// A builder with empty output arrays; `repeats`: [`has_repeats`] of the tree.
    fn new(bvh: &'a Bvh2, tris: &'a P, counts: &'a [u32], plan: &'a Plan, repeats: bool) -> Self {
        Self {
            bvh,
            tris,
            counts,
            plan,
            repeats,
            nodes: Vec::new(),
            packs: Vec::new(),
            #[cfg(feature = "std")]
            sink: None,
            #[cfg(feature = "std")]
            sunk: 0,
            depth: 0,
        }
    }

    /// Packs made so far.
    #[inline]
    fn pack_count(&self) -> usize {
        #[cfg(feature = "std")]
        if self.sink.is_some() {
            return self.sunk;
        }
        self.packs.len()
    }

    /// Appends a pack (to the sink, if one was given: a full sink is an error, never reached
    /// where it was sized by [`sizes`](Self::sizes)).
    #[inline]
    fn push_pack(&mut self, pack: TriangleLanes<L, N>) -> Result<(), CollapseError> {
        #[cfg(feature = "std")]
        if let Some(sink) = self.sink.as_mut() {
            sink.get_mut(self.sunk).ok_or(CollapseError::TooLarge)?.write(pack);
            self.sunk += 1;
            return Ok(());
        }
        self.packs.push(pack);
        Ok(())
    }

    /// Packs the primitives `prims` into leaf codes; more than `MAX_LEAF_PACKS * N` go below a
    /// node of their own. Returns the child code and its box.
    fn leaf(&mut self, prims: &[u32], depth: u32) -> Result<(u32, Aabb), CollapseError> {
        if prims.len() > MAX_LEAF_PACKS * N {
            // Split the run into up to N children of a node of its own.
            let at = self.new_node(depth)?;
            let per = prims.len().div_ceil(N);
            let mut node = WideNode::<L, N>::empty();
            let mut bounds = Aabb::EMPTY;
            let mut lo = [[f32::INFINITY; 8]; 3];
            let mut hi = [[f32::NEG_INFINITY; 8]; 3];
            for (i, chunk) in prims.chunks(per).enumerate() {
                let (code, b) = self.leaf(chunk, depth + 1)?;
                node.child[i] = code;
                bounds = bounds.union(&b);
                for a in 0..3 {
                    lo[a][i] = b.min[a];
                    hi[a][i] = b.max[a];
                }
            }
            node.bounds.min = lo.map(|v| L::load(&v));
            node.bounds.max = hi.map(|v| L::load(&v));
            self.nodes[at] = node;
            return Ok((at as u32, bounds));
        }
        let first = self.pack_count();
        if first + prims.len().div_ceil(N) >= 1 << 27 {
            return Err(CollapseError::TooLarge);
        }
        // Pack by pack from a local array: no allocation per leaf. (The collapse of the 1M
        // sphereflake took as long as with a vector per leaf, within the noise: its time goes to
        // fetching the triangles in leaf order, the cost-optimal plan and page faults.)
        let mut bounds = Aabb::EMPTY;
        let mut tris: [Triangle; 8] = [[crate::Vec3::ZERO; 3]; 8];
        for chunk in prims.chunks(N) {
            let mut kept = 0u32;
            for (i, (t, &p)) in tris.iter_mut().zip(chunk).enumerate() {
                *t = self.tris.triangle(p as usize).ok_or(CollapseError::Malformed)?;
                // The builders' rule (as `refit`'s): non-finite triangles, and those beyond the
                // range a box can hold, are in no box and never hit.
                if super::refit::kept(t) {
                    kept |= 1 << i;
                    for v in t.iter() {
                        bounds.grow(*v);
                    }
                }
            }
            let mut pack = TriangleLanes::pack(&tris[..chunk.len()], chunk);
            pack.valid &= kept;
            self.push_pack(pack)?;
        }
        let count = self.pack_count() - first;
        Ok((LEAF_BIT | (first as u32) << 4 | (count as u32 - 1), bounds))
    }

    fn new_node(&mut self, depth: u32) -> Result<usize, CollapseError> {
        if depth > MAX_WIDE_DEPTH {
            return Err(CollapseError::TooDeep);
        }
        self.depth = self.depth.max(depth);
        self.nodes.push(WideNode::empty());
        Ok(self.nodes.len() - 1)
    }

    fn bnode(&self, i: u32) -> Result<&crate::traverse::Node, CollapseError> {
        self.bvh.nodes.get(i as usize).ok_or(CollapseError::Malformed)
    }

    /// The primitives below binary node `b`, in leaf order.
    fn subtree_prims(&self, b: u32) -> Result<Vec<u32>, CollapseError> {
        let (mut out, mut todo) = (Vec::new(), Vec::new());
        self.subtree_prims_into(b, &mut out, &mut todo)?;
        Ok(out)
    }

    /// [`subtree_prims`](Self::subtree_prims) into `out` (emptied first), with `todo` as the
    /// walk's stack: no allocation once both have grown.
    // PERF: with two new vectors per subtree packed whole, the collapse of the 1M soup's
    // `balanced()` tree took 204.8-207.8 ms, with these reused 188.2-202.6 (best of 12, three
    // times taking turns, 2026-12-06, Intel Xeon).
    fn subtree_prims_into(&self, b: u32, out: &mut Vec<u32>, todo: &mut Vec<u32>) -> Result<(), CollapseError> {
        out.clear();
        todo.clear();
        todo.push(b);
        let mut budget = self.bvh.nodes.len();
        while let Some(i) = todo.pop() {
            budget = budget.checked_sub(1).ok_or(CollapseError::Malformed)?;
            let n = self.bnode(i)?;
            if n.is_leaf() {
                out.extend_from_slice(
                    self.bvh
                        .prim_indices
                        .get(n.prim_range())
                        .ok_or(CollapseError::Malformed)?,
                );
            } else {
                todo.push(n.right());
                todo.push(n.left());
            }
        }
        // A tree with spatial splits (`Bvh2::build_spatial`) may reference one triangle from
        // several of these leaves: one pack holds it once, so that a hit filter is asked once per
        // triangle and leaf.
        if self.repeats {
            // First occurrences, order kept, in O(k log k) (a subtree may be large).
            let mut by: Vec<(u32, usize)> = out.iter().copied().zip(0..).collect();
            by.sort_unstable();
            by.dedup_by_key(|x| x.0);
            by.sort_unstable_by_key(|x| x.1);
            out.clear();
            out.extend(by.into_iter().map(|x| x.0));
        }
        Ok(())
    }

    /// The children of the wide node made of binary node `b`, by decreasing surface area.
    fn kids(&self, b: u32) -> Result<Vec<u32>, CollapseError> {
        // Open the child with the largest surface area until there are N.
        let node = *self.bnode(b)?;
        let mut kids: Vec<u32> = if node.is_leaf() {
            vec![b]
        } else if !self.plan.dist.is_empty() {
            let mut kids = Vec::with_capacity(N);
            self.plan.open(self.bvh, b, N, &mut kids)?;
            kids
        } else {
            vec![node.left(), node.right()]
        };
        while self.plan.dist.is_empty() && kids.len() < N {
            let mut best = None;
            for (i, &k) in kids.iter().enumerate() {
                let n = self.bnode(k)?;
                if !n.is_leaf() && self.count(k) > N {
                    let a = half_area(&n.aabb());
                    if best.is_none_or(|(_, ba)| a > ba) {
                        best = Some((i, a));
                    }
                }
            }
            let Some((i, _)) = best else { break };
            let n = *self.bnode(kids[i])?;
            kids[i] = n.left();
            kids.insert(i + 1, n.right());
        }
        // Children by decreasing surface area (stable): the any-hit traversal visits them in
        // slot order, so the likeliest occluders come first.
        // PERF: shadow rays to random points (BVH8, 262k rays, best of 6-8 taking turns, Intel
        // Xeon): 1M sphereflake 153 -> 130 ms, bunny 48.4 -> 49.5 ms; closest hits alike.
        let mut keyed = Vec::with_capacity(kids.len());
        for &k in &kids {
            keyed.push((half_area(&self.bnode(k)?.aabb()), k));
        }
        keyed.sort_by(|a, b| b.0.total_cmp(&a.0));
        Ok(keyed.into_iter().map(|(_, k)| k).collect())
    }

    /// How many wide nodes and packs [`run_from`](Self::run_from) makes from binary node `b`
    /// (its wide node included), walking the same choices without making them. Used to size the
    /// output arrays once: growing them by doubling, then copying them onto huge pages, took
    /// about a fifth of the collapse of the 1M soup (fresh pages evict the triangles it gathers).
    fn sizes(&self, b: u32) -> Result<(usize, usize), CollapseError> {
        let (mut nodes, mut packs) = (1usize, 0usize);
        let mut todo = vec![b];
        let mut budget = self.bvh.nodes.len();
        while let Some(b) = todo.pop() {
            budget = budget.checked_sub(1).ok_or(CollapseError::Malformed)?;
            for k in self.kids(b)? {
                let n = self.bnode(k)?;
                let leaf = if n.is_leaf() {
                    let prims = self.bvh.prim_indices.get(n.prim_range());
                    Some(prims.ok_or(CollapseError::Malformed)?.len())
                } else if self.plan.as_leaf(k, self.count(k), N) {
                    // More than the tree holds: a malformed tree (left to `run` to report).
                    if self.count(k) > self.bvh.prim_indices.len() {
                        return Err(CollapseError::Malformed);
                    }
                    Some(if self.repeats {
                        self.subtree_prims(k)?.len()
                    } else {
                        self.count(k)
                    })
                } else {
                    None
                };
                match leaf {
                    Some(len) => {
                        let (ln, lp) = leaf_sizes(len, N);
                        nodes += ln;
                        packs += lp;
                    }
                    None => {
                        nodes += 1;
                        todo.push(k);
                    }
                }
            }
        }
        Ok((nodes, packs))
    }

    /// Output arrays with room for the wide tree made from binary node `b`
    /// ([`sizes`](Self::sizes)), advised for huge pages where large (see `layout::pages`).
    /// Where `sizes` fails (a malformed tree) or gives more packs than leaf codes address, the
    /// arrays are left as they are: [`run_from`](Self::run_from) then meets and reports the
    /// error itself, as without this step.
    fn presize(&mut self, b: u32) {
        let Ok((nodes, packs)) = self.sizes(b) else { return };
        if packs >= 1 << 27 {
            return;
        }
        reserve_advised(&mut self.nodes, nodes);
        reserve_advised(&mut self.packs, packs);
    }

    /// [`Triangles::prefetch`] for the triangles below binary node `b` if it becomes one leaf
    /// (a binary leaf, or a subtree the plan packs whole); the latter walked with a small fixed
    /// stack, stopping early where it is deeper than that.
    #[inline]
    fn prefetch_triangles(&self, b: u32) {
        let count = self.count(b);
        let Ok(n) = self.bnode(b) else { return };
        if !n.is_leaf() && !self.plan.as_leaf(b, count, N) {
            return;
        }
        let mut stack = [0u32; 16];
        let (mut top, mut node) = (0usize, *n);
        loop {
            if node.is_leaf() {
                for &p in self.bvh.prim_indices.get(node.prim_range()).unwrap_or(&[]) {
                    self.tris.prefetch(p as usize);
                }
            } else if top + 1 < stack.len() {
                stack[top] = node.right();
                stack[top + 1] = node.left();
                top += 2;
            }
            let Some(next) = top.checked_sub(1) else { return };
            top = next;
            let Ok(nd) = self.bnode(stack[top]) else { return };
            node = *nd;
        }
    }

    fn count(&self, b: u32) -> usize {
        self.counts.get(b as usize).map_or(usize::MAX, |&c| c as usize)
    }

    /// Fills wide node `at` from binary interior node `b`, then its interior children (explicit
    /// stack: no recursion on the tree depth).
    fn run(&mut self, root: u32) -> Result<(), CollapseError> {
        let at = self.new_node(1)?;
        self.run_from(root, at, 1, None)
    }

    /// [`run`](Self::run) from binary node `b` into the (new) wide node `at` at `depth`; with
    /// `defer = Some((jobs, grain))`, a wide node to be made of a binary node with at most
    /// `grain` primitives below is left empty and pushed to `jobs` (the parallel collapse).
    fn run_from(
        &mut self,
        b: u32,
        at: usize,
        depth: u32,
        mut defer: Option<(&mut Vec<Job>, usize)>,
    ) -> Result<(), CollapseError> {
        let mut todo = vec![(b, at, depth)];
        // A subtree packed whole: its primitives, and the walk that finds them.
        let (mut prims, mut walk) = (Vec::new(), Vec::new());
        while let Some((b, at, depth)) = todo.pop() {
            if let Some((jobs, grain)) = defer.as_mut()
                && self.count(b) <= *grain
            {
                jobs.push((b, at, depth));
                continue;
            }
            let kids = self.kids(b)?;
            // PERF: the leaves' triangles are read in leaf order, at random in the input: asked
            // for ahead, while the leaves before them are packed (1M soup: about a third of the
            // collapse went to these misses; with the triangles in leaf order it took 190
            // against 306 ms).
            for &k in &kids {
                self.prefetch_triangles(k);
            }
            let mut wide = WideNode::<L, N>::empty();
            let mut lo = [[f32::INFINITY; 8]; 3];
            let mut hi = [[f32::NEG_INFINITY; 8]; 3];
            for (i, &k) in kids.iter().enumerate() {
                let n = *self.bnode(k)?;
                let (code, bounds) = if n.is_leaf() {
                    let prims = self
                        .bvh
                        .prim_indices
                        .get(n.prim_range())
                        .ok_or(CollapseError::Malformed)?;
                    let (code, _) = self.leaf(prims, depth + 1)?;
                    (code, n.aabb())
                } else if self.plan.as_leaf(k, self.count(k), N) {
                    // A small subtree becomes one full pack: one x8 test instead of more nodes
                    // (greedy: every subtree of at most N primitives; optimal: where cheaper).
                    self.subtree_prims_into(k, &mut prims, &mut walk)?;
                    let (code, _) = self.leaf(&prims, depth + 1)?;
                    (code, n.aabb())
                } else {
                    let child = self.new_node(depth + 1)?;
                    todo.push((k, child, depth + 1));
                    (child as u32, n.aabb())
                };
                wide.child[i] = code;
                for a in 0..3 {
                    lo[a][i] = bounds.min[a];
                    hi[a][i] = bounds.max[a];
                }
            }
            wide.bounds.min = lo.map(|v| L::load(&v));
            wide.bounds.max = hi.map(|v| L::load(&v));
            self.nodes[at] = wide;
        }
        Ok(())
    }
}

/// Relative costs of the cost-optimal collapse, per unit of surface area of the box entered:
/// visiting a wide node (one N-wide box test, ordering its hits, stack traffic, and the cache
/// miss of fetching it) and testing one pack of N triangles (one N-wide triangle test).
// NOTE: chosen with a best-of-6 trace harness (BVH8, Möller-Trumbore; bunny and the 262k
// sphereflake; primary, diffuse and any-hit diffuse rays): pack costs 0.25 to 0.7 all traced
// 3 to 10% faster than the greedy collapse and within the noise of each other; 1 to 3 gave
// slower traces, closer to the greedy one. Leaves of up to 2, 3 or 4 packs: no difference
// measured, so 2 (fewer lanes wasted on partly filled packs).
pub(crate) const NODE_COST: f32 = 1.0;
/// See [`NODE_COST`].
pub(crate) const PACK_COST: f32 = 0.4;
/// Largest subtree (in packs) that the cost-optimal collapse may turn into one leaf.
const PLAN_LEAF_PACKS: usize = 2;

/// The cost-optimal collapse (Ylitie, Karras and Laine, "Efficient Incoherent Ray Traversal on
/// GPUs Through Compressed Wide BVHs", 2017): for every binary node `n` and `i = 1 ..= N`,
/// `dist[n][i - 1]`, the least SAH cost of covering `n`'s subtree with at most `i` children of
/// one wide node, each child a leaf (its primitives in packs) or a wide node of its own. Bottom
/// up: `dist(n, 1) = min(leaf(n), A(n) NODE_COST + best(n, N))` and
/// `dist(n, i) = min(dist(n, i - 1), best(n, i))`, with
/// `best(n, i) = min_k dist(left, k) + dist(right, i - k)` and
/// `leaf(n) = A(n) PACK_COST ceil(P(n) / N)`.
#[derive(Clone, Debug, Default)]
struct Plan {
    dist: Vec<[f32; 8]>,
    /// `dist(n, 1)` is a leaf.
    leaf: Vec<bool>,
}

impl Plan {
    /// The reference the fused passes ([`counts_and_plan`]) are tested against: the walk with a
    /// stack.
    #[cfg(test)]
    fn new(bvh: &Bvh2, counts: &[u32], n_wide: usize) -> Result<Self, CollapseError> {
        let mut plan = Plan::default();
        plan.fill(bvh, counts, n_wide)?;
        Ok(plan)
    }

    /// [`Plan::new`] into this plan's tables (kept between calls: no allocation, no page faults
    /// where they are large enough already).
    #[cfg(test)]
    fn fill(&mut self, bvh: &Bvh2, counts: &[u32], n_wide: usize) -> Result<(), CollapseError> {
        let n = bvh.nodes.len();
        self.reset(n);
        if n == 0 {
            return Ok(());
        }
        self.fill_with_stack(bvh, counts, n_wide)
    }

    /// Tables for `n` nodes, their values to be written.
    fn reset(&mut self, n: usize) {
        // PERF: 32 bytes a node (64 MB for the 1M soup's tree), written once: on huge pages where
        // the kernel allows (`hugepages`), first-touch page faults took about 25 ms of the plan.
        reserve_advised(&mut self.dist, n);
        self.dist.resize(n, [0.0; 8]);
        self.leaf.clear();
        self.leaf.resize(n, false);
    }

    /// [`Plan::new`]'s table by a post-order walk from the root with a stack (any node order;
    /// malformed trees are errors).
    fn fill_with_stack(&mut self, bvh: &Bvh2, counts: &[u32], n_wide: usize) -> Result<(), CollapseError> {
        let (n, plan) = (bvh.nodes.len(), self);
        let mut todo = vec![(0u32, false)];
        let mut budget = 2 * n + 1;
        while let Some((i, done)) = todo.pop() {
            budget = budget.checked_sub(1).ok_or(CollapseError::Malformed)?;
            let node = bvh.nodes.get(i as usize).ok_or(CollapseError::Malformed)?;
            let area = half_area(&node.aabb()).max(0.0);
            let prims = counts.get(i as usize).copied().unwrap_or(0) as usize;
            let packs = prims.div_ceil(n_wide) as f32;
            if node.is_leaf() {
                plan.dist[i as usize] = [area * PACK_COST * packs; 8];
                plan.leaf[i as usize] = true;
            } else if done {
                let (l, r) = (node.left() as usize, node.right() as usize);
                let (dl, dr) = match (plan.dist.get(l), plan.dist.get(r)) {
                    (Some(a), Some(b)) => (*a, *b),
                    _ => return Err(CollapseError::Malformed),
                };
                let internal = area * NODE_COST + best(&dl, &dr, n_wide).0;
                let leaf = if prims <= PLAN_LEAF_PACKS * n_wide {
                    area * PACK_COST * packs
                } else {
                    f32::INFINITY
                };
                let d = &mut plan.dist[i as usize];
                d[0] = leaf.min(internal);
                for k in 2..=n_wide {
                    d[k - 1] = d[k - 2].min(best(&dl, &dr, k).0);
                }
                plan.leaf[i as usize] = leaf <= internal;
            } else {
                todo.push((i, true));
                todo.push((node.right(), false));
                todo.push((node.left(), false));
            }
        }
        Ok(())
    }

    /// `true` if binary node `k` (interior, `count` primitives) becomes one leaf.
    fn as_leaf(&self, k: u32, count: usize, n_wide: usize) -> bool {
        match self.leaf.get(k as usize) {
            Some(&leaf) if !self.dist.is_empty() => leaf,
            _ => count <= n_wide,
        }
    }

    /// The children of the wide node made of binary interior node `b`: the cheapest cover of its
    /// two subtrees by `slots` nodes, appended to `kids`.
    fn open(&self, bvh: &Bvh2, b: u32, slots: usize, kids: &mut Vec<u32>) -> Result<(), CollapseError> {
        let node = bvh.nodes.get(b as usize).ok_or(CollapseError::Malformed)?;
        let (l, r) = (node.left(), node.right());
        let (dl, dr) = match (self.dist.get(l as usize), self.dist.get(r as usize)) {
            (Some(a), Some(b)) => (a, b),
            _ => return Err(CollapseError::Malformed),
        };
        let (_, k) = best(dl, dr, slots);
        self.cover(bvh, l, k, kids)?;
        self.cover(bvh, r, slots - k, kids)
    }

    /// The cheapest cover of binary node `n`'s subtree by at most `slots` wide children.
    fn cover(&self, bvh: &Bvh2, n: u32, slots: usize, kids: &mut Vec<u32>) -> Result<(), CollapseError> {
        let node = bvh.nodes.get(n as usize).ok_or(CollapseError::Malformed)?;
        let d = self.dist.get(n as usize).ok_or(CollapseError::Malformed)?;
        // Fewer slots as good (`dist` does not fall from `slots - 1` to `slots`), or no choice.
        let mut s = slots;
        while s > 1 && d[s - 1] >= d[s - 2] {
            s -= 1;
        }
        if s == 1 || node.is_leaf() {
            kids.push(n);
            return Ok(());
        }
        self.open(bvh, n, s, kids)
    }
}

/// A bit per node: which nodes some node has claimed as a child (a node claimed twice: not a
/// tree).
struct Claims(Vec<u64>);

impl Claims {
    fn new(n: usize) -> Self {
        Self(alloc::vec![0u64; n.div_ceil(64)])
    }

    /// Claims node `c` (`c` below the `n` of [`new`](Self::new)): `false` if it was already.
    #[inline(always)]
    fn claim(&mut self, c: usize) -> bool {
        let (w, b) = (c / 64, 1u64 << (c % 64));
        let fresh = self.0[w] & b == 0;
        self.0[w] |= b;
        fresh
    }
}

/// The subtree counts and the cost-optimal collapse's table together ([`subtree_counts_into`] and
/// [`Plan::fill`], the same numbers): in one pass from the last node to the first where the tree
/// allows ([`fused_range`]), with the nodes cut into ranges done side by side on `threads` threads
/// (`std`, [`fused_par`]); else the two walks with a stack, which report malformed trees. `plan`
/// left empty where `greedy`.
fn counts_and_plan(
    bvh: &Bvh2,
    counts: &mut Vec<u32>,
    plan: &mut Plan,
    n_wide: usize,
    greedy: bool,
    threads: usize,
) -> Result<(), CollapseError> {
    if greedy {
        plan.dist.clear();
        plan.leaf.clear();
        return subtree_counts_into(bvh, counts);
    }
    let n = bvh.nodes.len();
    counts.clear();
    counts.resize(n, 0);
    plan.reset(n);
    if n == 0 {
        return Ok(());
    }
    #[cfg(feature = "std")]
    if threads > 1 && n >= PAR_PLAN_NODES && fused_par(&bvh.nodes, counts, plan, n_wide, threads) {
        return Ok(());
    }
    let _ = threads;
    if fused_range(&bvh.nodes, 0, counts, &mut plan.dist, &mut plan.leaf, n_wide, None) {
        return Ok(());
    }
    counts.fill(0);
    counts_with_stack(bvh, counts)?;
    plan.fill_with_stack(bvh, counts, n_wide)
}

/// Trees of fewer nodes make their plan on one thread.
#[cfg(feature = "std")]
const PAR_PLAN_NODES: usize = 1 << 16;

/// The plan is made on at most this many threads.
#[cfg(feature = "std")]
const PLAN_THREADS: usize = 16;

/// The count and plan entry of a node with `prims` primitives below it, from its children's plan
/// entries (`None`: a leaf): what [`Plan::fill`]'s passes compute for it.
#[inline(always)]
fn plan_entry(
    node: &crate::traverse::Node,
    prims: usize,
    kids: Option<(&[f32; 8], &[f32; 8])>,
    n_wide: usize,
) -> ([f32; 8], bool) {
    let area = half_area(&node.aabb()).max(0.0);
    let packs = prims.div_ceil(n_wide) as f32;
    let Some((dl, dr)) = kids else {
        return ([area * PACK_COST * packs; 8], true);
    };
    let all = best_all(dl, dr);
    let internal = area * NODE_COST + all[(n_wide - 1) & 7];
    let leaf = if prims <= PLAN_LEAF_PACKS * n_wide {
        area * PACK_COST * packs
    } else {
        f32::INFINITY
    };
    let mut d = [0.0f32; 8];
    d[0] = leaf.min(internal);
    for k in 2..=n_wide.min(8) {
        d[k - 1] = d[k - 2].min(all[k - 1]);
    }
    (d, leaf <= internal)
}

/// Counts and plan entries of the nodes `base .. base + counts.len()` (the slices hold theirs) in
/// one pass from the last to the first, where every interior node among them has its two
/// children among them, after it, and no node is the child of two: `false` where that does not
/// hold (then the slices hold garbage).
// PERF: the counts' pass and the plan's took 12.4 and 38 ms on the 1M soup's tree (2M nodes);
// one pass reads the nodes once. (The walk with a stack, which any node order takes, about 40 ns
// a node.)
fn fused_range(
    nodes: &[crate::traverse::Node],
    base: usize,
    counts: &mut [u32],
    dist: &mut [[f32; 8]],
    leaf: &mut [bool],
    n_wide: usize,
    roots: Option<[usize; 2]>,
) -> bool {
    let len = counts.len().min(dist.len()).min(leaf.len());
    let end = base + len;
    if end > nodes.len() {
        return false;
    }
    let mut seen = Claims::new(len);
    let mut claim = |c: usize| seen.claim(c - base);
    for i in (base..end).rev() {
        let node = &nodes[i];
        let k = i - base;
        if node.is_leaf() {
            counts[k] = node.count;
            (dist[k], leaf[k]) = plan_entry(node, node.count as usize, None, n_wide);
            continue;
        }
        let (l, r) = (node.left() as usize, node.right() as usize);
        if l <= i || r <= i || l >= end || r >= end || l == r || !claim(l) || !claim(r) {
            return false;
        }
        counts[k] = counts[l - base].saturating_add(counts[r - base]);
        let kids = (&dist[l - base], &dist[r - base]);
        (dist[k], leaf[k]) = plan_entry(node, counts[k] as usize, Some(kids), n_wide);
    }
    // The subtree roots, whose parent is outside: nobody inside claimed them.
    roots.is_none_or(|r| r.iter().all(|&x| x >= base && x < end && claim(x)))
}

/// [`fused_range`] on `threads` threads: the subtrees of the interior nodes some levels below the
/// root (about 8 per thread), whose nodes the top-down builders lay out as one run each (every
/// node's children after it, a subtree's nodes after its root's pair), each done as a range side
/// by side; then the nodes outside the ranges, from the last to the first. The checks are
/// [`fused_range`]'s over the whole array (children after their parent, no node the child of
/// two; a node outside a range may have children inside one only as the subtree root it is), so
/// this succeeds only where the one-thread pass would, with the same numbers. `false` where the
/// tree does not fall into such ranges (then the arrays hold garbage and the caller makes them
/// again).
#[cfg(feature = "std")]
fn fused_par(
    nodes: &[crate::traverse::Node],
    counts: &mut [u32],
    plan: &mut Plan,
    n_wide: usize,
    threads: usize,
) -> bool {
    let n = nodes.len();
    if counts.len() != n || plan.dist.len() != n || plan.leaf.len() != n {
        return false;
    }
    // The pass waits on memory: more threads than this only add their start-up (256 threads on
    // this 2-core machine: 3x slower than one).
    let threads = threads.min(PLAN_THREADS);
    // NOTE: deep enough that the parallel builders' trees fall into ranges too: their nodes above
    // the tasks of the last round (about `8 threads` of them) are not laid out subtree by subtree.
    let want = threads.saturating_mul(64);
    // The subtree roots: interior nodes of the first level with enough of them.
    let mut level = alloc::vec![0usize];
    for _ in 0..24 {
        if level.len() >= want {
            break;
        }
        let mut next = Vec::with_capacity(2 * level.len());
        for &c in &level {
            let Some(node) = nodes.get(c) else { return false };
            if !node.is_leaf() {
                next.extend([node.left() as usize, node.right() as usize]);
            }
        }
        if next.is_empty() {
            break;
        }
        level = next;
    }
    // A node twice in the level: not a tree (the one-thread pass decides).
    level.sort_unstable();
    if level.windows(2).any(|w| w[0] == w[1]) {
        return false;
    }
    // Each root's run: from its first child to the last node of its subtree (where the last pair
    // made is: down the right child where it is interior, else the left). `(lo, end, root)`. The
    // walks share one budget of `n` steps (disjoint subtrees of a tree take fewer in all).
    let mut ranges = Vec::with_capacity(level.len());
    let mut steps = n;
    for &c in &level {
        let Some(node) = nodes.get(c).filter(|nd| !nd.is_leaf()) else {
            continue;
        };
        let (l, r) = (node.left() as usize, node.right() as usize);
        let mut x = c;
        let end = loop {
            steps = match steps.checked_sub(1) {
                Some(s) => s,
                None => return false,
            };
            let Some(nd) = nodes.get(x) else { return false };
            let (a, b) = (nd.left() as usize, nd.right() as usize);
            let (Some(na), Some(nb)) = (nodes.get(a), nodes.get(b)) else {
                return false;
            };
            if !nb.is_leaf() {
                x = b;
            } else if !na.is_leaf() {
                x = a;
            } else {
                break a.max(b) + 1;
            }
        };
        let lo = l.min(r);
        if lo <= c || l == r || l.max(r) >= end || end > n {
            return false;
        }
        ranges.push((lo, end, c));
    }
    ranges.sort_unstable();
    if ranges.is_empty() || ranges.windows(2).any(|w| w[0].1 > w[1].0) {
        return false;
    }
    // The ranges side by side, largest first.
    {
        use core::sync::atomic::{AtomicBool, Ordering};
        let spans = || ranges.iter().map(|r| (r.0, r.1));
        let cs = crate::par::split_ranges(counts, spans());
        let ds = crate::par::split_ranges(&mut plan.dist, spans());
        let ls = crate::par::split_ranges(&mut plan.leaf, spans());
        let ok: Vec<AtomicBool> = ranges.iter().map(|_| AtomicBool::new(false)).collect();
        let mut jobs: Vec<_> = ranges.iter().zip(cs).zip(ds).zip(ls).zip(&ok).collect();
        jobs.sort_by_key(|((((r, _), _), _), _)| core::cmp::Reverse(r.1 - r.0));
        crate::par::each_job(jobs, threads, |((((r, c), d), l), ok)| {
            let root = &nodes[r.2];
            let roots = [root.left() as usize, root.right() as usize];
            ok.store(fused_range(nodes, r.0, c, d, l, n_wide, Some(roots)), Ordering::Relaxed);
        });
        if !ok.iter().all(|o| o.load(Ordering::Relaxed)) {
            return false;
        }
    }
    // The nodes outside the ranges, from the last to the first.
    let mut seen = Claims::new(n);
    let inside = |x: usize| {
        let k = ranges.partition_point(|r| r.0 <= x);
        k > 0 && x < ranges[k - 1].1
    };
    let mut hi = n;
    for k in (0..=ranges.len()).rev() {
        let lo = if k > 0 { ranges[k - 1].1 } else { 0 };
        for i in (lo..hi).rev() {
            let node = &nodes[i];
            if node.is_leaf() {
                counts[i] = node.count;
                (plan.dist[i], plan.leaf[i]) = plan_entry(node, node.count as usize, None, n_wide);
                continue;
            }
            let (l, r) = (node.left() as usize, node.right() as usize);
            if l <= i || r <= i || l >= n || r >= n || l == r {
                return false;
            }
            // A subtree root's children are its range's (checked unclaimed there); any other
            // node's are outside every range.
            let root = ranges
                .binary_search_by_key(&(l.min(r)), |r| r.0)
                .is_ok_and(|j| ranges[j].2 == i);
            if !root && (inside(l) || inside(r) || !seen.claim(l) || !seen.claim(r)) {
                return false;
            }
            counts[i] = counts[l].saturating_add(counts[r]);
            let kids = (&plan.dist[l], &plan.dist[r]);
            (plan.dist[i], plan.leaf[i]) = plan_entry(node, counts[i] as usize, Some(kids), n_wide);
        }
        if k > 0 {
            hi = ranges[k - 1].0;
        }
    }
    true
}

/// `min_k dist_l(k) + dist_r(i - k)` over `k = 1 ..= i - 1` and the first `k` that reaches it
/// (`i >= 2`).
#[inline]
fn best(dl: &[f32; 8], dr: &[f32; 8], i: usize) -> (f32, usize) {
    let mut b = (f32::INFINITY, 1);
    for k in 1..i.min(8) {
        let c = dl[k - 1] + dr[i - k - 1];
        if c < b.0 {
            b = (c, k);
        }
    }
    b
}

/// Wide nodes and packs that [`Builder::leaf`] makes of `len` primitives, `n` to a pack.
fn leaf_sizes(len: usize, n: usize) -> (usize, usize) {
    if len <= MAX_LEAF_PACKS * n {
        return (0, len.div_ceil(n));
    }
    let per = len.div_ceil(n);
    let (mut nodes, mut packs) = (1, 0);
    let mut left = len;
    while left > 0 {
        let chunk = per.min(left);
        let (cn, cp) = leaf_sizes(chunk, n);
        nodes += cn;
        packs += cp;
        left -= chunk;
    }
    (nodes, packs)
}

/// `best(dl, dr, i).0` for every `i = 1 ..= 8` at once (lane `i - 1`; `+inf` for `i = 1`): the
/// same minima (a minimum does not depend on the order it is taken in), without branches.
// PERF: the same in eight lanes (each `k`'s `dl[k - 1]` plus `dr` moved up `k` lanes, a running
// `min_l`; the same bits): the collapse of the 1M soup's tree 171.1-172.5 ms against
// 170.6-173.8 with this loop (2026-12-06, Intel Xeon): not kept.
#[inline]
fn best_all(dl: &[f32; 8], dr: &[f32; 8]) -> [f32; 8] {
    let mut out = [f32::INFINITY; 8];
    for (j, o) in out.iter_mut().enumerate() {
        for k in 1..=j {
            let c = dl[k - 1] + dr[j - k];
            *o = if c < *o { c } else { *o };
        }
    }
    out
}

/// Primitives below every binary node (iterative post-order; malformed trees are errors).
#[cfg(test)]
fn subtree_counts(bvh: &Bvh2) -> Result<Vec<u32>, CollapseError> {
    let mut counts = Vec::new();
    subtree_counts_into(bvh, &mut counts)?;
    Ok(counts)
}

/// [`subtree_counts`] into `counts` (kept between calls).
fn subtree_counts_into(bvh: &Bvh2, counts: &mut Vec<u32>) -> Result<(), CollapseError> {
    let n = bvh.nodes.len();
    counts.clear();
    counts.resize(n, 0);
    if n == 0 || counts_in_index_order(bvh, counts) {
        return Ok(());
    }
    counts.fill(0);
    counts_with_stack(bvh, counts)
}

/// [`subtree_counts`] by a post-order walk from the root with a stack (any node order; malformed
/// trees are errors; nodes the walk does not reach keep their count).
fn counts_with_stack(bvh: &Bvh2, counts: &mut [u32]) -> Result<(), CollapseError> {
    let n = bvh.nodes.len().min(counts.len());
    // (node, children done)
    let mut todo = vec![(0u32, false)];
    let mut budget = 2 * n + 1;
    while let Some((i, done)) = todo.pop() {
        budget = budget.checked_sub(1).ok_or(CollapseError::Malformed)?;
        let node = bvh.nodes.get(i as usize).ok_or(CollapseError::Malformed)?;
        if node.is_leaf() {
            counts[i as usize] = node.count;
        } else if done {
            let c = |j: u32| counts.get(j as usize).copied().ok_or(CollapseError::Malformed);
            counts[i as usize] = c(node.left())?.saturating_add(c(node.right())?);
        } else {
            todo.push((i, true));
            todo.push((node.right(), false));
            todo.push((node.left(), false));
        }
    }
    Ok(())
}

/// [`subtree_counts`] in one pass from the last node to the first, where every interior node's
/// children come after it and no node is the child of two (a forest: the walk from the root
/// would give the same counts to every node it reaches, and never fail). `false` where that
/// does not hold (then `counts` holds garbage).
// PERF: the walk with a stack took about 19 ms on the 1M soup's tree (2M nodes).
fn counts_in_index_order(bvh: &Bvh2, counts: &mut [u32]) -> bool {
    let n = bvh.nodes.len().min(counts.len());
    let mut seen = Claims::new(n);
    for i in (0..n).rev() {
        let node = &bvh.nodes[i];
        if node.is_leaf() {
            counts[i] = node.count;
            continue;
        }
        let (l, r) = (node.left() as usize, node.right() as usize);
        if l <= i || r <= i || l >= n || r >= n || l == r || !seen.claim(l) || !seen.claim(r) {
            return false;
        }
        counts[i] = counts[l].saturating_add(counts[r]);
    }
    n == bvh.nodes.len()
}

impl<L: Lane, const N: usize> BvhWide<L, N> {
    /// Builds an `N`-wide BVH over `tris` in one call: the binary tree with `params`
    /// ([`Bvh2::build`]), then the cost-optimal collapse ([`from_bvh2`](Self::from_bvh2)); the
    /// binary tree is dropped. The binary build's statistics come with it (triangles left out;
    /// its nodes, leaves and depth are the binary tree's, not the wide one's). To keep the binary tree, refit it, or reuse memory across rebuilds, call the two
    /// steps ([`Builder`](crate::build::Builder), [`Collapser`]).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::BuildParams, layout::Bvh8, traverse::Watertight};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh8, stats) = Bvh8::build(&tris[..], &BuildParams::default()).unwrap();
    /// assert_eq!(stats.invalid, 0);
    /// let hit = bvh8.intersect::<Watertight>(&Ray::new(Vec3::new(0.1, 0.2, -5.0), Vec3::Z)).unwrap();
    /// assert!((hit.t - 4.0).abs() < 0.05);
    /// ```
    pub fn build<P: Triangles + ?Sized>(
        tris: &P,
        params: &crate::build::BuildParams,
    ) -> Result<(Self, crate::build::BuildStats), WideBuildError> {
        let (bvh, stats) = Bvh2::build(tris, params)?;
        Ok((Self::from_bvh2(&bvh, tris)?, stats))
    }

    /// [`build`](Self::build) on up to `threads` threads (`std`): [`Bvh2::build_par`], then
    /// [`from_bvh2_par`](Self::from_bvh2_par); the same tree as `build` for the builders whose
    /// parallel form builds the sequential tree (see
    /// [`Builder::build_into_par`](crate::build::Builder::build_into_par)).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::BuildParams, layout::Bvh8, traverse::Moller};
    /// let tris = strahl::scene::thin_soup(20_000, 1);
    /// let (one, _) = Bvh8::build(&tris[..], &BuildParams::default()).unwrap();
    /// let (two, _) = Bvh8::build_par(&tris[..], &BuildParams::default(), 2).unwrap();
    /// assert_eq!((one.nodes().len(), one.packs().len()), (two.nodes().len(), two.packs().len()));
    /// let ray = Ray::new(Vec3::splat(-1.0), Vec3::ONE);
    /// assert_eq!(one.intersect::<Moller>(&ray), two.intersect::<Moller>(&ray));
    /// ```
    #[cfg(feature = "std")]
    pub fn build_par<P: Triangles + Sync + ?Sized>(
        tris: &P,
        params: &crate::build::BuildParams,
        threads: usize,
    ) -> Result<(Self, crate::build::BuildStats), WideBuildError>
    where
        L: Send + Sync,
    {
        let (bvh, stats) = Bvh2::build_par(tris, params, threads)?;
        Ok((Self::from_bvh2_par(&bvh, tris, threads)?, stats))
    }

    /// Collapses `bvh` (built over `tris`) into an `N`-wide BVH with packed leaves.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// let mesh = strahl::scene::icosphere(2);
    /// let tris = mesh.to_soup();
    /// let (bvh2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let bvh8 = Bvh8::from_bvh2(&bvh2, &tris[..]).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -5.0), Vec3::Z);
    /// let hit = bvh8.intersect::<Watertight>(&ray).unwrap();
    /// assert_eq!(Some(hit), bvh2.intersect::<Watertight, _>(&tris[..], &ray));
    /// assert!(bvh8.occluded::<Watertight>(&ray));
    /// ```
    pub fn from_bvh2<P: Triangles + ?Sized>(bvh: &Bvh2, tris: &P) -> Result<Self, CollapseError> {
        Self::collapse::<P, false>(bvh, tris)
    }

    /// [`from_bvh2`](Self::from_bvh2) with the greedy collapse: open the child of largest surface
    /// area until there are `N`, and make every subtree of at most `N` primitives one pack.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// let tris = strahl::scene::icosphere(3).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let greedy = Bvh8::from_bvh2_greedy(&b2, &tris[..]).unwrap();
    /// let optimal = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// assert!(optimal.nodes().len() < greedy.nodes().len()); // the optimal collapse fills its nodes better
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// assert_eq!(greedy.intersect::<Watertight>(&ray), optimal.intersect::<Watertight>(&ray));
    /// ```
    pub fn from_bvh2_greedy<P: Triangles + ?Sized>(bvh: &Bvh2, tris: &P) -> Result<Self, CollapseError> {
        Self::collapse::<P, true>(bvh, tris)
    }

    fn collapse<P: Triangles + ?Sized, const GREEDY: bool>(bvh: &Bvh2, tris: &P) -> Result<Self, CollapseError> {
        let () = Self::LANES_MATCH;
        let (mut counts, mut plan) = (Vec::new(), Plan::default());
        counts_and_plan(bvh, &mut counts, &mut plan, N, GREEDY, 1)?;
        let mut out = Self::empty();
        Self::collapse_with(bvh, tris, &counts, &plan, &mut out)?;
        Ok(out)
    }

    /// An empty tree (no nodes, no memory).
    fn empty() -> Self {
        Self {
            nodes: Vec::new(),
            packs: Vec::new(),
            depth: 0,
        }
    }

    /// Empties the tree, keeping its arrays' memory.
    fn clear(&mut self) {
        self.nodes.clear();
        self.packs.clear();
        self.depth = 0;
    }

    /// The collapse of `bvh` with the subtree counts and plan already made (an empty plan: the
    /// greedy collapse) into `out`, whose arrays are reused where large enough. On an error
    /// `out` is left empty.
    fn collapse_with<P: Triangles + ?Sized>(
        bvh: &Bvh2,
        tris: &P,
        counts: &[u32],
        plan: &Plan,
        out: &mut Self,
    ) -> Result<(), CollapseError> {
        let mut b = Builder::<L, N, P>::new(bvh, tris, counts, plan, has_repeats(bvh, tris));
        b.nodes = core::mem::take(&mut out.nodes);
        b.packs = core::mem::take(&mut out.packs);
        b.nodes.clear();
        b.packs.clear();
        let done = if bvh.nodes.is_empty() {
            Ok(())
        } else {
            // PERF: large trees on transparent huge pages (feature `hugepages`, Linux; see
            // `layout::pages`): fewer TLB misses in traversal, results unchanged. The arrays are
            // made at their final size in advised memory (or were, the last time).
            b.presize(0);
            b.run(0)
        };
        (out.nodes, out.packs, out.depth) = (b.nodes, b.packs, b.depth);
        if done.is_err() {
            out.clear();
        }
        done
    }

    /// [`from_bvh2`](Self::from_bvh2) on up to `threads` threads (`std`; at least 1, at most
    /// [`MAX_THREADS`](crate::build::MAX_THREADS)): the same tree, node for node and pack for
    /// pack, numbered in another order (the same bytes on every run with the same `threads`).
    /// The subtree counts and the cost-optimal plan are made in one pass over the binary nodes,
    /// cut into runs of whole subtrees made side by side where the tree is laid out subtree by
    /// subtree (the top-down builders' trees, sequential and parallel; other trees on the calling
    /// thread); the wide nodes and packs of subtrees of at most `n / (8 threads)` triangles (at
    /// least 4,096) side by side, each subtree's packs written straight into its part of the
    /// output array (the parts sized by a first pass). Trees of up to 8,192 triangles are
    /// collapsed on the calling thread, and so is a tree that cannot be collapsed (the same error
    /// as `from_bvh2`).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams}, layout::Bvh8, scene, traverse::Moller};
    /// let tris = scene::thin_soup(20_000, 1);
    /// let (bvh2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let one = Bvh8::from_bvh2(&bvh2, &tris[..]).unwrap();
    /// let two = Bvh8::from_bvh2_par(&bvh2, &tris[..], 2).unwrap();
    /// assert_eq!((one.nodes().len(), one.packs().len()), (two.nodes().len(), two.packs().len()));
    /// let ray = strahl::Ray::new(strahl::Vec3::splat(-1.0), strahl::Vec3::ONE);
    /// assert_eq!(one.intersect::<Moller>(&ray), two.intersect::<Moller>(&ray));
    /// ```
    #[cfg(feature = "std")]
    pub fn from_bvh2_par<P: Triangles + Sync + ?Sized>(
        bvh: &Bvh2,
        tris: &P,
        threads: usize,
    ) -> Result<Self, CollapseError>
    where
        L: Send + Sync,
    {
        let mut out = Self::empty();
        Self::collapse_par_into(bvh, tris, threads, &mut Collapser::new(), &mut out)?;
        Ok(out)
    }

    /// [`from_bvh2_par`](Self::from_bvh2_par) with `scratch`'s tables and into `out`, both
    /// reused where large enough ([`Collapser::collapse_into_par`]). On an error `out` is left
    /// empty.
    #[cfg(feature = "std")]
    fn collapse_par_into<P: Triangles + Sync + ?Sized>(
        bvh: &Bvh2,
        tris: &P,
        threads: usize,
        scratch: &mut Collapser,
        out: &mut Self,
    ) -> Result<(), CollapseError>
    where
        L: Send + Sync,
    {
        use core::sync::atomic::{AtomicUsize, Ordering};
        use std::sync::Mutex;
        let () = Self::LANES_MATCH;
        let threads = threads.clamp(1, crate::build::MAX_THREADS);
        let made = counts_and_plan(bvh, &mut scratch.counts, &mut scratch.plan, N, false, threads);
        if let Err(e) = made {
            out.clear();
            return Err(e);
        }
        let (counts, plan) = (&scratch.counts[..], &scratch.plan);
        let total = counts.first().copied().unwrap_or(0) as usize;
        if threads == 1 || total <= 2 * PAR_GRAIN {
            return Self::collapse_with(bvh, tris, counts, plan, out);
        }
        // PERF: the repeat scan (a pass over every primitive index) once, not once per worker's
        // builder: each subtree's builder made it again, twice per job, and the collapse of the
        // 1M soup's tree took as long on 2 threads as on 1.
        let repeats = has_repeats(bvh, tris);
        let builder = || Builder::<L, N, P>::new(bvh, tris, counts, plan, repeats);
        // The top on this thread, down to subtrees of at most `grain` triangles.
        let grain = (total / threads.saturating_mul(8)).max(PAR_GRAIN);
        let mut top = builder();
        let mut jobs = Vec::new();
        // NOTE: on any error the sequential collapse runs instead, so that the error is the one
        // it reports (the parallel order of work could meet another error first).
        let Ok(at) = top.new_node(1) else {
            return Self::collapse_with(bvh, tris, counts, plan, out);
        };
        if top.run_from(0, at, 1, Some((&mut jobs, grain))).is_err() {
            return Self::collapse_with(bvh, tris, counts, plan, out);
        }
        // Each subtree's wide nodes and packs, counted side by side (`sizes`: exact), so that
        // the packs can go straight to their place in one array made once (no copy after).
        let mut order: Vec<usize> = (0..jobs.len()).collect();
        order.sort_by_key(|&j| core::cmp::Reverse(counts.get(jobs[j].0 as usize).copied().unwrap_or(0)));
        let run_jobs = |f: &(dyn Fn(usize) + Sync)| {
            let next = AtomicUsize::new(0);
            crate::par::each(0..threads.min(jobs.len()), |_| {
                while let Some(&j) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                    f(j);
                }
            });
        };
        let sizes: Vec<Mutex<Option<(usize, usize)>>> = (0..jobs.len()).map(|_| Mutex::new(None)).collect();
        run_jobs(&|j| {
            let got = builder().sizes(jobs[j].0).ok();
            if let Ok(mut g) = sizes[j].lock() {
                *g = got;
            }
        });
        let mut job_sizes = Vec::with_capacity(jobs.len());
        for s in sizes {
            let Some(s) = s.into_inner().ok().flatten() else {
                return Self::collapse_with(bvh, tris, counts, plan, out);
            };
            job_sizes.push(s);
        }
        let top_packs = top.packs.len();
        let packs_total = top_packs + job_sizes.iter().map(|s| s.1).sum::<usize>();
        if packs_total >= 1 << 27 {
            return Self::collapse_with(bvh, tris, counts, plan, out);
        }
        // `out` holds no half of the old tree from here on (a panic in a worker leaves it empty).
        out.clear();
        let mut packs = core::mem::take(&mut out.packs);
        reserve_advised(&mut packs, packs_total);
        packs.extend_from_slice(&top.packs);
        // The subtrees side by side, largest first: wide nodes into arrays of their own, packs
        // into their parts of `packs`, in job order after the top's.
        type Done<L, const N: usize> = (Vec<WideNode<L, N>>, usize, u32);
        type Part<L, const N: usize> = Mutex<Option<Result<Done<L, N>, CollapseError>>>;
        let parts: Vec<Part<L, N>> = (0..jobs.len()).map(|_| Mutex::new(None)).collect();
        {
            let mut spare = &mut packs.spare_capacity_mut()[..packs_total - top_packs];
            let mut sinks = Vec::with_capacity(jobs.len());
            for &(_, p) in &job_sizes {
                let (mine, rest) = core::mem::take(&mut spare).split_at_mut(p);
                spare = rest;
                sinks.push(Mutex::new(Some(mine)));
            }
            run_jobs(&|j| {
                let (b, _, depth) = jobs[j];
                let Some(sink) = sinks[j].lock().ok().and_then(|mut g| g.take()) else {
                    return;
                };
                let mut w = builder();
                w.nodes = super::pages::advised_with_capacity(job_sizes[j].0);
                w.sink = Some(sink);
                let part = w
                    .new_node(depth)
                    .and_then(|at| w.run_from(b, at, depth, None))
                    .map(|()| (core::mem::take(&mut w.nodes), w.sunk, w.depth));
                if let Ok(mut g) = parts[j].lock() {
                    *g = Some(part);
                }
            });
        }
        let mut done: Vec<Done<L, N>> = Vec::with_capacity(jobs.len());
        for (p, &(_, want)) in parts.into_iter().zip(&job_sizes) {
            match p.into_inner().ok().flatten() {
                Some(Ok(p)) if p.1 == want => done.push(p),
                _ => {
                    // The array goes back for the sequential collapse to reuse.
                    packs.clear();
                    out.packs = packs;
                    return Self::collapse_with(bvh, tris, counts, plan, out);
                }
            }
        }
        // SAFETY: `packs` has capacity at least `packs_total` (reserved above, never pushed to since) and its
        // first `top_packs` elements are initialised; the rest of the capacity was cut into one
        // disjoint part per job, of `job_sizes[j].1` elements, and job `j` wrote its part's first
        // `p.1` elements, checked above to be all of them (`MaybeUninit::write` at `sunk`, one
        // more each time). So all `packs_total` elements are initialised.
        unsafe { packs.set_len(packs_total) };
        // In job order: node i >= 1 of a part goes to `base + i - 1`, node 0 to the job's slot;
        // its packs follow the packs before it.
        let mut nodes = core::mem::take(&mut out.nodes);
        reserve_advised(
            &mut nodes,
            top.nodes.len() + done.iter().map(|d| d.0.len().saturating_sub(1)).sum::<usize>(),
        );
        nodes.extend_from_slice(&top.nodes);
        let mut depth = top.depth;
        let mut pbase = top_packs as u32;
        for (&(_, at, _), (pn, pc, pd)) in jobs.iter().zip(done) {
            let base = nodes.len() as u32;
            let relocate = |mut node: WideNode<L, N>| {
                for c in node.child.iter_mut() {
                    *c = if *c == EMPTY_CHILD {
                        *c
                    } else if *c & LEAF_BIT != 0 {
                        *c + (pbase << 4)
                    } else {
                        base + *c - 1
                    };
                }
                node
            };
            nodes[at] = relocate(pn[0]);
            nodes.extend(pn[1..].iter().map(|&n| relocate(n)));
            pbase += pc as u32;
            depth = depth.max(pd);
        }
        (out.nodes, out.packs, out.depth) = (nodes, packs, depth);
        Ok(())
    }

    const LANES_MATCH: () = assert!(L::N == N && N <= 8);
}

/// The parallel collapse does not cut the tree below this many triangles per subtree.
#[cfg(feature = "std")]
const PAR_GRAIN: usize = 4096;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::{Bvh4, Bvh8, EMPTY_CHILD, leaf_packs};

    /// `best_all` gives `best`'s minima bit for bit, `+inf` and NaN inputs included.
    #[test]
    fn best_all_is_best_for_every_width() {
        let mut r = crate::scene::Rng::new(5);
        let specials = [f32::INFINITY, f32::NAN, 0.0, 1e30, 3.5];
        for t in 0..2000 {
            let mut v = |k: usize| {
                if t % 7 == 0 && k.is_multiple_of(3) {
                    specials[(k + t) % specials.len()]
                } else {
                    r.range(0.0, 10.0)
                }
            };
            let dl: [f32; 8] = core::array::from_fn(&mut v);
            let dr: [f32; 8] = core::array::from_fn(&mut v);
            let all = best_all(&dl, &dr);
            assert_eq!(all[0], f32::INFINITY);
            for i in 2..=8 {
                assert_eq!(all[i - 1].to_bits(), best(&dl, &dr, i).0.to_bits(), "{dl:?} {dr:?} {i}");
            }
        }
    }

    /// `sizes` predicts exactly what `run` makes for spatial-split trees, also where invalid
    /// triangles keep the references fewer than the triangles (else the parallel collapse
    /// silently falls back to the sequential one).
    #[test]
    fn sizes_exact_on_spatial_trees() {
        let sp = crate::build::SpatialSplits {
            alpha: 0.0,
            max_references: 4.0,
            bins: 16,
            min_node_size: 2,
        };
        let mut with_invalid = crate::scene::thin_soup(3_000, 4);
        let n = with_invalid.len();
        for _ in 0..n {
            with_invalid.push([glam::Vec3::NAN, glam::Vec3::X, glam::Vec3::Y]);
        }
        for (name, tris) in [
            ("plain", crate::scene::thin_soup(3_000, 4)),
            ("half invalid", with_invalid),
        ] {
            let (b2, _) = Bvh2::build_spatial(&tris[..], &crate::build::BuildParams::default(), &sp).unwrap();
            let counts = subtree_counts(&b2).unwrap();
            let plan = Plan::new(&b2, &counts, 8).unwrap();
            let mut b =
                Builder::<crate::math::f32x8, 8, _>::new(&b2, &tris[..], &counts, &plan, has_repeats(&b2, &tris[..]));
            let want = b.sizes(0).unwrap();
            b.run(0).unwrap();
            assert_eq!(want, (b.nodes.len(), b.packs.len()), "{name}");
        }
    }

    #[test]
    fn every_triangle_lands_in_exactly_one_pack() {
        let mesh = crate::scene::icosphere(3);
        let tris = mesh.to_soup();
        for params in [
            crate::build::BuildParams::default(),
            crate::build::BuildParams::fastest(),
        ] {
            let (b2, _) = Bvh2::build(&tris[..], &params).unwrap();
            let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
            let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
            let mut seen = vec![0u32; tris.len()];
            for p in b8.packs() {
                for i in 0..8 {
                    if p.prim[i] != crate::geometry::INVALID {
                        seen[p.prim[i] as usize] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&c| c == 1));
            let seen4: usize = b4
                .packs()
                .iter()
                .map(|p| p.prim.iter().filter(|&&x| x != u32::MAX).count())
                .sum();
            assert_eq!(seen4, tris.len());
            // Every leaf code addresses packs in range; every child box contains its packs.
            for n in b8.nodes() {
                for (i, &c) in n.child.iter().enumerate() {
                    if c != EMPTY_CHILD && c & LEAF_BIT != 0 {
                        let (first, count) = leaf_packs(c);
                        assert!(first + count <= b8.packs().len());
                        let b = n.bounds.get(i);
                        for p in &b8.packs()[first..first + count] {
                            for l in 0..8 {
                                if p.valid >> l & 1 == 1 {
                                    for v in p.get(l) {
                                        assert!(b.contains_point(v));
                                    }
                                }
                            }
                        }
                    }
                }
            }
            assert!(b8.nodes().len() < b2.nodes.len() / 4);
        }
    }

    #[test]
    fn huge_leaves_get_a_node_of_their_own() {
        // 300 copies of one triangle: all centroids coincide; a builder allowed huge leaves
        // makes one leaf, which the collapse must split into packs under extra nodes.
        let t = [glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y];
        let tris = vec![t; 300];
        let b2 = Bvh2 {
            nodes: vec![crate::traverse::Node::leaf(&Aabb::from_points(&t), 0, 300)],
            prim_indices: (0..300).collect(),
        };
        let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
        let total: usize = b8.packs().iter().map(|p| p.valid.count_ones() as usize).sum();
        assert_eq!(total, 300);
        assert!(b8.depth() >= 2);
    }

    #[test]
    fn malformed_trees_are_errors() {
        let t = [glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y];
        let tris = [t; 2];
        let bad = Bvh2 {
            nodes: vec![crate::traverse::Node::interior(&Aabb::from_points(&t), 7)],
            prim_indices: vec![],
        };
        assert_eq!(Bvh8::from_bvh2(&bad, &tris[..]).unwrap_err(), CollapseError::Malformed);
        let bad = Bvh2 {
            nodes: vec![crate::traverse::Node::leaf(&Aabb::from_points(&t), 0, 5)],
            prim_indices: vec![0, 1],
        };
        assert_eq!(Bvh8::from_bvh2(&bad, &tris[..]).unwrap_err(), CollapseError::Malformed);
        // A leaf claiming far more primitives than exist: an error, not an allocation of its size.
        let bad = Bvh2 {
            nodes: vec![crate::traverse::Node::leaf(&Aabb::from_points(&t), 0, (1 << 31) - 1)],
            prim_indices: vec![],
        };
        assert_eq!(Bvh8::from_bvh2(&bad, &tris[..]).unwrap_err(), CollapseError::Malformed);
        assert_eq!(Bvh4::from_bvh2(&bad, &tris[..]).unwrap_err(), CollapseError::Malformed);
        let empty = Bvh8::from_bvh2(&Bvh2::default(), &tris[..]).unwrap();
        assert!(empty.is_empty());
    }

    /// The plan made in index order (`fused_range`, trees whose children follow their parents) is
    /// the plan of the walk with a stack, bit for bit, 4- and 8-wide; trees in another order (the LBVH's,
    /// PLOC's) take the walk.
    #[test]
    fn plan_in_index_order_equals_the_walk() {
        use crate::build::{BuildParams, Builder};
        let soups = [
            crate::scene::thin_soup(3000, 4),
            crate::scene::clustered_soup(2500, 6, 2),
            crate::scene::icosphere(3).to_soup(),
        ];
        for tris in &soups {
            for (name, p) in [
                ("fast", BuildParams::fast()),
                ("quality", BuildParams::quality()),
                ("median", BuildParams::median()),
                ("fastest", BuildParams::fastest()),
                ("ploc", BuildParams::ploc()),
                ("hybrid", BuildParams::hybrid()),
            ] {
                let (bvh, _) = Builder::new().build(&tris[..], &p).unwrap();
                let counts = subtree_counts(&bvh).unwrap();
                for n_wide in [4, 8] {
                    let n = bvh.nodes.len();
                    let mut walked = Plan {
                        dist: vec![[0.0; 8]; n],
                        leaf: vec![false; n],
                    };
                    walked.fill_with_stack(&bvh, &counts, n_wide).unwrap();
                    let mut ordered = Plan {
                        dist: vec![[0.0; 8]; n],
                        leaf: vec![false; n],
                    };
                    let in_order = bvh
                        .nodes
                        .iter()
                        .enumerate()
                        .all(|(i, nd)| nd.is_leaf() || (nd.left() as usize > i && nd.right() as usize > i));
                    let mut fused_counts = vec![0; n];
                    let (d, l) = (&mut ordered.dist, &mut ordered.leaf);
                    let fused = fused_range(&bvh.nodes, 0, &mut fused_counts, d, l, n_wide, None);
                    assert_eq!(fused, in_order, "{name}");
                    // The top-down builders' trees are in index order; the others not.
                    assert_eq!(in_order, ["fast", "quality", "median"].contains(&name), "{name}");
                    if in_order {
                        assert_eq!(ordered.leaf, walked.leaf, "{name} {n_wide}");
                        let bits = |p: &Plan| {
                            p.dist
                                .iter()
                                .flat_map(|d| d[..n_wide].iter().map(|x| x.to_bits()))
                                .collect::<Vec<_>>()
                        };
                        assert_eq!(bits(&ordered), bits(&walked), "{name} {n_wide}");
                        assert_eq!(fused_counts, counts, "{name} {n_wide}");
                    }
                    let made = Plan::new(&bvh, &counts, n_wide).unwrap();
                    assert_eq!(made.leaf, walked.leaf, "{name} {n_wide}");
                }
            }
        }
    }

    /// The fused counts and plan (`counts_and_plan`: one pass, or ranges side by side on several
    /// threads) equal the separate passes bit for bit on the trees of every kind of builder
    /// (sequential and parallel top-down builds, whose layout the ranges use, and the LBVH's,
    /// PLOC's and HLBVH's, which take the walks), and malformed trees answer as on one thread.
    #[test]
    #[cfg(feature = "std")]
    fn fused_counts_and_plan_equal_the_separate_passes() {
        use crate::build::{BuildParams, Builder as Bvh2Builder};
        let run = |bvh: &Bvh2, n_wide: usize, threads: usize| {
            let (mut c, mut plan) = (Vec::new(), Plan::default());
            counts_and_plan(bvh, &mut c, &mut plan, n_wide, false, threads).map(|()| (c, plan))
        };
        let bits = |p: &Plan, n_wide: usize| {
            p.dist
                .iter()
                .flat_map(|d| d[..n_wide].iter().map(|x| x.to_bits()))
                .collect::<Vec<_>>()
        };
        let soups = [
            crate::scene::thin_soup(70_000, 3),
            crate::scene::clustered_soup(70_000, 6, 2),
        ];
        for tris in &soups {
            for (name, p, build_threads) in [
                ("fast", BuildParams::fast(), 1),
                ("fast on 3 threads", BuildParams::fast(), 3),
                ("balanced", BuildParams::balanced(), 1),
                ("median", BuildParams::median(), 1),
                ("fastest", BuildParams::fastest(), 1),
                ("ploc", BuildParams::ploc(), 1),
                ("hybrid_sah", BuildParams::hybrid_sah(), 1),
            ] {
                let mut b = Bvh2Builder::new();
                let mut bvh = Bvh2::default();
                b.build_into_par(&tris[..], &p, &mut bvh, build_threads).unwrap();
                assert!(
                    bvh.nodes.len() >= PAR_PLAN_NODES,
                    "{name}: too small to take the ranges"
                );
                let counts = subtree_counts(&bvh).unwrap();
                for n_wide in [4, 8] {
                    let reference = Plan::new(&bvh, &counts, n_wide).unwrap();
                    for threads in [1, 2, 3, 8] {
                        let (c, plan) = run(&bvh, n_wide, threads).unwrap();
                        assert!(c == counts, "{name} {n_wide} {threads}");
                        assert!(plan.leaf == reference.leaf, "{name} {n_wide} {threads}");
                        assert!(
                            bits(&plan, n_wide) == bits(&reference, n_wide),
                            "{name} {n_wide} {threads}"
                        );
                    }
                }
                // The top-down builds, sequential and parallel, are cut into ranges (not a silent
                // fallback).
                if ["fast", "fast on 3 threads", "balanced", "median"].contains(&name) {
                    for threads in [2, 8] {
                        let n = bvh.nodes.len();
                        let mut c = vec![0; n];
                        let mut plan = Plan {
                            dist: vec![[0.0; 8]; n],
                            leaf: vec![false; n],
                        };
                        assert!(fused_par(&bvh.nodes, &mut c, &mut plan, 8, threads), "{name} {threads}");
                        assert!(c == counts, "{name} {threads}");
                    }
                }
            }
        }
        // Malformed trees: a child out of range, a node shared by two parents (a DAG: the walks
        // accept it), a cycle, deep in each of the ranges' subtrees and at the top.
        let (base, _) = Bvh2Builder::new().build(&soups[0][..], &BuildParams::fast()).unwrap();
        let n = base.nodes.len();
        let interiors: Vec<usize> = (0..n).filter(|&i| !base.nodes[i].is_leaf()).collect();
        // The root's two children sharing one pair of children: every level below them holds
        // each node twice (the runs would overlap; the walks accept the DAG).
        let mut shared = base.clone();
        let (a, b) = (shared.nodes[0].left() as usize, shared.nodes[0].right() as usize);
        if !shared.nodes[a].is_leaf() {
            shared.nodes[b] = crate::traverse::Node::interior(&shared.nodes[b].aabb(), shared.nodes[a].left());
            let one = run(&shared, 8, 1).unwrap();
            for threads in [2, 5] {
                let par = run(&shared, 8, threads).unwrap();
                assert!(one.0 == par.0 && one.1.leaf == par.1.leaf && bits(&one.1, 8) == bits(&par.1, 8));
            }
        }
        for (k, &at) in interiors
            .iter()
            .step_by(interiors.len() / 7)
            .chain(&interiors[..3])
            .enumerate()
        {
            let nd = base.nodes[at];
            let b = nd.aabb();
            for bad in [n as u32 + 5, at as u32, interiors[k % interiors.len()] as u32, 0, 1] {
                let mut t = base.clone();
                t.nodes[at] = crate::traverse::Node::interior(&b, bad.min(u32::MAX - 1));
                let one = run(&t, 8, 1);
                for threads in [2, 5] {
                    let par = run(&t, 8, threads);
                    match (&one, &par) {
                        (Ok((c1, p1)), Ok((c2, p2))) => {
                            assert!(c1 == c2, "node {at} -> {bad}");
                            assert!(p1.leaf == p2.leaf, "node {at} -> {bad}");
                            assert!(bits(p1, 8) == bits(p2, 8), "node {at} -> {bad}");
                        }
                        (Err(e1), Err(e2)) => assert_eq!(e1, e2, "node {at} -> {bad}"),
                        _ => panic!(
                            "node {at} -> {bad}: {:?} on one thread, {:?} on {threads}",
                            one.is_ok(),
                            par.is_ok()
                        ),
                    }
                }
            }
        }
    }

    /// The counts made in index order equal the walk's on every node the walk reaches; trees in
    /// another order, and a node that is the child of two, take the walk.
    #[test]
    fn counts_in_index_order_equal_the_walk() {
        use crate::build::{BuildParams, Builder as Bvh2Builder};
        let tris = crate::scene::clustered_soup(3000, 6, 2);
        for p in [
            BuildParams::fast(),
            BuildParams::median(),
            BuildParams::fastest(),
            BuildParams::ploc(),
        ] {
            let (bvh, _) = Bvh2Builder::new().build(&tris[..], &p).unwrap();
            let mut walked = vec![0; bvh.nodes.len()];
            counts_with_stack(&bvh, &mut walked).unwrap();
            let mut ordered = vec![0; bvh.nodes.len()];
            let in_order = counts_in_index_order(&bvh, &mut ordered);
            assert_eq!(
                in_order,
                p.strategy == BuildParams::fast().strategy || p.strategy == BuildParams::median().strategy
            );
            if in_order {
                assert_eq!(ordered, walked);
            }
            assert_eq!(subtree_counts(&bvh).unwrap(), walked);
        }
        // Node 1 is the child of two interior nodes: not a tree; the walk decides.
        let b = Aabb::from_points(&[glam::Vec3::ZERO, glam::Vec3::ONE]);
        let nodes = vec![
            crate::traverse::Node::interior(&b, 1),
            crate::traverse::Node::interior(&b, 3),
            crate::traverse::Node::leaf(&b, 0, 1),
            crate::traverse::Node::leaf(&b, 0, 1),
            crate::traverse::Node::leaf(&b, 0, 1),
        ];
        let mut dag = Bvh2 {
            nodes,
            prim_indices: vec![0],
        };
        let mut c = vec![0; 5];
        assert!(counts_in_index_order(&dag, &mut c));
        dag.nodes[1] = crate::traverse::Node::interior(&b, 2);
        assert!(!counts_in_index_order(&dag, &mut c), "a child claimed twice");
        let mut walked = vec![0; 5];
        assert_eq!(
            counts_with_stack(&dag, &mut walked).is_ok(),
            subtree_counts(&dag).is_ok()
        );
    }

    /// `Builder::sizes` predicts exactly the wide nodes and packs the collapse makes (the arrays
    /// are allocated at that size once), greedy and cost-optimal, 4- and 8-wide, with leaves
    /// large enough to be split below nodes of their own.
    #[test]
    fn sizes_predict_the_output_exactly() {
        use crate::build::{BuildParams, Builder as Bvh2Builder};
        let big_leaves = BuildParams {
            min_leaf_size: 150,
            max_leaf_size: 300,
            ..BuildParams::fast()
        };
        let soups = [
            crate::scene::thin_soup(3000, 4),
            crate::scene::clustered_soup(2500, 6, 2),
        ];
        for tris in &soups {
            for p in [
                BuildParams::fast(),
                BuildParams::fastest(),
                BuildParams::ploc(),
                big_leaves,
            ] {
                let (bvh, _) = Bvh2Builder::new().build(&tris[..], &p).unwrap();
                let counts = subtree_counts(&bvh).unwrap();
                fn check<L: Lane, const N: usize>(bvh: &Bvh2, tris: &[Triangle], counts: &[u32], greedy: bool) {
                    let plan = if greedy {
                        Plan::default()
                    } else {
                        Plan::new(bvh, counts, N).unwrap()
                    };
                    let mut b = Builder::<L, N, [Triangle]>::new(bvh, tris, counts, &plan, has_repeats(bvh, tris));
                    let want = b.sizes(0).unwrap();
                    b.run(0).unwrap();
                    assert_eq!(want, (b.nodes.len(), b.packs.len()), "N = {N}, greedy {greedy}");
                }
                for greedy in [false, true] {
                    check::<crate::math::f32x8, 8>(&bvh, tris, &counts, greedy);
                    check::<crate::math::f32x4, 4>(&bvh, tris, &counts, greedy);
                }
            }
        }
    }

    /// The collapse's cost model evaluated on a wide tree: `NODE_COST` per wide node and
    /// `PACK_COST` per pack, each times the area of its box (the box stored in its parent).
    fn wide_cost<L: Lane, const N: usize>(w: &BvhWide<L, N>, root: &Aabb) -> f64 {
        let area = |b: &Aabb| if b.is_empty() { 0.0 } else { b.half_area() as f64 };
        let mut cost = area(root) * NODE_COST as f64;
        for n in w.nodes() {
            for (i, &c) in n.child.iter().enumerate() {
                if c == EMPTY_CHILD {
                    continue;
                }
                let b = n.bounds.get(i);
                cost += if c & LEAF_BIT != 0 {
                    area(&b) * PACK_COST as f64 * leaf_packs(c).1 as f64
                } else {
                    area(&b) * NODE_COST as f64
                };
            }
        }
        cost
    }

    /// The cost-optimal collapse is never costlier than the greedy one by its own cost model
    /// (both are covers of the same binary tree), keeps every triangle exactly once, traces the
    /// same hits, and uses fewer nodes.
    #[test]
    fn optimal_collapse_beats_greedy_by_its_cost_model() {
        use crate::build::BuildParams;
        use crate::geometry::Ray;
        use crate::traverse::Watertight;
        let scenes = [
            crate::scene::icosphere(3).to_soup(),
            crate::scene::bunny().to_soup(),
            crate::scene::clustered_soup(5000, 7, 3),
            crate::scene::thin_soup(4000, 2),
        ];
        for tris in &scenes {
            for params in [BuildParams::default(), BuildParams::fastest(), BuildParams::quality()] {
                let (b2, _) = Bvh2::build(&tris[..], &params).unwrap();
                let root = b2.bounds();
                let opt = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
                let greedy = Bvh8::from_bvh2_greedy(&b2, &tris[..]).unwrap();
                let (co, cg) = (wide_cost(&opt, &root), wide_cost(&greedy, &root));
                assert!(co <= cg * (1.0 + 1e-5), "optimal {co} greedy {cg}");
                assert!(opt.nodes().len() <= greedy.nodes().len());
                let opt4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
                let greedy4 = Bvh4::from_bvh2_greedy(&b2, &tris[..]).unwrap();
                assert!(wide_cost(&opt4, &root) <= wide_cost(&greedy4, &root) * (1.0 + 1e-5));
                let mut seen = vec![0u32; tris.len()];
                for p in opt.packs() {
                    for l in 0..8 {
                        if p.valid >> l & 1 == 1 {
                            seen[p.prim[l] as usize] += 1;
                        }
                    }
                }
                assert!(seen.iter().all(|&c| c == 1));
                let mut rng = crate::scene::Rng::new(4);
                for _ in 0..300 {
                    let o = glam::Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
                    let ray = Ray::new(o, rng.unit_vector());
                    let want = b2.intersect::<Watertight, _>(&tris[..], &ray);
                    assert_eq!(opt.intersect::<Watertight>(&ray), want);
                    assert_eq!(opt4.intersect::<Watertight>(&ray), want);
                    assert_eq!(opt.occluded::<Watertight>(&ray), want.is_some());
                }
            }
        }
    }
}
