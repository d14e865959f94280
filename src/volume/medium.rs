//! What the marcher samples: the [`Medium`] trait, and [`VolumeMedium`], a volume seen through a
//! transfer function, optionally with a macrocell grid.

use super::skip::GridView;
use super::{Macrocell, MacrocellGrid, TransferFunction, Volume, VolumeError, Voxel};
use crate::geometry::Aabb;
use crate::math::f32x8;
use glam::Vec3;

/// Extinction and colour at one point.
///
/// ```
/// use strahl::{Vec3, volume::*};
/// let data = [1.0f32; 8];
/// let vol = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
/// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.0], 4.0)];
/// let m = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 2.0).unwrap());
/// // Value 1 lies halfway up the table: half its extinction, half its colour.
/// assert_eq!(m.lookup(Vec3::splat(0.5)), Lookup::Sample(Sample { tau: 2.0, color: [0.5, 0.25, 0.0] }));
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Extinction `tau` per world unit (`>= 0`; a NaN counts as 0).
    pub tau: f32,
    /// Emitted colour `c`, not premultiplied (finite).
    pub color: [f32; 3],
}

/// Extinction and colour at eight points.
///
/// ```
/// use strahl::{Vec3, math::f32x8, volume::*};
/// let data: Vec<f32> = (0..8).map(|i| i as f32).collect();
/// let vol = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
/// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.0], 8.0)];
/// let m = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 8.0).unwrap());
/// let xs = [0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0, 0.25];
/// let g = [f32x8::new(xs), f32x8::splat(0.5), f32x8::splat(0.25)];
/// let smp: SampleX8 = m.lookup_x8(&g, 0xff, &mut [EmptyRegion::default(); 8]).unwrap();
/// for (l, &x) in xs.iter().enumerate() {
///     let Lookup::Sample(s) = m.lookup(Vec3::new(x, 0.5, 0.25)) else { unreachable!() };
///     assert_eq!((smp.tau.to_array()[l].to_bits(), smp.color[1].to_array()[l]), (s.tau.to_bits(), s.color[1]));
/// }
/// ```
#[derive(Clone, Copy, Debug)]
pub struct SampleX8 {
    /// Extinction per lane.
    pub tau: f32x8,
    /// Colour per channel, per lane.
    pub color: [f32x8; 3],
}

/// A region of local space where the medium is transparent, reported by a [`Medium`] that can skip.
///
/// Contract: the sample that reported it adds nothing, every sample whose local position lies in
/// the closed box [`safe`](Self::safe) adds nothing (zero extinction), and [`exit`](Self::exit)
/// (the region the marcher jumps across) lies inside `safe`.
///
/// ```
/// # use strahl::{Vec3, math::f32x8, volume::*};
/// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
/// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
/// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
/// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
/// # grid.classify(&tf);
/// # let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
/// // `m`: 16^3 voxels, opaque only where x >= 12, skipping over a grid of 4^3-cell blocks.
///
/// let Lookup::Empty(r) = m.lookup(Vec3::new(2.0, 8.0, 8.0)) else { panic!("x = 2 is transparent") };
/// assert!(r.exit.contains_point(Vec3::new(2.0, 8.0, 8.0)) && r.safe.contains(&r.exit));
/// assert!(r.safe.max.x < 12.0); // every sample in `safe` has zero extinction; x = 12 does not
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmptyRegion {
    /// The box to jump across, in local coordinates.
    pub exit: Aabb,
    /// A box around it in which every sample has zero extinction, in local coordinates.
    pub safe: Aabb,
}

impl Default for EmptyRegion {
    fn default() -> Self {
        Self {
            exit: Aabb::EMPTY,
            safe: Aabb::EMPTY,
        }
    }
}

/// The answer of [`Medium::lookup`].
///
/// ```
/// # use strahl::{Vec3, math::f32x8, volume::*};
/// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
/// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
/// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
/// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
/// # grid.classify(&tf);
/// # let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
/// // `m`: 16^3 voxels, opaque only where x >= 12, skipping over a grid of 4^3-cell blocks.
///
/// assert!(matches!(m.lookup(Vec3::new(13.0, 8.0, 8.0)), Lookup::Sample(s) if s.tau > 0.0));
/// assert!(matches!(m.lookup(Vec3::new(1.0, 8.0, 8.0)), Lookup::Empty(_)));
/// // Without the grid the same point is a sample of zero extinction.
/// let plain = VolumeMedium::new(vol, tf);
/// assert!(matches!(plain.lookup(Vec3::new(1.0, 8.0, 8.0)), Lookup::Sample(s) if s.tau == 0.0));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lookup {
    /// The sample.
    Sample(Sample),
    /// The point lies in a transparent region the marcher may jump across.
    Empty(EmptyRegion),
}

