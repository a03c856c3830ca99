//! The MCAP container: records, chunks, message indexes and the summary, written here rather
//! than through [`mcap::Writer`] for speed.
//!
//! A decoded capture is about 37 bytes of JSON per byte of payload, so nearly all the writer's
//! work is per message and per compressed byte. `mcap::Writer` streams every record through a
//! zstd stream in five or six small writes (each a `ZSTD_compressStream2` call and a CRC
//! update): that bookkeeping cost about a quarter of its thread. Here the calling thread appends
//! each record to the open chunk's buffer (a header and one copy), a sealed chunk is compressed
//! in one call with a reused context on a pool of threads, and an output thread writes the
//! chunks in order with their message indexes, then the summary. No seek: a chunk's header is
//! known before it is written.
//!
//! The file has the layout `mcap::Writer` gives with its default options (header; schemas and
//! channels inside the chunks; metadata between them; message indexes after each chunk; data
//! end with the data CRC; summary with schemas, channels, statistics, chunk and metadata
//! indexes and summary offsets; footer with the summary CRC), so every reader finds the same
//! records.

use super::MAGIC;
use ::mcap::records::{op, Metadata};
use ::mcap::Compression;
use std::collections::{BTreeMap, HashMap};
use std::io::{self, Write};
use std::sync::mpsc::{self, Receiver, SyncSender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// How an [`McapWriter`](super::McapWriter) writes its file.
#[derive(Clone, Debug)]
pub struct McapOptions {
    compression: Option<Compression>,
    level: i32,
    chunk_size: Option<u64>,
    use_chunks: bool,
    threads: usize,
    library: String,
}

impl Default for McapOptions {
    fn default() -> Self {
        McapOptions {
            compression: Some(Compression::Zstd),
            level: DEFAULT_ZSTD_LEVEL,
            chunk_size: Some(DEFAULT_CHUNK_SIZE),
            use_chunks: true,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get().min(4)),
            library: format!("aptscope {}", env!("CARGO_PKG_VERSION")),
        }
    }
}

/// zstd level of the default options: 13–15 % fewer instructions than zstd's default (3), and
/// on [`DEFAULT_CHUNK_SIZE`] chunks the file is about as small (+0.3 %) as level 3 made it on
/// the 1 MiB chunks written before (docs/performance.md has the figures).
pub const DEFAULT_ZSTD_LEVEL: i32 = 1;
/// Uncompressed size after which a chunk is closed, by default. The writer holds a few chunks
/// at once (the open one, one queued, one per compression thread, and the compressed ones
/// waiting for the output thread), so about 30 MiB with 2 threads.
pub const DEFAULT_CHUNK_SIZE: u64 = 4 << 20;

impl McapOptions {
    /// zstd, level [`DEFAULT_ZSTD_LEVEL`], chunks of [`DEFAULT_CHUNK_SIZE`], one compression
    /// thread per core (at most 4).
    pub fn new() -> Self {
        Self::default()
    }
    /// Chunk compression (`None`: stored).
    pub fn compression(mut self, c: Option<Compression>) -> Self {
        self.compression = c;
        self
    }
    /// Compression level: zstd's (0 is zstd's default, 3; negative levels are faster), or lz4's.
    pub fn compression_level(mut self, level: i32) -> Self {
        self.level = level;
        self
    }
    /// Close a chunk once it holds more than this many uncompressed bytes (`None`: one chunk
    /// for everything between metadata records).
    pub fn chunk_size(mut self, size: Option<u64>) -> Self {
        self.chunk_size = size;
        self
    }
    /// `false`: no chunks (nor compression, nor message indexes); records go straight into the
    /// data section.
    pub fn use_chunks(mut self, yes: bool) -> Self {
        self.use_chunks = yes;
        self
    }
    /// Threads that compress chunks (at least 1); the chunks still come out in order.
    pub fn compression_threads(mut self, n: usize) -> Self {
        self.threads = n.max(1);
        self
    }
    /// The header's `library` string.
    pub fn library(mut self, s: impl Into<String>) -> Self {
        self.library = s.into();
        self
    }
}

