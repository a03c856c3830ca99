//! The shape of decoded records (documented in docs/ndjson.md), written once
//! through a [`Sink`]: NDJSON text (`String`, one object per line, no allocation per value),
//! the Python package's dicts, the replay's owned values. Every view that gives a record's
//! fields takes them from here, so the shape rules live in one place.

use crate::apt::{text_of, Addr, AptFrame, GarbageKind, Value};
use crate::diag::{Diag, DiagKind};
use crate::ell::{EllFrame, EllValue, Observation};
use crate::pair::PairInfo;
use crate::record::{Meta, Record};
use crate::shape::{curve_members, ell_derived, CurveNum, DerivedName, DerivedVal};
use crate::table::{Field, Table};
use crate::units::{Notice, Scale};

// Kept here too, where callers found them before [`crate::shape`] held them.
pub use crate::shape::{apt_diags, ell_phys, garbage_diag, hex_digits};
use std::fmt::Write;

/// Where a record's shape is written: objects, lists and scalars, in document order. A value
/// inside an object follows its [`key`](Sink::key); a sink places commas and nesting itself.
pub trait Sink {
    /// Open an object (a value, or the record itself).
    fn begin_obj(&mut self);
    /// Close the innermost object.
    fn end_obj(&mut self);
    /// Open a list.
    fn begin_list(&mut self);
    /// Close the innermost list.
    fn end_list(&mut self);
    /// The key of the next member of the innermost object. Keys are identifiers (names from
    /// this module and the message tables, which the APT table's parser and an Elliptec table
    /// test keep to letters, digits and `_`): NDJSON writes them without escaping.
    fn key(&mut self, k: &str);
    /// A key that lives as long as the program (a table's field name): a sink may keep what
    /// it makes of it.
    fn key_static(&mut self, k: &'static str) {
        self.key(k)
    }
    /// A key written in the code (see `key!`): NDJSON copies its prepared spelling.
    fn key_lit(&mut self, k: &Lit) {
        self.key(k.name)
    }
    /// A string value.
    fn str(&mut self, s: &str);
    /// A string value known to need no escaping (ASCII words: codes, directions, kinds).
    fn plain(&mut self, s: &str) {
        self.str(s)
    }
    /// Bytes as a lower-case hex string.
    fn hex(&mut self, b: &[u8]);
    /// An unsigned integer.
    fn uint(&mut self, x: u64);
    /// A signed integer.
    fn int(&mut self, x: i64);
    /// A float as NDJSON writes it (`{x}`: shortest round-trip digits, no exponent, whole
    /// numbers without a fraction); non-finite ones are null.
    fn float(&mut self, x: f64);
    /// A float with a fixed number of decimals (`0.950`).
    fn fixed(&mut self, x: f64, decimals: usize);
    /// A boolean.
    fn bool(&mut self, b: bool);
    /// Null.
    fn null(&mut self);
}

/// A key written in the code, with its NDJSON spelling prepared at compile time (`"name":`).
#[derive(Debug)]
pub struct Lit {
    /// The key.
    pub name: &'static str,
    /// `"name":`.
    pub json: &'static str,
}

/// `key!(out, "name")`: the key `name` of the next member, spelled for NDJSON at compile time.
macro_rules! key {
    ($out:expr, $name:literal) => {
        $out.key_lit(&Lit {
            name: $name,
            json: concat!("\"", $name, "\":"),
        })
    };
}

/// `rec_key!(out, "name")`: as [`key!`], for a key of a decoded record, which must be in the
/// record's shape ([`crate::shape::KEYS`], what filters and statistics read): a key written here
/// but not listed there does not build.
macro_rules! rec_key {
    ($out:expr, $name:literal) => {{
        const _: () = assert!(
            crate::shape::is_key($name),
            concat!("record key `", $name, "` is not in shape::KEYS")
        );
        key!($out, $name)
    }};
}

/// A comma before a member or element unless it is the first of its object or list (the
/// last byte written tells: keys end in `:`, openings in `{`/`[`, a caller's prefix in `,`).
#[inline(always)]
fn sep(out: &mut String) {
    if !matches!(
        out.as_bytes().last(),
        None | Some(b'{' | b'[' | b':' | b',')
    ) {
        out.push(',');
    }
}

