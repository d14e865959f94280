//! Robust secondary rays (`geometry::offset`): a ray leaving a hit point towards the side it
//! came from never hits its own triangle again, for triangles of every size from 1e-12 to 1e8 and
//! positions from the origin out to 1e8; the naive origin `o + t d` (no offset) does, often.

use strahl::geometry::offset::{hit_point, offset_origin};
use strahl::geometry::{Triangle, is_degenerate};
use strahl::intersect::{PreparedRay, moller, watertight};
use strahl::scene::Rng;
use strahl::{Ray, Vec3};

/// A direction on the hemisphere around `n`.
fn hemisphere(n: Vec3, rng: &mut Rng) -> Vec3 {
    let d = rng.unit_vector();
    if d.dot(n) < 0.0 { -d } else { d }
}

#[test]
fn offset_rays_never_rehit_their_triangle() {
    let mut rng = Rng::new(11);
    let (mut naive_rehits, mut secondary) = (0usize, 0usize);
    // Down to 1e-12: the cross product of such a triangle's edges (1e-24) has a squared length
    // that underflows, which a plain normalisation cannot handle.
    for size_exp in -12..=8 {
        for centre_exp in [-8, -3, 0, 3, 6, 8] {
            let size = 10f32.powi(size_exp);
            let centre =
                Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5).normalize() * 10f32.powi(centre_exp);
            if size > centre.length() * 10.0 && centre_exp > 0 {
                continue;
            }
            for _ in 0..40 {
                let tri: Triangle = [0, 1, 2].map(|_| centre + rng.unit_vector() * size);
                if is_degenerate(&tri) {
                    continue;
                }
                let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
                let Some(nn) = (n / n.abs().max_element()).try_normalize() else {
                    continue;
                };
                // A primary ray from the front side, aimed at a random interior point.
                let (mut u, mut v) = (rng.f32(), rng.f32());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                let target = tri[0] + (tri[1] - tri[0]) * u + (tri[2] - tri[0]) * v;
                let side = if rng.f32() < 0.5 { nn } else { -nn };
                let eye = target + (side + rng.unit_vector() * 0.5) * (size * 3.0 + centre.length() * 1e-3);
                let ray = Ray::new(eye, target - eye);
                let Some(hit) = watertight::intersect_scalar(&PreparedRay::new(&ray), &tri, 0) else {
                    continue;
                };
                // The side the ray came from.
                let facing = if n.dot(ray.direction) < 0.0 { n } else { -n };
                let origin = offset_origin(hit_point(&tri, &hit), facing);
                let naive = ray.origin + ray.direction * hit.t;
                for _ in 0..16 {
                    let d = hemisphere(facing, &mut rng);
                    let r = PreparedRay::new(&Ray::new(origin, d));
                    assert!(
                        watertight::intersect_scalar(&r, &tri, 0).is_none(),
                        "watertight re-hit: size {size:e} centre {centre} origin {origin} dir {d}"
                    );
                    assert!(
                        moller::intersect_scalar(&r, &tri, 0).is_none(),
                        "Moller re-hit: size {size:e}"
                    );
                    secondary += 1;
                    let rn = PreparedRay::new(&Ray::new(naive, d));
                    naive_rehits += watertight::intersect_scalar(&rn, &tri, 0).is_some() as usize;
                }
                // The offset is small: within 257 ULPs per axis (or 1/65536 near the origin).
                let p = hit_point(&tri, &hit);
                for a in 0..3 {
                    let (x, y) = (p[a], origin[a]);
                    if x.abs() >= 1.0 / 32.0 {
                        assert!((x.to_bits() as i64 - y.to_bits() as i64).abs() <= 257, "{x} -> {y}");
                    } else {
                        assert!((x - y).abs() <= 1.0 / 65536.0 * 1.001, "{x} -> {y}");
                    }
                }
            }
        }
    }
    println!("{secondary} secondary rays, none re-hit; without the offset {naive_rehits} re-hit");
    assert!(secondary > 10_000);
    // The test is not vacuous: starting at `o + t d` re-hits the surface for a good share.
    assert!(
        naive_rehits > secondary / 100,
        "naive re-hits {naive_rehits} of {secondary}"
    );
}
