//! The report: run time against error for every trade-off the crate offers, measured on this
//! machine and written as one Markdown page with SVG plots.
//!
//! ```text
//! cargo run --release --example report [-- OUT_DIR]      # default OUT_DIR: out/report
//! ```
//!
//! Writes `OUT_DIR/report.md` and the plots beside it (`OUT_DIR/*.svg`); progress goes to
//! stderr. Every number on the page comes from this run: nothing is copied in. Sections:
//!
//! 1. ray/triangle: Möller-Trumbore against watertight (ns per test, false misses on rays aimed at
//!    the edges and vertices of a closed mesh, `t` error against the `f64` reference);
//! 2. BVH2 builders: build time against SAH cost and against trace time (scalar BVH2, BVH8);
//! 3. 30- against 63-bit Morton codes (LBVH, HLBVH), with a scene where 30-bit codes collide;
//! 4. volume marching: step size and sampling rule against the error to a closed form;
//! 5. early ray termination: threshold against image error and its documented bound;
//! 6. empty-space skipping block size, and the packet/single-ray switch of packet traversal.
//!
//! Single thread throughout; each time is the median of several repetitions
//! (`std::time::Instant`). The scenes and rays are those of the benches and tests that measure
//! the same things (`benches/time_vs_error.rs`, `benches/build.rs`, `benches/volume.rs`,
//! `benches/packet.rs`, `tests/volume.rs`), so the numbers can be compared.

#[path = "../benches/common/mod.rs"]
mod common;
use common::{bounds, primary_rays, quantise, ramp};

use plotters::coord::Shift;
use plotters::prelude::*;
use std::error::Error;
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime, UNIX_EPOCH};
use strahl::build::{BinAxes, BuildParams, Builder, Bvh2, MortonBits, Refine, TreeletParams};
use strahl::geometry::{Triangle, morton};
use strahl::intersect::reference::{Verdict, classify_triangle, crossing_f64};
use strahl::intersect::{PreparedRay, TriangleX8, moller, watertight};
use strahl::layout::Bvh8;
use strahl::scene::{self, Aim, Rng};
use strahl::traverse::packet::{self, TileShape};
use strahl::traverse::{Moller, STACK_SIZE, Watertight, intersect_scalar};
use strahl::volume::procedural::{marschner_lobb, pinhole_rays, torus, unit_volume};
use strahl::volume::*;
use strahl::{Aabb, Hit, Ray, Vec3};

type Res<T> = Result<T, Box<dyn Error>>;

// ---------------------------------------------------------------------------------------------
// Timing and statistics

/// Median over `reps` runs (after one warm-up run) of the seconds `f` takes, and the last result.
/// Slow work is repeated less: where the warm-up run takes over 0.25 s, the median of it and 2
/// more runs; over 1 s, the warm-up run alone is the measurement.
fn median_with<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let s = Instant::now();
    let mut last = black_box(f());
    let first = s.elapsed().as_secs_f64();
    if first > 1.0 {
        return (first, last);
    }
    // Over 0.25 s the warm-up run counts as one of 3 (caches matter little at that length).
    let (reps, mut t) = if first > 0.25 {
        (2, vec![first])
    } else {
        (reps.max(1), vec![])
    };
    t.extend((0..reps).map(|_| {
        let s = Instant::now();
        last = black_box(f());
        s.elapsed().as_secs_f64()
    }));
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], last)
}

/// [`median_with`]'s time alone.
fn median_s<T>(reps: usize, f: impl FnMut() -> T) -> f64 {
    median_with(reps, f).0
}

/// Least-squares slope of `ln y` against `ln x`.
fn loglog_slope(pts: &[(f64, f64)]) -> f64 {
    let pts: Vec<(f64, f64)> = pts
        .iter()
        .filter(|p| p.0 > 0.0 && p.1 > 0.0)
        .map(|p| (p.0.ln(), p.1.ln()))
        .collect();
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    sxy / sxx
}

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn max_of(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

/// `true` for each point that no other beats on both coordinates (smaller is better).
fn pareto(pts: &[Option<(f64, f64)>]) -> Vec<bool> {
    pts.iter()
        .map(|p| {
            let Some((x, y)) = *p else { return false };
            !pts.iter()
                .flatten()
                .any(|&(ox, oy)| ox <= x && oy <= y && (ox < x || oy < y))
        })
        .collect()
}

/// Three significant digits, switching to exponents for very small or large values.
fn sig(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.2e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else {
        let digits = (2.0 - a.log10().floor()) as usize;
        format!("{v:.digits$}")
    }
}

fn yes(b: bool) -> &'static str {
    if b { "**yes**" } else { "" }
}

/// Progress on stderr: a section's start and, on drop, its end with the time it took.
struct Progress {
    name: String,
    start: Instant,
}

impl Progress {
    fn start(name: &str) -> Self {
        eprintln!("[report] {name}: started");
        Self {
            name: name.into(),
            start: Instant::now(),
        }
    }
    fn note(&self, what: &str) {
        eprintln!(
            "[report]   {}: {what} ({:.1} s)",
            self.name,
            self.start.elapsed().as_secs_f64()
        );
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        eprintln!(
            "[report] {}: finished in {:.1} s",
            self.name,
            self.start.elapsed().as_secs_f64()
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Plots: panels of labelled point series on linear or log10 axes

struct Series {
    name: String,
    color: RGBColor,
    pts: Vec<(f64, f64)>,
    /// Per point: filled marker (else hollow).
    filled: Vec<bool>,
    /// Per point: a label beside it (empty: none).
    labels: Vec<String>,
    /// Join the points with a line (in the given order).
    line: bool,
}

impl Series {
    fn new(name: &str, color: RGBColor, pts: Vec<(f64, f64)>) -> Self {
        let n = pts.len();
        Self {
            name: name.into(),
            color,
            pts,
            filled: vec![true; n],
            labels: vec![String::new(); n],
            line: false,
        }
    }
    fn labels(mut self, labels: Vec<String>) -> Self {
        self.labels = labels;
        self
    }
    fn filled(mut self, filled: Vec<bool>) -> Self {
        self.filled = filled;
        self
    }
    fn line(mut self) -> Self {
        self.line = true;
        self
    }
}

struct Panel {
    title: String,
    x_desc: String,
    y_desc: String,
    x_log: bool,
    y_log: bool,
    series: Vec<Series>,
    /// A staircase through these points (the Pareto front), drawn under the series.
    front: Vec<(f64, f64)>,
}

impl Panel {
    fn new(title: &str, x_desc: &str, y_desc: &str, x_log: bool, y_log: bool, series: Vec<Series>) -> Self {
        Self {
            title: title.into(),
            x_desc: x_desc.into(),
            y_desc: y_desc.into(),
            x_log,
            y_log,
            series,
            front: Vec::new(),
        }
    }
}

const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

fn tick(v: f64, log: bool) -> String {
    if log { sig(10f64.powf(v)) } else { sig(v) }
}

fn draw_panel(area: &DrawingArea<SVGBackend<'_>, Shift>, p: &Panel) -> Res<()> {
    let tx = |v: f64| if p.x_log { v.log10() } else { v };
    let ty = |v: f64| if p.y_log { v.log10() } else { v };
    let ok = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite() && (!p.x_log || x > 0.0) && (!p.y_log || y > 0.0);
    let all: Vec<(f64, f64)> = p
        .series
        .iter()
        .flat_map(|s| s.pts.iter().filter(|q| ok(q)).map(|&(x, y)| (tx(x), ty(y))))
        .collect();
    if all.is_empty() {
        return Ok(());
    }
    let range = |v: Vec<f64>, log: bool, right: f64| {
        let (lo, hi) = v.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        let span = if hi > lo {
            hi - lo
        } else if log {
            1.0
        } else {
            hi.abs().max(1.0)
        };
        let lo = if !log && lo >= 0.0 && lo < 0.3 * span { 0.0 } else { lo };
        (lo - 0.08 * span, hi + (0.08 + right) * span)
    };
    // Room on the right for point labels.
    let (x0, x1) = range(all.iter().map(|q| q.0).collect(), p.x_log, 0.3);
    let (y0, y1) = range(all.iter().map(|q| q.1).collect(), p.y_log, 0.05);
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, ("sans-serif", 15))
        .margin(10)
        .x_label_area_size(38)
        .y_label_area_size(62)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    let (xl, yl) = (p.x_log, p.y_log);
    let fx = move |v: &f64| tick(*v, xl);
    let fy = move |v: &f64| tick(*v, yl);
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_labels(7)
        .y_labels(7)
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .x_desc(format!("{}{}", p.x_desc, if p.x_log { " (log)" } else { "" }))
        .y_desc(format!("{}{}", p.y_desc, if p.y_log { " (log)" } else { "" }))
        .draw()?;
    if !p.front.is_empty() {
        let mut f: Vec<(f64, f64)> = p.front.iter().filter(|q| ok(q)).map(|&(x, y)| (tx(x), ty(y))).collect();
        f.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut steps = Vec::new();
        for (k, &(x, y)) in f.iter().enumerate() {
            if k > 0 {
                steps.push((x, f[k - 1].1));
            }
            steps.push((x, y));
        }
        chart.draw_series(LineSeries::new(steps, BLACK.mix(0.35).stroke_width(1)))?;
    }
    for s in &p.series {
        let c = s.color;
        let idx: Vec<usize> = (0..s.pts.len()).filter(|&i| ok(&s.pts[i])).collect();
        let pt = |i: usize| (tx(s.pts[i].0), ty(s.pts[i].1));
        if s.line {
            chart.draw_series(LineSeries::new(idx.iter().map(|&i| pt(i)), c.stroke_width(2)))?;
        }
        chart
            .draw_series(idx.iter().map(|&i| {
                let style = if s.filled[i] { c.filled() } else { c.stroke_width(2) };
                Circle::new(pt(i), 4, style)
            }))?
            .label(s.name.clone())
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, c.filled()));
        chart.draw_series(idx.iter().filter(|&&i| !s.labels[i].is_empty()).map(|&i| {
            Text::new(
                s.labels[i].clone(),
                (pt(i).0 + (x1 - x0) * 0.012, pt(i).1),
                ("sans-serif", 10),
            )
        }))?;
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.85))
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    Ok(())
}

