//! Empty-space skipping: a min/max macrocell grid, classified with a transfer function.
//!
//! Cells are the boxes between eight neighbouring voxels; a sample in cell `i` (per axis) reads
//! voxels `i` and `i + 1`. A macrocell is a block of `B^3` cells (`B` = [`GridParams::block`]).
//!
//! # Why the image does not change (bit for bit)
//! 1. **Range with halo.** Macrocell `m` (per axis, cells `mB .. (m+1)B`) stores the minimum and
//!    maximum of voxels `mB - 1 ..= (m+1)B + 1`: the voxels its own samples read (cells `mB` to
//!    `(m+1)B - 1` read up to voxel `(m+1)B`, the interpolation halo) widened by one voxel on each
//!    side. So every sample whose local position lies within half a voxel of the block, the
//!    [`EmptyRegion::safe`](super::EmptyRegion::safe) box `[mB - 1/2, (m+1)B + 1/2]`, interpolates
//!    voxels of this range, and
//!    its value lies in `[min, max]` (up to the rounding of the interpolation, which
//!    [`TransferFunction::is_transparent`](super::TransferFunction::is_transparent) pads for).
//! 2. **Classification.** [`MacrocellGrid::classify`] marks a block empty when the transfer function
//!    has zero extinction over its whole range. A sample with `tau = 0` has `a = 1 - exp(-0) = 0`
//!    exactly ([`one_minus_exp_neg_scalar`](super::one_minus_exp_neg_scalar)`(0) == 0`), so it adds `+0` to `C` and `A`:
//!    skipping it changes no bit.
//! 3. **Same lattice.** The marcher jumps from sample `k` (found in an empty block) to the first
//!    lattice sample `k'` past the exit of the empty region around it (the block, or the cube of
//!    empty blocks around it, see [`MacrocellGrid::classify`]), `t_k' = k' dt`, not to the exit. Before it
//!    jumps it checks that sample `k' - 1`, computed exactly as the marcher would, lies in the safe
//!    box. Sample positions are monotone in `k` on each axis (each rounding is monotone), so then
//!    every skipped sample lies in the safe box too; if the check fails, it skips only sample `k`.
//!
//! Rays marched with and without a grid therefore take the same samples where the medium is not
//! transparent, in the same order, with the same operations; the tests check the images bit for
//! bit.
//!
//! # Transfer function changes
//! The min/max ranges do not depend on the transfer function; the empty flags do. After changing
//! the transfer function call [`MacrocellGrid::classify`] again (`O(macrocells)`, no voxel is
//! read). The grid keeps a [fingerprint](super::TransferFunction::fingerprint) of the function it
//! was classified with, and [`VolumeMedium::with_grid`](super::VolumeMedium::with_grid) refuses a
//! grid whose fingerprint differs ([`VolumeError::StaleGrid`]). Colour-only changes keep the
//! fingerprint.

use super::{EmptyRegion, PreintegratedTable, TfEntry, TransferFunction, Volume, VolumeError, Voxel};
use crate::geometry::Aabb;
use crate::math::i32x8;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// Knobs of empty-space skipping.
///
/// ```
/// use strahl::volume::GridParams;
/// assert_eq!(GridParams::default().block, 8);
/// assert!(GridParams::fine().block < GridParams::coarse().block);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridParams {
    /// Cells per macrocell along each axis: a power of two in `2..=64`. Smaller blocks fit the
    /// empty space more tightly (more skipping) but cost more jumps and memory (`12` bytes per
    /// block).
    pub block: u32,
}

impl Default for GridParams {
    /// `block = 8`: 512 cells per macrocell, the usual compromise (a 256^3 volume has 32^3 blocks).
    fn default() -> Self {
        Self { block: 8 }
    }
}

