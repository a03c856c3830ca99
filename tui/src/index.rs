//! The capture index: every record (frame or garbage) of a capture, stored compactly (a small
//! fixed-size record plus its bytes in one arena), built by a background thread while the UI
//! already shows what has been read.
//!
//! Nothing rendered is stored: the UI decodes the rows it shows from the arena.

use aptscope_capture::model::{Direction, Event};
use aptscope_capture::open::{open_with_progress, OpenOptions};
use aptscope_dissector::apt::{AptFrame, AptFramer, GarbageKind, Item as AptItem};
use aptscope_dissector::detect::{detect, Proto, SAMPLE};
use aptscope_dissector::ell::{Bus, EllFrame, EllFramer, Item as EllItem, Module};
use aptscope_dissector::pair::AptPairer;
use aptscope_dissector::table::Dir;
use aptscope_dissector::units::{Scale, Tracker, UnitsOpts};
use aptscope_dissector::Table;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, RwLock};
use std::time::{Duration, Instant};

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

/// One record of the capture (a frame or a garbage run), about 40 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rec {
    /// Start of the bytes in the arena.
    pub start: u64,
    /// Stream offset of the first byte.
    pub offset: u64,
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
}

/// A point of a plotted series: (time in s since the first record, or record number; value).
pub type Point = (f64, f64);

/// Everything known about the capture so far.
#[derive(Debug, Default)]
pub struct Index {
    /// Records, in timeline order (record number = index + 1).
    pub recs: Vec<Rec>,
    /// Bytes of all records.
    pub arena: Vec<u8>,
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
    /// Time of the first record.
    pub first_ts: Option<u64>,
    /// Stream names by index.
    pub streams: Vec<String>,
    /// Capture format.
    pub format: String,
    /// Problems reading the file (offset, kind, message).
    pub file_diags: Vec<(u64, String)>,
    /// Plot series: positions and velocities from status updates, keyed by
    /// `quantity source` (e.g. `position usb ch1`, `position ell 0`).
    pub series: BTreeMap<String, Vec<Point>>,
    /// For records flagged [`F_NOT_FOR_MODEL`]: the device's model, by record number.
    pub not_for_model: BTreeMap<u64, [u8; 8]>,
    /// Whether the whole file has been read.
    pub done: bool,
    /// Error that stopped reading.
    pub error: Option<String>,
}

