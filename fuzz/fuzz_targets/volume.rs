//! Volume ray marching: x8 against the scalar reference, empty-space skipping and early
//! termination against marching everything, macrocell grids against brute force, bad input, and
//! (grid mode) optical depths against closed forms. Input format: `strahl_fuzz::volume`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strahl_fuzz::{VolumeCase, check_volume};

fuzz_target!(|data: &[u8]| {
    check_volume(&VolumeCase::decode(data));
});
