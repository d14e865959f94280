//! Every hit the `f32` kernels report is confirmed by the `f64` reference
//! ([`strahl::intersect::reference`]) within its stated bound.
//!
//! For each ray and triangle the reference gives a [`Verdict`]: a clear hit (every kernel must hit,
//! `|t32 - t64| <= Dt`), a clear miss (every kernel must miss) or a knife edge (within rounding of
//! an edge, of `tmin`/`tmax`, or ill-conditioned: either answer is allowed). Kernels: Möller-Trumbore
//! and watertight, scalar and x8 (`hit_mask` for every lane's decision, `intersect_x8` for the
//! closest hit's `t`); the slab test, scalar and x8, against the `f64` slab interval.
//!
//! Asserted: no unconfirmed hit (a hit on a clear miss, or `t` beyond `Dt` where the reference
//! hits), no false miss on a clear hit, every box the `f64` test hits is hit, box false hits only
//! within `AABB_GAP_REL_BOUND`, box entries within `AABB_ENTRY_REL_BOUND`, and no ray aimed at an
//! edge or vertex of a closed mesh that the watertight test lets through where the reference hits.
//! Measured and printed (`--nocapture`): per case family, the largest `|t32 - t64| / Dt`, knife-edge
//! counts and false misses at knife edges per kernel.

mod common;

use common::{bounded, vec3};
use proptest::prelude::*;
use strahl::geometry::Triangle;
use strahl::intersect::reference::{
    AABB_ENTRY_REL_BOUND, AABB_GAP_REL_BOUND, Verdict, aabb_interval_f64, crossing_f64,
};
use strahl::intersect::{
    AabbX8, PreparedRay, TriangleX8, intersect_aabb_scalar, intersect_aabb_x8, moller, watertight,
};
use strahl::scene::{self, Aim, Rng};
use strahl::{Aabb, Ray, Vec3};

const KERNELS: [&str; 4] = ["moller", "watertight", "moller x8", "watertight x8"];

/// Counts of one kernel over one family.
#[derive(Default, Clone, Copy)]
struct KernelCounts {
    hits: usize,
    knife_hits: usize,
    unconfirmed: usize,
    clear_false_miss: usize,
    knife_false_miss: usize,
    max_ratio: f64,
}

#[derive(Default)]
struct Family {
    pairs: usize,
    clear_hits: usize,
    knife: usize,
    ill: usize,
    ill_near: usize,
    k: [KernelCounts; 4],
    first_failure: Option<String>,
}

fn bits(v: Vec3) -> String {
    format!(
        "[{:#010x}, {:#010x}, {:#010x}]",
        v.x.to_bits(),
        v.y.to_bits(),
        v.z.to_bits()
    )
}

fn repro(ray: &Ray, tri: &Triangle) -> String {
    format!(
        "ray o {} d {} tmin {:#010x} tmax {:#010x}; tri {} {} {} ({ray:?} {tri:?})",
        bits(ray.origin),
        bits(ray.direction),
        ray.tmin.to_bits(),
        ray.tmax.to_bits(),
        bits(tri[0]),
        bits(tri[1]),
        bits(tri[2])
    )
}

