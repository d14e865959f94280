//! Replays the seeds under `seeds/<target>/` through the checker on stable Rust (`cargo test` in
//! `fuzz/`), so they stay regression tests.
//!
//! Files named `crash-*` reproduce open kernel issues (`strahl_fuzz::KNOWN_ISSUES`): they must
//! pass with the known issues tolerated, and `cargo test -- --ignored` shows them failing strictly
//! until the kernels are fixed (then drop the `#[ignore]`).

use std::path::{Path, PathBuf};
use strahl_fuzz::{KernelCase, check_kernels_with};

fn files(target: &str, crashes: bool) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("seeds").join(target);
    let mut v: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("crash-") == crashes)
        .collect();
    v.sort();
    v
}

fn replay(paths: &[PathBuf], strict: bool) {
    let mut failed = Vec::new();
    for path in paths {
        let data = std::fs::read(path).unwrap();
        let case = KernelCase::decode(&data);
        if std::panic::catch_unwind(|| check_kernels_with(&case, strict)).is_err() {
            failed.push(path.display().to_string());
        }
    }
    assert!(failed.is_empty(), "failed (strict: {strict}): {failed:#?}");
}

#[test]
fn kernels_seeds() {
    let seeds = files("kernels", false);
    assert!(!seeds.is_empty());
    replay(&seeds, true);
}

#[test]
fn kernels_crashes_tolerated() {
    replay(&files("kernels", true), false);
}

#[test]
#[ignore = "open kernel issues: see strahl_fuzz::KNOWN_ISSUES"]
fn kernels_crashes_strict() {
    replay(&files("kernels", true), true);
}

/// Every byte string decodes, including the empty one and truncations of the seeds.
#[test]
fn short_inputs() {
    for data in [&[][..], &[0], &[1], &[3], &[0xff; 3]] {
        check_kernels_with(&KernelCase::decode(data), true);
    }
    for path in files("kernels", false) {
        let data = std::fs::read(&path).unwrap();
        for n in (0..data.len()).step_by(7) {
            check_kernels_with(&KernelCase::decode(&data[..n]), true);
        }
    }
}
