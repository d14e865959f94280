//! Sort-last parallel rendering: every rank renders its part of the scene into a full-size image,
//! and the partial images are composited (Molnar et al., "A sorting classification of parallel
//! rendering", 1994). With many ranks the bottleneck is compositing bandwidth, so the schedules
//! split the work: direct-send, binary-swap and radix-k (Peterka et al. 2009).
//!
//! - [`pixel`]: the operators, premultiplied "over" (`f32` and `u8`) and depth, scalar and SIMD
//!   (core-only).
//! - [`schedule`]: radix-k and tree schedules as pure data, the k-vector cost model (core-only).
//! - [`order`]: k-d decomposition of the scene into rank boxes and their visibility order
//!   (core-only).
//! - [`sparse`]: run-length encoding of non-empty pixels, so ranks send only what they drew
//!   (`alloc`).
//! - [`exec`]: the executor over a [`Transport`] (`alloc`); [`ThreadTransport`] runs ranks as
//!   threads (`std`); `MpiTransport` runs them as MPI processes (feature `mpi`).
//! - [`tiles`](mod@tiles): sort-first dynamic load balancing with a tile queue (`std`).
//!
//! ```
//! use strahl::composite::{KVec, Plan, RgbaF32, Schedule, ThreadTransport, composite};
//! // Four ranks, each drew a quarter-opaque grey everywhere; radix-k [2, 2] (binary-swap).
//! let order = [0, 1, 2, 3];
//! let out = ThreadTransport::run(4, |t| {
//!     let img = vec![RgbaF32([0.25; 4]); 33];
//!     let plan = Plan { schedule: Schedule::RadixK(KVec::new(&[2, 2]).unwrap()), order: &order, root: 0, sparse: true };
//!     composite(t, &img, &plan).unwrap().0
//! });
//! let alpha = out[0].as_ref().unwrap()[0].0[3];
//! assert!((alpha - (1.0 - 0.75f32.powi(4))).abs() < 1e-6);
//! ```

pub mod order;
pub mod pixel;
pub mod schedule;

#[cfg(feature = "alloc")]
pub mod exec;
#[cfg(feature = "mpi")]
pub mod mpi;
#[cfg(feature = "alloc")]
pub mod sparse;
#[cfg(feature = "std")]
pub mod thread;
#[cfg(feature = "std")]
pub mod tiles;

#[cfg(feature = "std")]
pub use exec::measure_cost_model;
#[cfg(feature = "alloc")]
pub use exec::{
    CompositeError, CompositeStats, Plan, Schedule, Transport, TransportError, composite, composite_serial,
};
#[cfg(feature = "mpi")]
pub use mpi::MpiTransport;
pub use order::{View, kd_decompose, visibility_order};
pub use pixel::{
    DepthPixel, OVER_F32_TOLERANCE, Pixel, Rgba8, RgbaF32, depth_scalar, depth_x4, div255, over_f32_scalar,
    over_f32_x8, over_u8_scalar, over_u8_x8,
};
pub use schedule::{CostModel, Group, KVec, Message, RadixK, auto_kvec, piece, tree_partner, tree_rounds};
#[cfg(feature = "alloc")]
pub use sparse::{DecodeError, decode_composite, encode};
#[cfg(feature = "std")]
pub use thread::ThreadTransport;
#[cfg(feature = "std")]
pub use tiles::{Assignment, ImageSizeError, Tile, TileStats, render_tiles, render_tiles_into, tiles};
