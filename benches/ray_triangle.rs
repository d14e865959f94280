//! Ray/triangle throughput of Möller-Trumbore and watertight: scalar reference, one ray against
//! 4 or 8 triangles, and 8 rays against one triangle, as members of one group per test so the
//! ratios come from one run:
//!
//! ```text
//! cargo bench --bench ray_triangle   # .cargo/config.toml adds -C target-cpu=native
//! ```
//!
//! Every member does the same ray/triangle tests: [`RAYS`] rays in packets of 8, packet `k`
//! against the [`WIDTH`] triangles of leaf `k % LEAVES` (the leaves fit in L1). Each ray keeps its
//! closest hit: the scalar reference loops over the 8 triangles shrinking `tmax`, `x4` makes
//! 2 calls, `x8` one, and `packet8` runs [`PreparedPacket8`] through the 8 triangles one by one.
//! Throughput is in ray/triangle tests. Rays, packets and triangles are prepared outside the timed
//! loop (`packet8` copies its packet, since the kernel shrinks `tmax`); each member returns a
//! checksum of the closest primitives, which must agree, so nothing is optimised away.
//!
//! Scene: each leaf holds 8 triangles of random orientation around a point near the leaf's centre
//! (corners 0.5 to 1 away from it); a packet starts near a random point at distance 4 and its rays
//! aim at random points within 0.5 of the centre. About 41% of the tests and 95% of the rays hit
//! (both rates are printed at start-up).
//!
//! The group `occluded` compares the any-hit forms: `occluded_x8` against a scalar loop that
//! stops at the first hit (so the scalar side may do fewer tests than counted).

use criterion::{BenchmarkGroup, Criterion, Throughput, criterion_group, criterion_main, measurement::WallTime};
use std::hint::black_box;
use std::time::Duration;
use strahl::geometry::{INVALID, Triangle};
use strahl::intersect::{HitLanes, PreparedPacket8, PreparedRay, TriangleX4, TriangleX8, moller, watertight};
use strahl::{Hit, Ray, Vec3};

/// Rays per packet.
const PACKET: usize = 8;
/// Rays per iteration (a multiple of `PACKET * LEAVES`).
const RAYS: usize = 4096;
/// Triangles per leaf (tested against every ray of a packet).
const WIDTH: usize = 8;
/// Distinct leaves: `64 * 8` triangles are 18 KiB as `[Vec3; 3]`, 22 KiB as `TriangleX8`.
const LEAVES: usize = 64;

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

    /// Uniform in `[0, 1)^3`.
    fn unit(&mut self) -> Vec3 {
        Vec3::new(self.f(), self.f(), self.f())
    }

    /// Uniform in the unit ball (rejection from the cube).
    fn ball(&mut self) -> Vec3 {
        loop {
            let p = self.unit() * 2.0 - Vec3::ONE;
            if p.length_squared() <= 1.0 {
                return p;
            }
        }
    }

    /// A triangle around `c`: its corners lie at distance 0.5..1 from a point near `c`, about a
    /// third of a turn apart, in a plane of random orientation; rays aimed near `c` often hit it.
    fn triangle(&mut self, c: Vec3) -> Triangle {
        let (e1, e2) = self.sphere().any_orthonormal_pair();
        let centre = c + self.ball() * 0.2;
        let turn = self.f();
        [0.0, 1.0, 2.0].map(|i| {
            let angle = std::f32::consts::TAU * (turn + (i + self.f() * 0.5) / 3.0);
            centre + (e1 * angle.cos() + e2 * angle.sin()) * (0.5 + 0.5 * self.f())
        })
    }

    /// Uniform on the unit sphere.
    fn sphere(&mut self) -> Vec3 {
        loop {
            let p = self.ball();
            if p.length_squared() > 1e-3 {
                return p.normalize();
            }
        }
    }
}

