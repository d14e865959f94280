//! Animated geometry: the bundled bunny (or a sphereflake, `-- flake`) swaying through 8 frames,
//! its BVH8 refitted every frame (`BvhWide::refit_par`) instead of rebuilt; each frame rendered
//! (primary rays, normal shading) and put side by side into `out/animate.png`. Printed per frame:
//! the refit's time against a rebuild's (build + collapse), and the trace time of the refitted
//! tree against the rebuilt one, which grows as the motion piles up.
//!
//! With `-- crowd`: 1,024 bunny instances dancing in rings (each ring turning at its own speed,
//! the instances crossing one another's places), the TLAS refitted every frame (`Tlas::refit`)
//! against rebuilt (`Tlas::build`), the same figures printed, the frames in
//! `out/animate_crowd.png`.
//!
//! ```sh
//! cargo run --release --example animate            # the bunny
//! cargo run --release --example animate -- flake   # a 12,800-triangle sphereflake
//! cargo run --release --example animate -- crowd   # 1,024 moving instances of the bunny
//! ```

use std::time::Instant;
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::Triangle;
use strahl::glam::{Affine3A, Quat};
use strahl::layout::{Bvh8, Instance, InstanceHit, Tlas};
use strahl::scene;
use strahl::traverse::Watertight;
use strahl::{Aabb, Hit, Ray, Vec3};

const FRAMES: usize = 8;
const SIZE: u32 = 256;

/// Frame `f` of the sway: each vertex moves sideways by a wave that grows with its height.
fn sway(rest: &[Triangle], b: &Aabb, f: usize) -> Vec<Triangle> {
    let size = (b.max - b.min).max_element();
    let phase = f as f32 / FRAMES as f32 * std::f32::consts::TAU;
    rest.iter()
        .map(|t| {
            t.map(|v| {
                let h = (v.y - b.min.y) / size;
                let s = 0.4 * size * h * h * phase.sin();
                v + Vec3::new(s * (3.0 * h + phase).cos(), 0.0, s * 0.5)
            })
        })
        .collect()
}

/// Best of three of `f`, in milliseconds, with its last result.
fn timed<T>(mut f: impl FnMut() -> T) -> (T, f64) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..3 {
        let t = Instant::now();
        out = Some(f());
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
    }
    (out.expect("ran three times"), best)
}

/// `SIZE x SIZE` pinhole rays from `eye` towards `at`.
fn camera(eye: Vec3, at: Vec3) -> (Vec<Ray>, Vec3) {
    let fw = (at - eye).normalize();
    let right = fw.cross(Vec3::Y).normalize() * 0.5;
    let up = right.normalize().cross(fw) * 0.5;
    let rays = (0..SIZE * SIZE)
        .map(|i| {
            let (x, y) = (i % SIZE, i / SIZE);
            let u = (x as f32 + 0.5) / SIZE as f32 * 2.0 - 1.0;
            let v = 1.0 - (y as f32 + 0.5) / SIZE as f32 * 2.0;
            Ray::new(eye, fw + right * u + up * v)
        })
        .collect();
    (rays, fw)
}

/// The frames side by side, 4 a row, as a PNG at `path`.
fn write_sheet(sheet: &[u8], path: &str) {
    std::fs::create_dir_all("out").expect("create out/");
    let file = std::fs::File::create(path).expect("create the PNG");
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), SIZE * FRAMES as u32 / 2, SIZE * 2);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()
        .and_then(|mut w| w.write_image_data(sheet))
        .expect("write the PNG");
    println!("wrote {path}");
}

