//! Packet tracing, single thread: packets of 4, 8 and 16 rays over BVH2 and BVH8, the single-ray
//! hybrid, against single-ray BVH8 traversal and (with `--features embree`) Embree 3's
//! `rtcIntersect8` / `rtcIntersect16`, in one group per scene and ray kind so that the ratios come
//! from one run.
//!
//! Rays: `primary` (a 512 x 512 pinhole camera, closest hit, laid out tile by tile so that each
//! packet is a coherent 2 x 2, 4 x 2 or 4 x 4 pixel block: [`TileShape`]), `diffuse` (cosine-like
//! directions from random surface points, closest hit: incoherent packets). Scenes: the bundled
//! bunny and a 262k-triangle sphereflake. Every strahl member uses the same Möller-Trumbore test
//! and must find exactly the same hits as single rays; Embree (its own triangle test) within 0.1%.
//!
//! Members: `bvh8_single` (the reference), `packetK_bvh2`, `packetK_bvh8` (pure packets, switch 0),
//! `hybridK_bvh8` (the default switch, [`packet::default_switch`]) and, for diffuse rays,
//! `hybridK_bvh8_half` (switch K / 2: some packet traversal near the root); with a hit filter
//! that accepts every hit, `bvh8_single_filter_all` and `hybrid8_bvh8_filter_all`
//! ([`packet::intersect_packet_filtered`]).
//!
//! `cargo bench --bench packet -- --noplot` (add `--features embree` for Embree).

#[path = "common/mod.rs"]
mod common;
#[path = "peers/mod.rs"]
mod peers;

use common::{bounds, diffuse_rays, primary_rays};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use strahl::Ray;
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::{Hit, Triangle};
use strahl::layout::Bvh8;
use strahl::math::{f32x4, f32x8};
use strahl::scene;
use strahl::traverse::Moller;
use strahl::traverse::packet::{self, TileShape, f32x16};

struct Contenders {
    tris: Vec<Triangle>,
    bvh2: Bvh2,
    bvh8: Bvh8,
}

fn count(hits: &[Option<Hit>]) -> usize {
    hits.iter().filter(|h| h.is_some()).count()
}

// ---- the contenders: each returns a hit count so that nothing is optimised away ----

type Run = Box<dyn Fn(&Contenders, &[Ray], &mut [Option<Hit>]) -> usize>;

fn single_bvh8() -> Run {
    Box::new(|c, rays, _| rays.iter().filter(|r| c.bvh8.intersect::<Moller>(r).is_some()).count())
}

fn packets_bvh8(k: usize, switch: u32) -> Run {
    Box::new(move |c, rays, hits| {
        let v = c.bvh8.view();
        match k {
            4 => packet::intersect_batch_packets::<Moller, _, 8, f32x4, 4>(v, rays, hits, switch),
            8 => packet::intersect_batch_packets::<Moller, _, 8, f32x8, 8>(v, rays, hits, switch),
            _ => packet::intersect_batch_packets::<Moller, _, 8, f32x16, 16>(v, rays, hits, switch),
        }
        count(&hits[..rays.len()])
    })
}

/// Single rays through the filtered walk, with a filter that accepts every hit: what a hit filter
/// costs where it rejects nothing.
fn single_bvh8_filter_all() -> Run {
    Box::new(|c, rays, _| {
        rays.iter()
            .filter(|r| c.bvh8.intersect_filtered::<Moller>(r, |_: &Hit| true).is_some())
            .count()
    })
}

/// Packets of 8 through the filtered packet walk (`intersect_packet_filtered`), accepting every
/// hit: leaves lane by lane with the filtered single-ray kernels.
fn packets8_bvh8_filter_all(switch: u32) -> Run {
    Box::new(move |c, rays, hits| {
        for (r, h) in rays.chunks(8).zip(hits.chunks_mut(8)) {
            packet::intersect_packet_filtered::<Moller, _, 8, f32x8, 8>(c.bvh8.view(), r, h, switch, |_: &Hit| true);
        }
        count(&hits[..rays.len()])
    })
}

fn packets_bvh2(k: usize) -> Run {
    Box::new(move |c, rays, hits| {
        let (v, t) = (c.bvh2.view(), &c.tris[..]);
        match k {
            4 => packet::intersect_batch_bvh2::<Moller, _, f32x4, 4>(v, t, rays, hits),
            8 => packet::intersect_batch_bvh2::<Moller, _, f32x8, 8>(v, t, rays, hits),
            _ => packet::intersect_batch_bvh2::<Moller, _, f32x16, 16>(v, t, rays, hits),
        }
        count(&hits[..rays.len()])
    })
}

