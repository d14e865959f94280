//! The integrator: fixed-step front-to-back ray marching, scalar reference and 8 rays at once.

use super::exp::{one_minus_exp_neg_scalar, one_minus_exp_neg_x8};
use super::medium::{EmptyRegion, Lookup, Medium};
use super::preint::PreintegratedMedium;
use super::{Rgba, VolumeError, Voxel};
use crate::geometry::{Aabb, Ray};
use crate::math::{Lane, abs, ceil, f32x8, max_l, min_l, sign_bit};
use glam::Vec3;

/// Default [`MarchParams::max_steps`]: `2^16` samples per ray, enough for a step of a quarter
/// voxel across the diagonal of a `9000^3` volume.
///
/// ```
/// use strahl::volume::{DEFAULT_MAX_STEPS, MarchParams};
/// assert_eq!(MarchParams::reference(0.1).max_steps, DEFAULT_MAX_STEPS);
/// let diagonal = 9000.0 * 3f32.sqrt(); // in voxels
/// assert!(diagonal / 0.25 < DEFAULT_MAX_STEPS as f32);
/// ```
pub const DEFAULT_MAX_STEPS: u32 = 1 << 16;

/// Largest [`MarchParams::max_steps`]: `2^24`, so that every step index is exact in `f32`.
///
/// ```
/// use strahl::volume::{MAX_STEPS_LIMIT, MarchParams, VolumeError};
/// let p = MarchParams { max_steps: MAX_STEPS_LIMIT, ..MarchParams::fast(0.5) };
/// assert!(p.validate().is_ok());
/// assert_eq!((MAX_STEPS_LIMIT - 1) as f32 as u32, MAX_STEPS_LIMIT - 1); // exact
/// let over = MarchParams { max_steps: MAX_STEPS_LIMIT + 1, ..p };
/// assert_eq!(over.validate(), Err(VolumeError::InvalidMaxSteps));
/// ```
pub const MAX_STEPS_LIMIT: u32 = 1 << 24;

/// Where each step takes its sample.
///
/// ```
/// use strahl::{Aabb, Ray, Vec3, volume::*};
/// /// Extinction rising linearly with depth: the optical depth over [0, 1] is 1.
/// struct Ramp;
/// impl Medium for Ramp {
///     fn bounds(&self) -> Aabb { Aabb::new(Vec3::ZERO, Vec3::ONE) }
///     fn lookup(&self, g: Vec3) -> Lookup { Lookup::Sample(Sample { tau: 2.0 * g.z, color: [1.0; 3] }) }
/// }
/// let ray = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z);
/// let exact = 1.0 - (-1.0f32).exp();
/// let err = |sampling| {
///     let p = MarchParams { sampling, ..MarchParams::reference(0.125) };
///     (integrate_ray(&Ramp, &ray, &p).unwrap().a - exact).abs()
/// };
/// assert_eq!(Sampling::default(), Sampling::Midpoint);
/// assert!(err(Sampling::Midpoint) < 1e-5); // exact for a linear tau
/// assert!(err(Sampling::Endpoint) > 0.01); // a left sum: first order in dt
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Sampling {
    /// At the start of the step, `t_k = k dt`: a left Riemann sum, first order in `dt`.
    Endpoint,
    /// In the middle of the step, `t_k + h_k / 2`: the midpoint rule, second order in `dt`.
    #[default]
    Midpoint,
}

/// The knobs of the marcher, in one place.
///
/// | field | meaning | presets |
/// |---|---|---|
/// | [`step`](Self::step) | `dt`, world units | the argument of every preset; half the voxel spacing or less for a band-limited volume |
/// | [`sampling`](Self::sampling) | [`Sampling::Endpoint`] or [`Sampling::Midpoint`] | midpoint in all presets |
/// | [`termination`](Self::termination) | early ray termination: stop once `1 - A <= eps` | `reference`: off, `quality`: `Some(0.0)` (exact), `fast`: `Some(1/256)` |
/// | [`max_steps`](Self::max_steps) | samples per ray at most | [`DEFAULT_MAX_STEPS`] |
///
/// ```
/// use strahl::volume::{MarchParams, Sampling, VolumeError};
/// let p = MarchParams::fast(0.5);
/// assert_eq!((p.step, p.sampling, p.termination), (0.5, Sampling::Midpoint, Some(1.0 / 256.0)));
/// assert!(p.validate().is_ok());
/// for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
///     assert_eq!(MarchParams::reference(bad).validate(), Err(VolumeError::InvalidStep));
/// }
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarchParams {
    /// Step length `dt` in world units (finite, `> 0`).
    pub step: f32,
    /// Where a step takes its sample.
    pub sampling: Sampling,
    /// `None`: march every ray to its end. `Some(eps)`, `eps` in `[0, 1)`: stop a ray once its
    /// transmittance `1 - A` is at most `eps`; this changes each colour channel by at most
    /// `eps max|c|` and `A` by at most `eps`. `Some(0.0)` stops only at `A == 1` and is exact (the
    /// image is bit-identical to `None`); `A` rounds to exactly 1 in opaque media (steps with
    /// opacity above 1/2 near the end), while in thin media it can settle at `1 - 2^-24`, and then
    /// `Some(0.0)` never stops a ray early.
    pub termination: Option<f32>,
    /// Samples per ray at most, in `1..=MAX_STEPS_LIMIT`. A ray that would need more is marched
    /// over its first `max_steps` steps only and counted in [`MarchStats::truncated`].
    pub max_steps: u32,
}

impl MarchParams {
    /// The reference: midpoint sampling, no early termination.
    ///
    /// ```
    /// use strahl::volume::{DEFAULT_MAX_STEPS, MarchParams, Sampling};
    /// let p = MarchParams::reference(0.25);
    /// assert_eq!((p.step, p.sampling, p.termination), (0.25, Sampling::Midpoint, None));
    /// assert_eq!(p.max_steps, DEFAULT_MAX_STEPS);
    /// ```
    pub const fn reference(step: f32) -> Self {
        Self {
            step,
            sampling: Sampling::Midpoint,
            termination: None,
            max_steps: DEFAULT_MAX_STEPS,
        }
    }

    /// Midpoint sampling, termination at full opacity only: the same image as
    /// [`reference`](Self::reference), faster on opaque volumes.
    ///
    /// ```
    /// # use strahl::{Ray, Vec3, volume::*};
    /// # let data: Vec<u8> = (0..8 * 8 * 8).map(|i| (i * 37 % 251) as u8).collect();
    /// # let vol = Volume::new(&data, [8; 3], Vec3::splat(0.25), Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.2], 6.0), TfEntry::new([0.2, 0.5, 1.0], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let rays: Vec<Ray> = (0..11)
    /// #     .map(|i| Ray::new(Vec3::new(0.1 + 0.15 * i as f32, 0.9, -1.0), Vec3::new(0.0, -0.2, 1.0)))
    /// #     .collect();
    /// let (mut a, mut b) = (vec![Rgba::ZERO; 11], vec![Rgba::ZERO; 11]);
    /// let m = VolumeMedium::new(vol, tf); // rays: 11 rays across an 8^3 volume
    /// let sr = integrate(&m, &rays, &mut a, &MarchParams::reference(0.05)).unwrap();
    /// let sq = integrate(&m, &rays, &mut b, &MarchParams::quality(0.05)).unwrap();
    /// assert!(a.iter().zip(&b).all(|(x, y)| x.bit_eq(y))); // the same image
    /// assert!(sq.samples <= sr.samples);
    /// ```
    pub const fn quality(step: f32) -> Self {
        Self {
            termination: Some(0.0),
            ..Self::reference(step)
        }
    }

