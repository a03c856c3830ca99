//! Tests of the MCAP writer and reader.

use super::reader::{crc32_update, lengths_ok, u32le, u64le};
use super::schema::{apt_unknown_schema, garbage_schema, late_diag_schema};
use super::*;
use crate::model::{
    Direction, Event, McapProblem, OwnedChunk, ReadDiag, ReadProblem, Reader, StreamInfo, Writer,
};
use ::mcap::records::{op, MessageHeader};
use aptscope_dissector::apt::AptFramer;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::Table;
use proptest::prelude::*;
use std::collections::{BTreeMap, HashSet};
use std::io::Cursor;
use std::io::{self, Seek, Write};

/// A seekable writer into a shared buffer that fails once it holds `limit` bytes.
#[derive(Clone)]
struct Shared {
    buf: std::sync::Arc<std::sync::Mutex<Cursor<Vec<u8>>>>,
    limit: usize,
}

impl Write for Shared {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        let mut c = self.buf.lock().unwrap();
        if c.get_ref().len() + b.len() > self.limit {
            return Err(io::Error::new(io::ErrorKind::StorageFull, "disk full"));
        }
        c.write(b)
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Seek for Shared {
    fn seek(&mut self, to: io::SeekFrom) -> io::Result<u64> {
        self.buf.lock().unwrap().seek(to)
    }
}

fn shared(limit: usize) -> Shared {
    Shared {
        buf: Default::default(),
        limit,
    }
}

#[test]
fn a_write_error_of_the_writer_thread_is_returned() {
    let out = shared(50_000);
    let opts = McapOptions::new().compression(None).chunk_size(Some(4096));
    let mut w = McapWriter::with_options(out, Some(Proto::Apt), opts).unwrap();
    let chunks = some_chunks(2000);
    let mut err = None;
    for c in &chunks {
        if let Err(e) = w.chunk(&c.as_chunk()) {
            err = Some(e);
            break;
        }
    }
    let err = err.or_else(|| w.finish().err()).expect("an error");
    assert_eq!(err.kind(), io::ErrorKind::StorageFull, "{err}");
    // From then on, calls fail without a panic or a hang.
    assert!(w.chunk(&chunks[0].as_chunk()).is_err());
    let err = w.finish().unwrap_err();
    assert!(err.to_string().contains("earlier error"), "{err}");
    assert!(w.into_inner().is_none());
}

#[test]
fn dropping_without_finish_still_closes_the_file() {
    let out = shared(usize::MAX);
    let mut w = McapWriter::new(out.clone(), None).unwrap();
    for c in &some_chunks(50) {
        w.chunk(&c.as_chunk()).unwrap();
    }
    drop(w);
    let bytes = out.buf.lock().unwrap().get_ref().clone();
    assert!(bytes.ends_with(MAGIC));
    assert_eq!(read(&bytes).chunks, some_chunks(50));
}

// --- a small JSON parser, to check what we write --------------------------------------

#[derive(Debug, Clone, PartialEq)]
enum J {
    Null,
    Bool(bool),
    /// Value, and whether it was written as an integer.
    Num(f64, bool),
    Str(String),
    Arr(Vec<J>),
    Obj(Vec<(String, J)>),
}

impl J {
    fn get(&self, k: &str) -> Option<&J> {
        match self {
            J::Obj(v) => v.iter().find(|(x, _)| x == k).map(|(_, v)| v),
            _ => None,
        }
    }
    fn path(&self, p: &str) -> Option<&J> {
        p.split('.').try_fold(self, |j, k| j.get(k))
    }
    fn str(&self) -> Option<&str> {
        match self {
            J::Str(s) => Some(s),
            _ => None,
        }
    }
    fn num(&self) -> Option<f64> {
        match self {
            J::Num(x, _) => Some(*x),
            _ => None,
        }
    }
}

struct P<'a> {
    s: &'a [u8],
    i: usize,
}

