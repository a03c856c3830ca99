//! "Apply as filter" and "prepare as filter" (Wireshark's right-click actions on the packet
//! details): the display filter that selects the records sharing the selected detail-tree
//! line's value, in the language of [`aptscope_dissector::filter`].
//!
//! Values are read as filters read them ([`View`], the record's fields by name), not from the
//! tree's text, so every filter built here matches the record it was built from
//! (`tui/tests/as_filter.rs` checks it on every line of every sample).

use crate::decode::{tree, Node, NodeKind};
use crate::fields::View;
use crate::index::Index;
use aptscope_dissector::fields::{self as keys, Fields, Key, Num, Role, Val};
use aptscope_dissector::filter::Filter;
use std::borrow::Cow;

/// A value found in a record, owned.
type Owned = Val<'static>;

fn own(v: Val<'_>) -> Owned {
    match v {
        Val::Num(n) => Val::Num(n),
        Val::Bool(b) => Val::Bool(b),
        Val::Str(s) => Val::Str(Cow::Owned(s.into_owned())),
        Val::Obj(o) => Val::Obj(keys::Obj {
            num: o.num,
            text: o.text.map(|t| Cow::Owned(t.into_owned())),
            nonempty: o.nonempty,
        }),
    }
}

/// Every value at `key`/`rest` with how it was found (codes left out).
fn values(v: &View<'_>, key: Key, rest: &[String]) -> Vec<(Owned, Role)> {
    let mut out = vec![];
    v.visit(key, rest, &mut |x, r| {
        if r != Role::Code {
            out.push((own(x), r));
        }
    });
    out
}

/// The value at `key`/`rest`.
fn first(v: &View<'_>, key: Key, rest: &[String]) -> Option<Owned> {
    values(v, key, rest)
        .into_iter()
        .find(|(_, r)| *r == Role::Plain)
        .map(|(x, _)| x)
}

/// The whole number at `key`.
fn number(v: &View<'_>, key: Key) -> Option<u64> {
    match first(v, key, &[])? {
        Val::Num(n) => n.u64(),
        _ => None,
    }
}

