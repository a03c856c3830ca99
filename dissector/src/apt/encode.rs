//! Building frames from field values, driven by the same table as decoding.

use super::header::{emit_header, HEADER_LEN};
use crate::table::{parse_int, Field, Form, FormKind, Loc, Prim, Table, Ty};
use std::fmt;

/// A value to put into a field.
#[derive(Debug, Clone, PartialEq)]
pub enum FieldValue {
    /// An integer (also enum values and flag masks).
    Int(i64),
    /// A float (for `f32` fields).
    Float(f64),
    /// Text for `str[N]` fields.
    Text(String),
    /// Bytes for `bytes[N]`/`pad[N]` fields.
    Bytes(Vec<u8>),
    /// Elements of an array field.
    List(Vec<f64>),
}

/// Why a frame could not be built.
#[derive(Debug, Clone, PartialEq)]
pub enum EncodeError {
    /// No field of this name in the form.
    UnknownField(String),
    /// No form of the message has a field of this name.
    NoSuchField {
        /// The message (or sub-message).
        msg: String,
        /// The field asked for.
        field: String,
        /// The fields the message has, nearest to the one asked for first.
        fields: Vec<String>,
    },
    /// A field that must be given (the channel) was not.
    MissingField {
        /// The message.
        msg: String,
        /// The field.
        field: String,
    },
    /// The message's data is a sub-message and none was named.
    NeedsSub {
        /// The message.
        msg: String,
        /// Its group's sub-messages.
        subs: Vec<String>,
    },
    /// The value does not fit the field's type.
    OutOfRange {
        /// Field name.
        field: String,
        /// What was given.
        value: String,
        /// What the field takes (`an integer -2147483648..2147483647 (i32)`).
        range: String,
    },
    /// The text could not be read as a value for this field.
    BadValue {
        /// Field name.
        field: String,
        /// What was given.
        text: String,
        /// What the field takes.
        expected: String,
    },
    /// Encoding needs a header-only or data form; `form sub` is only a placeholder.
    SubFormNeedsSub,
    /// No message of this name in the table.
    UnknownMessage {
        /// What was asked for.
        name: String,
        /// The nearest known names.
        near: Vec<String>,
    },
    /// No sub-message of this name in the message's group.
    UnknownSub {
        /// The group (`la`, `tec`, …).
        group: String,
        /// What was asked for.
        name: String,
        /// The group's sub-messages.
        subs: Vec<String>,
    },
    /// A sub-message was named for a message without sub-messages.
    NoSubs(String),
    /// A form was asked for that is neither `hdr` nor a length.
    BadForm(String),
    /// No form of the message has every field given (or the form asked for).
    NoForm {
        /// The message.
        msg: String,
        /// Its forms (`hdr, 14`).
        forms: String,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::UnknownField(n) => write!(f, "no field `{n}` in this form"),
            EncodeError::NoSuchField { msg, field, fields } => write!(
                f,
                "{msg} has no field `{field}`; its fields are: {}",
                fields.join(", ")
            ),
            EncodeError::MissingField { msg, field } => {
                write!(f, "{msg} needs `{field}` (e.g. {field}=CH1)")
            }
            EncodeError::NeedsSub { msg, subs } => write!(
                f,
                "{msg} carries a sub-message: name one with --sub ({})",
                subs.join(", ")
            ),
            EncodeError::OutOfRange {
                field,
                value,
                range,
            } => {
                write!(
                    f,
                    "{field}: {value} does not fit the field: it takes {range}"
                )
            }
            EncodeError::BadValue {
                field,
                text,
                expected,
            } => {
                write!(f, "{field}: cannot read `{text}` (expected {expected})")
            }
            EncodeError::SubFormNeedsSub => write!(
                f,
                "this message's data is a sub-message: name the sub-message"
            ),
            EncodeError::UnknownMessage { name, near } => {
                write!(f, "no message named {name}")?;
                if !near.is_empty() {
                    write!(f, "; did you mean {}?", near.join(", "))?;
                }
                Ok(())
            }
            EncodeError::UnknownSub { group, name, subs } => {
                write!(
                    f,
                    "no sub-message {name} in group {group}; it has: {}",
                    subs.join(", ")
                )
            }
            EncodeError::NoSubs(m) => write!(f, "{m} has no sub-messages"),
            EncodeError::BadForm(x) => write!(f, "a form is hdr or a length, not {x}"),
            EncodeError::NoForm { msg, forms } => write!(
                f,
                "no form of {msg} fits (forms: {forms}; name a sub-message for sub-messages)"
            ),
        }
    }
}