/// Writes `panels` in a grid of `cols` columns to `dir/name`, each panel `w x h` pixels.
fn write_plot(dir: &Path, name: &str, title: &str, cols: usize, size: (u32, u32), panels: &[Panel]) -> Res<()> {
    let rows = panels.len().div_ceil(cols);
    let path = dir.join(name);
    let root = SVGBackend::new(&path, (size.0 * cols as u32, size.1 * rows as u32 + 30)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 17))?;
    let areas = root.split_evenly((rows, cols));
    for (a, p) in areas.iter().zip(panels) {
        draw_panel(a, p)?;
    }
    root.present()?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Scenes and rays (as in benches/trace.rs and benches/build.rs)

struct TraceScene {
    name: String,
    about: String,
    tris: Vec<Triangle>,
    primary: Vec<Ray>,
    diffuse: Vec<Ray>,
    /// The box the primary rays aim at, where it is not the scene's.
    target: Option<Aabb>,
}

impl TraceScene {
    /// Primary rays at the box `target` (the scene's box where `None`), diffuse rays from the
    /// surface (`benches/common`).
    fn new(name: &str, about: String, tris: Vec<Triangle>, target: Option<Aabb>, side: u32) -> Self {
        let b = bounds(&tris);
        let scale = (b.max - b.min).length();
        let primary = primary_rays(&target.unwrap_or(b), side, side, TileShape::X4_2);
        let diffuse = common::diffuse_rays(&tris, (side * side) as usize, scale);
        Self {
            name: name.into(),
            about,
            tris,
            primary,
            diffuse,
            target,
        }
    }
}

fn bunny_scene(side: u32) -> TraceScene {
    TraceScene::new(
        "bunny",
        "`scene::bunny()`, the bundled Stanford bunny".into(),
        scene::bunny().to_soup(),
        None,
        side,
    )
}

const SOUP_TRIS: usize = 200_000;

fn soup_scene(side: u32) -> TraceScene {
    TraceScene::new(
        "soup200k",
        format!(
            "`scene::thin_soup({SOUP_TRIS}, 1)`: long thin triangles filling the unit cube, heavily overlapping boxes"
        ),
        scene::thin_soup(SOUP_TRIS, 1),
        None,
        side,
    )
}

/// 100,000 small triangles in the unit cube and one far away (`tests/build.rs`' far outlier,
/// closer: at `1e4`, where 63-bit codes still resolve the cluster and 30-bit codes do not).
fn outlier_scene(side: u32) -> TraceScene {
    let mut r = Rng::new(10);
    let mut tris: Vec<Triangle> = (0..100_000)
        .map(|_| {
            let p = Vec3::new(r.f32(), r.f32(), r.f32());
            [p, p + r.unit_vector() * 0.01, p + r.unit_vector() * 0.01]
        })
        .collect();
    let far = Vec3::splat(1e4);
    tris.push([far, far + Vec3::X, far + Vec3::Y]);
    TraceScene::new(
        "outlier",
        "100,000 triangles of size 0.01 in the unit cube plus one at `(1e4, 1e4, 1e4)` (as `tests/build.rs`' far outlier); primary rays aimed at the cube".into(),
        tris,
        Some(Aabb::new(Vec3::ZERO, Vec3::ONE)),
        side,
    )
}

// ---------------------------------------------------------------------------------------------
// 1. Ray/triangle

type ScalarTest = fn(&PreparedRay, &Triangle, u32) -> Option<Hit>;
type X8Test = fn(&PreparedRay, &TriangleX8) -> Option<Hit>;

fn pack8(tris: &[Triangle]) -> Vec<TriangleX8> {
    tris.chunks(8)
        .enumerate()
        .map(|(c, ch)| TriangleX8::pack(ch, &(0..ch.len()).map(|i| (c * 8 + i) as u32).collect::<Vec<_>>()))
        .collect()
}

/// Relative `t` errors `|t32 - t64| / t64` and their ratios to the bound `Dt` over the pairs
/// where the kernel hit and the reference has a crossing; `clear`: only where the reference says
/// [`Verdict::Hit`] (and the clear hits the kernel missed are counted).
struct TErr {
    rel: Vec<f64>,
    ratio: Vec<f64>,
    pairs: usize,
    clear_missed: usize,
    x8_identical: bool,
}

fn t_errors(rays: &[Ray], tris: &[Triangle], fs: ScalarTest, f8: X8Test, clear: bool) -> TErr {
    let mut e = TErr {
        rel: vec![],
        ratio: vec![],
        pairs: 0,
        clear_missed: 0,
        x8_identical: true,
    };
    for ray in rays {
        let pr = PreparedRay::new(ray);
        for tri in tris {
            let hit = fs(&pr, tri, 0);
            if clear {
                if !matches!(classify_triangle(ray, tri), Verdict::Hit(_)) {
                    continue;
                }
                if hit.is_none() {
                    e.clear_missed += 1;
                    continue;
                }
            }
            let Some(h) = hit else { continue };
            let Some(c) = crossing_f64(ray, tri) else { continue };
            if c.t.is_nan() || c.t <= 0.0 {
                continue;
            }
            let h8 = f8(&pr, &TriangleX8::pack(&[*tri], &[0]));
            e.x8_identical &= h8.is_some_and(|h8| h8.t.to_bits() == h.t.to_bits());
            let err = (h.t as f64 - c.t).abs();
            e.pairs += 1;
            e.rel.push(err / c.t);
            e.ratio.push(err / c.t_bound);
        }
    }
    e
}

