//! Direct volume rendering: structured grids, transfer functions, fixed-step ray marching with
//! early ray termination and empty-space skipping.
//!
//! Pipeline stage: after the rays are made and before [`composite`](crate::composite). Input: a
//! [`Volume`] of `u8`, `u16` or `f32` voxels (taken zero-copy from bytes), a [`TransferFunction`],
//! optionally a [`MacrocellGrid`], and rays. Output: one premultiplied [`Rgba`] per ray, written to a
//! caller-provided slice. Nothing here allocates; only [`MacrocellGrid::build`] (feature `alloc`)
//! owns its storage, and [`MacrocellGrid::build_in`] does the same in a caller's slice.
//!
//! # The optical model (Max 1995)
//! Emission and absorption, after N. Max, "Optical Models for Direct Volume Rendering", IEEE TVCG
//! 1(2), 1995. Along a ray that enters the volume at `t = 0` (`t` in world units), with extinction
//! coefficient `tau(t)` (per world unit) and emitted colour `c(t)`, the light reaching the eye is
//!
//! ```text
//! I(L) = I0 T(L) + int_0^L c(u) tau(u) exp(-int_0^u tau) du,     T(L) = exp(-int_0^L tau)
//! ```
//!
//! The kernels return `C` (the integral) and `A = 1 - T(L)` (the opacity) as a premultiplied
//! [`Rgba`]; a background `I0` is added by the caller as `C + (1 - A) I0` (the over operator).
//!
//! # The discretisation
//! The ray is clipped to the volume's box and cut into steps of length `dt` ([`MarchParams::step`])
//! on one lattice, `t_k = k dt` from the entry point, computed as `k * dt` from an integer `k`
//! (never accumulated, so no drift and no hang: a ray has at most [`MarchParams::max_steps`]
//! samples). Step `k` covers `[t_k, t_k + h_k]` with `h_k = min(dt, L - t_k)` (only the last step is
//! shorter). Each step takes one sample of `tau` and `c`, at its start ([`Sampling::Endpoint`],
//! first order) or its middle ([`Sampling::Midpoint`], second order), and composites front to back
//! (a left Riemann sum of the optical depth inside the exponential):
//!
//! ```text
//! a = 1 - exp(-tau h)        C += (1 - A) a c        A += (1 - A) a
//! ```
//!
//! For constant `tau` and `c` this is exact at any step: `A = 1 - exp(-tau L)`, `C = c A`.
//!
//! # Transfer functions and the colour convention
//! A [`TransferFunction`] maps a scalar voxel value to a [`TfEntry`]: an emitted colour `c` (not
//! premultiplied) and an extinction `tau` (per world unit). Tables written as RGBA with opacity
//! `alpha0` *for a reference step* `dt0` (the usual way to author them) convert with
//! `tau = -ln(1 - alpha0) / dt0`; marching at another step `dt` then gives the opacity correction
//! `a = 1 - exp(-tau dt) = 1 - (1 - alpha0)^(dt / dt0)` and the premultiplied colour `a c`
//! ([`TfEntry::from_rgba_premultiplied`], [`correct_opacity`]). Between table entries `c` and
//! `tau` are interpolated linearly (not the opacity), so a scalar that varies linearly gives an
//! extinction that varies linearly.
//!
//! # Early ray termination
//! With [`MarchParams::termination`] `= Some(eps)` a ray stops once `1 - A <= eps`. Every later
//! step adds `(1 - A) a c`, and their sum is at most `(1 - A) max|c| <= eps max|c|` per channel
//! (and at most `eps` to `A`): that is the whole error it costs ([`TransferFunction::max_color`]
//! gives `max|c|`). `Some(0.0)` stops only at `A == 1`, where every later step adds exactly zero:
//! the image is bit-identical to `None`.
//!
//! # Empty-space skipping
//! A [`MacrocellGrid`] stores the minimum and maximum voxel value of each block of cells, including
//! the interpolation halo, and, after [`MacrocellGrid::classify`] with a transfer function, which
//! blocks are transparent. The marcher jumps over samples that fall in transparent blocks, to the
//! next lattice sample, so the samples it does take are the same ones at the same `t_k`, and the
//! ones it skips would have added exactly `+0`: the image is **bit-identical** with and without
//! skipping (see [`skip`] for why, and for the margin that keeps it so under rounding). The grid
//! remembers which transfer function it was classified with; a [`VolumeMedium`] refuses a stale
//! one ([`VolumeError::StaleGrid`]).
//!
//! # Scalar reference and SIMD
//! [`integrate_scalar`] marches one ray at a time; [`integrate_x8`] marches eight rays in the
//! lanes of [`f32x8`](crate::math::f32x8) and refills a lane from the ray slice as soon as its ray
//! finishes. Both do the same IEEE operations in the same order (no fused multiply-add; the step
//! opacity `1 - exp(-tau h)` is one polynomial, [`one_minus_exp_neg_scalar`] /
//! [`one_minus_exp_neg_x8`], in both, accurate also where `tau h` is tiny), so their results are
//! **bit-identical** (0 ULP), with or without skipping and termination. [`integrate`] picks x8.
//!
//! # Pre-integration
//! For transfer functions with features narrower than the scalar change over a step (thin
//! iso-bands), [`integrate_preintegrated`] marches a [`PreintegratedMedium`]: the scalar at both
//! ends of each step and the step's whole contribution from a [`PreintegratedTable`], exact for a
//! scalar that is linear along the step. Same lattice, clipping, termination and bit-identical
//! scalar/x8 pair; see [`preint`] for the table, its accuracy and its cost.
//!
//! # Bad input
//! Never a panic and never a hang. Parameters are checked ([`MarchParams::validate`]): a step that
//! is `0`, negative, NaN or infinite is [`VolumeError::InvalidStep`]. Invalid rays, rays that miss
//! the volume, zero-length rays and empty volumes give [`Rgba::ZERO`]. An infinite `tmax` is
//! clipped by the box. A ray whose start is so far out that `t + dt == t` in `f32` is still marched
//! correctly as long as its entry point is representable, because marching starts over at the entry
//! point; the number of samples is an integer, bounded by the box's diagonal and by
//! [`MarchParams::max_steps`].
//!
//! # References
//! - N. Max, "Optical Models for Direct Volume Rendering", IEEE TVCG 1(2), 1995.
//! - K. Engel, M. Kraus, T. Ertl, "High-Quality Pre-Integrated Volume Rendering Using
//!   Hardware-Accelerated Pixel Shading", Graphics Hardware 2001 ([`preint`]: pre-integrated
//!   transfer functions).
//! - T. Etiene, D. Jönsson, T. Ropinski, C. Scheidegger, J. Comba, L. G. Nonato, R. M. Kirby,
//!   A. Ynnerman, C. T. Silva, "Verifying Volume Rendering Using Discretization Error Analysis",
//!   IEEE TVCG 20(1), 2014 (the convergence-order tests in `tests/volume.rs`).
//!
//! # Example
//! ```
//! use strahl::{Ray, Vec3};
//! use strahl::volume::{MarchParams, Rgba, TfEntry, TransferFunction, Volume, VolumeMedium, integrate};
//! // A 2 x 2 x 2 volume of u8 taken from bytes, spanning the unit cube.
//! let bytes = [0u8, 0, 0, 0, 255, 255, 255, 255];
//! let vol = Volume::<u8>::from_bytes(&bytes, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
//! // Value 0 is clear; value 255 is white with extinction 2 per unit length.
//! let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
//! let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
//! let medium = VolumeMedium::new(vol, tf);
//! let rays = [Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z)];
//! let mut out = [Rgba::ZERO];
//! integrate(&medium, &rays, &mut out, &MarchParams::reference(1.0 / 64.0)).unwrap();
//! // tau rises linearly from 0 to 2 along the ray: optical depth 1.
//! assert!((out[0].a - (1.0 - (-1.0f32).exp())).abs() < 1e-4);
//! ```

