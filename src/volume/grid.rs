//! Structured volumes: voxels on a regular grid, borrowed zero-copy, and trilinear sampling.

use super::VolumeError;
use crate::geometry::Aabb;
use crate::math::{Lane, f32x8, i32x8, max_l, min_l};
use bytemuck::Pod;
use glam::Vec3;

/// A voxel type: plain old data that converts to `f32` exactly (`u8`, `u16`) or is `f32`.
///
/// Voxels are read in the machine's byte order (they are cast, not parsed).
///
/// ```
/// use strahl::{Vec3, volume::{Volume, Voxel}};
/// fn mean<V: Voxel>(v: &Volume<V>) -> f32 {
///     v.data().iter().map(|&x| x.to_f32()).sum::<f32>() / v.data().len() as f32
/// }
/// let bytes = [0u8, 10, 20, 30];
/// let words = [0u16, 1000, 2000, 3000];
/// assert_eq!(mean(&Volume::new(&bytes, [4, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap()), 15.0);
/// assert_eq!(mean(&Volume::new(&words, [2, 2, 1], Vec3::ONE, Vec3::ZERO).unwrap()), 1500.0);
/// ```
pub trait Voxel: Pod + Send + Sync + 'static {
    /// The value as `f32`.
    ///
    /// ```
    /// use strahl::volume::Voxel;
    /// assert_eq!(200u8.to_f32(), 200.0);
    /// assert_eq!(65535u16.to_f32(), 65535.0); // exact: u16 fits the f32 mantissa
    /// assert_eq!((-0.5f32).to_f32().to_bits(), (-0.5f32).to_bits());
    /// ```
    fn to_f32(self) -> f32;

    /// The eight corners of eight cells whose x neighbour is the next voxel, converted with
    /// [`to_f32`](Self::to_f32): for lane `l` with `b = base[l]`, corner `c` (bit 0: `+1`, bit 1:
    /// `+oy`, bit 2: `+oz`) is `data[b + (c & 1) + (c >> 1 & 1) oy + (c >> 2) oz]`. An index past
    /// the end reads as 0 or as some voxel of `data` (the volume never asks for one).
    ///
    /// The default loads one voxel at a time; `u8` and `u16` load each x-adjacent pair as one
    /// wider integer and split the pairs in vector registers; with AVX2, `u8`, `u16` and `f32`
    /// use gathers (`f32`: of x pairs as 64-bit words with AVX-512; on AMD processors without
    /// AVX-512 scalar loads, which were faster there). Each corner is an exact conversion,
    /// so every implementation gives the same bits.
    #[doc(hidden)]
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // lane l of eight arrays
    fn corners_x8(data: &[Self], base: i32x8, oy: usize, oz: usize) -> [f32x8; 8] {
        let base = base.to_array();
        let mut v = [[0.0f32; 8]; 8];
        let at = |i: usize| data.get(i).map_or(0.0, |x| x.to_f32());
        for l in 0..8 {
            let b = base[l] as usize;
            for (c, vc) in v.iter_mut().enumerate() {
                vc[l] = at(b + (c & 1) + (c >> 1 & 1) * oy + (c >> 2) * oz);
            }
        }
        v.map(f32x8::new)
    }
}

/// `[f(0), ..., f(7)]` as a vector, spelled out so that the lanes are built in registers.
#[inline(always)]
fn lanes(f: impl Fn(usize) -> i32) -> i32x8 {
    i32x8::new([f(0), f(1), f(2), f(3), f(4), f(5), f(6), f(7)])
}

impl Voxel for u8 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self as f32
    }

    #[inline(always)]
    fn corners_x8(data: &[Self], base: i32x8, oy: usize, oz: usize) -> [f32x8; 8] {
        #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
        if oz >= 2 {
            return gather::corners_u8(data, base, oy as i32, oz as i32);
        }
        if data.len() < 2 {
            return [f32x8::splat(0.0); 8]; // unreachable: a cell with an x neighbour has two voxels
        }
        // NOTE: the clamp never changes an index the volume asks for; it lets the compiler drop
        // the bounds checks (i <= len - 2 makes both reads in bounds).
        let last = data.len() - 2;
        let pair = |i: usize| {
            let i = i.min(last);
            u16::from_le_bytes([data[i], data[i + 1]]) as u32
        };
        // PERF: each x pair loaded as one u16, split into its bytes 8-wide.
        let base = base.to_array();
        let m = i32x8::splat(0xff);
        let mut v = [f32x8::splat(0.0); 8];
        for (c, o) in [0, oy, oz, oz + oy].into_iter().enumerate() {
            let w = lanes(|l| pair(base[l] as usize + o) as i32);
            v[2 * c] = (w & m).round_float();
            v[2 * c + 1] = (w >> 8u32).round_float();
        }
        v
    }
}

impl Voxel for u16 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self as f32
    }

    #[inline(always)]
    fn corners_x8(data: &[Self], base: i32x8, oy: usize, oz: usize) -> [f32x8; 8] {
        #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
        return gather::corners_u16(data, base, oy as i32, oz as i32);
        #[allow(unreachable_code)]
        if data.len() < 2 {
            return [f32x8::splat(0.0); 8]; // unreachable, as for u8
        }
        let last = data.len() - 2;
        let pair = |i: usize| {
            let i = i.min(last);
            data[i] as u32 | (data[i + 1] as u32) << 16
        };
        // PERF: each x pair loaded as one u32, split into its halves 8-wide.
        let base = base.to_array();
        let m = i32x8::splat(0xffff);
        let mut v = [f32x8::splat(0.0); 8];
        for (c, o) in [0, oy, oz, oz + oy].into_iter().enumerate() {
            let w = lanes(|l| pair(base[l] as usize + o) as i32);
            v[2 * c] = (w & m).round_float();
            v[2 * c + 1] = ((w >> 16u32) & m).round_float();
        }
        v
    }
}

/// AVX2 gathers: of x-adjacent voxel pairs (`u8`, `u16`), one `vpgatherdd` per corner pair row,
/// or of single `f32` voxels, one per corner; eight lanes at once instead of scalar loads and
/// inserts.
#[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
mod gather {
    use crate::math::{f32x8, i32x8};
    use core::arch::x86_64::{__m256i, _mm256_i32gather_epi32};