fn section_triangles(dir: &Path) -> Res<String> {
    let pg = Progress::start("1/6 ray/triangle");
    let mut rng = Rng::new(42);
    // Random rays against random triangles (examples/kernels.rs).
    let rays: Vec<Ray> = (0..4096)
        .map(|_| {
            let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), -3.0);
            let target = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            Ray::new(o, target - o)
        })
        .collect();
    let prepared: Vec<PreparedRay> = rays.iter().map(PreparedRay::new).collect();
    let tris: Vec<Triangle> = (0..8)
        .map(|_| {
            let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            [0, 1, 2].map(|_| c + rng.unit_vector() * 0.8)
        })
        .collect();
    let t8 = TriangleX8::pack(&tris, &(0..8).collect::<Vec<u32>>());
    // Rays aimed exactly at edges and vertices of a closed icosphere (benches/time_vs_error.rs).
    let mut m = scene::icosphere(3);
    for p in &mut m.positions {
        *p = *p * 3.7 + Vec3::new(0.31, -1.7, 2.1);
    }
    let mut aimed = scene::aimed_rays(&m, Aim::Edges, 4, 3.0, 1);
    aimed.extend(scene::aimed_rays(&m, Aim::Vertices, 8, 3.0, 2));
    let aimed_p: Vec<PreparedRay> = aimed.iter().map(PreparedRay::new).collect();
    let soup = m.to_soup();
    let packs = pack8(&soup);
    let timed = &aimed_p[..aimed_p.len().min(1024)];

    let kernels: [(&str, ScalarTest, X8Test); 2] = [
        ("Möller-Trumbore", moller::intersect_scalar, moller::intersect_x8),
        ("watertight", watertight::intersect_scalar, watertight::intersect_x8),
    ];
    struct Row {
        kernel: &'static str,
        width: &'static str,
        ns_random: f64,
        ns_aimed: f64,
        misses: usize,
    }
    let mut rows = Vec::new();
    let mut terr = Vec::new();
    let reps = 9;
    for (name, fs, f8) in kernels {
        let random_work = (prepared.len() * 8) as f64;
        let aimed_work = (timed.len() * soup.len()) as f64;
        let s_random = median_s(reps, || {
            prepared
                .iter()
                .map(|r| tris.iter().filter(|t| fs(r, t, 0).is_some()).count())
                .sum::<usize>()
        }) / random_work;
        let x_random = median_s(reps, || prepared.iter().filter(|r| f8(r, &t8).is_some()).count()) / random_work;
        let s_aimed = median_s(5, || {
            timed
                .iter()
                .map(|r| soup.iter().filter(|t| fs(r, t, 0).is_some()).count())
                .sum::<usize>()
        }) / aimed_work;
        let x_aimed = median_s(5, || {
            timed
                .iter()
                .map(|r| packs.iter().filter(|p| f8(r, p).is_some()).count())
                .sum::<usize>()
        }) / aimed_work;
        let miss_s = aimed_p
            .iter()
            .filter(|r| !soup.iter().any(|t| fs(r, t, 0).is_some()))
            .count();
        let miss_x = aimed_p
            .iter()
            .filter(|r| !packs.iter().any(|p| f8(r, p).is_some()))
            .count();
        rows.push(Row {
            kernel: name,
            width: "scalar",
            ns_random: s_random * 1e9,
            ns_aimed: s_aimed * 1e9,
            misses: miss_s,
        });
        rows.push(Row {
            kernel: name,
            width: "x8",
            ns_random: x_random * 1e9,
            ns_aimed: x_aimed * 1e9,
            misses: miss_x,
        });
        pg.note(&format!("{name} timed"));
        let random = t_errors(&rays, &tris, fs, f8, true);
        let edge = t_errors(&aimed, &soup, fs, f8, false);
        terr.push((name, random, edge));
        pg.note(&format!("{name} t errors"));
    }

    let mut md = String::new();
    let n_aimed = aimed.len();
    writeln!(
        md,
        "## 1. Ray/triangle: Möller-Trumbore against watertight\n\n\
         **Trade-off.** Möller-Trumbore is the cheaper test; the watertight test (Woop, Benthin and \
         Wald 2013, with its `f64` fallback for exactly-zero edge functions) costs more per test and \
         never lets a ray slip between two triangles that share an edge or vertex.\n\n\
         **How measured.** Time: ns per ray/triangle test (closest hit), on 4,096 random rays \
         against 8 random triangles (`examples/kernels.rs`' setup) and on 1,024 of the edge/vertex \
         rays against all {} triangles of the sphere (brute force; x8: packs of 8). False misses: \
         {n_aimed} rays aimed exactly at the shared edges (4 per edge) and vertices (8 per vertex) \
         of a closed `scene::icosphere(3)` (scaled by 3.7, moved off the origin; \
         `scene::aimed_rays`, each ray accepts only `t` in `[0.9, 1.1)`), counted as missed when \
         no triangle of the mesh reports a hit: every such ray must hit one. Error of `t`: against \
         the `f64` reference (`intersect::reference::crossing_f64`), `|t32 - t64| / t64`, over \
         the random rays' clear hits (`classify_triangle` says `Verdict::Hit`: every kernel must \
         hit) and over every hit the kernel reports on the edge/vertex rays (knife edges \
         included); `Dt` is the proved bound `t_error_bound` of that ray and triangle.\n",
        soup.len()
    )?;
    writeln!(
        md,
        "| test | width | ns/test, random rays | ns/test, edge/vertex rays | false misses (of {n_aimed}) | false-miss rate |\n|---|---|---|---|---|---|"
    )?;
    for r in &rows {
        writeln!(
            md,
            "| {} | {} | {} | {} | {} | {:.3}% |",
            r.kernel,
            r.width,
            sig(r.ns_random),
            sig(r.ns_aimed),
            r.misses,
            100.0 * r.misses as f64 / n_aimed as f64
        )?;
    }
    writeln!(
        md,
        "\n| test | ray set | hits compared | max rel. `t` error | RMS rel. `t` error | max `\\|t32 - t64\\| / Dt` | clear hits missed | x8 `t` bit-identical to scalar |\n|---|---|---|---|---|---|---|---|"
    )?;
    for (name, random, edge) in &terr {
        for (set, e) in [("random, clear hits", random), ("edge/vertex, all hits", edge)] {
            writeln!(
                md,
                "| {name} | {set} | {} | {:.2e} | {:.2e} | {:.3} | {} | {} |",
                e.pairs,
                max_of(&e.rel),
                rms(&e.rel),
                max_of(&e.ratio),
                if set.starts_with("random") {
                    e.clear_missed.to_string()
                } else {
                    "-".into()
                },
                if e.x8_identical { "yes" } else { "**no**" }
            )?;
        }
    }
    let (mt, wt) = (&rows[0], &rows[2]);
    let worst = terr
        .iter()
        .flat_map(|(_, a, b)| [max_of(&a.ratio), max_of(&b.ratio)])
        .fold(0.0, f64::max);
    writeln!(
        md,
        "\nOn this run the watertight test costs {:.2}x Möller-Trumbore's time per test on the \
         edge/vertex rays (scalar; {:.2}x in x8) and removes {} false misses ({:.2}% of the rays) \
         to {}. Largest `|t32 - t64| / Dt` over all hits compared: {:.3} ({}); largest relative \
         `t` error on clear hits: {:.1e} (Möller-Trumbore) against {:.1e} (watertight).\n",
        wt.ns_aimed / mt.ns_aimed,
        rows[3].ns_aimed / rows[1].ns_aimed,
        mt.misses,
        100.0 * mt.misses as f64 / n_aimed as f64,
        wt.misses,
        worst,
        if worst <= 1.0 {
            "every `t` within its proved bound"
        } else {
            "**a `t` outside its bound**"
        },
        max_of(&terr[0].1.rel),
        max_of(&terr[1].1.rel),
    )?;
    // Plot: time per test against false-miss rate.
    let series: Vec<Series> = (0..2)
        .map(|k| {
            let r = &rows[2 * k..2 * k + 2];
            Series::new(
                r[0].kernel,
                PALETTE[k],
                r.iter()
                    .map(|r| (r.ns_aimed, 100.0 * r.misses as f64 / n_aimed as f64))
                    .collect(),
            )
            .labels(r.iter().map(|r| format!("{} {}", r.kernel, r.width)).collect())
        })
        .collect();
    write_plot(
        dir,
        "triangle.svg",
        "ray/triangle: time per test against false misses on edge/vertex-aimed rays",
        1,
        (760, 440),
        &[Panel::new(
            &format!("closed icosphere(3), {n_aimed} rays aimed at edges and vertices"),
            "ns per test (edge/vertex rays, single thread)",
            "false-miss rate, %",
            true,
            false,
            series,
        )],
    )?;
    writeln!(md, "![time per test against false-miss rate](triangle.svg)\n")?;
    Ok(md)
}

// ---------------------------------------------------------------------------------------------
// 2. and 3. BVH builders

/// One builder's numbers on one scene (times in seconds; trace times per ray).
struct BuildRow {
    name: String,
    warm: f64,
    cold: f64,
    collapse: f64,
    sah: f32,
    /// SAH cost for rays into the scene's target box ([`sah_within`]), where it has one.
    sah_target: Option<f64>,
    depth: u32,
    leaves: u32,
    /// Scalar BVH2 reference: (primary, diffuse) seconds per ray.
    bvh2: Option<(f64, f64)>,
    /// BVH8 single-ray traversal: (primary, diffuse) seconds per ray.
    bvh8: Option<(f64, f64)>,
    hits: usize,
}

impl BuildRow {
    fn bvh8_mean(&self) -> Option<f64> {
        self.bvh8.map(|(p, d)| (p + d) / 2.0)
    }
    fn bvh2_mean(&self) -> Option<f64> {
        self.bvh2.map(|(p, d)| (p + d) / 2.0)
    }
}

fn measure_builder(s: &TraceScene, name: &str, p: &BuildParams, builder: &mut Builder) -> Res<BuildRow> {
    let tris = &s.tris[..];
    let n = tris.len();
    let reps = if n > 50_000 { 3 } else { 11 };
    let mut bvh = Bvh2::default();
    let warm = median_s(reps, || builder.build_into(tris, p, &mut bvh).expect("valid params"));
    let cold = median_s(reps.min(3), || Bvh2::build(tris, p).expect("valid params"));
    let stats = bvh
        .validate(tris)
        .map_err(|e| format!("{}: {name}: invalid tree: {e}", s.name))?;
    let sah = bvh.sah_cost(1.0, 1.0);
    let collapse = median_s(3, || Bvh8::from_bvh2(&bvh, tris));
    let mut row = BuildRow {
        name: name.into(),
        warm,
        cold,
        collapse,
        sah,
        sah_target: s.target.map(|b| sah_within(&bvh, &b)),
        depth: stats.max_depth,
        leaves: stats.leaves,
        bvh2: None,
        bvh8: None,
        hits: 0,
    };
    // Deeper than the stack: the traversal would finish rays by linear scans (exact, but it would
    // time the fallback, not the tree).
    if stats.max_depth as usize <= STACK_SIZE + 1 {
        let per = |rays: &[Ray]| {
            let (t, hits) = median_with(5, || {
                rays.iter()
                    .filter(|r| intersect_scalar::<Watertight, _>(bvh.view(), tris, r).is_some())
                    .count()
            });
            (t / rays.len() as f64, hits)
        };
        let ((p, hp), (d, hd)) = (per(&s.primary), per(&s.diffuse));
        row.bvh2 = Some((p, d));
        row.hits = hp + hd;
    }
    if let Ok(b8) = Bvh8::from_bvh2(&bvh, tris) {
        let per = |rays: &[Ray]| {
            let (t, hits) = median_with(5, || {
                rays.iter().filter(|r| b8.intersect::<Watertight>(r).is_some()).count()
            });
            (t / rays.len() as f64, hits)
        };
        let ((p, hp), (d, hd)) = (per(&s.primary), per(&s.diffuse));
        row.bvh8 = Some((p, d));
        let hits8 = hp + hd;
        if row.bvh2.is_some() && hits8 != row.hits {
            return Err(format!("{}: {name}: BVH8 finds {hits8} hits, BVH2 {}", s.name, row.hits).into());
        }
        row.hits = hits8;
    }
    Ok(row)
}

/// The SAH cost for rays that hit the box `target` rather than the root's: each node weighted by
/// the probability `A(node ∩ target) / A(target)` that such a ray hits it (interior nodes
/// `C_T = 1`, leaves `C_I = 1` per primitive). Equals `Bvh2::sah_cost(1.0, 1.0)` for the root's
/// box; for a scene whose root box a far outlier inflates, it prices the part the rays see.
fn sah_within(bvh: &Bvh2, target: &Aabb) -> f64 {
    let a0 = target.half_area() as f64;
    bvh.nodes
        .iter()
        .map(|n| {
            let b = n.aabb();
            let i = Aabb::new(b.min.max(target.min), b.max.min(target.max));
            let ratio = if i.min.cmple(i.max).all() {
                i.half_area() as f64 / a0
            } else {
                0.0
            };
            ratio * if n.is_leaf() { n.prim_range().len() as f64 } else { 1.0 }
        })
        .sum()
}