// --- record encoding ---------------------------------------------------------------------

fn put_u16(b: &mut Vec<u8>, x: u16) {
    b.extend_from_slice(&x.to_le_bytes());
}
fn put_u32(b: &mut Vec<u8>, x: u32) {
    b.extend_from_slice(&x.to_le_bytes());
}
fn put_u64(b: &mut Vec<u8>, x: u64) {
    b.extend_from_slice(&x.to_le_bytes());
}
fn put_str(b: &mut Vec<u8>, s: &str) {
    put_u32(b, s.len() as u32);
    b.extend_from_slice(s.as_bytes());
}
/// A length-prefixed field whose length (u32) is patched in once `f` wrote it.
fn put_prefixed(b: &mut Vec<u8>, f: impl FnOnce(&mut Vec<u8>)) {
    let at = b.len();
    put_u32(b, 0);
    f(b);
    let len = (b.len() - at - 4) as u32;
    b[at..at + 4].copy_from_slice(&len.to_le_bytes());
}
fn put_map(b: &mut Vec<u8>, m: &BTreeMap<String, String>) {
    put_prefixed(b, |b| {
        for (k, v) in m {
            put_str(b, k);
            put_str(b, v);
        }
    });
}
/// A record: opcode, length (u64, patched in), body.
fn put_record(b: &mut Vec<u8>, opcode: u8, f: impl FnOnce(&mut Vec<u8>)) {
    b.push(opcode);
    let at = b.len();
    put_u64(b, 0);
    f(b);
    let len = (b.len() - at - 8) as u64;
    b[at..at + 8].copy_from_slice(&len.to_le_bytes());
}

/// Compression name in chunk records.
fn compression_name(c: Option<Compression>) -> &'static str {
    match c {
        Some(Compression::Zstd) => "zstd",
        Some(Compression::Lz4) => "lz4",
        None => "",
    }
}

/// A channel, kept for the summary.
struct ChannelRec {
    id: u16,
    schema: u16,
    topic: String,
    encoding: &'static str,
    meta: BTreeMap<String, String>,
}

/// The open chunk.
#[derive(Default)]
struct Open {
    data: Vec<u8>,
    /// Message index entries (log time, offset in `data`) by channel id.
    index: Vec<Vec<(u64, u64)>>,
    /// Channels with entries in `index`, in first-use order.
    touched: Vec<u16>,
    bounds: Option<(u64, u64)>,
}

/// A sealed chunk, to compress.
struct Job {
    data: Vec<u8>,
    /// The buffer to compress into (a spare).
    out: Vec<u8>,
    compression: Option<Compression>,
    level: i32,
    done: SyncSender<io::Result<Done>>,
    /// Carried through to the output thread.
    meta: ChunkMeta,
}

/// What the output thread needs of a chunk besides its bytes.
struct ChunkMeta {
    bounds: (u64, u64),
    /// Message index entries by channel, channels ascending.
    index: Vec<(u16, Vec<(u64, u64)>)>,
}

/// A compressed chunk.
struct Done {
    data: Vec<u8>,
    /// Compressed bytes; `None` when stored (the bytes are `data`).
    out: Option<Vec<u8>>,
    crc: u32,
    compression: &'static str,
    meta: ChunkMeta,
}

/// What the output thread writes, in order.
enum Item {
    /// Records outside chunks (header, records when not chunking).
    Raw(Vec<u8>),
    /// A metadata record (indexed in the summary under its name).
    Metadata(Vec<u8>, String),
    /// A chunk, once a compression thread is done with it.
    Chunk(Receiver<io::Result<Done>>),
    /// Write the data end, the summary and the footer.
    Finish(Box<Summary>),
}

/// What the calling thread knows of the summary.
struct Summary {
    /// Schema and channel records, in id order.
    schemas: Vec<u8>,
    channels: Vec<u8>,
    has_schemas: bool,
    has_channels: bool,
    stats: Stats,
}

struct Stats {
    messages: u64,
    schemas: u16,
    channels: u32,
    metadata: u32,
    bounds: (u64, u64),
    /// Messages per channel, channels with none left out.
    per_channel: Vec<(u16, u64)>,
}

