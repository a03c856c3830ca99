//! Decoding one record of the index on demand: its timeline row, its detail tree, its NDJSON
//! object (the pipeline's renderer on the record re-decoded by [`with_record`]). Only what is
//! on screen is decoded.

use crate::fields::{garbage_kind, module_of};
pub use crate::fields::{latency, scale_of, with_record};
use crate::index::*;
use aptscope_dissector::apt::{fmt_value_in, summary_in, AptFrame, Value};
use aptscope_dissector::diag::{Diag, DiagKind};
use aptscope_dissector::ell::{self, head, EllFrame};
use aptscope_dissector::pipeline::{Format, Renderer};
use aptscope_dissector::table::{Dir, FormKind};
use aptscope_dissector::Table;
use std::fmt::Write;

/// Which way a record went (as captured, else as the message table says).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Way {
    /// Host → device.
    Out,
    /// Device → host.
    In,
    /// Not known.
    Unknown,
}

impl Way {
    /// An arrow for the timeline.
    pub fn arrow(self) -> &'static str {
        match self {
            Way::Out => "→",
            Way::In => "←",
            Way::Unknown => "·",
        }
    }
}

/// Message family, for colouring: the prefix of the APT name (`MOT`, `HW`, `PZ` …), or the
/// Elliptec command group.
pub type Family = &'static str;

/// One timeline row, decoded.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Record number.
    pub n: u64,
    /// Capture time.
    pub ts: Option<u64>,
    /// Stream (port/device) index.
    pub stream: u16,
    /// Direction.
    pub way: Way,
    /// `apt` or `ell`.
    pub proto: &'static str,
    /// Source name (`host`, `bay1`, `usb`; Elliptec: `host` or the address).
    pub src: String,
    /// Destination name.
    pub dst: String,
    /// Message name (`MOT_MOVE_ABSOLUTE`, `ma MOVE_ABSOLUTE`, `garbage`).
    pub name: String,
    /// Family of the message.
    pub family: Family,
    /// Key fields with units.
    pub fields: String,
    /// The paired record: the request (for a reply) or the reply (for a request).
    pub pair: Option<u64>,
    /// Whether this row is the reply of its pair.
    pub is_reply: bool,
    /// Latency to the request, for replies with times.
    pub latency_ns: Option<u64>,
    /// Diagnostics, as text; empty when clean.
    pub diag: String,
    /// Garbage record.
    pub garbage: bool,
}

fn way_of(r: &Rec, table_dir: Option<Dir>) -> Way {
    match r.cap_dir().or(table_dir.filter(|d| *d != Dir::Both)) {
        Some(Dir::HostToDevice) => Way::Out,
        Some(Dir::DeviceToHost) => Way::In,
        _ => Way::Unknown,
    }
}

/// Family of an APT message name.
pub fn apt_family(name: &str) -> Family {
    const FAMILIES: &[&str] = &[
        "MOT", "HW", "PZ", "PZMOT", "NT", "LA", "LD", "TEC", "QUAD", "KNA", "KPZ", "KSG", "RACK",
        "MOD", "KVS", "PDXC",
    ];
    let p = name.split('_').next().unwrap_or("");
    FAMILIES
        .iter()
        .find(|f| **f == p)
        .copied()
        .unwrap_or("other")
}

fn ell_family(code: &[u8; 2]) -> Family {
    match code[0].to_ascii_lowercase() {
        b'm' | b'h' | b'f' | b'b' | b'p' | b's' => "motion",
        b'g' | b'i' => "query",
        _ => "other",
    }
}

fn garbage_diag(r: &Rec, bytes: &[u8]) -> Diag {
    if r.has(F_ELL) {
        return Diag {
            offset: r.offset,
            kind: DiagKind::Garbage {
                len: bytes.len() as u32,
            },
        };
    }
    aptscope_dissector::json::garbage_diag(r.offset, bytes.len(), garbage_kind(r, bytes))
}

