//! The `bvh` target: every builder (and the treelet pass, and spatial splits), the BVH4/BVH8
//! collapse, single-ray traversal of all three trees and 8-ray packets (also with a hit filter), and the BVH8 refit,
//! against brute force.
//!
//! Input layout (every byte string decodes; see [`decode`](crate::decode) for values):
//!
//! ```text
//! header   1 byte   bit 0: mode (0 chaos, 1 grid); bit 1: append a copy of every triangle
//!                   (coincident centroids, ties); bits 2-3: groups of 8 triangles - 1
//! tris     groups x 8 triangles (shared vertex pool, as in `kernels`)
//! rays     8 x (origin, direction: 3 values each; range selector)
//! ```
//!
//! What must hold, in both modes: every build succeeds and `validate()` passes; every valid
//! primitive is in the tree. Where every non-zero coordinate lies in [`TAME_MIN`]`..=`[`TAME`]
//! (always in grid mode): closest hits of BVH2, BVH4, BVH8 and 8-ray packets have the `t` of
//! brute force over the tree's primitives (bit for bit for the same primitive; another primitive
//! only where it hits at an equal `t`, `+0` and `-0` included); any-hit answers agree.

use crate::decode::{Input, Mode};
use strahl::build::{
    BuildParams, Bvh2, MortonBits, MortonCells, Refine, ReinsertParams, SpatialSplits, Strategy, TreeletParams,
};
use strahl::geometry::{Hit, Triangle};
use strahl::intersect::{PreparedRay, watertight};
use strahl::layout::{Bvh4, Bvh8};
use strahl::math::f32x8;
use strahl::traverse::{Fast, Watertight, packet, wide};
use strahl::{Ray, Vec3};

/// Largest coordinate magnitude at which chaos inputs are compared with brute force.
pub const TAME: f32 = 1e15;
/// Smallest non-zero coordinate magnitude at which chaos inputs are compared with brute force.
pub const TAME_MIN: f32 = 1e-15;

/// A decoded `bvh` input.
#[derive(Clone, Debug)]
pub struct BvhCase {
    /// The input mode.
    pub mode: Mode,
    /// The scene.
    pub tris: Vec<Triangle>,
    /// The rays.
    pub rays: Vec<Ray>,
}

impl BvhCase {
    /// Decodes `data` (never fails).
    pub fn decode(data: &[u8]) -> Self {
        let mut inp = Input::new(data);
        let h = inp.byte();
        let mode = Mode::of_header(h);
        let groups = usize::from(h >> 2 & 3) + 1;
        let mut tris = Vec::new();
        for _ in 0..groups {
            tris.extend(inp.triangles::<8>(mode));
        }
        if h & 2 != 0 {
            tris.extend_from_within(..);
        }
        let rays = (0..8)
            .map(|_| {
                let o = inp.vec3(mode);
                let d = inp.vec3(mode);
                let (tmin, tmax) = inp.range(mode);
                Ray::with_range(o, d, tmin, tmax)
            })
            .collect();
        Self { mode, tris, rays }
    }
}

/// The builders checked, from fastest to best, with the hybrids and refinement.
pub fn builders() -> Vec<BuildParams> {
    vec![
        BuildParams::fastest(),
        BuildParams {
            morton_bits: MortonBits::Bits63,
            ..BuildParams::fastest()
        },
        BuildParams {
            morton_cells: MortonCells::Normalized,
            ..BuildParams::fastest()
        },
        BuildParams::median(),
        BuildParams::fast(),
        BuildParams::balanced(),
        BuildParams {
            bin_sample: 64,
            ..BuildParams::balanced()
        },
        BuildParams::high(),
        BuildParams::quality(),
        BuildParams::hybrid(),
        BuildParams {
            strategy: Strategy::Hlbvh,
            cluster_size: 2,
            refine: Refine::None,
            ..BuildParams::hybrid()
        },
        BuildParams {
            refine: Refine::Treelets(TreeletParams::new()),
            ..BuildParams::fastest()
        },
        BuildParams {
            refine: Refine::AgglomerativeTreelets(TreeletParams {
                leaves: 16,
                min_prims: 1,
                rounds: 2,
            }),
            ..BuildParams::fastest()
        },
        BuildParams::hybrid_sah(),
        BuildParams {
            refine: Refine::Rotations(2),
            ..BuildParams::fastest()
        },
        BuildParams {
            refine: Refine::Reinsertion(ReinsertParams::new()),
            ..BuildParams::fastest()
        },
        BuildParams {
            cluster_size: 2,
            morton_bits: MortonBits::Bits63,
            ..BuildParams::hybrid_sah()
        },
        BuildParams::ploc(),
        BuildParams {
            morton_bits: MortonBits::Bits63,
            ..BuildParams::ploc()
        },
    ]
}

