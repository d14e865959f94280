//! The crate's main job until the renderer lands: runs every kernel on generated data, checks the
//! SIMD forms against the scalar references, and prints what was measured (single thread).
//! Writes `out/time_vs_error.svg` (time per test against false-miss rate).
//!
//! `cargo run --release --example kernels`

use plotters::prelude::*;
use std::hint::black_box;
use std::time::Instant;
use strahl::geometry::{Triangle, morton};
use strahl::intersect::{
    AabbX4, AabbX8, PreparedRay, TriangleX4, TriangleX8, intersect_aabb_scalar, intersect_aabb_x4, intersect_aabb_x8,
    moller, watertight,
};
use strahl::scene::{self, Aim, Rng};
use strahl::{Aabb, Vec3};

/// Median over `runs` runs of nanoseconds per element of `f`, which does `work` elements.
fn ns_per(work: usize, runs: usize, mut f: impl FnMut() -> u64) -> f64 {
    black_box(f());
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let s = Instant::now();
            black_box(f());
            s.elapsed().as_nanos() as f64 / work as f64
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[runs / 2]
}

fn row(name: &str, ns: &[f64]) {
    let cells: Vec<String> = ns.iter().map(|n| format!("{:>7.2} ns", n)).collect();
    println!(
        "| {name:<22} | {} | {:>5.1}x |",
        cells.join(" | "),
        ns[0] / ns[ns.len() - 1]
    );
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut rng = Rng::new(42);
    println!("strahl kernels on generated data, single thread, median of 9 runs");
    println!(
        "SIMD: f32x8 is {}",
        if cfg!(target_feature = "avx") {
            "one AVX register"
        } else {
            "two SSE halves"
        }
    );

    // Rays from a box around the scene towards random points in it.
    let rays: Vec<PreparedRay> = (0..4096)
        .map(|_| {
            let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), -3.0);
            let target = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            PreparedRay::new(&strahl::Ray::new(o, target - o))
        })
        .collect();

    println!("\n[1/3] ray/box slab test: 4096 rays x 8 boxes");
    let boxes: Vec<Aabb> = (0..8)
        .map(|_| {
            let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            Aabb::new(c - Vec3::splat(0.4), c + Vec3::splat(0.4))
        })
        .collect();
    let (b4, b8) = (
        [AabbX4::from_boxes(&boxes[..4]), AabbX4::from_boxes(&boxes[4..])],
        AabbX8::from_boxes(&boxes),
    );
    let work = rays.len() * 8;
    let s = ns_per(work, 9, || {
        rays.iter()
            .map(|r| boxes.iter().filter(|b| intersect_aabb_scalar(r, b).is_some()).count() as u64)
            .sum()
    });
    let x4 = ns_per(work, 9, || {
        rays.iter()
            .map(|r| {
                b4.iter()
                    .map(|b| intersect_aabb_x4(r, b).1.count_ones() as u64)
                    .sum::<u64>()
            })
            .sum()
    });
    let x8 = ns_per(work, 9, || {
        rays.iter()
            .map(|r| intersect_aabb_x8(r, &b8).1.count_ones() as u64)
            .sum()
    });
    let hits: usize = rays
        .iter()
        .map(|r| intersect_aabb_x8(r, &b8).1.count_ones() as usize)
        .sum();
    let agree = rays.iter().all(|r| {
        let m = intersect_aabb_x8(r, &b8).1;
        boxes
            .iter()
            .enumerate()
            .all(|(i, b)| intersect_aabb_scalar(r, b).is_some() == (m >> i & 1 == 1))
    });
    println!(
        "hit rate {:.0}%, x8 agrees with scalar: {agree}",
        100.0 * hits as f64 / work as f64
    );
    println!("| kernel                 |  scalar    |  x4        |  x8        | x8/scalar |");
    println!("|---|---|---|---|---|");
    row("slab test", &[s, x4, x8]);

    println!("\n[2/3] ray/triangle: 4096 rays x 8 triangles");
    let tris: Vec<Triangle> = (0..8)
        .map(|_| {
            let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            [0, 1, 2].map(|_| c + rng.unit_vector() * 0.8)
        })
        .collect();
    let prims: Vec<u32> = (0..8).collect();
    let t4 = [
        TriangleX4::pack(&tris[..4], &prims[..4]),
        TriangleX4::pack(&tris[4..], &prims[4..]),
    ];
    let t8 = TriangleX8::pack(&tris, &prims);
    println!("| kernel                 |  scalar    |  x4        |  x8        | x8/scalar |");
    println!("|---|---|---|---|---|");
    type Scalar = fn(&PreparedRay, &Triangle, u32) -> Option<strahl::Hit>;
    type X4 = fn(&PreparedRay, &TriangleX4) -> Option<strahl::Hit>;
    type X8 = fn(&PreparedRay, &TriangleX8) -> Option<strahl::Hit>;
    let kernels: [(&str, Scalar, X4, X8); 2] = [
        (
            "Möller-Trumbore",
            moller::intersect_scalar,
            moller::intersect_x4,
            moller::intersect_x8,
        ),
        (
            "watertight",
            watertight::intersect_scalar,
            watertight::intersect_x4,
            watertight::intersect_x8,
        ),
    ];
    let mut per_test = Vec::new();
    for (name, fs, f4, f8) in kernels {
        let s = ns_per(work, 9, || {
            rays.iter()
                .map(|r| tris.iter().filter(|t| fs(r, t, 0).is_some()).count() as u64)
                .sum()
        });
        let x4 = ns_per(work, 9, || {
            rays.iter()
                .map(|r| t4.iter().filter(|t| f4(r, t).is_some()).count() as u64)
                .sum()
        });
        let x8 = ns_per(work, 9, || rays.iter().filter(|r| f8(r, &t8).is_some()).count() as u64);
        row(name, &[s, x4, x8]);
        per_test.push((name, s, x8));
    }

    println!("\n[3/3] time against error: rays aimed exactly at edges and vertices of a closed icosphere");
    let mut m = scene::icosphere(3);
    for p in &mut m.positions {
        *p = *p * 3.7 + Vec3::new(0.31, -1.7, 2.1);
    }
    let mut aimed = scene::aimed_rays(&m, Aim::Edges, 4, 3.0, 1);
    aimed.extend(scene::aimed_rays(&m, Aim::Vertices, 8, 3.0, 2));
    let soup = m.to_soup();
    println!("| test | ns/test scalar | ns/test x8 | false misses | false-miss rate |");
    println!("|---|---|---|---|---|");
    let mut points = Vec::new();
    for (i, (name, fs, _, _)) in kernels.iter().enumerate() {
        let misses = aimed
            .iter()
            .filter(|r| {
                let r = PreparedRay::new(r);
                !soup.iter().any(|t| fs(&r, t, 0).is_some())
            })
            .count();
        let rate = misses as f64 / aimed.len() as f64;
        let (_, s, x8) = per_test[i];
        println!(
            "| {name} | {s:.2} | {x8:.2} | {misses} of {} | {:.3}% |",
            aimed.len(),
            100.0 * rate
        );
        points.push((*name, s, x8, rate));
    }

    let codes = 1 << 20;
    let pts: Vec<Vec3> = (0..codes).map(|_| Vec3::new(rng.f32(), rng.f32(), rng.f32())).collect();
    let q = morton::MortonQuantizer::new30(&Aabb::new(Vec3::ZERO, Vec3::ONE));
    let mut out = vec![0u32; codes];
    let ms = ns_per(codes, 9, || {
        pts.iter().map(|p| morton::morton30_scalar(*p, &q) as u64).sum()
    });
    let mx = ns_per(codes, 9, || {
        morton::morton30_slice(&pts, &q, &mut out);
        out[codes - 1] as u64
    });
    println!(
        "\nMorton 30-bit: scalar {:.0} M codes/s, x8 slice {:.0} M codes/s",
        1e3 / ms,
        1e3 / mx
    );

    std::fs::create_dir_all("out")?;
    let path = "out/time_vs_error.svg";
    plot(path, &points)?;
    println!("\nwrote {path}");
    Ok(())
}