fn pair_diags(r: &Rec, out: &mut String) {
    if r.has(F_DUPLICATE) {
        push_sep(out, "duplicate reply");
    }
    if r.has(F_UNSOLICITED) {
        push_sep(out, "unsolicited reply");
    }
    if r.has(F_NO_REPLY) {
        push_sep(out, "no reply");
    }
    if r.has(F_NOT_FOR_MODEL) {
        push_sep(out, "not for this model");
    }
}

fn push_sep(out: &mut String, s: &str) {
    if !out.is_empty() {
        out.push_str("; ");
    }
    out.push_str(s);
}

/// Decode the timeline row of record `n`.
pub fn row(ix: &Index, n: u64) -> Option<Row> {
    let r = &ix.rec(n)?;
    let bytes = ix.bytes(r);
    let bytes = &*bytes;
    let mut row = Row {
        n,
        ts: r.ts(),
        stream: r.stream,
        way: way_of(r, None),
        proto: if r.has(F_ELL) { "ell" } else { "apt" },
        src: String::new(),
        dst: String::new(),
        name: String::new(),
        family: "other",
        fields: String::new(),
        pair: (r.pair != 0).then_some(r.pair as u64),
        is_reply: r.has(F_IS_REPLY),
        latency_ns: latency(ix, r),
        diag: String::new(),
        garbage: r.has(F_GARBAGE),
    };
    if r.has(F_GARBAGE) {
        row.name = "garbage".into();
        let d = garbage_diag(r, bytes);
        row.diag = d.kind.to_string();
        for b in bytes.iter().take(16) {
            let _ = write!(row.fields, "{b:02x}");
        }
        if bytes.len() > 16 {
            row.fields.push('…');
        }
        return Some(row);
    }
    if r.has(F_ELL) {
        let f = EllFrame::decode(r.offset, bytes, r.has(F_TRUNCATED))?;
        row.way = way_of(r, Some(f.dir()));
        let a = f.addr_char().to_string();
        if f.dir() == Dir::HostToDevice {
            row.src = "host".into();
            row.dst = a;
        } else {
            row.src = a;
            row.dst = "host".into();
        }
        row.name = format!("{} {}", f.code_str(), f.cmd.map_or("UNKNOWN", |c| c.name));
        row.family = ell_family(&f.code);
        let m = module_of(ix, r);
        let scale = m.as_ref().and_then(|m| m.scale());
        for (fd, v) in f.fields() {
            if !row.fields.is_empty() {
                row.fields.push(' ');
            }
            row.fields.push_str(fd.name);
            row.fields.push('=');
            ell::fmt_value(fd, &v, scale, &mut row.fields);
        }
        if let Some(model) = m.and_then(|m| m.model) {
            if !row.fields.is_empty() {
                row.fields.push(' ');
            }
            let _ = write!(row.fields, "[ELL{model}]");
        }
        if r.has(F_INTERIM) {
            row.fields.push_str(" (interim)");
        }
        for d in f.diags() {
            push_sep(&mut row.diag, &d.kind.to_string());
        }
        pair_diags(r, &mut row.diag);
        return Some(row);
    }
    let t = Table::global();
    let f = AptFrame::decode(t, r.offset, bytes, r.has(F_TRUNCATED))?;
    row.way = way_of(r, f.msg.map(|m| m.dir));
    row.src = f.src().name().to_string();
    row.dst = f.dst().name().to_string();
    row.name = match f.name() {
        Some(n) => n.to_string(),
        None => format!("UNKNOWN_0x{:04X}", f.header().msg_id()),
    };
    row.family = f.name().map_or("other", apt_family);
    if let Some(c) = f.channel() {
        let _ = write!(row.fields, "ch{c} ");
    }
    if let Some(s) = f.sub {
        let _ = write!(row.fields, "[{}] ", s.name);
    }
    let before = row.fields.len();
    summary_in(&f, 8, scale_of(ix, r), &mut row.fields);
    if row.fields.len() == before && f.form.is_none() && bytes.len() > 6 {
        row.fields.push_str("data=");
        for b in &bytes[6..bytes.len().min(6 + 24)] {
            let _ = write!(row.fields, "{b:02x}");
        }
    }
    let trimmed = row.fields.trim_end().len();
    row.fields.truncate(trimmed);
    for d in f.diags() {
        push_sep(&mut row.diag, &d.kind.to_string());
    }
    if r.has(F_OTHER_ADDR) {
        row.fields.push_str(" (reply from another address)");
    }
    pair_diags(r, &mut row.diag);
    Some(row)
}