impl Index {
    /// The bytes of a record.
    pub fn bytes(&self, r: &Rec) -> &[u8] {
        let s = r.start as usize;
        self.arena.get(s..s + r.len as usize).unwrap_or(&[])
    }
    /// A record by number (1-based).
    pub fn rec(&self, n: u64) -> Option<&Rec> {
        self.recs.get((n as usize).checked_sub(1)?)
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
    /// Set to stop the indexing thread.
    pub cancel: AtomicBool,
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
    // Readers are not `Send`: open in the indexing thread, hand back the shared index.
    let (tx, rx) = std::sync::mpsc::channel();
    let path = path.to_string();
    std::thread::Builder::new()
        .name("aptscope-index".into())
        .spawn(move || match opened(&path, opts) {
            Ok((shared, reader)) => {
                let _ = tx.send(Ok(shared.clone()));
                let mut ix = Indexer::new(shared, proto, units);
                ix.follow = opts.follow.and_then(|_| std::fs::File::open(&path).ok());
                ix.run(reader);
            }
            Err(e) => {
                let _ = tx.send(Err(e));
            }
        })?;
    rx.recv()
        .map_err(|_| std::io::Error::other("indexing thread failed"))?
}

type Opened = (Arc<Shared>, Box<dyn aptscope_capture::model::Reader>);

fn opened(path: &str, opts: OpenOptions) -> std::io::Result<Opened> {
    let (reader, _, progress) = open_with_progress(path, opts)?;
    let shared = Arc::new(Shared {
        read: progress.read.clone(),
        total: progress.total,
        ..Shared::default()
    });
    if let Ok(mut ix) = shared.index.write() {
        ix.format = reader.format();
    }
    Ok((shared, reader))
}

/// Open and index a capture completely, in the calling thread (tests, small files).
pub fn load(path: &str, opts: OpenOptions) -> std::io::Result<Arc<Shared>> {
    let (shared, reader) = opened(path, opts)?;
    Indexer::new(shared.clone(), None, UnitsOpts::default()).run(reader);
    Ok(shared)
}

/// [`load`] with a stage or scale for APT motion values.
pub fn load_with(path: &str, opts: OpenOptions, units: UnitsOpts) -> std::io::Result<Arc<Shared>> {
    let (shared, reader) = opened(path, opts)?;
    Indexer::new(shared.clone(), None, units).run(reader);
    Ok(shared)
}

struct Lane {
    stream: u32,
    dir: u8,
    apt: AptFramer<'static>,
    ell: EllFramer,
    ts: Option<u64>,
}

/// The indexing state: framers per lane, pairing, and a batch not yet published.
struct Indexer {
    shared: Arc<Shared>,
    proto: Option<Proto>,
    sample: Vec<(u32, u8, Option<u64>, Vec<u8>)>,
    sample_len: usize,
    lanes: Vec<Lane>,
    pairers: Vec<(u32, AptPairer)>,
    buses: Vec<(u32, Bus, Vec<Option<u32>>)>,
    /// Records not yet published, numbered from `base + 1`.
    batch: Vec<Rec>,
    arena: Vec<u8>,
    /// Arena bytes already published.
    arena_base: u64,
    /// Records already published.
    base: u64,
    modules: Vec<Module>,
    modules_base: usize,
    /// Models per device and the conversion of their motion values.
    units: Tracker,
    /// Every conversion given out so far (`Rec::module - 1` indexes them), and how many of
    /// them are published.
    scales: Vec<Scale>,
    scales_published: usize,
    units_notes: Vec<String>,
    /// Pair links and flags for already-published records: (record number, pair, flags to set).
    patches: Vec<(u64, u32, u16)>,
    series: BTreeMap<String, Vec<Point>>,
    not_for_model: Vec<(u64, [u8; 8])>,
    first_ts: Option<u64>,
    streams: Vec<String>,
    file_diags: Vec<(u64, String)>,
    last_flush: Instant,
    /// A followed (growing) file, to see when reading has caught up with it.
    follow: Option<std::fs::File>,
}

impl Indexer {
    /// An indexer; `proto` given: no detection.
    fn new(shared: Arc<Shared>, proto: Option<Proto>, units: UnitsOpts) -> Self {
        if let (Some(p), Ok(mut ix)) = (proto, shared.index.write()) {
            ix.proto = Some(p);
            ix.proto_certain = true;
        }
        Indexer {
            shared,
            proto,
            sample: vec![],
            sample_len: 0,
            lanes: vec![],
            pairers: vec![],
            buses: vec![],
            batch: Vec::with_capacity(4096),
            arena: Vec::with_capacity(1 << 16),
            arena_base: 0,
            base: 0,
            modules: vec![],
            modules_base: 0,
            units: Tracker::new(units),
            scales: vec![],
            scales_published: 0,
            units_notes: vec![],
            patches: vec![],
            series: BTreeMap::new(),
            not_for_model: vec![],
            first_ts: None,
            streams: vec![],
            file_diags: vec![],
            last_flush: Instant::now(),
            follow: None,
        }
    }

