//! Volume ray marching benchmarks (single thread). Each comparison first checks the images:
//!
//! - `volume_x8_vs_scalar`: the scalar reference against the 8-wide marcher on a dense
//!   Marschner-Lobb volume (`128^3` u8, no empty space); bit-identical images asserted.
//! - `volume_skipping`: x8 with and without the macrocell grid on a torus volume that is about
//!   97% empty (`128^3` u8); bit-identical images asserted, empty fractions printed.
//! - `volume_termination`: x8 without termination, with exact termination (`Some(0)`) and with
//!   `Some(1/256)` on an opaque volume; the first two bit-identical, the third within
//!   `eps max|c|`.
//! - The run-time-against-error sweep: RMS error of the image against a reference marched at
//!   1/64 voxel, against nanoseconds per ray, for endpoint and midpoint sampling over steps of 2
//!   to 1/16 voxel. Printed as a table before the timings and plotted to
//!   `out/volume_time_vs_error.svg`.
//!
//! `cargo bench --bench volume -- --warm-up-time 1 --measurement-time 3`

#[path = "common/mod.rs"]
mod common;

use common::{quantise, ramp};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use plotters::prelude::*;
use std::hint::black_box;
use std::time::{Duration, Instant};
use strahl::volume::procedural::{marschner_lobb, pinhole_rays, torus, unit_volume};
use strahl::volume::*;
use strahl::{Ray, Vec3};

const N: u32 = 128;
const IMG: u32 = 96;

fn camera() -> Vec<Ray> {
    pinhole_rays(Vec3::new(2.2, -2.9, 1.6), Vec3::ZERO, 36.0, IMG, IMG)
}

fn march(f: impl Fn(&[Ray], &mut [Rgba]) -> MarchStats, rays: &[Ray]) -> (Vec<Rgba>, MarchStats) {
    let mut out = vec![Rgba::ZERO; rays.len()];
    let s = f(rays, &mut out);
    (out, s)
}

fn identical(a: &[Rgba], b: &[Rgba]) -> bool {
    a.iter().zip(b).all(|(x, y)| x.bit_eq(y))
}

fn group<'a>(
    c: &'a mut Criterion,
    name: &str,
    rays: usize,
) -> criterion::BenchmarkGroup<'a, criterion::measurement::WallTime> {
    let mut g = c.benchmark_group(name);
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .throughput(Throughput::Elements(rays as u64));
    g
}

/// The same Marschner-Lobb field as `u8`, `u16` and `f32` voxels, each transfer function over
/// the voxel type's range, scalar and x8 in one group (the ratio per voxel type from one run).
fn x8_vs_scalar(c: &mut Criterion) {
    let field = marschner_lobb(N);
    let d8 = quantise(&field);
    let d16: Vec<u16> = d8.iter().map(|&x| x as u16 * 257).collect();
    let d32: Vec<f32> = d8.iter().map(|&x| x as f32).collect();
    let table = ramp(0, 255, 1.5);
    let rays = camera();
    let mut g = group(c, "volume_x8_vs_scalar", rays.len());
    x8_vs_scalar_one(&mut g, "u8", unit_volume(&d8, N).unwrap(), 255.0, &table, &rays);
    x8_vs_scalar_one(&mut g, "u16", unit_volume(&d16, N).unwrap(), 65535.0, &table, &rays);
    x8_vs_scalar_one(&mut g, "f32", unit_volume(&d32, N).unwrap(), 255.0, &table, &rays);
    g.finish();
}

fn x8_vs_scalar_one<V: Voxel>(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    ty: &str,
    vol: Volume<'_, V>,
    hi: f32,
    table: &[TfEntry],
    rays: &[Ray],
) {
    let tf = TransferFunction::new(table, 0.0, hi).unwrap();
    let m = VolumeMedium::new(vol, tf);
    let p = MarchParams::reference(vol.spacing().x * 0.5);
    let (a, sa) = march(|r, o| integrate_scalar(&m, r, o, &p).unwrap(), rays);
    let (b, sb) = march(|r, o| integrate_x8(&m, r, o, &p).unwrap(), rays);
    assert!(identical(&a, &b), "x8 differs from scalar ({ty})");
    assert_eq!(sa, sb);
    println!(
        "x8 vs scalar ({ty}): {} rays, {:.0} samples per ray (dense Marschner-Lobb {N}^3, step 1/2 voxel), images identical",
        sa.rays,
        sa.samples as f64 / sa.rays as f64
    );
    let mut out = vec![Rgba::ZERO; rays.len()];
    g.bench_function(format!("{ty}/scalar"), |bch| {
        bch.iter(|| integrate_scalar(&m, black_box(rays), &mut out, &p).unwrap())
    });
    g.bench_function(format!("{ty}/x8"), |bch| {
        bch.iter(|| integrate_x8(&m, black_box(rays), &mut out, &p).unwrap())
    });
}

