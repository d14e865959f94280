//! Pre-integrated transfer functions (Engel, Kraus and Ertl, "High-Quality Pre-Integrated Volume
//! Rendering Using Hardware-Accelerated Pixel Shading", Graphics Hardware 2001).
//!
//! The Riemann marcher ([`integrate`](super::integrate)) samples `tau` and `c` at one point per
//! step, so a transfer function with features narrower than the scalar change over a step (a thin
//! iso-band, a sharp ramp) is aliased unless the step is small. Pre-integration samples the
//! *scalar* at both ends of each step instead, `s_f` at its front and `s_b` at its back, assumes
//! the scalar varies linearly in between, and looks the step's whole contribution up in a 2D
//! table indexed by `(s_f, s_b)`, integrated in advance through every transfer-function entry the
//! step crosses. For a scalar that is linear along a step, the step is then exact whatever the
//! transfer function does within it (up to the table's resolution, below).
//!
//! # What the table holds
//! Entry `(i, j)` is the segment of length `dt` ([`PreintegratedTable::step`]) along which the
//! scalar runs linearly from node value `v_i` to `v_j`, with `v_i = lo + i (hi - lo) / (res - 1)`
//! over the transfer function's range `[lo, hi]`. It is stored as a [`TfEntry`] in the
//! marcher's own terms, so that the usual step
//!
//! ```text
//! a = 1 - exp(-tau h)        C += (1 - A) a c        A += (1 - A) a
//! ```
//!
//! gives the segment's exact opacity and premultiplied colour:
//!
//! - `tau` = the mean extinction over the segment, `int tau(s) ds / (v_j - v_i)` (the value at
//!   `v_i` where `i = j`): the segment's optical depth is `tau dt`, exactly (it is the integral
//!   of a piecewise-linear function, summed in `f64`);
//! - `c` = the attenuation-weighted mean colour, `int c tau T dt / int tau T dt` with `T` the
//!   transmittance from the segment's front, so that `a c` is the segment's emission
//!   `int c tau T dt` (computed in `f64` by 4-point Gauss-Legendre quadrature on pieces between
//!   transfer-function nodes, each cut so that its optical depth is at most 1/4: relative error
//!   below `1e-9`; the integration stops where the optical depth reaches 50, beyond which
//!   nothing passes in `f32`). Where the segment has no extinction, `c` is the plain mean colour
//!   (it is multiplied by `a = 0`).
//!
//! # Lookup and accuracy
//! A pair `(s_f, s_b)` maps to table coordinates as [`TransferFunction`] maps a value (clamped to
//! the range; NaN reads node 0) and interpolates the four nearest entries bilinearly. So a step
//! is exact (to `f32` rounding) where the scalar is linear along it and `s_f`, `s_b` lie on table
//! nodes (`tests/volume.rs` checks this against an `f64` integration of the model); elsewhere the
//! table's interpolation error adds, which falls with the resolution. Values outside `[lo, hi]` are
//! clamped before the lookup, as if the scalar stayed at the range's end (exact only where the
//! whole segment is outside on one side). Only the last step of a ray is shorter than `dt`: its
//! opacity `1 - exp(-tau h)` is exact, its colour is the full segment's weighted mean (exact where
//! the colour is constant along it).
//!
//! # Cost
//! Building a table costs about `res^2` times the number of transfer-function intervals a segment
//! crosses (those with extinction cost about eight times those without, which are only summed):
//! 0.25 to 0.4 s for `256^2` entries over a 256-entry transfer function with extinction
//! everywhere, 60 ms where most entries are clear (one thread, AMD EPYC), and it must be redone
//! when the transfer function or the step changes. So that a build always ends in reasonable time,
//! `res^2 (entries - 1)` is capped at [`PREINTEGRATED_MAX_WORK`] (a 512^2 table over 4097
//! entries; tens of seconds at most). Marching costs
//! one trilinear sample per step (the back sample of one step is the front sample of the next)
//! and a bilinear lookup in the table instead of a linear one.
//!
//! # Empty-space skipping
//! A [`MacrocellGrid`] classified with [`MacrocellGrid::classify_preintegrated`] marks the blocks
//! whose value range only reads zero-extinction segments of the table
//! ([`PreintegratedTable::is_transparent`]); [`PreintegratedMedium::with_grid`] uses it. The
//! marchers skip a run of steps only where the front of the first and the back of the last lie in
//! one empty region's safe box (positions are monotone along the ray, so every skipped step lies
//! in it, and each adds exactly `+0`), then resume with the front sample the marcher without a
//! grid would have carried: the image is bit-identical with and without skipping.

use super::grid::Volume;
use super::skip::GridView;
use super::transfer::{TfEntry, TransferFunction};
use super::{EmptyRegion, Macrocell, MacrocellGrid, VolumeError, Voxel};
use crate::geometry::Aabb;
use crate::math::{Lane, abs, f32x8, i32x8, max_l, min_l};
use glam::Vec3;

/// Largest table resolution (nodes per axis): `512`, so a table holds at most `2^18` entries
/// (4 MB).
///
/// ```
/// use strahl::volume::{PREINTEGRATED_MAX_RES, PreintegratedTable, TfEntry, TransferFunction, VolumeError};
/// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
/// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
/// let mut none: [TfEntry; 0] = [];
/// let mut err = |res| PreintegratedTable::build_in(&tf, 0.5, res, &mut none[..]).unwrap_err();
/// let needed = (PREINTEGRATED_MAX_RES * PREINTEGRATED_MAX_RES) as usize;
/// assert_eq!(err(PREINTEGRATED_MAX_RES), VolumeError::StorageTooSmall { needed, actual: 0 });
/// assert_eq!(err(PREINTEGRATED_MAX_RES + 1), VolumeError::InvalidResolution);
/// ```
pub const PREINTEGRATED_MAX_RES: u32 = 512;

