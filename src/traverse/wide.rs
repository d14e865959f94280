//! Single-ray traversal of 4- and 8-wide BVHs ([`layout`](crate::layout)): one x4/x8 slab test per
//! node, children visited near to far, leaves tested with the x4/x8 triangle kernels of the
//! compile-time [`TriangleTest`], a fixed-size stack on the call stack (no allocation, no_std).
//!
//! The ray's `[tmin, tmax)` is honoured; after a hit, `tmax` shrinks to it, and nodes whose entry
//! distance lies beyond the current closest hit are skipped (with the slab test's own
//! conservative slack, so nothing a hit could lie in is culled).

use super::{AcceptAll, HitFilter, TriangleTest, beyond, closest_in_pack, node_lanes, prepare};
use crate::geometry::{Hit, Ray};
use crate::intersect::{PreparedRay, TriangleLanes};

use super::stack::{CodeStack, Stack};
use crate::layout::{BvhWideRef, EMPTY_CHILD, LEAF_BIT, MAX_WIDE_DEPTH, leaf_packs};
use crate::math::{Lane, f32x8};

/// Stack entries: enough for `MAX_WIDE_DEPTH` levels of 8-wide nodes.
const STACK: usize = MAX_WIDE_DEPTH as usize * 7 + 1;

/// Asks the cache for child `code` (an interior node, or the first 384 bytes of a leaf's packs)
/// ahead of its visit: children pushed now are popped after their siblings' subtrees, by when the
/// lines have arrived. A hint only (no read happens; x86 only, a no-op elsewhere).
// PERF: measured on the 1M sphereflake (BVH8, 262k rays, best of 5): see the trace section of
// benches/RESULTS.md. Trees that fit in the cache gain nothing and lose nothing measurable.
#[inline(always)]
pub(crate) fn prefetch<L, const N: usize>(bvh: BvhWideRef<'_, L, N>, code: u32) {
    #[cfg(target_arch = "x86_64")]
    {
        let (p, bytes): (*const u8, usize) = if code & LEAF_BIT == 0 {
            (
                bvh.nodes.as_ptr().wrapping_add(code as usize).cast(),
                core::mem::size_of::<crate::layout::WideNode<L, N>>(),
            )
        } else {
            let (first, _) = leaf_packs(code);
            (
                bvh.packs.as_ptr().wrapping_add(first).cast(),
                core::mem::size_of::<crate::intersect::TriangleLanes<L, N>>(),
            )
        };
        let mut off = 0;
        while off < bytes.min(384) {
            // `wrapping_add` only computes an address, valid or not.
            crate::math::prefetch(p.wrapping_add(off));
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (bvh, code);
}

/// Closest hit of `ray` in the wide BVH `bvh`, with the triangle test `T`.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, traverse::{Moller, wide}};
/// let tris = strahl::scene::icosphere(1).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// let hit = wide::intersect::<Moller, _, 4>(b4.view(), &Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z));
/// assert!((hit.unwrap().t - 2.0).abs() < 0.1);
/// ```
#[inline]
pub fn intersect<T: TriangleTest, L: Lane, const N: usize>(bvh: BvhWideRef<'_, L, N>, ray: &Ray) -> Option<Hit> {
    let mut r = prepare::<T>(ray);
    if r.is_empty() || bvh.nodes.is_empty() {
        return None;
    }
    intersect_from::<T, L, N>(bvh, 0, &mut r)
}

/// [`intersect`] counting only the hits `filter` accepts ([`HitFilter`]): the nearest accepted
/// hit, the same as [`intersect_scalar_filtered`](super::intersect_scalar_filtered) and
/// [`intersect_brute_force_filtered`](super::intersect_brute_force_filtered) give for a filter
/// that is a function of the hit (as without a filter: the same `t`, and the primitive unless
/// tied; see [`TriangleTest::CONSERVATIVE_BOXES`] for near-ties).
///
/// ```
/// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, traverse::{Moller, wide}};
/// let tris = strahl::scene::icosphere(1).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// let ray = Ray::new(Vec3::new(0.05, 0.1, -3.0), Vec3::Z);
/// let front = wide::intersect::<Moller, _, 4>(b4.view(), &ray).unwrap();
/// // Skip the triangle the ray enters through: it leaves through the back of the sphere.
/// let back = wide::intersect_filtered::<Moller, _, 4, _>(b4.view(), &ray, |h: &Hit| h.prim != front.prim).unwrap();
/// assert!(front.t < 2.1 && back.t > 3.9);
/// ```
#[inline]
pub fn intersect_filtered<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    ray: &Ray,
    mut filter: F,
) -> Option<Hit> {
    intersect_filtered_by::<T, L, N, F>(bvh, ray, &mut filter)
}

/// [`intersect_filtered`] with the filter borrowed (the packets' single rays share one).
#[inline]
pub(crate) fn intersect_filtered_by<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    ray: &Ray,
    f: &mut F,
) -> Option<Hit> {
    let mut r = prepare::<T>(ray);
    if r.is_empty() || bvh.nodes.is_empty() {
        return None;
    }
    intersect_from_filtered::<T, L, N, F>(bvh, 0, &mut r, f)
}

/// [`occluded`] counting only the hits `filter` accepts ([`HitFilter`]): `true` if `ray` hits,
/// within `[tmin, tmax)`, a triangle whose hit `filter` accepts; stops at the first such hit.
///
/// ```
/// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let ray = Ray::new(Vec3::ZERO, Vec3::new(0.3, -0.5, 1.0)); // from inside the sphere
/// assert!(wide::occluded_filtered::<Watertight, _, 8, _>(b8.view(), &ray, |h: &Hit| h.prim < 1000));
/// // A sphere of cut-outs (every triangle rejected) lets the ray out.
/// assert!(!wide::occluded_filtered::<Watertight, _, 8, _>(b8.view(), &ray, |_: &Hit| false));
/// ```
#[inline]
pub fn occluded_filtered<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    ray: &Ray,
    mut filter: F,
) -> bool {
    occluded_prepared_filtered::<T, L, N, F>(bvh, &prepare::<T>(ray), &mut filter)
}

/// Closest hit of the prepared ray `r` in the subtree below child code `start` (a node index or a
/// leaf code; `0` is the whole tree); `r.tmax` shrinks to the hit. The packet traversal's hybrid
/// mode continues single rays with this.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, intersect::PreparedRay, layout::Bvh8};
/// use strahl::traverse::{Watertight, wide};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
/// let mut r = PreparedRay::new(&ray);
/// let hit = wide::intersect_from::<Watertight, _, 8>(b8.view(), 0, &mut r).unwrap(); // from the root
/// assert_eq!(Some(hit), b8.intersect::<Watertight>(&ray));
/// assert_eq!(r.tmax, hit.t);
/// ```
#[inline]
pub fn intersect_from<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    start: u32,
    r: &mut PreparedRay,
) -> Option<Hit> {
    intersect_from_filtered::<T, L, N, _>(bvh, start, r, &mut AcceptAll)
}

/// [`intersect_from`] counting only the hits `f` accepts (the instances' BLAS walks).
#[inline]
pub(crate) fn intersect_from_filtered<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    start: u32,
    r: &mut PreparedRay,
    f: &mut F,
) -> Option<Hit> {
    ClosestWalk::<STACK>::new(bvh, start).finish::<T, L, N, F>(bvh, r, f)
}

/// One ray's closest-hit walk, advanced one node or leaf at a time ([`step`](Self::step)), so
/// that two rays' walks can run interleaved ([`intersect_batch_incoherent`]): children pushed near
/// to far, the nearest on top, and entries beyond the closest hit so far skipped when popped.
struct ClosestWalk<const S: usize> {
    stack: Stack<S>,
    cur: u32,
    /// A valid tree visits each node at most once; more visits mean a cycle (a malformed view).
    budget: usize,
    best: Option<Hit>,
    done: bool,
}

impl<const S: usize> ClosestWalk<S> {
    #[inline(always)]
    fn new<L, const N: usize>(bvh: BvhWideRef<'_, L, N>, start: u32) -> Self {
        Self {
            stack: Stack::new(),
            cur: start,
            budget: bvh.nodes.len(),
            best: None,
            done: false,
        }
    }

