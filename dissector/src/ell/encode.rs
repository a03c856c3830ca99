//! Building Elliptec frames from the command table: `encode("0", "ma", &[("position", "1000")])`
//! gives `0ma000003E8`.
//!
//! Every field of the command must be given once. Numbers are decimal or `0x` hex; positions
//! are in encoder pulses (32-bit signed; a `0x` value of up to 8 digits is taken as the raw
//! two's complement pattern). Some kinds also take names: status codes (`BUSY`), home
//! directions (`CW`, `CCW`), states (`ON`, `OFF`), models (`ELL14`), firmware `M.m`. The binary
//! current curve of `C1`/`C2` is given as hex bytes. Host commands get no terminator (as the
//! manual's examples); replies end with CR LF, as modules send them.

use super::table::{by_name, lookup, Cmd, Field, Kind, COMMANDS, STATUS};
use crate::table::Dir;
use std::fmt;

/// Why a frame could not be built.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EncodeError {
    /// No command with this mnemonic or name.
    UnknownCommand {
        /// What was asked for.
        given: String,
        /// The closest mnemonic or name, if one is close.
        suggestion: Option<&'static str>,
    },
    /// Not a bus address `0`–`F`.
    BadAddress(String),
    /// The command has no field of this name.
    UnknownField {
        /// The command's mnemonic.
        cmd: &'static str,
        /// What was given.
        field: String,
        /// The command's fields.
        fields: Vec<&'static str>,
    },
    /// A field given twice.
    DuplicateField(String),
    /// A field of the command was not given.
    MissingField {
        /// The command's mnemonic.
        cmd: &'static str,
        /// The field.
        field: &'static str,
    },
    /// A value outside the field's range.
    OutOfRange {
        /// The field.
        field: &'static str,
        /// What was given.
        value: String,
        /// The range it takes.
        range: String,
    },
    /// Text that cannot be read as a value of the field.
    BadValue {
        /// The field.
        field: &'static str,
        /// What was given.
        text: String,
        /// What the field takes.
        expected: String,
    },
    /// An argument that is not `name=value`.
    NotAssignment(String),
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::UnknownCommand { given, suggestion } => {
                write!(f, "no Elliptec command `{given}`")?;
                match suggestion {
                    Some(s) => write!(f, " (did you mean `{s}`?)"),
                    None => write!(f, " (`aptscope messages --proto elliptec` lists them)"),
                }
            }
            EncodeError::BadAddress(a) => write!(f, "`{a}` is not a bus address (0-F)"),
            EncodeError::UnknownField { cmd, field, fields } => {
                if fields.is_empty() {
                    write!(f, "`{cmd}` has no data, so no field `{field}`")
                } else {
                    write!(
                        f,
                        "`{cmd}` has no field `{field}` (its fields: {})",
                        fields.join(", ")
                    )
                }
            }
            EncodeError::DuplicateField(n) => write!(f, "field `{n}` given twice"),
            EncodeError::MissingField { cmd, field } => {
                write!(f, "`{cmd}` needs `{field}=VALUE`")
            }
            EncodeError::OutOfRange {
                field,
                value,
                range,
            } => write!(f, "{field}: {value} is out of range ({range})"),
            EncodeError::BadValue {
                field,
                text,
                expected,
            } => write!(f, "{field}: cannot read `{text}` (expected {expected})"),
            EncodeError::NotAssignment(a) => write!(f, "`{a}` is not name=value"),
        }
    }
}

impl std::error::Error for EncodeError {}

/// The command a user means by `name`: a mnemonic (`ma`, case-sensitive first, then in any
/// case when only one matches) or a name (`MOVE_ABSOLUTE`, any case).
pub fn find(name: &str) -> Result<&'static Cmd, EncodeError> {
    if let Some(c) = lookup(name.as_bytes()).or_else(|| by_name(name)) {
        return Ok(c);
    }
    let unknown = |suggestion| EncodeError::UnknownCommand {
        given: name.to_string(),
        suggestion,
    };
    // `MA` for `ma`, `po` for `PO`: a mnemonic in the other case is only a suggestion, the
    // case being the direction.
    if let Some(c) = COMMANDS.iter().find(|c| c.code.eq_ignore_ascii_case(name)) {
        return Err(unknown(Some(c.code)));
    }
    let upper = name.to_ascii_uppercase();
    let best = COMMANDS
        .iter()
        .flat_map(|c| [c.code, c.name])
        .map(|s| (distance(&upper, &s.to_ascii_uppercase()), s))
        .min_by_key(|(d, _)| *d);
    let close = best.filter(|(d, s)| *d <= (s.len() / 3).max(1));
    Err(unknown(close.map(|(_, s)| s)))
}

