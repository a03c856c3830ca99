//! The table-driven encoder and decoder: encode arbitrary values into any form of any message
//! (or sub-message), then decode and compare.
//!
//! Input: `[form_hi, form_lo, dst, src, values...]`: the form is picked from every encodable
//! (message, form, sub-message) of the table; each field takes the next bytes of the input as a
//! value of a kind chosen by one byte (an integer, a float, text, bytes, a list — matching the
//! field's type or not, in range or not, text through `FieldValue::from_text` too). Checks: the
//! encoder either refuses or builds a frame of a length the form's rules give
//! (`Form::encoded_len`, `Form::accepts_len`: open forms hold as many elements as given, up to
//! the message's `maxlen=`) that frames as one frame,
//! decodes as the same message and form, and gives back every value it was given (as the
//! encoder documents: integers exactly, f32 rounding, u32 fields also from negative i32 masks,
//! text up to its first NUL, fields not given read 0).

use aptscope_dissector::apt::{
    encode, read_prim, AptFrame, AptFramer, FieldValue, Item, Value, HEADER_LEN,
};
use aptscope_dissector::synth::all_forms;
use aptscope_dissector::table::{Field, Form, MsgDef, Prim, Ty};
use aptscope_dissector::Table;
use std::sync::OnceLock;

type Forms = Vec<(&'static MsgDef, &'static Form, Option<u16>)>;

fn forms() -> &'static Forms {
    static F: OnceLock<Forms> = OnceLock::new();
    F.get_or_init(|| all_forms(Table::global()))
}

struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn take(&mut self, n: usize) -> Vec<u8> {
        let k = n.min(self.0.len());
        let (a, b) = self.0.split_at(k);
        self.0 = b;
        let mut v = a.to_vec();
        v.resize(n, 0);
        v
    }
    fn byte(&mut self) -> u8 {
        self.take(1)[0]
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take(8).try_into().unwrap())
    }
    fn num(&mut self, p: Prim) -> f64 {
        match self.byte() % 4 {
            // Raw bits of the field's own width, read as the decoder would.
            0 => read_prim(p, &self.take(8)).as_f64().unwrap_or(0.0),
            1 => self.u64() as i64 as f64,
            2 => f64::from_bits(self.u64()),
            _ => (self.byte() as i8) as f64,
        }
    }
}

/// The value an encoded number reads back as, per the encoder's rules (`None`: refused).
fn expect_prim(p: Prim, v: f64) -> Option<Value<'static>> {
    if p == Prim::F32 {
        return Some(Value::F((v as f32) as f64));
    }
    if v.fract() != 0.0 {
        return None;
    }
    let x = v as i64;
    Some(match p {
        Prim::U8 => Value::U(u8::try_from(x).ok()? as u64),
        Prim::I8 => Value::I(i8::try_from(x).ok()? as i64),
        Prim::U16 => Value::U(u16::try_from(x).ok()? as u64),
        Prim::I16 => Value::I(i16::try_from(x).ok()? as i64),
        Prim::U32 => Value::U(
            u32::try_from(x)
                .or_else(|_| i32::try_from(x).map(|y| y as u32))
                .ok()? as u64,
        ),
        Prim::I32 => Value::I(i32::try_from(x).ok()? as i64),
        Prim::F32 => unreachable!(),
    })
}

fn same_num(got: &Value<'_>, want: &Value<'_>) -> bool {
    match (got, want) {
        (Value::F(a), Value::F(b)) => a == b || (a.is_nan() && b.is_nan()),
        _ => got == want,
    }
}

