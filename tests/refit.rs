//! `BvhWide::refit`: a refit with unchanged triangles changes no bit of the tree; after the
//! triangles move (rigidly, by jitter larger than themselves, through shared vertices of an
//! indexed mesh, onto one point), become non-finite, move beyond the range the builders accept
//! or go missing, every child box is the exact box of the kept triangles below it, and BVH4/BVH8
//! closest and any hits equal brute force's over the moved triangles the tree keeps.

mod common;

use common::{mixed_rays, same};
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::{INVALID, Triangle, Triangles};
use strahl::layout::{BvhWide, EMPTY_CHILD, LEAF_BIT, leaf_packs};
use strahl::math::{Lane, f32x4, f32x8};
use strahl::scene::{self, Rng};
use strahl::traverse::{Moller, Watertight, intersect_brute_force, occluded_brute_force};
use strahl::{Hit, Ray, Vec3};

/// `true` if a refit keeps `t` in the tree: the builders' rule (`Primitives`, `Bvh2::refit`),
/// finite vertices and a box whose extent and `min + max` are finite (no coordinate beyond about
/// `±1.7e38`).
fn kept(t: &Triangle) -> bool {
    let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
    t.iter().all(|v| v.is_finite()) && (hi - lo).is_finite() && (hi + lo).is_finite()
}

/// `tris` with every triangle a refit leaves out made NaN (never hit by brute force), so that
/// brute force's answers are the tree's.
fn kept_only(tris: &[Triangle]) -> Vec<Triangle> {
    tris.iter().map(|t| if kept(t) { *t } else { [Vec3::NAN; 3] }).collect()
}

/// Every word of two trees, lane by lane (`to_bits`), the same; a box edge of `-0.0` counts as
/// `+0.0` (the collapse and the refit may take a zero's sign from different triangles).
fn identical<L: Lane, const N: usize>(a: &BvhWide<L, N>, b: &BvhWide<L, N>) -> bool {
    let lanes = |v: &L| (0..N).map(|i| v.lane(i).to_bits()).collect::<Vec<_>>();
    let edges = |v: &L| (0..N).map(|i| (v.lane(i) + 0.0).to_bits()).collect::<Vec<_>>();
    a.depth() == b.depth()
        && a.nodes().len() == b.nodes().len()
        && a.packs().len() == b.packs().len()
        && a.nodes().iter().zip(b.nodes()).all(|(x, y)| {
            x.child == y.child
                && (0..3).all(|k| {
                    edges(&x.bounds.min[k]) == edges(&y.bounds.min[k])
                        && edges(&x.bounds.max[k]) == edges(&y.bounds.max[k])
                })
        })
        && a.packs().iter().zip(b.packs()).all(|(x, y)| {
            x.prim == y.prim
                && x.valid == y.valid
                && (0..3).all(|v| (0..3).all(|k| lanes(&x.v[v][k]) == lanes(&y.v[v][k])))
        })
}

/// The exact box of the kept triangles (read from `tris`) below child code `code`, checked
/// against every lane on the way: each child box must be exactly what it holds. Returns the box
/// and counts the triangles seen in `seen`.
fn check_boxes<L: Lane, const N: usize, P: Triangles + ?Sized>(
    bvh: &BvhWide<L, N>,
    tris: &P,
    code: u32,
    seen: &mut Vec<u32>,
) -> (Vec3, Vec3) {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    if code & LEAF_BIT != 0 {
        let (first, count) = leaf_packs(code);
        for pack in &bvh.packs()[first..first + count] {
            for (i, &p) in pack.prim.iter().enumerate() {
                if p == INVALID {
                    continue;
                }
                seen.push(p);
                match tris.triangle(p as usize) {
                    Some(t) if kept(&t) => {
                        assert_eq!(pack.get(i), t, "prim {p}: lane not refilled");
                        for v in t {
                            (lo, hi) = (lo.min(v), hi.max(v));
                        }
                    }
                    _ => assert_eq!(pack.valid >> i & 1, 0, "prim {p}: left out, still valid"),
                }
            }
        }
        return (lo, hi);
    }
    let node = &bvh.nodes()[code as usize];
    for (slot, &c) in node.child.iter().enumerate() {
        let (l, h) = if c == EMPTY_CHILD {
            (Vec3::INFINITY, Vec3::NEG_INFINITY)
        } else {
            check_boxes(bvh, tris, c, seen)
        };
        let b = &node.bounds;
        let got_lo = Vec3::new(b.min[0].lane(slot), b.min[1].lane(slot), b.min[2].lane(slot));
        let got_hi = Vec3::new(b.max[0].lane(slot), b.max[1].lane(slot), b.max[2].lane(slot));
        assert_eq!((got_lo, got_hi), (l, h), "node {code} slot {slot}");
        (lo, hi) = (lo.min(l), hi.max(h));
    }
    (lo, hi)
}

