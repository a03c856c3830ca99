//! `aptscope probe`: survey a connected APT controller against the spec — which read-only
//! requests it answers, with which layout, how fast, and where it differs from the message
//! table.
//!
//! The survey is split in two: a sans-io part here ([`read_only`], [`plan`], [`check_reply`],
//! [`Report`]) that decides what to send and judges what came back, and the I/O driver in
//! [`run`] that opens the port, identifies the controller and sends the plan one request at a
//! time.
//!
//! **Only read-only requests are sent.** A message is sent only when the table makes it a
//! request for data: host → device, named `…_REQ_…`, answered by a message of its own, of no
//! `motion` or `stop` class, and not completed by an end-of-move message (the rule replay's
//! safety module uses to ask before a real port). No SET, MOVE, HOME, JOG, identify, enable or
//! anything else that changes the device's state or moves a stage is ever part of a plan.

pub mod ell;
pub mod run;

use crate::model::{OwnedChunk, StreamInfo, Writer};
use aptscope_dissector::apt::{encode_named, Named};
use aptscope_dissector::msg;
use aptscope_dissector::table::{
    Class, DeviceProfile, Dir, Form, FormKind, MsgDef, DEFAULT_TIMEOUT_MS,
};
use aptscope_dissector::Table;
use std::fmt::Write as _;

/// The host's address in what the probe sends.
pub const HOST: u8 = 0x01;
/// A single unit's (generic USB) address.
pub const USB: u8 = 0x50;
/// A rack's motherboard.
pub const RACK: u8 = 0x11;
/// A rack's first bay.
pub const BAY0: u8 = 0x21;

/// Whether the probe may send `m`: a read-only request (see the module's documentation). The
/// identification requests (HW_REQ_INFO, RACK_REQ_BAYUSED) pass it too.
pub fn read_only(m: &MsgDef) -> bool {
    let t = Table::global();
    m.dir == Dir::HostToDevice
        && m.name.contains("_REQ_")
        && !m.class.has(Class::MOTION)
        && !m.class.has(Class::STOP)
        && !t.reply_ids(m).is_empty()
        && !t
            .replies_of(m)
            .iter()
            .any(|r| r.class.has(Class::END_OF_MOVE) || r.class.has(Class::MOTION))
}

/// One addressable unit the identification found: a single controller at 0x50, or a rack's bay.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unit {
    /// Its address.
    pub addr: u8,
    /// The model its HW_GET_INFO names.
    pub model: String,
    /// Its serial number.
    pub serial: i64,
    /// Firmware version `major.interim.minor`.
    pub firmware: String,
    /// Channels it reports (HW_GET_INFO `nchs`, at least 1).
    pub channels: u16,
}

/// One request of a plan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Step {
    /// The request's name.
    pub name: &'static str,
    /// Its sub-message (PARAMS groups).
    pub sub: Option<&'static str>,
    /// Destination address.
    pub dst: u8,
    /// Channel asked for (`chan_ident`), when the request has one.
    pub chan: Option<u16>,
    /// The frame to send.
    pub bytes: Vec<u8>,
    /// How long to wait for the answer (the table's `timeout=`, else its default).
    pub timeout_ms: u32,
    /// Whether the spec lists the request for the model (otherwise it was added by
    /// `--unlisted`, to find what a device does beyond its list).
    pub listed: bool,
}

impl Step {
    /// `NAME[/SUB] [chN]` (the channel's number, 1–4, for idents 1, 2, 4, 8), as reports show
    /// it.
    pub fn label(&self) -> String {
        let mut s = self.name.to_string();
        if let Some(sub) = self.sub {
            let _ = write!(s, "/{sub}");
        }
        if let Some(c) = self.chan {
            let n = if c.is_power_of_two() {
                c.trailing_zeros() + 1
            } else {
                u32::from(c)
            };
            let _ = write!(s, " ch{n}");
        }
        s
    }
}

/// The channel idents of a unit with `n` channels (the table's `enum chan`: 1, 2, 4, 8 for four).
fn chan_idents(n: u16) -> Vec<u16> {
    (0..n.clamp(1, 4)).map(|i| 1 << i).collect()
}

/// Whether `m`'s request forms carry a channel ident.
fn has_chan(m: &MsgDef) -> bool {
    m.forms.iter().any(|f| f.chan_field().is_some())
}

