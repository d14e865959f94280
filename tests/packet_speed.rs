//! Packet-speed harness (ignored: run by hand): single-ray BVH8, pure packets of 4/8/16 rays and
//! the default hybrids, on the bunny and a 262k-triangle sphereflake, primary (512 x 512 camera in
//! tiles) and diffuse rays, the same rays as `benches/packet.rs`.
//!
//! `cargo test --release --test packet_speed -- --ignored --nocapture`: the members take turns
//! for 8 rounds and each keeps its best time, which holds up better on a shared, noisy machine
//! than medians taken minutes apart (the criterion bench's ratios moved by 20% between runs here).

#[path = "../benches/common/mod.rs"]
mod common;
use std::hint::black_box;
use std::time::Instant;
use strahl::build::{BuildParams, Bvh2};
use strahl::layout::Bvh8;
use strahl::math::{f32x4, f32x8};
use strahl::traverse::Moller;
use strahl::traverse::packet::{self, TileShape, f32x16};

/// Best wall time of `reps` runs of `f`, in milliseconds.
fn min_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}
#[test]
#[ignore]
fn speed() {
    for big in [false, true] {
        speed_on(big);
    }
}

fn speed_on(big: bool) {
    let tris = if big {
        strahl::scene::sphereflake(3, 2).to_soup()
    } else {
        strahl::scene::bunny().to_soup()
    };
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let b = common::bounds(&tris);
    let diffuse = common::diffuse_rays(&tris, 1 << 17, (b.max - b.min).length());
    for kind in ["primary", "diffuse"] {
        let rays = |k: usize| {
            if kind == "primary" {
                common::primary_rays(&b, 512, 512, TileShape::for_rays(k))
            } else {
                diffuse.clone()
            }
        };
        let (r4, r8, r16) = (rays(4), rays(8), rays(16));
        let mut hits = vec![None; r16.len()];
        let mut t = [f64::INFINITY; 7];
        let reps = if big { 1 } else { 3 };
        for _ in 0..8 {
            t[0] = t[0].min(min_ms(reps, || b8.intersect_batch::<Moller>(black_box(&r8), &mut hits)));
            // Pure packets (switch 0) into t[1..4], the default hybrids into t[4..7].
            for (j, pure) in [true, false].into_iter().enumerate() {
                let sw = |k| if pure { 0 } else { packet::default_switch(k) };
                let t = &mut t[1 + 3 * j..4 + 3 * j];
                t[0] = t[0].min(min_ms(reps, || {
                    packet::intersect_batch_packets::<Moller, _, 8, f32x4, 4>(
                        b8.view(),
                        black_box(&r4),
                        &mut hits,
                        sw(4),
                    )
                }));
                t[1] = t[1].min(min_ms(reps, || {
                    packet::intersect_batch_packets::<Moller, _, 8, f32x8, 8>(
                        b8.view(),
                        black_box(&r8),
                        &mut hits,
                        sw(8),
                    )
                }));
                t[2] = t[2].min(min_ms(reps, || {
                    packet::intersect_batch_packets::<Moller, _, 8, f32x16, 16>(
                        b8.view(),
                        black_box(&r16),
                        &mut hits,
                        sw(16),
                    )
                }));
            }
        }
        let s = t[0];
        println!(
            "{} {kind}: single {s:.2} ms | packet4 {:.2}x packet8 {:.2}x packet16 {:.2}x | hybrid4 {:.2}x hybrid8 {:.2}x hybrid16 {:.2}x (speed vs single, best of 8 rounds)",
            if big { "sphereflake" } else { "bunny" },
            s / t[1],
            s / t[2],
            s / t[3],
            s / t[4],
            s / t[5],
            s / t[6]
        );
    }
}

/// 8-ray packets against Embree's `rtcIntersect8` (coherent flag) on the bunny's primary rays in
/// 4 x 2 tiles, split into the packets where some ray hits and those where none does, taking
/// turns, best of `STRAHL_REPS` (default 60) rounds.
///
/// `cargo test --release --features embree --test packet_speed -- --ignored --nocapture versus_embree`
/// (`STRAHL_RES=512` for the 512 x 512 camera; default 1024).
#[cfg(feature = "embree")]
#[test]
#[ignore]
fn versus_embree() {
    #[path = "../benches/peers/mod.rs"]
    mod peers;
    let tris = strahl::scene::bunny().to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let b = common::bounds(&tris);
    let res: u32 = std::env::var("STRAHL_RES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1024);
    let reps: usize = std::env::var("STRAHL_REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let all = common::primary_rays(&b, res, res, TileShape::for_rays(8));
    let device = peers::embree::Device::single_threaded();
    let scene = peers::embree::Scene::new(&device, &tris, peers::embree::Quality::Medium);
    let single: Vec<_> = all.iter().map(|r| b8.intersect::<Moller>(r)).collect();
    let (mut hit, mut miss) = (Vec::new(), Vec::new());
    for (c, h) in all.chunks(8).zip(single.chunks(8)) {
        if h.iter().any(Option::is_some) {
            &mut hit
        } else {
            &mut miss
        }
        .extend_from_slice(c);
    }
    let ours = |rays: &[strahl::Ray]| {
        let mut hits = [None; 8];
        let mut n = 0;
        for r in rays.chunks(8) {
            packet::intersect8::<Moller, _, 8>(b8.view(), r, &mut hits, 0);
            n += hits[..r.len()].iter().filter(|h| h.is_some()).count();
        }
        n
    };
    let embree = |rays: &[strahl::Ray]| {
        rays.chunks(8)
            .map(|r| scene.intersect8(r)[..r.len()].iter().filter(|h| h.is_some()).count())
            .sum::<usize>()
    };
    let bvh8 = |rays: &[strahl::Ray]| rays.iter().filter(|r| b8.intersect::<Moller>(r).is_some()).count();
    let only = std::env::var("STRAHL_ONLY").unwrap_or_default();
    for (name, rays) in [("all", &all), ("hit", &hit), ("miss", &miss)] {
        if only == "ours_hit" {
            // For a profiler: only strahl's packets, only the packets with a hit.
            if name == "hit" {
                for _ in 0..reps {
                    black_box(ours(black_box(rays)));
                }
            }
            continue;
        }
        let n = ours(rays);
        assert!(n.abs_diff(embree(rays)) <= rays.len() / 1000 + 1);
        assert_eq!(n, bvh8(rays));
        let mut t = [f64::INFINITY; 3];
        for _ in 0..reps {
            t[0] = t[0].min(min_ms(1, || _ = black_box(ours(black_box(rays)))));
            t[1] = t[1].min(min_ms(1, || _ = black_box(embree(black_box(rays)))));
            t[2] = t[2].min(min_ms(1, || _ = black_box(bvh8(black_box(rays)))));
        }
        println!(
            "bunny {res}x{res} {name} ({} packets): packet8 {:.2} ms, Embree rtcIntersect8 {:.2} ms, single BVH8 {:.2} ms: packet8 / Embree {:.2}x",
            rays.len() / 8,
            t[0],
            t[1],
            t[2],
            t[1] / t[0]
        );
    }
}