/// NDJSON text: the record appended to the string.
impl Sink for String {
    #[inline(always)]
    fn begin_obj(&mut self) {
        sep(self);
        self.push('{');
    }
    #[inline(always)]
    fn end_obj(&mut self) {
        self.push('}');
    }
    #[inline(always)]
    fn begin_list(&mut self) {
        sep(self);
        self.push('[');
    }
    #[inline(always)]
    fn end_list(&mut self) {
        self.push(']');
    }
    #[inline(always)]
    fn key(&mut self, k: &str) {
        sep(self);
        self.push('"');
        self.push_str(k);
        self.push_str("\":");
    }
    #[inline(always)]
    fn key_static(&mut self, k: &'static str) {
        self.key(k);
    }
    #[inline(always)]
    fn key_lit(&mut self, k: &Lit) {
        sep(self);
        // A constant length: copied inline, not through `memcpy`.
        self.push_str(k.json);
    }
    #[inline(always)]
    fn str(&mut self, s: &str) {
        sep(self);
        string(self, s);
    }
    #[inline(always)]
    fn plain(&mut self, s: &str) {
        sep(self);
        self.push('"');
        self.push_str(s);
        self.push('"');
    }
    #[inline(always)]
    fn hex(&mut self, b: &[u8]) {
        sep(self);
        hex(self, b);
    }
    #[inline(always)]
    fn uint(&mut self, x: u64) {
        sep(self);
        uint(self, x);
    }
    #[inline(always)]
    fn int(&mut self, x: i64) {
        sep(self);
        int(self, x);
    }
    #[inline(always)]
    fn float(&mut self, x: f64) {
        sep(self);
        float(self, x);
    }
    fn fixed(&mut self, x: f64, decimals: usize) {
        sep(self);
        let _ = write!(self, "{x:.decimals$}");
    }
    #[inline(always)]
    fn bool(&mut self, b: bool) {
        sep(self);
        self.push_str(if b { "true" } else { "false" });
    }
    #[inline(always)]
    fn null(&mut self) {
        sep(self);
        self.push_str("null");
    }
}

/// Append `s` as a JSON string literal.
pub fn string(out: &mut String, s: &str) {
    out.push('"');
    // Names and labels never need escaping: copy them in one go.
    if s.bytes().all(|b| b >= 0x20 && b != b'"' && b != b'\\') {
        out.push_str(s);
        out.push('"');
        return;
    }
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

/// Append bytes as a lower-case hex JSON string.
pub fn hex(out: &mut String, b: &[u8]) {
    out.reserve(b.len() * 2 + 2);
    out.push('"');
    hex_digits(out, b);
    out.push('"');
}

/// Append a float (non-finite as `null`).
pub fn float(out: &mut String, x: f64) {
    if x.is_finite() {
        let _ = write!(out, "{x}");
    } else {
        out.push_str("null");
    }
}

/// Append an unsigned integer (two digits a step, no `fmt` machinery: integers are most of
/// a record's numbers).
pub fn uint(out: &mut String, x: u64) {
    out.push_str(itoa::Buffer::new().format(x));
}

/// Append a signed integer.
pub fn int(out: &mut String, x: i64) {
    if x < 0 {
        out.push('-');
    }
    uint(out, x.unsigned_abs());
}

/// Short text formatted on the stack (hex ids, model names, derived keys): no allocation.
struct Small {
    b: [u8; 64],
    n: usize,
}

impl Small {
    fn new() -> Self {
        Small { b: [0; 64], n: 0 }
    }
    fn as_str(&self) -> &str {
        std::str::from_utf8(&self.b[..self.n]).unwrap_or_default()
    }
}

impl Write for Small {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let end = self.n + s.len();
        self.b
            .get_mut(self.n..end)
            .ok_or(std::fmt::Error)?
            .copy_from_slice(s.as_bytes());
        self.n = end;
        Ok(())
    }
}

fn small(args: std::fmt::Arguments<'_>) -> Small {
    let mut s = Small::new();
    let _ = s.write_fmt(args);
    s
}

