//! Bytes -> rays, triangles and boxes, in the two input modes.
//!
//! Every byte string decodes to something: a reader past the end yields zero bytes, so libFuzzer
//! may cut, splice and grow inputs freely. The layout of a `kernels` input:
//!
//! ```text
//! header   1 byte    bit 0: mode (0 chaos, 1 grid)
//!                    bit 1: aim the ray at a point of a triangle
//!                    bit 2: turn +0 direction components into -0
//! tris     8 x 3 vertices, each: 1 ref byte; ref >= 0x80 reuses pool[(ref & 0x7f) % len]
//!                    (shared vertices, as in a mesh), else a new vertex of 3 values follows
//! ray      origin (3 values), then either aim (tri byte, 2 or 3 weight bytes) or direction
//!          (3 values), then a range selector byte (chaos: >= 0x80 reads tmin, tmax as 2 values)
//! boxes    8 x (kind byte: low 3 bits the kind, high 5 its argument; corners as 0, 3 or 6 values)
//! packet   7 variant bytes (low 3 bits the variant, high 5 its argument): lanes 1..8 of the
//!          ray packet; lane 0 is the ray itself
//! ```
//!
//! A *value* is one coordinate. In [`Mode::Grid`] it is one byte, an integer in `[-8, 8]`. In
//! [`Mode::Chaos`] it is a tag byte: `0x00..=0x3f` picks one of [`SPECIALS`], `0x40..=0x7f` a
//! quarter step in `[-8, 7.75]`, and `0x80..=0xff` reads the next 4 bytes as raw little-endian
//! `f32` bits (any NaN payload, infinity, subnormal, `-0`).

use core::fmt;
use strahl::geometry::Triangle;
use strahl::{Aabb, Ray, Vec3};

/// Special `f32` values the chaos mode reaches with a single tag byte.
pub const SPECIALS: [f32; 32] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    f32::NAN,
    f32::from_bits(0xffc0_0000), // negative quiet NaN
    f32::from_bits(0x7f80_0001), // signalling NaN
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MIN_POSITIVE,
    -f32::MIN_POSITIVE,
    1.0e-40, // subnormal
    -1.0e-40,
    f32::from_bits(1),           // smallest subnormal
    f32::from_bits(0x007f_ffff), // largest subnormal
    f32::MAX,
    f32::MIN,
    f32::EPSILON,
    1.0 + f32::EPSILON,
    1.0 - f32::EPSILON / 2.0,
    0.5,
    2.0,
    0.1,
    1.0 / 3.0,
    1.0e-20,
    1.0e20,
    -1.0e20,
    1.8e19, // its square overflows
    65536.0,
    16_777_216.0, // 2^24: the last exactly-integer f32 spacing of 1
    -3.0,
    8.0,
];

/// Ray ranges `(tmin, tmax)` picked by a selector byte: the usual, empty, touching and negative.
///
/// Grid mode uses only these, so `tmin` and `tmax` are exact dyadic rationals.
pub const RANGES: [(f32, f32); 14] = [
    (0.0, f32::INFINITY),
    (0.0, 1.0),
    (0.5, 1.5),
    (1.0, 1.0),
    (0.0, 0.999),
    (f32::NEG_INFINITY, f32::INFINITY),
    (1.0, 2.0),
    (2.0, 1.0),
    (-1.0, 0.0),
    (0.0, 0.5),
    (0.25, 1.0),
    (-0.0, f32::INFINITY),
    (1.0 / 3.0, 0.75),
    (0.0, 1.0e-30),
];

/// How the bytes become coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Any `f32` bit pattern, biased towards [`SPECIALS`]: only "no panic", "SIMD equals scalar
    /// bit for bit" and the documented policies can be asked of these.
    Chaos,
    /// Integers in `[-8, 8]` (aimed directions up to 64): every product is exact, so answers are
    /// unambiguous and are also checked against exact integer arithmetic.
    Grid,
}

impl Mode {
    /// The mode every target reads from bit 0 of its first byte (1: grid).
    pub fn of_header(header: u8) -> Self {
        if header & 1 == 0 { Self::Chaos } else { Self::Grid }
    }
}

