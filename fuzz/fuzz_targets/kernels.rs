//! Ray/box and ray/triangle kernels: scalar, x4, x8 and packet forms against each other, brute
//! force and (grid mode) exact arithmetic. Input format: `strahl_fuzz::decode`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strahl_fuzz::{KernelCase, check_kernels};

fuzz_target!(|data: &[u8]| {
    check_kernels(&KernelCase::decode(data));
});
