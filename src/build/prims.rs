//! Primitive input ([`Primitives`]) and the builders' working set: one 32-byte reference per valid
//! primitive, its box in "negated-min" form so that growing a box is a single `max`.

use super::{BuildError, Node};
use crate::geometry::{Aabb, Triangles};
use crate::math::{Lane, f32x4, f32x8};
use alloc::vec::Vec;
use glam::{Vec3, Vec3A};

/// What the builders need of a primitive: its count and each one's bounding box.
///
/// Implemented for everything that implements [`Triangles`] (indexed meshes, soups,
/// `[Triangle]`) and for `[Aabb]` (any primitive type, as boxes). A primitive whose box is
/// `None` (a triangle with a non-finite vertex or an index out of range) is **invalid**: the
/// builders leave it out and count it in [`BuildStats::invalid`](super::BuildStats::invalid).
/// Boxes that are empty, not finite, or whose extent or doubled centre `min + max` overflows `f32`
/// are invalid too: so a primitive with a coordinate beyond about `±1.7e38` (`f32::MAX / 2`) is
/// left out and counted (brute force over the triangles may still hit it; the trees never do).
/// A primitive's centroid, for splitting and Morton codes, is the centre of its box.
///
/// ```
/// use strahl::{Aabb, Vec3, build::Primitives};
/// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::ZERO, Vec3::X, Vec3::splat(f32::NAN)]];
/// assert_eq!(tris[..].prim_count(), 2);
/// assert_eq!(tris[..].prim_bounds(0), Some(Aabb::new(Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0))));
/// assert_eq!(tris[..].prim_bounds(1), None); // NaN vertex
/// let boxes = [Aabb::new(Vec3::ZERO, Vec3::ONE)];
/// assert_eq!(boxes[..].prim_bounds(0), Some(boxes[0]));
/// ```
pub trait Primitives {
    /// Number of primitives, valid or not.
    ///
    /// ```
    /// use strahl::{build::Primitives, scene};
    /// let mesh = scene::icosphere(1); // 80 triangles
    /// assert_eq!(mesh.as_indexed().prim_count(), 80);
    /// assert_eq!(mesh.to_soup()[..].prim_count(), mesh.as_indexed().prim_count());
    /// ```
    fn prim_count(&self) -> usize;
    /// Primitive `i`'s bounding box, or `None` if it is invalid or `i` is out of range.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, build::Primitives};
    /// let tris = [[Vec3::ZERO, Vec3::new(2.0, 0.0, -1.0), Vec3::Y]];
    /// let b = Aabb::new(Vec3::new(0.0, 0.0, -1.0), Vec3::new(2.0, 1.0, 0.0));
    /// assert_eq!(tris[..].prim_bounds(0), Some(b));
    /// assert_eq!(tris[..].prim_bounds(1), None); // out of range
    /// ```
    fn prim_bounds(&self, i: usize) -> Option<Aabb>;
}

impl<T: Triangles + ?Sized> Primitives for T {
    #[inline]
    fn prim_count(&self) -> usize {
        self.len()
    }
    #[inline]
    fn prim_bounds(&self, i: usize) -> Option<Aabb> {
        let [a, b, c] = self.triangle(i)?;
        let (a, b, c) = (Vec3A::from(a), Vec3A::from(b), Vec3A::from(c));
        // NOTE: `min`/`max` ignore NaN, so finiteness is checked on the vertices themselves:
        // `v * 0` is 0 for finite `v`, NaN for an infinity or a NaN.
        let finite = (a * 0.0 + b * 0.0 + c * 0.0) == Vec3A::ZERO;
        finite.then(|| Aabb::new(a.min(b).min(c).into(), a.max(b).max(c).into()))
    }
}

impl Primitives for [Aabb] {
    #[inline]
    fn prim_count(&self) -> usize {
        self.len()
    }
    #[inline]
    fn prim_bounds(&self, i: usize) -> Option<Aabb> {
        self.get(i).copied()
    }
}