/// Every builder worth listing, fastest build first (`benches/build.rs`' list).
fn builders() -> Vec<(&'static str, BuildParams)> {
    vec![
        ("lbvh30 = fastest()", BuildParams::fastest()),
        (
            "lbvh63",
            BuildParams {
                morton_bits: MortonBits::Bits63,
                ..BuildParams::fastest()
            },
        ),
        (
            "hlbvh (clusters of 32)",
            BuildParams {
                refine: Refine::None,
                ..BuildParams::hybrid()
            },
        ),
        ("median()", BuildParams::median()),
        ("binned8-longest = fast()", BuildParams::fast()),
        (
            "binned8-all",
            BuildParams {
                bin_axes: BinAxes::All,
                ..BuildParams::fast()
            },
        ),
        ("binned16-all = balanced()", BuildParams::balanced()),
        (
            "binned32-all",
            BuildParams {
                bins: 32,
                ..BuildParams::balanced()
            },
        ),
        ("binned64-all+rotations = high()", BuildParams::high()),
        ("sweep = quality()", BuildParams::quality()),
        ("hlbvh+treelets = hybrid()", BuildParams::hybrid()),
        ("hlbvh-sah = hybrid_sah()", BuildParams::hybrid_sah()),
        ("ploc = ploc()", BuildParams::ploc()),
        (
            "fast()+treelets",
            BuildParams {
                refine: Refine::Treelets(TreeletParams::new()),
                ..BuildParams::fast()
            },
        ),
    ]
}

fn us(v: Option<(f64, f64)>) -> (String, String) {
    v.map_or(("-".into(), "-".into()), |(p, d)| (sig(p * 1e6), sig(d * 1e6)))
}

fn build_table(md: &mut String, s: &TraceScene, rows: &[BuildRow], with_pareto: bool) -> Res<(Vec<bool>, Vec<bool>)> {
    let n = s.tris.len() as f64;
    let p_sah = pareto(&rows.iter().map(|r| Some((r.warm, r.sah as f64))).collect::<Vec<_>>());
    let p_trace = pareto(
        &rows
            .iter()
            .map(|r| r.bvh8_mean().map(|t| (r.warm, t)))
            .collect::<Vec<_>>(),
    );
    writeln!(
        md,
        "**{}** ({} triangles; {} primary + {} diffuse rays):\n\n\
         | builder | warm build ms | Mtri/s | cold build ms | BVH8 collapse ms | SAH cost |{} depth | leaves | BVH2 µs/ray primary | BVH2 µs/ray diffuse | BVH8 µs/ray primary | BVH8 µs/ray diffuse |{}\n\
         |---|---|---|---|---|---|{}---|---|---|---|---|---|{}",
        s.name,
        s.tris.len(),
        s.primary.len(),
        s.diffuse.len(),
        if s.target.is_some() {
            " SAH cost in the target box |"
        } else {
            ""
        },
        if with_pareto { " P(SAH) | P(trace) |" } else { "" },
        if s.target.is_some() { "---|" } else { "" },
        if with_pareto { "---|---|" } else { "" },
    )?;
    for (i, r) in rows.iter().enumerate() {
        let (b2p, b2d) = us(r.bvh2);
        let (b8p, b8d) = us(r.bvh8);
        write!(
            md,
            "| {} | {} | {} | {} | {} | {:.2} |{} {} | {} | {b2p} | {b2d} | {b8p} | {b8d} |",
            r.name,
            sig(r.warm * 1e3),
            sig(n / r.warm / 1e6),
            sig(r.cold * 1e3),
            sig(r.collapse * 1e3),
            r.sah,
            r.sah_target.map_or(String::new(), |c| format!(" {c:.2} |")),
            r.depth,
            r.leaves,
        )?;
        if with_pareto {
            write!(md, " {} | {} |", yes(p_sah[i]), yes(p_trace[i]))?;
        }
        md.push('\n');
    }
    md.push('\n');
    Ok((p_sah, p_trace))
}

/// Where two rows built the same tree (same SAH cost, leaves and depth: LBVH with 30- and 63-bit
/// codes when no codes collide), their trace times differ by noise alone: a note with the spread.
fn noise_note(md: &mut String, rows: &[BuildRow]) -> Res<()> {
    for (i, a) in rows.iter().enumerate() {
        for b in &rows[i + 1..] {
            if a.sah == b.sah
                && a.leaves == b.leaves
                && a.depth == b.depth
                && let (Some(x), Some(y)) = (a.bvh8_mean(), b.bvh8_mean())
            {
                writeln!(
                    md,
                    "Noise check: `{}` and `{}` built the same tree; their BVH8 trace times differ by {:.0}% \
                         and their BVH2 times by {:.0}%, which is this run's noise on the same work.\n",
                    a.name,
                    b.name,
                    100.0 * (x / y - 1.0).abs(),
                    100.0 * (a.bvh2_mean().unwrap_or(0.0) / b.bvh2_mean().unwrap_or(1.0) - 1.0).abs()
                )?;
            }
        }
    }
    Ok(())
}

fn check_hits(s: &TraceScene, rows: &[BuildRow]) -> Res<()> {
    if let Some(r0) = rows.iter().find(|r| r.bvh8.is_some()) {
        for r in rows.iter().filter(|r| r.bvh8.is_some()) {
            if r.hits != r0.hits {
                return Err(format!("{}: {} finds {} hits, {} {}", s.name, r.name, r.hits, r0.name, r0.hits).into());
            }
        }
    }
    Ok(())
}

fn section_builders(dir: &Path) -> Res<String> {
    let pg = Progress::start("2/6 builders");
    let scenes = [bunny_scene(128), soup_scene(96)];
    let mut md = String::new();
    writeln!(
        md,
        "## 2. BVH2 builders: build time against tree quality and trace time\n\n\
         **Trade-off.** A faster build makes a worse tree: LBVH sorts Morton codes and never \
         evaluates the SAH; binned SAH evaluates a few planes per axis; the full sweep every \
         primitive boundary; treelet restructuring (TRBVH) reorganises any builder's tree \
         afterwards.\n\n\
         **How measured.** Every `BuildParams` preset and the variants between them \
         (`benches/build.rs`' list). Warm build: one `build::Builder` and output tree reused \
         (median of 11 builds on the bunny, 3 on the soup); cold: `Bvh2::build` with fresh memory \
         (median of 3). SAH cost: `Bvh2::sah_cost(1.0, 1.0)`. Trace: the same rays for every tree, \
         closest hit with the watertight test, through the scalar BVH2 reference \
         (`traverse::intersect_scalar`) and through `Bvh8::from_bvh2` of the tree (single-ray \
         `Bvh8::intersect`), median of 5 passes (3 where one pass takes over 0.25 s); primary rays: a pinhole camera \
         (`benches/trace.rs`' `primary_rays`), diffuse rays: cosine-like directions from random \
         surface points (`benches/common`). Hit counts are checked equal for every tree. \
         **P(SAH)**: Pareto-optimal in (warm build time, SAH cost); **P(trace)**: in (warm build \
         time, BVH8 time per ray, mean of primary and diffuse); filled markers in the plot.\n"
    )?;
    let mut panels_sah = Vec::new();
    let mut panels_trace = Vec::new();
    let mut summary = Vec::new();
    for s in &scenes {
        writeln!(md, "Scene {}: {}.\n", s.name, s.about)?;
        let mut builder = Builder::new();
        let mut rows = Vec::new();
        for (name, p) in builders() {
            rows.push(measure_builder(s, name, &p, &mut builder)?);
            pg.note(&format!("{}: {name}", s.name));
        }
        check_hits(s, &rows)?;
        let (p_sah, p_trace) = build_table(&mut md, s, &rows, true)?;
        noise_note(&mut md, &rows)?;
        let labels: Vec<String> = rows.iter().map(|r| r.name.clone()).collect();
        let mut a = Panel::new(
            &format!("{}: SAH cost", s.name),
            "warm build time, ms",
            "SAH cost (C_T = C_I = 1)",
            true,
            false,
            vec![
                Series::new(
                    "builder (filled: Pareto-optimal)",
                    PALETTE[0],
                    rows.iter().map(|r| (r.warm * 1e3, r.sah as f64)).collect(),
                )
                .labels(labels.clone())
                .filled(p_sah.clone()),
            ],
        );
        a.front = rows
            .iter()
            .zip(&p_sah)
            .filter(|x| *x.1)
            .map(|(r, _)| (r.warm * 1e3, r.sah as f64))
            .collect();
        let mut b = Panel::new(
            &format!("{}: trace time", s.name),
            "warm build time, ms",
            "µs per ray (mean of primary and diffuse)",
            true,
            false,
            vec![
                Series::new(
                    "BVH8 (filled: Pareto-optimal)",
                    PALETTE[0],
                    rows.iter()
                        .map(|r| (r.warm * 1e3, r.bvh8_mean().unwrap_or(f64::NAN) * 1e6))
                        .collect(),
                )
                .labels(labels.clone())
                .filled(p_trace.clone()),
                Series::new(
                    "scalar BVH2 reference",
                    PALETTE[1],
                    rows.iter()
                        .map(|r| (r.warm * 1e3, r.bvh2_mean().unwrap_or(f64::NAN) * 1e6))
                        .collect(),
                )
                .filled(vec![false; rows.len()]),
            ],
        );
        b.front = rows
            .iter()
            .zip(&p_trace)
            .filter(|x| *x.1)
            .filter_map(|(r, _)| r.bvh8_mean().map(|t| (r.warm * 1e3, t * 1e6)))
            .collect();
        panels_sah.push(a);
        panels_trace.push(b);
        summary.push((s.name.clone(), s.tris.len(), rows));
    }
    // Headline: cheapest build, best SAH, fastest BVH8 trace per scene.
    for (name, n, rows) in &summary {
        let fastest = &rows[0];
        let best_sah = rows.iter().min_by(|a, b| a.sah.total_cmp(&b.sah)).expect("rows");
        let best_trace = rows
            .iter()
            .filter(|r| r.bvh8.is_some())
            .min_by(|a, b| {
                a.bvh8_mean()
                    .unwrap_or(f64::MAX)
                    .total_cmp(&b.bvh8_mean().unwrap_or(f64::MAX))
            })
            .expect("rows");
        writeln!(
            md,
            "{name} ({n} triangles): `{}` builds {:.1}x faster than `{}` (lowest SAH cost, {:.2} against \
             {:.2}); the fastest BVH8 trace comes from `{}` ({} µs/ray, against {} µs/ray for `{}`).\n",
            fastest.name,
            best_sah.warm / fastest.warm,
            best_sah.name,
            best_sah.sah,
            fastest.sah,
            best_trace.name,
            sig(best_trace.bvh8_mean().unwrap_or(0.0) * 1e6),
            sig(fastest.bvh8_mean().unwrap_or(0.0) * 1e6),
            fastest.name
        )?;
    }
    let panels: Vec<Panel> = panels_sah.into_iter().chain(panels_trace).collect();
    write_plot(
        dir,
        "builders.svg",
        "BVH2 builders, one thread: build time against SAH cost and trace time (filled: Pareto-optimal)",
        2,
        (720, 470),
        &panels,
    )?;
    writeln!(md, "![build time against SAH cost and trace time](builders.svg)\n")?;
    Ok(md)
}

