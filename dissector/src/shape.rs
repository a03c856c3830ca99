//! The record's shape, described once: the keys of each record kind as NDJSON names them
//! ([`KEYS`], with the filter's aliases and where each is valid) and what each holds
//! ([`Key::ty`]: the filter checks its literals against it), the record-level values a
//! holder of a record has at hand ([`Head`], answered by [`number`] and [`word`]), the keys
//! NDJSON derives beside an Elliptec field ([`ell_derived`]: their names and values), and the
//! rules that make a value of a record (`codes`, `phys` of Elliptec positions, the diagnostics
//! of a frame or garbage run, raw bytes as hex).
//!
//! The NDJSON writer ([`crate::json`]), the field access of filters and statistics
//! ([`crate::fields`]), the filter's name check and suggestions ([`crate::filter`]) and the
//! terminal UI's compact records read this module (the replay's decoded view reads the
//! writer); it reads none of them.

use crate::apt::{AptFrame, GarbageKind, Value as AptValue};
use crate::diag::{Diag, DiagKind};
use crate::ell::table::Kind as EllKind;
use crate::ell::{CurvePoint, EllValue};
use crate::pair::PairInfo;
use std::fmt;

/// The top-level keys of records, as filters and statistics name them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[allow(missing_docs)]
pub enum Key {
    File,
    N,
    Proto,
    Type,
    Offset,
    CapOffset,
    Len,
    Raw,
    Msgid,
    MsgidHex,
    Name,
    MsgDir,
    Src,
    Dst,
    DataFlag,
    DataLen,
    FormNote,
    Channel,
    Sub,
    Fields,
    Phys,
    Codes,
    Pair,
    LatencyMs,
    PairOtherAddress,
    Interim,
    Diag,
    Dir,
    TsNs,
    Stream,
    StreamName,
    Ref,
    Unpaired,
    Paired,
    Text,
    Addr,
    Cmd,
    Module,
}

/// Usable without a protocol prefix.
pub const TOP: u8 = 1;
/// A key of APT records (`apt.` prefix).
pub const APT: u8 = 2;
/// A key of Elliptec records (`ell.` prefix).
pub const ELL: u8 = 4;

/// One name a filter may use: the key it reads and where it is valid.
#[derive(Clone, Copy, Debug)]
pub struct KeyDef {
    /// The name as written in a filter (an NDJSON key, or an alias of one).
    pub name: &'static str,
    /// The key read.
    pub key: Key,
    /// [`TOP`], [`APT`], [`ELL`] bits.
    pub scope: u8,
}

/// Whether `name` is one of [`KEYS`]: the NDJSON writer checks every key of a decoded record
/// it writes against this list at compile time.
pub const fn is_key(name: &str) -> bool {
    let mut i = 0;
    while i < KEYS.len() {
        if str_eq(KEYS[i].name, name) {
            return true;
        }
        i += 1;
    }
    false
}

const fn str_eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

const fn k(name: &'static str, key: Key, scope: u8) -> KeyDef {
    KeyDef { name, key, scope }
}

