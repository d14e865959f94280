//! The `composite` target: the over (`f32`, `u8`) and depth operators, sparse images on the wire,
//! radix-k / direct-send / binary-swap / tree schedules as data and run by the executor over the
//! in-process thread transport, the k-vector cost model, the k-d visibility order and tiles.
//!
//! Input layout (every byte string decodes; values as in [`decode`](crate::decode)):
//!
//! ```text
//! header    1 byte   bit 0: mode (0 chaos, 1 grid); bits 1-2: pixel type (0 f32, 1 u8, 2 depth,
//!                    3 f32); bit 3: sparse messages; bit 4: shuffle the visibility order;
//!                    bit 5 (chaos): add a bad plan; bit 6: static tile assignment (else dynamic)
//! ranks     1 byte   P = 1 + b % 16
//! pixels    2 bytes  n = u16 % 1025
//! palette   16 pixels: f32 grid 1 byte (alpha 0, 1/2, 1, colours a j / 4), chaos 4 values;
//!           u8 grid 2 bytes (alpha 0 or 255), chaos 4 bytes; depth grid 2 bytes (depth 0..8),
//!           chaos a tag byte and a value + 4 bytes, or 8 raw bytes
//! images    per rank, runs until n pixels: 1 byte (palette index b & 15, 12..16 empty; length
//!           (1 + b >> 4) max(1, n / 64))
//! order     P - 1 bytes when shuffled (Fisher-Yates); root byte
//! schedules count byte (1 + b % 3), each a selector byte (tree, direct-send, binary-swap, auto,
//!           or a factorisation of P picked by further bytes)
//! bad plan  2 bytes (chaos, header bit 5): kind and argument
//! model     3 values (grid: bytes into tables), auto-k p (chaos: 4 bytes), pieces (4 + 4 + 1
//!           bytes), kd bounds (6 values) and view (1 byte + 3 values), tiles (3 bytes, threads
//!           byte, then 12 bytes of large sizes in chaos)
//! wire      the rest: a raw message for `decode_composite`
//! ```
//!
//! What must hold, in both modes: `over_f32_x8`, `over_u8_x8` and `depth_x4` equal their scalar
//! references bit for bit (both directions), and so do the `Pixel` methods; `EMPTY` is the
//! identity where pixels are finite (and not `-0`); sparse and dense encodings have the
//! documented sizes and decode back; every strict prefix of a message is `Truncated`, an extra
//! byte `TrailingBytes`, a short range `OutOfRange`; raw bytes decode without panic; every
//! schedule run on the thread transport returns the image on the root only, and `BadPlan` on
//! every rank for bad orders, roots and k-vectors (no hang); depth compositing equals the serial
//! reference bit for bit in any visibility order; radix-k sends at most `n (1 - 1/P) b` bytes plus
//! headers and uneven splits (dense) in `sum (k - 1)` messages; the schedules as data (final ranges
//! tile the image, groups agree, every send is a receive, pixels sent within `n (1 - 1/P)`),
//! `piece` tiles its range, tree partners pair up and reach rank 0, `auto_kvec` multiplies to `p`
//! with groups of at most `MAX_GROUP` (or direct-send); the visibility order is a permutation;
//! tiles cover the image once, in scanline order, and `render_tiles` puts every pixel in place.
//!
//! Grid mode (opacities 0, 1/2 and 1, colours of few bits, exact depths) adds: every schedule,
//! sparse or dense, equals the serial over reference **bit for bit** (over is exact on these
//! values, so the grouping of a schedule cannot change a bit); `u8` over with opacities 0 and
//! 255 likewise; `auto_kvec` is the cheapest ordered factorisation; the k-d parts tile the bounds.
//! Chaos mode compares over with the serial reference where every pixel is premultiplied with
//! channels in `[0, 1]`: within `OVER_F32_TOLERANCE` (`f32`), within `P` steps (`u8`).

use crate::decode::{Input, Mode};
use std::time::Duration;
use strahl::Aabb;
use strahl::composite::schedule::MAX_GROUP;
use strahl::composite::{Assignment, render_tiles, tiles};
use strahl::composite::{
    CompositeError, CompositeStats, CostModel, DecodeError, DepthPixel, KVec, OVER_F32_TOLERANCE, Pixel, Plan, RadixK,
    Rgba8, RgbaF32, Schedule, ThreadTransport, Transport, TransportError, View, auto_kvec, composite, composite_serial,
    decode_composite, depth_scalar, depth_x4, encode, kd_decompose, over_f32_scalar, over_f32_x8, over_u8_scalar,
    over_u8_x8, piece, tree_partner, tree_rounds, visibility_order,
};

/// Largest number of ranks.
pub const MAX_RANKS: u32 = 16;
/// Largest number of pixels per image.
pub const MAX_PIXELS: usize = 1024;
/// Largest number of tiles in the large-size tile check.
pub const MAX_TILES: u64 = 4096;

/// The partial images of a case, in their pixel type.
#[derive(Clone, Debug)]
pub enum Images {
    /// Premultiplied `f32` RGBA.
    F32(Vec<Vec<RgbaF32>>),
    /// Premultiplied `u8` RGBA.
    U8(Vec<Vec<Rgba8>>),
    /// Depth samples.
    Depth(Vec<Vec<DepthPixel>>),
}

