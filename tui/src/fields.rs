//! Records of the index as the decode chain gives them: [`with_record`] re-decodes record `n`
//! from the arena into a [`Record`] (what the NDJSON renderer, the detail view and field
//! filters read), and [`View`] answers a display filter's field reads ([`Fields`]) straight
//! from the compact [`Rec`] for record-level keys (number, protocol, message id and name,
//! direction, stream, length, time, pairing, flags), decoding the frame's bytes only for the
//! keys that need them (fields, addresses, diagnostics of damaged frames …).
//!
//! [`matches()`] is the one place the terminal UI calls the display filter.

use crate::index::*;
use aptscope_dissector::apt::{AptFrame, GarbageKind};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::diag::{Diag, DiagKind};
use aptscope_dissector::ell::{EllFrame, Module, Observation};
use aptscope_dissector::fields::{Fields, Key, Num, Role, Val};
use aptscope_dissector::filter::Filter;
use aptscope_dissector::pair::PairInfo;
use aptscope_dissector::record::{AptRec, EllRec, GarbageRec, Meta, NoReply, Record};
use aptscope_dissector::shape::{self, Head};
use aptscope_dissector::table::Dir;
use aptscope_dissector::units::Scale;
use aptscope_dissector::Table;
use std::borrow::Cow;

/// Does record `n` pass `filter`? (The terminal UI's one call of the display filter.)
pub fn matches(filter: &Filter, ix: &Index, n: u64) -> bool {
    match ix.rec(n) {
        Some(r) => filter.matches(&View { ix, n, r: &r }),
        None => false,
    }
}

/// Latency between a reply and its request. A duplicate reply names the request it repeats
/// the answer to but has no latency, as the dissector's pairing gives it (`decode` prints none).
pub fn latency(ix: &Index, r: &Rec) -> Option<u64> {
    if !r.has(F_IS_REPLY) || r.has(F_DUPLICATE) {
        return None;
    }
    let req = ix.rec(r.pair as u64)?;
    Some(r.ts()?.saturating_sub(req.ts()?))
}

/// The stage conversion of an APT record's motion values, when one applies.
pub fn scale_of<'a>(ix: &'a Index, r: &Rec) -> Option<&'a Scale> {
    if r.has(F_ELL) {
        return None;
    }
    (r.module as usize)
        .checked_sub(1)
        .and_then(|i| ix.scales.get(i))
}

/// The Elliptec module an Elliptec record concerns, as the bus knew it then.
pub fn module_of<'a>(ix: &'a Index, r: &Rec) -> Option<&'a Module> {
    if !r.has(F_ELL) {
        return None;
    }
    (r.module as usize)
        .checked_sub(1)
        .and_then(|i| ix.modules.get(i))
}

/// What the APT framer saw in a garbage record.
pub fn garbage_kind(r: &Rec, bytes: &[u8]) -> GarbageKind {
    if r.has(F_ABSURD) && bytes.len() >= 4 {
        GarbageKind::AbsurdLength {
            msg_id: u16::from_le_bytes([bytes[0], bytes[1]]),
            len: u16::from_le_bytes([bytes[2], bytes[3]]),
        }
    } else if r.has(F_TRAILING) {
        GarbageKind::TrailingBytes
    } else {
        GarbageKind::NoHeader
    }
}

/// The record's context as the decoder gave it.
fn meta(ix: &Index, n: u64, r: &Rec) -> Meta {
    let ts = r.ts();
    Meta {
        n,
        stream: r.stream as u32,
        cap_dir: r.cap_dir(),
        ts_ns: ts,
        rel_s: ts
            .zip(ix.first_ts)
            .map(|(t, f)| t.saturating_sub(f) as f64 / 1e9),
        cap_offset: r.cap_offset,
    }
}

/// The request a reply answers.
fn reply_to(r: &Rec) -> Option<u64> {
    (r.has(F_IS_REPLY) && r.pair != 0).then_some(r.pair as u64)
}

