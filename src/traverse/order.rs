//! Ray reordering for incoherent batches: trace rays whose origins lie close together one after
//! another, so that the nodes and leaves one ray loads are still in the cache for the next.
//!
//! [`RayOrder::compute`] sorts a batch's indices by the Morton code of each ray's origin (the
//! top [`KEY_BITS`] bits of the 30-bit code, over the bounds of the batch's finite origins, with
//! near-cubic cells as in [`MortonQuantizer::new_extended`]); a stable LSD radix sort, so rays in
//! one cell keep their order. The batch functions that take an order
//! ([`wide::occluded_batch_ordered`](super::wide::occluded_batch_ordered),
//! [`wide::intersect_batch_ordered`](super::wide::intersect_batch_ordered)) trace in that order and
//! write each answer to its ray's own slot, so the answers are those of one call per ray, in the
//! caller's order; [`BvhWide::occluded_batch_reordered`](crate::layout::BvhWide::occluded_batch_reordered)
//! and [`BvhWide::intersect_batch_reordered`](crate::layout::BvhWide::intersect_batch_reordered)
//! do both steps.
//!
//! This is the ray sorting of Pharr et al. ("Rendering Complex Scenes with Memory-Coherent Ray
//! Tracing", 1997) and Garanzha and Loop ("Fast Ray Sorting and Breadth-First Packet Traversal
//! for GPU Ray Tracing", 2010) in its simplest form, for single-ray traversal: the key is the
//! origin only. Rays from scattered surface points (shadow rays, ambient occlusion, diffuse
//! bounces, a wavefront renderer's rays after a shuffle) gain; a camera's rays, or rays already
//! generated tile by tile, are coherent as they come and gain nothing.
//!
//! PERF (`cargo bench --features embree --bench trace -- --noplot`, 262,144 rays, BVH8, the
//! sort's time included): see the trace section of `benches/RESULTS.md`.
//!
//! ```
//! use strahl::{Ray, Vec3, traverse::order::RayOrder};
//! let rays = [
//!     Ray::new(Vec3::new(9.0, 9.0, 9.0), Vec3::X),
//!     Ray::new(Vec3::ZERO, Vec3::X),
//!     Ray::new(Vec3::new(9.0, 9.0, 8.9), Vec3::Y),
//!     Ray::new(Vec3::splat(f32::NAN), Vec3::X), // invalid: sorted like any other ray
//! ];
//! let mut order = RayOrder::new();
//! let o = order.compute(&rays);
//! let mut sorted = o.to_vec();
//! sorted.sort();
//! assert_eq!(sorted, [0, 1, 2, 3]); // a permutation of the batch
//! let at = |i: u32| o.iter().position(|&j| j == i).unwrap();
//! assert_eq!(at(0).abs_diff(at(2)), 1); // the two rays from (9, 9, 9) are neighbours
//! ```

use crate::build::radix::{Item, sort_items};
use crate::geometry::morton::{BITS_PER_AXIS_30, MortonQuantizer, morton30_x8};
use crate::geometry::{Aabb, Ray};
use crate::math::{Lane, f32x8};
use alloc::vec::Vec;
use glam::Vec3A;

/// Bits of the sort key: the top 16 bits of the origin's 30-bit Morton code (about 40 cells per
/// axis), sorted in two passes of 8 bits.
///
/// ```
/// use strahl::{Ray, Vec3, traverse::order::{KEY_BITS, RayOrder}};
/// assert_eq!(KEY_BITS, 16); // about 40 cells per axis
/// let rays = [
///     Ray::new(Vec3::ONE, Vec3::X),
///     Ray::new(Vec3::ZERO, Vec3::X),
///     Ray::new(Vec3::splat(0.999), Vec3::X), // in the first ray's cell: keeps its place after it
/// ];
/// assert_eq!(RayOrder::new().compute(&rays), [1, 0, 2]);
/// ```
// PERF: 262,144 rays with random origins (Intel Xeon): the order in 2.5 ms with 16 bits, 3.2 ms
// with 24 and 4.0 ms with 30 (three passes of 1,024 buckets); the 1M sphereflake's shadow and
// diffuse rays traced no faster in the 24- or 30-bit order.
pub const KEY_BITS: u32 = 16;

/// The scratch and the result of [`compute`](Self::compute); keep one to reuse its memory from
/// batch to batch.
///
/// ```
/// use strahl::{Ray, Vec3, traverse::order::RayOrder};
/// let mut order = RayOrder::new();
/// for n in [20u32, 10] {
///     // Origins on a line, each in a cell of its own: the order sorts them along it.
///     let rays: Vec<Ray> = (0..n).map(|i| Ray::new(Vec3::new((i * 7 % n) as f32, 0.0, 0.0), Vec3::Y)).collect();
///     let o = order.compute(&rays);
///     assert!(o.windows(2).all(|w| rays[w[0] as usize].origin.x < rays[w[1] as usize].origin.x));
/// }
/// ```
#[derive(Clone, Debug, Default)]
pub struct RayOrder {
    items: Vec<Item<u32>>,
    tmp: Vec<Item<u32>>,
    order: Vec<u32>,
}

