//! Wide BVHs saved as bytes and read again (`layout::bytes`): the same tree, answer for answer
//! and byte for byte, copied or traced in place; and every damaged, cut, padded or malformed
//! input answered with an error, never a panic.

mod common;

use common::{mixed_rays, random_soup};
use proptest::prelude::*;
use strahl::build::{BuildParams, Bvh2, SpatialSplits};
use strahl::geometry::{Hit, Triangle};
use strahl::intersect::TriangleLanes;
use strahl::layout::{
    Bvh4, Bvh8, Bvh8Ref, BvhWide, BvhWideRef, EMPTY_CHILD, FormatError, HEADER_BYTES, LEAF_BIT, MAX_WIDE_DEPTH, Node8,
    WideNode,
};
use strahl::math::{Lane, f32x8};
use strahl::scene;
use strahl::traverse::{Watertight, wide};
use strahl::{Aabb, Ray, Vec3};

/// 64-byte blocks: an aligned buffer for in-place reading.
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(64))]
struct Block([u8; 64]);

/// `bytes` copied into a 64-byte-aligned buffer (and the buffer, which must outlive the view).
fn aligned(bytes: &[u8]) -> Vec<Block> {
    let mut blocks = vec![Block([0; 64]); bytes.len() / 64 + 1];
    bytemuck::cast_slice_mut::<Block, u8>(&mut blocks)[..bytes.len()].copy_from_slice(bytes);
    blocks
}

fn bits(h: Option<Hit>) -> Option<(u32, u32, u32, u32)> {
    h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim))
}

/// Every ray answers bit for bit the same through `a` and `b`.
fn same_answers<L: Lane, const N: usize>(a: BvhWideRef<L, N>, b: BvhWideRef<L, N>, rays: &[Ray], what: &str) {
    for ray in rays {
        assert_eq!(
            bits(wide::intersect::<Watertight, L, N>(a, ray)),
            bits(wide::intersect::<Watertight, L, N>(b, ray)),
            "{what}: {ray:?}"
        );
        assert_eq!(
            wide::occluded::<Watertight, L, N>(a, ray),
            wide::occluded::<Watertight, L, N>(b, ray),
            "{what}: {ray:?}"
        );
    }
}

fn round_trip<L: Lane + bytemuck::Pod, const N: usize>(tree: &BvhWide<L, N>, rays: &[Ray], what: &str)
where
    WideNode<L, N>: bytemuck::AnyBitPattern,
    TriangleLanes<L, N>: bytemuck::AnyBitPattern,
{
    let bytes = tree.to_bytes();
    assert_eq!(bytes.len(), HEADER_BYTES + tree.memory_bytes(), "{what}");
    let loaded = BvhWide::<L, N>::from_bytes(&bytes).unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_eq!(loaded.depth(), tree.depth(), "{what}");
    assert_eq!(loaded.to_bytes(), bytes, "{what}: written again");
    same_answers(loaded.view(), tree.view(), rays, what);
    // In place: the same nodes and packs, byte for byte as in memory (little-endian machines).
    let buf = aligned(&bytes);
    let raw = &bytemuck::cast_slice::<Block, u8>(&buf)[..bytes.len()];
    let view = BvhWideRef::<L, N>::from_bytes(raw).unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_eq!(view.check(), Ok(tree.depth()), "{what}");
    assert_eq!(
        (view.nodes.len(), view.packs.len()),
        (tree.nodes().len(), tree.packs().len())
    );
    same_answers(view, tree.view(), rays, what);
    // Misaligned by 4 bytes: refused, not misread.
    let mut shifted = aligned(&[&[0u8; 4], &bytes[..]].concat());
    let raw = &bytemuck::cast_slice_mut::<Block, u8>(&mut shifted)[4..4 + bytes.len()];
    assert_eq!(
        BvhWideRef::<L, N>::from_bytes(raw).err(),
        Some(FormatError::Misaligned),
        "{what}"
    );
}

