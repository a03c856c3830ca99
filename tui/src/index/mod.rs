//! The capture index: every record (frame or garbage) of a capture, stored compactly (24 bytes
//! a record, [`Recs`]), built by a background thread while the UI already shows what has been
//! read.
//!
//! The records come from the one decode chain ([`aptscope_dissector::record::Decoder`]): the
//! indexer keeps of each [`Record`](aptscope_dissector::record::Record) what the timeline,
//! filters and statistics read without decoding (a [`Rec`]). Its bytes are read back from the
//! capture file by position (a raw capture) or from an arena the indexer writes to an unlinked
//! scratch file (other formats, live sources). Nothing rendered is stored: the UI decodes the
//! rows it shows from those bytes.

use aptscope_capture::model::{Event, Reader};
use aptscope_capture::open::{open_with_progress, OpenOptions};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::ell::Module;
use aptscope_dissector::record::{Ctx, Decoder};
use aptscope_dissector::table::Dir;
use aptscope_dissector::units::{Scale, UnitsOpts};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, RwLock};
use std::time::Instant;

/// Record flag: an Elliptec record (else APT).
pub const F_ELL: u16 = 1;
/// Record flag: a garbage record (bytes outside frames).
pub const F_GARBAGE: u16 = 2;
/// Record flag: the stream ended inside the frame.
pub const F_TRUNCATED: u16 = 4;
/// Record flag: a reply nobody asked for.
pub const F_UNSOLICITED: u16 = 8;
/// Record flag: a second reply to an answered request.
pub const F_DUPLICATE: u16 = 16;
/// Record flag: the reply came from another address than the request went to.
pub const F_OTHER_ADDR: u16 = 32;
/// Record flag: an Elliptec busy `GS` before the final reply.
pub const F_INTERIM: u16 = 64;
/// Record flag: a request that got no reply.
pub const F_NO_REPLY: u16 = 128;
/// Record flag: the frame has decoding diagnostics.
pub const F_DIAG: u16 = 256;
/// Record flag (garbage): a header with an absurd length.
pub const F_ABSURD: u16 = 512;
/// Record flag (garbage): bytes left at the end of the stream.
pub const F_TRAILING: u16 = 1024;
/// Record flag: the frame is a reply (its `pair` is the request).
pub const F_IS_REPLY: u16 = 2048;
/// Record flag: the device's model does not implement the message (model in
/// [`Index::not_for_model`]).
pub const F_NOT_FOR_MODEL: u16 = 4096;

/// One record of the capture (a frame or a garbage run): what the timeline, filters and
/// statistics read without decoding the frame. [`Recs`] stores it packed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rec {
    /// Start of the bytes in the arena.
    pub start: u64,
    /// Stream offset of the first byte.
    pub offset: u64,
    /// Offset of the first byte in the whole capture (every stream and direction).
    pub cap_offset: u64,
    /// Capture time in ns, `u64::MAX` when not recorded.
    pub ts: u64,
    /// Record number of the paired record (request of a reply, first reply of a request), 0 if
    /// none.
    pub pair: u32,
    /// Length in bytes.
    pub len: u32,
    /// Elliptec: index + 1 of the module (in [`Index::modules`]) the frame concerns. APT:
    /// index + 1 of the conversion of its motion values (in [`Index::scales`]). 0 if none.
    pub module: u32,
    /// Stream (port/device) index.
    pub stream: u16,
    /// `F_*` flags.
    pub flags: u16,
    /// Direction as captured: 0 unknown, 1 host → device, 2 device → host.
    pub dir: u8,
    /// APT: source address byte. Elliptec: bus address (0–15).
    pub src: u8,
    /// APT: destination address byte.
    pub dst: u8,
    /// APT: message id. Elliptec: the two command characters (first in the high byte).
    pub id: u16,
    /// The kinds of the frame's own diagnostics (decoding's, not pairing's): index + 1 in
    /// [`Index::diag_sets`], 0 when it has none.
    pub diags: u16,
    /// APT: the channel (`AptFrame::channel`) + 1; 0 for none, [`CHAN_OTHER`] for one that
    /// does not fit (read from the frame). Filters on `apt.chan` read it without decoding.
    pub chan: u8,
}