impl GridParams {
    /// `block = 4`: tight around thin structures; 8x the blocks of the default.
    ///
    /// ```
    /// use strahl::volume::{GridParams, Macrocell, MacrocellGrid};
    /// let blocks = |p| MacrocellGrid::<Vec<Macrocell>>::len_for([33; 3], p).unwrap();
    /// assert_eq!(GridParams::fine().block, 4);
    /// assert_eq!(blocks(GridParams::fine()), 8 * blocks(GridParams::default()));
    /// ```
    pub const fn fine() -> Self {
        Self { block: 4 }
    }

    /// `block = 16`: few jumps, for volumes with large empty regions.
    ///
    /// ```
    /// use strahl::volume::{GridParams, Macrocell, MacrocellGrid};
    /// assert_eq!(GridParams::coarse().block, 16);
    /// let dims = MacrocellGrid::<Vec<Macrocell>>::macro_dims_for([257; 3], GridParams::coarse());
    /// assert_eq!(dims, Ok([16; 3])); // 256 cells per axis in blocks of 16
    /// ```
    pub const fn coarse() -> Self {
        Self { block: 16 }
    }

    fn shift(&self) -> Result<u32, VolumeError> {
        if self.block.is_power_of_two() && (2..=64).contains(&self.block) {
            Ok(self.block.trailing_zeros())
        } else {
            Err(VolumeError::InvalidBlock)
        }
    }
}

/// One macrocell: the value range of the voxels its samples can read, and whether the current
/// transfer function makes it transparent.
///
/// ```
/// use strahl::Vec3;
/// use strahl::volume::{GridParams, MacrocellGrid, Volume};
/// let data: Vec<u8> = (0..17).collect(); // one row of 17 voxels, 16 cells: two blocks of 8
/// let vol = Volume::new(&data, [17, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
/// let grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
/// let c = grid.cells();
/// assert_eq!((c[0].min, c[0].max), (0.0, 9.0)); // voxels 0..=8 and one beyond
/// assert_eq!((c[1].min, c[1].max), (7.0, 16.0)); // one before 8..=16
/// assert_eq!(c[0].empty, 0); // not classified yet
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Macrocell {
    /// Smallest voxel value (`-inf` if any voxel in range is not finite).
    pub min: f32,
    /// Largest voxel value (`+inf` if any voxel in range is not finite).
    pub max: f32,
    /// `0` if not transparent for the transfer function of the last classification; else
    /// `d >= 1`, and every macrocell within chessboard distance `d - 1` is transparent too.
    pub empty: u32,
}

const _: () = assert!(core::mem::size_of::<Macrocell>() == 12);

/// A min/max macrocell grid over a volume, with its cells in storage `S` (a `Vec<Macrocell>`, or
/// a caller's `&mut [Macrocell]` without `alloc`).
///
/// ```
/// use strahl::Vec3;
/// use strahl::volume::{GridParams, MacrocellGrid, TfEntry, TransferFunction, Volume};
/// let data = vec![0u8; 33 * 33 * 33];
/// let vol = Volume::new(&data, [33; 3], Vec3::ONE, Vec3::ZERO).unwrap();
/// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
/// assert_eq!(grid.macro_dims(), [4, 4, 4]); // 32 cells per axis in blocks of 8
/// // Values up to 127 are clear, 255 is opaque.
/// let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
/// let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// grid.classify(&tf);
/// assert_eq!(grid.empty_fraction(), 1.0);
/// ```
#[derive(Clone, Debug)]
pub struct MacrocellGrid<S> {
    cells: S,
    vdims: [u32; 3],
    mdims: [u32; 3],
    shift: u32,
    /// Fingerprint of the transfer function of the last classification, if any.
    classified: Option<u64>,
}

/// What the marcher needs of a grid: a borrowed, copyable view.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GridView<'a> {
    cells: &'a [Macrocell],
    mdims: [u32; 3],
    shift: u32,
    /// `dims - 1` per axis: the upper bound of local coordinates.
    gmax: [f32; 3],
}

