//! Every BVH builder, the BVH4/BVH8 collapse, single-ray and packet traversal against brute
//! force. Input format: `strahl_fuzz::bvh`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strahl_fuzz::{BvhCase, check_bvh};

fuzz_target!(|data: &[u8]| {
    check_bvh(&BvhCase::decode(data));
});