/// Levenshtein distance (short strings).
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

/// A bus address: one character `0`–`F` (any case), or a number 0–15.
pub fn parse_addr(s: &str) -> Result<u8, EncodeError> {
    let t = s.trim();
    let v = match t.len() {
        1 => t.chars().next().and_then(|c| c.to_digit(16)),
        _ => parse_int(t).and_then(|v| u32::try_from(v).ok()),
    };
    v.filter(|v| *v < 16)
        .map(|v| v as u8)
        .ok_or_else(|| EncodeError::BadAddress(s.to_string()))
}

/// Decimal or `0x` hex, with an optional sign.
fn parse_int(s: &str) -> Option<i128> {
    let (neg, t) = match s.strip_prefix('-') {
        Some(t) => (true, t),
        None => (false, s.strip_prefix('+').unwrap_or(s)),
    };
    let v = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => i128::from_str_radix(h, 16).ok()?,
        None if !t.is_empty() && t.bytes().all(|c| c.is_ascii_digit()) => t.parse().ok()?,
        None => return None,
    };
    Some(if neg { -v } else { v })
}

/// Split `name=value` arguments.
pub fn assignments<S: AsRef<str>>(args: &[S]) -> Result<Vec<(&str, &str)>, EncodeError> {
    args.iter()
        .map(|a| {
            a.as_ref()
                .split_once('=')
                .ok_or_else(|| EncodeError::NotAssignment(a.as_ref().to_string()))
        })
        .collect()
}

/// Build the frame of command `cmd` (mnemonic or name) for the module at `addr` with these
/// field values: the bytes as sent on the line.
pub fn encode(addr: &str, cmd: &str, values: &[(&str, &str)]) -> Result<Vec<u8>, EncodeError> {
    let c = find(cmd)?;
    let a = parse_addr(addr)?;
    encode_cmd(c, a, values)
}

/// [`encode`] with the command and address already known.
pub fn encode_cmd(
    c: &'static Cmd,
    addr: u8,
    values: &[(&str, &str)],
) -> Result<Vec<u8>, EncodeError> {
    for (i, (k, _)) in values.iter().enumerate() {
        if c.field(k).is_none() {
            return Err(EncodeError::UnknownField {
                cmd: c.code,
                field: k.to_string(),
                fields: c.fields.iter().map(|f| f.name).collect(),
            });
        }
        if values[..i].iter().any(|(k2, _)| k2 == k) {
            return Err(EncodeError::DuplicateField(k.to_string()));
        }
    }
    let mut out = Vec::with_capacity(3 + c.data_len() + 2);
    out.push(b"0123456789ABCDEF"[addr as usize & 15]);
    out.extend_from_slice(c.code.as_bytes());
    for f in c.fields {
        let (_, text) =
            values
                .iter()
                .find(|(k, _)| *k == f.name)
                .ok_or(EncodeError::MissingField {
                    cmd: c.code,
                    field: f.name,
                })?;
        field(f, text.trim(), &mut out)?;
    }
    if c.dir == Dir::DeviceToHost {
        out.extend_from_slice(b"\r\n");
    }
    Ok(out)
}

/// What a field of this kind takes, for error messages.
fn expected(f: &Field) -> String {
    match f.kind {
        Kind::Status => "a status code or name (OK, BUSY, …)".into(),
        Kind::HomeDir => "CW, CCW, 0 or 1".into(),
        Kind::Bool => "ON, OFF, 0 or 1".into(),
        Kind::Model => "ELLn or a number".into(),
        Kind::Firmware => "M.m or a number".into(),
        Kind::Addr => "an address 0-F".into(),
        Kind::Dec => format!("up to {} decimal digits", f.width),
        Kind::Raw => format!("{} bytes in hex", f.width),
        Kind::Position | Kind::Signed => {
            "pulses: a decimal or 0x hex integer (mm/deg are not converted: the pulses per unit are the module's, from its IN reply)".into()
        }
        _ => "a decimal or 0x hex integer".into(),
    }
}

