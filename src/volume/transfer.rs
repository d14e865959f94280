//! Transfer functions: a 1D table from scalar value to emitted colour and extinction.

use super::VolumeError;
use crate::math::{Lane, f32x8, i32x8, max_l, min_l};
use bytemuck::{Pod, Zeroable};

/// Largest extinction an entry may hold, per world unit: `2^100`. An opacity of exactly 1 converts
/// to it, and with any step of `1e-28` or more it gives `a = 1 - exp(-tau dt) = 1` in `f32`
/// (`tau dt` about 127 or more; a step of `1e-30` gives about 0.72).
///
/// ```
/// use strahl::volume::{TAU_MAX, TfEntry, TransferFunction, VolumeError};
/// assert_eq!(TAU_MAX, 2f32.powi(100));
/// let opaque = TfEntry::from_rgba_premultiplied([0.5, 0.5, 0.5, 1.0], 0.1);
/// assert_eq!(opaque.tau, TAU_MAX);
/// assert_eq!(opaque.opacity(1e-6), 1.0);
/// let too_dense = [TfEntry::new([1.0; 3], 2.0 * TAU_MAX)];
/// let err = TransferFunction::new(&too_dense, 0.0, 1.0).unwrap_err();
/// assert_eq!(err, VolumeError::InvalidEntry { index: 0 });
/// ```
pub const TAU_MAX: f32 = 1.267_650_6e30;

/// Largest `|c|` a colour channel of an entry may hold: `2^100`. Bounded so that interpolating two
/// entries, `a + (b - a) w`, never overflows (`+MAX` beside `-MAX` would give `inf - inf = NaN`),
/// and an accumulated colour stays below it too (its weights `(1 - A) a` sum to at most 1).
///
/// ```
/// use strahl::volume::{COLOR_MAX, TfEntry, TransferFunction, VolumeError};
/// let table = [TfEntry::new([COLOR_MAX; 3], 1.0), TfEntry::new([-COLOR_MAX; 3], 1.0)];
/// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
/// assert_eq!(tf.lookup_scalar(0.5).1, [0.0; 3]); // MAX + (-MAX - MAX) / 2: finite throughout
/// let bad = [TfEntry::TRANSPARENT, TfEntry::new([0.0, 2.0 * COLOR_MAX, 0.0], 1.0)];
/// assert_eq!(TransferFunction::new(&bad, 0.0, 1.0).unwrap_err(), VolumeError::InvalidEntry { index: 1 });
/// ```
pub const COLOR_MAX: f32 = 1.267_650_6e30;

/// One transfer function entry in physical form: emitted colour `c` (not premultiplied) and
/// extinction `tau` per world unit. See the [module docs](super) for the convention.
///
/// ```
/// use strahl::volume::TfEntry;
/// // Authored as premultiplied RGBA with opacity 0.5 for a reference step of 0.1:
/// let e = TfEntry::from_rgba_premultiplied([0.4, 0.2, 0.0, 0.5], 0.1);
/// assert!((e.color[0] - 0.8).abs() < 1e-6);                    // c = R / alpha0
/// assert!((e.tau - core::f32::consts::LN_2 / 0.1).abs() < 1e-4); // -ln(1 - 0.5) / 0.1
/// // Marching at the reference step gives the authored opacity and colour back:
/// let [r, _, _, a] = e.rgba_premultiplied(0.1);
/// assert!((a - 0.5).abs() < 1e-6 && (r - 0.4).abs() < 1e-6);
/// // Twice the step: opacity 1 - (1 - 0.5)^2.
/// assert!((e.opacity(0.2) - 0.75).abs() < 1e-6);
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TfEntry {
    /// Emitted colour `c`, not premultiplied.
    pub color: [f32; 3],
    /// Extinction coefficient `tau` per world unit, in `[0, TAU_MAX]`.
    pub tau: f32,
}

const _: () = assert!(core::mem::size_of::<TfEntry>() == 16);

impl TfEntry {
    /// Black and without extinction.
    ///
    /// ```
    /// use strahl::volume::TfEntry;
    /// assert_eq!(TfEntry::TRANSPARENT, TfEntry::default());
    /// assert_eq!(TfEntry::TRANSPARENT.opacity(1e6), 0.0);
    /// assert_eq!(TfEntry::TRANSPARENT.rgba_premultiplied(1.0), [0.0; 4]);
    /// ```
    pub const TRANSPARENT: Self = Self {
        color: [0.0; 3],
        tau: 0.0,
    };

