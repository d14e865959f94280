//! Procedural volumes and a pinhole camera, for tests, benches and examples (feature `alloc`).
//!
//! All volumes are `n^3` voxels over `[-1, 1]^3` (use [`unit_volume`] for the matching
//! [`Volume`]), x fastest.

use super::{Volume, Voxel};
use crate::geometry::Ray;
use alloc::vec::Vec;
use core::f32::consts::PI;
use glam::Vec3;
use libm::{cosf, sinf, sqrtf};

/// World position of voxel `(i, j, k)` of an `n^3` volume over `[-1, 1]^3`.
#[inline]
fn pos(n: u32, i: u32, j: u32, k: u32) -> Vec3 {
    let s = 2.0 / (n.max(2) - 1) as f32;
    Vec3::new(i as f32, j as f32, k as f32) * s - Vec3::ONE
}

fn fill<T>(n: u32, f: impl Fn(Vec3) -> T) -> Vec<T> {
    let mut v = Vec::with_capacity((n as usize).pow(3));
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                v.push(f(pos(n, i, j, k)));
            }
        }
    }
    v
}

/// The volume over `[-1, 1]^3` for `n^3` voxels of `data` (spacing `2 / (n - 1)`).
///
/// ```
/// use strahl::volume::procedural::{marschner_lobb, unit_volume};
/// let data = marschner_lobb(41);
/// let v = unit_volume(&data, 41).unwrap();
/// assert_eq!(v.bounds().min, strahl::Vec3::splat(-1.0));
/// ```
pub fn unit_volume<V: Voxel>(data: &[V], n: u32) -> Result<Volume<'_, V>, super::VolumeError> {
    Volume::new(
        data,
        [n; 3],
        Vec3::splat(2.0 / (n.max(2) - 1) as f32),
        Vec3::splat(-1.0),
    )
}

/// The Marschner-Lobb test signal (S. Marschner, R. Lobb, "An Evaluation of Reconstruction Filters
/// for Volume Rendering", Visualization 1994) with `f_M = 6`, `alpha = 1/4`, values in `[0, 1]`:
///
/// `rho(x, y, z) = (1 - sin(pi z / 2) + alpha (1 + cos(2 pi f_M cos(pi r / 2)))) / (2 (1 + alpha))`,
/// `r = sqrt(x^2 + y^2)`. Sampled on `41^3` it sits near the Nyquist limit.
///
/// ```
/// use strahl::{Vec3, volume::procedural::{marschner_lobb, marschner_lobb_at}};
/// let data = marschner_lobb(41);
/// assert_eq!(data.len(), 41 * 41 * 41);
/// assert!(data.iter().all(|v| (0.0..=1.0).contains(v)));
/// assert_eq!(data[0], marschner_lobb_at(Vec3::splat(-1.0))); // voxel (0, 0, 0) at the corner
/// ```
pub fn marschner_lobb(n: u32) -> Vec<f32> {
    fill(n, marschner_lobb_at)
}

/// The Marschner-Lobb signal at one point (see [`marschner_lobb`]).
///
/// ```
/// use strahl::{Vec3, volume::procedural::marschner_lobb_at};
/// // At the origin: r = 0, so rho_r = cos(12 pi) = 1: (1 + 2 alpha) / (2 (1 + alpha)) = 0.6.
/// assert!((marschner_lobb_at(Vec3::ZERO) - 0.6).abs() < 1e-6);
/// // At (1, 0, 1): rho_r = cos(0) = 1 again, sin(pi / 2) = 1: 2 alpha / (2 (1 + alpha)) = 0.2.
/// assert!((marschner_lobb_at(Vec3::new(1.0, 0.0, 1.0)) - 0.2).abs() < 1e-6);
/// ```
pub fn marschner_lobb_at(p: Vec3) -> f32 {
    let (fm, alpha) = (6.0f32, 0.25f32);
    let r = sqrtf(p.x * p.x + p.y * p.y);
    let rho_r = cosf(2.0 * PI * fm * cosf(PI * r / 2.0));
    (1.0 - sinf(PI * p.z / 2.0) + alpha * (1.0 + rho_r)) / (2.0 * (1.0 + alpha))
}