impl RayOrder {
    /// An empty order (no memory yet).
    ///
    /// ```
    /// use strahl::traverse::order::RayOrder;
    /// assert!(RayOrder::new().order().is_empty());
    /// ```
    pub fn new() -> Self {
        Self::default()
    }

    /// The indices of `rays` (all of them, each once) with the rays' origins in Morton order.
    /// Rays with a NaN or infinite origin are sorted too (their origin is clamped into the
    /// bounds of the finite ones, NaN to the lower corner); traversal answers them as always.
    ///
    /// A batch longer than `u32::MAX` rays gets the indices `0..u32::MAX` only.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, traverse::order::RayOrder};
    /// let rays = [
    ///     Ray::new(Vec3::new(5.0, 0.0, 0.0), Vec3::X),
    ///     Ray::new(Vec3::ZERO, Vec3::Y),
    ///     Ray::new(Vec3::new(5.0, 0.1, 0.0), -Vec3::X),
    /// ];
    /// assert_eq!(RayOrder::new().compute(&rays), [1, 0, 2]); // by origin, whatever the direction
    /// ```
    pub fn compute(&mut self, rays: &[Ray]) -> &[u32] {
        let rays = &rays[..rays.len().min(u32::MAX as usize)];
        let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        for r in rays {
            let o = Vec3A::from(r.origin);
            if o.is_finite() {
                lo = lo.min(o);
                hi = hi.max(o);
            }
        }
        // NOTE: with no finite origin the bounds are empty and every axis flat: all keys 0.
        let q = MortonQuantizer::new_extended(&Aabb::new(lo.into(), hi.into()), BITS_PER_AXIS_30);
        let shift = 3 * BITS_PER_AXIS_30 - KEY_BITS;
        self.items.clear();
        self.items.reserve(rays.len());
        let mut chunks = rays.chunks_exact(8);
        let mut base = 0u32;
        for c in &mut chunks {
            // A ray's eight floats start with its origin: lanes 0-2 of the transpose.
            let [x, y, z, ..] = f32x8::transpose8(bytemuck::cast_slice::<Ray, [f32; 8]>(c));
            let codes = morton30_x8(x, y, z, &q).to_array();
            self.items.extend((0..8).map(|i| Item {
                key: codes[i] >> shift,
                val: base + i as u32,
            }));
            base += 8;
        }
        for (i, r) in chunks.remainder().iter().enumerate() {
            self.items.push(Item {
                key: crate::geometry::morton::morton30_scalar(r.origin, &q) >> shift,
                val: base + i as u32,
            });
        }
        sort_items(&mut self.items, &mut self.tmp, KEY_BITS);
        self.order.clear();
        self.order.extend(self.items.iter().map(|it| it.val));
        &self.order
    }

    /// The order of the last [`compute`](Self::compute) (empty before the first).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, traverse::order::RayOrder};
    /// let rays = [Ray::new(Vec3::ONE, Vec3::X), Ray::new(Vec3::ZERO, Vec3::X)];
    /// let mut order = RayOrder::new();
    /// order.compute(&rays);
    /// assert_eq!(order.order(), [1, 0]);
    /// ```
    pub fn order(&self) -> &[u32] {
        &self.order
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vec3;
    use crate::scene::Rng;

    #[test]
    fn a_stable_permutation_by_origin_cell() {
        let mut rng = Rng::new(3);
        for n in [0usize, 1, 7, 8, 9, 1000] {
            let mut rays: Vec<Ray> = (0..n)
                .map(|_| Ray::new(Vec3::new(rng.f32(), rng.f32() * 4.0, rng.f32()), Vec3::X))
                .collect();
            if n > 2 {
                rays[1].origin = Vec3::splat(f32::NAN);
                rays[2].origin = Vec3::new(f32::INFINITY, 0.5, 0.5);
            }
            let mut o = RayOrder::new();
            let got = o.compute(&rays).to_vec();
            let mut seen = got.clone();
            seen.sort_unstable();
            assert_eq!(seen, (0..n as u32).collect::<Vec<_>>());
            // Keys never decrease along the order, and equal keys keep the input order.
            let mut b = Aabb::EMPTY;
            for r in rays.iter().filter(|r| r.origin.is_finite()) {
                b = Aabb::new(b.min.min(r.origin), b.max.max(r.origin));
            }
            let q = MortonQuantizer::new_extended(&b, BITS_PER_AXIS_30);
            let key = |i: u32| crate::geometry::morton::morton30_scalar(rays[i as usize].origin, &q) >> (30 - KEY_BITS);
            for w in got.windows(2) {
                assert!((key(w[0]), w[0]) < (key(w[1]), w[1]), "{n}: {w:?}");
            }
            assert_eq!(o.order(), &got[..]);
        }
    }

    #[test]
    fn no_finite_origin() {
        let rays = [Ray::new(Vec3::splat(f32::NAN), Vec3::X); 11];
        assert_eq!(RayOrder::new().compute(&rays), (0..11).collect::<Vec<u32>>());
    }
}
