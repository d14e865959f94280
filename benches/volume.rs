//! Volume ray marching benchmarks (single thread). Each comparison first checks the images:
//!
//! - `volume_x8_vs_scalar`: the scalar reference against the 8-wide marcher on a dense
//!   Marschner-Lobb volume (`128^3` as u8, u16 and f32, no empty space), Riemann and pre-integrated
//!   (table of `256^2`); bit-identical images asserted.
//! - `volume_preintegration_build`: building pre-integrated tables of `64^2` to `256^2` from a
//!   256-entry transfer function (a smooth ramp and two thin bands).
//! - `volume_skipping`: x8 (and scalar) with and without the macrocell grid on a torus volume that
//!   is about 97% empty (`128^3` u8), Riemann and pre-integrated; bit-identical images asserted,
//!   empty fractions printed.
//! - `volume_termination`: x8 without termination, with exact termination (`Some(0)`) and with
//!   `Some(1/256)` on an opaque volume; the first two bit-identical, the third within
//!   `eps max|c|`.
//! - The run-time-against-error sweeps, for a smooth ramp and for two thin bands as transfer
//!   function: RMS error of the image against a reference marched at 1/256 voxel (midpoint),
//!   against nanoseconds per ray, for endpoint, midpoint and pre-integrated marching over steps of
//!   2 to 1/16 voxel. Printed as tables before the timings and plotted to
//!   `out/volume_time_vs_error.svg` (ramp) and `out/volume_time_vs_error_band.svg` (bands).
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
    // Pre-integrated at the same step (table of 256^2, built outside the timing).
    let pre = PreintegratedTable::build(&tf, p.step, 256).unwrap();
    let pm = PreintegratedMedium::new(vol, pre.view());
    let (c, sc) = march(|r, o| integrate_preintegrated_scalar(&pm, r, o, &p).unwrap(), rays);
    let (d, sd) = march(|r, o| integrate_preintegrated_x8(&pm, r, o, &p).unwrap(), rays);
    assert!(identical(&c, &d), "pre-integrated x8 differs from scalar ({ty})");
    assert_eq!(sc, sd);
    g.bench_function(format!("{ty}/preintegrated_scalar"), |bch| {
        bch.iter(|| integrate_preintegrated_scalar(&pm, black_box(rays), &mut out, &p).unwrap())
    });
    g.bench_function(format!("{ty}/preintegrated_x8"), |bch| {
        bch.iter(|| integrate_preintegrated_x8(&pm, black_box(rays), &mut out, &p).unwrap())
    });
}

