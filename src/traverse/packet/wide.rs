//! Packet walks of wide BVHs, generic over the ray lanes `R` (`K = R::N` rays): the masked walk
//! with the single-ray hybrid, and the interval walk of coherent packets.

use super::leaf::{Leaves, any_rays, closest_rays};
use super::stack::{Entry, MaskStack};
use crate::geometry::{Hit, Ray};
use crate::intersect::aabb::FAR_SLACK;
use crate::intersect::{PreparedPacket, PreparedRay};
use crate::layout::{BvhWideRef, EMPTY_CHILD, LEAF_BIT, MAX_WIDE_DEPTH, leaf_packs};
use crate::math::Lane;
use crate::traverse::wide::{intersect_filtered_by, intersect_from_filtered, occluded_from_filtered};
use crate::traverse::{HitFilter, TriangleTest, prepare};

/// Stack entries: enough for `MAX_WIDE_DEPTH` levels of 8-wide nodes.
const STACK: usize = MAX_WIDE_DEPTH as usize * 7 + 1;

/// A lane mask per axis: all bits set in the lanes whose direction has its sign bit set, zero
/// elsewhere.
///
/// NOTE: full masks, not `-0.0`: `select` is a sign-bit blend on SSE4.1 and AVX but a bitwise
/// `(m & a) | (!m & b)` on plain SSE2, where a sign-bit-only mask would mix the bits of both
/// planes (found by the `bvh` fuzz target on an SSE2 build: a packet lane missed a hit).
#[inline(always)]
pub(super) fn sign_lanes<R: Lane, const K: usize>(single: &[PreparedRay; K]) -> [R; 3] {
    // The sign of `inv_dir` is the direction's (`neg`); an arithmetic shift spreads it over the
    // lane, without a branch.
    let mut s = [[0f32; K]; 3];
    for (i, r) in single.iter().enumerate() {
        for (axis, inv) in s.iter_mut().zip(r.inv_dir.to_array()) {
            axis[i] = f32::from_bits(((inv.to_bits() as i32) >> 31) as u32);
        }
    }
    [R::load(&s[0]), R::load(&s[1]), R::load(&s[2])]
}

/// The slab test of one box against the `K` rays, lane by lane equal to the single-ray test
/// ([`intersect_aabb_scalar`](crate::intersect::intersect_aabb_scalar)): near and far planes by
/// each lane's sign bits, the same reduction order, the same conservative far bound.
#[inline(always)]
pub(super) fn box_lanes<R: Lane, const K: usize>(
    p: &PreparedPacket<R, K>,
    neg: &[R; 3],
    lo: [f32; 3],
    hi: [f32; 3],
) -> (R, u32) {
    box_slabs(&p.origin, &p.inv_dir, p.tmin, p.tmax, neg, lo, hi)
}

/// [`box_lanes`] on the slab-test lanes alone (what the interval walk keeps of a packet).
#[inline(always)]
fn box_slabs<R: Lane>(
    origin: &[R; 3],
    inv_dir: &[R; 3],
    tmin: R,
    tmax: R,
    neg: &[R; 3],
    lo: [f32; 3],
    hi: [f32; 3],
) -> (R, u32) {
    let mut near = tmin;
    let mut far = tmax;
    for a in (0..3).rev() {
        let (l, h) = (R::splat(lo[a]), R::splat(hi[a]));
        let (n, f) = (neg[a].select(h, l), neg[a].select(l, h));
        near = ((n - origin[a]) * inv_dir[a]).max_l(near);
        far = ((f - origin[a]) * inv_dir[a]).min_l(far);
    }
    let hit = near.le(far + far.abs() * R::splat(FAR_SLACK));
    (near, hit.bitmask())
}

/// A packet's rays as lanes, for the interval walk: origins, flushed directions, reciprocals,
/// `[tmin, tmax)` (invalid rays: `[inf, -inf)`) and the reciprocals' sign masks, bit for bit
/// the fields of [`PreparedRay::new`] in every valid lane. Computed once from the rays by
/// [`root_lanes`] (PERF: transposing them out of `K` prepared rays, with the interval, coherence
/// and activity tests that read them lane by lane, was a fifth of a coherent packet's time).
pub(super) struct Slabs<R> {
    origin: [R; 3],
    direction: [R; 3],
    inv_dir: [R; 3],
    tmin: R,
    tmax: R,
    /// All bits set where `inv_dir` is negative (the near plane is the box's max).
    neg: [R; 3],
}

impl<R: Lane> Slabs<R> {
    /// The lanes whose interval `[tmin, tmax)` is not empty: those of the rays that
    /// [`PreparedRay::new`] does not make [`is_empty`](PreparedRay::is_empty).
    #[inline(always)]
    fn active(&self) -> u32 {
        self.tmin.lt(self.tmax).bitmask()
    }

    /// `true` if the lanes of `active` are coherent enough for interval culling (see the
    /// [module docs](super#wide-bvhs)): the same direction signs, directions within
    /// [`COHERENT_MIN_COS`](super::COHERENT_MIN_COS) of the first lane's, and origins within
    /// [`COHERENT_MAX_ORIGIN_SPREAD`](super::COHERENT_MAX_ORIGIN_SPREAD) of the tree's extent.
    /// The interval walk is exact for any packet, but it visits the union of the lanes' paths:
    /// for rays from scattered origins (diffuse bounces) that is most of the tree. Only speed
    /// depends on the answer.
    #[inline(always)]
    fn coherent<L: Lane, const N: usize>(&self, bvh: BvhWideRef<'_, L, N>, active: u32) -> bool {
        let first = active.trailing_zeros() as usize;
        for n in &self.neg {
            let m = n.bitmask() & active;
            if m != 0 && m != active {
                return false;
            }
        }
        let d = &self.direction;
        let d0 = [d[0].at(first), d[1].at(first), d[2].at(first)].map(R::splat);
        let dot = d[0] * d0[0] + d[1] * d0[1] + d[2] * d0[2];
        let (l0, l) = (
            d0[0] * d0[0] + d0[1] * d0[1] + d0[2] * d0[2],
            d[0] * d[0] + d[1] * d[1] + d[2] * d[2],
        );
        // `cos >= COHERENT_MIN_COS` without square roots: `d.d0 >= 0` and
        // `(d.d0)^2 >= cos^2 |d|^2 |d0|^2`.
        let cos2 = R::splat(super::COHERENT_MIN_COS * super::COHERENT_MIN_COS);
        let close = dot.ge(R::splat(0.0)) & (dot * dot).ge(cos2 * (l0 * l));
        if close.bitmask() & active != active {
            return false;
        }
        let on = R::from_bitmask(active);
        let mut spread = 0f32;
        for o in &self.origin {
            let (lo, hi) = (
                on.select(*o, R::splat(f32::INFINITY)),
                on.select(*o, R::splat(f32::NEG_INFINITY)),
            );
            spread = spread.max(hi.max_lane() - lo.min_lane());
        }
        if spread == 0.0 {
            return true; // one origin (a camera)
        }
        // The tree's extent (0 for an empty tree, where a spread above 0 fails).
        spread <= crate::traverse::wide::root_extent(bvh) * super::COHERENT_MAX_ORIGIN_SPREAD
    }
}

