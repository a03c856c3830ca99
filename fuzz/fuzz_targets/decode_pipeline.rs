//! The `decode_pipeline` target: its body is `aptscope_fuzz_bodies::decode_pipeline::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::decode_pipeline::fuzz(data));