    fn run(mut self, mut reader: Box<dyn aptscope_capture::model::Reader>) {
        while let Some(ev) = reader.next_event() {
            if self.shared.cancel.load(Ordering::Relaxed) {
                return;
            }
            match ev {
                Event::Stream(s) => {
                    let i = s.id as usize;
                    if self.streams.len() <= i {
                        self.streams.resize(i + 1, String::new());
                    }
                    self.streams[i] = s.name.clone();
                }
                Event::Diag(d) => self
                    .file_diags
                    .push((d.offset, format!("{}: {}", d.kind, d.msg))),
                Event::Chunk(c) => {
                    let dir = match c.dir {
                        Direction::HostToDevice => 1,
                        Direction::DeviceToHost => 2,
                        Direction::Unknown => 0,
                    };
                    self.push(c.stream, dir, c.ts_ns, c.bytes);
                }
            }
            let caught_up = self.caught_up();
            // A followed file may stay short of the 4 KiB sample for long: a certain detection
            // on what there is shows its traffic now.
            if caught_up && self.proto.is_none() && !self.sample.is_empty() {
                self.choose(true);
            }
            if caught_up || self.last_flush.elapsed() > Duration::from_millis(50) {
                self.flush(false);
            }
        }
        self.finish();
        self.flush(true);
    }

    /// A followed file read to its current end: the reader may now wait long for the next
    /// event, so what has been read is published at once (not at the next event).
    fn caught_up(&self) -> bool {
        self.follow.as_ref().is_some_and(|f| {
            f.metadata()
                .is_ok_and(|m| self.shared.read.load(Ordering::Relaxed) >= m.len())
        })
    }

    fn push(&mut self, stream: u32, dir: u8, ts: Option<u64>, bytes: &[u8]) {
        if self.proto.is_none() {
            self.sample.push((stream, dir, ts, bytes.to_vec()));
            self.sample_len += bytes.len();
            if self.sample_len >= SAMPLE {
                self.choose(false);
            }
            return;
        }
        self.feed(stream, dir, ts, bytes);
    }

    /// Decide the protocol from the sample and index it; `only_certain`: only when detection
    /// is certain (else keep sampling). Returns whether it decided.
    fn choose(&mut self, only_certain: bool) -> bool {
        // Judge the busiest lane of the sample.
        let mut totals: BTreeMap<(u32, u8), usize> = BTreeMap::new();
        for (s, d, _, b) in &self.sample {
            *totals.entry((*s, *d)).or_default() += b.len();
        }
        let best = totals.iter().max_by_key(|(_, t)| **t).map(|(k, _)| *k);
        let mut bytes = Vec::with_capacity(SAMPLE);
        for (s, d, _, b) in &self.sample {
            if Some((*s, *d)) == best && bytes.len() < SAMPLE {
                bytes.extend_from_slice(b);
            }
        }
        let det = detect(&bytes);
        if only_certain && det.proto.is_none() {
            return false;
        }
        let proto = det.proto.unwrap_or(if det.elliptec > det.apt {
            Proto::Elliptec
        } else {
            Proto::Apt
        });
        self.proto = Some(proto);
        if let Ok(mut ix) = self.shared.index.write() {
            ix.proto = Some(proto);
            ix.proto_certain = det.proto.is_some();
        }
        for (s, d, ts, b) in std::mem::take(&mut self.sample) {
            self.feed(s, d, ts, &b);
        }
        self.sample_len = 0;
        true
    }

    fn lane(&mut self, stream: u32, dir: u8) -> usize {
        if let Some(i) = self
            .lanes
            .iter()
            .position(|l| l.stream == stream && l.dir == dir)
        {
            return i;
        }
        self.lanes.push(Lane {
            stream,
            dir,
            apt: AptFramer::new(Table::global()),
            ell: EllFramer::new(),
            ts: None,
        });
        self.lanes.len() - 1
    }