/// Something to march through: extinction and colour as functions of position.
///
/// Positions are in *local* coordinates, `local = (world - origin) * scale` per axis with
/// `(origin, scale) =` [`local_frame`](Self::local_frame) (voxel coordinates for a volume), so the
/// marcher can step in them directly. Implement [`lookup`](Self::lookup); the default
/// [`lookup_x8`](Self::lookup_x8) calls it per lane, so the 8-wide marcher agrees with the scalar
/// one bit for bit for any medium. The tests use analytic media (a slab with piecewise-constant
/// extinction, an exponential atmosphere) through this trait.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3};
/// use strahl::volume::{Lookup, MarchParams, Medium, Sample, integrate_ray};
/// /// Constant extinction 2 in the unit cube, white.
/// struct Fog;
/// impl Medium for Fog {
///     fn bounds(&self) -> Aabb { Aabb::new(Vec3::ZERO, Vec3::ONE) }
///     fn lookup(&self, _g: Vec3) -> Lookup {
///         Lookup::Sample(Sample { tau: 2.0, color: [1.0; 3] })
///     }
/// }
/// let ray = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z);
/// let p = integrate_ray(&Fog, &ray, &MarchParams::reference(0.3)).unwrap();
/// assert!((p.a - (1.0 - (-2.0f32).exp())).abs() < 1e-6); // exact at any step
/// ```
pub trait Medium {
    /// The world box outside which the medium is empty.
    ///
    /// ```
    /// use strahl::{Vec3, volume::{Medium, TfEntry, TransferFunction, Volume, VolumeMedium}};
    /// let data = [0u8; 4 * 3 * 2];
    /// let vol = Volume::new(&data, [4, 3, 2], Vec3::splat(0.5), Vec3::X).unwrap();
    /// let m = VolumeMedium::new(vol, TransferFunction::new(&[TfEntry::TRANSPARENT], 0.0, 1.0).unwrap());
    /// let b = m.bounds(); // the voxel centres: origin + (dims - 1) spacing
    /// assert_eq!((b.min, b.max), (Vec3::X, Vec3::new(2.5, 1.0, 0.5)));
    /// ```
    fn bounds(&self) -> Aabb;

    /// `(origin, scale)` of the local coordinates: `local = (world - origin) * scale`, `scale > 0`.
    /// The default is the identity.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, volume::*};
    /// struct Fog;
    /// impl Medium for Fog {
    ///     fn bounds(&self) -> Aabb { Aabb::new(Vec3::ZERO, Vec3::ONE) }
    ///     fn lookup(&self, _g: Vec3) -> Lookup { Lookup::Sample(Sample { tau: 1.0, color: [1.0; 3] }) }
    /// }
    /// assert_eq!(Fog.local_frame(), (Vec3::ZERO, Vec3::ONE)); // the default: local = world
    /// # let data = [0u8; 8];
    /// let vol = Volume::new(&data, [2; 3], Vec3::splat(0.25), Vec3::X).unwrap();
    /// let m = VolumeMedium::new(vol, TransferFunction::new(&[TfEntry::TRANSPARENT], 0.0, 1.0).unwrap());
    /// assert_eq!(m.local_frame(), (Vec3::X, Vec3::splat(4.0))); // a volume's: voxel coordinates
    /// ```
    fn local_frame(&self) -> (Vec3, Vec3) {
        (Vec3::ZERO, Vec3::ONE)
    }

