//! BVH2 construction: every builder side by side, strahl's and its peers', one criterion group per
//! scene, single thread; then `build_threads/soup1M`, the parallel builds on 1 thread and on every
//! core.
//!
//! ```text
//! cargo bench --bench build -- --noplot                       # bunny and the 1M-triangle soup
//! cargo bench --features embree --bench build -- --noplot     # + Embree 3's rtcBuildBVH
//! cargo bench --features embree,tinybvh --bench build -- --noplot   # + tinybvh (see below)
//! STRAHL_BENCH_SCENES=all cargo bench --bench build -- --noplot   # + 1M terrain, 1M sphereflake
//! STRAHL_BENCH_SCENES=terrain1M,sphereflake1M cargo bench ...     # any list of the four
//! cargo bench --bench build -- --noplot build_threads         # the parallel builds only
//! STRAHL_BENCH_SCENES=none cargo bench --bench build -- --noplot refit/   # refit against rebuild only
//! ```
//!
//! Criterion reports build throughput as `thrpt` in elements (triangles) per second, for *warm*
//! builds: one `Builder` and one output `Bvh2` reused across iterations, as a renderer that
//! rebuilds every frame would (no new pages to fault in; see `build::Builder`). After each group
//! a table is printed for the same builders: warm build throughput in Mtri/s (the fastest single
//! build criterion timed), cold (`Bvh2::build`, fresh memory; best of 3, or one build where one
//! takes over a second), the SAH cost of the tree (`C_T = C_I = 1`, normalised by the root
//! area), its shape (from `Bvh2::validate`), and the speed of the scalar BVH2 reference traversal
//! (`traverse::intersect_scalar`, watertight test) on one fixed set of rays per scene, in million
//! rays per second (best of up to 3 passes within a second). Builders filtered out of the
//! criterion run are timed best of 3 there as well.
//!
//! Scenes: the Stanford bunny (`scene::bunny()`, 3,674 triangles) and `scene::thin_soup(1 << 20)`
//! (1,048,576 long thin triangles, heavily overlapping boxes), plus optionally
//! `scene::terrain(724)` (1,048,352) and `scene::sphereflake(3, 3)` (1,049,600).
//!
//! # Peers
//! Members `peer/<crate>/<builder>` of the same groups, all single-threaded:
//! - `peer/bvh/build`: the `bvh` crate's `Bvh::build` (binned SAH, one triangle per leaf; built
//!   without its `rayon` feature). Its API has no reusable builder, so criterion times cold builds
//!   and the table has no warm column for it.
//! - `peer/obvhs/<preset>`: `obvhs` 0.4 (without its `parallel` feature), PLOC (Meister and
//!   Bittner 2018) with reinsertion (Meister and Bittner 2022) and leaf collapsing, at its
//!   `BvhBuildParams` presets. Cold: `bvh2::builder::build_bvh2_from_tris`; warm: the same steps
//!   with one `PlocBuilder`, `ReinsertionOptimizer` and output `Bvh2` kept between builds. The
//!   `slow` preset runs without its `pre_split` (split triangles sit in several leaves, which a
//!   strahl `Bvh2` does not allow). Its presets collapse leaves (up to 8) with a traversal cost of
//!   3, not the `C_T = 1` the table's SAH cost uses: fewer, larger leaves than strahl's.
//! - `peer/embree/<quality>` (feature `embree`): Embree 3's `rtcBuildBVH` over the triangles'
//!   boxes, branching factor 2, leaves of 1 to 8, `C_T = C_I = 1`, a device with one thread; its
//!   callbacks create the nodes in Embree's allocator. Warm: one `RTCBVH` rebuilt; cold: a new one
//!   per build. `low` is its Morton builder, `medium` binned SAH; `high` adds spatial splits only
//!   with a split callback, so without one Embree runs the binned SAH builder for it as well;
//!   `high+splits` gives one (`splitPrimitive`, clipping with `strahl::build::clip_triangle`, room
//!   for up to 2 references per triangle): Embree's spatial-split builder, the peer of strahl's
//!   `spatial` members (both checked with `Bvh2::validate_split`; where Embree's leaves hold both
//!   parts of a triangle, it is kept once in the converted tree).
//!
//! - `peer/tinybvh/<builder>` (feature `tinybvh`; `bash benches/peers/tinybvh_fetch.sh` and
//!   `TINYBVH_DIR`): tinybvh 1.6.8 (Jacco Bikker's single-header C++ library), compiled with
//!   `-O3 -march=native` and `NO_THREADED_BUILDS`: `Build` (binned SAH, 8 bins on three axes
//!   over the node's box, the SAH leaf rule with `C_T = C_I = 1`) and `BuildAVX` (the same with
//!   AVX binning), and `BuildHQ` (its SBVH: binned SAH with spatial splits, checked with
//!   `validate_split`, both parts of a triangle in one leaf kept once in the converted tree, as
//!   for Embree's; its clipping rounds to nearest, not outwards, so its leaf boxes miss slivers
//!   of split triangles by fractions of an ulp or more: the converted boxes are widened by the
//!   fewest of 1, 2, 4, ..., 64 ulps that passes, which the summary prints). Its input is a
//!   vertex array (three 16-byte vertices per triangle), converted untimed; the triangles' boxes
//!   are computed inside its timed build. Warm: one `BVH` object rebuilt; cold: a new one per
//!   build.
//!
//! Every peer's build time includes computing the triangles' boxes, as strahl's does. Each peer's
//! tree is then converted (untimed) to a strahl `Bvh2`, depth first with siblings adjacent and the
//! leaves' primitives in leaf order (the layout strahl's top-down builders make), checked with
//! `Bvh2::validate` (`validate_split` for spatial splits), and measured as strahl's trees are: `sah_cost(1.0, 1.0)` and the scalar
//! trace, which must find the same number of hits for every tree.
//!
//! # Pareto data
//! After the last scene, `out/build_pareto.svg` (cold build time against SAH cost and against
//! trace time, one column per scene) and `out/build_pareto.md` (the same numbers as tables) are
//! written from this run's measurements, marking the contenders that no other beats on both
//! build time and SAH cost (and, separately, on build time and trace time).

#[path = "common/mod.rs"]
mod common;
#[path = "peers/mod.rs"]
mod peers;

use common::BvhCrateTri;

use criterion::{
    BenchmarkGroup, Criterion, SamplingMode, Throughput, criterion_group, criterion_main, measurement::WallTime,
};
use plotters::prelude::*;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::hint::black_box;
use std::time::{Duration, Instant};
use strahl::build::{
    BinAxes, BuildParams, Builder, Bvh2, BvhStats, MortonBits, Node, Refine, ReinsertParams, SpatialSplits,
    TreeletParams,
};
use strahl::geometry::Triangle;
use strahl::layout::{Bvh4, Bvh8};
use strahl::scene::{self, Rng};
use strahl::traverse::{Moller, STACK_SIZE, Watertight, intersect_scalar};
use strahl::{Aabb, Ray, Vec3};

struct Scene {
    name: &'static str,
    tris: Vec<Triangle>,
    rays: Vec<Ray>,
}