/// Primitive `i`'s box if the builders accept it: present and [`usable_box`].
#[inline]
pub(crate) fn usable_bounds<P: Primitives + ?Sized>(prims: &P, i: usize) -> Option<Aabb> {
    let b = prims.prim_bounds(i)?;
    usable_box(b.min, b.max).then_some(b)
}

/// `true` if a primitive box from `min` to `max` is one the trees accept: not empty, and its
/// extent `max - min` and doubled centre `min + max` finite (so its bounds are finite too, and
/// areas of single boxes and centroids never overflow). A coordinate beyond about `±1.7e38`
/// (`f32::MAX / 2`) fails it. The one rule of the builders ([`usable_bounds`]; `prim_ref` in four
/// lanes), [`Bvh2::refit`](super::Bvh2::refit) and `BvhWide::refit`.
#[inline(always)]
pub(crate) fn usable_box(min: Vec3, max: Vec3) -> bool {
    min.cmple(max).all() && (max - min).is_finite() && (max + min).is_finite()
}

/// Lane 3 of a [`PrimRef`] holds the primitive index's bits XOR this, so that it reads as a normal
/// float (in `[1, 2)` for indices below `2^23`) and never as a subnormal.
// PERF: subnormal lanes would make some x86 cores take microcode assists in the min/max ops.
const INDEX_XOR: u32 = 0x3F80_0000;

/// A box in negated-min form `[-min.x, -min.y, -min.z, *, max.x, max.y, max.z, *]`: the union of
/// two boxes is their lane-wise `max`, the empty box is all `-inf`.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub(crate) struct Box8(pub f32x8);

impl Box8 {
    pub const EMPTY: Self = Self(f32x8::new([f32::NEG_INFINITY; 8]));

    #[inline(always)]
    pub fn grow(&mut self, other: Box8) {
        self.0 = other.0.max_l(self.0);
    }

    #[inline(always)]
    pub fn union(self, other: Box8) -> Box8 {
        Box8(other.0.max_l(self.0))
    }

    /// `(-min, max)` as two `f32x4` (lane 3 of each is not a coordinate).
    #[inline(always)]
    pub fn halves(self) -> (f32x4, f32x4) {
        let [lo, hi]: [f32x4; 2] = bytemuck::cast(self.0);
        (lo, hi)
    }

    /// Half the surface area, 0 for an empty (or NaN) box.
    #[cfg(test)]
    pub fn half_area(self) -> f32 {
        let (nlo, hi) = self.halves();
        let d = (hi + nlo).to_array();
        if d[0] >= 0.0 && d[1] >= 0.0 && d[2] >= 0.0 {
            d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
        } else {
            0.0
        }
    }

    /// Half the surface area of a box that is not empty (branch-free; an empty box gives +inf).
    #[inline(always)]
    pub fn half_area_nonempty(self) -> f32 {
        let (nlo, hi) = self.halves();
        let d: glam::Vec3A = bytemuck::cast(hi + nlo);
        // dx dy + dy dz + dz dx; the fourth lane is ignored.
        d.dot(glam::Vec3Swizzles::yzx(d))
    }

    /// Flips lanes 0..3 between `-min` and `min` (the other lanes are left as they are).
    #[inline(always)]
    fn flip_low(v: f32x8) -> f32x8 {
        const S: f32 = -0.0;
        v ^ f32x8::new([S, S, S, 0.0, 0.0, 0.0, 0.0, 0.0])
    }

    /// A [`Node`] with this box (lanes: `min`, index, `max`, count).
    #[inline(always)]
    pub fn to_node(self, index: u32, count: u32) -> Node {
        let mut n: Node = bytemuck::cast(Self::flip_low(self.0));
        n.index = index;
        n.count = count;
        n
    }

    /// The box of a [`Node`].
    #[inline(always)]
    pub fn from_node(n: &Node) -> Self {
        Self(Self::flip_low(bytemuck::cast(*n)))
    }

    #[cfg(test)]
    pub fn from_aabb(b: &Aabb) -> Self {
        Self(f32x8::new([
            -b.min.x,
            -b.min.y,
            -b.min.z,
            f32::NEG_INFINITY,
            b.max.x,
            b.max.y,
            b.max.z,
            0.0,
        ]))
    }

