//! The `volume` target: volumes of `u8`, `u16` and `f32` voxels, transfer functions, the scalar
//! and x8 Riemann marchers, early termination and macrocell empty-space skipping.
//!
//! Input layout (every byte string decodes; values as in [`decode`](crate::decode)):
//!
//! ```text
//! header   1 byte   bit 0: mode (0 chaos, 1 grid); bits 1-2: voxel type (0 u8, 1 u16, else f32);
//!                   bit 3: constant volume (every voxel is the first); bit 4: midpoint sampling;
//!                   bits 5-7: termination (None, None, Some(0), 1/256, 0.05, 0.3, read, 0.999)
//! dims     3 bytes  grid: 1 + b % 16 per axis; chaos: b % 17 (0 makes an empty volume)
//! geometry 1 selector byte (chaos: >= 0x80 reads spacing and origin as 6 values), spacing
//!          (grid: 3 bytes into SPACINGS), origin (3 values)
//! tf       1 byte (entries 1 + b % 8, chaos: bit 7 reads lo, hi as 2 values), then per entry a
//!          tag byte (chaos >= 0x60: colour and tau as 4 values) or grid bytes into TAUS / COLOURS
//! params   step byte (chaos >= 0xa0: a value, else a multiple of the smallest spacing), max-steps
//!          byte, block byte, termination epsilon (1 value, read only when the header asks)
//! rays     count byte (1 + b % 12); per ray a kind byte (bit 0: aim at a point of the box given
//!          by 3 bytes, bit 1: -0 direction components), origin (3 values, relative to the volume
//!          origin), direction (3 values, unless aimed), range selector
//! probes   8 local points (3 values each), 8 transfer-function arguments, an active-lane byte
//! voxels   nx ny nz voxels (grid: bytes into the voxel set of the type; chaos: raw bytes for
//!          u8 / u16, values for f32); one voxel for a constant volume
//! ```
//!
//! What must hold, in both modes: construction errors exactly as documented (spacing, origin,
//! range, entries, step, termination, max steps, block size, stale or mismatched grids,
//! `LengthMismatch`), nothing written on error and nothing past the rays; the x8 sampler, the x8
//! transfer-function lookup and the x8 medium lookup equal their scalar forms bit for bit; the
//! macrocell ranges equal a brute-force min/max over each block and its halo, the empty flags
//! equal `is_transparent`, the stored distances are chessboard distances to the nearest
//! non-empty block; every empty region reported keeps its contract (zero extinction at the
//! sample and at the corners and centre of its safe box); the x8 marcher equals the scalar
//! reference bit for bit, counters included, with and without skipping; skipping leaves every
//! image bit for bit unchanged and `samples(plain) = samples(skip) + skipped(skip)`;
//! `integrate_ray` equals `integrate_scalar`; termination at `Some(0)` is bit-identical to none,
//! and `Some(eps)` stays within `eps max|c|` (plus rounding); `A` lies in `[0, 1]`; with colours
//! of sane magnitude every colour channel is finite and lies within `[min c, max c] A`;
//! invalid rays and empty volumes give `Rgba::ZERO`.
//!
//! Grid mode adds the optical depth: for rays that are not ambiguous (not in a face plane, not
//! touching the box), `A` lies within `1 - exp(-tau L)` for the least and largest extinction of
//! the table (`L` from an f64 clip of the ray to the box, cut at `max_steps dt`), which for a
//! constant volume is the closed form `A = 1 - exp(-tau L)`, `C = c A`; rays that miss give
//! `Rgba::ZERO`.

use crate::decode::{Input, Mode, negative_zeros};
use strahl::math::f32x8;
use strahl::volume::{
    COLOR_MAX, EmptyRegion, GridParams, Lookup, MAX_EMPTY_RADIUS, MAX_STEPS_LIMIT, Macrocell, MacrocellGrid,
    MarchParams, MarchStats, Medium, PreintegratedMedium, PreintegratedTable, Rgba, Sampling, TAU_MAX, TfEntry,
    TransferFunction, Volume, VolumeError, VolumeMedium, Voxel, integrate, integrate_preintegrated_scalar,
    integrate_preintegrated_x8, integrate_ray, integrate_scalar, integrate_x8,
};
use strahl::{Aabb, Ray, Vec3};

/// Largest number of voxels per axis.
pub const MAX_DIM: u32 = 16;
/// Largest number of rays per input (more than 8, so the x8 marcher refills lanes).
pub const MAX_RAYS: usize = 12;
/// Grid spacings, per axis.
pub const SPACINGS: [f32; 4] = [1.0, 0.5, 0.25, 2.0];
/// Grid extinctions of transfer-function entries (zero-heavy, so that there is space to skip).
pub const TAUS: [f32; 8] = [0.0, 0.0, 0.0, 0.5, 1.0, 2.0, 4.0, 8.0];
/// Grid colour channels of transfer-function entries.
pub const COLOURS: [f32; 4] = [0.0, 0.25, 0.5, 1.0];
/// Grid steps as multiples of the smallest spacing.
pub const STEP_MULTIPLES: [f32; 6] = [1.0, 0.5, 0.25, 2.0, 0.125, 1.0];
/// `max_steps` values: the bound on the work per ray, and the invalid `0` and `LIMIT + 1`.
pub const MAX_STEPS: [u32; 12] = [1024, 1024, 1024, 1024, 256, 64, 8, 3, 2, 1, 0, MAX_STEPS_LIMIT + 1];
/// Macrocell block sizes; the last four are invalid (chaos only).
pub const BLOCKS: [u32; 9] = [2, 4, 8, 16, 64, 0, 1, 3, 128];
/// Colour magnitude up to which outputs must be finite (beyond it, the linear interpolation of
/// two entries may overflow: see the crate's transfer-function docs).
pub const SANE_COLOUR: f32 = 1e30;

/// The voxels of a case, in their type.
#[derive(Clone, Debug)]
pub enum Voxels {
    /// `u8` voxels.
    U8(Vec<u8>),
    /// `u16` voxels.
    U16(Vec<u16>),
    /// `f32` voxels.
    F32(Vec<f32>),
}

