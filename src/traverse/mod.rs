//! Single-ray BVH traversal: closest hit ([`intersect_scalar`]) and any hit ([`occluded_scalar`])
//! through a binary BVH, plus brute force over all primitives ([`intersect_brute_force`],
//! [`occluded_brute_force`]).
//!
//! Pipeline stage: after [`build`](crate::build) (or any other producer of [`Node`] arrays).
//! Input: a [`Bvh2Ref`] (nodes and primitive indices, borrowed), the triangles as any
//! [`Triangles`](crate::geometry::Triangles), and a [`Ray`](crate::Ray). Output: the closest
//! [`Hit`], or whether anything is hit. Core-only: no allocation; the stack lives on
//! the call stack.
//!
//! These scalar loops are the **reference** that later wide (BVH4/BVH8) and packet traversals are
//! checked against, so they favour being obviously right: the crate's robust slab test
//! ([`intersect_aabb_scalar`](crate::intersect::intersect_aabb_scalar), Ize 2013) on both
//! children, near child first, the far one pushed with its entry distance and skipped on pop if a
//! closer hit has been found since (the same comparison the slab test would make with the new
//! `tmax`, so the result equals brute force exactly). One exception: the triangle test's `t`
//! is rounded, and on a stack of coplanar, overlapping triangles (exact ties: a z-fight) that
//! rounding ranks the tied triangles by a few ulps and can put a `t` just before its box's
//! entry, beyond the slab test's slack; the traversal then returns another of the tied
//! triangles, its `t` a few ulps from brute force's (`tests/traverse.rs`: 12,000 nested coplanar
//! triangles up to 12 times larger than their distance from the ray's origin, 300 rays through
//! them: 30 ulps apart at most; the error grows with the triangles' size against that distance).
//!
//! # The triangle test is chosen at compile time
//! [`TriangleTest`] is implemented by the marker types [`Moller`] and [`Watertight`]; traversal is
//! generic over it, so the test is inlined into the leaf loop:
//! `intersect_scalar::<Watertight, _>(bvh, &tris, &ray)`.
//!
//! # Hit filters
//! The single-ray traversals (BVH2, BVH4, BVH8, brute force, instances, incoherent batches) have a
//! `*_filtered` form taking a [`HitFilter`] (any closure `FnMut(&Hit) -> bool`): only the hits it
//! accepts count, as with Embree's intersection filter
//! functions (alpha tests, masks, skipping the triangle a ray leaves from). The filter is a type
//! parameter, inlined like the triangle test: `intersect_scalar_filtered::<Watertight, _, _>(bvh,
//! &tris, &ray, |h: &Hit| h.prim != origin_prim)`.
//!
//! # Depth and the stack
//! The stack holds [`STACK_SIZE`] entries, enough for any tree of depth `STACK_SIZE + 1` or less;
//! every builder in [`build`](crate::build) caps the depth at
//! [`BuildParams::max_depth`](crate::build::BuildParams::max_depth) `<=` [`MAX_DEPTH`]
//! `= STACK_SIZE`. A deeper tree (made elsewhere) is still answered exactly: when a push would
//! overflow the stack, the traversal finishes with a linear scan over all of the tree's primitive
//! indices (slow, but never wrong for a valid tree). A malformed tree (indices out of range, a
//! cycle) never panics and never loops forever: out-of-range entries are skipped and after as many
//! node visits as there are nodes, the same linear scan ends the search.
//!
//! ```
//! use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, geometry::TriangleSoup, scene};
//! use strahl::traverse::{Watertight, intersect_brute_force, intersect_scalar, occluded_scalar};
//! let mesh = scene::icosphere(2);
//! let tris = mesh.as_indexed();
//! let (bvh, _) = Bvh2::build(&tris, &BuildParams::default()).unwrap();
//! let ray = Ray::new(Vec3::new(0.1, 0.2, -5.0), Vec3::Z);
//! let hit = intersect_scalar::<Watertight, _>(bvh.view(), &tris, &ray).unwrap();
//! assert_eq!(Some(hit), intersect_brute_force::<Watertight, _>(&tris, &ray));
//! assert!((hit.t - 4.0).abs() < 0.05); // the sphere's near side, close to z = -1
//! assert!(occluded_scalar::<Watertight, _>(bvh.view(), &tris, &ray));
//! ```

