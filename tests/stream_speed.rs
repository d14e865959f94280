//! Any-hit batches by tree size (ignored: run by hand):
//! `cargo test --release --test stream_speed -- --ignored --nocapture`. The bench's shadow rays
//! (`benches/common`, 131,072 from surface points to random points in the box) through the BVH8
//! of `BuildParams::default()` on sphereflakes of 3k to 1M triangles and the bunny, three ways:
//! one `occluded` per ray, `occluded_batch_incoherent` and `occluded_batch_stream` (64 rays
//! walking together); best of 5 rounds taking turns. `occluded_batch_incoherent` was two walks
//! interleaved; it is now the single walk ray by ray (its column, "incoherent", measures the same
//! walk again: the spread between the two is the noise); the streams won on small trees on an Intel Xeon and lost on every tree on an AMD EPYC
//! (Zen 1), so `wide::occluded_batch` walks scattered rays one at a time.

#[path = "../benches/common/mod.rs"]
mod common;
use std::hint::black_box;
use std::time::Instant;
use strahl::build::{BuildParams, Bvh2};
use strahl::layout::Bvh8;
use strahl::traverse::{Moller, wide};

#[test]
#[ignore]
fn by_size() {
    let scenes = [
        ("bunny", strahl::scene::bunny().to_soup()),
        ("sphereflake(1,2)", strahl::scene::sphereflake(1, 2).to_soup()),
        ("sphereflake(1,3)", strahl::scene::sphereflake(1, 3).to_soup()),
        ("sphereflake(2,2)", strahl::scene::sphereflake(2, 2).to_soup()),
        ("sphereflake(2,3)", strahl::scene::sphereflake(2, 3).to_soup()),
        ("sphereflake(3,2)", strahl::scene::sphereflake(3, 2).to_soup()),
        ("sphereflake(3,3)", strahl::scene::sphereflake(3, 3).to_soup()),
    ];
    for (name, tris) in scenes {
        let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
        let b = common::bounds(&tris);
        let rays = common::shadow_rays(&tris, &b, 1 << 17, (b.max - b.min).length());
        let mut out = vec![false; rays.len()];
        let mut best = [f64::INFINITY; 3];
        let mut answers = [0usize; 3];
        for _ in 0..5 {
            for (k, t) in best.iter_mut().enumerate() {
                let start = Instant::now();
                match k {
                    0 => {
                        for (o, r) in out.iter_mut().zip(black_box(&rays)) {
                            *o = b8.occluded::<Moller>(r);
                        }
                    }
                    1 => wide::occluded_batch_incoherent::<Moller, _, 8>(b8.view(), black_box(&rays), &mut out),
                    _ => wide::occluded_batch_stream::<Moller, _, 8>(b8.view(), black_box(&rays), &mut out),
                }
                *t = t.min(start.elapsed().as_secs_f64() * 1e3);
                answers[k] = out.iter().filter(|&&o| o).count();
            }
        }
        assert!(answers.iter().all(|&a| a == answers[0]), "{name}: {answers:?}");
        println!(
            "{name:18} {:>8} tris, tree {:>9} bytes: single {:7.2} ms, incoherent {:7.2} ms ({:.2}x), stream {:7.2} ms ({:.2}x)",
            tris.len(),
            b8.memory_bytes(),
            best[0],
            best[1],
            best[0] / best[1],
            best[2],
            best[0] / best[2]
        );
    }
}
