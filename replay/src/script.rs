//! A capture as a replay script: its messages in order, who sent each, when, and which request
//! each reply answers (the dissector's pairing rules), plus the selection (`--filter`,
//! `--from/--to`, `--loop`) and the schedule built from it.

use aptscope_capture::open::{open, OpenOptions};
use aptscope_capture::Event;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::filter::Filter;
use aptscope_dissector::pipeline::{Format, Pipeline};
use serde_json::Value;
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
    /// The decoded record (the NDJSON object of `aptscope decode --json`).
    pub rec: Value,
}

impl Msg {
    /// The channel the record names, if any.
    pub fn channel(&self) -> Option<i64> {
        self.rec.get("channel").and_then(Value::as_i64)
    }

    /// `NAME`, or `NAME chN` when it names a channel, or `NAME @addr` for Elliptec modules.
    pub fn label(&self) -> String {
        label_of(&self.rec)
    }
}

/// `NAME`, `NAME chN`, `NAME @A` (Elliptec address), `NAME SUB` (sub-message) for a decoded
/// record.
pub fn label_of(rec: &Value) -> String {
    let mut name = rec
        .get("name")
        .and_then(Value::as_str)
        .unwrap_or("?")
        .to_string();
    if let Some(sub) = rec
        .get("sub")
        .and_then(|s| s.get("name"))
        .and_then(Value::as_str)
    {
        name = format!("{name} {sub}");
    }
    if let Some(c) = rec.get("channel").and_then(Value::as_i64) {
        format!("{name} ch{c}")
    } else if let Some(a) = rec.get("addr").and_then(Value::as_str) {
        format!("{name} @{a}")
    } else {
        name.to_string()
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

/// Which side a decoded record came from: the capture's direction when it has one, else the
/// message's own (the APT table gives each message a direction; Elliptec commands from the host
/// are lower case).
fn side_of(rec: &Value) -> Option<Side> {
    let pick = |k: &str| match rec.get(k).and_then(Value::as_str) {
        Some("h2d") => Some(Side::Host),
        Some("d2h") => Some(Side::Device),
        _ => None,
    };
    pick("dir").or_else(|| pick("msg_dir"))
}

fn unhex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

/// Turns the records of a pipeline into messages and notes.
#[derive(Debug, Default)]
pub struct Collector {
    /// Messages so far.
    pub msgs: Vec<Msg>,
    /// Notes so far.
    pub notes: Vec<String>,
    /// The protocol, once detected.
    pub proto: Option<Proto>,
}

impl Collector {
    /// Take one NDJSON record.
    pub fn line(&mut self, line: &str) {
        let rec: Value = match serde_json::from_str(line) {
            Ok(v) => v,
            Err(e) => {
                self.notes.push(format!("unreadable record ({e}): {line}"));
                return;
            }
        };
        match rec.get("type").and_then(Value::as_str) {
            Some("frame") => self.frame(rec),
            Some("detect") => {
                self.proto = match rec.get("proto").and_then(Value::as_str) {
                    Some("apt") => Some(Proto::Apt),
                    Some("ell" | "elliptec") => Some(Proto::Elliptec),
                    _ => self.proto,
                }
            }
            // Garbage, damaged frames, file problems, unanswered requests: said, not replayed.
            _ => self.notes.push(note(&rec)),
        }
    }

    fn frame(&mut self, rec: Value) {
        let n = rec.get("n").and_then(Value::as_u64).unwrap_or(0);
        let raw = rec.get("raw").and_then(Value::as_str).and_then(unhex);
        let name = rec.get("name").and_then(Value::as_str).map(str::to_string);
        let (Some(side), Some(raw), Some(name)) = (side_of(&rec), raw, name) else {
            self.notes.push(format!(
                "record {n}: no known sender or name, not replayed: {}",
                note(&rec)
            ));
            return;
        };
        let has_diag = rec
            .get("diag")
            .and_then(Value::as_array)
            .is_some_and(|d| !d.is_empty());
        if has_diag {
            self.notes.push(note(&rec));
        }
        self.msgs.push(Msg {
            n,
            ts_ns: rec.get("ts_ns").and_then(Value::as_u64),
            side,
            stream: rec.get("stream").and_then(Value::as_u64).unwrap_or(0) as u32,
            raw,
            name,
            pair: rec.get("pair").and_then(Value::as_u64),
            rec,
        });
    }
}

/// A one-line description of a record that is not a plain message.
fn note(rec: &Value) -> String {
    let ty = rec.get("type").and_then(Value::as_str).unwrap_or("record");
    let at = rec
        .get("offset")
        .and_then(Value::as_u64)
        .map(|o| format!(" @{o}"))
        .unwrap_or_default();
    let diags: Vec<String> = rec
        .get("diag")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .map(|d| {
                    let k = d.get("kind").and_then(Value::as_str).unwrap_or("?");
                    match d.get("msg").and_then(Value::as_str) {
                        Some(m) => format!("{k}: {m}"),
                        None => k.to_string(),
                    }
                })
                .collect()
        })
        .unwrap_or_default();
    let name = rec
        .get("name")
        .and_then(Value::as_str)
        .map(|s| format!(" {s}"))
        .unwrap_or_default();
    format!("{ty}{at}{name}: {}", diags.join("; "))
}