/// A value for a field, of a kind drawn from the input.
fn value_for(t: &Table, f: &Field, inp: &mut Bytes<'_>) -> FieldValue {
    let kind = inp.byte();
    match (kind % 8, f.ty) {
        (0..=2, Ty::Prim(p)) | (0, Ty::Array(p, _)) => {
            let v = inp.num(p);
            if kind & 0x80 != 0 && v.fract() == 0.0 && v.abs() < 9e15 {
                FieldValue::Int(v as i64)
            } else {
                FieldValue::Float(v)
            }
        }
        (3, _) => {
            // Through the text parser, as `aptscope encode` reads values.
            let n = (inp.byte() % 24) as usize;
            let s = String::from_utf8_lossy(&inp.take(n)).into_owned();
            FieldValue::from_text(t, f, &s).unwrap_or(FieldValue::Int(0))
        }
        (4, Ty::Str(n)) | (4, Ty::Bytes(n) | Ty::Pad(n)) | (5, Ty::Bytes(n) | Ty::Pad(n)) => {
            let len = (n as usize + inp.byte() as usize % 3).saturating_sub(1);
            let b = inp.take(len);
            if matches!(f.ty, Ty::Str(_)) {
                FieldValue::Text(String::from_utf8_lossy(&b).into_owned())
            } else {
                FieldValue::Bytes(b)
            }
        }
        (5, Ty::Str(n)) => FieldValue::Text(
            std::iter::repeat_n(
                'A',
                (n as usize + inp.byte() as usize % 3).saturating_sub(1),
            )
            .collect(),
        ),
        // An open array (`TYPE[*]`) takes any number of elements, past its message's largest
        // packet too (MOT_SET_MOVESYNCHARRAY: 1024 i32 with `maxlen=4104`).
        (6, Ty::Array(p, 0)) => {
            let k = usize::from(u16::from_le_bytes([inp.byte(), inp.byte()])) % 1100;
            FieldValue::List((0..k).map(|_| inp.num(p)).collect())
        }
        (6, Ty::Array(p, n)) => {
            let k = inp.byte() as usize % (n as usize + 2);
            FieldValue::List((0..k).map(|_| inp.num(p)).collect())
        }
        (7, _) => FieldValue::Text(String::from_utf8_lossy(&inp.take(3)).into_owned()),
        _ => FieldValue::Int(inp.byte() as i64),
    }
}

