//! Build-speed harness for the BVH2 builders (ignored: run by hand).
//!
//! `cargo test --release --test build_speed -- --ignored --nocapture speed`: each builder once to
//! warm its [`Builder`], then `STRAHL_REPS` timed builds (default 5), best and median. `STRAHL_N`
//! sets the soup size (`scene::thin_soup(n, 1)`, default 2^20); `STRAHL_ONLY` a comma-separated
//! list of builders (`fastest`, `lbvh63`, `fast`, `fast_exact` (`fast()` binning every reference),
//! `balanced_exact` (`balanced()` binning every reference), `binned8all`, `balanced`, `high`, `median`, `quality`,
//! `hlbvh`, `hybrid_sah`, `fast_treelets` (`fast()` + TRBVH treelets of 7), `fast_atrbvh`,
//! `fastest_atrbvh` (+ [`TreeletParams::agglomerative`]), `*_reinsert` (`balanced`, `high`, `fastest` with [`ReinsertParams::new`]); `*_normalized`: the Morton builders on the classic per-axis grid,
//! [`MortonCells::Normalized`]). `STRAHL_SCENE` picks the scene: `soup` (default), `terrain`
//! (`scene::terrain(724, 1)`, 1M triangles, 5:1 flat), `sphereflake` (`scene::sphereflake(3, 3)`)
//! or `bunny`. `STRAHL_THREADS=t` (t > 1) also times `Builder::build_into_par` on `t`
//! threads right after each builder's single-threaded builds (taking turns with them), with its
//! speed-up; "CPU" is then the calling thread's only. `STRAHL_CUSTOM=bins,axes,sample[,hybrid[,cluster]]`
//! adds a member `custom`: `balanced()` (or `hybrid_sah()` with `hybrid`) with those bins, axes
//! (`all`, `longest`, `allbutsmall`), `bin_sample` and cluster size, for trying points between
//! the presets.
//!
//! `far_outlier` (ignored too): the Morton builders' trees and trace times beside one far
//! outlier.

use std::time::Instant;
use strahl::build::{
    BinAxes, BuildParams, Builder, Bvh2, MortonBits, MortonCells, Refine, ReinsertParams, Strategy, TreeletParams,
};
use strahl::scene;

mod common;

