//! Sort-last distributed rendering: every rank renders the spheres inside its box of a k-d
//! decomposition of the scene into a full-size partial image, and the partial images are
//! composited with radix-k (the k-vector chosen by the cost model) onto rank 0, which writes
//! `out/sortlast_depth.png` (depth compositing) and `out/sortlast_over.png` (semi-transparent
//! spheres, "over" in visibility order).
//!
//! ```sh
//! cargo run --release --example sortlast                 # 4 ranks as threads
//! cargo run --release --example sortlast -- 6            # 6 ranks as threads
//! cargo build --release --features mpi --example sortlast
//! mpirun -np 4 target/release/examples/sortlast          # 4 MPI processes
//! ```

use std::time::Instant;
use strahl::composite::{
    CompositeStats, CostModel, DepthPixel, Pixel, Plan, RgbaF32, Schedule, ThreadTransport, Transport, View, auto_kvec,
    composite, kd_decompose, visibility_order,
};
use strahl::intersect::{PreparedRay, TriangleX8, intersect_aabb_scalar, watertight};
use strahl::{Aabb, Ray, Vec3};

const W: u32 = 512;
const H: u32 = 384;

/// One sphere: its box and its triangles in packs of 8.
struct Sphere {
    bounds: Aabb,
    packs: Vec<TriangleX8>,
    tris: Vec<[Vec3; 3]>,
    colour: Vec3,
}

fn scene() -> Vec<Sphere> {
    let unit = strahl::scene::icosphere(3);
    let mut spheres = Vec::new();
    for i in 0..4 {
        for j in 0..3 {
            for k in 0..2 {
                let c = Vec3::new(i as f32 * 2.2 - 3.3, j as f32 * 2.2 - 2.2, k as f32 * 2.4 - 1.2);
                let r = 0.8 + 0.15 * ((i + j + k) % 3) as f32;
                let tris: Vec<[Vec3; 3]> = unit.to_soup().iter().map(|t| t.map(|p| c + p * r)).collect();
                let prims: Vec<u32> = (0..tris.len() as u32).collect();
                let packs = tris
                    .chunks(8)
                    .zip(prims.chunks(8))
                    .map(|(t, p)| TriangleX8::pack(t, p))
                    .collect();
                let hue = (i * 6 + j * 2 + k) as f32 / 24.0 * std::f32::consts::TAU;
                let colour = Vec3::new(
                    0.5 + 0.5 * hue.cos(),
                    0.5 + 0.5 * (hue + 2.1).cos(),
                    0.5 + 0.5 * (hue + 4.2).cos(),
                );
                spheres.push(Sphere {
                    bounds: Aabb::new(c - Vec3::splat(r), c + Vec3::splat(r)),
                    packs,
                    tris,
                    colour,
                });
            }
        }
    }
    spheres
}

fn camera(x: u32, y: u32, eye: Vec3) -> Ray {
    let (fw, up) = ((Vec3::ZERO - eye).normalize(), Vec3::Y);
    let right = fw.cross(up).normalize();
    let up = right.cross(fw);
    let (u, v) = (
        (x as f32 + 0.5) / W as f32 * 2.0 - 1.0,
        1.0 - (y as f32 + 0.5) / H as f32 * 2.0,
    );
    Ray::new(eye, fw + right * u * 0.6 * W as f32 / H as f32 + up * v * 0.6)
}

/// Renders `mine` into a full-size image: the nearest hit's depth and shaded colour.
fn render(spheres: &[&Sphere], eye: Vec3) -> Vec<(f32, Vec3)> {
    let light = Vec3::new(0.4, 0.8, 0.6).normalize();
    (0..W * H)
        .map(|i| {
            let mut r = PreparedRay::new(&camera(i % W, i / W, eye));
            let mut best = None;
            for s in spheres {
                if intersect_aabb_scalar(&r, &s.bounds).is_none() {
                    continue;
                }
                for pack in &s.packs {
                    if let Some(h) = watertight::intersect_x8(&r, pack) {
                        r.tmax = h.t;
                        best = Some((h.t, s, h.prim));
                    }
                }
            }
            match best {
                Some((t, s, prim)) => {
                    let [a, b, c] = s.tris[prim as usize];
                    let n = (b - a).cross(c - a).normalize();
                    (t, s.colour * (0.15 + 0.85 * n.dot(light).abs()))
                }
                None => (f32::INFINITY, Vec3::ZERO),
            }
        })
        .collect()
}

fn rgba8(c: Vec3) -> u32 {
    let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u32;
    q(c.x) | (q(c.y) << 8) | (q(c.z) << 16) | (255 << 24)
}

fn write_png(path: &str, rgb: &[u8]) {
    std::fs::create_dir_all("out").expect("create out/");
    let file = std::fs::File::create(path).expect("create PNG");
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), W, H);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()
        .and_then(|mut w| w.write_image_data(rgb))
        .expect("write PNG");
}

