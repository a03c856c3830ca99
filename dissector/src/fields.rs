//! Field access by name: what display filters ([`crate::filter`]) and statistics
//! ([`crate::stats`]) read of a record, straight from the typed [`Record`] — no JSON rendered
//! and parsed back.
//!
//! Names are the NDJSON keys (see docs/ndjson.md), listed once in [`KEYS`]: the
//! filter's name check, its suggestions and the accessors below all read that list. A field is
//! read as a [`Key`] (the top-level key, resolved once when a filter is compiled) and the rest
//! of its dotted path. The same trait is implemented on `serde_json::Value` (one NDJSON object),
//! for views that hold records as JSON; a test holds both implementations equal on every sample.

use crate::apt::{text_of, AptFrame, Value as AptValue};
use crate::diag::Diag;
use crate::ell::table::Kind as EllKind;
use crate::ell::EllValue;
use crate::record::{AptRec, EllRec, GarbageRec, Record};
use crate::shape::{self, curve_members, ell_derived, CurveNum, DerivedVal, EllDerived, Head};
use std::borrow::Cow;

// The key list and the `codes` rules live with the rest of the record's shape.
pub use crate::shape::{apt_code, ell_code, Key, KeyDef, APT, ELL, KEYS, TOP};

/// A number: integers stay exact.
#[derive(Clone, Copy, Debug)]
pub enum Num {
    /// Integer.
    I(i128),
    /// Floating point.
    F(f64),
}

impl Num {
    /// As a float.
    pub fn f(self) -> f64 {
        match self {
            Num::I(i) => i as f64,
            Num::F(f) => f,
        }
    }
    /// As an unsigned integer (a whole number within range).
    pub fn u64(self) -> Option<u64> {
        match self {
            Num::I(i) => u64::try_from(i).ok(),
            Num::F(f) if f >= 0.0 && f.fract() == 0.0 && f < 1.8e19 => Some(f as u64),
            Num::F(_) => None,
        }
    }
}

/// An object found at a path, as a comparison sees it: by its numeric member (`addr`, `id`,
/// `value`, the first present) or its text member (`name`, `model`, `kind`).
#[derive(Clone, Debug, Default)]
pub struct Obj<'a> {
    /// What a number compares with.
    pub num: Option<Num>,
    /// What text compares with.
    pub text: Option<Cow<'a, str>>,
    /// Whether the object has members (an empty one is false on its own).
    pub nonempty: bool,
}

/// One value found at a path.
#[derive(Clone, Debug)]
pub enum Val<'a> {
    /// A number.
    Num(Num),
    /// Text.
    Str(Cow<'a, str>),
    /// A boolean.
    Bool(bool),
    /// An object.
    Obj(Obj<'a>),
}

/// How a value was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// The value at the path.
    Plain,
    /// An element of the list at the path.
    Member,
    /// The numeric code of the enum or flag field at the path (`codes.X` beside `fields.X`):
    /// compared with, never on its own.
    Code,
}

/// Read access to a record's fields by [`Key`] and path.
pub trait Fields {
    /// The record's protocol code (`apt`, `ell`), if it has one.
    fn proto(&self) -> Option<&str>;

    /// Pass each value at `key` then `rest` to `f` (list elements one by one, as
    /// [`Role::Member`]; `fields.X` also gives `codes.X` as [`Role::Code`]). Returns whether
    /// the record has `key` at all (a key that is there but null, or a path below it that is
    /// not, still counts).
    fn visit(&self, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool;

    /// The one number at top-level `key`, when the record has it at hand (`n`, `len` …):
    /// `Some(x)` means [`Fields::visit`] would give exactly `Val::Num(Num::I(x))` once and
    /// nothing else. `None`: ask `visit` (the default). Lets a filter compare such keys
    /// without the visitor's indirection (an `i64`: returned in a register).
    fn number(&self, _key: Key) -> Option<i64> {
        None
    }

    /// The one word at top-level `key`, when the record has it at hand (`dir`, `type` …):
    /// `Some(s)` means [`Fields::visit`] would give exactly `Val::Str(s)` once and nothing
    /// else. `None`: ask `visit` (the default).
    fn word(&self, _key: Key) -> Option<&'static str> {
        None
    }
}