impl<'a> GridView<'a> {
    /// The empty region around a sample in cell `idx`, if its macrocell is empty: the cube of
    /// macrocells within chessboard distance `empty - 1` of it (all empty), clipped to the grid, in
    /// local (voxel) coordinates.
    #[inline(always)]
    pub(crate) fn region(&self, idx: [i32; 3]) -> Option<Aabb> {
        let m = idx.map(|i| (i as u32) >> self.shift);
        let k = m[0] as usize + self.mdims[0] as usize * (m[1] as usize + self.mdims[1] as usize * m[2] as usize);
        let d = self.cells.get(k)?.empty;
        if d == 0 {
            return None;
        }
        let r = d - 1;
        let b = (1u32 << self.shift) as f32;
        let lo = Vec3::new(
            m[0].saturating_sub(r) as f32,
            m[1].saturating_sub(r) as f32,
            m[2].saturating_sub(r) as f32,
        );
        let hi = Vec3::new(
            (m[0] + r + 1).min(self.mdims[0]) as f32,
            (m[1] + r + 1).min(self.mdims[1]) as f32,
            (m[2] + r + 1).min(self.mdims[2]) as f32,
        );
        Some(Aabb::new(lo * b, hi * b))
    }

    /// Of the `active` lanes among eight cells (`idx[axis][lane]`, in the volume), those whose
    /// macrocell is empty: one index computation 8-wide and eight loads, no branch per lane.
    // PERF: the per-lane `region` call on every step was about 30% of the x8 marcher's time on the
    // sparse torus bench (`volume_skipping`), where most steps are in non-empty blocks.
    #[inline(always)]
    pub(crate) fn empty_mask_x8(&self, idx: &[[i32; 8]; 3], active: u32) -> u32 {
        let shift = self.shift;
        let m = idx.map(|a| i32x8::new(a) >> shift);
        // Cells are within the volume, so the linear index is below the number of macrocells
        // (< 2^31, as voxels are).
        let k =
            (m[0] + i32x8::splat(self.mdims[0] as i32) * (m[1] + i32x8::splat(self.mdims[1] as i32) * m[2])).to_array();
        let mut mask = 0;
        for (l, &k) in k.iter().enumerate() {
            let e = self.cells.get(k as u32 as usize).map_or(0, |c| c.empty);
            mask |= ((e != 0) as u32) << l;
        }
        mask & active
    }

    /// The exit box of a region: the blocks, clipped to the volume.
    #[inline]
    pub(crate) fn exit_box(&self, block: &Aabb) -> Aabb {
        Aabb::new(block.min, block.max.min(Vec3::from_array(self.gmax)))
    }

    /// The region the marcher may jump across around a sample in cell `idx`, if its macrocell is
    /// empty: the blocks of [`region`](Self::region) to exit, and their safe box (half a voxel
    /// wider, point 1 of the module docs).
    #[inline(always)]
    pub(crate) fn empty_region(&self, idx: [i32; 3]) -> Option<EmptyRegion> {
        let block = self.region(idx)?;
        Some(EmptyRegion {
            exit: self.exit_box(&block),
            safe: Aabb::new(block.min - Vec3::splat(0.5), block.max + Vec3::splat(0.5)),
        })
    }
}

impl<S: AsRef<[Macrocell]>> MacrocellGrid<S> {
    /// Macrocells per axis for a volume of `dims` voxels: `ceil(cells / block)`, with
    /// `cells = max(dims - 1, 1)` (`0` for an empty volume).
    ///
    /// ```
    /// use strahl::volume::{GridParams, Macrocell, MacrocellGrid, VolumeError};
    /// type Grid = MacrocellGrid<Vec<Macrocell>>;
    /// let p = GridParams::default();
    /// assert_eq!(Grid::macro_dims_for([33, 17, 2], p), Ok([4, 2, 1])); // 32, 16 and 1 cells
    /// assert_eq!(Grid::macro_dims_for([0, 5, 5], p), Ok([0; 3]));
    /// assert_eq!(Grid::macro_dims_for([9; 3], GridParams { block: 3 }), Err(VolumeError::InvalidBlock));
    /// ```
    pub fn macro_dims_for(dims: [u32; 3], params: GridParams) -> Result<[u32; 3], VolumeError> {
        let shift = params.shift()?;
        if dims.contains(&0) {
            return Ok([0; 3]);
        }
        Ok(dims.map(|d| (d.saturating_sub(1).max(1) + (1 << shift) - 1) >> shift))
    }

