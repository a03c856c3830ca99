//! The stored records: 24 bytes each in chunks, spilled to a scratch file over the memory
//! budget ([`index_memory`]).

use super::*;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// [`Rec::chan`] of a channel outside 0–253.
pub const CHAN_OTHER: u8 = u8::MAX;

/// A record as the index stores it, 24 bytes: [`Rec`] without its arena position and stream
/// offset (kept beside it only once they differ from its capture offset: they never do in a
/// raw capture, one stream whose every byte is a record's), its direction in the flags, its
/// capture offset, time and module relative to those of its [`Block`], and narrower fields
/// whose rare larger values ([`Wide`]) are kept beside it.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Packed {
    /// Time since the block's; [`NO_TS`]: not recorded.
    pub(super) ts: u32,
    pub(super) pair: u32,
    /// Capture offset after the block's (24 bits, little-endian).
    pub(super) cap: [u8; 3],
    /// Stream.
    pub(super) stream: u8,
    /// Length; [`NARROW`]: this record's values are in [`Recs::wide`].
    pub(super) len: u16,
    /// Module or scale entry: 0 none, else after the block's (+ 1).
    pub(super) module: u16,
    /// `F_*` flags, and the direction at [`DIR_SHIFT`].
    pub(super) flags: u16,
    pub(super) id: u16,
    /// Diagnostic kinds entry.
    pub(super) diags: u8,
    pub(super) src: u8,
    pub(super) dst: u8,
    pub(super) chan: u8,
}

// Memory per record of the index (a raw capture's: nothing beside it but a few blocks).
const _: () = assert!(std::mem::size_of::<Packed>() == 24);

/// [`Packed::len`] of a record with a value too large for its slot (in [`Recs::wide`]).
pub(super) const NARROW: u16 = u16::MAX;

/// Records in a chunk of [`Recs::packed`] (1.5 MB).
pub(super) const CHUNK: usize = 1 << 16;

/// [`Packed::ts`] of a record without time.
pub(super) const NO_TS: u32 = u32::MAX;

/// Capture offsets a block spans.
pub(super) const CAP_SPAN: u64 = 1 << 24;

/// How much earlier than its first record's time a block's time is (records of several
/// streams come a little out of time order).
pub(super) const TS_BACK: u64 = 1 << 30;

/// Where [`Packed::flags`] keeps the direction (the `F_*` flags use the bits below).
pub(super) const DIR_SHIFT: u16 = 13;

/// What the records from `first` on (to the next block) count their capture offset, time and
/// module from. A record that does not fit its block's ranges starts a new one.
#[derive(Debug, Clone, Copy)]
pub(super) struct Block {
    pub(super) first: u64,
    pub(super) cap: u64,
    pub(super) ts: u64,
    pub(super) module: u32,
}