/// The most a chunk buffer is given up front.
const MAX_RESERVE: usize = 64 << 20;
/// Records outside chunks go to the output thread in pieces of this size.
const RAW_BATCH: usize = 256 * 1024;

/// The calling thread's end: builds the records and chunks, assigns schema and channel ids
/// (sequentially from 1, identical schemas shared, as `mcap::Writer` does), and hands sealed
/// chunks to the compression threads and everything, in order, to the output thread.
pub(super) struct Sink {
    opts: McapOptions,
    open: Open,
    /// Records outside chunks not yet sent.
    raw: Vec<u8>,
    schemas: HashMap<(String, String), u16>,
    schema_recs: Vec<(u16, String, String)>,
    channels: Vec<ChannelRec>,
    /// Messages per channel id.
    counts: Vec<u64>,
    bounds: Option<(u64, u64)>,
    metadata: u32,
    items: SyncSender<Item>,
    jobs: Option<SyncSender<Job>>,
    /// Emptied buffers back from the output thread.
    spare: Receiver<Vec<u8>>,
    workers: Vec<JoinHandle<()>>,
}

impl Sink {
    /// Start the threads and write the magic and the header. The output thread returns the
    /// writer once the file is finished.
    pub(super) fn start<W: Write + Send + 'static>(
        w: W,
        opts: McapOptions,
    ) -> io::Result<(Sink, JoinHandle<io::Result<W>>)> {
        // Chunks alive at once: the open one, one queued, one per compression thread and one
        // more done than threads waiting for the output thread; a few MiB.
        let (items, items_rx) = mpsc::sync_channel::<Item>(opts.threads + 1);
        let (spare_tx, spare) = mpsc::channel::<Vec<u8>>();
        let out = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || output(w, items_rx, spare_tx))?;
        let mut workers = vec![];
        let (jobs, jobs_rx) = mpsc::sync_channel::<Job>(1);
        let jobs_rx = Arc::new(Mutex::new(jobs_rx));
        if opts.use_chunks {
            for i in 0..opts.threads {
                let rx = Arc::clone(&jobs_rx);
                workers.push(
                    std::thread::Builder::new()
                        .name(format!("mcap-zstd-{i}"))
                        .spawn(move || compress_jobs(&rx))?,
                );
            }
        }
        let mut raw = MAGIC.to_vec();
        put_record(&mut raw, op::HEADER, |b| {
            put_str(b, "");
            put_str(b, &opts.library);
        });
        let mut sink = Sink {
            open: Open::default(),
            raw,
            schemas: HashMap::new(),
            schema_recs: vec![],
            channels: vec![],
            counts: vec![],
            bounds: None,
            metadata: 0,
            items,
            jobs: opts.use_chunks.then_some(jobs),
            spare,
            workers,
            opts,
        };
        if sink.opts.use_chunks {
            sink.open.data = sink.chunk_buffer();
        }
        Ok((sink, out))
    }

    fn send(&mut self, item: Item) -> io::Result<()> {
        self.items
            .send(item)
            .map_err(|_| io::Error::other("MCAP writer thread stopped"))
    }

    fn take_spare(&mut self) -> Vec<u8> {
        self.spare.try_recv().unwrap_or_default()
    }

    /// A buffer for the next chunk, with room for a whole one (growing a fresh `Vec` to a
    /// few MiB would copy it several times).
    fn chunk_buffer(&mut self) -> Vec<u8> {
        let mut b = self.take_spare();
        if let Some(s) = self.opts.chunk_size {
            b.reserve((s as usize).min(MAX_RESERVE) + 64 * 1024);
        }
        b
    }

    /// Send the records outside chunks written so far.
    fn send_raw(&mut self) -> io::Result<()> {
        if self.raw.is_empty() {
            return Ok(());
        }
        let next = self.take_spare();
        let raw = std::mem::replace(&mut self.raw, next);
        self.send(Item::Raw(raw))
    }

    /// The buffer a record goes to: the open chunk's, or the data section's.
    fn target(&mut self) -> &mut Vec<u8> {
        if self.opts.use_chunks {
            &mut self.open.data
        } else {
            &mut self.raw
        }
    }

    /// Seal the open chunk (if it holds anything) and hand it to the compression threads.
    fn seal(&mut self) -> io::Result<()> {
        if self.open.data.is_empty() {
            return Ok(());
        }
        self.send_raw()?;
        let mut touched = std::mem::take(&mut self.open.touched);
        touched.sort_unstable();
        let index = touched
            .into_iter()
            .map(|ch| (ch, std::mem::take(&mut self.open.index[ch as usize])))
            .collect();
        let meta = ChunkMeta {
            bounds: self.open.bounds.take().unwrap_or((0, 0)),
            index,
        };
        let next = self.chunk_buffer();
        let data = std::mem::replace(&mut self.open.data, next);
        let (done, rx) = mpsc::sync_channel(1);
        let job = Job {
            data,
            out: self.take_spare(),
            compression: self.opts.compression,
            level: self.opts.level,
            done,
            meta,
        };
        // The output thread first: it must be waiting for the chunk before a full job queue
        // can block us (it never waits for anything else).
        self.send(Item::Chunk(rx))?;
        let jobs = self.jobs.as_ref().ok_or_else(closed)?;
        jobs.send(job).map_err(|_| closed())
    }

    pub(super) fn add_schema(&mut self, name: String, body: String) -> io::Result<u16> {
        let key = (name, body);
        if let Some(&id) = self.schemas.get(&key) {
            return Ok(id);
        }
        let id = u16::try_from(self.schemas.len() + 1)
            .map_err(|_| io::Error::other("too many MCAP schemas"))?;
        put_record(self.target(), op::SCHEMA, |b| {
            put_u16(b, id);
            put_str(b, &key.0);
            put_str(b, "jsonschema");
            put_str(b, &key.1);
        });
        self.schemas.insert(key.clone(), id);
        self.schema_recs.push((id, key.0, key.1));
        Ok(id)
    }

    /// Every channel we add has a distinct topic or metadata, so each gets a new id.
    pub(super) fn add_channel(
        &mut self,
        schema: u16,
        topic: String,
        encoding: &'static str,
        meta: BTreeMap<String, String>,
    ) -> io::Result<u16> {
        let id = u16::try_from(self.channels.len() + 1)
            .map_err(|_| io::Error::other("too many MCAP channels"))?;
        let c = ChannelRec {
            id,
            schema,
            topic,
            encoding,
            meta,
        };
        put_record(self.target(), op::CHANNEL, |b| channel_body(b, &c));
        self.channels.push(c);
        self.counts.push(0);
        Ok(id)
    }

    pub(super) fn message(
        &mut self,
        channel: u16,
        sequence: u32,
        log_time: u64,
        data: &[u8],
    ) -> io::Result<()> {
        let Some(n) = self.counts.get_mut((channel as usize).wrapping_sub(1)) else {
            return Err(io::Error::other(format!("unknown MCAP channel {channel}")));
        };
        *n += 1;
        self.bounds = Some(widen(self.bounds, log_time));
        if self.opts.use_chunks {
            // As `mcap::Writer`: a chunk past its size is closed before the next message.
            if self
                .opts
                .chunk_size
                .is_some_and(|s| self.open.data.len() as u64 > s)
            {
                self.seal()?;
            }
            let o = &mut self.open;
            if o.index.len() <= channel as usize {
                o.index.resize_with(channel as usize + 1, Vec::new);
            }
            let entries = &mut o.index[channel as usize];
            if entries.is_empty() {
                o.touched.push(channel);
            }
            entries.push((log_time, o.data.len() as u64));
            o.bounds = Some(widen(o.bounds, log_time));
        }
        let b = self.target();
        b.reserve(31 + data.len());
        b.push(op::MESSAGE);
        put_u64(b, 22 + data.len() as u64);
        put_u16(b, channel);
        put_u32(b, sequence);
        put_u64(b, log_time);
        put_u64(b, log_time);
        b.extend_from_slice(data);
        if !self.opts.use_chunks && self.raw.len() >= RAW_BATCH {
            self.send_raw()?;
        }
        Ok(())
    }

    /// A metadata record: it closes the open chunk, as in `mcap::Writer`.
    pub(super) fn metadata(&mut self, m: Metadata) -> io::Result<()> {
        self.seal()?;
        self.send_raw()?;
        let mut b = self.take_spare();
        put_record(&mut b, op::METADATA, |b| {
            put_str(b, &m.name);
            put_map(b, &m.metadata);
        });
        self.metadata += 1;
        self.send(Item::Metadata(b, m.name))
    }

    /// Close the file: the last chunk, then the summary (the output thread ends with it).
    pub(super) fn finish(mut self) -> io::Result<()> {
        self.seal()?;
        self.send_raw()?;
        let mut schemas = vec![];
        for (id, name, body) in &self.schema_recs {
            put_record(&mut schemas, op::SCHEMA, |b| {
                put_u16(b, *id);
                put_str(b, name);
                put_str(b, "jsonschema");
                put_str(b, body);
            });
        }
        let mut channels = vec![];
        for c in &self.channels {
            put_record(&mut channels, op::CHANNEL, |b| channel_body(b, c));
        }
        let per_channel: Vec<(u16, u64)> = self
            .channels
            .iter()
            .zip(&self.counts)
            .filter(|(_, &n)| n > 0)
            .map(|(c, &n)| (c.id, n))
            .collect();
        let s = Summary {
            has_schemas: !self.schema_recs.is_empty(),
            has_channels: !self.channels.is_empty(),
            schemas,
            channels,
            stats: Stats {
                messages: self.counts.iter().sum(),
                schemas: self.schema_recs.len() as u16,
                channels: self.channels.len() as u32,
                metadata: self.metadata,
                bounds: self.bounds.unwrap_or((0, 0)),
                per_channel,
            },
        };
        self.send(Item::Finish(Box::new(s)))
    }
}

