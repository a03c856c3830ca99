//! The capture index: every record (frame or garbage) of a capture, stored compactly (24 bytes
//! a record, [`Recs`]), built by a background thread while the UI already shows what has been
//! read.
//!
//! The records come from the one decode chain ([`aptscope_dissector::record::Decoder`]): the
//! indexer keeps of each [`Record`] what the timeline, filters and statistics read without
//! decoding (a [`Rec`]). Its bytes are read back from the capture file by position (a raw
//! capture) or from an arena the indexer writes to an unlinked scratch file (other formats, live
//! sources). Nothing rendered is stored: the UI decodes the rows it shows from those bytes.

use aptscope_capture::model::{Event, Reader};
use aptscope_capture::open::{open_with_progress, OpenOptions};
use aptscope_dissector::apt::GarbageKind;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::diag::DiagKind;
use aptscope_dissector::ell::Module;
use aptscope_dissector::hash::NumMap;
use aptscope_dissector::record::{AptRec, Ctx, Decoder, EllRec, GarbageRec, Record};
use aptscope_dissector::table::{Class, Dir};
use aptscope_dissector::units::{Scale, UnitsOpts};
use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
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

/// [`Rec::chan`] of a channel outside 0–253.
pub const CHAN_OTHER: u8 = u8::MAX;

/// A record as the index stores it, 24 bytes: [`Rec`] without its arena position and stream
/// offset (kept beside it only once they differ from its capture offset: they never do in a
/// raw capture, one stream whose every byte is a record's), its direction in the flags, its
/// capture offset, time and module relative to those of its [`Block`], and narrower fields
/// whose rare larger values ([`Wide`]) are kept beside it.
#[derive(Debug, Clone, Copy, Default)]
struct Packed {
    /// Time since the block's; [`NO_TS`]: not recorded.
    ts: u32,
    pair: u32,
    /// Capture offset after the block's (24 bits, little-endian).
    cap: [u8; 3],
    /// Stream.
    stream: u8,
    /// Length; [`NARROW`]: this record's values are in [`Recs::wide`].
    len: u16,
    /// Module or scale entry: 0 none, else after the block's (+ 1).
    module: u16,
    /// `F_*` flags, and the direction at [`DIR_SHIFT`].
    flags: u16,
    id: u16,
    /// Diagnostic kinds entry.
    diags: u8,
    src: u8,
    dst: u8,
    chan: u8,
}

// Memory per record of the index (a raw capture's: nothing beside it but a few blocks).
const _: () = assert!(std::mem::size_of::<Packed>() == 24);

/// [`Packed::len`] of a record with a value too large for its slot (in [`Recs::wide`]).
const NARROW: u16 = u16::MAX;

/// Records in a chunk of [`Recs::packed`] (1.5 MB).
const CHUNK: usize = 1 << 16;

/// [`Packed::ts`] of a record without time.
const NO_TS: u32 = u32::MAX;

/// Capture offsets a block spans.
const CAP_SPAN: u64 = 1 << 24;

/// How much earlier than its first record's time a block's time is (records of several
/// streams come a little out of time order).
const TS_BACK: u64 = 1 << 30;

/// Where [`Packed::flags`] keeps the direction (the `F_*` flags use the bits below).
const DIR_SHIFT: u16 = 13;

/// What the records from `first` on (to the next block) count their capture offset, time and
/// module from. A record that does not fit its block's ranges starts a new one.
#[derive(Debug, Clone, Copy)]
struct Block {
    first: u64,
    cap: u64,
    ts: u64,
    module: u32,
}

impl Block {
    /// The block a record would start.
    fn of(r: &Rec, prev: Option<&Block>) -> Block {
        Block {
            first: 0,
            // Room for records a little out of order (other streams, other directions).
            cap: r.cap_offset.saturating_sub(CAP_SPAN / 4),
            ts: r
                .ts()
                .map(|t| t.saturating_sub(TS_BACK))
                .or(prev.map(|b| b.ts))
                .unwrap_or(0),
            // Room for older entries than the record's (other devices' conversions).
            module: match r.module {
                0 => prev.map_or(1, |b| b.module),
                m => m.saturating_sub(u32::from(u16::MAX / 2)).max(1),
            },
        }
    }
    /// A record's capture offset, time and module relative to the block, when they fit.
    fn fit(&self, r: &Rec) -> Option<([u8; 3], u32, u16)> {
        let cap = r
            .cap_offset
            .checked_sub(self.cap)
            .filter(|&c| c < CAP_SPAN)?;
        let ts = match r.ts() {
            None => NO_TS,
            Some(t) => u32::try_from(t.checked_sub(self.ts)?)
                .ok()
                .filter(|&t| t != NO_TS)?,
        };
        let module = match r.module {
            0 => 0,
            m => u16::try_from(m.checked_sub(self.module)? + 1).ok()?,
        };
        let [a, b, c, _] = (cap as u32).to_le_bytes();
        Some(([a, b, c], ts, module))
    }
}

/// The values of a record that do not fit its [`Packed`] slot.
#[derive(Debug, Clone, Copy)]
struct Wide {
    len: u32,
    stream: u16,
    diags: u16,
}

/// The records of the index in timeline order, stored packed ([`Recs::get`] gives a [`Rec`]).
#[derive(Debug, Default)]
pub struct Recs {
    /// The records in chunks of [`CHUNK`]: growing never copies them (nor needs twice
    /// their memory for a moment, as a doubling vector does).
    packed: Vec<Vec<Packed>>,
    len: usize,
    /// The blocks, by first record.
    blocks: Vec<Block>,
    /// Where the records' arena starts are.
    starts: Starts,
    /// The stream offset of every record, once one has it apart from its capture offset; empty
    /// until then.
    apart: Vec<u64>,
    /// Records (by index, in order) with a value too large for their slot.
    wide: Vec<(u64, Wide)>,
    /// Where chunks go once the records in memory would exceed [`Recs::budget`]: the first
    /// `spilled` chunks are in this file (their entries in `packed` emptied).
    spill: Option<Arc<Spill>>,
    spilled: usize,
    /// Bytes of records kept in memory at most; `None`: [`index_memory`].
    budget: Option<usize>,
    /// Bumped when a spilled record is patched: chunks read back before are stale.
    spill_gen: u64,
}

/// Where the records' arena starts ([`Rec::start`]) are.
#[derive(Debug, Default)]
enum Starts {
    /// At their capture offsets (a raw capture read back from the file).
    #[default]
    Cap,
    /// One after the other from the first (the indexer writes the arena in record order): the
    /// start of every [`MARK`]th record kept, the others' found by adding the lengths before
    /// them; `next` is where the next record starts.
    Marks { marks: Vec<u64>, next: u64 },
    /// Each its own (records that are neither).
    All(Vec<u64>),
}

