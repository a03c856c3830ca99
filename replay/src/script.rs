//! A capture as a replay script: its messages in order, who sent each, when, and which request
//! each reply answers (the dissector's pairing rules), plus the selection (`--filter`,
//! `--from/--to`, `--loop`) and the schedule built from it.
//!
//! Messages are taken from the typed records of the one decode chain
//! ([`aptscope_dissector::record::Decoder`]): bytes, sender, pairing and the table's definition
//! come straight from the record, the decoded fields as a typed [`Decoded`], and `--filter` is
//! evaluated on the record itself when the capture is loaded.

use crate::decoded::Decoded;
use aptscope_capture::judge::refuse;
use aptscope_capture::open::{open, OpenOptions};
use aptscope_capture::Event;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::ell::table::Cmd;
use aptscope_dissector::filter::Filter;
use aptscope_dissector::record::{Decoder, Record};
use aptscope_dissector::table::{Dir, MsgDef};
use aptscope_dissector::Diag;
use std::collections::{BTreeMap, HashMap};
use std::io;

/// Who sent a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// The host program.
    Host,
    /// The controller.
    Device,
}

impl Side {
    fn of(d: Dir) -> Option<Side> {
        match d {
            Dir::HostToDevice => Some(Side::Host),
            Dir::DeviceToHost => Some(Side::Device),
            _ => None,
        }
    }
}

/// One decoded message of the capture.
#[derive(Debug, Clone)]
pub struct Msg {
    /// Record number in the capture (as `aptscope decode` numbers it).
    pub n: u64,
    /// Capture time of its last byte, ns.
    pub ts_ns: Option<u64>,
    /// Who sent it.
    pub side: Side,
    /// Stream (port) it was captured on.
    pub stream: u32,
    /// Its bytes, as captured.
    pub raw: Vec<u8>,
    /// Message name (`MOT_MOVE_HOME`, `GET_POSITION` …).
    pub name: String,
    /// Record number of the request this message answers.
    pub pair: Option<u64>,
    /// Its protocol.
    pub proto: Proto,
    /// The APT table's definition (what it does: `class=`, replies, timeout).
    pub def: Option<&'static MsgDef>,
    /// The Elliptec command table's row.
    pub cmd: Option<&'static Cmd>,
    /// Channel the message names (APT `chan_ident`, 1-based).
    pub chan: Option<i64>,
    /// Where it goes or comes from: APT destination address, Elliptec module address.
    pub addr: Option<u8>,
    /// `NAME`, `NAME SUB`, `NAME chN` or `NAME @A`.
    label: String,
    /// Its decoded fields and addressing: what the field-by-field comparison reads.
    pub decoded: Decoded,
    /// Whether the display filter the capture was loaded with accepts it (true without one).
    pub wanted: bool,
}

impl Msg {
    /// The channel the message names, if any.
    pub fn channel(&self) -> Option<i64> {
        self.chan
    }

    /// `NAME`, or `NAME chN` when it names a channel, or `NAME @addr` for Elliptec modules.
    pub fn label(&self) -> String {
        self.label.clone()
    }
}

/// `NAME`, `NAME SUB` (sub-message), then ` chN` (channel) or ` @A` (Elliptec address).
fn label(name: &str, sub: Option<&str>, chan: Option<i64>, ell_addr: Option<char>) -> String {
    let mut s = name.to_string();
    if let Some(sub) = sub {
        s = format!("{s} {sub}");
    }
    match (chan, ell_addr) {
        (Some(c), _) => format!("{s} ch{c}"),
        (None, Some(a)) => format!("{s} @{a}"),
        _ => s,
    }
}

/// A capture loaded for replay.
#[derive(Debug, Clone)]
pub struct Script {
    /// The protocol.
    pub proto: Proto,
    /// Every complete message, in capture order.
    pub msgs: Vec<Msg>,
    /// What was not turned into messages (garbage, damaged frames, file problems), one line each.
    pub notes: Vec<String>,
    /// The capture's format name.
    pub format: String,
    /// Time of the first message that has one (ranges by time count from it).
    first_ts: Option<u64>,
    /// Indices of the replies to each request, by the request's record number.
    replies: HashMap<u64, Vec<usize>>,
}