impl Family {
    /// Judges kernel `k`'s answer (`Some(t)` for a hit; `t` NaN where only the decision is known).
    fn judge(&mut self, k: usize, verdict: Verdict, t_bound: f64, got: Option<f32>, ray: &Ray, tri: &Triangle) {
        let c = &mut self.k[k];
        let mut fail = None;
        match (verdict, got) {
            (Verdict::Miss, Some(t)) => {
                c.hits += 1;
                fail = Some(format!("{}: hit at t {t} on a clear miss", KERNELS[k]));
            }
            (Verdict::Hit(_), None) => {
                c.clear_false_miss += 1;
                fail = Some(format!("{}: false miss on a clear hit", KERNELS[k]));
            }
            (Verdict::KnifeEdge(Some(_)), None) => c.knife_false_miss += 1,
            (Verdict::Hit(h) | Verdict::KnifeEdge(Some(h)), Some(t)) => {
                c.hits += 1;
                if matches!(verdict, Verdict::KnifeEdge(_)) {
                    c.knife_hits += 1;
                }
                if !t.is_nan() && t_bound.is_finite() {
                    let ratio = (t as f64 - h.t).abs() / t_bound;
                    c.max_ratio = c.max_ratio.max(ratio);
                    if ratio > 1.0 {
                        fail = Some(format!(
                            "{}: t32 {t} vs t64 {} beyond the bound {t_bound:e}",
                            KERNELS[k], h.t
                        ));
                    }
                }
            }
            (Verdict::KnifeEdge(None), Some(_)) => {
                c.hits += 1;
                c.knife_hits += 1;
            }
            (Verdict::Miss | Verdict::KnifeEdge(None), None) => {}
        }
        if let Some(f) = fail {
            if !f.contains("false miss") {
                c.unconfirmed += 1;
            }
            if self.first_failure.is_none() {
                self.first_failure = Some(format!("{f}: {}", repro(ray, tri)));
            }
        }
    }

    /// One ray against up to 8 triangles, every kernel.
    fn check(&mut self, ray: &Ray, tris: &[Triangle]) {
        let pre = PreparedRay::new(ray);
        for chunk in tris.chunks(8) {
            let cross: Vec<_> = chunk.iter().map(|t| crossing_f64(ray, t)).collect();
            let verdict: Vec<_> = cross.iter().map(|c| c.map_or(Verdict::Miss, |c| c.verdict())).collect();
            let bound: Vec<_> = cross.iter().map(|c| c.map_or(f64::INFINITY, |c| c.t_bound)).collect();
            for (i, v) in verdict.iter().enumerate() {
                self.pairs += 1;
                match v {
                    Verdict::Hit(_) => self.clear_hits += 1,
                    Verdict::KnifeEdge(_) => {
                        self.knife += 1;
                        if let Some(c) = cross[i].filter(|c| c.is_ill_conditioned()) {
                            self.ill += 1;
                            // Crossing inside or within half a triangle of it (not a far-away plane).
                            self.ill_near += (c.bary.iter().all(|&b| b >= -0.5)) as usize;
                        }
                    }
                    Verdict::Miss => {}
                }
            }
            for (i, tri) in chunk.iter().enumerate() {
                let mt = moller::intersect_scalar(&pre, tri, i as u32).map(|h| h.t);
                let wt = watertight::intersect_scalar(&pre, tri, i as u32).map(|h| h.t);
                self.judge(0, verdict[i], bound[i], mt, ray, tri);
                self.judge(1, verdict[i], bound[i], wt, ray, tri);
            }
            let prims: Vec<u32> = (0..chunk.len() as u32).collect();
            let pack = TriangleX8::pack(chunk, &prims);
            let closest = [moller::intersect_x8(&pre, &pack), watertight::intersect_x8(&pre, &pack)];
            let masks = [moller::hit_mask(&pre, &pack), watertight::hit_mask(&pre, &pack)];
            for w in 0..2 {
                for (i, tri) in chunk.iter().enumerate() {
                    let lane_hit = masks[w] >> i & 1 == 1;
                    // The closest hit's t is checked on its lane; other lanes' decisions only.
                    let t = match closest[w] {
                        Some(h) if h.prim == i as u32 => Some(h.t),
                        _ if lane_hit => Some(f32::NAN),
                        _ => None,
                    };
                    self.judge(2 + w, verdict[i], bound[i], t, ray, tri);
                }
            }
        }
    }