    /// Number of macrocells [`build_in`](Self::build_in) needs room for.
    ///
    /// ```
    /// use strahl::volume::{GridParams, Macrocell, MacrocellGrid};
    /// let n = MacrocellGrid::<&mut [Macrocell]>::len_for([33, 17, 2], GridParams::default());
    /// assert_eq!(n, Ok(4 * 2 * 1));
    /// ```
    pub fn len_for(dims: [u32; 3], params: GridParams) -> Result<usize, VolumeError> {
        let m = Self::macro_dims_for(dims, params)?;
        Ok(m.iter().map(|&d| d as usize).product())
    }

    /// Macrocells per axis.
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::{GridParams, MacrocellGrid, Volume};
    /// # let data = vec![0u8; 33 * 17 * 2];
    /// let vol = Volume::new(&data, [33, 17, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// assert_eq!(grid.macro_dims(), [4, 2, 1]);
    /// ```
    pub fn macro_dims(&self) -> [u32; 3] {
        self.mdims
    }

    /// Voxel dimensions of the volume the grid was built for.
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::{GridParams, MacrocellGrid, Volume};
    /// # let data = vec![0u8; 33 * 17 * 2];
    /// let vol = Volume::new(&data, [33, 17, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// assert_eq!(grid.volume_dims(), vol.dims());
    /// ```
    pub fn volume_dims(&self) -> [u32; 3] {
        self.vdims
    }

    /// Cells per macrocell along each axis.
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::{GridParams, MacrocellGrid, Volume};
    /// # let data = vec![0u8; 33 * 17 * 2];
    /// # let vol = Volume::new(&data, [33, 17, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let grid = MacrocellGrid::build(&vol, GridParams::fine()).unwrap();
    /// assert_eq!((grid.block(), grid.macro_dims()), (4, [8, 4, 1]));
    /// ```
    pub fn block(&self) -> u32 {
        1 << self.shift
    }

    /// The macrocells, x fastest.
    ///
    /// ```
    /// use strahl::Vec3;
    /// use strahl::volume::{GridParams, MacrocellGrid, Volume};
    /// let mut data = vec![0u8; 33 * 17 * 2];
    /// data[32 + 33 * 16] = 9; // the last voxel along x and y, at z = 0
    /// let vol = Volume::new(&data, [33, 17, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// let maxima: Vec<f32> = grid.cells().iter().map(|c| c.max).collect();
    /// assert_eq!(maxima, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 9.0]); // 4 x 2 x 1 blocks
    /// ```
    pub fn cells(&self) -> &[Macrocell] {
        &self.cells.as_ref()[..self.len()]
    }

    fn len(&self) -> usize {
        self.mdims.iter().map(|&d| d as usize).product()
    }

    /// Fingerprint of the transfer function of the last [`classify`](Self::classify), if any.
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::*;
    /// # let mut data = [0u8; 17];
    /// # data[16] = 255; // the last voxel: in block 1's range only
    /// # let vol = Volume::new(&data, [17, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// assert_eq!(grid.classified_for(), None);
    /// grid.classify(&tf);
    /// assert_eq!(grid.classified_for(), Some(tf.fingerprint()));
    /// ```
    pub fn classified_for(&self) -> Option<u64> {
        self.classified
    }