/// Pixel `i` of frame `f` on the sheet, normal `n` shaded (facing the camera), or the
/// background.
fn put(sheet: &mut [u8], f: usize, i: usize, n: Option<Vec3>, fw: Vec3) {
    let (ox, oy) = ((f % (FRAMES / 2)) * SIZE as usize, (f / (FRAMES / 2)) * SIZE as usize);
    let row = SIZE as usize * FRAMES / 2;
    let (x, y) = (i % SIZE as usize + ox, i / SIZE as usize + oy);
    let rgb = match n {
        Some(mut n) => {
            if n.dot(fw) > 0.0 {
                n = -n;
            }
            (n * 0.5 + Vec3::splat(0.5)).to_array().map(|v| (v * 255.0) as u8)
        }
        None => [40, 40, 50],
    };
    let at = (y * row + x) * 3;
    sheet[at..at + 3].copy_from_slice(&rgb);
}

/// Rings of bunnies on the ground: 1,024 instances in 16 rings of 64, ring `k` turning by
/// `(k % 5 - 2) / 8` of a turn over the frames, so neighbouring rings pass one another.
fn crowd_frame(mesh: &[Triangle], f: usize) -> Vec<Instance> {
    let b = mesh
        .iter()
        .flatten()
        .fold(Aabb::EMPTY, |acc, &v| acc.union(&Aabb::new(v, v)));
    let size = (b.max - b.min).max_element();
    let lift = Vec3::new(0.0, -b.min.y, 0.0);
    (0..1024)
        .map(|i| {
            let (ring, k) = (i / 64, i % 64);
            let radius = size * (2.0 + 1.2 * ring as f32);
            let speed = ((ring % 5) as f32 - 2.0) / 8.0;
            let a = (k as f32 / 64.0 + speed * f as f32 / FRAMES as f32) * std::f32::consts::TAU;
            let at = Vec3::new(radius * a.cos(), 0.0, radius * a.sin());
            let turn = Quat::from_rotation_y(-a);
            Instance::new(
                Affine3A::from_rotation_translation(turn, at) * Affine3A::from_translation(lift),
                0,
            )
        })
        .collect()
}

/// The `crowd` mode (see the module docs).
fn crowd(threads: usize) {
    let mesh = scene::bunny().to_soup();
    let (b2, _) = Bvh2::build(&mesh[..], &BuildParams::default()).expect("default params are valid");
    let blases = [Bvh8::from_bvh2(&b2, &mesh[..]).expect("a built tree collapses")];
    let first = crowd_frame(&mesh, 0);
    let mut tlas = Tlas::build(&first, &blases).expect("1,024 instances build");
    let extent = tlas.bvh().bounds();
    let span = (extent.max - extent.min).max_element();
    let (rays, fw) = camera(Vec3::new(0.0, 0.45, 0.75) * span, Vec3::ZERO);
    println!(
        "1024 instances of a {}-triangle bunny, {FRAMES} frames of {SIZE}x{SIZE}, {threads} threads",
        mesh.len()
    );
    println!("frame | refit ms | rebuild ms | rebuild / refit | trace refit ms | trace rebuilt ms | refit / rebuilt");
    let mut sheet = vec![0u8; (SIZE as usize * FRAMES / 2) * (SIZE as usize * 2) * 3];
    let mut hits: Vec<Option<InstanceHit>> = vec![None; rays.len()];
    for f in 0..FRAMES {
        let inst = crowd_frame(&mesh, f);
        let (ok, refit_ms) = timed(|| tlas.refit(&inst, &blases));
        assert!(ok && tlas.left_out() == 0, "the same 1,024 instances, all placed");
        let (fresh, rebuild_ms) = timed(|| Tlas::build(&inst, &blases).expect("1,024 instances build"));
        let ((), trace_fresh) =
            timed(|| fresh.intersect_batch_par::<Watertight, _, 8>(&blases, &rays, &mut hits, threads));
        let fresh_hits = hits.iter().filter(|h| h.is_some()).count();
        let ((), trace_refit) =
            timed(|| tlas.intersect_batch_par::<Watertight, _, 8>(&blases, &rays, &mut hits, threads));
        assert_eq!(
            hits.iter().filter(|h| h.is_some()).count(),
            fresh_hits,
            "the refitted and the rebuilt TLAS hit as many pixels"
        );
        println!(
            "{f:5} | {refit_ms:8.3} | {rebuild_ms:10.3} | {:14.1}x | {trace_refit:14.2} | {trace_fresh:16.2} | {:.2}x",
            rebuild_ms / refit_ms,
            trace_refit / trace_fresh
        );
        for (i, hit) in hits.iter().enumerate() {
            let n = hit.map(|h| {
                let [a, b, c] = mesh[h.hit.prim as usize];
                let m = inst[h.instance as usize].transform.matrix3;
                // A rotation: normals turn with the mesh.
                (m * (b - a).cross(c - a)).normalize_or_zero()
            });
            put(&mut sheet, f, i, n, fw);
        }
    }
    write_sheet(&sheet, "out/animate_crowd.png");
}