/// The plan for `units` of a controller whose messages are `profile` (the table's device
/// profile for its model): every read-only request the profile lists (with `unlisted`, also
/// every other read-only request of the table), on every unit and channel, in table order. A
/// request the encoder cannot build is left out (none is: every request's fields default to 0).
pub fn plan(profile: Option<&DeviceProfile>, units: &[Unit], unlisted: bool) -> Vec<Step> {
    let t = Table::global();
    let mut out = vec![];
    for u in units {
        for m in t.msgs().iter().filter(|m| read_only(m)) {
            // Identification is done before the plan; the rack's own requests are not a bay's.
            if m.id == msg::HW_REQ_INFO || m.name.starts_with("RACK_") {
                continue;
            }
            let listed = profile.is_none_or(|p| t.implements(p, m.id));
            if !listed && !unlisted {
                continue;
            }
            let subs: Vec<Option<&'static str>> = match m.subs {
                Some(g) => t
                    .subs()
                    .iter()
                    .filter(|s| s.group == g)
                    .map(|s| Some(s.name))
                    .collect(),
                None => vec![None],
            };
            let chans: Vec<Option<u16>> = if has_chan(m) {
                chan_idents(u.channels).into_iter().map(Some).collect()
            } else {
                vec![None]
            };
            for sub in &subs {
                for chan in &chans {
                    let c = chan.map(|c| c.to_string());
                    let values: Vec<(&str, &str)> =
                        c.iter().map(|c| ("chan_ident", c.as_str())).collect();
                    let Ok(bytes) = encode_named(
                        t,
                        &Named {
                            name: m.name,
                            sub: *sub,
                            values: &values,
                            form: None,
                            dst: u.addr,
                            src: HOST,
                        },
                    ) else {
                        continue;
                    };
                    out.push(Step {
                        name: m.name,
                        sub: *sub,
                        dst: u.addr,
                        chan: *chan,
                        bytes,
                        timeout_ms: m.timeout_ms.unwrap_or(DEFAULT_TIMEOUT_MS),
                        listed,
                    });
                }
            }
        }
    }
    out
}

/// What the table makes of a reply's length: the form it matches and the revisions of that
/// layout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Layout {
    /// The form's label (`hdr`, `84`, `8+`), or `none` when no form has this length.
    pub form: String,
    /// The form's note (`Issue 23`, `2025 revision`), empty when it has none.
    pub note: String,
    /// The spec revisions the layout follows (`23`, `2025`).
    pub revs: Vec<&'static str>,
}

/// Whether `f` is the layout of a data packet of `len` bytes (`None`: header only).
fn form_fits(f: &Form, len: Option<usize>) -> bool {
    match (f.kind, len) {
        (FormKind::Header, None) => true,
        (FormKind::Data(n), Some(l)) => usize::from(n) == l,
        (FormKind::Open(n), Some(l)) => l >= usize::from(n),
        _ => false,
    }
}

/// The revisions a form follows: its note names one (`Issue 23`, `2025 revision`), else those
/// of its message.
fn form_revs(m: &MsgDef, note: &str) -> Vec<&'static str> {
    let n = note.to_ascii_lowercase();
    match (n.contains("issue 23"), n.contains("2025")) {
        (true, false) => vec!["23"],
        (false, true) => vec!["2025"],
        _ => m.revs.names(),
    }
}

/// The layout of a reply `frame` of message `m` (a whole frame: header and data).
pub fn layout(m: &MsgDef, frame: &[u8]) -> Layout {
    let t = Table::global();
    let data = frame_data(frame);
    let forms: &[Form] = match (m.subs, data) {
        (Some(g), Some(d)) if d.len() >= 2 => {
            let id = u16::from_le_bytes([d[0], d[1]]);
            match t.sub_of(m, g, id) {
                Some(s) => &s.forms,
                None => &m.forms,
            }
        }
        _ => &m.forms,
    };
    match forms.iter().find(|f| form_fits(f, data.map(<[u8]>::len))) {
        Some(f) => Layout {
            form: f.label(),
            note: f.note.to_string(),
            revs: form_revs(m, f.note),
        },
        None => Layout {
            form: "none".into(),
            note: String::new(),
            revs: vec![],
        },
    }
}

/// The data packet of a frame whose header says one follows.
fn frame_data(frame: &[u8]) -> Option<&[u8]> {
    let dst = *frame.get(4)?;
    (dst & 0x80 != 0).then(|| frame.get(6..).unwrap_or(&[]))
}