/// Write one record as one object: what `decode --json` prints on a line (`file` first when
/// records name their input).
pub fn record<S: Sink + ?Sized>(out: &mut S, rec: &Record<'_>, file: Option<&str>) {
    out.begin_obj();
    if let Some(name) = file {
        key!(out, "file");
        out.str(name);
    }
    match rec {
        Record::Detect {
            proto,
            detection: d,
            ..
        } => {
            key!(out, "type");
            out.plain("detect");
            key!(out, "proto");
            out.plain(proto.code());
            key!(out, "certain");
            out.bool(d.proto.is_some());
            key!(out, "apt");
            out.fixed(d.apt, 3);
            key!(out, "ell");
            out.fixed(d.elliptec, 3);
        }
        Record::Stream { id, name, settings } => {
            key!(out, "type");
            out.plain("stream");
            key!(out, "stream");
            out.uint(u64::from(*id));
            key!(out, "stream_name");
            out.str(name);
            if let Some(x) = settings {
                key!(out, "settings");
                out.str(x);
            }
        }
        Record::Input(d) => {
            key!(out, "type");
            out.plain("input");
            key!(out, "diag");
            diags(out, std::iter::once(*d));
        }
        Record::FileDiag { offset, kind, msg } => {
            key!(out, "type");
            out.plain("input");
            key!(out, "diag");
            out.begin_list();
            out.begin_obj();
            key!(out, "kind");
            out.str(kind);
            key!(out, "offset");
            out.uint(*offset);
            key!(out, "msg");
            out.str(msg);
            out.end_obj();
            out.end_list();
        }
        Record::Units(nt) => units_members(out, nt),
        Record::Apt(a) => {
            apt_members(out, a.meta.n, a.frame, a.pair, a.scale);
            meta(
                out,
                &a.meta,
                Some(a.dir().map_or("unknown", |d| d.as_str())),
            );
        }
        Record::Ell(e) => {
            ell_members(out, e.meta.n, e.frame, e.obs);
            meta(out, &e.meta, None);
        }
        Record::Garbage(g) => match g.kind {
            Some(kind) => {
                apt_garbage_members(out, g.meta.n, g.offset, g.bytes, kind);
                let dir = g.meta.cap_dir.map_or("unknown", |d| d.as_str());
                meta(out, &g.meta, Some(dir));
            }
            // Elliptec garbage has no direction (the bus tells none).
            None => {
                ell_garbage_members(out, g.meta.n, g.offset, g.bytes);
                meta(out, &g.meta, None);
            }
        },
        Record::NoReply(e) => {
            late_diag_members(out, e.proto.code(), e.n, e.diag());
            rec_key!(out, "stream");
            out.uint(u64::from(e.stream));
        }
    }
    out.end_obj();
}

/// The capture context of a frame or garbage run, after its own members.
fn meta<S: Sink + ?Sized>(out: &mut S, m: &Meta, dir: Option<&str>) {
    rec_key!(out, "cap_offset");
    out.uint(m.cap_offset);
    if let Some(d) = dir {
        rec_key!(out, "dir");
        out.plain(d);
    }
    if let Some(t) = m.ts_ns {
        rec_key!(out, "ts_ns");
        out.uint(t);
    }
    rec_key!(out, "stream");
    out.uint(u64::from(m.stream));
}

/// A diagnostics list: `[{"kind":…, "offset":…, "msg":…}]`.
pub fn diags<S: Sink + ?Sized>(out: &mut S, ds: impl Iterator<Item = Diag>) {
    out.begin_list();
    for d in ds {
        out.begin_obj();
        key!(out, "kind");
        out.plain(d.kind.name());
        key!(out, "offset");
        out.uint(d.offset);
        key!(out, "msg");
        out.str(&d.kind.to_string());
        out.end_obj();
    }
    out.end_list();
}

/// One APT field value: numbers as numbers, enums as names, flags as lists of set names,
/// text as strings, opaque bytes as hex, arrays as arrays.
pub fn value<S: Sink + ?Sized>(out: &mut S, table: &Table, f: &Field, v: &Value<'_>) {
    match v {
        Value::U(x) => {
            if let Some(e) = f.enumeration {
                if let Some(l) = table.enum_def(e).label(*x as i64) {
                    return out.str(l);
                }
            }
            if let Some(fl) = f.flags {
                out.begin_list();
                for (_, l) in table.flags_def(fl).set(*x) {
                    out.str(l);
                }
                return out.end_list();
            }
            out.uint(*x);
        }
        Value::I(x) => {
            if let Some(l) = f.enumeration.and_then(|e| table.enum_def(e).label(*x)) {
                return out.str(l);
            }
            out.int(*x);
        }
        Value::F(x) => out.float(*x),
        Value::Str(b) => out.str(&text_of(b)),
        Value::Bytes(b) => out.hex(b),
        Value::Array(..) => {
            out.begin_list();
            for e in v.elements() {
                match e {
                    Value::U(x) => out.uint(x),
                    Value::I(x) => out.int(x),
                    Value::F(x) => out.float(x),
                    _ => out.null(),
                }
            }
            out.end_list();
        }
    }
}

const BAYS: [&str; 10] = [
    "bay0", "bay1", "bay2", "bay3", "bay4", "bay5", "bay6", "bay7", "bay8", "bay9",
];

/// An APT address: `{"addr":80,"name":"usb"}`, with `"bay"` for bays.
pub fn addr<S: Sink + ?Sized>(out: &mut S, a: Addr) {
    out.begin_obj();
    key!(out, "addr");
    out.uint(u64::from(a.byte()));
    key!(out, "name");
    match a {
        Addr::Host => out.plain("host"),
        Addr::Rack => out.plain("rack"),
        Addr::Usb => out.plain("usb"),
        Addr::Bay(n) => match BAYS.get(n as usize) {
            Some(b) => out.plain(b),
            None => out.plain(small(format_args!("bay{n}")).as_str()),
        },
        Addr::Unknown(x) => out.plain(small(format_args!("0x{x:02X}")).as_str()),
    }
    if let Some(b) = a.bay() {
        key!(out, "bay");
        out.uint(u64::from(b));
    }
    out.end_obj();
}