mod cache;
mod readback;
mod recs;
mod sink;
#[cfg(test)]
mod tests;

pub use cache::{
    cache_file_of, cache_max, default_cache, set_index_cache, CACHE_NONE, CACHE_NOT_SAVED,
    CACHE_READ, CACHE_SAVED, CACHE_SAVING, DEFAULT_CACHE_MAX,
};
pub use readback::*;
pub use recs::*;
use sink::*;

/// An APT record's channel as the index kept it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KeptChan {
    /// The frame has none.
    None,
    /// This channel.
    Chan(i64),
    /// One that did not fit: read it from the frame.
    InFrame,
}

impl Rec {
    /// The APT channel the index kept.
    pub fn chan(&self) -> KeptChan {
        match self.chan {
            0 => KeptChan::None,
            CHAN_OTHER => KeptChan::InFrame,
            c => KeptChan::Chan(i64::from(c) - 1),
        }
    }
}

/// [`Rec::chan`] for a channel.
fn chan_code(c: Option<i64>) -> u8 {
    match c {
        None => 0,
        Some(c) => u8::try_from(c + 1)
            .ok()
            .filter(|&x| x != CHAN_OTHER)
            .unwrap_or(CHAN_OTHER),
    }
}

impl Rec {
    /// Capture time, when recorded.
    pub fn ts(&self) -> Option<u64> {
        (self.ts != u64::MAX).then_some(self.ts)
    }
    /// Whether a flag is set.
    pub fn has(&self, f: u16) -> bool {
        self.flags & f != 0
    }
    /// Captured direction.
    pub fn cap_dir(&self) -> Option<Dir> {
        match self.dir {
            1 => Some(Dir::HostToDevice),
            2 => Some(Dir::DeviceToHost),
            _ => None,
        }
    }
    /// Elliptec: the command characters as written.
    pub fn code(&self) -> [u8; 2] {
        self.id.to_be_bytes()
    }
}

fn dir_code(d: Option<Dir>) -> u8 {
    match d {
        Some(Dir::HostToDevice) => 1,
        Some(Dir::DeviceToHost) => 2,
        _ => 0,
    }
}

/// A point of a plotted series: (time in s since the first record, or record number; value).
pub type Point = (f64, f64);

/// Everything known about the capture so far.
#[derive(Debug, Default)]
pub struct Index {
    /// Records, in timeline order (record number = index + 1).
    pub recs: Recs,
    /// Bytes of all records, when they are not read back from [`Index::file`] or
    /// [`Index::arena_file`] (an index loaded with [`load_in_memory`], or one whose scratch file
    /// could not be made).
    pub arena: Vec<u8>,
    /// The capture file records' bytes are read from (by capture offset) instead of the
    /// arena: a raw capture, whose capture offsets are file positions.
    pub file: Option<ReadBack>,
    /// The arena written to a file (by `Rec::start`) instead of kept in memory: every other
    /// format and live sources, whose containers cannot be read back by position (packets cut
    /// in pieces, text logs, pipes).
    pub arena_file: Option<ReadBack>,
    /// Elliptec modules as the bus knew them (indexed by `Rec::module - 1`).
    pub modules: Vec<Module>,
    /// APT: the stage conversions records use (indexed by `Rec::module - 1`).
    pub scales: Vec<Scale>,
    /// APT: what converts each device's motion values, as it changed (`units: …` lines).
    pub units_notes: Vec<String>,
    /// Protocol (once detected).
    pub proto: Option<Proto>,
    /// Whether detection was certain.
    pub proto_certain: bool,
    /// The share of the detection sample that framed cleanly as the protocol chosen (when
    /// detected): an uncertain guess says how little framed.
    pub proto_share: Option<f64>,
    /// Time of the first record.
    pub first_ts: Option<u64>,
    /// Stream names by index.
    pub streams: Vec<String>,
    /// Streams records were seen on (bit per stream index, the first 64): the timeline shows
    /// the stream of each row when there is more than one.
    pub streams_seen: u64,
    /// Capture format.
    pub format: String,
    /// Problems reading the file (offset, kind, message).
    pub file_diags: Vec<(u64, String)>,
    /// Plot series: positions and velocities from status updates, keyed by
    /// `quantity source` (e.g. `position usb ch1`, `position ell 0`).
    pub series: BTreeMap<String, Vec<Point>>,
    /// Kinds of diagnostics frames have (each list once), indexed by `Rec::diags - 1`.
    pub diag_sets: Vec<Vec<&'static str>>,
    /// For records flagged [`F_NOT_FOR_MODEL`]: the device's model, by record number.
    pub not_for_model: BTreeMap<u64, [u8; 8]>,
    /// Records that got [`F_NO_REPLY`] after they were published (their request's timeout
    /// passed later), in the order it happened: a scan that has counted them already counts
    /// the diagnostic now.
    pub late_no_reply: Vec<u64>,
    /// Whether the whole file has been read.
    pub done: bool,
    /// Error that stopped reading.
    pub error: Option<String>,
    /// The index was read back from the cache of an earlier opening (not indexed again).
    pub from_cache: bool,
}