/// The frame's message id.
pub fn frame_id(frame: &[u8]) -> u16 {
    match frame {
        [a, b, ..] => u16::from_le_bytes([*a, *b]),
        _ => 0,
    }
}

/// The forms a message exists in, as `hdr, 14, 28`.
fn forms_of(m: &MsgDef) -> String {
    let l: Vec<String> = m.forms.iter().map(Form::label).collect();
    l.join(", ")
}

/// Whether the answer `frame` is the reply `step` waits for: one of its replies, from the
/// address it went to, for the channel it asked about (when both name one).
pub fn answers(step: &Step, frame: &[u8]) -> bool {
    let t = Table::global();
    let Some(m) = t.msg_by_name(step.name) else {
        return false;
    };
    let id = frame_id(frame);
    if !t.reply_ids(m).contains(&id) || frame.get(5).is_some_and(|s| *s != step.dst) {
        return false;
    }
    match (step.chan, reply_chan(frame)) {
        (Some(c), Some(r)) => r == c || r == 0,
        _ => true,
    }
}

/// The channel ident a frame names (its `chan_ident` field, as decoded by the table).
fn reply_chan(frame: &[u8]) -> Option<u16> {
    let f = aptscope_dissector::apt::AptFrame::decode(Table::global(), 0, frame, false)?;
    let v = f.field("chan_ident")?.1.as_i64()?;
    u16::try_from(v).ok()
}

/// What one request got.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The request.
    pub step: Step,
    /// The answer, when one came in time.
    pub reply: Option<Reply>,
}

/// An answer to a request.
#[derive(Debug, Clone, PartialEq)]
pub struct Reply {
    /// Its message name (`0xNNNN` when the table does not know it).
    pub name: String,
    /// Its data length (0: header only).
    pub len: usize,
    /// The layout its length matches.
    pub layout: Layout,
    /// Time from the request's last write to the reply's last byte read, in µs.
    pub latency_us: u64,
    /// What differs from the spec (wrong length, decoding diagnostics, a reply the model's list
    /// does not name). A layout of one revision only is no deviation: see [`Layout::revs`].
    pub notes: Vec<String>,
}

impl Outcome {
    /// Whether the outcome differs from what the spec says of the model: an unanswered listed
    /// request, or an answer with notes. An unanswered sub-message is not one: the spec does
    /// not say which of its group's sub-messages a model has.
    pub fn deviates(&self) -> bool {
        match &self.reply {
            None => self.step.listed && self.step.sub.is_none(),
            Some(r) => !r.notes.is_empty(),
        }
    }

    /// The revision whose layout the answer follows, when its form belongs to one only
    /// (`Issue 23`, `2025 revision`).
    pub fn one_revision(&self) -> Option<&'static str> {
        match self.reply.as_ref()?.layout.revs.as_slice() {
            ["23"] => Some("Issue 23"),
            ["2025"] => Some("2025 revision"),
            _ => None,
        }
    }
}

/// Judge `frame`, the answer to a request (`profile`: the model's, when the table has one).
pub fn check_reply(frame: &[u8], latency_us: u64, profile: Option<&DeviceProfile>) -> Reply {
    let t = Table::global();
    let id = frame_id(frame);
    let len = frame_data(frame).map_or(0, <[u8]>::len);
    let mut notes = vec![];
    let Some(m) = t.msg(id) else {
        notes.push(format!("0x{id:04X} is not in the message table"));
        return Reply {
            name: format!("0x{id:04X}"),
            len,
            layout: Layout {
                form: "none".into(),
                note: String::new(),
                revs: vec![],
            },
            latency_us,
            notes,
        };
    };
    let lay = layout(m, frame);
    if lay.form == "none" {
        notes.push(format!(
            "wrong length: {len} data bytes fit no form of {} ({})",
            m.name,
            forms_of(m)
        ));
    }
    if let Some(p) = profile {
        if !t.implements(p, id) {
            notes.push(format!("{} is not in the {} list", m.name, p.model));
        }
    }
    if lay.form != "none" {
        if let Some(f) = aptscope_dissector::apt::AptFrame::decode(t, 0, frame, false) {
            for d in f.diags() {
                notes.push(d.kind.to_string());
            }
        }
    }
    Reply {
        name: m.name.to_string(),
        len,
        layout: lay,
        latency_us,
        notes,
    }
}