/// Rays from a sphere around the scene (1.5 bounding radii out) towards random points in its box.
fn rays_for(tris: &[Triangle], count: usize) -> Vec<Ray> {
    let mut b = Aabb::EMPTY;
    for t in tris {
        for v in t {
            b.grow(*v);
        }
    }
    let mut r = Rng::new(42);
    let (c, radius) = (b.centroid(), b.extent().length() * 0.75);
    (0..count)
        .map(|_| {
            let o = c + r.unit_vector() * radius;
            let target = b.min + b.extent() * Vec3::new(r.f32(), r.f32(), r.f32());
            Ray::new(o, (target - o).normalize())
        })
        .collect()
}

/// The scenes of `STRAHL_BENCH_SCENES`: `all`, or a comma-separated list of `bunny`, `soup1M`,
/// `terrain1M`, `sphereflake1M`; unset: the bunny and the soup.
fn scenes() -> Vec<Scene> {
    let pick = std::env::var("STRAHL_BENCH_SCENES").unwrap_or_else(|_| "bunny,soup1M".into());
    let want = |name: &str| pick == "all" || pick.split(',').any(|s| s == name);
    let mut v = Vec::new();
    if want("bunny") {
        v.push(("bunny", scene::bunny().to_soup(), 200_000));
    }
    if want("soup1M") {
        v.push(("soup1M", scene::thin_soup(1 << 20, 1), 50_000));
    }
    if want("terrain1M") {
        v.push(("terrain1M", scene::terrain(724, 1).to_soup(), 50_000));
    }
    if want("sphereflake1M") {
        v.push(("sphereflake1M", scene::sphereflake(3, 3).to_soup(), 50_000));
    }
    v.into_iter()
        .map(|(name, tris, nrays)| {
            let rays = rays_for(&tris, nrays);
            Scene { name, tris, rays }
        })
        .collect()
}

/// Every strahl builder, fastest build first (the presets, plus variants between them). A new
/// builder is one line here: it joins the criterion groups, the tables and the Pareto plot.
fn builders() -> Vec<(&'static str, BuildParams)> {
    vec![
        ("lbvh30 (fastest)", BuildParams::fastest()),
        (
            "lbvh63",
            BuildParams {
                morton_bits: MortonBits::Bits63,
                ..BuildParams::fastest()
            },
        ),
        ("median", BuildParams::median()),
        ("binned8-longest (fast)", BuildParams::fast()),
        (
            "binned8-longest, unsampled",
            BuildParams {
                bin_sample: 0,
                ..BuildParams::fast()
            },
        ),
        (
            "binned8-all",
            BuildParams {
                bin_axes: BinAxes::All,
                ..BuildParams::fast()
            },
        ),
        ("binned16-all (balanced)", BuildParams::balanced()),
        (
            "binned16-all, unsampled",
            BuildParams {
                bin_sample: 0,
                ..BuildParams::balanced()
            },
        ),
        (
            "binned32-all",
            BuildParams {
                bins: 32,
                ..BuildParams::balanced()
            },
        ),
        (
            "binned64-all",
            BuildParams {
                bins: 64,
                ..BuildParams::balanced()
            },
        ),
        ("binned64-all+rotations (high)", BuildParams::high()),
        ("sweep (quality)", BuildParams::quality()),
        (
            "hlbvh",
            BuildParams {
                refine: Refine::None,
                ..BuildParams::hybrid()
            },
        ),
        ("hlbvh+treelets (hybrid)", BuildParams::hybrid()),
        ("hlbvh-sah (hybrid_sah)", BuildParams::hybrid_sah()),
        ("ploc", BuildParams::ploc()),
        (
            "lbvh30+rotations",
            BuildParams {
                refine: Refine::Rotations(1),
                ..BuildParams::fastest()
            },
        ),
        (
            "binned64-all+reinsertion",
            BuildParams {
                refine: Refine::Reinsertion(ReinsertParams::new()),
                ..BuildParams::high()
            },
        ),
        (
            "binned8-longest+treelets",
            BuildParams {
                refine: Refine::Treelets(TreeletParams::new()),
                ..BuildParams::fast()
            },
        ),
        (
            "lbvh30+treelets",
            BuildParams {
                refine: Refine::Treelets(TreeletParams::new()),
                ..BuildParams::fastest()
            },
        ),
        (
            "lbvh30+agglomerative treelets",
            BuildParams {
                refine: Refine::AgglomerativeTreelets(TreeletParams::agglomerative()),
                ..BuildParams::fastest()
            },
        ),
        (
            "hlbvh-sah+agglomerative treelets",
            BuildParams {
                refine: Refine::AgglomerativeTreelets(TreeletParams {
                    rounds: 1,
                    ..TreeletParams::agglomerative()
                }),
                ..BuildParams::hybrid_sah()
            },
        ),
    ]
}

/// strahl's spatial-split builds (`Bvh2::build_spatial`): cold builds only (no reusable
/// builder), checked with `validate_split` (their leaves share and cut triangles).
fn spatial_builders() -> Vec<(&'static str, BuildParams, SpatialSplits)> {
    vec![
        ("spatial (sbvh)", BuildParams::default(), SpatialSplits::default()),
        (
            "spatial, binned64-all",
            BuildParams {
                bins: 64,
                ..BuildParams::default()
            },
            SpatialSplits::default(),
        ),
    ]
}

// ---- peers: each keeps its input (prepared untimed) and its last tree ----

/// A peer builder. `cold` and `warm` return the time of one build (the previous tree is dropped
/// outside the timed part); `tree` converts the last tree to a `Bvh2`.
trait Peer {
    /// The criterion member name, `peer/<crate>/<builder>`.
    fn name(&self) -> String;
    /// One build with fresh memory.
    fn cold(&mut self) -> Duration;
    /// One build reusing the peer's memory, `None` where its API has no way to.
    fn warm(&mut self) -> Option<Duration>;
    /// The last tree (cold, else warm) as a `Bvh2`.
    fn tree(&self) -> Bvh2;
    /// Whether its leaves may share and cut primitives (spatial splits: checked with
    /// `validate_split`).
    fn split(&self) -> bool {
        false
    }
    /// Whether its spatial-split leaf boxes may miss slivers of split triangles by rounding (its
    /// clipping rounds to nearest, not outwards): the converted boxes are then widened by the
    /// fewest of 1, 2, 4, ..., 64 ulps that passes `validate_split`, and that count printed.
    fn widen_split_boxes(&self) -> bool {
        false
    }
}

/// Every box of `bvh` moved `ulps` floats outwards (nested boxes stay nested).
fn widen_boxes(bvh: &mut Bvh2, ulps: u32) {
    for n in &mut bvh.nodes {
        for k in 0..3 {
            for _ in 0..ulps {
                n.min[k] = n.min[k].next_down();
                n.max[k] = n.max[k].next_up();
            }
        }
    }
}