impl Index {
    /// The bytes of a record: from the arena, or read from the capture file (empty when the
    /// file can no longer give them).
    pub fn bytes(&self, r: &Rec) -> Cow<'_, [u8]> {
        let back = match (&self.file, &self.arena_file) {
            (Some(f), _) => Some((f, r.cap_offset)),
            (None, Some(f)) => Some((f, r.start)),
            (None, None) => None,
        };
        if let Some((f, at)) = back {
            return f
                .read(at, r.len as usize)
                .map_or(Cow::Borrowed(&[]), Cow::Owned);
        }
        let s = r.start as usize;
        Cow::Borrowed(self.arena.get(s..s + r.len as usize).unwrap_or(&[]))
    }
    /// A record by number (1-based).
    pub fn rec(&self, n: u64) -> Option<Rec> {
        self.recs.get((n as usize).checked_sub(1)?)
    }
    /// Whether records were seen on more than one stream.
    pub fn multi_stream(&self) -> bool {
        self.streams_seen.count_ones() > 1
    }
}

/// The index shared between the indexing thread and the UI.
#[derive(Debug, Default)]
pub struct Shared {
    /// The index.
    pub index: RwLock<Index>,
    /// Bytes of the file read so far.
    pub read: Arc<AtomicU64>,
    /// The file size when known.
    pub total: Option<u64>,
    /// Set to stop the indexing thread (and, shared with a live source, the source).
    pub cancel: Arc<AtomicBool>,
    /// The source is live (a tap, a simulator, a file being written): the index keeps growing
    /// until it stops, and every record read is published at once.
    pub live: AtomicBool,
    /// What became of the index cache: [`CACHE_NONE`], [`CACHE_SAVING`], [`CACHE_SAVED`],
    /// [`CACHE_NOT_SAVED`] or [`CACHE_READ`].
    pub cache: AtomicU8,
}

impl Shared {
    /// Fraction of the file read (1.0 when done).
    pub fn progress(&self) -> f64 {
        match self.total {
            Some(t) if t > 0 => (self.read.load(Ordering::Relaxed) as f64 / t as f64).min(1.0),
            _ => 0.0,
        }
    }
}

/// How to decode a capture for the index.
#[derive(Debug, Clone, Default)]
pub struct IndexOpts {
    /// Decode as this protocol instead of detecting it.
    pub proto: Option<Proto>,
    /// Stage or scale for APT motion values.
    pub units: UnitsOpts,
    /// The source is live (see [`Shared::live`]).
    pub live: bool,
    /// A stop flag to share with the source (its reader returns when it is set): the viewer
    /// sets it when the user quits. A new one when `None`.
    pub cancel: Option<Arc<AtomicBool>>,
    /// The source is this file, still being written: when reading has caught up with its
    /// end, what was read is published at once and the protocol decided as soon as detection
    /// is certain; Elliptec host chunks are host writes (a command is framed without waiting
    /// for its terminator).
    pub follow: Option<String>,
    /// The capture file the source reads, when it stays put: a raw capture's record bytes are
    /// then read back from it ([`Index::file`]) instead of being kept in memory.
    pub file: Option<String>,
}