    fn report(&self, name: &str) {
        println!(
            "{name}: {} pairs, {} clear hits, {} knife edges ({} ill-conditioned, {} of them crossing within half a triangle)",
            self.pairs, self.clear_hits, self.knife, self.ill, self.ill_near
        );
        for (k, c) in self.k.iter().enumerate() {
            println!(
                "    {:14} hits {:7} (knife edge {:6})  max |t32 - t64| / Dt {:.2e}  false misses: clear {} knife edge {}  unconfirmed {}",
                KERNELS[k], c.hits, c.knife_hits, c.max_ratio, c.clear_false_miss, c.knife_false_miss, c.unconfirmed
            );
        }
        if let Some(f) = &self.first_failure {
            println!("    first failure: {f}");
        }
    }

    fn assert_confirmed(&self, name: &str) {
        for (k, c) in self.k.iter().enumerate() {
            assert_eq!(
                c.unconfirmed, 0,
                "{name}, {}: unconfirmed f32 hits: {:?}",
                KERNELS[k], self.first_failure
            );
            assert_eq!(
                c.clear_false_miss, 0,
                "{name}, {}: false misses on clear hits: {:?}",
                KERNELS[k], self.first_failure
            );
        }
    }
}

/// Runs a family: `cases` rays, each against its triangles.
fn run_family(name: &str, cases: &[(Ray, Vec<Triangle>)]) -> Family {
    let mut f = Family::default();
    for (ray, tris) in cases {
        f.check(ray, tris);
    }
    f.report(name);
    f.assert_confirmed(name);
    f
}

/// An orthonormal frame `(a, b, n)` from a random unit vector.
fn frame(rng: &mut Rng) -> (Vec3, Vec3, Vec3) {
    let n = rng.unit_vector();
    let a = n.any_orthonormal_vector();
    (a, n.cross(a), n)
}

/// `10^x` for `x` uniform in `[lo, hi)`.
fn log_uniform(rng: &mut Rng, lo: f32, hi: f32) -> f32 {
    10f32.powf(rng.range(lo, hi))
}

/// A point of `tri` at barycentrics drawn from `[-0.05, 1.05]` (some just outside).
fn aim_point(rng: &mut Rng, tri: &Triangle) -> Vec3 {
    let (mut a, mut b) = (rng.f32(), rng.f32());
    if a + b > 1.0 {
        (a, b) = (1.0 - a, 1.0 - b);
    }
    let (a, b) = (a * 1.1 - 0.05, b * 1.1 - 0.05);
    tri[0] + (tri[1] - tri[0]) * a + (tri[2] - tri[0]) * b
}

/// A ray from `origin` towards `target`, with one of a few `[tmin, tmax)` (the target at `t = 1`).
fn ray_to(rng: &mut Rng, origin: Vec3, target: Vec3) -> Ray {
    let (tmin, tmax) = match rng.u64() % 8 {
        0 => (0.5, 1.5),
        1 => (1.0, 2.0), // target at tmin
        2 => (0.0, 1.0), // target at tmax (exclusive)
        3 => (f32::NEG_INFINITY, f32::INFINITY),
        _ => (0.0, f32::INFINITY),
    };
    Ray::with_range(origin, target - origin, tmin, tmax)
}

/// Eight triangles from `make`, and one ray aimed at a point of one of them from `origin_of`.
fn cases(
    n: usize,
    seed: u64,
    mut make: impl FnMut(&mut Rng) -> Triangle,
    mut origin_of: impl FnMut(&mut Rng, &Triangle, Vec3) -> Vec3,
) -> Vec<(Ray, Vec<Triangle>)> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let tris: Vec<Triangle> = (0..8).map(|_| make(&mut rng)).collect();
            let k = (rng.u64() % 8) as usize;
            let target = aim_point(&mut rng, &tris[k]);
            let o = origin_of(&mut rng, &tris[k], target);
            (ray_to(&mut rng, o, target), tris)
        })
        .collect()
}

fn random_in(rng: &mut Rng, lo: f32, hi: f32) -> Vec3 {
    Vec3::new(rng.range(lo, hi), rng.range(lo, hi), rng.range(lo, hi))
}

