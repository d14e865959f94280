//! Sort-last compositing over a grid of edge cases (complementing `tests/composite.rs`): depth
//! compositing is bit-identical to `composite_serial` and over is within `OVER_F32_TOLERANCE` of
//! it, for rank counts 1, 2, 3, 5, 6, 7 and 12 (and 64 to 70), image sizes of 0 pixels, smaller
//! than and not divisible by the rank count, every schedule (`Schedule::Tree` and every ordered
//! factorisation of the rank count as a k-vector), several roots, sparse and dense, shuffled
//! visibility orders, and NaN, ±inf and ±0 depths and ties in depth. Also: repeated calls on one
//! transport each give the serial result; `measure_cost_model` gives every rank the same model;
//! `auto_kvec` is the cheapest ordered factorisation under its cost model; and the parts of
//! `kd_decompose` in `visibility_order` are front to back (no part occludes one before it).

use std::time::Duration;
use strahl::composite::schedule::MAX_GROUP;
use strahl::composite::{
    CostModel, DepthPixel, KVec, OVER_F32_TOLERANCE, Pixel, Plan, RgbaF32, Schedule, ThreadTransport, Transport, View,
    auto_kvec, composite, composite_serial, kd_decompose, measure_cost_model, visibility_order,
};
use strahl::scene::Rng;
use strahl::{Aabb, Vec3};

/// Every ordered factorisation of `p` into factors of at least 2 (`[[]]` for 1).
fn factorizations(p: u32) -> Vec<Vec<u32>> {
    if p == 1 {
        return vec![vec![]];
    }
    let mut out = vec![];
    for k in 2..=p {
        if p.is_multiple_of(k) {
            for mut rest in factorizations(p / k) {
                rest.insert(0, k);
                out.push(rest);
            }
        }
    }
    out
}

/// `Schedule::Tree` and every ordered factorisation of `p` as a radix-k schedule.
fn schedules(p: u32) -> Vec<Schedule> {
    let mut v = vec![Schedule::Tree];
    for f in factorizations(p) {
        v.push(Schedule::RadixK(KVec::new(&f).unwrap()));
    }
    v
}

/// Composites `images` (one per rank) on a `ThreadTransport` and returns the root's image,
/// asserting that the root, and only the root, gets one.
fn run<P: Pixel>(images: &[Vec<P>], order: &[u32], schedule: Schedule, root: u32, sparse: bool) -> Vec<P> {
    let p = images.len() as u32;
    let out = ThreadTransport::run(p, |t| {
        // A lost or misrouted message fails the test in seconds instead of hanging it.
        t.timeout = Duration::from_secs(5);
        let plan = Plan {
            schedule,
            order,
            root,
            sparse,
        };
        composite(t, &images[t.rank() as usize], &plan).unwrap().0
    });
    for (r, o) in out.iter().enumerate() {
        assert_eq!(o.is_some(), r as u32 == root);
    }
    out.into_iter().flatten().next().unwrap()
}

/// A visibility order that is not the identity, so the executor's rank mapping is exercised.
fn shuffled_order(p: u32, seed: u64) -> Vec<u32> {
    let mut rng = Rng::new(seed);
    let mut o: Vec<u32> = (0..p).collect();
    for i in (1..o.len()).rev() {
        o.swap(i, (rng.u64() % (i as u64 + 1)) as usize);
    }
    o
}

/// The serial reference for over: the images taken in visibility order (`order[v]` is the rank
/// `v`-th from the viewer).
fn serial_over(images: &[Vec<RgbaF32>], order: &[u32]) -> Vec<RgbaF32> {
    let refs: Vec<&[RgbaF32]> = order.iter().map(|&r| images[r as usize].as_slice()).collect();
    composite_serial(&refs)
}