/// Scatter of ns per test (x) against false-miss rate (y), one marker per test and width.
fn plot(path: &str, points: &[(&str, f64, f64, f64)]) -> Result<(), Box<dyn std::error::Error>> {
    let root = SVGBackend::new(path, (640, 400)).into_drawing_area();
    root.fill(&WHITE)?;
    let xmax = points.iter().map(|p| p.1).fold(0.0, f64::max) * 1.2;
    let ymax = points.iter().map(|p| p.3 * 100.0).fold(1.0, f64::max) * 1.2;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "ray/triangle: time per test against false misses on edge/vertex rays",
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..xmax, -0.5..ymax)?;
    chart
        .configure_mesh()
        .x_desc("ns per ray/triangle test (single thread)")
        .y_desc("false-miss rate (%)")
        .draw()?;
    let colors = [RED, BLUE];
    for (i, (name, s, x8, rate)) in points.iter().enumerate() {
        let c = colors[i % 2];
        for (w, x) in [("scalar", s), ("x8", x8)] {
            chart
                .draw_series(std::iter::once(Circle::new((*x, rate * 100.0), 5, c.filled())))?
                .label(format!("{name} {w}"))
                .legend(move |(x, y)| Circle::new((x, y), 4, c.filled()));
            chart.draw_series(std::iter::once(Text::new(
                format!("{name} {w}"),
                (*x, rate * 100.0 + ymax * 0.04),
                ("sans-serif", 12),
            )))?;
        }
    }
    root.present()?;
    Ok(())
}
