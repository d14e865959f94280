//! Saving and loading wide BVHs (`layout::bytes`), single thread, in one group per scene: making
//! the BVH8 from scratch (the `balanced()` build and the collapse, what a load replaces) against
//! reading saved bytes back, copied and checked in full (`Bvh8::from_bytes`) or in place
//! (`Bvh8Ref::from_bytes`: header, length and checksum; `Bvh8Ref::check`, the structure, timed on
//! its own), and against writing them (`Bvh8::to_bytes`). Each load is checked to answer as the
//! built tree on a few hundred rays before timing.
//!
//! `cargo bench --bench bytes -- --noplot`

#[path = "common/mod.rs"]
mod common;

use common::{bounds, diffuse_rays};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use strahl::build::{BuildParams, Builder, Bvh2};
use strahl::geometry::Triangle;
use strahl::layout::{Bvh8, Bvh8Ref, Collapser};
use strahl::scene;
use strahl::traverse::Moller;

/// 64-byte blocks: the aligned buffer an in-place read needs (a memory map gives one too).
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(64))]
struct Block([u8; 64]);

fn group(c: &mut Criterion, name: &str, tris: &[Triangle]) {
    let p = BuildParams::balanced();
    let (b2, _) = Bvh2::build(tris, &p).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, tris).unwrap();
    let bytes = b8.to_bytes();
    let mut blocks = vec![Block([0; 64]); bytes.len() / 64 + 1];
    bytemuck::cast_slice_mut::<Block, u8>(&mut blocks)[..bytes.len()].copy_from_slice(&bytes);
    let aligned = &bytemuck::cast_slice::<Block, u8>(&blocks)[..bytes.len()];
    // The loads answer as the built tree.
    let (loaded, view) = (Bvh8::from_bytes(&bytes).unwrap(), Bvh8Ref::from_bytes(aligned).unwrap());
    let b = bounds(tris);
    for ray in diffuse_rays(tris, 500, (b.max - b.min).length()) {
        let want = b8.intersect::<Moller>(&ray);
        assert_eq!(loaded.intersect::<Moller>(&ray), want);
        assert_eq!(strahl::traverse::wide::intersect::<Moller, _, 8>(view, &ray), want);
    }
    println!(
        "{name}: {} triangles, {:.1} MB of bytes ({} nodes, {} packs)",
        tris.len(),
        bytes.len() as f64 / 1e6,
        b8.nodes().len(),
        b8.packs().len()
    );
    let mut g = c.benchmark_group(format!("bytes/{name}"));
    g.sample_size(10);
    let (mut builder, mut collapser, mut bvh, mut wide) =
        (Builder::new(), Collapser::new(), Bvh2::default(), b8.clone());
    g.bench_function("build + collapse (warm)", |b| {
        b.iter(|| {
            builder.build_into(tris, &p, &mut bvh).unwrap();
            collapser.collapse_into(&bvh, tris, &mut wide).unwrap();
            black_box(wide.nodes().len())
        })
    });
    g.bench_function("from_bytes (copy, checked)", |b| {
        b.iter(|| black_box(Bvh8::from_bytes(black_box(&bytes)).unwrap().depth()))
    });
    g.bench_function("Bvh8Ref::from_bytes (in place)", |b| {
        b.iter(|| black_box(Bvh8Ref::from_bytes(black_box(aligned)).unwrap().nodes.len()))
    });
    g.bench_function("Bvh8Ref::check", |b| b.iter(|| black_box(view.check().unwrap())));
    g.bench_function("to_bytes", |b| b.iter(|| black_box(b8.to_bytes().len())));
    g.finish();
}

fn benches(c: &mut Criterion) {
    group(c, "bunny", &scene::bunny().to_soup());
    group(c, "sphereflake1M", &scene::sphereflake(3, 3).to_soup());
}

criterion_group!(b, benches);
criterion_main!(b);
