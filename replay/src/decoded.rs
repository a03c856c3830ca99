//! What a message means, owned and typed, as the field-by-field comparison ([`crate::diff`])
//! reads it: its decoded fields (name and value, in the shape `decode --json` gives `fields`)
//! and the sender's address and sub-message. Built straight from the frames of the decode
//! chain's records; JSON is only written from it (reports), never parsed back.

use aptscope_dissector::apt::{text_of, Addr, AptFrame, Value as AptValue};
use aptscope_dissector::ell::table::{status_name, Kind as EllKind};
use aptscope_dissector::ell::{curve_points, EllFrame, EllValue};
use serde_json::{Number, Value};
use std::borrow::Cow;

/// One decoded value.
#[derive(Debug, Clone, PartialEq)]
pub enum FieldVal {
    /// No value (a non-finite float, a key one side lacks).
    Null,
    /// A whole number.
    Int(i128),
    /// A finite float.
    Float(f64),
    /// Text: strings, enum labels, Elliptec status names, opaque bytes as lower-case hex.
    Text(Cow<'static, str>),
    /// A list: set flag names, array elements, curve points.
    List(Vec<FieldVal>),
    /// An object with named members (an address, a sub-message, a curve point).
    Obj(Vec<(&'static str, FieldVal)>),
}

impl FieldVal {
    fn float(x: f64) -> FieldVal {
        if x.is_finite() {
            FieldVal::Float(x)
        } else {
            FieldVal::Null
        }
    }

    fn hex(b: &[u8]) -> FieldVal {
        let mut s = String::with_capacity(b.len() * 2 + 2);
        aptscope_dissector::json::hex(&mut s, b);
        FieldVal::Text(Cow::Owned(s.trim_matches('"').to_string()))
    }

    /// The value as JSON, for reports: what `decode --json` writes, read as a JSON reader
    /// reads it (whole floats are written without a fraction and so come out as integers).
    pub fn to_json(&self) -> Value {
        match self {
            FieldVal::Null => Value::Null,
            FieldVal::Int(i) => {
                if let Ok(u) = u64::try_from(*i) {
                    Value::from(u)
                } else if let Ok(s) = i64::try_from(*i) {
                    Value::from(s)
                } else {
                    Number::from_f64(*i as f64).map_or(Value::Null, Value::Number)
                }
            }
            FieldVal::Float(x) => float_json(*x),
            FieldVal::Text(s) => Value::String(s.to_string()),
            FieldVal::List(v) => Value::Array(v.iter().map(FieldVal::to_json).collect()),
            FieldVal::Obj(m) => Value::Object(
                m.iter()
                    .map(|(k, v)| (k.to_string(), v.to_json()))
                    .collect(),
            ),
        }
    }
}

/// A float as `decode --json` writes it (`{x}`: no exponent, whole numbers without a
/// fraction) and a JSON reader then holds it.
fn float_json(x: f64) -> Value {
    const TWO_64: f64 = 18_446_744_073_709_551_616.0;
    const TWO_63: f64 = 9_223_372_036_854_775_808.0;
    let whole = x.fract() == 0.0;
    if !x.is_finite() {
        Value::Null
    } else if whole && x.is_sign_positive() && x < TWO_64 {
        Value::from(x as u64)
    } else if whole && (-TWO_63..0.0).contains(&x) {
        Value::from(x as i64)
    } else {
        // Fractions, -0 and whole numbers beyond 64 bits stay floats.
        Number::from_f64(x).map_or(Value::Null, Value::Number)
    }
}

/// The decoded fields and addressing of one message.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Decoded {
    /// The fields in frame order, with the keys `decode --json` derives beside Elliptec fields
    /// (`curve_points`, `<name>_name`, `<name>_version`, `thread`, `hw_release`).
    pub fields: Vec<(Cow<'static, str>, FieldVal)>,
    /// APT: the sender's address (`{addr, name, bay}`).
    pub src: Option<FieldVal>,
    /// Elliptec: the module address character.
    pub addr: Option<FieldVal>,
    /// APT: the sub-message (`{id, name}`).
    pub sub: Option<FieldVal>,
}

impl Decoded {
    /// The fields as one JSON object (a repeated name keeps its last value, as a JSON reader
    /// does).
    pub fn fields_json(&self) -> Value {
        Value::Object(
            self.fields
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_json()))
                .collect(),
        )
    }

    /// An APT frame's meaning: enum fields by label, flag fields as the names of the set flags.
    pub fn apt(f: &AptFrame<'_, '_>) -> Decoded {
        let t = f.table();
        let fields = f
            .fields()
            .map(|(fd, v)| {
                let label = |x: i64| fd.enumeration.and_then(|e| t.enum_def(e).label(x));
                let val = match v {
                    AptValue::U(x) => {
                        if let Some(l) = label(x as i64) {
                            FieldVal::Text(Cow::Borrowed(l))
                        } else if let Some(fl) = fd.flags {
                            FieldVal::List(
                                t.flags_def(fl)
                                    .items
                                    .iter()
                                    .filter(|(m, _)| x & m == *m)
                                    .map(|(_, l)| FieldVal::Text(Cow::Borrowed(*l)))
                                    .collect(),
                            )
                        } else {
                            FieldVal::Int(i128::from(x))
                        }
                    }
                    AptValue::I(x) => match label(x) {
                        Some(l) => FieldVal::Text(Cow::Borrowed(l)),
                        None => FieldVal::Int(i128::from(x)),
                    },
                    AptValue::F(x) => FieldVal::float(x),
                    AptValue::Str(b) => FieldVal::Text(Cow::Owned(text_of(b).into_owned())),
                    AptValue::Bytes(b) => FieldVal::hex(b),
                    AptValue::Array(..) => FieldVal::List(
                        v.elements()
                            .map(|e| match e {
                                AptValue::U(x) => FieldVal::Int(i128::from(x)),
                                AptValue::I(x) => FieldVal::Int(i128::from(x)),
                                AptValue::F(x) => FieldVal::float(x),
                                _ => FieldVal::Null,
                            })
                            .collect(),
                    ),
                };
                (Cow::Borrowed(fd.name), val)
            })
            .collect();
        Decoded {
            fields,
            src: Some(addr(f.header().src())),
            addr: None,
            sub: f.sub.map(|s| {
                FieldVal::Obj(vec![
                    ("id", FieldVal::Int(i128::from(s.id))),
                    ("name", FieldVal::Text(Cow::Borrowed(s.name))),
                ])
            }),
        }
    }

    /// An Elliptec frame's meaning: status codes by name, and the keys derived beside a field.
    pub fn ell(f: &EllFrame<'_>) -> Decoded {
        let mut fields = vec![];
        for (fd, v) in f.fields() {
            let val = match (fd.kind, v) {
                (EllKind::Status, EllValue::U(c)) => {
                    FieldVal::Text(Cow::Borrowed(status_name(c as u32)))
                }
                (_, EllValue::U(x)) => FieldVal::Int(i128::from(x)),
                (_, EllValue::I(x)) => FieldVal::Int(i128::from(x)),
                (_, EllValue::Char(c)) => FieldVal::Text(Cow::Owned(c.to_string())),
                (_, EllValue::Digits(d)) => FieldVal::Text(Cow::Owned(d.to_string())),
                (_, EllValue::Raw(b)) => FieldVal::hex(b),
            };
            fields.push((Cow::Borrowed(fd.name), val));
            match (fd.kind, v) {
                (EllKind::Raw, EllValue::Raw(b)) => {
                    let points = curve_points(b)
                        .map(|p| {
                            FieldVal::Obj(vec![
                                ("period", FieldVal::Int(i128::from(p.period))),
                                ("current", FieldVal::Int(i128::from(p.current))),
                                ("hz", FieldVal::float(p.hz().round())),
                                (
                                    "amps",
                                    FieldVal::float(aptscope_dissector::apt::round_sig(p.amps())),
                                ),
                            ])
                        })
                        .collect();
                    fields.push((Cow::Borrowed("curve_points"), FieldVal::List(points)));
                }
                (EllKind::Model, EllValue::U(x)) => fields.push((
                    Cow::Owned(format!("{}_name", fd.name)),
                    FieldVal::Text(Cow::Owned(format!("ELL{x}"))),
                )),
                (EllKind::Firmware, EllValue::U(x)) => fields.push((
                    Cow::Owned(format!("{}_version", fd.name)),
                    FieldVal::Text(Cow::Owned(format!("{}.{}", x >> 4, x & 15))),
                )),
                (EllKind::ThreadHw, EllValue::U(x)) => {
                    let thread = if x & 0x80 != 0 { "imperial" } else { "metric" };
                    fields.push((Cow::Borrowed("thread"), FieldVal::Text(thread.into())));
                    fields.push((
                        Cow::Borrowed("hw_release"),
                        FieldVal::Int(i128::from(x & 0x7F)),
                    ));
                }
                _ => {}
            }
        }
        Decoded {
            fields,
            src: None,
            addr: Some(FieldVal::Text(Cow::Owned(f.addr_char().to_string()))),
            sub: None,
        }
    }
}

/// An APT address as `decode --json` gives it: `{addr, name, bay}`.
fn addr(a: Addr) -> FieldVal {
    let name = match a {
        Addr::Host => Cow::Borrowed("host"),
        Addr::Rack => Cow::Borrowed("rack"),
        Addr::Usb => Cow::Borrowed("usb"),
        Addr::Bay(n) => Cow::Owned(format!("bay{n}")),
        Addr::Unknown(x) => Cow::Owned(format!("0x{x:02X}")),
    };
    let mut m = vec![
        ("addr", FieldVal::Int(i128::from(a.byte()))),
        ("name", FieldVal::Text(name)),
    ];
    if let Some(b) = a.bay() {
        m.push(("bay", FieldVal::Int(i128::from(b))));
    }
    FieldVal::Obj(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use aptscope_capture::open::{open, OpenOptions};
    use aptscope_capture::Event;
    use aptscope_dissector::pipeline::{Format, Renderer};
    use aptscope_dissector::record::{Decoder, Record};

    /// The comparison's view of every frame of every sample equals what `decode --json` writes
    /// (`fields`, `src`, `addr`, `sub`, as a JSON reader reads them back): the diff reads and
    /// shows the same values as when it compared the parsed NDJSON. Parsing our own lines is
    /// the oracle here, not a way of reading records.
    #[test]
    fn decoded_equals_the_ndjson_of_every_sample() {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples");
        let mut files = vec![];
        for dir in [root.to_string(), format!("{root}/sessions")] {
            let Ok(rd) = std::fs::read_dir(&dir) else {
                panic!("no samples in {dir}");
            };
            files.extend(rd.flatten().map(|e| e.path()).filter(|p| {
                p.extension()
                    .is_some_and(|x| x != "md" && x != "sh" && x != "py")
            }));
        }
        files.sort();
        let (mut apt, mut ell, mut opened) = (0usize, 0usize, 0usize);
        for path in &files {
            let name = path.to_string_lossy().to_string();
            // Formats `open` does not read (or that need options) are not the point here.
            let Ok((mut reader, _)) = open(&name, OpenOptions::default()) else {
                continue;
            };
            opened += 1;
            let mut dec = Decoder::new(None);
            let mut json = Renderer::new(Format::Json);
            let mut bad: Vec<String> = vec![];
            let mut emit = |r: &Record<'_>| -> Result<(), ()> {
                let d = match r {
                    Record::Apt(a) => {
                        apt += 1;
                        Decoded::apt(a.frame)
                    }
                    Record::Ell(e) => {
                        ell += 1;
                        Decoded::ell(e.frame)
                    }
                    _ => return Ok(()),
                };
                let line = json.line(r);
                let v: Value = serde_json::from_str(line).unwrap_or(Value::Null);
                let opt = |x: &Option<FieldVal>| x.as_ref().map_or(Value::Null, FieldVal::to_json);
                let got = [d.fields_json(), opt(&d.src), opt(&d.addr), opt(&d.sub)];
                let want = ["fields", "src", "addr", "sub"]
                    .map(|k| v.get(k).cloned().unwrap_or(Value::Null));
                if got != want && bad.len() < 3 {
                    bad.push(format!("{line}\n  got {got:?}"));
                }
                Ok(())
            };
            while let Some(ev) = reader.next_event() {
                let _ = match ev {
                    Event::Chunk(ch) => dec.push(ch.ctx(), ch.bytes, &mut emit),
                    Event::Diag(d) => dec.file_diag(d.offset, d.kind(), &d.msg(), &mut emit),
                    Event::Stream(_) => Ok(()),
                };
            }
            let _ = dec.finish(&mut emit);
            assert!(bad.is_empty(), "{name}:\n{}", bad.join("\n"));
        }
        assert!(opened >= 10, "only {opened} samples opened");
        assert!(apt > 500 && ell > 20, "{apt} APT and {ell} Elliptec frames");
    }

    #[test]
    fn floats_read_back_as_written() {
        assert_eq!(float_json(2.0).to_string(), "2");
        assert_eq!(float_json(-3.0).to_string(), "-3");
        assert_eq!(float_json(2.5).to_string(), "2.5");
        assert!(float_json(2.0).is_u64());
        assert!(float_json(-0.0).is_f64());
        assert!(float_json(1e20).is_f64());
        assert_eq!(float_json(f64::NAN), Value::Null);
        assert_eq!(FieldVal::float(f64::INFINITY), FieldVal::Null);
    }
}
