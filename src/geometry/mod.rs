//! Geometry types: [`Aabb`], [`Ray`], [`Hit`], triangle input ([`IndexedMesh`], [`TriangleSoup`], [`StridedMesh`])
//! and Morton codes ([`morton`]).
//!
//! All plain-data types are `#[repr(C)]` and [`bytemuck::Pod`], so they can be read zero-copy from
//! byte buffers (files, GPU readbacks, network packets) and written back the same way.

mod aabb;
mod mesh;
pub mod morton;
pub mod offset;
mod ray;

pub use aabb::Aabb;
pub use mesh::{GeometryError, IndexedMesh, StridedMesh, Triangle, TriangleSoup, Triangles, is_degenerate};
pub use ray::{Hit, INVALID, Ray};
