//! Lossless round trips through every writable capture format: our pcapng → MCAP → pcap →
//! pcapng keeps every byte, timestamp, direction and stream.

use aptscope_capture::open::{create, open, Format, OpenOptions};
use aptscope_capture::{Direction, Event, OwnedChunk, StreamInfo};
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

fn tmp(ext: &str) -> PathBuf {
    static N: AtomicU64 = AtomicU64::new(0);
    let n = N.fetch_add(1, Ordering::Relaxed);
    std::env::temp_dir().join(format!("aptscope-rt-{}-{n}.{ext}", std::process::id()))
}

fn write(path: &Path, format: Format, streams: &[StreamInfo], chunks: &[OwnedChunk]) {
    let p = path.to_str().expect("utf-8 temp path");
    let mut w = create(p, format, true).expect("create");
    for s in streams {
        w.stream(s).expect("stream");
    }
    for c in chunks {
        w.chunk(&c.as_chunk()).expect("chunk");
    }
    w.finish().expect("finish");
}

fn read(path: &Path) -> (Vec<OwnedChunk>, Vec<String>) {
    let (mut r, _) = open(path.to_str().expect("utf-8"), OpenOptions::default()).expect("open");
    let (mut chunks, mut diags) = (vec![], vec![]);
    while let Some(ev) = r.next_event() {
        match ev {
            Event::Chunk(c) => chunks.push(c.to_owned()),
            Event::Diag(d) => diags.push(d.to_string()),
            Event::Stream(_) => {}
        }
    }
    (chunks, diags)
}

fn chunk_strategy() -> impl Strategy<Value = Vec<OwnedChunk>> {
    proptest::collection::vec(
        (
            proptest::collection::vec(any::<u8>(), 1..300),
            0u8..3,
            0u32..3,
            0u64..5_000_000_000,
        ),
        1..40,
    )
    .prop_map(|v| {
        let mut t = 1_700_000_000_000_000_000u64;
        v.into_iter()
            .map(|(bytes, d, stream, dt)| {
                t += dt;
                OwnedChunk {
                    ts_ns: Some(t),
                    dir: match d {
                        0 => Direction::HostToDevice,
                        1 => Direction::DeviceToHost,
                        _ => Direction::Unknown,
                    },
                    stream,
                    bytes,
                }
            })
            .collect()
    })
}

fn streams() -> Vec<StreamInfo> {
    (0..3)
        .map(|id| StreamInfo {
            id,
            name: format!("/dev/ttyUSB{id}"),
            settings: Some("115200 8N1 RTS/CTS".into()),
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn pcapng_mcap_pcap_pcapng_is_lossless(chunks in chunk_strategy()) {
        let s = streams();
        let (a, b, c, d) = (tmp("pcapng"), tmp("mcap"), tmp("pcap"), tmp("pcapng"));
        write(&a, Format::PcapNg, &s, &chunks);
        let (ra, da) = read(&a);
        prop_assert!(da.is_empty(), "{da:?}");
        prop_assert_eq!(&ra, &chunks);
        write(&b, Format::Mcap, &s, &ra);
        let (rb, db) = read(&b);
        prop_assert!(db.is_empty(), "{db:?}");
        prop_assert_eq!(&rb, &chunks);
        write(&c, Format::Pcap, &s, &rb);
        let (rc, dc) = read(&c);
        prop_assert!(dc.is_empty(), "{dc:?}");
        prop_assert_eq!(&rc, &chunks);
        write(&d, Format::PcapNg, &s, &rc);
        let (rd, _) = read(&d);
        prop_assert_eq!(&rd, &chunks);
        for p in [a, b, c, d] {
            let _ = std::fs::remove_file(p);
        }
    }
}

#[test]
fn writing_refuses_to_overwrite_without_force() {
    let p = tmp("pcapng");
    write(&p, Format::PcapNg, &[], &[]);
    let e = create(p.to_str().expect("utf-8"), Format::PcapNg, false)
        .err()
        .expect("refused");
    assert!(e.to_string().contains("--force"), "{e}");
    let _ = std::fs::remove_file(p);
}

#[test]
fn truncated_pcapng_keeps_what_precedes_and_says_where() {
    let chunks: Vec<OwnedChunk> = (0..5)
        .map(|i| OwnedChunk {
            ts_ns: Some(1_000 + i),
            dir: Direction::HostToDevice,
            stream: 0,
            bytes: vec![0x23, 0x02, 0x01, 0x00, 0x50, 0x01],
        })
        .collect();
    let p = tmp("pcapng");
    write(&p, Format::PcapNg, &streams()[..1], &chunks);
    let full = std::fs::read(&p).expect("read");
    // Cut the last block in half.
    std::fs::write(&p, &full[..full.len() - 10]).expect("write");
    let (got, diags) = read(&p);
    assert_eq!(got, chunks[..4]);
    assert_eq!(diags.len(), 1, "{diags:?}");
    assert!(diags[0].contains("truncated_record"), "{diags:?}");
    // A corrupt block length in the middle: the blocks after it are still read.
    let mut bad = full.clone();
    // Find the EPBs (block type 6, little endian) and break the length of the second one.
    let u32_at =
        |i: usize| u32::from_le_bytes([full[i], full[i + 1], full[i + 2], full[i + 3]]) as usize;
    let mut epbs = vec![];
    let mut i = 0;
    while i + 8 <= full.len() {
        if u32_at(i) == 6 {
            epbs.push(i);
        }
        i += u32_at(i + 4).max(4);
    }
    assert!(epbs.len() >= 5);
    bad[epbs[1] + 4..epbs[1] + 8].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    std::fs::write(&p, &bad).expect("write");
    let (got, diags) = read(&p);
    assert_eq!(diags.len(), 1, "{diags:?}");
    assert!(diags[0].starts_with(&format!("@{}:", epbs[1])), "{diags:?}");
    assert_eq!(
        got.len(),
        4,
        "the corrupt block is skipped, the others read"
    );
    let _ = std::fs::remove_file(p);
}

#[test]
fn bad_magic_and_empty_files() {
    let p = tmp("pcap");
    std::fs::write(&p, b"").expect("write");
    let (got, diags) = read(&p);
    assert!(got.is_empty() && diags.is_empty());
    let _ = std::fs::remove_file(p);
}