    /// Walks on to the end; the closest hit (`r.tmax` shrunk to it).
    #[inline(always)]
    fn finish<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
        &mut self,
        bvh: BvhWideRef<'_, L, N>,
        r: &mut PreparedRay,
        f: &mut F,
    ) -> Option<Hit> {
        while !self.done {
            self.step::<T, L, N, F>(bvh, r, f);
        }
        self.best
    }

    /// The closest hit over every pack (closer than the one found so far), ending the walk: for
    /// views that are malformed or deeper than the stack.
    #[cold]
    fn give_up<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
        &mut self,
        bvh: BvhWideRef<'_, L, N>,
        r: &mut PreparedRay,
        f: &mut F,
    ) {
        self.best = scan_closest::<T, L, N, F>(bvh, r, f).or(self.best);
        self.done = true;
    }

    /// Visits the current node or leaf, then pops the nearest entry not beyond the closest hit.
    #[inline(always)]
    fn step<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
        &mut self,
        bvh: BvhWideRef<'_, L, N>,
        r: &mut PreparedRay,
        f: &mut F,
    ) {
        let cur = self.cur;
        if cur & LEAF_BIT == 0 {
            if self.budget == 0 {
                return self.give_up::<T, L, N, F>(bvh, r, f);
            }
            self.budget -= 1;
            if let Some(node) = bvh.nodes.get(cur as usize) {
                let (near, mut mask) = node_lanes::<T, L>(r, &node.bounds);
                if mask != 0 {
                    if mask & (mask - 1) == 0 {
                        // One child: descend without touching the stack.
                        self.cur = node.child[mask.trailing_zeros() as usize];
                        return;
                    }
                    let mut nears = [0f32; 8];
                    near.store(&mut nears);
                    // Push the hit children sorted, the nearest on top (ties: the lower slot).
                    let base = self.stack.len();
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        prefetch(bvh, node.child[i]);
                        if !self.stack.push_sorted(base, node.child[i], nears[i]) {
                            // Only trees deeper than MAX_WIDE_DEPTH (never built here) get here.
                            return self.give_up::<T, L, N, F>(bvh, r, f);
                        }
                    }
                }
            }
        } else if cur != EMPTY_CHILD {
            let (first, count) = leaf_packs(cur);
            if let Some(packs) = bvh.packs.get(first..first + count) {
                for pack in packs {
                    if let Some(h) = closest_in_pack::<T, L, N, F>(r, pack, f) {
                        r.tmax = h.t;
                        self.best = Some(h);
                    }
                }
            }
        }
        // Pop the nearest entry not beyond the closest hit.
        loop {
            match self.stack.pop() {
                None => {
                    self.done = true;
                    return;
                }
                Some((code, near)) if !beyond::<T>(near, r.tmax) => {
                    self.cur = code;
                    return;
                }
                Some(_) => {}
            }
        }
    }
}

/// [`intersect`] for every ray of a batch: `hits[i]` for `rays[i]` (the shorter length wins), the
/// same hits as one call per ray, two rays' walks interleaved (one node or leaf of each in turn,
/// a walk that ends taking the next ray, so that the processor overlaps the cache misses of one
/// walk with the work of the other): for rays that go their own ways (diffuse bounces, ambient occlusion); for coherent rays (a camera's)
/// call [`intersect`] per ray or use the [packets](super::packet).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..5)
///     .map(|i| Ray::new(Vec3::new(-3.0, 0.6 * i as f32 - 1.2, 0.1), Vec3::X))
///     .collect();
/// let mut hits = [None; 5];
/// wide::intersect_batch_incoherent::<Moller, _, 8>(b8.view(), &rays, &mut hits);
/// for (r, h) in rays.iter().zip(hits) {
///     assert_eq!(h, wide::intersect::<Moller, _, 8>(b8.view(), r));
/// }
/// assert!(hits[0].is_none() && hits[2].is_some_and(|h| (h.t - 2.0).abs() < 0.1));
/// ```
// PERF: BVH8, best of 3 x 3 rounds taking turns (Intel Xeon, 2026-12-04), against one call per
// ray: 262,144 diffuse rays 1.19x faster on the 1M sphereflake, 1.07x on the bunny; 1024 x 1024
// primary rays (coherent) 1.03x on the bunny and 0.92x (slower) on the sphereflake, hence the name;
// `intersect_batch` takes this path only for groups of rays from scattered origins.
pub fn intersect_batch_incoherent<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
) {
    intersect_batch_incoherent_filtered::<T, L, N, _>(bvh, rays, hits, AcceptAll);
}

/// [`intersect_batch_incoherent`] counting only the hits `filter` accepts ([`HitFilter`] over
/// [`BatchHit`]s: the hit and the index of its ray in `rays`): `hits[i]` is
/// [`intersect_filtered`] of `rays[i]` with the filter `|h: &Hit| filter(&BatchHit { ray: i, hit: *h })`.
///
/// ```
/// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{BatchHit, Moller, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..4).map(|i| Ray::new(Vec3::new(0.11 * i as f32 + 0.023, 0.047, -3.0), Vec3::Z)).collect();
/// // Each ray skips one primitive, say the one it was spawned from (here: the front face).
/// let front: Vec<u32> = rays.iter().map(|r| b8.intersect::<Moller>(r).unwrap().prim).collect();
/// let mut hits = [None; 4];
/// wide::intersect_batch_incoherent_filtered::<Moller, _, 8, _>(b8.view(), &rays, &mut hits, |h: &BatchHit| {
///     h.hit.prim != front[h.ray]
/// });
/// for (i, h) in hits.iter().enumerate() {
///     let own = |x: &Hit| x.prim != front[i];
///     assert_eq!(*h, wide::intersect_filtered::<Moller, _, 8, _>(b8.view(), &rays[i], own));
///     assert!(h.unwrap().prim != front[i]); // never the skipped one
/// }
/// ```
pub fn intersect_batch_incoherent_filtered<T: TriangleTest, L: Lane, const N: usize, F: HitFilter<BatchHit>>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    mut filter: F,
) {
    let start = |i: usize| {
        let r = prepare::<T>(&rays[i]);
        let mut w = ClosestWalk::<STACK>::new(bvh, 0);
        // An empty ray's walk starts done, with no hit (as `intersect`).
        w.done = r.is_empty() || bvh.nodes.is_empty();
        (i, r, w)
    };
    let n = rays.len().min(hits.len());
    interleave2(
        0..n,
        start,
        |(i, r, w)| {
            let mut f = InBatch {
                f: &mut filter,
                ray: *i,
            };
            w.step::<T, L, N, _>(bvh, r, &mut f)
        },
        |(_, _, w)| w.done.then_some(w.best),
        |i, h| hits[i] = h,
    );
}

/// A hit of a batch's ray: the hit and the index of its ray in the batch (what the filters of
/// [`intersect_batch_incoherent_filtered`] and [`occluded_batch_incoherent_filtered`] see).
///
/// ```
/// use strahl::{Hit, traverse::BatchHit};
/// let h = BatchHit { ray: 3, hit: Hit { t: 1.0, u: 0.25, v: 0.5, prim: 7 } };
/// assert_eq!((h.ray, h.hit.prim), (3, 7));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatchHit {
    /// Index of the ray in the batch.
    pub ray: usize,
    /// The hit.
    pub hit: Hit,
}

/// A filter over [`BatchHit`]s seen as one over the [`Hit`]s of ray `ray`.
struct InBatch<'a, F> {
    f: &'a mut F,
    ray: usize,
}

impl<F: HitFilter<BatchHit>> HitFilter for InBatch<'_, F> {
    const ACCEPTS_ALL: bool = F::ACCEPTS_ALL;
    #[inline(always)]
    fn accept(&mut self, hit: &Hit) -> bool {
        self.f.accept(&BatchHit {
            ray: self.ray,
            hit: *hit,
        })
    }
}

/// [`intersect_batch_incoherent`] in the order `order`: for each entry `i` of `order`, `hits[i]`
/// for `rays[i]` (entries past the shorter of `rays` and `hits` are skipped; slots `order` does
/// not name keep their value). With an order from `traverse::order::RayOrder` (`alloc`), rays
/// whose origins lie close together run one after another and find each other's nodes in the
/// cache; the hits are those of one call per ray.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..5)
///     .map(|i| Ray::new(Vec3::new(-3.0, 0.6 * i as f32 - 1.2, 0.1), Vec3::X))
///     .collect();
/// let mut hits = [None; 5];
/// wide::intersect_batch_ordered::<Moller, _, 8>(b8.view(), &rays, &[4, 0, 2, 1, 3], &mut hits);
/// for (r, h) in rays.iter().zip(hits) {
///     assert_eq!(h, wide::intersect::<Moller, _, 8>(b8.view(), r));
/// }
/// ```
pub fn intersect_batch_ordered<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    order: &[u32],
    hits: &mut [Option<Hit>],
) {
    // PERF: one walk at a time, not two interleaved: rays in this order share their nodes, and
    // interleaving them measured up to 1.2x slower (bunny, 1M sphereflake; 262k rays).
    gather_ordered(rays, order, hits.len(), |chunk, slots| {
        for (r, &i) in chunk.iter().zip(slots) {
            hits[i as usize] = intersect::<T, L, N>(bvh, r);
        }
    });
}

/// How [`intersect_batch`] and [`occluded_batch`] trace a group of up to 8 consecutive rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Group {
    /// The same direction signs and origins close together (a camera tile, shadow rays from a
    /// tile's hits to a light): one packet of 8 ([`packet`](super::packet), interval culling).
    Packet,
    /// Origins apart (diffuse bounces and shadow rays from scattered points): the whole run of
    /// such groups as [`intersect_batch_incoherent`] (walks two at a time, interleaved) or
    /// [`occluded_batch_incoherent`] (one walk at a time).
    Scattered,
    /// Origins close together but directions apart (ambient occlusion from one point): one ray
    /// at a time, each finding the nodes the last one left in the cache.
    Single,
}