mod exp;
mod grid;
mod march;
mod medium;
pub mod preint;
#[cfg(feature = "alloc")]
pub mod procedural;
pub mod skip;
mod transfer;

pub use exp::{ONE_MINUS_EXP_NEG_MAX_EPS, one_minus_exp_neg_scalar, one_minus_exp_neg_x8};
pub use grid::{Volume, Voxel};
pub use march::{
    DEFAULT_MAX_STEPS, MAX_STEPS_LIMIT, MarchParams, MarchStats, Sampling, integrate, integrate_preintegrated,
    integrate_preintegrated_scalar, integrate_preintegrated_x8, integrate_ray, integrate_scalar, integrate_x8,
};
pub use medium::{EmptyRegion, Lookup, Medium, Sample, SampleX8, VolumeMedium};
pub use preint::{PREINTEGRATED_MAX_RES, PREINTEGRATED_MAX_WORK, PreintegratedMedium, PreintegratedTable};
pub use skip::{GridParams, MAX_EMPTY_RADIUS, Macrocell, MacrocellGrid};
pub use transfer::{COLOR_MAX, TAU_MAX, TfEntry, TransferFunction, correct_opacity};

use bytemuck::{Pod, Zeroable};
use core::fmt;

/// A premultiplied colour and opacity: what one ray gathered, `C` and `A` in the module docs.
///
/// Composite it over a background `bg` as `C + (1 - A) bg`.
///
/// ```
/// use strahl::volume::Rgba;
/// let p = Rgba { r: 0.25, g: 0.0, b: 0.0, a: 0.5 };
/// assert_eq!(p.over([0.0, 0.0, 1.0]), [0.25, 0.0, 0.5]);
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Rgba {
    /// Red, premultiplied by opacity.
    pub r: f32,
    /// Green, premultiplied.
    pub g: f32,
    /// Blue, premultiplied.
    pub b: f32,
    /// Opacity `A = 1 - transmittance`, in `[0, 1]`.
    pub a: f32,
}