/// A CT-like phantom: the 3D Shepp-Logan head of Kak and Slaney ("Principles of Computerized
/// Tomographic Imaging", 1988), ten ellipsoids, with Toft's higher-contrast densities, stored as
/// `u16` "Hounsfield-like" units (`1000` per unit density, background `0`, skull `1000`, brain
/// `200`, ventricles `0`, small lesions `300`).
///
/// ```
/// use strahl::volume::procedural::ct_phantom;
/// let ct = ct_phantom(33); // voxel i at -1 + i / 16 on each axis
/// let at = |i: usize, j: usize, k: usize| ct[i + 33 * (j + 33 * k)];
/// assert_eq!(at(0, 0, 0), 0); // the corner: background
/// assert_eq!(at(16, 30, 16), 1000); // y = 0.875: skull
/// assert_eq!(at(16, 16, 16), 200); // the centre: brain (1 - 0.8)
/// ```
pub fn ct_phantom(n: u32) -> Vec<u16> {
    // (centre, semi-axes, rotation about z in degrees, density)
    const E: [([f32; 3], [f32; 3], f32, f32); 10] = [
        ([0.0, 0.0, 0.0], [0.69, 0.92, 0.81], 0.0, 1.0),
        ([0.0, -0.0184, 0.0], [0.6624, 0.874, 0.78], 0.0, -0.8),
        ([0.22, 0.0, 0.0], [0.11, 0.31, 0.22], -18.0, -0.2),
        ([-0.22, 0.0, 0.0], [0.16, 0.41, 0.28], 18.0, -0.2),
        ([0.0, 0.35, -0.15], [0.21, 0.25, 0.41], 0.0, 0.1),
        ([0.0, 0.1, 0.25], [0.046, 0.046, 0.05], 0.0, 0.1),
        ([0.0, -0.1, 0.25], [0.046, 0.046, 0.05], 0.0, 0.1),
        ([-0.08, -0.605, 0.0], [0.046, 0.023, 0.05], 0.0, 0.1),
        ([0.0, -0.606, 0.0], [0.023, 0.023, 0.02], 0.0, 0.1),
        ([0.06, -0.605, 0.0], [0.023, 0.046, 0.02], 0.0, 0.1),
    ];
    fill(n, |p| {
        let mut d = 0.0f32;
        for (c, s, deg, rho) in E {
            let (sn, cs) = (sinf(deg * PI / 180.0), cosf(deg * PI / 180.0));
            let q = p - Vec3::from_array(c);
            let x = cs * q.x + sn * q.y;
            let y = -sn * q.x + cs * q.y;
            let (a, b, c) = (x / s[0], y / s[1], q.z / s[2]);
            if a * a + b * b + c * c <= 1.0 {
                d += rho;
            }
        }
        // Rounded: the sums of densities are not exact in f32 (1 - 0.8 is 0.19999999).
        libm::roundf(d * 1000.0).clamp(0.0, 65535.0) as u16
    })
}

/// A torus around the z axis, radius `major`, tube radius `minor`: `255` on the tube's centre
/// circle falling linearly to `0` at its surface, `0` elsewhere. With `major = 0.5`,
/// `minor = 0.15` about 97% of the voxels are `0`: the sparse scene of the skipping benchmark.
///
/// ```
/// use strahl::volume::procedural::torus;
/// let t = torus(33, 0.5, 0.15); // voxel i at -1 + i / 16 on each axis
/// assert_eq!(t[24 + 33 * (16 + 33 * 16)], 255); // (0.5, 0, 0): on the centre circle
/// assert_eq!(t[16 + 33 * (16 + 33 * 16)], 0); // the origin: in the hole
/// let zeros = t.iter().filter(|&&v| v == 0).count() as f32 / t.len() as f32;
/// assert!(zeros > 0.95);
/// ```
pub fn torus(n: u32, major: f32, minor: f32) -> Vec<u8> {
    fill(n, |p| {
        let q = sqrtf(p.x * p.x + p.y * p.y) - major;
        let d = sqrtf(q * q + p.z * p.z);
        (255.0 * (1.0 - d / minor)).clamp(0.0, 255.0) as u8
    })
}

/// `w x h` rays from a pinhole camera at `eye` looking at `target` (up is `+z`, or `+y` when
/// looking along z), vertical field of view `fov_deg`, row by row from the top left. Where `eye`
/// and `target` coincide (no direction to look in) the rays are invalid and hit nothing; an
/// image of more than `u32::MAX` pixels (which could not be allocated anyway) gives no rays.
///
/// ```
/// use strahl::Vec3;
/// use strahl::volume::procedural::pinhole_rays;
/// let rays = pinhole_rays(Vec3::new(0.0, -3.0, 0.0), Vec3::ZERO, 40.0, 4, 3);
/// assert_eq!(rays.len(), 12);
/// assert!(rays.iter().all(|r| r.direction.y > 0.0));
/// assert!(pinhole_rays(Vec3::ZERO, Vec3::ZERO, 40.0, 2, 2).iter().all(|r| !r.is_valid()));
/// assert!(pinhole_rays(Vec3::ZERO, Vec3::X, 40.0, 1 << 16, 1 << 16).is_empty());
/// ```
pub fn pinhole_rays(eye: Vec3, target: Vec3, fov_deg: f32, w: u32, h: u32) -> Vec<Ray> {
    let fwd = (target - eye).normalize();
    let up0 = if fwd.cross(Vec3::Z).length_squared() < 1e-6 {
        Vec3::Y
    } else {
        Vec3::Z
    };
    let right = fwd.cross(up0).normalize();
    let up = right.cross(fwd);
    let half = libm::tanf(fov_deg.to_radians() / 2.0);
    let aspect = w as f32 / h.max(1) as f32;
    let Some(n) = w.checked_mul(h) else {
        return Vec::new();
    };
    let mut rays = Vec::with_capacity(n as usize);
    for y in 0..h {
        for x in 0..w {
            let u = ((x as f32 + 0.5) / w as f32 * 2.0 - 1.0) * half * aspect;
            let v = (1.0 - (y as f32 + 0.5) / h as f32 * 2.0) * half;
            rays.push(Ray::new(eye, fwd + right * u + up * v));
        }
    }
    rays
}
