//! Packet traversal: 4, 8 or 16 rays in SoA lanes ([`f32x4`], [`f32x8`], [`f32x16`]) share one walk
//! of a wide BVH ([`BvhWideRef`]) or a binary one ([`Bvh2Ref`]) (Wald et al., "Interactive
//! rendering with coherent ray tracing", 2001).
//!
//! Pipeline stage: after [`layout`](crate::layout) (or [`build`](crate::build) for BVH2), beside
//! the single-ray [`wide`](super::wide) traversal. Input: up to `K` [`Ray`]s (a shorter slice leaves
//! the last lanes inactive; invalid rays are inactive lanes too). Output: one closest [`Hit`] or
//! any-hit answer per ray. Core-only: no allocation, fixed stacks on the call stack.
//!
//! | rays | lanes | wide BVH, closest / any | BVH2, closest / any | default switch |
//! |---|---|---|---|---|
//! | 4 | [`f32x4`] | [`intersect4`] / [`occluded4`] | [`intersect4_bvh2`] / [`occluded4_bvh2`] | [`DEFAULT_SWITCH4`] |
//! | 8 | [`f32x8`] | [`intersect8`] / [`occluded8`] | [`intersect8_bvh2`] / [`occluded8_bvh2`] | [`DEFAULT_SWITCH`] |
//! | 16 | [`f32x16`] | [`intersect16`] / [`occluded16`] | [`intersect16_bvh2`] / [`occluded16_bvh2`] | [`DEFAULT_SWITCH16`] |
//!
//! The named functions are thin wrappers of the generic [`intersect_packet`], [`occluded_packet`],
//! [`intersect_packet_bvh2`] and [`occluded_packet_bvh2`]; the batch functions
//! ([`intersect_batch_packets`], [`intersect_batch_bvh2`], ...) cut a slice into packets, and
//! [`TileShape`] lays out camera rays so that each packet is a coherent pixel tile. Hit filters
//! ([`HitFilter`]: alpha tests) go with wide-BVH packets through [`intersect_packet_filtered`]
//! and [`occluded_packet_filtered`].
//!
//! # Wide BVHs
//! - **Coherent packets** (every active lane with the same direction signs, directions within
//!   [`COHERENT_MIN_COS`] and origins within [`COHERENT_MAX_ORIGIN_SPREAD`], e.g. a camera tile)
//!   are culled with interval arithmetic (Wald, Boulos and Shirley 2007): one test of the packet's
//!   bounding interval against a node's `N` children, like one fat ray; the lanes of a leaf child
//!   are then tested against its box (all lanes in SIMD), and each lane that hits it runs the
//!   single-ray x`N` kernel on its packs (one test per ray and pack of 8 triangles, not one packet
//!   test per triangle). Measured on 512 x 512 primary rays, best of 40 interleaved runs against
//!   single-ray BVH8 (noisy 2-core machine): packets of 4 / 8 / 16 at 1.3-1.6x / 1.3-1.7x /
//!   1.2-1.9x on the bunny and 1.2-1.3x / 1.3-1.6x / 1.4-1.6x on the 262k sphereflake (before:
//!   0.6x / 1.0-1.3x / 0.9-1.1x, with one packet test per triangle and a full packet setup).
//! - **Other packets** walk with per-lane masks and use the single-ray hybrid of Benthin et al.
//!   ("Combining single and packet ray tracing", 2012): where fewer than `switch` rays still
//!   enter a node, each finishes that subtree as a single ray ([`default_switch`]).
//!
//! # Binary BVHs
//! Per-lane masks: both children are tested against every lane that entered the node, the nearer
//! (by the nearest entry of any lane) is visited first and the other pushed with its lane mask. A
//! node is skipped only when no active lane hits it. No hybrid: BVH2 packets stay packets.
//!
//! # Exactness
//! Boxes are tested against each lane with the same arithmetic as the single-ray slab test (near
//! and far planes by each lane's sign bits, the same reduction order and conservative far bound),
//! always with each lane's current `tmax`; a popped entry keeps only the lanes whose `tmax` can
//! still reach it. Leaves run the packet triangle kernels restricted to the lanes that entered
//! them (masked walk), or each such lane's single-ray kernel (interval walk). So every lane's answer equals single-ray traversal ([`wide::intersect`](super::wide::intersect),
//! [`intersect_scalar`](super::intersect_scalar)): the same `t` bit for bit, and the same
//! primitive unless two triangles tie at that `t`. Any-hit walks retire lanes as they are
//! occluded and stop when none is left.