/// One compositing run: a plan for every rank, and whether it is valid.
#[derive(Clone, Debug)]
pub struct Run {
    /// The schedule.
    pub schedule: Schedule,
    /// The visibility order.
    pub order: Vec<u32>,
    /// The root rank.
    pub root: u32,
    /// Sparse messages.
    pub sparse: bool,
    /// `false` for a bad plan (every rank must refuse it).
    pub valid: bool,
}

/// A decoded `composite` input.
#[derive(Clone, Debug)]
pub struct CompositeCase {
    /// The input mode.
    pub mode: Mode,
    /// One image per rank (transport rank `r` has `images[r]`).
    pub images: Images,
    /// The compositing runs.
    pub runs: Vec<Run>,
    /// A cost model for `auto_kvec`.
    pub model: CostModel,
    /// A rank count for `auto_kvec` alone (up to 2^20, possibly 0).
    pub auto_p: u32,
    /// A pixel count for the schedules as data (any `u32` in chaos mode).
    pub big_n: u32,
    /// `(start, end, k)` for `piece`.
    pub piece: (u32, u32, u32),
    /// Bounds for the k-d decomposition.
    pub bounds: Aabb,
    /// The view for the visibility order.
    pub view: View,
    /// `(width, height, tile size, threads)` of a small tiled render.
    pub tiles: (u32, u32, u32, usize),
    /// Static (else dynamic) tile assignment.
    pub static_tiles: bool,
    /// `(width, height, tile size)` of any size (chaos), checked where at most [`MAX_TILES`].
    pub big_tiles: Option<(u32, u32, u32)>,
    /// A raw message.
    pub wire: Vec<u8>,
}

const LATENCIES: [f64; 4] = [0.0, 1e-6, 5e-6, 1.0];
const PER_BYTE: [f64; 4] = [0.0, 1e-10, 2e-10, 1.0];
const PER_BLEND: [f64; 4] = [0.0, 1e-9, 3e-9, 1.0];

impl CompositeCase {
    /// Decodes `data` (see the module docs); never fails.
    pub fn decode(data: &[u8]) -> Self {
        let mut inp = Input::new(data);
        let h = inp.byte();
        let mode = Mode::of_header(h);
        let grid = mode == Mode::Grid;
        let kind = (h >> 1) & 3;
        let sparse = h & 8 != 0;
        let p = 1 + u32::from(inp.byte()) % MAX_RANKS;
        let n = usize::from(u16::from_le_bytes([inp.byte(), inp.byte()])) % (MAX_PIXELS + 1);

        let images = match kind {
            1 => Images::U8(images(&mut inp, p, n, |inp| {
                if grid {
                    let (a, c) = (inp.byte(), inp.byte());
                    let a = if a & 1 == 0 { 0 } else { 255 };
                    Rgba8([c, c.rotate_left(3), c ^ 0x5a, a])
                } else {
                    Rgba8(inp.u32().to_le_bytes())
                }
            })),
            2 => Images::Depth(images(&mut inp, p, n, |inp| {
                if grid {
                    let (z, c) = (inp.byte(), inp.byte());
                    DepthPixel::new(f32::from(z % 8), u32::from(c) * 0x0101_0101)
                } else if inp.byte() < 0xc0 {
                    let z = inp.chaos();
                    DepthPixel::new(z, inp.u32())
                } else {
                    DepthPixel(u64::from(inp.u32()) | u64::from(inp.u32()) << 32)
                }
            })),
            _ => Images::F32(images(&mut inp, p, n, |inp| {
                if grid {
                    let b = inp.byte();
                    let a = [0.0, 0.5, 1.0, 0.5][usize::from(b & 3)];
                    let unit = if a == 0.0 { 0.125 } else { a };
                    let c = |s: u8| unit * [0.0, 1.0, 2.0, 4.0][usize::from((b >> s) & 3)] / 4.0;
                    RgbaF32([c(2), c(4), c(6), a])
                } else {
                    RgbaF32([inp.chaos(), inp.chaos(), inp.chaos(), inp.chaos()])
                }
            })),
        };

        // Visibility order and root.
        let mut order: Vec<u32> = (0..p).collect();
        if h & 16 != 0 {
            for i in (1..order.len()).rev() {
                order.swap(i, usize::from(inp.byte()) % (i + 1));
            }
        }
        let root = u32::from(inp.byte()) % p;

        // Schedules.
        let count = 1 + inp.byte() % 3;
        let pixels = n as u64;
        let mut runs: Vec<Run> = (0..count)
            .map(|_| {
                let s = inp.byte();
                let schedule = match s % 8 {
                    0 => Schedule::Tree,
                    1 => Schedule::RadixK(KVec::direct_send(p)),
                    2 => Schedule::RadixK(KVec::binary_swap(p).unwrap_or(KVec::direct_send(p))),
                    3 => Schedule::RadixK(auto_kvec(p, pixels.max(1), 16, &CostModel::shared_memory())),
                    _ => Schedule::RadixK(factorisation(&mut inp, p)),
                };
                Run {
                    schedule,
                    order: order.clone(),
                    root,
                    sparse: if s & 0x80 != 0 { !sparse } else { sparse },
                    valid: true,
                }
            })
            .collect();
        if !grid && h & 32 != 0 {
            let (k, arg) = (inp.byte(), inp.byte());
            let mut bad = Run {
                schedule: Schedule::RadixK(KVec::direct_send(p)),
                order: order.clone(),
                root,
                sparse,
                valid: false,
            };
            match k % 4 {
                0 if p >= 2 => bad.order[1] = bad.order[0],
                1 => bad.order[usize::from(arg) % p as usize] = p + u32::from(arg),
                2 => bad.root = p + u32::from(arg),
                _ => {
                    // A k-vector whose product is not P.
                    let f = 2 + u32::from(arg) % 15;
                    let kv = KVec::new(&[f]).unwrap_or(KVec::direct_send(p + 1));
                    bad.schedule = Schedule::RadixK(if kv.ranks() == p { KVec::direct_send(p + 1) } else { kv });
                }
            }
            if bad.order.len() < 2 && k % 4 == 0 {
                bad.root = p;
            }
            runs.push(bad);
        }

        // Cost model, pure schedule data, order, tiles.
        let model = if grid {
            CostModel {
                latency: LATENCIES[usize::from(inp.byte()) % 4],
                seconds_per_byte: PER_BYTE[usize::from(inp.byte()) % 4],
                seconds_per_blend: PER_BLEND[usize::from(inp.byte()) % 4],
            }
        } else {
            CostModel {
                latency: f64::from(inp.chaos()),
                seconds_per_byte: f64::from(inp.chaos()),
                seconds_per_blend: f64::from(inp.chaos()),
            }
        };
        let auto_p = if grid { p } else { inp.u32() % (1 << 20) };
        let big_n = if grid { n as u32 } else { inp.u32() };
        let (a, b) = (inp.u32(), inp.u32());
        let piece = if grid {
            (a % 64, a % 64 + b % 64, 1 + u32::from(inp.byte()) % 8)
        } else {
            (a.min(b), a.max(b), 1 + u32::from(inp.byte()))
        };
        let (c0, c1) = (inp.vec3(mode), inp.vec3(mode));
        let bounds = if grid {
            Aabb::new(c0.min(c1), c0.max(c1))
        } else {
            Aabb::new(c0, c1)
        };
        let vb = inp.byte();
        let v = inp.vec3(mode);
        let view = if vb & 1 == 0 { View::Eye(v) } else { View::Direction(v) };
        let tiles = (
            u32::from(inp.byte()) % 33,
            u32::from(inp.byte()) % 33,
            u32::from(inp.byte()) % 12,
            1 + usize::from(inp.byte()) % 4,
        );
        let big_tiles = if grid {
            None
        } else {
            Some((inp.u32(), inp.u32(), inp.u32()))
        };
        let mut wire = Vec::new();
        while !inp.is_exhausted() {
            wire.push(inp.byte());
        }
        Self {
            mode,
            images,
            runs,
            model,
            auto_p,
            big_n,
            piece,
            bounds,
            view,
            tiles,
            static_tiles: h & 64 != 0,
            big_tiles,
            wire,
        }
    }
}

