//! Volume rendering against closed forms (Max 1995's emission-absorption model), the observed
//! convergence order (Etiene et al. 2014), SIMD against the scalar reference, skipping and
//! termination against marching everything, and bad input.

mod common;

use common::{bounded, raw, vec3};
use proptest::prelude::*;
use strahl::volume::*;
use strahl::{Aabb, Ray, Vec3};

// ---------------------------------------------------------------------------------------------
// Helpers

/// A medium in the slab `[-1, 1] x [-1, 1] x [0, depth]` whose extinction and colour depend on z
/// only; rays along +z from `z = -1` sample it at `z = s` exactly.
struct Slab<F: Fn(f32) -> (f32, [f32; 3])> {
    f: F,
    depth: f32,
}

impl<F: Fn(f32) -> (f32, [f32; 3])> Medium for Slab<F> {
    fn bounds(&self) -> Aabb {
        Aabb::new(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, self.depth))
    }
    fn lookup(&self, g: Vec3) -> Lookup {
        let (tau, color) = (self.f)(g.z);
        Lookup::Sample(Sample { tau, color })
    }
}

fn down_z(x: f32, y: f32) -> Ray {
    Ray::new(Vec3::new(x, y, -1.0), Vec3::Z)
}

fn params(step: f32, sampling: Sampling) -> MarchParams {
    MarchParams {
        sampling,
        ..MarchParams::reference(step)
    }
}

/// Marches with both kernels, checks they agree bit for bit, returns the scalar results.
fn both<M: Medium>(m: &M, rays: &[Ray], p: &MarchParams) -> (Vec<Rgba>, MarchStats) {
    let mut a = vec![Rgba::ZERO; rays.len()];
    let mut b = vec![Rgba { r: 9.0, ..Rgba::ZERO }; rays.len()];
    let sa = integrate_scalar(m, rays, &mut a, p).unwrap();
    let sb = integrate_x8(m, rays, &mut b, p).unwrap();
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(x.bit_eq(y), "ray {i}: scalar {x:?} x8 {y:?}");
    }
    assert_eq!(sa, sb);
    (a, sb)
}

fn one<M: Medium>(m: &M, ray: Ray, p: &MarchParams) -> Rgba {
    both(m, &[ray], p).0[0]
}

/// Least-squares slope of log(err) against log(dt).
fn slope(pts: &[(f64, f64)]) -> f64 {
    let n = pts.len() as f64;
    let (lx, ly): (Vec<f64>, Vec<f64>) = pts.iter().map(|&(x, y)| (x.ln(), y.ln())).unzip();
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx) * (x - mx)).sum();
    sxy / sxx
}

/// A `n^3` u8 volume over `[0, 1]^3`: a ball of radius `r` (in `[0, 1]` units) around
/// `(0.5, 0.5, 0.5)`, 255 at the centre falling linearly to 0 at its surface, 0 outside.
fn ball(n: u32, r: f32) -> Vec<u8> {
    let mut v = Vec::with_capacity((n * n * n) as usize);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = Vec3::new(i as f32, j as f32, k as f32) / (n - 1) as f32 - Vec3::splat(0.5);
                v.push((255.0 * (1.0 - p.length() / r)).clamp(0.0, 255.0) as u8);
            }
        }
    }
    v
}

fn unit_volume<V: Voxel>(data: &[V], n: u32) -> Volume<'_, V> {
    Volume::new(data, [n; 3], Vec3::splat(1.0 / (n - 1) as f32), Vec3::ZERO).unwrap()
}

/// Rays through the unit cube from several directions, some grazing, some missing.
fn test_rays(count: usize) -> Vec<Ray> {
    let mut s = 0x9e37_79b9_u32;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        s as f32 / u32::MAX as f32
    };
    (0..count)
        .map(|_| {
            let o = Vec3::new(rnd() * 3.0 - 1.0, rnd() * 3.0 - 1.0, -1.5);
            let target = Vec3::new(rnd(), rnd(), rnd()) * 1.2 - Vec3::splat(0.1);
            Ray::new(o, target - o)
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Accuracy against closed forms

#[test]
fn constant_medium_is_exact_at_every_step() {
    let data = [200u8; 64];
    let vol = unit_volume(&data, 4);
    let c = [0.3f32, 0.6, 0.9];
    let table = [TfEntry::new(c, 1.7)];
    let m = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 255.0).unwrap());
    let rays = [
        (down_z(0.5, 0.5), 1.0f64),
        (Ray::new(Vec3::new(-1.0, -1.0, -1.0), Vec3::ONE), 3f64.sqrt()),
        (Ray::new(Vec3::new(0.25, -1.0, 0.5), Vec3::new(0.0, 2.0, 0.0)), 1.0),
        // Starts inside: from (0.5, 0.5, 0.2) to the z = 1 face.
        (Ray::new(Vec3::new(0.5, 0.5, 0.2), Vec3::Z), 0.8),
    ];
    for step in [0.01f32, 0.07, 0.1, 0.3, 1.0, 5.0] {
        for sampling in [Sampling::Endpoint, Sampling::Midpoint] {
            for &(ray, len) in &rays {
                let p = one(&m, ray, &params(step, sampling));
                let want = 1.0 - (-1.7 * len).exp();
                let n = (len / step as f64).ceil();
                let tol = 1e-6 * (n + 2.0);
                assert!((p.a as f64 - want).abs() < tol, "step {step}: A {} want {want}", p.a);
                for (got, c) in [p.r, p.g, p.b].into_iter().zip(c) {
                    assert!((got - c * p.a).abs() < tol as f32, "C = c A");
                }
            }
        }
    }
}

/// Front-to-back compositing of homogeneous segments `(length, tau, colour)`, in f64.
fn segments_closed_form(segs: &[(f64, f64, [f64; 3])]) -> [f64; 4] {
    let (mut c, mut t) = ([0.0; 3], 1.0);
    for &(l, tau, col) in segs {
        let a = 1.0 - (-tau * l).exp();
        for i in 0..3 {
            c[i] += t * a * col[i];
        }
        t *= 1.0 - a;
    }
    [c[0], c[1], c[2], 1.0 - t]
}

#[test]
fn piecewise_constant_segments_aligned_with_the_steps_are_exact() {
    let segs = [
        (0.25, 2.0, [1.0, 0.0, 0.0]),
        (0.25, 0.0, [0.0, 0.0, 0.0]),
        (0.375, 5.0, [0.0, 1.0, 0.0]),
        (0.125, 0.5, [0.0, 0.0, 1.0]),
    ];
    let medium = Slab {
        f: |z: f32| {
            let (mut start, mut i) = (0.0, 0);
            while i + 1 < segs.len() && z >= start + segs[i].0 as f32 {
                start += segs[i].0 as f32;
                i += 1;
            }
            let (_, tau, c) = segs[i];
            (tau as f32, c.map(|x| x as f32))
        },
        depth: 1.0,
    };
    let want = segments_closed_form(&segs);
    for e in 3..=8 {
        let dt = 0.5f32.powi(e);
        for sampling in [Sampling::Endpoint, Sampling::Midpoint] {
            let p = one(&medium, down_z(0.1, -0.3), &params(dt, sampling));
            let got = [p.r, p.g, p.b, p.a];
            for i in 0..4 {
                assert!(
                    (got[i] as f64 - want[i]).abs() < 2e-6 * (1 << e) as f64,
                    "dt 2^-{e} {sampling:?} ch {i}: {} want {}",
                    got[i],
                    want[i]
                );
            }
        }
    }
}

/// An f32 volume whose value is z (spacing 1/16 along z), and a two-entry transfer function from
/// tau = a at 0 to a + b at 1: along a ray down z, tau = a + b t.
fn ramp_volume() -> Vec<f32> {
    let mut d = vec![0.0f32; 2 * 2 * 17];
    for k in 0..17 {
        for i in 0..4 {
            d[k * 4 + i] = k as f32 / 16.0;
        }
    }
    d
}