/// What a detail line is, for styling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeKind {
    /// A section heading.
    Section,
    /// A field or header line.
    Item,
    /// A set flag.
    FlagOn,
    /// A clear flag.
    FlagOff,
    /// A link to another record.
    Link,
    /// A diagnostic.
    Diag,
}

/// One line of the detail tree.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Nesting depth (0 = top).
    pub depth: u16,
    /// Stable id (for collapsing).
    pub id: String,
    /// The text.
    pub text: String,
    /// Bytes of the frame it covers: (start, length) relative to the frame start.
    pub range: Option<(usize, usize)>,
    /// Kind.
    pub kind: NodeKind,
    /// A record this line refers to (pair link).
    pub link: Option<u64>,
    /// Whether lines below are its children (it can collapse).
    pub children: bool,
}

struct Tree(Vec<Node>);

impl Tree {
    fn add(
        &mut self,
        depth: u16,
        id: &str,
        text: String,
        range: Option<(usize, usize)>,
        kind: NodeKind,
    ) {
        self.0.push(Node {
            depth,
            id: id.to_string(),
            text,
            range,
            kind,
            link: None,
            children: false,
        });
    }
}

/// How an address reads, with routing explained.
fn addr_text(a: aptscope_dissector::apt::Addr) -> String {
    use aptscope_dissector::apt::Addr;
    let what = match a {
        Addr::Host => "the host (control PC)".to_string(),
        Addr::Rack => "rack / motherboard of a card-slot system".to_string(),
        Addr::Bay(n) => format!(
            "bay {n} of a rack (card slot {}), routed through the motherboard",
            n + 1
        ),
        Addr::Usb => "generic USB unit (single controller)".to_string(),
        Addr::Unknown(_) => "not an address of the spec".to_string(),
    };
    format!("0x{:02X} {} — {what}", a.byte(), a.name())
}

/// The detail tree of record `n` (every node; collapsing is the view's business).
pub fn tree(ix: &Index, n: u64) -> Vec<Node> {
    let mut t = Tree(vec![]);
    let Some(r) = &ix.rec(n) else {
        return t.0;
    };
    let bytes = ix.bytes(r);
    let bytes = &*bytes;
    let mut top = format!(
        "Record {n}: {} bytes at stream offset {:#x}",
        bytes.len(),
        r.offset
    );
    let stream = ix
        .streams
        .get(r.stream as usize)
        .filter(|s| !s.is_empty())
        .map(|s| format!(" ({s})"))
        .unwrap_or_default();
    let _ = write!(top, ", stream {}{stream}", r.stream);
    if let Some(ts) = r.ts() {
        let rel = ix.first_ts.map_or(0, |f| ts.saturating_sub(f));
        let _ = write!(top, ", t={:.6} s", rel as f64 / 1e9);
    }
    t.add(0, "rec", top, Some((0, bytes.len())), NodeKind::Section);
    if r.has(F_GARBAGE) {
        let d = garbage_diag(r, bytes);
        t.add(
            0,
            "garbage",
            format!("Garbage: {}", d.kind),
            Some((0, bytes.len())),
            NodeKind::Diag,
        );
        return t.0;
    }
    if r.has(F_ELL) {
        ell_tree(ix, r, n, bytes, &mut t);
    } else {
        apt_tree(r, bytes, scale_of(ix, r), &mut t);
    }
    pair_nodes(ix, r, &mut t);
    let mut v = t.0;
    for i in 0..v.len() {
        v[i].children = v.get(i + 1).is_some_and(|x| x.depth > v[i].depth);
    }
    v
}