/// A decoded `volume` input.
#[derive(Clone, Debug)]
pub struct VolumeCase {
    /// The input mode.
    pub mode: Mode,
    /// Voxels per axis.
    pub dims: [u32; 3],
    /// Every voxel has the same value.
    pub constant: bool,
    /// The voxels, x fastest.
    pub voxels: Voxels,
    /// Voxel spacing (possibly invalid in chaos mode).
    pub spacing: Vec3,
    /// Volume origin (possibly invalid in chaos mode).
    pub origin: Vec3,
    /// Transfer-function entries (possibly invalid in chaos mode).
    pub table: Vec<TfEntry>,
    /// Transfer-function value range (possibly invalid in chaos mode).
    pub range: (f32, f32),
    /// Marching parameters (possibly invalid in chaos mode).
    pub params: MarchParams,
    /// Macrocell block size (possibly invalid in chaos mode).
    pub block: u32,
    /// The rays.
    pub rays: Vec<Ray>,
    /// Local points for the sampler and medium lookups.
    pub points: [Vec3; 8],
    /// Scalar values for the transfer-function lookups.
    pub values: [f32; 8],
    /// Active lanes of the x8 medium lookup.
    pub active: u32,
}

impl VolumeCase {
    /// Decodes `data` (see the module docs); never fails.
    pub fn decode(data: &[u8]) -> Self {
        let mut inp = Input::new(data);
        let h = inp.byte();
        let mode = Mode::of_header(h);
        let grid = mode == Mode::Grid;
        let kind = (h >> 1) & 3;
        let constant = h & 8 != 0;
        let sampling = if h & 16 != 0 {
            Sampling::Midpoint
        } else {
            Sampling::Endpoint
        };
        let dims: [u32; 3] = core::array::from_fn(|_| {
            let b = u32::from(inp.byte());
            if grid { 1 + b % MAX_DIM } else { b % (MAX_DIM + 1) }
        });

        // Geometry.
        let sel = inp.byte();
        let (spacing, origin) = if !grid && sel >= 0x80 {
            (inp.vec3(mode), inp.vec3(mode))
        } else {
            let s = Vec3::from_array(core::array::from_fn(|_| SPACINGS[usize::from(inp.byte()) % 4]));
            (s, inp.vec3(Mode::Grid))
        };

        // Transfer function.
        let tb = inp.byte();
        let n_entries = 1 + usize::from(tb) % 8;
        let vmax = match kind {
            0 => 255.0,
            1 => 65535.0,
            _ => 4.0,
        };
        let range = if !grid && tb >= 0x80 {
            (inp.chaos(), inp.chaos())
        } else {
            (0.0, vmax)
        };
        let table = (0..n_entries)
            .map(|_| {
                let tag = inp.byte();
                if !grid && tag >= 0x60 {
                    let c = inp.vec3(mode);
                    TfEntry::new(c.to_array(), inp.chaos())
                } else {
                    let cb = inp.byte();
                    let c = [cb & 3, (cb >> 2) & 3, (cb >> 4) & 3].map(|i| COLOURS[usize::from(i)]);
                    TfEntry::new(c, TAUS[usize::from(tag) % TAUS.len()])
                }
            })
            .collect();

        // Marching parameters.
        let sb = inp.byte();
        let smin = spacing.x.min(spacing.y).min(spacing.z);
        let step = if !grid && sb >= 0xa0 {
            inp.chaos()
        } else {
            let s = if smin.is_finite() && smin > 0.0 { smin } else { 1.0 };
            s * STEP_MULTIPLES[usize::from(sb) % STEP_MULTIPLES.len()]
        };
        let mb = usize::from(inp.byte());
        let max_steps = if grid {
            MAX_STEPS[mb % 6]
        } else {
            MAX_STEPS[mb % MAX_STEPS.len()]
        };
        let bb = usize::from(inp.byte());
        let block = BLOCKS[bb % if grid { 5 } else { BLOCKS.len() }];
        let termination = match h >> 5 {
            0 | 1 => None,
            2 => Some(0.0),
            3 => Some(1.0 / 256.0),
            4 => Some(0.05),
            5 => Some(0.3),
            6 => Some(if grid { 0.125 } else { inp.chaos() }),
            _ => Some(0.999),
        };
        let params = MarchParams {
            step,
            sampling,
            termination,
            max_steps,
        };

        // Rays, relative to the volume origin; aimed ones at a point of the volume's box.
        let (o0, box_min, box_max) = {
            let o = if origin.is_finite() { origin } else { Vec3::ZERO };
            let s = if spacing.is_finite() { spacing } else { Vec3::ONE };
            let ext = Vec3::from_array(dims.map(|d| d.saturating_sub(1) as f32)) * s;
            (o, o, o + ext)
        };
        let n_rays = 1 + usize::from(inp.byte()) % MAX_RAYS;
        let rays = (0..n_rays)
            .map(|_| {
                let k = inp.byte();
                let o = o0 + inp.vec3(mode);
                let mut d = if k & 1 != 0 {
                    let f = Vec3::from_array(core::array::from_fn(|_| f32::from(inp.byte() % 17) / 16.0));
                    box_min + (box_max - box_min) * f - o
                } else {
                    inp.vec3(mode)
                };
                if k & 2 != 0 {
                    d = negative_zeros(d);
                }
                let (tmin, tmax) = inp.range(mode);
                Ray::with_range(o, d, tmin, tmax)
            })
            .collect();

        // Probes.
        let points = core::array::from_fn(|_| {
            let p = inp.vec3(mode);
            if grid { (p + Vec3::splat(8.0)) * 0.5 } else { p }
        });
        let values = core::array::from_fn(|_| {
            if grid {
                (inp.grid() + 8.0) * vmax / 16.0
            } else {
                inp.chaos()
            }
        });
        let active = u32::from(inp.byte() | 1);

        // Voxels last: past the end of the input they are all zero.
        let n = dims.iter().map(|&d| d as usize).product::<usize>();
        let m = if constant { n.min(1) } else { n };
        let voxels = match kind {
            0 => {
                let set = [0u8, 0, 0, 64, 128, 192, 255, 32];
                let v: Vec<u8> = (0..m)
                    .map(|_| {
                        let b = inp.byte();
                        if grid { set[usize::from(b) % 8] } else { b }
                    })
                    .collect();
                Voxels::U8(repeat(v, n))
            }
            1 => {
                let set = [0u16, 0, 0, 1000, 2000, 4000, 65535, 300];
                let v: Vec<u16> = (0..m)
                    .map(|_| {
                        if grid {
                            set[usize::from(inp.byte()) % 8]
                        } else {
                            u16::from_le_bytes([inp.byte(), inp.byte()])
                        }
                    })
                    .collect();
                Voxels::U16(repeat(v, n))
            }
            _ => {
                let set = [0.0f32, 0.0, 0.0, 0.25, 0.5, 1.0, 2.0, 4.0];
                let v: Vec<f32> = (0..m)
                    .map(|_| {
                        if grid {
                            set[usize::from(inp.byte()) % 8]
                        } else {
                            inp.chaos()
                        }
                    })
                    .collect();
                Voxels::F32(repeat(v, n))
            }
        };
        Self {
            mode,
            dims,
            constant,
            voxels,
            spacing,
            origin,
            table,
            range,
            params,
            block,
            rays,
            points,
            values,
            active,
        }
    }
}

