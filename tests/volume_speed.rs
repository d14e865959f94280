//! Speed harness for the volume marchers (ignored: run by hand).
//!
//! `cargo test --release --test volume_speed -- --ignored --nocapture speed`: the scenes of
//! `benches/volume.rs` (dense Marschner-Lobb 128^3 as `u8`, `u16` and `f32` voxels, Riemann and
//! pre-integrated; the sparse torus with and without its macrocell grid), 96x96 rays, step 1/2
//! voxel. Each contender runs
//! `STRAHL_REPS` times (default 5) and keeps its best, taking turns with the others, for
//! `STRAHL_ROUNDS` rounds (default 3); the table shows each contender's best over all rounds and
//! the ratios of those. On a shared machine whose load changes from second to second, taking
//! turns gives steadier ratios than criterion's one contender after the other. Every contender's
//! image is checked against the scalar reference's first.

#[path = "../benches/common/mod.rs"]
mod common;

use common::ramp;
use std::time::Instant;
use strahl::volume::procedural::{marschner_lobb, pinhole_rays, torus, unit_volume};
use strahl::volume::*;
use strahl::{Ray, Vec3};

const N: u32 = 128;

type Run<'a> = Box<dyn Fn(&[Ray], &mut [Rgba]) -> MarchStats + 'a>;

fn pair<'a, M: Medium>(m: &'a M, p: &'a MarchParams) -> (Run<'a>, Run<'a>) {
    (
        Box::new(move |r, o| integrate_scalar(m, r, o, p).unwrap()),
        Box::new(move |r, o| integrate_x8(m, r, o, p).unwrap()),
    )
}

fn pre_pair<'a, V: Voxel>(m: &'a PreintegratedMedium<'a, V>, p: &'a MarchParams) -> (Run<'a>, Run<'a>) {
    (
        Box::new(move |r, o| integrate_preintegrated_scalar(m, r, o, p).unwrap()),
        Box::new(move |r, o| integrate_preintegrated_x8(m, r, o, p).unwrap()),
    )
}

#[test]
#[ignore]
fn speed() {
    let env = |k: &str, d: usize| std::env::var(k).ok().and_then(|s| s.parse().ok()).unwrap_or(d).max(1);
    let (reps, rounds) = (env("STRAHL_REPS", 5), env("STRAHL_ROUNDS", 3));
    let field = marschner_lobb(N);
    let d8: Vec<u8> = field
        .iter()
        .map(|x| (x * 255.0).round().clamp(0.0, 255.0) as u8)
        .collect();
    let d16: Vec<u16> = d8.iter().map(|&x| x as u16 * 257).collect();
    let d32: Vec<f32> = d8.iter().map(|&x| x as f32).collect();
    let table = ramp(0, 255, 1.5);
    let tf = |hi: f32| TransferFunction::new(&table, 0.0, hi).unwrap();
    let m8 = VolumeMedium::new(unit_volume(&d8, N).unwrap(), tf(255.0));
    let m16 = VolumeMedium::new(unit_volume(&d16, N).unwrap(), tf(65535.0));
    let m32 = VolumeMedium::new(unit_volume(&d32, N).unwrap(), tf(255.0));
    let tdata = torus(N, 0.5, 0.15);
    let tvol = unit_volume(&tdata, N).unwrap();
    let ttable = ramp(40, 255, 6.0);
    let ttf = TransferFunction::new(&ttable, 0.0, 255.0).unwrap();
    let mut grid = MacrocellGrid::build(&tvol, GridParams::default()).unwrap();
    grid.classify(&ttf);
    let plain = VolumeMedium::new(tvol, ttf);
    let skip = VolumeMedium::new(tvol, ttf).with_grid(&grid).unwrap();
    let p = MarchParams::reference(m8.volume().spacing().x * 0.5);
    let rays = pinhole_rays(Vec3::new(2.2, -2.9, 1.6), Vec3::ZERO, 36.0, 96, 96);
    // Pre-integrated, tables of 256^2 at the same step (the u8 one also serves the f32 volume,
    // whose values span the same range).
    let (pre8, pre16) = (
        PreintegratedTable::build(&tf(255.0), p.step, 256).unwrap(),
        PreintegratedTable::build(&tf(65535.0), p.step, 256).unwrap(),
    );
    let pm8 = PreintegratedMedium::new(*m8.volume(), pre8.view());
    let pm16 = PreintegratedMedium::new(*m16.volume(), pre16.view());
    let pm32 = PreintegratedMedium::new(*m32.volume(), pre8.view());

    // Rows of (name, contenders); the first contender of a row is its reference.
    let (s8, x8) = pair(&m8, &p);
    let (s16, x16) = pair(&m16, &p);
    let (s32, x32) = pair(&m32, &p);
    let (s_plain, x_plain) = pair(&plain, &p);
    let (s_skip, x_skip) = pair(&skip, &p);
    let (ps8, px8) = pre_pair(&pm8, &p);
    let (ps16, px16) = pre_pair(&pm16, &p);
    let (ps32, px32) = pre_pair(&pm32, &p);
    let rows: Vec<(&str, Vec<(&str, Run)>)> = vec![
        ("dense u8", vec![("scalar", s8), ("x8", x8)]),
        ("dense u16", vec![("scalar", s16), ("x8", x16)]),
        ("dense f32", vec![("scalar", s32), ("x8", x32)]),
        ("dense u8, pre-integrated", vec![("scalar", ps8), ("x8", px8)]),
        ("dense u16, pre-integrated", vec![("scalar", ps16), ("x8", px16)]),
        ("dense f32, pre-integrated", vec![("scalar", ps32), ("x8", px32)]),
        (
            "sparse torus u8",
            vec![
                ("scalar", s_plain),
                ("x8", x_plain),
                ("scalar+grid", s_skip),
                ("x8+grid", x_skip),
            ],
        ),
    ];
    let mut out = vec![Rgba::ZERO; rays.len()];
    let mut want = vec![Rgba::ZERO; rays.len()];
    for (name, runs) in &rows {
        let stats = runs[0].1(&rays, &mut want);
        for (what, run) in &runs[1..] {
            run(&rays, &mut out);
            assert!(
                want.iter().zip(&out).all(|(a, b)| a.bit_eq(b)),
                "{name}: {what} differs from the scalar image"
            );
        }
        println!(
            "{name}: {} rays, {:.0} samples per ray; every image equals the scalar reference's",
            stats.rays,
            stats.samples as f64 / stats.rays as f64
        );
    }
    let mut best: Vec<Vec<f64>> = rows.iter().map(|(_, r)| vec![f64::MAX; r.len()]).collect();
    for round in 0..rounds {
        for ((_, runs), best) in rows.iter().zip(&mut best) {
            for ((_, run), b) in runs.iter().zip(best.iter_mut()) {
                for _ in 0..reps {
                    let t = Instant::now();
                    run(&rays, &mut out);
                    *b = b.min(t.elapsed().as_secs_f64() * 1e3);
                }
            }
        }
        eprintln!("round {}/{rounds} done", round + 1);
    }
    println!("| scene | contender | best ms | scalar / contender |");
    println!("|---|---|---:|---:|");
    for ((name, runs), best) in rows.iter().zip(&best) {
        for ((what, _), b) in runs.iter().zip(best) {
            println!("| {name} | {what} | {b:.2} | {:.2}x |", best[0] / b);
        }
    }
    let t = &best[6];
    println!(
        "empty-space skipping on the sparse torus: scalar {:.2}x, x8 {:.2}x faster with the grid",
        t[0] / t[2],
        t[1] / t[3]
    );
}
