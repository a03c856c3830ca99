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
                Event::Diag(d) => kinds.push(d.kind()),
                Event::Stream(_) => {}
            }
        }
        assert!(kinds.contains(&"bad_repeat"), "{f}: {kinds:?}");
    }
}

/// A pcap whose resynchronisation needed more input than was buffered: read whole, the reader
/// compared a position from before the buffer moved and gave up on the rest of the file; read
/// in short pieces, it found the records after the damage. Both now read the same.
#[test]
fn resynchronisation_rebases_after_reading_more() {
    use aptscope_capture::pcap::PcapReader;
    use std::io::Read;
    struct Short(std::io::Cursor<Vec<u8>>, usize);
    impl Read for Short {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = buf.len().min(self.1);
            self.0.read(&mut buf[..n])
        }
    }
    let path = format!(
        "{}/../fuzz/artifacts-found/pcap_reader/pcap-resync-rebase.fuzz",
        env!("CARGO_MANIFEST_DIR")
    );
    let data = std::fs::read(path).expect("reproducer");
    let file = data[3..].to_vec(); // after the fuzz target's control bytes
    let events = |r: &mut dyn aptscope_capture::Reader| {
        let mut v = vec![];
        while let Some(ev) = r.next_event() {
            v.push(match ev {
                Event::Diag(d) => format!("diag {}@{}", d.kind(), d.offset),
                e => format!("{e:?}"),
            });
        }
        v
    };
    let whole = events(&mut PcapReader::new(
        std::io::Cursor::new(file.clone()),
        None,
    ));
    for n in [1, 7, 31, 64, 4096] {
        let short = events(&mut PcapReader::new(
            Short(std::io::Cursor::new(file.clone()), n),
            None,
        ));
        assert_eq!(short, whole, "reads of {n} bytes");
    }
    let after = whole
        .iter()
        .position(|e| e == "diag bad_record@653")
        .expect("the damage is reported");
    assert!(
        whole[after..].iter().any(|e| e.starts_with("Chunk")),
        "records after the damage are read: {whole:?}"
    );
}