/// `v` (one voxel for a constant volume) repeated up to `n` voxels.
fn repeat<T: Copy>(v: Vec<T>, n: usize) -> Vec<T> {
    if v.len() == 1 && n > 1 { vec![v[0]; n] } else { v }
}

/// What a checked case exercised (for the seed tests: seeds should not be vacuous).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VolumeReport {
    /// Rays that gathered some opacity.
    pub hits: usize,
    /// Counters of the plain x8 march with the case's parameters.
    pub plain: MarchStats,
    /// Counters of the skipping x8 march.
    pub skipping: MarchStats,
    /// The parameters were invalid (and checked as such).
    pub bad_params: bool,
}

/// Runs every check on `case` (see the module docs); panics on the first violation.
pub fn check_volume(case: &VolumeCase) -> VolumeReport {
    match &case.voxels {
        Voxels::U8(d) => check_typed(case, d),
        Voxels::U16(d) => check_typed(case, d),
        Voxels::F32(d) => check_typed(case, d),
    }
}

/// Voxel types the checker knows how to turn into bytes.
trait FuzzVoxel: Voxel + Copy + PartialEq + core::fmt::Debug {
    fn push_bytes(self, out: &mut Vec<u8>);
}

impl FuzzVoxel for u8 {
    fn push_bytes(self, out: &mut Vec<u8>) {
        out.push(self);
    }
}

impl FuzzVoxel for u16 {
    fn push_bytes(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_ne_bytes());
    }
}

impl FuzzVoxel for f32 {
    fn push_bytes(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_ne_bytes());
    }
}

