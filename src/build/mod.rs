//! BVH2 construction: [`Bvh2`] and its builders (object median, full-sweep SAH, binned SAH,
//! LBVH, HLBVH, PLOC), treelet restructuring ([`Bvh2::optimize_treelets`], and agglomerative:
//! [`Bvh2::optimize_treelets_agglomerative`]), tree rotations
//! ([`Bvh2::optimize_rotations`]), reinsertion ([`Bvh2::optimize_reinsertion`]), spatial splits
//! ([`Bvh2::build_spatial`], triangles only), [`Bvh2::validate`], [`Bvh2::refit`] and
//! [`Bvh2::sah_cost`].
//!
//! Pipeline stage: after [`geometry`](crate::geometry), before `layout` (wide nodes) and
//! [`traverse`](crate::traverse). Input: anything that implements [`Primitives`] (every
//! [`Triangles`] storage, or a slice of [`Aabb`]) and a
//! [`BuildParams`]. Output: a [`Bvh2`] (32-byte [`Node`]s, siblings adjacent, one primitive-index
//! array) and [`BuildStats`]. Needs the `alloc` feature; single-threaded, but for
//! [`Builder::build_into_par`] and [`Bvh2::build_par`] (`std`), which build the median, binned-SAH
//! and [`HlbvhSah`](Strategy::HlbvhSah) trees on several threads: the same tree, numbered
//! differently (HLBVH-SAH's pruned trees, laid out by shape, numbered the same).
//!
//! # Builders
//! | [`Strategy`] | paper | per node | total |
//! |---|---|---|---|
//! | [`Median`](Strategy::Median) | (baseline) | `select_nth` on the longest centroid axis, O(n) | O(n log n) |
//! | [`BinnedSah`](Strategy::BinnedSah) | Wald, "On fast construction of SAH-based BVHs", 2007 | bin three axes (or the longest, [`BinAxes`]) in one pass, sweep the bins, branch-free partition; exact sweep at 8 references or fewer | O(n log n) |
//! | [`SweepSah`](Strategy::SweepSah) | MacDonald and Booth 1990; Wald, Boulos, Shirley 2007 | sweep every boundary of three pre-sorted lists, stable partition, O(n) | O(n log n) after three radix sorts |
//! | [`Lbvh`](Strategy::Lbvh) | Lauterbach et al. 2009; Karras 2012; near-cubic cells of Vinkler et al. 2017 ([`MortonCells`]) | binary search for the highest differing bit | O(n) after a radix sort |
//! | [`Hlbvh`](Strategy::Hlbvh) | Pantaleoni and Luebke 2010; Garanzha et al. 2011 | LBVH bottoms in clusters of up to [`cluster_size`](BuildParams::cluster_size) codes (SAH leaf collapse), binned SAH over the clusters' boxes on top | O(n) after a radix sort, plus binned SAH over the clusters |
//! | [`HlbvhSah`](Strategy::HlbvhSah) | HLBVH clusters with Bonsai-style SAH mini-trees, pruned on multi-scale scenes (Ganestam et al. 2015) | the binned builder within each cluster, in cache | O(n) sort, plus binned SAH over the clusters and within them |
//! | [`Ploc`](Strategy::Ploc) | Meister and Bittner 2018 (search radius 1) | Morton-sorted clusters merged bottom-up with the neighbour of smaller union area, where the two prefer each other; one-primitive leaves | O(n log n) after a radix sort; O(n) rounds on even scenes |
//! | [`Bvh2::build_spatial`] ([`SpatialSplits`]) | Stich, Friedrich and Dietrich 2009 (SBVH) | binned object split; where its children overlap, also planes through the node's box with every straddling triangle clipped into the bins it spans ("chopped binning"); the cheaper by the SAH, straddlers unsplit where a whole one is cheaper; triangles may sit in several leaves | O(n log n), about 10x binned SAH |
//! | [`Refine::Rotations`] (after any of them) | Kensler 2008 | the best of six child/grandchild swaps where it shrinks the two children's boxes | O(n) per round |
//! | [`Refine::Reinsertion`] (after any of them) | Bittner, Hapala and Havran 2013 (one subtree per move, as Meister and Bittner 2018) | take a subtree out, put it back where the SAH cost grows least (branch and bound over the tree) | about `n log n` per round over every node |
//! | [`Refine::Treelets`] (after any of them) | Karras and Aila 2013 (TRBVH) | best topology of a 3 ..= 8-leaf treelet by dynamic programming over its leaf subsets, `~3^k / 2` steps | O(n) per round |
//! | [`Refine::AgglomerativeTreelets`] (after any of them) | Domingues and Pedrini 2015 (ATRBVH) | the same treelets (3 ..= 16 leaves), each rebuilt by merging the two clusters of least union area first, `~k^3 / 6` steps | O(n) per round |
//!
//! The top-down builders share one loop (pbrt's `BUILD(node)`: split, group left and right,
//! recurse, else make a leaf), written iteratively with an explicit task stack. Each task is a
//! contiguous range of 32-byte primitive references, partitioned in O(n); nothing is allocated
//! per node. (The binned builder partitions from one buffer into a second one, branch-free, which
//! measured 10% faster than the best in-place partition: see `binned.rs`.) The full-sweep
//! builder keeps the references sorted three ways (once per axis, one radix sort each up front)
//! and partitions all three lists stably at every node, so each level costs O(n) instead of a sort
//! per node: `O(n log n)` in all instead of `O(n log^2 n)`, at the price of three copies of the
//! references.
//!
//! All working memory lives in a [`Builder`], kept between builds: fresh pages are expensive
//! (zeroed by the kernel on first touch), and a renderer that rebuilds every frame should not pay
//! for them every frame.
//!
//! # Guarantees
//! - **Bad primitives** (non-finite vertices, boxes whose extent or `min + max` overflows `f32`,
//!   i.e. coordinates beyond about `±1.7e38`, indices out of range) are left out and counted in
//!   [`BuildStats::invalid`]; the root box is finite.
//!   Zero-area triangles are kept (the ray kernels never hit them).
//! - **Empty input** gives an empty, valid tree (no nodes); a single primitive gives one leaf.
//! - **Termination.** Every split leaves both sides non-empty. Where the centroids of a node all
//!   coincide (no spatial split exists), the node becomes a leaf if it may
//!   (`N <= max_leaf_size`), else its range is cut in the middle.
//! - **Depth.** No tree is deeper than [`BuildParams::max_depth`] (at most
//!   [`traverse::MAX_DEPTH`](crate::traverse::MAX_DEPTH)), so the traversal stack never
//!   overflows; see [`BuildParams::max_depth`] for how the builders ensure it.
//! - **No panics, no recursion.** Invalid parameters give [`BuildError::InvalidParams`].
//!
//! ```
//! use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, scene, traverse::Watertight};
//! let bunny = scene::bunny();
//! let tris = bunny.as_indexed();
//! let (bvh, stats) = Bvh2::build(&tris, &BuildParams::fast()).unwrap();
//! assert_eq!((stats.primitives, stats.invalid), (3674, 0));
//! let check = bvh.validate(&tris).unwrap();
//! assert_eq!(check.primitives, 3674);
//! assert!(check.max_depth <= 64);
//! println!("SAH cost {:.1}", bvh.sah_cost(1.0, 1.0));
//! let ray = Ray::new(Vec3::new(0.0, 0.1, 1.0), -Vec3::Z);
//! let _hit = bvh.intersect::<Watertight, _>(&tris, &ray);
//! ```
//!
//! # Measured
//! `cargo bench --bench build -- --noplot`: one core of an AMD EPYC (AVX2,
//! `-C target-cpu=native`), a 2-vCPU VM shared with other jobs (load average about 2.5 during
//! the run, so expect 10 to 30% noise). "Warm": a reused [`Builder`] and output tree; "cold":
//! [`Bvh2::build`] with fresh memory. SAH cost with `C_T = C_I = 1`. Trace: the scalar reference
//! ([`traverse::intersect_scalar`](crate::traverse::intersect_scalar), watertight), rays from
//! outside the scene towards random points in its box.
//!
//! 1M-triangle thin soup (`scene::thin_soup(1 << 20, 1)`, 50,000 rays):
//!
//! | builder | warm Mtri/s | cold Mtri/s | SAH cost | nodes | depth | trace Mrays/s |
//! |---|---|---|---|---|---|---|
//! | `fastest()` (LBVH, 30-bit) | 17.3 | 7.2 | 525.0 | 1,340,619 | 25 | 0.022 |
//! | LBVH, 63-bit | 11.0 | 5.5 | 525.0 | 1,340,619 | 25 | 0.023 |
//! | `median()` | 4.9 | 3.6 | 518.9 | 2,031,617 | 21 | 0.025 |
//! | `fast()` (binned, 8 bins, longest axis) | 4.8 | 3.5 | 483.7 | 1,980,401 | 25 | 0.027 |
//! | binned, 8 bins, all axes | 3.4 | 2.7 | 473.4 | 1,976,363 | 25 | 0.028 |
//! | `balanced()` (binned, 16 bins, all axes) | 3.1 | 2.5 | 468.9 | 1,974,893 | 25 | 0.025 |
//! | binned, 32 bins, all axes | 3.0 | 2.4 | 466.8 | 1,974,709 | 25 | 0.027 |
//! | `quality()` (full sweep) | 1.2 | 1.1 | 466.0 | 1,974,995 | 25 | 0.024 |
//!
//! The soup fills a volume: a ray crosses about `n^(1/3)` triangles' boxes, hence the SAH cost
//! and the slow traces. The bunny (3,674 triangles, 200,000 rays), everything in cache:
//!
//! | builder | warm Mtri/s | SAH cost | trace Mrays/s |
//! |---|---|---|---|
//! | `fastest()` | 25.7 | 29.0 | 1.4 to 2.1 |
//! | `median()` | 7.1 | 30.6 | 1.3 to 1.9 |
//! | `fast()` | 7.7 | 26.5 | 1.6 to 2.2 |
//! | `balanced()` | 4.9 | 25.2 | 1.3 to 2.3 |
//! | `quality()` | 2.4 | 25.1 | 1.6 to 2.3 |
//!
//! **Hybrid and refinement** (`cargo test --release --test build_hybrid -- --ignored --nocapture
//! timing`: warm builder, best of 3 (soup) or 50 (bunny) builds, on the same VM under a heavier
//! load, average 5 to 6, so every builder ran 1.3 to 3.4 times slower than in the tables above;
//! ranges over three runs, the presets beside them from the same runs):
//!
//! | builder | soup Mtri/s | soup SAH | bunny Mtri/s | bunny SAH |
//! |---|---|---|---|---|
//! | `fastest()` | 4.2 to 4.7 | 525.0 | 21 to 29 | 29.0 |
//! | HLBVH, clusters of 32, no refinement | 2.7 to 4.0 | 508.8 | 9.6 to 16 | 28.0 |
//! | HLBVH + treelets of 5 (one round) | 0.78 to 0.92 | 484.9 | 2.6 to 3.8 | 26.6 |
//! | `hybrid()` (HLBVH + treelets of 7) | 0.40 to 0.45 | 479.4 | 1.2 to 1.6 | 26.3 |
//! | `fast()` | 1.8 to 1.9 | 483.7 | 5.1 to 7.3 | 26.5 |
//! | `balanced()` | 1.1 to 1.3 | 468.9 | 3.4 to 4.7 | 25.2 |
//! | `quality()` | 0.35 to 0.44 | 466.0 | 1.7 to 2.3 | 25.1 |
//!
//! HLBVH builds at 60 to 85% of the LBVH's speed with a 3% better tree on the soup. The treelet
//! pass does what it should for the tree (the hybrid is within 2.9% of the full sweep on the soup,
//! 5% on the bunny; one round takes an LBVH from 525 to 503) but costs about 2 us per 7-leaf
//! treelet on one core (the dynamic program, about 1,100 dependent steps), so one round at every
//! node costs as much as a full-sweep build. On one core the binned builders are the better
//! trade: `balanced()` builds faster than `hybrid()` and a better tree. The pass pays where the
//! starting tree is poor and the primitives are many per treelet
//! ([`min_prims`](TreeletParams::min_prims)), or to improve a tree that is kept.
//!
//! **Agglomerative treelets** (ATRBVH, [`Refine::AgglomerativeTreelets`], fifteenth session,
//! Intel Xeon, warm builder, best of 3; `benches/RESULTS.md` has the criterion run):
//! the same treelets, each rebuilt by merging the two clusters of least union area until one is
//! left (Domingues and Pedrini 2015), so 9 to 16 leaves cost less than the exact search's 7. After
//! the LBVH of the 1M soup / sphereflake: treelets of 7, one round, 316 / 322 ms to SAH 502.8 /
//! 54.62; agglomerative treelets of 9, one round, 186 / 182 ms to 503.8 / 54.67; two rounds
//! ([`TreeletParams::agglomerative`]) 314 / 313 ms to 501.6 / 53.72. As good a tree as the exact
//! search for 0.6 of its time, or a better one for the same time.
//!
//! (Trace speeds of the bunny varied between runs by the load; ranges over two runs.)
//!
//! **Single-threaded speed work** (the tables above were measured before it). `cargo test
//! --release --test build_speed -- --ignored --nocapture speed` with `STRAHL_REPS=10`, on the
//! 1M soup: warm builder, the code before and after built side by side and run alternately in
//! the same session (load average 1 to 3.5 from other jobs); each run keeps its best of 10
//! builds, the table the best run of 2 to 8 (a run's best varied by up to 40% with the load;
//! even the best runs were slower than the first table's, from a busier machine).
//! Instruction counts (and cache misses, simulated for a 32 KB L1 and a 512 KB L2) from
//! `valgrind --tool=callgrind` (2^16 soup, two builds, `build_into` only), which the load does
//! not move:
//!
//! | builder | before ms (Mtri/s) | after ms (Mtri/s) | instructions | SAH cost before / after |
//! |---|---|---|---|---|
//! | `fastest()` (LBVH, 30-bit) | 77 (13.6) | 69 (15.1) | +12% (D1 misses -22%, L2 -24%) | 525.0 / 525.0 |
//! | LBVH, 63-bit | 157 (6.7) | 129 (8.1) | | 525.0 / 525.0 |
//! | HLBVH, clusters of 32 | 130 (8.1) | 121 (8.7) | | 523.6 / 523.6 |
//! | `fast()` | 258 (4.1) | 236 (4.4) | -5.5% | 483.68 / 483.24 |
//! | `balanced()` | 378 (2.8) | 335 (3.1) | -3.3% | 468.89 / 468.72 |
//!
//! What changed: the 30-bit LBVH (and HLBVH) sort the references by bucket instead of gathering
//! them at random (see `lbvh.rs`), which took the LBVH's front end (codes, sort, gather) from about
//! 80 to 40 ms under load; `prepare` (`prims.rs`) checks and packs each box in four lanes (two to
//! three times faster); the binned builders bin into two sets of bins, grow the children's
//! centroid bounds with one `max` per side, split ranges of up to 16 references (not 8) by the
//! exact sweep (a slightly better tree, as many instructions), rank those without the tie test
//! where no keys tie, skip the empty-side test in the bin sweep (its cost is NaN anyway), and
//! build a left child without a trip through the task stack. Every tree is the same as before
//! except the binned ones, whose SAH cost fell by 0.04 to 0.1%. The targets of 40 (LBVH) and 10
//! (binned) million triangles per second are not reached on this machine.
//!
//! Where the time goes now, single-threaded, on the soup (under load): the LBVH spends about
//! 10% in `prepare`, 8% computing codes, 20% in the bucket scatter (32 MB read and written: bound
//! by memory bandwidth), 22% sorting and gathering within buckets and 40% in the hierarchy walk
//! (a third of it the binary searches for the splits). The binned builders spend about 20% in the
//! top levels (ranges of more than 16K references, out of cache: binning and partition passes
//! bound by memory bandwidth) and the rest in cache, bound by instructions: of those (callgrind,
//! `balanced()`) about 29% in the exact sweep of small ranges, 26% in binning and bin sweeps, 19%
//! in partitioning and 18% in the per-node loop. Cold builds are dominated by first-touch page
//! faults on this machine (64 MB of new pages cost about 40 ms).
//!
//! **Morton clusters with SAH mini-trees** (2026-12-02, [`BuildParams::hybrid_sah`]; same
//! harness, `STRAHL_ONLY=hybrid_sah,fast,quality STRAHL_REPS=5`, two runs at load average about
//! 1): on the 1M soup `hybrid_sah()` 166 to 177 ms (5.9 to 6.3 Mtri/s) with SAH cost 479.09,
//! `quality()` 899 to 903 ms with 465.96, `fast()` 198 to 206 ms with 483.24: within 2.8% of
//! the full sweep's cost at 5.1 to 5.4 times its speed, and a better tree than `fast()` in less
//! time. The knobs were chosen on that soup (best of 3 each; cost, ms): clusters of 32, 128, 512
//! with LBVH bottoms 523.6 at 85 ms; with binned bottoms on the longest axis only 484.7 to 483.2
//! at 164 ms; on all axes everywhere 480.3 (32), 475.6 (128), 473.3 (512) at 205 to 214 ms;
//! all axes but the longest in the exact sweep of ranges of at most 16 ([`BinAxes::AllButSmall`])
//! 480.2 (512) and 479.1 (1,024) at 173 to 175 ms. The Morton sort (about 26 ms) stands in for
//! the top-down builder's first six or so levels, where each level streams the 32 MB of
//! references through memory twice (about 64 ms of `fast()`'s build); the clusters' binned
//! builds then run in cache.
//!
//! **Tree rotations** ([`Refine::Rotations`], 2026-12-02, same harness with a scratch entry,
//! best of 3): on the 1M soup one round takes the LBVH from 525.0 to 511.0 and an HLBVH (clusters
//! of 32, leaves of up to 4) to 491.4, at about 60 ms a round (1.3 to 2 million nodes, 30 to
//! 45 ns each: the pre-order pass and six candidate unions per node); a second round gains
//! about 1% more, a fourth 0.3%. Cheaper than treelets of 5 or 7, but on one core not enough
//! for either tree to overtake the binned builders at equal build time.
//!
//! **The bottom-up LBVH** (2026-12-02; same harness, `STRAHL_REPS=7` to `9`, load average about
//! 1): the 30-bit LBVH now builds its hierarchy in one left-to-right pass over bucket-sorted
//! references (see `lbvh.rs`): `fastest()` on the 1M soup from 60.2 ms (17.4 Mtri/s) to 44.4 ms
//! (23.6 Mtri/s), the same tree (SAH 524.998, 1,340,619 nodes, depth 25; a unit test compares it
//! node for node with the top-down walk). Phase times (1M soup, warm): `prepare` 9 ms, codes
//! 5 ms, the top-digit scatter of the references 9 to 10 ms, then per bucket the key sort 5 ms
//! and the bottom-up pass 17 ms, of which about 7 ms writing the 43 MB of nodes. This machine
//! reads about 8 GB/s and copies about 14 GB/s (a C `memcpy` of 64 MB), so the passes over the
//! 37 MB of triangles, the 32 MB of references (written, read twice, scattered) and the nodes
//! already cost about 30 ms of memory traffic: the 40 Mtri/s target (25 ms) is below what this
//! design can reach here single-threaded.
//!
//! That estimate was wrong on the AMD EPYC (AVX-512) machines of later sessions: the same build
//! took 24-25 ms there, and 22.6-23.1 ms once `PrimRef::with_tag` stopped moving each reference
//! through general registers and the stack before the bottom-up pass read it back as a vector (a
//! store-forwarding stall): criterion 43.3 Mtri/s on the 1M soup, the target met.
//!
//! **PLOC** ([`BuildParams::ploc`], 2026-12-02, AMD EPYC): on the 1M soup 40.6 ms warm, 110 ms
//! cold, SAH cost 501.7, depth 26 (`cargo bench --features embree --bench build`), where the
//! `obvhs` crate's fastest preset (its PLOC, radius 1) takes 51.0 and 134 ms for 502.9. A greedy
//! sweep that also merged a cluster whose left neighbour was already taken built in 36 ms but to
//! 505.8; 63-bit codes gave the same cost in 52 ms.
//!
//! **Structured scenes, and extended Morton cells** (2026-12-04, Intel Xeon; `STRAHL_SCENE=terrain`
//! (or `sphereflake`, `soup`) `STRAHL_REPS=2 cargo test --release --test build_speed -- --ignored
//! --nocapture speed`). SAH cost above `quality()`'s on the three 1M-triangle scenes: the
//! terrain (`scene::terrain(724, 1)`, centroid bounds 1 x 0.2 x 1), the sphereflake
//! (`scene::sphereflake(3, 3)`) and the soup:
//!
//! | builder | terrain | sphereflake | soup |
//! |---|---|---|---|
//! | `fastest()` (LBVH), per-axis cells ([`MortonCells::Normalized`]) | +53.5% | +19.8% | +12.7% |
//! | `fastest()`, extended cells ([`MortonCells::Extended`], now every preset) | **+24.5%** | +19.8% | +12.7% |
//! | `ploc()`, per-axis / extended | +50.3% / **+25.0%** | +17.4% | +7.7% |
//! | `hybrid_sah()`, per-axis / extended | +14.4% / **+7.6%** | +10.7% | +2.8% |
//! | `fast()` | +5.2% | +9.5% | +3.7% |
//! | `balanced()` (a probe the same day, `terrain(1024)`) | +0.6% | +2.0% | +0.6% |
//!
//! On a plain Morton grid every level of the curve halves all three axes, so on the 5:1 terrain
//! the short axis is cut as often as the long ones and the LBVH's clusters are flat slabs. With
//! extended cells ([`MortonQuantizer::new_extended`](crate::geometry::morton::MortonQuantizer::new_extended),
//! Vinkler et al. 2017) the short axis's cells are `2^d` times longer and its bits start `d`
//! levels later: the LBVH's and PLOC's excess cost halves, and the scalar reference traces the
//! terrain's diffuse rays 1.20x (LBVH), 1.15x (PLOC) and 1.07x (`hybrid_sah()`) faster, primary
//! rays 1.06-1.09x (131,072 and 262,144 rays, best of 2 x 3 rounds taking turns). Scenes within
//! `sqrt(2)` of a cube (the soup, the sphereflake, the bunny) get the same codes and the same
//! trees as before; build times are unchanged (best of 2 x 4 rounds taking turns, the order
//! alternating, extended against per-axis on the terrain: LBVH 45.5 and 45.0 ms, PLOC 69.8 and
//! 70.8, `hybrid_sah()` 164.0 and 167.4). A cube grid
//! (every axis cut at the longest extent's cells) did a little better on the terrain (+22.7% for
//! the LBVH) but worse on the bunny (+20.1% against +15.5%), whose short axis it no longer
//! bisects. Noted, not solved: `hybrid_sah()`'s "within 3% of `quality()`" holds on the soup
//! only. On the sphereflake the Morton clusters cost most of its 10.7% (the same binning over the
//! whole scene: +4.1%; 16 bins on all axes with clusters of 1,024: +5.9% at about 3.7x
//! `quality()`'s speed; any cluster size from 32 to 65,536: +6.9% or more). On the terrain it is
//! the top over the clusters: the summed node areas per depth part from `balanced()`'s from
//! depth 3 on (a binned top over Morton patches cannot group triangles by height as top-down
//! splits do); clusters of 65,536 bring it to +2.3-2.9%. `balanced()` is within 2% on every scene
//! at 2.2-2.8x `quality()`'s speed.
//!
//! **Past the full sweep: [`BuildParams::high`]** (2026-12-04, fifth session, Intel Xeon; the
//! `high` member of `tests/build_speed.rs`, best of 3, the three presets one after the other):
//! binned SAH with 64 bins on all axes, then one round of rotations ([`Refine::Rotations`]).
//!
//! | 1M triangles | `balanced()` ms / SAH | `high()` ms / SAH | `quality()` ms / SAH | `high()` vs `quality()` |
//! |---|---|---|---|---|
//! | soup | 458 / 468.72 | 625 / **465.05** | 1168 / 465.96 | -0.20%, 1.87x the speed |
//! | terrain | 296 / 35.108 | 354 / **34.914** | 776 / 34.931 | -0.05%, 2.19x |
//! | sphereflake | 321 / 52.015 | 392 / **49.710** | 879 / 50.979 | -2.49%, 2.24x |
//!
//! (The soup's run was under load: 300 ms for `balanced()` in a quiet one.) The sphereflake gains
//! most: its greedy top-down splits leave small spheres grouped with patches of large ones,
//! which a swap of a child with a grandchild undoes. The same probe on smaller scenes (the bunny,
//! 100k soups, a 2-level sphereflake, a 200 x 200 terrain): 0.05% to 1.4% below the full sweep,
//! 1.4 to 2.4 times its speed; a 100 x 100 terrain 0.14% above (`tests/build.rs`). Two rounds of
//! rotations gain another 0.003% (terrain), 0.05% (soup) and 0.44% (sphereflake) for 5-18% more
//! time; 16 and 32 bins with one round reach -0.17%/-0.53% on the sphereflake but +0.47%/+0.10%
//! on the terrain. The rotation round walked the tree in pre-order then (62, 27 and 31 ms on the
//! soup, terrain and sphereflake); it now runs in index order where children follow their
//! parents, as the top-down builders lay them out (47-50, 18-20 and 21-23 ms; the same trees).
//!
//! **Reinsertion** ([`Refine::Reinsertion`], 2026-12-05, Intel Xeon; `STRAHL_BENCH_SCENES=soup1M,sphereflake1M
//! cargo bench --features embree --bench build -- --noplot`, member `binned64-all+reinsertion`:
//! [`BuildParams::high`] with reinsertion in place of its rotation round, two rounds over every
//! node). SAH cost, 1M soup: 449.65 against 465.05 (`high()`), 465.96 (full sweep) and 472.37
//! (Embree medium), at 0.30 Mtri/s warm (3.6 s); 1M sphereflake: 48.06 against 49.71, 50.98 and
//! 51.41 (1.9 s). The lowest SAH cost of any builder in the run, strahl's or a peer's (`obvhs`'s
//! PLOC with reinsertion: 605.6 and 54.95 with its larger leaves). What it does not buy here:
//! trace speed. Collapsed to BVH8 and traced taking turns (1M sphereflake, best of 5; 1024 x 1024
//! primary, 262k diffuse and 262k shadow rays), the reinserted `balanced()` tree (SAH 48.53)
//! took 55.8 / 228.1 / 113.7 ms against 55.3 / 223.8 / 110.1 for `balanced()` itself (52.02)
//! and 55.6 / 224.5 / 114.0 for the full sweep's: within the noise, as for the full sweep's
//! lower cost before it. Candidates are taken in slot order (the depth-first layout keeps a
//! subtree's nodes close in memory): 1.5x faster than in the order of their scores, trees as good.
//!
//! Tried the same day for `hybrid_sah()`'s "within 3% of `quality()` at 5 times its speed" on the
//! structured scenes, none of which reaches it (SAH cost above `quality()`'s; ms from probes
//! next to `quality()`'s 700-1050 ms):
//! - **PLOC with a wider search** (a probe of Meister and Bittner's radius `r`, with leaves
//!   collapsed by the SAH afterwards): `r` = 1, 2, 4, 8, 16 gave +7.6, +5.5, +5.7, +7.1, +8.5% on
//!   the soup, +20.7 to +14.6% on the terrain, +15.6, +9.8, +7.1, +4.6, +1.3% on the sphereflake,
//!   +7.2% or more on the bunny: agglomeration by union area alone does not follow the SAH, and on
//!   the terrain the Morton order limits it.
//! - **Treelets over `hybrid_sah()`'s top** (TRBVH at nodes of at least 256 or 1,024 primitives,
//!   two rounds): sphereflake +10.7% -> +3.5-3.9% (245-335 ms), terrain +7.6% -> +5.3-5.6%;
//!   with clusters of 65,536 the terrain reaches +2.6% but the sphereflake stays at +3.4% (360-390
//!   ms). One to four rounds of rotations: sphereflake +6.4% to +4.5%, terrain +6.1% to +5.4%.
//! - **Binning the longest axis only below a size** (all three above 1,024 to 65,536
//!   references): 5-15% faster than `balanced()`, but +2.4 to +3.9% on the terrain and +3.6 to
//!   +5.6% on the sphereflake (`balanced()`: +0.5% and +2.0%): the lower levels need the three
//!   axes as much as the top.

