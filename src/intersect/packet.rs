//! Ray packets in structure-of-arrays form for the packet kernels (N rays, one primitive).

use super::{HitLanes, PreparedRay};
use crate::geometry::Ray;
use crate::math::{Lane, f32x4, f32x8};

/// `N` prepared rays in SoA form: lane `i` holds exactly what [`PreparedRay::new`] computes for ray
/// `i`, so packet kernels agree with the single-ray kernels lane by lane.
///
/// Lanes past the rays given, and invalid rays, have the empty interval (`tmin = +inf`,
/// `tmax = -inf`) and never hit.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::PreparedPacket8};
/// let p = PreparedPacket8::new(&[Ray::new(Vec3::ZERO, Vec3::X)]);
/// assert_eq!(p.active(), 0b1);
/// ```
#[derive(Clone, Copy, Debug)]
pub struct PreparedPacket<L, const N: usize> {
    /// Origins per axis.
    pub origin: [L; 3],
    /// Directions per axis.
    pub direction: [L; 3],
    /// Reciprocal directions per axis.
    pub inv_dir: [L; 3],
    /// Smallest accepted distances (inclusive).
    pub tmin: L,
    /// Largest distances (exclusive), shrunk by the closest-hit kernels.
    pub tmax: L,
    /// Watertight shear `(Sx, Sy, Sz)` per lane.
    pub shear: [L; 3],
    /// Watertight axis permutation as lane masks: `k_sel[j][a]` is set where `k[j] == a`.
    pub k_sel: [[L; 3]; 3],
    /// The permutation shared by every active lane, if they all share one (coherent packets do):
    /// the watertight kernel then permutes the triangle once instead of blending per lane.
    pub k_uniform: Option<[usize; 3]>,
}

/// Four rays, SoA.
pub type PreparedPacket4 = PreparedPacket<f32x4, 4>;
/// Eight rays, SoA.
pub type PreparedPacket8 = PreparedPacket<f32x8, 8>;

impl<L: Lane, const N: usize> PreparedPacket<L, N> {
    /// Prepares up to `N` rays (extra rays are ignored).
    pub fn new(rays: &[Ray]) -> Self {
        let mut pre = [PreparedRay::EMPTY; 8];
        for (p, r) in pre.iter_mut().zip(rays.iter().take(N)) {
            *p = PreparedRay::new(r);
        }
        Self::from_prepared(&pre[..N])
    }

    /// Transposes up to `N` prepared rays; missing lanes are [`PreparedRay::EMPTY`].
    pub fn from_prepared(rays: &[PreparedRay]) -> Self {
        let lanes = |f: &dyn Fn(&PreparedRay) -> f32| {
            let mut a = [0.0f32; 8];
            for (i, slot) in a.iter_mut().enumerate().take(N) {
                *slot = f(rays.get(i).unwrap_or(&PreparedRay::EMPTY));
            }
            L::load(&a)
        };
        let axis3 = |f: &dyn Fn(&PreparedRay, usize) -> f32| [0, 1, 2].map(|a| lanes(&|r| f(r, a)));
        let mask = |b: bool| if b { f32::from_bits(u32::MAX) } else { 0.0 };
        Self {
            origin: axis3(&|r, a| r.origin[a]),
            direction: axis3(&|r, a| r.direction[a]),
            inv_dir: axis3(&|r, a| r.inv_dir[a]),
            tmin: lanes(&|r| r.tmin),
            tmax: lanes(&|r| r.tmax),
            shear: axis3(&|r, a| r.shear[a]),
            k_sel: [0, 1, 2].map(|j| axis3(&|r, a| mask(r.k[j] == a))),
            k_uniform: {
                // Inactive lanes never hit, so their permutation does not matter.
                let mut ks = rays.iter().take(N).filter(|r| r.tmin < r.tmax).map(|r| r.k);
                let first = ks.next().unwrap_or([0, 1, 2]);
                ks.all(|k| k == first).then_some(first)
            },
        }
    }

    /// Mask of lanes whose interval `[tmin, tmax)` is not empty.
    pub fn active(&self) -> u32 {
        self.tmin.lt(self.tmax).bitmask()
    }

    /// Picks, per lane, the component `k[j]` of `v`.
    #[inline(always)]
    pub(crate) fn pick(&self, j: usize, v: &[L; 3]) -> L {
        let s = &self.k_sel[j];
        (s[0] & v[0]) | (s[1] & v[1]) | (s[2] & v[2])
    }
}

/// Writes the lanes of `hit` into `hits`, shrinks their `tmax`, returns the lane mask.
#[inline(always)]
pub(crate) fn commit<L: Lane, const N: usize>(
    rays: &mut PreparedPacket<L, N>,
    hits: &mut HitLanes<L, N>,
    hit: L,
    t: L,
    u: L,
    v: L,
    prim: u32,
) -> u32 {
    let mut m = hit.bitmask();
    let mask = m;
    if m == 0 {
        return 0;
    }
    hits.t = hit.select(t, hits.t);
    hits.u = hit.select(u, hits.u);
    hits.v = hit.select(v, hits.v);
    rays.tmax = hit.select(t, rays.tmax);
    while m != 0 {
        hits.prim[m.trailing_zeros() as usize] = prim;
        m &= m - 1;
    }
    mask
}