const _: () = assert!(core::mem::size_of::<Rgba>() == 16);

impl Rgba {
    /// Nothing gathered: fully transparent.
    ///
    /// ```
    /// use strahl::volume::Rgba;
    /// assert_eq!(Rgba::ZERO, Rgba::default());
    /// assert_eq!(Rgba::ZERO.over([0.3, 0.6, 0.9]), [0.3, 0.6, 0.9]); // the background shows through
    /// assert!(Rgba::ZERO.bit_eq(&bytemuck::Zeroable::zeroed()));
    /// ```
    pub const ZERO: Self = Self {
        r: 0.0,
        g: 0.0,
        b: 0.0,
        a: 0.0,
    };

    /// `self` over an opaque background colour: `C + (1 - A) bg`.
    ///
    /// ```
    /// use strahl::volume::Rgba;
    /// let half_red = Rgba { r: 0.5, g: 0.0, b: 0.0, a: 0.5 };
    /// assert_eq!(half_red.over([0.0, 1.0, 0.0]), [0.5, 0.5, 0.0]);
    /// assert_eq!(Rgba::ZERO.over([0.2, 0.4, 0.6]), [0.2, 0.4, 0.6]); // nothing in front
    /// ```
    #[inline]
    pub fn over(&self, bg: [f32; 3]) -> [f32; 3] {
        let t = 1.0 - self.a;
        [self.r + t * bg[0], self.g + t * bg[1], self.b + t * bg[2]]
    }

    /// `true` if all four components have the same bits as `other`'s (stricter than `==`, which
    /// equates `0.0` and `-0.0`).
    ///
    /// ```
    /// use strahl::volume::Rgba;
    /// let neg = Rgba { r: -0.0, ..Rgba::ZERO };
    /// assert!(neg == Rgba::ZERO && !neg.bit_eq(&Rgba::ZERO));
    /// assert!(Rgba { a: 0.5, ..Rgba::ZERO }.bit_eq(&Rgba { a: 0.5, ..Rgba::ZERO }));
    /// ```
    #[inline]
    pub fn bit_eq(&self, other: &Rgba) -> bool {
        bytemuck::bytes_of(self) == bytemuck::bytes_of(other)
    }
}

