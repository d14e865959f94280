//! Replays the seeds under `seeds/<target>/` through the checker on stable Rust (`cargo test` in
//! `fuzz/`), so they stay regression tests.
//!
//! Files named `crash-*` reproduce bugs that fuzzing found and that have been fixed; they stay as
//! regression seeds.

use std::path::{Path, PathBuf};
use strahl_fuzz::{
    BvhCase, CompositeCase, CompositeReport, KernelCase, Mode, VolumeCase, VolumeReport, check_bvh, check_composite,
    check_kernels, check_volume,
};

fn files(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("seeds").join(target);
    let mut v: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    v.sort();
    v
}

fn replay(paths: &[PathBuf]) {
    let mut failed = Vec::new();
    for path in paths {
        let data = std::fs::read(path).unwrap();
        let case = KernelCase::decode(&data);
        if std::panic::catch_unwind(|| check_kernels(&case)).is_err() {
            failed.push(path.display().to_string());
        }
    }
    assert!(failed.is_empty(), "failed: {failed:#?}");
}

#[test]
fn kernels_seeds() {
    let seeds = files("kernels");
    assert!(
        seeds
            .iter()
            .any(|p| p.file_name().unwrap().to_string_lossy().starts_with("crash-"))
    );
    replay(&seeds);
}

/// Every byte string decodes, including the empty one and truncations of the seeds.
#[test]
fn short_inputs() {
    for data in [&[][..], &[0], &[1], &[3], &[0xff; 3]] {
        check_kernels(&KernelCase::decode(data));
    }
    for path in files("kernels") {
        let data = std::fs::read(&path).unwrap();
        for n in (0..data.len()).step_by(7) {
            check_kernels(&KernelCase::decode(&data[..n]));
        }
    }
}

#[test]
fn bvh_seeds() {
    let seeds = files("bvh");
    assert!(seeds.len() >= 4);
    let mut failed = Vec::new();
    for path in &seeds {
        let data = std::fs::read(path).unwrap();
        if std::panic::catch_unwind(|| check_bvh(&BvhCase::decode(&data))).is_err() {
            failed.push(path.display().to_string());
        }
        for n in (0..data.len()).step_by(13) {
            check_bvh(&BvhCase::decode(&data[..n]));
        }
    }
    assert!(failed.is_empty(), "failed: {failed:#?}");
    // The seeds are not vacuous: their rays hit something, in both modes.
    let hits: usize = seeds
        .iter()
        .map(|p| {
            let case = BvhCase::decode(&std::fs::read(p).unwrap());
            case.rays
                .iter()
                .filter(|r| {
                    strahl::traverse::intersect_brute_force::<strahl::traverse::Watertight, _>(&case.tris[..], r)
                        .is_some()
                })
                .count()
        })
        .sum();
    assert!(hits >= 4, "only {hits} seed rays hit anything");
}

/// Replays every seed of `target` and every `step`-th truncation of it; returns the reports of
/// the whole seeds.
fn replay_target<R>(target: &str, step: usize, check: fn(&[u8]) -> R) -> Vec<(PathBuf, R)> {
    let mut failed = Vec::new();
    let mut reports = Vec::new();
    for path in files(target) {
        let data = std::fs::read(&path).unwrap();
        match std::panic::catch_unwind(|| check(&data)) {
            Ok(r) => reports.push((path.clone(), r)),
            Err(_) => failed.push(path.display().to_string()),
        }
        for n in (0..data.len()).step_by(step) {
            if std::panic::catch_unwind(|| check(&data[..n])).is_err() {
                failed.push(format!("{} cut to {n} bytes", path.display()));
            }
        }
    }
    assert!(failed.is_empty(), "failed: {failed:#?}");
    reports
}

/// A few hundred pseudo-random inputs of every length up to `max_len` (xorshift, fixed seed), in
/// both modes: a smoke test of the decoder and checker beyond the seeds.
fn random_inputs(count: usize, max_len: usize) -> Vec<Vec<u8>> {
    let mut s = 0x2545_f491_u32;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        s
    };
    (0..count)
        .map(|i| {
            let len = next() as usize % (max_len + 1);
            let mut v: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            if let Some(h) = v.first_mut() {
                *h = (*h & !1) | (i as u8 & 1);
            }
            v
        })
        .collect()
}

#[test]
fn volume_seeds() {
    let reports = replay_target("volume", 5, |d| check_volume(&VolumeCase::decode(d)));
    assert!(reports.len() >= 6);
    let modes = |m: Mode| {
        reports
            .iter()
            .filter(|(p, _)| VolumeCase::decode(&std::fs::read(p).unwrap()).mode == m)
            .count()
    };
    assert!(modes(Mode::Grid) >= 3 && modes(Mode::Chaos) >= 3);
    // Not vacuous: rays gather opacity, blocks are skipped, rays terminate, bad parameters occur.
    let sum = |f: fn(&VolumeReport) -> u64| reports.iter().map(|(_, r)| f(r)).sum::<u64>();
    assert!(sum(|r| r.hits as u64) >= 10, "hits");
    assert!(sum(|r| r.skipping.skipped) > 0, "skipping");
    assert!(sum(|r| r.plain.terminated) > 0, "termination");
    assert!(sum(|r| r.plain.truncated) > 0, "truncation");
    assert!(sum(|r| r.bad_params as u64) > 0, "bad parameters");
}

#[test]
fn composite_seeds() {
    let reports = replay_target("composite", 11, |d| check_composite(&CompositeCase::decode(d)));
    assert!(reports.len() >= 6);
    let modes = |m: Mode| {
        reports
            .iter()
            .filter(|(p, _)| CompositeCase::decode(&std::fs::read(p).unwrap()).mode == m)
            .count()
    };
    assert!(modes(Mode::Grid) >= 3 && modes(Mode::Chaos) >= 3);
    let sum = |f: fn(&CompositeReport) -> usize| reports.iter().map(|(_, r)| f(r)).sum::<usize>();
    assert!(sum(|r| r.runs) >= 10 && sum(|r| r.compared) >= 10, "runs");
    assert!(sum(|r| r.covered) > 100, "covered pixels");
    assert!(sum(|r| r.bad_plans) > 0, "bad plans");
}

#[test]
fn volume_random_inputs() {
    for data in random_inputs(400, 300) {
        check_volume(&VolumeCase::decode(&data));
    }
}

#[test]
fn composite_random_inputs() {
    for data in random_inputs(150, 200) {
        check_composite(&CompositeCase::decode(&data));
    }
}