#[test]
#[ignore]
fn speed() {
    let env = |k: &str| std::env::var(k).ok();
    let n: usize = env("STRAHL_N").and_then(|s| s.parse().ok()).unwrap_or(1 << 20);
    let reps: usize = env("STRAHL_REPS").and_then(|s| s.parse().ok()).unwrap_or(5).max(1);
    let only = env("STRAHL_ONLY");
    let threads: usize = env("STRAHL_THREADS").and_then(|s| s.parse().ok()).unwrap_or(1);
    let soup = match env("STRAHL_SCENE").as_deref() {
        None | Some("soup") => scene::thin_soup(n, 1),
        Some("terrain") => scene::terrain(724, 1).to_soup(),
        Some("sphereflake") => scene::sphereflake(3, 3).to_soup(),
        Some("bunny") => scene::bunny().to_soup(),
        Some(other) => panic!("unknown STRAHL_SCENE {other}"),
    };
    let n = soup.len();
    let normalized = |p: BuildParams| BuildParams {
        morton_cells: MortonCells::Normalized,
        ..p
    };
    let list = [
        ("fastest", BuildParams::fastest()),
        (
            "lbvh63",
            BuildParams {
                morton_bits: MortonBits::Bits63,
                ..BuildParams::fastest()
            },
        ),
        ("fast", BuildParams::fast()),
        (
            "fast_exact",
            BuildParams {
                bin_sample: 0,
                ..BuildParams::fast()
            },
        ),
        (
            "balanced_exact",
            BuildParams {
                bin_sample: 0,
                ..BuildParams::balanced()
            },
        ),
        ("ploc", BuildParams::ploc()),
        (
            "ploc63",
            BuildParams {
                morton_bits: MortonBits::Bits63,
                ..BuildParams::ploc()
            },
        ),
        (
            "binned8all",
            BuildParams {
                bin_axes: BinAxes::All,
                ..BuildParams::fast()
            },
        ),
        ("balanced", BuildParams::balanced()),
        ("high", BuildParams::high()),
        ("hybrid_sah", BuildParams::hybrid_sah()),
        (
            "fast_treelets",
            BuildParams {
                refine: Refine::Treelets(TreeletParams::new()),
                ..BuildParams::fast()
            },
        ),
        (
            "fast_atrbvh",
            BuildParams {
                refine: Refine::AgglomerativeTreelets(TreeletParams::agglomerative()),
                ..BuildParams::fast()
            },
        ),
        (
            "fastest_atrbvh",
            BuildParams {
                refine: Refine::AgglomerativeTreelets(TreeletParams::agglomerative()),
                ..BuildParams::fastest()
            },
        ),
        (
            "balanced_reinsert",
            BuildParams {
                refine: Refine::Reinsertion(ReinsertParams::new()),
                ..BuildParams::balanced()
            },
        ),
        (
            "high_reinsert",
            BuildParams {
                refine: Refine::Reinsertion(ReinsertParams::new()),
                ..BuildParams::high()
            },
        ),
        (
            "fastest_reinsert",
            BuildParams {
                refine: Refine::Reinsertion(ReinsertParams::new()),
                ..BuildParams::fastest()
            },
        ),
        ("fastest_normalized", normalized(BuildParams::fastest())),
        ("ploc_normalized", normalized(BuildParams::ploc())),
        ("hybrid_sah_normalized", normalized(BuildParams::hybrid_sah())),
        ("median", BuildParams::median()),
        ("quality", BuildParams::quality()),
        (
            "hlbvh",
            BuildParams {
                strategy: Strategy::Hlbvh,
                max_leaf_size: 4,
                ..BuildParams::fastest()
            },
        ),
    ];
    // `STRAHL_CUSTOM=bins,axes,sample` (axes: all, longest, allbutsmall): one more binned-SAH
    // member, `custom`, for trying a point between the presets.
    let custom = env("STRAHL_CUSTOM").map(|c| {
        let f: Vec<&str> = c.split(',').collect();
        let axes = match f.get(1).copied() {
            Some("longest") => BinAxes::Longest,
            Some("allbutsmall") => BinAxes::AllButSmall,
            _ => BinAxes::All,
        };
        let bins = f.first().and_then(|s| s.parse().ok()).unwrap_or(16);
        let bin_sample = f.get(2).and_then(|s| s.parse().ok()).unwrap_or(0);
        let base = if f.get(3) == Some(&"hybrid") {
            BuildParams::hybrid_sah()
        } else {
            BuildParams::balanced()
        };
        let cluster_size = f.get(4).and_then(|s| s.parse().ok()).unwrap_or(base.cluster_size);
        (
            "custom",
            BuildParams {
                bins,
                bin_axes: axes,
                bin_sample,
                cluster_size,
                ..base
            },
        )
    });
    for (name, p) in list.iter().chain(custom.iter()) {
        if only.as_ref().is_some_and(|o| !o.split(',').any(|x| x == *name)) {
            continue;
        }
        let mut b = Builder::new();
        let mut bvh = Bvh2::default();
        b.build_into(&soup[..], p, &mut bvh).unwrap();
        let mut times = Vec::new();
        let mut par_times = Vec::new();
        let mut cpu = 0.0;
        for _ in 0..reps {
            let cpu0 = cpu_seconds();
            let t0 = Instant::now();
            b.build_into(&soup[..], p, &mut bvh).unwrap();
            times.push(t0.elapsed().as_secs_f64());
            cpu += cpu_seconds().zip(cpu0).map_or(f64::NAN, |(a, b)| a - b) / reps as f64;
            if threads > 1 {
                let mut par = Bvh2::default();
                b.build_into_par(&soup[..], p, &mut par, threads).unwrap();
                let t0 = Instant::now();
                b.build_into_par(&soup[..], p, &mut par, threads).unwrap();
                par_times.push(t0.elapsed().as_secs_f64());
                assert_eq!(
                    par.sah_cost(1.0, 1.0),
                    bvh.sah_cost(1.0, 1.0),
                    "{name}: parallel tree differs"
                );
            }
        }
        times.sort_by(f64::total_cmp);
        par_times.sort_by(f64::total_cmp);
        if let (Some(&best), Some(&med)) = (par_times.first(), par_times.get(par_times.len() / 2)) {
            println!(
                "{name:21} {threads} threads: best {:6.2} Mtri/s ({:7.2} ms, median {:7.2} ms): {:.2}x the best single-threaded",
                n as f64 / best / 1e6,
                best * 1e3,
                med * 1e3,
                times[0] / best
            );
        }
        let v = bvh.validate(&soup[..]).unwrap();
        println!(
            "{name:21} best {:6.2} Mtri/s ({:7.2} ms, median {:7.2} ms, CPU {:7.2} ms)  SAH {:8.3}  nodes {}  depth {}",
            n as f64 / times[0] / 1e6,
            times[0] * 1e3,
            times[times.len() / 2] * 1e3,
            cpu * 1e3,
            bvh.sah_cost(1.0, 1.0),
            bvh.nodes.len(),
            v.max_depth
        );
    }
}