/// The nearest entry distance over the lanes of `mask`.
#[inline(always)]
pub(super) fn hit_min<R: Lane, const K: usize>(near: R, mask: u32) -> f32 {
    let mut n = [0f32; K];
    near.store(&mut n);
    let mut d = f32::INFINITY;
    for (i, &x) in n.iter().enumerate() {
        if mask >> i & 1 == 1 && x < d {
            d = x;
        }
    }
    d
}

/// Lanes that can still hit a box entered no earlier than `dist`: `dist <= tmax + |tmax| FAR_SLACK`.
/// A lane outside this mask fails the slab test with its current `tmax` (its own entry is at least
/// `dist`), so dropping it changes no answer.
#[inline(always)]
pub(super) fn open_lanes<R: Lane>(tmax: R, dist: f32) -> u32 {
    R::splat(dist).le(tmax + tmax.abs() * R::splat(FAR_SLACK)).bitmask()
}

/// The single rays' `tmax` as lanes (after [`closest_rays`] shrank some).
#[inline(always)]
fn tmax_lanes<R: Lane, const K: usize>(single: &[PreparedRay; K]) -> R {
    let mut t = [0f32; K];
    for (t, s) in t.iter_mut().zip(single) {
        *t = s.tmax;
    }
    R::load(&t)
}

/// Copies the packet lanes' `tmax` into the single rays after leaf hits.
#[inline(always)]
fn sync_tmax<R: Lane, const K: usize>(packet: &PreparedPacket<R, K>, single: &mut [PreparedRay; K]) {
    let mut t = [0f32; K];
    packet.tmax.store(&mut t);
    for (s, t) in single.iter_mut().zip(t) {
        s.tmax = t;
    }
}

/// The rows of up to `K` rays (`origin`, `tmin`, `direction`, `tmax`) as lanes; lanes past
/// `rays` get an invalid ray (NaN origin, direction 1, interval `[0, 0]`).
#[inline(always)]
fn ray_lanes<R: Lane, const K: usize>(rays: &[Ray]) -> [R; 8] {
    if rays.len() >= K {
        R::transpose8(bytemuck::cast_slice::<Ray, [f32; 8]>(&rays[..K]))
    } else {
        let mut rows = [[f32::NAN, f32::NAN, f32::NAN, 0.0, 1.0, 1.0, 1.0, 0.0]; K];
        for (row, r) in rows.iter_mut().zip(rays) {
            *row = bytemuck::cast(*r);
        }
        R::transpose8(&rows)
    }
}

/// The lanes of up to `K` rays whose slab test, as single-ray traversal runs it at the root,
/// enters one of the root's children; `0` for an empty tree. Computed for all lanes at once from
/// the rays themselves (the same flushed direction, reciprocal, interval and validity as
/// [`PreparedRay::new`]), so that a packet that misses the scene, as most primary rays of a
/// small object do, costs one pass of lane arithmetic and no per-ray setup.
#[inline(always)]
pub(super) fn root_lanes<L: Lane, const N: usize, R: Lane, const K: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
) -> (u32, Slabs<R>) {
    let (valid, lanes) = lanes_of::<R, K>(rays);
    let (tmin, tmax) = (lanes.tmin, lanes.tmax);
    let Some(root) = bvh.nodes.first() else {
        return (0, lanes);
    };
    let (mut lo, mut hi) = ([[0f32; N]; 3], [[0f32; N]; 3]);
    for a in 0..3 {
        root.bounds.min[a].store(&mut lo[a]);
        root.bounds.max[a].store(&mut hi[a]);
    }
    let mut enter = 0u32;
    for (c, &child) in root.child.iter().enumerate() {
        if child != EMPTY_CHILD {
            let b = |v: &[[f32; N]; 3]| [v[0][c], v[1][c], v[2][c]];
            enter |= box_slabs(&lanes.origin, &lanes.inv_dir, tmin, tmax, &lanes.neg, b(&lo), b(&hi)).1;
        }
    }
    (
        enter & valid.bitmask() & ((1u64 << rays.len().min(K)) - 1) as u32,
        lanes,
    )
}

/// The lanes of up to `K` rays as single-ray traversal prepares them, and the mask of valid
/// lanes (as a lane mask): the first half of [`root_lanes`].
#[inline(always)]
fn lanes_of<R: Lane, const K: usize>(rays: &[Ray]) -> (R, Slabs<R>) {
    // Rays to lanes, transposed in registers; lanes past `rays` are invalid (a NaN origin).
    let [ox, oy, oz, tmin, dx, dy, dz, tmax] = ray_lanes::<R, K>(rays);
    let (origin, raw) = ([ox, oy, oz], [dx, dy, dz]);
    let (zero, inf) = (R::splat(0.0), R::splat(f32::INFINITY));
    // Valid (`Ray::is_valid`, the flushed direction not zero): finite origin and direction,
    // no NaN bound.
    let mut valid = tmin.eq(tmin) & tmax.eq(tmax);
    let mut moving = zero.ne(zero);
    let (mut inv, mut flushed) = ([zero; 3], [zero; 3]);
    for a in 0..3 {
        // Subnormal components flushed to a zero of their sign, as `PreparedRay::new` does.
        flushed[a] = raw[a]
            .abs()
            .lt(R::splat(f32::MIN_POSITIVE))
            .select(zero.xor_sign(raw[a]), raw[a]);
        valid = valid & origin[a].abs().lt(inf) & raw[a].abs().lt(inf);
        moving = moving | flushed[a].ne(zero);
        inv[a] = R::splat(1.0) / flushed[a];
    }
    let valid = valid & moving;
    // `tmin` no lower than `-f32::MAX`, as `PreparedRay::new` takes it.
    let tmin = tmin.max_l(R::splat(-f32::MAX));
    let (tmin, tmax) = (valid.select(tmin, inf), valid.select(tmax, R::splat(f32::NEG_INFINITY)));
    // Full lane masks of the reciprocal's sign (what `neg` holds); invalid lanes miss anyway.
    let neg = inv.map(|v| v.lt(zero));
    (
        valid,
        Slabs {
            origin,
            direction: flushed,
            inv_dir: inv,
            tmin,
            tmax,
            neg,
        },
    )
}