impl P<'_> {
    fn ws(&mut self) {
        while self.i < self.s.len() && b" \t\r\n".contains(&self.s[self.i]) {
            self.i += 1;
        }
    }
    fn eat(&mut self, c: u8) -> Result<(), String> {
        self.ws();
        if self.s.get(self.i) == Some(&c) {
            self.i += 1;
            Ok(())
        } else {
            Err(format!("expected {:?} at {}", c as char, self.i))
        }
    }
    fn lit(&mut self, w: &str, v: J) -> Result<J, String> {
        if self.s[self.i..].starts_with(w.as_bytes()) {
            self.i += w.len();
            Ok(v)
        } else {
            Err(format!("bad literal at {}", self.i))
        }
    }
    fn string(&mut self) -> Result<String, String> {
        self.eat(b'"')?;
        let mut out = Vec::new();
        loop {
            let c = *self.s.get(self.i).ok_or("unterminated string")?;
            self.i += 1;
            match c {
                b'"' => break,
                b'\\' => {
                    let e = *self.s.get(self.i).ok_or("bad escape")?;
                    self.i += 1;
                    match e {
                        b'"' | b'\\' | b'/' => out.push(e),
                        b'n' => out.push(b'\n'),
                        b'r' => out.push(b'\r'),
                        b't' => out.push(b'\t'),
                        b'b' => out.push(8),
                        b'f' => out.push(12),
                        b'u' => {
                            let h = self.s.get(self.i..self.i + 4).ok_or("bad \\u")?;
                            let h = std::str::from_utf8(h).map_err(|e| e.to_string())?;
                            let v = u32::from_str_radix(h, 16).map_err(|e| e.to_string())?;
                            self.i += 4;
                            let ch = char::from_u32(v).unwrap_or('\u{fffd}');
                            out.extend_from_slice(ch.to_string().as_bytes());
                        }
                        _ => return Err(format!("bad escape at {}", self.i)),
                    }
                }
                c if c < 0x20 => return Err(format!("control char in string at {}", self.i)),
                c => out.push(c),
            }
        }
        String::from_utf8(out).map_err(|e| e.to_string())
    }
    fn value(&mut self) -> Result<J, String> {
        self.ws();
        match self.s.get(self.i).copied().ok_or("unexpected end")? {
            b'{' => {
                self.i += 1;
                let mut v = vec![];
                self.ws();
                if self.s.get(self.i) == Some(&b'}') {
                    self.i += 1;
                    return Ok(J::Obj(v));
                }
                loop {
                    let k = self.string()?;
                    self.eat(b':')?;
                    let x = self.value()?;
                    if v.iter().any(|(kk, _)| *kk == k) {
                        return Err(format!("duplicate key {k}"));
                    }
                    v.push((k, x));
                    self.ws();
                    match self.s.get(self.i) {
                        Some(b',') => self.i += 1,
                        Some(b'}') => {
                            self.i += 1;
                            return Ok(J::Obj(v));
                        }
                        _ => return Err(format!("expected , or }} at {}", self.i)),
                    }
                }
            }
            b'[' => {
                self.i += 1;
                let mut v = vec![];
                self.ws();
                if self.s.get(self.i) == Some(&b']') {
                    self.i += 1;
                    return Ok(J::Arr(v));
                }
                loop {
                    v.push(self.value()?);
                    self.ws();
                    match self.s.get(self.i) {
                        Some(b',') => self.i += 1,
                        Some(b']') => {
                            self.i += 1;
                            return Ok(J::Arr(v));
                        }
                        _ => return Err(format!("expected , or ] at {}", self.i)),
                    }
                }
            }
            b'"' => Ok(J::Str(self.string()?)),
            b't' => self.lit("true", J::Bool(true)),
            b'f' => self.lit("false", J::Bool(false)),
            b'n' => self.lit("null", J::Null),
            _ => {
                let st = self.i;
                while self.i < self.s.len() && b"+-0123456789.eE".contains(&self.s[self.i]) {
                    self.i += 1;
                }
                let t = std::str::from_utf8(&self.s[st..self.i]).map_err(|e| e.to_string())?;
                let x: f64 = t.parse().map_err(|_| format!("bad number {t:?} at {st}"))?;
                Ok(J::Num(x, !t.contains(['.', 'e', 'E'])))
            }
        }
    }
}

fn parse_json(s: &str) -> Result<J, String> {
    let mut p = P {
        s: s.as_bytes(),
        i: 0,
    };
    let v = p.value()?;
    p.ws();
    if p.i != s.len() {
        return Err(format!("trailing text at {}", p.i));
    }
    Ok(v)
}

/// What Foxglove's JSON Schema reader accepts (packages/mcap-support parseJsonSchema): an
/// object with `properties`, each with one `type` among boolean, string, number, integer,
/// object (recursively) and array (of those scalars or of objects).
fn foxglove_ok(s: &J, path: &str) -> Result<(), String> {
    if s.get("type").and_then(J::str) != Some("object") {
        return Err(format!("{path}: not an object schema"));
    }
    let Some(J::Obj(props)) = s.get("properties") else {
        return Err(format!("{path}: no properties"));
    };
    for (name, f) in props {
        let p = format!("{path}.{name}");
        if f.get("oneOf").is_some() || f.get("anyOf").is_some() {
            return Err(format!("{p}: oneOf/anyOf"));
        }
        match f.get("type").and_then(J::str) {
            Some("boolean" | "string" | "number" | "integer") => {}
            Some("object") => foxglove_ok(f, &p)?,
            Some("array") => {
                let items = f.get("items").ok_or(format!("{p}: no items"))?;
                match items.get("type").and_then(J::str) {
                    Some("boolean" | "string" | "number" | "integer") => {}
                    Some("object") => foxglove_ok(items, &p)?,
                    t => return Err(format!("{p}: array of {t:?}")),
                }
            }
            t => return Err(format!("{p}: type {t:?}")),
        }
    }
    Ok(())
}

/// Whether a value matches a schema (every key declared, with the declared type; `null`
/// allowed where the dissector writes it for unknown names and non-finite numbers).
fn conforms(v: &J, s: &J, path: &str) -> Result<(), String> {
    if *v == J::Null {
        return Ok(());
    }
    let ty = s.get("type").and_then(J::str).unwrap_or("?");
    let ok = match (ty, v) {
        ("object", J::Obj(kv)) => {
            for (k, x) in kv {
                let fs = s
                    .path(&format!("properties.{k}"))
                    .ok_or(format!("{path}.{k}: not in the schema"))?;
                conforms(x, fs, &format!("{path}.{k}"))?;
            }
            true
        }
        ("array", J::Arr(xs)) => {
            let items = s.get("items").ok_or("no items")?;
            for (i, x) in xs.iter().enumerate() {
                conforms(x, items, &format!("{path}[{i}]"))?;
            }
            true
        }
        ("string", J::Str(x)) => match s.get("enum") {
            Some(J::Arr(labels)) => labels.contains(&J::Str(x.clone())),
            _ => true,
        },
        ("integer", J::Num(_, int)) => *int,
        ("number", J::Num(..)) => true,
        ("boolean", J::Bool(_)) => true,
        _ => false,
    };
    if ok {
        Ok(())
    } else {
        Err(format!("{path}: {v:?} does not match type {ty}"))
    }
}

