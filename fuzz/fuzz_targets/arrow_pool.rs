//! The `arrow_pool` target: its body is `aptscope_fuzz_bodies::arrow_pool::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::arrow_pool::fuzz(data));