/// The largest extent of the tree's root box (its child boxes; empty slots have empty boxes):
/// the scale of [`Group`]'s origin test and of the packets' coherence test; 0 for an empty tree.
#[inline]
pub(crate) fn root_extent<L: Lane, const N: usize>(bvh: BvhWideRef<'_, L, N>) -> f32 {
    let Some(root) = bvh.nodes.first() else {
        return 0.0;
    };
    let b = root.bounds.union();
    (b.max - b.min).max_element().max(0.0)
}

/// The path for `rays` (1 to 8 of them): origins within
/// [`COHERENT_MAX_ORIGIN_SPREAD`](super::packet::COHERENT_MAX_ORIGIN_SPREAD) of `extent` on
/// every axis count as close together (the packets' own test); packets only for the
/// conservative box test (they trace boxes conservatively whatever `T` asks for, and a batch
/// answers exactly as one call per ray). Only speed depends on the answer (NaN origins do not
/// count in the spread).
#[inline(always)]
pub(crate) fn group<T: TriangleTest>(rays: &[Ray], extent: f32) -> Group {
    let first = rays[0];
    let signs = first.direction.is_negative_bitmask();
    let (mut lo, mut hi, mut same) = (first.origin, first.origin, true);
    for r in &rays[1..] {
        lo = lo.min(r.origin);
        hi = hi.max(r.origin);
        same &= r.direction.is_negative_bitmask() == signs;
    }
    let spread = (hi - lo).max_element();
    if spread > extent * super::packet::COHERENT_MAX_ORIGIN_SPREAD {
        Group::Scattered
    } else if same && T::CONSERVATIVE_BOXES {
        Group::Packet
    } else {
        Group::Single
    }
}

/// Runs a batch group by group ([`Group`]): `packet(rays, out)` on a packet's 8 rays,
/// `single(ray)` one by one, `scattered(rays, out)` on each maximal run of scattered groups.
#[inline(always)]
pub(crate) fn by_groups<T: TriangleTest, O>(
    rays: &[Ray],
    out: &mut [O],
    extent: f32,
    mut packet: impl FnMut(&[Ray], &mut [O]),
    mut single: impl FnMut(&Ray) -> O,
    mut scattered: impl FnMut(&[Ray], &mut [O]),
) {
    let n = rays.len().min(out.len());
    let (mut run, mut at) = (0, 0);
    while at < n {
        let end = (at + 8).min(n);
        let g = group::<T>(&rays[at..end], extent);
        if g != Group::Scattered {
            if run < at {
                scattered(&rays[run..at], &mut out[run..at]);
            }
            if g == Group::Packet {
                packet(&rays[at..end], &mut out[at..end]);
            } else {
                for (o, r) in out[at..end].iter_mut().zip(&rays[at..end]) {
                    *o = single(r);
                }
            }
            run = end;
        }
        at = end;
    }
    if run < n {
        scattered(&rays[run..n], &mut out[run..n]);
    }
}

/// Closest hits of a batch of rays, any mix of coherent and incoherent ones: `hits[i]` for
/// `rays[i]` (the shorter length wins), the hits of one [`intersect`] per ray: the same `t`, and
/// the same primitive unless two triangles tie there (a packet visits nodes in another order, so
/// of two triangles hit at the same `t` it may report the other one, as
/// [`packet`](super::packet) documents). Each group of 8 consecutive rays takes the path that
/// suits it, decided from the rays alone:
///
/// - the same direction signs and origins close together (a camera tile: lay camera rays out
///   with [`TileShape`](super::packet::TileShape), or 8 along a scanline): one packet
///   ([`packet::intersect8`](super::packet::intersect8), interval culling, the default hybrid
///   switch);
/// - origins apart (diffuse bounces from scattered points): the run of such groups as
///   [`intersect_batch_incoherent`] (two walks interleaved);
/// - origins close together, directions apart (ambient occlusion from one point): one
///   [`intersect`] per ray.
///
/// Packets are used only with the conservative box test (not for [`Fast`](super::Fast) types),
/// so that every path answers alike. The checks cost a few comparisons per ray.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// // 16 parallel rays (two packets), then 8 from scattered points, then 8 from one point.
/// let mut rays: Vec<Ray> = (0..16).map(|i| Ray::new(Vec3::new(0.01 * i as f32, 0.02, -3.0), Vec3::Z)).collect();
/// rays.extend((0..8).map(|i| Ray::new(Vec3::new(0.8 - 0.2 * i as f32, 0.0, 0.0), Vec3::new(0.3, 1.0, 0.1))));
/// rays.extend((0..8).map(|i| Ray::new(Vec3::ZERO, Vec3::new(i as f32 - 3.5, 1.0, (i % 3) as f32 - 1.0))));
/// let mut hits = vec![None; rays.len()];
/// wide::intersect_batch::<Moller, _, 8>(b8.view(), &rays, &mut hits);
/// for (r, h) in rays.iter().zip(&hits) {
///     assert_eq!(*h, wide::intersect::<Moller, _, 8>(b8.view(), r));
/// }
/// assert!(hits.iter().all(Option::is_some));
/// ```
pub fn intersect_batch<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
) {
    by_groups::<T, _>(
        rays,
        hits,
        root_extent(bvh),
        |r, h| super::packet::intersect_packet::<T, L, N, f32x8, 8>(bvh, r, h, super::packet::DEFAULT_SWITCH),
        |r| intersect::<T, L, N>(bvh, r),
        |r, h| intersect_batch_incoherent::<T, L, N>(bvh, r, h),
    );
}

/// Any-hit answers of a batch of rays, any mix of coherent and incoherent ones: `occluded[i]` for
/// `rays[i]`, the same answers as one [`occluded`] per ray. Groups of 8 take the paths of
/// [`intersect_batch`]: packets ([`packet::occluded8`](super::packet::occluded8)), one ray at a
/// time, also for runs of rays from scattered origins ([`occluded_batch_incoherent`], which says
/// why neither interleaved walks nor [ray streams](occluded_batch_stream) are used).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// // Shadow rays towards a light at (0, 0, 5): 8 from a small patch below the sphere, 8 from
/// // points scattered around it.
/// let light = Vec3::new(0.0, 0.0, 5.0);
/// let patch = (0..8).map(|i| Vec3::new(0.001 * i as f32, 0.0, -2.0));
/// let scattered = (0..8).map(|i| Vec3::new(2.0 - 0.5 * i as f32, 1.5, -0.5 * (i % 2) as f32));
/// let rays: Vec<Ray> = patch.chain(scattered).map(|p| Ray::with_range(p, light - p, 0.0, 1.0)).collect();
/// let mut out = vec![false; rays.len()];
/// wide::occluded_batch::<Watertight, _, 8>(b8.view(), &rays, &mut out);
/// for (r, &o) in rays.iter().zip(&out) {
///     assert_eq!(o, wide::occluded::<Watertight, _, 8>(b8.view(), r));
/// }
/// assert!(out[..8].iter().all(|&o| o)); // the patch lies in the sphere's shadow
/// ```
pub fn occluded_batch<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
) {
    by_groups::<T, _>(
        rays,
        occluded,
        root_extent(bvh),
        |r, o| super::packet::occluded_packet::<T, L, N, f32x8, 8>(bvh, r, o, super::packet::DEFAULT_SWITCH),
        |r| self::occluded::<T, L, N>(bvh, r),
        |r, o| occluded_batch_incoherent::<T, L, N>(bvh, r, o),
    );
}

/// `true` if `ray` hits any triangle of the wide BVH `bvh` within `[tmin, tmax)`; stops at the
/// first hit found.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, traverse::{Moller, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// let d = Vec3::new(0.3, -0.5, 1.0);
/// assert!(wide::occluded::<Moller, _, 4>(b4.view(), &Ray::new(Vec3::ZERO, d))); // from inside the sphere
/// // A shadow ray to a light inside the sphere is not blocked.
/// assert!(!wide::occluded::<Moller, _, 4>(b4.view(), &Ray::with_range(Vec3::ZERO, d, 0.0, 0.5)));
/// ```
#[inline]
pub fn occluded<T: TriangleTest, L: Lane, const N: usize>(bvh: BvhWideRef<'_, L, N>, ray: &Ray) -> bool {
    let r = prepare::<T>(ray);
    occluded_prepared::<T, L, N>(bvh, &r)
}

/// [`occluded`] for an already prepared ray.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, intersect::PreparedRay, layout::Bvh8};
/// use strahl::traverse::{Watertight, wide};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let mut r = PreparedRay::new(&Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z));
/// assert!(wide::occluded_prepared::<Watertight, _, 8>(b8.view(), &r));
/// r.tmax = 1.5; // the sphere starts at about t = 2
/// assert!(!wide::occluded_prepared::<Watertight, _, 8>(b8.view(), &r));
/// ```
#[inline]
pub fn occluded_prepared<T: TriangleTest, L: Lane, const N: usize>(bvh: BvhWideRef<'_, L, N>, r: &PreparedRay) -> bool {
    // Children are visited in slot order, not near to far (as Embree's any-hit traversal does):
    // a shadow ray starts at a surface, and the nearest child is mostly the geometry around its
    // origin, which it leaves without a hit. Measured on shadow rays to random points (BVH8,
    // 262k rays, best of 5): 1.3x faster on the 1M sphereflake, the same on the bunny. The
    // collapse puts a node's children in decreasing surface area, so slot order tries the
    // children a random ray most likely hits first (another 1.15x on the sphereflake).
    // Nearest child first, the rest in slot order, measured 6% faster on the bunny (in cache)
    // but 1.45x slower on the sphereflake: not kept.
    occluded_prepared_filtered::<T, L, N, _>(bvh, r, &mut AcceptAll)
}

