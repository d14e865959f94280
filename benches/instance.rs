//! Instancing, single thread: a two-level BVH (`layout::Tlas` over BVH8 BLASes) against one BVH8
//! over every instance's triangles transformed into the world, on the same rays, in one group per
//! scene and ray kind; and the builds (the TLAS over built BLASes against building the flattened
//! scene).
//!
//! Scenes: `bunnies` (8 x 8 bunnies, each turned about y and scaled by 0.8 to 1.2: 64 instances,
//! 235k triangles) and `spheres` (32 x 32 icospheres of 1,280 triangles, turned and scaled: 1,024
//! instances, 1.3M triangles). Rays: `primary` (the benches' 1024 x 1024 pinhole camera) and
//! `diffuse` (262,144 rays from random surface points, closest hit). Hit counts are checked
//! against each other (within 0.1%: the transform's rounding) before timing.
//!
//! With `--features embree`, Embree 3 in the same groups: its instancing (a top scene of
//! `RTC_GEOMETRY_TYPE_INSTANCE` geometries over one mesh scene, `embree_instances`) and the
//! flattened scene (`embree_flat`), `rtcIntersect1` / `rtcOccluded1`, default (non-robust) mode.
//!
//! Masks (`*_masked`): half the instances, drawn at random, carry mask `0b10` (seen only by rays
//! with bit 1, say shadow rays), the rest `0b11`, and the rays trace with mask `0b01`, so they see
//! half the scene:
//! `Tlas::intersect_masked` / `occluded_masked` against Embree's geometry masks
//! (`rtcSetGeometryMask`, `RTCRay::mask`) and against the same visibility as a hit filter
//! (`tlas_bvh8_filter_mask`: `intersect_filtered` rejecting the hits of hidden instances, which
//! still walks their BLASes). Their hit counts are checked against each other first.
//!
//! Batches (`*_batch`): `Tlas::intersect_batch` / `occluded_batch`, which trace each group of 8
//! consecutive rays with the same direction signs and close origins (the camera's 4 x 2 tiles)
//! as one packet (`Tlas::intersect8`: the TLAS walked by the packet, each instance's BLAS by a
//! BLAS packet), against `Bvh8::intersect_batch` on the flattened scene and Embree's stream API
//! through its instances (`rtcIntersect1M`, `embree_instances_1M`; its `rtcOccluded1M` through
//! instances did not finish a criterion run here and is left out).
//!
//! Updates (`instance/*/update`, the two scenes and `crowd100k`: 100,000 instances of an
//! 80-triangle icosphere): the next frame's placement of every instance (each moved by up to a
//! tenth of the mesh's size on each axis and turned a little, two placements taking turns) by a rebuild of the TLAS
//! (`tlas`: the full sweep; `tlas_fast`: `Tlas::build_with` and `BuildParams::fast()`), by
//! `Tlas::refit` (`tlas_refit`; `tlas_refit_par2`: `refit_par` on 2 threads), and by Embree's
//! new transforms and commit of the top scene (`embree_commit_low` / `_medium`: the scene's
//! build quality). The trees' SAH costs after the move are printed.
//!
//! `cargo bench --bench instance -- --noplot` (add `--features embree` for Embree)

#[path = "common/mod.rs"]
mod common;
#[path = "peers/mod.rs"]
mod peers;

use common::{bounds, diffuse_rays, primary_rays};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Affine3A, Quat};
use std::hint::black_box;
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::Triangle;
use strahl::layout::{Bvh8, Instance, InstanceHit, Tlas};
use strahl::scene::{self, Rng};
use strahl::traverse::Moller;
use strahl::traverse::packet::TileShape;
use strahl::{Ray, Vec3};