/// Turns the records of a decoder into messages and notes.
#[derive(Default)]
pub struct Collector {
    /// Messages so far.
    pub msgs: Vec<Msg>,
    /// Notes so far.
    pub notes: Vec<String>,
    /// The protocol, once detected.
    pub proto: Option<Proto>,
    /// The display filter that sets [`Msg::wanted`], read on each frame's record.
    pub filter: Option<Filter>,
}

impl std::fmt::Debug for Collector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Collector")
            .field("msgs", &self.msgs.len())
            .field("notes", &self.notes)
            .field("proto", &self.proto)
            .field("filter", &self.filter.as_ref().map(Filter::as_str))
            .finish()
    }
}

/// `kind: text` of each diagnostic, joined.
fn diag_text(ds: impl Iterator<Item = Diag>) -> String {
    ds.map(|d| format!("{}: {}", d.kind.name(), d.kind))
        .collect::<Vec<_>>()
        .join("; ")
}

impl Collector {
    /// Take one record of the decoder.
    pub fn record(&mut self, rec: &Record<'_>) {
        match rec {
            Record::Detect { proto, .. } => self.proto = Some(*proto),
            Record::Apt(a) => {
                let f = a.frame;
                let diags: Vec<Diag> = f.diags().chain(a.pair.diags(f.offset)).collect();
                let name = f.msg.map(|m| m.name);
                let sub = f.sub.map(|s| s.name);
                let chan = f.channel();
                self.frame(
                    rec,
                    Parts {
                        n: a.meta.n,
                        offset: f.offset,
                        ts_ns: a.meta.ts_ns,
                        stream: a.meta.stream,
                        side: a.dir().and_then(Side::of),
                        raw: f.bytes,
                        name,
                        label: name.map(|n| label(n, sub, chan, None)),
                        pair: a.pair.pair,
                        proto: Proto::Apt,
                        def: f.msg,
                        cmd: None,
                        chan,
                        addr: Some(f.header().dst_byte()),
                        diags,
                        decoded: Decoded::apt(f),
                    },
                );
            }
            Record::Ell(e) => {
                let f = e.frame;
                let name = f.cmd.map(|c| c.name);
                self.frame(
                    rec,
                    Parts {
                        n: e.meta.n,
                        offset: f.offset,
                        ts_ns: e.meta.ts_ns,
                        stream: e.meta.stream,
                        // The frame's own direction: host commands are lower case.
                        side: Side::of(f.dir()),
                        raw: f.bytes,
                        name,
                        label: name.map(|n| label(n, None, None, Some(f.addr_char()))),
                        pair: e.obs.pair,
                        proto: Proto::Elliptec,
                        def: None,
                        cmd: f.cmd,
                        chan: None,
                        addr: Some(f.addr),
                        diags: f.diags().to_vec(),
                        decoded: Decoded::ell(f),
                    },
                );
            }
            // Garbage, file problems, unanswered requests: said, not replayed.
            Record::Garbage(g) => {
                let d = match g.kind {
                    Some(k) => aptscope_dissector::json::garbage_diag(g.offset, g.bytes.len(), k),
                    None => Diag {
                        offset: g.offset,
                        kind: aptscope_dissector::DiagKind::Garbage {
                            len: g.bytes.len() as u32,
                        },
                    },
                };
                self.notes.push(format!(
                    "garbage @{}: {}",
                    g.offset,
                    diag_text(std::iter::once(d))
                ));
            }
            Record::NoReply(r) => self
                .notes
                .push(format!("diag: {}", diag_text(std::iter::once(r.diag())))),
            Record::Input(d) => self
                .notes
                .push(format!("input: {}", diag_text(std::iter::once(*d)))),
            Record::FileDiag { offset, kind, msg } => {
                self.notes.push(format!("input @{offset}: {kind}: {msg}"))
            }
            // What converts values and which ports exist: not problems.
            Record::Units(_) | Record::Stream { .. } => {}
        }
    }