/// `got` is `want` up to ties: the same `t` bits, and the same primitive or another one of the
/// tree's that hits `ray` at exactly that `t`.
fn agrees(tris: &[Triangle], ray: &Ray, got: Option<Hit>, want: Option<Hit>, what: &str) {
    match (got, want) {
        (None, None) => {}
        (Some(g), Some(w)) if g.prim == w.prim => {
            assert_eq!(
                g.t.to_bits(),
                w.t.to_bits(),
                "{what}: t {} against brute force {}",
                g.t,
                w.t
            );
        }
        (Some(g), Some(w)) if g.t != w.t && near_tie(ray, g, w) => {
            // A near tie: the tree's hit is real and within rounding of brute force's. A triangle
            // hit whose computed `t` lies a rounding error before its own box's entry distance is
            // culled once a hit closer than that entry is known (found by this target, seed
            // `near-tie-edge-origin`: a ray starting on an edge two triangles share,
            // `tmin = -inf`, their hits 4e-9 apart at `t` = 0 on coordinates of size 8). A known
            // limit of the traversals' exactness, documented at `TriangleTest::CONSERVATIVE_BOXES`.
            let r = PreparedRay::new(ray);
            let alone = tris
                .get(g.prim as usize)
                .and_then(|t| watertight::intersect_scalar(&r, t, g.prim));
            assert_eq!(alone, Some(g), "{what}: prim {} is no hit", g.prim);
        }
        (Some(g), Some(w)) => {
            // A tie: another primitive at the same distance (`==`: `+0` and `-0` tie too, and
            // which of them comes first depends on the visiting order).
            assert!(
                g.t == w.t,
                "{what}: t {} (prim {}) against brute force {} (prim {})",
                g.t,
                g.prim,
                w.t,
                w.prim
            );
            let r = PreparedRay::new(ray);
            let alone = tris
                .get(g.prim as usize)
                .and_then(|t| watertight::intersect_scalar(&r, t, g.prim));
            assert!(alone.is_some_and(|h| h.t == w.t), "{what}: prim {} is no tie", g.prim);
        }
        _ => panic!("{what}: {got:?} against brute force {want:?}"),
    }
}

/// `got` lies after `want` by at most `2^-20` of the ray's scale (origin and the points hit),
/// measured along the ray.
fn near_tie(ray: &Ray, got: Hit, want: Hit) -> bool {
    let d = ray.direction.abs().max_element();
    let scale = ray.origin.abs().max_element() + got.t.abs().max(want.t.abs()) * d + 1.0;
    want.t < got.t && (got.t - want.t) * d <= scale * (1.0 / (1u32 << 20) as f32)
}

