//! MCAP reading and writing.
//!
//! **Writing** ([`McapWriter`]) keeps the capture lossless and adds what the dissector makes of
//! it, so Foxglove can plot decoded fields without a plugin:
//!
//! - raw channels, one per (stream, direction): topic `/serial/<stream>/<h2d|d2h|unknown>`,
//!   message encoding `application/octet-stream`, no schema; each message is one chunk's bytes,
//!   `log_time` = `publish_time` = its capture time in ns, `sequence` = the chunk's number.
//!   Chunks without a capture time go to a channel of the same topic whose metadata says
//!   `time: missing` (their `log_time` is 0), so a reader restores "no time" exactly;
//! - decoded channels, one per message type: `/apt/<NAME>` (`/apt/unknown`, `/apt/garbage`)
//!   or `/ell/<cmd>` (`/ell/unknown`, `/ell/garbage`, `/ell/diag`), message encoding `json`
//!   (the object `aptscope decode --json` writes for the record, capture context `dir`,
//!   `ts_ns`, `stream` included), schema encoding `jsonschema` generated from the message
//!   table; `log_time` is the time of the chunk that completed the frame. Plot
//!   `/apt/MOT_GET_DCSTATUSUPDATE.fields.position` in Foxglove, for example;
//! - metadata records: `aptscope` (version, what is lossless), `aptscope.stream` (one per
//!   declared stream, in order), `aptscope.decode` (protocol and how it was chosen) and
//!   `aptscope.times` (when some chunks have no capture time).
//!
//! **Reading** ([`McapReader`]) streams the file record by record with bounded buffers (chunks
//! are decompressed incrementally through the `mcap` crate's sans-io [`LinearReader`]), so
//! multi-GB files read in constant memory. It produces the raw channels of our files and any
//! other channel that is not a structured encoding (json, protobuf, ros1, cdr …); decoded
//! channels are skipped. Damage (bad magic, a truncated record, a chunk with a bad CRC, garbage
//! between records, a missing footer, a data section whose CRC does not match) gives a
//! diagnostic with its file offset; records before and, after resynchronisation, after the
//! damage are still read. A chunk's CRC is known only once the chunk has been read through, so
//! the messages of a chunk with a bad CRC come out before the diagnostic that flags them.
//!
//! [`LinearReader`]: mcap::sans_io::LinearReader

use crate::model::{Chunk, Direction, Event, ReadDiag, Reader, StreamInfo, Writer};
use aptscope_dissector::apt::{AptFrame, AptFramer, Item as AptItem};
use aptscope_dissector::detect::{detect, Proto, SAMPLE};
use aptscope_dissector::ell::table::{Cmd, Kind};
use aptscope_dissector::ell::{Bus, EllFrame, EllFramer, Expired, Item as EllItem};
use aptscope_dissector::table::{Dir, Field, FormKind, MsgDef, Prim, Ty};
use aptscope_dissector::{json, Diag, DiagKind, Table};
use mcap::records::{op, MessageHeader, Metadata};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::{McapError, WriteOptions};
use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::fmt::Write as _;
use std::hash::BuildHasherDefault;
use std::io::{self, Read, Seek, Write};

/// The MCAP magic, at the start and the end of every file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Whether `head` (the first bytes of a file) is MCAP.
pub fn sniff(head: &[u8]) -> bool {
    head.starts_with(MAGIC)
}

/// Message encoding of the raw channels.
pub const RAW_ENCODING: &str = "application/octet-stream";

fn mcap_err(e: McapError) -> io::Error {
    match e {
        McapError::Io(e) => e,
        e => io::Error::other(e.to_string()),
    }
}

fn finished_err() -> io::Error {
    io::Error::other("MCAP writer already finished")
}

fn failed_err() -> io::Error {
    io::Error::other("MCAP writer stopped after an earlier error")
}

// ---------------------------------------------------------------------------------------------
// Writer
// ---------------------------------------------------------------------------------------------

/// Buffer chunks for protocol detection until the first lane has a sample, or this much in all.
const DETECT_HOLD: usize = 64 * 1024;
/// … or this many chunks (empty ones add no bytes).
const DETECT_HOLD_CHUNKS: usize = 4096;

/// An MCAP capture writer: raw lossless channels plus decoded JSON channels (see the module
/// documentation for the layout).
///
/// The calling thread frames, decodes and renders the records; a writer thread owns the
/// [`mcap::Writer`] and does the MCAP encoding and the zstd compression (about 70 % of the
/// instructions), so the two overlap when a second core is free. The writer thread makes exactly the calls a single-threaded
/// writer would, in the same order, so the file is the same. An I/O error of the writer thread
/// is returned by a later [`chunk`](Writer::chunk) or by [`finish`](Writer::finish) (as with a
/// `BufWriter`); dropping the writer without `finish` still closes the file as
/// [`mcap::Writer`] does.
pub struct McapWriter<W: Write + Seek + Send + 'static> {
    sink: Option<Sink>,
    thread: Option<std::thread::JoinHandle<io::Result<W>>>,
    /// An error stopped the writer thread (and was returned).
    failed: bool,
    inner: Option<W>,
    raw: HashMap<(u32, Direction, bool), u16, FastHash>,
    streams: BTreeMap<u32, StreamInfo>,
    seq: u32,
    chunks: u64,
    untimed: u64,
    dec: Decoder,
}

impl<W: Write + Seek + Send + 'static> McapWriter<W> {
    /// A writer with zstd-compressed chunks. `proto` chooses the decoder of the decoded
    /// channels; `None` detects it from the first 4 KiB of the first lane with data.
    ///
    /// zstd runs single-threaded: a chunk (1 MiB) is smaller than one job of zstd's
    /// multi-threaded mode, so its worker threads never overlapped with anything and only
    /// added a copy and locking per write; the writer thread is what runs in parallel now.
    pub fn new(w: W, proto: Option<Proto>) -> io::Result<Self> {
        Self::with_options(
            w,
            proto,
            WriteOptions::new().compression_threads(0).library(format!(
                "aptscope {}; {}",
                env!("CARGO_PKG_VERSION"),
                mcap::LIBRARY_IDENTIFIER
            )),
        )
    }

    /// A writer with the given MCAP options (compression, chunk size, …).
    pub fn with_options(w: W, proto: Option<Proto>, opts: WriteOptions) -> io::Result<Self> {
        let mut mw = opts.create(w).map_err(mcap_err)?;
        let meta: BTreeMap<String, String> = [
            ("version", env!("CARGO_PKG_VERSION")),
            ("lossless", "bytes, times, direction"),
            ("raw_topics", "/serial/<stream>/<h2d|d2h|unknown>"),
            (
                "decoded_topics",
                "/apt/<NAME>, /ell/<cmd> (json, jsonschema)",
            ),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
        mw.write_metadata(&Metadata {
            name: "aptscope".into(),
            metadata: meta,
        })
        .map_err(mcap_err)?;
        let (sink, thread) = Sink::start(mw)?;
        Ok(McapWriter {
            sink: Some(sink),
            thread: Some(thread),
            failed: false,
            inner: None,
            raw: HashMap::default(),
            streams: BTreeMap::new(),
            seq: 0,
            chunks: 0,
            untimed: 0,
            dec: Decoder::new(proto),
        })
    }

    /// The underlying writer, once [`finish`](Writer::finish) has run.
    pub fn into_inner(mut self) -> Option<W> {
        self.inner.take()
    }

    /// Why there is no sink.
    fn no_sink(&self) -> io::Error {
        if self.failed {
            failed_err()
        } else {
            finished_err()
        }
    }

    /// Run `f` on the sink; when it fails because the writer thread stopped, return the
    /// thread's error instead (and have no sink from then on).
    fn with_sink<T>(
        &mut self,
        f: impl FnOnce(&mut Sink, &mut Decoder) -> io::Result<T>,
    ) -> io::Result<T> {
        let Some(sink) = self.sink.as_mut() else {
            return Err(self.no_sink());
        };
        match f(sink, &mut self.dec) {
            Ok(x) => Ok(x),
            Err(e) => Err(self.stop(e)),
        }
    }

    /// Stop the writer thread after `e` and return the error that explains it best: the
    /// thread's own, when it has one.
    fn stop(&mut self, e: io::Error) -> io::Error {
        self.sink = None;
        self.failed = true;
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(Err(te))) => te,
            Some(Err(_)) => io::Error::other("MCAP writer thread panicked"),
            _ => e,
        }
    }

    fn raw_channel(&mut self, stream: u32, dir: Direction, timed: bool) -> io::Result<u16> {
        if let Some(&id) = self.raw.get(&(stream, dir, timed)) {
            return Ok(id);
        }
        let mut meta = BTreeMap::new();
        meta.insert("stream".to_string(), stream.to_string());
        meta.insert("direction".to_string(), dir.as_str().to_string());
        meta.insert(
            "time".to_string(),
            if timed { "capture" } else { "missing" }.to_string(),
        );
        if let Some(s) = self.streams.get(&stream) {
            meta.insert("name".to_string(), s.name.clone());
            if let Some(x) = &s.settings {
                meta.insert("settings".to_string(), x.clone());
            }
        }
        let topic = format!("/serial/{stream}/{}", dir.as_str());
        let id = self.with_sink(|s, _| s.add_channel(0, topic, RAW_ENCODING, meta))?;
        self.raw.insert((stream, dir, timed), id);
        Ok(id)
    }
}