    /// Extinction and colour at local position `g`, or the empty region around it.
    ///
    /// ```
    /// use strahl::{Vec3, volume::*};
    /// let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let vol = Volume::new(&data, [2, 2, 2], Vec3::splat(0.5), Vec3::ZERO).unwrap();
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 8.0)];
    /// let m = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 8.0).unwrap()); // tau = value
    /// // Local (voxel) coordinates, not world ones: (1, 0.5, 0) reads 1 + 2 0.5 + 4 0.
    /// assert!(matches!(m.lookup(Vec3::new(1.0, 0.5, 0.0)), Lookup::Sample(s) if s.tau == 2.0));
    /// ```
    fn lookup(&self, g: Vec3) -> Lookup;

    /// The empty region around local position `g`, if [`lookup`](Self::lookup) would report one
    /// there (and `None` exactly where it would return a sample). The marcher asks this while it
    /// jumps across regions, where the sample itself is not needed; the default calls `lookup`,
    /// a medium that can answer without sampling (as [`VolumeMedium`] does) overrides it.
    ///
    /// ```
    /// # use strahl::{Vec3, math::f32x8, volume::*};
    /// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
    /// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// # grid.classify(&tf);
    /// # let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    /// // `m`: 16^3 voxels, opaque only where x >= 12, skipping over a grid of 4^3-cell blocks.
    ///
    /// assert_eq!(m.empty_region(Vec3::new(13.0, 8.0, 8.0)), None); // opaque
    /// let r = m.empty_region(Vec3::new(2.0, 8.0, 8.0)).unwrap();
    /// assert_eq!(m.lookup(Vec3::new(2.0, 8.0, 8.0)), Lookup::Empty(r)); // what lookup reports there
    /// assert_eq!(VolumeMedium::new(vol, tf).empty_region(Vec3::new(2.0, 8.0, 8.0)), None); // no grid
    /// ```
    #[inline]
    fn empty_region(&self, g: Vec3) -> Option<EmptyRegion> {
        match self.lookup(g) {
            Lookup::Empty(r) => Some(r),
            Lookup::Sample(_) => None,
        }
    }

    /// A hint: asks the cache for what [`lookup_x8`](Self::lookup_x8) at `g` will read, a few
    /// steps before it does. Changes no result; the default does nothing. [`integrate_x8`](super::integrate_x8)
    /// calls it about every second step for the positions six steps ahead; a medium over memory the
    /// caches do not hold (a large volume) implements it, as [`VolumeMedium`] does.
    ///
    /// ```
    /// # use strahl::{Vec3, math::f32x8, volume::*};
    /// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
    /// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// # grid.classify(&tf);
    /// # let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    /// // `m`: 16^3 voxels, opaque only where x >= 12, skipping over a grid of 4^3-cell blocks.
    ///
    /// let g = [f32x8::new([0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]), f32x8::splat(8.0), f32x8::splat(8.0)];
    /// let tau = || m.lookup_x8(&g, 0b1111_0000, &mut [EmptyRegion::default(); 8]).unwrap().tau.to_array();
    /// let before = tau();
    /// m.prefetch_x8(&g); // a hint to the cache only
    /// assert_eq!(tau().map(f32::to_bits), before.map(f32::to_bits));
    /// ```
    #[inline(always)]
    fn prefetch_x8(&self, g: &[f32x8; 3]) {
        let _ = g;
    }

    /// Eight lookups. Lanes not set in `active` are not looked at. Returns the samples, or, if any
    /// active lane lies in an empty region, the mask of those lanes (their regions written to
    /// `empty`). Must agree with [`lookup`](Self::lookup) lane by lane, bit for bit.
    ///
    /// ```
    /// # use strahl::{Vec3, math::f32x8, volume::*};
    /// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
    /// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// # grid.classify(&tf);
    /// # let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    /// // `m`: 16^3 voxels, opaque only where x >= 12, skipping over a grid of 4^3-cell blocks.
    ///
    /// let g = [f32x8::new([0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]), f32x8::splat(8.0), f32x8::splat(8.0)];
    /// let mut regions = [EmptyRegion::default(); 8];
    /// assert_eq!(m.lookup_x8(&g, 0xff, &mut regions).unwrap_err(), 0b0000_1111); // lanes at x < 8 jump
    /// assert_eq!(Lookup::Empty(regions[1]), m.lookup(Vec3::new(2.0, 8.0, 8.0)));
    /// let smp = m.lookup_x8(&g, 0b1111_0000, &mut regions).unwrap(); // the others sample
    /// let Lookup::Sample(s) = m.lookup(Vec3::new(14.0, 8.0, 8.0)) else { unreachable!() };
    /// assert_eq!(smp.tau.to_array()[7].to_bits(), s.tau.to_bits());
    /// ```
    #[inline]
    fn lookup_x8(&self, g: &[f32x8; 3], active: u32, empty: &mut [EmptyRegion; 8]) -> Result<SampleX8, u32> {
        match lookup_lanes(self, g, active, empty) {
            (smp, 0) => Ok(smp),
            (_, skip) => Err(skip),
        }
    }

    /// Eight lookups that sample every `active` lane outside an empty region and report the
    /// others: returns the samples and the mask of the `active` lanes in empty regions (their
    /// regions written to `empty`; their sample lanes, and those of inactive lanes, are
    /// unspecified). Must agree with [`lookup`](Self::lookup) lane by lane, bit for bit.
    /// [`integrate_x8`](super::integrate_x8) calls this every step: the lanes in empty regions
    /// jump while the others composite. It asks for a step's lookups before compositing the step
    /// before, so a lane whose ray reaches the opacity threshold may be looked up once more past
    /// its last step (that answer, and any region written for it, is not used); in a step where
    /// lanes take new rays, it asks a second time for those lanes alone. The default asks [`lookup_x8`](Self::lookup_x8) again
    /// for the lanes it did not find empty (and, should that still report empty lanes, looks
    /// those up one by one). A medium may override it to find both in one pass.
    ///
    /// ```
    /// use strahl::math::f32x8;
    /// use strahl::volume::*;
    /// use strahl::Vec3;
    /// // 16^3 voxels, opaque only where x >= 12.
    /// let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
    /// let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// grid.classify(&tf);
    /// let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    /// // Lane l at x = 2 l (local voxel coordinates), y = z = 8.
    /// let g = [f32x8::new([0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]), f32x8::splat(8.0), f32x8::splat(8.0)];
    /// let mut regions = [EmptyRegion::default(); 8];
    /// let (smp, empty) = m.lookup_x8_partial(&g, 0xff, &mut regions);
    /// // Cells of x in 0..8 (two blocks of 4) reach voxels of x <= 8 only: transparent.
    /// assert_eq!(empty, 0b0000_1111);
    /// let tau = smp.tau.to_array();
    /// for l in 4..8 {
    ///     match m.lookup(Vec3::new(2.0 * l as f32, 8.0, 8.0)) {
    ///         Lookup::Sample(s) => assert_eq!(s.tau.to_bits(), tau[l].to_bits()),
    ///         Lookup::Empty(_) => panic!("lane {l} was sampled"),
    ///     }
    /// }
    /// ```
    // PERF: `VolumeMedium` keeps the default. An override computing the cells once (regions of
    // the empty lanes, then samples of all) was 5% slower on the sparse torus (x8, best of 40,
    // taking turns: 4.00 against 3.81 ms): the default's first call returns before sampling.
    #[inline]
    fn lookup_x8_partial(&self, g: &[f32x8; 3], active: u32, empty: &mut [EmptyRegion; 8]) -> (SampleX8, u32) {
        let mask = match self.lookup_x8(g, active, empty) {
            Ok(smp) => return (smp, 0),
            Err(mask) => mask & active,
        };
        let rest = active & !mask;
        let z = f32x8::splat(0.0);
        if rest == 0 {
            return (SampleX8 { tau: z, color: [z; 3] }, mask);
        }
        if let Ok(smp) = self.lookup_x8(g, rest, empty) {
            return (smp, mask);
        }
        // Asked again, the medium found empty lanes it had not reported: one lane at a time.
        let (smp, more) = lookup_lanes(self, g, rest, empty);
        (smp, mask | more)
    }
}