/// Re-decode record `n` from the arena into the [`Record`] the decode chain gave for it (its
/// pairing from the index), and pass it to `f`. `None` when there is no such record.
pub fn with_record<T>(ix: &Index, n: u64, f: impl FnOnce(&Record<'_>) -> T) -> Option<T> {
    let r = &ix.rec(n)?;
    let bytes = ix.bytes(r);
    let bytes = &*bytes;
    let meta = meta(ix, n, r);
    let ell = r.has(F_ELL);
    if r.has(F_GARBAGE) {
        let g = GarbageRec {
            meta,
            proto: if ell { Proto::Elliptec } else { Proto::Apt },
            offset: r.offset,
            bytes,
            kind: (!ell).then(|| garbage_kind(r, bytes)),
        };
        return Some(f(&Record::Garbage(g)));
    }
    if ell {
        let mut frame = EllFrame::decode(r.offset, bytes, r.has(F_TRUNCATED))?;
        if r.has(F_UNSOLICITED) {
            frame.push_diag(Diag {
                offset: r.offset,
                kind: DiagKind::Unsolicited,
            });
        }
        let obs = Observation {
            pair: reply_to(r),
            latency_ns: reply_to(r).and_then(|_| latency(ix, r)),
            unsolicited: r.has(F_UNSOLICITED),
            interim: r.has(F_INTERIM),
            module: module_of(ix, r).cloned(),
            expired: vec![],
        };
        return Some(f(&Record::Ell(EllRec {
            meta,
            frame: &frame,
            obs: &obs,
        })));
    }
    let frame = AptFrame::decode(Table::global(), r.offset, bytes, r.has(F_TRUNCATED))?;
    let pair = PairInfo {
        pair: reply_to(r),
        latency_ns: reply_to(r).and_then(|_| latency(ix, r)),
        other_address: r.has(F_OTHER_ADDR),
        unsolicited: r.has(F_UNSOLICITED),
        duplicate: r.has(F_DUPLICATE),
        expired: vec![],
        not_for_model: r
            .has(F_NOT_FOR_MODEL)
            .then(|| ix.not_for_model.get(&n).copied())
            .flatten(),
    };
    Some(f(&Record::Apt(AptRec {
        meta,
        frame: &frame,
        pair: &pair,
        scale: scale_of(ix, r),
    })))
}

/// Pass the kind of each diagnostic in the `diag` list of record `n` to `f` (as
/// `View::visit(Key::Diag, ["kind"])` gives them, in another order): from the compact record,
/// decoding the frame only when the index could not keep its list.
pub fn diag_kinds(ix: &Index, n: u64, r: &Rec, f: &mut dyn FnMut(&'static str)) {
    if r.flags & DIAG_FLAGS == 0 {
        return;
    }
    if r.has(F_GARBAGE) {
        let len = r.len as usize;
        let d = if r.has(F_ELL) {
            DiagKind::Garbage { len: len as u32 }
        } else {
            aptscope_dissector::shape::garbage_diag(r.offset, len, garbage_kind(r, &ix.bytes(r)))
                .kind
        };
        return f(d.name());
    }
    let set = (r.diags as usize)
        .checked_sub(1)
        .and_then(|i| ix.diag_sets.get(i));
    match set {
        Some(kinds) => kinds.iter().for_each(|k| f(k)),
        None if r.has(F_DIAG) => {
            // Not kept: decode (the pairing ones are added below).
            let _ = with_record(ix, n, |rec| match rec {
                Record::Apt(a) => a.frame.diags().for_each(|d| f(d.kind.name())),
                Record::Ell(e) => e
                    .frame
                    .diags()
                    .iter()
                    .filter(|d| d.kind != DiagKind::Unsolicited)
                    .for_each(|d| f(d.kind.name())),
                _ => {}
            });
        }
        None => {}
    }
    if r.has(F_UNSOLICITED) {
        f(DiagKind::Unsolicited.name());
    }
    if r.has(F_DUPLICATE) && reply_to(r).is_some() && !r.has(F_ELL) {
        f(DiagKind::DuplicateReply { request: 0 }.name());
    }
    if r.has(F_NOT_FOR_MODEL) && ix.not_for_model.contains_key(&n) {
        f(DiagKind::NotForModel { model: [0; 8] }.name());
    }
    if r.has(F_NO_REPLY) {
        f(DiagKind::NoReply { cmd: n }.name());
    }
}

/// Directions as NDJSON names them (the order of [`View::dir_slot`]).
pub const DIRS: [&str; 3] = ["h2d", "d2h", "unknown"];

/// Flags that put something in a record's `diag` list.
pub const DIAG_FLAGS: u16 =
    F_DIAG | F_GARBAGE | F_UNSOLICITED | F_DUPLICATE | F_NO_REPLY | F_NOT_FOR_MODEL;

/// Record `n` of the index as filters read it: what the compact record holds is answered from
/// it, the rest from the re-decoded [`Record`] ([`with_record`]). A request that got no reply
/// has the `no_reply` diagnostic in its own `diag` list (`decode --json` gives it as a record of
/// its own, later).
#[derive(Debug, Clone, Copy)]
pub struct View<'a> {
    /// The index.
    pub ix: &'a Index,
    /// Record number.
    pub n: u64,
    /// The record.
    pub r: &'a Rec,
}

fn num(x: impl Into<i128>) -> Val<'static> {
    Val::Num(Num::I(x.into()))
}