/// The filter for detail line `node` of record `n`; `None` for a line without a value to
/// filter on (a section heading, the terminator …).
pub fn for_node(ix: &Index, n: u64, node: &Node) -> Option<String> {
    let v = View {
        ix,
        n,
        r: &ix.rec(n)?,
    };
    let proto = v.proto().unwrap_or("apt");
    let name = ["name".to_string()];
    let id = node.id.as_str();
    let s = match id {
        "rec" => format!("n == {n}"),
        "garbage" => "type == garbage".to_string(),
        "hdr" => "apt".to_string(),
        "hdr.id" => format!("apt.msgid == 0x{:04X}", number(&v, Key::Msgid)?),
        "hdr.len" => format!("apt.data_len == {}", number(&v, Key::DataLen)?),
        "hdr.p" => "apt.data_flag == false".to_string(),
        "hdr.src" => addr("apt.src", &first(&v, Key::Src, &[])?)?,
        "hdr.dst" => addr("apt.dst", &first(&v, Key::Dst, &[])?)?,
        "hdr.route" => format!(
            "{} && {}",
            addr("apt.src", &first(&v, Key::Src, &[])?)?,
            addr("apt.dst", &first(&v, Key::Dst, &[])?)?
        ),
        "msg" => format!("apt.name == {}", lit(&first(&v, Key::Name, &[])?)?),
        "sub" => format!("apt.sub == {}", lit(&first(&v, Key::Sub, &name)?)?),
        "text" => format!("ell.text == {}", lit(&first(&v, Key::Text, &[])?)?),
        "addr" => format!("ell.addr == {}", lit(&first(&v, Key::Addr, &[])?)?),
        "cmd" => format!("ell.cmd == {}", lit(&first(&v, Key::Cmd, &[])?)?),
        "diag" => "diag".to_string(),
        // The exchange: the request and every reply to it.
        "pair" => {
            let req = number(&v, Key::Pair).unwrap_or(n);
            format!("n == {req} || pair == {req}")
        }
        _ if id.starts_with("diag.") || id.starts_with("pdiag") => {
            format!("diag.kind == {}", diag_kind(&node.text)?)
        }
        _ => field(&v, proto, id.strip_prefix("f.")?, node)?,
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

/// An address compared by its name (by its number when the name is not a word).
fn addr(key: &str, a: &Owned) -> Option<String> {
    let Val::Obj(o) = a else { return None };
    match o.text.as_deref() {
        Some(name) if word(name) => Some(format!("{key} == {name}")),
        _ => Some(format!("{key} == 0x{:02X}", o.num?.u64()?)),
    }
}

/// The kind of a diagnostic line (`!! kind: message …`).
fn diag_kind(text: &str) -> Option<&str> {
    let (kind, _) = text.strip_prefix("!! ")?.split_once(':')?;
    (!kind.is_empty() && kind.bytes().all(|c| c.is_ascii_lowercase() || c == b'_')).then_some(kind)
}

/// A field line (`NAME`) or one of its flags (`NAME.LABEL`).
fn field(v: &View<'_>, proto: &str, path: &str, node: &Node) -> Option<String> {
    let (name, label) = match path.split_once('.') {
        Some((name, label)) => (name, Some(label)),
        None => (path, None),
    };
    // `apt.NAME` reads a record-level key of that name first: go through `fields` then.
    let top = keys::Key::lookup(name, keys::TOP | keys::APT | keys::ELL)
        .is_some_and(|d| v.visit(d.key, &[], &mut |_, _| {}));
    let key = if top || matches!(name, "chan" | "ts" | "latency") {
        format!("{proto}.fields.{name}")
    } else {
        format!("{proto}.{name}")
    };
    let message = || -> Option<String> {
        Some(format!(
            "{proto}.name == {}",
            lit(&first(v, Key::Name, &[])?)?
        ))
    };
    if let Some(label) = label {
        let l = lit(&Val::Str(Cow::Owned(label.to_string())))?;
        return match node.kind {
            NodeKind::FlagOn => Some(format!("{key} contains {l}")),
            // A clear flag: among the records of this message (others have no such flag).
            _ => Some(format!("{} && !({key} contains {l})", message()?)),
        };
    }
    let vals = values(v, Key::Fields, &[name.to_string()]);
    let members: Vec<&Owned> = vals
        .iter()
        .filter(|(_, r)| *r == Role::Member)
        .map(|(x, _)| x)
        .collect();
    match vals.first() {
        // A list (flags, an array): each element it holds; an empty one (a flags field with
        // its flags below it in the tree): none.
        Some((_, Role::Member)) => members
            .iter()
            .map(|x| Some(format!("{key} contains {}", lit(x)?)))
            .collect::<Option<Vec<_>>>()
            .map(|v| v.join(" && ")),
        None if node.children => Some(format!("{} && !{key}", message()?)),
        Some((Val::Obj(o), _)) => Some(format!("{key} == {}", lit(&Val::Str(o.text.clone()?))?)),
        Some((x, _)) => Some(format!("{key} == {}", lit(x)?)),
        None => None,
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

/// A value as a literal of the filter language.
fn lit(v: &Owned) -> Option<String> {
    match v {
        Val::Bool(b) => Some(b.to_string()),
        Val::Num(Num::I(i)) => Some(i.to_string()),
        // Rust prints floats without an exponent, which the filter language reads back.
        Val::Num(Num::F(x)) => Some(format!("{x}")),
        Val::Str(s) if word(s) => Some(s.to_string()),
        // A number written as text (an Elliptec address, a serial number) compares as written.
        Val::Str(s)
            if (1..=18).contains(&s.len())
                && s.bytes().all(|c| c.is_ascii_digit())
                && (s == "0" || !s.starts_with('0')) =>
        {
            Some(s.to_string())
        }
        Val::Str(s) => {
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
        Val::Obj(_) => None,
    }
}