fn pair_nodes(ix: &Index, r: &Rec, t: &mut Tree) {
    if r.pair != 0 {
        let other = r.pair as u64;
        let name = row(ix, other).map(|x| x.name).unwrap_or_default();
        let text = if r.has(F_IS_REPLY) {
            let mut s = format!("Reply to #{other} {name}");
            if let Some(l) = latency(ix, r) {
                let _ = write!(s, ", latency {:.3} ms", l as f64 / 1e6);
            }
            if r.has(F_INTERIM) {
                s.push_str(" (interim busy reply)");
            }
            if r.has(F_OTHER_ADDR) {
                s.push_str(" (from another address)");
            }
            s
        } else {
            format!("Answered by #{other} {name}")
        };
        t.add(
            0,
            "pair",
            format!("{text}   [p: jump]"),
            None,
            NodeKind::Link,
        );
        if let Some(last) = t.0.last_mut() {
            last.link = Some(other);
        }
    }
    let mut extra = vec![];
    if r.has(F_NO_REPLY) {
        extra.push("no_reply: this request got no reply (timeout or end of capture)");
    }
    if r.has(F_UNSOLICITED) {
        extra.push("unsolicited: a reply no pending request expected");
    }
    if r.has(F_DUPLICATE) {
        extra.push("duplicate_reply: a second reply to an answered request");
    }
    if r.has(F_NOT_FOR_MODEL) {
        extra.push("not_for_model: the spec does not list this message for the device's model");
    }
    for (i, e) in extra.into_iter().enumerate() {
        t.add(
            0,
            &format!("pdiag{i}"),
            format!("!! {e}"),
            None,
            NodeKind::Diag,
        );
    }
}