fn main() {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    if std::env::args().nth(1).is_some_and(|a| a == "crowd") {
        crowd(threads);
        return;
    }
    let flake = std::env::args().nth(1).is_some_and(|a| a == "flake");
    let mesh = if flake {
        scene::sphereflake(1, 3)
    } else {
        scene::bunny()
    };
    let rest = mesh.to_soup();
    let params = BuildParams::default();
    let (bvh2, _) = Bvh2::build(&rest[..], &params).expect("default params are valid");
    let mut bvh = Bvh8::from_bvh2(&bvh2, &rest[..]).expect("a built tree collapses");
    let bounds = bvh2.bounds();
    // Room for the sway: the camera frames the rest pose's box grown by the largest motion.
    let size = (bounds.max - bounds.min).max_element();
    let view = Aabb::new(
        bounds.min - Vec3::splat(0.3 * size),
        bounds.max + Vec3::splat(0.3 * size),
    );
    let c = view.centroid();
    let eye = c + Vec3::new(0.0, 0.15, 1.0) * (view.max - view.min).length() * 0.6;
    let (rays, fw) = camera(eye, c);

    println!(
        "{} triangles, {FRAMES} frames of {SIZE}x{SIZE}, {threads} threads",
        rest.len()
    );
    println!("frame | refit ms | rebuild ms | rebuild / refit | trace refit ms | trace rebuilt ms | refit / rebuilt");
    let mut sheet = vec![0u8; (SIZE as usize * FRAMES / 2) * (SIZE as usize * 2) * 3];
    let mut hits = vec![None; rays.len()];
    for f in 0..FRAMES {
        let tris = sway(&rest, &bounds, f);
        let (left_out, refit_ms) = timed(|| bvh.refit_par(&tris[..], threads));
        assert_eq!(left_out, 0, "every swayed triangle is finite");
        let (fresh, rebuild_ms) = timed(|| {
            let (b2, _) = Bvh2::build_par(&tris[..], &params, threads).expect("default params are valid");
            Bvh8::from_bvh2_par(&b2, &tris[..], threads).expect("a built tree collapses")
        });
        let ((), trace_fresh) = timed(|| fresh.intersect_batch_par::<Watertight>(&rays, &mut hits, threads));
        let fresh_hits = hits.iter().filter(|h| h.is_some()).count();
        let ((), trace_refit) = timed(|| bvh.intersect_batch_par::<Watertight>(&rays, &mut hits, threads));
        assert_eq!(
            hits.iter().filter(|h| h.is_some()).count(),
            fresh_hits,
            "the refitted and the rebuilt tree see the same"
        );
        println!(
            "{f:5} | {refit_ms:8.2} | {rebuild_ms:10.2} | {:14.1}x | {trace_refit:14.2} | {trace_fresh:16.2} | {:.2}x",
            rebuild_ms / refit_ms,
            trace_refit / trace_fresh
        );
        for (i, hit) in hits.iter().enumerate() {
            let n = hit.map(|Hit { prim, .. }| {
                let [a, b, c] = tris[prim as usize];
                (b - a).cross(c - a).normalize_or_zero()
            });
            put(&mut sheet, f, i, n, fw);
        }
    }
    write_sheet(&sheet, "out/animate.png");
}