/// Building pre-integrated tables from a 256-entry transfer function, at three resolutions.
fn preintegration_build(c: &mut Criterion) {
    let mut g = c.benchmark_group("volume_preintegration_build");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    for (name, table) in [("ramp", ramp(0, 255, 3.0)), ("band", band())] {
        let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
        for res in [64u32, 128, 256] {
            g.throughput(Throughput::Elements(res as u64 * res as u64));
            g.bench_function(format!("{name}/{res}"), |bch| {
                bch.iter(|| PreintegratedTable::build(&tf, black_box(1.0 / 63.0), res).unwrap())
            });
        }
    }
    g.finish();
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
    // Pre-integrated, with a grid classified for its table.
    let pre = PreintegratedTable::build(&tf, p.step, 256).unwrap();
    let mut pgrid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    pgrid.classify_preintegrated(&pre);
    let pplain = PreintegratedMedium::new(vol, pre.view());
    let pskip = pplain.with_grid(&pgrid).unwrap();
    let (c, sc) = march(|r, o| integrate_preintegrated_x8(&pplain, r, o, &p).unwrap(), &rays);
    let (d, sd) = march(|r, o| integrate_preintegrated_x8(&pskip, r, o, &p).unwrap(), &rays);
    assert!(identical(&c, &d), "skipping changed the pre-integrated image");
    println!(
        "skipping, pre-integrated: {:.1}% of macrocells transparent; steps {} -> {} ({} skipped), images identical",
        100.0 * pgrid.empty_fraction(),
        sc.samples,
        sd.samples,
        sd.skipped
    );
    g.bench_function("preintegrated_x8_no_grid", |bch| {
        bch.iter(|| integrate_preintegrated_x8(&pplain, black_box(&rays), &mut out, &p).unwrap())
    });
    g.bench_function("preintegrated_x8_grid", |bch| {
        bch.iter(|| integrate_preintegrated_x8(&pskip, black_box(&rays), &mut out, &p).unwrap())
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

/// 256 entries over `[0, 1]`: clear but for two thin bands, as iso-surfaces are drawn: 3 entries
/// (1% of the range) around 0.55, orange and dense, and 2 around 0.31, blue and lighter.
fn band() -> Vec<TfEntry> {
    (0..256)
        .map(|i| match i {
            139..=141 => TfEntry::new([1.0, 0.55, 0.1], if i == 140 { 80.0 } else { 40.0 }),
            79..=80 => TfEntry::new([0.2, 0.4, 1.0], 25.0),
            _ => TfEntry::TRANSPARENT,
        })
        .collect()
}

/// How a sweep point was marched.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Method {
    Endpoint,
    Midpoint,
    /// Pre-integrated, table of 256^2.
    Preintegrated,
}

fn sweep(_c: &mut Criterion) {
    for (name, table, path) in [
        ("ramp", ramp(0, 255, 3.0), "out/volume_time_vs_error.svg"),
        ("band", band(), "out/volume_time_vs_error_band.svg"),
    ] {
        sweep_one(name, &table, path);
    }
}

/// The step-size sweep over one transfer function: a table (printed) and a plot.
fn sweep_one(name: &str, table: &[TfEntry], path: &str) {
    let n = 64;
    let data = marschner_lobb(n);
    let vol = unit_volume(&data, n).unwrap();
    let tf = TransferFunction::new(table, 0.0, 1.0).unwrap();
    let m = VolumeMedium::new(vol, tf);
    let rays = pinhole_rays(Vec3::new(2.2, -2.9, 1.6), Vec3::ZERO, 36.0, 64, 64);
    let voxel = vol.spacing().x;
    let mut reference = vec![Rgba::ZERO; rays.len()];
    integrate_x8(
        &m,
        &rays,
        &mut reference,
        &MarchParams {
            max_steps: MAX_STEPS_LIMIT,
            ..MarchParams::reference(voxel / 256.0)
        },
    )
    .unwrap();
    println!(
        "\nstep-size sweep ({name} transfer function): Marschner-Lobb {n}^3 f32, {} rays, x8, error against a 1/256-voxel midpoint reference",
        rays.len()
    );
    println!("| method | step (voxels) | samples/ray | ns/ray | RMS error |");
    println!("|---|---|---|---|---|");
    let mut pts: Vec<(Method, f64, f64, f64)> = vec![];
    for method in [Method::Endpoint, Method::Midpoint, Method::Preintegrated] {
        for k in -1..=4 {
            let frac = 0.5f32.powi(k);
            let sampling = if method == Method::Endpoint {
                Sampling::Endpoint
            } else {
                Sampling::Midpoint
            };
            let p = MarchParams {
                sampling,
                ..MarchParams::reference(voxel * frac)
            };
            let mut out = vec![Rgba::ZERO; rays.len()];
            let (st, ns, build) = if method == Method::Preintegrated {
                let t = Instant::now();
                let pre = PreintegratedTable::build(&tf, p.step, 256).unwrap();
                let build = t.elapsed().as_secs_f64() * 1e3;
                let pm = PreintegratedMedium::new(vol, pre.view());
                let st = integrate_preintegrated_x8(&pm, &rays, &mut out, &p).unwrap();
                let ns = ns_per_ray(rays.len(), 5, || {
                    integrate_preintegrated_x8(&pm, &rays, &mut out, &p).unwrap();
                });
                (st, ns, Some(build))
            } else {
                let st = integrate_x8(&m, &rays, &mut out, &p).unwrap();
                let ns = ns_per_ray(rays.len(), 5, || {
                    integrate_x8(&m, &rays, &mut out, &p).unwrap();
                });
                (st, ns, None)
            };
            let e = rms(&out, &reference);
            let note = build.map_or(String::new(), |ms| format!(" (table {ms:.0} ms)"));
            println!(
                "| {method:?}{note} | {frac} | {:.0} | {ns:.0} | {e:.3e} |",
                st.samples as f64 / st.rays as f64
            );
            pts.push((method, frac as f64, ns, e));
        }
        // Observed order from the three finest steps.
        let s: Vec<_> = pts.iter().filter(|p| p.0 == method).rev().take(3).collect();
        let order = (s[2].3 / s[0].3).ln() / (s[2].1 / s[0].1).ln();
        println!("| {method:?} | observed order (finest 3 steps) | | | {order:.2} |");
    }
    std::fs::create_dir_all("out").ok();
    match plot(path, name, &pts) {
        Ok(()) => println!("wrote {path}\n"),
        Err(e) => println!("could not write {path}: {e}\n"),
    }
}

/// Log-log plot: ns per ray (x) against RMS error (y), one line per method.
fn plot(path: &str, name: &str, pts: &[(Method, f64, f64, f64)]) -> Result<(), Box<dyn std::error::Error>> {
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
            format!("volume marching: time per ray against RMS error (Marschner-Lobb 64^3, {name} TF)"),
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
    for (method, color) in [
        (Method::Endpoint, RED),
        (Method::Midpoint, BLUE),
        (Method::Preintegrated, GREEN),
    ] {
        let s: Vec<(f64, f64)> = pts.iter().filter(|p| p.0 == method).map(|p| (p.2, p.3)).collect();
        chart
            .draw_series(LineSeries::new(s.clone(), color.stroke_width(2)))?
            .label(format!("{method:?}"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2)));
        chart.draw_series(s.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        for p in pts.iter().filter(|p| p.0 == method) {
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

criterion_group!(
    benches,
    sweep,
    x8_vs_scalar,
    preintegration_build,
    skipping,
    termination
);
criterion_main!(benches);
