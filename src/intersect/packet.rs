//! Ray packets in structure-of-arrays form for the packet kernels (N rays, one primitive): 4 rays
//! in [`f32x4`], 8 in [`f32x8`], 16 in `wide`'s `f32x16` (one AVX-512 register, or two `f32x8`
//! halves without AVX-512).

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
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedPacket4, PreparedRay}, math::Lane};
/// let rays = [Ray::new(Vec3::ZERO, Vec3::X), Ray::new(Vec3::ZERO, Vec3::ZERO), Ray::new(Vec3::Y, -Vec3::Z)];
/// let p = PreparedPacket4::new(&rays);
/// assert_eq!(p.active(), 0b101); // the zero direction and the missing fourth ray never hit
/// assert_eq!(p.inv_dir[2].lane(2), PreparedRay::new(&rays[2]).inv_dir.z);
/// ```
pub type PreparedPacket4 = PreparedPacket<f32x4, 4>;
/// Eight rays, SoA.
///
/// ```
/// use strahl::{Ray, Vec3, intersect::{PreparedPacket8, PreparedRay}, math::Lane};
/// let rays: Vec<Ray> = (0..8).map(|i| Ray::new(Vec3::ZERO, Vec3::new(1.0, 0.1 * i as f32, 2.0))).collect();
/// let p = PreparedPacket8::new(&rays);
/// assert_eq!(p.active(), 0xff);
/// for (i, r) in rays.iter().enumerate() {
///     assert_eq!(p.inv_dir[1].lane(i), PreparedRay::new(r).inv_dir.y); // lane i is ray i
/// }
/// assert_eq!(p.k_uniform, Some(PreparedRay::new(&rays[0]).k)); // z dominates every direction
/// ```
pub type PreparedPacket8 = PreparedPacket<f32x8, 8>;

impl<L: Lane, const N: usize> PreparedPacket<L, N> {
    const _LANES_MATCH: () = assert!(L::N == N);

    /// Prepares up to `N` rays (extra rays are ignored).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::PreparedPacket, traverse::packet::f32x16};
    /// let rays = [Ray::new(Vec3::ZERO, Vec3::X); 11];
    /// assert_eq!(PreparedPacket::<f32x16, 16>::new(&rays).active(), 0x7ff);
    /// ```
    pub fn new(rays: &[Ray]) -> Self {
        let mut pre = [PreparedRay::EMPTY; N];
        for (p, r) in pre.iter_mut().zip(rays.iter().take(N)) {
            *p = PreparedRay::new(r);
        }
        Self::from_prepared(&pre[..N])
    }

    /// Transposes up to `N` prepared rays; missing lanes are [`PreparedRay::EMPTY`].
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::{PreparedPacket4, PreparedRay}, math::Lane};
    /// let rays = [Ray::new(Vec3::ZERO, Vec3::Z), Ray::with_range(Vec3::X, Vec3::Z, 0.5, 4.0)];
    /// let pre: Vec<PreparedRay> = rays.iter().map(PreparedRay::new).collect();
    /// let p = PreparedPacket4::from_prepared(&pre);
    /// assert_eq!(p.active(), 0b11); // lanes 2 and 3 are `PreparedRay::EMPTY`
    /// assert_eq!((p.tmin.lane(1), p.tmax.lane(1)), (0.5, 4.0));
    /// assert_eq!(p.tmax.lane(0), PreparedPacket4::new(&rays).tmax.lane(0)); // as `new` prepares them
    /// ```
    pub fn from_prepared(rays: &[PreparedRay]) -> Self {
        let () = Self::_LANES_MATCH;
        // PERF: plain loops into arrays (closures through `dyn Fn` cost about a third of a
        // coherent packet's traversal time on primary rays).
        let mut o = [[0f32; N]; 3];
        let mut d = [[0f32; N]; 3];
        let mut inv = [[0f32; N]; 3];
        let mut sh = [[0f32; N]; 3];
        let mut ksel = [[[0f32; N]; 3]; 3];
        let mut tmin = [0f32; N];
        let mut tmax = [0f32; N];
        let all = f32::from_bits(u32::MAX);
        for i in 0..N {
            let r = rays.get(i).unwrap_or(&PreparedRay::EMPTY);
            for a in 0..3 {
                o[a][i] = r.origin[a];
                d[a][i] = r.direction[a];
                inv[a][i] = r.inv_dir[a];
                sh[a][i] = r.shear[a];
            }
            for (j, &k) in r.k.iter().enumerate() {
                ksel[j][k.min(2)][i] = all;
            }
            tmin[i] = r.tmin;
            tmax[i] = r.tmax;
        }
        let load3 = |v: &[[f32; N]; 3]| [L::load(&v[0]), L::load(&v[1]), L::load(&v[2])];
        // Inactive lanes never hit, so their permutation does not matter.
        let mut ks = rays.iter().take(N).filter(|r| r.tmin < r.tmax).map(|r| r.k);
        let first = ks.next().unwrap_or([0, 1, 2]);
        let k_uniform = ks.all(|k| k == first).then_some(first);
        Self {
            origin: load3(&o),
            direction: load3(&d),
            inv_dir: load3(&inv),
            tmin: L::load(&tmin),
            tmax: L::load(&tmax),
            shear: load3(&sh),
            k_sel: [load3(&ksel[0]), load3(&ksel[1]), load3(&ksel[2])],
            k_uniform,
        }
    }

    /// Mask of lanes whose interval `[tmin, tmax)` is not empty.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, intersect::PreparedPacket4};
    /// let rays = [
    ///     Ray::new(Vec3::ZERO, Vec3::Z),
    ///     Ray::with_range(Vec3::ZERO, Vec3::Z, 1.0, 1.0), // `[1, 1)` is empty
    ///     Ray::new(Vec3::X, Vec3::Z),
    /// ];
    /// assert_eq!(PreparedPacket4::new(&rays).active(), 0b101); // lane 3 is unused
    /// ```
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