impl Block {
    /// The block a record would start.
    pub(super) fn of(r: &Rec, prev: Option<&Block>) -> Block {
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
    pub(super) fn fit(&self, r: &Rec) -> Option<([u8; 3], u32, u16)> {
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
pub(super) struct Wide {
    pub(super) len: u32,
    pub(super) stream: u16,
    pub(super) diags: u16,
}

/// The records of the index in timeline order, stored packed ([`Recs::get`] gives a [`Rec`]).
#[derive(Debug, Default)]
pub struct Recs {
    /// The records in chunks of [`CHUNK`]: growing never copies them (nor needs twice
    /// their memory for a moment, as a doubling vector does).
    pub(super) packed: Vec<Vec<Packed>>,
    pub(super) len: usize,
    /// The blocks, by first record.
    pub(super) blocks: Vec<Block>,
    /// Where the records' arena starts are.
    pub(super) starts: Starts,
    /// The stream offset of every record, once one has it apart from its capture offset; empty
    /// until then.
    pub(super) apart: Vec<u64>,
    /// Records (by index, in order) with a value too large for their slot.
    pub(super) wide: Vec<(u64, Wide)>,
    /// Where chunks go once the records in memory would exceed [`Recs::budget`]: the first
    /// `spilled` chunks are in this file (their entries in `packed` emptied).
    pub(super) spill: Option<Arc<Spill>>,
    pub(super) spilled: usize,
    /// Bytes of records kept in memory at most; `None`: [`index_memory`].
    pub(super) budget: Option<usize>,
    /// Bumped when a spilled record is patched: chunks read back before are stale.
    pub(super) spill_gen: u64,
}

/// Where the records' arena starts ([`Rec::start`]) are.
#[derive(Debug, Default)]
pub(super) enum Starts {
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
pub(super) const MARK: usize = 16;

/// The file the records over the memory budget are written to, chunk after chunk.
#[derive(Debug)]
pub(super) struct Spill {
    pub(super) file: std::fs::File,
    /// Tells this file's chunks from another index's in [`SPILLED`].
    pub(super) id: u64,
    /// Where the first chunk starts in the file (the record section of a cached index).
    pub(super) base: u64,
}

impl Spill {
    /// Where record `i` starts in the file.
    fn at(&self, i: usize) -> u64 {
        self.base + (i * std::mem::size_of::<Packed>()) as u64
    }

    /// Record `i`, read alone.
    fn read_one(&self, i: usize) -> std::io::Result<Packed> {
        use std::os::unix::fs::FileExt;
        let mut b = [0u8; 24];
        self.file.read_exact_at(&mut b, self.at(i))?;
        Ok(Packed::from_bytes(&b))
    }

    /// Record `i` written alone.
    fn write_one(&self, i: usize, p: &Packed) -> std::io::Result<()> {
        use std::os::unix::fs::FileExt;
        self.file.write_all_at(&p.to_bytes(), self.at(i))
    }

    /// The bytes of chunk `c`'s first `n` records into `buf` (resized to them).
    fn read_chunk(&self, c: usize, n: usize, buf: &mut Vec<u8>) -> std::io::Result<()> {
        use std::os::unix::fs::FileExt;
        buf.resize(n * std::mem::size_of::<Packed>(), 0);
        self.file.read_exact_at(buf, self.at(c * CHUNK))
    }

    /// Chunk `c`'s records (`bytes`, packed) written.
    fn write_chunk(&self, c: usize, bytes: &[u8]) -> std::io::Result<()> {
        use std::os::unix::fs::FileExt;
        self.file.write_all_at(bytes, self.at(c * CHUNK))
    }
}

/// A [`Spill::id`] no other spill of this process has.
pub(super) fn next_spill_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// Bytes of a chunk of records in a [`Spill`].
pub(super) const CHUNK_BYTES: usize = CHUNK * std::mem::size_of::<Packed>();

/// Spilled chunks a thread keeps read back (6 MB).
pub(super) const SPILLED_KEPT: usize = 4;

thread_local! {
    /// The spilled chunks this thread read back last: (spill id, [`Recs::spill_gen`], chunk
    /// number, its records), the newest last.
    static SPILLED: std::cell::RefCell<Vec<KeptChunk>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// A spilled chunk read back: (spill id, generation, chunk number, its records).
pub(super) type KeptChunk = (u64, u64, usize, Arc<Vec<Packed>>);

impl Packed {
    /// The record as it is written to a [`Spill`].
    pub(super) fn to_bytes(self) -> [u8; 24] {
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
    pub(super) fn from_bytes(b: &[u8; 24]) -> Packed {
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

/// The default of [`index_memory`] on a machine with a quarter of its memory or more to spare:
/// 22 M records (a 340 MB raw capture) before any is written out. A quarter of the memory
/// (6 GiB here) would let a 4 GB capture's 6.7 GB of records grow to that before spilling,
/// where 512 MiB keeps its view near 1 GiB resident (docs/tui.md); spilled chunks come back
/// from the page cache when touched, and indexing with records on disk costs ≈ 1.2× the CPU.
pub const DEFAULT_INDEX_MEMORY: usize = 512 << 20;

/// The memory the index's records may take before older ones are written to a scratch file
/// ([`set_index_memory`], else [`DEFAULT_INDEX_MEMORY`] or a quarter of the machine's memory,
/// whichever is less).
pub fn index_memory() -> usize {
    match INDEX_MEMORY.load(Ordering::Relaxed) {
        0 => {
            static DEFAULT: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
            *DEFAULT.get_or_init(|| {
                mem_total().map_or(DEFAULT_INDEX_MEMORY, |t| (t / 4).min(DEFAULT_INDEX_MEMORY))
            })
        }
        b => usize::try_from(b).unwrap_or(usize::MAX),
    }
}

/// Set the memory budget of the indexes made from now on ([`index_memory`]; `aptscope view
/// --index-memory`).
pub fn set_index_memory(bytes: u64) {
    INDEX_MEMORY.store(bytes.max(1), Ordering::Relaxed);
}

pub(super) static INDEX_MEMORY: AtomicU64 = AtomicU64::new(0);

/// The machine's memory (`MemTotal` of `/proc/meminfo`).
pub(super) fn mem_total() -> Option<usize> {
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
    pub(super) fn block_of(&self, i: usize) -> usize {
        self.blocks
            .partition_point(|b| b.first <= i as u64)
            .saturating_sub(1)
    }
    /// Record at index `i` (record number `i + 1`).
    pub fn get(&self, i: usize) -> Option<Rec> {
        self.unpack(i, self.block_of(i), None)
    }
    /// The packed record at index `i`: from memory, from its spilled chunk when this thread
    /// keeps it, else read alone (records looked up far apart, the statistics' one record of
    /// each message or a screen of rows, would otherwise read and push out a 1.5 MB chunk
    /// each; iterations read whole chunks, [`Recs::iter_from`]).
    #[inline]
    pub(super) fn packed_at(&self, i: usize) -> Option<Packed> {
        let c = i / CHUNK;
        if c >= self.spilled {
            return self.packed.get(c)?.get(i % CHUNK).copied();
        }
        if let Some(p) = self.kept_chunk(c, false) {
            return p.get(i % CHUNK).copied();
        }
        self.spill.as_ref()?.read_one(i).ok()
    }
    /// Spilled chunk `c` as this thread keeps it; read (and kept) when `read` and it is not.
    pub(super) fn kept_chunk(&self, c: usize, read: bool) -> Option<Arc<Vec<Packed>>> {
        let spill = self.spill.as_ref()?;
        let key = (spill.id, self.spill_gen, c);
        SPILLED.with_borrow_mut(|kept| {
            if let Some(k) = kept.iter().position(|e| (e.0, e.1, e.2) == key) {
                return Some(kept[k].3.clone());
            }
            if !read {
                return None;
            }
            if c * CHUNK > self.len {
                return None;
            }
            let mut buf = Vec::new();
            spill.read_chunk(c, self.chunk_len(c), &mut buf).ok()?;
            let recs: Arc<Vec<Packed>> = Arc::new(
                buf.chunks_exact(24)
                    .filter_map(|b| b.try_into().ok().map(Packed::from_bytes))
                    .collect(),
            );
            if kept.len() >= SPILLED_KEPT {
                kept.remove(0);
            }
            kept.push((key.0, key.1, key.2, recs.clone()));
            Some(recs)
        })
    }
    /// Keep the records in memory within the budget: write the oldest full chunks to the
    /// spill file (made at the first), and free them. The chunk being filled stays (the
    /// pairing's patches go mostly to recent records).
    pub(super) fn spill_over(&mut self) {
        let budget = self.budget.unwrap_or_else(index_memory);
        while (self.packed.len() - self.spilled) * CHUNK_BYTES > budget
            && self.spilled + 1 < self.packed.len()
        {
            if self.spill.is_none() {
                match scratch_file("index") {
                    Some(file) => {
                        let id = next_spill_id();
                        self.spill = Some(Arc::new(Spill { file, id, base: 0 }));
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
            if spill.write_chunk(c, &buf).is_err() {
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
    pub(super) fn unpack(&self, i: usize, b: usize, start_hint: Option<u64>) -> Option<Rec> {
        let p = self.packed_at(i)?;
        self.unpack_packed(i, b, &p, start_hint)
    }
    /// Record at index `i` of block `b`, packed as `p`.
    #[inline]
    fn unpack_packed(
        &self,
        i: usize,
        b: usize,
        p: &Packed,
        start_hint: Option<u64>,
    ) -> Option<Rec> {
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
    pub(super) fn len_at(&self, i: usize) -> Option<u64> {
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
    pub(super) fn start_of(&self, i: usize) -> Option<u64> {
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
        // The spilled chunk being read (not looked up again for every record).
        let mut chunk: Option<(usize, Arc<Vec<Packed>>)> = None;
        (from..self.len()).filter_map(move |i| {
            while self.blocks.get(b + 1).is_some_and(|x| x.first <= i as u64) {
                b += 1;
            }
            let c = i / CHUNK;
            let p = if c >= self.spilled {
                self.packed.get(c)?.get(i % CHUNK).copied()?
            } else {
                if chunk.as_ref().is_none_or(|(k, _)| *k != c) {
                    chunk = Some((c, self.kept_chunk(c, true)?));
                }
                chunk.as_ref()?.1.get(i % CHUNK).copied()?
            };
            let r = self.unpack_packed(i, b, &p, next)?;
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
    pub(super) fn patch(&mut self, i: usize, pair: u32, flags: u16) -> Option<u16> {
        if i / CHUNK < self.spilled {
            // Rare (a request's timeout passing long after it): patched in the file, read
            // alone (not through its chunk: the next patch would read that again).
            let spill = self.spill.as_ref()?;
            let mut p = spill.read_one(i).ok()?;
            let was = link(&mut p, pair, flags);
            spill.write_one(i, &p).ok()?;
            self.spill_gen += 1;
            return Some(was);
        }
        let p = self.packed.get_mut(i / CHUNK)?.get_mut(i % CHUNK)?;
        Some(link(p, pair, flags))
    }
    /// Records in chunk `c` (the last may be partly filled).
    fn chunk_len(&self, c: usize) -> usize {
        CHUNK.min(self.len.saturating_sub(c * CHUNK))
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
    /// Write every record as a [`Spill`] holds them (24 bytes each, in order) to `out`, a chunk
    /// at a time: those in memory packed, the spilled ones copied from their file.
    pub(super) fn write_packed(&self, out: &mut impl std::io::Write) -> std::io::Result<()> {
        let mut buf = Vec::with_capacity(CHUNK_BYTES);
        for (c, chunk) in self.packed.iter().enumerate() {
            buf.clear();
            if c < self.spilled {
                let spill = self
                    .spill
                    .as_ref()
                    .ok_or_else(|| std::io::Error::other("spilled records without their file"))?;
                spill.read_chunk(c, self.chunk_len(c), &mut buf)?;
            } else {
                for p in chunk {
                    buf.extend_from_slice(&p.to_bytes());
                }
            }
            out.write_all(&buf)?;
        }
        Ok(())
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

/// Give record `p` the pair link `pair` (when it has none) and add `flags`; the flags it had.
fn link(p: &mut Packed, pair: u32, flags: u16) -> u16 {
    if p.pair == 0 {
        p.pair = pair;
    }
    let was = p.flags & ((1 << DIR_SHIFT) - 1);
    p.flags |= flags;
    was
}