impl<T: Fields + ?Sized> Fields for &T {
    fn proto(&self) -> Option<&str> {
        (**self).proto()
    }
    fn visit(&self, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool {
        (**self).visit(key, rest, f)
    }
    fn number(&self, key: Key) -> Option<i64> {
        (**self).number(key)
    }
    fn word(&self, key: Key) -> Option<&'static str> {
        (**self).word(key)
    }
}

// ---------------------------------------------------------------------------------------------
// NDJSON objects.

impl Fields for serde_json::Value {
    fn proto(&self) -> Option<&str> {
        self.get("proto").and_then(serde_json::Value::as_str)
    }

    fn visit(&self, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool {
        let Some(v) = self.get(key.json_name()) else {
            return false;
        };
        collect(v, rest, false, f);
        if key == Key::Fields && rest.len() == 1 {
            if let Some(c) = self.get("codes").and_then(|c| c.get(&rest[0])) {
                if let Some(Val::Num(n)) = of_json(c) {
                    f(Val::Num(n), Role::Code);
                }
            }
        }
        true
    }
}

fn num_of_json(n: &serde_json::Number) -> Option<Num> {
    if let Some(i) = n.as_i64() {
        Some(Num::I(i128::from(i)))
    } else if let Some(u) = n.as_u64() {
        Some(Num::I(i128::from(u)))
    } else {
        n.as_f64().map(Num::F)
    }
}

fn of_json(v: &serde_json::Value) -> Option<Val<'_>> {
    use serde_json::Value as J;
    match v {
        J::Null | J::Array(_) => None,
        J::Bool(b) => Some(Val::Bool(*b)),
        J::Number(n) => num_of_json(n).map(Val::Num),
        J::String(s) => Some(Val::Str(Cow::Borrowed(s))),
        J::Object(m) => {
            let num = ["addr", "id", "value"]
                .iter()
                .filter_map(|k| m.get(*k).and_then(of_json))
                .find_map(|v| match v {
                    Val::Num(n) => Some(n),
                    _ => None,
                });
            let text = ["name", "model", "kind"]
                .iter()
                .filter_map(|k| m.get(*k).and_then(of_json))
                .find_map(|v| match v {
                    Val::Str(s) => Some(s),
                    _ => None,
                });
            Some(Val::Obj(Obj {
                num,
                text,
                nonempty: !m.is_empty(),
            }))
        }
    }
}

fn collect(v: &serde_json::Value, path: &[String], member: bool, f: &mut dyn FnMut(Val<'_>, Role)) {
    use serde_json::Value as J;
    match (v, path.split_first()) {
        (J::Array(items), _) => {
            for it in items {
                collect(it, path, member || path.is_empty(), f);
            }
        }
        (_, None) => {
            if let Some(x) = of_json(v) {
                f(x, if member { Role::Member } else { Role::Plain });
            }
        }
        (J::Object(m), Some((first, rest))) => {
            if let Some(next) = m.get(first) {
                collect(next, rest, false, f);
            }
        }
        _ => {}
    }
}

// ---------------------------------------------------------------------------------------------
// Typed records.

/// A record with the input file it came from (runs over several files name it).
#[derive(Debug, Clone, Copy)]
pub struct InFile<'a, 'r> {
    /// The input's name, when records name it.
    pub file: Option<&'a str>,
    /// The record.
    pub rec: &'a Record<'r>,
}

impl Fields for InFile<'_, '_> {
    fn proto(&self) -> Option<&str> {
        self.rec.proto()
    }
    fn visit(&self, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool {
        if key == Key::File {
            return match self.file {
                Some(name) => {
                    scalar(rest, Val::Str(Cow::Borrowed(name)), f);
                    true
                }
                None => false,
            };
        }
        self.rec.visit(key, rest, f)
    }
}

/// `v` when the path ends here (a scalar has nothing below it).
fn scalar(rest: &[String], v: Val<'_>, f: &mut dyn FnMut(Val<'_>, Role)) {
    if rest.is_empty() {
        f(v, Role::Plain);
    }
}

fn str_val(s: &str) -> Val<'_> {
    Val::Str(Cow::Borrowed(s))
}