/// A 16-entry palette, then every rank's image as runs of palette entries.
fn images<P: Pixel>(inp: &mut Input, p: u32, n: usize, mut px: impl FnMut(&mut Input) -> P) -> Vec<Vec<P>> {
    let palette: Vec<P> = (0..16).map(|_| px(inp)).collect();
    let unit = (n / 64).max(1);
    (0..p)
        .map(|_| {
            let mut img = Vec::with_capacity(n);
            while img.len() < n {
                let b = inp.byte();
                let i = usize::from(b & 15);
                let v = if i >= 12 { P::EMPTY } else { palette[i] };
                let len = ((1 + usize::from(b >> 4)) * unit).min(n - img.len());
                img.extend(core::iter::repeat_n(v, len));
            }
            img
        })
        .collect()
}

/// An ordered factorisation of `p`, each factor a divisor (>= 2) of what is left, picked by a byte.
fn factorisation(inp: &mut Input, p: u32) -> KVec {
    let mut f = Vec::new();
    let mut m = p;
    while m > 1 {
        let divs: Vec<u32> = (2..=m).filter(|d| m.is_multiple_of(*d)).collect();
        let d = divs[usize::from(inp.byte()) % divs.len()];
        f.push(d);
        m /= d;
    }
    KVec::new(&f).unwrap_or(KVec::direct_send(p))
}

/// How the checker compares and inspects one pixel type.
pub trait FuzzPixel: Pixel {
    /// The pixel as the words the scalar and SIMD kernels take.
    type Word: Copy + PartialEq + core::fmt::Debug;
    /// Flattens pixels to words.
    fn words(px: &[Self]) -> Vec<Self::Word>;
    /// Same bits.
    fn same(a: &Self, b: &Self) -> bool;
    /// Premultiplied with channels in `[0, 1]` (always true for depth).
    fn tame(&self) -> bool;
    /// Within the documented tolerance of a schedule against the serial reference, for `p` tame
    /// images.
    fn close(a: &Self, b: &Self, p: u32) -> bool;
    /// Equal up to the sign of zero and NaN payloads (what compositing with `EMPTY` gives).
    fn equivalent(a: &Self, b: &Self) -> bool;
    /// Same word, or (`f32`) both NaN: Rust does not specify the payload or sign of a NaN that
    /// arithmetic makes, so bit-identity stops at NaN.
    fn same_word(a: Self::Word, b: Self::Word) -> bool;
    /// Runs the scalar reference and the SIMD kernel on words; returns both results.
    fn kernels(acc: &[Self::Word], other: &[Self::Word], acc_in_front: bool) -> (Vec<Self::Word>, Vec<Self::Word>);
}

