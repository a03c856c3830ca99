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
    /// The value does not fit the field's type.
    OutOfRange {
        /// Field name.
        field: String,
        /// What was given.
        value: String,
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
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::UnknownField(n) => write!(f, "no field `{n}` in this form"),
            EncodeError::OutOfRange { field, value } => {
                write!(f, "{field}: {value} does not fit the field")
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
        }
    }
}

impl std::error::Error for EncodeError {}

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

fn put_prim(p: Prim, field: &str, v: f64, out: &mut [u8]) -> Result<(), EncodeError> {
    let oor = || EncodeError::OutOfRange {
        field: field.to_string(),
        value: v.to_string(),
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
    let data_len = match form.kind {
        FormKind::Header => 0,
        FormKind::Data(n) => n as usize,
        FormKind::Sub => return Err(EncodeError::SubFormNeedsSub),
    };
    let mut out = vec![0u8; HEADER_LEN + data_len];
    for (name, v) in values {
        let f = form
            .fields
            .iter()
            .find(|f| f.name == *name)
            .ok_or_else(|| EncodeError::UnknownField(name.to_string()))?;
        let at = f.loc.frame_offset();
        let w = f.ty.width();
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
                if xs.len() > *n as usize {
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
