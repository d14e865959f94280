//! Watertightness on closed meshes: rays aimed exactly at shared vertices and at points on shared
//! edges must hit at least one triangle with the watertight test, in every width. The same rays
//! measure (and print) the Möller-Trumbore false-miss rate.
//!
//! Meshes: an icosphere (closed; translated and scaled so that coordinates are not round numbers)
//! and a fan of 64 triangles around one apex. Ray origins are random points outside the surface,
//! on the side the target faces, so the target lies well inside the visible part of the surface
//! and a miss can only be a crack between triangles. Each ray only accepts hits within 10% of the
//! target's distance, so a ray that slips through the front cannot count a hit on the back.

use strahl::geometry::Triangle;
use strahl::intersect::{PreparedRay, TriangleX8, moller, watertight};
use strahl::scene::{self, Mesh, Rng};
use strahl::{Ray, Vec3};

struct Counts {
    rays: usize,
    wt_miss: usize,
    wt_x8_miss: usize,
    mt_miss: usize,
    mt_x8_miss: usize,
}

fn any_hit(f: fn(&PreparedRay, &Triangle, u32) -> Option<strahl::Hit>, r: &PreparedRay, tris: &[Triangle]) -> bool {
    tris.iter().enumerate().any(|(i, t)| f(r, t, i as u32).is_some())
}

fn run(tris: &[Triangle], rays: &[Ray]) -> Counts {
    let packed: Vec<TriangleX8> = tris
        .chunks(8)
        .enumerate()
        .map(|(c, ch)| TriangleX8::pack(ch, &(0..8).map(|i| (c * 8 + i) as u32).collect::<Vec<_>>()))
        .collect();
    let mut c = Counts { rays: rays.len(), wt_miss: 0, wt_x8_miss: 0, mt_miss: 0, mt_x8_miss: 0 };
    for ray in rays {
        let r = PreparedRay::new(ray);
        c.wt_miss += !any_hit(watertight::intersect_scalar, &r, tris) as usize;
        c.mt_miss += !any_hit(moller::intersect_scalar, &r, tris) as usize;
        c.wt_x8_miss += !packed.iter().any(|p| watertight::occluded_x8(&r, p)) as usize;
        c.mt_x8_miss += !packed.iter().any(|p| moller::occluded_x8(&r, p)) as usize;
    }
    c
}

fn report(name: &str, c: &Counts) {
    println!(
        "{name}: {} rays; watertight misses scalar {} x8 {}; Möller-Trumbore misses scalar {} ({:.3}%) x8 {}",
        c.rays,
        c.wt_miss,
        c.wt_x8_miss,
        c.mt_miss,
        100.0 * c.mt_miss as f64 / c.rays as f64,
        c.mt_x8_miss
    );
    assert_eq!(c.wt_miss, 0, "{name}: the watertight test let rays through");
    assert_eq!(c.wt_x8_miss, 0, "{name}: the x8 watertight test let rays through");
    assert_eq!(c.mt_miss, c.mt_x8_miss, "{name}: Möller-Trumbore x8 and scalar disagree");
}

/// Targets on a mesh: points on every edge (midpoint and a random point), and every vertex.
fn targets(m: &Mesh, rng: &mut Rng) -> (Vec<(Vec3, Vec3)>, Vec<(Vec3, Vec3)>) {
    let mut out = Vec::new();
    let mut normal = vec![Vec3::ZERO; m.positions.len()];
    for &[a, b, c] in &m.indices {
        let (pa, pb, pc) = (m.positions[a as usize], m.positions[b as usize], m.positions[c as usize]);
        let n = (pb - pa).cross(pc - pa);
        for i in [a, b, c] {
            normal[i as usize] += n;
        }
        for (i, j) in [(a, b), (b, c), (c, a)] {
            if i < j {
                let (pi, pj) = (m.positions[i as usize], m.positions[j as usize]);
                let n = (normal[i as usize] + normal[j as usize]).normalize_or(n.normalize());
                out.push((pi + (pj - pi) * 0.5, n));
                out.push((pi + (pj - pi) * rng.f32(), n));
            }
        }
    }
    let verts = m.positions.iter().zip(&normal).map(|(p, n)| (*p, n.normalize())).collect();
    (out, verts)
}

/// Rays from outside towards each target, within 60 degrees of the target's outward normal.
fn rays_towards(targets: &[(Vec3, Vec3)], per_target: usize, dist: f32, rng: &mut Rng) -> Vec<Ray> {
    let mut rays = Vec::new();
    for &(p, n) in targets {
        for _ in 0..per_target {
            let dir_out = loop {
                let v = rng.unit_vector();
                if v.dot(n) > 0.5 {
                    break v;
                }
            };
            let origin = p + dir_out * dist * rng.range(0.5, 2.0);
            // The target is at t = 1. The window [0.9, 1.1) admits only the surface around the target,
            // never the far side of the closed mesh, so a crack cannot be hidden by a back face.
            rays.push(Ray::with_range(origin, p - origin, 0.9, 1.1));
        }
    }
    rays
}

#[test]
fn icosphere_is_watertight() {
    let mut rng = Rng::new(1);
    let mut m = scene::icosphere(3);
    for p in &mut m.positions {
        *p = *p * 3.7 + Vec3::new(0.31, -1.7, 2.1);
    }
    let (edges, verts) = targets(&m, &mut rng);
    let soup = m.to_soup();
    report("icosphere(3) edge-aimed", &run(&soup, &rays_towards(&edges, 16, 5.0, &mut rng)));
    report("icosphere(3) vertex-aimed", &run(&soup, &rays_towards(&verts, 64, 5.0, &mut rng)));
}

#[test]
fn fan_is_watertight() {
    let mut rng = Rng::new(2);
    let mut m = scene::fan(64, 0.3);
    for p in &mut m.positions {
        *p = *p * 1.3 + Vec3::new(-0.7, 0.45, 1.1);
    }
    // Targets: the apex, and points along every spoke (shared edge), never on the rim.
    let apex = m.positions[0];
    let mut t = vec![];
    for i in 1..m.positions.len() {
        let rim = m.positions[i];
        for k in 1..8 {
            t.push((apex + (rim - apex) * (k as f32 / 8.0), Vec3::Z));
        }
        t.push((apex + (rim - apex) * rng.range(0.0, 0.95), Vec3::Z));
    }
    let soup = m.to_soup();
    report("fan(64) edge-aimed", &run(&soup, &rays_towards(&t, 16, 3.0, &mut rng)));
    report("fan(64) apex-aimed", &run(&soup, &rays_towards(&[(apex, Vec3::Z)], 20_000, 3.0, &mut rng)));
}
