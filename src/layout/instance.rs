//! Instancing: [`Tlas`] over [`Instance`]s of wide BVHs (the docs are on [`Tlas`]).

use crate::build::{BuildError, BuildParams, Bvh2, usable_box};
use crate::geometry::{Aabb, Hit, Ray};
use crate::intersect::AabbLanes;
use crate::layout::{BvhWide, BvhWideRef, EMPTY_CHILD, LEAF_BIT};
use crate::math::{Lane, f32x4, f32x8};
use crate::traverse::packet::BoxPacket;
use crate::traverse::packet::stack::{Entry, MaskStack};
use crate::traverse::stack::Stack;
use crate::traverse::{
    AcceptAll, Conservative, HitFilter, STACK_SIZE, TriangleTest, beyond, node_lanes, packet, prepare, wide,
};
use alloc::vec;
use alloc::vec::Vec;
use glam::{Affine3A, Vec3};

/// A bottom-level tree a [`Tlas`] can instance: anything that gives a view of a wide BVH. The
/// traversals and builds take `&[impl Blas<L, N>]`, so the BLASes may be owned trees
/// ([`BvhWide`]), views of trees read in place ([`BvhWideRef`], e.g. from a memory map with
/// [`BvhWideRef::from_bytes`]), or references and shared pointers to either (`&B`, `Box<B>`,
/// `Arc<B>`), held wherever the engine keeps them.
///
/// ```
/// use strahl::{Ray, Vec3, build::BuildParams, layout::{Bvh8, Bvh8Ref, Instance, Tlas}, traverse::Moller};
/// use strahl::glam::Affine3A;
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (owned, _) = Bvh8::build(&tris[..], &BuildParams::default()).unwrap();
/// let instances = [Instance::new(Affine3A::from_translation(Vec3::new(0.0, 0.0, 5.0)), 0)];
/// let ray = Ray::new(Vec3::new(0.1, 0.2, 0.0), Vec3::Z);
/// // Owned trees, views, references: the same TLAS, the same hits.
/// let tlas = Tlas::build(&instances, &[&owned]).unwrap();
/// let views: [Bvh8Ref; 1] = [owned.view()];
/// let shared = [std::sync::Arc::new(owned.clone())];
/// let want = tlas.intersect::<Moller, _, 8>(&[&owned], &ray).unwrap();
/// assert_eq!(tlas.intersect::<Moller, _, 8>(&views, &ray), Some(want));
/// assert_eq!(tlas.intersect::<Moller, _, 8>(&shared, &ray), Some(want));
/// assert!((want.hit.t - 4.0).abs() < 0.05);
/// ```
pub trait Blas<L, const N: usize> {
    /// The tree as a view.
    fn blas(&self) -> BvhWideRef<'_, L, N>;
}

impl<L: Lane, const N: usize> Blas<L, N> for BvhWide<L, N> {
    #[inline(always)]
    fn blas(&self) -> BvhWideRef<'_, L, N> {
        self.view()
    }
}

impl<L, const N: usize> Blas<L, N> for BvhWideRef<'_, L, N> {
    #[inline(always)]
    fn blas(&self) -> BvhWideRef<'_, L, N> {
        BvhWideRef {
            nodes: self.nodes,
            packs: self.packs,
        }
    }
}

impl<L, const N: usize, B: Blas<L, N> + ?Sized> Blas<L, N> for &B {
    #[inline(always)]
    fn blas(&self) -> BvhWideRef<'_, L, N> {
        (**self).blas()
    }
}

impl<L, const N: usize, B: Blas<L, N> + ?Sized> Blas<L, N> for alloc::boxed::Box<B> {
    #[inline(always)]
    fn blas(&self) -> BvhWideRef<'_, L, N> {
        (**self).blas()
    }
}

impl<L, const N: usize, B: Blas<L, N> + ?Sized> Blas<L, N> for alloc::sync::Arc<B> {
    #[inline(always)]
    fn blas(&self) -> BvhWideRef<'_, L, N> {
        (**self).blas()
    }
}

/// One placement of a bottom-level tree: its object-to-world transform, which tree (an index
/// into the slice of BLASes given to [`Tlas::build`] and to the traversals) and its visibility
/// mask.
///
/// ```
/// use strahl::{Vec3, layout::Instance};
/// use strahl::glam::Affine3A;
/// let i = Instance::new(Affine3A::from_translation(Vec3::X), 3);
/// assert_eq!((i.blas, i.transform.translation.x, i.mask), (3, 1.0, u32::MAX));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Object space to world space.
    pub transform: Affine3A,
    /// Index of the instance's BLAS.
    pub blas: u32,
    /// Visibility mask: the masked traversals ([`Tlas::intersect_masked`],
    /// [`Tlas::occluded_masked`]) see the instance only where `mask & ray_mask != 0`, as
    /// Embree's geometry masks and DXR's instance masks work. The other traversals trace with a
    /// ray mask of all ones, so an instance of mask `0` is hidden from every ray.
    pub mask: u32,
}

impl Instance {
    /// An instance of BLAS `blas` placed by `transform` (object to world).
    ///
    /// ```
    /// use strahl::layout::Instance;
    /// let i = Instance::new(strahl::glam::Affine3A::IDENTITY, 0);
    /// assert_eq!(i.blas, 0);
    /// ```
    pub const fn new(transform: Affine3A, blas: u32) -> Self {
        Self {
            transform,
            blas,
            mask: u32::MAX,
        }
    }

    /// The instance with visibility mask `mask` (see [`mask`](Self::mask)).
    ///
    /// ```
    /// use strahl::layout::Instance;
    /// // Seen by camera rays (bit 0), not by shadow rays (bit 1).
    /// let i = Instance::new(strahl::glam::Affine3A::IDENTITY, 0).with_mask(0b01);
    /// assert_eq!(i.mask, 1);
    /// ```
    #[must_use]
    pub const fn with_mask(self, mask: u32) -> Self {
        Self { mask, ..self }
    }
}

/// A closest hit through a [`Tlas`]: the hit in the instance's BLAS (`hit.prim` is the BLAS's
/// primitive index; `t`, `u`, `v` as for any hit) and the instance's index.
///
/// ```
/// use strahl::{Hit, layout::InstanceHit};
/// let h = InstanceHit { hit: Hit { t: 2.0, u: 0.25, v: 0.5, prim: 7 }, instance: 3 };
/// assert_eq!((h.instance, h.hit.prim), (3, 7));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstanceHit {
    /// The hit, in the instance's BLAS.
    pub hit: Hit,
    /// Index of the instance in the slice given to [`Tlas::build`].
    pub instance: u32,
}

/// A filter over [`InstanceHit`]s seen as one over the [`Hit`]s of instance `instance`'s BLAS.
struct InInstance<'a, F> {
    f: &'a mut F,
    instance: u32,
}

impl<F: HitFilter<InstanceHit>> HitFilter for InInstance<'_, F> {
    const ACCEPTS_ALL: bool = F::ACCEPTS_ALL;
    #[inline(always)]
    fn accept(&mut self, hit: &Hit) -> bool {
        self.f.accept(&InstanceHit {
            hit: *hit,
            instance: self.instance,
        })
    }
}

