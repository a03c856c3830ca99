//! APT framer + decoder on any bytes, pushed in chunks derived from the input.
//!
//! Input: `[max_chunk, seed, times, stream...]` (times: see `Times`). Checks: every input byte
//! is in exactly one frame or garbage record, in order, with contiguous offsets and the input's
//! own bytes; the records do not depend on the chunking; every frame keeps the framer's length
//! rules as the dissector states them (`apt::check_frame`: flagged data as the header says,
//! unflagged data recognised by its message's forms, header-only forms, open forms up to
//! `maxlen=`), and only the last is truncated; garbage runs are cut at `MAX_GARBAGE_RUN`; every
//! frame decodes, its diagnostics point inside it (or just past it for `truncated`), its JSON
//! parses; pairing and text rendering do not panic.

use crate::util::{cuts, split_ctl, Times};
use aptscope_dissector::apt::{
    check_frame, fmt_value, summary, AptFrame, AptFramer, GarbageKind, Item, HEADER_LEN,
    MAX_GARBAGE_RUN,
};
use aptscope_dissector::pair::{AptPairer, PairInfo};
use aptscope_dissector::{json, text, Table};

#[derive(Debug, Clone, PartialEq)]
enum Rec {
    Frame(u64, Vec<u8>, bool),
    Garbage(u64, Vec<u8>, GarbageKind),
}

fn run(input: &[u8], cut: &[usize]) -> Vec<Rec> {
    let mut f = AptFramer::new(Table::global());
    let mut out = vec![];
    let mut drain = |f: &mut AptFramer| {
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
        assert_eq!(f.stream_len(), c as u64);
        drain(&mut f);
        at = c;
    }
    f.finish();
    drain(&mut f);
    // After the end, nothing more comes out.
    assert!(f.next_item().is_none());
    out
}

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let (ctl, input) = split_ctl::<3>(data);
    let t = Table::global();
    let cut = cuts(input.len(), ctl[0], ctl[1]);
    let recs = run(input, &cut);
    if !cut.is_empty() {
        assert_eq!(recs, run(input, &[]), "chunking changed the records");
    }

    let mut at = 0u64;
    let mut pairer = AptPairer::new();
    let mut times = Times::new(ctl[2]);
    let mut s = String::new();
    let last = recs.len().saturating_sub(1);
    for (i, r) in recs.iter().enumerate() {
        let n = i as u64 + 1;
        match r {
            Rec::Frame(off, b, truncated) => {
                assert_eq!(*off, at, "records are contiguous");
                assert_eq!(&input[*off as usize..*off as usize + b.len()], &b[..]);
                // The framer's length rules, as the dissector states them.
                if let Err(e) = check_frame(t, b, *truncated) {
                    panic!("frame at {off} ({b:02x?}): {e}");
                }
                if *truncated {
                    assert_eq!(i, last, "only the last record can be truncated");
                }
                let f = AptFrame::decode(t, *off, b, *truncated).expect("every frame decodes");
                for d in f.diags() {
                    assert!(
                        d.offset >= *off && d.offset <= *off + b.len() as u64,
                        "diag {d:?} outside its frame at {off}+{}",
                        b.len()
                    );
                    let _ = d.to_string();
                }
                assert_eq!(f.has_diags(), f.diags().next().is_some());
                for (fd, v) in f.fields() {
                    s.clear();
                    fmt_value(t, fd, &v, &mut s);
                    let _ = v.as_f64();
                    let _ = v.elements().count();
                }
                s.clear();
                summary(&f, 6, &mut s);
                let _ = f.channel();
                // Pairing, with times that may be anywhere in the u64 range.
                let ts = times.next_time();
                let mut p = PairInfo::default();
                pairer.observe(t, n, &f, None, ts, &mut p);
                s.clear();
                json::apt_frame_paired(&mut s, n, &f, &p);
                if let Err(e) = serde_json::from_str::<serde_json::Value>(&s) {
                    panic!("frame JSON does not parse: {e}\n{s}");
                }
                s.clear();
                text::apt_line(&mut s, n, &f, Some(1.5));
                text::pair_suffix(&mut s, &p);
            }
            Rec::Garbage(off, b, kind) => {
                assert_eq!(*off, at, "records are contiguous");
                assert_eq!(&input[*off as usize..*off as usize + b.len()], &b[..]);
                assert!(!b.is_empty(), "empty garbage record");
                match kind {
                    GarbageKind::NoHeader => assert!(b.len() <= MAX_GARBAGE_RUN),
                    GarbageKind::AbsurdLength { len, .. } => {
                        assert_eq!(b.len(), HEADER_LEN);
                        assert!(*len as usize > aptscope_dissector::apt::MAX_DATA_LEN);
                    }
                    GarbageKind::TrailingBytes => {
                        assert_eq!(i, last, "trailing bytes come last");
                        assert!(b.len() < HEADER_LEN);
                    }
                }
                s.clear();
                json::apt_garbage(&mut s, n, *off, b, *kind);
                if let Err(e) = serde_json::from_str::<serde_json::Value>(&s) {
                    panic!("garbage JSON does not parse: {e}\n{s}");
                }
                s.clear();
                text::garbage_line(&mut s, n, *off, b, *kind, None);
            }
        }
        at += match r {
            Rec::Frame(_, b, _) | Rec::Garbage(_, b, _) => b.len() as u64,
        };
    }
    assert_eq!(at, input.len() as u64, "every input byte is in a record");
    for u in pairer.finish() {
        assert!(u.n >= 1 && u.n <= recs.len() as u64);
    }
}