/// Same bits, or both NaN: the payload and sign of a NaN that arithmetic makes are not
/// specified by Rust (LLVM may commute operands), so the bit-identity promise stops at NaN.
fn same_f32(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// [`same_f32`] per channel.
fn same_rgba(x: &Rgba, y: &Rgba) -> bool {
    same_f32(x.r, y.r) && same_f32(x.g, y.g) && same_f32(x.b, y.b) && same_f32(x.a, y.a)
}

fn same_lookup(a: &Lookup, b: &Lookup) -> bool {
    match (a, b) {
        (Lookup::Sample(x), Lookup::Sample(y)) => {
            same_f32(x.tau, y.tau) && (0..3).all(|c| same_f32(x.color[c], y.color[c]))
        }
        (Lookup::Empty(x), Lookup::Empty(y)) => x == y,
        _ => false,
    }
}

fn check_typed<V: FuzzVoxel>(case: &VolumeCase, data: &[V]) -> VolumeReport {
    let grid = case.mode == Mode::Grid;

    // Volume construction: InvalidGeometry exactly when documented.
    let (sp, or) = (case.spacing, case.origin);
    // The far corner `origin + (dims - 1) spacing` must be finite too (bounds that overflow).
    let far = or + Vec3::from_array(case.dims.map(|d| d.saturating_sub(1) as f32)) * sp;
    let geometry_ok = sp.is_finite() && sp.x > 0.0 && sp.y > 0.0 && sp.z > 0.0 && or.is_finite() && far.is_finite();
    let vol = match Volume::new(data, case.dims, sp, or) {
        Ok(v) => {
            assert!(geometry_ok, "spacing {sp} origin {or} accepted");
            v
        }
        Err(e) => {
            assert!(
                !geometry_ok,
                "spacing {sp} origin {or} dims {:?} refused: {e}",
                case.dims
            );
            assert_eq!(e, VolumeError::InvalidGeometry);
            Volume::new(data, case.dims, Vec3::ONE, Vec3::ZERO).expect("a valid volume")
        }
    };
    let wrong = [case.dims[0] + 1, case.dims[1].max(1), case.dims[2].max(1)];
    let expected = wrong.iter().map(|&d| d as usize).product::<usize>();
    assert_eq!(
        Volume::new(data, wrong, sp, or).map(|_| ()),
        Err(VolumeError::SizeMismatch {
            expected,
            actual: data.len()
        })
    );
    check_from_bytes(&vol);

    // Transfer function construction.
    let (lo, hi) = case.range;
    let range_ok = lo.is_finite() && hi.is_finite() && lo < hi && (hi - lo).is_finite();
    let bad_entry = case
        .table
        .iter()
        .position(|e| !(e.color.iter().all(|c| c.abs() <= COLOR_MAX) && e.tau >= 0.0 && e.tau <= TAU_MAX));
    let expected = if !range_ok {
        Err(VolumeError::InvalidRange)
    } else if let Some(index) = bad_entry {
        Err(VolumeError::InvalidEntry { index })
    } else {
        Ok(())
    };
    assert_eq!(
        TransferFunction::new(&case.table, lo, hi).map(|_| ()),
        expected,
        "range ({lo}, {hi})"
    );
    assert_eq!(
        TransferFunction::new(&[], lo, hi).map(|_| ()),
        Err(VolumeError::EmptyTable)
    );
    let table: Vec<TfEntry> = case
        .table
        .iter()
        .map(|e| {
            if e.color.iter().all(|c| c.abs() <= COLOR_MAX) && e.tau >= 0.0 && e.tau <= TAU_MAX {
                *e
            } else {
                TfEntry::TRANSPARENT
            }
        })
        .collect();
    let (lo, hi) = if range_ok { (lo, hi) } else { (0.0, 255.0) };
    let tf = TransferFunction::new(&table, lo, hi).expect("a sanitised transfer function");
    check_transfer_function(&tf, &case.values, data);

    // Sampling and lookups without a grid.
    let plain = VolumeMedium::new(vol, tf);
    check_sampler(&vol, &case.points);
    check_lookups(&plain, &plain, &case.points, case.active);

    // Macrocell grid.
    let gp = GridParams { block: case.block };
    let block_ok = case.block.is_power_of_two() && (2..=64).contains(&case.block);
    let built = MacrocellGrid::build(&vol, gp);
    assert_eq!(built.is_ok(), block_ok, "block {}", case.block);
    let mut mgrid = match built {
        Ok(g) => g,
        Err(e) => {
            assert_eq!(e, VolumeError::InvalidBlock);
            MacrocellGrid::build(&vol, GridParams::fine()).expect("a valid block")
        }
    };
    assert_eq!(
        VolumeMedium::new(vol, tf).with_grid(&mgrid).map(|_| ()).unwrap_err(),
        VolumeError::StaleGrid
    );
    check_ranges(&vol, &mgrid);
    mgrid.classify(&tf);
    check_classification(&tf, &mgrid);
    check_stale_and_mismatch(&vol, &tf, &table, &mgrid);
    let skipping = VolumeMedium::new(vol, tf).with_grid(&mgrid).expect("a classified grid");
    assert!(skipping.skips() && !plain.skips());
    check_lookups(&skipping, &plain, &case.points, case.active);

    // Marching parameters.
    let p = case.params;
    let param_check = if !(p.step > 0.0 && p.step.is_finite()) {
        Err(VolumeError::InvalidStep)
    } else if p.termination.is_some_and(|e| !(0.0..1.0).contains(&e)) {
        Err(VolumeError::InvalidTermination)
    } else if p.max_steps == 0 || p.max_steps > MAX_STEPS_LIMIT {
        Err(VolumeError::InvalidMaxSteps)
    } else {
        Ok(())
    };
    assert_eq!(p.validate(), param_check, "{p:?}");
    let p = match param_check {
        Ok(()) => p,
        Err(e) => {
            check_march_error(&plain, &case.rays, &p, e);
            MarchParams {
                step: if p.step > 0.0 && p.step.is_finite() {
                    p.step
                } else {
                    0.5
                },
                termination: p.termination.filter(|e| (0.0..1.0).contains(e)),
                max_steps: if p.max_steps == 0 || p.max_steps > MAX_STEPS_LIMIT {
                    64
                } else {
                    p.max_steps
                },
                ..p
            }
        }
    };
    check_length_mismatch(&plain, &case.rays, &p);

    // March: scalar and x8, plain and skipping.
    let rays = &case.rays;
    let (a, sa) = both(&plain, rays, &p);
    let (b, sb) = both(&skipping, rays, &p);
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(same_rgba(x, y), "ray {i}: plain {x:?} skipping {y:?}");
    }
    assert_eq!(sa.skipped, 0);
    assert_eq!(
        (sa.rays, sa.terminated, sa.truncated),
        (sb.rays, sb.terminated, sb.truncated),
        "{sa:?} {sb:?}"
    );
    assert_eq!(sa.samples, sb.samples + sb.skipped, "{sa:?} {sb:?}");
    assert!(sa.rays <= rays.len() as u64);
    for (i, ray) in rays.iter().enumerate() {
        let one = integrate_ray(&plain, ray, &p).expect("valid parameters");
        assert!(
            one.bit_eq(&a[i]),
            "ray {i}: integrate_ray {one:?} integrate_scalar {:?}",
            a[i]
        );
        if !ray.is_valid() || vol.is_empty() {
            assert!(a[i].bit_eq(&Rgba::ZERO), "ray {i}: {:?}", a[i]);
        }
    }
    if vol.is_empty() {
        assert_eq!(sa, MarchStats::default());
    }

    // Termination: Some(0) equals None bit for bit; Some(eps) within its bound of None.
    let maxc = tf.max_color();
    let sane = maxc <= SANE_COLOUR;
    let full = MarchParams { termination: None, ..p };
    let quality = MarchParams {
        termination: Some(0.0),
        ..p
    };
    let (none, s_none) = match p.termination {
        None => (a.clone(), sa),
        Some(_) => both(&plain, rays, &full),
    };
    if sane {
        let (q, _) = if p.termination == Some(0.0) {
            (a.clone(), sa)
        } else {
            let mut q = vec![Rgba::ZERO; rays.len()];
            let s = integrate(&skipping, rays, &mut q, &quality).expect("valid parameters");
            (q, s)
        };
        for (i, (x, y)) in none.iter().zip(&q).enumerate() {
            assert!(x.bit_eq(y), "ray {i}: no termination {x:?}, Some(0) {y:?}");
        }
    }
    if let Some(eps) = p.termination {
        assert!(sa.samples <= s_none.samples);
        let slack = eps.min(p.max_steps as f32 * f32::EPSILON);
        for (i, (x, y)) in none.iter().zip(&a).enumerate() {
            let da = x.a - y.a;
            assert!(
                (0.0..=(eps + slack) * 1.0001 + 1e-7).contains(&da),
                "ray {i}: eps {eps}: A {} without termination, {} with",
                x.a,
                y.a
            );
            if sane {
                let bound = maxc * ((eps + slack) * 1.0001 + 6e-8) + 1e-30;
                for (cx, cy) in [(x.r, y.r), (x.g, y.g), (x.b, y.b)] {
                    assert!(
                        (cx - cy).abs() <= bound,
                        "ray {i}: eps {eps}: colour {cx} without termination, {cy} with (bound {bound})"
                    );
                }
            }
        }
    }

    // What every result must be.
    let (cmin, cmax) = colour_range(&table);
    let n_max = p.max_steps.min(1 << 16) as f32;
    for (i, x) in a.iter().chain(&none).enumerate() {
        assert!((0.0..=1.0).contains(&x.a), "ray {i}: A {}", x.a);
        if sane {
            let tol = maxc * (2e-6 * (n_max + 2.0) + 1e-6) + 1e-30;
            for (c, v) in [x.r, x.g, x.b].into_iter().enumerate() {
                assert!(v.is_finite(), "ray {i}: colour {x:?}");
                assert!(
                    v >= cmin[c] * x.a - tol && v <= cmax[c] * x.a + tol,
                    "ray {i}: channel {c} = {v} outside [{}, {}] A (A = {})",
                    cmin[c],
                    cmax[c],
                    x.a
                );
            }
        }
    }

    check_preintegrated(&vol, &tf, &table, rays, &p, case.block, sane, &sa);
    if grid {
        check_optical_depth(&vol, &tf, data, case.constant, rays, &full, &none);
    }
    VolumeReport {
        hits: a.iter().filter(|x| x.a > 0.0).count(),
        plain: sa,
        skipping: sb,
        bad_params: param_check.is_err(),
    }
}