/// Brute-force answers over the kept triangles of a moved soup on mixed rays, computed once per
/// motion and shared by every tree refitted to it.
struct Truth {
    kept: Vec<Triangle>,
    rays: Vec<Ray>,
    watertight: Vec<Option<Hit>>,
    moller: Vec<Option<Hit>>,
    any: Vec<bool>,
}

impl Truth {
    fn new(tris: &[Triangle]) -> Self {
        // Rays over the kept triangles (mixed_rays skips nothing: it needs some triangles).
        let finite: Vec<Triangle> = tris.iter().copied().filter(kept).collect();
        let kept = kept_only(tris);
        let rays = if finite.is_empty() {
            vec![Ray::new(Vec3::splat(-1.0), Vec3::ONE)]
        } else {
            mixed_rays(&finite, 400, 3)
        };
        let watertight = rays
            .iter()
            .map(|r| intersect_brute_force::<Watertight, _>(&kept[..], r))
            .collect();
        let moller = rays
            .iter()
            .map(|r| intersect_brute_force::<Moller, _>(&kept[..], r))
            .collect();
        let any = rays
            .iter()
            .map(|r| occluded_brute_force::<Watertight, _>(&kept[..], r))
            .collect();
        Self {
            kept,
            rays,
            watertight,
            moller,
            any,
        }
    }
}

/// Refits `bvh` to `tris` and checks it: the left-out count, the boxes, each triangle of the
/// tree seen once, and closest and any hits against brute force over the kept triangles of
/// `tris` on mixed rays (`truth`, from `Truth::new(tris)`).
fn refit_and_check<L: Lane, const N: usize>(
    bvh: &mut BvhWide<L, N>,
    tris: &[Triangle],
    n_prims: usize,
    truth: &Truth,
    what: &str,
) {
    let want_out = (0..n_prims).filter(|&p| !tris.get(p).is_some_and(kept)).count();
    assert_eq!(bvh.refit(tris), want_out, "{what}");
    let mut seen = Vec::new();
    if !bvh.is_empty() {
        check_boxes(bvh, tris, 0, &mut seen);
    }
    seen.sort_unstable();
    assert_eq!(
        seen,
        (0..n_prims as u32).collect::<Vec<_>>(),
        "{what}: each triangle once"
    );
    let kept = &truth.kept[..];
    for (k, ray) in truth.rays.iter().enumerate() {
        same(bvh.intersect::<Watertight>(ray), truth.watertight[k], kept, ray, what);
        same(bvh.intersect::<Moller>(ray), truth.moller[k], kept, ray, what);
        assert_eq!(bvh.occluded::<Watertight>(ray), truth.any[k], "{what}: {ray:?}");
    }
}