/// Fraction of distinct Morton codes among the primitives' box centres (the builders' centroids),
/// 30- and 63-bit, quantised over the centroid bounds.
fn distinct_codes(tris: &[Triangle]) -> (f64, f64) {
    let c: Vec<Vec3> = tris.iter().map(|t| Aabb::from_points(&t[..]).centroid()).collect();
    let cb = Aabb::from_points(&c);
    let (q30, q63) = (morton::MortonQuantizer::new30(&cb), morton::MortonQuantizer::new63(&cb));
    let mut a: Vec<u32> = c.iter().map(|p| morton::morton30_scalar(*p, &q30)).collect();
    let mut b: Vec<u64> = c.iter().map(|p| morton::morton63_scalar(*p, &q63)).collect();
    a.sort_unstable();
    a.dedup();
    b.sort_unstable();
    b.dedup();
    let n = c.len() as f64;
    (a.len() as f64 / n, b.len() as f64 / n)
}

fn section_morton(dir: &Path) -> Res<String> {
    let pg = Progress::start("3/6 Morton bits");
    let scenes = [bunny_scene(128), soup_scene(96), outlier_scene(32)];
    let with = |bits, p: BuildParams| BuildParams { morton_bits: bits, ..p };
    let hl = BuildParams {
        refine: Refine::None,
        ..BuildParams::hybrid()
    };
    let variants = [
        ("lbvh30", with(MortonBits::Bits30, BuildParams::fastest())),
        ("lbvh63", with(MortonBits::Bits63, BuildParams::fastest())),
        ("hlbvh30", with(MortonBits::Bits30, hl)),
        ("hlbvh63", with(MortonBits::Bits63, hl)),
    ];
    let mut md = String::new();
    writeln!(
        md,
        "## 3. Morton codes: 30 against 63 bits\n\n\
         **Trade-off.** `MortonBits::Bits30` quantises each axis of the centroid bounds to 1,024 \
         cells and sorts in 3 radix passes; `Bits63` uses 2,097,152 cells per axis and 6 passes. \
         Where the scene's extent dwarfs its detail, 30-bit codes collide (many primitives in one \
         cell); the builders then order each run of equal codes by codes over the run's own bounds \
         and split it by those (the LBVH keeping as many of their bits as the depth bound leaves), \
         so what 63 bits buy there is mostly fewer such runs.\n\n\
         **How measured.** LBVH (`BuildParams::fastest()`) and HLBVH (`hybrid()` without the \
         treelet pass, clusters of 32, binned-SAH top) with either code width; builds, SAH cost and \
         traces measured as in section 2. Distinct codes: distinct centroid codes per primitive \
         (100%: no two primitives share a cell). Where a far primitive inflates the root box, \
         `sah_cost` (normalised by the root's area) says little; the table adds the SAH cost for \
         rays into the target box (each node weighted by `A(node ∩ box) / A(box)`, which is \
         `sah_cost` itself for the root's box).\n"
    )?;
    let mut panels = Vec::new();
    let mut pays = Vec::new();
    for s in &scenes {
        writeln!(md, "Scene {}: {}.\n", s.name, s.about)?;
        let (d30, d63) = distinct_codes(&s.tris);
        writeln!(
            md,
            "Distinct codes: {:.1}% (30-bit), {:.1}% (63-bit).\n",
            100.0 * d30,
            100.0 * d63
        )?;
        let mut builder = Builder::new();
        let mut rows = Vec::new();
        for (name, p) in &variants {
            rows.push(measure_builder(s, name, p, &mut builder)?);
            pg.note(&format!("{}: {name}", s.name));
        }
        check_hits(s, &rows)?;
        build_table(&mut md, s, &rows, false)?;
        noise_note(&mut md, &rows)?;
        let q = |r: &BuildRow| r.sah_target.unwrap_or(r.sah as f64);
        for k in [0, 2] {
            let (a, b) = (&rows[k], &rows[k + 1]);
            let same = a.sah == b.sah && a.leaves == b.leaves && a.depth == b.depth;
            pays.push(format!(
                "{} {}: 63 bits take {:.2}x the build time; SAH cost{} {:.2} -> {:.2} ({:+.1}%{}); BVH8 trace {} -> {} µs/ray ({:.2}x)",
                s.name,
                if k == 0 { "LBVH" } else { "HLBVH" },
                b.warm / a.warm,
                if a.sah_target.is_some() { " in the target box" } else { "" },
                q(a),
                q(b),
                100.0 * (q(b) / q(a) - 1.0),
                if same { ", same tree shape" } else { "" },
                sig(a.bvh8_mean().unwrap_or(f64::NAN) * 1e6),
                sig(b.bvh8_mean().unwrap_or(f64::NAN) * 1e6),
                a.bvh8_mean().unwrap_or(f64::NAN) / b.bvh8_mean().unwrap_or(f64::NAN),
            ));
        }
        let series = |y: &dyn Fn(&BuildRow) -> f64| -> Vec<Series> {
            [("LBVH", 0usize), ("HLBVH", 2)]
                .iter()
                .enumerate()
                .map(|(c, &(fam, k))| {
                    Series::new(
                        fam,
                        PALETTE[c],
                        rows[k..k + 2].iter().map(|r| (r.warm * 1e3, y(r))).collect(),
                    )
                    .labels(vec!["30".into(), "63".into()])
                    .line()
                })
                .collect()
        };
        panels.push(Panel::new(
            &format!("{}: SAH cost", s.name),
            "warm build time, ms",
            if s.target.is_some() {
                "SAH cost in the target box"
            } else {
                "SAH cost"
            },
            true,
            s.target.is_some(),
            series(&|r| r.sah_target.unwrap_or(r.sah as f64)),
        ));
        panels.push(Panel::new(
            &format!("{}: BVH8 trace", s.name),
            "warm build time, ms",
            "µs per ray",
            true,
            s.target.is_some(),
            series(&|r| r.bvh8_mean().unwrap_or(f64::NAN) * 1e6),
        ));
    }
    writeln!(md, "Summary (30 -> 63 bits):\n")?;
    for p in &pays {
        writeln!(md, "- {p}")?;
    }
    md.push('\n');
    // Columns are scenes: reorder to (SAH row, trace row).
    let (sah, trace): (Vec<_>, Vec<_>) = panels.into_iter().enumerate().partition(|(i, _)| i % 2 == 0);
    let panels: Vec<Panel> = sah.into_iter().chain(trace).map(|(_, p)| p).collect();
    write_plot(
        dir,
        "morton.svg",
        "Morton code width (labels: bits): build time against SAH cost and BVH8 trace time",
        3,
        (560, 420),
        &panels,
    )?;
    writeln!(
        md,
        "![Morton bits: build time against SAH cost and trace time](morton.svg)\n"
    )?;
    Ok(md)
}

// ---------------------------------------------------------------------------------------------
// 4. Volume: step size and sampling rule

const TAU0: f64 = 3.0;
const SCALE_H: f64 = 0.4;
const C0: [f32; 3] = [0.1, 0.3, 1.0];
const C1: [f32; 3] = [1.0, 0.6, 0.2];