fn num(x: impl Into<i128>) -> Val<'static> {
    Val::Num(Num::I(x.into()))
}

/// A float as NDJSON carries it: non-finite ones are `null`, no value.
fn float(x: f64) -> Option<Val<'static>> {
    x.is_finite().then_some(Val::Num(Num::F(x)))
}

fn hex(b: &[u8]) -> Val<'static> {
    let mut s = String::with_capacity(b.len() * 2);
    crate::shape::hex_digits(&mut s, b);
    Val::Str(Cow::Owned(s))
}

/// A member object given as `(name, value)` pairs: the path below it, or itself.
fn object<'v>(
    rest: &[String],
    members: &[(&str, Option<Val<'v>>)],
    role: Role,
    f: &mut dyn FnMut(Val<'_>, Role),
) {
    match rest.split_first() {
        None => {
            let pick = |keys: [&str; 3], want_num: bool| {
                keys.iter().find_map(|k| {
                    members
                        .iter()
                        .find(|(n, _)| n == k)
                        .and_then(|(_, v)| match (v, want_num) {
                            (Some(Val::Num(n)), true) => Some(Val::Num(*n)),
                            (Some(Val::Str(s)), false) => Some(Val::Str(s.clone())),
                            _ => None,
                        })
                })
            };
            let num = match pick(["addr", "id", "value"], true) {
                Some(Val::Num(n)) => Some(n),
                _ => None,
            };
            let text = match pick(["name", "model", "kind"], false) {
                Some(Val::Str(s)) => Some(s),
                _ => None,
            };
            f(
                Val::Obj(Obj {
                    num,
                    text,
                    nonempty: !members.is_empty(),
                }),
                role,
            );
        }
        Some((first, below)) => {
            if below.is_empty() {
                if let Some((_, Some(v))) = members.iter().find(|(n, _)| n == first) {
                    f(v.clone(), Role::Plain);
                }
            }
        }
    }
}

fn addr_members(a: crate::apt::Addr) -> [(&'static str, Option<Val<'static>>); 3] {
    use crate::apt::Addr;
    const BAYS: [&str; 10] = [
        "bay0", "bay1", "bay2", "bay3", "bay4", "bay5", "bay6", "bay7", "bay8", "bay9",
    ];
    let name: Cow<'static, str> = match a {
        Addr::Host => "host".into(),
        Addr::Rack => "rack".into(),
        Addr::Usb => "usb".into(),
        Addr::Bay(n) => BAYS
            .get(n as usize)
            .map_or_else(|| Cow::Owned(format!("bay{n}")), |s| Cow::Borrowed(*s)),
        Addr::Unknown(x) => Cow::Owned(format!("0x{x:02X}")),
    };
    [
        ("addr", Some(num(a.byte()))),
        ("name", Some(Val::Str(name))),
        ("bay", a.bay().map(num)),
    ]
}

fn diag_list(rest: &[String], ds: impl Iterator<Item = Diag>, f: &mut dyn FnMut(Val<'_>, Role)) {
    for d in ds {
        let members = [
            ("kind", Some(str_val(d.kind.name()))),
            ("offset", Some(num(d.offset))),
            (
                "msg",
                rest.first()
                    .filter(|s| *s == "msg")
                    .map(|_| Val::Str(Cow::Owned(d.kind.to_string()))),
            ),
        ];
        // Elements of the list itself are members; what is below them is not.
        object(rest, &members, Role::Member, f);
    }
}

impl Record<'_> {
    /// The record's protocol code, if it has one.
    pub fn proto(&self) -> Option<&'static str> {
        match self {
            Record::Apt(_) => Some("apt"),
            Record::Ell(_) => Some("ell"),
            Record::Garbage(g) => Some(g.proto.code()),
            Record::NoReply(e) => Some(e.proto.code()),
            Record::Detect { proto, .. } => Some(proto.code()),
            _ => None,
        }
    }
}