impl std::error::Error for EncodeError {}

impl EncodeError {
    /// The error for a message name the table does not have, with the nearest names.
    pub fn unknown_message(table: &Table, name: &str) -> EncodeError {
        let near = crate::suggest::nearest(name, table.msgs().iter().map(|m| m.name), 4);
        EncodeError::UnknownMessage {
            name: name.to_string(),
            near: near.into_iter().map(str::to_string).collect(),
        }
    }
}

impl FieldValue {
    /// Read a value for `field` from text: a number (decimal, `0x` hex, negative, float), an enum
    /// label, flag labels joined by `|`, a string, comma-separated array elements, or hex bytes.
    pub fn from_text(table: &Table, field: &Field, s: &str) -> Result<FieldValue, EncodeError> {
        let bad = |exp: &str| EncodeError::BadValue {
            field: field.name.to_string(),
            text: s.to_string(),
            expected: exp.to_string(),
        };
        match field.ty {
            Ty::Str(_) => return Ok(FieldValue::Text(s.to_string())),
            Ty::Bytes(_) | Ty::Pad(_) => {
                let clean: String = s.chars().filter(|c| c.is_ascii_hexdigit()).collect();
                if !clean.len().is_multiple_of(2)
                    || clean.len()
                        != s.chars()
                            .filter(|c| !c.is_whitespace() && *c != ',')
                            .count()
                {
                    return Err(bad("hex bytes"));
                }
                let bytes = (0..clean.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&clean[i..i + 2], 16).map_err(|_| bad("hex bytes")))
                    .collect::<Result<Vec<u8>, _>>()?;
                return Ok(FieldValue::Bytes(bytes));
            }
            Ty::Array(..) => {
                let v = s
                    .split(',')
                    .map(|x| parse_num(x.trim()).ok_or_else(|| bad("comma-separated numbers")))
                    .collect::<Result<Vec<f64>, _>>()?;
                return Ok(FieldValue::List(v));
            }
            Ty::Prim(_) => {}
        }
        if let Some(e) = field.enumeration {
            if let Some(v) = table.enum_def(e).value(s) {
                return Ok(FieldValue::Int(v));
            }
        }
        if let Some(fl) = field.flags {
            let defs = table.flags_def(fl);
            let mut acc: i64 = 0;
            let mut all = true;
            for part in s.split('|') {
                match defs.mask(part.trim()) {
                    Some(m) => acc |= m as i64,
                    None => match parse_int(part.trim()) {
                        Some(v) => acc |= v,
                        None => all = false,
                    },
                }
            }
            if all {
                return Ok(FieldValue::Int(acc));
            }
        }
        if let Some(v) = parse_int(s) {
            return Ok(FieldValue::Int(v));
        }
        // An integer too long for any field: out of range, not unreadable.
        let digits = s.strip_prefix('-').unwrap_or(s);
        if let (Ty::Prim(p), false, true) = (
            field.ty,
            digits.is_empty(),
            digits.bytes().all(|c| c.is_ascii_digit()),
        ) {
            return Err(EncodeError::OutOfRange {
                field: field.name.to_string(),
                value: s.to_string(),
                range: prim_range(p),
            });
        }
        if field.ty == Ty::Prim(Prim::F32) {
            if let Some(v) = parse_num(s) {
                return Ok(FieldValue::Float(v));
            }
        }
        let mut exp = String::from("a number");
        if let Some(e) = field.enumeration {
            exp.push_str(" or one of ");
            exp.push_str(
                &table
                    .enum_def(e)
                    .items
                    .iter()
                    .map(|(_, l)| *l)
                    .collect::<Vec<_>>()
                    .join(", "),
            );
        }
        if let Some(fl) = field.flags {
            exp.push_str(" or flags from ");
            exp.push_str(
                &table
                    .flags_def(fl)
                    .items
                    .iter()
                    .map(|(_, l)| *l)
                    .collect::<Vec<_>>()
                    .join("|"),
            );
        }
        Err(bad(&exp))
    }
}

fn parse_num(s: &str) -> Option<f64> {
    parse_int(s)
        .map(|v| v as f64)
        .or_else(|| s.parse::<f64>().ok().filter(|v| v.is_finite()))
}

