//! Property tests of the Morton code stage (`strahl::geometry::morton`): the bit interleaving
//! round-trips, the 8-lane kernels equal the scalar references lane by lane, codes preserve order
//! along each axis, and the slice functions handle every remainder length.

mod common;

use common::{bounded, grid, raw, vec3};
use proptest::prelude::*;
use strahl::geometry::morton::*;
use strahl::math::f32x8;
use strahl::{Aabb, Vec3};

/// Bounds from two corners, sorted per axis (a proper box, possibly flat on some axes).
fn sorted_box<S: Strategy<Value = f32> + Clone>(s: S) -> impl Strategy<Value = Aabb> {
    (vec3(s.clone()), vec3(s)).prop_map(|(a, b)| Aabb::new(a.min(b), a.max(b)))
}

/// Bounds of any kind: sorted boxes, raw corners in any order (NaN, inf, inverted), the empty box.
fn any_box() -> impl Strategy<Value = Aabb> {
    prop_oneof![
        sorted_box(bounded()),
        sorted_box(grid()),
        (vec3(raw()), vec3(raw())).prop_map(|(a, b)| Aabb::new(a, b)),
        Just(Aabb::EMPTY),
    ]
}

/// Eight points, one per lane.
fn points8<S: Strategy<Value = f32> + Clone>(s: S) -> impl Strategy<Value = [Vec3; 8]> {
    proptest::array::uniform8(vec3(s))
}

fn lanes(p: &[Vec3; 8]) -> (f32x8, f32x8, f32x8) {
    (
        f32x8::new(p.map(|v| v.x)),
        f32x8::new(p.map(|v| v.y)),
        f32x8::new(p.map(|v| v.z)),
    )
}

/// `morton30_x8` and `morton63_x8` equal their scalar references exactly, lane by lane.
fn check_x8(p: &[Vec3; 8], b: &Aabb) -> Result<(), TestCaseError> {
    let (q30, q63) = (MortonQuantizer::new30(b), MortonQuantizer::new63(b));
    let (x, y, z) = lanes(p);
    let c30 = morton30_x8(x, y, z, &q30).to_array();
    let c63 = morton63_x8(x, y, z, &q63);
    let [cx, cy, cz] = q63.quantize_x8(x, y, z);
    for i in 0..8 {
        prop_assert_eq!(
            c30[i],
            morton30_scalar(p[i], &q30),
            "lane {} of {:?} in {:?}",
            i,
            p[i],
            b
        );
        prop_assert_eq!(
            c63[i],
            morton63_scalar(p[i], &q63),
            "lane {} of {:?} in {:?}",
            i,
            p[i],
            b
        );
        let cell = [cx.to_array()[i], cy.to_array()[i], cz.to_array()[i]];
        prop_assert_eq!(cell, q63.quantize_scalar(p[i]));
        // 30-bit codes from the 63-bit quantizer: the x8 kernel equals the scalar, and both are
        // the code of the cells' top 10 bits.
        let c30_of_63 = morton30_x8(x, y, z, &q63).to_array();
        prop_assert_eq!(c30_of_63[i], morton30_scalar(p[i], &q63));
        prop_assert_eq!(c30_of_63[i], encode30(cell.map(|c| c >> 11)));
    }
    Ok(())
}