    /// Fraction of macrocells classified empty (`0` for a grid without macrocells).
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::*;
    /// # let mut data = [0u8; 17];
    /// # data[16] = 255; // the last voxel: in block 1's range only
    /// # let vol = Volume::new(&data, [17, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// assert_eq!(grid.empty_fraction(), 0.0); // unclassified: nothing is empty
    /// grid.classify(&tf);
    /// assert_eq!(grid.empty_fraction(), 0.5); // block 0 reads only zeros, block 1 reads 255
    /// ```
    pub fn empty_fraction(&self) -> f32 {
        let c = self.cells();
        if c.is_empty() {
            return 0.0;
        }
        c.iter().filter(|m| m.empty != 0).count() as f32 / c.len() as f32
    }

    pub(crate) fn view(&self) -> GridView<'_> {
        GridView {
            cells: self.cells(),
            mdims: self.mdims,
            shift: self.shift,
            gmax: self.vdims.map(|d| d.saturating_sub(1) as f32),
        }
    }
}

impl<S: AsRef<[Macrocell]> + AsMut<[Macrocell]>> MacrocellGrid<S> {
    /// Builds the min/max grid of `vol` in `storage` (at least [`len_for`](Self::len_for) cells),
    /// unclassified: every block counts as non-empty until [`classify`](Self::classify). Reads each
    /// voxel about `((B + 3) / B)^3` times (1.6 times for `B = 8`).
    ///
    /// ```
    /// use strahl::Vec3;
    /// use strahl::volume::{GridParams, Macrocell, MacrocellGrid, Volume};
    /// let data = [7u8; 27];
    /// let vol = Volume::new(&data, [3, 3, 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let mut storage = [Macrocell::default(); 1]; // no allocation
    /// let grid = MacrocellGrid::build_in(&vol, GridParams::default(), &mut storage[..]).unwrap();
    /// assert_eq!((grid.cells()[0].min, grid.cells()[0].max), (7.0, 7.0));
    /// ```
    pub fn build_in<V: Voxel>(vol: &Volume<'_, V>, params: GridParams, mut storage: S) -> Result<Self, VolumeError> {
        let shift = params.shift()?;
        let vdims = vol.dims();
        let mdims = Self::macro_dims_for(vdims, params)?;
        let needed = mdims.iter().map(|&d| d as usize).product::<usize>();
        let cells = storage.as_mut();
        if cells.len() < needed {
            return Err(VolumeError::StorageTooSmall {
                needed,
                actual: cells.len(),
            });
        }
        let data = vol.data();
        let (nx, nxy) = (vdims[0] as usize, vdims[0] as usize * vdims[1] as usize);
        let b = 1usize << shift;
        // Voxel range of block m on one axis: mB - 1 ..= (m+1)B + 1, clipped.
        let range = |m: u32, d: u32| {
            let lo = (m as usize * b).saturating_sub(1);
            let hi = ((m as usize + 1) * b + 1).min(d as usize - 1);
            lo..=hi
        };
        for mz in 0..mdims[2] {
            for my in 0..mdims[1] {
                for mx in 0..mdims[0] {
                    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                    for z in range(mz, vdims[2]) {
                        for y in range(my, vdims[1]) {
                            let row = z * nxy + y * nx;
                            for &v in &data[row + *range(mx, vdims[0]).start()..=row + *range(mx, vdims[0]).end()] {
                                let v = v.to_f32();
                                lo = if v < lo { v } else { lo };
                                hi = if v > hi { v } else { hi };
                                if !v.is_finite() {
                                    // A non-finite voxel can make any interpolated value (or NaN).
                                    lo = f32::NEG_INFINITY;
                                    hi = f32::INFINITY;
                                }
                            }
                        }
                    }
                    let k = mx as usize + mdims[0] as usize * (my as usize + mdims[1] as usize * mz as usize);
                    cells[k] = Macrocell {
                        min: lo,
                        max: hi,
                        empty: 0,
                    };
                }
            }
        }
        Ok(Self {
            cells: storage,
            vdims,
            mdims,
            shift,
            classified: None,
        })
    }