/// What a field of type `p` takes, for errors.
fn prim_range(p: Prim) -> String {
    let (lo, hi): (i64, i64) = match p {
        Prim::U8 => (0, u8::MAX.into()),
        Prim::I8 => (i8::MIN.into(), i8::MAX.into()),
        Prim::U16 => (0, u16::MAX.into()),
        Prim::I16 => (i16::MIN.into(), i16::MAX.into()),
        // Status words are often written as signed masks: the i32 range is taken too.
        Prim::U32 => (i32::MIN.into(), u32::MAX.into()),
        Prim::I32 => (i32::MIN.into(), i32::MAX.into()),
        Prim::F32 => return "a number (f32)".to_string(),
    };
    format!("an integer {lo}..{hi} ({})", Ty::Prim(p).name())
}

fn put_prim(p: Prim, field: &str, v: f64, out: &mut [u8]) -> Result<(), EncodeError> {
    let oor = || EncodeError::OutOfRange {
        field: field.to_string(),
        value: v.to_string(),
        range: prim_range(p),
    };
    let int = || -> Result<i64, EncodeError> {
        if v.fract() != 0.0 {
            return Err(oor());
        }
        Ok(v as i64)
    };
    match p {
        Prim::U8 => out[0] = u8::try_from(int()?).map_err(|_| oor())?,
        Prim::I8 => out[0] = i8::try_from(int()?).map_err(|_| oor())? as u8,
        Prim::U16 => {
            out[..2].copy_from_slice(&u16::try_from(int()?).map_err(|_| oor())?.to_le_bytes())
        }
        Prim::I16 => {
            out[..2].copy_from_slice(&i16::try_from(int()?).map_err(|_| oor())?.to_le_bytes())
        }
        // Status words are often written as signed masks; accept the i32 range for u32.
        Prim::U32 => {
            let x = int()?;
            let u = u32::try_from(x)
                .or_else(|_| i32::try_from(x).map(|y| y as u32))
                .map_err(|_| oor())?;
            out[..4].copy_from_slice(&u.to_le_bytes())
        }
        Prim::I32 => {
            out[..4].copy_from_slice(&i32::try_from(int()?).map_err(|_| oor())?.to_le_bytes())
        }
        Prim::F32 => out[..4].copy_from_slice(&(v as f32).to_le_bytes()),
    }
    Ok(())
}