/// Pre-integrated marching (a table of `2 + seed % 23` nodes per axis): the entries are means
/// (extinction finite and non-negative, colours within the table's range); scalar and x8 agree bit
/// for bit with the same counters, which match the Riemann marcher's rays, truncations and (without
/// termination) steps; a table for another step is refused; opacity lies in `[0, 1]` and colour in
/// the table's range times `A`; invalid rays and empty volumes give `Rgba::ZERO`.
#[allow(clippy::too_many_arguments)]
fn check_preintegrated<V: FuzzVoxel>(
    vol: &Volume<'_, V>,
    tf: &TransferFunction<'_>,
    table: &[TfEntry],
    rays: &[Ray],
    p: &MarchParams,
    seed: u32,
    sane: bool,
    riemann: &MarchStats,
) {
    let res = 2 + seed % 23;
    let pre = PreintegratedTable::build(tf, p.step, res).expect("a valid step and resolution");
    let (cmin, cmax) = colour_range(table);
    let maxc = tf.max_color();
    for (k, e) in pre.entries().iter().enumerate() {
        assert!(e.tau.is_finite() && e.tau >= 0.0, "entry {k}: {e:?}");
        for c in 0..3 {
            let tol = 1e-6 * maxc + 1e-30;
            assert!(
                e.color[c] >= cmin[c] - tol && e.color[c] <= cmax[c] + tol,
                "entry {k}: {e:?} outside the colours [{cmin:?}, {cmax:?}]"
            );
        }
    }
    let m = PreintegratedMedium::new(*vol, pre.view());
    let other = MarchParams {
        step: if p.step < 1.0 { p.step * 2.0 } else { p.step * 0.5 },
        ..*p
    };
    let mut out = vec![SENTINEL; rays.len()];
    assert_eq!(
        integrate_preintegrated_x8(&m, rays, &mut out, &other),
        Err(VolumeError::StepMismatch)
    );
    assert!(out.iter().all(|x| x.bit_eq(&SENTINEL)), "nothing written on error");
    let mut a = vec![SENTINEL; rays.len() + 1];
    let mut b = vec![SENTINEL; rays.len() + 1];
    let sa = integrate_preintegrated_scalar(&m, rays, &mut a, p).expect("valid parameters");
    let sb = integrate_preintegrated_x8(&m, rays, &mut b, p).expect("valid parameters");
    assert!(a[rays.len()].bit_eq(&SENTINEL) && b[rays.len()].bit_eq(&SENTINEL));
    for (i, (x, y)) in a.iter().zip(&b).take(rays.len()).enumerate() {
        assert!(same_rgba(x, y), "ray {i}: pre-integrated scalar {x:?} x8 {y:?} ({p:?})");
    }
    assert_eq!(sa, sb, "pre-integrated counters");
    assert_eq!((sa.rays, sa.truncated), (riemann.rays, riemann.truncated));
    // Skipping with a grid classified for the table: the same image, the same steps.
    let mut grid = MacrocellGrid::build(vol, GridParams { block: 2 << (seed % 3) }).expect("a valid block");
    assert_eq!(m.with_grid(&grid).map(|_| ()).unwrap_err(), VolumeError::StaleGrid);
    grid.classify_preintegrated(&pre);
    let ms = m.with_grid(&grid).expect("a grid classified for the table");
    let mut c = vec![SENTINEL; rays.len()];
    let mut d = vec![SENTINEL; rays.len()];
    let sc = integrate_preintegrated_scalar(&ms, rays, &mut c, p).expect("valid parameters");
    let sd = integrate_preintegrated_x8(&ms, rays, &mut d, p).expect("valid parameters");
    for (i, ((x, y), z)) in a.iter().zip(&c).zip(&d).enumerate() {
        assert!(
            same_rgba(x, y) && same_rgba(x, z),
            "ray {i}: pre-integrated {x:?}, skipping scalar {y:?}, x8 {z:?}"
        );
    }
    assert_eq!(sc, sd, "pre-integrated skipping counters");
    assert_eq!(sa.samples, sc.samples + sc.skipped);
    assert_eq!(
        (sa.rays, sa.terminated, sa.truncated),
        (sc.rays, sc.terminated, sc.truncated)
    );
    if p.termination.is_none() {
        assert_eq!(sa.samples, riemann.samples);
    }
    let n_max = p.max_steps.min(1 << 16) as f32;
    for (i, (x, ray)) in a.iter().zip(rays).enumerate() {
        assert!((0.0..=1.0).contains(&x.a), "ray {i}: pre-integrated A {}", x.a);
        if !ray.is_valid() || vol.is_empty() {
            assert!(x.bit_eq(&Rgba::ZERO), "ray {i}: {x:?}");
        }
        if sane {
            let tol = maxc * (2e-6 * (n_max + 2.0) + 1e-6) + 1e-30;
            for (c, v) in [x.r, x.g, x.b].into_iter().enumerate() {
                assert!(
                    v.is_finite() && v >= cmin[c] * x.a - tol && v <= cmax[c] * x.a + tol,
                    "ray {i}: pre-integrated channel {c} = {v} outside [{}, {}] A (A = {})",
                    cmin[c],
                    cmax[c],
                    x.a
                );
            }
        }
    }
}