/// A byte reader that yields zeros past the end.
#[derive(Clone, Debug)]
pub struct Input<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Input<'a> {
    /// Reads `data` from the start.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }

    /// `true` once every byte has been read.
    pub fn is_exhausted(&self) -> bool {
        self.pos >= self.data.len()
    }

    /// The next byte, or 0 past the end.
    pub fn byte(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    /// The next 4 bytes as a little-endian `u32`.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.byte(), self.byte(), self.byte(), self.byte()])
    }

    /// A grid value: an integer in `[-8, 8]` (byte 0 gives 0).
    pub fn grid(&mut self) -> f32 {
        ((i32::from(self.byte()) + 8) % 17 - 8) as f32
    }

    /// A chaos value (see the module docs).
    pub fn chaos(&mut self) -> f32 {
        let tag = self.byte();
        match tag {
            0x00..=0x3f => SPECIALS[usize::from(tag) % SPECIALS.len()],
            0x40..=0x7f => (f32::from(tag) - 96.0) * 0.25,
            _ => f32::from_bits(self.u32()),
        }
    }

    /// One value in `mode`.
    pub fn value(&mut self, mode: Mode) -> f32 {
        match mode {
            Mode::Grid => self.grid(),
            Mode::Chaos => self.chaos(),
        }
    }

    /// Three values in `mode`.
    pub fn vec3(&mut self, mode: Mode) -> Vec3 {
        Vec3::new(self.value(mode), self.value(mode), self.value(mode))
    }

    /// A ray range: one of [`RANGES`], or in chaos mode (selector `>= 0x80`) two chaos values.
    pub fn range(&mut self, mode: Mode) -> (f32, f32) {
        let s = self.byte();
        if mode == Mode::Chaos && s >= 0x80 {
            (self.chaos(), self.chaos())
        } else {
            RANGES[usize::from(s) % RANGES.len()]
        }
    }

    /// Up to `N` triangles whose vertices come from a shared pool (see the module docs).
    pub fn triangles<const N: usize>(&mut self, mode: Mode) -> [Triangle; N] {
        let mut pool = [Vec3::ZERO; 64];
        let mut len = 0;
        core::array::from_fn(|_| {
            core::array::from_fn(|_| {
                let r = self.byte();
                if r >= 0x80 && len > 0 {
                    pool[usize::from(r & 0x7f) % len]
                } else {
                    let v = self.vec3(mode);
                    if len < pool.len() {
                        pool[len] = v;
                        len += 1;
                    }
                    v
                }
            })
        })
    }

    /// A box of a kind picked by the low 3 bits of one byte (the high 5 bits are its argument):
    /// 1 raw corners (possibly inverted), 2 the bounds of triangle `arg % 8`, 3 a box flat on
    /// axis `arg % 3`, 4 (chaos) the empty box, 4 (grid) and 5 a point, else sorted corners.
    pub fn aabb(&mut self, mode: Mode, tris: &[Triangle]) -> Aabb {
        let kind = self.byte();
        let arg = usize::from(kind >> 3);
        match kind & 7 {
            1 => Aabb::new(self.vec3(mode), self.vec3(mode)),
            2 if !tris.is_empty() => Aabb::from_points(&tris[arg % tris.len()]),
            3 => {
                let (a, b) = (self.vec3(mode), self.vec3(mode));
                let (lo, mut hi) = (a.min(b), a.max(b));
                hi[arg % 3] = lo[arg % 3];
                Aabb::new(lo, hi)
            }
            4 if mode == Mode::Chaos => Aabb::EMPTY,
            4 | 5 => {
                let p = self.vec3(mode);
                Aabb::new(p, p)
            }
            _ => {
                let (a, b) = (self.vec3(mode), self.vec3(mode));
                Aabb::new(a.min(b), a.max(b))
            }
        }
    }
}

/// Replaces `+0` components by `-0`.
pub fn negative_zeros(v: Vec3) -> Vec3 {
    let f = |x: f32| if x.to_bits() == 0 { -0.0 } else { x };
    Vec3::new(f(v.x), f(v.y), f(v.z))
}

/// Everything one run of the `kernels` target tests: one ray (and a packet around it) against 8
/// triangles and 8 boxes.
#[derive(Clone, Debug)]
pub struct KernelCase {
    /// How the coordinates were decoded.
    pub mode: Mode,
    /// The ray.
    pub ray: Ray,
    /// The triangles (prim `i` is `tris[i]`).
    pub tris: [Triangle; 8],
    /// The boxes.
    pub boxes: [Aabb; 8],
    /// A ray packet: lane 0 is `ray`, the others are variations of it.
    pub packet: [Ray; 8],
}

