//! Wide BVHs as bytes: save a built tree, load it again without building, or trace it in place
//! (memory-mapped, shared memory) without a copy.
//!
//! The format is described at [`HEADER_BYTES`].
//!
//! # Reading
//! - [`BvhWide::from_bytes`] (`alloc`): copies out of bytes at any alignment, portable across
//!   byte orders, and checks everything: header, length, checksum, and the tree's structure
//!   ([`BvhWideRef::check`] lists it: the tree, the boxes, the packs' valid lanes), so the tree
//!   it returns keeps what [`BvhWide::from_bvh2`] guarantees.
//! - [`BvhWideRef::from_bytes`]: no copy, no allocation (`no_std`): checks header, length and
//!   checksum and casts the bytes, which must start at a multiple of 64 bytes (a memory map's
//!   page, or an aligned buffer) on a little-endian machine. A view's traversal never panics and
//!   always terminates whatever the nodes hold, so the structure check is separate
//!   ([`BvhWideRef::check`]). Only [`Bvh4`](super::Bvh4) and [`Bvh8`](super::Bvh8) shapes.

use super::{BvhWideRef, WideNode};
use crate::intersect::{AabbLanes, TriangleLanes};
use crate::math::{Lane, f32x4, f32x8};
use bytemuck::{AnyBitPattern, Pod, Zeroable};
use core::mem::{offset_of, size_of};
#[cfg(feature = "alloc")]
use {
    super::{BvhWide, EMPTY_CHILD, LEAF_BIT, MAX_WIDE_DEPTH, leaf_packs},
    crate::Vec3,
    crate::geometry::INVALID,
    alloc::vec,
    alloc::vec::Vec,
};

/// Bytes of the header before the nodes, in the format [`BvhWide::to_bytes`] writes (version 1).
///
/// Little-endian throughout. A 64-byte header, then the nodes, then the packs, each exactly as an
/// [`N`-wide node](WideNode) and a [triangle pack](crate::intersect::TriangleLanes) lie in
/// memory on a little-endian machine (padding written as zeros), so that on such a machine a
/// 64-byte-aligned buffer is the tree:
///
/// ```text
///  offset  field
///   0      magic      b"STRAHLWB"
///   8      version    u32 (1)
///  12      width N    u32 (4 or 8)
///  16      lanes      u32 (lanes of the box and triangle vectors, N)
///  20      node size  u32 (bytes)
///  24      pack size  u32 (bytes)
///  28      reserved   u32 (0)
///  32      nodes      u64 (count)
///  40      packs      u64 (count)
///  48      checksum   u64 (of bytes 0..48 and everything after the header)
///  56      reserved   u64 (0)
///  64      nodes, then packs
/// ```
///
/// The checksum catches files damaged or altered: changing any one aligned 8-byte word of the
/// header's first 48 bytes or of the payload always changes it (each step is a bijection of the
/// state), so counts traded against each other at the same length are caught too.
///
/// ```
/// use strahl::layout::{Bvh8, HEADER_BYTES};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = strahl::build::Bvh2::build(&tris[..], &Default::default()).unwrap();
/// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
/// let bytes = b8.to_bytes();
/// let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap());
/// assert_eq!((u64_at(32), u64_at(40)), (b8.nodes().len() as u64, b8.packs().len() as u64));
/// assert_eq!(bytes.len(), HEADER_BYTES + 256 * b8.nodes().len() + 352 * b8.packs().len());
/// ```
pub const HEADER_BYTES: usize = 64;
const MAGIC: &[u8; 8] = b"STRAHLWB";
const VERSION: u32 = 1;