/// What went wrong with a volume, a transfer function, a grid or marching parameters.
///
/// ```
/// use strahl::volume::{MarchParams, VolumeError};
/// let e = MarchParams::reference(0.0).validate().unwrap_err();
/// assert_eq!(e, VolumeError::InvalidStep);
/// assert!(format!("{e}").contains("step"));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum VolumeError {
    /// The voxel bytes are not aligned for the voxel type (`u16` needs 2, `f32` needs 4).
    Misaligned {
        /// Alignment the voxel type needs, in bytes.
        required: usize,
    },
    /// The number of voxels (or bytes) does not match the dimensions.
    SizeMismatch {
        /// Voxels (or bytes) the dimensions call for.
        expected: usize,
        /// Voxels (or bytes) given.
        actual: usize,
    },
    /// `nx ny nz` overflows, or exceeds [`Volume::MAX_VOXELS`].
    TooLarge,
    /// Spacing not finite and positive, or origin not finite.
    InvalidGeometry,
    /// Step size `0`, negative, NaN or infinite.
    InvalidStep,
    /// Termination epsilon NaN or outside `[0, 1)`.
    InvalidTermination,
    /// `max_steps` is `0` or above [`MAX_STEPS_LIMIT`].
    InvalidMaxSteps,
    /// Transfer function range not finite or not increasing (`lo < hi`).
    InvalidRange,
    /// A transfer function without entries.
    EmptyTable,
    /// A transfer function table longer than [`TransferFunction::MAX_ENTRIES`].
    ///
    /// ```
    /// use strahl::volume::{TfEntry, TransferFunction, VolumeError};
    /// let max = TransferFunction::MAX_ENTRIES;
    /// // 256 MiB of zeros (calloc'd: the pages are never touched, the length is checked first).
    /// let zeros = vec![0u32; 4 * (max + 1)];
    /// let table: &[TfEntry] = bytemuck::cast_slice(&zeros);
    /// let err = TransferFunction::new(table, 0.0, 1.0).unwrap_err();
    /// assert_eq!(err, VolumeError::TableTooLong { len: max + 1, max });
    /// assert_eq!(err.to_string(), "transfer function table has 16777217 entries, at most 16777216 allowed");
    /// ```
    TableTooLong {
        /// Entries given.
        len: usize,
        /// The most a table may have ([`TransferFunction::MAX_ENTRIES`]).
        max: usize,
    },
    /// A transfer function entry with a colour channel that is NaN or beyond `±`[`COLOR_MAX`], or an
    /// extinction that is NaN, negative or above [`TAU_MAX`].
    InvalidEntry {
        /// Index of the first bad entry.
        index: usize,
    },
    /// Macrocell block size not a power of two in `2..=64`.
    InvalidBlock,
    /// A caller-provided buffer is too small.
    StorageTooSmall {
        /// Elements needed.
        needed: usize,
        /// Elements given.
        actual: usize,
    },
    /// A macrocell grid built for a volume of other dimensions.
    GridMismatch,
    /// A macrocell grid not classified, or classified with a transfer function whose transparent
    /// entries or value range differ from the one in use: call [`MacrocellGrid::classify`] again.
    StaleGrid,
    /// A pre-integrated table's resolution outside `2..=`[`PREINTEGRATED_MAX_RES`], or so high for
    /// the transfer function's length that the build would exceed [`PREINTEGRATED_MAX_WORK`].
    InvalidResolution,
    /// A pre-integrated table built for another step than [`MarchParams::step`]: build it for
    /// that step ([`PreintegratedTable::build`]).
    StepMismatch,
    /// The output slice is shorter than the ray slice.
    LengthMismatch {
        /// Number of rays.
        rays: usize,
        /// Length of the output slice.
        out: usize,
    },
}

impl fmt::Display for VolumeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Misaligned { required } => {
                write!(
                    f,
                    "voxel bytes are not aligned to {required} bytes as the voxel type needs"
                )
            }
            Self::SizeMismatch { expected, actual } => {
                write!(f, "dimensions call for {expected} voxels (or bytes), got {actual}")
            }
            Self::TooLarge => write!(f, "volume dimensions overflow or exceed the voxel limit"),
            Self::InvalidGeometry => write!(f, "volume spacing must be finite and positive, origin finite"),
            Self::InvalidStep => write!(f, "step size must be finite and positive"),
            Self::InvalidTermination => write!(f, "termination epsilon must lie in [0, 1)"),
            Self::InvalidMaxSteps => write!(f, "max_steps must lie in 1..={MAX_STEPS_LIMIT}"),
            Self::InvalidRange => write!(f, "transfer function range must be finite with lo < hi"),
            Self::EmptyTable => write!(f, "transfer function table has no entries"),
            Self::TableTooLong { len, max } => {
                write!(f, "transfer function table has {len} entries, at most {max} allowed")
            }
            Self::InvalidEntry { index } => write!(
                f,
                "transfer function entry {index}: colour must be in [-COLOR_MAX, COLOR_MAX], extinction in [0, TAU_MAX]"
            ),
            Self::InvalidBlock => write!(f, "macrocell block size must be a power of two in 2..=64"),
            Self::StorageTooSmall { needed, actual } => {
                write!(f, "buffer holds {actual} elements, {needed} needed")
            }
            Self::GridMismatch => write!(f, "macrocell grid was built for a volume of other dimensions"),
            Self::StaleGrid => write!(
                f,
                "macrocell grid is not classified for this transfer function: call classify again"
            ),
            Self::InvalidResolution => {
                write!(
                    f,
                    "pre-integrated table resolution must lie in 2..={PREINTEGRATED_MAX_RES}, with res^2 x (entries - 1) at most {PREINTEGRATED_MAX_WORK}"
                )
            }
            Self::StepMismatch => write!(
                f,
                "pre-integrated table was built for another step than the marching step: build it for that step"
            ),
            Self::LengthMismatch { rays, out } => {
                write!(f, "{rays} rays but room for {out} results")
            }
        }
    }
}

impl core::error::Error for VolumeError {}
