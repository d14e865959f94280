//! Fuzzing support for strahl: input decoding and a shared checker that every fuzz target calls.
//!
//! Each target (one per pipeline stage, see `fuzz_targets/`) decodes its bytes with [`decode`]
//! and hands the result to a `check_*` function of [`check`], which compares every SIMD kernel with
//! its scalar reference lane by lane (bit for bit), every closest hit with brute force over the
//! scalar references, the documented bad-input policies, and, on grid inputs, everything with
//! exact arithmetic ([`exact`]). Later targets (builders, traversal) reuse the decoder, the
//! brute-force references and the exact tests; the [`volume`] and [`composite`] targets reuse the
//! value decoder and bring their own checkers (x8 marcher against the scalar one, skipping against
//! no skipping, every compositing schedule against the serial reference).
//!
//! Two input modes, selected by bit 0 of the first byte:
//! - **chaos**: coordinates are arbitrary `f32` bit patterns (NaN, infinities, subnormals, `-0`,
//!   huge and tiny values): kernels must not panic, must agree bit for bit, and must follow their
//!   policies (invalid rays and degenerate triangles never hit, `tmin <= t < tmax`).
//! - **grid**: coordinates are integers in `[-8, 8]`, where every product is exact and answers
//!   are unambiguous: Möller-Trumbore and watertight must also match exact integer arithmetic
//!   away from edges, vertices and range bounds, and the slab test must never miss a box that
//!   exact arithmetic hits.
//!
//! `tests/seeds.rs` replays every file under `seeds/` on stable Rust (`cargo test` in `fuzz/`);
//! `examples/replay.rs` prints a decoded input and checks it.
#![warn(missing_docs)]

pub mod bvh;
pub mod check;
pub mod composite;
pub mod decode;
pub mod exact;
pub mod volume;

pub use bvh::{BvhCase, check_bvh};
pub use check::{Kernel, brute_force_closest, check_kernels, same_hit};
pub use composite::{CompositeCase, CompositeReport, check_composite};
pub use decode::{Input, KernelCase, Mode};
pub use volume::{VolumeCase, VolumeReport, check_volume};
