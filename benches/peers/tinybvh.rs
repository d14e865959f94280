//! tinybvh 1.6.8 through a small C interface (`tinybvh.cpp`, compiled by `build.rs`), for
//! benchmarks only (feature `tinybvh`; `TINYBVH_DIR` must hold `tiny_bvh.h`, which
//! `benches/peers/tinybvh_fetch.sh` fetches). Its binary builders (`Build`, `BuildAVX`,
//! `BuildHQ`) with their SAH cost, and its fastest CPU single-ray layout, `BVH8_CPU`
//! (`Intersect` / `IsOccluded`, one call per ray in a C++ loop). Builds run on one thread.
#![allow(dead_code)]

use std::ffi::c_void;
use strahl::Ray;
use strahl::geometry::Triangle;

unsafe extern "C" {
    fn strahl_tb_bvh_new() -> *mut c_void;
    fn strahl_tb_bvh_free(b: *mut c_void);
    fn strahl_tb_bvh_build(b: *mut c_void, verts: *const f32, n: u32, mode: i32);
    fn strahl_tb_bvh_nodes(b: *const c_void, count: *mut u32) -> *const c_void;
    fn strahl_tb_bvh_prims(b: *const c_void, count: *mut u32) -> *const u32;
    fn strahl_tb_bvh8_new(verts: *const f32, n: u32, hq: i32) -> *mut c_void;
    fn strahl_tb_bvh8_free(b: *mut c_void);
    fn strahl_tb_bvh8_intersect(b: *const c_void, rays: *const f32, n: usize) -> usize;
    fn strahl_tb_bvh8_occluded(b: *const c_void, rays: *const f32, n: usize) -> usize;
}

/// A vertex as tinybvh reads it: four floats, 16-byte aligned.
#[derive(Clone, Copy)]
#[repr(C, align(16))]
struct V4([f32; 4]);

fn vertices(tris: &[Triangle]) -> Vec<V4> {
    tris.iter().flat_map(|t| t.map(|v| V4([v.x, v.y, v.z, 0.0]))).collect()
}

/// tinybvh's binary builders.
#[derive(Clone, Copy, Debug)]
pub enum Builder {
    /// `BVH::Build`: binned SAH, 8 bins on three axes.
    Build = 0,
    /// `BVH::BuildAVX`: the same, binned with AVX.
    BuildAvx = 1,
    /// `BVH::BuildHQ`: binned SAH with spatial splits.
    BuildHq = 2,
}

/// A binary BVH kept across builds (as strahl's `Builder` keeps its memory), with the vertices
/// tinybvh points into.
pub struct Bvh {
    raw: *mut c_void,
    verts: Vec<V4>,
}

impl Bvh {
    pub fn new(tris: &[Triangle]) -> Self {
        // SAFETY: no arguments; the pointer is freed once, in `Drop`.
        let raw = unsafe { strahl_tb_bvh_new() };
        Self {
            raw,
            verts: vertices(tris),
        }
    }

    /// Builds with `builder` (the build alone: the benches measure the tree from [`tree`](Self::tree)).
    pub fn build(&mut self, builder: Builder) {
        // SAFETY: `raw` is live; `verts` holds 3 aligned vertices per triangle and outlives the
        // tree (tinybvh keeps a pointer to it).
        unsafe {
            strahl_tb_bvh_build(
                self.raw,
                self.verts.as_ptr().cast(),
                (self.verts.len() / 3) as u32,
                builder as i32,
            )
        }
    }

    /// The last build's nodes (tinybvh's `BVHNode` has strahl's `Node` layout: min, left child
    /// or first primitive, max, count; siblings adjacent, root at 0, slot 1 unused) and
    /// primitive indices.
    pub fn tree(&self) -> (&[strahl::build::Node], &[u32]) {
        let (mut nn, mut np) = (0, 0);
        // SAFETY: `raw` is live; the arrays hold `nn` 32-byte nodes and `np` indices (tinybvh's
        // `usedNodes`, `idxCount`) and live until the next build, which needs `&mut self`. The
        // node layout equals `Node`'s (`#[repr(C)]`, 3 + 1 + 3 + 1 four-byte fields).
        unsafe {
            let nodes = strahl_tb_bvh_nodes(self.raw, &mut nn);
            let prims = strahl_tb_bvh_prims(self.raw, &mut np);
            if nn == 0 {
                return (&[], &[]);
            }
            (
                std::slice::from_raw_parts(nodes.cast(), nn as usize),
                std::slice::from_raw_parts(prims, np as usize),
            )
        }
    }
}

impl Drop for Bvh {
    fn drop(&mut self) {
        // SAFETY: made by `strahl_tb_bvh_new`, freed once.
        unsafe { strahl_tb_bvh_free(self.raw) }
    }
}

/// tinybvh's `BVH8_CPU` over a triangle list.
pub struct Bvh8 {
    raw: *mut c_void,
    _verts: Vec<V4>,
}

impl Bvh8 {
    /// Built by `Build` (binned SAH) or, with `hq`, `BuildHQ` (spatial splits).
    pub fn new(tris: &[Triangle], hq: bool) -> Self {
        let verts = vertices(tris);
        // SAFETY: 3 aligned vertices per triangle, kept alive beside the tree.
        let raw = unsafe { strahl_tb_bvh8_new(verts.as_ptr().cast(), tris.len() as u32, hq as i32) };
        Self { raw, _verts: verts }
    }

    /// How many of `rays` hit something (one `Intersect` each).
    pub fn intersect_count(&self, rays: &[Ray]) -> usize {
        // SAFETY: `Ray` is `#[repr(C)]`, 8 floats (origin, tmin, direction, tmax), as the C side
        // reads it; `raw` is live.
        unsafe { strahl_tb_bvh8_intersect(self.raw, rays.as_ptr().cast(), rays.len()) }
    }

    /// How many of `rays` are occluded (one `IsOccluded` each).
    pub fn occluded_count(&self, rays: &[Ray]) -> usize {
        // SAFETY: as in `intersect_count`.
        unsafe { strahl_tb_bvh8_occluded(self.raw, rays.as_ptr().cast(), rays.len()) }
    }
}

impl Drop for Bvh8 {
    fn drop(&mut self) {
        // SAFETY: made by `strahl_tb_bvh8_new`, freed once.
        unsafe { strahl_tb_bvh8_free(self.raw) }
    }
}