impl<W: Write + Seek + Send + 'static> Drop for McapWriter<W> {
    fn drop(&mut self) {
        // Hand over what was written so far and hang up; the thread then closes the file (as
        // dropping an `mcap::Writer` does).
        if let Some(mut sink) = self.sink.take() {
            let _ = sink.flush();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl<W: Write + Seek + Send + 'static> Writer for McapWriter<W> {
    fn stream(&mut self, s: &StreamInfo) -> io::Result<()> {
        if self.sink.is_none() {
            return Err(self.no_sink());
        }
        let mut meta = BTreeMap::new();
        meta.insert("id".to_string(), s.id.to_string());
        meta.insert("name".to_string(), s.name.clone());
        if let Some(x) = &s.settings {
            meta.insert("settings".to_string(), x.clone());
        }
        self.with_sink(|w, _| {
            w.metadata(Metadata {
                name: "aptscope.stream".into(),
                metadata: meta,
            })
        })?;
        self.streams.insert(s.id, s.clone());
        Ok(())
    }

    fn chunk(&mut self, c: &Chunk<'_>) -> io::Result<()> {
        let ch = self.raw_channel(c.stream, c.dir, c.ts_ns.is_some())?;
        let t = c.ts_ns.unwrap_or(0);
        let seq = self.seq;
        self.with_sink(|w, dec| {
            w.message(ch, seq, t, c.bytes)?;
            dec.chunk(c, w)
        })?;
        self.seq = self.seq.wrapping_add(1);
        self.chunks += 1;
        if c.ts_ns.is_none() {
            self.untimed += 1;
        }
        Ok(())
    }

    fn finish(&mut self) -> io::Result<()> {
        if self.sink.is_none() {
            return if self.failed {
                Err(failed_err())
            } else {
                Ok(())
            };
        }
        let (untimed, chunks) = (self.untimed, self.chunks);
        self.with_sink(|w, dec| {
            dec.finish(w)?;
            if let Some(p) = dec.proto {
                let mut m = BTreeMap::new();
                m.insert("proto".to_string(), p.name().to_string());
                m.insert("how".to_string(), dec.how.to_string());
                if let Some((a, e)) = dec.scores {
                    m.insert("apt".to_string(), format!("{a:.3}"));
                    m.insert("elliptec".to_string(), format!("{e:.3}"));
                }
                w.metadata(Metadata {
                    name: "aptscope.decode".into(),
                    metadata: m,
                })?;
            }
            if untimed > 0 {
                let mut m = BTreeMap::new();
                m.insert(
                    "missing".to_string(),
                    format!(
                        "{untimed} of {chunks} chunks have no capture time: their messages have \
                         log_time 0 (channels with metadata time=missing)"
                    ),
                );
                m.insert("chunks_without_time".to_string(), untimed.to_string());
                m.insert("chunks".to_string(), chunks.to_string());
                w.metadata(Metadata {
                    name: "aptscope.times".into(),
                    metadata: m,
                })?;
            }
            w.flush()
        })?;
        // Hang up: the thread finishes the file and hands the writer back.
        self.sink = None;
        let res = match self.thread.take().map(|t| t.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(io::Error::other("MCAP writer thread panicked")),
            None => Err(finished_err()),
        };
        self.failed = res.is_err();
        let mut inner = res?;
        inner.flush()?;
        self.inner = Some(inner);
        Ok(())
    }
}

// --- the writer thread -----------------------------------------------------------------------

/// One call to make on the [`mcap::Writer`].
enum Op {
    /// `add_schema` (jsonschema), which must return `id`.
    Schema {
        id: u16,
        name: String,
        body: String,
    },
    /// `add_channel`, which must return `id`.
    Channel {
        id: u16,
        schema: u16,
        topic: String,
        encoding: &'static str,
        meta: BTreeMap<String, String>,
    },
    /// `write_to_known_channel`; the message is the next `len` bytes of the batch's data.
    Message {
        channel: u16,
        sequence: u32,
        log_time: u64,
        len: usize,
    },
    Metadata(Metadata),
}

/// Calls to make, in order, with the messages' bytes back to back.
#[derive(Default)]
struct Batch {
    ops: Vec<Op>,
    data: Vec<u8>,
}

/// Send a batch to the writer thread once it holds this many message bytes …
const BATCH_BYTES: usize = 256 * 1024;
/// … or this many calls.
const BATCH_OPS: usize = 4096;
/// Full batches on their way to the writer thread (bounds the memory to a few batches).
const BATCHES_IN_FLIGHT: usize = 2;

/// The calling thread's end of the writer thread: it batches the calls, and assigns schema
/// and channel ids exactly as [`mcap::Writer::add_schema`] and
/// [`mcap::Writer::add_channel`] will (sequentially from 1, identical content deduplicated),
/// so no call waits for an answer. The writer thread checks every id.
struct Sink {
    batch: Batch,
    tx: std::sync::mpsc::SyncSender<Batch>,
    /// Emptied batches, back from the writer thread for reuse.
    spare: std::sync::mpsc::Receiver<Batch>,
    schemas: HashMap<(String, String), u16>,
    channels: u16,
}

impl Sink {
    fn start<W: Write + Seek + Send + 'static>(
        mut w: mcap::Writer<W>,
    ) -> io::Result<(Sink, std::thread::JoinHandle<io::Result<W>>)> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Batch>(BATCHES_IN_FLIGHT);
        let (spare_tx, spare) = std::sync::mpsc::channel::<Batch>();
        let thread = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || {
                for mut b in rx {
                    run_batch(&mut w, &mut b).map_err(mcap_err)?;
                    b.ops.clear();
                    b.data.clear();
                    let _ = spare_tx.send(b);
                }
                // Hung up: finish or drop; either way close the file as `mcap::Writer` does.
                w.finish().map_err(mcap_err)?;
                Ok(w.into_inner())
            })?;
        let sink = Sink {
            batch: Batch {
                ops: Vec::with_capacity(BATCH_OPS),
                data: Vec::with_capacity(BATCH_BYTES + 4096),
            },
            tx,
            spare,
            schemas: HashMap::new(),
            channels: 0,
        };
        Ok((sink, thread))
    }

    fn push(&mut self, op: Op) -> io::Result<()> {
        self.batch.ops.push(op);
        if self.batch.ops.len() >= BATCH_OPS || self.batch.data.len() >= BATCH_BYTES {
            self.flush()?;
        }
        Ok(())
    }

    /// Hand the batch to the writer thread.
    fn flush(&mut self) -> io::Result<()> {
        if self.batch.ops.is_empty() {
            return Ok(());
        }
        let next = self.spare.try_recv().unwrap_or_else(|_| Batch {
            ops: Vec::with_capacity(BATCH_OPS),
            data: Vec::with_capacity(BATCH_BYTES + 4096),
        });
        let full = std::mem::replace(&mut self.batch, next);
        self.tx
            .send(full)
            .map_err(|_| io::Error::other("MCAP writer thread stopped"))
    }

    fn add_schema(&mut self, name: String, body: String) -> io::Result<u16> {
        let key = (name, body);
        if let Some(&id) = self.schemas.get(&key) {
            return Ok(id);
        }
        let id = u16::try_from(self.schemas.len() + 1)
            .map_err(|_| mcap_err(McapError::TooManySchemas))?;
        self.schemas.insert(key.clone(), id);
        let (name, body) = key;
        self.push(Op::Schema { id, name, body })?;
        Ok(id)
    }

    /// Every channel we add has a distinct topic or metadata, so each gets a new id.
    fn add_channel(
        &mut self,
        schema: u16,
        topic: String,
        encoding: &'static str,
        meta: BTreeMap<String, String>,
    ) -> io::Result<u16> {
        self.channels = self
            .channels
            .checked_add(1)
            .ok_or_else(|| mcap_err(McapError::TooManyChannels))?;
        let id = self.channels;
        self.push(Op::Channel {
            id,
            schema,
            topic,
            encoding,
            meta,
        })?;
        Ok(id)
    }

    fn message(
        &mut self,
        channel: u16,
        sequence: u32,
        log_time: u64,
        data: &[u8],
    ) -> io::Result<()> {
        self.batch.data.extend_from_slice(data);
        self.push(Op::Message {
            channel,
            sequence,
            log_time,
            len: data.len(),
        })
    }

    fn metadata(&mut self, m: Metadata) -> io::Result<()> {
        self.push(Op::Metadata(m))
    }
}

/// Make a batch's calls on the MCAP writer (in the writer thread).
fn run_batch<W: Write + Seek>(w: &mut mcap::Writer<W>, b: &mut Batch) -> Result<(), McapError> {
    let mut at = 0;
    for op in b.ops.drain(..) {
        match op {
            Op::Message {
                channel,
                sequence,
                log_time,
                len,
            } => {
                w.write_to_known_channel(
                    &MessageHeader {
                        channel_id: channel,
                        sequence,
                        log_time,
                        publish_time: log_time,
                    },
                    &b.data[at..at + len],
                )?;
                at += len;
            }
            Op::Schema { id, name, body } => {
                let got = w.add_schema(&name, "jsonschema", body.as_bytes())?;
                check_id("schema", &name, id, got)?;
            }
            Op::Channel {
                id,
                schema,
                topic,
                encoding,
                meta,
            } => {
                let got = w.add_channel(schema, &topic, encoding, &meta)?;
                check_id("channel", &topic, id, got)?;
            }
            Op::Metadata(m) => w.write_metadata(&m)?,
        }
    }
    Ok(())
}

fn check_id(what: &str, name: &str, want: u16, got: u16) -> Result<(), McapError> {
    if want == got {
        Ok(())
    } else {
        Err(McapError::Io(io::Error::other(format!(
            "internal error: MCAP {what} {name} got id {got}, not {want}"
        ))))
    }
}

// --- decoded channels ------------------------------------------------------------------------

enum Framer {
    Apt(Box<AptFramer<'static>>),
    Ell(Box<EllFramer>),
}

struct Lane {
    framer: Framer,
    /// The last capture time seen on the lane.
    ts: Option<u64>,
}

#[derive(Default)]
struct StreamDec {
    bus: Bus,
}

/// Where decoded records go: the MCAP writer and the decoded channels made so far.
struct Out<'a> {
    w: &'a mut Sink,
    topics: &'a mut HashMap<String, u16>,
    /// Channel ids by [`TopicKey`]: the per-record lookup, without building or hashing the
    /// topic string.
    ids: &'a mut HashMap<TopicKey, u16, FastHash>,
    line: &'a mut String,
    topic: &'a mut String,
    expired: &'a mut Vec<Expired>,
    /// Record number, over the whole capture (as in `decode --json`).
    n: &'a mut u64,
}

/// What a decoded record's channel is known by on the hot path: a fixed topic, or the address
/// and length of the `&'static` name of the message (APT) or command (Elliptec) whose topic it
/// is. Two keys
/// may map to one topic (see [`Out::write`]); one key never maps to two.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum TopicKey {
    AptUnknown,
    AptGarbage,
    AptMsg(usize, usize),
    EllUnknown,
    EllGarbage,
    EllCmd(usize, usize),
    EllDiag,
}

/// A multiply-rotate hasher (as in rustc's FxHash) for the per-chunk and per-record lookups:
/// their keys are small integers, tags and addresses we make, so SipHash's flooding resistance
/// buys nothing and costs more than the rest of a lookup.
#[derive(Default)]
struct KeyHasher(u64);

type FastHash = BuildHasherDefault<KeyHasher>;

impl std::hash::Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn write_u8(&mut self, x: u8) {
        self.write_u64(x.into());
    }
    fn write_u32(&mut self, x: u32) {
        self.write_u64(x.into());
    }
    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }
    fn write_isize(&mut self, x: isize) {
        self.write_u64(x as u64);
    }
}

impl Out<'_> {
    /// Write `self.line` on the channel of `key`. On the key's first use, `topic` names the
    /// channel; the channel (with `schema()`) is made on the topic's first use.
    fn write(
        &mut self,
        key: TopicKey,
        seq: u64,
        log_time: u64,
        topic: impl FnOnce(&mut String),
        schema: impl FnOnce() -> (String, String),
    ) -> io::Result<()> {
        let id = match self.ids.get(&key) {
            Some(&id) => id,
            None => {
                self.topic.clear();
                topic(self.topic);
                let id = match self.topics.get(self.topic.as_str()) {
                    Some(&id) => id,
                    None => {
                        let (name, body) = schema();
                        let sid = self.w.add_schema(name, body)?;
                        let id =
                            self.w
                                .add_channel(sid, self.topic.clone(), "json", BTreeMap::new())?;
                        self.topics.insert(self.topic.clone(), id);
                        id
                    }
                };
                self.ids.insert(key, id);
                id
            }
        };
        self.w
            .message(id, seq as u32, log_time, self.line.as_bytes())
    }
}