fn report(t: &impl Transport, what: &str, tris: usize, render_ms: f64, stats: &CompositeStats) {
    let rounds: Vec<String> = stats.round_seconds.iter().map(|s| format!("{:.2}", s * 1e3)).collect();
    println!(
        "rank {:>2} {what}: {tris:>6} triangles, render {render_ms:7.1} ms, rounds + gather [{}] ms, sent {:.0} KiB",
        t.rank(),
        rounds.join(", "),
        (stats.bytes_sent + stats.gather_bytes) as f64 / 1024.0
    );
}

/// Everything one rank does; returns the two final images on the root.
fn rank_main(t: &mut impl Transport, spheres: &[Sphere]) {
    let p = t.size();
    let eye = Vec3::new(5.0, 3.0, 9.0);
    let bounds = spheres.iter().fold(Aabb::EMPTY, |b, s| b.union(&s.bounds));
    let mut boxes = vec![Aabb::EMPTY; p as usize];
    kd_decompose(&bounds, &mut boxes);
    // A sphere belongs to the rank whose box holds its centre (ties: the first such box).
    let owner = |s: &Sphere| {
        boxes
            .iter()
            .position(|b| b.contains_point(s.bounds.centroid()))
            .unwrap_or(0)
    };
    let mine: Vec<&Sphere> = spheres.iter().filter(|s| owner(s) == t.rank() as usize).collect();
    let tris: usize = mine.iter().map(|s| s.tris.len()).sum();

    let t0 = Instant::now();
    let img = render(&mine, eye);
    let render_ms = t0.elapsed().as_secs_f64() * 1e3;
    let n = img.len() as u64;
    let kvec = auto_kvec(p, n, DepthPixel::BYTES as u64, &CostModel::shared_memory());
    if t.rank() == 0 {
        println!(
            "{p} ranks, {W}x{H} pixels, k-vector {:?} (cost model: shared memory)",
            kvec.as_slice()
        );
    }

    // Depth compositing: any rank order gives the same image.
    let depth: Vec<DepthPixel> = img
        .iter()
        .map(|&(z, c)| {
            if z.is_finite() {
                DepthPixel::new(z, rgba8(c))
            } else {
                DepthPixel::EMPTY
            }
        })
        .collect();
    let identity: Vec<u32> = (0..p).collect();
    t.barrier().expect("barrier"); // time compositing, not the render imbalance
    let plan = Plan {
        schedule: Schedule::RadixK(kvec),
        order: &identity,
        root: 0,
        sparse: true,
    };
    let (out, stats) = composite(t, &depth, &plan).expect("depth compositing");
    report(t, "depth", tris, render_ms, &stats);
    if let Some(out) = out {
        let rgb: Vec<u8> = out
            .iter()
            .flat_map(|d| d.rgba().to_le_bytes().into_iter().take(3))
            .collect();
        write_png("out/sortlast_depth.png", &rgb);
    }

    // Over: the same spheres at 60% opacity, blended in the visibility order of the rank boxes.
    let over: Vec<RgbaF32> = img
        .iter()
        .map(|&(z, c)| {
            if z.is_finite() {
                RgbaF32([c.x * 0.6, c.y * 0.6, c.z * 0.6, 0.6])
            } else {
                RgbaF32::EMPTY
            }
        })
        .collect();
    let mut order = vec![0u32; p as usize];
    visibility_order(&bounds, View::Eye(eye), &mut order);
    let plan = Plan {
        schedule: Schedule::RadixK(kvec),
        order: &order,
        root: 0,
        sparse: true,
    };
    t.barrier().expect("barrier");
    let (out, stats) = composite(t, &over, &plan).expect("over compositing");
    report(t, "over ", tris, 0.0, &stats);
    if let Some(out) = out {
        let bg = 0.08;
        let rgb: Vec<u8> = out
            .iter()
            .flat_map(|px| {
                let [r, g, b, a] = px.0;
                [r, g, b].map(|c| ((c + (1.0 - a) * bg).clamp(0.0, 1.0) * 255.0 + 0.5) as u8)
            })
            .collect();
        write_png("out/sortlast_over.png", &rgb);
        println!("wrote out/sortlast_depth.png and out/sortlast_over.png");
    }
}

fn main() {
    let spheres = scene();
    #[cfg(feature = "mpi")]
    if std::env::var_os("OMPI_COMM_WORLD_SIZE").is_some() || std::env::var_os("PMI_SIZE").is_some() {
        let universe = mpi::initialize().expect("MPI initialises once");
        let mut t = strahl::composite::MpiTransport::new(universe.world());
        rank_main(&mut t, &spheres);
        return;
    }
    let p: u32 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(4)
        .clamp(1, 64);
    println!("(in-process: {p} ranks as threads; build with --features mpi and run under mpirun for MPI)");
    ThreadTransport::run(p, |t| rank_main(t, &spheres));
}