/// Something the device sent that answered no request of the plan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stray {
    /// Its message name (`0xNNNN` when unknown).
    pub name: String,
    /// Its source address.
    pub src: u8,
    /// Its data length.
    pub len: usize,
    /// The request that was waiting when it came.
    pub during: String,
}

/// A whole probe: what the controller is, and what each request got.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Report {
    /// The port probed.
    pub port: String,
    /// The controller's model (a rack's own, for racks).
    pub model: String,
    /// Whether the table has a device list for the model.
    pub profiled: bool,
    /// The units probed (one, or a rack's occupied bays).
    pub units: Vec<Unit>,
    /// Each request and what it got, in the order sent.
    pub outcomes: Vec<Outcome>,
    /// What came that answered nothing (status updates excepted, unless they are of the
    /// message a request waited for: a reply for another channel).
    pub strays: Vec<Stray>,
    /// Whether Ctrl-C ended the probe before the plan did.
    pub interrupted: bool,
    /// Whether the bus is Elliptec (families are then the modules' addresses).
    pub elliptec: bool,
    /// The whole exchange (for `-w`), times in ns since the Unix epoch.
    pub exchange: Vec<OwnedChunk>,
}

/// A titled list of answered requests, `  0xDST REQUEST  REPLY (N bytes)` and what `tail` adds
/// (a line only where it gives `Some`); nothing when there are none.
fn section<'a>(
    s: &mut String,
    title: &str,
    outcomes: impl Iterator<Item = &'a Outcome>,
    tail: impl Fn(&Outcome) -> Option<String>,
) {
    let mut head = false;
    for o in outcomes {
        let (Some(r), Some(t)) = (&o.reply, tail(o)) else {
            continue;
        };
        if !head {
            let _ = writeln!(s, "\n{title}");
            head = true;
        }
        let _ = writeln!(
            s,
            "  0x{:02X} {:<34} {} ({} bytes){t}",
            o.step.dst,
            o.step.label(),
            r.name,
            r.len
        );
    }
}

/// The family of a message: its name's prefix (`MOT`, `PZ`, `HW`).
pub fn family(name: &str) -> &str {
    name.split('_').next().unwrap_or(name)
}

impl Report {
    /// Requests the spec lists for the model that went unanswered.
    pub fn unanswered(&self) -> impl Iterator<Item = &Outcome> {
        self.outcomes
            .iter()
            .filter(|o| o.reply.is_none() && o.step.listed)
    }

    /// Every outcome that differs from the spec (see [`Outcome::deviates`]).
    pub fn deviations(&self) -> impl Iterator<Item = &Outcome> {
        self.outcomes.iter().filter(|o| o.deviates())
    }