/// Premultiplied RGBA of a ray through the exponential atmosphere `tau(z) = TAU0 exp(-z / h)`,
/// colour `c(v) = C0 + (C1 - C0) v` of the value `v = exp(-z / h)`, over `z` in `[0, 1]`, crossed
/// with `k = |d| / d_z` path length per unit of `z`: optical depth `D1 = M (1 - exp(-1 / h))` with
/// `M = TAU0 k h`, `A = 1 - exp(-D1)`; since `v = 1 - D / M` along the ray,
/// `C = int_0^D1 c e^-D dD = C1 (1 - e^-D1) - (C1 - C0) / M (1 - e^-D1 (1 + D1))`.
fn atmosphere_closed_form(k: f64) -> [f64; 4] {
    let m = TAU0 * k * SCALE_H;
    let d1 = m * (1.0 - (-1.0 / SCALE_H).exp());
    let a = 1.0 - (-d1).exp();
    let second = (1.0 - (-d1).exp() * (1.0 + d1)) / m;
    let c = |i: usize| C1[i] as f64 * a - (C1[i] as f64 - C0[i] as f64) * second;
    [c(0), c(1), c(2), a]
}

fn rgba_diffs(a: &[Rgba], b: &[Rgba]) -> Vec<f64> {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| [x.r - y.r, x.g - y.g, x.b - y.b, x.a - y.a].map(|d| d as f64))
        .collect()
}

fn section_volume_steps(dir: &Path) -> Res<String> {
    let pg = Progress::start("4/6 volume step and sampling");
    // The atmosphere as an f32 volume over [0, 1]^3: 2 x 2 x 1025 voxels, value exp(-z / h), and a
    // two-entry transfer function (tau 0 -> TAU0, colour C0 -> C1) over values [0, 1].
    let nz = 1025usize;
    let mut data = vec![0.0f32; 4 * nz];
    for k in 0..nz {
        for i in 0..4 {
            data[k * 4 + i] = (-(k as f64 / (nz - 1) as f64) / SCALE_H).exp() as f32;
        }
    }
    let vol = Volume::new(
        &data,
        [2, 2, nz as u32],
        Vec3::new(1.0, 1.0, 1.0 / (nz - 1) as f32),
        Vec3::ZERO,
    )?;
    let table = [TfEntry::new(C0, 0.0), TfEntry::new(C1, TAU0 as f32)];
    let tf = TransferFunction::new(&table, 0.0, 1.0)?;
    let m = VolumeMedium::new(vol, tf);
    // Rays entering the bottom face inside [0.2, 0.8]^2, up to 0.15 off vertical per unit z, so
    // every ray leaves through the top face.
    let mut rng = Rng::new(7);
    let rays: Vec<Ray> = (0..4096)
        .map(|_| {
            let p0 = Vec3::new(rng.range(0.2, 0.8), rng.range(0.2, 0.8), 0.0);
            let d = Vec3::new(rng.range(-0.15, 0.15), rng.range(-0.15, 0.15), 1.0);
            Ray::new(p0 - d, d)
        })
        .collect();
    // Errors are taken in f64 against the f64 closed form.
    let exact64: Vec<[f64; 4]> = rays
        .iter()
        .map(|r| {
            let d = r.direction.as_dvec3();
            atmosphere_closed_form(d.length() / d.z)
        })
        .collect();
    struct Pt {
        sampling: Sampling,
        e: i32,
        ns: f64,
        samples: f64,
        rms: f64,
        max_a: f64,
    }
    let mut pts = Vec::new();
    let mut out = vec![Rgba::ZERO; rays.len()];
    for sampling in [Sampling::Endpoint, Sampling::Midpoint] {
        for e in 1..=8 {
            let p = MarchParams {
                sampling,
                ..MarchParams::reference(0.5f32.powi(e))
            };
            let st = integrate_x8(&m, &rays, &mut out, &p)?;
            let ns = median_s(7, || integrate_x8(&m, &rays, &mut out, &p).expect("valid")) / rays.len() as f64 * 1e9;
            let diffs: Vec<f64> = out
                .iter()
                .zip(&exact64)
                .flat_map(|(x, y)| {
                    [
                        x.r as f64 - y[0],
                        x.g as f64 - y[1],
                        x.b as f64 - y[2],
                        x.a as f64 - y[3],
                    ]
                })
                .collect();
            let max_a = out
                .iter()
                .zip(&exact64)
                .map(|(x, y)| (x.a as f64 - y[3]).abs())
                .fold(0.0, f64::max);
            pts.push(Pt {
                sampling,
                e,
                ns,
                samples: st.samples as f64 / st.rays as f64,
                rms: rms(&diffs),
                max_a,
            });
        }
        pg.note(&format!("{sampling:?}"));
    }
    // Scalar reference at one step, for the x8 ratio.
    let p = MarchParams::reference(1.0 / 64.0);
    let scalar = median_s(5, || integrate_scalar(&m, &rays, &mut out, &p).expect("valid")) / rays.len() as f64 * 1e9;
    let x8 = median_s(5, || integrate_x8(&m, &rays, &mut out, &p).expect("valid")) / rays.len() as f64 * 1e9;

    let mut md = String::new();
    writeln!(
        md,
        "## 4. Volume marching: step size and sampling rule\n\n\
         **Trade-off.** The marcher (absorption plus emission, Max 1995) takes fixed steps `dt`: \
         time grows as `1/dt`, the error falls as `dt^p`. `Sampling::Endpoint` (a left Riemann sum) \
         has order 1, `Sampling::Midpoint` order 2, at the same cost per sample.\n\n\
         **How measured.** A medium with a closed-form answer (`tests/volume.rs`' exponential \
         atmosphere): extinction `tau(z) = {TAU0} exp(-z / {SCALE_H})` and colour \
         `c = C0 + (C1 - C0) exp(-z / {SCALE_H})` (C0 = {C0:?}, C1 = {C1:?}), stored as an `f32` volume \
         of 2 x 2 x {nz} voxels over the unit cube with a two-entry transfer function (value \
         `exp(-z / h)`, trilinear error below 1e-6 relative), {} rays entering the bottom face and \
         leaving through the top, up to 0.15 off vertical. Closed form per ray: optical depth \
         `D1 = M (1 - e^(-1/h))`, `M = tau0 k h` (`k` = path length per unit `z`), \
         `A = 1 - e^-D1`, `C = C1 A - (C1 - C0) (1 - e^-D1 (1 + D1)) / M`. Error: RMS over rays and \
         the four premultiplied RGBA channels, in `f64`, and the largest error of `A`. Time: \
         `integrate_x8`, median of 7 runs, no early termination. Order: least-squares slope of \
         log error against log `dt`.\n",
        rays.len()
    )?;
    writeln!(
        md,
        "| sampling | dt | samples/ray | ns/ray | RMS error (RGBA) | max error of A |\n|---|---|---|---|---|---|"
    )?;
    for p in &pts {
        writeln!(
            md,
            "| {:?} | 1/{} | {:.1} | {} | {:.2e} | {:.2e} |",
            p.sampling,
            1 << p.e,
            p.samples,
            sig(p.ns),
            p.rms,
            p.max_a
        )?;
    }
    let order = |s: Sampling| {
        loglog_slope(
            &pts.iter()
                .filter(|p| p.sampling == s)
                .map(|p| (0.5f64.powi(p.e), p.rms))
                .collect::<Vec<_>>(),
        )
    };
    let (o_end, o_mid) = (order(Sampling::Endpoint), order(Sampling::Midpoint));
    let at = |s: Sampling, e: i32| pts.iter().find(|p| p.sampling == s && p.e == e).expect("point");
    let target = at(Sampling::Endpoint, 8).rms;
    let cheapest_mid = pts
        .iter()
        .filter(|p| p.sampling == Sampling::Midpoint && p.rms <= target)
        .min_by(|a, b| a.ns.total_cmp(&b.ns));
    writeln!(
        md,
        "\nFitted order over dt = 1/2 .. 1/256: **{o_end:.2}** (endpoint), **{o_mid:.2}** (midpoint). \
         Midpoint sampling costs {:.2}x endpoint per ray at the same step (dt = 1/64) and is {:.0}x \
         more accurate there; {}. x8 against the scalar reference at dt = 1/64: {:.2}x ({} against \
         {} ns/ray; bit-identical images, tested in `tests/volume.rs`).\n",
        at(Sampling::Midpoint, 6).ns / at(Sampling::Endpoint, 6).ns,
        at(Sampling::Endpoint, 6).rms / at(Sampling::Midpoint, 6).rms,
        match cheapest_mid {
            Some(p) => format!(
                "endpoint's accuracy at dt = 1/256 ({:.1e}) is reached by midpoint at dt = 1/{} in {:.1}x less time",
                target,
                1 << p.e,
                at(Sampling::Endpoint, 8).ns / p.ns
            ),
            None => "midpoint never reaches endpoint's finest accuracy here".into(),
        },
        scalar / x8,
        sig(x8),
        sig(scalar)
    )?;
    let series: Vec<Series> = [Sampling::Endpoint, Sampling::Midpoint]
        .iter()
        .enumerate()
        .map(|(c, &s)| {
            let mine: Vec<&Pt> = pts.iter().filter(|p| p.sampling == s).collect();
            Series::new(
                &format!("{s:?} (order {:.2})", if c == 0 { o_end } else { o_mid }),
                PALETTE[c],
                mine.iter().map(|p| (p.ns, p.rms)).collect(),
            )
            .labels(mine.iter().map(|p| format!("1/{}", 1 << p.e)).collect())
            .line()
        })
        .collect();
    write_plot(
        dir,
        "volume_steps.svg",
        "volume marching: time per ray against RMS error to the closed form (labels: dt)",
        1,
        (760, 480),
        &[Panel::new(
            "exponential atmosphere, x8, single thread",
            "ns per ray",
            "RMS error of premultiplied RGBA",
            true,
            true,
            series,
        )],
    )?;
    writeln!(md, "![time per ray against error, log-log](volume_steps.svg)\n")?;
    Ok(md)
}