/// Instancing: a two-level BVH. Each [`Instance`] places one bottom-level tree (a [`BvhWide`] or
/// anything else that is a [`Blas`], such as a view read in place; the BLAS, built once in its
/// object space) in the world by an affine transform; a [`Tlas`] is a
/// 4-wide BVH over the instances' world boxes. A ray walks the TLAS in world space; at each
/// instance it is taken into object space by the instance's inverse transform and traced through
/// the BLAS with the same wide traversal as any other tree ([`traverse::wide`](crate::traverse::wide)),
/// as Embree's and tinybvh's instances work.
///
/// The object-space ray keeps its parameterisation (`o' = M^-1 o`, `d' = M^-1 d`, not
/// normalised), so a hit's `t` is the same number in both spaces and the closest hit over all
/// instances is the smallest `t`, with `tmax` carried from one instance to the next.
///
/// - **Build** ([`Tlas::build`]): each instance's world box is the union of the BLAS's boxes
///   one level below its root's slots (up to `N * N` boxes; a leaf slot's own box), each through
///   the transform (centre and half extent, `|M| e`, all of a node's lanes at once) and padded
///   by `2^-16` of its size and of the magnitudes the transform sums (`|M| |c| + |t|`), against
///   the rounding of the transform (also where those terms cancel: a part of the BLAS far from
///   its origin placed near the world's origin).
///   Under rotations this is much tighter than the root box through the transform (what Embree
///   and tinybvh place; `tests/instance.rs` checks both that it holds every transformed vertex
///   and that it is smaller); on the bench's instances, turned about y only, the TLAS walks 1-4%
///   faster on the spheres and within the machine's spread on the bunnies.
///   Then a full-sweep SAH BVH2 over those boxes with one instance per leaf
///   ([`BuildParams::quality`]: a TLAS holds few boxes), collapsed greedily (largest child
///   opened first) into 4-wide nodes whose child boxes sit in SoA lanes for the x4 slab test.
/// - **Moving instances** ([`Tlas::refit`]; for the TLAS what Embree's refit build quality does
///   for a geometry's BVH, where Embree itself rebuilds its instance level on a commit): new
///   transforms (and BLAS indices and masks) for the same instances, the world boxes made again
///   and the tree's boxes grown bottom-up in its old shape: 2.0-5.2x faster than a full-sweep
///   rebuild and 1.4-1.9x faster than one by `BuildParams::fast()` (see the README), at a
///   quality that falls the further the instances move; a rebuild restores it.
/// - **Bad input**: an instance whose transform is not finite or not invertible (`|det M|` not
///   a normal float), whose BLAS index is out of range, whose BLAS is empty, or whose world box
///   lies beyond the builders' range (about `±1.7e38`) is left out (never hit) and counted in
///   [`Tlas::left_out`]. Rays follow the crate's policy (NaN, infinite or
///   zero-direction rays hit nothing); an object-space ray that its transform makes invalid (a
///   direction flushed to zero) hits nothing in that instance.
/// - **Masks** ([`Instance::mask`], Embree's geometry masks, DXR's instance masks):
///   [`intersect_masked`](Tlas::intersect_masked) and [`occluded_masked`](Tlas::occluded_masked)
///   take a ray mask and see only the instances with `mask & ray_mask != 0`, for objects hidden
///   from the camera or casting no shadow. Each node slot holds the union (bitwise or) of the
///   masks below it, so a subtree no instance of which the ray can see is not entered (its
///   slot's box is tested with its siblings', none inside it). [`set_mask`](Tlas::set_mask) changes an instance's mask without a rebuild.
/// - **Packets** ([`intersect8`](Tlas::intersect8), [`occluded8`](Tlas::occluded8), and the
///   batch forms for coherent groups of 8, such as a camera's 4 x 2 tiles): the rays walk the
///   TLAS together (one interval test per node where they share direction signs) and each
///   instance's BLAS as one packet. Any hits are the single-ray answers; closest hits have the
///   single-ray `t`, up to a near tie: visiting the instances in another order, a packet lane
///   may cull a hit lying within rounding of a closer box entry (see
///   [`TriangleTest::CONSERVATIVE_BOXES`](crate::traverse::TriangleTest::CONSERVATIVE_BOXES)).
///   Packets test boxes conservatively whatever `T` asks for, so `Fast<T>` packets answer as
///   single rays of `T` do.
/// - **Ties**: where two instances are hit at exactly the same `t`, the one found first wins
///   (the TLAS's near-to-far order); within one BLAS, the wide traversal's rule.
/// - **Accuracy**: hits are those of a trace of the object-space ray through each instance's BLAS
///   (bit for bit, `tests/instance.rs`); against the triangles transformed into the world, `t`
///   differs by the transform's rounding (relative 1e-5 in the tests). Rays that start far from
///   an instance (more than about 10^4 times the size of the boxes its world box is made of) see
///   the rounding of `M^-1 o` grow with the distance and may be culled by the padded world box
///   where the object-space trace would graze the instance.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
/// use strahl::glam::{Affine3A, Quat};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
/// // Two spheres: one of radius 2 at x = 10, one of radius 1 at x = 20.
/// let instances = [
///     Instance::new(Affine3A::from_scale_rotation_translation(Vec3::splat(2.0), Quat::IDENTITY, Vec3::new(10.0, 0.0, 0.0)), 0),
///     Instance::new(Affine3A::from_translation(Vec3::new(20.0, 0.0, 0.0)), 0),
/// ];
/// let tlas = Tlas::build(&instances, &blases).unwrap();
/// let hit = tlas.intersect::<Moller, _, 8>(&blases, &Ray::new(Vec3::ZERO, Vec3::X)).unwrap();
/// assert_eq!(hit.instance, 0);
/// assert!((hit.hit.t - 8.0).abs() < 0.05); // the first sphere's surface, at about x = 8
/// let past = Ray::new(Vec3::new(15.0, 0.0, 0.0), Vec3::X);
/// assert_eq!(tlas.intersect::<Moller, _, 8>(&blases, &past).unwrap().instance, 1);
/// assert!(!tlas.occluded::<Moller, _, 8>(&blases, &Ray::new(Vec3::ZERO, -Vec3::X)));
/// ```
///
/// A row of spheres:
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh4, Instance, Tlas}, traverse::Watertight};
/// let tris = strahl::scene::icosphere(1).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let blases = [Bvh4::from_bvh2(&b2, &tris[..]).unwrap()];
/// // A row of 100 spheres along x, 3 apart.
/// let instances: Vec<Instance> = (0..100)
///     .map(|i| Instance::new(strahl::glam::Affine3A::from_translation(Vec3::new(3.0 * i as f32, 0.0, 0.0)), 0))
///     .collect();
/// let tlas = Tlas::build(&instances, &blases).unwrap();
/// assert_eq!((tlas.instances(), tlas.left_out()), (100, 0));
/// let down = Ray::new(Vec3::new(3.0 * 42.0, 5.0, 0.0), -Vec3::Y);
/// let hit = tlas.intersect::<Watertight, _, 4>(&blases, &down).unwrap();
/// assert_eq!(hit.instance, 42);
/// assert!((hit.hit.t - 4.0).abs() < 0.1);
/// ```
#[derive(Clone, Debug, Default)]
pub struct Tlas {
    bvh: Bvh2,
    /// `bvh` collapsed to 4-wide nodes (what the traversals walk).
    nodes: Vec<TlasNode>,
    /// World to object, per instance (identity for instances left out).
    inverse: Vec<Affine3A>,
    /// BLAS index per instance.
    blas: Vec<u32>,
    /// Visibility mask per instance ([`Instance::mask`]).
    masks: Vec<u32>,
    left_out: u32,
}

/// A 4-wide TLAS node: child boxes in SoA lanes; child codes a node index, [`LEAF_BIT`] with an
/// instance index, or [`EMPTY_CHILD`] (its box empty, so never hit); per child the union of the
/// masks of the instances below it (`0` for an empty slot). Two cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct TlasNode {
    bounds: AabbLanes<f32x4>,
    child: [u32; 4],
    mask: [u32; 4],
}

const _: () = assert!(core::mem::size_of::<TlasNode>() == 128);

/// Fills every slot's [`TlasNode::mask`] from `masks` (per instance): the children of a node lie
/// after it ([`collapse`] pushes them after their parent), so one pass from the last node to the
/// first sees every child's masks before its parent's.
fn fill_masks(nodes: &mut [TlasNode], masks: &[u32]) {
    for n in (0..nodes.len()).rev() {
        let mut m = [0u32; 4];
        for (slot, &c) in m.iter_mut().zip(&nodes[n].child) {
            *slot = if c == EMPTY_CHILD {
                0
            } else if c & LEAF_BIT != 0 {
                masks.get((c & !LEAF_BIT) as usize).copied().unwrap_or(0)
            } else {
                debug_assert!(c as usize > n, "collapse puts children after their parent");
                nodes[c as usize].mask.iter().fold(0, |a, b| a | b)
            };
        }
        nodes[n].mask = m;
    }
}

/// Collapses `bvh` (leaves of one instance each) into 4-wide nodes: each node takes its binary
/// node's two children and opens the interior child of largest surface area until it has four
/// (Wald et al. 2008's greedy collapse). Explicit stack; node 0 is the root.
fn collapse(bvh: &Bvh2) -> Vec<TlasNode> {
    let nodes = &bvh.nodes;
    let Some(root) = nodes.first() else {
        return Vec::new();
    };
    let code = |i: u32| {
        let n = &nodes[i as usize];
        // NOTE: the TLAS is built with leaves of one instance; instance indices stay below
        // `MAX_PRIMITIVES = 2^31 - 1` (the builder refuses more), so `LEAF_BIT | index` is never
        // `EMPTY_CHILD`.
        if n.is_leaf() {
            LEAF_BIT | bvh.prim_indices[n.index as usize]
        } else {
            i
        }
    };
    let mut out = vec![TlasNode {
        bounds: AabbLanes::empty(),
        child: [EMPTY_CHILD; 4],
        mask: [0; 4],
    }];
    // (binary node, wide slot): a single-leaf tree gets a root holding that leaf.
    let mut stack = vec![(0u32, 0usize)];
    let one = root.is_leaf();
    while let Some((b, at)) = stack.pop() {
        let mut kids: Vec<u32> = if one {
            vec![0]
        } else {
            vec![nodes[b as usize].left(), nodes[b as usize].right()]
        };
        while kids.len() < 4 {
            // The interior child of largest area, if any.
            let open = kids
                .iter()
                .enumerate()
                .filter(|&(_, &k)| !nodes[k as usize].is_leaf())
                .max_by(|a, b| {
                    nodes[*a.1 as usize]
                        .aabb()
                        .half_area()
                        .total_cmp(&nodes[*b.1 as usize].aabb().half_area())
                })
                .map(|(i, _)| i);
            let Some(i) = open else {
                break;
            };
            let k = kids.swap_remove(i);
            kids.extend([nodes[k as usize].left(), nodes[k as usize].right()]);
        }
        let boxes: Vec<Aabb> = kids.iter().map(|&k| nodes[k as usize].aabb()).collect();
        let mut child = [EMPTY_CHILD; 4];
        for (c, &k) in child.iter_mut().zip(&kids) {
            *c = if nodes[k as usize].is_leaf() {
                code(k)
            } else {
                out.push(TlasNode {
                    bounds: AabbLanes::empty(),
                    child: [EMPTY_CHILD; 4],
                    mask: [0; 4],
                });
                stack.push((k, out.len() - 1));
                (out.len() - 1) as u32
            };
        }
        out[at] = TlasNode {
            bounds: AabbLanes::from_boxes(&boxes),
            child,
            mask: [0; 4],
        };
    }
    out
}

/// Relative padding of an instance's world box against the rounding of its transform.
const PAD: f32 = 1.0 / 65536.0;

/// Grows `lo`/`hi` (per axis, per lane) by the boxes in `b`'s lanes where `take` is positive
/// (empty lanes skipped), each transformed by `m` and padded by [`PAD`]: all lanes at once, the
/// lanes reduced once by the caller. Returns `false` where a box taken does not transform to
/// finite bounds (an overflow, `inf * 0`): the lane reductions would drop such a lane's NaN, so
/// the caller must leave the instance out, as a world box beyond the builders' range is.
#[inline(always)]
fn grow_world<L: Lane>(lo: &mut [L; 3], hi: &mut [L; 3], m: &Affine3A, b: &AabbLanes<L>, take: L) -> bool {
    let half = L::splat(0.5);
    let c: [L; 3] = core::array::from_fn(|a| (b.min[a] + b.max[a]) * half);
    let e: [L; 3] = core::array::from_fn(|a| (b.max[a] - b.min[a]) * half);
    let cols = [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis];
    // Centre and half extent through the transform, per world axis `r`: `c' = M c + t`,
    // `e' = |M| e`.
    let wc: [L; 3] = core::array::from_fn(|r| {
        c[0] * L::splat(cols[0][r])
            + c[1] * L::splat(cols[1][r])
            + c[2] * L::splat(cols[2][r])
            + L::splat(m.translation[r])
    });
    let we: [L; 3] = core::array::from_fn(|r| {
        e[0] * L::splat(cols[0][r].abs()) + e[1] * L::splat(cols[1][r].abs()) + e[2] * L::splat(cols[2][r].abs())
    });
    let used = b.min[0].le(b.max[0]) & take.gt(L::splat(0.0));
    let (pad, zero) = (L::splat(PAD), L::splat(0.0));
    let big = we[0].max_l(we[1]).max_l(we[2]) * pad;
    // The rounding of `M c + t` scales with the magnitudes summed, not with the result: a box
    // far from its object's origin can land near the world's origin (the terms cancel), so the
    // padding takes `|M| |c| + |t|` (scaled before the sum, which could overflow where a box
    // reaches near `f32::MAX`). Found in review: padding by `|M c + t|` missed hits of a small
    // box 1,000 units from its origin moved back to the world's origin (`tests/instance.rs`).
    let cp: [L; 3] = core::array::from_fn(|a| c[a].max_l(zero - c[a]) * pad);
    let mut fine = true;
    for r in 0..3 {
        let mag = cp[0] * L::splat(cols[0][r].abs())
            + cp[1] * L::splat(cols[1][r].abs())
            + cp[2] * L::splat(cols[2][r].abs())
            + L::splat(m.translation[r].abs() * PAD);
        let w = we[r] + we[r] * pad + mag + big;
        let (a, b) = (wc[r] - w, wc[r] + w);
        // False for NaN and infinities.
        let finite = a.ge(L::splat(f32::MIN)) & b.le(L::splat(f32::MAX));
        fine &= used.bitmask() & !finite.bitmask() == 0;
        lo[r] = used.select(lo[r].min_l(a), lo[r]);
        hi[r] = used.select(hi[r].max_l(b), hi[r]);
    }
    fine
}

