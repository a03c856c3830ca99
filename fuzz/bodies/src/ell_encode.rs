//! The Elliptec encoder (`ell::encode`): any command of the table, field values as any text
//! (numbers in and out of range, decimal, hex, negative, the names some kinds take, hex bytes,
//! junk), fields left out or given twice.
//!
//! Input: `[cmd, addr, then per field: kind, length, bytes...]`: `cmd` picks a row of
//! `ell::table::COMMANDS` (or, `addr & 0x80`, a mnemonic or name from the input, through
//! `ell::encode`'s lookup); each field's text is drawn as `kind` says. Checks: the encoder
//! refuses (with a message) or builds bytes that start with the address and the mnemonic, frame
//! as one whole frame, decode as the same command without diagnostic, read back every plain
//! decimal value given, and build the same bytes again from the values they decode to.

use aptscope_dissector::ell::encode::{display, encode, encode_cmd, EncodeError};
use aptscope_dissector::ell::table::{Cmd, Kind, COMMANDS, STATUS};
use aptscope_dissector::ell::{EllFrame, EllFramer, EllValue, Item};
use aptscope_dissector::table::Dir;

struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn byte(&mut self) -> u8 {
        let (b, rest) = self.0.split_first().map_or((0, &[][..]), |(b, r)| (*b, r));
        self.0 = rest;
        b
    }
    fn take(&mut self, n: usize) -> &[u8] {
        let (a, b) = self.0.split_at(n.min(self.0.len()));
        self.0 = b;
        a
    }
    fn i64(&mut self) -> i64 {
        let mut v = [0u8; 8];
        let b = self.take(8);
        v[..b.len()].copy_from_slice(b);
        i64::from_le_bytes(v)
    }
}

/// Text for a field, of a kind drawn from the input.
fn text_for(kind: Kind, width: usize, inp: &mut Bytes<'_>) -> String {
    let k = inp.byte();
    // Small numbers often (in range), any i64 sometimes.
    let num = |inp: &mut Bytes<'_>| {
        let v = inp.i64();
        if k & 0x80 != 0 {
            v
        } else {
            v % (1 << (4 * width.min(15)))
        }
    };
    match k % 8 {
        0 => num(inp).to_string(),
        1 => format!("0x{:X}", num(inp)),
        2 => format!("-{}", num(inp).unsigned_abs()),
        3 => {
            // A name the kind may take.
            let names: &[&str] = match kind {
                Kind::Status => &["OK", "BUSY", "busy", "MOTOR_ERROR"],
                Kind::HomeDir => &["CW", "CCW", "cw"],
                Kind::Bool => &["ON", "OFF", "true"],
                Kind::Model => &["ELL14", "ELL", "ELL99999999999"],
                Kind::Firmware => &["1.2", "15.15", "16.0", "1."],
                Kind::Addr => &["A", "f", "0x0F", "16"],
                _ => &["ON", "0x", "-", "+1", " 7 "],
            };
            let s = names[inp.byte() as usize % names.len()];
            if kind == Kind::Status && k & 0x40 != 0 {
                STATUS[inp.byte() as usize % STATUS.len()].1.to_string()
            } else {
                s.to_string()
            }
        }
        4 => {
            // Hex bytes, the width of a binary field or off by one.
            let n = (width + inp.byte() as usize % 3).saturating_sub(1);
            inp.take(n).iter().map(|b| format!("{b:02x}")).collect()
        }
        5 => "9".repeat((width + inp.byte() as usize % 3).saturating_sub(1)),
        _ => {
            let n = inp.byte() as usize % 12;
            String::from_utf8_lossy(inp.take(n)).into_owned()
        }
    }
}

/// A decoded value as text the encoder takes back.
fn text_of(v: &EllValue<'_>) -> String {
    match v {
        EllValue::U(x) => x.to_string(),
        EllValue::I(x) => x.to_string(),
        EllValue::Char(c) => c.to_string(),
        EllValue::Digits(d) => d.to_string(),
        EllValue::Raw(b) => b.iter().map(|b| format!("{b:02x}")).collect(),
    }
}

