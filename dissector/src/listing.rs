//! The message table as people read it: `aptscope messages` (one line a message) and
//! `aptscope messages NAME|ID` (a man page for one message: fields, forms, revisions, devices,
//! replies, the spec's examples decoded).

use crate::apt::{fmt_value, AptFrame};
use crate::suggest::nearest;
use crate::table::{example_bytes, Example, Form, FormKind, Loc, MsgDef, SubDef, Table, Ty};
use std::fmt::Write;

/// What a query names.
#[derive(Debug, Clone, Copy)]
pub enum Entry<'t> {
    /// A message.
    Msg(&'t MsgDef),
    /// A sub-message of a PARAMS group.
    Sub(&'t SubDef),
}

/// Find what `query` names: a message name (`MGMSG_` prefix and case optional), an id (`0x0453`
/// or decimal), or a sub-message name (`SETPOINT`, or `la:SETPOINT` for one group). Several
/// sub-messages of different groups may share a name. An unknown name is an error that lists the
/// nearest known ones.
pub fn lookup<'t>(t: &'t Table, query: &str) -> Result<Vec<Entry<'t>>, String> {
    let q = query.trim();
    let id = match q.strip_prefix("0x").or_else(|| q.strip_prefix("0X")) {
        Some(h) => u16::from_str_radix(h, 16).ok(),
        None if q.bytes().all(|c| c.is_ascii_digit()) && !q.is_empty() => q.parse().ok(),
        None => None,
    };
    if let Some(id) = id {
        return t
            .msg(id)
            .map(|m| vec![Entry::Msg(m)])
            .ok_or_else(|| format!("no message has id 0x{id:04X}"));
    }
    let upper = q.to_ascii_uppercase();
    let name = upper.strip_prefix("MGMSG_").unwrap_or(&upper);
    if let Some(m) = t.msg_by_name(name) {
        return Ok(vec![Entry::Msg(m)]);
    }
    let (group, sub) = match name.split_once(':') {
        Some((g, s)) => (Some(g.to_ascii_lowercase()), s),
        None => (None, name),
    };
    let subs: Vec<Entry<'t>> = t
        .subs()
        .iter()
        .filter(|s| s.name == sub && group.as_deref().is_none_or(|g| g == s.group))
        .map(Entry::Sub)
        .collect();
    if !subs.is_empty() {
        return Ok(subs);
    }
    let names = t
        .msgs()
        .iter()
        .map(|m| m.name)
        .chain(t.subs().iter().map(|s| s.name));
    let near = nearest(name, names, 5);
    Err(if near.is_empty() {
        format!("unknown message `{query}` (`aptscope messages` lists them)")
    } else {
        format!(
            "unknown message `{query}`; did you mean {}?",
            near.join(", ")
        )
    })
}

fn field_rows(t: &Table, form: &Form, out: &mut String) {
    for f in &form.fields {
        if matches!(f.ty, Ty::Pad(_)) {
            let _ = writeln!(
                out,
                "      byte {:<3} (reserved, {} bytes)",
                f.loc.frame_offset(),
                f.ty.width()
            );
            continue;
        }
        let at = match f.loc {
            Loc::P1 => "param1".to_string(),
            Loc::P2 => "param2".to_string(),
            Loc::Data(_) => format!("byte {}", f.loc.frame_offset()),
        };
        let _ = write!(out, "      {at:<8} {:<24} {:<8}", f.name, f.ty.name());
        if let Some(u) = f.unit {
            let _ = write!(out, " [{u}]");
        }
        if let Some(s) = f.scale {
            let _ = write!(out, " ×{s}");
        }
        if let Some(e) = f.enumeration {
            let e = t.enum_def(e);
            let items: Vec<String> = e.items.iter().map(|(v, l)| format!("{v}={l}")).collect();
            let _ = write!(out, " enum {}: {}", e.name, items.join(" "));
        }
        if let Some(fl) = f.flags {
            let fl = t.flags_def(fl);
            let items: Vec<String> = fl
                .items
                .iter()
                .map(|(m, l)| format!("0x{m:X}={l}"))
                .collect();
            let _ = write!(out, " flags {}: {}", fl.name, items.join(" "));
        }
        out.push('\n');
    }
}