mod binned;
mod builder;
mod hlbvh;
mod lbvh;
mod params;
mod ploc;
mod prims;
pub mod radix;
mod refit;
mod reinsert;
mod rotate;
mod small;
mod spatial;
mod sweep;
mod topdown;
mod treelet;
mod validate;

pub use builder::Builder;
#[cfg(feature = "std")]
pub use builder::MAX_THREADS;
pub use params::{
    BinAxes, BuildParams, MAX_BINS, MAX_CLUSTER_SIZE, MAX_LEAF_SIZE, MIN_BIN_SAMPLE, MIN_BINS, MIN_DEPTH, MortonBits,
    MortonCells, Refine, Strategy, TreeletParams,
};
pub(crate) use prims::usable_box;
pub use prims::{MAX_PRIMITIVES, Primitives};
pub use reinsert::{REINSERT_SEARCH_BUDGET, ReinsertParams, ReinsertStats};
pub use rotate::RotationStats;
pub use spatial::{SpatialSplits, clip_triangle};
pub use treelet::TreeletStats;
pub use validate::{BvhStats, ValidateError};

pub use crate::traverse::Node;

use crate::geometry::{Aabb, Hit, Ray, Triangles};
use crate::traverse::{Bvh2Ref, TriangleTest, intersect_scalar, occluded_scalar};
use alloc::vec::Vec;

