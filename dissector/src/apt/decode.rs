//! Decoding a framed APT message against the table: message, form, sub-message, typed fields.

use super::header::{Addr, Header, HEADER_LEN, KNOWN_ADDR};
use crate::diag::{Diag, DiagKind, Which};
use crate::table::{
    DataForm, Field, FieldRead, Form, FormKind, MsgDef, Prim, ReadKind, SubDef, Table, Ty,
};

const D_TRUNCATED: u16 = 1;
const D_DST: u16 = 2;
const D_SRC: u16 = 4;
const D_UNKNOWN_ID: u16 = 8;
const D_SUB_HDR: u16 = 16;
const D_SUB_DATA: u16 = 32;
const D_LENGTH: u16 = 64;
const D_HDR_WITH_DATA: u16 = 128;
const D_NO_DATA_FLAG: u16 = 256;
const D_ZERO_ADDRS: u16 = 512;

/// A frame decoded against the table. Borrows the frame bytes and the table; no allocation.
#[derive(Debug, Clone, Copy)]
pub struct AptFrame<'a, 't> {
    /// Stream offset of the first byte.
    pub offset: u64,
    /// The bytes (at least the 6 header bytes).
    pub bytes: &'a [u8],
    /// The message definition, when the id is known.
    pub msg: Option<&'t MsgDef>,
    /// The message form that matched (for sub-messages: the msg's `sub` or `hdr` form).
    pub msg_form: Option<&'t Form>,
    /// The sub-message, for messages with sub-message ids.
    pub sub: Option<&'t SubDef>,
    /// The form whose fields apply (the sub's form for sub-message data packets).
    pub form: Option<&'t Form>,
    /// Problems found, as `D_*` bits (see [`diags`](Self::diags)); a whole word, so that
    /// copying a frame reads it as it was stored (a 16-bit store read back as part of a wider
    /// word stalls the copy).
    diag_bits: u64,
    table: &'t Table,
    /// [`channel`](Self::channel), read once (pairing, units, the index and the output all
    /// ask for it).
    chan: Option<i64>,
}

/// A field's value, read from the frame bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value<'a> {
    /// Unsigned integer.
    U(u64),
    /// Signed integer.
    I(i64),
    /// Float.
    F(f64),
    /// Text (zero-padded; the bytes up to the first NUL).
    Str(&'a [u8]),
    /// Opaque or reserved bytes.
    Bytes(&'a [u8]),
    /// An array of scalars (raw little-endian bytes).
    Array(Prim, &'a [u8]),
}

/// Read one scalar at the start of `b` (which holds at least its width).
#[inline]
pub fn read_prim(p: Prim, b: &[u8]) -> Value<'_> {
    match p {
        Prim::U8 => Value::U(b[0] as u64),
        Prim::I8 => Value::I(b[0] as i8 as i64),
        Prim::U16 => Value::U(u16::from_le_bytes([b[0], b[1]]) as u64),
        Prim::I16 => Value::I(i16::from_le_bytes([b[0], b[1]]) as i64),
        Prim::U32 => Value::U(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64),
        Prim::I32 => Value::I(i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as i64),
        Prim::F32 => Value::F(f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64),
    }
}

impl Value<'_> {
    /// The value as an integer, for integer scalars.
    pub fn as_i64(&self) -> Option<i64> {
        match *self {
            Value::U(v) => i64::try_from(v).ok(),
            Value::I(v) => Some(v),
            _ => None,
        }
    }
    /// The value as a float, for scalars.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Value::U(v) => Some(v as f64),
            Value::I(v) => Some(v as f64),
            Value::F(v) => Some(v),
            _ => None,
        }
    }
    /// Elements of an array value.
    pub fn elements(&self) -> impl Iterator<Item = Value<'_>> {
        let (p, b) = match *self {
            Value::Array(p, b) => (p, b),
            _ => (Prim::U8, &[][..]),
        };
        b.chunks_exact(p.width()).map(move |c| read_prim(p, c))
    }
}