    /// An entry from colour and extinction per world unit.
    ///
    /// ```
    /// use strahl::volume::TfEntry;
    /// let e = TfEntry::new([1.0, 0.5, 0.0], 2.0);
    /// assert_eq!((e.color, e.tau), ([1.0, 0.5, 0.0], 2.0));
    /// assert!((e.opacity(0.5) - (1.0 - (-1.0f32).exp())).abs() < 1e-6); // tau dt = 1
    /// ```
    #[inline]
    pub const fn new(color: [f32; 3], tau: f32) -> Self {
        Self { color, tau }
    }

    /// From premultiplied RGBA authored for the reference step `dt0`: the opacity `alpha0` (clamped
    /// to `[0, 1]`) of a slab `dt0` thick, and `R = alpha0 c`. Gives `tau = -ln(1 - alpha0) / dt0`
    /// ([`TAU_MAX`] for `alpha0 = 1`) and `c = R / alpha0` (`0` where `alpha0 = 0`). A NaN `alpha0`
    /// counts as 0; a `dt0` that is not finite and positive gives a transparent entry.
    ///
    /// ```
    /// use strahl::volume::{TAU_MAX, TfEntry};
    /// let e = TfEntry::from_rgba_premultiplied([0.2, 0.1, 0.0, 0.25], 1.0);
    /// assert_eq!(e.color, [0.8, 0.4, 0.0]); // R / alpha0
    /// assert!((e.tau - (4.0f32 / 3.0).ln()).abs() < 1e-6); // -ln(1 - 0.25)
    /// assert_eq!(TfEntry::from_rgba_premultiplied([1.0, 1.0, 1.0, 2.0], 0.5).tau, TAU_MAX); // alpha0 clamped to 1
    /// assert_eq!(TfEntry::from_rgba_premultiplied([0.1; 4], 0.0), TfEntry::TRANSPARENT); // dt0 = 0
    /// assert_eq!(TfEntry::from_rgba_premultiplied([0.1, 0.1, 0.1, f32::NAN], 1.0), TfEntry::TRANSPARENT);
    /// ```
    pub fn from_rgba_premultiplied(rgba: [f32; 4], dt0: f32) -> Self {
        // NaN -> 0 (max_l returns its second operand on NaN).
        let a = min_l(max_l(rgba[3], 0.0), 1.0);
        if a == 0.0 || !(dt0 > 0.0 && dt0.is_finite()) {
            return Self::TRANSPARENT;
        }
        let tau = if a >= 1.0 {
            TAU_MAX
        } else {
            min_l(-libm::log1pf(-a) / dt0, TAU_MAX)
        };
        Self {
            color: [rgba[0] / a, rgba[1] / a, rgba[2] / a],
            tau,
        }
    }

    /// From straight (not premultiplied) RGBA authored for the reference step `dt0`: as
    /// [`from_rgba_premultiplied`](Self::from_rgba_premultiplied) with `c = (r, g, b)`.
    ///
    /// ```
    /// use strahl::volume::TfEntry;
    /// let straight = TfEntry::from_rgba_straight([0.8, 0.4, 0.0, 0.25], 0.1);
    /// let premul = TfEntry::from_rgba_premultiplied([0.2, 0.1, 0.0, 0.25], 0.1);
    /// assert_eq!(straight, premul); // the same entry, authored two ways
    /// assert_eq!(TfEntry::from_rgba_straight([1.0, 1.0, 1.0, 0.0], 0.1), TfEntry::TRANSPARENT);
    /// ```
    pub fn from_rgba_straight(rgba: [f32; 4], dt0: f32) -> Self {
        let e = Self::from_rgba_premultiplied([0.0, 0.0, 0.0, rgba[3]], dt0);
        if e.tau == 0.0 {
            return Self::TRANSPARENT;
        }
        Self {
            color: [rgba[0], rgba[1], rgba[2]],
            tau: e.tau,
        }
    }

    /// Opacity of a slab `dt` thick: `1 - exp(-tau dt)`, which equals the corrected
    /// `1 - (1 - alpha0)^(dt / dt0)` of an entry authored at `dt0`.
    ///
    /// ```
    /// use strahl::volume::TfEntry;
    /// let e = TfEntry::new([1.0; 3], core::f32::consts::LN_2); // half the light passes one unit
    /// assert!((e.opacity(1.0) - 0.5).abs() < 1e-6);
    /// assert!((e.opacity(2.0) - 0.75).abs() < 1e-6); // two slabs: 1 - 0.5^2
    /// assert_eq!(e.opacity(0.0), 0.0);
    /// ```
    #[inline]
    pub fn opacity(&self, dt: f32) -> f32 {
        1.0 - libm::expf(-(self.tau * dt))
    }