/// Checks one decoded input (panics on a failed property).
pub fn check_bvh(case: &BvhCase) {
    let tris = &case.tris[..];
    for params in builders() {
        let (b2, stats) = Bvh2::build(tris, &params).expect("every preset is valid");
        let report = b2
            .validate(tris)
            .unwrap_or_else(|e| panic!("{params:?}: validate: {e:?}"));
        assert_eq!(report.primitives, stats.primitives, "{params:?}");
        assert_eq!((stats.primitives + stats.invalid) as usize, tris.len(), "{params:?}");
        // Brute force over the primitives the tree holds (the others are documented as left out).
        let mut kept: Vec<Triangle> = vec![[Vec3::NAN; 3]; tris.len()];
        for &p in &b2.prim_indices {
            kept[p as usize] = tris[p as usize];
        }
        let b4 = Bvh4::from_bvh2(&b2, tris).expect("a valid tree collapses");
        let b8 = Bvh8::from_bvh2(&b2, tris).expect("a valid tree collapses");
        // Saved and read again: the same bytes; one damaged byte (placed by the input) refused.
        let bytes = b8.to_bytes();
        let loaded = Bvh8::from_bytes(&bytes).expect("a saved tree loads");
        assert_eq!(loaded.to_bytes(), bytes, "{params:?}: bytes written again");
        assert_eq!(
            Bvh4::from_bytes(&b4.to_bytes()).expect("a saved tree loads").depth(),
            b4.depth()
        );
        let at = case.rays.len().wrapping_mul(2_654_435_761) % bytes.len();
        let mut damaged = bytes.clone();
        damaged[at] ^= 0x10;
        assert!(
            Bvh8::from_bytes(&damaged).is_err(),
            "{params:?}: damaged byte {at} read"
        );
        assert!(Bvh8::from_bytes(&bytes[..bytes.len() - 1]).is_err());
        let mut packet_hits = [None; 8];
        packet::intersect8::<Watertight, _, 8>(b8.view(), &case.rays, &mut packet_hits, packet::DEFAULT_SWITCH);
        let mut packet_pure = [None; 8];
        packet::intersect8::<Watertight, _, 8>(b8.view(), &case.rays, &mut packet_pure, 0);
        let mut packet_occ = [false; 8];
        packet::occluded8::<Watertight, _, 8>(b8.view(), &case.rays, &mut packet_occ);
        // Filtered packets (even primitives only), checked with the filtered single rays below.
        let even = |h: &Hit| h.prim.is_multiple_of(2);
        let mut packet_even = [None; 8];
        packet::intersect_packet_filtered::<Watertight, _, 8, f32x8, 8>(
            b8.view(),
            &case.rays,
            &mut packet_even,
            0,
            even,
        );
        let mut packet_even_occ = [false; 8];
        packet::occluded_packet_filtered::<Watertight, _, 8, f32x8, 8>(
            b8.view(),
            &case.rays,
            &mut packet_even_occ,
            packet::DEFAULT_SWITCH,
            even,
        );
        // The incoherent batch answers exactly as one call per ray, on every scene (tame or not).
        let mut batch_occ = vec![false; case.rays.len()];
        b8.occluded_batch_incoherent::<Watertight>(&case.rays, &mut batch_occ);
        for (ray, got) in case.rays.iter().zip(&batch_occ) {
            assert_eq!(
                *got,
                b8.occluded::<Watertight>(ray),
                "{:?}: occluded_batch_incoherent {ray:?}",
                params.strategy
            );
        }
        // Bit for bit (the same walk). A hit has a finite `t` and finite barycentrics: a ray
        // with `tmin = -inf` and a tiny direction (found by this target) once hit at `t = -inf`
        // with NaN barycentrics; `tmin` is now taken as `-f32::MAX` there.
        let bits = |h: Option<Hit>| {
            h.map(|h| {
                assert!(
                    h.t.is_finite() && h.u.is_finite() && h.v.is_finite(),
                    "a hit off the finite range: {h:?}"
                );
                (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim)
            })
        };
        let mut batch_hits = vec![None; case.rays.len()];
        b8.intersect_batch_incoherent::<Watertight>(&case.rays, &mut batch_hits);
        let mut ordered_hits = vec![None; case.rays.len()];
        let order: Vec<u32> = (0..case.rays.len() as u32).rev().collect();
        wide::intersect_batch_ordered::<Watertight, _, 8>(b8.view(), &case.rays, &order, &mut ordered_hits);
        let mut ordered_occ = vec![false; case.rays.len()];
        b8.occluded_batch_reordered::<Watertight>(&case.rays, &mut ordered_occ);
        assert_eq!(
            ordered_occ, batch_occ,
            "{:?}: occluded_batch_reordered",
            params.strategy
        );
        // The adaptive batches (packets, interleaved closest-hit walks or one ray at a time by
        // group) and the ray streams alone: one call per ray's any-hit answers exactly; closest
        // hits against brute force below, as the packets' (a packet visits nodes in another
        // order, so of two triangles tied at a hit it may report the other one: found by this
        // target, two triangles hit at the same `t` and barycentrics).
        let mut adaptive_hits = vec![None; case.rays.len()];
        b8.intersect_batch::<Watertight>(&case.rays, &mut adaptive_hits);
        let (mut adaptive_occ, mut stream_occ) = (vec![false; case.rays.len()], vec![false; case.rays.len()]);
        b4.occluded_batch::<Watertight>(&case.rays, &mut adaptive_occ);
        wide::occluded_batch_stream::<Watertight, _, 8>(b8.view(), &case.rays, &mut stream_occ);
        for (ray, got) in case.rays.iter().zip(&adaptive_occ) {
            assert_eq!(
                *got,
                b4.occluded::<Watertight>(ray),
                "{:?}: occluded_batch (BVH4) {ray:?}",
                params.strategy
            );
        }
        assert_eq!(stream_occ, batch_occ, "{:?}: occluded_batch_stream", params.strategy);
        for ((ray, got), ord) in case.rays.iter().zip(&batch_hits).zip(&ordered_hits) {
            let single = bits(b8.intersect::<Watertight>(ray));
            assert_eq!(
                bits(*got),
                single,
                "{:?}: intersect_batch_incoherent {ray:?}",
                params.strategy
            );
            assert_eq!(
                bits(*ord),
                single,
                "{:?}: intersect_batch_ordered {ray:?}",
                params.strategy
            );
        }
        // NOTE: the triangle kernels are exact enough for brute-force equality only while no
        // coordinate is huge or tiny: near `f32::MAX` the watertight shear loses every digit, and
        // near the subnormals its edge functions underflow to zero (counted as on the edge), so
        // both report hits just outside the triangle's box, which the exact box test culls (both
        // found by this target). Chaos scenes or rays with a non-zero magnitude outside
        // `TAME_MIN ..= TAME` only have to build, validate and trace without panicking.
        let tame = |v: Vec3| {
            v.to_array()
                .iter()
                .all(|x| *x == 0.0 || (TAME_MIN..=TAME).contains(&x.abs()))
        };
        let scene_tame = case.mode == Mode::Grid
            || b2
                .prim_indices
                .iter()
                .all(|&p| tris[p as usize].iter().all(|&v| tame(v)));
        for (i, ray) in case.rays.iter().enumerate() {
            if !(scene_tame && (case.mode == Mode::Grid || (tame(ray.origin) && tame(ray.direction)))) {
                continue;
            }
            let want = strahl::traverse::intersect_brute_force::<Watertight, _>(&kept[..], ray);
            let what = |s: &str| format!("{:?} {:?} ray {i} {s}", params.strategy, params.refine);
            agrees(
                &kept,
                ray,
                b2.intersect::<Watertight, _>(tris, ray),
                want,
                &what("bvh2"),
            );
            agrees(&kept, ray, b4.intersect::<Watertight>(ray), want, &what("bvh4"));
            agrees(&kept, ray, b8.intersect::<Watertight>(ray), want, &what("bvh8"));
            agrees(&kept, ray, packet_hits[i], want, &what("packet8 hybrid"));
            agrees(&kept, ray, packet_pure[i], want, &what("packet8"));
            agrees(&kept, ray, adaptive_hits[i], want, &what("intersect_batch"));
            let occ = strahl::traverse::occluded_brute_force::<Watertight, _>(&kept[..], ray);
            assert_eq!(
                b2.occluded::<Watertight, _>(tris, ray),
                occ,
                "{}",
                what("bvh2 occluded")
            );
            assert_eq!(b8.occluded::<Watertight>(ray), occ, "{}", what("bvh8 occluded"));
            assert_eq!(packet_occ[i], occ, "{}", what("packet8 occluded"));
            // The fast slab test only misses: a hit it reports is real and never closer than
            // brute force's, an occlusion it reports is real.
            let prepared = PreparedRay::new(ray);
            for (tree, fast) in [
                ("bvh2", b2.intersect::<Fast<Watertight>, _>(tris, ray)),
                ("bvh8", b8.intersect::<Fast<Watertight>>(ray)),
            ] {
                if let Some(h) = fast {
                    let w = want.unwrap_or_else(|| panic!("{}: {h:?}, brute force none", what(tree)));
                    assert!(h.t >= w.t, "{}: fast {h:?} before {w:?}", what(tree));
                    let tri = kept[h.prim as usize];
                    assert_eq!(
                        watertight::intersect_scalar(&prepared, &tri, h.prim),
                        Some(h),
                        "{}",
                        what(tree)
                    );
                }
            }
            assert!(
                !b8.occluded::<Fast<Watertight>>(ray) || occ,
                "{}",
                what("bvh8 fast occluded")
            );
            // A hit filter (even primitives only): the nearest accepted hit, and whether there is one.
            let want_even = strahl::traverse::intersect_brute_force_filtered::<Watertight, _, _>(&kept[..], ray, even);
            agrees(
                &kept,
                ray,
                b2.intersect_filtered::<Watertight, _>(tris, ray, even),
                want_even,
                &what("bvh2 filtered"),
            );
            agrees(
                &kept,
                ray,
                b8.intersect_filtered::<Watertight>(ray, even),
                want_even,
                &what("bvh8 filtered"),
            );
            assert_eq!(
                b8.occluded_filtered::<Watertight>(ray, even),
                want_even.is_some(),
                "{}",
                what("bvh8 filtered occluded")
            );
            agrees(&kept, ray, packet_even[i], want_even, &what("packet8 filtered"));
            assert_eq!(
                packet_even_occ[i],
                want_even.is_some(),
                "{}",
                what("packet8 filtered occluded")
            );
            // `agrees` allows another primitive at a tied `t`: it must pass the filter too.
            for (tree, got) in [
                ("bvh2", b2.intersect_filtered::<Watertight, _>(tris, ray, even)),
                ("bvh8", b8.intersect_filtered::<Watertight>(ray, even)),
                ("packet8", packet_even[i]),
            ] {
                assert!(got.is_none_or(|h| even(&h)), "{}: a rejected hit {got:?}", what(tree));
            }
        }
        if params == builders()[0] {
            check_refit(case, &b2, &b8);
            check_tlas(case, &kept, &b8, scene_tame);
            check_spatial(case, &kept, scene_tame);
        }
    }
}