/// Largest `res^2 (entries - 1)` a table may be built for (`2^30`): the intervals its segments
/// walk, which bounds the build time (see the module docs).
///
/// ```
/// use strahl::volume::{PREINTEGRATED_MAX_WORK, PreintegratedTable, TfEntry, TransferFunction, VolumeError};
/// assert_eq!(PREINTEGRATED_MAX_WORK, 512 * 512 * 4096);
/// let long = vec![TfEntry::TRANSPARENT; 4098]; // 4097 intervals
/// let tf = TransferFunction::new(&long, 0.0, 1.0).unwrap();
/// let big = PreintegratedTable::build(&tf, 0.1, 512).map(|_| ());
/// assert_eq!(big, Err(VolumeError::InvalidResolution)); // refused before any work
/// assert!(PreintegratedTable::build(&tf, 0.1, 16).is_ok());
/// ```
pub const PREINTEGRATED_MAX_WORK: u64 = 1 << 30;

/// Optical depth per quadrature piece (see the module docs).
const PIECE_DEPTH: f64 = 0.25;
/// Optical depth at which a segment's integration stops: `exp(-50) = 2e-22`.
const DEPTH_CUTOFF: f64 = 50.0;

/// 4-point Gauss-Legendre nodes and weights on `[-1, 1]`.
const GL_X: [f64; 4] = [
    -0.861_136_311_594_052_6,
    -0.339_981_043_584_856_3,
    0.339_981_043_584_856_3,
    0.861_136_311_594_052_6,
];
const GL_W: [f64; 4] = [
    0.347_854_845_137_453_9,
    0.652_145_154_862_546_1,
    0.652_145_154_862_546_1,
    0.347_854_845_137_453_9,
];

/// A pre-integrated transfer function: a `res x res` table of segment contributions for one step
/// length, built from a [`TransferFunction`] (see the [module docs](self)). `S` is the storage,
/// a `Vec<TfEntry>` from [`build`](PreintegratedTable::build) (feature `alloc`) or a caller's
/// slice from [`build_in`](PreintegratedTable::build_in).
///
/// ```
/// use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
/// // A thin opaque band around value 0.5, clear elsewhere.
/// let mut table = [TfEntry::TRANSPARENT; 64];
/// table[32] = TfEntry::new([1.0, 0.8, 0.2], 40.0);
/// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
/// let pre = PreintegratedTable::build(&tf, 0.1, 64).unwrap();
/// // A step whose scalar runs from 0.2 to 0.8 crosses the band (a point sample at either end sees nothing):
/// let (tau, c) = pre.lookup_scalar(0.2, 0.8);
/// assert!(tau > 0.0 && (c[1] / c[0] - 0.8).abs() < 1e-4);
/// assert_eq!(tf.lookup_scalar(0.2).0 + tf.lookup_scalar(0.8).0, 0.0);
/// // A step that stays below the band sees nothing either way.
/// assert_eq!(pre.lookup_scalar(0.1, 0.3).0, 0.0);
/// ```
#[derive(Clone, Copy, Debug)]
pub struct PreintegratedTable<S> {
    entries: S,
    res: u32,
    lo: f32,
    hi: f32,
    scale: f32,
    last: f32,
    step: f32,
    fingerprint: u64,
}

/// Entries a table of `res` nodes per axis needs, or the error for a bad `res`.
fn len_for(res: u32) -> Result<usize, VolumeError> {
    if !(2..=PREINTEGRATED_MAX_RES).contains(&res) {
        return Err(VolumeError::InvalidResolution);
    }
    Ok(res as usize * res as usize)
}