/// Append the capture context to a decoded record's JSON object, as the pipeline's NDJSON
/// does: `dir` (when given), `ts_ns` (when known) and `stream`.
fn close_json(line: &mut String, ts: Option<u64>, stream: u32, dir: Option<&str>) {
    if line.ends_with('}') {
        line.pop();
        if let Some(d) = dir {
            line.push_str(",\"dir\":\"");
            line.push_str(d);
            line.push('"');
        }
        if let Some(t) = ts {
            line.push_str(",\"ts_ns\":");
            push_uint(line, t);
        }
        line.push_str(",\"stream\":");
        push_uint(line, stream.into());
        line.push('}');
    }
}

/// Append `x` in decimal, two digits per division (`write!` costs several times more on this
/// per-record path, and capture times have 19 digits).
fn push_uint(out: &mut String, mut x: u64) {
    const PAIRS: &[u8; 200] = b"0001020304050607080910111213141516171819\
        2021222324252627282930313233343536373839\
        4041424344454647484950515253545556575859\
        6061626364656667686970717273747576777879\
        8081828384858687888990919293949596979899";
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    while x >= 100 {
        let p = (x % 100) as usize * 2;
        x /= 100;
        i -= 2;
        buf[i..i + 2].copy_from_slice(&PAIRS[p..p + 2]);
    }
    if x >= 10 {
        let p = x as usize * 2;
        i -= 2;
        buf[i..i + 2].copy_from_slice(&PAIRS[p..p + 2]);
    } else {
        i -= 1;
        buf[i] = b'0' + x as u8;
    }
    // Only ASCII digits were written.
    out.push_str(std::str::from_utf8(&buf[i..]).unwrap_or_default());
}

struct Decoder {
    proto: Option<Proto>,
    how: &'static str,
    scores: Option<(f64, f64)>,
    held: Vec<crate::model::OwnedChunk>,
    held_bytes: usize,
    first_lane: Option<(u32, Direction)>,
    first_lane_bytes: usize,
    lanes: HashMap<(u32, Direction), Lane, FastHash>,
    streams: HashMap<u32, StreamDec, FastHash>,
    topics: HashMap<String, u16>,
    ids: HashMap<TopicKey, u16, FastHash>,
    line: String,
    topic: String,
    expired: Vec<Expired>,
    n: u64,
}

impl Decoder {
    fn new(proto: Option<Proto>) -> Self {
        Decoder {
            proto,
            how: "given",
            scores: None,
            held: vec![],
            held_bytes: 0,
            first_lane: None,
            first_lane_bytes: 0,
            lanes: HashMap::default(),
            streams: HashMap::default(),
            topics: HashMap::new(),
            ids: HashMap::default(),
            line: String::with_capacity(1024),
            topic: String::with_capacity(64),
            expired: vec![],
            n: 0,
        }
    }

    fn chunk(&mut self, c: &Chunk<'_>, w: &mut Sink) -> io::Result<()> {
        if self.proto.is_some() {
            return self.push(c.stream, c.dir, c.bytes, c.ts_ns, w);
        }
        let lane = (c.stream, c.dir);
        if self.first_lane.is_none() && !c.bytes.is_empty() {
            self.first_lane = Some(lane);
        }
        if self.first_lane == Some(lane) {
            self.first_lane_bytes += c.bytes.len();
        }
        self.held_bytes += c.bytes.len();
        self.held.push(c.to_owned());
        if self.first_lane_bytes >= SAMPLE
            || self.held_bytes >= DETECT_HOLD
            || self.held.len() >= DETECT_HOLD_CHUNKS
        {
            self.decide(w)?;
        }
        Ok(())
    }

    /// Detect the protocol on the first lane's sample and decode what was held back.
    fn decide(&mut self, w: &mut Sink) -> io::Result<()> {
        let held = std::mem::take(&mut self.held);
        let Some(first) = self.first_lane else {
            // No data at all: nothing to decode.
            return Ok(());
        };
        let mut sample = Vec::with_capacity(SAMPLE);
        for c in held.iter().filter(|c| (c.stream, c.dir) == first) {
            let room = SAMPLE - sample.len();
            sample.extend_from_slice(&c.bytes[..c.bytes.len().min(room)]);
            if sample.len() >= SAMPLE {
                break;
            }
        }
        let d = detect(&sample);
        self.proto = Some(d.proto.unwrap_or(if d.elliptec > d.apt {
            Proto::Elliptec
        } else {
            Proto::Apt
        }));
        self.how = if d.proto.is_some() {
            "detected"
        } else {
            "best guess (mixed or unknown stream)"
        };
        self.scores = Some((d.apt, d.elliptec));
        for c in &held {
            self.push(c.stream, c.dir, &c.bytes, c.ts_ns, w)?;
        }
        Ok(())
    }

    fn push(
        &mut self,
        stream: u32,
        dir: Direction,
        bytes: &[u8],
        ts: Option<u64>,
        w: &mut Sink,
    ) -> io::Result<()> {
        let proto = self.proto.unwrap_or(Proto::Apt);
        let lane = self.lanes.entry((stream, dir)).or_insert_with(|| Lane {
            framer: match proto {
                Proto::Apt => Framer::Apt(Box::new(AptFramer::new(Table::global()))),
                Proto::Elliptec => Framer::Ell(Box::new(EllFramer::new())),
            },
            ts: None,
        });
        if ts.is_some() {
            lane.ts = ts;
        }
        match &mut lane.framer {
            Framer::Apt(f) => f.push(bytes),
            Framer::Ell(f) => f.push(bytes),
        }
        let st = self.streams.entry(stream).or_default();
        let mut out = Out {
            w,
            topics: &mut self.topics,
            ids: &mut self.ids,
            line: &mut self.line,
            topic: &mut self.topic,
            expired: &mut self.expired,
            n: &mut self.n,
        };
        drain(lane, st, stream, dir, &mut out)
    }

    fn finish(&mut self, w: &mut Sink) -> io::Result<()> {
        if self.proto.is_none() {
            self.decide(w)?;
        }
        let mut keys: Vec<(u32, Direction)> = self.lanes.keys().copied().collect();
        keys.sort();
        for (stream, dir) in keys {
            let Some(lane) = self.lanes.get_mut(&(stream, dir)) else {
                continue;
            };
            match &mut lane.framer {
                Framer::Apt(f) => f.finish(),
                Framer::Ell(f) => f.finish(),
            }
            let st = self.streams.entry(stream).or_default();
            let mut out = Out {
                w: &mut *w,
                topics: &mut self.topics,
                ids: &mut self.ids,
                line: &mut self.line,
                topic: &mut self.topic,
                expired: &mut self.expired,
                n: &mut self.n,
            };
            drain(lane, st, stream, dir, &mut out)?;
        }
        let mut ids: Vec<u32> = self.streams.keys().copied().collect();
        ids.sort_unstable();
        for id in ids {
            let Some(st) = self.streams.get_mut(&id) else {
                continue;
            };
            let left = st.bus.finish();
            let t = self
                .lanes
                .iter()
                .filter(|(k, _)| k.0 == id)
                .filter_map(|(_, l)| l.ts)
                .max()
                .unwrap_or(0);
            self.expired.extend(left);
            let mut out = Out {
                w: &mut *w,
                topics: &mut self.topics,
                ids: &mut self.ids,
                line: &mut self.line,
                topic: &mut self.topic,
                expired: &mut self.expired,
                n: &mut self.n,
            };
            late_diags(&mut out, id, t)?;
        }
        Ok(())
    }
}

/// Write the records the lane's framer has ready. They get the lane's latest capture time
/// (the time of the chunk that completed them) as `log_time` (0 when unknown).
fn drain(
    lane: &mut Lane,
    st: &mut StreamDec,
    stream: u32,
    dir: Direction,
    out: &mut Out<'_>,
) -> io::Result<()> {
    let table = Table::global();
    let ts = lane.ts;
    let t = ts.unwrap_or(0);
    let cap_dir = (dir != Direction::Unknown).then(|| dir.as_str());
    match &mut lane.framer {
        Framer::Apt(fr) => {
            while let Some(item) = fr.next_item() {
                *out.n += 1;
                let n = *out.n;
                out.line.clear();
                match item {
                    AptItem::Frame {
                        offset,
                        bytes,
                        truncated,
                    } => {
                        let Some(f) = AptFrame::decode(table, offset, bytes, truncated) else {
                            continue;
                        };
                        let m = f.msg;
                        // The captured direction, else the table's when it has one.
                        let d = cap_dir
                            .or_else(|| {
                                m.map(|m| m.dir)
                                    .filter(|d| *d != Dir::Both)
                                    .map(Dir::as_str)
                            })
                            .unwrap_or("unknown");
                        json::apt_frame(out.line, n, &f);
                        close_json(out.line, ts, stream, Some(d));
                        let key = m.map_or(TopicKey::AptUnknown, |m| {
                            TopicKey::AptMsg(m.name.as_ptr() as usize, m.name.len())
                        });
                        let topic = |s: &mut String| {
                            s.push_str("/apt/");
                            s.push_str(m.map_or("unknown", |m| m.name));
                        };
                        out.write(key, n, t, topic, || match m {
                            Some(m) => (format!("aptscope.apt.{}", m.name), apt_schema(table, m)),
                            None => ("aptscope.apt.unknown".into(), apt_unknown_schema()),
                        })?;
                    }
                    AptItem::Garbage {
                        offset,
                        bytes,
                        kind,
                    } => {
                        json::apt_garbage(out.line, n, offset, bytes, kind);
                        close_json(out.line, ts, stream, Some(cap_dir.unwrap_or("unknown")));
                        let topic = |s: &mut String| s.push_str("/apt/garbage");
                        out.write(TopicKey::AptGarbage, n, t, topic, || {
                            ("aptscope.apt.garbage".into(), garbage_schema("apt"))
                        })?;
                    }
                }
            }
        }
        Framer::Ell(fr) => {
            while let Some(item) = fr.next_item() {
                *out.n += 1;
                let n = *out.n;
                out.line.clear();
                match item {
                    EllItem::Frame {
                        offset,
                        bytes,
                        truncated,
                    } => {
                        let Some(mut f) = EllFrame::decode(offset, bytes, truncated) else {
                            continue;
                        };
                        let o = st.bus.observe(n, &f, ts);
                        if o.unsolicited {
                            f.push_diag(Diag {
                                offset,
                                kind: DiagKind::Unsolicited,
                            });
                        }
                        out.expired.extend(o.expired.iter().copied());
                        json::ell_frame(out.line, n, &f, &o);
                        close_json(out.line, ts, stream, None);
                        let cmd = f.cmd;
                        let key = cmd.map_or(TopicKey::EllUnknown, |c| {
                            TopicKey::EllCmd(c.code.as_ptr() as usize, c.code.len())
                        });
                        let topic = |s: &mut String| {
                            s.push_str("/ell/");
                            s.push_str(cmd.map_or("unknown", |c| c.code));
                        };
                        out.write(key, n, t, topic, || match cmd {
                            Some(c) => (format!("aptscope.ell.{}", c.code), ell_schema(Some(c))),
                            None => ("aptscope.ell.unknown".into(), ell_schema(None)),
                        })?;
                    }
                    EllItem::Garbage { offset, bytes, .. } => {
                        json::ell_garbage(out.line, n, offset, bytes);
                        close_json(out.line, ts, stream, None);
                        let topic = |s: &mut String| s.push_str("/ell/garbage");
                        out.write(TopicKey::EllGarbage, n, t, topic, || {
                            ("aptscope.ell.garbage".into(), garbage_schema("ell"))
                        })?;
                    }
                }
                if !out.expired.is_empty() {
                    late_diags(out, stream, t)?;
                }
            }
        }
    }
    Ok(())
}

