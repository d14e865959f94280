//! # strahl: CPU ray-tracing kernels
//!
//! strahl ("ray") is a `no_std`, data-oriented SIMD kernel crate for engines that trace rays on the
//! CPU. Every kernel has a scalar reference beside it, written separately, and SIMD forms for 4 and
//! 8 lanes that give **bit-identical** results (same operations in the same order, one NaN policy).
//!
//! ## The pipeline
//! ```text
//!  triangles ──► geometry ──► build ──► layout ──► traverse ──► hits ──► (shading: yours)
//!  (bytes,       Aabb, Ray,   BVH2       BVH4/8    single ray,
//!   meshes)      Morton       builders   collapse  packets
//!                   │                                 │
//!                   └────────► intersect ◄────────────┘  slab test, Möller-Trumbore, watertight
//!  volumes ──► volume (ray marching) ──► composite (over / depth, sort-last schedules)
//! ```
//! The modules: [`geometry`] (boxes, rays, hits, zero-copy triangle input, Morton codes, robust
//! secondary-ray origins), [`intersect`] (robust slab test, Möller-Trumbore and watertight
//! ray/triangle tests in scalar, x4, x8 and packet form, an `f64` reference), [`build`] (BVH2
//! builders: object median, full-sweep and binned SAH, LBVH, HLBVH, PLOC, spatial splits; treelet
//! restructuring, rotations and reinsertion; `validate`, `refit`, SAH cost; parallel builds with
//! `std`), [`layout`] (BVH4/BVH8 collapsed from any BVH2, refit, instancing with a TLAS, saving
//! and loading, in place from a memory map), [`traverse`] (the scalar BVH2 reference, single-ray
//! BVH4/BVH8 closest and any hit, batches, ray packets, ray streams, hit filters), [`volume`]
//! (absorption + emission ray marching, transfer functions, empty-space skipping),
//! [`composite`] (sort-last compositing: over and depth kernels, direct-send, binary-swap and
//! radix-k schedules, in-process and MPI transports, a tile queue), [`math`] (lane types) and
//! [`scene`] (bundled bunny, procedural meshes, OBJ reader).
//!
//! ## Example: a mesh, a BVH8, hits
//! ```
//! use strahl::build::{BuildParams, Bvh2};
//! use strahl::{Ray, Vec3, geometry::IndexedMesh, layout::Bvh8, traverse::Watertight};
//! // Your buffers, borrowed: a square at z = 1 as two triangles.
//! let positions = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].map(|[x, y]| Vec3::new(x, y, 1.0));
//! let mesh = IndexedMesh::new(&positions, &[[0, 1, 2], [0, 2, 3]]);
//! let (bvh2, _stats) = Bvh2::build(&mesh, &BuildParams::default()).unwrap();
//! let bvh8 = Bvh8::from_bvh2(&bvh2, &mesh).unwrap(); // 8-wide nodes, SoA triangle leaves
//! let hit = bvh8.intersect::<Watertight>(&Ray::new(Vec3::new(-0.5, 0.5, 0.0), Vec3::Z)).unwrap();
//! assert_eq!((hit.t, hit.prim), (1.0, 1)); // distance, and the triangle's index in your buffer
//! // Any hit in [tmin, tmax): a shadow ray that stops short of the square.
//! assert!(!bvh8.occluded::<Watertight>(&Ray::with_range(Vec3::ZERO, Vec3::Z, 0.0, 0.9)));
//! ```
//! The README's "Using it in your engine" goes on to secondary-ray origins, batches and saving.
//!
//! ## Example: one kernel
//! ```
//! use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8, watertight}};
//! let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
//! let leaf = TriangleX8::pack(&[tri], &[0]); // up to 8 triangles in SoA form
//! let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
//! let hit = watertight::intersect_x8(&ray, &leaf).unwrap();
//! assert_eq!((hit.t, hit.prim), (2.0, 0));
//! ```
//!
//! ## Features
//! | feature | default | what it adds |
//! |---|---|---|
//! | (none) | | all kernels: slab test, triangle tests, Morton codes, volume marching, on caller-provided slices; `#![no_std]`, no allocation |
//! | `alloc` | | [`scene`] (OBJ reader, procedural meshes); [`volume::MacrocellGrid::build`] in a `Vec`; [`build`] (BVH2 builders, reusable [`build::Builder`] memory); owned wide BVHs ([`layout::Bvh4`], [`layout::Bvh8`]: collapse, refit, saving) and instancing ([`layout::Tlas`]) |
//! | `std` | yes | `alloc`, plus std's float intrinsics in `glam`; threads: parallel BVH2 builds (spatial splits included), collapse and refit, threaded batch traversal, [`composite::ThreadTransport`], [`composite::render_tiles`] |
//! | `hugepages` | yes | `std`; on Linux, [`layout::Bvh4`]/[`layout::Bvh8`] arrays of 4 MiB and more advised for transparent huge pages (`madvise`, through `libc`): fewer TLB misses on large trees, same results |
//! | `mpi` | | [`composite`]'s `MpiTransport` over the system's MPI library (`libopenmpi-dev`, `libclang-dev`) |
//! | `embree`, `tinybvh` | | benches only: the peer libraries (see the README) |
//!
//! ## Where the tunables live
//! | stage | knob | where |
//! |---|---|---|
//! | slab test | conservative far bound `far + \|far\| 2 gamma(3)` (default), or the fast test by type | [`intersect::aabb::FAR_SLACK`], [`traverse::Fast`] |
//! | batches | each group of 8 rays as a packet, two interleaved walks (closest hits) or one walk at a time, chosen by its rays; ray streams on request | [`layout::BvhWide::intersect_batch`], [`traverse::wide::occluded_batch_stream`] |
//! | incoherent batches | trace in the Morton order of the rays' origins | [`traverse::order::RayOrder`], [`layout::BvhWide::occluded_batch_reordered`] |
//! | Morton codes | bits per axis (10 or 21), quantisation bounds | [`geometry::morton::MortonQuantizer`] |
//! | BVH2 build | strategy, `C_T`, `C_I`, leaf sizes, bins, binned axes, Morton bits, depth bound | [`build::BuildParams`] (`fastest`, `fast`, `balanced`, `quality`, `median`) |
//! | BVH2 traversal | stack entries, deepest tree traversed without fallback | [`traverse::STACK_SIZE`], [`traverse::MAX_DEPTH`] |
//! | volume marching | step, endpoint / midpoint sampling, early-termination epsilon, step cap | [`volume::MarchParams`] (`reference`, `quality`, `fast`) |
//! | transfer function | table, scalar range, reference step of authored opacities | [`volume::TransferFunction`], [`volume::TfEntry::from_rgba_premultiplied`] |
//! | empty-space skipping | macrocell block size | [`volume::GridParams`] (`fine`, default, `coarse`) |
//! | pre-integration | table resolution, step | [`volume::PreintegratedTable::build`] |
//! | compositing | k-vector, visibility order, sparse encoding, root | [`composite::Plan`], [`composite::auto_kvec`] with [`composite::CostModel`] |
//! | SIMD width | `wide` picks AVX / SSE / NEON from target features | build with `-C target-cpu=native` |
//!
//! ## Bad input
//! Kernels never panic. Invalid rays (NaN, infinite, zero direction) hit nothing; degenerate or
//! non-finite triangles are never hit; a reported distance is never NaN. See [`intersect`] for the
//! full policy, including `+-0` direction components and flat boxes.
#![no_std]
#![warn(missing_docs)]

#[cfg(feature = "alloc")]
extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

#[cfg(feature = "alloc")]
pub mod build;
pub mod composite;
pub mod geometry;
pub mod intersect;
pub mod layout;
pub mod math;
#[cfg(feature = "std")]
mod par;
#[cfg(feature = "alloc")]
pub mod scene;
pub mod traverse;
pub mod volume;

pub use geometry::{Aabb, Hit, Ray};
/// The `glam` strahl is built on (its `Vec3`, and `Affine3A` in [`layout::Instance`]), so that
/// callers name the same version.
///
/// ```
/// let m = strahl::glam::Affine3A::from_translation(strahl::Vec3::X);
/// assert_eq!(m.transform_point3(strahl::Vec3::ZERO), strahl::Vec3::X);
/// ```
pub use glam;
pub use glam::Vec3;

/// The README's Rust blocks (its usage example), compiled and run as doc tests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