    fn feed(&mut self, stream: u32, dir: u8, ts: Option<u64>, bytes: &[u8]) {
        if self.first_ts.is_none() {
            self.first_ts = ts;
        }
        let i = self.lane(stream, dir);
        let lane = &mut self.lanes[i];
        if ts.is_some() {
            lane.ts = ts;
        }
        match self.proto {
            Some(Proto::Apt) => lane.apt.push(bytes),
            _ => {
                lane.ell.push(bytes);
                // Following a live capture, a host chunk is a host write (as the tap's own
                // timeline assumes): a command sent without terminator is framed now, not at
                // the host's next write.
                if self.follow.is_some() && dir == 1 {
                    lane.ell.cut();
                }
            }
        }
        self.drain(i);
    }

    fn finish(&mut self) {
        if self.proto.is_none() {
            if self.sample.is_empty() {
                return;
            }
            self.choose(false);
        }
        for i in 0..self.lanes.len() {
            self.lanes[i].apt.finish();
            self.lanes[i].ell.finish();
            self.drain(i);
        }
        let mut left = vec![];
        for (_, bus, _) in self.buses.iter_mut() {
            left.extend(bus.finish().into_iter().map(|e| e.n));
        }
        for (_, p) in self.pairers.iter_mut() {
            left.extend(p.finish().into_iter().map(|u| u.n));
        }
        for n in left {
            self.set(n, 0, F_NO_REPLY);
        }
    }

    /// Set a pair link (when `pair != 0` and none yet) and flags on record `n`.
    fn set(&mut self, n: u64, pair: u32, flags: u16) {
        if n > self.base {
            if let Some(r) = self.batch.get_mut((n - self.base - 1) as usize) {
                if r.pair == 0 {
                    r.pair = pair;
                }
                r.flags |= flags;
            }
        } else {
            self.patches.push((n, pair, flags));
        }
    }

    fn next_n(&self) -> u64 {
        self.base + self.batch.len() as u64 + 1
    }

    fn add(&mut self, lane: usize, offset: u64, bytes: &[u8], flags: u16) -> u64 {
        let l = &self.lanes[lane];
        let rec = Rec {
            start: self.arena_base + self.arena.len() as u64,
            offset,
            ts: l.ts.unwrap_or(u64::MAX),
            pair: 0,
            len: bytes.len() as u32,
            module: 0,
            stream: l.stream.min(u16::MAX as u32) as u16,
            flags,
            dir: l.dir,
        };
        self.arena.extend_from_slice(bytes);
        self.batch.push(rec);
        self.base + self.batch.len() as u64
    }

    fn x_of(&self, ts: Option<u64>, n: u64) -> f64 {
        match (ts, self.first_ts) {
            (Some(t), Some(f)) => t.saturating_sub(f) as f64 / 1e9,
            _ => n as f64,
        }
    }