    /// Midpoint sampling, termination at `1 - A <= 1/256`: an error of at most `max|c| / 256` per
    /// channel, below the resolution of an 8-bit image.
    ///
    /// ```
    /// # use strahl::{Ray, Vec3, volume::*};
    /// # let data: Vec<u8> = (0..8 * 8 * 8).map(|i| (i * 37 % 251) as u8).collect();
    /// # let vol = Volume::new(&data, [8; 3], Vec3::splat(0.25), Vec3::ZERO).unwrap();
    /// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.2], 6.0), TfEntry::new([0.2, 0.5, 1.0], 1.0)];
    /// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    /// # let rays: Vec<Ray> = (0..11)
    /// #     .map(|i| Ray::new(Vec3::new(0.1 + 0.15 * i as f32, 0.9, -1.0), Vec3::new(0.0, -0.2, 1.0)))
    /// #     .collect();
    /// let (mut a, mut b) = (vec![Rgba::ZERO; 11], vec![Rgba::ZERO; 11]);
    /// let m = VolumeMedium::new(vol, tf); // rays: 11 rays across an 8^3 volume
    /// integrate(&m, &rays, &mut a, &MarchParams::reference(0.05)).unwrap();
    /// integrate(&m, &rays, &mut b, &MarchParams::fast(0.05)).unwrap();
    /// let bound = tf.max_color() / 256.0;
    /// for (x, y) in a.iter().zip(&b) {
    ///     assert!((x.r - y.r).abs() <= bound && (x.a - y.a).abs() <= 1.0 / 256.0);
    /// }
    /// ```
    pub const fn fast(step: f32) -> Self {
        Self {
            termination: Some(1.0 / 256.0),
            ..Self::reference(step)
        }
    }

    /// Checks every field: [`VolumeError::InvalidStep`], [`VolumeError::InvalidTermination`],
    /// [`VolumeError::InvalidMaxSteps`].
    ///
    /// ```
    /// use strahl::volume::{MarchParams, VolumeError};
    /// assert_eq!(MarchParams::fast(0.1).validate(), Ok(()));
    /// assert_eq!(MarchParams::reference(-0.1).validate(), Err(VolumeError::InvalidStep));
    /// let eps = MarchParams { termination: Some(1.0), ..MarchParams::fast(0.1) };
    /// assert_eq!(eps.validate(), Err(VolumeError::InvalidTermination)); // must be below 1
    /// let zero = MarchParams { max_steps: 0, ..MarchParams::fast(0.1) };
    /// assert_eq!(zero.validate(), Err(VolumeError::InvalidMaxSteps));
    /// ```
    pub fn validate(&self) -> Result<(), VolumeError> {
        if !(self.step > 0.0 && self.step.is_finite()) {
            return Err(VolumeError::InvalidStep);
        }
        if let Some(eps) = self.termination
            && !(0.0..1.0).contains(&eps)
        {
            return Err(VolumeError::InvalidTermination);
        }
        if self.max_steps == 0 || self.max_steps > MAX_STEPS_LIMIT {
            return Err(VolumeError::InvalidMaxSteps);
        }
        Ok(())
    }
}

/// Counters of one call of a marcher that takes many rays: [`integrate_scalar`],
/// [`integrate_x8`] and [`integrate`], and the pre-integrated ones,
/// [`integrate_preintegrated_scalar`], [`integrate_preintegrated_x8`] and
/// [`integrate_preintegrated`] (where `samples` counts the steps marched, each a look-up of the
/// pre-integrated table for the scalars at its ends). The scalar and `x8` kernels of each kind
/// count alike ([`integrate_ray`] marches one ray and returns no counters).
///
/// ```
/// # use strahl::{Ray, Vec3, volume::*};
/// # let data = [1.0f32; 8];
/// # let vol = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
/// # let table = [TfEntry::new([1.0; 3], 1.0)];
/// let m = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 1.0).unwrap()); // the unit cube
/// let rays = [
///     Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z), // crosses the unit cube: 1 / 0.25 = 4 steps
///     Ray::new(Vec3::new(5.0, 0.5, -1.0), Vec3::Z), // misses
/// ];
/// let mut out = [Rgba::ZERO; 2];
/// let stats = integrate_scalar(&m, &rays, &mut out, &MarchParams::reference(0.25)).unwrap();
/// assert_eq!(stats, MarchStats { rays: 1, samples: 4, ..MarchStats::default() });
/// let cut = MarchParams { max_steps: 3, ..MarchParams::reference(0.25) };
/// assert_eq!(integrate_scalar(&m, &rays, &mut out, &cut).unwrap().truncated, 1);
/// // Pre-integrated: the same lattice, a table look-up per step.
/// let pre = PreintegratedTable::build(m.transfer_function(), 0.25, 16).unwrap();
/// let pm = PreintegratedMedium::new(*m.volume(), pre.view());
/// let stats = integrate_preintegrated(&pm, &rays, &mut out, &MarchParams::reference(0.25)).unwrap();
/// assert_eq!(stats, MarchStats { rays: 1, samples: 4, ..MarchStats::default() });
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MarchStats {
    /// Rays that overlap the medium with positive length (the others are transparent at no cost).
    pub rays: u64,
    /// Samples taken (looked up and composited).
    pub samples: u64,
    /// Lattice samples jumped over by empty-space skipping.
    pub skipped: u64,
    /// Rays stopped by early termination before their end.
    pub terminated: u64,
    /// Rays cut at [`MarchParams::max_steps`].
    pub truncated: u64,
}

/// One ray's part inside the medium, in local coordinates: `g(s) = ge + gd s` for `s` in
/// `[0, len]` world units, marched in `n` steps.
#[derive(Clone, Copy, Debug, Default)]
struct Span {
    ge: [f32; 3],
    gd: [f32; 3],
    /// `1 / gd`, for the exit distances of skipped regions.
    inv_gd: [f32; 3],
    len: f32,
    n: u32,
    truncated: bool,
}

/// What every ray of a call shares.
struct Ctx {
    bounds: Aabb,
    diag: f32,
    origin: Vec3,
    scale: Vec3,
    dt: f32,
    inv_dt: f32,
    mid: bool,
    /// Keep marching while `A < thr`; `+inf` without termination.
    thr: f32,
    max_steps: u32,
}

impl Ctx {
    fn new<M: Medium>(m: &M, p: &MarchParams) -> Result<Self, VolumeError> {
        Self::with_frame(m.bounds(), m.local_frame(), p)
    }

    /// For the pre-integrated marchers: also checks that the table is for this step.
    fn preintegrated<V: Voxel>(m: &PreintegratedMedium<'_, V>, p: &MarchParams) -> Result<Self, VolumeError> {
        let ctx = Self::with_frame(m.bounds(), m.volume().local_frame(), p)?;
        if m.table().step().to_bits() != p.step.to_bits() {
            return Err(VolumeError::StepMismatch);
        }
        Ok(ctx)
    }