/// A packet of up to 8 rays walking a 4-wide tree of boxes (the instances' TLAS): its lanes as
/// single-ray traversal prepares them, each lane's current `tmax`, and, where every active lane
/// has the same direction signs, the packet's bounding interval, so that a node's four boxes are
/// culled with one interval test for the whole packet (Wald, Boulos and Shirley 2007) instead of
/// one slab test per lane.
#[cfg(feature = "alloc")]
pub(crate) struct BoxPacket {
    p: Slabs<crate::math::f32x8>,
    active: u32,
    /// `Some` where the active lanes share direction signs: the interval, its sign per axis
    /// and where a reciprocal is infinite (see [`product_lo`]).
    iv: Option<(Interval, [bool; 3], [bool; 3])>,
}

#[cfg(feature = "alloc")]
impl BoxPacket {
    /// The packet of `rays` (at most 8; lanes past them, and invalid rays, are inactive).
    #[inline(always)]
    pub(crate) fn new(rays: &[Ray]) -> Self {
        let (_, p) = lanes_of::<crate::math::f32x8, 8>(rays);
        let active = p.active() & ((1u32 << rays.len().min(8)) - 1);
        let mut b = Self { p, active, iv: None };
        if active != 0 {
            let first = active.trailing_zeros();
            let mut same = true;
            for n in &b.p.neg {
                let m = n.bitmask() & active;
                same &= m == 0 || m == active;
            }
            if same {
                let iv = Interval::new(&b.p, active);
                let neg = b.p.neg.map(|n| n.bitmask() >> first & 1 != 0);
                let guard = iv.inv.map(|(b0, b1)| b0.is_infinite() || b1.is_infinite());
                b.iv = Some((iv, neg, guard));
            }
        }
        b
    }

    /// The lanes still open: with a ray, not retired.
    #[inline(always)]
    pub(crate) fn active(&self) -> u32 {
        self.active
    }

    /// Lane `l`'s `tmax` (its closest hit so far).
    #[inline(always)]
    pub(crate) fn tmax(&self, l: usize) -> f32 {
        self.p.tmax.at(l)
    }

    /// Sets the `tmax` of the lanes of `lanes` to `t` (a closer hit found).
    #[inline(always)]
    pub(crate) fn set_tmax(&mut self, lanes: u32, t: &[f32; 8]) {
        use crate::math::f32x8;
        self.p.tmax = f32x8::from_bitmask(lanes).select(f32x8::load(t), self.p.tmax);
        self.refresh();
    }

    /// Retires the lanes of `lanes` (answered: blocked).
    #[inline(always)]
    pub(crate) fn retire(&mut self, lanes: u32) {
        self.active &= !lanes;
        self.refresh();
    }

    /// The interval's `tmax` after a lane's changed.
    #[inline(always)]
    fn refresh(&mut self) {
        use crate::math::f32x8;
        if let Some((iv, _, _)) = self.iv.as_mut() {
            iv.tmax = f32x8::from_bitmask(self.active)
                .select(self.p.tmax, f32x8::splat(f32::NEG_INFINITY))
                .max_lane();
        }
    }

    /// A node's four child boxes against the lanes of `lanes`: per child, the lanes that may
    /// enter it and a distance no larger than any of theirs. With the interval, every lane of
    /// `lanes` for each inner child the interval enters (conservative: a superset of the lanes'
    /// own slab tests), and for the children of `leaves` (bit per slot) that the interval
    /// enters, each lane's single-ray slab test, so that a lane reaches a leaf exactly where its
    /// own walk would; without the interval, each lane's slab test for every child.
    #[inline(always)]
    pub(crate) fn children(
        &self,
        b: &crate::intersect::AabbLanes<crate::math::f32x4>,
        lanes: u32,
        leaves: u32,
    ) -> ([u32; 4], [f32; 4]) {
        use crate::math::f32x4;
        let mut masks = [0u32; 4];
        let mut dist = [f32::INFINITY; 4];
        if let Some((iv, neg, guard)) = &self.iv {
            let slack = f32x4::splat(FAR_SLACK);
            let mut near = f32x4::splat(iv.tmin);
            let mut far = f32x4::splat(iv.tmax);
            for a in 0..3 {
                let (entry, exit) = if neg[a] {
                    (b.max[a], b.min[a])
                } else {
                    (b.min[a], b.max[a])
                };
                let (o0, o1) = (f32x4::splat(iv.o[a].0), f32x4::splat(iv.o[a].1));
                let (b0, b1) = iv.inv[a];
                near = product_lo(entry - o1, entry - o0, b0, b1, guard[a]).max_l(near);
                far = product_hi(exit - o1, exit - o0, b0, b1, guard[a]).min_l(far);
            }
            let lo = near - near.abs() * slack;
            let hit = lo.le(far + far.abs() * slack).bitmask() & 0xf;
            lo.store(&mut dist);
            for (c, m) in masks.iter_mut().enumerate() {
                if hit >> c & 1 != 0 {
                    *m = lanes;
                }
            }
            if hit & leaves == 0 {
                return (masks, dist);
            }
        }
        let (mut lo, mut hi) = ([[0f32; 4]; 3], [[0f32; 4]; 3]);
        for a in 0..3 {
            b.min[a].store(&mut lo[a]);
            b.max[a].store(&mut hi[a]);
        }
        for c in 0..4 {
            if self.iv.is_some() && (masks[c] == 0 || leaves >> c & 1 == 0) {
                continue;
            }
            let at = |v: &[[f32; 4]; 3]| [v[0][c], v[1][c], v[2][c]];
            let (near, m) = box_slabs(
                &self.p.origin,
                &self.p.inv_dir,
                self.p.tmin,
                self.p.tmax,
                &self.p.neg,
                at(&lo),
                at(&hi),
            );
            masks[c] = m & lanes;
            if masks[c] != 0 {
                dist[c] = hit_min::<crate::math::f32x8, 8>(near, masks[c]);
            }
        }
        (masks, dist)
    }
}