    fn drain(&mut self, i: usize) {
        let t = Table::global();
        let (ts, stream, dir) = (self.lanes[i].ts, self.lanes[i].stream, self.lanes[i].dir);
        let cap_dir = match dir {
            1 => Some(Dir::HostToDevice),
            2 => Some(Dir::DeviceToHost),
            _ => None,
        };
        if self.proto == Some(Proto::Apt) {
            let pi = match self.pairers.iter().position(|(s, _)| *s == stream) {
                Some(p) => p,
                None => {
                    self.pairers.push((stream, AptPairer::new()));
                    self.pairers.len() - 1
                }
            };
            loop {
                let n = self.next_n();
                let Some(item) = self.lanes[i].apt.next_item() else {
                    break;
                };
                // Copy out what we need: the framer borrow ends here.
                let (offset, bytes, kind) = match item {
                    AptItem::Frame {
                        offset,
                        bytes,
                        truncated,
                    } => (offset, bytes.to_vec(), Err(truncated)),
                    AptItem::Garbage {
                        offset,
                        bytes,
                        kind,
                    } => (offset, bytes.to_vec(), Ok(kind)),
                };
                match kind {
                    Ok(k) => {
                        let f = F_GARBAGE
                            | match k {
                                GarbageKind::NoHeader => 0,
                                GarbageKind::AbsurdLength { .. } => F_ABSURD,
                                GarbageKind::TrailingBytes => F_TRAILING,
                            };
                        self.add(i, offset, &bytes, f);
                    }
                    Err(truncated) => {
                        let Some(fr) = AptFrame::decode(t, offset, &bytes, truncated) else {
                            self.add(i, offset, &bytes, F_GARBAGE);
                            continue;
                        };
                        let p = self.pairers[pi].1.observe(t, n, &fr, cap_dir, ts);
                        let mut flags = 0;
                        if truncated {
                            flags |= F_TRUNCATED;
                        }
                        if fr.has_diags() {
                            flags |= F_DIAG;
                        }
                        if p.unsolicited {
                            flags |= F_UNSOLICITED;
                        }
                        if p.duplicate {
                            flags |= F_DUPLICATE;
                        }
                        if p.other_address {
                            flags |= F_OTHER_ADDR;
                        }
                        if let Some(m) = p.not_for_model {
                            flags |= F_NOT_FOR_MODEL;
                            self.not_for_model.push((n, m));
                        }
                        let (scale, notice) = self.units.observe(stream, &fr);
                        if let Some(nt) = notice {
                            self.units_notes.push(nt.text());
                        }
                        let mut pts = vec![];
                        if let Some(name) = fr.name() {
                            if name.contains("STATUSUPDATE") || name.ends_with("GET_POSCOUNTER") {
                                let src = fr.src().name().to_string();
                                let ch =
                                    fr.channel().map(|c| format!(" ch{c}")).unwrap_or_default();
                                for q in ["position", "velocity"] {
                                    let Some((fd, v)) = fr.field(q) else {
                                        continue;
                                    };
                                    // In mm (deg) once the stage is known: its own series.
                                    match aptscope_dissector::apt::phys(fd, &v, scale) {
                                        Some((x, unit)) => {
                                            pts.push((format!("{q} {src}{ch} ({unit})"), x))
                                        }
                                        None => {
                                            if let Some(x) = v.as_f64() {
                                                pts.push((format!("{q} {src}{ch}"), x));
                                            }
                                        }
                                    }
                                }
                            }
                        }
                        let scale_id = match scale {
                            Some(sc) => match self.scales.iter().position(|x| x == sc) {
                                Some(i) => i as u32 + 1,
                                None => {
                                    self.scales.push(sc.clone());
                                    self.scales.len() as u32
                                }
                            },
                            None => 0,
                        };
                        let x = self.x_of(ts, n);
                        for (k, v) in pts {
                            self.series.entry(k).or_default().push((x, v));
                        }
                        for u in &p.expired {
                            self.set(u.n, 0, F_NO_REPLY);
                        }
                        if let Some(req) = p.pair {
                            flags |= F_IS_REPLY;
                            self.set(req, n as u32, 0);
                        }
                        let me = self.add(i, offset, &bytes, flags);
                        if let Some(r) = self.batch.last_mut() {
                            if let Some(req) = p.pair {
                                r.pair = req as u32;
                            }
                            r.module = scale_id;
                        }
                        let _ = me;
                    }
                }
            }
            return;
        }
        let bi = match self.buses.iter().position(|(s, _, _)| *s == stream) {
            Some(b) => b,
            None => {
                self.buses.push((stream, Bus::new(), vec![None; 16]));
                self.buses.len() - 1
            }
        };
        loop {
            let n = self.next_n();
            let Some(item) = self.lanes[i].ell.next_item() else {
                break;
            };
            let (offset, bytes, frame) = match item {
                EllItem::Frame {
                    offset,
                    bytes,
                    truncated,
                } => (offset, bytes.to_vec(), Some(truncated)),
                EllItem::Garbage { offset, bytes, .. } => (offset, bytes.to_vec(), None),
            };
            let Some(truncated) = frame else {
                self.add(i, offset, &bytes, F_ELL | F_GARBAGE);
                continue;
            };
            let Some(fr) = EllFrame::decode(offset, &bytes, truncated) else {
                self.add(i, offset, &bytes, F_ELL | F_GARBAGE);
                continue;
            };
            let o = self.buses[bi].1.observe(n, &fr, ts);
            let mut flags = F_ELL;
            if truncated {
                flags |= F_TRUNCATED;
            }
            if !fr.diags().is_empty() {
                flags |= F_DIAG;
            }
            if o.unsolicited {
                flags |= F_UNSOLICITED;
            }
            if o.interim {
                flags |= F_INTERIM;
            }
            for e in &o.expired {
                self.set(e.n, 0, F_NO_REPLY);
            }
            // Module: reuse the last entry for this address when unchanged.
            let mut module = 0u32;
            if let Some(m) = &o.module {
                let slot = (fr.addr & 15) as usize;
                let known =
                    self.buses[bi].2[slot].and_then(|ix| self.module_at(ix).map(|k| (ix, k == m)));
                module = match known {
                    Some((ix, true)) => ix,
                    _ => {
                        self.modules.push(m.clone());
                        let ix = (self.modules_base + self.modules.len()) as u32;
                        self.buses[bi].2[slot] = Some(ix);
                        ix
                    }
                };
                if fr.code == *b"PO" || fr.code == *b"GP" {
                    if let Some(p) = fr.field("position").and_then(|v| v.as_i64()) {
                        let (v, unit) = match m.scale() {
                            Some((ppu, u)) if ppu > 0.0 => (p as f64 / ppu, u),
                            _ => (p as f64, "pulses"),
                        };
                        let x = self.x_of(ts, n);
                        self.series
                            .entry(format!("position ell {} ({unit})", fr.addr_char()))
                            .or_default()
                            .push((x, v));
                    }
                }
            }
            if let Some(req) = o.pair {
                flags |= F_IS_REPLY;
                if !o.interim {
                    self.set(req, n as u32, 0);
                }
            }
            self.add(i, offset, &bytes, flags);
            if let Some(r) = self.batch.last_mut() {
                r.module = module;
                if let Some(req) = o.pair {
                    r.pair = req as u32;
                }
            }
        }
    }