    fn with_frame(bounds: Aabb, (origin, scale): (Vec3, Vec3), p: &MarchParams) -> Result<Self, VolumeError> {
        p.validate()?;
        let diag = if bounds.is_empty() {
            0.0
        } else {
            bounds.extent().length()
        };
        Ok(Self {
            bounds,
            diag,
            origin,
            scale,
            dt: p.step,
            inv_dt: 1.0 / p.step,
            mid: p.sampling == Sampling::Midpoint,
            thr: p.termination.map_or(f32::INFINITY, |eps| 1.0 - eps),
            max_steps: p.max_steps,
        })
    }

    /// Clips `ray` to the medium's box and sets up its lattice; `None` if nothing is left.
    fn span(&self, ray: &Ray) -> Option<Span> {
        if !ray.is_valid() || self.bounds.is_empty() {
            return None;
        }
        // Unit direction without overflow or underflow: divide by the largest component first.
        let d = ray.direction;
        let m = max_l(max_l(abs(d.x), abs(d.y)), abs(d.z));
        let dn = d / m;
        let l = dn.length();
        let u = dn / l;
        let dlen = m * l;
        if !(dlen.is_finite() && dlen > 0.0) {
            return None;
        }
        // Slab test in world distance along u (not widened: the marcher only needs where to start).
        let (o, b) = (ray.origin, &self.bounds);
        let mut near = ray.tmin * dlen;
        let mut far = ray.tmax * dlen;
        for a in (0..3).rev() {
            let inv = 1.0 / u[a];
            let (lo, hi) = if sign_bit(u[a]) {
                (b.max[a], b.min[a])
            } else {
                (b.min[a], b.max[a])
            };
            near = max_l((lo - o[a]) * inv, near);
            far = min_l((hi - o[a]) * inv, far);
        }
        if !(near < far && near.is_finite() && far.is_finite()) {
            return None;
        }
        // March from the entry point, so a far-away origin costs no precision in t; a segment
        // inside a box is never longer than its diagonal (this bounds rounding in far - near).
        let entry = (o + u * near).max(b.min).min(b.max);
        let len = min_l(far - near, self.diag);
        if len.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            return None;
        }
        let ge = ((entry - self.origin) * self.scale).to_array();
        let gd = (u * self.scale).to_array();
        let q = len / self.dt;
        let (n, truncated) = if q <= self.max_steps as f32 {
            (ceil(q) as u32, false)
        } else {
            (self.max_steps, true)
        };
        if n == 0 {
            // len / dt underflowed: nothing to march.
            return None;
        }
        Some(Span {
            ge,
            gd,
            inv_gd: gd.map(|d| 1.0 / d),
            len,
            n,
            truncated,
        })
    }

    /// Local position and length of step `k` (the one formula both widths use).
    #[inline(always)]
    fn position(&self, sp: &Span, k: u32) -> ([f32; 3], f32) {
        let s0 = k as f32 * self.dt;
        let h = max_l(min_l(self.dt, sp.len - s0), 0.0);
        let s = if self.mid { s0 + 0.5 * h } else { s0 };
        (
            [
                sp.ge[0] + sp.gd[0] * s,
                sp.ge[1] + sp.gd[1] * s,
                sp.ge[2] + sp.gd[2] * s,
            ],
            h,
        )
    }

    /// Local position of the end of step `k` (where the next one starts) and the step's length.
    #[inline(always)]
    fn end_position(&self, sp: &Span, k: u32) -> ([f32; 3], f32) {
        let s0 = k as f32 * self.dt;
        let h = max_l(min_l(self.dt, sp.len - s0), 0.0);
        let s = s0 + h;
        (
            [
                sp.ge[0] + sp.gd[0] * s,
                sp.ge[1] + sp.gd[1] * s,
                sp.ge[2] + sp.gd[2] * s,
            ],
            h,
        )
    }

    /// Sample `k`, at local position `g`, lies in the empty region `r`: the next step index to
    /// look at. Jumps to the first lattice sample past `r.exit` if the last sample jumped over
    /// lies in `r.safe` (then all do: positions are monotone in `k`), else just past `k`.
    #[inline]
    fn jump(&self, sp: &Span, k: u32, g: [f32; 3], r: &EmptyRegion) -> u32 {
        let s_exit = exit_distance(sp, r);
        // Sample positions are k dt (endpoint) or k dt + dt / 2 (midpoint, full steps).
        let q = s_exit * self.inv_dt - if self.mid { 0.5 } else { 0.0 };
        let kn = if q < sp.n as f32 { ceil(q) as u32 } else { sp.n };
        let kn = kn.clamp(k + 1, sp.n.max(k + 1));
        if kn > k + 1 {
            let inside = |g: [f32; 3]| r.safe.contains_point(Vec3::from_array(g));
            if !(inside(g) && inside(self.position(sp, kn - 1).0)) {
                return k + 1;
            }
        }
        kn
    }

    /// Pre-integrated marching: the front of step `k`, at local position `front`, lies in the
    /// empty region `r`. Returns the step to resume at, past the steps whose front and back both
    /// lie in `r.safe`: up to the last step that ends before the exit, if the front and that
    /// step's end (computed as the marcher computes it) lie in `r.safe` (then every skipped step
    /// does: positions are monotone along the ray); else `k` (nothing skipped).
    #[inline]
    fn jump_segments(&self, sp: &Span, k: u32, front: [f32; 3], r: &EmptyRegion) -> u32 {
        // Lattice point j (position j dt) lies before the exit for j < q; step j ends at j + 1.
        let q = exit_distance(sp, r) * self.inv_dt;
        let kn = if q < sp.n as f32 {
            (ceil(q) as u32).saturating_sub(1)
        } else {
            sp.n
        };
        if kn <= k {
            return k;
        }
        let inside = |g: [f32; 3]| r.safe.contains_point(Vec3::from_array(g));
        if inside(front) && inside(self.end_position(sp, kn - 1).0) {
            kn
        } else {
            k
        }
    }

    /// Pre-integrated marching: jumps over empty regions from step `k`, whose front (at `front`)
    /// lies in `r`, region after region ([`jump_segments`](Self::jump_segments)), until a front
    /// outside any or a jump that is refused; returns the step to march next (`k` if none was
    /// skipped, `sp.n` if the rest was).
    fn skip_segments<V: Voxel>(
        &self,
        m: &PreintegratedMedium<'_, V>,
        sp: &Span,
        k: u32,
        front: [f32; 3],
        r: &EmptyRegion,
    ) -> u32 {
        let (mut k, mut front, mut r) = (k, front, *r);
        loop {
            let kn = self.jump_segments(sp, k, front, &r);
            if kn <= k || kn >= sp.n {
                return kn.max(k);
            }
            (k, front) = (kn, self.end_position(sp, kn - 1).0);
            match m.empty_region(front) {
                Some(next) => r = next,
                None => return k,
            }
        }
    }

    /// Jumps over empty regions from sample `k` (in region `r`, at `g`) until a sample outside
    /// any, or the end; returns its index. Each jump is checked as in [`jump`](Self::jump).
    fn skip<M: Medium>(&self, m: &M, sp: &Span, k: u32, g: [f32; 3], r: &EmptyRegion) -> u32 {
        let (mut k, mut g, mut r) = (k, g, *r);
        loop {
            let kn = self.jump(sp, k, g, &r);
            if kn >= sp.n {
                return kn;
            }
            let gn = self.position(sp, kn).0;
            match m.empty_region(Vec3::from_array(gn)) {
                Some(next) => (k, g, r) = (kn, gn, next),
                None => return kn,
            }
        }
    }
}