/// Open a capture and index it in a background thread. The returned [`Shared`] fills as the
/// thread goes.
pub fn spawn(path: &str, opts: OpenOptions) -> std::io::Result<Arc<Shared>> {
    spawn_as(path, opts, None)
}

/// [`spawn`], decoding as `proto` instead of detecting the protocol when it is given.
pub fn spawn_as(
    path: &str,
    opts: OpenOptions,
    proto: Option<Proto>,
) -> std::io::Result<Arc<Shared>> {
    spawn_with(path, opts, proto, UnitsOpts::default())
}

/// [`spawn_as`], converting APT motion values with the stage or scale of `units`.
pub fn spawn_with(
    path: &str,
    opts: OpenOptions,
    proto: Option<Proto>,
    units: UnitsOpts,
) -> std::io::Result<Arc<Shared>> {
    spawn_cached(path, opts, proto, units, default_cache())
}

/// [`spawn_with`], with the index cache in `cache` (`None`: neither read nor written). A
/// capture indexed before and unchanged since comes back complete at once; one indexed
/// completely now is written there for the next opening (on the indexing thread, after the
/// index is complete: [`Shared::cache`] says when it is written).
pub fn spawn_cached(
    path: &str,
    opts: OpenOptions,
    proto: Option<Proto>,
    units: UnitsOpts,
    cache: Option<PathBuf>,
) -> std::io::Result<Arc<Shared>> {
    let key = cache
        .as_deref()
        .and_then(|d| cache::Key::new(path, &opts, proto, &units, d));
    if let Some(shared) = key.as_ref().and_then(from_cache) {
        return Ok(shared);
    }
    let path = path.to_string();
    let iopts = IndexOpts {
        proto,
        units,
        // A file another process is still writing (`view --follow`, a tap's live view), or
        // standard input (a pipe a live capture writes: its reader blocks until more comes).
        live: opts.follow.is_some() || path == "-",
        follow: opts.follow.is_some().then(|| path.clone()),
        file: (opts.follow.is_none() && path != "-").then(|| path.clone()),
        ..IndexOpts::default()
    };
    spawn_inner(
        move || {
            let (reader, _, progress) = open_with_progress(&path, opts)?;
            Ok((reader, Some(progress)))
        },
        iopts,
        key,
    )
}

/// The shared index read back from the cache file of `key`, when it has a sound one.
fn from_cache(key: &cache::Key) -> Option<Arc<Shared>> {
    let ix = cache::read(key)?;
    Some(Arc::new(Shared {
        index: RwLock::new(ix),
        read: Arc::new(AtomicU64::new(key.size)),
        total: Some(key.size),
        cache: AtomicU8::new(CACHE_READ),
        ..Shared::default()
    }))
}

/// What a source opener gives: the reader, and how far it has read when that is known.
pub type Opened = (Box<dyn Reader>, Option<aptscope_capture::open::Progress>);

/// Index what the reader `open` returns in a background thread (readers are not `Send`: it is
/// opened in that thread). For live sources (`opts.live`), the reader's `next_event` may block
/// until more data comes or the stop flag ([`Shared::cancel`], `opts.cancel` when given) is set.
pub fn spawn_source<F>(open: F, opts: IndexOpts) -> std::io::Result<Arc<Shared>>
where
    F: FnOnce() -> std::io::Result<Opened> + Send + 'static,
{
    spawn_inner(open, opts, None)
}

