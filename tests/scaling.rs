//! Thread-scaling harness (ignored: run by hand): the parallel builders, the parallel BVH8
//! collapse and the parallel ray batches on 1, 2, 4, ... threads, each checked against its
//! single-threaded result.
//!
//! `STRAHL_THREADS_LIST=1,2,4,8,16 cargo test --release --test scaling -- --ignored --nocapture`
//! prints one markdown table per scene (`STRAHL_SCENE`: `soup`, the 1M thin soup (default), or
//! `sphereflake`, 1M triangles; `all` for both): best of `STRAHL_REPS` (default 3) wall-clock
//! milliseconds and the speed-up over one thread, for `Builder::build_into_par` with `fastest()`,
//! `fast()`, `balanced()`, `high()`, `hybrid_sah()` and `median()` (warm builder), `Bvh8::from_bvh2_par` of the
//! `balanced()` tree, and `intersect_batch_par` / `occluded_batch_par` of the BVH8 over 262,144 diffuse
//! rays (closest hit) and 262,144 shadow rays (any hit, towards random points in the scene's box),
//! watertight triangle test. The thread counts take turns within each repetition.

#[path = "../benches/common/mod.rs"]
mod common;
use std::time::Instant;
use strahl::build::{BuildParams, Builder, Bvh2};
use strahl::geometry::Triangle;
use strahl::layout::Bvh8;
use strahl::scene::{self, Rng};
use strahl::traverse::Watertight;
use strahl::{Ray, Vec3};

fn env(k: &str) -> Option<String> {
    std::env::var(k).ok()
}

fn shadow_rays(tris: &[Triangle], n: usize) -> Vec<Ray> {
    let b = common::bounds(tris);
    let mut rng = Rng::new(11);
    let scale = (b.max - b.min).length();
    common::surface_points(tris, n, &mut rng)
        .into_iter()
        .map(|(p, nrm)| {
            let q = b.min + (b.max - b.min) * Vec3::new(rng.f32(), rng.f32(), rng.f32());
            let o = p + nrm * scale * 1e-5;
            let d = q - o;
            Ray::with_range(o, d, 0.0, 1.0)
        })
        .collect()
}

