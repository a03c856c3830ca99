//! Throughput of Elliptec framing + decoding + bus state/pairing over a generated multi-drop bus
//! stream (commands and replies of every kind). Criterion prints MB/s and frames/s.

use aptscope_dissector::ell::{Bus, EllFrame, EllFramer, Item};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;

/// A realistic bus conversation, repeated with varying addresses and positions.
fn stream(total: usize) -> (Vec<u8>, u64) {
    let mut v = Vec::with_capacity(total + 256);
    let mut frames = 0u64;
    let mut i = 0u32;
    while v.len() < total {
        let a = b"0123456789ABCDEF"[(i % 16) as usize] as char;
        let pos = i.wrapping_mul(2654435761) & 0x000F_FFFF;
        for line in [
            format!("{a}in"),
            format!("{a}IN0E1140028420200117016800023000\r\n"),
            format!("{a}ma{pos:08X}"),
            format!("{a}GS09\r\n"),
            format!("{a}PO{pos:08X}\r\n"),
            format!("{a}gs"),
            format!("{a}GS00\r\n"),
            format!("{a}gp"),
            format!("{a}PO{pos:08X}\r\n"),
            format!("{a}gv"),
            format!("{a}GV64\r\n"),
        ] {
            v.extend_from_slice(line.as_bytes());
            frames += 1;
        }
        i += 1;
    }
    (v, frames)
}

fn benches(c: &mut Criterion) {
    let (data, frames) = stream(32 << 20);
    for (unit, tp) in [
        ("bytes", Throughput::Bytes(data.len() as u64)),
        ("frames", Throughput::Elements(frames)),
    ] {
        let mut g = c.benchmark_group(format!("ell_{unit}"));
        g.sample_size(10).throughput(tp);
        g.bench_function("frame_decode_pair", |b| {
            b.iter(|| {
                let mut f = EllFramer::new();
                let mut bus = Bus::new();
                let mut n = 0u64;
                let mut acc = 0u64;
                for chunk in data.chunks(64 * 1024) {
                    f.push(chunk);
                    while let Some(it) = f.next_item() {
                        n += 1;
                        if let Item::Frame {
                            offset,
                            bytes,
                            truncated,
                        } = it
                        {
                            if let Some(fr) = EllFrame::decode(offset, bytes, truncated) {
                                let o = bus.observe(n, &fr, None);
                                acc += o.pair.unwrap_or(0) + fr.fields().count() as u64;
                            }
                        }
                    }
                }
                black_box(acc)
            })
        });
        g.finish();
    }
}

criterion_group!(ell, benches);
criterion_main!(ell);