impl Fields for Record<'_> {
    fn proto(&self) -> Option<&str> {
        Record::proto(self)
    }

    // What `visit` gives as one plain number or word for the commonest keys of frames and
    // garbage (statistics and filters read them for every record).
    fn number(&self, key: Key) -> Option<i64> {
        match self {
            Record::Apt(a) => shape::number(a, key),
            Record::Ell(e) => shape::number(e, key),
            Record::Garbage(g) => shape::number(g, key),
            _ => None,
        }
    }

    fn word(&self, key: Key) -> Option<&'static str> {
        match self {
            Record::Apt(a) => shape::word(a, key),
            Record::Ell(e) => shape::word(e, key),
            Record::Garbage(g) => shape::word(g, key),
            _ => None,
        }
    }

    fn visit(&self, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool {
        match self {
            Record::Apt(a) => apt_visit(a, key, rest, f),
            Record::Ell(e) => ell_visit(e, key, rest, f),
            _ => other_visit(self, key, rest, f),
        }
    }
}

/// [`Fields::visit`] of the records that are not frames. Out of line: it keeps the frames'
/// path, which statistics and filters take for every record, small enough to be inlined.
#[inline(never)]
fn other_visit(
    rec: &Record<'_>,
    key: Key,
    rest: &[String],
    f: &mut dyn FnMut(Val<'_>, Role),
) -> bool {
    match rec {
        Record::Apt(_) | Record::Ell(_) => {
            unreachable!("frames are visited by apt_visit and ell_visit")
        }
        Record::Garbage(g) => {
            let m = &g.meta;
            let v = match key {
                Key::N => num(m.n),
                Key::Proto => str_val(g.proto.code()),
                Key::Type => str_val("garbage"),
                Key::Offset => num(g.offset),
                Key::CapOffset => num(m.cap_offset),
                Key::Len => num(g.bytes.len() as u64),
                Key::Raw => hex(g.bytes),
                Key::Text if g.kind.is_none() => Val::Str(String::from_utf8_lossy(g.bytes)),
                Key::Diag => {
                    let d = match g.kind {
                        Some(kind) => crate::shape::garbage_diag(g.offset, g.bytes.len(), kind),
                        None => Diag {
                            offset: g.offset,
                            kind: crate::DiagKind::Garbage {
                                len: g.bytes.len() as u32,
                            },
                        },
                    };
                    diag_list(rest, std::iter::once(d), f);
                    return true;
                }
                // Elliptec garbage has no direction (the bus tells none).
                Key::Dir if g.kind.is_some() => {
                    str_val(m.cap_dir.map_or("unknown", |d| d.as_str()))
                }
                Key::TsNs => match m.ts_ns {
                    Some(t) => num(t),
                    None => return false,
                },
                Key::Stream => num(m.stream),
                _ => return false,
            };
            scalar(rest, v, f);
            true
        }
        Record::NoReply(e) => {
            let v = match key {
                Key::Proto => str_val(e.proto.code()),
                Key::Type => str_val("diag"),
                Key::Ref => num(e.n),
                Key::Stream => num(e.stream),
                Key::Diag => {
                    diag_list(rest, std::iter::once(e.diag()), f);
                    return true;
                }
                _ => return false,
            };
            scalar(rest, v, f);
            true
        }
        Record::Detect {
            proto, detection, ..
        } => {
            let v = match key {
                Key::Type => str_val("detect"),
                Key::Proto => str_val(proto.code()),
                _ => return false,
            };
            let _ = detection;
            scalar(rest, v, f);
            true
        }
        Record::Stream { id, name, .. } => {
            let v = match key {
                Key::Type => str_val("stream"),
                Key::Stream => num(*id),
                Key::StreamName => str_val(name),
                _ => return false,
            };
            scalar(rest, v, f);
            true
        }
        Record::Input(d) => match key {
            Key::Type => {
                scalar(rest, str_val("input"), f);
                true
            }
            Key::Diag => {
                diag_list(rest, std::iter::once(*d), f);
                true
            }
            _ => false,
        },
        Record::FileDiag { offset, kind, msg } => match key {
            Key::Type => {
                scalar(rest, str_val("input"), f);
                true
            }
            Key::Diag => {
                let members = [
                    ("kind", Some(str_val(kind))),
                    ("offset", Some(num(*offset))),
                    ("msg", Some(str_val(msg))),
                ];
                object(rest, &members, Role::Member, f);
                true
            }
            _ => false,
        },
        Record::Units(nt) => match key {
            Key::Type => {
                scalar(rest, str_val("units"), f);
                true
            }
            Key::Stream => {
                scalar(rest, num(nt.stream), f);
                true
            }
            Key::Raw => {
                use crate::units::Resolution;
                let why = match &nt.resolution {
                    Resolution::Scale(_) => return false,
                    Resolution::Raw(why) => Cow::Borrowed(why.as_ref()),
                    Resolution::None => Cow::Borrowed("no stage"),
                };
                scalar(rest, Val::Str(why), f);
                true
            }
            _ => false,
        },
    }
}

/// The [`Head`] values APT and Elliptec frames give alike, from their context and bytes.
macro_rules! frame_head {
    () => {
        fn n(&self) -> u64 {
            self.meta.n
        }
        fn kind(&self) -> &'static str {
            "frame"
        }
        fn offset(&self) -> u64 {
            self.frame.offset
        }
        fn cap_offset(&self) -> u64 {
            self.meta.cap_offset
        }
        fn len_bytes(&self) -> u64 {
            self.frame.bytes.len() as u64
        }
        fn stream(&self) -> u32 {
            self.meta.stream
        }
        fn ts_ns(&self) -> Option<u64> {
            self.meta.ts_ns
        }
    };
}