mod brute;
mod bvh2;
mod node;
#[cfg(feature = "alloc")]
pub mod order;
pub mod packet;
pub(crate) mod stack;
pub mod wide;

pub use brute::{
    intersect_brute_force, intersect_brute_force_filtered, occluded_brute_force, occluded_brute_force_filtered,
};
pub use bvh2::{intersect_scalar, intersect_scalar_filtered, occluded_scalar, occluded_scalar_filtered};
pub use node::{Bvh2Ref, Node};
pub use wide::BatchHit;

use crate::geometry::{Hit, Triangle};
use crate::intersect::{HitLanes, PreparedPacket, PreparedRay, TriangleLanes, moller, watertight};
use crate::math::Lane;

/// Entries of the traversal stack (on the call stack: `STACK_SIZE * 8` bytes).
///
/// ```
/// use strahl::{build::{Bvh2, BuildParams}, traverse::STACK_SIZE};
/// let tris = strahl::scene::thin_soup(10_000, 1);
/// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap();
/// // Near-first traversal pushes at most one node per level below the root.
/// assert!(bvh.validate(&tris[..]).unwrap().max_depth as usize <= STACK_SIZE + 1);
/// ```
pub const STACK_SIZE: usize = 64;

/// The deepest tree (counting the root as depth 1) whose traversal never overflows the stack, and
/// the largest [`BuildParams::max_depth`](crate::build::BuildParams::max_depth) a builder accepts.
///
/// Near-first traversal pushes at most one node per level below the root, so a tree of depth
/// `STACK_SIZE + 1` would fit; the builders keep one level in reserve.
///
/// ```
/// use strahl::{Vec3, build::{Bvh2, BuildParams}, traverse::MAX_DEPTH};
/// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
/// let deepest = BuildParams { max_depth: MAX_DEPTH, ..BuildParams::default() };
/// assert!(Bvh2::build(&tris[..], &deepest).is_ok());
/// let deeper = BuildParams { max_depth: MAX_DEPTH + 1, ..BuildParams::default() };
/// assert!(Bvh2::build(&tris[..], &deeper).is_err());
/// ```
pub const MAX_DEPTH: u32 = STACK_SIZE as u32;

