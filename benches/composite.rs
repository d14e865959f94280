//! Sort-last compositing benchmarks.
//!
//! - `composite_kernels`: the over (f32, u8) and depth operators, scalar and SIMD, on a 1024 x 1024
//!   image, against a plain copy of the same buffer (`copy`); throughput in bytes of one image.
//! - `composite_schedules`: compositing time of 1024 x 1024 RGBA f32 partial images across P
//!   in-process ranks (threads) for each k-vector, including the automatic choice.
//! - `tile_queue`: a skewed render (cost concentrated in a corner) on 2 threads, static bands
//!   against the dynamic tile queue.
//!
//! `cargo bench --bench composite -- --noplot`

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use strahl::composite::{
    Assignment, CostModel, DepthPixel, KVec, Pixel, Plan, RgbaF32, Schedule, ThreadTransport, Transport, auto_kvec,
    composite, depth_scalar, depth_x4, over_f32_scalar, over_f32_x8, over_u8_scalar, over_u8_x8, render_tiles,
};
use strahl::scene::Rng;

const W: usize = 1024;
const H: usize = 1024;

fn kernels(c: &mut Criterion) {
    let n = W * H;
    let mut rng = Rng::new(1);
    let rgba: Vec<f32> = (0..n)
        .flat_map(|_| {
            let a = rng.f32();
            [rng.f32() * a, rng.f32() * a, rng.f32() * a, a]
        })
        .collect();
    let rgba2: Vec<f32> = rgba.iter().rev().copied().collect();
    let px8: Vec<u32> = (0..n)
        .map(|_| rng.u64() as u32)
        .map(|p| p & 0x7f7f_7f7f | 0x8000_0000)
        .collect();
    let px8b: Vec<u32> = px8.iter().rev().copied().collect();
    let keys: Vec<u64> = (0..n).map(|_| DepthPixel::new(rng.f32(), rng.u64() as u32).0).collect();
    let keys2: Vec<u64> = keys.iter().rev().copied().collect();

    let mut g = c.benchmark_group("composite_kernels");
    g.sample_size(20);
    // RGBA f32: 16 bytes per pixel.
    g.throughput(Throughput::Bytes((n * 16) as u64));
    let mut acc = rgba.clone();
    g.bench_function("copy_f32", |b| b.iter(|| acc.copy_from_slice(black_box(&rgba2))));
    g.bench_function("over_f32_scalar", |b| {
        b.iter(|| over_f32_scalar(&mut acc, black_box(&rgba2), true))
    });
    g.bench_function("over_f32_x8", |b| {
        b.iter(|| over_f32_x8(&mut acc, black_box(&rgba2), true))
    });
    // RGBA u8: 4 bytes per pixel.
    g.throughput(Throughput::Bytes((n * 4) as u64));
    let mut acc8 = px8.clone();
    g.bench_function("copy_u8", |b| b.iter(|| acc8.copy_from_slice(black_box(&px8b))));
    g.bench_function("over_u8_scalar", |b| {
        b.iter(|| over_u8_scalar(&mut acc8, black_box(&px8b), true))
    });
    g.bench_function("over_u8_x8", |b| {
        b.iter(|| over_u8_x8(&mut acc8, black_box(&px8b), true))
    });
    // Depth: 8 bytes per pixel.
    g.throughput(Throughput::Bytes((n * 8) as u64));
    let mut accz = keys.clone();
    g.bench_function("copy_depth", |b| b.iter(|| accz.copy_from_slice(black_box(&keys2))));
    g.bench_function("depth_scalar", |b| {
        b.iter(|| depth_scalar(&mut accz, black_box(&keys2)))
    });
    g.bench_function("depth_x4", |b| b.iter(|| depth_x4(&mut accz, black_box(&keys2))));
    g.finish();
}