    #[inline]
    pub fn to_aabb(self) -> Aabb {
        let a = self.0.to_array();
        if a[0] == f32::NEG_INFINITY && a[4] == f32::NEG_INFINITY {
            return Aabb::EMPTY;
        }
        Aabb::new(Vec3::new(-a[0], -a[1], -a[2]), Vec3::new(a[4], a[5], a[6]))
    }
}

/// A primitive reference: its box as a [`Box8`], the primitive index in lane 3 (XOR
/// [`INDEX_XOR`]). 32 bytes; the builders move these around.
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(transparent)]
pub(crate) struct PrimRef(pub f32x8);

impl PrimRef {
    #[cfg(test)]
    pub fn new(b: &Aabb, index: u32) -> Self {
        let idx = f32::from_bits(index ^ INDEX_XOR);
        Self(f32x8::new([
            -b.min.x, -b.min.y, -b.min.z, idx, b.max.x, b.max.y, b.max.z, 0.0,
        ]))
    }

    /// A reference to the box `lo ..= hi` (lanes 0..3) with index `index`.
    #[inline(always)]
    pub fn from_halves(lo: f32x4, hi: f32x4, index: u32) -> Self {
        let mut a: [u32; 8] = bytemuck::cast([-lo, hi]);
        a[3] = index ^ INDEX_XOR;
        a[7] = 0;
        Self(bytemuck::cast(a))
    }

    /// A reference with box `b` (not empty) and index `index`.
    #[inline]
    pub fn from_box(b: Box8, index: u32) -> Self {
        let mut a = b.0.to_array();
        a[3] = f32::from_bits(index ^ INDEX_XOR);
        a[7] = 0.0;
        Self(f32x8::new(a))
    }

    /// This reference with `tag`'s bits in lane 7 (0 in every reference the builders keep; the
    /// LBVH's sort carries codes there for a while).
    #[inline(always)]
    pub fn with_tag(self, tag: u32) -> Self {
        // PERF: a blend in registers. Writing lane 7 through an array moved the reference through
        // general registers and the stack, and the next vector load of it stalled on
        // store-to-load forwarding (the LBVH's bottom-up pass feeds every reference this way).
        let lane7 = f32x8::new([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, f32::from_bits(u32::MAX)]);
        Self(Lane::select(lane7, f32x8::splat(f32::from_bits(tag)), self.0))
    }

    /// The bits of lane 7 (see [`with_tag`](Self::with_tag)).
    #[inline(always)]
    pub fn tag(&self) -> u32 {
        let a: [u32; 8] = bytemuck::cast(self.0);
        a[7]
    }

    /// The primitive index.
    #[inline(always)]
    pub fn index(&self) -> u32 {
        let a: [u32; 8] = bytemuck::cast(self.0);
        a[3] ^ INDEX_XOR
    }

    #[inline(always)]
    pub fn bounds(&self) -> Box8 {
        Box8(self.0)
    }

    /// Twice the centroid, `max + min` (lane 3 is not a coordinate).
    #[inline(always)]
    pub fn c2(&self) -> f32x4 {
        let [nlo, hi]: [f32x4; 2] = bytemuck::cast(self.0);
        hi - nlo
    }

    /// Twice the centroid as a `Vec3` ([`c2`](Self::c2) without its fourth lane).
    #[inline(always)]
    pub fn c2_vec3(&self) -> Vec3 {
        let v = self.c2().to_array();
        Vec3::new(v[0], v[1], v[2])
    }

    /// Twice the centroid's coordinate on `axis` (0..3).
    #[inline(always)]
    pub fn c2_axis(&self, axis: usize) -> f32 {
        let a = self.0.to_array();
        a[4 + (axis & 3)] - a[axis & 3]
    }
}

/// Bounds of doubled centroids (`min + max` of the primitive boxes), lane 3 unused.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CBounds {
    pub lo: f32x4,
    pub hi: f32x4,
}

impl CBounds {
    pub const EMPTY: Self = Self {
        lo: f32x4::new([f32::INFINITY; 4]),
        hi: f32x4::new([f32::NEG_INFINITY; 4]),
    };