    fn module_at(&self, ix: u32) -> Option<&Module> {
        let i = (ix as usize).checked_sub(1)?;
        if i >= self.modules_base {
            self.modules.get(i - self.modules_base)
        } else {
            None // published: treat as changed (cheap, rare)
        }
    }

    /// Publish the batch to the shared index.
    fn flush(&mut self, done: bool) {
        self.last_flush = Instant::now();
        let Ok(mut ix) = self.shared.index.write() else {
            return;
        };
        ix.recs.append(&mut self.batch);
        ix.arena.append(&mut self.arena);
        self.modules_base += self.modules.len();
        ix.modules.append(&mut self.modules);
        ix.scales
            .extend(self.scales[self.scales_published..].iter().cloned());
        self.scales_published = self.scales.len();
        ix.units_notes.append(&mut self.units_notes);
        for (n, pair, flags) in self.patches.drain(..) {
            if let Some(r) = (n as usize).checked_sub(1).and_then(|i| ix.recs.get_mut(i)) {
                if r.pair == 0 {
                    r.pair = pair;
                }
                r.flags |= flags;
            }
        }
        ix.not_for_model.extend(self.not_for_model.drain(..));
        for (k, v) in std::mem::take(&mut self.series) {
            ix.series.entry(k).or_default().extend(v);
        }
        ix.first_ts = self.first_ts;
        ix.streams.clone_from(&self.streams);
        ix.file_diags.append(&mut self.file_diags);
        self.base = ix.recs.len() as u64;
        self.arena_base = ix.arena.len() as u64;
        if done {
            ix.done = true;
            if ix.proto.is_none() {
                ix.proto = self.proto;
            }
        }
    }
}