/// [`spawn_source`], writing the index to the cache file of `key` once complete.
fn spawn_inner<F>(open: F, opts: IndexOpts, key: Option<cache::Key>) -> std::io::Result<Arc<Shared>>
where
    F: FnOnce() -> std::io::Result<Opened> + Send + 'static,
{
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("aptscope-index".into())
        .spawn(move || match open() {
            Ok((reader, progress)) => {
                let input = progress.clone();
                let shared = shared_for(reader.as_ref(), progress, &opts);
                let from_file = read_back(&shared, reader.as_ref(), opts.file.as_deref());
                if key.is_some() {
                    shared.cache.store(CACHE_SAVING, Ordering::Relaxed);
                }
                let _ = tx.send(Ok(shared.clone()));
                let mut ix = Indexer::new(shared.clone(), opts.proto, opts.units);
                ix.sink.from_file = from_file;
                ix.follow = opts.follow.and_then(|p| std::fs::File::open(p).ok());
                ix.input = input;
                ix.run(reader);
                if let Some(key) = &key {
                    cache::save(&shared, key);
                }
            }
            Err(e) => {
                let _ = tx.send(Err(e));
            }
        })?;
    rx.recv()
        .map_err(|_| std::io::Error::other("indexing thread failed"))?
}

/// A new shared index for a source.
fn shared_for(
    reader: &dyn Reader,
    progress: Option<aptscope_capture::open::Progress>,
    opts: &IndexOpts,
) -> Arc<Shared> {
    let (read, total) = progress.map_or((Arc::default(), None), |p| (p.read, p.total));
    let shared = Arc::new(Shared {
        read,
        total,
        cancel: opts.cancel.clone().unwrap_or_default(),
        live: AtomicBool::new(opts.live),
        ..Shared::default()
    });
    if let Ok(mut ix) = shared.index.write() {
        ix.format = reader.format();
    }
    shared
}

/// Whether the records' bytes can be read back from `file` (a raw capture, whose capture
/// offsets are its file positions) rather than kept: if so, the index is given the file.
fn read_back(shared: &Shared, reader: &dyn Reader, file: Option<&str>) -> bool {
    if reader.format() != "raw bytes" {
        return false;
    }
    let Some(f) = file.and_then(|p| ReadBack::open(p).ok()) else {
        return false;
    };
    match shared.index.write() {
        Ok(mut ix) => {
            ix.file = Some(f);
            true
        }
        Err(_) => false,
    }
}

fn opened(
    path: &str,
    opts: OpenOptions,
    in_memory: bool,
) -> std::io::Result<(Arc<Shared>, Box<dyn Reader>, bool)> {
    let (reader, _, progress) = open_with_progress(path, opts)?;
    let shared = shared_for(reader.as_ref(), Some(progress), &IndexOpts::default());
    let file = (!in_memory && opts.follow.is_none() && path != "-").then_some(path);
    let from_file = read_back(&shared, reader.as_ref(), file);
    Ok((shared, reader, from_file))
}

/// Open and index a capture completely, in the calling thread (tests, small files). A raw
/// capture's bytes are read back from the file, as the viewer does.
pub fn load(path: &str, opts: OpenOptions) -> std::io::Result<Arc<Shared>> {
    load_with(path, opts, UnitsOpts::default())
}

/// [`load`] with a stage or scale for APT motion values.
pub fn load_with(path: &str, opts: OpenOptions, units: UnitsOpts) -> std::io::Result<Arc<Shared>> {
    load_inner(path, opts, units, false, None)
}

/// [`load`] keeping every record's bytes in memory (no scratch file): tests compare it with
/// the index that reads them back.
pub fn load_in_memory(path: &str, opts: OpenOptions) -> std::io::Result<Arc<Shared>> {
    load_inner(path, opts, UnitsOpts::default(), true, None)
}

/// [`load`] keeping at most `budget` bytes of records in memory (the others in a scratch
/// file), whatever [`index_memory`] says: tests compare it with the index kept in memory.
pub fn load_spilling(path: &str, opts: OpenOptions, budget: usize) -> std::io::Result<Arc<Shared>> {
    load_inner(path, opts, UnitsOpts::default(), false, Some(budget))
}