/// Distance along the span from its entry to where it leaves `r.exit` (a guess: the reciprocal
/// direction is used; callers check what they jump to).
#[inline]
fn exit_distance(sp: &Span, r: &EmptyRegion) -> f32 {
    let mut s_exit = f32::INFINITY;
    for a in 0..3 {
        let d = sp.gd[a];
        let bound = if d > 0.0 {
            r.exit.max[a]
        } else if d < 0.0 {
            r.exit.min[a]
        } else {
            continue;
        };
        s_exit = min_l((bound - sp.ge[a]) * sp.inv_gd[a], s_exit);
    }
    s_exit
}

/// One step front to back: `a = 1 - exp(-tau h)`; `C += (1 - A) a c`; `A += (1 - A) a`.
#[inline(always)]
fn composite_scalar(tau: f32, color: [f32; 3], h: f32, col: &mut [f32; 3], acc: &mut f32) {
    let a = one_minus_exp_neg_scalar(tau * h);
    let w = (1.0 - *acc) * a;
    for (c, sc) in col.iter_mut().zip(color) {
        *c += w * sc;
    }
    *acc += w;
}

/// [`composite_scalar`] in the `live` lanes of `v`.
#[inline(always)]
fn composite_x8(live: f32x8, tau: f32x8, color: [f32x8; 3], h: f32x8, v: &mut LaneVecs) {
    let a = one_minus_exp_neg_x8(tau * h);
    let w = (f32x8::splat(1.0) - v.acc) * a;
    for (c, sc) in v.col.iter_mut().zip(color) {
        *c = live.select(*c + w * sc, *c);
    }
    v.acc = live.select(v.acc + w, v.acc);
}

/// `true` once `acc` has reached the termination threshold: the same predicate as the x8
/// lanes' `acc.lt(thr)`, negated (not `acc >= thr` written as such).
#[inline(always)]
fn reached(acc: f32, thr: f32) -> bool {
    acc.partial_cmp(&thr) != Some(core::cmp::Ordering::Less)
}

/// The scalar reference for one ray.
#[inline]
fn march_scalar<M: Medium>(m: &M, ctx: &Ctx, sp: &Span, stats: &mut MarchStats) -> Rgba {
    let mut col = [0.0f32; 3];
    let mut acc = 0.0f32;
    let mut k = 0u32;
    while k < sp.n {
        let (g, h) = ctx.position(sp, k);
        match m.lookup(Vec3::from_array(g)) {
            Lookup::Empty(r) => {
                let kn = ctx.skip(m, sp, k, g, &r);
                stats.skipped += (kn - k) as u64;
                k = kn;
            }
            Lookup::Sample(s) => {
                composite_scalar(s.tau, s.color, h, &mut col, &mut acc);
                stats.samples += 1;
                k += 1;
                if reached(acc, ctx.thr) {
                    stats.terminated += (k < sp.n) as u64;
                    break;
                }
            }
        }
    }
    Rgba {
        r: col[0],
        g: col[1],
        b: col[2],
        a: acc,
    }
}

/// Marches one ray with the scalar reference.
///
/// Errors only for bad parameters ([`MarchParams::validate`]); a ray that is invalid, misses, or
/// has zero length inside the medium gives [`Rgba::ZERO`].
///
/// ```
/// use strahl::{Ray, Vec3};
/// use strahl::volume::{MarchParams, Rgba, TfEntry, TransferFunction, Volume, VolumeMedium, integrate_ray};
/// let data = [1.0f32; 8];
/// let vol = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
/// let table = [TfEntry::new([0.0, 1.0, 0.0], 3.0)];
/// let m = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 1.0).unwrap());
/// let hit = integrate_ray(&m, &Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z), &MarchParams::reference(0.1)).unwrap();
/// assert!((hit.a - (1.0 - (-3.0f32).exp())).abs() < 1e-6);
/// assert_eq!(hit.g, hit.a); // C = c A for constant colour
/// let miss = integrate_ray(&m, &Ray::new(Vec3::new(5.0, 0.5, -1.0), Vec3::Z), &MarchParams::reference(0.1));
/// assert_eq!(miss, Ok(Rgba::ZERO));
/// ```
pub fn integrate_ray<M: Medium>(m: &M, ray: &Ray, params: &MarchParams) -> Result<Rgba, VolumeError> {
    let ctx = Ctx::new(m, params)?;
    let mut stats = MarchStats::default();
    Ok(match ctx.span(ray) {
        Some(sp) => march_scalar(m, &ctx, &sp, &mut stats),
        None => Rgba::ZERO,
    })
}

/// Scalar reference: marches `rays[i]` into `out[i]`, one ray at a time.
///
/// Errors: bad parameters ([`MarchParams::validate`]), or [`VolumeError::LengthMismatch`] if
/// `out` is shorter than `rays` (nothing is written then).
///
/// ```
/// # use strahl::{Ray, Vec3, volume::*};
/// # let data: Vec<u8> = (0..8 * 8 * 8).map(|i| (i * 37 % 251) as u8).collect();
/// # let vol = Volume::new(&data, [8; 3], Vec3::splat(0.25), Vec3::ZERO).unwrap();
/// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.2], 6.0), TfEntry::new([0.2, 0.5, 1.0], 1.0)];
/// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// # let rays: Vec<Ray> = (0..11)
/// #     .map(|i| Ray::new(Vec3::new(0.1 + 0.15 * i as f32, 0.9, -1.0), Vec3::new(0.0, -0.2, 1.0)))
/// #     .collect();
/// let m = VolumeMedium::new(vol, tf); // rays: 11 rays across an 8^3 volume
/// let mut out = vec![Rgba::ZERO; rays.len()];
/// let p = MarchParams::fast(0.05);
/// integrate_scalar(&m, &rays, &mut out, &p).unwrap();
/// assert!(rays.iter().zip(&out).all(|(r, o)| integrate_ray(&m, r, &p).unwrap().bit_eq(o)));
/// let err = integrate_scalar(&m, &rays, &mut out[..3], &p).unwrap_err();
/// assert_eq!(err, VolumeError::LengthMismatch { rays: 11, out: 3 });
/// ```
pub fn integrate_scalar<M: Medium>(
    m: &M,
    rays: &[Ray],
    out: &mut [Rgba],
    params: &MarchParams,
) -> Result<MarchStats, VolumeError> {
    let ctx = Ctx::new(m, params)?;
    if out.len() < rays.len() {
        return Err(VolumeError::LengthMismatch {
            rays: rays.len(),
            out: out.len(),
        });
    }
    let mut stats = MarchStats::default();
    for (ray, o) in rays.iter().zip(out.iter_mut()) {
        *o = match ctx.span(ray) {
            Some(sp) => {
                stats.rays += 1;
                stats.truncated += sp.truncated as u64;
                march_scalar(m, &ctx, &sp, &mut stats)
            }
            None => Rgba::ZERO,
        };
    }
    Ok(stats)
}

