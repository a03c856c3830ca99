//! The key list: the names a filter may use, resolved to record keys, with suggestions for unknown ones.

use super::ast::FieldRef;
use crate::shape::{ell_derived, DerivedName, Key, APT, ELL, KEYS, TOP};

/// Names usable without a protocol prefix.
fn top_level() -> impl Iterator<Item = &'static str> + Clone {
    KEYS.iter().filter(|d| d.scope & TOP != 0).map(|d| d.name)
}

fn scope_of(proto: &str) -> u8 {
    if proto == "ell" {
        ELL
    } else {
        APT
    }
}

/// The field names a protocol's records can hold in `fields` (from the message tables, plus
/// the keys the NDJSON derives beside a field).
fn field_names(proto: &str) -> &'static [&'static str] {
    use std::sync::OnceLock;
    static APT: OnceLock<Vec<&'static str>> = OnceLock::new();
    static ELL: OnceLock<Vec<&'static str>> = OnceLock::new();
    let build = |v: Vec<&'static str>| {
        let mut v = v;
        v.sort_unstable();
        v.dedup();
        v
    };
    if proto == "ell" {
        ELL.get_or_init(|| {
            let mut v: Vec<&'static str> = vec![];
            for c in crate::ell::table::COMMANDS {
                for f in c.fields {
                    v.push(f.name);
                    for d in ell_derived(f.kind) {
                        v.push(match d.name {
                            DerivedName::Fixed(name) => name,
                            DerivedName::Suffix(s) => {
                                Box::leak(format!("{}{s}", f.name).into_boxed_str())
                            }
                        });
                    }
                }
            }
            build(v)
        })
    } else {
        APT.get_or_init(|| {
            let t = crate::Table::global();
            let forms = t
                .msgs()
                .iter()
                .flat_map(|m| m.forms.iter())
                .chain(t.subs().iter().flat_map(|s| s.forms.iter()));
            build(
                forms
                    .flat_map(|f| f.fields.iter().map(|x| x.name))
                    .collect(),
            )
        })
    }
}

/// Check that `rest` (the name after `apt.`/`ell.`) names something records of `proto` hold;
/// if not, say so with the nearest names.
fn check_name(proto: &str, rest: &[&str]) -> Result<(), String> {
    let scope = scope_of(proto);
    let keys = || {
        KEYS.iter()
            .filter(move |d| d.scope & scope != 0)
            .map(|d| d.name)
    };
    let fields = field_names(proto);
    let first = rest.first().copied().unwrap_or("");
    let (ok, bad, cands): (bool, &str, Vec<&str>) = match (first, rest.get(1)) {
        ("fields" | "phys" | "codes", Some(f)) => (fields.contains(f), f, fields.to_vec()),
        _ => (
            Key::lookup(first, scope).is_some() || fields.contains(&first),
            first,
            keys().chain(fields.iter().copied()).collect(),
        ),
    };
    if ok {
        return Ok(());
    }
    let near = crate::suggest::nearest(bad, cands, 4);
    let name = format!("{proto}.{}", rest.join("."));
    Err(if near.is_empty() {
        format!("unknown field `{name}`: no {proto} record has `{bad}`")
    } else {
        let prefix = match (first, rest.get(1)) {
            ("fields" | "phys" | "codes", Some(_)) => format!("{proto}.{first}."),
            _ => format!("{proto}."),
        };
        let list: Vec<String> = near.iter().map(|n| format!("`{prefix}{n}`")).collect();
        format!("unknown field `{name}`; did you mean {}?", list.join(", "))
    })
}

/// What a dotted name refers to.
pub(super) enum Ref {
    Proto(&'static str),
    Field(FieldRef),
}

pub(super) fn resolve(segs: &[&str]) -> Result<Ref, String> {
    let (proto, rest) = match segs.split_first() {
        Some((&"apt", rest)) => (Some("apt"), rest),
        Some((&("ell" | "elliptec"), rest)) => (Some("ell"), rest),
        _ => (None, segs),
    };
    let Some(first) = rest.first() else {
        return Ok(Ref::Proto(proto.unwrap_or("apt")));
    };
    let top = Key::lookup(first, TOP).filter(|_| proto.is_none());
    if proto.is_none() && top.is_none() {
        let name = segs.join(".");
        // Suggest only names that exist: a protocol field of that name, or a record key.
        let mut near: Vec<String> = vec![];
        for p in ["apt", "ell"] {
            if check_name(p, rest).is_ok() {
                near.push(format!("`{p}.{name}`"));
            }
        }
        let last = rest.last().copied().unwrap_or(first);
        for t in crate::suggest::nearest(last, top_level(), 3) {
            near.push(format!("`{t}`"));
        }
        return Err(if near.is_empty() {
            format!("unknown field `{name}`: protocol fields need a prefix (`apt.` or `ell.`)")
        } else {
            format!(
                "unknown field `{name}`: protocol fields need a prefix; did you mean {}?",
                near.join(", ")
            )
        });
    }
    let owned = |s: &[&str]| s.iter().map(|x| x.to_string()).collect::<Vec<String>>();
    let (key, path, fallback) = match proto {
        None => (top.map_or(Key::Fields, |d| d.key), owned(&rest[1..]), None),
        Some(p) => {
            check_name(p, rest)?;
            let is_field = field_names(p).contains(first);
            match Key::lookup(first, scope_of(p)) {
                Some(d) => (d.key, owned(&rest[1..]), is_field.then(|| owned(rest))),
                // A field name alone: `apt.position` is `apt.fields.position`.
                None => (Key::Fields, owned(rest), None),
            }
        }
    };
    let mut ts_seconds = false;
    let mut unit_ns = None;
    if rest.len() == 1 {
        match *first {
            "ts" => {
                ts_seconds = true;
                unit_ns = Some(1e9);
            }
            "ts_ns" => unit_ns = Some(1.0),
            "latency" | "latency_ms" => unit_ns = Some(1e6),
            _ => {}
        }
    }
    let last = rest.last().copied().unwrap_or("");
    Ok(Ref::Field(FieldRef {
        proto,
        key,
        rest: path,
        fallback,
        ts_seconds,
        unit_ns,
        dir_like: matches!(last, "dir" | "msg_dir"),
        case_sensitive: last == "cmd",
    }))
}