struct Scene {
    /// `RAYS` rays, packet-major: rays `8k .. 8k + 8` form packet `k`.
    rays: Vec<PreparedRay>,
    /// The same rays as packets.
    packets: Vec<PreparedPacket8>,
    /// `LEAVES * WIDTH` triangles, leaf-major; triangle `j` of leaf `l` is primitive `8 l + j`.
    tris: Vec<Triangle>,
    /// The same triangles, two 4-wide packs per leaf.
    x4: Vec<[TriangleX4; 2]>,
    /// The same triangles, one 8-wide pack per leaf.
    x8: Vec<TriangleX8>,
}

fn scene() -> Scene {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let centres: Vec<Vec3> = (0..LEAVES).map(|_| rng.unit() * 16.0).collect();
    let tris: Vec<Triangle> = centres
        .iter()
        .flat_map(|&c| (0..WIDTH).map(|_| rng.triangle(c)).collect::<Vec<_>>())
        .collect();
    let prims: Vec<u32> = (0..(LEAVES * WIDTH) as u32).collect();
    let x4 = tris
        .chunks(WIDTH)
        .zip(prims.chunks(WIDTH))
        .map(|(t, p)| [TriangleX4::pack(&t[..4], &p[..4]), TriangleX4::pack(&t[4..], &p[4..])])
        .collect();
    let x8 = tris
        .chunks(WIDTH)
        .zip(prims.chunks(WIDTH))
        .map(|(t, p)| TriangleX8::pack(t, p))
        .collect();
    let mut rays = Vec::with_capacity(RAYS);
    let mut packets = Vec::with_capacity(RAYS / PACKET);
    for k in 0..RAYS / PACKET {
        let c = centres[k % LEAVES];
        let eye = c + rng.sphere() * 4.0;
        let packet: Vec<Ray> = (0..PACKET)
            .map(|_| {
                let o = eye + rng.ball() * 0.05;
                Ray::new(o, c + rng.ball() * 0.5 - o)
            })
            .collect();
        rays.extend(packet.iter().map(PreparedRay::new));
        packets.push(PreparedPacket8::new(&packet));
    }
    Scene {
        rays,
        packets,
        tris,
        x4,
        x8,
    }
}

/// Checksum of one ray's closest hit: `prim + 1`, or 0 for a miss.
fn sum(h: Option<Hit>) -> u64 {
    h.map_or(0, |h| h.prim as u64 + 1)
}

/// The ray batches and the leaf of each: packet `k` meets leaf `k % LEAVES`.
fn batches<'a, L>(rays: &'a [PreparedRay], leaves: &'a [L]) -> impl Iterator<Item = (&'a [PreparedRay], &'a L)> {
    rays.chunks(PACKET * LEAVES)
        .flat_map(move |c| c.chunks_exact(PACKET).zip(leaves))
}

// The runners are `#[inline(never)]` so that `objdump -d` of the bench binary shows each one as a
// symbol of its own; the kernels (fn items, zero-sized) are inlined into them.

/// Scalar reference: a leaf loop over the 8 triangles that shrinks `tmax` on each hit.
#[inline(never)]
fn run_scalar(f: impl Fn(&PreparedRay, &Triangle, u32) -> Option<Hit>, rays: &[PreparedRay], tris: &[Triangle]) -> u64 {
    let mut acc = 0;
    for chunk in rays.chunks(PACKET * LEAVES) {
        for (packet, (leaf, tri)) in chunk.chunks_exact(PACKET).zip(tris.chunks_exact(WIDTH).enumerate()) {
            for ray in packet {
                let mut r = *ray;
                let mut best = None;
                for (j, t) in tri.iter().enumerate() {
                    if let Some(h) = f(&r, t, (leaf * WIDTH + j) as u32) {
                        r.tmax = h.t;
                        best = Some(h);
                    }
                }
                acc += sum(best);
            }
        }
    }
    acc
}

