//! The MCAP writer: raw channels, and decoded channels fed by the one decode chain
//! ([`record::Decoder`]) and rendered by the one renderer ([`Renderer`]).

use super::schema::{self, Schema};
use super::sink::{McapOptions, Sink};
use super::{failed_err, finished_err, RAW_ENCODING};
use crate::model::{Chunk, Direction, ReadDiag, StreamInfo, Writer};
use ::mcap::records::Metadata;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Format, Renderer};
use aptscope_dissector::record::{self, Record};
use std::collections::{BTreeMap, HashMap};
use std::hash::BuildHasherDefault;
use std::io::{self, Write};

/// An MCAP capture writer: raw lossless channels plus decoded JSON channels (see the module
/// documentation for the layout).
///
/// The calling thread frames, decodes and renders the records and appends them to the open
/// chunk; sealed chunks are compressed on a pool of threads and written, in order, by an output
/// thread (the `sink` module says why the container is written here and not by
/// [`mcap::Writer`]). An I/O error of the output thread is returned by a later
/// [`chunk`](Writer::chunk) or by [`finish`](Writer::finish) (as with a `BufWriter`); dropping
/// the writer without `finish` still closes the file, as [`mcap::Writer`] does. The writer
/// need not seek.
pub struct McapWriter<W: Write + Send + 'static> {
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
    dec: Decoded,
}

