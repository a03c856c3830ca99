//! The `dataset_rows` target: its body is `aptscope_fuzz_bodies::dataset_rows::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::dataset_rows::fuzz(data));