    fn frame(&mut self, rec: &Record<'_>, p: Parts<'_>) {
        let what = |p: &Parts<'_>| {
            format!(
                "frame @{}{}: {}",
                p.offset,
                p.name.map(|n| format!(" {n}")).unwrap_or_default(),
                diag_text(p.diags.iter().copied())
            )
        };
        let (Some(side), Some(name), Some(label)) = (p.side, p.name, p.label.clone()) else {
            self.notes.push(format!(
                "record {}: no known sender or name, not replayed: {}",
                p.n,
                what(&p)
            ));
            return;
        };
        if !p.diags.is_empty() {
            self.notes.push(what(&p));
        }
        let wanted = self.filter.as_ref().is_none_or(|f| f.matches(rec));
        self.msgs.push(Msg {
            n: p.n,
            ts_ns: p.ts_ns,
            side,
            stream: p.stream,
            raw: p.raw.to_vec(),
            name: name.to_string(),
            pair: p.pair,
            proto: p.proto,
            def: p.def,
            cmd: p.cmd,
            chan: p.chan,
            addr: p.addr,
            label,
            decoded: p.decoded,
            wanted,
        });
    }
}

/// What a frame record gives a message.
struct Parts<'a> {
    n: u64,
    offset: u64,
    ts_ns: Option<u64>,
    stream: u32,
    side: Option<Side>,
    raw: &'a [u8],
    name: Option<&'static str>,
    label: Option<String>,
    pair: Option<u64>,
    proto: Proto,
    def: Option<&'static MsgDef>,
    cmd: Option<&'static Cmd>,
    chan: Option<i64>,
    addr: Option<u8>,
    diags: Vec<Diag>,
    decoded: Decoded,
}

#[cfg(test)]
impl Msg {
    /// A hand-made APT message on channel 1 (test fixtures): no bytes, no fields, no address;
    /// the table's definition found by name.
    pub(crate) fn fixture(n: u64, name: &str, side: Side, ts_ns: u64, pair: Option<u64>) -> Msg {
        Msg {
            n,
            ts_ns: Some(ts_ns),
            side,
            stream: 0,
            raw: vec![],
            label: label(name, None, Some(1), None),
            def: aptscope_dissector::Table::global().msg_by_name(name),
            name: name.to_string(),
            pair,
            proto: Proto::Apt,
            cmd: None,
            chan: Some(1),
            addr: None,
            decoded: Decoded::default(),
            wanted: true,
        }
    }
}

