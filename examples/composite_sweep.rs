//! Compositing time against the k-vector: every ordered factorisation of P (radix-k, with
//! direct-send and binary-swap among them) and the tree reduction, on a 1024 x 1024 RGBA f32 image
//! per rank, median of repeated runs after a barrier; the automatic k-vector is marked.
//!
//! ```sh
//! cargo run --release --example composite_sweep -- 4          # 4 ranks as threads
//! cargo build --release --features mpi --example composite_sweep
//! mpirun -np 4 target/release/examples/composite_sweep        # 4 MPI processes
//! ```

use std::time::Instant;
use strahl::composite::{
    CostModel, KVec, Pixel, Plan, RgbaF32, Schedule, ThreadTransport, Transport, auto_kvec, composite,
    measure_cost_model,
};
use strahl::scene::Rng;

const W: usize = 1024;
const H: usize = 1024;
const REPS: usize = 7;

/// All ordered factorisations of `p` into factors >= 2.
fn factorisations(p: u32) -> Vec<Vec<u32>> {
    if p == 1 {
        return vec![vec![]];
    }
    let mut out = Vec::new();
    for k in 2..=p {
        if p.is_multiple_of(k) {
            for mut rest in factorisations(p / k) {
                rest.insert(0, k);
                out.push(rest);
            }
        }
    }
    out
}

fn sweep(t: &mut impl Transport, transport: &str) {
    let p = t.size();
    let n = W * H;
    let mut rng = Rng::new(7 + t.rank() as u64);
    // A vertical band per rank (a spatial partition seen from the front) plus 5% scattered pixels.
    let img: Vec<RgbaF32> = (0..n)
        .map(|i| {
            let band = (i % W) * p as usize / W == t.rank() as usize;
            if band || rng.f32() < 0.05 {
                RgbaF32([0.3, 0.2, 0.1, 0.5])
            } else {
                RgbaF32::EMPTY
            }
        })
        .collect();
    let order: Vec<u32> = (0..p).collect();
    // The cost model, measured on this transport (rank 0's figures, shared by all ranks).
    let model = measure_cost_model(t).expect("cost model");
    let auto = auto_kvec(p, n as u64, RgbaF32::BYTES as u64, &model);
    let preset = auto_kvec(p, n as u64, RgbaF32::BYTES as u64, &CostModel::shared_memory());
    let mut schedules: Vec<Schedule> = factorisations(p)
        .iter()
        .filter_map(|f| KVec::new(f))
        .map(Schedule::RadixK)
        .collect();
    schedules.push(Schedule::Tree);
    let mut rows = Vec::new();
    for s in schedules {
        let plan = Plan {
            schedule: s,
            order: &order,
            root: 0,
            sparse: true,
        };
        let mut times = Vec::new();
        for _ in 0..REPS {
            t.barrier().expect("barrier");
            let t0 = Instant::now();
            composite(t, &img, &plan).expect("compositing");
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        rows.push((s, times[REPS / 2]));
    }
    if t.rank() == 0 {
        let best = rows.iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
        let best_radix = rows
            .iter()
            .filter(|r| matches!(r.0, Schedule::RadixK(_)))
            .map(|r| r.1)
            .fold(f64::INFINITY, f64::min);
        println!("\n{transport}, P = {p}, {W}x{H} RGBA f32 per rank, median of {REPS} (ms at rank 0)");
        println!("| schedule | ms | vs best |");
        println!("|---|---|---|");
        for (s, ms) in &rows {
            let name = match s {
                Schedule::RadixK(k) if *k == auto => format!("radix-k {:?} (auto)", k.as_slice()),
                Schedule::RadixK(k) => format!("radix-k {:?}", k.as_slice()),
                Schedule::Tree => "tree".to_string(),
            };
            println!("| {name} | {ms:.2} | {:.2}x |", ms / best);
        }
        let auto_ms = rows
            .iter()
            .find(|r| r.0 == Schedule::RadixK(auto))
            .map(|r| r.1)
            .unwrap_or(f64::NAN);
        println!(
            "measured model: latency {:.1} us, {:.2} GB/s, {:.2} ns per blend; preset shared_memory() picks {:?}",
            model.latency * 1e6,
            1e-9 / model.seconds_per_byte,
            model.seconds_per_blend * 1e9,
            preset.as_slice()
        );
        println!(
            "auto k-vector {:?}: {:.0}% behind the best radix-k",
            auto.as_slice(),
            (auto_ms / best_radix - 1.0) * 100.0
        );
    }
}

fn main() {
    #[cfg(feature = "mpi")]
    if std::env::var_os("OMPI_COMM_WORLD_SIZE").is_some() || std::env::var_os("PMI_SIZE").is_some() {
        let universe = mpi::initialize().expect("MPI initialises once");
        let mut t = strahl::composite::MpiTransport::new(universe.world());
        sweep(&mut t, "MPI");
        return;
    }
    let p: u32 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(4)
        .clamp(1, 64);
    ThreadTransport::run(p, |t| sweep(t, "in-process (threads)"));
}