/// A ray/triangle test, chosen at compile time by a marker type ([`Moller`], [`Watertight`]).
///
/// ```
/// use strahl::{Ray, Vec3, intersect::PreparedRay, traverse::{Moller, TriangleTest, Watertight}};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// assert_eq!(Moller::intersect(&ray, &tri, 3).unwrap().t, 2.0);
/// assert_eq!(Watertight::intersect(&ray, &tri, 3).unwrap().prim, 3);
/// assert_eq!(Watertight::NAME, "watertight");
/// ```
pub trait TriangleTest {
    /// A short name for reports and bench labels.
    ///
    /// ```
    /// use strahl::traverse::{Fast, Moller, TriangleTest, Watertight};
    /// assert_eq!((Moller::NAME, Watertight::NAME), ("moller", "watertight"));
    /// assert_eq!(<Fast<Moller> as TriangleTest>::NAME, Moller::NAME); // the box test keeps the name
    /// ```
    const NAME: &'static str;
    /// `true` if the test reads [`PreparedRay::k`] and [`PreparedRay::shear`]; the traversals
    /// skip computing them otherwise, leaving them at [`PreparedRay::EMPTY`]'s values (every
    /// other field as [`PreparedRay::new`] sets it). Defaults to `true`.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::PreparedRay, traverse::{Moller, TriangleTest, Watertight}};
    /// assert!(Watertight::WATERTIGHT && !Moller::WATERTIGHT);
    /// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
    /// let mut ray = PreparedRay::new(&Ray::new(Vec3::new(0.1, 0.2, 0.0), Vec3::new(0.1, 0.0, 1.0)));
    /// let full = Moller::intersect(&ray, &tri, 0);
    /// (ray.k, ray.shear) = (PreparedRay::EMPTY.k, PreparedRay::EMPTY.shear); // skipped for `Moller`
    /// assert!(full.is_some() && Moller::intersect(&ray, &tri, 0) == full); // Möller never reads them
    /// ```
    const WATERTIGHT: bool = true;
    /// `true` (the default): the single-ray traversals test boxes with the conservative slab
    /// test ([`intersect_aabb_scalar`](crate::intersect::intersect_aabb_scalar)), which never
    /// culls a box a ray touches. (Closest hits then equal brute force's except where two hits
    /// lie within the triangle test's rounding of each other at a box's entry distance, when the
    /// later-found one can be culled: found by fuzzing, seed `fuzz/seeds/bvh/near-tie-edge-origin`.)
    /// `false` for [`Fast`]: the fast one
    /// ([`intersect_aabb_fast_scalar`](crate::intersect::aabb::intersect_aabb_fast_scalar)).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, traverse::{Fast, Moller, TriangleTest}};
    /// assert!(Moller::CONSERVATIVE_BOXES && !<Fast<Moller> as TriangleTest>::CONSERVATIVE_BOXES);
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z); // far from any box's faces
    /// let fast = bvh.intersect::<Fast<Moller>, _>(&tris[..], &ray);
    /// assert!(fast.is_some() && fast == bvh.intersect::<Moller, _>(&tris[..], &ray));
    /// ```
    const CONSERVATIVE_BOXES: bool = true;
    /// The hit of `ray` with `tri` (reported with `prim`), if any, within `[tmin, tmax)`.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::PreparedRay, traverse::{TriangleTest, Watertight}};
    /// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
    /// let o = Vec3::new(0.0, 0.0, -1.0);
    /// let hit = Watertight::intersect(&PreparedRay::new(&Ray::new(o, Vec3::Z)), &tri, 5).unwrap();
    /// assert_eq!((hit.t, hit.prim), (3.0, 5));
    /// let short = PreparedRay::new(&Ray::with_range(o, Vec3::Z, 0.0, 3.0));
    /// assert!(Watertight::intersect(&short, &tri, 5).is_none()); // `tmax` is exclusive
    /// ```
    fn intersect(ray: &PreparedRay, tri: &Triangle, prim: u32) -> Option<Hit>;
    /// The closest hit among `N` SoA triangles (ties: lowest lane), for wide-BVH leaves.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8}, traverse::{Moller, TriangleTest, Watertight}};
    /// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
    /// let leaf = TriangleX8::pack(&[tri(3.0), tri(2.0), tri(2.0)], &[7, 8, 9]);
    /// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
    /// let hit = Moller::intersect_lanes(&ray, &leaf).unwrap();
    /// assert_eq!((hit.t, hit.prim), (2.0, 8)); // a tie at t = 2: the lower lane
    /// assert_eq!(Watertight::intersect_lanes(&ray, &leaf).map(|h| (h.t, h.prim)), Some((2.0, 8)));
    /// ```
    fn intersect_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> Option<Hit>;
    /// The mask of lanes of `tris` hit within `[tmin, tmax)`, for any-hit queries.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX4}, traverse::{Moller, TriangleTest, Watertight}};
    /// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
    /// let leaf = TriangleX4::pack(&[tri(3.0), tri(-1.0), tri(2.0)], &[0, 1, 2]);
    /// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
    /// assert_eq!(Watertight::hit_mask_lanes(&ray, &leaf), 0b101); // lane 1 lies behind the origin
    /// assert_eq!(Moller::hit_mask_lanes(&ray, &leaf), 0b101);
    /// ```
    fn hit_mask_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> u32;
    /// The closest hit among `N` SoA triangles that `accept` takes (ties: lowest lane), for the
    /// hit filters ([`HitFilter`]): the hits offered nearest first, each once. The default tests
    /// the pack again without each rejected lane ([`intersect_lanes`](Self::intersect_lanes)
    /// at most `N` times); [`Moller`] and [`Watertight`] compute the lanes once and offer them in
    /// turn (the same hits, in the same order).
    ///
    /// ```
    /// use strahl::{Hit, Ray, Vec3, intersect::{PreparedRay, TriangleX8}, traverse::{Moller, TriangleTest}};
    /// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
    /// let leaf = TriangleX8::pack(&[tri(3.0), tri(2.0), tri(4.0)], &[7, 8, 9]);
    /// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
    /// let mut offered = Vec::new();
    /// let hit = Moller::closest_accepted_lanes(&ray, &leaf, |h: &Hit| {
    ///     offered.push(h.prim);
    ///     h.prim != 8
    /// });
    /// assert_eq!(hit.map(|h| (h.t, h.prim)), Some((3.0, 7)));
    /// assert_eq!(offered, [8, 7]); // nearest first
    /// ```
    #[inline(always)]
    fn closest_accepted_lanes<L: Lane, const N: usize>(
        ray: &PreparedRay,
        tris: &TriangleLanes<L, N>,
        mut accept: impl FnMut(&Hit) -> bool,
    ) -> Option<Hit> {
        let h = Self::intersect_lanes(ray, tris)?;
        if accept(&h) {
            return Some(h);
        }
        retest_without::<Self, L, N>(ray, tris, h, &mut accept)
    }
    /// `N` rays against one triangle: lanes hit closer than their `tmax` get `hits` and `tmax`
    /// updated; returns the mask of lanes hit (for packet traversal).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::{HitLanes, PreparedPacket4}, traverse::{TriangleTest, Watertight}};
    /// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
    /// let rays = [
    ///     Ray::new(Vec3::ZERO, Vec3::Z),
    ///     Ray::new(Vec3::new(3.0, 0.0, 0.0), Vec3::Z), // beside the triangle
    ///     Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z),
    ///     Ray::with_range(Vec3::ZERO, Vec3::Z, 0.0, 1.0), // ends before it
    /// ];
    /// let (mut packet, mut hits) = (PreparedPacket4::new(&rays), HitLanes::default());
    /// assert_eq!(Watertight::intersect_packet(&mut packet, &tri, 0, &mut hits), 0b0101);
    /// assert_eq!((hits.get(0).t, hits.get(2).t), (2.0, 3.0));
    /// ```
    fn intersect_packet<L: Lane, const N: usize>(
        rays: &mut PreparedPacket<L, N>,
        tri: &Triangle,
        prim: u32,
        hits: &mut HitLanes<L, N>,
    ) -> u32;
    /// For coherent packets' leaves: [`moller::closest_packet_leaf`]'s answer, where the test
    /// has such a kernel (`None`: test each ray on its own).
    #[doc(hidden)]
    #[inline(always)]
    fn closest_packet_leaf<R: Lane, L: Lane, const N: usize>(
        origin: [R; 3],
        direction: [R; 3],
        tmin: R,
        tmax: R,
        packs: &[TriangleLanes<L, N>],
    ) -> Option<(u32, R, R, R, R)> {
        let _ = (origin, direction, tmin, tmax, packs);
        None
    }
}

