//! The main job: build a BVH, collapse it to BVH8, and render primary rays with normal shading
//! plus ambient occlusion (any-hit rays), multithreaded over image tiles, into PNGs; print what
//! was measured. The third built-in scene is instanced: 36 bunnies placed by a TLAS over one
//! BVH8 (camera tiles as packets through the instances, `Tlas::intersect8`). The fourth is
//! the bunny with holes cut by an alpha mask, a hit filter (`HitFilter`) on every primary and AO
//! ray (camera tiles as filtered packets, `packet::intersect_packet_filtered`).
//!
//! ```sh
//! cargo run --release --example render                 # the bundled bunny, a sphereflake, 36 bunny instances, a cut-out bunny
//! cargo run --release --example render -- model.obj    # your OBJ file
//! ```
//! Options after the path: `--size WxH`, `--ao N` (AO rays per pixel, default 8), `--threads T`,
//! `--spatial` (build with spatial splits, `Bvh2::build_spatial_par` on the same threads: slower
//! to build, a better tree for scenes of long thin or large triangles).

use std::time::Instant;
use strahl::build::{BuildParams, Bvh2, SpatialSplits};
use strahl::composite::{Assignment, Tile, render_tiles};
use strahl::geometry::offset::{hit_point, offset_origin};
use strahl::geometry::{Triangle, Triangles};
use strahl::glam::{Affine3A, Quat};
use strahl::layout::{Bvh8, Instance, Tlas};
use strahl::math::f32x8;
use strahl::scene::{self, Mesh, Rng};
use strahl::traverse::{Watertight, packet};
use strahl::{Aabb, Hit, Ray, Vec3};

struct Options {
    width: u32,
    height: u32,
    ao: u32,
    threads: usize,
    /// Build with spatial splits.
    spatial: bool,
}

struct Camera {
    eye: Vec3,
    fw: Vec3,
    right: Vec3,
    up: Vec3,
}

impl Camera {
    /// Looks at the scene from the front-right and above, framing its bounds.
    fn framing(b: &Aabb, aspect: f32) -> Self {
        let c = b.centroid();
        let r = (b.max - b.min).length() * 0.5;
        let dir = Vec3::new(0.55, 0.35, 1.0).normalize();
        let eye = c + dir * r * 2.0;
        let fw = (c - eye).normalize();
        let right = fw.cross(Vec3::Y).normalize() * 0.45 * aspect;
        let up = right.normalize().cross(fw) * 0.45;
        Self { eye, fw, right, up }
    }

    fn ray(&self, x: u32, y: u32, w: u32, h: u32) -> Ray {
        let u = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
        let v = 1.0 - (y as f32 + 0.5) / h as f32 * 2.0;
        Ray::new(self.eye, self.fw + self.right * u + self.up * v)
    }
}

/// A cosine-weighted direction around `n`.
fn cosine_dir(n: Vec3, rng: &mut Rng) -> Vec3 {
    let (u1, u2) = (rng.f32(), rng.f32());
    let r = u1.sqrt();
    let phi = std::f32::consts::TAU * u2;
    let t = if n.x.abs() > 0.5 { Vec3::Y } else { Vec3::X };
    let b1 = n.cross(t).normalize();
    let b2 = n.cross(b1);
    (b1 * (r * phi.cos()) + b2 * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()).normalize()
}

/// What the two passes trace: a BVH8 over the scene's triangles, or a TLAS over instances.
trait Tracer: Sync {
    /// Closest hits of up to 8 coherent rays (one 4 x 2 tile of pixels), with the instance hit.
    fn primary(&self, rays: &[Ray], out: &mut [Option<(Hit, u32)>]);
    /// Any-hit answers for a batch of rays.
    fn occluded(&self, rays: &[Ray], out: &mut [bool]);
    /// The world-space triangle of a hit.
    fn triangle(&self, hit: &Hit, instance: u32) -> Option<Triangle>;
}