/// The width of field `f` in a frame of `frame_len` bytes: its type's, or for the open array
/// that ends an open form (`TYPE[*]`), the whole elements left in the frame.
#[inline]
fn field_width(f: &Field, frame_len: usize) -> usize {
    match f.ty {
        Ty::Array(p, 0) => {
            let left = frame_len.saturating_sub(f.loc.frame_offset());
            left - left % p.width()
        }
        t => t.width(),
    }
}

/// The data length of a frame (its header's, or for a data packet the framer took without
/// the 0x80 flag, the length bytes read as one).
fn data_len(bytes: &[u8]) -> usize {
    match Header::new(bytes) {
        Some(h) if h.has_data() => h.data_len(),
        _ if bytes.len() > HEADER_LEN => u16::from_le_bytes([bytes[2], bytes[3]]) as usize,
        _ => 0,
    }
}

/// The sub-message id a data packet starts with.
fn data_sub_id(bytes: &[u8]) -> Option<u16> {
    bytes.get(6..8).map(|b| u16::from_le_bytes([b[0], b[1]]))
}

/// The value of an integer field `f` in the frame `bytes` (what [`field_value`] and
/// [`Value::as_i64`] give, without their general cases: every frame's channel is read so).
#[inline]
fn int_value(bytes: &[u8], f: &Field) -> Option<i64> {
    let Ty::Prim(p) = f.ty else {
        return field_value(bytes, f)?.as_i64();
    };
    let start = f.loc.frame_offset();
    read_prim(p, bytes.get(start..start + p.width())?).as_i64()
}

/// The channel of a frame of form `fm` (see [`AptFrame::channel`]). Inline code, not a closure
/// of `decode`'s: that stayed a call, its answer returned through memory.
#[inline(always)]
fn form_channel(fm: &Form, bytes: &[u8]) -> Option<i64> {
    let c = match fm.chan_u16_at() {
        // The table's every chan_ident: read without looking at the field.
        Some(at) => i64::from(u16::from_le_bytes(le_bytes(bytes, at)?)),
        None => int_value(bytes, fm.chan_field()?)?,
    };
    Some(match c {
        4 => 3,
        8 => 4,
        c => c,
    })
}

/// The value of field `f` in the frame `bytes`.
#[inline]
fn field_value<'a>(bytes: &'a [u8], f: &Field) -> Option<Value<'a>> {
    let start = f.loc.frame_offset();
    let b = bytes.get(start..start + field_width(f, bytes.len()))?;
    Some(match f.ty {
        Ty::Prim(p) => read_prim(p, b),
        Ty::Array(p, _) => Value::Array(p, b),
        Ty::Str(_) => Value::Str(b),
        Ty::Bytes(_) | Ty::Pad(_) => Value::Bytes(b),
    })
}

/// `N` bytes of `b` from `at`, as an array.
#[inline(always)]
fn le_bytes<const N: usize>(b: &[u8], at: usize) -> Option<[u8; N]> {
    b.get(at..at + N)?.try_into().ok()
}

/// The value a [`FieldRead`] reads from the frame `bytes` (what [`field_value`] gives for its
/// field, in one match); `None` when the frame is too short to hold it.
#[inline(always)]
fn read_value<'a>(r: &FieldRead, bytes: &'a [u8]) -> Option<Value<'a>> {
    let start = r.start as usize;
    let w = r.width as usize;
    Some(match r.kind {
        ReadKind::U8 => Value::U(u64::from(*bytes.get(start)?)),
        ReadKind::I8 => Value::I(i64::from(*bytes.get(start)? as i8)),
        ReadKind::U16 => Value::U(u64::from(u16::from_le_bytes(le_bytes(bytes, start)?))),
        ReadKind::I16 => Value::I(i64::from(i16::from_le_bytes(le_bytes(bytes, start)?))),
        ReadKind::U32 => Value::U(u64::from(u32::from_le_bytes(le_bytes(bytes, start)?))),
        ReadKind::I32 => Value::I(i64::from(i32::from_le_bytes(le_bytes(bytes, start)?))),
        ReadKind::F32 => Value::F(f64::from(f32::from_le_bytes(le_bytes(bytes, start)?))),
        ReadKind::Array(p) => Value::Array(p, bytes.get(start..start + w)?),
        ReadKind::Open(p) => {
            let left = bytes.len().saturating_sub(start);
            Value::Array(p, bytes.get(start..start + (left - left % w))?)
        }
        ReadKind::Str => Value::Str(bytes.get(start..start + w)?),
        ReadKind::Bytes => Value::Bytes(bytes.get(start..start + w)?),
    })
}