/// Records per kept start in [`Starts::Marks`] (half a byte a record).
const MARK: usize = 16;

/// The file the records over the memory budget are written to, chunk after chunk.
#[derive(Debug)]
struct Spill {
    file: std::fs::File,
    /// Tells this file's chunks from another index's in [`SPILLED`].
    id: u64,
}

/// Bytes of a chunk of records in a [`Spill`].
const CHUNK_BYTES: usize = CHUNK * std::mem::size_of::<Packed>();

/// Spilled chunks a thread keeps read back (6 MB).
const SPILLED_KEPT: usize = 4;

thread_local! {
    /// The spilled chunks this thread read back last: (spill id, [`Recs::spill_gen`], chunk
    /// number, its records), the newest last.
    static SPILLED: std::cell::RefCell<Vec<KeptChunk>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// A spilled chunk read back: (spill id, generation, chunk number, its records).
type KeptChunk = (u64, u64, usize, Vec<Packed>);

impl Packed {
    /// The record as it is written to a [`Spill`].
    fn to_bytes(self) -> [u8; 24] {
        let mut b = [0u8; 24];
        b[0..4].copy_from_slice(&self.ts.to_le_bytes());
        b[4..8].copy_from_slice(&self.pair.to_le_bytes());
        b[8..11].copy_from_slice(&self.cap);
        b[11] = self.stream;
        b[12..14].copy_from_slice(&self.len.to_le_bytes());
        b[14..16].copy_from_slice(&self.module.to_le_bytes());
        b[16..18].copy_from_slice(&self.flags.to_le_bytes());
        b[18..20].copy_from_slice(&self.id.to_le_bytes());
        [b[20], b[21], b[22], b[23]] = [self.diags, self.src, self.dst, self.chan];
        b
    }
    /// A record read back from a [`Spill`].
    fn from_bytes(b: &[u8; 24]) -> Packed {
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Packed {
            ts: u32_at(0),
            pair: u32_at(4),
            cap: [b[8], b[9], b[10]],
            stream: b[11],
            len: u16_at(12),
            module: u16_at(14),
            flags: u16_at(16),
            id: u16_at(18),
            diags: b[20],
            src: b[21],
            dst: b[22],
            chan: b[23],
        }
    }
}

/// The memory the index's records may take before older ones are written to a scratch file
/// ([`set_index_memory`], else a quarter of the machine's memory).
pub fn index_memory() -> usize {
    match INDEX_MEMORY.load(Ordering::Relaxed) {
        0 => {
            static QUARTER: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
            *QUARTER.get_or_init(|| mem_total().map_or(usize::MAX, |t| t / 4))
        }
        b => usize::try_from(b).unwrap_or(usize::MAX),
    }
}

/// Set the memory budget of the indexes made from now on ([`index_memory`]; `aptscope view
/// --index-memory`).
pub fn set_index_memory(bytes: u64) {
    INDEX_MEMORY.store(bytes.max(1), Ordering::Relaxed);
}

static INDEX_MEMORY: AtomicU64 = AtomicU64::new(0);

/// The machine's memory (`MemTotal` of `/proc/meminfo`).
fn mem_total() -> Option<usize> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// A size as `--index-memory` takes it: bytes, or with a suffix `K`, `M`, `G`, `T` (powers
/// of 1024; `512M`, `1.5G`, `2GiB`).
pub fn parse_size(s: &str) -> Option<u64> {
    let s = s.trim();
    let t = s
        .strip_suffix("iB")
        .or_else(|| s.strip_suffix('B'))
        .unwrap_or(s);
    let (num, unit) = match t.char_indices().last()? {
        (i, c) if c.is_ascii_alphabetic() => (&t[..i], c.to_ascii_uppercase()),
        _ => (t, ' '),
    };
    let mult = match unit {
        ' ' => 1u64,
        'K' => 1 << 10,
        'M' => 1 << 20,
        'G' => 1 << 30,
        'T' => 1 << 40,
        _ => return None,
    };
    let x: f64 = num.trim().parse().ok()?;
    let b = x * mult as f64;
    (x.is_finite() && x > 0.0 && b < u64::MAX as f64).then_some(b as u64)
}

impl Recs {
    /// Number of records.
    pub fn len(&self) -> usize {
        self.len
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// The block of record index `i`.
    fn block_of(&self, i: usize) -> usize {
        self.blocks
            .partition_point(|b| b.first <= i as u64)
            .saturating_sub(1)
    }
    /// Record at index `i` (record number `i + 1`).
    pub fn get(&self, i: usize) -> Option<Rec> {
        self.unpack(i, self.block_of(i), None)
    }
    /// The packed record at index `i`, from memory or its spilled chunk.
    #[inline]
    fn packed_at(&self, i: usize) -> Option<Packed> {
        let c = i / CHUNK;
        if c >= self.spilled {
            return self.packed.get(c)?.get(i % CHUNK).copied();
        }
        let spill = self.spill.as_ref()?;
        let key = (spill.id, self.spill_gen, c);
        SPILLED.with_borrow_mut(|kept| {
            if let Some(k) = kept.iter().position(|e| (e.0, e.1, e.2) == key) {
                return kept[k].3.get(i % CHUNK).copied();
            }
            use std::os::unix::fs::FileExt;
            let mut buf = vec![0u8; CHUNK_BYTES];
            spill
                .file
                .read_exact_at(&mut buf, (c * CHUNK_BYTES) as u64)
                .ok()?;
            let recs: Vec<Packed> = buf
                .chunks_exact(24)
                .filter_map(|b| b.try_into().ok().map(Packed::from_bytes))
                .collect();
            let p = recs.get(i % CHUNK).copied();
            if kept.len() >= SPILLED_KEPT {
                kept.remove(0);
            }
            kept.push((key.0, key.1, key.2, recs));
            p
        })
    }
    /// Keep the records in memory within the budget: write the oldest full chunks to the
    /// spill file (made at the first), and free them. The chunk being filled stays (the
    /// pairing's patches go mostly to recent records).
    fn spill_over(&mut self) {
        let budget = self.budget.unwrap_or_else(index_memory);
        while (self.packed.len() - self.spilled) * CHUNK_BYTES > budget
            && self.spilled + 1 < self.packed.len()
        {
            if self.spill.is_none() {
                static NEXT: AtomicU64 = AtomicU64::new(1);
                match scratch_file("index") {
                    Some(file) => {
                        let id = NEXT.fetch_add(1, Ordering::Relaxed);
                        self.spill = Some(Arc::new(Spill { file, id }));
                    }
                    None => {
                        // Nowhere to write: the records stay in memory.
                        self.budget = Some(usize::MAX);
                        return;
                    }
                }
            }
            let Some(spill) = &self.spill else {
                return;
            };
            let c = self.spilled;
            let mut buf = Vec::with_capacity(CHUNK_BYTES);
            for p in &self.packed[c] {
                buf.extend_from_slice(&p.to_bytes());
            }
            use std::os::unix::fs::FileExt;
            if spill
                .file
                .write_all_at(&buf, (c * CHUNK_BYTES) as u64)
                .is_err()
            {
                self.budget = Some(usize::MAX);
                return;
            }
            self.packed[c] = Vec::new();
            self.spilled += 1;
        }
    }
    /// Keep at most `bytes` of records in memory (older ones go to a scratch file); the
    /// default is [`index_memory`].
    pub fn set_budget(&mut self, bytes: usize) {
        self.budget = Some(bytes);
    }
    /// Chunks of records written to the scratch file (none while within the budget).
    pub fn spilled_chunks(&self) -> usize {
        self.spilled
    }
    /// Record at index `i` of block `b` (`start_hint`: its arena start, when the caller knows
    /// it).
    fn unpack(&self, i: usize, b: usize, start_hint: Option<u64>) -> Option<Rec> {
        let p = &self.packed_at(i)?;
        let b = self.blocks.get(b)?;
        let [x, y, z] = p.cap;
        let cap_offset = b.cap + u64::from(u32::from_le_bytes([x, y, z, 0]));
        let mut r = Rec {
            start: cap_offset,
            offset: cap_offset,
            cap_offset,
            ts: match p.ts {
                NO_TS => u64::MAX,
                t => b.ts + u64::from(t),
            },
            pair: p.pair,
            len: u32::from(p.len),
            module: match p.module {
                0 => 0,
                m => b.module + u32::from(m) - 1,
            },
            stream: u16::from(p.stream),
            flags: p.flags & ((1 << DIR_SHIFT) - 1),
            dir: (p.flags >> DIR_SHIFT) as u8,
            src: p.src,
            dst: p.dst,
            id: p.id,
            diags: u16::from(p.diags),
            chan: p.chan,
        };
        if p.len == NARROW {
            let w = self.wide.binary_search_by_key(&(i as u64), |(j, _)| *j);
            if let Some((_, w)) = w.ok().and_then(|k| self.wide.get(k)) {
                r.len = w.len;
                r.stream = w.stream;
                r.diags = w.diags;
            }
        }
        r.start = match &self.starts {
            Starts::Cap => r.cap_offset,
            Starts::Marks { .. } => match start_hint {
                Some(s) => s,
                None => self.start_of(i)?,
            },
            Starts::All(v) => *v.get(i)?,
        };
        if let Some(&offset) = self.apart.get(i) {
            r.offset = offset;
        }
        Some(r)
    }
    /// The length of record index `i`.
    fn len_at(&self, i: usize) -> Option<u64> {
        let p = self.packed_at(i)?;
        if p.len != NARROW {
            return Some(u64::from(p.len));
        }
        let k = self
            .wide
            .binary_search_by_key(&(i as u64), |(j, _)| *j)
            .ok()?;
        self.wide.get(k).map(|(_, w)| u64::from(w.len))
    }
    /// The arena start of record index `i` (its mark's, and the lengths between).
    fn start_of(&self, i: usize) -> Option<u64> {
        match &self.starts {
            Starts::Cap => self.get(i).map(|r| r.cap_offset),
            Starts::Marks { marks, .. } => {
                let m = i / MARK;
                let mut s = *marks.get(m)?;
                for j in m * MARK..i {
                    s += self.len_at(j)?;
                }
                Some(s)
            }
            Starts::All(v) => v.get(i).copied(),
        }
    }
    /// The last record.
    pub fn last(&self) -> Option<Rec> {
        self.get(self.len().checked_sub(1)?)
    }
    /// Records from index `from` (record number `from + 1`) to the end.
    pub fn iter_from(&self, from: usize) -> impl Iterator<Item = Rec> + '_ {
        let mut b = self.block_of(from);
        // The next record's arena start, after the one before (records are contiguous there).
        let mut next = None;
        (from..self.len()).filter_map(move |i| {
            while self.blocks.get(b + 1).is_some_and(|x| x.first <= i as u64) {
                b += 1;
            }
            let r = self.unpack(i, b, next)?;
            next = Some(r.start + u64::from(r.len));
            Some(r)
        })
    }
    /// All records.
    pub fn iter(&self) -> impl Iterator<Item = Rec> + '_ {
        self.iter_from(0)
    }
    /// Append a record.
    pub fn push(&mut self, r: Rec) {
        let i = self.len;
        let apart = r.offset != r.cap_offset;
        if apart && self.apart.len() < i {
            // The first record kept apart: the ones before are given theirs.
            self.apart = self.iter().map(|r| r.cap_offset).collect();
        }
        if apart || !self.apart.is_empty() {
            self.apart.push(r.offset);
        }
        let end = r.start + u64::from(r.len);
        let kept = match &mut self.starts {
            Starts::Cap => r.start == r.cap_offset,
            Starts::Marks { marks, next } if *next == r.start => {
                if i.is_multiple_of(MARK) {
                    marks.push(r.start);
                }
                *next = end;
                true
            }
            _ => false,
        };
        if !kept {
            if i == 0 {
                self.starts = Starts::Marks {
                    marks: vec![r.start],
                    next: end,
                };
            } else {
                if !matches!(self.starts, Starts::All(_)) {
                    // The first record out of line: every start kept from now on.
                    let all = (0..i).map(|j| self.start_of(j).unwrap_or(0)).collect();
                    self.starts = Starts::All(all);
                }
                if let Starts::All(v) = &mut self.starts {
                    v.push(r.start);
                }
            }
        }
        let fit = self.blocks.last().and_then(|b| b.fit(&r));
        let Some((cap, ts, module)) = fit.or_else(|| {
            let b = Block {
                first: i as u64,
                ..Block::of(&r, self.blocks.last())
            };
            self.blocks.push(b);
            b.fit(&r)
        }) else {
            // A new block always fits its first record.
            return;
        };
        let narrow = |x: u32, max: u32| x < max;
        let fits = narrow(r.len, u32::from(NARROW))
            && narrow(r.stream.into(), 256)
            && narrow(r.diags.into(), 256);
        if !fits {
            self.wide.push((
                i as u64,
                Wide {
                    len: r.len,
                    stream: r.stream,
                    diags: r.diags,
                },
            ));
        }
        if self.packed.last().is_none_or(|c| c.len() == CHUNK) {
            if !self.packed.is_empty() {
                self.spill_over();
            }
            self.packed.push(Vec::with_capacity(CHUNK));
        }
        let Some(chunk) = self.packed.last_mut() else {
            return;
        };
        self.len += 1;
        chunk.push(Packed {
            ts,
            pair: r.pair,
            cap,
            stream: if fits { r.stream as u8 } else { 0 },
            len: if fits { r.len as u16 } else { NARROW },
            module,
            flags: r.flags | u16::from(r.dir) << DIR_SHIFT,
            id: r.id,
            diags: if fits { r.diags as u8 } else { 0 },
            src: r.src,
            dst: r.dst,
            chan: r.chan,
        });
    }
    /// Set the pair link of record index `i` (when it has none) and add `flags`; gives the
    /// flags it had.
    fn patch(&mut self, i: usize, pair: u32, flags: u16) -> Option<u16> {
        if i / CHUNK < self.spilled {
            // Rare (a request's timeout passing long after it): patched in the file, read
            // alone (not through its chunk: the next patch would read that again).
            use std::os::unix::fs::FileExt;
            let at = (i * std::mem::size_of::<Packed>()) as u64;
            let file = &self.spill.as_ref()?.file;
            let mut b = [0u8; 24];
            file.read_exact_at(&mut b, at).ok()?;
            let mut p = Packed::from_bytes(&b);
            if p.pair == 0 {
                p.pair = pair;
            }
            let was = p.flags & ((1 << DIR_SHIFT) - 1);
            p.flags |= flags;
            file.write_all_at(&p.to_bytes(), at).ok()?;
            self.spill_gen += 1;
            return Some(was);
        }
        let p = self.packed.get_mut(i / CHUNK)?.get_mut(i % CHUNK)?;
        if p.pair == 0 {
            p.pair = pair;
        }
        let was = p.flags & ((1 << DIR_SHIFT) - 1);
        p.flags |= flags;
        Some(was)
    }
    /// Bytes the records take in memory (their capacity; spilled chunks not counted).
    pub fn memory(&self) -> usize {
        self.packed.iter().map(Vec::capacity).sum::<usize>() * std::mem::size_of::<Packed>()
            + self.blocks.capacity() * std::mem::size_of::<Block>()
            + self.apart.capacity() * std::mem::size_of::<u64>()
            + match &self.starts {
                Starts::Cap => 0,
                Starts::Marks { marks: v, .. } | Starts::All(v) => v.capacity() * 8,
            }
            + self.wide.capacity() * std::mem::size_of::<(u64, Wide)>()
    }
    /// Number of blocks (the records' bases).
    pub fn blocks(&self) -> usize {
        self.blocks.len()
    }
}