/// Write the `no_reply` diagnostics collected in `out.expired` on `/ell/diag`.
fn late_diags(out: &mut Out<'_>, stream: u32, t: u64) -> io::Result<()> {
    let list = std::mem::take(out.expired);
    for e in &list {
        out.line.clear();
        json::late_diag(
            out.line,
            "ell",
            e.n,
            Diag {
                offset: e.offset,
                kind: DiagKind::NoReply { cmd: e.n },
            },
        );
        close_json(out.line, None, stream, None);
        let topic = |s: &mut String| s.push_str("/ell/diag");
        out.write(TopicKey::EllDiag, e.n, t, topic, || {
            ("aptscope.ell.diag".into(), late_diag_schema())
        })?;
    }
    Ok(())
}

// --- JSON schemas ----------------------------------------------------------------------------

/// A JSON Schema object under construction: `{"type":"object",…,"properties":{…}}`. Only the
/// constructs Foxglove's JSON Schema reader accepts are used: one `type` per property, arrays
/// of scalars or objects, objects with `properties`.
struct SchemaObj {
    props: String,
    head: String,
}

impl SchemaObj {
    fn new(title: Option<&str>, description: Option<&str>) -> Self {
        let mut head = String::new();
        if let Some(t) = title {
            head.push_str(
                "\"$schema\":\"https://json-schema.org/draft/2020-12/schema\",\"title\":",
            );
            json::string(&mut head, t);
            head.push(',');
        }
        if let Some(d) = description.filter(|d| !d.is_empty()) {
            head.push_str("\"description\":");
            json::string(&mut head, d);
            head.push(',');
        }
        SchemaObj {
            props: String::new(),
            head,
        }
    }

    /// Add a property whose schema is `body` (a JSON object text).
    fn raw(&mut self, name: &str, body: &str) -> &mut Self {
        if !self.props.is_empty() {
            self.props.push(',');
        }
        json::string(&mut self.props, name);
        self.props.push(':');
        self.props.push_str(body);
        self
    }

    /// Add a scalar property.
    fn prop(&mut self, name: &str, ty: &str, description: Option<&str>) -> &mut Self {
        let body = scalar(ty, description);
        self.raw(name, &body)
    }

    fn build(&self) -> String {
        format!(
            "{{{}\"type\":\"object\",\"properties\":{{{}}}}}",
            self.head, self.props
        )
    }
}

fn scalar(ty: &str, description: Option<&str>) -> String {
    let mut s = format!("{{\"type\":\"{ty}\"");
    if let Some(d) = description {
        s.push_str(",\"description\":");
        json::string(&mut s, d);
    }
    s.push('}');
    s
}

fn string_enum<'a>(labels: impl Iterator<Item = &'a str>, description: Option<&str>) -> String {
    let mut s = String::from("{\"type\":\"string\",\"enum\":[");
    for (i, l) in labels.enumerate() {
        if i > 0 {
            s.push(',');
        }
        json::string(&mut s, l);
    }
    s.push(']');
    if let Some(d) = description {
        s.push_str(",\"description\":");
        json::string(&mut s, d);
    }
    s.push('}');
    s
}

fn array_of(items: &str, description: Option<&str>) -> String {
    let mut s = format!("{{\"type\":\"array\",\"items\":{items}");
    if let Some(d) = description {
        s.push_str(",\"description\":");
        json::string(&mut s, d);
    }
    s.push('}');
    s
}

fn diag_array() -> String {
    let mut d = SchemaObj::new(None, None);
    d.prop("kind", "string", Some("stable snake_case kind"))
        .prop("offset", "integer", Some("byte offset in the lane"))
        .prop("msg", "string", None);
    array_of(&d.build(), Some("problems found in this record"))
}

/// Properties every decoded record has (as `decode --json` writes them). APT records carry the
/// capture direction as `dir`; Elliptec frames say their direction themselves.
fn common(o: &mut SchemaObj, proto: &str) {
    o.prop("n", "integer", Some("record number in the capture"))
        .raw(
            "proto",
            &string_enum(std::iter::once(proto), Some("protocol")),
        )
        .raw(
            "type",
            &string_enum(["frame", "garbage"].into_iter(), Some("record type")),
        )
        .prop(
            "offset",
            "integer",
            Some("byte offset of the record in its lane's byte stream"),
        )
        .prop(
            "cap_offset",
            "integer",
            Some("byte offset of the record in the whole capture (all lanes, read order)"),
        )
        .prop("len", "integer", Some("record length in bytes"))
        .prop("raw", "string", Some("the bytes, as hex"))
        .prop(
            "ts_ns",
            "integer",
            Some("capture time (ns) of the chunk that completed the record"),
        )
        .prop("stream", "integer", Some("capture stream index"));
    if proto == "apt" {
        o.raw(
            "dir",
            &string_enum(
                ["h2d", "d2h", "unknown"].into_iter(),
                Some("captured direction, else the message's direction in the table"),
            ),
        );
    }
}

fn addr_schema(what: &str) -> String {
    let mut a = SchemaObj::new(None, Some(what));
    a.prop(
        "addr",
        "integer",
        Some("address byte (0x01 host, 0x11 rack, 0x21-0x2A bays, 0x50 USB unit)"),
    )
    .prop("name", "string", Some("host, rack, usb, bay0-bay9 or 0xNN"))
    .prop("bay", "integer", Some("bay number 0-9, for bay addresses"));
    a.build()
}

/// The schema of one APT field's JSON value.
fn apt_field_schema(t: &Table, f: &Field) -> String {
    let mut desc = String::new();
    desc.push_str(&f.ty.name());
    match (f.unit, f.scale) {
        (Some(u), Some(s)) => {
            let _ = write!(desc, "; raw value, x {s} = {u} (see phys)");
        }
        (Some(u), None) => {
            let _ = write!(desc, "; {u}");
        }
        (None, Some(s)) => {
            let _ = write!(desc, "; raw value, scale {s}");
        }
        (None, None) => {}
    }
    let num = |p: Prim| if p == Prim::F32 { "number" } else { "integer" };
    match f.ty {
        Ty::Prim(p) => {
            if let Some(e) = f.enumeration {
                let d = t.enum_def(e);
                let _ = write!(desc, "; enum {} (unknown values as numbers)", d.name);
                string_enum(d.items.iter().map(|(_, l)| *l), Some(&desc))
            } else if let Some(fl) = f.flags {
                let d = t.flags_def(fl);
                let _ = write!(desc, "; flags {}: the names of the set bits", d.name);
                array_of(
                    &string_enum(d.items.iter().map(|(_, l)| *l), None),
                    Some(&desc),
                )
            } else {
                scalar(num(p), Some(&desc))
            }
        }
        Ty::Array(p, _) => array_of(&scalar(num(p), None), Some(&desc)),
        Ty::Str(_) => scalar("string", Some(&desc)),
        Ty::Bytes(_) | Ty::Pad(_) => {
            desc.push_str("; as hex");
            scalar("string", Some(&desc))
        }
    }
}

/// Every field of a message over all its forms (and, for sub-message groups, all the group's
/// sub-messages), each name once (the first definition wins), reserved bytes left out.
fn apt_fields<'t>(t: &'t Table, m: &'t MsgDef) -> Vec<&'t Field> {
    let mut seen = HashSet::new();
    let mut out = vec![];
    let mut add = |fs: &'t [Field]| {
        for f in fs {
            if !matches!(f.ty, Ty::Pad(_)) && seen.insert(f.name) {
                out.push(f);
            }
        }
    };
    for form in &m.forms {
        if form.kind == FormKind::Sub {
            if let Some(g) = m.subs {
                for s in t.subs().iter().filter(|s| s.group == g) {
                    for sf in &s.forms {
                        add(&sf.fields);
                    }
                }
            }
        } else {
            add(&form.fields);
        }
    }
    out
}

/// The JSON Schema of an APT message's decoded records, from the message table.
pub fn apt_schema(t: &Table, m: &MsgDef) -> String {
    let title = format!("APT {} (0x{:04X})", m.name, m.id);
    let mut o = SchemaObj::new(Some(&title), Some(m.doc));
    common(&mut o, "apt");
    o.prop("msgid", "integer", Some("message id"))
        .prop("msgid_hex", "string", None)
        .prop("name", "string", Some("message name (without MGMSG_)"))
        .raw(
            "msg_dir",
            &string_enum(
                std::iter::once(m.dir.as_str()),
                Some("who sends it, per the table"),
            ),
        )
        .raw("src", &addr_schema("source"))
        .raw("dst", &addr_schema("destination"))
        .prop(
            "data_flag",
            "boolean",
            Some("the 0x80 data-packet-follows bit of the destination byte"),
        )
        .prop("data_len", "integer", Some("data packet length"))
        .prop(
            "form_note",
            "string",
            Some("which variant of a multi-form message this is"),
        )
        .prop(
            "channel",
            "integer",
            Some("channel number 1-4 from chan_ident"),
        );
    if m.subs.is_some() {
        let mut s = SchemaObj::new(None, Some("sub-message"));
        s.prop("id", "integer", None).prop("name", "string", None);
        o.raw("sub", &s.build());
    }
    let fields = apt_fields(t, m);
    let mut fo = SchemaObj::new(
        None,
        Some("typed field values: raw numbers, enum labels, lists of set flags"),
    );
    let mut po = SchemaObj::new(None, Some("scaled fields in physical units"));
    let mut any_phys = false;
    for f in &fields {
        fo.raw(f.name, &apt_field_schema(t, f));
        if f.scale.is_some() {
            let mut v = SchemaObj::new(None, f.unit);
            v.prop("value", "number", f.unit)
                .prop("unit", "string", None);
            po.raw(f.name, &v.build());
            any_phys = true;
        }
    }
    o.raw("fields", &fo.build());
    if any_phys {
        o.raw("phys", &po.build());
    }
    let coded = fields
        .iter()
        .filter(|f| f.enumeration.is_some() || f.flags.is_some());
    codes_schema(&mut o, coded.map(|f| f.name));
    o.raw("diag", &diag_array());
    o.build()
}

/// `codes`: the number of each enum or flag field named in `fields` (when there are any).
fn codes_schema<'a>(o: &mut SchemaObj, names: impl Iterator<Item = &'a str>) {
    let mut co = SchemaObj::new(None, Some("numbers of the enum and flag fields"));
    let mut any = false;
    for n in names {
        co.prop(n, "integer", None);
        any = true;
    }
    if any {
        o.raw("codes", &co.build());
    }
}