/// The Morton builders beside a far outlier (`cargo test --release --test build_speed -- --ignored
/// --nocapture far_outlier`): for each builder, the build of 100,000 small triangles in the unit
/// cube without and with one triangle 10^7 away (`common::cube_and_far_outlier`), the SAH cost
/// of the cube's part of the tree (nodes inside `[0, 2]^3`, over that box's area), and the time
/// of 100,000 closest-hit rays into the cube through the BVH8 (each ray once, one thread).
#[test]
#[ignore]
fn far_outlier() {
    use strahl::layout::Bvh8;
    use strahl::traverse::Watertight;
    use strahl::{Aabb, Ray, Vec3};
    let with = common::cube_and_far_outlier(13);
    let without = &with[..100_000];
    let mut r = scene::Rng::new(14);
    let rays: Vec<Ray> = (0..100_000)
        .map(|_| {
            let o = Vec3::new(r.f32(), r.f32(), r.f32()) * 3.0 - 1.0;
            Ray::new(o, Vec3::new(r.f32(), r.f32(), r.f32()) - o)
        })
        .collect();
    let cube = Aabb::new(Vec3::ZERO, Vec3::splat(2.0));
    let cube_cost = |b: &Bvh2| -> f64 {
        b.nodes
            .iter()
            .filter(|n| n.aabb().max.max_element() <= 2.0)
            .map(|n| {
                n.aabb().half_area() as f64 / cube.half_area() as f64 * if n.is_leaf() { n.count as f64 } else { 1.0 }
            })
            .sum()
    };
    let b63 = |p: BuildParams| BuildParams {
        morton_bits: MortonBits::Bits63,
        ..p
    };
    for (name, p) in [
        ("fastest", BuildParams::fastest()),
        ("lbvh63", b63(BuildParams::fastest())),
        ("ploc", BuildParams::ploc()),
        ("ploc63", b63(BuildParams::ploc())),
        ("hybrid", BuildParams::hybrid()),
        ("hybrid_sah", BuildParams::hybrid_sah()),
        ("fast", BuildParams::fast()),
    ] {
        for (label, tris) in [("without", without), ("with", &with[..])] {
            let t0 = Instant::now();
            let (b2, _) = Bvh2::build(tris, &p).unwrap();
            let build = t0.elapsed().as_secs_f64();
            let b8 = Bvh8::from_bvh2(&b2, tris).unwrap();
            let t0 = Instant::now();
            let hits = rays
                .iter()
                .filter(|ray| b8.intersect::<Watertight>(ray).is_some())
                .count();
            let trace = t0.elapsed().as_secs_f64();
            println!(
                "{name:11} {label:7} the outlier: build {:7.1} ms, cube's cost {:8.1}, 100k rays {:8.1} ms ({hits} hits)",
                build * 1e3,
                cube_cost(&b2),
                trace * 1e3
            );
        }
    }
}

/// CPU time of this thread (user + system), from `/proc/thread-self/stat` (Linux; 10 ms ticks):
/// unlike wall-clock time, it leaves out the time the thread waits for a core on a loaded machine.
fn cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    // Fields after the command name (which may hold spaces): state is field 3, utime 14, stime 15.
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