/// A binary BVH: [`Node`]s with the root at index 0 and each interior node's children adjacent
/// (`left`, `left + 1`), and the primitive indices its leaves point into.
///
/// Built by [`Bvh2::build`]; the fields are public so that trees can be stored, loaded
/// (both are [`bytemuck::Pod`] slices) and inspected. [`validate`](Self::validate) checks every
/// invariant of a tree from anywhere.
///
/// ```
/// use strahl::{Aabb, Vec3, build::{Bvh2, BuildParams}};
/// // Builders work on boxes of any primitive, too.
/// let boxes: Vec<Aabb> = (0..100)
///     .map(|i| Aabb::new(Vec3::splat(i as f32), Vec3::splat(i as f32 + 0.5)))
///     .collect();
/// let (bvh, stats) = Bvh2::build(&boxes[..], &BuildParams::quality()).unwrap();
/// assert_eq!(bvh.bounds(), Aabb::new(Vec3::ZERO, Vec3::splat(99.5)));
/// assert_eq!(bvh.prim_indices.len(), 100);
/// assert_eq!(stats.nodes as usize, bvh.nodes.len());
/// assert!(bvh.validate(&boxes[..]).is_ok());
///
/// let (empty, _) = Bvh2::build(&[] as &[Aabb], &BuildParams::default()).unwrap();
/// assert!(empty.is_empty() && empty.validate(&[] as &[Aabb]).is_ok());
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh2 {
    /// Nodes; `nodes[0]` is the root. Empty for an empty tree.
    pub nodes: Vec<Node>,
    /// Primitive indices (into the builder's input), in leaf order.
    pub prim_indices: Vec<u32>,
}