#[test]
fn linear_ramp_optical_depth() {
    let (a, b) = (0.5f64, 3.0f64);
    let data = ramp_volume();
    let vol = Volume::new(&data, [2, 2, 17], Vec3::new(1.0, 1.0, 1.0 / 16.0), Vec3::ZERO).unwrap();
    let c = [0.2f32, 0.4, 0.8];
    let table = [TfEntry::new(c, a as f32), TfEntry::new(c, (a + b) as f32)];
    let m = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 1.0).unwrap());
    let ray = down_z(0.3, 0.7);
    let depth = a + b / 2.0; // a L + b L^2 / 2 with L = 1
    // Midpoint sampling is exact for a linear integrand, also with a partial last step.
    for dt in [0.5f32, 0.3, 0.125, 0.07, 1.0 / 64.0] {
        let p = one(&m, ray, &params(dt, Sampling::Midpoint));
        assert!(
            (p.a as f64 - (1.0 - (-depth).exp())).abs() < 2e-6,
            "midpoint dt {dt}: {}",
            p.a
        );
        assert!((p.b - 0.8 * p.a).abs() < 1e-6);
    }
    // Endpoint sampling (left sums) misses exactly b L dt / 2 of optical depth when dt divides L.
    for e in 2..=6 {
        let dt = 0.5f64.powi(e);
        let p = one(&m, ray, &params(dt as f32, Sampling::Endpoint));
        let want = 1.0 - (-(depth - b * dt / 2.0)).exp();
        assert!(
            (p.a as f64 - want).abs() < 2e-6,
            "endpoint dt {dt}: {} want {want}",
            p.a
        );
    }
}

const TAU0: f32 = 3.0;
const SCALE_H: f32 = 0.4;

fn exp_depth(l: f64) -> f64 {
    TAU0 as f64 * SCALE_H as f64 * (1.0 - (-l / SCALE_H as f64).exp())
}

#[test]
fn exponential_density_optical_depth() {
    let m = Slab {
        f: |z: f32| (TAU0 * libm::expf(-z / SCALE_H), [1.0, 0.5, 0.25]),
        depth: 1.0,
    };
    let want = 1.0 - (-exp_depth(1.0)).exp();
    let p = one(&m, down_z(0.0, 0.0), &params(1.0 / 256.0, Sampling::Midpoint));
    // Midpoint rule: error at most L dt^2 / 24 max|tau''| = 1.2e-5 in optical depth.
    assert!((p.a as f64 - want).abs() < 2e-5, "{} want {want}", p.a);
    assert!((p.g - 0.5 * p.a).abs() < 1e-6);

    // The same through a volume: exp(-z/h) sampled every 1/128 and a linear transfer function;
    // trilinear interpolation adds at most dz^2 / 8 max|f''| = 5e-5 relative in tau.
    let n = 129;
    let mut data = vec![0.0f32; 2 * 2 * n];
    for k in 0..n {
        for i in 0..4 {
            data[k * 4 + i] = libm::expf(-(k as f32 / (n - 1) as f32) / SCALE_H);
        }
    }
    let vol = Volume::new(&data, [2, 2, n as u32], Vec3::new(1.0, 1.0, 1.0 / 128.0), Vec3::ZERO).unwrap();
    let table = [TfEntry::new([1.0; 3], 0.0), TfEntry::new([1.0; 3], TAU0)];
    let vm = VolumeMedium::new(vol, TransferFunction::new(&table, 0.0, 1.0).unwrap());
    let p = one(&vm, down_z(0.5, 0.5), &params(1.0 / 256.0, Sampling::Midpoint));
    assert!((p.a as f64 - want).abs() < 2e-4, "{} want {want}", p.a);
}

/// Etiene et al. 2014: refine the step, fit the slope of log(error) against log(dt).
#[test]
fn observed_convergence_order() {
    // Exponential atmosphere with colour varying in depth, so both A and C have smooth integrands.
    let m = Slab {
        f: |z: f32| (TAU0 * libm::expf(-z / SCALE_H), [1.0 - 0.5 * z, 0.5, 0.25]),
        depth: 1.0,
    };
    let a_exact = 1.0 - (-exp_depth(1.0)).exp();
    // C_red = int_0^1 (1 - z/2) tau(z) exp(-depth(z)) dz, by composite Simpson in f64.
    let f = |z: f64| (1.0 - z / 2.0) * TAU0 as f64 * (-z / SCALE_H as f64).exp() * (-exp_depth(z)).exp();
    let n = 20_000;
    let hz = 1.0 / n as f64;
    let simpson: f64 = (0..=n)
        .map(|i| {
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            w * f(i as f64 * hz)
        })
        .sum::<f64>()
        * hz
        / 3.0;
    for (sampling, lo, hi) in [(Sampling::Endpoint, 0.9, 1.1), (Sampling::Midpoint, 1.85, 2.15)] {
        let (mut ea, mut ec) = (vec![], vec![]);
        for e in 2..=7 {
            let dt = 0.5f64.powi(e);
            let p = one(&m, down_z(0.0, 0.0), &params(dt as f32, sampling));
            ea.push((dt, (p.a as f64 - a_exact).abs()));
            ec.push((dt, (p.r as f64 - simpson).abs()));
        }
        let (sa, sc) = (slope(&ea), slope(&ec));
        println!("{sampling:?}: order {sa:.3} (A), {sc:.3} (C); errors {ea:?}");
        assert!((lo..hi).contains(&sa), "{sampling:?} order in A: {sa}");
        assert!((lo..hi).contains(&sc), "{sampling:?} order in C: {sc}");
    }
}

// ---------------------------------------------------------------------------------------------
// SIMD against scalar, skipping and termination against marching everything

fn ball_tf() -> [TfEntry; 8] {
    let mut t = [TfEntry::TRANSPARENT; 8];
    for (i, e) in t.iter_mut().enumerate().skip(3) {
        *e = TfEntry::new([i as f32 / 8.0, 1.0 - i as f32 / 8.0, 0.5], i as f32 * 1.5);
    }
    t
}

/// A medium that only answers `lookup`, passing it on: the marchers go through the trait's
/// default `lookup_x8` and `empty_region`.
struct ScalarOnly<'a, M: Medium>(&'a M);

impl<M: Medium> Medium for ScalarOnly<'_, M> {
    fn bounds(&self) -> Aabb {
        self.0.bounds()
    }
    fn local_frame(&self) -> (Vec3, Vec3) {
        self.0.local_frame()
    }
    fn lookup(&self, g: Vec3) -> Lookup {
        self.0.lookup(g)
    }
}

/// A medium whose `lookup_x8` breaks its contract: of the empty lanes it reports only the
/// lowest, and it samples nothing then. `lookup_x8_partial`'s default must still give the right
/// answer for every lane (it falls back to `lookup`, one lane at a time).
struct Stingy<'a, M: Medium>(&'a M);

impl<M: Medium> Medium for Stingy<'_, M> {
    fn bounds(&self) -> Aabb {
        self.0.bounds()
    }
    fn local_frame(&self) -> (Vec3, Vec3) {
        self.0.local_frame()
    }
    fn lookup(&self, g: Vec3) -> Lookup {
        self.0.lookup(g)
    }
    fn lookup_x8(
        &self,
        g: &[strahl::math::f32x8; 3],
        active: u32,
        empty: &mut [EmptyRegion; 8],
    ) -> Result<SampleX8, u32> {
        self.0
            .lookup_x8(g, active, empty)
            .map_err(|mask| mask & mask.wrapping_neg())
    }
}

/// Skipping through the trait's defaults: `ScalarOnly` gets the default `lookup_x8` (one lookup
/// per lane, empty lanes reported together) and `lookup_x8_partial` (which asks again for the
/// other lanes); `Stingy` reaches the partial lookup's per-lane fallback. Both give the image and
/// counters of the scalar marcher and of the medium's own `lookup_x8`.
#[test]
fn skipping_through_the_trait_defaults() {
    fn same<M: Medium>(want: &(Vec<Rgba>, MarchStats), m: &M, rays: &[Ray], p: &MarchParams, what: &str) {
        let (b, sb) = both(m, rays, p);
        assert_eq!(want.1, sb, "{what}");
        assert!(sb.skipped > 0, "{what}");
        for (i, (x, y)) in want.0.iter().zip(&b).enumerate() {
            assert!(x.bit_eq(y), "{what} ray {i}: {x:?} vs {y:?}");
        }
    }
    let n = 48;
    let data = ball(n, 0.3);
    let vol = unit_volume(&data, n);
    let table = ball_tf();
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    let rays = test_rays(600);
    for block in [2, 4, 8] {
        let mut grid = MacrocellGrid::build(&vol, GridParams { block }).unwrap();
        grid.classify(&tf);
        let skipping = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
        for p in [params(0.013, Sampling::Midpoint), params(0.02, Sampling::Endpoint)] {
            let want = both(&skipping, &rays, &p);
            same(
                &want,
                &ScalarOnly(&skipping),
                &rays,
                &p,
                &format!("default, block {block}"),
            );
            same(&want, &Stingy(&skipping), &rays, &p, &format!("stingy, block {block}"));
        }
    }
}