    /// The 32-bit words at `ptr + SCALE * idx[l]`, after clamping every `idx[l]` to `0..=hi`.
    ///
    /// # Safety
    /// `ptr + SCALE * i .. ptr + SCALE * i + 4` must lie in one allocation for every `i` in
    /// `0..=hi`.
    #[inline(always)]
    unsafe fn gather<const SCALE: i32>(ptr: *const u8, idx: i32x8, hi: i32) -> i32x8 {
        let idx: __m256i = bytemuck::cast(idx.max(i32x8::splat(0)).min(i32x8::splat(hi)));
        // SAFETY: every index lies in 0..=hi after the clamp, and the caller vouches for those
        // reads; the gather has no alignment requirement.
        bytemuck::cast(unsafe { _mm256_i32gather_epi32::<SCALE>(ptr.cast(), idx) })
    }

    /// [`Voxel::corners_x8`](super::Voxel::corners_x8) for `u8` with `oz >= 2`.
    ///
    /// A 4-byte gather at the pair start reads two bytes past it, which could run past the end of
    /// the volume; so rows `b` and `b + oy` are read from the pair start (their pairs end at least
    /// `oz >= 2` bytes before the last voxel) and rows `b + oz` and `b + oz + oy` from two bytes
    /// before it (at least `oz - 2 >= 0`), their pair in the high half.
    #[inline(always)]
    pub(super) fn corners_u8(data: &[u8], base: i32x8, oy: i32, oz: i32) -> [f32x8; 8] {
        let n = data.len();
        if n < 4 || n > i32::MAX as usize {
            return [f32x8::splat(0.0); 8]; // unreachable: oz >= 2 and x pairs make 4 voxels
        }
        let hi = n as i32 - 4;
        let p = data.as_ptr();
        // SAFETY: byte offsets 0..=n - 4 leave 4 bytes in `data`.
        let row = |o: i32| unsafe { gather::<1>(p, base + i32x8::splat(o), hi) };
        let (r0, r1, r2, r3) = (row(0), row(oy), row(oz - 2), row(oz + oy - 2));
        let m = i32x8::splat(0xff);
        let byte = |w: i32x8, s: u32| ((w >> s) & m).round_float();
        [
            byte(r0, 0),
            byte(r0, 8),
            byte(r1, 0),
            byte(r1, 8),
            byte(r2, 16),
            byte(r2, 24),
            byte(r3, 16),
            byte(r3, 24),
        ]
    }

    /// [`Voxel::corners_x8`](super::Voxel::corners_x8) for `f32`: one gather per corner (the
    /// bits of each voxel, unchanged).
    // PERF: on an Intel Xeon (AVX-512 machine, AVX2 gathers) the x8 marcher over a dense `f32`
    // volume ran 2.3x its scalar reference with 64 scalar loads per step and 3.4x with the
    // gathers; an earlier measurement on an AMD EPYC (Zen 3, slow gathers) found no difference,
    // and on the first Zen generation they were slower ([`f32_corners`]). The choice on every
    // processor but AMD's.
    #[inline(always)]
    pub(super) fn corners_f32(data: &[f32], base: i32x8, oy: i32, oz: i32) -> [f32x8; 8] {
        let n = data.len();
        if n < 2 || n > i32::MAX as usize {
            return [f32x8::splat(0.0); 8]; // unreachable: a cell has an x neighbour
        }
        let hi = n as i32 - 1;
        let p = data.as_ptr().cast::<u8>();
        // SAFETY: voxel indices 0..=n - 1 leave one voxel (4 bytes) in `data`.
        let row = |o: i32| -> f32x8 { bytemuck::cast(unsafe { gather::<4>(p, base + i32x8::splat(o), hi) }) };
        [
            row(0),
            row(1),
            row(oy),
            row(oy + 1),
            row(oz),
            row(oz + 1),
            row(oz + oy),
            row(oz + oy + 1),
        ]
    }

    /// How `f32` corners are read: [`PAIRS`], [`GATHER`] or [`LOADS`]; 0 not yet decided
    /// ([`f32_corners`] decides once; the tests set each in turn).
    pub(super) static F32_GATHER: core::sync::atomic::AtomicU8 = core::sync::atomic::AtomicU8::new(0);
    /// `f32` corners gathered as 64-bit x pairs ([`corners_f32_pairs`]; AVX-512 builds only).
    #[cfg_attr(not(target_feature = "avx512f"), allow(dead_code))]
    pub(super) const PAIRS: u8 = 1;
    /// `f32` corners gathered one voxel per element ([`corners_f32`]).
    pub(super) const GATHER: u8 = 2;
    /// `f32` corners read by scalar loads (the default of
    /// [`Voxel::corners_x8`](super::Voxel::corners_x8)).
    pub(super) const LOADS: u8 = 3;

    /// How this processor reads `f32` corners best: on AMD processors the 64-bit pair gathers in
    /// an AVX-512 build and scalar loads in an AVX2 one; elsewhere the 32-bit gathers.
    // PERF: dense f32 Marschner-Lobb 128^3, x8 (`volume_x8_vs_scalar`): on an Intel Xeon
    // (Emerald Rapids, 2026-12-04; best of 5 x 3 rounds, taking turns) the pairs took 22.5 ms and
    // the eight 32-bit gathers 17.0 ms; on an AMD EPYC (Zen 4) the pairs were 13% faster (see
    // `corners_f32_pairs`). On an AMD EPYC of the first Zen generation (AVX2, 2026-12-07; three
    // rounds of criterion medians, the two builds taking turns) the 32-bit gathers took 39.5-40.6
    // ms and scalar loads 33.8-34.9 ms (the `u8` and `u16` pair gathers 30.1-34.1 and 30.6-31.0 ms
    // against 32.9-33.6 and 29.2-31.7 ms with scalar pair loads: kept); an AMD EPYC of the third
    // generation had measured the gathers and loads alike. The vendor is read once (cpuid leaf
    // 0), then one relaxed load per call.
    #[inline(always)]
    pub(super) fn f32_corners() -> u8 {
        use core::sync::atomic::Ordering::Relaxed;
        match F32_GATHER.load(Relaxed) {
            0 => {
                // An SGX enclave faults on `cpuid`, and miri cannot run it: the 32-bit gathers
                // there.
                let c = if cfg!(target_env = "sgx") || cfg!(miri) {
                    GATHER
                } else {
                    // SAFETY: every x86_64 processor has `cpuid` (enclaves, which fault on it,
                    // are excluded above), and leaf 0 always exists. (The intrinsic is a safe
                    // function on newer compilers, hence the allow.)
                    #[allow(unused_unsafe)]
                    let id = unsafe { core::arch::x86_64::__cpuid(0) };
                    // "AuthenticAMD" in ebx, edx, ecx.
                    let amd = (id.ebx, id.edx, id.ecx) == (0x6874_7541, 0x6974_6e65, 0x444d_4163);
                    match (amd, cfg!(target_feature = "avx512f")) {
                        (true, true) => PAIRS,
                        (true, false) => LOADS,
                        (false, _) => GATHER,
                    }
                };
                F32_GATHER.store(c, Relaxed);
                c
            }
            c => c,
        }
    }

