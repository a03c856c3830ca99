//! The NDJSON shape of decoded records, written without allocation per value.
//!
//! One object per line; the shape is documented in the README ("NDJSON output").

use crate::apt::{text_of, AptFrame, GarbageKind, Value};
use crate::diag::{Diag, DiagKind};
use crate::table::{Field, Table};
use std::fmt::Write;

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
    const H: &[u8; 16] = b"0123456789abcdef";
    out.reserve(b.len() * 2 + 2);
    out.push('"');
    // Through a stack buffer: pushing chars one by one costs a UTF-8 encode each.
    let mut buf = [0u8; 128];
    for part in b.chunks(buf.len() / 2) {
        for (i, &x) in part.iter().enumerate() {
            buf[2 * i] = H[(x >> 4) as usize];
            buf[2 * i + 1] = H[(x & 15) as usize];
        }
        out.push_str(std::str::from_utf8(&buf[..2 * part.len()]).unwrap_or_default());
    }
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

/// Append a diagnostics array: `[{"kind":…, "offset":…, "msg":…}]`.
pub fn diags(out: &mut String, ds: impl Iterator<Item = Diag>) {
    out.push('[');
    for (i, d) in ds.enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push_str("{\"kind\":\"");
        out.push_str(d.kind.name());
        out.push_str("\",\"offset\":");
        uint(out, d.offset);
        out.push_str(",\"msg\":");
        string(out, &d.kind.to_string());
        out.push('}');
    }
    out.push(']');
}

/// Append one field value: numbers as numbers, enums as names, flags as lists of set names,
/// text as strings, opaque bytes as hex, arrays as arrays.
pub fn value(out: &mut String, table: &Table, f: &Field, v: &Value<'_>) {
    match v {
        Value::U(x) => {
            if let Some(e) = f.enumeration {
                if let Some(l) = table.enum_def(e).label(*x as i64) {
                    return string(out, l);
                }
            }
            if let Some(fl) = f.flags {
                out.push('[');
                let mut first = true;
                for (m, l) in &table.flags_def(fl).items {
                    if x & m == *m {
                        if !first {
                            out.push(',');
                        }
                        string(out, l);
                        first = false;
                    }
                }
                out.push(']');
                return;
            }
            uint(out, *x);
        }
        Value::I(x) => {
            if let Some(l) = f.enumeration.and_then(|e| table.enum_def(e).label(*x)) {
                return string(out, l);
            }
            int(out, *x);
        }
        Value::F(x) => float(out, *x),
        Value::Str(b) => string(out, &text_of(b)),
        Value::Bytes(b) => hex(out, b),
        Value::Array(..) => {
            out.push('[');
            for (i, e) in v.elements().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                match e {
                    Value::U(x) => uint(out, x),
                    Value::I(x) => int(out, x),
                    Value::F(x) => float(out, x),
                    _ => out.push_str("null"),
                }
            }
            out.push(']');
        }
    }
}

fn addr(out: &mut String, key: &str, a: crate::apt::Addr) {
    use crate::apt::Addr;
    out.push_str(",\"");
    out.push_str(key);
    out.push_str("\":{\"addr\":");
    uint(out, a.byte() as u64);
    out.push_str(",\"name\":\"");
    match a {
        Addr::Host => out.push_str("host"),
        Addr::Rack => out.push_str("rack"),
        Addr::Usb => out.push_str("usb"),
        Addr::Bay(n) => {
            out.push_str("bay");
            out.push((b'0' + n) as char);
        }
        Addr::Unknown(x) => {
            let _ = write!(out, "0x{x:02X}");
        }
    }
    out.push('"');
    if let Some(b) = a.bay() {
        out.push_str(",\"bay\":");
        uint(out, b as u64);
    }
    out.push('}');
}

/// Append an unsigned integer (cheaper than `write!` on the hot path).
pub fn uint(out: &mut String, mut x: u64) {
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (x % 10) as u8;
        x /= 10;
        if x == 0 {
            break;
        }
    }
    out.push_str(std::str::from_utf8(&buf[i..]).unwrap_or_default());
}

/// Append a signed integer.
pub fn int(out: &mut String, x: i64) {
    if x < 0 {
        out.push('-');
    }
    uint(out, x.unsigned_abs());
}