/// What a build did.
///
/// ```
/// use strahl::{Vec3, build::{Bvh2, BuildParams}};
/// let mut tris = strahl::scene::icosphere(2).to_soup();
/// tris.push([Vec3::ZERO, Vec3::X, Vec3::INFINITY]); // not finite: left out
/// let (bvh, stats) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
/// assert_eq!((stats.primitives, stats.invalid), (320, 1));
/// let check = bvh.validate(&tris[..]).unwrap();
/// assert_eq!((stats.nodes, stats.leaves, stats.max_depth), (check.nodes, check.leaves, check.max_depth));
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BuildStats {
    /// Primitives in the tree (the valid ones).
    pub primitives: u32,
    /// Primitives left out: non-finite or unusable (see [`Primitives`]).
    pub invalid: u32,
    /// Nodes, interior and leaf.
    pub nodes: u32,
    /// Leaves.
    pub leaves: u32,
    /// Depth of the deepest leaf (root = 1; 0 for an empty tree).
    pub max_depth: u32,
    /// Splits not chosen by the strategy: object-median splits forced by the depth bound, and
    /// middle splits of ranges whose centroids all coincide.
    pub forced_splits: u32,
    /// Treelets rearranged by [`BuildParams::refine`] (0 without it).
    pub restructured: u32,
}