    /// The report as text, like `stats`: the controller, a summary per family, then every
    /// deviation and answer beyond the model's list.
    pub fn text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "port      {}", self.port);
        let _ = writeln!(
            s,
            "model     {}{}",
            self.model,
            if self.profiled {
                ""
            } else {
                " (no device list in the spec: every read-only request was sent)"
            }
        );
        for u in &self.units {
            let _ = writeln!(
                s,
                "unit      0x{:02X} {} serial {} firmware {} channels {}",
                u.addr, u.model, u.serial, u.firmware, u.channels
            );
        }
        let answered = self.outcomes.iter().filter(|o| o.reply.is_some()).count();
        let _ = writeln!(
            s,
            "requests  {} sent, {} answered, {} deviation(s){}",
            self.outcomes.len(),
            answered,
            self.deviations().count(),
            if self.interrupted {
                " (interrupted)"
            } else {
                ""
            }
        );
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "{:<8} {:>5} {:>8} {:>10} {:>10}",
            "family", "sent", "answered", "median µs", "max µs"
        );
        let fam = |o: &Outcome| {
            if self.elliptec {
                format!("addr {}", ell::addr_char(o.step.dst))
            } else {
                family(o.step.name).to_string()
            }
        };
        let mut fams: Vec<String> = vec![];
        for o in self.outcomes.iter().filter(|o| o.step.listed) {
            let f = fam(o);
            if !fams.contains(&f) {
                fams.push(f);
            }
        }
        for f in fams {
            let of: Vec<&Outcome> = self
                .outcomes
                .iter()
                .filter(|o| o.step.listed && fam(o) == f)
                .collect();
            let mut lat: Vec<u64> = of
                .iter()
                .filter_map(|o| o.reply.as_ref().map(|r| r.latency_us))
                .collect();
            lat.sort_unstable();
            let med = lat.get(lat.len() / 2).map_or("-".into(), u64::to_string);
            let max = lat.last().map_or("-".into(), u64::to_string);
            let _ = writeln!(
                s,
                "{:<8} {:>5} {:>8} {:>10} {:>10}",
                f,
                of.len(),
                lat.len(),
                med,
                max
            );
        }
        let dev: Vec<&Outcome> = self.deviations().collect();
        if !dev.is_empty() {
            let _ = writeln!(s, "\ndeviations");
            for o in dev {
                let _ = write!(s, "  0x{:02X} {:<34} ", o.step.dst, o.step.label());
                match &o.reply {
                    None => {
                        let _ = writeln!(s, "no reply within {} ms", o.step.timeout_ms);
                    }
                    Some(r) => {
                        let _ = writeln!(s, "{} ({} bytes): {}", r.name, r.len, r.notes.join("; "));
                    }
                }
            }
        }
        let one = self.outcomes.iter().filter(|o| o.one_revision().is_some());
        section(
            &mut s,
            "layouts of one revision (where the revisions differ)",
            one,
            |o| o.one_revision().map(|rev| format!(": {rev} layout")),
        );
        let subs: Vec<String> = self
            .outcomes
            .iter()
            .filter(|o| o.reply.is_none() && o.step.sub.is_some())
            .map(|o| o.step.label())
            .collect();
        if !subs.is_empty() {
            let _ = writeln!(
                s,
                "\nsub-messages not answered (the spec does not say which a model has)\n  {}",
                subs.join(", ")
            );
        }
        let extra = self
            .outcomes
            .iter()
            .filter(|o| !o.step.listed && o.reply.is_some());
        section(&mut s, "answered beyond the model's list", extra, |_| {
            Some(String::new())
        });
        if !self.strays.is_empty() {
            let _ = writeln!(s, "\nanswering nothing");
            for x in &self.strays {
                let _ = writeln!(
                    s,
                    "  {} from 0x{:02X} ({} bytes) during {}",
                    x.name, x.src, x.len, x.during
                );
            }
        }
        s
    }

    /// Every request and its answer, one line each (`--verbose`).
    pub fn detail(&self) -> String {
        let mut s = String::new();
        for o in &self.outcomes {
            let _ = write!(s, "0x{:02X} {:<34} ", o.step.dst, o.step.label());
            match &o.reply {
                None => {
                    let _ = writeln!(s, "-");
                }
                Some(r) => {
                    let revs = match r.layout.revs.join(",") {
                        v if v.is_empty() => String::new(),
                        v => format!(" rev {v}"),
                    };
                    let _ = writeln!(
                        s,
                        "{} len {} form {}{revs} {} µs",
                        r.name, r.len, r.layout.form, r.latency_us
                    );
                }
            }
        }
        s
    }
}

impl Report {
    /// The report as JSON (`--json`), the form `--compare` reads back.
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::json;
        let units: Vec<_> = self
            .units
            .iter()
            .map(|u| {
                json!({"addr": u.addr, "model": u.model, "serial": u.serial,
                       "firmware": u.firmware, "channels": u.channels})
            })
            .collect();
        let outcomes: Vec<_> = self
            .outcomes
            .iter()
            .map(|o| {
                let reply = o.reply.as_ref().map(|r| {
                    json!({"name": r.name, "len": r.len, "form": r.layout.form,
                           "form_note": r.layout.note, "revs": r.layout.revs,
                           "latency_us": r.latency_us, "notes": r.notes})
                });
                json!({"key": key(&o.step), "request": o.step.name, "sub": o.step.sub,
                       "dst": o.step.dst, "chan": o.step.chan, "listed": o.step.listed,
                       "timeout_ms": o.step.timeout_ms, "reply": reply,
                       "deviates": o.deviates()})
            })
            .collect();
        let strays: Vec<_> = self
            .strays
            .iter()
            .map(|x| json!({"name": x.name, "src": x.src, "len": x.len, "during": x.during}))
            .collect();
        json!({
            "port": self.port, "model": self.model, "profiled": self.profiled,
            "proto": if self.elliptec { "elliptec" } else { "apt" },
            "units": units, "interrupted": self.interrupted,
            "sent": self.outcomes.len(),
            "answered": self.outcomes.iter().filter(|o| o.reply.is_some()).count(),
            "deviations": self.deviations().count(),
            "outcomes": outcomes, "strays": strays,
        })
    }
}