fn skipping(c: &mut Criterion) {
    let data = torus(N, 0.5, 0.15);
    let vol = unit_volume(&data, N).unwrap();
    let table = ramp(40, 255, 6.0);
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    grid.classify(&tf);
    let plain = VolumeMedium::new(vol, tf);
    let skip = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    let rays = camera();
    let p = MarchParams::reference(vol.spacing().x * 0.5);
    let (a, sa) = march(|r, o| integrate_x8(&plain, r, o, &p).unwrap(), &rays);
    let (b, sb) = march(|r, o| integrate_x8(&skip, r, o, &p).unwrap(), &rays);
    let (s, _) = march(|r, o| integrate_scalar(&skip, r, o, &p).unwrap(), &rays);
    assert!(identical(&a, &b) && identical(&a, &s), "skipping changed the image");
    let empty_voxels =
        data.iter().filter(|&&v| tf.is_transparent(v as f32, v as f32)).count() as f64 / data.len() as f64;
    assert!(empty_voxels >= 0.8);
    println!(
        "skipping: torus {N}^3, {:.1}% of voxels and {:.1}% of {}^3 macrocells transparent; samples {} -> {} ({} skipped), images identical",
        100.0 * empty_voxels,
        100.0 * grid.empty_fraction(),
        grid.block(),
        sa.samples,
        sb.samples,
        sb.skipped
    );
    let mut g = group(c, "volume_skipping", rays.len());
    let mut out = vec![Rgba::ZERO; rays.len()];
    g.bench_function("x8_no_grid", |bch| {
        bch.iter(|| integrate_x8(&plain, black_box(&rays), &mut out, &p).unwrap())
    });
    g.bench_function("x8_grid", |bch| {
        bch.iter(|| integrate_x8(&skip, black_box(&rays), &mut out, &p).unwrap())
    });
    g.bench_function("scalar_no_grid", |bch| {
        bch.iter(|| integrate_scalar(&plain, black_box(&rays), &mut out, &p).unwrap())
    });
    g.bench_function("scalar_grid", |bch| {
        bch.iter(|| integrate_scalar(&skip, black_box(&rays), &mut out, &p).unwrap())
    });
    g.finish();
}

fn termination(c: &mut Criterion) {
    let data = quantise(&marschner_lobb(N));
    let vol = unit_volume(&data, N).unwrap();
    let table = ramp(0, 255, 400.0); // opaque: a step of 1/2 voxel has opacity 0.5 .. 0.99
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    let m = VolumeMedium::new(vol, tf);
    let rays = camera();
    let step = vol.spacing().x * 0.5;
    let none = MarchParams::reference(step);
    let exact = MarchParams::quality(step);
    let fast = MarchParams::fast(step);
    let (a, sa) = march(|r, o| integrate_x8(&m, r, o, &none).unwrap(), &rays);
    let (b, sb) = march(|r, o| integrate_x8(&m, r, o, &exact).unwrap(), &rays);
    let (f, sf) = march(|r, o| integrate_x8(&m, r, o, &fast).unwrap(), &rays);
    assert!(identical(&a, &b), "exact termination changed the image");
    let eps = fast.termination.unwrap();
    let bound = eps * tf.max_color();
    let worst = a
        .iter()
        .zip(&f)
        .map(|(x, y)| (x.r - y.r).abs().max((x.g - y.g).abs()).max((x.b - y.b).abs()))
        .fold(0.0f32, f32::max);
    assert!(worst <= bound + 1e-6, "termination error {worst} above {bound}");
    println!(
        "termination: opaque Marschner-Lobb; samples {} (none) / {} (exact, {} rays stopped, image identical) / {} (eps 1/256, max error {worst:.2e} <= bound {bound:.2e})",
        sa.samples, sb.samples, sb.terminated, sf.samples
    );
    let mut g = group(c, "volume_termination", rays.len());
    let mut out = vec![Rgba::ZERO; rays.len()];
    for (name, p) in [("x8_none", none), ("x8_exact", exact), ("x8_eps_1_256", fast)] {
        g.bench_function(name, |bch| {
            bch.iter(|| integrate_x8(&m, black_box(&rays), &mut out, &p).unwrap())
        });
    }
    g.finish();
}

/// Median of `runs` timings of `f`, in nanoseconds per ray.
fn ns_per_ray(rays: usize, runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_nanos() as f64 / rays as f64
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[runs / 2]
}