impl Script {
    /// Read and decode a capture file (`proto` forces the protocol; `None` detects it);
    /// `filter` decides each message's [`Msg::wanted`] on its record.
    pub fn load(
        path: &str,
        opts: OpenOptions,
        proto: Option<Proto>,
        filter: Option<Filter>,
    ) -> io::Result<Script> {
        let (mut reader, format) = open(path, opts)?;
        let mut dec = Decoder::new(proto);
        let mut c = Collector {
            proto,
            filter,
            ..Collector::default()
        };
        let mut emit = |r: &Record<'_>| -> Result<(), ()> {
            c.record(r);
            Ok(())
        };
        let mut file_problems = 0;
        while let Some(ev) = reader.next_event() {
            if matches!(ev, Event::Diag(_)) {
                file_problems += 1;
            }
            let _ = ev.feed(&mut dec, &mut emit);
        }
        let _ = dec.finish(&mut emit);
        // What is not a capture of these protocols is not replayed: random bytes would send
        // the few headers they happen to hold (MOT_MOVE_STOP on channel 202) to a real device.
        if let Some(e) = refuse(&dec, format, file_problems).filter(|_| proto.is_none()) {
            return Err(e);
        }
        let proto = c.proto.or(dec.proto()).unwrap_or(Proto::Apt);
        Ok(Script::new(
            proto,
            c.msgs,
            c.notes,
            format.name().to_string(),
        ))
    }

    /// A script of these messages, in capture order.
    pub fn new(proto: Proto, msgs: Vec<Msg>, notes: Vec<String>, format: String) -> Script {
        let first_ts = msgs.iter().find_map(|m| m.ts_ns);
        let mut replies: HashMap<u64, Vec<usize>> = HashMap::new();
        for (j, m) in msgs.iter().enumerate() {
            if let (Side::Device, Some(p)) = (m.side, m.pair) {
                replies.entry(p).or_default().push(j);
            }
        }
        Script {
            proto,
            msgs,
            notes,
            format,
            first_ts,
            replies,
        }
    }

    /// Whether the capture has times for its messages.
    pub fn has_times(&self) -> bool {
        self.first_ts.is_some()
    }

    /// Time of the first message that has one.
    pub fn first_ts(&self) -> Option<u64> {
        self.first_ts
    }

    /// Time of the last message in `sel`'s range (what a pass of the replay lasts until).
    pub fn last_ts_in(&self, sel: &Selection) -> Option<u64> {
        self.msgs
            .iter()
            .filter(|m| sel.in_range(self, m))
            .filter_map(|m| m.ts_ns)
            .max()
    }

    /// The streams that hold messages, with their message counts.
    pub fn streams(&self) -> BTreeMap<u32, usize> {
        let mut s = BTreeMap::new();
        for m in &self.msgs {
            *s.entry(m.stream).or_insert(0) += 1;
        }
        s
    }

    /// Index of the message numbered `n`.
    pub fn index_of(&self, n: u64) -> Option<usize> {
        self.msgs.binary_search_by_key(&n, |m| m.n).ok()
    }

    /// Indices of the replies to message `i`, in capture order.
    pub fn replies_to(&self, i: usize) -> &[usize] {
        self.msgs
            .get(i)
            .and_then(|req| self.replies.get(&req.n))
            .map_or(&[], Vec::as_slice)
    }
}

/// One end of a `--from`/`--to` range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    /// A record number (as `aptscope decode` prints them).
    Record(u64),
    /// A time from the first message of the capture, ns.
    Time(u64),
}

impl Bound {
    /// `120` (record) or `2.5s`, `300ms`, `2min` (time from the capture's first message).
    pub fn parse(s: &str) -> Result<Bound, String> {
        let t = s.trim();
        if let Ok(n) = t.parse::<u64>() {
            return Ok(Bound::Record(n));
        }
        let (num, mul) = if let Some(x) = t.strip_suffix("ms") {
            (x, 1e6)
        } else if let Some(x) = t.strip_suffix("us") {
            (x, 1e3)
        } else if let Some(x) = t.strip_suffix("min") {
            (x, 60e9)
        } else if let Some(x) = t.strip_suffix('s') {
            (x, 1e9)
        } else {
            return Err(format!(
                "`{s}`: give a record number (120) or a time (2.5s, 300ms, 2min)"
            ));
        };
        match num.trim().parse::<f64>() {
            Ok(v) if v.is_finite() && v >= 0.0 => Ok(Bound::Time((v * mul) as u64)),
            _ => Err(format!("`{s}` is not a time")),
        }
    }
}

/// What part of a capture to replay. Only messages the display filter accepted when the
/// capture was loaded ([`Msg::wanted`]) are selected.
#[derive(Debug, Default)]
pub struct Selection {
    /// From this record or time on.
    pub from: Option<Bound>,
    /// Up to and including this record or time.
    pub to: Option<Bound>,
    /// The stream to replay, when the capture has several.
    pub stream: Option<u32>,
}

impl Selection {
    /// Whether message `m` is in the range and stream (the filter aside).
    pub fn in_range(&self, script: &Script, m: &Msg) -> bool {
        let t0 = script.first_ts;
        let rel = |m: &Msg| match (m.ts_ns, t0) {
            (Some(t), Some(z)) => Some(t.saturating_sub(z)),
            _ => None,
        };
        let after = |b: &Bound| match b {
            Bound::Record(n) => m.n >= *n,
            Bound::Time(t) => rel(m).is_none_or(|r| r >= *t),
        };
        let before = |b: &Bound| match b {
            Bound::Record(n) => m.n <= *n,
            Bound::Time(t) => rel(m).is_none_or(|r| r <= *t),
        };
        self.stream.is_none_or(|s| s == m.stream)
            && self.from.as_ref().is_none_or(after)
            && self.to.as_ref().is_none_or(before)
    }