impl View<'_> {
    /// Direction as NDJSON gives it (`h2d`, `d2h`, `unknown`), from the compact record;
    /// `None` for Elliptec garbage (the bus gives it none).
    pub fn dir(&self) -> Option<&'static str> {
        self.dir_slot().map(|i| DIRS[i])
    }

    /// [`View::dir`] as an index in [`DIRS`].
    pub fn dir_slot(&self) -> Option<usize> {
        let r = self.r;
        let slot = |d: Option<Dir>| match d {
            Some(Dir::HostToDevice) => 0,
            Some(Dir::DeviceToHost) => 1,
            _ => 2,
        };
        if r.has(F_ELL) {
            // Elliptec: the case of the command; garbage has none.
            return (!r.has(F_GARBAGE)).then(|| {
                if r.code()[0].is_ascii_lowercase() {
                    0
                } else {
                    1
                }
            });
        }
        if let Some(d) = r.cap_dir() {
            return Some(slot(Some(d)));
        }
        let table = (!r.has(F_GARBAGE))
            .then(|| Table::global().msg(r.id).map(|m| m.dir))
            .flatten()
            .filter(|d| *d != Dir::Both);
        Some(slot(table))
    }

    /// An APT frame (not Elliptec, not garbage).
    fn apt_frame(&self) -> bool {
        !self.r.has(F_ELL) && !self.r.has(F_GARBAGE)
    }

    fn decoded(&self, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool {
        with_record(self.ix, self.n, |rec| rec.visit(key, rest, f)).unwrap_or(false)
    }
}

/// What the compact record has at hand ([`shape::number`], [`shape::word`]).
impl Head for View<'_> {
    fn n(&self) -> u64 {
        self.n
    }
    fn kind(&self) -> &'static str {
        if self.r.has(F_GARBAGE) {
            "garbage"
        } else {
            "frame"
        }
    }
    fn offset(&self) -> u64 {
        self.r.offset
    }
    fn cap_offset(&self) -> u64 {
        self.r.cap_offset
    }
    fn len_bytes(&self) -> u64 {
        u64::from(self.r.len)
    }
    fn stream(&self) -> u32 {
        u32::from(self.r.stream)
    }
    fn ts_ns(&self) -> Option<u64> {
        self.r.ts()
    }
    fn pair(&self) -> Option<u64> {
        reply_to(self.r).filter(|_| !self.r.has(F_GARBAGE))
    }
    fn msgid(&self) -> Option<u16> {
        self.apt_frame().then_some(self.r.id)
    }
    fn channel(&self) -> Option<i64> {
        match self.r.chan() {
            KeptChan::Chan(c) if self.apt_frame() => Some(c),
            _ => None,
        }
    }
    fn dir(&self) -> Option<&'static str> {
        View::dir(self)
    }
    fn name(&self) -> Option<&'static str> {
        self.apt_frame()
            .then(|| Table::global().msg(self.r.id).map(|m| m.name))
            .flatten()
    }
}

impl Fields for View<'_> {
    fn proto(&self) -> Option<&str> {
        Some(if self.r.has(F_ELL) { "ell" } else { "apt" })
    }

    fn number(&self, key: Key) -> Option<i64> {
        shape::number(self, key)
    }

    fn word(&self, key: Key) -> Option<&'static str> {
        shape::word(self, key)
    }

    fn visit(&self, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool {
        let r = self.r;
        let (ell, garbage) = (r.has(F_ELL), r.has(F_GARBAGE));
        let apt_frame = !ell && !garbage;
        // What the compact record has at hand, as `number` and `word` give it.
        let v = if let Some(x) = shape::number(self, key) {
            num(x)
        } else if let Some(w) = shape::word(self, key) {
            Val::Str(Cow::Borrowed(w))
        } else {
            match key {
                Key::Proto => Val::Str(Cow::Borrowed(if ell { "ell" } else { "apt" })),
                // Not at hand: there is none (or, for a time, one beyond `i64`).
                Key::TsNs => match r.ts() {
                    Some(t) => num(t),
                    None => return false,
                },
                Key::Dir => return false,
                Key::Channel if apt_frame => match r.chan() {
                    KeptChan::InFrame => return self.decoded(key, rest, f),
                    KeptChan::Chan(_) | KeptChan::None => return false,
                },
                // A message the table does not know: `name` is null.
                Key::Name if apt_frame => return true,
                Key::Pair if !garbage => return false,
                Key::LatencyMs if !garbage => match reply_to(r).and_then(|_| latency(self.ix, r)) {
                    Some(l) => Val::Num(Num::F(l as f64 / 1e6)),
                    None => return false,
                },
                Key::Diag if !garbage => {
                    if r.flags & DIAG_FLAGS == 0 {
                        return true;
                    }
                    let there = self.decoded(key, rest, f);
                    if r.has(F_NO_REPLY) {
                        let e = NoReply {
                            proto: if ell { Proto::Elliptec } else { Proto::Apt },
                            stream: r.stream as u32,
                            n: self.n,
                            offset: r.offset,
                            name: "",
                        };
                        Record::NoReply(e).visit(key, rest, f);
                    }
                    return there;
                }
                _ => return self.decoded(key, rest, f),
            }
        };
        if rest.is_empty() {
            f(v, Role::Plain);
        }
        true
    }
}