#[test]
fn skipping_leaves_the_image_unchanged_bit_for_bit() {
    let n = 48;
    let data = ball(n, 0.3);
    let vol = unit_volume(&data, n);
    let table = ball_tf();
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    let plain = VolumeMedium::new(vol, tf);
    let rays = test_rays(600);
    for block in [2, 4, 8, 16, 64] {
        let mut grid = MacrocellGrid::build(&vol, GridParams { block }).unwrap();
        grid.classify(&tf);
        // With blocks of 64 the single block holds the ball: nothing to skip, nothing changes.
        let sparse = block < 64;
        assert!(
            !sparse || grid.empty_fraction() > 0.3,
            "block {block}: {}",
            grid.empty_fraction()
        );
        let skipping = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
        for p in [
            params(0.013, Sampling::Midpoint),
            params(0.02, Sampling::Endpoint),
            MarchParams::fast(0.011),
        ] {
            let (a, sa) = both(&plain, &rays, &p);
            let (b, sb) = both(&skipping, &rays, &p);
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                assert!(x.bit_eq(y), "block {block} ray {i}: {x:?} vs {y:?}");
            }
            assert!(!sparse || (sb.skipped > 0 && sb.samples < sa.samples), "{sa:?} {sb:?}");
            assert!(a.iter().any(|x| x.a > 0.5));
        }
    }
}

#[test]
fn regrid_after_transfer_function_change() {
    let n = 32;
    let data = ball(n, 0.3);
    let vol = unit_volume(&data, n);
    let t1 = ball_tf();
    let tf1 = TransferFunction::new(&t1, 0.0, 255.0).unwrap();
    // t2 makes the low values (the shell of the ball and beyond) visible: more non-empty blocks.
    let mut t2 = t1;
    t2[1] = TfEntry::new([0.0, 0.0, 1.0], 0.7);
    let tf2 = TransferFunction::new(&t2, 0.0, 255.0).unwrap();
    // A colour-only change keeps the classification.
    let mut t3 = t1;
    t3[5].color = [1.0, 1.0, 1.0];
    let tf3 = TransferFunction::new(&t3, 0.0, 255.0).unwrap();

    let mut grid = MacrocellGrid::build(&vol, GridParams::fine()).unwrap();
    assert_eq!(
        VolumeMedium::new(vol, tf1).with_grid(&grid).unwrap_err(),
        VolumeError::StaleGrid
    );
    grid.classify(&tf1);
    let before = grid.empty_fraction();
    assert!(VolumeMedium::new(vol, tf3).with_grid(&grid).is_ok());
    assert_eq!(
        VolumeMedium::new(vol, tf2).with_grid(&grid).unwrap_err(),
        VolumeError::StaleGrid
    );
    grid.classify(&tf2);
    assert!(grid.empty_fraction() < before);
    let rays = test_rays(300);
    let p = params(0.02, Sampling::Midpoint);
    let (a, _) = both(&VolumeMedium::new(vol, tf2), &rays, &p);
    let (b, _) = both(&VolumeMedium::new(vol, tf2).with_grid(&grid).unwrap(), &rays, &p);
    assert!(a.iter().zip(&b).all(|(x, y)| x.bit_eq(y)));
    // A grid of another volume is refused.
    let small = unit_volume(&data[..8], 2);
    assert_eq!(
        VolumeMedium::new(small, tf2).with_grid(&grid).unwrap_err(),
        VolumeError::GridMismatch
    );
}

#[test]
fn early_termination_stays_within_its_bound() {
    let n = 32;
    let data = ball(n, 0.45);
    let vol = unit_volume(&data, n);
    let rays = test_rays(400);
    let base = MarchParams::reference(0.01);
    // A dense medium (step opacity up to 0.47) and an opaque one (up to 0.998).
    for (gain, opaque) in [(6.0, false), (60.0, true)] {
        let mut table = ball_tf();
        for e in &mut table[3..] {
            e.tau *= gain;
            e.color = [e.color[0] * 2.0, e.color[1], 0.3];
        }
        let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
        let maxc = tf.max_color();
        let m = VolumeMedium::new(vol, tf);
        let (full, s_full) = both(&m, &rays, &base);
        // Termination at A == 1 only is exact; it fires in the opaque medium.
        let (exact, s_exact) = both(&m, &rays, &MarchParams::quality(0.01));
        assert!(full.iter().zip(&exact).all(|(x, y)| x.bit_eq(y)));
        if opaque {
            assert!(
                s_exact.terminated > 0 && s_exact.samples < s_full.samples,
                "{s_exact:?}"
            );
        }
        for eps in [1e-4f32, 1.0 / 256.0, 0.05, 0.3] {
            let (t, st) = both(
                &m,
                &rays,
                &MarchParams {
                    termination: Some(eps),
                    ..base
                },
            );
            assert!(st.terminated > 0 && st.samples < s_full.samples);
            for (x, y) in full.iter().zip(&t) {
                let bound = eps * maxc + 1e-6;
                assert!((x.r - y.r).abs() <= bound && (x.g - y.g).abs() <= bound && (x.b - y.b).abs() <= bound);
                assert!((x.a - y.a).abs() <= eps + 1e-6);
            }
        }
    }
}