/// The ways triangles move, each a function of the original soup.
fn motions(tris: &[Triangle], seed: u64) -> Vec<(&'static str, Vec<Triangle>)> {
    let mut rng = Rng::new(seed);
    let map = |f: &dyn Fn(Vec3) -> Vec3| tris.iter().map(|t| t.map(f)).collect::<Vec<_>>();
    let rigid = map(&|v| {
        let (s, c) = 0.7f32.sin_cos();
        Vec3::new(c * v.x - s * v.z, v.y, s * v.x + c * v.z) * 3.0 + Vec3::new(100.0, -4.0, 0.5)
    });
    let jitter: Vec<Triangle> = tris
        .iter()
        .map(|t| t.map(|v| v + Vec3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), rng.range(-0.3, 0.3))))
        .collect();
    let point = map(&|_| Vec3::splat(2.0));
    let mut broken = jitter.clone();
    for (i, t) in broken.iter_mut().enumerate() {
        match i % 7 {
            0 => t[1].y = f32::NAN,
            3 => t[2].x = f32::INFINITY,
            // Finite, but beyond the range: `min + max` overflows.
            5 => *t = t.map(|v| v + Vec3::new(1.8e38, 0.0, 0.0)),
            // Finite, but the extent overflows.
            6 => (t[0].z, t[1].z) = (-3e38, 3e38),
            _ => {}
        }
    }
    vec![
        ("rigid", rigid),
        ("jitter", jitter),
        ("point", point),
        ("non-finite or beyond the range", broken),
    ]
}

fn check_width<L: Lane, const N: usize>(tris: &[Triangle], name: &str) {
    let cases: Vec<_> = motions(tris, 5)
        .into_iter()
        .map(|(motion, moved)| {
            let truth = Truth::new(&moved);
            (motion, moved, truth)
        })
        .collect();
    let half_truth: Vec<(Ray, Option<Hit>)> = mixed_rays(tris, 300, 9)
        .into_iter()
        .map(|r| (r, intersect_brute_force::<Watertight, _>(&tris[..tris.len() / 2], &r)))
        .collect();
    for (pname, p) in [("default", BuildParams::default()), ("fastest", BuildParams::fastest())] {
        let (b2, _) = Bvh2::build(tris, &p).unwrap();
        let trees = [
            ("cost-optimal", BvhWide::<L, N>::from_bvh2(&b2, tris).unwrap()),
            ("greedy", BvhWide::<L, N>::from_bvh2_greedy(&b2, tris).unwrap()),
            ("threaded", BvhWide::<L, N>::from_bvh2_par(&b2, tris, 2).unwrap()),
        ];
        for (cname, tree) in trees {
            let what = format!("{name} / {pname} / {cname} / {N} wide");
            // Unchanged triangles: not a bit changes.
            let mut same_tree = tree.clone();
            assert_eq!(same_tree.refit(tris), 0, "{what}");
            assert!(
                identical(&same_tree, &tree),
                "{what}: a refit without motion changed the tree"
            );
            for (motion, moved, truth) in &cases {
                let mut t = tree.clone();
                refit_and_check(&mut t, moved, tris.len(), truth, &format!("{what} / {motion}"));
                // And back: the very tree of the start again.
                assert_eq!(t.refit(tris), 0);
                assert!(
                    identical(&t, &tree),
                    "{what} / {motion}: not the same tree after moving back"
                );
            }
            // Triangles gone missing (a shorter slice): left out, the rest exact.
            let mut t = tree.clone();
            let half = &tris[..tris.len() / 2];
            let mut seen = Vec::new();
            assert_eq!(t.refit(half), tris.len() - half.len(), "{what}");
            if !t.is_empty() {
                check_boxes(&t, half, 0, &mut seen);
            }
            for (ray, want) in &half_truth {
                same(t.intersect::<Watertight>(ray), *want, half, ray, &what);
            }
        }
    }
}

#[test]
fn refits_are_exact_in_every_width() {
    let flake = scene::sphereflake(1, 1).to_soup();
    let soup = {
        let mut rng = Rng::new(11);
        (0..3000)
            .map(|_| {
                let c = Vec3::new(rng.range(-5.0, 5.0), rng.range(-5.0, 5.0), rng.range(-5.0, 5.0));
                [c, c + rng.unit_vector() * 0.4, c + rng.unit_vector() * 0.4]
            })
            .collect::<Vec<Triangle>>()
    };
    // Large enough that `from_bvh2_par(.., 2)` splits the work (and numbers the nodes its own way).
    let thin = scene::thin_soup(20_000, 3);
    // Box edges at -0.0 and +0.0 side by side.
    let zeros: Vec<Triangle> = (0..64)
        .map(|i| {
            let z = if i % 2 == 0 { -0.0 } else { 0.0 };
            let y = (i / 2) as f32;
            [Vec3::new(z, y, z), Vec3::new(1.0, y, z), Vec3::new(z, y + 1.0, 1.0)]
        })
        .collect();
    for (name, tris) in [
        ("sphereflake", &flake),
        ("soup", &soup),
        ("thin soup", &thin),
        ("signed zeros", &zeros),
    ] {
        check_width::<f32x4, 4>(tris, name);
        check_width::<f32x8, 8>(tris, name);
    }
}