    /// The premultiplied RGBA of a slab `dt` thick: `[a c, a]` with `a = opacity(dt)`. This is the
    /// classic opacity-corrected table entry, for callers that composite tables themselves.
    ///
    /// ```
    /// use strahl::volume::TfEntry;
    /// let e = TfEntry::new([1.0, 0.5, 0.0], core::f32::consts::LN_2);
    /// let [r, g, b, a] = e.rgba_premultiplied(1.0);
    /// assert!((a - 0.5).abs() < 1e-6);
    /// assert_eq!([r, g, b], [a, 0.5 * a, 0.0]); // colour times opacity
    /// ```
    #[inline]
    pub fn rgba_premultiplied(&self, dt: f32) -> [f32; 4] {
        let a = self.opacity(dt);
        [a * self.color[0], a * self.color[1], a * self.color[2], a]
    }
}

/// Opacity correction: the opacity `alpha0` of a slab `dt0` thick, scaled to a slab `dt` thick,
/// `1 - (1 - alpha0)^(dt / dt0)`.
///
/// ```
/// use strahl::volume::correct_opacity;
/// assert!((correct_opacity(0.5, 0.2, 0.1) - 0.75).abs() < 1e-6);
/// assert_eq!(correct_opacity(0.3, 0.1, 0.1), 0.3);
/// assert_eq!(correct_opacity(1.0, 0.01, 1.0), 1.0);
/// ```
#[inline]
pub fn correct_opacity(alpha0: f32, dt: f32, dt0: f32) -> f32 {
    1.0 - libm::powf(1.0 - alpha0, dt / dt0)
}

/// A transfer function: `n` entries spread evenly over the scalar range `[lo, hi]`, interpolated
/// linearly (colour and extinction separately), clamped outside the range. Borrows its table.
///
/// A value `s` maps to the table coordinate `u = (s - lo) (n - 1) / (hi - lo)`, clamped to
/// `[0, n - 1]` (a NaN value maps to 0), and interpolates entries `j = min(floor(u), n - 2)` and
/// `j + 1` with weight `u - j`.
///
/// ```
/// use strahl::volume::{TfEntry, TransferFunction};
/// let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.0], 4.0)];
/// let tf = TransferFunction::new(&table, 0.0, 200.0).unwrap();
/// let (tau, c) = tf.lookup_scalar(125.0);
/// assert_eq!((tau, c), (1.0, [0.25, 0.125, 0.0]));
/// assert_eq!(tf.lookup_scalar(1e9).0, 4.0);        // clamped
/// assert_eq!(tf.lookup_scalar(f32::NAN).0, 0.0);   // NaN reads entry 0
/// assert!(tf.is_transparent(-5.0, 90.0));          // values up to 100 read entries 0 and 1 only
/// assert!(!tf.is_transparent(-5.0, 100.0));        // conservative at the boundary
/// ```
#[derive(Clone, Copy, Debug)]
pub struct TransferFunction<'a> {
    entries: &'a [TfEntry],
    lo: f32,
    hi: f32,
    scale: f32,
    last: f32,
    last_idx: i32,
}

impl<'a> TransferFunction<'a> {
    /// Most entries a table may have (`2^24`, so that entry indices are exact in `f32`); a
    /// longer one is [`VolumeError::TableTooLong`].
    ///
    /// ```
    /// use strahl::volume::{TransferFunction, VolumeError};
    /// assert_eq!(TransferFunction::MAX_ENTRIES, 1 << 24);
    /// let top = (TransferFunction::MAX_ENTRIES - 1) as f32; // the last index, exact in f32
    /// assert_eq!(top as usize, TransferFunction::MAX_ENTRIES - 1);
    /// assert_eq!(TransferFunction::new(&[], 0.0, 1.0).unwrap_err(), VolumeError::EmptyTable);
    /// ```
    pub const MAX_ENTRIES: usize = 1 << 24;