/// Every name of the filter language: NDJSON keys and the aliases `chan` (`channel`), `ts`
/// (`ts_ns`, in seconds), `latency` (`latency_ms`). The one list the name check, the
/// suggestions and the accessors share.
pub const KEYS: &[KeyDef] = &[
    k("file", Key::File, TOP),
    k("n", Key::N, TOP | APT | ELL),
    k("proto", Key::Proto, TOP | APT | ELL),
    k("type", Key::Type, TOP | APT | ELL),
    k("offset", Key::Offset, TOP | APT | ELL),
    k("cap_offset", Key::CapOffset, TOP | APT | ELL),
    k("len", Key::Len, TOP | APT | ELL),
    k("raw", Key::Raw, TOP | APT | ELL),
    k("msgid", Key::Msgid, APT),
    k("msgid_hex", Key::MsgidHex, APT),
    k("name", Key::Name, APT | ELL),
    k("msg_dir", Key::MsgDir, APT),
    k("src", Key::Src, APT),
    k("dst", Key::Dst, APT),
    k("data_flag", Key::DataFlag, APT),
    k("data_len", Key::DataLen, APT),
    k("form_note", Key::FormNote, APT),
    k("channel", Key::Channel, APT),
    k("chan", Key::Channel, APT),
    k("sub", Key::Sub, APT),
    k("text", Key::Text, ELL),
    k("addr", Key::Addr, ELL),
    k("cmd", Key::Cmd, ELL),
    k("fields", Key::Fields, APT | ELL),
    k("phys", Key::Phys, APT | ELL),
    k("codes", Key::Codes, APT | ELL),
    k("module", Key::Module, ELL),
    k("pair", Key::Pair, TOP | APT | ELL),
    k("latency", Key::LatencyMs, TOP | APT | ELL),
    k("latency_ms", Key::LatencyMs, TOP | APT | ELL),
    k("pair_other_address", Key::PairOtherAddress, APT),
    k("interim", Key::Interim, TOP | ELL),
    k("diag", Key::Diag, TOP | APT | ELL),
    k("dir", Key::Dir, TOP | APT | ELL),
    k("ts", Key::TsNs, TOP | APT | ELL),
    k("ts_ns", Key::TsNs, TOP | APT | ELL),
    k("stream", Key::Stream, TOP | APT | ELL),
    // Read by statistics, not offered to filters (it would be suggested for `name`).
    k("stream_name", Key::StreamName, 0),
    k("ref", Key::Ref, TOP | APT | ELL),
    k("unpaired", Key::Unpaired, TOP | APT | ELL),
    k("paired", Key::Paired, TOP | APT | ELL),
];

/// What a key's value is, in NDJSON and to filters: what comparisons mean on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ty {
    /// A non-negative integer.
    UInt,
    /// An integer.
    Int,
    /// A number with a fraction.
    Float,
    /// `true` or `false`.
    Bool,
    /// One of a few words (`h2d`, `frame`, a message name).
    Word,
    /// Free text (a file name, an Elliptec frame's text, its address character).
    Text,
    /// Bytes, written as hex text.
    Hex,
    /// An APT address: `{"addr", "name", "bay"}`; filters compare its number, or its name.
    Address,
    /// An object of named values (`fields`, `phys`, `codes`, `sub`, `module`).
    Object,
    /// A list (`diag`).
    List,
}

impl Ty {
    /// Whether the value is a number (no text ever equals it).
    pub fn is_number(self) -> bool {
        matches!(self, Ty::UInt | Ty::Int | Ty::Float)
    }

    /// Whether `<`, `>` … mean something on the value (text and words in byte order, as
    /// Wireshark orders strings).
    pub fn is_ordered(self) -> bool {
        !matches!(self, Ty::Bool | Ty::Object | Ty::List)
    }

    /// How a user is told what the value is.
    pub fn describe(self) -> &'static str {
        match self {
            Ty::UInt | Ty::Int | Ty::Float => "a number",
            Ty::Bool => "true or false",
            Ty::Word => "a word",
            Ty::Text => "text",
            Ty::Hex => "bytes (hex)",
            Ty::Address => "an address",
            Ty::Object => "a set of named values",
            Ty::List => "a list",
        }
    }
}

impl Key {
    /// What the key's value is (at the record's top level; below it, what the path names).
    pub const fn ty(self) -> Ty {
        match self {
            Key::N
            | Key::Offset
            | Key::CapOffset
            | Key::Len
            | Key::Msgid
            | Key::DataLen
            | Key::Pair
            | Key::TsNs
            | Key::Stream
            | Key::Ref => Ty::UInt,
            Key::Channel => Ty::Int,
            Key::LatencyMs => Ty::Float,
            Key::DataFlag | Key::PairOtherAddress | Key::Interim | Key::Unpaired | Key::Paired => {
                Ty::Bool
            }
            Key::Proto | Key::Type | Key::Name | Key::MsgDir | Key::Dir | Key::Cmd => Ty::Word,
            Key::File | Key::MsgidHex | Key::FormNote | Key::StreamName | Key::Text | Key::Addr => {
                Ty::Text
            }
            Key::Raw => Ty::Hex,
            Key::Src | Key::Dst => Ty::Address,
            Key::Fields | Key::Phys | Key::Codes | Key::Sub | Key::Module => Ty::Object,
            Key::Diag => Ty::List,
        }
    }

