//! MPI compositing gives the same image as the in-process run (feature `mpi`, no test harness).
//!
//! Run under MPI, e.g. `mpirun -np 4 --oversubscribe target/release/deps/mpi-<hash>` (`.ci/run`
//! finds the binary); a single process (`cargo test --features mpi --test mpi`) checks P = 1.
//! Every rank builds the same deterministic partial images; each schedule is run over MPI, and
//! the root compares the result with [`ThreadTransport`] bit for bit (the same operations happen
//! in the same order, so even "over" matches exactly).

use strahl::composite::{
    CostModel, DepthPixel, KVec, MpiTransport, Pixel, Plan, RgbaF32, Schedule, ThreadTransport, Transport, auto_kvec,
    composite,
};
use strahl::scene::Rng;

fn images<P: Pixel>(p: u32, n: usize, f: impl Fn(&mut Rng) -> P) -> Vec<Vec<P>> {
    let mut rng = Rng::new(42 + p as u64);
    (0..p)
        .map(|_| {
            (0..n)
                .map(|_| if rng.f32() < 0.6 { f(&mut rng) } else { P::EMPTY })
                .collect()
        })
        .collect()
}

fn check<P: Pixel>(t: &mut MpiTransport, name: &str, imgs: &[Vec<P>], schedules: &[Schedule]) -> bool {
    let p = t.size();
    let order: Vec<u32> = (0..p).rev().collect();
    let mut ok = true;
    for &schedule in schedules {
        let root = p / 2;
        let plan = Plan {
            schedule,
            order: &order,
            root,
            sparse: true,
        };
        let (img, stats) = composite(t, &imgs[t.rank() as usize], &plan).expect("MPI compositing");
        if let Some(img) = img {
            let reference = ThreadTransport::run(p, |tt| composite(tt, &imgs[tt.rank() as usize], &plan).unwrap().0);
            let same = reference[root as usize].as_ref() == Some(&img);
            let rounds: Vec<String> = stats.round_seconds.iter().map(|s| format!("{:.3}", s * 1e3)).collect();
            println!(
                "mpi P={p} {name} {schedule:?}: {} (root sent {} B, rounds [{}] ms)",
                if same { "same as in-process" } else { "DIFFERENT" },
                stats.bytes_sent,
                rounds.join(", ")
            );
            ok &= same;
        }
    }
    ok
}

fn main() {
    let Some(universe) = mpi::initialize() else {
        eprintln!("MPI could not be initialised");
        std::process::exit(1);
    };
    let mut t = MpiTransport::new(universe.world());
    let p = t.size();
    let mut schedules = vec![Schedule::Tree, Schedule::RadixK(KVec::direct_send(p))];
    if let Some(k) = KVec::binary_swap(p) {
        schedules.push(Schedule::RadixK(k));
    }
    schedules.push(Schedule::RadixK(auto_kvec(p, 1 << 16, 16, &CostModel::shared_memory())));
    schedules.dedup();
    let n = 64 * 63 + 1; // odd
    let depth = images(p, n, |r| DepthPixel::new((r.u64() % 16) as f32, r.u64() as u32));
    let over = images(p, n, |r| {
        let a = r.f32();
        RgbaF32([r.f32() * a, r.f32() * a, r.f32() * a, a])
    });
    let mut ok = check(&mut t, "depth", &depth, &schedules);
    ok &= check(&mut t, "over", &over, &schedules);
    // Every rank learns the verdict from the root's exit status alone; a failure exits non-zero.
    if !ok {
        eprintln!("MPI and in-process images differ");
        std::process::exit(1);
    }
}