struct Flat {
    bvh: Bvh8,
    tris: Vec<Triangle>,
}

impl Tracer for Flat {
    fn primary(&self, rays: &[Ray], out: &mut [Option<(Hit, u32)>]) {
        // Coherent: interval-culled packet traversal.
        let mut block = [None; 8];
        packet::intersect8::<Watertight, _, 8>(self.bvh.view(), rays, &mut block, packet::DEFAULT_SWITCH);
        for (o, h) in out.iter_mut().zip(block) {
            *o = h.map(|h| (h, 0));
        }
    }
    fn occluded(&self, rays: &[Ray], out: &mut [bool]) {
        // One ray at a time: a pixel's AO rays leave one point, so they are coherent, and two
        // interleaved any-hit walks (which the batches no longer use) measured 1.07-1.2x slower here (the bunny, the sphereflake, the cut-out bunny; two runs each,
        // 2 threads).
        self.bvh.occluded_batch::<Watertight>(rays, out);
    }
    fn triangle(&self, hit: &Hit, _: u32) -> Option<Triangle> {
        self.tris[..].triangle(hit.prim as usize)
    }
}

/// A BVH8 whose triangles are cut out by an alpha mask: a hit filter (`strahl::traverse::HitFilter`) keeps a hit
/// only outside a lattice of spherical holes around its surface point, for primary and AO rays
/// alike, so light passes through the holes as the camera's rays do.
struct Cutout {
    bvh: Bvh8,
    tris: Vec<Triangle>,
    /// Lattice cells per unit of length.
    freq: f32,
}

impl Cutout {
    /// The alpha test: `true` (opaque) outside a hole of radius 0.3 cells around each lattice point.
    fn opaque(&self, hit: &Hit) -> bool {
        let Some(tri) = self.tris.get(hit.prim as usize) else {
            return false;
        };
        let q = hit_point(tri, hit) * self.freq;
        (q - q.round()).length() > 0.3
    }
}

impl Tracer for Cutout {
    fn primary(&self, rays: &[Ray], out: &mut [Option<(Hit, u32)>]) {
        // Coherent: the filtered packet traversal (shared box tests, leaves lane by lane).
        let mut block = [None; 8];
        let opaque = |h: &Hit| self.opaque(h);
        packet::intersect_packet_filtered::<Watertight, _, 8, f32x8, 8>(
            self.bvh.view(),
            rays,
            &mut block,
            packet::DEFAULT_SWITCH,
            opaque,
        );
        for (o, h) in out.iter_mut().zip(block) {
            *o = h.map(|h| (h, 0));
        }
    }
    fn occluded(&self, rays: &[Ray], out: &mut [bool]) {
        // One ray at a time, as for the plain scenes.
        for (o, r) in out.iter_mut().zip(rays) {
            *o = self.bvh.occluded_filtered::<Watertight>(r, |h: &Hit| self.opaque(h));
        }
    }
    fn triangle(&self, hit: &Hit, _: u32) -> Option<Triangle> {
        self.tris[..].triangle(hit.prim as usize)
    }
}

struct Instanced {
    tlas: Tlas,
    blases: [Bvh8; 1],
    tris: Vec<Triangle>,
    instances: Vec<Instance>,
}

impl Tracer for Instanced {
    fn primary(&self, rays: &[Ray], out: &mut [Option<(Hit, u32)>]) {
        // Coherent: the tile walks the TLAS as one packet, and each bunny's BLAS too.
        let mut block = [None; 8];
        self.tlas.intersect8::<Watertight, _, 8>(&self.blases, rays, &mut block);
        for (o, h) in out.iter_mut().zip(block) {
            *o = h.map(|h| (h.hit, h.instance));
        }
    }
    fn occluded(&self, rays: &[Ray], out: &mut [bool]) {
        self.tlas.occluded_batch::<Watertight, _, 8>(&self.blases, rays, out);
    }
    fn triangle(&self, hit: &Hit, instance: u32) -> Option<Triangle> {
        let m = self.instances.get(instance as usize)?.transform;
        Some(
            self.tris[..]
                .triangle(hit.prim as usize)?
                .map(|v| m.transform_point3(v)),
        )
    }
}