impl Extend<Rec> for Recs {
    fn extend<I: IntoIterator<Item = Rec>>(&mut self, it: I) {
        for r in it {
            self.push(r);
        }
    }
}

impl FromIterator<Rec> for Recs {
    fn from_iter<I: IntoIterator<Item = Rec>>(it: I) -> Self {
        let mut recs = Recs::default();
        recs.extend(it);
        recs
    }
}

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

/// Where the viewer keeps its files: `$XDG_CACHE_HOME/aptscope`, else `~/.cache/aptscope`,
/// else the temporary directory (whichever can be made).
pub fn cache_dir() -> std::path::PathBuf {
    let home = std::env::var_os("HOME").map(|h| std::path::PathBuf::from(h).join(".cache"));
    let xdg = std::env::var_os("XDG_CACHE_HOME")
        .map(std::path::PathBuf::from)
        .filter(|p| p.is_absolute());
    xdg.or(home)
        .map(|d| d.join("aptscope"))
        .filter(|d| std::fs::create_dir_all(d).is_ok())
        .unwrap_or_else(std::env::temp_dir)
}

/// A new file of the viewer's own, already unlinked (it goes when the process does, however it
/// ends), opened for reading and writing: in [`cache_dir`], else the temporary directory.
pub(crate) fn scratch_file(what: &str) -> Option<std::fs::File> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let name = format!("{what}-{}-{n}.tmp", std::process::id());
    [cache_dir(), std::env::temp_dir()].iter().find_map(|d| {
        let p = d.join(&name);
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&p)
            .ok()?;
        let _ = std::fs::remove_file(&p);
        Some(f)
    })
}