/// `true` if the hybrid will send these rays to single-ray traversal at the root whatever they
/// hit: their directions' signs differ (so [`coherent`] fails) and there are fewer than `switch`.
/// Such packets (diffuse bounces, shadow rays from scattered points) go to single rays at once,
/// without the packet's setup or [`root_lanes`], which would cost them time and save none. Only
/// speed depends on it: every path answers as single rays do.
#[inline(always)]
fn to_singles(rays: &[Ray], switch: u32) -> bool {
    let signs = |r: &Ray| r.direction.is_negative_bitmask();
    let first = rays.first().map_or(0, signs);
    (rays.len() as u32) < switch && rays.iter().any(|r| signs(r) != first)
}

/// Prepares up to `K` rays into `single` (its lanes past `rays` are left as they are), with the
/// watertight fields where `watertight` (`PreparedRay::new_for`, hidden from the docs).
#[inline(always)]
pub(super) fn prepare_into<const K: usize>(rays: &[Ray], single: &mut [PreparedRay; K], watertight: bool) {
    for (s, r) in single.iter_mut().zip(rays) {
        *s = PreparedRay::new_for(r, watertight);
    }
}

/// How a packet starts, decided once for [`intersect`] and [`occluded`].
enum Start<R> {
    /// The hybrid's answer at the root, without the packet's setup: every ray as a single ray.
    Singles,
    /// No lane enters the scene (or none has a ray): every answer is a miss.
    Miss,
    /// The rays are in `lanes`, and prepared into the caller's array unless `coherent` (the
    /// interval walk prepares them where it needs them): the lanes with a ray (`active`), and
    /// whether they are [`coherent`](Slabs::coherent).
    Prepared {
        active: u32,
        coherent: bool,
        lanes: Slabs<R>,
    },
}

/// PERF: the prepared rays go to the caller's array, not out in the enum: returning them by
/// value cost a 704-byte `memcpy` per packet.
#[inline(always)]
fn start<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    switch: u32,
    single: &mut [PreparedRay; K],
) -> Start<R> {
    if to_singles(rays, switch) {
        return Start::Singles;
    }
    // `root_lanes` is 0 for an empty tree too.
    let (enter, lanes) = root_lanes::<L, N, R, K>(bvh, rays);
    let active = lanes.active();
    if enter == 0 || active == 0 {
        return Start::Miss;
    }
    let coherent = lanes.coherent(bvh, active);
    if !coherent {
        // The masked walk and the hybrid's single rays start from prepared rays; the interval
        // walk prepares them only where it needs them.
        prepare_into(rays, single, T::WATERTIGHT);
    }
    Start::Prepared {
        active,
        coherent,
        lanes,
    }
}

/// `dst = src[..dst.len()]`, with a fixed-size copy for a full packet (the common case) instead
/// of a `memcpy` call.
#[inline(always)]
fn copy_out<T: Copy, const K: usize>(dst: &mut [T], src: &[T; K]) {
    if let Ok(d) = <&mut [T; K]>::try_from(&mut *dst) {
        *d = *src;
    } else {
        dst.copy_from_slice(&src[..dst.len()]);
    }
}

/// Closest hits of up to `K` rays that `f` accepts (see
/// [`intersect_packet_filtered`](super::intersect_packet_filtered)).
pub(super) fn intersect<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    switch: u32,
    f: &mut F,
) {
    let n = rays.len().min(hits.len()).min(K);
    let mut single = [PreparedRay::EMPTY; K];
    let (active, coherent, lanes) = match start::<T, L, N, R, K>(bvh, &rays[..n], switch, &mut single) {
        Start::Singles => {
            for (h, r) in hits[..n].iter_mut().zip(rays) {
                *h = intersect_filtered_by::<T, L, N, F>(bvh, r, f);
            }
            return;
        }
        Start::Miss => {
            // PERF: a copy, not `fill(None)`: LLVM turned the fill (one tag every 20 bytes)
            // into an AVX-512 scatter, 7% of the time of packets that miss (AMD EPYC).
            copy_out(&mut hits[..n], &[None; K]);
            return;
        }
        Start::Prepared {
            active,
            coherent,
            lanes,
        } => (active, coherent, lanes),
    };
    let mut best: [Option<Hit>; K] = [None; K];
    if !coherent && active.count_ones() < switch {
        // Hybrid at the root: single rays, without building the packet.
        let mut m = active;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            best[i] = intersect_from_filtered::<T, L, N, F>(bvh, 0, &mut single[i], f);
        }
    } else if coherent {
        walk_interval::<T, L, N, R, K, false, F>(bvh, lanes, &rays[..n], &mut single, &mut best, active, f);
    } else {
        masked_walk::<T, L, N, R, K, false, F>(bvh, &lanes.neg, &mut single, &mut best, active, switch, f);
    }
    copy_out(&mut hits[..n], &best);
}

/// Any-hit answers of up to `K` rays counting the hits `f` accepts (see
/// [`occluded_packet_filtered`](super::occluded_packet_filtered)).
pub(super) fn occluded<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    rays: &[Ray],
    occluded: &mut [bool],
    switch: u32,
    f: &mut F,
) {
    let n = rays.len().min(occluded.len()).min(K);
    let mut single = [PreparedRay::EMPTY; K];
    let (active, coherent, lanes) = match start::<T, L, N, R, K>(bvh, &rays[..n], switch, &mut single) {
        Start::Singles => {
            for (o, r) in occluded[..n].iter_mut().zip(rays) {
                *o = occluded_from_filtered::<T, L, N, F>(bvh, 0, &prepare::<T>(r), f);
            }
            return;
        }
        Start::Miss => {
            occluded[..n].fill(false);
            return;
        }
        Start::Prepared {
            active,
            coherent,
            lanes,
        } => (active, coherent, lanes),
    };
    let mut mask = 0u32;
    if !coherent && active.count_ones() < switch {
        let mut m = active;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            if occluded_from_filtered::<T, L, N, F>(bvh, 0, &single[i], f) {
                mask |= 1 << i;
            }
        }
    } else if coherent {
        mask = walk_interval::<T, L, N, R, K, true, F>(bvh, lanes, &rays[..n], &mut single, &mut [None; K], active, f);
    } else {
        let mut best = [None; K];
        mask = masked_walk::<T, L, N, R, K, true, F>(bvh, &lanes.neg, &mut single, &mut best, active, switch, f);
    }
    for (i, o) in occluded[..n].iter_mut().enumerate() {
        *o = mask >> i & 1 == 1;
    }
}