/// `from_bytes` over the voxels' bytes: aligned it gives the same volume, misaligned (for `u16`
/// and `f32`) it is refused, one byte short it is a size mismatch.
fn check_from_bytes<V: FuzzVoxel>(vol: &Volume<'_, V>) {
    let mut bytes = Vec::new();
    for &v in vol.data() {
        v.push_bytes(&mut bytes);
    }
    let align = core::mem::align_of::<V>();
    let mut buf = vec![0u8; bytes.len() + 2 * align];
    let start = (align - buf.as_ptr() as usize % align) % align;
    buf[start..start + bytes.len()].copy_from_slice(&bytes);
    let aligned = &buf[start..start + bytes.len()];
    let v = Volume::<V>::from_bytes(aligned, vol.dims(), vol.spacing(), vol.origin()).expect("aligned bytes");
    assert!(
        v.data()
            .iter()
            .zip(vol.data())
            .all(|(a, b)| a.to_f32().to_bits() == b.to_f32().to_bits())
    );
    assert_eq!(v.data().len(), vol.data().len());
    if !bytes.is_empty() {
        let e = Volume::<V>::from_bytes(&aligned[..bytes.len() - 1], vol.dims(), vol.spacing(), vol.origin())
            .map(|_| ())
            .unwrap_err();
        assert_eq!(
            e,
            VolumeError::SizeMismatch {
                expected: bytes.len(),
                actual: bytes.len() - 1
            }
        );
    }
    if align > 1 && !bytes.is_empty() {
        buf.copy_within(start..start + bytes.len(), start + 1);
        let e = Volume::<V>::from_bytes(
            &buf[start + 1..start + 1 + bytes.len()],
            vol.dims(),
            vol.spacing(),
            vol.origin(),
        )
        .map(|_| ())
        .unwrap_err();
        assert_eq!(e, VolumeError::Misaligned { required: align });
    }
}

/// Lookups x8 against scalar, and `is_transparent` is sound for the values it is asked about.
fn check_transfer_function<V: FuzzVoxel>(tf: &TransferFunction<'_>, values: &[f32; 8], data: &[V]) {
    let mut vs = *values;
    // Also the voxel values themselves (every sample of a constant volume is one of them).
    for (v, d) in vs.iter_mut().skip(5).zip(data) {
        *v = d.to_f32();
    }
    let (tau, col) = tf.lookup_x8(f32x8::new(vs));
    let (tau, col) = (tau.to_array(), col.map(|c| c.to_array()));
    for (l, &s) in vs.iter().enumerate() {
        let (t, c) = tf.lookup_scalar(s);
        assert!(same_f32(t, tau[l]), "lookup of {s}: tau {t} scalar, {} x8", tau[l]);
        for ch in 0..3 {
            assert!(same_f32(c[ch], col[ch][l]), "lookup of {s}: colour {c:?} scalar");
        }
        assert!(t >= 0.0, "lookup of {s}: tau {t}");
    }
    // Soundness of the conservative transparency test over ranges of the probe values.
    for w in vs.windows(2) {
        let (a, b) = (w[0].min(w[1]), w[0].max(w[1]));
        if tf.is_transparent(a, b) {
            for s in [a, b, a + (b - a) * 0.5, a + (b - a) * 0.25] {
                if s >= a && s <= b {
                    assert_eq!(tf.lookup_scalar(s).0, 0.0, "is_transparent({a}, {b}) but tau({s}) > 0");
                }
            }
        }
    }
    // A NaN bound or min > max checks the whole table.
    let all_clear = tf.entries().iter().all(|e| e.tau == 0.0);
    assert_eq!(tf.is_transparent(f32::NAN, 1.0), all_clear);
    assert_eq!(tf.is_transparent(2.0, 1.0), all_clear);
}

/// The x8 sampler equals the scalar one, in world and local coordinates.
fn check_sampler<V: FuzzVoxel>(vol: &Volume<'_, V>, points: &[Vec3; 8]) {
    let soa = |pts: &[Vec3; 8]| -> [f32x8; 3] { core::array::from_fn(|a| f32x8::new(pts.map(|p| p[a]))) };
    let local = vol.sample_local_x8(soa(points)).to_array();
    for (l, p) in points.iter().enumerate() {
        let s = vol.sample_local_scalar(*p);
        assert!(
            same_f32(s, local[l]),
            "local sample at {p}: {s} scalar, {} x8",
            local[l]
        );
    }
    let (o, scale) = vol.local_frame();
    let world: [Vec3; 8] = points.map(|p| p / scale + o);
    let w8 = vol.sample_x8(soa(&world)).to_array();
    for (l, p) in world.iter().enumerate() {
        let s = vol.sample_scalar(*p);
        assert!(same_f32(s, w8[l]), "world sample at {p}: {s} scalar, {} x8", w8[l]);
    }
}

/// `Medium::lookup_x8` against `lookup` lane by lane, and the contract of every empty region
/// (checked against `plain`, the same volume without a grid).
fn check_lookups<V: FuzzVoxel>(m: &VolumeMedium<'_, V>, plain: &VolumeMedium<'_, V>, points: &[Vec3; 8], active: u32) {
    let g: [f32x8; 3] = core::array::from_fn(|a| f32x8::new(points.map(|p| p[a])));
    let mut empty = [EmptyRegion::default(); 8];
    let scalar = points.map(|p| m.lookup(p));
    // The cheap answer the marcher uses while jumping agrees with the full lookup.
    for (p, l) in points.iter().zip(&scalar) {
        let want = match l {
            Lookup::Empty(r) => Some(*r),
            Lookup::Sample(_) => None,
        };
        assert_eq!(m.empty_region(*p), want, "empty_region at {p}");
    }
    match m.lookup_x8(&g, active, &mut empty) {
        Ok(s) => {
            let (tau, col) = (s.tau.to_array(), s.color.map(|c| c.to_array()));
            for l in (0..8).filter(|l| active >> l & 1 == 1) {
                let want = Lookup::Sample(strahl::volume::Sample {
                    tau: tau[l],
                    color: [col[0][l], col[1][l], col[2][l]],
                });
                assert!(
                    same_lookup(&scalar[l], &want),
                    "lane {l}: {:?} scalar, {want:?} x8",
                    scalar[l]
                );
            }
        }
        Err(mask) => {
            assert!(mask != 0 && mask & !active == 0, "mask {mask:#x} active {active:#x}");
            for l in 0..8 {
                if mask >> l & 1 == 1 {
                    assert!(
                        same_lookup(&scalar[l], &Lookup::Empty(empty[l])),
                        "lane {l}: {:?} scalar, empty x8",
                        scalar[l]
                    );
                } else if active >> l & 1 == 1 {
                    assert!(matches!(scalar[l], Lookup::Sample(_)), "lane {l} not in the mask");
                }
            }
        }
    }
    for (p, l) in points.iter().zip(&scalar) {
        if let Lookup::Empty(r) = l {
            assert!(r.safe.contains(&r.exit), "{r:?}");
            let Aabb { min, max } = r.safe;
            let mut probes = vec![*p, (min + max) * 0.5];
            for c in 0..8 {
                probes.push(Vec3::new(
                    if c & 1 == 0 { min.x } else { max.x },
                    if c & 2 == 0 { min.y } else { max.y },
                    if c & 4 == 0 { min.z } else { max.z },
                ));
            }
            for q in probes {
                match plain.lookup(q) {
                    Lookup::Sample(s) => {
                        assert_eq!(s.tau, 0.0, "{q} lies in the safe box of {r:?} but tau = {}", s.tau)
                    }
                    Lookup::Empty(_) => panic!("a medium without a grid reported an empty region"),
                }
            }
        }
    }
}