    /// Marks each macrocell empty or not for `tf`, and remembers `tf`'s fingerprint. Call it again
    /// whenever the transfer function changes. Reads no voxel; `O(macrocells)`.
    ///
    /// An empty macrocell also gets its chessboard distance `d` to the nearest non-empty one
    /// (`empty = d`, capped at [`MAX_EMPTY_RADIUS`]): every macrocell within distance `d - 1` is
    /// empty too, so the marcher jumps across that whole cube at once (the "proximity clouds" of
    /// D. Cohen, Z. Sheffer, "Proximity clouds: an acceleration technique for 3D grid traversal",
    /// The Visual Computer 11, 1994). Two raster passes over the 26-neighbourhood compute it.
    ///
    /// ```
    /// use strahl::Vec3;
    /// use strahl::volume::{GridParams, MacrocellGrid, TfEntry, TransferFunction, Volume};
    /// let mut data = [0u8; 33]; // one row, four blocks of 8 cells
    /// data[32] = 255; // seen only by the last block
    /// let vol = Volume::new(&data, [33, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// grid.classify(&TransferFunction::new(&table, 0.0, 255.0).unwrap());
    /// let empty: Vec<u32> = grid.cells().iter().map(|c| c.empty).collect();
    /// assert_eq!(empty, [3, 2, 1, 0]); // distance to the non-empty block
    /// ```
    pub fn classify(&mut self, tf: &TransferFunction<'_>) {
        self.classify_by(tf.fingerprint(), |min, max| tf.is_transparent(min, max));
    }

    /// [`classify`](Self::classify) for the pre-integrated marchers: a block is empty where every
    /// segment between values of its range has zero extinction in `table`
    /// ([`PreintegratedTable::is_transparent`]); remembers `table`'s fingerprint, which
    /// [`PreintegratedMedium::with_grid`](super::PreintegratedMedium::with_grid) checks (and which
    /// no transfer function's fingerprint equals, so a grid classified for one kind of marcher is
    /// refused by the other).
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::*;
    /// # let mut data = [0u8; 17];
    /// # data[16] = 255; // the last voxel: in block 1's range only
    /// # let vol = Volume::new(&data, [17, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.5, 16).unwrap();
    /// grid.classify_preintegrated(&pre);
    /// assert_eq!(grid.classified_for(), Some(pre.fingerprint()));
    /// assert_eq!(grid.cells().iter().map(|c| c.empty != 0).collect::<Vec<_>>(), [true, false]);
    /// ```
    pub fn classify_preintegrated<T: AsRef<[TfEntry]>>(&mut self, table: &PreintegratedTable<T>) {
        self.classify_by(table.fingerprint(), |min, max| table.is_transparent(min, max));
    }

    fn classify_by(&mut self, fingerprint: u64, transparent: impl Fn(f32, f32) -> bool) {
        let n = self.len();
        let [mx, my, mz] = self.mdims.map(|d| d as i64);
        let cells = &mut self.cells.as_mut()[..n];
        for m in cells.iter_mut() {
            // NaN or infinite voxels made min = -inf, max = +inf: the whole table is checked.
            m.empty = if transparent(m.min, m.max) { MAX_EMPTY_RADIUS } else { 0 };
        }
        let idx = |x: i64, y: i64, z: i64| (x + mx * (y + my * z)) as usize;
        // Forward pass: neighbours before (x, y, z) in raster order; backward: after.
        for backward in [false, true] {
            let s = if backward { -1 } else { 1 };
            for zi in 0..mz {
                let z = if backward { mz - 1 - zi } else { zi };
                for yi in 0..my {
                    let y = if backward { my - 1 - yi } else { yi };
                    for xi in 0..mx {
                        let x = if backward { mx - 1 - xi } else { xi };
                        let mut d = cells[idx(x, y, z)].empty;
                        if d == 0 {
                            continue;
                        }
                        for (dx, dy, dz) in HALF_NEIGHBOURHOOD {
                            let (nx, ny, nz) = (x - s * dx, y - s * dy, z - s * dz);
                            if (0..mx).contains(&nx) && (0..my).contains(&ny) && (0..mz).contains(&nz) {
                                d = d.min(cells[idx(nx, ny, nz)].empty.saturating_add(1));
                            }
                        }
                        cells[idx(x, y, z)].empty = d;
                    }
                }
            }
        }
        self.classified = Some(fingerprint);
    }
}