fn bench_scene(cr: &mut Criterion, name: &str, tris: Vec<Triangle>) {
    println!("\n== scene {name}: {} triangles", tris.len());
    let (bvh2, _) = Bvh2::build(&tris[..], &BuildParams::default()).expect("build");
    let bvh8 = Bvh8::from_bvh2(&bvh2, &tris[..]).expect("collapse");
    let c = Contenders { tris, bvh2, bvh8 };
    let b = bounds(&c.tris);
    let scale = (b.max - b.min).length();
    let (w, h) = (512, 512);
    #[cfg(feature = "embree")]
    let device = peers::embree::Device::single_threaded();
    #[cfg(feature = "embree")]
    let embree = peers::embree::Scene::new(&device, &c.tris, peers::embree::Quality::Medium);

    for kind in ["primary", "diffuse"] {
        // Rays in the order each packet size wants (primary: tiles of 2 x 2, 4 x 2, 4 x 4).
        let rays_for = |k: usize| match kind {
            "primary" => primary_rays(&b, w, h, TileShape::for_rays(k)),
            _ => diffuse_rays(&c.tris, 1 << 17, scale),
        };
        let rays: [Vec<Ray>; 3] = [rays_for(4), rays_for(8), rays_for(16)];
        let by_k = |k: usize| &rays[k.trailing_zeros() as usize - 2];
        let mut members: Vec<(String, usize, Run)> = vec![
            ("bvh8_single".into(), 8, single_bvh8()),
            ("bvh8_single_filter_all".into(), 8, single_bvh8_filter_all()),
            (
                "hybrid8_bvh8_filter_all".into(),
                8,
                packets8_bvh8_filter_all(packet::DEFAULT_SWITCH),
            ),
        ];
        for k in [4, 8, 16] {
            members.push((format!("packet{k}_bvh2"), k, packets_bvh2(k)));
            members.push((format!("packet{k}_bvh8"), k, packets_bvh8(k, 0)));
            members.push((format!("hybrid{k}_bvh8"), k, packets_bvh8(k, packet::default_switch(k))));
            if kind == "diffuse" {
                members.push((format!("hybrid{k}_bvh8_half"), k, packets_bvh8(k, k as u32 / 2)));
            }
        }
        // The same answers before timing: every strahl member exactly as many hits as single rays.
        let mut hits = vec![None; by_k(16).len()];
        let reference = members[0].2(&c, by_k(8), &mut hits);
        for (m, k, f) in &members[1..] {
            let got = f(&c, by_k(*k), &mut hits);
            assert_eq!(got, reference, "{name}/{kind}: {m} hits {got}, single rays {reference}");
        }
        println!(
            "{name}/{kind}: {} rays, {} hit ({:.1}%)",
            by_k(8).len(),
            reference,
            reference as f64 * 100.0 / by_k(8).len() as f64
        );

        let mut g = cr.benchmark_group(format!("packet/{name}/{kind}"));
        g.sample_size(10);
        g.warm_up_time(std::time::Duration::from_millis(500));
        g.measurement_time(std::time::Duration::from_secs(3));
        // Throughput in rays of the image (edge tiles add no padding at 512 x 512).
        g.throughput(Throughput::Elements(by_k(8).len() as u64));
        for (m, k, f) in &members {
            let rays = by_k(*k);
            g.bench_function(m.as_str(), |bch| {
                bch.iter(|| f(black_box(&c), black_box(rays), &mut hits))
            });
        }
        #[cfg(feature = "embree")]
        {
            let e = &embree;
            let run8 = |rays: &[Ray]| -> usize {
                rays.chunks(8)
                    .map(|r| e.intersect8(r).iter().filter(|h| h.is_some()).count())
                    .sum()
            };
            let run16 = |rays: &[Ray]| -> usize {
                rays.chunks(16)
                    .map(|r| e.intersect16(r).iter().filter(|h| h.is_some()).count())
                    .sum()
            };
            let tol = by_k(8).len() / 1000 + 1;
            for (m, got) in [("rtcIntersect8", run8(by_k(8))), ("rtcIntersect16", run16(by_k(16)))] {
                assert!(
                    got.abs_diff(reference) <= tol,
                    "{name}/{kind}: embree {m} hits {got}, single rays {reference}"
                );
            }
            g.bench_function("embree_rtcIntersect8", |bch| bch.iter(|| run8(black_box(by_k(8)))));
            g.bench_function("embree_rtcIntersect16", |bch| bch.iter(|| run16(black_box(by_k(16)))));
        }
        g.finish();
    }
}

fn benches(c: &mut Criterion) {
    bench_scene(c, "bunny", scene::bunny().to_soup());
    // (9^4 - 1) / 8 spheres of 320 triangles: 262,400.
    bench_scene(c, "sphereflake_262k", scene::sphereflake(3, 2).to_soup());
}

criterion_group!(packet_benches, benches);
criterion_main!(packet_benches);