    /// [`Voxel::corners_x8`](super::Voxel::corners_x8) for `f32` with AVX-512: each x pair of
    /// voxels gathered as one 64-bit word, eight pairs per gather (half the gathered elements of
    /// the AVX2 form), then split into its halves.
    // PERF: x8 over a dense f32 Marschner-Lobb 32^3 (in cache), best of 15 x 4 runs alternating
    // (AMD EPYC, AVX-512): 4.12 -> 3.65 ms. Gathering the transfer function's rows the same way
    // (four 64-bit gathers instead of eight loads and a transpose) was 12% slower: tried, dropped.
    #[cfg(target_feature = "avx512f")]
    #[inline(always)]
    pub(super) fn corners_f32_pairs(data: &[f32], base: i32x8, oy: i32, oz: i32) -> [f32x8; 8] {
        use core::arch::x86_64::{__m512i, _mm512_cvtepi64_epi32, _mm512_i32gather_epi64, _mm512_srli_epi64};
        let n = data.len();
        if n < 2 || n > i32::MAX as usize {
            return [f32x8::splat(0.0); 8]; // unreachable: a cell has an x neighbour
        }
        let hi = n as i32 - 2;
        let p = data.as_ptr();
        let row = |o: i32| -> (f32x8, f32x8) {
            let idx: __m256i = bytemuck::cast((base + i32x8::splat(o)).max(i32x8::splat(0)).min(i32x8::splat(hi)));
            // SAFETY: every index lies in 0..=n - 2 after the clamp, so each 8-byte read (voxels
            // i and i + 1) lies in `data`; the gather has no alignment requirement, and the other
            // two intrinsics are register operations (avx512f is enabled for the whole build).
            unsafe {
                let w: __m512i = _mm512_i32gather_epi64::<4>(idx, p.cast());
                let lo = _mm512_cvtepi64_epi32(w);
                let hi = _mm512_cvtepi64_epi32(_mm512_srli_epi64::<32>(w));
                (bytemuck::cast(lo), bytemuck::cast(hi))
            }
        };
        let (a, b, c, d) = (row(0), row(oy), row(oz), row(oz + oy));
        [a.0, a.1, b.0, b.1, c.0, c.1, d.0, d.1]
    }

    /// [`Voxel::corners_x8`](super::Voxel::corners_x8) for `u16`: each pair is exactly one
    /// 32-bit word.
    #[inline(always)]
    pub(super) fn corners_u16(data: &[u16], base: i32x8, oy: i32, oz: i32) -> [f32x8; 8] {
        let n = data.len();
        if n < 2 || n > i32::MAX as usize {
            return [f32x8::splat(0.0); 8]; // unreachable: an x pair is 2 voxels
        }
        let hi = n as i32 - 2;
        let p = data.as_ptr().cast::<u8>();
        // SAFETY: voxel indices 0..=n - 2 leave 2 voxels (4 bytes) in `data`.
        let row = |o: i32| unsafe { gather::<2>(p, base + i32x8::splat(o), hi) };
        let m = i32x8::splat(0xffff);
        let mut v = [f32x8::splat(0.0); 8];
        for (c, o) in [0, oy, oz, oz + oy].into_iter().enumerate() {
            let w = row(o);
            v[2 * c] = (w & m).round_float();
            v[2 * c + 1] = ((w >> 16u32) & m).round_float();
        }
        v
    }
}

impl Voxel for f32 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }

    #[inline(always)]
    fn corners_x8(data: &[Self], base: i32x8, oy: usize, oz: usize) -> [f32x8; 8] {
        #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
        match gather::f32_corners() {
            #[cfg(target_feature = "avx512f")]
            gather::PAIRS => return gather::corners_f32_pairs(data, base, oy as i32, oz as i32),
            gather::LOADS => {}
            _ => return gather::corners_f32(data, base, oy as i32, oz as i32),
        }
        {
            // The default: one scalar load per lane and corner.
            let base = base.to_array();
            let mut v = [[0.0f32; 8]; 8];
            let at = |i: usize| data.get(i).copied().unwrap_or(0.0);
            for l in 0..8 {
                let b = base[l] as usize;
                for (c, vc) in v.iter_mut().enumerate() {
                    vc[l] = at(b + (c & 1) + (c >> 1 & 1) * oy + (c >> 2) * oz);
                }
            }
            v.map(f32x8::new)
        }
    }
}