    /// The key's NDJSON name.
    pub fn json_name(self) -> &'static str {
        match self {
            Key::Channel => "channel",
            Key::LatencyMs => "latency_ms",
            Key::TsNs => "ts_ns",
            other => KEYS.iter().find(|d| d.key == other).map_or("", |d| d.name),
        }
    }

    /// The definition of a filter name valid in `scope`.
    pub fn lookup(name: &str, scope: u8) -> Option<&'static KeyDef> {
        KEYS.iter().find(|d| d.name == name && d.scope & scope != 0)
    }
}

// ---------------------------------------------------------------------------------------------
// Record-level values at hand.

/// The record-level values of a frame or garbage record, as a holder of it keeps them (a typed
/// [`crate::record::Record`], the terminal UI's compact record): what [`number`] and [`word`]
/// answer for their keys. `None`: not at hand (read the record through
/// [`crate::fields::Fields::visit`]).
pub trait Head {
    /// `n`.
    fn n(&self) -> u64;
    /// `type`: `frame` or `garbage`.
    fn kind(&self) -> &'static str;
    /// `offset`, in the record's lane.
    fn offset(&self) -> u64;
    /// `cap_offset`.
    fn cap_offset(&self) -> u64;
    /// `len`.
    fn len_bytes(&self) -> u64;
    /// `stream`.
    fn stream(&self) -> u32;
    /// `ts_ns`.
    fn ts_ns(&self) -> Option<u64>;
    /// `pair`: the request a reply answers.
    fn pair(&self) -> Option<u64> {
        None
    }
    /// `msgid` of an APT frame.
    fn msgid(&self) -> Option<u16> {
        None
    }
    /// `channel` of an APT frame.
    fn channel(&self) -> Option<i64> {
        None
    }
    /// `dir`.
    fn dir(&self) -> Option<&'static str> {
        None
    }
    /// `name` of an APT frame's message.
    fn name(&self) -> Option<&'static str> {
        None
    }
}

/// The one number at top-level `key` that `h` has at hand (see [`crate::fields::Fields::number`]).
#[inline]
pub fn number<H: Head + ?Sized>(h: &H, key: Key) -> Option<i64> {
    let x: u64 = match key {
        Key::N => h.n(),
        Key::Offset => h.offset(),
        Key::CapOffset => h.cap_offset(),
        Key::Len => h.len_bytes(),
        Key::Stream => u64::from(h.stream()),
        Key::TsNs => h.ts_ns()?,
        Key::Pair => h.pair()?,
        Key::Msgid => u64::from(h.msgid()?),
        Key::Channel => return h.channel(),
        _ => return None,
    };
    i64::try_from(x).ok()
}

/// The one word at top-level `key` that `h` has at hand (see [`crate::fields::Fields::word`]).
#[inline]
pub fn word<H: Head + ?Sized>(h: &H, key: Key) -> Option<&'static str> {
    match key {
        Key::Type => Some(h.kind()),
        Key::Dir => h.dir(),
        Key::Name => h.name(),
        _ => None,
    }
}

// ---------------------------------------------------------------------------------------------
// Keys derived beside an Elliptec field.

/// How a key derived beside an Elliptec field is named.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DerivedName {
    /// A name of its own (`thread`).
    Fixed(&'static str),
    /// The field's name with this suffix (`model` → `model_name`).
    Suffix(&'static str),
}

impl DerivedName {
    /// Is `name` this key beside the field `field`?
    pub fn is(self, name: &str, field: &str) -> bool {
        match self {
            DerivedName::Fixed(s) => name == s,
            DerivedName::Suffix(s) => name.strip_suffix(s) == Some(field),
        }
    }
}

impl fmt::Display for DerivedName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DerivedName::Fixed(s) | DerivedName::Suffix(s) => f.write_str(s),
        }
    }
}