/// An outcome's key across reports: `0xDST NAME[/SUB] [chN]`.
fn key(s: &Step) -> String {
    format!("0x{:02X} {}", s.dst, s.label())
}

/// One outcome of a JSON report in a line: `NAME len N form F µs` or `-`.
fn cell(o: &serde_json::Value) -> (String, Option<u64>) {
    match o.get("reply") {
        Some(r) if !r.is_null() => {
            let s = |k: &str| r.get(k).and_then(|v| v.as_str()).unwrap_or("?").to_string();
            let len = r.get("len").and_then(|v| v.as_u64()).unwrap_or(0);
            (
                format!("{} len {} form {}", s("name"), len, s("form")),
                r.get("latency_us").and_then(|v| v.as_u64()),
            )
        }
        _ => ("-".into(), None),
    }
}

/// Two JSON reports side by side (`--compare`): their controllers, then every request whose
/// answer differs (answered in one only, another reply, length or layout), then how many agree.
/// `a` and `b` name the reports.
pub fn compare(a: (&str, &serde_json::Value), b: (&str, &serde_json::Value)) -> String {
    let mut s = String::new();
    let units = |v: &serde_json::Value| -> String {
        let us = v.get("units").and_then(|u| u.as_array()).cloned();
        us.unwrap_or_default()
            .iter()
            .map(|u| {
                let f = |k: &str| u.get(k).map(|x| x.to_string()).unwrap_or_default();
                format!("{} fw {}", f("model"), f("firmware")).replace('"', "")
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(s, "A  {}: {}", a.0, units(a.1));
    let _ = writeln!(s, "B  {}: {}", b.0, units(b.1));
    let rows = |v: &serde_json::Value| -> Vec<(String, serde_json::Value)> {
        let os = v.get("outcomes").and_then(|o| o.as_array()).cloned();
        os.unwrap_or_default()
            .into_iter()
            .map(|o| {
                let k = o
                    .get("key")
                    .and_then(|k| k.as_str())
                    .unwrap_or("?")
                    .to_string();
                (k, o)
            })
            .collect()
    };
    let (ra, rb) = (rows(a.1), rows(b.1));
    let mut keys: Vec<&String> = ra.iter().map(|(k, _)| k).collect();
    for (k, _) in &rb {
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    let find = |r: &[(String, serde_json::Value)], k: &str| -> Option<(String, Option<u64>)> {
        r.iter().find(|(x, _)| x == k).map(|(_, o)| cell(o))
    };
    let (mut same, mut diff) = (0, 0);
    let mut lat = (0u64, 0u64, 0usize);
    let mut lines = String::new();
    for k in keys {
        let ca = find(&ra, k);
        let cb = find(&rb, k);
        let show = |c: &Option<(String, Option<u64>)>| {
            c.as_ref().map_or("(not sent)".to_string(), |c| c.0.clone())
        };
        if let (Some((_, Some(x))), Some((_, Some(y)))) = (&ca, &cb) {
            lat = (lat.0 + x, lat.1 + y, lat.2 + 1);
        }
        if ca.as_ref().map(|c| &c.0) == cb.as_ref().map(|c| &c.0) {
            same += 1;
            continue;
        }
        diff += 1;
        let _ = writeln!(lines, "  {k:<36} A {:<40} B {}", show(&ca), show(&cb));
    }
    let _ = writeln!(s, "{same} request(s) answered alike, {diff} differ");
    if lat.2 > 0 {
        let n = lat.2 as u64;
        let _ = writeln!(
            s,
            "mean latency over {} answered by both: A {} µs, B {} µs",
            lat.2,
            lat.0 / n,
            lat.1 / n
        );
    }
    if diff > 0 {
        let _ = writeln!(s, "\ndiffering");
        s.push_str(&lines);
    }
    s
}

impl Report {
    /// Write the whole exchange to a capture writer (one serial stream named after the port):
    /// a pcapng to attach to a ticket or open in `aptscope view` or Wireshark.
    pub fn write_to(&self, out: &mut dyn Writer) -> std::io::Result<()> {
        out.stream(&StreamInfo {
            id: 0,
            name: self.port.clone(),
            settings: Some(
                if self.elliptec {
                    "9600 8N1"
                } else {
                    "115200 8N1 RTS/CTS"
                }
                .into(),
            ),
        })?;
        for c in &self.exchange {
            out.chunk(&c.as_chunk())?;
        }
        out.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kdc(addr: u8, channels: u16) -> Unit {
        Unit {
            addr,
            model: "KDC101".into(),
            serial: 27000123,
            firmware: "3.0.11".into(),
            channels,
        }
    }

    fn reply(name: &str, data: &[u8]) -> Vec<u8> {
        let m = Table::global().msg_by_name(name).expect(name);
        let mut f = m.id.to_le_bytes().to_vec();
        f.extend((data.len() as u16).to_le_bytes());
        f.extend([0x81, USB]);
        f.extend_from_slice(data);
        f
    }

    #[test]
    fn a_plan_holds_the_models_read_only_requests_on_every_unit_and_channel() {
        let p = Table::global().device_profile("KDC101");
        let steps = plan(p.as_ref(), &[kdc(0x21, 2), kdc(0x22, 1)], false);
        let t = Table::global();
        assert!(steps
            .iter()
            .all(|s| t.msg_by_name(s.name).is_some_and(read_only) && s.listed));
        let vel: Vec<(u8, Option<u16>)> = steps
            .iter()
            .filter(|s| s.name == "MOT_REQ_VELPARAMS")
            .map(|s| (s.dst, s.chan))
            .collect();
        assert_eq!(vel, [(0x21, Some(1)), (0x21, Some(2)), (0x22, Some(1))]);
        let s = steps
            .iter()
            .find(|s| s.name == "MOT_REQ_VELPARAMS")
            .unwrap();
        assert_eq!(s.bytes, [0x14, 0x04, 0x01, 0x00, 0x21, 0x01]);
        assert_eq!(s.timeout_ms, DEFAULT_TIMEOUT_MS);
        // --unlisted adds what the model's list leaves out, marked so.
        let all = plan(p.as_ref(), &[kdc(0x50, 1)], true);
        assert!(all.iter().any(|s| !s.listed && s.name.starts_with("PZ_")));
    }

    #[test]
    fn replies_are_judged_against_the_tables_forms() {
        let p = Table::global().device_profile("KDC101");
        let ok = check_reply(
            &reply(
                "MOT_GET_VELPARAMS",
                &[1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
            ),
            5,
            p.as_ref(),
        );
        assert!(ok.notes.is_empty(), "{:?}", ok.notes);
        assert_eq!(ok.layout.form, "14");
        let short = check_reply(&reply("MOT_GET_VELPARAMS", &[1, 0, 0, 0]), 5, p.as_ref());
        assert_eq!(
            short.notes,
            ["wrong length: 4 data bytes fit no form of MOT_GET_VELPARAMS (14)"]
        );
        let old = check_reply(&reply("MOT_GET_KCUBEMMIPARAMS", &[0; 28]), 5, p.as_ref());
        assert_eq!(old.layout.revs, ["23"]);
        let new = check_reply(&reply("MOT_GET_KCUBEMMIPARAMS", &[0; 36]), 5, p.as_ref());
        assert_eq!(new.layout.revs, ["2025"]);
        let alien = check_reply(&reply("PZ_GET_OUTPUTVOLTS", &[1, 0, 0, 0]), 5, p.as_ref());
        assert!(
            alien
                .notes
                .iter()
                .any(|n| n.contains("not in the KDC101 list")),
            "{:?}",
            alien.notes
        );
    }

    #[test]
    fn an_answer_is_for_the_channel_asked() {
        let p = Table::global().device_profile("KDC101");
        let steps = plan(p.as_ref(), &[kdc(0x50, 2)], false);
        let ch2 = steps
            .iter()
            .find(|s| s.name == "MOT_REQ_VELPARAMS" && s.chan == Some(2))
            .unwrap();
        let mut data = [0u8; 14];
        data[0] = 1;
        assert!(!answers(ch2, &reply("MOT_GET_VELPARAMS", &data)));
        data[0] = 2;
        assert!(answers(ch2, &reply("MOT_GET_VELPARAMS", &data)));
        assert!(!answers(ch2, &reply("MOT_GET_JOGPARAMS", &[2, 0])));
        assert_eq!(ch2.label(), "MOT_REQ_VELPARAMS ch2");
    }
}