/// Append the JSON object of a decoded APT frame (no trailing newline). `n` is the record number.
pub fn apt_frame(out: &mut String, n: u64, f: &AptFrame<'_, '_>) {
    apt_frame_paired(out, n, f, &crate::pair::PairInfo::default());
}

/// [`apt_frame`] with what pairing found: `pair`, `latency_ms`, `pair_other_address`, and the
/// `unsolicited`/`duplicate_reply` diagnostics.
pub fn apt_frame_paired(out: &mut String, n: u64, f: &AptFrame<'_, '_>, p: &crate::pair::PairInfo) {
    apt_frame_in(out, n, f, p, None)
}

/// [`apt_frame_paired`] with the stage's conversion: motion fields (`q=` in the table) get a
/// `phys` entry (`{"value": 2.5, "unit": "mm/s"}`) beside their raw value in `fields`.
pub fn apt_frame_in(
    out: &mut String,
    n: u64,
    f: &AptFrame<'_, '_>,
    p: &crate::pair::PairInfo,
    scale: Option<&crate::units::Scale>,
) {
    let h = f.header();
    out.push_str("{\"n\":");
    uint(out, n);
    out.push_str(",\"proto\":\"apt\",\"type\":\"frame\",\"offset\":");
    uint(out, f.offset);
    out.push_str(",\"len\":");
    uint(out, f.bytes.len() as u64);
    out.push_str(",\"raw\":");
    hex(out, f.bytes);
    out.push_str(",\"msgid\":");
    uint(out, h.msg_id() as u64);
    const H: &[u8; 16] = b"0123456789ABCDEF";
    out.push_str(",\"msgid_hex\":\"0x");
    for sh in [12, 8, 4, 0] {
        out.push(H[(h.msg_id() >> sh) as usize & 15] as char);
    }
    out.push_str("\",\"name\":");
    match f.msg {
        Some(m) => {
            string(out, m.name);
            out.push_str(",\"msg_dir\":\"");
            out.push_str(m.dir.as_str());
            out.push('"');
        }
        None => out.push_str("null"),
    }
    addr(out, "src", h.src());
    addr(out, "dst", h.dst());
    out.push_str(if h.has_data() {
        ",\"data_flag\":true,\"data_len\":"
    } else {
        ",\"data_flag\":false,\"data_len\":"
    });
    uint(out, f.data_len() as u64);
    if let Some(form) = f.form {
        if !form.note.is_empty() {
            out.push_str(",\"form_note\":");
            string(out, form.note);
        }
    }
    if let Some(c) = f.channel() {
        out.push_str(",\"channel\":");
        int(out, c);
    }
    if let Some(s) = f.sub {
        out.push_str(",\"sub\":{\"id\":");
        uint(out, s.id as u64);
        out.push_str(",\"name\":");
        string(out, s.name);
        out.push('}');
    }
    out.push_str(",\"fields\":{");
    let mut phys = String::new();
    for (i, (fd, v)) in f.fields().enumerate() {
        if i > 0 {
            out.push(',');
        }
        string(out, fd.name);
        out.push(':');
        value(out, f.table(), fd, &v);
        if let Some((x, unit)) = crate::apt::phys_or_scaled(fd, &v, scale) {
            if !phys.is_empty() {
                phys.push(',');
            }
            string(&mut phys, fd.name);
            phys.push_str(":{\"value\":");
            float(&mut phys, x);
            phys.push_str(",\"unit\":");
            string(&mut phys, unit);
            phys.push('}');
        }
    }
    out.push('}');
    close_map(out, "phys", &phys);
    // A second pass rather than a buffer: no allocation per frame.
    codes(
        out,
        f.fields()
            .filter_map(|(fd, v)| Some((fd.name, crate::fields::apt_code(fd, &v)?))),
    );
    if let Some(x) = p.pair {
        out.push_str(",\"pair\":");
        uint(out, x);
    }
    if let Some(l) = p.latency_ns {
        out.push_str(",\"latency_ms\":");
        float(out, l as f64 / 1e6);
    }
    if p.other_address {
        out.push_str(",\"pair_other_address\":true");
    }
    out.push_str(",\"diag\":");
    diags(out, apt_diags(f, p));
    out.push('}');
}