fn forms(t: &Table, forms: &[Form], out: &mut String) {
    out.push_str("  forms:\n");
    for f in forms {
        let size = match f.kind {
            FormKind::Header => "6 bytes, header only".to_string(),
            FormKind::Data(n) => format!("6 + {n} bytes"),
            FormKind::Sub => "6 + a sub-message's data packet".to_string(),
            FormKind::Open(n) => format!(
                "6 + {n} bytes, then {} bytes per element of its last field",
                f.open_elem().unwrap_or(0)
            ),
        };
        let _ = write!(out, "    [{}] {size}", f.label());
        if !f.note.is_empty() {
            let _ = write!(out, ": {}", f.note);
        }
        out.push('\n');
        field_rows(t, f, out);
    }
}

fn examples(t: &Table, exs: &[Example], out: &mut String) {
    if exs.is_empty() {
        return;
    }
    out.push_str("  spec examples:\n");
    for ex in exs {
        let bytes = example_bytes(ex.hex).unwrap_or_default();
        let hex: Vec<String> = bytes.iter().map(|b| format!("{b:02X}")).collect();
        let _ = writeln!(out, "    {}", hex.join(" "));
        if let Some(r) = ex.bad_reason {
            let _ = writeln!(out, "      wrong as printed: {r}");
            continue;
        }
        if let Some(f) = AptFrame::decode(t, 0, &bytes, false) {
            let mut vals = String::new();
            for (fd, v) in f.fields() {
                let _ = write!(vals, " {}=", fd.name);
                fmt_value(t, fd, &v, &mut vals);
            }
            let _ = writeln!(
                out,
                "      {} → {}:{}",
                f.src().name(),
                f.dst().name(),
                vals
            );
        }
    }
}

/// The man page of one entry, as text.
pub fn man_page(t: &Table, e: Entry<'_>, out: &mut String) {
    match e {
        Entry::Msg(m) => {
            let _ = writeln!(out, "{}  0x{:04X}  ({})", m.name, m.id, m.dir.as_str());
            if !m.doc.is_empty() {
                let _ = writeln!(out, "  {}", m.doc);
            }
            let revs: Vec<String> = m
                .revs
                .names()
                .iter()
                .map(|r| match *r {
                    "23" => "Issue 23 (2018)".to_string(),
                    r => format!("{r} revision"),
                })
                .collect();
            let _ = writeln!(out, "  defined in: {}", revs.join(", "));
            let replies: Vec<&str> = t.replies_of(m).iter().map(|r| r.name).collect();
            if !replies.is_empty() {
                let _ = writeln!(out, "  answered by: {}", replies.join(", "));
            }
            let asks: Vec<&str> = t
                .msgs()
                .iter()
                .filter(|q| t.reply_ids(q).contains(&m.id))
                .map(|q| q.name)
                .collect();
            if !asks.is_empty() {
                let _ = writeln!(out, "  answers: {}", asks.join(", "));
            }
            let models = t.models_of(m);
            if models.is_empty() {
                out.push_str("  devices: (no device list of the spec names it)\n");
            } else {
                let _ = writeln!(out, "  devices: {}", models.join(" "));
            }
            forms(t, &m.forms, out);
            if let Some(g) = m.subs {
                let subs: Vec<String> = t
                    .subs()
                    .iter()
                    .filter(|s| s.group == g)
                    .map(|s| format!("0x{:02X} {}", s.id, s.name))
                    .collect();
                let _ = writeln!(out, "  sub-messages ({g}): {}", subs.join(", "));
            }
            examples(t, &m.examples, out);
            let _ = writeln!(out, "  table: dissector/msgs/{}:{}", m.file, m.line);
        }
        Entry::Sub(s) => {
            let users: Vec<&str> = t
                .msgs()
                .iter()
                .filter(|m| m.subs == Some(s.group))
                .map(|m| m.name)
                .collect();
            let _ = writeln!(
                out,
                "{}  sub-message 0x{:04X} of group {}",
                s.name, s.id, s.group
            );
            if !s.doc.is_empty() {
                let _ = writeln!(out, "  {}", s.doc);
            }
            let _ = writeln!(out, "  carried by: {}", users.join(", "));
            forms(t, &s.forms, out);
            examples(t, &s.examples, out);
            let _ = writeln!(out, "  table: dissector/msgs/{}:{}", s.file, s.line);
        }
    }
}

/// `aptscope messages NAME|ID`: the page of each entry `query` names (see [`lookup`]), as
/// text ([`man_page`]) or one NDJSON object each, without trailing blank lines.
pub fn pages(t: &Table, query: &str, as_json: bool) -> Result<Vec<String>, String> {
    let mut pages = vec![];
    for e in lookup(t, query)? {
        let mut s = String::new();
        match (as_json, e) {
            (true, Entry::Msg(m)) => crate::json::msg_def(&mut s, t, m),
            (true, Entry::Sub(x)) => crate::json::sub_def(&mut s, t, x),
            (false, e) => man_page(t, e, &mut s),
        }
        pages.push(s.trim_end().to_string());
    }
    Ok(pages)
}

