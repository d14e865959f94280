//! Watertightness on closed meshes: rays aimed exactly at shared vertices and at points on shared
//! edges must hit at least one triangle with the watertight test, in every width. The same rays
//! measure (and print) the Möller-Trumbore false-miss rate.
//!
//! Meshes: an icosphere (closed; translated and scaled so that coordinates are not round numbers)
//! and a fan of 64 triangles around one apex. Rays come from [`scene::aimed_rays`]: random origins
//! on the side the target faces, so the target lies well inside the visible part of the surface,
//! and each ray accepts only hits within 10% of the target's distance, so a ray that slips through
//! the front cannot count a hit on the back. A miss can only be a crack between triangles.

use strahl::Ray;
use strahl::Vec3;
use strahl::geometry::Triangle;
use strahl::intersect::{PreparedRay, TriangleX8, moller, watertight};
use strahl::scene::{self, Aim, Mesh};

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
    let mut c = Counts {
        rays: rays.len(),
        wt_miss: 0,
        wt_x8_miss: 0,
        mt_miss: 0,
        mt_x8_miss: 0,
    };
    for ray in rays {
        let r = PreparedRay::new(ray);
        c.wt_miss += !any_hit(watertight::intersect_scalar, &r, tris) as usize;
        c.mt_miss += !any_hit(moller::intersect_scalar, &r, tris) as usize;
        c.wt_x8_miss += !packed.iter().any(|p| watertight::occluded_x8(&r, p)) as usize;
        c.mt_x8_miss += !packed.iter().any(|p| moller::occluded_x8(&r, p)) as usize;
    }
    c
}

/// Aims rays at the `aim` features of `targets` and tests them against `mesh`.
fn check(name: &str, mesh: &Mesh, targets: &Mesh, aim: Aim, per_target: usize, seed: u64) {
    let c = run(&mesh.to_soup(), &scene::aimed_rays(targets, aim, per_target, 3.0, seed));
    println!(
        "{name} {aim:?}: {} rays; watertight misses scalar {} x8 {}; Möller-Trumbore misses scalar {} ({:.3}%) x8 {}",
        c.rays,
        c.wt_miss,
        c.wt_x8_miss,
        c.mt_miss,
        100.0 * c.mt_miss as f64 / c.rays as f64,
        c.mt_x8_miss
    );
    assert_eq!(c.wt_miss, 0, "{name}: the watertight test let rays through");
    assert_eq!(c.wt_x8_miss, 0, "{name}: the x8 watertight test let rays through");
    assert_eq!(
        c.mt_miss, c.mt_x8_miss,
        "{name}: Möller-Trumbore x8 and scalar disagree"
    );
}

#[test]
fn icosphere_is_watertight() {
    let mut m = scene::icosphere(3);
    for p in &mut m.positions {
        *p = *p * 3.7 + Vec3::new(0.31, -1.7, 2.1);
    }
    check("icosphere(3)", &m, &m, Aim::Edges, 16, 1);
    check("icosphere(3)", &m, &m, Aim::Vertices, 64, 2);
}

#[test]
fn fan_is_watertight() {
    let mut m = scene::fan(64, 0.3);
    for p in &mut m.positions {
        *p = *p * 1.3 + Vec3::new(-0.7, 0.45, 1.1);
    }
    // The rim is a boundary, not a shared edge: aim at the spokes (degenerate [apex, rim, rim]
    // "triangles" have only the spoke as an edge) and at the apex.
    let spokes = Mesh {
        positions: m.positions.clone(),
        indices: m.indices.iter().map(|&[a, b, _]| [a, b, b]).collect(),
    };
    check("fan(64) spokes", &m, &spokes, Aim::Edges, 64, 3);
    let apex = Mesh {
        positions: vec![m.positions[0]],
        indices: vec![],
    };
    check("fan(64) apex", &m, &apex, Aim::Vertices, 20_000, 4);
}