/// Möller-Trumbore ([`moller::intersect_scalar`]): fast, not watertight.
///
/// On edges and grazing rays its rounding can report a hit just outside the triangle (by less
/// than an ulp of the coordinates), or an ill-conditioned `t` on a ray almost parallel to the
/// triangle's plane. Such a hit can lie outside the triangle's box, so brute force may report it
/// while a BVH traversal, which never opens that box, does not. Use [`Watertight`] where every
/// traversal must agree with brute force on such rays (`tests/packet_edges.rs` shows both cases).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, traverse::{Moller, intersect_brute_force}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
/// let hit = bvh.intersect::<Moller, _>(&tris[..], &ray).unwrap();
/// // Away from edges and grazing angles, the same hit as brute force.
/// assert_eq!(Some(hit), intersect_brute_force::<Moller, _>(&tris[..], &ray));
/// ```
#[derive(Clone, Copy, Debug, Default)]
pub struct Moller;

/// Woop, Benthin and Wald's watertight test ([`watertight::intersect_scalar`]).
///
/// ```
/// use strahl::{build::{Bvh2, BuildParams}, scene::{self, Aim}, traverse::Watertight};
/// let mesh = scene::icosphere(2);
/// let tris = mesh.as_indexed();
/// let (bvh, _) = Bvh2::build(&tris, &BuildParams::default()).unwrap();
/// // Rays aimed exactly at the closed mesh's shared edges: none slips through a crack.
/// let rays = scene::aimed_rays(&mesh, Aim::Edges, 2, 3.0, 1);
/// assert!(rays.iter().all(|r| bvh.intersect::<Watertight, _>(&tris, r).is_some()));
/// ```
#[derive(Clone, Copy, Debug, Default)]
pub struct Watertight;