fn scenes() -> Vec<(&'static str, Vec<Triangle>)> {
    vec![
        ("bunny", scene::bunny().to_soup()),
        ("soup", random_soup(3000, 5)),
        ("sphereflake", scene::sphereflake(2, 3).to_soup()),
        ("one triangle", vec![[Vec3::ZERO, Vec3::X, Vec3::Y]]),
        ("empty", Vec::new()),
        ("all invalid", vec![[Vec3::NAN, Vec3::X, Vec3::Y]; 3]),
    ]
}

#[test]
fn saved_trees_load_as_the_same_tree() {
    for (name, tris) in scenes() {
        let rays = if tris.is_empty() {
            vec![Ray::new(Vec3::ZERO, Vec3::Z)]
        } else {
            mixed_rays(&tris, 300, 3)
        };
        // Spatial splits too: leaf boxes clip their triangles (not checked), nodes still nest.
        let trees = [
            ("fastest", Bvh2::build(&tris[..], &BuildParams::fastest()).unwrap().0),
            ("balanced", Bvh2::build(&tris[..], &BuildParams::balanced()).unwrap().0),
            (
                "spatial",
                Bvh2::build_spatial(&tris[..], &BuildParams::balanced(), &SpatialSplits::default())
                    .unwrap()
                    .0,
            ),
        ];
        // Refitted to moved triangles, every seventh collapsed to a point (left out).
        let moved: Vec<Triangle> = tris
            .iter()
            .enumerate()
            .map(|(i, t)| {
                if i % 7 == 0 {
                    [t[0]; 3]
                } else {
                    t.map(|v| v * 1.1 + Vec3::X)
                }
            })
            .collect();
        for (pname, b2) in &trees {
            let what = |kind: &str| format!("{name} / {pname} / {kind}");
            round_trip(&Bvh4::from_bvh2(b2, &tris[..]).unwrap(), &rays, &what("BVH4"));
            let b8 = Bvh8::from_bvh2(b2, &tris[..]).unwrap();
            round_trip(&b8, &rays, &what("BVH8"));
            round_trip(
                &Bvh8::from_bvh2_greedy(b2, &tris[..]).unwrap(),
                &rays,
                &what("BVH8 greedy"),
            );
            let mut refitted = b8;
            refitted.refit(&moved[..]);
            round_trip(&refitted, &rays, &what("BVH8 refitted"));
        }
    }
}

fn bunny8() -> (Vec<Triangle>, Bvh8) {
    let tris = scene::bunny().to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    (tris, b8)
}

/// The header's fields each answer with their own error; widths and lane types do not mix.
#[test]
fn headers_are_checked_field_by_field() {
    let (_, b8) = bunny8();
    let bytes = b8.to_bytes();
    let with = |at: usize, v: u32| {
        let mut b = bytes.clone();
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        b
    };
    assert_eq!(Bvh8::from_bytes(&with(0, 0)).unwrap_err(), FormatError::Magic);
    assert_eq!(Bvh8::from_bytes(&with(8, 2)).unwrap_err(), FormatError::Version(2));
    for at in [12, 16, 20, 24, 28, 56] {
        assert_eq!(
            Bvh8::from_bytes(&with(at, 7)).unwrap_err(),
            FormatError::Shape,
            "field at {at}"
        );
    }
    // More nodes than the bytes hold; a count whose byte size overflows.
    let more = b8.nodes().len() as u32 + 1;
    assert!(matches!(
        Bvh8::from_bytes(&with(32, more)),
        Err(FormatError::Length { found, .. }) if found == bytes.len() as u64
    ));
    let huge = with(36, u32::MAX);
    assert_eq!(
        Bvh8::from_bytes(&huge).unwrap_err(),
        FormatError::Length {
            expected: u64::MAX,
            found: bytes.len() as u64
        }
    );
    // The checksum field itself.
    assert_eq!(Bvh8::from_bytes(&with(48, 12345)).unwrap_err(), FormatError::Checksum);
    // Counts traded at the same length (11 nodes of 256 bytes for 8 packs of 352): the checksum
    // covers the header's counts, so the in-place read refuses it too.
    let (nodes, packs) = (b8.nodes().len() as u32, b8.packs().len() as u32);
    let traded = {
        let mut b = with(32, nodes - 11);
        b[40..44].copy_from_slice(&(packs + 8).to_le_bytes());
        b
    };
    assert_eq!(Bvh8::from_bytes(&traded).unwrap_err(), FormatError::Checksum);
    let buf = aligned(&traded);
    assert_eq!(
        Bvh8Ref::from_bytes(&bytemuck::cast_slice::<Block, u8>(&buf)[..traded.len()]).unwrap_err(),
        FormatError::Checksum
    );
    // An 8-wide tree is not a 4-wide one (and the other way round; lanes that do not match the
    // width, such as `BvhWide<f32x4, 8>`, do not compile).
    assert_eq!(Bvh4::from_bytes(&bytes).unwrap_err(), FormatError::Shape);
    let tris = scene::icosphere(2).to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap().to_bytes();
    assert_eq!(Bvh8::from_bytes(&b4).unwrap_err(), FormatError::Shape);
}