/// Why bytes are not a wide BVH of the type asked for.
///
/// ```
/// use strahl::layout::{Bvh4, Bvh8, FormatError};
/// # let tris = strahl::scene::icosphere(2).to_soup();
/// # let (b2, _) = strahl::build::Bvh2::build(&tris[..], &Default::default()).unwrap();
/// let bytes = Bvh8::from_bvh2(&b2, &tris[..]).unwrap().to_bytes();
/// assert_eq!(Bvh4::from_bytes(&bytes).unwrap_err(), FormatError::Shape); // an 8-wide tree
/// assert!(matches!(Bvh8::from_bytes(&bytes[..100]), Err(FormatError::Length { .. })));
/// let mut damaged = bytes.clone();
/// damaged[1000] ^= 1;
/// assert_eq!(Bvh8::from_bytes(&damaged).unwrap_err(), FormatError::Checksum);
/// assert!(FormatError::Checksum.to_string().contains("checksum"));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FormatError {
    /// The bytes do not start with the format's magic number.
    Magic,
    /// A format version this build does not read.
    Version(u32),
    /// Written for another width, lane type or node or pack size (or with reserved header fields
    /// set).
    Shape,
    /// The length is not the header's plus the nodes' and packs' it announces (or a buffer to
    /// write into is too short): `expected` bytes, `found`.
    Length {
        /// Bytes the header announces (or the tree needs).
        expected: u64,
        /// Bytes given.
        found: u64,
    },
    /// The payload's checksum differs from the header's: damaged or altered bytes.
    Checksum,
    /// In-place reading only: the bytes do not start at the nodes' alignment (64 bytes), or the
    /// machine is big-endian.
    Misaligned,
    /// Not a tree as the collapse makes them ([`BvhWideRef::check`] lists what is checked): a
    /// child code out of range, a node with two parents or none or not reached from the root, a
    /// box that is NaN, empty where used or not empty where unused, a child's boxes outside its
    /// slot's, or a lane marked valid past `N` or over a degenerate triangle or without a
    /// primitive index.
    Malformed,
    /// Deeper than [`MAX_WIDE_DEPTH`].
    TooDeep,
}

impl core::fmt::Display for FormatError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Magic => f.write_str("not a strahl wide BVH (wrong magic number)"),
            Self::Version(v) => write!(f, "wide BVH format version {v} is not supported (this build reads 1)"),
            Self::Shape => f.write_str("the wide BVH was written for another width, lane type or node layout"),
            Self::Length { expected, found } => {
                write!(
                    f,
                    "wide BVH bytes of the wrong length: {expected} expected, {found} found"
                )
            }
            Self::Checksum => f.write_str("the wide BVH's checksum does not match: the bytes are damaged"),
            Self::Misaligned => f.write_str("in-place reading needs bytes aligned to 64 on a little-endian machine"),
            Self::Malformed => f.write_str("the wide BVH's nodes do not form a tree over its packs"),
            Self::TooDeep => f.write_str("the wide BVH is deeper than MAX_WIDE_DEPTH"),
        }
    }
}

impl core::error::Error for FormatError {}

/// The node and pack types of [`Bvh4`](super::Bvh4) and [`Bvh8`](super::Bvh8) read in place.
/// Only these two shapes: a node of `N` children must have `N` box lanes, and the collapse makes
/// no wider ones, so bytes cannot make a node the traversals do not take.
macro_rules! any_bit_pattern {
    ($lane:ty, $n:literal) => {
        // SAFETY: `WideNode` is `repr(C)` over `[L; 3]` twice and `[u32; N]` twice, and
        // `TriangleLanes` over `[[L; 3]; 3]`, `[u32; N]` and `u32`; `L` (`wide`'s `f32xN`, which is
        // `Pod`) and `u32` are valid for any bit pattern and for all zeros, so every field is, and
        // so is the whole. Padding (none in the node; the pack's tail, asserted in the layout
        // module) is allowed for `AnyBitPattern`, which is only read through shared references
        // or by value. `Copy` and `'static` hold.
        unsafe impl Zeroable for WideNode<$lane, $n> {}
        // SAFETY: as above.
        unsafe impl AnyBitPattern for WideNode<$lane, $n> {}
        // SAFETY: as above.
        unsafe impl Zeroable for TriangleLanes<$lane, $n> {}
        // SAFETY: as above.
        unsafe impl AnyBitPattern for TriangleLanes<$lane, $n> {}
    };
}
any_bit_pattern!(f32x4, 4);
any_bit_pattern!(f32x8, 8);