impl<S: AsRef<[TfEntry]> + AsMut<[TfEntry]>> PreintegratedTable<S> {
    /// Builds the table of `tf` for steps of length `step` (world units) with `res` nodes per
    /// axis, in `storage` (at least `res * res` entries; the first `res * res` are used).
    ///
    /// Errors: [`VolumeError::InvalidStep`] unless `step` is finite and positive,
    /// [`VolumeError::InvalidResolution`] unless `res` lies in `2..=`[`PREINTEGRATED_MAX_RES`] and
    /// `res^2 (entries - 1)` is at most [`PREINTEGRATED_MAX_WORK`], [`VolumeError::StorageTooSmall`].
    ///
    /// ```
    /// use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// // tau rises linearly from 0 to 2 over the range [0, 1].
    /// let table = [TfEntry::new([1.0; 3], 0.0), TfEntry::new([1.0; 3], 2.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    /// let mut storage = [TfEntry::TRANSPARENT; 9]; // 3 x 3 nodes, no allocation
    /// let pre = PreintegratedTable::build_in(&tf, 0.5, 3, &mut storage[..]).unwrap();
    /// let e = pre.entries();
    /// assert!((e[2].tau - 1.0).abs() < 1e-6); // from 0 to 1: the mean of the ramp
    /// assert!((e[4].tau - 1.0).abs() < 1e-6); // from 0.5 to 0.5: tau(0.5)
    /// ```
    pub fn build_in(tf: &TransferFunction<'_>, step: f32, res: u32, mut storage: S) -> Result<Self, VolumeError> {
        if !(step.is_finite() && step > 0.0) {
            return Err(VolumeError::InvalidStep);
        }
        let n = len_for(res)?;
        if n as u64 * (tf.entries().len() as u64 - 1) > PREINTEGRATED_MAX_WORK {
            return Err(VolumeError::InvalidResolution);
        }
        let out = storage.as_mut();
        if out.len() < n {
            return Err(VolumeError::StorageTooSmall {
                needed: n,
                actual: out.len(),
            });
        }
        let f = Tf64::new(tf);
        let (lo, hi) = tf.range();
        let node = |i: u32| {
            let (lo, hi) = (lo as f64, hi as f64);
            if i == res - 1 {
                hi
            } else {
                lo + (hi - lo) * i as f64 / (res - 1) as f64
            }
        };
        for (i, row) in out[..n].chunks_exact_mut(res as usize).enumerate() {
            for (j, e) in row.iter_mut().enumerate() {
                *e = f.segment(node(i as u32), node(j as u32), step as f64);
            }
        }
        // What transparency depends on: the transfer function's fingerprint and the nodes; the
        // tag keeps it apart from any transfer function's own.
        let mut fingerprint = tf.fingerprint();
        for b in (res as u64 | 0x7072_6569_6e74 << 16).to_le_bytes() {
            fingerprint = (fingerprint ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
        Ok(Self {
            entries: storage,
            res,
            lo,
            hi,
            scale: (res - 1) as f32 / (hi - lo),
            last: (res - 1) as f32,
            step,
            fingerprint,
        })
    }
}

#[cfg(feature = "alloc")]
impl PreintegratedTable<alloc::vec::Vec<TfEntry>> {
    /// Builds the table in a new `Vec` (feature `alloc`); see [`build_in`](Self::build_in).
    ///
    /// ```
    /// use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction, VolumeError};
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    /// assert_eq!(PreintegratedTable::build(&tf, 0.25, 32).unwrap().entries().len(), 32 * 32);
    /// assert_eq!(PreintegratedTable::build(&tf, 0.0, 32).unwrap_err(), VolumeError::InvalidStep);
    /// ```
    pub fn build(tf: &TransferFunction<'_>, step: f32, res: u32) -> Result<Self, VolumeError> {
        let n = len_for(res)?;
        Self::build_in(tf, step, res, alloc::vec![TfEntry::TRANSPARENT; n])
    }
}

impl<S: AsRef<[TfEntry]>> PreintegratedTable<S> {
    /// Nodes per axis.
    ///
    /// ```
    /// # use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, -1.0, 3.0).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.25, 8).unwrap();
    /// assert_eq!(pre.res(), 8);
    /// ```
    #[inline]
    pub fn res(&self) -> u32 {
        self.res
    }

    /// The step length the table was integrated for.
    ///
    /// ```
    /// # use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, -1.0, 3.0).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.25, 8).unwrap();
    /// assert_eq!(pre.step(), 0.25);
    /// ```
    #[inline]
    pub fn step(&self) -> f32 {
        self.step
    }

    /// The scalar range `(lo, hi)` of the nodes (the transfer function's).
    ///
    /// ```
    /// # use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, -1.0, 3.0).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.25, 8).unwrap();
    /// assert_eq!(pre.range(), (-1.0, 3.0));
    /// ```
    #[inline]
    pub fn range(&self) -> (f32, f32) {
        (self.lo, self.hi)
    }

    /// The entries, row `i` (front value `v_i`) after row `i - 1`: entry `(i, j)` at `i res + j`.
    ///
    /// ```
    /// use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 3.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.5, 5).unwrap();
    /// let e = pre.entries(); // nodes 0, 0.25, 0.5, 0.75, 1
    /// assert_eq!(e.len(), 25);
    /// assert_eq!(e[5 + 2].tau, 0.0); // (1, 2): from 0.25 to 0.5, clear
    /// assert!(e[2 * 5 + 3].tau > 0.0); // (2, 3): from 0.5 to 0.75, into the ramp
    /// ```
    #[inline]
    pub fn entries(&self) -> &[TfEntry] {
        &self.entries.as_ref()[..self.res as usize * self.res as usize]
    }

    /// The table borrowed, for a [`PreintegratedMedium`].
    ///
    /// ```
    /// # use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// # let tf = TransferFunction::new(&table, -1.0, 3.0).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.25, 8).unwrap();
    /// let view = pre.view();
    /// assert_eq!(view.entries(), pre.entries());
    /// assert_eq!(view.lookup_scalar(0.3, 2.1), pre.lookup_scalar(0.3, 2.1));
    /// ```
    #[inline]
    pub fn view(&self) -> PreintegratedTable<&[TfEntry]> {
        PreintegratedTable {
            entries: self.entries(),
            res: self.res,
            lo: self.lo,
            hi: self.hi,
            scale: self.scale,
            last: self.last,
            step: self.step,
            fingerprint: self.fingerprint,
        }
    }

    /// A hash of what [`is_transparent`](Self::is_transparent) depends on (the transfer
    /// function's [fingerprint](TransferFunction::fingerprint) and the resolution, hashed on with
    /// a tag), so it differs from any transfer function's own (but for a 64-bit hash collision):
    /// what [`MacrocellGrid::classify_preintegrated`] remembers.
    ///
    /// ```
    /// use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    /// let pre = |step, res| PreintegratedTable::build(&tf, step, res).unwrap().fingerprint();
    /// assert_ne!(pre(0.5, 16), tf.fingerprint()); // never the transfer function's own
    /// assert_ne!(pre(0.5, 16), pre(0.5, 32)); // other nodes
    /// assert_eq!(pre(0.5, 16), pre(0.1, 16)); // the step does not change which entries are clear
    /// ```
    ///
    /// [`MacrocellGrid::classify_preintegrated`]: super::MacrocellGrid::classify_preintegrated
    #[inline]
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    /// `true` if every segment whose values both lie in `[min, max]` looks up zero extinction.
    /// Conservative as [`TransferFunction::is_transparent`]: the range is padded by
    /// `(|min| + |max|) 2^-16 + f32::MIN_POSITIVE` first; then the nodes a lookup in it can read span `i..=j`, and the
    /// widest segment among them, entry `(i, j)`, has zero mean extinction only if the transfer
    /// function has none anywhere between (a positive mean never rounds to zero in the table), so
    /// neither has any segment in between. A NaN bound, or `min > max`, checks the whole range.
    ///
    /// ```
    /// use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// let mut table = [TfEntry::TRANSPARENT; 16];
    /// table[10] = TfEntry::new([1.0; 3], 5.0);
    /// let tf = TransferFunction::new(&table, 0.0, 15.0).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.5, 16).unwrap();
    /// assert!(pre.is_transparent(0.0, 8.5));
    /// assert!(!pre.is_transparent(0.0, 9.5)); // reads node 10
    /// assert!(!pre.is_transparent(f32::NAN, 1.0));
    /// ```
    pub fn is_transparent(&self, min: f32, max: f32) -> bool {
        let (a, b) = if min <= max {
            let pad = (abs(min) + abs(max)) * (1.0 / 65536.0) + f32::MIN_POSITIVE;
            // coord is monotone (every rounding is), so all values in the padded range map between.
            (self.coord(min - pad), self.coord(max + pad))
        } else {
            (0.0, self.last)
        };
        let top = self.res as usize - 1;
        let i = (a as usize).min(top - 1);
        let j = (b as usize + 1).min(top);
        self.entries()
            .get(i * self.res as usize + j)
            .is_some_and(|e| e.tau == 0.0)
    }

    /// Table coordinate of `s`, clamped to `[0, res - 1]` (NaN: 0), as [`TransferFunction`]'s.
    #[inline(always)]
    fn coord(&self, s: f32) -> f32 {
        min_l(max_l((s - self.lo) * self.scale, 0.0), self.last)
    }

    /// Mean extinction and weighted mean colour of a segment of length [`step`](Self::step) whose
    /// scalar runs from `front` to `back`: the four nearest entries, interpolated bilinearly
    /// (first along the back value, then the front).
    ///
    /// ```
    /// use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// // Red, tau rising linearly from 0 to 4 over [0, 1].
    /// let table = [TfEntry::new([1.0, 0.0, 0.0], 0.0), TfEntry::new([1.0, 0.0, 0.0], 4.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.1, 5).unwrap();
    /// let (tau, c) = pre.lookup_scalar(0.0, 1.0);
    /// assert!((tau - 2.0).abs() < 1e-6); // the mean of 4 s over [0, 1]
    /// assert!((c[0] - 1.0).abs() < 1e-6 && c[1] == 0.0);
    /// assert_eq!(pre.lookup_scalar(-5.0, 9.0), (tau, c)); // clamped to the range
    /// ```
    #[inline(always)]
    pub fn lookup_scalar(&self, front: f32, back: f32) -> (f32, [f32; 3]) {
        let (u, v) = (self.coord(front), self.coord(back));
        let top = self.res as i32 - 2;
        let (i, j) = ((u as i32).min(top), (v as i32).min(top));
        let (wu, wv) = (u - i as f32, v - j as f32);
        let e = self.entries.as_ref();
        let r = self.res as usize;
        let at = |k: usize| e.get(k).copied().unwrap_or_default();
        let k = i as usize * r + j as usize;
        let (e00, e01, e10, e11) = (at(k), at(k + 1), at(k + r), at(k + r + 1));
        let l = |a: f32, b: f32, w: f32| a + (b - a) * w;
        let both = |f: fn(&TfEntry) -> f32| l(l(f(&e00), f(&e01), wv), l(f(&e10), f(&e11), wv), wu);
        (
            both(|e| e.tau),
            [both(|e| e.color[0]), both(|e| e.color[1]), both(|e| e.color[2])],
        )
    }

    /// Eight lookups; lane `l` equals [`lookup_scalar`](Self::lookup_scalar) of lane `l` bit for bit.
    ///
    /// ```
    /// # use strahl::volume::{PreintegratedTable, TfEntry, TransferFunction};
    /// # let table = [TfEntry::new([1.0, 0.5, 0.0], 0.0), TfEntry::new([0.0, 0.5, 1.0], 4.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    /// use strahl::math::f32x8;
    /// let pre = PreintegratedTable::build(&tf, 0.1, 17).unwrap();
    /// let front = [0.0, 0.1, 0.3, 0.5, 0.77, 1.0, -2.0, f32::NAN];
    /// let back = [1.0, 0.9, 0.3, 0.2, 0.0, 1.5, 0.4, 0.6];
    /// let (tau, c) = pre.lookup_x8(f32x8::new(front), f32x8::new(back));
    /// for l in 0..8 {
    ///     let (t, cs) = pre.lookup_scalar(front[l], back[l]);
    ///     assert_eq!(tau.to_array()[l].to_bits(), t.to_bits());
    ///     assert_eq!(c[2].to_array()[l].to_bits(), cs[2].to_bits());
    /// }
    /// ```
    #[inline(always)]
    pub fn lookup_x8(&self, front: f32x8, back: f32x8) -> (f32x8, [f32x8; 3]) {
        let coord = |s: f32x8| {
            ((s - f32x8::splat(self.lo)) * f32x8::splat(self.scale))
                .max_l(f32x8::splat(0.0))
                .min_l(f32x8::splat(self.last))
        };
        let (u, v) = (coord(front), coord(back));
        let top = i32x8::splat(self.res as i32 - 2);
        let (i, j) = (u.fast_trunc_int().min(top), v.fast_trunc_int().min(top));
        let (wu, wv) = (u - i.round_float(), v - j.round_float());
        let r = self.res as usize;
        let k = (i * i32x8::splat(r as i32) + j).to_array();
        let e = self.entries.as_ref();
        // PERF: entries (i, j) and (i, j + 1) are 8 adjacent floats, as are (i + 1, j) and
        // (i + 1, j + 1): one unaligned load per lane and row, then an 8 x 8 transpose per row.
        // NOTE: the clamp never moves a row (k <= (res - 2) (res + 1)); it lets the compiler drop
        // the bounds checks.
        let kmax = e.len().saturating_sub(r + 2);
        if e.len() < r + 2 {
            return (f32x8::splat(0.0), [f32x8::splat(0.0); 3]); // unreachable: res >= 2
        }
        let row = |l: usize, off: usize| {
            let i = (k[l] as u32 as usize).min(kmax) + off;
            f32x8::new(bytemuck::cast::<[TfEntry; 2], [f32; 8]>([e[i], e[i + 1]]))
        };
        let rows = |off: usize| {
            f32x8::transpose([
                row(0, off),
                row(1, off),
                row(2, off),
                row(3, off),
                row(4, off),
                row(5, off),
                row(6, off),
                row(7, off),
            ])
        };
        let [r00, g00, b00, t00, r01, g01, b01, t01] = rows(0);
        let [r10, g10, b10, t10, r11, g11, b11, t11] = rows(r);
        let l = |a: f32x8, b: f32x8, w: f32x8| a + (b - a) * w;
        let both = |a00, a01, a10, a11| l(l(a00, a01, wv), l(a10, a11, wv), wu);
        (
            both(t00, t01, t10, t11),
            [
                both(r00, r01, r10, r11),
                both(g00, g01, g10, g11),
                both(b00, b01, b10, b11),
            ],
        )
    }
}

/// The transfer function in `f64`, for integrating segments.
struct Tf64<'a> {
    e: &'a [TfEntry],
    lo: f64,
    /// Scalar distance between nodes (`0` for a one-entry table).
    h: f64,
}

/// `(tau, c)` of one point of the transfer function, in `f64`.
type Point = (f64, [f64; 3]);

impl<'a> Tf64<'a> {
    fn new(tf: &TransferFunction<'a>) -> Self {
        let e = tf.entries();
        let (lo, hi) = tf.range();
        let h = if e.len() > 1 {
            (hi as f64 - lo as f64) / (e.len() - 1) as f64
        } else {
            0.0
        };
        Self { e, lo: lo as f64, h }
    }