/// Converts a peer's binary tree to a `Bvh2`: depth first, each pair of siblings allocated
/// together (root at 0, pairs from 1), each leaf's primitives appended in leaf order. `expand`
/// appends a leaf's primitive indices and returns `None`, or returns an interior node's two
/// children with their boxes.
fn convert<N: Copy>(
    root: Option<(Aabb, N)>,
    mut expand: impl FnMut(N, &mut Vec<u32>) -> Option<[(Aabb, N); 2]>,
) -> Bvh2 {
    let mut out = Bvh2::default();
    let Some((root_box, root)) = root else {
        return out;
    };
    out.nodes.push(Node::interior(&root_box, 0));
    let mut stack = vec![(0usize, root)];
    while let Some((i, n)) = stack.pop() {
        let b = out.nodes[i].aabb();
        let first = out.prim_indices.len() as u32;
        match expand(n, &mut out.prim_indices) {
            None => {
                let count = out.prim_indices.len() as u32 - first;
                out.nodes[i] = Node::leaf(&b, first, count);
            }
            Some([(lb, l), (rb, r)]) => {
                let left = out.nodes.len();
                out.nodes[i] = Node::interior(&b, left as u32);
                out.nodes.push(Node::interior(&lb, 0));
                out.nodes.push(Node::interior(&rb, 0));
                // Left child on top: depth-first, left subtree first.
                stack.push((left + 1, r));
                stack.push((left, l));
            }
        }
    }
    out
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, Duration) {
    let t = Instant::now();
    let r = f();
    (r, t.elapsed())
}

struct BvhCratePeer {
    shapes: Vec<BvhCrateTri>,
    out: Option<bvh::bvh::Bvh<f32, 3>>,
}

impl BvhCratePeer {
    fn new(tris: &[Triangle]) -> Self {
        let p = |v: Vec3| nalgebra::Point3::new(v.x, v.y, v.z);
        let shapes = tris
            .iter()
            .map(|t| BvhCrateTri {
                a: p(t[0]),
                b: p(t[1]),
                c: p(t[2]),
                node: 0,
            })
            .collect();
        Self { shapes, out: None }
    }
}

fn bvh_crate_aabb(b: &bvh::aabb::Aabb<f32, 3>) -> Aabb {
    Aabb::new(
        Vec3::new(b.min.x, b.min.y, b.min.z),
        Vec3::new(b.max.x, b.max.y, b.max.z),
    )
}

impl Peer for BvhCratePeer {
    fn name(&self) -> String {
        "peer/bvh/build".into()
    }
    fn cold(&mut self) -> Duration {
        self.out = None;
        let (bvh, t) = timed(|| bvh::bvh::Bvh::build(&mut self.shapes));
        self.out = Some(bvh);
        t
    }
    fn warm(&mut self) -> Option<Duration> {
        None
    }
    fn tree(&self) -> Bvh2 {
        use bvh::aabb::Bounded;
        use bvh::bvh::BvhNode;
        let Some(bvh) = self.out.as_ref().filter(|b| !b.nodes.is_empty()) else {
            return Bvh2::default();
        };
        let root_box = match bvh.nodes[0] {
            BvhNode::Leaf { shape_index, .. } => bvh_crate_aabb(&self.shapes[shape_index].aabb()),
            BvhNode::Node {
                child_l_aabb,
                child_r_aabb,
                ..
            } => bvh_crate_aabb(&child_l_aabb).union(&bvh_crate_aabb(&child_r_aabb)),
        };
        convert(Some((root_box, 0usize)), |i, prims| match bvh.nodes[i] {
            BvhNode::Leaf { shape_index, .. } => {
                prims.push(shape_index as u32);
                None
            }
            BvhNode::Node {
                child_l_index,
                child_l_aabb,
                child_r_index,
                child_r_aabb,
                ..
            } => Some([
                (bvh_crate_aabb(&child_l_aabb), child_l_index),
                (bvh_crate_aabb(&child_r_aabb), child_r_index),
            ]),
        })
    }
}

struct ObvhsPeer {
    preset: &'static str,
    params: obvhs::BvhBuildParams,
    tris: Vec<obvhs::triangle::Triangle>,
    out: Option<obvhs::bvh2::Bvh2>,
    // Warm builds: kept between builds.
    ploc: obvhs::ploc::PlocBuilder,
    reinsertion: obvhs::bvh2::reinsertion::ReinsertionOptimizer,
    warm_out: obvhs::bvh2::Bvh2,
}

impl ObvhsPeer {
    fn new(tris: &[Triangle], preset: &'static str, params: obvhs::BvhBuildParams) -> Self {
        let tris = tris
            .iter()
            .map(|t| obvhs::triangle::Triangle {
                v0: t[0].into(),
                v1: t[1].into(),
                v2: t[2].into(),
            })
            .collect();
        Self {
            preset,
            params,
            tris,
            out: None,
            ploc: obvhs::ploc::PlocBuilder::new(),
            reinsertion: Default::default(),
            warm_out: Default::default(),
        }
    }
}

/// The presets, fastest first; `pre_split` off (see the module docs).
fn obvhs_presets() -> Vec<(&'static str, obvhs::BvhBuildParams)> {
    use obvhs::BvhBuildParams as P;
    vec![
        ("fastest", P::fastest_build()),
        ("very_fast", P::very_fast_build()),
        ("fast", P::fast_build()),
        ("medium", P::medium_build()),
        (
            "slow-nosplit",
            P {
                pre_split: false,
                ..P::slow_build()
            },
        ),
    ]
}

impl Peer for ObvhsPeer {
    fn name(&self) -> String {
        format!("peer/obvhs/{}", self.preset)
    }
    fn cold(&mut self) -> Duration {
        self.out = None;
        let (bvh, t) =
            timed(|| obvhs::bvh2::builder::build_bvh2_from_tris(&self.tris, self.params, &mut Duration::default()));
        self.out = Some(bvh);
        t
    }
    fn warm(&mut self) -> Option<Duration> {
        // `build_bvh2_from_tris` without `pre_split`, step by step, with kept memory.
        let p = self.params;
        let bvh = &mut self.warm_out;
        let mut indices = std::mem::take(&mut bvh.primitive_indices);
        let t = Instant::now();
        indices.clear();
        indices.extend(0..self.tris.len() as u32);
        self.ploc.build_with_bvh(
            bvh,
            p.ploc_search_distance,
            &self.tris,
            indices,
            p.sort_precision,
            p.search_depth_threshold,
        );
        self.reinsertion.run(bvh, p.reinsertion_batch_ratio, None);
        obvhs::bvh2::leaf_collapser::collapse(bvh, p.max_prims_per_leaf.clamp(1, 255), p.collapse_traversal_cost);
        self.reinsertion.run(
            bvh,
            p.reinsertion_batch_ratio * p.post_collapse_reinsertion_batch_ratio_multiplier,
            None,
        );
        Some(t.elapsed())
    }
    fn tree(&self) -> Bvh2 {
        let bvh = self.out.as_ref().unwrap_or(&self.warm_out);
        let node_box = |i: usize| {
            let b = bvh.nodes[i].aabb();
            Aabb::new(b.min.into(), b.max.into())
        };
        let root = (!bvh.nodes.is_empty()).then(|| (node_box(0), 0usize));
        convert(root, |i, prims| {
            let n = &bvh.nodes[i];
            let first = n.first_index as usize;
            if n.prim_count > 0 {
                prims.extend_from_slice(&bvh.primitive_indices[first..first + n.prim_count as usize]);
                None
            } else {
                Some([(node_box(first), first), (node_box(first + 1), first + 1)])
            }
        })
    }
}

