//! BVH2 construction: every builder side by side, one criterion group per scene, single thread.
//!
//! ```text
//! cargo bench --bench build -- --noplot                       # bunny and the 1M-triangle soup
//! STRAHL_BENCH_SCENES=all cargo bench --bench build -- --noplot   # + 1M terrain, 1M sphereflake
//! ```
//!
//! Criterion reports build throughput as `thrpt` in elements (triangles) per second, for *warm*
//! builds: one `Builder` and one output `Bvh2` reused across iterations, as a renderer that
//! rebuilds every frame would (no new pages to fault in; see `build::Builder`). After each group
//! a table is printed for the same builders: best-of-3 warm and cold (`Bvh2::build`, fresh
//! memory) build throughput in Mtri/s, the SAH cost of the tree (`C_T = C_I = 1`, normalised by
//! the root area), its shape, and the speed of the scalar BVH2 reference traversal
//! (`traverse::intersect_scalar`, watertight test) on one fixed set of rays per scene, in million
//! rays per second.
//!
//! Scenes: the Stanford bunny (`scene::bunny()`, 3,674 triangles) and `scene::thin_soup(1 << 20)`
//! (1,048,576 long thin triangles, heavily overlapping boxes), plus optionally
//! `scene::terrain(724)` (1,048,352) and `scene::sphereflake(3, 3)` (1,049,600).
//!
//! Peers (the `bvh` and `obvhs` crates, Embree 3's `rtcBuildBVH`) are a later slice: they join
//! each group as members named `peer/<crate>/<builder>` in `peers()` below, and their trees go
//! through the same SAH cost and trace measurement (converted to a `Bvh2`).

use criterion::{BenchmarkGroup, Criterion, Throughput, criterion_group, criterion_main, measurement::WallTime};
use std::hint::black_box;
use std::time::{Duration, Instant};
use strahl::build::{BinAxes, BuildParams, Builder, Bvh2, MortonBits};
use strahl::geometry::Triangle;
use strahl::scene::{self, Rng};
use strahl::traverse::{Watertight, intersect_scalar};
use strahl::{Aabb, Ray, Vec3};

struct Scene {
    name: &'static str,
    tris: Vec<Triangle>,
    rays: Vec<Ray>,
}

/// Rays from a sphere around the scene (1.5 bounding radii out) towards random points in its box.
fn rays_for(tris: &[Triangle], count: usize) -> Vec<Ray> {
    let mut b = Aabb::EMPTY;
    for t in tris {
        for v in t {
            b.grow(*v);
        }
    }
    let mut r = Rng::new(42);
    let (c, radius) = (b.centroid(), b.extent().length() * 0.75);
    (0..count)
        .map(|_| {
            let o = c + r.unit_vector() * radius;
            let target = b.min + b.extent() * Vec3::new(r.f32(), r.f32(), r.f32());
            Ray::new(o, (target - o).normalize())
        })
        .collect()
}

fn scenes() -> Vec<Scene> {
    let mut v = vec![
        ("bunny", scene::bunny().to_soup(), 200_000),
        ("soup1M", scene::thin_soup(1 << 20, 1), 50_000),
    ];
    if std::env::var("STRAHL_BENCH_SCENES").is_ok_and(|s| s == "all") {
        v.push(("terrain1M", scene::terrain(724, 1).to_soup(), 50_000));
        v.push(("sphereflake1M", scene::sphereflake(3, 3).to_soup(), 50_000));
    }
    v.into_iter()
        .map(|(name, tris, nrays)| {
            let rays = rays_for(&tris, nrays);
            Scene { name, tris, rays }
        })
        .collect()
}

/// Every builder, fastest build first (the presets, plus variants between them).
fn builders() -> Vec<(&'static str, BuildParams)> {
    vec![
        ("lbvh30 (fastest)", BuildParams::fastest()),
        (
            "lbvh63",
            BuildParams {
                morton_bits: MortonBits::Bits63,
                ..BuildParams::fastest()
            },
        ),
        ("median", BuildParams::median()),
        ("binned8-longest (fast)", BuildParams::fast()),
        (
            "binned8-all",
            BuildParams {
                bin_axes: BinAxes::All,
                ..BuildParams::fast()
            },
        ),
        ("binned16-all (balanced)", BuildParams::balanced()),
        (
            "binned32-all",
            BuildParams {
                bins: 32,
                ..BuildParams::balanced()
            },
        ),
        ("sweep (quality)", BuildParams::quality()),
    ]
}

/// Peer builders join the group here (later slice): `bvh` (`Bvh::build`), `obvhs` (its
/// `BvhBuildParams` presets), Embree 3 (`rtcBuildBVH`, behind a bench-only feature). Each is a
/// member `peer/<crate>/<builder>` of `g`, and its tree is converted to a `Bvh2` for the summary.
fn peers(_g: &mut BenchmarkGroup<'_, WallTime>, _scene: &Scene) {}

fn trace_mrays(bvh: &Bvh2, s: &Scene) -> (f64, usize) {
    let start = Instant::now();
    let mut hits = 0;
    for ray in &s.rays {
        hits += intersect_scalar::<Watertight, _>(bvh.view(), &s.tris[..], black_box(ray)).is_some() as usize;
    }
    (s.rays.len() as f64 / start.elapsed().as_secs_f64() / 1e6, hits)
}

fn summary(s: &Scene) {
    println!(
        "\n{}: {} triangles, {} rays\n| builder | warm Mtri/s | cold Mtri/s | SAH cost | nodes | leaves | depth | trace Mrays/s | hits |\n|---|---|---|---|---|---|---|---|---|",
        s.name,
        s.tris.len(),
        s.rays.len()
    );
    let mut builder = Builder::new();
    let mut bvh = Bvh2::default();
    for (name, p) in builders() {
        let (mut warm, mut cold) = (f64::INFINITY, f64::INFINITY);
        let mut stats = None;
        for _ in 0..3 {
            let t = Instant::now();
            stats = Some(builder.build_into(&s.tris[..], &p, &mut bvh).expect("valid params"));
            warm = warm.min(t.elapsed().as_secs_f64());
            let t = Instant::now();
            black_box(Bvh2::build(&s.tris[..], &p).expect("valid params"));
            cold = cold.min(t.elapsed().as_secs_f64());
        }
        let stats = stats.expect("built");
        let (mrays, hits) = trace_mrays(&bvh, s);
        let n = s.tris.len() as f64;
        println!(
            "| {name} | {:.2} | {:.2} | {:.2} | {} | {} | {} | {:.3} | {} |",
            n / warm / 1e6,
            n / cold / 1e6,
            bvh.sah_cost(1.0, 1.0),
            stats.nodes,
            stats.leaves,
            stats.max_depth,
            mrays,
            hits
        );
    }
}

fn build(c: &mut Criterion) {
    for s in scenes() {
        let mut g = c.benchmark_group(format!("build/{}", s.name));
        g.throughput(Throughput::Elements(s.tris.len() as u64));
        g.sample_size(10);
        g.warm_up_time(Duration::from_millis(500));
        g.measurement_time(Duration::from_secs(if s.tris.len() > 100_000 { 4 } else { 2 }));
        let mut builder = Builder::new();
        let mut bvh = Bvh2::default();
        for (name, p) in builders() {
            g.bench_function(name, |b| {
                b.iter(|| {
                    builder
                        .build_into(black_box(&s.tris[..]), &p, &mut bvh)
                        .expect("valid params")
                })
            });
        }
        peers(&mut g, &s);
        g.finish();
        summary(&s);
    }
}

criterion_group!(benches, build);
criterion_main!(benches);