// --- helpers ----------------------------------------------------------------------------

fn uncompressed(chunk_size: Option<u64>) -> McapOptions {
    McapOptions::new().compression(None).chunk_size(chunk_size)
}

fn write(
    streams: &[StreamInfo],
    chunks: &[OwnedChunk],
    proto: Option<Proto>,
    opts: McapOptions,
) -> Vec<u8> {
    let mut w = McapWriter::with_options(Cursor::new(Vec::new()), proto, opts).unwrap();
    for s in streams {
        w.stream(s).unwrap();
    }
    for c in chunks {
        w.chunk(&c.as_chunk()).unwrap();
    }
    w.finish().unwrap();
    w.into_inner().unwrap().into_inner()
}

struct Got {
    streams: Vec<StreamInfo>,
    chunks: Vec<OwnedChunk>,
    diags: Vec<ReadDiag>,
}

fn read_events(mut r: McapReader) -> Got {
    let mut g = Got {
        streams: vec![],
        chunks: vec![],
        diags: vec![],
    };
    let mut announced = HashSet::new();
    while let Some(e) = r.next_event() {
        match e {
            Event::Stream(s) => {
                assert!(announced.insert(s.id), "stream {} announced twice", s.id);
                g.streams.push(s);
            }
            Event::Chunk(c) => {
                assert!(
                    announced.contains(&c.stream),
                    "chunk before its stream {}",
                    c.stream
                );
                g.chunks.push(c.to_owned());
            }
            Event::Diag(d) => g.diags.push(d),
        }
    }
    g
}

fn read(bytes: &[u8]) -> Got {
    read_events(McapReader::new(Cursor::new(bytes.to_vec())))
}

/// The top-level records of a file: (offset, opcode, record length including the 9-byte
/// opcode and length).
fn records(b: &[u8]) -> Vec<(usize, u8, usize)> {
    let mut out = vec![];
    let mut at = 8;
    while at + 9 <= b.len() {
        let len = u64le(&b[at + 1..at + 9]) as usize;
        out.push((at, b[at], 9 + len));
        if b[at] == op::FOOTER {
            break;
        }
        at += 9 + len;
    }
    out
}

fn stream_infos(n: usize) -> Vec<StreamInfo> {
    (0..n as u32)
        .map(|id| StreamInfo {
            id,
            name: format!("/dev/ttyUSB{id}"),
            settings: (id % 2 == 0).then(|| "115200 8N1 RTS/CTS".to_string()),
        })
        .collect()
}

fn dir_of(i: u8) -> Direction {
    [
        Direction::HostToDevice,
        Direction::DeviceToHost,
        Direction::Unknown,
    ][i as usize % 3]
}

fn some_chunks(n: usize) -> Vec<OwnedChunk> {
    (0..n)
        .map(|i| OwnedChunk {
            ts_ns: Some(1_000_000 * i as u64 + 7),
            dir: dir_of(i as u8),
            stream: (i % 2) as u32,
            bytes: (0..(5 + i % 40)).map(|k| (i * 31 + k * 7) as u8).collect(),
        })
        .collect()
}

// --- round trip -------------------------------------------------------------------------

