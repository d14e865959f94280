//! Peer libraries for side-by-side benchmarks. Included by the bench files with
//! `#[path = "peers/mod.rs"] mod peers;`.

#[cfg(feature = "embree")]
pub mod embree;
#[cfg(feature = "tinybvh")]
pub mod tinybvh;