/// Asserts that every channel of `img` is within `OVER_F32_TOLERANCE` of `serial`, and raises
/// `worst` to the largest difference seen. The tolerance is the stated bound for regrouping the
/// over of up to 64 images with channels in `[0, 1]`; a schedule only regroups, so it applies.
fn assert_over_close(img: &[RgbaF32], serial: &[RgbaF32], worst: &mut f32, what: &str) {
    for (a, b) in img.iter().zip(serial) {
        for c in 0..4 {
            let d = (a.0[c] - b.0[c]).abs();
            *worst = worst.max(d);
            assert!(d <= OVER_F32_TOLERANCE, "{what}: {a:?} vs {b:?} ({d:e})");
        }
    }
}

/// True if the open segment from `s` to `e` passes through the interior of `b`.
fn seg_hits(s: Vec3, e: Vec3, b: &Aabb) -> bool {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for ax in 0..3 {
        let (o, d) = (s[ax] as f64, (e[ax] - s[ax]) as f64);
        // The box is shrunk by 1e-4 of its extent, so that a segment along a face shared with a
        // neighbouring part, or through a shared edge or corner, does not count as crossing it.
        let (lo, hi) = (b.min[ax] as f64, b.max[ax] as f64);
        let eps = 1e-4 * (hi - lo).max(1e-9);
        let (lo, hi) = (lo + eps, hi - eps);
        if d.abs() < 1e-30 {
            if o <= lo || o >= hi {
                return false;
            }
            continue;
        }
        let (mut a, mut c) = ((lo - o) / d, (hi - o) / d);
        if a > c {
            std::mem::swap(&mut a, &mut c);
        }
        t0 = t0.max(a);
        t1 = t1.min(c);
    }
    t0 < t1 - 1e-9
}

/// Depth compositing gives the bits of `composite_serial` for every rank count, image size
/// (including 0 and sizes below or not divisible by the rank count), schedule, root (first, last,
/// middle), sparse and dense, with a quarter of the pixels empty and depths drawn from NaN, -NaN,
/// ±inf, ±0 and repeated values; the root alone gets the image.
#[test]
fn depth_is_bit_identical_to_serial_on_every_schedule() {
    let zs = [
        f32::NAN,
        -f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        0.0,
        -0.0,
        1.0,
        1.0,
        -1.0,
    ];
    for p in [1u32, 2, 3, 5, 6, 7, 12] {
        for n in [0usize, 1, 2, 3, 5, 11, 13, 40] {
            let mut rng = Rng::new(p as u64 * 31 + n as u64);
            let images: Vec<Vec<DepthPixel>> = (0..p)
                .map(|_| {
                    (0..n)
                        .map(|_| {
                            if rng.u64().is_multiple_of(4) {
                                DepthPixel::EMPTY
                            } else {
                                // Colours 0, 0x4000_0001 and 0x8000_0002: ties in depth are
                                // broken by colour, the high bit included.
                                DepthPixel::new(
                                    zs[(rng.u64() % zs.len() as u64) as usize],
                                    (rng.u64() % 3) as u32 * 0x4000_0001,
                                )
                            }
                        })
                        .collect()
                })
                .collect();
            // Depth compositing is a `min`, commutative: the reference takes the ranks in rank
            // order, whatever the visibility order.
            let refs: Vec<&[DepthPixel]> = images.iter().map(|v| v.as_slice()).collect();
            let serial = composite_serial(&refs);
            let order = shuffled_order(p, n as u64 + 3);
            for s in schedules(p) {
                for root in [0, p - 1, p / 2] {
                    for sparse in [true, false] {
                        let img = run(&images, &order, s, root, sparse);
                        assert_eq!(img, serial, "p {p} n {n} {s:?} root {root} sparse {sparse}");
                    }
                }
            }
        }
    }
}

