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