/// The text of a `str[N]` field: bytes up to the first NUL, lossy UTF-8.
pub fn text_of(b: &[u8]) -> std::borrow::Cow<'_, str> {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    let b = &b[..end];
    // Valid UTF-8 (the usual ASCII) borrowed after the fast check; `from_utf8_lossy` walks
    // its chunks even then.
    match std::str::from_utf8(b) {
        Ok(s) => std::borrow::Cow::Borrowed(s),
        Err(_) => String::from_utf8_lossy(b),
    }
}

impl<'a, 't> AptFrame<'a, 't> {
    /// Decode a frame (as produced by the framer: at least 6 bytes).
    // Always inlined into the caller's loop (a few dozen call sites): returned from a call,
    // the frame (12 words) was stored and copied out again, its last stores read back by
    // wider loads (a store-forwarding stall on every frame); `#[inline]` alone left it a call
    // (8 % of decode_file's CPU time, 2.2 M instructions per MB).
    #[inline(always)]
    pub fn decode(table: &'t Table, offset: u64, bytes: &'a [u8], truncated: bool) -> Option<Self> {
        // Worked out in locals and the frame built once at the end: building it field by field
        // stored its 16-bit diagnostic bits just before copying them out as part of a wider
        // word, a store-forwarding stall costing about a sixth of the decode.
        let h = Header::new(bytes)?;
        let msg = table.msg(h.msg_id());
        let mut diag_bits = 0u16;
        if truncated {
            diag_bits |= D_TRUNCATED;
        }
        let (dst, src) = (h.dst_byte(), h.src_byte());
        if dst == 0 && src == 0 {
            diag_bits |= D_ZERO_ADDRS;
        } else {
            // The framer's lookup table, not `Addr::from_byte`'s match: the same known set.
            if !KNOWN_ADDR[usize::from(dst)] {
                diag_bits |= D_DST;
            }
            if !KNOWN_ADDR[usize::from(src)] {
                diag_bits |= D_SRC;
            }
        }
        let frame = |msg_form, sub, form, diag_bits, chan| AptFrame {
            offset,
            bytes,
            msg,
            msg_form,
            sub,
            form,
            diag_bits: u64::from(diag_bits),
            table,
            chan,
        };
        let Some(m) = msg else {
            return Some(frame(None, None, None, diag_bits | D_UNKNOWN_ID, None));
        };
        // A data packet after a header without the 0x80 flag (the framer took it by length).
        let no_flag = !h.has_data() && bytes.len() > HEADER_LEN;
        if no_flag {
            diag_bits |= D_NO_DATA_FLAG;
        }
        let has_data = h.has_data() || no_flag;
        // `data_len(bytes)` without reading the header again.
        let len = if has_data {
            usize::from(u16::from_le_bytes([h.param1(), h.param2()]))
        } else {
            0
        };
        let (mut msg_form, mut sub, mut form) = (None, None, None);
        // Without a data packet: the first header-only form (found when the table was built).
        let header = m.hdr_form.and_then(|i| m.forms.get(usize::from(i)));
        if let Some(fm) = header.filter(|_| !has_data) {
            msg_form = Some(fm);
            form = Some(fm);
            if let Some(g) = m.subs {
                if let Some(p1) = fm.sub_field() {
                    sub = table.sub_of(m, g, bytes[p1.loc.frame_offset()] as u16);
                    if sub.is_none() {
                        diag_bits |= D_SUB_HDR;
                    }
                }
            }
        }
        // Most data packets: the form found when the table was built, without the walk.
        let data_form = if has_data {
            m.data_form.get(len).copied().unwrap_or(DataForm::WALK)
        } else {
            DataForm::NONE
        };
        if let Some(fm) = data_form.form().and_then(|i| m.forms.get(i)) {
            msg_form = Some(fm);
            form = Some(fm);
        }
        let walk = data_form == DataForm::WALK;
        for fm in m.forms.iter().filter(|_| walk) {
            match fm.kind {
                FormKind::Data(_) | FormKind::Open(_) if fm.accepts_len(true, len) => {
                    msg_form = Some(fm);
                    form = Some(fm);
                }
                FormKind::Sub if len >= 2 => {
                    let (Some(g), Some(id)) = (m.subs, data_sub_id(bytes)) else {
                        continue;
                    };
                    msg_form = Some(fm);
                    match table.sub_of(m, g, id) {
                        None => diag_bits |= D_SUB_DATA,
                        Some(s) => {
                            sub = Some(s);
                            form = s.forms.iter().find(|sf| sf.accepts_len(true, len));
                            if form.is_none() {
                                diag_bits |= D_LENGTH;
                            }
                        }
                    }
                }
                _ => continue,
            }
            break;
        }
        if msg_form.is_none() {
            let hdr_only = m.forms.iter().all(|x| x.kind == FormKind::Header);
            diag_bits |= if has_data && hdr_only {
                D_HDR_WITH_DATA
            } else {
                D_LENGTH
            };
        }
        let chan = match form {
            Some(fm) => form_channel(fm, bytes),
            None => None,
        };
        Some(frame(msg_form, sub, form, diag_bits, chan))
    }

