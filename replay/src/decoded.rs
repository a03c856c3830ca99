//! What a message means, owned and typed, as the field-by-field comparison ([`crate::diff`])
//! reads it: its decoded fields (name and value, in the shape `decode --json` gives `fields`)
//! and the sender's address and sub-message. Built straight from the frames of the decode
//! chain's records; JSON is only written from it (reports), never parsed back.

use aptscope_dissector::apt::AptFrame;
use aptscope_dissector::ell::EllFrame;
use aptscope_dissector::json::{self, Sink};
use serde_json::{Number, Value};
use std::borrow::Cow;

/// One decoded value.
#[derive(Debug, Clone, PartialEq)]
pub enum FieldVal {
    /// No value (a non-finite float, a key one side lacks).
    Null,
    /// A boolean.
    Bool(bool),
    /// A whole number.
    Int(i128),
    /// A finite float.
    Float(f64),
    /// Text: strings, enum labels, Elliptec status names, opaque bytes as lower-case hex.
    Text(Cow<'static, str>),
    /// A list: set flag names, array elements, curve points.
    List(Vec<FieldVal>),
    /// An object with named members (an address, a sub-message, a curve point).
    Obj(Vec<(Cow<'static, str>, FieldVal)>),
}

impl FieldVal {
    /// The value as JSON, for reports: what `decode --json` writes, read as a JSON reader
    /// reads it (whole floats are written without a fraction and so come out as integers).
    pub fn to_json(&self) -> Value {
        match self {
            FieldVal::Null => Value::Null,
            FieldVal::Bool(b) => Value::Bool(*b),
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
    /// ([`aptscope_dissector::shape::ell_derived`]).
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

    /// An APT frame's meaning: its `fields`, `src` and `sub` as `decode --json` gives them
    /// (built by the same writer, [`json`]).
    pub fn apt(f: &AptFrame<'_, '_>) -> Decoded {
        let fields = match Build::of(|b| json::apt_fields(b, f)) {
            FieldVal::Obj(m) => m,
            _ => vec![],
        };
        Decoded {
            fields,
            src: Some(Build::of(|b| json::addr(b, f.header().src()))),
            addr: None,
            sub: f.sub.map(|s| Build::of(|b| json::sub(b, s))),
        }
    }

    /// An Elliptec frame's meaning: its `fields` (with the keys derived beside a field) and
    /// the module address, as `decode --json` gives them.
    pub fn ell(f: &EllFrame<'_>) -> Decoded {
        let fields = match Build::of(|b| json::ell_fields(b, f)) {
            FieldVal::Obj(m) => m,
            _ => vec![],
        };
        Decoded {
            fields,
            src: None,
            addr: Some(FieldVal::Text(Cow::Owned(f.addr_char().to_string()))),
            sub: None,
        }
    }
}

/// Builds owned [`FieldVal`]s from the record shape's writer ([`json`], which writes what
/// [`aptscope_dissector::shape`] describes): the one spelling of the shape, read back here.
#[derive(Default)]
struct Build {
    /// Open objects and lists, innermost last, each with the key it goes under.
    stack: Vec<(Option<Cow<'static, str>>, FieldVal)>,
    /// The key of the next member.
    key: Option<Cow<'static, str>>,
    /// The value written, once complete.
    top: Option<FieldVal>,
}

impl Build {
    /// The one value `write` writes.
    fn of(write: impl FnOnce(&mut Build)) -> FieldVal {
        let mut b = Build::default();
        write(&mut b);
        b.top.unwrap_or(FieldVal::Null)
    }

    fn put(&mut self, v: FieldVal) {
        match self.stack.last_mut() {
            None => self.top = Some(v),
            Some((_, FieldVal::Obj(m))) => m.push((self.key.take().unwrap_or_default(), v)),
            Some((_, FieldVal::List(l))) => l.push(v),
            Some(_) => {}
        }
    }

    fn close(&mut self) {
        if let Some((k, v)) = self.stack.pop() {
            self.key = k;
            self.put(v);
        }
    }
}

impl Sink for Build {
    fn begin_obj(&mut self) {
        self.stack.push((self.key.take(), FieldVal::Obj(vec![])));
    }
    fn end_obj(&mut self) {
        self.close();
    }
    fn begin_list(&mut self) {
        self.stack.push((self.key.take(), FieldVal::List(vec![])));
    }
    fn end_list(&mut self) {
        self.close();
    }
    fn key(&mut self, k: &str) {
        self.key = Some(Cow::Owned(k.to_string()));
    }
    fn key_lit(&mut self, k: &json::Lit) {
        self.key = Some(Cow::Borrowed(k.name));
    }
    fn str(&mut self, s: &str) {
        self.put(FieldVal::Text(Cow::Owned(s.to_string())));
    }
    fn hex(&mut self, b: &[u8]) {
        let mut s = String::with_capacity(b.len() * 2);
        json::hex_digits(&mut s, b);
        self.put(FieldVal::Text(Cow::Owned(s)));
    }
    fn uint(&mut self, x: u64) {
        self.put(FieldVal::Int(i128::from(x)));
    }
    fn int(&mut self, x: i64) {
        self.put(FieldVal::Int(i128::from(x)));
    }
    fn float(&mut self, x: f64) {
        self.put(if x.is_finite() {
            FieldVal::Float(x)
        } else {
            FieldVal::Null
        });
    }
    fn fixed(&mut self, x: f64, decimals: usize) {
        self.float(format!("{x:.decimals$}").parse().unwrap_or(x));
    }
    fn bool(&mut self, b: bool) {
        self.put(FieldVal::Bool(b));
    }
    fn null(&mut self) {
        self.put(FieldVal::Null);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aptscope_capture::open::{open, OpenOptions};
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
                let _ = ev.feed(&mut dec, &mut emit);
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
        assert_eq!(Build::of(|b| b.float(f64::INFINITY)), FieldVal::Null);
    }
}
