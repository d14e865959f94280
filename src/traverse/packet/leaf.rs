//! Leaf tests of a packet: the packet triangle kernels restricted to the lanes that entered a leaf.
//!
//! Up to 8 lanes run the kernels on the packet itself. 16 lanes run them as two 8-lane halves,
//! skipping a half without a lane in the leaf: the kernels' own scratch (the watertight edge
//! fallback) holds 8 lanes, and half packets share more work on incoherent leaves. Boxes are still
//! tested 16 lanes at a time.

use crate::geometry::{Hit, Triangle};
use crate::intersect::{HitLanes, PreparedPacket, PreparedPacket8, PreparedRay, TriangleLanes};
use crate::math::{Lane, f32x8};
use crate::traverse::wide::any_in_pack;
use crate::traverse::{HitFilter, TriangleTest, closest_in_pack};

/// One 8-lane half of a 16-ray packet.
struct Half {
    p: PreparedPacket8,
    hits: HitLanes<f32x8, 8>,
}

/// The leaf-test state of a packet of `K` rays in lanes `R`.
pub(super) struct Leaves<R, const K: usize> {
    hits: HitLanes<R, K>,
    halves: Option<[Half; 2]>,
    /// The packet's `tmax` before [`begin`](Self::begin) (lanes outside the leaf get it back).
    keep: R,
    /// The lanes in the leaf, as a lane mask.
    inside: R,
    /// The lanes in the leaf, as bits.
    mask: u32,
}

impl<R: Lane, const K: usize> Leaves<R, K> {
    /// Leaf state for the prepared rays `single` (the lanes of the packet).
    #[inline(always)]
    pub(super) fn new(single: &[PreparedRay; K]) -> Self {
        let halves = (K > 8).then(|| {
            let half = |s: &[PreparedRay]| Half {
                p: PreparedPacket8::from_prepared(s),
                hits: HitLanes::default(),
            };
            [half(&single[..8]), half(&single[8..])]
        });
        Self {
            hits: HitLanes::default(),
            halves,
            keep: R::splat(0.0),
            inside: R::splat(0.0),
            mask: 0,
        }
    }

    /// Starts a leaf entered by the lanes of `mask`: the others are masked off until
    /// [`end`](Self::end).
    #[inline(always)]
    pub(super) fn begin(&mut self, packet: &mut PreparedPacket<R, K>, mask: u32) {
        self.mask = mask;
        match &mut self.halves {
            None => {
                self.keep = packet.tmax;
                self.inside = R::from_bitmask(mask);
                packet.tmax = self.inside.select(packet.tmax, R::splat(f32::NEG_INFINITY));
            }
            Some(halves) => {
                let mut t = [0f32; K];
                packet.tmax.store(&mut t);
                for (h, half) in halves.iter_mut().enumerate() {
                    let m = mask >> (8 * h) & 0xff;
                    if m != 0 {
                        let tmax = f32x8::load(&t[8 * h..]);
                        half.p.tmax = f32x8::from_bitmask(m).select(tmax, f32x8::splat(f32::NEG_INFINITY));
                    }
                }
            }
        }
    }

    /// Tests one triangle against the lanes in the leaf; returns the lanes hit closer than their
    /// `tmax` (which shrinks to the hit).
    #[inline(always)]
    pub(super) fn test<T: TriangleTest>(
        &mut self,
        packet: &mut PreparedPacket<R, K>,
        tri: &Triangle,
        prim: u32,
    ) -> u32 {
        match &mut self.halves {
            None => T::intersect_packet(packet, tri, prim, &mut self.hits),
            Some(halves) => {
                let mut hit = 0;
                for (h, half) in halves.iter_mut().enumerate() {
                    if self.mask >> (8 * h) & 0xff != 0 {
                        hit |= T::intersect_packet(&mut half.p, tri, prim, &mut half.hits) << (8 * h);
                    }
                }
                hit
            }
        }
    }

    /// Ends the leaf: every lane's `tmax` is its closest hit so far again.
    #[inline(always)]
    pub(super) fn end(&mut self, packet: &mut PreparedPacket<R, K>) {
        match &self.halves {
            None => packet.tmax = self.inside.select(packet.tmax, self.keep),
            Some(halves) => {
                let mut t = [0f32; K];
                packet.tmax.store(&mut t);
                for (h, half) in halves.iter().enumerate() {
                    let mut m = self.mask >> (8 * h) & 0xff;
                    if m != 0 {
                        let mut ht = [0f32; 8];
                        half.p.tmax.store(&mut ht);
                        while m != 0 {
                            let i = m.trailing_zeros() as usize;
                            m &= m - 1;
                            t[8 * h + i] = ht[i];
                        }
                    }
                }
                packet.tmax = R::load(&t);
            }
        }
    }