/// A triangle test `T` with the single-ray traversals' box test chosen by `CONSERVATIVE`: the
/// conservative slab test (`true`, what `T` alone gives) or the fast one (`false`: [`Fast`]).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, traverse::{Fast, TriangleTest, Watertight, WithBoxes}};
/// assert!(<WithBoxes<Watertight, true> as TriangleTest>::CONSERVATIVE_BOXES);
/// assert!(!<Fast<Watertight> as TriangleTest>::CONSERVATIVE_BOXES);
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
/// let conservative = bvh.intersect::<WithBoxes<Watertight, true>, _>(&tris[..], &ray);
/// assert_eq!(conservative, bvh.intersect::<Watertight, _>(&tris[..], &ray)); // what `Watertight` alone gives
/// ```
#[derive(Clone, Copy, Debug, Default)]
pub struct WithBoxes<T, const CONSERVATIVE: bool>(core::marker::PhantomData<T>);

/// The triangle test `T` with the **fast slab test** in the single-ray traversals (scalar BVH2,
/// BVH4, BVH8, their batches): each plane distance one fused multiply-add, `bound * inv -
/// origin * inv`, and a box hit when `near <= far`, as Embree tests boxes unless a scene asks for
/// `RTC_SCENE_FLAG_ROBUST`
/// ([`intersect_aabb_fast_scalar`](crate::intersect::aabb::intersect_aabb_fast_scalar)).
///
/// What it trades: the conservative test (the default, [`TriangleTest::CONSERVATIVE_BOXES`])
/// never culls a box a ray touches; the fast one can cull a box the ray grazes within about
/// `|origin * inv| 2^-24` of its distance, and with it a hit on the box's surface. A direction
/// component below `1e-18` counts as `1e-18` (the reciprocal's clamp, as in Embree,
/// [`PreparedRay::with_fast_inv`]): meant for directions of ordinary length; one scaled down to
/// `1e-17` or less can miss boxes it crosses. Every answer it gives is still a real hit (never closer than the
/// true closest one; an occlusion it reports is real): it only misses. Measured on the trace
/// bench (`benches/RESULTS.md`): 4 to 12% faster on primary, diffuse and shadow rays, BVH8, both scenes; on
/// rays aimed at a closed mesh's edges and vertices, 20 of 20,496 fall through with the
/// watertight test where none do with the conservative one. Ray packets keep the conservative
/// test whatever the type (they trace `Fast<T>` as `T`).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Fast, Moller}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
/// let fast = b8.intersect::<Fast<Moller>>(&ray).unwrap();
/// assert_eq!(Some(fast), b8.intersect::<Moller>(&ray)); // a ray through the middle: the same hit
/// assert!(b2.intersect::<Fast<Moller>, _>(&tris[..], &ray).is_some());
/// ```
pub type Fast<T> = WithBoxes<T, false>;

/// `T` with the conservative box test, whatever `T` asks for (the packet traversals).
pub(crate) type Conservative<T> = WithBoxes<T, true>;

impl<T: TriangleTest, const CONSERVATIVE: bool> TriangleTest for WithBoxes<T, CONSERVATIVE> {
    const NAME: &'static str = T::NAME;
    const WATERTIGHT: bool = T::WATERTIGHT;
    const CONSERVATIVE_BOXES: bool = CONSERVATIVE;
    #[inline(always)]
    fn intersect(ray: &PreparedRay, tri: &Triangle, prim: u32) -> Option<Hit> {
        T::intersect(ray, tri, prim)
    }
    #[inline(always)]
    fn intersect_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> Option<Hit> {
        T::intersect_lanes(ray, tris)
    }
    #[inline(always)]
    fn hit_mask_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> u32 {
        T::hit_mask_lanes(ray, tris)
    }
    #[inline(always)]
    fn closest_accepted_lanes<L: Lane, const N: usize>(
        ray: &PreparedRay,
        tris: &TriangleLanes<L, N>,
        accept: impl FnMut(&Hit) -> bool,
    ) -> Option<Hit> {
        T::closest_accepted_lanes(ray, tris, accept)
    }
    #[inline(always)]
    fn intersect_packet<L: Lane, const N: usize>(
        rays: &mut PreparedPacket<L, N>,
        tri: &Triangle,
        prim: u32,
        hits: &mut HitLanes<L, N>,
    ) -> u32 {
        T::intersect_packet(rays, tri, prim, hits)
    }
    #[inline(always)]
    fn closest_packet_leaf<R: Lane, L: Lane, const N: usize>(
        origin: [R; 3],
        direction: [R; 3],
        tmin: R,
        tmax: R,
        packs: &[TriangleLanes<L, N>],
    ) -> Option<(u32, R, R, R, R)> {
        T::closest_packet_leaf(origin, direction, tmin, tmax, packs)
    }
}