/// Spatial splits (`Bvh2::build_spatial`, eager knobs: every node searched, no overlap threshold,
/// up to 4 references per triangle, 4 and 16 planes): the build succeeds, `validate_split`
/// passes with the plain build's primitive count (`kept`: the triangles it holds), the reference
/// budget holds; on tame inputs BVH2 and BVH8 give brute force's closest and any hits.
fn check_spatial(case: &BvhCase, kept: &[Triangle], scene_tame: bool) {
    let tris = &case.tris[..];
    for bins in [4, 16] {
        let sp = SpatialSplits {
            alpha: 0.0,
            max_references: 4.0,
            bins,
            min_node_size: 2,
        };
        let params = BuildParams {
            min_leaf_size: 1,
            max_leaf_size: 2,
            ..BuildParams::default()
        };
        let (b2, stats) = Bvh2::build_spatial(tris, &params, &sp).expect("valid knobs");
        let report = b2
            .validate_split(tris)
            .unwrap_or_else(|e| panic!("spatial {bins}: validate_split: {e:?}"));
        let held = kept.iter().filter(|t| !t[0].is_nan()).count();
        assert_eq!(
            (report.primitives as usize, stats.primitives as usize),
            (held, held),
            "spatial {bins}"
        );
        assert!(
            b2.prim_indices.len() <= 4 * held,
            "spatial {bins}: {} references",
            b2.prim_indices.len()
        );
        let b8 = Bvh8::from_bvh2(&b2, tris).expect("a valid tree collapses");
        // A wide leaf holds a triangle once (the collapse drops the repeats of split triangles).
        for code in b8.nodes().iter().flat_map(|n| n.child) {
            if code == strahl::layout::EMPTY_CHILD || code & strahl::layout::LEAF_BIT == 0 {
                continue;
            }
            let (first, count) = strahl::layout::leaf_packs(code);
            let mut prims: Vec<u32> = b8.packs()[first..first + count]
                .iter()
                .flat_map(|p| (0..8).filter(|&i| p.valid >> i & 1 == 1).map(|i| p.prim[i]))
                .collect();
            let all = prims.len();
            prims.sort_unstable();
            prims.dedup();
            assert_eq!(prims.len(), all, "spatial {bins}: a triangle twice in one BVH8 leaf");
        }
        let tame = |v: Vec3| {
            v.to_array()
                .iter()
                .all(|x| *x == 0.0 || (TAME_MIN..=TAME).contains(&x.abs()))
        };
        for (i, ray) in case.rays.iter().enumerate() {
            let _ = (b8.intersect::<Watertight>(ray), b8.occluded::<Watertight>(ray));
            if !(scene_tame && (case.mode == Mode::Grid || (tame(ray.origin) && tame(ray.direction)))) {
                continue;
            }
            let what = format!("spatial {bins} ray {i}");
            let want = strahl::traverse::intersect_brute_force::<Watertight, _>(kept, ray);
            agrees(
                kept,
                ray,
                b2.intersect::<Watertight, _>(tris, ray),
                want,
                &format!("{what} bvh2"),
            );
            agrees(
                kept,
                ray,
                b8.intersect::<Watertight>(ray),
                want,
                &format!("{what} bvh8"),
            );
            let occ = strahl::traverse::occluded_brute_force::<Watertight, _>(kept, ray);
            assert_eq!(b8.occluded::<Watertight>(ray), occ, "{what} bvh8 occluded");
        }
    }
}