#[test]
fn random_triangles() {
    let c = cases(
        20_000,
        1,
        |r| {
            [
                random_in(r, -10.0, 10.0),
                random_in(r, -10.0, 10.0),
                random_in(r, -10.0, 10.0),
            ]
        },
        |r, _, _| random_in(r, -20.0, 20.0),
    );
    run_family("random", &c);
}

#[test]
fn near_parallel_rays() {
    // Well-shaped triangles in a random plane; rays at 1e-6 .. 1e-1 rad to it, aimed inside.
    let mut rng = Rng::new(2);
    let mut out = Vec::new();
    for _ in 0..20_000 {
        let (a, b, n) = frame(&mut rng);
        let c = random_in(&mut rng, -5.0, 5.0);
        let s = rng.range(1.0, 10.0);
        let vtx = |r: &mut Rng, k: f32| {
            let ang = (k + r.range(-0.2, 0.2)) * core::f32::consts::TAU / 3.0;
            c + (a * ang.cos() + b * ang.sin()) * s
        };
        let tri = [vtx(&mut rng, 0.0), vtx(&mut rng, 1.0), vtx(&mut rng, 2.0)];
        let target = aim_point(&mut rng, &tri);
        let theta = log_uniform(&mut rng, -6.0, -1.0);
        let phi = rng.range(0.0, core::f32::consts::TAU);
        let along = a * phi.cos() + b * phi.sin();
        let side = if rng.f32() < 0.5 { 1.0 } else { -1.0 };
        let dir = along * theta.cos() + n * (side * theta.sin());
        let o = target - dir * s * rng.range(1.0, 4.0);
        out.push((ray_to(&mut rng, o, target), vec![tri]));
    }
    run_family("near-parallel (1e-6 .. 1e-1 rad)", &out);
}

#[test]
fn skinny_triangles() {
    // Needles with aspect ratios 10 .. 1e6 in random orientations.
    let needle = |r: &mut Rng| -> Triangle {
        let (a, b, _) = frame(r);
        let c = random_in(r, -5.0, 5.0);
        let len = r.range(0.5, 5.0);
        let aspect = log_uniform(r, 1.0, 6.0);
        [c, c + a * len, c + a * (len * r.f32()) + b * (len / aspect)]
    };
    let c = cases(20_000, 3, needle, |r, _, target| {
        target + r.unit_vector() * r.range(1.0, 20.0)
    });
    run_family("skinny (aspect 1e1 .. 1e6)", &c);
}

#[test]
fn huge_triangles() {
    let huge = |r: &mut Rng| -> Triangle {
        let s = log_uniform(r, 6.0, 8.0);
        let off = if r.f32() < 0.5 {
            Vec3::ZERO
        } else {
            r.unit_vector() * s * r.range(1.0, 10.0)
        };
        [0, 1, 2].map(|_| off + random_in(r, -s, s))
    };
    let c = cases(10_000, 4, huge, |r, tri, target| {
        let s = (tri[1] - tri[0]).abs().max_element();
        target + r.unit_vector() * s * r.range(0.5, 5.0)
    });
    run_family("huge (1e6 .. 1e8, near and far)", &c);
}

#[test]
fn tiny_triangles() {
    // Sizes 1e-8 .. 1e-6, placed at up to 1e4 sizes from the origin (where f32 still resolves them);
    // rays from nearby or from the world origin.
    let tiny = |r: &mut Rng| -> Triangle {
        let s = log_uniform(r, -8.0, -6.0);
        let off = r.unit_vector() * s * log_uniform(r, 0.0, 4.0);
        [0, 1, 2].map(|_| off + random_in(r, -s, s))
    };
    let c = cases(10_000, 5, tiny, |r, tri, target| {
        let s = (tri[1] - tri[0]).abs().max_element();
        if r.f32() < 0.25 {
            Vec3::ZERO
        } else {
            target + r.unit_vector() * s * log_uniform(r, 0.0, 3.0)
        }
    });
    run_family("tiny (1e-8 .. 1e-6, near and far)", &c);
}