fn rms(a: &[Rgba], b: &[Rgba]) -> f64 {
    let s: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| {
            [(x.r - y.r), (x.g - y.g), (x.b - y.b), (x.a - y.a)]
                .iter()
                .map(|d| (*d as f64).powi(2))
                .sum::<f64>()
        })
        .sum();
    (s / (4 * a.len()) as f64).sqrt()
}

fn sweep(_c: &mut Criterion) {
    let n = 64;
    let data = marschner_lobb(n);
    let vol = unit_volume(&data, n).unwrap();
    let table: Vec<TfEntry> = ramp(0, 255, 3.0);
    let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    let m = VolumeMedium::new(vol, tf);
    let rays = pinhole_rays(Vec3::new(2.2, -2.9, 1.6), Vec3::ZERO, 36.0, 64, 64);
    let voxel = vol.spacing().x;
    let mut reference = vec![Rgba::ZERO; rays.len()];
    integrate_x8(&m, &rays, &mut reference, &MarchParams::reference(voxel / 64.0)).unwrap();
    println!(
        "\nstep-size sweep: Marschner-Lobb {n}^3 f32, {} rays, x8, error against 1/64-voxel midpoint reference",
        rays.len()
    );
    println!("| sampling | step (voxels) | samples/ray | ns/ray | RMS error |");
    println!("|---|---|---|---|---|");
    let mut pts: Vec<(Sampling, f64, f64, f64)> = vec![];
    for sampling in [Sampling::Endpoint, Sampling::Midpoint] {
        for k in -1..=4 {
            let frac = 0.5f32.powi(k);
            let p = MarchParams {
                sampling,
                ..MarchParams::reference(voxel * frac)
            };
            let mut out = vec![Rgba::ZERO; rays.len()];
            let st = integrate_x8(&m, &rays, &mut out, &p).unwrap();
            let ns = ns_per_ray(rays.len(), 5, || {
                integrate_x8(&m, &rays, &mut out, &p).unwrap();
            });
            let e = rms(&out, &reference);
            println!(
                "| {sampling:?} | {frac} | {:.0} | {ns:.0} | {e:.3e} |",
                st.samples as f64 / st.rays as f64
            );
            pts.push((sampling, frac as f64, ns, e));
        }
        // Observed order from the three finest steps.
        let s: Vec<_> = pts.iter().filter(|p| p.0 == sampling).rev().take(3).collect();
        let order = (s[2].3 / s[0].3).ln() / (s[2].1 / s[0].1).ln();
        println!("| {sampling:?} | observed order (finest 3 steps) | | | {order:.2} |");
    }
    std::fs::create_dir_all("out").ok();
    let path = "out/volume_time_vs_error.svg";
    match plot(path, &pts) {
        Ok(()) => println!("wrote {path}\n"),
        Err(e) => println!("could not write {path}: {e}\n"),
    }
}

/// Log-log plot: ns per ray (x) against RMS error (y), one line per sampling rule.
fn plot(path: &str, pts: &[(Sampling, f64, f64, f64)]) -> Result<(), Box<dyn std::error::Error>> {
    let root = SVGBackend::new(path, (720, 460)).into_drawing_area();
    root.fill(&WHITE)?;
    let (x0, x1) = pts
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), p| (a.min(p.2), b.max(p.2)));
    let (y0, y1) = pts
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), p| (a.min(p.3), b.max(p.3)));
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "volume marching: time per ray against RMS error (Marschner-Lobb 64^3)",
            ("sans-serif", 16),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d((x0 * 0.7..x1 * 1.4).log_scale(), (y0 * 0.5..y1 * 2.0).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("ns per ray (x8, single thread)")
        .y_desc("RMS error of premultiplied RGBA")
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()?;
    for (sampling, color) in [(Sampling::Endpoint, RED), (Sampling::Midpoint, BLUE)] {
        let s: Vec<(f64, f64)> = pts.iter().filter(|p| p.0 == sampling).map(|p| (p.2, p.3)).collect();
        chart
            .draw_series(LineSeries::new(s.clone(), color.stroke_width(2)))?
            .label(format!("{sampling:?}"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2)));
        chart.draw_series(s.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        for p in pts.iter().filter(|p| p.0 == sampling) {
            chart.draw_series(std::iter::once(Text::new(
                format!("{} vox", p.1),
                (p.2 * 1.04, p.3 * 1.15),
                ("sans-serif", 11),
            )))?;
        }
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE)
        .draw()?;
    root.present()?;
    Ok(())
}

criterion_group!(benches, sweep, x8_vs_scalar, skipping, termination);
criterion_main!(benches);