mod bvh2;
mod leaf;
pub(crate) mod stack;
mod tile;
mod wide;

#[cfg(feature = "alloc")]
pub(crate) use wide::BoxPacket;

/// Sixteen `f32` lanes (`wide`'s type): one AVX-512 register, or two [`f32x8`] halves.
pub use crate::math::f32x16;
pub use tile::TileShape;
#[cfg(feature = "alloc")]
pub use tile::image_rays;

use super::{AcceptAll, Conservative, HitFilter, TriangleTest};
use crate::geometry::{Hit, Ray, Triangles};
use crate::layout::BvhWideRef;
use crate::math::{Lane, f32x4, f32x8};
use crate::traverse::Bvh2Ref;

/// Interval culling needs directions within this cosine (about 18 degrees) of the packet's first
/// ray; other packets walk with lane masks. A camera tile of 4 x 4 pixels spans well under a
/// degree.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, packet}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// // Directions fanning out to 19 degrees from the first: past the cone, so the packet walks with lane masks.
/// let rays: Vec<Ray> = (0..8)
///     .map(|i| Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::new(0.05 * i as f32, 0.0, 1.0)))
///     .collect();
/// assert!(rays[7].direction.normalize().z < packet::COHERENT_MIN_COS);
/// let mut hits = [None; 8];
/// packet::intersect8::<Watertight, _, 8>(b8.view(), &rays, &mut hits, 0);
/// assert!(rays.iter().zip(hits).all(|(r, h)| h == b8.intersect::<Watertight>(r))); // the same hits
/// ```
pub const COHERENT_MIN_COS: f32 = 0.95;

/// Interval culling needs origins within this fraction of the tree's extent (largest axis of the
/// root's box) on every axis. The walk is exact for any packet, but it visits the union of the
/// lanes' paths: 4 diffuse rays from scattered surface points with the same direction signs
/// (1 packet in 500) visited most of a 262k-triangle tree and cost 5x the whole batch.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, packet}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// // Parallel rays whose origins span 1.4, far more than 1/64 of the sphere's extent of 2:
/// // the packet walks with lane masks, and answers as single rays do.
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(0.2 * i as f32 - 0.7, 0.1, -3.0), Vec3::Z)).collect();
/// let mut occluded = [false; 8];
/// packet::occluded8::<Watertight, _, 8>(b8.view(), &rays, &mut occluded);
/// assert!(rays.iter().zip(occluded).all(|(r, o)| o == b8.occluded::<Watertight>(r)));
/// assert_eq!(occluded, [true; 8]);
/// ```
pub const COHERENT_MAX_ORIGIN_SPREAD: f32 = 1.0 / 64.0;

/// Switch to single rays where fewer than this many of 8 lanes enter a node, in packets whose
/// lanes do not share direction signs. Measured on diffuse rays (bunny and a 262k-triangle
/// sphereflake, 200k rays): thresholds 3, 5, 7 ran at 0.6-1.0x single rays, 9 (every such packet
/// starts as single rays at the root) at 1.0x, pure packets (0) at 0.3x. Coherent packets (shared
/// direction signs) always use interval culling.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, packet}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// // Incoherent rays (from the centre into the eight octants): single rays from the root.
/// let s = |i: u32, bit: u32| if i & bit == 0 { 1.0 } else { -1.0 };
/// let rays: Vec<_> = (0..8).map(|i| Ray::new(Vec3::ZERO, Vec3::new(s(i, 1), 0.8 * s(i, 2), 0.6 * s(i, 4)))).collect();
/// let (mut hybrid, mut pure) = ([None; 8], [None; 8]);
/// packet::intersect8::<Watertight, _, 8>(b8.view(), &rays, &mut hybrid, packet::DEFAULT_SWITCH);
/// packet::intersect8::<Watertight, _, 8>(b8.view(), &rays, &mut pure, 0);
/// assert_eq!(hybrid, pure);
/// assert!(hybrid.iter().all(Option::is_some));
/// ```
pub const DEFAULT_SWITCH: u32 = 9;