/// The macrocell ranges against a brute-force min/max over each block's voxels and halo.
fn check_ranges<V: FuzzVoxel, S: AsRef<[Macrocell]>>(vol: &Volume<'_, V>, g: &MacrocellGrid<S>) {
    let d = vol.dims();
    let md = g.macro_dims();
    assert_eq!(g.volume_dims(), d);
    let b = g.block() as usize;
    if vol.is_empty() {
        assert_eq!(md, [0; 3]);
        assert!(g.cells().is_empty());
        return;
    }
    for a in 0..3 {
        let cells = (d[a] as usize).saturating_sub(1).max(1);
        assert_eq!(md[a] as usize, cells.div_ceil(b), "axis {a}");
    }
    let range = |m: usize, n: u32| (m * b).saturating_sub(1)..=((m + 1) * b + 1).min(n as usize - 1);
    for (k, cell) in g.cells().iter().enumerate() {
        let (mx, my, mz) = (
            k % md[0] as usize,
            k / md[0] as usize % md[1] as usize,
            k / (md[0] * md[1]) as usize,
        );
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        let mut finite = true;
        for z in range(mz, d[2]) {
            for y in range(my, d[1]) {
                for x in range(mx, d[0]) {
                    let v = vol.voxel(x as u32, y as u32, z as u32).expect("in the volume").to_f32();
                    finite &= v.is_finite();
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
        let (lo, hi) = if finite {
            (lo, hi)
        } else {
            (f32::NEG_INFINITY, f32::INFINITY)
        };
        assert!(
            cell.min == lo && cell.max == hi && cell.empty == 0,
            "macrocell {k} ({mx}, {my}, {mz}): {cell:?}, brute force ({lo}, {hi})"
        );
    }
}

/// Empty flags follow `is_transparent`; distances are chessboard distances to the nearest
/// non-empty macrocell, capped.
fn check_classification<S: AsRef<[Macrocell]>>(tf: &TransferFunction<'_>, g: &MacrocellGrid<S>) {
    assert_eq!(g.classified_for(), Some(tf.fingerprint()));
    let md = g.macro_dims().map(|d| d as i64);
    let cells = g.cells();
    let at = |k: usize| {
        let k = k as i64;
        [k % md[0], k / md[0] % md[1], k / (md[0] * md[1])]
    };
    let full: Vec<usize> = (0..cells.len()).filter(|&k| cells[k].empty == 0).collect();
    for (k, c) in cells.iter().enumerate() {
        assert_eq!(c.empty != 0, tf.is_transparent(c.min, c.max), "macrocell {k}: {c:?}");
    }
    if cells.len() * full.len() > 50_000 {
        return;
    }
    for (k, c) in cells.iter().enumerate() {
        let a = at(k);
        let want = full
            .iter()
            .map(|&j| {
                let b = at(j);
                (0..3).map(|i| (a[i] - b[i]).unsigned_abs()).max().unwrap_or(0) as u32
            })
            .min()
            .unwrap_or(MAX_EMPTY_RADIUS)
            .min(MAX_EMPTY_RADIUS);
        assert_eq!(c.empty, want, "macrocell {a:?}");
    }
    let frac = if cells.is_empty() {
        0.0
    } else {
        (cells.len() - full.len()) as f32 / cells.len() as f32
    };
    assert_eq!(g.empty_fraction(), frac);
}

/// A grid classified for another transparency pattern is stale, a colour-only change is not, a
/// grid of other dimensions is refused.
fn check_stale_and_mismatch<V: FuzzVoxel, S: AsRef<[Macrocell]>>(
    vol: &Volume<'_, V>,
    tf: &TransferFunction<'_>,
    table: &[TfEntry],
    g: &MacrocellGrid<S>,
) {
    let (lo, hi) = tf.range();
    let mut recoloured = table.to_vec();
    recoloured[0].color = [0.125, 0.75, 0.5];
    let tf_c = TransferFunction::new(&recoloured, lo, hi).expect("valid");
    assert_eq!(tf_c.fingerprint(), tf.fingerprint());
    assert!(VolumeMedium::new(*vol, tf_c).with_grid(g).is_ok());
    let mut toggled = table.to_vec();
    toggled[0].tau = if toggled[0].tau == 0.0 { 1.0 } else { 0.0 };
    let tf_t = TransferFunction::new(&toggled, lo, hi).expect("valid");
    if tf_t.fingerprint() != tf.fingerprint() {
        assert_eq!(
            VolumeMedium::new(*vol, tf_t).with_grid(g).map(|_| ()).unwrap_err(),
            VolumeError::StaleGrid
        );
    }
    let other = [vol.dims()[0] + 1, vol.dims()[1], vol.dims()[2]];
    let zeros = vec![0u8; other.iter().map(|&d| d as usize).product()];
    let ov = Volume::new(&zeros, other, Vec3::ONE, Vec3::ZERO).expect("valid");
    assert_eq!(
        VolumeMedium::new(ov, *tf).with_grid(g).map(|_| ()).unwrap_err(),
        VolumeError::GridMismatch
    );
}

const SENTINEL: Rgba = Rgba {
    r: 9.0,
    g: -7.0,
    b: 1e30,
    a: -3.0,
};

/// Invalid parameters: every entry point returns `e` and writes nothing.
fn check_march_error<M: Medium>(m: &M, rays: &[Ray], p: &MarchParams, e: VolumeError) {
    if let Some(r) = rays.first() {
        assert_eq!(integrate_ray(m, r, p), Err(e));
    }
    for f in [integrate_scalar::<M>, integrate_x8::<M>, integrate::<M>] {
        let mut out = vec![SENTINEL; rays.len()];
        assert_eq!(f(m, rays, &mut out, p), Err(e));
        assert!(out.iter().all(|o| o.bit_eq(&SENTINEL)), "written on error");
    }
}

/// An output slice one short is refused, unwritten.
fn check_length_mismatch<M: Medium>(m: &M, rays: &[Ray], p: &MarchParams) {
    if rays.is_empty() {
        return;
    }
    for f in [integrate_scalar::<M>, integrate_x8::<M>] {
        let mut out = vec![SENTINEL; rays.len() - 1];
        assert_eq!(
            f(m, rays, &mut out, p),
            Err(VolumeError::LengthMismatch {
                rays: rays.len(),
                out: rays.len() - 1
            })
        );
        assert!(out.iter().all(|o| o.bit_eq(&SENTINEL)));
    }
}

/// Marches with both kernels (into slices one longer than the rays, to see that nothing is
/// written past them), checks that they agree bit for bit, counters included.
fn both<M: Medium>(m: &M, rays: &[Ray], p: &MarchParams) -> (Vec<Rgba>, MarchStats) {
    let mut a = vec![SENTINEL; rays.len() + 1];
    let mut b = vec![SENTINEL; rays.len() + 1];
    let sa = integrate_scalar(m, rays, &mut a, p).expect("valid parameters");
    let sb = integrate_x8(m, rays, &mut b, p).expect("valid parameters");
    assert!(a[rays.len()].bit_eq(&SENTINEL) && b[rays.len()].bit_eq(&SENTINEL));
    a.truncate(rays.len());
    b.truncate(rays.len());
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(same_rgba(x, y), "ray {i}: scalar {x:?} x8 {y:?} ({p:?})");
    }
    assert_eq!(sa, sb, "counters");
    assert!(sa.terminated <= sa.rays && sa.truncated <= sa.rays);
    (a, sa)
}

/// Per channel, the least and largest colour of the table.
fn colour_range(table: &[TfEntry]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for e in table {
        for c in 0..3 {
            lo[c] = lo[c].min(e.color[c]);
            hi[c] = hi[c].max(e.color[c]);
        }
    }
    (lo, hi)
}

/// The ray clipped to `b` in f64: `Some(length)` if it overlaps (0 for a clear miss), `None`
/// where the answer is ambiguous (in a face plane, touching, or at a range bound).
fn clip_length(ray: &Ray, b: &Aabb) -> Option<f64> {
    let o = ray.origin.to_array().map(f64::from);
    let d = ray.direction.to_array().map(f64::from);
    let (lo, hi) = (b.min.to_array().map(f64::from), b.max.to_array().map(f64::from));
    let dl = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let (mut near, mut far) = (f64::from(ray.tmin), f64::from(ray.tmax));
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] == lo[a] || o[a] == hi[a] {
                return None;
            }
            if o[a] < lo[a] || o[a] > hi[a] {
                return Some(0.0);
            }
        } else {
            let (t0, t1) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
        }
    }
    if !(near.is_finite() && far.is_finite()) {
        return None;
    }
    let len = (far - near) * dl;
    let scale = 1e-4 * (1.0 + near.abs() * dl + far.abs() * dl);
    if len.abs() < scale { None } else { Some(len.max(0.0)) }
}