impl Drop for Sink {
    fn drop(&mut self) {
        // Hang up on the compression threads once their queue is drained.
        self.jobs = None;
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

fn closed() -> io::Error {
    io::Error::other("MCAP compression threads stopped")
}

fn widen(b: Option<(u64, u64)>, t: u64) -> (u64, u64) {
    match b {
        None => (t, t),
        Some((s, e)) => (s.min(t), e.max(t)),
    }
}

fn channel_body(b: &mut Vec<u8>, c: &ChannelRec) {
    put_u16(b, c.id);
    put_u16(b, c.schema);
    put_str(b, &c.topic);
    put_str(b, c.encoding);
    put_map(b, &c.meta);
}

// --- compression threads -----------------------------------------------------------------

/// Compress jobs until the queue is closed. Each thread keeps its zstd context, so a chunk
/// costs no setup beyond a reset.
fn compress_jobs(rx: &Mutex<Receiver<Job>>) {
    let mut zstd: Option<(i32, zstd::bulk::Compressor<'static>)> = None;
    loop {
        // The lock is held only while waiting for the next job.
        let job = match rx.lock() {
            Ok(rx) => rx.recv(),
            Err(_) => return,
        };
        let Ok(job) = job else { return };
        let Job {
            data,
            mut out,
            compression,
            level,
            done,
            meta,
        } = job;
        let crc = crc32fast::hash(&data);
        out.clear();
        let res = match compression {
            None => Ok(None),
            Some(Compression::Zstd) => zstd_compress(&mut zstd, level, &data, out).map(Some),
            Some(Compression::Lz4) => lz4_compress(&data, out, level).map(Some),
        };
        let _ = done.send(res.map(|out| Done {
            data,
            out,
            crc,
            compression: compression_name(compression),
            meta,
        }));
    }
}

/// One zstd frame (with the content size) of `data`, with this thread's context for `level`.
fn zstd_compress(
    ctx: &mut Option<(i32, zstd::bulk::Compressor<'static>)>,
    level: i32,
    data: &[u8],
    mut out: Vec<u8>,
) -> io::Result<Vec<u8>> {
    if ctx.as_ref().map(|c| c.0) != Some(level) {
        *ctx = Some((level, zstd::bulk::Compressor::new(level)?));
    }
    let Some((_, c)) = ctx.as_mut() else {
        return Err(io::Error::other("no zstd context"));
    };
    out.reserve(zstd::compress_bound(data.len()));
    c.compress_to_buffer(data, &mut out)?;
    Ok(out)
}

/// An lz4 frame without block checksums (the chunk has a CRC), as `mcap::Writer` writes it.
fn lz4_compress(data: &[u8], out: Vec<u8>, level: i32) -> io::Result<Vec<u8>> {
    let mut e = lz4::EncoderBuilder::new()
        .level(level.max(0) as u32)
        .block_checksum(lz4::liblz4::BlockChecksum::NoBlockChecksum)
        .build(out)?;
    e.write_all(data)?;
    let (out, res) = e.finish();
    res.map(|_| out)
}

// --- output thread -----------------------------------------------------------------------

/// The output writer: counts the position and the CRC of the data section.
struct Counting<W> {
    w: W,
    pos: u64,
    crc: crc32fast::Hasher,
}

impl<W: Write> Counting<W> {
    fn put(&mut self, b: &[u8]) -> io::Result<()> {
        self.w.write_all(b)?;
        self.crc.update(b);
        self.pos += b.len() as u64;
        Ok(())
    }
}

/// A chunk index entry, kept for the summary.
struct ChunkIdx {
    bounds: (u64, u64),
    start: u64,
    len: u64,
    index_offsets: Vec<(u16, u64)>,
    index_len: u64,
    compression: &'static str,
    compressed: u64,
    uncompressed: u64,
}

/// Write the items in order, then (on `Finish`) the summary; hand the writer back.
fn output<W: Write>(w: W, rx: Receiver<Item>, spare: mpsc::Sender<Vec<u8>>) -> io::Result<W> {
    let mut w = Counting {
        w,
        pos: 0,
        crc: crc32fast::Hasher::new(),
    };
    let mut chunks: Vec<ChunkIdx> = vec![];
    let mut metadata: Vec<(u64, u64, String)> = vec![];
    let mut head = Vec::with_capacity(64);
    for item in rx {
        match item {
            Item::Raw(mut b) => {
                w.put(&b)?;
                b.clear();
                let _ = spare.send(b);
            }
            Item::Metadata(mut b, name) => {
                metadata.push((w.pos, b.len() as u64, name));
                w.put(&b)?;
                b.clear();
                let _ = spare.send(b);
            }
            Item::Chunk(done) => {
                let d = done
                    .recv()
                    .map_err(|_| closed())
                    .and_then(|r| r)
                    .map_err(|e| io::Error::new(e.kind(), format!("MCAP chunk: {e}")))?;
                let body = d.out.as_deref().unwrap_or(&d.data);
                let start = w.pos;
                head.clear();
                put_record(&mut head, op::CHUNK, |b| {
                    put_u64(b, d.meta.bounds.0);
                    put_u64(b, d.meta.bounds.1);
                    put_u64(b, d.data.len() as u64);
                    put_u32(b, d.crc);
                    put_str(b, d.compression);
                    put_u64(b, body.len() as u64);
                });
                // The record's length counts the body written after it.
                let len = (head.len() - 9 + body.len()) as u64;
                head[1..9].copy_from_slice(&len.to_le_bytes());
                w.put(&head)?;
                w.put(body)?;
                let chunk_len = w.pos - start;
                head.clear();
                let mut index_offsets = Vec::with_capacity(d.meta.index.len());
                let index_start = w.pos;
                for (ch, entries) in &d.meta.index {
                    index_offsets.push((*ch, index_start + head.len() as u64));
                    put_record(&mut head, op::MESSAGE_INDEX, |b| {
                        put_u16(b, *ch);
                        put_prefixed(b, |b| {
                            for &(t, at) in entries {
                                put_u64(b, t);
                                put_u64(b, at);
                            }
                        });
                    });
                }
                w.put(&head)?;
                chunks.push(ChunkIdx {
                    bounds: d.meta.bounds,
                    start,
                    len: chunk_len,
                    index_offsets,
                    index_len: head.len() as u64,
                    compression: d.compression,
                    compressed: body.len() as u64,
                    uncompressed: d.data.len() as u64,
                });
                let Done { mut data, out, .. } = d;
                data.clear();
                let _ = spare.send(data);
                if let Some(mut out) = out {
                    out.clear();
                    let _ = spare.send(out);
                }
            }
            Item::Finish(s) => {
                write_summary(&mut w, &s, &chunks, &metadata)?;
                w.w.flush()?;
                return Ok(w.w);
            }
        }
    }
    // Hung up without `Finish`: the calling side failed; leave the file as it is.
    Err(io::Error::other("MCAP writer closed without finishing"))
}

/// Data end, summary section, footer and magic.
fn write_summary<W: Write>(
    w: &mut Counting<W>,
    s: &Summary,
    chunks: &[ChunkIdx],
    metadata: &[(u64, u64, String)],
) -> io::Result<()> {
    let mut b = vec![];
    let data_crc = w.crc.clone().finalize();
    put_record(&mut b, op::DATA_END, |b| put_u32(b, data_crc));
    w.put(&b)?;
    let start = w.pos;
    b.clear();
    let mut groups: Vec<(u8, u64, u64)> = vec![];
    let mut group = |b: &mut Vec<u8>, opcode: u8, f: &mut dyn FnMut(&mut Vec<u8>)| {
        let at = b.len();
        f(b);
        groups.push((opcode, start + at as u64, (b.len() - at) as u64));
    };
    if s.has_schemas {
        group(&mut b, op::SCHEMA, &mut |b| b.extend_from_slice(&s.schemas));
    }
    if s.has_channels {
        group(&mut b, op::CHANNEL, &mut |b| {
            b.extend_from_slice(&s.channels)
        });
    }
    group(&mut b, op::STATISTICS, &mut |b| {
        let st = &s.stats;
        put_record(b, op::STATISTICS, |b| {
            put_u64(b, st.messages);
            put_u16(b, st.schemas);
            put_u32(b, st.channels);
            put_u32(b, 0); // attachments
            put_u32(b, st.metadata);
            put_u32(b, chunks.len() as u32);
            put_u64(b, st.bounds.0);
            put_u64(b, st.bounds.1);
            put_prefixed(b, |b| {
                for &(ch, n) in &st.per_channel {
                    put_u16(b, ch);
                    put_u64(b, n);
                }
            });
        })
    });
    if !chunks.is_empty() {
        group(&mut b, op::CHUNK_INDEX, &mut |b| {
            for c in chunks {
                put_record(b, op::CHUNK_INDEX, |b| {
                    put_u64(b, c.bounds.0);
                    put_u64(b, c.bounds.1);
                    put_u64(b, c.start);
                    put_u64(b, c.len);
                    put_prefixed(b, |b| {
                        for &(ch, at) in &c.index_offsets {
                            put_u16(b, ch);
                            put_u64(b, at);
                        }
                    });
                    put_u64(b, c.index_len);
                    put_str(b, c.compression);
                    put_u64(b, c.compressed);
                    put_u64(b, c.uncompressed);
                });
            }
        });
    }
    if !metadata.is_empty() {
        group(&mut b, op::METADATA_INDEX, &mut |b| {
            for (at, len, name) in metadata {
                put_record(b, op::METADATA_INDEX, |b| {
                    put_u64(b, *at);
                    put_u64(b, *len);
                    put_str(b, name);
                });
            }
        });
    }
    let offsets_start = start + b.len() as u64;
    for (opcode, at, len) in groups {
        put_record(&mut b, op::SUMMARY_OFFSET, |b| {
            b.push(opcode);
            put_u64(b, at);
            put_u64(b, len);
        });
    }
    // The summary CRC covers the summary and the footer up to the CRC itself.
    b.push(op::FOOTER);
    put_u64(&mut b, 20);
    put_u64(&mut b, start);
    put_u64(&mut b, offsets_start);
    let crc = crc32fast::hash(&b);
    put_u32(&mut b, crc);
    b.extend_from_slice(MAGIC);
    w.put(&b)
}
