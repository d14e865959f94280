//! Renders volumes to PNG with emission-absorption ray marching (single thread) and prints what was
//! measured: time, Mrays/s, samples, the x8/scalar ratio and the empty-space skipping speedup.
//!
//! Scenes: the Marschner-Lobb test signal (`f32`), a CT-like Shepp-Logan head phantom (`u16`), a
//! sparse torus (`u8`), and optionally a raw volume of your own:
//!
//! ```text
//! cargo run --release --example volume
//! cargo run --release --example volume -- --raw head.raw 256 256 113 u8 [--spacing 1 1 2] [--size 512]
//! ```
//!
//! A `.raw` file is `nx ny nz` voxels, x fastest, in the machine's byte order (`u8`, `u16` or
//! `f32`). Images go to `out/volume_*.png`. Last, thin iso-bands at a step of one voxel: the
//! midpoint rule, pre-integration and a fine reference side by side (`out/volume_preintegrated.png`).

use std::error::Error;
use std::fs::File;
use std::io::BufWriter;
use std::time::Instant;
use strahl::volume::procedural::{ct_phantom, marschner_lobb, pinhole_rays, torus, unit_volume};
use strahl::volume::*;
use strahl::{Ray, Vec3};

/// A transfer function from control points `(value in [0, 1], colour, opacity at a 1-voxel step)`,
/// linearly interpolated into `n` entries.
fn table(points: &[(f32, [f32; 3], f32)], n: usize, voxel: f32) -> Vec<TfEntry> {
    (0..n)
        .map(|i| {
            let x = i as f32 / (n - 1) as f32;
            let k = points.iter().rposition(|p| p.0 <= x).unwrap_or(0).min(points.len() - 2);
            let (a, b) = (points[k], points[k + 1]);
            let t = ((x - a.0) / (b.0 - a.0)).clamp(0.0, 1.0);
            let c = [0, 1, 2].map(|j| a.1[j] + (b.1[j] - a.1[j]) * t);
            let alpha = a.2 + (b.2 - a.2) * t;
            TfEntry::from_rgba_straight([c[0], c[1], c[2], alpha], voxel)
        })
        .collect()
}