/// Grid mode: `A` between the optical depths of the least and largest extinction over the
/// ray's length in the box (the closed form for a constant volume), `C = c A` for a constant one,
/// and misses give nothing.
fn check_optical_depth<V: FuzzVoxel>(
    vol: &Volume<'_, V>,
    tf: &TransferFunction<'_>,
    data: &[V],
    constant: bool,
    rays: &[Ray],
    p: &MarchParams,
    out: &[Rgba],
) {
    if vol.is_empty() {
        return;
    }
    let b = vol.bounds();
    let diag = f64::from(b.extent().length());
    let (tau_lo, tau_hi, colour) = if constant {
        let (t, c) = tf.lookup_scalar(data[0].to_f32());
        (t, t, Some(c))
    } else {
        let t = tf.entries().iter().map(|e| e.tau);
        (t.clone().fold(f32::INFINITY, f32::min), t.fold(0.0, f32::max), None)
    };
    let dt = f64::from(p.step);
    for (i, (ray, x)) in rays.iter().zip(out).enumerate() {
        if !ray.is_valid() {
            continue;
        }
        let Some(len) = clip_length(ray, &b) else { continue };
        let len = len.min(diag);
        if len == 0.0 {
            assert!(x.bit_eq(&Rgba::ZERO), "ray {i} misses the box but gave {x:?}");
            continue;
        }
        let q = len / dt;
        if (q - f64::from(p.max_steps)).abs() < 1e-3 * q.max(1.0) {
            continue; // at the truncation threshold
        }
        let l_eff = len.min(f64::from(p.max_steps) * dt);
        let n = (l_eff / dt).ceil() + 1.0;
        let tol = 2e-6 * (n + 2.0) + 2e-5;
        let a_lo = 1.0 - (-f64::from(tau_lo) * l_eff).exp();
        let a_hi = 1.0 - (-f64::from(tau_hi) * l_eff).exp();
        let a = f64::from(x.a);
        assert!(
            a >= a_lo - tol && a <= a_hi + tol,
            "ray {i}: A = {a}, expected within [{a_lo}, {a_hi}] (L = {l_eff}, tau in [{tau_lo}, {tau_hi}], {p:?})"
        );
        if let Some(c) = colour {
            for (ch, v) in [x.r, x.g, x.b].into_iter().enumerate() {
                let want = f64::from(c[ch]) * a;
                assert!(
                    (f64::from(v) - want).abs() <= tol * f64::from(c[ch].abs().max(1.0)),
                    "ray {i}: channel {ch} = {v}, c A = {want}"
                );
            }
        }
    }
}