fn apt_unknown_schema() -> String {
    let mut o = SchemaObj::new(
        Some("APT frame of an unknown message id"),
        Some("a frame whose message id the table lacks; data shown in raw"),
    );
    common(&mut o, "apt");
    o.prop("msgid", "integer", Some("message id"))
        .prop("msgid_hex", "string", None)
        .prop("name", "string", Some("null: the table lacks this id"))
        .raw("src", &addr_schema("source"))
        .raw("dst", &addr_schema("destination"))
        .prop("data_flag", "boolean", None)
        .prop("data_len", "integer", None)
        .raw("fields", &SchemaObj::new(None, None).build())
        .raw("diag", &diag_array());
    o.build()
}

fn garbage_schema(proto: &str) -> String {
    let mut o = SchemaObj::new(
        Some(&format!("{proto} garbage")),
        Some("bytes that are not part of any frame"),
    );
    common(&mut o, proto);
    if proto == "ell" {
        o.prop("text", "string", Some("the bytes as text"));
    }
    o.raw("diag", &diag_array());
    o.build()
}

fn late_diag_schema() -> String {
    let mut o = SchemaObj::new(
        Some("Elliptec late diagnostic"),
        Some("a problem found later about an earlier record (a command that got no reply)"),
    );
    o.prop("stream", "integer", Some("capture stream index"))
        .prop("proto", "string", None)
        .prop("type", "string", None)
        .prop(
            "ref",
            "integer",
            Some("record number the diagnostic is about"),
        )
        .raw("diag", &diag_array());
    o.build()
}

fn ell_field_schema(kind: Kind) -> String {
    let (ty, d): (&str, String) = match kind {
        Kind::Hex => ("integer", "hex number".into()),
        Kind::Signed => ("integer", "signed number".into()),
        Kind::Dec => ("string", "decimal digits as written".into()),
        Kind::Addr => ("string", "bus address 0-F".into()),
        Kind::Status => (
            "string",
            "status code name (OK, BUSY, OUT_OF_RANGE ...)".into(),
        ),
        Kind::Model => ("integer", "module type: ELL number".into()),
        Kind::Firmware => (
            "integer",
            "firmware release: high nibble major, low minor".into(),
        ),
        Kind::ThreadHw => (
            "integer",
            "packed thread (bit 7) and hardware release".into(),
        ),
        Kind::Position => (
            "integer",
            "encoder pulses (in mm or deg under phys once the module is known)".into(),
        ),
        Kind::Period => (
            "integer",
            "drive period: frequency = 14740000 / period Hz".into(),
        ),
        Kind::Current => ("integer", "motor current: 1866 per ampere".into()),
        Kind::Bool => ("integer", "0 or 1".into()),
        Kind::Percent => ("integer", "percent".into()),
        Kind::Minutes => ("integer", "minutes".into()),
        Kind::HomeDir => (
            "integer",
            "home direction: 0 clockwise, 1 counter-clockwise".into(),
        ),
        Kind::Raw => ("string", "binary data as hex".into()),
    };
    scalar(ty, Some(&d))
}

/// The JSON Schema of an Elliptec command's (or reply's) decoded records; `None` for commands
/// the manual lacks.
pub fn ell_schema(cmd: Option<&Cmd>) -> String {
    let title = match cmd {
        Some(c) => format!("Elliptec {} {}", c.code, c.name),
        None => "Elliptec unknown command".to_string(),
    };
    let mut o = SchemaObj::new(Some(&title), cmd.map(|c| c.doc));
    common(&mut o, "ell");
    o.prop(
        "text",
        "string",
        Some("the frame as text, terminator included"),
    )
    .prop("addr", "string", Some("bus address 0-F"))
    .raw(
        "dir",
        &string_enum(
            ["h2d", "d2h"].into_iter(),
            Some("h2d for lower-case commands, d2h for replies"),
        ),
    )
    .prop("cmd", "string", Some("the two-letter mnemonic"))
    .prop("name", "string", Some("the command's name"));
    let mut fo = SchemaObj::new(None, Some("typed field values"));
    let mut po = SchemaObj::new(None, Some("positions in mm, deg or slots"));
    let mut any_phys = false;
    for f in cmd.map_or(&[][..], |c| c.fields) {
        fo.raw(f.name, &ell_field_schema(f.kind));
        if f.kind == Kind::ThreadHw {
            fo.raw(
                "thread",
                &string_enum(["metric", "imperial"].into_iter(), None),
            );
            fo.prop("hw_release", "integer", Some("hardware release"));
        }
        if f.kind == Kind::Model {
            fo.prop(
                &format!("{}_name", f.name),
                "string",
                Some("the model as named: ELL14"),
            );
        }
        if f.kind == Kind::Firmware {
            fo.prop(
                &format!("{}_version", f.name),
                "string",
                Some("the release as major.minor: 1.5"),
            );
        }
        if f.kind == Kind::Raw {
            let mut p = SchemaObj::new(None, None);
            p.prop("period", "integer", Some("drive period"))
                .prop("current", "integer", Some("1866 per ampere"))
                .prop("hz", "number", Some("14740000 / period"))
                .prop("amps", "number", None);
            fo.raw(
                "curve_points",
                &array_of(&p.build(), Some("the current curve, point by point")),
            );
        }
        if f.kind == Kind::Position {
            let mut v = SchemaObj::new(None, None);
            v.prop("value", "number", None)
                .prop("unit", "string", Some("mm, deg or slot"));
            po.raw(f.name, &v.build());
            any_phys = true;
        }
    }
    o.raw("fields", &fo.build());
    if any_phys {
        o.raw("phys", &po.build());
    }
    let fields = cmd.map_or(&[][..], |c| c.fields);
    let coded = fields.iter().filter(|f| f.kind == Kind::Status);
    codes_schema(&mut o, coded.map(|f| f.name));
    let mut mo = SchemaObj::new(None, Some("what the bus knows of the module"));
    mo.prop(
        "first_addr",
        "integer",
        Some("the address it was first seen at"),
    )
    .prop("model", "string", None)
    .prop("serial", "string", None);
    o.raw("module", &mo.build())
        .prop(
            "pair",
            "integer",
            Some("record number of the command this reply answers"),
        )
        .prop("latency_ms", "number", Some("time since that command"))
        .prop(
            "interim",
            "boolean",
            Some("a busy status before the final reply"),
        )
        .raw("diag", &diag_array());
    o.build()
}

// ---------------------------------------------------------------------------------------------
// Reader
// ---------------------------------------------------------------------------------------------

/// Size of the file read buffer.
const BUF: usize = 64 * 1024;
/// Largest record (outside chunks: anything but chunks and attachments; inside chunks: any)
/// read into memory. Larger ones are skipped with a diagnostic.
const MAX_RECORD: usize = 64 * 1024 * 1024;
/// Largest schema/channel/metadata record considered while resynchronising.
const MAX_PEEK_RECORD: usize = 16 * 1024;

/// A buffered byte source that knows its file offset.
struct Src {
    r: Box<dyn Read>,
    buf: Box<[u8]>,
    pos: usize,
    len: usize,
    off: u64,
    eof: bool,
    /// CRC-32 of the bytes consumed so far, while the data section lasts.
    crc: Option<u32>,
}

impl Src {
    fn new(r: Box<dyn Read>) -> Self {
        Src {
            r,
            buf: vec![0; BUF].into_boxed_slice(),
            pos: 0,
            len: 0,
            off: 0,
            eof: false,
            crc: Some(!0),
        }
    }

    fn avail(&self) -> &[u8] {
        &self.buf[self.pos..self.len]
    }

    /// Make at least `n` (at most [`BUF`]) bytes available unless the file ends first; returns
    /// how many are.
    fn fill(&mut self, n: usize) -> io::Result<usize> {
        let n = n.min(BUF);
        if self.len - self.pos >= n || self.eof {
            return Ok(self.len - self.pos);
        }
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.len, 0);
            self.len -= self.pos;
            self.pos = 0;
        }
        while self.len < n {
            match self.r.read(&mut self.buf[self.len..]) {
                Ok(0) => {
                    self.eof = true;
                    break;
                }
                Ok(k) => self.len += k,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            }
        }
        Ok(self.len - self.pos)
    }

    fn consume(&mut self, n: usize) {
        let n = n.min(self.len - self.pos);
        if let Some(c) = &mut self.crc {
            *c = crc32_update(*c, &self.buf[self.pos..self.pos + n]);
        }
        self.pos += n;
        self.off += n as u64;
    }

    /// The CRC-32 of everything consumed so far; stops hashing.
    fn take_crc(&mut self) -> Option<u32> {
        self.crc.take().map(|c| !c)
    }

    /// Read up to `dst.len()` bytes; 0 at the end of the file.
    fn read_some(&mut self, dst: &mut [u8]) -> io::Result<usize> {
        if dst.is_empty() {
            return Ok(0);
        }
        if self.pos == self.len {
            if self.eof {
                return Ok(0);
            }
            if dst.len() >= BUF {
                loop {
                    match self.r.read(dst) {
                        Ok(0) => {
                            self.eof = true;
                            return Ok(0);
                        }
                        Ok(k) => {
                            if let Some(c) = &mut self.crc {
                                *c = crc32_update(*c, &dst[..k]);
                            }
                            self.off += k as u64;
                            return Ok(k);
                        }
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                        Err(e) => return Err(e),
                    }
                }
            }
            self.fill(1)?;
        }
        let k = dst.len().min(self.len - self.pos);
        dst[..k].copy_from_slice(&self.buf[self.pos..self.pos + k]);
        self.consume(k);
        Ok(k)
    }

    /// Fill `dst` completely unless the file ends; returns how many bytes were read.
    fn read_full(&mut self, dst: &mut [u8]) -> io::Result<usize> {
        let mut got = 0;
        while got < dst.len() {
            let k = self.read_some(&mut dst[got..])?;
            if k == 0 {
                break;
            }
            got += k;
        }
        Ok(got)
    }

    /// Skip `n` bytes; returns how many were skipped (fewer at the end of the file).
    fn skip(&mut self, n: u64) -> io::Result<u64> {
        let mut done = 0;
        while done < n {
            let a = self.fill(1)?;
            if a == 0 {
                break;
            }
            let k = (a as u64).min(n - done) as usize;
            self.consume(k);
            done += k as u64;
        }
        Ok(done)
    }
}

/// CRC-32 (IEEE, as MCAP uses), one table lookup per byte.
const CRC_TABLE: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

/// Continue a CRC-32 (pre- and post-inverted by the caller).
fn crc32_update(mut c: u32, b: &[u8]) -> u32 {
    for &x in b {
        c = CRC_TABLE[((c ^ x as u32) & 0xFF) as usize] ^ (c >> 8);
    }
    c
}

fn u16le(b: &[u8]) -> u16 {
    u16::from_le_bytes([b[0], b[1]])
}
fn u32le(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], b[3]])
}
fn u64le(b: &[u8]) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[..8]);
    u64::from_le_bytes(a)
}