/// An APT sub-message: `{"id":…,"name":…}`.
pub fn sub<S: Sink + ?Sized>(out: &mut S, s: &crate::table::SubDef) {
    out.begin_obj();
    key!(out, "id");
    out.uint(u64::from(s.id));
    key!(out, "name");
    out.str(s.name);
    out.end_obj();
}

/// The `fields` object of an APT frame (decoded values by field name, in frame order).
pub fn apt_fields<S: Sink + ?Sized>(out: &mut S, f: &AptFrame<'_, '_>) {
    out.begin_obj();
    for (fd, v) in f.fields() {
        out.key_static(fd.name);
        value(out, f.table(), fd, &v);
    }
    out.end_obj();
}

/// The object of a decoded APT frame. `n` is the record number.
pub fn apt_frame<S: Sink + ?Sized>(out: &mut S, n: u64, f: &AptFrame<'_, '_>) {
    apt_frame_paired(out, n, f, &PairInfo::default());
}

/// [`apt_frame`] with what pairing found: `pair`, `latency_ms`, `pair_other_address`, and the
/// `unsolicited`/`duplicate_reply` diagnostics.
pub fn apt_frame_paired<S: Sink + ?Sized>(out: &mut S, n: u64, f: &AptFrame<'_, '_>, p: &PairInfo) {
    apt_frame_in(out, n, f, p, None)
}

/// [`apt_frame_paired`] with the stage's conversion: motion fields (`q=` in the table) get a
/// `phys` entry (`{"value": 2.5, "unit": "mm/s"}`) beside their raw value in `fields`.
pub fn apt_frame_in<S: Sink + ?Sized>(
    out: &mut S,
    n: u64,
    f: &AptFrame<'_, '_>,
    p: &PairInfo,
    scale: Option<&Scale>,
) {
    out.begin_obj();
    apt_members(out, n, f, p, scale);
    out.end_obj();
}

fn apt_members<S: Sink + ?Sized>(
    out: &mut S,
    n: u64,
    f: &AptFrame<'_, '_>,
    p: &PairInfo,
    scale: Option<&Scale>,
) {
    let h = f.header();
    record_head(out, "apt", "frame", n, f.offset, f.bytes);
    rec_key!(out, "msgid");
    out.uint(u64::from(h.msg_id()));
    rec_key!(out, "msgid_hex");
    const H: &[u8; 16] = b"0123456789ABCDEF";
    let id = h.msg_id();
    let mut x = *b"0x0000";
    for (i, sh) in [12, 8, 4, 0].into_iter().enumerate() {
        x[2 + i] = H[(id >> sh) as usize & 15];
    }
    out.plain(std::str::from_utf8(&x).unwrap_or_default());
    rec_key!(out, "name");
    match f.msg {
        Some(m) => {
            out.str(m.name);
            rec_key!(out, "msg_dir");
            out.plain(m.dir.as_str());
        }
        None => out.null(),
    }
    rec_key!(out, "src");
    addr(out, h.src());
    rec_key!(out, "dst");
    addr(out, h.dst());
    rec_key!(out, "data_flag");
    out.bool(h.has_data());
    rec_key!(out, "data_len");
    out.uint(f.data_len() as u64);
    if let Some(form) = f.form.filter(|x| !x.note.is_empty()) {
        rec_key!(out, "form_note");
        out.str(form.note);
    }
    if let Some(c) = f.channel() {
        rec_key!(out, "channel");
        out.int(c);
    }
    if let Some(s) = f.sub {
        rec_key!(out, "sub");
        sub(out, s);
    }
    rec_key!(out, "fields");
    apt_fields(out, f);
    // `phys` and `codes` in passes of their own (no buffer, no allocation per frame), taken
    // only when the form has fields they concern.
    let defs = f.form.map_or(&[][..], |x| x.fields.as_slice());
    if defs.iter().any(|fd| {
        fd.scale.is_some() || (scale.is_some() && (fd.q.is_some() || fd.pct_of.is_some()))
    }) {
        phys_map(
            out,
            f.fields()
                .filter_map(|(fd, v)| Some((fd.name, crate::apt::phys_or_scaled(fd, &v, scale)?))),
        );
    }
    if defs
        .iter()
        .any(|fd| fd.enumeration.is_some() || fd.flags.is_some())
    {
        codes(
            out,
            f.fields()
                .filter_map(|(fd, v)| Some((fd.name, crate::shape::apt_code(fd, &v)?))),
        );
    }
    pairing(out, p.pair, p.latency_ns);
    if p.other_address {
        rec_key!(out, "pair_other_address");
        out.bool(true);
    }
    rec_key!(out, "diag");
    diags(out, apt_diags(f, p));
}

