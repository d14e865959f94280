//! Sort-last compositing: every schedule for P = 1 ..= 16 (primes and non-powers of two included)
//! on odd image sizes equals the serial reference: depth bit for bit, over within
//! `OVER_F32_TOLERANCE`; binary-swap and radix-k send at most n (1 - 1/P) b bytes plus headers.

use strahl::composite::{
    CostModel, DepthPixel, KVec, OVER_F32_TOLERANCE, Pixel, Plan, Rgba8, RgbaF32, Schedule, ThreadTransport, Transport,
    auto_kvec, composite, composite_serial,
};
use strahl::scene::Rng;

/// Ordered factorisations worth trying for `p`: direct-send, binary-swap (powers of two), a
/// two-level split, the reverse, and the automatic choice.
fn schedules(p: u32) -> Vec<Schedule> {
    let mut v = vec![Schedule::Tree, Schedule::RadixK(KVec::direct_send(p))];
    if let Some(k) = KVec::binary_swap(p) {
        v.push(Schedule::RadixK(k));
    }
    if let Some(a) = (2..p).find(|a| p.is_multiple_of(*a)) {
        v.push(Schedule::RadixK(KVec::new(&[a, p / a]).unwrap()));
        v.push(Schedule::RadixK(KVec::new(&[p / a, a]).unwrap()));
    }
    v.push(Schedule::RadixK(auto_kvec(p, 1 << 16, 16, &CostModel::shared_memory())));
    v.dedup();
    v
}

/// A rank's partial image: each pixel covered with probability `cover`, else empty.
fn partial<P: Pixel>(rng: &mut Rng, n: usize, cover: f32, f: impl Fn(&mut Rng) -> P) -> Vec<P> {
    (0..n)
        .map(|_| if rng.f32() < cover { f(rng) } else { P::EMPTY })
        .collect()
}

fn rgba(rng: &mut Rng) -> RgbaF32 {
    let a = rng.f32();
    RgbaF32([rng.f32() * a, rng.f32() * a, rng.f32() * a, a])
}

