//! A Wireshark/tshark Lua dissector generated from the message tables (`aptscope export
//! wireshark-lua`).
//!
//! The output is one Lua file: a data part written here from [`Table::global`] (APT messages,
//! forms, fields, enums, flags, sub-messages) and [`COMMANDS`] (Elliptec), and a fixed engine
//! ([`ENGINE`]) that frames and dissects with those tables. Nothing per message is written by
//! hand, so the dissector follows the tables.
//!
//! Field names are aptscope's display-filter names: `apt.msgid`, `apt.name`, `apt.src`,
//! `apt.dst`, `apt.chan`, `apt.<field>`, `ell.cmd`, `ell.addr`, `ell.<field>`. Wireshark needs
//! one type per field name; a table field name that occurs with several types or value sets
//! (integer signedness, float, text, bytes, enum, flag word) gets one ProtoField per variant:
//! the first in table order is `apt.<field>`, each other one `apt.<field>.<suffix>` with the
//! suffix the name of its enum, else `flags` or its type (`uint`, `int`, `float`, `string`,
//! `bytes`), numbered (`_2`) if still taken. Integers of the same signedness share one field
//! whatever their width, and flag words of one name share one field whatever their flag set.
//! Bits of a flag word are `<field abbrev>.<flag label in lower case>`, or
//! `<field abbrev>.<flag set>.<label>` when another set already uses that label with another
//! mask.

use crate::ell::table::{Class, Kind, COMMANDS, STATUS, STATUS_BUSY};
use crate::table::{FlagsDef, FormKind, Loc, Prim, Table, Ty};
use std::collections::HashMap;
use std::fmt::Write;

/// Header-level APT field names the engine defines itself; a table field with one of these
/// names gets a suffix.
const APT_RESERVED: &[&str] = &[
    "msgid",
    "name",
    "data_len",
    "param1",
    "param2",
    "dst",
    "src",
    "data_flag",
    "chan",
    "sub",
    "form",
    "garbage",
    "pending",
    "expert",
];
/// Elliptec field names the engine defines itself.
const ELL_RESERVED: &[&str] = &["cmd", "addr", "name", "data", "garbage", "expert", "text"];

/// One ProtoField to declare.
struct Pf {
    abbr: String,
    ctor: String,
    label: String,
    base: &'static str,
    vs: Option<String>,
    mask: Option<u64>,
}

/// The ProtoFields of one protocol, deduplicated by (name, variant).
struct Fields {
    prefix: &'static str,
    reserved: &'static [&'static str],
    pfs: Vec<Pf>,
    by_key: HashMap<String, usize>,
    taken: HashMap<String, usize>,
}