/// A test each candidate hit must pass to count, as Embree's intersection filter functions:
/// alpha-tested leaves (a texture lookup at the hit's `u`, `v`), skipping the triangle a
/// secondary ray leaves from, masks by primitive. The single-ray traversals take one in their
/// `*_filtered` forms ([`BvhWide::intersect_filtered`](crate::layout::BvhWide::intersect_filtered),
/// [`BvhWide::occluded_filtered`](crate::layout::BvhWide::occluded_filtered),
/// [`wide::intersect_filtered`], [`intersect_scalar_filtered`], [`intersect_brute_force_filtered`],
/// and their any-hit forms), the packets in [`packet::intersect_packet_filtered`] and
/// [`packet::occluded_packet_filtered`], and the instances (over [`InstanceHit`](crate::layout::InstanceHit)s)
/// in [`Tlas::intersect_filtered`](crate::layout::Tlas::intersect_filtered) and
/// [`Tlas::intersect_masked_filtered`](crate::layout::Tlas::intersect_masked_filtered); every
/// closure `FnMut(&Hit) -> bool` is one.
///
/// The closest hit is then the nearest hit the filter accepts (ties as without a filter), and
/// an any-hit query reports whether some hit is accepted. The traversals offer hits in no fixed
/// order, and may offer a hit more than once or offer hits beyond the answer, so the filter
/// should be a function of the hit (its `prim`, `t`, `u`, `v`): then every traversal, width and
/// the brute-force reference give the same answer. A leaf pack's lanes are tested once and its
/// hits offered nearest first ([`TriangleTest::closest_accepted_lanes`]): a rejected hit costs the
/// selection of the next one, an accepted one a call (and, for any-hit queries, the pack's
/// closest-hit test in place of its hit-mask test). The monomorphised traversals without a
/// filter ([`AcceptAll`]) are the unfiltered ones, with no call and no test.
///
/// A closure needs its argument's type written out (`|h: &Hit| ...`, not `|h| ...`): the trait is
/// implemented for every `FnMut(&H) -> bool`, so the compiler cannot infer `H` from the call. A
/// filter behind a pointer works too (`&mut dyn FnMut(&Hit) -> bool` is such a closure); a
/// filter type of your own is passed by value (keep state you need afterwards outside it, as the
/// counting closure below does).
///
/// ```
/// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{HitFilter, Watertight}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris = [tri(2.0), tri(3.0), tri(4.0)];
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let ray = Ray::new(Vec3::ZERO, Vec3::Z);
/// // Triangle 0 is a cut-out (say, an alpha-tested leaf): the ray goes through it.
/// let hit = b8.intersect_filtered::<Watertight>(&ray, |h: &Hit| h.prim != 0).unwrap();
/// assert_eq!((hit.prim, hit.t), (1, 3.0));
/// // A filter with state: count the candidates it was offered.
/// let mut offered = 0;
/// assert!(!b8.occluded_filtered::<Watertight>(&ray, |_: &Hit| {
///     offered += 1;
///     false // every hit rejected
/// }));
/// assert_eq!(offered, 3);
/// // Or a type of its own: a mask of primitives.
/// struct Mask<'a>(&'a [bool]);
/// impl HitFilter for Mask<'_> {
///     fn accept(&mut self, hit: &Hit) -> bool {
///         self.0.get(hit.prim as usize).copied().unwrap_or(false)
///     }
/// }
/// let hit = b8.intersect_filtered::<Watertight>(&ray, Mask(&[false, false, true])).unwrap();
/// assert_eq!(hit.prim, 2);
/// ```
///
/// The hit type `H` is [`Hit`] for the traversals of one tree and
/// [`InstanceHit`](crate::layout::InstanceHit) (the hit and its instance) for
/// [`Tlas::intersect_filtered`](crate::layout::Tlas::intersect_filtered).
pub trait HitFilter<H = Hit> {
    /// `true` if every hit passes without a call ([`AcceptAll`]): the traversals then skip the
    /// filter altogether. Leave it `false`.
    const ACCEPTS_ALL: bool = false;
    /// `true` if `hit` counts.
    ///
    /// ```
    /// use strahl::{Hit, traverse::HitFilter};
    /// let mut near = |h: &Hit| h.t < 5.0; // closures are filters
    /// assert!(near.accept(&Hit { t: 1.0, u: 0.2, v: 0.3, prim: 0 }));
    /// assert!(!near.accept(&Hit { t: 9.0, u: 0.2, v: 0.3, prim: 0 }));
    /// ```
    fn accept(&mut self, hit: &H) -> bool;
}