/// The checksum of a file: the header's first 48 bytes (all but the checksum and the reserved
/// word after it), then the payload, as eight interleaved lanes of 8-byte words, the tail and the
/// length folded in at the end. Each word step `h -> rotl((h ^ w) * K, 29)` is a bijection of `h`
/// (and of `w`), so any change within one lane's words changes the result.
fn checksum(head: &[u8], payload: &[u8]) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let step = |h: u64, w: u64| ((h ^ u64::from_le(w)).wrapping_mul(K)).rotate_left(29);
    let mut h: [u64; 8] = core::array::from_fn(|l| K ^ l as u64);
    let mut first = [0u8; 64];
    first[..48].copy_from_slice(&head[..48]);
    let w: [u64; 8] = bytemuck::pod_read_unaligned(&first);
    h = core::array::from_fn(|l| step(h[l], w[l]));
    let mut blocks = payload.chunks_exact(64);
    for c in &mut blocks {
        let w: [u64; 8] = bytemuck::pod_read_unaligned(c);
        h = core::array::from_fn(|l| step(h[l], w[l]));
    }
    let mut tail = [0u8; 64];
    let rest = blocks.remainder();
    tail[..rest.len()].copy_from_slice(rest);
    let w: [u64; 8] = bytemuck::pod_read_unaligned(&tail);
    h = core::array::from_fn(|l| step(h[l], w[l]));
    let mix = |x: u64| {
        let x = (x ^ (x >> 33)).wrapping_mul(0xFF51_AFD7_ED55_8CCD);
        x ^ (x >> 29)
    };
    h.iter().enumerate().fold(payload.len() as u64, |acc, (l, &x)| {
        acc ^ mix(x).rotate_left(8 * l as u32)
    })
}

/// Node and pack sizes, checked against the header.
const fn sizes<L, const N: usize>() -> (usize, usize) {
    (size_of::<WideNode<L, N>>(), size_of::<TriangleLanes<L, N>>())
}

/// The header's counts, checked against the type and the length of `bytes`.
fn read_header<L: Lane, const N: usize>(bytes: &[u8]) -> Result<(usize, usize), FormatError> {
    let len = bytes.len() as u64;
    if bytes.len() < HEADER_BYTES {
        return Err(FormatError::Length {
            expected: HEADER_BYTES as u64,
            found: len,
        });
    }
    let u32_at = |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let u64_at = |o: usize| u64::from(u32_at(o)) | u64::from(u32_at(o + 4)) << 32;
    if &bytes[..8] != MAGIC {
        return Err(FormatError::Magic);
    }
    if u32_at(8) != VERSION {
        return Err(FormatError::Version(u32_at(8)));
    }
    let (node_bytes, pack_bytes) = sizes::<L, N>();
    let shape = [N, L::N, node_bytes, pack_bytes].map(|x| x as u64);
    // The reserved fields too: a later version may give them a meaning.
    if [12, 16, 20, 24].map(|o| u64::from(u32_at(o))) != shape || u32_at(28) != 0 || u64_at(56) != 0 {
        return Err(FormatError::Shape);
    }
    let (nodes, packs) = (u64_at(32), u64_at(40));
    let expected = nodes
        .checked_mul(node_bytes as u64)
        .zip(packs.checked_mul(pack_bytes as u64))
        .and_then(|(a, b)| a.checked_add(b))
        .and_then(|p| p.checked_add(HEADER_BYTES as u64))
        .unwrap_or(u64::MAX);
    if expected != len {
        return Err(FormatError::Length { expected, found: len });
    }
    if checksum(&bytes[..HEADER_BYTES], &bytes[HEADER_BYTES..]) != u64_at(48) {
        return Err(FormatError::Checksum);
    }
    Ok((nodes as usize, packs as usize))
}

/// Every field of nodes and packs is a 4-byte word (`f32` lanes, `u32` codes): on a big-endian
/// machine each word's bytes are reversed to and from the little-endian file; on a little-endian
/// one this does nothing.
#[inline(always)]
fn words_le(bytes: &mut [u8]) {
    if cfg!(target_endian = "big") {
        for w in bytes.chunks_exact_mut(4) {
            w.reverse();
        }
    }
}

/// Writes the field `v` at `out[at..]`, little-endian.
#[inline(always)]
fn put<T: Pod>(out: &mut [u8], at: usize, v: &[T]) {
    let b: &[u8] = bytemuck::cast_slice(v);
    let dst = &mut out[at..at + b.len()];
    dst.copy_from_slice(b);
    words_le(dst);
}

/// Reads a node or pack from the little-endian bytes `b` (its whole size).
#[cfg(feature = "alloc")]
#[inline(always)]
fn get<T: AnyBitPattern>(b: &[u8]) -> T {
    if cfg!(target_endian = "big") {
        let mut w = b.to_vec();
        words_le(&mut w);
        bytemuck::pod_read_unaligned(&w)
    } else {
        bytemuck::pod_read_unaligned(b)
    }
}