fn apt_tree(r: &Rec, bytes: &[u8], scale: Option<&aptscope_dissector::units::Scale>, t: &mut Tree) {
    let table = Table::global();
    let Some(f) = AptFrame::decode(table, r.offset, bytes, r.has(F_TRUNCATED)) else {
        return;
    };
    let h = f.header();
    let name = f.name().unwrap_or("unknown id");
    t.add(
        0,
        "hdr",
        "Header (6 bytes)".into(),
        Some((0, 6)),
        NodeKind::Section,
    );
    t.add(
        1,
        "hdr.id",
        format!("message id: 0x{:04X} {name}", h.msg_id()),
        Some((0, 2)),
        NodeKind::Item,
    );
    if h.has_data() {
        t.add(
            1,
            "hdr.len",
            format!(
                "data length: {} (long form: destination bit 7 set)",
                h.data_len()
            ),
            Some((2, 2)),
            NodeKind::Item,
        );
    } else if f.data_len() > 0 {
        t.add(
            1,
            "hdr.len",
            format!(
                "data length: {} (0x80 flag missing: the param bytes give the length)",
                f.data_len()
            ),
            Some((2, 2)),
            NodeKind::Item,
        );
    } else {
        t.add(
            1,
            "hdr.p",
            format!(
                "short form: param1 0x{:02X}, param2 0x{:02X}",
                h.param1(),
                h.param2()
            ),
            Some((2, 2)),
            NodeKind::Item,
        );
    }
    let dst_raw = bytes.get(4).copied().unwrap_or(0);
    t.add(
        1,
        "hdr.dst",
        format!("destination: {} (byte 0x{dst_raw:02X})", addr_text(f.dst())),
        Some((4, 1)),
        NodeKind::Item,
    );
    t.add(
        1,
        "hdr.src",
        format!("source: {}", addr_text(f.src())),
        Some((5, 1)),
        NodeKind::Item,
    );
    let route = match (f.src().bay(), f.dst().bay()) {
        (_, Some(b)) => format!("routing: host → rack motherboard → bay {b}"),
        (Some(b), _) => format!("routing: bay {b} → rack motherboard → host"),
        _ => format!("routing: {} → {}", f.src().name(), f.dst().name()),
    };
    t.add(1, "hdr.route", route, None, NodeKind::Item);
    if let Some(m) = f.msg {
        let dir = match m.dir {
            Dir::HostToDevice => "host → device",
            Dir::DeviceToHost => "device → host",
            Dir::Both => "either way",
        };
        let mut s = format!("Message {} ({dir})", m.name);
        if !m.doc.is_empty() {
            let _ = write!(s, ": {}", m.doc);
        }
        t.add(0, "msg", s, None, NodeKind::Item);
    }
    if let Some(s) = f.sub {
        let mut x = format!("Sub-message 0x{:04X} {} (group {})", s.id, s.name, s.group);
        if !s.doc.is_empty() {
            let _ = write!(x, ": {}", s.doc);
        }
        t.add(0, "sub", x, None, NodeKind::Item);
    }
    if let Some(form) = f.form {
        let kind = match form.kind {
            FormKind::Header => "header-only".to_string(),
            FormKind::Data(n) => format!("{n}-byte data packet"),
            FormKind::Sub => "sub-message".to_string(),
            FormKind::Open(_) => format!("{}-byte data packet", f.data_len()),
        };
        let mut head = format!("Fields ({kind}");
        if !form.note.is_empty() {
            let _ = write!(head, ", {}", form.note);
        }
        head.push(')');
        t.add(0, "fields", head, None, NodeKind::Section);
        let motion = form.fields.iter().any(|x| x.q.is_some());
        if let Some(sc) = scale.filter(|_| motion) {
            t.add(
                1,
                "units",
                format!("units: {} (spec section 8)", sc.describe()),
                None,
                NodeKind::Item,
            );
        }
        for (fd, v) in f.fields() {
            let at = fd.loc.frame_offset();
            let w = fd.ty.width();
            let mut s = format!("{} = ", fd.name);
            fmt_value_in(table, fd, &v, scale, &mut s);
            let raw = raw_text(&v);
            let shown = aptscope_dissector::apt::phys(fd, &v, scale).is_some();
            if !raw.is_empty() && !s.ends_with(&raw) && !shown {
                let _ = write!(s, "   (raw {raw})");
            }
            let _ = write!(s, "  [{} @{at}]", fd.ty.name());
            let id = format!("f.{}", fd.name);
            t.add(1, &id, s, Some((at, w)), NodeKind::Item);
            if let (Some(fl), Some(x)) = (fd.flags, v.as_i64()) {
                let defs = table.flags_def(fl);
                for (mask, label) in &defs.items {
                    let on = (x as u64) & mask == *mask && *mask != 0;
                    let kind = if on {
                        NodeKind::FlagOn
                    } else {
                        NodeKind::FlagOff
                    };
                    let mark = if on { "[x]" } else { "[ ]" };
                    t.add(
                        2,
                        &format!("{id}.{label}"),
                        format!("{mark} 0x{mask:08X} {label}"),
                        Some((at, w)),
                        kind,
                    );
                }
            }
        }
    } else if bytes.len() > 6 {
        let mut s = String::from("Data (no matching form): ");
        for b in &bytes[6..] {
            let _ = write!(s, "{b:02x}");
        }
        t.add(0, "data", s, Some((6, bytes.len() - 6)), NodeKind::Item);
    }
    let diags: Vec<Diag> = f.diags().collect();
    if !diags.is_empty() {
        t.add(
            0,
            "diag",
            format!("Diagnostics ({})", diags.len()),
            None,
            NodeKind::Section,
        );
        for (i, d) in diags.iter().enumerate() {
            let rel = d.offset.saturating_sub(r.offset) as usize;
            let range = (rel < bytes.len()).then_some((rel, 1));
            t.add(
                1,
                &format!("diag.{i}"),
                format!("!! {} (offset {:#x}, +{rel})", diag_text(d), d.offset),
                range,
                NodeKind::Diag,
            );
        }
    }
}

/// A diagnostic as `kind: message`, the kind once (some messages start with it:
/// `truncated: header announces …`).
fn diag_text(d: &Diag) -> String {
    let (name, msg) = (d.kind.name(), d.kind.to_string());
    match msg.strip_prefix(name).and_then(|m| m.strip_prefix(':')) {
        Some(_) => msg,
        None => format!("{name}: {msg}"),
    }
}