/// `k x k` instances of `mesh` on a grid in x-z, spaced `1.5` times the mesh's size, each turned
/// about y and scaled by 0.8 to 1.2; the instances and the world triangles.
fn grid(mesh: &[Triangle], k: usize, seed: u64) -> (Vec<Instance>, Vec<Triangle>) {
    let b = bounds(mesh);
    let size = (b.max - b.min).max_element();
    let mut rng = Rng::new(seed);
    let inst: Vec<Instance> = (0..k * k)
        .map(|i| {
            let q = Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU));
            let s = Vec3::splat(rng.range(0.8, 1.2));
            let t = Vec3::new((i % k) as f32, 0.0, (i / k) as f32) * size * 1.5;
            Instance::new(Affine3A::from_scale_rotation_translation(s, q, t), 0)
        })
        .collect();
    let world = inst
        .iter()
        .flat_map(|x| mesh.iter().map(move |t| t.map(|v| x.transform.transform_point3(v))))
        .collect();
    (inst, world)
}

/// Embree's 3 x 4 column-major transforms of `inst`.
#[cfg(feature = "embree")]
fn embree_transforms(inst: &[Instance]) -> Vec<[f32; 12]> {
    inst.iter()
        .map(|x| {
            let m = x.transform;
            let c = |v: glam::Vec3A| [v.x, v.y, v.z];
            let mut a = [0.0; 12];
            a[0..3].copy_from_slice(&c(m.matrix3.x_axis));
            a[3..6].copy_from_slice(&c(m.matrix3.y_axis));
            a[6..9].copy_from_slice(&c(m.matrix3.z_axis));
            a[9..12].copy_from_slice(&c(m.translation));
            a
        })
        .collect()
}

/// `inst` moved for the next frame: each instance shifted by up to `step` on each axis and
/// turned a little about y (the tree's shape, made for `inst`, still fits).
fn moved(inst: &[Instance], step: f32, seed: u64) -> Vec<Instance> {
    let mut rng = Rng::new(seed);
    inst.iter()
        .map(|x| {
            let d = Vec3::new(rng.range(-step, step), rng.range(-step, step), rng.range(-step, step));
            let turn = Affine3A::from_quat(Quat::from_rotation_y(rng.range(-0.2, 0.2)));
            Instance {
                transform: Affine3A::from_translation(d) * x.transform * turn,
                ..*x
            }
        })
        .collect()
}

/// The update of a scene's instances for the next frame, two placements taking turns: a
/// rebuild of the TLAS (`tlas`), its refit (`tlas_refit`), and with `--features embree`
/// Embree's new transforms and scene commit (its instance-level BVH rebuilt, at the top scene's
/// quality).
fn bench_update(c: &mut Criterion, group: &str, mesh: &[Triangle], inst: &[Instance], blases: &[Bvh8], step: f32) {
    let next = moved(inst, step, 5);
    let frames = [inst, &next[..]];
    let mut g = c.benchmark_group(group);
    g.sample_size(20);
    g.throughput(Throughput::Elements(inst.len() as u64));
    g.bench_function("tlas", |bch| {
        let mut f = 0;
        bch.iter(|| {
            f ^= 1;
            Tlas::build(black_box(frames[f]), blases).unwrap()
        })
    });
    g.bench_function("tlas_fast", |bch| {
        let mut f = 0;
        bch.iter(|| {
            f ^= 1;
            Tlas::build_with(black_box(frames[f]), blases, &BuildParams::fast()).unwrap()
        })
    });
    // The trees' SAH costs (C_T = C_I = 1) on the moved instances: rebuilt by the full sweep and
    // by `fast()`, and refitted from the first placement.
    let cost = |t: &Tlas| t.bvh().sah_cost(1.0, 1.0);
    let mut refitted = Tlas::build(inst, blases).unwrap();
    assert!(refitted.refit(&next, blases));
    eprintln!(
        "{group}: TLAS SAH cost after the move: rebuilt {:.2}, rebuilt by fast() {:.2}, refitted {:.2}",
        cost(&Tlas::build(&next, blases).unwrap()),
        cost(&Tlas::build_with(&next, blases, &BuildParams::fast()).unwrap()),
        cost(&refitted)
    );
    let mut tlas = Tlas::build(inst, blases).unwrap();
    g.bench_function("tlas_refit", |bch| {
        let mut f = 0;
        bch.iter(|| {
            f ^= 1;
            assert!(tlas.refit(black_box(frames[f]), blases));
        })
    });
    g.bench_function("tlas_refit_par2", |bch| {
        let mut f = 0;
        bch.iter(|| {
            f ^= 1;
            assert!(tlas.refit_par(black_box(frames[f]), blases, 2));
        })
    });
    #[cfg(feature = "embree")]
    {
        use peers::embree::{Device, InstanceScene, Quality};
        let device = Device::single_threaded();
        let xfms = [embree_transforms(inst), embree_transforms(&next)];
        for (name, q) in [
            ("embree_commit_low", Quality::Low),
            ("embree_commit_medium", Quality::Medium),
        ] {
            let mut scene = InstanceScene::new(&device, mesh, &xfms[0], q);
            g.bench_function(name, |bch| {
                let mut f = 0;
                bch.iter(|| {
                    f ^= 1;
                    scene.set_transforms(black_box(&xfms[f]));
                })
            });
        }
    }
    #[cfg(not(feature = "embree"))]
    let _ = mesh;
    g.finish();
}