/// The world box of `inst` and its inverse transform, or `None` where the instance is left out.
fn place<L: Lane, const N: usize>(inst: &Instance, blases: &[impl Blas<L, N>]) -> Option<(Aabb, Affine3A)> {
    let m = inst.transform;
    let finite = m.matrix3.is_finite() && m.translation.is_finite();
    if !finite || !m.matrix3.determinant().abs().is_normal() {
        return None;
    }
    let inv = m.inverse();
    if !(inv.matrix3.is_finite() && inv.translation.is_finite()) {
        return None;
    }
    let blas = blases.get(inst.blas as usize)?.blas();
    let root = blas.nodes.first()?;
    let b = root.bounds.union();
    if !(b.min.is_finite() && b.max.is_finite()) || b.min.cmpgt(b.max).any() {
        return None;
    }
    // The union of the boxes one level below the root's slots (the root's own box for a leaf
    // slot), each transformed: much tighter than the root box transformed where the instance
    // is turned (see `tests/instance.rs`).
    let (mut lo, mut hi) = ([L::splat(f32::INFINITY); 3], [L::splat(f32::NEG_INFINITY); 3]);
    // 1.0 in the lanes of the root's leaf slots (`N <= 8`: `WideNode::LANES_MATCH`).
    let mut leaf = [0f32; 8];
    let mut fine = true;
    for (flag, &c) in leaf.iter_mut().zip(&root.child) {
        if c & LEAF_BIT == 0
            && let Some(kid) = blas.nodes.get(c as usize)
        {
            fine &= grow_world(&mut lo, &mut hi, &m, &kid.bounds, L::splat(1.0));
        } else if c != EMPTY_CHILD {
            *flag = 1.0;
        }
    }
    if leaf.iter().any(|&x| x != 0.0) {
        fine &= grow_world(&mut lo, &mut hi, &m, &root.bounds, L::load(&leaf[..N]));
    }
    // A box that overflowed in the transform: its lane would be dropped by the reductions below
    // (found by the `bvh` fuzz target, seed `crash-tlas-overflowed-lane`: a BLAS box from
    // -2.5e33 to `f32::MAX`, whose extent overflows, left the instance's world box as its other
    // box alone, and a hit outside it was culled).
    if !fine {
        return None;
    }
    let world = AabbLanes { min: lo, max: hi }.union();
    // The builders' own rule (extent and `min + max` finite), so that every instance the TLAS
    // leaves out is counted here.
    usable_box(world.min, world.max).then_some((world, inv))
}

/// Places `instances` (those `placed` in the tree; the others left out) into `boxes` and
/// `inverse` (empty box and identity where left out).
fn place_range<L: Lane, const N: usize>(
    placed: &[bool],
    instances: &[Instance],
    blases: &[impl Blas<L, N>],
    boxes: &mut [Aabb],
    inverse: &mut [Affine3A],
) {
    for (k, inst) in instances.iter().enumerate() {
        let now = if placed[k] { place(inst, blases) } else { None };
        (boxes[k], inverse[k]) = now.unwrap_or((Aabb::EMPTY, Affine3A::IDENTITY));
    }
}