/// A file for the arena: the indexer's handle to write it, and the index's to read it back.
fn arena_file_pair() -> Option<(std::fs::File, ReadBack)> {
    let f = scratch_file("arena")?;
    let back = f.try_clone().ok()?;
    Some((f, ReadBack::of(back)))
}

/// A capture file records' bytes are read back from ([`Index::file`]).
#[derive(Debug)]
pub struct ReadBack {
    file: std::fs::File,
    /// Tells this file's [`WINDOW`] from another index's.
    id: u64,
}

/// Bytes read back at once: records read in order (a filter's scan, a screen of rows) cost one
/// read of the file per window, not one each.
const WINDOW_LEN: usize = 64 << 10;

thread_local! {
    /// The part of a file this thread read back last: ([`ReadBack::id`], its file position,
    /// its bytes).
    static WINDOW: std::cell::RefCell<(u64, u64, Vec<u8>)> =
        const { std::cell::RefCell::new((0, 0, Vec::new())) };
}

impl ReadBack {
    /// Read records' bytes back from the file at `path`.
    pub fn open(path: &str) -> std::io::Result<Self> {
        Ok(Self::of(std::fs::File::open(path)?))
    }

    /// Read back from an open file.
    fn of(file: std::fs::File) -> Self {
        static NEXT: AtomicU64 = AtomicU64::new(1);
        ReadBack {
            file,
            id: NEXT.fetch_add(1, Ordering::Relaxed),
        }
    }

