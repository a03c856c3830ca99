//! Typed decoding of a raw APT byte stream held in memory, timed: `decode_file FILE [RUNS]`.
//!
//! The file is read fully first; each run then frames it (64 KiB pushes, like the `decode_typed`
//! criterion bench), decodes every frame against the table (`AptFrame::decode`) and reads every
//! field value. Prints one JSON object: bytes, frames, garbage records, the seconds of each run
//! and of the best one, and throughput of the best run.
//!
//! `decode_file FILE --dump` instead prints one JSON line per frame with the raw field values
//! (numbers as read, text up to the first NUL, bytes as hex), for comparing with another decoder.

use aptscope_dissector::apt::{text_of, AptFrame, AptFramer, Item, Value};
use aptscope_dissector::Table;
use serde_json::{json, Map, Value as Json};
use std::hint::black_box;
use std::io::Write;
use std::time::Instant;

const CHUNK: usize = 64 * 1024;

/// Frame and decode `input`, reading every field; returns (frames, garbage records, checksum).
fn decode_all(input: &[u8]) -> (u64, u64, u64) {
    let t = Table::global();
    let mut frames = 0u64;
    let mut garbage = 0u64;
    let mut acc = 0u64;
    let mut each = |it: Item<'_>| match it {
        Item::Frame {
            offset,
            bytes,
            truncated,
        } => {
            frames += 1;
            if let Some(fr) = AptFrame::decode(t, offset, bytes, truncated) {
                // Summed in a local: `acc` is behind the closure's reference, and adding to it
                // per field made a chain of stores and loads through memory.
                let mut sum = 0u64;
                for (_, v) in fr.fields() {
                    sum = sum.wrapping_add(fold(&v));
                }
                acc = acc.wrapping_add(sum);
            }
        }
        Item::Garbage { .. } => garbage += 1,
    };
    let mut f = AptFramer::new(t);
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
    (frames, garbage, acc)
}

/// Use a value so that reading it cannot be optimised away. Inline in the field loop: as a
/// call (it recursed for arrays) it cost more than reading the value.
#[inline]
fn fold(v: &Value<'_>) -> u64 {
    match *v {
        Value::U(x) => x,
        Value::I(x) => x as u64,
        Value::F(x) => x.to_bits(),
        Value::Str(b) => text_of(b).len() as u64,
        Value::Bytes(b) => b.len() as u64,
        Value::Array(..) => fold_array(v),
    }
}

/// [`fold`] of an array's elements (a call of its own, so that `fold` itself inlines).
#[inline(never)]
fn fold_array(v: &Value<'_>) -> u64 {
    v.elements().map(|e| fold(&e)).fold(0, u64::wrapping_add)
}

fn raw_json(v: &Value<'_>) -> Json {
    match *v {
        Value::U(x) => json!(x),
        Value::I(x) => json!(x),
        Value::F(x) => json!(x),
        Value::Str(b) => json!(text_of(b)),
        Value::Bytes(b) => json!(b.iter().map(|x| format!("{x:02x}")).collect::<String>()),
        Value::Array(..) => Json::Array(v.elements().map(|e| raw_json(&e)).collect()),
    }
}

fn dump(input: &[u8]) -> std::io::Result<()> {
    let t = Table::global();
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let mut f = AptFramer::new(t);
    f.push(input);
    f.finish();
    while let Some(it) = f.next_item() {
        let line = match it {
            Item::Frame {
                offset,
                bytes,
                truncated,
            } => match AptFrame::decode(t, offset, bytes, truncated) {
                Some(fr) => {
                    let fields: Map<String, Json> = fr
                        .fields()
                        .map(|(f, v)| (f.name.to_string(), raw_json(&v)))
                        .collect();
                    let h = fr.header();
                    json!({"offset": offset, "name": fr.name(), "msgid": h.msg_id(),
                           "src": h.src_byte(), "dst": h.dst_byte(),
                           "len": bytes.len(), "diag": fr.has_diags(), "fields": fields})
                }
                None => json!({"offset": offset, "name": null}),
            },
            Item::Garbage { offset, bytes, .. } => {
                json!({"offset": offset, "garbage": bytes.len()})
            }
        };
        writeln!(out, "{line}")?;
    }
    out.flush()
}

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: decode_file FILE [RUNS | --dump]");
        std::process::exit(2);
    };
    let input = std::fs::read(&path).unwrap_or_else(|e| {
        eprintln!("decode_file: {path}: {e}");
        std::process::exit(1);
    });
    let arg = args.next();
    if arg.as_deref() == Some("--dump") {
        if let Err(e) = dump(&input) {
            // A closed pipe (`| head`) is not an error worth a panic.
            if e.kind() != std::io::ErrorKind::BrokenPipe {
                eprintln!("decode_file: {e}");
                std::process::exit(1);
            }
        }
        return;
    }
    let runs: usize = arg.and_then(|a| a.parse().ok()).unwrap_or(5).max(1);
    let mut secs = Vec::with_capacity(runs);
    let mut result = (0, 0, 0);
    for _ in 0..runs {
        let start = Instant::now();
        result = black_box(decode_all(black_box(&input)));
        secs.push(start.elapsed().as_secs_f64());
    }
    let best = secs.iter().copied().fold(f64::INFINITY, f64::min);
    let (frames, garbage, checksum) = result;
    println!(
        "{}",
        json!({
            "bytes": input.len(),
            "messages": frames,
            "garbage": garbage,
            "checksum": checksum,
            "runs": secs,
            "seconds": best,
            "mb_per_s": input.len() as f64 / best / 1e6,
            "msgs_per_s": frames as f64 / best,
        })
    );
}