/// The filter that accepts every hit, without being called: what the unfiltered traversals use.
///
/// ```
/// use strahl::{Hit, traverse::{AcceptAll, HitFilter}};
/// assert!(<AcceptAll as HitFilter>::ACCEPTS_ALL && HitFilter::<Hit>::accept(&mut AcceptAll, &Hit::NONE));
/// ```
#[derive(Clone, Copy, Debug, Default)]
pub struct AcceptAll;

impl<H> HitFilter<H> for AcceptAll {
    const ACCEPTS_ALL: bool = true;
    #[inline(always)]
    fn accept(&mut self, _: &H) -> bool {
        true
    }
}

impl<H, F: FnMut(&H) -> bool> HitFilter<H> for F {
    #[inline(always)]
    fn accept(&mut self, hit: &H) -> bool {
        self(hit)
    }
}

/// The closest hit of `r` in `pack` that `f` accepts (ties: the lowest lane).
#[inline(always)]
pub(crate) fn closest_in_pack<T: TriangleTest, L: Lane, const N: usize, F: HitFilter>(
    r: &PreparedRay,
    pack: &TriangleLanes<L, N>,
    f: &mut F,
) -> Option<Hit> {
    if F::ACCEPTS_ALL {
        T::intersect_lanes(r, pack)
    } else {
        T::closest_accepted_lanes(r, pack, |h: &Hit| f.accept(h))
    }
}

/// [`TriangleTest::closest_accepted_lanes`]'s default after `rejected`: the pack tested again
/// without the lane that gave it, until a hit is accepted or none is left (at most `N` tests).
#[cold]
#[inline(never)]
fn retest_without<T: TriangleTest + ?Sized, L: Lane, const N: usize>(
    r: &PreparedRay,
    pack: &TriangleLanes<L, N>,
    rejected: Hit,
    accept: &mut impl FnMut(&Hit) -> bool,
) -> Option<Hit> {
    let mut rest = *pack;
    let mut h = rejected;
    loop {
        // The lowest valid lane with the rejected hit's primitive (the one the kernel reports
        // among tied lanes); a malformed pack that repeats a primitive only loses a candidate.
        let lane = (0..N.min(32)).find(|&i| rest.valid >> i & 1 == 1 && rest.prim[i] == h.prim)?;
        rest.valid &= !(1 << lane);
        h = T::intersect_lanes(r, &rest)?;
        if accept(&h) {
            return Some(h);
        }
    }
}

/// `ray` prepared for the single-ray traversals under `T`: without the watertight fields for
/// Möller-Trumbore, with clamped reciprocals for the fast slab test.
#[inline(always)]
pub(crate) fn prepare<T: TriangleTest>(ray: &crate::geometry::Ray) -> PreparedRay {
    let r = PreparedRay::new_for(ray, T::WATERTIGHT);
    if T::CONSERVATIVE_BOXES { r } else { r.with_fast_inv() }
}