/// Largest distance [`MacrocellGrid::classify`] stores in [`Macrocell::empty`].
///
/// ```
/// use strahl::Vec3;
/// use strahl::volume::{GridParams, MAX_EMPTY_RADIUS, MacrocellGrid, TfEntry, TransferFunction, Volume};
/// let data = [0u8; 33 * 33 * 33];
/// let vol = Volume::new(&data, [33; 3], Vec3::ONE, Vec3::ZERO).unwrap();
/// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
/// grid.classify(&TransferFunction::new(&[TfEntry::TRANSPARENT], 0.0, 1.0).unwrap());
/// assert!(grid.cells().iter().all(|c| c.empty == MAX_EMPTY_RADIUS)); // nothing to be near
/// ```
pub const MAX_EMPTY_RADIUS: u32 = 1 << 16;

/// The 13 neighbours that precede a cell in raster order (x fastest), as `(dx, dy, dz)` to
/// subtract.
const HALF_NEIGHBOURHOOD: [(i64, i64, i64); 13] = [
    (1, 0, 0),
    (-1, 1, 0),
    (0, 1, 0),
    (1, 1, 0),
    (-1, -1, 1),
    (0, -1, 1),
    (1, -1, 1),
    (-1, 0, 1),
    (0, 0, 1),
    (1, 0, 1),
    (-1, 1, 1),
    (0, 1, 1),
    (1, 1, 1),
];