fn run<P: Pixel>(images: &[Vec<P>], order: &[u32], schedule: Schedule, root: u32, sparse: bool) -> (Vec<P>, Vec<u64>) {
    let p = images.len() as u32;
    let out = ThreadTransport::run(p, |t| {
        let plan = Plan {
            schedule,
            order,
            root,
            sparse,
        };
        let (img, stats) = composite(t, &images[t.rank() as usize], &plan).unwrap();
        (img, stats.bytes_sent)
    });
    let bytes = out.iter().map(|o| o.1).collect();
    let img = out.into_iter().find_map(|o| o.0).expect("the root has the image");
    (img, bytes)
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

#[test]
fn depth_is_bit_identical_to_serial_for_every_schedule() {
    for p in 1..=16u32 {
        for n in [1usize, 17, 255, 1001] {
            let mut rng = Rng::new(p as u64 * 1000 + n as u64);
            let images: Vec<Vec<DepthPixel>> = (0..p)
                .map(|_| {
                    partial(&mut rng, n, 0.5, |r| {
                        DepthPixel::new((r.u64() % 8) as f32, r.u64() as u32)
                    })
                })
                .collect();
            let refs: Vec<&[DepthPixel]> = images.iter().map(|v| v.as_slice()).collect();
            let serial = composite_serial(&refs);
            let order = shuffled_order(p, n as u64);
            for s in schedules(p) {
                for sparse in [true, false] {
                    let root = (n as u32) % p;
                    let (img, _) = run(&images, &order, s, root, sparse);
                    assert!(img == serial, "p {p} n {n} {s:?} sparse {sparse}");
                }
            }
        }
    }
}

#[test]
fn over_is_within_tolerance_of_serial_front_to_back() {
    let mut worst = 0.0f32;
    for p in 1..=16u32 {
        for n in [1usize, 33, 499] {
            let mut rng = Rng::new(p as u64 * 7 + n as u64);
            let images: Vec<Vec<RgbaF32>> = (0..p).map(|_| partial(&mut rng, n, 0.7, rgba)).collect();
            // Visibility order: order[v] is the rank v-th from the viewer.
            let order = shuffled_order(p, 99 + p as u64);
            let in_order: Vec<&[RgbaF32]> = order.iter().map(|&r| images[r as usize].as_slice()).collect();
            let serial = composite_serial(&in_order);
            for s in schedules(p) {
                let (img, _) = run(&images, &order, s, 0, true);
                for (a, b) in img.iter().zip(&serial) {
                    for c in 0..4 {
                        let d = (a.0[c] - b.0[c]).abs();
                        worst = worst.max(d);
                        assert!(d <= OVER_F32_TOLERANCE, "p {p} n {n} {s:?}: {a:?} vs {b:?}");
                    }
                }
            }
        }
    }
    println!("over: largest difference from the serial reference {worst:e} (bound {OVER_F32_TOLERANCE:e})");
}

#[test]
fn u8_over_is_within_one_step_per_round_of_serial() {
    for p in [2u32, 3, 6, 8, 13] {
        let n = 301;
        let mut rng = Rng::new(p as u64);
        let images: Vec<Vec<Rgba8>> = (0..p)
            .map(|_| {
                partial(&mut rng, n, 0.8, |r| {
                    let a = (r.u64() % 256) as u32;
                    let c = |r: &mut Rng| ((r.u64() % 256) as u32 * a / 255) as u8;
                    Rgba8([c(r), c(r), c(r), a as u8])
                })
            })
            .collect();
        let order: Vec<u32> = (0..p).collect();
        let refs: Vec<&[Rgba8]> = images.iter().map(|v| v.as_slice()).collect();
        let serial = composite_serial(&refs);
        for s in schedules(p) {
            let (img, _) = run(&images, &order, s, 0, true);
            for (a, b) in img.iter().zip(&serial) {
                for c in 0..4 {
                    let d = (a.0[c] as i32 - b.0[c] as i32).abs();
                    assert!(d <= p as i32, "p {p} {s:?}: {a:?} vs {b:?}");
                }
            }
        }
    }
}

#[test]
fn bytes_sent_within_n_one_minus_one_over_p() {
    for p in 2..=16u32 {
        let n = 4099usize; // odd and prime
        let b = RgbaF32::BYTES as f64;
        let mut rng = Rng::new(5);
        let images: Vec<Vec<RgbaF32>> = (0..p).map(|_| partial(&mut rng, n, 1.0, rgba)).collect();
        let order: Vec<u32> = (0..p).collect();
        for s in schedules(p) {
            let Schedule::RadixK(k) = s else { continue };
            let (_, bytes) = run(&images, &order, s, 0, false);
            let messages: u32 = k.as_slice().iter().map(|k| k - 1).sum();
            // Headers: one run's per dense message; uneven splits: one pixel per piece.
            let header = strahl::composite::sparse::header_bytes(1) as f64;
            let slack = messages as f64 * header + k.as_slice().iter().sum::<u32>() as f64 * b;
            let bound = n as f64 * (1.0 - 1.0 / p as f64) * b + slack;
            for (r, &sent) in bytes.iter().enumerate() {
                assert!(sent as f64 <= bound, "p {p} {k:?} rank {r}: {sent} > {bound}");
            }
        }
    }
}

#[test]
fn sparse_images_send_less() {
    let p = 8;
    let n = 10_000;
    let mut rng = Rng::new(1);
    // Each rank covers only its own contiguous tenth of the image, as a spatial partition does.
    let images: Vec<Vec<DepthPixel>> = (0..p)
        .map(|r| {
            (0..n)
                .map(|i| {
                    if i / 1250 == r {
                        DepthPixel::new(rng.f32(), 1)
                    } else {
                        DepthPixel::EMPTY
                    }
                })
                .collect()
        })
        .collect();
    let order: Vec<u32> = (0..p as u32).collect();
    let s = Schedule::RadixK(KVec::binary_swap(8).unwrap());
    let (dense_img, dense) = run(&images, &order, s, 0, false);
    let (sparse_img, sparse) = run(&images, &order, s, 0, true);
    assert_eq!(dense_img, sparse_img);
    let (d, sp): (u64, u64) = (dense.iter().sum(), sparse.iter().sum());
    assert!(sp * 3 < d, "sparse {sp} bytes vs dense {d}");
}

#[test]
fn bad_plans_are_errors_not_panics() {
    let out = ThreadTransport::run(3, |t| {
        let img = vec![DepthPixel::EMPTY; 4];
        let bad_order = [0, 0, 1];
        let plan = Plan {
            schedule: Schedule::RadixK(KVec::direct_send(3)),
            order: &bad_order,
            root: 0,
            sparse: true,
        };
        let a = composite(t, &img, &plan).is_err();
        let order = [0, 1, 2];
        let plan = Plan {
            schedule: Schedule::RadixK(KVec::new(&[2, 2]).unwrap()),
            order: &order,
            root: 0,
            sparse: true,
        };
        let b = composite(t, &img, &plan).is_err();
        let plan = Plan {
            schedule: Schedule::Tree,
            order: &order,
            root: 7,
            sparse: true,
        };
        let c = composite(t, &img, &plan).is_err();
        a && b && c
    });
    assert!(out.iter().all(|&ok| ok));
}

/// A transport that loses the last message of every exchange: `composite` answers with an error
/// on every schedule (no panic on a missing message, no image with a piece left out); so do ranks
/// whose images differ in size; a thread transport asked for a rank outside its group answers at
/// once.
#[test]
fn lost_messages_and_unknown_ranks_are_errors() {
    struct Lossy<'a>(&'a mut ThreadTransport);
    impl Transport for Lossy<'_> {
        fn rank(&self) -> u32 {
            self.0.rank()
        }
        fn size(&self) -> u32 {
            self.0.size()
        }
        fn exchange(
            &mut self,
            tag: u32,
            sends: Vec<(u32, Vec<u8>)>,
            from: &[u32],
        ) -> Result<Vec<Vec<u8>>, strahl::composite::TransportError> {
            let mut got = self.0.exchange(tag, sends, from)?;
            got.pop();
            Ok(got)
        }
    }
    for p in [2u32, 3, 4] {
        for schedule in schedules(p) {
            let order: Vec<u32> = (0..p).collect();
            let out = ThreadTransport::run(p, |t| {
                let img = vec![DepthPixel(12345); 9];
                let plan = Plan {
                    schedule,
                    order: &order,
                    root: 0,
                    sparse: true,
                };
                composite(&mut Lossy(t), &img, &plan).map(|(img, _)| img.is_some())
            });
            // Some rank receives, loses a message and fails; no rank returns an image.
            assert!(out.iter().any(|r| r.is_err()), "{p} ranks, {schedule:?}: {out:?}");
            assert!(
                !out.iter().any(|r| matches!(r, Ok(true))),
                "{p} ranks, {schedule:?}: an image"
            );
        }
    }
    // Ranks with images of different sizes (10 and 12 pixels): every piece lands in a range of
    // another length, an error where it arrives (it was blended one pixel off before).
    for schedule in [Schedule::Tree, Schedule::RadixK(KVec::direct_send(2))] {
        let order = [0, 1];
        let out = ThreadTransport::run(2, |t| {
            let img = vec![DepthPixel(12345); 10 + 2 * t.rank() as usize];
            let plan = Plan {
                schedule,
                order: &order,
                root: 0,
                sparse: true,
            };
            composite(t, &img, &plan).map(|(img, _)| img.is_some())
        });
        assert!(out[0].is_err(), "{schedule:?}: {out:?}");
        assert!(!out.iter().any(|r| matches!(r, Ok(true))), "{schedule:?}: an image");
    }
    let mut t = ThreadTransport::group(2).remove(0);
    let start = std::time::Instant::now();
    assert!(t.exchange(1, Vec::new(), &[5]).is_err());
    assert!(start.elapsed() < std::time::Duration::from_secs(5));
}