    /// Node `m` (an entry).
    fn node(&self, m: usize) -> Point {
        let e = &self.e[m];
        (e.tau as f64, e.color.map(|c| c as f64))
    }

    /// The transfer function at node coordinate `u` (`0 ..= n - 1`), interpolated linearly as
    /// the `f32` lookup does.
    fn at_node_coord(&self, u: f64) -> Point {
        let n = self.e.len();
        let u = u.clamp(0.0, (n - 1) as f64);
        let j = (u as usize).min(n - 2);
        let w = u - j as f64;
        let (a, b) = (&self.e[j], &self.e[j + 1]);
        let l = |x: f32, y: f32| x as f64 + (y as f64 - x as f64) * w;
        (
            l(a.tau, b.tau),
            [
                l(a.color[0], b.color[0]),
                l(a.color[1], b.color[1]),
                l(a.color[2], b.color[2]),
            ],
        )
    }

    /// The transfer function at scalar `s`.
    #[cfg(test)]
    fn at(&self, s: f64) -> Point {
        if self.e.len() == 1 {
            return self.node(0);
        }
        self.at_node_coord((s - self.lo) / self.h)
    }

    /// The segment of length `d` along which the scalar runs linearly from `a` to `b` (both in the
    /// range), as the entry the marcher composites (see the module docs).
    fn segment(&self, a: f64, b: f64, d: f64) -> TfEntry {
        let n = self.e.len();
        let x_len = (b - a).abs();
        if n == 1 {
            let (tau, c) = self.node(0);
            return entry(tau, c);
        }
        let (ua, ub) = ((a - self.lo) / self.h, (b - self.lo) / self.h);
        if x_len == 0.0 || ua == ub {
            let (tau, c) = self.at_node_coord(ua);
            return entry(tau, c);
        }
        // Walk in node coordinates from ua to ub through the nodes strictly in between: pieces on
        // which tau and c are linear. `kappa`: optical depth per unit of tau and of scalar walked.
        let kappa = d / x_len;
        let up = ub > ua;
        // Optical depth from the front, and the transmittance exp(-depth) (kept as a product of
        // per-piece factors while the depth is below the cutoff).
        let (mut tau_sum, mut depth, mut trans) = (0.0f64, 0.0f64, 1.0f64);
        let (mut num, mut den) = ([0.0f64; 3], 0.0f64);
        let mut col_sum = [0.0f64; 3];
        let (mut u0, mut p0) = (ua, self.at_node_coord(ua));
        // The first node strictly beyond ua.
        let mut m = if up {
            libm::floor(ua) + 1.0
        } else {
            libm::ceil(ua) - 1.0
        };
        loop {
            let inside = if up { m < ub } else { m > ub };
            let (u1, p1) = if inside {
                (m, self.node(m as usize))
            } else {
                (ub, self.at_node_coord(ub))
            };
            let w = (u1 - u0).abs() * self.h;
            let piece_tau = 0.5 * (p0.0 + p1.0) * w;
            tau_sum += piece_tau;
            for (ch, s) in col_sum.iter_mut().enumerate() {
                *s += 0.5 * (p0.1[ch] + p1.1[ch]) * w;
            }
            if depth < DEPTH_CUTOFF && w > 0.0 && piece_tau > 0.0 {
                trans = integrate_piece([p0, p1], w, kappa, depth, trans, &mut num, &mut den);
            }
            depth += kappa * piece_tau;
            if !inside {
                break;
            }
            (u0, p0) = (u1, p1);
            m += if up { 1.0 } else { -1.0 };
        }
        let tau = tau_sum / x_len;
        let c = if den > 0.0 {
            num.map(|x| x / den)
        } else {
            col_sum.map(|x| x / x_len)
        };
        entry(tau, c)
    }
}

/// `exp(-y)` for `y` in `[0, PIECE_DEPTH]`: Taylor to degree 9 (error below `3e-13`), cheaper
/// than a library `exp`.
#[inline(always)]
fn exp_neg_small(y: f64) -> f64 {
    // 1 - y (1 - y/2 (1 - y/3 (... (1 - y/9)))), the reciprocals as constants.
    const INV: [f64; 9] = [
        1.0,
        1.0 / 2.0,
        1.0 / 3.0,
        1.0 / 4.0,
        1.0 / 5.0,
        1.0 / 6.0,
        1.0 / 7.0,
        1.0 / 8.0,
        1.0 / 9.0,
    ];
    let mut r = 1.0;
    for inv in INV.iter().rev() {
        r = 1.0 - y * inv * r;
    }
    r
}

/// `int c tau exp(-D) dx` (into `num`) and `int tau exp(-D) dx` (into `den`) over one piece of
/// scalar width `w` where `tau` and `c` are linear (`[start, end]`), `D` the optical depth from
/// the segment's front (`depth` at the piece's start, where `exp(-D) = trans`; `kappa` per unit of
/// scalar and of `tau`). The piece is cut where its depth passes multiples of [`PIECE_DEPTH`], up
/// to the cutoff. Returns `exp(-D)` at the piece's end (or where the cutoff stopped it).
#[allow(clippy::too_many_arguments)]
fn integrate_piece(
    [(t0, c0), (t1, c1)]: [Point; 2],
    w: f64,
    kappa: f64,
    depth: f64,
    trans: f64,
    num: &mut [f64; 3],
    den: &mut f64,
) -> f64 {
    // Depth within the piece after x: q(x) = kappa (t0 x + (t1 - t0) x^2 / (2 w)).
    let (qa, qb) = (kappa * (t1 - t0) / (2.0 * w), kappa * t0);
    let q = |x: f64| qb * x + qa * x * x;
    let total = q(w);
    // x where q(x) = target (0 <= target <= total; q is increasing on [0, w]).
    let x_at = |target: f64| -> f64 {
        if target <= 0.0 {
            return 0.0;
        }
        if target >= total {
            return w;
        }
        // qa x^2 + qb x - target = 0, the root in [0, w], in the form without cancellation.
        let disc = max_f64(qb * qb + 4.0 * qa * target, 0.0);
        let x = 2.0 * target / (qb + libm::sqrt(disc));
        x.clamp(0.0, w)
    };
    let room = DEPTH_CUTOFF - depth;
    let span = if total < room { total } else { room };
    let cuts = libm::ceil(span / PIECE_DEPTH).clamp(1.0, (DEPTH_CUTOFF / PIECE_DEPTH) + 1.0) as usize;
    let (mut xa, mut base) = (0.0, trans);
    for k in 1..=cuts {
        let xb = if k == cuts && total < room {
            w
        } else {
            x_at(span * k as f64 / cuts as f64)
        };
        let (mid, half) = (0.5 * (xa + xb), 0.5 * (xb - xa));
        // exp(-D(x)) = exp(-D(xa)) exp(-(q(x) - q(xa))), the second factor's argument in
        // [0, 1/4] (up to rounding in x_at).
        let qa0 = q(xa);
        for (gx, gw) in GL_X.iter().zip(GL_W) {
            let x = mid + half * gx;
            let f = x / w;
            let t = t0 + (t1 - t0) * f;
            let weight = half * gw * t * base * exp_neg_small(max_f64(q(x) - qa0, 0.0));
            *den += weight;
            for (ch, s) in num.iter_mut().enumerate() {
                *s += weight * (c0[ch] + (c1[ch] - c0[ch]) * f);
            }
        }
        base *= exp_neg_small(max_f64(q(xb) - qa0, 0.0));
        xa = xb;
    }
    base
}

#[inline]
fn max_f64(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// An `f32` entry from `f64` mean extinction and colour (finite: both are means of finite values).
/// A positive extinction stays positive (at least the least subnormal), so that a zero entry means
/// no extinction anywhere along its segment ([`PreintegratedTable::is_transparent`]).
fn entry(tau: f64, c: [f64; 3]) -> TfEntry {
    let t = tau as f32;
    let t = if tau > 0.0 && t == 0.0 { f32::from_bits(1) } else { t };
    TfEntry::new(c.map(|x| x as f32), t)
}

/// A [`Volume`] seen through a [`PreintegratedTable`]: what the pre-integrated marchers
/// ([`integrate_preintegrated_scalar`](super::integrate_preintegrated_scalar),
/// [`integrate_preintegrated_x8`](super::integrate_preintegrated_x8)) march through.
///
/// ```
/// use strahl::{Ray, Vec3};
/// use strahl::volume::*;
/// let data: Vec<f32> = (0..8 * 8 * 8).map(|i| (i % 8) as f32 / 7.0).collect(); // s = x / 7
/// let vol = Volume::new(&data, [8; 3], Vec3::ONE, Vec3::ZERO).unwrap();
/// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0), TfEntry::TRANSPARENT];
/// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
/// let pre = PreintegratedTable::build(&tf, 1.0, 64).unwrap();
/// let m = PreintegratedMedium::new(vol, pre.view());
/// let rays = [Ray::new(Vec3::new(-1.0, 3.5, 3.5), Vec3::X)];
/// let mut out = [Rgba::ZERO];
/// integrate_preintegrated(&m, &rays, &mut out, &MarchParams::reference(1.0)).unwrap();
/// // tau is a tent of height 2 over x in [0, 7]: optical depth 7, whatever the step.
/// assert!((out[0].a - (1.0 - (-7.0f32).exp())).abs() < 1e-5);
/// ```
#[derive(Clone, Copy, Debug)]
pub struct PreintegratedMedium<'a, V: Voxel> {
    vol: Volume<'a, V>,
    table: PreintegratedTable<&'a [TfEntry]>,
    grid: Option<GridView<'a>>,
}

impl<'a, V: Voxel> PreintegratedMedium<'a, V> {
    /// The volume seen through `table`, without empty-space skipping.
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::*;
    /// # let data = [0u8, 0, 0, 0, 255, 255, 255, 255];
    /// # let vol = Volume::new(&data, [2; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let pre = PreintegratedTable::build(&tf, 0.5, 16).unwrap();
    /// let m = PreintegratedMedium::new(vol, pre.view());
    /// assert!(!m.skips());
    /// assert_eq!(m.table().entries(), pre.entries());
    /// ```
    pub fn new(vol: Volume<'a, V>, table: PreintegratedTable<&'a [TfEntry]>) -> Self {
        Self { vol, table, grid: None }
    }