/// [`DEFAULT_SWITCH`] for packets of 4: `5`, every incoherent packet runs as single rays from the
/// root. Measured (`benches/packet.rs`' diffuse rays, best of 5, BVH8, noisy 2-core machine):
/// thresholds 2, 3, 5 ran at 0.58-0.79x single rays on the bunny and 0.85-0.90x on the
/// sphereflake; 5 was the best or within noise of it; pure packets (1) at 0.15-0.43x.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, traverse::{Moller, packet}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// assert!(packet::DEFAULT_SWITCH4 > 4); // more than a packet's lanes: every incoherent packet starts as single rays
/// let dirs = [Vec3::X, -Vec3::Y, Vec3::new(0.3, 0.4, -1.0), Vec3::new(-1.0, 0.5, 0.5)];
/// let rays = dirs.map(|d| Ray::new(Vec3::ZERO, d));
/// let mut hits = [None; 4];
/// packet::intersect4::<Moller, _, 4>(b4.view(), &rays, &mut hits, packet::DEFAULT_SWITCH4);
/// assert!(rays.iter().zip(hits).all(|(r, h)| h == b4.intersect::<Moller>(r)));
/// ```
pub const DEFAULT_SWITCH4: u32 = 5;

/// [`DEFAULT_SWITCH`] for packets of 16: `17`, every incoherent packet runs as single rays from
/// the root. Measured as for [`DEFAULT_SWITCH4`]: thresholds 2, 4, 8, 12, 17 ran at 0.39, 0.54,
/// 0.67, 0.71, 0.75x single rays on the bunny and 0.72, 0.82, 0.87, 0.82, 0.84x on the
/// sphereflake (8 and 17 within noise there, 17 clearly best on the bunny).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, packet}};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// // Incoherent rays (from the centre, every sign of x and y): single rays from the root.
/// let rays: Vec<Ray> = (0..16)
///     .map(|i| Ray::new(Vec3::ZERO, Vec3::new((i % 4) as f32 - 1.5, (i / 4) as f32 - 1.5, 0.5)))
///     .collect();
/// let mut hits = [None; 16];
/// packet::intersect16::<Watertight, _, 8>(b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH16);
/// assert!(rays.iter().zip(hits).all(|(r, h)| h == b8.intersect::<Watertight>(r)));
/// ```
pub const DEFAULT_SWITCH16: u32 = 17;

/// The default hybrid threshold for packets of `rays` rays: [`DEFAULT_SWITCH4`],
/// [`DEFAULT_SWITCH`] or [`DEFAULT_SWITCH16`] (`rays + 1` for other sizes).
///
/// ```
/// use strahl::traverse::packet::{DEFAULT_SWITCH, default_switch};
/// assert_eq!(default_switch(8), DEFAULT_SWITCH);
/// assert_eq!(default_switch(16), 17);
/// ```
pub const fn default_switch(rays: usize) -> u32 {
    match rays {
        4 => DEFAULT_SWITCH4,
        8 => DEFAULT_SWITCH,
        16 => DEFAULT_SWITCH16,
        k => k as u32 + 1,
    }
}

/// Closest hits of up to `K` rays (`rays[i]` into `hits[i]`, the shortest length wins) through the
/// wide BVH `bvh` as one packet in the lanes `R` (`R::N == K <= 16`, checked at compile time); where
/// fewer than `switch` lanes enter a node they continue as single rays (`switch` = 0 never
/// switches, `K + 1` at once for incoherent packets). Lanes past `rays.len()` and invalid rays are
/// inactive.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, math::f32x4};
/// use strahl::traverse::{Moller, packet};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..3).map(|i| Ray::new(Vec3::new(i as f32 * 0.1, 0.0, -3.0), Vec3::Z)).collect();
/// let mut hits = [None; 4];
/// packet::intersect_packet::<Moller, _, 4, f32x4, 4>(b4.view(), &rays, &mut hits, 0);
/// for (r, h) in rays.iter().zip(&hits) {
///     assert_eq!(*h, b4.intersect::<Moller>(r));
/// }
/// assert_eq!(hits[3], None); // no fourth ray: an inactive lane
/// ```
#[inline]
pub fn intersect_packet<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
) {
    const { assert!(R::N == K && K <= 16) };
    wide::intersect::<Conservative<T>, L, N, R, K, _>(bvh, rays, hits, switch, &mut AcceptAll);
}

