//! Prints a decoded `kernels` input and runs the checker on it:
//!
//! ```text
//! cargo run --example replay -- seeds/kernels/grid-aim-edge artifacts/kernels/crash-...
//! ```

use strahl_fuzz::{KernelCase, check_kernels};

fn main() {
    for path in std::env::args().skip(1) {
        let data = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let case = KernelCase::decode(&data);
        println!("== {path} ({} bytes)\n{case}", data.len());
        check_kernels(&case);
        println!("ok");
    }
}