    /// The medium with empty-space skipping over `grid`, classified with
    /// [`MacrocellGrid::classify_preintegrated`] for this table. The marchers then jump over the
    /// steps whose both ends lie in the safe box of an empty region; the image is bit-identical
    /// (see [`skip`](super::skip) for why, with segments in place of samples).
    ///
    /// Errors: [`VolumeError::GridMismatch`] for a grid of other dimensions,
    /// [`VolumeError::StaleGrid`] if it was not classified for this table. The voxels are not
    /// compared: build the grid again after they change (see
    /// [`VolumeMedium::with_grid`](super::VolumeMedium::with_grid)).
    ///
    /// ```
    /// use strahl::Vec3;
    /// use strahl::volume::*;
    /// let data = vec![0u8; 16 * 16 * 16];
    /// let vol = Volume::new(&data, [16; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// let pre = PreintegratedTable::build(&tf, 0.5, 64).unwrap();
    /// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// grid.classify(&tf); // for the Riemann marchers: refused here
    /// assert_eq!(PreintegratedMedium::new(vol, pre.view()).with_grid(&grid).unwrap_err(), VolumeError::StaleGrid);
    /// grid.classify_preintegrated(&pre);
    /// let m = PreintegratedMedium::new(vol, pre.view()).with_grid(&grid).unwrap();
    /// assert!(m.skips());
    /// ```
    pub fn with_grid<S: AsRef<[Macrocell]>>(self, grid: &'a MacrocellGrid<S>) -> Result<Self, VolumeError> {
        if grid.volume_dims() != self.vol.dims() {
            return Err(VolumeError::GridMismatch);
        }
        if grid.classified_for() != Some(self.table.fingerprint()) {
            return Err(VolumeError::StaleGrid);
        }
        Ok(Self {
            grid: Some(grid.view()),
            ..self
        })
    }

