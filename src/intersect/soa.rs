//! Structure-of-arrays triangle storage for the `x4` / `x8` kernels, and the lane reductions.

use crate::geometry::{Hit, INVALID, Triangle, is_degenerate};
use crate::math::{Lane, f32x4, f32x8};
use glam::Vec3;

/// `N` triangles in structure-of-arrays form, with the primitive index of each lane and a mask of
/// the lanes that can be hit.
///
/// `v[j][axis]` holds vertex `j`'s coordinate on `axis` for all lanes. The vertices are stored as
/// given (not as edges) so that the watertight test sees shared vertices bit for bit; Möller-Trumbore
/// forms the edges on the fly. Lane `i` can be hit only if bit `i` of `valid` is set: packing clears
/// it for unused lanes and for [degenerate](crate::geometry::is_degenerate) triangles, so the
/// kernels need no degeneracy test of their own.
///
/// ```
/// use strahl::{Vec3, intersect::TriangleX8};
/// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::ZERO, Vec3::X, Vec3::X]];
/// let soa = TriangleX8::pack(&tris, &[10, 11]);
/// assert_eq!(soa.valid, 0b01); // lane 1 is degenerate, lanes 2..8 are unused
/// assert_eq!(soa.prim[0], 10);
/// assert_eq!(soa.get(0), tris[0]);
/// ```
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct TriangleLanes<L, const N: usize> {
    /// Vertices: `v[vertex][axis]`, one lane per triangle.
    pub v: [[L; 3]; 3],
    /// Primitive index reported for each lane.
    pub prim: [u32; N],
    /// Bit `i` set if lane `i` holds a hittable triangle.
    pub valid: u32,
}

/// Four triangles, SoA.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX4, watertight}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris = [tri(4.0), tri(2.0), tri(3.0)];
/// let soa = TriangleX4::pack(&tris, &[]);
/// let ray = PreparedRay::new(&Ray::new(Vec3::new(0.1, 0.2, 0.0), Vec3::Z));
/// let scalar = (0..3).filter_map(|i| watertight::intersect_scalar(&ray, &tris[i], i as u32));
/// let best = scalar.min_by(|a, b| a.t.total_cmp(&b.t));
/// assert_eq!(watertight::intersect_x4(&ray, &soa), best); // the scalar loop's closest hit
/// assert_eq!(best.map(|h| h.prim), Some(1));
/// ```
pub type TriangleX4 = TriangleLanes<f32x4, 4>;
/// Eight triangles, SoA.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedRay, TriangleX8, moller}};
/// let tri = |z: f32| [Vec3::new(-1.0, -1.0, z), Vec3::new(1.0, -1.0, z), Vec3::new(0.0, 1.0, z)];
/// let tris: Vec<_> = (0..10).map(|i| tri(10.0 - i as f32)).collect();
/// let soa = TriangleX8::pack(&tris, &[]);
/// assert_eq!(soa.valid, 0xff); // the first 8; the rest do not fit
/// let ray = PreparedRay::new(&Ray::new(Vec3::ZERO, Vec3::Z));
/// assert_eq!(moller::intersect_x8(&ray, &soa).map(|h| (h.t, h.prim)), Some((3.0, 7)));
/// ```
pub type TriangleX8 = TriangleLanes<f32x8, 8>;

impl<L: Lane, const N: usize> TriangleLanes<L, N> {
    const _LANES_MATCH: () = assert!(L::N == N);

    /// Packs up to `N` triangles with their primitive indices (`prims[i]` for `tris[i]`; missing
    /// indices default to the position `i`). Unused lanes are zero and invalid.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::INVALID, intersect::TriangleX4};
    /// let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
    /// let soa = TriangleX4::pack(&[t, t, t], &[7]);
    /// assert_eq!(soa.prim, [7, 1, 2, INVALID]); // missing indices: the lane's position
    /// assert_eq!(soa.valid, 0b111);
    /// ```
    pub fn pack(tris: &[Triangle], prims: &[u32]) -> Self {
        let () = Self::_LANES_MATCH;
        let mut c = [[[0.0f32; 8]; 3]; 3];
        let mut prim = [INVALID; N];
        let mut valid = 0;
        for (i, t) in tris.iter().take(N).enumerate() {
            for (j, vtx) in t.iter().enumerate() {
                for a in 0..3 {
                    c[j][a][i] = vtx[a];
                }
            }
            prim[i] = prims.get(i).copied().unwrap_or(i as u32);
            if !is_degenerate(t) {
                valid |= 1 << i;
            }
        }
        Self {
            v: c.map(|vtx| vtx.map(|axis| L::load(&axis))),
            prim,
            valid,
        }
    }

    /// Triangle of lane `i`.
    ///
    /// ```
    /// use strahl::{Vec3, intersect::TriangleX8};
    /// let tris = [[Vec3::new(0.1, 0.2, 0.3), Vec3::X, Vec3::Y], [Vec3::ONE, Vec3::NEG_ONE, Vec3::Z]];
    /// let soa = TriangleX8::pack(&tris, &[]);
    /// assert_eq!((soa.get(0), soa.get(1)), (tris[0], tris[1])); // bit for bit
    /// assert_eq!(soa.get(5), [Vec3::ZERO; 3]); // an unused lane
    /// ```
    pub fn get(&self, i: usize) -> Triangle {
        self.v
            .map(|vtx| Vec3::new(vtx[0].lane(i), vtx[1].lane(i), vtx[2].lane(i)))
    }
}

