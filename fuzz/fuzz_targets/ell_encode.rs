//! The `ell_encode` target: its body is `aptscope_fuzz_bodies::ell_encode::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::ell_encode::fuzz(data));