/// `"pair"` and `"latency_ms"` of a reply, when paired.
fn pairing<S: Sink + ?Sized>(out: &mut S, pair: Option<u64>, latency_ns: Option<u64>) {
    if let Some(x) = pair {
        rec_key!(out, "pair");
        out.uint(x);
    }
    if let Some(l) = latency_ns {
        rec_key!(out, "latency_ms");
        out.float(l as f64 / 1e6);
    }
}

/// `"phys":{name:{"value":…,"unit":…},…}` when any field converts.
fn phys_map<'u, S: Sink + ?Sized>(
    out: &mut S,
    items: impl Iterator<Item = (&'static str, (f64, &'u str))>,
) {
    let mut first = true;
    for (name, (x, unit)) in items {
        if first {
            rec_key!(out, "phys");
            out.begin_obj();
            first = false;
        }
        out.key_static(name);
        out.begin_obj();
        key!(out, "value");
        out.float(x);
        key!(out, "unit");
        out.str(unit);
        out.end_obj();
    }
    if !first {
        out.end_obj();
    }
}

/// `"codes":{name:number,…}` when there are any.
fn codes<S: Sink + ?Sized>(out: &mut S, items: impl Iterator<Item = (&'static str, i128)>) {
    let mut first = true;
    for (name, c) in items {
        if first {
            rec_key!(out, "codes");
            out.begin_obj();
            first = false;
        }
        out.key_static(name);
        match u64::try_from(c) {
            Ok(u) => out.uint(u),
            Err(_) => out.int(c as i64),
        }
    }
    if !first {
        out.end_obj();
    }
}

/// The object of a units notice: what converts a device's motion values from now on
/// (`{"type":"units","stream":0,"addr":{…},"model":"KDC101","stage":"MTS25-Z8",
/// "family":"dc_servo","counts_per_unit":34554.96,"unit":"mm"}`), or why they stay raw
/// (`"raw":"…"`).
pub fn units_notice<S: Sink + ?Sized>(out: &mut S, n: &Notice) {
    out.begin_obj();
    units_members(out, n);
    out.end_obj();
}

fn units_members<S: Sink + ?Sized>(out: &mut S, n: &Notice) {
    use crate::units::Resolution;
    key!(out, "type");
    out.plain("units");
    key!(out, "stream");
    out.uint(u64::from(n.stream));
    key!(out, "addr");
    addr(out, Addr::from_byte(n.addr));
    if let Some(m) = &n.model {
        key!(out, "model");
        out.str(m);
    }
    match &n.resolution {
        Resolution::Scale(s) => {
            key!(out, "stage");
            out.str(s.stage);
            if let Some(f) = s.family {
                key!(out, "family");
                out.str(f.name());
            }
            key!(out, "counts_per_unit");
            out.float(s.counts_per_unit);
            key!(out, "unit");
            out.str(s.unit);
        }
        Resolution::Raw(why) => {
            key!(out, "raw");
            out.str(why);
        }
        Resolution::None => {
            key!(out, "raw");
            out.plain("no stage");
        }
    }
}

/// The object of an APT garbage record.
pub fn apt_garbage<S: Sink + ?Sized>(
    out: &mut S,
    n: u64,
    offset: u64,
    bytes: &[u8],
    kind: GarbageKind,
) {
    out.begin_obj();
    apt_garbage_members(out, n, offset, bytes, kind);
    out.end_obj();
}

/// The keys every frame and garbage record starts with: number, protocol, type (`frame` or
/// `garbage`), offset, length, raw bytes.
fn record_head<S: Sink + ?Sized>(
    out: &mut S,
    proto: &str,
    kind: &str,
    n: u64,
    offset: u64,
    bytes: &[u8],
) {
    rec_key!(out, "n");
    out.uint(n);
    rec_key!(out, "proto");
    out.plain(proto);
    rec_key!(out, "type");
    out.plain(kind);
    rec_key!(out, "offset");
    out.uint(offset);
    rec_key!(out, "len");
    out.uint(bytes.len() as u64);
    rec_key!(out, "raw");
    out.hex(bytes);
}

fn apt_garbage_members<S: Sink + ?Sized>(
    out: &mut S,
    n: u64,
    offset: u64,
    bytes: &[u8],
    kind: GarbageKind,
) {
    record_head(out, "apt", "garbage", n, offset, bytes);
    rec_key!(out, "diag");
    diags(
        out,
        std::iter::once(garbage_diag(offset, bytes.len(), kind)),
    );
}

/// The `fields` object of an Elliptec frame: status codes by name, and the keys derived beside
/// a field (`curve_points`, `<name>_name`, `<name>_version`, `thread`, `hw_release`).
pub fn ell_fields<S: Sink + ?Sized>(out: &mut S, f: &EllFrame<'_>) {
    use crate::ell::table::Kind;
    out.begin_obj();
    for (fd, v) in f.fields() {
        out.key_static(fd.name);
        match (fd.kind, v) {
            (Kind::Status, EllValue::U(c)) => out.str(crate::ell::table::status_name(c as u32)),
            (_, EllValue::U(x)) => out.uint(x),
            (_, EllValue::I(x)) => out.int(x),
            (_, EllValue::Char(c)) => out.str(c.encode_utf8(&mut [0; 4])),
            (_, EllValue::Digits(d)) => out.str(d),
            (_, EllValue::Raw(b)) => out.hex(b),
        }
        for d in ell_derived(fd.kind) {
            let Some(x) = (d.value)(&v) else { continue };
            match d.name {
                DerivedName::Fixed(name) => out.key_static(name),
                DerivedName::Suffix(s) => out.key(small(format_args!("{}{s}", fd.name)).as_str()),
            }
            match x {
                DerivedVal::Word(w) => out.plain(w),
                DerivedVal::Uint(x) => out.uint(x),
                DerivedVal::Model(_) | DerivedVal::Version(_) => {
                    out.plain(small(format_args!("{x}")).as_str())
                }
                DerivedVal::Curve(b) => {
                    out.begin_list();
                    for p in crate::ell::curve_points(b) {
                        out.begin_obj();
                        for (name, v) in curve_members(&p) {
                            out.key_static(name);
                            match v {
                                CurveNum::U(x) => out.uint(x),
                                CurveNum::F(x) => out.float(x),
                            }
                        }
                        out.end_obj();
                    }
                    out.end_list();
                }
            }
        }
    }
    out.end_obj();
}

/// The object of a decoded Elliptec frame with what the bus made of it.
pub fn ell_frame<S: Sink + ?Sized>(out: &mut S, n: u64, f: &EllFrame<'_>, o: &Observation) {
    out.begin_obj();
    ell_members(out, n, f, o);
    out.end_obj();
}

fn ell_members<S: Sink + ?Sized>(out: &mut S, n: u64, f: &EllFrame<'_>, o: &Observation) {
    record_head(out, "ell", "frame", n, f.offset, f.bytes);
    rec_key!(out, "text");
    out.str(&String::from_utf8_lossy(f.bytes));
    rec_key!(out, "addr");
    out.plain(f.addr_char().encode_utf8(&mut [0; 4]));
    rec_key!(out, "dir");
    out.plain(f.dir().as_str());
    rec_key!(out, "cmd");
    out.str(f.code_str());
    rec_key!(out, "name");
    match f.cmd {
        Some(c) => out.str(c.name),
        None => out.null(),
    }
    rec_key!(out, "fields");
    ell_fields(out, f);
    let scale = o.module.as_ref().and_then(|m| m.scale());
    phys_map(
        out,
        f.fields()
            .filter_map(|(fd, v)| Some((fd.name, ell_phys(fd, &v, scale)?))),
    );
    codes(
        out,
        f.fields()
            .filter_map(|(fd, v)| Some((fd.name, i128::from(crate::shape::ell_code(fd, &v)?)))),
    );
    if let Some(m) = &o.module {
        rec_key!(out, "module");
        out.begin_obj();
        key!(out, "first_addr");
        out.uint(u64::from(m.first_addr));
        if let Some(x) = m.model {
            key!(out, "model");
            out.plain(small(format_args!("{}", DerivedVal::Model(u64::from(x)))).as_str());
        }
        if let Some(s) = &m.serial {
            key!(out, "serial");
            out.str(s);
        }
        out.end_obj();
    }
    pairing(out, o.pair, o.latency_ns);
    if o.interim {
        rec_key!(out, "interim");
        out.bool(true);
    }
    rec_key!(out, "diag");
    diags(out, f.diags().iter().copied());
}

/// The object of an Elliptec garbage record.
pub fn ell_garbage<S: Sink + ?Sized>(out: &mut S, n: u64, offset: u64, bytes: &[u8]) {
    out.begin_obj();
    ell_garbage_members(out, n, offset, bytes);
    out.end_obj();
}

fn ell_garbage_members<S: Sink + ?Sized>(out: &mut S, n: u64, offset: u64, bytes: &[u8]) {
    record_head(out, "ell", "garbage", n, offset, bytes);
    rec_key!(out, "text");
    out.str(&String::from_utf8_lossy(bytes));
    rec_key!(out, "diag");
    let d = Diag {
        offset,
        kind: DiagKind::Garbage {
            len: bytes.len() as u32,
        },
    };
    diags(out, std::iter::once(d));
}

/// The object of a diagnostic that refers to an earlier record (a command that got no reply).
pub fn late_diag<S: Sink + ?Sized>(out: &mut S, proto: &str, refers_to: u64, d: Diag) {
    out.begin_obj();
    late_diag_members(out, proto, refers_to, d);
    out.end_obj();
}

fn late_diag_members<S: Sink + ?Sized>(out: &mut S, proto: &str, refers_to: u64, d: Diag) {
    rec_key!(out, "proto");
    out.plain(proto);
    rec_key!(out, "type");
    out.plain("diag");
    rec_key!(out, "ref");
    out.uint(refers_to);
    rec_key!(out, "diag");
    diags(out, std::iter::once(d));
}

// ---------------------------------------------------------------------------------------------
// Message listings (`aptscope messages --json`): table definitions, not records.

fn form_json(out: &mut String, table: &Table, form: &crate::table::Form) {
    use crate::table::{FormKind, Loc};
    out.push_str("{\"kind\":");
    match form.kind {
        FormKind::Header => out.push_str("\"header\",\"data_len\":0"),
        FormKind::Data(n) => {
            let _ = write!(out, "\"data\",\"data_len\":{n}");
        }
        FormKind::Sub => out.push_str("\"sub\""),
        FormKind::Open(n) => {
            let _ = write!(out, "\"open\",\"data_len\":{n}");
        }
    }
    if !form.note.is_empty() {
        out.push_str(",\"note\":");
        string(out, form.note);
    }
    out.push_str(",\"fields\":[");
    for (i, f) in form.fields.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push_str("{\"name\":");
        string(out, f.name);
        match f.loc {
            Loc::P1 => out.push_str(",\"loc\":\"param1\""),
            Loc::P2 => out.push_str(",\"loc\":\"param2\""),
            Loc::Data(o) => {
                let _ = write!(out, ",\"offset\":{o}");
            }
        }
        let _ = write!(
            out,
            ",\"type\":\"{}\",\"width\":{}",
            f.ty.name(),
            f.ty.width()
        );
        if let Some(u) = f.unit {
            out.push_str(",\"unit\":");
            string(out, u);
        }
        if let Some(s) = f.scale {
            out.push_str(",\"scale\":");
            float(out, s);
        }
        if let Some(q) = f.q {
            out.push_str(",\"q\":");
            string(out, q.as_str());
        }
        if let Some(e) = f.enumeration {
            let d = table.enum_def(e);
            let _ = write!(out, ",\"enum\":{{\"name\":\"{}\",\"values\":{{", d.name);
            for (j, (v, l)) in d.items.iter().enumerate() {
                let _ = write!(out, "{}\"{v}\":\"{l}\"", if j > 0 { "," } else { "" });
            }
            out.push_str("}}");
        }
        if let Some(fl) = f.flags {
            let d = table.flags_def(fl);
            let _ = write!(out, ",\"flags\":{{\"name\":\"{}\",\"bits\":{{", d.name);
            for (j, (m, l)) in d.items.iter().enumerate() {
                let _ = write!(out, "{}\"0x{m:X}\":\"{l}\"", if j > 0 { "," } else { "" });
            }
            out.push_str("}}");
        }
        out.push('}');
    }
    out.push_str("]}");
}