/// An indexed mesh: moving a shared vertex moves every triangle around it; an index past the
/// vertex array leaves its triangles out.
#[test]
fn indexed_meshes_refit_through_shared_vertices() {
    let mut mesh = scene::icosphere(3);
    let (b2, _) = Bvh2::build(&mesh.as_indexed(), &BuildParams::default()).unwrap();
    let mut b8 = BvhWide::<f32x8, 8>::from_bvh2(&b2, &mesh.as_indexed()).unwrap();
    for (i, p) in mesh.positions.iter_mut().enumerate() {
        // A bumpy sphere: each vertex out or in along its normal.
        *p *= 1.0 + 0.2 * ((i * 7919) % 13) as f32 / 13.0;
    }
    assert_eq!(b8.refit(&mesh.as_indexed()), 0);
    let soup = mesh.to_soup();
    let mut seen = Vec::new();
    check_boxes(&b8, &mesh.as_indexed(), 0, &mut seen);
    for ray in &mixed_rays(&soup, 400, 1) {
        same(
            b8.intersect::<Watertight>(ray),
            intersect_brute_force::<Watertight, _>(&soup[..], ray),
            &soup,
            ray,
            "bumpy icosphere",
        );
    }
    // The last vertex dropped from the array: the triangles that use it are left out.
    let using = mesh
        .indices
        .iter()
        .filter(|t| t.contains(&(mesh.positions.len() as u32 - 1)))
        .count();
    mesh.positions.pop();
    assert_eq!(b8.refit(&mesh.as_indexed()), using);
}