/// [`intersect_packet`] counting only the hits `filter` accepts ([`HitFilter`]: alpha tests,
/// masks; Embree's filter functions on `rtcIntersect8`): per lane the nearest accepted hit, the
/// same `t` as [`wide::intersect_filtered`](crate::traverse::wide::intersect_filtered) for a filter
/// that is a function of the hit (and the same primitive unless two tie). The packet still
/// shares its box tests; leaves are tested lane by lane with the single-ray kernels, which ask the
/// filter before they commit a hit. The filter sees each lane's candidate hits in an order of
/// the walk's choosing.
///
/// ```
/// use strahl::{Hit, Ray, Vec3, build::BuildParams, layout::Bvh8, math::f32x8};
/// use strahl::traverse::{Watertight, packet};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b8, _) = Bvh8::build(&tris[..], &BuildParams::default()).unwrap();
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.05, 0.1, -3.0), Vec3::Z)).collect();
/// // Cut out the odd triangles: some rays go on to the back of the sphere.
/// let even = |h: &Hit| h.prim % 2 == 0;
/// let mut hits = [None; 8];
/// packet::intersect_packet_filtered::<Watertight, _, 8, f32x8, 8>(b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH, even);
/// for (r, h) in rays.iter().zip(&hits) {
///     assert_eq!(*h, b8.intersect_filtered::<Watertight>(r, even));
/// }
/// ```
#[inline]
pub fn intersect_packet_filtered<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
    mut filter: impl HitFilter,
) {
    const { assert!(R::N == K && K <= 16) };
    wide::intersect::<Conservative<T>, L, N, R, K, _>(bvh, rays, hits, switch, &mut filter);
}

/// Any-hit answers of up to `K` rays (`occluded[i]` for `rays[i]`) through the wide BVH `bvh`:
/// coherent packets walk together with interval culling, others with lane masks and the hybrid
/// `switch` (as in [`intersect_packet`]); lanes retire as they are occluded.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8};
/// use strahl::traverse::{Watertight, packet::{self, f32x16}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// // Rays in every direction from outside: an incoherent packet.
/// let rays: Vec<Ray> = (0..16)
///     .map(|i| Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::new((i % 4) as f32 - 1.5, (i / 4) as f32 - 1.5, 2.0)))
///     .collect();
/// let mut occ = [false; 16];
/// packet::occluded_packet::<Watertight, _, 8, f32x16, 16>(b8.view(), &rays, &mut occ, 0);
/// for (r, o) in rays.iter().zip(occ) {
///     assert_eq!(o, b8.occluded::<Watertight>(r));
/// }
/// ```
#[inline]
pub fn occluded_packet<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
    switch: u32,
) {
    const { assert!(R::N == K && K <= 16) };
    wide::occluded::<Conservative<T>, L, N, R, K, _>(bvh, rays, occluded, switch, &mut AcceptAll);
}