/// `aptscope messages --json`: one NDJSON object per message, then one per sub-message.
pub fn json_lines(t: &Table) -> Vec<String> {
    let msgs = t.msgs().iter().map(|m| {
        let mut s = String::new();
        crate::json::msg_def(&mut s, t, m);
        s
    });
    let subs = t.subs().iter().map(|x| {
        let mut s = String::new();
        crate::json::sub_def(&mut s, t, x);
        s
    });
    msgs.chain(subs).collect()
}

/// `aptscope messages`: one line per message by id (`0x0443  MOT_MOVE_HOME  …`: direction,
/// forms, replies, a 2025 mark), with `verbose` its description, devices and each form's
/// fields; then one line per sub-message.
pub fn text(t: &Table, verbose: bool) -> String {
    let mut out = String::new();
    let mut msgs: Vec<&MsgDef> = t.msgs().iter().collect();
    msgs.sort_by_key(|m| m.id);
    for m in msgs {
        let forms: Vec<String> = m.forms.iter().map(Form::label).collect();
        let replies: Vec<&str> = t.replies_of(m).iter().map(|r| r.name).collect();
        let reply = if replies.is_empty() {
            String::new()
        } else {
            format!(" → {}", replies.join(","))
        };
        let rev = if m.revs == crate::table::Revs::REV_2025 {
            "  [2025]"
        } else {
            ""
        };
        let _ = writeln!(
            out,
            "0x{:04X}  {:<40} {:<4}  {:<10}{reply}{rev}",
            m.id,
            m.name,
            m.dir.as_str(),
            forms.join("|")
        );
        if verbose {
            if !m.doc.is_empty() {
                let _ = writeln!(out, "        {}", m.doc);
            }
            let models = t.models_of(m);
            if !models.is_empty() {
                let _ = writeln!(out, "        devices: {}", models.join(" "));
            }
            for f in &m.forms {
                let fields: Vec<String> = f
                    .fields
                    .iter()
                    .map(|x| format!("{}:{}", x.name, x.ty.name()))
                    .collect();
                let _ = writeln!(out, "        [{}] {}", f.label(), fields.join(" "));
            }
        }
    }
    for s in t.subs() {
        let forms: Vec<String> = s.forms.iter().map(Form::label).collect();
        let _ = writeln!(
            out,
            "  sub {:<6} 0x{:04X}  {:<32} {}",
            s.group,
            s.id,
            s.name,
            forms.join("|")
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup_by_name_id_and_sub() {
        let t = Table::global();
        for q in ["MOT_MOVE_HOME", "mgmsg_mot_move_home", "0x0443", "1091"] {
            match lookup(t, q).as_deref() {
                Ok([Entry::Msg(m)]) => assert_eq!(m.name, "MOT_MOVE_HOME", "{q}"),
                other => panic!("{q}: {other:?}"),
            }
        }
        match lookup(t, "la:SETPOINT").as_deref() {
            Ok([Entry::Sub(s)]) => assert_eq!((s.group, s.name), ("la", "SETPOINT")),
            other => panic!("{other:?}"),
        }
        let e = lookup(t, "MOT_MOVE_HOM").unwrap_err();
        assert!(e.contains("did you mean MOT_MOVE_HOME"), "{e}");
        assert!(lookup(t, "0xFFFF").unwrap_err().contains("0xFFFF"));
    }

    #[test]
    fn man_page_shows_what_a_message_is() {
        let t = Table::global();
        let mut s = String::new();
        let Ok(e) = lookup(t, "MOT_MOVE_ABSOLUTE") else {
            panic!()
        };
        man_page(t, e[0], &mut s);
        for want in [
            "MOT_MOVE_ABSOLUTE  0x0453",
            "answered by: MOT_MOVE_COMPLETED, MOT_MOVE_STOPPED",
            "devices: ",
            "KDC101",
            "[6] 6 + 6 bytes",
            "absolute_position",
            "spec examples:",
            "chan_ident=CH1",
            "defined in: Issue 23 (2018), 2025 revision",
        ] {
            assert!(s.contains(want), "missing {want:?} in\n{s}");
        }
    }
}
