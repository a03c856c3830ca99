//! The `textlog_reader` target: its body is `aptscope_fuzz_bodies::textlog_reader::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::textlog_reader::fuzz(data));