/// `m.lookup` for each lane set in `lanes`: the samples (zero in the other lanes) and the mask
/// of the lanes found empty, their regions written to `empty`.
#[inline]
fn lookup_lanes<M: Medium + ?Sized>(
    m: &M,
    g: &[f32x8; 3],
    lanes: u32,
    empty: &mut [EmptyRegion; 8],
) -> (SampleX8, u32) {
    let (x, y, z) = (g[0].to_array(), g[1].to_array(), g[2].to_array());
    let (mut tau, mut col, mut skip) = ([0.0f32; 8], [[0.0f32; 8]; 3], 0);
    for l in (0..8).filter(|l| lanes >> l & 1 != 0) {
        match m.lookup(Vec3::new(x[l], y[l], z[l])) {
            Lookup::Sample(s) => {
                tau[l] = s.tau;
                for (c, sc) in col.iter_mut().zip(s.color) {
                    c[l] = sc;
                }
            }
            Lookup::Empty(r) => {
                empty[l] = r;
                skip |= 1 << l;
            }
        }
    }
    (
        SampleX8 {
            tau: f32x8::new(tau),
            color: col.map(f32x8::new),
        },
        skip,
    )
}

/// A [`Volume`] seen through a [`TransferFunction`], optionally with a classified
/// [`MacrocellGrid`] for empty-space skipping.
///
/// ```
/// use strahl::Vec3;
/// use strahl::volume::{GridParams, MacrocellGrid, TfEntry, TransferFunction, Volume, VolumeMedium};
/// let data = vec![0u8; 16 * 16 * 16];
/// let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
/// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
/// let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
/// // Not yet classified: refused.
/// assert!(VolumeMedium::new(vol, tf).with_grid(&grid).is_err());
/// grid.classify(&tf);
/// let medium = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
/// ```
#[derive(Clone, Copy, Debug)]
pub struct VolumeMedium<'a, V: Voxel> {
    vol: Volume<'a, V>,
    tf: TransferFunction<'a>,
    grid: Option<GridView<'a>>,
}

