//! Procedural scenes for the BVH builders' tests and benches, from 1 to millions of triangles,
//! deterministic from a seed: a soup of long thin triangles, clustered triangles, a fractal
//! terrain and Haines' sphereflake.

use super::{Mesh, Rng, icosphere};
use crate::geometry::Triangle;
use alloc::vec::Vec;
use glam::Vec3;

/// `n` long, thin triangles at random in the unit cube: each is `0.5 ..= 2` times the mean spacing
/// `n^(-1/3)` long, pointing in a random direction, and 1/50 of that wide. Long thin triangles
/// have large, mostly empty boxes that overlap: a hard scene for BVH builders. Like any volume
/// filled with primitives (rather than a surface), a ray crosses about `n^(1/3)` of them.
///
/// ```
/// let soup = strahl::scene::thin_soup(1000, 7);
/// assert_eq!(soup.len(), 1000);
/// assert_eq!(soup, strahl::scene::thin_soup(1000, 7)); // deterministic
/// ```
pub fn thin_soup(n: usize, seed: u64) -> Vec<Triangle> {
    let mut r = Rng::new(seed);
    let spacing = 1.0 / libm::cbrtf(n.max(1) as f32);
    (0..n)
        .map(|_| {
            let c = Vec3::new(r.f32(), r.f32(), r.f32());
            let d = r.unit_vector() * (spacing * r.range(0.5, 2.0));
            let w = r.unit_vector() * (d.length() * 0.02);
            [c - d * 0.5, c + d * 0.5, c + w]
        })
        .collect()
}

/// `n` small triangles in `clusters` clumps of random size (radius `0.002 ..= 0.05`) at random
/// places in the unit cube: dense spots in empty space, as in scenes with detailed objects far
/// apart. Triangle sizes are about a tenth of their clump's radius.
///
/// ```
/// let s = strahl::scene::clustered_soup(500, 5, 1);
/// assert_eq!(s.len(), 500);
/// ```
pub fn clustered_soup(n: usize, clusters: usize, seed: u64) -> Vec<Triangle> {
    let mut r = Rng::new(seed);
    let k = clusters.max(1);
    let centres: Vec<(Vec3, f32)> = (0..k)
        .map(|_| (Vec3::new(r.f32(), r.f32(), r.f32()), r.range(0.002, 0.05)))
        .collect();
    (0..n)
        .map(|i| {
            let (c, rad) = centres[i % k];
            // Sum of three uniforms: a bell-shaped clump.
            let mut off = || (r.f32() + r.f32() + r.f32() - 1.5) * rad;
            let p = c + Vec3::new(off(), off(), off());
            let s = rad * 0.1;
            [p, p + r.unit_vector() * s, p + r.unit_vector() * s]
        })
        .collect()
}