/// A triangle moved out beyond about `±1.7e38` (finite, but its box's `min + max` overflows) is
/// left out by `BvhWide::refit` and `refit_par` as by `Bvh2::refit` and the builders: counted,
/// never hit, in no box; back in range, it is hit again.
#[test]
fn refit_leaves_out_triangles_beyond_the_range() {
    fn check<L: Lane + Send, const N: usize>() {
        let near: Vec<Triangle> = (0..40)
            .map(|i| {
                let x = 2.0 * i as f32;
                [Vec3::new(x, 0.0, 0.0), Vec3::new(x, 1.0, 0.0), Vec3::new(x, 0.0, 1.0)]
            })
            .collect();
        let mut far = near.clone();
        far[7] = far[7].map(|v| v + Vec3::new(2e38, 0.0, 0.0)); // x = 2e38 + 14 = 2e38
        let mut wide = far.clone();
        wide[9] = [
            Vec3::new(-3e38, 0.0, 0.0),
            Vec3::new(3e38, 1.0, 0.0),
            Vec3::new(18.0, 0.0, 1.0),
        ];
        // From x = 13 along +x: the triangles at x = 14, ..., then (far) at x = 2e38.
        let ray = Ray::new(Vec3::new(13.0, 0.2, 0.2), Vec3::X);
        let beyond = Ray::new(Vec3::new(100.0, 0.2, 0.2), Vec3::X); // only the far one ahead
        let (b2, _) = Bvh2::build(&near[..], &BuildParams::default()).unwrap();
        let tree = BvhWide::<L, N>::from_bvh2(&b2, &near[..]).unwrap();
        assert_eq!(tree.intersect::<Watertight>(&ray).map(|h| h.prim), Some(7));
        for (name, moved, out) in [("far", &far, 1), ("far and wide", &wide, 2)] {
            let what = format!("{name}, {N} wide");
            // Brute force over all the triangles hits the far one; the trees never do.
            assert!(occluded_brute_force::<Watertight, _>(&moved[..], &beyond), "{what}");
            let mut b = b2.clone();
            b.refit(&moved[..]).unwrap();
            assert!(b.intersect::<Watertight, _>(&moved[..], &beyond).is_none(), "{what}");
            let mut one = tree.clone();
            let mut two = tree.clone();
            assert_eq!(one.refit(&moved[..]), out, "{what}");
            assert_eq!(two.refit_par(&moved[..], 2), out, "{what}");
            for t in [&one, &two] {
                assert!(t.intersect::<Watertight>(&beyond).is_none(), "{what}");
                assert!(!t.occluded::<Watertight>(&beyond), "{what}");
                assert!(t.intersect::<Moller>(&beyond).is_none(), "{what}");
                assert_eq!(t.intersect::<Watertight>(&ray).map(|h| h.prim), Some(8), "{what}");
                // The root's box: the kept triangles' only.
                let root = &t.nodes()[0].bounds;
                let hi = (0..N).map(|l| root.max[0].lane(l)).fold(f32::NEG_INFINITY, f32::max);
                let lo = (0..N).map(|l| root.min[0].lane(l)).fold(f32::INFINITY, f32::min);
                assert_eq!((lo, hi), (0.0, 78.0), "{what}");
                let mut seen = Vec::new();
                check_boxes(t, &moved[..], 0, &mut seen);
                assert_eq!(seen.len(), 40, "{what}");
            }
            assert!(identical(&one, &two), "{what}");
            // A collapse of the refit binary tree over the moved triangles keeps to the same
            // rule (its shape may differ: the collapse chooses by the new boxes).
            let collapsed = BvhWide::<L, N>::from_bvh2(&b, &moved[..]).unwrap();
            assert!(collapsed.intersect::<Watertight>(&beyond).is_none(), "{what}");
            assert!(!collapsed.occluded::<Moller>(&beyond), "{what}");
            assert_eq!(
                collapsed.intersect::<Watertight>(&ray).map(|h| h.prim),
                Some(8),
                "{what}"
            );
            let mut seen = Vec::new();
            check_boxes(&collapsed, &moved[..], 0, &mut seen);
            assert_eq!(seen.len(), 40, "{what}");
            // Back in range: hit again, the tree of the start.
            assert_eq!(one.refit(&near[..]), 0, "{what}");
            assert!(identical(&one, &tree), "{what}");
            assert_eq!(one.intersect::<Watertight>(&ray).map(|h| h.prim), Some(7), "{what}");
        }
    }
    check::<f32x4, 4>();
    check::<f32x8, 8>();
}

#[test]
fn an_empty_tree_refits_to_nothing() {
    let tris = [[Vec3::splat(f32::NAN); 3]];
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let mut b8 = BvhWide::<f32x8, 8>::from_bvh2(&b2, &tris[..]).unwrap();
    assert!(b8.is_empty());
    assert_eq!(b8.refit(&[[Vec3::ZERO, Vec3::X, Vec3::Y]][..]), 0);
    assert!(
        b8.intersect::<Moller>(&Ray::new(Vec3::new(0.1, 0.1, -1.0), Vec3::Z))
            .is_none()
    );
}

/// `refit_par` on 1 to 4 threads: the very tree `refit` makes, and the same count left out
/// (the soup is large enough for every thread count to split the packs).
#[test]
fn threaded_refits_equal_the_single_threaded_one() {
    fn check<L: Lane + Send, const N: usize>(tris: &[Triangle]) {
        let (b2, _) = Bvh2::build(tris, &BuildParams::default()).unwrap();
        let tree = BvhWide::<L, N>::from_bvh2_par(&b2, tris, 2).unwrap();
        assert!(
            tree.packs().len() >= 4 * 1024,
            "{} packs: too few to split",
            tree.packs().len()
        );
        for (motion, moved) in motions(tris, 8) {
            let mut one = tree.clone();
            let want = one.refit(&moved[..]);
            for threads in 1..=4 {
                let mut par = tree.clone();
                assert_eq!(par.refit_par(&moved[..], threads), want, "{motion} on {threads}");
                assert!(identical(&one, &par), "{motion} on {threads} threads: another tree");
            }
        }
    }
    let tris = scene::thin_soup(40_000, 2);
    check::<f32x4, 4>(&tris);
    check::<f32x8, 8>(&tris);
}