    /// Whether anything is wrong with this frame.
    pub fn has_diags(&self) -> bool {
        self.diag_bits != 0
    }

    fn bits(&self) -> u16 {
        self.diag_bits as u16
    }

    /// The problems found, each with its stream offset. Derived from the frame on demand, so a
    /// clean frame costs nothing.
    pub fn diags(&self) -> impl Iterator<Item = Diag> + '_ {
        let h = self.header();
        let no_flag = self.bits() & D_NO_DATA_FLAG != 0;
        let (has_data, len) = (h.has_data() || no_flag, self.data_len() as u32);
        // A constant list: an array built here would be stored and then copied into the
        // iterator by wider loads (a store-forwarding stall), for clean frames too.
        const BITS: [u16; 10] = [
            D_TRUNCATED,
            D_DST,
            D_SRC,
            D_UNKNOWN_ID,
            D_SUB_HDR,
            D_SUB_DATA,
            D_LENGTH,
            D_HDR_WITH_DATA,
            D_NO_DATA_FLAG,
            D_ZERO_ADDRS,
        ];
        BITS.iter()
            .copied()
            .filter(move |bit| self.bits() & bit != 0)
            .map(move |bit| {
                let (at, kind) = match bit {
                    D_TRUNCATED => (
                        self.bytes.len(),
                        DiagKind::Truncated {
                            expected: HEADER_LEN as u32 + len,
                            got: self.bytes.len() as u32,
                        },
                    ),
                    D_DST => (
                        4,
                        DiagKind::UnknownAddress {
                            which: Which::Destination,
                            value: h.dst_byte(),
                        },
                    ),
                    D_SRC => (
                        5,
                        DiagKind::UnknownAddress {
                            which: Which::Source,
                            value: h.src_byte(),
                        },
                    ),
                    D_UNKNOWN_ID => (0, DiagKind::UnknownId { msg_id: h.msg_id() }),
                    D_SUB_HDR => (
                        2,
                        DiagKind::UnknownSubId {
                            sub_id: h.param1() as u16,
                        },
                    ),
                    D_SUB_DATA => (
                        6,
                        DiagKind::UnknownSubId {
                            sub_id: data_sub_id(self.bytes).unwrap_or(0),
                        },
                    ),
                    D_LENGTH => (2, DiagKind::LengthMismatch { len, has_data }),
                    D_NO_DATA_FLAG => (4, DiagKind::MissingDataFlag { len }),
                    D_ZERO_ADDRS => (4, DiagKind::ZeroAddresses),
                    _ => (4, DiagKind::HeaderOnlyWithData { len }),
                };
                Diag {
                    offset: self.offset + at as u64,
                    kind,
                }
            })
    }

    /// Length of the data packet: the header's length field, or for a packet sent without the
    /// 0x80 flag the bytes after the header (its param bytes hold the length).
    pub fn data_len(&self) -> usize {
        data_len(self.bytes)
    }

    /// The header view.
    pub fn header(&self) -> Header<'a> {
        // The constructor checked the length.
        Header::new(self.bytes).unwrap_or_else(|| unreachable!("frames hold a header"))
    }

    /// The table this frame was decoded with.
    pub fn table(&self) -> &'t Table {
        self.table
    }

    /// Message name, or `None` for an unknown id.
    pub fn name(&self) -> Option<&'static str> {
        self.msg.map(|m| m.name)
    }

    /// Source address.
    pub fn src(&self) -> Addr {
        self.header().src()
    }

    /// Destination address.
    pub fn dst(&self) -> Addr {
        self.header().dst()
    }

    /// A field's value; `None` when the frame is too short to hold it.
    pub fn value(&self, f: &Field) -> Option<Value<'a>> {
        field_value(self.bytes, f)
    }

    /// The fields of the matched form with their values (reserved `pad` fields left out).
    #[inline]
    pub fn fields(&self) -> impl Iterator<Item = (&'t Field, Value<'a>)> + '_ {
        // The form's reads (pads left out when the table was built), not its `Field`s: a
        // field's 100-odd bytes are only pointed at.
        let (fields, reads): (&'t [Field], &'t [FieldRead]) =
            self.form.map_or((&[], &[]), |f| (&f.fields, &f.reads));
        Fields {
            fields,
            reads: reads.iter(),
            bytes: self.bytes,
        }
    }

    /// A field by name (as [`AptFrame::fields`] gives it; only its value is read).
    pub fn field(&self, name: &str) -> Option<(&'t Field, Value<'a>)> {
        let fields: &'t [Field] = self.form.map_or(&[], |f| f.fields.as_slice());
        fields
            .iter()
            .filter(|f| f.name == name && !matches!(f.ty, Ty::Pad(_)))
            .find_map(|f| Some((f, field_value(self.bytes, f)?)))
    }

    /// The channel number (1-based), from the `chan_ident` field: idents 0x01, 0x02, 0x04, 0x08
    /// are channels 1–4; other values are given as they are.
    #[inline]
    pub fn channel(&self) -> Option<i64> {
        self.chan
    }

    /// Whether a field is the form's sub-id or channel (shown in their own columns).
    pub fn is_key_field(f: &Field) -> bool {
        f.name == "sub_id" || f.name == "chan_ident"
    }
}

