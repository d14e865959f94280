//! Ray/box slab test throughput: scalar reference, `x4` and `x8`, as members of one group so the
//! ratios come from one run:
//!
//! ```text
//! cargo bench --bench ray_box        # .cargo/config.toml adds -C target-cpu=native
//! ```
//!
//! Every member does the same work: [`RAYS`] rays, each against the [`WIDTH`] boxes of one node
//! (a BVH8 node's children), nodes taken round-robin from [`NODES`] nodes that together fit in L1.
//! The scalar reference loops over the 8 boxes (`scalar` one box at a time, `scalar_autovec` the
//! same loop as LLVM vectorises it), `x4` makes 2 calls and `x8` one. Throughput is in
//! ray/box tests. Rays and boxes are prepared and packed outside the timed loop; the hit count
//! is returned (and black-boxed by criterion) so nothing is optimised away.
//!
//! Scene: boxes with random centres in `[0, 1]^3` and half-extents in `[0.25, 0.45]`; rays from
//! random points on a sphere of radius 2 around the cube's centre, aimed at random points of the
//! cube. About 47% of the tests hit (the rate is printed at start-up).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Duration;
use strahl::intersect::{AabbX4, AabbX8, PreparedRay, intersect_aabb_scalar, intersect_aabb_x4, intersect_aabb_x8};
use strahl::{Aabb, Ray, Vec3};

/// Rays per iteration.
const RAYS: usize = 4096;
/// Boxes per node (tested against every ray).
const WIDTH: usize = 8;
/// Distinct nodes: `64 * 8` boxes are 12 KiB in either layout.
const NODES: usize = 64;

/// Deterministic xorshift64* generator, so runs are comparable without `rand`.
struct Rng(u64);

impl Rng {
    /// Uniform in `[0, 1)`.
    fn f(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }

    /// Uniform in `[0, 1)^3`.
    fn unit(&mut self) -> Vec3 {
        Vec3::new(self.f(), self.f(), self.f())
    }

    /// Uniform on the unit sphere (rejection from the cube).
    fn sphere(&mut self) -> Vec3 {
        loop {
            let p = self.unit() * 2.0 - Vec3::ONE;
            let l = p.length_squared();
            if l > 1e-3 && l <= 1.0 {
                return p / l.sqrt();
            }
        }
    }
}

struct Scene {
    rays: Vec<PreparedRay>,
    /// `NODES * WIDTH` boxes, node-major (AoS, for the scalar reference).
    boxes: Vec<Aabb>,
    /// The same boxes, two 4-wide packs per node.
    x4: Vec<[AabbX4; 2]>,
    /// The same boxes, one 8-wide pack per node.
    x8: Vec<AabbX8>,
}

fn scene() -> Scene {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let centre = Vec3::splat(0.5);
    let rays = (0..RAYS)
        .map(|_| {
            let o = centre + rng.sphere() * 2.0;
            PreparedRay::new(&Ray::new(o, rng.unit() - o))
        })
        .collect();
    let boxes: Vec<Aabb> = (0..NODES * WIDTH)
        .map(|_| {
            let c = rng.unit();
            let h = Vec3::new(rng.range(0.25, 0.45), rng.range(0.25, 0.45), rng.range(0.25, 0.45));
            Aabb::new(c - h, c + h)
        })
        .collect();
    let x4 = boxes
        .chunks(WIDTH)
        .map(|n| [AabbX4::from_boxes(&n[..4]), AabbX4::from_boxes(&n[4..])])
        .collect();
    let x8 = boxes.chunks(WIDTH).map(AabbX8::from_boxes).collect();
    Scene { rays, boxes, x4, x8 }
}

// The runners are `#[inline(never)]` so that `objdump -d` of the bench binary shows each one as a
// symbol of its own; one call per iteration of 32768 tests costs nothing measurable.

/// Hits of the scalar reference, one box at a time as a traversal visits them: ray `i` against the
/// boxes of node `i % NODES`.
///
/// NOTE: `black_box(b)` is an optimisation barrier per test. Without it LLVM vectorises this loop
/// (AoS loads gathered with `vinsertps` into `ymm`, across the 8 boxes or across 8 rays), because
/// the hits are only counted; that variant is measured as `scalar_autovec`.
#[inline(never)]
fn run_scalar(rays: &[PreparedRay], boxes: &[Aabb]) -> u32 {
    let mut hits = 0;
    for chunk in rays.chunks(NODES) {
        for (r, node) in chunk.iter().zip(boxes.chunks_exact(WIDTH)) {
            for b in node {
                hits += intersect_aabb_scalar(r, black_box(b)).is_some() as u32;
            }
        }
    }
    hits
}

/// The scalar reference loop without a barrier: whatever LLVM makes of it.
#[inline(never)]
fn run_scalar_autovec(rays: &[PreparedRay], boxes: &[Aabb]) -> u32 {
    let mut hits = 0;
    for chunk in rays.chunks(NODES) {
        for (r, node) in chunk.iter().zip(boxes.chunks_exact(WIDTH)) {
            for b in node {
                hits += intersect_aabb_scalar(r, b).is_some() as u32;
            }
        }
    }
    hits
}

/// Hits of two `x4` calls per ray and node.
#[inline(never)]
fn run_x4(rays: &[PreparedRay], nodes: &[[AabbX4; 2]]) -> u32 {
    let mut hits = 0;
    for chunk in rays.chunks(NODES) {
        for (r, [lo, hi]) in chunk.iter().zip(nodes) {
            hits += intersect_aabb_x4(r, lo).1.count_ones() + intersect_aabb_x4(r, hi).1.count_ones();
        }
    }
    hits
}

/// Hits of one `x8` call per ray and node.
#[inline(never)]
fn run_x8(rays: &[PreparedRay], nodes: &[AabbX8]) -> u32 {
    let mut hits = 0;
    for chunk in rays.chunks(NODES) {
        for (r, node) in chunk.iter().zip(nodes) {
            hits += intersect_aabb_x8(r, node).1.count_ones();
        }
    }
    hits
}

fn ray_box(c: &mut Criterion) {
    let s = scene();
    let tests = (RAYS * WIDTH) as u64;
    // All members must agree; the hit rate shows the workload is not trivially all-hit or all-miss.
    let hits = run_scalar(&s.rays, &s.boxes);
    assert_eq!(hits, run_scalar_autovec(&s.rays, &s.boxes));
    assert_eq!(hits, run_x4(&s.rays, &s.x4));
    assert_eq!(hits, run_x8(&s.rays, &s.x8));
    eprintln!(
        "ray_box: {tests} tests per iteration, hit rate {:.1}%",
        100.0 * hits as f64 / tests as f64
    );

    let mut g = c.benchmark_group("ray_box");
    g.throughput(Throughput::Elements(tests));
    g.sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2));
    g.bench_function("scalar", |b| {
        b.iter(|| run_scalar(black_box(&s.rays), black_box(&s.boxes)))
    });
    g.bench_function("scalar_autovec", |b| {
        b.iter(|| run_scalar_autovec(black_box(&s.rays), black_box(&s.boxes)))
    });
    g.bench_function("x4", |b| b.iter(|| run_x4(black_box(&s.rays), black_box(&s.x4))));
    g.bench_function("x8", |b| b.iter(|| run_x8(black_box(&s.rays), black_box(&s.x8))));
    g.finish();
}

criterion_group!(benches, ray_box);
criterion_main!(benches);