/// How many steps ahead [`integrate_x8`] prefetches voxels ([`Medium::prefetch_x8`]).
// PERF: dense Marschner-Lobb 128^3, x8, best of 15 x 3 runs alternating (AMD EPYC, AVX-512):
// f32 (8 MB) 18.7 -> 16.1 ms, u16 15.1 -> 13.6 ms, u8 (2 MB) 12.7 -> 12.4 ms; prefetching every
// step instead cost u8 5% (13.4 ms); 4, 8 and 16 steps ahead measured alike.
const PREFETCH_STEPS: f32 = 6.0;

#[inline(always)]
fn set_lane(v: &mut f32x8, l: usize, x: f32) {
    // PERF: a blend, not a trip through memory (a store of the vector, one lane, a reload).
    let lane = f32x8::new([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]).eq(f32x8::splat(l as f32));
    *v = lane.select(f32x8::splat(x), *v);
}

/// What the 8-wide marcher updates every step, one ray per lane, in SoA form.
#[derive(Clone, Copy)]
struct LaneVecs {
    ge: [f32x8; 3],
    gd: [f32x8; 3],
    len: f32x8,
    n: f32x8,
    k: f32x8,
    col: [f32x8; 3],
    acc: f32x8,
}

impl LaneVecs {
    /// Each lane's local position at distance `s` along its ray.
    #[inline(always)]
    fn at(&self, s: f32x8) -> [f32x8; 3] {
        [
            self.ge[0] + self.gd[0] * s,
            self.ge[1] + self.gd[1] * s,
            self.ge[2] + self.gd[2] * s,
        ]
    }
}

/// Lane state of the 8-wide marcher.
struct Lanes {
    ray: [usize; 8],
    span: [Span; 8],
    /// PERF: the marching loop works on a copy of these in registers and writes it back only
    /// around the (rare) calls that change a lane, so no step stores to memory with a mask.
    v: LaneVecs,
}

impl Lanes {
    /// [`finish_and_refill`](Self::finish_and_refill) for every lane set in `done`, the marching
    /// loop's register copy `v` written back around it; `started(span, lane)` after each refill.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn refill_done(
        &mut self,
        v: &mut LaneVecs,
        done: u32,
        ctx: &Ctx,
        rays: &[Ray],
        out: &mut [Rgba],
        next: &mut usize,
        stats: &mut MarchStats,
        mut started: impl FnMut(&Span, usize),
    ) {
        self.v = *v;
        let mut bits = done;
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            self.finish_and_refill(l, ctx, rays, out, next, stats);
            started(&self.span[l], l);
        }
        *v = self.v;
    }

    /// Writes lane `l`'s result and loads the next ray that overlaps the medium into it (writing
    /// [`Rgba::ZERO`] for the ones that do not); leaves the lane idle (`n = 0`) when none is left.
    fn finish_and_refill(
        &mut self,
        l: usize,
        ctx: &Ctx,
        rays: &[Ray],
        out: &mut [Rgba],
        next: &mut usize,
        stats: &mut MarchStats,
    ) {
        let v = &mut self.v;
        if self.ray[l] != usize::MAX {
            out[self.ray[l]] = Rgba {
                r: v.col[0].lane(l),
                g: v.col[1].lane(l),
                b: v.col[2].lane(l),
                a: v.acc.lane(l),
            };
            stats.terminated += (v.k.lane(l) < v.n.lane(l)) as u64;
            self.ray[l] = usize::MAX;
        }
        let mut sp = Span::default();
        while *next < rays.len() {
            let i = *next;
            *next += 1;
            if let Some(s) = ctx.span(&rays[i]) {
                sp = s;
                self.ray[l] = i;
                stats.rays += 1;
                stats.truncated += s.truncated as u64;
                break;
            }
            out[i] = Rgba::ZERO;
        }
        self.span[l] = sp;
        let v = &mut self.v;
        for a in 0..3 {
            set_lane(&mut v.ge[a], l, sp.ge[a]);
            set_lane(&mut v.gd[a], l, sp.gd[a]);
            set_lane(&mut v.col[a], l, 0.0);
        }
        set_lane(&mut v.len, l, sp.len);
        set_lane(&mut v.n, l, sp.n as f32);
        set_lane(&mut v.k, l, 0.0);
        set_lane(&mut v.acc, l, 0.0);
    }
}