impl<'a, L: Lane + Pod, const N: usize> BvhWideRef<'a, L, N>
where
    WideNode<L, N>: AnyBitPattern,
    TriangleLanes<L, N>: AnyBitPattern,
{
    /// Bytes [`write_bytes`](Self::write_bytes) writes: the header, the nodes and the packs.
    ///
    /// ```
    /// use strahl::layout::{Bvh8, HEADER_BYTES};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = strahl::build::Bvh2::build(&tris[..], &Default::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// assert_eq!(b8.view().byte_len(), HEADER_BYTES + b8.memory_bytes());
    /// ```
    pub fn byte_len(&self) -> usize {
        let (node_bytes, pack_bytes) = sizes::<L, N>();
        HEADER_BYTES + self.nodes.len() * node_bytes + self.packs.len() * pack_bytes
    }

    /// Writes the tree into `out` (at least [`byte_len`](Self::byte_len) bytes; the rest is left
    /// as it is) and returns the bytes written; no allocation. The format is described at
    /// [`HEADER_BYTES`].
    ///
    /// ```
    /// use strahl::{Ray, Vec3, layout::{Bvh8, Bvh8Ref, FormatError}, traverse::Moller};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = strahl::build::Bvh2::build(&tris[..], &Default::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let view = b8.view();
    /// let mut buf = vec![0u8; view.byte_len() + 10];
    /// assert_eq!(view.write_bytes(&mut buf), Ok(view.byte_len()));
    /// let short = view.write_bytes(&mut [0u8; 16]);
    /// assert!(matches!(short, Err(FormatError::Length { found: 16, .. })));
    /// let copy = Bvh8::from_bytes(&buf[..view.byte_len()]).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// assert_eq!(copy.intersect::<Moller>(&ray), b8.intersect::<Moller>(&ray));
    /// ```
    pub fn write_bytes(&self, out: &mut [u8]) -> Result<usize, FormatError> {
        let total = self.byte_len();
        if out.len() < total {
            return Err(FormatError::Length {
                expected: total as u64,
                found: out.len() as u64,
            });
        }
        let out = &mut out[..total];
        let (node_bytes, pack_bytes) = sizes::<L, N>();
        let (head, payload) = out.split_at_mut(HEADER_BYTES);
        head.fill(0);
        let bounds = offset_of!(WideNode<L, N>, bounds);
        let (min, max) = (
            bounds + offset_of!(AabbLanes<L>, min),
            bounds + offset_of!(AabbLanes<L>, max),
        );
        let child = offset_of!(WideNode<L, N>, child);
        // Each node and pack zeroed (its padding) and written while in cache.
        for (node, o) in self.nodes.iter().zip((0..).step_by(node_bytes)) {
            payload[o..o + node_bytes].fill(0);
            put(payload, o + min, &node.bounds.min[..]);
            put(payload, o + max, &node.bounds.max[..]);
            put(payload, o + child, &node.child[..]);
        }
        let base = self.nodes.len() * node_bytes;
        let (v, prim, valid) = (
            offset_of!(TriangleLanes<L, N>, v),
            offset_of!(TriangleLanes<L, N>, prim),
            offset_of!(TriangleLanes<L, N>, valid),
        );
        for (pack, o) in self.packs.iter().zip((base..).step_by(pack_bytes)) {
            payload[o..o + pack_bytes].fill(0);
            put(payload, o + v, pack.v.as_flattened());
            put(payload, o + prim, &pack.prim[..]);
            put(payload, o + valid, core::slice::from_ref(&pack.valid));
        }
        head[..8].copy_from_slice(MAGIC);
        for (k, x) in [VERSION, N as u32, L::N as u32, node_bytes as u32, pack_bytes as u32]
            .into_iter()
            .enumerate()
        {
            head[8 + 4 * k..12 + 4 * k].copy_from_slice(&x.to_le_bytes());
        }
        for (k, x) in [self.nodes.len() as u64, self.packs.len() as u64]
            .into_iter()
            .enumerate()
        {
            head[32 + 8 * k..40 + 8 * k].copy_from_slice(&x.to_le_bytes());
        }
        let sum = checksum(head, payload);
        head[48..56].copy_from_slice(&sum.to_le_bytes());
        Ok(total)
    }

    /// The tree in `bytes`, traced in place: no copy, no allocation. Checks the header, the
    /// length and the checksum (one pass over the bytes), not the structure
    /// ([`check`](Self::check) does that; traversal is safe on any view). `bytes` must start at a
    /// multiple of 64 bytes (a memory map does) on a little-endian machine, else
    /// [`FormatError::Misaligned`]: [`BvhWide::from_bytes`] reads any alignment.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, layout::{Bvh8, Bvh8Ref, FormatError}, traverse::{Moller, wide}};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = strahl::build::Bvh2::build(&tris[..], &Default::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let bytes = b8.to_bytes();
    /// // An aligned buffer (a memory-mapped file's pages would do): 64-byte blocks.
    /// #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
    /// #[repr(C, align(64))]
    /// struct Block([u8; 64]);
    /// let mut blocks = vec![Block([0; 64]); bytes.len() / 64 + 1];
    /// let aligned: &mut [u8] = bytemuck::cast_slice_mut(&mut blocks);
    /// aligned[..bytes.len()].copy_from_slice(&bytes);
    /// let view = Bvh8Ref::from_bytes(&aligned[..bytes.len()]).unwrap();
    /// assert_eq!((view.nodes.len(), view.packs.len()), (b8.nodes().len(), b8.packs().len()));
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// assert_eq!(wide::intersect::<Moller, _, 8>(view, &ray), b8.intersect::<Moller>(&ray));
    /// // One byte later, the nodes would not be aligned.
    /// aligned.copy_within(..bytes.len(), 1);
    /// assert_eq!(Bvh8Ref::from_bytes(&aligned[1..bytes.len() + 1]).unwrap_err(), FormatError::Misaligned);
    /// ```
    pub fn from_bytes(bytes: &'a [u8]) -> Result<Self, FormatError> {
        let (nodes, _) = read_header::<L, N>(bytes)?;
        if cfg!(target_endian = "big") {
            return Err(FormatError::Misaligned);
        }
        let (node_bytes, _) = sizes::<L, N>();
        let (n, p) = bytes[HEADER_BYTES..].split_at(nodes * node_bytes);
        // The casts check alignment (the lengths are whole nodes and packs, by the header). The
        // nodes' start is checked at 64 bytes even where there are none, so that an aligned
        // buffer is refused or accepted whatever it holds.
        let misaligned = |_| FormatError::Misaligned;
        if bytes.as_ptr().align_offset(64) != 0 {
            return Err(FormatError::Misaligned);
        }
        Ok(Self {
            nodes: bytemuck::try_cast_slice(n).map_err(misaligned)?,
            packs: bytemuck::try_cast_slice(p).map_err(misaligned)?,
        })
    }

    /// Checks that the nodes form a tree over the packs, as [`BvhWide::from_bvh2`] makes them,
    /// and returns its depth (root = 1, 0 for no nodes):
    ///
    /// - every child code an unused slot ([`EMPTY_CHILD`]) whose box is the empty box, a leaf
    ///   whose packs exist, or a node other than the root; every used slot's box free of NaN and
    ///   not empty;
    /// - every node but the root the child of exactly one node and reached from the root; the
    ///   depth at most [`MAX_WIDE_DEPTH`];
    /// - a node's box in its parent's slot holding all of its own slots' boxes (the leaves'
    ///   boxes are not checked against their triangles: a spatial-split tree's leaves clip them);
    /// - every lane a pack marks valid within `N`, with a primitive index (not
    ///   [`INVALID`]) and a triangle the packer would mark valid:
    ///   not degenerate, its coordinates within the builders' range.
    ///
    /// [`BvhWide::from_bvh2`]'s trees always pass.
    ///
    /// ```
    /// use strahl::layout::{Bvh8, Bvh8Ref, FormatError};
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = strahl::build::Bvh2::build(&tris[..], &Default::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// assert_eq!(b8.view().check(), Ok(b8.depth()));
    /// let mut nodes = b8.nodes().to_vec();
    /// nodes[0].child[0] = 0; // the root its own child
    /// assert_eq!(Bvh8Ref { nodes: &nodes, packs: b8.packs() }.check(), Err(FormatError::Malformed));
    /// ```
    #[cfg(feature = "alloc")]
    pub fn check(&self) -> Result<u32, FormatError> {
        let n = self.nodes.len();
        // Each valid lane's triangle as the packer would judge it, all lanes at once: finite,
        // not degenerate (`geometry::is_degenerate`: a zero cross product of the edges; the
        // products are the same, and a difference's sign does not change whether it is zero) and
        // within the builders' range (`refit::kept`: the box's extent and centre finite).
        let pack_ok = |p: &TriangleLanes<L, N>| {
            let [a, b, c] = p.v;
            let inf = L::splat(f32::INFINITY);
            let finite = |x: L| x.abs().lt(inf);
            let mut ok = L::splat(-0.0).eq(L::splat(0.0)); // all lanes set
            for k in 0..3 {
                ok = ok & finite(a[k]) & finite(b[k]) & finite(c[k]);
                let (lo, hi) = (a[k].min_l(b[k]).min_l(c[k]), a[k].max_l(b[k]).max_l(c[k]));
                ok = ok & finite(hi - lo) & finite(hi + lo);
            }
            let (e1, e2) = ([0, 1, 2].map(|k| b[k] - a[k]), [0, 1, 2].map(|k| c[k] - a[k]));
            let zero = L::splat(0.0);
            let n = [1, 2, 0].map(|k| {
                let (j, l) = (k, (k + 1) % 3);
                e1[j] * e2[l] - e2[j] * e1[l]
            });
            ok = ok & (n[0].ne(zero) | n[1].ne(zero) | n[2].ne(zero));
            let valid = p.valid;
            valid >> N == 0 && valid & !ok.bitmask() == 0 && (0..N).all(|i| valid >> i & 1 == 0 || p.prim[i] != INVALID)
        };
        if !self.packs.iter().all(pack_ok) {
            return Err(FormatError::Malformed);
        }
        if n == 0 {
            return Ok(0);
        }
        // Slot `i`'s box as `(min, max)`.
        let slot = |node: &WideNode<L, N>, i: usize| {
            let b = &node.bounds;
            (
                Vec3::new(b.min[0].lane(i), b.min[1].lane(i), b.min[2].lane(i)),
                Vec3::new(b.max[0].lane(i), b.max[1].lane(i), b.max[2].lane(i)),
            )
        };
        // Parents: every node at most one, the root none; the slots' boxes.
        let mut parented = vec![false; n];
        for node in self.nodes {
            for (i, &c) in node.child.iter().enumerate() {
                let (lo, hi) = slot(node, i);
                if c == EMPTY_CHILD {
                    if lo != Vec3::INFINITY || hi != Vec3::NEG_INFINITY {
                        return Err(FormatError::Malformed);
                    }
                    continue;
                }
                // Not NaN, not empty (`lo <= hi` fails for both).
                if !lo.cmple(hi).all() {
                    return Err(FormatError::Malformed);
                }
                if c & LEAF_BIT != 0 {
                    let (first, count) = leaf_packs(c);
                    if first + count > self.packs.len() {
                        return Err(FormatError::Malformed);
                    }
                    continue;
                }
                let c = c as usize;
                if c == 0 || c >= n || core::mem::replace(&mut parented[c], true) {
                    return Err(FormatError::Malformed);
                }
                // The child's slots within this slot.
                let inner = &self.nodes[c];
                for (k, &cc) in inner.child.iter().enumerate() {
                    let (clo, chi) = slot(inner, k);
                    if cc != EMPTY_CHILD && !(lo.cmple(clo).all() && chi.cmple(hi).all()) {
                        return Err(FormatError::Malformed);
                    }
                }
            }
        }
        // With one parent each, the walk from the root meets every node it reaches once.
        let (mut stack, mut reached, mut depth) = (vec![(0usize, 1u32)], 0usize, 0u32);
        while let Some((i, d)) = stack.pop() {
            reached += 1;
            depth = depth.max(d);
            if d > MAX_WIDE_DEPTH {
                return Err(FormatError::TooDeep);
            }
            for &c in &self.nodes[i].child {
                if c & LEAF_BIT == 0 {
                    stack.push((c as usize, d + 1));
                }
            }
        }
        if reached != n {
            return Err(FormatError::Malformed);
        }
        Ok(depth)
    }
}

#[cfg(feature = "alloc")]
impl<L: Lane + Pod, const N: usize> BvhWide<L, N>
where
    WideNode<L, N>: AnyBitPattern,
    TriangleLanes<L, N>: AnyBitPattern,
{
    /// The tree as bytes (the format is described at [`HEADER_BYTES`]), to store and read again with
    /// [`from_bytes`](Self::from_bytes) or trace in place with [`BvhWideRef::from_bytes`].
    ///
    /// ```
    /// use strahl::layout::Bvh8;
    /// # let tris = strahl::scene::icosphere(2).to_soup();
    /// # let (b2, _) = strahl::build::Bvh2::build(&tris[..], &Default::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let bytes = b8.to_bytes();
    /// assert_eq!(&bytes[..8], b"STRAHLWB");
    /// assert_eq!(Bvh8::from_bytes(&bytes).unwrap().to_bytes(), bytes); // the same bytes again
    /// ```
    pub fn to_bytes(&self) -> Vec<u8> {
        let view = self.view();
        let mut out = vec![0u8; view.byte_len()];
        let written = view.write_bytes(&mut out);
        debug_assert_eq!(written, Ok(out.len()));
        out
    }

    /// Reads a tree from bytes at any alignment (copied; portable across byte orders), checked
    /// in full: header, length, checksum and structure ([`BvhWideRef::check`]), so the tree keeps
    /// what [`from_bvh2`](Self::from_bvh2) guarantees. Loading a million triangles' BVH8 takes a
    /// small part of building it (README, "Saving and loading wide BVHs").
    ///
    /// ```
    /// use strahl::{Ray, Vec3, layout::{Bvh8, FormatError}, traverse::Watertight};
    /// let tris = strahl::scene::icosphere(3).to_soup();
    /// let (b2, _) = strahl::build::Bvh2::build(&tris[..], &Default::default()).unwrap();
    /// let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
    /// let loaded = Bvh8::from_bytes(&b8.to_bytes()).unwrap();
    /// assert_eq!(loaded.depth(), b8.depth());
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -3.0), Vec3::Z);
    /// assert_eq!(loaded.intersect::<Watertight>(&ray), b8.intersect::<Watertight>(&ray));
    /// assert_eq!(Bvh8::from_bytes(b"not a tree").unwrap_err(), FormatError::Length { expected: 64, found: 10 });
    /// ```
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, FormatError> {
        let (nodes, packs) = read_header::<L, N>(bytes)?;
        let (node_bytes, pack_bytes) = sizes::<L, N>();
        let payload = &bytes[HEADER_BYTES..];
        let mut out = Self {
            nodes: alloc_like(nodes),
            packs: alloc_like(packs),
            depth: 0,
        };
        let (node_part, pack_part) = payload.split_at(nodes * node_bytes);
        out.nodes
            .extend(node_part.chunks_exact(node_bytes).map(get::<WideNode<L, N>>));
        out.packs
            .extend(pack_part.chunks_exact(pack_bytes).map(get::<TriangleLanes<L, N>>));
        out.depth = out.view().check()?;
        Ok(out)
    }
}

