//! Scene and ray helpers shared by the bench files (included with
//! `#[path = "common/mod.rs"] mod common;`), so that every bench traces the same kinds of rays.
#![allow(dead_code)] // each bench uses a part

use strahl::geometry::Triangle;
use strahl::scene::Rng;
use strahl::traverse::packet::{self, TileShape};
use strahl::volume::TfEntry;
use strahl::{Aabb, Ray, Vec3};

/// The box around every vertex of `tris`.
pub fn bounds(tris: &[Triangle]) -> Aabb {
    tris.iter().flatten().fold(Aabb::EMPTY, |mut b, v| {
        b.grow(*v);
        b
    })
}

/// The benches' pinhole camera: looking at `b` from above one corner, `w x h` rays, the pixels in
/// tiles of `shape` ([`packet::image_rays`]), so that each packet of `shape.rays()` consecutive
/// rays is a coherent tile (single-ray benches use 4 x 2 tiles too, for the same ray order).
pub fn primary_rays(b: &Aabb, w: u32, h: u32, shape: TileShape) -> Vec<Ray> {
    let c = b.centroid();
    let r = (b.max - b.min).length() * 0.5;
    let eye = c + Vec3::new(0.55, 0.35, 1.0).normalize() * r * 2.6;
    let fw = (c - eye).normalize();
    let right = fw.cross(Vec3::Y).normalize() * 0.45;
    let up = right.normalize().cross(fw) * 0.45;
    packet::image_rays(shape, w, h, |x, y| {
        let u = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
        let v = 1.0 - (y as f32 + 0.5) / h as f32 * 2.0;
        Ray::new(eye, fw + right * u + up * v)
    })
}

/// `n` random points on the surface with their (geometric) normals.
pub fn surface_points(tris: &[Triangle], n: usize, rng: &mut Rng) -> Vec<(Vec3, Vec3)> {
    (0..n)
        .filter_map(|_| {
            let t = tris[(rng.u64() % tris.len() as u64) as usize];
            let (mut u, mut v) = (rng.f32(), rng.f32());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let p = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
            let nrm = (t[1] - t[0]).cross(t[2] - t[0]).try_normalize()?;
            Some((p, nrm))
        })
        .collect()
}

/// Rays from `n` random surface points in cosine-like directions around the normal, started
/// `scale * 1e-5` off the surface.
pub fn diffuse_rays(tris: &[Triangle], n: usize, scale: f32) -> Vec<Ray> {
    let mut rng = Rng::new(5);
    surface_points(tris, n, &mut rng)
        .into_iter()
        .map(|(p, nrm)| {
            let mut d = rng.unit_vector();
            if d.dot(nrm) < 0.0 {
                d = -d;
            }
            Ray::new(p + nrm * scale * 1e-5, (d + nrm).normalize_or(nrm))
        })
        .collect()
}

/// Any-hit rays from `n` random surface points (started `scale * 1e-5` off the surface) to random
/// points of `b`, `tmax` 1 on the unnormalised direction: shadow rays to scattered lights.
pub fn shadow_rays(tris: &[Triangle], b: &Aabb, n: usize, scale: f32) -> Vec<Ray> {
    let mut rng = Rng::new(6);
    surface_points(tris, n, &mut rng)
        .into_iter()
        .map(|(p, nrm)| {
            let o = p + nrm * scale * 1e-5;
            let target = b.min + (b.max - b.min) * Vec3::new(rng.f32(), rng.f32(), rng.f32());
            let d = target - o;
            Ray::with_range(o, d, 0.0, 1.0)
        })
        .collect()
}

/// A triangle for the `bvh` crate (it stores each shape's leaf index in the shape).
pub struct BvhCrateTri {
    pub a: nalgebra::Point3<f32>,
    pub b: nalgebra::Point3<f32>,
    pub c: nalgebra::Point3<f32>,
    pub node: usize,
}

impl bvh::aabb::Bounded<f32, 3> for BvhCrateTri {
    fn aabb(&self) -> bvh::aabb::Aabb<f32, 3> {
        bvh::aabb::Aabb::empty().grow(&self.a).grow(&self.b).grow(&self.c)
    }
}

impl bvh::bounding_hierarchy::BHShape<f32, 3> for BvhCrateTri {
    fn set_bh_node_index(&mut self, i: usize) {
        self.node = i;
    }
    fn bh_node_index(&self) -> usize {
        self.node
    }
}

/// The volume benches' colour ramp over the 8-bit range: values `lo..=hi` visible, extinction
/// growing with the value (`gain * (0.2 + t)`), transparent elsewhere.
pub fn ramp(lo: usize, hi: usize, gain: f32) -> Vec<TfEntry> {
    (0..256)
        .map(|i| {
            if i < lo || i > hi {
                return TfEntry::TRANSPARENT;
            }
            let t = (i - lo) as f32 / (hi - lo).max(1) as f32;
            TfEntry::new([0.9 * t + 0.1, 0.4 + 0.3 * t, 1.0 - 0.8 * t], gain * (0.2 + t))
        })
        .collect()
}

/// Values in `[0, 1]` as `u8` voxels (rounded, clamped).
pub fn quantise(v: &[f32]) -> Vec<u8> {
    v.iter().map(|x| (x * 255.0).round().clamp(0.0, 255.0) as u8).collect()
}
