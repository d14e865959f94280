use std::time::Instant;
use strahl::volume::procedural::{pinhole_rays, torus, unit_volume};
use strahl::volume::*;
use strahl::Vec3;

#[test]
#[ignore]
fn probe() {
    let n = 128;
    let data = torus(n, 0.5, 0.15);
    let vol = unit_volume(&data, n).unwrap();
    let table: Vec<TfEntry> = (0..256).map(|i| if i < 40 { TfEntry::TRANSPARENT } else { let t = (i - 40) as f32 / 215.0; TfEntry::new([0.9 * t + 0.1, 0.4 + 0.3 * t, 1.0 - 0.8 * t], 6.0 * (0.2 + t)) }).collect();
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    grid.classify(&tf);
    let plain = VolumeMedium::new(vol, tf);
    let skip = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    let rays = pinhole_rays(Vec3::new(2.2, -2.9, 1.6), Vec3::ZERO, 36.0, 96, 96);
    let p = MarchParams::reference(vol.spacing().x * 0.5);
    let mut out = vec![Rgba::ZERO; rays.len()];
    let which = std::env::var("W").unwrap_or_default();
    let (mut a, mut b) = (f64::MAX, f64::MAX);
    for _ in 0..60 {
        if which != "grid" { let t = Instant::now(); integrate_x8(&plain, &rays, &mut out, &p).unwrap(); a = a.min(t.elapsed().as_secs_f64()); }
        if which != "plain" { let t = Instant::now(); integrate_x8(&skip, &rays, &mut out, &p).unwrap(); b = b.min(t.elapsed().as_secs_f64()); }
    }
    println!("x8 no grid {:.2} ms, grid {:.2} ms, ratio {:.2}", a * 1e3, b * 1e3, a / b);
}