/// Every prefix, a trailing byte and a flipped bit anywhere: errors, and for a flip in the
/// payload always the checksum's.
#[test]
fn cut_padded_or_damaged_bytes_are_refused() {
    let tris = scene::icosphere(2).to_soup();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    let bytes = b8.to_bytes();
    for n in 0..bytes.len() {
        let e = Bvh8::from_bytes(&bytes[..n]).unwrap_err();
        assert!(matches!(e, FormatError::Length { .. }), "{n}: {e:?}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(Bvh8::from_bytes(&longer), Err(FormatError::Length { .. })));
    for at in 0..bytes.len() {
        for bit in [0, 3, 7] {
            let mut b = bytes.clone();
            b[at] ^= 1 << bit;
            let e = Bvh8::from_bytes(&b).unwrap_err();
            if at >= HEADER_BYTES {
                assert_eq!(e, FormatError::Checksum, "byte {at} bit {bit}");
            }
            let buf = aligned(&b);
            assert!(Bvh8Ref::from_bytes(&bytemuck::cast_slice::<Block, u8>(&buf)[..b.len()]).is_err());
        }
    }
}

/// Trees whose checksum is right but whose nodes are not a tree over the packs (written from
/// views, which promise nothing): the copy refuses them; the in-place view takes them (traversal
/// is safe on any view) and `check` names what broke.
#[test]
fn malformed_trees_with_good_checksums_are_refused() {
    let (tris, b8) = bunny8();
    let rays = mixed_rays(&tris, 200, 9);
    let (nodes, packs) = (b8.nodes().to_vec(), b8.packs().to_vec());
    let interior = |n: &Node8| n.child.iter().position(|&c| c & LEAF_BIT == 0);
    let (pi, ps) = nodes
        .iter()
        .enumerate()
        .find_map(|(i, n)| interior(n).map(|s| (i, s)))
        .unwrap();
    let child = nodes[pi].child[ps];
    // A leaf slot (its packs dropped when it takes another code).
    let (li, ls) = nodes
        .iter()
        .enumerate()
        .find_map(|(i, n)| {
            n.child
                .iter()
                .position(|&c| c != EMPTY_CHILD && c & LEAF_BIT != 0)
                .map(|s| (i, s))
        })
        .unwrap();
    let mut cases: Vec<(&str, Vec<Node8>, Vec<_>, FormatError)> = Vec::new();
    let edit = |f: &dyn Fn(&mut Vec<Node8>)| {
        let mut n = nodes.clone();
        f(&mut n);
        n
    };
    cases.push((
        "child out of range",
        edit(&|n| n[pi].child[ps] = n.len() as u32),
        packs.clone(),
        FormatError::Malformed,
    ));
    cases.push((
        "root as a child",
        edit(&|n| n[pi].child[ps] = 0),
        packs.clone(),
        FormatError::Malformed,
    ));
    cases.push((
        "a node with two parents",
        edit(&|n| n[li].child[ls] = child),
        packs.clone(),
        FormatError::Malformed,
    ));
    cases.push((
        "an unreachable node",
        edit(&|n| n[pi].child[ps] = EMPTY_CHILD),
        packs.clone(),
        FormatError::Malformed,
    ));
    cases.push((
        "a leaf past the packs",
        edit(&|n| n[li].child[ls] = LEAF_BIT | (packs.len() as u32) << 4),
        packs.clone(),
        FormatError::Malformed,
    ));
    let mut bad_lanes = packs.clone();
    bad_lanes[0].valid |= 1 << 8;
    cases.push(("a lane past N", nodes.clone(), bad_lanes, FormatError::Malformed));
    // Boxes: an unused slot's not empty, a used one's NaN or empty, a node's child outside it.
    let (ei, es) = nodes
        .iter()
        .enumerate()
        .find_map(|(i, n)| n.child.iter().position(|&c| c == EMPTY_CHILD).map(|s| (i, s)))
        .expect("the bunny's BVH8 has an unused slot");
    let set = |n: &mut Node8, i: usize, lo: Vec3, hi: Vec3| {
        for a in 0..3 {
            let (mut l, mut h) = (n.bounds.min[a].to_array(), n.bounds.max[a].to_array());
            (l[i], h[i]) = (lo[a], hi[a]);
            (n.bounds.min[a], n.bounds.max[a]) = (f32x8::new(l), f32x8::new(h));
        }
    };
    cases.push((
        "an unused slot with a box",
        edit(&|n| set(&mut n[ei], es, Vec3::splat(-1e30), Vec3::splat(1e30))),
        packs.clone(),
        FormatError::Malformed,
    ));
    let used = |n: &Node8, i: usize| n.bounds.get(i);
    cases.push((
        "a NaN in a used box",
        edit(&|n| {
            let b = used(&n[pi], ps);
            set(&mut n[pi], ps, Vec3::new(f32::NAN, b.min.y, b.min.z), b.max)
        }),
        packs.clone(),
        FormatError::Malformed,
    ));
    cases.push((
        "an empty used box",
        edit(&|n| set(&mut n[li], ls, Vec3::INFINITY, Vec3::NEG_INFINITY)),
        packs.clone(),
        FormatError::Malformed,
    ));
    cases.push((
        "a child outside its slot",
        edit(&|n| {
            let b = used(&n[pi], ps);
            set(&mut n[pi], ps, b.min, b.min)
        }),
        packs.clone(),
        FormatError::Malformed,
    ));
    // Packs: a valid lane over a degenerate triangle, past the builders' range, or without a
    // primitive index (the packer marks none of them valid).
    type Edit<'a> = &'a dyn Fn(&mut [[f32; 8]; 9], &mut [u32; 8]);
    let lane0 = |f: Edit| {
        let mut p = packs.clone();
        let mut v: [[f32; 8]; 9] = core::array::from_fn(|k| p[0].v[k / 3][k % 3].to_array());
        f(&mut v, &mut p[0].prim);
        p[0].v = core::array::from_fn(|j| core::array::from_fn(|a| f32x8::new(v[3 * j + a])));
        assert_eq!(p[0].valid & 1, 1);
        p
    };
    cases.push((
        "a degenerate triangle marked valid",
        nodes.clone(),
        lane0(&|v, _| {
            for k in 3..9 {
                v[k][0] = v[k % 3][0];
            }
        }),
        FormatError::Malformed,
    ));
    cases.push((
        "a vertex past the builders' range",
        nodes.clone(),
        lane0(&|v, _| (v[3][0], v[6][0]) = (3e38, -3e38)),
        FormatError::Malformed,
    ));
    cases.push((
        "a valid lane without a primitive",
        nodes.clone(),
        lane0(&|_, prim| prim[0] = strahl::geometry::INVALID),
        FormatError::Malformed,
    ));
    // A chain one node deeper than traversal takes.
    let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    let chain: Vec<Node8> = (0..=MAX_WIDE_DEPTH)
        .map(|i| {
            let mut n = Node8::empty();
            n.bounds = strahl::intersect::AabbX8::from_boxes(&[b, b]);
            n.child[0] = if i == MAX_WIDE_DEPTH { LEAF_BIT } else { i + 1 };
            n.child[1] = LEAF_BIT;
            n
        })
        .collect();
    cases.push(("too deep", chain.clone(), packs[..1].to_vec(), FormatError::TooDeep));
    let ok = chain[1..].to_vec();
    let mut ok = ok;
    for (i, n) in ok.iter_mut().enumerate() {
        if n.child[0] != LEAF_BIT {
            n.child[0] = i as u32 + 1;
        }
    }
    assert_eq!(
        Bvh8Ref {
            nodes: &ok,
            packs: &packs[..1]
        }
        .check(),
        Ok(MAX_WIDE_DEPTH)
    );
    for (what, nodes, packs, err) in cases {
        let view = Bvh8Ref {
            nodes: &nodes,
            packs: &packs,
        };
        let bytes = {
            let mut b = vec![0u8; view.byte_len()];
            view.write_bytes(&mut b).unwrap();
            b
        };
        assert_eq!(Bvh8::from_bytes(&bytes).err(), Some(err), "{what}");
        let buf = aligned(&bytes);
        let in_place = Bvh8Ref::from_bytes(&bytemuck::cast_slice::<Block, u8>(&buf)[..bytes.len()]).unwrap();
        assert_eq!(in_place.check(), Err(err), "{what}");
        // Traced anyway: no panic, no hang.
        for ray in &rays {
            let _ = wide::intersect::<Watertight, f32x8, 8>(in_place, ray);
            let _ = wide::occluded::<Watertight, f32x8, 8>(in_place, ray);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Arbitrary bytes behind a valid header, and arbitrary bytes alone: an error or a tree,
    /// never a panic.
    #[test]
    fn arbitrary_bytes_never_panic(payload in proptest::collection::vec(any::<u8>(), 0..2048), nodes in 0u64..4, packs in 0u64..4, raw in any::<bool>()) {
        let mut bytes = Vec::new();
        if !raw {
            bytes.extend_from_slice(b"STRAHLWB");
            for v in [1u32, 8, 8, 256, 352, 0] {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            for v in [nodes, packs, 0, 0] {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        bytes.extend_from_slice(&payload);
        let _ = Bvh8::from_bytes(&bytes);
        let _ = Bvh4::from_bytes(&bytes);
        let buf = aligned(&bytes);
        let _ = Bvh8Ref::from_bytes(&bytemuck::cast_slice::<Block, u8>(&buf)[..bytes.len()]);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Random child codes and pack masks written with a good checksum: `from_bytes` answers a
    /// tree (which `check` accepts and traversal walks) or an error, never a panic.
    #[test]
    fn random_structures_load_or_are_refused(
        codes in proptest::collection::vec(prop_oneof![0u32..8, (0u32..4).prop_map(|p| LEAF_BIT | p << 4), Just(EMPTY_CHILD), any::<u32>()], 8..48),
        packs in 0usize..4,
        mask in any::<u32>(),
    ) {
        let (_, b8) = bunny8();
        let b = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
        let nodes: Vec<Node8> = codes
            .chunks_exact(8)
            .map(|c| {
                let mut n = Node8::empty();
                n.bounds = strahl::intersect::AabbX8::from_boxes(&[b; 8]);
                n.child.copy_from_slice(c);
                n
            })
            .collect();
        let mut packs = b8.packs()[..packs].to_vec();
        if let Some(p) = packs.first_mut() {
            p.valid = mask;
        }
        let view = Bvh8Ref { nodes: &nodes, packs: &packs };
        let mut bytes = vec![0u8; view.byte_len()];
        view.write_bytes(&mut bytes).unwrap();
        let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
        match Bvh8::from_bytes(&bytes) {
            Ok(tree) => {
                prop_assert_eq!(view.check(), Ok(tree.depth()));
                let _ = tree.intersect::<Watertight>(&ray);
                let _ = tree.occluded::<Watertight>(&ray);
            }
            Err(e) => prop_assert_eq!(view.check(), Err(e)),
        }
    }
}