/// The iterator of [`AptFrame::fields`]: a named type with an inline `next`, so that the
/// caller's loop reads the values in registers (a closure's body stays behind a call in this
/// crate, its value returned through memory and read back by wider loads).
struct Fields<'a, 't> {
    fields: &'t [Field],
    reads: std::slice::Iter<'t, FieldRead>,
    bytes: &'a [u8],
}

impl<'a, 't> Iterator for Fields<'a, 't> {
    type Item = (&'t Field, Value<'a>);

    #[inline]
    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let r = self.reads.next()?;
            let Some(f) = self.fields.get(usize::from(r.field)) else {
                continue;
            };
            if let Some(v) = read_value(r, self.bytes) {
                return Some((f, v));
            }
        }
    }
}

/// How a field's value reads for people: enum label, flag names, scaled value with unit.
pub fn fmt_value(table: &Table, f: &Field, v: &Value<'_>, out: &mut String) {
    fmt_value_in(table, f, v, None, out)
}

/// [`fmt_value`] with the stage's conversion: a motion value (`q=`) reads raw then physical,
/// `1932478 (2.5 mm/s)`; without a conversion it reads raw with its raw unit
/// (`1932478 vel_units`).
pub fn fmt_value_in(
    table: &Table,
    f: &Field,
    v: &Value<'_>,
    scale: Option<&crate::units::Scale>,
    out: &mut String,
) {
    use std::fmt::Write;
    if let Some(p) = phys(f, v, scale) {
        fmt_scalar(v, out);
        let _ = write!(out, " ({} {})", round_sig(p.0), p.1);
        return;
    }
    match v {
        Value::Str(b) => {
            let _ = write!(out, "{:?}", text_of(b));
        }
        Value::Bytes(b) | Value::Array(_, b) if b.is_empty() => out.push_str("[]"),
        Value::Bytes(b) => {
            for x in b.iter() {
                let _ = write!(out, "{x:02x}");
            }
        }
        Value::Array(..) => {
            out.push('[');
            for (i, e) in v.elements().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                fmt_scalar(&e, out);
            }
            out.push(']');
        }
        _ => {
            let raw = v.as_i64();
            if let (Some(e), Some(r)) = (f.enumeration, raw) {
                let def = table.enum_def(e);
                match def.label(r) {
                    // The number beside the name: what the manual and the device give.
                    Some(l) => {
                        let _ = write!(out, "{l} ({r})");
                    }
                    None => {
                        let _ = write!(out, "{r}(not in enum {})", def.name);
                    }
                }
                return;
            }
            if let (Some(fl), Some(r)) = (f.flags, raw) {
                let defs = table.flags_def(fl);
                let mut first = true;
                let mut rest = r as u64;
                for (m, l) in defs.set(r as u64) {
                    if !first {
                        out.push('|');
                    }
                    out.push_str(l);
                    first = false;
                    rest &= !m;
                }
                if rest != 0 {
                    if !first {
                        out.push('|');
                    }
                    let _ = write!(out, "0x{rest:X}");
                } else if first {
                    out.push('0');
                }
                if !first {
                    // The whole word beside the names.
                    let _ = write!(out, " (0x{:X})", r as u64);
                }
                return;
            }
            match (f.scale, v.as_f64()) {
                (Some(s), Some(x)) => {
                    let _ = write!(out, "{}", round_sig(x * s));
                }
                _ => fmt_scalar(v, out),
            }
            if let Some(u) = f.unit {
                out.push(' ');
                out.push_str(u);
            }
        }
    }
}