/// Sort-first tiles: `render_tiles` and `render_tiles_into` put every pixel in place for image
/// and tile sizes with partial edge tiles, tiles of 0 (taken as 1), tiles larger than the image
/// and empty images, on 1 to 9 threads, both assignments; an image buffer of the wrong size is
/// an error that leaves it untouched; a reused buffer is overwritten everywhere.
#[test]
fn tiled_renders_put_every_pixel_in_place() {
    use strahl::composite::{Assignment, ImageSizeError, render_tiles, render_tiles_into, tiles};
    let shade = |w: u32, salt: u32| {
        move |t: strahl::composite::Tile, out: &mut [u32]| {
            let tw = t.x1 - t.x0;
            assert_eq!(out.len(), t.pixels());
            for (i, p) in out.iter_mut().enumerate() {
                let (x, y) = (t.x0 + i as u32 % tw, t.y0 + i as u32 / tw);
                *p = (y * w + x) ^ salt;
            }
        }
    };
    for (w, h) in [(0, 5), (5, 0), (1, 1), (37, 11), (64, 64), (100, 3), (3, 100)] {
        for size in [0, 1, 7, 16, 64, 1000, u32::MAX] {
            for threads in [1, 2, 3, 9] {
                for a in [Assignment::Static, Assignment::Dynamic] {
                    let (img, stats) = render_tiles(w, h, size, threads, a, shade(w, 0));
                    assert!(
                        img.iter().enumerate().all(|(i, &p)| p == i as u32),
                        "{w}x{h}/{size}/{threads}"
                    );
                    assert_eq!(stats.tiles_per_thread.iter().sum::<usize>(), tiles(w, h, size).len());
                    let mut again = vec![u32::MAX; (w * h) as usize];
                    for salt in [0x55, 0xAA00] {
                        render_tiles_into(&mut again, w, h, size, threads, a, shade(w, salt)).unwrap();
                        assert!(again.iter().enumerate().all(|(i, &p)| p == i as u32 ^ salt));
                    }
                }
            }
        }
    }
    let mut short = vec![7u32; 10];
    assert_eq!(
        render_tiles_into(&mut short, 4, 3, 2, 2, Assignment::Dynamic, shade(4, 0)),
        Err(ImageSizeError { expected: 12, got: 10 })
    );
    assert!(short.iter().all(|&p| p == 7));
}
