//! The `encode_roundtrip` target: its body is `aptscope_fuzz_bodies::encode_roundtrip::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::encode_roundtrip::fuzz(data));