/// Over compositing is within `OVER_F32_TOLERANCE` of `composite_serial` in visibility order, per
/// channel, with the image's length, for every rank count, image size, schedule, first and last
/// root, sparse and dense, with a quarter of the pixels empty.
#[test]
fn over_is_within_tolerance_of_serial_on_every_schedule() {
    let mut worst = 0.0f32;
    for p in [1u32, 2, 3, 5, 6, 7, 12] {
        for n in [0usize, 1, 2, 3, 5, 11, 13, 40] {
            let mut rng = Rng::new(p as u64 * 31 + n as u64);
            let images: Vec<Vec<RgbaF32>> = (0..p)
                .map(|_| {
                    (0..n)
                        .map(|_| {
                            if rng.u64().is_multiple_of(4) {
                                RgbaF32::EMPTY
                            } else {
                                let a = rng.f32();
                                RgbaF32([rng.f32() * a, rng.f32() * a, rng.f32() * a, a])
                            }
                        })
                        .collect()
                })
                .collect();
            let order = shuffled_order(p, n as u64 + 3);
            let serial = serial_over(&images, &order);
            for s in schedules(p) {
                for root in [0, p - 1] {
                    for sparse in [true, false] {
                        let img = run(&images, &order, s, root, sparse);
                        assert_eq!(img.len(), n);
                        let what = format!("p {p} n {n} {s:?} root {root} sparse {sparse}");
                        assert_over_close(&img, &serial, &mut worst, &what);
                    }
                }
            }
        }
    }
    println!("over: largest difference from the serial reference {worst:e} (bound {OVER_F32_TOLERANCE:e})");
}

/// Over on 64, 67 and 70 ranks (groups of more than `MAX_GROUP` members under direct-send; 67 is
/// a prime above it) is within `OVER_F32_TOLERANCE` of the serial reference with the tree,
/// direct-send, the automatic k-vector and (for 64) binary-swap, rooted at rank 1.
#[test]
fn over_is_within_tolerance_on_64_to_70_ranks() {
    let mut worst = 0.0f32;
    for p in [64u32, 67, 70] {
        let n = 150usize;
        let mut rng = Rng::new(p as u64);
        // Alpha at most 0.1, so that the farthest of 70 layers still shows through (by at least
        // 0.9^70, about 6e-4) and every rank's pixels reach the result. The tolerance is stated for 64
        // images; the rounding grows by about an ulp per image, far inside it at 70.
        let images: Vec<Vec<RgbaF32>> = (0..p)
            .map(|_| {
                (0..n)
                    .map(|_| {
                        let a = rng.f32() * 0.1;
                        RgbaF32([rng.f32() * a, rng.f32() * a, rng.f32() * a, a])
                    })
                    .collect()
            })
            .collect();
        let order = shuffled_order(p, 9);
        let serial = serial_over(&images, &order);
        let mut scheds = vec![
            Schedule::Tree,
            Schedule::RadixK(KVec::direct_send(p)),
            Schedule::RadixK(auto_kvec(p, n as u64, 16, &CostModel::shared_memory())),
        ];
        if let Some(k) = KVec::binary_swap(p) {
            scheds.push(Schedule::RadixK(k));
        }
        for s in scheds {
            let img = run(&images, &order, s, 1, true);
            assert_over_close(&img, &serial, &mut worst, &format!("p {p} {s:?}"));
        }
    }
    println!("over: largest difference on 64-70 ranks {worst:e} (bound {OVER_F32_TOLERANCE:e})");
}

/// Over on 64 ranks, 2000 pixels, is within `OVER_F32_TOLERANCE` of the serial reference for
/// alphas near 0, near 1, alternating small and any, and multiples of 1/1024, with the tree and
/// k-vectors of one round (64), two (8 8, 2 32, 32 2), three (4 4 4) and six (2 ... 2).
#[test]
fn over_on_64_ranks_is_within_tolerance_for_every_alpha_distribution() {
    // 64 ranks: the largest image count `OVER_F32_TOLERANCE` is stated for.
    let p = 64u32;
    let n = 2000usize;
    let mut worst = 0.0f32;
    for dist in 0..4 {
        let mut rng = Rng::new(dist + 77);
        let images: Vec<Vec<RgbaF32>> = (0..p)
            .map(|_| {
                (0..n)
                    .map(|i| {
                        let a = match dist {
                            0 => rng.f32() * 0.02,
                            1 => 1.0 - rng.f32() * 0.02,
                            2 => {
                                if i % 2 == 0 {
                                    rng.f32() * 0.05
                                } else {
                                    rng.f32()
                                }
                            }
                            _ => (rng.u64() % 64) as f32 / 1024.0,
                        };
                        let a: f32 = a.clamp(0.0, 1.0);
                        // Red equal to alpha: the largest premultiplied channel.
                        RgbaF32([a, a * rng.f32(), a * 0.999, a])
                    })
                    .collect()
            })
            .collect();
        let order = shuffled_order(p, dist);
        let serial = serial_over(&images, &order);
        for f in [
            vec![2u32; 6],
            vec![64],
            vec![4, 4, 4],
            vec![8, 8],
            vec![2, 32],
            vec![32, 2],
        ] {
            let img = run(&images, &order, Schedule::RadixK(KVec::new(&f).unwrap()), 0, true);
            assert_over_close(&img, &serial, &mut worst, &format!("dist {dist} {f:?}"));
        }
        let img = run(&images, &order, Schedule::Tree, 0, true);
        assert_over_close(&img, &serial, &mut worst, &format!("dist {dist} tree"));
    }
    println!("over on 64 ranks: largest difference {worst:e} (bound {OVER_F32_TOLERANCE:e})");
}