impl Head for AptRec<'_> {
    frame_head!();
    fn pair(&self) -> Option<u64> {
        self.pair.pair
    }
    fn msgid(&self) -> Option<u16> {
        Some(self.frame.header().msg_id())
    }
    fn channel(&self) -> Option<i64> {
        self.frame.channel()
    }
    fn dir(&self) -> Option<&'static str> {
        Some(AptRec::dir(self).map_or("unknown", |d| d.as_str()))
    }
    fn name(&self) -> Option<&'static str> {
        self.frame.msg.map(|m| m.name)
    }
}

impl Head for EllRec<'_> {
    frame_head!();
    fn pair(&self) -> Option<u64> {
        self.obs.pair
    }
}

impl Head for GarbageRec<'_> {
    fn n(&self) -> u64 {
        self.meta.n
    }
    fn kind(&self) -> &'static str {
        "garbage"
    }
    fn offset(&self) -> u64 {
        self.offset
    }
    fn cap_offset(&self) -> u64 {
        self.meta.cap_offset
    }
    fn len_bytes(&self) -> u64 {
        self.bytes.len() as u64
    }
    fn stream(&self) -> u32 {
        self.meta.stream
    }
    fn ts_ns(&self) -> Option<u64> {
        self.meta.ts_ns
    }
}

/// The value of an APT field as NDJSON gives it: enum label, flag names (a list), number,
/// text, hex.
fn apt_value<'v>(
    fr: &AptFrame<'v, 'static>,
    fd: &crate::table::Field,
    v: &AptValue<'v>,
    rest: &[String],
    f: &mut dyn FnMut(Val<'_>, Role),
) {
    let t = fr.table();
    match v {
        AptValue::U(x) => {
            if let Some(l) = fd.enumeration.and_then(|e| t.enum_def(e).label(*x as i64)) {
                return scalar(rest, str_val(l), f);
            }
            if let Some(fl) = fd.flags {
                if rest.is_empty() {
                    for (_, l) in t.flags_def(fl).set(*x) {
                        f(str_val(l), Role::Member);
                    }
                }
                return;
            }
            scalar(rest, num(*x), f)
        }
        AptValue::I(x) => match fd.enumeration.and_then(|e| t.enum_def(e).label(*x)) {
            Some(l) => scalar(rest, str_val(l), f),
            None => scalar(rest, num(*x), f),
        },
        AptValue::F(x) => {
            if let Some(v) = float(*x) {
                scalar(rest, v, f)
            }
        }
        AptValue::Str(b) => scalar(rest, Val::Str(text_of(b)), f),
        AptValue::Bytes(b) => scalar(rest, hex(b), f),
        AptValue::Array(..) => {
            if rest.is_empty() {
                for e in v.elements() {
                    let x = match e {
                        AptValue::U(x) => Some(num(x)),
                        AptValue::I(x) => Some(num(x)),
                        AptValue::F(x) => float(x),
                        _ => None,
                    };
                    if let Some(x) = x {
                        f(x, Role::Member);
                    }
                }
            }
        }
    }
}

