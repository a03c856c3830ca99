//! Checking the spec's example byte strings (the `ex`/`exbad` lines of the table) against the
//! framer and decoder. Used by the crate's tests and the `checktable` example.

use crate::apt::{text_of, AptFrame, AptFramer, Item, Value};
use crate::table::{example_bytes, parse_int, Example, FlagsDef, Table};

/// What an example belongs to.
#[derive(Debug, Clone, Copy)]
pub enum Owner<'t> {
    /// A message (`ex` under `msg`).
    Msg(&'t crate::table::MsgDef),
    /// A sub-message (`ex` under `sub`).
    Sub(&'t crate::table::SubDef),
}

/// Every example in the table with its owner.
pub fn all(table: &Table) -> Vec<(Owner<'_>, &Example)> {
    let mut v: Vec<(Owner<'_>, &Example)> = vec![];
    for m in table.msgs() {
        v.extend(m.examples.iter().map(|e| (Owner::Msg(m), e)));
    }
    for s in table.subs() {
        v.extend(s.examples.iter().map(|e| (Owner::Sub(s), e)));
    }
    v
}

fn flags_mask(defs: Option<&FlagsDef>, s: &str) -> Option<u64> {
    let mut acc = 0u64;
    for part in s.split('|') {
        let p = part.trim();
        acc |= match defs.and_then(|d| d.mask(p)) {
            Some(m) => m,
            None => parse_int(p)? as u64,
        };
    }
    Some(acc)
}

fn value_matches(table: &Table, f: &crate::table::Field, v: &Value<'_>, want: &str) -> bool {
    match v {
        Value::U(_) | Value::I(_) => {
            let got = v.as_i64().unwrap_or(i64::MIN);
            if let Some(w) = parse_int(want) {
                return w == got || (w as u32 as i64) == got;
            }
            if let Some(e) = f.enumeration {
                if table.enum_def(e).value(want) == Some(got) {
                    return true;
                }
            }
            if let Some(fl) = f.flags {
                return flags_mask(Some(table.flags_def(fl)), want) == Some(got as u64);
            }
            if let Ok(x) = want.parse::<f64>() {
                return x == got as f64;
            }
            false
        }
        Value::F(x) => want
            .parse::<f64>()
            .is_ok_and(|w| (w - x).abs() <= 1e-4 * w.abs().max(1e-3)),
        Value::Str(b) => text_of(b).trim() == want.trim(),
        Value::Bytes(b) => {
            let h: String = b.iter().map(|x| format!("{x:02x}")).collect();
            h == want.to_ascii_lowercase().replace([' ', ','], "")
        }
        Value::Array(..) => {
            let got: Vec<String> = v
                .elements()
                .map(|e| e.as_f64().map(|x| x.to_string()).unwrap_or_default())
                .collect();
            let w: Vec<String> = want
                .split(',')
                .map(|x| {
                    x.trim()
                        .parse::<f64>()
                        .map(|x| x.to_string())
                        .unwrap_or_default()
                })
                .collect();
            got == w
        }
    }
}

/// Check one example: it must frame as exactly one complete frame of its owner and decode to
/// the stated values with no diagnostic. An `exbad` example must fail that.
pub fn check(table: &Table, owner: Owner<'_>, ex: &Example) -> Result<(), String> {
    let result = check_good(table, owner, ex);
    match (ex.bad_reason, result) {
        (None, r) => r,
        (Some(_), Err(_)) => Ok(()),
        (Some(reason), Ok(())) => Err(format!(
            "marked exbad ({reason}) but it decodes cleanly: if the bytes contradict the text, state the text's values after a second `;` (exbad HEX ; reason ; field=value …, see FORMAT.md); if the bytes are right, make it an `ex` line"
        )),
    }
}

fn check_good(table: &Table, owner: Owner<'_>, ex: &Example) -> Result<(), String> {
    let bytes = example_bytes(ex.hex)?;
    let mut fr = AptFramer::new(table);
    fr.push(&bytes);
    fr.finish();
    let mut frames = vec![];
    while let Some(it) = fr.next_item() {
        match it {
            Item::Frame {
                offset,
                bytes,
                truncated,
            } => frames.push((offset, bytes.to_vec(), truncated)),
            Item::Garbage {
                offset,
                bytes,
                kind,
            } => {
                return Err(format!(
                    "{} byte(s) at offset {offset} do not frame ({kind:?})",
                    bytes.len()
                ))
            }
        }
    }
    let [(off, fb, trunc)] = frames.as_slice() else {
        return Err(format!("frames as {} frames, not 1", frames.len()));
    };
    let f = AptFrame::decode(table, *off, fb, *trunc).ok_or("not a frame")?;
    if let Some(d) = f.diags().next() {
        return Err(format!("diagnostic: {d}"));
    }
    match owner {
        Owner::Msg(m) if f.msg.map(|x| x.id) != Some(m.id) => {
            return Err(format!("decodes as {:?}, not {}", f.name(), m.name))
        }
        Owner::Sub(s) if f.sub.map(|x| (x.group, x.id)) != Some((s.group, s.id)) => {
            return Err(format!(
                "decodes as sub {:?} of {:?}, not {}",
                f.sub.map(|x| x.name),
                f.name(),
                s.name
            ))
        }
        _ => {}
    }
    let h = f.header();
    for (k, want) in &ex.checks {
        let ok = match *k {
            // The spec writes the destination with or without the 0x80 data flag.
            "dst" => parse_int(want).is_some_and(|w| w & 0x7F == h.dst_byte() as i64),
            "src" => parse_int(want) == Some(h.src_byte() as i64),
            _ => {
                let Some((fd, v)) = f.field(k) else {
                    return Err(format!("no field `{k}` in the decoded form"));
                };
                value_matches(table, fd, &v, want)
            }
        };
        if !ok {
            let got = match *k {
                "dst" => format!("0x{:02X}", h.dst_byte()),
                "src" => format!("0x{:02X}", h.src_byte()),
                _ => f
                    .field(k)
                    .map(|(_, v)| format!("{v:?}"))
                    .unwrap_or_default(),
            };
            return Err(format!("{k}: spec says {want}, decoded {got}"));
        }
    }
    Ok(())
}