/// The masked walk of prepared rays (incoherent packets with at least `switch` lanes), with the
/// sign masks of the root test's lanes (the prepared rays' signs, full lane masks in every lane).
/// Returns the occluded lanes (`ANY`) or 0.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn masked_walk<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize, const ANY: bool, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    neg: &[R; 3],
    single: &mut [PreparedRay; K],
    best: &mut [Option<Hit>; K],
    active: u32,
    switch: u32,
    filter: &mut F,
) -> u32 {
    let mut packet = PreparedPacket::<R, K>::from_prepared(single);
    let mut leaves = Leaves::<R, K>::new(single);
    Walk {
        packet: &mut packet,
        neg,
        single,
        lanes: &mut leaves,
        best,
        filter,
    }
    .run::<T, L, N, ANY>(bvh, active, switch)
}

/// The state of one masked walk: the packet, its sign lanes, the same rays as single rays (for the
/// hybrid), the leaf kernels' hit lanes, the closest hits so far and the hit filter.
struct Walk<'a, R, const K: usize, F> {
    packet: &'a mut PreparedPacket<R, K>,
    neg: &'a [R; 3],
    single: &'a mut [PreparedRay; K],
    lanes: &'a mut Leaves<R, K>,
    best: &'a mut [Option<Hit>; K],
    filter: &'a mut F,
}

impl<R: Lane, const K: usize, F: HitFilter> Walk<'_, R, K, F> {
    /// Finishes the lanes of `mask` below `code` as single rays; returns the lanes found occluded
    /// (`ANY`) or 0.
    #[inline(never)]
    fn singles<T: TriangleTest, L: Lane, const N: usize, const ANY: bool>(
        &mut self,
        bvh: BvhWideRef<'_, L, N>,
        code: u32,
        mut mask: u32,
    ) -> u32 {
        let mut occluded = 0;
        while mask != 0 {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if ANY {
                if occluded_from_filtered::<T, L, N, F>(bvh, code, &self.single[i], self.filter) {
                    occluded |= 1 << i;
                }
            } else if let Some(h) = intersect_from_filtered::<T, L, N, F>(bvh, code, &mut self.single[i], self.filter) {
                self.best[i] = Some(h);
            }
        }
        if !ANY {
            let t: [f32; K] = core::array::from_fn(|i| self.single[i].tmax);
            self.packet.tmax = R::load(&t);
        }
        occluded
    }

    /// Walks the tree with per-lane masks; where fewer than `switch` lanes enter a node they finish
    /// its subtree as single rays. Returns the occluded lanes (`ANY`) or 0.
    fn run<T: TriangleTest, L: Lane, const N: usize, const ANY: bool>(
        &mut self,
        bvh: BvhWideRef<'_, L, N>,
        mut active: u32,
        switch: u32,
    ) -> u32 {
        let mut occluded = 0u32;
        let mut stack = MaskStack::<STACK>::new();
        let mut cur = Entry {
            code: 0,
            dist: f32::NEG_INFINITY,
            mask: active,
        };
        // A valid tree visits each node and leaf at most once per packet.
        let mut budget = bvh.nodes.len().saturating_mul(N + 1).saturating_add(1);
        loop {
            let Entry { code, mask, .. } = cur;
            if budget == 0 {
                // Only a malformed view (a cycle) or a stack overflow gets here: finish every
                // lane still active as a single ray from the root (exact for a valid tree).
                return occluded | self.singles::<T, L, N, ANY>(bvh, 0, active);
            }
            budget -= 1;
            if mask.count_ones() < switch {
                // Hybrid: the few rays left finish this subtree alone.
                let hit = self.singles::<T, L, N, ANY>(bvh, code, mask);
                if ANY && hit != 0 {
                    occluded |= hit;
                    active &= !hit;
                    if active == 0 {
                        return occluded;
                    }
                    self.retire(active);
                }
            } else if code & LEAF_BIT == 0 {
                if let Some(node) = bvh.nodes.get(code as usize) {
                    let mut lo = [[0f32; N]; 3];
                    let mut hi = [[0f32; N]; 3];
                    for a in 0..3 {
                        node.bounds.min[a].store(&mut lo[a]);
                        node.bounds.max[a].store(&mut hi[a]);
                    }
                    let base = stack.len();
                    for (c, &child) in node.child.iter().enumerate() {
                        if child == EMPTY_CHILD {
                            continue;
                        }
                        let (near, hit) = box_lanes(
                            self.packet,
                            self.neg,
                            [lo[0][c], lo[1][c], lo[2][c]],
                            [hi[0][c], hi[1][c], hi[2][c]],
                        );
                        let hit = hit & mask;
                        if hit != 0 {
                            crate::traverse::wide::prefetch(bvh, child);
                            // Order children by the nearest entry of any lane.
                            let e = Entry {
                                code: child,
                                dist: hit_min::<R, K>(near, hit),
                                mask: hit,
                            };
                            if !stack.push_sorted(base, e) {
                                budget = 0; // NOTE: unreachable within MAX_WIDE_DEPTH
                                break;
                            }
                        }
                    }
                }
            } else if code != EMPTY_CHILD {
                let hit = if F::ACCEPTS_ALL {
                    self.leaf::<T, L, N>(bvh, code, mask)
                } else {
                    self.leaf_filtered::<T, L, N, ANY>(bvh, code, mask)
                };
                if hit != 0 {
                    if ANY {
                        // Any hit: retire the lanes hit; stop when none is left.
                        occluded |= hit;
                        active &= !hit;
                        if active == 0 {
                            return occluded;
                        }
                        self.retire(active);
                    } else if F::ACCEPTS_ALL {
                        // (A filtered leaf has set its lanes' hits and `tmax` itself.)
                        sync_tmax(self.packet, self.single);
                        let mut h = hit;
                        while h != 0 {
                            let i = h.trailing_zeros() as usize;
                            h &= h - 1;
                            self.best[i] = Some(self.lanes.get(i));
                        }
                    }
                }
            }
            if budget == 0 {
                continue;
            }
            // Pop the next entry that some lane can still hit, keeping only those lanes.
            loop {
                match stack.pop() {
                    None => return occluded,
                    Some(e) => {
                        let m = e.mask & active & open_lanes(self.packet.tmax, e.dist);
                        if m != 0 {
                            cur = Entry { mask: m, ..e };
                            break;
                        }
                    }
                }
            }
        }
    }

    /// Retired lanes get an empty interval (`tmax = -inf`): no box or triangle test accepts them.
    #[inline(always)]
    fn retire(&mut self, active: u32) {
        self.packet.tmax = R::from_bitmask(active).select(self.packet.tmax, R::splat(f32::NEG_INFINITY));
    }

    /// Tests the leaf `code` against the lanes of `mask` (the others are masked off for the call);
    /// returns the lanes hit.
    #[inline(always)]
    fn leaf<T: TriangleTest, L: Lane, const N: usize>(
        &mut self,
        bvh: BvhWideRef<'_, L, N>,
        code: u32,
        mask: u32,
    ) -> u32 {
        let (first, count) = leaf_packs(code);
        let Some(packs) = bvh.packs.get(first..first + count) else {
            return 0;
        };
        self.lanes.begin(self.packet, mask);
        let mut hit_any = 0;
        for pack in packs {
            let mut v = pack.valid;
            while v != 0 {
                let j = v.trailing_zeros() as usize;
                v &= v - 1;
                hit_any |= self.lanes.test::<T>(self.packet, &pack.get(j), pack.prim[j]);
            }
        }
        self.lanes.end(self.packet);
        hit_any
    }

    /// [`leaf`](Self::leaf) with a hit filter: each lane of `mask` as a single ray with the
    /// filtered single-ray kernels (the packet kernels test a triangle for all lanes at once, and
    /// commit before a filter could answer). For closest hits, the lanes' hits go to `best` and
    /// their `tmax` to the packet. Returns the lanes hit.
    #[inline(always)]
    fn leaf_filtered<T: TriangleTest, L: Lane, const N: usize, const ANY: bool>(
        &mut self,
        bvh: BvhWideRef<'_, L, N>,
        code: u32,
        mask: u32,
    ) -> u32 {
        let (first, count) = leaf_packs(code);
        let Some(packs) = bvh.packs.get(first..first + count) else {
            return 0;
        };
        if ANY {
            any_rays::<T, L, N, K, F>(packs, self.single, mask, self.filter)
        } else {
            let hit = closest_rays::<T, L, N, K, F>(packs, self.single, self.best, mask, self.filter);
            if hit != 0 {
                self.packet.tmax = tmax_lanes::<R, K>(self.single);
            }
            hit
        }
    }
}

