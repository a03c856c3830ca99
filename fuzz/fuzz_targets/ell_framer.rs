//! The `ell_framer` target: its body is `aptscope_fuzz_bodies::ell_framer::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::ell_framer::fuzz(data));