/// Builds a binned-SAH BVH2 of `tris` on `o.threads` and collapses it to BVH8; prints the figures.
/// `None` (said why) where nothing can be rendered.
fn build(tris: &[Triangle], o: &Options) -> Option<(Bvh2, Bvh8)> {
    let t0 = Instant::now();
    let built = if o.spatial {
        Bvh2::build_spatial_par(tris, &BuildParams::default(), &SpatialSplits::default(), o.threads)
    } else {
        Bvh2::build_par(tris, &BuildParams::default(), o.threads)
    };
    let (bvh2, stats) = match built {
        Ok(b) => b,
        Err(e) => {
            eprintln!("cannot build a BVH: {e}");
            return None;
        }
    };
    let build_s = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let bvh = Bvh8::from_bvh2_par(&bvh2, tris, o.threads).expect("a built tree collapses");
    let collapse_s = t0.elapsed().as_secs_f64();
    println!(
        "build: {} on up to {} threads {:.1} ms ({:.1} M tri/s, {} invalid triangles skipped), collapse to BVH8 {:.1} ms, SAH cost {:.1}, {} BVH8 nodes{}",
        if o.spatial { "spatial splits" } else { "binned SAH" },
        o.threads,
        build_s * 1e3,
        stats.primitives as f64 / build_s / 1e6,
        stats.invalid,
        collapse_s * 1e3,
        bvh2.sah_cost(1.0, 1.0),
        bvh.nodes().len(),
        if o.spatial {
            format!(
                ", {:.2} references per triangle",
                bvh2.prim_indices.len() as f64 / stats.primitives.max(1) as f64
            )
        } else {
            String::new()
        }
    );
    if bvh.is_empty() {
        println!("nothing to render");
        return None;
    }
    Some((bvh2, bvh))
}

fn render(name: &str, mesh: &Mesh, o: &Options) {
    let tris: Vec<Triangle> = mesh.to_soup();
    println!("\n== {name}: {} triangles", tris.len());
    let Some((bvh2, bvh)) = build(&tris, o) else {
        return;
    };
    let bounds = bvh2.bounds();
    shade(name, &Flat { bvh, tris }, &bounds, o);
}

/// `mesh` with holes cut by an alpha mask (a hit filter): `cells` lattice cells across its bounds.
fn render_cutout(name: &str, mesh: &Mesh, cells: f32, o: &Options) {
    let tris: Vec<Triangle> = mesh.to_soup();
    println!(
        "\n== {name}: {} triangles, alpha-tested holes (a hit filter on every ray)",
        tris.len()
    );
    let Some((bvh2, bvh)) = build(&tris, o) else {
        return;
    };
    let bounds = bvh2.bounds();
    let freq = cells / (bounds.max - bounds.min).max_element();
    shade(name, &Cutout { bvh, tris, freq }, &bounds, o);
}