fn chunk_strategy() -> impl Strategy<Value = (u8, u8, Option<u64>, Vec<u8>)> {
    (
        0u8..4,
        0u8..3,
        proptest::option::of(any::<u64>()),
        proptest::collection::vec(any::<u8>(), 0..80),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn round_trip_is_lossless(
        n_streams in 1usize..4,
        spec in proptest::collection::vec(chunk_strategy(), 0..60),
        mode in 0u8..4,
    ) {
        let streams = stream_infos(n_streams);
        let chunks: Vec<OwnedChunk> = spec
            .into_iter()
            .map(|(s, d, ts, bytes)| OwnedChunk {
                ts_ns: ts,
                dir: dir_of(d),
                stream: s as u32 % n_streams as u32,
                bytes,
            })
            .collect();
        let opts = match mode {
            0 => McapOptions::new(),
            1 => uncompressed(Some(200)),
            2 => uncompressed(None).use_chunks(false),
            _ => McapOptions::new()
                .compression(Some(mcap::Compression::Lz4))
                .chunk_size(Some(300)),
        };
        let bytes = write(&streams, &chunks, None, opts);
        let got = read(&bytes);
        prop_assert!(got.diags.is_empty(), "{:?}", got.diags);
        prop_assert_eq!(&got.streams, &streams);
        prop_assert_eq!(&got.chunks, &chunks);
        // The file is valid for the reference reader too.
        let n = mcap::MessageStream::new(&bytes).unwrap().count();
        prop_assert!(n >= chunks.len());
        // And read with its length known.
        let got = read_events(
            McapReader::new(Cursor::new(bytes.clone())).with_file_len(bytes.len() as u64),
        );
        prop_assert!(got.diags.is_empty(), "{:?}", got.diags);
        prop_assert_eq!(&got.chunks, &chunks);
    }

    /// Any cut of the file: a prefix of the chunks, a diagnostic, no panic.
    #[test]
    fn any_cut_gives_a_prefix_and_a_diag(frac in 0.0f64..1.0) {
        let chunks = some_chunks(40);
        let bytes = write(&stream_infos(2), &chunks, None, uncompressed(Some(256)));
        let at = (bytes.len() as f64 * frac) as usize;
        let got = read(&bytes[..at]);
        prop_assert!(got.chunks.len() <= chunks.len());
        prop_assert_eq!(&chunks[..got.chunks.len()], &got.chunks[..]);
        prop_assert!(!got.diags.is_empty());
        prop_assert!(got.diags.iter().all(|d| d.offset <= at as u64), "{:?}", got.diags);
        // With the length known, lengths past the end are caught up front and the
        // records inside a cut chunk are looked for: still a prefix.
        let known = read_events(
            McapReader::new(Cursor::new(bytes[..at].to_vec())).with_file_len(at as u64),
        );
        prop_assert!(known.chunks.len() >= got.chunks.len());
        prop_assert_eq!(&chunks[..known.chunks.len()], &known.chunks[..]);
        prop_assert!(!known.diags.is_empty());
    }

    /// Garbage anywhere never panics, and never invents a stream without a chunk or
    /// metadata behind it.
    #[test]
    fn garbage_never_panics(junk in proptest::collection::vec(any::<u8>(), 0..400), magic in any::<bool>()) {
        let mut b = if magic { MAGIC.to_vec() } else { vec![] };
        b.extend_from_slice(&junk);
        let got = read(&b);
        prop_assert!(!got.diags.is_empty());
        let got = read_events(McapReader::new(Cursor::new(b.clone())).with_file_len(b.len() as u64));
        prop_assert!(!got.diags.is_empty());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Damage anywhere in real files (flipped bytes, a cut): no panic, a diagnostic when
    /// the file is not intact, and the chunks before the first damaged MCAP chunk.
    #[test]
    fn damaged_files_never_panic(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 1..6),
        cut in proptest::option::of(any::<prop::sample::Index>()),
        compressed in any::<bool>(),
        known_len in any::<bool>(),
    ) {
        let chunks = some_chunks(30);
        let opts = if compressed {
            McapOptions::new().chunk_size(Some(400))
        } else {
            uncompressed(Some(400))
        };
        let mut bytes = write(&stream_infos(2), &chunks, None, opts);
        for (i, x) in &flips {
            let at = i.index(bytes.len());
            bytes[at] ^= x;
        }
        if let Some(c) = cut {
            bytes.truncate(c.index(bytes.len()));
        }
        let mut r = McapReader::new(Cursor::new(bytes.clone()));
        if known_len {
            r = r.with_file_len(bytes.len() as u64);
        }
        let got = read_events(r);
        prop_assert!(!got.diags.is_empty() || got.chunks == chunks);
        prop_assert!(got.diags.iter().all(|d| d.offset <= bytes.len() as u64));
    }
}

#[test]
fn crc32_is_ieee() {
    assert_eq!(!crc32_update(!0, b"123456789"), 0xCBF4_3926);
}

#[test]
fn damage_only_the_data_crc_sees_is_reported() {
    let mut bytes = write(&stream_infos(2), &some_chunks(10), None, McapOptions::new());
    // A stream's name, in an `aptscope.stream` metadata record.
    let at = bytes
        .windows(12)
        .position(|w| w == b"/dev/ttyUSB1")
        .unwrap();
    bytes[at + 5] = b'X';
    let got = read(&bytes);
    assert_eq!(got.streams[1].name, "/dev/XtyUSB1");
    assert_eq!(got.diags.len(), 1, "{:?}", got.diags);
    assert_eq!(got.diags[0].kind(), "bad_data_crc");
    let data_end = records(&bytes)
        .into_iter()
        .find(|r| r.1 == op::DATA_END)
        .unwrap();
    assert_eq!(got.diags[0].offset, data_end.0 as u64);
}

#[test]
fn sniffs_the_magic() {
    assert!(sniff(b"\x89MCAP0\r\n\x01\x02"));
    assert!(!sniff(b"\x89MCAP0\r"));
    assert!(!sniff(b"\xd4\xc3\xb2\xa1"));
}

#[test]
fn empty_capture() {
    let bytes = write(&[], &[], None, McapOptions::new());
    let got = read(&bytes);
    assert!(got.diags.is_empty(), "{:?}", got.diags);
    assert!(got.chunks.is_empty() && got.streams.is_empty());
}

/// The summary and the indexes (which the linear readers above never use) lead to every
/// message, with every compression, several compression threads and many small chunks: what
/// Foxglove's random access and `mcap info` read.
#[test]
fn summary_and_indexes_lead_to_every_message() {
    type Msg = (u16, u32, u64, Vec<u8>);
    let chunks = some_chunks(400);
    for compression in [
        Some(mcap::Compression::Zstd),
        Some(mcap::Compression::Lz4),
        None,
    ] {
        let opts = McapOptions::new()
            .compression(compression)
            .chunk_size(Some(3000))
            .compression_threads(3);
        let bytes = write(&stream_infos(2), &chunks, None, opts);
        let linear: Vec<Msg> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| {
                let m = m.unwrap();
                assert_eq!(m.log_time, m.publish_time);
                (m.channel.id, m.sequence, m.log_time, m.data.to_vec())
            })
            .collect();
        let sum = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let stats = sum.stats.as_ref().expect("statistics");
        assert_eq!(stats.message_count, linear.len() as u64);
        assert_eq!(
            stats.channel_message_counts.values().sum::<u64>(),
            linear.len() as u64
        );
        assert_eq!(stats.channel_count as usize, sum.channels.len());
        assert_eq!(stats.schema_count as usize, sum.schemas.len());
        assert_eq!(stats.chunk_count as usize, sum.chunk_indexes.len());
        assert!(sum.chunk_indexes.len() > 20, "{}", sum.chunk_indexes.len());
        assert_eq!(
            (stats.message_start_time, stats.message_end_time),
            (
                linear.iter().map(|m| m.2).min().unwrap(),
                linear.iter().map(|m| m.2).max().unwrap()
            )
        );
        let mut indexed: Vec<Msg> = vec![];
        for ci in &sum.chunk_indexes {
            let mut in_chunk = vec![];
            for m in sum.stream_chunk(&bytes, ci).unwrap() {
                let m = m.unwrap();
                assert!((ci.message_start_time..=ci.message_end_time).contains(&m.log_time));
                in_chunk.push((m.channel.id, m.sequence, m.log_time, m.data.to_vec()));
            }
            if ci.message_index_offsets.is_empty() {
                // A chunk of schema and channel records only.
                assert!(in_chunk.is_empty());
                continue;
            }
            let mut by_index = vec![];
            for (ch, entries) in sum.read_message_indexes(&bytes, ci).unwrap() {
                for e in entries {
                    let m = sum.seek_message(&bytes, ci, &e).unwrap();
                    assert_eq!((m.channel.id, m.log_time), (ch.id, e.log_time));
                    by_index.push((m.channel.id, m.sequence, m.log_time, m.data.to_vec()));
                }
            }
            by_index.sort();
            let mut sorted = in_chunk.clone();
            sorted.sort();
            assert_eq!(by_index, sorted);
            indexed.extend(in_chunk);
        }
        assert_eq!(indexed, linear);
        let names: Vec<String> = sum
            .metadata_indexes
            .iter()
            .map(|i| mcap::read::metadata(&bytes, i).unwrap().name)
            .collect();
        assert_eq!(
            names,
            [
                "aptscope",
                "aptscope.stream",
                "aptscope.stream",
                "aptscope.decode"
            ]
        );
        // The footer's CRC covers the summary section and the footer up to the CRC.
        let footer = mcap::read::footer(&bytes).unwrap();
        let end = bytes.len() - MAGIC.len() - 4;
        assert_eq!(
            footer.summary_crc,
            !crc32_update(!0, &bytes[footer.summary_start as usize..end])
        );
    }
}

