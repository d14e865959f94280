#![no_std]
#![warn(missing_docs)]
//! strahl: CPU ray-tracing kernels (crate docs are written in src/lib.rs).

#[cfg(feature = "alloc")]
extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

pub mod geometry;
pub mod intersect;
pub mod math;
#[cfg(feature = "alloc")]
pub mod scene;

pub use geometry::{Aabb, Hit, Ray};
pub use glam::Vec3;
