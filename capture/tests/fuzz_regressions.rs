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

/// A source giving a few bytes per read is not asked for 1 MiB each time: the room a read asks
/// for is zeroed first, which made a 4.7 KB usbmon capture read 31 bytes at a time take 4.5 s
/// in a debug build (the fuzz corpus test showed it). After the first read (1 MiB), a request
/// is twice what the last read gave, 4 KiB at least.
#[test]
fn short_reads_are_not_answered_with_megabyte_requests() {
    use aptscope_capture::pcap::PcapReader;
    use std::io::Read;
    struct Asked {
        data: std::io::Cursor<Vec<u8>>,
        most: usize,
        asked: Vec<usize>,
    }
    impl Read for &mut Asked {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            self.asked.push(buf.len());
            let n = buf.len().min(self.most);
            self.data.read(&mut buf[..n])
        }
    }
    let path = format!(
        "{}/../samples/kdc101-session.usbmon.pcap",
        env!("CARGO_MANIFEST_DIR")
    );
    let file = std::fs::read(path).expect("sample");
    for most in [31, 1 << 30] {
        let mut src = Asked {
            data: std::io::Cursor::new(file.clone()),
            most,
            asked: vec![],
        };
        let mut r = PcapReader::new(&mut src, None);
        while aptscope_capture::Reader::next_event(&mut r).is_some() {}
        drop(r);
        let later = &src.asked[1..];
        if most == 31 {
            let largest = later.iter().max().copied().unwrap_or(0);
            assert!(
                largest <= 4096,
                "{} requests after the first, up to {largest} bytes",
                later.len()
            );
        } else {
            // Read whole by the first request; the next (which finds the end) asks for twice
            // what that one gave.
            let second = (2 * file.len()).clamp(4096, 1 << 20);
            assert_eq!(src.asked, [1 << 20, second]);
        }
    }
}