/// [`occluded_packet`] counting only the hits `filter` accepts (see
/// [`intersect_packet_filtered`]): `occluded[i]` is whether `rays[i]` has an accepted hit, as
/// [`wide::occluded_filtered`](crate::traverse::wide::occluded_filtered) answers.
///
/// ```
/// use strahl::{Hit, Ray, Vec3, build::BuildParams, layout::Bvh8, math::f32x8};
/// use strahl::traverse::{Moller, packet};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b8, _) = Bvh8::build(&tris[..], &BuildParams::default()).unwrap();
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.05, 0.1, -3.0), Vec3::Z)).collect();
/// let mut occ = [true; 8];
/// packet::occluded_packet_filtered::<Moller, _, 8, f32x8, 8>(b8.view(), &rays, &mut occ, 0, |_: &Hit| false);
/// assert_eq!(occ, [false; 8]); // every hit rejected: nothing blocks
/// ```
#[inline]
pub fn occluded_packet_filtered<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
    switch: u32,
    mut filter: impl HitFilter,
) {
    const { assert!(R::N == K && K <= 16) };
    wide::occluded::<Conservative<T>, L, N, R, K, _>(bvh, rays, occluded, switch, &mut filter);
}

/// Closest hits of up to 4 rays through a wide BVH ([`intersect_packet`] with [`f32x4`] lanes).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..4).map(|i| Ray::new(Vec3::new(i as f32 * 0.1, 0.0, -3.0), Vec3::Z)).collect();
/// let mut hits = [None; 4];
/// packet::intersect4::<Watertight, _, 8>(b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH4);
/// for (r, h) in rays.iter().zip(&hits) {
///     assert_eq!(*h, b8.intersect::<Watertight>(r));
/// }
/// ```
#[inline]
pub fn intersect4<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
) {
    intersect_packet::<T, L, N, f32x4, 4>(bvh, rays, hits, switch);
}

/// Closest hits of up to 8 rays (`rays[i]` into `hits[i]`) through the wide BVH `bvh` as one
/// packet; where fewer than `switch` lanes enter a node they continue as single rays (`switch`
/// = 0 never switches, 9 switches at once). Lanes past `rays.len()` and invalid rays are inactive.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.1, 0.0, -3.0), Vec3::Z)).collect();
/// let mut hits = [None; 8];
/// packet::intersect8::<Watertight, _, 8>(b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH);
/// for (r, h) in rays.iter().zip(&hits) {
///     assert_eq!(*h, b8.intersect::<Watertight>(r));
/// }
/// ```
#[inline]
pub fn intersect8<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
) {
    intersect_packet::<T, L, N, f32x8, 8>(bvh, rays, hits, switch);
}

/// Closest hits of up to 16 rays through a wide BVH ([`intersect_packet`] with [`f32x16`] lanes).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Watertight, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..16).map(|i| Ray::new(Vec3::new(i as f32 * 0.1, 0.0, -3.0), Vec3::Z)).collect();
/// let mut hits = [None; 16];
/// packet::intersect16::<Watertight, _, 8>(b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH16);
/// for (r, h) in rays.iter().zip(&hits) {
///     assert_eq!(*h, b8.intersect::<Watertight>(r));
/// }
/// ```
#[inline]
pub fn intersect16<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
) {
    intersect_packet::<T, L, N, f32x16, 16>(bvh, rays, hits, switch);
}

/// Any-hit answers for up to 4 rays through a wide BVH ([`occluded_packet`] with
/// [`DEFAULT_SWITCH4`]).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, traverse::{Moller, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..4).map(|i| Ray::new(Vec3::new(i as f32 * 0.4, 0.0, -3.0), Vec3::Z)).collect();
/// let mut occ = [false; 4];
/// packet::occluded4::<Moller, _, 4>(b4.view(), &rays, &mut occ);
/// assert_eq!(occ, [true, true, true, false]);
/// ```
#[inline]
pub fn occluded4<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
) {
    occluded_packet::<T, L, N, f32x4, 4>(bvh, rays, occluded, DEFAULT_SWITCH4);
}

/// Any-hit answers for up to 8 rays (`occluded[i]` for `rays[i]`): coherent packets walk together
/// and retire lanes as they are occluded; other packets follow [`DEFAULT_SWITCH`] (as single rays).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(i as f32 * 0.2, 0.0, -3.0), Vec3::Z)).collect();
/// let mut occ = [false; 8];
/// packet::occluded8::<Moller, _, 8>(b8.view(), &rays, &mut occ);
/// assert_eq!(occ, [true, true, true, true, true, false, false, false]);
/// ```
#[inline]
pub fn occluded8<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
) {
    occluded_packet::<T, L, N, f32x8, 8>(bvh, rays, occluded, DEFAULT_SWITCH);
}