/// Two 4-wide calls per ray and leaf; ties go to the first call, as in the scalar loop.
#[inline(never)]
fn run_x4(f: impl Fn(&PreparedRay, &TriangleX4) -> Option<Hit>, rays: &[PreparedRay], x4: &[[TriangleX4; 2]]) -> u64 {
    let mut acc = 0;
    for (packet, [lo, hi]) in batches(rays, x4) {
        for r in packet {
            let best = match (f(r, lo), f(r, hi)) {
                (Some(a), Some(b)) => Some(if b.t < a.t { b } else { a }),
                (a, b) => a.or(b),
            };
            acc += sum(best);
        }
    }
    acc
}

/// One 8-wide call per ray and leaf.
#[inline(never)]
fn run_x8(f: impl Fn(&PreparedRay, &TriangleX8) -> Option<Hit>, rays: &[PreparedRay], x8: &[TriangleX8]) -> u64 {
    let mut acc = 0;
    for (packet, leaf) in batches(rays, x8) {
        for r in packet {
            acc += sum(f(r, leaf));
        }
    }
    acc
}

/// 8 rays at a time against each triangle of the leaf.
#[inline(never)]
fn run_packet8(
    f: impl Fn(&mut PreparedPacket8, &Triangle, u32, &mut HitLanes<strahl::math::f32x8, 8>) -> u32,
    packets: &[PreparedPacket8],
    tris: &[Triangle],
) -> u64 {
    let mut acc = 0;
    for chunk in packets.chunks(LEAVES) {
        for (packet, (leaf, tri)) in chunk.iter().zip(tris.chunks_exact(WIDTH).enumerate()) {
            let mut p = *packet;
            let mut hits = HitLanes::default();
            for (j, t) in tri.iter().enumerate() {
                f(&mut p, t, (leaf * WIDTH + j) as u32, &mut hits);
            }
            acc += hits
                .prim
                .iter()
                .map(|&i| if i == INVALID { 0 } else { i as u64 + 1 })
                .sum::<u64>();
        }
    }
    acc
}

/// Any-hit scalar loop: stops at the first triangle hit.
#[inline(never)]
fn run_occluded_scalar(
    f: impl Fn(&PreparedRay, &Triangle, u32) -> Option<Hit>,
    rays: &[PreparedRay],
    tris: &[Triangle],
) -> u32 {
    let mut n = 0;
    for chunk in rays.chunks(PACKET * LEAVES) {
        for (packet, tri) in chunk.chunks_exact(PACKET).zip(tris.chunks_exact(WIDTH)) {
            for r in packet {
                n += tri.iter().any(|t| f(r, t, 0).is_some()) as u32;
            }
        }
    }
    n
}

/// Any-hit, one 8-wide call per ray and leaf.
#[inline(never)]
fn run_occluded_x8(f: impl Fn(&PreparedRay, &TriangleX8) -> bool, rays: &[PreparedRay], x8: &[TriangleX8]) -> u32 {
    let mut n = 0;
    for (packet, leaf) in batches(rays, x8) {
        for r in packet {
            n += f(r, leaf) as u32;
        }
    }
    n
}

fn configure(g: &mut BenchmarkGroup<'_, WallTime>) {
    g.throughput(Throughput::Elements((RAYS * WIDTH) as u64));
    g.sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2));
}

/// Prints the hit rates of the workload (per test and per ray) for the report.
fn rates(name: &str, f: impl Fn(&PreparedRay, &Triangle, u32) -> Option<Hit>, s: &Scene) {
    let (mut tests, mut rays) = (0usize, 0usize);
    for (k, packet) in s.rays.chunks_exact(PACKET).enumerate() {
        let tri = &s.tris[(k % LEAVES) * WIDTH..][..WIDTH];
        for r in packet {
            let n = tri.iter().filter(|t| f(r, t, 0).is_some()).count();
            tests += n;
            rays += (n > 0) as usize;
        }
    }
    let pct = |n: usize, of: usize| 100.0 * n as f64 / of as f64;
    eprintln!(
        "{name}: {} tests per iteration, {:.1}% of tests hit, {:.1}% of rays hit",
        RAYS * WIDTH,
        pct(tests, RAYS * WIDTH),
        pct(rays, RAYS)
    );
}