/// A structured volume: `nx * ny * nz` voxels, x fastest, borrowed from the caller.
///
/// # Geometry
/// Voxel `(i, j, k)` is a sample of the field at world point `origin + (i, j, k) * spacing` (voxels
/// are points, as in VTK image data), so the volume's [`bounds`](Self::bounds) run from `origin`
/// to `origin + (dims - 1) * spacing`. *Local* (voxel) coordinates are
/// `g = (p - origin) / spacing`; voxel `(i, j, k)` sits at `g = (i, j, k)`.
///
/// # Sampling
/// Trilinear interpolation of the 8 voxels around `g`, after clamping `g` to the box (clamp to
/// edge; a NaN coordinate reads as 0). Each axis interpolates as `a + (b - a) f`, x first, then y,
/// then z, in every width, so [`sample_local_scalar`](Self::sample_local_scalar) and
/// [`sample_local_x8`](Self::sample_local_x8) agree bit for bit. A linear field is reproduced up to
/// rounding. An axis with one voxel is constant along it; an empty volume (a zero dimension) samples
/// as `0` and its box is empty.
///
/// ```
/// use strahl::Vec3;
/// use strahl::volume::Volume;
/// // 2 x 1 x 1 voxels of u16, from bytes (machine byte order), 0.5 apart along x.
/// let data: [u16; 2] = [100, 300];
/// let bytes: &[u8] = bytemuck::cast_slice(&data);
/// let v = Volume::<u16>::from_bytes(bytes, [2, 1, 1], Vec3::new(0.5, 1.0, 1.0), Vec3::ZERO).unwrap();
/// assert_eq!(v.bounds().max, Vec3::new(0.5, 0.0, 0.0));
/// assert_eq!(v.sample_scalar(Vec3::new(0.125, 0.0, 0.0)), 150.0);
/// assert_eq!(v.sample_scalar(Vec3::new(9.0, 0.0, 0.0)), 300.0); // clamped to the box
/// ```
#[derive(Clone, Copy, Debug)]
pub struct Volume<'a, V: Voxel> {
    data: &'a [V],
    dims: [u32; 3],
    spacing: Vec3,
    origin: Vec3,
    inv_spacing: Vec3,
    /// `dims - 1` per axis, as `f32`: the clamp for local coordinates.
    gmax: [f32; 3],
    /// `max(dims - 2, 0)` per axis: the last cell index.
    cmax: [i32; 3],
    /// Index strides of x, y, z.
    stride: [i32; 3],
    /// Offset to the next voxel per axis: the stride, or 0 on an axis with one voxel.
    next: [i32; 3],
}

/// Cell of one sample: the linear index of its lowest voxel and the fractions along each axis.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Cell {
    pub base: usize,
    pub idx: [i32; 3],
    pub frac: [f32; 3],
}

/// Cells of eight samples.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CellX8 {
    pub base: i32x8,
    pub idx: [[i32; 8]; 3],
    pub frac: [f32x8; 3],
}

#[inline(always)]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

#[inline(always)]
fn lerp8(a: f32x8, b: f32x8, t: f32x8) -> f32x8 {
    a + (b - a) * t
}

impl<'a, V: Voxel> Volume<'a, V> {
    /// Most voxels a volume may have: `2^31 - 1`, so voxel indices fit the `i32` lanes.
    ///
    /// ```
    /// use strahl::{Vec3, volume::{Volume, VolumeError}};
    /// assert_eq!(Volume::<u8>::MAX_VOXELS, (1 << 31) - 1);
    /// // 2^16 * 2^15 = 2^31 voxels: one too many (checked before the data length).
    /// let err = Volume::<u8>::new(&[], [1 << 16, 1 << 15, 1], Vec3::ONE, Vec3::ZERO).unwrap_err();
    /// assert_eq!(err, VolumeError::TooLarge);
    /// ```
    pub const MAX_VOXELS: usize = i32::MAX as usize;

    /// A volume over `data` (x fastest, then y, then z).
    ///
    /// Errors: [`VolumeError::TooLarge`] if `nx ny nz` overflows or exceeds
    /// [`MAX_VOXELS`](Self::MAX_VOXELS); [`VolumeError::SizeMismatch`] if `data.len()` differs from
    /// it; [`VolumeError::InvalidGeometry`] unless `spacing` is finite and positive and `origin`
    /// and the far corner `origin + (dims - 1) spacing` finite. Zero dimensions with empty `data` make a valid, empty volume.
    ///
    /// ```
    /// use strahl::{Vec3, volume::{Volume, VolumeError}};
    /// let data = [1.0f32; 6];
    /// assert!(Volume::new(&data, [3, 2, 1], Vec3::ONE, Vec3::ZERO).is_ok());
    /// let err = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap_err();
    /// assert_eq!(err, VolumeError::SizeMismatch { expected: 8, actual: 6 });
    /// let err = Volume::new(&data, [3, 2, 1], Vec3::new(1.0, 0.0, 1.0), Vec3::ZERO).unwrap_err();
    /// assert_eq!(err, VolumeError::InvalidGeometry); // zero spacing
    /// assert!(Volume::<f32>::new(&[], [0, 5, 5], Vec3::ONE, Vec3::ZERO).unwrap().is_empty());
    /// assert!(Volume::<u8>::new(&[], [1 << 16, 1 << 16, 0], Vec3::ONE, Vec3::ZERO).unwrap().is_empty());
    /// // Bounds that overflow `f32`: the far corner at 3e38 + 3e38.
    /// let err = Volume::new(&[1.0f32; 8], [2, 2, 2], Vec3::splat(3e38), Vec3::splat(3e38)).unwrap_err();
    /// assert_eq!(err, VolumeError::InvalidGeometry);
    /// ```
    pub fn new(data: &'a [V], dims: [u32; 3], spacing: Vec3, origin: Vec3) -> Result<Self, VolumeError> {
        let n = Self::voxel_count(dims)?;
        if data.len() != n {
            return Err(VolumeError::SizeMismatch {
                expected: n,
                actual: data.len(),
            });
        }
        let gmax = dims.map(|d| d.saturating_sub(1) as f32);
        // The far corner too: a volume whose bounds overflow could not be marched.
        let far = origin + Vec3::from_array(gmax) * spacing;
        if !(spacing.is_finite() && spacing.cmpgt(Vec3::ZERO).all() && origin.is_finite() && far.is_finite()) {
            return Err(VolumeError::InvalidGeometry);
        }
        let (nx, ny) = (dims[0] as i32, dims[1] as i32);
        // `nx ny <= n <= i32::MAX` unless the volume is empty (then no voxel is ever read).
        let stride = if n == 0 { [0; 3] } else { [1, nx, nx * ny] };
        Ok(Self {
            data,
            dims,
            spacing,
            origin,
            inv_spacing: Vec3::ONE / spacing,
            gmax,
            cmax: dims.map(|d| d.saturating_sub(2) as i32),
            stride,
            next: core::array::from_fn(|a| if dims[a] > 1 { stride[a] } else { 0 }),
        })
    }

