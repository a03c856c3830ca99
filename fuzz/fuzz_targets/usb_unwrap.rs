//! The `usb_unwrap` target: its body is `aptscope_fuzz_bodies::usb_unwrap::fuzz` (see there).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| aptscope_fuzz_bodies::usb_unwrap::fuzz(data));