#[cfg(feature = "embree")]
struct EmbreePeer<'d> {
    device: &'d peers::embree::Device,
    settings: peers::embree::TreeSettings,
    label: &'static str,
    /// Spatial splits (`BuiltTree::build_split`).
    split: bool,
    tris: Vec<Triangle>,
    boxes: Vec<Aabb>,
    cold_out: Option<peers::embree::BuiltTree<'d>>,
    warm_out: peers::embree::BuiltTree<'d>,
}

#[cfg(feature = "embree")]
impl<'d> EmbreePeer<'d> {
    fn new(
        device: &'d peers::embree::Device,
        tris: &[Triangle],
        label: &'static str,
        quality: peers::embree::Quality,
        split: bool,
    ) -> Self {
        Self {
            device,
            settings: peers::embree::TreeSettings {
                quality,
                max_leaf: 8,
                traversal_cost: 1.0,
                intersection_cost: 1.0,
            },
            label,
            split,
            tris: tris.to_vec(),
            boxes: Vec::new(),
            cold_out: None,
            warm_out: peers::embree::BuiltTree::new(device),
        }
    }
}

#[cfg(feature = "embree")]
impl Peer for EmbreePeer<'_> {
    fn name(&self) -> String {
        format!("peer/embree/{}", self.label)
    }
    fn cold(&mut self) -> Duration {
        self.cold_out = None;
        let (tree, t) = timed(|| {
            let boxes: Vec<Aabb> = self.tris.iter().map(|t| Aabb::from_points(t)).collect();
            let mut tree = peers::embree::BuiltTree::new(self.device);
            if self.split {
                tree.build_split(&boxes, &self.tris, &self.settings);
            } else {
                tree.build(&boxes, &self.settings);
            }
            tree
        });
        self.cold_out = Some(tree);
        t
    }
    fn warm(&mut self) -> Option<Duration> {
        let t = Instant::now();
        self.boxes.clear();
        self.boxes.extend(self.tris.iter().map(|t| Aabb::from_points(t)));
        if self.split {
            self.warm_out.build_split(&self.boxes, &self.tris, &self.settings);
        } else {
            self.warm_out.build(&self.boxes, &self.settings);
        }
        Some(t.elapsed())
    }
    fn split(&self) -> bool {
        self.split
    }
    fn tree(&self) -> Bvh2 {
        use peers::embree::TreeNodeKind;
        let tree = self.cold_out.as_ref().unwrap_or(&self.warm_out);
        let split = self.split;
        convert(tree.root(), |n, prims| match tree.node(n) {
            TreeNodeKind::Leaf(ids) => {
                let start = prims.len();
                for &id in ids {
                    // Embree's spatial splits may leave both parts of a triangle in one leaf:
                    // kept once (redundant for traversal; `validate_split` rejects repeats).
                    if !(split && prims[start..].contains(&id)) {
                        prims.push(id);
                    }
                }
                None
            }
            TreeNodeKind::Inner(children) => Some(children),
        })
    }
}

/// tinybvh's binary builders (feature `tinybvh`). Its input is the vertex array (three
/// 16-byte vertices per triangle), converted untimed.
#[cfg(feature = "tinybvh")]
struct TinybvhPeer {
    builder: peers::tinybvh::Builder,
    label: &'static str,
    /// `BuildHQ`: spatial splits (a triangle may sit in several leaves).
    split: bool,
    tris: Vec<Triangle>,
    cold_out: Option<peers::tinybvh::Bvh>,
    warm_out: peers::tinybvh::Bvh,
}

#[cfg(feature = "tinybvh")]
impl TinybvhPeer {
    fn new(tris: &[Triangle], label: &'static str, builder: peers::tinybvh::Builder) -> Self {
        Self {
            builder,
            label,
            split: matches!(builder, peers::tinybvh::Builder::BuildHq),
            tris: tris.to_vec(),
            cold_out: None,
            warm_out: peers::tinybvh::Bvh::new(tris),
        }
    }
}

#[cfg(feature = "tinybvh")]
impl Peer for TinybvhPeer {
    fn name(&self) -> String {
        format!("peer/tinybvh/{}", self.label)
    }
    fn cold(&mut self) -> Duration {
        self.cold_out = None;
        // A fresh tree (no memory from an earlier build); the vertices are its input.
        let mut fresh = peers::tinybvh::Bvh::new(&self.tris);
        let (_, t) = timed(|| fresh.build(self.builder));
        self.cold_out = Some(fresh);
        t
    }
    fn warm(&mut self) -> Option<Duration> {
        let (_, t) = timed(|| self.warm_out.build(self.builder));
        Some(t)
    }
    fn split(&self) -> bool {
        self.split
    }
    fn tree(&self) -> Bvh2 {
        let bvh = self.cold_out.as_ref().unwrap_or(&self.warm_out);
        let (nodes, prim_idx) = bvh.tree();
        let root = nodes.first().map(|n| (n.aabb(), 0usize));
        let split = self.split;
        convert(root, |i, prims| {
            let n = &nodes[i];
            let first = n.index as usize;
            if n.count > 0 {
                let start = prims.len();
                for &id in &prim_idx[first..first + n.count as usize] {
                    // As for Embree's splits: both parts of a triangle in one leaf kept once.
                    if !(split && prims[start..].contains(&id)) {
                        prims.push(id);
                    }
                }
                None
            } else {
                Some([(nodes[first].aabb(), first), (nodes[first + 1].aabb(), first + 1)])
            }
        })
    }
    fn widen_split_boxes(&self) -> bool {
        self.split
    }
}

/// The peers for one scene (their inputs converted here, untimed).
fn peers_for<'d>(s: &Scene, #[cfg(feature = "embree")] device: &'d peers::embree::Device) -> Vec<Box<dyn Peer + 'd>> {
    let mut v: Vec<Box<dyn Peer + 'd>> = vec![Box::new(BvhCratePeer::new(&s.tris))];
    for (name, p) in obvhs_presets() {
        v.push(Box::new(ObvhsPeer::new(&s.tris, name, p)));
    }
    #[cfg(feature = "embree")]
    {
        use peers::embree::Quality;
        for (label, q, split) in [
            ("low", Quality::Low, false),
            ("medium", Quality::Medium, false),
            ("high", Quality::High, false),
            ("high+splits", Quality::High, true),
        ] {
            v.push(Box::new(EmbreePeer::new(device, &s.tris, label, q, split)));
        }
    }
    #[cfg(feature = "tinybvh")]
    {
        use peers::tinybvh::Builder as B;
        for (label, b) in [("Build", B::Build), ("BuildAVX", B::BuildAvx), ("BuildHQ", B::BuildHq)] {
            v.push(Box::new(TinybvhPeer::new(&s.tris, label, b)));
        }
    }
    v
}

/// The fastest single build criterion timed per member and kind (`true`: warm), which the
/// summary reuses instead of timing those builds again.
type Fastest = HashMap<(String, bool), Duration>;

fn record(fastest: &mut Fastest, name: &str, warm: bool, t: Duration) -> Duration {
    let e = fastest.entry((name.to_string(), warm)).or_insert(t);
    *e = (*e).min(t);
    t
}

