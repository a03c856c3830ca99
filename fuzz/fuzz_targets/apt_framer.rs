//! The `apt_framer` target: its body is `aptscope_fuzz_bodies::apt_framer::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::apt_framer::fuzz(data));
