//! The `filter_parse` target: its body is `aptscope_fuzz_bodies::filter_parse::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::filter_parse::fuzz(data));
