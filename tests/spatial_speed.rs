//! Spatial-split harness (ignored: run by hand): [`Bvh2::build_spatial`] against the plain binned
//! and full-sweep builds of the same scenes, each collapsed to BVH8 and traced on the same rays.
//!
//! `cargo test --release --test spatial_speed -- --ignored --nocapture`: per scene, build time
//! (best of `STRAHL_REPS`, default 3), SAH cost (`C_T = C_I = 1`), references per triangle, and
//! the BVH8 trace times of 1024 x 1024 primary rays, 262,144 diffuse (closest hit) and 262,144
//! shadow rays (any hit), Möller-Trumbore; the trees take turns for `STRAHL_ROUNDS` rounds
//! (default 4), each keeping its best. `STRAHL_SCENES` picks scenes (comma-separated: `bunny`,
//! `soup` (`scene::thin_soup(262_144, 1)`), `sphereflake` (262k), `terrain` (262k)).
//! Members: `BuildParams::default()` (binned), `quality()` (full sweep), and `build_spatial` with
//! `default()`'s object bins and with 64; `STRAHL_SBINS`, `STRAHL_MIN_NODE` and `STRAHL_ALPHA`
//! set [`SpatialSplits`]' `bins`, `min_node_size` and `alpha` (defaults 16, 64, `1e-5`).

#[path = "../benches/common/mod.rs"]
mod common;
use std::hint::black_box;
use std::time::Instant;
use strahl::build::{BuildParams, Bvh2, SpatialSplits};
use strahl::geometry::Triangle;
use strahl::layout::Bvh8;
use strahl::traverse::Moller;
use strahl::traverse::packet::TileShape;

/// A named build of the scene.
type Build<'a> = Box<dyn Fn() -> Bvh2 + 'a>;

fn ms(mut f: impl FnMut()) -> f64 {
    let s = Instant::now();
    f();
    s.elapsed().as_secs_f64() * 1e3
}

fn env(k: &str, default: usize) -> usize {
    std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

#[test]
#[ignore]
fn speed() {
    let reps = env("STRAHL_REPS", 3).max(1);
    let rounds = env("STRAHL_ROUNDS", 4).max(1);
    let scenes = std::env::var("STRAHL_SCENES").unwrap_or_else(|_| "bunny,soup,sphereflake,terrain".into());
    for name in scenes.split(',') {
        let tris: Vec<Triangle> = match name {
            "bunny" => strahl::scene::bunny().to_soup(),
            "soup" => strahl::scene::thin_soup(1 << 18, 1),
            "sphereflake" => strahl::scene::sphereflake(3, 2).to_soup(),
            "terrain" => strahl::scene::terrain(362, 1).to_soup(),
            other => panic!("unknown scene {other}"),
        };
        let b = common::bounds(&tris);
        let scale = (b.max - b.min).length();
        let primary = common::primary_rays(&b, 1024, 1024, TileShape::X4_2);
        let diffuse = common::diffuse_rays(&tris, 1 << 18, scale);
        let shadow = common::shadow_rays(&tris, &b, 1 << 18, scale);
        let sp = SpatialSplits {
            bins: env("STRAHL_SBINS", 16) as u32,
            min_node_size: env("STRAHL_MIN_NODE", 64) as u32,
            alpha: std::env::var("STRAHL_ALPHA")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(1e-5),
            ..SpatialSplits::default()
        };
        let builds: [(&str, Build); 4] = [
            (
                "binned (default)",
                Box::new(|| Bvh2::build(&tris[..], &BuildParams::default()).unwrap().0),
            ),
            (
                "sweep (quality)",
                Box::new(|| Bvh2::build(&tris[..], &BuildParams::quality()).unwrap().0),
            ),
            (
                "spatial (default)",
                Box::new(|| Bvh2::build_spatial(&tris[..], &BuildParams::default(), &sp).unwrap().0),
            ),
            (
                "spatial (64 bins)",
                Box::new(|| {
                    Bvh2::build_spatial(
                        &tris[..],
                        &BuildParams {
                            bins: 64,
                            ..BuildParams::default()
                        },
                        &sp,
                    )
                    .unwrap()
                    .0
                }),
            ),
        ];
        println!("{name}: {} triangles", tris.len());
        let mut trees = Vec::new();
        for (label, build) in &builds {
            let mut tree = build();
            let mut best = f64::INFINITY;
            for _ in 0..reps {
                best = best.min(ms(|| tree = build()));
            }
            assert!(tree.validate_split(&tris[..]).is_ok(), "{label}");
            let b8 = Bvh8::from_bvh2(&tree, &tris[..]).unwrap();
            trees.push((label, best, tree, b8));
        }
        let mut hits = vec![None; primary.len().max(diffuse.len())];
        let mut occ = vec![false; shadow.len()];
        let mut times = vec![[f64::INFINITY; 3]; trees.len()];
        let mut counts = vec![[0usize; 3]; trees.len()];
        for _ in 0..rounds {
            for ((_, _, _, b8), (t, c)) in trees.iter().zip(times.iter_mut().zip(counts.iter_mut())) {
                t[0] = t[0].min(ms(|| b8.intersect_batch::<Moller>(black_box(&primary), &mut hits)));
                c[0] = hits[..primary.len()].iter().flatten().count();
                t[1] = t[1].min(ms(|| b8.intersect_batch::<Moller>(black_box(&diffuse), &mut hits)));
                c[1] = hits[..diffuse.len()].iter().flatten().count();
                t[2] = t[2].min(ms(|| b8.occluded_batch::<Moller>(black_box(&shadow), &mut occ)));
                c[2] = occ.iter().filter(|&&o| o).count();
            }
        }
        for ((label, build, tree, b8), (t, c)) in trees.iter().zip(times.iter().zip(&counts)) {
            println!(
                "  {label:18} build {build:8.1} ms  SAH {:8.3}  refs/tri {:.3}  BVH8 {:6.1} MB  primary {:6.1}  diffuse {:6.1}  shadow {:6.1} ms  (hits {} {} {})",
                tree.sah_cost(1.0, 1.0),
                tree.prim_indices.len() as f64 / tris.len() as f64,
                b8.memory_bytes() as f64 / 1e6,
                t[0],
                t[1],
                t[2],
                c[0],
                c[1],
                c[2]
            );
        }
    }
}