    /// A volume over raw bytes, without copying: the bytes are cast to voxels with `bytemuck`.
    ///
    /// Errors as [`new`](Self::new), plus [`VolumeError::Misaligned`] if `bytes` is not aligned for
    /// `V`, and [`VolumeError::SizeMismatch`] (in bytes) if its length is not `nx ny nz size_of::<V>()`.
    ///
    /// ```
    /// use strahl::Vec3;
    /// use strahl::volume::{Volume, VolumeError};
    /// let words = [0u32; 3]; // 4-aligned storage
    /// let bytes: &[u8] = bytemuck::cast_slice(&words);
    /// assert!(Volume::<f32>::from_bytes(&bytes[..8], [2, 1, 1], Vec3::ONE, Vec3::ZERO).is_ok());
    /// let err = Volume::<f32>::from_bytes(&bytes[1..9], [2, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap_err();
    /// assert_eq!(err, VolumeError::Misaligned { required: 4 });
    /// ```
    pub fn from_bytes(bytes: &'a [u8], dims: [u32; 3], spacing: Vec3, origin: Vec3) -> Result<Self, VolumeError> {
        let n = Self::voxel_count(dims)?;
        let size = core::mem::size_of::<V>();
        let expected = n.checked_mul(size).ok_or(VolumeError::TooLarge)?;
        if bytes.len() != expected {
            return Err(VolumeError::SizeMismatch {
                expected,
                actual: bytes.len(),
            });
        }
        let data: &[V] = bytemuck::try_cast_slice(bytes).map_err(|e| match e {
            bytemuck::PodCastError::TargetAlignmentGreaterAndInputNotAligned
            | bytemuck::PodCastError::AlignmentMismatch => VolumeError::Misaligned {
                required: core::mem::align_of::<V>(),
            },
            _ => VolumeError::SizeMismatch {
                expected,
                actual: bytes.len(),
            },
        })?;
        Self::new(data, dims, spacing, origin)
    }

    fn voxel_count(dims: [u32; 3]) -> Result<usize, VolumeError> {
        // An empty volume is valid whatever its other dimensions (even where their product
        // would overflow a 32-bit `usize`).
        if dims.contains(&0) {
            return Ok(0);
        }
        let n = (dims[0] as usize)
            .checked_mul(dims[1] as usize)
            .and_then(|n| n.checked_mul(dims[2] as usize))
            .ok_or(VolumeError::TooLarge)?;
        if n > Self::MAX_VOXELS {
            return Err(VolumeError::TooLarge);
        }
        Ok(n)
    }