/// The packet's bounding interval: per axis the range of origins and of reciprocal directions
/// over the active lanes, and the union of their `[tmin, tmax)`.
struct Interval {
    o: [(f32, f32); 3],
    inv: [(f32, f32); 3],
    tmin: f32,
    tmax: f32,
}

impl Interval {
    /// The interval of the lanes of `active` (masked reductions in registers).
    #[inline(always)]
    fn new<R: Lane>(p: &Slabs<R>, active: u32) -> Self {
        let on = R::from_bitmask(active);
        let lo = |v: R| on.select(v, R::splat(f32::INFINITY)).min_lane();
        let hi = |v: R| on.select(v, R::splat(f32::NEG_INFINITY)).max_lane();
        Interval {
            o: p.origin.map(|v| (lo(v), hi(v))),
            inv: p.inv_dir.map(|v| (lo(v), hi(v))),
            tmin: lo(p.tmin),
            tmax: hi(p.tmax),
        }
    }
}

/// Lower bound of `[a0, a1] * [b0, b1]` per lane. With `guard` (where `b0` or `b1` is infinite),
/// a NaN product (`0 * inf`: a lane's origin on the plane with a zero direction component) counts
/// as `-inf`, so the bound stays conservative: left as NaN it would drop the other corners from
/// the `min` chain and cull a box some lane enters. Without infinite `b`, no product is NaN.
// PERF: the guard is a branch on a per-packet constant; always fixing the products made coherent
// 8-ray packets 8-17% slower (bunny and 262k sphereflake primary rays, `tests/packet_speed.rs`).
#[inline(always)]
fn product_lo<L: Lane>(a0: L, a1: L, b0: f32, b1: f32, guard: bool) -> L {
    let (b0, b1) = (L::splat(b0), L::splat(b1));
    let (p0, p1, p2, p3) = (a0 * b0, a0 * b1, a1 * b0, a1 * b1);
    if guard {
        let ninf = L::splat(f32::NEG_INFINITY);
        let fix = |p: L| p.eq(p).select(p, ninf);
        fix(p0).min_l(fix(p1)).min_l(fix(p2)).min_l(fix(p3))
    } else {
        p0.min_l(p1).min_l(p2).min_l(p3)
    }
}

/// Upper bound of `[a0, a1] * [b0, b1]` per lane, NaN products counted as `+inf` under `guard`
/// (see [`product_lo`]).
#[inline(always)]
fn product_hi<L: Lane>(a0: L, a1: L, b0: f32, b1: f32, guard: bool) -> L {
    let (b0, b1) = (L::splat(b0), L::splat(b1));
    let (p0, p1, p2, p3) = (a0 * b0, a0 * b1, a1 * b0, a1 * b1);
    if guard {
        let inf = L::splat(f32::INFINITY);
        let fix = |p: L| p.eq(p).select(p, inf);
        fix(p0).max_l(fix(p1)).max_l(fix(p2)).max_l(fix(p3))
    } else {
        p0.max_l(p1).max_l(p2).max_l(p3)
    }
}