/// Build a frame of `form` (a message's `hdr` or data form, or a sub-message's form) from named
/// values; fields not given are 0. For a sub-message form, give `sub_id` (or it stays 0).
pub fn encode(
    form: &Form,
    values: &[(&str, FieldValue)],
    msg_id: u16,
    dst: u8,
    src: u8,
) -> Result<Vec<u8>, EncodeError> {
    if form.kind == FormKind::Sub {
        return Err(EncodeError::SubFormNeedsSub);
    }
    // An open form: the fixed fields, then as many elements of the open array as given.
    let open = form.open_elem().and(form.fields.last());
    let elems = values.iter().find_map(|(k, v)| match (open, v) {
        (Some(f), FieldValue::List(xs)) if f.name == *k => Some((f, xs.len())),
        _ => None,
    });
    // The length rule of forms (`Form::encoded_len`): more elements than the message's
    // largest packet holds do not fit.
    let data_len = form
        .encoded_len(elems.map_or(0, |(_, n)| n))
        .ok_or_else(|| match elems {
            Some((f, n)) => EncodeError::OutOfRange {
                field: f.name.to_string(),
                value: format!("{n} elements"),
                range: format!(
                    "as many as fit {} bytes of data (the message's largest packet)",
                    form.max_data_len()
                ),
            },
            None => EncodeError::OutOfRange {
                field: form.label(),
                value: "no data length".into(),
                range: "a data length the form has".into(),
            },
        })?;
    let mut out = vec![0u8; HEADER_LEN + data_len];
    for (name, v) in values {
        let f = form
            .fields
            .iter()
            .find(|f| f.name == *name)
            .ok_or_else(|| EncodeError::UnknownField(name.to_string()))?;
        let at = f.loc.frame_offset();
        let w = match f.ty {
            Ty::Array(_, 0) => out.len() - at,
            t => t.width(),
        };
        let slot = &mut out[at..at + w];
        let mismatch = || EncodeError::BadValue {
            field: f.name.to_string(),
            text: format!("{v:?}"),
            expected: f.ty.name(),
        };
        match (&f.ty, v) {
            (Ty::Prim(p), FieldValue::Int(i)) => put_prim(*p, f.name, *i as f64, slot)?,
            (Ty::Prim(p), FieldValue::Float(x)) => put_prim(*p, f.name, *x, slot)?,
            (Ty::Str(n), FieldValue::Text(t)) => {
                if t.len() > *n as usize {
                    return Err(EncodeError::OutOfRange {
                        field: f.name.to_string(),
                        value: t.clone(),
                        range: format!("text of at most {n} bytes"),
                    });
                }
                slot[..t.len()].copy_from_slice(t.as_bytes());
            }
            (Ty::Bytes(n) | Ty::Pad(n), FieldValue::Bytes(b)) => {
                if b.len() != *n as usize {
                    return Err(mismatch());
                }
                slot.copy_from_slice(b);
            }
            (Ty::Array(p, n), FieldValue::List(xs)) => {
                // The open array's slot was sized by the first list given for it.
                let open_len = (*n == 0).then(|| xs.len() * p.width());
                if (*n != 0 && xs.len() > *n as usize) || open_len.is_some_and(|l| l != w) {
                    return Err(mismatch());
                }
                for (i, x) in xs.iter().enumerate() {
                    put_prim(*p, f.name, *x, &mut slot[i * p.width()..])?;
                }
            }
            _ => return Err(mismatch()),
        }
    }
    let params = if data_len > 0 {
        (data_len as u16).to_le_bytes()
    } else {
        let p = |l: Loc| {
            form.fields
                .iter()
                .find(|f| f.loc == l)
                .map(|f| out[f.loc.frame_offset()])
                .unwrap_or(0)
        };
        [p(Loc::P1), p(Loc::P2)]
    };
    out[..HEADER_LEN].copy_from_slice(&emit_header(msg_id, params, data_len > 0, dst, src));
    Ok(out)
}

/// A message to build by name, its field values as text (numbers, `0x` hex, enum labels,
/// flags `A|B`), as `aptscope encode` and scripted sessions give them.
#[derive(Debug, Clone, Copy)]
pub struct Named<'a> {
    /// Message name (`MOT_MOVE_ABSOLUTE`).
    pub name: &'a str,
    /// Sub-message name, for the PARAMS messages of LA_, TEC_, QUAD_, PZMOT_ ….
    pub sub: Option<&'a str>,
    /// `(field, value)` pairs; fields not given are 0.
    pub values: &'a [(&'a str, &'a str)],
    /// The form: `hdr` or a data length; `None`: the first form that has every field given
    /// (the header form when none is given).
    pub form: Option<&'a str>,
    /// Destination address.
    pub dst: u8,
    /// Source address.
    pub src: u8,
}

/// Build the frame described by `n` from the table: the message, its sub-message, the form,
/// and each value read as its field's type.
pub fn encode_named(table: &Table, n: &Named<'_>) -> Result<Vec<u8>, EncodeError> {
    encode_named_report(table, n).map(|(b, _)| b)
}