fn f32_equivalent(a: f32, b: f32) -> bool {
    a == b || (a.is_nan() && b.is_nan())
}

impl FuzzPixel for RgbaF32 {
    type Word = u32;
    fn same_word(a: u32, b: u32) -> bool {
        a == b || (f32::from_bits(a).is_nan() && f32::from_bits(b).is_nan())
    }
    fn words(px: &[Self]) -> Vec<u32> {
        px.iter().flat_map(|p| p.0.map(f32::to_bits)).collect()
    }
    fn same(a: &Self, b: &Self) -> bool {
        a.0.map(f32::to_bits) == b.0.map(f32::to_bits)
    }
    fn tame(&self) -> bool {
        let [r, g, b, a] = self.0;
        (0.0..=1.0).contains(&a) && [r, g, b].iter().all(|c| (0.0..=a).contains(c))
    }
    fn close(a: &Self, b: &Self, _p: u32) -> bool {
        (0..4).all(|c| (a.0[c] - b.0[c]).abs() <= OVER_F32_TOLERANCE)
    }
    fn equivalent(a: &Self, b: &Self) -> bool {
        (0..4).all(|c| f32_equivalent(a.0[c], b.0[c]))
    }
    fn kernels(acc: &[u32], other: &[u32], acc_in_front: bool) -> (Vec<u32>, Vec<u32>) {
        let other: Vec<f32> = other.iter().map(|&w| f32::from_bits(w)).collect();
        let mut s: Vec<f32> = acc.iter().map(|&w| f32::from_bits(w)).collect();
        let mut v = s.clone();
        over_f32_scalar(&mut s, &other, acc_in_front);
        over_f32_x8(&mut v, &other, acc_in_front);
        (
            s.iter().map(|x| x.to_bits()).collect(),
            v.iter().map(|x| x.to_bits()).collect(),
        )
    }
}

impl FuzzPixel for Rgba8 {
    type Word = u32;
    fn same_word(a: u32, b: u32) -> bool {
        a == b
    }
    fn words(px: &[Self]) -> Vec<u32> {
        px.iter().map(|p| u32::from_le_bytes(p.0)).collect()
    }
    fn same(a: &Self, b: &Self) -> bool {
        a == b
    }
    fn tame(&self) -> bool {
        self.0[..3].iter().all(|&c| c <= self.0[3])
    }
    fn close(a: &Self, b: &Self, p: u32) -> bool {
        (0..4).all(|c| u32::from(a.0[c].abs_diff(b.0[c])) <= p)
    }
    fn equivalent(a: &Self, b: &Self) -> bool {
        a == b
    }
    fn kernels(acc: &[u32], other: &[u32], acc_in_front: bool) -> (Vec<u32>, Vec<u32>) {
        let (mut s, mut v) = (acc.to_vec(), acc.to_vec());
        over_u8_scalar(&mut s, other, acc_in_front);
        over_u8_x8(&mut v, other, acc_in_front);
        (s, v)
    }
}

impl FuzzPixel for DepthPixel {
    type Word = u64;
    fn same_word(a: u64, b: u64) -> bool {
        a == b
    }
    fn words(px: &[Self]) -> Vec<u64> {
        px.iter().map(|p| p.0).collect()
    }
    fn same(a: &Self, b: &Self) -> bool {
        a == b
    }
    fn tame(&self) -> bool {
        true
    }
    fn close(a: &Self, b: &Self, _p: u32) -> bool {
        a == b
    }
    fn equivalent(a: &Self, b: &Self) -> bool {
        a == b
    }
    fn kernels(acc: &[u64], other: &[u64], _acc_in_front: bool) -> (Vec<u64>, Vec<u64>) {
        let (mut s, mut v) = (acc.to_vec(), acc.to_vec());
        depth_scalar(&mut s, other);
        depth_x4(&mut v, other);
        (s, v)
    }
}

/// What a checked case exercised (for the seed tests: seeds should not be vacuous).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CompositeReport {
    /// Valid runs composited and compared.
    pub runs: usize,
    /// Bad plans refused by every rank.
    pub bad_plans: usize,
    /// Non-empty pixels of the composited images.
    pub covered: usize,
    /// Runs compared with the serial reference (bit for bit, or within the tolerance).
    pub compared: usize,
}

/// Runs every check on `case` (see the module docs); panics on the first violation.
pub fn check_composite(case: &CompositeCase) -> CompositeReport {
    let report = match &case.images {
        Images::F32(im) => check_images(case, im),
        Images::U8(im) => check_images(case, im),
        Images::Depth(im) => {
            check_depth_pixels(im);
            check_images(case, im)
        }
    };
    check_schedule_data(case);
    check_order(case);
    check_tiles(case);
    report
}