/// Codes never decrease when one coordinate grows and the others stay put.
fn check_order(p: Vec3, axis: usize, a: f32, b: f32, bounds: &Aabb) -> Result<(), TestCaseError> {
    let (lo, hi) = if a < b {
        (a, b)
    } else if b < a {
        (b, a)
    } else {
        return Ok(()); // equal or unordered (NaN): nothing to compare
    };
    let (mut p0, mut p1) = (p, p);
    p0[axis] = lo;
    p1[axis] = hi;
    for q in [MortonQuantizer::new30(bounds), MortonQuantizer::new63(bounds)] {
        let (c0, c1) = (q.quantize_scalar(p0), q.quantize_scalar(p1));
        prop_assert!(c0[axis] <= c1[axis], "{:?} {:?} -> {:?} {:?}", p0, p1, c0, c1);
        for k in 0..3 {
            if k != axis {
                prop_assert_eq!(c0[k], c1[k]);
            }
        }
    }
    let (q30, q63) = (MortonQuantizer::new30(bounds), MortonQuantizer::new63(bounds));
    prop_assert!(morton30_scalar(p0, &q30) <= morton30_scalar(p1, &q30));
    prop_assert!(morton63_scalar(p0, &q63) <= morton63_scalar(p1, &q63));
    // 30-bit codes of the 63-bit quantizer keep the order too.
    prop_assert!(morton30_scalar(p0, &q63) <= morton30_scalar(p1, &q63));
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn roundtrip30(c in proptest::array::uniform3(0u32..1024)) {
        prop_assert_eq!(decode30(encode30(c)), c);
    }

    #[test]
    fn roundtrip63(c in proptest::array::uniform3(0u32..(1 << 21))) {
        prop_assert_eq!(decode63(encode63(c)), c);
    }

    #[test]
    fn encode_masks_high_bits(c in proptest::array::uniform3(any::<u32>())) {
        prop_assert_eq!(decode30(encode30(c)), c.map(|v| v & 1023));
        prop_assert_eq!(decode63(encode63(c)), c.map(|v| v & ((1 << 21) - 1)));
        prop_assert!(encode30(c) <= MORTON30_MAX);
        prop_assert!(encode63(c) <= MORTON63_MAX);
    }

    #[test]
    fn decode_roundtrip_of_any_code(c30 in any::<u32>(), c63 in any::<u64>()) {
        prop_assert_eq!(encode30(decode30(c30)), c30 & MORTON30_MAX);
        prop_assert_eq!(encode63(decode63(c63)), c63 & MORTON63_MAX);
    }

    #[test]
    fn x8_equals_scalar_bounded(p in points8(bounded()), b in sorted_box(bounded())) {
        check_x8(&p, &b)?;
    }

    #[test]
    fn x8_equals_scalar_raw(p in points8(raw()), b in any_box()) {
        check_x8(&p, &b)?;
    }

    #[test]
    fn x8_equals_scalar_grid(p in points8(grid()), b in sorted_box(grid())) {
        check_x8(&p, &b)?;
    }

    #[test]
    fn order_preserved_bounded(
        p in vec3(bounded()), axis in 0usize..3, a in bounded(), b in bounded(), bounds in sorted_box(bounded()),
    ) {
        check_order(p, axis, a, b, &bounds)?;
    }

    #[test]
    fn order_preserved_raw(p in vec3(raw()), axis in 0usize..3, a in raw(), b in raw(), bounds in any_box()) {
        check_order(p, axis, a, b, &bounds)?;
    }

    #[test]
    fn order_preserved_grid(
        p in vec3(grid()), axis in 0usize..3, a in grid(), b in grid(), bounds in sorted_box(grid()),
    ) {
        check_order(p, axis, a, b, &bounds)?;
    }

    #[test]
    fn decode_equals_quantize(p in vec3(raw()), b in any_box()) {
        let (q30, q63) = (MortonQuantizer::new30(&b), MortonQuantizer::new63(&b));
        prop_assert_eq!(decode30(morton30_scalar(p, &q30)), q30.quantize_scalar(p));
        prop_assert_eq!(decode63(morton63_scalar(p, &q63)), q63.quantize_scalar(p));
        for c in q30.quantize_scalar(p) {
            prop_assert!(c < 1 << 10);
        }
        for c in q63.quantize_scalar(p) {
            prop_assert!(c < 1 << 21);
        }
    }

    #[test]
    fn corners_map_to_first_and_last_cell(b in sorted_box(bounded())) {
        // The min corner is cell 0; the max corner is the last cell on every axis that is not flat.
        let q = MortonQuantizer::new30(&b);
        prop_assert_eq!(morton30_scalar(b.min, &q), 0);
        let c = q.quantize_scalar(b.max);
        let e = b.extent();
        for k in 0..3 {
            prop_assert_eq!(c[k], if e[k] > 0.0 && (1024.0 / e[k]).is_finite() { 1023 } else { 0 });
        }
        let q = MortonQuantizer::new63(&b);
        prop_assert_eq!(morton63_scalar(b.min, &q), 0);
        if e.min_element() > 0.0 {
            prop_assert_eq!(morton63_scalar(b.max, &q), MORTON63_MAX);
        }
    }

    #[test]
    fn extended_cells_are_near_cubic_and_monotone(
        b in sorted_box(bounded()), p in vec3(raw()), axis in 0usize..3, a in bounded(), c in bounded(),
    ) {
        // Every axis's cell length, `1 / scale`, is within a factor sqrt(2) of the longest
        // extent's `E / 1024` (or the axis is flat, or as long as 1024 halvings allow), and the
        // x8 kernel agrees with the scalar reference.
        for bits in [10u32, 21] {
            let (qe, qn) = (MortonQuantizer::new_extended(&b, bits), MortonQuantizer::new(&b, bits));
            let (e, se, sn) = (b.extent(), qe.scale(), qn.scale());
            let longest = e.max_element();
            for k in 0..3 {
                if sn[k] == 0.0 {
                    prop_assert_eq!(se[k], 0.0);
                    continue;
                }
                // A whole number of halvings: the extended scale is the plain one over 2^d.
                let d = (sn[k] / se[k]).log2();
                prop_assert!(d == d.round() && (0.0..=bits as f32).contains(&d), "{} {}", sn[k], se[k]);
                if longest.is_finite() && d < bits as f32 {
                    // `2^d e` is within sqrt(2) of the longest extent.
                    let r = (e[k] * d.exp2()) / longest;
                    prop_assert!(r >= 0.5f32.sqrt() * 0.999 && r <= 2f32.sqrt() * 1.001, "ratio {r}");
                }
            }
            // Cells in range and monotone; the x8 kernel equals the scalar reference.
            let cells = qe.quantize_scalar(p);
            prop_assert!(cells.iter().all(|&x| x < 1 << bits));
            let (lo, hi) = if a <= c { (a, c) } else { (c, a) };
            let (mut p0, mut p1) = (p, p);
            p0[axis] = lo;
            p1[axis] = hi;
            prop_assert!(qe.quantize_scalar(p0)[axis] <= qe.quantize_scalar(p1)[axis]);
            let l = |v: f32| f32x8::splat(v);
            let [x8, y8, z8] = qe.quantize_x8(l(p.x), l(p.y), l(p.z));
            prop_assert_eq!([x8.to_array()[0], y8.to_array()[0], z8.to_array()[0]], cells);
        }
    }

    #[test]
    fn extended_survives_any_bounds(p in vec3(raw()), b in any_box()) {
        // NaN, infinite, inverted and empty bounds: finite non-negative scales, cells in range,
        // flat axes where `new` has them, and the x8 kernel equal to the scalar reference.
        for bits in [10u32, 21] {
            let (qe, qn) = (MortonQuantizer::new_extended(&b, bits), MortonQuantizer::new(&b, bits));
            for k in 0..3 {
                let s = qe.scale()[k];
                prop_assert!(s.is_finite() && s >= 0.0 && s <= qn.scale()[k]);
                prop_assert_eq!(s == 0.0, qn.scale()[k] == 0.0);
            }
            let cells = qe.quantize_scalar(p);
            prop_assert!(cells.iter().all(|&x| x < 1 << bits));
            let l = |v: f32| f32x8::splat(v);
            let [x8, y8, z8] = qe.quantize_x8(l(p.x), l(p.y), l(p.z));
            prop_assert_eq!([x8.to_array()[0], y8.to_array()[0], z8.to_array()[0]], cells);
        }
    }

    #[test]
    fn extended_equals_plain_on_near_cubic_boxes(
        min in vec3(bounded()), size in 1.0e-3f32..1.0e3, f in vec3(1.0f32..1.41),
    ) {
        // Extents within a factor 1.41 < sqrt(2) of each other: no axis is shortened.
        let b = Aabb::new(min, min + f * size);
        // (Rounding may stretch the extents of a small box far from the origin.)
        let e = b.extent();
        prop_assume!(e.min_element() > 0.0 && e.max_element() < e.min_element() * 1.414);
        prop_assert_eq!(MortonQuantizer::new_extended(&b, 10), MortonQuantizer::new30(&b));
        prop_assert_eq!(MortonQuantizer::new_extended(&b, 21), MortonQuantizer::new63(&b));
    }

    #[test]
    fn slices_equal_scalar(
        pts in proptest::collection::vec(vec3(raw()), 0..40),
        short in 0usize..40,
        b in any_box(),
    ) {
        let (q30, q63) = (MortonQuantizer::new30(&b), MortonQuantizer::new63(&b));
        let n = pts.len();
        let (xs, ys, zs): (Vec<f32>, Vec<f32>, Vec<f32>) =
            (pts.iter().map(|p| p.x).collect(), pts.iter().map(|p| p.y).collect(), pts.iter().map(|p| p.z).collect());
        // `out` as long as the input (plus slack that must stay untouched), then shorter.
        for m in [n, short.min(n)] {
            let (mut a30, mut s30) = (vec![u32::MAX; n + 3], vec![u32::MAX; n + 3]);
            let (mut a63, mut s63) = (vec![u64::MAX; n + 3], vec![u64::MAX; n + 3]);
            let written = if m == n { n + 3 } else { m };
            morton30_slice(&pts, &q30, &mut a30[..written]);
            morton63_slice(&pts, &q63, &mut a63[..written]);
            morton30_slice_soa(&xs, &ys, &zs, &q30, &mut s30[..written]);
            morton63_slice_soa(&xs, &ys, &zs, &q63, &mut s63[..written]);
            for i in 0..n + 3 {
                let (e30, e63) = if i < m {
                    (morton30_scalar(pts[i], &q30), morton63_scalar(pts[i], &q63))
                } else {
                    (u32::MAX, u64::MAX)
                };
                prop_assert_eq!(a30[i], e30, "aos30 i {} n {} m {}", i, n, m);
                prop_assert_eq!(a63[i], e63, "aos63 i {} n {} m {}", i, n, m);
                prop_assert_eq!(s30[i], e30, "soa30 i {} n {} m {}", i, n, m);
                prop_assert_eq!(s63[i], e63, "soa63 i {} n {} m {}", i, n, m);
            }
        }
    }

    #[test]
    fn soa_takes_the_shortest_slice(
        pts in proptest::collection::vec(vec3(bounded()), 0..40),
        cut in proptest::array::uniform3(0usize..40),
    ) {
        let b = Aabb::from_points(&pts);
        let q = MortonQuantizer::new30(&b);
        let n = pts.len();
        let [cx, cy, cz] = cut.map(|c| c.min(n));
        let xs: Vec<f32> = pts[..cx].iter().map(|p| p.x).collect();
        let ys: Vec<f32> = pts[..cy].iter().map(|p| p.y).collect();
        let zs: Vec<f32> = pts[..cz].iter().map(|p| p.z).collect();
        let mut out = vec![u32::MAX; n];
        morton30_slice_soa(&xs, &ys, &zs, &q, &mut out);
        let m = cx.min(cy).min(cz);
        for (i, &c) in out.iter().enumerate() {
            prop_assert_eq!(c, if i < m { morton30_scalar(pts[i], &q) } else { u32::MAX });
        }
    }
}