/// Any-hit answers for up to 16 rays through a wide BVH ([`occluded_packet`] with
/// [`DEFAULT_SWITCH16`]).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..16).map(|i| Ray::new(Vec3::new(i as f32 * 0.1, 0.0, -3.0), Vec3::Z)).collect();
/// let mut occ = [false; 16];
/// packet::occluded16::<Moller, _, 8>(b8.view(), &rays, &mut occ);
/// assert_eq!(occ.iter().filter(|&&o| o).count(), 10); // x = 0.0 ..= 0.9 hit the unit sphere
/// ```
#[inline]
pub fn occluded16<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
) {
    occluded_packet::<T, L, N, f32x16, 16>(bvh, rays, occluded, DEFAULT_SWITCH16);
}

/// Closest hits of up to `K` rays through the binary BVH `bvh` over `tris` as one packet in the
/// lanes `R` (`R::N == K`); `hits[i]` for `rays[i]`, the shortest length wins. Each lane equals
/// [`intersect_scalar`](super::intersect_scalar).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, math::f32x8};
/// use strahl::traverse::{Watertight, intersect_scalar, packet};
/// let mesh = strahl::scene::icosphere(2);
/// let tris = mesh.as_indexed();
/// let (bvh, _) = Bvh2::build(&tris, &BuildParams::default()).unwrap();
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::new(i as f32 * 0.1, 0.0, 1.0))).collect();
/// let mut hits = [None; 8];
/// packet::intersect_packet_bvh2::<Watertight, _, f32x8, 8>(bvh.view(), &tris, &rays, &mut hits);
/// for (r, h) in rays.iter().zip(&hits) {
///     assert_eq!(*h, intersect_scalar::<Watertight, _>(bvh.view(), &tris, r));
/// }
/// ```
#[inline]
pub fn intersect_packet_bvh2<T: TriangleTest, P: Triangles + ?Sized, R: Lane, const K: usize>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
) {
    const { assert!(R::N == K && K <= 16) };
    let n = rays.len().min(hits.len()).min(K);
    let mut best = [None; K];
    bvh2::run::<Conservative<T>, P, R, K, false>(bvh, tris, &rays[..n], &mut best);
    hits[..n].copy_from_slice(&best[..n]);
}

/// Any-hit answers of up to `K` rays through the binary BVH `bvh` (`occluded[i]` for `rays[i]`);
/// lanes retire as they are occluded, the walk ends when none is left. Each lane equals
/// [`occluded_scalar`](super::occluded_scalar).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, math::f32x4};
/// use strahl::traverse::{Moller, packet};
/// let mesh = strahl::scene::icosphere(1);
/// let tris = mesh.as_indexed();
/// let (bvh, _) = Bvh2::build(&tris, &BuildParams::default()).unwrap();
/// let o = Vec3::new(0.0, 0.0, -3.0);
/// let rays = [Ray::new(o, Vec3::Z), Ray::new(o, -Vec3::Z), Ray::new(o, Vec3::X)];
/// let mut occ = [false; 3];
/// packet::occluded_packet_bvh2::<Moller, _, f32x4, 4>(bvh.view(), &tris, &rays, &mut occ);
/// assert_eq!(occ, [true, false, false]);
/// ```
#[inline]
pub fn occluded_packet_bvh2<T: TriangleTest, P: Triangles + ?Sized, R: Lane, const K: usize>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    rays: &[Ray],
    occluded: &mut [bool],
) {
    const { assert!(R::N == K && K <= 16) };
    let n = rays.len().min(occluded.len()).min(K);
    let mut best = [None; K];
    let mask = bvh2::run::<Conservative<T>, P, R, K, true>(bvh, tris, &rays[..n], &mut best);
    for (i, o) in occluded[..n].iter_mut().enumerate() {
        *o = mask >> i & 1 == 1;
    }
}

