//! Throughput of capture reading and writing: pcapng read, usbmon read with FTDI unwrapping,
//! MCAP write (raw and decoded channels). Criterion prints MB/s of serial payload and chunks/s.

use aptscope_capture::mcap::{McapOptions, McapWriter};
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

/// The MCAP options the environment asks for, to compare settings: `APTSCOPE_MCAP_COMPRESSION`
/// (`zstd:LEVEL`, `lz4`, `none`), `APTSCOPE_MCAP_CHUNK` (chunk size in bytes),
/// `APTSCOPE_MCAP_THREADS` (compression threads); the writer's defaults without them.
fn mcap_options() -> McapOptions {
    let mut o = McapOptions::new();
    if let Ok(c) = std::env::var("APTSCOPE_MCAP_COMPRESSION") {
        o = match c.split_once(':') {
            _ if c == "none" => o.compression(None),
            _ if c == "lz4" => o.compression(Some(mcap::Compression::Lz4)),
            Some(("zstd", l)) => o
                .compression(Some(mcap::Compression::Zstd))
                .compression_level(l.parse().expect("zstd:LEVEL")),
            _ => panic!("APTSCOPE_MCAP_COMPRESSION: zstd:LEVEL, lz4 or none"),
        };
    }
    if let Ok(n) = std::env::var("APTSCOPE_MCAP_CHUNK") {
        o = o.chunk_size(Some(n.parse().expect("APTSCOPE_MCAP_CHUNK=<bytes>")));
    }
    if let Ok(n) = std::env::var("APTSCOPE_MCAP_THREADS") {
        o = o.compression_threads(n.parse().expect("APTSCOPE_MCAP_THREADS=<n>"));
    }
    o
}

/// Write `cs` as MCAP (raw and decoded channels).
#[inline(never)]
fn mcap_write_once(cs: &[OwnedChunk], port: &StreamInfo) -> Vec<u8> {
    let out = Cursor::new(Vec::with_capacity(64 << 20));
    let mut w = McapWriter::with_options(out, None, mcap_options()).expect("mcap");
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
/// main thread's profile plus the whole of the `mcap-zstd-*` and `mcap-writer` threads'.
fn mcap_once() -> bool {
    let Ok(mib) = std::env::var("APTSCOPE_MCAP_ONCE") else {
        return false;
    };
    let mib: usize = mib.parse().expect("APTSCOPE_MCAP_ONCE=<MiB>");
    let cs = chunks(mib << 20);
    let payload: usize = cs.iter().map(|c| c.bytes.len()).sum();
    let (wall, proc0, main0) = (std::time::Instant::now(), process_cpu(), thread_cpu());
    let mcap = mcap_write_once(&cs, &port());
    let (wall, proc_s, main_s) = (
        wall.elapsed().as_secs_f64(),
        process_cpu() - proc0,
        thread_cpu() - main0,
    );
    let mib = payload as f64 / (1 << 20) as f64;
    eprintln!(
        "{} chunks, {payload} payload bytes -> {} bytes of MCAP\n\
         wall {wall:.2} s ({:.1} MiB/s); CPU {proc_s:.2} s = {:.3} s/MiB \
         (calling thread {:.3}, other threads {:.3}): {:.1} MiB per CPU-second",
        cs.len(),
        mcap.len(),
        mib / wall,
        proc_s / mib,
        main_s / mib,
        (proc_s - main_s) / mib,
        mib / proc_s,
    );
    if let Ok(path) = std::env::var("APTSCOPE_MCAP_OUT") {
        std::fs::write(path, &mcap).expect("write MCAP");
    }
    true
}

/// CPU time of the whole process so far (every thread, ended ones included), in seconds; the
/// kernel counts it in clock ticks (10 ms), so runs should last a few seconds.
fn process_cpu() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces): utime and stime are 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|x| x.parse::<u64>().ok()).unwrap_or(0);
    (ticks(11) + ticks(12)) as f64 / 100.0
}

/// CPU time of the calling thread so far, in seconds (ns resolution).
fn thread_cpu() -> f64 {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap_or_default();
    s.split_whitespace()
        .next()
        .and_then(|x| x.parse::<u64>().ok())
        .unwrap_or(0) as f64
        / 1e9
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