/// Why a build could not run.
///
/// ```
/// use strahl::{Vec3, build::{Bvh2, BuildError, BuildParams, MIN_DEPTH}};
/// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
/// let shallow = BuildParams { max_depth: MIN_DEPTH - 1, ..BuildParams::default() };
/// let err = Bvh2::build(&tris[..], &shallow).unwrap_err();
/// assert!(matches!(err, BuildError::InvalidParams(_)));
/// assert!(err.to_string().starts_with("invalid build parameters"));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildError {
    /// More primitives than [`MAX_PRIMITIVES`] (node indices would not fit in `u32`).
    TooManyPrimitives {
        /// The number of primitives given.
        count: usize,
    },
    /// A [`BuildParams`] field is out of range; the text names it and the range.
    InvalidParams(&'static str),
}

impl core::fmt::Display for BuildError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::TooManyPrimitives { count } => {
                write!(f, "{count} primitives: more than the {MAX_PRIMITIVES} a Bvh2 can index")
            }
            Self::InvalidParams(what) => write!(f, "invalid build parameters: {what}"),
        }
    }
}

impl core::error::Error for BuildError {}

impl Bvh2 {
    /// Builds a tree over `prims` with `params`; invalid primitives are left out and counted.
    ///
    /// Errors only for out-of-range `params` or more than [`MAX_PRIMITIVES`] primitives. To
    /// rebuild often, keep a [`Builder`] and use [`Builder::build_into`]: it reuses memory.
    ///
    /// ```
    /// use strahl::{Vec3, build::{Bvh2, BuildError, BuildParams, Strategy}};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::ZERO, Vec3::X, Vec3::NAN]];
    /// for params in [BuildParams::fastest(), BuildParams::fast(), BuildParams::quality(), BuildParams::median()] {
    ///     let (bvh, stats) = Bvh2::build(&tris[..], &params).unwrap();
    ///     assert_eq!((stats.primitives, stats.invalid, stats.leaves), (1, 1, 1));
    ///     assert_eq!(bvh.prim_indices, vec![0]);
    /// }
    /// let bad = BuildParams { bins: 1000, ..BuildParams::fast() };
    /// assert!(matches!(Bvh2::build(&tris[..], &bad), Err(BuildError::InvalidParams(_))));
    /// ```
    pub fn build<P: Primitives + ?Sized>(prims: &P, params: &BuildParams) -> Result<(Bvh2, BuildStats), BuildError> {
        Builder::new().build(prims, params)
    }