macro_rules! bvh2_wrappers {
    ($($k:literal, $lane:ty, $hit:ident, $occ:ident;)*) => {$(
        #[doc = concat!("Closest hits of up to ", $k, " rays through a binary BVH ([`intersect_packet_bvh2`] with [`", stringify!($lane), "`] lanes).")]
        ///
        /// ```
        /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}};
        /// use strahl::traverse::{Watertight, intersect_scalar, packet};
        /// let tris = strahl::scene::icosphere(2).to_soup();
        /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        #[doc = concat!("let rays: Vec<Ray> = (0..", $k, ").map(|i| Ray::new(Vec3::new(i as f32 * 0.1, 0.0, -3.0), Vec3::Z)).collect();")]
        #[doc = concat!("let mut hits = [None; ", $k, "];")]
        #[doc = concat!("packet::", stringify!($hit), "::<Watertight, _>(bvh.view(), &tris[..], &rays, &mut hits);")]
        /// for (r, h) in rays.iter().zip(&hits) {
        ///     assert_eq!(*h, intersect_scalar::<Watertight, _>(bvh.view(), &tris[..], r));
        /// }
        /// ```
        #[inline]
        pub fn $hit<T: TriangleTest, P: Triangles + ?Sized>(bvh: Bvh2Ref<'_>, tris: &P, rays: &[Ray], hits: &mut [Option<Hit>]) {
            intersect_packet_bvh2::<T, P, $lane, $k>(bvh, tris, rays, hits);
        }

        #[doc = concat!("Any-hit answers of up to ", $k, " rays through a binary BVH ([`occluded_packet_bvh2`] with [`", stringify!($lane), "`] lanes).")]
        ///
        /// ```
        /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}};
        /// use strahl::traverse::{Moller, occluded_scalar, packet};
        /// let tris = strahl::scene::icosphere(2).to_soup();
        /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        #[doc = concat!("let rays: Vec<Ray> = (0..", $k, ").map(|i| Ray::new(Vec3::new(i as f32 * 0.2, 0.0, -3.0), Vec3::Z)).collect();")]
        #[doc = concat!("let mut occ = [false; ", $k, "];")]
        #[doc = concat!("packet::", stringify!($occ), "::<Moller, _>(bvh.view(), &tris[..], &rays, &mut occ);")]
        /// for (r, o) in rays.iter().zip(occ) {
        ///     assert_eq!(o, occluded_scalar::<Moller, _>(bvh.view(), &tris[..], r));
        /// }
        /// assert!(occ[0]);
        /// ```
        #[inline]
        pub fn $occ<T: TriangleTest, P: Triangles + ?Sized>(bvh: Bvh2Ref<'_>, tris: &P, rays: &[Ray], occluded: &mut [bool]) {
            occluded_packet_bvh2::<T, P, $lane, $k>(bvh, tris, rays, occluded);
        }
    )*};
}

bvh2_wrappers! {
    4, f32x4, intersect4_bvh2, occluded4_bvh2;
    8, f32x8, intersect8_bvh2, occluded8_bvh2;
    16, f32x16, intersect16_bvh2, occluded16_bvh2;
}

/// Closest hits of a batch of rays, 8 at a time as packets ([`intersect8`]).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..21).map(|i| Ray::new(Vec3::new(i as f32 * 0.05, 0.0, -3.0), Vec3::Z)).collect();
/// let mut hits = vec![None; rays.len()];
/// packet::intersect_batch::<Moller, _, 8>(b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH);
/// assert!(rays.iter().zip(&hits).all(|(r, h)| *h == b8.intersect::<Moller>(r)));
/// ```
pub fn intersect_batch<T: TriangleTest, L: Lane, const N: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
) {
    intersect_batch_packets::<T, L, N, f32x8, 8>(bvh, rays, hits, switch);
}

