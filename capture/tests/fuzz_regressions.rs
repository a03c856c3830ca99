//! Inputs the fuzzers found, kept as regression tests.

use aptscope_capture::open::{open, OpenOptions};
use aptscope_capture::Event;

/// A hexdump/xxd `*` line standing for gigabytes (or 16 EiB) is reported, not expanded.
#[test]
fn huge_hexdump_repeats_are_reported_not_expanded() {
    for f in [
        "hexdump-repeat-4gib.txt",
        "hexdump-repeat-16eib.txt",
        "xxd-repeat-4gib.txt",
    ] {
        let path = format!("{}/../fuzz/artifacts-found/{f}", env!("CARGO_MANIFEST_DIR"));
        let (mut r, _) = open(&path, OpenOptions::default()).expect("open");
        let (mut bytes, mut kinds) = (0u64, vec![]);
        while let Some(ev) = r.next_event() {
            match ev {
                Event::Chunk(c) => {
                    bytes += c.bytes.len() as u64;
                    assert!(bytes < 1 << 20, "{f}: the repeat is being expanded");
                }
                Event::Diag(d) => kinds.push(d.kind),
                Event::Stream(_) => {}
            }
        }
        assert!(kinds.contains(&"bad_repeat"), "{f}: {kinds:?}");
    }
}