/// strahl's builders as members of `g`: warm builds (one `Builder` and output tree kept).
fn bench_strahl(g: &mut BenchmarkGroup<'_, WallTime>, s: &Scene, fastest: &mut Fastest) {
    let mut builder = Builder::new();
    let mut bvh = Bvh2::default();
    for (name, p) in builders() {
        g.bench_function(name, |b| {
            b.iter_custom(|iters| {
                (0..iters)
                    .map(|_| {
                        let (stats, t) = timed(|| builder.build_into(black_box(&s.tris[..]), &p, &mut bvh));
                        black_box(stats.expect("valid params"));
                        record(fastest, name, true, t)
                    })
                    .sum()
            })
        });
    }
}

/// strahl's spatial-split builds as members of `g` (cold).
fn bench_spatial(g: &mut BenchmarkGroup<'_, WallTime>, s: &Scene, fastest: &mut Fastest) {
    for (name, p, sp) in spatial_builders() {
        g.bench_function(name, |b| {
            b.iter_custom(|iters| {
                (0..iters)
                    .map(|_| {
                        let (r, t) = timed(|| Bvh2::build_spatial(black_box(&s.tris[..]), &p, &sp));
                        drop(black_box(r.expect("valid params")));
                        record(fastest, name, false, t)
                    })
                    .sum()
            })
        });
    }
}

/// The peers as members of `g`: warm builds where the peer can reuse memory, else cold ones.
fn bench_peers(g: &mut BenchmarkGroup<'_, WallTime>, peers: &mut [Box<dyn Peer + '_>], fastest: &mut Fastest) {
    for p in peers {
        let name = p.name();
        let warm = p.warm().is_some();
        g.bench_function(&name, |b| {
            b.iter_custom(|iters| {
                (0..iters)
                    .map(|_| {
                        let t = if warm { p.warm().expect("warm") } else { p.cold() };
                        record(fastest, &name, warm, t)
                    })
                    .sum()
            })
        });
    }
}

// ---- measurements: the same for every contender ----

/// One contender's numbers on one scene (times in seconds).
struct Row {
    name: String,
    family: &'static str,
    warm: Option<f64>,
    cold: f64,
    sah: f32,
    stats: BvhStats,
    mrays: Option<f64>,
    hits: usize,
}

/// Million rays per second of the scalar reference over the scene's rays (the best of up to three
/// passes while they take under a second in all), and the number of rays that hit.
fn trace_mrays(bvh: &Bvh2, s: &Scene) -> (f64, usize) {
    let (mut best, mut total, mut hits) = (Duration::MAX, Duration::ZERO, 0);
    for _ in 0..3 {
        let start = Instant::now();
        hits = 0;
        for ray in &s.rays {
            hits += intersect_scalar::<Watertight, _>(bvh.view(), &s.tris[..], black_box(ray)).is_some() as usize;
        }
        let t = start.elapsed();
        (best, total) = (best.min(t), total + t);
        if total > Duration::from_secs(1) {
            break;
        }
    }
    (s.rays.len() as f64 / best.as_secs_f64() / 1e6, hits)
}

/// The faster of `first` (a build just timed, which left the tree to measure) and the fastest
/// build criterion timed; where criterion timed none (filtered out), the best of `first` and two
/// more builds by `f`, or `first` alone where it took over a second.
fn best_time(first: Duration, fastest: Option<&Duration>, mut f: impl FnMut() -> Duration) -> f64 {
    let mut best = first;
    match fastest {
        Some(&t) => best = best.min(t),
        None if best < Duration::from_secs(1) => {
            for _ in 0..2 {
                best = best.min(f());
            }
        }
        None => {}
    }
    best.as_secs_f64()
}

/// Validates `bvh` (`validate_split` where `split`: a spatial-split tree) and measures its SAH
/// cost and trace speed.
fn measure(
    s: &Scene,
    name: String,
    family: &'static str,
    warm: Option<f64>,
    cold: f64,
    bvh: &Bvh2,
    split: bool,
) -> Row {
    let stats = if split {
        bvh.validate_split(&s.tris[..])
    } else {
        bvh.validate(&s.tris[..])
    }
    .unwrap_or_else(|e| panic!("{}: {name}: invalid tree: {e}", s.name));
    // Deeper than the stack: the traversal would finish rays by linear scans (exact, but it would
    // time the fallback, not the tree).
    let (mrays, hits) = if stats.max_depth as usize <= STACK_SIZE + 1 {
        let (m, h) = trace_mrays(bvh, s);
        (Some(m), h)
    } else {
        (None, 0)
    };
    Row {
        name,
        family,
        warm,
        cold,
        sah: bvh.sah_cost(1.0, 1.0),
        stats,
        mrays,
        hits,
    }
}

fn summary(s: &Scene, peers: &mut [Box<dyn Peer + '_>], fastest: &Fastest) -> Vec<Row> {
    let mut rows = Vec::new();
    let mut builder = Builder::new();
    let mut bvh = Bvh2::default();
    let get = |name: &str, warm: bool| fastest.get(&(name.to_string(), warm));
    for (name, p) in builders() {
        let cold = || {
            let (r, t) = timed(|| Bvh2::build(&s.tris[..], &p).expect("valid params"));
            drop(black_box(r));
            t
        };
        let cold = best_time(cold(), get(name, false), cold);
        let mut warm = || timed(|| builder.build_into(&s.tris[..], &p, &mut bvh).expect("valid params")).1;
        let warm = best_time(warm(), get(name, true), warm);
        rows.push(measure(s, name.into(), "strahl", Some(warm), cold, &bvh, false));
    }
    for (name, p, sp) in spatial_builders() {
        let build = || Bvh2::build_spatial(&s.tris[..], &p, &sp).expect("valid params");
        let ((tree, _), first) = timed(build);
        let cold = best_time(first, get(name, false), || timed(build).1);
        rows.push(measure(s, name.into(), "strahl", None, cold, &tree, true));
    }
    for p in peers.iter_mut() {
        let name = p.name();
        let warm = p
            .warm()
            .map(|first| best_time(first, get(&name, true), || p.warm().expect("warm")));
        let cold = best_time(p.cold(), get(&name, false), || p.cold());
        let mut tree = p.tree();
        if p.widen_split_boxes() && tree.validate_split(&s.tris[..]).is_err() {
            let mut done = 0;
            for ulps in [1, 2, 4, 8, 16, 32, 64] {
                widen_boxes(&mut tree, ulps - done);
                done = ulps;
                if tree.validate_split(&s.tris[..]).is_ok() {
                    break;
                }
            }
            println!(
                "{}: {name}: leaf boxes missed slivers of split triangles; widened by {done} ulps",
                s.name
            );
        }
        rows.push(measure(s, name.clone(), family_of(&name), warm, cold, &tree, p.split()));
    }
    let n = s.tris.len() as f64;
    let reference = rows[0].hits;
    println!(
        "\n{}: {} triangles, {} rays\n| builder | warm Mtri/s | cold Mtri/s | SAH cost | nodes | leaves | depth | trace Mrays/s | hits |\n|---|---|---|---|---|---|---|---|---|",
        s.name,
        s.tris.len(),
        s.rays.len()
    );
    for r in &rows {
        println!(
            "| {} | {} | {:.2} | {:.2} | {} | {} | {} | {} | {} |",
            r.name,
            r.warm.map_or("-".into(), |w| format!("{:.2}", n / w / 1e6)),
            n / r.cold / 1e6,
            r.sah,
            r.stats.nodes,
            r.stats.leaves,
            r.stats.max_depth,
            r.mrays
                .map_or("- (deeper than the stack)".into(), |m| format!("{m:.3}")),
            r.hits
        );
    }
    for r in rows.iter().filter(|r| r.mrays.is_some()) {
        assert_eq!(
            r.hits, reference,
            "{}: {} finds {} hits, {} {}",
            s.name, r.name, r.hits, rows[0].name, reference
        );
    }
    rows
}

fn family_of(name: &str) -> &'static str {
    ["bvh", "obvhs", "embree", "tinybvh"]
        .into_iter()
        .find(|f| name.starts_with(&format!("peer/{f}/")))
        .unwrap_or("strahl")
}