/// An empty vector for `n` elements (advised for huge pages where large, as the collapse's).
#[cfg(feature = "alloc")]
fn alloc_like<T>(n: usize) -> Vec<T> {
    #[cfg(feature = "std")]
    return super::pages::advised_with_capacity(n);
    #[cfg(not(feature = "std"))]
    Vec::with_capacity(n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::{BuildParams, Bvh2};
    use crate::layout::{Bvh4, Bvh8};
    use crate::math::f32x8;
    use crate::traverse::{Moller, wide};
    use crate::{Ray, Vec3};

    /// Whole 64-byte blocks: an aligned buffer.
    #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
    #[repr(C, align(64))]
    struct Block([u8; 64]);

    /// The in-place view (the `AnyBitPattern` casts) reads what was written, field for field,
    /// for both widths; under miri in CI.
    #[test]
    fn in_place_views_read_the_written_trees() {
        // Triangles on a small grid (no square roots: miri runs no inline assembly).
        let tris: Vec<[Vec3; 3]> = (0..200)
            .map(|i| {
                let v = Vec3::new((i % 7) as f32, (i / 7) as f32, (i % 3) as f32 * 0.5);
                [v, v + Vec3::X, v + Vec3::Y * 0.75]
            })
            .collect();
        let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        let b8 = Bvh8::from_bvh2(&b2, &tris[..]).unwrap();
        let bytes = b8.to_bytes();
        let mut buf = vec![Block([0; 64]); bytes.len() / 64 + 1];
        let raw: &mut [u8] = bytemuck::cast_slice_mut(&mut buf);
        raw[..bytes.len()].copy_from_slice(&bytes);
        let view = BvhWideRef::<f32x8, 8>::from_bytes(&raw[..bytes.len()]).unwrap();
        assert_eq!(view.nodes.len(), b8.nodes().len());
        for (a, b) in view.nodes.iter().zip(b8.nodes()) {
            assert_eq!(a.child, b.child);
            for k in 0..8 {
                assert_eq!(a.bounds.get(k), b.bounds.get(k));
            }
        }
        for (a, b) in view.packs.iter().zip(b8.packs()) {
            assert_eq!((a.prim, a.valid), (b.prim, b.valid));
            for k in 0..8 {
                assert_eq!(a.get(k), b.get(k));
            }
        }
        let ray = Ray::new(Vec3::new(2.3, 3.2, -3.0), Vec3::Z);
        assert!(b8.intersect::<Moller>(&ray).is_some());
        assert_eq!(
            wide::intersect::<Moller, _, 8>(view, &ray),
            b8.intersect::<Moller>(&ray)
        );
        let b4 = Bvh4::from_bvh2(&b2, &tris[..]).unwrap();
        let bytes = b4.to_bytes();
        let mut buf = vec![Block([0; 64]); bytes.len() / 64 + 1];
        let raw: &mut [u8] = bytemuck::cast_slice_mut(&mut buf);
        raw[..bytes.len()].copy_from_slice(&bytes);
        let view = BvhWideRef::<crate::math::f32x4, 4>::from_bytes(&raw[..bytes.len()]).unwrap();
        assert_eq!(view.check(), Ok(b4.depth()));
        assert_eq!(
            wide::intersect::<Moller, _, 4>(view, &ray),
            b4.intersect::<Moller>(&ray)
        );
    }

    /// `check` judges each valid lane as the packer and the builders would (`is_degenerate`,
    /// `refit::kept`, a primitive index), all lanes at once, on adversarial coordinates.
    #[test]
    fn lanes_are_judged_as_the_packer_judges_them() {
        use crate::geometry::{INVALID, Triangle, is_degenerate};
        use crate::layout::{Bvh8Ref, LEAF_BIT, Node8};
        use crate::scene::Rng;
        let values = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            1e-30,
            -1e-30,
            1e-40,
            1e30,
            1.7e38,
            -1.7e38,
            3e38,
            f32::INFINITY,
            f32::NAN,
        ];
        let mut rng = Rng::new(3);
        let mut node = Node8::empty();
        node.child[0] = LEAF_BIT;
        node.bounds = crate::intersect::AabbX8::from_boxes(&[crate::Aabb::new(Vec3::splat(-1.0), Vec3::ONE)]);
        let (mut accepted, mut refused) = (0, 0);
        for round in 0..2000usize {
            let pick = |rng: &mut Rng| {
                if rng.u64().is_multiple_of(3) {
                    rng.range(-2.0, 2.0)
                } else {
                    values[(rng.u64() % values.len() as u64) as usize]
                }
            };
            let vertex = |rng: &mut Rng| Vec3::new(pick(rng), pick(rng), pick(rng));
            let tris: [Triangle; 8] = core::array::from_fn(|_| {
                let v0 = vertex(&mut rng);
                // Some repeat a vertex or lie on a line: degenerate by construction.
                match rng.u64() % 4 {
                    0 => [v0, v0, vertex(&mut rng)],
                    1 => [v0, v0 * 2.0, v0 * 3.0],
                    _ => [v0, vertex(&mut rng), vertex(&mut rng)],
                }
            });
            let mut pack = crate::intersect::TriangleX8::pack(&tris, &[]);
            if round.is_multiple_of(5) {
                pack.prim[round % 8] = INVALID;
            }
            for (i, t) in tris.iter().enumerate() {
                pack.valid = 1 << i;
                let want = pack.prim[i] != INVALID && !is_degenerate(t) && crate::layout::refit::kept(t);
                let got = Bvh8Ref {
                    nodes: &[node],
                    packs: &[pack],
                }
                .check();
                assert_eq!(got.is_ok(), want, "{t:?} prim {}", pack.prim[i]);
                if want {
                    accepted += 1;
                } else {
                    refused += 1;
                }
            }
        }
        assert!(accepted > 1000 && refused > 1000, "{accepted} / {refused}");
    }

    /// A change confined to one 8-byte word always changes the checksum (each step is a
    /// bijection), the length too.
    #[test]
    fn the_checksum_sees_every_word() {
        let bytes: Vec<u8> = (0..1000u32).map(|i| (i * 37 % 251) as u8).collect();
        let head: Vec<u8> = (0..64u8).collect();
        let sum = checksum(&head, &bytes);
        for at in 0..bytes.len() {
            let mut b = bytes.clone();
            b[at] = b[at].wrapping_add(1 + (at % 200) as u8);
            assert_ne!(checksum(&head, &b), sum, "byte {at}");
        }
        for at in 0..48 {
            let mut h = head.clone();
            h[at] ^= 0x40;
            assert_ne!(checksum(&h, &bytes), sum, "header byte {at}");
        }
        let mut h = head.clone();
        h[50] ^= 1; // the checksum's own bytes are not summed
        assert_eq!(checksum(&h, &bytes), sum);
        assert_ne!(checksum(&head, &bytes[..999]), sum);
        assert_ne!(checksum(&head, &[0u8; 8]), checksum(&head, &[0u8; 9]));
    }
}