/// A fractal terrain: a `size` x `size` grid of quads (`2 size^2` triangles) over `[0, 1]^2` in
/// `x` and `z`, with height `y` from six octaves of value noise (fractional Brownian motion: each
/// octave twice the frequency and half the amplitude of the last), about `0 ..= 0.3` high.
/// Vertices are shared; the surface is closed under the grid (no cracks).
///
/// ```
/// let t = strahl::scene::terrain(16, 3);
/// assert_eq!((t.positions.len(), t.indices.len()), (17 * 17, 2 * 16 * 16));
/// assert!(t.positions.iter().all(|p| p.y >= 0.0 && p.y <= 0.3));
/// ```
pub fn terrain(size: u32, seed: u64) -> Mesh {
    let s = size.max(1);
    let lattice = |x: i32, y: i32, octave: u32| -> f32 {
        let mut h = Rng::new(
            seed ^ (x as u32 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (y as u32 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
                ^ (octave as u64) << 56,
        );
        h.f32()
    };
    let noise = |x: f32, y: f32, octave: u32| -> f32 {
        let (x0, y0) = (libm::floorf(x), libm::floorf(y));
        let (fx, fy) = (x - x0, y - y0);
        // Smoothstep weights: the surface has no creases along lattice lines.
        let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
        let (ix, iy) = (x0 as i32, y0 as i32);
        let a = lattice(ix, iy, octave) + (lattice(ix + 1, iy, octave) - lattice(ix, iy, octave)) * sx;
        let b = lattice(ix, iy + 1, octave) + (lattice(ix + 1, iy + 1, octave) - lattice(ix, iy + 1, octave)) * sx;
        a + (b - a) * sy
    };
    let height = |x: f32, z: f32| -> f32 {
        let (mut amp, mut freq, mut h, mut total) = (1.0f32, 4.0f32, 0.0f32, 0.0f32);
        for o in 0..6 {
            h += amp * noise(x * freq, z * freq, o);
            total += amp;
            amp *= 0.5;
            freq *= 2.0;
        }
        (h / total * 0.3).clamp(0.0, 0.3)
    };
    let mut positions = Vec::with_capacity(((s + 1) * (s + 1)) as usize);
    for j in 0..=s {
        for i in 0..=s {
            let (x, z) = (i as f32 / s as f32, j as f32 / s as f32);
            positions.push(Vec3::new(x, height(x, z), z));
        }
    }
    let mut indices = Vec::with_capacity(2 * (s * s) as usize);
    let w = s + 1;
    for j in 0..s {
        for i in 0..s {
            let v = j * w + i;
            indices.push([v, v + w, v + 1]);
            indices.push([v + 1, v + w, v + w + 1]);
        }
    }
    Mesh { positions, indices }
}

/// Haines' sphereflake (from the Standard Procedural Databases, 1987): a unit sphere with nine
/// spheres of a third its radius resting on it (six around its equator, three above), each with
/// nine of its own, `levels` generations below the first. Every sphere is an
/// [`icosphere`]`(subdivisions)`: `(9^(levels + 1) - 1) / 8 * 20 * 4^subdivisions` triangles;
/// `sphereflake(3, 3)` has 1,049,600.
///
/// ```
/// let f = strahl::scene::sphereflake(1, 1);
/// assert_eq!(f.indices.len(), 10 * 80);
/// assert_eq!(strahl::scene::sphereflake(0, 2).indices.len(), 320);
/// ```
pub fn sphereflake(levels: u32, subdivisions: u32) -> Mesh {
    let ball = icosphere(subdivisions);
    // Child directions in the parent's frame (axis = +z): six on the equator, three at 60 degrees.
    let mut dirs = [Vec3::ZERO; 9];
    for (k, d) in dirs.iter_mut().enumerate() {
        let (az, el) = if k < 6 {
            (k as f32 * core::f32::consts::TAU / 6.0, 0.0f32)
        } else {
            (
                (k - 6) as f32 * core::f32::consts::TAU / 3.0 + 0.5,
                core::f32::consts::FRAC_PI_3,
            )
        };
        let (ce, se) = (libm::cosf(el), libm::sinf(el));
        *d = Vec3::new(ce * libm::cosf(az), ce * libm::sinf(az), se);
    }
    let mut mesh = Mesh::default();
    // (centre, radius, axis, generation); an explicit stack, no recursion.
    let mut stack: Vec<(Vec3, f32, Vec3, u32)> = alloc::vec![(Vec3::ZERO, 1.0, Vec3::Z, 0)];
    while let Some((c, r, axis, gen_)) = stack.pop() {
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(ball.positions.iter().map(|&p| c + p * r));
        mesh.indices
            .extend(ball.indices.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
        if gen_ < levels {
            // An orthonormal frame (t, b, axis).
            let helper = if axis.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
            let t = helper.cross(axis).normalize();
            let b = axis.cross(t);
            for d in dirs {
                let dir = t * d.x + b * d.y + axis * d.z;
                let rc = r / 3.0;
                stack.push((c + dir * (r + rc), rc, dir, gen_ + 1));
            }
        }
    }
    mesh
}
