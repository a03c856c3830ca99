//! The `units` target: its body is `aptscope_fuzz_bodies::units::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::units::fuzz(data));