    /// Whether `m` is selected for sending by the side that sends `side` messages.
    pub fn selects(&self, script: &Script, m: &Msg, side: Side) -> bool {
        m.side == side && m.wanted && self.in_range(script, m)
    }

    /// Check `from`/`to` against the capture: `from` after `to` (of the same kind) and a `from`
    /// beyond the capture's last record or time are errors that say so.
    pub fn check_range(&self, script: &Script) -> Result<(), String> {
        let show = |b: &Bound| match b {
            Bound::Record(n) => format!("record {n}"),
            Bound::Time(t) => format!("{:.3} s", *t as f64 / 1e9),
        };
        if let (Some(f), Some(t)) = (&self.from, &self.to) {
            let after = match (f, t) {
                (Bound::Record(a), Bound::Record(b)) | (Bound::Time(a), Bound::Time(b)) => a > b,
                _ => false,
            };
            if after {
                return Err(format!(
                    "--from ({}) is after --to ({}): nothing to replay",
                    show(f),
                    show(t)
                ));
            }
        }
        let last_n = script.msgs.iter().map(|m| m.n).max().unwrap_or(0);
        let last_t = match (
            script.msgs.iter().filter_map(|m| m.ts_ns).max(),
            script.first_ts,
        ) {
            (Some(l), Some(z)) => Some(l.saturating_sub(z)),
            _ => None,
        };
        match self.from {
            Some(Bound::Record(n)) if n > last_n => Err(format!(
                "--from record {n} is beyond the capture (its last record is {last_n})"
            )),
            Some(Bound::Time(t)) if last_t.is_some_and(|l| t > l) => Err(format!(
                "--from {} is beyond the capture (it lasts {:.3} s)",
                show(&Bound::Time(t)),
                last_t.unwrap_or(0) as f64 / 1e9
            )),
            _ => Ok(()),
        }
    }

    /// Check the stream choice against the capture: several streams need `stream`.
    pub fn check_streams(&self, script: &Script) -> Result<(), String> {
        let s = script.streams();
        match self.stream {
            Some(x) if !s.contains_key(&x) => Err(format!(
                "stream {x} has no messages (streams: {})",
                list(&s)
            )),
            None if s.len() > 1 => Err(format!(
                "the capture has several streams ({}); choose one with --stream",
                list(&s)
            )),
            _ => Ok(()),
        }
    }
}