/// [`load_spilling`] (`budget`: `None` for [`index_memory`]) with the index cache in `cache`:
/// the index read back from there when the capture was indexed before and has not changed
/// since, else indexed and written there ([`Shared::cache`] says which).
pub fn load_cached(
    path: &str,
    opts: OpenOptions,
    budget: Option<usize>,
    cache: &Path,
) -> std::io::Result<Arc<Shared>> {
    let key = cache::Key::new(path, &opts, None, &UnitsOpts::default(), cache);
    if let Some(shared) = key.as_ref().and_then(from_cache) {
        return Ok(shared);
    }
    let shared = load_inner(path, opts, UnitsOpts::default(), false, budget)?;
    if let Some(key) = &key {
        cache::save(&shared, key);
    }
    Ok(shared)
}

fn load_inner(
    path: &str,
    opts: OpenOptions,
    units: UnitsOpts,
    in_memory: bool,
    budget: Option<usize>,
) -> std::io::Result<Arc<Shared>> {
    let (shared, reader, from_file) = opened(path, opts, in_memory)?;
    if let (Some(b), Ok(mut ix)) = (budget, shared.index.write()) {
        ix.recs.set_budget(b);
    }
    let mut ix = Indexer::new(shared.clone(), None, units);
    ix.sink.from_file = from_file;
    ix.sink.arena_tried = in_memory;
    ix.run(reader);
    Ok(shared)
}

/// Builds the index: feeds a [`Decoder`] and keeps a [`Rec`] of each record, publishing to
/// the [`Shared`] index in batches. [`Indexer::run`] reads a whole source; a caller that gets
/// its bytes another way (a simulator's own traffic, tests) feeds [`Indexer::chunk`] and
/// publishes with [`Indexer::flush`].
pub struct Indexer {
    shared: Arc<Shared>,
    dec: Decoder,
    sink: Sink,
    last_flush: Instant,
    /// A followed (growing) file, to see when reading has caught up with it.
    follow: Option<std::fs::File>,
    /// How reading goes: a live input (a pipe on standard input) says when it has nothing
    /// more for now.
    input: Option<aptscope_capture::open::Progress>,
    /// While [`Indexer::run`] reads a source: the thread that applies publications, and the
    /// buffers it gives back.
    publisher: Option<Publisher>,
}

/// The channels to the publishing thread.
struct Publisher {
    to: std::sync::mpsc::SyncSender<Publication>,
    back: std::sync::mpsc::Receiver<(Vec<Rec>, Vec<u8>)>,
}

impl Indexer {
    /// An indexer filling `shared`; `proto` given: no detection.
    pub fn new(shared: Arc<Shared>, proto: Option<Proto>, units: UnitsOpts) -> Self {
        if let (Some(p), Ok(mut ix)) = (proto, shared.index.write()) {
            ix.proto = Some(p);
            ix.proto_certain = true;
        }
        let mut dec = Decoder::new(proto);
        dec.set_units(units);
        Indexer {
            shared,
            dec,
            sink: Sink::default(),
            last_flush: Instant::now(),
            follow: None,
            input: None,
            publisher: None,
        }
    }

