//! Collapse harness (ignored: run by hand): the greedy and the cost-optimal BVH2 -> BVH8
//! collapse of the same binary tree (`BuildParams::default()`), traced on the same rays.
//!
//! `cargo test --release --test collapse_speed -- --ignored --nocapture`: the bunny and a
//! 262k-triangle sphereflake; 1024 x 1024 primary rays (4 x 2 tiles, as `benches/trace.rs`) and
//! 131,072 diffuse rays from surface points, closest hit and any hit, Möller-Trumbore. The trees
//! take turns for `STRAHL_ROUNDS` rounds (default 6) and each keeps its best time.

#[path = "../benches/common/mod.rs"]
mod common;
use std::hint::black_box;
use std::time::Instant;
use strahl::build::{BuildParams, Bvh2};
use strahl::layout::{Bvh8, EMPTY_CHILD};
use strahl::traverse::Moller;
use strahl::traverse::packet::TileShape;

fn ms(mut f: impl FnMut()) -> f64 {
    let s = Instant::now();
    f();
    s.elapsed().as_secs_f64() * 1e3
}

#[test]
#[ignore]
fn speed() {
    let rounds: usize = std::env::var("STRAHL_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(6);
    for big in [false, true] {
        let (name, tris) = if big {
            ("sphereflake 262k", strahl::scene::sphereflake(3, 2).to_soup())
        } else {
            ("bunny", strahl::scene::bunny().to_soup())
        };
        let b = common::bounds(&tris);
        let primary = common::primary_rays(&b, 1024, 1024, TileShape::X4_2);
        let diffuse = common::diffuse_rays(&tris, 1 << 17, (b.max - b.min).length());
        let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        let trees = [
            ("greedy", Bvh8::from_bvh2_greedy(&b2, &tris[..]).unwrap()),
            ("optimal", Bvh8::from_bvh2(&b2, &tris[..]).unwrap()),
        ];
        let mut hits = vec![None; primary.len().max(diffuse.len())];
        let mut occ = vec![false; diffuse.len()];
        let mut best = [[f64::INFINITY; 3]; 2];
        for _ in 0..rounds {
            for ((_, t), b) in trees.iter().zip(best.iter_mut()) {
                b[0] = b[0].min(ms(|| t.intersect_batch::<Moller>(black_box(&primary), &mut hits)));
                b[1] = b[1].min(ms(|| t.intersect_batch::<Moller>(black_box(&diffuse), &mut hits)));
                b[2] = b[2].min(ms(|| t.occluded_batch::<Moller>(black_box(&diffuse), &mut occ)));
            }
        }
        for ((label, t), b) in trees.iter().zip(&best) {
            let kids: usize = t
                .nodes()
                .iter()
                .map(|n| n.child.iter().filter(|&&c| c != EMPTY_CHILD).count())
                .sum();
            let full: usize = t.packs().iter().map(|p| p.valid.count_ones() as usize).sum();
            println!(
                "{name:16} {label:7}: {:6} nodes ({:.2} children each), {:6} packs ({:.2} triangles each); \
                 best ms: primary {:7.2}, diffuse {:7.2}, diffuse any hit {:7.2}",
                t.nodes().len(),
                kids as f64 / t.nodes().len() as f64,
                t.packs().len(),
                full as f64 / t.packs().len() as f64,
                b[0],
                b[1],
                b[2]
            );
        }
    }
}