#[cfg(feature = "alloc")]
impl MacrocellGrid<alloc::vec::Vec<Macrocell>> {
    /// Builds the grid in a new `Vec` (feature `alloc`); see [`build_in`](Self::build_in).
    ///
    /// ```
    /// use strahl::Vec3;
    /// use strahl::volume::{GridParams, MacrocellGrid, Volume, VolumeError};
    /// let data: Vec<f32> = (0..9 * 9 * 9).map(|i| i as f32).collect();
    /// let vol = Volume::new(&data, [9; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let grid = MacrocellGrid::build(&vol, GridParams { block: 4 }).unwrap();
    /// assert_eq!(grid.cells().len(), 8); // 8 cells per axis in blocks of 4
    /// assert_eq!((grid.cells()[0].min, grid.cells()[7].max), (0.0, 728.0));
    /// assert_eq!(MacrocellGrid::build(&vol, GridParams { block: 5 }).unwrap_err(), VolumeError::InvalidBlock);
    /// ```
    pub fn build<V: Voxel>(vol: &Volume<'_, V>, params: GridParams) -> Result<Self, VolumeError> {
        let n = Self::len_for(vol.dims(), params)?;
        Self::build_in(vol, params, alloc::vec![Macrocell::default(); n])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_include_the_halo() {
        // 17 voxels along x (16 cells, two blocks of 8); a spike at voxel 9 (inside block 1, and
        // one past block 0's halo voxel 8, so in block 0's widened range).
        let mut data = [0.0f32; 17];
        data[9] = 5.0;
        let vol = Volume::new(&data, [17, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
        let mut storage = [Macrocell::default(); 2];
        let g = MacrocellGrid::build_in(&vol, GridParams::default(), &mut storage[..]).unwrap();
        assert_eq!(g.macro_dims(), [2, 1, 1]);
        assert_eq!(g.cells()[0].max, 5.0);
        assert_eq!(g.cells()[1].max, 5.0);
        data[9] = 0.0;
        data[10] = 5.0;
        let vol = Volume::new(&data, [17, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
        let g = MacrocellGrid::build_in(&vol, GridParams::default(), &mut storage[..]).unwrap();
        assert_eq!(g.cells()[0].max, 0.0);
        // A NaN voxel widens the range to everything.
        data[3] = f32::NAN;
        let vol = Volume::new(&data, [17, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
        let g = MacrocellGrid::build_in(&vol, GridParams::default(), &mut storage[..]).unwrap();
        assert_eq!((g.cells()[0].min, g.cells()[0].max), (f32::NEG_INFINITY, f32::INFINITY));
    }

    #[test]
    fn classification_stores_chessboard_distances() {
        // 7 blocks of 2 cells per axis (15 voxels); one opaque voxel in the middle block.
        let mut data = [0u8; 15 * 15 * 15];
        data[7 + 15 * 7 + 225 * 7] = 255;
        let vol = Volume::new(&data, [15; 3], Vec3::ONE, Vec3::ZERO).unwrap();
        let mut storage = [Macrocell::default(); 343];
        let mut g = MacrocellGrid::build_in(&vol, GridParams { block: 2 }, &mut storage[..]).unwrap();
        let table = [
            crate::volume::TfEntry::TRANSPARENT,
            crate::volume::TfEntry::TRANSPARENT,
            crate::volume::TfEntry::new([1.0; 3], 1.0),
        ];
        let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
        g.classify(&tf);
        let non_empty: alloc_free::Set = g
            .cells()
            .iter()
            .enumerate()
            .filter(|(_, m)| m.empty == 0)
            .map(|(i, _)| i)
            .collect();
        assert!(non_empty.n > 0);
        let at = |i: usize| [i % 7, i / 7 % 7, i / 49].map(|v| v as i64);
        for (i, m) in g.cells().iter().enumerate() {
            let want = non_empty.items[..non_empty.n]
                .iter()
                .map(|&j| {
                    let (a, b) = (at(i), at(j));
                    (0..3).map(|k| (a[k] - b[k]).abs()).max().unwrap() as u32
                })
                .min()
                .unwrap();
            assert_eq!(m.empty, want, "block {:?}", at(i));
        }
        // Nothing visible at all: every block gets the cap.
        let clear = [crate::volume::TfEntry::TRANSPARENT];
        g.classify(&TransferFunction::new(&clear, 0.0, 255.0).unwrap());
        assert!(g.cells().iter().all(|m| m.empty == MAX_EMPTY_RADIUS));
    }

    /// A fixed-size set, so the test needs no allocation.
    mod alloc_free {
        pub struct Set {
            pub items: [usize; 64],
            pub n: usize,
        }
        impl FromIterator<usize> for Set {
            fn from_iter<I: IntoIterator<Item = usize>>(it: I) -> Self {
                let mut s = Set { items: [0; 64], n: 0 };
                for i in it {
                    s.items[s.n] = i;
                    s.n += 1;
                }
                s
            }
        }
    }

    #[test]
    fn errors_and_empty_volume() {
        let data = [0u8; 8];
        let vol = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
        for block in [0, 1, 3, 128] {
            assert_eq!(
                MacrocellGrid::build_in(&vol, GridParams { block }, &mut [Macrocell::default(); 1][..]).unwrap_err(),
                VolumeError::InvalidBlock
            );
        }
        assert_eq!(
            MacrocellGrid::build_in(&vol, GridParams::default(), &mut [][..]).unwrap_err(),
            VolumeError::StorageTooSmall { needed: 1, actual: 0 }
        );
        let empty = Volume::<u8>::new(&[], [0, 0, 0], Vec3::ONE, Vec3::ZERO).unwrap();
        let g = MacrocellGrid::build_in(&empty, GridParams::default(), &mut [][..]).unwrap();
        assert_eq!(g.cells().len(), 0);
        assert_eq!(g.empty_fraction(), 0.0);
    }
}
