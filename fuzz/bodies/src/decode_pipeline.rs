//! End to end, as `aptscope decode` runs: format detection from the content, the capture reader
//! it picks, and the decoding pipeline (protocol detection, per-lane framers, decoding, pairing,
//! Elliptec bus state), rendering NDJSON and text.
//!
//! Input: `[flags, file...]`: `flags % 3` is the protocol (auto, apt, elliptec), `flags & 4`
//! forces hex-text input and `flags & 8` raw input (like `--hex`/`--format raw`). Checks: every
//! NDJSON line parses as a JSON object with a `type`; frame and garbage records are numbered
//! 1, 2, 3 … and together hold exactly the captured bytes (no byte lost or repeated); within a
//! single-lane capture their offsets are contiguous; late diagnostics refer to earlier records;
//! the text output has as many lines as the NDJSON.

use crate::util::{expansion_limit, split_ctl, strict};
use aptscope_capture::open::{sniff, ByteReader, Format};
use aptscope_capture::textlog;
use aptscope_capture::{mcap, pcap, Event, Reader};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Format as PFormat, Pipeline};
use aptscope_dissector::record::{Decoder, Record};
use aptscope_dissector::table::Dir;
use std::io::{BufReader, Cursor};

/// The reader `aptscope decode` picks for `format`, over the bytes of `file`.
pub(crate) fn reader(file: &[u8], format: Format) -> Box<dyn Reader> {
    let stream = Cursor::new(file.to_vec());
    match format {
        Format::Pcap | Format::PcapNg => Box::new(pcap::PcapReader::new(stream, None)),
        Format::Mcap => Box::new(mcap::McapReader::new(stream)),
        Format::Text(t) => textlog::open(t, BufReader::new(stream)),
        Format::Hex => Box::new(ByteReader::new(Box::new(stream), true)),
        Format::Raw => Box::new(ByteReader::new(Box::new(stream), false)),
    }
}

/// Decode `file` as `aptscope decode` reads it (the format sniffed, the reader it picks), each
/// record to `each` (its errors are failures), the decoder finished at the end. A hexdump `*`
/// can expand a few bytes into gigabytes: the capture ends once its chunks are over
/// [`expansion_limit`]. Returns the bytes captured and whether the capture was ended so.
pub(crate) fn decode_records(
    file: &[u8],
    proto: Option<Proto>,
    each: &mut impl FnMut(&Record<'_>) -> std::io::Result<()>,
) -> (u64, bool) {
    let format = sniff(&file[..file.len().min(aptscope_capture::open::SNIFF_LEN)]);
    let mut r = reader(file, format);
    let mut dec = Decoder::new(proto);
    let mut bytes = 0u64;
    let mut expanded = false;
    while let Some(ev) = r.next_event() {
        if let Event::Chunk(c) = &ev {
            bytes += c.bytes.len() as u64;
        }
        ev.feed(&mut dec, each).expect("records");
        expanded = bytes > expansion_limit(file.len()) as u64;
        if expanded {
            break;
        }
    }
    dec.finish(each).expect("records");
    (bytes, expanded)
}

/// Run the pipeline; returns the lines, the captured byte count and the lanes seen.
fn run(
    file: &[u8],
    format: Format,
    proto: Option<Proto>,
    fmt: PFormat,
) -> (Vec<String>, u64, usize) {
    let mut r = reader(file, format);
    let mut p = Pipeline::new(proto, fmt);
    let mut lines: Vec<String> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        lines.push(l.to_string());
        Ok(())
    };
    let mut bytes = 0u64;
    let mut lanes: Vec<(u32, Option<Dir>)> = vec![];
    let mut events = 0usize;
    while let Some(ev) = r.next_event() {
        events += 1;
        assert!(events <= 64 + 8 * file.len(), "endless reader");
        let mut expanded = false;
        if let Event::Chunk(c) = &ev {
            let lane = (c.stream, c.dir.dir());
            if !c.bytes.is_empty() && !lanes.contains(&lane) {
                lanes.push(lane);
            }
            bytes += c.bytes.len() as u64;
            // A hexdump `*` can expand a few bytes into gigabytes (see fuzz/artifacts-found):
            // stop feeding there, unless strict.
            expanded = bytes > expansion_limit(file.len()) as u64;
            assert!(!(expanded && strict()), "expansion beyond the limit");
        }
        ev.feed(&mut p, &mut emit).unwrap();
        if expanded {
            break;
        }
    }
    p.finish(&mut emit).unwrap();
    (lines, bytes, lanes.len())
}

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let ([flags], file) = split_ctl::<1>(data);
    let proto = match flags % 3 {
        0 => None,
        1 => Some(Proto::Apt),
        _ => Some(Proto::Elliptec),
    };
    let format = if flags & 4 != 0 {
        Format::Hex
    } else if flags & 8 != 0 {
        Format::Raw
    } else {
        sniff(&file[..file.len().min(aptscope_capture::open::SNIFF_LEN)])
    };
    let (lines, bytes, lanes) = run(file, format, proto, PFormat::Json);
    let mut n = 0u64;
    let mut held = 0u64;
    let mut next_offset = 0u64;
    for l in &lines {
        let v: serde_json::Value = serde_json::from_str(l)
            .unwrap_or_else(|e| panic!("NDJSON line does not parse: {e}\n{l}"));
        let ty = v["type"].as_str().unwrap_or_else(|| panic!("no type: {l}"));
        match ty {
            "frame" | "garbage" => {
                n += 1;
                assert_eq!(v["n"].as_u64(), Some(n), "records numbered in order: {l}");
                let len = v["len"].as_u64().expect("len");
                let raw = v["raw"].as_str().expect("raw");
                assert!(len > 0, "empty record: {l}");
                assert_eq!(raw.len() as u64, 2 * len, "raw holds len bytes: {l}");
                let off = v["offset"].as_u64().expect("offset");
                if lanes == 1 {
                    assert_eq!(off, next_offset, "records contiguous in one lane: {l}");
                    next_offset = off + len;
                }
                held += len;
            }
            "diag" => {
                let r = v["ref"].as_u64().expect("ref");
                assert!(
                    r >= 1 && r <= n,
                    "late diag refers to a record not yet seen: {l}"
                );
            }
            "detect" | "input" | "stream" => {}
            other => panic!("unknown record type {other}: {l}"),
        }
        if let Some(ds) = v["diag"].as_array() {
            for d in ds {
                assert!(
                    d["kind"].is_string() && d["offset"].is_u64(),
                    "bad diag {d} in {l}"
                );
            }
        }
    }
    assert_eq!(held, bytes, "records hold exactly the captured bytes");
    let (text, tbytes, _) = run(file, format, proto, PFormat::Text);
    assert_eq!(tbytes, bytes);
    assert_eq!(
        text.len(),
        lines.len(),
        "text and NDJSON have the same records"
    );
}