/// [`occluded_prepared`] counting only the hits `f` accepts (the instances' BLAS walks).
#[inline]
pub(crate) fn occluded_prepared_filtered<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    r: &PreparedRay,
    f: &mut F,
) -> bool {
    occluded_from_filtered::<T, L, N, F>(bvh, 0, r, f)
}

/// The any-hit walk from child code `start` (`0`: the whole tree) counting the hits `f` accepts;
/// an empty ray, or an empty tree walked from its root, answers `false`. The packets' single rays,
/// which leave the packet below the root, walk this way (with the packets' conservative `T`, so
/// the box test is theirs).
#[inline]
pub(crate) fn occluded_from_filtered<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    start: u32,
    r: &PreparedRay,
    f: &mut F,
) -> bool {
    if r.is_empty() || (start == 0 && bvh.nodes.is_empty()) {
        return false;
    }
    any_hit_walk::<STACK, T, L, N, F>(bvh, start, r, f)
}

/// One ray's whole any-hit walk in one loop, its state in locals (registers); every any-hit path
/// of the wide BVHs but the ray streams walks this way.
// PERF: against the same visits as a walk object stepped to its end (its state in memory, the
// form two interleaved walks needed; BVH8, 131,072 shadow rays; Intel Xeon; the two builds run
// alternately, each run's best of 4, the best of 6 runs): 1.01-1.05x on the 1M sphereflake,
// 1.00-1.06x on the bunny (two such comparisons; the machine's noise is about 5%).
// The same loop for closest hits, also with the nearest child visited without the stack,
// measured 0.97-1.02x on primary and diffuse rays: not kept.
#[inline(always)]
fn any_hit_walk<const S: usize, T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    start: u32,
    r: &PreparedRay,
    f: &mut F,
) -> bool {
    let mut stack = CodeStack::<S>::new();
    let mut cur = start;
    let mut budget = bvh.nodes.len();
    loop {
        cur = match any_hit_visit::<S, T, L, N, F>(bvh, r, f, cur, &mut stack, &mut budget) {
            AnyHitNext::Visit(code) => code,
            AnyHitNext::Answer(hit) => return hit,
            AnyHitNext::Pop => match stack.pop() {
                None => return false,
                Some(code) => code,
            },
        }
    }
}

/// What an any-hit walk does after visiting a node or leaf ([`any_hit_visit`]).
enum AnyHitNext {
    /// Visit this child next.
    Visit(u32),
    /// Take the next entry from the stack.
    Pop,
    /// The walk has ended with this answer.
    Answer(bool),
}

/// Visits node or leaf `cur` of an any-hit walk. Of a node's hit children the lowest slot is
/// visited next and the others pushed, the highest first (so popped in slot order; see
/// [`occluded_prepared`] for why). Past a budget of `nodes.len()` node visits (a cycle, a node
/// with two parents), or where the children would not fit on the stack (a view deeper than
/// [`MAX_WIDE_DEPTH`]), the answer is every pack's, exact for any view.
#[inline(always)]
fn any_hit_visit<const S: usize, T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    r: &PreparedRay,
    f: &mut F,
    cur: u32,
    stack: &mut CodeStack<S>,
    budget: &mut usize,
) -> AnyHitNext {
    // The answer for views that cannot be walked: every pack's.
    let scan = |f: &mut F| AnyHitNext::Answer(bvh.packs.iter().any(|p| any_in_pack::<T, L, N, F>(r, p, f)));
    if cur & LEAF_BIT == 0 {
        if *budget == 0 {
            return scan(f);
        }
        *budget -= 1;
        if let Some(node) = bvh.nodes.get(cur as usize) {
            let (_, mut mask) = node_lanes::<T, L>(r, &node.bounds);
            if mask != 0 {
                let next = node.child[mask.trailing_zeros() as usize % N];
                mask &= mask - 1;
                if mask != 0 {
                    // Room for all of them, the next one too (as the stack's bound assumes).
                    if mask.count_ones() as usize >= stack.room() {
                        return scan(f);
                    }
                    prefetch(bvh, next);
                    while mask != 0 {
                        let i = 31 - mask.leading_zeros() as usize;
                        mask &= !(1 << i);
                        prefetch(bvh, node.child[i % N]);
                        stack.push(node.child[i % N]);
                    }
                }
                return AnyHitNext::Visit(next);
            }
        }
    } else if cur != EMPTY_CHILD {
        let (first, count) = leaf_packs(cur);
        if let Some(packs) = bvh.packs.get(first..first + count)
            && packs.iter().any(|p| any_in_pack::<T, L, N, F>(r, p, f))
        {
            return AnyHitNext::Answer(true);
        }
    }
    AnyHitNext::Pop
}

/// Rays in one any-hit stream ([`occluded_stream`]): one bit each in a `u64` mask.
const STREAM: usize = 64;

/// Any-hit answers of up to [`STREAM`] prepared rays that walk the tree together (a ray stream,
/// as in Fuetterling et al., "Efficient ray tracing kernels for modern CPU architectures", 2015,
/// and Embree's `rtcOccluded1M`): each stack entry carries the mask of the rays that entered it,
/// a node is loaded once for all of them and tested against each with the single-ray slab test,
/// and a leaf's packs are tested with each of its rays' single-ray kernels. Rays retire when
/// blocked; the walk stops when all are. Bit `i` of the answer for `rays[i]`.
///
/// Every ray's box and triangle tests are its single-ray walk's ([`node_lanes`], `any_in_pack`),
/// and an any-hit answer does not depend on the visiting order, so each answer equals
/// [`occluded_prepared`]'s wherever that walk runs to its end. It runs to its end unless it
/// exceeds its budget of `nodes.len()` node visits or its stack, and the stream visits every
/// (node, ray) pair that walk would: so the stream stops and answers every ray with
/// [`occluded_prepared`] itself where it exceeds the same budget (a cycle, a node with two
/// parents) or visits a node deeper than [`MAX_WIDE_DEPTH`] (below that depth the single walk's
/// stack cannot overflow: at most 7 entries per level above and 8 at the node). A valid tree does
/// neither.
fn occluded_stream<T: TriangleTest, L: Lane, const N: usize>(bvh: BvhWideRef<'_, L, N>, rays: &[PreparedRay]) -> u64 {
    let rays = &rays[..rays.len().min(STREAM)];
    let mut open = 0u64;
    for (i, r) in rays.iter().enumerate() {
        open |= ((!r.is_empty()) as u64) << i;
    }
    if open == 0 || bvh.nodes.is_empty() {
        return 0;
    }
    let mut blocked = 0u64;
    // Entries: child code, the rays that entered it, its depth (the root's is 1).
    let (mut codes, mut masks, mut depths) = ([0u32; STACK], [0u64; STACK], [0u8; STACK]);
    let (mut len, mut budget) = (0usize, bvh.nodes.len());
    let (mut cur, mut mask, mut depth) = (0u32, open, 1u32);
    'walk: loop {
        mask &= !blocked;
        if mask != 0 {
            if cur & LEAF_BIT == 0 {
                if budget == 0 || depth > MAX_WIDE_DEPTH {
                    break 'walk;
                }
                budget -= 1;
                if let Some(node) = bvh.nodes.get(cur as usize) {
                    // Which rays enter each child: bit `i` of `enter[c]` for ray `i`.
                    let mut enter = [0u64; N];
                    let mut m = mask;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let (_, hit) = node_lanes::<T, L>(&rays[i], &node.bounds);
                        for (c, e) in enter.iter_mut().enumerate() {
                            *e |= ((hit >> c) as u64 & 1) << i;
                        }
                    }
                    // Slot order, as the single-ray any-hit walk: the highest slot pushed first.
                    let mut next = None;
                    for c in (0..N).rev() {
                        if enter[c] == 0 || node.child[c] == EMPTY_CHILD {
                            continue;
                        }
                        if let Some((code, m)) = next.replace((node.child[c], enter[c])) {
                            if len == STACK {
                                break 'walk;
                            }
                            (codes[len], masks[len], depths[len]) = (code, m, (depth + 1) as u8);
                            len += 1;
                        }
                    }
                    if let Some((code, m)) = next {
                        (cur, mask, depth) = (code, m, depth + 1);
                        continue;
                    }
                }
            } else if cur != EMPTY_CHILD {
                let (first, count) = leaf_packs(cur);
                if let Some(packs) = bvh.packs.get(first..first + count) {
                    let mut m = mask;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        if packs
                            .iter()
                            .any(|p| any_in_pack::<T, L, N, _>(&rays[i], p, &mut AcceptAll))
                        {
                            blocked |= 1 << i;
                        }
                    }
                    if blocked == open {
                        return blocked;
                    }
                }
            }
        }
        if len == 0 {
            return blocked;
        }
        len -= 1;
        (cur, mask, depth) = (codes[len], masks[len], depths[len] as u32);
    }
    // Past the budget, the depth or the stack (a malformed view): every ray's own walk answers.
    let mut m = open;
    blocked = 0;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if occluded_prepared::<T, L, N>(bvh, &rays[i]) {
            blocked |= 1 << i;
        }
    }
    blocked
}