/// As [`encode_named`], also naming the fields that were not given and so are 0.
pub fn encode_named_report(
    table: &Table,
    n: &Named<'_>,
) -> Result<(Vec<u8>, Vec<&'static str>), EncodeError> {
    let m = table
        .msg_by_name(n.name)
        .ok_or_else(|| EncodeError::unknown_message(table, n.name))?;
    let group_subs = |g: &str| -> Vec<String> {
        table
            .subs()
            .iter()
            .filter(|s| s.group == g)
            .map(|s| s.name.to_string())
            .collect()
    };
    let sub = match (n.sub, m.subs) {
        (Some(s), Some(g)) => {
            Some(
                table
                    .sub_by_name(g, s)
                    .ok_or_else(|| EncodeError::UnknownSub {
                        group: g.to_string(),
                        name: s.to_string(),
                        subs: group_subs(g),
                    })?,
            )
        }
        (Some(_), None) => return Err(EncodeError::NoSubs(m.name.to_string())),
        (None, _) => None,
    };
    // Candidate forms: the sub-message's for a message whose data is a sub-message.
    let mut cands: Vec<&Form> = m.forms.iter().filter(|f| f.kind != FormKind::Sub).collect();
    let has_sub_form = m.forms.iter().any(|f| f.kind == FormKind::Sub);
    if let Some(s) = sub {
        if has_sub_form {
            cands = s.forms.iter().collect();
        }
    }
    let what = match sub {
        Some(s) => format!("{}:{}", m.name, s.name),
        None => m.name.to_string(),
    };
    // A field no candidate form has: say which fields there are.
    for (k, _) in n.values {
        if !cands.iter().any(|f| f.fields.iter().any(|x| x.name == *k)) {
            if sub.is_none() && has_sub_form {
                return Err(EncodeError::NeedsSub {
                    msg: m.name.to_string(),
                    subs: m.subs.map(group_subs).unwrap_or_default(),
                });
            }
            let mut all: Vec<&str> = vec![];
            for f in &cands {
                for x in &f.fields {
                    if !matches!(x.ty, Ty::Pad(_)) && !all.contains(&x.name) {
                        all.push(x.name);
                    }
                }
            }
            let near = crate::suggest::nearest(k, all.iter().copied(), all.len());
            let mut fields: Vec<String> = near.iter().map(|s| s.to_string()).collect();
            fields.extend(
                all.iter()
                    .filter(|a| !near.contains(a))
                    .map(|s| s.to_string()),
            );
            return Err(EncodeError::NoSuchField {
                msg: what,
                field: k.to_string(),
                fields,
            });
        }
    }
    let has_all = |f: &&&Form| {
        n.values
            .iter()
            .all(|(k, _)| f.fields.iter().any(|x| x.name == *k))
    };
    let chosen = match n.form {
        Some("hdr") => cands.iter().find(|f| f.kind == FormKind::Header),
        Some(x) => {
            let len: u16 = x.parse().map_err(|_| EncodeError::BadForm(x.to_string()))?;
            cands.iter().find(|f| f.kind == FormKind::Data(len))
        }
        None => cands
            .iter()
            .find(|f| has_all(f) && (!n.values.is_empty() || f.kind == FormKind::Header))
            .or_else(|| cands.iter().find(has_all)),
    }
    .ok_or_else(|| {
        if cands.is_empty() && has_sub_form {
            return EncodeError::NeedsSub {
                msg: m.name.to_string(),
                subs: m.subs.map(group_subs).unwrap_or_default(),
            };
        }
        EncodeError::NoForm {
            msg: what.clone(),
            forms: cands
                .iter()
                .map(|f| f.label())
                .collect::<Vec<_>>()
                .join(", "),
        }
    })?;
    // The channel has no sensible default (0 addresses no channel).
    if chosen.fields.iter().any(|f| f.name == "chan_ident")
        && !n.values.iter().any(|(k, _)| *k == "chan_ident")
    {
        return Err(EncodeError::MissingField {
            msg: what,
            field: "chan_ident".into(),
        });
    }
    let mut vals: Vec<(&str, FieldValue)> = vec![];
    if let Some(s) = sub {
        if chosen.fields.iter().any(|f| f.name == "sub_id")
            && !n.values.iter().any(|(k, _)| *k == "sub_id")
        {
            vals.push(("sub_id", FieldValue::Int(i64::from(s.id))));
        }
    }
    for (k, v) in n.values {
        let f = chosen
            .fields
            .iter()
            .find(|f| f.name == *k)
            .ok_or_else(|| EncodeError::UnknownField(k.to_string()))?;
        vals.push((k, FieldValue::from_text(table, f, v)?));
    }
    let defaulted: Vec<&'static str> = chosen
        .fields
        .iter()
        .filter(|f| !matches!(f.ty, Ty::Pad(_)))
        .filter(|f| !vals.iter().any(|(k, _)| *k == f.name))
        .map(|f| f.name)
        .collect();
    encode(chosen, &vals, m.id, n.dst, n.src).map(|b| (b, defaulted))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn named<'a>(
        name: &'a str,
        sub: Option<&'a str>,
        values: &'a [(&'a str, &'a str)],
    ) -> Named<'a> {
        Named {
            name,
            sub,
            values,
            form: None,
            dst: 0x50,
            src: 0x01,
        }
    }

    #[test]
    fn builds_by_name_with_forms_and_sub_messages() {
        let t = Table::global();
        let stop = named(
            "MOT_MOVE_STOP",
            None,
            &[("chan_ident", "CH1"), ("stop_mode", "PROFILED")],
        );
        assert_eq!(
            encode_named(t, &stop),
            Ok(vec![0x65, 0x04, 0x01, 0x02, 0x50, 0x01])
        );
        // A sub-message: its id comes first in the data.
        let sp = named("LA_SET_PARAMS", Some("SETPOINT"), &[("setpoint", "1638")]);
        let b = encode_named(t, &sp).expect("encodes");
        assert_eq!(&b[6..8], &[0x01, 0x00], "{b:02x?}");
        // What cannot be built says why.
        let e = |n: &Named<'_>| encode_named(t, n).expect_err("refused").to_string();
        assert!(e(&named("NO_SUCH", None, &[])).contains("no message named NO_SUCH"));
        assert!(e(&named("HW_REQ_INFO", Some("X"), &[])).contains("has no sub-messages"));
        assert!(e(&named("NO_SUCH", None, &[])).contains("no message named NO_SUCH"));
        let typo = e(&named("MOT_MOVE_STPO", None, &[]));
        assert!(typo.contains("did you mean MOT_MOVE_STOP"), "{typo}");
        let field = e(&named(
            "MOT_MOVE_ABSOLUTE",
            None,
            &[("chan_ident", "CH1"), ("position", "5")],
        ));
        assert!(
            field
                .contains("has no field `position`; its fields are: absolute_position, chan_ident"),
            "{field}"
        );
        let needs = e(&named("LA_SET_PARAMS", None, &[("setpoint", "1638")]));
        assert!(
            needs.contains("name one with --sub (") && needs.contains("SETPOINT"),
            "{needs}"
        );
        let bad_sub = e(&named("LA_SET_PARAMS", Some("FOO"), &[]));
        assert!(
            bad_sub.contains("it has: ") && bad_sub.contains("SETPOINT"),
            "{bad_sub}"
        );
        let chan = e(&named(
            "MOT_MOVE_ABSOLUTE",
            None,
            &[("absolute_position", "5")],
        ));
        assert!(chan.contains("needs `chan_ident`"), "{chan}");
        let (_, zero) = encode_named_report(
            t,
            &named(
                "MOT_SET_VELPARAMS",
                None,
                &[("chan_ident", "1"), ("max_vel", "9")],
            ),
        )
        .expect("encodes");
        assert_eq!(zero, ["min_vel", "acceleration"]);
        let hdr = Named {
            form: Some("12x"),
            ..stop
        };
        assert!(e(&hdr).contains("a form is hdr or a length"));
    }

    /// An open form holds as many rows as given, up to its message's `maxlen=`: the length
    /// `Form::encoded_len` states and `Form::accepts_len` (the decoder's rule) accepts.
    #[test]
    fn open_forms_take_rows_up_to_the_messages_largest_packet() {
        let t = Table::global();
        let m = t
            .msg_by_name("MOT_SET_MOVESYNCHARRAY")
            .expect("in the table");
        let form = &m.forms[0];
        assert_eq!(form.max_data_len(), 4104);
        assert_eq!(form.encoded_len(0), Some(8));
        assert_eq!(form.encoded_len(1024), Some(4104));
        assert_eq!(form.encoded_len(1025), None);
        assert!(form.accepts_len(true, 4104) && !form.accepts_len(true, 4106));
        assert!(
            !form.accepts_len(false, 8),
            "an open form has a data packet"
        );
        let rows = |n: usize| ("time_pos", FieldValue::List(vec![7.0; n]));
        let b = encode(form, &[rows(1024)], m.id, 0x50, 0x01).expect("fits");
        assert_eq!(b.len(), 6 + 4104);
        assert_eq!(&b[2..5], &[0x08, 0x10, 0xD0]);
        // One row more: refused, not a frame the framer would take for a corrupt header.
        let e = encode(form, &[rows(1025)], m.id, 0x50, 0x01).expect_err("too long");
        assert!(matches!(e, EncodeError::OutOfRange { .. }), "{e}");
        // The open array given twice: the slot was sized by the first list, so a longer second
        // one is refused (it once panicked, writing past the slot).
        let e = encode(form, &[rows(1), rows(3)], m.id, 0x50, 0x01).expect_err("twice");
        assert!(matches!(e, EncodeError::BadValue { .. }), "{e}");
    }
}