/// On one transport, `measure_cost_model`, a barrier and then one composite per schedule (each
/// with its own shuffled order, the root moving from rank to rank, sparse and dense in turn, some
/// ranks late) each give the serial depth result: no call takes another's messages.
#[test]
fn repeated_calls_on_one_transport_each_match_serial() {
    for p in [3u32, 5, 6, 8] {
        let n = 37usize;
        let mut rng = Rng::new(p as u64 + 100);
        let images: Vec<Vec<DepthPixel>> = (0..p)
            .map(|_| {
                (0..n)
                    .map(|_| DepthPixel::new((rng.u64() % 5) as f32, rng.u64() as u32))
                    .collect()
            })
            .collect();
        let refs: Vec<&[DepthPixel]> = images.iter().map(|v| v.as_slice()).collect();
        let serial = composite_serial(&refs);
        let scheds = schedules(p);
        let orders: Vec<Vec<u32>> = (0..scheds.len()).map(|i| shuffled_order(p, i as u64)).collect();
        let res = ThreadTransport::run(p, |t| {
            t.timeout = Duration::from_secs(5);
            let mut out = vec![];
            let _ = measure_cost_model(t).unwrap();
            t.barrier().unwrap();
            for (i, &s) in scheds.iter().enumerate() {
                // A third of the ranks start each call late, so that the others' messages for
                // this call arrive while they are still finishing the previous one.
                if (t.rank() as usize + i).is_multiple_of(3) {
                    std::thread::sleep(Duration::from_millis(2));
                }
                let root = (i as u32) % p;
                let plan = Plan {
                    schedule: s,
                    order: &orders[i],
                    root,
                    sparse: i % 2 == 0,
                };
                out.push(composite(t, &images[t.rank() as usize], &plan).unwrap().0);
            }
            out
        });
        for (i, s) in scheds.iter().enumerate() {
            let root = (i as u32 % p) as usize;
            assert_eq!(res[root][i].as_ref().unwrap(), &serial, "p {p} {s:?}");
        }
    }
}

/// `measure_cost_model` returns the same model on every rank for 1, 2, 3 and 5 ranks, and
/// `auto_kvec` on it gives a k-vector over all the ranks.
#[test]
fn cost_model_is_the_same_on_every_rank() {
    for p in [1u32, 2, 3, 5] {
        let m = ThreadTransport::run(p, |t| measure_cost_model(t).unwrap());
        assert!(m.iter().all(|x| *x == m[0]), "{m:?}");
        let k = auto_kvec(p, 1 << 16, 16, &m[0]);
        assert_eq!(k.ranks(), p);
    }
}