    /// A transfer function over `entries` for scalar values in `[lo, hi]`.
    ///
    /// Errors: [`VolumeError::EmptyTable`] for no entries, [`VolumeError::TableTooLong`] for
    /// more than [`MAX_ENTRIES`](Self::MAX_ENTRIES), [`VolumeError::InvalidRange`] unless
    /// `lo < hi` are finite, [`VolumeError::InvalidEntry`] for a colour channel that is NaN or
    /// beyond `±`[`COLOR_MAX`], or an extinction that is NaN, negative or above [`TAU_MAX`].
    ///
    /// ```
    /// use strahl::volume::{TfEntry, TransferFunction, VolumeError};
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// assert!(TransferFunction::new(&table, -1.0, 1.0).is_ok());
    /// assert_eq!(TransferFunction::new(&table, 1.0, 1.0).unwrap_err(), VolumeError::InvalidRange);
    /// assert_eq!(TransferFunction::new(&table, 0.0, f32::INFINITY).unwrap_err(), VolumeError::InvalidRange);
    /// let bad = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], -2.0)];
    /// assert_eq!(TransferFunction::new(&bad, 0.0, 1.0).unwrap_err(), VolumeError::InvalidEntry { index: 1 });
    /// ```
    pub fn new(entries: &'a [TfEntry], lo: f32, hi: f32) -> Result<Self, VolumeError> {
        if entries.is_empty() {
            return Err(VolumeError::EmptyTable);
        }
        if entries.len() > Self::MAX_ENTRIES {
            return Err(VolumeError::TableTooLong {
                len: entries.len(),
                max: Self::MAX_ENTRIES,
            });
        }
        if !(lo.is_finite() && hi.is_finite() && lo < hi && (hi - lo).is_finite()) {
            return Err(VolumeError::InvalidRange);
        }
        if let Some(index) = entries.iter().position(|e| {
            !(e.color.iter().all(|c| crate::math::abs(*c) <= COLOR_MAX) && e.tau >= 0.0 && e.tau <= TAU_MAX)
        }) {
            return Err(VolumeError::InvalidEntry { index });
        }
        let last_idx = entries.len() as i32 - 1;
        Ok(Self {
            entries,
            lo,
            hi,
            scale: last_idx as f32 / (hi - lo),
            last: last_idx as f32,
            last_idx,
        })
    }