impl Tlas {
    /// Builds the top level over `instances`, whose `blas` fields index `blases` (pass the same
    /// slice to the traversals). Instances that cannot be used are left out and counted
    /// ([`left_out`](Self::left_out)); an empty slice gives an empty TLAS. Errors only where the
    /// builder does (more instances than it indexes).
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}};
    /// use strahl::glam::Affine3A;
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let instances = [
    ///     Instance::new(Affine3A::IDENTITY, 0),
    ///     Instance::new(Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0)), 0), // flattened: not invertible
    ///     Instance::new(Affine3A::from_translation(Vec3::NAN), 0),
    ///     Instance::new(Affine3A::IDENTITY, 5), // no BLAS 5
    /// ];
    /// let tlas = Tlas::build(&instances, &blases).unwrap();
    /// assert_eq!((tlas.instances(), tlas.left_out()), (4, 3));
    /// assert!(Tlas::build(&[], &blases).unwrap().is_empty());
    /// ```
    pub fn build<L: Lane, const N: usize>(
        instances: &[Instance],
        blases: &[impl Blas<L, N>],
    ) -> Result<Self, BuildError> {
        Self::build_with(instances, blases, &BuildParams::quality())
    }

    /// [`build`](Self::build) with the binary tree over the instances' world boxes built by
    /// `params` (its leaf sizes set to one instance a leaf; its strategy, bins and refinement
    /// apply). [`build`](Self::build) takes [`BuildParams::quality`] (the
    /// full sweep); for a TLAS of many instances rebuilt every frame, a binned preset builds
    /// faster at a little cost in SAH cost (`fast()` on 100,000 instances: 2.8x faster, SAH cost
    /// +3.6%; see the README; trace times not measured). Errors where
    /// the builder does (more instances than it indexes, parameters out of range).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// use strahl::glam::Affine3A;
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let row: Vec<Instance> = (0..1000)
    ///     .map(|i| Instance::new(Affine3A::from_translation(Vec3::new(3.0 * i as f32, 0.0, 0.0)), 0))
    ///     .collect();
    /// let tlas = Tlas::build_with(&row, &blases, &BuildParams::fast()).unwrap();
    /// let down = Ray::new(Vec3::new(3.0 * 500.0, 5.0, 0.0), -Vec3::Y);
    /// assert_eq!(tlas.intersect::<Moller, _, 8>(&blases, &down).unwrap().instance, 500);
    /// let bad = BuildParams { bins: 3, ..BuildParams::fast() }; // fewer than MIN_BINS
    /// assert!(Tlas::build_with(&row, &blases, &bad).is_err());
    /// ```
    pub fn build_with<L: Lane, const N: usize>(
        instances: &[Instance],
        blases: &[impl Blas<L, N>],
        params: &BuildParams,
    ) -> Result<Self, BuildError> {
        let mut boxes = Vec::with_capacity(instances.len());
        let mut inverse = Vec::with_capacity(instances.len());
        let mut left_out = 0u32;
        for inst in instances {
            match place(inst, blases) {
                Some((b, inv)) => {
                    boxes.push(b);
                    inverse.push(inv);
                }
                None => {
                    // A NaN box: the builder leaves it out.
                    boxes.push(Aabb::new(Vec3::NAN, Vec3::NAN));
                    inverse.push(Affine3A::IDENTITY);
                    left_out += 1;
                }
            }
        }
        // One instance per leaf: an instance costs a transform and a BLAS walk, far more than a
        // box test.
        let params = BuildParams {
            min_leaf_size: 1,
            max_leaf_size: 1,
            ..*params
        };
        let (bvh, _) = Bvh2::build(&boxes[..], &params)?;
        let masks: Vec<u32> = instances.iter().map(|i| i.mask).collect();
        let mut nodes = collapse(&bvh);
        fill_masks(&mut nodes, &masks);
        Ok(Self {
            nodes,
            bvh,
            inverse,
            blas: instances.iter().map(|i| i.blas).collect(),
            masks,
            left_out,
        })
    }

    /// The visibility mask of instance `instance` ([`Instance::mask`]), `None` past the
    /// instances given to [`build`](Self::build).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0).with_mask(6)], &blases).unwrap();
    /// assert_eq!((tlas.mask(0), tlas.mask(1)), (Some(6), None));
    /// ```
    pub fn mask(&self, instance: usize) -> Option<u32> {
        self.masks.get(instance).copied()
    }

    /// Sets the visibility mask of instance `instance` without a rebuild (the tree's slot masks
    /// are made again: time linear in the number of TLAS nodes, about a third of the number of
    /// instances). Returns `false`, changing nothing, past the instances given to
    /// [`build`](Self::build).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let mut tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// assert!(tlas.occluded::<Moller, _, 8>(&blases, &ray));
    /// assert!(tlas.set_mask(0, 0)); // hidden from every ray
    /// assert!(!tlas.occluded::<Moller, _, 8>(&blases, &ray));
    /// assert!(!tlas.set_mask(1, 0));
    /// ```
    pub fn set_mask(&mut self, instance: usize, mask: u32) -> bool {
        let Some(m) = self.masks.get_mut(instance) else {
            return false;
        };
        *m = mask;
        fill_masks(&mut self.nodes, &self.masks);
        true
    }

    /// [`set_mask`](Self::set_mask) for many instances at once: `(instance, mask)` pairs applied
    /// in order (a later pair for the same instance wins), the slot masks made again once. Returns
    /// `false`, changing nothing, if any instance is past those given to [`build`](Self::build).
    /// For a frame that changes many masks this costs one [`set_mask`](Self::set_mask), not one
    /// per change.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// use strahl::glam::Affine3A;
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let row: Vec<Instance> = (0..4)
    ///     .map(|i| Instance::new(Affine3A::from_translation(Vec3::new(3.0 * i as f32, 0.0, 0.0)), 0))
    ///     .collect();
    /// let mut tlas = Tlas::build(&row, &blases).unwrap();
    /// // Hide the even instances from rays of mask 1, in one call.
    /// assert!(tlas.set_masks(&[(0, 0b10), (2, 0b10)]));
    /// let visible = |tlas: &Tlas, i: usize| {
    ///     let ray = Ray::new(Vec3::new(3.0 * i as f32, 0.1, -5.0), Vec3::Z);
    ///     tlas.occluded_masked::<Moller, _, 8>(&blases, &ray, 0b01)
    /// };
    /// assert_eq!((0..4).map(|i| visible(&tlas, i)).collect::<Vec<_>>(), [false, true, false, true]);
    /// // One pair out of range: nothing changes.
    /// assert!(!tlas.set_masks(&[(1, 0), (4, 0)]));
    /// assert_eq!(tlas.mask(1), Some(u32::MAX));
    /// ```
    pub fn set_masks(&mut self, changes: &[(usize, u32)]) -> bool {
        if changes.iter().any(|&(i, _)| i >= self.masks.len()) {
            return false;
        }
        for &(i, m) in changes {
            self.masks[i] = m;
        }
        if !changes.is_empty() {
            fill_masks(&mut self.nodes, &self.masks);
        }
        true
    }

    /// Moves the instances without a rebuild (for animation; what Embree's refit build quality
    /// does for a geometry's BVH): takes
    /// `instances` (as many as given to [`build`](Self::build): their transforms, BLAS indices
    /// and masks may all have changed), places each again and grows the tree's boxes bottom-up
    /// around the new world boxes, keeping the tree's shape. Time linear in the number of
    /// instances; the tree's quality falls as instances move away from where the
    /// tree was built, and a rebuild restores it. Instances that cannot be placed now are left
    /// out (an empty box, never hit), as are those the build left out: the tree has no leaf for
    /// them, so bringing them in takes a rebuild ([`left_out`](Self::left_out) counts both).
    /// Returns `false`, changing nothing, if the number of instances differs.
    ///
    /// Call it too, with the same instances, after a BLAS's bounds changed
    /// ([`BvhWide::refit`](crate::layout::BvhWide::refit), or a new tree in its slot): the TLAS
    /// keeps the world boxes it placed, and its walks cull whatever lies outside them (as in
    /// Embree, where a changed BLAS scene needs the instancing scene committed again).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// # use strahl::glam::Affine3A;
    /// # let mut tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// # let mut blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let one = [Instance::new(Affine3A::IDENTITY, 0)];
    /// let mut tlas = Tlas::build(&one, &blases).unwrap();
    /// // The BLAS's triangles move up by 5 and the BLAS is refitted: the TLAS still holds the old box.
    /// for v in tris.iter_mut().flatten() {
    ///     v.y += 5.0;
    /// }
    /// assert_eq!(blases[0].refit(&tris[..]), 0);
    /// let ray = Ray::new(Vec3::new(0.0, 5.0, -3.0), Vec3::Z);
    /// assert!(tlas.intersect::<Moller, _, 8>(&blases, &ray).is_none()); // culled by the old box
    /// assert!(tlas.refit(&one, &blases));
    /// assert!(tlas.intersect::<Moller, _, 8>(&blases, &ray).is_some());
    /// ```
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// use strahl::glam::Affine3A;
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let at = |x: f32| Instance::new(Affine3A::from_translation(Vec3::new(x, 0.0, 0.0)), 0);
    /// let mut tlas = Tlas::build(&[at(0.0), at(3.0)], &blases).unwrap();
    /// let down = Ray::new(Vec3::new(10.0, 5.0, 0.0), -Vec3::Y);
    /// assert!(!tlas.occluded::<Moller, _, 8>(&blases, &down));
    /// // The second sphere moves to x = 10: the ray now hits it.
    /// assert!(tlas.refit(&[at(0.0), at(10.0)], &blases));
    /// assert_eq!(tlas.intersect::<Moller, _, 8>(&blases, &down).unwrap().instance, 1);
    /// // A transform that cannot be inverted leaves that instance out until it can.
    /// let flat = Instance::new(Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0)), 0);
    /// assert!(tlas.refit(&[at(0.0), flat], &blases));
    /// assert_eq!((tlas.left_out(), tlas.occluded::<Moller, _, 8>(&blases, &down)), (1, false));
    /// assert!(!tlas.refit(&[at(0.0)], &blases)); // one instance fewer: nothing changes
    /// assert_eq!(tlas.left_out(), 1);
    /// ```
    pub fn refit<L: Lane, const N: usize>(&mut self, instances: &[Instance], blases: &[impl Blas<L, N>]) -> bool {
        self.refit_with(instances, |placed, boxes, inverse| {
            place_range(placed, instances, blases, boxes, inverse);
        })
    }

    /// [`refit`](Self::refit) with the instances placed on up to `threads` threads (in chunks
    /// of at least 1,024 instances), the tree's boxes then grown on the calling thread: the
    /// same tree as [`refit`](Self::refit) for any number of threads (`std`).
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}};
    /// use strahl::glam::Affine3A;
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let at = |x: f32| (0..5000).map(|i| Instance::new(Affine3A::from_translation(Vec3::new(3.0 * i as f32 + x, 0.0, 0.0)), 0)).collect::<Vec<_>>();
    /// let (mut one, mut two) = (Tlas::build(&at(0.0), &blases).unwrap(), Tlas::build(&at(0.0), &blases).unwrap());
    /// assert!(one.refit(&at(0.5), &blases) && two.refit_par(&at(0.5), &blases, 2));
    /// assert_eq!(one.bvh().nodes, two.bvh().nodes);
    /// ```
    #[cfg(feature = "std")]
    pub fn refit_par<L: Lane, const N: usize>(
        &mut self,
        instances: &[Instance],
        blases: &[impl Blas<L, N> + Sync],
        threads: usize,
    ) -> bool {
        let threads = threads.clamp(1, crate::build::MAX_THREADS);
        self.refit_with(instances, |placed, boxes, inverse| {
            let n = instances.len();
            let chunk = n.div_ceil(threads * 4).max(1024);
            let ranges: Vec<(usize, usize)> = (0..n).step_by(chunk).map(|lo| (lo, (lo + chunk).min(n))).collect();
            let jobs: Vec<_> = ranges
                .iter()
                .zip(crate::par::split_ranges(boxes, ranges.iter().copied()))
                .zip(crate::par::split_ranges(inverse, ranges.iter().copied()))
                .map(|((&(lo, hi), b), inv)| (lo, hi, b, inv))
                .collect();
            crate::par::each_job(jobs, threads, |(lo, hi, b, inv)| {
                place_range(&placed[lo..hi], &instances[lo..hi], blases, b, inv);
            });
        })
    }

    /// The refits' common part: `place_all(placed, boxes, inverse)` places the instances (those
    /// in the tree, `placed`), then the counts, BLAS indices, masks and the trees' boxes follow.
    fn refit_with(
        &mut self,
        instances: &[Instance],
        place_all: impl FnOnce(&[bool], &mut [Aabb], &mut [Affine3A]),
    ) -> bool {
        if instances.len() != self.inverse.len() {
            return false;
        }
        // The instances in the tree: one leaf each, in the binary tree's primitive order.
        let mut boxes = vec![Aabb::EMPTY; instances.len()];
        let mut placed = vec![false; instances.len()];
        for &i in &self.bvh.prim_indices {
            placed[i as usize] = true;
        }
        place_all(&placed, &mut boxes, &mut self.inverse);
        // A placed instance's box is never empty (`usable_box`); a left-out one's is.
        self.left_out = boxes.iter().filter(|b| b.is_empty()).count() as u32;
        for (k, inst) in instances.iter().enumerate() {
            self.blas[k] = inst.blas;
            self.masks[k] = inst.mask;
        }
        // The binary tree (what `bvh()` shows); its structure is the build's, so the refit's
        // checks cannot fail.
        let refitted = self.bvh.refit(&boxes[..]);
        debug_assert!(refitted.is_ok());
        // The 4-wide nodes, children (after their parents) first.
        for n in (0..self.nodes.len()).rev() {
            let mut b = [Aabb::EMPTY; 4];
            for (slot, &c) in b.iter_mut().zip(&self.nodes[n].child) {
                *slot = if c == EMPTY_CHILD {
                    Aabb::EMPTY
                } else if c & LEAF_BIT != 0 {
                    boxes[(c & !LEAF_BIT) as usize]
                } else {
                    self.nodes[c as usize].bounds.union()
                };
            }
            self.nodes[n].bounds = AabbLanes::from_boxes(&b);
        }
        fill_masks(&mut self.nodes, &self.masks);
        true
    }

    /// Number of instances given to [`build`](Self::build), left out ones included.
    ///
    /// ```
    /// assert_eq!(strahl::layout::Tlas::default().instances(), 0);
    /// ```
    pub fn instances(&self) -> usize {
        self.inverse.len()
    }

    /// Instances left out by [`build`](Self::build) (or by the last [`refit`](Self::refit)): transform not finite or not invertible,
    /// BLAS index out of range, an empty BLAS, or a world box beyond the builders' range (an
    /// extent or `min + max` that overflows `f32`, i.e. coordinates beyond about `±1.7e38`).
    ///
    /// ```
    /// assert_eq!(strahl::layout::Tlas::default().left_out(), 0);
    /// ```
    pub fn left_out(&self) -> u32 {
        self.left_out
    }

    /// Bytes of the TLAS: its nodes and primitive indices, and per instance the inverse
    /// transform, the BLAS index and the mask (the BLASes not counted).
    ///
    /// ```
    /// use strahl::{build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// // One binary leaf (32 bytes) and its index (4), one 4-wide node (128), one inverse (64), one
    /// // BLAS index (4), one mask (4).
    /// assert_eq!(tlas.memory_bytes(), 32 + 4 + 128 + size_of::<strahl::glam::Affine3A>() + 4 + 4);
    /// ```
    pub fn memory_bytes(&self) -> usize {
        core::mem::size_of_val(self.bvh.nodes.as_slice())
            + core::mem::size_of_val(self.bvh.prim_indices.as_slice())
            + core::mem::size_of_val(self.nodes.as_slice())
            + core::mem::size_of_val(self.inverse.as_slice())
            + core::mem::size_of_val(self.blas.as_slice())
            + core::mem::size_of_val(self.masks.as_slice())
    }

    /// `true` if no instance can be hit: none given, or every one left out (by the build or by
    /// the last [`refit`](Self::refit)).
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}};
    /// use strahl::glam::Affine3A;
    /// assert!(Tlas::default().is_empty());
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let mut tlas = Tlas::build(&[Instance::new(Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// assert!(!tlas.is_empty());
    /// // Moved to a transform that cannot be inverted: left out, nothing to hit.
    /// assert!(tlas.refit(&[Instance::new(Affine3A::from_scale(Vec3::ZERO), 0)], &blases));
    /// assert!(tlas.is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.bvh.nodes.is_empty() || self.left_out as usize == self.inverse.len()
    }

    /// The binary BVH over the instances' world boxes that the 4-wide nodes were collapsed from
    /// (one instance per leaf; its primitive indices are instance indices).
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let far = Instance::new(strahl::glam::Affine3A::from_translation(Vec3::splat(10.0)), 0);
    /// let tlas = Tlas::build(&[far], &blases).unwrap();
    /// let b = b2.bounds();
    /// let moved = strahl::Aabb::new(b.min + Vec3::splat(10.0), b.max + Vec3::splat(10.0));
    /// assert!(tlas.bvh().bounds().contains(&moved));
    /// assert_eq!(tlas.bvh().prim_indices, [0]);
    /// ```
    pub fn bvh(&self) -> &Bvh2 {
        &self.bvh
    }

    /// Closest hit of `ray` over every instance (`blases`: the slice given to
    /// [`build`](Self::build); an instance whose BLAS index is out of range is skipped).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// // One instance at the identity: the BLAS's own hit.
    /// assert_eq!(tlas.intersect::<Moller, _, 8>(&blases, &ray).map(|h| h.hit), blases[0].intersect::<Moller>(&ray));
    /// assert_eq!(tlas.intersect::<Moller, _, 8>(&blases, &Ray::new(Vec3::NAN, Vec3::Z)), None);
    /// ```
    pub fn intersect<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        ray: &Ray,
    ) -> Option<InstanceHit> {
        self.walk::<T, L, N, _, false, false>(blases, ray, u32::MAX, &mut AcceptAll)
    }

    /// `true` if `ray` hits any instance within `[tmin, tmax)` (any hit: stops at the first).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let moved = Instance::new(strahl::glam::Affine3A::from_translation(Vec3::new(0.0, 0.0, 5.0)), 0);
    /// let tlas = Tlas::build(&[moved], &blases).unwrap();
    /// // The sphere spans z = 4 to 6: a shadow ray from the origin to z = 3 is not blocked.
    /// assert!(!tlas.occluded::<Moller, _, 8>(&blases, &Ray::with_range(Vec3::ZERO, Vec3::Z, 0.0, 3.0)));
    /// assert!(tlas.occluded::<Moller, _, 8>(&blases, &Ray::with_range(Vec3::ZERO, Vec3::Z, 0.0, 4.5)));
    /// ```
    pub fn occluded<T: TriangleTest, L: Lane, const N: usize>(&self, blases: &[impl Blas<L, N>], ray: &Ray) -> bool {
        self.walk::<T, L, N, _, true, false>(blases, ray, u32::MAX, &mut AcceptAll)
            .is_some()
    }

    /// [`intersect`](Self::intersect) counting only the hits `filter` accepts
    /// ([`HitFilter`] over [`InstanceHit`]s: the hit in the BLAS and the instance's index, so a
    /// filter can alpha-test per instance or mask instances, as Embree's filter functions read
    /// `instID`): the nearest accepted hit over every instance.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, InstanceHit, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let at = |z: f32| Instance::new(strahl::glam::Affine3A::from_translation(Vec3::new(0.0, 0.0, z)), 0);
    /// let tlas = Tlas::build(&[at(5.0), at(10.0)], &blases).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, 0.0), Vec3::Z);
    /// assert_eq!(tlas.intersect::<Moller, _, 8>(&blases, &ray).unwrap().instance, 0);
    /// // Instance 0 is hidden: the ray goes on to instance 1.
    /// let hit = tlas.intersect_filtered::<Moller, _, 8>(&blases, &ray, |h: &InstanceHit| h.instance != 0).unwrap();
    /// assert_eq!(hit.instance, 1);
    /// assert!(hit.hit.t > 8.9 && hit.hit.t < 9.1);
    /// assert!(!tlas.occluded_filtered::<Moller, _, 8>(&blases, &ray, |_: &InstanceHit| false));
    /// ```
    pub fn intersect_filtered<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        ray: &Ray,
        mut filter: impl HitFilter<InstanceHit>,
    ) -> Option<InstanceHit> {
        self.walk::<T, L, N, _, false, false>(blases, ray, u32::MAX, &mut filter)
    }

    /// [`occluded`](Self::occluded) counting only the hits `filter` accepts (see
    /// [`intersect_filtered`](Self::intersect_filtered)).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, InstanceHit, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// assert!(tlas.occluded_filtered::<Moller, _, 8>(&blases, &ray, |h: &InstanceHit| h.hit.u >= 0.0));
    /// assert!(!tlas.occluded_filtered::<Moller, _, 8>(&blases, &ray, |h: &InstanceHit| h.instance > 0));
    /// ```
    pub fn occluded_filtered<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        ray: &Ray,
        mut filter: impl HitFilter<InstanceHit>,
    ) -> bool {
        self.walk::<T, L, N, _, true, false>(blases, ray, u32::MAX, &mut filter)
            .is_some()
    }

    /// [`intersect`](Self::intersect) seeing only the instances whose
    /// [`mask`](Instance::mask) shares a bit with `ray_mask` (Embree's `RTCRay::mask`, DXR's
    /// `InstanceInclusionMask`): the closest hit among them. Subtrees holding no such instance
    /// are skipped whole. `u32::MAX` gives [`intersect`](Self::intersect)'s answer.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// use strahl::glam::Affine3A;
    /// const CAMERA: u32 = 1;
    /// const SHADOW: u32 = 2;
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let at = |z: f32| Affine3A::from_translation(Vec3::new(0.0, 0.0, z));
    /// let instances = [
    ///     Instance::new(at(5.0), 0).with_mask(CAMERA),          // seen, casts no shadow
    ///     Instance::new(at(10.0), 0).with_mask(CAMERA | SHADOW), // seen, casts shadows
    /// ];
    /// let tlas = Tlas::build(&instances, &blases).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, 0.0), Vec3::Z);
    /// assert_eq!(tlas.intersect_masked::<Moller, _, 8>(&blases, &ray, CAMERA).unwrap().instance, 0);
    /// assert_eq!(tlas.intersect_masked::<Moller, _, 8>(&blases, &ray, SHADOW).unwrap().instance, 1);
    /// assert_eq!(tlas.intersect_masked::<Moller, _, 8>(&blases, &ray, 4), None);
    /// ```
    pub fn intersect_masked<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        ray: &Ray,
        ray_mask: u32,
    ) -> Option<InstanceHit> {
        self.walk::<T, L, N, _, false, true>(blases, ray, ray_mask, &mut AcceptAll)
    }

    /// [`occluded`](Self::occluded) seeing only the instances whose [`mask`](Instance::mask)
    /// shares a bit with `ray_mask` (see [`intersect_masked`](Self::intersect_masked)).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let glass = Instance::new(strahl::glam::Affine3A::IDENTITY, 0).with_mask(0b01);
    /// let tlas = Tlas::build(&[glass], &blases).unwrap();
    /// let shadow = Ray::with_range(Vec3::new(0.1, 0.2, -3.0), Vec3::Z, 0.0, 10.0);
    /// assert!(tlas.occluded_masked::<Moller, _, 8>(&blases, &shadow, 0b01));
    /// assert!(!tlas.occluded_masked::<Moller, _, 8>(&blases, &shadow, 0b10));
    /// ```
    pub fn occluded_masked<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        ray: &Ray,
        ray_mask: u32,
    ) -> bool {
        self.walk::<T, L, N, _, true, true>(blases, ray, ray_mask, &mut AcceptAll)
            .is_some()
    }

    /// [`intersect_masked`](Self::intersect_masked) and
    /// [`intersect_filtered`](Self::intersect_filtered) at once: the nearest hit that `filter`
    /// accepts among the instances whose mask shares a bit with `ray_mask` (hidden subtrees are
    /// skipped whole; the filter sees only hits in visible instances), as Embree's rays carry a
    /// mask and meet filter functions in one call.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, InstanceHit, Tlas}, traverse::Moller};
    /// use strahl::glam::Affine3A;
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let at = |z: f32, mask: u32| Instance::new(Affine3A::from_translation(Vec3::new(0.0, 0.0, z)), 0).with_mask(mask);
    /// let tlas = Tlas::build(&[at(5.0, 0b10), at(10.0, 0b01), at(15.0, 0b01)], &blases).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, 0.0), Vec3::Z);
    /// // Mask 0b01 hides instance 0; the filter rejects the front faces of instance 1
    /// // (entered at t ~ 9), so the ray meets its back (t ~ 11).
    /// let back = |h: &InstanceHit| h.instance != 1 || h.hit.t > 10.0;
    /// let hit = tlas.intersect_masked_filtered::<Moller, _, 8>(&blases, &ray, 0b01, back).unwrap();
    /// assert_eq!(hit.instance, 1);
    /// assert!(hit.hit.t > 10.9 && hit.hit.t < 11.1);
    /// assert!(!tlas.occluded_masked_filtered::<Moller, _, 8>(&blases, &ray, 0b01, |h: &InstanceHit| h.instance == 0));
    /// ```
    pub fn intersect_masked_filtered<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        ray: &Ray,
        ray_mask: u32,
        mut filter: impl HitFilter<InstanceHit>,
    ) -> Option<InstanceHit> {
        self.walk::<T, L, N, _, false, true>(blases, ray, ray_mask, &mut filter)
    }

    /// [`occluded_masked`](Self::occluded_masked) and
    /// [`occluded_filtered`](Self::occluded_filtered) at once (see
    /// [`intersect_masked_filtered`](Self::intersect_masked_filtered)).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, InstanceHit, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let leaves = Instance::new(strahl::glam::Affine3A::IDENTITY, 0).with_mask(0b01);
    /// let tlas = Tlas::build(&[leaves], &blases).unwrap();
    /// let shadow = Ray::with_range(Vec3::new(0.1, 0.2, -3.0), Vec3::Z, 0.0, 10.0);
    /// let opaque = |h: &InstanceHit| h.hit.u < 0.5; // an alpha test
    /// assert_eq!(
    ///     tlas.occluded_masked_filtered::<Moller, _, 8>(&blases, &shadow, 0b01, opaque),
    ///     tlas.occluded_filtered::<Moller, _, 8>(&blases, &shadow, opaque),
    /// );
    /// assert!(!tlas.occluded_masked_filtered::<Moller, _, 8>(&blases, &shadow, 0b10, opaque));
    /// ```
    pub fn occluded_masked_filtered<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        ray: &Ray,
        ray_mask: u32,
        mut filter: impl HitFilter<InstanceHit>,
    ) -> bool {
        self.walk::<T, L, N, _, true, true>(blases, ray, ray_mask, &mut filter)
            .is_some()
    }

    /// [`intersect`](Self::intersect) for every ray of a batch: `hits[i]` for `rays[i]` (the
    /// shorter length wins). Groups of 8 consecutive rays with the same direction signs and
    /// origins close together (a camera tile, as [`wide::intersect_batch`] decides) go as one
    /// packet ([`intersect8`](Self::intersect8)), the others one call per ray: the `t` of
    /// [`intersect`](Self::intersect) (up to a near tie in a packet, see [`Tlas`]), the same
    /// instance and primitive unless two tie there. (`Fast<T>` batches send no packets.)
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let row: Vec<Instance> = (0..4)
    ///     .map(|i| Instance::new(strahl::glam::Affine3A::from_translation(Vec3::new(3.0 * i as f32, 0.0, 0.0)), 0))
    ///     .collect();
    /// let tlas = Tlas::build(&row, &blases).unwrap();
    /// let rays: Vec<Ray> = (0..5).map(|i| Ray::new(Vec3::new(3.0 * i as f32, 0.1, -5.0), Vec3::Z)).collect();
    /// let mut hits = [None; 5];
    /// tlas.intersect_batch::<Moller, _, 8>(&blases, &rays, &mut hits);
    /// assert_eq!(hits.map(|h| h.map(|h| h.instance)), [Some(0), Some(1), Some(2), Some(3), None]);
    /// ```
    pub fn intersect_batch<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        rays: &[Ray],
        hits: &mut [Option<InstanceHit>],
    ) {
        wide::by_groups::<T, _>(
            rays,
            hits,
            self.extent(),
            |r, h| self.intersect8::<T, L, N>(blases, r, h),
            |r| self.intersect::<T, L, N>(blases, r),
            |r, h| {
                for (r, h) in r.iter().zip(h.iter_mut()) {
                    *h = self.intersect::<T, L, N>(blases, r);
                }
            },
        );
    }

    /// [`occluded`](Self::occluded) for every ray of a batch: `out[i]` for `rays[i]` (the
    /// shorter length wins); coherent groups of 8 as packets ([`occluded8`](Self::occluded8)),
    /// the same answers.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// let rays = [Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z), Ray::new(Vec3::new(0.0, 0.0, -5.0), -Vec3::Z)];
    /// let mut out = [false; 2];
    /// tlas.occluded_batch::<Moller, _, 8>(&blases, &rays, &mut out);
    /// assert_eq!(out, [true, false]);
    /// ```
    pub fn occluded_batch<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        rays: &[Ray],
        out: &mut [bool],
    ) {
        wide::by_groups::<T, _>(
            rays,
            out,
            self.extent(),
            |r, o| self.occluded8::<T, L, N>(blases, r, o),
            |r| self.occluded::<T, L, N>(blases, r),
            |r, o| {
                for (r, o) in r.iter().zip(o.iter_mut()) {
                    *o = self.occluded::<T, L, N>(blases, r);
                }
            },
        );
    }

    /// [`intersect_batch`](Self::intersect_batch) on `threads` threads (`std`; chunks of 1024
    /// rays), the same hits.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// let rays: Vec<Ray> = (0..3000).map(|i| Ray::new(Vec3::new((i % 9) as f32 * 0.3 - 1.2, 0.1, -5.0), Vec3::Z)).collect();
    /// let (mut one, mut two) = (vec![None; rays.len()], vec![None; rays.len()]);
    /// tlas.intersect_batch::<Moller, _, 8>(&blases, &rays, &mut one);
    /// tlas.intersect_batch_par::<Moller, _, 8>(&blases, &rays, &mut two, 2);
    /// assert_eq!(one, two);
    /// assert!(one.iter().any(Option::is_some) && one.iter().any(Option::is_none));
    /// ```
    #[cfg(feature = "std")]
    pub fn intersect_batch_par<T: TriangleTest, L: Lane + Sync, const N: usize>(
        &self,
        blases: &[impl Blas<L, N> + Sync],
        rays: &[Ray],
        hits: &mut [Option<InstanceHit>],
        threads: usize,
    ) {
        wide::par_chunks(rays, hits, threads, |r, h| {
            self.intersect_batch::<T, L, N>(blases, r, h)
        });
    }

    /// [`occluded_batch`](Self::occluded_batch) on `threads` threads (`std`; chunks of 1024
    /// rays), the same answers.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(1).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// let rays: Vec<Ray> = (0..3000).map(|i| Ray::new(Vec3::new((i % 9) as f32 * 0.3 - 1.2, 0.1, -5.0), Vec3::Z)).collect();
    /// let (mut one, mut two) = (vec![false; rays.len()], vec![false; rays.len()]);
    /// tlas.occluded_batch::<Moller, _, 8>(&blases, &rays, &mut one);
    /// tlas.occluded_batch_par::<Moller, _, 8>(&blases, &rays, &mut two, 2);
    /// assert_eq!(one, two);
    /// ```
    #[cfg(feature = "std")]
    pub fn occluded_batch_par<T: TriangleTest, L: Lane + Sync, const N: usize>(
        &self,
        blases: &[impl Blas<L, N> + Sync],
        rays: &[Ray],
        out: &mut [bool],
        threads: usize,
    ) {
        wide::par_chunks(rays, out, threads, |r, o| self.occluded_batch::<T, L, N>(blases, r, o));
    }

    /// Closest hits of up to 8 rays as one packet: `hits[i]` for `rays[i]` (the shorter length
    /// wins, at most 8). The rays walk the TLAS together, each node's boxes tested against every
    /// lane that entered it; at each instance the lanes that reach it are taken into object
    /// space and traced through its BLAS as one packet ([`packet::intersect_packet`]: interval
    /// culling where the lanes are coherent, as a camera tile stays under any affine
    /// transform; single rays where they diverge). Each answer has the `t` of
    /// [`intersect`](Self::intersect), and its instance and primitive unless two tie at that
    /// `t`, up to a near tie (the packet visits instances in another order; see the
    /// [`Tlas`] docs). Boxes are tested conservatively whatever `T` asks for, as the packets
    /// do (for `Fast<T>`, the answers of [`intersect`](Self::intersect) with `T`).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// use strahl::glam::Affine3A;
    /// let tris = strahl::scene::icosphere(3).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let row: Vec<Instance> = (0..4)
    ///     .map(|i| Instance::new(Affine3A::from_translation(Vec3::new(3.0 * i as f32, 0.0, 0.0)), 0))
    ///     .collect();
    /// let tlas = Tlas::build(&row, &blases).unwrap();
    /// // A 4 x 2 tile of camera rays towards the second sphere.
    /// let eye = Vec3::new(3.0, 0.0, -6.0);
    /// let rays: Vec<Ray> = (0..8)
    ///     .map(|i| Ray::new(eye, Vec3::new((i % 4) as f32 * 0.01, (i / 4) as f32 * 0.01, 1.0)))
    ///     .collect();
    /// let mut hits = [None; 8];
    /// tlas.intersect8::<Moller, _, 8>(&blases, &rays, &mut hits);
    /// for (r, h) in rays.iter().zip(hits) {
    ///     assert_eq!(h, tlas.intersect::<Moller, _, 8>(&blases, r));
    ///     assert_eq!(h.unwrap().instance, 1);
    /// }
    /// ```
    pub fn intersect8<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        rays: &[Ray],
        hits: &mut [Option<InstanceHit>],
    ) {
        self.intersect8_masked::<T, L, N>(blases, rays, u32::MAX, hits);
    }

    /// [`intersect8`](Self::intersect8) seeing only the instances whose
    /// [`mask`](Instance::mask) shares a bit with `ray_mask` (as
    /// [`intersect_masked`](Self::intersect_masked), one mask for the packet).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// use strahl::glam::Affine3A;
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let at = |z: f32| Affine3A::from_translation(Vec3::new(0.0, 0.0, z));
    /// let tlas = Tlas::build(&[Instance::new(at(5.0), 0).with_mask(1), Instance::new(at(10.0), 0).with_mask(2)], &blases).unwrap();
    /// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(0.01 * i as f32, 0.1, 0.0), Vec3::Z)).collect();
    /// let mut hits = [None; 8];
    /// tlas.intersect8_masked::<Moller, _, 8>(&blases, &rays, 2, &mut hits);
    /// assert!(hits.iter().all(|h| h.unwrap().instance == 1)); // the nearer sphere is hidden
    /// ```
    pub fn intersect8_masked<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        rays: &[Ray],
        ray_mask: u32,
        hits: &mut [Option<InstanceHit>],
    ) {
        let n = rays.len().min(hits.len()).min(PACKET);
        let (best, _) = self.walk_packet::<T, L, N, false>(blases, &rays[..n], ray_mask);
        hits[..n].copy_from_slice(&best[..n]);
    }

    /// Any-hit answers of up to 8 rays as one packet: `out[i]` for `rays[i]` (the shorter length
    /// wins, at most 8), the answers of [`occluded`](Self::occluded); lanes retire as they are
    /// blocked. See [`intersect8`](Self::intersect8).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let tlas = Tlas::build(&[Instance::new(strahl::glam::Affine3A::IDENTITY, 0)], &blases).unwrap();
    /// // Shadow rays from a patch below the sphere: blocked up to a light above it, not short of it.
    /// let rays: Vec<Ray> = (0..8)
    ///     .map(|i| Ray::with_range(Vec3::new(0.01 * i as f32, 0.0, -3.0), Vec3::Z, 0.0, if i < 4 { 6.0 } else { 1.5 }))
    ///     .collect();
    /// let mut out = [false; 8];
    /// tlas.occluded8::<Moller, _, 8>(&blases, &rays, &mut out);
    /// assert_eq!(out, [true, true, true, true, false, false, false, false]);
    /// ```
    pub fn occluded8<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        rays: &[Ray],
        out: &mut [bool],
    ) {
        self.occluded8_masked::<T, L, N>(blases, rays, u32::MAX, out);
    }

    /// [`occluded8`](Self::occluded8) seeing only the instances whose [`mask`](Instance::mask)
    /// shares a bit with `ray_mask`.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::{Bvh8, Instance, Tlas}, traverse::Moller};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let blases = [Bvh8::from_bvh2(&b2, &tris[..]).unwrap()];
    /// let glass = Instance::new(strahl::glam::Affine3A::IDENTITY, 0).with_mask(0b01);
    /// let tlas = Tlas::build(&[glass], &blases).unwrap();
    /// let rays = [Ray::with_range(Vec3::new(0.1, 0.2, -3.0), Vec3::Z, 0.0, 10.0); 8];
    /// let mut out = [true; 8];
    /// tlas.occluded8_masked::<Moller, _, 8>(&blases, &rays, 0b10, &mut out);
    /// assert_eq!(out, [false; 8]); // glass casts no shadow
    /// ```
    pub fn occluded8_masked<T: TriangleTest, L: Lane, const N: usize>(
        &self,
        blases: &[impl Blas<L, N>],
        rays: &[Ray],
        ray_mask: u32,
        out: &mut [bool],
    ) {
        let n = rays.len().min(out.len()).min(PACKET);
        let (_, blocked) = self.walk_packet::<T, L, N, true>(blases, &rays[..n], ray_mask);
        for (i, o) in out[..n].iter_mut().enumerate() {
            *o = blocked >> i & 1 != 0;
        }
    }

    /// The largest extent of the TLAS's root box (0 for an empty TLAS): the scale of the batch
    /// forms' coherence test.
    fn extent(&self) -> f32 {
        let Some(root) = self.nodes.first() else {
            return 0.0;
        };
        let b = root.bounds.union();
        (b.max - b.min).max_element().max(0.0)
    }

    /// The hit of `ray` (world space, with `tmax` the closest hit so far) in instance `i`.
    /// `ANY`: any hit (its `t` is then `tmax`, the only thing the caller reads being `Some`).
    #[inline(always)]
    fn trace_instance<T: TriangleTest, L: Lane, const N: usize, F: HitFilter<InstanceHit>, const ANY: bool>(
        &self,
        blases: &[impl Blas<L, N>],
        i: u32,
        ray: &Ray,
        tmax: f32,
        f: &mut F,
    ) -> Option<Hit> {
        let inv = self.inverse.get(i as usize)?;
        let blas = blases.get(*self.blas.get(i as usize)? as usize)?.blas();
        let mut r = prepare::<T>(&object_ray(inv, ray, tmax));
        if r.is_empty() || blas.nodes.is_empty() {
            return None;
        }
        let mut f = InInstance { f, instance: i };
        if ANY {
            wide::occluded_prepared_filtered::<T, L, N, _>(blas, &r, &mut f).then_some(Hit {
                t: tmax,
                u: 0.0,
                v: 0.0,
                prim: crate::geometry::INVALID,
            })
        } else {
            wide::intersect_from_filtered::<T, L, N, _>(blas, 0, &mut r, &mut f)
        }
    }

    /// The TLAS walk over 4-wide nodes: children hit in order of entry distance, the nearest
    /// next and the others on the stack (farthest deepest) with their entry distances.
    /// `MASKED`: slots whose mask shares no bit with `ray_mask` are not entered; else (the
    /// unmasked calls, whose ray mask is all ones) only instances of mask `0` are skipped, at
    /// their leaf, so the unmasked walk does no per-node mask work.
    // PERF: against the binary TLAS walk it replaced (scalar slab tests, leaves of up to 8
    // instances), the same run of `cargo bench --features embree --bench instance` (Intel Xeon,
    // 2026-12-05): diffuse rays 66.8 -> 61.3 ms (bunnies), 81.1 -> 70.2 ms (spheres); primary
    // rays 50.0 -> 50.6 and 58.2 -> 59.7 ms (within the noise). Embree's instancing in that run:
    // 46.0 / 50.0 / 52.8 / 54.0 ms (primary and diffuse, bunnies and spheres).
    // 8-wide nodes (f32x8 lanes, up to 8 hits sorted), measured next: diffuse 59.5 and 70.1 ms,
    // primary 55.0 and 66.0 ms (slower), so 4 wide.
    // PERF: the per-node mask test in every walk measured 1-3% slower on the instance bench's
    // closest-hit rows (one run, old and new builds one after the other), hence the two forms
    // (`MASKED`); with the test in the masked walk only, the unmasked walks are within 1% of the
    // code before masks on every row (two rounds, old and new taking turns, 2026-12-07).
    #[inline(always)]
    fn walk<
        T: TriangleTest,
        L: Lane,
        const N: usize,
        F: HitFilter<InstanceHit>,
        const ANY: bool,
        const MASKED: bool,
    >(
        &self,
        blases: &[impl Blas<L, N>],
        ray: &Ray,
        ray_mask: u32,
        f: &mut F,
    ) -> Option<InstanceHit> {
        let mut r = prepare::<T>(ray);
        if r.is_empty() || self.nodes.is_empty() {
            return None;
        }
        // A tree of depth `d` keeps at most `3 (d - 1) + 1` entries; the builder bounds `d` by
        // `STACK_SIZE`.
        // PERF: the crate's uninitialised stack, not a zeroed array (1.5 KB written per ray):
        // 1.06-1.16x faster on the instance bench's rays (old and new binaries taking turns).
        let mut stack = Stack::<{ 3 * STACK_SIZE + 1 }>::new();
        let mut cur = 0u32;
        let mut best: Option<InstanceHit> = None;
        loop {
            if cur & LEAF_BIT == 0 {
                if let Some(node) = self.nodes.get(cur as usize) {
                    let (dist, mut mask) = node_lanes::<T, f32x4>(&r, &node.bounds);
                    // Slots with no instance the ray can see are not entered (empty slots hold
                    // mask 0 and an empty box: missed either way).
                    if MASKED {
                        let mut seen = 0u32;
                        for (i, &m) in node.mask.iter().enumerate() {
                            seen |= u32::from(m & ray_mask != 0) << i;
                        }
                        mask &= seen;
                    }
                    let d = dist.to_array();
                    // The hit children, nearest first (ties: the lower slot).
                    let mut hit = [(0u32, 0.0f32); 4];
                    let mut n = 0;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let mut j = n;
                        // Any hit: slot order, no sort (as the wide any-hit walk). PERF: taking
                        // turns with the sorted order, diffuse any-hit rays 1.02-1.12x faster,
                        // primary ones the same.
                        while !ANY && j > 0 && hit[j - 1].1 > d[i] {
                            hit[j] = hit[j - 1];
                            j -= 1;
                        }
                        hit[j] = (node.child[i], d[i]);
                        n += 1;
                    }
                    if n > 0 {
                        for &(c, d) in hit[1..n].iter().rev() {
                            let pushed = stack.push(c, d);
                            debug_assert!(pushed);
                        }
                        cur = hit[0].0;
                        continue;
                    }
                }
            } else if cur != EMPTY_CHILD
                && (MASKED || self.masks.get((cur & !LEAF_BIT) as usize).is_some_and(|&m| m != 0))
                && let Some(h) = self.trace_instance::<T, L, N, F, ANY>(blases, cur & !LEAF_BIT, ray, r.tmax, f)
            {
                best = Some(InstanceHit {
                    hit: h,
                    instance: cur & !LEAF_BIT,
                });
                if ANY {
                    return best;
                }
                r.tmax = h.t;
            }
            // The next entry that can still hold a closer hit.
            loop {
                let Some((c, near)) = stack.pop() else {
                    return best;
                };
                if !beyond::<T>(near, r.tmax) {
                    cur = c;
                    break;
                }
            }
        }
    }
}

