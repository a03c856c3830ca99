//! Throughput of capture reading and writing: pcapng read, usbmon read with FTDI unwrapping,
//! MCAP write (raw and decoded channels). Criterion prints MB/s of serial payload and chunks/s.

use aptscope_capture::mcap::McapWriter;
use aptscope_capture::model::{Event, Reader, Writer};
use aptscope_capture::pcap::{PcapNgOut, PcapReader};
use aptscope_capture::usb::synth_usbmon;
use aptscope_capture::{Direction, OwnedChunk, StreamInfo};
use aptscope_dissector::{synth, Table};
use criterion::{criterion_group, Criterion, Throughput};
use pcap_file::pcap::{PcapHeader, PcapPacket, PcapWriter};
use pcap_file::{DataLink, TsResolution};
use std::hint::black_box;
use std::io::Cursor;
use std::time::Duration;

/// Serial traffic as chunks of 20 bytes, alternating direction, 100 µs apart.
fn chunks(total: usize) -> Vec<OwnedChunk> {
    let bytes = synth::stream(Table::global(), 7, total / 14, false);
    let mut t = 1_700_000_000_000_000_000u64;
    bytes
        .chunks(20)
        .enumerate()
        .map(|(i, b)| {
            t += 100_000;
            OwnedChunk {
                ts_ns: Some(t),
                dir: if i % 2 == 0 {
                    Direction::HostToDevice
                } else {
                    Direction::DeviceToHost
                },
                stream: 0,
                bytes: b.to_vec(),
            }
        })
        .collect()
}

fn read_all(r: &mut dyn Reader) -> u64 {
    let mut n = 0;
    while let Some(ev) = r.next_event() {
        if let Event::Chunk(c) = ev {
            n += c.bytes.len() as u64;
        }
    }
    n
}

/// The MCAP options `APTSCOPE_MCAP_COMPRESSION` asks for (`zstd:LEVEL`, `lz4`, `none`), to
/// compare compressions; the writer's defaults without it.
fn mcap_options() -> Option<mcap::WriteOptions> {
    let c = std::env::var("APTSCOPE_MCAP_COMPRESSION").ok()?;
    let o = mcap::WriteOptions::new().compression_threads(0);
    Some(match c.split_once(':') {
        _ if c == "none" => o.compression(None),
        _ if c == "lz4" => o.compression(Some(mcap::Compression::Lz4)),
        Some(("zstd", l)) => o
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(l.parse().expect("zstd:LEVEL")),
        _ => panic!("APTSCOPE_MCAP_COMPRESSION: zstd:LEVEL, lz4 or none"),
    })
}

/// Write `cs` as MCAP (raw and decoded channels).
#[inline(never)]
fn mcap_write_once(cs: &[OwnedChunk], port: &StreamInfo) -> Vec<u8> {
    let out = Cursor::new(Vec::with_capacity(64 << 20));
    let mut w = match mcap_options() {
        Some(o) => McapWriter::with_options(out, None, o),
        None => McapWriter::new(out, None),
    }
    .expect("mcap");
    w.stream(port).expect("stream");
    for ch in cs {
        w.chunk(&ch.as_chunk()).expect("chunk");
    }
    w.finish().expect("finish");
    w.into_inner().expect("finished").into_inner()
}

fn port() -> StreamInfo {
    StreamInfo {
        id: 0,
        name: "/dev/ttyUSB0".into(),
        settings: None,
    }
}

/// `APTSCOPE_MCAP_ONCE=<MiB>`: write that much once and exit (and save the file to
/// `APTSCOPE_MCAP_OUT` when set), instead of running criterion, for a repeatable instruction
/// count on a fixed input: `APTSCOPE_MCAP_ONCE=1 valgrind --tool=callgrind --separate-threads=yes
/// target/release/deps/capture-<hash>`. The write costs `mcap_write_once` (inclusive) in the
/// main thread's profile plus the whole of the `mcap-writer` thread's.
fn mcap_once() -> bool {
    let Ok(mib) = std::env::var("APTSCOPE_MCAP_ONCE") else {
        return false;
    };
    let mib: usize = mib.parse().expect("APTSCOPE_MCAP_ONCE=<MiB>");
    let cs = chunks(mib << 20);
    let payload: usize = cs.iter().map(|c| c.bytes.len()).sum();
    let mcap = mcap_write_once(&cs, &port());
    eprintln!(
        "{} chunks, {payload} payload bytes -> {} bytes of MCAP",
        cs.len(),
        mcap.len()
    );
    if let Ok(path) = std::env::var("APTSCOPE_MCAP_OUT") {
        std::fs::write(path, &mcap).expect("write MCAP");
    }
    true
}

fn benches(c: &mut Criterion) {
    let cs = chunks(16 << 20);
    let payload: u64 = cs.iter().map(|c| c.bytes.len() as u64).sum();
    let port = port();
    let mut pcapng = vec![];
    {
        let mut w = PcapNgOut::new(&mut pcapng).expect("writer");
        w.stream(&port).expect("stream");
        for ch in &cs {
            w.chunk(&ch.as_chunk()).expect("chunk");
        }
        w.finish().expect("finish");
    }
    let mut usb = vec![];
    {
        let header = PcapHeader {
            datalink: DataLink::from(220),
            ts_resolution: TsResolution::MicroSecond,
            ..PcapHeader::default()
        };
        let mut pw = PcapWriter::with_header(&mut usb, header).expect("usbmon");
        for (ts, rec) in synth_usbmon(&cs, 1, 7, 64) {
            pw.write_packet(&PcapPacket::new(
                Duration::from_nanos(ts),
                rec.len() as u32,
                &rec,
            ))
            .expect("packet");
        }
    }
    for (unit, tp) in [
        ("bytes", Throughput::Bytes(payload)),
        ("chunks", Throughput::Elements(cs.len() as u64)),
    ] {
        let mut g = c.benchmark_group(format!("capture_{unit}"));
        g.sample_size(10).throughput(tp);
        g.bench_function("pcapng_read", |b| {
            b.iter(|| {
                black_box(read_all(&mut PcapReader::new(
                    Cursor::new(&pcapng[..]),
                    None,
                )))
            })
        });
        g.bench_function("usbmon_read_ftdi", |b| {
            b.iter(|| black_box(read_all(&mut PcapReader::new(Cursor::new(&usb[..]), None))))
        });
        g.bench_function("mcap_write", |b| {
            b.iter(|| black_box(mcap_write_once(&cs, &port)))
        });
        g.finish();
    }
}

criterion_group!(capture, benches);

fn main() {
    if !mcap_once() {
        capture();
        Criterion::default().configure_from_args().final_summary();
    }
}