/// [`occluded`] for every ray of a batch, 64 rays at a time walking the tree together: `out[i]`
/// for `rays[i]` (the shorter length wins), the same answers as one call per ray.
///
/// A ray stream (Fuetterling et al., "Efficient ray tracing kernels for modern CPU
/// architectures", 2015; Embree's `rtcOccluded1M`): each stack entry carries the mask of the
/// rays that entered it, so a node is loaded once for all of them and tested against each with
/// its single-ray slab test; a leaf's packs are tested with each entering ray's single-ray
/// kernel; rays retire when blocked. Whether it pays depends on the processor, so
/// [`occluded_batch`] does not pick it: shadow rays from scattered points (`tests/stream_speed.rs`)
/// ran 1.09-1.16x as fast as one call per ray through BVH8s of 0.2 MB on an Intel Xeon (2 MB of
/// L2 per core; 0.99-1.02x at 0.8-2 MB), but took 1.19-1.35x as long through BVH8s of 0.2 to
/// 2 MB on an AMD EPYC of the first Zen generation, and longer on both on trees larger than the
/// cache. Measure it on yours.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..100)
///     .map(|i| Ray::new(Vec3::new(-3.0, 0.03 * i as f32 - 1.5, 0.1), Vec3::X))
///     .collect();
/// let mut out = vec![false; rays.len()];
/// wide::occluded_batch_stream::<Moller, _, 8>(b8.view(), &rays, &mut out);
/// for (r, o) in rays.iter().zip(&out) {
///     assert_eq!(*o, wide::occluded::<Moller, _, 8>(b8.view(), r));
/// }
/// assert!(out[50] && !out[0]);
/// ```
pub fn occluded_batch_stream<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    out: &mut [bool],
) {
    let n = rays.len().min(out.len());
    let mut prepared = [PreparedRay::EMPTY; STREAM];
    for (r, o) in rays[..n].chunks(STREAM).zip(out[..n].chunks_mut(STREAM)) {
        for (p, ray) in prepared.iter_mut().zip(r) {
            *p = prepare::<T>(ray);
        }
        let blocked = occluded_stream::<T, L, N>(bvh, &prepared[..r.len()]);
        for (i, o) in o.iter_mut().enumerate() {
            *o = blocked >> i & 1 == 1;
        }
    }
}

/// [`occluded`] for every ray of a batch of incoherent rays (ambient occlusion, shadow rays to
/// scattered points): `out[i]` for `rays[i]` (the shorter length wins), the same answers as one
/// call per ray.
///
/// One walk at a time, each [`occluded`]'s. Unlike closest-hit walks
/// ([`intersect_batch_incoherent`]), any-hit walks are not interleaved: since the single walk
/// keeps its state in registers, two interleaved walks (state in memory) took longer on every
/// tree measured on an AMD EPYC (Zen 1) and in the Xeon's bench of one form against the other;
/// the Xeon's batch through the 70 MB sphereflake measured 0.97x and 1.07x one call per ray in
/// two runs (within its noise).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..5)
///     .map(|i| Ray::new(Vec3::new(-3.0, 0.6 * i as f32 - 1.2, 0.1), Vec3::X))
///     .collect();
/// let mut out = [false; 5];
/// wide::occluded_batch_incoherent::<Moller, _, 8>(b8.view(), &rays, &mut out);
/// for (r, o) in rays.iter().zip(out) {
///     assert_eq!(o, wide::occluded::<Moller, _, 8>(b8.view(), r));
/// }
/// assert_eq!(out, [false, true, true, true, false]);
/// ```
// PERF: two walks interleaved measured 1.12x (bunny) and 1.18x (1M sphereflake) faster than one
// call per ray on shadow rays (Intel Xeon, 2026-12-04), but after the single walk kept its state
// in registers (2026-12-06) 0.92x and 0.90x (the trace bench's `bvh8_incoherent` against `bvh8`),
// and on an AMD EPYC (Zen 1; `tests/stream_speed.rs`, 131,072 shadow rays, best of 5) 0.75-0.91x
// on BVH8s of 0.2 to 70 MB; in Morton order (`occluded_batch_ordered`) 0.76x (bunny) and 0.86x
// (1M sphereflake). Three or four walks at a time (in arrays) were slower still (Xeon).
pub fn occluded_batch_incoherent<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    out: &mut [bool],
) {
    occluded_batch_incoherent_filtered::<T, L, N, _>(bvh, rays, out, AcceptAll);
}

/// [`occluded_batch_incoherent`] counting only the hits `filter` accepts ([`HitFilter`] over
/// [`BatchHit`]s): `out[i]` is [`occluded_filtered`] of `rays[i]` with the filter
/// `|h: &Hit| filter(&BatchHit { ray: i, hit: *h })`.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{BatchHit, Moller, wide}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays = [Ray::new(Vec3::ZERO, Vec3::X); 4]; // from inside the sphere
/// let mut out = [false; 4];
/// // Odd rays see every triangle, even rays none (say, a light-linking mask per ray).
/// wide::occluded_batch_incoherent_filtered::<Moller, _, 8, _>(b8.view(), &rays, &mut out, |h: &BatchHit| h.ray % 2 == 1);
/// assert_eq!(out, [false, true, false, true]);
/// ```
pub fn occluded_batch_incoherent_filtered<T: TriangleTest, L: Lane, const N: usize, F: HitFilter<BatchHit>>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    out: &mut [bool],
    mut filter: F,
) {
    let n = rays.len().min(out.len());
    for (i, (o, ray)) in out[..n].iter_mut().zip(&rays[..n]).enumerate() {
        let mut f = InBatch { f: &mut filter, ray: i };
        *o = occluded_from_filtered::<T, L, N, _>(bvh, 0, &prepare::<T>(ray), &mut f);
    }
}

/// [`occluded_batch_incoherent`] in the order `order`: for each entry `i` of `order`, `out[i]`
/// for `rays[i]` (entries past the shorter of `rays` and `out` are skipped; slots `order` does not
/// name keep their value). See [`intersect_batch_ordered`].
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8};
/// use strahl::traverse::{Moller, order::RayOrder, wide};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..5)
///     .map(|i| Ray::new(Vec3::new(-3.0, 0.6 * i as f32 - 1.2, 0.1), Vec3::X))
///     .collect();
/// let mut order = RayOrder::new();
/// let mut out = [false; 5];
/// wide::occluded_batch_ordered::<Moller, _, 8>(b8.view(), &rays, order.compute(&rays), &mut out);
/// assert_eq!(out, [false, true, true, true, false]);
/// ```
pub fn occluded_batch_ordered<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    order: &[u32],
    out: &mut [bool],
) {
    // One walk at a time, as `intersect_batch_ordered` (see `occluded_batch_incoherent`).
    gather_ordered(rays, order, out.len(), |chunk, slots| {
        for (r, &i) in chunk.iter().zip(slots) {
            out[i as usize] = occluded::<T, L, N>(bvh, r);
        }
    });
}

/// Runs the walks of the items `items` yields, two at a time, interleaved: each turn steps both
/// unfinished walks once; a finished walk's answer goes to `put(i, answer)` and its slot starts
/// the next item. `start(i)` makes item `i`'s walk, `step` advances it, `answer` is `Some` once it
/// has ended.
#[inline(always)]
fn interleave2<S, O>(
    mut items: impl Iterator<Item = usize>,
    start: impl Fn(usize) -> S,
    mut step: impl FnMut(&mut S),
    answer: impl Fn(&S) -> Option<O>,
    mut put: impl FnMut(usize, O),
) {
    let finish = |w: &mut S, step: &mut dyn FnMut(&mut S)| loop {
        match answer(w) {
            Some(x) => return x,
            None => step(w),
        }
    };
    let Some(mut ia) = items.next() else { return };
    let Some(mut ib) = items.next() else {
        put(ia, finish(&mut start(ia), &mut step));
        return;
    };
    let (mut a, mut b) = (start(ia), start(ib));
    loop {
        if answer(&a).is_none() {
            step(&mut a);
        }
        if answer(&b).is_none() {
            step(&mut b);
        }
        if let Some(x) = answer(&a) {
            put(ia, x);
            let Some(next) = items.next() else {
                put(ib, finish(&mut b, &mut step));
                return;
            };
            ia = next;
            a = start(ia);
        }
        if let Some(x) = answer(&b) {
            put(ib, x);
            let Some(next) = items.next() else {
                put(ia, finish(&mut a, &mut step));
                return;
            };
            ib = next;
            b = start(ib);
        }
    }
}

