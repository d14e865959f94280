//! Morton code throughput: scalar reference, 8-lane kernel, and the slice APIs (AoS and SoA), on
//! 2^20 random points in the unit cube. One group per code width so the ratios come from one run:
//!
//! ```text
//! cargo bench --bench morton    # .cargo/config.toml adds -C target-cpu=native (AVX2 here)
//! ```
//!
//! `x8` calls [`morton30_x8`] / [`morton63_x8`] on points already in lanes; `slice_aos` and
//! `slice_soa` are the slice APIs a builder calls (AoS transposes eight `Vec3` per step).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Duration;
use strahl::geometry::morton::*;
use strahl::math::{f32x8, u32x8};
use strahl::{Aabb, Vec3};

const N: usize = 1 << 20;

/// Deterministic points in `[0, 1)^3` (xorshift64*), so runs are comparable without `rand`.
fn points() -> Vec<Vec3> {
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut f = move || {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        (s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    };
    (0..N).map(|_| Vec3::new(f(), f(), f())).collect()
}

struct Soa {
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
    lanes: Vec<[f32x8; 3]>,
}

fn soa(pts: &[Vec3]) -> Soa {
    let xs: Vec<f32> = pts.iter().map(|p| p.x).collect();
    let ys: Vec<f32> = pts.iter().map(|p| p.y).collect();
    let zs: Vec<f32> = pts.iter().map(|p| p.z).collect();
    let lanes = (0..pts.len() / 8)
        .map(|i| {
            let l = |v: &[f32]| f32x8::new(v[8 * i..8 * i + 8].try_into().unwrap());
            [l(&xs), l(&ys), l(&zs)]
        })
        .collect();
    Soa { xs, ys, zs, lanes }
}

fn morton30(c: &mut Criterion) {
    let pts = points();
    let s = soa(&pts);
    let q = MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::ONE));
    let mut out = vec![0u32; N];
    let mut out8 = vec![u32x8::ZERO; N / 8];

    let mut g = c.benchmark_group("morton30");
    g.throughput(Throughput::Elements(N as u64));
    g.sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    g.bench_function("scalar", |b| {
        b.iter(|| {
            for (p, o) in black_box(&pts).iter().zip(out.iter_mut()) {
                *o = morton30_scalar(*p, &q);
            }
            black_box(&mut out);
        })
    });
    g.bench_function("x8", |b| {
        b.iter(|| {
            for ([x, y, z], o) in black_box(&s.lanes).iter().zip(out8.iter_mut()) {
                *o = morton30_x8(*x, *y, *z, &q);
            }
            black_box(&mut out8);
        })
    });
    g.bench_function("slice_aos", |b| {
        b.iter(|| morton30_slice(black_box(&pts), &q, black_box(&mut out)))
    });
    g.bench_function("slice_soa", |b| {
        b.iter(|| morton30_slice_soa(black_box(&s.xs), &s.ys, &s.zs, &q, black_box(&mut out)))
    });
    g.finish();
}

fn morton63(c: &mut Criterion) {
    let pts = points();
    let s = soa(&pts);
    let q = MortonQuantizer::new63(&Aabb::new(Vec3::ZERO, Vec3::ONE));
    let mut out = vec![0u64; N];
    let mut out8 = vec![[0u64; 8]; N / 8];

    let mut g = c.benchmark_group("morton63");
    g.throughput(Throughput::Elements(N as u64));
    g.sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    g.bench_function("scalar", |b| {
        b.iter(|| {
            for (p, o) in black_box(&pts).iter().zip(out.iter_mut()) {
                *o = morton63_scalar(*p, &q);
            }
            black_box(&mut out);
        })
    });
    g.bench_function("x8", |b| {
        b.iter(|| {
            for ([x, y, z], o) in black_box(&s.lanes).iter().zip(out8.iter_mut()) {
                *o = morton63_x8(*x, *y, *z, &q);
            }
            black_box(&mut out8);
        })
    });
    g.bench_function("slice_aos", |b| {
        b.iter(|| morton63_slice(black_box(&pts), &q, black_box(&mut out)))
    });
    g.bench_function("slice_soa", |b| {
        b.iter(|| morton63_slice_soa(black_box(&s.xs), &s.ys, &s.zs, &q, black_box(&mut out)))
    });
    g.finish();
}

criterion_group!(benches, morton30, morton63);
criterion_main!(benches);