/// `k x k` instances of `mesh` on a grid, each turned about y and scaled by 0.7 to 1.3: one BLAS,
/// a TLAS over the instances.
fn render_instances(name: &str, mesh: &Mesh, k: usize, o: &Options) {
    let tris: Vec<Triangle> = mesh.to_soup();
    println!(
        "\n== {name}: {} instances of one {}-triangle BLAS ({} triangles in the world)",
        k * k,
        tris.len(),
        k * k * tris.len()
    );
    let Some((bvh2, blas)) = build(&tris, o) else {
        return;
    };
    let b = bvh2.bounds();
    let size = (b.max - b.min).max_element();
    let mut rng = Rng::new(11);
    let instances: Vec<Instance> = (0..k * k)
        .map(|i| {
            let q = Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU));
            let s = Vec3::splat(rng.range(0.7, 1.3));
            let t = Vec3::new((i % k) as f32, 0.0, (i / k) as f32) * size * 1.2;
            Instance::new(Affine3A::from_scale_rotation_translation(s, q, t), 0)
        })
        .collect();
    let blases = [blas];
    let t0 = Instant::now();
    let tlas = Tlas::build(&instances, &blases).expect("a few instances build");
    println!(
        "TLAS over {} instances in {:.3} ms ({} left out); memory: BLAS {:.2} MB + TLAS {:.3} MB",
        tlas.instances(),
        t0.elapsed().as_secs_f64() * 1e3,
        tlas.left_out(),
        blases[0].memory_bytes() as f64 / 1e6,
        tlas.memory_bytes() as f64 / 1e6
    );
    let bounds = tlas.bvh().bounds();
    let scene = Instanced {
        tlas,
        blases,
        tris,
        instances,
    };
    shade(name, &scene, &bounds, o);
}

