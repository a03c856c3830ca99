//! The `mcap_reader` target: its body is `aptscope_fuzz_bodies::mcap_reader::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::mcap_reader::fuzz(data));