/// The box test of the single-ray traversals under `T`: the conservative slab test, or the fast
/// one for [`Fast`] tests. Entry distances and the mask of lanes hit.
#[inline(always)]
pub(crate) fn node_lanes<T: TriangleTest, L: Lane>(r: &PreparedRay, b: &crate::intersect::AabbLanes<L>) -> (L, u32) {
    if T::CONSERVATIVE_BOXES {
        crate::intersect::aabb::intersect_aabb_lanes(r, b)
    } else {
        crate::intersect::aabb::intersect_aabb_fast_lanes(r, b)
    }
}

/// [`node_lanes`] for one box (the scalar reference).
#[inline(always)]
pub(crate) fn node_scalar<T: TriangleTest>(r: &PreparedRay, b: &crate::geometry::Aabb) -> Option<f32> {
    if T::CONSERVATIVE_BOXES {
        crate::intersect::intersect_aabb_scalar(r, b)
    } else {
        crate::intersect::aabb::intersect_aabb_fast_scalar(r, b)
    }
}

/// `true` if a box entered at `tnear` lies beyond `tmax` under `T`'s box test: the negation of
/// its acceptance `near <= far` (with the conservative test's widening of `far`).
#[inline(always)]
pub(crate) fn beyond<T: TriangleTest>(tnear: f32, tmax: f32) -> bool {
    if T::CONSERVATIVE_BOXES {
        tnear > tmax + crate::math::abs(tmax) * crate::intersect::aabb::FAR_SLACK
    } else {
        tnear > tmax
    }
}

impl TriangleTest for Moller {
    const NAME: &'static str = "moller";
    const WATERTIGHT: bool = false;
    #[inline(always)]
    fn intersect(ray: &PreparedRay, tri: &Triangle, prim: u32) -> Option<Hit> {
        moller::intersect_scalar(ray, tri, prim)
    }
    #[inline(always)]
    fn intersect_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> Option<Hit> {
        moller::intersect_lanes(ray, tris)
    }
    #[inline(always)]
    fn hit_mask_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> u32 {
        moller::hit_mask(ray, tris)
    }
    #[inline(always)]
    fn closest_accepted_lanes<L: Lane, const N: usize>(
        ray: &PreparedRay,
        tris: &TriangleLanes<L, N>,
        accept: impl FnMut(&Hit) -> bool,
    ) -> Option<Hit> {
        moller::closest_accepted(ray, tris, accept)
    }
    #[inline(always)]
    fn intersect_packet<L: Lane, const N: usize>(
        rays: &mut PreparedPacket<L, N>,
        tri: &Triangle,
        prim: u32,
        hits: &mut HitLanes<L, N>,
    ) -> u32 {
        moller::intersect_packet(rays, tri, prim, hits)
    }
    #[inline(always)]
    fn closest_packet_leaf<R: Lane, L: Lane, const N: usize>(
        origin: [R; 3],
        direction: [R; 3],
        tmin: R,
        tmax: R,
        packs: &[TriangleLanes<L, N>],
    ) -> Option<(u32, R, R, R, R)> {
        Some(moller::closest_packet_leaf(origin, direction, tmin, tmax, packs))
    }
}

impl TriangleTest for Watertight {
    const NAME: &'static str = "watertight";
    #[inline(always)]
    fn intersect(ray: &PreparedRay, tri: &Triangle, prim: u32) -> Option<Hit> {
        watertight::intersect_scalar(ray, tri, prim)
    }
    #[inline(always)]
    fn intersect_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> Option<Hit> {
        watertight::intersect_lanes(ray, tris)
    }
    #[inline(always)]
    fn hit_mask_lanes<L: Lane, const N: usize>(ray: &PreparedRay, tris: &TriangleLanes<L, N>) -> u32 {
        watertight::hit_mask(ray, tris)
    }
    #[inline(always)]
    fn closest_accepted_lanes<L: Lane, const N: usize>(
        ray: &PreparedRay,
        tris: &TriangleLanes<L, N>,
        accept: impl FnMut(&Hit) -> bool,
    ) -> Option<Hit> {
        watertight::closest_accepted(ray, tris, accept)
    }
    #[inline(always)]
    fn intersect_packet<L: Lane, const N: usize>(
        rays: &mut PreparedPacket<L, N>,
        tri: &Triangle,
        prim: u32,
        hits: &mut HitLanes<L, N>,
    ) -> u32 {
        watertight::intersect_packet(rays, tri, prim, hits)
    }
}