/// Per-lane hit records of a packet kernel: lane `i` is meaningful where the packet's hit mask has
/// bit `i` set (`prim[i] != INVALID`).
///
/// ```
/// use strahl::{Ray, Vec3, geometry::INVALID, intersect::{HitLanes, PreparedPacket4, moller}, math::Lane};
/// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
/// let rays = [Ray::new(Vec3::ZERO, Vec3::Z), Ray::new(Vec3::new(5.0, 0.0, 0.0), Vec3::Z)];
/// let (mut packet, mut hits) = (PreparedPacket4::new(&rays), HitLanes::default());
/// assert_eq!(hits.prim, [INVALID; 4]);
/// assert_eq!(moller::intersect_packet(&mut packet, &tri, 9, &mut hits), 0b01);
/// assert_eq!((hits.prim[0], hits.t.lane(0)), (9, 2.0));
/// assert_eq!((hits.prim[1], hits.t.lane(1)), (INVALID, f32::INFINITY)); // lane 1 passed beside it
/// ```
#[derive(Clone, Copy, Debug)]
pub struct HitLanes<L, const N: usize> {
    /// Hit distances (`+inf` where no hit).
    pub t: L,
    /// Barycentric `u`.
    pub u: L,
    /// Barycentric `v`.
    pub v: L,
    /// Primitive index per lane, or [`INVALID`].
    pub prim: [u32; N],
}

impl<L: Lane, const N: usize> Default for HitLanes<L, N> {
    fn default() -> Self {
        Self {
            t: L::splat(f32::INFINITY),
            u: L::splat(0.0),
            v: L::splat(0.0),
            prim: [INVALID; N],
        }
    }
}

impl<L: Lane, const N: usize> HitLanes<L, N> {
    /// Lane `i` as a [`Hit`] ([`Hit::NONE`] where no hit).
    ///
    /// ```
    /// use strahl::{Hit, Ray, Vec3, intersect::{HitLanes, PreparedPacket4, PreparedRay, watertight}};
    /// let tri = [Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, -1.0, 2.0), Vec3::new(0.0, 1.0, 2.0)];
    /// let rays = [Ray::new(Vec3::new(0.1, 0.2, 0.0), Vec3::Z), Ray::new(Vec3::new(5.0, 0.0, 0.0), Vec3::Z)];
    /// let (mut packet, mut hits) = (PreparedPacket4::new(&rays), HitLanes::default());
    /// watertight::intersect_packet(&mut packet, &tri, 9, &mut hits);
    /// let scalar = watertight::intersect_scalar(&PreparedRay::new(&rays[0]), &tri, 9);
    /// assert_eq!(Some(hits.get(0)), scalar);
    /// assert_eq!(hits.get(1), Hit::NONE);
    /// ```
    pub fn get(&self, i: usize) -> Hit {
        if self.prim[i] == INVALID {
            return Hit::NONE;
        }
        Hit {
            t: self.t.lane(i),
            u: self.u.lane(i),
            v: self.v.lane(i),
            prim: self.prim[i],
        }
    }
}

/// The closest hit among the lanes in `mask` that `accept` takes (the hit filters' leaf test):
/// the lanes in [`closest_lane`]'s order, each offered until one is taken.
#[inline(always)]
pub(crate) fn closest_accepted<L: Lane>(
    mut mask: u32,
    t: L,
    u: L,
    v: L,
    prim: &[u32],
    mut accept: impl FnMut(&Hit) -> bool,
) -> Option<Hit> {
    // The same selection as `closest_lane` (the least `t`, ties to the lowest lane); a rejected
    // lane is dropped and the next one selected from the same lanes, computed once.
    loop {
        if mask == 0 {
            return None;
        }
        let tm = L::from_bitmask(mask).select(t, L::splat(f32::INFINITY));
        let best = tm.min_lane();
        let lane = (tm.eq(L::splat(best)).bitmask() & mask).trailing_zeros() as usize;
        let h = Hit {
            t: t.lane(lane),
            u: u.lane(lane),
            v: v.lane(lane),
            prim: prim[lane],
        };
        if accept(&h) {
            return Some(h);
        }
        mask &= !(1 << lane);
    }
}

/// The closest hit among the lanes in `mask`; ties go to the lowest lane (as a scalar loop over the
/// lanes with a strict `<` would).
#[inline(always)]
pub(crate) fn closest_lane<L: Lane>(mask: u32, t: L, u: L, v: L, prim: &[u32]) -> Option<Hit> {
    if mask == 0 {
        return None;
    }
    // Branch-free, in registers: the minimum over the masked lanes (hit distances are never NaN,
    // and finite: t < tmax), then the lowest masked lane holding it; its own `t`, so that of a
    // -0.0 and a 0.0 the lower lane's is reported, whichever the reduction kept.
    // PERF: a scalar loop over the stored lanes was 12% of coherent packet traversal's profile
    // (bunny primary rays, 8-ray packets, whose leaves run this per lane and pack).
    let tm = L::from_bitmask(mask).select(t, L::splat(f32::INFINITY));
    let best = tm.min_lane();
    let lane = (tm.eq(L::splat(best)).bitmask() & mask).trailing_zeros() as usize;
    Some(Hit {
        t: t.lane(lane),
        u: u.lane(lane),
        v: v.lane(lane),
        prim: prim[lane],
    })
}