    /// `true` if empty-space skipping is on.
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::*;
    /// # let data = [0u8, 0, 0, 0, 255, 255, 255, 255];
    /// # let vol = Volume::new(&data, [2; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let pre = PreintegratedTable::build(&tf, 0.5, 16).unwrap();
    /// let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    /// grid.classify_preintegrated(&pre);
    /// assert!(!PreintegratedMedium::new(vol, pre.view()).skips());
    /// assert!(PreintegratedMedium::new(vol, pre.view()).with_grid(&grid).unwrap().skips());
    /// ```
    #[inline]
    pub fn skips(&self) -> bool {
        self.grid.is_some()
    }

    /// [`empty_region`](Self::empty_region) for the `active` lanes of eight positions: the mask of
    /// lanes in empty regions, their regions written to `out`.
    #[inline(always)]
    pub(crate) fn empty_regions_x8(&self, g: [f32x8; 3], active: u32, out: &mut [EmptyRegion; 8]) -> u32 {
        let Some(grid) = self.grid.as_ref() else {
            return 0;
        };
        if self.vol.is_empty() {
            return 0;
        }
        let cell = self.vol.cell_x8(g);
        let mut bits = grid.empty_mask_x8(&cell.idx, active);
        let mut mask = 0;
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            if let Some(r) = grid.empty_region([cell.idx[0][l], cell.idx[1][l], cell.idx[2][l]]) {
                out[l] = r;
                mask |= 1 << l;
            }
        }
        mask
    }