// ---- Pareto data ----

/// `true` for each row that no other row beats on both `x` and `y` (smaller is better; ties on
/// both count as not beaten).
fn pareto(rows: &[Row], key: impl Fn(&Row) -> Option<(f64, f64)>) -> Vec<bool> {
    rows.iter()
        .map(|r| {
            let Some((x, y)) = key(r) else { return false };
            !rows
                .iter()
                .any(|o| key(o).is_some_and(|(ox, oy)| ox <= x && oy <= y && (ox < x || oy < y)))
        })
        .collect()
}

fn build_vs_sah(r: &Row) -> Option<(f64, f64)> {
    Some((r.cold, r.sah as f64))
}

fn build_vs_trace(r: &Row) -> Option<(f64, f64)> {
    r.mrays.map(|m| (r.cold, 1.0 / m))
}

fn write_markdown(path: &str, scenes: &[(&str, usize, usize, Vec<Row>)]) -> std::io::Result<()> {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# BVH2 builders: build time, SAH cost, trace time\n\n\
         Written by `cargo bench --bench build` from one run's measurements (single thread; best of \
         3 builds, or one where a build takes over a second). Build: cold (fresh memory), and warm \
         where the builder can reuse its memory. SAH cost: `Bvh2::sah_cost(1.0, 1.0)` of each tree \
         converted to a strahl `Bvh2`. Trace: the scalar BVH2 reference traversal \
         (`intersect_scalar`, watertight) over the scene's fixed rays. \
         **P(SAH)**: Pareto-optimal in (cold build time, SAH cost); **P(trace)**: Pareto-optimal \
         in (cold build time, trace time).\n"
    );
    for (name, tris, rays, rows) in scenes {
        let p_sah = pareto(rows, build_vs_sah);
        let p_trace = pareto(rows, build_vs_trace);
        let _ = writeln!(
            md,
            "## {name}: {tris} triangles, {rays} rays\n\n\
             | builder | cold build ms | warm build ms | SAH cost | trace Mrays/s | trace µs/ray | depth | P(SAH) | P(trace) |\n\
             |---|---|---|---|---|---|---|---|---|"
        );
        let mut order: Vec<usize> = (0..rows.len()).collect();
        order.sort_by(|&a, &b| rows[a].cold.total_cmp(&rows[b].cold));
        for i in order {
            let r = &rows[i];
            let _ = writeln!(
                md,
                "| {} | {:.2} | {} | {:.2} | {} | {} | {} | {} | {} |",
                r.name,
                r.cold * 1e3,
                r.warm.map_or("-".into(), |w| format!("{:.2}", w * 1e3)),
                r.sah,
                r.mrays.map_or("-".into(), |m| format!("{m:.3}")),
                r.mrays.map_or("-".into(), |m| format!("{:.2}", 1.0 / m)),
                r.stats.max_depth,
                if p_sah[i] { "**yes**" } else { "" },
                if p_trace[i] { "**yes**" } else { "" },
            );
        }
        md.push('\n');
    }
    std::fs::write(path, md)
}

fn family_color(f: &str) -> RGBColor {
    match f {
        "strahl" => RGBColor(31, 119, 180),
        "bvh" => RGBColor(255, 127, 14),
        "obvhs" => RGBColor(44, 160, 44),
        "tinybvh" => RGBColor(148, 103, 189),
        _ => RGBColor(214, 39, 40),
    }
}

/// One panel: cold build time (ms, log) against `y`, the Pareto front as a staircase, filled
/// markers on it, hollow ones off it, every point labelled.
fn panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
    y_desc: &str,
    rows: &[Row],
    key: fn(&Row) -> Option<(f64, f64)>,
    y_scale: f64,
) -> Result<(), Box<dyn std::error::Error>> {
    let pts: Vec<(usize, f64, f64)> = rows
        .iter()
        .enumerate()
        .filter_map(|(i, r)| key(r).map(|(x, y)| (i, x * 1e3, y * y_scale)))
        .collect();
    if pts.is_empty() {
        return Ok(());
    }
    let front = pareto(rows, key);
    let (x0, x1) = pts
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let (y0, y1) = pts
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), p| (a.min(p.2), b.max(p.2)));
    let pad = (y1 - y0).max(y1 * 0.02) * 0.08;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 15))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(56)
        // Room on the right for the labels of the slowest builders.
        .build_cartesian_2d((x0 * 0.7..x1 * 3.0).log_scale().base(2.0), y0 - pad..y1 + pad)?;
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_labels(8)
        .x_label_formatter(&|v| match *v {
            v if v >= 100.0 => format!("{v:.0}"),
            v if v >= 1.0 => format!("{v:.1}"),
            v => format!("{v:.2}"),
        })
        .x_desc("cold build time, ms (log scale)")
        .y_desc(y_desc)
        .draw()?;
    let mut stair: Vec<(f64, f64)> = pts.iter().filter(|p| front[p.0]).map(|p| (p.1, p.2)).collect();
    stair.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut steps = Vec::new();
    for (k, &(x, y)) in stair.iter().enumerate() {
        if k > 0 {
            steps.push((x, stair[k - 1].1));
        }
        steps.push((x, y));
    }
    chart.draw_series(LineSeries::new(steps, BLACK.mix(0.4).stroke_width(1)))?;
    for family in ["strahl", "bvh", "obvhs", "embree", "tinybvh"] {
        let c = family_color(family);
        let mine: Vec<&(usize, f64, f64)> = pts.iter().filter(|p| rows[p.0].family == family).collect();
        if mine.is_empty() {
            continue;
        }
        chart
            .draw_series(mine.iter().map(|p| {
                let style = if front[p.0] { c.filled() } else { c.stroke_width(2) };
                Circle::new((p.1, p.2), 5, style)
            }))?
            .label(family)
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, c.filled()));
        chart.draw_series(mine.iter().map(|p| {
            let label = rows[p.0].name.trim_start_matches("peer/");
            Text::new(label.to_string(), (p.1 * 1.05, p.2), ("sans-serif", 10))
        }))?;
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE)
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    Ok(())
}