impl Script {
    /// Read and decode a capture file (`proto` forces the protocol; `None` detects it).
    pub fn load(path: &str, opts: OpenOptions, proto: Option<Proto>) -> io::Result<Script> {
        let (mut reader, format) = open(path, opts)?;
        let mut p = Pipeline::new(proto, Format::Json);
        let mut c = Collector {
            proto,
            ..Collector::default()
        };
        let mut emit = |l: &str| -> Result<(), ()> {
            c.line(l);
            Ok(())
        };
        while let Some(ev) = reader.next_event() {
            let _ = match ev {
                Event::Chunk(ch) => p.push_chunk(ch.ctx(), ch.bytes, &mut emit),
                Event::Diag(d) => p.file_diag(d.offset, d.kind, &d.msg, &mut emit),
                Event::Stream(_) => Ok(()),
            };
        }
        let _ = p.finish(&mut emit);
        let proto = c.proto.or(p.proto()).unwrap_or(Proto::Apt);
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

/// What part of a capture to replay.
#[derive(Debug, Default)]
pub struct Selection {
    /// Only messages this display filter accepts (host messages when acting as host, device
    /// messages when acting as device).
    pub filter: Option<Filter>,
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
        m.side == side
            && self.in_range(script, m)
            && self.filter.as_ref().is_none_or(|f| f.matches(&m.rec))
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

    fn script(lines: &[&str]) -> Script {
        let mut c = Collector::default();
        for l in lines {
            c.line(l);
        }
        Script::new(Proto::Apt, c.msgs, c.notes, "test".into())
    }

    const S: &[&str] = &[
        r#"{"n":1,"type":"frame","raw":"050000005001","name":"HW_REQ_INFO","dir":"h2d","ts_ns":1000000000,"stream":0,"diag":[]}"#,
        r#"{"n":2,"type":"frame","raw":"0600","name":"HW_GET_INFO","dir":"d2h","ts_ns":1002000000,"pair":1,"stream":0,"diag":[]}"#,
        r#"{"type":"garbage","offset":8,"diag":[{"kind":"garbage","msg":"3 bytes"}]}"#,
        r#"{"n":4,"proto":"apt","type":"frame","raw":"230201005001","name":"MOD_IDENTIFY","msg_dir":"h2d","ts_ns":1500000000,"stream":0,"diag":[]}"#,
    ];

    #[test]
    fn records_become_messages_and_notes() {
        let s = script(S);
        assert_eq!(s.msgs.len(), 3);
        assert_eq!(s.msgs[1].side, Side::Device);
        assert_eq!(
            s.msgs[2].side,
            Side::Host,
            "side from the table's direction"
        );
        assert_eq!(s.msgs[0].raw, vec![5, 0, 0, 0, 0x50, 1]);
        assert_eq!(s.replies_to(0), [1]);
        assert_eq!(s.notes.len(), 1);
        assert!(s.notes[0].contains("@8"), "{:?}", s.notes);
    }

    #[test]
    fn schedule_keeps_gaps_scales_and_loops() {
        let s = script(S);
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
        let s = script(S);
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
        let s = script(S);
        let sel = Selection {
            filter: Some(Filter::parse("apt.name == \"MOD_IDENTIFY\"").unwrap()),
            ..Selection::default()
        };
        let plan = host_schedule(&s, &sel, Timing::default(), 1);
        assert_eq!(plan.len(), 1);
        assert_eq!(
            plan[0].at_ns, 0,
            "times count from the first selected message"
        );
    }
}