/// Check a decoded field against the value given, per the encoder's rules; `false` when the
/// encoder should have refused the value.
fn check(f: &Field, got: Value<'_>, given: &FieldValue) -> bool {
    match (f.ty, given) {
        (Ty::Prim(p), FieldValue::Int(i)) => match expect_prim(p, *i as f64) {
            Some(w) => {
                assert!(same_num(&got, &w), "{}: gave {i}, read {got:?}", f.name);
                true
            }
            None => false,
        },
        (Ty::Prim(p), FieldValue::Float(x)) => match expect_prim(p, *x) {
            Some(w) => {
                assert!(same_num(&got, &w), "{}: gave {x}, read {got:?}", f.name);
                true
            }
            None => false,
        },
        (Ty::Str(n), FieldValue::Text(s)) => {
            if s.len() > n as usize {
                return false;
            }
            let Value::Str(b) = got else {
                panic!("{}: not text: {got:?}", f.name)
            };
            assert_eq!(&b[..s.len()], s.as_bytes(), "{}", f.name);
            assert!(b[s.len()..].iter().all(|&c| c == 0), "{}: padding", f.name);
            true
        }
        (Ty::Bytes(n) | Ty::Pad(n), FieldValue::Bytes(v)) => {
            if v.len() != n as usize {
                return false;
            }
            let (Value::Bytes(b) | Value::Array(_, b) | Value::Str(b)) = got else {
                panic!("{}: not bytes: {got:?}", f.name)
            };
            assert_eq!(b, &v[..], "{}", f.name);
            true
        }
        (Ty::Array(p, n), FieldValue::List(xs)) => {
            // A closed array holds `n` elements (the ones not given read 0), an open one as
            // many as given.
            let want_len = if n == 0 { xs.len() } else { n as usize };
            if xs.len() > want_len {
                return false;
            }
            let elems: Vec<Value<'_>> = got.elements().collect();
            assert_eq!(elems.len(), want_len, "{}", f.name);
            for (i, e) in elems.iter().enumerate() {
                let want = match xs.get(i) {
                    Some(x) => match expect_prim(p, *x) {
                        Some(w) => w,
                        None => return false,
                    },
                    None => expect_prim(p, 0.0).unwrap(),
                };
                assert!(
                    same_num(e, &want),
                    "{}[{i}]: read {e:?}, want {want:?}",
                    f.name
                );
            }
            true
        }
        _ => false,
    }
}

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let t = Table::global();
    let all = forms();
    let mut inp = Bytes(data);
    let pick = u16::from_be_bytes([inp.byte(), inp.byte()]) as usize % all.len();
    let (m, form, sub) = all[pick];
    let (dst, src) = (inp.byte(), inp.byte());
    let mut vals: Vec<(&str, FieldValue)> = vec![];
    // A sub-message's data form carries its sub id (as `aptscope encode --sub` puts it).
    if let Some(id) = sub {
        vals.push(("sub_id", FieldValue::Int(id as i64)));
    }
    for f in &form.fields {
        if inp.0.is_empty() {
            break;
        }
        if f.name != "sub_id" || sub.is_none() {
            vals.push((f.name, value_for(t, f, &mut inp)));
        }
    }
    let Ok(bytes) = encode(form, &vals, m.id, dst, src) else {
        return;
    };
    // The form's length rules, as the dissector states them: the length `encoded_len` gives
    // for the elements of the open array (if any), one the form (so the decoder) accepts.
    let elems = vals.iter().find_map(|(k, v)| match (v, form.open_elem()) {
        (FieldValue::List(xs), Some(_)) if form.fields.last().is_some_and(|f| f.name == *k) => {
            Some(xs.len())
        }
        _ => None,
    });
    let data_len = bytes.len() - HEADER_LEN;
    assert_eq!(
        form.encoded_len(elems.unwrap_or(0)),
        Some(data_len),
        "{} {}: frame length",
        m.name,
        form.label()
    );
    let flagged = bytes[4] & 0x80 != 0;
    assert_eq!(flagged, data_len > 0, "{}: data flag", m.name);
    assert!(
        form.accepts_len(flagged, data_len),
        "{} {}: {data_len} data bytes, a length the form does not accept",
        m.name,
        form.label()
    );
    let f = AptFrame::decode(t, 0, &bytes, false).expect("a frame");
    assert_eq!(f.msg.map(|x| x.id), Some(m.id), "{}", m.name);
    assert!(
        f.form.is_some_and(|x| std::ptr::eq(x, form)),
        "{} {:?} (sub {sub:?}): decoded as another form {:?}",
        m.name,
        form.kind,
        f.form.map(|x| x.kind)
    );
    for (name, given) in &vals {
        let fd = form.fields.iter().find(|x| x.name == *name).unwrap();
        let got = f.value(fd).expect("the field is in the frame");
        assert!(
            check(fd, got, given),
            "{}: the encoder took {name}={given:?}, which does not fit {:?}",
            m.name,
            fd.ty
        );
    }
    // Fields not given read 0.
    for fd in form
        .fields
        .iter()
        .filter(|x| !vals.iter().any(|(n, _)| n == &x.name))
    {
        let got = f.value(fd).unwrap();
        let zero = match got {
            Value::U(v) => v == 0,
            Value::I(v) => v == 0,
            Value::F(v) => v == 0.0,
            Value::Str(b) | Value::Bytes(b) | Value::Array(_, b) => b.iter().all(|&c| c == 0),
        };
        assert!(zero, "{}: {} not given but reads {got:?}", m.name, fd.name);
    }
    // A frame with known addresses frames as one frame, whole.
    let known = |a: u8| matches!(a, 0x01 | 0x11 | 0x21..=0x2A | 0x50);
    if known(dst & 0x7f) && known(src) {
        let mut fr = AptFramer::new(t);
        fr.push(&bytes);
        fr.finish();
        match fr.next_item() {
            Some(Item::Frame {
                offset: 0,
                bytes: b,
                truncated: false,
            }) => assert_eq!(b, &bytes[..]),
            other => panic!("{}: {bytes:02x?} frames as {other:?}", m.name),
        }
    }
}