/// `,"codes":{name:number,…}` when there are any.
fn codes(out: &mut String, items: impl Iterator<Item = (&'static str, i128)>) {
    let mut first = true;
    for (name, c) in items {
        out.push_str(if first { ",\"codes\":{" } else { "," });
        first = false;
        string(out, name);
        out.push(':');
        match u64::try_from(c) {
            Ok(u) => uint(out, u),
            Err(_) => int(out, c as i64),
        }
    }
    if !first {
        out.push('}');
    }
}

/// `,"key":{members}` when there are members.
fn close_map(out: &mut String, key: &str, members: &str) {
    if !members.is_empty() {
        out.push_str(",\"");
        out.push_str(key);
        out.push_str("\":{");
        out.push_str(members);
        out.push('}');
    }
}

/// The diagnostics of an APT frame: the decoder's, then pairing's (`unsolicited`,
/// `duplicate_reply`, `not_for_model`).
pub fn apt_diags<'x>(
    f: &'x AptFrame<'_, '_>,
    p: &'x crate::pair::PairInfo,
) -> impl Iterator<Item = Diag> + 'x {
    f.diags().chain(p.diags(f.offset))
}

/// Append the JSON object of a units notice: what converts a device's motion values from now
/// on (`{"type":"units","stream":0,"addr":{…},"model":"KDC101","stage":"MTS25-Z8",
/// "family":"dc_servo","counts_per_unit":34554.96,"unit":"mm"}`), or why they stay raw
/// (`"raw":"…"`).
pub fn units_notice(out: &mut String, n: &crate::units::Notice) {
    use crate::units::Resolution;
    out.push_str("{\"type\":\"units\",\"stream\":");
    uint(out, n.stream as u64);
    addr(out, "addr", crate::apt::Addr::from_byte(n.addr));
    if let Some(m) = &n.model {
        out.push_str(",\"model\":");
        string(out, m);
    }
    match &n.resolution {
        Resolution::Scale(s) => {
            out.push_str(",\"stage\":");
            string(out, s.stage);
            if let Some(f) = s.family {
                out.push_str(",\"family\":");
                string(out, f.name());
            }
            out.push_str(",\"counts_per_unit\":");
            float(out, s.counts_per_unit);
            out.push_str(",\"unit\":");
            string(out, &s.unit);
        }
        Resolution::Raw(why) => {
            out.push_str(",\"raw\":");
            string(out, why);
        }
        Resolution::None => out.push_str(",\"raw\":\"no stage\""),
    }
    out.push('}');
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

/// Append the JSON object of a garbage record.
pub fn apt_garbage(out: &mut String, n: u64, offset: u64, bytes: &[u8], kind: GarbageKind) {
    let _ = write!(
        out,
        "{{\"n\":{n},\"proto\":\"apt\",\"type\":\"garbage\",\"offset\":{offset},\"len\":{},\"raw\":",
        bytes.len()
    );
    hex(out, bytes);
    out.push_str(",\"diag\":");
    let d = garbage_diag(offset, bytes.len(), kind);
    diags(out, std::iter::once(d));
    out.push('}');
}

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

/// Append the JSON object of a decoded Elliptec frame with what the bus made of it.
pub fn ell_frame(
    out: &mut String,
    n: u64,
    f: &crate::ell::EllFrame<'_>,
    o: &crate::ell::Observation,
) {
    use crate::ell::{table::Kind, EllValue};
    out.push_str("{\"n\":");
    uint(out, n);
    out.push_str(",\"proto\":\"ell\",\"type\":\"frame\",\"offset\":");
    uint(out, f.offset);
    out.push_str(",\"len\":");
    uint(out, f.bytes.len() as u64);
    out.push_str(",\"raw\":");
    hex(out, f.bytes);
    out.push_str(",\"text\":");
    string(out, &String::from_utf8_lossy(f.bytes));
    let _ = write!(
        out,
        ",\"addr\":\"{}\",\"dir\":\"{}\",\"cmd\":",
        f.addr_char(),
        f.dir().as_str()
    );
    string(out, f.code_str());
    out.push_str(",\"name\":");
    match f.cmd {
        Some(c) => string(out, c.name),
        None => out.push_str("null"),
    }
    let scale = o.module.as_ref().and_then(|m| m.scale());
    out.push_str(",\"fields\":{");
    let mut phys = String::new();
    for (i, (fd, v)) in f.fields().enumerate() {
        if i > 0 {
            out.push(',');
        }
        string(out, fd.name);
        out.push(':');
        match (fd.kind, v) {
            (Kind::Status, EllValue::U(c)) => string(out, crate::ell::table::status_name(c as u32)),
            (_, EllValue::U(x)) => uint(out, x),
            (_, EllValue::I(x)) => int(out, x),
            (_, EllValue::Char(c)) => string(out, c.encode_utf8(&mut [0; 4])),
            (_, EllValue::Digits(d)) => string(out, d),
            (_, EllValue::Raw(b)) => hex(out, b),
        }
        // The binary current curve, point by point.
        if let (Kind::Raw, EllValue::Raw(b)) = (fd.kind, v) {
            out.push_str(",\"curve_points\":[");
            for (i, p) in crate::ell::curve_points(b).enumerate() {
                if i > 0 {
                    out.push(',');
                }
                let _ = write!(
                    out,
                    "{{\"period\":{},\"current\":{},\"hz\":",
                    p.period, p.current
                );
                float(out, p.hz().round());
                out.push_str(",\"amps\":");
                float(out, crate::apt::round_sig(p.amps()));
                out.push('}');
            }
            out.push(']');
        }
        // Coded numbers also as the text shows them (the number stays for scripts).
        if let (Kind::Model, EllValue::U(x)) = (fd.kind, v) {
            let _ = write!(out, ",\"{}_name\":\"ELL{x}\"", fd.name);
        }
        if let (Kind::Firmware, EllValue::U(x)) = (fd.kind, v) {
            let _ = write!(out, ",\"{}_version\":\"{}.{}\"", fd.name, x >> 4, x & 15);
        }
        // The manual packs two facts into this byte: give each its own key too.
        if let (Kind::ThreadHw, EllValue::U(x)) = (fd.kind, v) {
            let thread = if x & 0x80 != 0 { "imperial" } else { "metric" };
            let _ = write!(out, ",\"thread\":\"{thread}\",\"hw_release\":{}", x & 0x7F);
        }
        if let (Kind::Position, EllValue::I(p), Some((ppu, unit))) = (fd.kind, v, scale) {
            if ppu > 0.0 {
                if !phys.is_empty() {
                    phys.push(',');
                }
                string(&mut phys, fd.name);
                phys.push_str(":{\"value\":");
                float(&mut phys, crate::apt::round_sig(p as f64 / ppu));
                let _ = write!(phys, ",\"unit\":\"{unit}\"}}");
            }
        }
    }
    out.push('}');
    close_map(out, "phys", &phys);
    codes(
        out,
        f.fields()
            .filter_map(|(fd, v)| Some((fd.name, i128::from(crate::fields::ell_code(fd, &v)?)))),
    );
    if let Some(m) = &o.module {
        out.push_str(",\"module\":{\"first_addr\":");
        uint(out, m.first_addr as u64);
        if let Some(x) = m.model {
            let _ = write!(out, ",\"model\":\"ELL{x}\"");
        }
        if let Some(s) = &m.serial {
            out.push_str(",\"serial\":");
            string(out, s);
        }
        out.push('}');
    }
    if let Some(p) = o.pair {
        out.push_str(",\"pair\":");
        uint(out, p);
    }
    if let Some(l) = o.latency_ns {
        out.push_str(",\"latency_ms\":");
        float(out, l as f64 / 1e6);
    }
    if o.interim {
        out.push_str(",\"interim\":true");
    }
    out.push_str(",\"diag\":");
    diags(out, f.diags().iter().copied());
    out.push('}');
}

/// Append the JSON object of an Elliptec garbage record.
pub fn ell_garbage(out: &mut String, n: u64, offset: u64, bytes: &[u8]) {
    let _ = write!(out, "{{\"n\":{n},\"proto\":\"ell\",\"type\":\"garbage\",\"offset\":{offset},\"len\":{},\"raw\":", bytes.len());
    hex(out, bytes);
    out.push_str(",\"text\":");
    string(out, &String::from_utf8_lossy(bytes));
    out.push_str(",\"diag\":");
    let d = Diag {
        offset,
        kind: DiagKind::Garbage {
            len: bytes.len() as u32,
        },
    };
    diags(out, std::iter::once(d));
    out.push('}');
}

/// Append a diagnostic that refers to an earlier record (a command that got no reply).
pub fn late_diag(out: &mut String, proto: &str, refers_to: u64, d: Diag) {
    let _ = write!(
        out,
        "{{\"proto\":\"{proto}\",\"type\":\"diag\",\"ref\":{refers_to},\"diag\":"
    );
    diags(out, std::iter::once(d));
    out.push('}');
}