fn apt_visit(a: &AptRec<'_>, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool {
    let fr = a.frame;
    let h = fr.header();
    let common = Common {
        meta: &a.meta,
        offset: fr.offset,
        bytes: fr.bytes,
        pair: a.pair.pair,
        latency_ns: a.pair.latency_ns,
    };
    if let Some(found) = frame_key(
        &common,
        || crate::shape::apt_diags(fr, a.pair),
        || {
            fr.fields()
                .filter_map(|(fd, v)| Some((fd.name, crate::apt::phys_or_scaled(fd, &v, a.scale)?)))
        },
        || {
            fr.fields()
                .filter_map(|(fd, v)| Some((fd.name, apt_code(fd, &v)?)))
        },
        key,
        rest,
        f,
    ) {
        return found;
    }
    let v = match key {
        Key::Proto => str_val("apt"),
        Key::Msgid => num(h.msg_id()),
        Key::MsgidHex => Val::Str(Cow::Owned(format!("0x{:04X}", h.msg_id()))),
        Key::Name => match fr.msg {
            Some(d) => str_val(d.name),
            None => return true,
        },
        Key::MsgDir => match fr.msg {
            Some(d) => str_val(d.dir.as_str()),
            None => return false,
        },
        Key::Src | Key::Dst => {
            let ad = if key == Key::Src { h.src() } else { h.dst() };
            let members = addr_members(ad);
            let n = if members[2].1.is_some() { 3 } else { 2 };
            object(rest, &members[..n], Role::Plain, f);
            return true;
        }
        Key::DataFlag => Val::Bool(h.has_data()),
        Key::DataLen => num(fr.data_len() as u64),
        Key::FormNote => match fr.form.filter(|x| !x.note.is_empty()) {
            Some(x) => str_val(x.note),
            None => return false,
        },
        Key::Channel => match fr.channel() {
            Some(c) => num(c),
            None => return false,
        },
        Key::Sub => match fr.sub {
            Some(s) => {
                let members = [("id", Some(num(s.id))), ("name", Some(str_val(s.name)))];
                object(rest, &members, Role::Plain, f);
                return true;
            }
            None => return false,
        },
        Key::Fields => {
            match rest.split_first() {
                None => {
                    let members: Vec<(&str, Option<Val<'_>>)> = fr
                        .fields()
                        .map(|(fd, v)| {
                            let mut one = None;
                            apt_value(fr, fd, &v, &[], &mut |x, r| {
                                if r == Role::Plain && one.is_none() {
                                    one = Some(own(x));
                                }
                            });
                            (fd.name, one)
                        })
                        .collect();
                    object(&[], &members, Role::Plain, f);
                }
                Some((name, below)) => {
                    if let Some((fd, v)) = fr.field(name) {
                        apt_value(fr, fd, &v, below, f);
                        if below.is_empty() {
                            if let Some(c) = apt_code(fd, &v) {
                                f(Val::Num(Num::I(c)), Role::Code);
                            }
                        }
                    }
                }
            }
            return true;
        }
        Key::PairOtherAddress if a.pair.other_address => Val::Bool(true),
        Key::Dir => str_val(a.dir().map_or("unknown", |d| d.as_str())),
        _ => return false,
    };
    scalar(rest, v, f);
    true
}

/// An owned copy of a value (for objects built from computed members).
fn own(v: Val<'_>) -> Val<'static> {
    match v {
        Val::Num(n) => Val::Num(n),
        Val::Bool(b) => Val::Bool(b),
        Val::Str(s) => Val::Str(Cow::Owned(s.into_owned())),
        Val::Obj(o) => Val::Obj(Obj {
            num: o.num,
            text: o.text.map(|t| Cow::Owned(t.into_owned())),
            nonempty: o.nonempty,
        }),
    }
}

/// The value of an Elliptec field, or of a key NDJSON derives beside it
/// ([`crate::shape::ell_derived`]), by name.
fn ell_field(
    fr: &crate::ell::EllFrame<'_>,
    name: &str,
    rest: &[String],
    f: &mut dyn FnMut(Val<'_>, Role),
) {
    // The last key of that name wins, as in a JSON object with a repeated key.
    let mut last: Option<(&crate::ell::table::Field, EllValue<'_>, Option<&EllDerived>)> = None;
    for (fd, v) in fr.fields() {
        if fd.name == name {
            last = Some((fd, v, None));
        } else if let Some(d) = ell_derived(fd.kind)
            .iter()
            .find(|d| d.name.is(name, fd.name) && (d.value)(&v).is_some())
        {
            last = Some((fd, v, Some(d)));
        }
    }
    let Some((fd, v, derived)) = last else { return };
    let Some(d) = derived else {
        let x = match (fd.kind, v) {
            (EllKind::Status, EllValue::U(c)) => str_val(crate::ell::table::status_name(c as u32)),
            (_, EllValue::U(x)) => num(x),
            (_, EllValue::I(x)) => num(x),
            (_, EllValue::Char(c)) => Val::Str(Cow::Owned(c.to_string())),
            (_, EllValue::Digits(d)) => Val::Str(Cow::Owned(d.to_string())),
            (_, EllValue::Raw(b)) => hex(b),
        };
        scalar(rest, x, f);
        if rest.is_empty() {
            if let Some(c) = ell_code(fd, &v) {
                f(num(c), Role::Code);
            }
        }
        return;
    };
    match (d.value)(&v) {
        Some(DerivedVal::Curve(b)) => {
            for p in crate::ell::curve_points(b) {
                let members = curve_members(&p).map(|(n, x)| {
                    let x = match x {
                        CurveNum::U(u) => Some(num(u)),
                        CurveNum::F(x) => float(x),
                    };
                    (n, x)
                });
                object(rest, &members, Role::Member, f);
            }
        }
        Some(DerivedVal::Word(w)) => scalar(rest, str_val(w), f),
        Some(DerivedVal::Uint(x)) => scalar(rest, num(x), f),
        Some(x) => scalar(rest, Val::Str(Cow::Owned(x.to_string())), f),
        None => {}
    }
}

fn ell_visit(e: &EllRec<'_>, key: Key, rest: &[String], f: &mut dyn FnMut(Val<'_>, Role)) -> bool {
    let fr = e.frame;
    let scale = e.obs.module.as_ref().and_then(|m| m.scale());
    let common = Common {
        meta: &e.meta,
        offset: fr.offset,
        bytes: fr.bytes,
        pair: e.obs.pair,
        latency_ns: e.obs.latency_ns,
    };
    if let Some(found) = frame_key(
        &common,
        || fr.diags().iter().copied(),
        || {
            fr.fields()
                .filter_map(move |(fd, v)| Some((fd.name, crate::shape::ell_phys(fd, &v, scale)?)))
        },
        || {
            fr.fields()
                .filter_map(|(fd, v)| Some((fd.name, i128::from(ell_code(fd, &v)?))))
        },
        key,
        rest,
        f,
    ) {
        return found;
    }
    let v = match key {
        Key::Proto => str_val("ell"),
        Key::Text => Val::Str(String::from_utf8_lossy(fr.bytes)),
        Key::Addr => Val::Str(Cow::Owned(fr.addr_char().to_string())),
        Key::Dir => str_val(fr.dir().as_str()),
        Key::Cmd => str_val(fr.code_str()),
        Key::Name => match fr.cmd {
            Some(c) => str_val(c.name),
            None => return true,
        },
        Key::Fields => {
            match rest.split_first() {
                None => {
                    let nonempty = fr.fields().next().is_some();
                    // An object compares through `addr`/`id`/`value` or `name`/`model`/`kind`
                    // members: no Elliptec field has those names.
                    f(
                        Val::Obj(Obj {
                            num: None,
                            text: None,
                            nonempty,
                        }),
                        Role::Plain,
                    );
                }
                Some((name, below)) => ell_field(fr, name, below, f),
            }
            return true;
        }
        Key::Module => match &e.obs.module {
            Some(md) => {
                let members = [
                    ("first_addr", Some(num(md.first_addr))),
                    (
                        "model",
                        md.model.map(|x| {
                            Val::Str(Cow::Owned(DerivedVal::Model(u64::from(x)).to_string()))
                        }),
                    ),
                    ("serial", md.serial.as_deref().map(str_val)),
                ];
                let members: Vec<_> = members.into_iter().filter(|(_, v)| v.is_some()).collect();
                object(rest, &members, Role::Plain, f);
                return true;
            }
            None => return false,
        },
        Key::Interim if e.obs.interim => Val::Bool(true),
        _ => return false,
    };
    scalar(rest, v, f);
    true
}

/// What APT and Elliptec frames give alike.
struct Common<'a> {
    meta: &'a crate::record::Meta,
    offset: u64,
    bytes: &'a [u8],
    pair: Option<u64>,
    latency_ns: Option<u64>,
}

/// The keys APT and Elliptec frames give the same way — number, offsets, bytes, pairing,
/// diagnostics, `phys`, `codes`, time, stream — from what they have in common and their
/// diagnostics, converted values and codes (`(field name, …)`; the last of a name counts, as
/// in a JSON object). `None` for the keys each protocol gives its own way.
fn frame_key<'u, D, P, C>(
    c: &Common<'_>,
    diags: impl FnOnce() -> D,
    phys: impl Fn() -> P,
    codes: impl Fn() -> C,
    key: Key,
    rest: &[String],
    f: &mut dyn FnMut(Val<'_>, Role),
) -> Option<bool>
where
    D: Iterator<Item = Diag>,
    P: Iterator<Item = (&'static str, (f64, &'u str))>,
    C: Iterator<Item = (&'static str, i128)>,
{
    let m = c.meta;
    let v = match key {
        Key::N => num(m.n),
        Key::Type => str_val("frame"),
        Key::Offset => num(c.offset),
        Key::CapOffset => num(m.cap_offset),
        Key::Len => num(c.bytes.len() as u64),
        Key::Raw => hex(c.bytes),
        Key::Pair => match c.pair {
            Some(p) => num(p),
            None => return Some(false),
        },
        Key::LatencyMs => match c.latency_ns {
            Some(l) => match float(l as f64 / 1e6) {
                Some(v) => v,
                None => return Some(true),
            },
            None => return Some(false),
        },
        Key::Diag => {
            diag_list(rest, diags(), f);
            return Some(true);
        }
        Key::Phys => {
            if phys().next().is_none() {
                return Some(false);
            }
            match rest.split_first() {
                None => f(
                    Val::Obj(Obj {
                        num: None,
                        text: None,
                        nonempty: true,
                    }),
                    Role::Plain,
                ),
                Some((name, below)) => {
                    if let Some((_, (x, unit))) = phys().filter(|(n, _)| n == name).last() {
                        let members = [("value", float(x)), ("unit", Some(str_val(unit)))];
                        object(below, &members, Role::Plain, f);
                    }
                }
            }
            return Some(true);
        }
        Key::Codes => {
            if codes().next().is_none() {
                return Some(false);
            }
            match rest.split_first() {
                None => {
                    let members: Vec<(&str, Option<Val<'_>>)> = codes()
                        .map(|(n, x)| (n, Some(Val::Num(Num::I(x)))))
                        .collect();
                    object(&[], &members, Role::Plain, f);
                }
                Some((name, below)) => {
                    if let Some((_, x)) = codes().filter(|(n, _)| n == name).last() {
                        scalar(below, Val::Num(Num::I(x)), f);
                    }
                }
            }
            return Some(true);
        }
        Key::TsNs => match m.ts_ns {
            Some(t) => num(t),
            None => return Some(false),
        },
        Key::Stream => num(m.stream),
        _ => return None,
    };
    scalar(rest, v, f);
    Some(true)
}