/// Closest hits of a batch of rays through a wide BVH, `K` at a time as packets
/// ([`intersect_packet`]); `hits[i]` for `rays[i]` (the shorter length wins). Consecutive rays
/// should be neighbours (see [`TileShape`]) for the packets to be coherent.
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh8, traverse::{Moller, packet}};
/// use packet::f32x16;
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..37).map(|i| Ray::new(Vec3::new(i as f32 * 0.03, 0.0, -3.0), Vec3::Z)).collect();
/// let mut hits = vec![None; rays.len()];
/// packet::intersect_batch_packets::<Moller, _, 8, f32x16, 16>(b8.view(), &rays, &mut hits, packet::DEFAULT_SWITCH16);
/// assert!(rays.iter().zip(&hits).all(|(r, h)| *h == b8.intersect::<Moller>(r)));
/// ```
pub fn intersect_batch_packets<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
) {
    let n = rays.len().min(hits.len());
    for (r, h) in rays[..n].chunks(K).zip(hits[..n].chunks_mut(K)) {
        intersect_packet::<T, L, N, R, K>(bvh, r, h, switch);
    }
}

/// Any-hit answers of a batch of rays through a wide BVH, `K` at a time as packets
/// ([`occluded_packet`] with [`default_switch`]`(K)`).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, layout::Bvh4, math::f32x4, traverse::{Moller, packet}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
/// let rays: Vec<Ray> = (0..10).map(|i| Ray::new(Vec3::new(i as f32 * 0.2, 0.0, -3.0), Vec3::Z)).collect();
/// let mut occ = vec![false; rays.len()];
/// packet::occluded_batch_packets::<Moller, _, 4, f32x4, 4>(b4.view(), &rays, &mut occ);
/// assert_eq!(occ.iter().filter(|&&o| o).count(), 5);
/// ```
pub fn occluded_batch_packets<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
) {
    let n = rays.len().min(occluded.len());
    for (r, o) in rays[..n].chunks(K).zip(occluded[..n].chunks_mut(K)) {
        occluded_packet::<T, L, N, R, K>(bvh, r, o, default_switch(K));
    }
}

/// Closest hits of a batch of rays through a binary BVH, `K` at a time as packets
/// ([`intersect_packet_bvh2`]).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, math::f32x8};
/// use strahl::traverse::{Moller, intersect_scalar, packet};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let rays: Vec<Ray> = (0..19).map(|i| Ray::new(Vec3::new(i as f32 * 0.05, 0.0, -3.0), Vec3::Z)).collect();
/// let mut hits = vec![None; rays.len()];
/// packet::intersect_batch_bvh2::<Moller, _, f32x8, 8>(bvh.view(), &tris[..], &rays, &mut hits);
/// assert!(rays.iter().zip(&hits).all(|(r, h)| *h == intersect_scalar::<Moller, _>(bvh.view(), &tris[..], r)));
/// ```
pub fn intersect_batch_bvh2<T: TriangleTest, P: Triangles + ?Sized, R: Lane, const K: usize>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
) {
    let n = rays.len().min(hits.len());
    for (r, h) in rays[..n].chunks(K).zip(hits[..n].chunks_mut(K)) {
        intersect_packet_bvh2::<T, P, R, K>(bvh, tris, r, h);
    }
}

/// Any-hit answers of a batch of rays through a binary BVH, `K` at a time as packets
/// ([`occluded_packet_bvh2`]).
///
/// ```
/// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}};
/// use strahl::traverse::{Moller, packet::{self, f32x16}};
/// let tris = strahl::scene::icosphere(2).to_soup();
/// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// let rays: Vec<Ray> = (0..20).map(|i| Ray::new(Vec3::new(i as f32 * 0.1, 0.0, -3.0), Vec3::Z)).collect();
/// let mut occ = vec![false; rays.len()];
/// packet::occluded_batch_bvh2::<Moller, _, f32x16, 16>(bvh.view(), &tris[..], &rays, &mut occ);
/// assert_eq!(occ.iter().filter(|&&o| o).count(), 10);
/// ```
pub fn occluded_batch_bvh2<T: TriangleTest, P: Triangles + ?Sized, R: Lane, const K: usize>(
    bvh: Bvh2Ref<'_>,
    tris: &P,
    rays: &[Ray],
    occluded: &mut [bool],
) {
    let n = rays.len().min(occluded.len());
    for (r, o) in rays[..n].chunks(K).zip(occluded[..n].chunks_mut(K)) {
        occluded_packet_bvh2::<T, P, R, K>(bvh, tris, r, o);
    }
}