fn check_images<P: FuzzPixel>(case: &CompositeCase, images: &[Vec<P>]) -> CompositeReport {
    let mut report = CompositeReport::default();
    let grid = case.mode == Mode::Grid;
    let p = images.len() as u32;
    let a = &images[0];
    let b = &images[images.len().min(2) - 1];

    // Kernels: SIMD against scalar, and the Pixel methods (which call the SIMD forms).
    for front in [true, false] {
        let (s, v) = P::kernels(&P::words(a), &P::words(b), front);
        let same =
            |x: &[P::Word], y: &[P::Word]| x.len() == y.len() && x.iter().zip(y).all(|(a, b)| P::same_word(*a, *b));
        assert!(
            same(&s, &v),
            "scalar and SIMD differ (acc_in_front {front}): {s:?} {v:?}"
        );
        let mut x = a.clone();
        if front {
            P::composite_behind(&mut x, b);
        } else {
            P::composite_in_front(&mut x, b);
        }
        assert!(
            same(&P::words(&x), &s),
            "Pixel method and scalar reference differ (acc_in_front {front})"
        );
    }
    // EMPTY is the identity (up to -0 and NaN payloads outside grid mode) for tame pixels.
    let empty = vec![P::EMPTY; a.len()];
    for op in [P::composite_behind, P::composite_in_front] {
        let mut x = a.clone();
        op(&mut x, &empty);
        for (i, (y, z)) in x.iter().zip(a).enumerate() {
            if grid {
                assert!(P::same(y, z), "pixel {i}: {z:?} with EMPTY gave {y:?}");
            } else if z.tame() {
                assert!(P::equivalent(y, z), "pixel {i}: {z:?} with EMPTY gave {y:?}");
            }
        }
    }

    check_wire(a, grid);
    let mut acc = vec![P::EMPTY; a.len()];
    let _ = decode_composite(&case.wire, &mut acc, true);
    let _ = decode_composite(&case.wire, &mut acc, false);
    let _ = decode_composite(&case.wire, &mut acc[..a.len() / 2], false);

    // Serial references: in visibility order, and in rank order (any order for depth).
    let by_rank: Vec<&[P]> = images.iter().map(|v| v.as_slice()).collect();
    let serial_rank = composite_serial(&by_rank);
    let tame = images.iter().flatten().all(|px| px.tame());
    let depth = core::any::TypeId::of::<P>() == core::any::TypeId::of::<DepthPixel>();
    let results = run_all(images, &case.runs);
    for (run, per_rank) in case.runs.iter().zip(&results) {
        if !run.valid {
            for (r, res) in per_rank.iter().enumerate() {
                assert_eq!(
                    res.as_ref().map(|_| ()),
                    Err(&CompositeError::BadPlan),
                    "rank {r}: {run:?}"
                );
            }
            report.bad_plans += 1;
            continue;
        }
        let in_order: Vec<&[P]> = run.order.iter().map(|&r| images[r as usize].as_slice()).collect();
        let serial = composite_serial(&in_order);
        let mut got = None;
        for (r, res) in per_rank.iter().enumerate() {
            let (img, stats) = res.as_ref().unwrap_or_else(|e| panic!("rank {r}: {e} ({run:?})"));
            assert_eq!(
                img.is_some(),
                r as u32 == run.root,
                "rank {r}: image only on the root ({run:?})"
            );
            if let Some(img) = img {
                got = Some(img);
            }
            check_stats(run, stats, p, a.len(), P::BYTES);
        }
        let got = got.expect("the root has the image");
        assert_eq!(got.len(), a.len());
        report.runs += 1;
        report.covered += got.iter().filter(|x| **x != P::EMPTY).count();
        report.compared += usize::from(grid || tame || depth);
        // Depth: the same bits in any order; over: in visibility order, exactly on the grid.
        if depth {
            for (i, (x, y)) in got.iter().zip(&serial_rank).enumerate() {
                assert!(P::same(x, y), "pixel {i}: {x:?}, serial {y:?} ({run:?})");
            }
        }
        for (i, (x, y)) in got.iter().zip(&serial).enumerate() {
            if grid {
                assert!(P::same(x, y), "pixel {i}: {x:?}, serial {y:?} ({run:?})");
            } else if tame {
                assert!(P::close(x, y, p), "pixel {i}: {x:?}, serial {y:?} ({run:?})");
            }
        }
    }
    report
}