/// Rays an ordered batch copies together at a time (on the call stack: 8 KiB).
const GATHER: usize = 256;

/// Runs an ordered batch: the rays `order` names (entries below `n`), [`GATHER`] at a time
/// copied into a local array in that order, each chunk handed to `chunk(rays, slots)` (`slots[k]`
/// the index of `rays[k]` in the batch). The order jumps about the batch; the walks then read
/// their rays in sequence.
#[inline(always)]
fn gather_ordered(rays: &[Ray], order: &[u32], n: usize, mut chunk: impl FnMut(&[Ray], &[u32])) {
    let mut buf = [Ray::new(glam::Vec3::ZERO, glam::Vec3::ZERO); GATHER];
    let mut slot = [0u32; GATHER];
    let mut todo = order.iter().filter(|&&i| (i as usize) < n.min(rays.len()));
    loop {
        let mut m = 0;
        // NOTE: the buffer first: `zip` pulls from its first iterator before the second, and an
        // entry pulled from `todo` when the buffer is full would be lost.
        for ((b, s), &i) in buf.iter_mut().zip(slot.iter_mut()).zip(&mut todo) {
            *b = rays[i as usize];
            *s = i;
            m += 1;
        }
        if m == 0 {
            return;
        }
        chunk(&buf[..m], &slot[..m]);
    }
}

/// `true` if `r` hits a triangle of `pack` that `f` accepts.
#[inline(always)]
pub(crate) fn any_in_pack<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    r: &PreparedRay,
    pack: &TriangleLanes<L, N>,
    f: &mut F,
) -> bool {
    if F::ACCEPTS_ALL {
        T::hit_mask_lanes(r, pack) != 0
    } else {
        // The closest-hit test at once (not the mask first): a pack with a hit is tested once.
        closest_in_pack::<T, L, N, F>(r, pack, f).is_some()
    }
}

/// The closest hit over every pack: the exact answer for any tree, used only when a malformed or
/// too deep view cannot be traversed.
#[cold]
fn scan_closest<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    r: &mut PreparedRay,
    f: &mut F,
) -> Option<Hit> {
    let mut best = None;
    for p in bvh.packs {
        if let Some(h) = closest_in_pack::<T, L, N, F>(r, p, f) {
            r.tmax = h.t;
            best = Some(h);
        }
    }
    best
}

#[cfg(feature = "alloc")]
impl<L: Lane, const N: usize> crate::layout::BvhWide<L, N> {
    /// Closest hit of `ray` ([`intersect`]).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -4.0), Vec3::Z);
    /// let hit = b8.intersect::<Watertight>(&ray).unwrap();
    /// assert!(hit.t > 3.0 && hit.t < 3.1); // the unit sphere's near side, just inside z = -1
    /// assert_eq!(Some(hit), b2.intersect::<Watertight, _>(&tris[..], &ray));
    /// ```
    #[inline]
    pub fn intersect<T: TriangleTest>(&self, ray: &Ray) -> Option<Hit> {
        intersect::<T, L, N>(self.view(), ray)
    }

    /// Any hit of `ray` ([`occluded`]).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let d = Vec3::new(1.0, 0.2, 0.1);
    /// assert!(b8.occluded::<Watertight>(&Ray::new(Vec3::ZERO, d))); // from the centre, the sphere is in the way
    /// assert!(!b8.occluded::<Watertight>(&Ray::new(Vec3::new(2.0, 0.0, 0.0), d))); // outside, facing away
    /// ```
    #[inline]
    pub fn occluded<T: TriangleTest>(&self, ray: &Ray) -> bool {
        occluded::<T, L, N>(self.view(), ray)
    }

    /// Closest hit of `ray` that `filter` accepts ([`intersect_filtered`], [`HitFilter`]).
    ///
    /// ```
    /// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -4.0), Vec3::Z);
    /// // An alpha test: triangles are cut out where their barycentric u is below 0.5.
    /// let alpha = |h: &Hit| h.u >= 0.5;
    /// let hit = b8.intersect_filtered::<Watertight>(&ray, alpha);
    /// assert_eq!(hit, b2.intersect_filtered::<Watertight, _>(&tris[..], &ray, alpha));
    /// assert!(hit.is_none_or(|h| h.u >= 0.5));
    /// ```
    #[inline]
    pub fn intersect_filtered<T: TriangleTest>(&self, ray: &Ray, filter: impl HitFilter) -> Option<Hit> {
        intersect_filtered::<T, L, N, _>(self.view(), ray, filter)
    }

    /// Whether `ray` hits a triangle that `filter` accepts ([`occluded_filtered`], [`HitFilter`]).
    ///
    /// ```
    /// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let ray = Ray::new(Vec3::ZERO, Vec3::new(1.0, 0.2, 0.1)); // from the centre
    /// assert!(b8.occluded_filtered::<Watertight>(&ray, |_: &Hit| true));
    /// assert!(!b8.occluded_filtered::<Watertight>(&ray, |_: &Hit| false));
    /// ```
    #[inline]
    pub fn occluded_filtered<T: TriangleTest>(&self, ray: &Ray, filter: impl HitFilter) -> bool {
        occluded_filtered::<T, L, N, _>(self.view(), ray, filter)
    }

    /// Closest hits of a batch: `hits[i]` for `rays[i]` (the shorter length wins), those of one
    /// [`intersect`](Self::intersect) per ray (of two triangles tied at a hit, possibly the
    /// other); groups of 8 coherent rays as packets, scattered rays as two walks interleaved
    /// ([`intersect_batch`]).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let rays: Vec<Ray> = (0..5).map(|i| Ray::new(Vec3::new(0.4 * i as f32 - 0.6, 0.1, -3.0), Vec3::Z)).collect();
    /// let mut hits = [None; 5];
    /// b8.intersect_batch::<Watertight>(&rays, &mut hits);
    /// assert!(rays.iter().zip(hits).all(|(r, h)| h == b8.intersect::<Watertight>(r)));
    /// assert_eq!(hits.map(|h| h.is_some()), [true, true, true, true, false]); // x = 1.0 passes beside
    /// ```
    pub fn intersect_batch<T: TriangleTest>(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        intersect_batch::<T, L, N>(self.view(), rays, hits);
    }

    /// Closest hits of a batch of incoherent rays ([`intersect_batch_incoherent`]).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let dirs = [Vec3::new(1.0, 0.1, 0.0), Vec3::new(0.2, -1.0, 0.3), Vec3::new(1.0, 2.0, 3.0), Vec3::NEG_ONE];
    /// let rays = dirs.map(|d| Ray::new(Vec3::ZERO, d.normalize()));
    /// let mut hits = [None; 4];
    /// b8.intersect_batch_incoherent::<Watertight>(&rays, &mut hits);
    /// for (r, h) in rays.iter().zip(hits) {
    ///     assert_eq!(h, b8.intersect::<Watertight>(r));
    ///     assert!(h.is_some_and(|h| h.t > 0.9 && h.t <= 1.0)); // the unit sphere, from its centre
    /// }
    /// ```
    pub fn intersect_batch_incoherent<T: TriangleTest>(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        intersect_batch_incoherent::<T, L, N>(self.view(), rays, hits);
    }

    /// [`intersect_batch_incoherent`](Self::intersect_batch_incoherent) counting only the hits
    /// `filter` accepts ([`intersect_batch_incoherent_filtered`], [`BatchHit`]).
    ///
    /// ```
    /// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{BatchHit, Watertight}};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let rays: Vec<Ray> = (0..6).map(|i| Ray::new(Vec3::new(0.1 * i as f32, 0.0, -3.0), Vec3::Z)).collect();
    /// let mut hits = [None; 6];
    /// b8.intersect_batch_incoherent_filtered::<Watertight>(&rays, &mut hits, |h: &BatchHit| h.hit.t > 2.5);
    /// assert!(hits.iter().all(|h| h.is_some_and(|h| h.t > 3.5))); // through the front, onto the back
    /// ```
    pub fn intersect_batch_incoherent_filtered<T: TriangleTest>(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        filter: impl HitFilter<BatchHit>,
    ) {
        intersect_batch_incoherent_filtered::<T, L, N, _>(self.view(), rays, hits, filter);
    }

    /// Any-hit answers of a batch: `occluded[i]` for `rays[i]`, the same as one
    /// [`occluded`](Self::occluded) per ray; groups of 8 coherent rays as packets, the others one
    /// at a time ([`occluded_batch`]).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let d = Vec3::new(0.1, 1.0, 0.2);
    /// let rays = [
    ///     Ray::new(Vec3::ZERO, d),
    ///     Ray::new(Vec3::new(0.0, 2.0, 0.0), d),
    ///     Ray::with_range(Vec3::ZERO, d, 0.0, 0.5),
    /// ];
    /// let mut out = [false; 3];
    /// b8.occluded_batch::<Watertight>(&rays, &mut out);
    /// assert_eq!(out, [true, false, false]); // from inside; outside facing away; ending inside
    /// ```
    pub fn occluded_batch<T: TriangleTest>(&self, rays: &[Ray], occluded: &mut [bool]) {
        occluded_batch::<T, L, N>(self.view(), rays, occluded);
    }