/// For every rank count 1 ..= 150, four cost models (shared memory, cluster, latency-bound,
/// bandwidth-bound) and image sizes 0 to 2^20, `auto_kvec` covers all the ranks, has no factor
/// above `MAX_GROUP` unless it is direct-send, and costs no more than any ordered factorisation
/// that obeys the same limit.
#[test]
fn auto_kvec_is_the_cheapest_factorisation() {
    let models = [
        CostModel::shared_memory(),
        CostModel::cluster(),
        CostModel {
            latency: 1e-3,
            seconds_per_byte: 1e-12,
            seconds_per_blend: 1e-12,
        },
        CostModel {
            latency: 0.0,
            seconds_per_byte: 1e-9,
            seconds_per_blend: 0.0,
        },
    ];
    let max_group = MAX_GROUP as u32;
    for p in 1..=150u32 {
        let all = factorizations(p);
        for m in &models {
            for n in [0u64, 1, 1000, 1 << 20] {
                let k = auto_kvec(p, n, 16, m);
                assert_eq!(k.ranks(), p);
                assert!(
                    k.as_slice().iter().all(|&f| f <= max_group) || k.as_slice() == [p],
                    "{p} {k:?}"
                );
                let c = m.cost(&k, n, 16);
                for f in &all {
                    if f.iter().any(|&x| x > max_group) && f.as_slice() != [p] {
                        continue;
                    }
                    let o = m.cost(&KVec::new(f).unwrap(), n, 16);
                    // `auto_kvec` sums the rounds' costs last to first, with the pixels divided
                    // once, where `cost` sums first to last dividing round by round: the same
                    // k-vector may differ by rounding, hence the relative 1e-9 (and an absolute
                    // 1e-300 for costs of zero).
                    assert!(
                        c <= o * (1.0 + 1e-9) + 1e-300,
                        "p {p} n {n} {m:?}: {k:?} {c} vs {f:?} {o}"
                    );
                }
            }
        }
    }
}

/// For 300 random boxes, 1 to 13 parts and random eyes (inside and outside the box) and
/// directions, `visibility_order` is a permutation of the parts of `kd_decompose`, and no part is
/// crossed by the line of sight to a point of a part before it in the order.
#[test]
fn kd_parts_in_visibility_order_are_front_to_back() {
    let mut rng = Rng::new(5);
    for iter in 0..300 {
        let lo = Vec3::new(rng.f32() * 4.0 - 2.0, rng.f32() * 4.0 - 2.0, rng.f32() * 4.0 - 2.0);
        let ext = Vec3::new(rng.f32() * 5.0 + 0.1, rng.f32() * 5.0 + 0.1, rng.f32() * 5.0 + 0.1);
        let b = Aabb::new(lo, lo + ext);
        for p in [1usize, 2, 3, 5, 6, 7, 12, 13] {
            let mut parts = vec![Aabb::EMPTY; p];
            kd_decompose(&b, &mut parts);
            let dir = Vec3::new(rng.f32() * 2.0 - 1.0, rng.f32() * 2.0 - 1.0, rng.f32() * 2.0 - 1.0);
            // An eye anywhere from one extent before the box to one extent after it, per axis.
            let eye = lo + ext * Vec3::new(rng.f32() * 3.0 - 1.0, rng.f32() * 3.0 - 1.0, rng.f32() * 3.0 - 1.0);
            for view in [View::Eye(eye), View::Direction(dir)] {
                let mut order = vec![0u32; p];
                visibility_order(&b, view, &mut order);
                let mut s = order.clone();
                s.sort();
                assert_eq!(s, (0..p as u32).collect::<Vec<_>>());
                for i in 0..p {
                    for j in i + 1..p {
                        let (a, c) = (parts[order[i] as usize], parts[order[j] as usize]);
                        // A point in a: the segment from the viewer to it must not cross c. An
                        // orthographic viewer is 1000 along -dir, far outside every box here.
                        for _ in 0..20 {
                            let q = a.min + (a.max - a.min) * Vec3::new(rng.f32(), rng.f32(), rng.f32());
                            let from = match view {
                                View::Eye(e) => e,
                                View::Direction(d) => q - d * 1000.0,
                            };
                            assert!(
                                !seg_hits(from, q, &c),
                                "iter {iter} p {p} {view:?}: part {} (pos {j}) occludes part {} (pos {i}); order {order:?}",
                                order[j],
                                order[i]
                            );
                        }
                    }
                }
            }
        }
    }
}