/// `Tlas` over three instances of the tree whose transforms are exact in floating point (the
/// identity; axes permuted and scaled by 2; x mirrored and scaled by 1/2), so that the
/// object-space rays are the world rays' exact images, and two bad ones (a NaN translation, a
/// BLAS index out of range): the bad ones left out; every ray traced without panicking, with
/// finite hits; on tame inputs, closest hits equal to the closest of one BVH8 trace per instance
/// (the same `t`, or a tie, or a near tie whose hit is real, as [`agrees`] allows), any hits
/// agreeing with them. The good instances carry masks `0b01`, `0b10` and `0b11`: the masked
/// traversals see only the instances that share a bit with the ray's mask (checked on every ray;
/// on tame inputs against the traces of those instances alone). Packets of the case's rays
/// (`intersect8`, `occluded8`) answer as one call per ray.
fn check_tlas(case: &BvhCase, kept: &[Triangle], b8: &Bvh8, scene_tame: bool) {
    use strahl::glam::{Affine3A, Mat3};
    use strahl::layout::{Instance, Tlas};
    let good = [
        Affine3A::IDENTITY,
        Affine3A::from_mat3(Mat3::from_cols(
            Vec3::new(0.0, 2.0, 0.0),
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(2.0, 0.0, 0.0),
        )),
        Affine3A::from_scale(Vec3::new(-0.5, 0.5, 0.5)),
    ];
    const MASKS: [u32; 3] = [0b01, 0b10, 0b11];
    let mut inst: Vec<Instance> = good
        .iter()
        .zip(MASKS)
        .map(|(&m, k)| Instance::new(m, 0).with_mask(k))
        .collect();
    inst.push(Instance::new(Affine3A::from_translation(Vec3::NAN), 0));
    inst.push(Instance::new(Affine3A::IDENTITY, 1));
    let blases = core::slice::from_ref(b8);
    let tlas = Tlas::build(&inst, blases).expect("five instances build");
    // The good ones are left out too where the tree is empty, or where their world box
    // overflows (a scene reaching near `f32::MAX`); never on a tame scene.
    let left_out = tlas.left_out() as usize;
    if b8.is_empty() {
        assert_eq!(left_out, 5, "tlas left_out");
    } else if scene_tame {
        assert_eq!(left_out, 2, "tlas left_out");
    } else {
        assert!(left_out >= 2, "tlas left_out {left_out}");
    }
    let local = |m: &Affine3A, ray: &Ray| {
        let inv = m.inverse();
        Ray {
            origin: inv.transform_point3(ray.origin),
            tmin: ray.tmin,
            direction: inv.transform_vector3(ray.direction),
            tmax: ray.tmax,
        }
    };
    // Whether a ray's `t` is compared across walks (up to a near tie): a tame scene, and a grid
    // input or a ray of tame magnitudes (with room for the instances' scale of 2).
    let comparable = |ray: &Ray| {
        let tame = |v: Vec3| {
            v.to_array()
                .iter()
                .all(|x| *x == 0.0 || (TAME_MIN..=TAME * 0.25).contains(&x.abs()))
        };
        scene_tame && (case.mode == Mode::Grid || (tame(ray.origin) && tame(ray.direction)))
    };
    // Packets of 8 (the case's rays in order; `intersect8`, `occluded8` and their masked forms):
    // any hits as one call per ray; closest hits whenever one call per ray finds one, with its
    // `t` up to a near tie (the packet visits instances in another order, and a closer hit
    // known earlier can cull one within rounding of it, see `check_tlas`' masked check), where
    // the ray is `comparable`.
    for (c, chunk) in case.rays.chunks(8).enumerate() {
        for ray_mask in [u32::MAX, 0b01] {
            let (mut hits, mut occ) = ([None; 8], [false; 8]);
            tlas.intersect8_masked::<Watertight, _, 8>(blases, chunk, ray_mask, &mut hits);
            tlas.occluded8_masked::<Watertight, _, 8>(blases, chunk, ray_mask, &mut occ);
            for (l, ray) in chunk.iter().enumerate() {
                let one = tlas.intersect_masked::<Watertight, _, 8>(blases, ray, ray_mask);
                let what = format!("tlas packet {c} lane {l} mask {ray_mask:#b}");
                assert_eq!(
                    occ[l],
                    tlas.occluded_masked::<Watertight, _, 8>(blases, ray, ray_mask),
                    "{what}: occluded"
                );
                match (hits[l], one) {
                    (None, None) => {}
                    (Some(p), Some(o)) => {
                        assert!(
                            p.hit.t == o.hit.t
                                || near_tie(ray, p.hit, o.hit)
                                || near_tie(ray, o.hit, p.hit)
                                || !comparable(ray),
                            "{what}: {p:?} against {o:?}"
                        );
                        assert!(
                            p.instance < 3 && MASKS[p.instance as usize] & ray_mask != 0,
                            "{what}: {p:?} hidden"
                        );
                    }
                    (p, o) => panic!("{what}: {p:?} against {o:?}"),
                }
            }
        }
    }
    for (i, ray) in case.rays.iter().enumerate() {
        let got = tlas.intersect::<Watertight, _, 8>(blases, ray);
        let occ = tlas.occluded::<Watertight, _, 8>(blases, ray);
        if let Some(g) = got {
            assert!(
                g.hit.t.is_finite() && g.hit.u.is_finite() && g.hit.v.is_finite(),
                "tlas ray {i}: {g:?}"
            );
            assert!(g.instance < 3, "tlas ray {i}: a bad instance hit: {g:?}");
        }
        let compare = comparable(ray);
        for ray_mask in [0b01, 0b10] {
            let m = tlas.intersect_masked::<Watertight, _, 8>(blases, ray, ray_mask);
            if let Some(h) = m {
                assert!(
                    h.instance < 3 && MASKS[h.instance as usize] & ray_mask != 0,
                    "tlas ray {i}: {h:?} hidden"
                );
                // Never before the unmasked hit, up to a near tie: the box tests cull by rounded
                // entry distances, so once a closer hit is known a hit within rounding of it may
                // be culled (found by this target, seed `crash-masked-denormal-tie`: hits at
                // `t` = -0 and 1e-45 in two instances, the unmasked walk finding the later one
                // first; see `TriangleTest::CONSERVATIVE_BOXES`). Only where the scene and the
                // ray are tame: beyond, `t` itself may be off by more than that (seed
                // `crash-masked-underflow-t`: a triangle of subnormal coordinates, a direction
                // of 1e20, a hit one unit along the ray reported at `t` = 0 as its quotient
                // underflows, the unmasked walk's hit at 1e-20 in another instance culling it).
                assert!(
                    got.is_some_and(|g| !compare || g.hit.t <= h.hit.t || near_tie(ray, g.hit, h.hit)),
                    "tlas ray {i}: masked {h:?} before {got:?} ray {ray:?}"
                );
            }
            assert_eq!(
                tlas.occluded_masked::<Watertight, _, 8>(blases, ray, ray_mask),
                m.is_some(),
                "tlas ray {i}: masked occluded"
            );
        }
        assert_eq!(
            tlas.intersect_masked::<Watertight, _, 8>(blases, ray, u32::MAX),
            got,
            "tlas ray {i}: all ones"
        );
        if !compare {
            continue;
        }
        // One trace per instance; the smallest t (ties: the first instance).
        let want = good
            .iter()
            .enumerate()
            .filter_map(|(k, m)| b8.intersect::<Watertight>(&local(m, ray)).map(|h| (k, h)))
            .fold(None::<(usize, Hit)>, |b, (k, h)| match b {
                Some((_, bh)) if bh.t <= h.t => b,
                _ => Some((k, h)),
            });
        assert_eq!(occ, want.is_some(), "tlas ray {i}: occluded {occ}, traces {want:?}");
        match (got, want) {
            (None, None) => {}
            (Some(g), Some((k, w))) => {
                if (g.instance as usize, g.hit.prim) == (k, w.prim) {
                    assert_eq!(g.hit.t.to_bits(), w.t.to_bits(), "tlas ray {i}: {g:?} against {w:?}");
                } else {
                    // A tie or a near tie: the hit must be real in its instance.
                    assert!(
                        g.hit.t == w.t || near_tie(ray, g.hit, w),
                        "tlas ray {i}: {g:?} against {k} {w:?}"
                    );
                    let lr = local(&good[g.instance as usize], ray);
                    let alone = kept
                        .get(g.hit.prim as usize)
                        .and_then(|t| watertight::intersect_scalar(&PreparedRay::new(&lr), t, g.hit.prim));
                    assert_eq!(alone, Some(g.hit), "tlas ray {i}: not a hit of its instance");
                }
            }
            _ => panic!("tlas ray {i}: {got:?} against {want:?}"),
        }
        // Masked: the closest of the visible instances' traces (the same t; the instance may
        // differ on a tie).
        for ray_mask in [0b01, 0b10] {
            let want = good
                .iter()
                .enumerate()
                .filter(|&(k, _)| MASKS[k] & ray_mask != 0)
                .filter_map(|(k, m)| b8.intersect::<Watertight>(&local(m, ray)).map(|h| (k, h)))
                .fold(None::<(usize, Hit)>, |b, (k, h)| match b {
                    Some((_, bh)) if bh.t <= h.t => b,
                    _ => Some((k, h)),
                });
            let got = tlas.intersect_masked::<Watertight, _, 8>(blases, ray, ray_mask);
            match (got, want) {
                (None, None) => {}
                (Some(g), Some((_, w))) => assert!(
                    g.hit.t == w.t || near_tie(ray, g.hit, w),
                    "tlas ray {i} mask {ray_mask}: {g:?} against {w:?}"
                ),
                _ => panic!("tlas ray {i} mask {ray_mask}: {got:?} against {want:?}"),
            }
        }
    }
    // `Tlas::refit` to the good transforms rotated among the first three instances (each one
    // moves): answers as a fresh build over the moved instances (closest hits up to a near tie,
    // the trees differing, where the ray is `comparable`), where both leave out the same instances (on a scene near `f32::MAX`
    // an instance the build left out stays out); then refitted back: the very answers of the
    // first build.
    let mut moved = inst.clone();
    for (k, x) in moved.iter_mut().take(3).enumerate() {
        x.transform = good[(k + 1) % 3];
    }
    let fresh = Tlas::build(&moved, blases).expect("five instances build");
    let mut re = tlas.clone();
    assert!(re.refit(&moved, blases), "tlas refit");
    assert!(re.left_out() >= fresh.left_out(), "tlas refit left_out");
    if scene_tame {
        assert_eq!(re.left_out(), fresh.left_out(), "tlas refit left_out");
    }
    if re.left_out() == fresh.left_out() {
        for (i, ray) in case.rays.iter().enumerate() {
            assert_eq!(
                re.occluded::<Watertight, _, 8>(blases, ray),
                fresh.occluded::<Watertight, _, 8>(blases, ray),
                "tlas refit ray {i}: occluded"
            );
            match (
                re.intersect::<Watertight, _, 8>(blases, ray),
                fresh.intersect::<Watertight, _, 8>(blases, ray),
            ) {
                (None, None) => {}
                (Some(r), Some(f)) => assert!(
                    r.hit.t == f.hit.t
                        || near_tie(ray, r.hit, f.hit)
                        || near_tie(ray, f.hit, r.hit)
                        || !comparable(ray),
                    "tlas refit ray {i}: {r:?} against {f:?}"
                ),
                (r, f) => panic!("tlas refit ray {i}: {r:?} against {f:?}"),
            }
        }
    }
    assert!(re.refit(&inst, blases), "tlas refit back");
    assert_eq!(re.left_out(), tlas.left_out(), "tlas refit back left_out");
    for (i, ray) in case.rays.iter().enumerate() {
        assert_eq!(
            re.intersect::<Watertight, _, 8>(blases, ray),
            tlas.intersect::<Watertight, _, 8>(blases, ray),
            "tlas refit back ray {i}"
        );
        assert_eq!(
            re.occluded::<Watertight, _, 8>(blases, ray),
            tlas.occluded::<Watertight, _, 8>(blases, ray),
            "tlas refit back ray {i}: occluded"
        );
    }
}