fn list(s: &BTreeMap<u32, usize>) -> String {
    s.iter()
        .map(|(k, v)| format!("{k}: {v} messages"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// One message to send, at a time relative to the start of the replay.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Send {
    /// Index into [`Script::msgs`].
    pub idx: usize,
    /// When to send it, ns after the start (before any `--wait-replies` shift).
    pub at_ns: u64,
    /// Which pass of `--loop` (0 for the first).
    pub lap: u32,
}

/// Gap between the passes of `--loop`, after the last message of a pass.
pub const LAP_GAP_NS: u64 = 100_000_000;

/// How sends are timed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Time factor: 2.0 replays twice as fast.
    pub speed: f64,
    /// Ignore the captured gaps: send as soon as possible.
    pub asap: bool,
}

impl Timing {
    /// A captured duration as replayed: divided by the speed, or nothing with `asap`.
    pub fn scale(&self, ns: u64) -> u64 {
        if self.asap {
            0
        } else {
            (ns as f64 / self.speed.max(1e-9)) as u64
        }
    }
}

impl Default for Timing {
    fn default() -> Self {
        Timing {
            speed: 1.0,
            asap: false,
        }
    }
}

/// The host side's schedule: the selected host messages at their captured offsets (scaled by
/// `speed`), `loops` times.
pub fn host_schedule(script: &Script, sel: &Selection, timing: Timing, loops: u32) -> Vec<Send> {
    let chosen: Vec<usize> = (0..script.msgs.len())
        .filter(|&i| sel.selects(script, &script.msgs[i], Side::Host))
        .collect();
    let Some(&first) = chosen.first() else {
        return vec![];
    };
    let t0 = script.msgs[first].ts_ns;
    // A pass lasts until the last message in range (its replies and updates included).
    let span = match (t0, script.last_ts_in(sel)) {
        (Some(a), Some(b)) => b.saturating_sub(a),
        _ => 0,
    };
    let scale = |ns| timing.scale(ns);
    let mut out = Vec::with_capacity(chosen.len() * loops.max(1) as usize);
    for lap in 0..loops.max(1) {
        let base = (lap as u64).saturating_mul(scale(span.saturating_add(LAP_GAP_NS)));
        for &i in &chosen {
            let off = match (script.msgs[i].ts_ns, t0) {
                (Some(t), Some(z)) => t.saturating_sub(z),
                _ => 0,
            };
            out.push(Send {
                idx: i,
                at_ns: base.saturating_add(scale(off)),
                lap,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoded::FieldVal;
    use aptscope_dissector::record::Ctx;

    /// Decode chunks (direction, time in ms, bytes) of one APT stream into a script, with a
    /// display filter.
    fn decode_with(chunks: &[(Option<Dir>, u64, Vec<u8>)], filter: Option<Filter>) -> Script {
        let mut dec = Decoder::new(Some(Proto::Apt));
        let mut c = Collector {
            filter,
            ..Collector::default()
        };
        let mut emit = |r: &Record<'_>| -> Result<(), ()> {
            c.record(r);
            Ok(())
        };
        for (dir, ms, b) in chunks {
            let ctx = Ctx {
                stream: 0,
                dir: *dir,
                ts_ns: Some(ms * 1_000_000),
            };
            let _ = dec.push(ctx, b, &mut emit);
        }
        let _ = dec.finish(&mut emit);
        Script::new(Proto::Apt, c.msgs, c.notes, "test".into())
    }

    fn script() -> Script {
        script_with(None)
    }

    fn script_with(filter: Option<Filter>) -> Script {
        // HW_GET_INFO: 84 data bytes from 0x50 to the host, then 3 bytes of garbage.
        let mut info = vec![0x06, 0x00, 0x54, 0x00, 0x81, 0x50];
        info.extend([0u8; 84]);
        info.extend([0xFF, 0xFF, 0xFF]);
        decode_with(
            &[
                (
                    Some(Dir::HostToDevice),
                    1000,
                    vec![0x05, 0x00, 0x00, 0x00, 0x50, 0x01],
                ),
                (Some(Dir::DeviceToHost), 1002, info),
                // No direction captured: the table's (MOD_IDENTIFY goes to the device).
                (None, 1500, vec![0x23, 0x02, 0x01, 0x00, 0x50, 0x01]),
            ],
            filter,
        )
    }

    #[test]
    fn records_become_messages_and_notes() {
        let s = script();
        assert_eq!(s.msgs.len(), 3);
        assert_eq!(s.msgs[1].side, Side::Device);
        assert_eq!(
            s.msgs[2].side,
            Side::Host,
            "side from the table's direction"
        );
        assert_eq!(s.msgs[0].raw, vec![5, 0, 0, 0, 0x50, 1]);
        assert_eq!(s.msgs[1].raw.len(), 90, "the bytes come from the record");
        assert_eq!(s.msgs[2].label(), "MOD_IDENTIFY ch1");
        assert_eq!(s.msgs[2].addr, Some(0x50));
        assert!(s.msgs[2].def.is_some_and(|d| d.name == "MOD_IDENTIFY"));
        assert_eq!(s.msgs[1].name, "HW_GET_INFO");
        let d = &s.msgs[1].decoded;
        assert!(
            d.fields
                .iter()
                .any(|(k, v)| k == "serial_number" && *v == FieldVal::Int(0)),
            "{d:?}"
        );
        assert_eq!(
            d.src.as_ref().map(FieldVal::to_json),
            Some(serde_json::json!({"addr": 0x50, "name": "usb"}))
        );
        assert!(s.msgs.iter().all(|m| m.wanted), "no filter: all wanted");
        assert_eq!(s.replies_to(0), [1]);
        assert_eq!(s.notes.len(), 1, "{:?}", s.notes);
        assert!(s.notes[0].starts_with("garbage @90"), "{:?}", s.notes);
    }

    #[test]
    fn schedule_keeps_gaps_scales_and_loops() {
        let s = script();
        let sel = Selection::default();
        let plan = host_schedule(&s, &sel, Timing::default(), 1);
        assert_eq!(
            plan.iter().map(|p| p.at_ns).collect::<Vec<_>>(),
            [0, 500_000_000]
        );
        let fast = Timing {
            speed: 2.0,
            asap: false,
        };
        let plan = host_schedule(&s, &sel, fast, 2);
        assert_eq!(
            plan.iter().map(|p| (p.at_ns, p.lap)).collect::<Vec<_>>(),
            [(0, 0), (250_000_000, 0), (300_000_000, 1), (550_000_000, 1)]
        );
        let asap = Timing {
            speed: 1.0,
            asap: true,
        };
        assert!(host_schedule(&s, &sel, asap, 1)
            .iter()
            .all(|p| p.at_ns == 0));
    }

    #[test]
    fn ranges_by_record_and_time() {
        let s = script();
        let sel = Selection {
            from: Some(Bound::parse("2").unwrap()),
            ..Selection::default()
        };
        let plan = host_schedule(&s, &sel, Timing::default(), 1);
        assert_eq!(plan.len(), 1);
        assert_eq!(s.msgs[plan[0].idx].name, "MOD_IDENTIFY");
        let sel = Selection {
            to: Some(Bound::parse("100ms").unwrap()),
            ..Selection::default()
        };
        let plan = host_schedule(&s, &sel, Timing::default(), 1);
        assert_eq!(plan.len(), 1);
        assert_eq!(s.msgs[plan[0].idx].name, "HW_REQ_INFO");
        assert!(Bound::parse("soon").is_err());
        assert!(Bound::parse("-1s").is_err());
    }

    #[test]
    fn filter_selects_host_messages() {
        let f = Filter::parse("apt.name == \"MOD_IDENTIFY\" && apt.dst.addr == 0x50");
        let s = script_with(Some(f.unwrap()));
        assert_eq!(
            s.msgs.iter().map(|m| m.wanted).collect::<Vec<_>>(),
            [false, false, true],
            "the filter read each record"
        );
        let sel = Selection::default();
        let plan = host_schedule(&s, &sel, Timing::default(), 1);
        assert_eq!(plan.len(), 1);
        assert_eq!(
            plan[0].at_ns, 0,
            "times count from the first selected message"
        );
    }

    #[test]
    fn a_loaded_capture_is_filtered_on_its_records() {
        let sample = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../samples/sessions/kdc101.pcapng"
        );
        let f = Filter::parse("apt.fields.enable_state == 1").ok();
        let s = Script::load(sample, OpenOptions::default(), None, f).expect("sample");
        let wanted: Vec<(u64, &str)> = s
            .msgs
            .iter()
            .filter(|m| m.wanted)
            .map(|m| (m.n, m.name.as_str()))
            .collect();
        assert_eq!(
            wanted,
            [
                (3, "MOD_SET_CHANENABLESTATE"),
                (5, "MOD_GET_CHANENABLESTATE"),
                (64, "MOD_GET_CHANENABLESTATE"),
            ],
            "the enum field read by its code, as `decode --filter` selects"
        );
        let plan = host_schedule(&s, &Selection::default(), Timing::default(), 1);
        assert_eq!(
            plan.iter().map(|p| s.msgs[p.idx].n).collect::<Vec<_>>(),
            [3]
        );
    }
}