// --- decoded channels -------------------------------------------------------------------

fn sample(name: &str) -> Vec<u8> {
    std::fs::read(format!("{}/../samples/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

/// Per decoded topic: schema name, schema (parsed) and messages (log time, parsed JSON).
type Decoded = BTreeMap<String, (String, J, Vec<(u64, J)>)>;

fn decoded(bytes: &[u8]) -> Decoded {
    let mut out: Decoded = BTreeMap::new();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        let t = &m.channel.topic;
        if !(t.starts_with("/apt/") || t.starts_with("/ell/") || t.starts_with("/aptscope/")) {
            continue;
        }
        assert_eq!(m.channel.message_encoding, "json", "{t}");
        let s = m
            .channel
            .schema
            .as_ref()
            .expect("decoded channels have a schema");
        assert_eq!(s.encoding, "jsonschema", "{t}");
        let text = std::str::from_utf8(&m.data).unwrap();
        let v = parse_json(text).unwrap_or_else(|e| panic!("{t}: {e}: {text}"));
        let e = out.entry(t.clone()).or_insert_with(|| {
            let st = std::str::from_utf8(&s.data).unwrap();
            let sj = parse_json(st).unwrap_or_else(|e| panic!("schema of {t}: {e}: {st}"));
            foxglove_ok(&sj, t).unwrap();
            (s.name.clone(), sj, vec![])
        });
        conforms(&v, &e.1, t).unwrap_or_else(|err| panic!("{err}\n{text}"));
        e.2.push((m.log_time, v));
    }
    out
}

/// The KDC101 sample, one chunk per frame, host frames on the h2d lane.
fn kdc101() -> Vec<OwnedChunk> {
    let b = sample("kdc101-session.bin");
    let mut f = AptFramer::new(Table::global());
    f.push(&b);
    f.finish();
    let mut out = vec![];
    while let Some(it) = f.next_item() {
        let bytes = it.bytes().to_vec();
        let dir = if bytes.get(5) == Some(&0x01) {
            Direction::HostToDevice
        } else {
            Direction::DeviceToHost
        };
        out.push(OwnedChunk {
            ts_ns: Some(1_700_000_000_000_000_000 + 1_000_000 * out.len() as u64),
            dir,
            stream: 0,
            bytes,
        });
    }
    out
}

#[test]
fn kdc101_session_has_decoded_channels_with_schemas() {
    let chunks = kdc101();
    assert_eq!(chunks.len(), 20);
    let bytes = write(&stream_infos(1), &chunks, None, McapOptions::new());
    let dec = decoded(&bytes);
    let (name, schema, msgs) = &dec["/apt/MOT_GET_DCSTATUSUPDATE"];
    assert_eq!(name, "aptscope.apt.MOT_GET_DCSTATUSUPDATE");
    assert_eq!(
        schema
            .path("properties.fields.properties.position.type")
            .and_then(J::str),
        Some("integer")
    );
    assert_eq!(
        schema
            .path("properties.fields.properties.status_bits.items.type")
            .and_then(J::str),
        Some("string")
    );
    assert_eq!(msgs.len(), 9);
    // The second status update: position -1200, at the time of its chunk (the 9th).
    let (t, v) = &msgs[1];
    assert_eq!(v.path("fields.position").and_then(J::num), Some(-1200.0));
    assert_eq!(v.path("dir").and_then(J::str), Some("d2h"));
    assert_eq!(v.path("msg_dir").and_then(J::str), Some("d2h"));
    assert_eq!(
        v.path("ts_ns").and_then(J::num),
        Some(chunks[8].ts_ns.unwrap() as f64)
    );
    assert_eq!(v.path("channel").and_then(J::num), Some(1.0));
    assert_eq!(*t, chunks[8].ts_ns.unwrap());
    // Host commands are decoded on their own lane.
    let (_, _, moves) = &dec["/apt/MOT_MOVE_ABSOLUTE"];
    assert_eq!(moves.len(), 1);
    assert_eq!(
        moves[0].1.path("fields.absolute_position").and_then(J::num),
        Some(171520.0)
    );
    assert_eq!(moves[0].1.path("dir").and_then(J::str), Some("h2d"));
    for topic in [
        "/apt/HW_GET_INFO",
        "/apt/MOT_MOVE_COMPLETED",
        "/apt/HW_REQ_INFO",
    ] {
        assert!(dec.contains_key(topic), "{topic}: {:?}", dec.keys());
    }
    assert!(!dec.contains_key("/apt/garbage"));
    // The decode verdict and the lossless statement are in the metadata.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let names: Vec<&str> = summary
        .metadata_indexes
        .iter()
        .map(|m| m.name.as_str())
        .collect();
    assert!(names.contains(&"aptscope") && names.contains(&"aptscope.decode"));
    assert!(!names.contains(&"aptscope.times"));
    let meta = mcap::read::metadata(
        &bytes,
        summary
            .metadata_indexes
            .iter()
            .find(|m| m.name == "aptscope")
            .unwrap(),
    )
    .unwrap();
    assert_eq!(meta.metadata["lossless"], "bytes, times, direction");
    assert_eq!(meta.metadata["version"], env!("CARGO_PKG_VERSION"));
    // And the raw channels still read back exactly.
    let got = read(&bytes);
    assert!(got.diags.is_empty());
    assert_eq!(got.chunks, chunks);
}

#[test]
fn every_message_schema_is_foxglove_readable() {
    let t = Table::global();
    for m in t.msgs() {
        let s = parse_json(&apt_schema(t, m)).unwrap_or_else(|e| panic!("{}: {e}", m.name));
        foxglove_ok(&s, m.name).unwrap();
    }
    for c in aptscope_dissector::ell::table::COMMANDS {
        let s = parse_json(&ell_schema(Some(c))).unwrap();
        foxglove_ok(&s, c.code).unwrap();
    }
    for s in [
        ell_schema(None),
        apt_unknown_schema(),
        garbage_schema("apt"),
        garbage_schema("ell"),
        late_diag_schema(Proto::Apt),
        late_diag_schema(Proto::Elliptec),
    ] {
        foxglove_ok(&parse_json(&s).unwrap(), "x").unwrap();
    }
}

#[test]
fn elliptec_bus_decodes_on_ell_channels() {
    let b = sample("elliptec-bus.txt");
    let chunks: Vec<OwnedChunk> = b
        .split_inclusive(|&c| c == b'\n')
        .enumerate()
        .map(|(i, l)| OwnedChunk {
            ts_ns: Some(10_000_000 * i as u64),
            dir: Direction::Unknown,
            stream: 0,
            bytes: l.to_vec(),
        })
        .collect();
    let bytes = write(&stream_infos(1), &chunks, None, McapOptions::new());
    let dec = decoded(&bytes);
    let (_, schema, po) = &dec["/ell/PO"];
    assert_eq!(
        schema
            .path("properties.fields.properties.position.type")
            .and_then(J::str),
        Some("integer")
    );
    assert!(!po.is_empty());
    assert!(dec.contains_key("/ell/ma") && dec.contains_key("/ell/IN"));
    let got = read(&bytes);
    assert_eq!(got.chunks, chunks);
}

#[test]
fn damaged_sample_gives_garbage_and_unknown_channels() {
    let b = sample("damaged.bin");
    let chunks = vec![OwnedChunk {
        ts_ns: None,
        dir: Direction::Unknown,
        stream: 0,
        bytes: b,
    }];
    let bytes = write(
        &stream_infos(1),
        &chunks,
        Some(Proto::Apt),
        McapOptions::new(),
    );
    let dec = decoded(&bytes);
    assert!(dec.contains_key("/apt/garbage"), "{:?}", dec.keys());
    assert!(dec.contains_key("/apt/unknown"), "{:?}", dec.keys());
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(summary
        .metadata_indexes
        .iter()
        .any(|m| m.name == "aptscope.times"));
    let got = read(&bytes);
    assert_eq!(got.chunks, chunks);
    assert_eq!(got.chunks[0].ts_ns, None);
}

// --- damage -----------------------------------------------------------------------------

#[test]
fn truncated_file_gives_messages_before_and_a_diag() {
    let chunks = some_chunks(60);
    let bytes = write(&stream_infos(2), &chunks, None, uncompressed(Some(256)));
    let recs = records(&bytes);
    let chunk_recs: Vec<_> = recs.iter().filter(|r| r.1 == op::CHUNK).collect();
    // Cut in the middle of a chunk that has raw messages before it (the first chunks hold
    // the decoded stream records).
    let k = (3..chunk_recs.len())
        .find(|&k| !read(&bytes[..chunk_recs[k].0]).chunks.is_empty())
        .expect("a chunk after raw messages");
    assert!(chunk_recs.len() > k + 1);
    let (at, _, len) = *chunk_recs[k];
    let cut = at + len / 2;
    for known_len in [false, true] {
        let mut r = McapReader::new(Cursor::new(bytes[..cut].to_vec()));
        if known_len {
            r = r.with_file_len(cut as u64);
        }
        let got = read_events(r);
        let d = got
            .diags
            .iter()
            .find(|d| d.kind() == "truncated_record")
            .unwrap_or_else(|| panic!("{:?}", got.diags));
        assert_eq!(d.offset, at as u64, "{:?}", got.diags);
        // Every chunk of the MCAP chunks before came out, and then some.
        let before = read(&bytes[..at]).chunks.len();
        assert!(before > 0);
        assert!(got.chunks.len() > before, "{} {}", got.chunks.len(), before);
        assert_eq!(&got.chunks[..], &chunks[..got.chunks.len()]);
    }
    // Cut at a record boundary: everything before, and the missing footer is reported.
    let got = read(&bytes[..at]);
    let d = got.diags.last().unwrap();
    assert_eq!((d.kind(), d.offset), ("missing_footer", at as u64));
    assert_eq!(&got.chunks[..], &chunks[..got.chunks.len()]);
}

#[test]
fn bad_chunk_crc_is_reported_and_reading_goes_on() {
    let chunks = some_chunks(60);
    let mut bytes = write(&stream_infos(2), &chunks, None, uncompressed(Some(256)));
    let chunk_recs: Vec<_> = records(&bytes)
        .into_iter()
        .filter(|r| r.1 == op::CHUNK)
        .collect();
    let (at, _, _) = chunk_recs[2];
    // Flip the last data byte of the chunk's last message record (uncompressed chunk).
    let body = at + 9;
    let clen = u32le(&bytes[body + 28..]) as usize;
    let csize = u64le(&bytes[body + 32 + clen..]) as usize;
    let (mut r, end) = (body + 40 + clen, body + 40 + clen + csize);
    let mut last = None;
    while r < end {
        let len = u64le(&bytes[r + 1..]) as usize;
        if bytes[r] == op::MESSAGE && len > 22 {
            last = Some(r + 9 + len - 1);
        }
        r += 9 + len;
    }
    bytes[last.unwrap()] ^= 0xFF;
    let got = read(&bytes);
    assert_eq!(got.diags.len(), 1, "{:?}", got.diags);
    assert_eq!(got.diags[0].kind(), "bad_chunk_crc");
    assert!(
        matches!(
            got.diags[0].problem,
            ReadProblem::Mcap(McapProblem::BadChunkCrc { .. })
        ),
        "{:?}",
        got.diags[0]
    );
    assert_eq!(got.diags[0].offset, at as u64);
    // Every raw chunk is still produced (the damaged byte is in a decoded message here or
    // in raw data; either way the count and the chunks of other MCAP chunks are intact).
    assert_eq!(got.chunks.len(), chunks.len());
    let ok = got
        .chunks
        .iter()
        .zip(&chunks)
        .filter(|(a, b)| a == b)
        .count();
    assert!(ok >= chunks.len() - 1);
}

#[test]
fn garbage_between_records_is_skipped() {
    let chunks = some_chunks(60);
    let bytes = write(&stream_infos(2), &chunks, None, uncompressed(Some(256)));
    let chunk_recs: Vec<_> = records(&bytes)
        .into_iter()
        .filter(|r| r.1 == op::CHUNK)
        .collect();
    let (at, _, _) = chunk_recs[3];
    let mut damaged = bytes[..at].to_vec();
    damaged.extend((0..100u32).map(|i| (i * 37 + 11) as u8 | 0x40));
    damaged.extend_from_slice(&bytes[at..]);
    let got = read(&damaged);
    assert_eq!(got.chunks, chunks, "{:?}", got.diags);
    assert_eq!(got.diags.len(), 2, "{:?}", got.diags);
    assert_eq!(got.diags[0].kind(), "bad_record");
    assert_eq!(got.diags[0].offset, at as u64);
    assert_eq!(got.diags[1].kind(), "skipped_bytes");
    assert!(
        got.diags[1].msg().starts_with("100 byte(s)"),
        "{:?}",
        got.diags
    );
}

#[test]
fn a_chunk_with_a_wild_length_is_resynchronised() {
    let chunks = some_chunks(60);
    let bytes = write(&stream_infos(2), &chunks, None, uncompressed(Some(256)));
    let chunk_recs: Vec<_> = records(&bytes)
        .into_iter()
        .filter(|r| r.1 == op::CHUNK)
        .collect();
    let (at, _, _) = chunk_recs[3];
    let mut damaged = bytes.clone();
    damaged[at + 8] = 0x7F; // length now ~ 2^62
    let got = read_events(
        McapReader::new(Cursor::new(damaged.clone())).with_file_len(damaged.len() as u64),
    );
    assert!(got.diags.iter().any(|d| d.offset == at as u64));
    // Records inside the damaged chunk and all later chunks are found again.
    assert_eq!(got.chunks, chunks, "{:?}", got.diags);
    // Without the file length, the chunk's own header still bounds it.
    let got = read(&damaged);
    assert!(
        got.diags.iter().any(|d| d.offset == at as u64),
        "{:?}",
        got.diags
    );
    assert_eq!(&got.chunks[..], &chunks[..got.chunks.len()]);
}

#[test]
fn bad_magic_is_reported_and_records_still_read() {
    let chunks = some_chunks(10);
    let mut bytes = write(&stream_infos(2), &chunks, None, McapOptions::new());
    bytes[1] = b'X';
    let got = read(&bytes);
    assert_eq!(got.diags[0].kind(), "bad_magic");
    assert_eq!(got.diags[0].offset, 0);
    assert_eq!(got.chunks, chunks, "{:?}", got.diags);
    let got = read(b"hello world, this is not mcap at all");
    assert_eq!(got.diags[0].kind(), "bad_magic");
    assert!(got.chunks.is_empty());
}

#[test]
fn foreign_raw_channels_are_read_with_directions() {
    let mut w = mcap::Writer::new(Cursor::new(Vec::new())).unwrap();
    let none = BTreeMap::new();
    let tx = w.add_channel(0, "/uart0/tx", "", &none).unwrap();
    let rx = w.add_channel(0, "/uart0/rx", "", &none).unwrap();
    let other = w
        .add_channel(0, "/bridge/serial_out", "application/octet-stream", &none)
        .unwrap();
    let sid = w.add_schema("Pose", "protobuf", b"x").unwrap();
    let pb = w.add_channel(sid, "/pose", "protobuf", &none).unwrap();
    for (i, ch) in [tx, rx, pb, other, tx].into_iter().enumerate() {
        w.write_to_known_channel(
            &MessageHeader {
                channel_id: ch,
                sequence: i as u32,
                log_time: 100 + i as u64,
                publish_time: 0,
            },
            &[i as u8; 3],
        )
        .unwrap();
    }
    w.finish().unwrap();
    let bytes = w.into_inner().into_inner();
    let got = read(&bytes);
    assert!(got.diags.is_empty(), "{:?}", got.diags);
    let names: Vec<&str> = got.streams.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["/uart0", "/bridge/serial"]);
    let dirs: Vec<(u32, Direction, Option<u64>)> = got
        .chunks
        .iter()
        .map(|c| (c.stream, c.dir, c.ts_ns))
        .collect();
    assert_eq!(
        dirs,
        [
            (0, Direction::HostToDevice, Some(100)),
            (0, Direction::DeviceToHost, Some(101)),
            (1, Direction::HostToDevice, Some(103)),
            (0, Direction::HostToDevice, Some(104)),
        ]
    );
}

#[test]
fn lying_string_lengths_are_caught_before_parsing() {
    // A channel record whose topic claims 4 GB: a diagnostic, not a 4 GB allocation.
    let mut b = MAGIC.to_vec();
    let mut body = vec![1, 0, 0, 0];
    body.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    body.extend_from_slice(b"/x");
    b.push(op::CHANNEL);
    b.extend_from_slice(&(body.len() as u64).to_le_bytes());
    b.extend_from_slice(&body);
    let got = read(&b);
    assert_eq!(got.diags[0].kind(), "bad_record", "{:?}", got.diags);
    assert_eq!(got.diags[0].offset, 8);
    assert_eq!(got.diags[1].kind(), "missing_footer");
    assert!(!lengths_ok(op::METADATA, &[5, 0, 0, 0, b'a']));
    assert!(lengths_ok(op::METADATA, &[1, 0, 0, 0, b'a', 0, 0, 0, 0]));
}

#[test]
fn streams_without_chunks_and_untimed_chunks_survive() {
    let streams = stream_infos(3);
    let chunks = vec![
        OwnedChunk {
            ts_ns: None,
            dir: Direction::HostToDevice,
            stream: 2,
            bytes: b"abc".to_vec(),
        },
        OwnedChunk {
            ts_ns: Some(0),
            dir: Direction::HostToDevice,
            stream: 2,
            bytes: b"def".to_vec(),
        },
    ];
    let bytes = write(&streams, &chunks, None, McapOptions::new());
    let got = read(&bytes);
    assert_eq!(got.streams, streams);
    assert_eq!(got.chunks, chunks);
}

/// Every sample, written as MCAP: each decoded message conforms to its channel's schema (every
/// key declared, with its type) and every schema is one Foxglove reads.
#[test]
fn every_sample_conforms_to_its_channels_schemas() {
    use crate::open::{open, OpenOptions};
    let root = format!("{}/../samples", env!("CARGO_MANIFEST_DIR"));
    let mut paths = vec![];
    for dir in [root.clone(), format!("{root}/sessions")] {
        for e in std::fs::read_dir(&dir).unwrap().flatten() {
            let p = e.path();
            let ext = p.extension().and_then(|x| x.to_str()).unwrap_or("");
            if p.is_file() && !matches!(ext, "sh" | "py" | "md") {
                paths.push(p);
            }
        }
    }
    paths.sort();
    let mut msgs = 0;
    for p in &paths {
        let name = p.display().to_string();
        let (mut r, _) = open(&name, OpenOptions::default()).unwrap();
        let mut w = McapWriter::new(Cursor::new(Vec::new()), None).unwrap();
        while let Some(ev) = r.next_event() {
            match ev {
                Event::Stream(s) => w.stream(&s).unwrap(),
                Event::Chunk(c) => w.chunk(&c).unwrap(),
                Event::Diag(d) => w.file_diag(d.offset, d.kind(), &d.msg()).unwrap(),
            }
        }
        w.finish().unwrap();
        let bytes = w.into_inner().unwrap().into_inner();
        let dec = decoded(&bytes);
        assert!(!dec.is_empty(), "{name}");
        msgs += dec.values().map(|d| d.2.len()).sum::<usize>();
    }
    assert!(paths.len() >= 30, "{} samples", paths.len());
    assert!(msgs > 1000, "{msgs} messages");
}