/// Rays aimed at the edges or vertices of `mesh`: every pair judged, and per ray whether the mesh
/// is hit where the reference hits it.
fn aimed(name: &str, mesh: &scene::Mesh, targets: &scene::Mesh, aim: Aim, per_target: usize, seed: u64) {
    let tris = mesh.to_soup();
    let rays = scene::aimed_rays(targets, aim, per_target, 3.0, seed);
    let mut f = Family::default();
    let mut mesh_miss = [0usize; 4];
    let mut reference_hit = 0;
    for ray in &rays {
        f.check(ray, &tris);
        let pre = PreparedRay::new(ray);
        let expect = tris
            .iter()
            .any(|t| crossing_f64(ray, t).is_some_and(|c| c.hit().is_some()));
        if !expect {
            continue;
        }
        reference_hit += 1;
        let packs: Vec<TriangleX8> = tris.chunks(8).map(|c| TriangleX8::pack(c, &[])).collect();
        let got = [
            tris.iter().any(|t| moller::intersect_scalar(&pre, t, 0).is_some()),
            tris.iter().any(|t| watertight::intersect_scalar(&pre, t, 0).is_some()),
            packs.iter().any(|p| moller::occluded_x8(&pre, p)),
            packs.iter().any(|p| watertight::occluded_x8(&pre, p)),
        ];
        for k in 0..4 {
            mesh_miss[k] += !got[k] as usize;
        }
    }
    f.report(name);
    println!(
        "    mesh level: {} rays, {} hit by the reference; let through: moller {} ({:.2}%), watertight {}, moller x8 {}, watertight x8 {}",
        rays.len(),
        reference_hit,
        mesh_miss[0],
        100.0 * mesh_miss[0] as f64 / reference_hit.max(1) as f64,
        mesh_miss[1],
        mesh_miss[2],
        mesh_miss[3]
    );
    f.assert_confirmed(name);
    assert_eq!(mesh_miss[1], 0, "{name}: the watertight test let rays through");
    assert_eq!(mesh_miss[3], 0, "{name}: the x8 watertight test let rays through");
}

#[test]
fn edge_and_vertex_aimed_rays() {
    let mut m = scene::icosphere(2);
    for p in &mut m.positions {
        *p = *p * 3.7 + Vec3::new(0.31, -1.7, 2.1);
    }
    aimed("icosphere(2) edges", &m, &m, Aim::Edges, 4, 11);
    aimed("icosphere(2) vertices", &m, &m, Aim::Vertices, 16, 12);
    let mut fan = scene::fan(64, 0.3);
    for p in &mut fan.positions {
        *p = *p * 1.3 + Vec3::new(-0.7, 0.45, 1.1);
    }
    let apex = scene::Mesh {
        positions: vec![fan.positions[0]],
        indices: vec![],
    };
    aimed("fan(64) apex", &fan, &apex, Aim::Vertices, 2000, 13);
}

// ---- Boxes ----

#[derive(Default)]
struct BoxCounts {
    pairs: usize,
    hits: usize,
    touching_false_hits: usize,
    max_entry_ratio: f64,
    max_gap_ratio: f64,
}