fn raw_text(v: &Value<'_>) -> String {
    match v {
        Value::U(x) => format!("{x:#x}"),
        Value::I(x) => format!("{x}"),
        Value::F(x) => format!("{x}"),
        _ => String::new(),
    }
}

fn ell_tree(ix: &Index, r: &Rec, _n: u64, bytes: &[u8], t: &mut Tree) {
    let Some(f) = EllFrame::decode(r.offset, bytes, r.has(F_TRUNCATED)) else {
        return;
    };
    let h = head(bytes).and_then(|h| h.ok());
    let (cmd_at, data_at) = h.map_or((1, 3), |h| (h.cmd_at, h.data_at));
    t.add(
        0,
        "text",
        format!("Text: {:?}", String::from_utf8_lossy(bytes)),
        Some((0, bytes.len())),
        NodeKind::Item,
    );
    let m = module_of(ix, r);
    let mut a = format!("address: {}", f.addr_char());
    if let Some(m) = &m {
        if let Some(model) = m.model {
            let _ = write!(a, " — ELL{model}");
        }
        if let Some(s) = &m.serial {
            let _ = write!(a, " serial {s}");
        }
        if m.first_addr != f.addr {
            let _ = write!(a, " (first seen at address {:X})", m.first_addr);
        }
    }
    t.add(0, "addr", a, Some((0, 1)), NodeKind::Item);
    let dir = if f.dir() == Dir::HostToDevice {
        "host → module"
    } else {
        "module → host"
    };
    let mut c = format!(
        "command: {} {} ({dir})",
        f.code_str(),
        f.cmd.map_or("UNKNOWN", |c| c.name)
    );
    if let Some(cmd) = f.cmd {
        if !cmd.doc.is_empty() {
            let _ = write!(c, ": {}", cmd.doc);
        }
    }
    t.add(0, "cmd", c, Some((cmd_at, 2)), NodeKind::Item);
    let scale = m.as_ref().and_then(|m| m.scale());
    let fields: Vec<_> = f.fields().collect();
    if !fields.is_empty() {
        t.add(0, "fields", "Fields".into(), None, NodeKind::Section);
        let mut at = data_at;
        for (fd, v) in fields {
            // Binary data runs to the terminator (whose bytes it may share values with).
            let w = if fd.kind == ell::table::Kind::Raw {
                f.terminator_at().saturating_sub(at)
            } else {
                fd.width as usize
            };
            let mut s = format!("{} = ", fd.name);
            ell::fmt_value(fd, &v, scale, &mut s);
            let raw = bytes.get(at..(at + w).min(bytes.len())).unwrap_or(&[]);
            if fd.kind != ell::table::Kind::Raw {
                let _ = write!(s, "   (raw {:?})", String::from_utf8_lossy(raw));
            }
            t.add(
                1,
                &format!("f.{}", fd.name),
                s,
                Some((at.min(bytes.len()), w)),
                NodeKind::Item,
            );
            at += w;
        }
    }
    if f.terminated {
        let end = f.terminator_at();
        t.add(
            0,
            "term",
            "terminator: CR/LF".into(),
            Some((end, bytes.len() - end)),
            NodeKind::Item,
        );
    }
    if !f.diags().is_empty() {
        t.add(
            0,
            "diag",
            format!("Diagnostics ({})", f.diags().len()),
            None,
            NodeKind::Section,
        );
        for (i, d) in f.diags().iter().enumerate() {
            let rel = d.offset.saturating_sub(r.offset) as usize;
            let range = (rel < bytes.len()).then_some((rel, 1));
            t.add(
                1,
                &format!("diag.{i}"),
                format!("!! {} (offset {:#x}, +{rel})", diag_text(d), d.offset),
                range,
                NodeKind::Diag,
            );
        }
    }
}

/// The NDJSON object of record `n`, as `aptscope decode --json` prints it: the pipeline's
/// renderer on the re-decoded record.
pub fn json_of(ix: &Index, n: u64) -> Option<String> {
    with_record(ix, n, |rec| {
        Renderer::new(Format::Json).line(rec).to_string()
    })
}