/// Encodings have the documented sizes, decode back, and malformed ones are errors.
fn check_wire<P: FuzzPixel>(px: &[P], grid: bool) {
    for sparse in [true, false] {
        let mut wire = vec![0xab];
        encode(px, sparse, &mut wire);
        assert_eq!(wire[0], 0xab, "encode appends");
        let wire = &wire[1..];
        let active: Vec<usize> = (0..px.len()).filter(|&i| px[i] != P::EMPTY).collect();
        let runs = (0..px.len())
            .filter(|&i| px[i] != P::EMPTY && (i == 0 || px[i - 1] == P::EMPTY))
            .count();
        let want = if sparse {
            8 + 8 * runs + active.len() * P::BYTES
        } else if px.is_empty() {
            8
        } else {
            16 + px.len() * P::BYTES
        };
        assert_eq!(wire.len(), want, "sparse {sparse}: {} pixels", px.len());
        let mut acc = vec![P::EMPTY; px.len()];
        decode_composite(wire, &mut acc, true).expect("a valid message");
        for (i, (x, y)) in acc.iter().zip(px).enumerate() {
            if grid {
                assert!(P::same(x, y), "pixel {i}: decoded {x:?}, encoded {y:?}");
            } else {
                assert!(P::equivalent(x, y), "pixel {i}: decoded {x:?}, encoded {y:?}");
            }
        }
        for cut in [0, 3, wire.len() / 2, wire.len().saturating_sub(1)] {
            if cut < wire.len() {
                assert_eq!(
                    decode_composite(&wire[..cut], &mut acc, true),
                    Err(DecodeError::Truncated),
                    "prefix of {cut} bytes"
                );
            }
        }
        let mut longer = wire.to_vec();
        longer.push(0);
        assert_eq!(
            decode_composite(&longer, &mut acc, false),
            Err(DecodeError::TrailingBytes)
        );
        // One pixel short of the last run's end.
        let end = if sparse {
            active.last().map(|&i| i + 1)
        } else {
            Some(px.len()).filter(|&n| n > 0)
        };
        if let Some(end) = end {
            // Into a shorter range: refused by the length in the header.
            assert_eq!(
                decode_composite(wire, &mut acc[..end - 1], true),
                Err(DecodeError::LengthMismatch)
            );
            // The same message claiming that shorter length: its runs reach past it.
            let mut forged = wire.to_vec();
            forged[4..8].copy_from_slice(&((end - 1) as u32).to_le_bytes());
            assert_eq!(
                decode_composite(&forged, &mut acc[..end - 1], true),
                Err(DecodeError::OutOfRange)
            );
        }
    }
}

/// Depth keys: round trip of depth and colour, never `EMPTY`, ordered like `total_cmp`.
fn check_depth_pixels(images: &[Vec<DepthPixel>]) {
    let mut seen: Vec<DepthPixel> = images.iter().flatten().copied().filter(|p| !p.is_empty()).collect();
    seen.sort_unstable();
    seen.dedup();
    for w in seen.windows(2).take(64) {
        let (a, b) = (w[0], w[1]);
        let (za, zb) = (a.depth(), b.depth());
        let mk = |p: DepthPixel| DepthPixel::new(p.depth(), p.rgba());
        // Keys made by `new` order by depth, then colour.
        if mk(a) == a && mk(b) == b {
            assert!(za.total_cmp(&zb).then(a.rgba().cmp(&b.rgba())).is_lt(), "{a:?} {b:?}");
        }
    }
    for p in seen.iter().take(64) {
        let z = p.depth();
        let q = DepthPixel::new(z, p.rgba());
        assert!(!q.is_empty());
        assert_eq!(
            q.depth().to_bits(),
            if z.is_nan() {
                f32::INFINITY.to_bits()
            } else {
                z.to_bits()
            }
        );
        assert_eq!(q.rgba(), p.rgba());
    }
    assert_eq!(DepthPixel::new(f32::NAN, 7).depth(), f32::INFINITY);
    assert_eq!(DepthPixel::EMPTY.depth(), f32::INFINITY);
    assert_eq!(DepthPixel::EMPTY.rgba(), 0);
}

/// Bytes and messages of one rank against the cost the schedules promise.
fn check_stats(run: &Run, stats: &CompositeStats, p: u32, n: usize, bytes: usize) {
    match run.schedule {
        Schedule::RadixK(k) => {
            let messages: u32 = k.as_slice().iter().map(|k| k - 1).sum();
            assert_eq!(stats.messages, messages, "{run:?}");
            assert_eq!(stats.round_seconds.len(), k.rounds() + 1);
            if !run.sparse {
                let b = bytes as f64;
                let header = strahl::composite::sparse::header_bytes(1) as f64;
                let slack = f64::from(messages) * header + f64::from(k.as_slice().iter().sum::<u32>()) * b;
                let bound = n as f64 * (1.0 - 1.0 / f64::from(p)) * b + slack;
                assert!(
                    stats.bytes_sent as f64 <= bound,
                    "{run:?}: {} > {bound}",
                    stats.bytes_sent
                );
            }
        }
        Schedule::Tree => {
            assert!(stats.messages <= 1, "{run:?}: {stats:?}");
            assert_eq!(stats.round_seconds.len(), tree_rounds(p) as usize + 1);
        }
    }
}

/// A transport that shifts every tag, so that several compositing runs can share one group.
struct Shifted<'a> {
    t: &'a mut ThreadTransport,
    base: u32,
}

impl Transport for Shifted<'_> {
    fn rank(&self) -> u32 {
        self.t.rank()
    }
    fn size(&self) -> u32 {
        self.t.size()
    }
    fn exchange(&mut self, tag: u32, sends: Vec<(u32, Vec<u8>)>, from: &[u32]) -> Result<Vec<Vec<u8>>, TransportError> {
        self.t.exchange(tag + self.base, sends, from)
    }
}

type RankResult<P> = Result<(Option<Vec<P>>, CompositeStats), CompositeError>;

