//! What the dissector's integration tests share: building frames from the table by name, and
//! running bytes through the pipeline.
#![allow(dead_code)]

use aptscope_dissector::apt::{encode_named, Named};
use aptscope_dissector::pipeline::{Format, Pipeline};
use aptscope_dissector::Table;

/// A frame of message `name` with field values as text (`form`: `hdr`, a length, or the first
/// that fits).
pub fn frame(name: &str, values: &[(&str, &str)], form: Option<&str>, dst: u8, src: u8) -> Vec<u8> {
    encode_named(
        Table::global(),
        &Named {
            name,
            sub: None,
            values,
            form,
            dst,
            src,
        },
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The lines the pipeline writes for `bytes` fed in chunks of `step` bytes (0: all at once).
pub fn decode_lines(bytes: &[u8], fmt: Format, step: usize) -> Vec<String> {
    let mut p = Pipeline::new(None, fmt);
    let mut out: Vec<String> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(l.to_string());
        Ok(())
    };
    let chunks: Vec<&[u8]> = if step == 0 {
        vec![bytes]
    } else {
        bytes.chunks(step).collect()
    };
    for c in chunks {
        p.push(c, None, &mut emit).expect("push");
    }
    p.finish(&mut emit).expect("finish");
    out
}

/// The NDJSON records the pipeline writes for `bytes` (chunks of `step`), without the
/// protocol-detection notice.
pub fn decode_json(bytes: &[u8], step: usize) -> Vec<serde_json::Value> {
    decode_lines(bytes, Format::Json, step)
        .iter()
        .map(|l| serde_json::from_str(l).expect("json"))
        .filter(|v: &serde_json::Value| v["type"] != "detect")
        .collect()
}

/// The diagnostic kinds of a record.
pub fn kinds(v: &serde_json::Value) -> Vec<&str> {
    v["diag"]
        .as_array()
        .map(|a| a.iter().filter_map(|d| d["kind"].as_str()).collect())
        .unwrap_or_default()
}

/// A framer's item, owned: a frame (offset, bytes, truncated) or a garbage run (offset, bytes,
/// and what the APT framer saw; `None` for Elliptec).
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// A frame.
    Frame(u64, Vec<u8>, bool),
    /// Bytes outside frames.
    Garbage(u64, Vec<u8>, Option<aptscope_dissector::apt::GarbageKind>),
}

/// `input` in the chunks that cutting it at `cuts` (clamped, in order) gives.
fn chunks<'a>(input: &'a [u8], cuts: &[usize]) -> Vec<&'a [u8]> {
    let mut out = vec![];
    let mut at = 0;
    for &c in cuts.iter().chain(std::iter::once(&input.len())) {
        let c = c.clamp(at, input.len());
        out.push(&input[at..c]);
        at = c;
    }
    out
}

/// The APT framer's items for `input` pushed in the chunks cut at `cuts`, then finished.
pub fn run_apt(input: &[u8], cuts: &[usize]) -> Vec<Item> {
    use aptscope_dissector::apt::{AptFramer, Item as A};
    let mut f = AptFramer::new(Table::global());
    let mut out = vec![];
    let drain = |f: &mut AptFramer, out: &mut Vec<Item>| {
        while let Some(it) = f.next_item() {
            out.push(match it {
                A::Frame {
                    offset,
                    bytes,
                    truncated,
                } => Item::Frame(offset, bytes.to_vec(), truncated),
                A::Garbage {
                    offset,
                    bytes,
                    kind,
                } => Item::Garbage(offset, bytes.to_vec(), Some(kind)),
            });
        }
    };
    for c in chunks(input, cuts) {
        f.push(c);
        drain(&mut f, &mut out);
    }
    f.finish();
    drain(&mut f, &mut out);
    out
}

/// The Elliptec framer's items for `input` pushed in the chunks cut at `cuts`, then finished.
pub fn run_ell(input: &[u8], cuts: &[usize]) -> Vec<Item> {
    use aptscope_dissector::ell::{EllFramer, Item as E};
    let mut f = EllFramer::new();
    let mut out = vec![];
    let drain = |f: &mut EllFramer, out: &mut Vec<Item>| {
        while let Some(it) = f.next_item() {
            out.push(match it {
                E::Frame {
                    offset,
                    bytes,
                    truncated,
                } => Item::Frame(offset, bytes.to_vec(), truncated),
                E::Garbage { offset, bytes, .. } => Item::Garbage(offset, bytes.to_vec(), None),
            });
        }
    };
    for c in chunks(input, cuts) {
        f.push(c);
        drain(&mut f, &mut out);
    }
    f.finish();
    drain(&mut f, &mut out);
    out
}

/// The frames (offset, bytes, truncated) of `items`, and how many garbage bytes they hold.
pub fn frames_and_garbage(items: &[Item]) -> (Vec<(u64, Vec<u8>, bool)>, usize) {
    let (mut fs, mut garbage) = (vec![], 0);
    for it in items {
        match it {
            Item::Frame(o, b, t) => fs.push((*o, b.clone(), *t)),
            Item::Garbage(_, b, _) => garbage += b.len(),
        }
    }
    (fs, garbage)
}