impl<'a, V: Voxel> VolumeMedium<'a, V> {
    /// The medium without empty-space skipping.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, volume::*};
    /// let data = [1.0f32; 8];
    /// let vol = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let table = [TfEntry::new([1.0; 3], 0.5)];
    /// let m = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 1.0).unwrap());
    /// assert!(!m.skips());
    /// let ray = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z);
    /// let p = integrate_ray(&m, &ray, &MarchParams::reference(0.25)).unwrap();
    /// assert!((p.a - (1.0 - (-0.5f32).exp())).abs() < 1e-6); // tau 0.5 over length 1
    /// ```
    pub fn new(vol: Volume<'a, V>, tf: TransferFunction<'a>) -> Self {
        Self { vol, tf, grid: None }
    }

    /// The medium with empty-space skipping over `grid`.
    ///
    /// Errors: [`VolumeError::GridMismatch`] if the grid was built for other dimensions,
    /// [`VolumeError::StaleGrid`] if it was not classified with this transfer function (compared by
    /// [`TransferFunction::fingerprint`]). The voxels themselves are not compared (that would read
    /// them all): a grid built from other data of the same dimensions, or before the data
    /// changed, skips blocks by the old values; build it again
    /// ([`MacrocellGrid::build`](super::MacrocellGrid::build)) after the voxels change.
    ///
    /// ```
    /// # use strahl::{Vec3, math::f32x8, volume::*};
    /// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
    /// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// # grid.classify(&tf);
    /// let small = [0u8; 8];
    /// let other = Volume::new(&small, [2; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// assert_eq!(VolumeMedium::new(other, tf).with_grid(&grid).unwrap_err(), VolumeError::GridMismatch);
    /// let denser = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)]; // another table, other empty entries
    /// grid.classify(&TransferFunction::new(&denser, 0.0, 255.0).unwrap());
    /// assert_eq!(VolumeMedium::new(vol, tf).with_grid(&grid).unwrap_err(), VolumeError::StaleGrid);
    /// grid.classify(&tf);
    /// assert!(VolumeMedium::new(vol, tf).with_grid(&grid).unwrap().skips());
    /// ```
    pub fn with_grid<S: AsRef<[Macrocell]>>(self, grid: &'a MacrocellGrid<S>) -> Result<Self, VolumeError> {
        if grid.volume_dims() != self.vol.dims() {
            return Err(VolumeError::GridMismatch);
        }
        if grid.classified_for() != Some(self.tf.fingerprint()) {
            return Err(VolumeError::StaleGrid);
        }
        Ok(Self {
            grid: Some(grid.view()),
            ..self
        })
    }