fn fmt_scalar(v: &Value<'_>, out: &mut String) {
    use std::fmt::Write;
    let _ = match v {
        Value::U(x) => write!(out, "{x}"),
        Value::I(x) => write!(out, "{x}"),
        Value::F(x) => write!(out, "{}", round_sig(*x)),
        _ => Ok(()),
    };
}

/// Round a physical value to 6 significant digits for display.
pub fn round_sig(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let d = 6 - x.abs().log10().ceil() as i32;
    let p = 10f64.powi(d.clamp(-300, 300));
    (x * p).round() / p
}

/// A motion field's value in physical units, with the unit, when `scale` converts it.
pub fn phys<'s>(
    f: &Field,
    v: &Value<'_>,
    scale: Option<&'s crate::units::Scale>,
) -> Option<(f64, &'s str)> {
    let s = scale?;
    if let Some(m) = f.pct_of {
        return s.of_maximum(m, v.as_f64()? * f.scale.unwrap_or(1.0));
    }
    s.convert(f.q?, v.as_f64()?)
}

/// A field's physical value and unit as every view gives it: the device's or stage's conversion
/// when it applies (piezo % in V or µm, motion values in mm), else the table's fixed scale;
/// rounded to 6 significant digits.
pub fn phys_or_scaled<'s>(
    f: &Field,
    v: &Value<'_>,
    scale: Option<&'s crate::units::Scale>,
) -> Option<(f64, &'s str)> {
    let (x, unit) = phys(f, v, scale).or_else(|| {
        let (s, x) = f.scale.zip(v.as_f64())?;
        Some((x * s, f.unit.unwrap_or("")))
    })?;
    Some((round_sig(x), unit))
}