    /// The voxels, x fastest.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    /// assert!(core::ptr::eq(v.data(), &data[..])); // borrowed, not copied
    /// assert_eq!(v.data()[1 + 2 * 1 + 4 * 1], 7.0); // voxel (1, 1, 1)
    /// ```
    #[inline]
    pub fn data(&self) -> &'a [V] {
        self.data
    }

    /// Number of voxels per axis.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 4, 1], Vec3::ONE, Vec3::ZERO).unwrap();
    /// assert_eq!(v.dims(), [2, 4, 1]);
    /// assert_eq!(v.dims().iter().product::<u32>() as usize, v.data().len());
    /// ```
    #[inline]
    pub fn dims(&self) -> [u32; 3] {
        self.dims
    }

    /// World distance between neighbouring voxels, per axis.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::new(0.5, 1.0, 2.0), Vec3::ZERO).unwrap();
    /// assert_eq!(v.spacing(), Vec3::new(0.5, 1.0, 2.0));
    /// assert_eq!(v.bounds().max, v.spacing()); // two voxels per axis: one spacing apart
    /// ```
    #[inline]
    pub fn spacing(&self) -> Vec3 {
        self.spacing
    }

    /// World position of voxel `(0, 0, 0)`.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::new(-1.0, 2.0, 0.0)).unwrap();
    /// assert_eq!(v.origin(), Vec3::new(-1.0, 2.0, 0.0));
    /// assert_eq!(v.sample_scalar(v.origin()), 0.0); // voxel (0, 0, 0)
    /// ```
    #[inline]
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// `true` for a volume without voxels.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// assert!(!Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap().is_empty());
    /// let empty = Volume::<f32>::new(&[], [4, 0, 4], Vec3::ONE, Vec3::ZERO).unwrap();
    /// assert!(empty.is_empty());
    /// assert_eq!(empty.sample_scalar(Vec3::ZERO), 0.0);
    /// ```
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The box spanned by the voxel centres, `origin ..= origin + (dims - 1) spacing`; empty for an
    /// empty volume.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::splat(0.25), Vec3::new(1.0, 0.0, -1.0)).unwrap();
    /// assert_eq!((v.bounds().min, v.bounds().max), (Vec3::new(1.0, 0.0, -1.0), Vec3::new(1.25, 0.25, -0.75)));
    /// let empty = Volume::<f32>::new(&[], [0, 0, 0], Vec3::ONE, Vec3::ZERO).unwrap();
    /// assert!(empty.bounds().is_empty());
    /// ```
    pub fn bounds(&self) -> Aabb {
        if self.is_empty() {
            return Aabb::EMPTY;
        }
        let g = Vec3::from_array(self.gmax);
        Aabb::new(self.origin, self.origin + g * self.spacing)
    }

    /// Voxel `(i, j, k)`, or `None` outside the grid.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    /// assert_eq!(v.voxel(1, 0, 1), Some(5.0)); // 1 + 2 0 + 4 1
    /// assert_eq!(v.voxel(0, 2, 0), None);
    /// ```
    pub fn voxel(&self, i: u32, j: u32, k: u32) -> Option<V> {
        if i >= self.dims[0] || j >= self.dims[1] || k >= self.dims[2] {
            return None;
        }
        let idx = i as usize + j as usize * self.stride[1] as usize + k as usize * self.stride[2] as usize;
        self.data.get(idx).copied()
    }

    /// Local (voxel) coordinates of world point `p`: `(p - origin) / spacing`.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::new(0.5, 2.0, 4.0), Vec3::new(1.0, 1.0, 1.0)).unwrap();
    /// assert_eq!(v.to_local(Vec3::new(1.25, 2.0, 3.0)), Vec3::new(0.5, 0.5, 0.5));
    /// assert_eq!(v.to_local(v.origin()), Vec3::ZERO);
    /// ```
    #[inline]
    pub fn to_local(&self, p: Vec3) -> Vec3 {
        (p - self.origin) * self.inv_spacing
    }

    /// `(origin, 1 / spacing)`: local = `(world - origin) * (1 / spacing)`.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::new(0.5, 0.25, 2.0), Vec3::new(3.0, 0.0, -1.0)).unwrap();
    /// let (o, inv) = v.local_frame();
    /// assert_eq!((o, inv), (Vec3::new(3.0, 0.0, -1.0), Vec3::new(2.0, 4.0, 0.5)));
    /// let p = Vec3::new(3.3, 0.1, 0.7);
    /// assert_eq!((p - o) * inv, v.to_local(p));
    /// ```
    #[inline]
    pub fn local_frame(&self) -> (Vec3, Vec3) {
        (self.origin, self.inv_spacing)
    }

    /// Trilinear sample at world point `p` (clamped to the box); `0` for an empty volume.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::splat(0.5), Vec3::ZERO).unwrap();
    /// // Trilinear interpolation reproduces the linear field i + 2j + 4k exactly.
    /// assert_eq!(v.sample_scalar(Vec3::new(0.25, 0.25, 0.25)), 3.5); // local (0.5, 0.5, 0.5)
    /// assert_eq!(v.sample_scalar(Vec3::new(0.5, 0.0, 0.125)), 2.0); // local (1, 0, 0.25)
    /// assert_eq!(v.sample_scalar(Vec3::new(-7.0, 0.0, 9.0)), 4.0); // clamped to voxel (0, 0, 1)
    /// ```
    #[inline]
    pub fn sample_scalar(&self, p: Vec3) -> f32 {
        self.sample_local_scalar(self.to_local(p))
    }

    /// Trilinear samples at eight world points (SoA); lane `i` equals [`sample_scalar`](Self::sample_scalar)
    /// of lane `i`'s point bit for bit.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// # use strahl::math::f32x8;
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::splat(0.5), Vec3::new(1.0, 0.0, 0.0)).unwrap();
    /// let xs = [0.9, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6];
    /// let p = [f32x8::new(xs), f32x8::splat(0.2), f32x8::splat(0.45)];
    /// let s = v.sample_x8(p).to_array();
    /// for i in 0..8 {
    ///     assert_eq!(s[i].to_bits(), v.sample_scalar(Vec3::new(xs[i], 0.2, 0.45)).to_bits());
    /// }
    /// ```
    #[inline]
    pub fn sample_x8(&self, p: [f32x8; 3]) -> f32x8 {
        let o = self.origin;
        let s = self.inv_spacing;
        self.sample_local_x8([
            (p[0] - f32x8::splat(o.x)) * f32x8::splat(s.x),
            (p[1] - f32x8::splat(o.y)) * f32x8::splat(s.y),
            (p[2] - f32x8::splat(o.z)) * f32x8::splat(s.z),
        ])
    }

    /// Trilinear sample at local coordinates `g` (clamped to `[0, dims - 1]`); `0` for an empty
    /// volume. Interpolated in `f32` as `a + (b - a) t`: where two neighbouring voxels differ by more
    /// than `f32::MAX` (values beyond about `±1.7e38`) the sample is infinite.
    ///
    /// ```
    /// # use strahl::{Vec3, volume::Volume};
    /// # let data: Vec<f32> = (0..8).map(|i| i as f32).collect(); // voxel (i, j, k) holds i + 2j + 4k
    /// let v = Volume::new(&data, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    /// assert_eq!(v.sample_local_scalar(Vec3::new(0.5, 0.25, 0.75)), 0.5 + 0.5 + 3.0);
    /// assert_eq!(v.sample_local_scalar(Vec3::new(5.0, -1.0, f32::NAN)), 1.0); // clamped: NaN to 0
    /// ```
    #[inline]
    pub fn sample_local_scalar(&self, g: Vec3) -> f32 {
        if self.data.is_empty() {
            return 0.0;
        }
        self.interp_scalar(&self.cell_scalar(g))
    }

    /// Trilinear samples at eight local points; bit-identical to
    /// [`sample_local_scalar`](Self::sample_local_scalar) per lane.
    ///
    /// ```
    /// use strahl::{Vec3, math::f32x8};
    /// use strahl::volume::Volume;
    /// let data: Vec<f32> = (0..27).map(|i| (i * i % 7) as f32).collect();
    /// let v = Volume::new(&data, [3, 3, 3], Vec3::ONE, Vec3::ZERO).unwrap();
    /// let xs = [0.1, 0.5, 1.0, 1.7, 2.0, -1.0, 3.5, f32::NAN];
    /// let g = [f32x8::new(xs), f32x8::splat(0.3), f32x8::splat(1.9)];
    /// let s = v.sample_local_x8(g).to_array();
    /// for i in 0..8 {
    ///     assert_eq!(s[i].to_bits(), v.sample_local_scalar(Vec3::new(xs[i], 0.3, 1.9)).to_bits());
    /// }
    /// ```
    #[inline]
    pub fn sample_local_x8(&self, g: [f32x8; 3]) -> f32x8 {
        if self.data.is_empty() {
            return f32x8::splat(0.0);
        }
        self.interp_x8(&self.cell_x8(g))
    }

    /// Clamps `g` to the box and finds its cell. Needs a non-empty volume.
    #[inline(always)]
    pub(crate) fn cell_scalar(&self, g: Vec3) -> Cell {
        let mut idx = [0i32; 3];
        let mut frac = [0.0f32; 3];
        for a in 0..3 {
            // NaN -> 0 (max_l returns its second operand on NaN).
            let gc = min_l(max_l(g[a], 0.0), self.gmax[a]);
            let i = (gc as i32).min(self.cmax[a]);
            idx[a] = i;
            // At most 1: on an axis of more than 2^24 voxels `gmax` rounds up past the last voxel,
            // and the clamp to the edge must read that voxel, not extrapolate beyond it.
            frac[a] = min_l(gc - i as f32, 1.0);
        }
        let base = idx[0] + idx[1] * self.stride[1] + idx[2] * self.stride[2];
        Cell {
            base: base as usize,
            idx,
            frac,
        }
    }

    /// Eight cells at once; lane `i` as [`cell_scalar`](Self::cell_scalar).
    #[inline(always)]
    pub(crate) fn cell_x8(&self, g: [f32x8; 3]) -> CellX8 {
        let mut idx = [[0i32; 8]; 3];
        let mut frac = [f32x8::splat(0.0); 3];
        let mut base = i32x8::splat(0);
        for a in 0..3 {
            let gc = g[a].max_l(f32x8::splat(0.0)).min_l(f32x8::splat(self.gmax[a]));
            // gc >= 0 and not NaN, so truncation is the floor, as `as i32` in the scalar form.
            // NOTE: the saturating form: on an axis of 2^31 - 63 voxels or more `gmax` rounds up to
            // 2^31, where the untrapped conversion gives `i32::MIN` (found in review).
            let i = gc.trunc_int().min(i32x8::splat(self.cmax[a]));
            frac[a] = (gc - i.round_float()).min_l(f32x8::splat(1.0));
            base += i * i32x8::splat(self.stride[a]);
            idx[a] = i.to_array();
        }
        CellX8 { base, idx, frac }
    }

    /// Asks the cache for the four voxel rows (`+0`, `+oy`, `+oz`, `+oz + oy`) of the cells at
    /// eight local points. A hint only: nothing is read (x86_64 only, a no-op elsewhere).
    #[inline(always)]
    pub(crate) fn prefetch_x8(&self, g: [f32x8; 3]) {
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
            let mut base = i32x8::splat(0);
            for ((g, hi), stride) in g.into_iter().zip(self.gmax).zip(self.stride) {
                let gc = g.max_l(f32x8::splat(0.0)).min_l(f32x8::splat(hi));
                base += gc.fast_trunc_int() * i32x8::splat(stride);
            }
            let [_, oy, oz] = self.next.map(|o| o as usize);
            let p = self.data.as_ptr();
            for b in base.to_array() {
                for o in [0, oy, oz, oz + oy] {
                    // SAFETY: SSE is part of every x86_64 target; a prefetch reads nothing and
                    // never faults (`wrapping_add` only computes an address, valid or not).
                    unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(b as u32 as usize + o).cast()) };
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = g;
    }

    /// Trilinear interpolation in a cell: x, then y, then z.
    #[inline(always)]
    pub(crate) fn interp_scalar(&self, c: &Cell) -> f32 {
        let [ox, oy, oz] = self.next.map(|o| o as usize);
        let d = self.data;
        let b = c.base;
        let v = |i: usize| d[i].to_f32();
        let [fx, fy, fz] = c.frac;
        let c00 = lerp(v(b), v(b + ox), fx);
        let c10 = lerp(v(b + oy), v(b + oy + ox), fx);
        let c01 = lerp(v(b + oz), v(b + oz + ox), fx);
        let c11 = lerp(v(b + oz + oy), v(b + oz + oy + ox), fx);
        let c0 = lerp(c00, c10, fy);
        let c1 = lerp(c01, c11, fy);
        lerp(c0, c1, fz)
    }

    /// Eight trilinear interpolations; the voxel loads are scalar (a gather), the arithmetic 8-wide.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // lane l of eight arrays
    pub(crate) fn interp_x8(&self, c: &CellX8) -> f32x8 {
        let [ox, oy, oz] = self.next.map(|o| o as usize);
        let d = self.data;
        let v = if ox == 1 {
            V::corners_x8(d, c.base, oy, oz)
        } else {
            // One voxel along x: both x corners are the same voxel.
            let mut v = [[0.0f32; 8]; 8];
            let base = c.base.to_array();
            for l in 0..8 {
                let b = base[l] as usize;
                for (k, o) in [0, oy, oz, oz + oy].into_iter().enumerate() {
                    let x = d.get(b + o).map_or(0.0, |x| x.to_f32());
                    (v[2 * k][l], v[2 * k + 1][l]) = (x, x);
                }
            }
            v.map(f32x8::new)
        };
        let [fx, fy, fz] = c.frac;
        let c00 = lerp8(v[0], v[1], fx);
        let c10 = lerp8(v[2], v[3], fx);
        let c01 = lerp8(v[4], v[5], fx);
        let c11 = lerp8(v[6], v[7], fx);
        let c0 = lerp8(c00, c10, fy);
        let c1 = lerp8(c01, c11, fy);
        lerp8(c0, c1, fz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec::Vec;

    #[test]
    fn construction_errors() {
        let d = [0u8; 8];
        assert!(Volume::new(&d, [2, 2, 2], Vec3::ONE, Vec3::ZERO).is_ok());
        assert_eq!(
            Volume::new(&d, [2, 2, 3], Vec3::ONE, Vec3::ZERO).unwrap_err(),
            VolumeError::SizeMismatch {
                expected: 12,
                actual: 8
            }
        );
        for bad in [
            Vec3::ZERO,
            Vec3::new(1.0, -1.0, 1.0),
            Vec3::splat(f32::NAN),
            Vec3::INFINITY,
        ] {
            assert_eq!(
                Volume::new(&d, [2, 2, 2], bad, Vec3::ZERO).unwrap_err(),
                VolumeError::InvalidGeometry
            );
        }
        assert_eq!(
            Volume::new(&d, [2, 2, 2], Vec3::ONE, Vec3::splat(f32::NAN)).unwrap_err(),
            VolumeError::InvalidGeometry
        );
        assert_eq!(
            Volume::<u8>::new(&[], [u32::MAX, u32::MAX, 2], Vec3::ONE, Vec3::ZERO).unwrap_err(),
            VolumeError::TooLarge
        );
        assert_eq!(
            Volume::<u8>::new(&[], [65536, 65536, 1], Vec3::ONE, Vec3::ZERO).unwrap_err(),
            VolumeError::TooLarge
        );
        let words = [0u16; 5];
        let bytes: &[u8] = bytemuck::cast_slice(&words);
        assert_eq!(
            Volume::<u16>::from_bytes(&bytes[1..9], [2, 2, 1], Vec3::ONE, Vec3::ZERO).unwrap_err(),
            VolumeError::Misaligned { required: 2 }
        );
        assert_eq!(
            Volume::<u16>::from_bytes(&bytes[..7], [2, 2, 1], Vec3::ONE, Vec3::ZERO).unwrap_err(),
            VolumeError::SizeMismatch { expected: 8, actual: 7 }
        );
    }

    #[test]
    fn empty_volume_samples_zero() {
        let v = Volume::<f32>::new(&[], [0, 4, 4], Vec3::ONE, Vec3::ZERO).unwrap();
        assert!(v.is_empty());
        assert!(v.bounds().is_empty());
        assert_eq!(v.sample_scalar(Vec3::ZERO), 0.0);
        assert_eq!(v.sample_x8([f32x8::splat(0.5); 3]).to_array(), [0.0; 8]);
        assert_eq!(v.voxel(0, 0, 0), None);
    }

    #[test]
    fn linear_field_is_reproduced() {
        // f = 1 + 2x - 3y + 0.5z on a 5 x 4 x 3 grid with spacing 0.5 (exact in f32).
        let dims = [5u32, 4, 3];
        let sp = Vec3::splat(0.5);
        let f = |p: Vec3| 1.0 + 2.0 * p.x - 3.0 * p.y + 0.5 * p.z;
        let mut data = [0.0f32; 60];
        for k in 0..3 {
            for j in 0..4 {
                for i in 0..5 {
                    data[i + 5 * j + 20 * k] = f(Vec3::new(i as f32, j as f32, k as f32) * sp);
                }
            }
        }
        let v = Volume::new(&data, dims, sp, Vec3::ZERO).unwrap();
        for s in 0..200 {
            let p = Vec3::new(
                (s * 37 % 200) as f32 / 100.0,
                (s * 11 % 150) as f32 / 100.0,
                (s * 7 % 100) as f32 / 100.0,
            );
            assert!((v.sample_scalar(p) - f(p)).abs() < 1e-5, "{p}");
        }
    }

    #[test]
    fn single_voxel_axes() {
        let data = [3.0f32, 5.0];
        let v = Volume::new(&data, [2, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
        assert_eq!(v.sample_local_scalar(Vec3::new(0.5, 7.0, -3.0)), 4.0);
        let one = Volume::new(&data[..1], [1, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
        assert_eq!(one.sample_local_scalar(Vec3::new(0.5, 0.5, 0.5)), 3.0);
        assert_eq!(one.bounds(), Aabb::new(Vec3::ZERO, Vec3::ZERO));
    }
    /// Every small shape (1, 2, 3 or 5 voxels per axis), every voxel type: the x8 sampler (with
    /// the AVX2 gathers of `u8`/`u16` pairs where the build has AVX2, the `f32` gathers of single
    /// voxels and the scalar loads there too, the 64-bit pair gathers where it has AVX-512, and
    /// the pair loads elsewhere) equals the scalar reference bit
    /// for bit, including the last cells of the volume, where a gather of 4 or 8 bytes would run
    /// past its end if the offsets were wrong. Every x8 march test also runs the prefetches.
    #[test]
    fn x8_corners_equal_scalar_on_every_small_shape() {
        fn check<V: Voxel>(make: impl Fn(u32) -> V) {
            // Under miri (which checks the gathers' memory accesses) a reduced set of shapes.
            let sizes: &[u32] = if cfg!(miri) { &[1, 3] } else { &[1, 2, 3, 5] };
            for &nx in sizes {
                for &ny in sizes {
                    for &nz in sizes {
                        let n = (nx * ny * nz) as usize;
                        let data: Vec<V> = (0..n as u32)
                            .map(|i| make(i.wrapping_mul(2_654_435_761) >> 7))
                            .collect();
                        let v = Volume::new(&data, [nx, ny, nz], Vec3::ONE, Vec3::ZERO).unwrap();
                        // Points on a lattice that reaches every cell, the far faces and beyond
                        // (under miri one point per cell and past the far faces, not two).
                        let (step, per_cell) = if cfg!(miri) { (1.0, 1) } else { (0.5, 2) };
                        let last = |n: u32| per_cell * n + 1;
                        let pts: Vec<Vec3> = (0..=last(nz))
                            .flat_map(|k| {
                                (0..=last(ny)).flat_map(move |j| {
                                    (0..=last(nx)).map(move |i| Vec3::new(i as f32, j as f32, k as f32) * step - 0.25)
                                })
                            })
                            .collect();
                        for c in pts.chunks(8) {
                            let mut g = [[0.0f32; 8]; 3];
                            for (l, p) in c.iter().enumerate() {
                                for a in 0..3 {
                                    g[a][l] = p[a];
                                }
                            }
                            let s = v.sample_local_x8(g.map(f32x8::new)).to_array();
                            for (l, p) in c.iter().enumerate() {
                                let want = v.sample_local_scalar(*p);
                                assert_eq!(s[l].to_bits(), want.to_bits(), "{nx}x{ny}x{nz} at {p}");
                            }
                        }
                    }
                }
            }
        }
        check(|x| x as u8);
        check(|x| x as u16);
        check(|x| (x % 1000) as f32 * 0.37);
        // Every way of reading f32 corners the build has (the pair gathers with AVX-512, the
        // 32-bit gathers, scalar loads), whichever this processor gets (other tests running
        // meanwhile see the same bits either way).
        #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
        for choice in [gather::PAIRS, gather::GATHER, gather::LOADS] {
            if choice == gather::PAIRS && !cfg!(target_feature = "avx512f") {
                continue;
            }
            gather::F32_GATHER.store(choice, core::sync::atomic::Ordering::Relaxed);
            check(|x| (x % 1000) as f32 * 0.37);
            check(|x| f32::from_bits(x.wrapping_mul(0x9e37_79b9) & 0x807f_ffff | 0x3f00_0000));
        }
    }
}