    /// The volume.
    ///
    /// ```
    /// # use strahl::{Vec3, math::f32x8, volume::*};
    /// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
    /// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// # grid.classify(&tf);
    /// # let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    /// // `m`: 16^3 voxels, opaque only where x >= 12, skipping over a grid of 4^3-cell blocks.
    ///
    /// assert_eq!(m.volume().dims(), [16; 3]);
    /// assert!(core::ptr::eq(m.volume().data(), &data[..])); // borrowed, not copied
    /// ```
    pub fn volume(&self) -> &Volume<'a, V> {
        &self.vol
    }

    /// The transfer function.
    ///
    /// ```
    /// # use strahl::{Vec3, math::f32x8, volume::*};
    /// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
    /// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// # grid.classify(&tf);
    /// # let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    /// // `m`: 16^3 voxels, opaque only where x >= 12, skipping over a grid of 4^3-cell blocks.
    ///
    /// assert_eq!(m.transfer_function().fingerprint(), grid.classified_for().unwrap());
    /// assert_eq!(m.transfer_function().lookup_scalar(255.0), (2.0, [1.0; 3]));
    /// ```
    pub fn transfer_function(&self) -> &TransferFunction<'a> {
        &self.tf
    }

    /// `true` if empty-space skipping is on.
    ///
    /// ```
    /// # use strahl::{Vec3, math::f32x8, volume::*};
    /// # let data: Vec<u8> = (0..16 * 16 * 16).map(|i| if i % 16 >= 12 { 200 } else { 0 }).collect();
    /// # let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let mut grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// # grid.classify(&tf);
    /// # let m = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
    /// // `m`: 16^3 voxels, opaque only where x >= 12, skipping over a grid of 4^3-cell blocks.
    ///
    /// assert!(m.skips());
    /// assert!(!VolumeMedium::new(vol, tf).skips());
    /// ```
    pub fn skips(&self) -> bool {
        self.grid.is_some()
    }
}

impl<V: Voxel> Medium for VolumeMedium<'_, V> {
    fn bounds(&self) -> Aabb {
        self.vol.bounds()
    }

    fn local_frame(&self) -> (Vec3, Vec3) {
        self.vol.local_frame()
    }

    #[inline(always)]
    fn lookup(&self, g: Vec3) -> Lookup {
        if self.vol.is_empty() {
            return Lookup::Sample(Sample::default());
        }
        let cell = self.vol.cell_scalar(g);
        if let Some(grid) = &self.grid
            && let Some(r) = grid.empty_region(cell.idx)
        {
            return Lookup::Empty(r);
        }
        let s = self.vol.interp_scalar(&cell);
        let (tau, color) = self.tf.lookup_scalar(s);
        Lookup::Sample(Sample { tau, color })
    }

    #[inline(always)]
    fn empty_region(&self, g: Vec3) -> Option<EmptyRegion> {
        let grid = self.grid.as_ref()?;
        if self.vol.is_empty() {
            return None;
        }
        grid.empty_region(self.vol.cell_scalar(g).idx)
    }

    #[inline(always)]
    fn prefetch_x8(&self, g: &[f32x8; 3]) {
        self.vol.prefetch_x8(*g);
    }

    #[inline(always)]
    fn lookup_x8(&self, g: &[f32x8; 3], active: u32, empty: &mut [EmptyRegion; 8]) -> Result<SampleX8, u32> {
        if self.vol.is_empty() {
            let z = f32x8::splat(0.0);
            return Ok(SampleX8 { tau: z, color: [z; 3] });
        }
        let cell = self.vol.cell_x8(*g);
        if let Some(grid) = &self.grid {
            let mut bits = grid.empty_mask_x8(&cell.idx, active);
            if bits != 0 {
                let mut skip = 0;
                while bits != 0 {
                    let l = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    if let Some(r) = grid.empty_region([cell.idx[0][l], cell.idx[1][l], cell.idx[2][l]]) {
                        empty[l] = r;
                        skip |= 1 << l;
                    }
                }
                if skip != 0 {
                    return Err(skip);
                }
            }
        }
        let s = self.vol.interp_x8(&cell);
        let (tau, color) = self.tf.lookup_x8(s);
        Ok(SampleX8 { tau, color })
    }
}