    /// [`build`](Self::build) on up to `threads` threads (`std`); see
    /// [`Builder::build_into_par`] for what runs in parallel and what the result is.
    ///
    /// ```
    /// use strahl::{build::{BuildParams, Bvh2}, scene};
    /// let soup = scene::thin_soup(20_000, 3);
    /// let (bvh, stats) = Bvh2::build_par(&soup[..], &BuildParams::balanced(), 2).unwrap();
    /// assert_eq!(bvh.validate(&soup[..]).unwrap().leaves, stats.leaves);
    /// ```
    #[cfg(feature = "std")]
    pub fn build_par<P: Primitives + Sync + ?Sized>(
        prims: &P,
        params: &BuildParams,
        threads: usize,
    ) -> Result<(Bvh2, BuildStats), BuildError> {
        let mut bvh = Bvh2::default();
        let stats = Builder::new().build_into_par(prims, params, &mut bvh, threads)?;
        Ok((bvh, stats))
    }

    /// A borrowed view for the [`traverse`](crate::traverse) functions.
    ///
    /// ```
    /// # use strahl::build::{Bvh2, BuildParams};
    /// # let tris = strahl::scene::icosphere(1).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let view = bvh.view();
    /// assert_eq!((view.nodes, view.prim_indices), (&bvh.nodes[..], &bvh.prim_indices[..]));
    /// assert_eq!(view.bounds(), bvh.bounds());
    /// ```
    #[inline]
    pub fn view(&self) -> Bvh2Ref<'_> {
        Bvh2Ref::new(&self.nodes, &self.prim_indices)
    }

    /// `true` if the tree has no nodes.
    ///
    /// ```
    /// use strahl::{Aabb, Vec3, build::{Bvh2, BuildParams}};
    /// let (empty, _) = Bvh2::build(&[] as &[Aabb], &BuildParams::default()).unwrap();
    /// assert!(empty.is_empty());
    /// // Invalid primitives are left out: a tree of nothing but those is empty too.
    /// let (none_valid, _) = Bvh2::build(&[[Vec3::ZERO, Vec3::X, Vec3::NAN]][..], &BuildParams::default()).unwrap();
    /// assert!(none_valid.is_empty());
    /// ```
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The root's box ([`Aabb::EMPTY`] for an empty tree).
    ///
    /// ```
    /// use strahl::{Aabb, build::{Bvh2, BuildParams}};
    /// let mesh = strahl::scene::icosphere(2);
    /// let (bvh, _) = Bvh2::build(&mesh.as_indexed(), &BuildParams::default()).unwrap();
    /// assert_eq!(bvh.bounds(), Aabb::from_points(&mesh.positions));
    /// assert_eq!(Bvh2::default().bounds(), Aabb::EMPTY);
    /// ```
    #[inline]
    pub fn bounds(&self) -> Aabb {
        self.view().bounds()
    }

    /// Closest hit of `ray` among `tris` through this tree, with the triangle test `T`
    /// ([`traverse::intersect_scalar`](crate::traverse::intersect_scalar)).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, traverse::{Watertight, intersect_brute_force}};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -4.0), Vec3::Z);
    /// let hit = bvh.intersect::<Watertight, _>(&tris[..], &ray).unwrap();
    /// assert_eq!(Some(hit), intersect_brute_force::<Watertight, _>(&tris[..], &ray));
    /// assert!(hit.t > 3.0 && hit.t < 3.1); // the unit sphere's near side, just inside z = -1
    /// ```
    #[inline]
    pub fn intersect<T: TriangleTest, P: Triangles + ?Sized>(&self, tris: &P, ray: &Ray) -> Option<Hit> {
        intersect_scalar::<T, P>(self.view(), tris, ray)
    }

    /// `true` if `ray` hits anything ([`traverse::occluded_scalar`](crate::traverse::occluded_scalar)).
    ///
    /// ```
    /// use strahl::{Ray, Vec3, build::{Bvh2, BuildParams}, traverse::Watertight};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let o = Vec3::new(0.1, 0.2, -4.0);
    /// assert!(bvh.occluded::<Watertight, _>(&tris[..], &Ray::new(o, Vec3::Z)));
    /// // A shadow ray that ends before the sphere (at t = 2.5) is not blocked.
    /// assert!(!bvh.occluded::<Watertight, _>(&tris[..], &Ray::with_range(o, Vec3::Z, 0.0, 2.5)));
    /// ```
    #[inline]
    pub fn occluded<T: TriangleTest, P: Triangles + ?Sized>(&self, tris: &P, ray: &Ray) -> bool {
        occluded_scalar::<T, P>(self.view(), tris, ray)
    }

    /// Closest hit of `ray` that `filter` accepts
    /// ([`traverse::intersect_scalar_filtered`](crate::traverse::intersect_scalar_filtered),
    /// [`HitFilter`](crate::traverse::HitFilter)).
    ///
    /// ```
    /// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, traverse::{Watertight, intersect_brute_force_filtered}};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -4.0), Vec3::Z);
    /// let even = |h: &Hit| h.prim % 2 == 0;
    /// let hit = bvh.intersect_filtered::<Watertight, _>(&tris[..], &ray, even).unwrap();
    /// assert_eq!(Some(hit), intersect_brute_force_filtered::<Watertight, _, _>(&tris[..], &ray, even));
    /// assert_eq!(hit.prim % 2, 0);
    /// ```
    #[inline]
    pub fn intersect_filtered<T: TriangleTest, P: Triangles + ?Sized>(
        &self,
        tris: &P,
        ray: &Ray,
        filter: impl crate::traverse::HitFilter,
    ) -> Option<Hit> {
        crate::traverse::intersect_scalar_filtered::<T, P, _>(self.view(), tris, ray, filter)
    }

    /// `true` if `ray` hits a triangle that `filter` accepts
    /// ([`traverse::occluded_scalar_filtered`](crate::traverse::occluded_scalar_filtered)).
    ///
    /// ```
    /// use strahl::{Hit, Ray, Vec3, build::{Bvh2, BuildParams}, traverse::Watertight};
    /// let tris = strahl::scene::icosphere(2).to_soup();
    /// let (bvh, _) = Bvh2::build(&tris[..], &BuildParams::default()).unwrap();
    /// let ray = Ray::new(Vec3::new(0.1, 0.2, -4.0), Vec3::Z);
    /// assert!(bvh.occluded_filtered::<Watertight, _>(&tris[..], &ray, |_: &Hit| true));
    /// assert!(!bvh.occluded_filtered::<Watertight, _>(&tris[..], &ray, |_: &Hit| false));
    /// ```
    #[inline]
    pub fn occluded_filtered<T: TriangleTest, P: Triangles + ?Sized>(
        &self,
        tris: &P,
        ray: &Ray,
        filter: impl crate::traverse::HitFilter,
    ) -> bool {
        crate::traverse::occluded_scalar_filtered::<T, P, _>(self.view(), tris, ray, filter)
    }
}