    /// Read `reader` to its end (or until cancelled), then finish and publish. Publications
    /// are applied to the shared index by a second thread, so that copying the records there
    /// overlaps with indexing the next ones; `run` returns once all are applied.
    pub fn run(mut self, mut reader: Box<dyn Reader>) {
        let shared = self.shared.clone();
        std::thread::scope(|s| {
            // Two publications in flight at most: a slow publisher holds the indexer back
            // rather than letting records pile up.
            let (to, rx) = std::sync::mpsc::sync_channel::<Publication>(2);
            let (back_tx, back) = std::sync::mpsc::channel();
            let spawned = std::thread::Builder::new()
                .name("aptscope-publish".into())
                .spawn_scoped(s, move || {
                    for p in rx {
                        let Ok(mut ix) = shared.index.write() else {
                            return;
                        };
                        // Emptied by `apply` (their contents appended to the index).
                        let spare = p.apply(&mut ix);
                        drop(ix);
                        let _ = back_tx.send(spare);
                    }
                });
            if spawned.is_ok() {
                self.publisher = Some(Publisher { to, back });
            }
            while let Some(ev) = reader.next_event() {
                if self.shared.cancel.load(Ordering::Relaxed) {
                    break;
                }
                self.event(ev);
                let caught_up = self.caught_up();
                if caught_up {
                    // A followed file may stay short of the 4 KiB detection sample for long: a
                    // certain detection on what there is shows its traffic now.
                    let sink = &mut self.sink;
                    let _ = self.dec.detect_if_certain(&mut |r| sink.on(r));
                }
                // A live source's reader blocks until more comes: publish what it gave now.
                let live = self.follow.is_none() && self.shared.live.load(Ordering::Relaxed);
                // A full batch goes too: the batches in flight stay a few MB.
                let full = self.sink.batch.len() >= MAX_BATCH;
                if caught_up || live || full || self.last_flush.elapsed() > FLUSH_EVERY {
                    self.flush();
                }
            }
            self.end();
            // Closing the channel ends the publisher; the scope waits for it.
            self.publisher = None;
        });
    }

    /// A followed file read to its current end, or a live input that had nothing more at its
    /// last read: the reader may now wait long for the next event, so what has been read is
    /// published at once (not at the next event).
    fn caught_up(&self) -> bool {
        self.input.as_ref().is_some_and(|p| p.idle())
            || self.follow.as_ref().is_some_and(|f| {
                f.metadata()
                    .is_ok_and(|m| self.shared.read.load(Ordering::Relaxed) >= m.len())
            })
    }

    /// Index one event of a capture reader.
    pub fn event(&mut self, ev: Event<'_>) {
        let sink = &mut self.sink;
        let _ = ev.feed(&mut self.dec, &mut |r| sink.on(r));
        // Following a live capture, a host chunk is a host write (as the tap's own timeline
        // assumes): an Elliptec command sent without terminator is framed now, not at the
        // host's next write.
        if let (Some(_), Event::Chunk(c)) = (&self.follow, &ev) {
            if c.dir.dir() == Some(Dir::HostToDevice) {
                let _ = self
                    .dec
                    .cut(c.stream, Dir::HostToDevice, &mut |r| sink.on(r));
            }
        }
    }

    /// Index one captured chunk.
    pub fn chunk(&mut self, ctx: Ctx, bytes: &[u8]) {
        let sink = &mut self.sink;
        let _ = self.dec.push(ctx, bytes, &mut |r| sink.on(r));
    }

    /// Say that the sender of `dir` on `stream` has paused (see [`Decoder::cut`]).
    pub fn cut(&mut self, stream: u32, dir: Dir) {
        let sink = &mut self.sink;
        let _ = self.dec.cut(stream, dir, &mut |r| sink.on(r));
    }

    /// Publish what was indexed since the last call (inside [`Indexer::run`], handed to its
    /// publishing thread; otherwise applied before this returns).
    pub fn flush(&mut self) {
        self.last_flush = Instant::now();
        self.publish(false);
    }

    fn publish(&mut self, done: bool) {
        self.sink.first_ts = self.dec.first_ts();
        let spare = self.publisher.as_ref().and_then(|p| p.back.try_recv().ok());
        let mut p = self.sink.take(done, spare);
        if done {
            p.fallback_proto = self.dec.proto();
        }
        let p = match &self.publisher {
            Some(publisher) => match publisher.to.send(p) {
                Ok(()) => return,
                // The publishing thread has gone: apply here.
                Err(std::sync::mpsc::SendError(p)) => p,
            },
            None => p,
        };
        if let Ok(mut ix) = self.shared.index.write() {
            p.apply(&mut ix);
        }
    }

    /// End of the source: requests without reply are marked, everything is published and the
    /// index is complete.
    pub fn finish(mut self) {
        self.end();
    }

    fn end(&mut self) {
        let sink = &mut self.sink;
        let _ = self.dec.finish(&mut |r| sink.on(r));
        self.publish(true);
    }
}