impl<W: Write + Send + 'static> McapWriter<W> {
    /// A writer with the default [`McapOptions`] (zstd-compressed chunks). `proto` chooses
    /// the decoder of the decoded channels; `None` detects it as `decode` does (the busiest
    /// lane of the first 4 KiB).
    pub fn new(w: W, proto: Option<Proto>) -> io::Result<Self> {
        Self::with_options(w, proto, McapOptions::new())
    }

    /// A writer with the given options (compression, chunk size, threads, …).
    pub fn with_options(w: W, proto: Option<Proto>, opts: McapOptions) -> io::Result<Self> {
        let (mut sink, thread) = Sink::start(w, opts)?;
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
        sink.metadata(Metadata {
            name: "aptscope".into(),
            metadata: meta,
        })?;
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
            dec: Decoded::new(proto),
        })
    }

    /// The underlying writer, once [`finish`](Writer::finish) has run.
    pub fn into_inner(mut self) -> Option<W> {
        self.inner.take()
    }

    /// Report a problem of the input capture (a damaged record of the file being converted):
    /// it goes on `/aptscope/input` as `decode --json` writes it, in its place among the
    /// records.
    pub fn file_diag(&mut self, offset: u64, kind: &str, msg: &str) -> io::Result<()> {
        self.with_sink(|w, dec| dec.file_diag(offset, kind, msg, w))
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
        f: impl FnOnce(&mut Sink, &mut Decoded) -> io::Result<T>,
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

impl<W: Write + Send + 'static> Drop for McapWriter<W> {
    fn drop(&mut self) {
        // Close the file with what was written so far (as dropping an `mcap::Writer` does).
        if let Some(sink) = self.sink.take() {
            let _ = sink.finish();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl<W: Write + Send + 'static> Writer for McapWriter<W> {
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
        self.with_sink(|w, dec| {
            w.metadata(Metadata {
                name: "aptscope.stream".into(),
                metadata: meta,
            })?;
            dec.stream(s, w)
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

    fn diag(&mut self, d: &ReadDiag) -> io::Result<()> {
        self.file_diag(d.offset, d.kind(), &d.msg())
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
            if let Some(p) = dec.dec.proto() {
                let mut m = BTreeMap::new();
                m.insert("proto".to_string(), p.code().to_string());
                m.insert("how".to_string(), dec.out.how.to_string());
                if let Some((a, e)) = dec.out.scores {
                    m.insert("apt".to_string(), format!("{a:.3}"));
                    m.insert("ell".to_string(), format!("{e:.3}"));
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
            Ok(())
        })?;
        // The last chunk and the summary; the output thread then hands the writer back.
        if let Some(sink) = self.sink.take() {
            if let Err(e) = sink.finish() {
                return Err(self.stop(e));
            }
        }
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

// --- decoded channels ------------------------------------------------------------------------

/// The decoded channels: the records of the one decode chain, each written as the line
/// `decode --json` writes for it, on the channel of its message (or kind).
struct Decoded {
    dec: record::Decoder,
    out: Out,
}

/// Where the records go (apart from the decoder, so the decoder's callback can borrow it).
struct Out {
    r: Renderer,
    /// Channel ids by [`TopicKey`]: the per-record lookup, without building or hashing the
    /// topic string.
    ids: HashMap<TopicKey, u16, FastHash>,
    /// Channel ids by topic (two keys may share a topic).
    topics: HashMap<String, u16>,
    /// How the protocol was chosen, and the detector's scores (for `aptscope.decode`).
    how: &'static str,
    scores: Option<(f64, f64)>,
    /// The first and the latest capture time fed: the `log_time` of records that have none
    /// of their own (detection; stream, units, input and no-reply records).
    first: Option<u64>,
    now: u64,
}

impl Decoded {
    fn new(proto: Option<Proto>) -> Self {
        Decoded {
            dec: record::Decoder::new(proto),
            out: Out {
                r: Renderer::new(Format::Json),
                ids: HashMap::default(),
                topics: HashMap::new(),
                how: "given",
                scores: None,
                first: None,
                now: 0,
            },
        }
    }

    fn chunk(&mut self, c: &Chunk<'_>, w: &mut Sink) -> io::Result<()> {
        if let Some(t) = c.ts_ns {
            self.out.first.get_or_insert(t);
            self.out.now = t;
        }
        let out = &mut self.out;
        self.dec
            .push(c.ctx(), c.bytes, &mut |rec: &Record<'_>| out.write(w, rec))
    }

    fn stream(&mut self, s: &StreamInfo, w: &mut Sink) -> io::Result<()> {
        let out = &mut self.out;
        self.dec
            .stream_info(s.id, &s.name, s.settings.as_deref(), &mut |rec: &Record<
                '_,
            >| {
                out.write(w, rec)
            })
    }

    fn file_diag(&mut self, offset: u64, kind: &str, msg: &str, w: &mut Sink) -> io::Result<()> {
        let out = &mut self.out;
        self.dec
            .file_diag(offset, kind, msg, &mut |rec: &Record<'_>| out.write(w, rec))
    }

    fn finish(&mut self, w: &mut Sink) -> io::Result<()> {
        let out = &mut self.out;
        self.dec.finish(&mut |rec: &Record<'_>| out.write(w, rec))
    }
}

impl Out {
    /// Write one record on its channel (made, with its schema, on the topic's first use).
    fn write(&mut self, w: &mut Sink, rec: &Record<'_>) -> io::Result<()> {
        let (key, seq, log_time) = match rec {
            Record::Apt(a) => (
                a.frame
                    .msg
                    .map_or(TopicKey::AptUnknown, |m| TopicKey::of(m.name)),
                a.meta.n,
                a.meta.ts_ns.unwrap_or(0),
            ),
            Record::Ell(e) => (
                e.frame
                    .cmd
                    .map_or(TopicKey::EllUnknown, |c| TopicKey::of(c.code)),
                e.meta.n,
                e.meta.ts_ns.unwrap_or(0),
            ),
            Record::Garbage(g) => (
                match g.proto {
                    Proto::Apt => TopicKey::AptGarbage,
                    Proto::Elliptec => TopicKey::EllGarbage,
                },
                g.meta.n,
                g.meta.ts_ns.unwrap_or(0),
            ),
            Record::NoReply(x) => (
                match x.proto {
                    Proto::Apt => TopicKey::AptDiag,
                    Proto::Elliptec => TopicKey::EllDiag,
                },
                x.n,
                self.now,
            ),
            Record::Units(_) => (TopicKey::Units, 0, self.now),
            Record::Detect { detection, .. } => {
                self.how = if detection.proto.is_some() {
                    "detected"
                } else {
                    "best guess (mixed or unknown stream)"
                };
                self.scores = Some((detection.apt, detection.elliptec));
                (TopicKey::Detect, 0, self.first.unwrap_or(0))
            }
            Record::Stream { .. } => (TopicKey::Stream, 0, self.now),
            Record::Input(_) | Record::FileDiag { .. } => (TopicKey::Input, 0, self.now),
        };
        let id = match self.ids.get(&key) {
            Some(&id) => id,
            None => {
                let Schema { topic, name, body } = schema::of(rec);
                let id = match self.topics.get(&topic) {
                    Some(&id) => id,
                    None => {
                        let sid = w.add_schema(name, body)?;
                        let id = w.add_channel(sid, topic.clone(), "json", BTreeMap::new())?;
                        self.topics.insert(topic, id);
                        id
                    }
                };
                self.ids.insert(key, id);
                id
            }
        };
        let line = self.r.line(rec);
        w.message(id, seq as u32, log_time, line.as_bytes())
    }
}

/// What a decoded record's channel is known by on the hot path: a fixed topic, or the address
/// and length of the `&'static` name of the message (APT) or command (Elliptec) whose topic it
/// is. Two keys may map to one topic (see [`Out::write`]); one key never maps to two.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum TopicKey {
    Named(usize, usize),
    AptUnknown,
    AptGarbage,
    AptDiag,
    EllUnknown,
    EllGarbage,
    EllDiag,
    Units,
    Detect,
    Stream,
    Input,
}

impl TopicKey {
    /// The key of a message's or command's name (a `&'static` table entry: its address).
    fn of(name: &'static str) -> Self {
        TopicKey::Named(name.as_ptr() as usize, name.len())
    }
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