/// Lanes of a TLAS packet ([`Tlas::intersect8`]).
const PACKET: usize = 8;

/// World ray `ray` in an instance's object space (`inv`: world to object), with `tmax`: the
/// parameterisation kept, so `t` is the same number in both spaces.
#[inline(always)]
fn object_ray(inv: &Affine3A, ray: &Ray, tmax: f32) -> Ray {
    Ray {
        origin: inv.transform_point3(ray.origin),
        tmin: ray.tmin,
        direction: inv.transform_vector3(ray.direction),
        tmax,
    }
}

impl Tlas {
    /// The TLAS walk of up to [`PACKET`] rays ([`BoxPacket`]): where the lanes share direction
    /// signs, each node's four boxes culled with the packet's interval and an instance's box
    /// with each lane's slab test (the conservative one), else every box with each lane's; the
    /// children some lane enters visited nearest first (by a distance no larger than any of its
    /// lanes'), each with the mask of those lanes; at an instance, those lanes still open go
    /// through its BLAS as one packet, with their `tmax` the closest hit so far. Slots whose mask shares no bit with
    /// `ray_mask` are not entered (all ones: only instances of mask `0` are hidden, as in the
    /// single-ray walk). Returns the closest hits (`ANY`: none) and the mask of blocked lanes
    /// (`ANY` only).
    #[inline(always)]
    fn walk_packet<T: TriangleTest, L: Lane, const N: usize, const ANY: bool>(
        &self,
        blases: &[impl Blas<L, N>],
        rays: &[Ray],
        ray_mask: u32,
    ) -> ([Option<InstanceHit>; PACKET], u32) {
        let mut best = [None; PACKET];
        let mut p = BoxPacket::new(rays);
        if p.active() == 0 || self.nodes.is_empty() {
            return (best, 0);
        }
        let mut blocked = 0u32;
        // As in the single-ray walk: at most `3 (d - 1) + 1` entries for a tree of depth `d`.
        let mut stack = MaskStack::<{ 3 * STACK_SIZE + 1 }>::new();
        let (mut cur, mut lanes) = (0u32, p.active());
        loop {
            if cur & LEAF_BIT == 0 {
                if let Some(node) = self.nodes.get(cur as usize) {
                    let mut leaves = 0u32;
                    for (s, &c) in node.child.iter().enumerate() {
                        leaves |= u32::from(c & LEAF_BIT != 0) << s;
                    }
                    let (hit_by, near) = p.children(&node.bounds, lanes, leaves);
                    let base = stack.len();
                    for s in 0..4 {
                        if hit_by[s] != 0 && node.mask[s] & ray_mask != 0 {
                            // Any hit: slot order (equal distances keep the order of pushing
                            // reversed, the lowest slot on top), as the single-ray walk; `-inf`,
                            // so that no lane is culled at the pop (an any-hit walk's `tmax`
                            // never shrinks, and may be negative: a range behind the origin;
                            // found by the `bvh` fuzz target with `0.0` here).
                            let e = Entry {
                                code: node.child[s],
                                dist: if ANY { f32::NEG_INFINITY } else { near[s] },
                                mask: hit_by[s],
                            };
                            // NOTE: cannot fail: the builder bounds the TLAS's depth by
                            // `STACK_SIZE` (as the single-ray walk relies on too).
                            let pushed = stack.push_sorted(base, e);
                            debug_assert!(pushed, "the builder bounds the TLAS's depth");
                        }
                    }
                }
            } else if cur != EMPTY_CHILD {
                let i = cur & !LEAF_BIT;
                let open = lanes & p.active();
                if open != 0
                    && self.masks.get(i as usize).is_some_and(|&m| m & ray_mask != 0)
                    && let Some(inv) = self.inverse.get(i as usize)
                    && let Some(blas) = self
                        .blas
                        .get(i as usize)
                        .and_then(|&b| blases.get(b as usize))
                        .map(|b| b.blas())
                {
                    // Lanes not open: the first open lane's ray with an empty range (inactive),
                    // not a zero direction, whose signs would make the BLAS packet take its
                    // lanes for incoherent and trace them as single rays.
                    let first = open.trailing_zeros() as usize;
                    let empty = Ray {
                        tmax: f32::NEG_INFINITY,
                        ..object_ray(inv, &rays[first], p.tmax(first))
                    };
                    let mut local = [empty; PACKET];
                    let mut m = open;
                    while m != 0 {
                        let l = m.trailing_zeros() as usize;
                        m &= m - 1;
                        local[l] = object_ray(inv, &rays[l], p.tmax(l));
                    }
                    if ANY {
                        let mut out = [false; PACKET];
                        packet::occluded_packet::<T, L, N, f32x8, PACKET>(
                            blas,
                            &local,
                            &mut out,
                            packet::DEFAULT_SWITCH,
                        );
                        let mut now = 0u32;
                        for (l, &o) in out.iter().enumerate() {
                            now |= u32::from(o) << l;
                        }
                        if now != 0 {
                            blocked |= now;
                            p.retire(now);
                            if p.active() == 0 {
                                return (best, blocked);
                            }
                        }
                    } else {
                        let mut hits = [None; PACKET];
                        packet::intersect_packet::<T, L, N, f32x8, PACKET>(
                            blas,
                            &local,
                            &mut hits,
                            packet::DEFAULT_SWITCH,
                        );
                        let (mut closer, mut t) = (0u32, [0f32; PACKET]);
                        for (l, h) in hits.iter().enumerate() {
                            if let Some(h) = *h {
                                best[l] = Some(InstanceHit { hit: h, instance: i });
                                closer |= 1 << l;
                                t[l] = h.t;
                            }
                        }
                        if closer != 0 {
                            p.set_tmax(closer, &t);
                        }
                    }
                }
            }
            // The next entry that some open lane can still reach.
            loop {
                let Some(e) = stack.pop() else {
                    return (best, blocked);
                };
                let mut keep = 0u32;
                let mut m = e.mask & p.active();
                while m != 0 {
                    let l = m.trailing_zeros() as usize;
                    m &= m - 1;
                    keep |= u32::from(!beyond::<Conservative<T>>(e.dist, p.tmax(l))) << l;
                }
                if keep != 0 {
                    (cur, lanes) = (e.code, keep);
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::Bvh4;

    /// One BLAS: the 4-wide BVH of an icosphere subdivided `level` times.
    fn sphere_blas(level: u32) -> [Bvh4; 1] {
        let tris = crate::scene::icosphere(level).to_soup();
        let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        [Bvh4::from_bvh2(&b2, &tris[..]).unwrap()]
    }

    /// The union of the masks of the instances below child code `c`.
    fn below(nodes: &[TlasNode], masks: &[u32], c: u32) -> u32 {
        if c == EMPTY_CHILD {
            0
        } else if c & LEAF_BIT != 0 {
            masks[(c & !LEAF_BIT) as usize]
        } else {
            nodes[c as usize]
                .child
                .iter()
                .fold(0, |a, &k| a | below(nodes, masks, k))
        }
    }

    #[test]
    fn refit_and_back_is_the_build() {
        // Refitted to other placements (every instance moved and turned, some left out) and
        // back: the 4-wide nodes (boxes, codes, masks) and the binary tree are the build's, bit
        // for bit; in between, every slot's box is the union of the boxes below it.
        let blases = sphere_blas(2);
        let mut rng = crate::scene::Rng::new(6);
        let mut place_all = |spread: f32| -> Vec<Instance> {
            (0..200)
                .map(|i| {
                    let q = glam::Quat::from_axis_angle(rng.unit_vector(), rng.range(0.0, 6.0));
                    let t = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * spread;
                    Instance::new(Affine3A::from_rotation_translation(q, t), 0).with_mask(1 << (i % 5))
                })
                .collect()
        };
        let first = place_all(40.0);
        let mut other = place_all(60.0);
        other[7].transform = Affine3A::from_translation(Vec3::NAN);
        let built = Tlas::build(&first, &blases).unwrap();
        let mut t = built.clone();
        assert!(t.refit(&other, &blases));
        assert_eq!(t.left_out(), 1);
        fn union_below(t: &Tlas, c: u32) -> Aabb {
            if c == EMPTY_CHILD {
                Aabb::EMPTY
            } else if c & LEAF_BIT != 0 {
                let i = c & !LEAF_BIT;
                let leaf = t
                    .bvh
                    .nodes
                    .iter()
                    .find(|n| n.is_leaf() && t.bvh.prim_indices[n.prim_range()] == [i]);
                leaf.map_or(Aabb::EMPTY, |n| n.aabb())
            } else {
                t.nodes[c as usize]
                    .child
                    .iter()
                    .fold(Aabb::EMPTY, |a, &k| a.union(&union_below(t, k)))
            }
        }
        for n in &t.nodes {
            for (s, &c) in n.child.iter().enumerate() {
                assert_eq!(n.bounds.get(s), union_below(&t, c), "slot {s}");
            }
        }
        assert!(t.refit(&first, &blases));
        assert_eq!(t.left_out(), 0);
        assert_eq!(t.bvh.nodes, built.bvh.nodes);
        for (a, b) in t.nodes.iter().zip(&built.nodes) {
            assert_eq!((a.child, a.mask), (b.child, b.mask));
            for s in 0..4 {
                let (x, y) = (a.bounds.get(s), b.bounds.get(s));
                assert_eq!(
                    (x.min.to_array(), x.max.to_array()),
                    (y.min.to_array(), y.max.to_array())
                );
            }
        }
    }

    #[test]
    fn slot_masks_are_the_union_below() {
        let blases = sphere_blas(1);
        let mut rng = crate::scene::Rng::new(5);
        let inst: Vec<Instance> = (0..300)
            .map(|i| {
                let t = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 50.0;
                // One in ten left out (a NaN transform), with a bit of its own that must not
                // reach any slot.
                if i % 10 == 3 {
                    Instance::new(Affine3A::from_translation(Vec3::NAN), 0).with_mask(1 << 20)
                } else {
                    Instance::new(Affine3A::from_translation(t), 0).with_mask(1 << (i % 7))
                }
            })
            .collect();
        let mut tlas = Tlas::build(&inst, &blases).unwrap();
        assert_eq!(tlas.left_out(), 30);
        let check = |tlas: &Tlas| {
            assert!(tlas.nodes.len() > 20);
            for n in &tlas.nodes {
                for (slot, &c) in n.child.iter().enumerate() {
                    assert_eq!(n.mask[slot], below(&tlas.nodes, &tlas.masks, c));
                }
            }
            // The root sees every bit of the instances in the tree, none of the left-out ones'.
            assert!(tlas.nodes.iter().all(|n| n.mask.iter().all(|m| m & 1 << 20 == 0)));
            let root = tlas.nodes[0].mask.iter().fold(0, |a, b| a | b);
            let want = (0..300).filter(|i| i % 10 != 3).fold(0, |a, i| a | tlas.masks[i]);
            assert_eq!(root, want);
        };
        check(&tlas);
        // Bit 0 gone from every instance (those of `i % 7 == 0`): gone from every slot.
        for i in (0..300).step_by(7) {
            assert!(tlas.set_mask(i, 0));
        }
        check(&tlas);
        assert_eq!(tlas.mask(7), Some(0));
        // A left-out instance's new mask reaches no slot either.
        assert!(tlas.set_mask(13, 1 << 20 | 1));
        check(&tlas);
        assert!(tlas.nodes.iter().all(|n| n.mask.iter().all(|m| m & 1 == 0)));
        // Many at once: the same slot masks as one `set_mask` per change.
        let changes: Vec<(usize, u32)> = (0..300).step_by(3).map(|i| (i, (i as u32 * 37) & 0xff)).collect();
        let mut one_by_one = tlas.clone();
        for &(i, m) in &changes {
            assert!(one_by_one.set_mask(i, m));
        }
        assert!(tlas.set_masks(&changes));
        check(&tlas);
        assert_eq!(tlas.masks, one_by_one.masks);
        assert!(tlas.nodes.iter().zip(&one_by_one.nodes).all(|(a, b)| a.mask == b.mask));
        // One index out of range: nothing changes.
        assert!(!tlas.set_masks(&[(0, 1), (300, 1)]));
        assert_eq!(tlas.masks, one_by_one.masks);
    }
}