/// Marches `rays[i]` into `out[i]`, eight rays at a time in the lanes of [`f32x8`]. A lane whose
/// ray ends (or terminates early) takes the next ray at once, so lanes stay busy when ray lengths
/// differ.
///
/// Every result equals [`integrate_scalar`]'s bit for bit (the same operations in the same order
/// per ray), and so do the counters. Errors as [`integrate_scalar`].
///
/// ```
/// use strahl::{Ray, Vec3};
/// use strahl::volume::*;
/// let data: Vec<u8> = (0..16 * 16 * 16).map(|i| (i * 37 % 251) as u8).collect();
/// let vol = Volume::new(&data, [16; 3], Vec3::splat(0.25), Vec3::ZERO).unwrap();
/// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.2], 6.0), TfEntry::new([0.2, 0.5, 1.0], 1.0)];
/// let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// let m = VolumeMedium::new(vol, tf);
/// let rays: Vec<Ray> = (0..20)
///     .map(|i| Ray::new(Vec3::new(0.1 + 0.17 * i as f32, 1.9, -1.0), Vec3::new(0.0, -0.3, 1.0)))
///     .collect();
/// let (mut a, mut b) = (vec![Rgba::ZERO; 20], vec![Rgba::ZERO; 20]);
/// let p = MarchParams::fast(0.1);
/// let sa = integrate_scalar(&m, &rays, &mut a, &p).unwrap();
/// let sb = integrate_x8(&m, &rays, &mut b, &p).unwrap();
/// assert!(a.iter().zip(&b).all(|(x, y)| x.bit_eq(y)));
/// assert_eq!(sa, sb);
/// ```
pub fn integrate_x8<M: Medium>(
    m: &M,
    rays: &[Ray],
    out: &mut [Rgba],
    params: &MarchParams,
) -> Result<MarchStats, VolumeError> {
    let ctx = Ctx::new(m, params)?;
    if out.len() < rays.len() {
        return Err(VolumeError::LengthMismatch {
            rays: rays.len(),
            out: out.len(),
        });
    }
    let mut stats = MarchStats::default();
    let z = f32x8::splat(0.0);
    let mut ln = Lanes {
        ray: [usize::MAX; 8],
        span: [Span::default(); 8],
        v: LaneVecs {
            ge: [z; 3],
            gd: [z; 3],
            len: z,
            n: z,
            k: z,
            col: [z; 3],
            acc: z,
        },
    };
    let mut next = 0usize;
    for l in 0..8 {
        ln.finish_and_refill(l, &ctx, rays, out, &mut next, &mut stats);
    }
    let dt = f32x8::splat(ctx.dt);
    let thr = f32x8::splat(ctx.thr);
    let (zero, one, half) = (f32x8::splat(0.0), f32x8::splat(1.0), f32x8::splat(0.5));
    let mut regions = [EmptyRegion::default(); 8];
    let ahead = f32x8::splat(ctx.dt * PREFETCH_STEPS);
    let mut v = ln.v;
    // Each round's positions and step lengths, from `v.k` (as `Ctx::position` per lane); every
    // second round also asks for the voxels PREFETCH_STEPS ahead (their lines serve two steps of
    // half a voxel; see PREFETCH_STEPS for the figures).
    let place = |v: &LaneVecs, prefetch: bool| {
        let s0 = v.k * dt;
        let h = dt.min_l(v.len - s0).max_l(zero);
        let s = if ctx.mid { s0 + half * h } else { s0 };
        let g = v.at(s);
        if prefetch {
            m.prefetch_x8(&v.at(s + ahead));
        }
        (g, h)
    };
    let mut prefetch_now = true;
    // Lanes with a ray, samples left and opacity below the threshold.
    let mut active = (v.k.lt(v.n) & v.acc.lt(thr)).bitmask();
    let (mut g, mut h) = place(&v, prefetch_now);
    // Lanes in empty regions (`jumping`) make one jump each per round (the scalar marcher's
    // region-after-region loop, one region per round: the next round looks at where the jump
    // landed, as the scalar loop asks `empty_region` there); the other lanes sample.
    // PERF: before, a round with any lane in an empty region sampled nothing and ran that lane's
    // whole loop of jumps, one serial chain of dependent loads and conversions after another,
    // while the other seven lanes waited; on the sparse torus bench the jumps were about half of
    // the time. Now they run beside the sampling of the other lanes.
    let (mut smp, mut jumping) = m.lookup_x8_partial(&g, active, &mut regions);
    while active != 0 {
        let jumping_now = jumping & active;
        let sampling = active & !jumping_now;
        // Every lane with a ray is live here (finished ones were refilled at once), so k steps
        // without waiting for this round's opacity (idle lanes, n = 0, step too, harmlessly: k
        // < n stays false); the jumping lanes then move to their jump's end.
        let k0 = v.k;
        v.k += one;
        let mut bits = jumping_now;
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let k = k0.lane(l) as u32;
            let gl = [g[0].lane(l), g[1].lane(l), g[2].lane(l)];
            let kn = ctx.jump(&ln.span[l], k, gl, &regions[l]);
            stats.skipped += (kn - k) as u64;
            set_lane(&mut v.k, l, kn as f32);
        }
        // The next round's lookups, made before this round's compositing: every lane with steps
        // left, whatever its opacity becomes (a lane that reaches the threshold now is refilled
        // below and, if it takes a new ray, looked up again).
        // PERF: a round is one long chain of dependent latencies (position, cell, gathers,
        // interpolation, table rows, exp, compositing) and wider than the processor's window
        // allows to overlap; issuing the next round's gathers before this round's exp and
        // compositing lets them run beside it. Dense Marschner-Lobb 128^3, best of 5 x 3 rounds
        // taking turns (Intel Xeon, 2026-12-04): f32 16.4 -> 15.1 ms, u16 15.0 -> 14.1 ms,
        // u8 14.7 -> 13.8 ms; the sparse torus with a grid alike (3.86 -> 3.90 ms). Only the
        // lanes that take new rays are looked up again, in one call (redoing all eight: torus
        // 5.5 against 4.8 ms, one criterion run each).
        prefetch_now = !prefetch_now;
        let (g1, h1) = place(&v, prefetch_now);
        let (smp1, jumping1) = m.lookup_x8_partial(&g1, v.k.lt(v.n).bitmask(), &mut regions);
        if sampling != 0 {
            let lanes = f32x8::from_bitmask(sampling);
            composite_x8(lanes, smp.tau, smp.color, h, &mut v);
            stats.samples += sampling.count_ones() as u64;
        }
        let live = (v.k.lt(v.n) & v.acc.lt(thr)).bitmask();
        let done = active & !live;
        (g, h, smp, jumping) = (g1, h1, smp1, jumping1);
        active = live;
        if done != 0 {
            // Lanes that took a new ray (`fresh`) are looked up again; the others keep the
            // lookups made above.
            let mut fresh = 0u32;
            ln.refill_done(&mut v, done, &ctx, rays, out, &mut next, &mut stats, |sp, l| {
                fresh |= u32::from(sp.n > 0) << l;
            });
            active = (v.k.lt(v.n) & v.acc.lt(thr)).bitmask();
            jumping &= !fresh;
            if fresh != 0 {
                (g, h) = place(&v, false);
                let mut r = [EmptyRegion::default(); 8];
                let (s, j) = m.lookup_x8_partial(&g, fresh, &mut r);
                let sel = f32x8::from_bitmask(fresh);
                smp.tau = sel.select(s.tau, smp.tau);
                for (c, sc) in smp.color.iter_mut().zip(s.color) {
                    *c = sel.select(sc, *c);
                }
                let mut bits = j & fresh;
                jumping |= bits;
                while bits != 0 {
                    let l = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    regions[l] = r[l];
                }
            }
        }
    }
    Ok(stats)
}

/// Marches `rays[i]` into `out[i]` with the fastest kernel, [`integrate_x8`].
///
/// ```
/// # use strahl::{Ray, Vec3, volume::*};
/// # let data: Vec<u8> = (0..8 * 8 * 8).map(|i| (i * 37 % 251) as u8).collect();
/// # let vol = Volume::new(&data, [8; 3], Vec3::splat(0.25), Vec3::ZERO).unwrap();
/// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.2], 6.0), TfEntry::new([0.2, 0.5, 1.0], 1.0)];
/// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// # let rays: Vec<Ray> = (0..11)
/// #     .map(|i| Ray::new(Vec3::new(0.1 + 0.15 * i as f32, 0.9, -1.0), Vec3::new(0.0, -0.2, 1.0)))
/// #     .collect();
/// let m = VolumeMedium::new(vol, tf); // rays: 11 rays across an 8^3 volume
/// let (mut a, mut b) = (vec![Rgba::ZERO; 11], vec![Rgba::ZERO; 11]);
/// let p = MarchParams::quality(0.05);
/// let sa = integrate(&m, &rays, &mut a, &p).unwrap();
/// assert_eq!(sa, integrate_scalar(&m, &rays, &mut b, &p).unwrap());
/// assert!(a.iter().zip(&b).all(|(x, y)| x.bit_eq(y))); // the scalar reference's bits
/// ```
#[inline]
pub fn integrate<M: Medium>(
    m: &M,
    rays: &[Ray],
    out: &mut [Rgba],
    params: &MarchParams,
) -> Result<MarchStats, VolumeError> {
    integrate_x8(m, rays, out, params)
}