fn forms_json(out: &mut String, table: &Table, forms: &[crate::table::Form]) {
    out.push_str(",\"forms\":[");
    for (i, f) in forms.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        form_json(out, table, f);
    }
    out.push(']');
}

/// Append the JSON object describing a message definition (for `aptscope messages --json`).
pub fn msg_def(out: &mut String, table: &Table, m: &crate::table::MsgDef) {
    let _ = write!(
        out,
        "{{\"proto\":\"apt\",\"type\":\"msg\",\"msgid\":{},\"msgid_hex\":\"0x{:04X}\",\"name\":",
        m.id, m.id
    );
    string(out, m.name);
    let _ = write!(out, ",\"dir\":\"{}\",\"doc\":", m.dir.as_str());
    string(out, m.doc);
    let replies: Vec<&str> = table.replies_of(m).iter().map(|r| r.name).collect();
    out.push_str(",\"replies\":[");
    for (i, r) in replies.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        string(out, r);
    }
    out.push(']');
    if let Some(g) = m.subs {
        out.push_str(",\"sub_group\":");
        string(out, g);
    }
    out.push_str(",\"revisions\":[");
    for (i, r) in m.revs.names().iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        string(out, r);
    }
    out.push_str("],\"devices\":[");
    for (i, d) in table.models_of(m).iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        string(out, d);
    }
    out.push(']');
    forms_json(out, table, &m.forms);
    let _ = write!(out, ",\"examples\":{}}}", m.examples.len());
}