    /// Any-hit answers of a batch of incoherent rays ([`occluded_batch_incoherent`]).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// // Shadow rays from points around the sphere towards a light at (0, 0, 5).
    /// let light = Vec3::new(0.0, 0.0, 5.0);
    /// let rays = [Vec3::new(0.0, 0.0, -2.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.1, -0.2, -1.5)]
    ///     .map(|p| Ray::with_range(p, light - p, 0.0, 1.0));
    /// let mut out = [false; 3];
    /// b8.occluded_batch_incoherent::<Watertight>(&rays, &mut out);
    /// assert_eq!(out, [true, false, true]); // the sphere shadows the points behind it
    /// ```
    pub fn occluded_batch_incoherent<T: TriangleTest>(&self, rays: &[Ray], occluded: &mut [bool]) {
        occluded_batch_incoherent::<T, L, N>(self.view(), rays, occluded);
    }

    /// [`occluded_batch_incoherent`](Self::occluded_batch_incoherent) counting only the hits
    /// `filter` accepts ([`occluded_batch_incoherent_filtered`], [`BatchHit`]).
    ///
    /// ```
    /// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{BatchHit, Watertight}};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let rays: Vec<Ray> = (0..6).map(|i| Ray::new(Vec3::ZERO, Vec3::new(1.0, 0.3 * i as f32, 0.2))).collect();
    /// let alpha = |h: &Hit| h.u < 0.4;
    /// let mut out = [false; 6];
    /// b8.occluded_batch_incoherent_filtered::<Watertight>(&rays, &mut out, |h: &BatchHit| alpha(&h.hit));
    /// for (r, o) in rays.iter().zip(out) {
    ///     assert_eq!(o, b8.occluded_filtered::<Watertight>(r, alpha));
    /// }
    /// ```
    pub fn occluded_batch_incoherent_filtered<T: TriangleTest>(
        &self,
        rays: &[Ray],
        occluded: &mut [bool],
        filter: impl HitFilter<BatchHit>,
    ) {
        occluded_batch_incoherent_filtered::<T, L, N, _>(self.view(), rays, occluded, filter);
    }

    /// Closest hits of a batch of incoherent rays, traced in the Morton order of their origins
    /// ([`RayOrder`](super::order::RayOrder), then [`intersect_batch_ordered`]): `hits[i]` for
    /// `rays[i]`, the same hits as one call per ray. For rays from scattered surface points on a
    /// scene larger than the cache; allocates `20 n` bytes of scratch (keep a `RayOrder` and call
    /// [`intersect_batch_ordered`] to reuse it).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let rays: Vec<Ray> = (0..64)
    ///     .map(|i| Ray::new(Vec3::new(0.1 * (i % 8) as f32 - 0.4, 0.1 * (i / 8) as f32 - 0.4, -3.0), Vec3::Z))
    ///     .collect();
    /// let mut hits = vec![None; 64];
    /// b8.intersect_batch_reordered::<Moller>(&rays, &mut hits);
    /// for (r, h) in rays.iter().zip(&hits) {
    ///     assert_eq!(*h, b8.intersect::<Moller>(r));
    /// }
    /// ```
    pub fn intersect_batch_reordered<T: TriangleTest>(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        reordered(
            rays,
            hits,
            |r, o, h| intersect_batch_ordered::<T, L, N>(self.view(), r, o, h),
            |r, h| intersect_batch_incoherent::<T, L, N>(self.view(), r, h),
        );
    }

    /// Any-hit answers of a batch of incoherent rays, traced in the Morton order of their
    /// origins ([`RayOrder`](super::order::RayOrder), then [`occluded_batch_ordered`]):
    /// `occluded[i]` for `rays[i]`. See [`intersect_batch_reordered`](Self::intersect_batch_reordered).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let rays: Vec<Ray> = (0..5)
    ///     .map(|i| Ray::new(Vec3::new(-3.0, 0.6 * i as f32 - 1.2, 0.1), Vec3::X))
    ///     .collect();
    /// let mut out = [false; 5];
    /// b8.occluded_batch_reordered::<Moller>(&rays, &mut out);
    /// assert_eq!(out, [false, true, true, true, false]);
    /// ```
    pub fn occluded_batch_reordered<T: TriangleTest>(&self, rays: &[Ray], occluded: &mut [bool]) {
        reordered(
            rays,
            occluded,
            |r, o, out| occluded_batch_ordered::<T, L, N>(self.view(), r, o, out),
            |r, out| occluded_batch_incoherent::<T, L, N>(self.view(), r, out),
        );
    }

    /// [`intersect_batch`](Self::intersect_batch) on `threads` threads (`std`; at least 1, at
    /// most [`MAX_THREADS`](crate::build::MAX_THREADS)): the batch is cut into chunks of 1024
    /// rays taken from a shared counter.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let rays: Vec<Ray> = (0..3000)
    ///     .map(|i| Ray::new(Vec3::ZERO, Vec3::new((i % 7) as f32 - 3.0, (i % 11) as f32 - 5.0, 1.0)))
    ///     .collect();
    /// let (mut one, mut two) = (vec![None; rays.len()], vec![None; rays.len()]);
    /// b8.intersect_batch::<Watertight>(&rays, &mut one);
    /// b8.intersect_batch_par::<Watertight>(&rays, &mut two, 2);
    /// assert_eq!(one, two);
    /// assert!(one.iter().all(Option::is_some)); // from the centre, every ray leaves through the sphere
    /// ```
    #[cfg(feature = "std")]
    pub fn intersect_batch_par<T: TriangleTest>(&self, rays: &[Ray], hits: &mut [Option<Hit>], threads: usize)
    where
        L: Sync,
    {
        par_chunks(rays, hits, threads, |r, h| self.intersect_batch::<T>(r, h));
    }

    /// [`occluded_batch`](Self::occluded_batch) on `threads` threads (`std`).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let rays: Vec<Ray> = (0..3000)
    ///     .map(|i| Ray::new(Vec3::new((i % 7) as f32 * 0.3 - 0.9, (i % 11) as f32 * 0.3 - 1.5, -3.0), Vec3::Z))
    ///     .collect();
    /// let mut out = vec![false; rays.len()];
    /// b8.occluded_batch_par::<Watertight>(&rays, &mut out, 2);
    /// assert!(rays.iter().zip(&out).all(|(r, &o)| o == b8.occluded::<Watertight>(r)));
    /// assert!(out.contains(&true) && out.contains(&false));
    /// ```
    #[cfg(feature = "std")]
    pub fn occluded_batch_par<T: TriangleTest>(&self, rays: &[Ray], occluded: &mut [bool], threads: usize)
    where
        L: Sync,
    {
        par_chunks(rays, occluded, threads, |r, o| self.occluded_batch::<T>(r, o));
    }

    /// [`intersect_batch_reordered`](Self::intersect_batch_reordered) on `threads` threads
    /// (`std`): the order computed once, chunks of 1024 rays in that order traced side by side,
    /// the hits those of one call per ray.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let rays: Vec<Ray> = (0..3000)
    ///     .map(|i| Ray::new(Vec3::new((i % 7) as f32 * 0.1, (i % 11) as f32 * 0.1, -3.0), Vec3::Z))
    ///     .collect();
    /// let mut hits = vec![None; rays.len()];
    /// b8.intersect_batch_reordered_par::<Moller>(&rays, &mut hits, 2);
    /// assert!(rays.iter().zip(&hits).all(|(r, h)| *h == b8.intersect::<Moller>(r)));
    /// ```
    #[cfg(feature = "std")]
    pub fn intersect_batch_reordered_par<T: TriangleTest>(&self, rays: &[Ray], hits: &mut [Option<Hit>], threads: usize)
    where
        L: Sync,
    {
        reordered_par(rays, hits, threads, |r, h| self.intersect_batch::<T>(r, h));
    }

    /// [`occluded_batch_reordered`](Self::occluded_batch_reordered) on `threads` threads (`std`),
    /// as [`intersect_batch_reordered_par`](Self::intersect_batch_reordered_par); each chunk's
    /// walks one at a time.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::Watertight};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// // Shadow rays from scattered points towards a light at (0, 0, 5).
    /// let light = Vec3::new(0.0, 0.0, 5.0);
    /// let rays: Vec<Ray> = (0..3000)
    ///     .map(|i| Vec3::new((i % 13) as f32 * 0.4 - 2.4, (i % 7) as f32 * 0.4 - 1.2, (i % 5) as f32 - 4.0))
    ///     .map(|p| Ray::with_range(p, light - p, 0.0, 1.0))
    ///     .collect();
    /// let (mut one, mut two) = (vec![false; rays.len()], vec![false; rays.len()]);
    /// b8.occluded_batch::<Watertight>(&rays, &mut one);
    /// b8.occluded_batch_reordered_par::<Watertight>(&rays, &mut two, 2);
    /// assert_eq!(one, two);
    /// assert!(one.contains(&true) && one.contains(&false));
    /// ```
    #[cfg(feature = "std")]
    pub fn occluded_batch_reordered_par<T: TriangleTest>(&self, rays: &[Ray], occluded: &mut [bool], threads: usize)
    where
        L: Sync,
    {
        reordered_par(rays, occluded, threads, |r, o| {
            self.occluded_batch_incoherent::<T>(r, o)
        });
    }
}