/// The pre-integrated scalar reference for one ray: the scalar at each step's ends, the step's
/// contribution from the table.
#[inline]
fn march_preintegrated_scalar<V: Voxel>(
    m: &PreintegratedMedium<'_, V>,
    ctx: &Ctx,
    sp: &Span,
    stats: &mut MarchStats,
) -> Rgba {
    let (mut col, mut acc) = ([0.0f32; 3], 0.0f32);
    let mut front_pos = sp.ge;
    let mut front = m.scalar(front_pos);
    let mut k = 0u32;
    while k < sp.n {
        if let Some(r) = m.empty_region(front_pos) {
            let kn = ctx.skip_segments(m, sp, k, front_pos, &r);
            if kn > k {
                stats.skipped += (kn - k) as u64;
                k = kn;
                if k >= sp.n {
                    break;
                }
                // The front the marcher without a grid carries into step k.
                front_pos = ctx.end_position(sp, k - 1).0;
                front = m.scalar(front_pos);
            }
        }
        let (g, h) = ctx.end_position(sp, k);
        let back = m.scalar(g);
        let (tau, color) = m.table().lookup_scalar(front, back);
        (front, front_pos) = (back, g);
        composite_scalar(tau, color, h, &mut col, &mut acc);
        stats.samples += 1;
        k += 1;
        if reached(acc, ctx.thr) {
            stats.terminated += (k < sp.n) as u64;
            break;
        }
    }
    Rgba {
        r: col[0],
        g: col[1],
        b: col[2],
        a: acc,
    }
}

/// Scalar reference of pre-integrated marching ([`preint`](super::preint)): `rays[i]` into
/// `out[i]`, one ray at a time. Each step of length `h` from `t_k = k dt` samples the scalar at
/// its end (its start is the previous step's end; the first step samples the entry point too) and
/// composites the table's entry for the pair as the Riemann marcher composites a sample. The
/// lattice, the clipping, termination, `max_steps` and the counters are
/// [`integrate_scalar`]'s (`samples` counts the steps marched, `skipped` those jumped over where
/// the medium has a grid, [`PreintegratedMedium::with_grid`]); [`MarchParams::sampling`] is not
/// used.
///
/// Errors: as [`integrate_scalar`], and [`VolumeError::StepMismatch`] unless `params.step` is
/// the table's step.
///
/// ```
/// # use strahl::{Ray, Vec3, volume::*};
/// # let data = [0u8, 0, 0, 0, 255, 255, 255, 255]; // 0 at z = 0, 255 at z = 1
/// # let vol = Volume::new(&data, [2; 3], Vec3::ONE, Vec3::ZERO).unwrap();
/// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 2.0)];
/// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// let pre = PreintegratedTable::build(&tf, 0.25, 32).unwrap();
/// let m = PreintegratedMedium::new(vol, pre.view()); // the unit cube, scalar rising along z
/// let (rays, mut out) = ([Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z)], [Rgba::ZERO]);
/// integrate_preintegrated_scalar(&m, &rays, &mut out, &MarchParams::reference(0.25)).unwrap();
/// // tau rises from 0 to 2 along the ray: optical depth 1, exact even in four steps.
/// assert!((out[0].a - (1.0 - (-1.0f32).exp())).abs() < 1e-5);
/// let err = integrate_preintegrated_scalar(&m, &rays, &mut out, &MarchParams::reference(0.1)).unwrap_err();
/// assert!(matches!(err, VolumeError::StepMismatch { .. })); // the table is for one step only
/// ```
pub fn integrate_preintegrated_scalar<V: Voxel>(
    m: &PreintegratedMedium<'_, V>,
    rays: &[Ray],
    out: &mut [Rgba],
    params: &MarchParams,
) -> Result<MarchStats, VolumeError> {
    let ctx = Ctx::preintegrated(m, params)?;
    if out.len() < rays.len() {
        return Err(VolumeError::LengthMismatch {
            rays: rays.len(),
            out: out.len(),
        });
    }
    let mut stats = MarchStats::default();
    for (ray, o) in rays.iter().zip(out.iter_mut()) {
        *o = match ctx.span(ray) {
            Some(sp) => {
                stats.rays += 1;
                stats.truncated += sp.truncated as u64;
                march_preintegrated_scalar(m, &ctx, &sp, &mut stats)
            }
            None => Rgba::ZERO,
        };
    }
    Ok(stats)
}

/// Pre-integrated marching eight rays at a time, as [`integrate_x8`] marches: every result equals
/// [`integrate_preintegrated_scalar`]'s bit for bit, and so do the counters. Errors as
/// [`integrate_preintegrated_scalar`].
///
/// ```
/// use strahl::{Ray, Vec3};
/// use strahl::volume::*;
/// let data: Vec<u8> = (0..16 * 16 * 16).map(|i| (i * 37 % 251) as u8).collect();
/// let vol = Volume::new(&data, [16; 3], Vec3::splat(0.25), Vec3::ZERO).unwrap();
/// let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.2], 6.0), TfEntry::new([0.2, 0.5, 1.0], 1.0)];
/// let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// let pre = PreintegratedTable::build(&tf, 0.1, 32).unwrap();
/// let m = PreintegratedMedium::new(vol, pre.view());
/// let rays: Vec<Ray> = (0..20)
///     .map(|i| Ray::new(Vec3::new(0.1 + 0.17 * i as f32, 1.9, -1.0), Vec3::new(0.0, -0.3, 1.0)))
///     .collect();
/// let (mut a, mut b) = (vec![Rgba::ZERO; 20], vec![Rgba::ZERO; 20]);
/// let p = MarchParams::fast(0.1);
/// let sa = integrate_preintegrated_scalar(&m, &rays, &mut a, &p).unwrap();
/// let sb = integrate_preintegrated_x8(&m, &rays, &mut b, &p).unwrap();
/// assert!(a.iter().zip(&b).all(|(x, y)| x.bit_eq(y)));
/// assert_eq!(sa, sb);
/// // The table is for one step only.
/// let e = integrate_preintegrated_x8(&m, &rays, &mut b, &MarchParams::fast(0.2)).unwrap_err();
/// assert!(matches!(e, VolumeError::StepMismatch { .. }));
/// ```
pub fn integrate_preintegrated_x8<V: Voxel>(
    m: &PreintegratedMedium<'_, V>,
    rays: &[Ray],
    out: &mut [Rgba],
    params: &MarchParams,
) -> Result<MarchStats, VolumeError> {
    let ctx = Ctx::preintegrated(m, params)?;
    if out.len() < rays.len() {
        return Err(VolumeError::LengthMismatch {
            rays: rays.len(),
            out: out.len(),
        });
    }
    let mut stats = MarchStats::default();
    let z = f32x8::splat(0.0);
    let mut ln = Lanes {
        ray: [usize::MAX; 8],
        span: [Span::default(); 8],
        v: LaneVecs {
            ge: [z; 3],
            gd: [z; 3],
            len: z,
            n: z,
            k: z,
            col: [z; 3],
            acc: z,
        },
    };
    // The scalar at each lane's current step start, and where it was sampled.
    let (mut front, mut fpos) = (z, [z; 3]);
    let mut next = 0usize;
    for l in 0..8 {
        ln.finish_and_refill(l, &ctx, rays, out, &mut next, &mut stats);
        start_lane(m, &ln.span[l], l, &mut front, &mut fpos);
    }
    let dt = f32x8::splat(ctx.dt);
    let thr = f32x8::splat(ctx.thr);
    let (zero, one) = (f32x8::splat(0.0), f32x8::splat(1.0));
    let ahead = f32x8::splat(ctx.dt * PREFETCH_STEPS);
    let mut prefetch_now = false;
    let mut v = ln.v;
    // Each round's step ends (as `Ctx::end_position` per lane), step lengths and scalars there.
    let place = |v: &LaneVecs, prefetch: bool| {
        let s0 = v.k * dt;
        let h = dt.min_l(v.len - s0).max_l(zero);
        let s = s0 + h;
        let g = v.at(s);
        if prefetch {
            m.volume().prefetch_x8(v.at(s + ahead));
        }
        (g, h, m.volume().sample_local_x8(g))
    };
    // This round's ends and scalars, when still those of the lanes' current steps.
    let mut ready = None;
    loop {
        let mut live = v.k.lt(v.n) & v.acc.lt(thr);
        let mut active = live.bitmask();
        if active == 0 {
            break;
        }
        if m.skips()
            && skip_lanes(
                m, &ctx, active, &mut ln, &mut v, &mut front, &mut fpos, rays, out, &mut next, &mut stats,
            )
        {
            // Lanes jumped (and may have taken new rays): march each from where it landed.
            ready = None;
            live = v.k.lt(v.n) & v.acc.lt(thr);
            active = live.bitmask();
            if active == 0 {
                break;
            }
        }
        let (g, h, back) = match ready {
            Some(r) => r,
            None => {
                prefetch_now = !prefetch_now;
                place(&v, prefetch_now)
            }
        };
        v.k += one;
        // PERF: as in integrate_x8, the next round's samples before this round's table lookup
        // and compositing. Dense Marschner-Lobb 128^3, best of 5 x 4 rounds taking turns (Intel
        // Xeon, 2026-12-04): u8 20.4 -> 17.2 ms, u16 20.2 -> 17.4 ms, f32 22.1 -> 19.6 ms; the
        // sparse torus with a grid alike (7.99 -> 7.96 ms), where jumps often void the early
        // samples.
        prefetch_now = !prefetch_now;
        ready = Some(place(&v, prefetch_now));
        let (tau, color) = m.table().lookup_x8(front, back);
        (front, fpos) = (back, g);
        composite_x8(live, tau, color, h, &mut v);
        stats.samples += active.count_ones() as u64;
        let done = active & !(v.k.lt(v.n) & v.acc.lt(thr)).bitmask();
        if done != 0 {
            ready = None;
            ln.refill_done(&mut v, done, &ctx, rays, out, &mut next, &mut stats, |sp, l| {
                start_lane(m, sp, l, &mut front, &mut fpos)
            });
        }
    }
    Ok(stats)
}

