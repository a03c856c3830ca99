//! What the indexing thread keeps of each record and publishes in batches.

use super::*;

use aptscope_dissector::apt::GarbageKind;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::diag::DiagKind;
use aptscope_dissector::ell::Module;
use aptscope_dissector::hash::NumMap;
use aptscope_dissector::record::{AptRec, EllRec, GarbageRec, Meta, Record};
use aptscope_dissector::table::Class;
use aptscope_dissector::units::Scale;
use std::collections::HashMap;
use std::time::Duration;

/// Records published at once at most (their [`Rec`]s take 3.7 MB): the indexer's batch, the
/// ones in flight to the publishing thread and the spare stay small beside the index.
pub(super) const MAX_BATCH: usize = 1 << 16;

/// How long read records may wait before they are published.
pub(super) const FLUSH_EVERY: Duration = Duration::from_millis(50);

/// Conversions remembered for reuse (one per device).
pub(super) const MAX_SCALE_AT: usize = 4096;

/// Series keys remembered (beyond, series are found by name).
pub(super) const MAX_SERIES_OF: usize = 4096;

/// Which plotted quantity a series holds.
pub(super) const QUANTITIES: [&str; 2] = ["position", "velocity"];

/// What the indexer keeps of the records: a batch not yet published and what it needs to link
/// records that are.
#[derive(Default)]
pub(super) struct Sink {
    /// Records not yet published, numbered from `base + 1`.
    pub(super) batch: Vec<Rec>,
    pub(super) arena: Vec<u8>,
    /// Arena bytes already published.
    pub(super) arena_base: u64,
    /// Records' bytes are read back from the capture file ([`Index::file`]): none kept.
    pub(super) from_file: bool,
    /// Where published arena bytes are written ([`Index::arena_file`]), once made.
    pub(super) arena_out: Option<std::fs::File>,
    /// Whether making it was tried (or is not wanted: the bytes stay in memory).
    pub(super) arena_tried: bool,
    /// Records already published.
    pub(super) base: u64,
    pub(super) proto: Option<(Proto, bool, f64)>,
    pub(super) modules: Vec<Module>,
    pub(super) modules_base: usize,
    /// Per stream, the module entry last given to each bus address.
    pub(super) slots: Vec<(u32, [Option<u32>; 16])>,
    /// The conversions given out since the last publication (entries from `scales_published`
    /// on; `Rec::module - 1` indexes them all), and how many were published before.
    pub(super) scales: Vec<Scale>,
    pub(super) scales_published: usize,
    /// The entry given for each revision of a conversion ([`Scale::revision`]).
    pub(super) scale_at: NumMap<u64, u32>,
    /// The entry given for each different conversion (equal [`Scale`]s): a device whose stage
    /// changes back gets its earlier entry, not a new copy.
    pub(super) scale_of: HashMap<Scale, u32>,
    pub(super) units_notes: Vec<String>,
    /// Pair links and flags for already-published records: (record number, pair, flags to set).
    pub(super) patches: Vec<(u64, u32, u16)>,
    /// Plot series by key, points not yet published; `series_at` finds a key's entry.
    pub(super) series: Vec<(String, Vec<Point>)>,
    pub(super) series_at: HashMap<String, usize>,
    /// The series of (message id, source, channel, quantity, scale revision): a status update
    /// finds its series without formatting and hashing its name.
    pub(super) series_of: NumMap<(u16, u8, Option<i64>, u8, u64), usize>,
    /// Lists of diagnostic kinds given out (`Rec::diags - 1`), how many are published, and
    /// the entry of each.
    pub(super) diag_sets: Vec<Vec<&'static str>>,
    pub(super) diag_sets_published: usize,
    pub(super) diag_set_ids: HashMap<Vec<&'static str>, u16>,
    pub(super) kinds: Vec<&'static str>,
    /// Whether an APT message id is plotted: 0 not known yet, 1 yes, 2 no.
    pub(super) plotted: Vec<u8>,
    pub(super) scratch: String,
    pub(super) not_for_model: Vec<(u64, [u8; 8])>,
    pub(super) first_ts: Option<u64>,
    pub(super) streams: Vec<String>,
    /// Whether `streams` changed since the last publication.
    pub(super) streams_changed: bool,
    pub(super) streams_seen: u64,
    pub(super) file_diags: Vec<(u64, String)>,
}