fn write_svg(path: &str, scenes: &[(&str, usize, usize, Vec<Row>)]) -> Result<(), Box<dyn std::error::Error>> {
    let cols = scenes.len().max(1);
    let root = SVGBackend::new(path, (620 * cols as u32, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        "BVH2 builders, one thread: build time against SAH cost and trace time (filled: Pareto-optimal)",
        ("sans-serif", 17),
    )?;
    let areas = root.split_evenly((2, cols));
    for (c, (name, tris, _, rows)) in scenes.iter().enumerate() {
        panel(
            &areas[c],
            &format!("{name} ({tris} triangles): SAH cost"),
            "SAH cost (C_T = C_I = 1)",
            rows,
            build_vs_sah,
            1.0,
        )?;
        panel(
            &areas[cols + c],
            &format!("{name}: scalar trace time"),
            "µs per ray (intersect_scalar)",
            rows,
            build_vs_trace,
            1.0,
        )?;
    }
    root.present()?;
    Ok(())
}

fn build(c: &mut Criterion) {
    #[cfg(feature = "embree")]
    let device = peers::embree::Device::single_threaded();
    let mut results = Vec::new();
    for s in scenes() {
        let mut peers = peers_for(
            &s,
            #[cfg(feature = "embree")]
            &device,
        );
        let mut g = c.benchmark_group(format!("build/{}", s.name));
        g.throughput(Throughput::Elements(s.tris.len() as u64));
        g.sample_size(10);
        // Flat: one build per iteration at 1M triangles takes 0.1 to 3 s; linear sampling would
        // need at least 55 of them per member.
        g.sampling_mode(SamplingMode::Flat);
        g.warm_up_time(Duration::from_millis(500));
        g.measurement_time(Duration::from_secs(if s.tris.len() > 100_000 { 4 } else { 2 }));
        let mut fastest = Fastest::new();
        bench_strahl(&mut g, &s, &mut fastest);
        bench_spatial(&mut g, &s, &mut fastest);
        bench_peers(&mut g, &mut peers, &mut fastest);
        g.finish();
        let rows = summary(&s, &mut peers, &fastest);
        results.push((s.name, s.tris.len(), s.rays.len(), rows));
    }
    std::fs::create_dir_all("out").ok();
    for (path, r) in [
        (
            "out/build_pareto.md",
            write_markdown("out/build_pareto.md", &results).map_err(Into::into),
        ),
        ("out/build_pareto.svg", write_svg("out/build_pareto.svg", &results)),
    ] {
        match r {
            Ok(()) => println!("wrote {path}"),
            Err(e) => println!("could not write {path}: {e}"),
        }
    }
}

/// `build_threads/soup1M`: the parallel builds (`Builder::build_into_par`, warm) of the builders
/// that have one, on 1 thread and on every core (`available_parallelism`), side by side; each
/// parallel tree is checked to have the single-threaded tree's SAH cost. With the `embree`
/// feature, Embree's binned SAH builder on 1 thread and on every core. Spatial splits on the 262k
/// soup: `Bvh2::build_spatial_par` on 1 thread and every core (and Embree's spatial-split
/// builder likewise), cold. Then the BVH8 collapse (`Bvh8::from_bvh2` and `from_bvh2_par`, fresh
/// memory each time, as a one-off build).
fn build_threads(c: &mut Criterion) {
    let tris = scene::thin_soup(1 << 20, 1);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut g = c.benchmark_group("build_threads/soup1M");
    g.throughput(Throughput::Elements(tris.len() as u64));
    g.sample_size(10);
    g.sampling_mode(SamplingMode::Flat);
    g.warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(4));
    let presets = [
        ("fastest", BuildParams::fastest()),
        ("ploc", BuildParams::ploc()),
        ("fast", BuildParams::fast()),
        ("balanced", BuildParams::balanced()),
        ("high", BuildParams::high()),
        ("hybrid_sah", BuildParams::hybrid_sah()),
        ("median", BuildParams::median()),
        (
            "fast+agglomerative treelets",
            BuildParams {
                refine: Refine::AgglomerativeTreelets(TreeletParams::agglomerative()),
                ..BuildParams::fast()
            },
        ),
    ];
    for (name, p) in presets {
        let mut builder = Builder::new();
        let (mut one, mut many) = (Bvh2::default(), Bvh2::default());
        builder.build_into(&tris[..], &p, &mut one).expect("valid params");
        builder
            .build_into_par(&tris[..], &p, &mut many, cores)
            .expect("valid params");
        assert_eq!(
            one.sah_cost(1.0, 1.0),
            many.sah_cost(1.0, 1.0),
            "{name}: parallel tree differs"
        );
        for threads in [1, cores] {
            g.bench_function(format!("{name}/{threads}"), |b| {
                b.iter(|| builder.build_into_par(black_box(&tris[..]), &p, &mut many, threads))
            });
            if cores == 1 {
                break;
            }
        }
    }
    // Embree's binned SAH builder (`rtcBuildBVH`, medium) on a device with 1 thread and with
    // every core: the triangles' boxes (computed on the calling thread, as strahl computes them
    // inside the build) and the build, warm (one `RTCBVH` rebuilt).
    #[cfg(feature = "embree")]
    embree_on_threads(&mut g, "medium", &tris, peers::embree::Quality::Medium, false, cores);
    // Spatial splits on the 262k thin soup (the 1M one takes seconds a build): strahl's
    // `build_spatial_par` (the sequential build's tree, checked), cold, and Embree's
    // spatial-split builder (`high+splits`), warm, each on 1 thread and on every core.
    let small = scene::thin_soup(1 << 18, 1);
    let (p, sp) = (BuildParams::default(), SpatialSplits::default());
    let (one, _) = Bvh2::build_spatial(&small[..], &p, &sp).expect("valid params");
    let (many, _) = Bvh2::build_spatial_par(&small[..], &p, &sp, cores).expect("valid params");
    assert!(one == many, "spatial: parallel tree differs");
    for threads in [1, cores] {
        g.bench_function(format!("spatial262k/{threads}"), |b| {
            b.iter(|| Bvh2::build_spatial_par(black_box(&small[..]), &p, &sp, threads))
        });
        if cores == 1 {
            break;
        }
    }
    #[cfg(feature = "embree")]
    embree_on_threads(
        &mut g,
        "high+splits262k",
        &small,
        peers::embree::Quality::High,
        true,
        cores,
    );
    // The cost-optimal BVH8 collapse of the `balanced()` tree, `from_bvh2` against
    // `from_bvh2_par` (whose tree is checked to have as many nodes and packs).
    let (bvh2, _) = Bvh2::build(&tris[..], &BuildParams::balanced()).expect("valid params");
    let one = Bvh8::from_bvh2(&bvh2, &tris[..]).expect("a built tree collapses");
    let many = Bvh8::from_bvh2_par(&bvh2, &tris[..], cores).expect("a built tree collapses");
    assert_eq!(
        (one.nodes().len(), one.packs().len()),
        (many.nodes().len(), many.packs().len())
    );
    g.bench_function("collapse_bvh8/1", |b| {
        b.iter(|| Bvh8::from_bvh2(black_box(&bvh2), &tris[..]))
    });
    if cores > 1 {
        g.bench_function(format!("collapse_bvh8/{cores}"), |b| {
            b.iter(|| Bvh8::from_bvh2_par(black_box(&bvh2), &tris[..], cores))
        });
    }
    g.finish();
}