impl KernelCase {
    /// Decodes `data` (see the module docs); never fails.
    pub fn decode(data: &[u8]) -> Self {
        let mut inp = Input::new(data);
        let header = inp.byte();
        let mode = Mode::of_header(header);
        let aim = header & 2 != 0;
        let neg_zero = header & 4 != 0;
        let tris: [Triangle; 8] = inp.triangles(mode);

        let origin = inp.vec3(mode);
        let mut direction = if aim {
            aim_at(&mut inp, mode, origin, &tris)
        } else {
            inp.vec3(mode)
        };
        if neg_zero {
            direction = negative_zeros(direction);
        }
        let (tmin, tmax) = inp.range(mode);
        let ray = Ray::with_range(origin, direction, tmin, tmax);

        let boxes = core::array::from_fn(|_| inp.aabb(mode, &tris));
        let mut packet = [ray; 8];
        for lane in packet.iter_mut().skip(1) {
            *lane = variant(&mut inp, mode, &ray, &tris);
        }
        Self {
            mode,
            ray,
            tris,
            boxes,
            packet,
        }
    }
}

/// A direction from `origin` towards a point of a triangle picked by the input.
///
/// Grid: weights `a, b, c` in `0..=4` and `d = a v0 + b v1 + c v2 - (a + b + c) origin`, an
/// integer vector (components up to 64) reaching the point at `t = 1 / (a + b + c)`; zero weights
/// aim exactly at edges and vertices. Chaos: `target = v0 + (v1 - v0) a + (v2 - v0) b` with
/// `a, b` in `[-0.5, 1.5)` steps of 1/128, so that rays aim inside, on and beyond the edges.
fn aim_at(inp: &mut Input, mode: Mode, origin: Vec3, tris: &[Triangle; 8]) -> Vec3 {
    let [v0, v1, v2] = tris[usize::from(inp.byte()) % 8];
    match mode {
        Mode::Grid => {
            let w = |b: u8| f32::from(b % 5);
            let (mut a, b, c) = (w(inp.byte()), w(inp.byte()), w(inp.byte()));
            if a + b + c == 0.0 {
                a = 1.0;
            }
            v0 * a + v1 * b + v2 * c - origin * (a + b + c)
        }
        Mode::Chaos => {
            let w = |b: u8| (f32::from(b) - 64.0) / 128.0;
            let (a, b) = (w(inp.byte()), w(inp.byte()));
            v0 + (v1 - v0) * a + (v2 - v0) * b - origin
        }
    }
}

/// A packet lane derived from `ray` by one variant byte.
fn variant(inp: &mut Input, mode: Mode, ray: &Ray, tris: &[Triangle; 8]) -> Ray {
    let v = inp.byte();
    let arg = usize::from(v >> 3);
    let mut r = *ray;
    match v % 8 {
        0 => {}
        1 => r.direction = -r.direction,
        // Exactly at a vertex of a triangle (shared vertices make this an edge case of several).
        2 => r.direction = tris[arg % 8][(arg / 8) % 3] - r.origin,
        3 => (r.tmin, r.tmax) = RANGES[arg % RANGES.len()],
        // Invalid: must hit nothing.
        4 => {
            if mode == Mode::Chaos {
                r.origin.x = f32::NAN;
            } else {
                r.direction = Vec3::ZERO;
            }
        }
        5 => r.direction = negative_zeros(r.direction),
        6 => {
            r.origin = inp.vec3(mode);
            r.direction = inp.vec3(mode);
        }
        _ => r.tmax = r.tmin,
    }
    r
}

/// `f32` shown as its value and its bits.
pub struct Bits(pub f32);

impl fmt::Display for Bits {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?} ({:#010x})", self.0, self.0.to_bits())
    }
}

impl fmt::Display for KernelCase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = |p: Vec3| format!("({}, {}, {})", Bits(p.x), Bits(p.y), Bits(p.z));
        let ray = |r: &Ray| {
            format!(
                "o {} d {} t [{}, {})",
                v(r.origin),
                v(r.direction),
                Bits(r.tmin),
                Bits(r.tmax)
            )
        };
        writeln!(f, "mode {:?}", self.mode)?;
        writeln!(f, "ray     {}", ray(&self.ray))?;
        for (i, t) in self.tris.iter().enumerate() {
            writeln!(f, "tri {i}   {} {} {}", v(t[0]), v(t[1]), v(t[2]))?;
        }
        for (i, b) in self.boxes.iter().enumerate() {
            writeln!(f, "box {i}   {} .. {}", v(b.min), v(b.max))?;
        }
        for (i, r) in self.packet.iter().enumerate().skip(1) {
            writeln!(f, "lane {i}  {}", ray(r))?;
        }
        Ok(())
    }
}