fn op_name(o: u8) -> &'static str {
    match o {
        op::HEADER => "header",
        op::FOOTER => "footer",
        op::SCHEMA => "schema",
        op::CHANNEL => "channel",
        op::MESSAGE => "message",
        op::CHUNK => "chunk",
        op::MESSAGE_INDEX => "message index",
        op::CHUNK_INDEX => "chunk index",
        op::ATTACHMENT => "attachment",
        op::ATTACHMENT_INDEX => "attachment index",
        op::STATISTICS => "statistics",
        op::METADATA => "metadata",
        op::METADATA_INDEX => "metadata index",
        op::SUMMARY_OFFSET => "summary offset",
        op::DATA_END => "data end",
        0x80..=0xFF => "private",
        _ => "reserved",
    }
}

/// The fixed part of a chunk record (after opcode and length) is 40 bytes plus the compression
/// name.
const CHUNK_FIXED: usize = 40;

/// A chunk header read from `body`: (header length, compressed size, compression name).
fn chunk_header(body: &[u8]) -> Option<(usize, u64, &[u8])> {
    if body.len() < CHUNK_FIXED {
        return None;
    }
    let clen = u32le(&body[28..32]) as usize;
    if clen > 255 || body.len() < CHUNK_FIXED + clen {
        return None;
    }
    let comp = &body[32..32 + clen];
    let csize = u64le(&body[32 + clen..40 + clen]);
    Some((CHUNK_FIXED + clen, csize, comp))
}

/// A cursor over a record body that checks MCAP length prefixes against what is there.
struct Lens<'a> {
    b: &'a [u8],
    i: usize,
}

impl Lens<'_> {
    fn skip(&mut self, n: usize) -> Option<()> {
        self.i = self.i.checked_add(n).filter(|&e| e <= self.b.len())?;
        Some(())
    }
    fn u32(&mut self) -> Option<usize> {
        let v = u32le(self.b.get(self.i..self.i + 4)?) as usize;
        self.i += 4;
        Some(v)
    }
    fn string(&mut self) -> Option<()> {
        let n = self.u32()?;
        self.skip(n)
    }
    fn map(&mut self) -> Option<()> {
        let n = self.u32()?;
        let end = self.i.checked_add(n).filter(|&e| e <= self.b.len())?;
        while self.i < end {
            self.string()?;
            self.string()?;
        }
        (self.i == end).then_some(())
    }
}

/// Whether every length inside a record body fits in it, so parsing it cannot ask for more
/// memory than the body holds (the parser reserves a string's declared length up front).
fn lengths_ok(opcode: u8, body: &[u8]) -> bool {
    let mut c = Lens { b: body, i: 0 };
    let ok = match opcode {
        op::HEADER => c.string().and_then(|_| c.string()),
        op::CHANNEL => c
            .skip(4)
            .and_then(|_| c.string())
            .and_then(|_| c.string())
            .and_then(|_| c.map()),
        op::METADATA => c.string().and_then(|_| c.map()),
        op::SCHEMA => c
            .skip(2)
            .and_then(|_| c.string())
            .and_then(|_| c.string())
            .and_then(|_| c.string()),
        op::MESSAGE => c.skip(22),
        _ => None,
    };
    ok.is_some()
}

/// [`mcap::parse_record`] for the records we read, after [`lengths_ok`].
fn parse(opcode: u8, body: &[u8]) -> Result<mcap::records::Record<'_>, String> {
    if !lengths_ok(opcode, body) {
        return Err("a length inside the record runs past its end".into());
    }
    mcap::parse_record(opcode, body).map_err(|e| e.to_string())
}

/// Encodings whose messages are structured data, not serial bytes.
const STRUCTURED: &[&str] = &[
    "json",
    "protobuf",
    "ros1",
    "ros2",
    "cdr",
    "flatbuffer",
    "cbor",
    "msgpack",
];

#[derive(Debug, Clone, Copy)]
enum Chan {
    Skip,
    Raw {
        stream: u32,
        dir: Direction,
        timed: bool,
    },
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
enum StreamKey {
    Ours(u32),
    Foreign(String),
}

/// The direction a foreign topic names in its last path segment (`/port/tx`, `/serial_rx`),
/// and the topic without it.
fn topic_dir(topic: &str) -> (String, Direction) {
    let (base, last) = match topic.rfind('/') {
        Some(i) => (&topic[..i], &topic[i + 1..]),
        None => ("", topic),
    };
    if let Some(d) = Direction::parse(&last.to_ascii_lowercase()) {
        if !base.is_empty() {
            return (base.to_string(), d);
        }
    }
    if let Some(i) = last.rfind(['_', '-', '.']) {
        if let Some(d) = Direction::parse(&last[i + 1..].to_ascii_lowercase()) {
            return (format!("{base}/{}", &last[..i]), d);
        }
    }
    (topic.to_string(), Direction::Unknown)
}

struct InChunk {
    /// File offset of the chunk record.
    at: u64,
    lr: LinearReader,
    /// Compressed bytes still to feed.
    to_feed: u64,
    /// Bytes after the compressed records, up to the record's end.
    padding: u64,
    /// The file ended before the chunk did.
    cut: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum St {
    Magic,
    Records,
    EndMagic,
    Done,
}

#[derive(Debug, Clone, Copy)]
struct Ready {
    ts: Option<u64>,
    dir: Direction,
    stream: u32,
}

/// A streaming MCAP reader (see the module documentation).
pub struct McapReader {
    src: Src,
    file_len: Option<u64>,
    st: St,
    queue: VecDeque<Event<'static>>,
    ready: Option<Ready>,
    data: Vec<u8>,
    body: Vec<u8>,
    chunk: Option<InChunk>,
    channels: HashMap<u16, Chan>,
    bad_channels: HashSet<u16>,
    keys: HashMap<StreamKey, u32>,
    infos: HashMap<u32, StreamInfo>,
    announced: HashSet<u32>,
    used: HashSet<u32>,
    seen_footer: bool,
    seen_data_end: bool,
    library: Option<String>,
    /// Private opcodes reported.
    private: HashSet<u8>,
    /// The data section's CRC, once its end was reached.
    data_crc: Option<u32>,
    /// A problem was reported (the data CRC then adds nothing).
    damaged: bool,
}

impl McapReader {
    /// Read MCAP from `r` (a file, standard input, any stream).
    pub fn new<R: Read + 'static>(r: R) -> Self {
        McapReader {
            src: Src::new(Box::new(r)),
            file_len: None,
            st: St::Magic,
            queue: VecDeque::new(),
            ready: None,
            data: Vec::new(),
            body: Vec::new(),
            chunk: None,
            channels: HashMap::new(),
            bad_channels: HashSet::new(),
            keys: HashMap::new(),
            infos: HashMap::new(),
            announced: HashSet::new(),
            used: HashSet::new(),
            seen_footer: false,
            seen_data_end: false,
            library: None,
            private: HashSet::new(),
            data_crc: None,
            damaged: false,
        }
    }

    /// Open a file (its size lets lengths that run past the end be caught before reading).
    pub fn open(path: impl AsRef<std::path::Path>) -> io::Result<Self> {
        let f = std::fs::File::open(path)?;
        let len = f.metadata().ok().map(|m| m.len());
        let mut r = Self::new(f);
        r.file_len = len;
        Ok(r)
    }

    /// Tell the reader the file's total length, when known.
    pub fn with_file_len(mut self, len: u64) -> Self {
        self.file_len = Some(len);
        self
    }

    fn diag(&mut self, offset: u64, kind: &'static str, msg: String) {
        self.damaged = true;
        self.queue
            .push_back(Event::Diag(ReadDiag { offset, kind, msg }));
    }

    fn io_fail(&mut self, e: io::Error) {
        let at = self.src.off;
        self.diag(at, "io_error", e.to_string());
        self.st = St::Done;
        self.chunk = None;
    }

    /// One step of reading; may queue events or make a chunk ready.
    fn step(&mut self) {
        let r = match self.st {
            St::Magic => self.read_magic(),
            St::Records if self.chunk.is_some() => self.step_chunk(),
            St::Records => self.read_record(),
            St::EndMagic => self.read_end_magic(),
            St::Done => Ok(()),
        };
        if let Err(e) = r {
            self.io_fail(e);
        }
    }

    fn read_magic(&mut self) -> io::Result<()> {
        let n = self.src.fill(MAGIC.len())?;
        if n == 0 {
            self.diag(0, "bad_magic", "the file is empty, not MCAP".into());
            self.st = St::Done;
            return Ok(());
        }
        if self.src.avail().starts_with(MAGIC) {
            self.src.consume(MAGIC.len());
            self.st = St::Records;
            return Ok(());
        }
        let shown = hex_prefix(self.src.avail(), 8);
        self.diag(
            0,
            "bad_magic",
            format!("the file starts with {shown}, not the MCAP magic 89 4d 43 41 50 30 0d 0a; looking for records"),
        );
        self.st = St::Records;
        self.resync(false)
    }

    fn read_end_magic(&mut self) -> io::Result<()> {
        let at = self.src.off;
        let n = self.src.fill(MAGIC.len())?;
        if n >= MAGIC.len() && self.src.avail().starts_with(MAGIC) {
            self.src.consume(MAGIC.len());
            let more = self.src.fill(1)?;
            if more > 0 {
                let at = self.src.off;
                self.diag(
                    at,
                    "trailing_bytes",
                    "bytes after the MCAP end magic (ignored)".into(),
                );
            }
        } else {
            self.diag(
                at,
                "bad_end_magic",
                format!(
                    "the footer is not followed by the MCAP magic ({} byte(s) left)",
                    n
                ),
            );
        }
        self.st = St::Done;
        Ok(())
    }

    /// The file ended at a record boundary.
    fn at_eof(&mut self) {
        let at = self.src.off;
        if !self.seen_footer {
            let what = if self.seen_data_end {
                "after the data section, without summary footer"
            } else {
                "without data end, summary or footer"
            };
            self.diag(
                at,
                "missing_footer",
                format!("the file ends {what}: the recording was probably cut short; everything before was read"),
            );
        }
        self.st = St::Done;
    }

