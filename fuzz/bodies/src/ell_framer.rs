//! Elliptec framer + decoder + bus state on any bytes, pushed in chunks derived from the input.
//!
//! Input: `[max_chunk, seed, times, stream...]` (times: see `Times`). Checks: every input byte is in exactly one
//! frame or garbage record, in order, with contiguous offsets and the input's own bytes; the
//! records do not depend on the chunking; only the last record can be truncated; every frame the
//! framer gives decodes (the pipeline drops a frame that does not, losing its bytes); diagnostics
//! point inside their frame (or just past it); the bus, JSON and text rendering do not panic, and
//! the JSON parses. Times fed to the bus may be anywhere in the u64 range.

use crate::util::{cuts, split_ctl, Times};
use aptscope_dissector::ell::{fmt_value, Bus, EllFrame, EllFramer, GarbageKind, Item};
use aptscope_dissector::{apt::MAX_GARBAGE_RUN, json, text};

#[derive(Debug, Clone, PartialEq)]
enum Rec {
    Frame(u64, Vec<u8>, bool),
    Garbage(u64, Vec<u8>, GarbageKind),
}

fn run(input: &[u8], cut: &[usize]) -> Vec<Rec> {
    let mut f = EllFramer::new();
    let mut out = vec![];
    let mut drain = |f: &mut EllFramer| {
        while let Some(it) = f.next_item() {
            out.push(match it {
                Item::Frame {
                    offset,
                    bytes,
                    truncated,
                } => Rec::Frame(offset, bytes.to_vec(), truncated),
                Item::Garbage {
                    offset,
                    bytes,
                    kind,
                } => Rec::Garbage(offset, bytes.to_vec(), kind),
            });
        }
    };
    let mut at = 0;
    for &c in cut.iter().chain(std::iter::once(&input.len())) {
        f.push(&input[at..c]);
        drain(&mut f);
        at = c;
    }
    f.finish();
    drain(&mut f);
    assert!(f.next_item().is_none());
    out
}

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let (ctl, input) = split_ctl::<3>(data);
    let cut = cuts(input.len(), ctl[0], ctl[1]);
    let recs = run(input, &cut);
    if !cut.is_empty() {
        assert_eq!(recs, run(input, &[]), "chunking changed the records");
    }

    let mut bus = Bus::new();
    let mut times = Times::new(ctl[2]);
    let mut s = String::new();
    let mut at = 0u64;
    let last = recs.len().saturating_sub(1);
    for (i, r) in recs.iter().enumerate() {
        let n = i as u64 + 1;
        let (off, b) = match r {
            Rec::Frame(o, b, _) | Rec::Garbage(o, b, _) => (*o, b),
        };
        assert_eq!(off, at, "records are contiguous");
        assert!(!b.is_empty(), "empty record");
        assert_eq!(&input[off as usize..off as usize + b.len()], &b[..]);
        at += b.len() as u64;
        match r {
            Rec::Frame(_, _, truncated) => {
                if *truncated {
                    assert_eq!(i, last, "only the last record can be truncated");
                }
                let f = EllFrame::decode(off, b, *truncated)
                    .unwrap_or_else(|| panic!("framed bytes {b:?} at {off} do not decode"));
                for d in f.diags() {
                    assert!(
                        d.offset >= off && d.offset <= off + b.len() as u64,
                        "diag {d:?} outside its frame at {off}+{}",
                        b.len()
                    );
                    let _ = d.to_string();
                }
                let ts = times.next_time();
                let o = bus.observe(n, &f, ts);
                let scale = o.module.as_ref().and_then(|m| m.scale());
                for (fd, v) in f.fields() {
                    s.clear();
                    fmt_value(fd, &v, scale, &mut s);
                    let _ = v.as_i64();
                }
                let _ = (f.code_str(), f.addr_char(), f.dir(), f.data());
                s.clear();
                json::ell_frame(&mut s, n, &f, &o);
                if let Err(e) = serde_json::from_str::<serde_json::Value>(&s) {
                    panic!("frame JSON does not parse: {e}\n{s}");
                }
                s.clear();
                text::ell_line(&mut s, n, &f, &o, Some(0.25));
            }
            Rec::Garbage(_, _, kind) => {
                if *kind == GarbageKind::TrailingBytes {
                    assert_eq!(i, last, "trailing bytes come last");
                }
                assert!(b.len() <= MAX_GARBAGE_RUN);
                s.clear();
                json::ell_garbage(&mut s, n, off, b);
                if let Err(e) = serde_json::from_str::<serde_json::Value>(&s) {
                    panic!("garbage JSON does not parse: {e}\n{s}");
                }
                s.clear();
                text::ell_garbage_line(&mut s, n, off, b, None);
            }
        }
    }
    assert_eq!(at, input.len() as u64, "every input byte is in a record");
    for e in bus.finish() {
        assert!(e.n >= 1 && e.n <= recs.len() as u64);
    }
}