    /// The table.
    ///
    /// ```
    /// use strahl::volume::{TfEntry, TransferFunction};
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    /// assert!(core::ptr::eq(tf.entries(), &table[..])); // borrowed, not copied
    /// ```
    #[inline]
    pub fn entries(&self) -> &'a [TfEntry] {
        self.entries
    }

    /// The scalar range `(lo, hi)` the table spans.
    ///
    /// ```
    /// use strahl::volume::{TfEntry, TransferFunction};
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
    /// let tf = TransferFunction::new(&table, -10.0, 30.0).unwrap();
    /// assert_eq!(tf.range(), (-10.0, 30.0));
    /// assert_eq!(tf.lookup_scalar(tf.range().1).0, 2.0); // the top of the range reads the last entry
    /// ```
    #[inline]
    pub fn range(&self) -> (f32, f32) {
        (self.lo, self.hi)
    }

    /// Largest `|c|` over all entries and channels: the factor in the early-termination bound.
    ///
    /// ```
    /// use strahl::volume::{TfEntry, TransferFunction};
    /// let table = [TfEntry::new([0.5, -3.0, 1.0], 0.0), TfEntry::new([2.0, 0.0, 0.25], 1.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    /// assert_eq!(tf.max_color(), 3.0); // by magnitude, transparent entries included
    /// ```
    pub fn max_color(&self) -> f32 {
        self.entries
            .iter()
            .flat_map(|e| e.color)
            .fold(0.0, |m, c| max_l(crate::math::abs(c), m))
    }

    /// Table coordinate of `s`, clamped.
    #[inline(always)]
    fn coord(&self, s: f32) -> f32 {
        min_l(max_l((s - self.lo) * self.scale, 0.0), self.last)
    }

    /// Extinction and colour at scalar value `s`.
    ///
    /// Reads entries `j` and `j + 1` with `j = min(floor(u), n - 2)` and weight `w = u - j` (so
    /// `w = 1` at the top of the range); a one-entry table is constant.
    ///
    /// ```
    /// use strahl::volume::{TfEntry, TransferFunction};
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.0], 4.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 2.0).unwrap();
    /// assert_eq!(tf.lookup_scalar(0.5), (1.0, [0.25, 0.125, 0.0])); // u = 0.25
    /// assert_eq!(tf.lookup_scalar(-1.0), (0.0, [0.0; 3])); // clamped to entry 0
    /// let one = [TfEntry::new([0.2; 3], 7.0)];
    /// assert_eq!(TransferFunction::new(&one, 0.0, 1.0).unwrap().lookup_scalar(123.0), (7.0, [0.2; 3]));
    /// ```
    #[inline(always)]
    pub fn lookup_scalar(&self, s: f32) -> (f32, [f32; 3]) {
        if self.last_idx == 0 {
            let e = &self.entries[0];
            return (e.tau, e.color);
        }
        let u = self.coord(s);
        let j = (u as i32).min(self.last_idx - 1);
        let w = u - j as f32;
        let (e0, e1) = (&self.entries[j as usize], &self.entries[j as usize + 1]);
        let l = |a: f32, b: f32| a + (b - a) * w;
        (
            l(e0.tau, e1.tau),
            [
                l(e0.color[0], e1.color[0]),
                l(e0.color[1], e1.color[1]),
                l(e0.color[2], e1.color[2]),
            ],
        )
    }

    /// Eight lookups; lane `i` equals [`lookup_scalar`](Self::lookup_scalar) of lane `i` bit for bit.
    ///
    /// ```
    /// use strahl::{math::f32x8, volume::{TfEntry, TransferFunction}};
    /// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.2], 3.0), TfEntry::new([0.1, 0.9, 0.3], 0.7)];
    /// let tf = TransferFunction::new(&table, 10.0, 50.0).unwrap();
    /// let s = [-5.0, 10.0, 17.3, 29.9, 30.0, 41.7, 50.0, f32::NAN];
    /// let (tau, c) = tf.lookup_x8(f32x8::new(s));
    /// for (i, &si) in s.iter().enumerate() {
    ///     let (t, col) = tf.lookup_scalar(si);
    ///     assert_eq!(tau.to_array()[i].to_bits(), t.to_bits());
    ///     assert!((0..3).all(|ch| c[ch].to_array()[i].to_bits() == col[ch].to_bits()));
    /// }
    /// ```
    #[inline(always)]
    pub fn lookup_x8(&self, s: f32x8) -> (f32x8, [f32x8; 3]) {
        if self.last_idx == 0 {
            let e = &self.entries[0];
            return (f32x8::splat(e.tau), e.color.map(f32x8::splat));
        }
        let u = ((s - f32x8::splat(self.lo)) * f32x8::splat(self.scale))
            .max_l(f32x8::splat(0.0))
            .min_l(f32x8::splat(self.last));
        let j = u.fast_trunc_int().min(i32x8::splat(self.last_idx - 1));
        let w = u - j.round_float();
        let e = self.entries;
        if e.len() < 2 {
            return (f32x8::splat(0.0), [f32x8::splat(0.0); 3]); // unreachable: last_idx > 0
        }
        let [r0, g0, b0, t0, r1, g1, b1, t1] = pair_columns(e, j.to_array());
        let l = |a: f32x8, b: f32x8| a + (b - a) * w;
        (l(t0, t1), [l(r0, r1), l(g0, g1), l(b0, b1)])
    }

    /// `true` if every value in `[min, max]` maps to zero extinction. Conservative: the range is
    /// widened by `(|min| + |max|) 2^-16` first, far more than the rounding of a trilinear
    /// interpolation can take a value outside the range of its voxels, and the entry after the
    /// last one reached is checked too (interpolation reads it). A NaN bound, or `min > max`, checks
    /// the whole table.
    ///
    /// ```
    /// use strahl::volume::{TfEntry, TransferFunction};
    /// // Entries at 0, 10, 20, 30: only the one at 30 has extinction.
    /// let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
    /// let tf = TransferFunction::new(&table, 0.0, 30.0).unwrap();
    /// assert!(tf.is_transparent(0.0, 15.0));
    /// assert!(!tf.is_transparent(0.0, 25.0)); // values above 20 interpolate towards the entry at 30
    /// assert!(!tf.is_transparent(f32::NAN, 1.0)); // checks the whole table
    /// ```
    pub fn is_transparent(&self, min: f32, max: f32) -> bool {
        let (a, b) = if min <= max {
            let pad = (crate::math::abs(min) + crate::math::abs(max)) * (1.0 / 65536.0) + f32::MIN_POSITIVE;
            // coord is monotone (every rounding is), so all values in the widened range map between.
            (self.coord(min - pad), self.coord(max + pad))
        } else {
            (0.0, self.last)
        };
        let first = (a as i32).min(self.last_idx - 1).max(0) as usize;
        let last = ((b as i32) + 1).min(self.last_idx) as usize;
        self.entries[first..=last].iter().all(|e| e.tau == 0.0)
    }

    /// A hash of what empty-space classification depends on: the range, the table length and which
    /// entries have zero extinction (colours do not matter). FNV-1a, 64 bits.
    ///
    /// ```
    /// use strahl::volume::{TfEntry, TransferFunction};
    /// let red = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.0, 0.0], 2.0)];
    /// let blue = [TfEntry::TRANSPARENT, TfEntry::new([0.0, 0.0, 1.0], 5.0)];
    /// let fp = |t: &[TfEntry], hi: f32| TransferFunction::new(t, 0.0, hi).unwrap().fingerprint();
    /// assert_eq!(fp(&red, 1.0), fp(&blue, 1.0)); // same empty entries: a grid classified for one fits both
    /// assert_ne!(fp(&red, 1.0), fp(&red, 2.0)); // another range
    /// assert_ne!(fp(&red, 1.0), fp(&[TfEntry::new([0.0; 3], 1.0), red[1]], 1.0)); // entry 0 no longer empty
    /// ```
    pub fn fingerprint(&self) -> u64 {
        const PRIME: u64 = 0x0000_0100_0000_01b3;
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |x: u64| {
            for b in x.to_le_bytes() {
                h = (h ^ b as u64).wrapping_mul(PRIME);
            }
        };
        eat(self.lo.to_bits() as u64 | (self.hi.to_bits() as u64) << 32);
        eat(self.entries.len() as u64);
        for chunk in self.entries.chunks(64) {
            let mut bits = 0u64;
            for (i, e) in chunk.iter().enumerate() {
                bits |= ((e.tau == 0.0) as u64) << i;
            }
            eat(bits);
        }
        h
    }
}