/// Pass 1, primary rays (closest hit) in 4 x 2 tiles; pass 2, normal shading with `o.ao`
/// ambient-occlusion rays per hit pixel; the PNG and the figures.
fn shade(name: &str, scene: &dyn Tracer, bounds: &Aabb, o: &Options) {
    let (w, h) = (o.width, o.height);
    let cam = Camera::framing(bounds, w as f32 / h as f32);
    let scale = (bounds.max - bounds.min).length();

    // Pass 1: primary rays (closest hit), tiles from a queue.
    let t0 = Instant::now();
    let (hits, _) = render_tiles(
        w,
        h,
        16,
        o.threads,
        Assignment::Dynamic,
        |t: Tile, out: &mut [Option<(Hit, u32)>]| {
            let tw = t.x1 - t.x0;
            // Once per tile: every packet overwrites the entries it uses.
            let mut block = [None; 8];
            for by in (t.y0..t.y1).step_by(2) {
                for bx in (t.x0..t.x1).step_by(4) {
                    let mut rays = [Ray::new(Vec3::ZERO, Vec3::ZERO); 8];
                    let mut at = [0usize; 8];
                    let mut n = 0;
                    for y in by..(by + 2).min(t.y1) {
                        for x in bx..(bx + 4).min(t.x1) {
                            rays[n] = cam.ray(x, y, w, h);
                            at[n] = ((y - t.y0) * tw + (x - t.x0)) as usize;
                            n += 1;
                        }
                    }
                    scene.primary(&rays[..n], &mut block[..n]);
                    for (i, &j) in at[..n].iter().enumerate() {
                        out[j] = block[i];
                    }
                }
            }
        },
    );
    let primary_s = t0.elapsed().as_secs_f64();
    let primary = (w * h) as f64;
    let hit_count = hits.iter().filter(|h| h.is_some()).count();

    // Pass 2: ambient occlusion, `ao` any-hit rays per hit pixel within 0.1 of the scene's size.
    let t0 = Instant::now();
    let (shade, _) = render_tiles(
        w,
        h,
        16,
        o.threads,
        Assignment::Dynamic,
        |t: Tile, out: &mut [[u8; 3]]| {
            let tw = t.x1 - t.x0;
            // One pixel's AO rays are traced together.
            let (mut ao_rays, mut occ) = (Vec::with_capacity(o.ao as usize), vec![false; o.ao as usize]);
            for (i, px) in out.iter_mut().enumerate() {
                let (x, y) = (t.x0 + i as u32 % tw, t.y0 + i as u32 / tw);
                let ray = cam.ray(x, y, w, h);
                let Some((hit, instance)) = hits[(y * w + x) as usize] else {
                    let g = (40.0 + 30.0 * (y as f32 / h as f32)) as u8;
                    *px = [g, g, g + 10];
                    continue;
                };
                let Some([a, b, c]) = scene.triangle(&hit, instance) else {
                    continue;
                };
                let mut n = (b - a).cross(c - a).normalize_or_zero();
                if n.dot(ray.direction) > 0.0 {
                    n = -n;
                }
                // The AO rays start off the surface by a few ULPs (Wächter and Binder 2019).
                let p = offset_origin(hit_point(&[a, b, c], &hit), n);
                let mut rng = Rng::new((y as u64) << 32 | x as u64);
                ao_rays.clear();
                ao_rays.extend((0..o.ao).map(|_| Ray::with_range(p, cosine_dir(n, &mut rng), 0.0, scale * 0.1)));
                scene.occluded(&ao_rays, &mut occ);
                let open = occ.iter().filter(|&&blocked| !blocked).count();
                let ao = if o.ao == 0 { 1.0 } else { open as f32 / o.ao as f32 };
                let base = n * 0.5 + Vec3::splat(0.5);
                let c = base * (0.25 + 0.75 * ao);
                *px = [c.x, c.y, c.z].map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
            }
        },
    );
    let ao_s = t0.elapsed().as_secs_f64();
    let ao_rays = hit_count as f64 * o.ao as f64;

    std::fs::create_dir_all("out").expect("create out/");
    let path = format!("out/render_{name}.png");
    let file = std::fs::File::create(&path).expect("create the PNG");
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let rgb: Vec<u8> = shade.iter().flatten().copied().collect();
    enc.write_header()
        .and_then(|mut wr| wr.write_image_data(&rgb))
        .expect("write the PNG");

    println!(
        "primary: {w}x{h} rays in {:.1} ms = {:.2} Mrays/s ({:.0}% hit); ambient occlusion: {:.0} rays in {:.1} ms = {:.2} Mrays/s; {} threads",
        primary_s * 1e3,
        primary / primary_s / 1e6,
        hit_count as f64 / primary * 100.0,
        ao_rays,
        ao_s * 1e3,
        ao_rays / ao_s / 1e6,
        o.threads
    );
    println!("wrote {path}");
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut path = None;
    let mut o = Options {
        width: 1024,
        height: 768,
        ao: 8,
        threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        spatial: false,
    };
    while let Some(a) = args.next() {
        match a.as_str() {
            "--size" => {
                let v = args.next().unwrap_or_default();
                if let Some((w, h)) = v
                    .split_once('x')
                    .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                {
                    (o.width, o.height) = (w, h);
                }
            }
            "--ao" => o.ao = args.next().and_then(|v| v.parse().ok()).unwrap_or(o.ao),
            "--threads" => o.threads = args.next().and_then(|v| v.parse().ok()).unwrap_or(o.threads).max(1),
            "--spatial" => o.spatial = true,
            _ => path = Some(a),
        }
    }
    o.width = o.width.clamp(1, 8192);
    o.height = o.height.clamp(1, 8192);
    println!(
        "strahl renderer: BVH8, primary rays as 4x2 packets, AO as single any-hit rays, watertight triangles, {} AO rays per pixel",
        o.ao
    );
    match path {
        Some(p) => {
            let text = match std::fs::read_to_string(&p) {
                Ok(t) => t,
                Err(e) => {
                    eprintln!("cannot read {p}: {e}");
                    std::process::exit(1);
                }
            };
            match Mesh::from_obj(&text) {
                Ok(m) => {
                    let stem = std::path::Path::new(&p)
                        .file_stem()
                        .and_then(|s| s.to_str())
                        .unwrap_or("model");
                    render(stem, &m, &o);
                }
                Err(e) => {
                    eprintln!("cannot parse {p}: {e}");
                    std::process::exit(1);
                }
            }
        }
        None => {
            render("bunny", &scene::bunny(), &o);
            render("sphereflake", &scene::sphereflake(2, 2), &o);
            render_instances("bunnies", &scene::bunny(), 6, &o);
            render_cutout("bunny_cutout", &scene::bunny(), 9.0, &o);
        }
    }
}
