//! "Apply as filter" and "prepare as filter" (Wireshark's right-click actions on the packet
//! details): the display filter that selects the records sharing the selected detail-tree
//! line's value, in the language of [`aptscope_dissector::filter`].
//!
//! Values come from the record's NDJSON object (as `decode --json` writes it), not from the
//! tree's text, so every filter built here matches the record it was built from
//! (`tui/tests/as_filter.rs` checks it on every line of every sample).

use crate::decode::{json_value, tree, Node, NodeKind};
use crate::index::Index;
use aptscope_dissector::filter::Filter;
use serde_json::Value;

/// The filter for detail line `node` of record `n`; `None` for a line without a value to
/// filter on (a section heading, the terminator …).
pub fn for_node(ix: &Index, n: u64, node: &Node) -> Option<String> {
    let rec = json_value(ix, n)?;
    let proto = rec.get("proto").and_then(Value::as_str).unwrap_or("apt");
    let id = node.id.as_str();
    let s = match id {
        "rec" => format!("n == {n}"),
        "garbage" => "type == garbage".to_string(),
        "hdr" => "apt".to_string(),
        "hdr.id" => format!("apt.msgid == 0x{:04X}", rec.get("msgid")?.as_u64()?),
        "hdr.len" => format!("apt.data_len == {}", rec.get("data_len")?.as_u64()?),
        "hdr.p" => "apt.data_flag == false".to_string(),
        "hdr.src" => addr("apt.src", rec.get("src")?)?,
        "hdr.dst" => addr("apt.dst", rec.get("dst")?)?,
        "hdr.route" => format!(
            "{} && {}",
            addr("apt.src", rec.get("src")?)?,
            addr("apt.dst", rec.get("dst")?)?
        ),
        "msg" => format!("apt.name == {}", lit(rec.get("name")?)?),
        "sub" => format!("apt.sub == {}", lit(rec.get("sub")?.get("name")?)?),
        "text" => format!("ell.text == {}", lit(rec.get("text")?)?),
        "addr" => format!("ell.addr == {}", lit(rec.get("addr")?)?),
        "cmd" => format!("ell.cmd == {}", lit(rec.get("cmd")?)?),
        "diag" => "diag".to_string(),
        // The exchange: the request and every reply to it.
        "pair" => {
            let req = match rec.get("pair").and_then(Value::as_u64) {
                Some(req) => req,
                None => n,
            };
            format!("n == {req} || pair == {req}")
        }
        _ if id.starts_with("diag.") || id.starts_with("pdiag") => {
            format!("diag.kind == {}", diag_kind(&node.text)?)
        }
        _ => field(&rec, proto, id.strip_prefix("f.")?, node.kind)?,
    };
    // Only what the filter language accepts leaves here.
    Filter::parse(&s).ok().map(|_| s)
}

/// The filter for the message of record `n` (its name, command or kind), for the action taken
/// on a timeline row.
pub fn for_record(ix: &Index, n: u64) -> Option<String> {
    let nodes = tree(ix, n);
    ["msg", "cmd", "garbage", "hdr.id"]
        .iter()
        .find_map(|id| nodes.iter().find(|x| x.id == *id))
        .and_then(|node| for_node(ix, n, node))
}

/// `old` narrowed by `new` (Wireshark's "… and Selected").
pub fn and(old: &str, new: &str) -> String {
    if old.trim().is_empty() {
        new.to_string()
    } else {
        format!("({}) && ({new})", old.trim())
    }
}

/// An address object compared by its name (by its number when the name is not a word).
fn addr(key: &str, a: &Value) -> Option<String> {
    match a.get("name").and_then(Value::as_str) {
        Some(name) if word(name) => Some(format!("{key} == {name}")),
        _ => Some(format!("{key} == 0x{:02X}", a.get("addr")?.as_u64()?)),
    }
}

/// The kind of a diagnostic line (`!! kind: message …`).
fn diag_kind(text: &str) -> Option<&str> {
    let (kind, _) = text.strip_prefix("!! ")?.split_once(':')?;
    (!kind.is_empty() && kind.bytes().all(|c| c.is_ascii_lowercase() || c == b'_')).then_some(kind)
}

/// A field line (`NAME`) or one of its flags (`NAME.LABEL`).
fn field(rec: &Value, proto: &str, path: &str, kind: NodeKind) -> Option<String> {
    let (name, label) = match path.split_once('.') {
        Some((name, label)) => (name, Some(label)),
        None => (path, None),
    };
    // `apt.NAME` reads a record-level key of that name first: go through `fields` then.
    let key = if rec.get(name).is_some() || matches!(name, "chan" | "ts" | "latency") {
        format!("{proto}.fields.{name}")
    } else {
        format!("{proto}.{name}")
    };
    let message = || -> Option<String> {
        Some(format!(
            "{proto}.name == {}",
            lit(rec.get("name").filter(|v| !v.is_null())?)?
        ))
    };
    if let Some(label) = label {
        let l = lit(&Value::from(label))?;
        return match kind {
            NodeKind::FlagOn => Some(format!("{key} contains {l}")),
            // A clear flag: among the records of this message (others have no such flag).
            _ => Some(format!("{} && !({key} contains {l})", message()?)),
        };
    }
    match rec.get("fields")?.get(name)? {
        Value::Array(items) if items.is_empty() => Some(format!("{} && !{key}", message()?)),
        Value::Array(items) => items
            .iter()
            .map(|x| Some(format!("{key} contains {}", lit(x)?)))
            .collect::<Option<Vec<_>>>()
            .map(|v| v.join(" && ")),
        Value::Object(o) => Some(format!("{key} == {}", lit(o.get("name")?)?)),
        v => Some(format!("{key} == {}", lit(v)?)),
    }
}

/// Whether `s` reads as a bare word of the filter language (not a keyword).
fn word(s: &str) -> bool {
    let mut c = s.chars();
    c.next()
        .is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
        && c.all(|x| x.is_ascii_alphanumeric() || x == '_' || x == '.')
        && !matches!(
            s,
            "and" | "or" | "not" | "in" | "contains" | "matches" | "true" | "false"
        )
}

/// A JSON scalar as a literal of the filter language.
fn lit(v: &Value) -> Option<String> {
    match v {
        Value::Bool(b) => Some(b.to_string()),
        Value::Number(x) => match (x.as_i64(), x.as_u64()) {
            (Some(i), _) => Some(i.to_string()),
            (_, Some(u)) => Some(u.to_string()),
            // Rust prints floats without an exponent, which the filter language reads back.
            _ => Some(format!("{}", x.as_f64()?)),
        },
        Value::String(s) if word(s) => Some(s.clone()),
        // A number written as text (an Elliptec address, a serial number) compares as written.
        Value::String(s)
            if (1..=18).contains(&s.len())
                && s.bytes().all(|c| c.is_ascii_digit())
                && (s == "0" || !s.starts_with('0')) =>
        {
            Some(s.clone())
        }
        Value::String(s) => {
            let mut out = String::from('"');
            for c in s.chars() {
                match c {
                    '"' => out.push_str("\\\""),
                    '\\' => out.push_str("\\\\"),
                    '\n' => out.push_str("\\n"),
                    '\r' => out.push_str("\\r"),
                    '\t' => out.push_str("\\t"),
                    c => out.push(c),
                }
            }
            out.push('"');
            Some(out)
        }
        _ => None,
    }
}