/// `Bvh8::refit` to the scene's triangles shifted by one slot (triangle `i` takes triangle
/// `i + 1`'s place: any motion, non-finite triangles moving into the tree and out of it) and
/// back: the count of triangles left out, closest and any hits against brute force over the
/// moved triangles the tree holds (where the moved scene is tame), and the very tree of the
/// start after moving back.
fn check_refit(case: &BvhCase, b2: &Bvh2, b8: &Bvh8) {
    let tris = &case.tris[..];
    if tris.is_empty() {
        return;
    }
    let moved: Vec<Triangle> = (0..tris.len()).map(|i| tris[(i + 1) % tris.len()]).collect();
    // The builders' rule, which the refit follows: finite vertices, and the box's extent and
    // `min + max` finite (no coordinate beyond about +-1.7e38).
    let finite = |t: &Triangle| {
        let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
        t.iter().all(|v| v.is_finite()) && (hi - lo).is_finite() && (hi + lo).is_finite()
    };
    let mut kept_moved: Vec<Triangle> = vec![[Vec3::NAN; 3]; tris.len()];
    let mut want_out = 0;
    for &p in &b2.prim_indices {
        let t = moved[p as usize];
        if finite(&t) {
            kept_moved[p as usize] = t;
        } else {
            want_out += 1;
        }
    }
    let mut r8 = b8.clone();
    assert_eq!(r8.refit(&moved[..]), want_out, "refit: triangles left out");
    let tame = |v: Vec3| {
        v.to_array()
            .iter()
            .all(|x| *x == 0.0 || (TAME_MIN..=TAME).contains(&x.abs()))
    };
    let scene_tame = case.mode == Mode::Grid
        || kept_moved
            .iter()
            .filter(|t| finite(t))
            .all(|t| t.iter().all(|&v| tame(v)));
    for (i, ray) in case.rays.iter().enumerate() {
        if !(scene_tame && (case.mode == Mode::Grid || (tame(ray.origin) && tame(ray.direction)))) {
            continue;
        }
        let want = strahl::traverse::intersect_brute_force::<Watertight, _>(&kept_moved[..], ray);
        agrees(
            &kept_moved,
            ray,
            r8.intersect::<Watertight>(ray),
            want,
            &format!("refit ray {i}"),
        );
        let occ = strahl::traverse::occluded_brute_force::<Watertight, _>(&kept_moved[..], ray);
        assert_eq!(r8.occluded::<Watertight>(ray), occ, "refit ray {i} occluded");
    }
    // Back to the start: the tree of the collapse again, answer for answer.
    assert_eq!(r8.refit(tris), 0, "refit back: every triangle of the tree is valid");
    for ray in &case.rays {
        let (a, b) = (r8.intersect::<Watertight>(ray), b8.intersect::<Watertight>(ray));
        assert_eq!(
            a.map(|h| (h.t.to_bits(), h.prim)),
            b.map(|h| (h.t.to_bits(), h.prim)),
            "refit back"
        );
    }
}