/// Judges the scalar and x8 slab tests on one ray and up to 8 boxes against the `f64` interval.
fn check_boxes(c: &mut BoxCounts, ray: &Ray, boxes: &[Aabb]) {
    let pre = PreparedRay::new(ray);
    let (near8, mask) = intersect_aabb_x8(&pre, &AabbX8::from_boxes(boxes));
    for (i, b) in boxes.iter().enumerate() {
        c.pairs += 1;
        let s = intersect_aabb_scalar(&pre, b);
        assert_eq!(s.is_some(), mask >> i & 1 == 1, "x8 lane {i} disagrees: {ray:?} {b:?}");
        if let Some(t) = s {
            assert_eq!(t.to_bits(), near8.to_array()[i].to_bits());
        }
        let exact = aabb_interval_f64(ray, b);
        let hit64 = exact.is_some_and(|(n, f)| n <= f);
        assert!(
            !hit64 || s.is_some(),
            "f32 slab test misses a box the f64 test hits: ray o {} d {} [{}, {}) box {} {}",
            bits(ray.origin),
            bits(ray.direction),
            ray.tmin,
            ray.tmax,
            bits(b.min),
            bits(b.max)
        );
        let Some(t32) = s else { continue };
        c.hits += 1;
        let Some((near, far)) = exact else {
            panic!("f32 hit for a ray the reference calls invalid: {ray:?}");
        };
        if !hit64 {
            c.touching_false_hits += 1;
            let scale = near.abs().max(far.abs());
            let ratio = (near - far) / (AABB_GAP_REL_BOUND * scale);
            c.max_gap_ratio = c.max_gap_ratio.max(ratio);
            assert!(
                ratio <= 1.0,
                "box false hit beyond the bound: {ray:?} {b:?} near {near} far {far}"
            );
            continue;
        }
        let t32 = t32 as f64;
        if t32 != near {
            let ratio = (t32 - near).abs() / (AABB_ENTRY_REL_BOUND * near.abs());
            c.max_entry_ratio = c.max_entry_ratio.max(ratio);
            assert!(
                ratio <= 1.0,
                "box entry {t32} vs {near} beyond the bound: {ray:?} {b:?}"
            );
        }
    }
}

fn box_family(name: &str, cases: &[(Ray, Vec<Aabb>)]) {
    let mut c = BoxCounts::default();
    for (r, b) in cases {
        check_boxes(&mut c, r, b);
    }
    println!(
        "{name}: {} pairs, {} f32 hits, {} touching false hits (max gap / bound {:.2e}), max |entry32 - entry64| / bound {:.2e}, 0 false misses",
        c.pairs, c.hits, c.touching_false_hits, c.max_gap_ratio, c.max_entry_ratio
    );
}

/// A box of size ~`s` around `center`, flat on one axis one time in eight.
fn random_box(rng: &mut Rng, center: Vec3, s: f32) -> Aabb {
    let a = center + random_in(rng, -s, s);
    let b = center + random_in(rng, -s, s);
    let mut bx = Aabb::new(a.min(b), a.max(b));
    if rng.u64().is_multiple_of(8) {
        let k = (rng.u64() % 3) as usize;
        bx.max[k] = bx.min[k];
    }
    bx
}

/// A point on the surface of `b`: a corner, a point on an edge, or on a face.
fn surface_point(rng: &mut Rng, b: &Aabb) -> Vec3 {
    let mut p = Vec3::ZERO;
    let kind = rng.u64() % 3; // number of free coordinates
    let fixed = (rng.u64() % 3) as usize;
    for a in 0..3 {
        let pick = if rng.f32() < 0.5 { b.min[a] } else { b.max[a] };
        let free = match kind {
            0 => false,
            1 => a == fixed,
            _ => a != fixed,
        };
        p[a] = if free {
            b.min[a] + (b.max[a] - b.min[a]) * rng.f32()
        } else {
            pick
        };
    }
    p
}