#[test]
#[ignore]
fn scaling() {
    let reps: usize = env("STRAHL_REPS").and_then(|s| s.parse().ok()).unwrap_or(3).max(1);
    let list: Vec<usize> = env("STRAHL_THREADS_LIST")
        .unwrap_or_else(|| "1,2".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .filter(|&t| t > 0)
        .collect();
    assert!(!list.is_empty(), "STRAHL_THREADS_LIST names no thread count");
    let scenes: Vec<&str> = match env("STRAHL_SCENE").as_deref() {
        None | Some("soup") => vec!["soup"],
        Some("sphereflake") => vec!["sphereflake"],
        Some("all") => vec!["soup", "sphereflake"],
        Some(other) => panic!("unknown STRAHL_SCENE {other}"),
    };
    for name in scenes {
        let tris = match name {
            "soup" => scene::thin_soup(1 << 20, 1),
            _ => scene::sphereflake(3, 3).to_soup(),
        };
        run_scene(name, &tris, &list, reps);
    }
}

fn run_scene(name: &str, tris: &[Triangle], list: &[usize], reps: usize) {
    let n = tris.len();
    let rays_n = 1 << 18;
    let b = common::bounds(tris);
    let diffuse = common::diffuse_rays(tris, rays_n, (b.max - b.min).length());
    let shadow = shadow_rays(tris, rays_n);
    // Rows: (label, per-thread-count best seconds).
    let builders = [
        ("build `fastest()`", BuildParams::fastest()),
        ("build `fast()`", BuildParams::fast()),
        ("build `balanced()`", BuildParams::balanced()),
        ("build `high()`", BuildParams::high()),
        ("build `hybrid_sah()`", BuildParams::hybrid_sah()),
        ("build `median()`", BuildParams::median()),
    ];
    let mut rows: Vec<(String, Vec<f64>)> = Vec::new();
    for (label, p) in &builders {
        let mut b = Builder::new();
        let mut reference = Bvh2::default();
        b.build_into(tris, p, &mut reference).unwrap();
        let mut outs: Vec<Bvh2> = list.iter().map(|_| Bvh2::default()).collect();
        let mut best = vec![f64::INFINITY; list.len()];
        for (i, &t) in list.iter().enumerate() {
            b.build_into_par(tris, p, &mut outs[i], t).unwrap(); // warm-up, pages touched
        }
        for _ in 0..reps {
            for (i, &t) in list.iter().enumerate() {
                let s = Instant::now();
                b.build_into_par(tris, p, &mut outs[i], t).unwrap();
                best[i] = best[i].min(s.elapsed().as_secs_f64());
            }
        }
        for (o, &t) in outs.iter().zip(list) {
            assert_eq!(
                o.sah_cost(1.0, 1.0),
                reference.sah_cost(1.0, 1.0),
                "{label} on {t} threads differs"
            );
            assert_eq!(o.nodes.len(), reference.nodes.len(), "{label} on {t} threads differs");
        }
        rows.push((label.to_string(), best));
        eprintln!("{name}: {label} done");
    }
    let (bvh2, _) = Bvh2::build(tris, &BuildParams::balanced()).unwrap();
    let reference = Bvh8::from_bvh2(&bvh2, tris).unwrap();
    let mut best = vec![f64::INFINITY; list.len()];
    for _ in 0..reps {
        for (i, &t) in list.iter().enumerate() {
            let s = Instant::now();
            let w = Bvh8::from_bvh2_par(&bvh2, tris, t).unwrap();
            best[i] = best[i].min(s.elapsed().as_secs_f64());
            assert_eq!(
                (w.nodes().len(), w.packs().len()),
                (reference.nodes().len(), reference.packs().len()),
                "collapse on {t} threads differs"
            );
        }
    }
    rows.push(("BVH8 collapse of `balanced()`".into(), best));
    eprintln!("{name}: collapse done");
    let bvh8 = reference;
    let mut want_hits = vec![None; diffuse.len()];
    bvh8.intersect_batch::<Watertight>(&diffuse, &mut want_hits);
    let mut want_occ = vec![false; shadow.len()];
    bvh8.occluded_batch::<Watertight>(&shadow, &mut want_occ);
    let mut hits = vec![None; diffuse.len()];
    let mut occ = vec![false; shadow.len()];
    let mut best_i = vec![f64::INFINITY; list.len()];
    let mut best_o = vec![f64::INFINITY; list.len()];
    for _ in 0..reps {
        for (i, &t) in list.iter().enumerate() {
            hits.fill(None);
            let s = Instant::now();
            bvh8.intersect_batch_par::<Watertight>(&diffuse, &mut hits, t);
            best_i[i] = best_i[i].min(s.elapsed().as_secs_f64());
            assert!(hits == want_hits, "closest hits on {t} threads differ");
            occ.fill(false);
            let s = Instant::now();
            bvh8.occluded_batch_par::<Watertight>(&shadow, &mut occ, t);
            best_o[i] = best_o[i].min(s.elapsed().as_secs_f64());
            assert!(occ == want_occ, "any-hit answers on {t} threads differ");
        }
    }
    let hit = want_hits.iter().filter(|h| h.is_some()).count();
    let blocked = want_occ.iter().filter(|&&o| o).count();
    rows.push((format!("262,144 diffuse rays, closest hit ({hit} hits)"), best_i));
    rows.push((format!("262,144 shadow rays, any hit ({blocked} blocked)"), best_o));

    println!(
        "\n{name}, {n} triangles, {} available cores; best of {reps}, ms (speed-up over 1 thread):\n",
        std::thread::available_parallelism().map_or(0, |c| c.get())
    );
    let head: Vec<String> = list
        .iter()
        .map(|&t| {
            if t == 1 {
                "1 thread".to_string()
            } else {
                format!("{t} threads")
            }
        })
        .collect();
    println!("| | {} |", head.join(" | "));
    println!("|---|{}", "---|".repeat(list.len()));
    for (label, best) in &rows {
        let one = list.iter().position(|&t| t == 1).map(|i| best[i]);
        let cells: Vec<String> = best
            .iter()
            .map(|&b| match one {
                Some(o) => format!("{:.1} ({:.2}x)", b * 1e3, o / b),
                None => format!("{:.1}", b * 1e3),
            })
            .collect();
        println!("| {label} | {} |", cells.join(" | "));
    }
}