fn arb_case() -> impl Strategy<Value = (Vec<u8>, [u32; 3], Vec<TfEntry>, Vec<Ray>, MarchParams, u32)> {
    let dims = (1u32..7, 1u32..7, 1u32..7);
    let entry = prop_oneof![
        Just(TfEntry::TRANSPARENT),
        (0.0f32..1.0, 0.0f32..1.0, 0.0f32..20.0).prop_map(|(r, g, t)| TfEntry::new([r, g, 0.5], t)),
    ];
    let ray = prop_oneof![
        3 => (vec3(-3.0f32..4.0), vec3(bounded())).prop_map(|(o, d)| Ray::new(o, d)),
        1 => (vec3(raw()), vec3(raw()), raw(), raw()).prop_map(|(o, d, t0, t1)| Ray::with_range(o, d, t0, t1)),
    ];
    let p = (
        0.01f32..1.5,
        any::<bool>(),
        prop_oneof![Just(None), Just(Some(0.0)), (0.0f32..0.9).prop_map(Some)],
        prop_oneof![4 => Just(DEFAULT_MAX_STEPS), 1 => 1u32..50],
    )
        .prop_map(|(step, mid, termination, max_steps)| MarchParams {
            step,
            sampling: if mid { Sampling::Midpoint } else { Sampling::Endpoint },
            termination,
            max_steps,
        });
    dims.prop_flat_map(move |(x, y, z)| {
        let n = (x * y * z) as usize;
        (
            proptest::collection::vec(prop_oneof![3 => Just(0u8), 1 => any::<u8>()], n),
            Just([x, y, z]),
            proptest::collection::vec(entry.clone(), 1..9),
            proptest::collection::vec(ray.clone(), 1..40),
            p.clone(),
            prop_oneof![Just(2u32), Just(4)],
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// x8 equals scalar bit for bit, and skipping changes nothing, on random volumes, transfer
    /// functions, rays (including special values) and parameters.
    #[test]
    fn x8_scalar_and_skipping_agree((data, dims, table, rays, p, block) in arb_case()) {
        let vol = Volume::new(&data, dims, Vec3::new(0.5, 0.25, 0.75), Vec3::new(0.1, -0.2, 0.3)).unwrap();
        let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
        let plain = VolumeMedium::new(vol, tf);
        let (a, _) = both(&plain, &rays, &p);
        let mut grid = MacrocellGrid::build(&vol, GridParams { block }).unwrap();
        grid.classify(&tf);
        let skipping = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
        let (b, _) = both(&skipping, &rays, &p);
        for (x, y) in a.iter().zip(&b) {
            prop_assert!(x.bit_eq(y), "{:?} vs {:?}", x, y);
            prop_assert!((0.0..=1.0).contains(&x.a));
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Bad input: a defined result or a clear error, never a panic or a hang

fn small_medium(data: &[u8]) -> VolumeMedium<'_, u8> {
    static TABLE: [TfEntry; 2] = [TfEntry::new([1.0; 3], 0.5), TfEntry::new([1.0; 3], 4.0)];
    VolumeMedium::new(unit_volume(data, 4), TransferFunction::new(&TABLE, 0.0, 255.0).unwrap())
}

#[test]
fn bad_steps_are_errors() {
    let data = [100u8; 64];
    let m = small_medium(&data);
    let rays = [down_z(0.5, 0.5)];
    let mut out = [Rgba { r: 7.0, ..Rgba::ZERO }];
    for step in [0.0, -0.0, -0.1, f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let p = MarchParams::reference(step);
        assert_eq!(integrate_ray(&m, &rays[0], &p), Err(VolumeError::InvalidStep));
        assert_eq!(integrate_scalar(&m, &rays, &mut out, &p), Err(VolumeError::InvalidStep));
        assert_eq!(integrate_x8(&m, &rays, &mut out, &p), Err(VolumeError::InvalidStep));
        assert_eq!(out[0].r, 7.0, "nothing written on error");
    }
    for eps in [f32::NAN, -0.1, 1.0, 2.0] {
        let p = MarchParams {
            termination: Some(eps),
            ..MarchParams::reference(0.1)
        };
        assert_eq!(
            integrate_x8(&m, &rays, &mut out, &p),
            Err(VolumeError::InvalidTermination)
        );
    }
    for max_steps in [0, MAX_STEPS_LIMIT + 1] {
        let p = MarchParams {
            max_steps,
            ..MarchParams::reference(0.1)
        };
        assert_eq!(
            integrate_scalar(&m, &rays, &mut out, &p),
            Err(VolumeError::InvalidMaxSteps)
        );
    }
    assert_eq!(
        integrate_x8(&m, &[rays[0]; 2], &mut out, &MarchParams::reference(0.1)),
        Err(VolumeError::LengthMismatch { rays: 2, out: 1 })
    );
}

#[test]
fn degenerate_and_missing_rays_are_transparent() {
    let data = [100u8; 64];
    let m = small_medium(&data);
    let o = Vec3::new(0.5, 0.5, -1.0);
    let rays = [
        Ray::with_range(Vec3::splat(0.5), Vec3::Z, 0.2, 0.2), // zero length inside
        Ray::with_range(o, Vec3::Z, 1.5, 1.5),
        Ray::with_range(o, Vec3::Z, 1.7, 1.2), // tmin > tmax
        Ray::with_range(o, Vec3::Z, 0.0, 0.5), // ends before the volume
        Ray::new(o, Vec3::ZERO),
        Ray::new(Vec3::new(f32::NAN, 0.5, -1.0), Vec3::Z),
        Ray::new(o, Vec3::new(0.0, f32::INFINITY, 1.0)),
        Ray::new(Vec3::new(2.0, 0.5, -1.0), Vec3::Z), // misses
        Ray::new(Vec3::new(0.5, 0.5, 2.0), Vec3::Z),  // volume behind
        Ray::new(Vec3::new(1.0, 0.5, -1.0), Vec3::new(1e-3, 0.0, 1.0)), // grazes the x = 1 face outward
        Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::new(0.0, 0.0, 1e-30)), // tiny direction is fine
    ];
    let (out, _) = both(&m, &rays, &MarchParams::reference(0.05));
    for (i, p) in out.iter().enumerate().take(rays.len() - 2) {
        assert!(p.bit_eq(&Rgba::ZERO), "ray {i}: {p:?}");
    }
    assert!(out[9].a < 0.01); // enters only at the corner edge region, if at all
    assert!(out[10].a > 0.5, "a short direction is still a valid ray");
}

#[test]
fn far_start_where_t_plus_dt_equals_t() {
    let data = ball(16, 0.45);
    let table = ball_tf();
    let m = VolumeMedium::new(
        unit_volume(&data, 16),
        TransferFunction::new(&table, 0.0, 255.0).unwrap(),
    );
    let dt = 0.01f32;
    assert_eq!(1.0e7f32 + dt, 1.0e7f32);
    let p = MarchParams::reference(dt);
    // Marching restarts at the entry point, so the far start costs nothing here.
    let near = one(&m, Ray::new(Vec3::new(0.5, 0.5, -2.0), Vec3::Z), &p);
    let far = one(&m, Ray::new(Vec3::new(0.5, 0.5, -1.0e7), Vec3::Z), &p);
    assert!(near.a > 0.1);
    assert!(near.bit_eq(&far), "{near:?} {far:?}");
    // So far out that the entry point itself is lost: still a prompt, defined, bounded result.
    let start = std::time::Instant::now();
    for o in [-1.0e30f32, -3.0e38] {
        for d in [Vec3::Z, Vec3::new(1e-30, 0.0, 1.0), Vec3::new(0.0, 0.0, 3.0e38)] {
            let r = one(&m, Ray::new(Vec3::new(0.5, 0.5, o), d), &p);
            assert!(
                r.a.is_finite() && (0.0..=1.0).contains(&r.a) && r.r.is_finite(),
                "{r:?}"
            );
        }
    }
    assert!(start.elapsed().as_secs() < 5);
}

#[test]
fn infinite_ranges_and_step_caps() {
    let data = [120u8; 64];
    let m = small_medium(&data);
    let p = MarchParams::reference(0.05);
    let o = Vec3::new(0.5, 0.5, -1.0);
    let a = one(&m, Ray::new(o, Vec3::Z), &p);
    let b = one(&m, Ray::with_range(o, Vec3::Z, f32::NEG_INFINITY, f32::INFINITY), &p);
    assert!(a.bit_eq(&b) && a.a > 0.5);
    // A tiny step with the default cap: bounded work, counted as truncated.
    let tiny = MarchParams::reference(1e-9);
    let (out, st) = both(&m, &[Ray::new(o, Vec3::Z); 3], &tiny);
    assert_eq!(st.truncated, 3);
    assert_eq!(st.samples, 3 * DEFAULT_MAX_STEPS as u64);
    assert!(out[0].a > 0.0 && out[0].a < a.a);
    let capped = MarchParams {
        max_steps: 5,
        ..MarchParams::reference(0.01)
    };
    let (_, st) = both(&m, &[Ray::new(o, Vec3::Z)], &capped);
    assert_eq!((st.samples, st.truncated), (5, 1));
}

#[test]
fn empty_volume_and_transparent_transfer_function() {
    let table = [TfEntry::new([1.0; 3], 1.0)];
    let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    let rays = test_rays(50);
    for dims in [[0, 0, 0], [0, 5, 5], [3, 0, 1]] {
        let vol = Volume::<f32>::new(&[], dims, Vec3::ONE, Vec3::ZERO).unwrap();
        let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
        grid.classify(&tf);
        for m in [
            VolumeMedium::new(vol, tf),
            VolumeMedium::new(vol, tf).with_grid(&grid).unwrap(),
        ] {
            let (out, st) = both(&m, &rays, &MarchParams::reference(0.1));
            assert!(out.iter().all(|p| p.bit_eq(&Rgba::ZERO)));
            assert_eq!(st.samples, 0);
        }
    }
    // All-zero opacity: transparent, and with a grid nothing is even sampled.
    let data = ball(16, 0.4);
    let vol = unit_volume(&data, 16);
    let clear = [TfEntry::new([1.0, 0.0, 0.0], 0.0); 4];
    let tf = TransferFunction::new(&clear, 0.0, 255.0).unwrap();
    let mut grid = MacrocellGrid::build(&vol, GridParams::default()).unwrap();
    grid.classify(&tf);
    assert_eq!(grid.empty_fraction(), 1.0);
    let (out, st) = both(&VolumeMedium::new(vol, tf), &rays, &MarchParams::reference(0.05));
    assert!(out.iter().all(|p| p.bit_eq(&Rgba::ZERO)) && st.samples > 0);
    let (out, st) = both(
        &VolumeMedium::new(vol, tf).with_grid(&grid).unwrap(),
        &rays,
        &MarchParams::reference(0.05),
    );
    assert!(out.iter().all(|p| p.bit_eq(&Rgba::ZERO)));
    assert_eq!(st.samples, 0);
    assert!(st.skipped > 0);
}

#[test]
fn non_finite_voxels_are_defined() {
    let mut data = [0.5f32; 64];
    data[21] = f32::NAN;
    data[22] = f32::INFINITY;
    data[42] = f32::NEG_INFINITY;
    let vol = unit_volume(&data, 4);
    let table = [TfEntry::new([0.0, 1.0, 0.0], 0.0), TfEntry::new([1.0, 0.0, 0.0], 2.0)];
    let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    let mut grid = MacrocellGrid::build(&vol, GridParams { block: 2 }).unwrap();
    grid.classify(&tf);
    let rays = test_rays(200);
    let p = MarchParams::reference(0.02);
    let (a, _) = both(&VolumeMedium::new(vol, tf), &rays, &p);
    let (b, _) = both(&VolumeMedium::new(vol, tf).with_grid(&grid).unwrap(), &rays, &p);
    for (x, y) in a.iter().zip(&b) {
        assert!(x.bit_eq(y));
        assert!(x.r.is_finite() && x.g.is_finite() && (0.0..=1.0).contains(&x.a));
    }
}

#[test]
fn zero_copy_from_bytes() {
    let words: Vec<u32> = (0..8).map(|i| (i as f32 * 0.25).to_bits()).collect();
    let bytes: &[u8] = bytemuck::cast_slice(&words);
    let v = Volume::<f32>::from_bytes(bytes, [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    assert_eq!(v.data().as_ptr() as usize, bytes.as_ptr() as usize);
    assert_eq!(v.voxel(1, 1, 1), Some(1.75));
    let v16 = Volume::<u16>::from_bytes(&bytes[..16], [2, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    assert_eq!(v16.data().len(), 8);
    for (off, ty) in [(1usize, 2usize), (2, 4)] {
        let r = if ty == 2 {
            Volume::<u16>::from_bytes(&bytes[off..off + 16], [2, 2, 2], Vec3::ONE, Vec3::ZERO).map(|_| ())
        } else {
            Volume::<f32>::from_bytes(&bytes[off..off + 8], [2, 1, 1], Vec3::ONE, Vec3::ZERO).map(|_| ())
        };
        let e = r.unwrap_err();
        assert_eq!(e, VolumeError::Misaligned { required: ty });
        assert!(e.to_string().contains("aligned"));
    }
    let e: Box<dyn std::error::Error> = Box::new(VolumeError::StaleGrid);
    assert!(e.to_string().contains("classify"));
}

// ---------------------------------------------------------------------------------------------
// Pre-integrated transfer functions (Engel, Kraus and Ertl 2001)

/// Marches with both pre-integrated kernels, checks they agree bit for bit (results and
/// counters), returns the scalar results.
fn both_pre<V: Voxel>(m: &PreintegratedMedium<'_, V>, rays: &[Ray], p: &MarchParams) -> (Vec<Rgba>, MarchStats) {
    let mut a = vec![Rgba::ZERO; rays.len()];
    let mut b = vec![Rgba { r: 9.0, ..Rgba::ZERO }; rays.len()];
    let sa = integrate_preintegrated_scalar(m, rays, &mut a, p).unwrap();
    let sb = integrate_preintegrated_x8(m, rays, &mut b, p).unwrap();
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(x.bit_eq(y), "ray {i}: scalar {x:?} x8 {y:?}");
    }
    assert_eq!(sa, sb);
    (a, sb)
}

/// A transfer function with spikes narrower than one entry apart: zero entries, one-entry peaks
/// of high extinction, colour changing at every entry.
fn spiky_table(n: usize) -> Vec<TfEntry> {
    (0..n)
        .map(|i| {
            let tau = match i % 6 {
                0 | 3 => 0.0,
                1 => 2.5,
                2 => 0.2,
                4 => 6.0,
                _ => 0.7,
            };
            let t = i as f32 / n as f32;
            TfEntry::new([t, (3.0 * t).sin().abs(), 1.0 - t], tau)
        })
        .collect()
}

/// Max's model along a path where the transfer function's value runs as `s(x)` for `x` in
/// `[0, len]`, in `f64` by the midpoint rule with `steps` steps (second order: with the steps used
/// here, far below the `f32` rounding the marchers are held to).
fn max_model_f64(table: &[TfEntry], lo: f64, hi: f64, s: impl Fn(f64) -> f64, len: f64, steps: usize) -> [f64; 4] {
    let n = table.len();
    let at = |v: f64| {
        let u = ((v - lo) / (hi - lo) * (n - 1) as f64).clamp(0.0, (n - 1) as f64);
        let j = (u as usize).min(n - 2);
        let w = u - j as f64;
        let l = |a: f32, b: f32| a as f64 + (b as f64 - a as f64) * w;
        let (e0, e1) = (&table[j], &table[j + 1]);
        (l(e0.tau, e1.tau), [0, 1, 2].map(|k| l(e0.color[k], e1.color[k])))
    };
    let h = len / steps as f64;
    let (mut col, mut acc) = ([0.0f64; 3], 0.0f64);
    for k in 0..steps {
        let (tau, c) = at(s((k as f64 + 0.5) * h));
        let w = (1.0 - acc) * -(-tau * h).exp_m1();
        for ch in 0..3 {
            col[ch] += w * c[ch];
        }
        acc += w;
    }
    [col[0], col[1], col[2], acc]
}

fn err4(a: &Rgba, b: [f64; 4]) -> f64 {
    [a.r, a.g, a.b, a.a]
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - y).abs())
        .fold(0.0, f64::max)
}

/// The scalar runs linearly along every step and the step ends fall on table nodes: pre-integration
/// is exact (to `f32` rounding) at a step of a whole voxel, where the midpoint rule, which samples
/// between the spikes, is far off.
#[test]
fn preintegration_is_exact_for_a_linear_scalar() {
    let n = 24u32;
    // Voxel value i at x = i (constant in y and z): linear along x.
    let data: Vec<f32> = (0..n * 4).map(|i| (i % n) as f32).collect();
    let vol = Volume::new(&data, [n, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    let table = spiky_table(n as usize);
    let tf = TransferFunction::new(&table, 0.0, (n - 1) as f32).unwrap();
    let reference = max_model_f64(&table, 0.0, (n - 1) as f64, |x| x, (n - 1) as f64, 200_000);
    for (dir, origin) in [
        (Vec3::X, Vec3::new(-1.0, 0.5, 0.5)),
        (-Vec3::X, Vec3::new(n as f32, 0.5, 0.5)),
    ] {
        let ray = Ray::new(origin, dir);
        let pre = PreintegratedTable::build(&tf, 1.0, n).unwrap();
        let m = PreintegratedMedium::new(vol, pre.view());
        let (out, st) = both_pre(&m, &[ray], &MarchParams::reference(1.0));
        assert_eq!(st.samples, (n - 1) as u64);
        // Backwards the value runs from n - 1 down to 0: the reference with s(x) = n - 1 - x.
        let want = if dir.x > 0.0 {
            reference
        } else {
            max_model_f64(
                &table,
                0.0,
                (n - 1) as f64,
                |x| (n - 1) as f64 - x,
                (n - 1) as f64,
                200_000,
            )
        };
        let e = err4(&out[0], want);
        assert!(e < 2e-6, "pre-integrated error {e:e}: {:?} vs {want:?}", out[0]);
        // The Riemann marcher at the same step is nowhere near.
        let riemann = one(&VolumeMedium::new(vol, tf), ray, &MarchParams::reference(1.0));
        let er = err4(&riemann, want);
        println!("linear scalar, step 1 voxel, dir {dir}: pre-integrated error {e:.2e}, midpoint {er:.2e}");
        assert!(
            er > 1000.0 * e.max(1e-7),
            "midpoint error {er:e} vs pre-integrated {e:e}"
        );
    }
}

/// A constant scalar on a table node: the closed form `A = 1 - exp(-tau L)`, `C = c A` at every
/// step, the last (shorter) step included. (Off the nodes, the bilinear lookup blends in the
/// neighbouring segments' means: the resolution test below.)
#[test]
fn preintegration_of_a_constant_field_is_exact() {
    let table = spiky_table(12);
    let tf = TransferFunction::new(&table, 0.0, 1.0).unwrap();
    let data = [0.4f32; 27];
    let vol = Volume::new(&data, [3, 3, 3], Vec3::splat(0.5), Vec3::ZERO).unwrap();
    let (tau, c) = tf.lookup_scalar(0.4);
    let ray = Ray::new(Vec3::new(0.3, 0.6, -1.0), Vec3::Z);
    let a = -(-(tau as f64)).exp_m1(); // length 1
    let want = [c[0] as f64 * a, c[1] as f64 * a, c[2] as f64 * a, a];
    for step in [0.07f32, 0.3, 0.5, 1.0, 2.5] {
        // 0.4 is node 2 of 6, 4 of 11 and 20 of 51.
        for res in [6u32, 11, 51] {
            let pre = PreintegratedTable::build(&tf, step, res).unwrap();
            let m = PreintegratedMedium::new(vol, pre.view());
            let (out, _) = both_pre(&m, &[ray], &MarchParams::reference(step));
            let e = err4(&out[0], want);
            assert!(e < 2e-6, "step {step} res {res}: error {e:e}");
        }
    }
}

/// Where the step ends fall between table nodes the table's bilinear interpolation adds an error,
/// which falls as the resolution grows.
#[test]
fn preintegration_error_falls_with_the_table_resolution() {
    let n = 32u32;
    // s = 0.37 x + 0.11 (voxel units), over a transfer function on [0, 12].
    let data: Vec<f32> = (0..n * 4).map(|i| 0.37 * (i % n) as f32 + 0.11).collect();
    let vol = Volume::new(&data, [n, 2, 2], Vec3::ONE, Vec3::ZERO).unwrap();
    let table = spiky_table(13);
    let tf = TransferFunction::new(&table, 0.0, 12.0).unwrap();
    let want = max_model_f64(&table, 0.0, 12.0, |x| 0.37 * x + 0.11, (n - 1) as f64, 100_000);
    let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X);
    let step = 1.5f32;
    let errs: Vec<f64> = [16u32, 64, 256]
        .iter()
        .map(|&res| {
            let pre = PreintegratedTable::build(&tf, step, res).unwrap();
            let m = PreintegratedMedium::new(vol, pre.view());
            err4(&both_pre(&m, &[ray], &MarchParams::reference(step)).0[0], want)
        })
        .collect();
    println!(
        "off-node linear scalar, step 1.5: errors at res 16/64/256 {:.2e} {:.2e} {:.2e}",
        errs[0], errs[1], errs[2]
    );
    assert!(errs[2] < errs[1] && errs[1] < errs[0], "{errs:?}");
    assert!(errs[2] < 2e-3, "{errs:?}");
    let riemann = one(&VolumeMedium::new(vol, tf), ray, &MarchParams::reference(step));
    println!("  midpoint at the same step: {:.2e}", err4(&riemann, want));
    assert!(
        err4(&riemann, want) > 5.0 * errs[2],
        "{errs:?} vs midpoint {:e}",
        err4(&riemann, want)
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// x8 equals scalar bit for bit on random volumes, transfer functions, table resolutions,
    /// rays (including special values) and parameters; opacity stays in [0, 1].
    #[test]
    fn preintegrated_x8_equals_scalar((data, dims, table, rays, p, block) in arb_case()) {
        let vol = Volume::new(&data, dims, Vec3::new(0.5, 0.25, 0.75), Vec3::new(0.1, -0.2, 0.3)).unwrap();
        let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
        let pre = PreintegratedTable::build(&tf, p.step, 2 + 7 * block).unwrap();
        let (out, _) = both_pre(&PreintegratedMedium::new(vol, pre.view()), &rays, &p);
        for x in &out {
            prop_assert!((0.0..=1.0).contains(&x.a) && x.r.is_finite() && x.g.is_finite() && x.b.is_finite(), "{:?}", x);
        }
    }
}

/// Empty-space skipping with a grid classified for the table: the same image bit for bit, the
/// same steps (marched + skipped), on a sparse volume and on random cases; grids classified for
/// anything else are refused.
#[test]
fn preintegrated_skipping_leaves_the_image_unchanged() {
    let data = ball(32, 0.3);
    let vol = unit_volume(&data, 32);
    let table = ball_tf();
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    let rays = test_rays(300);
    for (step, res, block) in [(0.02f32, 64u32, 4u32), (0.05, 8, 2), (0.005, 256, 8), (0.3, 33, 8)] {
        let pre = PreintegratedTable::build(&tf, step, res).unwrap();
        let mut grid = MacrocellGrid::build(&vol, GridParams { block }).unwrap();
        grid.classify(&tf);
        let plain = PreintegratedMedium::new(vol, pre.view());
        assert_eq!(plain.with_grid(&grid).unwrap_err(), VolumeError::StaleGrid);
        let other = PreintegratedTable::build(&tf, step, res + 1).unwrap();
        grid.classify_preintegrated(&other);
        assert_eq!(plain.with_grid(&grid).unwrap_err(), VolumeError::StaleGrid);
        grid.classify_preintegrated(&pre);
        assert!(grid.empty_fraction() > 0.2, "{}", grid.empty_fraction());
        let skipping = plain.with_grid(&grid).unwrap();
        assert!(skipping.skips() && !plain.skips());
        for p in [MarchParams::reference(step), MarchParams::fast(step)] {
            let (a, sa) = both_pre(&plain, &rays, &p);
            let (b, sb) = both_pre(&skipping, &rays, &p);
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                assert!(x.bit_eq(y), "step {step} res {res} ray {i}: {x:?} vs {y:?}");
            }
            assert_eq!(sa.skipped, 0);
            assert!(sb.skipped > 0);
            assert_eq!(sa.samples, sb.samples + sb.skipped);
            assert_eq!(
                (sa.rays, sa.terminated, sa.truncated),
                (sb.rays, sb.terminated, sb.truncated)
            );
        }
    }
    let small = MacrocellGrid::build(&unit_volume(&data[..4096], 16), GridParams::default()).unwrap();
    let pre = PreintegratedTable::build(&tf, 0.1, 16).unwrap();
    assert_eq!(
        PreintegratedMedium::new(vol, pre.view()).with_grid(&small).unwrap_err(),
        VolumeError::GridMismatch
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Skipping changes nothing on random volumes, transfer functions, resolutions, blocks and rays.
    #[test]
    fn preintegrated_skipping_agrees((data, dims, table, rays, p, block) in arb_case()) {
        let vol = Volume::new(&data, dims, Vec3::new(0.5, 0.25, 0.75), Vec3::new(0.1, -0.2, 0.3)).unwrap();
        let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
        let pre = PreintegratedTable::build(&tf, p.step, 2 + 5 * block).unwrap();
        let mut grid = MacrocellGrid::build(&vol, GridParams { block }).unwrap();
        grid.classify_preintegrated(&pre);
        let plain = PreintegratedMedium::new(vol, pre.view());
        let (a, sa) = both_pre(&plain, &rays, &p);
        let (b, sb) = both_pre(&plain.with_grid(&grid).unwrap(), &rays, &p);
        for (x, y) in a.iter().zip(&b) {
            prop_assert!(x.bit_eq(y), "{:?} vs {:?}", x, y);
        }
        prop_assert_eq!(sa.samples, sb.samples + sb.skipped);
    }
}

#[test]
fn preintegrated_bad_input() {
    let data = [100u8; 64];
    let vol = unit_volume(&data, 4);
    let table = [TfEntry::new([1.0; 3], 0.5), TfEntry::new([1.0; 3], 4.0)];
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    for step in [0.0, -0.0, -0.1, f32::NAN, f32::INFINITY] {
        assert_eq!(
            PreintegratedTable::build(&tf, step, 8).unwrap_err(),
            VolumeError::InvalidStep
        );
    }
    let pre = PreintegratedTable::build(&tf, 0.1, 8).unwrap();
    let m = PreintegratedMedium::new(vol, pre.view());
    let rays = [down_z(0.5, 0.5)];
    let mut out = [Rgba { r: 7.0, ..Rgba::ZERO }];
    for (p, e) in [
        (MarchParams::reference(0.0), VolumeError::InvalidStep),
        (MarchParams::reference(f32::NAN), VolumeError::InvalidStep),
        (MarchParams::reference(0.2), VolumeError::StepMismatch),
        (
            MarchParams::reference(f32::from_bits(0.1f32.to_bits() + 1)),
            VolumeError::StepMismatch,
        ),
    ] {
        assert_eq!(integrate_preintegrated_scalar(&m, &rays, &mut out, &p), Err(e));
        assert_eq!(integrate_preintegrated_x8(&m, &rays, &mut out, &p), Err(e));
        assert_eq!(out[0].r, 7.0, "nothing written on error");
    }
    assert!(VolumeError::StepMismatch.to_string().contains("step"));
    assert_eq!(
        integrate_preintegrated(&m, &[rays[0]; 2], &mut out, &MarchParams::reference(0.1)),
        Err(VolumeError::LengthMismatch { rays: 2, out: 1 })
    );
    // Degenerate, missing and non-finite rays: transparent; a tiny step: capped work.
    let o = Vec3::new(0.5, 0.5, -1.0);
    let odd = [
        Ray::with_range(Vec3::splat(0.5), Vec3::Z, 0.2, 0.2),
        Ray::new(o, Vec3::ZERO),
        Ray::new(Vec3::new(f32::NAN, 0.5, -1.0), Vec3::Z),
        Ray::new(o, Vec3::new(0.0, f32::INFINITY, 1.0)),
        Ray::new(Vec3::new(2.0, 0.5, -1.0), Vec3::Z),
    ];
    let (out, st) = both_pre(&m, &odd, &MarchParams::reference(0.1));
    assert!(out.iter().all(|p| p.bit_eq(&Rgba::ZERO)) && st.samples == 0);
    let tiny = PreintegratedTable::build(&tf, 1e-9, 4).unwrap();
    let capped = PreintegratedMedium::new(vol, tiny.view());
    let (out, st) = both_pre(&capped, &[down_z(0.5, 0.5)], &MarchParams::reference(1e-9));
    assert_eq!((st.samples, st.truncated), (DEFAULT_MAX_STEPS as u64, 1));
    assert!(out[0].a > 0.0);
    // An empty volume and an all-zero opacity: transparent.
    let empty = Volume::<u8>::new(&[], [0, 3, 3], Vec3::ONE, Vec3::ZERO).unwrap();
    let (out, _) = both_pre(
        &PreintegratedMedium::new(empty, pre.view()),
        &test_rays(20),
        &MarchParams::reference(0.1),
    );
    assert!(out.iter().all(|p| p.bit_eq(&Rgba::ZERO)));
    let clear = [TfEntry::new([1.0, 0.0, 0.0], 0.0); 4];
    let tf0 = TransferFunction::new(&clear, 0.0, 255.0).unwrap();
    let pre0 = PreintegratedTable::build(&tf0, 0.05, 16).unwrap();
    let ball_data = ball(16, 0.4);
    let (out, st) = both_pre(
        &PreintegratedMedium::new(unit_volume(&ball_data, 16), pre0.view()),
        &test_rays(50),
        &MarchParams::reference(0.05),
    );
    assert!(out.iter().all(|p| p.bit_eq(&Rgba::ZERO)) && st.samples > 0);
}

// ---- Media that stretch the `lookup_x8_partial` contract (written in review of the pipelined
// x8 marchers, 2026-12-04).

/// Looks every lane up one at a time, like the wrapped medium, but puts NaN in the sample lanes it
/// does not sample, writes a junk region (a box of 1e9) into every lane it does not report empty,
/// and reports every lane it was not asked about as empty: the marchers may use only what the
/// contract promises (the samples of the asked lanes it did not report, the regions of the lanes
/// it did).
struct Garbage<'a, M: Medium>(&'a M);
impl<M: Medium> Medium for Garbage<'_, M> {
    fn bounds(&self) -> Aabb {
        self.0.bounds()
    }
    fn local_frame(&self) -> (Vec3, Vec3) {
        self.0.local_frame()
    }
    fn lookup(&self, g: Vec3) -> Lookup {
        self.0.lookup(g)
    }
    fn prefetch_x8(&self, g: &[strahl::math::f32x8; 3]) {
        self.0.prefetch_x8(g)
    }
    fn lookup_x8_partial(
        &self,
        g: &[strahl::math::f32x8; 3],
        active: u32,
        empty: &mut [EmptyRegion; 8],
    ) -> (SampleX8, u32) {
        let (x, y, z) = (g[0].to_array(), g[1].to_array(), g[2].to_array());
        let junk = EmptyRegion {
            exit: Aabb::new(Vec3::splat(-1e9), Vec3::splat(1e9)),
            safe: Aabb::new(Vec3::splat(-1e9), Vec3::splat(1e9)),
        };
        let (mut tau, mut col, mut skip) = ([f32::NAN; 8], [[f32::NAN; 8]; 3], 0u32);
        for l in 0..8 {
            if active >> l & 1 == 0 {
                empty[l] = junk;
                skip |= 1 << l;
                continue;
            }
            match self.0.lookup(Vec3::new(x[l], y[l], z[l])) {
                Lookup::Sample(s) => {
                    tau[l] = s.tau;
                    for (c, sc) in col.iter_mut().zip(s.color) {
                        c[l] = sc;
                    }
                    empty[l] = junk;
                }
                Lookup::Empty(r) => {
                    empty[l] = r;
                    skip |= 1 << l;
                }
            }
        }
        (
            SampleX8 {
                tau: strahl::math::f32x8::new(tau),
                color: col.map(strahl::math::f32x8::new),
            },
            skip,
        )
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    /// Random volumes, tables, rays and parameters: the x8 marchers through `Garbage` and
    /// `Stingy` equal the plain medium's, bit for bit, counters too; the pre-integrated x8
    /// marcher equals its scalar reference with and without a grid.
    #[test]
    fn junk_in_unused_lanes_changes_nothing((data, dims, table, rays, p, block) in arb_case()) {
        let vol = Volume::new(&data, dims, Vec3::new(0.5, 0.25, 0.75), Vec3::new(0.1, -0.2, 0.3)).unwrap();
        let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
        let mut grid = MacrocellGrid::build(&vol, GridParams { block }).unwrap();
        grid.classify(&tf);
        let skipping = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
        let (a, sa) = both(&skipping, &rays, &p);
        let (b, sb) = both(&Garbage(&skipping), &rays, &p);
        let (c, sc) = both(&Stingy(&skipping), &rays, &p);
        prop_assert_eq!(sa, sb);
        prop_assert_eq!(sa, sc);
        for ((x, y), z) in a.iter().zip(&b).zip(&c) {
            prop_assert!(x.bit_eq(y) && x.bit_eq(z));
        }
        let pre = PreintegratedTable::build(&tf, p.step, 16).unwrap();
        grid.classify_preintegrated(&pre);
        for m in [
            PreintegratedMedium::new(vol, pre.view()),
            PreintegratedMedium::new(vol, pre.view()).with_grid(&grid).unwrap(),
        ] {
            let mut o1 = vec![Rgba::ZERO; rays.len()];
            let mut o2 = vec![Rgba { r: 9.0, ..Rgba::ZERO }; rays.len()];
            let s1 = integrate_preintegrated_scalar(&m, &rays, &mut o1, &p).unwrap();
            let s2 = integrate_preintegrated_x8(&m, &rays, &mut o2, &p).unwrap();
            prop_assert_eq!(s1, s2);
            for (x, y) in o1.iter().zip(&o2) {
                prop_assert!(x.bit_eq(y), "{:?} {:?}", x, y);
            }
        }
    }
}

/// Batches of 0 to 300 rays (NaN and zero-direction ones among them) at every block size, step,
/// sampling, termination and step cap: every adversarial medium gives the plain medium's images
/// and counters, and the pre-integrated x8 marcher its scalar reference's.
#[test]
fn every_setting_through_adversarial_media() {
    let n = 40;
    let data = ball(n, 0.3);
    let vol = unit_volume(&data, n);
    let table = ball_tf();
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    let mut total = MarchStats::default();
    for count in [0usize, 1, 3, 7, 8, 9, 17, 300] {
        let mut rays = test_rays(count);
        if count > 5 {
            rays[2] = Ray::new(Vec3::splat(f32::NAN), Vec3::Z);
            rays[4] = Ray::new(Vec3::splat(0.5), Vec3::ZERO);
        }
        for block in [2, 4, 8] {
            let mut grid = MacrocellGrid::build(&vol, GridParams { block }).unwrap();
            grid.classify(&tf);
            let skipping = VolumeMedium::new(vol, tf).with_grid(&grid).unwrap();
            for step in [0.007f32, 0.013, 0.05, 0.3] {
                for s in [Sampling::Midpoint, Sampling::Endpoint] {
                    for term in [None, Some(0.0), Some(0.01), Some(0.5), Some(0.95)] {
                        for ms in [DEFAULT_MAX_STEPS, 7] {
                            let p = MarchParams {
                                step,
                                sampling: s,
                                termination: term,
                                max_steps: ms,
                            };
                            let (a, sa) = both(&skipping, &rays, &p);
                            let (b, sb) = both(&Garbage(&skipping), &rays, &p);
                            let (c, sc) = both(&Stingy(&skipping), &rays, &p);
                            let (d, sd) = both(&ScalarOnly(&skipping), &rays, &p);
                            assert_eq!(sa, sb);
                            assert_eq!(sa, sc);
                            assert_eq!(sa, sd);
                            for i in 0..a.len() {
                                assert!(a[i].bit_eq(&b[i]) && a[i].bit_eq(&c[i]) && a[i].bit_eq(&d[i]));
                            }
                            total.skipped += sa.skipped;
                            total.terminated += sa.terminated;
                            total.samples += sa.samples;
                            let pre = PreintegratedTable::build(&tf, step, 32).unwrap();
                            let mut g2 = MacrocellGrid::build(&vol, GridParams { block }).unwrap();
                            g2.classify_preintegrated(&pre);
                            for m in [
                                PreintegratedMedium::new(vol, pre.view()),
                                PreintegratedMedium::new(vol, pre.view()).with_grid(&g2).unwrap(),
                            ] {
                                let mut o1 = vec![Rgba::ZERO; rays.len()];
                                let mut o2 = vec![Rgba { r: 9.0, ..Rgba::ZERO }; rays.len()];
                                let s1 = integrate_preintegrated_scalar(&m, &rays, &mut o1, &p).unwrap();
                                let s2 = integrate_preintegrated_x8(&m, &rays, &mut o2, &p).unwrap();
                                assert_eq!(s1, s2, "{p:?}");
                                for (x, y) in o1.iter().zip(&o2) {
                                    assert!(x.bit_eq(y));
                                }
                                total.skipped += s1.skipped;
                            }
                        }
                    }
                }
            }
        }
    }
    assert!(
        total.skipped > 0 && total.terminated > 0 && total.samples > 0,
        "{total:?}"
    );
}

/// A procedural medium: empty stripes whose exit boxes are sometimes wider than their safe boxes
/// (so jumps get refused), and, with `nan`, NaN extinction in a corner.
struct Stripes {
    nan: bool,
}
impl Medium for Stripes {
    fn bounds(&self) -> Aabb {
        Aabb::new(Vec3::ZERO, Vec3::ONE)
    }
    fn lookup(&self, g: Vec3) -> Lookup {
        let c = (g.x * 7.0).floor();
        if (c as i32) % 2 == 0 && g.y < 0.8 {
            let lo = Vec3::new(c / 7.0, 0.0, 0.0);
            let hi = Vec3::new((c + 1.0) / 7.0, 0.8, 1.0);
            // exit sometimes wider than safe -> refused jumps
            let exit = if g.z > 0.5 {
                Aabb::new(lo, hi + Vec3::X * 0.05)
            } else {
                Aabb::new(lo, hi)
            };
            Lookup::Empty(EmptyRegion {
                exit,
                safe: Aabb::new(lo, hi),
            })
        } else {
            let tau = if self.nan && g.z > 0.93 && g.x < 0.3 {
                f32::NAN
            } else {
                3.0 * g.z + g.y * 40.0 * (g.x - 0.5).abs()
            };
            Lookup::Sample(Sample {
                tau,
                color: [g.x, g.y, g.z],
            })
        }
    }
}

/// `Stripes` marched directly, through `Garbage` and through `Stingy`: the same images and
/// counters.
#[test]
fn refused_jumps_and_nan_extinction_through_adversarial_media() {
    for count in [1usize, 5, 8, 13, 200] {
        let rays = test_rays(count);
        for nan in [false, true] {
            let m = Stripes { nan };
            for step in [0.004f32, 0.011, 0.07] {
                for s in [Sampling::Midpoint, Sampling::Endpoint] {
                    for term in [None, Some(0.0), Some(0.02), Some(0.7)] {
                        let p = MarchParams {
                            step,
                            sampling: s,
                            termination: term,
                            max_steps: DEFAULT_MAX_STEPS,
                        };
                        let (a, sa) = both(&m, &rays, &p);
                        let (b, sb) = both(&Garbage(&m), &rays, &p);
                        let (c, sc) = both(&Stingy(&m), &rays, &p);
                        assert_eq!(sa, sb);
                        assert_eq!(sa, sc);
                        assert!(sa.skipped > 0 || count < 8);
                        for i in 0..a.len() {
                            assert!(a[i].bit_eq(&b[i]) && a[i].bit_eq(&c[i]));
                        }
                    }
                }
            }
        }
    }
}

/// An axis of 2^24 + 4 voxels: `dims - 1 = 16777219` rounds up to 16777220 in `f32`, so the box
/// reaches past the last voxel. The clamp to the edge there must read the last voxel (the cell's
/// fraction is capped at 1), not extrapolate (200 from voxels 0 and 100, which once made the
/// marcher see what the grid had classified empty, so skipping changed the image).
#[test]
fn long_axis_clamp_reads_the_last_voxel() {
    let d = (1u32 << 24) + 4;
    let mut data = vec![0u8; d as usize];
    data[d as usize - 1] = 100;
    let vol = Volume::new(&data, [d, 1, 1], Vec3::ONE, Vec3::ZERO).unwrap();
    assert_eq!(vol.sample_local_scalar(Vec3::new(1.0e9, 0.0, 0.0)), 100.0);
    assert_eq!(vol.sample_local_scalar(vol.bounds().max), 100.0);
    let far = [Vec3::new(1.0e9, 0.0, 0.0); 8];
    let x8 = vol.sample_local_x8([0, 1, 2].map(|a| strahl::math::f32x8::from(far.map(|p| p[a]))));
    assert_eq!(x8.to_array(), [100.0; 8]);
    // No voxel exceeds 100, so the table is transparent everywhere the volume's values reach.
    let table = [TfEntry::TRANSPARENT, TfEntry::TRANSPARENT, TfEntry::new([1.0; 3], 50.0)];
    let tf = TransferFunction::new(&table, 0.0, 255.0).unwrap();
    let mut grid = MacrocellGrid::build(&vol, GridParams { block: 64 }).unwrap();
    grid.classify(&tf);
    let rays = [Ray::new(Vec3::new(16_777_200.0, 0.0, 0.0), Vec3::X)];
    let p = MarchParams::reference(0.25);
    let plain = both(&VolumeMedium::new(vol, tf), &rays, &p).0[0];
    let skipping = both(&VolumeMedium::new(vol, tf).with_grid(&grid).unwrap(), &rays, &p).0[0];
    assert!(
        plain.bit_eq(&skipping),
        "grid changed the image: {plain:?} vs {skipping:?}"
    );
    assert_eq!(plain.a, 0.0, "no voxel is visible through this table");
}