    /// The empty region around local position `g`, if skipping is on and `g`'s macrocell is empty.
    #[inline(always)]
    pub(crate) fn empty_region(&self, g: [f32; 3]) -> Option<EmptyRegion> {
        let grid = self.grid.as_ref()?;
        if self.vol.is_empty() {
            return None;
        }
        grid.empty_region(self.vol.cell_scalar(Vec3::from_array(g)).idx)
    }

    /// The volume.
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::*;
    /// # let data = [0u8, 0, 0, 0, 255, 255, 255, 255];
    /// # let vol = Volume::new(&data, [2; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let pre = PreintegratedTable::build(&tf, 0.5, 16).unwrap();
    /// let m = PreintegratedMedium::new(vol, pre.view());
    /// assert_eq!(m.volume().dims(), [2, 2, 2]);
    /// ```
    #[inline]
    pub fn volume(&self) -> &Volume<'a, V> {
        &self.vol
    }

    /// The table.
    ///
    /// ```
    /// # use strahl::Vec3;
    /// # use strahl::volume::*;
    /// # let data = [0u8, 0, 0, 0, 255, 255, 255, 255];
    /// # let vol = Volume::new(&data, [2; 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let pre = PreintegratedTable::build(&tf, 0.5, 16).unwrap();
    /// let m = PreintegratedMedium::new(vol, pre.view());
    /// assert_eq!((m.table().res(), m.table().step()), (16, 0.5));
    /// ```
    #[inline]
    pub fn table(&self) -> &PreintegratedTable<&'a [TfEntry]> {
        &self.table
    }

    /// The world box of the volume.
    #[inline]
    pub(crate) fn bounds(&self) -> Aabb {
        self.vol.bounds()
    }

    /// The scalar at local position `g`.
    #[inline(always)]
    pub(crate) fn scalar(&self, g: [f32; 3]) -> f32 {
        self.vol.sample_local_scalar(Vec3::from_array(g))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;
    use alloc::vec::Vec;

    fn tf_table() -> Vec<TfEntry> {
        (0..17)
            .map(|i| {
                let t = i as f32 / 16.0;
                TfEntry::new(
                    [t, 1.0 - t, (t * 7.0).sin().abs()],
                    if i % 5 == 2 { 0.0 } else { 3.0 * t + 0.5 },
                )
            })
            .collect()
    }

    #[test]
    fn construction_errors() {
        let t = tf_table();
        let tf = TransferFunction::new(&t, 0.0, 1.0).unwrap();
        for step in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(
                PreintegratedTable::build(&tf, step, 16).unwrap_err(),
                VolumeError::InvalidStep
            );
        }
        for res in [0, 1, PREINTEGRATED_MAX_RES + 1] {
            assert_eq!(
                PreintegratedTable::build(&tf, 0.1, res).unwrap_err(),
                VolumeError::InvalidResolution
            );
        }
        // The work cap: a 512^2 table over 4098 entries is refused (4097 is exactly at the cap),
        // a small table over them is not.
        let big = vec![TfEntry::TRANSPARENT; 4098];
        let tf_big = TransferFunction::new(&big, 0.0, 1.0).unwrap();
        assert_eq!(
            PreintegratedTable::build(&tf_big, 0.1, 512).map(|_| ()),
            Err(VolumeError::InvalidResolution)
        );
        assert_eq!(512u64 * 512 * 4096, PREINTEGRATED_MAX_WORK);
        assert!(PreintegratedTable::build(&tf_big, 0.1, 16).is_ok());
        let mut small = vec![TfEntry::TRANSPARENT; 15];
        assert_eq!(
            PreintegratedTable::build_in(&tf, 0.1, 4, &mut small[..]).unwrap_err(),
            VolumeError::StorageTooSmall { needed: 16, actual: 15 }
        );
    }

    /// The diagonal holds the transfer function itself; off it, the mean extinction is the exact
    /// mean of the piecewise-linear tau, and the colour a convex combination.
    #[test]
    fn entries_are_means() {
        let t = tf_table();
        let tf = TransferFunction::new(&t, 0.0, 1.0).unwrap();
        let res = 33;
        let pre = PreintegratedTable::build(&tf, 0.3, res).unwrap();
        let f = Tf64::new(&tf);
        for i in 0..res as usize {
            for j in 0..res as usize {
                let (a, b) = (i as f64 / 32.0, j as f64 / 32.0);
                let e = pre.entries()[i * res as usize + j];
                if i == j {
                    let (tau, c) = tf.lookup_scalar(a as f32);
                    assert!((e.tau - tau).abs() <= 1e-6 && (0..3).all(|k| (e.color[k] - c[k]).abs() <= 1e-6));
                    continue;
                }
                // Mean of tau by a fine midpoint rule.
                let steps = 4_000;
                let mean = (0..steps)
                    .map(|k| f.at(a + (b - a) * (k as f64 + 0.5) / steps as f64).0)
                    .sum::<f64>()
                    / steps as f64;
                assert!((e.tau as f64 - mean).abs() < 1e-5, "({i}, {j}): {} vs {mean}", e.tau);
                assert!(
                    (e.tau - pre.entries()[j * res as usize + i].tau).abs() <= 1e-6 * e.tau,
                    "symmetric"
                );
                for k in 0..3 {
                    let (lo, hi) = t
                        .iter()
                        .fold((f32::MAX, f32::MIN), |(l, h), x| (l.min(x.color[k]), h.max(x.color[k])));
                    assert!(e.color[k] >= lo - 1e-6 && e.color[k] <= hi + 1e-6);
                }
            }
        }
    }

    /// The bilinear x8 lookup equals the scalar one bit for bit, also for values outside the range,
    /// NaN, and on the top nodes.
    #[test]
    fn x8_lookup_equals_scalar() {
        let t = tf_table();
        let tf = TransferFunction::new(&t, -2.0, 3.0).unwrap();
        for res in [2, 3, 17, 64] {
            let pre = PreintegratedTable::build(&tf, 0.25, res).unwrap();
            let vals = [
                -5.0,
                -2.0,
                -1.99,
                0.0,
                0.3,
                1.0,
                2.999,
                3.0,
                3.5,
                f32::NAN,
                1e30,
                -1e30,
                0.77,
                2.1,
            ];
            for chunk in 0..vals.len() {
                let f: [f32; 8] = core::array::from_fn(|l| vals[(chunk + l) % vals.len()]);
                let b: [f32; 8] = core::array::from_fn(|l| vals[(chunk * 3 + l * 5) % vals.len()]);
                let (tau, c) = pre.lookup_x8(f32x8::new(f), f32x8::new(b));
                for l in 0..8 {
                    let (ts, cs) = pre.lookup_scalar(f[l], b[l]);
                    assert_eq!(tau.to_array()[l].to_bits(), ts.to_bits());
                    for k in 0..3 {
                        assert_eq!(c[k].to_array()[l].to_bits(), cs[k].to_bits());
                    }
                }
            }
        }
    }

    /// A segment through an extinction so high that it is opaque right after its front: the colour
    /// is the front's, the extinction the exact mean (no quadrature node sees anything but zero
    /// transmittance except near the front).
    #[test]
    fn opaque_segments_take_the_front_colour() {
        let t = [
            TfEntry::new([1.0, 0.0, 0.0], 1e6),
            TfEntry::new([0.0, 0.0, 1.0], 1e6),
            TfEntry::new([0.0, 1.0, 0.0], crate::volume::TAU_MAX),
        ];
        let tf = TransferFunction::new(&t, 0.0, 1.0).unwrap();
        let pre = PreintegratedTable::build(&tf, 1.0, 3).unwrap();
        let e = pre.entries()[1]; // from 0 to 0.5
        assert!((e.color[0] - 1.0).abs() < 1e-3 && e.color[2] < 1e-3, "{e:?}");
        assert!((e.tau - 1e6).abs() < 1.0);
        let e = pre.entries()[2 * 3]; // from 1 to 0
        assert!((e.color[1] - 1.0).abs() < 1e-3, "{e:?}");
        assert!(e.tau.is_finite());
    }

    /// `is_transparent` is conservative: where it says so, every lookup with both values in the
    /// range (and a little beyond, for the interpolation's rounding) reads zero extinction; and it
    /// says so for ranges well inside zero stretches. A tiny positive mean stays positive.
    #[test]
    fn transparency_is_conservative() {
        let mut t = tf_table();
        for e in &mut t[1..=4] {
            e.tau = 0.0; // zero over [1/16, 4/16]
        }
        t[9].tau = 1e-44; // a mean of it over many nodes is below the least f32
        let tf = TransferFunction::new(&t, 0.0, 1.0).unwrap();
        for res in [2u32, 5, 16, 17, 40] {
            let pre = PreintegratedTable::build(&tf, 0.2, res).unwrap();
            assert!(
                pre.entries()
                    .iter()
                    .all(|e| e.tau > 0.0 || e.tau == 0.0 && !e.tau.is_sign_negative())
            );
            let mut some = false;
            for i in 0..=64 {
                for j in i..=64 {
                    let (lo, hi) = (i as f32 / 64.0, j as f32 / 64.0);
                    if !pre.is_transparent(lo, hi) {
                        continue;
                    }
                    some |= j > i;
                    for a in 0..=8 {
                        for b in 0..=8 {
                            let pad = 1e-6;
                            let sf = lo - pad + (hi - lo + 2.0 * pad) * a as f32 / 8.0;
                            let sb = lo - pad + (hi - lo + 2.0 * pad) * b as f32 / 8.0;
                            assert_eq!(pre.lookup_scalar(sf, sb).0, 0.0, "res {res} [{lo}, {hi}]: ({sf}, {sb})");
                        }
                    }
                }
            }
            // With 40 nodes the range around 0.125 reads only zero segments.
            if res == 40 {
                assert!(some && pre.is_transparent(0.12, 0.13));
            }
            assert!(
                !pre.is_transparent(0.0, 1.0) && !pre.is_transparent(f32::NAN, 0.5) && !pre.is_transparent(0.5, 0.4)
            );
        }
    }

    /// A one-entry transfer function is constant: every table entry is it.
    #[test]
    fn one_entry_table() {
        let t = [TfEntry::new([0.2, 0.4, 0.6], 1.5)];
        let tf = TransferFunction::new(&t, 0.0, 1.0).unwrap();
        let pre = PreintegratedTable::build(&tf, 0.5, 4).unwrap();
        assert!(pre.entries().iter().all(|e| *e == t[0]));
    }
}