// ---------------------------------------------------------------------------------------------
// 5. Early ray termination

fn camera(side: u32) -> Vec<Ray> {
    pinhole_rays(Vec3::new(2.2, -2.9, 1.6), Vec3::ZERO, 36.0, side, side)
}

fn section_termination(dir: &Path) -> Res<String> {
    let pg = Progress::start("5/6 early termination");
    let n = 128;
    let data = quantise(&marschner_lobb(n));
    let vol = unit_volume(&data, n)?;
    let rays = camera(96);
    let step = vol.spacing().x * 0.5;
    let eps_list: [Option<f32>; 8] = [
        None,
        Some(0.0),
        Some(1e-3),
        Some(1.0 / 256.0),
        Some(0.01),
        Some(0.05),
        Some(0.1),
        Some(0.3),
    ];
    let mut md = String::new();
    writeln!(
        md,
        "## 5. Early ray termination\n\n\
         **Trade-off.** `MarchParams::termination = Some(eps)` stops a ray once its transmittance \
         `1 - A` is at most `eps` (opacity threshold `1 - eps`): fewer samples, and per the docs an \
         error of at most `eps max|c|` per colour channel and `eps` in `A`. `Some(0)` stops only at \
         `A == 1` and is exact.\n\n\
         **How measured.** `benches/volume.rs`' termination scene: a Marschner-Lobb volume \
         (`volume::procedural::marschner_lobb({n})`, quantised to `u8`) with its colour ramp at \
         two extinction gains: 400 (opaque: a half-voxel step has opacity 0.5 to 0.99) and 20 \
         (semi-transparent), {} rays of a 96 x 96 pinhole camera, step 1/2 voxel, midpoint \
         sampling, `integrate_x8`, median of 5 runs. Error: against the same image without \
         termination, the largest colour-channel difference, the largest `A` difference and the \
         RMS over all four channels; bound: `eps * TransferFunction::max_color()`.\n",
        rays.len()
    )?;
    let mut panels = Vec::new();
    for (medium, gain) in [("opaque", 400.0f32), ("semi-transparent", 20.0)] {
        let table = ramp(0, 255, gain);
        let tf = TransferFunction::new(&table, 0.0, 255.0)?;
        let maxc = tf.max_color() as f64;
        let m = VolumeMedium::new(vol, tf);
        let mut full = vec![Rgba::ZERO; rays.len()];
        integrate_x8(&m, &rays, &mut full, &MarchParams::reference(step))?;
        writeln!(
            md,
            "**{medium}** (gain {gain}, max|c| = {maxc:.2}):\n\n\
             | termination | opacity threshold | ns/ray | speed-up | samples/ray | rays stopped | max colour error | bound eps max\\|c\\| | max A error | RMS error (RGBA) | image identical |\n\
             |---|---|---|---|---|---|---|---|---|---|---|"
        )?;
        let mut out = vec![Rgba::ZERO; rays.len()];
        let mut pts = Vec::new();
        let mut base_ns = 0.0;
        for eps in eps_list {
            let p = MarchParams {
                termination: eps,
                ..MarchParams::reference(step)
            };
            let st = integrate_x8(&m, &rays, &mut out, &p)?;
            let ns = median_s(5, || integrate_x8(&m, &rays, &mut out, &p).expect("valid")) / rays.len() as f64 * 1e9;
            if eps.is_none() {
                base_ns = ns;
            }
            let d = rgba_diffs(&out, &full);
            let max_c = d
                .chunks(4)
                .map(|c| c[0].abs().max(c[1].abs()).max(c[2].abs()))
                .fold(0.0, f64::max);
            let max_a = d.chunks(4).map(|c| c[3].abs()).fold(0.0, f64::max);
            let identical = out.iter().zip(&full).all(|(x, y)| x.bit_eq(y));
            let bound = eps.map(|e| e as f64 * maxc);
            writeln!(
                md,
                "| {} | {} | {} | {:.2}x | {:.1} | {} | {:.2e} | {} | {:.2e} | {:.2e} | {} |",
                eps.map_or("off".into(), |e| format!("Some({})", sig(e as f64))),
                eps.map_or("-".into(), |e| sig(1.0 - e as f64)),
                sig(ns),
                base_ns / ns,
                st.samples as f64 / st.rays.max(1) as f64,
                st.terminated,
                max_c,
                bound.map_or("-".into(), |b| format!("{b:.2e}")),
                max_a,
                rms(&d),
                if identical { "yes" } else { "no" }
            )?;
            if let (Some(e), Some(b)) = (eps, bound) {
                if max_c > b + 1e-6 {
                    writeln!(md, "\n**Bound exceeded at eps = {e}: {max_c:.3e} > {b:.3e}.**\n")?;
                }
                pts.push((e, ns, max_c, b));
            }
        }
        let worst = pts.iter().filter(|p| p.3 > 0.0).map(|p| p.2 / p.3).fold(0.0, f64::max);
        writeln!(
            md,
            "\nLargest measured colour error / bound over `eps > 0`: {worst:.3} ({}).\n",
            if worst <= 1.0 {
                "within the documented bound"
            } else {
                "**above the documented bound**"
            }
        )?;
        pg.note(medium);
        // Exact rows (error 0) cannot sit on a log axis: plotted are eps > 0.
        let pos: Vec<&(f32, f64, f64, f64)> = pts.iter().filter(|p| p.0 > 0.0).collect();
        let labels: Vec<String> = pos.iter().map(|p| format!("eps {}", sig(p.0 as f64))).collect();
        panels.push(Panel::new(
            &format!("{medium} Marschner-Lobb (off: {} ns/ray)", sig(base_ns)),
            "ns per ray",
            "max colour error against no termination",
            false,
            true,
            vec![
                Series::new("measured", PALETTE[0], pos.iter().map(|p| (p.1, p.2)).collect())
                    .labels(labels)
                    .line(),
                Series::new("bound eps max|c|", PALETTE[1], pos.iter().map(|p| (p.1, p.3)).collect())
                    .filled(vec![false; pos.len()])
                    .line(),
            ],
        ));
    }
    write_plot(
        dir,
        "termination.svg",
        "early ray termination: time per ray against image error (x8, single thread)",
        2,
        (620, 440),
        &panels,
    )?;
    writeln!(
        md,
        "![time per ray against error for early termination](termination.svg)\n"
    )?;
    Ok(md)
}

// ---------------------------------------------------------------------------------------------
// 6. Skipping block size, packet switch

