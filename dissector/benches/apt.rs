//! Throughput of APT framing, typed decoding and NDJSON output over a 100 MB stream of mixed
//! messages (every form of the table, random values). Criterion prints MB/s and frames/s.

use aptscope_dissector::apt::{AptFrame, AptFramer, Item};
use aptscope_dissector::{json, synth, Table};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;

const TOTAL: usize = 100 * 1024 * 1024;
const CHUNK: usize = 64 * 1024;

fn input() -> (Vec<u8>, u64) {
    let block = synth::stream(Table::global(), 42, 200_000, false);
    let mut v = Vec::with_capacity(TOTAL + block.len());
    while v.len() < TOTAL {
        v.extend_from_slice(&block);
    }
    let mut f = AptFramer::new(Table::global());
    f.push(&v);
    f.finish();
    let mut frames = 0;
    while f.next_item().is_some() {
        frames += 1;
    }
    (v, frames)
}

fn run(input: &[u8], mut each: impl FnMut(Item<'_>)) {
    let mut f = AptFramer::new(Table::global());
    for c in input.chunks(CHUNK) {
        f.push(c);
        while let Some(it) = f.next_item() {
            each(it);
        }
    }
    f.finish();
    while let Some(it) = f.next_item() {
        each(it);
    }
}

fn typed(it: Item<'_>) -> u64 {
    let t = Table::global();
    let mut acc = 0u64;
    if let Item::Frame {
        offset,
        bytes,
        truncated,
    } = it
    {
        if let Some(fr) = AptFrame::decode(t, offset, bytes, truncated) {
            for (_, v) in fr.fields() {
                acc = acc.wrapping_add(v.as_i64().unwrap_or(1) as u64);
            }
        }
    }
    acc
}

fn benches(c: &mut Criterion) {
    let (data, frames) = input();
    let t = Table::global();
    eprintln!("stream: {} bytes, {frames} frames", data.len());
    for (unit, tp) in [
        ("bytes", Throughput::Bytes(data.len() as u64)),
        ("frames", Throughput::Elements(frames)),
    ] {
        let mut g = c.benchmark_group(format!("apt_{unit}"));
        g.sample_size(10).throughput(tp);
        g.bench_function("frame", |b| {
            b.iter(|| {
                let mut n = 0u64;
                run(&data, |it| n += it.bytes().len() as u64);
                black_box(n)
            })
        });
        g.bench_function("decode_typed", |b| {
            b.iter(|| {
                let mut acc = 0u64;
                run(&data, |it| acc = acc.wrapping_add(typed(it)));
                black_box(acc)
            })
        });
        g.bench_function("ndjson", |b| {
            let mut line = String::with_capacity(1024);
            b.iter(|| {
                let mut n = 0u64;
                let mut k = 0u64;
                run(&data, |it| {
                    line.clear();
                    k += 1;
                    match it {
                        Item::Frame {
                            offset,
                            bytes,
                            truncated,
                        } => {
                            if let Some(f) = AptFrame::decode(t, offset, bytes, truncated) {
                                json::apt_frame(&mut line, k, &f);
                            }
                        }
                        Item::Garbage {
                            offset,
                            bytes,
                            kind,
                        } => json::apt_garbage(&mut line, k, offset, bytes, kind),
                    }
                    n += line.len() as u64;
                });
                black_box(n)
            })
        });
        g.finish();
    }
}

criterion_group!(apt, benches);
criterion_main!(apt);