/// Append the JSON object describing a sub-message definition.
pub fn sub_def(out: &mut String, table: &Table, s: &crate::table::SubDef) {
    let _ = write!(
        out,
        "{{\"proto\":\"apt\",\"type\":\"sub\",\"group\":\"{}\",\"sub_id\":{},\"name\":",
        s.group, s.id
    );
    string(out, s.name);
    out.push_str(",\"doc\":");
    string(out, s.doc);
    forms_json(out, table, &s.forms);
    let _ = write!(out, ",\"examples\":{}}}", s.examples.len());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::Proto;
    use crate::record::{Ctx, Decoder};
    use serde_json::Value as J;

    /// A sink that builds `serde_json` values through the trait's structure calls only (what
    /// the Python package and the replay do): keys, nesting and values must come in an order
    /// that rebuilds the text's object.
    #[derive(Default)]
    struct Tree {
        stack: Vec<(Option<String>, J)>,
        key: Option<String>,
        top: Option<J>,
    }

    impl Tree {
        fn put(&mut self, v: J) {
            match self.stack.last_mut() {
                None => self.top = Some(v),
                Some((_, J::Object(m))) => {
                    let k = self.key.take().expect("a member without a key");
                    assert!(!m.contains_key(&k), "key {k} twice");
                    m.insert(k, v);
                }
                Some((_, J::Array(a))) => a.push(v),
                Some(_) => panic!("a value inside a scalar"),
            }
        }
        fn close(&mut self) {
            let (k, v) = self.stack.pop().expect("balanced");
            self.key = k;
            self.put(v);
        }
    }

    impl Sink for Tree {
        fn begin_obj(&mut self) {
            self.stack
                .push((self.key.take(), J::Object(Default::default())));
        }
        fn end_obj(&mut self) {
            self.close();
        }
        fn begin_list(&mut self) {
            self.stack.push((self.key.take(), J::Array(vec![])));
        }
        fn end_list(&mut self) {
            self.close();
        }
        fn key(&mut self, k: &str) {
            assert!(self.key.is_none(), "two keys in a row");
            self.key = Some(k.to_string());
        }
        fn str(&mut self, s: &str) {
            self.put(J::from(s));
        }
        fn hex(&mut self, b: &[u8]) {
            let mut s = String::new();
            hex_digits(&mut s, b);
            self.put(J::from(s));
        }
        fn uint(&mut self, x: u64) {
            self.put(J::from(x));
        }
        fn int(&mut self, x: i64) {
            self.put(J::from(x));
        }
        fn float(&mut self, x: f64) {
            // What a JSON reader makes of `{x}`.
            let mut s = String::new();
            float(&mut s, x);
            self.put(serde_json::from_str(&s).expect("a number"));
        }
        fn fixed(&mut self, x: f64, decimals: usize) {
            self.put(serde_json::from_str(&format!("{x:.decimals$}")).expect("a number"));
        }
        fn bool(&mut self, b: bool) {
            self.put(J::from(b));
        }
        fn null(&mut self) {
            self.put(J::Null);
        }
    }

    /// Every record of a stream with every message form of the table (and garbage), APT and
    /// Elliptec: built through the sink's structure calls it equals the NDJSON text read back.
    #[test]
    fn a_structured_sink_rebuilds_the_ndjson_object() {
        let apt = crate::synth::stream(Table::global(), 7, 3000, true);
        let ell = b"0in0E1140TESTSERIAL2019015001F4000001000\r\n0ma00001000\r\n0PO00001000\r\n\
                    0gs\r\n0GS0C\r\nxyz\r\n0gp\r\n"
            .to_vec();
        let mut seen = [0usize; 2];
        for (i, (proto, bytes)) in [(Proto::Apt, apt), (Proto::Elliptec, ell)]
            .into_iter()
            .enumerate()
        {
            let mut dec = Decoder::new(None);
            let mut check = |r: &Record<'_>| -> Result<(), ()> {
                let mut line = String::new();
                record(&mut line, r, Some("a \"file\""));
                let text: J = serde_json::from_str(&line).expect("NDJSON");
                let mut t = Tree::default();
                record(&mut t, r, Some("a \"file\""));
                assert!(t.stack.is_empty());
                assert_eq!(t.top.as_ref(), Some(&text), "{line}");
                seen[i] += 1;
                Ok(())
            };
            let ctx = Ctx {
                ts_ns: Some(1_000),
                ..Ctx::default()
            };
            dec.push(ctx, &bytes, &mut check).expect("records");
            dec.finish(&mut check).expect("records");
            assert_eq!(dec.proto(), Some(proto));
        }
        assert!(seen[0] > 3000 && seen[1] > 6, "{seen:?}");
    }
}