/// The value of a derived key.
#[derive(Clone, Copy, Debug)]
pub enum DerivedVal<'a> {
    /// A word.
    Word(&'static str),
    /// A number.
    Uint(u64),
    /// An Elliptec model number as the text shows it (`ELL14`).
    Model(u64),
    /// A firmware release byte as a version (`1.7`).
    Version(u64),
    /// The binary current curve, point by point ([`curve_members`]).
    Curve(&'a [u8]),
}

impl fmt::Display for DerivedVal<'_> {
    /// The text of a word, number, model or version (a curve has none).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DerivedVal::Word(w) => f.write_str(w),
            DerivedVal::Uint(x) => write!(f, "{x}"),
            DerivedVal::Model(x) => write!(f, "ELL{x}"),
            DerivedVal::Version(x) => write!(f, "{}.{}", x >> 4, x & 15),
            DerivedVal::Curve(_) => Ok(()),
        }
    }
}

/// A key NDJSON derives beside an Elliptec field of some kind: coded numbers also as the text
/// shows them (the number stays for scripts), a byte that packs two facts as two keys, the
/// binary current curve as points.
#[derive(Clone, Copy, Debug)]
pub struct EllDerived {
    /// Its name.
    pub name: DerivedName,
    /// Its value from the field's, when the field has one of the expected type.
    pub value: for<'a> fn(&EllValue<'a>) -> Option<DerivedVal<'a>>,
}

/// The keys derived beside an Elliptec field of `kind`, in the order NDJSON writes them after
/// the field.
#[inline]
pub fn ell_derived(kind: EllKind) -> &'static [EllDerived] {
    const MODEL: &[EllDerived] = &[EllDerived {
        name: DerivedName::Suffix("_name"),
        value: model,
    }];
    const FIRMWARE: &[EllDerived] = &[EllDerived {
        name: DerivedName::Suffix("_version"),
        value: version,
    }];
    // The manual packs two facts into this byte: each gets its own key.
    const THREAD_HW: &[EllDerived] = &[
        EllDerived {
            name: DerivedName::Fixed("thread"),
            value: thread,
        },
        EllDerived {
            name: DerivedName::Fixed("hw_release"),
            value: hw_release,
        },
    ];
    const RAW: &[EllDerived] = &[EllDerived {
        name: DerivedName::Fixed("curve_points"),
        value: curve,
    }];
    match kind {
        EllKind::Model => MODEL,
        EllKind::Firmware => FIRMWARE,
        EllKind::ThreadHw => THREAD_HW,
        EllKind::Raw => RAW,
        _ => &[],
    }
}

#[inline]
fn model<'a>(v: &EllValue<'a>) -> Option<DerivedVal<'a>> {
    match *v {
        EllValue::U(x) => Some(DerivedVal::Model(x)),
        _ => None,
    }
}

#[inline]
fn version<'a>(v: &EllValue<'a>) -> Option<DerivedVal<'a>> {
    match *v {
        EllValue::U(x) => Some(DerivedVal::Version(x)),
        _ => None,
    }
}

#[inline]
fn thread<'a>(v: &EllValue<'a>) -> Option<DerivedVal<'a>> {
    match *v {
        EllValue::U(x) => Some(DerivedVal::Word(if x & 0x80 != 0 {
            "imperial"
        } else {
            "metric"
        })),
        _ => None,
    }
}

#[inline]
fn hw_release<'a>(v: &EllValue<'a>) -> Option<DerivedVal<'a>> {
    match *v {
        EllValue::U(x) => Some(DerivedVal::Uint(x & 0x7F)),
        _ => None,
    }
}