    fn read_record(&mut self) -> io::Result<()> {
        let at = self.src.off;
        let n = self.src.fill(9)?;
        if n == 0 {
            self.at_eof();
            return Ok(());
        }
        if n < 9 {
            self.diag(
                at,
                "truncated_record",
                format!("the file ends {n} byte(s) into a record header (9 bytes)"),
            );
            self.st = St::Done;
            return Ok(());
        }
        let b = self.src.avail();
        let opcode = b[0];
        let len = u64le(&b[1..9]);
        let name = op_name(opcode);
        if opcode == 0 || (0x10..0x80).contains(&opcode) {
            self.diag(
                at,
                "bad_record",
                format!("opcode 0x{opcode:02x} is not an MCAP record; looking for the next record"),
            );
            return self.resync(true);
        }
        let end = at.saturating_add(9).saturating_add(len);
        if let Some(fl) = self.file_len.filter(|&fl| end > fl) {
            self.diag(
                at,
                "truncated_record",
                format!(
                    "{name} record of {len} bytes runs past the end of the file ({} bytes left); looking for records inside it",
                    fl.saturating_sub(at + 9)
                ),
            );
            return self.resync(true);
        }
        if opcode == op::DATA_END {
            // The data section's CRC covers every byte before this record.
            self.data_crc = self.src.take_crc();
        }
        let big = len > MAX_RECORD as u64;
        match opcode {
            op::CHUNK => self.start_chunk(at, len),
            op::ATTACHMENT => {
                self.src.consume(9);
                self.skip_body(at, name, len)
            }
            0x80..=0xFF => {
                // Application-defined; legal, but a damaged opcode looks like one too.
                if self.private.insert(opcode) {
                    self.diag(
                        at,
                        "private_record",
                        format!("record with private opcode 0x{opcode:02x} ({len} bytes) skipped (reported once per opcode)"),
                    );
                }
                self.src.consume(9);
                self.skip_body(at, name, len)
            }
            _ if big => {
                self.diag(
                    at,
                    "bad_record",
                    format!("{name} record claims {len} bytes (limit {MAX_RECORD}); looking for the next record"),
                );
                self.resync(true)
            }
            op::MESSAGE_INDEX
            | op::CHUNK_INDEX
            | op::ATTACHMENT_INDEX
            | op::STATISTICS
            | op::METADATA_INDEX
            | op::SUMMARY_OFFSET
            | op::SCHEMA => {
                self.src.consume(9);
                self.skip_body(at, name, len)
            }
            _ => {
                self.src.consume(9);
                let mut body = std::mem::take(&mut self.body);
                body.resize(len as usize, 0);
                let got = self.src.read_full(&mut body)?;
                if got < body.len() {
                    self.body = body;
                    self.truncated(at, name, len, got as u64);
                    return Ok(());
                }
                self.record(at, opcode, &body);
                self.body = body;
                Ok(())
            }
        }
    }

    fn truncated(&mut self, at: u64, name: &str, len: u64, got: u64) {
        self.diag(
            at,
            "truncated_record",
            format!("{name} record of {len} bytes: the file ends after {got} of them"),
        );
        self.st = St::Done;
    }

    fn skip_body(&mut self, at: u64, name: &str, len: u64) -> io::Result<()> {
        let got = self.src.skip(len)?;
        if got < len {
            self.truncated(at, name, len, got);
        }
        Ok(())
    }

    /// A whole record outside chunks.
    fn record(&mut self, at: u64, opcode: u8, body: &[u8]) {
        match opcode {
            op::FOOTER => {
                self.seen_footer = true;
                self.st = St::EndMagic;
            }
            op::DATA_END => {
                self.seen_data_end = true;
                let saved = body.get(..4).map_or(0, u32le);
                if let Some(calc) = self.data_crc.filter(|&c| saved != 0 && c != saved) {
                    if !self.damaged {
                        self.diag(
                            at,
                            "bad_data_crc",
                            format!("the data section's CRC is {calc:08x}, the file says {saved:08x}: some bytes before offset {at} are damaged"),
                        );
                    }
                }
            }
            op::MESSAGE | op::CHANNEL | op::METADATA | op::HEADER => match parse(opcode, body) {
                Ok(r) => self.parsed(at, r),
                Err(e) => self.diag(
                    at,
                    "bad_record",
                    format!("{} record does not parse: {e}", op_name(opcode)),
                ),
            },
            _ => {}
        }
    }

    /// A parsed record (outside or inside a chunk; `at` = the record's or chunk's offset).
    fn parsed(&mut self, at: u64, r: mcap::records::Record<'_>) {
        use mcap::records::Record;
        match r {
            Record::Header(h) if !h.library.is_empty() => {
                self.library = Some(h.library);
            }
            Record::Channel(c) => self.channel(c),
            Record::Metadata(m) if m.name == "aptscope.stream" => {
                let Some(id) = m.metadata.get("id").and_then(|s| s.parse::<u32>().ok()) else {
                    return;
                };
                let sid = self.stream_id(StreamKey::Ours(id));
                let info = StreamInfo {
                    id: sid,
                    name: m.metadata.get("name").cloned().unwrap_or_default(),
                    settings: m.metadata.get("settings").cloned(),
                };
                self.infos.insert(sid, info);
                self.announce(sid);
            }
            Record::Message { header, data } => self.message(at, header, &data),
            _ => {}
        }
    }

    fn stream_id(&mut self, key: StreamKey) -> u32 {
        if let Some(&id) = self.keys.get(&key) {
            return id;
        }
        let want = match key {
            StreamKey::Ours(id) => id,
            StreamKey::Foreign(_) => 0,
        };
        let mut id = want;
        while self.used.contains(&id) {
            id = id.wrapping_add(1);
        }
        self.used.insert(id);
        self.keys.insert(key, id);
        id
    }

    fn announce(&mut self, id: u32) {
        if self.announced.insert(id) {
            let info = self.infos.get(&id).cloned().unwrap_or(StreamInfo {
                id,
                name: String::new(),
                settings: None,
            });
            self.queue.push_back(Event::Stream(info));
        }
    }

    fn channel(&mut self, c: mcap::records::Channel) {
        let enc = c.message_encoding.to_ascii_lowercase();
        let decoded =
            (c.topic.starts_with("/apt/") || c.topic.starts_with("/ell/")) && enc == "json";
        if decoded || STRUCTURED.contains(&enc.as_str()) {
            self.channels.insert(c.id, Chan::Skip);
            return;
        }
        let md = &c.metadata;
        let ours = c
            .topic
            .starts_with("/serial/")
            .then(|| md.get("stream").and_then(|s| s.parse::<u32>().ok()))
            .flatten();
        let (key, dir, timed, name, settings) = match ours {
            Some(id) => {
                let dir = md
                    .get("direction")
                    .and_then(|d| Direction::parse(d))
                    .unwrap_or_else(|| topic_dir(&c.topic).1);
                let timed = md.get("time").map(String::as_str) != Some("missing");
                (
                    StreamKey::Ours(id),
                    dir,
                    timed,
                    md.get("name").cloned().unwrap_or_default(),
                    md.get("settings").cloned(),
                )
            }
            None => {
                let (base, mut dir) = topic_dir(&c.topic);
                if let Some(d) = md.get("direction").and_then(|d| Direction::parse(d)) {
                    dir = d;
                }
                (StreamKey::Foreign(base.clone()), dir, true, base, None)
            }
        };
        let stream = self.stream_id(key);
        self.infos.entry(stream).or_insert(StreamInfo {
            id: stream,
            name,
            settings,
        });
        self.channels.insert(c.id, Chan::Raw { stream, dir, timed });
    }

    fn message(&mut self, at: u64, h: MessageHeader, data: &[u8]) {
        match self.channels.get(&h.channel_id).copied() {
            None => {
                if self.bad_channels.insert(h.channel_id) {
                    self.diag(
                        at,
                        "unknown_channel",
                        format!(
                            "message on channel {} which no channel record defined (skipped)",
                            h.channel_id
                        ),
                    );
                }
            }
            Some(Chan::Skip) => {}
            Some(Chan::Raw { stream, dir, timed }) => {
                self.announce(stream);
                self.data.clear();
                self.data.extend_from_slice(data);
                self.ready = Some(Ready {
                    ts: timed.then_some(h.log_time),
                    dir,
                    stream,
                });
            }
        }
    }

    fn start_chunk(&mut self, at: u64, len: u64) -> io::Result<()> {
        // The fixed header and the compression name sit in the read buffer.
        let n = self.src.fill(9 + CHUNK_FIXED)?;
        let clen = if n >= 9 + CHUNK_FIXED {
            u32le(&self.src.avail()[9 + 28..9 + 32]) as usize
        } else {
            0
        };
        let want = 9 + CHUNK_FIXED + clen.min(255);
        let n = self.src.fill(want)?;
        if n < want && (want as u64) <= 9 + len {
            let got = n.saturating_sub(9) as u64;
            self.truncated(at, "chunk", len, got);
            return Ok(());
        }
        let hdr = chunk_header(&self.src.avail()[9..n]);
        let Some((hlen, csize, _)) = hdr.filter(|h| h.0 as u64 <= len && h.1 <= len - h.0 as u64)
        else {
            self.diag(
                at,
                "bad_chunk",
                "chunk header is inconsistent with the record length; looking for the next record"
                    .into(),
            );
            return self.resync(true);
        };
        let mut lr = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_skip_start_magic(true)
                .with_skip_end_magic(true)
                .with_validate_chunk_crcs(true)
                .with_record_length_limit(MAX_RECORD),
        );
        // The reader sees a chunk record without the padding after its records, so records
        // that overrun the compressed data cannot reach into it.
        let buf = lr.insert(9 + hlen);
        buf[0] = op::CHUNK;
        buf[1..9].copy_from_slice(&(hlen as u64 + csize).to_le_bytes());
        buf[9..].copy_from_slice(&self.src.avail()[9..9 + hlen]);
        lr.notify_read(9 + hlen);
        self.src.consume(9 + hlen);
        self.chunk = Some(InChunk {
            at,
            lr,
            to_feed: csize,
            padding: len - hlen as u64 - csize,
            cut: false,
        });
        Ok(())
    }

    fn step_chunk(&mut self) -> io::Result<()> {
        let Some(mut ch) = self.chunk.take() else {
            return Ok(());
        };
        let at = ch.at;
        match ch.lr.next_event() {
            None => {
                // The chunk is done (CRC checked): skip what follows its records.
                let got = self.src.skip(ch.padding)?;
                if got < ch.padding {
                    self.truncated(at, "chunk", ch.padding, got);
                }
                return Ok(());
            }
            Some(Ok(LinearReadEvent::ReadRequest(need))) => {
                if ch.to_feed == 0 || ch.cut {
                    ch.lr.notify_read(0);
                } else {
                    let want = (need.max(1) as u64).min(ch.to_feed).min(BUF as u64) as usize;
                    let buf = ch.lr.insert(want);
                    let got = self.src.read_some(buf)?;
                    if got == 0 {
                        ch.cut = true;
                    }
                    ch.lr.notify_read(got);
                    ch.to_feed -= got as u64;
                }
            }
            Some(Ok(LinearReadEvent::Record { data, opcode })) => match opcode {
                op::MESSAGE | op::CHANNEL => match parse(opcode, data) {
                    Ok(r) => self.parsed(at, r),
                    Err(e) => self.diag(
                        at,
                        "bad_record",
                        format!(
                            "{} record in the chunk does not parse: {e}",
                            op_name(opcode)
                        ),
                    ),
                },
                _ => {}
            },
            Some(Err(e)) => {
                if ch.cut {
                    let end = self.src.off;
                    self.diag(
                        at,
                        "truncated_record",
                        format!("the file ends at offset {end}, inside this chunk; its messages up to there were read"),
                    );
                    self.st = St::Done;
                    return Ok(());
                }
                let (kind, msg) = match e {
                    McapError::BadChunkCrc { saved, calculated } => (
                        "bad_chunk_crc",
                        format!("chunk CRC is {calculated:08x}, the chunk says {saved:08x}: its messages (read above) may be damaged"),
                    ),
                    McapError::UnsupportedCompression(c) => (
                        "unsupported_compression",
                        format!("chunk compressed with {c:?}, which this reader lacks: skipped"),
                    ),
                    e => ("bad_chunk", format!("chunk cannot be read further: {e}")),
                };
                self.diag(at, kind, msg);
                let rest = ch.to_feed + ch.padding;
                let got = self.src.skip(rest)?;
                if got < rest {
                    self.truncated(at, "chunk", rest, got);
                }
                return Ok(());
            }
        }
        self.chunk = Some(ch);
        Ok(())
    }