/// `peer/embree/<label>/<threads>` members of `g`: Embree's `rtcBuildBVH` at `quality` (with
/// `split`, its spatial-split builder) on a device with 1 thread and with every core, warm (one
/// `RTCBVH` rebuilt), the triangles' boxes computed in the timed part as strahl computes them.
#[cfg(feature = "embree")]
fn embree_on_threads(
    g: &mut BenchmarkGroup<'_, WallTime>,
    label: &str,
    tris: &[Triangle],
    quality: peers::embree::Quality,
    split: bool,
    cores: usize,
) {
    for threads in [1, cores] {
        let device = peers::embree::Device::with_threads(threads);
        let settings = peers::embree::TreeSettings {
            quality,
            max_leaf: 8,
            traversal_cost: 1.0,
            intersection_cost: 1.0,
        };
        let mut tree = peers::embree::BuiltTree::new(&device);
        let mut boxes: Vec<Aabb> = Vec::with_capacity(tris.len());
        g.bench_function(format!("peer/embree/{label}/{threads}"), |b| {
            b.iter(|| {
                boxes.clear();
                boxes.extend(black_box(tris).iter().map(|t| Aabb::from_points(t)));
                if split {
                    tree.build_split(&boxes, tris, &settings);
                } else {
                    tree.build(&boxes, &settings);
                }
            })
        });
        drop(tree);
        if cores == 1 {
            break;
        }
    }
}

/// The 1M sphereflake bent by a wave of `amp` times its size: every vertex moves, connectivity
/// stays.
fn bent(tris: &[Triangle], amp: f32) -> Vec<Triangle> {
    let mut b = Aabb::EMPTY;
    for v in tris.iter().flatten() {
        b.grow(*v);
    }
    let size = b.extent().max_element();
    let k = std::f32::consts::TAU / size;
    tris.iter()
        .map(|t| t.map(|v| v + Vec3::new((k * v.y).sin(), 0.0, (k * v.x).cos()) * (amp * size)))
        .collect()
}

/// `refit/sphereflake1M`: animated geometry, every frame. `BvhWide::refit` (BVH4, BVH8; BVH8 also
/// with `refit_par` on every core) and `Bvh2::refit` to the bent sphereflake, and (feature
/// `embree`) Embree's refit of a dynamic scene (`RTC_BUILD_QUALITY_REFIT`, vertices in a shared
/// buffer) on one thread and on every core, against rebuilding (`Builder::build_into` with
/// `BuildParams::default()`, warm, and `Bvh8::from_bvh2`), single thread. Then, printed: what the
/// refit costs in trace time as the bend grows (BVH8 closest hits of 262,144 rays from
/// `rays_for`, best of 3, refit tree against a rebuilt one; the hit counts checked equal).
fn refit(c: &mut Criterion) {
    let tris = scene::sphereflake(3, 3).to_soup();
    let moved = bent(&tris, 0.01);
    let p = BuildParams::default();
    let mut builder = Builder::new();
    let mut bvh2 = Bvh2::default();
    builder.build_into(&tris[..], &p, &mut bvh2).expect("valid params");
    let mut b8 = Bvh8::from_bvh2(&bvh2, &tris[..]).expect("a built tree collapses");
    let mut b4 = Bvh4::from_bvh2(&bvh2, &tris[..]).expect("a built tree collapses");
    let mut g = c.benchmark_group("refit/sphereflake1M");
    g.throughput(Throughput::Elements(tris.len() as u64));
    g.sample_size(10);
    g.sampling_mode(SamplingMode::Flat);
    g.warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(3));
    g.bench_function("bvh8_refit", |b| b.iter(|| b8.refit(black_box(&moved[..]))));
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if cores > 1 {
        g.bench_function(format!("bvh8_refit_par/{cores}"), |b| {
            b.iter(|| b8.refit_par(black_box(&moved[..]), cores))
        });
    }
    g.bench_function("bvh4_refit", |b| b.iter(|| b4.refit(black_box(&moved[..]))));
    let mut refit2 = bvh2.clone();
    g.bench_function("bvh2_refit", |b| b.iter(|| refit2.refit(black_box(&moved[..]))));
    // Embree's refit (`RTC_BUILD_QUALITY_REFIT`) on a device with one thread and with every
    // core, its vertices shared (set once, outside the timing).
    #[cfg(feature = "embree")]
    for threads in [1, cores] {
        let device = peers::embree::Device::with_threads(threads);
        let mut scene = peers::embree::RefitScene::new(&device, &tris);
        scene.set_vertices(&moved);
        scene.refit();
        let ray = Ray::new(Vec3::new(0.0, 0.0, -100.0), Vec3::Z);
        assert_eq!(
            scene.intersect1(&ray).is_some(),
            b8.intersect::<Moller>(&ray).is_some(),
            "Embree's refit scene hits differently"
        );
        g.bench_function(format!("peer/embree_refit/{threads}"), |b| b.iter(|| scene.refit()));
        if cores == 1 {
            break;
        }
    }
    let mut rebuilt = Bvh2::default();
    g.bench_function("rebuild_bvh8", |b| {
        b.iter(|| {
            builder
                .build_into(black_box(&moved[..]), &p, &mut rebuilt)
                .expect("valid params");
            Bvh8::from_bvh2(&rebuilt, &moved[..]).expect("a built tree collapses")
        })
    });
    g.finish();

    let rays = rays_for(&tris, 1 << 18);
    let mut hits = vec![None; rays.len()];
    let trace = |t: &Bvh8, hits: &mut [Option<strahl::Hit>]| {
        (0..3)
            .map(|_| {
                let t0 = Instant::now();
                t.intersect_batch::<Moller>(&rays, hits);
                t0.elapsed().as_secs_f64() * 1e3
            })
            .fold(f64::INFINITY, f64::min)
    };
    eprintln!(
        "refit/sphereflake1M: BVH8 trace of {} rays after a bend, refit against rebuilt",
        rays.len()
    );
    eprintln!("| bend (of the size) | refit ms | rebuilt ms | refit / rebuilt | SAH refit / rebuilt |");
    eprintln!("|---|---|---|---|---|");
    for amp in [0.0, 0.01, 0.05, 0.2] {
        let moved = bent(&tris, amp);
        let mut r8 = Bvh8::from_bvh2(&bvh2, &tris[..]).expect("a built tree collapses");
        r8.refit(&moved[..]);
        let mut r2 = bvh2.clone();
        r2.refit(&moved[..]).expect("a built tree refits");
        let (n2, _) = Bvh2::build(&moved[..], &p).expect("valid params");
        let n8 = Bvh8::from_bvh2(&n2, &moved[..]).expect("a built tree collapses");
        let t_refit = trace(&r8, &mut hits);
        let a = hits.iter().filter(|h| h.is_some()).count();
        let t_new = trace(&n8, &mut hits);
        let b = hits.iter().filter(|h| h.is_some()).count();
        assert_eq!(a, b, "bend {amp}: refit and rebuilt trees hit differently");
        eprintln!(
            "| {amp} | {t_refit:.1} | {t_new:.1} | {:.2}x | {:.2}x |",
            t_refit / t_new,
            r2.sah_cost(1.0, 1.0) / n2.sah_cost(1.0, 1.0)
        );
    }
}

criterion_group!(benches, build, build_threads, refit);
criterion_main!(benches);
