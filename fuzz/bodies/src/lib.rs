//! The bodies of the fuzz targets, one module per target, each a `fuzz(&[u8])` that panics when
//! a check fails. `fuzz/fuzz_targets/<target>.rs` hands libFuzzer's input to it;
//! `tests/corpus.rs` runs it over the target's seed corpus and the inputs that once crashed it,
//! so a check that goes stale fails `cargo test` without libFuzzer or a nightly compiler.

pub mod util;

pub mod apt_framer;
pub mod arrow_pool;
pub mod dataset_rows;
pub mod decode_pipeline;
pub mod ell_encode;
pub mod ell_framer;
pub mod encode_roundtrip;
pub mod filter_parse;
pub mod follow_reader;
pub mod mcap_reader;
pub mod pcap_reader;
pub mod textlog_reader;
pub mod tui_view;
pub mod units;
pub mod usb_unwrap;

/// A target's body: panics when a check fails.
pub type Body = fn(&[u8]);

/// Every target: its name (the `fuzz_targets/<name>.rs` binary and the `corpus/<name>/` folder)
/// and its body.
pub const TARGETS: &[(&str, Body)] = &[
    ("apt_framer", apt_framer::fuzz),
    ("arrow_pool", arrow_pool::fuzz),
    ("dataset_rows", dataset_rows::fuzz),
    ("decode_pipeline", decode_pipeline::fuzz),
    ("ell_encode", ell_encode::fuzz),
    ("ell_framer", ell_framer::fuzz),
    ("encode_roundtrip", encode_roundtrip::fuzz),
    ("filter_parse", filter_parse::fuzz),
    ("follow_reader", follow_reader::fuzz),
    ("mcap_reader", mcap_reader::fuzz),
    ("pcap_reader", pcap_reader::fuzz),
    ("textlog_reader", textlog_reader::fuzz),
    ("tui_view", tui_view::fuzz),
    ("units", units::fuzz),
    ("usb_unwrap", usb_unwrap::fuzz),
];