/// The body of the target: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let mut inp = Bytes(data);
    let pick = inp.byte();
    let addr_b = inp.byte();
    let addr = addr_b & 0x0f;
    let c: &'static Cmd = &COMMANDS[pick as usize % COMMANDS.len()];
    let mut owned: Vec<(String, String)> = vec![];
    for f in c.fields {
        let how = inp.byte();
        if how % 16 == 0 {
            continue; // left out
        }
        let t = text_for(f.kind, f.width as usize, &mut inp);
        if how % 16 == 1 {
            owned.push((f.name.to_string(), t.clone())); // given twice
        }
        owned.push((f.name.to_string(), t));
    }
    if addr_b & 0x40 != 0 {
        owned.push(("no_such_field".into(), "1".into()));
    }
    let values: Vec<(&str, &str)> = owned
        .iter()
        .map(|(k, v)| (k.as_str(), v.as_str()))
        .collect();
    let built = if addr_b & 0x80 != 0 {
        // By text, as `aptscope encode --proto elliptec` reads it.
        let name = String::from_utf8_lossy(inp.take(inp.0.len().min(24))).into_owned();
        let a = format!("{addr:X}");
        match encode(&a, &name, &values) {
            Err(e) => {
                check_error(&e);
                return;
            }
            Ok(b) => b,
        }
    } else {
        match encode_cmd(c, addr, &values) {
            Err(e) => {
                check_error(&e);
                return;
            }
            Ok(b) => b,
        }
    };
    let _ = display(&built);
    // The command the bytes name (by text, the lookup may have found another).
    let c = aptscope_dissector::ell::table::lookup(&built[1..3]).expect("a known mnemonic");
    assert_eq!(
        built[0], b"0123456789ABCDEF"[addr as usize],
        "address first"
    );
    assert_eq!(&built[1..3], c.code.as_bytes());
    if c.dir == Dir::DeviceToHost {
        assert!(built.ends_with(b"\r\n"), "a reply ends with CR LF");
    }
    // One whole frame.
    let mut fr = EllFramer::new();
    fr.push(&built);
    fr.finish();
    match fr.next_item() {
        Some(Item::Frame {
            offset: 0,
            bytes,
            truncated: false,
        }) => assert_eq!(bytes, &built[..], "{}", display(&built)),
        other => panic!("{} frames as {other:?}", display(&built)),
    }
    assert!(
        fr.next_item().is_none(),
        "{}: more than one record",
        display(&built)
    );
    let f = EllFrame::decode(0, &built, false).expect("decodes");
    assert!(
        f.cmd.is_some_and(|x| std::ptr::eq(x, c)),
        "{}: decoded as {:?}",
        display(&built),
        f.cmd.map(|x| x.code)
    );
    assert!(f.diags().is_empty(), "{}: {:?}", display(&built), f.diags());
    // Plain decimal values read back as given (the others: names, hex, raw patterns, are
    // covered by the round trip below).
    for (k, t) in &values {
        let fd = c.field(k).expect("a field of the command");
        let plain = t.trim().parse::<i64>().ok();
        if let (Some(want), false) = (plain, matches!(fd.kind, Kind::Dec | Kind::Raw | Kind::Addr))
        {
            let got = f.field(k).and_then(|v| v.as_i64());
            assert_eq!(got, Some(want), "{}: {k}={t}", display(&built));
        }
    }
    // Built again from what it decodes to: the same bytes.
    let back: Vec<(&str, String)> = f.fields().map(|(fd, v)| (fd.name, text_of(&v))).collect();
    let back: Vec<(&str, &str)> = back.iter().map(|(k, v)| (*k, v.as_str())).collect();
    assert_eq!(
        encode_cmd(c, addr, &back).as_deref(),
        Ok(&built[..]),
        "{}: rebuilt from {back:?}",
        display(&built)
    );
}

fn check_error(e: &EncodeError) {
    assert!(!e.to_string().is_empty());
}