    /// The `len` bytes at `at`, when the file has them.
    fn read(&self, at: u64, len: usize) -> Option<Vec<u8>> {
        use std::os::unix::fs::FileExt;
        if len > WINDOW_LEN {
            let mut buf = vec![0; len];
            return self.file.read_exact_at(&mut buf, at).ok().map(|()| buf);
        }
        WINDOW.with_borrow_mut(|(id, start, buf)| {
            let end = at.checked_add(len as u64)?;
            let inside = *id == self.id && at >= *start && end <= *start + buf.len() as u64;
            if !inside {
                buf.resize(WINDOW_LEN, 0);
                let mut got = 0;
                while got < WINDOW_LEN {
                    match self.file.read_at(&mut buf[got..], at + got as u64) {
                        Ok(0) => break,
                        Ok(n) => got += n,
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                        Err(_) => break,
                    }
                }
                buf.truncate(got);
                (*id, *start) = (self.id, at);
            }
            let from = usize::try_from(at - *start).ok()?;
            buf.get(from..from + len).map(<[u8]>::to_vec)
        })
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
    spawn_source(
        move || {
            let (reader, _, progress) = open_with_progress(&path, opts)?;
            Ok((reader, Some(progress)))
        },
        iopts,
    )
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
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("aptscope-index".into())
        .spawn(move || match open() {
            Ok((reader, progress)) => {
                let input = progress.clone();
                let shared = shared_for(reader.as_ref(), progress, &opts);
                let from_file = read_back(&shared, reader.as_ref(), opts.file.as_deref());
                let _ = tx.send(Ok(shared.clone()));
                let mut ix = Indexer::new(shared, opts.proto, opts.units);
                ix.sink.from_file = from_file;
                ix.follow = opts.follow.and_then(|p| std::fs::File::open(p).ok());
                ix.input = input;
                ix.run(reader);
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

/// Records published at once at most (their [`Rec`]s take 3.7 MB): the indexer's batch, the
/// ones in flight to the publishing thread and the spare stay small beside the index.
const MAX_BATCH: usize = 1 << 16;

/// How long read records may wait before they are published.
const FLUSH_EVERY: Duration = Duration::from_millis(50);

/// Conversions remembered for reuse (one per device).
const MAX_SCALE_AT: usize = 4096;

/// Series keys remembered (beyond, series are found by name).
const MAX_SERIES_OF: usize = 4096;

/// Which plotted quantity a series holds.
const QUANTITIES: [&str; 2] = ["position", "velocity"];

/// What the indexer keeps of the records: a batch not yet published and what it needs to link
/// records that are.
#[derive(Default)]
struct Sink {
    /// Records not yet published, numbered from `base + 1`.
    batch: Vec<Rec>,
    arena: Vec<u8>,
    /// Arena bytes already published.
    arena_base: u64,
    /// Records' bytes are read back from the capture file ([`Index::file`]): none kept.
    from_file: bool,
    /// Where published arena bytes are written ([`Index::arena_file`]), once made.
    arena_out: Option<std::fs::File>,
    /// Whether making it was tried (or is not wanted: the bytes stay in memory).
    arena_tried: bool,
    /// Records already published.
    base: u64,
    proto: Option<(Proto, bool, f64)>,
    modules: Vec<Module>,
    modules_base: usize,
    /// Per stream, the module entry last given to each bus address.
    slots: Vec<(u32, [Option<u32>; 16])>,
    /// The conversions given out since the last publication (entries from `scales_published`
    /// on; `Rec::module - 1` indexes them all), and how many were published before.
    scales: Vec<Scale>,
    scales_published: usize,
    /// The entry given for each revision of a conversion ([`Scale::revision`]).
    scale_at: NumMap<u64, u32>,
    units_notes: Vec<String>,
    /// Pair links and flags for already-published records: (record number, pair, flags to set).
    patches: Vec<(u64, u32, u16)>,
    /// Plot series by key, points not yet published; `series_at` finds a key's entry.
    series: Vec<(String, Vec<Point>)>,
    series_at: HashMap<String, usize>,
    /// The series of (message id, source, channel, quantity, scale revision): a status update
    /// finds its series without formatting and hashing its name.
    series_of: NumMap<(u16, u8, Option<i64>, u8, u64), usize>,
    /// Lists of diagnostic kinds given out (`Rec::diags - 1`), how many are published, and
    /// the entry of each.
    diag_sets: Vec<Vec<&'static str>>,
    diag_sets_published: usize,
    diag_set_ids: HashMap<Vec<&'static str>, u16>,
    kinds: Vec<&'static str>,
    /// Whether an APT message id is plotted: 0 not known yet, 1 yes, 2 no.
    plotted: Vec<u8>,
    scratch: String,
    not_for_model: Vec<(u64, [u8; 8])>,
    first_ts: Option<u64>,
    streams: Vec<String>,
    /// Whether `streams` changed since the last publication.
    streams_changed: bool,
    streams_seen: u64,
    file_diags: Vec<(u64, String)>,
}

impl Sink {
    fn on(&mut self, rec: &Record<'_>) -> Result<(), ()> {
        match rec {
            Record::Detect {
                proto, detection, ..
            } => {
                let share = match proto {
                    Proto::Apt => detection.apt,
                    Proto::Elliptec => detection.elliptec,
                };
                self.proto = Some((*proto, detection.proto.is_some(), share))
            }
            Record::Stream { id, name, .. } => {
                let i = *id as usize;
                if self.streams.len() <= i {
                    self.streams.resize(i + 1, String::new());
                }
                self.streams[i] = name.to_string();
                self.streams_changed = true;
            }
            Record::Input(d) => self
                .file_diags
                .push((d.offset, format!("{}: {}", d.kind.name(), d.kind))),
            Record::FileDiag { offset, kind, msg } => {
                self.file_diags.push((*offset, format!("{kind}: {msg}")))
            }
            Record::Units(nt) => self.units_notes.push(nt.text()),
            Record::Apt(a) => self.apt(a),
            Record::Ell(e) => self.ell(e),
            Record::Garbage(g) => self.garbage(g),
            Record::NoReply(e) => self.set(e.n, 0, F_NO_REPLY),
        }
        Ok(())
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

    /// Append record `n` (numbers the decoder skipped get an empty garbage record, so that
    /// record `n` stays at index `n - 1`). Inlined so that the record is written straight into
    /// the batch, not built on the stack and copied (a store-forwarding stall per record).
    #[inline(always)]
    fn add(&mut self, n: u64, mut rec: Rec, bytes: &[u8]) {
        while self.base + (self.batch.len() as u64) + 1 < n {
            // Read back from the file, a record starts at its capture offset (and is then
            // stored without a position apart from it).
            let start = match self.from_file {
                true => rec.cap_offset,
                false => self.arena_base + self.arena.len() as u64,
            };
            self.batch.push(Rec {
                start,
                len: 0,
                flags: F_GARBAGE | (rec.flags & F_ELL),
                ..rec
            });
        }
        rec.len = bytes.len() as u32;
        if rec.stream < 64 {
            self.streams_seen |= 1 << rec.stream;
        }
        if self.from_file {
            rec.start = rec.cap_offset;
        } else {
            rec.start = self.arena_base + self.arena.len() as u64;
            self.arena.extend_from_slice(bytes);
        }
        self.batch.push(rec);
    }

    /// Add a point to the series named by `self.scratch`.
    fn point(&mut self, x: f64, y: f64) {
        let i = self.series_index();
        self.series[i].1.push((x, y));
    }

    /// The entry of the series named by `self.scratch` (made if new).
    fn series_index(&mut self) -> usize {
        match self.series_at.get(self.scratch.as_str()) {
            Some(i) => *i,
            None => {
                self.series.push((self.scratch.clone(), vec![]));
                self.series_at
                    .insert(self.scratch.clone(), self.series.len() - 1);
                self.series.len() - 1
            }
        }
    }

    /// A frame's own diagnostics: `F_DIAG` (and `F_TRUNCATED`) into `flags`, and the entry of
    /// their kinds ([`Sink::diag_set`]).
    fn frame_diags(&mut self, kinds: impl Iterator<Item = DiagKind>, flags: &mut u16) -> u16 {
        self.kinds.clear();
        for k in kinds {
            *flags |= F_DIAG;
            if matches!(k, DiagKind::Truncated { .. }) {
                *flags |= F_TRUNCATED;
            }
            self.kinds.push(k.name());
        }
        self.diag_set()
    }

    /// The entry (+ 1) of the diagnostic kinds in `self.kinds`; 0 when there are none, or too
    /// many lists (filters then decode the frame).
    fn diag_set(&mut self) -> u16 {
        if self.kinds.is_empty() {
            return 0;
        }
        if let Some(id) = self.diag_set_ids.get(&self.kinds) {
            return *id;
        }
        if self.diag_sets.len() >= u16::MAX as usize - 1 {
            return 0;
        }
        self.diag_sets.push(self.kinds.clone());
        let id = self.diag_sets.len() as u16;
        self.diag_set_ids.insert(self.kinds.clone(), id);
        id
    }

    /// The entry of a conversion in `scales` (+ 1): the one kept for its revision (a
    /// device's conversion changes seldom), else a new one.
    fn scale_id(&mut self, sc: &Scale) -> u32 {
        let key = sc.revision();
        if let Some(&id) = self.scale_at.get(&key) {
            return id;
        }
        self.scales.push(sc.clone());
        let id = (self.scales_published + self.scales.len()) as u32;
        if self.scale_at.len() >= MAX_SCALE_AT {
            self.scale_at.clear();
        }
        self.scale_at.insert(key, id);
        id
    }

    fn apt(&mut self, a: &AptRec<'_>) {
        use std::fmt::Write;
        let (fr, p, m) = (a.frame, a.pair, &a.meta);
        let h = fr.header();
        let mut flags = 0;
        // A clean frame (the common case) does not walk its diagnostic bits.
        let diags = if fr.has_diags() {
            self.frame_diags(fr.diags().map(|d| d.kind), &mut flags)
        } else {
            0
        };
        if p.unsolicited {
            flags |= F_UNSOLICITED;
        }
        if p.duplicate {
            flags |= F_DUPLICATE;
        }
        if p.other_address {
            flags |= F_OTHER_ADDR;
        }
        if let Some(model) = p.not_for_model {
            flags |= F_NOT_FOR_MODEL;
            self.not_for_model.push((m.n, model));
        }
        if let Some(req) = p.pair {
            flags |= F_IS_REPLY;
            self.set(req, m.n as u32, 0);
        }
        let module = match a.scale {
            Some(sc) => self.scale_id(sc),
            None => 0,
        };
        // Positions and velocities of status updates, for the plot.
        if let Some(msg) = fr.msg {
            let id = h.msg_id() as usize;
            if self.plotted.is_empty() {
                self.plotted = vec![0; 1 << 16];
            }
            if self.plotted[id] == 0 {
                let yes = msg.class.has(Class::STATUS) || msg.class.has(Class::READING);
                self.plotted[id] = if yes { 1 } else { 2 };
            }
            if self.plotted[id] == 1 {
                let x = m.rel_s.unwrap_or(m.n as f64);
                let chan = fr.channel();
                for (qi, q) in QUANTITIES.iter().enumerate() {
                    let Some((fd, v)) = fr.field(q) else {
                        continue;
                    };
                    // In mm (deg) once the stage is known: its own series.
                    let phys = aptscope_dissector::apt::phys(fd, &v, a.scale);
                    let Some(y) = phys.map(|(y, _)| y).or_else(|| v.as_f64()) else {
                        continue;
                    };
                    let rev = a
                        .scale
                        .filter(|_| phys.is_some())
                        .map_or(0, |sc| sc.revision());
                    let key = (h.msg_id(), h.src_byte(), chan, qi as u8, rev);
                    let i = match self.series_of.get(&key) {
                        Some(&i) => i,
                        None => {
                            self.scratch.clear();
                            let _ = write!(self.scratch, "{q} {}", fr.src().name());
                            if let Some(c) = chan {
                                let _ = write!(self.scratch, " ch{c}");
                            }
                            if let Some((_, unit)) = phys {
                                let _ = write!(self.scratch, " ({unit})");
                            }
                            let i = self.series_index();
                            if self.series_of.len() < MAX_SERIES_OF {
                                self.series_of.insert(key, i);
                            }
                            i
                        }
                    };
                    self.series[i].1.push((x, y));
                }
            }
        }
        let rec = Rec {
            start: 0,
            offset: fr.offset,
            cap_offset: m.cap_offset,
            ts: m.ts_ns.unwrap_or(u64::MAX),
            pair: p.pair.map_or(0, |r| r as u32),
            len: 0,
            module,
            stream: m.stream.min(u16::MAX as u32) as u16,
            flags,
            dir: dir_code(m.cap_dir),
            src: h.src_byte(),
            dst: h.dst_byte(),
            id: h.msg_id(),
            diags,
            chan: chan_code(fr.channel()),
        };
        self.add(m.n, rec, fr.bytes);
    }

    fn ell(&mut self, e: &EllRec<'_>) {
        let (fr, o, m) = (e.frame, e.obs, &e.meta);
        let mut flags = F_ELL;
        // The decoder adds the bus's `unsolicited` to the frame's diagnostics: a flag of its own.
        let kinds = fr.diags().iter().map(|d| d.kind);
        let diags = self.frame_diags(kinds.filter(|k| *k != DiagKind::Unsolicited), &mut flags);
        if o.unsolicited {
            flags |= F_UNSOLICITED;
        }
        if o.interim {
            flags |= F_INTERIM;
        }
        if let Some(req) = o.pair {
            flags |= F_IS_REPLY;
            if !o.interim {
                self.set(req, m.n as u32, 0);
            }
        }
        // Module: reuse the last entry of this address while it is unchanged.
        let mut module = 0u32;
        if let Some(md) = &o.module {
            let si = match self.slots.iter().position(|(s, _)| *s == m.stream) {
                Some(i) => i,
                None => {
                    self.slots.push((m.stream, [None; 16]));
                    self.slots.len() - 1
                }
            };
            let slot = (fr.addr & 15) as usize;
            let known = self.slots[si].1[slot].and_then(|ix| {
                let i = (ix as usize).checked_sub(1 + self.modules_base)?;
                self.modules.get(i).map(|k| (ix, k == md))
            });
            module = match known {
                Some((ix, true)) => ix,
                _ => {
                    self.modules.push(md.clone());
                    let ix = (self.modules_base + self.modules.len()) as u32;
                    self.slots[si].1[slot] = Some(ix);
                    ix
                }
            };
            if fr.code == *b"PO" || fr.code == *b"GP" {
                if let Some(pos) = fr.field("position").and_then(|v| v.as_i64()) {
                    let (v, unit) = match md.scale() {
                        Some((ppu, u)) if ppu > 0.0 => (pos as f64 / ppu, u),
                        _ => (pos as f64, "pulses"),
                    };
                    let x = m.rel_s.unwrap_or(m.n as f64);
                    self.scratch.clear();
                    self.scratch
                        .push_str(&format!("position ell {} ({unit})", fr.addr_char()));
                    self.point(x, v);
                }
            }
        }
        let rec = Rec {
            start: 0,
            offset: fr.offset,
            cap_offset: m.cap_offset,
            ts: m.ts_ns.unwrap_or(u64::MAX),
            pair: o.pair.map_or(0, |r| r as u32),
            len: 0,
            module,
            stream: m.stream.min(u16::MAX as u32) as u16,
            flags,
            dir: dir_code(m.cap_dir),
            src: fr.addr,
            dst: 0,
            id: u16::from_be_bytes(fr.code),
            diags,
            chan: 0,
        };
        self.add(m.n, rec, fr.bytes);
    }

    fn garbage(&mut self, g: &GarbageRec<'_>) {
        let m = &g.meta;
        let flags = F_GARBAGE
            | match g.kind {
                None => F_ELL,
                Some(GarbageKind::NoHeader) => 0,
                Some(GarbageKind::AbsurdLength { .. }) => F_ABSURD,
                Some(GarbageKind::TrailingBytes) => F_TRAILING,
            };
        let rec = Rec {
            start: 0,
            offset: g.offset,
            cap_offset: m.cap_offset,
            ts: m.ts_ns.unwrap_or(u64::MAX),
            pair: 0,
            len: 0,
            module: 0,
            stream: m.stream.min(u16::MAX as u32) as u16,
            flags,
            dir: dir_code(m.cap_dir),
            src: 0,
            dst: 0,
            id: 0,
            diags: 0,
            chan: 0,
        };
        self.add(m.n, rec, g.bytes);
    }

    /// Take what was indexed since the last publication (`done`: and the source has ended),
    /// to be applied to the shared index ([`Publication::apply`]), here or in another thread.
    /// `spare` is an emptied batch and arena to fill next (memory already touched).
    fn take(&mut self, done: bool, spare: Option<(Vec<Rec>, Vec<u8>)>) -> Publication {
        // Without a spare, room for as much as this batch: no copies while it grows.
        let (batch, arena) = spare.unwrap_or_else(|| {
            (
                Vec::with_capacity(self.batch.len()),
                Vec::with_capacity(self.arena.len()),
            )
        });
        let recs = std::mem::replace(&mut self.batch, batch);
        let mut arena = std::mem::replace(&mut self.arena, arena);
        let mut arena_file = None;
        if !self.from_file && !self.arena_tried {
            self.arena_tried = true;
            if let Some((out, back)) = arena_file_pair() {
                self.arena_out = Some(out);
                arena_file = Some(back);
            }
        }
        let at = self.arena_base;
        self.arena_base += arena.len() as u64;
        if let Some(out) = &self.arena_out {
            use std::os::unix::fs::FileExt;
            // Written before the records are published: they are read back at once. A failed
            // write (a full disk) leaves those records without bytes (shown empty), as a
            // capture file that can no longer be read does.
            let _ = out.write_all_at(&arena, at);
            arena.clear();
        }
        self.base += recs.len() as u64;
        let series = self
            .series
            .iter_mut()
            .filter(|(_, pts)| !pts.is_empty())
            .map(|(k, pts)| (k.clone(), std::mem::take(pts)))
            .collect();
        // Published ones are the index's: not kept here too (a capture whose stages change
        // often has as many as a tenth of its records).
        let scales = std::mem::take(&mut self.scales);
        self.scales_published += scales.len();
        let diag_sets = self.diag_sets[self.diag_sets_published..].to_vec();
        self.diag_sets_published = self.diag_sets.len();
        self.modules_base += self.modules.len();
        Publication {
            proto: self.proto.take(),
            recs,
            arena,
            arena_file,
            modules: std::mem::take(&mut self.modules),
            scales,
            units_notes: std::mem::take(&mut self.units_notes),
            patches: std::mem::take(&mut self.patches),
            diag_sets,
            not_for_model: std::mem::take(&mut self.not_for_model),
            series,
            first_ts: self.first_ts,
            streams: std::mem::take(&mut self.streams_changed).then(|| self.streams.clone()),
            streams_seen: self.streams_seen,
            file_diags: std::mem::take(&mut self.file_diags),
            done,
            fallback_proto: None,
        }
    }
}

/// What the indexer publishes at once: the records and everything else indexed since the
/// last publication. Applying it is mostly copying records into the shared index (and the
/// page faults of its growth), which a separate thread can do while indexing goes on.
struct Publication {
    proto: Option<(Proto, bool, f64)>,
    recs: Vec<Rec>,
    arena: Vec<u8>,
    /// The file the arena is written to, from the first publication on.
    arena_file: Option<ReadBack>,
    modules: Vec<Module>,
    scales: Vec<Scale>,
    units_notes: Vec<String>,
    patches: Vec<(u64, u32, u16)>,
    diag_sets: Vec<Vec<&'static str>>,
    not_for_model: Vec<(u64, [u8; 8])>,
    series: Vec<(String, Vec<Point>)>,
    first_ts: Option<u64>,
    streams: Option<Vec<String>>,
    streams_seen: u64,
    file_diags: Vec<(u64, String)>,
    done: bool,
    /// The protocol to show when detection never named one (set at the end).
    fallback_proto: Option<Proto>,
}

impl Publication {
    /// Add to the shared index; gives back the emptied record and arena buffers for reuse.
    fn apply(mut self, ix: &mut Index) -> (Vec<Rec>, Vec<u8>) {
        if let Some((p, certain, share)) = self.proto {
            ix.proto = Some(p);
            ix.proto_certain = certain;
            ix.proto_share = Some(share);
        }
        if let Some(f) = self.arena_file.take() {
            ix.arena_file = Some(f);
        }
        ix.recs.extend(self.recs.drain(..));
        ix.arena.append(&mut self.arena);
        ix.modules.append(&mut self.modules);
        ix.scales.append(&mut self.scales);
        ix.units_notes.append(&mut self.units_notes);
        for (n, pair, flags) in self.patches {
            let was = (n as usize)
                .checked_sub(1)
                .and_then(|i| ix.recs.patch(i, pair, flags));
            if was.is_some_and(|was| flags & !was & F_NO_REPLY != 0) {
                ix.late_no_reply.push(n);
            }
        }
        ix.diag_sets.append(&mut self.diag_sets);
        ix.not_for_model.extend(self.not_for_model);
        for (k, mut pts) in self.series {
            match ix.series.get_mut(k.as_str()) {
                Some(v) => v.append(&mut pts),
                None => {
                    ix.series.insert(k, pts);
                }
            }
        }
        ix.first_ts = self.first_ts;
        if let Some(st) = self.streams {
            ix.streams = st;
        }
        ix.streams_seen |= self.streams_seen;
        ix.file_diags.append(&mut self.file_diags);
        if self.done {
            if ix.proto.is_none() {
                ix.proto = self.fallback_proto;
            }
            ix.done = true;
        }
        (self.recs, self.arena)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two files read back in turn on one thread give their own bytes (each read misses the
    /// other's window), across windows and up to their ends.
    #[test]
    fn files_read_back_give_their_own_bytes() {
        let dir = std::env::temp_dir().join(format!("aptscope-readback-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let data: Vec<Vec<u8>> = (0..2u8)
            .map(|k| {
                (0..WINDOW_LEN * 2 + 100)
                    .map(|i| (i % 251) as u8 ^ k)
                    .collect()
            })
            .collect();
        let files: Vec<ReadBack> = data
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let p = dir.join(format!("{k}.bin"));
                std::fs::write(&p, d).expect("write");
                ReadBack::open(&p.to_string_lossy()).expect("open")
            })
            .collect();
        let _ = std::fs::remove_dir_all(&dir);
        let end = data[0].len();
        for (at, len) in [
            (0, 10),
            (WINDOW_LEN - 3, 6),
            (5, WINDOW_LEN + 7),
            (end - 4, 4),
        ] {
            for (f, d) in files.iter().zip(&data) {
                assert_eq!(f.read(at as u64, len).as_deref(), d.get(at..at + len));
            }
        }
        assert_eq!(files[0].read(end as u64 - 2, 4), None);
    }

    /// Records of every shape (offsets and times going back and far ahead, no time, old and
    /// new module entries, values too wide for their slot, offsets apart from the capture's
    /// from some record on) come back from the packed store as they went in, by index, by
    /// iteration from any record, and after their pair link and flags are patched.
    #[test]
    fn packed_records_read_back_as_pushed() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let (mut cap, mut ts) = (0u64, 1_000u64);
        let mut recs = vec![];
        for i in 0..(CHUNK as u64 * 2 + 777) {
            let r = next();
            cap = match r % 50 {
                0 => cap.saturating_sub(r >> 40),
                1 => cap + (r >> 20),
                _ => cap + r % 300,
            };
            ts = match (r >> 8) % 40 {
                0 => ts.saturating_sub((r >> 30) % 5_000_000_000),
                1 => ts + (r >> 16),
                _ => ts + (r >> 12) % 100_000,
            };
            let apart = i > CHUNK as u64 + 5;
            recs.push(Rec {
                start: if apart { cap / 2 } else { cap },
                offset: if apart && r % 3 == 0 { cap + 1 } else { cap },
                cap_offset: cap,
                ts: if (r >> 20) % 9 == 0 { u64::MAX } else { ts },
                pair: (r >> 24) as u32,
                len: if (r >> 4) % 500 == 0 {
                    70_000 + (r % 9) as u32
                } else {
                    (r % 300) as u32
                },
                module: match (r >> 6) % 5 {
                    0 => 0,
                    1 => 1,
                    2 => (r >> 40) as u32,
                    _ => (i / 100) as u32,
                },
                stream: if (r >> 9) % 300 == 0 {
                    300
                } else {
                    ((r >> 9) % 4) as u16
                },
                flags: (r >> 32) as u16 & ((1 << DIR_SHIFT) - 1),
                dir: ((r >> 50) % 3) as u8,
                src: (r >> 13) as u8,
                dst: (r >> 21) as u8,
                id: (r >> 29) as u16,
                diags: if (r >> 3) % 700 == 0 {
                    999
                } else {
                    ((r >> 3) % 5) as u16
                },
                chan: (r >> 45) as u8,
            });
        }
        // Arena starts at the capture offsets, then apart; one after the other (an arena
        // written in order); one after the other, then out of line.
        let in_line = |recs: &[Rec], upto: usize| {
            let mut at = 1000;
            let mut out = recs.to_vec();
            for r in out.iter_mut().take(upto) {
                r.start = at;
                at += u64::from(r.len);
            }
            out
        };
        let variants = [
            recs.clone(),
            in_line(&recs, recs.len()),
            in_line(&recs, CHUNK + 100),
        ];
        // In memory, and over a budget of about one chunk (the older ones in a scratch file).
        let cases = variants
            .iter()
            .flat_map(|v| [(v, None), (v, Some(CHUNK_BYTES))]);
        let mut whole = 0;
        for (pristine, budget) in cases {
            let mut recs = pristine.clone();
            let mut packed = Recs::default();
            if let Some(b) = budget {
                packed.set_budget(b);
            }
            packed.extend(recs.iter().copied());
            check_packed(&mut packed, &mut recs);
            let spilled = packed.spilled_chunks();
            assert_eq!(spilled > 0, budget.is_some(), "{spilled}");
            // Of the three chunks, the first is spilled: the budget holds the second, and the
            // third is being filled.
            match budget {
                None => whole = packed.memory(),
                Some(_) => assert_eq!(packed.memory() + CHUNK_BYTES, whole),
            }
        }
    }

    fn check_packed(packed: &mut Recs, recs: &mut [Rec]) {
        assert_eq!(packed.len(), recs.len());
        for (i, r) in recs.iter().enumerate() {
            assert_eq!(packed.get(i).as_ref(), Some(r), "#{i}");
        }
        for from in [
            0,
            1,
            CHUNK - 1,
            CHUNK,
            CHUNK + 6,
            recs.len() - 1,
            recs.len(),
        ] {
            assert!(
                packed.iter_from(from).eq(recs[from..].iter().copied()),
                "from {from}"
            );
        }
        assert_eq!(packed.last(), recs.last().copied());
        for i in [0, 5, CHUNK + 3, recs.len() - 1, 7] {
            let was = packed.patch(i, 42, F_NO_REPLY);
            assert_eq!(was, Some(recs[i].flags));
            recs[i].flags |= F_NO_REPLY;
            if recs[i].pair == 0 {
                recs[i].pair = 42;
            }
            assert_eq!(packed.get(i), Some(recs[i]), "patched #{i}");
        }
        assert_eq!(packed.get(recs.len()), None);
        // Patches to spilled records are seen by reads after them, not the chunks kept before.
        assert!(packed.iter().eq(recs.iter().copied()));
    }
}