/// Coherent packets: children are culled against the packet's interval (Wald, Boulos and Shirley
/// 2007), leaf children against each lane's slab test, and the lanes that enter a leaf test its
/// packs: for closest hits, where at least half the lanes enter and the packet is at least as wide
/// as the packs, each triangle against the whole packet ([`TriangleTest::closest_packet_leaf`]),
/// else each lane with the single-ray x`N` kernel; exact per lane either way, so the answers equal
/// single rays. Returns the occluded lanes (`ANY`) or 0.
#[allow(clippy::too_many_arguments)]
fn walk_interval<T: TriangleTest, L: Lane, const N: usize, R: Lane, const K: usize, const ANY: bool, F: HitFilter>(
    bvh: BvhWideRef<'_, L, N>,
    mut p: Slabs<R>,
    rays: &[Ray],
    single: &mut [PreparedRay; K],
    best: &mut [Option<Hit>; K],
    mut active: u32,
    f: &mut F,
) -> u32 {
    // The rays as single rays, prepared only where a kernel needs them (most coherent packets
    // never do: their leaves take the triangle-major kernel), with the lanes' `tmax` so far.
    // PERF: preparing all `K` up front was 6% of a coherent packet's time.
    let mut ready = false;
    #[inline(always)]
    fn singles<R: Lane, const K: usize>(
        ready: &mut bool,
        watertight: bool,
        rays: &[Ray],
        single: &mut [PreparedRay; K],
        tmax: R,
        active: u32,
    ) {
        if !core::mem::replace(ready, true) {
            prepare_into(rays, single, watertight);
            for (i, s) in single.iter_mut().enumerate() {
                if active >> i & 1 == 1 {
                    s.tmax = tmax.at(i);
                }
            }
        }
    }
    let mut occluded = 0u32;
    let mut iv = Interval::new(&p, active);
    let first = active.trailing_zeros();
    let neg = p.neg.map(|n| n.bitmask() >> first & 1 != 0);
    let slack = L::splat(FAR_SLACK);
    let mut stack = MaskStack::<STACK>::new();
    let mut cur = 0u32;
    // The lanes to test at a leaf: those whose own slab test accepted its box.
    let mut cur_mask = active;
    let mut budget = bvh.nodes.len();
    let widened = |t: f32| t + t.abs() * FAR_SLACK;
    // Axes where some lane's reciprocal direction is infinite: only there can a product be NaN.
    // (Kept when `iv` is recomputed for fewer lanes: a subset adds no infinity.)
    let guard = iv.inv.map(|(b0, b1)| b0.is_infinite() || b1.is_infinite());
    loop {
        if budget == 0 {
            // A malformed view or a stack overflow: finish the active lanes as single rays.
            singles(&mut ready, T::WATERTIGHT, rays, single, p.tmax, active);
            let mut m = active;
            while m != 0 {
                let i = m.trailing_zeros() as usize;
                m &= m - 1;
                if ANY {
                    if occluded_from_filtered::<T, L, N, F>(bvh, 0, &single[i], f) {
                        occluded |= 1 << i;
                    }
                } else if let Some(h) = intersect_from_filtered::<T, L, N, F>(bvh, 0, &mut single[i], f) {
                    best[i] = Some(h);
                }
            }
            return occluded;
        }
        if cur & LEAF_BIT == 0 {
            budget -= 1;
            if let Some(node) = bvh.nodes.get(cur as usize) {
                let mut near = L::splat(iv.tmin);
                let mut far = L::splat(iv.tmax);
                for (a, &negative) in neg.iter().enumerate() {
                    let (entry, exit) = if negative {
                        (node.bounds.max[a], node.bounds.min[a])
                    } else {
                        (node.bounds.min[a], node.bounds.max[a])
                    };
                    let (o0, o1) = (L::splat(iv.o[a].0), L::splat(iv.o[a].1));
                    let (b0, b1) = iv.inv[a];
                    let n_lo = product_lo(entry - o1, entry - o0, b0, b1, guard[a]);
                    let f_hi = product_hi(exit - o1, exit - o0, b0, b1, guard[a]);
                    near = n_lo.max_l(near);
                    far = f_hi.min_l(far);
                }
                // Both bounds widened by the slab test's slack (conservative for every lane).
                let lo = near - near.abs() * slack;
                let mut mask = lo.le(far + far.abs() * slack).bitmask() & ((1u32 << N) - 1);
                if mask != 0 {
                    let mut nears = [0f32; N];
                    lo.store(&mut nears);
                    let (mut bmin, mut bmax) = ([[0f32; N]; 3], [[0f32; N]; 3]);
                    for a in 0..3 {
                        node.bounds.min[a].store(&mut bmin[a]);
                        node.bounds.max[a].store(&mut bmax[a]);
                    }
                    let base = stack.len();
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let child = node.child[i];
                        if child == EMPTY_CHILD {
                            continue;
                        }
                        let lane_mask = if child & LEAF_BIT != 0 {
                            // PERF: a leaf's triangles cost more than one more box test per lane.
                            let b = |v: &[[f32; N]; 3]| [v[0][i], v[1][i], v[2][i]];
                            box_slabs(&p.origin, &p.inv_dir, p.tmin, p.tmax, &p.neg, b(&bmin), b(&bmax)).1 & active
                        } else {
                            active
                        };
                        if lane_mask == 0 {
                            continue;
                        }
                        crate::traverse::wide::prefetch(bvh, child);
                        let e = Entry {
                            code: child,
                            dist: nears[i],
                            mask: lane_mask,
                        };
                        if !stack.push_sorted(base, e) {
                            budget = 0; // NOTE: unreachable within MAX_WIDE_DEPTH; finish as singles
                            break;
                        }
                    }
                }
            }
        } else if cur != EMPTY_CHILD {
            let (first, count) = leaf_packs(cur);
            if let Some(packs) = bvh.packs.get(first..first + count) {
                let m = cur_mask & active;
                // PERF: any hit, and closest hits with few lanes or narrow packets, run the
                // single-ray kernel per lane on every pack (one x`N` test per ray and pack). An
                // earlier packet kernel per triangle (AoS triangles, per-bit commits) measured
                // 1.1-2x slower; the SoA one below wins where the packet fills its lanes.
                let hit_any = if ANY {
                    singles(&mut ready, T::WATERTIGHT, rays, single, p.tmax, active);
                    any_rays::<T, L, N, K, F>(packs, single, m, f)
                } else {
                    // PERF: where the packet is at least as wide as the packs and at least half
                    // its lanes enter the leaf, each valid triangle is tested against the whole
                    // packet (Möller-Trumbore; the same bits, tested), as Embree's packet kernels
                    // do: bunny, 1024 x 1024 primary rays in 4 x 2 tiles, BVH8, best of 120:
                    // packets that reach a triangle 14.4 -> 13.0 ms, all 25.45 -> 24.5 ms; at
                    // 512 x 512 no change. With fewer lanes than pack lanes (4-ray packets over
                    // a BVH8) it was slower (1.22x -> 1.11x single rays), so those stay per lane.
                    // (A hit filter takes the per-lane kernels: they ask it before committing.)
                    let tri_major = if F::ACCEPTS_ALL && K >= N && m.count_ones() as usize * 2 >= K {
                        let tmax = R::from_bitmask(m).select(p.tmax, R::splat(f32::NEG_INFINITY));
                        T::closest_packet_leaf(p.origin, p.direction, p.tmin, tmax, packs)
                    } else {
                        None
                    };
                    match tri_major {
                        Some((h, t, u, v, prim)) => {
                            if h != 0 {
                                p.tmax = R::from_bitmask(h).select(t, p.tmax);
                                let (mut ta, mut ua, mut va, mut pa) = ([0f32; K], [0f32; K], [0f32; K], [0f32; K]);
                                t.store(&mut ta);
                                u.store(&mut ua);
                                v.store(&mut va);
                                prim.store(&mut pa);
                                let mut b = h;
                                while b != 0 {
                                    let l = b.trailing_zeros() as usize % K;
                                    b &= b - 1;
                                    if ready {
                                        // Prepared singles keep their `tmax` in step.
                                        single[l].tmax = ta[l];
                                    }
                                    best[l] = Some(Hit {
                                        t: ta[l],
                                        u: ua[l],
                                        v: va[l],
                                        prim: pa[l].to_bits(),
                                    });
                                }
                            }
                            h
                        }
                        None => {
                            singles(&mut ready, T::WATERTIGHT, rays, single, p.tmax, active);
                            let h = closest_rays::<T, L, N, K, F>(packs, single, best, m, f);
                            if h != 0 {
                                p.tmax = tmax_lanes::<R, K>(single);
                            }
                            h
                        }
                    }
                };
                if hit_any != 0 && ANY {
                    // Any hit: retire the lanes hit; stop when none is left.
                    occluded |= hit_any;
                    active &= !hit_any;
                    if active == 0 {
                        return occluded;
                    }
                    p.tmax = R::from_bitmask(active).select(p.tmax, R::splat(f32::NEG_INFINITY));
                    iv = Interval::new(&p, active);
                } else if hit_any != 0 {
                    iv.tmax = R::from_bitmask(active)
                        .select(p.tmax, R::splat(f32::NEG_INFINITY))
                        .max_lane();
                }
            }
        }
        if budget == 0 {
            continue;
        }
        loop {
            match stack.pop() {
                None => return occluded,
                Some(e) if e.dist <= widened(iv.tmax) && e.mask & active != 0 => {
                    (cur, cur_mask) = (e.code, e.mask);
                    break;
                }
                Some(_) => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::{BuildParams, Bvh2};
    use crate::intersect::aabb::intersect_aabb_lanes;
    use crate::layout::{Bvh4, Bvh8};
    use crate::math::{f32x4, f32x8};
    use crate::scene::Rng;
    use glam::Vec3;

    /// Single-ray traversal's root test: the children of node 0 that the prepared ray enters.
    fn enters<L: Lane, const N: usize>(bvh: BvhWideRef<'_, L, N>, ray: &Ray) -> bool {
        let r = PreparedRay::new(ray);
        let root = &bvh.nodes[0];
        let mask = intersect_aabb_lanes(&r, &root.bounds).1;
        (0..N).any(|c| mask >> c & 1 == 1 && root.child[c] != EMPTY_CHILD)
    }

    /// Rays from a pool of special and ordinary values, aimed at the scene or anywhere.
    fn rays(rng: &mut Rng, n: usize) -> alloc::vec::Vec<Ray> {
        let specials = [
            0.0,
            -0.0,
            1e-39,
            -1e-39,
            1e-45,
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            0.5,
            -2.0,
        ];
        let v = |rng: &mut Rng| {
            if rng.u64().is_multiple_of(4) {
                specials[(rng.u64() % specials.len() as u64) as usize]
            } else {
                rng.range(-3.0, 3.0)
            }
        };
        (0..n)
            .map(|i| {
                let origin = Vec3::new(v(rng), v(rng), v(rng));
                let toward = Vec3::new(rng.range(0.0, 1.0), rng.range(0.0, 1.0), rng.range(0.0, 1.0)) - origin;
                let direction = if i % 3 == 0 {
                    toward
                } else {
                    Vec3::new(v(rng), v(rng), v(rng))
                };
                Ray {
                    origin,
                    direction,
                    tmin: if i % 5 == 0 { v(rng) } else { 0.0 },
                    tmax: if i % 7 == 0 { v(rng) } else { f32::INFINITY },
                }
            })
            .collect()
    }

    /// The packet's lanes hold, bit for bit, the fields of the rays prepared one by one in every
    /// valid lane, and the same active lanes (those with a non-empty interval) in all lanes.
    fn same_as_prepared<R: Lane>(lanes: &Slabs<R>, rays: &[Ray]) {
        let mut active = 0;
        for (i, r) in rays.iter().take(R::N).enumerate() {
            let p = PreparedRay::new(r);
            active |= (!p.is_empty() as u32) << i;
            if p == PreparedRay::EMPTY {
                continue;
            }
            let bits = |v: &[R; 3]| [v[0].at(i).to_bits(), v[1].at(i).to_bits(), v[2].at(i).to_bits()];
            let want = |v: Vec3| v.to_array().map(f32::to_bits);
            assert_eq!(bits(&lanes.origin), want(p.origin), "{r:?}");
            assert_eq!(bits(&lanes.direction), want(p.direction), "{r:?}");
            assert_eq!(bits(&lanes.inv_dir), want(p.inv_dir), "{r:?}");
            assert_eq!(lanes.tmin.at(i).to_bits(), p.tmin.to_bits(), "{r:?}");
            assert_eq!(lanes.tmax.at(i).to_bits(), p.tmax.to_bits(), "{r:?}");
            assert_eq!(lanes.neg.map(|n| n.bitmask() >> i & 1 == 1), p.neg, "{r:?}");
        }
        assert_eq!(lanes.active(), active, "{rays:?}");
    }

    #[test]
    fn root_lanes_are_the_single_ray_root_test() {
        let tris = crate::scene::thin_soup(300, 4);
        let (b2, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
        let (b4, b8) = (
            Bvh4::from_bvh2(&b2, &tris[..]).unwrap(),
            Bvh8::from_bvh2(&b2, &tris[..]).unwrap(),
        );
        let mut rng = Rng::new(21);
        let mut entered = 0;
        for round in 0..3000 {
            let rs = rays(&mut rng, 1 + round % 16);
            let want = |n: usize, f: &dyn Fn(&Ray) -> bool| {
                rs.iter()
                    .take(n)
                    .enumerate()
                    .fold(0u32, |m, (i, r)| m | (f(r) as u32) << i)
            };
            let w8 = want(8, &|r| enters(b8.view(), r));
            let (e8, l8) = root_lanes::<f32x8, 8, f32x8, 8>(b8.view(), &rs);
            assert_eq!(e8, w8, "{rs:?}");
            same_as_prepared(&l8, &rs);
            let (e4, l4) = root_lanes::<f32x8, 8, f32x4, 4>(b8.view(), &rs);
            assert_eq!(e4, w8 & 0xf, "{rs:?}");
            same_as_prepared(&l4, &rs);
            let w4 = want(16, &|r| enters(b4.view(), r));
            let (e16, l16) = root_lanes::<f32x4, 4, crate::math::f32x16, 16>(b4.view(), &rs);
            assert_eq!(e16, w4, "{rs:?}");
            same_as_prepared(&l16, &rs);
            entered += w8.count_ones();
        }
        assert!(entered > 3000, "too few rays enter the scene to test much: {entered}");
    }
}