fn schedules(c: &mut Criterion) {
    let n = W * H;
    let model = CostModel::shared_memory();
    let mut g = c.benchmark_group("composite_schedules");
    g.sample_size(10);
    g.throughput(Throughput::Bytes((n * RgbaF32::BYTES) as u64));
    for p in [2u32, 4, 8] {
        let mut rng = Rng::new(p as u64);
        // Each rank covers a vertical band (a spatial partition seen from the front) plus noise.
        let images: Vec<Vec<RgbaF32>> = (0..p as usize)
            .map(|r| {
                (0..n)
                    .map(|i| {
                        let x = i % W;
                        if x * p as usize / W == r || rng.f32() < 0.1 {
                            RgbaF32([0.25; 4])
                        } else {
                            RgbaF32::EMPTY
                        }
                    })
                    .collect()
            })
            .collect();
        let order: Vec<u32> = (0..p).collect();
        let auto = auto_kvec(p, n as u64, RgbaF32::BYTES as u64, &model);
        let mut kinds = vec![
            ("tree".to_string(), Schedule::Tree),
            ("direct".into(), Schedule::RadixK(KVec::direct_send(p))),
        ];
        if let Some(k) = KVec::binary_swap(p) {
            kinds.push(("binary_swap".into(), Schedule::RadixK(k)));
        }
        if p == 8 {
            kinds.push(("radix_4x2".into(), Schedule::RadixK(KVec::new(&[4, 2]).unwrap())));
            kinds.push(("radix_2x4".into(), Schedule::RadixK(KVec::new(&[2, 4]).unwrap())));
        }
        kinds.push((format!("auto_{:?}", auto.as_slice()), Schedule::RadixK(auto)));
        for (name, s) in kinds {
            g.bench_with_input(BenchmarkId::new(name, p), &s, |b, &s| {
                b.iter(|| {
                    ThreadTransport::run(p, |t| {
                        let plan = Plan {
                            schedule: s,
                            order: &order,
                            root: 0,
                            sparse: true,
                        };
                        composite(t, &images[t.rank() as usize], &plan).map(|r| r.0.map(|v| v.len()))
                    })
                })
            });
        }
    }
    g.finish();
}

/// Cost of shading pixel `(x, y)`: heavy in the top-left eighth of the image, light elsewhere.
fn skewed(x: u32, y: u32) -> f32 {
    let heavy = x < 256 && y < 256;
    let iters = if heavy { 400 } else { 4 };
    let mut v = (x ^ y) as f32;
    for i in 0..iters {
        v = (v * 1.0001 + i as f32).sqrt();
    }
    v
}

fn tile_queue(c: &mut Criterion) {
    let mut g = c.benchmark_group("tile_queue");
    g.sample_size(10);
    g.throughput(Throughput::Elements((W * H) as u64));
    for (name, a) in [
        ("static_bands", Assignment::Static),
        ("dynamic_queue", Assignment::Dynamic),
    ] {
        let stats = render_tiles(W as u32, H as u32, 32, 2, a, |t, out: &mut [f32]| {
            let w = t.x1 - t.x0;
            for (i, p) in out.iter_mut().enumerate() {
                *p = skewed(t.x0 + i as u32 % w, t.y0 + i as u32 / w);
            }
        })
        .1;
        println!(
            "tile_queue/{name}: tiles per thread {:?}, busy ms {:?}, imbalance (max/mean busy) {:.2}",
            stats.tiles_per_thread,
            stats.busy_seconds.iter().map(|s| (s * 1e3).round()).collect::<Vec<_>>(),
            stats.imbalance()
        );
        g.bench_function(name, |b| {
            b.iter(|| {
                render_tiles(W as u32, H as u32, 32, 2, a, |t, out: &mut [f32]| {
                    let w = t.x1 - t.x0;
                    for (i, p) in out.iter_mut().enumerate() {
                        *p = skewed(t.x0 + i as u32 % w, t.y0 + i as u32 / w);
                    }
                })
                .1
                .wall_seconds
            })
        });
    }
    g.finish();
}

criterion_group!(benches, kernels, schedules, tile_queue);
criterion_main!(benches);