impl Fields {
    fn new(prefix: &'static str, reserved: &'static [&'static str]) -> Self {
        Fields {
            prefix,
            reserved,
            pfs: vec![],
            by_key: HashMap::new(),
            taken: HashMap::new(),
        }
    }

    /// The bit fields of flag set `set` in a word of `width` bits under ProtoField `parent`:
    /// `<parent>.<label>`, or `<parent>.<set>.<label>` when another set of the same field name
    /// already has that label with another mask or width.
    fn bits_of(&mut self, parent: usize, set: &FlagsDef, width: usize) -> Vec<usize> {
        let mut out = vec![];
        for (mask, l) in &set.items {
            let one_bit = mask.count_ones() == 1;
            let ctor = if one_bit {
                "bool".to_string()
            } else {
                format!("uint{width}")
            };
            let base = if one_bit {
                // ProtoField.bool takes the word's width in bits.
                match width {
                    8 => "8",
                    16 => "16",
                    _ => "32",
                }
            } else {
                "base.HEX"
            };
            let label = l.to_ascii_lowercase();
            let p = self.pfs[parent].abbr.clone();
            let mut found = None;
            for abbr in [
                format!("{p}.{label}"),
                format!("{p}.{}.{label}", set.name),
                format!("{p}.{}.{label}_{width}", set.name),
            ] {
                match self.taken.get(&abbr) {
                    Some(&i) => {
                        let b = &self.pfs[i];
                        if b.mask == Some(*mask) && b.ctor == ctor && b.base == base {
                            found = Some(i);
                            break;
                        }
                    }
                    None => {
                        self.pfs.push(Pf {
                            abbr: abbr.clone(),
                            ctor: ctor.clone(),
                            label: l.to_string(),
                            base,
                            vs: None,
                            mask: Some(*mask),
                        });
                        let i = self.pfs.len() - 1;
                        self.taken.insert(abbr, i);
                        found = Some(i);
                        break;
                    }
                }
            }
            // The last name is unique: set names are, labels within a set are.
            out.extend(found);
        }
        out
    }

    /// The index of the ProtoField for `name` in variant `key`, declared on first use by `mk`.
    fn get(
        &mut self,
        name: &str,
        key: String,
        suffix: &str,
        mk: impl FnOnce(String) -> Pf,
    ) -> usize {
        let full = format!("{name}\u{0}{key}");
        if let Some(&i) = self.by_key.get(&full) {
            return i;
        }
        let plain = format!("{}.{name}", self.prefix);
        let mut abbr = if self.reserved.contains(&name) || self.taken.contains_key(&plain) {
            format!("{plain}.{suffix}")
        } else {
            plain
        };
        let stem = abbr.clone();
        let mut n = 2;
        while self.taken.contains_key(&abbr) {
            abbr = format!("{stem}_{n}");
            n += 1;
        }
        let pf = mk(abbr.clone());
        let i = self.pfs.len();
        self.pfs.push(pf);
        self.taken.insert(abbr, i);
        self.by_key.insert(full, i);
        i
    }
}

/// A Lua string literal.
fn lua_str(s: &str) -> String {
    let mut o = String::with_capacity(s.len() + 2);
    o.push('"');
    for c in s.chars() {
        match c {
            '\\' => o.push_str("\\\\"),
            '"' => o.push_str("\\\""),
            '\n' => o.push_str("\\n"),
            '\r' => o.push_str("\\r"),
            c if (c as u32) < 0x20 => {
                let _ = write!(o, "\\{}", c as u32);
            }
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

fn prim_name(p: Prim) -> &'static str {
    p.as_str()
}

/// Wireshark class of a primitive: (ProtoField constructor, suffix).
fn prim_class(p: Prim) -> (&'static str, &'static str) {
    match p {
        Prim::F32 => ("float", "float"),
        p if p.signed() => ("int32", "int"),
        _ => ("uint32", "uint"),
    }
}

/// The label of a table field: its name and unit.
fn label_of(name: &str, unit: Option<&str>, scale: Option<f64>) -> String {
    match (unit, scale) {
        (Some(u), Some(s)) => format!("{name} (raw; x {s} = {u})"),
        (Some(u), None) => format!("{name} ({u})"),
        _ => name.to_string(),
    }
}

/// Generate the Lua dissector for both protocols from the global tables.
pub fn lua() -> String {
    lua_for(Table::global())
}

/// Generate the Lua dissector from `table` (APT) and [`COMMANDS`] (Elliptec).
pub fn lua_for(table: &Table) -> String {
    let mut out = String::new();
    out.push_str(
        "-- aptscope.lua: Wireshark/tshark dissector for Thorlabs APT and Elliptec ELLx.\n\
         -- GENERATED by `aptscope export wireshark-lua` from aptscope's message tables: do not edit.\n\
         -- Install: copy to ~/.local/lib/wireshark/plugins/ (Wireshark 4.0 or newer).\n\n\
         local apt = Proto(\"apt\", \"Thorlabs APT\")\n\
         local ell = Proto(\"ell\", \"Thorlabs Elliptec ELLx\")\n\
         local link = Proto(\"aptscope\", \"aptscope serial link\")\n\n",
    );

    // Enumerations and flag sets as value tables.
    out.push_str("local VS = {}\n");
    for (i, e) in table.enums().iter().enumerate() {
        let _ = write!(out, "VS[{}] = {{", i + 1);
        for (v, l) in &e.items {
            let _ = write!(out, "[{v}]={},", lua_str(l));
        }
        let _ = writeln!(out, "}} -- {}", e.name);
    }

    let mut af = Fields::new("apt", APT_RESERVED);
    // Lua source of one field entry: {o, ty, count, pf, unit, scale, chan}.
    let field_entry = |af: &mut Fields, f: &crate::table::Field| -> String {
        let off = f.loc.frame_offset();
        let (ty, count, prim) = match f.ty {
            Ty::Prim(p) => (prim_name(p).to_string(), 1, Some(p)),
            Ty::Array(p, n) => (prim_name(p).to_string(), n as usize, Some(p)),
            Ty::Str(n) => ("str".into(), n as usize, None),
            Ty::Bytes(n) => ("bytes".into(), n as usize, None),
            Ty::Pad(n) => ("pad".into(), n as usize, None),
        };
        let label = label_of(f.name, f.unit, f.scale);
        let mut bits: Vec<usize> = vec![];
        let pf = match (f.ty, prim) {
            (Ty::Pad(_), _) => 0,
            (_, Some(p)) => {
                let (mut ctor, mut suffix) = prim_class(p);
                let mut base = "base.DEC";
                let mut vs = None;
                let mut key = ctor.to_string();
                if f.flags.is_some() {
                    // Flag words of one name share a field whatever their flag set; their bits
                    // are fields of their own.
                    base = "base.HEX";
                    suffix = "flags";
                    key = "uint32/flags".into();
                    ctor = "uint32";
                } else if let Some(e) = f.enumeration {
                    vs = Some(format!("VS[{}]", e + 1));
                    suffix = table.enum_def(e).name;
                    key = format!("{ctor}/enum{e}");
                }
                let i = af.get(f.name, key, suffix, |abbr| Pf {
                    abbr,
                    ctor: ctor.to_string(),
                    label,
                    base,
                    vs,
                    mask: None,
                });
                if let Some(fl) = f.flags {
                    bits = af.bits_of(i, table.flags_def(fl), p.width() * 8);
                }
                i + 1
            }
            (Ty::Str(_), _) => {
                af.get(f.name, "string".into(), "string", |abbr| Pf {
                    abbr,
                    ctor: "string".into(),
                    label,
                    base: "",
                    vs: None,
                    mask: None,
                }) + 1
            }
            _ => {
                af.get(f.name, "bytes".into(), "bytes", |abbr| Pf {
                    abbr,
                    ctor: "bytes".into(),
                    label,
                    base: "",
                    vs: None,
                    mask: None,
                }) + 1
            }
        };
        let mut e = format!("{{{off},\"{ty}\",{count},{pf}");
        // The unit goes into the item text when the field's label (from the first field of
        // that name) does not already say it, or to show the scaled value.
        let labelled = pf > 0 && af.pfs[pf - 1].label == label_of(f.name, f.unit, f.scale);
        let unit = f.unit.filter(|_| f.scale.is_some() || !labelled);
        let _ = write!(e, ",{}", unit.map_or("nil".into(), lua_str));
        let _ = write!(e, ",{}", f.scale.map_or("nil".into(), |s| format!("{s:e}")));
        if f.name == "chan_ident" {
            e.push_str(",chan=true");
        }
        if !bits.is_empty() {
            let b: Vec<String> = bits.iter().map(|b| (b + 1).to_string()).collect();
            let _ = write!(e, ",bits={{{}}}", b.join(","));
        }
        e.push('}');
        e
    };
    let forms_src = |af: &mut Fields, forms: &[crate::table::Form]| -> String {
        let mut s = String::from("{");
        for fm in forms {
            let k = match fm.kind {
                FormKind::Header => "HDR".to_string(),
                FormKind::Data(n) => n.to_string(),
                FormKind::Sub => "SUB".to_string(),
                // An open form: at least `min` bytes, then whole elements of its last field.
                FormKind::Open(n) => format!("OPEN,min={n},elem={}", fm.open_elem().unwrap_or(1)),
            };
            let sid = fm
                .fields
                .iter()
                .any(|f| f.name == "sub_id" && f.loc == Loc::P1);
            let _ = write!(s, "{{k={k},note={},sid={sid},f={{", lua_str(fm.note));
            for f in &fm.fields {
                s.push_str(&field_entry(af, f));
                s.push(',');
            }
            s.push_str("}},");
        }
        s.push('}');
        s
    };

    let mut msgs = String::from("local MSG = {}\n");
    for m in table.msgs() {
        let _ = writeln!(
            msgs,
            "MSG[0x{:04x}] = {{name={},d2h={},max={},rep={{{}}},to={},subs={},forms={}}}",
            m.id,
            lua_str(m.name),
            m.dir == crate::table::Dir::DeviceToHost,
            table.max_data_len(m),
            table
                .reply_ids(m)
                .iter()
                .map(|id| format!("[0x{id:04x}]=true"))
                .collect::<Vec<_>>()
                .join(","),
            crate::pair::default_timeout_ns(m) / 1_000_000,
            m.subs.map_or("nil".into(), lua_str),
            forms_src(&mut af, &m.forms)
        );
    }
    let mut subs = String::from("local SUBS = {}\nlocal SUBLEN = {}\n");
    let mut groups: Vec<&str> = vec![];
    for s in table.subs() {
        if !groups.contains(&s.group) {
            groups.push(s.group);
            let _ = writeln!(
                subs,
                "SUBS[{g}] = {{}}\nSUBLEN[{g}] = {{}}",
                g = lua_str(s.group)
            );
        }
        let _ = writeln!(
            subs,
            "SUBS[{}][{}] = {{name={},forms={}}}",
            lua_str(s.group),
            s.id,
            lua_str(s.name),
            forms_src(&mut af, &s.forms)
        );
        for f in &s.forms {
            if let FormKind::Data(n) = f.kind {
                let _ = writeln!(subs, "SUBLEN[{}][{n}] = true", lua_str(s.group));
            }
        }
    }

    // Elliptec commands.
    let mut ef = Fields::new("ell", ELL_RESERVED);
    let mut cmds = String::from("local CMD = {}\n");
    for c in COMMANDS {
        let _ = write!(
            cmds,
            "CMD[{}] = {{name={},len={},bin={},rep={{{}}},interim={},newaddr={},to={},f={{",
            lua_str(c.code),
            lua_str(c.name),
            c.data_len(),
            c.is_binary(),
            c.replies
                .iter()
                .map(|r| format!("[{}]=true", lua_str(r)))
                .collect::<Vec<_>>()
                .join(","),
            c.class.busy_is_interim(),
            matches!(c.class, Class::Address | Class::Group),
            c.timeout_ms
        );
        for f in c.fields {
            let (ctor, suffix, base, vs) = match f.kind {
                Kind::Position | Kind::Signed => ("int32", "int", "base.DEC", None),
                Kind::Dec | Kind::Addr => ("string", "string", "", None),
                Kind::Raw => ("bytes", "bytes", "", None),
                Kind::Status => ("uint32", "status", "base.DEC", Some("ELL_STATUS".into())),
                _ => ("uint32", "uint", "base.DEC", None),
            };
            let unit = f.kind.unit();
            let label = if unit.is_empty() {
                f.name.to_string()
            } else {
                format!("{} ({unit})", f.name)
            };
            let i = ef.get(f.name, format!("{ctor}/{suffix}"), suffix, |abbr| Pf {
                abbr,
                ctor: ctor.into(),
                label,
                base,
                vs,
                mask: None,
            });
            let _ = write!(cmds, "{{{},\"{}\",{}}},", f.width, f.kind.name(), i + 1);
        }
        cmds.push_str("}}\n");
    }

    let mut status = String::from("local ELL_STATUS = {");
    for (v, l) in STATUS {
        let _ = write!(status, "[{v}]={},", lua_str(l));
    }
    let _ = write!(status, "}}\nlocal ELL_BUSY = {STATUS_BUSY}\n\n");
    out.push_str(&status);

    for (var, f) in [("APF", &af), ("EPF", &ef)] {
        let _ = writeln!(out, "local {var} = {{}}");
        for (i, p) in f.pfs.iter().enumerate() {
            let mut args = vec![lua_str(&p.abbr), lua_str(&p.label)];
            match p.ctor.as_str() {
                "string" | "bytes" => {}
                "bool" => {
                    args.push(p.base.to_string());
                    args.push("nil".into());
                    args.push(format!("0x{:x}", p.mask.unwrap_or(0)));
                }
                _ => {
                    args.push(p.base.to_string());
                    args.push(p.vs.clone().unwrap_or_else(|| "nil".into()));
                    if let Some(m) = p.mask {
                        args.push(format!("0x{m:x}"));
                    }
                }
            }
            let _ = writeln!(
                out,
                "{var}[{}] = ProtoField.{}({})",
                i + 1,
                p.ctor,
                args.join(", ")
            );
        }
        out.push('\n');
    }
    out.push_str("local HDR, SUB, OPEN = -1, -2, -3\n");
    out.push_str(&msgs);
    out.push_str(&subs);
    out.push_str(&cmds);
    out.push_str(ENGINE);
    out
}

/// The fixed part of the dissector: framing, reassembly, dissection and registration, driven by
/// the generated tables above it.
pub const ENGINE: &str = include_str!("wireshark_engine.lua");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_abbrevs_are_unique_and_prefixed() {
        let lua = lua();
        let mut seen = std::collections::HashSet::new();
        for line in lua.lines().filter(|l| l.contains("= ProtoField.")) {
            let abbr = line.split('"').nth(1).expect("abbrev");
            assert!(
                ["apt.", "ell.", "aptscope."]
                    .iter()
                    .any(|p| abbr.starts_with(p)),
                "{abbr}"
            );
            assert!(seen.insert(abbr.to_string()), "duplicate field {abbr}");
        }
        for want in [
            "apt.chan_ident",
            "apt.position",
            "ell.position",
            "apt.status_bits",
        ] {
            assert!(seen.contains(want), "{want} missing");
        }
    }

    #[test]
    fn every_message_and_command_is_in_the_lua() {
        let lua = lua();
        for m in Table::global().msgs() {
            assert!(lua.contains(&format!("MSG[0x{:04x}] = {{name=\"{}\"", m.id, m.name)));
        }
        for c in COMMANDS {
            assert!(lua.contains(&format!("CMD[\"{}\"] = {{name=\"{}\"", c.code, c.name)));
        }
    }
}