/// A reordered batch on the calling thread: the order of the rays' origins
/// ([`RayOrder`](super::order::RayOrder)), then `ordered(rays, order, out)`; rays past the
/// `u32::MAX` an order can index go to `rest(rays, out)` in their own order.
#[cfg(feature = "alloc")]
fn reordered<O>(
    rays: &[Ray],
    out: &mut [O],
    ordered: impl Fn(&[Ray], &[u32], &mut [O]),
    rest: impl Fn(&[Ray], &mut [O]),
) {
    let m = rays.len().min(out.len());
    let n = m.min(u32::MAX as usize);
    let mut order = super::order::RayOrder::new();
    ordered(&rays[..n], order.compute(&rays[..n]), out);
    if m > n {
        rest(&rays[n..m], &mut out[n..m]);
    }
}

/// Runs `f` over matching chunks of `input` and `out` (1024 items each) on `threads` threads.
#[cfg(feature = "std")]
pub(crate) fn par_chunks<I: Sync, O: Send, F: Fn(&[I], &mut [O]) + Sync>(
    input: &[I],
    out: &mut [O],
    threads: usize,
    f: F,
) {
    const CHUNK: usize = 1024;
    let n = input.len().min(out.len());
    let jobs: alloc::vec::Vec<_> = input[..n].chunks(CHUNK).zip(out[..n].chunks_mut(CHUNK)).collect();
    crate::par::each_job(jobs, threads.clamp(1, crate::build::MAX_THREADS), |(i, o)| f(i, o));
}

/// A reordered batch on `threads` threads: the order of the rays' origins
/// ([`RayOrder`](super::order::RayOrder)), its chunks traced side by side into answers in that
/// sequence (`trace(rays, answers)` over each chunk's rays, copied together [`GATHER`] at a time),
/// then each answer moved to its ray's slot in `out`.
#[cfg(feature = "std")]
fn reordered_par<O: Copy + Default + Send>(
    rays: &[Ray],
    out: &mut [O],
    threads: usize,
    trace: impl Fn(&[Ray], &mut [O]) + Sync,
) {
    let n = rays.len().min(out.len()).min(u32::MAX as usize);
    let mut order = super::order::RayOrder::new();
    let order = order.compute(&rays[..n]);
    let mut seq = alloc::vec![O::default(); n];
    par_chunks(order, &mut seq, threads, |ord, answers| {
        let mut at = 0;
        gather_ordered(rays, ord, n, |chunk, _| {
            trace(chunk, &mut answers[at..at + chunk.len()]);
            at += chunk.len();
        });
    });
    for (&i, a) in order.iter().zip(seq) {
        out[i as usize] = a;
    }
    if out.len().min(rays.len()) > n {
        let m = out.len().min(rays.len());
        trace(&rays[n..m], &mut out[n..m]);
    }
}

#[cfg(test)]
mod tests {
    use super::{Group, group, occluded_stream};
    use crate::traverse::{Fast, Moller};
    use crate::{Ray, Vec3};

    /// The walk from a child code (the packets' single rays): from the root it is
    /// `occluded_prepared` (an empty tree answers `false` even with packs), from a child it
    /// answers for that subtree alone.
    #[test]
    #[cfg(feature = "alloc")]
    fn walks_from_a_child() {
        use super::{AcceptAll, occluded_from_filtered, occluded_prepared};
        use crate::build::{BuildParams, Bvh2};
        use crate::intersect::PreparedRay;
        use crate::layout::{Bvh8, BvhWideRef, EMPTY_CHILD, LEAF_BIT};
        let tri = |x: f32| {
            [
                Vec3::new(x, -1.0, 2.0),
                Vec3::new(x + 1.0, -1.0, 2.0),
                Vec3::new(x, 1.0, 2.0),
            ]
        };
        let one = Bvh8::from_bvh2(
            &Bvh2::build(&[tri(0.0)][..], &BuildParams::default()).unwrap().0,
            &[tri(0.0)][..],
        )
        .unwrap();
        let r = PreparedRay::new(&Ray::new(Vec3::new(0.2, 0.0, 0.0), Vec3::Z));
        let no_nodes = BvhWideRef {
            nodes: &[],
            packs: one.packs(),
        };
        assert!(!occluded_prepared::<Moller, _, 8>(no_nodes, &r));
        assert!(!occluded_from_filtered::<Moller, _, 8, _>(
            no_nodes,
            0,
            &r,
            &mut AcceptAll
        ));
        assert!(occluded_from_filtered::<Moller, _, 8, _>(
            no_nodes,
            LEAF_BIT,
            &r,
            &mut AcceptAll
        )); // pack 0 itself
        // Two far-apart groups of triangles: the ray hits the first only.
        let tris: alloc::vec::Vec<_> = (0..40)
            .map(|i| tri(if i < 20 { 0.0 } else { 100.0 } + 0.01 * i as f32))
            .collect();
        let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
        assert!(occluded_prepared::<Moller, _, 8>(b8.view(), &r));
        assert!(occluded_from_filtered::<Moller, _, 8, _>(
            b8.view(),
            0,
            &r,
            &mut AcceptAll
        ));
        let kids = b8.nodes()[0].child.iter().filter(|&&c| c != EMPTY_CHILD);
        let from_kids: alloc::vec::Vec<bool> = kids
            .map(|&c| occluded_from_filtered::<Moller, _, 8, _>(b8.view(), c, &r, &mut AcceptAll))
            .collect();
        assert!(
            from_kids.len() >= 2 && from_kids.contains(&true) && from_kids.contains(&false),
            "{from_kids:?}"
        );
    }

    /// Streams answer as single rays: 40 streams of 64 long rays from scattered points through a
    /// soup, some blocked and some not.
    #[test]
    #[cfg(feature = "alloc")]
    fn streams_equal_single_rays() {
        use crate::build::{BuildParams, Bvh2};
        use crate::intersect::PreparedRay;
        use crate::layout::Bvh8;
        use crate::scene::Rng;
        let mut rng = Rng::new(3);
        let tris: alloc::vec::Vec<_> = (0..3000)
            .map(|_| {
                let c = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 10.0;
                [c, c + rng.unit_vector() * 0.6, c + rng.unit_vector() * 0.6]
            })
            .collect();
        let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
        let (mut some, mut all) = (0u64, u64::MAX);
        for _ in 0..40 {
            let rays: alloc::vec::Vec<PreparedRay> = (0..64)
                .map(|_| {
                    let o = Vec3::new(rng.f32(), rng.f32(), 0.0) * 10.0;
                    PreparedRay::new(&Ray::new(o, Vec3::new(rng.f32(), rng.f32(), 1.0) * 10.0 - o))
                })
                .collect();
            let want = rays
                .iter()
                .enumerate()
                .map(|(i, r)| (super::occluded_prepared::<Moller, _, 8>(b8.view(), r) as u64) << i)
                .fold(0, |a, b| a | b);
            (some, all) = (some | want, all & want);
            assert_eq!(occluded_stream::<Moller, _, 8>(b8.view(), &rays), want);
        }
        assert!(some == u64::MAX && all != u64::MAX, "{some:x} {all:x}"); // blocked and open rays
    }

    /// The paths of `intersect_batch` for the kinds of rays its docs name (the answers are
    /// tested in `tests/wide.rs`).
    #[test]
    fn groups_by_kind() {
        let eye = Vec3::new(0.0, 0.0, -5.0);
        let tile: [Ray; 8] = core::array::from_fn(|i| Ray::new(eye, Vec3::new(0.01 * i as f32, 0.02, 1.0)));
        assert_eq!(group::<Moller>(&tile, 2.0), Group::Packet);
        assert_eq!(group::<Moller>(&tile[..1], 2.0), Group::Packet);
        assert_eq!(group::<Fast<Moller>>(&tile, 2.0), Group::Single); // packets test boxes conservatively
        // Origins apart by more than 1/64 of the extent.
        let mut apart = tile;
        apart[5].origin.y += 0.04;
        assert_eq!(group::<Moller>(&apart, 2.0), Group::Scattered);
        apart[5].origin.y -= 0.01; // 0.03 <= 2 / 64
        assert_eq!(group::<Moller>(&apart, 2.0), Group::Packet);
        // One point, directions in different octants; -0.0 counts as negative.
        let mut fan = tile;
        fan[2].direction.x = -0.5;
        assert_eq!(group::<Moller>(&fan, 2.0), Group::Single);
        let mut zero = tile;
        zero[0].direction.x = -0.0;
        assert_eq!(group::<Moller>(&zero, 2.0), Group::Single);
        // A NaN origin does not count in the spread (every path answers alike anyway).
        let mut nan = fan;
        nan[1].origin = Vec3::NAN;
        assert_eq!(group::<Moller>(&nan, 2.0), Group::Single);
        // An empty tree (extent 0): any spread is scattered.
        assert_eq!(group::<Moller>(&apart, 0.0), Group::Scattered);
    }
}