/// The entries `j[l]` and `j[l] + 1` of every lane `l`, as columns: `r0, g0, b0, tau0, r1, g1, b1,
/// tau1` across the lanes. Every `j[l]` is clamped to `0..=len - 2` (the callers' indices are in
/// range already; the clamp keeps every read in `e`). Needs `e.len() >= 2`.
#[inline(always)]
fn pair_columns(e: &[TfEntry], j: [i32; 8]) -> [f32x8; 8] {
    let jmax = e.len().saturating_sub(2);
    let at = |l: usize| (j[l] as u32 as usize).min(jmax);
    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    {
        // PERF: entry j of lanes l and l + 4 loaded into the halves of one register (the insert
        // from memory runs beside the shuffle port), then a 4 x 4 transpose within the halves:
        // 16 shuffles instead of the 24 of an 8 x 8 transpose of eight 32-byte rows. Dense
        // Marschner-Lobb 128^3, x8, best of 5 x 6 rounds taking turns (Intel Xeon, 2026-12-04):
        // 2 to 3% faster on u8, u16 and f32 voxels.
        use core::arch::x86_64::{
            __m256, _mm_loadu_ps, _mm256_castps128_ps256, _mm256_insertf128_ps, _mm256_shuffle_ps, _mm256_unpackhi_ps,
            _mm256_unpacklo_ps,
        };
        if e.len() < 2 {
            return [f32x8::splat(0.0); 8];
        }
        let p = e.as_ptr().cast::<f32>();
        let i = [at(0), at(1), at(2), at(3), at(4), at(5), at(6), at(7)];
        // SAFETY: `avx` is enabled for the whole build. Each read is the four floats of entry
        // `i[l] + o` (o = 0 or 1) with `i[l] <= len - 2`, so inside `e` (`TfEntry` is four `f32`,
        // `repr(C)`); the loads have no alignment requirement.
        unsafe {
            let pair = |a: usize, b: usize, o: usize| -> __m256 {
                let lo = _mm_loadu_ps(p.add(4 * (a + o)));
                _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(lo), _mm_loadu_ps(p.add(4 * (b + o))))
            };
            let t4 = |o: usize| -> [f32x8; 4] {
                let (u0, u1, u2, u3) = (
                    pair(i[0], i[4], o),
                    pair(i[1], i[5], o),
                    pair(i[2], i[6], o),
                    pair(i[3], i[7], o),
                );
                let (a0, a1) = (_mm256_unpacklo_ps(u0, u1), _mm256_unpackhi_ps(u0, u1));
                let (a2, a3) = (_mm256_unpacklo_ps(u2, u3), _mm256_unpackhi_ps(u2, u3));
                [
                    bytemuck::cast(_mm256_shuffle_ps::<0x44>(a0, a2)),
                    bytemuck::cast(_mm256_shuffle_ps::<0xee>(a0, a2)),
                    bytemuck::cast(_mm256_shuffle_ps::<0x44>(a1, a3)),
                    bytemuck::cast(_mm256_shuffle_ps::<0xee>(a1, a3)),
                ]
            };
            let ([r0, g0, b0, t0], [r1, g1, b1, t1]) = (t4(0), t4(1));
            [r0, g0, b0, t0, r1, g1, b1, t1]
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    {
        // Entries j and j + 1 are 8 adjacent floats: one load per lane, then an 8 x 8 transpose.
        let row = |l: usize| {
            let i = at(l);
            match (e.get(i), e.get(i + 1)) {
                (Some(&a), Some(&b)) => f32x8::new(bytemuck::cast::<[TfEntry; 2], [f32; 8]>([a, b])),
                _ => f32x8::splat(0.0), // unreachable: i <= len - 2
            }
        };
        f32x8::transpose([row(0), row(1), row(2), row(3), row(4), row(5), row(6), row(7)])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn construction_errors() {
        let ok = [TfEntry::TRANSPARENT; 4];
        assert_eq!(
            TransferFunction::new(&[], 0.0, 1.0).unwrap_err(),
            VolumeError::EmptyTable
        );
        // Too long: its own error, found before any entry is read (the zeros are calloc'd pages,
        // 256 MiB never touched); the longest table is accepted.
        let max = TransferFunction::MAX_ENTRIES;
        let zeros = alloc::vec![0u32; 4 * (max + 1)];
        let long: &[TfEntry] = bytemuck::cast_slice(&zeros);
        assert_eq!(
            TransferFunction::new(long, 0.0, 1.0).unwrap_err(),
            VolumeError::TableTooLong { len: max + 1, max }
        );
        let tf = TransferFunction::new(&long[..max], 0.0, 1.0).unwrap();
        assert_eq!(tf.entries().len(), max);
        for (lo, hi) in [
            (1.0, 1.0),
            (2.0, 1.0),
            (f32::NAN, 1.0),
            (0.0, f32::INFINITY),
            (-3e38, 3e38),
        ] {
            assert_eq!(
                TransferFunction::new(&ok, lo, hi).unwrap_err(),
                VolumeError::InvalidRange,
                "{lo} {hi}"
            );
        }
        for bad in [
            TfEntry::new([f32::NAN, 0.0, 0.0], 1.0),
            TfEntry::new([0.0; 3], -1.0),
            TfEntry::new([0.0; 3], f32::NAN),
            TfEntry::new([0.0; 3], f32::INFINITY),
            TfEntry::new([0.0, f32::MAX, 0.0], 1.0),
            TfEntry::new([0.0, 0.0, -2.0 * COLOR_MAX], 0.0),
            TfEntry::new([f32::NEG_INFINITY, 0.0, 0.0], 0.0),
        ] {
            let t = [TfEntry::TRANSPARENT, bad];
            assert_eq!(
                TransferFunction::new(&t, 0.0, 1.0).unwrap_err(),
                VolumeError::InvalidEntry { index: 1 }
            );
        }
    }

    #[test]
    fn extreme_colours_interpolate_to_finite_values() {
        // +COLOR_MAX beside -COLOR_MAX: `a + (b - a) w` must not overflow anywhere in between (the
        // fuzzer found `+MAX`/`-MAX` entries giving NaN at w = 0 before COLOR_MAX was enforced).
        let m = COLOR_MAX;
        let t = [
            TfEntry::new([m, -m, m], 0.0),
            TfEntry::new([-m, m, m], 0.0),
            TfEntry::new([m, -m, -m], 1.0),
        ];
        let tf = TransferFunction::new(&t, 0.0, 2.0).unwrap();
        for i in 0..=64 {
            let s = i as f32 / 32.0;
            let (tau, c) = tf.lookup_scalar(s);
            assert!(
                tau.is_finite() && c.iter().all(|c| c.is_finite() && c.abs() <= m),
                "{s}: {c:?}"
            );
            let (tau8, c8) = tf.lookup_x8(f32x8::splat(s));
            assert_eq!(tau8.to_array()[3].to_bits(), tau.to_bits());
            assert_eq!(c8.map(|c| c.to_array()[5].to_bits()), c.map(f32::to_bits));
        }
    }

    #[test]
    fn authoring_conversions() {
        assert_eq!(
            TfEntry::from_rgba_premultiplied([1.0, 1.0, 1.0, 0.0], 1.0),
            TfEntry::TRANSPARENT
        );
        assert_eq!(
            TfEntry::from_rgba_premultiplied([0.5, 0.5, 0.5, f32::NAN], 1.0).tau,
            0.0
        );
        assert_eq!(TfEntry::from_rgba_premultiplied([0.5, 0.5, 0.5, 0.5], 0.0).tau, 0.0);
        let opaque = TfEntry::from_rgba_premultiplied([1.0, 0.0, 0.0, 1.0], 1.0);
        assert_eq!(opaque.tau, TAU_MAX);
        assert_eq!(opaque.opacity(1e-6), 1.0);
        let s = TfEntry::from_rgba_straight([0.2, 0.4, 0.6, 0.3], 0.5);
        assert_eq!(s.color, [0.2, 0.4, 0.6]);
        assert!((s.opacity(0.5) - 0.3).abs() < 1e-6);
        // Opacity correction agrees with the extinction form.
        for (a0, dt, dt0) in [(0.1f32, 0.3f32, 0.1f32), (0.9, 0.01, 1.0), (0.5, 1.0, 1.0)] {
            let e = TfEntry::from_rgba_straight([1.0; 4].map(|x| x * a0), dt0);
            assert!((e.opacity(dt) - correct_opacity(a0, dt, dt0)).abs() < 1e-6);
        }
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn lanes_equal_scalar_and_transparency_is_conservative() {
        let mut table = [TfEntry::TRANSPARENT; 17];
        for (i, e) in table.iter_mut().enumerate() {
            if (6..11).contains(&i) {
                *e = TfEntry::new([i as f32 * 0.1, 1.0, 0.5], i as f32 * 0.7);
            }
        }
        let tf = TransferFunction::new(&table, -3.0, 13.0).unwrap();
        let vals: [f32; 16] = [
            -10.0,
            -3.0,
            -2.999,
            0.0,
            2.5,
            2.9999,
            3.0,
            3.0001,
            7.25,
            12.999,
            13.0,
            1e30,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
        ];
        for c in vals.chunks(8) {
            let a: [f32; 8] = c.try_into().unwrap();
            let (t8, c8) = tf.lookup_x8(f32x8::new(a));
            for i in 0..8 {
                let (t, col) = tf.lookup_scalar(a[i]);
                assert_eq!(t8.to_array()[i].to_bits(), t.to_bits());
                for ch in 0..3 {
                    assert_eq!(c8[ch].to_array()[i].to_bits(), col[ch].to_bits());
                }
            }
        }
        // Entries 6..=10 are opaque: values in [3, 7] map to them (entry = value + 3).
        assert!(tf.is_transparent(-3.0, 1.0));
        assert!(!tf.is_transparent(-3.0, 2.5));
        assert!(!tf.is_transparent(8.0, 20.0));
        assert!(tf.is_transparent(9.0, 20.0));
        assert!(!tf.is_transparent(f32::NAN, 0.0));
        // Every value judged transparent looks up zero extinction.
        for i in 0..=1600 {
            let s = -3.0 + i as f32 * 0.01;
            if tf.is_transparent(s, s) {
                assert_eq!(tf.lookup_scalar(s).0, 0.0, "{s}");
            }
        }
        assert_eq!(tf.max_color(), 1.0);
    }

    #[test]
    fn fingerprint_ignores_colour() {
        let a = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 1.0)];
        let b = [TfEntry::TRANSPARENT, TfEntry::new([0.5; 3], 3.0)];
        let c = [TfEntry::new([0.5; 3], 3.0), TfEntry::TRANSPARENT];
        let f = |t: &[TfEntry], hi| TransferFunction::new(t, 0.0, hi).unwrap().fingerprint();
        assert_eq!(f(&a, 1.0), f(&b, 1.0));
        assert_ne!(f(&a, 1.0), f(&c, 1.0));
        assert_ne!(f(&a, 1.0), f(&a, 2.0));
    }
}