fn box_cases(n: usize, seed: u64, scale: (f32, f32), far: (f32, f32)) -> Vec<(Ray, Vec<Aabb>)> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let s = log_uniform(&mut rng, scale.0, scale.1);
            let center = rng.unit_vector() * s * log_uniform(&mut rng, far.0, far.1);
            let boxes: Vec<Aabb> = (0..8).map(|_| random_box(&mut rng, center, s)).collect();
            let k = (rng.u64() % 8) as usize;
            let target = surface_point(&mut rng, &boxes[k]);
            let ray = match rng.u64() % 4 {
                // Towards a corner, edge or face point.
                0 | 1 => {
                    let o = center + rng.unit_vector() * s * 3.0;
                    ray_to(&mut rng, o, target)
                }
                // Grazing a face: along it, tilted by 1e-6 .. 1e-1 rad.
                2 => {
                    let a = (rng.u64() % 3) as usize;
                    let mut d = rng.unit_vector();
                    d[a] = 0.0;
                    let d = d.normalize_or(Vec3::X);
                    let mut tilt = Vec3::ZERO;
                    tilt[a] = log_uniform(&mut rng, -6.0, -1.0) * if rng.f32() < 0.5 { 1.0 } else { -1.0 };
                    let dir = d + tilt;
                    ray_to(&mut rng, target - dir * s * 2.0, target)
                }
                // Axis-aligned with +-0 components, from a point on a slab plane or inside.
                _ => {
                    let a = (rng.u64() % 3) as usize;
                    let mut d = Vec3::new(0.0, -0.0, if rng.f32() < 0.5 { 0.0 } else { -0.0 });
                    d[a] = if rng.f32() < 0.5 { 1.0 } else { -1.0 };
                    let mut o = target;
                    o[a] -= d[a] * s * 3.0;
                    let tmin = if rng.f32() < 0.25 { f32::NEG_INFINITY } else { 0.0 };
                    Ray::with_range(o, d, tmin, f32::INFINITY)
                }
            };
            (ray, boxes)
        })
        .collect()
}

#[test]
fn boxes_against_f64_slab_test() {
    box_family("boxes, unit scale", &box_cases(3000, 21, (0.0, 1.0), (0.0, 1.0)));
    box_family("boxes, huge (1e6 .. 1e8)", &box_cases(2000, 22, (6.0, 8.0), (0.0, 1.0)));
    box_family(
        "boxes, tiny (1e-8 .. 1e-6)",
        &box_cases(2000, 23, (-8.0, -6.0), (0.0, 3.0)),
    );
    let mut rng = Rng::new(24);
    let random: Vec<(Ray, Vec<Aabb>)> = (0..3000)
        .map(|_| {
            let boxes = (0..8).map(|_| random_box(&mut rng, Vec3::ZERO, 10.0)).collect();
            let ray = Ray::new(random_in(&mut rng, -20.0, 20.0), rng.unit_vector());
            (ray, boxes)
        })
        .collect();
    box_family("boxes, random rays", &random);
}

// ---- Property tests on bounded floats ----

fn triangle_scene() -> impl Strategy<Value = (Ray, Vec<Triangle>)> {
    let tri = (vec3(bounded()), vec3(bounded()), vec3(bounded())).prop_map(|(a, b, c)| [a, b, c]);
    (
        proptest::collection::vec(tri, 8),
        vec3(bounded()),
        0usize..8,
        0.0f32..1.0,
        0.0f32..1.0,
        any::<u64>(),
    )
        .prop_map(|(tris, o, k, a, b, seed)| {
            let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
            let t = tris[k];
            let target = t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b;
            (ray_to(&mut Rng::new(seed), o, target), tris)
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, ..ProptestConfig::default() })]

    #[test]
    fn bounded_triangles_confirmed((ray, tris) in triangle_scene()) {
        let mut f = Family::default();
        f.check(&ray, &tris);
        for (k, c) in f.k.iter().enumerate() {
            prop_assert_eq!(c.unconfirmed + c.clear_false_miss, 0, "{}: {:?}", KERNELS[k], f.first_failure);
        }
    }

    #[test]
    fn bounded_boxes_confirmed(o in vec3(bounded()), d in vec3(bounded()), corners in proptest::collection::vec((vec3(bounded()), vec3(bounded())), 8)) {
        let boxes: Vec<Aabb> = corners.iter().map(|(a, b)| Aabb::new(a.min(*b), a.max(*b))).collect();
        check_boxes(&mut BoxCounts::default(), &Ray::new(o, d), &boxes);
    }
}
