//! Sort-last compositing: over and depth kernels (SIMD against scalar), sparse messages, every
//! schedule on the thread transport against the serial reference (bit for bit on the grid),
//! schedules as data, the cost model, the visibility order and tiles. Input format:
//! `strahl_fuzz::composite`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strahl_fuzz::{CompositeCase, check_composite};

fuzz_target!(|data: &[u8]| {
    check_composite(&CompositeCase::decode(data));
});