fn write_png(path: &str, w: u32, h: u32, px: &[Rgba], bg: [f32; 3]) -> Result<(), Box<dyn Error>> {
    let mut bytes = Vec::with_capacity(px.len() * 3);
    for p in px {
        for c in p.over(bg) {
            bytes.push((c.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8);
        }
    }
    let mut enc = png::Encoder::new(BufWriter::new(File::create(path)?), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()?.write_image_data(&bytes)?;
    Ok(())
}

/// Seconds of the fastest of `runs` calls.
fn best(runs: usize, mut f: impl FnMut() -> MarchStats) -> (f64, MarchStats) {
    let mut t = f64::MAX;
    let mut s = MarchStats::default();
    for _ in 0..runs {
        let start = Instant::now();
        s = f();
        t = t.min(start.elapsed().as_secs_f64());
    }
    (t, s)
}

struct Scene<'a, V: Voxel> {
    name: &'a str,
    vol: Volume<'a, V>,
    table: Vec<TfEntry>,
    range: (f32, f32),
    eye: Vec3,
}

fn render<V: Voxel>(s: &Scene<'_, V>, size: u32) -> Result<(), Box<dyn Error>> {
    let tf = TransferFunction::new(&s.table, s.range.0, s.range.1)?;
    let b = s.vol.bounds();
    let centre = b.centroid();
    let extent = b.extent().length();
    let rays: Vec<Ray> = pinhole_rays(centre + s.eye * extent, centre, 30.0, size, size);
    let voxel = s.vol.spacing().min_element();
    let params = MarchParams::fast(voxel * 0.5);

    let t0 = Instant::now();
    let mut grid = MacrocellGrid::build(&s.vol, GridParams::default())?;
    grid.classify(&tf);
    let t_grid = t0.elapsed().as_secs_f64();

    let plain = VolumeMedium::new(s.vol, tf);
    let skip = VolumeMedium::new(s.vol, tf).with_grid(&grid)?;
    let mut img = vec![Rgba::ZERO; rays.len()];
    let mut other = vec![Rgba::ZERO; rays.len()];
    let runs = 3;
    let (t_scalar, st) = best(runs, || integrate_scalar(&plain, &rays, &mut other, &params).unwrap());
    let (t_x8, _) = best(runs, || integrate_x8(&plain, &rays, &mut img, &params).unwrap());
    let same_width = img.iter().zip(&other).all(|(a, b)| a.bit_eq(b));
    let (t_skip, sk) = best(runs, || integrate_x8(&skip, &rays, &mut other, &params).unwrap());
    let same_skip = img.iter().zip(&other).all(|(a, b)| a.bit_eq(b));
    assert!(same_width && same_skip, "images differ");

    let mrays = |t: f64| rays.len() as f64 / t / 1e6;
    let d = s.vol.dims();
    println!(
        "{:<14} {}x{}x{} {:>4}  grid {:>5.1} ms ({:>4.1}% empty)  scalar {:>7.1} ms {:>5.2} Mrays/s  x8 {:>6.1} ms {:>5.2} Mrays/s ({:.1}x)  x8+skip {:>6.1} ms {:>5.2} Mrays/s ({:.1}x over x8)  samples/ray {:.0} -> {:.0}",
        s.name,
        d[0],
        d[1],
        d[2],
        core::any::type_name::<V>(),
        t_grid * 1e3,
        100.0 * grid.empty_fraction(),
        t_scalar * 1e3,
        mrays(t_scalar),
        t_x8 * 1e3,
        mrays(t_x8),
        t_scalar / t_x8,
        t_skip * 1e3,
        mrays(t_skip),
        t_x8 / t_skip,
        st.samples as f64 / st.rays.max(1) as f64,
        sk.samples as f64 / sk.rays.max(1) as f64,
    );
    let path = format!("out/volume_{}.png", s.name);
    write_png(&path, size, size, &img, [0.02, 0.02, 0.05])?;
    println!("{:<14} wrote {path}", "");
    Ok(())
}

fn raw_scene(args: &[String], size: u32) -> Result<(), Box<dyn Error>> {
    let usage = "--raw PATH NX NY NZ u8|u16|f32 [--spacing SX SY SZ]";
    let get = |i: usize| args.get(i).ok_or_else(|| format!("usage: {usage}"));
    let path = get(0)?;
    let dims = [get(1)?.parse::<u32>()?, get(2)?.parse()?, get(3)?.parse()?];
    let ty = get(4)?.as_str();
    let mut spacing = Vec3::ONE;
    if let Some(i) = args.iter().position(|a| a == "--spacing") {
        spacing = Vec3::new(get(i + 1)?.parse()?, get(i + 2)?.parse()?, get(i + 3)?.parse()?);
    }
    let bytes = std::fs::read(path)?;
    // Copy into 4-aligned storage so any voxel type can be viewed zero-copy.
    let mut words = vec![0u32; bytes.len().div_ceil(4)];
    bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(&bytes);
    let aligned = &bytemuck::cast_slice::<u32, u8>(&words)[..bytes.len()];
    let name = "raw";
    let eye = Vec3::new(0.4, -0.8, 0.35);
    let ramp = |lo: f32, hi: f32| (lo, hi);
    match ty {
        "u8" => {
            let vol = Volume::<u8>::from_bytes(aligned, dims, spacing, Vec3::ZERO)?;
            let (lo, hi) = vol.data().iter().fold((255u8, 0u8), |(a, b), &v| (a.min(v), b.max(v)));
            render(&raw_tf(name, vol, ramp(lo as f32, hi.max(lo + 1) as f32), eye), size)
        }
        "u16" => {
            let vol = Volume::<u16>::from_bytes(aligned, dims, spacing, Vec3::ZERO)?;
            let (lo, hi) = vol
                .data()
                .iter()
                .fold((u16::MAX, 0u16), |(a, b), &v| (a.min(v), b.max(v)));
            render(&raw_tf(name, vol, ramp(lo as f32, hi.max(lo + 1) as f32), eye), size)
        }
        "f32" => {
            let vol = Volume::<f32>::from_bytes(aligned, dims, spacing, Vec3::ZERO)?;
            let (lo, hi) = vol
                .data()
                .iter()
                .filter(|v| v.is_finite())
                .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            let hi = if hi > lo { hi } else { lo + 1.0 };
            render(&raw_tf(name, vol, ramp(lo, hi), eye), size)
        }
        _ => Err(format!("voxel type must be u8, u16 or f32; usage: {usage}").into()),
    }
}

fn raw_tf<'a, V: Voxel>(name: &'a str, vol: Volume<'a, V>, range: (f32, f32), eye: Vec3) -> Scene<'a, V> {
    let voxel = vol.spacing().min_element();
    Scene {
        name,
        vol,
        table: table(
            &[
                (0.0, [0.0; 3], 0.0),
                (0.2, [0.8, 0.4, 0.2], 0.0),
                (0.5, [0.9, 0.7, 0.5], 0.08),
                (1.0, [1.0, 1.0, 1.0], 0.5),
            ],
            256,
            voxel,
        ),
        range,
        eye,
    }
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let size = args
        .iter()
        .position(|a| a == "--size")
        .and_then(|i| args.get(i + 1)?.parse().ok())
        .unwrap_or(384u32);
    std::fs::create_dir_all("out")?;
    println!(
        "strahl volume rendering, {size}x{size} rays, step 1/2 voxel, midpoint, termination 1/256, single thread; f32x8 is {}",
        if cfg!(target_feature = "avx") {
            "one AVX register"
        } else {
            "two SSE halves"
        }
    );
    if let Some(i) = args.iter().position(|a| a == "--raw") {
        return raw_scene(&args[i + 1..], size);
    }

    let n = 128;
    let ml = marschner_lobb(n);
    let voxel = 2.0 / (n - 1) as f32;
    render(
        &Scene {
            name: "marschner_lobb",
            vol: unit_volume(&ml, n)?,
            table: table(
                &[
                    (0.0, [0.0; 3], 0.0),
                    (0.35, [0.1, 0.2, 0.8], 0.0),
                    (0.5, [0.2, 0.8, 0.9], 0.25),
                    (0.65, [1.0, 0.8, 0.3], 0.05),
                    (1.0, [1.0, 0.3, 0.1], 0.6),
                ],
                256,
                voxel,
            ),
            range: (0.0, 1.0),
            eye: Vec3::new(0.5, -0.75, 0.45),
        },
        size,
    )?;

    let n = 160;
    let ct = ct_phantom(n);
    let voxel = 2.0 / (n - 1) as f32;
    render(
        &Scene {
            name: "ct_phantom",
            vol: unit_volume(&ct, n)?,
            table: table(
                &[
                    (0.0, [0.0; 3], 0.0),
                    (0.1, [0.0; 3], 0.0),
                    (0.17, [0.9, 0.5, 0.4], 0.01),
                    (0.22, [0.9, 0.5, 0.4], 0.01),
                    (0.25, [1.0, 0.2, 0.1], 0.4),
                    (0.3, [1.0, 0.2, 0.1], 0.4),
                    (0.5, [0.0; 3], 0.0),
                    (0.8, [0.0; 3], 0.0),
                    (0.83, [0.95, 0.95, 0.9], 0.08),
                    (1.0, [1.0; 3], 0.08),
                ],
                256,
                voxel,
            ),
            range: (0.0, 1200.0),
            eye: Vec3::new(0.7, -0.5, 0.5),
        },
        size,
    )?;

    let n = 160;
    let tor = torus(n, 0.5, 0.15);
    let voxel = 2.0 / (n - 1) as f32;
    render(
        &Scene {
            name: "torus_sparse",
            vol: unit_volume(&tor, n)?,
            table: table(
                &[
                    (0.0, [0.0; 3], 0.0),
                    (0.15, [0.0; 3], 0.0),
                    (0.2, [0.2, 0.4, 1.0], 0.05),
                    (0.7, [1.0, 0.6, 0.2], 0.3),
                    (1.0, [1.0, 1.0, 0.8], 0.9),
                ],
                256,
                voxel,
            ),
            range: (0.0, 255.0),
            eye: Vec3::new(0.3, -0.8, 0.6),
        },
        size,
    )?;
    preintegration(size.min(256))
}

/// Thin iso-bands at a coarse step: the midpoint rule against pre-integration, beside a reference
/// at 1/16 voxel, written side by side to `out/volume_preintegrated.png` (left to right: midpoint,
/// pre-integrated, reference).
fn preintegration(size: u32) -> Result<(), Box<dyn Error>> {
    let n = 128;
    let ml = marschner_lobb(n);
    let vol = unit_volume(&ml, n)?;
    // Two bands about 1% of the value range wide, clear elsewhere.
    let bands: Vec<TfEntry> = (0..256)
        .map(|i| match i {
            139..=141 => TfEntry::new([1.0, 0.55, 0.1], if i == 140 { 160.0 } else { 80.0 }),
            79..=80 => TfEntry::new([0.2, 0.4, 1.0], 50.0),
            _ => TfEntry::TRANSPARENT,
        })
        .collect();
    let tf = TransferFunction::new(&bands, 0.0, 1.0)?;
    let rays = pinhole_rays(Vec3::new(1.1, -1.6, 1.0), Vec3::ZERO, 34.0, size, size);
    let voxel = vol.spacing().x;
    let step = voxel;
    let p = MarchParams::reference(step);
    let m = VolumeMedium::new(vol, tf);
    let t0 = Instant::now();
    let table = PreintegratedTable::build(&tf, step, 256)?;
    let t_table = t0.elapsed().as_secs_f64();
    let pm = PreintegratedMedium::new(vol, table.view());
    let (mut mid, mut pre, mut reference) = (
        vec![Rgba::ZERO; rays.len()],
        vec![Rgba::ZERO; rays.len()],
        vec![Rgba::ZERO; rays.len()],
    );
    let (t_mid, _) = best(3, || integrate_x8(&m, &rays, &mut mid, &p).unwrap());
    let (t_pre, _) = best(3, || integrate_preintegrated_x8(&pm, &rays, &mut pre, &p).unwrap());
    let t0 = Instant::now();
    integrate_x8(&m, &rays, &mut reference, &MarchParams::reference(voxel / 16.0))?;
    let t_ref = t0.elapsed().as_secs_f64();
    let rms = |a: &[Rgba]| {
        let s: f64 = a
            .iter()
            .zip(&reference)
            .map(|(x, y)| {
                [x.r - y.r, x.g - y.g, x.b - y.b, x.a - y.a]
                    .iter()
                    .map(|d| (*d as f64).powi(2))
                    .sum::<f64>()
            })
            .sum();
        (s / (4 * a.len()) as f64).sqrt()
    };
    println!(
        "{:<14} Marschner-Lobb {n}^3, two thin bands, step 1 voxel: midpoint {:>6.1} ms RMS {:.2e}, pre-integrated {:>6.1} ms RMS {:.2e} (table 256^2 built in {:.0} ms); reference 1/16 voxel {:.0} ms",
        "preintegrated",
        t_mid * 1e3,
        rms(&mid),
        t_pre * 1e3,
        rms(&pre),
        t_table * 1e3,
        t_ref * 1e3,
    );
    // Three panels side by side.
    let mut img = vec![Rgba::ZERO; 3 * rays.len()];
    for y in 0..size as usize {
        for (k, panel) in [&mid, &pre, &reference].into_iter().enumerate() {
            let row = &panel[y * size as usize..(y + 1) * size as usize];
            let at = (y * 3 + k) * size as usize;
            img[at..at + size as usize].copy_from_slice(row);
        }
    }
    let path = "out/volume_preintegrated.png";
    write_png(path, 3 * size, size, &img, [0.02, 0.02, 0.05])?;
    println!("{:<14} wrote {path} (midpoint | pre-integrated | reference)", "");
    Ok(())
}