    #[inline(always)]
    pub fn grow(&mut self, c2: f32x4) {
        self.lo = c2.min_l(self.lo);
        self.hi = c2.max_l(self.hi);
    }

    /// Extent per axis (lane 3 meaningless).
    #[inline(always)]
    pub fn extent(&self) -> [f32; 4] {
        (self.hi - self.lo).to_array()
    }

    /// The axis of largest extent (ties: lowest), and that extent (`<= 0` when all centroids
    /// coincide on every axis).
    #[inline]
    pub fn longest_axis(&self) -> (usize, f32) {
        let e = self.extent();
        let mut a = 0;
        if e[1] > e[a] {
            a = 1;
        }
        if e[2] > e[a] {
            a = 2;
        }
        (a, e[a])
    }

    /// As an [`Aabb`] (in doubled-centroid space).
    pub fn to_aabb(self) -> Aabb {
        let (lo, hi) = (self.lo.to_array(), self.hi.to_array());
        Aabb::new(Vec3::new(lo[0], lo[1], lo[2]), Vec3::new(hi[0], hi[1], hi[2]))
    }
}

/// What [`prepare`] learns about the input besides the references themselves.
pub(crate) struct PrepInfo {
    /// The joint box of the valid primitives.
    pub bounds: Box8,
    /// Bounds of their doubled centroids.
    pub cbounds: CBounds,
    /// Primitives left out.
    pub invalid: u32,
    /// Total primitives, valid or not (primitive indices are below this).
    pub total: usize,
}

/// Most primitives a build accepts: node indices (`2 n - 1` nodes) must fit in a `u32`.
///
/// ```
/// use strahl::{Aabb, build::{BuildError, BuildParams, Bvh2, MAX_PRIMITIVES, Primitives}};
/// struct TooMany;
/// impl Primitives for TooMany {
///     fn prim_count(&self) -> usize { MAX_PRIMITIVES + 1 }
///     fn prim_bounds(&self, _: usize) -> Option<Aabb> { None }
/// }
/// let err = Bvh2::build(&TooMany, &BuildParams::default()).unwrap_err();
/// assert_eq!(err, BuildError::TooManyPrimitives { count: MAX_PRIMITIVES + 1 });
/// assert!(2 * MAX_PRIMITIVES - 1 <= u32::MAX as usize); // every node index fits
/// ```
pub const MAX_PRIMITIVES: usize = (1 << 31) - 1;

/// Fills `refs` with references to the valid primitives of `prims` (one pass; `refs` keeps its
/// capacity from earlier builds).
pub(crate) fn prepare<P: Primitives + ?Sized>(prims: &P, refs: &mut Vec<PrimRef>) -> Result<PrepInfo, BuildError> {
    let total = prims.prim_count();
    if total > MAX_PRIMITIVES {
        return Err(BuildError::TooManyPrimitives { count: total });
    }
    refs.clear();
    refs.reserve(total);
    let mut bounds = Box8::EMPTY;
    let mut cbounds = CBounds::EMPTY;
    for i in 0..total {
        let Some(r) = prim_ref(prims, i) else { continue };
        bounds.grow(r.bounds());
        cbounds.grow(r.c2());
        refs.push(r);
    }
    Ok(PrepInfo {
        bounds,
        cbounds,
        invalid: (total - refs.len()) as u32,
        total,
    })
}

/// The reference to primitive `i`, or `None` if it is invalid (a box that is not finite, or
/// inverted).
#[inline(always)]
fn prim_ref<P: Primitives + ?Sized>(prims: &P, i: usize) -> Option<PrimRef> {
    // `usable_bounds` in four lanes: extent `d >= 0`, and `d` and `min + max` finite
    // (`x * 0 == 0` only for finite `x`; NaN fails every comparison). Finite `d` and
    // `min + max` imply finite bounds.
    // PERF: about twice as fast as the scalar checks (measured in `prepare` on the 1M soup).
    let b = prims.prim_bounds(i)?;
    // `+ 0.0` turns -0.0 into +0.0 (and nothing else): the bounds of nodes are unions of these,
    // and a union keeps whichever of two equal zeros it met first, so with two signs of zero a
    // node's box could depend on the order of the unions (the parallel builds sum bins in
    // another order than the sequential ones).
    let lo = f32x4::new([b.min.x, b.min.y, b.min.z, 0.0]) + f32x4::ZERO;
    let hi = f32x4::new([b.max.x, b.max.y, b.max.z, 0.0]) + f32x4::ZERO;
    let (d, c2) = (hi - lo, hi + lo);
    let ok = d.ge(f32x4::ZERO) & (d * f32x4::ZERO).eq(f32x4::ZERO) & (c2 * f32x4::ZERO).eq(f32x4::ZERO);
    (ok.bitmask() & 7 == 7).then(|| PrimRef::from_halves(lo, hi, i as u32))
}