/// Lane `l` of the pre-integrated x8 marcher starts its span `sp`: the front sample at the entry.
#[inline]
fn start_lane<V: Voxel>(m: &PreintegratedMedium<'_, V>, sp: &Span, l: usize, front: &mut f32x8, fpos: &mut [f32x8; 3]) {
    set_lane(front, l, m.scalar(sp.ge));
    for (p, x) in fpos.iter_mut().zip(sp.ge) {
        set_lane(p, l, x);
    }
}

/// Pre-integrated x8 marching with a grid: every `active` lane whose front lies in an empty region
/// jumps as the scalar marcher does ([`Ctx::skip_segments`]), then takes the front the marcher
/// without a grid would carry, or finishes and takes the next ray. Returns `true` if any lane
/// moved.
#[allow(clippy::too_many_arguments)]
fn skip_lanes<V: Voxel>(
    m: &PreintegratedMedium<'_, V>,
    ctx: &Ctx,
    active: u32,
    ln: &mut Lanes,
    v: &mut LaneVecs,
    front: &mut f32x8,
    fpos: &mut [f32x8; 3],
    rays: &[Ray],
    out: &mut [Rgba],
    next: &mut usize,
    stats: &mut MarchStats,
) -> bool {
    let mut regions = [EmptyRegion::default(); 8];
    let mut bits = m.empty_regions_x8(*fpos, active, &mut regions);
    if bits == 0 {
        return false;
    }
    let mut moved = false;
    while bits != 0 {
        let l = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        let mut r = regions[l];
        loop {
            let fp = [fpos[0].lane(l), fpos[1].lane(l), fpos[2].lane(l)];
            let (k, sp) = (v.k.lane(l) as u32, ln.span[l]);
            let kn = ctx.skip_segments(m, &sp, k, fp, &r);
            if kn <= k {
                break;
            }
            moved = true;
            stats.skipped += (kn - k) as u64;
            set_lane(&mut v.k, l, kn as f32);
            if kn < sp.n {
                let g = ctx.end_position(&sp, kn - 1).0;
                set_lane(front, l, m.scalar(g));
                for (p, x) in fpos.iter_mut().zip(g) {
                    set_lane(p, l, x);
                }
                break;
            }
            // The ray is done: the lane takes the next one, whose start may be empty too (the
            // scalar marcher skips from a ray's first step; so must this, for the same counters).
            ln.v = *v;
            ln.finish_and_refill(l, ctx, rays, out, next, stats);
            *v = ln.v;
            start_lane(m, &ln.span[l], l, front, fpos);
            if ln.span[l].n == 0 {
                break;
            }
            match m.empty_region(ln.span[l].ge) {
                Some(next_r) => r = next_r,
                None => break,
            }
        }
    }
    moved
}

/// Pre-integrated marching with the fastest kernel, [`integrate_preintegrated_x8`].
///
/// ```
/// # use strahl::{Ray, Vec3, volume::*};
/// # let data: Vec<u8> = (0..8 * 8 * 8).map(|i| (i * 37 % 251) as u8).collect();
/// # let vol = Volume::new(&data, [8; 3], Vec3::splat(0.25), Vec3::ZERO).unwrap();
/// # let table = [TfEntry::TRANSPARENT, TfEntry::new([1.0, 0.5, 0.2], 6.0), TfEntry::new([0.2, 0.5, 1.0], 1.0)];
/// # let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
/// # let rays: Vec<Ray> = (0..11)
/// #     .map(|i| Ray::new(Vec3::new(0.1 + 0.15 * i as f32, 0.9, -1.0), Vec3::new(0.0, -0.2, 1.0)))
/// #     .collect();
/// let pre = PreintegratedTable::build(&tf, 0.05, 32).unwrap();
/// let m = PreintegratedMedium::new(vol, pre.view()); // rays: 11 rays across an 8^3 volume
/// let (mut a, mut b) = (vec![Rgba::ZERO; 11], vec![Rgba::ZERO; 11]);
/// let p = MarchParams::fast(0.05);
/// let sa = integrate_preintegrated(&m, &rays, &mut a, &p).unwrap();
/// assert_eq!(sa, integrate_preintegrated_scalar(&m, &rays, &mut b, &p).unwrap());
/// assert!(a.iter().zip(&b).all(|(x, y)| x.bit_eq(y))); // the scalar reference's bits
/// ```
#[inline]
pub fn integrate_preintegrated<V: Voxel>(
    m: &PreintegratedMedium<'_, V>,
    rays: &[Ray],
    out: &mut [Rgba],
    params: &MarchParams,
) -> Result<MarchStats, VolumeError> {
    integrate_preintegrated_x8(m, rays, out, params)
}