    /// The last hit recorded for lane `i`.
    #[inline(always)]
    pub(super) fn get(&self, i: usize) -> Hit {
        match &self.halves {
            None => self.hits.get(i),
            Some(halves) => halves[(i / 8) % 2].hits.get(i % 8),
        }
    }
}

/// Closest hits of the lanes of `mask` in `packs` that `f` accepts, ray by ray with the single-ray
/// x`N` kernel (the very test single-ray traversal runs, so the answers are the same bit for bit):
/// each lane's `tmax` shrinks to its hit and the hit goes to `best`. Returns the lanes hit.
///
/// PERF: a pack of 8 triangles costs one x8 kernel per ray here, against 8 packet kernels (each
/// extracting and splatting one triangle) in [`Leaves::test`]: cheaper unless most lanes of a wide
/// packet enter the leaf.
#[inline(always)]
pub(super) fn closest_rays<T: TriangleTest, L: Lane, const N: usize, const K: usize, F: HitFilter>(
    packs: &[TriangleLanes<L, N>],
    single: &mut [PreparedRay; K],
    best: &mut [Option<Hit>; K],
    mask: u32,
    f: &mut F,
) -> u32 {
    let mut hit = 0;
    let mut m = mask;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        let (Some(r), Some(b)) = (single.get_mut(i), best.get_mut(i)) else {
            continue;
        };
        for pack in packs {
            if let Some(h) = closest_in_pack::<T, L, N, F>(r, pack, f) {
                r.tmax = h.t;
                *b = Some(h);
                hit |= 1 << i;
            }
        }
    }
    hit
}

/// Any-hit form of [`closest_rays`]: the lanes of `mask` that hit some triangle of `packs` with a
/// hit `f` accepts.
#[inline(always)]
pub(super) fn any_rays<T: TriangleTest, L: Lane, const N: usize, const K: usize, F: HitFilter>(
    packs: &[TriangleLanes<L, N>],
    single: &[PreparedRay; K],
    mask: u32,
    f: &mut F,
) -> u32 {
    let mut hit = 0;
    let mut m = mask;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if let Some(r) = single.get(i)
            && packs.iter().any(|p| any_in_pack::<T, L, N, F>(r, p, f))
        {
            hit |= 1 << i;
        }
    }
    hit
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ray;
    use crate::intersect::TriangleX8;
    use crate::traverse::{AcceptAll, Moller, Watertight};
    use glam::Vec3;

    fn check<T: TriangleTest>() {
        let tri = |z: f32, x: f32| {
            [
                Vec3::new(x - 1.0, -1.0, z),
                Vec3::new(x + 1.0, -1.0, z),
                Vec3::new(x, 1.0, z),
            ]
        };
        let packs = [
            TriangleX8::pack(&[tri(5.0, 0.0), tri(3.0, 0.5), tri(4.0, -0.5)], &[0, 1, 2]),
            TriangleX8::pack(&[tri(3.0, 0.5), tri(2.0, 3.0)], &[3, 4]),
        ];
        let single: [PreparedRay; 8] =
            core::array::from_fn(|i| PreparedRay::new(&Ray::new(Vec3::new(i as f32 * 0.4 - 1.0, 0.0, 0.0), Vec3::Z)));
        let mask = 0b1011_0110;
        let (mut rays, mut best) = (single, [None; 8]);
        let hit = closest_rays::<T, _, 8, 8, _>(&packs, &mut rays, &mut best, mask, &mut AcceptAll);
        assert_eq!(any_rays::<T, _, 8, 8, _>(&packs, &single, mask, &mut AcceptAll), hit);
        for i in 0..8 {
            let mut r = single[i];
            let mut want = None;
            if mask >> i & 1 == 1 {
                for p in &packs {
                    if let Some(h) = T::intersect_lanes(&r, p) {
                        r.tmax = h.t;
                        want = Some(h);
                    }
                }
            }
            assert_eq!(best[i], want, "lane {i}");
            assert_eq!(hit >> i & 1 == 1, want.is_some());
            assert_eq!(rays[i].tmax.to_bits(), r.tmax.to_bits());
        }
        assert_ne!(hit, 0);
    }

    #[test]
    fn ray_by_ray_leaves_equal_single_rays() {
        check::<Moller>();
        check::<Watertight>();
    }
}