/// Every run, on one thread per rank; `result[run][rank]`.
fn run_all<P: Pixel>(images: &[Vec<P>], runs: &[Run]) -> Vec<Vec<RankResult<P>>> {
    let p = images.len() as u32;
    let per_rank = ThreadTransport::run(p, |t| {
        // A deadlock shows as a transport error, not a hang.
        t.timeout = Duration::from_secs(20);
        let me = t.rank() as usize;
        runs.iter()
            .enumerate()
            .map(|(i, run)| {
                let plan = Plan {
                    schedule: run.schedule,
                    order: &run.order,
                    root: run.root,
                    sparse: run.sparse,
                };
                let mut s = Shifted {
                    t: &mut *t,
                    base: 64 * i as u32,
                };
                composite(&mut s, &images[me], &plan)
            })
            .collect::<Vec<_>>()
    });
    let mut out: Vec<Vec<RankResult<P>>> = runs.iter().map(|_| Vec::new()).collect();
    for rank in per_rank {
        for (i, r) in rank.into_iter().enumerate() {
            out[i].push(r);
        }
    }
    out
}

/// The schedules as pure data, `piece`, the tree and `auto_kvec`.
fn check_schedule_data(case: &CompositeCase) {
    let grid = case.mode == Mode::Grid;
    let p = match &case.images {
        Images::F32(v) => v.len(),
        Images::U8(v) => v.len(),
        Images::Depth(v) => v.len(),
    } as u32;
    for run in case.runs.iter().filter(|r| r.valid) {
        if let Schedule::RadixK(k) = run.schedule {
            assert_eq!(k.ranks(), p);
            check_radix_k(k, case.big_n);
            check_radix_k(k, case.big_n % 1000);
        }
    }
    check_tree(p);

    // piece: consecutive pieces tile the range.
    let (s, e, k) = case.piece;
    let r = s..e;
    let mut at = s;
    for j in 0..k {
        let q = piece(&r, j, k);
        assert_eq!(q.start, at, "piece {j} of {k} of {r:?}");
        assert!(q.start <= q.end && q.end <= e);
        at = q.end;
    }
    assert_eq!(at, e);

    // auto_kvec: a valid k-vector for p, the cheapest one on the grid.
    let pixels = u64::from(case.big_n).max(1);
    let kv = auto_kvec(case.auto_p, pixels, 16, &case.model);
    assert_eq!(kv.ranks(), case.auto_p.max(1), "{kv:?}");
    assert_eq!(KVec::new(kv.as_slice()), Some(kv));
    assert!(
        kv.as_slice() == [case.auto_p] || kv.as_slice().iter().all(|&k| k as usize <= MAX_GROUP),
        "{kv:?}"
    );
    check_radix_k(kv, case.big_n % 4096);
    if grid {
        let best = case.model.cost(&kv, pixels, 16);
        for f in ordered_factorisations(case.auto_p) {
            let other = KVec::new(&f).expect("factors >= 2");
            let c = case.model.cost(&other, pixels, 16);
            assert!(best <= c * (1.0 + 1e-12), "auto {kv:?} costs {best}, {other:?} {c}");
        }
    }
}

fn ordered_factorisations(p: u32) -> Vec<Vec<u32>> {
    if p <= 1 {
        return vec![vec![]];
    }
    let mut all = Vec::new();
    for d in (2..=p).filter(|d| p.is_multiple_of(*d)) {
        for mut rest in ordered_factorisations(p / d) {
            rest.insert(0, d);
            all.push(rest);
        }
    }
    all
}

/// The radix-k invariants for every virtual rank (sampled above 64 ranks).
fn check_radix_k(k: KVec, n: u32) {
    let p = k.ranks();
    let s = RadixK::new(k, n);
    let vs: Vec<u32> = if p <= 64 {
        (0..p).collect()
    } else {
        [0, 1, p / 3, p / 2, p - 2, p - 1]
            .into_iter()
            .filter(|&v| v < p)
            .collect()
    };
    let slack: u64 = k.as_slice().iter().map(|&x| u64::from(x)).sum();
    for &v in &vs {
        for round in 0..k.rounds() {
            let g = s.group(v, round);
            let d = s.digit(v, round);
            assert_eq!(s.member(v, round, d), v);
            if (k.as_slice()[round] as usize) <= MAX_GROUP {
                assert_eq!(g[d as usize], v, "{k:?} v {v} round {round}");
            }
            let r = s.region(v, round);
            let inner = s.region(v, round + 1);
            assert!(
                r.start <= inner.start && inner.end <= r.end,
                "{k:?} v {v} round {round}"
            );
            if p <= 64 {
                for &m in g.iter() {
                    assert_eq!(s.region(m, round), r, "{k:?}: group members share a range");
                    assert_eq!(s.group(m, round), g);
                }
                for msg in s.sends(v, round) {
                    assert!(
                        s.receives(msg.to, round).any(|x| x == msg),
                        "{k:?}: {msg:?} not received"
                    );
                }
            }
        }
        if p <= 64 {
            let sent = s.pixels_sent(v);
            let bound = f64::from(n) * (1.0 - 1.0 / f64::from(p)) + slack as f64;
            assert!(sent as f64 <= bound, "{k:?} n {n} v {v}: {sent} > {bound}");
        }
    }
    if p <= 64 {
        let mut ranges: Vec<(u32, u32)> = (0..p).map(|v| s.final_region(v)).map(|r| (r.start, r.end)).collect();
        ranges.sort_unstable();
        let mut at = 0;
        for (a, b) in ranges {
            assert_eq!(a, at, "{k:?} n {n}: final ranges must tile the image");
            at = b;
        }
        assert_eq!(at, n);
    }
}