impl Sink {
    pub(super) fn on(&mut self, rec: &Record<'_>) -> Result<(), ()> {
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
    pub(super) fn set(&mut self, n: u64, pair: u32, flags: u16) {
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
    pub(super) fn add(&mut self, n: u64, mut rec: Rec, bytes: &[u8]) {
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
    pub(super) fn point(&mut self, x: f64, y: f64) {
        let i = self.series_index();
        self.series[i].1.push((x, y));
    }

    /// The entry of the series named by `self.scratch` (made if new).
    pub(super) fn series_index(&mut self) -> usize {
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
    pub(super) fn frame_diags(
        &mut self,
        kinds: impl Iterator<Item = DiagKind>,
        flags: &mut u16,
    ) -> u16 {
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
    pub(super) fn diag_set(&mut self) -> u16 {
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
    pub(super) fn scale_id(&mut self, sc: &Scale) -> u32 {
        let key = sc.revision();
        if let Some(&id) = self.scale_at.get(&key) {
            return id;
        }
        let id = match self.scale_of.get(sc) {
            Some(&id) => id,
            None => {
                self.scales.push(sc.clone());
                let id = (self.scales_published + self.scales.len()) as u32;
                if self.scale_of.len() >= MAX_SCALE_AT {
                    self.scale_of.clear();
                }
                self.scale_of.insert(sc.clone(), id);
                id
            }
        };
        if self.scale_at.len() >= MAX_SCALE_AT {
            self.scale_at.clear();
        }
        self.scale_at.insert(key, id);
        id
    }

    pub(super) fn apt(&mut self, a: &AptRec<'_>) {
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
            pair: p.pair.map_or(0, |r| r as u32),
            module,
            src: h.src_byte(),
            dst: h.dst_byte(),
            id: h.msg_id(),
            diags,
            chan: chan_code(fr.channel()),
            ..rec_at(m, fr.offset, flags)
        };
        self.add(m.n, rec, fr.bytes);
    }

    pub(super) fn ell(&mut self, e: &EllRec<'_>) {
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
            pair: o.pair.map_or(0, |r| r as u32),
            module,
            src: fr.addr,
            id: u16::from_be_bytes(fr.code),
            diags,
            ..rec_at(m, fr.offset, flags)
        };
        self.add(m.n, rec, fr.bytes);
    }

    pub(super) fn garbage(&mut self, g: &GarbageRec<'_>) {
        let m = &g.meta;
        let flags = F_GARBAGE
            | match g.kind {
                None => F_ELL,
                Some(GarbageKind::NoHeader) => 0,
                Some(GarbageKind::AbsurdLength { .. }) => F_ABSURD,
                Some(GarbageKind::TrailingBytes) => F_TRAILING,
            };
        self.add(m.n, rec_at(m, g.offset, flags), g.bytes);
    }

    /// Take what was indexed since the last publication (`done`: and the source has ended),
    /// to be applied to the shared index ([`Publication::apply`]), here or in another thread.
    /// `spare` is an emptied batch and arena to fill next (memory already touched).
    pub(super) fn take(&mut self, done: bool, spare: Option<(Vec<Rec>, Vec<u8>)>) -> Publication {
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

/// A record's fields that its [`Meta`] gives (`start` and `len` are set when it is added);
/// the rest zero, for the kind of record to fill in.
fn rec_at(m: &Meta, offset: u64, flags: u16) -> Rec {
    Rec {
        start: 0,
        offset,
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
    }
}

/// What the indexer publishes at once: the records and everything else indexed since the
/// last publication. Applying it is mostly copying records into the shared index (and the
/// page faults of its growth), which a separate thread can do while indexing goes on.
pub(super) struct Publication {
    pub(super) proto: Option<(Proto, bool, f64)>,
    pub(super) recs: Vec<Rec>,
    pub(super) arena: Vec<u8>,
    /// The file the arena is written to, from the first publication on.
    pub(super) arena_file: Option<ReadBack>,
    pub(super) modules: Vec<Module>,
    pub(super) scales: Vec<Scale>,
    pub(super) units_notes: Vec<String>,
    pub(super) patches: Vec<(u64, u32, u16)>,
    pub(super) diag_sets: Vec<Vec<&'static str>>,
    pub(super) not_for_model: Vec<(u64, [u8; 8])>,
    pub(super) series: Vec<(String, Vec<Point>)>,
    pub(super) first_ts: Option<u64>,
    pub(super) streams: Option<Vec<String>>,
    pub(super) streams_seen: u64,
    pub(super) file_diags: Vec<(u64, String)>,
    pub(super) done: bool,
    /// The protocol to show when detection never named one (set at the end).
    pub(super) fallback_proto: Option<Proto>,
}

impl Publication {
    /// Add to the shared index; gives back the emptied record and arena buffers for reuse.
    pub(super) fn apply(mut self, ix: &mut Index) -> (Vec<Rec>, Vec<u8>) {
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