#[inline]
fn curve<'a>(v: &EllValue<'a>) -> Option<DerivedVal<'a>> {
    match *v {
        EllValue::Raw(b) => Some(DerivedVal::Curve(b)),
        _ => None,
    }
}

/// The members of one point of the current curve (`curve_points`): period and current as
/// integers, frequency (Hz, rounded) and current (A, 6 significant digits) as floats.
#[inline]
pub fn curve_members(p: &CurvePoint) -> [(&'static str, CurveNum); 4] {
    [
        ("period", CurveNum::U(u64::from(p.period))),
        ("current", CurveNum::U(u64::from(p.current))),
        ("hz", CurveNum::F(p.hz().round())),
        ("amps", CurveNum::F(crate::apt::round_sig(p.amps()))),
    ]
}

/// A member of a curve point.
#[derive(Clone, Copy, Debug)]
pub enum CurveNum {
    /// An integer.
    U(u64),
    /// A float.
    F(f64),
}

// ---------------------------------------------------------------------------------------------
// Values a record derives.

/// The numeric code of an enum or flag field (what `codes` holds).
#[inline]
pub fn apt_code(fd: &crate::table::Field, v: &AptValue<'_>) -> Option<i128> {
    if fd.enumeration.is_none() && fd.flags.is_none() {
        return None;
    }
    match v {
        AptValue::U(x) => Some(i128::from(*x)),
        AptValue::I(x) => Some(i128::from(*x)),
        _ => None,
    }
}

/// The numeric code of an Elliptec field shown by name (status codes).
#[inline]
pub fn ell_code(fd: &crate::ell::table::Field, v: &EllValue<'_>) -> Option<u64> {
    match (fd.kind, v) {
        (EllKind::Status, EllValue::U(c)) => Some(*c),
        _ => None,
    }
}

/// An Elliptec position in the module's physical unit (rounded to 6 significant digits), when
/// its pulses per unit are known: what `phys` gives beside the raw count.
#[inline]
pub fn ell_phys(
    fd: &crate::ell::table::Field,
    v: &EllValue<'_>,
    scale: Option<(f64, &'static str)>,
) -> Option<(f64, &'static str)> {
    match (fd.kind, v, scale) {
        (crate::ell::table::Kind::Position, EllValue::I(p), Some((ppu, unit))) if ppu > 0.0 => {
            Some((crate::apt::round_sig(*p as f64 / ppu), unit))
        }
        _ => None,
    }
}

/// The diagnostics of an APT frame: the decoder's, then pairing's (`unsolicited`,
/// `duplicate_reply`, `not_for_model`).
pub fn apt_diags<'x>(f: &'x AptFrame<'_, '_>, p: &'x PairInfo) -> impl Iterator<Item = Diag> + 'x {
    f.diags().chain(p.diags(f.offset))
}

/// The diagnostic of a garbage record.
pub fn garbage_diag(offset: u64, len: usize, kind: GarbageKind) -> Diag {
    Diag {
        offset,
        kind: match kind {
            GarbageKind::NoHeader => DiagKind::Garbage { len: len as u32 },
            GarbageKind::AbsurdLength { msg_id, len } => DiagKind::AbsurdLength { msg_id, len },
            GarbageKind::TrailingBytes => DiagKind::TrailingBytes { len: len as u32 },
        },
    }
}

/// Append bytes as lower-case hex digits (no quotes).
#[inline]
pub fn hex_digits(out: &mut String, b: &[u8]) {
    const H: &[u8; 16] = b"0123456789abcdef";
    // Through a stack buffer: pushing chars one by one costs a UTF-8 encode each.
    let mut buf = [0u8; 128];
    for part in b.chunks(buf.len() / 2) {
        for (i, &x) in part.iter().enumerate() {
            buf[2 * i] = H[(x >> 4) as usize];
            buf[2 * i + 1] = H[(x & 15) as usize];
        }
        out.push_str(std::str::from_utf8(&buf[..2 * part.len()]).unwrap_or_default());
    }
}
