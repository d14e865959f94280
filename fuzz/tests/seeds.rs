//! Replays the seeds under `seeds/<target>/` through the checker on stable Rust (`cargo test` in
//! `fuzz/`), so they stay regression tests.
//!
//! Files named `crash-*` reproduce bugs that fuzzing found and that have been fixed; they stay as
//! regression seeds.

use std::path::{Path, PathBuf};
use strahl_fuzz::{BvhCase, KernelCase, check_bvh, check_kernels};

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
