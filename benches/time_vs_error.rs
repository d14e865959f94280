//! Time against error for the two ray/triangle tests: nanoseconds per ray/triangle test on rays
//! aimed exactly at the edges and vertices of a closed icosphere, beside the false-miss rate on the
//! same rays (printed once, before the timings). Group `time_vs_error_bvh8`: whole BVH8 closest-hit
//! traversals of the same rays with the conservative and the fast slab test
//! ([`Fast`](strahl::traverse::Fast)), each triangle test, beside their false misses.
//!
//! `cargo bench --bench time_vs_error`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Duration;
use strahl::Vec3;
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::Triangle;
use strahl::intersect::{PreparedRay, TriangleX8, moller, watertight};
use strahl::layout::Bvh8;
use strahl::scene::{self, Aim};
use strahl::traverse::{Fast, Moller, TriangleTest, Watertight};

type Scalar = fn(&PreparedRay, &Triangle, u32) -> Option<strahl::Hit>;

fn setup() -> (Vec<Triangle>, Vec<TriangleX8>, Vec<PreparedRay>) {
    let mut m = scene::icosphere(3);
    for p in &mut m.positions {
        *p = *p * 3.7 + Vec3::new(0.31, -1.7, 2.1);
    }
    let mut rays = scene::aimed_rays(&m, Aim::Edges, 4, 3.0, 1);
    rays.extend(scene::aimed_rays(&m, Aim::Vertices, 8, 3.0, 2));
    let tris = m.to_soup();
    let packed = tris
        .chunks(8)
        .enumerate()
        .map(|(c, ch)| TriangleX8::pack(ch, &(0..8).map(|i| (c * 8 + i) as u32).collect::<Vec<_>>()))
        .collect();
    (tris, packed, rays.iter().map(PreparedRay::new).collect())
}

fn bench(c: &mut Criterion) {
    let (tris, packed, rays) = setup();
    for (name, f) in [
        ("moller", moller::intersect_scalar as Scalar),
        ("watertight", watertight::intersect_scalar),
    ] {
        let misses = rays
            .iter()
            .filter(|r| !tris.iter().any(|t| f(r, t, 0).is_some()))
            .count();
        println!(
            "false-miss rate {name}: {misses} of {} edge/vertex-aimed rays = {:.3}%",
            rays.len(),
            100.0 * misses as f64 / rays.len() as f64
        );
    }
    // Time a subset of the rays against every triangle (closest hit, brute force).
    let timed = &rays[..rays.len().min(1024)];
    let mut g = c.benchmark_group("time_vs_error");
    g.sample_size(20)
        .measurement_time(Duration::from_secs(3))
        .warm_up_time(Duration::from_secs(1));
    g.throughput(Throughput::Elements((timed.len() * tris.len()) as u64));
    for (name, f) in [
        ("moller_scalar", moller::intersect_scalar as Scalar),
        ("watertight_scalar", watertight::intersect_scalar),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut n = 0u32;
                for r in timed {
                    for (i, t) in tris.iter().enumerate() {
                        n += f(r, t, i as u32).is_some() as u32;
                    }
                }
                black_box(n)
            })
        });
    }
    g.bench_function("moller_x8", |b| {
        b.iter(|| {
            timed
                .iter()
                .map(|r| packed.iter().filter(|p| moller::intersect_x8(r, p).is_some()).count())
                .sum::<usize>()
        })
    });
    g.bench_function("watertight_x8", |b| {
        b.iter(|| {
            timed
                .iter()
                .map(|r| {
                    packed
                        .iter()
                        .filter(|p| watertight::intersect_x8(r, p).is_some())
                        .count()
                })
                .sum::<usize>()
        })
    });
    g.finish();
    bench_bvh8(c, &tris, &rays);
}

/// Closest hits of every aimed ray through a BVH8 under `T`.
fn trace_bvh8<T: TriangleTest>(b8: &Bvh8, rays: &[strahl::Ray]) -> usize {
    rays.iter().filter(|r| b8.intersect::<T>(r).is_some()).count()
}

fn bench_bvh8(c: &mut Criterion, tris: &[Triangle], prepared: &[PreparedRay]) {
    let rays: Vec<strahl::Ray> = prepared
        .iter()
        .map(|r| strahl::Ray::with_range(r.origin, r.direction, r.tmin, r.tmax))
        .collect();
    let (b2, _) = Bvh2::build(tris, &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, tris).unwrap();
    type Trace = fn(&Bvh8, &[strahl::Ray]) -> usize;
    let members: [(&str, Trace); 4] = [
        ("bvh8_moller", trace_bvh8::<Moller>),
        ("bvh8_fast_moller", trace_bvh8::<Fast<Moller>>),
        ("bvh8_watertight", trace_bvh8::<Watertight>),
        ("bvh8_fast_watertight", trace_bvh8::<Fast<Watertight>>),
    ];
    for (name, f) in &members {
        let misses = rays.len() - f(&b8, &rays);
        println!(
            "false-miss rate {name}: {misses} of {} edge/vertex-aimed rays = {:.3}%",
            rays.len(),
            100.0 * misses as f64 / rays.len() as f64
        );
    }
    let mut g = c.benchmark_group("time_vs_error_bvh8");
    g.sample_size(20)
        .measurement_time(Duration::from_secs(3))
        .warm_up_time(Duration::from_secs(1));
    g.throughput(Throughput::Elements(rays.len() as u64));
    for (name, f) in members {
        g.bench_function(name, |b| b.iter(|| f(&b8, black_box(&rays))));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
