//! The `tui_view` target: its body is `aptscope_fuzz_bodies::tui_view::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::tui_view::fuzz(data));