/// The range a numeric field takes.
fn range(f: &Field) -> (i128, i128) {
    let max = (1i128 << (4 * f.width.min(30) as u32)) - 1;
    match f.kind {
        Kind::Position | Kind::Signed => (i32::MIN as i128, u32::MAX as i128),
        Kind::Percent => (0, 100),
        Kind::Bool | Kind::HomeDir => (0, 1),
        Kind::Addr => (0, 15),
        _ => (0, max),
    }
}

/// A name some kinds take instead of a number.
fn named(f: &Field, t: &str) -> Option<i128> {
    let u = t.to_ascii_uppercase();
    let v = match f.kind {
        Kind::Status => STATUS
            .iter()
            .find(|(_, n)| *n == u)
            .map(|(c, _)| *c as i128)?,
        Kind::HomeDir => match u.as_str() {
            "CW" => 0,
            "CCW" => 1,
            _ => return None,
        },
        Kind::Bool => match u.as_str() {
            "ON" | "TRUE" => 1,
            "OFF" | "FALSE" => 0,
            _ => return None,
        },
        Kind::Model => u.strip_prefix("ELL")?.parse().ok()?,
        Kind::Firmware => {
            let (ma, mi) = t.split_once('.')?;
            let (ma, mi): (i128, i128) = (ma.parse().ok()?, mi.parse().ok()?);
            if !(0..16).contains(&ma) || !(0..16).contains(&mi) {
                return None;
            }
            ma << 4 | mi
        }
        _ => return None,
    };
    Some(v)
}

fn field(f: &'static Field, t: &str, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    let bad = || EncodeError::BadValue {
        field: f.name,
        text: t.to_string(),
        expected: expected(f),
    };
    let w = f.width as usize;
    match f.kind {
        Kind::Raw => {
            let hex: Vec<u8> = t.bytes().filter(|c| !c.is_ascii_whitespace()).collect();
            if hex.len() != 2 * w || !hex.iter().all(u8::is_ascii_hexdigit) {
                return Err(bad());
            }
            for pair in hex.chunks(2) {
                let s = std::str::from_utf8(pair).map_err(|_| bad())?;
                out.push(u8::from_str_radix(s, 16).map_err(|_| bad())?);
            }
            return Ok(());
        }
        Kind::Addr => {
            let a = parse_addr(t).map_err(|_| bad())?;
            out.push(b"0123456789ABCDEF"[a as usize]);
            return Ok(());
        }
        Kind::Dec => {
            if t.is_empty() || !t.bytes().all(|c| c.is_ascii_digit()) {
                return Err(bad());
            }
            if t.len() > w {
                return Err(EncodeError::OutOfRange {
                    field: f.name,
                    value: t.to_string(),
                    range: format!("up to {w} digits"),
                });
            }
            // Kept as written (a serial number's leading zeros), padded to the width.
            out.extend(std::iter::repeat_n(b'0', w - t.len()));
            out.extend_from_slice(t.as_bytes());
            return Ok(());
        }
        _ => {}
    }
    let v = named(f, t).or_else(|| parse_int(t)).ok_or_else(bad)?;
    let pulses = matches!(f.kind, Kind::Position | Kind::Signed);
    let (lo, mut hi) = range(f);
    // Positions are signed 32-bit; a positive `0x` value may also be the raw pattern.
    if pulses && !(t.starts_with("0x") || t.starts_with("0X")) {
        hi = i32::MAX as i128;
    }
    if v < lo || v > hi {
        let range = if pulses {
            format!("{}..{} pulses, or 0x0..0xFFFFFFFF", i32::MIN, i32::MAX)
        } else {
            format!("{lo}-{hi}")
        };
        return Err(EncodeError::OutOfRange {
            field: f.name,
            value: t.to_string(),
            range,
        });
    }
    let raw = if pulses {
        (v as i64 as u32) as u64
    } else {
        v as u64
    };
    let digits = format!("{raw:0w$X}");
    out.extend_from_slice(digits.as_bytes());
    Ok(())
}

/// A built frame for people: its text with CR and LF written `\r` and `\n`, or its bytes in
/// hex when it holds binary data (the current curve of `C1`/`C2`).
pub fn display(bytes: &[u8]) -> String {
    if bytes
        .iter()
        .all(|b| b.is_ascii_graphic() || matches!(b, b' ' | b'\r' | b'\n'))
    {
        String::from_utf8_lossy(bytes)
            .replace('\r', "\\r")
            .replace('\n', "\\n")
    } else {
        let hex: Vec<String> = bytes.iter().map(|b| format!("{b:02X}")).collect();
        hex.join(" ")
    }
}