fn build_bvh8(tris: &[Triangle]) -> Bvh8 {
    let (b2, _) = Bvh2::build(tris, &BuildParams::default()).unwrap();
    Bvh8::from_bvh2(&b2, tris).unwrap()
}

fn bench_scene(c: &mut Criterion, name: &str, mesh: Vec<Triangle>, k: usize, builds: bool) {
    let (inst, world) = grid(&mesh, k, 3);
    let blases = [build_bvh8(&mesh)];
    let tlas = Tlas::build(&inst, &blases).unwrap();
    // Half the instances hidden from rays of mask 0b01 (see the module docs).
    let masks: Vec<u32> = {
        let mut rng = Rng::new(17);
        inst.iter().map(|_| if rng.f32() < 0.5 { 0b10 } else { 0b11 }).collect()
    };
    let masked_inst: Vec<Instance> = inst.iter().zip(&masks).map(|(i, &m)| i.with_mask(m)).collect();
    let masked = Tlas::build(&masked_inst, &blases).unwrap();
    const RAY_MASK: u32 = 0b01;
    let visible = |h: &InstanceHit| masks[h.instance as usize] & RAY_MASK != 0;
    let flat = build_bvh8(&world);
    eprintln!(
        "{name}: {} instances, {} world triangles; memory: flat BVH8 {:.1} MB, BLAS {:.2} MB + TLAS {:.3} MB",
        inst.len(),
        world.len(),
        flat.memory_bytes() as f64 / 1e6,
        blases[0].memory_bytes() as f64 / 1e6,
        tlas.memory_bytes() as f64 / 1e6
    );
    #[cfg(feature = "embree")]
    let embree = {
        use peers::embree::{Device, InstanceScene, Quality, Scene};
        let device: &'static Device = Box::leak(Box::new(Device::single_threaded()));
        let xfms = embree_transforms(&inst);
        (
            device,
            InstanceScene::new(device, &mesh, &xfms, Quality::Medium),
            Scene::new(device, &world, Quality::Medium),
            InstanceScene::with_masks(device, &mesh, &xfms, &masks, Quality::Medium),
        )
    };
    let b = bounds(&world);
    let scale = (b.max - b.min).length();
    let kinds: [(&str, Vec<Ray>); 2] = [
        ("primary", primary_rays(&b, 1024, 1024, TileShape::X4_2)),
        ("diffuse", diffuse_rays(&world, 1 << 18, scale)),
    ];
    for (kind, rays) in &kinds {
        let n_flat = rays.iter().filter(|r| flat.intersect::<Moller>(r).is_some()).count();
        let n_tlas = rays
            .iter()
            .filter(|r| tlas.intersect::<Moller, _, 8>(&blases, r).is_some())
            .count();
        assert!(
            n_flat.abs_diff(n_tlas) * 1000 <= rays.len(),
            "{name}/{kind}: {n_flat} vs {n_tlas} hits"
        );
        let mut g = c.benchmark_group(format!("instance/{name}/{kind}"));
        g.throughput(Throughput::Elements(rays.len() as u64));
        g.sample_size(10);
        g.bench_function("flat_bvh8", |bch| {
            bch.iter(|| {
                black_box(rays)
                    .iter()
                    .filter(|r| flat.intersect::<Moller>(r).is_some())
                    .count()
            })
        });
        g.bench_function("tlas_bvh8", |bch| {
            bch.iter(|| {
                black_box(rays)
                    .iter()
                    .filter(|r| tlas.intersect::<Moller, _, 8>(&blases, r).is_some())
                    .count()
            })
        });
        g.bench_function("flat_bvh8_occluded", |bch| {
            bch.iter(|| black_box(rays).iter().filter(|r| flat.occluded::<Moller>(r)).count())
        });
        g.bench_function("tlas_bvh8_occluded", |bch| {
            bch.iter(|| {
                black_box(rays)
                    .iter()
                    .filter(|r| tlas.occluded::<Moller, _, 8>(&blases, r))
                    .count()
            })
        });
        // Batches: coherent groups of 8 (the camera's 4 x 2 tiles) as packets, the others one
        // call per ray; the same hits as one call per ray.
        let mut hits = vec![None; rays.len()];
        let mut flat_hits = vec![None; rays.len()];
        let mut occ = vec![false; rays.len()];
        tlas.intersect_batch::<Moller, _, 8>(&blases, rays, &mut hits);
        assert_eq!(hits.iter().flatten().count(), n_tlas, "{name}/{kind}: batch hits");
        tlas.occluded_batch::<Moller, _, 8>(&blases, rays, &mut occ);
        assert_eq!(
            occ.iter().filter(|&&o| o).count(),
            n_tlas,
            "{name}/{kind}: batch occluded"
        );
        g.bench_function("flat_bvh8_batch", |bch| {
            bch.iter(|| {
                flat.intersect_batch::<Moller>(black_box(rays), &mut flat_hits);
                flat_hits.iter().flatten().count()
            })
        });
        g.bench_function("tlas_bvh8_batch", |bch| {
            bch.iter(|| {
                tlas.intersect_batch::<Moller, _, 8>(&blases, black_box(rays), &mut hits);
                hits.iter().flatten().count()
            })
        });
        g.bench_function("tlas_bvh8_occluded_batch", |bch| {
            bch.iter(|| {
                tlas.occluded_batch::<Moller, _, 8>(&blases, black_box(rays), &mut occ);
                occ.iter().filter(|&&o| o).count()
            })
        });
        let n_masked = rays
            .iter()
            .filter(|r| masked.intersect_masked::<Moller, _, 8>(&blases, r, RAY_MASK).is_some())
            .count();
        let n_filter = rays
            .iter()
            .filter(|r| tlas.intersect_filtered::<Moller, _, 8>(&blases, r, visible).is_some())
            .count();
        assert_eq!(n_masked, n_filter, "{name}/{kind}: masks against the filter");
        assert!(n_masked < n_tlas, "{name}/{kind}: the masks hide nothing");
        g.bench_function("tlas_bvh8_masked", |bch| {
            bch.iter(|| {
                black_box(rays)
                    .iter()
                    .filter(|r| masked.intersect_masked::<Moller, _, 8>(&blases, r, RAY_MASK).is_some())
                    .count()
            })
        });
        g.bench_function("tlas_bvh8_filter_mask", |bch| {
            bch.iter(|| {
                black_box(rays)
                    .iter()
                    .filter(|r| tlas.intersect_filtered::<Moller, _, 8>(&blases, r, visible).is_some())
                    .count()
            })
        });
        g.bench_function("tlas_bvh8_occluded_masked", |bch| {
            bch.iter(|| {
                black_box(rays)
                    .iter()
                    .filter(|r| masked.occluded_masked::<Moller, _, 8>(&blases, r, RAY_MASK))
                    .count()
            })
        });
        #[cfg(feature = "embree")]
        {
            let (ei, ef, em) = (&embree.1, &embree.2, &embree.3);
            let n_embree = rays.iter().filter(|r| ei.intersect1(r).is_some()).count();
            assert!(
                n_embree.abs_diff(n_tlas) * 1000 <= rays.len(),
                "{name}/{kind}: Embree {n_embree} vs {n_tlas} hits"
            );
            g.bench_function("embree_flat", |bch| {
                bch.iter(|| black_box(rays).iter().filter(|r| ef.intersect1(r).is_some()).count())
            });
            g.bench_function("embree_instances", |bch| {
                bch.iter(|| black_box(rays).iter().filter(|r| ei.intersect1(r).is_some()).count())
            });
            g.bench_function("embree_flat_occluded", |bch| {
                bch.iter(|| black_box(rays).iter().filter(|r| ef.occluded1(r)).count())
            });
            g.bench_function("embree_instances_occluded", |bch| {
                bch.iter(|| black_box(rays).iter().filter(|r| ei.occluded1(r)).count())
            });
            // Embree's stream API through its instances (256 rays a call, flagged coherent for
            // the camera's rays), against the batches.
            let coherent = *kind == "primary";
            let mut n_1m = 0;
            ei.intersect1m(rays, coherent, |_, h| n_1m += usize::from(h.is_some()));
            assert!(
                n_1m.abs_diff(n_tlas) * 1000 <= rays.len(),
                "{name}/{kind}: Embree stream {n_1m} vs {n_tlas} hits"
            );
            g.bench_function("embree_instances_1M", |bch| {
                bch.iter(|| {
                    let mut n = 0;
                    ei.intersect1m(black_box(rays), coherent, |_, h| n += usize::from(h.is_some()));
                    n
                })
            });
            let n_em = rays
                .iter()
                .filter(|r| em.intersect1_masked(r, RAY_MASK).is_some())
                .count();
            assert!(
                n_em.abs_diff(n_masked) * 1000 <= rays.len(),
                "{name}/{kind}: Embree masked {n_em} vs {n_masked} hits"
            );
            g.bench_function("embree_instances_masked", |bch| {
                bch.iter(|| {
                    black_box(rays)
                        .iter()
                        .filter(|r| em.intersect1_masked(r, RAY_MASK).is_some())
                        .count()
                })
            });
            let (o_tlas, o_em) = (
                rays.iter()
                    .filter(|r| masked.occluded_masked::<Moller, _, 8>(&blases, r, RAY_MASK))
                    .count(),
                rays.iter().filter(|r| em.occluded1_masked(r, RAY_MASK)).count(),
            );
            assert!(
                o_em.abs_diff(o_tlas) * 1000 <= rays.len(),
                "{name}/{kind}: Embree masked occluded {o_em} vs {o_tlas}"
            );
            g.bench_function("embree_instances_occluded_masked", |bch| {
                bch.iter(|| {
                    black_box(rays)
                        .iter()
                        .filter(|r| em.occluded1_masked(r, RAY_MASK))
                        .count()
                })
            });
        }
        g.finish();
    }
    if builds {
        let mut g = c.benchmark_group(format!("instance/{name}/build"));
        g.sample_size(10);
        g.bench_function("tlas", |bch| {
            bch.iter(|| Tlas::build(black_box(&inst), &blases).unwrap())
        });
        g.bench_function("flat_bvh8", |bch| bch.iter(|| build_bvh8(black_box(&world))));
        g.finish();
    }
    let size = (bounds(&mesh).max - bounds(&mesh).min).max_element();
    bench_update(c, &format!("instance/{name}/update"), &mesh, &inst, &blases, size * 0.1);
}

/// 100,000 instances of an 80-triangle icosphere (radius 1) at random places and turns in a
/// cube of side 400 (about 8.6 apart, 4.3 diameters): the update of a crowd of moving objects.
fn bench_crowd(c: &mut Criterion) {
    let mesh = scene::icosphere(1).to_soup();
    let blases = [build_bvh8(&mesh)];
    let mut rng = Rng::new(9);
    let inst: Vec<Instance> = (0..100_000)
        .map(|_| {
            let q = Quat::from_axis_angle(rng.unit_vector(), rng.range(0.0, std::f32::consts::TAU));
            let t = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 400.0;
            Instance::new(Affine3A::from_rotation_translation(q, t), 0)
        })
        .collect();
    bench_update(c, "instance/crowd100k/update", &mesh, &inst, &blases, 0.2);
}

fn benches(c: &mut Criterion) {
    bench_scene(c, "bunnies", scene::bunny().to_soup(), 8, true);
    bench_scene(c, "spheres", scene::icosphere(3).to_soup(), 32, false);
    bench_crowd(c);
}

criterion_group!(instance, benches);
criterion_main!(instance);