/// Inputs below this many primitives per thread are prepared on the calling thread.
#[cfg(feature = "std")]
const PREP_CHUNK: usize = 32_768;

/// [`prepare`] on up to `threads` threads (`std`): the primitives in equal chunks, each chunk's
/// valid references written to the front of its part of `refs`, then closed up in order. The
/// same references in the same order as [`prepare`]; the bounds are the same unions.
#[cfg(feature = "std")]
pub(crate) fn prepare_par<P: Primitives + Sync + ?Sized>(
    prims: &P,
    refs: &mut Vec<PrimRef>,
    threads: usize,
) -> Result<PrepInfo, BuildError> {
    use core::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let total = prims.prim_count();
    let chunks = threads.min(total / PREP_CHUNK);
    if total > MAX_PRIMITIVES || chunks < 2 {
        return prepare(prims, refs);
    }
    // NOTE: not cleared first: a rebuild over as many primitives writes nothing here.
    refs.resize(total, PrimRef(Default::default()));
    let chunk = total.div_ceil(chunks);
    type Part<'a> = Mutex<Option<(usize, &'a mut [PrimRef])>>;
    let parts: Vec<Part<'_>> = refs
        .chunks_mut(chunk)
        .enumerate()
        .map(|(j, c)| Mutex::new(Some((j * chunk, c))))
        .collect();
    let done: Vec<Mutex<(usize, Box8, CBounds)>> = (0..parts.len())
        .map(|_| Mutex::new((0, Box8::EMPTY, CBounds::EMPTY)))
        .collect();
    let next = AtomicUsize::new(0);
    crate::par::each(0..chunks, |_| {
        loop {
            let j = next.fetch_add(1, Ordering::Relaxed);
            let Some(part) = parts.get(j) else { break };
            let Some((start, out)) = part.lock().ok().and_then(|mut g| g.take()) else {
                continue;
            };
            let (mut k, mut bounds, mut cbounds) = (0, Box8::EMPTY, CBounds::EMPTY);
            for i in start..start + out.len() {
                let Some(r) = prim_ref(prims, i) else { continue };
                bounds.grow(r.bounds());
                cbounds.grow(r.c2());
                out[k] = r;
                k += 1;
            }
            if let Ok(mut g) = done[j].lock() {
                *g = (k, bounds, cbounds);
            }
        }
    });
    drop(parts);
    let (mut at, mut bounds, mut cbounds) = (0, Box8::EMPTY, CBounds::EMPTY);
    for (j, d) in done.into_iter().enumerate() {
        let (k, b, cb) = d.into_inner().unwrap_or((0, Box8::EMPTY, CBounds::EMPTY));
        refs.copy_within(j * chunk..j * chunk + k, at);
        at += k;
        bounds.grow(b);
        cbounds.lo = cb.lo.min_l(cbounds.lo);
        cbounds.hi = cb.hi.max_l(cbounds.hi);
    }
    refs.truncate(at);
    Ok(PrepInfo {
        bounds,
        cbounds,
        invalid: (total - at) as u32,
        total,
    })
}

/// `ceil(log2(n))` for `n >= 1` (0 for `n <= 1`).
#[inline]
pub(crate) fn ceil_log2(n: u32) -> u32 {
    if n <= 1 { 0 } else { 32 - (n - 1).leading_zeros() }
}