    /// Whether a record plausibly starts at the head of `b` (file offset `at`).
    fn plausible(&self, b: &[u8], at: u64) -> bool {
        if b.len() < 9 {
            return false;
        }
        let opcode = b[0];
        let len = u64le(&b[1..9]);
        if let Some(fl) = self.file_len {
            if at.saturating_add(9).saturating_add(len) > fl {
                return false;
            }
        }
        let body = &b[9..];
        match opcode {
            op::CHUNK => match chunk_header(body) {
                Some((hlen, csize, comp)) => {
                    let usize_ = u64le(&body[16..24]);
                    let start = u64le(&body[0..8]);
                    let end = u64le(&body[8..16]);
                    start <= end
                        && matches!(comp, b"" | b"lz4" | b"zstd")
                        && (!comp.is_empty() || usize_ == csize)
                        && (hlen as u64).checked_add(csize) == Some(len)
                }
                None => false,
            },
            op::MESSAGE => {
                (22..=MAX_RECORD as u64).contains(&len)
                    && body.len() >= 2
                    && self.channels.contains_key(&u16le(body))
            }
            op::MESSAGE_INDEX => {
                len >= 6 && body.len() >= 6 && self.channels.contains_key(&u16le(body)) && {
                    let r = u32le(&body[2..6]) as u64;
                    r + 6 == len && r.is_multiple_of(16)
                }
            }
            op::DATA_END => len == 4,
            op::FOOTER => len == 20,
            op::CHANNEL | op::SCHEMA | op::METADATA | op::HEADER => {
                (len as usize) <= body.len() && parse(opcode, &body[..len as usize]).is_ok()
            }
            _ => false,
        }
    }

    /// Look for the next plausible record from the current offset (`skip_first`: not at the
    /// current offset itself). Reports the bytes skipped.
    fn resync(&mut self, skip_first: bool) -> io::Result<()> {
        let start = self.src.off;
        if skip_first {
            self.src.consume(1);
        }
        loop {
            let n = self.src.fill(64)?;
            if n == 0 {
                let skipped = self.src.off - start;
                self.diag(
                    start,
                    "skipped_bytes",
                    format!(
                        "{skipped} byte(s) skipped: no MCAP record found up to the end of the file"
                    ),
                );
                self.at_eof();
                return Ok(());
            }
            let b = self.src.avail();
            let opcode = b[0];
            let interesting = matches!(
                opcode,
                op::CHUNK
                    | op::MESSAGE
                    | op::MESSAGE_INDEX
                    | op::DATA_END
                    | op::FOOTER
                    | op::CHANNEL
                    | op::SCHEMA
                    | op::METADATA
                    | op::HEADER
            );
            if interesting && n >= 9 {
                let len = u64le(&b[1..9]);
                let want = match opcode {
                    op::CHUNK => 9 + CHUNK_FIXED + 8,
                    op::CHANNEL | op::SCHEMA | op::METADATA | op::HEADER
                        if len <= MAX_PEEK_RECORD as u64 =>
                    {
                        9 + len as usize
                    }
                    _ => 9,
                };
                let n = self.src.fill(want)?;
                let at = self.src.off;
                if self.plausible(&self.src.avail()[..n], at) {
                    if at > start {
                        self.diag(
                            start,
                            "skipped_bytes",
                            format!(
                                "{} byte(s) skipped up to the next record at offset {at}",
                                at - start
                            ),
                        );
                    }
                    return Ok(());
                }
            }
            self.src.consume(1);
        }
    }
}

fn hex_prefix(b: &[u8], n: usize) -> String {
    let mut s = String::new();
    for (i, x) in b.iter().take(n).enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{x:02x}");
    }
    s
}

impl Reader for McapReader {
    fn next_event(&mut self) -> Option<Event<'_>> {
        loop {
            if let Some(e) = self.queue.pop_front() {
                return Some(e);
            }
            if let Some(r) = self.ready.take() {
                return Some(Event::Chunk(Chunk {
                    ts_ns: r.ts,
                    dir: r.dir,
                    stream: r.stream,
                    bytes: &self.data,
                }));
            }
            if self.st == St::Done {
                return None;
            }
            self.step();
        }
    }

    fn format(&self) -> String {
        match &self.library {
            Some(l) => format!("mcap ({l})"),
            None => "mcap".to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::OwnedChunk;
    use proptest::prelude::*;
    use std::io::Cursor;

    #[test]
    fn push_uint_matches_display() {
        let mut xs = vec![0, 1, 9, 10, 11, 99, 100, 101, 999, 1000, 65_535, u64::MAX];
        xs.extend((0..64).map(|b| 1u64 << b));
        xs.extend((1..20).map(|e| 10u64.pow(e) - 1));
        xs.push(1_700_000_000_123_456_789);
        for x in xs {
            let mut s = String::from("x");
            push_uint(&mut s, x);
            assert_eq!(s, format!("x{x}"));
        }
    }

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
        let opts = WriteOptions::new().compression(None).chunk_size(Some(4096));
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

    fn uncompressed(chunk_size: Option<u64>) -> WriteOptions {
        WriteOptions::new().compression(None).chunk_size(chunk_size)
    }

    fn write(
        streams: &[StreamInfo],
        chunks: &[OwnedChunk],
        proto: Option<Proto>,
        opts: WriteOptions,
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
                0 => WriteOptions::new(),
                1 => uncompressed(Some(200)),
                2 => uncompressed(None).use_chunks(false),
                _ => WriteOptions::new()
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
                WriteOptions::new().chunk_size(Some(400))
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
        let mut bytes = write(
            &stream_infos(2),
            &some_chunks(10),
            None,
            WriteOptions::new(),
        );
        // A stream's name, in an `aptscope.stream` metadata record.
        let at = bytes
            .windows(12)
            .position(|w| w == b"/dev/ttyUSB1")
            .unwrap();
        bytes[at + 5] = b'X';
        let got = read(&bytes);
        assert_eq!(got.streams[1].name, "/dev/XtyUSB1");
        assert_eq!(got.diags.len(), 1, "{:?}", got.diags);
        assert_eq!(got.diags[0].kind, "bad_data_crc");
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
        let bytes = write(&[], &[], None, WriteOptions::new());
        let got = read(&bytes);
        assert!(got.diags.is_empty(), "{:?}", got.diags);
        assert!(got.chunks.is_empty() && got.streams.is_empty());
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
            if !(t.starts_with("/apt/") || t.starts_with("/ell/")) {
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
        let bytes = write(&stream_infos(1), &chunks, None, WriteOptions::new());
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
            late_diag_schema(),
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
        let bytes = write(&stream_infos(1), &chunks, None, WriteOptions::new());
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
            WriteOptions::new(),
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
        assert!(chunk_recs.len() > 4);
        // Cut in the middle of the fourth chunk.
        let (at, _, len) = *chunk_recs[3];
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
                .find(|d| d.kind == "truncated_record")
                .unwrap_or_else(|| panic!("{:?}", got.diags));
            assert_eq!(d.offset, at as u64, "{:?}", got.diags);
            // Every chunk of the first three MCAP chunks came out, and then some.
            let before = read(&bytes[..at]).chunks.len();
            assert!(before > 0);
            assert!(got.chunks.len() > before, "{} {}", got.chunks.len(), before);
            assert_eq!(&got.chunks[..], &chunks[..got.chunks.len()]);
        }
        // Cut at a record boundary: everything before, and the missing footer is reported.
        let got = read(&bytes[..at]);
        let d = got.diags.last().unwrap();
        assert_eq!((d.kind, d.offset), ("missing_footer", at as u64));
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
        assert_eq!(got.diags[0].kind, "bad_chunk_crc");
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
        assert_eq!(got.diags[0].kind, "bad_record");
        assert_eq!(got.diags[0].offset, at as u64);
        assert_eq!(got.diags[1].kind, "skipped_bytes");
        assert!(
            got.diags[1].msg.starts_with("100 byte(s)"),
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
        let mut bytes = write(&stream_infos(2), &chunks, None, WriteOptions::new());
        bytes[1] = b'X';
        let got = read(&bytes);
        assert_eq!(got.diags[0].kind, "bad_magic");
        assert_eq!(got.diags[0].offset, 0);
        assert_eq!(got.chunks, chunks, "{:?}", got.diags);
        let got = read(b"hello world, this is not mcap at all");
        assert_eq!(got.diags[0].kind, "bad_magic");
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
        assert_eq!(got.diags[0].kind, "bad_record", "{:?}", got.diags);
        assert_eq!(got.diags[0].offset, 8);
        assert_eq!(got.diags[1].kind, "missing_footer");
        assert!(!lengths_ok(op::METADATA, &[5, 0, 0, 0, b'a']));
        assert!(lengths_ok(op::METADATA, &[1, 0, 0, 0, b'a', 0, 0, 0, 0]));
    }

    /// Reads a large file and reports the peak memory (run by hand with --ignored).
    #[test]
    #[ignore]
    fn large_file_reads_in_bounded_memory() {
        let path = std::env::temp_dir().join("aptscope-mcap-large.mcap");
        {
            let f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
            let mut w =
                mcap::Writer::with_options(f, WriteOptions::new().compression(None)).unwrap();
            let mut m = BTreeMap::new();
            m.insert("stream".to_string(), "0".to_string());
            let ch = w.add_channel(0, "/serial/0/d2h", RAW_ENCODING, &m).unwrap();
            let data: Vec<u8> = (0..4096u32)
                .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
                .collect();
            for i in 0..100_000u32 {
                w.write_to_known_channel(
                    &MessageHeader {
                        channel_id: ch,
                        sequence: i,
                        log_time: i as u64,
                        publish_time: i as u64,
                    },
                    &data,
                )
                .unwrap();
            }
            w.finish().unwrap();
        }
        let size = std::fs::metadata(&path).unwrap().len();
        let mut r = McapReader::open(&path).unwrap();
        let (mut n, mut bytes) = (0u64, 0u64);
        while let Some(e) = r.next_event() {
            if let Event::Chunk(c) = e {
                n += 1;
                bytes += c.bytes.len() as u64;
            }
        }
        let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
        let hwm = status
            .lines()
            .find(|l| l.starts_with("VmHWM"))
            .unwrap_or("");
        eprintln!("file {size} bytes, {n} chunks, {bytes} bytes; {hwm}");
        let _ = std::fs::remove_file(&path);
        assert_eq!(n, 100_000);
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
        let bytes = write(&streams, &chunks, None, WriteOptions::new());
        let got = read(&bytes);
        assert_eq!(got.streams, streams);
        assert_eq!(got.chunks, chunks);
    }
}