fn section_extras(dir: &Path) -> Res<String> {
    let pg = Progress::start("6/6 skipping and packets");
    let mut md = String::new();
    // Empty-space skipping: benches/volume.rs' torus.
    let n = 128;
    let data = torus(n, 0.5, 0.15);
    let vol = unit_volume(&data, n)?;
    let table = ramp(40, 255, 6.0);
    let tf = TransferFunction::new(&table, 0.0, 255.0)?;
    let rays = camera(96);
    let p = MarchParams::reference(vol.spacing().x * 0.5);
    let plain = VolumeMedium::new(vol, tf);
    let mut reference = vec![Rgba::ZERO; rays.len()];
    let st0 = integrate_x8(&plain, &rays, &mut reference, &p)?;
    let mut out = vec![Rgba::ZERO; rays.len()];
    let ns0 = median_s(5, || integrate_x8(&plain, &rays, &mut out, &p).expect("valid")) / rays.len() as f64 * 1e9;
    writeln!(
        md,
        "## 6. Empty-space skipping and the packet switch\n\n\
         ### Macrocell block size\n\n\
         **Trade-off.** Empty-space skipping (`MacrocellGrid`, `VolumeMedium::with_grid`) jumps \
         over macrocells the transfer function makes transparent; the image is bit-identical by \
         design. Smaller blocks find more empty space but cost more grid memory, build time and \
         jumps (`GridParams::fine()` 4, default 8, `coarse()` 16).\n\n\
         **How measured.** `benches/volume.rs`' sparse torus (`torus({n}, 0.5, 0.15)`, `u8`, \
         visible values 40..255), {} camera rays, step 1/2 voxel, midpoint, `integrate_x8`, median \
         of 5; grid: `MacrocellGrid::build` plus `classify`, median of 3.\n\n\
         | grid | build + classify ms | empty macrocells | ns/ray | speed-up | samples/ray | skipped lattice samples/ray | image identical |\n\
         |---|---|---|---|---|---|---|---|\n\
         | none | - | - | {} | 1.00x | {:.1} | 0 | (reference) |",
        rays.len(),
        sig(ns0),
        st0.samples as f64 / st0.rays as f64
    )?;
    let mut skip_pts = vec![];
    for block in [2u32, 4, 8, 16, 32] {
        let gp = GridParams { block };
        let build = median_s(3, || {
            let mut g = MacrocellGrid::build(&vol, gp).expect("grid");
            g.classify(&tf);
            g
        });
        let mut grid = MacrocellGrid::build(&vol, gp)?;
        grid.classify(&tf);
        let m = VolumeMedium::new(vol, tf).with_grid(&grid)?;
        let st = integrate_x8(&m, &rays, &mut out, &p)?;
        let identical = out.iter().zip(&reference).all(|(x, y)| x.bit_eq(y));
        let ns = median_s(5, || integrate_x8(&m, &rays, &mut out, &p).expect("valid")) / rays.len() as f64 * 1e9;
        writeln!(
            md,
            "| block {block} | {} | {:.1}% | {} | {:.2}x | {:.1} | {:.1} | {} |",
            sig(build * 1e3),
            100.0 * grid.empty_fraction(),
            sig(ns),
            ns0 / ns,
            st.samples as f64 / st.rays as f64,
            st.skipped as f64 / st.rays as f64,
            if identical { "yes" } else { "**no**" }
        )?;
        skip_pts.push((block, ns, build * 1e3));
    }
    pg.note("skipping");

    // Packet switch: benches/packet.rs' question on the bunny.
    let s = bunny_scene(256);
    let (b2, _) = Bvh2::build(&s.tris[..], &BuildParams::default())?;
    let b8 = Bvh8::from_bvh2(&b2, &s.tris[..])?;
    let switches = [0u32, 1, 3, 5, 7, packet::DEFAULT_SWITCH];
    writeln!(
        md,
        "\n### Packet traversal: the single-ray switch\n\n\
         **Trade-off.** Packets of 8 rays (`traverse::packet::intersect_batch`) share node visits: \
         a gain for coherent rays, a loss for incoherent ones. Where fewer than `switch` lanes \
         enter a node, the lanes continue as single rays (0: never; 9 = `DEFAULT_SWITCH`: \
         incoherent packets start as single rays). Coherent packets (shared direction signs, \
         close origins) use interval culling whatever the switch. The hits are exact for every \
         switch (checked equal to single-ray traversal here).\n\n\
         **How measured.** The bunny, `BuildParams::default()` collapsed to a BVH8, Möller-Trumbore; \
         {} primary rays in 4 x 2 pixel tiles and {} diffuse rays; 9 rounds, each timing every row once, median per row.\n\n\
         | traversal | primary Mrays/s | diffuse Mrays/s | primary / single | diffuse / single |\n|---|---|---|---|---|",
        s.primary.len(),
        s.diffuse.len()
    )?;
    // Configurations: None = single rays, Some(switch) = packets. Timed round-robin (one run of
    // each per round, median over rounds), so that drift in the machine's speed hits all alike.
    let configs: Vec<Option<u32>> = std::iter::once(None).chain(switches.iter().map(|&w| Some(w))).collect();
    let run = |c: Option<u32>, rays: &[Ray], hits: &mut [Option<Hit>]| match c {
        None => {
            for (h, r) in hits.iter_mut().zip(rays) {
                *h = b8.intersect::<Moller>(r);
            }
        }
        Some(sw) => packet::intersect_batch::<Moller, _, 8>(b8.view(), rays, hits, sw),
    };
    let mut rates = Vec::new();
    for rays in [&s.primary, &s.diffuse] {
        let mut want = vec![None; rays.len()];
        run(None, rays, &mut want);
        let mut hits = vec![None; rays.len()];
        for &c in &configs {
            run(c, rays, &mut hits);
            if hits != want {
                return Err(format!("packet switch {c:?}: hits differ from single rays").into());
            }
        }
        let mut t = vec![Vec::new(); configs.len()];
        for _ in 0..9 {
            for (k, &c) in configs.iter().enumerate() {
                let s = Instant::now();
                run(c, rays, &mut hits);
                black_box(&hits);
                t[k].push(s.elapsed().as_secs_f64());
            }
        }
        rates.push(
            t.into_iter()
                .map(|mut v| {
                    v.sort_by(f64::total_cmp);
                    rays.len() as f64 / v[v.len() / 2] / 1e6
                })
                .collect::<Vec<f64>>(),
        );
    }
    let (sp, sd) = (rates[0][0], rates[1][0]);
    let mut pk_pts = vec![];
    for (k, c) in configs.iter().enumerate() {
        let (p, d) = (rates[0][k], rates[1][k]);
        let name = match c {
            None => "single rays (`Bvh8::intersect`)".to_string(),
            Some(sw) => format!(
                "packets of 8, switch {sw}{}",
                if *sw == packet::DEFAULT_SWITCH {
                    " (default)"
                } else {
                    ""
                }
            ),
        };
        writeln!(
            md,
            "| {name} | {} | {} | {:.2}x | {:.2}x |",
            sig(p),
            sig(d),
            p / sp,
            d / sd
        )?;
        if let Some(sw) = c {
            pk_pts.push((*sw, p / sp, d / sd));
        }
    }
    md.push('\n');
    pg.note("packets");
    let labels = |v: Vec<u32>, f: &dyn Fn(u32) -> String| v.into_iter().map(f).collect::<Vec<_>>();
    let blocks: Vec<u32> = skip_pts.iter().map(|p| p.0).collect();
    let panels = [
        Panel::new(
            "skipping: macrocell block size (torus 128^3)",
            "grid build + classify, ms",
            "ns per ray",
            true,
            false,
            vec![
                Series::new("with grid", PALETTE[0], skip_pts.iter().map(|p| (p.2, p.1)).collect())
                    .labels(labels(blocks, &|b| format!("block {b}")))
                    .line(),
            ],
        ),
        Panel::new(
            "packets of 8 against single rays (bunny, BVH8)",
            "switch (lanes below which a packet splits)",
            "speed relative to single rays",
            false,
            false,
            vec![
                Series::new(
                    "primary",
                    PALETTE[0],
                    pk_pts.iter().map(|p| (p.0 as f64, p.1)).collect(),
                )
                .line(),
                Series::new(
                    "diffuse",
                    PALETTE[1],
                    pk_pts.iter().map(|p| (p.0 as f64, p.2)).collect(),
                )
                .line(),
            ],
        ),
    ];
    write_plot(
        dir,
        "extras.svg",
        "empty-space skipping (no grid: ns per ray in the table) and the packet switch",
        2,
        (620, 420),
        &panels,
    )?;
    writeln!(md, "![skipping block size and packet switch](extras.svg)\n")?;
    Ok(md)
}

// ---------------------------------------------------------------------------------------------
// The page

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into())
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".into())
}

/// Today's date (UTC) from the system clock, `YYYY-MM-DD` (Hinnant's civil-from-days).
fn today() -> String {
    let secs = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs()) as i64;
    let z = secs.div_euclid(86_400) + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

fn simd_line() -> &'static str {
    if cfg!(target_feature = "avx2") {
        "AVX2 build (`f32x8` is one register)"
    } else if cfg!(target_feature = "avx") {
        "AVX build (`f32x8` is one register)"
    } else {
        "SSE build (`f32x8` is two halves)"
    }
}

fn main() -> Res<()> {
    let dir: PathBuf = std::env::args_os()
        .nth(1)
        .map_or_else(|| PathBuf::from("out/report"), PathBuf::from);
    std::fs::create_dir_all(&dir)?;
    let start = Instant::now();
    let load_start = load_average();
    let threads = std::thread::available_parallelism().map_or(0, |n| n.get());
    eprintln!("[report] writing {}", dir.display());
    type Section = fn(&Path) -> Res<String>;
    let sections: [Section; 6] = [
        section_triangles,
        section_builders,
        section_morton,
        section_volume_steps,
        section_termination,
        section_extras,
    ];
    // For working on one section: STRAHL_REPORT_SECTIONS=2,3 runs only those (the page says so).
    let only: Option<Vec<usize>> = std::env::var("STRAHL_REPORT_SECTIONS")
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect());
    let mut body = String::new();
    for (i, s) in sections.iter().enumerate() {
        if only.as_ref().is_none_or(|o| o.contains(&(i + 1))) {
            body.push_str(&s(&dir)?);
        }
    }
    if let Some(o) = &only {
        body.insert_str(
            0,
            &format!("**Partial run: sections {o:?} only (`STRAHL_REPORT_SECTIONS`).**\n\n"),
        );
    }
    let total = start.elapsed().as_secs_f64();
    let shown_dir = dir.display().to_string();
    let command = if shown_dir == "out/report" {
        "cargo run --release --example report".to_string()
    } else {
        format!("cargo run --release --example report -- {shown_dir}")
    };
    let mut md = String::new();
    writeln!(
        md,
        "# strahl: run time against error, every trade-off\n\n\
         Generated by `{command}` (`examples/report.rs`) from this run's measurements; nothing on \
         this page is typed in. Machine: {} ({threads} hardware threads visible), {}, strahl {}, \
         {}; load average {load_start} at the start and {} at the end; the whole run took {total:.0} s.\n\n\
         Everything runs on **one thread**; each time is the **median** of several repetitions \
         (`std::time::Instant`). The machine is shared (2 cores, other jobs running), so absolute \
         times move by 10-30% between runs: **read the ratios** between rows of one table, which \
         come from the same run minutes apart.\n\n\
         Contents: [1. ray/triangle](#1-raytriangle-möller-trumbore-against-watertight) · \
         [2. builders](#2-bvh2-builders-build-time-against-tree-quality-and-trace-time) · \
         [3. Morton bits](#3-morton-codes-30-against-63-bits) · \
         [4. volume step and sampling](#4-volume-marching-step-size-and-sampling-rule) · \
         [5. early termination](#5-early-ray-termination) · \
         [6. skipping, packets](#6-empty-space-skipping-and-the-packet-switch)\n",
        cpu_model(),
        simd_line(),
        env!("CARGO_PKG_VERSION"),
        today(),
        load_average(),
    )?;
    md.push_str(&body);
    let path = dir.join("report.md");
    std::fs::write(&path, md)?;
    eprintln!("[report] wrote {} in {total:.1} s", path.display());
    println!("{}", path.display());
    Ok(())
}