/// `true` if a node at `depth` may get children holding `nl` and `nr` primitives: each child must
/// still be finishable as a balanced subtree within `max_depth` (the invariant
/// `depth + ceil(log2 N) <= max_depth` that every node of the builders keeps).
#[inline]
pub(crate) fn depth_ok(depth: u32, nl: u32, nr: u32, max_depth: u32) -> bool {
    depth + 1 + ceil_log2(nl.max(nr)) <= max_depth
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prim_ref_round_trips() {
        let b = Aabb::new(Vec3::new(-1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.5));
        for idx in [0, 1, 7, 1 << 23, (1 << 31) - 2, u32::MAX] {
            let r = PrimRef::new(&b, idx);
            assert_eq!(r.index(), idx);
            assert_eq!(r.bounds().to_aabb(), b);
            assert_eq!(&r.c2().to_array()[..3], &[3.0, 7.0, 9.5]);
            assert_eq!(r.c2_axis(2), 9.5);
        }
        assert_eq!(Box8::EMPTY.half_area(), 0.0);
        assert!(Box8::EMPTY.to_aabb().is_empty());
        assert_eq!(Box8::from_aabb(&b).half_area(), b.half_area());
        let n = Box8::from_aabb(&b).to_node(7, 3);
        assert_eq!(n, Node::leaf(&b, 7, 3));
        assert_eq!(Box8::from_node(&n).to_aabb(), b);
    }

    #[test]
    fn ceil_log2_table() {
        let want = [
            (0, 0),
            (1, 0),
            (2, 1),
            (3, 2),
            (4, 2),
            (5, 3),
            (1 << 31, 31),
            (u32::MAX, 32),
        ];
        for (n, l) in want {
            assert_eq!(ceil_log2(n), l, "{n}");
        }
    }

    #[test]
    fn prepare_keeps_exactly_the_usable_boxes() {
        let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let (inf, nan, big) = (f32::INFINITY, f32::NAN, f32::MAX);
        let boxes = [
            Aabb::new(v(0.0, 0.0, 0.0), v(1.0, 2.0, 3.0)),
            Aabb::new(v(1.0, 0.0, 0.0), v(0.0, 1.0, 1.0)), // empty on x
            Aabb::new(v(0.0, 0.0, 0.0), v(0.0, 0.0, 0.0)), // a point
            Aabb::new(v(0.0, nan, 0.0), v(1.0, 1.0, 1.0)),
            Aabb::new(v(0.0, 0.0, 0.0), v(1.0, 1.0, inf)),
            Aabb::new(v(-inf, 0.0, 0.0), v(1.0, 1.0, 1.0)),
            Aabb::new(v(-big, 0.0, 0.0), v(big, 1.0, 1.0)), // extent overflows
            Aabb::new(v(big, 0.0, 0.0), v(big, 1.0, 1.0)),  // centre overflows
            Aabb::new(v(-0.0, -1e-40, 5.0), v(0.0, 1e-40, 5.0)),
            Aabb::new(v(-big, -big, -big), v(0.0, 0.0, 0.0)),
        ];
        let mut refs = Vec::new();
        let info = prepare(&boxes[..], &mut refs).unwrap();
        let want: Vec<u32> = (0..boxes.len() as u32)
            .filter(|&i| usable_bounds(&boxes[..], i as usize).is_some())
            .collect();
        assert_eq!(refs.iter().map(PrimRef::index).collect::<Vec<_>>(), want);
        assert_eq!(want, [0, 2, 8, 9]);
        assert_eq!(info.invalid, 6);
        for r in &refs {
            let i = r.index() as usize;
            assert_eq!(r.bounds().to_aabb(), boxes[i]);
            assert_eq!(r.tag(), 0);
            assert_eq!(r.with_tag(77).tag(), 77);
            // Every other lane keeps its bits, whatever the tag's bits are as a float (NaN too).
            for tag in [0, 77, u32::MAX, 0x7fc0_0001, 0x8000_0000] {
                let t: [u32; 8] = bytemuck::cast(r.with_tag(tag).0);
                let mut want: [u32; 8] = bytemuck::cast(r.0);
                want[7] = tag;
                assert_eq!(t, want);
            }
        }
    }
}