/// Tree partners pair up, and after `tree_rounds` every image has reached rank 0.
fn check_tree(p: u32) {
    let mut merged = vec![1u32; p as usize];
    for round in 0..tree_rounds(p) {
        let before = merged.clone();
        for v in 0..p {
            if let Some((w, receive)) = tree_partner(v, round, p) {
                assert!(w < p);
                assert_eq!(tree_partner(w, round, p), Some((v, !receive)));
                if receive {
                    merged[v as usize] += before[w as usize];
                }
            }
        }
    }
    assert_eq!(merged[0], p);
    assert_eq!(tree_rounds(p), if p <= 1 { 0 } else { 32 - (p - 1).leading_zeros() });
}

/// The visibility order is a permutation; on the grid the k-d parts tile the bounds.
fn check_order(case: &CompositeCase) {
    let p = case.runs[0].order.len();
    let mut parts = vec![Aabb::EMPTY; p];
    kd_decompose(&case.bounds, &mut parts);
    let mut order = vec![u32::MAX; p];
    visibility_order(&case.bounds, case.view, &mut order);
    let mut seen = vec![false; p];
    for &o in &order {
        assert!((o as usize) < p && !seen[o as usize], "{order:?} is not a permutation");
        seen[o as usize] = true;
    }
    if case.mode == Mode::Grid {
        let b = case.bounds;
        let vol = |a: &Aabb| {
            let e = a.max - a.min;
            f64::from(e.x) * f64::from(e.y) * f64::from(e.z)
        };
        let total: f64 = parts.iter().map(vol).sum();
        assert!((total - vol(&b)).abs() <= 1e-5 * vol(&b).max(1.0), "{parts:?}");
        for q in &parts {
            assert!(b.contains(q) && q.min.cmple(q.max).all(), "{q:?} outside {b:?}");
        }
    }
}

/// Tiles cover the image once in scanline order; a tiled render puts every pixel in place.
fn check_tiles(case: &CompositeCase) {
    let (w, h, size, threads) = case.tiles;
    check_tile_list(w, h, size);
    let assignment = if case.static_tiles {
        Assignment::Static
    } else {
        Assignment::Dynamic
    };
    let (img, stats) = render_tiles(w, h, size, threads, assignment, |t, out: &mut [u32]| {
        let tw = t.x1 - t.x0;
        for (i, p) in out.iter_mut().enumerate() {
            let (x, y) = (t.x0 + i as u32 % tw, t.y0 + i as u32 / tw);
            *p = y * w + x;
        }
    });
    assert_eq!(img.len(), (w * h) as usize);
    assert!(
        img.iter().enumerate().all(|(i, &p)| p == i as u32),
        "render_tiles misplaced pixels"
    );
    let count = tiles(w, h, size).len();
    let t = threads.clamp(1, count.max(1));
    assert_eq!(stats.tiles_per_thread.len(), t);
    assert_eq!(stats.busy_seconds.len(), t);
    assert_eq!(stats.tiles_per_thread.iter().sum::<usize>(), count);
    if assignment == Assignment::Static {
        for (i, &k) in stats.tiles_per_thread.iter().enumerate() {
            assert_eq!(k, (i + 1) * count / t - i * count / t);
        }
    }
    assert!(stats.imbalance().is_finite());
    if let Some((w, h, size)) = case.big_tiles {
        let s = u64::from(size.max(1));
        let count = u64::from(w).div_ceil(s) * u64::from(h).div_ceil(s);
        if count <= MAX_TILES {
            check_tile_list(w, h, size);
        }
    }
}

fn check_tile_list(w: u32, h: u32, size: u32) {
    let list = tiles(w, h, size);
    let s = u64::from(size.max(1));
    assert_eq!(list.len() as u64, u64::from(w).div_ceil(s) * u64::from(h).div_ceil(s));
    let mut total = 0u64;
    for (i, t) in list.iter().enumerate() {
        assert!(
            t.x0 < t.x1 && t.x1 <= w && t.y0 < t.y1 && t.y1 <= h,
            "tile {i} {t:?} of {w} x {h} by {size}"
        );
        assert!(u64::from(t.x1 - t.x0) <= s && u64::from(t.y1 - t.y0) <= s);
        if i > 0 {
            let q = list[i - 1];
            assert!((q.y0, q.x0) < (t.y0, t.x0), "scanline order");
        }
        total += t.pixels() as u64;
    }
    assert_eq!(total, u64::from(w) * u64::from(h));
    if u64::from(w) * u64::from(h) <= 4096 {
        let mut covered = vec![0u8; (w * h) as usize];
        for t in &list {
            for y in t.y0..t.y1 {
                for x in t.x0..t.x1 {
                    covered[(y * w + x) as usize] += 1;
                }
            }
        }
        assert!(covered.iter().all(|&c| c == 1), "tiles overlap or leave gaps");
    }
}
