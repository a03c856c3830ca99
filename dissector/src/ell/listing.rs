//! `aptscope messages --proto elliptec`: the command table as text or NDJSON, read from
//! [`COMMANDS`] (nothing here knows a command).

use super::table::{Class, Cmd, COMMANDS, MODELS, STATUS};
use crate::json::{string, uint};
use std::fmt::Write;

/// Replies of a command that are interim when they carry status BUSY (`GS` of a motion).
fn interim(c: &Cmd) -> impl Iterator<Item = &'static str> + '_ {
    c.replies
        .iter()
        .copied()
        .filter(|r| *r == "GS" && c.class.busy_is_interim())
}

fn timeout_text(c: &Cmd) -> String {
    if c.timeout_ms == 0 {
        "-".to_string()
    } else {
        format!("{} s", c.timeout_ms / 1000)
    }
}

/// What the command is answered with (host commands) or answers (replies), as a list.
fn links(c: &Cmd) -> String {
    let (arrow, list): (&str, Vec<&str>) = if c.class == Class::Reply || c.replies.is_empty() {
        ("answers", c.answers().map(|a| a.code).collect())
    } else {
        ("→", c.replies.to_vec())
    };
    if list.is_empty() {
        return String::new();
    }
    let mut s = format!("{arrow} {}", list.join(","));
    let busy: Vec<&str> = interim(c).collect();
    if !busy.is_empty() {
        let _ = write!(s, " ({} BUSY interim)", busy.join(","));
    }
    s
}

/// The listing as text: one line per command (mnemonic, name, direction, class, reply timeout,
/// data characters, replies); `verbose` adds the doc line and one line per data field, then
/// the status codes and module models.
pub fn text(verbose: bool) -> String {
    let mut out = String::from(
        "# code, name, direction, class, reply timeout, data characters (B: binary bytes), replies\n",
    );
    for c in COMMANDS {
        let data = if c.fields.is_empty() {
            "-".to_string()
        } else if c.is_binary() {
            format!("{}B", c.data_len())
        } else {
            c.data_len().to_string()
        };
        let line = format!(
            "{}  {:<26} {:<4} {:<12} {:>5} {:>5}  {}",
            c.code,
            c.name,
            c.dir.as_str(),
            c.class.name(),
            timeout_text(c),
            data,
            links(c)
        );
        out.push_str(line.trim_end());
        out.push('\n');
        if verbose {
            let _ = writeln!(out, "      {}", c.doc);
            let mut at = 0;
            for f in c.fields {
                let _ = writeln!(
                    out,
                    "      {:<16} @{:<3} {:>3}{}  {:<10} {:<11} {}",
                    f.name,
                    at,
                    f.width,
                    if f.kind.is_binary() { "B" } else { "c" },
                    f.kind.name(),
                    f.kind.unit(),
                    f.kind.doc()
                );
                at += f.width as usize;
            }
        }
    }
    if verbose {
        out.push_str("\nstatus codes (GS, BS):");
        for (code, name) in STATUS {
            let _ = write!(out, " {code}={name}");
        }
        out.push_str(" 14-255=RESERVED\nmodels (IN):");
        for m in MODELS {
            let _ = write!(out, " ELL{}={} ({})", m.number, m.what, m.unit);
        }
        out.push('\n');
    }
    out
}

/// The JSON object of one command: `{"proto":"ell","type":"cmd","code","name","dir","class",
/// "timeout_ms","data_len","binary","fields":[{"name","offset","width","kind","unit","doc"}],
/// "replies","interim","answers","doc"}`.
pub fn cmd_json(out: &mut String, c: &Cmd) {
    out.push_str("{\"proto\":\"ell\",\"type\":\"cmd\",\"code\":");
    string(out, c.code);
    out.push_str(",\"name\":");
    string(out, c.name);
    let _ = write!(
        out,
        ",\"dir\":\"{}\",\"class\":\"{}\",\"timeout_ms\":",
        c.dir.as_str(),
        c.class.name()
    );
    uint(out, c.timeout_ms as u64);
    out.push_str(",\"data_len\":");
    uint(out, c.data_len() as u64);
    let _ = write!(out, ",\"binary\":{},\"fields\":[", c.is_binary());
    let mut at = 0u64;
    for (i, f) in c.fields.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push_str("{\"name\":");
        string(out, f.name);
        out.push_str(",\"offset\":");
        uint(out, at);
        out.push_str(",\"width\":");
        uint(out, f.width as u64);
        out.push_str(",\"kind\":");
        string(out, f.kind.name());
        out.push_str(",\"unit\":");
        string(out, f.kind.unit());
        out.push_str(",\"doc\":");
        string(out, f.kind.doc());
        out.push('}');
        at += f.width as u64;
    }
    out.push(']');
    let list = |out: &mut String, key: &str, items: &mut dyn Iterator<Item = &str>| {
        let _ = write!(out, ",\"{key}\":[");
        for (i, r) in items.enumerate() {
            if i > 0 {
                out.push(',');
            }
            string(out, r);
        }
        out.push(']');
    };
    list(out, "replies", &mut c.replies.iter().copied());
    list(out, "interim", &mut interim(c));
    list(out, "answers", &mut c.answers().map(|a| a.code));
    out.push_str(",\"doc\":");
    string(out, c.doc);
    out.push('}');
}

/// The listing as NDJSON lines: every command ([`cmd_json`]), then every status code
/// (`{"proto":"ell","type":"status","code","name"}`) and known module
/// (`{"proto":"ell","type":"model","number","name","what","unit","slots"}`).
pub fn json_lines() -> Vec<String> {
    let mut lines = vec![];
    for c in COMMANDS {
        let mut s = String::new();
        cmd_json(&mut s, c);
        lines.push(s);
    }
    for (code, name) in STATUS {
        let mut s = String::from("{\"proto\":\"ell\",\"type\":\"status\",\"code\":");
        uint(&mut s, *code as u64);
        s.push_str(",\"name\":");
        string(&mut s, name);
        s.push('}');
        lines.push(s);
    }
    for m in MODELS {
        let mut s = String::from("{\"proto\":\"ell\",\"type\":\"model\",\"number\":");
        uint(&mut s, m.number as u64);
        let _ = write!(s, ",\"name\":\"ELL{}\",\"what\":", m.number);
        string(&mut s, m.what);
        s.push_str(",\"unit\":");
        string(&mut s, m.unit);
        s.push_str(",\"slots\":");
        uint(&mut s, m.slots as u64);
        s.push('}');
        lines.push(s);
    }
    lines
}