/// A one-line summary of the key fields (`name=value unit`, comma separated), for timelines.
pub fn summary(frame: &AptFrame<'_, '_>, max_fields: usize, out: &mut String) {
    summary_in(frame, max_fields, None, out)
}

/// [`summary`] with motion values also in physical units (see [`fmt_value_in`]).
pub fn summary_in(
    frame: &AptFrame<'_, '_>,
    max_fields: usize,
    scale: Option<&crate::units::Scale>,
    out: &mut String,
) {
    let mut n = 0;
    for (f, v) in frame.fields() {
        if AptFrame::is_key_field(f) {
            continue;
        }
        if n == max_fields {
            out.push_str(" …");
            break;
        }
        if n > 0 {
            out.push(' ');
        }
        out.push_str(f.name);
        out.push('=');
        fmt_value_in(frame.table(), f, &v, scale, out);
        n += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::apt::{AptFramer, Item};

    /// What `fields` gave before the per-form reads: every field but `pad`, read by its `Field`.
    fn fields_by_field<'a, 't>(fr: &AptFrame<'a, 't>) -> Vec<(&'t Field, Value<'a>)> {
        let fields: &'t [Field] = fr.form.map_or(&[], |f| f.fields.as_slice());
        fields
            .iter()
            .filter(|f| !matches!(f.ty, Ty::Pad(_)))
            .filter_map(|f| Some((f, field_value(fr.bytes, f)?)))
            .collect()
    }

    /// The channel as read before the `u16` shortcut.
    fn channel_by_field(fr: &AptFrame<'_, '_>) -> Option<i64> {
        let c = int_value(fr.bytes, fr.form?.chan_field()?)?;
        Some(match c {
            4 => 3,
            8 => 4,
            c => c,
        })
    }

    /// Text ends at the first NUL; valid UTF-8 is borrowed, invalid bytes become U+FFFD.
    #[test]
    fn text_reads_up_to_the_nul() {
        use std::borrow::Cow;
        assert!(matches!(text_of(b"KDC101\0\0x"), Cow::Borrowed("KDC101")));
        assert!(matches!(text_of("µm".as_bytes()), Cow::Borrowed("µm")));
        assert_eq!(text_of(b"a\xffb\0c"), "a\u{FFFD}b");
        assert_eq!(text_of(b"\xe2\x82"), "\u{FFFD}");
        assert_eq!(text_of(b""), "");
    }

    /// Every form of the table with random values, each frame whole and cut at every length:
    /// the values, fields and channel are those read field by field.
    #[test]
    fn reads_give_what_the_fields_give() {
        let t = Table::global();
        let stream = crate::synth::stream(t, 7, 3000, false);
        let mut f = AptFramer::new(t);
        f.push(&stream);
        f.finish();
        let mut frames = 0;
        while let Some(it) = f.next_item() {
            let Item::Frame { offset, bytes, .. } = it else {
                continue;
            };
            for end in HEADER_LEN..=bytes.len() {
                let cut = &bytes[..end];
                let truncated = end < bytes.len();
                let Some(fr) = AptFrame::decode(t, offset, cut, truncated) else {
                    panic!("{cut:02x?}: no frame");
                };
                let got: Vec<_> = fr.fields().collect();
                let want = fields_by_field(&fr);
                assert_eq!(got.len(), want.len(), "{cut:02x?}");
                for ((gf, gv), (wf, wv)) in got.iter().zip(&want) {
                    assert!(std::ptr::eq(*gf, *wf), "{cut:02x?}: {}", wf.name);
                    // Bit for bit: a random f32 may be a NaN.
                    let same = match (gv, wv) {
                        (Value::F(a), Value::F(b)) => a.to_bits() == b.to_bits(),
                        _ => gv == wv,
                    };
                    assert!(same, "{cut:02x?}: {}: {gv:?} vs {wv:?}", wf.name);
                }
                assert_eq!(fr.channel(), channel_by_field(&fr), "{cut:02x?}");
            }
            frames += 1;
        }
        assert!(frames >= 3000, "{frames} frames");
    }
}