fn closest(c: &mut Criterion) {
    let s = scene();

    rates("moller", moller::intersect_scalar, &s);
    let want = run_scalar(moller::intersect_scalar, &s.rays, &s.tris);
    assert_eq!(want, run_x4(moller::intersect_x4, &s.rays, &s.x4));
    assert_eq!(want, run_x8(moller::intersect_x8, &s.rays, &s.x8));
    assert_eq!(want, run_packet8(moller::intersect_packet, &s.packets, &s.tris));
    let mut g = c.benchmark_group("moller");
    configure(&mut g);
    g.bench_function("scalar", |b| {
        b.iter(|| run_scalar(moller::intersect_scalar, black_box(&s.rays), black_box(&s.tris)))
    });
    g.bench_function("x4", |b| {
        b.iter(|| run_x4(moller::intersect_x4, black_box(&s.rays), black_box(&s.x4)))
    });
    g.bench_function("x8", |b| {
        b.iter(|| run_x8(moller::intersect_x8, black_box(&s.rays), black_box(&s.x8)))
    });
    g.bench_function("packet8", |b| {
        b.iter(|| run_packet8(moller::intersect_packet, black_box(&s.packets), black_box(&s.tris)))
    });
    g.finish();

    rates("watertight", watertight::intersect_scalar, &s);
    let want = run_scalar(watertight::intersect_scalar, &s.rays, &s.tris);
    assert_eq!(want, run_x4(watertight::intersect_x4, &s.rays, &s.x4));
    assert_eq!(want, run_x8(watertight::intersect_x8, &s.rays, &s.x8));
    assert_eq!(want, run_packet8(watertight::intersect_packet, &s.packets, &s.tris));
    let mut g = c.benchmark_group("watertight");
    configure(&mut g);
    g.bench_function("scalar", |b| {
        b.iter(|| run_scalar(watertight::intersect_scalar, black_box(&s.rays), black_box(&s.tris)))
    });
    g.bench_function("x4", |b| {
        b.iter(|| run_x4(watertight::intersect_x4, black_box(&s.rays), black_box(&s.x4)))
    });
    g.bench_function("x8", |b| {
        b.iter(|| run_x8(watertight::intersect_x8, black_box(&s.rays), black_box(&s.x8)))
    });
    g.bench_function("packet8", |b| {
        b.iter(|| run_packet8(watertight::intersect_packet, black_box(&s.packets), black_box(&s.tris)))
    });
    g.finish();
}

fn occluded(c: &mut Criterion) {
    let s = scene();
    let want = run_occluded_scalar(moller::intersect_scalar, &s.rays, &s.tris);
    assert_eq!(want, run_occluded_x8(moller::occluded_x8, &s.rays, &s.x8));
    let want = run_occluded_scalar(watertight::intersect_scalar, &s.rays, &s.tris);
    assert_eq!(want, run_occluded_x8(watertight::occluded_x8, &s.rays, &s.x8));

    let mut g = c.benchmark_group("occluded");
    configure(&mut g);
    g.bench_function("moller_scalar", |b| {
        b.iter(|| run_occluded_scalar(moller::intersect_scalar, black_box(&s.rays), black_box(&s.tris)))
    });
    g.bench_function("moller_x8", |b| {
        b.iter(|| run_occluded_x8(moller::occluded_x8, black_box(&s.rays), black_box(&s.x8)))
    });
    g.bench_function("watertight_scalar", |b| {
        b.iter(|| run_occluded_scalar(watertight::intersect_scalar, black_box(&s.rays), black_box(&s.tris)))
    });
    g.bench_function("watertight_x8", |b| {
        b.iter(|| run_occluded_x8(watertight::occluded_x8, black_box(&s.rays), black_box(&s.x8)))
    });
    g.finish();
}

criterion_group!(benches, closest, occluded);
criterion_main!(benches);
